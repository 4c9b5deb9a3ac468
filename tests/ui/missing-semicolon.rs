use mvad::hybrid;

hybrid! {
    model Ball {
        param g = 9.81
        state v = 0.0;
        flow {
            der(v) = -g;
        }
    }
}

fn main() {}
