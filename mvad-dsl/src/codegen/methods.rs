//! The model trait's methods, each cut from its kernel by [`Gen`]: the static description
//! (`ModelInfo`, `info.rs`), the `HybridModel` core and the fused sparse `ModelSens::rhs_sens`.

use proc_macro2::{Literal, TokenStream};
use quote::{format_ident, quote};

use super::emit::Body;
use super::info::Build;
use super::products::{a_s_plus_b, Coef};
use super::{usize_lit, Gen};
use crate::schedule::{GradKernels, Kernel, ModelKernels};

impl Gen<'_> {
    /// The model's [`ModelKernels::info`], rebuilt; the row count of each `at each` event's
    /// table is `rows[t]`, bound by the constructor of a model with tables.
    pub(super) fn info(&self, k: &ModelKernels) -> TokenStream {
        let info = k.info().build();
        let rows = k.event_meta.iter().enumerate().filter_map(|(e, m)| {
            let (e, t) = (usize_lit(e), usize_lit(m.table?));
            Some(quote!(info.events[#e].trigger = ::mvad::__private::Trigger::Each { rows: rows[#t] };))
        });
        let rows: Vec<TokenStream> = rows.collect();
        if rows.is_empty() {
            return info;
        }
        quote!({
            let mut info = #info;
            #(#rows)*
            info
        })
    }

    /// The `HybridModel` methods and the `ModelSens` override.
    pub(super) fn methods(&self, k: &ModelKernels) -> (TokenStream, TokenStream) {
        let pr = quote!(::mvad::__private);
        let n = k.nstates();
        let p = k.nparams();
        let nm = k.modes.len();
        let xv = quote!(#pr::OVector<f64, Self::N>);
        let pv = quote!(#pr::OVector<f64, Self::P>);
        let mnn = quote!(#pr::OMatrix<f64, Self::N, Self::N>);
        let mnp = quote!(#pr::OMatrix<f64, Self::N, Self::P>);
        let sw_t = quote!(#pr::Switches);
        let [at, let_at, occ, let_occ] = eval_args(&pr);
        let vecd = |buf: TokenStream| {
            move |s: usize| {
                let i = usize_lit(s);
                quote!(#buf[#i])
            }
        };
        let matd = |buf: TokenStream, cols: usize, off: usize| {
            move |s: usize| {
                let (r, c) = (
                    usize_lit((s - off) / cols.max(1)),
                    usize_lit((s - off) % cols.max(1)),
                );
                quote!(#buf[(#r, #c)])
            }
        };
        let nan_fill = |buf: TokenStream| quote!(#buf.fill(f64::NAN););

        // Initial state and horizon.
        let x0 = self.fill_body(&k.x0, quote!(x0), vecd(quote!(x0)));
        let x0j = self.fill_body(&k.x0_jac, quote!(dx0), matd(quote!(dx0), p, 0));
        let (hz, hzg) = match &k.horizon {
            Some((h, hg)) => {
                let v = self.scalar(h);
                (
                    quote!(::core::option::Option::Some(#v)),
                    self.fill_body(hg, quote!(dt), vecd(quote!(dt))),
                )
            }
            None => (quote!(::core::option::Option::None), quote!(dt.fill(0.0);)),
        };

        // Flow (qps read under the frozen bits `sw`).
        self.frozen.set(true);
        let per_mode = |f: &dyn Fn(usize) -> TokenStream, buf: TokenStream| {
            let arms: Vec<(usize, TokenStream)> = (0..nm).map(|m| (m, f(m))).collect();
            self.dispatch(quote!(mode), arms, nan_fill(buf), nm)
        };
        let rhs = per_mode(
            &|m| self.fill_body(&k.modes[m].rhs, quote!(f), vecd(quote!(f))),
            quote!(f),
        );
        let jx = per_mode(
            &|m| self.fill_body(&k.modes[m].jac_x, quote!(fx), matd(quote!(fx), n, 0)),
            quote!(fx),
        );
        let jp = per_mode(
            &|m| self.fill_body(&k.modes[m].jac_p, quote!(fp), matd(quote!(fp), p, 0)),
            quote!(fp),
        );
        let any_t = k.modes.iter().any(|m| m.depends_on_t);
        let dt = if any_t {
            per_mode(
                &|m| self.fill_body(&k.modes[m].dt, quote!(ft), vecd(quote!(ft))),
                quote!(ft),
            )
        } else {
            quote!(ft.fill(0.0);)
        };
        let modes_where = |pred: &dyn Fn(&crate::schedule::ModeKernels) -> bool| {
            let ms: Vec<Literal> = (k.modes.iter().enumerate())
                .filter(|(_, m)| pred(m))
                .map(|(i, _)| usize_lit(i))
                .collect();
            if ms.is_empty() {
                quote!(false)
            } else {
                quote!(matches!(mode, #(#ms)|*))
            }
        };
        let dep_t = modes_where(&|m| m.depends_on_t);
        let constant = modes_where(&|m| m.constant);
        let affine: Vec<Literal> = (k.event_meta.iter().enumerate())
            .filter(|(_, e)| e.affine_guard)
            .map(|(i, _)| usize_lit(i))
            .collect();
        let affine = if affine.is_empty() {
            quote!(false)
        } else {
            quote!(matches!(event, #(#affine)|*))
        };
        let sens = per_mode(&|m| self.sens_body(k, m), quote!(f));
        self.frozen.set(false);

        // Events.
        let ne = k.events.len();
        let ev_arms = |f: &dyn Fn(usize) -> Option<TokenStream>| -> Vec<(usize, TokenStream)> {
            (0..ne).filter_map(|e| f(e).map(|b| (e, b))).collect()
        };
        let guard = self.dispatch(
            quote!(event),
            ev_arms(&|e| Some(self.scalar(&k.events[e].guard.value))),
            quote!(f64::NAN),
            ne,
        );
        let guard_grad = self.dispatch(
            quote!(event),
            ev_arms(&|e| Some(self.grad_body(&k.events[e].guard, n, p, quote!(gx), quote!(gp)))),
            quote!(gx.fill(f64::NAN); gp.fill(f64::NAN); f64::NAN),
            ne,
        );
        let reset = self.dispatch(
            quote!(event),
            ev_arms(&|e| {
                Some(self.fill_body(&k.events[e].reset, quote!(xplus), vecd(quote!(xplus))))
            }),
            nan_fill(quote!(xplus)),
            ne,
        );
        let reset_jac = self.dispatch(
            quote!(event),
            ev_arms(&|e| Some(self.reset_jac_body(&k.events[e].reset_jac, n, p))),
            quote!(rx.fill(f64::NAN); rp.fill(f64::NAN); rt.fill(f64::NAN);),
            ne,
        );
        let ecost = self.dispatch(
            quote!(event),
            ev_arms(&|e| k.events[e].cost.as_ref().map(|c| self.scalar(&c.value))),
            quote!(0.0),
            ne,
        );
        let ecost_grad = self.dispatch(
            quote!(event),
            ev_arms(&|e| {
                k.events[e]
                    .cost
                    .as_ref()
                    .map(|c| self.grad_body(c, n, p, quote!(cx), quote!(cp)))
            }),
            quote!(cx.fill(0.0); cp.fill(0.0); 0.0),
            ne,
        );

        // Times of time events: τ_j = τ (at), τ(row j) (at each), start + j·period (every).
        let etime = self.dispatch(
            quote!(event),
            ev_arms(&|e| {
                let tk = k.events[e].time.as_ref()?;
                let first = self.scalar(&tk.time);
                Some(match &tk.period {
                    Some((per, _)) => {
                        let per = self.scalar(per);
                        quote!(#first + (j as f64) * #per)
                    }
                    None => first,
                })
            }),
            quote!(f64::NAN),
            ne,
        );
        let etime_grad = self.dispatch(
            quote!(event),
            ev_arms(&|e| {
                let tk = k.events[e].time.as_ref()?;
                let mut body = self.fill_body(&tk.time_grad, quote!(dtau), vecd(quote!(dtau)));
                if let Some((_, per_grad)) = &tk.period {
                    let Body { lets, outputs, .. } = self.body(per_grad);
                    let adds = outputs.iter().map(|(s, v)| {
                        let i = usize_lit(*s);
                        quote!(dtau[#i] += (j as f64) * #v;)
                    });
                    body.extend(quote!({ #lets #(#adds)* }));
                }
                Some(body)
            }),
            quote!(dtau.fill(f64::NAN);),
            ne,
        );
        let row = row_binding(k);

        // Switching functions.
        let ns = k.switches.len();
        let sw_arms = |f: &dyn Fn(&GradKernels) -> TokenStream| -> Vec<(usize, TokenStream)> {
            k.switches
                .iter()
                .enumerate()
                .map(|(j, g)| (j, f(g)))
                .collect()
        };
        // Past the kinks' switching functions come the qps' constraints (`codegen/qp.rs`).
        let (swv_default, swg_default) = if k.nswitches() > ns {
            (
                quote!(self.__qp_switch_value(j, t, x.as_slice(), p.as_slice())),
                quote!(self.__qp_switch_grad(
                    j,
                    t,
                    x.as_slice(),
                    p.as_slice(),
                    gx.as_mut_slice(),
                    gp.as_mut_slice()
                )),
            )
        } else {
            (
                quote!(f64::NAN),
                quote!(gx.fill(f64::NAN); gp.fill(f64::NAN); f64::NAN),
            )
        };
        let swv = self.dispatch(
            quote!(j),
            sw_arms(&|g| self.scalar(&g.value)),
            swv_default,
            k.nswitches(),
        );
        let swg = self.dispatch(
            quote!(j),
            sw_arms(&|g| self.grad_body(g, n, p, quote!(gx), quote!(gp))),
            swg_default,
            k.nswitches(),
        );

        // Observables (their kinks and qps under the frozen bits, as the flow's).
        self.frozen.set(true);
        let nobs = k.observables.len();
        let nobs_l = usize_lit(nobs);
        let (obs, obs_jac) = if nobs == 0 {
            (quote!(), quote!())
        } else {
            let Body { lets, outputs, .. } = self.body(&k.observe);
            let mut written = vec![false; nobs];
            let mut stores = TokenStream::new();
            for (s, v) in outputs {
                written[s] = true;
                let i = usize_lit(s);
                stores.extend(quote!(y[#i] = #v;));
            }
            for (s, w) in written.iter().enumerate() {
                if !w {
                    let i = usize_lit(s);
                    stores.extend(quote!(y[#i] = 0.0;));
                }
            }
            let obs = quote!(if y.len() < #nobs_l { return; } #lets #stores);
            let Body { lets, outputs, .. } = self.body(&k.observe_jac);
            let mut stores = TokenStream::new();
            for (s, v) in outputs {
                let (buf, i) = if s < nobs * n {
                    (quote!(yx), s)
                } else {
                    (quote!(yp), s - nobs * n)
                };
                let i = usize_lit(i);
                stores.extend(quote!(#buf[#i] = #v;));
            }
            let (lx, lp) = (usize_lit(nobs * n), usize_lit(nobs * p));
            let jac = quote!(
                if yx.len() < #lx || yp.len() < #lp { return; }
                yx[..#lx].fill(0.0); yp[..#lp].fill(0.0);
                #lets #stores
            );
            (obs, jac)
        };
        self.frozen.set(false);

        // Cost (ℓ reads qps under the frozen bits, as the flow does).
        self.frozen.set(true);
        let (rc, rcg) = self.cost_bodies(k.running_cost.as_ref(), n, p, quote!(lx), quote!(lp));
        self.frozen.set(false);
        let (fc, fcg) = self.cost_bodies(k.final_cost.as_ref(), n, p, quote!(cx), quote!(cp));

        let sens_methods = quote! {
            #[inline]
            fn rhs_sens(&self, pt: #pr::Point<'_, Self::N, Self::P>, s: &#mnp, f: &mut #xv, ds: &mut #mnp) {
        let #pr::Point { mode, sw, t, x, p } = pt; #sens }
        };
        let core = quote! {
            #[inline]
            fn info(&self) -> &#pr::ModelInfo { &self.info }
            fn nstates(&self) -> Self::N { #pr::Const }
            fn nparams(&self) -> Self::P { #pr::Const }
            fn initial_state(&self, p: &#pv, x0: &mut #xv) { #x0 }
            fn initial_state_jac(&self, p: &#pv, dx0: &mut #mnp) { #x0j }
            fn horizon(&self, p: &#pv) -> ::core::option::Option<f64> { #hz }
            fn horizon_grad(&self, p: &#pv, dt: &mut #pv) { #hzg }
            #[inline]
            fn rhs(&self, pt: #pr::Point<'_, Self::N, Self::P>, f: &mut #xv) {
        let #pr::Point { mode, sw, t, x, p } = pt; #rhs }
            fn rhs_jac_x(&self, pt: #pr::Point<'_, Self::N, Self::P>, fx: &mut #mnn) {
        let #pr::Point { mode, sw, t, x, p } = pt; #jx }
            fn rhs_jac_p(&self, pt: #pr::Point<'_, Self::N, Self::P>, fp: &mut #mnp) {
        let #pr::Point { mode, sw, t, x, p } = pt; #jp }
            fn rhs_dt(&self, pt: #pr::Point<'_, Self::N, Self::P>, ft: &mut #xv) {
        let #pr::Point { mode, sw, t, x, p } = pt; #dt }
            fn rhs_depends_on_t(&self, mode: usize) -> bool { #dep_t }
            #[inline]
            fn flow_is_constant(&self, mode: usize) -> bool { #constant }
            fn guard_is_affine(&self, event: usize) -> bool { #affine }
            #[inline]
            fn guard(&self, event: usize, #at) -> f64 { #let_at #guard }
            #[inline]
            fn guard_grad(&self, event: usize, #at, gx: &mut #xv, gp: &mut #pv) -> f64 { #let_at #guard_grad }
            #[inline]
            fn reset(&self, #occ, #at, xplus: &mut #xv) { #let_occ #let_at #row #reset }
            #[inline]
            fn reset_jac(&self, #occ, #at, rx: &mut #mnn, rp: &mut #mnp, rt: &mut #xv) { #let_occ #let_at #row #reset_jac }
            #[inline]
            fn event_time(&self, #occ, p: &#pv) -> f64 { #let_occ #row #etime }
            #[inline]
            fn event_time_grad(&self, #occ, p: &#pv, dtau: &mut #pv) { #let_occ #row #etime_grad }
            #[inline]
            fn switch_value(&self, j: usize, #at) -> f64 { #let_at #swv }
            #[inline]
            fn switch_grad(&self, j: usize, #at, gx: &mut #xv, gp: &mut #pv) -> f64 { #let_at #swg }
            fn observe(&self, sw: &#sw_t, #at, y: &mut [f64]) { #let_at #obs }
            fn observe_jac(&self, sw: &#sw_t, #at, yx: &mut [f64], yp: &mut [f64]) { #let_at #obs_jac }
            #[inline]
            fn running_cost(&self, sw: &#sw_t, #at) -> f64 { #let_at #rc }
            #[inline]
            fn running_cost_value_grad(&self, sw: &#sw_t, #at, lx: &mut #xv, lp: &mut #pv) -> f64 { #let_at #rcg }
            #[inline]
            fn event_cost(&self, #occ, #at) -> f64 { #let_occ #let_at #row #ecost }
            #[inline]
            fn event_cost_grad(&self, #occ, #at, cx: &mut #xv, cp: &mut #pv) -> f64 { #let_occ #let_at #row #ecost_grad }
            fn final_cost(&self, #at) -> f64 { #let_at #fc }
            fn final_cost_grad(&self, #at, cx: &mut #xv, cp: &mut #pv) -> f64 { #let_at #fcg }
        };
        (core, sens_methods)
    }

    /// ∂R/∂x, ∂R/∂θ, ∂R/∂t from one kernel, each block zero-filled unless dense.
    fn reset_jac_body(&self, kernel: &Kernel, n: usize, p: usize) -> TokenStream {
        let Body { lets, outputs, .. } = self.body(kernel);
        let mut counts = [0usize; 3];
        let mut stores = TokenStream::new();
        for (s, v) in outputs {
            let (blk, buf, cols, off) = if s < n * n {
                (0, quote!(rx), n, 0)
            } else if s < n * n + n * p {
                (1, quote!(rp), p, n * n)
            } else {
                (2, quote!(rt), 1, n * n + n * p)
            };
            counts[blk] += 1;
            let (r, c) = ((s - off) / cols.max(1), (s - off) % cols.max(1));
            let d = if blk == 2 {
                let r = usize_lit(r);
                quote!(#buf[#r])
            } else {
                let (r, c) = (usize_lit(r), usize_lit(c));
                quote!(#buf[(#r, #c)])
            };
            stores.extend(quote!(#d = #v;));
        }
        let mut fills = TokenStream::new();
        for (i, (buf, size)) in [(quote!(rx), n * n), (quote!(rp), n * p), (quote!(rt), n)]
            .into_iter()
            .enumerate()
        {
            if counts[i] < size {
                fills.extend(quote!(#buf.fill(0.0);));
            }
        }
        quote!(#fills #lets #stores)
    }

    /// f and Ṡ = f_x S + f_θ for mode `m`, unrolled over the non-zero f_x entries.
    fn sens_body(&self, k: &ModelKernels, m: usize) -> TokenStream {
        let n = k.nstates();
        let p = k.nparams();
        let mk = &k.modes[m];
        let nnz = mk.sparsity.len();
        let body = self.body(&mk.sens);
        let mut stores = TokenStream::new();
        // Per non-zero f_x entry: a constant, or the name it is bound to.
        let mut fxv: Vec<Option<Coef>> = vec![None; nnz];
        let mut fpv: Vec<Option<TokenStream>> = vec![None; n * p];
        let mut fwritten = vec![false; n];
        for (j, (s, v)) in body.outputs.iter().enumerate() {
            let s = *s;
            if s < n {
                let i = usize_lit(s);
                stores.extend(quote!(f[#i] = #v;));
                fwritten[s] = true;
            } else if s < n + nnz {
                let id = format_ident!("fx{}", s - n);
                fxv[s - n] = Some(self.coef(&mk.sens, &body, j, Some(id), &mut stores));
            } else {
                // Each f_θ entry is used once: inlined (an `if` in parentheses).
                fpv[s - n - nnz] = Some(body.term(j));
            }
        }
        for (i, w) in fwritten.iter().enumerate() {
            if !w {
                let i = usize_lit(i);
                stores.extend(quote!(f[#i] = 0.0;));
            }
        }
        // ds = f_θ + Σ f_x·S, summed left to right as the tape does.
        let ds = a_s_plus_b(&mk.sparsity, &fxv, &fpv, (n, p), None, |r, c| {
            let (r, c) = (usize_lit(r), usize_lit(c));
            quote!(ds[(#r, #c)])
        });
        let lets = &body.lets;
        quote!(#lets #stores #ds)
    }
}

/// `let row = self.row(j);` in the event methods of a model that reads table columns: the
/// values of row j (the occurrence) that [`Node::Column`](crate::ir::Node::Column) leaves read.
pub(super) fn row_binding(k: &ModelKernels) -> TokenStream {
    if k.names.columns.is_empty() {
        quote!()
    } else {
        quote!(let row = self.row(j);)
    }
}

/// The evaluation-point parameters of the emitted event-side methods and the bindings that
/// unpack them into the names the kernels read, with the runtime's items under the path `pr`:
/// `at: At<'_, N, P>`, `let At { t, x, p } = at;`, `occ: Occurrence` and
/// `let Occurrence { event, j } = occ;`.
pub(super) fn eval_args(pr: &TokenStream) -> [TokenStream; 4] {
    [
        quote!(at: #pr::At<'_, Self::N, Self::P>),
        quote!(let #pr::At { t, x, p } = at;),
        quote!(occ: #pr::Occurrence),
        quote!(let #pr::Occurrence { event, j } = occ;),
    ]
}
