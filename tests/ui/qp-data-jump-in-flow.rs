use mvad::hybrid;

hybrid! {
    model QpIf {
        param c = 0.5;
        state x = 0;
        state y = 0;
        qp q(u) {
            minimize 0.5 * u^2 - (if x >= c then 2 else 1) * u;
        }
        flow { der(x) = 1; der(y) = q.u; }
        cost = final(y);
        horizon 1;
    }
}

fn main() {}
