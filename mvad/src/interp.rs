//! Models loaded at run time: [`InterpretedModel`] evaluates the same scheduled kernels
//! the `hybrid!` macro compiles, through `mvad_dsl::eval` tapes, with dynamic sizes.
//!
//! Each trait method runs one tape into a scratch register file kept in a `RefCell`, so
//! no call allocates. Matrices are written entry by entry from the tape's non-zero
//! outputs after one zero fill. [`ModelSens::rhs_sens`] is overridden with the fused
//! kernel: f, the non-zero entries of f_x and f_θ in one pass, then
//! Ṡ = f_θ + Σ_{(i,k) ∈ nz(f_x)} (f_x)_{ik} S_{k·}, the same sums in the same order as the
//! generated code. The capability products (`ModelAdjoint`, `ModelSecondOrder`) live in
//! `interp/products.rs`.
//!
//! A model with qps keeps a [`QpBank`]: a tape that reads qp solutions first has the bank
//! evaluate them at its point (the data tapes fill each qp's data and Jacobian), then runs
//! with the bank's u* and ∂u*/∂(x, θ, t) as inputs.

use std::cell::RefCell;

use mvad_dsl::diag::Diagnostic;
use mvad_dsl::eval::Tape;
use mvad_dsl::ir::{self, Inputs, Point, QpValues};
use mvad_dsl::schedule::{GradKernels, Kernel, ModelKernels, TimeKind};
use mvad_runtime::qp::{
    ConstraintKind, QpBank, QpError, QpFlowKink, QpLayerInfo, QpOptions, QpState, Side,
};
use mvad_runtime::{
    At, EventInfo, HybridModel, ModelDims, ModelInfo, ModelSens, Occurrence, Switches, Trigger,
};
use nalgebra::{DMatrix, DVector, Dyn};

use products::SecondTapes;
use tables::{Tables, TimeTapes};

mod products;
mod tables;

/// A value tape and a gradient tape (slots: ∂/∂x, ∂/∂θ, then ∂/∂t or the value).
#[derive(Clone, Debug)]
struct GradTapes {
    value: Tape,
    grad: Tape,
}

#[derive(Clone, Debug)]
struct ModeTapes {
    rhs: Tape,
    jac_x: Tape,
    jac_p: Tape,
    dt: Tape,
    sens: Tape,
    /// The non-zero f_x entries, then the non-zero f_θ entries (as in `second`).
    jac: Tape,
    second: SecondTapes,
    sparsity: Vec<(usize, usize)>,
    /// The support of the adjoint's gradient quadrature (`ModelKernels::gradient_support`).
    gradient_support: Vec<usize>,
    depends_on_t: bool,
    constant: bool,
}

#[derive(Clone, Debug)]
struct EventTapes {
    guard: GradTapes,
    affine_guard: bool,
    reset: Tape,
    reset_jac: Tape,
    cost: Option<GradTapes>,
    /// A time event's τ (or start) and ∂τ/∂θ, and for `every` the period and its gradient.
    time: Option<TimeTapes>,
}

#[derive(Clone, Debug)]
struct Scratch {
    regs: Vec<f64>,
    out: Vec<f64>,
    /// Σᵢ vᵢ ∂(G_x)ₑ/∂xᵢ per G_x entry, for the directional second-order products.
    w: Vec<f64>,
}

/// A model loaded from `.hyb` text, evaluated by tapes (`N = P = Dyn`).
#[derive(Clone, Debug)]
pub struct InterpretedModel {
    info: ModelInfo,
    n: usize,
    p: usize,
    x0: Tape,
    x0_jac: Tape,
    horizon: Option<(Tape, Tape)>,
    modes: Vec<ModeTapes>,
    events: Vec<EventTapes>,
    switches: Vec<GradTapes>,
    observe: Tape,
    observe_jac: Tape,
    running_cost: Option<GradTapes>,
    final_cost: Option<GradTapes>,
    running_cost_second: Option<SecondTapes>,
    tables: Tables,
    scratch: RefCell<Scratch>,
    /// Per qp: its data tape and their Jacobian's.
    qp_tapes: Vec<(Tape, Tape)>,
    qp_info: Vec<QpLayerInfo>,
    qp_bank: RefCell<QpBank>,
    /// Registers for the data tapes (run while `scratch` is borrowed).
    qp_regs: RefCell<Vec<f64>>,
    /// Whether the second-order products are difference quotients (a flow reads a qp of
    /// the state; see `ModelKernels::second_order_by_differences`).
    second_by_differences: bool,
}

