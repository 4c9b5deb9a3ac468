//! Symbolic differentiation on the arena: d/dx_i, d/dθ_j, d/dt.
//!
//! [`diff`] walks the nodes below a root in topological order (a loop, no recursion) and
//! builds each derivative with the smart constructors, so results share nodes with the
//! original expression and with each other (one arena, one CSE). Rules, with u' = du/dv:
//!
//! | node | derivative |
//! |---|---|
//! | a + b, −a, a·b | a' + b', −a', a'b + ab' |
//! | a / b | (a' − (a/b)·b') / b |
//! | aⁿ | n·aⁿ⁻¹·a' |
//! | a^b | a^b·(b' ln a + b a'/a); b' = 0: b a^(b−1) a'; a' = 0: a^b ln a · b' |
//! | sin, cos, tan | cos·u', −sin·u', (1 + tan²)·u' |
//! | asin, acos, atan | u'/√(1−u²), −u'/√(1−u²), u'/(1+u²) |
//! | exp, log, sqrt | exp·u', u'/u, u'/(2√u) |
//! | sinh, cosh, tanh | cosh·u', sinh·u', (1 − tanh²)·u' |
//! | abs, sign | sign(u)·u', 0 |
//! | select / switch (min, max, if, frozen kinks) | the derivative of the side taken |
//! | qp solution u*_k | w.r.t. x, θ, t: the leaf ∂u*_k/∂w (`Node::QpDeriv`); w.r.t. the qp variable u_k: 1 |
//! | ∂u*_k/∂w | 0 (only first derivatives are taken of expressions reading qp solutions) |

use crate::ir::{Cmp, ExprArena, ExprId, Func, Node, Wrt};

/// A variable to differentiate with respect to.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Var {
    /// State x_i.
    State(usize),
    /// Parameter θ_i.
    Param(usize),
    /// Time t.
    Time,
    /// Variable k of the qps (`Node::QpSol(k)` read as a decision variable), to extract a
    /// qp's data from its objective and constraints.
    Qp(usize),
}

impl Var {
    fn matches(self, n: &Node) -> bool {
        match (self, n) {
            (Var::State(i), Node::State(j)) => i == *j as usize,
            (Var::Param(i), Node::Param(j)) => i == *j as usize,
            (Var::Time, Node::Time) => true,
            (Var::Qp(i), Node::QpSol(j)) => i == *j as usize,
            _ => false,
        }
    }

    /// What ∂u*/∂(this variable) is taken with respect to (`None` for a qp variable).
    fn wrt(self) -> Option<Wrt> {
        match self {
            Var::State(i) => Some(Wrt::State(i as u32)),
            Var::Param(i) => Some(Wrt::Param(i as u32)),
            Var::Time => Some(Wrt::Time),
            Var::Qp(_) => None,
        }
    }
}

