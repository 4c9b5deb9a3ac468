//! Qp layers through both doors: the paper's E3 (`models/qp_kink.hyb`) swept over 101
//! points of θ ∈ [−1, 1] against its closed form (counts of active, boundary and inactive
//! points, mean error of dJ/dθ, the kink at θ = 0 with both one-sided derivatives), and the
//! compiled and loaded models agreeing.

use models::qp_kink::{self, QpKink};
use mvad::interp::InterpretedModel;
use mvad::qp::ConstraintStatus;
use mvad::{solve, DiagnosticKind, HybridModel, ModelAlloc, Options};
use mvad_tests::model_source;
use nalgebra::{DefaultAllocator, OVector};

/// θ_i = (i − 50)/50, i = 0..=100: θ = 0 exactly at i = 50.
fn thetas() -> impl Iterator<Item = f64> {
    (0..=100).map(|i| (i as f64 - 50.0) / 50.0)
}

/// (active, boundary, inactive) counts and the mean |dJ/dθ − θH(θ)| of the E3 sweep.
fn e3_sweep<M: HybridModel>(m: &M) -> ((usize, usize, usize), f64)
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let (mut counts, mut err) = ((0, 0, 0), 0.0);
    for theta in thetas() {
        let p =
            OVector::<f64, M::P>::from_element_generic(m.nparams(), nalgebra::Const::<1>, theta);
        let sol = solve(m, &p, &Options::default()).expect("E3 solves");
        assert_eq!(sol.qp.len(), 1);
        let u = sol.qp[0].u[0];
        assert_eq!(u, qp_kink::solution(theta));
        assert_eq!(sol.cost, 0.5 * u * u);
        err += (sol.gradient[0] - qp_kink::gradient(theta)).abs();
        let kink = sol
            .diagnostics
            .iter()
            .any(|d| d.kind == DiagnosticKind::Kink);
        match sol.qp[0].status[0] {
            ConstraintStatus::Active => counts.0 += 1,
            ConstraintStatus::WeaklyActive => {
                counts.1 += 1;
                assert_eq!(theta, 0.0);
                assert!(kink);
                // dJ/dθ = u du/dθ = 0 on both sides at u = 0.
                assert_eq!(sol.gradient_left.as_deref(), Some(&[0.0][..]));
            }
            ConstraintStatus::Inactive => counts.2 += 1,
        }
        if sol.qp[0].status[0] != ConstraintStatus::WeaklyActive {
            assert!(!kink && sol.gradient_left.is_none());
        }
    }
    (counts, err / 101.0)
}

#[test]
fn e3_sweep_compiled_and_loaded() {
    let loaded = InterpretedModel::from_source(&model_source("qp_kink.hyb")).expect("loads");
    for (counts, mean) in [e3_sweep(&QpKink::new()), e3_sweep(&loaded)] {
        assert_eq!(counts, (50, 1, 50));
        assert!(mean <= 1e-15, "mean error {mean}");
    }
}
