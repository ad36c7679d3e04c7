//! One-dimensional speed profiles along one path segment: the building block of the look-ahead
//! (issue 4, items 3 and 4).
//!
//! Pure, allocation-free and panic-free. A segment of length `L > 0` is run from the start speed
//! `v0 ≥ 0` to the end speed `v1 ≥ 0`, with zero acceleration at both ends, under a speed cap
//! `vmax`, an acceleration limit `amax` and a jerk limit `jmax` ([`ProfileLimits`]).
//!
//! Units in names: `_mm` millimetres, `_mm_s` mm/s, `_mm_s2` mm/s², `_mm_s3` mm/s³, `_s`
//! seconds.
//!
//! # Profiles
//!
//! Every profile has the seven phases of the S-curve (`shared/seeds` 001, eqs. 14–21), some of
//! them possibly of zero duration:
//!
//! | phase | 0 | 1 | 2 | 3 | 4 | 5 | 6 |
//! |-------|---|---|---|---|---|---|---|
//! | jerk  | +σ₁J | 0 | −σ₁J | 0 | +σ₂J | 0 | −σ₂J |
//! | what  | jerk | constant acceleration | jerk | cruise at `vc` | jerk | constant acceleration | jerk |
//!
//! i.e. a *transition* from `v0` to the cruise speed `vc`, a cruise, and a transition from `vc`
//! to `v1` (σ is the sign of each transition: `vc ≥ v0, v1` in a time-optimal profile, anything
//! in a [stretched](SpeedProfile::stretch_to_period) one). Three families share this structure
//! and all the code:
//!
//! - the **trapezoid**: `jmax = ∞` ([`ProfileLimits::trapezoid`]); the jerk phases vanish and the
//!   results are those of the exact-stop planner's `trapezoid` (with start and end speeds);
//! - the **S-curve** ([`JerkShape::Square`]): jerk ±`jmax` or 0 in each phase;
//! - the **jerk-continuous S-curve** ([`JerkShape::RaisedCosine`], 001 problem 4): each jerk
//!   phase of duration `Tj` is one raised-cosine pulse `J(τ) = (J/2)(1 − cos 2πτ/Tj)` with peak
//!   `J = jmax`, so the acceleration is C¹ and the jerk continuous. A pulse changes the
//!   acceleration by `J·Tj/2` and its acceleration edge is point-symmetric like the square
//!   one's, so phase durations, transition times and transition lengths are those of the
//!   square S-curve with the *effective jerk* `jmax/2`; only the evaluation inside a pulse
//!   differs.
//!
//! # Method
//!
//! A transition between the speeds `va` and `vb` (`Δ = |vb − va|`, effective jerk `j`) is the
//! time-optimal one: with `vA = amax²/j`,
//!
//! - `Δ ≥ vA`: `Tj = amax/j`, constant-acceleration phase `Ta = Δ/amax − amax/j`;
//! - `Δ < vA`: `Tj = √(Δ/j)`, no constant-acceleration phase, peak acceleration `√(Δ·j)`;
//!
//! its duration is `t = 2Tj + Ta` and, its acceleration being symmetric in time, its length is
//! `d(va, vb) = (va + vb)/2 · t` ([`transition_length_mm`]; symmetric in `va`, `vb`).
//!
//! **Plan** ([`plan`]): a profile of the family of 001 (speed up to a peak `vp ≥ max(v0, v1)`,
//! cruise, speed down) exists iff `d(v0, v1) ≤ L`, the only reason for `None` on valid inputs.
//! (Stopping first and starting again can fit in less length than a slow start, e.g.
//! `d(0.1·v, 0) + d(0, v) < d(0.1·v, v)` below `amax`; such profiles are outside the family, and
//! the look-ahead's passes never need them.) The total length `D(vp) = d(v0, vp) + d(vp, v1)` of the two
//! transitions through a peak `vp ≥ max(v0, v1)` increases strictly with `vp`, and the duration
//! `T(vp) = t(v0,vp) + t(vp,v1) + (L − D(vp))/vp` decreases wherever `D(vp) ≤ L` (its derivative
//! is `−(L − D)/vp² − Σ(d′ − vp·t′)/vp` and `d′ ≥ vp·t′` in every regime), so the time-optimal
//! peak is `vmax` if `D(vmax) ≤ L` (cruise present) and otherwise the root of `D(vp) = L`. The
//! regime of each transition changes at `vp = v0 + vA` and `vp = v1 + vA`; between these
//! breakpoints:
//!
//! - both transitions reach `amax`: `D` is a quadratic in `vp`, solved in **closed form**
//!   `vp = (−vA + √((vA − v0 − v1)² + (v0 − v1)² + 4·amax·L))/2` (also the trapezoid);
//! - neither reaches `amax` and `v0 = v1`: with `x = √(vp − v0)`, `x³ + 2·v0·x = L·√j/2`, a
//!   depressed cubic with one real root, solved by **Newton from an upper bound**, on which
//!   the cubic's convexity makes the iterates fall monotonically onto the root in a few steps;
//! - otherwise (one transition at `amax` and the other not, or neither with `v0 ≠ v1`): `D` is a
//!   quartic in `√(vp − vi)`, or a sum of two different square roots; no closed form worth its
//!   rounding, so a **bracketed solve**: safeguarded Newton on `D(vp) − L` inside the regime's
//!   bracket, falling back to bisection, seeded by Newton in `x = √(vp − max(v0, v1))`, in
//!   which `D` is convex (in `vp` it has a vertical tangent at `max(v0, v1)`, which made the
//!   bracketed Newton fall back to bisection on short segments whose peak is barely above a
//!   boundary speed, the look-ahead's common case).
//!
//! The closed forms only seed the same bracketed refinement (one or two Newton steps), which
//! returns a peak with `D(vp) ≤ L` *as computed*; the remainder `L − D(vp)` (zero, a few ulps,
//! or the real cruise) becomes the cruise `(L − D)/vp`. The length is thus exact by
//! construction, whatever the solve's last bit.
//!
//! **Reachability** ([`max_end_speed`], [`max_start_speed`]): the largest `v1 ≥ v0` with
//! `d(v0, v1) ≤ L`, capped at `vmax`; both in **closed form** (`d` is a quadratic in `Δ` when
//! `amax` is reached) or by the same monotone Newton on a depressed cubic in `√Δ` (otherwise),
//! then refined and adjusted by a few ulps with the
//! very predicate [`plan`] uses, so that a returned speed is always feasible in [`plan`] and the
//! next one up is not. `d` being symmetric, the two functions are the same function; both are
//! provided for the look-ahead's two passes. Feasible speeds *above* the known one form an
//! interval (`d` increases with the higher speed), which is what the passes rely on; feasible
//! end speeds *below* `v0` need not (slowing a little can take longer than stopping).
//!
//! **Integer periods** (000, [`SpeedProfile::stretch_to_period`]): the duration is rounded up to
//! a whole number of periods by lowering the cruise speed `vc` (the transitions stay
//! time-optimal, so no limit is exceeded, and the cruise absorbs the length exactly); `T(vc)`
//! decreases with `vc` wherever the transitions fit, so this is a bisection on `vc`, from the
//! time-optimal `vc` down to 0, then, if that ends on the edge of the feasible set, in the
//! highest of 256 slices of `(0, vc]` that brackets a root. `vc` may fall below a boundary
//! speed (a dip: a segment cruising through at `v0 = v1` can only be stretched so). A profile
//! without slack (e.g. a segment that accelerates over its whole length to `max_end_speed`, or
//! nearly so) cannot be stretched: the error says so and the look-ahead must lower a boundary
//! speed.
//!
//! **Evaluation** ([`SpeedProfile::at`]): the start state of each phase is stored, so a sample is
//! a scan over seven phase ends and one polynomial (plus two sines inside a cosine pulse):
//! no allocation, no solving. At the start of a phase the stored state is returned exactly, the
//! second transition is anchored at the end (`s = L − d(vc, v1)`), and at and after the end the
//! sample is exactly `(L, v1, 0, 0)`.

