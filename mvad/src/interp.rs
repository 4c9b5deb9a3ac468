//! Models loaded at run time: [`InterpretedModel`] evaluates the same scheduled kernels
//! the `hybrid!` macro compiles, through `mvad_dsl::eval` tapes, with dynamic sizes.
//!
//! Each trait method runs one tape into a scratch register file kept in a `RefCell`, so
//! no call allocates. Matrices are written entry by entry from the tape's non-zero
//! outputs after one zero fill. [`HybridModel::rhs_sens`] is overridden with the fused
//! kernel: f, the non-zero entries of f_x and f_θ in one pass, then
//! Ṡ = f_θ + Σ_{(i,k) ∈ nz(f_x)} (f_x)_{ik} S_{k·}, the same sums in the same order as the
//! generated code.

use std::cell::RefCell;

use mvad_dsl::diag::Diagnostic;
use mvad_dsl::eval::Tape;
use mvad_dsl::ir::{self, Point};
use mvad_dsl::schedule::{GradKernels, Kernel, ModelKernels, TimeKind};
use mvad_runtime::{
    EventInfo, HybridModel, ModelAdjoint, ModelDims, ModelInfo, ModelSecondOrder, ModelSens,
    Switches, Trigger,
};

use crate::table::{bind_columns, Table, TableError, TableNeeds};
use nalgebra::{DMatrix, DVector, Dyn};

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
    sparsity: Vec<(usize, usize)>,
    depends_on_t: bool,
}

#[derive(Clone, Debug)]
struct EventTapes {
    guard: GradTapes,
    reset: Tape,
    reset_jac: Tape,
    cost: Option<GradTapes>,
    /// A time event's τ (or start) and ∂τ/∂θ, and for `every` the period and its gradient.
    time: Option<TimeTapes>,
    /// The table an `at each` event runs over.
    table: Option<usize>,
}

/// τ (or the start of `every`), ∂τ/∂θ, and for `every` the period and its gradient.
type TimeTapes = (Tape, Tape, Option<(Tape, Tape)>);

/// The data tables of a model: its declarations and the columns it reads, bound to data.
#[derive(Clone, Debug, Default)]
struct Tables {
    /// Declared (name, file).
    decls: Vec<(String, String)>,
    /// Columns read: (table, column name).
    names: Vec<(usize, String)>,
    /// Columns used bare as the times of an `at each` event: (column, event name).
    times: Vec<(usize, String)>,
    /// The bound values of each column (empty until [`InterpretedModel::bind_tables`]).
    values: Vec<Vec<f64>>,
}

