//! Event sinks: every sink sees the same events and leaves C and dC/dθ unchanged; the
//! table sink is what `solve` returns; with `()` a run allocates nothing per event.

use mvad_runtime::fixtures::counting::{allocations, Counting};
use mvad_runtime::fixtures::Ball;
use mvad_runtime::sink::{EventCounts, EventView, Stream};
use mvad_runtime::solution::{EventRecord, Options};
use mvad_runtime::solve::{solve, solve_with};

#[global_allocator]
static GLOBAL: Counting = Counting;

/// An elastic ball (e = 1): one impact every 2·sqrt(2 h0/g) ≈ 1.28 s, no accumulation.
fn elastic(t_end: f64) -> (Ball, nalgebra::SVector<f64, 4>, Options) {
    let ball = Ball::new();
    let mut p = ball.default_params();
    p[0] = 1.0;
    let opts = Options {
        t_end: Some(t_end),
        ..Options::default()
    };
    (ball, p, opts)
}

#[test]
fn every_sink_sees_the_same_events_and_the_same_gradient() {
    let (ball, p, opts) = elastic(20.0);
    let reference = solve(&ball, &p, &opts).unwrap();
    assert!(
        reference.events.len() >= 15,
        "{} events",
        reference.events.len()
    );

    let mut table: Vec<EventRecord> = Vec::new();
    let sol = solve_with(&ball, &p, &opts, &mut table).unwrap();
    assert!(sol.events.is_empty());
    assert_eq!(table, reference.events);

    let mut counts = EventCounts::new(1);
    let sol = solve_with(&ball, &p, &opts, &mut counts).unwrap();
    assert_eq!(counts.per_event, vec![reference.events.len()]);
    assert_eq!(sol.stats.events, reference.events.len());

    // A streaming reduction: Σ t_k and Σ dt_k/de, and the atoms rebuilt from the view.
    let (mut sum_t, mut sum_dt, mut n) = (0.0, 0.0, 0);
    let mut check = Stream(|ev: &EventView<'_>| {
        let rec = &reference.events[ev.index];
        assert_eq!(ev.to_record(), *rec);
        sum_t += ev.t;
        sum_dt += ev.dt[0];
        n += 1;
    });
    let sol = solve_with(&ball, &p, &opts, &mut check).unwrap();
    assert_eq!(n, reference.events.len());
    let want_t: f64 = reference.events.iter().map(|e| e.t).sum();
    let want_dt: f64 = reference.events.iter().map(|e| e.dt[0]).sum();
    assert_eq!((sum_t, sum_dt), (want_t, want_dt));

    let none = solve_with(&ball, &p, &opts, &mut ()).unwrap();
    for s in [&sol, &none] {
        assert_eq!(s.cost, reference.cost);
        assert_eq!(s.gradient, reference.gradient);
        assert_eq!(s.x_final, reference.x_final);
        assert_eq!(s.stats.events, reference.events.len());
    }
}

#[test]
fn without_a_table_the_allocations_do_not_grow_with_the_events() {
    let count = |t_end: f64, table: bool| {
        let (ball, p, opts) = elastic(t_end);
        let before = allocations();
        let sol = if table {
            solve(&ball, &p, &opts).unwrap()
        } else {
            solve_with(&ball, &p, &opts, &mut ()).unwrap()
        };
        (allocations() - before, sol.stats.events)
    };
    let (few, e_few) = count(5.0, false);
    let (many, e_many) = count(200.0, false);
    assert!(e_many > 100 && e_few < 5, "{e_few} and {e_many} events");
    assert_eq!(
        few, many,
        "{few} allocations for {e_few} events, {many} for {e_many}"
    );
    // The table does allocate per event: the check above can fail.
    let (with_table, _) = count(200.0, true);
    assert!(with_table > many + e_many, "{with_table} vs {many}");
}
