//! Kinks in observables are switching surfaces (the spec's "Non-smooth functions"): the run
//! watches them (steps end there, `stats.switch_crossings` counts them), the measure's
//! density takes each step's frozen branch, and an observable that jumps at a crossing
//! (`sign`, `if`) gets the atom −J t' there. Both doors, closed forms; samples and their
//! vector–Jacobian products in both gradient modes.

use mvad::runtime::solution::{GradientMode, Options, Solution};
use mvad::runtime::vjp::{vjp, Cotangents};
use mvad::{measure, sample, HybridModel, ModelAlloc};
use mvad_tests::{assert_near, precise};
use nalgebra::{Const, DefaultAllocator, OVector};

mvad::hybrid!(include "tests/obs_sign.hyb");
mvad::hybrid!(include "tests/obs_max_cost.hyb");
mvad::hybrid!(include "tests/obs_kink_only.hyb");

/// [`mvad_tests::precise`], recording.
fn tight(mode: GradientMode) -> Options {
    Options {
        record: true,
        ..precise(mode)
    }
}

fn params<M: HybridModel>(m: &M) -> OVector<f64, M::P>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    OVector::<f64, M::P>::from_iterator_generic(
        m.nparams(),
        Const::<1>,
        m.info().param_defaults.iter().copied(),
    )
}

fn run<M: HybridModel>(m: &M) -> Solution
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    mvad::solve(m, &params(m), &tight(GradientMode::Forward)).expect("runs")
}

/// m01: y = sign(x − c) and z = if x > c then x else 0 with x = t: density 0, one atom at
/// t = c of −2 (y) and −c (z).
fn check_sign<M: HybridModel>(m: &M, door: &str)
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let c = 0.7;
    let sol = run(m);
    assert_eq!(
        sol.stats.switch_crossings, 1,
        "{door}: the kink x = c is watched"
    );
    let p = params(m);
    for (name, want) in [("y", -2.0), ("z", -c)] {
        let what = format!("{door}, {name}");
        let obs = m.info().observable_index(name).unwrap();
        let mu = measure(m, &p, &sol, obs).unwrap();
        assert_eq!(mu.atoms.len(), 1, "{what}: {:?}", mu.atoms);
        let (t, alpha) = &mu.atoms[0];
        assert_near(*t, c, 1e-12, format_args!("{what}: atom time"));
        assert_near(alpha[0], want, 1e-8, format_args!("{what}: atom"));
        assert_near(mu.pair_density(|_| 1.0)[0], 0.0, 1e-8, &what);
        assert_near(mu.pair(|_| 1.0)[0], want, 1e-8, &what);
        for i in 0..=40 {
            let t = 2.0 * i as f64 / 40.0;
            assert_near(
                mu.density(t)[0],
                0.0,
                1e-9,
                format_args!("{what}: density at {t}"),
            );
        }
    }
    // A sample at the crossing itself is the left limit (y = −1, z = w = 0); after it y = 1.
    let t_c = sol.trajectory.as_ref().unwrap().crossings[0].t;
    let s = sample(m, &p, &sol, &[t_c, 1.5]).unwrap();
    assert_eq!(s.observables[..4], [-1.0, 0.0, 0.0, 1.0], "{door}");
    assert_near(s.observables[4], 1.5, 1e-12, door);
    assert_near(s.observables[5], c * 1.5, 1e-12, door);
}

mvad_tests::test_both_doors!(
    a_jumping_observable_has_an_atom_at_its_switch_crossing: check_sign,
    ObsSign::new(),
    "obs_sign.hyb"
);

/// q21: u = max(−x, −a) shares the flow's kink. ⟨μ_u, 1⟩ = dC/da (C = ∫u) in closed form and
/// as `grad` has it, and du/da = −1 exactly between the kick and the switch.
fn check_max_cost<M: HybridModel>(m: &M, door: &str)
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let x1 = 0.5 * (-1.0f64).exp() + 2.0;
    let t_s = 1.0 + (x1 - 1.0);
    let want = (-(4.0 - x1)).exp() * (1.0 - x1);
    let sol = run(m);
    assert_eq!(sol.stats.switch_crossings, 1, "{door}");
    assert_near(sol.gradient[0], want, 1e-8, format_args!("{door}: grad"));
    let p = params(m);
    let mu = measure(m, &p, &sol, m.info().observable_index("u").unwrap()).unwrap();
    let total = mu.pair(|_| 1.0);
    assert_near(
        total[0],
        sol.gradient[0],
        1e-7,
        format_args!("{door}: ⟨μ_u, 1⟩ vs grad"),
    );
    assert_near(total[0], want, 1e-7, format_args!("{door}: ⟨μ_u, 1⟩"));
    // u is continuous across the kink (an atom of rounding size at most), and the kick's
    // atom has t' = 0 in a.
    assert!(
        mu.atoms.iter().all(|(_, a)| a[0].abs() < 1e-13),
        "{door}: {:?}",
        mu.atoms
    );
    // The density on the step that ends at the switch is exactly −1 (it was garbage
    // when the node at the crossing took the other branch).
    let n = 200;
    for i in 0..=n {
        let t = 1.0 + (t_s - 1.0) * i as f64 / n as f64;
        if t > 1.0 && t < t_s {
            let d = mu.density(t)[0];
            assert!((d + 1.0).abs() <= 1e-9, "{door}: du/da at {t} = {d}");
        }
    }
}

