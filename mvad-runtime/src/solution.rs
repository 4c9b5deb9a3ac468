//! What a run returns: the cost, dC/dθ, the event table with the measure's atoms,
//! diagnostics and statistics; and the options that steer it.
//!
//! These are the types the command line and the library print. They use plain `Vec`s
//! (not the model's type-level dimensions) so a caller can hold results of compiled and
//! loaded models alike.

/// Integration method.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Method {
    /// Start explicit (Tsitouras 5(4)); switch to the implicit method when stiffness is detected.
    #[default]
    Auto,
    /// Tsitouras 5(4), explicit, FSAL, 4th-order dense output.
    Tsit5,
    /// Verner 9(8), explicit, for tight tolerances.
    Verner9,
    /// Rosenbrock (Rodas-type), linearly implicit, for stiff models; uses the symbolic Jacobian.
    Rosenbrock,
}

impl Method {
    /// The name used on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Method::Auto => "auto",
            Method::Tsit5 => "tsit5",
            Method::Verner9 => "verner9",
            Method::Rosenbrock => "rosenbrock",
        }
    }
    /// All methods, for option parsing and help texts.
    pub const ALL: [Method; 4] = [
        Method::Auto,
        Method::Tsit5,
        Method::Verner9,
        Method::Rosenbrock,
    ];
    /// Parses a command-line name.
    pub fn from_name(name: &str) -> Option<Method> {
        Self::ALL.into_iter().find(|m| m.name() == name)
    }
}

/// How dC/dθ is computed: forward sensitivities carried along the run, or one backward
/// (adjoint) sweep after a primal run (see [`crate::adjoint`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum GradientMode {
    /// Forward sensitivities S = ∂x/∂θ: O(n·p) work per step; every forward quantity
    /// (t_k', atoms, S(T), the measure) is available.
    #[default]
    Forward,
    /// A primal run that records the trajectory, then λ integrated from T down to 0: work per
    /// step O(n² + p) (with sparse vector–Jacobian products), memory O(steps · n).
    Adjoint,
    /// Adjoint when the model has at least [`GradientMode::AUTO_ADJOINT_MIN_PARAMS`]
    /// parameters, forward otherwise.
    Auto,
}

impl GradientMode {
    /// `auto` picks the adjoint from this many parameters on: where the adjoint overtook
    /// forward mode in the `adjoint` benchmark (`models/benches/adjoint.rs`) on the model
    /// whose flow does not grow with p (between p = 20 and 100 at rtol 1e-8; on a model whose
    /// flow sums p terms it did not overtake up to p = 1000: `docs/report/adjoint-scaling.md`).
    pub const AUTO_ADJOINT_MIN_PARAMS: usize = 50;

    /// The name used on the command line and in `stats.mode`.
    pub fn name(self) -> &'static str {
        match self {
            GradientMode::Forward => "forward",
            GradientMode::Adjoint => "adjoint",
            GradientMode::Auto => "auto",
        }
    }
    /// Parses a command-line name.
    pub fn from_name(name: &str) -> Option<GradientMode> {
        [
            GradientMode::Forward,
            GradientMode::Adjoint,
            GradientMode::Auto,
        ]
        .into_iter()
        .find(|m| m.name() == name)
    }
    /// The mode a run with `p` parameters uses: `Auto` resolved, the others as they are.
    pub fn resolve(self, p: usize) -> GradientMode {
        match self {
            GradientMode::Auto if p >= Self::AUTO_ADJOINT_MIN_PARAMS => GradientMode::Adjoint,
            GradientMode::Auto => GradientMode::Forward,
            m => m,
        }
    }
}

