//! A cart driven toward a wall by a saturating qp controller (`models/qp_cart.hyb`):
//! u = argmin ½(u − kx − cv)² s.t. |u| ≤ umax inside the flow, an impact at the wall.
//!
//! Reference: the same model with u = max(−umax, min(umax, kx + cv)) written with
//! `min`/`max` ([`MINMAX_SOURCE`]); both give the same trajectory, cost and gradient, the qp's
//! active-set changes located as switch crossings exactly where min/max's kinks are.

mvad::hybrid!(include "qp_cart.hyb");

/// The same cart with the controller written with `min`/`max`.
pub const MINMAX_SOURCE: &str = "model MinMaxCart {
    param k = -2.0; param c = -0.5; param umax = 1.0; param e = 0.7; param x0 = 1.5;
    state x = x0; state v = 0.0;
    flow { der(x) = v; der(v) = max(-umax, min(umax, k*x + c*v)); }
    event wall when x <= 0 { v = -e * v; }
    observe force = max(-umax, min(umax, k*x + c*v));
    cost = integral(x^2 + 0.1 * max(-umax, min(umax, k*x + c*v))^2);
    horizon 4;
}";
