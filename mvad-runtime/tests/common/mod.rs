//! Test support: a forward-mode dual number and a model adapter that derives every Jacobian
//! of the [`HybridModel`] trait from one generic description (`Spec`) by dual numbers, so
//! test models are written once, as plain formulas. Dual numbers are exact derivatives
//! (no truncation error); they also differentiate the hand-derived closed forms.
#![allow(dead_code)]

pub mod ball;
pub mod cases;
pub mod check;
pub mod models;

use mvad_runtime::model::{
    At, AtOf, HybridModel, ModelAdjoint, ModelDims, ModelInfo, ModelSecondOrder, ModelSens,
    Occurrence, Switches,
};
use nalgebra::{DVector, Dyn, OMatrix, OVector};
use std::ops::{Add, Div, Mul, Neg, Sub};

/// Number of dual directions.
pub const K: usize = 16;

/// A dual number v + Σ g_i ε_i.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct D {
    pub v: f64,
    pub g: [f64; K],
}

impl D {
    pub fn c(v: f64) -> D {
        D { v, g: [0.0; K] }
    }
    pub fn var(v: f64, i: usize) -> D {
        let mut d = D::c(v);
        d.g[i] = 1.0;
        d
    }
    fn chain(self, v: f64, dv: f64) -> D {
        let mut g = self.g;
        for x in g.iter_mut() {
            *x *= dv;
        }
        D { v, g }
    }
}

/// Scalars a model formula may be evaluated with.
pub trait Sc:
    Copy
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + Add<f64, Output = Self>
    + Sub<f64, Output = Self>
    + Mul<f64, Output = Self>
    + Div<f64, Output = Self>
{
    fn cst(v: f64) -> Self;
    fn val(self) -> f64;
    fn sqrt(self) -> Self;
    fn exp(self) -> Self;
    fn ln(self) -> Self;
    fn sin(self) -> Self;
    fn cos(self) -> Self;
    fn powi(self, n: i32) -> Self;
    fn tanh(self) -> Self;
}

impl Sc for f64 {
    fn cst(v: f64) -> Self {
        v
    }
    fn val(self) -> f64 {
        self
    }
    fn sqrt(self) -> Self {
        f64::sqrt(self)
    }
    fn exp(self) -> Self {
        f64::exp(self)
    }
    fn ln(self) -> Self {
        f64::ln(self)
    }
    fn sin(self) -> Self {
        f64::sin(self)
    }
    fn cos(self) -> Self {
        f64::cos(self)
    }
    fn powi(self, n: i32) -> Self {
        f64::powi(self, n)
    }
    fn tanh(self) -> Self {
        f64::tanh(self)
    }
}

impl Sc for D {
    fn cst(v: f64) -> Self {
        D::c(v)
    }
    fn val(self) -> f64 {
        self.v
    }
    fn sqrt(self) -> Self {
        let s = self.v.sqrt();
        self.chain(s, 0.5 / s)
    }
    fn exp(self) -> Self {
        let e = self.v.exp();
        self.chain(e, e)
    }
    fn ln(self) -> Self {
        self.chain(self.v.ln(), 1.0 / self.v)
    }
    fn sin(self) -> Self {
        self.chain(self.v.sin(), self.v.cos())
    }
    fn cos(self) -> Self {
        self.chain(self.v.cos(), -self.v.sin())
    }
    fn powi(self, n: i32) -> Self {
        self.chain(self.v.powi(n), n as f64 * self.v.powi(n - 1))
    }
    fn tanh(self) -> Self {
        let t = self.v.tanh();
        self.chain(t, 1.0 - t * t)
    }
}

