//! The closed-form test matrix, the way diffsol's tests are written: a list of [`Case`]s
//! (a model, its parameters and options, and a check against its closed form) run under
//! every [`Method`] with a per-method tolerance table ([`tol`]). Known failures would be
//! listed in [`KNOWN_FAILURES`] and skipped by the matrix (the list is empty).

use super::ball::{ceiling_closed, flights, zeno_series, BallCost, BallSpec};
use super::check::{has, tight, Report};
use super::models::{relay_closed, thermostat_closed, Decay, Dip, Kink, Relay, Thermostat, Twin};
use super::{AdModel, Sc, D};
use mvad_runtime::error::SolveError;
use mvad_runtime::fixtures::Ball as Fixture;
use mvad_runtime::solution::{DiagnosticKind, Method, Options, Solution};
use mvad_runtime::solve::solve;
use nalgebra::DVector;

/// Factors on a case's base tolerances (the ones its original test asserted under `auto`):
/// `t` on event times, `x` on everything else.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Tol {
    /// Event times.
    pub t: f64,
    /// Costs, gradients, slopes, atoms, states.
    pub x: f64,
}

/// The per-method tolerance table. Tsit5 reproduces a parabola to rounding; Verner's
/// interpolant to ~2e-13 (its coefficients), hence 10× on event times; Rosenbrock leaves
/// 1.1e-11 in dΣv⁺²/dv0 = 0 against the floor of 1e-11, hence 2× on the rest.
pub fn tol(method: Method) -> Tol {
    match method {
        Method::Auto | Method::Tsit5 => Tol { t: 1.0, x: 1.0 },
        Method::Verner9 => Tol { t: 10.0, x: 1.0 },
        Method::Rosenbrock => Tol { t: 1.0, x: 2.0 },
    }
}

/// Checks a solution (with the tolerance factors and the run's wall time in seconds).
pub type Check = Box<dyn Fn(&Solution, Tol, f64, &mut Report)>;
/// Solves the case's model with the given options.
pub type Run = Box<dyn Fn(&Options) -> Result<Solution, SolveError>>;

/// One model with its closed-form reference.
pub struct Case {
    /// Unique name, used in messages and in [`KNOWN_FAILURES`].
    pub name: String,
    /// Options (the method is set per run).
    pub opts: Options,
    /// The methods the case applies to (a stiff case leaves the explicit ones out).
    pub methods: &'static [Method],
    /// Solves.
    pub run: Run,
    /// Checks.
    pub check: Check,
}

/// Cases whose check fails under a method: (case, method, what happens). Each is a bug to
/// fix; the matrix skips them, and the list is empty: the near-grazing ceiling under Verner9
/// and the narrow dip under auto/Tsit5 (a peak between the last interior sample and t₁) are
/// found since the scanner searches that last interval too.
pub const KNOWN_FAILURES: &[(&str, Method, &str)] = &[];

/// Methods for the stiff cases: the explicit ones would need ~1e8 steps.
pub const STIFF: &[Method] = &[Method::Auto, Method::Rosenbrock];

fn ad_case<T: super::Spec + Clone + 'static>(
    name: String,
    spec: T,
    p: &[f64],
    opts: Options,
    methods: &'static [Method],
    check: Check,
) -> Case {
    let p = DVector::from_column_slice(p);
    Case {
        name,
        opts,
        methods,
        run: Box::new(move |o| solve(&AdModel::new(spec.clone()), &p, o)),
        check,
    }
}

/// Event count and times against `want` (relative `rel`).
pub fn check_events(r: &mut Report, sol: &Solution, want: &[f64], rel: f64) {
    r.eq("event count", sol.events.len(), want.len());
    for (i, (e, t)) in sol.events.iter().zip(want).enumerate() {
        r.close(&format!("event {i} time"), e.t, *t, rel, 0.0);
    }
}

/// The cost against `c.v` and the gradient against `c`'s first `np` directions, each with
/// (relative, absolute) tolerances.
fn cost_and_grad(
    r: &mut Report,
    sol: &Solution,
    c: &D,
    np: usize,
    cost: (f64, f64),
    grad: (f64, f64),
) {
    r.close("cost", sol.cost, c.v, cost.0, cost.1);
    r.all_close("grad", &sol.gradient, &c.g[..np], grad.0, grad.1);
}