#[derive(Clone, Debug)]
struct Scratch {
    regs: Vec<f64>,
    out: Vec<f64>,
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
    tables: Tables,
    scratch: RefCell<Scratch>,
    /// The current row's values of every column (scratch of the event methods).
    row: RefCell<Vec<f64>>,
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
            name: k.name.clone(),
            states: k.states.clone(),
            params: k.params.clone(),
            param_defaults: k.param_defaults.clone(),
            modes: k.mode_names.clone(),
            initial_mode: k.initial_mode,
            events: k
                .event_meta
                .iter()
                .map(|e| EventInfo {
                    name: e.name.clone(),
                    direction: match e.direction {
                        ir::Direction::Down => mvad_runtime::Direction::Down,
                        ir::Direction::Up => mvad_runtime::Direction::Up,
                    },
                    mode: e.mode,
                    target: e.target,
                    has_reset: e.has_reset,
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
            switches: k.switches.len(),
            has_running_cost: k.running_cost.is_some(),
            has_final_cost: k.final_cost.is_some(),
            has_horizon: k.horizon.is_some(),
            jacobian_sparsity: k.modes.iter().map(|m| m.sparsity.clone()).collect(),
        };
        let all = k.all_kernels();
        let nregs = all.iter().map(|k| k.nodes.len()).max().unwrap_or(0);
        let nout = all.iter().map(|k| k.len).max().unwrap_or(0);
        let mut model = InterpretedModel {
            n: k.nstates(),
            p: k.nparams(),
            x0: tape(&k.x0),
            x0_jac: tape(&k.x0_jac),
            horizon: k.horizon.as_ref().map(|(h, g)| (tape(h), tape(g))),
            modes: k
                .modes
                .iter()
                .map(|m| ModeTapes {
                    rhs: tape(&m.rhs),
                    jac_x: tape(&m.jac_x),
                    jac_p: tape(&m.jac_p),
                    dt: tape(&m.dt),
                    sens: tape(&m.sens),
                    sparsity: m.sparsity.clone(),
                    depends_on_t: m.depends_on_t,
                })
                .collect(),
            events: k
                .events
                .iter()
                .map(|e| EventTapes {
                    guard: grad(&e.guard),
                    reset: tape(&e.reset),
                    reset_jac: tape(&e.reset_jac),
                    cost: e.cost.as_ref().map(grad),
                    time: e.time.as_ref().map(|tk| {
                        let period = tk.period.as_ref().map(|(a, b)| (tape(a), tape(b)));
                        (tape(&tk.time), tape(&tk.time_grad), period)
                    }),
                    table: None,
                })
                .collect(),
            switches: k.switches.iter().map(grad).collect(),
            observe: tape(&k.observe),
            observe_jac: tape(&k.observe_jac),
            running_cost: k.running_cost.as_ref().map(grad),
            final_cost: k.final_cost.as_ref().map(grad),
            tables: Tables {
                decls: k.tables.clone(),
                names: k.columns.clone(),
                times: k
                    .bare_time_columns()
                    .into_iter()
                    .map(|(c, e)| (c, k.event_meta[e].name.clone()))
                    .collect(),
                values: Vec::new(),
            },
            scratch: RefCell::new(Scratch {
                regs: vec![0.0; nregs],
                out: vec![0.0; nout],
            }),
            row: RefCell::new(vec![f64::NAN; k.columns.len()]),
            info,
        };
        for (e, meta) in model.events.iter_mut().zip(&k.event_meta) {
            if let Some(TimeKind::Each { table }) = meta.time {
                e.table = Some(table);
            }
        }
        model
    }

    /// The declared tables: (name, file as written in the model).
    pub fn table_decls(&self) -> &[(String, String)] {
        &self.tables.decls
    }

    /// Binds the model's data: one table per declaration, in declaration order. Checks that
    /// the columns the model reads exist and that bare `at each` times do not decrease (errors
    /// located in the table's file), and sets the row counts of the `at each` events.
    pub fn bind_tables(&mut self, tables: &[&Table]) -> Result<(), TableError> {
        let t = &self.tables;
        let needs = TableNeeds {
            tables: t.decls.iter().map(|(n, _)| n.as_str()).collect(),
            columns: t.names.iter().map(|(i, c)| (*i, c.as_str())).collect(),
            times: t.times.iter().map(|(c, e)| (*c, e.as_str())).collect(),
        };
        let (values, rows) = bind_columns(&needs, tables)?;
        for (info, e) in self.info.events.iter_mut().zip(&self.events) {
            if let Some(table) = e.table {
                info.trigger = Trigger::Each {
                    rows: rows.get(table).copied().unwrap_or(0),
                };
            }
        }
        self.tables.values = values;
        Ok(())
    }

