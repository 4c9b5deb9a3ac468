//! A run that asks only for C and dC/dθ (the `()` sink) builds no event table, no trajectory
//! and no measure: its allocation count does not grow with the number of events. Counted on
//! the queue (E4) through both doors at 10³ and 2·10⁴ customers (about 1.2 events each), with
//! `fixtures::counting` (per thread). A sink keeping the first N events
//! (`FirstEvents`) allocates for those N only.

use models::queue::{self, Arrivals};
use mvad::interp::InterpretedModel;
use mvad::runtime::solution::Options;
use mvad::runtime::solve::solve_with;
use mvad::{EventSink, FirstEvents, HybridModel, ModelAlloc};
use mvad_runtime::fixtures::counting::{allocations, Counting};
use nalgebra::{DefaultAllocator, OVector};

#[global_allocator]
static GLOBAL: Counting = Counting;

/// (allocations of the solve, events) with `sink`.
fn count<M: HybridModel>(m: &M, p: &OVector<f64, M::P>, sink: &mut impl EventSink) -> (usize, usize)
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let before = allocations();
    let sol = solve_with(m, p, &Options::default(), sink).expect("runs");
    (allocations() - before, sol.stats.events)
}

#[test]
fn a_cost_and_gradient_run_allocates_nothing_per_event_through_both_doors() {
    let mut seen = Vec::new();
    for n in [1_000, 20_000] {
        let a = Arrivals::generate(n, 8);
        let table = a.table().expect("table");
        let compiled = queue::Queue::new(queue::QueueTables {
            arrivals: table.clone(),
        })
        .expect("binds");
        let mut loaded =
            InterpretedModel::from_source(&mvad_tests::model_source("queue.hyb")).expect("model");
        loaded.bind_tables(&[&table]).expect("binds");
        let pc = nalgebra::SVector::<f64, 1>::new(1.25);
        let pl = nalgebra::DVector::from_vec(vec![1.25]);
        let (ac, ec) = count(&compiled, &pc, &mut ());
        let (al, el) = count(&loaded, &pl, &mut ());
        // The first 10 events only: ten records more, whatever the run's length.
        let (af, _) = count(&compiled, &pc, &mut FirstEvents::new(10));
        assert!(ec > n && el == ec, "{n}: {ec} / {el} events");
        eprintln!("{n} customers, {ec} events: {ac} allocations compiled, {al} loaded, {af} keeping 10 events");
        seen.push((ac, al, af));
    }
    assert_eq!(
        seen[0], seen[1],
        "allocations grew with the number of events"
    );
}
