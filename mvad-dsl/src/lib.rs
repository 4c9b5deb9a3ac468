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
        [TokenTree::Literal(lit)] => syn::parse2::<syn::LitStr>(TokenTree::Literal(lit.clone()).into()),
        _ => Err(syn::Error::new(kw, "expected a file path: `include \"path/to/model.hyb\"`")),
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
            return syn::Error::new(lit.span(), format!("cannot read `{}`: {e}", path.display()))
                .to_compile_error()
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
