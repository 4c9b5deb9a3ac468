//! Timing helpers shared by the benches.

use std::hint::black_box;
use std::time::Instant;

/// Median over 15 batches of the mean time per call of `f`, in µs.
pub fn median_us<T>(mut f: impl FnMut() -> T) -> f64 {
    let mut batch = 200usize;
    // Size the batch to ~20 ms.
    loop {
        let t = Instant::now();
        for _ in 0..batch {
            black_box(f());
        }
        if t.elapsed().as_secs_f64() > 0.02 || batch > 1_000_000 {
            break;
        }
        batch *= 2;
    }
    let mut v: Vec<f64> = (0..15)
        .map(|_| {
            let t = Instant::now();
            for _ in 0..batch {
                black_box(f());
            }
            t.elapsed().as_secs_f64() * 1e6 / batch as f64
        })
        .collect();
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}
