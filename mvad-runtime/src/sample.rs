//! A recorded run read at given times: the states x(tᵢ), the observables
//! yᵢ = h(tᵢ, x(tᵢ), θ) and, when the run carried sensitivities, their parameter Jacobians
//!
//! ```text
//!   ∂yᵢ/∂θ = h_x(tᵢ) S(tᵢ) + h_θ(tᵢ),
//! ```
//!
//! the density of the measure μ_y at tᵢ ([`crate::measure`](mod@crate::measure)): a sample at a fixed time tᵢ that
//! is not an event time sees no atom, since the event moves past it only when θ moves by a
//! finite amount. Like the record, a sample is right-continuous at user events: at an event
//! time it reads the post-event state x(t_k⁺). At a switch crossing of a kink it is the left
//! limit: the observables under the bits before the flip, with S(t_c⁻) (x is continuous).

use crate::error::{SolveError, Time};
use crate::measure::add_density;
use crate::model::{At, HybridModel, ModelAlloc};
use crate::solution::{Solution, Trajectory};
use nalgebra::{Const, DefaultAllocator, Dim, OVector};

/// States, observables and (optionally) the observables' parameter Jacobians at the times
/// of a sampling grid. All arrays are row-major with the time index first.
#[derive(Clone, Debug, PartialEq)]
pub struct Samples {
    /// The sample times tᵢ, as given.
    pub times: Vec<f64>,
    /// Number of states n.
    pub nstates: usize,
    /// Number of observables m.
    pub nobservables: usize,
    /// Number of parameters p in the Jacobian (0 without sensitivities).
    pub nparams: usize,
    /// x(tᵢ): `states[i * n + r]`.
    pub states: Vec<f64>,
    /// yᵢ: `observables[i * m + o]`.
    pub observables: Vec<f64>,
    /// ∂yᵢ/∂θ: `jacobian[(i * m + o) * p + j]`; empty when the run had no sensitivities.
    pub jacobian: Vec<f64>,
}

/// Checks that every sample time is finite and inside [0, T].
pub fn check_times(times: &[f64], t_end: f64) -> Result<(), SolveError> {
    match times
        .iter()
        .position(|t| !(t.is_finite() && (0.0..=t_end).contains(t)))
    {
        None => Ok(()),
        Some(i) => Err(SolveError::BadOption {
            what: format!(
                "sample time {} (index {i}) is outside the horizon [0, {}]",
                Time(times[i]),
                Time(t_end)
            ),
        }),
    }
}

