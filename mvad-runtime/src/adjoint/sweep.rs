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
//!    those jumps are undone; one at T takes x(T) after any jump at T. At a switch crossing of
//!    a kink a sample is the left limit (the trajectory record's convention there): it is
//!    added on the segment that ends at the crossing, after the flip is undone, with that
//!    segment's bits. h is evaluated under the bits of the segment it is added on.
//! 4. At t = 0: g += λ(0)ᵀ∂x₀/∂θ ([`crate::model::ModelAdjoint::initial_state_vjp`]).
//!
//! The quadrature g is not under error control (only λ is: see `integrate::adjoint`), so
//! what resolves its integrand G(t) = −(λᵀf_θ + w ℓ_θ)(t, x(t)) where x(t) moves fast (the
//! stiff relay's lag, τ = 1e-8, whose f_τ has a transient of width 1e-8 after each switch
//! while λ has none) is the record itself: x(t) is a polynomial per recorded step, the steps
//! the primal run chose for x, and no backward step is longer than [`RECORD_REACH`] times
//! the shortest recorded step it overlaps ([`Tape::backward_reach`]). Where x moved fast the
//! sweep's steps are as fine as the primal run's; elsewhere λ's error control decides.
//!
//! Then g = w dC/dθ + Σ_s w_sᵀ dy(t_s)/dθ: the sum of every term of DESIGN.md's dC/dθ,
//! transposed. The integrator restarts at every segment start and every sample (λ jumps
//! there), its first step seeded with the last step's size. It runs in the segment's local
//! time s = t − t_start (see [`super::record`]).

use super::record::{FinalState, Item, Tape};
use super::transpose::{
    transpose_jump, transpose_jump_with_error, JumpErrorWork, JumpSite, JumpWork,
};
use crate::error::SolveError;
use crate::integrate::{Backward, Integrator};
use crate::model::{At, HybridModel, ModelAlloc, Point, Switches};
use crate::solution::{Options, Stats};
use nalgebra::{Const, DefaultAllocator, Dim, OVector};