type X = DVector<f64>;
type M = DMatrix<f64>;

impl InterpretedModel {
    /// Builds the tapes of every kernel.
    pub fn new(k: ModelKernels) -> Self {
        let ar = &k.arena;
        let tape = |kernel: &Kernel| Tape::new(ar, kernel);
        let grad = |g: &GradKernels| GradTapes {
            value: tape(&g.value),
            grad: tape(&g.grad),
        };
        let info = ModelInfo {
            name: k.names.name.clone(),
            states: k.names.states.clone(),
            params: k.names.params.clone(),
            param_defaults: k.names.param_defaults.clone(),
            modes: k.mode_names.clone(),
            initial_mode: k.initial_mode,
            events: k
                .event_meta
                .iter()
                .map(|e| EventInfo {
                    name: e.decl.name.clone(),
                    direction: match e.decl.direction {
                        ir::Direction::Down => mvad_runtime::Direction::Down,
                        ir::Direction::Up => mvad_runtime::Direction::Up,
                    },
                    mode: e.decl.mode,
                    target: e.decl.target,
                    has_reset: e.decl.has_reset,
                    has_cost: e.has_cost,
                    trigger: match e.time {
                        None => Trigger::Guard,
                        Some(TimeKind::At) => Trigger::At,
                        Some(TimeKind::Every) => Trigger::Every,
                        Some(TimeKind::Each { .. }) => Trigger::Each { rows: 0 },
                    },
                })
                .collect(),
            observables: k.observables.clone(),
            switches: k.nswitches(),
            has_running_cost: k.running_cost.is_some(),
            has_final_cost: k.final_cost.is_some(),
            has_horizon: k.horizon.is_some(),
            jacobian_sparsity: k.modes.iter().map(|m| m.sparsity.clone()).collect(),
        };
        let all = k.all_kernels();
        let nregs = all.iter().map(|k| k.nodes.len()).max().unwrap_or(0);
        let nout = all.iter().map(|k| k.len).max().unwrap_or(0);
        let second = |so| SecondTapes::new(ar, so);
        let nw = (k.modes.iter().map(|m| &m.second))
            .chain(&k.running_cost_second)
            .map(|so| so.x_entries.len())
            .max()
            .unwrap_or(0);
        let qp_info: Vec<QpLayerInfo> = k
            .qps
            .iter()
            .map(|q| QpLayerInfo {
                name: q.name.clone(),
                vars: q.vars.clone(),
                kinds: q
                    .kinds
                    .iter()
                    .map(|kind| match kind {
                        ir::QpKind::Eq => ConstraintKind::Eq,
                        ir::QpKind::Le => ConstraintKind::Le,
                    })
                    .collect(),
                dynamic: q.dynamic,
                switches: q.switches,
                events_before: q.events_before.clone(),
                events_after: q.events_after.clone(),
            })
            .collect();
        InterpretedModel {
            qp_tapes: k
                .qps
                .iter()
                .map(|q| (tape(&q.data), tape(&q.data_jac)))
                .collect(),
            qp_bank: RefCell::new(QpBank::new(
                qp_info.clone(),
                k.nstates(),
                k.nparams(),
                QpOptions::default(),
            )),
            qp_info,
            qp_regs: RefCell::new(vec![0.0; nregs]),
            second_by_differences: k.second_order_by_differences(),
            n: k.nstates(),
            p: k.nparams(),
            x0: tape(&k.x0),
            x0_jac: tape(&k.x0_jac),
            horizon: k.horizon.as_ref().map(|(h, g)| (tape(h), tape(g))),
            modes: k
                .modes
                .iter()
                .enumerate()
                .map(|(mode, m)| ModeTapes {
                    rhs: tape(&m.rhs),
                    jac_x: tape(&m.jac_x),
                    jac_p: tape(&m.jac_p),
                    dt: tape(&m.dt),
                    sens: tape(&m.sens),
                    jac: tape(&m.jac),
                    second: second(&m.second),
                    sparsity: m.sparsity.clone(),
                    gradient_support: k.gradient_support(mode),
                    depends_on_t: m.depends_on_t,
                    constant: m.constant,
                })
                .collect(),
            events: (k.events.iter().zip(&k.event_meta))
                .map(|(e, meta)| EventTapes {
                    guard: grad(&e.guard),
                    affine_guard: meta.affine_guard,
                    reset: tape(&e.reset),
                    reset_jac: tape(&e.reset_jac),
                    cost: e.cost.as_ref().map(grad),
                    time: e.time.as_ref().map(|tk| {
                        let period = tk.period.as_ref().map(|(a, b)| (tape(a), tape(b)));
                        (tape(&tk.time), tape(&tk.time_grad), period)
                    }),
                })
                .collect(),
            switches: k.switches.iter().map(grad).collect(),
            observe: tape(&k.observe),
            observe_jac: tape(&k.observe_jac),
            running_cost: k.running_cost.as_ref().map(grad),
            final_cost: k.final_cost.as_ref().map(grad),
            running_cost_second: k.running_cost_second.as_ref().map(second),
            tables: Tables::new(&k),
            scratch: RefCell::new(Scratch {
                regs: vec![0.0; nregs],
                out: vec![0.0; nout],
                w: vec![0.0; nw],
            }),
            info,
        }
    }