/// Options of one run.
#[derive(Clone, Debug, PartialEq)]
pub struct Options {
    /// Integration method.
    pub method: Method,
    /// Relative tolerance.
    pub rtol: f64,
    /// Absolute tolerance.
    pub atol: f64,
    /// Overrides the model's horizon (then dT/dθ = 0).
    pub t_end: Option<f64>,
    /// τ of the grazing test |g_x f⁻| < τ |g_x| |f⁻|.
    pub grazing_tol: f64,
    /// The run stops with a `max_events` diagnostic after this many events (time events, and
    /// one state event or switch crossing per time event, not counted: their number is the
    /// schedule's, bounded by `max_periodic_occurrences` and the tables' rows).
    pub max_events: usize,
    /// The run stops with a `max_steps` error after this many step attempts (accepted and
    /// rejected, over the whole run): an explicit method on a stiff model would otherwise
    /// take ~10⁸ steps. The default, 10⁶, is ~700× the most any example model needs at
    /// rtol 1e-12 (`stiff_relay.hyb` under `auto`: ~1,500 attempts). Each event of an `at each`
    /// table, `every` sample or `at` event adds 100 attempts, so a run over a long schedule is
    /// not cut short.
    pub max_steps: usize,
    /// An `every` event with more occurrences than this before T is bad input
    /// ([`crate::error::SolveError::BadSchedule`]): time events count against neither
    /// `max_events` nor `max_steps`, so this bounds a run whose period was given far too short
    /// (the default 10⁹; the fuzz target sets a small one).
    pub max_periodic_occurrences: usize,
    /// Put the sensitivities (and cost quadratures) under error control too, column j
    /// weighted by |θ_j| (on by default: a step size chosen for x alone can leave S wrong
    /// at every tolerance, e.g. a stiff lag whose S_τ ~ 1/τ is resolved only near events).
    pub sens_error_control: bool,
    /// Carry a global error estimate along the run (the steps' local error estimates
    /// transported to T by the linearised flow) and raise an `ill_conditioned` diagnostic when
    /// it exceeds what the tolerances ask for by more than [`ILL_CONDITIONED_FACTOR`] (on by
    /// default: local error control bounds each step's error, not the error at T).
    pub global_error: bool,
    /// Compute sensitivities at all (false: primal simulation only).
    pub sensitivities: bool,
    /// Keep every accepted step with its dense output (for trajectories and measures).
    pub record: bool,
    /// Events closer than this (relative to the horizon) count as simultaneous.
    pub simultaneous_tol: f64,
    /// The most memory the adjoint's record of a run may take (2 GiB by default). A run whose
    /// record grows past it (10⁷ events of a small model take about 4 GB) stops recording and
    /// is computed in forward mode, whose memory does not grow with the number of events (a
    /// `record_budget` diagnostic says so).
    pub max_record_bytes: usize,
    /// How dC/dθ is computed (when `sensitivities` is set); [`Stats::mode`] says which mode
    /// a run used. Adjoint runs leave out the forward quantities: the events' `dt` (and so
    /// their atoms), [`Solution::s_final`], and S in a recorded trajectory.
    pub gradient_mode: GradientMode,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            method: Method::Auto,
            rtol: 1e-8,
            atol: 1e-10,
            t_end: None,
            grazing_tol: 1e-3,
            max_events: 100_000,
            max_steps: 1_000_000,
            max_periodic_occurrences: 1_000_000_000,
            max_record_bytes: 2 << 30,
            sens_error_control: true,
            global_error: true,
            sensitivities: true,
            record: false,
            simultaneous_tol: 1e-12,
            gradient_mode: GradientMode::Forward,
        }
    }
}

/// An `ill_conditioned` diagnostic is raised when the run's global error estimate of C or of
/// dC/dθ exceeds this many times the tolerance atol + rtol·|value| (the estimate is usually an
/// overestimate by 10 to 200×, so the true error then exceeds the tolerance severalfold).
pub const ILL_CONDITIONED_FACTOR: f64 = 1e3;

