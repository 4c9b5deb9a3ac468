//! Tests of the lowering: programs from source, their errors, and the depth bound.

use super::*;
use crate::ir::Point;

fn program(src: &str) -> Program {
    let model = crate::front(src).unwrap_or_else(|e| panic!("front: {e:?}"));
    lower(&model).unwrap_or_else(|e| panic!("lower: {e:?}"))
}

fn errors(src: &str) -> Vec<String> {
    match crate::front(src).and_then(|m| lower(&m)) {
        Ok(_) => Vec::new(),
        Err(e) => e.into_iter().map(|d| d.message).collect(),
    }
}

#[test]
fn events_directions_names_and_resets() {
    let p = program(
        "model M { param e = 0.8; state h = 1; state v = 0;
           flow { der(h) = v; der(v) = -9.81; }
           event impact when h <= 0 { v = -e * v; }
           event when v > 2;
           event when 1 >= h - v { h = v; v = h; } }",
    );
    assert_eq!(p.modes.len(), 1);
    assert_eq!(p.modes[0].name, "main");
    let names: Vec<&str> = p.events.iter().map(|e| e.info.name.as_str()).collect();
    assert_eq!(names, ["impact", "event_1", "event_2"]);
    let dirs: Vec<Direction> = p.events.iter().map(|e| e.info.direction).collect();
    assert_eq!(dirs, [Direction::Down, Direction::Up, Direction::Up]);
    assert!(!p.events[1].info.has_reset);
    // Identity for unassigned states; right-hand sides read the pre-event state.
    assert_eq!(p.events[0].reset[0], p.arena.clone().state(0));
    let x = [0.3, 1.7];
    let at = Point {
        t: 0.0,
        x: &x,
        p: &[0.8],
        sw: 0,
    };
    assert_eq!(p.arena.eval(&p.events[2].reset, &at), vec![1.7, 0.3]);
    // g = LHS − RHS.
    assert_eq!(
        p.arena.eval(&[p.events[2].guard], &at),
        vec![1.0 - (0.3 - 1.7)]
    );
}

#[test]
fn kinks_become_deduplicated_switches_in_flows_running_cost_and_observables() {
    let p = program(
        "model M { param a = 1; state x = 1; state y = 2;
           flow { der(x) = abs(x - y) + sign(x - y); der(y) = min(x, y) + max(y, a); }
           observe o = abs(x - y);
           event when abs(x) <= 1;
           cost = integral(max(y, a)) + final(abs(x)); }",
    );
    // abs(x−y), sign(x−y), min(x, y) share σ = x − y; max(y, a) has σ = y − a.
    assert_eq!(p.switches.len(), 2);
    let x = [0.5, 2.0];
    let th = [1.0];
    let at = |sw| Point {
        t: 0.0,
        x: &x,
        p: &th,
        sw,
    };
    // Frozen branches follow the bits, not the point: bit 0 set means x − y > 0.
    let f_pos = p.arena.eval(&p.modes[0].flow, &at(0b11));
    let f_neg = p.arena.eval(&p.modes[0].flow, &at(0b00));
    assert_eq!(f_pos, vec![(0.5 - 2.0) + 1.0, 2.0 + 2.0]);
    assert_eq!(f_neg, vec![(2.0 - 0.5) - 1.0, 0.5 + 1.0]);
    // Observables follow the bits too (their kink is the flow's σ = x − y), guards do not.
    assert_eq!(p.arena.eval(&[p.observables[0].1], &at(0b11)), vec![-1.5]);
    assert_eq!(p.arena.eval(&[p.observables[0].1], &at(0b00)), vec![1.5]);
    assert_eq!(
        p.arena.eval(&[p.events[0].guard], &at(0b11)),
        p.arena.eval(&[p.events[0].guard], &at(0b00))
    );
}

#[test]
fn if_branches_follow_the_comparison() {
    let p = program(
        "model M { state x = 1;
           flow { der(x) = (if x < 2 then 10 else 20) + (if x >= 3 then 100 else 200); }
           observe o = if x < 2 then 10 else 20; }",
    );
    assert_eq!(p.switches.len(), 2);
    let x = [1.0];
    let at = |sw| Point {
        t: 0.0,
        x: &x,
        p: &[],
        sw,
    };
    // σ₀ = x − 2 > 0 selects the else branch of `<`; σ₁ = x − 3 > 0 the then branch of `>=`.
    assert_eq!(
        p.arena.eval(&p.modes[0].flow, &at(0b01)),
        vec![20.0 + 200.0]
    );
    assert_eq!(
        p.arena.eval(&p.modes[0].flow, &at(0b10)),
        vec![10.0 + 100.0]
    );
    assert_eq!(p.arena.eval(&[p.observables[0].1], &at(0)), vec![10.0]);
}

