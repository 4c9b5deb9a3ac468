//! Event detection on accepted steps (the paper's Algorithm 1) and bracketed root finding.
//!
//! The driver watches one scalar function per event and per switching function, signed so
//! that a crossing in the armed direction is a crossing of zero *upwards*:
//!
//! - event k with guard g_k and direction d_k ∈ {+1 (`Up`), −1 (`Down`)}: v = d_k·g_k. It fires
//!   when v reaches zero from below (v ≥ 0 after v < 0). After it fires it is *disarmed*
//!   until v has been strictly below min(v_f, 0) again, v_f its value at the state it fired
//!   from (it left zero in the opposite sense), so a guard that is exactly zero after the
//!   reset neither re-triggers nor hides the next crossing. v_f < 0 when the event fired
//!   within the simultaneity window of an earlier crossing, before its own guard had
//!   triggered: its own crossing, a moment later, is the one it already stood for, and
//!   re-arming at v < 0 would fire it a second time there (two guards 10⁻¹² apart fired
//!   one event twice). Every other event is re-armed at a restart iff v ≤ 0 there, so a
//!   guard that starts exactly on zero and is carried into the firing side fires at once (a
//!   ball released on the floor moving down bounces at t = 0);
//! - switching function σ_j with frozen bit b_j: v = −σ_j if b_j is set, +σ_j otherwise. It
//!   triggers when the sign of σ_j strictly disagrees with the bit (v > 0); it is always armed.
//!
//! On each accepted step [t₀, t₁] the watched values are sampled at t₀, at `INTERIOR` interior
//! points of the dense output and at t₁ (when every one is affine in t over the step, as on an
//! exact step of a constant flow, the interior samples are interpolated from the ends: a line
//! has no dips). A sign change between two samples gives a bracket.
//! Two crossings between samples (a near-grazing dip) show up as an interior local maximum of
//! v that is close to zero relative to v's variation over the step; then v is maximised
//! on the neighbouring samples' interval by golden-section search and, if the maximum
//! reaches zero, the bracket [left sample, argmax] is used. On the first step after an event
//! fired, a guard that never went below zero at the samples is minimised between t₀ and the
//! first sample, so a whole hop that fits in there is not missed. Roots are found by safeguarded
//! secant/regula-falsi steps with bisection fallback (see [`locate_root`]) to the resolution
//! of t (relative ~1e-15), returning the end of the bracket where the function has triggered, so the state
//! handed to the reset is always on or past the guard.

/// Interior samples per step for sign-change detection.
pub const INTERIOR: usize = 4;

/// Number of samples per step (t₀, the interior points, t₁).
const NSAMP: usize = INTERIOR + 2;

/// Whether the watched value `v` has triggered (`strict`: v > 0, else v ≥ 0).
#[inline]
fn triggered(v: f64, strict: bool) -> bool {
    if strict {
        v > 0.0
    } else {
        v >= 0.0
    }
}

