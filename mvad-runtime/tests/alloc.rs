//! The hot loop allocates nothing per step: a run's allocation count does not depend on
//! how many steps it takes (counted with a global allocator wrapper).

use mvad_runtime::fixtures::Ball;
use mvad_runtime::solution::{Method, Options};
use mvad_runtime::solve::solve;
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

struct Counting;

static ALLOCS: AtomicUsize = AtomicUsize::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCS.fetch_add(1, Ordering::Relaxed);
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCS.fetch_add(1, Ordering::Relaxed);
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

fn count(opts: &Options) -> (usize, usize, usize) {
    let ball = Ball::new();
    let p = ball.default_params();
    let before = ALLOCS.load(Ordering::Relaxed);
    let sol = solve(&ball, &p, opts).unwrap();
    let n = ALLOCS.load(Ordering::Relaxed) - before;
    (n, sol.stats.steps, sol.events.len())
}

#[test]
fn allocations_do_not_grow_with_steps() {
    for method in [
        Method::Tsit5,
        Method::Auto,
        Method::Verner9,
        Method::Rosenbrock,
    ] {
        // Same events (two impacts), very different step counts.
        let loose = Options {
            method,
            rtol: 1e-4,
            atol: 1e-6,
            ..Options::default()
        };
        let tight = Options {
            method,
            rtol: 1e-12,
            atol: 1e-14,
            sens_error_control: true,
            ..Options::default()
        };
        let (a_loose, s_loose, e_loose) = count(&loose);
        let (a_tight, s_tight, e_tight) = count(&tight);
        eprintln!("{method:?}: {a_loose} allocations");
        assert_eq!(e_loose, e_tight);
        assert!(s_tight > s_loose, "{s_tight} vs {s_loose} steps");
        assert_eq!(
            a_loose, a_tight,
            "{method:?}: {a_loose} allocations for {s_loose} steps, {a_tight} for {s_tight}"
        );
    }
}
