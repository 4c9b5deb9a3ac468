//! The intermediate representation: a hash-consed expression DAG and the resolved model.
//!
//! Expressions live in an [`ExprArena`]: a vector of [`Node`]s whose children are
//! [`ExprId`]s of *earlier* nodes (egg's `RecExpr`), so the arena is always in
//! topological order and every pass is a loop over indices, never a recursion. Nodes are
//! interned: building the same node twice returns the same id, which makes common
//! subexpressions shared for free (CSE). The smart constructors that fold constants and
//! normalise operands live in `simplify.rs`; the derivative rules in `diff.rs`.
//!
//! A [`Program`] is a checked model with every name resolved: states, params, modes with
//! their flows, events with guards and resets, observables, the cost terms, the horizon
//! and the switching functions σ_j of the non-smooth flows.

use std::collections::HashMap;

/// Index of a node in an [`ExprArena`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct ExprId(pub u32);

impl ExprId {
    /// The index as `usize`.
    pub fn index(self) -> usize {
        self.0 as usize
    }
}

/// Unary elementary functions.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Func {
    /// sin
    Sin,
    /// cos
    Cos,
    /// tan
    Tan,
    /// asin
    Asin,
    /// acos
    Acos,
    /// atan
    Atan,
    /// exp
    Exp,
    /// natural log
    Log,
    /// square root
    Sqrt,
    /// sinh
    Sinh,
    /// cosh
    Cosh,
    /// tanh
    Tanh,
    /// |u|, evaluated pointwise
    Abs,
    /// sign(u) ∈ {−1, 0, 1} (0 at 0), evaluated pointwise; its derivative is 0
    Sign,
}

impl Func {
    /// All functions, for tests and tables.
    pub const ALL: [Func; 14] = [
        Func::Sin,
        Func::Cos,
        Func::Tan,
        Func::Asin,
        Func::Acos,
        Func::Atan,
        Func::Exp,
        Func::Log,
        Func::Sqrt,
        Func::Sinh,
        Func::Cosh,
        Func::Tanh,
        Func::Abs,
        Func::Sign,
    ];

    /// The function of a one-argument call by its `.hyb` name.
    pub fn from_name(name: &str) -> Option<Func> {
        Some(match name {
            "sin" => Func::Sin,
            "cos" => Func::Cos,
            "tan" => Func::Tan,
            "asin" => Func::Asin,
            "acos" => Func::Acos,
            "atan" => Func::Atan,
            "exp" => Func::Exp,
            "log" => Func::Log,
            "sqrt" => Func::Sqrt,
            "sinh" => Func::Sinh,
            "cosh" => Func::Cosh,
            "tanh" => Func::Tanh,
            "abs" => Func::Abs,
            "sign" => Func::Sign,
            _ => return None,
        })
    }

    /// The name of the `f64` method computing the function (`sign` is `__private::sign`).
    pub fn method_name(self) -> &'static str {
        match self {
            Func::Sin => "sin",
            Func::Cos => "cos",
            Func::Tan => "tan",
            Func::Asin => "asin",
            Func::Acos => "acos",
            Func::Atan => "atan",
            Func::Exp => "exp",
            Func::Log => "ln",
            Func::Sqrt => "sqrt",
            Func::Sinh => "sinh",
            Func::Cosh => "cosh",
            Func::Tanh => "tanh",
            Func::Abs => "abs",
            Func::Sign => "sign",
        }
    }

    /// Evaluates the function (the one definition shared by folding, the tape and codegen).
    pub fn apply(self, x: f64) -> f64 {
        match self {
            Func::Sin => x.sin(),
            Func::Cos => x.cos(),
            Func::Tan => x.tan(),
            Func::Asin => x.asin(),
            Func::Acos => x.acos(),
            Func::Atan => x.atan(),
            Func::Exp => x.exp(),
            Func::Log => x.ln(),
            Func::Sqrt => x.sqrt(),
            Func::Sinh => x.sinh(),
            Func::Cosh => x.cosh(),
            Func::Tanh => x.tanh(),
            Func::Abs => x.abs(),
            Func::Sign => sign(x),
        }
    }
}

/// sign(x): 1 for x > 0, −1 for x < 0, 0 for ±0, NaN for NaN.
pub fn sign(x: f64) -> f64 {
    if x > 0.0 {
        1.0
    } else if x < 0.0 {
        -1.0
    } else {
        x * 0.0
    }
}