/// Finds the crossing of a continuous `f` in [a, b] where `f(a)` has not triggered and `f(b)`
/// has (triggered: v > 0 if `strict`, else v ≥ 0): secant steps through the last two
/// iterates when they land inside the bracket (superlinear), regula falsi on the bracket
/// otherwise, a bisection step after three iterations that failed to halve the bracket, and
/// every iterate at least one resolution step inside the bracket (so the bracket collapses
/// from both sides, as in Brent's method). Stops when the bracket is below 2 ulp of t (or after 200
/// evaluations) and returns the triggered end b, so the returned time is never before the
/// crossing.
pub fn locate_root<F: FnMut(f64) -> f64>(
    mut f: F,
    mut a: f64,
    mut fa: f64,
    mut b: f64,
    mut fb: f64,
    strict: bool,
) -> f64 {
    if !strict && fb == 0.0 {
        // Exactly on the guard at b (a touch of zero before b inside a bracket this narrow is
        // below the sampling's resolution).
        return b;
    }
    let mut width = b - a;
    let mut slow = 0; // consecutive iterations that did not halve the bracket
                      // The last two iterates, for the secant step (the better end last).
    let (mut p, mut fp, mut q, mut fq) = if fa.abs() < fb.abs() {
        (b, fb, a, fa)
    } else {
        (a, fa, b, fb)
    };
    for _ in 0..200 {
        let tol = 2.0 * f64::EPSILON * a.abs().max(b.abs()) + f64::MIN_POSITIVE;
        if b - a <= 2.0 * tol {
            break;
        }
        let mut c = 0.5 * (a + b);
        if slow < 3 {
            let secant = if fq != fp {
                q - fq * (q - p) / (fq - fp)
            } else {
                f64::NAN
            };
            c = if secant > a && secant < b {
                secant
            } else if fb != fa {
                b - fb * (b - a) / (fb - fa)
            } else {
                c
            };
        }
        // Keep c at least `tol` inside the bracket, so that once the secant lands on the
        // root the next iterate crosses it and the bracket collapses.
        c = c.clamp(a + tol, b - tol);
        let fc = f(c);
        if fc.is_nan() {
            // Stop here: the driver evaluates the guard at the returned time again and
            // reports the NaN with the expression it came from.
            b = c;
            break;
        }
        if triggered(fc, strict) {
            b = c;
            fb = fc;
            if !strict && fc == 0.0 {
                break;
            }
        } else {
            a = c;
            fa = fc;
        }
        (p, fp, q, fq) = (q, fq, c, fc);
        slow = if b - a > 0.5 * width { slow + 1 } else { 0 };
        width = b - a;
    }
    b
}

/// Golden-section search for the maximum of `f` on [a, b] (30 iterations, the interval
/// shrinks by 0.618³⁰ ≈ 5·10⁻⁷), refined by the vertex of the parabola through the last two
/// points and their midpoint. Returns (argmax, max) among the evaluated points.
pub fn maximize<F: FnMut(f64) -> f64>(mut f: F, a: f64, b: f64) -> (f64, f64) {
    const R: f64 = 0.618_033_988_749_894_9;
    let (mut lo, mut hi) = (a, b);
    let mut c = hi - R * (hi - lo);
    let mut d = lo + R * (hi - lo);
    let mut fc = f(c);
    let mut fd = f(d);
    for _ in 0..30 {
        if fc >= fd {
            hi = d;
            d = c;
            fd = fc;
            c = hi - R * (hi - lo);
            fc = f(c);
        } else {
            lo = c;
            c = d;
            fc = fd;
            d = lo + R * (hi - lo);
            fd = f(d);
        }
    }
    // The vertex of the parabola through c, their midpoint and d: exact for a quadratic, so a
    // peak narrower than the final interval (a guard that rises above zero only within 1e-7 of
    // its vertex) is not missed.
    let m = 0.5 * (c + d);
    let fm = f(m);
    let best = [(c, fc), (m, fm), (d, fd)]
        .into_iter()
        .fold((c, fc), |b, p| if p.1 > b.1 { p } else { b });
    let curvature = fc - 2.0 * fm + fd;
    if curvature < 0.0 {
        let vertex = m + 0.25 * (d - c) * (fc - fd) / curvature;
        if vertex > lo && vertex < hi {
            let fv = f(vertex);
            if fv > best.1 {
                return (vertex, fv);
            }
        }
    }
    best
}

/// What a watched function is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Watch {
    /// User event k (index into `ModelInfo::events`).
    Event(usize),
    /// Switching function σ_j.
    Switch(usize),
}

/// A crossing found on the current step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Crossing {
    /// Index of the watched function (events first, then switches).
    pub w: usize,
    /// Located time.
    pub t: f64,
}

