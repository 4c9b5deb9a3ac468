//! E2, the seed paper's transversality sweep (`models/e2_sweep.hyb`): the ball of E1
//! dropped from h0 = 1 with initial velocity v0 ∈ [−5, −0.5]; over T = 0.5 it hits the
//! floor once. The observable `position` is continuous at the impact, so its measure has
//! no atom although the guard slope |∇g·f| = |v⁻| is large.
//!
//! Closed form of the first impact: |v⁻| = √(v0² + 2 g h0), t₁ = (v0 + |v⁻|) / g,
//! dt₁/dv0 = (1 + v0/|v⁻|) / g, dt₁/dh0 = 1/|v⁻|.

mvad::hybrid!(include "e2_sweep.hyb");

/// The first impact for (v0, g, h0): (t₁, |∇ₓg·f| = |v⁻|).
pub fn first_impact(v0: f64, g: f64, h0: f64) -> (f64, f64) {
    let speed = (v0 * v0 + 2.0 * g * h0).sqrt();
    ((v0 + speed) / g, speed)
}

/// Reference values from the design notes: (v0, t₁, |∇ₓg·f|).
pub const REFERENCE: [(f64, f64, f64); 2] = [
    (-0.5, 0.403_422_815_250_207_34, 4.457_577_817_604_534),
    (-5.0, 0.171_235_510_383_883_18, 6.679_820_356_865_894),
];

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tolerances;
    use approx::assert_relative_eq;
    use mvad::solve::solve;

    #[test]
    fn first_impact_over_the_sweep() {
        let m = E2Sweep::new();
        let opts = tolerances(1e-10, 1e-12);
        for (v0, t_ref, slope_ref) in REFERENCE {
            let (t, slope) = first_impact(v0, 9.81, 1.0);
            assert_relative_eq!(t, t_ref, max_relative = 1e-14);
            assert_relative_eq!(slope, slope_ref, max_relative = 1e-14);
        }
        for i in 0..10 {
            let v0 = -0.5 - 0.5 * i as f64;
            let p = E2SweepParams {
                v0,
                ..E2SweepParams::default()
            };
            let sol = solve(&m, &p.to_vector(), &opts).expect("runs");
            assert_eq!(sol.events.len(), 1, "v0 = {v0}");
            let ev = &sol.events[0];
            let (t, slope) = first_impact(v0, p.g, p.h0);
            assert_relative_eq!(ev.t, t, max_relative = 1e-12);
            assert_relative_eq!(ev.guard_slope, -slope, max_relative = 1e-10);
            assert!(ev.transversal);
            // t₁' w.r.t. v0 (index 0) and h0 (index 3).
            assert_relative_eq!(ev.dt[0], (1.0 + v0 / slope) / p.g, max_relative = 1e-9);
            assert_relative_eq!(ev.dt[3], 1.0 / slope, max_relative = 1e-9);
            // Position is continuous: no atom; velocity jumps by (1 + e)|v⁻|.
            assert!(
                ev.atoms[0].iter().all(|a| a.abs() < 1e-12),
                "{:?}",
                ev.atoms[0]
            );
            assert_relative_eq!(
                ev.jump_observables[1],
                (1.0 + p.e) * slope,
                max_relative = 1e-10
            );
        }
    }
}
