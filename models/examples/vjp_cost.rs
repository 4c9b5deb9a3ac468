//! The cost of one vector–Jacobian product λᵀf_x, λᵀf_θ (`ModelAdjoint::rhs_vjp`) of a loaded
//! model as the number of parameters grows, against the dense products the trait's default
//! forms (f_x and f_θ, then f_xᵀλ and f_θᵀλ), beside the forward sensitivity right-hand side
//! `rhs_sens` and the second-order product `rhs_sens_dir_x` for scale, and the time to load
//! the model (parse, differentiate, schedule, tapes).
//!
//! The models have n = 10 states and p parameters, each entering one equation through its own
//! term: der(x_i) = −x_i + Σ_{j ≡ i mod n} k_j·u_j with u_j = tanh(x_{i+1} − j/p) (a
//! transcendental per parameter) or u_j = (1 + j/p)·x_{i+1} (one multiplication). So f_θ has
//! p non-zero entries and f_x 2n, and a sparse product costs O(p), not O(n·p).
//!
//! `cargo run --release -p models --example vjp_cost`

use models::median_us;
use mvad::interp::InterpretedModel;
use mvad::{HybridModel, ModelAdjoint, ModelSecondOrder, ModelSens, Point, Switches};
use nalgebra::{DMatrix, DVector};
use std::hint::black_box;
use std::time::Instant;

/// The `.hyb` text of the model with `n` states and `p` parameters (tanh or linear terms).
fn wide_model(n: usize, p: usize, tanh: bool) -> String {
    let mut src = String::from("model Wide {");
    for j in 0..p {
        src.push_str(&format!(" param k{j} = {};", 0.5 + 0.001 * j as f64));
    }
    for i in 0..n {
        src.push_str(&format!(" state x{i} = {};", 0.1 * i as f64));
    }
    src.push_str(" flow {");
    for i in 0..n {
        let terms: Vec<String> = (i..p)
            .step_by(n)
            .map(|j| {
                let (xn, c) = ((i + 1) % n, j as f64 / p as f64);
                if tanh {
                    format!("k{j} * tanh(x{xn} - {c})")
                } else {
                    format!("k{j} * ({} * x{xn})", 1.0 + c)
                }
            })
            .collect();
        src.push_str(&format!(" der(x{i}) = -x{i} + {};", terms.join(" + ")));
    }
    src.push_str(" } horizon 1; }");
    src
}

/// [`median_us`] in ns.
fn median_ns(f: impl FnMut()) -> f64 {
    1e3 * median_us(f)
}

fn main() {
    let n = 10;
    println!("n = {n} states; times per call (median), loaded model\n");
    println!(
        "{:>6} {:>5} {:>8} {:>8} | {:>12} {:>14} | {:>12} {:>16} | {:>8}",
        "terms",
        "p",
        "nnz f_x",
        "nnz f_θ",
        "rhs_vjp",
        "dense f_xᵀλ+f_θᵀλ",
        "rhs_sens",
        "rhs_sens_dir_x",
        "load"
    );
    for (tanh, p) in [false, true]
        .into_iter()
        .flat_map(|t| [10, 100, 1000].map(|p| (t, p)))
    {
        let load = Instant::now();
        let m = InterpretedModel::from_source(&wide_model(n, p, tanh)).expect("model loads");
        let load = load.elapsed().as_secs_f64();
        let th = m.default_params();
        let x = DVector::from_fn(n, |i, _| 0.3 + 0.05 * i as f64);
        let lam = DVector::from_fn(n, |i, _| 1.0 - 0.1 * i as f64);
        let s = DMatrix::from_fn(n, p, |i, j| ((i * 7 + j * 3) % 11) as f64 / 11.0 - 0.5);
        let sw = Switches::default();
        let pt = Point::new(0, &sw, 0.0, &x, &th);
        let (mut vx, mut vp) = (DVector::zeros(n), DVector::zeros(p));
        let sparse = median_ns(|| {
            m.rhs_vjp(pt, black_box(&lam), &mut vx, &mut vp);
            black_box(&vp);
        });
        // What the dense default does: both Jacobians, then both transposed products.
        let (mut fx, mut fp) = (DMatrix::zeros(n, n), DMatrix::zeros(n, p));
        let (mut dx, mut dp) = (DVector::zeros(n), DVector::zeros(p));
        let dense = median_ns(|| {
            m.rhs_jac_x(pt, &mut fx);
            m.rhs_jac_p(pt, &mut fp);
            fx.tr_mul_to(black_box(&lam), &mut dx);
            fp.tr_mul_to(&lam, &mut dp);
            black_box(&dp);
        });
        assert!((&vp - &dp).amax() <= 1e-12 && (&vx - &dx).amax() <= 1e-12);
        let (mut f, mut ds) = (DVector::zeros(n), DMatrix::zeros(n, p));
        let sens = median_ns(|| {
            m.rhs_sens(pt, black_box(&s), &mut f, &mut ds);
            black_box(&ds);
        });
        let dir = median_ns(|| {
            m.rhs_sens_dir_x(pt, black_box(&s), &lam, &mut ds);
            black_box(&ds);
        });
        let nnz_x = m.info().jacobian_sparsity[0].len();
        let terms = if tanh { "tanh" } else { "linear" };
        println!(
            "{terms:>6} {p:>5} {nnz_x:>8} {p:>8} | {:>9.0} ns {:>14.0} ns | {:>9.0} ns {:>13.0} ns | {load:>6.3} s",
            sparse, dense, sens, dir
        );
    }
}