impl Add for D {
    type Output = D;
    fn add(self, o: D) -> D {
        let mut g = self.g;
        for (a, b) in g.iter_mut().zip(o.g) {
            *a += b;
        }
        D { v: self.v + o.v, g }
    }
}
impl Sub for D {
    type Output = D;
    fn sub(self, o: D) -> D {
        self + (-o)
    }
}
impl Neg for D {
    type Output = D;
    fn neg(self) -> D {
        self.chain(-self.v, -1.0)
    }
}
impl Mul for D {
    type Output = D;
    fn mul(self, o: D) -> D {
        let mut g = [0.0; K];
        for (i, gi) in g.iter_mut().enumerate() {
            *gi = self.g[i] * o.v + self.v * o.g[i];
        }
        D { v: self.v * o.v, g }
    }
}
impl Div for D {
    type Output = D;
    fn div(self, o: D) -> D {
        let mut g = [0.0; K];
        for (i, gi) in g.iter_mut().enumerate() {
            *gi = (self.g[i] * o.v - self.v * o.g[i]) / (o.v * o.v);
        }
        D { v: self.v / o.v, g }
    }
}
impl Add<f64> for D {
    type Output = D;
    fn add(self, o: f64) -> D {
        D {
            v: self.v + o,
            g: self.g,
        }
    }
}
impl Sub<f64> for D {
    type Output = D;
    fn sub(self, o: f64) -> D {
        D {
            v: self.v - o,
            g: self.g,
        }
    }
}
impl Mul<f64> for D {
    type Output = D;
    fn mul(self, o: f64) -> D {
        self.chain(self.v * o, o)
    }
}
impl Div<f64> for D {
    type Output = D;
    fn div(self, o: f64) -> D {
        self.chain(self.v / o, 1.0 / o)
    }
}

/// A hybrid model as plain generic formulas. Defaults: x₀ = `X0` and T = `T_END` (constants),
/// no switches, identity reset, no costs.
pub trait Spec {
    /// A constant initial state, what the default `x0` writes (a model whose x₀ reads θ
    /// overrides `x0` instead).
    const X0: &'static [f64] = &[];
    /// A constant horizon, what the default `horizon` returns.
    const T_END: Option<f64> = None;
    fn info(&self) -> ModelInfo;
    fn x0<S: Sc>(&self, _p: &[S], x: &mut [S]) {
        assert_eq!(x.len(), Self::X0.len(), "Spec::X0 gives every state");
        for (xi, &v) in x.iter_mut().zip(Self::X0) {
            *xi = S::cst(v);
        }
    }
    fn horizon<S: Sc>(&self, _p: &[S]) -> Option<S> {
        Self::T_END.map(S::cst)
    }
    fn rhs<S: Sc>(&self, mode: usize, sw: u64, t: S, x: &[S], p: &[S], f: &mut [S]);
    fn guard<S: Sc>(&self, _k: usize, _t: S, _x: &[S], _p: &[S]) -> S {
        S::cst(1.0)
    }
    fn reset<S: Sc>(&self, _k: usize, _t: S, x: &[S], _p: &[S], xp: &mut [S]) {
        xp.copy_from_slice(x);
    }
    fn switch<S: Sc>(&self, _j: usize, _t: S, _x: &[S], _p: &[S]) -> S {
        S::cst(0.0)
    }
    fn observe<S: Sc>(&self, _t: S, _x: &[S], _p: &[S], _y: &mut [S]) {}
    fn running<S: Sc>(&self, _sw: u64, _t: S, _x: &[S], _p: &[S]) -> S {
        S::cst(0.0)
    }
    fn event_cost<S: Sc>(&self, _k: usize, _t: S, _x: &[S], _p: &[S]) -> S {
        S::cst(0.0)
    }
    fn final_cost<S: Sc>(&self, _t: S, _x: &[S], _p: &[S]) -> S {
        S::cst(0.0)
    }
}

/// [`HybridModel`] (Dyn sizes) of a [`Spec`], every derivative by dual numbers.
pub struct AdModel<T: Spec> {
    pub spec: T,
    pub info: ModelInfo,
}

