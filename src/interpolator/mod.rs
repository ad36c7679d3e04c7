//! Cyclic interpolator: samples planned segments once per control period (the CANopen SYNC
//! period).
//!
//! Third stage of the pipeline (`gcode → planner → interpolator → setpoints`). Shaped like Ruckig:
//! constructed with the cycle time, then [`Interpolator::update`] once per cycle, which never
//! allocates, blocks or panics and answers with a [`Status`]. Sample `k` (k = 1, 2, ...) is the
//! plan's position at `t = k · period_s`, computed from `k` (not by adding periods) so there is
//! no drift however long the program runs.
//!
//! Segments sit in a queue: either a whole [`Plan`] given at construction
//! ([`Interpolator::new`]), or segments pushed as the planner settles them
//! ([`Interpolator::streaming`], [`Interpolator::push`], then [`Interpolator::close`]), so a
//! program of any length is sampled with bounded memory. The queue's capacity grows only while
//! a producer pushes faster than the samples consume; `update` itself only pops.
//!
//! The first sample whose time reaches the end of a closed queue is exactly the last segment's
//! end point (bit for bit) and comes with [`Status::Finished`]; every later call returns that
//! point again. A sample that falls beyond the queued segments of a queue still open is a
//! producer underrun: [`Status::Starved`], the previous sample again, and time does not advance
//! (the planner keeps every settled segment ending at a speed it can stop from, so that holding
//! is a planning failure to report, never a normal event).
//!
//! # Feed override and feed hold
//!
//! The sample times above are *plan* times. With an [`OverrideRamp`] configured
//! ([`Interpolator::with_override_ramp`]), the plan-time cursor `τ` advances by `k·T` per cycle
//! instead of `T`: `k ∈ [0, 2]` is the effective override, so every axis moves at `k` times its
//! planned speed along the same path. [`Interpolator::set_override`] asks for a new value,
//! [`Interpolator::hold`] for `k = 0` (the motion stops on the path, wherever it is: not at a
//! segment end) and [`Interpolator::resume`] for the requested value again. A change is planned
//! at once from the state of the latest sample and moves `k` from the very next
//! [`update`](Interpolator::update): within one cycle.
//!
//! `k` never steps: it follows a jerk-limited ramp (an S-curve in `k`: `|k'| ≤ D`, `|k''| ≤ J`,
//! [`OverrideRamp`]), replanned from the current `k` and `k'` whenever the request changes, and it
//! never leaves `[0, 2]`: a ramp reaches its target without overshoot, and one replanned in
//! flight goes no further than where the current one would have stopped. Up to 1 any target is
//! taken at once; above 1 only where the plan leaves room (see "Above 100 %" below). With the plan's path
//! quantities of each axis (`v`, `a`, `j` at plan time `τ`), the setpoints' derivatives are
//!
//! - velocity `k·v`,
//! - acceleration `k²·a + k'·v`,
//! - jerk `k³·j + 3k·k'·a + k''·v`.
//!
//! The planner lets its profiles use the share `s` ([`crate::planner::PlannerConfig::path_acc_share`])
//! of each axis's acceleration `A` and jerk `Jₐ`, and bounds every axis's speed by
//! `V = min(max_vel, max_feed)`. [`OverrideRamp::for_machine`] takes the ramp's rates from the
//! share `1 − s` left over:
//!
//! - `D ≤ (1 − s)·A/V`, so `|k'·v| ≤ (1 − s)·A` and, with `k ≤ 1`, `|k²·a| ≤ s·A`: the sum is
//!   within `A`;
//! - for S-curves also `D ≤ (1 − s)·Jₐ/(6·s·A)` and `J ≤ (1 − s)·Jₐ/(2·V)`, so
//!   `|3k·k'·a| ≤ (1 − s)·Jₐ/2` and `|k''·v| ≤ (1 − s)·Jₐ/2`, and with `|k³·j| ≤ s·Jₐ` the sum
//!   is within `Jₐ`.
//!
//! At a junction the planner spends what its profiles leave of an axis's acceleration on the
//! velocity vector's turn within one period. Sampled with steps of `k·T` in plan time, that
//! turn's contribution to the second (third) difference scales with `k` (`k²`), so a ramp
//! down frees `(1 − k)·A` for the `k'·v` term; while `k` leaves 1, `k'` and `1 − k` grow together
//! from 0 (the ramp is an S-curve) and the excess, at most `J·v²/(2A)` per axis, is far below a
//! percent of `A` for any realistic `J` (`tests/override_limits.rs` checks random programs
//! against the limits within 1 %).
//!
//! # Quiet ramps
//!
//! On the cruise of a line the profile uses none of the path acceleration `a` and jerk `j` it
//! may use there (each axis `|uᵢ|·a`, `|uᵢ|·j`, which the junctions' budgets leave aside), so a
//! ramp of `k` that runs on such cruises only may take them: `|k'|·v ≤ a` and `|k''|·v ≤ j`
//! (`k'` over four periods without a jerk limit), far more than `D` and `J` when the speed is
//! below the machine's. A ramp to a target at or below 1 (a hold, a lower override, a resume)
//! uses these rates where it fits: its whole span of plan time, a period's travel either side,
//! on quiet stretches, at the lowest rates among them; with a jerk limit within one segment's
//! cruise (at a junction `k'·v` would turn with the path, a step of acceleration). A hold at
//! full speed on a line then stops about as fast as the plan itself could brake. While such a
//! ramp runs, a new target waits for its end (its `k'` may exceed `D`) unless a quiet ramp to it
//! fits too.
//!
//! # Above 100 %
//!
//! Time scaling by `k > 1` multiplies the planned acceleration by `k²` and the jerk by `k³`, and
//! the plan uses its whole share `s` of them wherever it accelerates or decelerates, so there
//! `k` must stay at 1. On a cruise (path speed `v` constant, phase 4 of a profile) a line has no
//! acceleration and an arc only its centripetal one, which the planner holds within the share
//! for every speed up to the element's `v_limit` ([`Segment::v_limit_mm_s`]: the machine's
//! limits without the programmed feed). So the plan has a *ceiling* for `k`: 1 wherever it
//! accelerates, decelerates or dwells, and `min(v_limit/v, v_junction/v_j)` on a cruise, with
//! the junctions' own limits ([`Segment::v_start_limit_mm_s`], which are conditions on the
//! speed sampled through them, whatever the feed) where the cruise runs into a junction. Under
//! the ceiling, every bound of the ramp above holds with `k > 1` too: `k·|vᵢ| ≤ Vᵢ`,
//! `k²·|aᵢ| ≤ s·A`, `k³·|jᵢ| ≤ s·Jₐ`, and the ramp's own terms are bounded as before since
//! `k·|vᵢ| ≤ Vᵢ`.
//!
//! The ceiling is known as far as the queue goes (for a whole plan, to its end). Above 100 %,
//! before each sample, the interpolator takes the next step of the ramp towards the target
//! only if, from that step, the ramp back down to 1 keeps every sample under the ceiling of
//! every stretch of plan between it and the sample before; otherwise it ramps down to 1 from the
//! latest sample, a ramp that the same check admitted one cycle earlier. So `k` never has to
//! step, and a target at or below 1 is always safe from where it is. Past the end of an open
//! queue the ceiling is 1. The check walks only the stretches where the ceiling is below
//! [`MAX_OVERRIDE`] (kept as the queue fills), so it costs little per cycle.
//!
//! Below 100 % a dwell is scaled like the motion (it lasts `1/k` as long, and a hold pauses it);
//! above, its ceiling is 1: it is not shortened. The end of a closed queue is still exact: the
//! sample whose `τ` reaches it is the last segment's end point, bit for bit.
//!
//! Units in names: `_mm` millimetres, `_s` seconds.

pub mod aux;
pub mod filter;
pub mod smooth;

use std::collections::VecDeque;

use nalgebra::Vector3;

use crate::planner::{Limits, Plan, PlannerConfig, Segment, SegmentPath, Smoothing};
use smooth::{Smoother, precompensation};

/// A sample time within this fraction of a period before the plan's end counts as the end, so
/// that rounding in `k · period_s` never adds one extra period of standing still.
const END_SNAP_PERIODS: f64 = 1e-9;

/// The highest feed override, 200 % (see the module documentation for what bounds it further).
pub const MAX_OVERRIDE: f64 = 2.0;

