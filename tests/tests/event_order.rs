//! A time event and a state event closer together than the state event's location error
//! (`solve/order.rs`): their order is decided by the numerics, and the run says so with
//! `simultaneous_events`; away from the coincidence it says nothing and the numbers are the
//! closed form's. Through both doors, in both gradient modes.
//!
//! Before, `coincide.hyb` at tau = fl(ln 2) fired `tk` 1.4e-11 before `s` at the default
//! tolerances, and at tau in (ln 2, located crossing), where the true order is `s` first
//! (C = 7.61), printed C = 9.92 with no diagnostic (probe4 finding 4).

use mvad::interp::InterpretedModel;
use mvad::runtime::solution::{DiagnosticKind, GradientMode, Options, Solution};
use mvad::{HybridModel, ModelAlloc};
use nalgebra::DefaultAllocator;
use std::f64::consts::LN_2;

mvad::hybrid!(include "tests/coincide.hyb");
mvad::hybrid!(include "tests/thermo_sampled.hyb");

fn loaded(file: &str) -> InterpretedModel {
    mvad_tests::loaded_test_model(file)
}

/// Solves the model at `p` through both doors in both modes (rtol, atol as given) and runs
/// `check` on each solution with a label.
fn both_doors_and_modes<M: HybridModel>(
    compiled: &M,
    file: &str,
    p: &[f64],
    tol: (f64, f64),
    check: impl Fn(&Solution, &str),
) where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let interp = loaded(file);
    for mode in [GradientMode::Forward, GradientMode::Adjoint] {
        let opts = Options {
            rtol: tol.0,
            atol: tol.1,
            gradient_mode: mode,
            ..Options::default()
        };
        let sol = mvad_tests::solve_at(compiled, p, &opts).expect("runs");
        check(&sol, &format!("compiled {mode:?} {p:?}"));
        let sol = run_loaded(&interp, p, &opts);
        check(&sol, &format!("loaded {mode:?} {p:?}"));
    }
}

/// [`mvad_tests::solve_at`] on the loaded door (outside the generic caller, whose bound on
/// `M` would hide `InterpretedModel`'s).
fn run_loaded(m: &InterpretedModel, p: &[f64], opts: &Options) -> Solution {
    mvad_tests::solve_at(m, p, opts).expect("runs")
}

fn simultaneous(sol: &Solution) -> bool {
    sol.diagnostics
        .iter()
        .any(|d| d.kind == DiagnosticKind::SimultaneousEvents)
}

/// |got − want| ≤ rel·max(|want|, 1).
#[track_caller]
fn close(got: f64, want: f64, rel: f64, what: &str) {
    assert!(
        (got - want).abs() <= rel * want.abs().max(1.0),
        "{what}: {got:e} vs {want:e} (rel {rel:e})"
    );
}

/// `Coincide` (x = 2(1 − e^{−at}), crossing c at t_s = ln(2/(2 − c))/a; y doubles at t_s and
/// gains 1 at tau; T = 2): tk first, C = 4 + 4T − tau − 2t_s; s first, C = 3 + 3T − t_s − tau;
/// with dt_s/da = −t_s/a, dt_s/dc = 1/(a(2 − c)). Returns C and dC/d(a, c, tau).
fn coincide_closed_form(a: f64, c: f64, tau: f64) -> (f64, [f64; 3]) {
    let t_end = 2.0;
    let ts = (2.0 / (2.0 - c)).ln() / a;
    let (dts_da, dts_dc) = (-ts / a, 1.0 / (a * (2.0 - c)));
    if tau < ts {
        (
            4.0 + 4.0 * t_end - tau - 2.0 * ts,
            [-2.0 * dts_da, -2.0 * dts_dc, -1.0],
        )
    } else {
        (3.0 + 3.0 * t_end - ts - tau, [-dts_da, -dts_dc, -1.0])
    }
}

#[test]
fn the_coincide_closed_form_agrees_with_central_differences() {
    for tau in [LN_2 - 1e-3, LN_2 + 1e-3] {
        let p = [1.0, 1.0, tau];
        let (_, g) = coincide_closed_form(p[0], p[1], p[2]);
        for i in 0..3 {
            let h = 1e-6;
            let (mut hi, mut lo) = (p, p);
            hi[i] += h;
            lo[i] -= h;
            let fd = (coincide_closed_form(hi[0], hi[1], hi[2]).0
                - coincide_closed_form(lo[0], lo[1], lo[2]).0)
                / (2.0 * h);
            close(fd, g[i], 1e-8, &format!("tau {tau} θ_{i}"));
        }
    }
}

