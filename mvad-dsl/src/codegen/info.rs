//! The static description of a model as tokens: a value of `ModelInfo`, `EventInfo` or
//! `QpLayerInfo` (crate `mvad-info`, which the front end builds and the runtime reads)
//! written as the Rust expression that builds the same value at the `::mvad::__private`
//! paths. The generated model thus holds what the interpreter holds: one value, two doors.

use proc_macro2::TokenStream;
use quote::quote;

use super::{lit, usize_lit};
use crate::ir::{ConstraintKind, Direction, EventInfo, ModelInfo, QpLayerInfo, Trigger};

/// A value that generated code can rebuild: `build()` is an expression equal to it.
pub(super) trait Build {
    /// The expression.
    fn build(&self) -> TokenStream;
}

impl Build for bool {
    fn build(&self) -> TokenStream {
        quote!(#self)
    }
}

impl Build for usize {
    fn build(&self) -> TokenStream {
        let i = usize_lit(*self);
        quote!(#i)
    }
}

impl Build for f64 {
    fn build(&self) -> TokenStream {
        lit(*self)
    }
}

impl Build for String {
    fn build(&self) -> TokenStream {
        quote!(::std::string::String::from(#self))
    }
}

impl<T: Build> Build for Option<T> {
    fn build(&self) -> TokenStream {
        match self {
            Some(v) => {
                let v = v.build();
                quote!(::core::option::Option::Some(#v))
            }
            None => quote!(::core::option::Option::None),
        }
    }
}

impl<T: Build> Build for Vec<T> {
    fn build(&self) -> TokenStream {
        let items = self.iter().map(Build::build);
        quote!(::std::vec![#(#items),*])
    }
}

impl<A: Build, B: Build> Build for (A, B) {
    fn build(&self) -> TokenStream {
        let (a, b) = (self.0.build(), self.1.build());
        quote!((#a, #b))
    }
}

/// The enums and structs, variant by variant and field by field (the patterns are
/// exhaustive: a new variant or field must be named here).
macro_rules! build_plain {
    ($(enum $ty:ident { $($unit:ident),* $(; $var:ident { $($vf:ident),* })? })*) => {$(
        impl Build for $ty {
            fn build(&self) -> TokenStream {
                match self {
                    $($ty::$unit => quote!(::mvad::__private::$ty::$unit),)*
                    $($ty::$var { $($vf),* } => {
                        $(let $vf = $vf.build();)*
                        quote!(::mvad::__private::$ty::$var { $($vf: #$vf),* })
                    })?
                }
            }
        }
    )*};
    ($(struct $ty:ident { $($f:ident),* })*) => {$(
        impl Build for $ty {
            fn build(&self) -> TokenStream {
                let $ty { $($f),* } = self;
                $(let $f = $f.build();)*
                quote!(::mvad::__private::$ty { $($f: #$f),* })
            }
        }
    )*};
}

build_plain! {
    enum Direction { Down, Up }
    enum ConstraintKind { Eq, Le }
    enum Trigger { Guard, At, Every; Each { rows } }
}

build_plain! {
    struct EventInfo { name, direction, mode, target, has_reset, has_cost, trigger }
    struct QpLayerInfo { name, vars, kinds, dynamic, switches, events_before, events_after }
    struct ModelInfo {
        name, states, params, param_defaults, modes, initial_mode, events, observables,
        switches, has_running_cost, has_final_cost, has_horizon, jacobian_sparsity
    }
}
