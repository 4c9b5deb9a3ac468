//! Adjoint mode through both doors: every bundled model (`models/*.hyb`, loaded, and the
//! `hybrid!`-compiled types of the `models` crate) and a model using every construct
//! (`every_construct.hyb`: two modes, parameter- and time-dependent guards and resets, a
//! top-level event, kinks of abs/min/max/sign/if in flows and ℓ, a param-dependent initial
//! state and horizon, integral, event and final costs), each under every method it runs
//! with, against forward mode at rtol 1e-12: agreement to 1e-10 of the gradient's scale. The
//! Zeno ball falls back to forward mode and says so. qp layers: qps in flows (the saturating
//! cart, two coupled controls) swept exactly, and a qp at a kink at T whose one-sided
//! gradients come from two sweeps (against forward mode and the closed form).

use mvad::interp::InterpretedModel;
use mvad::{solve, DiagnosticKind, GradientMode, HybridModel, Method, ModelAlloc, Options};
use mvad_tests::{model_files, model_source};
use nalgebra::{DefaultAllocator, OVector};

mvad::hybrid!(include "tests/every_construct.hyb");

/// The every-construct model's source, for the loader.
const EVERY: &str = include_str!("every_construct.hyb");

/// [`mvad_tests::tight`] (rtol 1e-12, atol 1e-14), in `mode` under `method`.
fn fine(method: Method, mode: GradientMode) -> Options {
    Options {
        method,
        gradient_mode: mode,
        ..mvad_tests::tight()
    }
}

/// max_j |a_j − f_j| / max(max_j |f_j|, 1e-8).
fn rel_diff(a: &[f64], f: &[f64]) -> f64 {
    let scale = f.iter().fold(1e-8f64, |m, v| m.max(v.abs()));
    a.iter()
        .zip(f)
        .map(|(x, y)| (x - y).abs() / scale)
        .fold(0.0, f64::max)
}

/// Forward and adjoint at θ under `method`: the relative difference of the gradients, and
/// whether the adjoint ran (false: it fell back to forward mode at an accumulation).
fn compare<M: HybridModel>(m: &M, p: &OVector<f64, M::P>, method: Method, what: &str) -> (f64, bool)
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let f = solve(m, p, &fine(method, GradientMode::Forward)).expect(what);
    let a = solve(m, p, &fine(method, GradientMode::Adjoint)).expect(what);
    assert!(
        (a.cost - f.cost).abs() <= 1e-11 * f.cost.abs().max(1e-12),
        "{what}: cost {} vs {}",
        a.cost,
        f.cost
    );
    assert_eq!(a.events.len(), f.events.len(), "{what}: events");
    let ran = a.stats.mode == GradientMode::Adjoint;
    if !ran {
        let z = a.diagnostic(DiagnosticKind::Zeno);
        assert!(
            z.is_some_and(|d| d.message.contains("forward mode")),
            "{what}: fell back without saying so: {:?}",
            a.diagnostics
        );
    }
    let d = rel_diff(&a.gradient, &f.gradient);
    assert!(
        d <= 1e-10,
        "{what}: adjoint {:?} forward {:?} ({d:.1e})",
        a.gradient,
        f.gradient
    );
    (d, ran)
}

/// The methods a model runs with at rtol 1e-12 (the stiff relay: the implicit ones).
fn methods(name: &str) -> &'static [Method] {
    if name.starts_with("stiff") {
        &[Method::Auto, Method::Rosenbrock]
    } else {
        &Method::ALL
    }
}

#[test]
fn bundled_models_loaded_adjoint_matches_forward() {
    let files = model_files();
    assert!(files.len() >= 6, "{files:?}");
    let mut swept = 0;
    for (name, src) in files {
        let m = InterpretedModel::from_source(&src).expect(&name);
        let p = m.default_params();
        for &method in methods(&name) {
            let what = format!("{name} (loaded) {method:?}");
            let (d, ran) = compare(&m, &p, method, &what);
            println!(
                "{what}: {d:.1e}{}",
                if ran { "" } else { " (forward fallback)" }
            );
            swept += usize::from(ran);
            assert_eq!(ran, !name.starts_with("zeno"), "{what}");
        }
    }
    // Four methods on eight models (two with qps, the two queues without their tables, which
    // `tests/time_events.rs` sweeps with them), the implicit two on the stiff relay; none on
    // the Zeno ball.
    assert_eq!(swept, 8 * 4 + 2);
}