/// Kinds of diagnostics (the spec's names).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum DiagnosticKind {
    /// |g_x f⁻| < τ |g_x| |f⁻| at an event: the event-time sensitivity is ill-conditioned.
    Grazing,
    /// Events accumulate; the run ended at the estimated accumulation time.
    Zeno,
    /// The run stopped after `Options::max_events` events.
    MaxEvents,
    /// The step size fell below what the floating-point resolution of t allows.
    StepSizeUnderflow,
    /// A NaN or infinity appeared.
    Nonfinite,
    /// The run stopped after `Options::max_steps` step attempts.
    MaxSteps,
    /// Two or more events fired at the same time (within `Options::simultaneous_tol`).
    SimultaneousEvents,
    /// A qp constraint is weakly active (slack and multiplier both zero): the solution map
    /// has a kink, and the gradient is one-sided.
    Kink,
    /// The global error estimate of C or dC/dθ exceeds [`ILL_CONDITIONED_FACTOR`] times the
    /// tolerance: the steps' errors reach T amplified (or not damped), so local error control
    /// does not bound the answer's error.
    IllConditioned,
    /// The adjoint's record of the run passed [`Options::max_record_bytes`]: the gradient was
    /// computed in forward mode instead.
    RecordBudget,
}

impl DiagnosticKind {
    /// The spec's name (`grazing`, `zeno`, ...).
    pub fn name(self) -> &'static str {
        match self {
            DiagnosticKind::Grazing => "grazing",
            DiagnosticKind::Zeno => "zeno",
            DiagnosticKind::MaxEvents => "max_events",
            DiagnosticKind::StepSizeUnderflow => "step_size_underflow",
            DiagnosticKind::Nonfinite => "nonfinite",
            DiagnosticKind::MaxSteps => "max_steps",
            DiagnosticKind::SimultaneousEvents => "simultaneous_events",
            DiagnosticKind::Kink => "kink",
            DiagnosticKind::IllConditioned => "ill_conditioned",
            DiagnosticKind::RecordBudget => "record_budget",
        }
    }
}

/// A numerical warning or failure, with the time it refers to.
#[derive(Clone, Debug, PartialEq)]
pub struct Diagnostic {
    /// What happened.
    pub kind: DiagnosticKind,
    /// When.
    pub t: f64,
    /// Human-readable detail (which event, which expression, estimates).
    pub message: String,
}

/// One event that fired, with everything the measure needs.
#[derive(Clone, Debug, PartialEq)]
pub struct EventRecord {
    /// Position in the run's event sequence (0, 1, ...).
    pub index: usize,
    /// Index of the event in `ModelInfo::events`.
    pub event: usize,
    /// t_k.
    pub t: f64,
    /// Mode before the event.
    pub mode_before: usize,
    /// Mode after the event.
    pub mode_after: usize,
    /// The total rate of the guard at t_k⁻, dg/dt = ∇ₓg · f⁻ + ∂ₜg (signed): what t_k' divides
    /// by and what the grazing test measures (a pure time guard `t >= p` has slope 1).
    pub guard_slope: f64,
    /// ∂ₜg at t_k (zero for time-independent guards), the part of `guard_slope` not along f.
    pub guard_dt: f64,
    /// Whether the crossing passed the transversality (cosine) test.
    pub transversal: bool,
    /// t_k' = dt_k/dθ, one per parameter (empty without forward sensitivities: a primal run
    /// or an adjoint one).
    pub dt: Vec<f64>,
    /// x(t_k⁻).
    pub x_before: Vec<f64>,
    /// x(t_k⁺).
    pub x_after: Vec<f64>,
    /// J_k per state: x(t_k⁺) − x(t_k⁻).
    pub jump_states: Vec<f64>,
    /// J_k per observable: y(t_k⁺) − y(t_k⁻).
    pub jump_observables: Vec<f64>,
    /// α_k = −J_k t_k': `atoms[i][j]` for observable i and parameter j (rows empty when `dt`
    /// is).
    pub atoms: Vec<Vec<f64>>,
}

