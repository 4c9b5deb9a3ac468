//! Unit tests of the root finder, the maximiser and the scanner.

use super::*;
use approx::assert_relative_eq;

#[test]
fn root_of_a_parabola_to_machine_precision() {
    // v(t) = t² − 2 on [1, 2]: root √2.
    let mut n = 0;
    let r = locate_root(
        |t| {
            n += 1;
            t * t - 2.0
        },
        1.0,
        -1.0,
        2.0,
        2.0,
        false,
    );
    assert!((r - 2f64.sqrt()).abs() <= 4.0 * f64::EPSILON, "{r}");
    assert!(r * r - 2.0 >= 0.0, "returned the triggered side");
    // Superlinear: a handful of evaluations to reach the resolution of t.
    assert!(n <= 10, "{n} evaluations");
}

#[test]
fn root_of_a_flat_function() {
    // v(t) = (t − 0.3)³: a triple root, where secant steps converge only linearly.
    let r = locate_root(|t| (t - 0.3f64).powi(3), 0.0, -0.027, 1.0, 0.343, false);
    assert_relative_eq!(r, 0.3, max_relative = 1e-5);
    let r = locate_root(|t| (t - 0.3f64).powi(3), 0.0, -0.027, 1.0, 0.343, true);
    assert!((r - 0.3).abs() < 1e-5);
}

#[test]
fn golden_section_finds_max() {
    let (t, v) = maximize(|t| -(t - 0.4) * (t - 0.4) + 1e-3, 0.0, 1.0);
    assert!((t - 0.4).abs() < 1e-6);
    assert_relative_eq!(v, 1e-3, max_relative = 1e-6);
}

/// A peak narrower than golden section's final interval (5e-7 of [a, b]) is found by the
/// parabolic refinement: a guard r² − (t − t*)² with r = 3e-7 (an `abs(x − c) <= r` window
/// crossed at unit speed) is positive at the returned point.
#[test]
fn maximize_finds_a_narrow_peak() {
    let peak = 0.371_234_5;
    let (t, v) = maximize(|t| 9e-14 - (t - peak) * (t - peak), 0.0, 1.0);
    assert!(v > 0.0, "max {v} at {t}");
    assert!((t - peak).abs() < 3e-7);
}

/// A dip that crosses zero and comes back between two samples is found; its first root
/// is located.
#[test]
fn scanner_finds_double_crossing_between_samples() {
    // v(t) = 1e-4 − (t − 0.5)²: up at 0.49, down at 0.51, between the samples 0.4 and 0.6.
    let f = |t: f64| 1e-4 - (t - 0.5) * (t - 0.5);
    let g = |t: f64| -1.0 + 0.0 * t;
    let mut sc = Scanner::new(2, 0);
    sc.restart_one(0, f(0.0), None);
    sc.restart_one(1, g(0.0), None);
    let vals = |t: f64, out: &mut [f64]| {
        out[0] = f(t);
        out[1] = g(t);
    };
    sc.scan(
        0.0,
        1.0,
        false,
        |t, _, _, o| vals(t, o),
        |w, t| if w == 0 { f(t) } else { g(t) },
        0.0,
    )
    .unwrap();
    assert_eq!(sc.found.len(), 1);
    assert_relative_eq!(sc.found[0].t, 0.49, max_relative = 1e-12);
}

/// A dip whose peak lies between the last interior sample and t₁ (the samples only see
/// v rise towards t₁) is found on this step: the next one starts past the peak.
#[test]
fn scanner_finds_a_dip_peaking_just_before_the_end_of_the_step() {
    // v rises at every sample (0, 0.2, …, 1); its peak, at 0.95, lies between the last
    // interior sample and t₁ (for any INTERIOR ≥ 1).
    let f = |t: f64| 1e-10 - (t - 0.95) * (t - 0.95);
    let mut sc = Scanner::new(1, 0);
    sc.restart_one(0, f(0.0), None);
    sc.scan(0.0, 1.0, false, |t, _, _, o| o[0] = f(t), |_, t| f(t), 0.0)
        .unwrap();
    assert_eq!(sc.found.len(), 1, "the dip at 0.95 ± 1e-5 is missed");
    assert_relative_eq!(sc.found[0].t, 0.95 - 1e-5, max_relative = 1e-12);
}

