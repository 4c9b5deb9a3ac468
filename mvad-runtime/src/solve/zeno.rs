//! Accumulating events: detecting a Zeno sequence, a reset that leaves the state stuck on
//! its guard, and the limit the run is continued with.
//!
//! After each user event the dwell times are checked for geometric shrinking (the last
//! [`ZENO_RATIOS`] ratios below [`ZENO_MAX_RATIO`] and within 5 % of each other). Once
//! established, the run stops when an event grazes (its crossing cosine
//! |dg/dt| / (|∇g||f⁻| + |∂g/∂t|) is below max(τ, [`ZENO_GRAZE`]),
//! independent of a user's τ = 0, since ever smaller hops would eventually be lost in
//! rounding) or the estimated remaining time t* − t_k is below 1e-9·max(1, t*).
//!
//! ## The tail as a geometric series, and its derivative
//! A quantity a_k read after event k (the event time t_k, the post-event state x_k⁺, the cost
//! accumulated so far C_k) changes by a_k − a_{k−1} = B ρ_aᵏ per event in a geometric tail
//! (for the bouncing ball with restitution e: t_k and v_k⁺ with ρ = e, C_k = Σ ∫h over bounces
//! with ρ = e³). Its limit is the sum of the series,
//!
//! ```text
//!   a_∞ = a_k + (a_k − a_{k−1}) (ρ + ρ² + …) = a_k + (a_k − a_{k−1}) ρ/(1 − ρ),
//!   ρ = (a_k − a_{k−1}) / (a_{k−1} − a_{k−2})                        (Aitken's Δ²),
//! ```
//!
//! applied twice over the last [`ZENO_SNAPS`] snapshots (the second pass removes a slowly
//! drifting ratio). B and ρ both depend on θ, so the derivative of the limit is the derivative
//! of this sum, by the chain rule through it:
//!
//! ```text
//!   da_∞/dθ = Σ_i (∂a_∞/∂a_i) da_i/dθ,
//!   ∂a_∞/∂a_k = 1/(1 − ρ)²,  ∂a_∞/∂a_{k−1} = −2ρ/(1 − ρ)²,  ∂a_∞/∂a_{k−2} = ρ²/(1 − ρ)²,
//! ```
//!
//! with da_i/dθ what the run carries at event i: t_i', d x_i⁺/dθ = S⁺ + f⁺ t_i' and dC_i/dθ.
//! This is exact whenever a_k is exactly geometric; extrapolating the sequence da_k/dθ
//! instead is not, since da_k/dθ − da_∞/dθ = (B' + B k ρ'/ρ) ρᵏ has the factor k (for the
//! ball, d/de of ∫v dt came out −3e-4 instead of 0 that way). If T > t* the state is held at its limit x*
//! on [t*, T] with ∂x/∂θ = dx*/dθ, and ∫_{t*}^T ℓ(t, x*, θ) dt is added with its derivative
//! −ℓ(t*, x*) dt*/dθ + ∫ (ℓ_x dx*/dθ + ℓ_θ) dt.

use super::Driver;
use crate::model::{At, HybridModel, ModelAlloc, Point};
use crate::reduce::{aitken_iterated_weights, FinalWork, GL8};
use nalgebra::{Const, DefaultAllocator, OMatrix, OVector};

/// How many dwell ratios must agree before a Zeno accumulation is declared.
pub(super) const ZENO_RATIOS: usize = 6;

/// Dwell ratios at or above this count as periodic, not accumulating.
const ZENO_MAX_RATIO: f64 = 0.999;

/// Cosine below which an event of an established Zeno sequence ends the run.
const ZENO_GRAZE: f64 = 1e-3;

/// Post-event snapshots kept for the Zeno limit: five, so Aitken's Δ² can be applied twice
/// (per-bounce terms of the form (a + bk)ρᵏ, as derivatives w.r.t. a restitution give,
/// need the second pass).
const ZENO_SNAPS: usize = 5;

