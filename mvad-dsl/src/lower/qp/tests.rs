//! Lowering of qps: the data H, c, A, b against hand-derived values, and the symbolic
//! checks (degree, convexity, constraints that involve the variables), each located.

use crate::ir::{ConstraintKind, Point, Program};
use crate::testing::located;

fn program(src: &str) -> Program {
    let model = crate::front(src).unwrap_or_else(|e| panic!("front: {e:?}"));
    crate::lower::lower(&model).unwrap_or_else(|e| panic!("lower: {e:?}"))
}

/// The lowering errors of a model the checker accepts, as (line, column, message).
fn errors(src: &str) -> Vec<(usize, usize, String)> {
    let model = crate::front(src).unwrap_or_else(|e| panic!("front: {e:?}"));
    located(src, crate::lower::lower(&model).err().unwrap_or_default())
}

#[test]
fn data_of_a_two_variable_qp() {
    // F = ½a u² + b u v + v² − c u + 7;  u + 2v ≤ d;  v ≥ e (−v ≤ −e);  u = f x.
    let p = program(
        "model M { param a = 3; param b = 0.5; param c = 2; param d = 1; param e = -1; param f = 4;
         state x = 1; flow { der(x) = 0; }
         qp q(u, v) { minimize 0.5*a*u^2 + b*u*v + v^2 - c*u + 7;
                      subject to u + 2*v <= d; v >= e; u == f*x; }
         cost = final(q.u); horizon 1; }",
    );
    let q = &p.qps[0];
    assert_eq!(q.vars, ["u", "v"]);
    assert_eq!(
        q.kinds,
        [ConstraintKind::Le, ConstraintKind::Le, ConstraintKind::Eq]
    );
    assert!(q.dynamic);
    let theta = [3.0, 0.5, 2.0, 1.0, -1.0, 4.0];
    let at = Point {
        t: 0.0,
        x: &[0.25],
        p: &theta,
        sw: 0,
    };
    let ev = |v: &[crate::ir::ExprId]| p.arena.eval(v, &at);
    assert_eq!(ev(&q.h), [3.0, 0.5, 0.5, 2.0]);
    assert_eq!(ev(&q.c), [-2.0, 0.0]);
    assert_eq!(ev(&q.a), [1.0, 2.0, 0.0, -1.0, 1.0, 0.0]);
    assert_eq!(ev(&q.b), [1.0, 1.0, 1.0]);
}

#[test]
fn static_and_stateless() {
    let p = program(
        "model QpKink { param theta = 0.5;
         qp u_star(u) { minimize 0.5 * u^2 - theta * u; subject to u >= 0; }
         cost = 0.5 * u_star.u^2; }",
    );
    assert!(!p.qps[0].dynamic);
    assert_eq!(p.nstates(), 0);
    assert_eq!(p.modes.len(), 1);
    assert!(p.final_cost.is_some() && p.horizon.is_none());
}

#[test]
fn objectives_must_be_quadratic() {
    let cases = [
        ("u^3", "in `u`"),
        ("exp(u) + u^2", "in `u`"),
        ("abs(u) + u^2", "in `u`"),
        ("u^2 + 1/u", "in `u`"),
        ("u^2 + a^u", "in `u`"),
        ("u^2 + (if u > 0 then u else 0)", "in `u`"),
    ];
    for (obj, var) in cases {
        let src = format!("model M {{ param a = 1;\n qp q(u) {{ minimize {obj}; }} cost = q.u; }}");
        let want = format!("the objective of qp `q` is not quadratic {var}");
        assert_eq!(errors(&src), [(2, 21, want)], "{obj}");
    }
    // A product of three variables names no single variable.
    assert_eq!(
        errors("model M {\n qp q(u, v, w) { minimize u^2 + v^2 + w^2 + u*v*w; } cost = q.u; }"),
        [(
            2,
            27,
            "the objective of qp `q` is not quadratic in its variables".to_string()
        )]
    );
}

#[test]
fn objectives_must_be_strictly_convex_where_constants_decide() {
    assert_eq!(
        errors("model M {\n qp q(u, v) { minimize u^2 + v; } cost = q.u; }"),
        [(
            2,
            24,
            "the objective of qp `q` has no quadratic term in `v`, so it is not strictly convex"
                .to_string()
        )]
    );
    assert_eq!(
        errors("model M {\n qp q(u) { minimize -u^2; } cost = q.u; }"),
        [(
            2,
            21,
            "the objective of qp `q` is not strictly convex: ∂²/∂u² is -2, not positive"
                .to_string()
        )]
    );
    assert_eq!(
        errors("model M {\n qp q(u, v) { minimize u^2 + 2*u*v + v^2; } cost = q.u; }"),
        [(2, 24, "the objective of qp `q` is not strictly convex in (`u`, `v`): its Hessian has a non-positive 2×2 minor".to_string())]
    );
    // A coefficient that depends on a param is the solver's to check at run time.
    assert!(
        errors("model M { param a = -1;\n qp q(u) { minimize a*u^2; } cost = q.u; }").is_empty()
    );
}

#[test]
fn constraints_must_be_affine_and_involve_the_variables() {
    assert_eq!(
        errors(
            "model M { param a = 1;\n qp q(u, v) { minimize u^2 + v^2;\n subject to u*v <= 1;\n u^2 >= a;\n sin(u) == 0;\n a <= 2; } cost = q.u; }"
        ),
        [
            (3, 13, "constraint 0 of qp `q` is not affine in its variables".to_string()),
            (4, 2, "constraint 1 of qp `q` is not affine in `u`".to_string()),
            (5, 2, "constraint 2 of qp `q` is not affine in `u`".to_string()),
            (6, 2, "constraint 3 of qp `q` involves none of its variables".to_string()),
        ]
    );
}
