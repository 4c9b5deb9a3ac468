//! Smart constructors: local rewrites applied while nodes are built.
//!
//! Every constructor folds constants, applies the 0/1 identities and normalises
//! commutative operands (sorted by id), then interns the node, so that `a*b` and `b*a`
//! are one node and `x − x` is `0`. The rewrites are value-preserving for finite inputs:
//! x + 0 = x, x·1 = x, x·0 = 0, x − x = 0, −(−x) = x, (−a)·b = −(a·b), c₁·(c₂·x) = (c₁c₂)·x,
//! x·x = x², (xᵐ)ⁿ = x^{mn}, x^c = x^{⌊c⌋} for integral c, x/1 = x, 0/x = 0. `x/x` is *not*
//! rewritten (it is NaN at 0). Choices with identical sides collapse to that side.

use crate::ir::{Cmp, ExprArena, ExprId, Func, Node};

/// What [`ExprArena::replace`] puts in place of a node.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Replacement {
    /// The constant.
    Const(f64),
    /// An expression of the same arena, taken as it is (not rebuilt).
    Expr(ExprId),
}

impl ExprArena {
    /// The constant `v` (−0.0 is stored as 0.0).
    pub fn constant(&mut self, v: f64) -> ExprId {
        let v = if v == 0.0 { 0.0 } else { v };
        self.intern(Node::Const(v.to_bits()))
    }

    /// The time t.
    pub fn time(&mut self) -> ExprId {
        self.intern(Node::Time)
    }

    /// State x_i.
    pub fn state(&mut self, i: usize) -> ExprId {
        self.intern(Node::State(i as u32))
    }

    /// Parameter θ_i.
    pub fn param(&mut self, i: usize) -> ExprId {
        self.intern(Node::Param(i as u32))
    }

    /// a + b.
    pub fn add(&mut self, a: ExprId, b: ExprId) -> ExprId {
        match (self.as_const(a), self.as_const(b)) {
            (Some(x), Some(y)) => return self.constant(x + y),
            (Some(0.0), None) => return b,
            (None, Some(0.0)) => return a,
            _ => {}
        }
        if self.node(a) == Node::Neg(b) || self.node(b) == Node::Neg(a) {
            return self.constant(0.0);
        }
        if a == b {
            let two = self.constant(2.0);
            return self.mul(two, a);
        }
        // −a + −b = −(a + b)
        if let (Node::Neg(x), Node::Neg(y)) = (self.node(a), self.node(b)) {
            let s = self.add(x, y);
            return self.neg(s);
        }
        let (a, b) = if a <= b { (a, b) } else { (b, a) };
        self.intern(Node::Add(a, b))
    }

    /// a − b.
    pub fn sub(&mut self, a: ExprId, b: ExprId) -> ExprId {
        if a == b {
            return self.constant(0.0);
        }
        let nb = self.neg(b);
        self.add(a, nb)
    }

    /// −a.
    pub fn neg(&mut self, a: ExprId) -> ExprId {
        match self.node(a) {
            Node::Const(bits) => self.constant(-f64::from_bits(bits)),
            Node::Neg(x) => x,
            Node::Mul(x, y) if self.as_const(x).is_some() || self.as_const(y).is_some() => {
                let (x, y) = if self.as_const(x).is_some() {
                    (x, y)
                } else {
                    (y, x)
                };
                let c = self.constant(-self.as_const(x).unwrap_or(0.0));
                self.mul(c, y)
            }
            _ => self.intern(Node::Neg(a)),
        }
    }

    /// Pulls a negation out of either operand of a product or quotient `op`:
    /// (−x) op b = −(x op b) and a op (−y) = −(a op y); `None` when neither is negated.
    fn pull_negation(
        &mut self,
        a: ExprId,
        b: ExprId,
        op: fn(&mut Self, ExprId, ExprId) -> ExprId,
    ) -> Option<ExprId> {
        let inner = match (self.node(a), self.node(b)) {
            (Node::Neg(x), _) => op(self, x, b),
            (_, Node::Neg(y)) => op(self, a, y),
            _ => return None,
        };
        Some(self.neg(inner))
    }

