//! More than 64 switching functions: a flow with 70 kinks, ẏ = Σᵢ |x − cᵢ| with x = a t and
//! cᵢ = 0.05 + i/10 (i < 70; `kinks70.hyb`), through both doors against the closed form
//! y(T) = Σᵢ (cᵢ² + (aT − cᵢ)²)/(2a) for the cᵢ crossed before T (and Σᵢ (cᵢ − a t) dt beyond).

use mvad::interp::InterpretedModel;
use mvad::{solve, HybridModel, ModelAlloc, Options};
use nalgebra::{DefaultAllocator, OVector};

mvad::hybrid!(include "tests/kinks70.hyb");

/// y(T) and dy(T)/da in closed form: ∫₀ᵀ |a t − c| dt is (c² + (aT − c)²)/(2a) when
/// 0 < c < aT and T(c − aT/2) when c ≥ aT.
fn closed_form(a: f64, t_end: f64) -> (f64, f64) {
    let (mut y, mut dy) = (0.0, 0.0);
    for i in 0..70 {
        let c = 0.05 + f64::from(i) / 10.0;
        let u = a * t_end;
        if c < u {
            let num = c * c + (u - c) * (u - c);
            y += num / (2.0 * a);
            dy += (u - c) * t_end / a - num / (2.0 * a * a);
        } else {
            y += t_end * (c - u / 2.0);
            dy += -t_end * t_end / 2.0;
        }
    }
    (y, dy)
}

fn check<M: HybridModel>(m: &M, p: &OVector<f64, M::P>, door: &str)
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    assert_eq!(m.info().switches, 70, "{door}");
    let opts = Options {
        rtol: 1e-10,
        atol: 1e-12,
        ..Options::default()
    };
    let sol = solve(m, p, &opts).expect("the run succeeds");
    let (y, dy) = closed_form(1.3, 5.8);
    // x = a t crosses cᵢ < aT = 7.54: all 70 kinks.
    assert_eq!(sol.stats.switch_crossings, 70, "{door}");
    assert!(
        (sol.cost - y).abs() <= 1e-8 * y.abs(),
        "{door}: C = {} vs {y}",
        sol.cost
    );
    assert!(
        (sol.gradient[0] - dy).abs() <= 1e-7 * dy.abs(),
        "{door}: dC/da = {} vs {dy}",
        sol.gradient[0]
    );
}

#[test]
fn seventy_kinks_match_the_closed_form_through_both_doors() {
    let compiled = Kinks70::new();
    check(&compiled, &compiled.default_params(), "hybrid!");
    let loaded =
        InterpretedModel::from_source(include_str!("kinks70.hyb")).expect("the model loads");
    check(&loaded, &loaded.default_params(), "loaded");
}
