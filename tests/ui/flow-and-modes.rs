use mvad::hybrid;

hybrid! {
    model Mixed {
        state x = 0.0;
        flow {
            der(x) = 1.0;
        }
        mode fast {
            der(x) = 2.0;
        }
    }
}

fn main() {}
