use mvad::hybrid;

hybrid! {
    model Wave {
        param sin = 0.5;
        state x = 0.0;
        flow { der(x) = -sin; }
    }
}

fn main() {}
