use mvad::hybrid;

hybrid! {
    model Ball {
        param g = 9.81;
        param g = 1.62;
        state h = 2.0;
        flow {
            der(h) = -g;
        }
    }
}

fn main() {}
