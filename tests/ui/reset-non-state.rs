use mvad::hybrid;

hybrid! {
    model Ball {
        param e = 0.8;
        state h = 2.0;
        flow { der(h) = -1.0; }
        event impact when h <= 0 { e = 0.5; }
    }
}

fn main() {}
