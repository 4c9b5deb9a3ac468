//! E4, the single-server FIFO queue (`models/queue.hyb`): workload w, modes busy (ẇ = −1) and
//! idle (ẇ = 0), arrivals from the table `arrivals` (times t_i, service requirements s_i),
//! service rate μ, a `drained` state event, and C = Σᵢ w(A_i⁺), the sum of the sojourn times.
//! `models/queue_stretched.hyb` is the same queue with its arrivals at scale·t_i.
//!
//! The references:
//! - [`lindley_ipa`]: the hand-written baseline, the Lindley recursion of the workload just
//!   after arrival i, u_i = max(u_{i−1} − (A_i − A_{i−1}), 0) + s_i/μ, with its IPA derivatives
//!   du_i/dμ = [u_{i−1} > A_i − A_{i−1}]·du_{i−1}/dμ − s_i/μ² and
//!   du_i/dscale = \[busy\]·(du_{i−1}/dscale − (t_i − t_{i−1})) (DESIGN.md, E4), in `f64`;
//! - [`exact`]: the same recursion in exact integer arithmetic on the same `f64` data (every
//!   quantity an integer multiple of one fixed tiny unit), rounded to `f64` once at the end.
//!
//! [`Arrivals::generate`] makes seeded tables with exponential interarrival and service
//! times.

use mvad::table::{Table, TableError};
use num_bigint::BigInt;
use num_rational::BigRational;
use num_traits::{ToPrimitive, Zero};
use rand::{RngExt, SeedableRng};

mvad::hybrid!(include "queue.hyb");

/// The stretched-arrivals queue, compiled.
pub mod stretched {
    mvad::hybrid!(include "queue_stretched.hyb");
}

/// An arrival table: times t (nondecreasing) and service requirements s.
#[derive(Clone, Debug, PartialEq)]
pub struct Arrivals {
    /// Arrival times.
    pub t: Vec<f64>,
    /// Service requirements (service time s/μ).
    pub s: Vec<f64>,
}

impl Arrivals {
    /// `n` customers with exponential interarrival times of mean 1 and exponential service
    /// requirements of mean 1 (so the load is 1/μ), from the generator seeded with `seed`.
    pub fn generate(n: usize, seed: u64) -> Arrivals {
        let mut rng = rand::rngs::Xoshiro256PlusPlus::seed_from_u64(seed);
        // −ln(1 − U) with U uniform on [0, 1): an exponential of mean 1.
        let mut exp = || -(1.0 - rng.random::<f64>()).ln();
        let mut t = Vec::with_capacity(n);
        let mut s = Vec::with_capacity(n);
        let mut now = 0.0;
        for _ in 0..n {
            now += exp();
            t.push(now);
            s.push(exp());
        }
        Arrivals { t, s }
    }

    /// The table as CSV text (`t,s` header; every value written so that it reads back as the
    /// same `f64`).
    pub fn to_csv(&self) -> String {
        let mut out = String::with_capacity(self.t.len() * 40 + 4);
        out.push_str("t,s\n");
        for (t, s) in self.t.iter().zip(&self.s) {
            out.push_str(&format!("{t:?},{s:?}\n"));
        }
        out
    }

    /// The table the models read (columns `t` and `s`).
    pub fn table(&self) -> Result<Table, TableError> {
        Table::from_columns(
            "arrivals",
            vec![("t".into(), self.t.clone()), ("s".into(), self.s.clone())],
        )
    }
}

