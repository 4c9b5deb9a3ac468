//! Every generated partial derivative against central finite differences.
//!
//! For each model (the files in `models/*.hyb` and a model using every construct of the
//! language), at seeded pseudo-random points: ∂f/∂x, ∂f/∂θ, ∂f/∂t per mode and switch
//! word, the fused Ṡ = f_x S + f_θ, ∇g/∂θg/∂ₜg per event, ∂R/∂x, ∂R/∂θ, ∂R/∂t, σ_j's
//! gradient, ∂h/∂x, ∂h/∂θ, ℓ/φ/Φ partials, ∂x₀/∂θ and dT/dθ. Central differences use
//! h = ε^(1/3)·|v| (ε^(1/3) at v = 0), so parameters like τ = 1e-8 get a relative step.
//! Both doors are checked: the interpreted model and the `hybrid!`-compiled one.
//!
//! The capability products too ([`check_products`]), under the consistent switch word and
//! under a random one (frozen branches are respected): λᵀf_x, λᵀf_θ, μᵀR_x, μᵀR_θ, μᵀR_t and
//! μᵀ∂x₀/∂θ against λ, μ times the (checked) dense Jacobians, and the second-order products
//! ∂ₓ(f_x S + f_θ)·v, ∂ₜ(f_x S + f_θ), ∂ₓ(ℓ_x S + ℓ_θ)·v, ∂ₜ(ℓ_x S + ℓ_θ) and ∂ₜℓ against
//! central differences of the first-derivative kernels (`rhs_sens`, `running_cost_value_grad`).

use mvad::interp::InterpretedModel;
use mvad::{At, HybridModel, ModelAlloc, Occurrence};
use mvad_tests::{model_files, Rng, Sink, SINK};
use nalgebra::{Const, DefaultAllocator, OMatrix, OVector};

fn vn<M: HybridModel>(m: &M, v: &[f64]) -> OVector<f64, M::N>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let mut o = OVector::<f64, M::N>::zeros_generic(m.nstates(), Const::<1>);
    o.as_mut_slice().copy_from_slice(v);
    o
}

fn vp<M: HybridModel>(m: &M, v: &[f64]) -> OVector<f64, M::P>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let mut o = OVector::<f64, M::P>::zeros_generic(m.nparams(), Const::<1>);
    o.as_mut_slice().copy_from_slice(v);
    o
}

/// Row-major copy of a nalgebra matrix.
fn rows<R: nalgebra::Dim, C: nalgebra::Dim>(m: &OMatrix<f64, R, C>) -> Vec<f64>
where
    DefaultAllocator: nalgebra::allocator::Allocator<R, C>,
{
    let mut v = Vec::with_capacity(m.nrows() * m.ncols());
    for r in 0..m.nrows() {
        for c in 0..m.ncols() {
            v.push(m[(r, c)]);
        }
    }
    v
}

/// A point: states, params, time.
#[derive(Clone, Debug)]
pub struct Pt {
    /// States.
    pub x: Vec<f64>,
    /// Params.
    pub p: Vec<f64>,
    /// Time.
    pub t: f64,
}

/// A random point near the model's defaults: θ = θ₀(1 + 0.2u), x = x₀(θ) + u·max(1, |x₀|)/2.
pub fn random_point<M: HybridModel>(m: &M, rng: &mut Rng) -> Pt
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let info = m.info();
    let p: Vec<f64> = info
        .param_defaults
        .iter()
        .map(|&d| {
            if d == 0.0 {
                rng.range(-0.3, 0.3)
            } else {
                d * rng.range(0.8, 1.2)
            }
        })
        .collect();
    let mut x0 = OVector::<f64, M::N>::zeros_generic(m.nstates(), Const::<1>);
    m.initial_state(&vp(m, &p), &mut x0);
    let x = x0
        .iter()
        .map(|&v| v + rng.range(-0.5, 0.5) * v.abs().max(1.0))
        .collect();
    Pt {
        x,
        p,
        t: rng.range(0.05, 1.5),
    }
}