/// After firing, a function exactly at zero is disarmed; it re-arms once negative and the
/// next crossing fires.
#[test]
fn disarmed_until_it_leaves_zero() {
    // v(0) = 0, v < 0 on (0, 0.6), crosses up at 0.6.
    let f = |t: f64| t * (t - 0.6);
    let mut sc = Scanner::new(1, 0);
    sc.restart_one(0, f(0.0), Some(0.0));
    assert!(!sc.tracks[0].armed);
    sc.scan(0.0, 1.0, false, |t, _, _, o| o[0] = f(t), |_, t| f(t), 0.0)
        .unwrap();
    assert_eq!(sc.found.len(), 1);
    assert_relative_eq!(sc.found[0].t, 0.6, max_relative = 1e-14);
    // The same function without a crossing after the zero never fires: v = −t.
    let g = |t: f64| -t;
    let mut sc = Scanner::new(1, 0);
    sc.restart_one(0, 0.0, Some(0.0));
    sc.scan(0.0, 1.0, false, |t, _, _, o| o[0] = g(t), |_, t| g(t), 0.0)
        .unwrap();
    assert!(sc.found.is_empty());
    assert!(sc.tracks[0].armed);
    // And one that stays at zero and then goes up never fires either: v = 0 then t − 0.5
    // for t > 0.5 is positive: no negative excursion ⇒ stays disarmed.
    let k = |t: f64| (t - 0.5).max(0.0);
    let mut sc = Scanner::new(1, 0);
    sc.restart_one(0, 0.0, Some(0.0));
    sc.scan(0.0, 1.0, false, |t, _, _, o| o[0] = k(t), |_, t| k(t), 0.0)
        .unwrap();
    assert!(sc.found.is_empty());
    assert!(!sc.tracks[0].armed);
}

/// A whole hop below zero between t₀ and the first sample (0.2) right after the event
/// fired: v = t (t − 0.05) re-arms on (0, 0.05) and fires at 0.05. Only on the first step
/// after the firing; later, or for an event that did not fire, samples decide.
#[test]
fn a_hop_before_the_first_sample_after_firing_is_found() {
    let f = |t: f64| t * (t - 0.05);
    let mut sc = Scanner::new(1, 0);
    sc.restart_one(0, f(0.0), Some(0.0));
    assert!(sc.tracks[0].fresh && !sc.tracks[0].armed);
    sc.scan(0.0, 1.0, false, |t, _, _, o| o[0] = f(t), |_, t| f(t), 0.0)
        .unwrap();
    assert_eq!(sc.found.len(), 1);
    assert_relative_eq!(sc.found[0].t, 0.05, max_relative = 1e-14);
    // A hop that never goes below zero (v = t²) does not fire, and the next step is not
    // searched again.
    let g = |t: f64| t * t;
    let mut sc = Scanner::new(1, 0);
    sc.restart_one(0, 0.0, Some(0.0));
    sc.scan(0.0, 1.0, false, |t, _, _, o| o[0] = g(t), |_, t| g(t), 0.0)
        .unwrap();
    assert!(sc.found.is_empty());
    assert!(!sc.tracks[0].fresh && !sc.tracks[0].armed);
    let mut evals = 0;
    sc.scan(
        1.0,
        2.0,
        false,
        |t, _, _, o| o[0] = f(t - 1.0),
        |_, t| {
            evals += 1;
            f(t - 1.0)
        },
        0.0,
    )
    .unwrap();
    assert!(sc.found.is_empty());
    assert_eq!(evals, 0);
}

#[test]
fn simultaneous_crossings_are_grouped_and_ordered() {
    let fs: [fn(f64) -> f64; 3] = [|t| t - 0.3, |t| t - 0.3 - 1e-15, |t| t - 0.7];
    let mut sc = Scanner::new(3, 0);
    for (w, fw) in fs.iter().enumerate() {
        sc.restart_one(w, fw(0.0), None);
    }
    sc.scan(
        0.0,
        1.0,
        false,
        |t, _, _, o| {
            for (w, fw) in fs.iter().enumerate() {
                o[w] = fw(t);
            }
        },
        |w, t| fs[w](t),
        1e-12,
    )
    .unwrap();
    let ws: Vec<usize> = sc.found.iter().map(|c| c.w).collect();
    assert_eq!(ws, vec![0, 1]);
}

