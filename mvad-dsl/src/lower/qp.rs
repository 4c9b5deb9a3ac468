//! A qp's objective F and constraints g_i → its data, with the symbolic checks.
//!
//! With the qp's variables u as the leaves [`Node::QpSol`] (in scope only inside the qp):
//! H = ∂²F/∂u², c = ∂F/∂u at u = 0, a_i = ∂g_i/∂u, b_i = −g_i(u = 0), where g = LHS − RHS
//! for `<=` and `==` and g = RHS − LHS for `>=` (stored as a_iᵀu ≤ b_i).
//!
//! Checks (errors located at the objective or the constraint):
//! - F is a polynomial of degree ≤ 2 in u and each g_i of degree ≤ 1, with coefficients any
//!   expression of θ, x and t ([`degree`]: a variable under a function, in a denominator,
//!   a condition or a non-integer power makes the degree infinite). Then H does not depend
//!   on u and the gradient is affine, so c and b are exact.
//! - Strict convexity where the data decide it: every Hₖₖ must be present, and a constant
//!   Hₖₖ positive; a constant 2×2 principal minor HₖₖHₗₗ − Hₖₗ² positive. What depends on θ,
//!   x or t is the solver's to refuse at run time (`QpError::NotConvex`).
//! - Every constraint involves at least one variable.
//!
//! A dynamic qp that a flow or ℓ reads gets one switch bit per inequality constraint
//! ([`Qp::switches`]): its frozen active set.

use super::{Ctx, Lowerer, Sym};
use crate::ast::{self, ConstraintOp};
use crate::diff::{diff, Var};
use crate::ir::{ConstraintKind, ExprArena, ExprId, Node, Qp};
use crate::span::Span;

/// The degree of a non-polynomial expression.
const INF: u32 = u32::MAX;

/// The degree of `root` as a polynomial in the [`Node::QpSol`] leaves selected by `is_var`
/// (an upper bound: no cancellation beyond the simplifier's), [`INF`] when it is not a
/// polynomial in them.
pub(super) fn degree(ar: &ExprArena, root: ExprId, is_var: impl Fn(u32) -> bool) -> u32 {
    let top = root.index() + 1;
    let live = ar.live(&[root]);
    let mut d = vec![0u32; top];
    for i in 0..top {
        if !live[i] {
            continue;
        }
        let g = |c: ExprId| d[c.index()];
        d[i] = match ar.node(ExprId(i as u32)) {
            Node::Const(_)
            | Node::Time
            | Node::State(_)
            | Node::Param(_)
            | Node::Column(_)
            | Node::QpDeriv(..) => 0,
            Node::QpSol(k) => u32::from(is_var(k)),
            Node::Add(a, b) | Node::Switch(_, a, b) => g(a).max(g(b)),
            Node::Neg(a) => g(a),
            Node::Mul(a, b) => g(a).saturating_add(g(b)),
            Node::Div(a, b) => {
                if g(b) == 0 {
                    g(a)
                } else {
                    INF
                }
            }
            Node::Powi(a, n) => match (g(a), n) {
                (0, _) => 0,
                (da, n) if n >= 0 => da.saturating_mul(n as u32),
                _ => INF,
            },
            Node::Pow(a, b) => {
                if g(a) == 0 && g(b) == 0 {
                    0
                } else {
                    INF
                }
            }
            Node::Select(_, cond, a, b) => {
                if g(cond) == 0 {
                    g(a).max(g(b))
                } else {
                    INF
                }
            }
            Node::Call(_, a) => {
                if g(a) == 0 {
                    0
                } else {
                    INF
                }
            }
        };
    }
    d[root.index()]
}

impl<'a> Lowerer<'a> {
    /// The [`Node::QpSol`] index of the variable `name` of the qp being lowered, if any.
    pub(super) fn qp_variable(&self, name: &str) -> Option<usize> {
        let (off, vars) = &self.qp_vars[self.qp_scope?];
        vars.iter().position(|v| *v == name).map(|k| off + k)
    }

    /// `NAME.VAR`: the leaf u*_k (read in a flow or ℓ when `ctx` is frozen).
    pub(super) fn qp_solution(
        &mut self,
        table: &ast::Ident,
        column: &ast::Ident,
        ctx: Ctx,
    ) -> ExprId {
        let found = match self.names.get(table.name.as_str()) {
            Some(&Sym::Qp(q)) => {
                self.qp_in_flow[q] |= ctx == Ctx::Frozen;
                self.qp_in_guard[q] |= self.in_guard;
                let (off, vars) = &self.qp_vars[q];
                vars.iter().position(|v| *v == column.name).map(|k| off + k)
            }
            _ => None,
        };
        match found {
            Some(k) => self.ar.intern(Node::QpSol(k as u32)),
            None => {
                self.internal(
                    table.span.to(column.span),
                    format!("`{}.{}` is not a qp variable", table.name, column.name),
                );
                self.ar.constant(f64::NAN)
            }
        }
    }

