//! Running the tapes of an [`InterpretedModel`] at a point: the point as the tapes read it
//! ([`TapeAt`]), the qps solved first for a tape that reads them, and the scatter of a
//! tape's non-zero outputs into the dense vectors and matrices the trait methods fill.

use mvad_dsl::eval::Tape;
use mvad_dsl::ir::{Inputs, Point, QpValues};
use mvad_runtime::{At, Switches};
use nalgebra::Dyn;

use super::{GradTapes, InterpretedModel, ModeTapes, Scratch, M, X};

impl InterpretedModel {
    /// Has the qp bank solve every qp at the point of `at` (on the frozen active sets of a
    /// flow's point; with derivatives if `derivs`).
    pub(super) fn evaluate_qps(&self, at: &TapeAt<'_>, derivs: bool) {
        let Point { t, x, p, .. } = at.pt;
        self.qp_bank
            .borrow_mut()
            .evaluate(t, x, p, at.frozen, derivs, self.qp_fill(at));
    }

    /// The closure that writes qp q's data (and Jacobian) at the point of `at`.
    pub(super) fn qp_fill<'s>(
        &'s self,
        at: &'s TapeAt<'_>,
    ) -> impl FnMut(usize, &mut [f64], Option<&mut [f64]>) + 's {
        move |q, data, jac| {
            let mut regs = self.qp_regs.borrow_mut();
            let (dt, jt) = &self.qp_tapes[q];
            dt.eval(&at.pt, at.hi, &Inputs::NONE, &mut regs, data);
            if let Some(jac) = jac {
                jt.eval(&at.pt, at.hi, &Inputs::NONE, &mut regs, jac);
            }
        }
    }

    /// Runs `tape` into `regs` with the row of `at`, first solving the qps it reads.
    pub(super) fn run(&self, tape: &Tape, at: &TapeAt<'_>, regs: &mut [f64]) -> bool {
        if !tape.reads_qp() {
            let inputs = Inputs {
                qp: QpValues::NONE,
                row: at.row,
            };
            return tape.run(&at.pt, at.hi, &inputs, regs);
        }
        self.evaluate_qps(at, tape.reads_qp_derivs());
        let bank = self.qp_bank.borrow();
        let inputs = Inputs {
            qp: QpValues {
                u: bank.u(),
                du: bank.du(),
                n: self.n,
                p: self.p,
            },
            row: at.row,
        };
        tape.run(&at.pt, at.hi, &inputs, regs)
    }

    /// Runs `tape` and writes its dense output (zeros included) into `out`; NaN on failure.
    pub(super) fn eval(&self, tape: &Tape, at: &TapeAt<'_>, regs: &mut [f64], out: &mut [f64]) {
        let ran = self.run(tape, at, regs);
        tape.write_output(ran, regs, out);
    }

    /// Runs `tape` and hands the registers and the dense output buffer to `f`.
    pub(super) fn with<R>(
        &self,
        tape: &Tape,
        at: &TapeAt<'_>,
        f: impl FnOnce(bool, &[f64], &mut [f64]) -> R,
    ) -> R {
        let mut sc = self.scratch.borrow_mut();
        let Scratch { regs, out, .. } = &mut *sc;
        let ok = self.run(tape, at, regs);
        f(ok, regs, out)
    }

    /// Writes a vector kernel into `v` (dense, zeros included).
    pub(super) fn vec_out(&self, tape: &Tape, at: &TapeAt<'_>, v: &mut X) {
        let mut sc = self.scratch.borrow_mut();
        self.eval(tape, at, &mut sc.regs, v.as_mut_slice());
    }

    /// Writes a row-major matrix block of a kernel (slots `off..off + rows·cols`) into `m`.
    pub(super) fn mat_out(tape: &Tape, ok: bool, regs: &[f64], m: &mut M, cols: usize, off: usize) {
        if !ok {
            m.fill(f64::NAN);
            return;
        }
        m.fill(0.0);
        let size = m.nrows() * cols;
        for (s, r) in tape.outputs() {
            if s >= off && s < off + size {
                let (i, j) = ((s - off) / cols, (s - off) % cols);
                if let Some(e) = m.get_mut((i, j)) {
                    *e = regs[r];
                }
            }
        }
    }

    pub(super) fn mat(&self, tape: &Tape, at: &TapeAt<'_>, m: &mut M, cols: usize) {
        self.with(tape, at, |ok, regs, _| {
            Self::mat_out(tape, ok, regs, m, cols, 0)
        });
    }

    pub(super) fn scalar(&self, tape: &Tape, at: &TapeAt<'_>) -> f64 {
        let mut sc = self.scratch.borrow_mut();
        let mut out = [0.0];
        self.eval(tape, at, &mut sc.regs, &mut out);
        out[0]
    }

    /// Gradient kernel into `gx`, `gp`; returns the last slot.
    pub(super) fn grad(&self, g: &GradTapes, at: &TapeAt<'_>, gx: &mut X, gp: &mut X) -> f64 {
        let (n, p) = (self.n, self.p);
        let mut sc = self.scratch.borrow_mut();
        let Scratch { regs, out, .. } = &mut *sc;
        self.eval(&g.grad, at, regs, out);
        copy_into(gx.as_mut_slice(), &out[..n]);
        copy_into(gp.as_mut_slice(), &out[n..n + p]);
        out[n + p]
    }

    pub(super) fn mode(&self, mode: usize) -> Option<&ModeTapes> {
        self.modes.get(mode)
    }
}