fn dual(p: &[f64]) -> impl Fn(usize) -> D + '_ {
    |i| D::var(p[i], i)
}

/// Every case of the matrix.
pub fn cases() -> Vec<Case> {
    let mut out = vec![e1_fixture()];
    out.extend(e1_costs());
    out.extend(e2_first_impacts());
    out.extend(thermostats());
    out.push(relay());
    out.extend(ceilings());
    out.push(kink());
    out.extend(zeno_balls());
    out.push(inelastic());
    out.extend(dips());
    out.push(twin());
    out.push(decay());
    out
}

/// E1 with the hand-written (static-size) ball: impacts, ∫h and its gradient.
fn e1_fixture() -> Case {
    let ball = Fixture::new();
    let p = ball.default_params();
    let (cf, impacts) = flights_dual(p.as_slice(), 2.0);
    Case {
        name: "E1 fixture".into(),
        opts: tight(),
        methods: &Method::ALL,
        run: Box::new(move |o| solve(&ball, &p, o)),
        check: Box::new(move |sol, tol, _, r| {
            check_events(r, sol, &impacts, 1e-13 * tol.t);
            r.close("cost", sol.cost, cf[0].v, 1e-10 * tol.x, 0.0);
            r.all_close(
                "∫h",
                &sol.gradient,
                &cf[0].g[..4],
                1e-9 * tol.x,
                1e-12 * tol.x,
            );
        }),
    }
}

/// [`flights`] differentiated in all four parameters.
pub fn flights_dual(p: &[f64], t_end: f64) -> ([D; 5], Vec<f64>) {
    let d = dual(p);
    flights(d(0), d(1), d(2), d(3), t_end)
}

/// E1 with each cost at three parameter points.
fn e1_costs() -> Vec<Case> {
    let points = [
        [0.8, 9.81, 2.0, 0.0],
        [0.7, 9.0, 1.5, 0.8],
        [0.9, 9.81, 1.0, -2.0],
    ];
    let mut out = vec![];
    for cost in BallCost::CLOSED_FORM {
        for p in points {
            let (cf, impacts) = flights_dual(&p, 2.0);
            let c = cf[cost as usize];
            let check: Check = Box::new(move |sol, tol, _, r| {
                check_events(r, sol, &impacts, 1e-13 * tol.t);
                cost_and_grad(
                    r,
                    sol,
                    &c,
                    4,
                    (1e-9 * tol.x, 1e-12 * tol.x),
                    (1e-9 * tol.x, 1e-11 * tol.x),
                );
            });
            let name = format!("E1 {cost:?} θ={p:?}");
            out.push(ad_case(
                name,
                BallSpec::new(cost, 2.0),
                &p,
                tight(),
                &Method::ALL,
                check,
            ));
        }
    }
    out
}