/// At the default tolerances (rtol 1e-8: the state event's window δg/|ġ| ≈ 1e-8 in forward
/// mode, 1e-10 in adjoint mode, whose primal run is 100× tighter) a time event at ln 2, or
/// 5e-11 either side of it (before or after the located crossing: checks (a) and (b)), is
/// reported; 1e-3 away it is not, and C and dC/dθ are the closed form's.
#[test]
fn a_time_event_within_a_state_events_location_error_is_reported() {
    let tol = (1e-8, 1e-10);
    for tau in [LN_2, LN_2.next_up(), LN_2 - 5e-11, LN_2 + 5e-11] {
        coincide_at(tau, tol, |sol, how| {
            assert!(simultaneous(sol), "{how}: {:?}", sol.diagnostics);
            let d = sol
                .diagnostics
                .iter()
                .find(|d| d.kind == DiagnosticKind::SimultaneousEvents)
                .expect("reported");
            assert!(
                d.message.contains("`tk`") && d.message.contains("`s`"),
                "{how}: {}",
                d.message
            );
            assert!(d.message.contains("location error"), "{how}: {}", d.message);
            // Either order's C (tau = t_s = ln 2 to 1e-10): tk first 12 − 3 ln 2, s first
            // 9 − 2 ln 2; nothing in between.
            let (c_tk, c_s) = (12.0 - 3.0 * LN_2, 9.0 - 2.0 * LN_2);
            assert!(
                (sol.cost - c_tk).abs() < 1e-6 || (sol.cost - c_s).abs() < 1e-6,
                "{how}: C = {}",
                sol.cost
            );
        });
    }
    coincide_clean_away(tol, 1e-9, Some(1e-7));
}

/// `check` on `coincide.hyb` (a = c = 1) at τ = `tau`, both doors and modes, tolerances `tol`.
fn coincide_at(tau: f64, tol: (f64, f64), check: impl Fn(&Solution, &str)) {
    both_doors_and_modes(
        &Coincide::new(),
        "coincide.hyb",
        &[1.0, 1.0, tau],
        tol,
        check,
    );
}

/// `coincide.hyb` at τ = ln 2 ± 1e-3, far outside the location error at tolerances `tol`: no
/// diagnostic, C within `c_rel` of the closed form and, with `g_rel`, dC/dθ within it.
fn coincide_clean_away(tol: (f64, f64), c_rel: f64, g_rel: Option<f64>) {
    for tau in [LN_2 - 1e-3, LN_2 + 1e-3] {
        let (c, g) = coincide_closed_form(1.0, 1.0, tau);
        coincide_at(tau, tol, |sol, how| {
            assert!(sol.diagnostics.is_empty(), "{how}: {:?}", sol.diagnostics);
            close(sol.cost, c, c_rel, &format!("{how}: C"));
            if let Some(rel) = g_rel {
                for (i, &want) in g.iter().enumerate() {
                    close(sol.gradient[i], want, rel, &format!("{how}: dC/dθ_{i}"));
                }
            }
        });
    }
}

/// The same at rtol 1e-10 (windows 1e-10 forward, 1e-12 adjoint): the probe's tolerance, at
/// which tk at fl(ln 2) came 2.7e-13 before the located crossing.
#[test]
fn the_coincidence_is_reported_at_rtol_1e_10() {
    let tol = (1e-10, 1e-12);
    coincide_at(LN_2, tol, |sol, how| {
        assert!(simultaneous(sol), "{how}: {:?}", sol.diagnostics);
    });
    coincide_clean_away(tol, 1e-11, None);
}

/// `check` on `ThermoSampled` at its defaults but `off`, both doors and modes, tolerances
/// `tol`.
fn thermo_at(off: f64, tol: (f64, f64), check: impl Fn(&Solution, &str)) {
    let params = [0.5, 18.0, 22.0, 10.0, 1.0, off];
    both_doors_and_modes(
        &ThermoSampled::new(),
        "thermo_sampled.hyb",
        &params,
        tol,
        check,
    );
}

