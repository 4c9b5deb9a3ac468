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
//! Per model and p: `forward`, forward sensitivities (O(n·p) per step); `adjoint`,
//! `GradientMode::Adjoint` with the interpreter's vector–Jacobian products as they are today
//! (the dense defaults of `ModelAdjoint`: f_x and f_θ, n × p, formed at every stage); and
//! `adjoint_sparse`, the same sweep on the same model with the sparse λᵀf_θ the symbolic
//! kernels will emit, written by hand here: what to expect once they land.
//!
//! After criterion, a table per model (medians of 9 runs in ms, for p = 1, 10, 20, 50, 100,
//! 1000; steps; the forward record's memory; forward/adjoint agreement), the crossover p and
//! the flatness ratio time(p = 1000)/time(p = 10) (target ≤ 3) are printed.

use criterion::{criterion_group, Criterion};
use mvad::interp::InterpretedModel;
use mvad::model::{ModelAdjoint, ModelDims, ModelInfo, ModelSecondOrder, ModelSens, Point};
use mvad::solution::{GradientMode, Options, Solution};
use mvad::solve::solve;
use mvad::{HybridModel, Switches};
use nalgebra::{DMatrix, DVector, Dyn};
use std::cell::RefCell;
use std::hint::black_box;
use std::time::Instant;

/// Masses in the chain (n = 2 × MASSES states: q₁, v₁, q₂, v₂, …).
const MASSES: usize = 4;

/// `(t₁ + t₂ + …)`, as a balanced tree (the language bounds nesting at 256 levels).
fn balanced_sum(terms: &[String]) -> String {
    match terms {
        [] => "0".into(),
        [t] => t.clone(),
        _ => {
            let (a, b) = terms.split_at(terms.len() / 2);
            format!("({} + {})", balanced_sum(a), balanced_sum(b))
        }
    }
}

/// The `.hyb` text of the impact model with p parameters (g and p − 1 restitution weights).
fn impact(p: usize) -> String {
    let m = p - 1;
    let mut s = String::from("model Impact {\n    param g = 9.81;\n");
    for j in 1..=m {
        s += &format!("    param a{j} = {:?};\n", 0.8 / m as f64);
    }
    s += "    state h = 2; state v = 0;\n    flow { der(h) = v; der(v) = -g - 0.05 * v; }\n";
    let terms: Vec<String> = (1..=m)
        .map(|j| format!("a{j} / (1 + (v / {})^2)", 10 * j))
        .collect();
    let law = if m == 0 {
        "0.8".into()
    } else {
        balanced_sum(&terms)
    };
    s += &format!("    event impact when h <= 0 {{ v = -{law} * v; }}\n");
    s += "    cost = integral(h) + sum(impact, 0.01 * v^2);\n    horizon 3;\n}\n";
    s
}

/// λᵀf_θ of the impact model: f = (v, −g − 0.05 v) depends on g alone.
fn impact_vjp_p(_pt: &Point<'_, Dyn, Dyn>, lambda: &V, vp: &mut V) {
    vp.fill(0.0);
    vp[0] = -lambda[1];
}

/// λᵀf_θ of the chain: ∂f_{v_i}/∂a_j = −c_j q_i for the mass i that a_j stiffens.
fn chain_vjp_p(pt: &Point<'_, Dyn, Dyn>, lambda: &V, vp: &mut V) {
    for (j0, out) in vp.iter_mut().enumerate() {
        let (j, i) = (j0 + 1, mass_of(j0 + 1));
        *out = -lambda[2 * i + 1] * c(j) * pt.x[2 * i];
    }
}
/// The parameter counts benchmarked by criterion.
const PS: [usize; 4] = [1, 10, 100, 1000];
/// The parameter counts of the summary table (finer, to locate the crossover).
const TABLE_PS: [usize; 6] = [1, 10, 20, 50, 100, 1000];

/// c_j of parameter j (1-based): fixed in (0, 1].
fn c(j: usize) -> f64 {
    ((j * 7) % 10 + 1) as f64 / 10.0
}

/// The mass (0-based) parameter j (1-based) stiffens.
fn mass_of(j: usize) -> usize {
    (j - 1) % MASSES
}

