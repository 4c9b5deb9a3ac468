//! Helpers shared by the integration tests in `tests/tests`: the sink model (every construct
//! of the language) as source and compiled, the `.hyb` files of `models/`, and a small
//! deterministic generator. The example models compiled by `hybrid!` are the `models` crate's.

/// The language's every construct: modes, kinks in flows and ℓ, time dependence, event
/// and final costs, a param-dependent horizon, observables using observables.
pub const SINK: &str = include_str!("../tests/sink.hyb");

mvad::hybrid!(include "tests/sink.hyb");

/// Solves `m` at the params `p` (a slice, in declaration order).
pub fn solve_at<M: mvad::HybridModel>(
    m: &M,
    p: &[f64],
    opts: &mvad::Options,
) -> Result<mvad::Solution, mvad::runtime::error::SolveError>
where
    nalgebra::DefaultAllocator: mvad::ModelAlloc<M::N, M::P>,
{
    let pv = nalgebra::OVector::<f64, M::P>::from_iterator_generic(
        m.nparams(),
        nalgebra::Const::<1>,
        p.iter().copied(),
    );
    mvad::solve(m, &pv, opts)
}

/// Solves `m` at its params' default values.
pub fn solve_at_defaults<M: mvad::HybridModel>(m: &M, opts: &mvad::Options) -> mvad::Solution
where
    nalgebra::DefaultAllocator: mvad::ModelAlloc<M::N, M::P>,
{
    solve_at(m, &m.info().param_defaults, opts).expect("runs")
}

/// The model of `tests/tests/FILE` through the loaded door.
pub fn loaded_test_model(file: &str) -> mvad::interp::InterpretedModel {
    let src = std::fs::read_to_string(format!("{}/tests/{file}", env!("CARGO_MANIFEST_DIR")))
        .expect(file);
    mvad::interp::InterpretedModel::from_source(&src).unwrap_or_else(|e| panic!("{file}: {e:?}"))
}

/// The `.hyb` files of `models/`, as (file name, source), sorted by name.
pub fn model_files() -> Vec<(String, String)> {
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/../models");
    let mut out: Vec<(String, String)> = std::fs::read_dir(dir)
        .map(|rd| {
            rd.filter_map(|e| e.ok())
                .map(|e| e.path())
                .filter(|p| p.extension().is_some_and(|x| x == "hyb"))
                .filter_map(|p| {
                    Some((
                        p.file_name()?.to_string_lossy().into_owned(),
                        std::fs::read_to_string(&p).ok()?,
                    ))
                })
                .collect()
        })
        .unwrap_or_default();
    out.sort();
    out
}

/// Integration tolerances for comparisons at the level of rounding: rtol 1e-12, atol 1e-14.
pub fn tight() -> mvad::Options {
    mvad::Options {
        rtol: 1e-12,
        atol: 1e-14,
        ..mvad::Options::default()
    }
}

/// Integration tolerances rtol 1e-10, atol 1e-12 in gradient mode `mode`: where a test's
/// closed forms hold to about 1e-8.
pub fn precise(mode: mvad::GradientMode) -> mvad::Options {
    mvad::Options {
        rtol: 1e-10,
        atol: 1e-12,
        gradient_mode: mode,
        ..mvad::Options::default()
    }
}

/// `check(model, door)` on the model compiled by `hybrid!` (the expression `compiled`) and
/// on the same model loaded from `tests/tests/FILE`, with `door` "compiled" and "loaded".
/// (`check` is generic over the model, so this is a macro, not a function taking it.) With
/// `NAME:` first, the `#[test]` function NAME doing so.
#[macro_export]
macro_rules! test_both_doors {
    ($test:ident: $check:expr, $compiled:expr, $file:expr) => {
        #[test]
        fn $test() {
            $crate::test_both_doors!($check, $compiled, $file);
        }
    };
    ($check:expr, $compiled:expr, $file:expr) => {{
        $check(&$compiled, "compiled");
        $check(&$crate::loaded_test_model($file), "loaded");
    }};
}

/// Asserts |got − want| ≤ rel · max(|want|, 1) (relative above 1, absolute below; false
/// for NaN); `what` names the value in the message.
#[track_caller]
pub fn assert_near(got: f64, want: f64, rel: f64, what: impl std::fmt::Display) {
    assert!(
        (got - want).abs() <= rel * want.abs().max(1.0),
        "{what}: {got:e} vs {want:e} (rel {rel:e})"
    );
}

/// The source of `models/FILE`.
pub fn model_source(file: &str) -> String {
    std::fs::read_to_string(format!("{}/../models/{file}", env!("CARGO_MANIFEST_DIR"))).expect(file)
}

/// A small deterministic generator (splitmix64), uniform in [0, 1).
pub struct Rng(u64);

impl Rng {
    /// A generator with the given seed.
    pub fn new(seed: u64) -> Self {
        Rng(seed)
    }
    /// The next number in [0, 1).
    pub fn uniform(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    }
    /// Uniform in [lo, hi).
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.uniform()
    }
}

use mvad::{
    At, HybridModel, ModelAdjoint, ModelAlloc, ModelDims, ModelSecondOrder, ModelSens, Occurrence,
};
use nalgebra::{DefaultAllocator, OMatrix, OVector};

