//! Guards that jump across zero, made continuous with the same firing set.
//!
//! A guard is evaluated pointwise, so `if σ ≥ 0 then A else B` (or `sign(σ)`) in it is a
//! choice taken at each point, not a frozen kink. Where its two sides differ at σ = 0 the
//! guard jumps there, and a jump from one side of zero to the other is a crossing of the
//! guard's surface at the instant σ crosses zero. The event time then moves with σ's zero,
//! not with the guard's: t' = −(∇g·S + ∂g/∂θ)/(dg/dt) taken from either side of the jump
//! is the wrong sensitivity. So before anything is derived from it, a guard g firing in
//! direction d is rewritten, one jump point at a time, as the continuous
//!
//! ```text
//!   d = up:    g ≥ 0  ⇔  (σ ≥ 0 ∧ g_A ≥ 0) ∨ (σ < 0 ∧ g_B ≥ 0)  ⇔  max(min(σ, g_A), min(−σ, g_B)) ≥ 0
//!   d = down:  g ≤ 0  ⇔  (σ ≥ 0 ∧ g_A ≤ 0) ∨ (σ < 0 ∧ g_B ≤ 0)  ⇔  min(max(−σ, g_A), max(σ, g_B)) ≤ 0
//! ```
//!
//! (the same set up to the instant σ = 0 itself), g_A and g_B being the guard with the
//! choice replaced by its side for σ ≥ 0 and σ < 0. Where g crosses zero on one side the
//! rewritten guard is that side near the root (g_A or g_B is the active piece), so nothing
//! changes there; where the jump crosses zero the active piece is ±σ, and t' is σ's
//! crossing-time sensitivity, exactly. The `min`/`max` introduced are continuous choices,
//! as is a choice whose condition is the difference of its sides (`max`, `min`, and an `if`
//! written as one), `abs`, and any choice on a value that does not move along the flow at
//! fixed θ: none of those is a jump point.

use crate::ir::{Cmp, Direction, ExprArena, ExprId, Func, Node};
use crate::schedule::varies_in_time;
use crate::simplify::Replacement;

/// At most this many jump points per guard: the rewriting copies the guard twice per jump
/// point (2^k copies for k of them).
pub(super) const MAX_JUMPS: usize = 6;

/// A choice in a guard at which its value may jump: the node `at`, the switching value σ
/// (the side `pos` is taken for σ ≥ 0, `neg` for σ < 0).
struct Jump {
    at: ExprId,
    sigma: ExprId,
    pos: Replacement,
    neg: Replacement,
}

/// The first (lowest id) jump point of `g`: a choice (`if`, `sign`) on a value that moves
/// along the flow, whose sides need not agree where the value is zero.
fn first_jump(ar: &mut ExprArena, g: ExprId) -> Option<Jump> {
    let live = ar.live(&[g]);
    for (i, &l) in live.iter().enumerate() {
        if !l {
            continue;
        }
        let at = ExprId(i as u32);
        let jump = match ar.node(at) {
            Node::Select(cmp, c, a, b) if moves(ar, c) && !is_difference(ar, c, a, b) => {
                let sigma = match cmp {
                    Cmp::Gt | Cmp::Ge => c,
                    Cmp::Lt | Cmp::Le => ar.neg(c),
                };
                let (pos, neg) = (Replacement::Expr(a), Replacement::Expr(b));
                Jump {
                    at,
                    sigma,
                    pos,
                    neg,
                }
            }
            Node::Call(Func::Sign, u) if moves(ar, u) => Jump {
                at,
                sigma: u,
                pos: Replacement::Const(1.0),
                neg: Replacement::Const(-1.0),
            },
            _ => continue,
        };
        return Some(jump);
    }
    None
}

/// Whether `e` moves along a segment at fixed θ.
fn moves(ar: &ExprArena, e: ExprId) -> bool {
    ar.depends_on(e, varies_in_time)
}

/// Whether the condition `c` of a choice between `a` and `b` is a − b or b − a: the sides
/// agree where it is zero, and the choice is continuous (`max`, `min`).
fn is_difference(ar: &mut ExprArena, c: ExprId, a: ExprId, b: ExprId) -> bool {
    c == ar.sub(a, b) || c == ar.sub(b, a)
}

/// Whether guard `g` has a jump point (see the module doc).
pub(super) fn jumps(ar: &mut ExprArena, g: ExprId) -> bool {
    first_jump(ar, g).is_some()
}

/// Guard `g` (firing in `direction`) rewritten without jump points (see the module doc);
/// `None` when it has more than [`MAX_JUMPS`].
pub(super) fn continuous(ar: &mut ExprArena, g: ExprId, direction: Direction) -> Option<ExprId> {
    rewrite(ar, g, direction, MAX_JUMPS)
}