    /// a · b.
    pub fn mul(&mut self, a: ExprId, b: ExprId) -> ExprId {
        match (self.as_const(a), self.as_const(b)) {
            (Some(x), Some(y)) => return self.constant(x * y),
            (Some(0.0), None) | (None, Some(0.0)) => return self.constant(0.0),
            (Some(1.0), None) => return b,
            (None, Some(1.0)) => return a,
            (Some(-1.0), None) => return self.neg(b),
            (None, Some(-1.0)) => return self.neg(a),
            _ => {}
        }
        if let Some(m) = self.pull_negation(a, b, Self::mul) {
            return m;
        }
        if a == b {
            return self.powi(a, 2);
        }
        // Constant first, then merge nested constant factors: c₁·(c₂·x) = (c₁c₂)·x.
        let (a, b) = if self.as_const(b).is_some() {
            (b, a)
        } else {
            (a, b)
        };
        if let Some(c1) = self.as_const(a) {
            if let Node::Mul(x, y) = self.node(b) {
                let (x, y) = if self.as_const(y).is_some() {
                    (y, x)
                } else {
                    (x, y)
                };
                if let Some(c2) = self.as_const(x) {
                    let c = self.constant(c1 * c2);
                    return self.mul(c, y);
                }
            }
            if c1 < 0.0 {
                let c = self.constant(-c1);
                let m = self.mul(c, b);
                return self.intern(Node::Neg(m));
            }
        }
        let (a, b) = if a <= b { (a, b) } else { (b, a) };
        self.intern(Node::Mul(a, b))
    }

    /// a / b.
    pub fn div(&mut self, a: ExprId, b: ExprId) -> ExprId {
        match (self.as_const(a), self.as_const(b)) {
            (Some(x), Some(y)) => return self.constant(x / y),
            (Some(0.0), None) => return self.constant(0.0),
            (None, Some(1.0)) => return a,
            (None, Some(-1.0)) => return self.neg(a),
            _ => {}
        }
        if let Some(d) = self.pull_negation(a, b, Self::div) {
            return d;
        }
        self.intern(Node::Div(a, b))
    }

    /// aⁿ.
    pub fn powi(&mut self, a: ExprId, n: i32) -> ExprId {
        if let Some(x) = self.as_const(a) {
            return self.constant(x.powi(n));
        }
        match n {
            0 => return self.constant(1.0),
            1 => return a,
            _ => {}
        }
        if let Node::Powi(x, m) = self.node(a) {
            if let Some(k) = m.checked_mul(n) {
                return self.powi(x, k);
            }
        }
        self.intern(Node::Powi(a, n))
    }

    /// a^b (real exponent); integral constant exponents become [`Node::Powi`].
    pub fn pow(&mut self, a: ExprId, b: ExprId) -> ExprId {
        if let Some(y) = self.as_const(b) {
            if y.fract() == 0.0 && y.abs() <= 1024.0 {
                return self.powi(a, y as i32);
            }
            if let Some(x) = self.as_const(a) {
                return self.constant(x.powf(y));
            }
        }
        if self.is_const(a, 1.0) {
            return self.constant(1.0);
        }
        self.intern(Node::Pow(a, b))
    }

    /// f(a).
    pub fn call(&mut self, f: Func, a: ExprId) -> ExprId {
        if let Some(x) = self.as_const(a) {
            return self.constant(f.apply(x));
        }
        match (f, self.node(a)) {
            (Func::Abs, Node::Neg(x)) => self.call(Func::Abs, x),
            (Func::Abs, Node::Call(Func::Abs, _)) => a,
            (Func::Sign, Node::Call(Func::Sign, _)) => a,
            _ => self.intern(Node::Call(f, a)),
        }
    }

    /// Pointwise `if c cmp 0 then a else b`.
    pub fn select(&mut self, cmp: Cmp, c: ExprId, a: ExprId, b: ExprId) -> ExprId {
        if a == b {
            return a;
        }
        if let Some(v) = self.as_const(c) {
            return if cmp.test(v) { a } else { b };
        }
        self.intern(Node::Select(cmp, c, a, b))
    }

    /// Frozen `if bit j of sw then a else b`.
    pub fn switch(&mut self, j: u32, a: ExprId, b: ExprId) -> ExprId {
        if a == b {
            return a;
        }
        self.intern(Node::Switch(j, a, b))
    }

    /// Rebuilds `roots` with every node for which `value` gives a number replaced by that
    /// constant (through the smart constructors, so the result is simplified), e.g. a qp's
    /// variables set to 0.
    pub fn substitute(
        &mut self,
        roots: &[ExprId],
        value: impl Fn(&Node) -> Option<f64>,
    ) -> Vec<ExprId> {
        self.replace(roots, |_, node| value(node).map(Replacement::Const))
    }