/// E2: first impact of the ball from h0 = 1 for v0 = −0.5 … −5: event time, guard slope,
/// t' (all params), the velocity atom and the zero position atom, against the closed form
/// t1 = (v0 + √(v0² + 2 g h0))/g, v⁻ = v0 − g t1, J_v = −(1 + e) v⁻, α = −J t1'.
fn e2_first_impacts() -> Vec<Case> {
    let reference = [
        (-0.5, 0.403_422_815_250_207_34, 4.457_577_817_604_534),
        (-5.0, 0.171_235_510_383_883_18, 6.679_820_356_865_894),
    ];
    (0..10)
        .map(|i| {
            let v0 = -0.5 * (i + 1) as f64;
            let p = [0.8, 9.81, 1.0, v0];
            let d = dual(&p);
            let (e, g, h0, v0d) = (d(0), d(1), d(2), d(3));
            let t1 = (v0d + (v0d * v0d + g * h0 * 2.0).sqrt()) / g;
            let vminus = v0d - g * t1;
            let jv = -(vminus * (e + 1.0));
            let refv = reference.iter().find(|r| r.0 == v0).copied();
            let check: Check = Box::new(move |sol, tol, _, r| {
                let Some(evr) = sol.events.first() else {
                    return r.check(false, || "no event".into());
                };
                r.close("t1", evr.t, t1.v, 1e-13 * tol.t, 0.0);
                r.close("slope", evr.guard_slope, vminus.v, 1e-11 * tol.x, 0.0);
                r.check(evr.transversal, || "not transversal".into());
                if let Some((_, t, slope)) = refv {
                    r.close("t1 reference", evr.t, t, 1e-13 * tol.t, 0.0);
                    r.close(
                        "slope reference",
                        evr.guard_slope.abs(),
                        slope,
                        1e-11 * tol.x,
                        0.0,
                    );
                }
                r.all_close("t'", &evr.dt, &t1.g[..4], 1e-10 * tol.x, 1e-13 * tol.x);
                r.close("J_v", evr.jump_states[1], jv.v, 1e-11 * tol.x, 0.0);
                r.eq("J_h", evr.jump_states[0], 0.0);
                // atoms[observable][param]: height atoms exactly zero, velocity atoms −J_v t'.
                r.check(evr.atoms[0].iter().all(|&a| a == 0.0), || {
                    format!("height atoms {:?}", evr.atoms[0])
                });
                let want: Vec<f64> = (0..4).map(|j| -jv.v * t1.g[j]).collect();
                r.all_close(
                    "velocity atom",
                    &evr.atoms[1],
                    &want,
                    1e-10 * tol.x,
                    1e-13 * tol.x,
                );
            });
            let spec = BallSpec::new(BallCost::IntH, t1.v + 0.01);
            ad_case(
                format!("E2 v0={v0}"),
                spec,
                &p,
                tight(),
                &Method::ALL,
                check,
            )
        })
        .collect()
}

/// Two-mode thermostat, costs ∫temp and ∫(temp − 20)², all four parameters.
fn thermostats() -> Vec<Case> {
    let p = [0.5, 18.0, 22.0, 10.0];
    let d = dual(&p);
    let (c1, c2, nev) = thermostat_closed(d(0), d(1), d(2), d(3), 10.0);
    [(false, c1), (true, c2)]
        .into_iter()
        .map(|(squared, c)| {
            // Exponential segments: S is put under error control too.
            let opts = Options {
                sens_error_control: true,
                ..tight()
            };
            let check: Check = Box::new(move |sol, tol, _, r| {
                r.eq("event count", sol.events.len(), nev);
                cost_and_grad(
                    r,
                    sol,
                    &c,
                    4,
                    (1e-9 * tol.x, 1e-12 * tol.x),
                    (1e-9 * tol.x, 1e-11 * tol.x),
                );
                r.eq("final mode", sol.mode_final, nev % 2);
            });
            let name = format!("thermostat squared={squared}");
            ad_case(name, Thermostat { squared }, &p, opts, &Method::ALL, check)
        })
        .collect()
}

/// The stiff relay (τ = 1e-8) at rtol 1e-8: events, few steps, cost and gradient.
fn relay() -> Case {
    let p = [1.0, 0.2, 1.0];
    let d = dual(&p);
    let (c, nev) = relay_closed(d(0), d(1), d(2), 3.0);
    let opts = Options {
        rtol: 1e-8,
        atol: 1e-10,
        ..Options::default()
    };
    let check: Check = Box::new(move |sol, tol, _, r| {
        r.eq("event count", sol.events.len(), nev);
        r.check(sol.stats.steps < 5000, || {
            format!("{} steps", sol.stats.steps)
        });
        cost_and_grad(
            r,
            sol,
            &c,
            3,
            (1e-6 * tol.x, 0.0),
            (1e-6 * tol.x, 1e-9 * tol.x),
        );
    });
    ad_case("stiff relay".into(), Relay, &p, opts, STIFF, check)
}

