//! The qp and stateless-model rules, each error at its place.

use crate::testing::{expect_check, expect_check_each};

const KINK: &str = "model QpKink { param theta = 0.5;
 qp u_star(u) { minimize 0.5 * u^2 - theta * u; subject to u >= 0; }
 observe u = u_star.u; cost = 0.5 * u_star.u^2; }";

#[test]
fn the_spec_example_and_its_variants_are_clean() {
    expect_check_each(&[
        (KINK, &[]),
        // `subject to` may be repeated; several variables; equalities; a dynamic qp in a flow,
        // an observable and a final cost; a static qp in a static term next to a state's terms.
        (
            "model M { param a = 1; state x = 1;
         qp q(u, v) { minimize u^2 + v^2 - x*u; subject to u + v == a; subject to u <= 1; v >= -1; }
         qp s(w) { minimize w^2 - a*w; }
         flow { der(x) = -q.u; }
         observe y = q.v + s.w;
         cost = integral(x^2) + final(q.u) + 2 * s.w^2;
         horizon 1; }",
            &[],
        ),
    ]);
}

#[test]
fn qp_declarations() {
    expect_check_each(&[
        (
            "model M { param a = 1;\n qp q(u, u) { minimize u^2; } cost = q.u; }",
            &[(2, 10, "variable `u` is declared twice in qp `q`")],
        ),
        (
            "model M { param a = 1;\n qp q(u) { minimize u^2; subject to u < a; } cost = q.u; }",
            &[(2, 39, "strict inequality `<` in a constraint of qp `q`")],
        ),
        (
            "model M { param a = 1;\n qp q(sin) { minimize sin^2; } cost = a; }",
            &[(2, 7, "reserved name `sin` used as an identifier")],
        ),
        (
            "model M { param q = 1;\n qp q(u) { minimize u^2; } cost = q; }",
            &[(2, 5, "duplicate declaration of `q`")],
        ),
    ]);
}

#[test]
fn references_to_solutions() {
    expect_check_each(&[
        (
            "model M { param a = 1; qp q(u) { minimize u^2 - a*u; }\n cost = p.u + q.w + a.u; }",
            &[
                (2, 9, "unknown qp `p`"),
                (2, 17, "qp `q` has no variable `w`"),
                (2, 21, "param `a` is not a qp: `a.u` names nothing"),
            ],
        ),
        (
            "model M { param a = 1; qp q(u) { minimize u^2 - a*u; }\n cost = q; }",
            &[(2, 9, "qp `q` is not a value")],
        ),
        (
            "model M { param a = 1; qp q(u) { minimize u^2 - a*u; }\n observe y = u; }",
            &[(2, 14, "undefined name `u`")],
        ),
        (
            "model M { param a = 1; qp q(u) { minimize u^2 - a*u; }\n const c = q.u; param b = q.u; cost = a; }",
            &[
                (2, 12, "const `c` cannot depend on the solution of qp `q`"),
                (2, 27, "the default value of param `b` cannot depend on the solution of qp `q`"),
            ],
        ),
    ]);
}

#[test]
fn qp_data_scope() {
    expect_check(
        "model M { param a = 1; state x = 1; flow { der(x) = 0; } observe o = x;
         qp p(w) { minimize w^2; }\n qp q(u) { minimize u^2 - o*u - p.w*u; } cost = final(q.u); horizon 1; }",
        &[
            (3, 27, "the data of qp `q` cannot depend on observable `o`"),
            (3, 33, "the data of qp `q` cannot use the solution of qp `p`"),
        ],
    );
}

#[test]
fn static_cost_terms_read_only_params_and_static_qps() {
    // `cost = h;` used to be a syntax error; it is a static term now, refused here.
    expect_check_each(&[
        ("model M { state h = 0; flow { der(h) = 1; } cost = h; }", &[(1, 52, "a static cost term cannot depend on state `h`")]),
        ("model M { cost = h; }", &[
            (1, 7, "model `M` has no states"),
            (1, 7, "model `M` has no `flow` block and no `mode`"),
            (1, 18, "undefined name `h`"),
        ]),
        ("model M { state x = 1; flow { der(x) = -x; }
         qp q(u) { minimize u^2 - x*u; }\n cost = 2 * q.u + t; horizon 1; }", &[
            (3, 13, "a static cost term cannot use the solution of qp `q`, which depends on states or `t`"),
            (3, 19, "a static cost term cannot depend on the time `t`"),
        ]),
    ]);
}

#[test]
fn stateless_models_have_no_time() {
    expect_check(
        "model M { param a = 1; qp q(u) { minimize u^2 - a*u; }
 flow { }\n event e when a >= 0;\n horizon 1;\n observe y = q.u * t;\n cost = integral(a) + final(q.u) + q.u; }",
        &[
            (2, 2, "a model without states cannot have a `flow` block"),
            (3, 2, "a model without states cannot have events"),
            (4, 2, "a model without states cannot have a `horizon`"),
            (5, 20, "a model without states has no time `t`"),
            (6, 9, "a model without states cannot have `integral` cost terms"),
            (6, 23, "a model without states cannot have `final` cost terms"),
        ],
    );
}