use std::f64::consts::PI;

use super::MAX_LIMIT;

/// Smallest value accepted for a limit in [`ProfileLimits`].
pub const MIN_LIMIT: f64 = 1.0e-9;

/// Longest segment accepted by [`plan`] and the reachability functions; keeps products such as
/// `amax·L` far from overflow.
pub const MAX_LENGTH_MM: f64 = 1.0e12;

/// Shape of the jerk pulses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum JerkShape {
    /// Jerk ±`jmax` or 0 (the classic 7-phase S-curve; acceleration continuous, jerk not).
    Square,
    /// Each jerk phase is one raised-cosine pulse `(jmax/2)(1 − cos 2πτ/Tj)` (acceleration C¹,
    /// jerk continuous); equivalent for durations and lengths to [`Square`](Self::Square) with
    /// half the jerk.
    RaisedCosine,
}

/// Limits of one segment along its path. Valid by construction (see [`ProfileLimits::new`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProfileLimits {
    v_max_mm_s: f64,
    a_max_mm_s2: f64,
    j_max_mm_s3: f64,
    shape: JerkShape,
}

impl ProfileLimits {
    /// Limits with speed cap `v_max_mm_s`, acceleration `a_max_mm_s2` and jerk `j_max_mm_s3`
    /// (peak jerk of the pulses). `None` unless every value lies in
    /// [`MIN_LIMIT`]`..=`[`MAX_LIMIT`]; the jerk may also be `f64::INFINITY` (a trapezoid; the
    /// shape is then irrelevant).
    pub fn new(
        v_max_mm_s: f64,
        a_max_mm_s2: f64,
        j_max_mm_s3: f64,
        shape: JerkShape,
    ) -> Option<ProfileLimits> {
        let ok = |x: f64| (MIN_LIMIT..=MAX_LIMIT).contains(&x);
        (ok(v_max_mm_s) && ok(a_max_mm_s2) && (ok(j_max_mm_s3) || j_max_mm_s3 == f64::INFINITY))
            .then_some(ProfileLimits {
                v_max_mm_s,
                a_max_mm_s2,
                j_max_mm_s3,
                shape,
            })
    }