/// `ThermoSampled` at the defaults except off: t₁ = 2 ln(11/8) the first switch-off (temp
/// reaches hi = 22 with rate 4 there), C = (T − off)·[off < t₁] + temp(T) with
/// temp(T) = 10 + 12 e^{−(T − t₁)/2}, dC/doff = −[off < t₁],
/// dC/dhi = e^{−k(T − t₁)}(1 + k (hi − 10) dt₁/dhi), dt₁/dhi = 1/(k(10 + p/k − hi)).
fn thermo_closed_form(off: f64) -> (f64, f64, f64) {
    let (k, hi, p, t_end) = (0.5, 22.0, 10.0, 1.2);
    let t1 = 2.0 * (11.0f64 / 8.0).ln();
    let e = (-k * (t_end - t1)).exp();
    let temp_t = 10.0 + (hi - 10.0) * e;
    let first = if off < t1 { 1.0 } else { 0.0 };
    let dt1_dhi = 1.0 / (k * (10.0 + p / k - hi));
    let dhi = e * (1.0 + k * (hi - 10.0) * dt1_dhi);
    ((t_end - off) * first + temp_t, -first, dhi)
}

/// An `every` sampler at the thermostat's switch-off on a stepped segment (rtol 1e-6: the
/// window δg/|ġ| ≈ 22·10⁻⁶/4 = 5.5e-6 forward, 5.5e-8 adjoint): at t₁ and 1e-8 either side
/// reported; 1e-3 away not, with C and the gradient the closed form's.
#[test]
fn a_sampler_at_a_thermostat_switch_is_reported() {
    let t1 = 2.0 * (11.0f64 / 8.0).ln();
    let tol = (1e-6, 1e-8);
    for off in [t1, t1 - 1e-8, t1 + 1e-8] {
        thermo_at(off, tol, |sol, how| {
            assert!(simultaneous(sol), "{how}: {:?}", sol.diagnostics);
        });
    }
    for off in [t1 - 1e-3, t1 + 1e-3] {
        let (c, d_off, d_hi) = thermo_closed_form(off);
        thermo_at(off, tol, |sol, how| {
            assert!(sol.diagnostics.is_empty(), "{how}: {:?}", sol.diagnostics);
            close(sol.cost, c, 1e-6, &format!("{how}: C"));
            close(sol.gradient[5], d_off, 1e-9, &format!("{how}: dC/doff"));
            close(sol.gradient[2], d_hi, 1e-5, &format!("{how}: dC/dhi"));
        });
    }
}

/// A sampler armed only in the mode the switch-off enters (`cooling`): 1e-8 after the
/// located switch it fires there, but had the switch come after it (within the location
/// error) its occurrence would have passed in `heating`, which does not arm it. Reported
/// from the switch's instant (check (b) over the target mode's time events); 1e-3 after it,
/// not, with z = h = 0 held from the sample: C = temp(T).
#[test]
fn a_sampler_armed_only_in_the_target_mode_is_reported() {
    let src = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/thermo_sampled.hyb"
    ))
    .expect("reads")
    .replace("    event samp every per from off { z = h; }\n", "")
    .replace(
        "event switch_on when temp <= lo -> heating { h = 1; }",
        "event switch_on when temp <= lo -> heating { h = 1; }\n        \
         event samp every per from off { z = h + 2; }",
    );
    assert!(src.contains("z = h + 2"), "{src}");
    let m = InterpretedModel::from_source(&src).expect("valid");
    let t1 = 2.0 * (11.0f64 / 8.0).ln();
    for mode in [GradientMode::Forward, GradientMode::Adjoint] {
        let opts = Options {
            rtol: 1e-6,
            atol: 1e-8,
            gradient_mode: mode,
            ..Options::default()
        };
        let near = run_loaded(&m, &[0.5, 18.0, 22.0, 10.0, 1.0, t1 + 1e-8], &opts);
        assert!(simultaneous(&near), "{mode:?}: {:?}", near.diagnostics);
        let off = t1 + 1e-3;
        let far = run_loaded(&m, &[0.5, 18.0, 22.0, 10.0, 1.0, off], &opts);
        assert!(
            far.diagnostics.is_empty(),
            "{mode:?}: {:?}",
            far.diagnostics
        );
        let (temp_t, _, _) = thermo_closed_form(t1 + 1.0);
        close(
            far.cost,
            2.0 * (1.2 - off) + temp_t,
            1e-6,
            &format!("{mode:?}: C"),
        );
    }
}