/// Buffers for the snapshots of one user event, for the Zeno limit.
pub(super) struct Snapshot<M: HybridModel>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    t: f64,
    dt: OVector<f64, M::P>,
    x: OVector<f64, M::N>,
    dx: OMatrix<f64, M::N, M::P>,
    c: f64,
    g: OVector<f64, M::P>,
}

/// Dwell-time history and the last [`ZENO_SNAPS`] event snapshots.
pub(super) struct Zeno<M: HybridModel>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    times: [f64; ZENO_RATIOS + 2],
    count: usize,
    snaps: [Snapshot<M>; ZENO_SNAPS],
}

impl<M: HybridModel> Zeno<M>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    /// Snapshots for `model` whose derivatives are `p` wide (0 without sensitivities, which
    /// then are never recorded).
    pub(super) fn new(model: &M, p: M::P) -> Self {
        let n = model.nstates();
        let snap = || Snapshot {
            t: 0.0,
            dt: OVector::zeros_generic(p, Const::<1>),
            x: OVector::zeros_generic(n, Const::<1>),
            dx: OMatrix::zeros_generic(n, p),
            c: 0.0,
            g: OVector::zeros_generic(p, Const::<1>),
        };
        Zeno {
            times: [0.0; ZENO_RATIOS + 2],
            count: 0,
            snaps: std::array::from_fn(|_| snap()),
        }
    }

    /// The snapshot slot for the event being recorded now.
    fn slot(&mut self) -> &mut Snapshot<M> {
        &mut self.snaps[self.count % ZENO_SNAPS]
    }

    /// Registers the time of the event just recorded in `slot()`.
    fn push(&mut self, t: f64) {
        let k = self.times.len();
        self.times[self.count % k] = t;
        self.count += 1;
    }

    /// The common dwell ratio ρ if the last dwell times shrink geometrically.
    fn ratio(&self) -> Option<f64> {
        let k = self.times.len();
        if self.count < k {
            return None;
        }
        let t = |i: usize| self.times[(self.count - k + i) % k];
        let mut ratios = [0.0; ZENO_RATIOS];
        for (i, r) in ratios.iter_mut().enumerate() {
            let d0 = t(i + 1) - t(i);
            let d1 = t(i + 2) - t(i + 1);
            if !(d0 > 0.0 && d1 > 0.0) {
                return None;
            }
            *r = d1 / d0;
        }
        let (lo, hi) = ratios.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), &r| {
            (lo.min(r), hi.max(r))
        });
        let mean = ratios.iter().sum::<f64>() / ZENO_RATIOS as f64;
        (hi < ZENO_MAX_RATIO && hi - lo <= 0.05 * mean).then_some(mean)
    }

    /// (t_k, t_k − t_{k−1}) of the last event.
    fn last_dwell(&self) -> (f64, f64) {
        let k = self.times.len();
        let last = self.times[(self.count - 1) % k];
        let prev = self.times[(self.count - 2) % k];
        (last, last - prev)
    }

    /// The limit of a snapshot quantity and its weights w over the snapshots (oldest first):
    /// iterated Aitken Δ² over the last [`ZENO_SNAPS`] snapshots with w_i = ∂limit/∂value_i
    /// ([`aitken_iterated_weights`]), or the last snapshot itself (w = (0, …, 0, 1)) when
    /// `hold_last` (a state stuck on its guard).
    fn limit(&self, hold_last: bool, f: impl Fn(&Snapshot<M>) -> f64) -> (f64, [f64; ZENO_SNAPS]) {
        let mut w = [0.0; ZENO_SNAPS];
        if hold_last {
            w[ZENO_SNAPS - 1] = 1.0;
            return (f(self.snap(ZENO_SNAPS - 1)), w);
        }
        let seq: [f64; ZENO_SNAPS] = std::array::from_fn(|i| f(self.snap(i)));
        let (lim, wv) = aitken_iterated_weights(&seq);
        w.copy_from_slice(&wv);
        (lim, w)
    }

    /// The derivative of a limit with weights `w` ([`Zeno::limit`]): Σ_i w_i d_i, with d_i
    /// the derivative the snapshot i carries.
    fn limit_derivative(&self, w: &[f64; ZENO_SNAPS], d: impl Fn(&Snapshot<M>) -> f64) -> f64 {
        (0..ZENO_SNAPS).map(|i| w[i] * d(self.snap(i))).sum()
    }

    /// Snapshot i of the last [`ZENO_SNAPS`], oldest first.
    fn snap(&self, i: usize) -> &Snapshot<M> {
        &self.snaps[(self.count + i) % ZENO_SNAPS]
    }

    /// The time of the last snapshot.
    fn last_time(&self) -> f64 {
        self.snaps[(self.count + ZENO_SNAPS - 1) % ZENO_SNAPS].t
    }
}