/// What one [`Interpolator::update`] produced.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Status {
    /// The sample lies inside the plan, on a segment of this source line.
    Working {
        /// 1-based source line of the segment being executed.
        line: usize,
    },
    /// The queue is open and ran dry before this sample's time: the previous sample again,
    /// time held (see the module documentation).
    Starved,
    /// The sample is the plan's final point (this call and every later one).
    Finished,
    /// A hold (or a 0 % override) has brought the motion to standstill on the path: the same
    /// sample as the previous one, on a segment of this source line, until a resume.
    Held {
        /// 1-based source line of the segment the motion stopped on.
        line: usize,
    },
}

/// Why an interpolator could not be built or fed.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum InterpError {
    /// The period is not finite or not positive.
    #[error("interpolation period {period_s} s must be finite and greater than zero")]
    InvalidPeriod {
        /// The offending period.
        period_s: f64,
    },
    /// A pushed segment does not continue the queue (in place or in time), or the queue is
    /// closed.
    #[error(
        "segment of line {line} does not continue the queued motion (it must start where and when the previous one ended, before close)"
    )]
    Discontinuous {
        /// The segment's source line.
        line: usize,
    },
    /// An override that is not a finite fraction of at least 0.
    #[error("feed override {fraction} must be a finite fraction of at least 0 (1 = 100 %)")]
    InvalidOverride {
        /// The offending fraction.
        fraction: f64,
    },
    /// The override or a hold was asked of an interpolator without an override ramp.
    #[error("feed override and hold need an override ramp, and this motion has none")]
    NoOverrideRamp,
    /// Ramp rates that are not finite and positive.
    #[error(
        "override ramp rates {rate_per_s} /s and {rate_change_per_s2} /s² must be finite and greater than zero"
    )]
    InvalidOverrideRamp {
        /// `D`.
        rate_per_s: f64,
        /// `J`.
        rate_change_per_s2: f64,
    },
    /// The planner keeps nothing of the axes' acceleration for an override ramp.
    #[error(
        "planner path_acc_share = 1 leaves no acceleration for a feed override or hold ramp: set it below 1 (0.75 is the default)"
    )]
    NoOverrideBudget,
}

/// How fast the effective override `k` may change: `|k'| ≤ max_rate_per_s` and
/// `|k''| ≤ max_rate_change_per_s2` (see the module documentation).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OverrideRamp {
    max_rate_per_s: f64,
    max_rate_change_per_s2: f64,
}

impl OverrideRamp {
    /// A ramp with these rates (`D` in 1/s, `J` in 1/s²), both finite and positive.
    pub fn new(
        max_rate_per_s: f64,
        max_rate_change_per_s2: f64,
    ) -> Result<OverrideRamp, InterpError> {
        let ok = |x: f64| x > 0.0 && x.is_finite();
        if !(ok(max_rate_per_s) && ok(max_rate_change_per_s2)) {
            return Err(InterpError::InvalidOverrideRamp {
                rate_per_s: max_rate_per_s,
                rate_change_per_s2: max_rate_change_per_s2,
            });
        }
        Ok(OverrideRamp {
            max_rate_per_s,
            max_rate_change_per_s2,
        })
    }

    /// The fastest ramp that keeps every axis within its limits on top of the plans of
    /// `config` (see the module documentation for the bounds). Without a jerk limit (a
    /// trapezoid planner without finite axis jerks), `k'` still ramps up over four periods.
    pub fn for_machine(
        limits: &Limits,
        config: &PlannerConfig,
    ) -> Result<OverrideRamp, InterpError> {
        let (d, j) = crate::planner::override_ramp_rates(limits, config)
            .ok_or(InterpError::NoOverrideBudget)?;
        OverrideRamp::new(d, j)
    }

    /// `D`: the largest `|k'|`, 1/s.
    pub fn max_rate_per_s(&self) -> f64 {
        self.max_rate_per_s
    }

    /// `J`: the largest `|k''|`, 1/s².
    pub fn max_rate_change_per_s2(&self) -> f64 {
        self.max_rate_change_per_s2
    }

    /// Duration of a ramp between two overrides, starting and ending with `k' = 0` (e.g. a
    /// hold from a steady override `from` to 0).
    pub fn ramp_time_s(&self, from: f64, to: f64) -> f64 {
        let (d, j) = (self.max_rate_per_s, self.max_rate_change_per_s2);
        let delta = (to - from).abs();
        if delta >= d * d / j {
            delta / d + d / j
        } else {
            2.0 * (delta / j).sqrt()
        }
    }
}

/// The effective override `k` against time since a ramp started: three phases of constant
/// `k''` (to the peak `k'`, at it, back to 0), then `k` constant at the target. `τ` is
/// integrated exactly, so the plan time never drifts.
#[derive(Debug, Clone, Copy)]
struct KProfile {
    /// Samples counted when the ramp started (its time 0), and the plan time then.
    n0: u64,
    tau0_s: f64,
    /// State at the start of each phase: `k`, `k'`, and `∫k dt` since the ramp started.
    k: [f64; 3],
    rate: [f64; 3],
    integral_s: [f64; 3],
    /// `k''` and duration of each phase.
    rate_change: [f64; 3],
    dur_s: [f64; 3],
    /// The target and `∫k dt` over the whole ramp.
    k_end: f64,
    integral_end_s: f64,
    /// Planned with the quiet rates (valid on straight cruises only).
    quiet: bool,
}

/// `k`, `k'` and `∫k dt` at some time.
#[derive(Debug, Clone, Copy, PartialEq)]
struct KState {
    k: f64,
    rate: f64,
    integral_s: f64,
    /// The ramp is over (`k` is the target, `k' = 0`).
    done: bool,
}

impl KProfile {
    /// `k = k0` from the start, forever.
    fn steady(n0: u64, tau0_s: f64, k0: f64) -> KProfile {
        KProfile {
            n0,
            tau0_s,
            k: [k0; 3],
            rate: [0.0; 3],
            integral_s: [0.0; 3],
            rate_change: [0.0; 3],
            dur_s: [0.0; 3],
            k_end: k0,
            integral_end_s: 0.0,
            quiet: false,
        }
    }

    /// The time-optimal ramp from `k0`, `k' = rate0` to `target` with `k' = 0` at the end.
    fn plan(n0: u64, tau0_s: f64, k0: f64, rate0: f64, target: f64, r: &OverrideRamp) -> KProfile {
        let (dm, jm) = (r.max_rate_per_s, r.max_rate_change_per_s2);
        // Where k settles if k' goes to 0 at once.
        let k_settle = k0 + rate0 * rate0.abs() / (2.0 * jm);
        let sigma = if target > k_settle {
            1.0
        } else if target < k_settle {
            -1.0
        } else {
            0.0
        };
        // Peak k' (signed): from rate0 to the peak and back to 0 covers target − k0.
        let peak = if sigma == 0.0 {
            0.0
        } else {
            let (kk, rr, gg) = (sigma * k0, sigma * rate0, sigma * target);
            sigma
                * ((2.0 * jm * (gg - kk) + rr * rr) / 2.0)
                    .max(0.0)
                    .sqrt()
                    .min(dm)
        };
        let t1 = (peak - rate0).abs() / jm;
        let t3 = peak.abs() / jm;
        let dk1 = 0.5 * (rate0 + peak) * t1;
        let dk3 = 0.5 * peak * t3;
        let t2 = if peak != 0.0 {
            ((target - k0 - dk1 - dk3) / peak).max(0.0)
        } else {
            0.0
        };
        let mut p = KProfile {
            n0,
            tau0_s,
            k: [k0; 3],
            rate: [rate0; 3],
            integral_s: [0.0; 3],
            rate_change: [(peak - rate0).signum() * jm, 0.0, -peak.signum() * jm],
            dur_s: [t1, t2, t3],
            k_end: target,
            integral_end_s: 0.0,
            quiet: false,
        };
        if t1 == 0.0 {
            p.rate_change[0] = 0.0;
        }
        if t3 == 0.0 {
            p.rate_change[2] = 0.0;
        }
        for i in 0..3 {
            let end = p.phase_at(i, p.dur_s[i]);
            if i < 2 {
                p.k[i + 1] = end.k;
                p.rate[i + 1] = end.rate;
                p.integral_s[i + 1] = end.integral_s;
            } else {
                p.integral_end_s = end.integral_s;
            }
        }
        p
    }

