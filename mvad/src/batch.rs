//! Many runs of one model across cores: parameter sweeps (`mvad sweep`) and the batches of
//! the Python package.
//!
//! [`par_map`] applies a function to every item on rayon's thread pool and returns the
//! results in input order. Each run is a pure function of its item, so the results are
//! those of a serial loop, bit for bit. A model keeps scratch space in interior-mutable
//! buffers (it is `Send`, not `Sync`), so every worker runs its own clone. A panic inside one
//! run is caught and returned as that item's [`Panicked`], so one bad item neither aborts
//! the batch nor unwinds into a caller that cannot take it (the Python interpreter).

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::Mutex;

use rayon::prelude::*;

/// A run that panicked, with the panic's message.
#[derive(Clone, Debug, PartialEq)]
pub struct Panicked(pub String);

impl std::fmt::Display for Panicked {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "internal error (a panic, please report it): {}", self.0)
    }
}

impl std::error::Error for Panicked {}

/// Runs `f`, turning a panic into [`Panicked`].
pub fn catch<R>(f: impl FnOnce() -> R) -> Result<R, Panicked> {
    catch_unwind(AssertUnwindSafe(f)).map_err(|payload| {
        let msg = payload
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| payload.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "unknown panic".to_string());
        Panicked(msg)
    })
}

/// `f(model, item)` for every item, in parallel, results in input order; `tick` is called
/// once per finished item (from any thread: a progress bar).
pub fn par_map<M, I, R, F>(
    model: &M,
    items: &[I],
    f: F,
    tick: &(dyn Fn() + Sync),
) -> Vec<Result<R, Panicked>>
where
    M: Clone + Send,
    I: Sync,
    R: Send,
    F: Fn(&M, &I) -> R + Sync,
{
    let shared = Mutex::new(model.clone());
    let fresh = || match shared.lock() {
        Ok(m) => m.clone(),
        Err(poisoned) => poisoned.into_inner().clone(),
    };
    items
        .par_iter()
        .map_init(fresh, |local, item| {
            let out = catch(|| f(local, item));
            if out.is_err() {
                // The panic may have left the clone's scratch half written.
                *local = fresh();
            }
            tick();
            out
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use mvad_runtime::fixtures::Ball;
    use mvad_runtime::solution::Options;
    use mvad_runtime::solve::solve;
    use nalgebra::U4;
    use std::sync::atomic::{AtomicUsize, Ordering};

    #[test]
    fn results_are_in_input_order_and_equal_the_serial_loop() {
        let ball = Ball::new();
        let items: Vec<f64> = (0..64).map(|i| 0.3 + 0.01 * i as f64).collect();
        let run = |m: &Ball, e: &f64| {
            let p = nalgebra::OVector::<f64, U4>::from([*e, 9.81, 2.0, 0.0]);
            solve(m, &p, &Options::default()).map(|s| (s.cost, s.gradient))
        };
        let count = AtomicUsize::new(0);
        let tick = || {
            count.fetch_add(1, Ordering::Relaxed);
        };
        let par = par_map(&ball, &items, run, &tick);
        let serial: Vec<_> = items.iter().map(|e| run(&ball, e)).collect();
        assert_eq!(count.load(Ordering::Relaxed), items.len());
        for (a, b) in par.into_iter().zip(serial) {
            assert_eq!(a.expect("no panic"), b);
        }
    }

    #[test]
    fn a_panicking_item_is_an_error_and_the_others_still_run() {
        let out = par_map(
            &(),
            &[1, 2, 3],
            |_, &i| if i == 2 { panic!("boom {i}") } else { i * 10 },
            &|| {},
        );
        assert_eq!(out[0], Ok(10));
        assert_eq!(out[1], Err(Panicked("boom 2".into())));
        assert_eq!(out[2], Ok(30));
    }
}