/// The detection state of one watched function (one record per function, so a restart or
/// a scan touches one place per function).
#[derive(Clone, Copy, Debug, Default)]
pub struct Track {
    /// Watched in the current mode (switches: always).
    pub active: bool,
    /// Armed (switches: always).
    pub armed: bool,
    /// v was increasing at the end of the previous step (dip detection at t₀).
    pub rising: bool,
    /// The rise of v over the last sample interval of the previous step and that interval's
    /// length (0 and 1 after a restart): their ratio is dv/dt there, what a guard just short
    /// of zero needs to reach it (see [`Scanner::join_events_due`]).
    pub last_rise: f64,
    /// See `last_rise`.
    pub last_span: f64,
    /// The event fired at the last restart and this is the first step since (see
    /// [`Scanner::scan`]: a whole excursion below zero may hide before the first sample).
    pub fresh: bool,
    /// A disarmed function re-arms once v < `rearm_below`: min(v_f, 0) for the event that
    /// fired at the last restart from the value v_f, 0 for every other.
    pub rearm_below: f64,
    /// Signed value v at the start of the current step.
    pub start_val: f64,
    /// The bracket of the current step, if any.
    bracket: Option<(f64, f64, f64, f64)>,
    /// The highest maximum (t, v) the dip search evaluated on the current step, if it ran:
    /// v ≥ 0 when it closed a bracket (a crossing found as a dip), v < 0 when it did not (a
    /// near miss if v lies within the guard's uncertainty of zero; see [`Scanner::peak`]).
    peak: Option<(f64, f64)>,
}

impl Track {
    /// Commits the line from v₀ = `a` at the start of a step to v₁ = `b` at its end, `span`
    /// later, on which the function has not crossed: it re-arms if the line went below its
    /// re-arming level (a line that fired at t₀ and starts below that level was armed at
    /// the restart; one that starts above it and falls re-arms only past t₁: a line has its
    /// minimum at an end), and v₁, the rise over the last sample interval (the one
    /// `bracket_curve` would have interpolated) and the rise over the step start the next.
    #[inline]
    fn commit_line(&mut self, a: f64, b: f64, span: f64) {
        let below = self.rearm_below;
        if !self.armed && (a < below || b < below) {
            self.armed = true;
        }
        self.start_val = b;
        self.rising = b > line_sample(a, b, NSAMP - 2);
        self.last_rise = b - a;
        self.last_span = span;
    }
}

/// Where the watched lines of a segment first reach zero, predicted from their values at its
/// start and their rates (see [`Scanner::first_line_root`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LineRoot {
    /// No armed line reaches zero before the segment's stop.
    Beyond,
    /// Line w is the first to reach zero, at the predicted time t (t₀ − v₀/v̇ as rounded),
    /// and no other line reaches it within the simultaneity window after t.
    At(usize, f64),
    /// The closed form does not decide alone: an armed line on or past zero at t₀ (it fires
    /// there, or its value is NaN), or a second line reaching zero within the simultaneity
    /// window of the first. The step is scanned as any other.
    Scan,
}

/// Per-run event-detection state: which functions are watched, armed flags, the values at
/// the start of the current step, and scratch for the samples (all allocated once).
#[derive(Clone, Debug)]
pub struct Scanner {
    /// Number of user events; watched index w < nevents is event w, else switch w − nevents.
    pub nevents: usize,
    /// The state of function w.
    pub tracks: Vec<Track>,
    /// The watched functions, in the order they were restarted (ascending w): every loop of
    /// a scan walks this list, never all functions (see [`Scanner::begin_restart`]).
    watched: Vec<usize>,
    /// Crossings on the current step, earliest first (filled by [`Scanner::scan`]).
    pub found: Vec<Crossing>,
    /// Samples per function: `vals[w][i]` at the i-th sample time of the step.
    vals: Vec<[f64; NSAMP]>,
    /// One sample of every function, as written by the caller.
    tmp: Vec<f64>,
    /// Some watched event's dip search evaluated a maximum on the current step (see
    /// [`Scanner::peak`]).
    peaked: bool,
}

