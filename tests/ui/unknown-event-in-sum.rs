use mvad::hybrid;

hybrid! {
    model Bounce {
        state y = 1.0;
        flow { der(y) = -2.0; }
        event impact when y <= 0 { y = 1.0; }
        cost = sum(impakt, y^2);
    }
}

fn main() {}
