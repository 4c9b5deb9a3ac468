use mvad::hybrid;

hybrid! {
    model Fall {
        param g = 9.81;
        state v = 0.0;
        flow { der(v) = -g * vv; }
    }
}

fn main() {}