#[test]
fn constant_kinks_are_exact_and_not_switches() {
    let p = program(
        "model M { const c = 1; state x = 1;
           flow { der(x) = (if c >= 1 then 5 else 7) + sign(c - 1) + max(c, 1) + abs(0 - c); } }",
    );
    assert!(p.switches.is_empty());
    assert_eq!(
        p.arena.as_const(p.modes[0].flow[0]),
        Some(5.0 + 0.0 + 1.0 + 1.0)
    );
}

#[test]
fn observables_are_inlined_and_consts_folded() {
    let p = program(
        "model M { const c = 2 * 3; param a = c + 1; state x = a;
           flow { der(x) = o1 * c; }
           observe o1 = x + a; }",
    );
    assert_eq!(p.names.param_defaults, vec![7.0]);
    let mut ar = p.arena.clone();
    let (x, a) = (ar.state(0), ar.param(0));
    let s = ar.add(x, a);
    let six = ar.constant(6.0);
    assert_eq!(p.modes[0].flow[0], ar.mul(s, six));
    assert_eq!(p.observables[0].1, s);
}

#[test]
fn bad_models_are_errors_not_panics() {
    let cyc = "model M { state x = 1; flow { der(x) = a; } observe a = b; observe b = a; }";
    assert!(!errors(cyc).is_empty());
    let hz = "model M { state x = 1; flow { der(x) = 1; } horizon x; }";
    assert!(!errors(hz).is_empty());
    let mut many = String::from("model M { state x = 1; flow { der(x) = 0");
    for i in 0..70 {
        many.push_str(&format!(" + abs(x - {i})"));
    }
    many.push_str("; } }");
    // More than 64 kinks are fine: the switch bits are not limited to one word.
    let e = errors(&many);
    assert!(e.is_empty(), "{e:?}");
}

/// Models the checker rejects, lowered without it: every broken invariant comes back
/// as an `internal error: ...` diagnostic, never a panic or a user-facing duplicate.
#[test]
fn unchecked_models_give_internal_errors_not_panics() {
    let bad = [
        // undefined name, unknown function, wrong argument counts
        "model M { state x = 1; flow { der(x) = y; } }",
        "model M { state x = 1; flow { der(x) = foo(x); } }",
        "model M { state x = 1; flow { der(x) = min(x) + max(x, x, x) + pow(x); } }",
        "model M { state x = 1; flow { der(x) = sin(); } }",
        // `der` of a non-state, a missing `der`, no flow at all
        "model M { param p = 1; state x = 1; flow { der(p) = 1; } }",
        "model M { state x = 1; state z = 2; flow { der(x) = 1; } }",
        "model M { state x = 1; }",
        // unknown modes, unknown event in `sum`, reset of a non-state
        "model M { state x = 1; mode a { der(x) = 1; } initial mode b; }",
        "model M { state x = 1; mode a { der(x) = 1; } event when x >= 2 -> b; }",
        "model M { state x = 1; flow { der(x) = 1; } cost = sum(nope, x); }",
        "model M { param p = 1; state x = 1; flow { der(x) = 1; } event when x >= 2 { p = 0; } }",
        // non-constant consts and defaults, state or time where only params may appear
        "model M { state x = 1; const c = x; param p = t; flow { der(x) = c + p; } }",
        "model M { param p = 1; state x = 1; state y = x + t; flow { der(x) = 1; der(y) = 1; } horizon x; }",
        // self-referential observables
        "model M { state x = 1; flow { der(x) = a; } observe a = b; observe b = a; }",
    ];
    for src in bad {
        let model = crate::parse::parse(src).unwrap_or_else(|e| panic!("parse {src}: {e:?}"));
        assert!(
            !crate::check::check(&model).is_empty(),
            "the checker accepts {src}"
        );
        let diags = match std::panic::catch_unwind(|| lower(&model)) {
            Ok(Err(d)) => d,
            Ok(Ok(_)) => panic!("lowered without an error: {src}"),
            Err(_) => panic!("lower panicked on {src}"),
        };
        assert!(
            diags
                .iter()
                .all(|d| d.message.starts_with("internal error: ")),
            "{src}: {diags:?}"
        );
    }
}

/// Observables chained through each other nest deeper than any one expression: the
/// lowering depth bound turns that into an error instead of a stack overflow.
#[test]
fn deep_observable_chains_are_errors() {
    let mut src = String::from("model M { state x = 1; flow { der(x) = o39; } observe o0 = x;");
    for i in 1..40 {
        let inner = format!("{}o{}{}", "sin(".repeat(100), i - 1, ")".repeat(100));
        src.push_str(&format!(" observe o{i} = {inner};"));
    }
    src.push('}');
    let r = std::thread::Builder::new()
        .stack_size(2 << 20)
        .spawn(move || {
            crate::compile(&src)
                .map(|_| ())
                .map_err(|e| e.into_iter().map(|d| d.message).collect::<Vec<_>>())
        })
        .expect("thread")
        .join()
        .expect("no stack overflow");
    let errs = r.expect_err("too deep");
    assert!(
        errs.iter().any(|m| m.contains("nested too deeply")),
        "{errs:?}"
    );
}