/// C, dC/dμ and dC/dscale of the queue whose customer i arrives at scale·t_i, by the
/// Lindley recursion in `f64` (the benchmark's baseline; `scale` = 1 is the plain queue).
pub fn lindley_ipa(t: &[f64], s: &[f64], mu: f64, scale: f64) -> (f64, f64, f64) {
    let (mut u, mut du_mu, mut du_sc) = (0.0, 0.0, 0.0);
    let (mut c, mut dc_mu, mut dc_sc) = (0.0, 0.0, 0.0);
    let mut prev = 0.0;
    for (&ti, &si) in t.iter().zip(s) {
        let gap = scale * (ti - prev);
        let left = u - gap;
        if left > 0.0 {
            u = left;
            du_sc -= ti - prev;
        } else {
            u = 0.0;
            du_mu = 0.0;
            du_sc = 0.0;
        }
        u += si / mu;
        du_mu -= si / (mu * mu);
        c += u;
        dc_mu += du_mu;
        dc_sc += du_sc;
        prev = ti;
    }
    (c, dc_mu, dc_sc)
}

/// The exact C, dC/dμ and dC/dscale of the same recursion on the same `f64` data, rounded to
/// `f64` once at the end.
///
/// Every datum is a dyadic rational m·2^e, so with μ = M·2^E (M odd) and ε = 2^−1100 all of
/// scale·t_i, s_i/μ and u_i are integer multiples of ε/M, all of s_i/μ² of ε/M², and all of
/// t_i of ε·2^−e_s (scale = m_s·2^e_s): the recursion runs on those integers (additions, subtractions and comparisons
/// only), exactly.
pub fn exact(t: &[f64], s: &[f64], mu: f64, scale: f64) -> (f64, f64, f64) {
    const L: i32 = 1100;
    let (m, e) = odd_mantissa(mu);
    let m = BigInt::from(m);
    let m2 = &m * &m;
    // Units: value·(M·2^L) for u, scale·t, s/μ; value·(M²·2^L) for d/dμ; value·2^(L + e_s)
    // for t and d/dscale, where scale = m_s·2^e_s.
    let (sc_m, sc_e) = odd_mantissa(scale);
    let sc = BigInt::from(sc_m);
    let (mut u, mut du_mu, mut du_sc) = (BigInt::zero(), BigInt::zero(), BigInt::zero());
    let (mut c, mut dc_mu, mut dc_sc) = (BigInt::zero(), BigInt::zero(), BigInt::zero());
    let mut prev = BigInt::zero(); // t_{i−1}·2^(L + e_s)
    for (&ti, &si) in t.iter().zip(s) {
        let tn = dyadic(ti, L + sc_e);
        let step = &tn - &prev; // (t_i − t_{i−1})·2^(L + e_s)
        let gap = &step * &sc * &m; // scale·(t_i − t_{i−1})·M·2^L
        let left = &u - gap;
        if left > BigInt::zero() {
            u = left;
            du_sc -= &step;
        } else {
            u = BigInt::zero();
            du_mu = BigInt::zero();
            du_sc = BigInt::zero();
        }
        u += dyadic(si, L - e); // s/μ·M·2^L = s·2^(L − E)
        du_mu -= dyadic(si, L - 2 * e); // s/μ²·M²·2^L = s·2^(L − 2E)
        c += &u;
        dc_mu += &du_mu;
        dc_sc += &du_sc;
        prev = tn;
    }
    let unit = BigInt::from(1) << L as usize;
    let t_unit = BigInt::from(1) << (L + sc_e) as usize;
    let ratio = |num: BigInt, den: BigInt| BigRational::new(num, den).to_f64().unwrap_or(f64::NAN);
    (
        ratio(c, &m * &unit),
        ratio(dc_mu, &m2 * &unit),
        ratio(dc_sc, t_unit),
    )
}

/// The exact C and dC/dμ of the plain queue on (t, s) at μ, as the JSON object
/// `{"mu": μ, "cost": C, "gradient": {"mu": dC/dμ}}` (numbers that read back as the same
/// `f64`): the reference the command-line tests compare `mvad grad --json` against.
pub fn exact_json(t: &[f64], s: &[f64], mu: f64) -> String {
    let (c, g, _) = exact(t, s, mu, 1.0);
    format!("{{\"mu\": {mu:?}, \"cost\": {c:?}, \"gradient\": {{\"mu\": {g:?}}}}}")
}