    /// Parses, checks, lowers and schedules `.hyb` text, then builds the tapes.
    pub fn from_source(src: &str) -> Result<Self, Vec<Diagnostic>> {
        mvad_dsl::compile(src).map(Self::new)
    }

    /// The declared parameter values as a vector θ.
    pub fn default_params(&self) -> X {
        X::from_column_slice(&self.info.param_defaults)
    }

    /// Has the qp bank solve every qp at the point of `at` (on the frozen active sets of a
    /// flow's point; with derivatives if `derivs`).
    fn evaluate_qps(&self, at: &TapeAt<'_>, derivs: bool) {
        let Point { t, x, p, .. } = at.pt;
        self.qp_bank
            .borrow_mut()
            .evaluate(t, x, p, at.frozen, derivs, self.qp_fill(at));
    }

    /// The closure that writes qp q's data (and Jacobian) at the point of `at`.
    fn qp_fill<'s>(
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
    fn run(&self, tape: &Tape, at: &TapeAt<'_>, regs: &mut [f64]) -> bool {
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
    fn eval(&self, tape: &Tape, at: &TapeAt<'_>, regs: &mut [f64], out: &mut [f64]) {
        let ran = self.run(tape, at, regs);
        tape.write_output(ran, regs, out);
    }

    /// Runs `tape` and hands the registers and the dense output buffer to `f`.
    fn with<R>(
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
    fn vec_out(&self, tape: &Tape, at: &TapeAt<'_>, v: &mut X) {
        let mut sc = self.scratch.borrow_mut();
        self.eval(tape, at, &mut sc.regs, v.as_mut_slice());
    }

    /// Writes a row-major matrix block of a kernel (slots `off..off + rows·cols`) into `m`.
    fn mat_out(tape: &Tape, ok: bool, regs: &[f64], m: &mut M, cols: usize, off: usize) {
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

    fn mat(&self, tape: &Tape, at: &TapeAt<'_>, m: &mut M, cols: usize) {
        self.with(tape, at, |ok, regs, _| {
            Self::mat_out(tape, ok, regs, m, cols, 0)
        });
    }

    fn scalar(&self, tape: &Tape, at: &TapeAt<'_>) -> f64 {
        let mut sc = self.scratch.borrow_mut();
        let mut out = [0.0];
        self.eval(tape, at, &mut sc.regs, &mut out);
        out[0]
    }

    /// Gradient kernel into `gx`, `gp`; returns the last slot.
    fn grad(&self, g: &GradTapes, at: &TapeAt<'_>, gx: &mut X, gp: &mut X) -> f64 {
        let (n, p) = (self.n, self.p);
        let mut sc = self.scratch.borrow_mut();
        let Scratch { regs, out, .. } = &mut *sc;
        self.eval(&g.grad, at, regs, out);
        copy_into(gx.as_mut_slice(), &out[..n]);
        copy_into(gp.as_mut_slice(), &out[n..n + p]);
        out[n + p]
    }

    fn mode(&self, mode: usize) -> Option<&ModeTapes> {
        self.modes.get(mode)
    }
}

fn copy_into(dst: &mut [f64], src: &[f64]) {
    let k = dst.len().min(src.len());
    dst[..k].copy_from_slice(&src[..k]);
}

/// An evaluation point for the tapes: [`Point`] carries switch bits 0..64, `hi` the rest;
/// `frozen` is the whole switch set at a flow's point (qps are then solved on it); `row` the
/// current row's column values (event methods of `at each` events).
struct TapeAt<'a> {
    pt: Point<'a>,
    hi: &'a [u64],
    frozen: Option<&'a Switches>,
    row: &'a [f64],
}

/// The point (t, x, θ) under the frozen branches `sw` (flows and ℓ).
fn at_sw<'a>(at: At<'a, Dyn, Dyn>, sw: &'a Switches) -> TapeAt<'a> {
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
fn at_pt(pt: mvad_runtime::Point<'_, Dyn, Dyn>) -> TapeAt<'_> {
    at_sw(pt.at(), pt.sw)
}

/// The point (t, x, θ) for pointwise functions (no frozen branches).
fn pt0(at: At<'_, Dyn, Dyn>) -> TapeAt<'_> {
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
fn pt_row<'a>(at: At<'a, Dyn, Dyn>, row: &'a [f64]) -> TapeAt<'a> {
    TapeAt { row, ..pt0(at) }
}

/// The point for functions of θ alone (x₀, T).
fn pt_theta(p: &X) -> TapeAt<'_> {
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

impl ModelDims for InterpretedModel {
    type N = Dyn;
    type P = Dyn;
}

impl HybridModel for InterpretedModel {
    fn info(&self) -> &ModelInfo {
        &self.info
    }
    fn nstates(&self) -> Dyn {
        Dyn(self.n)
    }
    fn nparams(&self) -> Dyn {
        Dyn(self.p)
    }

    fn initial_state(&self, p: &X, x0: &mut X) {
        let at = pt_theta(p);
        self.vec_out(&self.x0, &at, x0);
    }
    fn initial_state_jac(&self, p: &X, dx0: &mut M) {
        let at = pt_theta(p);
        self.mat(&self.x0_jac, &at, dx0, self.p);
    }
    fn horizon(&self, p: &X) -> Option<f64> {
        let at = pt_theta(p);
        self.horizon.as_ref().map(|(h, _)| self.scalar(h, &at))
    }
    fn horizon_grad(&self, p: &X, dt: &mut X) {
        let at = pt_theta(p);
        match &self.horizon {
            Some((_, g)) => self.vec_out(g, &at, dt),
            None => dt.fill(0.0),
        }
    }

    fn rhs(&self, pt: mvad_runtime::Point<'_, Self::N, Self::P>, f: &mut X) {
        let mode = pt.mode;
        match self.mode(mode) {
            Some(m) => self.vec_out(&m.rhs, &at_pt(pt), f),
            None => f.fill(f64::NAN),
        }
    }
    fn rhs_jac_x(&self, pt: mvad_runtime::Point<'_, Self::N, Self::P>, fx: &mut M) {
        let mode = pt.mode;
        match self.mode(mode) {
            Some(m) => self.mat(&m.jac_x, &at_pt(pt), fx, self.n),
            None => fx.fill(f64::NAN),
        }
    }
    fn rhs_jac_p(&self, pt: mvad_runtime::Point<'_, Self::N, Self::P>, fp: &mut M) {
        let mode = pt.mode;
        match self.mode(mode) {
            Some(m) => self.mat(&m.jac_p, &at_pt(pt), fp, self.p),
            None => fp.fill(f64::NAN),
        }
    }
    fn rhs_dt(&self, pt: mvad_runtime::Point<'_, Self::N, Self::P>, ft: &mut X) {
        let mode = pt.mode;
        match self.mode(mode) {
            Some(m) if m.depends_on_t => self.vec_out(&m.dt, &at_pt(pt), ft),
            Some(_) => ft.fill(0.0),
            None => ft.fill(f64::NAN),
        }
    }
    fn rhs_depends_on_t(&self, mode: usize) -> bool {
        self.mode(mode).is_some_and(|m| m.depends_on_t)
    }
    fn flow_is_constant(&self, mode: usize) -> bool {
        self.mode(mode).is_some_and(|m| m.constant)
    }

    fn guard(&self, event: usize, at: At<'_, Self::N, Self::P>) -> f64 {
        match self.events.get(event) {
            Some(e) => self.scalar(&e.guard.value, &pt0(at)),
            None => f64::NAN,
        }
    }
    fn guard_is_affine(&self, event: usize) -> bool {
        self.events.get(event).is_some_and(|e| e.affine_guard)
    }
    fn guard_grad(
        &self,
        event: usize,
        at: At<'_, Self::N, Self::P>,
        gx: &mut X,
        gp: &mut X,
    ) -> f64 {
        match self.events.get(event) {
            Some(e) => self.grad(&e.guard, &pt0(at), gx, gp),
            None => {
                gx.fill(f64::NAN);
                gp.fill(f64::NAN);
                f64::NAN
            }
        }
    }
    fn reset(&self, occ: Occurrence, at: At<'_, Self::N, Self::P>, xplus: &mut X) {
        let Occurrence { event, j } = occ;
        let row = self.tables.row(event, j);
        match self.events.get(event) {
            Some(e) => self.vec_out(&e.reset, &pt_row(at, &row), xplus),
            None => xplus.fill(f64::NAN),
        }
    }
    fn reset_jac(
        &self,
        occ: Occurrence,
        at: At<'_, Self::N, Self::P>,
        rx: &mut M,
        rp: &mut M,
        rt: &mut X,
    ) {
        let Occurrence { event, j } = occ;
        let Some(e) = self.events.get(event) else {
            rx.fill(f64::NAN);
            rp.fill(f64::NAN);
            rt.fill(f64::NAN);
            return;
        };
        let (n, np) = (self.n, self.p);
        let tape = &e.reset_jac;
        let row = self.tables.row(event, j);
        self.with(tape, &pt_row(at, &row), |ok, regs, out| {
            Self::mat_out(tape, ok, regs, rx, n, 0);
            Self::mat_out(tape, ok, regs, rp, np, n * n);
            out[..n].fill(if ok { 0.0 } else { f64::NAN });
            if ok {
                for (s, r) in tape.outputs() {
                    if s >= n * n + n * np {
                        out[s - n * n - n * np] = regs[r];
                    }
                }
            }
            copy_into(rt.as_mut_slice(), &out[..n]);
        });
    }

    fn event_time(&self, occ: Occurrence, p: &X) -> f64 {
        let Occurrence { event, j } = occ;
        self.time_of(event, j, p)
    }
    fn event_time_grad(&self, occ: Occurrence, p: &X, dtau: &mut X) {
        let Occurrence { event, j } = occ;
        self.time_grad_of(event, j, p, dtau);
    }

    fn switch_value(&self, j: usize, at: At<'_, Self::N, Self::P>) -> f64 {
        let At { t, x, p } = at;
        let at = pt0(at);
        match self.switches.get(j) {
            Some(s) => self.scalar(&s.value, &at),
            // Past the kinks' switching functions: the qps' constraints.
            None => self.qp_bank.borrow_mut().switch_value(
                j,
                t,
                x.as_slice(),
                p.as_slice(),
                self.qp_fill(&at),
            ),
        }
    }
    fn switch_grad(&self, j: usize, at: At<'_, Self::N, Self::P>, gx: &mut X, gp: &mut X) -> f64 {
        let At { t, x, p } = at;
        let at = pt0(at);
        match self.switches.get(j) {
            Some(s) => self.grad(s, &at, gx, gp),
            None => {
                let fill = self.qp_fill(&at);
                let (gx, gp) = (gx.as_mut_slice(), gp.as_mut_slice());
                let mut bank = self.qp_bank.borrow_mut();
                bank.switch_grad(j, t, x.as_slice(), p.as_slice(), fill, gx, gp)
                    .1
            }
        }
    }

    fn observe(&self, sw: &Switches, at: At<'_, Self::N, Self::P>, y: &mut [f64]) {
        if y.len() < self.info.observables.len() {
            return;
        }
        let mut sc = self.scratch.borrow_mut();
        let at = at_sw(at, sw);
        self.eval(&self.observe, &at, &mut sc.regs, y);
    }
    fn observe_jac(
        &self,
        sw: &Switches,
        at: At<'_, Self::N, Self::P>,
        yx: &mut [f64],
        yp: &mut [f64],
    ) {
        let nobs = self.info.observables.len();
        let (n, np) = (self.n, self.p);
        if yx.len() < nobs * n || yp.len() < nobs * np {
            return;
        }
        let tape = &self.observe_jac;
        self.with(tape, &at_sw(at, sw), |ok, regs, _| {
            let fill = if ok { 0.0 } else { f64::NAN };
            yx.iter_mut().take(nobs * n).for_each(|v| *v = fill);
            yp.iter_mut().take(nobs * np).for_each(|v| *v = fill);
            if !ok {
                return;
            }
            for (s, r) in tape.outputs() {
                let slot = if s < nobs * n {
                    yx.get_mut(s)
                } else {
                    yp.get_mut(s - nobs * n)
                };
                if let Some(v) = slot {
                    *v = regs[r];
                }
            }
        });
    }

    fn running_cost(&self, sw: &Switches, at: At<'_, Self::N, Self::P>) -> f64 {
        match &self.running_cost {
            Some(c) => self.scalar(&c.value, &at_sw(at, sw)),
            None => 0.0,
        }
    }
    fn running_cost_value_grad(
        &self,
        sw: &Switches,
        at: At<'_, Self::N, Self::P>,
        lx: &mut X,
        lp: &mut X,
    ) -> f64 {
        match &self.running_cost {
            Some(c) => self.grad(c, &at_sw(at, sw), lx, lp),
            None => {
                lx.fill(0.0);
                lp.fill(0.0);
                0.0
            }
        }
    }
    fn event_cost(&self, occ: Occurrence, at: At<'_, Self::N, Self::P>) -> f64 {
        let Occurrence { event, j } = occ;
        let row = self.tables.row(event, j);
        match self.events.get(event).and_then(|e| e.cost.as_ref()) {
            Some(c) => self.scalar(&c.value, &pt_row(at, &row)),
            None => 0.0,
        }
    }
    fn event_cost_grad(
        &self,
        occ: Occurrence,
        at: At<'_, Self::N, Self::P>,
        cx: &mut X,
        cp: &mut X,
    ) -> f64 {
        let Occurrence { event, j } = occ;
        let row = self.tables.row(event, j);
        match self.events.get(event).and_then(|e| e.cost.as_ref()) {
            Some(c) => self.grad(c, &pt_row(at, &row), cx, cp),
            None => {
                cx.fill(0.0);
                cp.fill(0.0);
                0.0
            }
        }
    }
    fn final_cost(&self, at: At<'_, Self::N, Self::P>) -> f64 {
        match &self.final_cost {
            Some(c) => self.scalar(&c.value, &pt0(at)),
            None => 0.0,
        }
    }
    fn final_cost_grad(&self, at: At<'_, Self::N, Self::P>, cx: &mut X, cp: &mut X) -> f64 {
        match &self.final_cost {
            Some(c) => self.grad(c, &pt0(at), cx, cp),
            None => {
                cx.fill(0.0);
                cp.fill(0.0);
                0.0
            }
        }
    }

    fn qps(&self) -> &[QpLayerInfo] {
        &self.qp_info
    }
    fn qp_states(&self, at: At<'_, Self::N, Self::P>) -> Result<Vec<QpState>, (usize, QpError)> {
        self.evaluate_qps(&pt0(at), false);
        self.qp_bank.borrow().states()
    }
    fn set_qp_side(&self, side: Side) {
        self.qp_bank.borrow_mut().set_side(side);
    }
    fn qp_failure(&self) -> Option<(usize, QpError)> {
        self.qp_bank.borrow().failure().map(|(q, e)| (q, e.clone()))
    }
    fn qp_flow_pieces(
        &self,
        pt: mvad_runtime::Point<'_, Self::N, Self::P>,
        f: &X,
        s: Option<&M>,
        pieces: &mut [Switches],
    ) -> Option<bool> {
        let at = at_pt(pt);
        let Point { t, x, p, .. } = at.pt;
        let s = s.map(|s| s.as_slice());
        let fill = self.qp_fill(&at);
        let mut bank = self.qp_bank.borrow_mut();
        let found = bank.flow_pieces(t, x, p, pt.sw, f.as_slice(), s, pieces, fill);
        found.ok()
    }
    fn qp_flow_kinks(&self) -> Vec<QpFlowKink> {
        self.qp_bank.borrow().flow_kinks().to_vec()
    }
    fn clear_qp_flow_kinks(&self) {
        self.qp_bank.borrow_mut().clear_flow_kinks();
    }
    fn qp_piece(
        &self,
        q: usize,
        at: At<'_, Self::N, Self::P>,
        (dx, j, dt): (&X, usize, f64),
        active: &mut [bool],
    ) -> Option<bool> {
        let at = pt0(at);
        let Point { t, x, p, .. } = at.pt;
        let fill = self.qp_fill(&at);
        let mut bank = self.qp_bank.borrow_mut();
        let found = bank.pointwise_piece(q, (t, x, p), (dx.as_slice(), j, dt), active, fill);
        found.ok()
    }
    fn pin_qp(&self, q: usize, active: Option<&[bool]>) {
        self.qp_bank.borrow_mut().pin(q, active);
    }
}

impl ModelSens for InterpretedModel {
    fn rhs_sens(
        &self,
        pt: mvad_runtime::Point<'_, Self::N, Self::P>,
        s: &M,
        f: &mut X,
        ds: &mut M,
    ) {
        let mode = pt.mode;
        let Some(m) = self.mode(mode) else {
            f.fill(f64::NAN);
            ds.fill(f64::NAN);
            return;
        };
        let (n, np) = (self.n, self.p);
        let nnz = m.sparsity.len();
        if s.nrows() != n || s.ncols() != np || ds.nrows() != n || ds.ncols() != np {
            f.fill(f64::NAN);
            ds.fill(f64::NAN);
            return;
        }
        let mut sc = self.scratch.borrow_mut();
        let Scratch { regs, out, .. } = &mut *sc;
        let at = at_pt(pt);
        self.eval(&m.sens, &at, regs, out);
        copy_into(f.as_mut_slice(), &out[..n]);
        let fp = &out[n + nnz..n + nnz + n * np];
        for r in 0..n {
            for c in 0..np {
                ds[(r, c)] = fp[r * np + c];
            }
        }
        for (e, &(r, k)) in m.sparsity.iter().enumerate() {
            let a = out[n + e];
            for c in 0..np {
                ds[(r, c)] += a * s[(k, c)];
            }
        }
    }
}