    /// Fills the row scratch with row `j` of the table of event `event` (NaN elsewhere).
    fn fill_row(&self, event: usize, j: usize) {
        let mut row = self.row.borrow_mut();
        let table = self.events.get(event).and_then(|e| e.table);
        for (c, v) in row.iter_mut().enumerate() {
            *v = match (table, self.tables.names.get(c), self.tables.values.get(c)) {
                (Some(t), Some((ct, _)), Some(col)) if *ct == t => {
                    col.get(j).copied().unwrap_or(f64::NAN)
                }
                _ => f64::NAN,
            };
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

    /// Runs `tape` and hands the registers and the dense output buffer to `f`.
    fn with<R>(
        &self,
        tape: &Tape,
        at: &At<'_>,
        f: impl FnOnce(bool, &[f64], &mut [f64]) -> R,
    ) -> R {
        let mut sc = self.scratch.borrow_mut();
        let Scratch { regs, out } = &mut *sc;
        let ok = tape.run_row(&at.pt, at.hi, at.row, regs);
        f(ok, regs, out)
    }

    /// Writes a vector kernel into `v` (dense, zeros included).
    fn vec_out(&self, tape: &Tape, at: &At<'_>, v: &mut X) {
        let mut sc = self.scratch.borrow_mut();
        tape.eval_row(&at.pt, at.hi, at.row, &mut sc.regs, v.as_mut_slice());
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

    fn mat(&self, tape: &Tape, at: &At<'_>, m: &mut M, cols: usize) {
        self.with(tape, at, |ok, regs, _| {
            Self::mat_out(tape, ok, regs, m, cols, 0)
        });
    }

    fn scalar(&self, tape: &Tape, at: &At<'_>) -> f64 {
        let mut sc = self.scratch.borrow_mut();
        let mut out = [0.0];
        tape.eval_row(&at.pt, at.hi, at.row, &mut sc.regs, &mut out);
        out[0]
    }

    /// Gradient kernel into `gx`, `gp`; returns the last slot.
    fn grad(&self, g: &GradTapes, at: &At<'_>, gx: &mut X, gp: &mut X) -> f64 {
        let (n, p) = (self.n, self.p);
        let mut sc = self.scratch.borrow_mut();
        let Scratch { regs, out } = &mut *sc;
        g.grad.eval_row(&at.pt, at.hi, at.row, regs, out);
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

/// An evaluation point for the tapes: [`Point`] carries switch bits 0..64, `hi` the rest,
/// `row` the current row's column values (event methods of `at each` events).
struct At<'a> {
    pt: Point<'a>,
    hi: &'a [u64],
    row: &'a [f64],
}

/// The point (t, x, θ) under the frozen branches `sw` (flows and ℓ).
fn at_sw<'a>(t: f64, x: &'a X, p: &'a X, sw: &'a Switches) -> At<'a> {
    At {
        pt: Point {
            t,
            x: x.as_slice(),
            p: p.as_slice(),
            sw: sw.low_word(),
        },
        hi: sw.high_words(),
        row: &[],
    }
}

/// The point (t, x, θ) for pointwise functions (no frozen branches).
fn pt0<'a>(t: f64, x: &'a X, p: &'a X) -> At<'a> {
    At {
        pt: Point {
            t,
            x: x.as_slice(),
            p: p.as_slice(),
            sw: 0,
        },
        hi: &[],
        row: &[],
    }
}

/// The point (t, x, θ) at a table row, for the reset and event cost of an event.
fn pt_row<'a>(t: f64, x: &'a X, p: &'a X, row: &'a [f64]) -> At<'a> {
    At {
        row,
        ..pt0(t, x, p)
    }
}

