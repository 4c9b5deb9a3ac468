//! scratch
fn main() {
    let srcs = [
        "model M { state h = 0; flow { der(h) = vv; } }",
        "model M { param a = 1; param a = 2; state h = 0; flow { der(h) = a; } }",
        "model M { state h = 0; state v = 0; flow { der(h) = v; } }",
        "model M { param g = 1; state h = 0; flow { der(h) = 1; der(g) = 2; } }",
        "model M { state h = 0; flow { der(h) = 1; der(h) = 2; } }",
        "model M { param e = 1; state h = 0; flow { der(h) = 1; } event hit when h <= 0 { e = 2; } }",
        "model M { state h = 0; initial mode up; mode a { der(h) = 1; event s when h >= 1 -> b; } }",
        "model M { state h = 0; flow { der(h) = 1; } event hit when h <= 0; cost = sum(hot, h); }",
        "model M { state h = 0; flow { der(h) = sine(h); } }",
        "model M { state h = 0; flow { der(h) = max(h); } }",
        "model M { state h = 0; flow { der(h) = 1; } event hit when h { h = 1; } }",
        "model M { param p = 1; const c = 2 * p; state h = 0; flow { der(h) = c; } }",
        "model M { param p = 1; }",
        "model M { param sin = 1; state t = 0; flow { der(t) = 1; } }",
        "model M { state h = 0; flow { der(h) = 1; } mode a { der(h) = 2; } }",
        "model M { state h = 0; }",
        "model M { state h = 0; flow { der(h) = 1; } horizon h; }",
        "model M { state h = 0; param q = h; flow { der(h) = 1; } }",
        "model M { state h = 0; flow { der(h) = 1; } observe a = b; observe b = a + 1; }",
        "model M { state h = 0; flow { der(h) = if h then 1 else 2; } }",
        "model M { state h = 0; flow { der(h) = sin + 1; } }",
        "model M { const a = b; const b = 1; state h = t; flow { der(h) = der(h); } }",
        "model type { param self = 1; state h = 0; flow { der(h) = 1; } }",
        "model M { state h = 0; state h = 1; mode a { der(h) = 1; } mode a { der(h) = 1; } cost = integral(h); cost = final(h); }",
    ];
    for s in srcs {
        match mvad_dsl::front(s) {
            Ok(_) => println!("OK {s:?}"),
            Err(d) => print!("{}", mvad_dsl::diag::render("m.hyb", s, &d)),
        }
        println!("----");
    }
}
