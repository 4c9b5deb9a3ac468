use mvad::hybrid;

hybrid! {
    model Proj {
        param a = 1.0;
        qp q(u) {
            minimize 0.5 * u^2 - a * u;
            subject to u <= 1;
        }
        cost = q.v;
    }
}

fn main() {}