/// A model with the capability defaults: `Defaults(m)` answers every core method as `m` does
/// and every capability ([`ModelSens`], [`ModelAdjoint`], [`ModelSecondOrder`]) with the
/// trait's dense or finite-difference default, so tests can hold a model's own products
/// against the defaults.
pub struct Defaults<M>(pub M);

type Xv<M> = OVector<f64, <M as ModelDims>::N>;
type Pv<M> = OVector<f64, <M as ModelDims>::P>;
type Nn<M> = OMatrix<f64, <M as ModelDims>::N, <M as ModelDims>::N>;
type Np<M> = OMatrix<f64, <M as ModelDims>::N, <M as ModelDims>::P>;
type Pt<'a, M> = mvad::Point<'a, <M as ModelDims>::N, <M as ModelDims>::P>;
type AtM<'a, M> = At<'a, <M as ModelDims>::N, <M as ModelDims>::P>;

impl<M: ModelDims> ModelDims for Defaults<M> {
    type N = M::N;
    type P = M::P;
}

impl<M: HybridModel> ModelSens for Defaults<M> where DefaultAllocator: ModelAlloc<M::N, M::P> {}
impl<M: HybridModel> ModelAdjoint for Defaults<M> where DefaultAllocator: ModelAlloc<M::N, M::P> {}
impl<M: HybridModel> ModelSecondOrder for Defaults<M> where DefaultAllocator: ModelAlloc<M::N, M::P> {}

/// For each signature `fn NAME(&self, ARG: TYPE, ..) -> RET;`, the method that answers as the
/// wrapped model does: `self.0.NAME(ARG, ..)`.
macro_rules! delegate_to_inner {
    ($(fn $name:ident(&self $(, $arg:ident: $ty:ty)* $(,)?) $(-> $ret:ty)?;)*) => {
        $(fn $name(&self $(, $arg: $ty)*) $(-> $ret)? { self.0.$name($($arg),*) })*
    };
}

impl<M: HybridModel> HybridModel for Defaults<M>
where
    DefaultAllocator: ModelAlloc<M::N, M::P>,
{
    delegate_to_inner! {
        fn info(&self) -> &mvad::ModelInfo;
        fn nstates(&self) -> M::N;
        fn nparams(&self) -> M::P;
        fn initial_state(&self, p: &Pv<M>, x0: &mut Xv<M>);
        fn initial_state_jac(&self, p: &Pv<M>, dx0: &mut Np<M>);
        fn horizon(&self, p: &Pv<M>) -> Option<f64>;
        fn horizon_grad(&self, p: &Pv<M>, dt: &mut Pv<M>);
        fn rhs(&self, pt: Pt<'_, M>, f: &mut Xv<M>);
        fn rhs_jac_x(&self, pt: Pt<'_, M>, fx: &mut Nn<M>);
        fn rhs_jac_p(&self, pt: Pt<'_, M>, fp: &mut Np<M>);
        fn rhs_dt(&self, pt: Pt<'_, M>, ft: &mut Xv<M>);
        fn rhs_depends_on_t(&self, mode: usize) -> bool;
        fn flow_is_constant(&self, mode: usize) -> bool;
        fn guard(&self, k: usize, at: AtM<'_, M>) -> f64;
        fn guard_is_affine(&self, k: usize) -> bool;
        fn guard_grad(&self, k: usize, at: AtM<'_, M>, gx: &mut Xv<M>, gp: &mut Pv<M>) -> f64;
        fn reset(&self, occ: Occurrence, at: AtM<'_, M>, xplus: &mut Xv<M>);
        fn reset_jac(&self, occ: Occurrence, at: AtM<'_, M>,
            rx: &mut Nn<M>, rp: &mut Np<M>, rt: &mut Xv<M>);
        fn event_time(&self, occ: Occurrence, p: &Pv<M>) -> f64;
        fn event_time_grad(&self, occ: Occurrence, p: &Pv<M>, dtau: &mut Pv<M>);
        fn switch_value(&self, j: usize, at: AtM<'_, M>) -> f64;
        fn switch_grad(&self, j: usize, at: AtM<'_, M>, gx: &mut Xv<M>, gp: &mut Pv<M>) -> f64;
        fn observe(&self, sw: &mvad::Switches, at: AtM<'_, M>, y: &mut [f64]);
        fn observe_jac(&self, sw: &mvad::Switches, at: AtM<'_, M>, yx: &mut [f64], yp: &mut [f64]);
        fn running_cost(&self, sw: &mvad::Switches, at: AtM<'_, M>) -> f64;
        fn running_cost_value_grad(&self, sw: &mvad::Switches, at: AtM<'_, M>,
            lx: &mut Xv<M>, lp: &mut Pv<M>) -> f64;
        fn event_cost(&self, occ: Occurrence, at: AtM<'_, M>) -> f64;
        fn event_cost_grad(&self, occ: Occurrence, at: AtM<'_, M>,
            cx: &mut Xv<M>, cp: &mut Pv<M>) -> f64;
        fn final_cost(&self, at: AtM<'_, M>) -> f64;
        fn final_cost_grad(&self, at: AtM<'_, M>, cx: &mut Xv<M>, cp: &mut Pv<M>) -> f64;
    }
}