/// A comparison of a value against zero, used by pointwise [`Node::Select`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Cmp {
    /// c > 0
    Gt,
    /// c ≥ 0
    Ge,
    /// c < 0
    Lt,
    /// c ≤ 0
    Le,
}

impl Cmp {
    /// Whether `c cmp 0` holds (false for NaN).
    pub fn test(self, c: f64) -> bool {
        match self {
            Cmp::Gt => c > 0.0,
            Cmp::Ge => c >= 0.0,
            Cmp::Lt => c < 0.0,
            Cmp::Le => c <= 0.0,
        }
    }
}

/// What a derivative of a qp solution is taken with respect to (see [`Node::QpDeriv`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Wrt {
    /// State x_i.
    State(u32),
    /// Parameter θ_i.
    Param(u32),
    /// Time t.
    Time,
}

impl Wrt {
    /// The column of ∂u/∂w in a row (∂/∂x (n), ∂/∂θ (p), ∂/∂t) of [`QpValues::du`].
    pub fn column(self, n: usize, p: usize) -> usize {
        match self {
            Wrt::State(i) => i as usize,
            Wrt::Param(i) => n + i as usize,
            Wrt::Time => n + p,
        }
    }
}

/// One node of the expression DAG. Children are ids of earlier nodes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Node {
    /// A constant, stored as its `f64` bits so nodes can be hashed.
    Const(u64),
    /// The time t.
    Time,
    /// State x_i.
    State(u32),
    /// Parameter θ_i.
    Param(u32),
    /// Column c of the program's `Program::columns` at the current row of its table (a
    /// datum, never differentiated; read only by `at each` events).
    Column(u32),
    /// a + b (operands sorted by id).
    Add(ExprId, ExprId),
    /// a · b (operands sorted by id).
    Mul(ExprId, ExprId),
    /// −a.
    Neg(ExprId),
    /// a / b.
    Div(ExprId, ExprId),
    /// aⁿ for an integer n.
    Powi(ExprId, i32),
    /// a^b = exp(b ln a) for real b.
    Pow(ExprId, ExprId),
    /// f(a) for an elementary function.
    Call(Func, ExprId),
    /// Pointwise choice: `if c cmp 0 then a else b`; its derivative is that of the side taken.
    Select(Cmp, ExprId, ExprId, ExprId),
    /// Frozen choice: `if bit j of sw then a else b` (the branch for σ_j > 0 is `a`).
    Switch(u32, ExprId, ExprId),
    /// Variable k of the qp solutions, all qps' variables flattened in declaration order
    /// ([`Qp::offset`]): inside a qp's own data the decision variable (differentiated with
    /// `diff::Var::Qp` to extract H, c, A, b), elsewhere the solution u*_k, an input of the
    /// evaluation ([`QpValues::u`]).
    QpSol(u32),
    /// ∂u*_k/∂w, an input of the evaluation ([`QpValues::du`]): the derivative of
    /// [`Node::QpSol`]`(k)` with respect to a state, a param or t, from the KKT system.
    /// Its own derivatives are zero: only first derivatives are taken of expressions that
    /// read qp solutions.
    QpDeriv(u32, Wrt),
}

impl Node {
    /// The children of the node, in order (at most three).
    pub fn children(&self) -> impl Iterator<Item = ExprId> {
        let (a, b, c) = match *self {
            Node::Const(_)
            | Node::Time
            | Node::State(_)
            | Node::Param(_)
            | Node::Column(_)
            | Node::QpSol(_)
            | Node::QpDeriv(..) => (None, None, None),
            Node::Neg(a) | Node::Powi(a, _) | Node::Call(_, a) => (Some(a), None, None),
            Node::Add(a, b)
            | Node::Mul(a, b)
            | Node::Div(a, b)
            | Node::Pow(a, b)
            | Node::Switch(_, a, b) => (Some(a), Some(b), None),
            Node::Select(_, c, a, b) => (Some(c), Some(a), Some(b)),
        };
        a.into_iter().chain(b).chain(c)
    }