    /// The state `t_s` into phase `i`.
    fn phase_at(&self, i: usize, t_s: f64) -> KState {
        let (k, r, j) = (self.k[i], self.rate[i], self.rate_change[i]);
        KState {
            k: (k + r * t_s + 0.5 * j * t_s * t_s).clamp(0.0, MAX_OVERRIDE),
            rate: r + j * t_s,
            integral_s: self.integral_s[i]
                + k * t_s
                + 0.5 * r * t_s * t_s
                + j * t_s * t_s * t_s / 6.0,
            done: false,
        }
    }

    /// The time since the ramp started at which `∫k dt` reaches `integral_s` (`k` > 0 on the
    /// way; Newton's method on the smooth, increasing integral).
    fn time_at(&self, integral_s: f64) -> f64 {
        let total_s = self.dur_s[0] + self.dur_s[1] + self.dur_s[2];
        if integral_s >= self.integral_end_s && self.k_end > 0.0 {
            return total_s + (integral_s - self.integral_end_s) / self.k_end;
        }
        let (mut lo, mut hi) = (0.0, total_s);
        let mut t = (integral_s / self.k[0].max(1e-9)).clamp(lo, hi);
        for _ in 0..50 {
            let s = self.at(t);
            let err = s.integral_s - integral_s;
            if err.abs() <= 1e-12 * integral_s.abs().max(1e-3) {
                break;
            }
            if err > 0.0 {
                hi = t;
            } else {
                lo = t;
            }
            let next = t - err / s.k.max(1e-9);
            t = if next > lo && next < hi {
                next
            } else {
                0.5 * (lo + hi)
            };
        }
        t
    }

    /// The state `t_s` after the ramp started.
    fn at(&self, t_s: f64) -> KState {
        let mut t = t_s;
        for i in 0..3 {
            if t < self.dur_s[i] {
                return self.phase_at(i, t);
            }
            t -= self.dur_s[i];
        }
        KState {
            k: self.k_end,
            rate: 0.0,
            integral_s: self.integral_end_s + self.k_end * t,
            done: true,
        }
    }
}

/// A stretch of plan time where `k` may not reach [`MAX_OVERRIDE`]: `k ≤ ceiling` there.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Low {
    from_s: f64,
    to_s: f64,
    ceiling: f64,
}

/// The stretches of a segment where `k` is held below [`MAX_OVERRIDE`], given the segment that
/// follows it (`None`: the end of the motion): 1 wherever the plan accelerates, decelerates or
/// dwells; on the cruise, `v_limit/v` of the segment and of the junctions the cruise runs into
/// (see the module documentation).
fn lows_of(seg: &Segment, next: Option<&Segment>, out: &mut VecDeque<Low>) {
    const EPS_S: f64 = 1e-12;
    let mut add = |from_s: f64, to_s: f64, ceiling: f64| {
        if to_s < from_s || ceiling >= MAX_OVERRIDE {
            return;
        }
        match out.back_mut() {
            Some(last) if last.ceiling == ceiling && last.to_s >= from_s => last.to_s = to_s,
            _ => out.push_back(Low {
                from_s,
                to_s,
                ceiling,
            }),
        }
    };
    let (start, end) = (seg.start_time_s, seg.end_time_s());
    let Some(p) = &seg.profile else {
        // A dwell is not shortened; a stop has no duration.
        add(start, end, 1.0);
        return;
    };
    let times = p.phase_start_times_s();
    let (cruise_from, cruise_to) = (times[3], times[4]);
    let v = p.v_cruise_mm_s();
    if !(cruise_to > cruise_from && v > 0.0) {
        add(start, end, 1.0);
        return;
    }
    let mut c = seg.v_limit_mm_s / v;
    if cruise_from <= EPS_S && seg.v_start_mm_s > 0.0 {
        c = c.min(seg.v_start_limit_mm_s / seg.v_start_mm_s);
    }
    if cruise_to >= p.duration_s() - EPS_S && seg.v_end_mm_s > 0.0 {
        c = c.min(next.map_or(1.0, |n| n.v_start_limit_mm_s / seg.v_end_mm_s));
    }
    if cruise_from > 0.0 {
        add(start, start + cruise_from, 1.0);
    }
    add(start + cruise_from, start + cruise_to, c.max(1.0));
    if cruise_to < p.duration_s() {
        add(start + cruise_to, end, 1.0);
    }
}

/// A straight cruise, where the profile uses none of the acceleration and jerk it may use: a
/// ramp of `k` may take them instead, `|k'| ≤ rate` and `|k''| ≤ rate_change` (see "Quiet
/// ramps" in the module documentation).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Quiet {
    from_s: f64,
    to_s: f64,
    rate_per_s: f64,
    rate_change_per_s2: f64,
    /// A ramp may go on into the next segment's quiet stretch: without a jerk limit only (with
    /// one, `k'·v` turning with the path at a junction would step the acceleration).
    joins: bool,
}

/// The quiet stretch of a segment, if it has one: the cruise of a line, where `|k'|·v ≤ a` and
/// `|k''|·v ≤ j` with the profile's own path limits `a` and `j` keep every axis within what the
/// profile may use there (`|uᵢ|·a`, `|uᵢ|·j`). Without a jerk limit `k'` ramps over four periods.
fn quiet_of(seg: &Segment, period_s: f64, out: &mut VecDeque<Quiet>) {
    let (Some(p), SegmentPath::Line { .. }) = (&seg.profile, seg.path) else {
        return;
    };
    let times = p.phase_start_times_s();
    let v = p.v_cruise_mm_s();
    if !(times[4] > times[3] && v > 0.0) {
        return;
    }
    let rate_per_s = (p.limits().a_max_mm_s2() / v).min(1.0 / period_s);
    let j = p.limits().j_max_mm_s3();
    let rate_change_per_s2 = if j.is_finite() {
        (j / v).min(1.0 / (period_s * period_s))
    } else {
        rate_per_s / (4.0 * period_s)
    };
    out.push_back(Quiet {
        from_s: seg.start_time_s + times[3],
        to_s: seg.start_time_s + times[4],
        rate_per_s,
        rate_change_per_s2,
        joins: !j.is_finite(),
    });
}

/// Samples planned segments at a fixed period. See the module documentation.
#[derive(Debug, Clone)]
pub struct Interpolator {
    /// The segments not yet passed: by the raw cursor (from `raw` on) and, with smoothing, by
    /// the filtered point (from `geo` on).
    queue: VecDeque<Segment>,
    /// Path distance from the start to each queued segment's start.
    starts_mm: VecDeque<f64>,
    /// Path distance to the end of the queued motion.
    queued_end_dist_mm: f64,
    /// Index in `queue` of the segment of the raw cursor (plan time `τ`).
    raw: usize,
    /// Index in `queue` of the segment of the filtered point.
    geo: usize,
    /// Indices in `queue` of the segments of the contour pre-compensation's window ends
    /// (`floor ≤ behind ≤ geo ≤ ahead`; see [`smooth`]).
    behind: usize,
    ahead: usize,
    /// Index in `queue` of the first segment after the latest stop the filtered point has
    /// passed: the window reaches no further back.
    floor: usize,
    /// The jerk-limited mode's filters ([`crate::planner::Smoothing`]), if the plan has them.
    smoother: Option<Smoother>,
    period_s: f64,
    /// End point and end time of the last segment queued (the start before any).
    queued_end_mm: Vector3<f64>,
    queued_end_s: f64,
    /// No more segments will come.
    closed: bool,
    /// Number of samples produced so far (starved calls do not count).
    samples: u64,
    /// The latest sample.
    last_mm: Vector3<f64>,
    /// Source line of the segment of the latest sample (or of the first queued before any).
    line: Option<usize>,
    finished: bool,
    /// The override ramp; `None`: no override, `k = 1` always.
    ramp: Option<OverrideRamp>,
    /// The override asked for (may exceed [`MAX_OVERRIDE`]; clamped to it in effect).
    requested: f64,
    /// A hold is asked for.
    held: bool,
    /// `k` against time since the latest change.
    k_profile: KProfile,
    /// `k` at the latest sample, and its plan time.
    last_k: KState,
    last_tau_s: f64,
    /// Where the queued plan holds `k` below [`MAX_OVERRIDE`], in time order, known up to
    /// `lows_until_s` (the last queued segment's waits for its successor, or the close).
    lows: VecDeque<Low>,
    lows_until_s: f64,
    /// The straight cruises of the queued plan, in time order.
    quiets: VecDeque<Quiet>,
    /// A change of the target waits for the quiet ramp in flight to end.
    deferred: bool,
    /// The auxiliary axes' samples ([`aux`]).
    aux: aux::AuxSampler,
}

