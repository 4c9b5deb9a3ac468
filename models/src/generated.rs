//! Generated models with any number p of parameters, for the adjoint benchmark
//! (`benches/adjoint.rs`, where their definitions are explained) and
//! `examples/adjoint_profile.rs`: `.hyb` text, loaded at run time.
//!
//! - [`impact`]: a ball with linear drag whose restitution law has p − 1 fitted weights
//!   (parameters in the reset only).
//! - [`chain`]: four masses on springs, each parameter stiffening one mass (parameters in
//!   the flow: every evaluation costs O(p)).

/// Masses in the chain (n = 2 × MASSES states: q₁, v₁, q₂, v₂, …).
pub const MASSES: usize = 4;

/// `(t₁ + t₂ + …)`, as a balanced tree (the language bounds nesting at 256 levels).
fn balanced_sum(terms: &[String]) -> String {
    match terms {
        [] => "0".into(),
        [t] => t.clone(),
        _ => {
            let (a, b) = terms.split_at(terms.len() / 2);
            format!("({} + {})", balanced_sum(a), balanced_sum(b))
        }
    }
}

/// The `.hyb` text of the impact model with p parameters (g and p − 1 restitution weights).
pub fn impact(p: usize) -> String {
    let m = p - 1;
    let mut s = String::from("model Impact {\n    param g = 9.81;\n");
    for j in 1..=m {
        s += &format!("    param a{j} = {:?};\n", 0.8 / m as f64);
    }
    s += "    state h = 2; state v = 0;\n    flow { der(h) = v; der(v) = -g - 0.05 * v; }\n";
    let terms: Vec<String> = (1..=m)
        .map(|j| format!("a{j} / (1 + (v / {})^2)", 10 * j))
        .collect();
    let law = if m == 0 {
        "0.8".into()
    } else {
        balanced_sum(&terms)
    };
    s += &format!("    event impact when h <= 0 {{ v = -{law} * v; }}\n");
    s += "    cost = integral(h) + sum(impact, 0.01 * v^2);\n    horizon 3;\n}\n";
    s
}

/// c_j of parameter j (1-based): fixed in (0, 1].
fn c(j: usize) -> f64 {
    ((j * 7) % 10 + 1) as f64 / 10.0
}

/// The mass (0-based) parameter j (1-based) stiffens.
fn mass_of(j: usize) -> usize {
    (j - 1) % MASSES
}

/// The `.hyb` text of the chain with p parameters.
pub fn chain(p: usize) -> String {
    let mut s = String::from("model Chain {\n    const k = 4.0; const d = 0.05;\n");
    for j in 1..=p {
        s += &format!("    param a{j} = {:?};\n", 0.5 / p as f64);
    }
    for i in 1..=MASSES {
        let v0 = if i == 1 { 2.0 } else { 0.0 };
        s += &format!("    state q{i} = 0; state v{i} = {v0:?};\n");
    }
    s += "    flow {\n";
    for i in 1..=MASSES {
        let left = if i > 1 {
            format!("q{}", i - 1)
        } else {
            "0".into()
        };
        let right = if i < MASSES {
            format!("q{}", i + 1)
        } else {
            "0".into()
        };
        let terms: Vec<String> = (1..=p)
            .filter(|&j| mass_of(j) == i - 1)
            .map(|j| format!("{:?} * a{j}", c(j)))
            .collect();
        let gain = balanced_sum(&terms);
        let drive = if i == 1 { "1.5 * sin(2 * t) " } else { "" };
        s += &format!("        der(q{i}) = v{i};\n");
        s += &format!(
            "        der(v{i}) = {drive}- k * (2 * q{i} - {left} - {right}) - d * v{i} - q{i} * ({gain});\n"
        );
    }
    s += "    }\n    event hit when q1 >= 0.3 { v1 = -v1; }\n";
    s += &format!("    cost = integral(q1^2 + q{MASSES}^2) + sum(hit, v1^2);\n");
    s += "    horizon 10;\n}\n";
    s
}
