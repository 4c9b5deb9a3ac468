//! The paper's E3 (`models/qp_kink.hyb`, the language spec's `qp` example): a static
//! parametric QP min ½u² − θu s.t. u ≥ 0 inside a model without states, J = ½u*².
//!
//! Closed form: u*(θ) = max(0, θ), J(θ) = ½ max(0, θ)², dJ/dθ = θ·H(θ) (H the Heaviside
//! step, H(0) = 0 for the derivative from the left and 1 from the right, where J' = 0
//! either way), du*/dθ = H(θ): 0 from the left and 1 from the right at the kink θ = 0.

mvad::hybrid!(include "qp_kink.hyb");

/// u*(θ) = max(0, θ).
pub fn solution(theta: f64) -> f64 {
    theta.max(0.0)
}

/// dJ/dθ = θ·H(θ) for J = ½u*².
pub fn gradient(theta: f64) -> f64 {
    if theta > 0.0 {
        theta
    } else {
        0.0
    }
}