    /// Trapezoid limits (infinite jerk).
    pub fn trapezoid(v_max_mm_s: f64, a_max_mm_s2: f64) -> Option<ProfileLimits> {
        ProfileLimits::new(v_max_mm_s, a_max_mm_s2, f64::INFINITY, JerkShape::Square)
    }

    /// Speed cap.
    pub fn v_max_mm_s(&self) -> f64 {
        self.v_max_mm_s
    }

    /// Acceleration limit.
    pub fn a_max_mm_s2(&self) -> f64 {
        self.a_max_mm_s2
    }

    /// Jerk limit (peak jerk; `f64::INFINITY` for a trapezoid).
    pub fn j_max_mm_s3(&self) -> f64 {
        self.j_max_mm_s3
    }

    /// Shape of the jerk pulses.
    pub fn shape(&self) -> JerkShape {
        self.shape
    }

    /// Whether the jerk is unlimited (a trapezoid).
    pub fn is_trapezoid(&self) -> bool {
        self.j_max_mm_s3 == f64::INFINITY
    }

    fn kin(&self) -> Kin {
        let j = match self.shape {
            JerkShape::Square => self.j_max_mm_s3,
            JerkShape::RaisedCosine => 0.5 * self.j_max_mm_s3,
        };
        let a = self.a_max_mm_s2;
        Kin {
            a,
            j,
            a_over_j: a / j,
            v_a: a * (a / j),
        }
    }
}

/// How the cruise (peak) speed of a profile was found (see the module documentation).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PeakMethod {
    /// `vmax` is reached (a cruise at `vmax`, possibly of zero length).
    AtVmax,
    /// Both transitions reach `amax` (or a trapezoid): closed-form quadratic.
    Quadratic,
    /// Neither transition reaches `amax` and `v0 = v1`: a depressed cubic (monotone Newton).
    Cubic,
    /// Bracketed solve (safeguarded Newton / bisection).
    Bracketed,
    /// Lowered to stretch the duration to whole periods (bisection).
    Stretched,
}

/// Position, speed, acceleration and jerk along the path at one instant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    /// Distance from the segment start, in `[0, L]`.
    pub s_mm: f64,
    /// Path speed.
    pub v_mm_s: f64,
    /// Path acceleration.
    pub a_mm_s2: f64,
    /// Path jerk (right-continuous at the phase boundaries; 0 for a trapezoid).
    pub j_mm_s3: f64,
}

/// A planned speed profile over one segment. `Copy`, 7 phases, no heap.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SpeedProfile {
    limits: ProfileLimits,
    length_mm: f64,
    v_start_mm_s: f64,
    v_end_mm_s: f64,
    v_cruise_mm_s: f64,
    method: PeakMethod,
    /// Duration of each phase (kept apart from the start times: a short phase after a long
    /// cruise must not lose its digits).
    phase_s: [f64; 7],
    /// Start time of each phase; `[7]` is the duration.
    t_start_s: [f64; 8],
    /// Signed peak jerk of each phase (0 in constant-acceleration phases, the cruise and every
    /// empty phase).
    jerk_mm_s3: [f64; 7],
    /// `(s, v, a)` at the start of each phase.
    start: [State; 7],
}

#[derive(Debug, Clone, Copy, PartialEq)]
struct State {
    s: f64,
    v: f64,
    a: f64,
}

/// Effective kinematic constants of a [`ProfileLimits`].
#[derive(Debug, Clone, Copy)]
struct Kin {
    /// `amax`.
    a: f64,
    /// Effective jerk (`jmax`, or `jmax/2` for raised-cosine pulses; may be infinite).
    j: f64,
    /// `amax / j`: duration of a jerk phase that reaches `amax`.
    a_over_j: f64,
    /// `amax² / j`: the speed change from which a transition reaches `amax`.
    v_a: f64,
}

/// A time-optimal speed change with zero acceleration at both ends.
#[derive(Debug, Clone, Copy)]
struct Transition {
    /// Duration of each of the two jerk phases.
    tj: f64,
    /// Duration of the constant-acceleration phase.
    ta: f64,
    /// Peak acceleration, signed like the speed change.
    a_peak: f64,
    /// Duration `2·tj + ta`.
    t: f64,
    /// Length `(va + vb)/2 · t`.
    d: f64,
}

impl Kin {
    fn transition(&self, va: f64, vb: f64) -> Transition {
        let dv = (vb - va).abs();
        let sign = if vb < va { -1.0 } else { 1.0 };
        let (tj, ta, a_peak) = if dv == 0.0 {
            (0.0, 0.0, 0.0)
        } else if dv >= self.v_a {
            (
                self.a_over_j,
                (dv / self.a - self.a_over_j).max(0.0),
                self.a,
            )
        } else {
            let tj = (dv / self.j).sqrt();
            (tj, 0.0, self.j * tj)
        };
        let t = 2.0 * tj + ta;
        Transition {
            tj,
            ta,
            a_peak: sign * a_peak,
            t,
            d: 0.5 * (va + vb) * t,
        }
    }

    /// `d(va, vb)`; bit-for-bit symmetric in its arguments.
    fn length(&self, va: f64, vb: f64) -> f64 {
        self.transition(va, vb).d
    }

