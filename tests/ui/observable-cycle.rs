use mvad::hybrid;

hybrid! {
    model Loop {
        state x = 0.0;
        flow {
            der(x) = 1.0;
        }
        observe a = b + x;
        observe b = 2 * a;
    }
}

fn main() {}
