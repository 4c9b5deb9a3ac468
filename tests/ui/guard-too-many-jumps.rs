use mvad::hybrid;

hybrid! {
    model Jumps {
        state x = 0;
        flow { der(x) = 1; }
        event e when sign(x - 1) + sign(x - 2) + sign(x - 3) + sign(x - 4) + sign(x - 5) + sign(x - 6) + sign(x - 7) >= 0 { x = 0; }
        horizon 1;
    }
}

fn main() {}