    /// The node with each child c replaced by `f(c)`.
    pub fn map_children(self, f: impl Fn(ExprId) -> ExprId) -> Node {
        match self {
            Node::Add(a, b) => Node::Add(f(a), f(b)),
            Node::Mul(a, b) => Node::Mul(f(a), f(b)),
            Node::Neg(a) => Node::Neg(f(a)),
            Node::Div(a, b) => Node::Div(f(a), f(b)),
            Node::Powi(a, n) => Node::Powi(f(a), n),
            Node::Pow(a, b) => Node::Pow(f(a), f(b)),
            Node::Call(g, a) => Node::Call(g, f(a)),
            Node::Select(c, x, a, b) => Node::Select(c, f(x), f(a), f(b)),
            Node::Switch(j, a, b) => Node::Switch(j, f(a), f(b)),
            leaf => leaf,
        }
    }

    /// Whether the node is a leaf (constant, time, state, parameter, table column, qp
    /// solution or its derivative).
    pub fn is_leaf(&self) -> bool {
        self.children().next().is_none()
    }

    /// Whether the node reads a qp solution or its derivative.
    pub fn is_qp(&self) -> bool {
        matches!(self, Node::QpSol(_) | Node::QpDeriv(..))
    }
}

/// Inputs of a pointwise evaluation.
#[derive(Clone, Copy, Debug)]
pub struct Point<'a> {
    /// Time t.
    pub t: f64,
    /// States x.
    pub x: &'a [f64],
    /// Parameters θ.
    pub p: &'a [f64],
    /// Frozen branches.
    pub sw: u64,
}

/// The qp solutions and their derivatives an evaluation reads: `u` (one entry per
/// [`Node::QpSol`] index) and `du`, row k holding ∂u*_k/∂(x (n), θ (p), t) ([`Wrt::column`]).
#[derive(Clone, Copy, Debug)]
pub struct QpValues<'a> {
    /// u*, all qps' variables flattened.
    pub u: &'a [f64],
    /// ∂u*/∂(x, θ, t), row-major, rows of n + p + 1.
    pub du: &'a [f64],
    /// Number of states n.
    pub n: usize,
    /// Number of params p.
    pub p: usize,
}

impl QpValues<'_> {
    /// No qp values (every qp leaf reads NaN).
    pub const NONE: QpValues<'static> = QpValues {
        u: &[],
        du: &[],
        n: 0,
        p: 0,
    };

    /// The value of a qp leaf (NaN when absent).
    pub fn leaf(&self, node: &Node) -> f64 {
        let got = match *node {
            Node::QpSol(k) => self.u.get(k as usize),
            Node::QpDeriv(k, w) => self
                .du
                .get(k as usize * (self.n + self.p + 1) + w.column(self.n, self.p)),
            _ => None,
        };
        got.copied().unwrap_or(f64::NAN)
    }
}

/// The inputs of an evaluation beyond its [`Point`]: the qp solutions and the current row of
/// a table (column c, [`Node::Column`]`(c)`, reads `row[c]`).
#[derive(Clone, Copy, Debug)]
pub struct Inputs<'a> {
    /// The qp solutions and their derivatives.
    pub qp: QpValues<'a>,
    /// The current row's value of every column of `Program::columns` (empty outside the
    /// methods of `at each` events).
    pub row: &'a [f64],
}

impl Inputs<'_> {
    /// No inputs (every qp leaf and column reads NaN).
    pub const NONE: Inputs<'static> = Inputs {
        qp: QpValues::NONE,
        row: &[],
    };

    /// The value of a leaf that is an input (NaN when absent or not an input).
    pub fn leaf(&self, node: &Node) -> f64 {
        match *node {
            Node::Column(c) => self.row.get(c as usize).copied().unwrap_or(f64::NAN),
            _ => self.qp.leaf(node),
        }
    }
}

/// Evaluates one node given the values of its children (`v` indexed by node id).
/// The reference evaluator has no [`Inputs`] and sees switch bits 0..64 only: qp leaves and
/// columns are NaN here, and a bit j ≥ 64 is off.
pub fn apply_node(node: &Node, v: &[f64], at: &Point<'_>) -> f64 {
    apply_node_in(node, |id| v[id.index()], at, &[], &Inputs::NONE)
}