mvad_tests::test_both_doors!(
    an_observable_sharing_the_flows_kink_has_an_exact_density: check_max_cost,
    MaxObsCost::new(),
    "obs_max_cost.hyb"
);

/// m05: a kink only in the observable. The run now ends a step at it, so ⟨μ_y, 1⟩ = dC/dθ
/// (C = ∫y) to 1e-8; dC/dc = −(T − t_c) in closed form.
fn check_kink_only<M: HybridModel>(m: &M, door: &str)
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let (c, a) = (0.5f64, 0.3f64);
    let t_c = -(1.0 - a * c).ln() / a;
    let sol = run(m);
    assert_eq!(sol.stats.switch_crossings, 1, "{door}");
    assert_near(
        sol.gradient[0],
        -(3.0 - t_c),
        1e-8,
        format_args!("{door}: dC/dc"),
    );
    let p = params(m);
    let mu = measure(m, &p, &sol, 0).unwrap();
    let total = mu.pair(|_| 1.0);
    for (j, (&got, &want)) in total.iter().zip(&sol.gradient).enumerate() {
        assert_near(got, want, 1e-8, format_args!("{door}: θ{j}"));
    }
    // y is continuous at the kink: its atom is the rounding of the located crossing.
    assert!(
        mu.atoms
            .iter()
            .all(|(_, a)| a.iter().all(|v| v.abs() < 1e-13)),
        "{door}: {:?}",
        mu.atoms
    );
}

mvad_tests::test_both_doors!(
    a_kink_only_in_an_observable_is_watched: check_kink_only,
    ObsKinkOnly::new(),
    "obs_kink_only.hyb"
);

/// Samples of u = max(−x, −a) and y = x t: their VJPs agree between forward and adjoint
/// mode, and with the closed forms du/da = −1 on (1, t_s), 0 before the kick.
fn check_vjp_modes<M: HybridModel>(m: &M, door: &str)
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let p = params(m);
    let times = [0.5, 1.5, 3.0];
    for (k, &t) in times.iter().enumerate() {
        let mut w = vec![0.0; times.len() * 2];
        w[2 * k] = 1.0;
        let cot = Cotangents {
            cost: 0.0,
            times: &times,
            observables: &w,
        };
        let fwd = vjp(m, &p, &tight(GradientMode::Forward), &cot).unwrap();
        let adj = vjp(m, &p, &tight(GradientMode::Adjoint), &cot).unwrap();
        let what = format!("{door}, du({t})/dθ");
        for j in 0..4 {
            assert_near(
                adj.gradient[j],
                fwd.gradient[j],
                1e-7,
                format_args!("{what} θ{j}"),
            );
        }
        assert_near(fwd.observables[2 * k], adj.observables[2 * k], 1e-9, &what);
        match k {
            0 => assert_near(fwd.gradient[0], 0.0, 1e-9, &what),
            1 => assert_near(fwd.gradient[0], -1.0, 1e-9, &what),
            _ => {}
        }
    }
}

mvad_tests::test_both_doors!(
    samples_of_a_kinked_observable_agree_between_modes: check_vjp_modes,
    MaxObsCost::new(),
    "obs_max_cost.hyb"
);

/// A kink in an observable does not change the gradient of the cost: the model without the
/// observable gives the same dC/dθ (the extra watched function only ends a step there).
#[test]
fn an_observable_kink_leaves_the_gradient_alone() {
    let src = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/obs_kink_only.hyb"
    ))
    .unwrap()
    .replace("cost = integral(y);", "cost = integral(x * x);");
    let load = |s: &str| mvad::interp::InterpretedModel::from_source(s).unwrap();
    let with = load(&src);
    let without = load(&src.replace("observe y = max(x - c, 0);", ""));
    let (a, b) = (run(&with), run(&without));
    assert_eq!((a.stats.switch_crossings, b.stats.switch_crossings), (1, 0));
    for j in 0..2 {
        assert_near(a.gradient[j], b.gradient[j], 1e-9, format_args!("θ{j}"));
    }
    assert_near(a.cost, b.cost, 1e-9, "C");
}

/// At the switch crossing itself (the time t_c ≈ c the forward run located it at) a sample
/// is the left limit, in both modes: y = −1, w = 0 and dw/dc = 0 (the right limit would be
/// c² and c). The adjoint's primal run (at tighter tolerances) locates its own t_c, so
/// there this checks only that the sample is not taken from the right of its crossing.
fn check_sample_at_crossing<M: HybridModel>(m: &M, door: &str)
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let p = params(m);
    let c = run(m).trajectory.unwrap().crossings[0].t;
    let (y, w) = (0, 2);
    for mode in [GradientMode::Forward, GradientMode::Adjoint] {
        let what = format!("{door}, {mode:?}");
        let mut cot_w = vec![0.0; 3];
        cot_w[w] = 1.0;
        let cot = Cotangents {
            cost: 0.0,
            times: &[c],
            observables: &cot_w,
        };
        let out = vjp(m, &p, &tight(mode), &cot).unwrap();
        assert_eq!(out.observables[y], -1.0, "{what}: y(c)");
        assert_eq!(out.observables[w], 0.0, "{what}: w(c)");
        assert_near(
            out.gradient[0],
            0.0,
            1e-12,
            format_args!("{what}: dw(c)/dc"),
        );
    }
}

mvad_tests::test_both_doors!(
    a_sample_at_a_switch_crossing_is_the_left_limit: check_sample_at_crossing,
    ObsSign::new(),
    "obs_sign.hyb"
);