impl Scanner {
    /// A scanner for `nevents` events and `nswitches` switching functions.
    pub fn new(nevents: usize, nswitches: usize) -> Self {
        let nw = nevents + nswitches;
        Scanner {
            nevents,
            tracks: vec![Track::default(); nw],
            watched: Vec::with_capacity(nw),
            found: Vec::with_capacity(nw),
            vals: vec![[0.0; NSAMP]; nw],
            tmp: vec![0.0; nw],
            peaked: false,
        }
    }

    /// Number of watched functions.
    pub fn len(&self) -> usize {
        self.tracks.len()
    }

    /// Whether nothing is watched at all.
    pub fn is_empty(&self) -> bool {
        self.tracks.is_empty()
    }

    /// What watched function `w` is.
    pub fn watch(&self, w: usize) -> Watch {
        if w < self.nevents {
            Watch::Event(w)
        } else {
            Watch::Switch(w - self.nevents)
        }
    }

    /// The highest maximum (t, v) of function w's signed value that the dip search of the
    /// last scan evaluated, if it ran: v ≥ 0 when that maximum closed w's bracket (the
    /// crossing is a dip's: the trajectory reaches the surface only by v over it), v < 0 when
    /// it did not (the trajectory turned back v short of the surface). Either is undecided
    /// when |v| is within what the tolerances allow the guard to err by.
    pub fn peak(&self, w: usize) -> Option<(f64, f64)> {
        self.tracks[w].peak
    }

    /// Whether the last scan's dip search evaluated a maximum of an event's guard (see
    /// [`Scanner::peak`]).
    pub fn peaked(&self) -> bool {
        self.peaked
    }

    /// Whether function `w` triggers on v > 0 (switches) rather than v ≥ 0 (events).
    pub fn strict(&self, w: usize) -> bool {
        w >= self.nevents
    }

    /// Starts a restart: nothing is watched until [`Scanner::restart_one`] activates it
    /// (the other fields of an unwatched function are set again when it is). O(number
    /// watched before), not O(number of functions).
    #[inline]
    pub fn begin_restart(&mut self) {
        for &w in &self.watched {
            self.tracks[w].active = false;
        }
        self.watched.clear();
    }

    /// The functions watched since the last restart.
    pub fn watched(&self) -> &[usize] {
        &self.watched
    }

    /// (Re)activates function w at a restart with its signed value `v` at the new state:
    /// events are armed iff v ≤ 0 (a guard that starts exactly on zero fires at once if the
    /// flow carries it into the firing side), except an event that just fired from the
    /// signed value v_f (`fired` = `Some(v_f)`), which is disarmed until v < min(v_f, 0)
    /// (armed at once if v⁺ already is); switches are always armed.
    #[inline(always)]
    pub fn restart_one(&mut self, w: usize, v: f64, fired: Option<f64>) {
        let strict = self.strict(w);
        let tr = &mut self.tracks[w];
        if !tr.active {
            tr.active = true;
            self.watched.push(w);
        }
        tr.start_val = v;
        tr.peak = None;
        tr.rising = false;
        tr.last_rise = 0.0;
        tr.last_span = 1.0;
        tr.fresh = fired.is_some() && !strict;
        let below = fired.map_or(0.0, |vf| vf.min(0.0));
        tr.rearm_below = below;
        tr.armed = if strict {
            true
        } else if fired.is_some() {
            v < below
        } else {
            v <= 0.0
        };
    }

    /// Adds to `found`, at t, every armed event whose value at the end of the last step
    /// reaches zero within `window` at its slope there (v + max(v̇, 0)·window ≥ 0, v̇ the last
    /// rise over its span).
    #[inline]
    pub fn join_events_due(&mut self, t: f64, window: f64) {
        for &w in &self.watched {
            if w < self.nevents {
                let tr = &self.tracks[w];
                if tr.armed && tr.start_val * tr.last_span + tr.last_rise.max(0.0) * window >= 0.0 {
                    self.found.push(Crossing { w, t });
                }
            }
        }
    }

