//! Adjoint against forward mode as the number of parameters grows (issue 8), on two
//! generated models loaded from text (the `Dyn` door), at the default options (rtol 1e-8,
//! method auto), p = 1, 10, 100, 1000:
//!
//! - **impact** (parameters in the reset): a ball with linear drag, ḣ = v, v̇ = −g − 0.05 v,
//!   bouncing off the floor with a fitted restitution law v⁺ = −e(v⁻) v⁻,
//!   e(v) = Σ_{j<p} a_j / (1 + (v/10j)²) (a_j = 0.8/(p − 1); e = 0.8 for p = 1), θ = (g, a_1,
//!   …); C = ∫h dt + Σ 0.01 v⁺², T = 3 (three or four impacts). The model costs the same to
//!   evaluate for every p except at the events, so the adjoint's cost should stay flat while
//!   forward mode carries S (2 × p).
//! - **chain** (parameters in the flow): four masses on springs between two walls (n = 8), the
//!   first driven by 1.5 sin 2t and bouncing elastically off a wall at q₁ = 0.3 (five events
//!   on [0, 10]); each a_j stiffens one mass, v̇_i = … − q_i Σ_{j ≡ i mod 4} c_j a_j
//!   (a_j = 0.5/p, c_j ∈ (0, 1]); C = ∫(q₁² + q₄²) dt + Σ v₁². Here f itself has p terms, so
//!   every evaluation, the primal's included, costs O(p).
//!
//! Per model and p: `forward`, forward sensitivities (O(n·p) per step), and `adjoint`,
//! `GradientMode::Adjoint` (a primal run at 1/100 of the tolerances, then the sweep, with the
//! interpreter's sparse vector–Jacobian products: λ alone in the stepper, the gradient
//! quadrature added once per step at O(nnz f_θ) per stage value).
//!
//! After criterion, a table per model (medians of 9 runs in ms, for p = 1, 10, 20, 50, 100,
//! 1000; steps; the adjoint's record in bytes; the peak heap of one run in each mode, from
//! this binary's counting global allocator [`PeakHeap`]; forward/adjoint agreement), the
//! crossover p and the flatness ratio time(p = 1000)/time(p = 10) (target ≤ 3) are printed,
//! then the process's peak resident set (not with `ADJOINT_BENCH_NO_TABLE` set, e.g. under a
//! profiler with a criterion filter).
//!
//! ## Figures
//!
//! `docs/report/adjoint-scaling.md` has this bench's output, the instruction counts of
//! `examples/adjoint_profile.rs` under callgrind (the steady figure on a shared machine), the
//! crossover and the memory, with how each was measured. In short (helper `adjflat2`): the
//! impact model's adjoint costs 2.65× at p = 1000 what it costs at p = 10 in instructions
//! (forward mode 34×) and overtakes forward mode between p = 20 and 100; on chain, whose
//! flow sums p terms, it does not overtake up to p = 1000 (1.8× slower there).

use criterion::{criterion_group, Criterion};
use models::generated::{chain, impact};
use mvad::interp::InterpretedModel;
use mvad::solution::{GradientMode, Options, Solution};
use mvad::solve::solve;
use nalgebra::DVector;
use std::alloc::{GlobalAlloc, Layout, System};
use std::hint::black_box;
use std::sync::atomic::{AtomicUsize, Ordering::Relaxed};
use std::time::Instant;

/// The system allocator, keeping the bytes live and their peak, for the heap a run adds
/// at its peak ([`peak_heap`]).
struct PeakHeap;

static LIVE: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);

fn grow(bytes: usize) {
    let live = LIVE.fetch_add(bytes, Relaxed) + bytes;
    PEAK.fetch_max(live, Relaxed);
}

