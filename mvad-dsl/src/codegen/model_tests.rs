use super::*;

const SINK: &str = r#"
model Sink {
param a = 0.5; param b = 2.0; param c = -1.0;
const k = 3.0;
state x = a;
state y = b * c;
state z = 1.0;
initial mode one;
mode one {
    der(x) = abs(y) * sin(x) + max(x, a) + t * c;
    der(y) = min(x, y) - if x > 0.5 then y^2 else exp(-y) / k;
    der(z) = sign(x - y) + pow(abs(x) + 1, b) + sqrt(z^2 + 1);
    event up when x >= b -> two { y = -a * y; z = z + t; }
}
mode two {
    der(x) = -x * a;
    der(y) = tanh(y) + cosh(x) - sinh(z) / 10;
    der(z) = atan(x) + log(z^2 + 2) + cos(t);
    event down when x <= 0.1 -> one;
}
event floor when y < -5 { y = -y; }
observe o1 = x + y;
observe o2 = o1 * z + abs(x);
cost = integral(x^2 + abs(y)) + 0.5 * sum(up, y^2) + final(z * a) - 2 * integral(max(z, 0.5));
horizon 2 + a;
}
"#;

/// Generated code is valid Rust for every declaration form.
#[test]
fn generated_code_parses() {
    let model = crate::front(SINK).expect("front");
    let program = crate::lower::lower(&model).expect("lower");
    let kernels = crate::schedule::kernels(&program);
    let ts = generate(&kernels);
    let file: syn::File = syn::parse2(ts.clone()).expect("generated code must parse");
    assert!(file.items.len() >= 6);
    let _ = ts;
}

/// Expansion time of `hybrid!` for the largest model (the all-constructs test model)
/// and the bouncing ball; `MVAD_DUMP_CODEGEN=path` writes the ball's generated code.
#[test]
fn expansion_time_and_ball_code() {
    let dir = env!("CARGO_MANIFEST_DIR");
    let ball = std::fs::read_to_string(format!("{dir}/../models/bouncing_ball.hyb"));
    let sink = std::fs::read_to_string(format!("{dir}/../tests/tests/sink.hyb"));
    let (Ok(ball), Ok(sink)) = (ball, sink) else {
        return;
    };
    for (name, src) in [("bouncing_ball", &ball), ("sink", &sink)] {
        let tokens: TokenStream = src.parse().expect("model text lexes as Rust tokens");
        let start = std::time::Instant::now();
        let out = crate::expand(tokens);
        let dt = start.elapsed();
        let text = out.to_string();
        assert!(!text.contains("compile_error"), "{name}: {text}");
        println!(
            "expand({name}): {:.2} ms, {} bytes of tokens",
            dt.as_secs_f64() * 1e3,
            text.len()
        );
    }
    let which = std::env::var("MVAD_DUMP_MODEL").unwrap_or_default();
    let kernels = crate::compile(if which == "sink" { &sink } else { &ball }).expect("compiles");
    let code = generate(&kernels).to_string();
    if let Ok(path) = std::env::var("MVAD_DUMP_CODEGEN") {
        let _ = std::fs::write(path, code);
    }
}