    /// Scans the accepted step [t0, t1] for crossings. With `linear` (every active watched
    /// value is affine in t over the step: an exact step of a constant flow and affine guards)
    /// only the values at t0 and t1 are evaluated: the interior samples are interpolated
    /// (exact for a line), and there are no dips to search.
    ///
    /// `sample(t, is_end, watched, vals)` must write the signed value v_w(t) of every watched w
    /// (the list [`Scanner::watched`]) into `vals[w]` (using the dense output inside the step
    /// and the exact end state at t1).
    /// `eval(w, t)` evaluates one function at an interior time (for root finding and dip
    /// search). Crossings no later than `earliest + sim_tol` land in `self.found`, sorted by
    /// index w (declaration order, events before switches). Returns `Err((w, t))` when a
    /// watched value is NaN.
    ///
    /// When no crossing is found, the armed flags and start values are committed for the
    /// next step; otherwise the caller restarts every function after handling the event.
    #[allow(clippy::too_many_arguments)]
    pub fn scan<S, E>(
        &mut self,
        t0: f64,
        t1: f64,
        linear: bool,
        sample: S,
        mut eval: E,
        sim_tol: f64,
    ) -> Result<(), (usize, f64)>
    where
        S: FnMut(f64, bool, &[usize], &mut [f64]),
        E: FnMut(usize, f64) -> f64,
    {
        self.found.clear();
        self.peaked = false;
        if self.watched.is_empty() {
            return Ok(());
        }
        let first_right = if linear {
            self.bracket_line(t0, t1, sample)?
        } else {
            self.bracket_curve(&sample_times(t0, t1), sample, &mut eval)?
        };
        if first_right.is_infinite() {
            // Commit the step (`bracket_line` has committed every line already).
            if linear {
                return Ok(());
            }
            for i in 0..self.watched.len() {
                let w = self.watched[i];
                let v = &self.vals[w];
                let tr = &mut self.tracks[w];
                if !tr.armed && v.iter().any(|&x| x < tr.rearm_below) {
                    tr.armed = true;
                }
                tr.start_val = v[NSAMP - 1];
                tr.rising = v[NSAMP - 1] > v[NSAMP - 2];
                tr.last_rise = v[NSAMP - 1] - v[NSAMP - 2];
                tr.last_span = (t1 - t0) / (NSAMP - 1) as f64;
            }
            return Ok(());
        }
        // Roots for brackets that can compete with the earliest.
        let mut earliest = f64::INFINITY;
        for i in 0..self.watched.len() {
            let w = self.watched[i];
            if let Some((a, fa, b, fb)) = self.tracks[w].bracket {
                if a > first_right {
                    continue;
                }
                let strict = self.strict(w);
                // A bracket whose left end is already on zero (an armed guard that starts
                // exactly on its surface and moves into the firing side) fires at that end.
                let t = if triggered(fa, strict) {
                    a
                } else {
                    locate_root(|t| eval(w, t), a, fa, b, fb, strict)
                };
                earliest = earliest.min(t);
                self.found.push(Crossing { w, t });
            }
        }
        let limit = earliest + sim_tol;
        self.found.retain(|c| c.t <= limit);
        Ok(())
    }

    /// The brackets of a step on which every active watched value is affine in t (see
    /// [`Scanner::scan`]): only v at t₁ is evaluated. A line that is armed at t₀ (or fired there
    /// and starts below zero) crosses on the step iff v(t₁) has triggered, and its bracket is
    /// the one the equispaced samples would give, [s_{i−1}, s_i] around the first interpolated
    /// sample that has triggered. Returns the earliest right end of a bracket (∞ if none).
    /// A line without a bracket is committed for the next step at once (a bracket means an
    /// event and a restart of every function).
    fn bracket_line<S>(&mut self, t0: f64, t1: f64, mut sample: S) -> Result<f64, (usize, f64)>
    where
        S: FnMut(f64, bool, &[usize], &mut [f64]),
    {
        sample(t1, true, &self.watched, &mut self.tmp);
        let mut first_right = f64::INFINITY;
        for i in 0..self.watched.len() {
            let (w, strict, a, b) = self.line_ends(i, t0, t1)?;
            let tr = &mut self.tracks[w];
            if !(tr.armed && triggered(b, strict)) {
                tr.commit_line(a, b, t1 - t0);
                continue;
            }
            let times = sample_times(t0, t1);
            let mut prev = a;
            for (i, &ti) in times.iter().enumerate().skip(1) {
                let vi = if i == NSAMP - 1 {
                    b
                } else {
                    line_sample(a, b, i)
                };
                if triggered(vi, strict) {
                    tr.bracket = Some((times[i - 1], prev, ti, vi));
                    first_right = first_right.min(ti);
                    break;
                }
                prev = vi;
            }
        }
        Ok(first_right)
    }