/// The `.hyb` text of the chain with p parameters.
fn chain(p: usize) -> String {
    let mut s = String::from("model Chain {\n    const k = 4.0; const d = 0.05;\n");
    for j in 1..=p {
        s += &format!("    param a{j} = {:?};\n", 0.5 / p as f64);
    }
    for i in 1..=MASSES {
        let v0 = if i == 1 { 2.0 } else { 0.0 };
        s += &format!("    state q{i} = 0; state v{i} = {v0:?};\n");
    }
    s += "    flow {\n";
    for i in 1..=MASSES {
        let left = if i > 1 {
            format!("q{}", i - 1)
        } else {
            "0".into()
        };
        let right = if i < MASSES {
            format!("q{}", i + 1)
        } else {
            "0".into()
        };
        let terms: Vec<String> = (1..=p)
            .filter(|&j| mass_of(j) == i - 1)
            .map(|j| format!("{:?} * a{j}", c(j)))
            .collect();
        let gain = balanced_sum(&terms);
        let drive = if i == 1 { "1.5 * sin(2 * t) " } else { "" };
        s += &format!("        der(q{i}) = v{i};\n");
        s += &format!(
            "        der(v{i}) = {drive}- k * (2 * q{i} - {left} - {right}) - d * v{i} - q{i} * ({gain});\n"
        );
    }
    s += "    }\n    event hit when q1 >= 0.3 { v1 = -v1; }\n";
    s += &format!("    cost = integral(q1^2 + q{MASSES}^2) + sum(hit, v1^2);\n");
    s += "    horizon 10;\n}\n";
    s
}