/// Which variable block a derivative is taken in.
#[derive(Clone, Copy, Debug)]
enum Wrt {
    X,
    P,
    T,
}

/// [`fd_check`] of the three blocks ∂/∂x, ∂/∂θ, ∂/∂t of `val`, given in that order.
fn fd_check_xpt(what: &str, pt: &Pt, sym: [&[f64]; 3], val: &dyn Fn(&Pt) -> Vec<f64>) {
    for (wrt, sym) in [Wrt::X, Wrt::P, Wrt::T].into_iter().zip(sym) {
        fd_check(what, pt, wrt, sym, val);
    }
}

/// Compares `sym` (row-major outputs × vars of block `wrt`) with central differences of `val`.
fn fd_check(what: &str, pt: &Pt, wrt: Wrt, sym: &[f64], val: &dyn Fn(&Pt) -> Vec<f64>) {
    let nout = val(pt).len();
    let nvar = match wrt {
        Wrt::X => pt.x.len(),
        Wrt::P => pt.p.len(),
        Wrt::T => 1,
    };
    assert_eq!(sym.len(), nout * nvar, "{what}: size");
    fn get(q: &mut Pt, wrt: Wrt, j: usize) -> &mut f64 {
        match wrt {
            Wrt::X => &mut q.x[j],
            Wrt::P => &mut q.p[j],
            Wrt::T => &mut q.t,
        }
    }
    for j in 0..nvar {
        let mut q = pt.clone();
        let v = *get(&mut q, wrt, j);
        let h = f64::EPSILON.cbrt() * if v != 0.0 { v.abs() } else { 1.0 };
        *get(&mut q, wrt, j) = v + h;
        let up = val(&q);
        *get(&mut q, wrt, j) = v - h;
        let dn = val(&q);
        let h2 = (v + h) - (v - h);
        for i in 0..nout {
            let what = format!("{what}: d[{i}]/d{wrt:?}[{j}]");
            assert_fd(&what, sym[i * nvar + j], up[i], dn[i], h2, pt);
        }
    }
}

/// `sym` against the central difference (up − dn)/h2: to 1e-6 relative, plus the rounding of
/// up and dn amplified by 1/h2.
fn assert_fd(what: &str, sym: f64, up: f64, dn: f64, h2: f64, pt: &Pt) {
    let fd = (up - dn) / h2;
    let tol =
        1e-6 * sym.abs().max(fd.abs()) + 20.0 * f64::EPSILON * (up.abs() + dn.abs()) / h2 + 1e-9;
    assert!(
        (sym - fd).abs() <= tol,
        "{what}: symbolic {sym:e} vs FD {fd:e} at {pt:?}"
    );
}

/// `got` = Jᵀw for J (rows × cols, row-major `j`): to 8ε·(|J|ᵀ|w|)·rows (summation order).
fn assert_vjp(what: &str, got: &[f64], j: &[f64], w: &[f64]) {
    let cols = got.len();
    for (k, g) in got.iter().enumerate() {
        let want: f64 = w
            .iter()
            .enumerate()
            .map(|(r, wr)| wr * j[r * cols + k])
            .sum();
        let bound: f64 = w
            .iter()
            .enumerate()
            .map(|(r, wr)| (wr * j[r * cols + k]).abs())
            .sum();
        assert!(
            (g - want).abs() <= 8.0 * f64::EPSILON * bound * w.len() as f64,
            "{what}[{k}]: {g:e} vs {want:e}"
        );
    }
}