    /// The i-th watched function w of a step of lines [t₀, t₁], its value just sampled at t₁
    /// in `tmp`: its bracket, peak and freshness cleared (a line has no dip, and the step
    /// has begun), and (w, strict, v(t₀), v(t₁)); `Err((w, t))` where the line is NaN.
    #[inline(always)]
    fn line_ends(
        &mut self,
        i: usize,
        t0: f64,
        t1: f64,
    ) -> Result<(usize, bool, f64, f64), (usize, f64)> {
        let w = self.watched[i];
        let strict = self.strict(w);
        let b = self.tmp[w];
        let tr = &mut self.tracks[w];
        tr.bracket = None;
        tr.peak = None;
        tr.fresh = false;
        let a = tr.start_val;
        if let Some(t) = line_nan_at(t0, t1, a, b) {
            return Err((w, t));
        }
        Ok((w, strict, a, b))
    }

    /// On a segment on which every watched value is a line, v_w(t) = v_w(t₀) + v̇_w (t − t₀)
    /// with v_w(t₀) the start value and v̇_w = `slope[w]` (an exact segment of a constant flow
    /// and affine guards): where the first armed line reaches zero, t₀ − v_w(t₀)/v̇_w, if before
    /// `t_stop`. Only an armed line rising towards zero can cross: a falling or flat line
    /// stays below zero, and a disarmed line does not fire on the segment (it re-arms only
    /// below its re-arming level ≤ 0, and a line that went there cannot come back up). A line
    /// has no turning point, so there is no dip to search and no near miss to judge, and its
    /// crossing is transversal unless v̇ = 0, which never crosses.
    pub fn first_line_root(&self, t0: f64, t_stop: f64, slope: &[f64], sim_tol: f64) -> LineRoot {
        let (mut first, mut t_first, mut t_second) = (usize::MAX, f64::INFINITY, f64::INFINITY);
        for &w in &self.watched {
            let tr = &self.tracks[w];
            if !tr.armed {
                continue;
            }
            let v0 = tr.start_val;
            // On or past zero (or NaN): not below it.
            if v0 >= 0.0 || v0.is_nan() {
                return LineRoot::Scan;
            }
            let rate = slope[w];
            // Falling, flat (or NaN: the slopes are checked finite when they are made).
            if rate <= 0.0 || rate.is_nan() {
                continue;
            }
            let t = t0 + (-v0) / rate;
            if t < t_first {
                (first, t_first, t_second) = (w, t, t_first);
            } else if t < t_second {
                t_second = t;
            }
        }
        if t_first > t_stop {
            LineRoot::Beyond
        } else if t_second <= t_first + sim_tol {
            LineRoot::Scan
        } else {
            LineRoot::At(first, t_first)
        }
    }