    /// Derivative of `d(v, w)` with respect to the higher speed `w ≥ v`.
    fn length_slope(&self, v: f64, w: f64) -> f64 {
        let dv = w - v;
        if dv >= self.v_a {
            w / self.a + 0.5 * self.a_over_j
        } else if dv > 0.0 {
            (dv / self.j).sqrt() + (v + w) / (2.0 * (dv * self.j).sqrt())
        } else {
            f64::INFINITY
        }
    }

    /// Length of the two transitions through the peak `vp ≥ max(v0, v1)`, and its derivative.
    fn two_lengths(&self, v0: f64, vp: f64, v1: f64) -> (f64, f64) {
        (
            self.length(v0, vp) + self.length(vp, v1),
            self.length_slope(v0, vp) + self.length_slope(v1, vp),
        )
    }

    /// A close estimate of the root of `D(vp) = l` (finite jerk, `D(max(v0, v1)) ≤ l`), the
    /// seed of the bracketed solve. With `m = max(v0, v1)`, `n = min(v0, v1)` and
    /// `vp = m + x²`, `D = (2m + x²)/2 · t(x²) + (n + m + x²)/2 · t(x² + m − n)` is increasing
    /// and convex in `x ≥ 0` in every regime (`t` is C¹, `2√(Δ/j)` then `Δ/a + a/j`; the mean
    /// speeds and `t(x² + δ)` are increasing and convex in `x`), unlike in `vp`, where it has
    /// a vertical tangent at `m`: Newton from an upper bound of the root falls monotonically
    /// onto it, from the smallest of three bounds: `t(Δ) ≥ 2√(Δ/j)` gives
    /// `D ≥ (3m + n + 2x²)·x/√j` and `D ≥ 2x³/√j`, and convexity `D ≥ D(0) + D′(0⁺)·x`.
    fn peak_seed(&self, l: f64, v0: f64, v1: f64) -> f64 {
        let (m, n) = (v0.max(v1), v0.min(v1));
        let delta = m - n;
        let sqrt_j = self.j.sqrt();
        let (rj, ra) = (1.0 / sqrt_j, 1.0 / self.a);
        // t(x² + δ) and its derivative in x.
        let t = |x: f64, delta: f64| {
            let dv = x * x + delta;
            if dv >= self.v_a {
                (dv * ra + self.a_over_j, 2.0 * x * ra)
            } else if delta == 0.0 {
                (2.0 * x * rj, 2.0 * rj)
            } else {
                let s = dv.sqrt();
                (2.0 * s * rj, 2.0 * x * rj / s)
            }
        };
        let f = |x: f64| {
            let (th, dth) = t(x, 0.0);
            let (tl, dtl) = t(x, delta);
            let (mh, ml) = (0.5 * (2.0 * m + x * x), 0.5 * (n + m + x * x));
            (mh * th + ml * tl - l, x * (th + tl) + mh * dth + ml * dtl)
        };
        let (f0, df0) = f(0.0);
        if f0.is_nan() || f0 >= 0.0 {
            return m;
        }
        let q = l * sqrt_j;
        let mut x = (q / (3.0 * m + n)).min(-f0 / df0);
        if x.is_nan() || 2.0 * x * x * x > q {
            x = (0.5 * q).cbrt();
        }
        for _ in 0..60 {
            let (fx, dfx) = f(x);
            if !(fx > 0.0 && dfx > 0.0) {
                break;
            }
            let step = fx / dfx;
            x -= step;
            if step <= 1e-14 * x {
                break;
            }
        }
        m + x * x
    }

    /// Largest `w ∈ [v, vmax]` with `d(v, w) ≤ l` (the caller checked `v ≤ vmax`).
    fn reach(&self, l: f64, v: f64, vmax: f64) -> f64 {
        if self.length(v, vmax) <= l {
            return vmax;
        }
        // Δ with d(v, v + Δ) = l: a quadratic, or a depressed cubic in √Δ.
        let dv = if self.v_a == 0.0 || l >= self.length(v, v + self.v_a) {
            // (2v + Δ)/2 · (Δ/a + a/j) = l ⇔ Δ² + (2v + vA)Δ + 2v·vA − 2a·l = 0.
            let p = 2.0 * v + self.v_a;
            let disc = (2.0 * v - self.v_a).powi(2) + 8.0 * self.a * l;
            2.0 * (2.0 * self.a * l - 2.0 * v * self.v_a) / (p + disc.sqrt())
        } else {
            // (2v + x²)·x/√j = l with x = √Δ.
            cubic_root(2.0 * v, l * self.j.sqrt()).powi(2)
        };
        let f = |w: f64| (self.length(v, w) - l, self.length_slope(v, w));
        let mut w = refine(f, v, vmax, v + dv);
        // The largest float that passes the very predicate `plan` uses.
        for _ in 0..4 {
            let up = w.next_up();
            if up > vmax || self.length(v, up) > l {
                break;
            }
            w = up;
        }
        w
    }
}