    /// Rebuilds `roots` with every node (id, node) for which `with` gives a
    /// [`Replacement`] replaced by it, through the smart constructors (so the result is
    /// simplified): e.g. one pointwise choice of a guard replaced by one of its sides.
    pub fn replace(
        &mut self,
        roots: &[ExprId],
        with: impl Fn(ExprId, &Node) -> Option<Replacement>,
    ) -> Vec<ExprId> {
        let top = roots.iter().max().map_or(0, |m| m.index() + 1);
        let live = self.live(roots);
        let mut map: Vec<ExprId> = (0..top).map(|i| ExprId(i as u32)).collect();
        for i in 0..top {
            if !live[i] {
                continue;
            }
            let id = ExprId(i as u32);
            let node = self.node(id);
            map[i] = match with(id, &node) {
                Some(Replacement::Const(v)) => self.constant(v),
                Some(Replacement::Expr(e)) => e,
                None => self.rebuild(node.map_children(|c| map[c.index()])),
            };
        }
        roots.iter().map(|r| map[r.index()]).collect()
    }

    /// Rebuilds node `n` (with children already mapped) through the smart constructors.
    pub fn rebuild(&mut self, n: Node) -> ExprId {
        match n {
            Node::Const(bits) => self.constant(f64::from_bits(bits)),
            Node::Time
            | Node::State(_)
            | Node::Param(_)
            | Node::Column(_)
            | Node::QpSol(_)
            | Node::QpDeriv(..) => self.intern(n),
            Node::Add(a, b) => self.add(a, b),
            Node::Mul(a, b) => self.mul(a, b),
            Node::Neg(a) => self.neg(a),
            Node::Div(a, b) => self.div(a, b),
            Node::Powi(a, k) => self.powi(a, k),
            Node::Pow(a, b) => self.pow(a, b),
            Node::Call(f, a) => self.call(f, a),
            Node::Select(c, x, a, b) => self.select(c, x, a, b),
            Node::Switch(j, a, b) => self.switch(j, a, b),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ir::Point;
    use approx::assert_relative_eq;
    use proptest::prelude::*;

    fn x(ar: &mut ExprArena) -> ExprId {
        ar.state(0)
    }

    macro_rules! simp {
        ($name:ident, |$ar:ident| $lhs:expr => |$ar2:ident| $rhs:expr) => {
            #[test]
            fn $name() {
                let mut $ar = ExprArena::new();
                let l = $lhs;
                let $ar2 = &mut $ar;
                let r = $rhs;
                assert_eq!(l, r, "{:?}", $ar2);
            }
        };
    }

    simp!(add_zero, |ar| { let a = x(&mut ar); let z = ar.constant(0.0); ar.add(a, z) } => |ar| x(ar));
    simp!(mul_one, |ar| { let a = x(&mut ar); let o = ar.constant(1.0); ar.mul(o, a) } => |ar| x(ar));
    simp!(mul_zero, |ar| { let a = x(&mut ar); let z = ar.constant(0.0); ar.mul(a, z) } => |ar| ar.constant(0.0));
    simp!(x_minus_x, |ar| { let a = x(&mut ar); ar.sub(a, a) } => |ar| ar.constant(0.0));
    simp!(neg_neg, |ar| { let a = x(&mut ar); let n = ar.neg(a); ar.neg(n) } => |ar| x(ar));
    simp!(fold, |ar| { let a = ar.constant(2.0); let b = ar.constant(3.0); let m = ar.mul(a, b); ar.sin_of(m) } => |ar| ar.constant(6f64.sin()));
    simp!(commute, |ar| { let a = ar.state(0); let b = ar.param(1); ar.mul(a, b) } => |ar| { let b = ar.param(1); let a = ar.state(0); ar.mul(b, a) });
    simp!(commute_add, |ar| { let a = ar.state(0); let b = ar.time(); ar.add(a, b) } => |ar| { let b = ar.time(); let a = ar.state(0); ar.add(b, a) });
    simp!(square, |ar| { let a = x(&mut ar); ar.mul(a, a) } => |ar| { let a = x(ar); ar.powi(a, 2) });
    simp!(pow_int, |ar| { let a = x(&mut ar); let c = ar.constant(3.0); ar.pow(a, c) } => |ar| { let a = x(ar); ar.powi(a, 3) });
    simp!(const_factors, |ar| { let a = x(&mut ar); let c = ar.constant(3.0); let d = ar.constant(2.0); let m = ar.mul(c, a); ar.mul(d, m) } => |ar| { let a = x(ar); let c = ar.constant(6.0); ar.mul(a, c) });
    simp!(div_one, |ar| { let a = x(&mut ar); let c = ar.constant(1.0); ar.div(a, c) } => |ar| x(ar));
    simp!(select_same, |ar| { let a = x(&mut ar); let c = ar.param(0); ar.select(Cmp::Gt, c, a, a) } => |ar| x(ar));

    #[test]
    fn x_over_x_is_kept() {
        let mut ar = ExprArena::new();
        let a = x(&mut ar);
        let d = ar.div(a, a);
        assert!(matches!(ar.node(d), Node::Div(_, _)));
    }

    impl ExprArena {
        fn sin_of(&mut self, a: ExprId) -> ExprId {
            self.call(Func::Sin, a)
        }
    }

    /// A random expression over x0, x1, p0, t built by a small stack program, once raw
    /// (interned without rewrites) and once through the smart constructors.
    fn build(ops: &[(u8, u8, u8, f64)]) -> (ExprArena, ExprArena, ExprId, ExprId) {
        let mut raw = ExprArena::new();
        let mut smart = ExprArena::new();
        let mut rs: Vec<ExprId> = Vec::new();
        let mut ss: Vec<ExprId> = Vec::new();
        for &(op, i, j, c) in ops {
            let leaf = |ar: &mut ExprArena, k: u8| match k % 5 {
                0 => ar.state(0),
                1 => ar.state(1),
                2 => ar.param(0),
                3 => ar.time(),
                _ => ar.intern(Node::Const(c.to_bits())),
            };
            let pick = |ar: &mut ExprArena, stack: &[ExprId], k: u8| {
                if stack.is_empty() || k.is_multiple_of(3) {
                    leaf(ar, k / 3)
                } else {
                    stack[k as usize % stack.len()]
                }
            };
            let (ra, rb) = (pick(&mut raw, &rs, i), pick(&mut raw, &rs, j));
            let (sa, sb) = (pick(&mut smart, &ss, i), pick(&mut smart, &ss, j));
            let node = |a: ExprId, b: ExprId| match op % 12 {
                0 => Node::Add(a, b),
                1 => Node::Mul(a, b),
                2 => Node::Neg(a),
                3 => Node::Div(a, b),
                4 => Node::Powi(a, (j % 4) as i32),
                5 => Node::Call(Func::Sin, a),
                6 => Node::Call(Func::Exp, a),
                7 => Node::Call(Func::Abs, a),
                8 => Node::Select(Cmp::Gt, a, a, b),
                9 => Node::Pow(a, b),
                10 => Node::Switch(1, a, b),
                _ => Node::Call(Func::Atan, a),
            };
            rs.push(raw.intern(node(ra, rb)));
            ss.push(smart.rebuild(node(sa, sb)));
        }
        let r = *rs.last().unwrap_or(&ExprId(0));
        let s = *ss.last().unwrap_or(&ExprId(0));
        (raw, smart, r, s)
    }

    proptest! {
        /// Simplification and sharing preserve values at random points.
        #[test]
        fn simplification_preserves_values(
            ops in proptest::collection::vec((0u8..12, 0u8..30, 0u8..30, -3.0f64..3.0), 1..25),
            x0 in -2.0f64..2.0, x1 in -2.0f64..2.0, p0 in 0.1f64..2.0, t in 0.0f64..3.0, sw in 0u64..4,
        ) {
            let (raw, smart, r, s) = build(&ops);
            let xs = [x0, x1];
            let ps = [p0];
            let at = Point { t, x: &xs, p: &ps, sw };
            let a = raw.eval(&[r], &at)[0];
            let b = smart.eval(&[s], &at)[0];
            prop_assume!(a.is_finite() && a.abs() < 1e12);
            assert_relative_eq!(a, b, epsilon = 1e-12, max_relative = 1e-10);
            prop_assert!(smart.len() <= 2 * raw.len() + 8);
        }
    }

    /// A case proptest found: chains of x + x and x·x. The smart arena holds the
    /// intermediate forms it rewrote (2x, x², their constants) next to the results, so it may
    /// be larger than the raw one, but only by a bounded factor.
    #[test]
    fn rewrites_keep_the_arena_small() {
        let ops = [
            (0, 15, 0, 0.0),
            (1, 1, 12, -0.716533659903501),
            (1, 1, 0, 0.0),
            (0, 1, 4, 0.0),
            (0, 0, 0, 0.0),
            (0, 0, 0, 0.0),
            (0, 0, 0, 0.0),
            (0, 0, 0, 0.0),
            (0, 0, 0, 0.0),
            (0, 0, 0, 0.0),
            (0, 0, 0, 0.0),
            (1, 0, 12, -0.3544839026778638),
            (0, 0, 0, 0.0),
        ];
        let (raw, smart, _, _) = build(&ops);
        assert!(
            smart.len() <= 2 * raw.len() + 8,
            "raw {} smart {}",
            raw.len(),
            smart.len()
        );
    }
}
