use super::*;

#[test]
fn literals_never_panic() {
    for v in [
        0.0,
        -0.0,
        1.5,
        -2.25,
        f64::NAN,
        f64::INFINITY,
        f64::NEG_INFINITY,
        1e-300,
        f64::MAX,
    ] {
        let s = lit(v).to_string();
        assert!(!s.is_empty());
    }
    assert_eq!(lit(-2.5).to_string().replace(' ', ""), "-2.5f64");
}

#[test]
fn identifiers_never_panic() {
    for name in [
        "type", "self", "Self", "crate", "x", "_a", "", "1a", "é", "_", "union", "fn",
    ] {
        let _ = rust_ident(name).to_string();
    }
    assert_eq!(rust_ident("type").to_string(), "r#type");
}