// SAFETY: forwards every call to the system allocator; the counters are atomics (touching
// them never allocates).
unsafe impl GlobalAlloc for PeakHeap {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        grow(layout.size());
        unsafe { System.alloc(layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        grow(layout.size());
        unsafe { System.alloc_zeroed(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        LIVE.fetch_sub(layout.size(), Relaxed);
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        if new_size >= layout.size() {
            grow(new_size - layout.size());
        } else {
            LIVE.fetch_sub(layout.size() - new_size, Relaxed);
        }
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: PeakHeap = PeakHeap;

/// The most heap `f` holds at any moment beyond what was live when it started, in bytes
/// (the run's buffers, its record and its solution; the model and θ exist before).
fn peak_heap(f: impl FnOnce() -> Solution) -> usize {
    let before = LIVE.load(Relaxed);
    PEAK.store(before, Relaxed);
    drop(black_box(f()));
    PEAK.load(Relaxed) - before
}

/// The peak resident set size of this process so far (`VmHWM` of /proc/self/status, kB),
/// where /proc has it.
fn peak_rss_kb() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    line.split_whitespace().nth(1)?.parse().ok()
}

/// The parameter counts benchmarked by criterion.
const PS: [usize; 4] = [1, 10, 100, 1000];
/// The parameter counts of the summary table (finer, to locate the crossover).
const TABLE_PS: [usize; 6] = [1, 10, 20, 50, 100, 1000];

/// A generated model with p parameters, loaded, and θ.
struct Case {
    family: &'static str,
    p: usize,
    loaded: InterpretedModel,
    theta: DVector<f64>,
}

/// A generator of model text for p parameters.
type Generator = fn(usize) -> String;

/// The generated models: (name, text generator).
const FAMILIES: [(&str, Generator); 2] = [("impact", impact), ("chain", chain)];

fn cases() -> Vec<Case> {
    let mut out = Vec::new();
    for (family, text) in FAMILIES {
        for p in TABLE_PS {
            let loaded = InterpretedModel::from_source(&text(p)).expect("the model loads");
            let theta = loaded.default_params();
            out.push(Case {
                family,
                p,
                loaded,
                theta,
            });
        }
    }
    out
}

fn opts(mode: GradientMode) -> Options {
    Options {
        gradient_mode: mode,
        ..Options::default()
    }
}

/// The two runs of a case: 0 forward, 1 adjoint.
fn run(case: &Case, which: usize) -> Solution {
    let mode = [GradientMode::Forward, GradientMode::Adjoint][which];
    solve(&case.loaded, black_box(&case.theta), &opts(mode)).expect("the model runs")
}

const NAMES: [&str; 2] = ["forward", "adjoint"];

fn bench(c: &mut Criterion) {
    let cases = cases();
    let mut group = c.benchmark_group("adjoint");
    group.sample_size(10);
    for case in cases.iter().filter(|c| PS.contains(&c.p)) {
        for (which, name) in NAMES.iter().enumerate() {
            group.bench_function(format!("{}/{name}/{}", case.family, case.p), |b| {
                b.iter(|| run(case, which).gradient[0])
            });
        }
    }
    group.finish();
    // The table times every case again: skip it under a profiler or a criterion filter.
    if std::env::var_os("ADJOINT_BENCH_NO_TABLE").is_some() {
        return;
    }
    for (family, _) in FAMILIES {
        let of: Vec<&Case> = cases.iter().filter(|c| c.family == family).collect();
        summary(family, &of);
    }
    if let Some(kb) = peak_rss_kb() {
        println!("\npeak resident set of the whole bench process (VmHWM): {kb} kB");
    }
}

/// Median of 9 timed runs, in ms.
fn median_ms(f: impl Fn() -> Solution) -> f64 {
    let mut v: Vec<f64> = (0..9)
        .map(|_| {
            let t = Instant::now();
            black_box(f());
            t.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    v.sort_by(f64::total_cmp);
    v[4]
}

/// The table of one model: medians, steps, memory, agreement, crossover, flatness ratio.
fn summary(family: &str, cases: &[&Case]) {
    println!("\n{family}:");
    println!(
        "{:>5} {:>12} {:>12} {:>8} {:>8} {:>11} {:>11} {:>11} {:>10}",
        "p",
        "forward ms",
        "adjoint ms",
        "fwd st.",
        "adj st.",
        "record B",
        "fwd heap B",
        "adj heap B",
        "|Δ|/|g|"
    );
    let mut t = vec![[0.0; 2]; cases.len()];
    for (row, &case) in t.iter_mut().zip(cases) {
        let (f, a) = (run(case, 0), run(case, 1));
        for (w, cell) in row.iter_mut().enumerate() {
            *cell = median_ms(|| run(case, w));
        }
        let heap = [peak_heap(|| run(case, 0)), peak_heap(|| run(case, 1))];
        let scale = f.gradient.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let diff = (a.gradient.iter().zip(&f.gradient))
            .map(|(x, y)| (x - y).abs())
            .fold(0.0f64, f64::max);
        println!(
            "{:>5} {:>12.3} {:>12.3} {:>8} {:>8} {:>11} {:>11} {:>11} {:>10.1e}",
            case.p,
            row[0],
            row[1],
            f.stats.steps,
            a.stats.steps,
            a.stats.record_bytes,
            heap[0],
            heap[1],
            diff / scale
        );
    }
    let at = |p: usize| TABLE_PS.iter().position(|&q| q == p).expect("tabled p");
    let cross = TABLE_PS
        .iter()
        .zip(&t)
        .find(|(_, r)| r[1] < r[0])
        .map_or("none up to 1000".into(), |(p, _)| format!("p = {p}"));
    println!(
        "adjoint: time(p = 1000) / time(p = 10) = {:.2} (target ≤ 3); faster than forward from {cross}",
        t[at(1000)][1] / t[at(10)][1]
    );
    println!(
        "forward: time(p = 1000) / time(p = 10) = {:.2}",
        t[at(1000)][0] / t[at(10)][0]
    );
}

criterion_group!(benches, bench);

fn main() {
    benches();
    Criterion::default().configure_from_args().final_summary();
}
