use mvad::hybrid;

hybrid! {
    model Ball {
        state h = 2.0;
        state v = 0.0;
        flow { der(h) = v; }
    }
}

fn main() {}
