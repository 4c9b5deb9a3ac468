//! A two-mode thermostat (`models/thermostat.hyb`, the language spec's example): heat at
//! power p until the temperature reaches hi, cool until it falls to lo; Newton cooling
//! with rate k toward the ambient 10; C = ∫₀¹⁰ (temp − 20)² dt.
//!
//! Closed form: on a segment temp(s) = A + B e^{−ks} with A = 10 + p/k (heating) or
//! A = 10 (cooling) and B = temp(0) − A; it reaches the threshold θ* after
//! s = ln(B / (θ* − A)) / (−k)·(−1) = ln((θ* − A)/B)/(−k), and contributes
//! ∫₀ˢ (A − 20 + B e^{−kσ})² dσ = (A−20)² s + 2(A−20)B(1 − e^{−ks})/k + B²(1 − e^{−2ks})/(2k).

mvad::hybrid!(include "thermostat.hyb");

/// Ambient temperature of the model.
pub const AMBIENT: f64 = 10.0;

/// (C, switching times) of the thermostat for (k, lo, hi, p) from temp = 19 in `heating`
/// up to `t_end`, in closed form.
pub fn closed_form(k: f64, lo: f64, hi: f64, p: f64, t_end: f64) -> (f64, Vec<f64>) {
    let seg = |a: f64, b: f64, s: f64| {
        (a - 20.0).powi(2) * s
            + 2.0 * (a - 20.0) * b * (1.0 - (-k * s).exp()) / k
            + b * b * (1.0 - (-2.0 * k * s).exp()) / (2.0 * k)
    };
    let (mut t, mut temp, mut heating, mut cost) = (0.0, 19.0, true, 0.0);
    let mut times = Vec::new();
    while times.len() < 10_000 {
        let (a, target) = if heating {
            (AMBIENT + p / k, hi)
        } else {
            (AMBIENT, lo)
        };
        let b = temp - a;
        let ratio = (target - a) / b;
        let s = if ratio > 0.0 && ratio < 1.0 {
            -ratio.ln() / k
        } else {
            f64::INFINITY
        };
        if t + s >= t_end {
            cost += seg(a, b, t_end - t);
            break;
        }
        cost += seg(a, b, s);
        t += s;
        times.push(t);
        temp = target;
        heating = !heating;
    }
    (cost, times)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::derivative;
    use approx::assert_relative_eq;

    #[test]
    fn cost_switch_times_and_gradient_match_the_closed_form() {
        let (_, p, sol) = solved_at_defaults!(Thermostat, ThermostatParams, 1e-11, 1e-12);
        let (c, times) = closed_form(p.k, p.lo, p.hi, p.p, 10.0);
        assert_relative_eq!(sol.cost, c, max_relative = 1e-9);
        assert_eq!(sol.events.len(), times.len());
        for (e, t) in sol.events.iter().zip(&times) {
            assert_relative_eq!(e.t, *t, max_relative = 1e-10);
        }
        let f = |k: f64, lo: f64, hi: f64, pw: f64| closed_form(k, lo, hi, pw, 10.0).0;
        // Twelve switches compound: the closed form has large higher derivatives, so
        // the extrapolation starts from a small step (1e-3).
        let exact = [
            derivative(|x| f(x, p.lo, p.hi, p.p), p.k, 1e-3),
            derivative(|x| f(p.k, x, p.hi, p.p), p.lo, 1e-3),
            derivative(|x| f(p.k, p.lo, x, p.p), p.hi, 1e-3),
            derivative(|x| f(p.k, p.lo, p.hi, x), p.p, 1e-3),
        ];
        // dC/dlo to 40 digits (mpmath, h → 0): −9.632249245531071.
        assert_relative_eq!(exact[1], -9.632_249_245_531_07, max_relative = 1e-8);
        for (a, b) in sol.gradient.iter().zip(exact) {
            assert_relative_eq!(*a, b, max_relative = 1e-7);
        }
    }
}