impl Interpolator {
    /// Prepares to sample a whole `plan` every `period_s` seconds, starting at its start.
    pub fn new(plan: Plan, period_s: f64) -> Result<Interpolator, InterpError> {
        let mut interp = Interpolator::streaming(plan.start_mm(), period_s)?;
        if let Some(spec) = plan.smoothing() {
            interp = interp.with_smoothing(spec);
        }
        for seg in plan.segments() {
            interp.aux.note_segment(seg);
            interp.starts_mm.push_back(interp.queued_end_dist_mm);
            interp.queued_end_dist_mm += seg.length_mm;
            interp.queue.push_back(*seg);
        }
        interp.queued_end_mm = plan.end_mm();
        interp.queued_end_s = plan.duration_s();
        interp.line = plan.segments().first().map(|s| s.line);
        interp.closed = true;
        Ok(interp)
    }

    /// Prepares to sample segments pushed later, from `start_mm` at time 0.
    pub fn streaming(start_mm: Vector3<f64>, period_s: f64) -> Result<Interpolator, InterpError> {
        if !(period_s > 0.0 && period_s.is_finite()) {
            return Err(InterpError::InvalidPeriod { period_s });
        }
        Ok(Interpolator {
            queue: VecDeque::new(),
            starts_mm: VecDeque::new(),
            queued_end_dist_mm: 0.0,
            raw: 0,
            geo: 0,
            behind: 0,
            ahead: 0,
            floor: 0,
            smoother: None,
            period_s,
            queued_end_mm: start_mm,
            queued_end_s: 0.0,
            closed: false,
            samples: 0,
            last_mm: start_mm,
            line: None,
            finished: false,
            ramp: None,
            requested: 1.0,
            held: false,
            k_profile: KProfile::steady(0, 0.0, 1.0),
            last_k: KState {
                k: 1.0,
                rate: 0.0,
                integral_s: 0.0,
                done: true,
            },
            last_tau_s: 0.0,
            lows: VecDeque::new(),
            lows_until_s: 0.0,
            quiets: VecDeque::new(),
            deferred: false,
            aux: aux::AuxSampler::new(),
        })
    }

    /// Applies the jerk-limited mode's filters to the samples (see [`smooth`]): the segments
    /// must be planned for them ([`crate::planner::Planner::smoothing`]). Call before the
    /// first [`update`](Self::update).
    pub fn with_smoothing(mut self, spec: Smoothing) -> Interpolator {
        self.smoother = Some(Smoother::new(spec, self.period_s, self.last_mm));
        self.aux.with_filters(spec, self.period_s);
        self
    }

    /// The filters applied to the samples, if any.
    pub fn smoothing(&self) -> Option<Smoothing> {
        self.smoother.as_ref().map(Smoother::spec)
    }

    /// Allows [`set_override`](Self::set_override), [`hold`](Self::hold) and
    /// [`resume`](Self::resume), with `k` ramping within `ramp`.
    pub fn with_override_ramp(mut self, ramp: OverrideRamp) -> Interpolator {
        self.ramp = Some(ramp);
        self.lows.clear();
        self.quiets.clear();
        // The last segment of an open queue waits for its successor (or the close).
        let known = if self.closed {
            self.queue.len()
        } else {
            self.queue.len().saturating_sub(1)
        };
        for i in self.raw.min(known)..known {
            self.note_stretches(i);
        }
        self
    }

    /// Records where queued segment `i` holds `k` below [`MAX_OVERRIDE`] and where it is a
    /// quiet cruise; its successor must be queued, or the queue closed. Only an interpolator
    /// with an override ramp keeps them.
    fn note_stretches(&mut self, i: usize) {
        if self.ramp.is_none() {
            return;
        }
        let seg = &self.queue[i];
        lows_of(seg, self.queue.get(i + 1), &mut self.lows);
        quiet_of(seg, self.period_s, &mut self.quiets);
        self.lows_until_s = seg.end_time_s();
    }

    /// Asks for the feed override `fraction` (1 = 100 %; above 1 counts as 1, see the module
    /// documentation). `k` starts moving towards it with the next [`update`](Self::update)
    /// (during a hold, on [`resume`](Self::resume)).
    pub fn set_override(&mut self, fraction: f64) -> Result<(), InterpError> {
        if !(fraction >= 0.0 && fraction.is_finite()) {
            return Err(InterpError::InvalidOverride { fraction });
        }
        if self.ramp.is_none() {
            return Err(InterpError::NoOverrideRamp);
        }
        self.requested = fraction;
        self.retarget();
        Ok(())
    }

    /// Feed hold: `k` ramps down to 0 and the motion stops on the path; [`Status::Held`] once
    /// it stands still.
    pub fn hold(&mut self) -> Result<(), InterpError> {
        self.set_held(true)
    }

    /// Ends a hold: `k` ramps back up to the requested override.
    pub fn resume(&mut self) -> Result<(), InterpError> {
        self.set_held(false)
    }

    fn set_held(&mut self, held: bool) -> Result<(), InterpError> {
        if self.ramp.is_none() {
            return Err(InterpError::NoOverrideRamp);
        }
        self.held = held;
        self.retarget();
        Ok(())
    }

    /// The override asked for with [`set_override`](Self::set_override) (1 by default).
    pub fn requested_override(&self) -> f64 {
        self.requested
    }

    /// The effective override `k` of the latest sample (0 while held, 1 without override).
    pub fn effective_override(&self) -> f64 {
        self.last_k.k
    }

    /// Whether a hold is asked for (the motion may still be ramping down; see
    /// [`is_standing_still`](Self::is_standing_still)).
    pub fn is_held(&self) -> bool {
        self.held
    }

    /// Whether `k` has ramped down to 0 and stays there (a hold, or a 0 % override, done).
    pub fn is_standing_still(&self) -> bool {
        self.last_k.done && self.last_k.k == 0.0 && self.smoother_settled()
    }

    fn smoother_settled(&self) -> bool {
        self.smoother.as_ref().is_none_or(Smoother::is_settled) && self.aux.is_settled()
    }

    /// The override ramp, if any.
    pub fn override_ramp(&self) -> Option<OverrideRamp> {
        self.ramp
    }

    /// The target of `k`: 0 in a hold, else the requested override up to [`MAX_OVERRIDE`].
    fn k_target(&self) -> f64 {
        if self.held {
            0.0
        } else {
            self.requested.min(MAX_OVERRIDE)
        }
    }

    /// Above 100 %: before the sample numbered `self.samples + 1`, keeps `k` where the plan
    /// allows it (see the module documentation). The ramp towards the target goes on if, from
    /// the sample it gives, a ramp down to 1 stays under the ceiling all the way; otherwise `k`
    /// ramps down to 1 from the latest sample, which the same check admitted a cycle earlier.
    fn govern(&mut self) {
        let Some(ramp) = self.ramp else { return };
        let want = self.k_target();
        if want <= 1.0 || self.deferred {
            // A ramp to 1 or below stays under the ramp to 1 that was checked.
            return;
        }
        let n = self.samples.saturating_add(1);
        let braking = self.k_profile.k_end == 1.0;
        if self.k_profile.k_end == want {
            if self.brake_fits(&self.k_profile, n, &ramp) {
                return;
            }
        } else {
            let now = self.k_at(self.samples);
            let tau_s = self.tau_at(self.samples);
            let towards = KProfile::plan(self.samples, tau_s, now.k, now.rate, want, &ramp);
            if self.brake_fits(&towards, n, &ramp) {
                self.k_profile = towards;
                return;
            }
        }
        if !braking {
            let now = self.k_at(self.samples);
            let tau_s = self.tau_at(self.samples);
            self.k_profile = KProfile::plan(self.samples, tau_s, now.k, now.rate, 1.0, &ramp);
        }
    }