/// Checks the capability products of `m` at `pt` with switch word `sw` (see the module doc).
pub fn check_products<M: HybridModel>(m: &M, pt: &Pt, sw: u64, rng: &mut Rng)
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let sw = &mvad::Switches::from_bits(sw);
    let info = m.info().clone();
    let zn = || OVector::<f64, M::N>::zeros_generic(m.nstates(), Const::<1>);
    let zp = || OVector::<f64, M::P>::zeros_generic(m.nparams(), Const::<1>);
    let znn = || OMatrix::<f64, M::N, M::N>::zeros_generic(m.nstates(), m.nstates());
    let znp = || OMatrix::<f64, M::N, M::P>::zeros_generic(m.nstates(), m.nparams());
    let mut random = |v: &mut [f64]| v.iter_mut().for_each(|e| *e = rng.range(-1.0, 1.0));
    let (mut lam, mut v, mut s) = (zn(), zn(), znp());
    random(lam.as_mut_slice());
    random(v.as_mut_slice());
    random(s.as_mut_slice());
    let (x, pv, t) = (vn(m, &pt.x), vp(m, &pt.p), pt.t);
    let at = At::new(t, &x, &pv);
    // The step along v and in t, and the points x ± h v, t ± ht.
    let h = f64::EPSILON.cbrt() * x.amax().max(1.0) / v.amax().max(f64::MIN_POSITIVE);
    let (mut xu, mut xd) = (x.clone(), x.clone());
    xu.axpy(h, &v, 1.0);
    xd.axpy(-h, &v, 1.0);
    let ht = f64::EPSILON.cbrt() * t.abs().max(1.0);
    let (tu, td) = (t + ht, t - ht);
    let compare = |what: &str, sym: &[f64], up: &[f64], dn: &[f64], h2: f64| {
        for (i, ((a, u), d)) in sym.iter().zip(up).zip(dn).enumerate() {
            assert_fd(&format!("{} {what}[{i}]", info.name), *a, *u, *d, h2, pt);
        }
    };

    for mode in 0..info.modes.len() {
        let what = |w: &str| format!("mode {mode} {w}");
        let pt_at = |t: f64, x| mvad::Point::new(mode, sw, t, x, &pv);
        // λᵀf_x, λᵀf_θ.
        let (mut fx, mut fp) = (znn(), znp());
        m.rhs_jac_x(pt_at(t, &x), &mut fx);
        m.rhs_jac_p(pt_at(t, &x), &mut fp);
        let (mut vx, mut vpp) = (zn(), zp());
        m.rhs_vjp(pt_at(t, &x), &lam, &mut vx, &mut vpp);
        let l = lam.as_slice();
        assert_vjp(&what("λᵀf_x"), vx.as_slice(), &rows(&fx), l);
        assert_vjp(&what("λᵀf_θ"), vpp.as_slice(), &rows(&fp), l);
        // The adjoint's products: −(λᵀf_x + w ℓ_x) and g += −a (λᵀf_θ + w ℓ_θ), against the
        // dense Jacobians with ℓ's gradient as one more row weighted by w.
        let w = 0.7;
        let (mut lx, mut lp) = (zn(), zp());
        m.running_cost_value_grad(sw, At::new(t, &x, &pv), &mut lx, &mut lp);
        let lw: Vec<f64> = l.iter().copied().chain([w]).collect();
        let mut rate = zn();
        m.adjoint_rate(pt_at(t, &x), &lam, w, &mut rate);
        let neg: Vec<f64> = rate.iter().map(|r| -r).collect();
        let jx: Vec<f64> = rows(&fx).into_iter().chain(lx.iter().copied()).collect();
        assert_vjp(&what("adjoint_rate"), &neg, &jx, &lw);
        let mut g = zp();
        m.adjoint_quadrature_add(pt_at(t, &x), &lam, w, -1.0, &mut g);
        let jp: Vec<f64> = rows(&fp).into_iter().chain(lp.iter().copied()).collect();
        assert_vjp(&what("adjoint_quadrature_add"), g.as_slice(), &jp, &lw);
        // It adds (scaled) to what g holds: g + 2.5·(−G) = −1.5·G, G = λᵀf_θ + w ℓ_θ.
        let once = g.clone();
        m.adjoint_quadrature_add(pt_at(t, &x), &lam, w, 2.5, &mut g);
        for (k, (a, b)) in g.iter().zip(&once).enumerate() {
            let want = -1.5 * b;
            assert!(
                (a - want).abs() <= 1e-14 * (1.0 + b.abs()),
                "{}[{k}]: {a:e} vs {want:e}",
                what("adjoint_quadrature_add adds")
            );
        }
        // G's support (`gradient_support`, what the sweep's per-step work runs over): the
        // columns of f_θ and ℓ_θ outside it are zero, and the product leaves g alone there.
        if let Some(support) = m.gradient_support(mode) {
            let np = lp.len();
            assert!(
                support.windows(2).all(|s| s[0] < s[1]) && support.iter().all(|&k| k < np),
                "{}: {support:?}",
                what("gradient_support")
            );
            let mut g = zp();
            g.fill(7.0);
            m.adjoint_quadrature_add(pt_at(t, &x), &lam, w, 1.0, &mut g);
            for k in (0..np).filter(|k| !support.contains(k)) {
                let column_zero = fp.column(k).iter().all(|&v| v == 0.0) && lp[k] == 0.0;
                assert!(
                    column_zero && g[k] == 7.0,
                    "{}: parameter {k} is outside {support:?}",
                    what("gradient_support")
                );
            }
        }
        // ∂ₓ(f_x S + f_θ)·v and ∂ₜ(f_x S + f_θ) against differences of rhs_sens.
        let ds = |t: f64, x: &OVector<f64, M::N>| {
            let (mut f, mut ds) = (zn(), znp());
            m.rhs_sens(mvad::Point::new(mode, sw, t, x, &pv), &s, &mut f, &mut ds);
            ds.as_slice().to_vec()
        };
        let mut out = znp();
        m.rhs_sens_dir_x(pt_at(t, &x), &s, &v, &mut out);
        compare(
            &what("B v"),
            out.as_slice(),
            &ds(t, &xu),
            &ds(t, &xd),
            2.0 * h,
        );
        m.rhs_sens_dt(pt_at(t, &x), &s, &mut out);
        compare(
            &what("∂ₜṠ"),
            out.as_slice(),
            &ds(tu, &x),
            &ds(td, &x),
            tu - td,
        );
        if !m.rhs_depends_on_t(mode) {
            assert!(out.iter().all(|&e| e == 0.0), "{}", what("autonomous ∂ₜṠ"));
        }
    }

    // ∂ₓ(ℓ_x S + ℓ_θ)·v, ∂ₜ(ℓ_x S + ℓ_θ) and ∂ₜℓ against differences of ℓ and its gradient.
    let lsens = |t: f64, x: &OVector<f64, M::N>| {
        let (mut lx, mut lp) = (zn(), zp());
        let l = m.running_cost_value_grad(sw, At::new(t, x, &pv), &mut lx, &mut lp);
        lp.gemv_tr(1.0, &s, &lx, 1.0);
        (l, lp.as_slice().to_vec())
    };
    let mut out = zp();
    m.running_cost_sens_dir_x(sw, at, &s, &v, &mut out);
    compare(
        "D v",
        out.as_slice(),
        &lsens(t, &xu).1,
        &lsens(t, &xd).1,
        2.0 * h,
    );
    let lt = m.running_cost_sens_dt(sw, at, &s, &mut out);
    let ((lu, su), (ld, sd)) = (lsens(tu, &x), lsens(td, &x));
    compare("∂ₜq̇_θ", out.as_slice(), &su, &sd, tu - td);
    compare("∂ₜℓ", &[lt], &[lu], &[ld], tu - td);

    // μᵀR_x, μᵀR_θ, μᵀR_t per event and μᵀ∂x₀/∂θ.
    let mu = lam.as_slice();
    for k in 0..info.events.len() {
        let what = |w: &str| format!("{} event {k} {w}", info.name);
        let (mut rx, mut rp, mut rt) = (znn(), znp(), zn());
        m.reset_jac(Occurrence::new(k, 0), at, &mut rx, &mut rp, &mut rt);
        let (mut vx, mut vpp) = (zn(), zp());
        let vt = m.reset_vjp(Occurrence::new(k, 0), at, &lam, &mut vx, &mut vpp);
        assert_vjp(&what("μᵀR_x"), vx.as_slice(), &rows(&rx), mu);
        assert_vjp(&what("μᵀR_θ"), vpp.as_slice(), &rows(&rp), mu);
        assert_vjp(&what("μᵀR_t"), &[vt], rt.as_slice(), mu);
        // The pair product: the same numbers, bit for bit, for each of two cotangents (λ and
        // a second one, -2λ + 1, so that no entry of it is a multiple of λ's).
        let mu2 = lam.map(|l| 1.0 - 2.0 * l);
        let (mut vx2, mut vp2) = (zn(), zp());
        let (mut vx1, mut vp1) = (zn(), zp());
        let (t1, t2) = m.reset_vjp_pair(
            Occurrence::new(k, 0),
            at,
            (&lam, &mu2),
            (&mut vx1, &mut vp1),
            (&mut vx2, &mut vp2),
        );
        let (mut wx2, mut wp2) = (zn(), zp());
        let u2 = m.reset_vjp(Occurrence::new(k, 0), at, &mu2, &mut wx2, &mut wp2);
        assert_eq!((t1, vx1, vp1), (vt, vx, vpp), "{}", what("pair, first"));
        assert_eq!((t2, vx2, vp2), (u2, wx2, wp2), "{}", what("pair, second"));
    }
    let mut dx0 = znp();
    m.initial_state_jac(&pv, &mut dx0);
    let mut v0 = zp();
    m.initial_state_vjp(&pv, &lam, &mut v0);
    assert_vjp(
        &format!("{} μᵀ∂x₀/∂θ", info.name),
        v0.as_slice(),
        &rows(&dx0),
        mu,
    );
}

