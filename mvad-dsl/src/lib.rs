//! # mvad-dsl
//!
//! The `.hyb` language: one pest grammar, a spanned AST, semantic checks with located
//! errors, lowering to a hash-consed expression DAG, symbolic differentiation with
//! simplification and common-subexpression elimination, and two back ends of the same
//! scheduled IR: Rust code generation (for `hybrid!`) and a compact tape evaluator (for
//! models loaded at run time). Knows nothing of integrators or nalgebra.
//!
//! Entry points: [`front`] (text -> checked [`ast::Model`]), [`compile`] (text ->
//! [`schedule::ModelKernels`]) and [`expand`] (the `hybrid!` macro's body). Errors are
//! [`Diagnostic`]s; [`diag::render`] prints them as `FILE:LINE:COL: error: MESSAGE`.

// Front end: text -> checked AST.
pub mod ast;
pub mod check;
pub mod diag;
pub mod parse;
pub mod span;
pub mod tokens;

// Middle and back ends: AST -> IR -> derivatives -> kernels -> code / tape.
pub mod codegen;
pub mod diff;
pub mod eval;
pub mod ir;
pub mod lower;
pub mod schedule;
pub mod simplify;
#[cfg(test)]
mod testing;

use proc_macro2::{Span as TokenSpan, TokenStream, TokenTree};

pub use ast::Model;
pub use diag::Diagnostic;
pub use span::{SourceFile, Span};

/// Parses and checks a model: the `.hyb` front end. Returns the checked syntax tree, or
/// every error found (a syntax error stops at the first one; semantic checks report all).
pub fn front(src: &str) -> Result<ast::Model, Vec<diag::Diagnostic>> {
    let model = parse::parse(src)?;
    let errors = check::check(&model);
    if errors.is_empty() {
        Ok(model)
    } else {
        Err(errors)
    }
}

/// Text -> kernels: [`front`], then [`lower::lower`] to the IR, then
/// [`schedule::kernels`] (symbolic derivatives, CSE, one straight-line kernel per model
/// function). The result feeds [`codegen::generate`] or the tape evaluator.
pub fn compile(src: &str) -> Result<schedule::ModelKernels, Vec<diag::Diagnostic>> {
    let model = front(src)?;
    let program = lower::lower(&model)?;
    Ok(schedule::kernels(&program))
}

/// The body of `hybrid!`: `model NAME { ... }` inline, or `include "path.hyb"` (relative
/// to the invoking crate's `CARGO_MANIFEST_DIR`).
///
/// On success, the code of [`codegen::generate`] (after a `const _: &str =
/// include_str!(..)` for a file, so Cargo rebuilds when it changes). On error,
/// `compile_error!`s at the user's tokens (for a file: at the path, with the rendered
/// `FILE:LINE:COL` diagnostics) plus stub `struct NAME;` and `struct NAMEParams;` so the
/// user's other uses of the model raise no follow-on errors. Never panics: an internal
/// panic becomes a compile error too.
pub fn expand(input: TokenStream) -> TokenStream {
    let fallback = input.clone();
    match std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| expand_inner(input))) {
        Ok(out) => out,
        Err(_) => {
            let mut out = syn::Error::new(
                TokenSpan::call_site(),
                "internal error in `hybrid!` (a bug in mvad; please report it with the model)",
            )
            .to_compile_error();
            out.extend(stub_from_tokens(&fallback.into_iter().collect::<Vec<_>>()));
            out
        }
    }
}

fn expand_inner(input: TokenStream) -> TokenStream {
    let tokens: Vec<TokenTree> = input.clone().into_iter().collect();
    if let Some(TokenTree::Ident(kw)) = tokens.first() {
        if kw == "include" {
            return expand_include(kw.span(), &tokens[1..]);
        }
    }
    let (text, map) = tokens::restring(input);
    match compile(&text) {
        Ok(kernels) => codegen::generate(&kernels),
        Err(diags) => {
            let mut errors = diags.iter().map(|d| diag::to_syn_error(d, &map));
            let mut out = TokenStream::new();
            if let Some(mut first) = errors.next() {
                errors.for_each(|e| first.combine(e));
                out.extend(first.to_compile_error());
            }
            out.extend(stub_from_tokens(&tokens));
            out
        }
    }
}