/// The real root `x ≥ 0` of `x³ + p·x = q` (`p, q ≥ 0`), by Newton from the smaller of two
/// upper bounds, `q/p` (as `x³ ≥ 0`) and `∛q` (as `p·x ≥ 0`; `cbrt` only when it is the
/// smaller): the cubic is increasing and convex for `x ≥ 0`, so the iterates fall monotonically
/// onto the root, within a few steps from the better bound (cheaper than the hyperbolic form of
/// Cardano's formula, whose `asinh` and `sinh` cost more than the steps).
fn cubic_root(p: f64, q: f64) -> f64 {
    if q.is_nan() || q <= 0.0 {
        return 0.0;
    }
    let linear = q / p;
    let mut x = if linear * linear * linear <= q {
        linear
    } else {
        q.cbrt()
    };
    for _ in 0..200 {
        let f = x * (x * x + p) - q;
        let df = 3.0 * x * x + p;
        if !(f > 0.0 && df > 0.0 && df.is_finite()) {
            break;
        }
        let next = x - f / df;
        if next.is_nan() || next >= x {
            break;
        }
        x = next;
    }
    x.max(0.0)
}

/// Largest `x ∈ [lo, hi]` (to a few ulps) with `f(x) ≤ 0`, for `f` increasing with
/// `f(lo) ≤ 0 < f(hi)`; `f` returns the value and the derivative. Safeguarded Newton from
/// `guess`, bisection whenever Newton leaves the bracket. Never returns a point with `f > 0`.
fn refine(f: impl Fn(f64) -> (f64, f64), mut lo: f64, mut hi: f64, guess: f64) -> f64 {
    let mut x = if guess > lo && guess < hi {
        guess
    } else {
        0.5 * (lo + hi)
    };
    for iteration in 0..200 {
        let (fx, dfx) = f(x);
        if fx.is_nan() {
            return lo;
        }
        let step = if dfx > 0.0 { fx / dfx } else { 0.0 };
        let converged = step.abs() <= 4.0 * f64::EPSILON * x.abs();
        if fx <= 0.0 {
            lo = x;
            if fx == 0.0 || converged {
                return x;
            }
        } else {
            hi = x;
        }
        if hi - lo <= 4.0 * f64::EPSILON * hi.abs() {
            return lo;
        }
        let mut next = x - step;
        if fx > 0.0 && converged {
            // Newton has converged from above: step just below the root.
            next = x - 2.0 * step - 4.0 * f64::EPSILON * x.abs();
        }
        if iteration >= 100 || !(next > lo && next < hi) {
            next = 0.5 * (lo + hi);
        }
        x = next;
    }
    lo
}

fn length_ok(length_mm: f64) -> bool {
    length_mm > 0.0 && length_mm <= MAX_LENGTH_MM
}

/// The shortest length over which the speed can change between `va` and `vb` (acceleration 0
/// at both ends): the S-curve path-length constraint of `shared/seeds` 003. Symmetric.
pub fn transition_length_mm(va_mm_s: f64, vb_mm_s: f64, limits: &ProfileLimits) -> f64 {
    limits.kin().length(va_mm_s, vb_mm_s)
}

/// The time-optimal profile over `length_mm` from `v_start_mm_s` to `v_end_mm_s`. `None` when
/// an input is outside its domain (`0 < L ≤` [`MAX_LENGTH_MM`], `0 ≤ v ≤ vmax`) or when the
/// speed change does not fit in the length (exactly when `v_end` is above
/// [`max_end_speed`]`(L, v_start)` or `v_start` is above [`max_start_speed`]`(L, v_end)`).
pub fn plan(
    length_mm: f64,
    v_start_mm_s: f64,
    v_end_mm_s: f64,
    limits: &ProfileLimits,
) -> Option<SpeedProfile> {
    let (l, v0, v1, vmax) = (length_mm, v_start_mm_s, v_end_mm_s, limits.v_max_mm_s);
    let speeds = 0.0..=vmax;
    if !(length_ok(l) && speeds.contains(&v0) && speeds.contains(&v1)) {
        return None;
    }
    let k = limits.kin();
    if k.length(v0, v1) > l {
        return None;
    }
    let (vp, method) = peak_speed(&k, l, v0, v1, vmax);
    build(limits, l, v0, vp, v1, method)
}

