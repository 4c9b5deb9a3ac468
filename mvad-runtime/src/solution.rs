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
    pub const ALL: [Method; 4] = [Method::Auto, Method::Tsit5, Method::Verner9, Method::Rosenbrock];
    /// Parses a command-line name.
    pub fn from_name(name: &str) -> Option<Method> {
        Self::ALL.into_iter().find(|m| m.name() == name)
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
    /// The run stops with a `max_events` diagnostic after this many events.
    pub max_events: usize,
    /// Put the sensitivities (and cost quadratures) under error control too.
    pub sens_error_control: bool,
    /// Compute sensitivities at all (false: primal simulation only).
    pub sensitivities: bool,
    /// Keep every accepted step with its dense output (for trajectories and measures).
    pub record: bool,
    /// Events closer than this (relative to the horizon) count as simultaneous.
    pub simultaneous_tol: f64,
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
            sens_error_control: false,
            sensitivities: true,
            record: false,
            simultaneous_tol: 1e-12,
        }
    }
}

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
    /// Two or more events fired at the same time (within `Options::simultaneous_tol`).
    SimultaneousEvents,
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
            DiagnosticKind::SimultaneousEvents => "simultaneous_events",
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
    /// ∇ₓg · f⁻ at t_k⁻ (signed).
    pub guard_slope: f64,
    /// ∂ₜg at t_k (zero for time-independent guards); t_k' divides by guard_slope + guard_dt.
    pub guard_dt: f64,
    /// Whether the crossing passed the transversality (cosine) test.
    pub transversal: bool,
    /// t_k' = dt_k/dθ, one per parameter.
    pub dt: Vec<f64>,
    /// x(t_k⁻).
    pub x_before: Vec<f64>,
    /// x(t_k⁺).
    pub x_after: Vec<f64>,
    /// J_k per state: x(t_k⁺) − x(t_k⁻).
    pub jump_states: Vec<f64>,
    /// J_k per observable: y(t_k⁺) − y(t_k⁻).
    pub jump_observables: Vec<f64>,
    /// α_k = −J_k t_k': `atoms[i][j]` for observable i and parameter j.
    pub atoms: Vec<Vec<f64>>,
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
}
