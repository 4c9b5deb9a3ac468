//! # mvad-dsl
//!
//! The `.hyb` language: one pest grammar, a spanned AST, semantic checks with located
//! errors, lowering to a hash-consed expression DAG, symbolic differentiation with
//! simplification and common-subexpression elimination, and two back ends of the same
//! scheduled IR: Rust code generation (for `hybrid!`) and a compact tape evaluator (for
//! models loaded at run time). Knows nothing of integrators or nalgebra.

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