/// Evaluates one node given its children's values through `child`: the single definition
/// of every node's value, which folding, the tape ([`crate::eval::Tape`]) and codegen agree
/// with. Switch bit j is bit j of `at.sw` for j < 64 and bit (j − 64) % 64 of
/// `hi[(j − 64) / 64]` beyond (off when absent); qp solutions, their derivatives and table
/// columns are read from `inputs`.
#[inline(always)]
pub fn apply_node_in(
    node: &Node,
    child: impl Fn(ExprId) -> f64,
    at: &Point<'_>,
    hi: &[u64],
    inputs: &Inputs<'_>,
) -> f64 {
    let g = child;
    match *node {
        Node::Const(bits) => f64::from_bits(bits),
        Node::Time => at.t,
        Node::State(i) => at.x.get(i as usize).copied().unwrap_or(f64::NAN),
        Node::Param(i) => at.p.get(i as usize).copied().unwrap_or(f64::NAN),
        Node::Add(a, b) => g(a) + g(b),
        Node::Mul(a, b) => g(a) * g(b),
        Node::Neg(a) => -g(a),
        Node::Div(a, b) => g(a) / g(b),
        Node::Powi(a, n) => g(a).powi(n),
        Node::Pow(a, b) => g(a).powf(g(b)),
        Node::Call(f, a) => f.apply(g(a)),
        Node::Select(c, cond, a, b) => {
            if c.test(g(cond)) {
                g(a)
            } else {
                g(b)
            }
        }
        Node::Switch(j, a, b) => {
            if switch_bit(at.sw, hi, j) {
                g(a)
            } else {
                g(b)
            }
        }
        Node::Column(_) | Node::QpSol(_) | Node::QpDeriv(..) => inputs.leaf(node),
    }
}

/// Switch bit j of the frozen branches: bit j of `sw` for j < 64, else bit (j − 64) % 64 of
/// `hi[(j − 64) / 64]` (off when absent).
#[inline(always)]
fn switch_bit(sw: u64, hi: &[u64], j: u32) -> bool {
    if j < 64 {
        sw >> j & 1 != 0
    } else {
        let k = (j - 64) as usize;
        hi.get(k / 64).is_some_and(|w| w >> (k % 64) & 1 != 0)
    }
}

/// A hash-consed expression DAG in topological order.
#[derive(Clone, Debug, Default)]
pub struct ExprArena {
    nodes: Vec<Node>,
    map: HashMap<Node, ExprId>,
    /// Per [`Node::QpSol`] index: whether that solution can depend on x and on t (its qp's
    /// data read states, t); `diff` gives ∂u*/∂x and ∂u*/∂t only where they can be non-zero.
    qp_deps: Vec<(bool, bool)>,
}

impl ExprArena {
    /// An empty arena.
    pub fn new() -> Self {
        Self::default()
    }

    /// Number of nodes.
    pub fn len(&self) -> usize {
        self.nodes.len()
    }

    /// Whether the arena is empty.
    pub fn is_empty(&self) -> bool {
        self.nodes.is_empty()
    }

    /// Records, per [`Node::QpSol`] index, whether the solution can depend on (x, t).
    pub fn set_qp_deps(&mut self, deps: Vec<(bool, bool)>) {
        self.qp_deps = deps;
    }

    /// Whether qp solution k can depend on (x, t) (both true when not recorded).
    pub fn qp_deps(&self, k: u32) -> (bool, bool) {
        self.qp_deps
            .get(k as usize)
            .copied()
            .unwrap_or((true, true))
    }

    /// The node with id `id`.
    pub fn node(&self, id: ExprId) -> Node {
        self.nodes[id.index()]
    }

    /// All nodes in topological order.
    pub fn nodes(&self) -> &[Node] {
        &self.nodes
    }

    /// Interns `node` as is (no simplification): the same node always gets the same id.
    /// Children must already be in the arena.
    pub fn intern(&mut self, node: Node) -> ExprId {
        if let Some(&id) = self.map.get(&node) {
            return id;
        }
        debug_assert!(node.children().all(|c| c.index() < self.nodes.len()));
        let id = ExprId(self.nodes.len() as u32);
        self.nodes.push(node);
        self.map.insert(node, id);
        id
    }

    /// The value of `id` if it is a constant.
    pub fn as_const(&self, id: ExprId) -> Option<f64> {
        match self.node(id) {
            Node::Const(bits) => Some(f64::from_bits(bits)),
            _ => None,
        }
    }

    /// Whether `id` is the constant `v` (0.0 and −0.0 both count as zero).
    pub fn is_const(&self, id: ExprId, v: f64) -> bool {
        self.as_const(id) == Some(v)
    }

