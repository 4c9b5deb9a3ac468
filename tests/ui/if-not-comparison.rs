use mvad::hybrid;

hybrid! {
    model Relay {
        state x = 1.0;
        flow {
            der(x) = if x then -1 else 1;
        }
    }
}

fn main() {}