/// The run's global error estimate at T (see `integrate/global_error.rs`): absolute errors,
/// usually an overestimate of the true ones.
#[derive(Clone, Debug, PartialEq)]
pub struct ErrorEstimate {
    /// Estimated error of C.
    pub cost: f64,
    /// Estimated error of dC/dθ, per parameter (empty without sensitivities).
    pub gradient: Vec<f64>,
    /// |error of C| / (atol + rtol |C|).
    pub cost_ratio: f64,
    /// max_j w_j |error of dC/dθ_j| / (atol + rtol max_j w_j |dC/dθ_j|), the larger of its
    /// values with w_j = |θ_j| (1 for θ_j = 0; the weighting of the sensitivities' error
    /// control) and w_j = 1 (0 without sensitivities). In adjoint mode the gradient is the
    /// VJP the sweep returned.
    pub gradient_ratio: f64,
}

/// Work counters.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Stats {
    /// Accepted steps.
    pub steps: usize,
    /// Rejected steps.
    pub rejected_steps: usize,
    /// Events that fired (switch crossings of non-smooth flows not included).
    pub events: usize,
    /// Zero crossings of switching functions (kinks of abs/min/max/sign/if).
    pub switch_crossings: usize,
    /// Right-hand-side evaluations.
    pub rhs_evals: usize,
    /// Jacobian evaluations (implicit method).
    pub jac_evals: usize,
    /// LU factorisations (implicit method).
    pub factorizations: usize,
    /// Wall time of the run in seconds.
    pub wall_seconds: f64,
    /// How the gradient was computed (an adjoint run that falls back says `Forward`). The
    /// counters of an adjoint run add the backward sweep's steps to the primal run's.
    pub mode: GradientMode,
    /// Bytes of the forward record an adjoint run kept for its sweep (0 in forward mode);
    /// see [`crate::adjoint::record`] for what a step and a jump cost.
    pub record_bytes: usize,
}

/// The result of [`crate::solve::solve`]: cost, dC/dθ, the event table (with the measure's
/// atoms), diagnostics, work counters and, with `Options::record`, the trajectory.
#[derive(Clone, Debug, PartialEq)]
pub struct Solution {
    /// The horizon T the cost refers to.
    pub t_end: f64,
    /// dT/dθ, one entry per parameter: the horizon's gradient when T comes from the model's
    /// `horizon` (zeros when `Options::t_end` fixes it or the horizon reads no param).
    pub dt_end: Vec<f64>,
    /// The parameter values of the run.
    pub params: Vec<f64>,
    /// C(θ) = ∫₀ᵀ ℓ dt + Σ_k φ_k + Φ(T, x(T)).
    pub cost: f64,
    /// dC/dθ, one entry per parameter (empty when `Options::sensitivities` is false). At a
    /// qp kink, the derivative from the right (θ → θ⁺ along each parameter).
    pub gradient: Vec<f64>,
    /// The derivative from the left, when a qp of the model is at a kink (a `kink`
    /// diagnostic); `gradient` is then the right one.
    pub gradient_left: Option<Vec<f64>>,
    /// Each qp of the model solved at (T, x(T), θ), in declaration order.
    pub qp: Vec<crate::qp::QpState>,
    /// x(T) (after a Zeno accumulation: the limit state x*).
    pub x_final: Vec<f64>,
    /// ∂x(T)/∂θ, column-major n×p (empty without forward sensitivities).
    pub s_final: Vec<f64>,
    /// The mode at T.
    pub mode_final: usize,
    /// The user events that fired, in time order (switch crossings are not listed).
    pub events: Vec<EventRecord>,
    /// Warnings of a run that finished (grazing, zeno, simultaneous_events, ill_conditioned).
    pub diagnostics: Vec<Diagnostic>,
    /// The global error estimate of the run (`Options::global_error`), if it was carried.
    pub error_estimate: Option<ErrorEstimate>,
    /// Work counters.
    pub stats: Stats,
    /// Dense record of x and S when `Options::record` was set.
    pub trajectory: Option<Trajectory>,
}

/// Nodes per recorded step: x and S are stored at `TRAJ_NODES` equispaced points of each
/// accepted step and interpolated by the degree-4 polynomial through them (the same order
/// as the methods' dense output).
pub const TRAJ_NODES: usize = 5;

