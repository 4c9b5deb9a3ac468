//! Tsitouras' 5(4) pair (Ch. Tsitouras, "Runge–Kutta pairs of order 5(4) satisfying only the
//! first column simplifying assumption", Comput. Math. Appl. 62 (2011) 770–775).
//!
//! Seven stages, FSAL: b = a₇,· and c₆ = c₇ = 1, so k₇ = F(t + h, y₁) is the next step's k₁
//! (reused only between accepted steps of the same segment — a restart discards it). The
//! error estimate is h Σ b̃_i k_i with b̃ = b − b̂ (4th order); the continuous extension is
//! y(t₀ + θh) = y₀ + h Σ b_i(θ) k_i with the quartic polynomials b_i(θ) of the paper, which
//! reproduce b_i at θ = 1 (4th-order dense output). The stage loop is [`super::explicit`].

use super::explicit::Tableau;

/// Number of stages.
pub(super) const STAGES: usize = 7;

/// The weights b_i of the 5th-order solution (also the last row of `a`: FSAL).
#[rustfmt::skip]
const B: [f64; STAGES] = [
    0.09646076681806523, 0.01, 0.4798896504144996, 1.379008574103742,
    -3.290069515436081, 2.324710524099774, 0.0,
];

/// The tableau; the last row of `a` is `b` (FSAL), `dense` holds r_i1..r_i4 of
/// b_i(θ) = r_i1 θ + r_i2 θ² + r_i3 θ³ + r_i4 θ⁴.
#[rustfmt::skip]
pub(super) const TSIT5: Tableau<STAGES, STAGES, 4> = Tableau {
    c: [
        0.0, 0.161, 0.327, 0.9,
        0.9800255409045097, 1.0, 1.0,
    ],
    a: [
        &[],
        &[0.161],
        &[-0.008480655492356989, 0.335480655492357],
        &[2.8971530571054935, -6.359448489975075, 4.3622954328695815],
        &[
            5.325864828439257, -11.748883564062828, 7.4955393428898365,
            -0.09249506636175525,
        ],
        &[
            5.86145544294642, -12.92096931784711, 8.159367898576159,
            -0.071584973281401, -0.028269050394068383,
        ],
        // FSAL: stage 7 is F(t₀ + h, y₁), its row is b.
        B.split_at(STAGES - 1).0,
    ],
    b: B,
    btilde: [
        -0.001780011052225777, -0.0008164344596567469, 0.007880878010261995, -0.1447110071732629,
        0.5823571654525552, -0.45808210592918697, 0.015151515151515152,
    ],
    dense: [
        [1.0, -2.763706197274826, 2.9132554618219126, -1.0530884977290216],
        [0.0, 0.1317, -0.2234, 0.1017],
        [0.0, 3.9302962368947516, -5.941033872131505, 2.490627285651253],
        [0.0, -12.411077166933676, 30.33818863028232, -16.548102889244902],
        [0.0, 37.50931341651104, -88.1789048947664, 47.37952196281928],
        [0.0, -27.896526289197286, 65.09189467479366, -34.87065786149661],
        [0.0, 1.5, -4.0, 2.5],
    ],
    error_order: 5.0,
    last_stage_is_solution: true,
    stiffness_test: true,
};

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tableau_order_conditions() {
        super::super::explicit::check_tableau(&TSIT5, 5, 4, 4, 1e-13);
        assert_eq!(TSIT5.a[STAGES - 1], &TSIT5.b[..STAGES - 1]);
        assert_eq!(TSIT5.b[STAGES - 1], 0.0);
    }
}
