use mvad::hybrid;

hybrid! {
    model Ball {
        param g = 9.81;
        state h = 2.0;
        flow {
            der(h) = 1.0;
            der(g) = 0.0;
        }
    }
}

fn main() {}