    /// Whether `k` may take the sample numbered `n` of `profile`: from that sample, the ramp
    /// down to 1 keeps every sample under the ceiling of the queued plan. A sample's `k` counts
    /// against every stretch of the plan between it and the sample before (plan time advances
    /// at most `MAX_OVERRIDE·T` per sample), so that the velocity changes it samples are those
    /// of a plan run at that `k`.
    fn brake_fits(&self, profile: &KProfile, n: u64, ramp: &OverrideRamp) -> bool {
        let t = self.period_s;
        let at = profile.at(n.saturating_sub(profile.n0) as f64 * t);
        let tau_s = (profile.tau0_s + at.integral_s).max(self.last_tau_s);
        let brake = KProfile::plan(n, tau_s, at.k, at.rate, 1.0, ramp);
        // The highest k from the latest sample on, and where the ramp is at 1 again (plan time).
        let peak_t_s = if at.rate > 0.0 {
            at.rate / ramp.max_rate_change_per_s2
        } else {
            0.0
        };
        let peak = self.last_k.k.max(brake.at(peak_t_s).k).max(at.k);
        if peak <= 1.0 {
            return true;
        }
        let end_s = brake.tau0_s + brake.integral_end_s;
        if end_s > self.lows_until_s && !(self.closed && end_s >= self.queued_end_s) {
            return false;
        }
        let step_s = MAX_OVERRIDE * t;
        for low in &self.lows {
            if low.to_s < self.last_tau_s {
                continue;
            }
            if low.from_s > end_s + step_s {
                break;
            }
            if low.ceiling >= peak {
                continue;
            }
            // The highest k of a sample that steps into the stretch or lies in it: the ramp is
            // past its peak and falls from there on.
            let from_s = low.from_s - step_s;
            let k = if from_s <= tau_s {
                peak
            } else {
                let t_in = brake.time_at(from_s - brake.tau0_s);
                if t_in <= peak_t_s {
                    peak
                } else {
                    brake.at(t_in).k
                }
            };
            if k > low.ceiling {
                return false;
            }
        }
        true
    }

    /// Replans `k` from the latest sample's state towards the current target (above 1, the
    /// next [`update`](Self::update) checks it first).
    fn retarget(&mut self) {
        let Some(ramp) = self.ramp else { return };
        let target = self.k_target();
        let now = self.k_at(self.samples);
        self.deferred = false;
        if now.done && now.k == target {
            return;
        }
        let tau_s = self.tau_at(self.samples);
        if target <= 1.0
            && let Some(quiet) = self.quiet_ramp(now, tau_s, target, &ramp)
        {
            self.k_profile = quiet;
            return;
        }
        // A quiet ramp whose `k` already stands at its end (clamped there, its rate a rounding
        // or at most one period's change of the ramp's own) has ended: a target above 1 that
        // came then waited a sample for nothing (a proptest seed of
        // `k_stays_within_0_and_2_and_its_rate_within_the_ramp`).
        let ended = now.done
            || (now.k == self.k_profile.k_end
                && now.rate.abs() <= ramp.max_rate_change_per_s2 * self.period_s);
        if self.k_profile.quiet && !ended {
            // `k'` may be beyond the ramp's own rate: the quiet ramp runs to its end first.
            self.deferred = true;
            return;
        }
        self.k_profile = KProfile::plan(self.samples, tau_s, now.k, now.rate, target, &ramp);
    }

    /// A ramp from `now` (plan time `tau_s`) to `target` faster than `ramp`, where it runs on
    /// straight cruises only, a period's travel either side included, at the lowest quiet rates
    /// of the cruises it runs on; `None` where there is none.
    fn quiet_ramp(
        &self,
        now: KState,
        tau_s: f64,
        target: f64,
        ramp: &OverrideRamp,
    ) -> Option<KProfile> {
        let step_s = MAX_OVERRIDE * self.period_s;
        let mut rates = (f64::INFINITY, f64::INFINITY);
        let mut span_s = 0.0;
        for _ in 0..4 {
            rates = self.quiet_rates(tau_s - step_s, tau_s + span_s + step_s, rates)?;
            if rates.0 <= ramp.max_rate_per_s || rates.1 <= ramp.max_rate_change_per_s2 {
                return None;
            }
            let quiet = OverrideRamp {
                max_rate_per_s: rates.0,
                max_rate_change_per_s2: rates.1,
            };
            let mut p = KProfile::plan(self.samples, tau_s, now.k, now.rate, target, &quiet);
            p.quiet = true;
            if p.integral_end_s <= span_s {
                return Some(p);
            }
            span_s = p.integral_end_s;
        }
        None
    }

    /// The lowest quiet rates (no higher than `at_most`) over `[from, to]` of plan time, if
    /// quiet stretches cover it without a gap.
    fn quiet_rates(&self, from_s: f64, to_s: f64, at_most: (f64, f64)) -> Option<(f64, f64)> {
        const EPS_S: f64 = 1e-9;
        let mut covered_s = from_s;
        let mut rates = at_most;
        let mut joins = true;
        for q in &self.quiets {
            if q.to_s < from_s {
                continue;
            }
            if q.from_s > covered_s + EPS_S || (q.from_s > from_s && !(joins && q.joins)) {
                return None;
            }
            joins = q.joins;
            rates = (rates.0.min(q.rate_per_s), rates.1.min(q.rate_change_per_s2));
            covered_s = q.to_s;
            if covered_s >= to_s {
                return Some(rates);
            }
        }
        None
    }

    /// `k` at the sample numbered `n`.
    fn k_at(&self, n: u64) -> KState {
        let p = &self.k_profile;
        p.at(n.saturating_sub(p.n0) as f64 * self.period_s)
    }

    /// Plan time of the sample numbered `n` (never before the latest sample's).
    fn tau_at(&self, n: u64) -> f64 {
        let tau_s = self.k_profile.tau0_s + self.k_at(n).integral_s;
        if n > self.samples {
            tau_s.max(self.last_tau_s)
        } else {
            tau_s
        }
    }

    /// The first of the moving segments `from..=self.raw` that run on into segment `raw`
    /// with `same` holding for each: where a filter that segment `raw` switches began to be
    /// needed. The plan switches the filters only at rest, so that is the point they start
    /// settled at; the sample that switches them may lie in a later segment of the run (a
    /// short one, or one that a move ending on a sample hands over to at once). Started at
    /// the latest sample instead, the axis filters pulled a move alone's last period into
    /// the next move (6–8 nm, X's jerk 16 % over on LinuxCNC's `rickg-arcs.ngc` at 1 ms), and
    /// started at segment `raw`'s own start, the time-law filter jumped over a segment of
    /// 10 µm passed over (`tangent_check.ngc` at 4 ms: X's jerk 35 % over).
    fn run_start(&self, from: usize, same: impl Fn(&Segment) -> bool) -> usize {
        let mut j = self.raw;
        while j > from && {
            let before = &self.queue[j - 1];
            before.length_mm > 0.0 && same(before)
        } {
            j -= 1;
        }
        j
    }

    /// Queues the next segment: it must start exactly where and when the last queued one ended
    /// (`start_mm` bit for bit; `start_time_s` within a nanosecond), on a queue not closed.
    pub fn push(&mut self, segment: Segment) -> Result<(), InterpError> {
        let continuous = segment.start_mm == self.queued_end_mm
            && (segment.start_time_s - self.queued_end_s).abs() <= 1e-9;
        if self.closed || !continuous {
            return Err(InterpError::Discontinuous { line: segment.line });
        }
        self.queued_end_mm = segment.end_mm;
        self.queued_end_s = segment.end_time_s();
        self.aux.note_segment(&segment);
        if self.line.is_none() {
            self.line = Some(segment.line);
        }
        self.starts_mm.push_back(self.queued_end_dist_mm);
        self.queued_end_dist_mm += segment.length_mm;
        self.queue.push_back(segment);
        if self.queue.len() >= 2 {
            self.note_stretches(self.queue.len() - 2);
        }
        Ok(())
    }

    /// No more segments: the sample that reaches the end of the queue finishes.
    pub fn close(&mut self) {
        if !self.closed && !self.queue.is_empty() {
            self.closed = true;
            self.note_stretches(self.queue.len() - 1);
        }
        self.closed = true;
    }

    /// Whether the next sample's time lies beyond the queued segments of an open queue: the
    /// producer must push (or close) before the next [`update`](Self::update).
    ///
    /// With the jerk-limited mode's filters the queue must also reach beyond the next sample's
    /// plan time by the filters' look-ahead: the contour pre-compensation's window reaches
    /// `PRECOMP_REACH·v·T_k` past the filtered point, which trails the raw one.
    pub fn needs_segments(&self) -> bool {
        let ahead_s = self.smoother.as_ref().map_or(0.0, |sm| {
            let spec = sm.spec();
            spec.time_law_s(self.period_s)
                + 2.0 * smooth::PRECOMP_REACH * spec.axis_s(self.period_s)
        });
        !self.closed
            && self.tau_at(self.samples.saturating_add(1)) + ahead_s
                >= self.queued_end_s - END_SNAP_PERIODS * self.period_s
    }