/// [`compare`] on each compiled model `models::MODULE::TYPE` at its defaults under `method`,
/// named "MODULE (compiled)".
macro_rules! compare_compiled {
    ($method:expr; $($module:ident::$ty:ident),* $(,)?) => {
        $(
            let m = models::$module::$ty::new();
            let what = concat!(stringify!($module), " (compiled)");
            compare(&m, &m.default_params(), $method, what);
        )*
    };
}

#[test]
fn bundled_models_compiled_adjoint_matches_forward() {
    for method in Method::ALL {
        compare_compiled!(method;
            bouncing_ball::BouncingBall,
            ceiling::Ceiling,
            e2_sweep::E2Sweep,
            thermostat::Thermostat,
            zeno_ball::ZenoBall,
            qp_cart::QpCart,
            qp_kink::QpKink,
        );
    }
    for method in [Method::Auto, Method::Rosenbrock] {
        compare_compiled!(method; stiff_relay::StiffRelay);
    }
}

/// The every-construct model through both doors, at its defaults and at shifted params;
/// the two doors' adjoint gradients agree with each other too.
#[test]
fn every_construct_model_both_doors() {
    let loaded = InterpretedModel::from_source(EVERY).expect("every_construct.hyb");
    let compiled = Every::new();
    let base = compiled.default_params();
    for shift in [[0.0; 6], [0.05, -0.02, 0.1, 0.03, -0.05, 0.04]] {
        let pc = base + OVector::<f64, nalgebra::Const<6>>::from(shift);
        let pl = nalgebra::DVector::from_column_slice(pc.as_slice());
        for method in Method::ALL {
            let what = format!("every construct {shift:?} {method:?}");
            let (dc, _) = compare(&compiled, &pc, method, &format!("{what} compiled"));
            let (dl, _) = compare(&loaded, &pl, method, &format!("{what} loaded"));
            println!("{what}: compiled {dc:.1e}, loaded {dl:.1e}");
            let o = fine(method, GradientMode::Adjoint);
            let a = solve(&compiled, &pc, &o).expect("compiled");
            let b = solve(&loaded, &pl, &o).expect("loaded");
            // Both events and their modes, the tick, and the kinks crossed.
            let names: Vec<usize> = a.events.iter().map(|e| e.event).collect();
            assert!((0..3).all(|k| names.contains(&k)), "{what}: {names:?}");
            assert!(
                a.stats.switch_crossings >= 5,
                "{what}: {}",
                a.stats.switch_crossings
            );
            assert!(rel_diff(&a.gradient, &b.gradient) <= 1e-12, "{what}: doors");
        }
    }
}

/// qps in flows swept exactly: the saturating cart (three active-set changes and a wall
/// impact) and two controls with a coupled constraint and an equality, loaded and compiled,
/// adjoint against forward at rtol 1e-12 (to 1e-10, via `compare`) and against central
/// differences (to 1e-6 at the best of three steps).
#[test]
fn qps_in_flows_adjoint_matches_forward_and_fd() {
    let cart = InterpretedModel::from_source(&model_source("qp_cart.hyb")).expect("qp_cart");
    let two = InterpretedModel::from_source(include_str!("two_controls.hyb")).expect("two");
    let compiled = models::qp_cart::QpCart::new();
    for method in Method::ALL {
        let (dc, _) = compare(
            &compiled,
            &compiled.default_params(),
            method,
            "cart compiled",
        );
        let (dl, _) = compare(&cart, &cart.default_params(), method, "cart loaded");
        let (dt, _) = compare(&two, &two.default_params(), method, "two controls");
        println!("qp {method:?}: cart compiled {dc:.1e}, loaded {dl:.1e}, two controls {dt:.1e}");
    }
    for m in [&cart, &two] {
        let p = m.default_params();
        let a = solve(m, &p, &fine(Method::Auto, GradientMode::Adjoint)).expect("adjoint");
        assert_eq!(a.stats.mode, GradientMode::Adjoint);
        assert!(a.stats.switch_crossings >= 1, "{:?}", a.stats);
        for (i, &g) in a.gradient.iter().enumerate() {
            let err = [1e-4, 1e-5, 1e-6]
                .iter()
                .map(|&h| {
                    let fd =
                        mvad::fd_gradient(m, &p, &fine(Method::Auto, GradientMode::Forward), i, h)
                            .expect("fd");
                    (fd - g).abs() / g.abs().max(1.0)
                })
                .fold(f64::INFINITY, f64::min);
            println!(
                "{} param {i}: adjoint {g:.12e}, FD rel err {err:.1e}",
                m.info().name
            );
            assert!(err <= 1e-6, "{} param {i}: FD error {err:e}", m.info().name);
        }
    }
}