    /// Closes a segment of lines at its end t₁ (see [`Scanner::first_line_root`]): `sample`
    /// writes every watched value at t₁ (as for [`Scanner::scan`]); an armed line that has
    /// triggered there is a crossing at t₁ (into `found`), every other line is committed for
    /// the next step. Returns `Err((w, t))` when a watched value is NaN.
    pub fn close_lines<S>(&mut self, t0: f64, t1: f64, mut sample: S) -> Result<(), (usize, f64)>
    where
        S: FnMut(f64, bool, &[usize], &mut [f64]),
    {
        self.found.clear();
        self.peaked = false;
        sample(t1, true, &self.watched, &mut self.tmp);
        for i in 0..self.watched.len() {
            let (w, strict, a, b) = self.line_ends(i, t0, t1)?;
            let tr = &mut self.tracks[w];
            if tr.armed && triggered(b, strict) {
                self.found.push(Crossing { w, t: t1 });
            } else {
                tr.commit_line(a, b, t1 - t0);
            }
        }
        Ok(())
    }

    /// The brackets of a step of a curve: v sampled at t₀ (the start value), the interior
    /// samples of the dense output and t₁; a sign change between two samples, or a dip found
    /// by [`dip`], or a whole excursion before the first sample after a firing. Returns the
    /// earliest right end of a bracket (∞ if none).
    fn bracket_curve<S, E>(
        &mut self,
        times: &[f64; NSAMP],
        mut sample: S,
        eval: &mut E,
    ) -> Result<f64, (usize, f64)>
    where
        S: FnMut(f64, bool, &[usize], &mut [f64]),
        E: FnMut(usize, f64) -> f64,
    {
        for &w in &self.watched {
            self.vals[w][0] = self.tracks[w].start_val;
        }
        for (i, &t) in times.iter().enumerate().skip(1) {
            sample(t, i == NSAMP - 1, &self.watched, &mut self.tmp);
            for &w in &self.watched {
                self.vals[w][i] = self.tmp[w];
            }
        }
        let mut first_right = f64::INFINITY;
        for wi in 0..self.watched.len() {
            let w = self.watched[wi];
            self.tracks[w].bracket = None;
            let v = self.vals[w];
            if let Some(i) = v.iter().position(|x| x.is_nan()) {
                return Err((w, times[i]));
            }
            let strict = self.strict(w);
            let Track {
                mut armed,
                rearm_below: below,
                rising,
                fresh,
                ..
            } = self.tracks[w];
            let mut armed_from = if armed { Some(0) } else { None };
            let mut bracket = None;
            let mut peak = None;
            for i in 1..NSAMP {
                let vi = v[i];
                if !armed {
                    if vi < below {
                        armed = true;
                        armed_from = Some(i);
                    }
                } else if triggered(vi, strict) {
                    bracket = Some((times[i - 1], v[i - 1], times[i], vi));
                    break;
                }
            }
            if bracket.is_none() {
                if let Some(i0) = armed_from {
                    (bracket, peak) = dip(&v, times, i0, rising, strict, |t| eval(w, t));
                    self.peaked |= w < self.nevents && peak.is_some();
                } else if fresh {
                    // The event fired at t₀ and no sample went below its re-arming level:
                    // the whole excursion to the negative side and back (a short hop of a
                    // ball after its bounce) may lie between t₀ and the first sample. Look
                    // for the minimum there; if it is below the level the event re-armed at
                    // that time and the first sample, which has triggered, closes the bracket.
                    let (tm, neg) = maximize(|t| -eval(w, t), times[0], times[1]);
                    if -neg < below && triggered(v[1], strict) {
                        bracket = Some((tm, -neg, times[1], v[1]));
                    }
                }
            }
            if let Some(b) = bracket {
                first_right = first_right.min(b.2);
            }
            let tr = &mut self.tracks[w];
            tr.fresh = false;
            tr.bracket = bracket;
            tr.peak = peak;
        }
        Ok(first_right)
    }
}

/// Sample i of the line from `a` (at t₀) to `b` (at t₁) at the equispaced sample times.
#[inline]
fn line_sample(a: f64, b: f64, i: usize) -> f64 {
    a + (b - a) * (i as f64 / (NSAMP - 1) as f64)
}