/// A backward step reaches at most this many times the shortest recorded step it overlaps
/// (see the module doc).
pub(crate) const RECORD_REACH: f64 = 4.0;

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
    /// (`Options::global_error`; see `integrate/adjoint_error.rs`).
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
    /// λ += h_xᵀ w and g += h_θᵀ w at (t, `self.x`) under the bits `bits`.
    fn add(
        &mut self,
        model: &M,
        p: &OVector<f64, M::P>,
        bits: &Switches,
        s: &Sample<'_>,
        lam: &mut OVector<f64, M::N>,
        g: &mut OVector<f64, M::P>,
    ) {
        if s.w.iter().all(|&w| w == 0.0) {
            return;
        }
        let (n, np) = (lam.len(), g.len());
        model.observe_jac(bits, At::new(s.t, &self.x, p), &mut self.yx, &mut self.yp);
        for (i, &wi) in s.w.iter().enumerate() {
            if wi == 0.0 {
                continue;
            }
            for (l, v) in lam.iter_mut().zip(&self.yx[i * n..(i + 1) * n]) {
                *l += wi * v;
            }
            for (g, v) in g.iter_mut().zip(&self.yp[i * np..(i + 1) * np]) {
                *g += wi * v;
            }
        }
    }

    /// Adds the samples still to come (`samples[..*left]`, consumed from the back) while
    /// `due` takes their time, all at one state: `state` writes it into `self.x` before the
    /// first (so a sweep that passes no sample evaluates none).
    #[allow(clippy::too_many_arguments)]
    fn add_due(
        &mut self,
        model: &M,
        p: &OVector<f64, M::P>,
        bits: &Switches,
        (samples, left): (&[Sample<'_>], &mut usize),
        due: impl Fn(f64) -> bool,
        state: impl FnOnce(&mut [f64]),
        lam: &mut OVector<f64, M::N>,
        g: &mut OVector<f64, M::P>,
    ) {
        let mut state = Some(state);
        while *left > 0 && due(samples[*left - 1].t) {
            if let Some(write) = state.take() {
                write(self.x.as_mut_slice());
            }
            self.add(model, p, bits, &samples[*left - 1], lam, g);
            *left -= 1;
        }
    }
}

/// λ(T) = w Φ_xᵀ and g = w [Φ_θ + (ℓ(T) + Φ_x f(T) + Φ_t) dT/dθ] into `lam`, `g`.
#[allow(clippy::too_many_arguments)]
fn terminal<M: HybridModel>(
    model: &M,
    p: &OVector<f64, M::P>,
    fin: &FinalState,
    cw: f64,
    dt_end: &OVector<f64, M::P>,
    x: &mut OVector<f64, M::N>,
    lam: &mut OVector<f64, M::N>,
    g: &mut OVector<f64, M::P>,
) where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let info = model.info();
    lam.fill(0.0);
    g.fill(0.0);
    if cw == 0.0 {
        return;
    }
    x.as_mut_slice().copy_from_slice(&fin.x);
    let mut rate = 0.0;
    if info.has_final_cost {
        let mut f = x.clone_owned();
        let phi_t = model.final_cost_grad(At::new(fin.t, x, p), lam, g);
        model.rhs(Point::new(fin.mode, &fin.sw, fin.t, x, p), &mut f);
        rate += lam.dot(&f) + phi_t;
        *lam *= cw;
        *g *= cw;
    }
    if info.has_running_cost {
        rate += model.running_cost(&fin.sw, At::new(fin.t, x, p));
    }
    if rate != 0.0 {
        g.axpy(cw * rate, dt_end, 1.0);
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
    let mut lam = OVector::<f64, M::N>::zeros_generic(n, Const::<1>);
    let mut sw = SampleWork::<M> {
        yx: vec![0.0; nobs * n.value()],
        yp: vec![0.0; nobs * np.value()],
        x: OVector::zeros_generic(n, Const::<1>),
    };
    // g lives in the backward system, which adds each step's quadrature to it.
    let mut integ = Integrator::with_system(Backward::new(model, p, tape, opts, cw), opts);
    terminal(
        model,
        p,
        fin,
        cw,
        dt_end,
        &mut sw.x,
        &mut lam,
        integ.gradient_mut(),
    );
    // Samples are consumed from the back: samples[..left] are still to come.
    let mut left = samples.len();
    sw.add_due(
        model,
        p,
        &fin.sw,
        (samples, &mut left),
        |t| t >= fin.t,
        |x| x.copy_from_slice(&fin.x),
        &mut lam,
        integ.gradient_mut(),
    );
    let mut work = JumpWork::new(model);
    let mut error_work = opts.global_error.then(|| JumpErrorWork::new(model));
    let mut h_seed = 0.0;
    for (i, item) in tape.items().iter().enumerate().rev() {
        let seg = match item {
            Item::Jump(j) => {
                let states = tape.jump_states(j);
                let site = JumpSite {
                    model,
                    p,
                    cw,
                    jump: j,
                };
                let (g, ge) = integ.gradient_and_error_mut();
                match (ge, &mut error_work) {
                    (Some(ge), Some(ew)) => {
                        let shift = tape.jump_shift(j);
                        let y = (&mut lam, g);
                        transpose_jump_with_error(site, states, shift, y, ge, &mut work, ew)?;
                    }
                    _ => transpose_jump(site, states, &mut lam, g, &mut work)?,
                }
                continue;
            }
            Item::Segment(seg) => seg,
        };
        let mut t = seg.t_end;
        loop {
            integ.restart_segment(seg, seg.local(t), &lam);
            integ.set_step_size(h_seed);
            let stop = match left {
                0 => seg.t_start,
                _ => samples[left - 1].t.max(seg.t_start),
            };
            // A stop within the time resolution of where the sweep stands (a sample a few ulps
            // before a segment's end) is reached: no step is that short.
            let s_stop = seg.local(stop);
            let mut cursor = seg.steps.end - 1;
            while integ.t() - s_stop > 16.0 * f64::EPSILON * integ.t().abs() {
                // No backward step is longer than RECORD_REACH recorded steps (module doc).
                let s = integ.t();
                let h = integ.next_step_size();
                let reach = tape.backward_reach(seg, s, RECORD_REACH, h, &mut cursor);
                let resolvable = s - reach > 64.0 * f64::EPSILON * s.abs();
                integ.step(if resolvable {
                    reach.max(s_stop)
                } else {
                    s_stop
                })?;
                h_seed = integ.last_step_size().abs();
            }
            lam.copy_from(integ.y());
            let mut cursor = seg.steps.end - 1;
            // A sample at a switch crossing is the left limit: the segment before takes it.
            let left_limit = |t: f64| t == seg.t_start && tape.starts_at_switch(i);
            sw.add_due(
                model,
                p,
                &seg.sw,
                (samples, &mut left),
                |t| t >= stop && !left_limit(t),
                |x| tape.state_at(seg, s_stop, &mut cursor, x),
                &mut lam,
                integ.gradient_mut(),
            );
            if stop <= seg.t_start {
                break;
            }
            t = stop;
        }
    }
    let mut vp = OVector::<f64, M::P>::zeros_generic(np, Const::<1>);
    model.initial_state_vjp(p, &lam, &mut vp);
    let (g, ge) = integ.gradient_and_error_mut();
    *g += &vp;
    // e_Γ = r_g + (∂x₀/∂θ)ᵀ r_λ.
    let error = ge.map(|ge| {
        let (r_lam, r_g) = ge.remainder_mut();
        model.initial_state_vjp(p, r_lam, &mut vp);
        *r_g += &vp;
        r_g.iter().copied().collect()
    });
    if !g.iter().all(|v| v.is_finite()) {
        return Err(SolveError::NonFinite {
            t: 0.0,
            what: "adjoint gradient".into(),
        });
    }
    Ok(SweepOut {
        gradient: integ.gradient_mut().iter().copied().collect(),
        stats: integ.stats().clone(),
        error,
    })
}