    /// Produces the next sample into `out_mm`: the position one period after the previous
    /// sample (the first call gives the position at `period_s`). No allocation, no panic.
    pub fn update(&mut self, out_mm: &mut Vector3<f64>) -> Status {
        if self.finished {
            *out_mm = self.last_mm;
            return Status::Finished;
        }
        let behind_s = self.last_tau_s - MAX_OVERRIDE * self.period_s;
        while let Some(low) = self.lows.front()
            && low.to_s < behind_s
        {
            self.lows.pop_front();
        }
        while let Some(quiet) = self.quiets.front()
            && quiet.to_s < behind_s
        {
            self.quiets.pop_front();
        }
        if self.deferred && self.k_at(self.samples).done {
            self.retarget();
        }
        if self.ramp.is_some() && self.k_target() > 1.0 {
            self.govern();
        }
        // Exact for any realistic count (< 2^53 samples); without override `τ = n·T`.
        let n = self.samples.saturating_add(1);
        let k = self.k_at(n);
        let t_s = self.tau_at(n);
        let snap_s = END_SNAP_PERIODS * self.period_s;
        let entered = self.raw;
        while let Some(seg) = self.queue.get(self.raw) {
            // The last segment of an open queue is kept: it is what a starved call holds to.
            if t_s < seg.end_time_s() - snap_s {
                self.samples = n;
                self.last_k = k;
                self.last_tau_s = t_s;
                let local_s = t_s - seg.start_time_s;
                // The filters switch at rest, where the run of segments that needs them so
                // begins: this sample may have passed over its first ones.
                let (time_law_from, filters_from) = match self.smoother.as_ref() {
                    Some(smoother) if seg.length_mm > 0.0 => (
                        (seg.time_law != smoother.time_law())
                            .then(|| self.run_start(entered, |s| s.time_law == seg.time_law)),
                        (seg.axis_filters != smoother.axis_filters()).then(|| {
                            self.run_start(entered, |s| s.axis_filters == seg.axis_filters)
                        }),
                    ),
                    _ => (None, None),
                };
                self.last_mm = if let Some(smoother) = self.smoother.as_mut() {
                    if let Some(j) = time_law_from {
                        smoother.set_time_law(seg.time_law, self.starts_mm[j]);
                    }
                    if let Some(j) = filters_from {
                        smoother.set_axis_filters(seg.axis_filters, self.queue[j].start_mm);
                    }
                    smoother.note_plan_time(t_s);
                    let raw_mm = self.starts_mm[self.raw] + seg.distance_at(local_s);
                    self.smooth(raw_mm)
                } else {
                    self.line = Some(seg.line);
                    self.aux.sample(seg, seg.distance_at(local_s));
                    seg.position_at(local_s)
                };
                self.trim();
                *out_mm = self.last_mm;
                let line = self.line.unwrap_or(0);
                if k.done && k.k == 0.0 && self.smoother_settled() {
                    return Status::Held { line };
                }
                return Status::Working { line };
            }
            if self.smoother.is_none() {
                self.line = Some(seg.line);
            }
            self.raw += 1;
        }
        if self.closed {
            self.samples = n;
            self.last_k = k;
            self.last_tau_s = t_s.min(self.queued_end_s);
            if let Some(smoother) = self.smoother.as_mut() {
                smoother.note_plan_time(self.last_tau_s);
                // The end of the raw plan: the filters catch up (the planner keeps still for
                // that long at the end, so this only happens for plans made otherwise).
                self.last_mm = self.smooth(self.queued_end_dist_mm);
                self.trim();
                if !self.smoother_settled() {
                    *out_mm = self.last_mm;
                    return Status::Working {
                        line: self.line.unwrap_or(0),
                    };
                }
            }
            self.finished = true;
            self.last_mm = self.queued_end_mm;
            self.aux.finish();
            *out_mm = self.last_mm;
            return Status::Finished;
        }
        *out_mm = self.last_mm;
        Status::Starved
    }

    /// The filtered sample for the raw path distance `raw_mm` (see [`smooth`]).
    fn smooth(&mut self, raw_mm: f64) -> Vector3<f64> {
        let period_s = self.period_s;
        let Some(smoother) = self.smoother.as_mut() else {
            return self.last_mm;
        };
        let s_mm = smoother.filter_distance(raw_mm);
        let v_mm_s = smoother.speed(s_mm, period_s);
        let reach_mm = smoother.reach_mm(v_mm_s, period_s);
        let n_k = smoother.spec().axis_periods;
        let last = self.queue.len().saturating_sub(1);
        while self.geo < last.min(self.raw)
            && self.starts_mm[self.geo] + self.queue[self.geo].length_mm < s_mm
        {
            let seg = &self.queue[self.geo];
            if seg.length_mm == 0.0
                || seg.v_end_mm_s == 0.0
                || self.queue[self.geo + 1].length_mm == 0.0
            {
                self.floor = self.geo + 1;
            }
            self.geo += 1;
        }
        let point = match self.queue.get(self.geo) {
            Some(seg) => {
                self.line = Some(seg.line);
                let start_mm = self.starts_mm[self.geo];
                self.aux.sample(seg, s_mm - start_mm);
                if s_mm >= start_mm + seg.length_mm {
                    seg.end_mm
                } else {
                    seg.point_at_distance(s_mm - start_mm)
                }
            }
            None => {
                if let Some(end) = self.aux.queued_end() {
                    self.aux.sample_raw(end);
                }
                self.queued_end_mm
            }
        };
        self.behind = self.behind.clamp(self.floor, self.geo);
        self.ahead = self.ahead.max(self.geo);
        let offset = if reach_mm > 0.0 && !self.queue.is_empty() && smoother.axis_filters() {
            let behind = self.window_behind(s_mm - reach_mm);
            let ahead = self.window_ahead(s_mm + reach_mm);
            precompensation(behind - point, ahead - point, v_mm_s, n_k, period_s)
        } else {
            Vector3::zeros()
        };
        let Some(smoother) = self.smoother.as_mut() else {
            return self.last_mm;
        };
        smoother.filter_point(point + offset)
    }

    /// The point at path distance `x_mm ≥` the filtered point's, for the window of the contour
    /// pre-compensation: on the queued path, but not beyond a stop (a segment ending at rest,
    /// or a dwell or stop) after the filtered point's segment, nor beyond the queue's end.
    fn window_ahead(&mut self, x_mm: f64) -> Vector3<f64> {
        let last = self.queue.len() - 1;
        let mut i = self.ahead.clamp(self.geo, last);
        while i > self.geo && x_mm < self.starts_mm[i] {
            i -= 1;
        }
        loop {
            let seg = &self.queue[i];
            let start_mm = self.starts_mm[i];
            if x_mm <= start_mm + seg.length_mm {
                self.ahead = i;
                return seg.point_at_distance(x_mm - start_mm);
            }
            let stops = seg.length_mm == 0.0
                || seg.v_end_mm_s == 0.0
                || i == last
                || self.queue[i + 1].length_mm == 0.0;
            if stops {
                self.ahead = i;
                return seg.end_mm;
            }
            i += 1;
        }
    }

    /// The point at path distance `x_mm ≤` the filtered point's, for the window of the contour
    /// pre-compensation: on the queued path, but not before the latest stop the filtered point
    /// has passed (`floor`).
    fn window_behind(&mut self, x_mm: f64) -> Vector3<f64> {
        let mut i = self.behind;
        while i < self.geo && x_mm > self.starts_mm[i] + self.queue[i].length_mm {
            i += 1;
        }
        while i > self.floor && x_mm < self.starts_mm[i] {
            i -= 1;
        }
        self.behind = i;
        let seg = &self.queue[i];
        seg.point_at_distance(x_mm - self.starts_mm[i])
    }

    /// Drops the segments every cursor has passed.
    fn trim(&mut self) {
        let passed = if self.smoother.is_some() {
            self.geo.min(self.raw).min(self.behind)
        } else {
            self.raw
        };
        for _ in 0..passed {
            self.queue.pop_front();
            self.starts_mm.pop_front();
        }
        self.raw -= passed;
        self.geo -= passed.min(self.geo);
        self.behind -= passed.min(self.behind);
        self.ahead -= passed.min(self.ahead);
        self.floor -= passed.min(self.floor);
    }

    /// Source line of the segment of the latest sample (the first segment's before any
    /// sample, the last one's once finished); `None` before any segment.
    pub fn current_line(&self) -> Option<usize> {
        self.line
    }

    /// The latest sample (the start point before any).
    pub fn last_mm(&self) -> Vector3<f64> {
        self.last_mm
    }