/// The ceiling bounce as H approaches the apex (grazing), with per-gap tolerances.
fn ceilings() -> Vec<Case> {
    // Apex of h0 = 1, v0 = 3: 1 + 9/(2·9.81).
    let apex = 1.0 + 9.0 / (2.0 * 9.81);
    [(1e-1, 1e-9), (1e-3, 1e-8), (1e-5, 1e-7), (1e-7, 1e-5)]
        .into_iter()
        .map(|(gap, rel)| {
            let p = [0.8, 9.81, 1.0, 3.0, apex - gap];
            let d = dual(&p);
            let (c, tc, vc) = ceiling_closed(d(0), d(1), d(2), d(3), d(4), 0.6);
            let check: Check = Box::new(move |sol, tol, _, r| {
                r.eq("event count", sol.events.len(), 1);
                let Some(evr) = sol.events.first() else {
                    return;
                };
                r.close("t_c", evr.t, tc.v, 1e-9 * tol.t, 0.0);
                r.close("slope", evr.guard_slope, vc.v, rel * tol.x, 1e-12 * tol.x);
                let grazing = has(sol, DiagnosticKind::Grazing);
                // |∇g·f| = v_c against τ |∇g| |f| = 1e-3 √(v_c² + g²).
                r.eq(
                    "grazing",
                    grazing,
                    vc.v < 1e-3 * (vc.v * vc.v + 9.81 * 9.81).sqrt(),
                );
                r.eq("transversal", evr.transversal, !grazing);
                cost_and_grad(
                    r,
                    sol,
                    &c,
                    5,
                    (1e-9 * tol.x, 1e-12 * tol.x),
                    (rel * tol.x, 1e-9 * tol.x),
                );
                r.all_close("t'", &evr.dt, &tc.g[..5], rel * tol.x, 1e-9 * tol.x);
            });
            let name = format!("ceiling gap {gap:e}");
            ad_case(name, BallSpec::ceiling(), &p, tight(), &Method::ALL, check)
        })
        .collect()
}

/// ẋ = −|x − c| − 1, ℓ = x + |x − c|: one switch crossing, no event; cost, gradient, FD.
fn kink() -> Case {
    let p = [1.5, 0.5];
    let (x0, c) = (D::var(p[0], 0), D::var(p[1], 1));
    let y0 = x0 - c;
    let ts = (y0 + 1.0).ln();
    let t_end = 2.0;
    // ∫y: before (y0+1)(1 − e^{−t*}) − t*, after (T − t*) − (e^{T − t*} − 1).
    let int_before = (y0 + 1.0) * (-((-ts).exp()) + 1.0) - ts;
    let int_after = -(ts - t_end) - ((-(ts - t_end)).exp() - 1.0);
    // ∫x = cT + ∫y; ∫|y| = ∫_before y − ∫_after y.
    let want = c * t_end + int_before + int_after + int_before - int_after;
    let opts = Options {
        sens_error_control: true,
        ..tight()
    };
    let check: Check = Box::new(move |sol, tol, _, r| {
        r.eq("switch crossings", sol.stats.switch_crossings, 1);
        r.eq("event count", sol.events.len(), 0);
        cost_and_grad(
            r,
            sol,
            &want,
            2,
            (1e-9 * tol.x, 0.0),
            (1e-9 * tol.x, 1e-11 * tol.x),
        );
        let pv = DVector::from_column_slice(&p);
        match mvad_runtime::fd::fd_full_gradient(&AdModel::new(Kink), &pv, &tight(), 1e-6) {
            Ok(fd) => r.all_close("fd", &fd, &want.g[..2], 1e-6, 1e-8),
            Err(e) => r.check(false, || format!("fd: {e:?}")),
        }
    });
    ad_case("kink".into(), Kink, &p, opts, &Method::ALL, check)
}

