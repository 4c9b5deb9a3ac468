//! Kernels → straight-line Rust: shared nodes bound once with `let`, single-use nodes
//! inlined into their user, outputs stored slot by slot.

use proc_macro2::{Ident, Literal, Span, TokenStream};
use quote::{format_ident, quote};

use super::{lit, usize_lit, MAX_INLINE_DEPTH};
use crate::ir::{Cmp, ExprArena, ExprId, Func, Node};
use crate::schedule::{GradKernels, Kernel};

/// Operator precedence of a rendered expression (higher binds tighter).
#[derive(Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub(super) enum Prec {
    If,
    Add,
    Mul,
    Unary,
    Atom,
}

/// A rendered expression and its precedence.
#[derive(Clone)]
struct Rendered {
    tokens: TokenStream,
    prec: Prec,
}

/// The straight-line code of one kernel.
pub(super) struct Body {
    /// `let` statements, in order.
    pub(super) lets: TokenStream,
    /// Value tokens of each output, as (slot, value).
    pub(super) outputs: Vec<(usize, TokenStream)>,
    /// The precedence of each output's tokens (`If` the lowest).
    pub(super) prec: Vec<Prec>,
}

impl Body {
    /// Output `k` as an operand of `*` on either side: in parentheses unless it is an atom or
    /// a unary minus, so a product keeps the association the tape evaluates.
    pub(super) fn factor(&self, k: usize) -> TokenStream {
        let t = &self.outputs[k].1;
        if self.prec[k] >= Prec::Unary {
            t.clone()
        } else {
            quote!((#t))
        }
    }

    /// Output `k` as an operand of a sum (in parentheses only when it is an `if`).
    pub(super) fn term(&self, k: usize) -> TokenStream {
        let t = &self.outputs[k].1;
        if self.prec[k] == Prec::If {
            quote!((#t))
        } else {
            t.clone()
        }
    }
}

pub(super) struct Gen<'a> {
    pub(super) ar: &'a ExprArena,
    /// Whether the bodies being generated evaluate under frozen switch bits `sw` (flows
    /// and ℓ), so that qps read there are solved on their frozen active sets.
    pub(super) frozen: std::cell::Cell<bool>,
    /// Number of states and params: the row length n + p + 1 of the qp derivatives `qd`.
    pub(super) n: usize,
    pub(super) p: usize,
}

impl Gen<'_> {
    /// Renders `kernel`: shared nodes bound once, single-use nodes inlined.
    pub(super) fn body(&self, kernel: &Kernel) -> Body {
        let ar = self.ar;
        let top = kernel.nodes.last().map_or(0, |i| i.index() + 1);
        let mut uses = vec![0u32; top];
        for &id in &kernel.nodes {
            for c in ar.node(id).children() {
                uses[c.index()] += 1;
            }
        }
        for &(_, e) in &kernel.outputs {
            uses[e.index()] += 1;
        }
        let mut rendered: Vec<Option<Rendered>> = vec![None; top];
        let mut depth = vec![0u32; top];
        let mut lets = self.qp_prelude(kernel);
        for &id in &kernel.nodes {
            let node = ar.node(id);
            let r = self.render(node, &rendered);
            let d = 1 + node.children().map(|c| depth[c.index()]).max().unwrap_or(0);
            let i = id.index();
            if node.is_leaf() || (uses[i] <= 1 && d <= MAX_INLINE_DEPTH) {
                depth[i] = if node.is_leaf() { 0 } else { d };
                rendered[i] = Some(r);
            } else {
                let v = format_ident!("v{}", i);
                let tokens = r.tokens;
                lets.extend(quote!(let #v: f64 = #tokens;));
                depth[i] = 0;
                rendered[i] = Some(Rendered {
                    tokens: quote!(#v),
                    prec: Prec::Atom,
                });
            }
        }
        let get = |e: ExprId| rendered[e.index()].clone();
        let outputs = kernel
            .outputs
            .iter()
            .map(|&(s, e)| (s, get(e).map_or_else(|| quote!(f64::NAN), |r| r.tokens)))
            .collect();
        let prec = kernel
            .outputs
            .iter()
            .map(|&(_, e)| get(e).map_or(Prec::Atom, |r| r.prec))
            .collect();
        Body {
            lets,
            outputs,
            prec,
        }
    }

    /// Renders one node from its rendered children.
    fn render(&self, node: Node, done: &[Option<Rendered>]) -> Rendered {
        let get = |id: ExprId| -> Rendered {
            done[id.index()].clone().unwrap_or(Rendered {
                tokens: quote!(f64::NAN),
                prec: Prec::Atom,
            })
        };
        // Child tokens wrapped in parentheses when they bind looser than `min`.
        let at = |id: ExprId, min: Prec| -> TokenStream {
            let r = get(id);
            let t = r.tokens;
            if r.prec >= min {
                t
            } else {
                quote!((#t))
            }
        };
        let atom = |tokens| Rendered {
            tokens,
            prec: Prec::Atom,
        };
        // `slice[i]`, an atom: a state, parameter, column or qp value the method has bound.
        let element = |slice: TokenStream, i: usize| {
            let i = usize_lit(i);
            atom(quote!(#slice[#i]))
        };
        match node {
            Node::Const(bits) => {
                let v = f64::from_bits(bits);
                let prec = if v.is_sign_negative() && v != 0.0 {
                    Prec::Unary
                } else {
                    Prec::Atom
                };
                Rendered {
                    tokens: lit(v),
                    prec,
                }
            }
            Node::Time => atom(quote!(t)),
            Node::State(i) => element(quote!(x), i as usize),
            Node::Param(i) => element(quote!(p), i as usize),
            // The event method binds `row`, the current row's values of the model's columns.
            Node::Column(c) => element(quote!(row), c as usize),
            // qp solutions and their derivatives: slices the method binds first (see
            // `methods::qp_prelude`).
            Node::QpSol(k) => element(quote!(qu), k as usize),
            Node::QpDeriv(k, w) => element(
                quote!(qd),
                k as usize * (self.n + self.p + 1) + w.column(self.n, self.p),
            ),
            Node::Add(a, b) => {
                // a + (−c) is printed a − c (the same IEEE operation).
                let (l, r, minus) = match (self.ar.node(b), self.ar.node(a)) {
                    (Node::Neg(c), _)
                        if done[b.index()]
                            .as_ref()
                            .is_some_and(|r| r.prec == Prec::Unary) =>
                    {
                        (at(a, Prec::Add), at(c, Prec::Mul), true)
                    }
                    (_, Node::Neg(c))
                        if done[a.index()]
                            .as_ref()
                            .is_some_and(|r| r.prec == Prec::Unary) =>
                    {
                        (at(b, Prec::Add), at(c, Prec::Mul), true)
                    }
                    _ => (at(a, Prec::Add), at(b, Prec::Mul), false),
                };
                let tokens = if minus {
                    quote!(#l - #r)
                } else {
                    quote!(#l + #r)
                };
                Rendered {
                    tokens,
                    prec: Prec::Add,
                }
            }
            Node::Mul(a, b) => {
                let (l, r) = (at(a, Prec::Mul), at(b, Prec::Unary));
                Rendered {
                    tokens: quote!(#l * #r),
                    prec: Prec::Mul,
                }
            }
            Node::Div(a, b) => {
                let (l, r) = (at(a, Prec::Mul), at(b, Prec::Unary));
                Rendered {
                    tokens: quote!(#l / #r),
                    prec: Prec::Mul,
                }
            }
            Node::Neg(a) => {
                let a = at(a, Prec::Unary);
                Rendered {
                    tokens: quote!(-#a),
                    prec: Prec::Unary,
                }
            }
            Node::Powi(a, k) => {
                let a = at(a, Prec::Atom);
                let m = Literal::u32_unsuffixed(k.unsigned_abs());
                let k = if k < 0 { quote!(-#m) } else { quote!(#m) };
                atom(quote!(#a.powi(#k)))
            }
            Node::Pow(a, b) => {
                let (a, b) = (at(a, Prec::Atom), get(b).tokens);
                atom(quote!(#a.powf(#b)))
            }
            Node::Call(Func::Sign, a) => {
                let a = get(a).tokens;
                atom(quote!(::mvad::__private::sign(#a)))
            }
            Node::Call(f, a) => {
                let a = at(a, Prec::Atom);
                let m = Ident::new(f.method_name(), Span::call_site());
                atom(quote!(#a.#m()))
            }
            Node::Select(c, x, a, b) => {
                let x = at(x, Prec::Add);
                let (a, b) = (get(a).tokens, get(b).tokens);
                let cond = match c {
                    Cmp::Gt => quote!(#x > 0.0),
                    Cmp::Ge => quote!(#x >= 0.0),
                    Cmp::Lt => quote!(#x < 0.0),
                    Cmp::Le => quote!(#x <= 0.0),
                };
                Rendered {
                    tokens: quote!(if #cond { #a } else { #b }),
                    prec: Prec::If,
                }
            }
            Node::Switch(j, a, b) => {
                let (a, b) = (get(a).tokens, get(b).tokens);
                // Bits 0..64 with a constant mask on the inline word; the rest through `get`.
                let on = match 1u64.checked_shl(j) {
                    Some(m) => {
                        let mask = Literal::u64_suffixed(m);
                        quote!(sw.low_word() & #mask != 0)
                    }
                    None => {
                        let j = usize_lit(j as usize);
                        quote!(sw.get(#j))
                    }
                };
                Rendered {
                    tokens: quote!(if #on { #a } else { #b }),
                    prec: Prec::If,
                }
            }
        }
    }

    /// `lets; dest[slot] = value; ..` with a zero fill of `buf` first unless dense.
    pub(super) fn fill_body(
        &self,
        kernel: &Kernel,
        buf: TokenStream,
        dest: impl Fn(usize) -> TokenStream,
    ) -> TokenStream {
        let Body { lets, outputs, .. } = self.body(kernel);
        let fill = if kernel.is_dense() {
            quote!()
        } else {
            quote!(#buf.fill(0.0);)
        };
        let stores = outputs.iter().map(|(s, v)| {
            let d = dest(*s);
            quote!(#d = #v;)
        });
        quote!(#fill #lets #(#stores)*)
    }

    /// The value of a scalar kernel as an expression block.
    pub(super) fn scalar(&self, kernel: &Kernel) -> TokenStream {
        let Body { lets, outputs, .. } = self.body(kernel);
        match outputs.first() {
            Some((_, v)) if lets.is_empty() => v.clone(),
            Some((_, v)) => quote!({ #lets #v }),
            None => quote!(0.0),
        }
    }

    /// `match index { 0 => a, 1 => b, _ => default }`, or just the arm for one case.
    pub(super) fn dispatch(
        &self,
        index: TokenStream,
        arms: Vec<(usize, TokenStream)>,
        default: TokenStream,
        total: usize,
    ) -> TokenStream {
        if total == 1 && arms.len() == 1 {
            return arms.into_iter().map(|(_, b)| b).collect();
        }
        if arms.is_empty() {
            return default;
        }
        let arms = arms.into_iter().map(|(i, b)| {
            let i = usize_lit(i);
            quote!(#i => { #b })
        });
        quote!(match #index { #(#arms)* _ => { #default } })
    }

    /// The value and gradient bodies of a cost term (ℓ or Φ): its value, and the body that
    /// fills `gx`, `gp` and returns its t partial; `0.0` and zeros for a model without it.
    pub(super) fn cost_bodies(
        &self,
        cost: Option<&GradKernels>,
        n: usize,
        p: usize,
        gx: TokenStream,
        gp: TokenStream,
    ) -> (TokenStream, TokenStream) {
        match cost {
            Some(c) => (self.scalar(&c.value), self.grad_body(c, n, p, gx, gp)),
            None => (quote!(0.0), quote!(#gx.fill(0.0); #gp.fill(0.0); 0.0)),
        }
    }

    /// A gradient kernel written to `gx`, `gp`; returns the last slot (∂ₜ or the value).
    pub(super) fn grad_body(
        &self,
        g: &GradKernels,
        n: usize,
        p: usize,
        gx: TokenStream,
        gp: TokenStream,
    ) -> TokenStream {
        let Body { lets, outputs, .. } = self.body(&g.grad);
        let mut stores = TokenStream::new();
        let mut ret = quote!(0.0);
        let (mut nx, mut np) = (0, 0);
        for (s, v) in outputs {
            if s < n {
                let i = usize_lit(s);
                stores.extend(quote!(#gx[#i] = #v;));
                nx += 1;
            } else if s < n + p {
                let i = usize_lit(s - n);
                stores.extend(quote!(#gp[#i] = #v;));
                np += 1;
            } else {
                ret = v;
            }
        }
        let fx = if nx < n {
            quote!(#gx.fill(0.0);)
        } else {
            quote!()
        };
        let fp = if np < p {
            quote!(#gp.fill(0.0);)
        } else {
            quote!()
        };
        quote!(#fx #fp #lets #stores #ret)
    }
}
