//! The static description of a hybrid model: its names, its events and its qp layers.
//!
//! These are plain data, with no dependency: the front end (`mvad-dsl`) builds them from a
//! checked model and the runtime (`mvad-runtime`, which re-exports every item here at its
//! own paths) reads them, so the two crates declare each concept once and the back ends
//! hand the front end's value to the runtime as it is. A model with n states, p parameters
//! and modes m = 0, 1, … has events k = 0, 1, … (top-level and in-mode events share one
//! index space) whose guards g_k(t, x, θ) fire when they cross zero in their
//! [`Direction`], and qp layers min_u ½uᵀHu + cᵀu s.t. a_iᵀu (= or ≤) b_i
//! ([`ConstraintKind`]).

/// The direction in which a guard g = LHS − RHS fires.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Direction {
    /// `LHS <= RHS` or `LHS < RHS`: g crosses zero from above (g goes + → −).
    Down,
    /// `LHS >= RHS` or `LHS > RHS`: g crosses zero from below (g goes − → +).
    Up,
}

impl Direction {
    /// +1 for [`Direction::Up`], −1 for [`Direction::Down`]: the sign of ġ at a genuine crossing.
    #[inline]
    pub fn sign(self) -> f64 {
        match self {
            Direction::Up => 1.0,
            Direction::Down => -1.0,
        }
    }
}

/// Static description of one event.
#[derive(Clone, Debug, PartialEq)]
pub struct EventInfo {
    /// The declared name, or `event_K` (K its index) for an unnamed event.
    pub name: String,
    /// Direction in which the guard fires.
    pub direction: Direction,
    /// `None`: declared at the top level, armed in every mode; `Some(m)`: armed only in mode m.
    pub mode: Option<usize>,
    /// Mode switched to after the reset (`-> MODE`), if any.
    pub target: Option<usize>,
    /// Whether the event has a reset block (false for `;`: the reset is the identity).
    pub has_reset: bool,
    /// Whether the cost has `sum(EVENT, ..)` terms for this event.
    pub has_cost: bool,
    /// What fires it: its guard, or a schedule of times.
    pub trigger: Trigger,
}

impl EventInfo {
    /// Whether this event is armed in mode `mode`.
    #[inline]
    pub fn armed_in(&self, mode: usize) -> bool {
        self.mode.is_none_or(|m| m == mode)
    }
    /// Whether this is a time event (its times come from the model's `event_time`).
    #[inline]
    pub fn is_time_event(&self) -> bool {
        self.trigger != Trigger::Guard
    }
}

/// What fires an event, and what its occurrence index j counts.
///
/// A time event's times τ_kj(θ) are known in advance (the model's `event_time`); its
/// event-time sensitivity is t' = ∂τ/∂θ, which is what the guard formula gives for
/// g = t − τ(θ) (g_x = 0, g_t = 1). The event loop steps exactly onto each time, with no
/// root finding. Occurrences that pass while the event is not armed (a time event inside a
/// mode the model is not in) are skipped. The reset and event cost methods receive j.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Trigger {
    /// `when`: the guard crosses zero in [`EventInfo::direction`]; j counts earlier firings.
    Guard,
    /// `at EXPR`: once (j = 0).
    At,
    /// `every PERIOD from START`: j = 0, 1, ... while start + j·period ≤ T.
    Every,
    /// `at each EXPR`: j runs over the `rows` of a data table, in row order (0 until the
    /// table is bound to the model).
    Each {
        /// The number of rows.
        rows: usize,
    },
}

/// Static description of a model: names, defaults and which parts exist.
#[derive(Clone, Debug, PartialEq)]
pub struct ModelInfo {
    /// Model name (`model NAME { .. }`).
    pub name: String,
    /// State names, in declaration order (the order of x).
    pub states: Vec<String>,
    /// Parameter names, in declaration order (the order of θ).
    pub params: Vec<String>,
    /// Declared parameter values.
    pub param_defaults: Vec<f64>,
    /// Mode names; a single-mode model has one mode named `main`.
    pub modes: Vec<String>,
    /// Index of the initial mode.
    pub initial_mode: usize,
    /// Events, in declaration order (top-level and in-mode events share one index space).
    pub events: Vec<EventInfo>,
    /// Observable names, in declaration order.
    pub observables: Vec<String>,
    /// Number of switching functions σ_j (kinks of flows and ℓ, then the switch bits of the
    /// qps a flow reads); any number.
    pub switches: usize,
    /// Whether the cost has `integral(..)` terms (ℓ ≢ 0).
    pub has_running_cost: bool,
    /// Whether the cost has `final(..)` terms (Φ ≢ 0).
    pub has_final_cost: bool,
    /// Whether the model declares a `horizon`.
    pub has_horizon: bool,
    /// Per mode, the structurally non-zero entries (row, col) of ∂f/∂x.
    pub jacobian_sparsity: Vec<Vec<(usize, usize)>>,
}

impl ModelInfo {
    /// The name of mode `m`, or its index if the model names fewer modes.
    pub fn mode_name(&self, m: usize) -> String {
        self.modes.get(m).cloned().unwrap_or_else(|| m.to_string())
    }
    /// Number of observables.
    pub fn nobservables(&self) -> usize {
        self.observables.len()
    }
    /// Index of the parameter called `name`.
    pub fn param_index(&self, name: &str) -> Option<usize> {
        self.params.iter().position(|p| p == name)
    }
    /// Index of the state called `name`.
    pub fn state_index(&self, name: &str) -> Option<usize> {
        self.states.iter().position(|p| p == name)
    }
    /// Index of the observable called `name`.
    pub fn observable_index(&self, name: &str) -> Option<usize> {
        self.observables.iter().position(|p| p == name)
    }
    /// Index of the event called `name`.
    pub fn event_index(&self, name: &str) -> Option<usize> {
        self.events.iter().position(|e| e.name == name)
    }
}

/// The kind of a qp constraint aᵢᵀu (op) bᵢ.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ConstraintKind {
    /// aᵢᵀu = bᵢ (multiplier of either sign).
    Eq,
    /// aᵢᵀu ≤ bᵢ (multiplier ≥ 0). A `≥` constraint is written with −aᵢ, −bᵢ.
    Le,
}

/// Static description of one qp layer.
#[derive(Clone, Debug, PartialEq)]
pub struct QpLayerInfo {
    /// The qp's name.
    pub name: String,
    /// Its variables' names (the order of u).
    pub vars: Vec<String>,
    /// Its constraints' kinds, in declaration order.
    pub kinds: Vec<ConstraintKind>,
    /// Whether its data depend on states or t (solved along the trajectory) rather than only
    /// on θ.
    pub dynamic: bool,
    /// The model's switch index of the first of its switch bits, one per inequality
    /// constraint in order, when a flow reads its solution (its active set is then frozen
    /// along the steps); `None` otherwise.
    pub switches: Option<usize>,
    /// The events whose guard or reset reads its solution (at the state before the jump):
    /// a weakly active constraint there is a kink of the cost in θ at the event.
    pub events_before: Vec<usize>,
    /// The events whose cost term reads its solution (at the state after the jump).
    pub events_after: Vec<usize>,
}