/// A smooth piece of the run between two events (or switch crossings).
#[derive(Clone, Debug, PartialEq)]
pub struct Segment {
    /// Start time (an event time or 0).
    pub t_start: f64,
    /// End time (the next event time or T).
    pub t_end: f64,
    /// The mode on the segment.
    pub mode: usize,
    /// The frozen switch bits on the segment.
    pub switches: crate::model::Switches,
    /// Range of step indices `first_step..end_step` covering the segment.
    pub first_step: usize,
    /// One past the last step index.
    pub end_step: usize,
}

impl Solution {
    /// The first diagnostic of `kind` the run raised, if any.
    pub fn diagnostic(&self, kind: DiagnosticKind) -> Option<&Diagnostic> {
        self.diagnostics.iter().find(|d| d.kind == kind)
    }
}

/// The recorded trajectory: x(t) and S(t) = ∂x/∂θ on every accepted step.
///
/// Each step [t₀, t₁] keeps x and S at [`TRAJ_NODES`] equispaced nodes, filled from the
/// integrator's dense output; [`Trajectory::sample`] evaluates the interpolating polynomial.
/// The record is right-continuous at user events: at an event time t_k it returns the
/// post-event state x(t_k⁺), S(t_k⁺) (the step that *starts* at t_k); at T the last step's
/// end. At a switch crossing of a kink (x continuous, S and the bits jump) it returns the
/// left limit x(t_c), S(t_c⁻) with the bits of the segment that ends there
/// ([`Trajectory::step_for`]), the value at t_c⁻ of an observable that jumps there.
#[derive(Clone, Debug, PartialEq)]
pub struct Trajectory {
    /// Number of states n.
    pub n: usize,
    /// Number of parameters p in S (0 when run without sensitivities).
    pub p: usize,
    /// Start times of the steps.
    pub t0: Vec<f64>,
    /// End times of the steps.
    pub t1: Vec<f64>,
    /// Segments between events, in time order.
    pub segments: Vec<Segment>,
    /// Node data, per step `TRAJ_NODES × (n + n·p)` values: x then S (column-major) per node.
    pub data: Vec<f64>,
    /// The switch crossings of kinks, in time order (what the measure's atoms of an
    /// observable that jumps at a crossing need).
    pub crossings: Vec<SwitchCrossing>,
}

/// A switch crossing of a kink as a recording run keeps it: switching function σ_j reached
/// zero at t, x is continuous there and the bits flip. An observable y = h(sw, t, x, θ) that
/// reads bit j jumps by J = h(after) − h(before), and its measure has the atom α = −J t'
/// there, t' = −(∇ₓσ_j·S⁻ + ∂θσ_j)/σ̇_j (the crossing-time sensitivity the run computed).
#[derive(Clone, Debug, PartialEq)]
pub struct SwitchCrossing {
    /// Crossing time t_c.
    pub t: f64,
    /// Index j of the switching function.
    pub switch: usize,
    /// x(t_c).
    pub x: Vec<f64>,
    /// t' = dt_c/dθ (empty when the run had no sensitivities).
    pub dt: Vec<f64>,
    /// The bits before the crossing.
    pub before: crate::model::Switches,
    /// The bits after it.
    pub after: crate::model::Switches,
}

impl Trajectory {
    /// An empty record for n states and p parameters.
    pub fn new(n: usize, p: usize) -> Self {
        Trajectory {
            n,
            p,
            t0: Vec::new(),
            t1: Vec::new(),
            segments: Vec::new(),
            data: Vec::new(),
            crossings: Vec::new(),
        }
    }

    /// The step a sample at t reads: [`Trajectory::step_at`] (right-continuous), except at
    /// the time of a switch crossing, where the step that ends there (the left limit: x is
    /// continuous, S and the bits are those before the flip).
    pub fn step_for(&self, t: f64) -> Option<usize> {
        let k = self.step_at(t)?;
        let at_crossing = k > 0
            && self.t0[k] == t
            && self.t1[k - 1] == t
            && self
                .crossings
                .binary_search_by(|c| c.t.total_cmp(&t))
                .is_ok();
        Some(if at_crossing { k - 1 } else { k })
    }

