//! More than 64 switching functions: a flow with 70 kinks, ẏ = Σᵢ |x − cᵢ| with x = a t and
//! cᵢ = 0.05 + i/10 (i < 70), through both doors against the closed form
//! y(T) = Σᵢ (cᵢ² + (aT − cᵢ)²)/(2a) for the cᵢ crossed before T (and Σᵢ (cᵢ − a t) dt beyond).

use mvad::interp::InterpretedModel;
use mvad::{solve, HybridModel, ModelAlloc, Options};
use nalgebra::{DefaultAllocator, OVector};

mvad::hybrid! {
    model Kinks70 {
        param a = 1.3;
        state x = 0;
        state y = 0;
        flow {
            der(x) = a;
            der(y) =
                   abs(x - 0.05) + abs(x - 0.15) + abs(x - 0.25) + abs(x - 0.35) + abs(x - 0.45) +
                   abs(x - 0.55) + abs(x - 0.65) + abs(x - 0.75) + abs(x - 0.85) + abs(x - 0.95) +
                   abs(x - 1.05) + abs(x - 1.15) + abs(x - 1.25) + abs(x - 1.35) + abs(x - 1.45) +
                   abs(x - 1.55) + abs(x - 1.65) + abs(x - 1.75) + abs(x - 1.85) + abs(x - 1.95) +
                   abs(x - 2.05) + abs(x - 2.15) + abs(x - 2.25) + abs(x - 2.35) + abs(x - 2.45) +
                   abs(x - 2.55) + abs(x - 2.65) + abs(x - 2.75) + abs(x - 2.85) + abs(x - 2.95) +
                   abs(x - 3.05) + abs(x - 3.15) + abs(x - 3.25) + abs(x - 3.35) + abs(x - 3.45) +
                   abs(x - 3.55) + abs(x - 3.65) + abs(x - 3.75) + abs(x - 3.85) + abs(x - 3.95) +
                   abs(x - 4.05) + abs(x - 4.15) + abs(x - 4.25) + abs(x - 4.35) + abs(x - 4.45) +
                   abs(x - 4.55) + abs(x - 4.65) + abs(x - 4.75) + abs(x - 4.85) + abs(x - 4.95) +
                   abs(x - 5.05) + abs(x - 5.15) + abs(x - 5.25) + abs(x - 5.35) + abs(x - 5.45) +
                   abs(x - 5.55) + abs(x - 5.65) + abs(x - 5.75) + abs(x - 5.85) + abs(x - 5.95) +
                   abs(x - 6.05) + abs(x - 6.15) + abs(x - 6.25) + abs(x - 6.35) + abs(x - 6.45) +
                   abs(x - 6.55) + abs(x - 6.65) + abs(x - 6.75) + abs(x - 6.85) + abs(x - 6.95);
        }
        cost = final(y);
        horizon 5.8;
    }
}

/// The same model as text for the loader.
fn source() -> String {
    let terms: Vec<String> = (0..70)
        .map(|i| format!("abs(x - {:.2})", 0.05 + f64::from(i) / 10.0))
        .collect();
    format!(
        "model Kinks70 {{ param a = 1.3; state x = 0; state y = 0; \
         flow {{ der(x) = a; der(y) = {}; }} cost = final(y); horizon 5.8; }}",
        terms.join(" + ")
    )
}

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
    let loaded = InterpretedModel::from_source(&source()).expect("the model loads");
    check(&loaded, &loaded.default_params(), "loaded");
}