/// Reads `solution` (run with `Options::record`) at `times`; the Jacobian is filled when the
/// run carried sensitivities.
pub fn sample<M: HybridModel>(
    model: &M,
    params: &OVector<f64, M::P>,
    solution: &Solution,
    times: &[f64],
) -> Result<Samples, SolveError>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    check_times(times, solution.t_end)?;
    let traj: &Trajectory = solution
        .trajectory
        .as_ref()
        .ok_or(SolveError::NotRecorded)?;
    let n = model.nstates().value();
    let m = model.info().nobservables();
    if traj.n != n || (traj.p != 0 && traj.p != model.nparams().value()) {
        return Err(SolveError::NotRecorded);
    }
    let p = traj.p;
    let mut out = Samples {
        times: times.to_vec(),
        nstates: n,
        nobservables: m,
        nparams: p,
        states: Vec::with_capacity(times.len() * n),
        observables: Vec::with_capacity(times.len() * m),
        jacobian: Vec::with_capacity(times.len() * m * p),
    };
    let mut x = OVector::<f64, M::N>::zeros_generic(model.nstates(), Const::<1>);
    let mut s = vec![0.0; n * p];
    let mut y = vec![0.0; m];
    let mut yx = vec![0.0; m * n];
    let mut yp = vec![0.0; m * model.nparams().value()];
    let mut row = vec![0.0; p];
    for &t in times {
        if !traj.sample_into(t, x.as_mut_slice(), &mut s) {
            return Err(SolveError::NotRecorded);
        }
        // The bits of the step the sample read (at a switch crossing: the one on the left).
        let sw = traj.switches_of_step(traj.step_for(t).unwrap_or(0));
        model.observe(sw, At::new(t, &x, params), &mut y);
        out.states.extend_from_slice(x.as_slice());
        out.observables.extend_from_slice(&y);
        if p == 0 {
            continue;
        }
        model.observe_jac(sw, At::new(t, &x, params), &mut yx, &mut yp);
        for o in 0..m {
            row.copy_from_slice(&yp[o * p..(o + 1) * p]);
            add_density(&yx[o * n..(o + 1) * n], &s, &mut row);
            out.jacobian.extend_from_slice(&row);
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fixtures::Ball;
    use crate::solution::Options;
    use crate::solve::solve;
    use approx::assert_relative_eq;

    fn run(sensitivities: bool) -> (Ball, OVector<f64, nalgebra::U4>, Solution) {
        let ball = Ball::new();
        let p = OVector::<f64, nalgebra::U4>::from([0.8, 9.81, 2.0, 0.0]);
        let opts = Options {
            rtol: 1e-10,
            atol: 1e-12,
            record: true,
            sensitivities,
            ..Options::default()
        };
        let sol = solve(&ball, &p, &opts).expect("runs");
        (ball, p, sol)
    }

    /// Before the first impact h = h0 + v0 t − g t²/2: ∂h/∂g = −t²/2, ∂h/∂h0 = 1, ∂h/∂v0 = t;
    /// after it (t₁ = sqrt(2 h0/g), v⁺ = e g t₁) h = v⁺ (t − t₁) − g (t − t₁)²/2, so
    /// ∂h/∂e = g t₁ (t − t₁).
    #[test]
    fn heights_and_their_jacobian_against_the_closed_form() {
        let (ball, p, sol) = run(true);
        let g: f64 = 9.81;
        let t1 = (2.0 * 2.0 / g).sqrt();
        let times = [0.0, 0.3, 0.6, 0.7, 1.0];
        let smp = sample(&ball, &p, &sol, &times).expect("samples");
        assert_eq!((smp.nstates, smp.nobservables, smp.nparams), (2, 2, 4));
        for (i, &t) in times.iter().enumerate() {
            let h = smp.observables[i * 2];
            let dh = &smp.jacobian[i * 2 * 4..i * 2 * 4 + 4];
            assert_eq!(smp.states[i * 2], h);
            if t < t1 {
                assert_relative_eq!(h, 2.0 - 0.5 * g * t * t, epsilon = 1e-9);
                assert_relative_eq!(dh[0], 0.0, epsilon = 1e-9);
                assert_relative_eq!(dh[1], -0.5 * t * t, epsilon = 1e-9);
                assert_relative_eq!(dh[2], 1.0, epsilon = 1e-9);
                assert_relative_eq!(dh[3], t, epsilon = 1e-9);
            } else {
                let s = t - t1;
                assert_relative_eq!(h, 0.8 * g * t1 * s - 0.5 * g * s * s, epsilon = 1e-9);
                assert_relative_eq!(dh[0], g * t1 * s, epsilon = 1e-8);
            }
        }
    }

    #[test]
    fn without_sensitivities_there_is_no_jacobian_and_bad_times_are_refused() {
        let (ball, p, sol) = run(false);
        let smp = sample(&ball, &p, &sol, &[0.5, 2.0]).expect("samples");
        assert!(smp.jacobian.is_empty());
        assert_eq!(smp.observables.len(), 4);
        for bad in [[-0.1], [2.5], [f64::NAN]] {
            let e = sample(&ball, &p, &sol, &bad).expect_err("outside");
            assert!(matches!(e, SolveError::BadOption { .. }), "{e:?}");
        }
        let mut unrecorded = sol.clone();
        unrecorded.trajectory = None;
        assert_eq!(
            sample(&ball, &p, &unrecorded, &[0.5]),
            Err(SolveError::NotRecorded)
        );
    }
}