impl<T: Spec> AdModel<T> {
    pub fn new(spec: T) -> Self {
        let info = spec.info();
        assert!(1 + info.states.len() + info.params.len() <= K);
        AdModel { spec, info }
    }
    pub fn defaults(&self) -> DVector<f64> {
        DVector::from_column_slice(&self.info.param_defaults)
    }
    fn n(&self) -> usize {
        self.info.states.len()
    }
    fn np(&self) -> usize {
        self.info.params.len()
    }
    /// Seeds t (direction 0), x (1..=n), p (n+1..) at the point `at`.
    fn seed(&self, at: At<'_, Dyn, Dyn>) -> (D, Vec<D>, Vec<D>) {
        let (t, x, p) = slices(at);
        let n = x.len();
        let td = D::var(t, 0);
        let xd = x
            .iter()
            .enumerate()
            .map(|(i, &v)| D::var(v, 1 + i))
            .collect();
        let pd = p
            .iter()
            .enumerate()
            .map(|(i, &v)| D::var(v, 1 + n + i))
            .collect();
        (td, xd, pd)
    }
    /// ∂/∂x and ∂/∂p of the scalar `f` at `at` into `gx`, `gp`; returns (f, ∂f/∂t).
    fn scalar_grad(
        &self,
        at: At<'_, Dyn, Dyn>,
        gx: &mut V,
        gp: &mut V,
        f: impl Fn(D, &[D], &[D]) -> D,
    ) -> (f64, f64) {
        let (td, xd, pd) = self.seed(at);
        let d = f(td, &xd, &pd);
        (d.v, self.split(&d, gx.as_mut_slice(), gp.as_mut_slice()))
    }
    /// The flow at `pt` in dual numbers seeded at (t, x, p).
    fn flow(&self, pt: Pt<'_>) -> Vec<D> {
        let (td, xd, pd) = self.seed(pt.at());
        let mut f = vec![D::c(0.0); self.n()];
        self.spec
            .rhs(pt.mode, pt.sw.low_word(), td, &xd, &pd, &mut f);
        f
    }
    fn split(&self, d: &D, gx: &mut [f64], gp: &mut [f64]) -> f64 {
        let n = self.n();
        gx.copy_from_slice(&d.g[1..1 + n]);
        gp.copy_from_slice(&d.g[1 + n..1 + n + self.np()]);
        d.g[0]
    }
}

type V = OVector<f64, Dyn>;
type Mx = OMatrix<f64, Dyn, Dyn>;
type Pt<'a> = mvad_runtime::Point<'a, Dyn, Dyn>;

/// out[(r, c)] = ∂v_r along dual direction `first + c`, for every entry of `out`.
fn partials(v: &[D], first: usize, out: &mut Mx) {
    for r in 0..out.nrows() {
        for c in 0..out.ncols() {
            out[(r, c)] = v[r].g[first + c];
        }
    }
}

impl<T: Spec> ModelSens for AdModel<T> {}
impl<T: Spec> ModelAdjoint for AdModel<T> {}
impl<T: Spec> ModelSecondOrder for AdModel<T> {}

impl<T: Spec> ModelDims for AdModel<T> {
    type N = Dyn;
    type P = Dyn;
}