pub(super) fn copy_into(dst: &mut [f64], src: &[f64]) {
    let k = dst.len().min(src.len());
    dst[..k].copy_from_slice(&src[..k]);
}

/// An evaluation point for the tapes: [`Point`] carries switch bits 0..64, `hi` the rest;
/// `frozen` is the whole switch set at a flow's point (qps are then solved on it); `row` the
/// current row's column values (event methods of `at each` events).
pub(super) struct TapeAt<'a> {
    pub(super) pt: Point<'a>,
    pub(super) hi: &'a [u64],
    pub(super) frozen: Option<&'a Switches>,
    pub(super) row: &'a [f64],
}

/// The point (t, x, θ) under the frozen branches `sw` (flows and ℓ).
pub(super) fn at_sw<'a>(at: At<'a, Dyn, Dyn>, sw: &'a Switches) -> TapeAt<'a> {
    TapeAt {
        pt: Point {
            t: at.t,
            x: at.x.as_slice(),
            p: at.p.as_slice(),
            sw: sw.low_word(),
        },
        hi: sw.high_words(),
        frozen: Some(sw),
        row: &[],
    }
}

/// The flow point `pt` under its frozen branches.
pub(super) fn at_pt(pt: mvad_runtime::Point<'_, Dyn, Dyn>) -> TapeAt<'_> {
    at_sw(pt.at(), pt.sw)
}

/// The point (t, x, θ) for pointwise functions (no frozen branches).
pub(super) fn pt0(at: At<'_, Dyn, Dyn>) -> TapeAt<'_> {
    TapeAt {
        pt: Point {
            t: at.t,
            x: at.x.as_slice(),
            p: at.p.as_slice(),
            sw: 0,
        },
        hi: &[],
        frozen: None,
        row: &[],
    }
}

/// The point (t, x, θ) at a table row, for the reset and event cost of an event.
pub(super) fn pt_row<'a>(at: At<'a, Dyn, Dyn>, row: &'a [f64]) -> TapeAt<'a> {
    TapeAt { row, ..pt0(at) }
}

/// The point for functions of θ alone (x₀, T).
pub(super) fn pt_theta(p: &X) -> TapeAt<'_> {
    TapeAt {
        pt: Point {
            t: 0.0,
            x: &[],
            p: p.as_slice(),
            sw: 0,
        },
        hi: &[],
        frozen: None,
        row: &[],
    }
}
