//! Helpers shared by the integration tests in `tests/tests`: the sink model (every construct
//! of the language) as source and compiled, the `.hyb` files of `models/`, and a small
//! deterministic generator. The example models compiled by `hybrid!` are the `models` crate's.

/// The language's every construct: modes, kinks in flows and ℓ, time dependence, event
/// and final costs, a param-dependent horizon, observables using observables.
pub const SINK: &str = include_str!("../tests/sink.hyb");

mvad::hybrid!(include "tests/sink.hyb");

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
