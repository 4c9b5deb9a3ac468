use mvad::hybrid;

hybrid! {
    model Decay {
        param k = 0.5;
        state x = 1.0;
        flow { der(x) = -k * sine(x); }
    }
}

fn main() {}
