//! Time events armed only in some modes: an occurrence that falls while the run is in another
//! mode is skipped, also when a state event switches into the event's mode later in the same
//! step (before, it fired late, at the switch, with t' = 0: probe3 A1, C 6× off with a clean
//! bill), and the instant of a switch belongs to the mode it leaves (a queue written with one
//! arrival event per mode handles each row once: the Lindley recursion). Both doors, forward and
//! adjoint, closed forms.

use models::queue::{self, Arrivals};
use mvad::interp::InterpretedModel;
use mvad::runtime::solution::GradientMode;
use mvad::{HybridModel, ModelAlloc};
use mvad_tests::{assert_near, precise};
use nalgebra::{DVector, DefaultAllocator, OVector};

mvad::hybrid!(include "tests/mode_time_events.hyb");

/// C and dC/dr: x = r t up to t₁ = 1/r, then x' = 1 with +10 at the multiples of 0.3 in
/// (t₁, 2], which are 1.2, 1.5 and 1.8 for t₁ ∈ (0.9, 1.2) (the `at 0.1` never fires).
fn closed_form(r: f64) -> (f64, f64) {
    let t1 = 1.0 / r;
    let kicks = [1.2, 1.5, 1.8];
    let c = 0.5 * r * t1 * t1
        + (2.0 - t1)
        + 0.5 * (2.0 - t1).powi(2)
        + kicks.iter().map(|k| 10.0 * (2.0 - k)).sum::<f64>();
    // C = t₁/2 + (2 − t₁) + (2 − t₁)²/2 + Σ 10(2 − kᵢ), so dC/dr = (1/2 − 1 − (2 − t₁))·(−1/r²).
    let dc_dt1 = 0.5 - 1.0 - (2.0 - t1);
    (c, dc_dt1 * (-1.0 / (r * r)))
}

fn check<M: HybridModel>(m: &M, door: &str)
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    for r in [1.0, 0.9, 1.05] {
        let (c, dc) = closed_form(r);
        let p = OVector::<f64, M::P>::from_element_generic(m.nparams(), nalgebra::Const::<1>, r);
        for mode in [GradientMode::Forward, GradientMode::Adjoint] {
            let what = format!("{door} r = {r} {mode:?}");
            let sol = mvad::solve(m, &p, &precise(mode)).expect("runs");
            assert_eq!(sol.stats.events, 4, "{what}: up and three kicks");
            assert_near(sol.cost, c, 1e-9, format_args!("{what}: C"));
            assert_near(sol.gradient[0], dc, 1e-8, format_args!("{what}: dC/dr"));
        }
    }
}

mvad_tests::test_both_doors!(
    a_time_event_skips_what_fell_before_its_mode_was_entered: check,
    ModeTimeEvents::new(),
    "mode_time_events.hyb"
);

/// The queue with `arrive_idle` (idle → busy) and `arrive_busy` over the same rows: each row is
/// handled once, by the event of the mode current at its time (an arrival to an empty queue
/// switches to busy, and busy's event does not handle the same row again at that instant).
#[test]
fn a_queue_with_one_arrival_event_per_mode_is_the_lindley_recursion() {
    let src = "model QueueTwoModes {
        param mu = 1.25;
        table arrivals = \"arrivals.csv\";
        state w = 0;
        initial mode idle;
        mode busy {
            der(w) = -1;
            event drained when w <= 0 -> idle;
            event arrive_busy at each arrivals.t { w = w + arrivals.s / mu; }
        }
        mode idle {
            der(w) = 0;
            event arrive_idle at each arrivals.t -> busy { w = w + arrivals.s / mu; }
        }
        cost = sum(arrive_idle, w) + sum(arrive_busy, w);
        horizon 1e9;
    }";
    let a = Arrivals::generate(500, 11);
    let mut m = InterpretedModel::from_source(src).expect("valid model");
    m.bind_tables(&[&a.table().expect("table")]).expect("binds");
    let mu = 1.25;
    let (c, dmu, _) = queue::exact(&a.t, &a.s, mu, 1.0);
    for mode in [GradientMode::Forward, GradientMode::Adjoint] {
        let sol = mvad::solve(&m, &DVector::from_element(1, mu), &precise(mode)).expect("runs");
        assert_near(sol.cost, c, 1e-12, format_args!("{mode:?}: C"));
        assert_near(
            sol.gradient[0],
            dmu,
            1e-12,
            format_args!("{mode:?}: dC/dmu"),
        );
    }
}