/// The time-optimal peak: `vmax` or the root of `D(vp) = L` (see the module documentation).
fn peak_speed(k: &Kin, l: f64, v0: f64, v1: f64, vmax: f64) -> (f64, PeakMethod) {
    // `two_lengths(..).0`, without the slopes.
    let d = |vp: f64| k.length(v0, vp) + k.length(vp, v1);
    if d(vmax) <= l {
        return (vmax, PeakMethod::AtVmax);
    }
    // The regime bracket [left, right] holding the root: D(left) ≤ L < D(right).
    let (mut left, mut right) = (v0.max(v1), vmax);
    let (b_lo, b_hi) = ((v0 + k.v_a).min(v1 + k.v_a), (v0 + k.v_a).max(v1 + k.v_a));
    for b in [b_lo, b_hi] {
        if b > left && b < right {
            if d(b) <= l {
                left = b;
            } else {
                right = b;
                break;
            }
        }
    }
    let mid = 0.5 * (left + right);
    let reaches_a = |v: f64| mid - v >= k.v_a;
    let (guess, method) = if reaches_a(v0) && reaches_a(v1) {
        let disc = (k.v_a - v0 - v1).powi(2) + (v0 - v1).powi(2) + 4.0 * k.a * l;
        (0.5 * (disc.sqrt() - k.v_a), PeakMethod::Quadratic)
    } else if !reaches_a(v0) && !reaches_a(v1) && v0 == v1 {
        let x = cubic_root(2.0 * v0, 0.5 * l * k.j.sqrt());
        (v0 + x * x, PeakMethod::Cubic)
    } else {
        // Two ulps low, so that the refinement's first step usually lands below the root and
        // ends there (within its tolerance of 4 ulps); just above `left` when the root is
        // within rounding of it (the refinement then ends at once on `left`).
        let seed = k.peak_seed(l, v0, v1);
        let seed = seed - 2.0 * f64::EPSILON * seed;
        let seed = if seed > left { seed } else { left.next_up() };
        (seed, PeakMethod::Bracketed)
    };
    let f = |vp: f64| {
        let (d, slope) = k.two_lengths(v0, vp, v1);
        (d - l, slope)
    };
    (refine(f, left, right, guess), method)
}

/// The profile `v0 → vc`, cruise, `vc → v1` over `l` (the caller checked `D(vc) ≤ l`, or
/// nothing is built).
fn build(
    limits: &ProfileLimits,
    l: f64,
    v0: f64,
    vc: f64,
    v1: f64,
    method: PeakMethod,
) -> Option<SpeedProfile> {
    let k = limits.kin();
    let (up, down) = (k.transition(v0, vc), k.transition(vc, v1));
    let cruise_mm = l - (up.d + down.d);
    if cruise_mm.is_nan() || cruise_mm < 0.0 {
        return None;
    }
    let t_cruise = if cruise_mm > 0.0 { cruise_mm / vc } else { 0.0 };
    let durations = [up.tj, up.ta, up.tj, t_cruise, down.tj, down.ta, down.tj];
    let peak_jerk = |tr: &Transition| {
        if tr.tj > 0.0 {
            limits.j_max_mm_s3.copysign(tr.a_peak)
        } else {
            0.0
        }
    };
    let (ju, jd) = (peak_jerk(&up), peak_jerk(&down));
    let jerk_mm_s3 = [ju, 0.0, -ju, 0.0, jd, 0.0, -jd];
    let mut t_start_s = [0.0; 8];
    for i in 0..7 {
        t_start_s[i + 1] = t_start_s[i] + durations[i];
    }
    let shape = limits.shape;
    let mut start = [State {
        s: 0.0,
        v: v0,
        a: 0.0,
    }; 7];
    // The acceleration plateaus are set exactly (a trapezoid's jerk phases are empty).
    start[1] = State {
        a: up.a_peak,
        ..advance(start[0], jerk_mm_s3[0], durations[0], shape, durations[0])
    };
    start[2] = State {
        a: up.a_peak,
        ..advance(start[1], 0.0, durations[1], shape, durations[1])
    };
    start[3] = State {
        s: up.d,
        v: vc,
        a: 0.0,
    };
    // The second transition is anchored at the end, so the profile ends exactly at L.
    start[4] = State {
        s: l - down.d,
        v: vc,
        a: 0.0,
    };
    start[5] = State {
        a: down.a_peak,
        ..advance(start[4], jerk_mm_s3[4], durations[4], shape, durations[4])
    };
    start[6] = State {
        a: down.a_peak,
        ..advance(start[5], 0.0, durations[5], shape, durations[5])
    };
    let profile = SpeedProfile {
        limits: *limits,
        length_mm: l,
        v_start_mm_s: v0,
        v_end_mm_s: v1,
        v_cruise_mm_s: vc,
        method,
        phase_s: durations,
        t_start_s,
        jerk_mm_s3,
        start,
    };
    let finite = t_start_s[7].is_finite()
        && start
            .iter()
            .all(|s| s.s.is_finite() && s.v.is_finite() && s.a.is_finite());
    finite.then_some(profile)
}

/// The state `tau` into a phase of duration `phase_s` with peak jerk `jerk` from `st`.
#[inline]
fn advance(st: State, jerk: f64, phase_s: f64, shape: JerkShape, tau: f64) -> State {
    eval(st, jerk, phase_s, shape, tau).0
}