    /// Whether `id` is structurally zero.
    pub fn is_zero(&self, id: ExprId) -> bool {
        self.is_const(id, 0.0)
    }

    /// Marks the nodes reachable from `roots` (iteratively, no recursion).
    pub fn live(&self, roots: &[ExprId]) -> Vec<bool> {
        let mut live = vec![false; self.nodes.len()];
        let top = match roots.iter().max() {
            Some(m) => m.index(),
            None => return live,
        };
        for r in roots {
            live[r.index()] = true;
        }
        for i in (0..=top).rev() {
            if live[i] {
                for c in self.nodes[i].children() {
                    live[c.index()] = true;
                }
            }
        }
        live
    }

    /// Whether the expression `id` reads the node kind selected by `pred` (e.g. the time).
    pub fn depends_on(&self, id: ExprId, pred: impl Fn(&Node) -> bool) -> bool {
        let live = self.live(&[id]);
        live.iter().zip(&self.nodes).any(|(&l, n)| l && pred(n))
    }

    /// Evaluates the expressions `roots` at a point by a dense sweep (reference evaluator
    /// for tests and constant folding of whole expressions; allocates).
    pub fn eval(&self, roots: &[ExprId], at: &Point<'_>) -> Vec<f64> {
        let top = roots.iter().max().map_or(0, |m| m.index() + 1);
        let live = self.live(roots);
        let mut v = vec![0.0; top];
        for i in 0..top {
            if live[i] {
                v[i] = apply_node(&self.nodes[i], &v, at);
            }
        }
        roots.iter().map(|r| v[r.index()]).collect()
    }
}

/// A model's static description, as the runtime reads it (crate `mvad-info`): the lowered
/// events carry their [`EventInfo`], the qps their [`ConstraintKind`]s, and the kernels
/// build the [`ModelInfo`] and [`QpLayerInfo`]s both back ends hand over.
pub use mvad_info::{ConstraintKind, Direction, EventInfo, ModelInfo, QpLayerInfo, Trigger};

/// One mode: its name and flow ẋ = f_m(t, x, θ) (one expression per state, frozen branches).
#[derive(Clone, Debug)]
pub struct Mode {
    /// Mode name (`main` for a single-mode model).
    pub name: String,
    /// f_m, one expression per state.
    pub flow: Vec<ExprId>,
}

/// When a time event fires (expressions of θ, and for `at each` of the columns of its table).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Schedule {
    /// `at τ`: once at t = τ(θ).
    At(ExprId),
    /// `every period from start`: at t = start(θ) + j·period(θ), j = 0, 1, ...
    Every {
        /// The period.
        period: ExprId,
        /// The first time.
        start: ExprId,
    },
    /// `at each τ`: at t = τ(θ, row j) for every row j of table `table`.
    Each {
        /// Index into `Program::tables`.
        table: usize,
        /// τ, reading [`Node::Column`]s of that table.
        time: ExprId,
    },
}

/// One event: its declaration, guard (or schedule), reset and event cost.
#[derive(Clone, Debug)]
pub struct Event {
    /// What the model says of it besides its expressions: name, direction, modes, whether
    /// it has a reset block and an event cost, what fires it (`Trigger::Each { rows: 0 }`
    /// until a back end binds the table).
    pub info: EventInfo,
    /// g = LHS − RHS of a state event; NaN for a time event (which has no guard).
    pub guard: ExprId,
    /// `Some` for a time event: when it fires.
    pub schedule: Option<Schedule>,
    /// x⁺ = R(t, x⁻, θ), one expression per state (x_i itself when not assigned).
    pub reset: Vec<ExprId>,
    /// φ_k = Σ factor · `sum(EVENT, expr)` terms, evaluated after the reset, if any.
    pub cost: Option<ExprId>,
}