impl<T: Spec> HybridModel for AdModel<T> {
    fn info(&self) -> &ModelInfo {
        &self.info
    }
    fn nstates(&self) -> Dyn {
        Dyn(self.n())
    }
    fn nparams(&self) -> Dyn {
        Dyn(self.np())
    }
    fn initial_state(&self, p: &V, x0: &mut V) {
        self.spec.x0(p.as_slice(), x0.as_mut_slice());
    }
    fn initial_state_jac(&self, p: &V, dx0: &mut Mx) {
        let pd = params_dual(p);
        let mut x = vec![D::c(0.0); self.n()];
        self.spec.x0(&pd, &mut x);
        partials(&x, 0, dx0);
    }
    fn horizon(&self, p: &V) -> Option<f64> {
        self.spec.horizon(p.as_slice())
    }
    fn horizon_grad(&self, p: &V, dt: &mut V) {
        let pd = params_dual(p);
        dt.fill(0.0);
        if let Some(h) = self.spec.horizon(&pd) {
            for c in 0..self.np() {
                dt[c] = h.g[c];
            }
        }
    }
    fn rhs(&self, pt: Pt<'_>, f: &mut V) {
        on_slices(pt.at(), |t, x, p| {
            self.spec
                .rhs(pt.mode, pt.sw.low_word(), t, x, p, f.as_mut_slice())
        });
    }
    fn rhs_jac_x(&self, pt: Pt<'_>, fx: &mut Mx) {
        partials(&self.flow(pt), 1, fx);
    }
    fn rhs_jac_p(&self, pt: Pt<'_>, fp: &mut Mx) {
        partials(&self.flow(pt), 1 + self.n(), fp);
    }
    fn rhs_dt(&self, pt: Pt<'_>, ft: &mut V) {
        let f = self.flow(pt);
        for r in 0..self.n() {
            ft[r] = f[r].g[0];
        }
    }
    fn rhs_depends_on_t(&self, _mode: usize) -> bool {
        true
    }
    fn guard(&self, k: usize, at: AtOf<'_, Self>) -> f64 {
        on_slices(at, |t, x, p| self.spec.guard(k, t, x, p))
    }
    fn guard_grad(&self, k: usize, at: AtOf<'_, Self>, gx: &mut V, gp: &mut V) -> f64 {
        self.scalar_grad(at, gx, gp, |t, x, p| self.spec.guard(k, t, x, p))
            .1
    }
    fn reset(&self, occ: Occurrence, at: AtOf<'_, Self>, xp: &mut V) {
        on_slices(at, |t, x, p| {
            self.spec.reset(occ.event, t, x, p, xp.as_mut_slice())
        });
    }
    fn reset_jac(&self, occ: Occurrence, at: AtOf<'_, Self>, rx: &mut Mx, rp: &mut Mx, rt: &mut V) {
        let (td, xd, pd) = self.seed(at);
        let mut r = vec![D::c(0.0); self.n()];
        self.spec.reset(occ.event, td, &xd, &pd, &mut r);
        for (rti, ri) in rt.iter_mut().zip(&r) {
            *rti = ri.g[0];
        }
        partials(&r, 1, rx);
        partials(&r, 1 + self.n(), rp);
    }
    fn switch_value(&self, j: usize, at: AtOf<'_, Self>) -> f64 {
        on_slices(at, |t, x, p| self.spec.switch(j, t, x, p))
    }
    fn switch_grad(&self, j: usize, at: AtOf<'_, Self>, gx: &mut V, gp: &mut V) -> f64 {
        self.scalar_grad(at, gx, gp, |t, x, p| self.spec.switch(j, t, x, p))
            .1
    }
    fn observe(&self, _sw: &Switches, at: AtOf<'_, Self>, y: &mut [f64]) {
        on_slices(at, |t, x, p| self.spec.observe(t, x, p, y));
    }
    fn observe_jac(&self, _sw: &Switches, at: AtOf<'_, Self>, yx: &mut [f64], yp: &mut [f64]) {
        let (td, xd, pd) = self.seed(at);
        let no = self.info.observables.len();
        let mut y = vec![D::c(0.0); no];
        self.spec.observe(td, &xd, &pd, &mut y);
        let (n, np) = (self.n(), self.np());
        for i in 0..no {
            yx[i * n..(i + 1) * n].copy_from_slice(&y[i].g[1..1 + n]);
            yp[i * np..(i + 1) * np].copy_from_slice(&y[i].g[1 + n..1 + n + np]);
        }
    }
    fn running_cost(&self, sw: &Switches, at: AtOf<'_, Self>) -> f64 {
        on_slices(at, |t, x, p| self.spec.running(sw.low_word(), t, x, p))
    }
    fn running_cost_value_grad(
        &self,
        sw: &Switches,
        at: AtOf<'_, Self>,
        lx: &mut V,
        lp: &mut V,
    ) -> f64 {
        self.scalar_grad(at, lx, lp, |t, x, p| {
            self.spec.running(sw.low_word(), t, x, p)
        })
        .0
    }
    fn event_cost(&self, occ: Occurrence, at: AtOf<'_, Self>) -> f64 {
        on_slices(at, |t, x, p| self.spec.event_cost(occ.event, t, x, p))
    }
    fn event_cost_grad(&self, occ: Occurrence, at: AtOf<'_, Self>, cx: &mut V, cp: &mut V) -> f64 {
        self.scalar_grad(at, cx, cp, |t, x, p| {
            self.spec.event_cost(occ.event, t, x, p)
        })
        .1
    }
    fn final_cost(&self, at: AtOf<'_, Self>) -> f64 {
        on_slices(at, |t, x, p| self.spec.final_cost(t, x, p))
    }
    fn final_cost_grad(&self, at: AtOf<'_, Self>, cx: &mut V, cp: &mut V) -> f64 {
        self.scalar_grad(at, cx, cp, |t, x, p| self.spec.final_cost(t, x, p))
            .1
    }
}