/// A qp read by the final cost at a kink at T: x(0) = θ, ẋ = −a x, u* = argmin ½u² − x u
/// s.t. u ≥ 0 = max(0, x), C = ∫x² + u*(x(T)). At θ = 0, x ≡ 0 and the constraint is weakly
/// active at T: dC/dθ = e^{−aT} from the right, 0 from the left (dC/da = 0 on both sides).
/// At the kink adjoint mode hands the run over to forward mode (each parameter's side of the
/// final cost's kink follows its own direction S_j(T), which a sweep does not have) and gives
/// both one-sided gradients as forward mode does. Away from the kink (θ = 0.3) the run stays
/// adjoint, there is no left gradient and dC/dθ = 2θ(1 − e^{−2aT})/(2a) + e^{−aT}.
#[test]
fn qp_kink_at_t_gives_both_one_sided_gradients_in_adjoint_mode() {
    let src = "model KinkAtT {
        param theta = 0.0; param a = 0.5;
        state x = theta;
        qp proj(u) { minimize 0.5 * u^2 - x * u; subject to u >= 0; }
        flow { der(x) = -a * x; }
        cost = integral(x^2) + final(proj.u);
        horizon 2;
    }";
    let m = InterpretedModel::from_source(src).expect("loads");
    let (a, t) = (0.5f64, 2.0f64);
    for theta in [0.0, 0.3] {
        let p = nalgebra::DVector::from_vec(vec![theta, a]);
        let f = solve(&m, &p, &fine(Method::Auto, GradientMode::Forward)).expect("forward");
        let s = solve(&m, &p, &fine(Method::Auto, GradientMode::Adjoint)).expect("adjoint");
        let mode = match theta == 0.0 {
            true => GradientMode::Forward,
            false => GradientMode::Adjoint,
        };
        assert_eq!(s.stats.mode, mode);
        let kink = s.diagnostic(DiagnosticKind::Kink).is_some();
        assert_eq!(kink, theta == 0.0, "{:?}", s.diagnostics);
        let right = 2.0 * theta * (1.0 - (-2.0 * a * t).exp()) / (2.0 * a) + (-a * t).exp();
        println!(
            "θ = {theta}: adjoint {:?} left {:?}; forward {:?} left {:?}; closed form dC/dθ {right}",
            s.gradient, s.gradient_left, f.gradient, f.gradient_left
        );
        assert!((s.gradient[0] - right).abs() <= 1e-10, "{:?}", s.gradient);
        assert!(rel_diff(&s.gradient, &f.gradient) <= 1e-10);
        if theta == 0.0 {
            let left = s.gradient_left.as_deref().expect("left gradient");
            assert!(left[0].abs() <= 1e-12 && left[1].abs() <= 1e-12, "{left:?}");
            let fl = f.gradient_left.as_deref().expect("forward left");
            assert!(rel_diff(left, fl) <= 1e-10, "{left:?} vs {fl:?}");
        } else {
            assert_eq!(s.gradient_left, None);
        }
    }
}
