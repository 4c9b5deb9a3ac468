use mvad::hybrid;

hybrid! {
    model Ball {
        param e = 0.8;
        state h = 2.0;
        state v = 0.0;
        flow {
            der(h) = v;
            der(v) = -9.81;
        }
        event impact when h <= 0 {
            e = 0.5;
        }
    }
}

fn main() {}
