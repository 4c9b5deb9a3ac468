//! The measure of an observable under a horizon that moves with θ (`horizon Tf`): its support
//! ends at T(θ), so it has the atom y(T⁻) dT/dθ there and ⟨μ, 1⟩ = d/dθ ∫₀ᵀ y dt for every
//! parameter, the horizon's included. Both doors, against the closed form and against the
//! gradient of `cost = integral(x)`.

use mvad::runtime::measure::AtomOrigin;
use mvad::runtime::solution::Options;
use mvad::{measure, HybridModel, ModelAlloc};
use mvad_tests::assert_near;
use nalgebra::{Const, DefaultAllocator, OVector};

mvad::hybrid!(include "tests/moving_horizon.hyb");

fn check<M: HybridModel>(m: &M, door: &str)
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    let (k, tau, d, tf) = (0.8_f64, 0.6, 0.5, 2.5);
    let x_end = ((-k * tau).exp() + d) * (-k * (tf - tau)).exp();
    let p = OVector::<f64, M::P>::from_iterator_generic(
        m.nparams(),
        Const::<1>,
        m.info().param_defaults.iter().copied(),
    );
    let opts = Options {
        rtol: 1e-11,
        atol: 1e-13,
        record: true,
        ..Options::default()
    };
    let sol = mvad::solve(m, &p, &opts).expect("runs");
    assert_near(sol.dt_end[3], 1.0, 0.0, format_args!("{door}: dT/dTf"));
    let y = m.info().observable_index("y").unwrap();
    let mu = measure(m, &p, &sol, y).unwrap();
    let total = mu.pair(|_| 1.0);
    for (i, name) in ["k", "tau", "d", "Tf"].iter().enumerate() {
        // cost = integral(x) = ∫y: its gradient is ⟨μ_y, 1⟩ for every parameter.
        assert_near(
            total[i],
            sol.gradient[i],
            1e-9,
            format_args!("{door}: d/d{name} ∫y against the gradient"),
        );
    }
    assert_near(total[3], x_end, 1e-9, format_args!("{door}: d/dTf ∫y"));
    let (t, alpha) = mu.atoms.last().unwrap();
    assert_eq!(*t, tf, "{door}: the horizon atom sits at T");
    assert_near(alpha[3], x_end, 1e-9, format_args!("{door}: α_T"));
    assert!(alpha[..3].iter().all(|&a| a == 0.0), "{door}: {alpha:?}");
    match mu.origins.last().unwrap() {
        AtomOrigin::Horizon { jump } => {
            assert_near(*jump, -x_end, 1e-9, format_args!("{door}: J at T"))
        }
        o => panic!("{door}: the last atom is {o:?}"),
    }
    let z = m.info().observable_index("z").unwrap();
    let mu_z = measure(m, &p, &sol, z).unwrap();
    assert_near(
        mu_z.pair_density(|_| 1.0)[3],
        0.0,
        1e-12,
        format_args!("{door}: z's density in Tf"),
    );
    assert_near(
        mu_z.pair(|_| 1.0)[3],
        x_end * tf,
        1e-9,
        format_args!("{door}: d/dTf ∫z"),
    );

    // A horizon fixed by the options does not move: no atom at T, nothing in Tf.
    let fixed = Options {
        t_end: Some(tf),
        ..opts
    };
    let sol = mvad::solve(m, &p, &fixed).expect("runs");
    let mu = measure(m, &p, &sol, y).unwrap();
    assert!(
        !mu.origins
            .iter()
            .any(|o| matches!(o, AtomOrigin::Horizon { .. })),
        "{door}: {:?}",
        mu.origins
    );
    assert_eq!(mu.pair(|_| 1.0)[3], 0.0, "{door}");
}

mvad_tests::test_both_doors!(
    a_moving_horizon_is_an_atom_of_every_observables_measure: check,
    MovingHorizon::new(),
    "moving_horizon.hyb"
);