fn rewrite(ar: &mut ExprArena, g: ExprId, direction: Direction, budget: usize) -> Option<ExprId> {
    let Some(jump) = first_jump(ar, g) else {
        return Some(g);
    };
    let budget = budget.checked_sub(1)?;
    let side = |ar: &mut ExprArena, with: Replacement| {
        let at = jump.at;
        ar.replace(&[g], |id, _| (id == at).then_some(with))[0]
    };
    let (g_pos, g_neg) = (side(ar, jump.pos), side(ar, jump.neg));
    let g_pos = rewrite(ar, g_pos, direction, budget)?;
    let g_neg = rewrite(ar, g_neg, direction, budget)?;
    let (sigma, minus_sigma) = (jump.sigma, ar.neg(jump.sigma));
    Some(match direction {
        Direction::Up => {
            let a = min(ar, sigma, g_pos);
            let b = min(ar, minus_sigma, g_neg);
            max(ar, a, b)
        }
        Direction::Down => {
            let a = max(ar, minus_sigma, g_pos);
            let b = max(ar, sigma, g_neg);
            min(ar, a, b)
        }
    })
}

/// max(a, b) as a continuous pointwise choice (the lowering's `max`).
fn max(ar: &mut ExprArena, a: ExprId, b: ExprId) -> ExprId {
    let c = ar.sub(a, b);
    ar.select(Cmp::Gt, c, a, b)
}

/// min(a, b) as a continuous pointwise choice (the lowering's `min`).
fn min(ar: &mut ExprArena, a: ExprId, b: ExprId) -> ExprId {
    let c = ar.sub(a, b);
    ar.select(Cmp::Gt, c, b, a)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ir::Point;

    fn eval(ar: &ExprArena, g: ExprId, x: f64, c: f64) -> f64 {
        let (xs, ps) = ([x], [c]);
        let at = Point {
            t: 0.0,
            x: &xs,
            p: &ps,
            sw: 0,
        };
        ar.eval(&[g], &at)[0]
    }

    /// `if x ≥ c then x else x − 1` jumps from below zero to above it at x = c; the rewritten
    /// guard has the same sign everywhere but at the jump, and is continuous there.
    #[test]
    fn a_jump_across_zero_becomes_a_kink_with_the_same_sign() {
        let mut ar = ExprArena::new();
        let (x, c, one) = (ar.state(0), ar.param(0), ar.constant(1.0));
        let sigma = ar.sub(x, c);
        let x1 = ar.sub(x, one);
        let g = ar.select(Cmp::Ge, sigma, x, x1);
        assert!(jumps(&mut ar, g));
        for direction in [Direction::Up, Direction::Down] {
            let h = continuous(&mut ar, g, direction).expect("one jump");
            assert!(!jumps(&mut ar, h));
            for i in 0..=40 {
                let xv = -1.0 + 0.05 * i as f64;
                if (xv - 0.5f64).abs() < 1e-12 {
                    continue;
                }
                let (gv, hv) = (eval(&ar, g, xv, 0.5), eval(&ar, h, xv, 0.5));
                match direction {
                    Direction::Up => assert_eq!(gv >= 0.0, hv >= 0.0, "x = {xv}"),
                    Direction::Down => assert_eq!(gv <= 0.0, hv <= 0.0, "x = {xv}"),
                }
            }
            let (below, above) = (eval(&ar, h, 0.5 - 1e-9, 0.5), eval(&ar, h, 0.5 + 1e-9, 0.5));
            assert!(
                (above - below).abs() < 1e-8,
                "{direction:?}: {below} → {above}"
            );
        }
    }

    /// `max`, `min`, `abs` and a choice on a value that does not move are not jump points.
    #[test]
    fn continuous_choices_are_left_alone() {
        let mut ar = ExprArena::new();
        let (x, c) = (ar.state(0), ar.param(0));
        let d = ar.sub(x, c);
        let mx = ar.select(Cmp::Gt, d, x, c);
        let mn = ar.select(Cmp::Gt, d, c, x);
        let ab = ar.call(Func::Abs, d);
        let sc = ar.call(Func::Sign, c);
        let fixed = ar.select(Cmp::Ge, c, x, d);
        for g in [mx, mn, ab, sc, fixed] {
            assert!(!jumps(&mut ar, g));
            assert_eq!(continuous(&mut ar, g, Direction::Up), Some(g));
        }
    }

    /// `sign` of a moving value is a jump point; more than `MAX_JUMPS` of them are refused.
    #[test]
    fn sign_jumps_and_the_number_of_jumps_is_bounded() {
        let mut ar = ExprArena::new();
        let x = ar.state(0);
        let mut g = ar.constant(0.0);
        for k in 0..=MAX_JUMPS {
            let ck = ar.constant(k as f64);
            let u = ar.sub(x, ck);
            let s = ar.call(Func::Sign, u);
            g = ar.add(g, s);
        }
        assert!(jumps(&mut ar, g));
        assert_eq!(continuous(&mut ar, g, Direction::Up), None);
    }
}
