use mvad::hybrid;

hybrid! {
    model Ball {
        param g = 9.81;
        state h = 2.0;
        state v = 0.0;
        flow { der(h) = vv; der(v) = -gg; }
        event impact when h <= 0 -> nowhere;
    }
}

fn main() {}
