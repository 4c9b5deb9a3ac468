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
//! interpreter's sparse vector–Jacobian products: O(p) per stage for λᵀf_θ).
//!
//! After criterion, a table per model (medians of 9 runs in ms, for p = 1, 10, 20, 50, 100,
//! 1000; steps; the forward record's memory; forward/adjoint agreement), the crossover p and
//! the flatness ratio time(p = 1000)/time(p = 10) (target ≤ 3) are printed (not with
//! `ADJOINT_BENCH_NO_TABLE` set, e.g. under a profiler with a criterion filter).
//!
//! ## Figures (2 cores shared with other builds: load average 1.6 at the start, 5.5 at the end)
//!
//! `cargo bench -p models --bench adjoint`, release, AMD EPYC (2 vCPUs); the table's medians
//! in ms (criterion's medians agree within the noise of the load, e.g. impact adjoint p = 1000:
//! 0.88 ms [0.79, 0.96], p = 10: 0.14 ms [0.13, 0.16]):
//!
//! | p | impact fwd | impact adj | chain fwd | chain adj |
//! |---|---|---|---|---|
//! | 1 | 0.039 | 0.080 | 1.05 | 2.31 |
//! | 10 | 0.059 | 0.088 | 1.95 | 3.83 |
//! | 20 | 0.078 | 0.096 | 2.92 | 9.07 |
//! | 50 | 0.130 | 0.101 | 9.09 | 14.1 |
//! | 100 | 0.219 | 0.122 | 13.3 | 25.3 |
//! | 1000 | 1.83 | 0.506 | 123 | 138 |
//!
//! - impact: adjoint time(1000)/time(10) = 5.8 (target ≤ 3: **not met**), forward 31; the
//!   adjoint is faster from p = 50 (`GradientMode::AUTO_ADJOINT_MIN_PARAMS`), 3.6× faster at
//!   p = 1000. Where the adjoint's p = 1000 time goes (perf): up to ~45 % the sweep's O(p) work
//!   per stage (the quadrature g is p long in every stage vector, combination, error norm and
//!   finiteness check, though f_θ has one non-zero), ~30 % the model's own O(p) work at the
//!   four impacts (the reset's p-term law evaluated forwards and its Jacobian transposed:
//!   ~0.24 ms at p = 1000 by perf's shares, more than twice the whole p = 10 run), the rest
//!   the O(1) primal and λ. So on this model 3× is out of reach even for an adjoint with no
//!   O(p) work of its own ((0.088 + 0.24)/0.088 ≈ 3.7); what the adjoint can still remove is
//!   its per-stage O(p), by accumulating the quadrature sparsely outside the integrator's
//!   vectors (a product that adds into g instead of overwriting a p vector).
//! - chain: f has p terms, so every evaluation is O(p) in both modes; the adjoint takes 1592
//!   steps (primal at 1/100 of the tolerances, then the sweep) to forward's 249, and is not
//!   faster up to p = 1000 (1.1× slower there). Adjoint 1000/10 = 36, forward 63.
//! - Memory (`stats.record_bytes`, the forward record): impact 7.5–8.0 kB (77–89 steps, 3–4
//!   impacts), chain 451 kB (n = 8, ~1600 steps), the same for every p: the record holds x,
//!   never anything of size p.
//! - Agreement forward/adjoint at the default rtol 1e-8: impact ≤ 1.6e-10, chain ≤ 3.8e-8 of
//!   the gradient's scale.

use criterion::{criterion_group, Criterion};
use mvad::interp::InterpretedModel;
use mvad::solution::{GradientMode, Options, Solution};
use mvad::solve::solve;
use models::generated::{chain, impact};
use nalgebra::DVector;
use std::hint::black_box;
use std::time::Instant;

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
        "{:>5} {:>12} {:>12} {:>8} {:>8} {:>11} {:>10}",
        "p", "forward ms", "adjoint ms", "fwd st.", "adj st.", "record B", "|Δ|/|g|"
    );
    let mut t = vec![[0.0; 2]; cases.len()];
    for (row, &case) in t.iter_mut().zip(cases) {
        let (f, a) = (run(case, 0), run(case, 1));
        for (w, cell) in row.iter_mut().enumerate() {
            *cell = median_ms(|| run(case, w));
        }
        let scale = f.gradient.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let diff = (a.gradient.iter().zip(&f.gradient))
            .map(|(x, y)| (x - y).abs())
            .fold(0.0f64, f64::max);
        println!(
            "{:>5} {:>12.3} {:>12.3} {:>8} {:>8} {:>11} {:>10.1e}",
            case.p,
            row[0],
            row[1],
            f.stats.steps,
            a.stats.steps,
            a.stats.record_bytes,
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