/// Where the samples of the line from `a` (at t₀) to `b` (at t₁) would first be NaN, if
/// either is: t₀, or the first interior sample time.
fn line_nan_at(t0: f64, t1: f64, a: f64, b: f64) -> Option<f64> {
    if a.is_nan() {
        Some(t0)
    } else if b.is_nan() {
        Some(sample_times(t0, t1)[1])
    } else {
        None
    }
}

/// The sample times of a step: t₀, the interior points, t₁ (exactly).
fn sample_times(t0: f64, t1: f64) -> [f64; NSAMP] {
    let h = t1 - t0;
    let mut times = [t1; NSAMP];
    for (i, t) in times.iter_mut().enumerate().take(NSAMP - 1) {
        *t = t0 + h * (i as f64) / ((NSAMP - 1) as f64);
    }
    times
}

/// Looks for a double crossing hidden between the samples `v` of one function (armed from
/// sample i0 on): an interior local maximum of v that is close to zero relative to v's
/// variation over the step, or a maximum just after t₀ when v was `rising` at the end of the
/// last step. Returns the bracket [left sample, argmax] if a maximum has triggered, and the
/// highest maximum evaluated (t, v) (the one that triggered, if one did).
#[allow(clippy::type_complexity)]
fn dip<E: FnMut(f64) -> f64>(
    v: &[f64; NSAMP],
    times: &[f64; NSAMP],
    i0: usize,
    rising: bool,
    strict: bool,
    mut eval: E,
) -> (Option<(f64, f64, f64, f64)>, Option<(f64, f64)>) {
    let (lo, hi) = v
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &x| {
            (lo.min(x), hi.max(x))
        });
    let spread = hi - lo;
    let close = |vi: f64| -vi < 0.5 * spread;
    // A maximum near sample i: search [s_{i−1}, s_{i+1}] (or [s₀, s₁] for i = 0).
    let mut candidates = [usize::MAX; NSAMP];
    let mut nc = 0;
    if i0 == 0 && rising && v[0] >= v[1] && close(v[0]) {
        candidates[nc] = 0;
        nc += 1;
    }
    for i in (i0 + 1).max(1)..NSAMP - 1 {
        if v[i] > v[i - 1] && v[i] >= v[i + 1] && close(v[i]) {
            candidates[nc] = i;
            nc += 1;
        }
    }
    // A maximum between the last interior sample and t₁, which the samples see only as a
    // rise: the parabola through the last three samples is concave and peaks inside
    // (s_{N−2}, t₁). Without this the next step, starting past the peak, sees only a fall.
    let last = NSAMP - 1;
    if i0 < last && v[last] > v[last - 1] && close(v[last]) && peaks_before_end(v) {
        candidates[nc] = last;
        nc += 1;
    }
    let mut peak: Option<(f64, f64)> = None;
    for &i in &candidates[..nc] {
        let left = i.saturating_sub(1);
        let right = if i == 0 { 1 } else { (i + 1).min(last) };
        let (tm, vm) = maximize(&mut eval, times[left], times[right]);
        if triggered(vm, strict) {
            return (Some((times[left], v[left], tm, vm)), Some((tm, vm)));
        }
        if peak.is_none_or(|(_, best)| vm > best) {
            peak = Some((tm, vm));
        }
    }
    (None, peak)
}

/// Whether the parabola through the last three (equispaced) samples of `v` is concave with
/// its vertex strictly between the last two sample times. With the samples v_a, v_b, v_c at
/// −d, 0, d the vertex lies at s* = d (v_a − v_c) / (2 (v_a − 2 v_b + v_c)).
fn peaks_before_end(v: &[f64; NSAMP]) -> bool {
    let (va, vb, vc) = (v[NSAMP - 3], v[NSAMP - 2], v[NSAMP - 1]);
    let curvature = va - 2.0 * vb + vc;
    if curvature.is_nan() || curvature >= 0.0 {
        return false;
    }
    let vertex = (va - vc) / (2.0 * curvature);
    vertex > 0.0 && vertex < 1.0
}

#[cfg(test)]
mod tests;
