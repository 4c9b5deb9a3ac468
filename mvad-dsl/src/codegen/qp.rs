//! The qp part of a generated model: a `QpBank` field, the functions that write each qp's
//! data and Jacobian from their kernels, the prelude of every method body whose kernel
//! reads qp solutions, and the `HybridModel` qp methods.
//!
//! A body that reads u* or ∂u*/∂w starts with
//! `let __qp = self.__qp_eval(t, x.as_slice(), p.as_slice(), DERIVS);` and binds the slices
//! `qu` (u*) and `qd` (∂u*/∂(x, θ, t), rows of n + p + 1) that the rendered leaves index.

use proc_macro2::TokenStream;
use quote::quote;

use super::info::Build;
use super::{usize_lit, Gen};
use crate::ir::Node;
use crate::schedule::{Kernel, ModelKernels};

/// Tokens of the qp part of a model (all empty for a model without qps).
pub(super) struct QpItems {
    /// Struct fields.
    pub(super) fields: TokenStream,
    /// Their initialisers in `new()`.
    pub(super) init: TokenStream,
    /// Inherent (private) methods.
    pub(super) inherent: TokenStream,
    /// `HybridModel` methods.
    pub(super) methods: TokenStream,
}

impl Gen<'_> {
    /// The bindings a body needs before it reads qp leaves (empty when it reads none).
    pub(super) fn qp_prelude(&self, kernel: &Kernel) -> TokenStream {
        let values = kernel.uses(self.ar, |n| matches!(n, Node::QpSol(_)));
        let derivs = kernel.uses(self.ar, |n| matches!(n, Node::QpDeriv(..)));
        if !values && !derivs {
            return TokenStream::new();
        }
        let frozen = if self.frozen.get() {
            quote!(::core::option::Option::Some(sw))
        } else {
            quote!(::core::option::Option::None)
        };
        let mut out =
            quote!(let __qp = self.__qp_eval(t, x.as_slice(), p.as_slice(), #frozen, #derivs););
        if values {
            out.extend(quote!(let qu: &[f64] = __qp.u();));
        }
        if derivs {
            out.extend(quote!(let qd: &[f64] = __qp.du();));
        }
        out
    }

    pub(super) fn qp_items(&self, k: &ModelKernels) -> QpItems {
        if k.qps.is_empty() {
            return QpItems {
                fields: TokenStream::new(),
                init: TokenStream::new(),
                inherent: TokenStream::new(),
                methods: TokenStream::new(),
            };
        }
        let pr = quote!(::mvad::__private);
        let (n, p) = (usize_lit(k.nstates()), usize_lit(k.nparams()));
        let infos = k.qps.iter().map(|q| q.info.build());
        let arms = k.qps.iter().enumerate().map(|(i, q)| {
            let i = usize_lit(i);
            let data = self.fill_body(&q.data, quote!(data), |s| {
                let s = usize_lit(s);
                quote!(data[#s])
            });
            let jac = self.fill_body(&q.data_jac, quote!(jac), |s| {
                let s = usize_lit(s);
                quote!(jac[#s])
            });
            quote!(#i => {
                { #data }
                if let ::core::option::Option::Some(jac) = jac { #jac }
            })
        });
        QpItems {
            fields: quote! {
                qp_info: ::std::vec::Vec<#pr::QpLayerInfo>,
                qp: ::core::cell::RefCell<#pr::QpBank>,
            },
            init: quote! {
                qp_info: Self::__qp_infos(),
                qp: ::core::cell::RefCell::new(#pr::QpBank::new(
                    Self::__qp_infos(),
                    #n,
                    #p,
                    <#pr::QpOptions as ::core::default::Default>::default(),
                )),
            },
            inherent: quote! {
                /// The static description of the qps.
                fn __qp_infos() -> ::std::vec::Vec<#pr::QpLayerInfo> {
                    ::std::vec![#(#infos),*]
                }
                /// Writes the data of qp `q` at (t, x, θ), and their Jacobian into `jac`.
                #[allow(unused_variables, unused_parens, unused_braces, non_snake_case, clippy::all)]
                fn __qp_fill(&self, q: usize, t: f64, x: &[f64], p: &[f64], data: &mut [f64], jac: ::core::option::Option<&mut [f64]>) {
                    match q {
                        #(#arms)*
                        _ => data.fill(f64::NAN),
                    }
                }
                /// Solves every qp at (t, x, θ), on the active sets `frozen` holds if given
                /// (cached per point), and lends the bank.
                fn __qp_eval(&self, t: f64, x: &[f64], p: &[f64], frozen: ::core::option::Option<&#pr::Switches>, derivs: bool) -> ::core::cell::Ref<'_, #pr::QpBank> {
                    self.qp.borrow_mut().evaluate(t, x, p, frozen, derivs, |q, data, jac| {
                        self.__qp_fill(q, t, x, p, data, jac)
                    });
                    self.qp.borrow()
                }
                /// The switching function of qp switch bit `j`.
                #[allow(dead_code)]
                fn __qp_switch_value(&self, j: usize, t: f64, x: &[f64], p: &[f64]) -> f64 {
                    self.qp.borrow_mut().switch_value(j, t, x, p, |q, data, jac| {
                        self.__qp_fill(q, t, x, p, data, jac)
                    })
                }
                /// Its gradient (∂/∂x into `gx`, ∂/∂θ into `gp`); returns ∂/∂t.
                #[allow(dead_code)]
                fn __qp_switch_grad(&self, j: usize, t: f64, x: &[f64], p: &[f64], gx: &mut [f64], gp: &mut [f64]) -> f64 {
                    self.qp.borrow_mut().switch_grad(j, t, x, p, |q, data, jac| {
                        self.__qp_fill(q, t, x, p, data, jac)
                    }, gx, gp).1
                }
            },
            methods: quote! {
                fn qps(&self) -> &[#pr::QpLayerInfo] {
                    &self.qp_info
                }
                fn qp_states(
                    &self,
                    at: #pr::At<'_, Self::N, Self::P>,
                ) -> ::core::result::Result<::std::vec::Vec<#pr::QpState>, (usize, #pr::QpError)> {
                    self.__qp_eval(at.t, at.x.as_slice(), at.p.as_slice(), ::core::option::Option::None, false).states()
                }
                fn qp_bank(&self) -> ::core::option::Option<&::core::cell::RefCell<#pr::QpBank>> {
                    ::core::option::Option::Some(&self.qp)
                }
                fn qp_flow_pieces(
                    &self,
                    pt: #pr::Point<'_, Self::N, Self::P>,
                    f: &#pr::OVector<f64, Self::N>,
                    s: ::core::option::Option<&#pr::OMatrix<f64, Self::N, Self::P>>,
                    pieces: &mut [#pr::Switches],
                ) -> ::core::option::Option<bool> {
                    let (t, x, p) = (pt.t, pt.x.as_slice(), pt.p.as_slice());
                    self.qp.borrow_mut().flow_pieces(
                        t, x, p, pt.sw, f.as_slice(), s.map(|s| s.as_slice()), pieces,
                        |q, data, jac| self.__qp_fill(q, t, x, p, data, jac),
                    ).ok()
                }
                fn qp_piece(
                    &self,
                    q: usize,
                    at: #pr::At<'_, Self::N, Self::P>,
                    (dx, j, dt): (&#pr::OVector<f64, Self::N>, usize, f64),
                    active: &mut [bool],
                ) -> ::core::option::Option<bool> {
                    let (t, x, p) = (at.t, at.x.as_slice(), at.p.as_slice());
                    self.qp.borrow_mut().pointwise_piece(
                        q, (t, x, p), (dx.as_slice(), j, dt), active,
                        |q, data, jac| self.__qp_fill(q, t, x, p, data, jac),
                    ).ok()
                }
            },
        }
    }
}