/// State and jerk `tau` into a phase. A square phase is the cubic; a raised-cosine pulse
/// `J/2·(1 − cos ωτ)` integrates to `a = a0 + J/2·(τ − sin ωτ/ω)`,
/// `v = v0 + a0τ + J/2·(τ²/2 − (1 − cos ωτ)/ω²)`,
/// `s = s0 + v0τ + a0τ²/2 + J/2·(τ³/6 − τ/ω² + sin ωτ/ω³)`.
#[inline]
fn eval(st: State, jerk: f64, phase_s: f64, shape: JerkShape, tau: f64) -> (State, f64) {
    let base_v = st.v + st.a * tau;
    let base_s = st.s + tau * (st.v + 0.5 * st.a * tau);
    if jerk == 0.0 {
        return (
            State {
                s: base_s,
                v: base_v,
                a: st.a,
            },
            0.0,
        );
    }
    match shape {
        JerkShape::Square => (
            State {
                s: base_s + jerk * tau * tau * tau / 6.0,
                v: base_v + 0.5 * jerk * tau * tau,
                a: st.a + jerk * tau,
            },
            jerk,
        ),
        JerkShape::RaisedCosine => {
            let w = 2.0 * PI / phase_s;
            let x = w * tau;
            let sin = x.sin();
            let half = 0.5 * jerk;
            // 1 − cos x without cancellation near the pulse edges.
            let one_minus_cos = 2.0 * (0.5 * x).sin().powi(2);
            (
                State {
                    s: base_s + half * (tau * tau * tau / 6.0 + (sin - x) / (w * w * w)),
                    v: base_v + half * (0.5 * tau * tau - one_minus_cos / (w * w)),
                    a: st.a + half * (tau - sin / w),
                },
                half * one_minus_cos,
            )
        }
    }
}

/// The largest end speed reachable from `v_start_mm_s` within `length_mm` (capped at `vmax`):
/// the forward pass of the look-ahead. Every `v_end` in `[v_start, result]` is feasible in
/// [`plan`], and the result is the largest such float (a speed one ulp above is not feasible
/// unless the result is `vmax`). `None` when an input is outside the domain of [`plan`].
pub fn max_end_speed(length_mm: f64, v_start_mm_s: f64, limits: &ProfileLimits) -> Option<f64> {
    let vmax = limits.v_max_mm_s;
    (length_ok(length_mm) && (0.0..=vmax).contains(&v_start_mm_s))
        .then(|| limits.kin().reach(length_mm, v_start_mm_s, vmax))
}

/// The largest start speed from which `v_end_mm_s` is reachable within `length_mm` (capped at
/// `vmax`): the backward pass of the look-ahead. Every `v_start` in `[v_end, result]` is
/// feasible in [`plan`]; the same function as [`max_end_speed`], the length of a speed change
/// being symmetric.
pub fn max_start_speed(length_mm: f64, v_end_mm_s: f64, limits: &ProfileLimits) -> Option<f64> {
    max_end_speed(length_mm, v_end_mm_s, limits)
}

/// What [`SpeedProfile::stretch_to_period`] did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Stretch {
    /// Whole periods of the stretched profile (its duration is `periods · period` to rounding).
    pub periods: u64,
    /// Time added to the time-optimal duration.
    pub added_s: f64,
    /// Cruise speed before the stretch.
    pub v_cruise_before_mm_s: f64,
    /// Cruise speed after the stretch (≤ before).
    pub v_cruise_after_mm_s: f64,
}

/// Why a profile could not be stretched to whole periods.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum StretchError {
    /// The period is not finite and positive.
    #[error("period {period_s} s must be finite and greater than zero")]
    InvalidPeriod {
        /// The period.
        period_s: f64,
    },
    /// The duration is more than 2^53 periods.
    #[error("duration {duration_s} s is too many periods of {period_s} s")]
    TooManyPeriods {
        /// The profile's duration.
        duration_s: f64,
        /// The period.
        period_s: f64,
    },
    /// Lowering the cruise speed cannot make the profile last `target_s` within its length
    /// (e.g. it accelerates over the whole segment): lower a boundary speed.
    #[error("cannot stretch to {target_s} s: at most {longest_s} s with these boundary speeds")]
    NoSlack {
        /// The whole-period duration asked for.
        target_s: f64,
        /// The longest duration below the target found.
        longest_s: f64,
    },
}

impl SpeedProfile {
    /// Position, speed, acceleration and jerk `t_s` after the start. `(0, v0, 0, 0)` before the
    /// start (and for NaN), exactly `(L, v1, 0, 0)` from [`duration_s`](Self::duration_s) on,
    /// exactly the stored state at the start of each phase. Constant time, no allocation.
    #[inline]
    pub fn at(&self, t_s: f64) -> Sample {
        if t_s.is_nan() || t_s < 0.0 {
            return Sample {
                s_mm: 0.0,
                v_mm_s: self.v_start_mm_s,
                a_mm_s2: 0.0,
                j_mm_s3: 0.0,
            };
        }
        if t_s >= self.t_start_s[7] {
            return Sample {
                s_mm: self.length_mm,
                v_mm_s: self.v_end_mm_s,
                a_mm_s2: 0.0,
                j_mm_s3: 0.0,
            };
        }
        let mut k = 0;
        while k < 6 && t_s >= self.t_start_s[k + 1] {
            k += 1;
        }
        let (st, jerk) = self.eval_phase(k, t_s - self.t_start_s[k]);
        Sample {
            s_mm: st.s.clamp(0.0, self.length_mm),
            v_mm_s: st.v,
            a_mm_s2: st.a,
            j_mm_s3: jerk,
        }
    }

    fn eval_phase(&self, k: usize, tau: f64) -> (State, f64) {
        eval(
            self.start[k],
            self.jerk_mm_s3[k],
            self.phase_s[k],
            self.limits.shape,
            tau,
        )
    }

    /// Total duration.
    pub fn duration_s(&self) -> f64 {
        self.t_start_s[7]
    }

