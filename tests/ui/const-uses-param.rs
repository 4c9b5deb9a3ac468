use mvad::hybrid;

hybrid! {
    model Decay {
        param k = 0.5;
        const two_k = 2 * k;
        state x = 1.0;
        flow {
            der(x) = -two_k * x;
        }
    }
}

fn main() {}
