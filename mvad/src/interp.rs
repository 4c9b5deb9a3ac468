//! Models loaded at run time: [`InterpretedModel`] evaluates the same scheduled kernels
//! the `hybrid!` macro compiles, through `mvad_dsl::eval` tapes, with dynamic sizes.
//!
//! Each trait method runs one tape into a scratch register file kept in a `RefCell`, so
//! no call allocates. Matrices are written entry by entry from the tape's non-zero
//! outputs after one zero fill. [`ModelSens::rhs_sens`](mvad_runtime::ModelSens::rhs_sens)
//! is overridden with the fused kernel: f, the non-zero entries of f_x and f_θ in one pass, then
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
use mvad_dsl::schedule::{GradKernels, Kernel, ModelKernels};
use mvad_runtime::qp::{QpBank, QpLayerInfo, QpOptions};
use mvad_runtime::ModelInfo;
use nalgebra::{DMatrix, DVector};

use products::SecondTapes;
use tables::{Tables, TimeTapes};

mod model;
mod products;
mod run;
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
        let info = k.info();
        let all = k.all_kernels();
        let nregs = all.iter().map(|k| k.nodes.len()).max().unwrap_or(0);
        let nout = all.iter().map(|k| k.len).max().unwrap_or(0);
        let second = |so| SecondTapes::new(ar, so);
        let nw = (k.modes.iter().map(|m| &m.second))
            .chain(&k.running_cost_second)
            .map(|so| so.x_entries.len())
            .max()
            .unwrap_or(0);
        let qp_info: Vec<QpLayerInfo> = k.qps.iter().map(|q| q.info.clone()).collect();
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
}
