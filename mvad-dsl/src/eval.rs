//! A compact tape evaluator for [`Kernel`]s: the back end of models loaded at run time.
//!
//! A [`Tape`] is a register machine: one instruction per live node of the kernel, in
//! topological order, instruction i writing register i from earlier registers. An
//! instruction is the kernel's [`Node`] with its children renamed to registers, evaluated by
//! [`crate::ir::apply_node_in`], the one definition of a node's value that
//! [`crate::ir::apply_node`] and the generated code also follow. Evaluation reads `&[f64]`
//! slices (no nalgebra) and writes into caller-provided scratch, so a call allocates
//! nothing; qp solutions, their derivatives and table columns are read from the [`Inputs`]
//! of the run.

use crate::ir::{apply_node_in, ExprArena, ExprId, Inputs, Node, Point};
use crate::schedule::Kernel;

/// A kernel compiled to register code.
#[derive(Clone, Debug, PartialEq)]
pub struct Tape {
    /// Instruction i: a node whose children are register indices (as [`ExprId`]s).
    ops: Vec<Node>,
    outputs: Vec<(u32, u32)>,
    len: usize,
    reads_qp: bool,
    reads_qp_derivs: bool,
}

impl Tape {
    /// Compiles `kernel` (whose nodes live in `ar`).
    pub fn new(ar: &ExprArena, kernel: &Kernel) -> Tape {
        // Map node id -> register; nodes are in topological order so children come first.
        let mut reg = std::collections::HashMap::with_capacity(kernel.nodes.len());
        let mut ops = Vec::with_capacity(kernel.nodes.len());
        for (r, &id) in kernel.nodes.iter().enumerate() {
            let g = |c: ExprId| ExprId(reg.get(&c).copied().unwrap_or(0));
            ops.push(ar.node(id).map_children(g));
            reg.insert(id, r as u32);
        }
        let outputs = kernel
            .outputs
            .iter()
            .map(|&(s, e)| (s as u32, reg.get(&e).copied().unwrap_or(0)))
            .collect();
        let reads_qp = ops.iter().any(Node::is_qp);
        let reads_qp_derivs = ops.iter().any(|o| matches!(o, Node::QpDeriv(..)));
        Tape {
            ops,
            outputs,
            len: kernel.len,
            reads_qp,
            reads_qp_derivs,
        }
    }

    /// Whether the tape reads qp solutions (then they must be passed to [`Tape::run`] in its [`Inputs`]).
    pub fn reads_qp(&self) -> bool {
        self.reads_qp
    }

    /// Whether the tape reads derivatives of qp solutions.
    pub fn reads_qp_derivs(&self) -> bool {
        self.reads_qp_derivs
    }

    /// Registers needed by [`Tape::run`].
    pub fn nregs(&self) -> usize {
        self.ops.len()
    }

    /// Length of the dense output.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Whether the dense output is empty.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The non-zero outputs as (slot, register).
    pub fn outputs(&self) -> impl Iterator<Item = (usize, usize)> + '_ {
        self.outputs.iter().map(|&(s, r)| (s as usize, r as usize))
    }

    /// Runs the tape, filling `regs[..nregs]`: switch bits 0..64 from `at.sw` and the rest
    /// from `hi` (bit j ≥ 64 is bit (j − 64) % 64 of `hi[(j − 64) / 64]`, off when absent),
    /// qp solutions, their derivatives and table columns from `inputs`. Returns false (and
    /// does nothing) when `regs` is too short.
    pub fn run(&self, at: &Point<'_>, hi: &[u64], inputs: &Inputs<'_>, regs: &mut [f64]) -> bool {
        if regs.len() < self.ops.len() {
            return false;
        }
        for i in 0..self.ops.len() {
            regs[i] = apply_node_in(&self.ops[i], |r| regs[r.index()], at, hi, inputs);
        }
        true
    }

    /// Writes the dense output (zeros included) of a run into `out` from its registers, or
    /// NaN in every slot when the run failed (`ran` false); entries beyond `out.len()` are
    /// dropped.
    pub fn write_output(&self, ran: bool, regs: &[f64], out: &mut [f64]) {
        let fill = if ran { 0.0 } else { f64::NAN };
        out.iter_mut().take(self.len).for_each(|o| *o = fill);
        if ran {
            for &(s, r) in &self.outputs {
                if let Some(o) = out.get_mut(s as usize) {
                    *o = regs[r as usize];
                }
            }
        }
    }

    /// [`Tape::run`], then [`Tape::write_output`] into `out`.
    pub fn eval(
        &self,
        at: &Point<'_>,
        hi: &[u64],
        inputs: &Inputs<'_>,
        regs: &mut [f64],
        out: &mut [f64],
    ) {
        let ran = self.run(at, hi, inputs, regs);
        self.write_output(ran, regs, out);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ir::{Cmp, ExprArena, Func};
    use approx::assert_relative_eq;

    #[test]
    fn tape_matches_reference_evaluator() {
        let mut ar = ExprArena::new();
        let x = ar.state(0);
        let y = ar.state(1);
        let p = ar.param(0);
        let t = ar.time();
        let s = ar.call(Func::Sin, x);
        let m = ar.mul(s, p);
        let d = ar.div(m, y);
        let c = ar.sub(x, y);
        let sel = ar.select(Cmp::Gt, c, d, t);
        let sw = ar.switch(0, sel, p);
        let z = ar.constant(0.0);
        let k = Kernel::new(&ar, &[sw, z, d]);
        assert_eq!(k.outputs.len(), 2);
        let tape = Tape::new(&ar, &k);
        let mut regs = vec![0.0; tape.nregs()];
        let mut out = [9.0; 3];
        for (xv, bits) in [(0.7, 1u64), (-0.7, 1), (0.7, 0)] {
            let xs = [xv, 0.3];
            let at = Point {
                t: 0.25,
                x: &xs,
                p: &[1.5],
                sw: bits,
            };
            tape.eval(&at, &[], &Inputs::NONE, &mut regs, &mut out);
            let want = ar.eval(&[sw, d], &at);
            assert_relative_eq!(out[0], want[0]);
            assert_eq!(out[1], 0.0);
            assert_relative_eq!(out[2], want[1]);
        }
        // Too little scratch: NaN, no panic.
        let mut small = [0.0; 1];
        tape.eval(
            &Point {
                t: 0.0,
                x: &[],
                p: &[],
                sw: 0,
            },
            &[],
            &Inputs::NONE,
            &mut small,
            &mut out,
        );
        assert!(out[0].is_nan());
    }
}