    /// The auxiliary axes (A B C U V W) at the latest sample: `None` until a moving segment
    /// was queued (it says where they start); see [`aux`].
    pub fn aux(&self) -> Option<&crate::gcode::AuxPos> {
        self.aux.last()
    }

    /// Time of the latest sample since the start: `n · period_s` after `n` samples (real
    /// time: a hold or an override below 100 % makes it run ahead of the plan time).
    pub fn elapsed_s(&self) -> f64 {
        self.samples as f64 * self.period_s
    }

    /// Plan time of the latest sample (`τ`; equal to [`elapsed_s`](Self::elapsed_s) without
    /// override, at most the plan's duration once finished).
    pub fn plan_time_s(&self) -> f64 {
        self.last_tau_s
    }

    /// A plan time whose point the latest sample has reached along the path: the plan time
    /// itself without smoothing; with it, that of the sample one settling time earlier (the
    /// filters lag behind the plan). A resume point taken here never skips any of the path.
    pub fn reached_plan_time_s(&self) -> f64 {
        match &self.smoother {
            Some(s) if !self.finished => s.reached_plan_time_s().min(self.last_tau_s),
            _ => self.last_tau_s,
        }
    }

    /// Whether the final point has been produced.
    pub fn is_finished(&self) -> bool {
        self.finished
    }

    /// The interpolation period.
    pub fn period_s(&self) -> f64 {
        self.period_s
    }

    /// End point of the queued motion (the whole program's once closed).
    pub fn queued_end_mm(&self) -> Vector3<f64> {
        self.queued_end_mm
    }

    /// Where the queued motion leaves the auxiliary axes (`None` before a moving segment).
    pub fn queued_end_aux(&self) -> Option<crate::gcode::AuxPos> {
        self.aux.queued_end()
    }

    /// End time of the queued motion (the whole program's duration once closed).
    pub fn duration_s(&self) -> f64 {
        self.queued_end_s
    }

    /// Segments queued and not yet passed by the plan time.
    pub fn queued(&self) -> usize {
        self.queue.len() - self.raw.min(self.queue.len())
    }

    /// Number of calls to [`update`](Self::update) needed to reach [`Status::Finished`]
    /// from the start (1 for a plan without motion), once the queue is closed, at 100 %.
    pub fn total_samples(&self) -> u64 {
        let periods = self.queued_end_s / self.period_s;
        let k = (periods - END_SNAP_PERIODS).ceil().max(1.0);
        // Saturating float-to-int cast: a plan too long to count is "forever".
        k as u64
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::planner::tests::{Move, feed, plan_moves, v};
    use crate::planner::{Limits, ProfileKind};
    use proptest::prelude::*;

    fn limits() -> Limits {
        Limits {
            max_vel_mm_s: v(100.0, 100.0, 50.0),
            max_acc_mm_s2: v(1000.0, 1000.0, 500.0),
            max_feed_mm_s: 100.0,
        }
    }

    /// Runs to the end; returns the samples and statuses (first `Finished` included).
    fn run(interp: &mut Interpolator) -> Vec<(Vector3<f64>, Status)> {
        let mut out = Vec::new();
        let mut p = Vector3::zeros();
        loop {
            let status = interp.update(&mut p);
            out.push((p, status));
            if status == Status::Finished {
                return out;
            }
        }
    }

    /// With the jerk-limited mode's filters the output lags behind the plan time; the plan
    /// time it is said to have reached (the resume point's) is never ahead of it on the path.
    #[test]
    fn the_reached_plan_time_is_never_ahead_of_the_filtered_output() {
        let program = crate::gcode::parse_program(
            "G21 G90 G64 G1 X50 F6000\nG1 X120 F3000\nM2\n",
            "line.ngc",
            Vector3::zeros(),
        )
        .unwrap();
        let cfg = PlannerConfig {
            period_s: 0.001,
            corner_acc_mm_s2: 1000.0,
            path_acc_share: 0.75,
            max_jerk_mm_s3: v(20_000.0, 20_000.0, 10_000.0),
            profile: ProfileKind::SCurve,
            ..PlannerConfig::exact_stop()
        };
        let plan = crate::planner::plan_with(&program, &limits(), &cfg).unwrap();
        assert!(plan.smoothing().is_some());
        let mut interp = Interpolator::new(plan.clone(), cfg.period_s).unwrap();
        let mut p = Vector3::zeros();
        let mut lagged = false;
        while interp.update(&mut p) != Status::Finished {
            let reached = plan.position_at(interp.reached_plan_time_s());
            assert!(reached.x <= p.x + 1e-9, "{} ahead of {}", reached.x, p.x);
            lagged |= plan.position_at(interp.plan_time_s()).x > p.x + 1e-3;
        }
        assert!(lagged, "the filters lag behind the plan");
        assert_eq!(interp.reached_plan_time_s(), plan.duration_s());
        assert_eq!(p, Vector3::new(120.0, 0.0, 0.0));
    }

    #[test]
    fn samples_follow_the_plan_and_end_exactly() {
        let target = v(10.1, -3.3, 0.7);
        let plan = plan_moves(Vector3::zeros(), &[feed(3, target, 20.0)], &limits()).unwrap();
        let reference = plan.clone();
        let mut interp = Interpolator::new(plan, 0.001).unwrap();
        assert_eq!(interp.current_line(), Some(3));
        let samples = run(&mut interp);
        assert_eq!(samples.len() as u64, interp.total_samples());
        for (k, (p, status)) in samples.iter().enumerate() {
            if *status != Status::Finished {
                assert_eq!(*status, Status::Working { line: 3 });
                assert_eq!(*p, reference.position_at((k + 1) as f64 * 0.001));
            }
        }
        let (last, status) = *samples.last().unwrap();
        assert_eq!(status, Status::Finished);
        assert_eq!(last, target);
        assert!(interp.is_finished());
        assert!((interp.elapsed_s() - samples.len() as f64 * 0.001).abs() < 1e-12);
        // Keeps returning the final point.
        let mut p = Vector3::zeros();
        for _ in 0..3 {
            assert_eq!(interp.update(&mut p), Status::Finished);
            assert_eq!(p, target);
        }
        assert_eq!(interp.current_line(), Some(3));
    }

    #[test]
    fn reports_the_line_of_each_segment() {
        let moves = [
            feed(1, v(1.0, 0.0, 0.0), 10.0),
            feed(2, v(1.0, 0.0, 0.0), 10.0),
            feed(5, v(1.0, 1.0, 0.0), 10.0),
        ];
        let plan = plan_moves(Vector3::zeros(), &moves, &limits()).unwrap();
        let mut interp = Interpolator::new(plan, 0.002).unwrap();
        let mut lines: Vec<usize> = run(&mut interp)
            .iter()
            .filter_map(|(_, s)| match s {
                Status::Working { line } => Some(*line),
                Status::Finished | Status::Starved | Status::Held { .. } => None,
            })
            .collect();
        lines.dedup();
        assert_eq!(lines, vec![1, 5]);
        assert_eq!(interp.current_line(), Some(5));
    }

    #[test]
    fn streaming_gives_the_samples_of_the_whole_plan_and_holds_time_when_starved() {
        let moves = [
            feed(1, v(3.0, 0.0, 0.0), 20.0),
            feed(2, v(3.0, 2.0, 1.0), 15.0),
            feed(3, v(0.0, 0.0, 0.0), 30.0),
        ];
        let plan = plan_moves(Vector3::zeros(), &moves, &limits()).unwrap();
        let whole = run(&mut Interpolator::new(plan.clone(), 0.001).unwrap());

        let mut interp = Interpolator::streaming(Vector3::zeros(), 0.001).unwrap();
        let mut pending = plan.segments().iter().copied();
        let mut streamed = Vec::new();
        let mut starved = 0;
        let mut out = Vector3::zeros();
        loop {
            // Starve the sampler once per segment before feeding it.
            if interp.needs_segments() {
                let held = interp.elapsed_s();
                assert_eq!(interp.update(&mut out), Status::Starved);
                assert_eq!(
                    interp.elapsed_s(),
                    held,
                    "a starved call must not advance time"
                );
                starved += 1;
                match pending.next() {
                    Some(seg) => interp.push(seg).unwrap(),
                    None => interp.close(),
                }
                continue;
            }
            let status = interp.update(&mut out);
            streamed.push((out, status));
            if status == Status::Finished {
                break;
            }
        }
        assert_eq!(streamed, whole, "bit for bit the samples of the whole plan");
        assert_eq!(starved, plan.segments().len() + 1);
        assert_eq!(interp.queued(), 0);
    }

    #[test]
    fn a_segment_that_does_not_continue_the_queue_is_refused() {
        let moves = [
            feed(1, v(3.0, 0.0, 0.0), 20.0),
            feed(2, v(3.0, 2.0, 0.0), 20.0),
        ];
        let plan = plan_moves(Vector3::zeros(), &moves, &limits()).unwrap();
        let segs = plan.segments();
        let mut interp = Interpolator::streaming(Vector3::zeros(), 0.001).unwrap();
        assert_eq!(
            interp.push(segs[1]),
            Err(InterpError::Discontinuous { line: 2 }),
            "the second segment cannot come first"
        );
        interp.push(segs[0]).unwrap();
        let mut late = segs[1];
        late.start_time_s += 0.01;
        assert!(interp.push(late).is_err(), "a gap in time is refused");
        interp.push(segs[1]).unwrap();
        interp.close();
        assert!(interp.push(segs[1]).is_err(), "nothing after close");
    }

    #[test]
    fn exact_multiple_of_the_period_ends_without_an_extra_sample() {
        // 100 mm at 50 mm/s, a = 1000 (X): duration 2.05 s, which is 2050 periods of 1 ms.
        let plan = plan_moves(
            Vector3::zeros(),
            &[feed(1, v(100.0, 0.0, 0.0), 50.0)],
            &limits(),
        )
        .unwrap();
        assert!((plan.duration_s() - 2.05).abs() < 1e-12);
        let mut interp = Interpolator::new(plan, 0.001).unwrap();
        assert_eq!(interp.total_samples(), 2050);
        assert_eq!(run(&mut interp).len(), 2050);
    }

    #[test]
    fn empty_plan_finishes_at_once() {
        let mut interp = Interpolator::new(Plan::at_rest(v(1.0, 2.0, 3.0)), 0.004).unwrap();
        assert_eq!(interp.current_line(), None);
        assert_eq!(interp.total_samples(), 1);
        let mut p = Vector3::zeros();
        assert_eq!(interp.update(&mut p), Status::Finished);
        assert_eq!(p, v(1.0, 2.0, 3.0));
    }

    #[test]
    fn rejects_bad_periods() {
        for period_s in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            assert!(Interpolator::new(Plan::at_rest(Vector3::zeros()), period_s).is_err());
        }
    }