/// A lowered qp: min ½uᵀHu + cᵀu s.t. a_iᵀu (= or ≤) b_i, its data expressions of (t, x, θ).
#[derive(Clone, Debug)]
pub struct Qp {
    /// The qp's name.
    pub name: String,
    /// Its variables' names.
    pub vars: Vec<String>,
    /// The [`Node::QpSol`] index of its first variable.
    pub offset: usize,
    /// Each constraint's kind, in declaration order.
    pub kinds: Vec<ConstraintKind>,
    /// H = ∂²F/∂u², row-major (n_u × n_u).
    pub h: Vec<ExprId>,
    /// c = ∂F/∂u at u = 0.
    pub c: Vec<ExprId>,
    /// Rows a_i = ∂g_i/∂u, row-major (m × n_u).
    pub a: Vec<ExprId>,
    /// b_i = −g_i(u = 0).
    pub b: Vec<ExprId>,
    /// Whether the data read states or t (solved along the trajectory) rather than only θ.
    pub dynamic: bool,
    /// When a flow or ℓ reads the solution of this dynamic qp: the switch index of the
    /// first of its bits, one per inequality constraint in order (after the kinks'
    /// switching functions in [`Program::switches`]); bit set ⇔ the constraint is held
    /// active.
    pub switches: Option<usize>,
    /// Whether a flow or ℓ reads its solution.
    pub in_flow: bool,
}

impl Qp {
    /// The data in one list: H (row-major), c, A (row-major), b.
    pub fn data(&self) -> Vec<ExprId> {
        let mut v = self.h.clone();
        v.extend(&self.c);
        v.extend(&self.a);
        v.extend(&self.b);
        v
    }
}

/// What a model declares by name, in declaration order: the part of a [`Program`] that
/// its kernels ([`crate::schedule::ModelKernels`]) carry over unchanged.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ModelNames {
    /// Model name.
    pub name: String,
    /// State names (the order of x).
    pub states: Vec<String>,
    /// Parameter names (the order of θ).
    pub params: Vec<String>,
    /// Data tables: (name, file as written in the model).
    pub tables: Vec<(String, String)>,
    /// The table columns the model reads: (index into `tables`, column name); column c is
    /// [`Node::Column`]`(c)`, `row[c]` in the kernels.
    pub columns: Vec<(usize, String)>,
    /// Declared parameter values (consts folded).
    pub param_defaults: Vec<f64>,
}

impl ModelNames {
    /// Number of states n.
    pub fn nstates(&self) -> usize {
        self.states.len()
    }
    /// Number of parameters p.
    pub fn nparams(&self) -> usize {
        self.params.len()
    }
}

/// A checked model with all names resolved.
#[derive(Clone, Debug)]
pub struct Program {
    /// The shared expression arena.
    pub arena: ExprArena,
    /// Its names: model, states, parameters, tables and columns, parameter defaults.
    pub names: ModelNames,
    /// x₀(θ), one expression per state.
    pub x0: Vec<ExprId>,
    /// Modes with their flows.
    pub modes: Vec<Mode>,
    /// Index of the initial mode.
    pub initial_mode: usize,
    /// Events in declaration order.
    pub events: Vec<Event>,
    /// Observables (name, pointwise expression).
    pub observables: Vec<(String, ExprId)>,
    /// ℓ (frozen branches), if the cost has `integral` terms.
    pub running_cost: Option<ExprId>,
    /// Φ, if the cost has `final` terms.
    pub final_cost: Option<ExprId>,
    /// T(θ), if declared.
    pub horizon: Option<ExprId>,
    /// Switching functions σ_j (pointwise expressions), any number: the tape reads the bits
    /// past 64 from the words `Tape::run` is given; the arena's own evaluator ([`Point::sw`]) sees bits 0..64.
    pub switches: Vec<ExprId>,
    /// The qps, in declaration order; their variables are flattened in this order.
    pub qps: Vec<Qp>,
}

impl Program {
    /// Number of states.
    pub fn nstates(&self) -> usize {
        self.names.nstates()
    }
    /// Number of parameters.
    pub fn nparams(&self) -> usize {
        self.names.nparams()
    }
    /// Number of switch bits: the kinks' switching functions, then the qps' constraints.
    pub fn nswitches(&self) -> usize {
        self.switches.len() + qp_switch_bits(self.qps.iter().map(|q| (q.switches, &q.kinds)))
    }
}

/// The number of qp switch bits: one per inequality constraint of each qp that has them.
pub fn qp_switch_bits<'a>(
    qps: impl Iterator<Item = (Option<usize>, &'a Vec<ConstraintKind>)>,
) -> usize {
    qps.filter(|(s, _)| s.is_some())
        .map(|(_, kinds)| kinds.iter().filter(|&&k| k == ConstraintKind::Le).count())
        .sum()
}
