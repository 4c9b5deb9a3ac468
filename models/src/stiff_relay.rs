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
    use approx::assert_relative_eq;
    use mvad::solution::Options;
    use mvad::solve::solve;

    #[test]
    fn auto_solves_the_stiff_relay_with_exact_switch_times_and_sensitivities() {
        let m = StiffRelay::new();
        let p = StiffRelayParams::default();
        let sol = solve(
            &m,
            &p.to_vector(),
            &Options {
                rtol: 1e-8,
                atol: 1e-10,
                ..Options::default()
            },
        )
        .expect("runs");
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
}
