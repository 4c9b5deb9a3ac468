//! The backward sweep (the paper's Algorithm 3): λ from T down to 0 over the forward record,
//! through every jump, with dC/dθ accumulated on the way.
//!
//! With w the cotangent of C and samples (t_s, w_s) of the observables y = h(t, x, θ):
//!
//! 1. At T: λ(T) = w Φ_xᵀ and g = w [Φ_θ + (ℓ(T) + Φ_x f(T) + Φ_t) dT/dθ] (f(T), ℓ(T) in
//!    the final mode and bits, as `reduce::final_terms` has them forwards).
//! 2. Backwards over the record's items: on a segment, λ̇ = −f_xᵀλ − w ℓ_xᵀ and
//!    ġ = −(f_θᵀλ + w ℓ_θᵀ) from its end to its start ([`crate::integrate::Backward`], any
//!    method, steps of negative size); at a jump, its transpose ([`super::transpose`]).
//! 3. A sample at t_s adds h_xᵀw_s to λ and h_θᵀw_s to g where the sweep passes t_s. Samples
//!    are right-continuous, as the trajectory record is (`Trajectory::sample`): one at an
//!    event time t_k takes x(t_k⁺), the state after every jump at t_k, so it is added before
//!    those jumps are undone; one at T takes x(T) after any jump at T.
//! 4. At t = 0: g += λ(0)ᵀ∂x₀/∂θ ([`crate::model::ModelAdjoint::initial_state_vjp`]).
//!
//! Then g = w dC/dθ + Σ_s w_sᵀ dy(t_s)/dθ: the sum of every term of DESIGN.md's dC/dθ,
//! transposed. The integrator restarts at every segment start and every sample (λ jumps
//! there), its first step seeded with the last step's size. It runs in the segment's local
//! time s = t − t_start (see [`super::record`]).

use super::record::{FinalState, Item, Tape};
use super::transpose::{shift_error, transpose_jump, JumpWork, ShiftWork};
use crate::error::SolveError;
use crate::integrate::{AdjState, Integrator, StageVector};
use crate::model::{HybridModel, ModelAlloc, Point};
use crate::solution::{Options, Stats};
use nalgebra::{Const, DefaultAllocator, Dim, OVector};

/// The cotangent w_s of the observables at one sample time t_s.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Sample<'a> {
    /// t_s.
    pub t: f64,
    /// w_s, one entry per observable.
    pub w: &'a [f64],
}

/// What a sweep returns: the pulled-back gradient and the backward integrator's counters.
pub(crate) struct SweepOut {
    /// w dC/dθ + Σ_s w_sᵀ dy(t_s)/dθ.
    pub gradient: Vec<f64>,
    /// Steps, rejections and evaluations of the backward integration.
    pub stats: Stats,
    /// The estimated global error of `gradient` from the sweep's local errors
    /// (`Options::global_error`; see `integrate/global_error.rs`).
    pub error: Option<Vec<f64>>,
}

/// Scratch for the samples: ∂h/∂x (nobs×n), ∂h/∂θ (nobs×p), row-major, and x(t_s).
struct SampleWork<M: HybridModel>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    yx: Vec<f64>,
    yp: Vec<f64>,
    x: OVector<f64, M::N>,
}

impl<M: HybridModel> SampleWork<M>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    /// λ += h_xᵀ w and g += h_θᵀ w at (t, `self.x`).
    fn add(
        &mut self,
        model: &M,
        p: &OVector<f64, M::P>,
        s: &Sample<'_>,
        y: &mut AdjState<M::N, M::P>,
    ) {
        if s.w.iter().all(|&w| w == 0.0) {
            return;
        }
        let (n, np) = (y.lam.len(), y.g.len());
        model.observe_jac(s.t, &self.x, p, &mut self.yx, &mut self.yp);
        for (i, &wi) in s.w.iter().enumerate() {
            if wi == 0.0 {
                continue;
            }
            for (l, v) in y.lam.iter_mut().zip(&self.yx[i * n..(i + 1) * n]) {
                *l += wi * v;
            }
            for (g, v) in y.g.iter_mut().zip(&self.yp[i * np..(i + 1) * np]) {
                *g += wi * v;
            }
        }
    }
}

/// λ(T) = w Φ_xᵀ and g = w [Φ_θ + (ℓ(T) + Φ_x f(T) + Φ_t) dT/dθ] into `y`.
fn terminal<M: HybridModel>(
    model: &M,
    p: &OVector<f64, M::P>,
    fin: &FinalState,
    cw: f64,
    dt_end: &OVector<f64, M::P>,
    x: &mut OVector<f64, M::N>,
    y: &mut AdjState<M::N, M::P>,
) where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let info = model.info();
    y.lam.fill(0.0);
    y.g.fill(0.0);
    if cw == 0.0 {
        return;
    }
    x.as_mut_slice().copy_from_slice(&fin.x);
    let mut rate = 0.0;
    if info.has_final_cost {
        let mut f = x.clone_owned();
        let phi_t = model.final_cost_grad(fin.t, x, p, &mut y.lam, &mut y.g);
        model.rhs(Point::new(fin.mode, &fin.sw, fin.t, x, p), &mut f);
        rate += y.lam.dot(&f) + phi_t;
        y.lam *= cw;
        y.g *= cw;
    }
    if info.has_running_cost {
        rate += model.running_cost(&fin.sw, fin.t, x, p);
    }
    if rate != 0.0 {
        y.g.axpy(cw * rate, dt_end, 1.0);
    }
}

