//! A stiff relay (`models/stiff_relay.hyb`): a first-order lag u̇ = (±1 − u)/τ with
//! τ = 1e-8 driving a slow state ẏ = rate·u between the thresholds lo and hi.
//!
//! Closed form of the switching times: u starts at its target 1, so y = rate·t reaches
//! hi at t₁ = hi/rate. After a switch u relaxes as ∓1 ± 2e^{−s/τ}, so y changes by
//! rate(s − 2τ(1 − e^{−s/τ})) and reaches the other threshold after
//! s = (hi − lo)/rate + 2τ (up to e^{−1/τ}): t_{k+1} = t_k + (hi − lo)/rate + 2τ.
//! An explicit method needs ~T/τ = 3e8 steps; `--method auto` must switch to the
//! implicit one by itself.

mvad::hybrid!(include "stiff_relay.hyb");

/// The switching times up to `t_end` for (tau, rate, lo, hi), in closed form.
pub fn switch_times(tau: f64, rate: f64, lo: f64, hi: f64, t_end: f64) -> Vec<f64> {
    let mut t = hi / rate;
    let mut out = Vec::new();
    while t < t_end && out.len() < 10_000 {
        out.push(t);
        t += (hi - lo) / rate + 2.0 * tau;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tolerances;
    use approx::assert_relative_eq;
    use mvad::solution::Options;
    use mvad::solve::solve;

    #[test]
    fn auto_solves_the_stiff_relay_with_exact_switch_times_and_sensitivities() {
        let m = StiffRelay::new();
        let p = StiffRelayParams::default();
        let sol = solve(&m, &p.to_vector(), &tolerances(1e-8, 1e-10)).expect("runs");
        let times = switch_times(p.tau, p.rate, p.lo, p.hi, 3.0);
        assert_eq!(sol.events.len(), times.len());
        assert!(sol.stats.steps < 20_000, "{} steps", sol.stats.steps);
        for (k, (e, t)) in sol.events.iter().zip(&times).enumerate() {
            assert_relative_eq!(e.t, *t, max_relative = 1e-6);
            // dt_k/dθ for θ = (tau, rate, lo, hi), from the closed form.
            let kf = k as f64;
            let exact = [
                2.0 * kf,
                -t / p.rate + 2.0 * p.tau * kf / p.rate,
                -kf,
                1.0 + kf,
            ];
            for (a, b) in e.dt.iter().zip(exact) {
                assert_relative_eq!(*a, b, max_relative = 1e-5, epsilon = 1e-6);
            }
        }
    }

    /// dC/dτ of C = ∫₀³ y² dt in closed form: after k switches y is the τ = 0 triangle wave
    /// delayed by 2τk, so dC/dτ = Σ_k −2k·[y₀²] over segment k = −2·3·(0 − 0.25) = 1.5
    /// (segments 1 and 2 run between ±0.5, so only the last one, k = 3, counts).
    ///
    /// The class this guards: a parameter whose sensitivities are far larger than the state
    /// (S_τ ~ 1/τ = 1e8 near each switch). A step size chosen for x alone left S wrong by 5×
    /// at rtol 1e-3…1e-6 with a misleading grazing warning; sensitivity error control without
    /// the |θ_j| weight put S_τ's rounding floor above atol and ran into `max_steps`.
    #[test]
    fn the_gradient_in_tau_is_right_at_every_tolerance_with_default_options() {
        let m = StiffRelay::new();
        let p = StiffRelayParams::default().to_vector();
        for method in [
            mvad::solution::Method::Auto,
            mvad::solution::Method::Rosenbrock,
        ] {
            for rtol in [1e-3, 1e-4, 1e-6, 1e-8, 1e-10, 1e-12] {
                let opts = Options {
                    method,
                    rtol,
                    ..Options::default()
                };
                let sol = solve(&m, &p, &opts).expect("runs");
                let what = format!("{method:?} rtol {rtol:e}");
                assert!(sol.diagnostics.is_empty(), "{what}: {:?}", sol.diagnostics);
                assert_eq!(sol.events.len(), 3, "{what}");
                let err = (sol.gradient[0] - 1.5).abs() / 1.5;
                assert!(
                    err <= 10.0 * rtol + 1e-10,
                    "{what}: dC/dtau = {:.15e}, rel err {err:.1e}",
                    sol.gradient[0]
                );
                for (k, e) in sol.events.iter().enumerate() {
                    let want = 2.0 * k as f64;
                    assert!(
                        (e.dt[0] - want).abs() <= 10.0 * rtol * want.max(1.0) + 1e-9,
                        "{what}: event {k} dt/dtau = {}, want {want}",
                        e.dt[0]
                    );
                }
            }
        }
    }
}