/// A scalar s(t, x, θ) of `m` whose gradient method `grad` fills ∂ₓs and ∂θs and returns
/// ∂ₜs, against central differences of its `value` at `pt`.
fn check_scalar<M: HybridModel>(
    m: &M,
    pt: &Pt,
    what: &str,
    value: impl Fn(f64, &OVector<f64, M::N>, &OVector<f64, M::P>) -> f64,
    grad: impl FnOnce(&mut OVector<f64, M::N>, &mut OVector<f64, M::P>) -> f64,
) where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let mut gx = OVector::<f64, M::N>::zeros_generic(m.nstates(), Const::<1>);
    let mut gp = OVector::<f64, M::P>::zeros_generic(m.nparams(), Const::<1>);
    let gt = grad(&mut gx, &mut gp);
    let val = |q: &Pt| vec![value(q.t, &vn(m, &q.x), &vp(m, &q.p))];
    fd_check_xpt(what, pt, [gx.as_slice(), gp.as_slice(), &[gt]], &val);
}

/// Checks every partial of `m` at `pt` with switch word `sw`.
pub fn check_model<M: HybridModel>(m: &M, pt: &Pt, sw: u64, rng: &mut Rng)
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let sw = &mvad::Switches::from_bits(sw);
    let info = m.info().clone();
    let n = pt.x.len();
    let p = pt.p.len();
    let zn = || OVector::<f64, M::N>::zeros_generic(m.nstates(), Const::<1>);
    let zp = || OVector::<f64, M::P>::zeros_generic(m.nparams(), Const::<1>);
    let znn = || OMatrix::<f64, M::N, M::N>::zeros_generic(m.nstates(), m.nstates());
    let znp = || OMatrix::<f64, M::N, M::P>::zeros_generic(m.nstates(), m.nparams());
    let (x, pv) = (vn(m, &pt.x), vp(m, &pt.p));
    let t = pt.t;
    let at = At::new(t, &x, &pv);
    // Flow, per mode.
    for mode in 0..info.modes.len() {
        let f = |q: &Pt| {
            let mut f = zn();
            m.rhs(
                mvad::Point::new(mode, sw, q.t, &vn(m, &q.x), &vp(m, &q.p)),
                &mut f,
            );
            f.as_slice().to_vec()
        };
        let mut fx = znn();
        m.rhs_jac_x(mvad::Point::new(mode, sw, t, &x, &pv), &mut fx);
        let mut fp = znp();
        m.rhs_jac_p(mvad::Point::new(mode, sw, t, &x, &pv), &mut fp);
        let mut ft = zn();
        m.rhs_dt(mvad::Point::new(mode, sw, t, &x, &pv), &mut ft);
        let what = format!("{} mode {mode} f", info.name);
        fd_check_xpt(&what, pt, [&rows(&fx), &rows(&fp), ft.as_slice()], &f);
        if !m.rhs_depends_on_t(mode) {
            assert!(
                ft.iter().all(|&v| v == 0.0),
                "{what}: autonomous flow with ∂f/∂t ≠ 0"
            );
        }
        // Sparsity: every entry outside the declared pattern is exactly zero.
        for r in 0..n {
            for c in 0..n {
                if !info.jacobian_sparsity[mode].contains(&(r, c)) {
                    assert_eq!(
                        fx[(r, c)],
                        0.0,
                        "{what}: f_x[{r},{c}] outside the sparsity pattern"
                    );
                }
            }
        }
        // Fused sensitivity right-hand side.
        let mut s = znp();
        s.iter_mut().for_each(|v| *v = rng.range(-1.0, 1.0));
        let (mut f1, mut ds) = (zn(), znp());
        m.rhs_sens(mvad::Point::new(mode, sw, t, &x, &pv), &s, &mut f1, &mut ds);
        let want = &fx * &s + &fp;
        assert_eq!(f1.as_slice(), f(pt).as_slice(), "{what}: rhs_sens f");
        for (a, b) in ds.iter().zip(want.iter()) {
            assert!(
                (a - b).abs() <= 1e-13 * (1.0 + b.abs()),
                "{what}: rhs_sens {a} vs {b}"
            );
        }
    }

    // Events.
    for k in 0..info.events.len() {
        let what = format!("{} event {k}", info.name);
        if info.events[k].is_time_event() {
            // A time event has no guard: its time τ_kj(θ) (occurrence 1, so a period counts)
            // and ∂τ/∂θ; NaN for a table that is not bound here.
            let tau = |q: &Pt| vec![m.event_time(Occurrence::new(k, 1), &vp(m, &q.p))];
            if tau(pt)[0].is_finite() {
                let mut dtau = zp();
                m.event_time_grad(Occurrence::new(k, 1), &pv, &mut dtau);
                fd_check(&format!("{what} time"), pt, Wrt::P, dtau.as_slice(), &tau);
            }
        } else {
            check_scalar(
                m,
                pt,
                &format!("{what} guard"),
                |t, x, p| m.guard(k, At::new(t, x, p)),
                |gx, gp| m.guard_grad(k, at, gx, gp),
            );
        }

        let r = |q: &Pt| {
            let mut xp = zn();
            m.reset(
                Occurrence::new(k, 0),
                At::new(q.t, &vn(m, &q.x), &vp(m, &q.p)),
                &mut xp,
            );
            xp.as_slice().to_vec()
        };
        let (mut rx, mut rp, mut rt) = (znn(), znp(), zn());
        m.reset_jac(Occurrence::new(k, 0), at, &mut rx, &mut rp, &mut rt);
        fd_check_xpt(
            &format!("{what} reset"),
            pt,
            [&rows(&rx), &rows(&rp), rt.as_slice()],
            &r,
        );

        check_scalar(
            m,
            pt,
            &format!("{what} cost"),
            |t, x, p| m.event_cost(Occurrence::new(k, 0), At::new(t, x, p)),
            |cx, cp| m.event_cost_grad(Occurrence::new(k, 0), at, cx, cp),
        );
    }

    // Switching functions.
    for j in 0..info.switches {
        check_scalar(
            m,
            pt,
            &format!("{} switch {j}", info.name),
            |t, x, p| m.switch_value(j, At::new(t, x, p)),
            |gx, gp| m.switch_grad(j, at, gx, gp),
        );
    }

    // Observables.
    let nobs = info.observables.len();
    let y = |q: &Pt| {
        let mut y = vec![0.0; nobs];
        m.observe(sw, At::new(q.t, &vn(m, &q.x), &vp(m, &q.p)), &mut y);
        y
    };
    let (mut yx, mut yp) = (vec![9.0; nobs * n], vec![9.0; nobs * p]);
    m.observe_jac(sw, at, &mut yx, &mut yp);
    fd_check(&format!("{} observe", info.name), pt, Wrt::X, &yx, &y);
    fd_check(&format!("{} observe", info.name), pt, Wrt::P, &yp, &y);

    // Costs.
    let l = |q: &Pt| vec![m.running_cost(sw, At::new(q.t, &vn(m, &q.x), &vp(m, &q.p)))];
    let (mut lx, mut lp) = (zn(), zp());
    let lv = m.running_cost_value_grad(sw, at, &mut lx, &mut lp);
    assert_eq!(lv, l(pt)[0], "running_cost_value_grad returns ℓ");
    fd_check(&format!("{} ℓ", info.name), pt, Wrt::X, lx.as_slice(), &l);
    fd_check(&format!("{} ℓ", info.name), pt, Wrt::P, lp.as_slice(), &l);
    check_scalar(
        m,
        pt,
        &format!("{} Φ", info.name),
        |t, x, p| m.final_cost(At::new(t, x, p)),
        |cx, cp| m.final_cost_grad(at, cx, cp),
    );

    // x₀(θ) and T(θ).
    let x0 = |q: &Pt| {
        let mut x0 = zn();
        m.initial_state(&vp(m, &q.p), &mut x0);
        x0.as_slice().to_vec()
    };
    let mut dx0 = znp();
    m.initial_state_jac(&pv, &mut dx0);
    fd_check(&format!("{} x0", info.name), pt, Wrt::P, &rows(&dx0), &x0);
    let hz = |q: &Pt| vec![m.horizon(&vp(m, &q.p)).unwrap_or(0.0)];
    let mut dt = zp();
    m.horizon_grad(&pv, &mut dt);
    fd_check(&format!("{} T", info.name), pt, Wrt::P, dt.as_slice(), &hz);
}

