//! The qp and stateless-model rules, each error at its place.

use crate::testing::{expect_check, expect_check_section};

/// The tables of cases of the tests below (the format: [`crate::testing::cases`]).
const ERRORS: &str = include_str!("errors.txt");

#[test]
fn the_spec_example_and_its_variants_are_clean() {
    expect_check_section(ERRORS, "the_spec_example_and_its_variants_are_clean");
}

#[test]
fn qp_declarations() {
    expect_check_section(ERRORS, "qp_declarations");
}

#[test]
fn references_to_solutions() {
    expect_check_section(ERRORS, "references_to_solutions");
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
    expect_check_section(ERRORS, "static_cost_terms_read_only_params_and_static_qps");
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