/// On a linear step only the end is evaluated; a line that fired at t₀ and starts below
/// zero re-arms and is found wherever in the step it crosses.
#[test]
fn a_linear_step_evaluates_only_its_end_and_finds_the_crossing() {
    let f = |t: f64| 3.0 * t - 0.3;
    let mut sc = Scanner::new(1, 0);
    sc.restart_one(0, f(0.0), Some(0.0));
    let (mut samples, mut evals) = (0, 0);
    sc.scan(
        0.0,
        1.0,
        true,
        |t, _, _, o| {
            samples += 1;
            o[0] = f(t);
        },
        |_, t| {
            evals += 1;
            f(t)
        },
        0.0,
    )
    .unwrap();
    assert_eq!(samples, 1);
    assert!(
        evals <= 3,
        "{evals} evaluations to locate the root of a line"
    );
    assert_eq!(sc.found.len(), 1);
    assert_relative_eq!(sc.found[0].t, 0.1, max_relative = 1e-14);
    assert!(f(sc.found[0].t) >= 0.0);
}

/// The closed-form root of the watched lines: the first armed line rising towards zero, its
/// root t₀ − v₀/v̇; a falling line, a disarmed one and one whose root lies past the stop do
/// not count; a line already on zero at t₀ or two roots within the simultaneity window are
/// left to the scan.
#[test]
fn the_first_line_root_is_the_earliest_armed_rising_line() {
    // Four events: v₀ = −1 rising at 2 (root 0.5), −1 rising at 1 (root 1), −1 falling,
    // and a disarmed one (fired from 0 at the restart, v₀ = 0.5 ≥ its level 0).
    let mut sc = Scanner::new(4, 0);
    sc.restart_one(0, -1.0, None);
    sc.restart_one(1, -1.0, None);
    sc.restart_one(2, -1.0, None);
    sc.restart_one(3, 0.5, Some(0.0));
    let slope = [2.0, 1.0, -3.0, 5.0];
    assert_eq!(
        sc.first_line_root(0.0, 2.0, &slope, 1e-12),
        LineRoot::At(0, 0.5)
    );
    assert_eq!(
        sc.first_line_root(0.0, 0.4, &slope, 1e-12),
        LineRoot::Beyond
    );
    // The second root within the window of the first: scanned.
    assert_eq!(sc.first_line_root(0.0, 2.0, &slope, 0.6), LineRoot::Scan);
    // Only falling lines: beyond any stop.
    assert_eq!(
        sc.first_line_root(0.0, 1e300, &[-2.0, -1.0, -3.0, 5.0], 0.0),
        LineRoot::Beyond
    );
    // An armed line exactly on zero at t₀ fires there: scanned.
    let mut sc = Scanner::new(1, 0);
    sc.restart_one(0, 0.0, None);
    assert_eq!(sc.first_line_root(0.0, 1.0, &[1.0], 0.0), LineRoot::Scan);
}

/// Closing a segment of lines: an armed line that has triggered at the end is a crossing
/// there; the others are committed (the start value, the rise and the span for the next
/// step, a falling disarmed line re-armed), and a NaN is reported where the samples would
/// first have been NaN.
#[test]
fn closing_lines_finds_the_triggered_and_commits_the_rest() {
    let mut sc = Scanner::new(3, 0);
    sc.restart_one(0, -1.0, None);
    sc.restart_one(1, -1.0, None);
    sc.restart_one(2, 0.25, Some(0.0));
    let end = [0.0, -0.5, -0.25];
    sc.close_lines(0.0, 2.0, |t, is_end, watched, out| {
        assert!(is_end && t == 2.0);
        for &w in watched {
            out[w] = end[w];
        }
    })
    .unwrap();
    assert_eq!(sc.found, vec![Crossing { w: 0, t: 2.0 }]);
    let tr = sc.tracks[1];
    assert_eq!((tr.start_val, tr.last_rise, tr.last_span), (-0.5, 0.5, 2.0));
    assert!(tr.armed && tr.rising);
    assert!(
        sc.tracks[2].armed,
        "a disarmed line that fell below its level re-arms"
    );
    let mut sc = Scanner::new(1, 0);
    sc.restart_one(0, -1.0, None);
    let err = sc.close_lines(0.0, 1.0, |_, _, _, out| out[0] = f64::NAN);
    assert_eq!(err, Err((0, 0.2)));
}
