use mvad::hybrid;

hybrid! {
    model Ball {
        state h = 2.0;
        state v = 0.0;
        flow {
            der(h) = v;
            der(v) = -9.81;
        }
        event impact when h <= 0 {
            v = -0.8 * v;
        }
        cost = sum(impakt, v^2);
    }
}

fn main() {}