/// d`root`/d`var`, built in the same arena (simplified and shared).
pub fn diff(ar: &mut ExprArena, root: ExprId, var: Var) -> ExprId {
    let top = root.index() + 1;
    let live = ar.live(&[root]);
    let zero = ar.constant(0.0);
    // Memo of derivatives, indexed by node id (only ids ≤ root are ever looked up).
    let mut d: Vec<ExprId> = vec![zero; top];
    for i in 0..top {
        if !live[i] {
            continue;
        }
        let e = ExprId(i as u32);
        let node = ar.node(e);
        let dv = |id: ExprId| d[id.index()];
        let r = match node {
            Node::Const(_) | Node::Column(_) | Node::QpDeriv(..) => zero,
            Node::QpSol(k) => match var.wrt() {
                Some(w) => {
                    let (on_x, on_t) = ar.qp_deps(k);
                    match w {
                        Wrt::State(_) if !on_x => zero,
                        Wrt::Time if !on_t => zero,
                        _ => ar.intern(Node::QpDeriv(k, w)),
                    }
                }
                None if var.matches(&node) => ar.constant(1.0),
                None => zero,
            },
            Node::Time | Node::State(_) | Node::Param(_) => {
                if var.matches(&node) {
                    ar.constant(1.0)
                } else {
                    zero
                }
            }
            Node::Add(a, b) => {
                let (da, db) = (dv(a), dv(b));
                ar.add(da, db)
            }
            Node::Neg(a) => {
                let da = dv(a);
                ar.neg(da)
            }
            Node::Mul(a, b) => {
                let (da, db) = (dv(a), dv(b));
                let l = ar.mul(da, b);
                let r = ar.mul(a, db);
                ar.add(l, r)
            }
            Node::Div(a, b) => {
                let (da, db) = (dv(a), dv(b));
                if ar.is_zero(db) {
                    ar.div(da, b)
                } else {
                    let q = ar.mul(e, db);
                    let num = ar.sub(da, q);
                    ar.div(num, b)
                }
            }
            Node::Powi(a, n) => chain(ar, dv(a), |ar| {
                let c = ar.constant(n as f64);
                let p = ar.powi(a, n.saturating_sub(1));
                ar.mul(c, p)
            }),
            Node::Pow(a, b) => {
                let (da, db) = (dv(a), dv(b));
                match (ar.is_zero(da), ar.is_zero(db)) {
                    (true, true) => zero,
                    (false, true) => chain(ar, da, |ar| {
                        let one = ar.constant(1.0);
                        let bm1 = ar.sub(b, one);
                        let p = ar.pow(a, bm1);
                        ar.mul(b, p)
                    }),
                    (true, false) => chain(ar, db, |ar| exponent_derivative(ar, a, e)),
                    (false, false) => {
                        // ∂/∂b a^b · b' + b a^(b−1) · a' (not a^b (b' ln a + b a'/a), which is
                        // 0/0 at a = 0).
                        let t1 = exponent_derivative(ar, a, e);
                        let t1 = ar.mul(t1, db);
                        let one = ar.constant(1.0);
                        let bm1 = ar.sub(b, one);
                        let p = ar.pow(a, bm1);
                        let bp = ar.mul(b, p);
                        let t2 = ar.mul(bp, da);
                        ar.add(t1, t2)
                    }
                }
            }
            Node::Call(f, a) => chain(ar, dv(a), |ar| func_derivative(ar, f, a, e)),
            Node::Select(c, cond, a, b) => {
                let (da, db) = (dv(a), dv(b));
                ar.select(c, cond, da, db)
            }
            Node::Switch(j, a, b) => {
                let (da, db) = (dv(a), dv(b));
                ar.switch(j, da, db)
            }
        };
        d[i] = r;
    }
    d[root.index()]
}

/// ∂(a^b)/∂b = a^b ln a for `e` = a^b, taken as 0 where a^b = 0 (a = 0, b > 0: a^b is 0 for
/// every such b, the limit of a^b ln a as a → 0⁺), where the product would be 0·(−∞): t^p at
/// t = 0 has ∂/∂p = 0, not NaN. A NaN a^b (a < 0) stays NaN in the value itself.
fn exponent_derivative(ar: &mut ExprArena, a: ExprId, e: ExprId) -> ExprId {
    let ln = ar.call(Func::Log, a);
    let d = ar.mul(e, ln);
    let zero = ar.constant(0.0);
    ar.select(Cmp::Gt, e, d, zero)
}

/// The chain rule f'(a)·a' for an outer function f of one argument a, with a' = `da` and
/// f'(a) built by `outer`; 0 when a' = 0, without building f'(a).
fn chain(ar: &mut ExprArena, da: ExprId, outer: impl FnOnce(&mut ExprArena) -> ExprId) -> ExprId {
    if ar.is_zero(da) {
        return ar.constant(0.0);
    }
    let fp = outer(ar);
    ar.mul(fp, da)
}

/// f'(a) for a call node `e = f(a)`.
fn func_derivative(ar: &mut ExprArena, f: Func, a: ExprId, e: ExprId) -> ExprId {
    let one = ar.constant(1.0);
    match f {
        Func::Sin => ar.call(Func::Cos, a),
        Func::Cos => {
            let s = ar.call(Func::Sin, a);
            ar.neg(s)
        }
        Func::Tan => {
            let sq = ar.powi(e, 2);
            ar.add(one, sq)
        }
        Func::Asin | Func::Acos => {
            let sq = ar.powi(a, 2);
            let d = ar.sub(one, sq);
            let r = ar.call(Func::Sqrt, d);
            let q = ar.div(one, r);
            if f == Func::Asin {
                q
            } else {
                ar.neg(q)
            }
        }
        Func::Atan => {
            let sq = ar.powi(a, 2);
            let d = ar.add(one, sq);
            ar.div(one, d)
        }
        Func::Exp => e,
        Func::Log => ar.div(one, a),
        Func::Sqrt => {
            let two = ar.constant(2.0);
            let d = ar.mul(two, e);
            ar.div(one, d)
        }
        Func::Sinh => ar.call(Func::Cosh, a),
        Func::Cosh => ar.call(Func::Sinh, a),
        Func::Tanh => {
            let sq = ar.powi(e, 2);
            ar.sub(one, sq)
        }
        Func::Abs => ar.call(Func::Sign, a),
        Func::Sign => ar.constant(0.0),
    }
}