/// `include "path.hyb"`: reads the file and compiles it; errors go on the path literal.
fn expand_include(kw: TokenSpan, rest: &[TokenTree]) -> TokenStream {
    let lit = match rest {
        [TokenTree::Literal(lit)] => {
            syn::parse2::<syn::LitStr>(TokenTree::Literal(lit.clone()).into())
        }
        _ => Err(syn::Error::new(
            kw,
            "expected a file path: `include \"path/to/model.hyb\"`",
        )),
    };
    let lit = match lit {
        Ok(l) => l,
        Err(e) => return e.to_compile_error(),
    };
    let rel = lit.value();
    let path = match std::env::var_os("CARGO_MANIFEST_DIR") {
        Some(dir) => std::path::Path::new(&dir).join(&rel),
        None => std::path::PathBuf::from(&rel),
    };
    let src = match std::fs::read_to_string(&path) {
        Ok(s) => s,
        Err(e) => {
            let message = format!("cannot read `{rel}` (relative to the crate's Cargo.toml): {e}");
            return syn::Error::new(lit.span(), message).to_compile_error();
        }
    };
    let abs = path.to_string_lossy().into_owned();
    let mut out = quote::quote! { const _: &str = ::core::include_str!(#abs); };
    match compile(&src) {
        Ok(kernels) => out.extend(codegen::generate(&kernels)),
        Err(diags) => {
            let rendered = diag::render(&rel, &src, &diags);
            let message = format!("invalid model in `{rel}`\n{}", rendered.trim_end());
            out.extend(syn::Error::new(lit.span(), message).to_compile_error());
            let name = parse::parse(&src).ok().map(|m| m.name.name);
            out.extend(stub(name.as_deref(), lit.span()));
        }
    }
    out
}

/// Stub types for a model whose `model NAME` is found among the input tokens.
fn stub_from_tokens(tokens: &[TokenTree]) -> TokenStream {
    let name = tokens.windows(2).find_map(|w| match w {
        [TokenTree::Ident(kw), TokenTree::Ident(name)] if kw == "model" => Some(name.clone()),
        _ => None,
    });
    match name {
        Some(n) => stub(Some(&n.to_string()), n.span()),
        None => TokenStream::new(),
    }
}

/// `pub struct NAME; pub struct NAMEParams;` if NAME is a usable Rust identifier.
fn stub(name: Option<&str>, span: TokenSpan) -> TokenStream {
    let Some(name) = name.filter(|n| !check::is_reserved(n)) else {
        return TokenStream::new();
    };
    let (Ok(mut ty), Ok(mut params)) = (
        syn::parse_str::<syn::Ident>(name),
        syn::parse_str::<syn::Ident>(&format!("{name}Params")),
    ) else {
        return TokenStream::new();
    };
    ty.set_span(span);
    params.set_span(span);
    quote::quote! {
        #[allow(dead_code)]
        pub struct #ty;
        #[allow(dead_code)]
        pub struct #params;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use std::str::FromStr;

    fn expand_str(src: &str) -> String {
        expand(TokenStream::from_str(src).expect("lexes")).to_string()
    }

    #[test]
    fn errors_become_compile_errors_plus_stubs() {
        let out = expand_str("model Ball { state h = 0; flow { der(h) = vv + ww; } }");
        assert_eq!(out.matches("compile_error").count(), 2, "{out}");
        assert!(out.contains("undefined name `vv`"), "{out}");
        assert!(out.contains("undefined name `ww`"), "{out}");
        assert!(out.contains("pub struct Ball ;"), "{out}");
        assert!(out.contains("pub struct BallParams ;"), "{out}");
        // No stub for a reserved model name, and no panic.
        let out = expand_str("model type { state h = 0; flow { der(h) = 1; } }");
        assert!(
            out.contains("compile_error") && !out.contains("struct"),
            "{out}"
        );
    }

    #[test]
    fn valid_model_expands_to_code() {
        let out = expand_str(
            "model Decay { param k = 0.5; state x = 1; flow { der(x) = -k * x; } horizon 1; }",
        );
        assert!(!out.contains("compile_error"), "{out}");
        assert!(
            out.contains("Decay") && out.contains("DecayParams"),
            "{out}"
        );
    }

    #[test]
    fn odd_inputs_give_errors_not_panics() {
        for src in [
            "",
            "include",
            "include 1",
            "include \"a\" \"b\"",
            "model",
            "model 3 { }",
            "fn main() {}",
            "model M { state x = 'c'; }",
            "model M { state x = b\"x\"; }",
            "model M { state x = 1; flow { der(x) = x ; } } model N { }",
        ] {
            let out = expand_str(src);
            assert!(out.contains("compile_error"), "{src}: {out}");
        }
    }

    /// A temporary file `name` holding `text`, removed when the returned directory drops.
    fn temp_file(name: &str, text: &str) -> (tempfile::TempDir, std::path::PathBuf) {
        let dir = tempfile::tempdir().expect("a temporary directory");
        let path = dir.path().join(name);
        std::fs::write(&path, text).expect("write temp file");
        (dir, path)
    }

    #[test]
    fn include_reads_the_file() {
        // An absolute path ignores CARGO_MANIFEST_DIR.
        let (_good_dir, good) = temp_file(
            "good.hyb",
            "model Inc { state x = 0; flow { der(x) = 1; } }\n",
        );
        let out = expand_str(&format!("include {:?}", good.to_str().unwrap()));
        assert!(out.contains("include_str"), "{out}");
        assert!(!out.contains("compile_error"), "{out}");
        assert!(out.contains("Inc"), "{out}");

        let (_bad_dir, bad) = temp_file(
            "bad.hyb",
            "model Bad {\n  state x = 0;\n  flow { der(x) = y; }\n}\n",
        );
        let out = expand_str(&format!("include {:?}", bad.to_str().unwrap()));
        assert!(out.contains("compile_error"), "{out}");
        assert!(out.contains(":3:19: error: undefined name `y`"), "{out}");
        assert!(out.contains("pub struct Bad ;"), "{out}");
        assert!(out.contains("include_str"), "{out}");

        let out = expand_str("include \"/nonexistent/dir/model.hyb\"");
        assert!(out.contains("cannot read"), "{out}");
    }

    #[test]
    fn render_format() {
        let src = "model M {\n\tstate h = 0;\n\tflow { der(h) = vv; }\n}\n";
        let diags = front(src).unwrap_err();
        let text = diag::render("m.hyb", src, &diags);
        assert_eq!(
            text,
            "m.hyb:3:18: error: undefined name `vv`\n  |\n3 | \tflow { der(h) = vv; }\n  | \t                ^^\n"
        );
        // Labels and help.
        let src =
            "model M {\n  param a = 1;\n  param a = 2;\n  state h = 0; flow { der(h) = a; }\n}";
        let text = diag::render("m.hyb", src, &front(src).unwrap_err());
        assert_eq!(
            text,
            "m.hyb:3:9: error: duplicate declaration of `a`\n  |\n2 |   param a = 1;\n  |         - first declared here\n3 |   param a = 2;\n  |         ^\n"
        );
    }

    #[test]
    fn whole_pipeline_fits_a_small_stack_at_the_nesting_limits() {
        // Inputs at the parser's limits go through lowering, differentiation and
        // scheduling too on a 1 MiB stack (recursive passes are bounded by the limits).
        let rhs = |e: String| format!("model M {{ state x = 0; flow {{ der(x) = {e}; }} }}");
        let k = parse::MAX_NESTING - 8;
        let d = ast::MAX_DEPTH - 2;
        let inputs = [
            rhs(format!("{}x{}", "(".repeat(k), ")".repeat(k))),
            rhs(format!("{}1", "if x < 1 then 0 else ".repeat(k))),
            rhs(format!("{}x{}", "sin(".repeat(k), ")".repeat(k))),
            rhs(format!("x{}", "+x".repeat(d))),
            rhs(format!("x{}", "^x".repeat(d))),
            rhs(format!("{}x", "-".repeat(d))),
        ];
        let results = std::thread::Builder::new()
            .stack_size(1 << 20)
            .spawn(move || {
                inputs
                    .iter()
                    .map(|s| compile(s).map(|_| ()).map_err(|d| d[0].message.clone()))
                    .collect::<Vec<_>>()
            })
            .expect("spawn")
            .join()
            .expect("no stack overflow");
        assert_eq!(results, vec![Ok(()); 6]);
    }

    #[test]
    fn render_clips_long_lines_around_the_error() {
        let pad = "+ x ".repeat(80);
        let src = format!("model M {{ state x = 0; flow {{ der(x) = x {pad}+ vv {pad}; }} }}");
        let text = diag::render("m.hyb", &src, &front(&src).unwrap_err());
        let lines: Vec<&str> = text.lines().collect();
        assert!(lines[0].starts_with("m.hyb:1:"), "{text}");
        let quoted = lines[2].strip_prefix("1 | ").expect("quoted line");
        let marks = lines[3].strip_prefix("  | ").expect("mark line");
        assert!(
            quoted.starts_with("...") && quoted.ends_with("..."),
            "{text}"
        );
        assert!(quoted.chars().count() <= 126, "{text}");
        let caret = marks.find('^').expect("caret");
        assert_eq!(&quoted[caret..caret + 2], "vv", "{text}");
        assert_eq!(marks.trim(), "^^");
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(300))]

        #[test]
        fn front_never_panics_on_any_text(s in "\\PC{0,200}") {
            let _ = front(&s);
        }

        #[test]
        fn front_never_panics_on_model_like_text(
            s in "(model M \\{|state x = |param p = |flow \\{|der\\(x\\) = |event e when |if |then |else |\\(|\\)|\\{|\\}|;|,|[-+*/^]|<=|>=|->|x|p|t|1\\.5|2|sin\\(|max\\(| ){0,60}"
        ) {
            if let Err(d) = front(&s) {
                prop_assert!(!d.is_empty());
                let text = diag::render("f.hyb", &s, &d);
                prop_assert!(text.starts_with("f.hyb:"));
            }
        }
    }
}