    /// Gives every dynamic qp that a flow or ℓ reads one switch bit per inequality
    /// constraint (its frozen active set), after the kinks' switching functions: a change of
    /// its active set is a kink of the flow, located like the others.
    pub(super) fn assign_qp_switches(&mut self, qps: &mut [Qp]) {
        let mut next = self.switches.len();
        for (q, qp) in qps.iter_mut().enumerate() {
            qp.in_flow = self.qp_in_flow[q];
            let le = qp
                .kinds
                .iter()
                .filter(|&&k| k == ConstraintKind::Le)
                .count();
            if self.qp_in_flow[q] && qp.dynamic && le > 0 {
                qp.switches = Some(next);
                next += le;
            }
        }
    }

    /// The error for a qp whose data jump along the flow (an `if` or `sign` of a state or t
    /// whose sides differ at its zero: see `lower/guard.rs`) and whose solution a flow, ℓ,
    /// an observable or a guard reads. A qp's data are evaluated pointwise, so such a jump
    /// would be a jump of the flow (or of the guard) that no switching function marks: the
    /// steps would cross it without its saltation term, the event time without the jump's
    /// sensitivity, and dC/dθ would be silently wrong. (Read only by resets and costs, the
    /// qp is evaluated where it is read, as their own choices are.)
    pub(super) fn no_jumping_qp_read_along_the_flow(&mut self, model: &ast::Model, qps: &[Qp]) {
        for (q, (qp, decl)) in qps.iter().zip(model.qps()).enumerate() {
            if !(self.qp_in_flow[q] || self.qp_in_guard[q]) {
                continue;
            }
            let jumps = qp
                .data()
                .into_iter()
                .any(|e| super::guard::jumps(&mut self.ar, e));
            if jumps {
                let reader = if self.qp_in_flow[q] {
                    "a flow, the running cost or an observable"
                } else {
                    "a guard"
                };
                self.error_with_help(
                    decl.name.span,
                    format!(
                        "the data of qp `{}` jump along the flow (an `if` or `sign` of a state or `t`), and {reader} reads its solution",
                        decl.name.name
                    ),
                    "write the choice outside the qp (one qp per side, chosen by an `if` in the flow or guard), where its crossing is located",
                );
            }
        }
    }

    /// Lowers qp number `index`: its data and the checks of the module documentation.
    pub(super) fn qp(&mut self, q: &'a ast::Qp, index: usize) -> Qp {
        let (off, nv) = (self.qp_vars[index].0, q.vars.len());
        self.qp_scope = Some(index);
        let f = self.expr(&q.objective, Ctx::Pointwise);
        let gs: Vec<(ConstraintKind, ExprId, Span)> = q
            .constraints
            .iter()
            .map(|c| {
                let (l, r) = (
                    self.expr(&c.lhs, Ctx::Pointwise),
                    self.expr(&c.rhs, Ctx::Pointwise),
                );
                let (kind, g) = match c.op {
                    ConstraintOp::Le | ConstraintOp::Lt => (ConstraintKind::Le, self.ar.sub(l, r)),
                    ConstraintOp::Ge | ConstraintOp::Gt => (ConstraintKind::Le, self.ar.sub(r, l)),
                    ConstraintOp::Eq => (ConstraintKind::Eq, self.ar.sub(l, r)),
                };
                (kind, g, c.span)
            })
            .collect();
        self.qp_scope = None;
        let name = &q.name.name;
        let own = |k: u32| (off..off + nv).contains(&(k as usize));

        // The objective: quadratic, then H, c and the convexity that constants decide.
        let objective_ok = self.check_degree(f, 2, q, off, q.objective.span, || {
            format!("the objective of qp `{name}` is not quadratic")
        });
        let grad: Vec<ExprId> = (0..nv)
            .map(|k| diff(&mut self.ar, f, Var::Qp(off + k)))
            .collect();
        let mut h = Vec::with_capacity(nv * nv);
        for &gk in &grad {
            for l in 0..nv {
                h.push(diff(&mut self.ar, gk, Var::Qp(off + l)));
            }
        }
        let c = self.ar.substitute(&grad, |n| match *n {
            Node::QpSol(k) if own(k) => Some(0.0),
            _ => None,
        });
        if objective_ok {
            self.check_convex(&h, q);
        }

        // The constraints: affine, each involving a variable.
        let mut kinds = Vec::with_capacity(gs.len());
        let mut a = Vec::with_capacity(gs.len() * nv);
        let mut gvals = Vec::with_capacity(gs.len());
        for (i, &(kind, g, span)) in gs.iter().enumerate() {
            let affine = self.check_degree(g, 1, q, off, span, || {
                format!("constraint {i} of qp `{name}` is not affine")
            });
            let row: Vec<ExprId> = (0..nv)
                .map(|k| diff(&mut self.ar, g, Var::Qp(off + k)))
                .collect();
            if affine && row.iter().all(|&e| self.ar.is_zero(e)) {
                self.error(
                    span,
                    format!("constraint {i} of qp `{name}` involves none of its variables"),
                );
            }
            kinds.push(kind);
            a.extend(row);
            gvals.push(g);
        }
        let g0 = self.ar.substitute(&gvals, |n| match *n {
            Node::QpSol(k) if own(k) => Some(0.0),
            _ => None,
        });
        let b: Vec<ExprId> = g0.into_iter().map(|g| self.ar.neg(g)).collect();

        let mut data = h.clone();
        data.extend(&c);
        data.extend(&a);
        data.extend(&b);
        let on_x = data
            .iter()
            .any(|&e| self.ar.depends_on(e, |n| matches!(n, Node::State(_))));
        let on_t = data
            .iter()
            .any(|&e| self.ar.depends_on(e, |n| matches!(n, Node::Time)));
        let dynamic = on_x || on_t;
        self.qp_deps.extend(std::iter::repeat_n((on_x, on_t), nv));
        Qp {
            name: name.clone(),
            vars: q.vars.iter().map(|v| v.name.clone()).collect(),
            offset: off,
            kinds,
            h,
            c,
            a,
            b,
            dynamic,
            switches: None,
            in_flow: false,
        }
    }