/// The gradient of `root` with respect to every state, every param and the time:
/// (∂/∂x, ∂/∂θ, ∂/∂t).
pub fn gradient(
    ar: &mut ExprArena,
    root: ExprId,
    n: usize,
    p: usize,
) -> (Vec<ExprId>, Vec<ExprId>, ExprId) {
    let gx = (0..n).map(|i| diff(ar, root, Var::State(i))).collect();
    let gp = (0..p).map(|i| diff(ar, root, Var::Param(i))).collect();
    let gt = diff(ar, root, Var::Time);
    (gx, gp, gt)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ir::{Cmp, Point};
    use approx::assert_relative_eq;
    use proptest::prelude::*;

    /// Central difference of `e` in x0 at `x`, h = ε^(1/3)·max(1, |x|).
    fn fd(ar: &ExprArena, e: ExprId, x: f64, p: f64, t: f64, sw: u64, var: Var) -> f64 {
        let at = |x: f64, p: f64, t: f64| {
            let xs = [x, 0.3];
            let ps = [p];
            ar.eval(
                &[e],
                &Point {
                    t,
                    x: &xs,
                    p: &ps,
                    sw,
                },
            )[0]
        };
        let base = match var {
            Var::State(_) => x,
            Var::Param(_) => p,
            Var::Time => t,
            Var::Qp(_) => unreachable!("the finite-difference helper has no qp variables"),
        };
        let h = f64::EPSILON.cbrt() * base.abs().max(1.0);
        let (up, dn) = match var {
            Var::State(_) => (at(x + h, p, t), at(x - h, p, t)),
            Var::Param(_) => (at(x, p + h, t), at(x, p - h, t)),
            Var::Time => (at(x, p, t + h), at(x, p, t - h)),
            Var::Qp(_) => unreachable!("the finite-difference helper has no qp variables"),
        };
        (up - dn) / (2.0 * h)
    }

    fn check(ar: &mut ExprArena, e: ExprId, x: f64, p: f64, t: f64, sw: u64) {
        for var in [Var::State(0), Var::Param(0), Var::Time] {
            let d = diff(ar, e, var);
            let xs = [x, 0.3];
            let ps = [p];
            let sym = ar.eval(
                &[d],
                &Point {
                    t,
                    x: &xs,
                    p: &ps,
                    sw,
                },
            )[0];
            let num = fd(ar, e, x, p, t, sw, var);
            assert_relative_eq!(sym, num, epsilon = 1e-6, max_relative = 1e-6);
        }
    }

    /// u = x·p + t/3 + 0.1: a smooth argument depending on every variable.
    fn arg(ar: &mut ExprArena) -> ExprId {
        let x = ar.state(0);
        let p = ar.param(0);
        let t = ar.time();
        let xp = ar.mul(x, p);
        let c = ar.constant(3.0);
        let t3 = ar.div(t, c);
        let s = ar.add(xp, t3);
        let k = ar.constant(0.1);
        ar.add(s, k)
    }

    proptest! {
        /// Every elementary function's rule matches central differences (inside its domain).
        #[test]
        fn every_function_rule(x in -0.6f64..0.6, p in 0.2f64..0.9, t in 0.0f64..0.5, k in 0usize..14) {
            let mut ar = ExprArena::new();
            let u = arg(&mut ar);
            let f = Func::ALL[k];
            let u = if matches!(f, Func::Log | Func::Sqrt) {
                let c = ar.constant(1.5);
                ar.add(u, c)
            } else {
                u
            };
            prop_assume!(!matches!(f, Func::Abs | Func::Sign) || (x * p + t / 3.0 + 0.1).abs() > 1e-3);
            let e = ar.call(f, u);
            check(&mut ar, e, x, p, t, 0);
        }

        /// Arithmetic, powers, min/max/if (select) and frozen switches.
        #[test]
        fn arithmetic_rules(x in 0.2f64..2.0, p in 0.2f64..2.0, t in 0.1f64..2.0, sw in 0u64..2) {
            let mut ar = ExprArena::new();
            let u = arg(&mut ar);
            let xv = ar.state(0);
            let pv = ar.param(0);
            let tv = ar.time();
            let q = ar.div(u, pv);
            let pw = ar.pow(xv, pv);
            let pt = ar.pow(pv, tv);
            let pc = ar.constant(2.5);
            let px = ar.pow(xv, pc);
            let pi = ar.powi(u, -3);
            let diffv = ar.sub(xv, pv);
            prop_assume!((x - p).abs() > 1e-3);
            let sel = ar.select(Cmp::Gt, diffv, xv, pv); // max(x, p)
            let sw_e = ar.switch(0, q, pw);
            let exprs = [q, pw, pt, px, pi, sel, sw_e];
            for &e in &exprs {
                check(&mut ar, e, x, p, t, sw);
            }
            let m1 = ar.mul(q, pw);
            let m2 = ar.sub(m1, pi);
            let all = ar.add(m2, sel);
            check(&mut ar, all, x, p, t, sw);
        }
    }

    /// A random smooth expression over x0, p0, t (and a frozen switch), from a stack program.
    fn random_expr(ar: &mut ExprArena, ops: &[(u8, u8, u8, f64)]) -> ExprId {
        let mut stack: Vec<ExprId> = Vec::new();
        for &(op, i, j, c) in ops {
            let pick = |ar: &mut ExprArena, stack: &[ExprId], k: u8| {
                if stack.is_empty() || k.is_multiple_of(3) {
                    match k % 4 {
                        0 => ar.state(0),
                        1 => ar.param(0),
                        2 => ar.time(),
                        _ => ar.constant(c),
                    }
                } else {
                    stack[k as usize % stack.len()]
                }
            };
            let a = pick(ar, &stack, i);
            let b = pick(ar, &stack, j);
            let e = match op % 10 {
                0 => ar.add(a, b),
                1 => ar.sub(a, b),
                2 => ar.mul(a, b),
                3 => {
                    // a / (1 + b²): no poles.
                    let one = ar.constant(1.0);
                    let b2 = ar.powi(b, 2);
                    let d = ar.add(one, b2);
                    ar.div(a, d)
                }
                4 => ar.call(Func::Sin, a),
                5 => ar.call(Func::Atan, a),
                6 => {
                    let s = ar.call(Func::Tanh, a);
                    ar.call(Func::Exp, s)
                }
                7 => ar.powi(a, (j % 4) as i32),
                8 => ar.switch(0, a, b),
                _ => ar.neg(a),
            };
            stack.push(e);
        }
        stack.last().copied().unwrap_or_else(|| ar.state(0))
    }

    proptest! {
        /// Random compositions: the chain rule through shared subexpressions matches FD.
        #[test]
        fn random_expressions_match_fd(
            ops in proptest::collection::vec((0u8..10, 0u8..30, 0u8..30, -2.0f64..2.0), 1..20),
            x in -1.0f64..1.0, p in -1.0f64..1.0, t in 0.0f64..1.0, sw in 0u64..2,
        ) {
            let mut ar = ExprArena::new();
            let e = random_expr(&mut ar, &ops);
            let xs = [x, 0.3];
            let v = ar.eval(&[e], &Point { t, x: &xs, p: &[p], sw })[0];
            prop_assume!(v.is_finite() && v.abs() < 1e6);
            check(&mut ar, e, x, p, t, sw);
        }
    }

    #[test]
    fn derivative_shares_nodes() {
        let mut ar = ExprArena::new();
        let x = ar.state(0);
        let s = ar.call(Func::Exp, x);
        let d = diff(&mut ar, s, Var::State(0));
        assert_eq!(d, s, "d exp(x)/dx must be the node exp(x) itself");
        let p = ar.param(0);
        assert_eq!(diff(&mut ar, s, Var::Param(0)), ar.constant(0.0));
        let _ = p;
    }

    #[test]
    fn deep_chain_does_not_recurse() {
        let mut ar = ExprArena::new();
        let mut e = ar.state(0);
        for _ in 0..200_000 {
            e = ar.call(Func::Sin, e);
        }
        let d = diff(&mut ar, e, Var::State(0));
        let xs = [0.1];
        let v = ar.eval(
            &[d],
            &Point {
                t: 0.0,
                x: &xs,
                p: &[],
                sw: 0,
            },
        )[0];
        assert!(v.is_finite());
    }
}
