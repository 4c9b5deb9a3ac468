use mvad::hybrid;

hybrid! {
    model Ball {
        state h = 2.0;
        flow { der(h) = -1.0; }
        event impact when h - 0.5 { h = 1.0; }
    }
}

fn main() {}
