//! Events that chatter — a sliding mode, where the flow on both sides of a guard or a kink
//! points into it — stop at `max_events` with a message that says so (before, only
//! "stopped after 100000 events"), through both doors; a flood that is not chattering (many
//! events spread over the run) keeps the plain message.

use mvad::interp::InterpretedModel;
use mvad::runtime::error::SolveError;
use mvad::runtime::solution::Options;

mvad::hybrid!(include "tests/sliding.hyb");

const THERMOSTAT_NO_HYSTERESIS: &str = "model Chatter {
    param lo = 20; param hi = 20;
    state temp = 18;
    initial mode heat;
    mode heat { der(temp) = 1; event off when temp >= hi -> cool; }
    mode cool { der(temp) = -1; event on when temp <= lo -> heat; }
    cost = integral(temp);
    horizon 10;
}";

const FLOOD: &str = "model Flood {
    state x = 0;
    flow { der(x) = 1; }
    event tick when x >= 0.001 { x = 0; }
    cost = integral(x);
    horizon 10;
}";

fn chatter_message(err: SolveError) -> String {
    assert!(matches!(err, SolveError::MaxEvents { .. }), "{err:?}");
    err.to_string()
}

#[test]
fn a_sliding_mode_is_named_as_chattering() {
    let opts = Options {
        max_events: 2000,
        ..Options::default()
    };
    let loaded = mvad_tests::loaded_test_model("sliding.hyb");
    for err in [
        mvad_tests::solve_at(&Sliding::new(), &[0.5], &opts).unwrap_err(),
        mvad_tests::solve_at(&loaded, &[0.5], &opts).unwrap_err(),
        mvad_tests::solve_at(
            &InterpretedModel::from_source(THERMOSTAT_NO_HYSTERESIS).expect("valid"),
            &[20.0, 20.0],
            &opts,
        )
        .unwrap_err(),
    ] {
        let msg = chatter_message(err);
        assert!(msg.contains("the events chatter"), "{msg}");
        assert!(msg.contains("sliding mode"), "{msg}");
    }
}

#[test]
fn a_flood_spread_over_the_run_is_not_called_chattering() {
    let opts = Options {
        max_events: 2000,
        ..Options::default()
    };
    let m = InterpretedModel::from_source(FLOOD).expect("valid");
    let msg = chatter_message(mvad_tests::solve_at(&m, &[], &opts).unwrap_err());
    assert!(msg.contains("stopped after 2000 events"), "{msg}");
    assert!(!msg.contains("chatter"), "{msg}");
}
