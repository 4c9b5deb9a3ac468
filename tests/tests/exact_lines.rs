//! Segments of lines (an exact segment whose watched guards are all affine: `solve/line.rs`)
//! are taken straight to their first root; a recording run scans the same segments as before
//! (the recorder keeps the step as the scan sees it). Both must give the same run: the queue
//! (whose drains snap w onto 0 either way) bit for bit, with its event times within a few
//! ulp (the closed-form root against the root finder's); the sawtooth (whose event times
//! are sums of roots) against its closed form.

use models::queue::{self, Arrivals};
use mvad::interp::InterpretedModel;
use mvad::runtime::solution::{Options, Solution};
use mvad::runtime::solve::solve;
use mvad::{HybridModel, ModelAlloc};
use nalgebra::{DefaultAllocator, OVector};

mvad::hybrid!(include "tests/sawtooth.hyb");

fn run<M: HybridModel>(m: &M, p: &[f64], record: bool) -> Solution
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let p = OVector::<f64, M::P>::from_iterator_generic(
        m.nparams(),
        nalgebra::Const::<1>,
        p.iter().copied(),
    );
    let opts = Options {
        record,
        ..Options::default()
    };
    solve(m, &p, &opts).expect("runs")
}

/// The run taken by lines against the scanned one: the same events in the same order, times
/// within `ulps` ulp of t, C and every entry of dC/dθ within `rel` relative.
#[track_caller]
fn assert_same_run(what: &str, lines: &Solution, scanned: &Solution, ulps: f64, rel: f64) {
    assert_eq!(
        lines.events.len(),
        scanned.events.len(),
        "{what}: event count"
    );
    for (a, b) in lines.events.iter().zip(&scanned.events) {
        assert_eq!(a.event, b.event, "{what}: event at t = {}", b.t);
        let tol = ulps * f64::EPSILON * b.t.abs().max(1.0);
        assert!((a.t - b.t).abs() <= tol, "{what}: t {} vs {}", a.t, b.t);
    }
    let close = |x: f64, y: f64| (x - y).abs() <= rel * y.abs().max(1.0);
    assert!(
        close(lines.cost, scanned.cost),
        "{what}: C {} vs {}",
        lines.cost,
        scanned.cost
    );
    for (g, h) in lines.gradient.iter().zip(&scanned.gradient) {
        assert!(close(*g, *h), "{what}: dC/dθ {g} vs {h}");
    }
}

#[test]
fn the_queue_by_lines_is_the_scanned_queue_bit_for_bit_through_both_doors() {
    let a = Arrivals::generate(20_000, 5);
    let compiled = queue::Queue::new(queue::QueueTables {
        arrivals: a.table().expect("table"),
    })
    .expect("binds");
    let mut loaded =
        InterpretedModel::from_source(&mvad_tests::model_source("queue.hyb")).expect("loads");
    loaded
        .bind_tables(&[&a.table().expect("table")])
        .expect("binds");
    let pairs = [
        (
            "compiled",
            run(&compiled, &[1.25], false),
            run(&compiled, &[1.25], true),
        ),
        (
            "loaded",
            run(&loaded, &[1.25], false),
            run(&loaded, &[1.25], true),
        ),
    ];
    for (door, lines, scanned) in &pairs {
        let drains = scanned.events.iter().filter(|e| e.event == 0).count();
        assert!(drains > 1000, "{door}: {drains} drains");
        assert_same_run(door, lines, scanned, 8.0, 0.0);
        // The state handed to every drain's reset is on its guard (w snapped onto 0).
        for e in lines.events.iter().filter(|e| e.event == 0) {
            assert_eq!(e.x_after[0], 0.0, "{door}: w after the drain at {}", e.t);
        }
    }
}

/// The largest error of a run's event times against the sawtooth's t_k = k·h/a.
fn worst_time_error(sol: &Solution, a: f64, h: f64) -> f64 {
    let exact = |k: usize| (k + 1) as f64 * h / a;
    let errors = sol
        .events
        .iter()
        .enumerate()
        .map(|(k, e)| (e.t - exact(k)).abs());
    errors.fold(0.0, f64::max)
}

/// The sawtooth's event times are sums of the segments' roots, so their rounding accumulates
/// over the run and the two ways of locating a root (closed form, root finder) drift apart
/// by more than a few ulp: each is held to the closed form t_k = k·h/a instead, the lines no
/// worse than the scan (the root finder returns the bracket's triggered end, a little late),
/// and C and dC/dθ of both agree with each other to 1e-12.
#[test]
fn the_sawtooth_by_lines_is_the_scanned_sawtooth_through_both_doors() {
    let loaded = InterpretedModel::from_source(include_str!("sawtooth.hyb")).expect("loads");
    let compiled = Sawtooth::new();
    for (a, h) in [(1.3, 2.0), (0.7, 1e-3), (3.0, 0.1)] {
        let what = format!("a = {a}, h = {h}");
        let runs = [
            (
                "compiled",
                run(&compiled, &[a, h], false),
                run(&compiled, &[a, h], true),
            ),
            (
                "loaded",
                run(&loaded, &[a, h], false),
                run(&loaded, &[a, h], true),
            ),
        ];
        for (door, lines, scanned) in &runs {
            let what = format!("{door}, {what}");
            assert_same_run(&what, lines, scanned, f64::INFINITY, 1e-12);
            let (by_lines, by_scan) = (
                worst_time_error(lines, a, h),
                worst_time_error(scanned, a, h),
            );
            let ulp = f64::EPSILON * 10.0;
            assert!(
                by_lines <= by_scan + 4.0 * ulp,
                "{what}: event times off by {by_lines:e} (lines) vs {by_scan:e} (scanned)"
            );
        }
    }
}
