//! E1, the seed paper's bouncing ball (`models/bouncing_ball.hyb`): ḣ = v, v̇ = −g,
//! impact when h ≤ 0 with v⁺ = −e v⁻, C = ∫₀² h dt; θ = (e, g, h0, v0) =
//! (0.8, 9.81, 2, 0).
//!
//! Closed form (see [`crate::ball_closed_form`]): t₁ = √(2h0/g), the ball leaves the floor
//! at e g t₁, t₂ = t₁ + 2 e t₁;
//! C = (2/3) h0 t₁ + ∫ of the second flight up to t₂ and of the third up to T = 2.

mvad::hybrid!(include "bouncing_ball.hyb");

/// The two impact times before T = 2.
pub const IMPACT_TIMES: [f64; 2] = [0.638_550_856_814_101, 1.660_232_227_716_662_4];
/// C = ∫₀² h dt.
pub const COST: f64 = 1.890_513_712_317_350_6;
/// dC/de.
pub const DCOST_DE: f64 = 2.831_440_814_147_005_5;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{ball_closed_form, central};
    use approx::assert_relative_eq;
    use mvad::solution::Options;
    use mvad::solve::solve;

    fn tight() -> Options {
        crate::tolerances(1e-10, 1e-12)
    }

    #[test]
    fn compiled_model_matches_the_closed_form_in_all_four_params() {
        let m = BouncingBall::new();
        let p = BouncingBallParams::default();
        let sol = solve(&m, &p.to_vector(), &tight()).expect("runs");
        assert_relative_eq!(sol.cost, COST, max_relative = 1e-10);
        assert_eq!(sol.events.len(), 2);
        assert_relative_eq!(sol.events[1].t, IMPACT_TIMES[1], max_relative = 1e-12);
        let f = |e: f64, g: f64, h0: f64, v0: f64| ball_closed_form(e, g, h0, v0, 2.0).0;
        let exact = [
            central(|e| f(e, p.g, p.h0, p.v0), p.e),
            central(|g| f(p.e, g, p.h0, p.v0), p.g),
            central(|h| f(p.e, p.g, h, p.v0), p.h0),
            central(|v| f(p.e, p.g, p.h0, v), p.v0),
        ];
        assert_relative_eq!(exact[0], DCOST_DE, max_relative = 1e-9);
        for (k, (a, b)) in sol.gradient.iter().zip(exact).enumerate() {
            assert_relative_eq!(*a, b, max_relative = 1e-8, epsilon = 1e-10);
            let _ = k;
        }
    }

    #[test]
    fn loaded_model_agrees_with_the_compiled_one() {
        let loaded =
            mvad::load::load_str("bouncing_ball.hyb", include_str!("../bouncing_ball.hyb"))
                .expect("loads");
        let theta = loaded.default_params();
        let a = solve(&loaded, &theta, &tight()).expect("runs");
        let m = BouncingBall::new();
        let b = solve(&m, &m.default_params(), &tight()).expect("runs");
        assert_relative_eq!(a.cost, b.cost, max_relative = 1e-12);
        for (x, y) in a.gradient.iter().zip(&b.gradient) {
            assert_relative_eq!(*x, *y, max_relative = 1e-10, epsilon = 1e-12);
        }
    }
}