/// The switch word of the branches active at `pt` (bit j iff σ_j > 0), as the runtime keeps it.
pub fn consistent_switches<M: HybridModel>(m: &M, pt: &Pt) -> u64
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let (x, p) = (vn(m, &pt.x), vp(m, &pt.p));
    (0..m.info().switches)
        .filter(|&j| m.switch_value(j, At::new(pt.t, &x, &p)) > 0.0)
        .fold(0, |w, j| w | (1 << j))
}

/// The switch bits (0..64) of the model's qp constraints.
fn qp_switch_mask<M: HybridModel>(m: &M) -> u64
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let mut mask = 0u64;
    for q in m.qps() {
        if let Some(first) = q.switches {
            let le = q
                .kinds
                .iter()
                .filter(|k| **k == mvad::qp::ConstraintKind::Le)
                .count();
            for j in first..(first + le).min(64) {
                mask |= 1 << j;
            }
        }
    }
    mask
}

/// Whether every mode's flow is finite at `pt` under the frozen bits `sw`.
fn flows_finite<M: HybridModel>(m: &M, pt: &Pt, sw: u64) -> bool
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let sw = &mvad::Switches::from_bits(sw);
    let (x, pv) = (vn(m, &pt.x), vp(m, &pt.p));
    let mut f = OVector::<f64, M::N>::zeros_generic(m.nstates(), Const::<1>);
    (0..m.info().modes.len()).all(|mode| {
        m.rhs(mvad::Point::new(mode, sw, pt.t, &x, &pv), &mut f);
        f.iter().all(|v| v.is_finite())
    })
}