/// Zeno balls past their accumulation time: t*, cost and gradient against the exact
/// series, never through the floor, quickly. e = 0.5 at T = 3, then e = 0.3 … 0.99 at T = 200.
fn zeno_balls() -> Vec<Case> {
    let mut out = vec![];
    for (e, t_end) in [
        (0.5, 3.0),
        (0.3, 200.0),
        (0.9, 200.0),
        (0.95, 200.0),
        (0.97, 200.0),
        (0.99, 200.0),
    ] {
        let spec = BallSpec::int_h(t_end, e);
        let p = spec.defaults.clone();
        let d = dual(&p);
        let (c, t_star) = zeno_series(d(0), d(1), d(2), d(3));
        let check: Check = if t_end == 3.0 {
            Box::new(move |sol, tol, wall, r| {
                let z: Vec<_> = sol
                    .diagnostics
                    .iter()
                    .filter(|d| d.kind == DiagnosticKind::Zeno)
                    .collect();
                r.eq("zeno diagnostics", z.len(), 1);
                if let Some(z) = z.first() {
                    r.close("t*", z.t, t_star.v, 0.0, 1e-6 * tol.t);
                }
                cost_and_grad(r, sol, &c, 4, (0.0, 1e-6 * tol.x), (0.0, 1e-6 * tol.x));
                r.check(wall < 0.5, || format!("took {wall} s"));
                // Never through the floor.
                r.check(
                    sol.x_final[0].abs() < 1e-6 && sol.x_final[1].abs() < 1e-3,
                    || format!("x(T) = {:?}", sol.x_final),
                );
            })
        } else {
            Box::new(move |sol, tol, wall, r| {
                let z = sol.diagnostic(DiagnosticKind::Zeno);
                r.check(z.is_some(), || "no zeno diagnostic".into());
                if let Some(z) = z {
                    r.close("t*", z.t, t_star.v, 1e-9 * tol.t, 0.0);
                }
                cost_and_grad(
                    r,
                    sol,
                    &c,
                    4,
                    (1e-9 * tol.x, 0.0),
                    (1e-6 * tol.x, 1e-9 * tol.x),
                );
                r.check(sol.x_final[0] > -1e-9, || {
                    format!("through the floor {:?}", sol.x_final)
                });
                r.check(wall < 1.0, || format!("took {wall} s"));
            })
        };
        out.push(ad_case(
            format!("zeno e={e} T={t_end}"),
            spec,
            &p,
            tight(),
            &Method::ALL,
            check,
        ));
    }
    out
}

/// e = 0: the ball stops dead on the floor at the first impact and must stay there.
fn inelastic() -> Case {
    let spec = BallSpec::int_h(2.0, 0.0);
    let p = spec.defaults.clone();
    let d = dual(&p);
    let (g, h0) = (d(1), d(2));
    // C = ∫ h over the fall = h0 t1 − g t1³/6 with t1 = √(2 h0/g); then h = 0.
    let t1 = (h0 * 2.0 / g).sqrt();
    let c = h0 * t1 - g * t1 * t1 * t1 / 6.0;
    let opts = Options {
        record: true,
        ..tight()
    };
    let check: Check = Box::new(move |sol, tol, _, r| {
        r.eq("event count", sol.events.len(), 1);
        r.check(has(sol, DiagnosticKind::Zeno), || {
            format!("{:?}", sol.diagnostics)
        });
        r.check(
            sol.x_final[0].abs() < 1e-12 * tol.x && sol.x_final[1].abs() < 1e-12 * tol.x,
            || format!("x(T) = {:?}", sol.x_final),
        );
        r.close("cost", sol.cost, c.v, 1e-10 * tol.x, 0.0);
        r.all_close(
            "grad θ1..3",
            &sol.gradient[1..3],
            &c.g[1..3],
            1e-8 * tol.x,
            1e-12 * tol.x,
        );
        match &sol.trajectory {
            Some(traj) => {
                let (x, _) = traj.sample(1.5);
                r.check(x[0].abs() < 1e-12 * tol.x, || format!("h(1.5) = {}", x[0]));
            }
            None => r.check(false, || "no trajectory recorded".into()),
        }
    });
    ad_case("inelastic ball".into(), spec, &p, opts, &Method::ALL, check)
}

/// A dip of width 2w that a coarse step straddles without a sign change at its samples.
fn dips() -> Vec<Case> {
    [1e-2, 1e-3, 1e-5]
        .into_iter()
        .map(|w| {
            let check: Check = Box::new(move |sol, tol, _, r| {
                r.check(sol.stats.steps < 60, || {
                    format!("{} steps", sol.stats.steps)
                });
                let names: Vec<usize> = sol.events.iter().map(|e| e.event).collect();
                r.eq("events", names, vec![0, 1]);
                // Pass-through events with identity resets are not "stuck".
                r.check(sol.diagnostics.is_empty(), || {
                    format!("{:?}", sol.diagnostics)
                });
                if sol.events.len() == 2 {
                    let (a, b) = (&sol.events[0], &sol.events[1]);
                    r.close("t_enter", a.t, 0.5 - w, 0.0, 1e-13 * tol.t);
                    r.close("t_leave", b.t, 0.5 + w, 0.0, 1e-13 * tol.t);
                    // t' = (1, −1) and (1, 1): t_enter = c − w, t_leave = c + w.
                    r.all_close("t_enter'", &a.dt, &[1.0, -1.0], 0.0, 1e-9 * tol.x);
                    r.all_close("t_leave'", &b.dt, &[1.0, 1.0], 0.0, 1e-9 * tol.x);
                }
            });
            ad_case(
                format!("dip w={w:e}"),
                Dip,
                &[0.5, w],
                tight(),
                &Method::ALL,
                check,
            )
        })
        .collect()
}