    /// A random program: each axis of each target either moves to a new value or stays.
    fn moves_strategy() -> impl Strategy<Value = (Vector3<f64>, Vec<Move>)> {
        let coord = -50.0..50.0f64;
        let start = (coord.clone(), coord.clone(), coord.clone()).prop_map(|(x, y, z)| v(x, y, z));
        let axis = proptest::option::weighted(0.7, coord);
        let step = (
            [axis.clone(), axis.clone(), axis],
            any::<bool>(),
            5.0..300.0f64,
        );
        (start, proptest::collection::vec(step, 1..6)).prop_map(|(start, steps)| {
            let mut position = start;
            let mut moves = Vec::new();
            for (line, (axes, rapid, feed_mm_s)) in steps.into_iter().enumerate() {
                for (i, a) in axes.iter().enumerate() {
                    if let Some(a) = a {
                        position[i] = *a;
                    }
                }
                moves.push(Move {
                    line: line + 1,
                    rapid,
                    target_mm: position,
                    feed_mm_s: (!rapid).then_some(feed_mm_s),
                });
            }
            (start, moves)
        })
    }

    fn limits_strategy() -> impl Strategy<Value = Limits> {
        let vel = 10.0..500.0f64;
        let acc = 50.0..5000.0f64;
        (
            [vel.clone(), vel.clone(), vel.clone()],
            [acc.clone(), acc.clone(), acc],
            vel,
        )
            .prop_map(|(vel, acc, feed)| Limits {
                max_vel_mm_s: Vector3::from(vel),
                max_acc_mm_s2: Vector3::from(acc),
                max_feed_mm_s: feed,
            })
    }

    proptest! {
        /// Whatever the requests and whenever they come, `k` stays in `[0, 2]`, `|k'| ≤ D` or
        /// the quiet rate of the cruise (by differences of `k` between samples, a `J·T²` of
        /// slack), each request moves `k`
        /// on the next sample unless it is already there (or, above 1, while the plan still
        /// accelerates), and the plan time never goes back.
        #[test]
        fn k_stays_within_0_and_2_and_its_rate_within_the_ramp(
            requests in proptest::collection::vec((1..120usize, 0.0..2.5f64, any::<bool>()), 1..20),
        ) {
            // 50 mm/s on a 100 mm/s machine: room for 200 % once the line cruises (0.05 s).
            let plan = plan_moves(Vector3::zeros(), &[feed(1, v(1.0e4, 0.0, 0.0), 50.0)], &limits()).unwrap();
            let ramp = OverrideRamp::new(2.0, 30.0).unwrap();
            let t = 0.002;
            // On the cruise a ramp may use the path acceleration the profile leaves unused there
            // ("Quiet ramps"), over four periods (no jerk limit).
            let quiet_d = plan.segments()[0].profile.unwrap().limits().a_max_mm_s2() / 50.0;
            let (d, j) = (quiet_d.max(2.0), (quiet_d / (4.0 * t)).max(30.0));
            let mut interp = Interpolator::new(plan, t).unwrap().with_override_ramp(ramp);
            let mut p = Vector3::zeros();
            let (mut k_prev, mut tau_prev) = (1.0, 0.0);
            for (gap, fraction, hold) in requests {
                if hold { interp.hold().unwrap() } else { interp.resume().unwrap() }
                interp.set_override(fraction).unwrap();
                let target = if hold { 0.0 } else { fraction.min(MAX_OVERRIDE) };
                for i in 0..gap {
                    let accelerating = interp.plan_time_s() < 0.06;
                    interp.update(&mut p);
                    let k = interp.effective_override();
                    prop_assert!((0.0..=MAX_OVERRIDE).contains(&k), "k = {}", k);
                    prop_assert!((k - k_prev).abs() <= d * t + j * t * t, "k from {} to {}", k_prev, k);
                    if i == 0 && k_prev != target && !(accelerating && target > 1.0 && k_prev >= 1.0) {
                        prop_assert_ne!(k, k_prev, "k did not move towards {}", target);
                    }
                    prop_assert!(interp.plan_time_s() >= tau_prev);
                    k_prev = k;
                    tau_prev = interp.plan_time_s();
                }
            }
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(128))]

        #[test]
        fn sampled_setpoints_hold_the_axis_limits(
            (start, moves) in moves_strategy(),
            limits in limits_strategy(),
            period_s in 0.0005..0.004f64,
        ) {
            let plan = plan_moves(start, &moves, &limits).unwrap();
            let final_mm = moves.last().unwrap().target_mm;
            let mut interp = Interpolator::new(plan, period_s).unwrap();
            // Two samples at rest before the start, so the first differences see the start.
            let mut prev2 = start;
            let mut prev = start;
            let mut p = Vector3::zeros();
            let mut finished_at = None;
            let mut k = 0u64;
            // A few samples past the end: holding still must not break the limits either.
            while finished_at.is_none_or(|f| k < f + 3) {
                k += 1;
                let status = interp.update(&mut p);
                prop_assert!(p.iter().all(|c| c.is_finite()), "NaN at sample {}", k);
                for i in 0..3 {
                    let vel = (p[i] - prev[i]).abs() / period_s;
                    let acc = (p[i] - 2.0 * prev[i] + prev2[i]).abs() / (period_s * period_s);
                    prop_assert!(
                        vel <= limits.max_vel_mm_s[i] * (1.0 + 1e-9) + 1e-6,
                        "axis {} velocity {} > {} at sample {}", i, vel, limits.max_vel_mm_s[i], k
                    );
                    prop_assert!(
                        acc <= limits.max_acc_mm_s2[i] * 1.01,
                        "axis {} acceleration {} > {} at sample {}", i, acc, limits.max_acc_mm_s2[i], k
                    );
                }
                if status == Status::Finished && finished_at.is_none() {
                    finished_at = Some(k);
                    prop_assert_eq!(k, interp.total_samples());
                }
                if finished_at.is_some() {
                    prop_assert_eq!(status, Status::Finished);
                    prop_assert_eq!(p, final_mm);
                }
                prev2 = prev;
                prev = p;
            }
        }
    }
}
