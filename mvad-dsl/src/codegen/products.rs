//! The capability products, cut from their kernels: the sparse sums A S + b behind
//! `rhs_sens` and the second-order products (`ModelSecondOrder`), and the transposed sums
//! behind the vector–Jacobian products (`ModelAdjoint`).
//!
//! Every sum is written left to right in entry order, starting from b, exactly as the
//! interpreter (`mvad::interp`) accumulates it, so both doors agree to rounding.

use proc_macro2::TokenStream;
use quote::{format_ident, quote};

use super::emit::Body;
use super::methods::eval_args;
use super::{lit, usize_lit, Gen};
use crate::schedule::{Kernel, ModelKernels, SecondOrderKernels};

/// A non-zero matrix entry as the coefficient of a product.
#[derive(Clone)]
pub(super) enum Coef {
    /// A constant (±1 become a sign).
    Const(f64),
    /// An operand of `*`: a `let` name or a parenthesised expression.
    Tok(TokenStream),
}

impl Coef {
    /// self · w as a signed term (negated, tokens).
    fn times(&self, w: TokenStream) -> (bool, TokenStream) {
        match self {
            Coef::Const(a) if *a == 1.0 => (false, w),
            Coef::Const(a) if *a == -1.0 => (true, w),
            Coef::Const(a) => {
                let a = lit(*a);
                (false, quote!((#a) * #w))
            }
            Coef::Tok(t) => (false, quote!(#t * #w)),
        }
    }
}

/// `init ± t₁ ± t₂ …`, left to right (`None` when there is nothing to add).
fn sum(
    init: Option<TokenStream>,
    terms: impl IntoIterator<Item = (bool, TokenStream)>,
) -> Option<TokenStream> {
    terms.into_iter().fold(init, |acc, (neg, t)| {
        Some(match (acc, neg) {
            (None, false) => t,
            (None, true) => quote!(-#t),
            (Some(a), false) => quote!(#a + #t),
            (Some(a), true) => quote!(#a - #t),
        })
    })
}

/// dest(r, c) = b\[r·p + c\] + Σ_{e : entries\[e\].0 = r} a\[e\] · s\[(entries\[e\].1, c)\] for every
/// r < rows, c < p; entries without a coefficient are skipped. Where there is no term the
/// entry is set to 0.0, or, with `fill = Some(buf)`, `buf` is zero-filled once first.
pub(super) fn a_s_plus_b(
    entries: &[(usize, usize)],
    a: &[Option<Coef>],
    b: &[Option<TokenStream>],
    (rows, p): (usize, usize),
    fill: Option<TokenStream>,
    dest: impl Fn(usize, usize) -> TokenStream,
) -> TokenStream {
    let mut out = TokenStream::new();
    let mut zeros = 0;
    for r in 0..rows {
        let row: Vec<(usize, &Coef)> = entries
            .iter()
            .zip(a)
            .filter(|((rr, _), _)| *rr == r)
            .filter_map(|((_, k), a)| a.as_ref().map(|a| (*k, a)))
            .collect();
        for c in 0..p {
            let cl = usize_lit(c);
            let terms = row.iter().map(|(k, a)| {
                let kl = usize_lit(*k);
                a.times(quote!(s[(#kl, #cl)]))
            });
            let d = dest(r, c);
            match sum(b[r * p + c].clone(), terms) {
                Some(v) => out.extend(quote!(#d = #v;)),
                None if fill.is_none() => out.extend(quote!(#d = 0.0;)),
                None => zeros += 1,
            }
        }
    }
    match fill {
        Some(buf) if zeros > 0 => quote!(#buf.fill(0.0); #out),
        _ => out,
    }
}

/// dest(k) = Σ_{e : entries\[e\].1 = k} w\[entries\[e\].0\] · a\[e\], e ascending, for k < ncols,
/// after one zero fill of `buf` unless every k has a term.
fn transposed(
    entries: &[(usize, usize)],
    a: &[Coef],
    w: &TokenStream,
    ncols: usize,
    buf: TokenStream,
    dest: impl Fn(usize) -> TokenStream,
) -> TokenStream {
    let mut cols: Vec<Vec<(bool, TokenStream)>> = vec![Vec::new(); ncols];
    for (&(r, k), a) in entries.iter().zip(a) {
        let rl = usize_lit(r);
        cols[k].push(a.times(quote!(#w[#rl])));
    }
    let mut out = if cols.iter().all(|c| !c.is_empty()) {
        TokenStream::new()
    } else {
        quote!(#buf.fill(0.0);)
    };
    for (k, terms) in cols.into_iter().enumerate() {
        if let Some(v) = sum(None, terms) {
            let d = dest(k);
            out.extend(quote!(#d = #v;));
        }
    }
    out
}

/// `buf[k] −= a·(w[r]·a_e)` (or `+=` for a negated coefficient) for every entry e = (r, k),
/// in entry order: a scaled transposed product added into `buf`, no fill, nothing per column
/// without an entry.
fn scaled_transposed_add(
    entries: &[(usize, usize)],
    coefs: &[Coef],
    w: &TokenStream,
    a: TokenStream,
    buf: TokenStream,
) -> TokenStream {
    let mut out = TokenStream::new();
    for (&(r, k), c) in entries.iter().zip(coefs) {
        let (rl, kl) = (usize_lit(r), usize_lit(k));
        let (neg, term) = c.times(quote!(#w[#rl]));
        out.extend(if neg {
            quote!(#buf[#kl] += #a * (#term);)
        } else {
            quote!(#buf[#kl] -= #a * (#term);)
        });
    }
    out
}

/// `buf[i]`.
fn at1(buf: TokenStream) -> impl Fn(usize) -> TokenStream {
    move |i| {
        let i = usize_lit(i);
        quote!(#buf[#i])
    }
}

/// `buf[(r, c)]`.
fn at2(buf: TokenStream) -> impl Fn(usize, usize) -> TokenStream {
    move |r, c| {
        let (r, c) = (usize_lit(r), usize_lit(c));
        quote!(#buf[(#r, #c)])
    }
}

impl Gen<'_> {
    /// The coefficient of output `k` of `body` (kernel `kernel`): a constant, or with `bind`
    /// a `let NAME` appended to `lets` (for coefficients used once per column of S), else the
    /// output as a factor.
    pub(super) fn coef(
        &self,
        kernel: &Kernel,
        body: &Body,
        k: usize,
        bind: Option<proc_macro2::Ident>,
        lets: &mut TokenStream,
    ) -> Coef {
        if let Some(c) = self.ar.as_const(kernel.outputs[k].1) {
            return Coef::Const(c);
        }
        match bind {
            Some(id) => {
                let v = &body.outputs[k].1;
                lets.extend(quote!(let #id: f64 = #v;));
                Coef::Tok(quote!(#id))
            }
            None => Coef::Tok(body.factor(k)),
        }
    }

    /// The `ModelAdjoint` methods: λᵀf_x, λᵀf_θ per mode, ℓ_x alone, μᵀR_x, μᵀR_θ, μᵀR_t per
    /// event and μᵀ∂x₀/∂θ, each from the non-zero entries of its Jacobian kernel.
    pub(super) fn adjoint_methods(&self, k: &ModelKernels) -> TokenStream {
        let pr = quote!(::mvad::__private);
        let (n, p) = (k.nstates(), k.nparams());
        let xv = quote!(#pr::OVector<f64, Self::N>);
        let pv = quote!(#pr::OVector<f64, Self::P>);
        let lam = quote!(lambda);
        let mu = quote!(mu);
        let [at, let_at, occ, let_occ] = eval_args(&pr);

        // λᵀf_x, λᵀf_θ read qps under the frozen bits, as the flow does; so does ℓ.
        self.frozen.set(true);
        let (mut rhs_arms, mut rate_arms, mut quad_arms) = (vec![], vec![], vec![]);
        for (m, mk) in k.modes.iter().enumerate() {
            let body = self.body(&mk.jac);
            let nx = mk.second.x_entries.len();
            let mut lets = body.lets.clone();
            let a: Vec<Coef> = (0..mk.jac.outputs.len())
                .map(|j| self.coef(&mk.jac, &body, j, None, &mut lets))
                .collect();
            let xe = &mk.second.x_entries;
            let vx = transposed(xe, &a[..nx], &lam, n, quote!(vx), at1(quote!(vx)));
            let pe = &mk.second.p_entries;
            let vp = transposed(pe, &a[nx..], &lam, p, quote!(vp), at1(quote!(vp)));
            rhs_arms.push((m, quote!(#lets #vx #vp)));
            let rate = transposed(xe, &a[..nx], &lam, n, quote!(out), at1(quote!(out)));
            rate_arms.push((m, quote!(#lets #rate)));
            let quad = scaled_transposed_add(pe, &a[nx..], &lam, quote!(a), quote!(g));
            quad_arms.push((m, quote!(#lets #quad)));
        }
        let (rc_rate, rc_quad, rc_x) = match &k.running_cost {
            Some(c) => {
                let body = self.body(&c.grad);
                let (mut xs, mut ps, mut lx) =
                    (TokenStream::new(), TokenStream::new(), TokenStream::new());
                for (s, v) in &body.outputs {
                    if *s < n {
                        let i = usize_lit(*s);
                        xs.extend(quote!(out[#i] -= w * (#v);));
                        lx.extend(quote!(lx[#i] = #v;));
                    } else if *s < n + p {
                        let i = usize_lit(s - n);
                        ps.extend(quote!(g[#i] -= aw * (#v);));
                    }
                }
                let lets = &body.lets;
                (
                    quote!(if w != 0.0 { #lets #xs }),
                    quote!(if w != 0.0 { let aw = a * w; #lets #ps }),
                    quote!(#lets #lx),
                )
            }
            None => (TokenStream::new(), TokenStream::new(), TokenStream::new()),
        };
        self.frozen.set(false);
        let nm = k.modes.len();
        let rhs = self.dispatch(
            quote!(mode),
            rhs_arms,
            quote!(vx.fill(f64::NAN); vp.fill(f64::NAN);),
            nm,
        );
        let rate = self.dispatch(quote!(mode), rate_arms, quote!(out.fill(f64::NAN);), nm);
        let quad = self.dispatch(quote!(mode), quad_arms, quote!(g.fill(f64::NAN);), nm);
        let support_arms = (0..nm)
            .map(|m| {
                let cols = k.gradient_support(m).into_iter().map(usize_lit);
                (m, quote!(Some(&[#(#cols),*])))
            })
            .collect();
        let support = self.dispatch(quote!(mode), support_arms, quote!(None), 0);

        let reset_arms = (0..k.events.len())
            .map(|e| {
                let kernel = &k.events[e].reset_jac;
                let body = self.body(kernel);
                let mut lets = body.lets.clone();
                let (mut xe, mut xa, mut pe, mut pa, mut ts) =
                    (vec![], vec![], vec![], vec![], vec![]);
                for (j, &(s, _)) in kernel.outputs.iter().enumerate() {
                    let a = self.coef(kernel, &body, j, None, &mut lets);
                    if s < n * n {
                        xe.push((s / n, s % n));
                        xa.push(a);
                    } else if s < n * n + n * p {
                        let s = s - n * n;
                        pe.push((s / p, s % p));
                        pa.push(a);
                    } else {
                        let i = usize_lit(s - n * n - n * p);
                        ts.push(a.times(quote!(mu[#i])));
                    }
                }
                let vx = transposed(&xe, &xa, &mu, n, quote!(vx), at1(quote!(vx)));
                let vp = transposed(&pe, &pa, &mu, p, quote!(vp), at1(quote!(vp)));
                let rt = sum(None, ts).unwrap_or_else(|| quote!(0.0));
                (e, quote!(#lets #vx #vp #rt))
            })
            .collect();
        let row = super::methods::row_binding(k);
        let reset = self.dispatch(
            quote!(event),
            reset_arms,
            quote!(vx.fill(f64::NAN); vp.fill(f64::NAN); f64::NAN),
            k.events.len(),
        );

        let x0 = {
            let kernel = &k.x0_jac;
            let body = self.body(kernel);
            let mut lets = body.lets.clone();
            let a: Vec<Coef> = (0..kernel.outputs.len())
                .map(|j| self.coef(kernel, &body, j, None, &mut lets))
                .collect();
            let e: Vec<(usize, usize)> = kernel
                .outputs
                .iter()
                .map(|&(s, _)| (s / p, s % p))
                .collect();
            let vp = transposed(&e, &a, &mu, p, quote!(vp), at1(quote!(vp)));
            quote!(#lets #vp)
        };

        quote! {
            fn rhs_vjp(&self, pt: #pr::Point<'_, Self::N, Self::P>, lambda: &#xv, vx: &mut #xv, vp: &mut #pv) {
                let #pr::Point { mode, sw, t, x, p } = pt; #rhs }
            fn adjoint_rate(&self, pt: #pr::Point<'_, Self::N, Self::P>, lambda: &#xv, w: f64, out: &mut #xv) {
                let #pr::Point { mode, sw, t, x, p } = pt; { #rate } out.neg_mut(); #rc_rate }
            fn adjoint_quadrature_add(&self, pt: #pr::Point<'_, Self::N, Self::P>, lambda: &#xv, w: f64, a: f64, g: &mut #pv) {
                let #pr::Point { mode, sw, t, x, p } = pt; { #quad } #rc_quad }
            fn running_cost_grad_x(&self, sw: &#pr::Switches, #at, lx: &mut #xv) {
                #let_at lx.fill(0.0); #rc_x }
            fn gradient_support(&self, mode: usize) -> Option<&[usize]> { #support }
            fn reset_vjp(&self, #occ, #at, mu: &#xv, vx: &mut #xv, vp: &mut #pv) -> f64 { #let_occ #let_at #row #reset }
            fn initial_state_vjp(&self, p: &#pv, mu: &#xv, vp: &mut #pv) { #x0 }
        }
    }

    /// ∂ₓ(G_x S + G_θ)·v into `dest`: wₑ = Σᵢ vᵢ ∂(G_x)ₑ/∂xᵢ bound once per G_x entry, then
    /// A S + b with A = w and b = Σᵢ vᵢ ∂G_θ/∂xᵢ.
    fn dir_x_body(
        &self,
        so: &SecondOrderKernels,
        p: usize,
        buf: TokenStream,
        dest: impl Fn(usize, usize) -> TokenStream,
    ) -> TokenStream {
        let body = self.body(&so.dx);
        let nx = so.x_entries.len();
        let mut lets = body.lets.clone();
        let mut wt: Vec<Vec<(bool, TokenStream)>> = vec![Vec::new(); nx];
        let mut bt: Vec<Vec<(bool, TokenStream)>> = vec![Vec::new(); so.rows * p];
        for (j, &(e, i)) in so.dx_terms.iter().enumerate() {
            let il = usize_lit(i);
            let term = self
                .coef(&so.dx, &body, j, None, &mut lets)
                .times(quote!(v[#il]));
            if e < nx {
                wt[e].push(term);
            } else {
                let (r, c) = so.p_entries[e - nx];
                bt[r * p + c].push(term);
            }
        }
        let a: Vec<Option<Coef>> = wt
            .into_iter()
            .enumerate()
            .map(|(e, terms)| {
                let v = sum(None, terms)?;
                let id = format_ident!("w{}", e);
                lets.extend(quote!(let #id: f64 = #v;));
                Some(Coef::Tok(quote!(#id)))
            })
            .collect();
        let b: Vec<Option<TokenStream>> = bt.into_iter().map(|t| sum(None, t)).collect();
        let stores = a_s_plus_b(&so.x_entries, &a, &b, (so.rows, p), Some(buf), dest);
        quote!(#lets #stores)
    }

    /// ∂ₜ(G_x S + G_θ) into `dest`; with `value`, ∂ₜG₀ (ℓ's) ends the block as its value.
    fn dt_body(
        &self,
        so: &SecondOrderKernels,
        p: usize,
        value: bool,
        buf: TokenStream,
        dest: impl Fn(usize, usize) -> TokenStream,
    ) -> TokenStream {
        let body = self.body(&so.dt);
        let nx = so.x_entries.len();
        let ne = so.nentries();
        let mut lets = body.lets.clone();
        let mut a: Vec<Option<Coef>> = vec![None; nx];
        let mut b: Vec<Option<TokenStream>> = vec![None; so.rows * p];
        let mut dt_row = quote!(0.0);
        for (j, &(s, _)) in so.dt.outputs.iter().enumerate() {
            if s < nx {
                let id = format_ident!("a{}", s);
                a[s] = Some(self.coef(&so.dt, &body, j, Some(id), &mut lets));
            } else if s < ne {
                let (r, c) = so.p_entries[s - nx];
                b[r * p + c] = Some(body.term(j));
            } else {
                dt_row = body.outputs[j].1.clone();
            }
        }
        let stores = a_s_plus_b(&so.x_entries, &a, &b, (so.rows, p), Some(buf), dest);
        if value {
            quote!(#lets #stores #dt_row)
        } else {
            quote!(#lets #stores)
        }
    }

    /// The `ModelSecondOrder` methods: ∂ₓ(f_x S + f_θ)·v and ∂ₜ(f_x S + f_θ) per mode,
    /// ∂ₓ(ℓ_x S + ℓ_θ)·v and ∂ₜ(ℓ_x S + ℓ_θ) with ∂ₜℓ.
    pub(super) fn second_order_methods(&self, k: &ModelKernels) -> TokenStream {
        let pr = quote!(::mvad::__private);
        let p = k.nparams();
        let nm = k.modes.len();
        let xv = quote!(#pr::OVector<f64, Self::N>);
        let pv = quote!(#pr::OVector<f64, Self::P>);
        let mnp = quote!(#pr::OMatrix<f64, Self::N, Self::P>);
        let sw_t = quote!(#pr::Switches);
        let [at, let_at, ..] = eval_args(&pr);
        let nan = quote!(out.fill(f64::NAN););

        // Flows and ℓ read (static) qps under the frozen bits.
        self.frozen.set(true);
        let dir_arms = (0..nm)
            .map(|m| {
                (
                    m,
                    self.dir_x_body(&k.modes[m].second, p, quote!(out), at2(quote!(out))),
                )
            })
            .collect();
        let dir = self.dispatch(quote!(mode), dir_arms, nan.clone(), nm);
        let dt_arms = (0..nm)
            .map(|m| {
                let mk = &k.modes[m];
                let b = if mk.depends_on_t {
                    self.dt_body(&mk.second, p, false, quote!(out), at2(quote!(out)))
                } else {
                    quote!(out.fill(0.0);)
                };
                (m, b)
            })
            .collect();
        let dt = self.dispatch(quote!(mode), dt_arms, nan, nm);
        let out1 = |_r: usize, c: usize| at1(quote!(out))(c);
        let (rc_dir, rc_dt) = match &k.running_cost_second {
            Some(so) => (
                self.dir_x_body(so, p, quote!(out), out1),
                self.dt_body(so, p, true, quote!(out), out1),
            ),
            None => (quote!(out.fill(0.0);), quote!(out.fill(0.0); 0.0)),
        };
        self.frozen.set(false);
        quote! {
            fn rhs_sens_dir_x(&self, pt: #pr::Point<'_, Self::N, Self::P>, s: &#mnp, v: &#xv, out: &mut #mnp) {
                let #pr::Point { mode, sw, t, x, p } = pt; #dir }
            fn rhs_sens_dt(&self, pt: #pr::Point<'_, Self::N, Self::P>, s: &#mnp, out: &mut #mnp) {
                let #pr::Point { mode, sw, t, x, p } = pt; #dt }
            fn running_cost_sens_dir_x(&self, sw: &#sw_t, #at, s: &#mnp, v: &#xv, out: &mut #pv) { #let_at #rc_dir }
            fn running_cost_sens_dt(&self, sw: &#sw_t, #at, s: &#mnp, out: &mut #pv) -> f64 { #let_at #rc_dt }
        }
    }
}
