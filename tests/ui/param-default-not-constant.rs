use mvad::hybrid;

hybrid! {
    model Decay {
        param k = 0.5;
        param k2 = k * k;
        state x = 1.0;
        flow {
            der(x) = -k2 * x;
        }
    }
}

fn main() {}