/// The limit of an accumulation, extrapolated from the snapshots.
pub(super) struct Accumulation {
    /// The accumulation time t*.
    pub t_star: f64,
    /// C accumulated up to t* (running cost and event costs).
    pub cost: f64,
}

impl<M: HybridModel> Driver<'_, M>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    /// Records the post-event snapshot of the event that fired at t (x⁺, S⁺ + f⁺t', t', C and
    /// dC/dθ so far, including ℓ⁺t' for the running cost the event moves) and decides whether
    /// the run ends here: `Some((t*, ρ))` once the dwell times shrink geometrically with
    /// ratio ρ, t* < T, and the event grazes or t* − t_k ≤ 1e-9·max(1, t*).
    pub(super) fn zeno_verdict(
        &mut self,
        t: f64,
        l_plus: f64,
        grazing: bool,
        cosine: f64,
    ) -> Option<(f64, f64)> {
        let c = self.y.q + self.c_ev.value();
        let snap = self.zeno.slot();
        snap.t = t;
        snap.x.copy_from(&self.x_plus);
        snap.c = c;
        if self.sens {
            snap.dt.copy_from(&self.dt);
            snap.dx.copy_from(&self.dtot);
            snap.g.copy_from(&self.y.qp);
            snap.g += &self.g_ev;
            snap.g.axpy(l_plus, &self.dt, 1.0);
        }
        self.zeno.push(t);
        let r = self.zeno.ratio().filter(|&r| r > 0.0)?;
        let (tk, dk) = self.zeno.last_dwell();
        let t_star = tk + dk * r / (1.0 - r);
        let remaining = t_star - tk;
        let zeno_graze = grazing || cosine < ZENO_GRAZE;
        (t_star < self.t_end && (zeno_graze || remaining <= 1e-9 * t_star.abs().max(1.0)))
            .then_some((t_star, r))
    }

    /// Whether event k's reset left the state stuck on its guard: the flow approached the
    /// guard (d·ġ⁻ > 0), the reset stopped or reversed that approach to first order
    /// (d·ġ⁺ ≤ 0 at x⁺) and yet a short Heun probe x⁺ + δ/2 (f⁺ + f(x⁺ + δ f⁺)),
    /// δ = 1e-6·max(|t_k|, 1), lands on the firing side of the guard again. Without a crossing
    /// the event cannot fire again and the state would sink through the guard (the bouncing
    /// ball with e = 0, or a Zeno sequence too fine to resolve): events accumulate at t_k, and
    /// the run ends there with the state held at x⁺. `rate_minus` is ∇g·f⁻ + ∂g/∂t.
    pub(super) fn stuck_after_reset(
        &mut self,
        k: usize,
        t: f64,
        mode: usize,
        rate_minus: f64,
    ) -> bool {
        let (model, p) = (self.model, self.p);
        let d = model.info().events[k].direction.sign();
        if d * rate_minus <= 0.0 {
            return false;
        }
        let gt = model.guard_grad(k, At::new(t, &self.x_plus, p), &mut self.gx, &mut self.gp);
        if d * (self.gx.dot(&self.f_plus) + gt) > 0.0 {
            return false;
        }
        // Relative to the event time (the time resolution there), not to the horizon T: the
        // verdict must be the same whether T lies just past t_k or 10⁶ times beyond it.
        let delta = 1e-6 * t.abs().max(1.0);
        let v_plus = d * model.guard(k, At::new(t, &self.x_plus, p));
        self.xs.copy_from(&self.x_plus);
        self.xs.axpy(delta, &self.f_plus, 1.0);
        model.rhs(
            Point::new(mode, &self.sw_next, t + delta, &self.xs, p),
            &mut self.work,
        );
        self.xe.copy_from(&self.x_plus);
        self.xe.axpy(0.5 * delta, &self.f_plus, 1.0);
        self.xe.axpy(0.5 * delta, &self.work, 1.0);
        let v2 = d * model.guard(k, At::new(t + delta, &self.xe, p));
        v2 > 0.0 && v2 > v_plus
    }

    /// Extrapolates the run to the accumulation point: x(T) = x*, ∂x(T)/∂θ = dx*/dθ into
    /// `x_final`, `s_final`, dC/dθ into `grad`, plus the rest of the running cost on
    /// [t*, T] with the state held at x*. `t_star_geo` is the geometric estimate of t*, used
    /// when Aitken's extrapolation of the event times is not usable.
    pub(super) fn extrapolate_accumulation(
        &self,
        t_star_geo: f64,
        fw: &mut FinalWork<M>,
        x_final: &mut OVector<f64, M::N>,
        s_final: &mut OMatrix<f64, M::N, M::P>,
        grad: &mut OVector<f64, M::P>,
    ) -> Accumulation {
        let (model, p, sens, t_end) = (self.model, self.p, self.sens, self.t_end);
        let z = &self.zeno;
        // Stuck on a guard: the limit is the last post-event state itself.
        let hold = self.stuck.is_some();
        let (t_lim, wt) = z.limit(hold, |s| s.t);
        let mut dt_star = OVector::<f64, M::P>::zeros_generic(model.nparams(), Const::<1>);
        let t_star = if t_lim.is_finite() && t_lim >= z.last_time() {
            if sens {
                for j in 0..dt_star.len() {
                    dt_star[j] = z.limit_derivative(&wt, |s| s.dt[j]);
                }
            }
            t_lim
        } else {
            if sens {
                dt_star.copy_from(&z.snap(ZENO_SNAPS - 1).dt);
            }
            t_star_geo
        };
        for i in 0..x_final.len() {
            let (xi, wx) = z.limit(hold, |s| s.x[i]);
            x_final[i] = xi;
            if sens {
                for j in 0..s_final.ncols() {
                    s_final[(i, j)] = z.limit_derivative(&wx, |s| s.dx[(i, j)]);
                }
            }
        }
        let (mut cost, wc) = z.limit(hold, |s| s.c);
        if sens {
            for j in 0..grad.len() {
                grad[j] = z.limit_derivative(&wc, |s| s.g[j]);
            }
        }
        // Rest on [t*, T]: ∫ ℓ(t, x*) dt by 8-point Gauss–Legendre, and its derivative.
        if model.info().has_running_cost && t_end > t_star {
            let l_star = model.running_cost(&self.sw, At::new(t_star, x_final, p));
            if sens {
                grad.axpy(-l_star, &dt_star, 1.0);
            }
            let (c0, r0) = (0.5 * (t_star + t_end), 0.5 * (t_end - t_star));
            for &(xi, wi) in &GL8 {
                let t = c0 + r0 * xi;
                let l = model.running_cost_value_grad(
                    &self.sw,
                    At::new(t, x_final, p),
                    &mut fw.cx,
                    &mut fw.cp,
                );
                cost += wi * r0 * l;
                if sens {
                    grad.gemv_tr(wi * r0, s_final, &fw.cx, 1.0);
                    grad.axpy(wi * r0, &fw.cp, 1.0);
                }
            }
        }
        Accumulation { t_star, cost }
    }
}
