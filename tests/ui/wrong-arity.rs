use mvad::hybrid;

hybrid! {
    model Clip {
        state x = 1.0;
        flow { der(x) = -max(x); }
    }
}

fn main() {}