/// x = m·2^e with m odd (x ≠ 0 finite); (0, 0) for zero.
fn odd_mantissa(x: f64) -> (i64, i32) {
    if x == 0.0 {
        return (0, 0);
    }
    let bits = x.to_bits();
    let sign = if bits >> 63 == 0 { 1 } else { -1 };
    let exp = ((bits >> 52) & 0x7ff) as i32;
    let frac = bits & ((1u64 << 52) - 1);
    let (mut m, mut e) = if exp == 0 {
        (frac as i64, -1074)
    } else {
        ((frac | 1 << 52) as i64, exp - 1075)
    };
    while m % 2 == 0 {
        m /= 2;
        e += 1;
    }
    (sign * m, e)
}

/// x·2^shift as an integer (exact; panics if it is not one, which a shift of 1100 or more
/// past the data's exponents rules out).
fn dyadic(x: f64, shift: i32) -> BigInt {
    let (m, e) = odd_mantissa(x);
    let k = e + shift;
    assert!(k >= 0, "{x}·2^{shift} is not an integer");
    BigInt::from(m) << k as usize
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exact_and_float_recursions_agree_on_small_cases_by_hand() {
        // A_i = 1, 2, 10; s = 2, 2, 1; μ = 1: u = 2, max(2 − 1, 0) + 2 = 3, max(3 − 8, 0) + 1 = 1.
        let (t, s) = ([1.0, 2.0, 10.0], [2.0, 2.0, 1.0]);
        for f in [lindley_ipa, exact] {
            let (c, dmu, dsc) = f(&t, &s, 1.0, 1.0);
            assert_eq!(c, 6.0);
            // du/dμ = −2, −2 − 2 = −4, −1 (idle before the third).
            assert_eq!(dmu, -7.0);
            // du/dscale = 0, −1 (the second waits: its arrival moves by t₂ − t₁), 0.
            assert_eq!(dsc, -1.0);
        }
        assert_eq!(odd_mantissa(1.25), (5, -2));
        assert_eq!(odd_mantissa(-3.0), (-3, 0));
    }

    #[test]
    fn exact_reference_matches_the_float_recursion_to_rounding() {
        let a = Arrivals::generate(2000, 7);
        let (c, dmu, dsc) = lindley_ipa(&a.t, &a.s, 1.25, 0.9);
        let (ce, dmue, dsce) = exact(&a.t, &a.s, 1.25, 0.9);
        for (x, y) in [(c, ce), (dmu, dmue), (dsc, dsce)] {
            assert!(((x - y) / y).abs() < 1e-12, "{x} vs exact {y}");
        }
    }

    #[test]
    fn the_stored_reference_of_queue_csv_is_its_exact_recursion() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
        let table = Table::read_csv(&dir.join("queue.csv")).expect("queue.csv");
        let stored = std::fs::read_to_string(dir.join("queue_exact.json")).expect("stored");
        let (t, s) = (table.column("t").expect("t"), table.column("s").expect("s"));
        assert_eq!(stored.trim(), exact_json(t, s, 1.25));
        let text = std::fs::read_to_string(dir.join("queue.csv")).expect("queue.csv");
        assert_eq!(Arrivals::generate(1000, 1).to_csv(), text);
    }

    #[test]
    fn generated_tables_are_seeded_and_read_back_exactly() {
        let a = Arrivals::generate(50, 3);
        assert_eq!(a, Arrivals::generate(50, 3));
        assert_ne!(a, Arrivals::generate(50, 4));
        assert!(a.t.windows(2).all(|w| w[0] <= w[1]));
        let t = Table::parse_csv("q.csv", a.to_csv()).expect("parses");
        assert_eq!(t.column("t"), Some(&a.t[..]));
        assert_eq!(t.column("s"), Some(&a.s[..]));
    }
}