/// λᵀf_θ of a generated model, written by hand.
type VjpP = fn(&Point<'_, Dyn, Dyn>, &V, &mut V);

/// A loaded model with a sparse `rhs_vjp` (λᵀf_x from the n × n Jacobian, λᵀf_θ by `vjp_p`);
/// every other method is the interpreter's.
struct SparseVjp {
    m: InterpretedModel,
    /// f_x scratch (n × n), so the product allocates nothing.
    fx: RefCell<DMatrix<f64>>,
    vjp_p: VjpP,
}

type V = DVector<f64>;
type M = DMatrix<f64>;

impl ModelDims for SparseVjp {
    type N = Dyn;
    type P = Dyn;
}
impl ModelSens for SparseVjp {}
impl ModelSecondOrder for SparseVjp {}
impl ModelAdjoint for SparseVjp {
    fn rhs_vjp(&self, pt: Point<'_, Dyn, Dyn>, lambda: &V, vx: &mut V, vp: &mut V) {
        let mut fx = self.fx.borrow_mut();
        self.m.rhs_jac_x(pt, &mut fx);
        fx.tr_mul_to(lambda, vx);
        (self.vjp_p)(&pt, lambda, vp);
    }
}

impl HybridModel for SparseVjp {
    fn info(&self) -> &ModelInfo {
        self.m.info()
    }
    fn nstates(&self) -> Dyn {
        self.m.nstates()
    }
    fn nparams(&self) -> Dyn {
        self.m.nparams()
    }
    fn initial_state(&self, p: &V, x0: &mut V) {
        self.m.initial_state(p, x0)
    }
    fn initial_state_jac(&self, p: &V, dx0: &mut M) {
        self.m.initial_state_jac(p, dx0)
    }
    fn horizon(&self, p: &V) -> Option<f64> {
        self.m.horizon(p)
    }
    fn horizon_grad(&self, p: &V, dt: &mut V) {
        self.m.horizon_grad(p, dt)
    }
    fn rhs(&self, pt: Point<'_, Dyn, Dyn>, f: &mut V) {
        self.m.rhs(pt, f)
    }
    fn rhs_jac_x(&self, pt: Point<'_, Dyn, Dyn>, fx: &mut M) {
        self.m.rhs_jac_x(pt, fx)
    }
    fn rhs_jac_p(&self, pt: Point<'_, Dyn, Dyn>, fp: &mut M) {
        self.m.rhs_jac_p(pt, fp)
    }
    fn rhs_dt(&self, pt: Point<'_, Dyn, Dyn>, ft: &mut V) {
        self.m.rhs_dt(pt, ft)
    }
    fn rhs_depends_on_t(&self, mode: usize) -> bool {
        self.m.rhs_depends_on_t(mode)
    }
    fn guard(&self, k: usize, t: f64, x: &V, p: &V) -> f64 {
        self.m.guard(k, t, x, p)
    }
    fn guard_grad(&self, k: usize, t: f64, x: &V, p: &V, gx: &mut V, gp: &mut V) -> f64 {
        self.m.guard_grad(k, t, x, p, gx, gp)
    }
    fn reset(&self, k: usize, t: f64, x: &V, p: &V, xp: &mut V) {
        self.m.reset(k, t, x, p, xp)
    }
    fn reset_jac(&self, k: usize, t: f64, x: &V, p: &V, rx: &mut M, rp: &mut M, rt: &mut V) {
        self.m.reset_jac(k, t, x, p, rx, rp, rt)
    }
    fn switch_value(&self, j: usize, t: f64, x: &V, p: &V) -> f64 {
        self.m.switch_value(j, t, x, p)
    }
    fn switch_grad(&self, j: usize, t: f64, x: &V, p: &V, gx: &mut V, gp: &mut V) -> f64 {
        self.m.switch_grad(j, t, x, p, gx, gp)
    }
    fn observe(&self, t: f64, x: &V, p: &V, y: &mut [f64]) {
        self.m.observe(t, x, p, y)
    }
    fn observe_jac(&self, t: f64, x: &V, p: &V, yx: &mut [f64], yp: &mut [f64]) {
        self.m.observe_jac(t, x, p, yx, yp)
    }
    fn running_cost(&self, sw: &Switches, t: f64, x: &V, p: &V) -> f64 {
        self.m.running_cost(sw, t, x, p)
    }
    fn running_cost_value_grad(
        &self,
        sw: &Switches,
        t: f64,
        x: &V,
        p: &V,
        lx: &mut V,
        lp: &mut V,
    ) -> f64 {
        self.m.running_cost_value_grad(sw, t, x, p, lx, lp)
    }
    fn event_cost(&self, k: usize, t: f64, x: &V, p: &V) -> f64 {
        self.m.event_cost(k, t, x, p)
    }
    fn event_cost_grad(&self, k: usize, t: f64, x: &V, p: &V, cx: &mut V, cp: &mut V) -> f64 {
        self.m.event_cost_grad(k, t, x, p, cx, cp)
    }
    fn final_cost(&self, t: f64, x: &V, p: &V) -> f64 {
        self.m.final_cost(t, x, p)
    }
    fn final_cost_grad(&self, t: f64, x: &V, p: &V, cx: &mut V, cp: &mut V) -> f64 {
        self.m.final_cost_grad(t, x, p, cx, cp)
    }
}

/// A generated model with p parameters, loaded twice (plain and with the sparse product),
/// and θ.
struct Case {
    family: &'static str,
    p: usize,
    loaded: InterpretedModel,
    sparse: SparseVjp,
    theta: DVector<f64>,
}

/// The generated models: (name, text generator, hand-written λᵀf_θ).
const FAMILIES: [(&str, fn(usize) -> String, VjpP); 2] = [
    ("impact", impact, impact_vjp_p),
    ("chain", chain, chain_vjp_p),
];

fn cases() -> Vec<Case> {
    let mut out = Vec::new();
    for (family, text, vjp_p) in FAMILIES {
        for p in TABLE_PS {
            let text = text(p);
            let loaded = InterpretedModel::from_source(&text).expect("the model loads");
            let theta = loaded.default_params();
            let n = loaded.nstates().0;
            let sparse = SparseVjp {
                m: InterpretedModel::from_source(&text).expect("the model loads"),
                fx: RefCell::new(DMatrix::zeros(n, n)),
                vjp_p,
            };
            out.push(Case {
                family,
                p,
                loaded,
                sparse,
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

/// The three runs of a case.
fn run(case: &Case, which: usize) -> Solution {
    let theta = black_box(&case.theta);
    match which {
        0 => solve(&case.loaded, theta, &opts(GradientMode::Forward)),
        1 => solve(&case.loaded, theta, &opts(GradientMode::Adjoint)),
        _ => solve(&case.sparse, theta, &opts(GradientMode::Adjoint)),
    }
    .expect("the model runs")
}

const NAMES: [&str; 3] = ["forward", "adjoint", "adjoint_sparse"];

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
    for (family, _, _) in FAMILIES {
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
        "{:>5} {:>12} {:>12} {:>16} {:>8} {:>8} {:>11} {:>10}",
        "p",
        "forward ms",
        "adjoint ms",
        "adj. sparse ms",
        "fwd st.",
        "adj st.",
        "record B",
        "|Δ|/|g|"
    );
    let mut t = vec![[0.0; 3]; cases.len()];
    for (row, &case) in t.iter_mut().zip(cases) {
        let sols: Vec<Solution> = (0..3).map(|w| run(case, w)).collect();
        for (w, cell) in row.iter_mut().enumerate() {
            *cell = median_ms(|| run(case, w));
        }
        let g = &sols[0].gradient;
        let scale = g.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let diff = sols[1..]
            .iter()
            .flat_map(|s| s.gradient.iter().zip(g).map(|(a, b)| (a - b).abs()))
            .fold(0.0f64, f64::max);
        println!(
            "{:>5} {:>12.3} {:>12.3} {:>16.3} {:>8} {:>8} {:>11} {:>10.1e}",
            case.p,
            row[0],
            row[1],
            row[2],
            sols[0].stats.steps,
            sols[1].stats.steps,
            sols[1].stats.record_bytes,
            diff / scale
        );
    }
    let at = |p: usize| TABLE_PS.iter().position(|&q| q == p).expect("tabled p");
    for (w, name) in [(1, "adjoint"), (2, "adjoint_sparse")] {
        let cross = TABLE_PS
            .iter()
            .zip(&t)
            .find(|(_, r)| r[w] < r[0])
            .map_or("none up to 1000".into(), |(p, _)| format!("p = {p}"));
        println!(
            "{name}: time(p = 1000) / time(p = 10) = {:.2} (target ≤ 3); faster than forward from {cross}",
            t[at(1000)][w] / t[at(10)][w]
        );
    }
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
