use mvad::hybrid;

hybrid! {
    model Clock {
        state t = 0.0;
        flow {
            der(t) = 1.0;
        }
    }
}

fn main() {}
