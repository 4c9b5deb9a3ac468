//! A ball thrown up toward a ceiling just below its apex (`models/ceiling.hyb`): a
//! near-grazing event. h(t) = v0 t − g t²/2 reaches the ceiling c at
//! t_c = (v0 − w)/g with the upward speed w = √(v0² − 2gc) (the guard slope), so
//! dt_c/dc = 1/w blows up as c approaches the apex v0²/(2g). After the hit
//! v⁺ = −e w and the ball falls freely (no floor before T).
//!
//! Closed form of C = ∫₀ᵀ h dt: v0 t_c²/2 − g t_c³/6 + c s + v⁺ s²/2 − g s³/6, s = T − t_c.

mvad::hybrid!(include "ceiling.hyb");

/// (t_c, w = guard slope) of the hit, or `None` when the ball does not reach the ceiling.
pub fn hit(g: f64, v0: f64, c: f64) -> Option<(f64, f64)> {
    let d = v0 * v0 - 2.0 * g * c;
    (d > 0.0).then(|| {
        let w = d.sqrt();
        ((v0 - w) / g, w)
    })
}

/// C = ∫₀ᵀ h dt in closed form (the ball must hit the ceiling before T).
pub fn cost(e: f64, g: f64, v0: f64, c: f64, t_end: f64) -> f64 {
    match hit(g, v0, c) {
        Some((tc, w)) if tc < t_end => {
            let s = t_end - tc;
            v0 * tc * tc / 2.0 - g * tc.powi(3) / 6.0 + c * s
                - e * w * s * s / 2.0
                - g * s.powi(3) / 6.0
        }
        _ => v0 * t_end * t_end / 2.0 - g * t_end.powi(3) / 6.0,
    }
}

/// dC/dc in closed form: with s = T − t_c, dt_c/dc = 1/w and dw/dc = −g/w,
/// dC/dc = (1 + e) s (1 + g s / (2w)) (the terms h(t_c)/w − c/w cancel).
pub fn dcost_dc(e: f64, g: f64, v0: f64, c: f64, t_end: f64) -> f64 {
    match hit(g, v0, c) {
        Some((tc, w)) if tc < t_end => {
            let s = t_end - tc;
            (1.0 + e) * s * (1.0 + g * s / (2.0 * w))
        }
        _ => 0.0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{derivative, tolerances};
    use approx::assert_relative_eq;
    use mvad::solve::solve;

    #[test]
    fn approaching_grazing_against_the_closed_form() {
        let m = Ceiling::new();
        let opts = tolerances(1e-12, 1e-14);
        let apex = 4.4f64 * 4.4 / (2.0 * 9.81);
        // Ceilings ever closer to the apex: the slope w shrinks like √(apex − c).
        for gap in [1e-1, 1e-2, 1e-3, 1e-4] {
            let p = CeilingParams {
                c: apex - gap,
                ..CeilingParams::default()
            };
            let sol = solve(&m, &p.to_vector(), &opts).expect("runs");
            assert_eq!(sol.events.len(), 1, "gap {gap}");
            let (tc, w) = hit(p.g, p.v0, p.c).expect("hits");
            let ev = &sol.events[0];
            assert_relative_eq!(ev.t, tc, max_relative = 1e-9);
            assert_relative_eq!(ev.guard_slope, w, max_relative = 1e-6);
            assert_relative_eq!(ev.dt[3], 1.0 / w, max_relative = 1e-6);
            assert_relative_eq!(
                sol.cost,
                cost(p.e, p.g, p.v0, p.c, 0.8),
                max_relative = 1e-9
            );
            let exact = dcost_dc(p.e, p.g, p.v0, p.c, 0.8);
            if gap >= 1e-2 {
                // Far enough from grazing for differences of the closed form to be accurate.
                let fd = derivative(|c| cost(p.e, p.g, p.v0, c, 0.8), p.c, gap / 10.0);
                assert_relative_eq!(exact, fd, max_relative = 1e-9);
            }
            assert_relative_eq!(sol.gradient[3], exact, max_relative = 1e-7);
        }
    }
}