    /// The frozen switch bits of the segment that holds step k (empty bits for a step outside
    /// every segment, which a finished run never has).
    pub fn switches_of_step(&self, k: usize) -> &crate::model::Switches {
        static NONE: std::sync::OnceLock<crate::model::Switches> = std::sync::OnceLock::new();
        let i = self.segments.partition_point(|s| s.end_step <= k);
        match self.segments.get(i) {
            Some(s) if s.first_step <= k => &s.switches,
            _ => NONE.get_or_init(crate::model::Switches::default),
        }
    }

    /// Values stored per node (x then S).
    pub fn node_len(&self) -> usize {
        self.n + self.n * self.p
    }

    /// Number of recorded steps.
    pub fn len(&self) -> usize {
        self.t0.len()
    }

    /// Whether no step was recorded.
    pub fn is_empty(&self) -> bool {
        self.t0.is_empty()
    }

    /// End times of the accepted steps (the integrator's grid).
    pub fn step_times(&self) -> &[f64] {
        &self.t1
    }

    /// The step that holds t (right-continuous: the last step with t₀ ≤ t), clamped to the
    /// first/last step outside [0, T]. `None` when nothing was recorded.
    pub fn step_at(&self, t: f64) -> Option<usize> {
        if self.t0.is_empty() {
            return None;
        }
        let i = self.t0.partition_point(|&s| s <= t);
        Some(i.saturating_sub(1))
    }

    /// Lagrange weights of the equispaced nodes at θ = (t − t₀)/(t₁ − t₀).
    pub fn weights(theta: f64) -> [f64; TRAJ_NODES] {
        let m = (TRAJ_NODES - 1) as f64;
        let mut w = [1.0; TRAJ_NODES];
        for (i, wi) in w.iter_mut().enumerate() {
            let ti = i as f64 / m;
            for j in 0..TRAJ_NODES {
                if j != i {
                    let tj = j as f64 / m;
                    *wi *= (theta - tj) / (ti - tj);
                }
            }
        }
        w
    }

    /// The [`Trajectory::weights`] at t on the step [a, b]: θ = (t − a)/(b − a) clamped to
    /// [0, 1], and θ = 0 on a step of zero length.
    pub fn weights_on(a: f64, b: f64, t: f64) -> [f64; TRAJ_NODES] {
        let theta = if b > a {
            ((t - a) / (b - a)).clamp(0.0, 1.0)
        } else {
            0.0
        };
        Self::weights(theta)
    }

    /// x(t) and S(t) into `x` (length n) and `s` (length n·p, column-major); see the type's
    /// doc for which side of an event is returned. Returns false when nothing was recorded.
    pub fn sample_into(&self, t: f64, x: &mut [f64], s: &mut [f64]) -> bool {
        let Some(k) = self.step_for(t) else {
            return false;
        };
        let w = Self::weights_on(self.t0[k], self.t1[k], t);
        let len = self.node_len();
        let base = k * TRAJ_NODES * len;
        x.fill(0.0);
        s.fill(0.0);
        for (i, wi) in w.iter().enumerate() {
            let node = &self.data[base + i * len..base + (i + 1) * len];
            for (xv, nv) in x.iter_mut().zip(&node[..self.n]) {
                *xv += wi * nv;
            }
            for (sv, nv) in s.iter_mut().zip(&node[self.n..]) {
                *sv += wi * nv;
            }
        }
        true
    }

    /// x(t) and S(t) (column-major n×p) as new vectors; empty when nothing was recorded.
    pub fn sample(&self, t: f64) -> (Vec<f64>, Vec<f64>) {
        let mut x = vec![0.0; self.n];
        let mut s = vec![0.0; self.n * self.p];
        if !self.sample_into(t, &mut x, &mut s) {
            return (Vec::new(), Vec::new());
        }
        (x, s)
    }
}