/// Two events on the same guard: fired at the same time in declaration order, reported.
fn twin() -> Case {
    let check: Check = Box::new(move |sol, tol, _, r| {
        let names: Vec<usize> = sol.events.iter().map(|e| e.event).collect();
        r.eq("events", names, vec![0, 1]);
        if sol.events.len() == 2 {
            r.eq("same time", sol.events[0].t, sol.events[1].t);
        }
        // (1 + 1)·2, not 1·2 + 1.
        r.close("y(T)", sol.x_final[1], 4.0, 0.0, 1e-14 * tol.x);
        r.check(has(sol, DiagnosticKind::SimultaneousEvents), || {
            format!("{:?}", sol.diagnostics)
        });
        // At (c, y0, u, v) = (0.4, 1, 1, 2): C = 0.4·1 + 0.6·4 + 4² = 18.8, dC/dc = 1 − 4 = −3.
        r.close("cost", sol.cost, 18.8, 0.0, 1e-12 * tol.x);
        r.close("dC/dc", sol.gradient[0], -3.0, 0.0, 1e-9 * tol.x);
    });
    let p = [0.4, 1.0, 1.0, 2.0];
    ad_case("twin".into(), Twin, &p, tight(), &Method::ALL, check)
}

/// No parameters: x = e^{−t} until ln 2, then 0.25 e^{−(t − ln 2)}.
fn decay() -> Case {
    let check: Check = Box::new(move |sol, tol, _, r| {
        r.check(sol.gradient.is_empty(), || {
            format!("gradient {:?}", sol.gradient)
        });
        r.eq("event count", sol.events.len(), 1);
        // ∫ = 0.5 + 0.25 (1 − e^{−(2 − ln 2)}).
        let want = 0.5 + 0.25 * (1.0 - (-(2.0 - 2f64.ln())).exp());
        r.close("cost", sol.cost, want, 1e-9 * tol.x, 0.0);
    });
    ad_case(
        "decay without parameters".into(),
        Decay,
        &[],
        tight(),
        &Method::ALL,
        check,
    )
}

/// Runs `case` under `method` and checks it; the failures, each prefixed with the case
/// and the method.
pub fn run(case: &Case, method: Method) -> Vec<String> {
    let opts = Options {
        method,
        ..case.opts.clone()
    };
    let mut r = Report::default();
    let start = std::time::Instant::now();
    match (case.run)(&opts) {
        Ok(sol) => (case.check)(&sol, tol(method), start.elapsed().as_secs_f64(), &mut r),
        Err(e) => r.check(false, || format!("solve failed: {e:?}")),
    }
    r.0.into_iter()
        .map(|m| format!("{} under {method:?}: {m}", case.name))
        .collect()
}

/// Runs every case under every method it applies to, except the [`KNOWN_FAILURES`], and
/// asserts that there were at least `min_runs` runs and no failure (all reported at once).
pub fn run_matrix(cases: impl IntoIterator<Item = Case>, min_runs: usize) {
    let mut failures = vec![];
    let mut runs = 0;
    for case in cases {
        for &method in case.methods {
            if known(&case.name, method) {
                continue;
            }
            failures.extend(run(&case, method));
            runs += 1;
        }
    }
    assert!(runs >= min_runs, "{runs} runs");
    assert!(
        failures.is_empty(),
        "{} failures:\n{}",
        failures.len(),
        failures.join("\n")
    );
}

/// Whether (case, method) is a listed known failure.
pub fn known(case: &str, method: Method) -> bool {
    KNOWN_FAILURES
        .iter()
        .any(|(c, m, _)| *c == case && *m == method)
}
