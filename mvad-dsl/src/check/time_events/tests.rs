use crate::testing::{assert_errors, front_errors as errors, Expected};

const HEAD: &str = "model M { param k = 1; param p = 0.5; state x = 0; table arr = \"a.csv\";\n";

/// Each case: a model body after [`HEAD`] (so on line 2) and the column and message of its
/// one expected error.
#[track_caller]
fn expect_each_with_head(cases: &[(&str, usize, &'static str)]) {
    for &(body, column, message) in cases {
        let src = format!("{HEAD}{body}");
        let want: Expected = (2, column, message);
        assert_errors(&src, errors(&src), &[want]);
    }
}

#[test]
fn every_trigger_parses_and_names_may_be_keywords_of_triggers() {
    for body in [
        "flow { der(x) = 1; } event dose at 2 * p { x = x + k; } }",
        "flow { der(x) = 1; } event at at p; }",
        "flow { der(x) = 1; } event every every p from 1 { x = 0; } }",
        "flow { der(x) = 1; } event sample every p { x = -k * x; } }",
        "flow { der(x) = 1; } event arrive at each arr.t * k { x = x + arr.s; } cost = sum(arrive, x * arr.s); }",
        "mode a { der(x) = 1; event at each arr.t -> b; } mode b { der(x) = 0; } }",
    ] {
        assert_eq!(errors(&format!("{HEAD}{body}")), vec![], "{body}");
    }
    let m = crate::front(&format!(
        "{HEAD}flow {{ der(x) = 1; }} event every p from 1; }}"
    ))
    .expect("parses");
    let (_, e) = m.all_events()[0];
    assert!(matches!(
        e.trigger,
        crate::ast::Trigger::Every { start: Some(_), .. }
    ));
    let t = m.tables().next().expect("a table");
    assert_eq!((t.name.name.as_str(), t.file.as_str()), ("arr", "a.csv"));
}

#[test]
fn time_and_table_rules_report_located_errors() {
    let cases: &[(&str, usize, &str)] = &[
        (
            "flow { der(x) = 1; } event at x { x = 0; } }",
            31,
            "the time of an event cannot depend on state `x`",
        ),
        (
            "flow { der(x) = 1; } event e every t; }",
            36,
            "the time of event `e` cannot depend on the time `t`",
        ),
        (
            "flow { der(x) = arr.s; } }",
            17,
            "table column `arr.s` is read where no row is current",
        ),
        (
            "flow { der(x) = 1; } event e at each arq.t; }",
            38,
            "unknown table `arq`",
        ),
        (
            "flow { der(x) = 1; } event e at each k * p; }",
            38,
            "the times of event `e` read no table column",
        ),
        (
            "flow { der(x) = 1; } event e at 1 { x = arr.s; } }",
            41,
            "table column `arr.s` is read where no row is current",
        ),
        (
            "table arr = \"b.csv\"; flow { der(x) = 1; } }",
            7,
            "duplicate table `arr`",
        ),
    ];
    expect_each_with_head(cases);
}

#[test]
fn two_tables_in_one_event_are_errors() {
    let src = "model M { state x = 0; table a = \"a.csv\"; table b = \"b.csv\";\n\
               flow { der(x) = 1; } event e at each a.t + b.t { x = a.s; }\n\
               event f at each a.t { x = b.s; } }";
    let got: Vec<String> = errors(src).into_iter().map(|e| e.2).collect();
    assert_eq!(
        got,
        vec![
            "the times of event `e` read two tables, `a` and `b`".to_string(),
            "`b.s` is a column of table `b`, but event `f` runs over the rows of table `a`"
                .to_string(),
        ]
    );
}

#[test]
fn dotted_names_resolve_to_a_table_column_or_a_qp_variable() {
    // One model reads a column and a qp's solution with the same syntax.
    let ok = "model M { param k = 1; state x = 0; table arr = \"a.csv\";\n\
              qp q(u) { minimize (u - x)^2; }\n\
              flow { der(x) = -q.u; } event e at each arr.t { x = x + arr.s * q.u; } }";
    assert_eq!(errors(ok), vec![], "{ok}");
    let m = crate::compile(ok).expect("compiles");
    assert_eq!(
        m.names.columns,
        vec![(0, "t".to_string()), (0, "s".to_string())]
    );
    assert_eq!(m.qps.len(), 1);
    let cases: &[(&str, usize, &str)] = &[
        // A name that is neither: the message names both kinds the model declares.
        (
            "qp q(u) { minimize u^2; } flow { der(x) = 1; } event e at each arr.t { x = r.s; } }",
            76,
            "unknown table or qp `r`",
        ),
        // A name that is both.
        (
            "qp arr(u) { minimize u^2; } flow { der(x) = 1; } event e at each arr.t; }",
            66,
            "`arr.t` is ambiguous: `arr` is a table and a qp",
        ),
        // A param is neither.
        (
            "flow { der(x) = 1; } event e at each arr.t { x = k.s; } }",
            50,
            "param `k` is not a table: `k.s` names nothing",
        ),
        // A qp's solution is not a row value: an event time cannot read it.
        (
            "qp q(u) { minimize (u - k)^2; } flow { der(x) = 1; } event e at each arr.t + q.u; }",
            78,
            "the time of event `e` cannot depend on the solution of qp `q`",
        ),
    ];
    expect_each_with_head(cases);
}

#[test]
fn a_table_names_a_file() {
    for file in ["\"\"", "\"  \""] {
        let src = format!("model M {{ state x = 0; table arr = {file};\nflow {{ der(x) = 1; }} }}");
        assert_errors(&src, errors(&src), &[(1, 36, "table `arr` names no file")]);
    }
}