    /// Reports `e` if its degree in the qp's variables exceeds `max`, naming the first
    /// variable whose own degree does; returns whether it is within `max`.
    fn check_degree(
        &mut self,
        e: ExprId,
        max: u32,
        q: &ast::Qp,
        off: usize,
        span: Span,
        what: impl FnOnce() -> String,
    ) -> bool {
        let nv = q.vars.len();
        let total = degree(&self.ar, e, |k| (off..off + nv).contains(&(k as usize)));
        if total <= max {
            return true;
        }
        let culprit = (0..nv).find(|&k| degree(&self.ar, e, |j| j as usize == off + k) > max);
        let msg = match culprit {
            Some(k) => format!("{} in `{}`", what(), q.vars[k].name),
            None => format!("{} in its variables", what()),
        };
        let help = if max == 2 {
            "the objective must be a polynomial of degree at most 2 in the variables (their coefficients may be any expression of params, consts, states and `t`)"
        } else {
            "a constraint must be affine in the variables: a sum of coefficients times variables plus a term free of them"
        };
        self.error_with_help(span, msg, help);
        false
    }

    /// Strict convexity as far as constant entries of H decide it.
    fn check_convex(&mut self, h: &[ExprId], q: &ast::Qp) {
        let nv = q.vars.len();
        let name = &q.name.name;
        let span = q.objective.span;
        let mut bad = false;
        for k in 0..nv {
            let hkk = h[k * nv + k];
            let v = &q.vars[k].name;
            if self.ar.is_zero(hkk) {
                bad = true;
                self.error_with_help(
                    span,
                    format!("the objective of qp `{name}` has no quadratic term in `{v}`, so it is not strictly convex"),
                    format!("add a term such as `0.5 * {v}^2` (with a positive coefficient)"),
                );
            } else if let Some(val) = self.ar.as_const(hkk).filter(|&x| x <= 0.0) {
                bad = true;
                self.error(
                    span,
                    format!(
                        "the objective of qp `{name}` is not strictly convex: ∂²/∂{v}² is {val}, not positive"
                    ),
                );
            }
        }
        if bad {
            return;
        }
        for k in 0..nv {
            for l in k + 1..nv {
                let get = |i: usize, j: usize| self.ar.as_const(h[i * nv + j]);
                if let (Some(a), Some(b), Some(c)) = (get(k, k), get(l, l), get(k, l)) {
                    if a * b - c * c <= 0.0 {
                        self.error(
                            span,
                            format!(
                                "the objective of qp `{name}` is not strictly convex in (`{}`, `{}`): its Hessian has a non-positive 2×2 minor",
                                q.vars[k].name, q.vars[l].name
                            ),
                        );
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests;
