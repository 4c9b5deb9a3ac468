//! The `hybrid!` procedural macro of mvad. Use it through `mvad::hybrid!`.

use proc_macro::TokenStream;

/// Compiles a `.hyb` model (inline, or `include "path.hyb"`) into a Rust model type.
#[proc_macro]
pub fn hybrid(input: TokenStream) -> TokenStream {
    let _ = input;
    TokenStream::new()
}
