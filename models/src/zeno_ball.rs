//! A Zeno ball (`models/zeno_ball.hyb`): the E1 ball with e = 0.5 run to T = 3. Its
//! impacts accumulate at t* = t₁(1 + 2e/(1 − e)) = 3t₁ ≈ 1.9157 s (t₁ = √(2h0/g)); after
//! t* the ball rests on the floor.
//!
//! Closed form for T ≥ t*, v0 = 0: the first fall contributes (2/3) h0 t₁ and the k-th
//! bounce, launched at e^k g t₁, contributes 2(e^k g t₁)³/(3g²), so
//! C = (2/3) h0 t₁ (1 + 2e³/(1 − e³)) and dC/de = 4 h0 t₁ e²/(1 − e³)².

mvad::hybrid!(include "zeno_ball.hyb");

/// The accumulation time t* = √(2h0/g)(1 + 2e/(1 − e)) for v0 = 0.
pub fn accumulation_time(e: f64, g: f64, h0: f64) -> f64 {
    (2.0 * h0 / g).sqrt() * (1.0 + 2.0 * e / (1.0 - e))
}

/// C = ∫₀ᵀ h dt for T ≥ t* and v0 = 0.
pub fn cost(e: f64, g: f64, h0: f64) -> f64 {
    let t1 = (2.0 * h0 / g).sqrt();
    let e3 = e * e * e;
    2.0 / 3.0 * h0 * t1 * (1.0 + 2.0 * e3 / (1.0 - e3))
}

/// dC/de for T ≥ t* and v0 = 0.
pub fn dcost_de(e: f64, g: f64, h0: f64) -> f64 {
    let t1 = (2.0 * h0 / g).sqrt();
    4.0 * h0 * t1 * e * e / (1.0 - e * e * e).powi(2)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{ball_closed_form, central};
    use approx::assert_relative_eq;
    use mvad::solution::DiagnosticKind;

    #[test]
    fn the_series_tail_is_estimated_to_1e_6() {
        let (_, p, sol) = solved_at_defaults!(ZenoBall, ZenoBallParams, 1e-10, 1e-12);
        // The tail is summed, not stepped through: a few dozen bounces, not thousands.
        assert!(sol.events.len() < 100, "{} events", sol.events.len());
        let zeno = sol
            .diagnostic(DiagnosticKind::Zeno)
            .expect("a zeno diagnostic");
        assert_relative_eq!(
            zeno.t,
            accumulation_time(p.e, p.g, p.h0),
            max_relative = 1e-6
        );
        assert_relative_eq!(sol.cost, cost(p.e, p.g, p.h0), max_relative = 1e-6);
        assert_relative_eq!(
            cost(p.e, p.g, p.h0),
            ball_closed_form(p.e, p.g, p.h0, 0.0, 3.0).0,
            max_relative = 1e-13
        );
        assert_relative_eq!(
            sol.gradient[0],
            dcost_de(p.e, p.g, p.h0),
            max_relative = 1e-6
        );
        assert_relative_eq!(
            dcost_de(p.e, p.g, p.h0),
            central(|e| cost(e, p.g, p.h0), p.e),
            max_relative = 1e-9
        );
        assert_relative_eq!(
            sol.gradient[1],
            central(|g| cost(p.e, g, p.h0), p.g),
            max_relative = 1e-6
        );
        assert_relative_eq!(
            sol.gradient[2],
            central(|h| cost(p.e, p.g, h), p.h0),
            max_relative = 1e-6
        );
        // The floor holds: the final height is 0, never below.
        assert!(sol.x_final[0].abs() < 1e-9, "{:?}", sol.x_final);
    }
}