/// θ in dual numbers, θ_i seeded in direction i.
fn params_dual(p: &V) -> Vec<D> {
    p.iter().enumerate().map(|(i, &v)| D::var(v, i)).collect()
}

/// The point `at` as the plain (t, x, θ) a [`Spec`] formula reads.
fn slices<'a>(at: At<'a, Dyn, Dyn>) -> (f64, &'a [f64], &'a [f64]) {
    (at.t, at.x.as_slice(), at.p.as_slice())
}

/// `f` of the point `at` as plain (t, x, θ): a [`Spec`] formula evaluated in `f64`.
fn on_slices<R>(at: At<'_, Dyn, Dyn>, f: impl FnOnce(f64, &[f64], &[f64]) -> R) -> R {
    let (t, x, p) = slices(at);
    f(t, x, p)
}

/// Builds a `ModelInfo` quickly: running cost and horizon, no final cost.
pub fn info(
    name: &str,
    states: &[&str],
    params: &[(&str, f64)],
    modes: &[&str],
    events: Vec<mvad_runtime::EventInfo>,
    observables: &[&str],
    switches: usize,
) -> ModelInfo {
    let s = |v: &[&str]| v.iter().map(|x| x.to_string()).collect::<Vec<_>>();
    ModelInfo {
        name: name.into(),
        states: s(states),
        params: params.iter().map(|(n, _)| n.to_string()).collect(),
        param_defaults: params.iter().map(|(_, v)| *v).collect(),
        modes: s(modes),
        initial_mode: 0,
        events,
        observables: s(observables),
        switches,
        has_running_cost: true,
        has_final_cost: false,
        has_horizon: true,
        jacobian_sparsity: vec![vec![]; modes.len()],
    }
}

/// An event description.
pub fn ev(
    name: &str,
    dir: mvad_runtime::Direction,
    mode: Option<usize>,
    target: Option<usize>,
    has_cost: bool,
) -> mvad_runtime::EventInfo {
    mvad_runtime::EventInfo {
        name: name.into(),
        direction: dir,
        mode,
        target,
        has_reset: true,
        has_cost,
        trigger: mvad_runtime::Trigger::Guard,
    }
}

/// Central finite difference of `f` at `x` in direction i with step h.
pub fn central(f: impl Fn(&DVector<f64>) -> f64, x: &DVector<f64>, i: usize, h: f64) -> f64 {
    let mut a = x.clone();
    let mut b = x.clone();
    a[i] += h;
    b[i] -= h;
    (f(&a) - f(&b)) / (2.0 * h)
}
