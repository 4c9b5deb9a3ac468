// A model without states whose cost is a static qp term compiles, and its qp is reachable.
use mvad::{HybridModel, Options};

mvad::hybrid! {
    model QpKink {
        param theta = 0.5;
        qp u_star(u) {
            minimize 0.5 * u^2 - theta * u;
            subject to u >= 0;
        }
        observe u = u_star.u;
        cost = 0.5 * u_star.u^2;
    }
}

fn main() {
    let m = QpKink::new();
    let sol = mvad::solve(&m, &m.default_params(), &Options::default()).unwrap();
    assert_eq!(sol.cost, 0.125);
    assert_eq!(m.qps()[0].name, "u_star");
}