    /// Durations of the seven phases (jerk, constant acceleration, jerk, cruise, jerk, constant
    /// acceleration, jerk).
    pub fn phase_durations_s(&self) -> [f64; 7] {
        self.phase_s
    }

    /// Start time of each phase; the last entry is the duration.
    pub fn phase_start_times_s(&self) -> [f64; 8] {
        self.t_start_s
    }

    /// Segment length.
    pub fn length_mm(&self) -> f64 {
        self.length_mm
    }

    /// Speed at the start.
    pub fn v_start_mm_s(&self) -> f64 {
        self.v_start_mm_s
    }

    /// Speed at the end.
    pub fn v_end_mm_s(&self) -> f64 {
        self.v_end_mm_s
    }

    /// Cruise speed (the peak of a time-optimal profile; a cruise of zero duration when the
    /// segment is too short to hold it).
    pub fn v_cruise_mm_s(&self) -> f64 {
        self.v_cruise_mm_s
    }

    /// The limits the profile was planned with.
    pub fn limits(&self) -> &ProfileLimits {
        &self.limits
    }

    /// How the cruise speed was found.
    pub fn method(&self) -> PeakMethod {
        self.method
    }

    /// The same segment stretched to the smallest whole number of periods `period_s` not
    /// shorter than this profile (`shared/seeds` 000: segment ends on interpolation points), by
    /// lowering the cruise speed; the length, the boundary speeds and every limit are kept. A
    /// profile already a whole number of periods long (to 4 ulps) is returned as is.
    pub fn stretch_to_period(
        &self,
        period_s: f64,
    ) -> Result<(SpeedProfile, Stretch), StretchError> {
        if !(period_s > 0.0 && period_s.is_finite()) {
            return Err(StretchError::InvalidPeriod { period_s });
        }
        let duration_s = self.duration_s();
        let periods = (duration_s / period_s).ceil();
        if periods > 9.0e15 {
            return Err(StretchError::TooManyPeriods {
                duration_s,
                period_s,
            });
        }
        let periods = periods.max(1.0);
        let target_s = periods * period_s;
        let vc0 = self.v_cruise_mm_s;
        let unchanged = Stretch {
            periods: periods as u64,
            added_s: 0.0,
            v_cruise_before_mm_s: vc0,
            v_cruise_after_mm_s: vc0,
        };
        if target_s <= duration_s * (1.0 + 4.0 * f64::EPSILON) {
            return Ok((*self, unchanged));
        }
        let (l, v0, v1) = (self.length_mm, self.v_start_mm_s, self.v_end_mm_s);
        let k = self.limits.kin();
        // Duration with cruise speed vc, or None where the transitions do not fit.
        let duration_at = |vc: f64| {
            let (up, down) = (k.transition(v0, vc), k.transition(vc, v1));
            let cruise_mm = l - (up.d + down.d);
            (cruise_mm >= 0.0).then(|| up.t + down.t + cruise_mm / vc)
        };
        // Bisection for the crossing of "infeasible or long enough" and "feasible and too
        // short" in [lo, hi]; the result is kept only if it is a root of T(vc) = target, not the
        // edge of the feasible set (nor rounding noise where the transitions alone fill the
        // length, as a trapezoid's do).
        let long_enough = |vc: f64| duration_at(vc).is_none_or(|t| t >= target_s);
        let mut longest_s = duration_s;
        let mut attempt = |mut lo: f64, mut hi: f64| {
            for _ in 0..2100 {
                let mid = 0.5 * (lo + hi);
                if mid <= lo || mid >= hi {
                    break;
                }
                if long_enough(mid) {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            if let Some(t) = duration_at(hi) {
                longest_s = longest_s.max(t.min(target_s));
            }
            if lo == 0.0 || duration_at(lo).is_none() {
                return None;
            }
            build(&self.limits, l, v0, hi, v1, PeakMethod::Stretched)
                .filter(|p| (p.duration_s() - target_s).abs() <= 1e-9 * target_s)
        };
        // First from the time-optimal cruise speed down to 0 (near 0 the cruise takes forever);
        // when that ends on the edge of the feasible set, a scan for a lower feasible stretch
        // of cruise speeds that holds a root (slowing down can take more length than stopping).
        const SCAN: u32 = 256;
        let found = attempt(0.0, vc0).or_else(|| {
            (1..SCAN).rev().find_map(|i| {
                let (a, b) = (
                    vc0 * f64::from(i) / f64::from(SCAN),
                    vc0 * f64::from(i + 1) / f64::from(SCAN),
                );
                let bracket = duration_at(a).is_some_and(|t| t >= target_s)
                    && duration_at(b).is_some_and(|t| t < target_s);
                if bracket { attempt(a, b) } else { None }
            })
        });
        let Some(stretched) = found else {
            return Err(StretchError::NoSlack {
                target_s,
                longest_s,
            });
        };
        Ok((
            stretched,
            Stretch {
                added_s: stretched.duration_s() - duration_s,
                v_cruise_after_mm_s: stretched.v_cruise_mm_s,
                ..unchanged
            },
        ))
    }
}

#[cfg(test)]
mod tests;