fn check_all<M: HybridModel>(m: &M, seed: u64, npoints: usize)
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let mut rng = Rng::new(seed);
    let mut rng_products = Rng::new(seed ^ 0x5eed);
    let nsw = m.info().switches.min(64) as u32;
    for _ in 0..npoints {
        let pt = random_point(m, &mut rng);
        let sw = consistent_switches(m, &pt);
        check_model(m, &pt, sw, &mut rng);
        check_products(m, &pt, sw, &mut rng_products);
        // Any frozen word (the branches need not be the active ones) — except for the bits
        // of qp constraints, which must hold a consistent active set (|u| ≤ 1 held active on
        // both sides at once has no solution): those keep the point's own bits.
        let qp_bits = qp_switch_mask(m);
        let random_word = (rng_products.uniform() * 2f64.powi(nsw as i32)) as u64;
        let random_word = (random_word & !qp_bits) | (sw & qp_bits);
        // A branch held outside its domain (abs(x) taken as −x under pow(abs(x) + 1, b) at
        // x > 1) makes the flow itself NaN: nothing to differentiate there.
        if flows_finite(m, &pt, random_word) {
            check_products(m, &pt, random_word, &mut rng_products);
        }
    }
}

#[test]
fn interpreted_models_match_finite_differences() {
    let files = model_files();
    assert!(files.len() >= 4, "models/*.hyb not found");
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../models");
    for (name, src) in files {
        let mut m = InterpretedModel::from_source(&src).unwrap_or_else(|e| panic!("{name}: {e:?}"));
        mvad::load::bind_tables(&mut m, &dir, &[]).unwrap_or_else(|e| panic!("{name}: {e}"));
        check_all(&m, 7, 20);
    }
    let m = InterpretedModel::from_source(SINK).expect("sink model");
    // Six kinks of the flows and ℓ, and the observables' max(y, c) and if z <= 1 (their
    // abs(x) is the flow's).
    assert_eq!(m.info().switches, 8);
    check_all(&m, 11, 60);
}

#[test]
fn compiled_models_match_finite_differences() {
    check_all(&models::bouncing_ball::BouncingBall::new(), 1, 20);
    check_all(&models::ceiling::Ceiling::new(), 2, 20);
    check_all(&models::e2_sweep::E2Sweep::new(), 3, 20);
    check_all(&models::stiff_relay::StiffRelay::new(), 4, 20);
    check_all(&models::thermostat::Thermostat::new(), 5, 20);
    check_all(&models::zeno_ball::ZenoBall::new(), 6, 20);
    check_all(&models::qp_kink::QpKink::new(), 13, 20);
    check_all(&models::qp_cart::QpCart::new(), 14, 20);
    check_all(&Sink::new(), 12, 60);
    let a = models::queue::Arrivals::generate(10, 1);
    let q = models::queue::Queue::new(models::queue::QueueTables {
        arrivals: a.table().expect("table"),
    })
    .expect("binds");
    check_all(&q, 13, 20);
    let q = models::queue::stretched::StretchedQueue::new(
        models::queue::stretched::StretchedQueueTables {
            arrivals: a.table().expect("table"),
        },
    )
    .expect("binds");
    check_all(&q, 14, 20);
}