/// Runs the sweep over `tape` (which must have reached T) with cost cotangent `cw` and
/// `samples` sorted by time (each within [0, T]); `dt_end` is dT/dθ.
pub(crate) fn sweep<M: HybridModel>(
    model: &M,
    p: &OVector<f64, M::P>,
    tape: &Tape,
    opts: &Options,
    dt_end: &OVector<f64, M::P>,
    cw: f64,
    samples: &[Sample<'_>],
) -> Result<SweepOut, SolveError>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let fin = tape.final_state().ok_or(SolveError::NotRecorded)?;
    let (n, np) = (model.nstates(), model.nparams());
    let nobs = model.info().nobservables();
    let mut y = AdjState::zeros(n, np);
    let mut sw = SampleWork::<M> {
        yx: vec![0.0; nobs * n.value()],
        yp: vec![0.0; nobs * np.value()],
        x: OVector::zeros_generic(n, Const::<1>),
    };
    terminal(model, p, fin, cw, dt_end, &mut sw.x, &mut y);
    // Samples are consumed from the back: samples[..left] are still to come.
    let mut left = samples.len();
    while left > 0 && samples[left - 1].t >= fin.t {
        sw.x.as_mut_slice().copy_from_slice(&fin.x);
        sw.add(model, p, &samples[left - 1], &mut y);
        left -= 1;
    }
    let mut integ = Integrator::backward(model, p, tape, opts, cw);
    let mut work = JumpWork::new(model);
    let mut shift_work = ShiftWork::new(model);
    let mut lam_plus = y.lam.clone();
    let mut g_jump = y.g.clone();
    let mut h_seed = 0.0;
    for item in tape.items().iter().rev() {
        let seg = match item {
            Item::Jump(j) => {
                let states = tape.jump_states(j);
                lam_plus.copy_from(&y.lam);
                g_jump.copy_from(&y.g);
                transpose_jump(model, p, cw, j, states, &mut y.lam, &mut y.g, &mut work)?;
                if let Some(ge) = integ.global_error_mut() {
                    // The jump's homogeneous part (w = 0) maps the remainder (a failure was
                    // the main transpose's, reported above); the primal run's displacement
                    // of the jump adds its share.
                    let r = ge.remainder_mut();
                    let _ =
                        transpose_jump(model, p, 0.0, j, states, &mut r.lam, &mut r.g, &mut work);
                    if let Some(shift) = tape.jump_shift(j) {
                        // What the sweep's transpose added to g.
                        g_jump.axpy(1.0, &y.g, -1.0);
                        let (w, s) = (&mut work, &mut shift_work);
                        let (lm, ga) = (&y.lam, &g_jump);
                        shift_error(model, p, cw, j, states, shift, &lam_plus, lm, ga, r, w, s);
                    }
                }
                continue;
            }
            Item::Segment(seg) => seg,
        };
        let mut t = seg.t_end;
        loop {
            integ.restart_segment(seg, seg.local(t), &y);
            integ.set_step_size(h_seed);
            let stop = match left {
                0 => seg.t_start,
                _ => samples[left - 1].t.max(seg.t_start),
            };
            // A stop within the time resolution of where the sweep stands (a sample a few ulps
            // before a segment's end) is reached: no step is that short.
            let s_stop = seg.local(stop);
            while integ.t() - s_stop > 16.0 * f64::EPSILON * integ.t().abs() {
                integ.step(s_stop)?;
                h_seed = integ.last_step_size().abs();
            }
            integ.carry_global_error();
            y.copy_from(integ.y());
            let mut cursor = seg.steps.end - 1;
            while left > 0 && samples[left - 1].t >= stop {
                tape.state_at(seg, s_stop, &mut cursor, sw.x.as_mut_slice());
                sw.add(model, p, &samples[left - 1], &mut y);
                left -= 1;
            }
            if stop <= seg.t_start {
                break;
            }
            t = stop;
        }
    }
    let mut vp = OVector::<f64, M::P>::zeros_generic(np, Const::<1>);
    model.initial_state_vjp(p, &y.lam, &mut vp);
    y.g += &vp;
    // e_G = r_g + (∂x₀/∂θ)ᵀ r_λ.
    let error = integ.global_error_mut().map(|ge| {
        let r = ge.remainder_mut();
        model.initial_state_vjp(p, &r.lam, &mut vp);
        r.g += &vp;
        r.g.iter().copied().collect()
    });
    if !y.g.iter().all(|v| v.is_finite()) {
        return Err(SolveError::NonFinite {
            t: 0.0,
            what: "adjoint gradient".into(),
        });
    }
    Ok(SweepOut {
        gradient: y.g.iter().copied().collect(),
        stats: integ.stats().clone(),
        error,
    })
}