/// The point for functions of θ alone (x₀, T).
fn pt_theta(p: &X) -> At<'_> {
    At {
        pt: Point {
            t: 0.0,
            x: &[],
            p: p.as_slice(),
            sw: 0,
        },
        hi: &[],
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
        let mvad_runtime::Point { mode, sw, t, x, p } = pt;
        match self.mode(mode) {
            Some(m) => self.vec_out(&m.rhs, &at_sw(t, x, p, sw), f),
            None => f.fill(f64::NAN),
        }
    }
    fn rhs_jac_x(&self, pt: mvad_runtime::Point<'_, Self::N, Self::P>, fx: &mut M) {
        let mvad_runtime::Point { mode, sw, t, x, p } = pt;
        match self.mode(mode) {
            Some(m) => self.mat(&m.jac_x, &at_sw(t, x, p, sw), fx, self.n),
            None => fx.fill(f64::NAN),
        }
    }
    fn rhs_jac_p(&self, pt: mvad_runtime::Point<'_, Self::N, Self::P>, fp: &mut M) {
        let mvad_runtime::Point { mode, sw, t, x, p } = pt;
        match self.mode(mode) {
            Some(m) => self.mat(&m.jac_p, &at_sw(t, x, p, sw), fp, self.p),
            None => fp.fill(f64::NAN),
        }
    }
    fn rhs_dt(&self, pt: mvad_runtime::Point<'_, Self::N, Self::P>, ft: &mut X) {
        let mvad_runtime::Point { mode, sw, t, x, p } = pt;
        match self.mode(mode) {
            Some(m) if m.depends_on_t => self.vec_out(&m.dt, &at_sw(t, x, p, sw), ft),
            Some(_) => ft.fill(0.0),
            None => ft.fill(f64::NAN),
        }
    }
    fn rhs_depends_on_t(&self, mode: usize) -> bool {
        self.mode(mode).is_some_and(|m| m.depends_on_t)
    }

    fn guard(&self, event: usize, t: f64, x: &X, p: &X) -> f64 {
        match self.events.get(event) {
            Some(e) => self.scalar(&e.guard.value, &pt0(t, x, p)),
            None => f64::NAN,
        }
    }
    fn guard_grad(&self, event: usize, t: f64, x: &X, p: &X, gx: &mut X, gp: &mut X) -> f64 {
        match self.events.get(event) {
            Some(e) => self.grad(&e.guard, &pt0(t, x, p), gx, gp),
            None => {
                gx.fill(f64::NAN);
                gp.fill(f64::NAN);
                f64::NAN
            }
        }
    }
    fn reset(&self, event: usize, j: usize, t: f64, x: &X, p: &X, xplus: &mut X) {
        self.fill_row(event, j);
        let row = self.row.borrow();
        match self.events.get(event) {
            Some(e) => self.vec_out(&e.reset, &pt_row(t, x, p, &row), xplus),
            None => xplus.fill(f64::NAN),
        }
    }
    #[allow(clippy::too_many_arguments)]
    fn reset_jac(
        &self,
        event: usize,
        j: usize,
        t: f64,
        x: &X,
        p: &X,
        rx: &mut M,
        rp: &mut M,
        rt: &mut X,
    ) {
        let Some(e) = self.events.get(event) else {
            rx.fill(f64::NAN);
            rp.fill(f64::NAN);
            rt.fill(f64::NAN);
            return;
        };
        let (n, np) = (self.n, self.p);
        let tape = &e.reset_jac;
        self.fill_row(event, j);
        let row = self.row.borrow();
        self.with(tape, &pt_row(t, x, p, &row), |ok, regs, out| {
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

    fn event_time(&self, event: usize, j: usize, p: &X) -> f64 {
        let Some((tau, _, period)) = self.events.get(event).and_then(|e| e.time.as_ref()) else {
            return f64::NAN;
        };
        self.fill_row(event, j);
        let row = self.row.borrow();
        let at = At {
            row: &row,
            ..pt_theta(p)
        };
        let first = self.scalar(tau, &at);
        match period {
            Some((per, _)) => first + j as f64 * self.scalar(per, &at),
            None => first,
        }
    }
    fn event_time_grad(&self, event: usize, j: usize, p: &X, dtau: &mut X) {
        let Some((_, grad, period)) = self.events.get(event).and_then(|e| e.time.as_ref()) else {
            dtau.fill(f64::NAN);
            return;
        };
        self.fill_row(event, j);
        let row = self.row.borrow();
        let at = At {
            row: &row,
            ..pt_theta(p)
        };
        self.vec_out(grad, &at, dtau);
        if let Some((_, per_grad)) = period {
            let mut sc = self.scratch.borrow_mut();
            let Scratch { regs, out } = &mut *sc;
            per_grad.eval_row(&at.pt, at.hi, at.row, regs, out);
            for (d, g) in dtau.iter_mut().zip(out.iter()) {
                *d += j as f64 * g;
            }
        }
    }

    fn switch_value(&self, j: usize, t: f64, x: &X, p: &X) -> f64 {
        match self.switches.get(j) {
            Some(s) => self.scalar(&s.value, &pt0(t, x, p)),
            None => f64::NAN,
        }
    }
    fn switch_grad(&self, j: usize, t: f64, x: &X, p: &X, gx: &mut X, gp: &mut X) -> f64 {
        match self.switches.get(j) {
            Some(s) => self.grad(s, &pt0(t, x, p), gx, gp),
            None => {
                gx.fill(f64::NAN);
                gp.fill(f64::NAN);
                f64::NAN
            }
        }
    }

    fn observe(&self, t: f64, x: &X, p: &X, y: &mut [f64]) {
        if y.len() < self.info.observables.len() {
            return;
        }
        let mut sc = self.scratch.borrow_mut();
        let at = pt0(t, x, p);
        self.observe.eval_with(&at.pt, at.hi, &mut sc.regs, y);
    }
    fn observe_jac(&self, t: f64, x: &X, p: &X, yx: &mut [f64], yp: &mut [f64]) {
        let nobs = self.info.observables.len();
        let (n, np) = (self.n, self.p);
        if yx.len() < nobs * n || yp.len() < nobs * np {
            return;
        }
        let tape = &self.observe_jac;
        self.with(tape, &pt0(t, x, p), |ok, regs, _| {
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

    fn running_cost(&self, sw: &Switches, t: f64, x: &X, p: &X) -> f64 {
        match &self.running_cost {
            Some(c) => self.scalar(&c.value, &at_sw(t, x, p, sw)),
            None => 0.0,
        }
    }
    fn running_cost_value_grad(
        &self,
        sw: &Switches,
        t: f64,
        x: &X,
        p: &X,
        lx: &mut X,
        lp: &mut X,
    ) -> f64 {
        match &self.running_cost {
            Some(c) => self.grad(c, &at_sw(t, x, p, sw), lx, lp),
            None => {
                lx.fill(0.0);
                lp.fill(0.0);
                0.0
            }
        }
    }
    fn event_cost(&self, event: usize, j: usize, t: f64, x: &X, p: &X) -> f64 {
        self.fill_row(event, j);
        let row = self.row.borrow();
        match self.events.get(event).and_then(|e| e.cost.as_ref()) {
            Some(c) => self.scalar(&c.value, &pt_row(t, x, p, &row)),
            None => 0.0,
        }
    }
    #[allow(clippy::too_many_arguments)]
    fn event_cost_grad(
        &self,
        event: usize,
        j: usize,
        t: f64,
        x: &X,
        p: &X,
        cx: &mut X,
        cp: &mut X,
    ) -> f64 {
        self.fill_row(event, j);
        let row = self.row.borrow();
        match self.events.get(event).and_then(|e| e.cost.as_ref()) {
            Some(c) => self.grad(c, &pt_row(t, x, p, &row), cx, cp),
            None => {
                cx.fill(0.0);
                cp.fill(0.0);
                0.0
            }
        }
    }
    fn final_cost(&self, t: f64, x: &X, p: &X) -> f64 {
        match &self.final_cost {
            Some(c) => self.scalar(&c.value, &pt0(t, x, p)),
            None => 0.0,
        }
    }
    fn final_cost_grad(&self, t: f64, x: &X, p: &X, cx: &mut X, cp: &mut X) -> f64 {
        match &self.final_cost {
            Some(c) => self.grad(c, &pt0(t, x, p), cx, cp),
            None => {
                cx.fill(0.0);
                cp.fill(0.0);
                0.0
            }
        }
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
        let mvad_runtime::Point { mode, sw, t, x, p } = pt;
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
        let Scratch { regs, out } = &mut *sc;
        let at = at_sw(t, x, p, sw);
        m.sens.eval_with(&at.pt, at.hi, regs, out);
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

impl ModelAdjoint for InterpretedModel {}
impl ModelSecondOrder for InterpretedModel {}
