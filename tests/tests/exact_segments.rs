//! Segments of a constant flow (a mode whose flow is a function of θ alone) are taken in one
//! exact step each ([`mvad::integrate::Scheme::Exact`]): the sawtooth against its closed form
//! through both doors, with one step per segment; flows that read the state or t are not
//! constant.

use approx::assert_relative_eq;
use mvad::interp::InterpretedModel;
use mvad::runtime::solution::{GradientMode, Options};
use mvad::runtime::solve::solve;
use mvad::{HybridModel, ModelAlloc};
use nalgebra::{DefaultAllocator, OVector};

mvad::hybrid!(include "tests/sawtooth.hyb");

/// C = x(T) + Σ_k t_k with t_k = k·h/a, k = 1..K, K = ⌊aT/h⌋, x(T) = aT − Kh, and
/// (dC/da, dC/dh) (K is locally constant).
fn closed_form(a: f64, h: f64, t_end: f64) -> (f64, [f64; 2], usize) {
    let k = (a * t_end / h).floor();
    let tri = k * (k + 1.0) / 2.0;
    let c = a * t_end - k * h + h / a * tri;
    (c, [t_end - h / (a * a) * tri, -k + tri / a], k as usize)
}

fn check<M: HybridModel>(m: &M, name: &str)
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    assert!(m.flow_is_constant(0), "{name}: ẋ = a is constant");
    assert!(m.guard_is_affine(0), "{name}: x − h is affine");
    let p =
        OVector::<f64, M::P>::from_iterator_generic(m.nparams(), nalgebra::Const::<1>, [1.3, 2.0]);
    // Loose tolerances: an exact step has no error to control.
    let opts = Options {
        rtol: 1e-3,
        atol: 1e-3,
        ..Options::default()
    };
    let sol = solve(m, &p, &opts).expect("runs");
    let (c, g, k) = closed_form(1.3, 2.0, 10.0);
    assert_eq!(sol.events.len(), k, "{name}");
    assert_relative_eq!(sol.cost, c, max_relative = 1e-14);
    for (i, &gi) in g.iter().enumerate() {
        assert_relative_eq!(sol.gradient[i], gi, max_relative = 1e-13);
    }
    for (j, e) in sol.events.iter().enumerate() {
        assert_relative_eq!(e.t, (j + 1) as f64 * 2.0 / 1.3, max_relative = 1e-15);
    }
    // One step per segment: K events cut K + 1 segments.
    assert_eq!(sol.stats.steps, k + 1, "{name}: {:?}", sol.stats);
    assert_eq!(sol.stats.rejected_steps, 0, "{name}");
    // Adjoint mode steps the same exact segments backwards and adds g += −h λᵀf_θ over
    // each (the quadrature of a closed exact step).
    let adjoint = Options {
        gradient_mode: GradientMode::Adjoint,
        ..opts
    };
    let sol = solve(m, &p, &adjoint).expect("runs");
    for (i, &gi) in g.iter().enumerate() {
        assert_relative_eq!(sol.gradient[i], gi, max_relative = 1e-13);
    }
}

mvad_tests::test_both_doors!(
    a_constant_flow_takes_one_exact_step_per_segment_through_both_doors: check,
    Sawtooth::new(),
    "sawtooth.hyb"
);

#[test]
fn guards_that_are_not_affine_in_the_state_and_t_are_not_flagged() {
    for (guard, affine) in [
        ("x >= h", true),
        ("2 * x + t >= h * h", true),
        ("h * x >= 1", true),
        ("x * x >= h", false),
        ("x >= t * t", false),
        ("sin(x) >= 0.5", false),
    ] {
        let src = format!(
            "model M {{ param h = 2; state x = 0; flow {{ der(x) = 1; }} \
             event e when {guard} {{ x = 0; }} horizon 1; }}"
        );
        let m = InterpretedModel::from_source(&src).expect("loads");
        assert_eq!(m.guard_is_affine(0), affine, "{guard}");
    }
}

#[test]
fn flows_that_read_the_state_or_t_are_not_constant() {
    for (src, constant) in [
        (
            "model M { state x = 1; flow { der(x) = -x; } horizon 1; }",
            false,
        ),
        (
            "model M { state x = 1; flow { der(x) = t; } horizon 1; }",
            false,
        ),
        (
            "model M { param k = 2; state x = 1; flow { der(x) = k * k; } horizon 1; }",
            true,
        ),
        (
            "model M { state x = 1; flow { der(x) = if x > 0 then 1 else 2; } horizon 1; }",
            false,
        ),
    ] {
        let m = InterpretedModel::from_source(src).expect("loads");
        assert_eq!(m.flow_is_constant(0), constant, "{src}");
    }
}
