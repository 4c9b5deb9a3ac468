//! The `hybrid!` procedural macro of mvad. Use it through `mvad::hybrid!`.
//!
//! All the work (grammar, checks, symbolic derivatives, code generation) lives in
//! `mvad-dsl`, which can be tested without a compiler in the loop; this crate only moves
//! tokens across the proc-macro boundary. pest's derived `Rule` enum cannot sit at a
//! proc-macro crate's root, which is one more reason the grammar lives there.

use proc_macro::TokenStream;

/// Compiles a hybrid model into a Rust model type implementing `mvad::HybridModel`.
///
/// ```ignore
/// mvad::hybrid! {
///     model BouncingBall {
///         param g = 9.81;
///         state h = 2.0;
///         state v = 0.0;
///         flow { der(h) = v; der(v) = -g; }
///         event impact when h <= 0 { v = -0.8 * v; }
///     }
/// }
/// mvad::hybrid!(include "models/bouncing_ball.hyb"); // path relative to Cargo.toml's dir
/// ```
///
/// An invalid model is a compile error at the offending token.
#[proc_macro]
pub fn hybrid(input: TokenStream) -> TokenStream {
    mvad_dsl::expand(input.into()).into()
}
