use mvad::hybrid;

hybrid! {
    model Ball {
        state h = 2.0;
        flow { der(h) = -1.0; der(h) = 1.0; }
    }
}

fn main() {}
