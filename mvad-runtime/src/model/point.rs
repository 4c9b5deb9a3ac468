//! Evaluation points: where a model method is evaluated.
//!
//! Every model method takes its (t, x, θ) as one value, so the long argument lists are
//! written once, here, instead of in every method, implementation and call site:
//! - [`Point`]: a point of the flow, (m, frozen branches, t, x, θ), for f and its
//!   derivatives and products;
//! - [`At`]: a point (t, x, θ) of a pointwise function — guards, resets, switching
//!   functions, observables, the costs ℓ (with the frozen branches beside it), φ and Φ;
//! - [`Occurrence`]: which event k fires and its occurrence j (see [`crate::Trigger`]), for
//!   the methods whose value depends on it (resets, event costs, event times).
//!
//! All three are `Copy` and a few words long, passed by value; [`Point::at`] drops the mode
//! and branches of a flow point.

use nalgebra::{allocator::Allocator, DefaultAllocator, Dim, OVector};

/// Frozen branches of the switching functions: bit j set iff σ_j's positive branch is active.
///
/// Any number of switching functions: bits 0..64 live in an inline word (so a model with at
/// most 64 kinks never touches the heap, and generated code reads its bits from
/// [`Switches::low_word`] with a constant mask); bits 64.. live in words allocated once, by
/// [`Switches::new`], for the run. Copy one into another with `clone_from`, which reuses the
/// destination's words, so no step or event allocates.
#[derive(Clone, Debug, Default, Eq)]
pub struct Switches {
    lo: u64,
    hi: Vec<u64>,
}

/// The derived equality, word by word, written out: the derived one compares the (usually
/// empty) `hi` words with `memcmp`, and glibc's AVX-512 `memcmp` of zero bytes at an empty
/// `Vec`'s dangling address takes a masked load's fault-suppression assist, ~100 ns a call (the
/// queue's constant-rate check at every restart spent a third of its time there).
impl PartialEq for Switches {
    #[inline]
    fn eq(&self, other: &Self) -> bool {
        self.lo == other.lo
            && self.hi.len() == other.hi.len()
            && self.hi.iter().zip(&other.hi).all(|(a, b)| a == b)
    }
}

/// What the derived `Hash` would do (consistent with the equality above).
impl std::hash::Hash for Switches {
    fn hash<H: std::hash::Hasher>(&self, state: &mut H) {
        self.lo.hash(state);
        self.hi.hash(state);
    }
}

impl Switches {
    /// All branches negative, with room for `n` switching functions.
    pub fn new(n: usize) -> Self {
        Switches {
            lo: 0,
            hi: vec![0; n.saturating_sub(64).div_ceil(64)],
        }
    }
    /// Bits 0..64 from a word (for at most 64 switching functions).
    pub fn from_bits(bits: u64) -> Self {
        Switches {
            lo: bits,
            hi: Vec::new(),
        }
    }
    /// Bits 0..64 (bit j of the word is bit j of the set).
    #[inline(always)]
    pub fn low_word(&self) -> u64 {
        self.lo
    }
    /// Bit j: whether σ_j's positive branch is active (false beyond the allocated words).
    #[inline(always)]
    pub fn get(&self, j: usize) -> bool {
        if j < 64 {
            self.lo >> j & 1 != 0
        } else {
            self.hi
                .get((j - 64) / 64)
                .is_some_and(|w| w >> ((j - 64) % 64) & 1 != 0)
        }
    }
    /// Sets bit j to `on` (grows the words if j is beyond them: allocate with [`Switches::new`]).
    pub fn set(&mut self, j: usize, on: bool) {
        let (w, b) = if j < 64 {
            (&mut self.lo, j)
        } else {
            let k = (j - 64) / 64;
            if k >= self.hi.len() {
                self.hi.resize(k + 1, 0);
            }
            (&mut self.hi[k], (j - 64) % 64)
        };
        if on {
            *w |= 1 << b;
        } else {
            *w &= !(1 << b);
        }
    }
    /// Flips bit j.
    pub fn flip(&mut self, j: usize) {
        let on = self.get(j);
        self.set(j, !on);
    }
    /// Clears every bit (keeps the words).
    pub fn clear(&mut self) {
        self.lo = 0;
        if !self.hi.is_empty() {
            self.hi.fill(0);
        }
    }
    /// Bits 64.. as words: bit j ≥ 64 is bit (j − 64) % 64 of word (j − 64) / 64.
    pub fn high_words(&self) -> &[u64] {
        &self.hi
    }
}

/// One evaluation point of the flow: mode m, frozen branches, t, x and θ.
///
/// The flow-side methods ([`HybridModel::rhs`](crate::HybridModel::rhs) and its derivatives, and the capability
/// products) take one `Point` instead of five arguments, so every source of flow
/// evaluations (steps, events, an adjoint pass) shares one signature. It is `Copy`: five
/// words, passed by value.
#[derive(Clone, Copy)]
pub struct Point<'a, N: Dim, P: Dim>
where
    DefaultAllocator: Allocator<N> + Allocator<P>,
{
    /// The mode m.
    pub mode: usize,
    /// The frozen branches of the switching functions.
    pub sw: &'a Switches,
    /// Time t.
    pub t: f64,
    /// State x.
    pub x: &'a OVector<f64, N>,
    /// Parameters θ.
    pub p: &'a OVector<f64, P>,
}

impl<'a, N: Dim, P: Dim> Point<'a, N, P>
where
    DefaultAllocator: Allocator<N> + Allocator<P>,
{
    /// The point (m, sw, t, x, θ).
    #[inline(always)]
    pub fn new(
        mode: usize,
        sw: &'a Switches,
        t: f64,
        x: &'a OVector<f64, N>,
        p: &'a OVector<f64, P>,
    ) -> Self {
        Point { mode, sw, t, x, p }
    }

    /// The pointwise part (t, x, θ), without the mode and branches.
    #[inline(always)]
    pub fn at(self) -> At<'a, N, P> {
        At::new(self.t, self.x, self.p)
    }
}

/// A point (t, x, θ) of a pointwise function: guards, resets, switching functions,
/// observables and the costs (see the module doc). It is `Copy`: three words.
#[derive(Clone, Copy)]
pub struct At<'a, N: Dim, P: Dim>
where
    DefaultAllocator: Allocator<N> + Allocator<P>,
{
    /// Time t.
    pub t: f64,
    /// State x.
    pub x: &'a OVector<f64, N>,
    /// Parameters θ.
    pub p: &'a OVector<f64, P>,
}

impl<'a, N: Dim, P: Dim> At<'a, N, P>
where
    DefaultAllocator: Allocator<N> + Allocator<P>,
{
    /// The point (t, x, θ).
    #[inline(always)]
    pub fn new(t: f64, x: &'a OVector<f64, N>, p: &'a OVector<f64, P>) -> Self {
        At { t, x, p }
    }
}

/// Occurrence j of event k: the event that fires and how many times before it has (a guard
/// event) or which of its scheduled times this is (a time event; for `at each`, the table
/// row its reset and cost read). See [`crate::Trigger`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Occurrence {
    /// The event k.
    pub event: usize,
    /// The occurrence j.
    pub j: usize,
}

impl Occurrence {
    /// Occurrence j of event k.
    #[inline(always)]
    pub fn new(event: usize, j: usize) -> Self {
        Occurrence { event, j }
    }
}
