use mvad::hybrid;

hybrid! {
    model Cubic {
        param a = 1.0;
        qp q(u) {
            minimize u^3 - a * u;
            subject to u >= 0;
        }
        cost = q.u;
    }
}

fn main() {}
