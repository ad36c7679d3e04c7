//! Motion planner: path elements into time-parameterised segments, with look-ahead.
//!
//! Third stage of the pipeline (`gcode → compensation → planner → interpolator`). Pure: no clock, no
//! I/O; the output is a stream of [`Segment`]s (or a whole [`Plan`]) whose only question
//! downstream is the position at a time (as in Klipper, the sampler knows nothing about G-code
//! or limits).
//!
//! Units in names: `_mm` millimetres, `_mm_s` mm/s, `_mm_s2` mm/s², `_mm_s3` mm/s³, `_s`
//! seconds.
//!
//! # Segments
//!
//! Each element (line, arc or helix, see [`crate::gcode::Element`]) becomes one [`Segment`]
//! along its path with a [`profile::SpeedProfile`] from its start speed to its end speed: a
//! trapezoid, a 7-phase S-curve or a jerk-continuous S-curve ([`ProfileKind`]); a dwell becomes
//! a segment of zero motion of its duration, a program stop (M0/M1) a segment of zero motion
//! and zero duration that marks where the run must wait. Both stop the motion.
//!
//! # Limits along an element
//!
//! For a move along the unit direction `u`, with `s` the share of each axis's acceleration
//! (and jerk) the profiles may use ([`PlannerConfig::path_acc_share`]; the rest is kept for
//! the velocity jumps at junctions),
//!
//! - speed: `v ≤ min(feed, max_feed, min_i max_vel_i / |u_i|)` (a rapid uses `max_feed`),
//! - acceleration: `a = min(path_acc, s · min_i max_acc_i / |u_i|)`,
//! - jerk (S-curves): `j = s · min_i max_jerk_i / |u_i|`,
//!
//! so every axis stays within its own limits (`|v_i| = v |u_i|`, and so on). On an arc of
//! radius `r` (plane normal `n`, helix angle `α`) the tangent `T` and the inward normal `N` are
//! orthogonal unit vectors, so the acceleration `a_t T + a_n N` has magnitude `√(a_t² + a_n²)`
//! and no axis sees more than that times its share of the plane spanned by `T` and `N` (1 for
//! an axis of the arc's plane, `sin α` for the helix axis). With `A` the smallest
//! `s · max_acc_i / share_i`, the path acceleration is `a_t = A/2` and the centripetal
//! acceleration is held to `a_n = v²/r ≤ A·√3/2` (LinuxCNC's 0.5 tangential ratio); or, on a
//! programmed arc where it is more, `a_t` is what every axis leaves of its share beside the
//! centripetal acceleration at the element's top speed, `a_t·|Tᵢ| + v²κ·|Nᵢ| ≤ s·Aᵢ` (a steep
//! helix moves its plane's axes by `cos α` of its path only), and its tangential jerk likewise
//! beside the curve's parts (`arc_limits`). The chord (bow-height) error of one period's
//! step is held within ε (`shared/seeds` 001, 003): `v ≤ 2·√(2rε − ε²)/T`. For S-curves the
//! jerk of circular motion, `(j_t − v³/r²) T + (3 v a_t / r) N`, is held within the jerk
//! budget `J` by `|j_t| ≤ J/2`, `v³/r² ≤ J/4` and `3 v a_t / r ≤ (√7/4)·J`: its two parts are
//! orthogonal, so its magnitude is at most `√((3J/4)² + (√7·J/4)²) = J` (a plain sum of the
//! three terms, `J/4` for the last, left a short arc under half the acceleration it may use).
//! In the jerk-limited mode a programmed arc long enough to run mostly at its cap may share
//! its budget otherwise (`ArcSplit`): `0.45·J` or `0.6·J` for the curve, `0.4·J` or `0.25·J`
//! tangential, the rest in quadrature for the normal part, whichever is estimated fastest
//! from and to half its cap (three turns of a 10 mm circle: 114 mm/s instead of 97.9). Under
//! the time-law filter a plane arc's plan may accelerate at more than the split gives: the
//! filtered time law has `a_t ≤ a` and `|j_t| ≤ 2·a/T_f`, and an axis of the plane at the
//! angle `φ` to the tangent sees `(j_t − v³κ²)·cos φ + 3·v·κ·a_t·sin φ`, at most its share of
//! the plane times `√((2·a/T_f + v³κ²)² + (3·v·κ·a)²)`; the largest `a` that keeps this within
//! `s·Jᵢ` (and `√(a² + (v²κ)²)` within `s·Aᵢ`) at the top speed is taken where it is more
//! (session 35; the split, a sum over the same parts, gave `J_t·T_f/2` = 375 mm/s² on a
//! 6.35 mm arc at 72 mm/s where this gives 485). A move alone, an exact S-curve without the
//! time-law filter, keeps the split's limits.
//!
//! # Junctions
//!
//! Under G61 (exact path) and G61.1 (exact stop) every junction is a stop. Otherwise the speed
//! `v` through a junction is continuous and the *velocity vector* turns there within one
//! period (`shared/seeds` 000): by eq. 5, `v·|u₂ − u₁| ≤ T·a_corner`, and, per axis, the jump
//! `v·|u₂ᵢ − u₁ᵢ|` taken in one period on top of the acceleration the neighbouring profiles use
//! must stay within the axis's limit: `v·|Δuᵢ| ≤ T·(max_accᵢ − usedᵢ)`. With S-curves the jump
//! also bounds the jerk of the setpoints: `v·|Δuᵢ| ≤ T²·(max_jerkᵢ − usedᵢ)/2`, and so does
//! the step of the centripetal acceleration where an arc begins or ends:
//! `v²·|Δ(N/r)ᵢ| ≤ T·(max_jerkᵢ − usedᵢ)/2`. Never grbl's junction deviation: it lets the
//! velocity jump by several times `a_max·T` in one period, a shock for a servo that follows
//! cyclic setpoints.
//!
//! Under G64 P (a tolerance), a corner between two lines, a line and a plane arc or two arcs
//! of one plane may instead be rounded by a tangent arc within the tolerance (`shared/seeds`
//! 001, `src/planner/blend.rs`), where that is faster than the sharp corner; helices and
//! elements not in one plane keep their corners. G64 without P, or P0, keeps the corner exact.
//!
//! # The jerk-limited mode (`profile = "s-curve"`)
//!
//! Planning jerk element by element (every element starting and ending at zero
//! acceleration, every polyline vertex charged against the jerk budget within one period)
//! made whole programs 2–14 times slower than their trapezoid plans. The `s-curve` mode
//! instead keeps the trapezoid look-ahead, which carries speed and acceleration through
//! junctions, and makes its output jerk-limited with filters the plan is made for
//! ([`Smoothing`], applied by [`crate::interpolator`]); FIR interpolation in the sense of Tajima &
//! Sencer and Biagiotti & Melchiorri, with the filter on the time law rather than on the axes
//! for the long part:
//!
//! - **Time law.** The path parameter `s(t)` (distance along the whole path) passes through a
//!   moving average of `T_f = min_i A_i/J_i`; the axes are `path(s_f(t))`, so this filter
//!   costs no contour error. Its output's acceleration is an average of the plan's, and its
//!   jerk is at most the range of the plan's acceleration over `T_f`, divided by `T_f`: a
//!   trapezoid whose tangential acceleration stays within `J_t·T_f/2` comes out with its
//!   tangential jerk within `J_t` (`J_t`: the element's jerk budget, as the S-curves had),
//!   even where it brakes right after accelerating. Elements joined at speed plan with the
//!   lower of their two accelerations, since the filter's window spans the junction; but only
//!   within the filter's reach of it: a line with the higher acceleration and long enough is
//!   split where the reach ends and keeps its own beyond (`Planner::share_at_junction`).
//! - **Whole acceleration in long speed changes.** `J·T_f/2` is needed only where the plan's
//!   acceleration may reverse within `T_f`. Each speed change of a line, arc or helix of a
//!   filtered run that lasts more than two zones of `T_f` (and two periods: the samples' jerk is
//!   a third difference) keeps `J·T_f/2` in a zone at either end and runs at the whole `J·T_f`
//!   (within its axes' share and the element's own rules) between: the element keeps the
//!   look-ahead's acceleration within `T_f` of its ends, where its neighbours' accelerations
//!   meet it in the filter, and either side of its peak, so the whole acceleration never
//!   meets one of the other sign within `T_f`. The look-ahead plans as before; settling splits
//!   such an element into parts where that is faster, its peak as high as the shorter speed
//!   changes allow (`Planner::split_for_acceleration`; LinuxCNC's `long-kink.ngc` 0.79 →
//!   0.66 s against 0.52 s in trapezoid mode; an arc's parts are arcs of its circle or
//!   helix). The lines of chord runs (their acceleration is their curve's) and moves of the
//!   auxiliary axes keep one profile.
//! - **Dips.** The filtered speed rounds every dip of the plan: through a V-shaped dip to `c`
//!   with the acceleration `A` on both sides it passes the dip's position at `c + A·T_f/4`. So a
//!   junction whose cap is below either neighbour's speed is planned `A·T_f/4` lower, and one
//!   where that leaves nothing becomes a stop (`Planner::junction_caps`).
//! - **Plateaus.** Where such stops would be dense (CAM chords whose rounding turns many
//!   vertices sharply), the filtered speed is bounded another way: it is the distance the plan
//!   covers in one filter time, over `T_f`, and that window contains the time the plan passes
//!   the junction. If the plan's speed stays within the cap `c` over `c·T_f` on either side, it
//!   cannot leave that stretch within `T_f`, so the filtered speed at the junction is at most
//!   `c`. The junction waits until the elements within reach are known; if they are all short
//!   (at most `c·T_f`), they are capped at `c` and the junction keeps its cap
//!   (`Planner::finalize_junction`). A plateau takes `2·T_f` at `c`; a stop there costs more
//!   (the plan comes down to rest and the filter settles), so every such junction among short
//!   elements gets one. An isolated sharp corner between longer elements still stops.
//! - **Kinked runs.** A line's time-law acceleration reaches each axis as the jerk
//!   `2·a/T_f·|uᵢ|` wherever it reverses (at every dip), and a vertex passed at speed keeps
//!   half of what its lines leave: with `a = J·T_f/2` an eighth of each axis's jerk, which
//!   holds the dips of a polygon whose vertices turn a little each (CAM chords too sparse to
//!   run as a curve) to a crawl. Such a line, joined at speed to the line before with a kink,
//!   plans with three quarters, half or 0.35 of its acceleration (and of that jerk) where an
//!   estimate of both lines' times says so: half leaves the vertex 2.5 times as much and
//!   makes its dip half as deep (`Planner::choose_kink_share`). The line before is lowered
//!   with it where the filter's window at the vertex stays within it, or where it starts
//!   from a stop (after a partial stand its use of the axes counts the deceleration before
//!   the stand); otherwise it keeps its acceleration and the vertex its use
//!   (LinuxCNC's `sam-circle_lines.ngc` 22.6 → 16.1 s).
//! - **Stops.** Where the plan stops after a filtered move, it stands still until the time-law
//!   filter has settled (`T_f`), so that the filtered time law reaches the stop exactly before
//!   anything else moves; before dwells, program stops and the program's end the axis filters
//!   settle too ([`Smoothing::settle_periods`] in all), so these are exact. Before the next
//!   move they settle only where their mix of the two legs could cut the corner beyond the
//!   tolerance, as after a move alone (below); an estimate that over-states the cut
//!   (`filtered_stop_behind_mm`). Each leg keeps its limits on its own and both are at rest
//!   with no acceleration where they meet, so the moving averages of their sum keep them too.
//!   Where the stop is a junction whose own cap `c > 0` the dip left nothing of, and the next
//!   move runs through the time-law filter too, the plan stands only `T_f − 2·√(c·T_f/A)`:
//!   the filter's output then passes the junction at `A·(T_f − h)²/(4·T_f) ≤ c` after a
//!   stand of `h` (the V-shaped dip with its bottom held), within the junction's rules
//!   (`Planner::partial_hold_periods`); a move alone after it, a dwell, a program stop or the
//!   end wait for the rest.
//! - **Moves alone.** A move from rest to rest (a sharp corner before and after it) is planned
//!   as an exact, time-optimal S-curve of its own and bypasses the time-law filter, which would
//!   cost it `T_f` of standing still; the filter is switched only at rest. Where it starts with
//!   every filter settled (`Planner::filters_quiet_s`: the plan's start, a stand that waited
//!   for them, another such move), it bypasses the axis filters too
//!   ([`Segment::axis_filters`]): the exact profile keeps every axis's limits and the path on
//!   its own, and nothing of it is left in the filters, so the next move needs no settling
//!   time (consecutive moves alone under a tiny tolerance waited `2·(T_k − T)` at each corner
//!   for the filters, whose mix of the two legs would have cut it). The settling time counts
//!   one period more than the filters' own, since the first sample standing at a move's end
//!   may come up to a period after it. Moves of the auxiliary axes keep them. A move alone
//!   passes no junction, so it takes more of each axis than `path_acc_share`: as much as
//!   leaves the feed override's ramp its terms (`D·v` of acceleration, `3·D·a + J·v` of
//!   jerk) at each phase of its profile (`Planner::alone_at_axes`; a 1 mm line 6.6 % sooner
//!   on the demo machine). Where the filters switch on again, they start settled at the
//!   point the run that needs them begins, exactly (`Interpolator::run_start`).
//! - **Geometry.** Each axis then passes through two moving averages of `T_k`
//!   ([`AXIS_FILTER_S`]), which spread the velocity step of a polyline's vertex over `2·T_k`:
//!   a vertex's step `Δv` reaches the drive as an acceleration of at most `Δv/T_k` and a jerk
//!   of at most `Δv/T_k²`, so the junction rules use `T_k` where the trapezoid mode uses the
//!   period (`Planner::smoothed_junction_limit_mm_s`). Their price is contour error,
//!   `v·|Δu|·2·T_k/8` at a corner and `2·v²·T_k²/(24·r)` on an arc, which the junction and arc
//!   speeds keep within the tolerance: half the G64 P tolerance (the corner blends take the
//!   other half), else `chord_tol_mm`. A step `Δa` of the acceleration (where an arc begins
//!   or ends) reaches the drive as a jerk of at most `Δa/T_k` for `2·T_k`; the rules of one
//!   junction share the jerk budget its elements leave in halves, since steps of neighbouring
//!   junctions may meet in the filters' output, except where a step is alone: between two
//!   elements each at least `2·T_k` long at its top speed (whatever blends may still take of
//!   them), or long enough that the plan, passing the junction at most at `v` and
//!   accelerating at most at four times its acceleration (a feed override up to 200 %),
//!   needs `2·T_k` to cross them (`L ≥ 2·T_k·v + 8·a·T_k²`, for `v` up to there), a turn of
//!   the tangent between two lines, or a curvature step at a tangent junction, meets no
//!   other and takes all of it. What a programmed arc leaves a curvature step or a turn at
//!   its end is taken at the junction's speed: its jerk along an axis,
//!   `(2·a_t/T_f + v³κ²)·|Tᵢ| + 3·v·κ·a_t·|Nᵢ|` (and a helix's `v³κτ·|Bᵢ|`), is its whole
//!   budget only at its cap
//!   (`Planner::cap_at_speed`; a line into a 6.35 mm arc, `sam-tail-slowdown.ngc`:
//!   17 → 36 mm/s; arcs of CAM output meeting at kinks of about 1°, `spreadsheeterrors.ngc`:
//!   20–50 → 50–130 mm/s). Blend arcs, and every junction while a corner's blend is chosen,
//!   keep the use at the cap that the blend's estimate was made for (the sharp corner it is
//!   compared with is taken at speed, as it would run).
//! - **Curvature.** On arcs and helices the jerk of following the curve, `v³κ²`, is capped as
//!   with S-curves; on chord polylines the discrete curvature `|Δu|/L` is capped the same way.
//! - **Chord smoothing.** Before any of this, a dense run of G64 lines (chords of 0.1 mm at
//!   most, no corner) has its vertices moved onto the smooth curve it approximates: each
//!   across the run to the centre of the least-squares parabola through up to 16 neighbours
//!   either side, where the run is rough, as far as it then stays within a quarter of the
//!   tolerance of the programmed one, by a bound computed per chord; each line goes on with
//!   the tolerance less what its chord and the next one spent. The rounding of CAM output to
//!   4 decimals makes every vertex a kink of ±0.16 rad on 16 µm chords (`contour.ngc`);
//!   smoothed, the run turns by its curve's few milliradians per vertex and runs at its
//!   curvature's speed instead of a crawl (`src/planner/smooth.rs`).
//! - **Chord fairing.** Then the inner vertices of a run of G64 lines between 0.02 and 2 mm
//!   that turn by at most 0.35 rad each, beside a chord longer than 0.1 mm (shorter runs are
//!   the smoother's), are moved, within a quarter of the tolerance (and of the shorter chord
//!   beside), where the curvature zig-zags from vertex to vertex, until
//!   each vertex's curvature is about the mean of its neighbours' (a discrete smoothing
//!   spline with the tolerance as its obstacle; `src/planner/fair.rs`). CAM output of a 3D
//!   surface is such a polyline, every vertex within the CAM's chordal tolerance of the
//!   surface's smooth section, and any curve through its vertices bends back and forth at
//!   each: `3D_Chips.ngc` ran at 5–12 mm/s where the trapezoid plan runs at 20–48 (session
//!   33: 156.1 → 117.6 s, `LHchips4.ngc` 547.7 → 486.4 s, no corpus program slower). A
//!   clean polyline (a circle's, any evenly sampled smooth curve's) stays as it is, and so do
//!   the run's first and last chords and the vertices that shape the curve of a chord the
//!   refiner would cut as programmed but not as faired; each line goes on with the tolerance
//!   less what its chord and the next one spent.
//! - **Chord refinement.** Then each chord of a run of G64 lines between 0.1 and 2 mm whose
//!   vertices turn by more than the axis filters take at the curve's speed (a vertex's step
//!   `v·|Δu|` leaves up to `v·|Δu|/T_k²` of jerk, however dense the chords) is replaced by
//!   shorter chords on a curve through the run's vertices, the quintic Hermite curve with the
//!   tangent and curvature of the circle through each vertex and its neighbours at either
//!   end, curvature-continuous at the programmed vertices, within a quarter of the tolerance
//!   (`src/planner/refine.rs`). The pieces' vertices are computed, so the vertex rules'
//!   allowance for the rounding of written coordinates does not apply to them; and no blend
//!   arc goes between two pieces, whose curve the run already follows (an arc would step
//!   the curvature at both of its ends).
//! - **Collinear lines.** After the smoother, the fairer and the refiner, G64 lines that
//!   continue one another exactly along one straight line (the vertex within a nanometre of
//!   the merged line, same feed, mode, compensation and plane, the auxiliary axes still)
//!   become one line
//!   where the run is at least as long as the axis filters' span at the max feed `2·T_k·F`
//!   (`src/planner/merge.rs`; shorter, it may be a few written vertices of a curve that line up): a
//!   straight move written as many short lines is then a move alone, an exact S-curve,
//!   instead of a run of trapezoids at the time-law filter's `J·T_f/2`
//!   (`straight_short_lines_X.ngc`: 0.422 s → 0.318 s, against 0.261 s in trapezoid mode).
//! - **Chord runs as curves.** Where a run of lines is dense (two chords at least within the
//!   axis filters' reach) and turns little at each vertex, its lines take the curve from
//!   their own budget as an arc does, with the run's curvature estimated over a window of
//!   chords that averages the rounding's noise away; the vertices are then charged only what
//!   they turn beyond the curve, and each line's cap holds over the time-law filter's reach
//!   on either side instead of a dip at every vertex (`src/planner/curve.rs`). A steady curve may use most
//!   of each axis's acceleration and jerk (the centripetal part and the jerk of following
//!   it, the rate of its curvature's change included); where the speed changes, each line
//!   plans with the tangential acceleration the curve leaves at the faster end of its speed
//!   change, in both passes: a time-optimal parameterisation at chord resolution, whose
//!   acceleration bound falls with the speed, in place of one split of the budget held at
//!   every speed.
//!
//! # Auxiliary axes
//!
//! A B C (degrees) and U V W ride along each element linearly in its path parameter; a move
//! without X/Y/Z motion takes their length (U/V/W, else A/B/C) as its path. Their limits cap
//! the element's speed, acceleration and jerk, their velocity steps cap the junctions, and
//! corners where they move stay unblended: [`aux_axes`].
//!
//! # Look-ahead
//!
//! [`Planner`] keeps a window of up to [`PlannerConfig::lookahead`] elements. When it is full
//! (or the program ends, or a dwell or stop comes), a backward pass computes the highest speed
//! at each junction from which the rest of the window can still stop at its end (so a stop is
//! always possible), with the reachability of the profile actually used
//! ([`profile::max_start_speed`], 003's path-length constraint for S-curves); a forward pass
//! then limits each end speed to what the element can reach from its start
//! ([`profile::max_end_speed`]). An element is settled once its end speed can no longer change:
//! the forward pass binds it, or its backward bound comes from a junction's own limit, at its
//! end or at any junction further on that the backward pass reached (more elements can only
//! raise the bound from the window's end, never beyond such a limit). Settled elements leave
//! the window as segments and are never planned again, so the work per element is bounded; if
//! too few are settled (a ramp longer than the window), the first quarter of the window is
//! settled with the speeds it has, which are always safe. Where the forward pass stops short
//! of the window's end, the last `lookahead / 8` of the elements it would settle stay in the
//! window too (a reserve): the elements left otherwise brake just enough for a stop at its end
//! from the settled speed, and the next vertex of a chord run taken as a curve, whose curve
//! lowers the accelerations within its reach (`curve.rs`), could not be planned from there.

use std::collections::VecDeque;

use nalgebra::Vector3;
use serde::Deserialize;

use crate::gcode::{ArcGeometry, AuxMove, AuxPos, BlendMode, Element, ElementKind, Item, Program};
pub mod aux_axes;
mod blend;
pub mod bounds;
mod curve;
mod fair;
mod merge;
pub mod profile;
mod refine;
mod smooth;
mod window;

pub use aux_axes::AuxLimits;

use blend::Blend;
use profile::{JerkShape, ProfileLimits, SpeedProfile};

/// Largest value accepted for any machine limit; keeps squares and products of limits and
/// lengths finite.
pub const MAX_LIMIT: f64 = 1.0e9;

/// Machine limits per axis (X, Y, Z) and for the path.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    /// Maximum speed of each axis.
    pub max_vel_mm_s: Vector3<f64>,
    /// Maximum acceleration (and deceleration) of each axis.
    pub max_acc_mm_s2: Vector3<f64>,
    /// Maximum path feed; programmed feeds above it are clamped, rapids run at it.
    pub max_feed_mm_s: f64,
}

impl Limits {
    /// Checks that every limit is finite, positive and at most [`MAX_LIMIT`].
    pub fn validate(&self) -> Result<(), PlanError> {
        const VEL: [&str; 3] = ["max_vel_mm_s.x", "max_vel_mm_s.y", "max_vel_mm_s.z"];
        const ACC: [&str; 3] = ["max_acc_mm_s2.x", "max_acc_mm_s2.y", "max_acc_mm_s2.z"];
        let named = (0..3)
            .map(|i| (VEL[i], self.max_vel_mm_s[i]))
            .chain((0..3).map(|i| (ACC[i], self.max_acc_mm_s2[i])))
            .chain(std::iter::once(("max_feed_mm_s", self.max_feed_mm_s)));
        for (name, value) in named {
            if !(value > 0.0 && value <= MAX_LIMIT) {
                return Err(PlanError::InvalidLimit { name, value });
            }
        }
        Ok(())
    }
}

/// The speed profile the look-ahead plans every element with.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ProfileKind {
    /// Constant acceleration phases (infinite jerk).
    #[default]
    Trapezoid,
    /// 7-phase jerk-limited S-curve (square jerk pulses).
    SCurve,
    /// Jerk-continuous S-curve (raised-cosine jerk pulses, 001 problem 4).
    Smooth,
}

/// Time of each of the two moving averages per axis of the jerk-limited mode (the geometry
/// filter, see the module documentation) by default, rounded up to whole periods (at least
/// 2); [`PlannerConfig::axis_filter_s`].
pub const AXIS_FILTER_S: f64 = 0.008;

/// The range of [`PlannerConfig::axis_filter_s`]. Below: the chord runs keep `curve`'s
/// share of each axis's jerk for their vertices' rounding, which reaches the jerk through the
/// axis filters as `v·Δu/T_k²`, sized at 8 ms: it holds for longer filters (less), not
/// shorter. Above: the corners' and curvature steps' contour rules take each junction alone,
/// and from about 20 ms the filters' span reaches several corners of a kinked polyline whose
/// cuts add up (`tests/planner_limits.rs` found 0.7 % over the tolerance at 32 ms and 2 % at
/// 24 ms; none in 3000 random cases at 10, 12 and 16 ms).
pub const AXIS_FILTER_RANGE_S: std::ops::RangeInclusive<f64> = 0.008..=0.016;

/// Share of an arc's pull towards its centre (`v²·κ·σ²/2`) that the axis filters still take
/// where the curvature steps by `Δκ` at speed, with the interpolator's contour
/// pre-compensation (`crate::interpolator::smooth`): 0.28 measured for a tangent line into an
/// arc at filter lengths of 8 to 24 periods, so `0.3·v²·|Δκ|·T_k²/12` is held within the
/// tolerance.
pub const PRECOMP_STEP_RESIDUAL: f64 = 0.3;

/// Factor on the jerk of a curvature step through the axis filters that their pre-compensation
/// adds (measured 1.013 at most against `v²·|Δκ|/T_k`, in the same cases).
pub const PRECOMP_JERK: f64 = 1.05;

/// Largest turn `|Δu|` of the tangent at a junction whose curvature step may take the whole
/// jerk budget its elements leave (`Planner::smoothed_junction_limit_mm_s`): a tangent junction
/// as G-code writes it, within the rounding of its arcs' centres. The velocity step of such a
/// turn, `v·|Δuᵢ|/T_k²` of jerk at most, is charged against that budget too.
const ISOLATED_TURN: f64 = 1.0e-6;

/// Default of [`PlannerConfig::default_tolerance_mm`]: 0.01 mm, the deviation a bare `G64`
/// allows in the jerk-limited mode (and the mode a program starts in, as in LinuxCNC).
pub const DEFAULT_TOLERANCE_MM: f64 = 0.01;

/// Longest time-law filter: past it the tangential acceleration is lowered instead
/// (`a ≤ J·T_f/2`).
pub const MAX_TIME_LAW_FILTER_S: f64 = 1.0;

/// The filters of the jerk-limited mode ([`ProfileKind::SCurve`]), which the planner plans
/// for and the interpolator applies (see the module documentation): a moving average of the
/// path parameter over `time_law_periods` periods, then two moving averages of each axis over
/// `axis_periods` periods each.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Smoothing {
    /// Periods of the moving average of the path parameter `s(t)` (at least 1).
    pub time_law_periods: usize,
    /// Periods of each of the two moving averages of each axis (at least 1).
    pub axis_periods: usize,
}

impl Smoothing {
    /// The filters for `limits` and `cfg`: `None` unless the profile is
    /// [`ProfileKind::SCurve`]. The time-law filter lasts `T_f = min_i A_i/J_i` (the time a
    /// jerk-limited axis takes to build up its acceleration; at most
    /// [`MAX_TIME_LAW_FILTER_S`]), rounded up to whole periods. A plan whose tangential
    /// acceleration stays within `J·T_f/2` then comes out with its jerk within `J`, even where
    /// the acceleration reverses within one filter time.
    pub fn for_machine(limits: &Limits, cfg: &PlannerConfig) -> Option<Smoothing> {
        if cfg.profile != ProfileKind::SCurve {
            return None;
        }
        let mut t_f = MAX_TIME_LAW_FILTER_S;
        for i in 0..3 {
            let j = cfg.max_jerk_mm_s3[i];
            if j.is_finite() && j > 0.0 {
                t_f = t_f.min(limits.max_acc_mm_s2[i] / j);
            }
        }
        let periods =
            |t: f64, at_least: f64| (t / cfg.period_s - 1e-9).ceil().max(at_least) as usize;
        Some(Smoothing {
            time_law_periods: periods(t_f, 1.0),
            axis_periods: periods(cfg.axis_filter_s, 2.0),
        })
    }

    /// The time-law filter's length `T_f`.
    pub fn time_law_s(&self, period_s: f64) -> f64 {
        self.time_law_periods as f64 * period_s
    }

    /// The length `T_k` of each of the axis filters.
    pub fn axis_s(&self, period_s: f64) -> f64 {
        self.axis_periods as f64 * period_s
    }

    /// Samples after its input stops until the output stands exactly where the input does.
    pub fn settle_periods(&self) -> usize {
        (self.time_law_periods - 1) + 2 * (self.axis_periods - 1)
    }
}

/// How the look-ahead joins elements and shapes their speed (the machine's `[planner]` table).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlannerConfig {
    /// The interpolation (SYNC) period `T`.
    pub period_s: f64,
    /// `a_corner` of 000's eq. 5: the largest velocity change a junction may take in one period,
    /// divided by the period. 0: exact stop at every junction.
    pub corner_acc_mm_s2: f64,
    /// Share (0, 1] of each axis's acceleration and jerk the profiles may use; the rest is the
    /// budget of the junctions' velocity jumps.
    pub path_acc_share: f64,
    /// Cap on the path (tangential) acceleration; `f64::INFINITY` for none.
    pub path_acc_mm_s2: f64,
    /// Jerk limit of each axis (used by the S-curve profiles).
    pub max_jerk_mm_s3: Vector3<f64>,
    /// The profile.
    pub profile: ProfileKind,
    /// Largest chord (bow-height) error of one period's step on an arc; 0 for no limit.
    pub chord_tol_mm: f64,
    /// The tolerance of a bare `G64` (no P; LinuxCNC's "no limit") in the jerk-limited mode:
    /// its blends and axis filters stay within it. The trapezoid mode keeps such corners exact
    /// for now.
    pub default_tolerance_mm: f64,
    /// Elements in the look-ahead window (at least 2).
    pub lookahead: usize,
    /// 000's option: every moving element lasts a whole number of periods, its end point on a
    /// sample, by lowering its cruise speed (never a boundary speed or a limit).
    pub integer_periods: bool,
    /// Limits of the auxiliary axes A B C U V W ([`aux_axes`]).
    pub aux: AuxLimits,
    /// Time `T_k` of each of the two moving averages per axis of the jerk-limited mode (the
    /// geometry filter), within [`AXIS_FILTER_RANGE_S`]; [`AXIS_FILTER_S`] by default. Longer
    /// filters pass a polyline's vertices at a higher speed for the jerk (`v·Δu/T_k²`) and cut
    /// corners and curvature steps by more (`v·|Δu|·T_k/4`, `v²·|Δκ|·T_k²/12`), which the
    /// tolerance then holds to a lower speed.
    pub axis_filter_s: f64,
}

impl PlannerConfig {
    /// Trapezoids from rest to rest: a stop at every junction, the whole acceleration of each
    /// axis for the profiles.
    pub fn exact_stop() -> PlannerConfig {
        PlannerConfig {
            period_s: 0.004,
            corner_acc_mm_s2: 0.0,
            path_acc_share: 1.0,
            path_acc_mm_s2: f64::INFINITY,
            max_jerk_mm_s3: Vector3::repeat(f64::INFINITY),
            profile: ProfileKind::Trapezoid,
            chord_tol_mm: 0.0,
            default_tolerance_mm: DEFAULT_TOLERANCE_MM,
            lookahead: 1000,
            integer_periods: false,
            aux: AuxLimits::NONE,
            axis_filter_s: AXIS_FILTER_S,
        }
    }

    /// Checks every value's range.
    pub fn validate(&self) -> Result<(), PlanError> {
        let checks: [(&'static str, f64, bool); 6] = [
            (
                "period_s",
                self.period_s,
                self.period_s > 0.0 && self.period_s <= 1.0,
            ),
            (
                "corner_acc_mm_s2",
                self.corner_acc_mm_s2,
                (0.0..=MAX_LIMIT).contains(&self.corner_acc_mm_s2),
            ),
            (
                "path_acc_share",
                self.path_acc_share,
                self.path_acc_share > 0.0 && self.path_acc_share <= 1.0,
            ),
            (
                "path_acc_mm_s2",
                self.path_acc_mm_s2,
                self.path_acc_mm_s2 > 0.0 && self.path_acc_mm_s2 <= f64::INFINITY,
            ),
            (
                "chord_tol_mm",
                self.chord_tol_mm,
                (0.0..=1.0e3).contains(&self.chord_tol_mm),
            ),
            (
                "default_tolerance_mm",
                self.default_tolerance_mm,
                self.default_tolerance_mm > 0.0 && self.default_tolerance_mm <= 1.0e3,
            ),
        ];
        for (name, value, ok) in checks {
            if !ok {
                return Err(PlanError::InvalidLimit { name, value });
            }
        }
        if !AXIS_FILTER_RANGE_S.contains(&self.axis_filter_s) {
            return Err(PlanError::InvalidAxisFilter {
                value_s: self.axis_filter_s,
            });
        }
        if self.profile != ProfileKind::Trapezoid {
            const JERK: [&str; 3] = ["max_jerk_mm_s3.x", "max_jerk_mm_s3.y", "max_jerk_mm_s3.z"];
            for (i, name) in JERK.iter().enumerate() {
                let j = self.max_jerk_mm_s3[i];
                if !(j > 0.0 && j <= MAX_LIMIT) {
                    return Err(PlanError::InvalidLimit { name, value: j });
                }
            }
        }
        if self.lookahead < 2 {
            return Err(PlanError::InvalidLimit {
                name: "lookahead",
                value: self.lookahead as f64,
            });
        }
        self.aux.validate()
    }

    fn jerk_limited(&self) -> bool {
        self.profile != ProfileKind::Trapezoid
    }
}

#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum PlanError {
    /// The axis filters' time is outside [`AXIS_FILTER_RANGE_S`].
    #[error(
        "axis_filter_s = {value_s} s must be in {lo}..={hi} s, the filters the planner's vertex and corner rules are made for",
        lo = AXIS_FILTER_RANGE_S.start(),
        hi = AXIS_FILTER_RANGE_S.end()
    )]
    InvalidAxisFilter {
        /// The time asked for.
        value_s: f64,
    },
    /// A machine limit is not finite, not positive, or above [`MAX_LIMIT`].
    #[error("machine limit {name} = {value} must be greater than 0 and at most 1e9")]
    InvalidLimit {
        /// Field name, e.g. `max_acc_mm_s2.y`.
        name: &'static str,
        /// The offending value.
        value: f64,
    },
    /// The start position has a NaN or infinite coordinate.
    #[error("start position is not finite")]
    NonFiniteStart,
    /// A move target has a NaN or infinite coordinate.
    #[error("line {line}: move target is not finite")]
    NonFiniteTarget {
        /// 1-based source line.
        line: usize,
    },
    /// A feed move with a feed that is missing, not finite or not positive.
    #[error("line {line}: feed {feed_mm_s:?} mm/s must be finite and greater than zero")]
    InvalidFeed {
        /// 1-based source line.
        line: usize,
        /// The feed (`None` for a G1 move without feed).
        feed_mm_s: Option<f64>,
    },
    /// An element does not start where the previous one ended.
    #[error("line {line}: element does not start where the previous one ended")]
    Discontinuity {
        /// 1-based source line.
        line: usize,
    },
    /// An arc whose geometry is degenerate (zero radius, zero normal).
    #[error("line {line}: degenerate arc (zero radius or no plane)")]
    InvalidArc {
        /// 1-based source line.
        line: usize,
    },
    /// A dwell that is negative or not finite.
    #[error("line {line}: dwell {seconds} s must be finite and at least zero")]
    InvalidDwell {
        /// 1-based source line.
        line: usize,
        /// The dwell.
        seconds: f64,
    },
    /// No speed profile joins the speeds the passes chose (a planner defect: reported rather
    /// than run).
    #[error(
        "line {line}: no speed profile from {v_start_mm_s} to {v_end_mm_s} mm/s over the element (planner defect)"
    )]
    NoProfile {
        /// 1-based source line.
        line: usize,
        /// Start speed.
        v_start_mm_s: f64,
        /// End speed.
        v_end_mm_s: f64,
    },
    /// The move is so long or so slow that its length or duration overflows.
    #[error("line {line}: move length or duration is not finite (move too long or feed too low)")]
    Overflow {
        /// 1-based source line.
        line: usize,
    },
}

/// What a segment follows.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SegmentPath {
    /// A straight line.
    Line {
        /// Unit vector from start to end.
        direction: Vector3<f64>,
    },
    /// An arc or a helix; the position at distance `d` is `point_at(d / length_mm)`.
    Arc(ArcGeometry),
    /// G4: no motion for the segment's duration.
    Dwell,
    /// M0 / M1: no motion, no duration; the run waits here for the operator.
    Stop {
        /// M1 rather than M0.
        optional: bool,
    },
}

/// One element with its speed profile. Times are relative to the segment start;
/// [`Segment::start_time_s`] places it in the plan.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Segment {
    /// 1-based source line of the move.
    pub line: usize,
    /// Whether the move is a rapid (G0).
    pub rapid: bool,
    /// Where the segment starts (the previous segment's `end_mm`, bit for bit).
    pub start_mm: Vector3<f64>,
    /// Where it ends (the element's end, bit for bit).
    pub end_mm: Vector3<f64>,
    /// The auxiliary axes (A B C U V W), linear in the distance along the path. Dwells and
    /// stops hold them where the motion before left them (at 0 before any motion).
    pub aux: AuxMove,
    /// The path followed.
    pub path: SegmentPath,
    /// Path length along `path` (> 0 for lines and arcs, 0 for dwells and stops).
    pub length_mm: f64,
    /// Path speed at the start.
    pub v_start_mm_s: f64,
    /// Highest path speed reached (the cruise speed of the profile).
    pub v_peak_mm_s: f64,
    /// Path speed at the end.
    pub v_end_mm_s: f64,
    /// Highest path speed the machine allows on this element whatever the programmed feed
    /// (max feed, each axis's speed, and on arcs the centripetal, chord and jerk limits): the
    /// ceiling of a feed override above 100 % ([`crate::interpolator`]). 0 for dwells and stops.
    pub v_limit_mm_s: f64,
    /// Highest path speed the machine allows through the junction at the start, whatever the
    /// programmed feeds (0 where the motion stops there).
    pub v_start_limit_mm_s: f64,
    /// The speed profile along the path (`None` for dwells and stops).
    pub profile: Option<SpeedProfile>,
    /// Duration of a dwell or stop (0 for moves: their profile has the duration).
    pub hold_s: f64,
    /// Time in the plan at which the segment starts.
    pub start_time_s: f64,
    /// Whether the interpolator passes its path parameter through the time-law filter
    /// ([`Smoothing`]); false for moves planned as exact jerk-limited profiles on their own, and
    /// for every move of a plan without smoothing. Stills keep whatever came before.
    pub time_law: bool,
    /// Whether the interpolator passes its points through the axis filters (and their
    /// contour pre-compensation, [`Smoothing`]); false for a move planned alone that starts
    /// where every filter has settled (its exact profile needs none, and it then leaves
    /// nothing in them to settle), and for every move of a plan without smoothing. Stills
    /// keep whatever came before.
    pub axis_filters: bool,
}

impl Segment {
    /// Total duration of the segment.
    pub fn duration_s(&self) -> f64 {
        self.profile.map_or(self.hold_s, |p| p.duration_s())
    }

    /// Time in the plan at which the segment ends.
    pub fn end_time_s(&self) -> f64 {
        self.start_time_s + self.duration_s()
    }

    /// Distance travelled along the path at `t_s` after the segment start, clamped to
    /// `[0, length_mm]`.
    pub fn distance_at(&self, t_s: f64) -> f64 {
        match &self.profile {
            Some(p) if t_s > 0.0 => p.at(t_s).s_mm.clamp(0.0, self.length_mm),
            _ => 0.0,
        }
    }

    /// Path speed at `t_s` after the segment start.
    pub fn speed_at(&self, t_s: f64) -> f64 {
        match &self.profile {
            Some(p) if t_s.is_nan() || t_s <= 0.0 => p.v_start_mm_s(),
            Some(p) => p.at(t_s).v_mm_s,
            None => 0.0,
        }
    }

    /// Position at `t_s` after the segment start. Exactly `start_mm` at `t_s <= 0` and exactly
    /// `end_mm` at `t_s >= duration_s()`. On a line the second half is measured back from the
    /// end, so the approach to `end_mm` is as precise as the departure from `start_mm`, and an
    /// axis that does not move keeps its coordinate bit for bit. On an arc the point is on the
    /// circle (helix) at the distance travelled.
    pub fn position_at(&self, t_s: f64) -> Vector3<f64> {
        if t_s.is_nan() || t_s <= 0.0 {
            return self.start_mm;
        }
        if t_s >= self.duration_s() {
            return self.end_mm;
        }
        self.point_at_distance(self.distance_at(t_s))
    }

    /// The point at `d_mm` along the path from the start: exactly `start_mm` at `d_mm <= 0`
    /// and exactly `end_mm` at `d_mm >= length_mm`; on a line the second half is measured back
    /// from the end (see [`position_at`](Self::position_at)).
    pub fn point_at_distance(&self, d_mm: f64) -> Vector3<f64> {
        if d_mm.is_nan() || d_mm <= 0.0 {
            return self.start_mm;
        }
        if d_mm >= self.length_mm {
            return self.end_mm;
        }
        let d = d_mm;
        match &self.path {
            SegmentPath::Line { direction } => {
                if d <= 0.5 * self.length_mm {
                    self.start_mm + direction * d
                } else {
                    self.end_mm - direction * (self.length_mm - d)
                }
            }
            SegmentPath::Arc(arc) => arc.point_at(d / self.length_mm),
            SegmentPath::Dwell | SegmentPath::Stop { .. } => self.start_mm,
        }
    }

    /// The auxiliary axes' positions at `t_s` after the segment start: exactly `aux.start` at
    /// `t_s <= 0` and exactly `aux.end` at the end.
    pub fn aux_at(&self, t_s: f64) -> AuxPos {
        if t_s.is_nan() || t_s <= 0.0 {
            return self.aux.start;
        }
        if t_s >= self.duration_s() {
            return self.aux.end;
        }
        self.aux_at_distance(self.distance_at(t_s))
    }

    /// The auxiliary axes' positions at `d_mm` along the path (see [`AuxMove::at`]).
    pub fn aux_at_distance(&self, d_mm: f64) -> AuxPos {
        if self.length_mm > 0.0 {
            self.aux.at(d_mm / self.length_mm)
        } else {
            self.aux.end
        }
    }

    /// The unit direction of a straight segment (`None` for arcs, dwells and stops).
    pub fn direction(&self) -> Option<Vector3<f64>> {
        match self.path {
            SegmentPath::Line { direction } => Some(direction),
            _ => None,
        }
    }
}

/// Reference trapezoid of the first planner, kept to check [`profile`] against.
#[cfg(test)]
#[derive(Debug, Clone, Copy, PartialEq)]
struct Profile {
    v_peak_mm_s: f64,
    t_acc_s: f64,
    t_cruise_s: f64,
    t_dec_s: f64,
}

/// Trapezoid (or triangle) over `length_mm` from `v_start` to `v_end` with speed cap `v_max` and
/// acceleration `accel`. `None` if the end speed cannot be reached within the length or an input
/// is out of its domain.
#[cfg(test)]
fn trapezoid(
    length_mm: f64,
    v_start_mm_s: f64,
    v_end_mm_s: f64,
    v_max_mm_s: f64,
    accel_mm_s2: f64,
) -> Option<Profile> {
    let (l, v0, v1, vmax, a) = (length_mm, v_start_mm_s, v_end_mm_s, v_max_mm_s, accel_mm_s2);
    let domain_ok = l > 0.0
        && l.is_finite()
        && a > 0.0
        && a.is_finite()
        && vmax > 0.0
        && vmax.is_finite()
        && (0.0..=vmax).contains(&v0)
        && (0.0..=vmax).contains(&v1);
    if !domain_ok || (v1 * v1 - v0 * v0).abs() > 2.0 * a * l * (1.0 + 1e-12) {
        return None;
    }
    let v_apex_sq = a * l + 0.5 * (v0 * v0 + v1 * v1);
    let profile = if v_apex_sq <= vmax * vmax {
        let vp = v_apex_sq.sqrt().max(v0).max(v1);
        Profile {
            v_peak_mm_s: vp,
            t_acc_s: (vp - v0) / a,
            t_cruise_s: 0.0,
            t_dec_s: (vp - v1) / a,
        }
    } else {
        let d_acc = (vmax * vmax - v0 * v0) / (2.0 * a);
        let d_dec = (vmax * vmax - v1 * v1) / (2.0 * a);
        Profile {
            v_peak_mm_s: vmax,
            t_acc_s: (vmax - v0) / a,
            t_cruise_s: ((l - d_acc - d_dec) / vmax).max(0.0),
            t_dec_s: (vmax - v1) / a,
        }
    };
    let total_s = profile.t_acc_s + profile.t_cruise_s + profile.t_dec_s;
    total_s.is_finite().then_some(profile)
}

/// A time-parameterised path: segments back to back, starting at time 0.
#[derive(Debug, Clone, PartialEq)]
pub struct Plan {
    start_mm: Vector3<f64>,
    segments: Vec<Segment>,
    duration_s: f64,
    smoothing: Option<Smoothing>,
}

impl Plan {
    /// A plan with no motion that stays at `start_mm`.
    pub fn at_rest(start_mm: Vector3<f64>) -> Plan {
        Plan {
            start_mm,
            segments: Vec::new(),
            duration_s: 0.0,
            smoothing: None,
        }
    }

    /// The filters the plan was made for (the jerk-limited mode's), which the interpolator
    /// applies to its samples; `None` for a plan whose profiles are sampled as they are.
    pub fn smoothing(&self) -> Option<Smoothing> {
        self.smoothing
    }

    /// The segments in time order.
    pub fn segments(&self) -> &[Segment] {
        &self.segments
    }

    /// Total duration.
    pub fn duration_s(&self) -> f64 {
        self.duration_s
    }

    /// Where the plan starts.
    pub fn start_mm(&self) -> Vector3<f64> {
        self.start_mm
    }

    /// Where the plan ends: the last segment's `end_mm` (the start if there is no segment).
    pub fn end_mm(&self) -> Vector3<f64> {
        self.segments.last().map_or(self.start_mm, |s| s.end_mm)
    }

    /// Index of the segment running at `t_s` (the first at `t_s <= 0`, the last at or after the
    /// end); `None` for a plan without segments.
    pub fn segment_index_at(&self, t_s: f64) -> Option<usize> {
        if self.segments.is_empty() {
            return None;
        }
        let after = self.segments.partition_point(|s| s.start_time_s <= t_s);
        Some(after.saturating_sub(1))
    }

    /// Position at `t_s` (exact, analytic). `start_mm` before 0 (and for NaN), exactly
    /// `end_mm()` from `duration_s()` on.
    pub fn position_at(&self, t_s: f64) -> Vector3<f64> {
        if t_s.is_nan() || t_s <= 0.0 {
            return self.start_mm;
        }
        if t_s >= self.duration_s {
            return self.end_mm();
        }
        match self
            .segment_index_at(t_s)
            .and_then(|i| self.segments.get(i))
        {
            Some(seg) => seg.position_at(t_s - seg.start_time_s),
            None => self.start_mm,
        }
    }
}

/// Plans a parsed program from its start position, stopping at every junction.
pub fn plan(program: &Program, limits: &Limits) -> Result<Plan, PlanError> {
    plan_with(program, limits, &PlannerConfig::exact_stop())
}

/// Plans a parsed program from its start position with the look-ahead `config`.
pub fn plan_with(
    program: &Program,
    limits: &Limits,
    config: &PlannerConfig,
) -> Result<Plan, PlanError> {
    plan_items_with(program.start_mm, &program.items, limits, config)
}

/// Plans `items` (elements, dwells, stops; notes and the end are ignored) from `start_mm`
/// into one [`Plan`], stopping at every junction.
pub fn plan_items<'a>(
    start_mm: Vector3<f64>,
    items: impl IntoIterator<Item = &'a Item>,
    limits: &Limits,
) -> Result<Plan, PlanError> {
    plan_items_with(start_mm, items, limits, &PlannerConfig::exact_stop())
}

/// [`plan_items`] with the look-ahead `config`: [`Planner`] run over all of them.
pub fn plan_items_with<'a>(
    start_mm: Vector3<f64>,
    items: impl IntoIterator<Item = &'a Item>,
    limits: &Limits,
    config: &PlannerConfig,
) -> Result<Plan, PlanError> {
    let mut planner = Planner::with_config(start_mm, limits, config)?;
    let mut segments = Vec::new();
    for item in items {
        planner.push(item)?;
        segments.extend(planner.drain());
    }
    planner.finish()?;
    segments.extend(planner.drain());
    Ok(Plan {
        start_mm,
        segments,
        duration_s: planner.time_s(),
        smoothing: planner.smoothing(),
    })
}

/// The time a corner taken at `v` costs over running through at `v_cruise`: slowing down
/// and speeding up again by `Δv = v_cruise − v` takes `t = Δv/a + a/j` each way (`2√(Δv/j)`
/// when the acceleration never reaches `a`) at the mean speed `(v_cruise + v)/2`, so the two
/// lose `t·Δv/v_cruise` against cruising. An estimate for choosing between a sharp corner and
/// a blend; the profiles are planned exactly afterwards.
fn corner_cost_s(v_cruise: f64, v: f64, acc: f64, jerk: f64) -> f64 {
    let dv = (v_cruise - v).max(0.0);
    if dv == 0.0 || v_cruise <= 0.0 {
        return 0.0;
    }
    let t = if jerk.is_finite() && dv < acc * acc / jerk {
        2.0 * (dv / jerk).sqrt()
    } else if jerk.is_finite() {
        dv / acc + acc / jerk
    } else {
        dv / acc
    };
    t * dv / v_cruise
}

/// An element waiting in the look-ahead window.
#[derive(Debug, Clone, Copy)]
struct Pending {
    /// Geometry (the speeds and the profile are filled in when it settles).
    seg: Segment,
    limits: ProfileLimits,
    blend: BlendMode,
    /// Highest speed allowed at its start (the junction with the element before).
    cap_start_mm_s: f64,
    /// The same and the element's own speed limit, by the machine alone (the programmed feed
    /// aside): [`Segment::v_start_limit_mm_s`], [`Segment::v_limit_mm_s`].
    cap_start_limit_mm_s: f64,
    v_limit_mm_s: f64,
    /// Length as programmed, before blends took some of it (each blend takes at most half).
    full_length_mm: f64,
    tangent_start: Vector3<f64>,
    tangent_end: Vector3<f64>,
    /// Curvature vector `N/r` at the start and at the end (zero on lines).
    curvature_start: Vector3<f64>,
    curvature_end: Vector3<f64>,
    /// The auxiliary axes' rates `Δᵢ/L` ([`aux_axes`]).
    aux_rate: AuxPos,
    /// Largest acceleration and jerk of each axis the profile may use.
    acc_used_mm_s2: Vector3<f64>,
    jerk_used_mm_s3: Vector3<f64>,
    /// With smoothing: the S-curve limits for a move from rest to rest, run on its own without
    /// the time-law filter (exactly time-optimal for one element).
    alone: Option<ProfileLimits>,
    /// The discrete curvature `Δu/L̄` of the vertex at its start (zero where the motion stops
    /// there or the path is tangent), `L̄` the mean length of the two elements.
    kink_in: Vector3<f64>,
    /// A piece of a refined chord ([`refine`]): its vertices are computed, not rounded, so
    /// the vertex rules' allowance for rounding does not apply to them.
    refined: bool,
    /// The junction at its start, while the plan does not yet know whether its dip is planned
    /// as a plateau or lowered ([`Planner::finalize_junction`]); its caps are the lowered
    /// ones meanwhile.
    provisional: Option<Provisional>,
    /// Its place in the program's sequence of elements (to find it in the window).
    seq: u64,
    /// Whether the time-law filter's dip left nothing of the cap at its start (a stop, or a
    /// plateau instead): where such junctions are dense, plateaus pay.
    low_cap: bool,
    /// Whether it is a corner's blend arc ([`Planner::blend_arc`]): the lines on either side
    /// give it their ends.
    is_blend_arc: bool,
    /// The junction at its start's cap under the feeds before the time-law filter's dip
    /// ([`Planner::dip_caps`]); 0 where none is known (after a blend arc, at the start).
    raw_cap_start_mm_s: f64,
    /// Its tangential acceleration as its own limits and [`share_acceleration`] with its
    /// neighbours leave it, before a vertex's normal-jerk cap
    /// ([`Planner::curve_acc_mm_s2`]), which holds for the elements at that vertex only and
    /// is not passed on through further junctions.
    shared_acc_mm_s2: f64,
    /// As a line of a chord run taken as a curve (`curve::take_curve_vertex`): the curve its
    /// limits were made for, which the junction at its end then leaves to it, and which sets
    /// its use of the axes at a speed.
    curve_fit: Option<curve::CurveFit>,
    /// As a line of a chord run taken as a curve: the curve of the vertex at its start (at
    /// its end for the run's first line), whose use of the axes leaves it the tangential
    /// acceleration it plans with at its speed ([`curve::CurveFit::acc_at`]).
    curve_acc: Option<curve::CurveFit>,
    /// With [`Pending::curve_acc`]: the acceleration the look-ahead's backward pass planned
    /// it with last and the speed up to which that is valid (`curve::reach_mm_s`).
    reach_memo: Option<(f64, f64)>,
    /// What the look-ahead's backward pass found here last (`curve::PassMark`).
    pass_mark: Option<curve::PassMark>,
    /// With [`Pending::curve_acc`]: the tangential acceleration its curve leaves at every speed
    /// up to its cap (`curve::refresh_floor`); ∞ without.
    acc_floor_mm_s2: f64,
    /// How far before its start every element's ceiling (`v_limit_mm_s`) is within its own:
    /// the erosion of curve caps stops walking back there (`curve::erode_back`).
    floor_reach_mm: f64,
    /// The share of its time-law acceleration (and of the jerk that makes) the element plans
    /// with ([`Planner::choose_kink_share`]); 1 unless a kinked run took less.
    time_law_share: f64,
    /// With a smaller `time_law_share`: how far back from the element's end the plan's
    /// accelerations are all within that share (the run of lines that took it, infinite from
    /// a stop where the filter settles whole); 0 otherwise.
    lowered_run_mm: f64,
}

/// A junction whose cap is below its neighbours' speeds, in the jerk-limited mode, while the
/// elements after it within reach have not all come ([`Planner::finalize_junction`]).
#[derive(Debug, Clone, Copy)]
struct Provisional {
    /// The junction's caps before the dip (under the feeds; by the machine alone).
    fed_mm_s: f64,
    limit_mm_s: f64,
    /// The discrete curvature of the vertex, [`Pending::kink_in`] if the motion passes it.
    kink: Vector3<f64>,
}

/// Most elements on each side of a junction a plateau ([`Planner::finalize_junction`]) may
/// span: it bounds the work per element.
const MAX_PLATEAU_ELEMENTS: usize = 256;

/// The look-ahead keeps a reserve of `lookahead / RESERVE_PER_LOOKAHEAD` elements it could
/// settle before those braking for the stop at its end (`Planner::replan`).
const RESERVE_PER_LOOKAHEAD: usize = 8;

/// The streaming planner: items in with [`push`](Planner::push), settled segments out with
/// [`pop`](Planner::pop), [`finish`](Planner::finish) at the end of the program. Memory is
/// bounded by the look-ahead window, whatever the program's length (see the module
/// documentation for the passes). Each element must start where the previous one ended.
#[derive(Debug, Clone)]
pub struct Planner {
    limits: Limits,
    config: PlannerConfig,
    /// Where everything pushed ends.
    position_mm: Vector3<f64>,
    /// Where the auxiliary axes are at the end of everything pushed (`None` before the first
    /// element), and at the end of everything settled.
    aux_pushed: Option<AuxPos>,
    aux_settled: Option<AuxPos>,
    /// End time of everything settled.
    time_s: f64,
    /// The elements pushed and not settled, oldest first ([`window`]).
    window: window::Window,
    /// Start speed of the window's first element (the last settled end speed).
    v_settled_mm_s: f64,
    /// Backward-pass speeds, scratch.
    back_mm_s: Vec<f64>,
    /// The acceleration the backward pass reached each `back_mm_s` with, on a chord run taken
    /// as a curve ([`curve::reach_mm_s`]; NaN elsewhere), and the speed up to which it is
    /// valid (at least the reach before the start's cap). Scratch.
    back_acc: Vec<(f64, f64)>,
    /// Whether each backward speed comes from a junction's own cap (reached through elements
    /// whose lengths bind) rather than from the stop at the window's end: such a speed no
    /// longer changes as elements come. Scratch, like `back_mm_s`.
    back_anchored: Vec<bool>,
    /// The forward pass's start and end speed of each element it would settle, and the
    /// curve's pair (`Planner::settle`), before the reserve is kept back. Scratch.
    forward: Vec<(f64, f64, (f64, f64))>,
    ready: VecDeque<Segment>,
    finished: bool,
    /// Elements that could not be stretched to whole periods (see
    /// [`PlannerConfig::integer_periods`]).
    off_grid: usize,
    /// The jerk-limited mode's filters, which the plan is made for.
    smoothing: Option<Smoothing>,
    /// A move planned alone (without the time-law filter) ended here, at rest, and the axis
    /// filters have not been given time to settle.
    axes_unsettled: Option<Unsettled>,
    /// A filtered move stopped here at a junction its time-law filter may pass slowly, and the
    /// plan stood still only part of that filter's settling time.
    time_law_unsettled: Option<TimeLawUnsettled>,
    /// Plan time at which the plan last decelerated, or ran a move alone (whose last
    /// acceleration the time-law filter did not see): [`Planner::split_for_acceleration`]
    /// lets an element start at its whole acceleration where this lies at least the filter's
    /// length (and two periods) behind it.
    decel_until_s: f64,
    /// Plan time from which the filters' output stands where the plan does (every move
    /// settled so far has ended, and the filters it ran through have had their settling
    /// time): a move alone starting then bypasses the axis filters.
    filters_quiet_s: f64,
    /// The sequence number of the next element pushed ([`Pending::seq`]).
    next_seq: u64,
    /// The elements of the window whose start junction is provisional, in order.
    provisional: VecDeque<u64>,
    /// The run of chords being taken as a curve (jerk-limited mode, [`curve`]).
    curve: curve::CurveState,
    /// Dense runs of lines on their way in, smoothed (jerk-limited mode, [`smooth`]).
    smoother: smooth::ChordSmoother,
    /// The chord fairer after it ([`fair`]).
    fairer: fair::ChordFairer,
    /// The chord refiner after it ([`refine`]).
    refiner: refine::ChordRefiner,
    /// While a corner's blend is chosen: curvature steps and turns with the arcs' uses of the
    /// axes at their caps, as the blend's estimate was made for ([`Planner::cap_at_speed`];
    /// the sharp corner it is compared with is taken at speed, as it would run).
    steps_at_caps: std::cell::Cell<bool>,
    /// Collinear lines after them, merged ([`merge`]).
    merger: merge::CollinearMerger,
    /// The feed override ramp's rates `(D, J)` the profiles leave room for
    /// ([`override_ramp_rates`]); `None` where `path_acc_share` leaves none.
    ramp_rates: Option<(f64, f64)>,
}

/// The end of a move planned alone, where the axis filters have not settled: the next move
/// from rest may start at once only if the filters' mix of the two cuts the corner within the
/// tolerance (`Planner::settle`).
#[derive(Debug, Clone, Copy)]
struct Unsettled {
    line: usize,
    at_mm: Vector3<f64>,
    /// The move's direction at its end.
    tangent: Vector3<f64>,
    /// Its distance from its end point at each of the axis filters' last `2·N_k − 1`
    /// samples before it stopped (index `k`: `k + 1` periods before), then zeros.
    behind_mm: [f64; MAX_FILTER_TAPS],
    /// The deviation the axis filters may take at its end.
    tol_mm: f64,
}

/// The end of a filtered move that stopped at a junction whose cap the time-law filter's dip
/// left nothing of: the plan stood still for part of that filter's settling time, so that its
/// output passes the junction no faster than the junction's own cap (`Planner::settle`).
#[derive(Debug, Clone, Copy)]
struct TimeLawUnsettled {
    line: usize,
    at_mm: Vector3<f64>,
    /// Periods of the time-law filter's settling time still to stand, if the next move needs
    /// it settled (a move alone, a dwell, a program stop, the end).
    periods: usize,
    /// The axis filters' state once it has settled (see [`Unsettled`]); `None`: they settle
    /// too.
    axes: Option<Unsettled>,
}

impl Planner {
    /// A planner at rest at `start_mm`, at time 0, that stops at every junction.
    pub fn new(start_mm: Vector3<f64>, limits: &Limits) -> Result<Planner, PlanError> {
        Planner::with_config(start_mm, limits, &PlannerConfig::exact_stop())
    }

    /// A planner at rest at `start_mm`, at time 0, with the look-ahead `config`.
    pub fn with_config(
        start_mm: Vector3<f64>,
        limits: &Limits,
        config: &PlannerConfig,
    ) -> Result<Planner, PlanError> {
        limits.validate()?;
        config.validate()?;
        if !start_mm.iter().all(|c| c.is_finite()) {
            return Err(PlanError::NonFiniteStart);
        }
        let smoothing = Smoothing::for_machine(limits, config);
        let refiner = refine::ChordRefiner::new(refine::Machine {
            axis_filter_s: smoothing.map_or(0.0, |s| s.axis_s(config.period_s)),
            acc_mm_s2: limits.max_acc_mm_s2.min(),
            jerk_mm_s3: config.max_jerk_mm_s3.min(),
            max_feed_mm_s: limits.max_feed_mm_s,
            lookahead: config.lookahead,
        });
        Ok(Planner {
            limits: *limits,
            config: *config,
            position_mm: start_mm,
            aux_pushed: None,
            aux_settled: None,
            time_s: 0.0,
            window: window::Window::with_capacity(config.lookahead.min(1 << 16) + 1),
            v_settled_mm_s: 0.0,
            back_mm_s: Vec::with_capacity(config.lookahead.min(1 << 16) + 2),
            back_acc: Vec::with_capacity(config.lookahead.min(1 << 16) + 2),
            back_anchored: Vec::with_capacity(config.lookahead.min(1 << 16) + 2),
            forward: Vec::with_capacity(config.lookahead.min(1 << 16) + 2),
            ready: VecDeque::new(),
            finished: false,
            off_grid: 0,
            smoothing,
            axes_unsettled: None,
            time_law_unsettled: None,
            decel_until_s: f64::NEG_INFINITY,
            filters_quiet_s: 0.0,
            next_seq: 0,
            provisional: VecDeque::new(),
            curve: curve::CurveState::default(),
            // Straight runs as long as the axis filters' span at the max feed.
            merger: merge::CollinearMerger::new(smoothing.map_or(0.0, |s| {
                2.0 * s.axis_s(config.period_s) * limits.max_feed_mm_s
            })),
            smoother: smooth::ChordSmoother::default(),
            fairer: fair::ChordFairer::default(),
            refiner,
            steps_at_caps: std::cell::Cell::new(false),
            ramp_rates: override_ramp_rates(limits, config),
        })
    }

    /// Adds the next item of the program (notes and the end are ignored). Segments that
    /// settle become available to [`pop`](Self::pop).
    pub fn push(&mut self, item: &Item) -> Result<(), PlanError> {
        if self.smoothing.is_none() {
            return self.push_item(item, false);
        }
        // Jerk-limited mode: runs of G64 lines pass through the chord smoother, the fairer
        // and the refiner, then collinear lines merge.
        let tol_mm = self.item_tolerance_mm(item);
        self.smoother.push(item, tol_mm);
        self.push_smoothed()
    }

    /// Plans what the chord smoother has passed on, through the chord fairer.
    fn push_smoothed(&mut self) -> Result<(), PlanError> {
        while let Some(item) = self.smoother.out.pop_front() {
            let tol_mm = self.item_tolerance_mm(&item);
            self.fairer.push(&item, tol_mm);
            self.push_faired()?;
        }
        Ok(())
    }

    /// Plans what the chord fairer has passed on, through the chord refiner.
    fn push_faired(&mut self) -> Result<(), PlanError> {
        while let Some(item) = self.fairer.out.pop_front() {
            let tol_mm = self.item_tolerance_mm(&item);
            self.refiner.push(item, tol_mm);
            self.push_refined()?;
        }
        Ok(())
    }

    /// Plans what the chord refiner has passed on.
    fn push_refined(&mut self) -> Result<(), PlanError> {
        while let Some((item, refined)) = self.refiner.out.pop_front() {
            // A refined chord's pieces go straight on; anything else through the merger.
            let pushed = if refined {
                self.merger.flush();
                self.push_merged()
                    .and_then(|()| self.push_item(&item, true))
            } else {
                self.merger.push(item);
                self.push_merged()
            };
            if let Err(e) = pushed {
                self.smoother.out.clear();
                self.fairer.out.clear();
                self.refiner.out.clear();
                return Err(e);
            }
        }
        Ok(())
    }

    /// Plans what the collinear merger has passed on.
    fn push_merged(&mut self) -> Result<(), PlanError> {
        while let Some(item) = self.merger.out.pop_front() {
            if let Err(e) = self.push_item(&item, false) {
                self.merger.out.clear();
                return Err(e);
            }
        }
        Ok(())
    }

    /// [`push`](Self::push) after the chord smoother and refiner; `refined`: the item is a
    /// piece of a refined chord ([`refine`]).
    fn push_item(&mut self, item: &Item, refined: bool) -> Result<(), PlanError> {
        match item {
            Item::Motion(e) => {
                let Some(mut p) = self.element(e)? else {
                    return Ok(());
                };
                p.refined = refined;
                self.choose_kink_share(&mut p);
                // The blend is chosen with the curvature steps' and turns' rules at the arcs'
                // caps, which its estimate of the time was made for: at the junction's speed,
                // blend arcs that ran slower than the sharp corner were taken (two lines of
                // 30 mm turning 4°: 0.78 s sharp, 1.01 s blended).
                self.steps_at_caps.set(true);
                let blend = match self.window.back() {
                    Some(prev) => self.blend_arc(prev, &p),
                    None => Ok(None),
                };
                self.steps_at_caps.set(false);
                let blend = blend?;
                // What is left of `p` beyond the time-law filter's reach of its start, where
                // `p` was split there ([`Planner::share_at_junction`]).
                let mut rest = None;
                let blended = blend.is_some();
                match blend {
                    None => {
                        // A vertex of a chord run: its curve taken by the elements, the caps
                        // of those before it within reach held ahead ([`curve`]).
                        let raw = self.start_caps(&mut p);
                        (p.cap_start_mm_s, p.cap_start_limit_mm_s) =
                            raw.map_or((0.0, 0.0), |(_, dipped)| dipped);
                        let ((fed_mm_s, limit_mm_s), _) = raw.unwrap_or_default();
                        p.raw_cap_start_mm_s = fed_mm_s;
                        p.low_cap = raw.is_some() && p.cap_start_mm_s == 0.0;
                        // Only a dip that would become a stop (a shallower one costs less than
                        // a plateau), among others.
                        let provisional = self.smoothing.is_some()
                            && fed_mm_s > 0.0
                            && p.low_cap
                            && self.dense_before(limit_mm_s);
                        if let Some(prev) = self.window.back_mut() {
                            if provisional {
                                // Planned once the elements within the filter's reach are known.
                                p.provisional = Some(Provisional {
                                    fed_mm_s,
                                    limit_mm_s,
                                    kink: discrete_curvature(prev, &p),
                                });
                            } else if p.cap_start_mm_s > 0.0 {
                                p.kink_in = discrete_curvature(prev, &p);
                            }
                        }
                        // Moved into `rest` only where there is one (an element is large).
                        if !provisional
                            && p.cap_start_mm_s > 0.0
                            && let Some(r) = self.share_at_junction(&mut p, (fed_mm_s, limit_mm_s))
                        {
                            rest = Some(r);
                        }
                    }
                    Some(blend) => {
                        self.curve.end_run();
                        let prev = self.window.back_mut().expect("a blend follows an element");
                        let before_mm = prev.seg.length_mm;
                        blend.trim(prev, &mut p);
                        self.curve.pushed_mm -= before_mm - prev.seg.length_mm;
                        let Blend {
                            mut arc,
                            cap_in,
                            cap_out,
                            ..
                        } = *blend;
                        // No auxiliary axis moves on either side of a blended corner.
                        arc.seg.aux = AuxMove::still(prev.seg.aux.end);
                        (arc.cap_start_mm_s, arc.cap_start_limit_mm_s) = cap_in;
                        (p.cap_start_mm_s, p.cap_start_limit_mm_s) = cap_out;
                        if self.smoothing.is_some() {
                            if arc.cap_start_mm_s > 0.0 {
                                share_acceleration(prev, &mut arc);
                            }
                            if p.cap_start_mm_s > 0.0 {
                                share_acceleration(&mut arc, &mut p);
                            }
                        }
                        // The caps held ahead of a chord run before the corner.
                        let at_mm = self.curve.pushed_mm;
                        let prev = self.window.back().expect("a blend follows an element");
                        let prev_acc = prev.limits.a_max_mm_s2();
                        curve::link_floor(prev, &mut arc);
                        let ahead = self.curve.cap_at(at_mm);
                        self.erode_ahead_blend(&mut arc, ahead, prev_acc);
                        let ahead = self.curve.cap_at(at_mm + arc.seg.length_mm);
                        self.erode_ahead_blend(&mut p, ahead, arc.limits.a_max_mm_s2());
                        curve::link_floor(&arc, &mut p);
                        self.curve.pushed_mm += arc.seg.length_mm;
                        arc.seq = self.next_seq;
                        self.next_seq += 1;
                        self.window.push_back(arc);
                    }
                }
                if !blended && let Some(prev) = self.window.back() {
                    curve::link_floor(prev, &mut p);
                }
                if let Some(rest) = rest.as_mut() {
                    curve::link_floor(&p, rest);
                }
                // The part of a line beyond the reach of what was held ahead of it
                // ([`Planner::hold_on`]), after all of `p`.
                // Taken only where there is one: a pending element is large, and `take` copies it
                // whole either way.
                let mut held_rest = match self.curve.held_rest {
                    Some(_) => self.curve.held_rest.take(),
                    None => None,
                };
                if let Some(held) = held_rest.as_mut() {
                    curve::link_floor(rest.as_ref().unwrap_or(&p), held);
                }
                self.curve.pushed_mm += p.seg.length_mm
                    + rest.as_ref().map_or(0.0, |r| r.seg.length_mm)
                    + held_rest.as_ref().map_or(0.0, |r| r.seg.length_mm);
                let last = held_rest.as_ref().or(rest.as_ref()).unwrap_or(&p);
                self.position_mm = last.seg.end_mm;
                self.aux_pushed = Some(last.seg.aux.end);
                p.seq = self.next_seq;
                self.next_seq += 1;
                if p.provisional.is_some() {
                    self.provisional.push_back(p.seq);
                }
                self.window.push_back(p);
                let pushed = 1 + usize::from(rest.is_some()) + usize::from(held_rest.is_some());
                // By reference: chaining the options moved both, each a large element.
                for rest in [rest.as_mut(), held_rest.as_mut()].into_iter().flatten() {
                    rest.seq = self.next_seq;
                    self.next_seq += 1;
                    self.window.push_back(*rest);
                }
                self.memo_pushed(pushed);
                self.finalize_junctions(false);
                if self.window.len() >= self.config.lookahead {
                    self.replan(false)?;
                }
                Ok(())
            }
            Item::Dwell(d) => {
                if !(d.seconds >= 0.0 && d.seconds.is_finite()) {
                    return Err(PlanError::InvalidDwell {
                        line: d.line,
                        seconds: d.seconds,
                    });
                }
                if d.seconds == 0.0 {
                    return Ok(());
                }
                self.replan(true)?;
                self.curve.reset();
                self.settle_axes()?;
                self.push_still(still(
                    d.line,
                    self.position_mm,
                    SegmentPath::Dwell,
                    d.seconds,
                    self.time_s,
                ))
            }
            Item::Stop(s) => {
                self.replan(true)?;
                self.curve.reset();
                self.settle_axes()?;
                self.push_still(still(
                    s.line,
                    self.position_mm,
                    SegmentPath::Stop {
                        optional: s.optional,
                    },
                    0.0,
                    self.time_s,
                ))
            }
            Item::Note(_) | Item::End(_) => Ok(()),
        }
    }

    /// The program ended: everything pushed settles, the motion ending at rest.
    pub fn finish(&mut self) -> Result<(), PlanError> {
        self.smoother.flush();
        self.push_smoothed()?;
        self.fairer.flush();
        self.push_faired()?;
        self.refiner.flush();
        self.push_refined()?;
        self.merger.flush();
        self.push_merged()?;
        self.finished = true;
        self.replan(true)?;
        self.curve.reset();
        self.settle_axes()
    }

    /// Before an exact stop (a dwell, a program stop, the end): the axis filters settle after a
    /// move planned alone (after a filtered move [`settle`](Self::settle) already waited).
    fn settle_axes(&mut self) -> Result<(), PlanError> {
        self.settle_time_law()?;
        let (Some(smoothing), Some(Unsettled { line, at_mm, .. })) =
            (self.smoothing, self.axes_unsettled.take())
        else {
            return Ok(());
        };
        let periods = 2 * (smoothing.axis_periods - 1);
        if periods == 0 {
            return Ok(());
        }
        self.push_still(still(
            line,
            at_mm,
            SegmentPath::Dwell,
            periods as f64 * self.config.period_s,
            self.time_s,
        ))
    }

    /// Before a move alone or an exact stop: the time-law filter settles after a filtered move
    /// that stopped for part of its settling time only; then the axis filters are left as after
    /// a whole one (to settle where the next move needs it).
    fn settle_time_law(&mut self) -> Result<(), PlanError> {
        let (Some(smoothing), Some(u)) = (self.smoothing, self.time_law_unsettled.take()) else {
            return Ok(());
        };
        let periods = match u.axes {
            Some(_) => u.periods,
            None => u.periods + 2 * (smoothing.axis_periods - 1),
        };
        if periods > 0 {
            self.push_still(still(
                u.line,
                u.at_mm,
                SegmentPath::Dwell,
                periods as f64 * self.config.period_s,
                self.time_s,
            ))?;
        }
        self.axes_unsettled = u.axes;
        Ok(())
    }

    /// The next settled segment, in time order.
    pub fn pop(&mut self) -> Option<Segment> {
        self.ready.pop_front()
    }

    /// Every settled segment, in time order.
    pub fn drain(&mut self) -> impl Iterator<Item = Segment> + '_ {
        self.ready.drain(..)
    }

    /// End time of everything settled (of the whole program once finished).
    pub fn time_s(&self) -> f64 {
        self.time_s
    }

    /// Where everything pushed so far ends.
    pub fn position_mm(&self) -> Vector3<f64> {
        self.position_mm
    }

    /// Whether [`finish`](Self::finish) was called.
    pub fn is_finished(&self) -> bool {
        self.finished
    }

    /// Moving elements that [`PlannerConfig::integer_periods`] could not stretch to a whole
    /// number of periods (their boundary speeds left no slack).
    pub fn off_grid(&self) -> usize {
        self.off_grid
    }

    /// The filters the plan is made for (see [`Smoothing`]); the interpolator must apply them.
    pub fn smoothing(&self) -> Option<Smoothing> {
        self.smoothing
    }

    /// Elements in the look-ahead window (pushed, not settled).
    pub fn pending(&self) -> usize {
        self.window.len()
    }

    fn push_still(&mut self, mut segment: Segment) -> Result<(), PlanError> {
        // A still holds the auxiliary axes where the settled motion left them.
        segment.aux = AuxMove::still(self.aux_settled.or(self.aux_pushed).unwrap_or_default());
        let end_s = segment.end_time_s();
        if !end_s.is_finite() {
            return Err(PlanError::Overflow { line: segment.line });
        }
        self.time_s = end_s;
        self.ready.push_back(segment);
        Ok(())
    }

    /// The backward and forward passes over the window, then the settled elements out
    /// (`all`: every element, the last ending at rest).
    fn replan(&mut self, all: bool) -> Result<(), PlanError> {
        if all {
            self.finalize_junctions(true);
        }
        let n = self.window.len();
        if n == 0 {
            return Ok(());
        }
        // Elements within reach of a provisional junction wait for it (more elements can only
        // raise its cap).
        let hold_from = if all { n } else { self.held_from() };
        // Backward: the highest start speed of each element from which the rest of the window
        // can still stop at its end.
        self.back_mm_s.clear();
        self.back_mm_s.resize(n + 1, 0.0);
        self.back_anchored.clear();
        self.back_anchored.resize(n + 1, all);
        self.back_acc.clear();
        self.back_acc.resize(n + 1, (f64::NAN, 0.0));
        let mut v_next = 0.0;
        let mut anchored = all;
        for i in (0..n).rev() {
            let p = &self.window[i];
            let cap = if i == 0 {
                self.v_settled_mm_s
            } else {
                p.cap_start_mm_s
            };
            let provisional = p.provisional.is_some();
            let (v, a, pair) = curve::back_reach(p, v_next, cap);
            // The acceleration, valid up to the speed the pair gives (at least the bound).
            self.back_acc[i] = (a, pair.map_or(v, |(_, valid)| valid.max(v)));
            let p = &mut self.window[i];
            if pair.is_some() {
                p.reach_memo = pair;
            }
            p.pass_mark = curve::PassMark::of(p, v, v_next, cap);
            v_next = v;
            if v_next >= cap {
                // A provisional cap may still rise.
                anchored = i == 0 || !provisional;
            }
            self.back_mm_s[i] = v_next;
            self.back_anchored[i] = anchored;
        }
        // Forward: settle the prefix whose end speeds can no longer change.
        let quarter = (n / 4).max(1);
        let mut v0 = self.v_settled_mm_s;
        let mut settled = 0;
        self.forward.clear();
        while settled < n {
            let i = settled;
            // By reference: an element is large, and `settle` copies only its segment.
            let p = &self.window[i];
            let back = self.back_mm_s[i + 1];
            // The forward reach is at least `v0`: below it, `back` is the end speed and the
            // reach itself is not needed (`fwd > back`, whatever its value).
            let mut fwd_acc = (f64::NAN, 0.0);
            let fwd = if back < v0 {
                v0
            } else if p.curve_acc.is_some() {
                let (v, a, valid) =
                    curve::reach_mm_s(p, v0, p.limits.v_max_mm_s()).unwrap_or((v0, f64::NAN, v0));
                fwd_acc = (a, valid.max(v));
                v
            } else {
                profile::max_end_speed(p.seg.length_mm, v0, &p.limits).unwrap_or(v0)
            };
            let v1 = fwd.min(back);
            // The next push may still lower the acceleration of the window's last element
            // (`Planner::share_at_junction`), and with it the speed the element before can
            // end at: neither settles until more come.
            let last = i + 2 >= n;
            // More elements can only raise the backward bound from the window's end; one that
            // comes from a junction's own cap stays.
            let fixed = all
                || (!last && i < hold_from && (fwd <= back || self.back_anchored[i + 1]))
                || (!last && settled < quarter && n >= self.config.lookahead);
            if !fixed {
                break;
            }
            // On a chord run taken as a curve, the acceleration of the pass that bounds the
            // speed change, and the speed up to which it is valid.
            let curve = if v1 >= v0 { fwd_acc } else { self.back_acc[i] };
            self.forward.push((v0, v1, curve));
            v0 = v1;
            settled += 1;
        }
        // The reserve: where the pass stops short of the window's end (the elements left
        // brake for a stop at its end), the last `lookahead / RESERVE_PER_LOOKAHEAD` of the
        // elements it would settle stay too. Otherwise the window kept just what a stop from the settled speed needs,
        // and the next element's curve, lowering the accelerations within its reach, could
        // no longer be planned from it: the vertex fell back to its own junction rules, a dip
        // to 18 mm/s on a 2 mm chorded circle at 50 mm/s, at every lap (`curve.rs`).
        if !all && settled < n {
            let forced = if n >= self.config.lookahead {
                quarter
            } else {
                0
            };
            let reserve = self.config.lookahead / RESERVE_PER_LOOKAHEAD;
            settled = settled.saturating_sub(reserve).max(forced.min(settled));
        }
        for i in 0..settled {
            let (v0, v1, curve) = self.forward[i];
            self.settle(i, v0, v1, curve)?;
        }
        if let Some(&(_, v1, _)) = settled.checked_sub(1).map(|i| &self.forward[i]) {
            self.v_settled_mm_s = v1;
        }
        self.window.drain(..settled);
        // A provisional junction settled by force keeps its lowered caps.
        let front = self.window.front().map_or(u64::MAX, |p| p.seq);
        while self.provisional.front().is_some_and(|&seq| seq < front) {
            self.provisional.pop_front();
        }
        Ok(())
    }

    /// The window's index of the first element that a provisional junction's plateau could
    /// still cap (`window.len()` if none).
    fn held_from(&self) -> usize {
        let (Some(&seq), Some(front), Some(smoothing)) = (
            self.provisional.front(),
            self.window.front(),
            self.smoothing,
        ) else {
            return self.window.len();
        };
        let Some(idx) = seq.checked_sub(front.seq).map(|i| i as usize) else {
            return self.window.len();
        };
        let Some(raw) = self.window.get(idx).and_then(|p| p.provisional) else {
            return self.window.len();
        };
        let reach_mm = raw.limit_mm_s * smoothing.time_law_s(self.config.period_s);
        let mut from = idx;
        let mut covered_mm = 0.0;
        while from > 0 && idx - from < MAX_PLATEAU_ELEMENTS && covered_mm < reach_mm {
            from -= 1;
            covered_mm += self.window[from].seg.length_mm;
        }
        from
    }

    /// Whether the elements at the end of the window within the reach of a plateau at
    /// `limit_mm_s` ([`Planner::finalize_junction`]) are short: a plateau for the next
    /// junction may be possible. Elsewhere (a sharp corner after a longer element) the
    /// junction is lowered at once, its neighbours' rules knowing whether the motion passes
    /// it. Until session 27 a junction among them had to stop or wait for its own plateau
    /// too: an isolated junction among short elements stopped (see
    /// [`Planner::finalize_junction`]).
    fn dense_before(&self, limit_mm_s: f64) -> bool {
        let Some(smoothing) = self.smoothing else {
            return false;
        };
        let reach_mm = limit_mm_s * smoothing.time_law_s(self.config.period_s);
        let mut covered_mm = 0.0;
        for p in self.window.iter().rev().take(MAX_PLATEAU_ELEMENTS) {
            if covered_mm >= reach_mm {
                break;
            }
            if p.seg.length_mm > reach_mm {
                return false;
            }
            covered_mm += p.seg.length_mm;
        }
        covered_mm >= reach_mm
    }

    /// Plans the provisional junctions whose elements within reach have all come (`flush`:
    /// all of them, the window ending at rest).
    fn finalize_junctions(&mut self, flush: bool) {
        while let (Some(&seq), Some(front)) = (self.provisional.front(), self.window.front()) {
            let Some(idx) = seq.checked_sub(front.seq).map(|i| i as usize) else {
                self.provisional.pop_front();
                continue;
            };
            if !self.finalize_junction(idx, flush) {
                break;
            }
            self.provisional.pop_front();
        }
    }

    /// The junction at the start of the window's element `idx`, whose cap `c` is below its
    /// neighbours' speeds: the time-law filter would round the dip of the plan there by up to
    /// `A·T_f/4` (see [`Planner::dip_caps`]). If every element within `c·T_f` of it on either
    /// side is short (at most `c·T_f`, as on a chorded curve), they are capped at `c`
    /// instead (a plateau): the filtered speed at the junction is the distance the plan
    /// covers in one filter time `T_f` around it, over `T_f`, and the plan cannot leave the
    /// plateau within `T_f` at `c`, so it passes at most at `c` and the junction keeps its
    /// cap. Otherwise the lowered caps stay (a stop where nothing is left). `false` while the
    /// elements after it within reach have not all come (the last element of the window may
    /// still be shortened by a blend).
    fn finalize_junction(&mut self, idx: usize, flush: bool) -> bool {
        let (Some(smoothing), Some(raw)) = (
            self.smoothing,
            self.window.get(idx).and_then(|p| p.provisional),
        ) else {
            return true;
        };
        if idx == 0 {
            // It starts at the speed already settled, whatever its cap.
            self.window[0].provisional = None;
            return true;
        }
        let reach_mm = raw.limit_mm_s * smoothing.time_law_s(self.config.period_s);
        let n = self.window.len();
        let known = if flush { n } else { n - 1 };
        // After the elements within reach.
        let mut end = idx;
        let mut covered_mm = 0.0;
        let mut plateau = raw.fed_mm_s >= profile::MIN_LIMIT && reach_mm.is_finite();
        while plateau && covered_mm < reach_mm {
            if end >= known {
                if !flush {
                    return false;
                }
                // The motion stops at the window's end.
                break;
            }
            let len_mm = self.window[end].seg.length_mm;
            plateau = len_mm <= reach_mm && end - idx < MAX_PLATEAU_ELEMENTS;
            covered_mm += len_mm;
            end += 1;
        }
        // Before: still in the window, not settled.
        let mut from = idx;
        covered_mm = 0.0;
        while plateau && covered_mm < reach_mm {
            if from == 0 || idx - from >= MAX_PLATEAU_ELEMENTS {
                plateau = false;
                break;
            }
            from -= 1;
            let len_mm = self.window[from].seg.length_mm;
            plateau = len_mm <= reach_mm;
            covered_mm += len_mm;
        }
        // The window starts at the speed already settled: the plan must still come down to
        // the plateau from it, each element at the acceleration it may plan with (on a chord
        // run taken as a curve, the lower one its curve leaves at speed).
        plateau = plateau && self.can_come_down(from, raw.fed_mm_s * (1.0 - 1e-9));
        // A plateau takes `2·T_f` at `c`. Until session 27 it was taken only where other
        // junctions within reach stopped too (a dense run of low caps, as on a chorded curve
        // whose chords are rounded), a plateau being thought dearer than one stop; a stop
        // among short elements costs more (the plan comes down to rest from the elements
        // either side and the time-law filter settles): with every such junction a plateau,
        // `random_lines_0.001in` −19 %, `3D_Chips` −3.3 %, no corpus program slower by
        // more than 0.3 %.
        if plateau {
            for k in from..end {
                cap_speed(&mut self.window[k], raw.fed_mm_s, raw.limit_mm_s);
            }
            // The junction after the plateau is within it too.
            if let Some(after) = self.window.get_mut(end) {
                after.cap_start_mm_s = after.cap_start_mm_s.min(raw.fed_mm_s);
                after.cap_start_limit_mm_s = after.cap_start_limit_mm_s.min(raw.limit_mm_s);
            }
            let b = &mut self.window[idx];
            b.cap_start_mm_s = raw.fed_mm_s;
            b.cap_start_limit_mm_s = raw.limit_mm_s;
            // Every junction of the plateau within both its elements' speeds (other plateaus
            // may have capped them a rounding lower).
            for k in from.max(1)..=end.min(n - 1) {
                let (a, b) = (&self.window[k - 1], &self.window[k]);
                let fed = a.limits.v_max_mm_s().min(b.limits.v_max_mm_s());
                let limit = a.v_limit_mm_s.min(b.v_limit_mm_s);
                let b = &mut self.window[k];
                b.cap_start_mm_s = b.cap_start_mm_s.min(fed);
                b.cap_start_limit_mm_s = b.cap_start_limit_mm_s.min(limit);
            }
        }
        let (mut a, mut b) = (self.window[idx - 1], self.window[idx]);
        b.provisional = None;
        b.kink_in = Vector3::zeros();
        if b.cap_start_mm_s > 0.0 {
            // Joined at speed: the filter's window spans the junction.
            b.kink_in = raw.kink;
            share_acceleration(&mut a, &mut b);
            let acc = self.curve_acc_mm_s2(&a, &b, b.cap_start_mm_s);
            lower_acceleration(&mut a, acc);
            lower_acceleration(&mut b, acc);
        }
        self.window[idx - 1] = a;
        self.window[idx] = b;
        true
    }

    /// Settles the window's element `i` with the boundary speeds `v0`, `v1`.
    fn settle(
        &mut self,
        i: usize,
        v0: f64,
        v1: f64,
        (curve_acc_mm_s2, curve_mm_s): (f64, f64),
    ) -> Result<(), PlanError> {
        let mut seg = self.window[i].seg;
        let mut limits = self.window[i].limits;
        // On a chord run taken as a curve: the acceleration its look-ahead pass took, under
        // the speed up to which it is valid, `curve_mm_s` (see [`curve::reach_mm_s`]); not
        // under the start's cap: an element whose start is capped low still rises within
        // itself (its peak is at most the pass's reach before the cap). Under the bound at
        // its start, a line of 0.16 mm before a stop ran at 0.11 mm/s for 1.5 s.
        if self.window[i].curve_acc.is_some() {
            let cap = limits.v_max_mm_s().min(curve_mm_s).max(v0).max(v1);
            limits = ProfileLimits::trapezoid(cap, curve_acc_mm_s2)
                .or_else(|| {
                    ProfileLimits::trapezoid(cap, limits.a_max_mm_s2()).filter(|_| v0 == v1)
                })
                .unwrap_or(limits);
        }
        let line = seg.line;
        let no_profile = PlanError::NoProfile {
            line,
            v_start_mm_s: v0,
            v_end_mm_s: v1,
        };
        let alone = self.window[i]
            .alone
            .filter(|_| v0 == 0.0 && v1 == 0.0)
            .map(|share| self.alone_at_axes(&self.window[i], seg.length_mm, share));
        let limits = alone.unwrap_or(limits);
        let mut profile = profile::plan(seg.length_mm, v0, v1, &limits).ok_or(no_profile)?;
        seg.time_law = self.smoothing.is_some() && alone.is_none();
        // A filtered line or arc runs its long speed changes at its whole acceleration, in
        // parts (whole periods keep the element in one piece).
        let parts = if seg.time_law && !self.config.integer_periods {
            self.split_for_acceleration(i, &seg, v0, v1, &profile)
        } else {
            None
        };
        if let Some(parts) = &parts {
            // What follows up to the segment's push looks at the element's start.
            profile = parts[0].1;
        }
        if self.config.integer_periods {
            // Where the boundary speeds leave no slack (a pure acceleration that fills the
            // element), the element keeps its time-optimal duration and the next starts off the
            // grid; counted in `off_grid`.
            match profile.stretch_to_period(self.config.period_s) {
                Ok((stretched, _)) => profile = stretched,
                Err(_) => self.off_grid += 1,
            }
        }
        if v0 == 0.0 && self.time_law_unsettled.is_some() {
            if alone.is_some() {
                // A move alone switches the time-law filter off, at rest: it settles first.
                self.settle_time_law()?;
            } else {
                // The time law runs on through the junction, within its cap.
                self.time_law_unsettled = None;
            }
        }
        if v0 == 0.0
            && let (Some(smoothing), Some(u)) = (self.smoothing, self.axes_unsettled)
        {
            // The axis filters still hold the end of the move alone before this one: their
            // output mixes the last `2·T_k` of it with the first of this move, which cuts the
            // corner by at most the shorter of the two stretches (times the sine of the turn,
            // up to a right angle). Where that could leave the tolerance they settle first.
            let t = self.window[i].tangent_start;
            let turn = if u.tangent.dot(&t) < 0.0 {
                1.0
            } else {
                u.tangent.cross(&t).norm()
            };
            let cut_mm = corner_cut_mm(
                &u.behind_mm,
                |k| profile.at(k as f64 * self.config.period_s).s_mm,
                smoothing,
            );
            if u.tol_mm > 0.0 && cut_mm * turn > u.tol_mm {
                self.settle_axes()?;
            } else {
                self.axes_unsettled = None;
            }
        }
        // A move alone from where the filters have settled needs none of them: its exact
        // profile keeps every limit, and its path is followed exactly. Moves of the auxiliary
        // axes keep them (their samples pass through filters of their own).
        let bypass = alone.is_some()
            && !seg.aux.moves()
            && self.time_s >= self.filters_quiet_s - 0.5 * self.config.period_s;
        seg.axis_filters = self.smoothing.is_some() && !bypass;
        seg.v_limit_mm_s = self.window[i].v_limit_mm_s;
        seg.v_start_limit_mm_s = self.window[i].cap_start_limit_mm_s;
        if let Some(mut parts) = parts {
            // Every part but the last goes out here; the last is the segment from here on.
            let tail = parts.pop().expect("a split has a tail");
            for (k, (mut piece, p)) in parts.into_iter().enumerate() {
                // The junctions between the parts do not turn: the line's own limit.
                piece.v_limit_mm_s = seg.v_limit_mm_s;
                piece.axis_filters = seg.axis_filters;
                piece.v_start_limit_mm_s = if k == 0 {
                    seg.v_start_limit_mm_s
                } else {
                    seg.v_limit_mm_s
                };
                self.put_out(&mut piece, p)?;
            }
            let (v_limit, axis_filters) = (seg.v_limit_mm_s, seg.axis_filters);
            (seg, profile) = tail;
            seg.v_limit_mm_s = v_limit;
            seg.axis_filters = axis_filters;
            seg.v_start_limit_mm_s = v_limit;
        }
        self.put_out(&mut seg, profile)?;
        self.aux_settled = Some(seg.aux.end);
        if let Some(smoothing) = self.smoothing {
            // The filters this move ran through settle after its end: their settling time
            // counts from the first sample that stands at the end, which may come up to a
            // period after it (the move's last sample falls before its end, unless it ends on
            // a sample), so one period more. (Without it a move alone after a stand of exactly
            // the settling time was planned as bypassing filters that had not settled, the
            // interpolator kept them on, and the next corner under `G64 P0.0001` was cut by
            // 0.12 µm: `a_move_alone_after_a_filtered_run_keeps_the_filters_until_they_settle`.)
            let periods = match (seg.time_law, seg.axis_filters) {
                (true, _) => smoothing.settle_periods() + 1,
                (false, true) => 2 * (smoothing.axis_periods - 1) + 1,
                (false, false) => 0,
            };
            self.filters_quiet_s = self.time_s + periods as f64 * self.config.period_s;
        }
        if bypass {
            // Nothing of it is left in the filters.
            self.axes_unsettled = None;
        } else if alone.is_some() {
            let duration_s = profile.duration_s();
            let mut behind_mm = [0.0; MAX_FILTER_TAPS];
            for (k, d) in behind_mm.iter_mut().enumerate() {
                *d = seg.length_mm
                    - profile
                        .at(duration_s - (k + 1) as f64 * self.config.period_s)
                        .s_mm;
            }
            self.axes_unsettled = Some(Unsettled {
                line,
                at_mm: seg.end_mm,
                tangent: self.window[i].tangent_end,
                behind_mm,
                tol_mm: self.filter_tolerance_mm(self.window[i].blend),
            });
        } else if let Some(smoothing) = self.smoothing
            && v1 == 0.0
        {
            // The time-law filter catches up before anything else starts: its output then
            // stands exactly at the element's end. The axis filters settle too before an exact
            // stop, a program stop or dwell and the program's end (`settle_axes`), and before
            // the next move only where mixing the two legs could cut the corner beyond the
            // tolerance, as after a move alone (see the start of this function).
            let behind = filtered_stop_behind_mm(&profile, smoothing, self.config.period_s);
            let full = match behind {
                Some(_) => smoothing.time_law_periods - 1,
                None => smoothing.settle_periods(),
            };
            let axes = behind.map(|behind_mm| Unsettled {
                line,
                at_mm: seg.end_mm,
                tangent: self.window[i].tangent_end,
                behind_mm,
                tol_mm: self.filter_tolerance_mm(self.window[i].blend),
            });
            self.axes_unsettled = None;
            // Only where the axis filters' state is known (`behind`): a move too short for it
            // stands its full settling time, the axis filters' too.
            let hold = behind
                .and_then(|_| self.partial_hold_periods(i, smoothing))
                .filter(|&h| h < full);
            let periods = hold.unwrap_or(full);
            if periods > 0 {
                let settle = still(
                    line,
                    seg.end_mm,
                    SegmentPath::Dwell,
                    periods as f64 * self.config.period_s,
                    self.time_s,
                );
                self.push_still(settle)?;
            }
            match hold {
                Some(h) => {
                    self.time_law_unsettled = Some(TimeLawUnsettled {
                        line,
                        at_mm: seg.end_mm,
                        periods: smoothing.time_law_periods - 1 - h,
                        axes,
                    });
                }
                None => self.axes_unsettled = axes,
            }
        }
        Ok(())
    }

    /// Stamps the moving segment `seg` with `profile` (its speeds, peak and start time) and puts
    /// it out: the plan's time moves on to its end.
    fn put_out(&mut self, seg: &mut Segment, profile: SpeedProfile) -> Result<(), PlanError> {
        seg.v_start_mm_s = profile.v_start_mm_s();
        seg.v_end_mm_s = profile.v_end_mm_s();
        seg.v_peak_mm_s = profile
            .v_cruise_mm_s()
            .max(seg.v_start_mm_s)
            .max(seg.v_end_mm_s);
        seg.profile = Some(profile);
        seg.start_time_s = self.time_s;
        let end_s = seg.end_time_s();
        if !end_s.is_finite() {
            return Err(PlanError::Overflow { line: seg.line });
        }
        self.time_s = end_s;
        self.note_decel(seg);
        self.ready.push_back(*seg);
        Ok(())
    }

    /// Keeps [`Planner::decel_until_s`] with the moving segment `seg` settled.
    fn note_decel(&mut self, seg: &Segment) {
        if !seg.time_law || seg.v_end_mm_s < seg.v_peak_mm_s {
            self.decel_until_s = seg.end_time_s();
        }
    }

    /// The filtered line or arc `i` (settled from `v0` to `v1`, its plain trapezoid `plain`) in
    /// parts whose speed changes run at its whole acceleration in their middles (`J·T_f`,
    /// within what its axes' share and, on an arc, its own rules allow: the limits of its move
    /// alone), where that is faster: `None` where it is not, or the element is a line of a
    /// chord run or moves an auxiliary axis.
    ///
    /// The time-law filter's jerk is the range of the plan's acceleration over one filter
    /// length `T_f`, over `T_f`: a run of trapezoids at `a = J·T_f/2`, as the look-ahead plans
    /// them, keeps it within `J` even where the acceleration reverses at once (a peak, a dip).
    /// The whole `J·T_f` may be used where no acceleration of the other sign lies within `T_f`:
    /// each speed change of the element longer than two zones of `T_f` keeps `a` for a zone at
    /// either end and runs at the whole acceleration between. The element then keeps `a` within
    /// `T_f` of its ends, where its neighbours' accelerations meet it in the filter (whatever
    /// they plan), and either side of its peak, where it reverses; the whole acceleration only
    /// ever meets `a` of the same sign or 0. Each `T_f` counts two periods more: the jerk of
    /// the samples, a third difference, sees the plan's acceleration over `T_f` and two
    /// periods. The peak is the highest the element's length then allows (the speed changes
    /// take less of it), within its cap. Where nothing decelerated within that before the
    /// element ([`Planner::decel_until_s`]) and it starts at rest (the program's start, after a
    /// dwell), its first zone is not needed. The end speeds stay those the look-ahead settled,
    /// and the parts within its end zones keep the acceleration the rules at its junctions (the
    /// time-law filter's dip, a stand's length, the axis filters' turn) were planned with. The
    /// gain grows continuously with the speed changes' length (a blend that shortens an
    /// element loses it gradually).
    fn split_for_acceleration(
        &self,
        i: usize,
        seg: &Segment,
        v0: f64,
        v1: f64,
        plain: &SpeedProfile,
    ) -> Option<Vec<(Segment, SpeedProfile)>> {
        let p = &self.window[i];
        let smoothing = self.smoothing?;
        let period_s = self.config.period_s;
        let t_f = smoothing.time_law_s(period_s);
        let acc = split_acc_mm_s2(p, t_f)?;
        let t_z = (t_f + 2.0 * period_s) * (1.0 + 1e-9);
        let (v_max, a_e) = (p.limits.v_max_mm_s(), p.limits.a_max_mm_s2());
        // (NaN-safe: a limit that is not a number splits nothing.)
        if acc.is_nan() || acc <= a_e * 1.01 || v0 > v_max || v1 > v_max {
            return None;
        }
        // The first zone is not needed where the plan starts at rest and has not decelerated
        // within the time-law filter's length (and two periods) before.
        let free_head = v0 == 0.0 && self.time_s - self.decel_until_s >= t_f + 2.0 * period_s;
        let dv_z = a_e * t_z;
        // A speed change runs at `acc` only past a zone at its top (`(w − dv_z + dv_z/2)·t_z`
        // long, `w > dv_z`): shorter elements (the tiny chords of CAM output) keep their
        // profile without the search below.
        if seg.length_mm < 0.5 * dv_z * t_z {
            return None;
        }
        // A speed change from `v` up to `w`: whether it runs at `acc` in its middle (its zones,
        // `zones` of them at its ends, take `dv_z` each), and its length.
        let ramp = |v: f64, w: f64, zones: f64| {
            let fast = w - v > zones * dv_z;
            let len = if fast {
                let (lo, hi) = (v + (zones - 1.0) * dv_z, w - dv_z);
                // The zones at `a_e` (at `v`'s end only where there is one) and the middle.
                (zones - 1.0) * (v * t_z + 0.5 * dv_z * t_z)
                    + ((w - dv_z) * t_z + 0.5 * dv_z * t_z)
                    + (hi * hi - lo * lo) / (2.0 * acc)
            } else {
                (w * w - v * v) / (2.0 * a_e)
            };
            (fast, len)
        };
        let zones0 = if free_head { 1.0 } else { 2.0 };
        let need = |w: f64| ramp(v0, w, zones0).1 + ramp(v1, w, 2.0).1;
        let floor = v0.max(v1);
        if need(floor) > seg.length_mm {
            return None;
        }
        // The highest peak the length allows (the length needed rises with it).
        let v_p = if need(v_max) <= seg.length_mm {
            v_max
        } else {
            let (mut lo, mut hi) = (floor, v_max);
            for _ in 0..60 {
                let mid = 0.5 * (lo + hi);
                if need(mid) <= seg.length_mm {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            lo * (1.0 - 1e-9)
        }
        .max(floor);
        let (fast0, fast1) = (ramp(v0, v_p, zones0).0, ramp(v1, v_p, 2.0).0);
        if !(fast0 || fast1) {
            return None;
        }
        let lim_e = ProfileLimits::trapezoid(v_max, a_e)?;
        let lim_a = ProfileLimits::trapezoid(v_max, acc)?;
        // The parts of a fast speed change from `v` to the middle trapezoid (at `a_e`, with the
        // peak): its zone at `a_e` (where it has one) and its part at the whole acceleration,
        // each `(length, profile)` and run up from `v` (`up`) or down to it; and the speed
        // they reach.
        let ramp_parts = |v: f64, zone: bool, up: bool| {
            let step = |len: f64, from: f64, lim: &ProfileLimits| {
                let u = profile::max_end_speed(len, from, lim)?;
                let p = if up {
                    profile::plan(len, from, u, lim)?
                } else {
                    profile::plan(len, u, from, lim)?
                };
                Some((u, (len, p)))
            };
            let mut parts: Vec<(f64, SpeedProfile)> = Vec::with_capacity(2);
            let mut x = v;
            if zone {
                let (u, part) = step(v * t_z + 0.5 * dv_z * t_z, x, &lim_e)?;
                parts.push(part);
                x = u;
            }
            let w = v_p - dv_z;
            let len = (w * w - x * x) / (2.0 * acc);
            if len > 0.0 {
                let (u, part) = step(len, x, &lim_a)?;
                parts.push(part);
                x = u;
            }
            Some((parts, x))
        };
        let (head, x0) = if fast0 {
            ramp_parts(v0, !free_head, true)?
        } else {
            (Vec::new(), v0)
        };
        let (mut tail, x1) = if fast1 {
            ramp_parts(v1, true, false)?
        } else {
            (Vec::new(), v1)
        };
        tail.reverse();
        let taken: f64 = head.iter().chain(&tail).map(|&(len, _)| len).sum();
        let len_m = seg.length_mm - taken;
        let lim_m = ProfileLimits::trapezoid(v_p.max(x0).max(x1), a_e)?;
        let middle = profile::plan(len_m, x0, x1, &lim_m)?;
        let mut parts = head;
        parts.push((len_m, middle));
        parts.extend(tail);
        // The split must pay for itself.
        let total: f64 = parts.iter().map(|(_, p)| p.duration_s()).sum();
        if total.is_nan() || total >= plain.duration_s() - 1e-6 {
            return None;
        }
        // The parts' ends on the path (a line's second half measured back from its end, as
        // `Segment::point_at_distance` does), and their paths: an arc's parts are arcs of its
        // circle (or helix) through them.
        let path = |from: Vector3<f64>, to: Vector3<f64>, share: f64| match seg.path {
            SegmentPath::Arc(arc) => {
                // A helix's centre lies in the plane of its part's start.
                let rise = (from - arc.center_mm).dot(&arc.normal);
                let arc = ArcGeometry {
                    center_mm: arc.center_mm + arc.normal * rise,
                    ..arc
                };
                blend::trimmed_arc((from, to), &arc, share * arc.sweep_rad).map(SegmentPath::Arc)
            }
            other => Some(other),
        };
        let mut pieces = Vec::with_capacity(parts.len());
        let (mut at_mm, mut from) = (0.0, seg.start_mm);
        let last = parts.len() - 1;
        for (k, (len, profile)) in parts.into_iter().enumerate() {
            at_mm += len;
            let to = if k == last {
                seg.end_mm
            } else {
                seg.point_at_distance(at_mm)
            };
            let mut s = *seg;
            s.start_mm = from;
            s.end_mm = to;
            s.length_mm = len;
            s.path = path(from, to, len / seg.length_mm)?;
            pieces.push((s, profile));
            from = to;
        }
        Some(pieces)
    }

    /// Where the filtered element `i` stops at a junction that the motion could pass at its
    /// own cap `c > 0` (the time-law filter's dip, `A·T_f/4`, left nothing of it): the periods
    /// the plan must stand there so that the filter's output passes no faster than `c`. The
    /// plan reaches the stop and leaves it with the acceleration `A` at most, so through a
    /// stand of `h` the filtered speed at the junction is at most `A·(T_f − h)²/(4·T_f)` (the
    /// V of [`Planner::dip_caps`] with its bottom held for `h`; `A·T_f/4` without it, 0 from
    /// `h = T_f`), within `c` from `h = T_f − 2·√(c·T_f/A)`. `None` without such a cap.
    fn partial_hold_periods(&self, i: usize, smoothing: Smoothing) -> Option<usize> {
        let (a, b) = (&self.window[i], self.window.get(i + 1)?);
        let c = b.raw_cap_start_mm_s;
        if c.is_nan() || c <= 0.0 || b.cap_start_mm_s != 0.0 {
            return None;
        }
        let acc = a.limits.a_max_mm_s2().max(b.limits.a_max_mm_s2());
        let t_f = smoothing.time_law_s(self.config.period_s);
        let hold_s = t_f - 2.0 * (c * t_f / acc).sqrt();
        let periods = (hold_s / self.config.period_s - 1e-9).ceil().max(0.0);
        periods.is_finite().then_some(periods as usize)
    }

    /// The share of their time-law acceleration `p`, a line joined at speed to the last line
    /// of the window with a kink, and that line plan with: a smaller one ([`KINK_SHARES`])
    /// where that is estimated faster over both. Under the time-law filter a line's
    /// acceleration `a` reaches each axis as the jerk `2·a/T_f·|uᵢ|` (where the plan's
    /// acceleration reverses, as at every dip), and the vertex rules share what the elements
    /// leave of each axis's jerk: with `a = J·T_f/2` a vertex keeps an eighth of it, and a
    /// polyline whose vertices turn a little each (CAM chords of a few tenths of a millimetre
    /// and more, too sparse to be taken as a curve) runs its dips at the speed that eighth
    /// allows. Half the acceleration leaves the vertices 2.5 times as much, and the dips
    /// (`a·T_f/4`) are half as deep. The estimate ([`sawtooth_s`]) takes `p`'s next junction
    /// as this one, and a junction whose dip leaves nothing as a stop, `p` then run alone. The
    /// last line is lowered as a whole (its earlier junction keeps the caps it has, planned
    /// with its higher use) where the filter's window at the vertex cannot reach the element
    /// before it, and only where the plan can still stop at the window's end with it
    /// ([`Planner::can_stop_with`]); otherwise `p` keeps its acceleration too. In a run the
    /// lines after the first find the line before already lowered.
    fn choose_kink_share(&mut self, p: &mut Pending) {
        let Some(smoothing) = self.smoothing else {
            return;
        };
        let Some(prev) = self.window.back() else {
            return;
        };
        let line = |q: &Pending| {
            matches!(q.seg.path, SegmentPath::Line { .. })
                && !q.seg.aux.moves()
                && q.alone.is_some()
        };
        // Chords as short as the chord smoother's ([`smooth::DENSE_MM`]) are points of a curve
        // where they run as one ([`curve`]), whose lines take their acceleration from the
        // curve's budget; the pieces of a refined chord are not written chords.
        let dense = !(p.refined && prev.refined)
            && p.full_length_mm.min(prev.full_length_mm) <= smooth::DENSE_MM;
        if dense
            || !(line(prev) && line(p))
            || prev.curve_fit.is_some()
            || prev.provisional.is_some()
            || !matches!(p.blend, BlendMode::Blend { .. })
            || !matches!(prev.blend, BlendMode::Blend { .. })
            || (p.tangent_start - prev.tangent_end).norm() == 0.0
        {
            return;
        }
        let t_f = smoothing.time_law_s(self.config.period_s);
        // The junction's cap and the bottom of its dip.
        let caps = |a: &Pending, b: &Pending| {
            let cap = self.junction_limit_mm_s(a, b).min(b.limits.v_max_mm_s());
            let depth = self.dip_depth_mm_s(a.limits.a_max_mm_s2(), b.limits.a_max_mm_s2());
            (cap, cap - depth)
        };
        // Both lines' time with the junction's dip at `bottom` (`p`'s next junction as this
        // one) or, where the dip stops the motion, `p` run alone, time-optimal at its whole
        // acceleration, after the filter settles.
        let time_s = |a: &Pending, b: &Pending, bottom: f64| {
            let t_a = sawtooth_s(a, a.cap_start_mm_s, bottom.max(0.0));
            if bottom > 0.0 {
                Some(t_a + sawtooth_s(b, bottom, bottom))
            } else {
                let alone = b
                    .alone
                    .and_then(|l| profile::plan(b.full_length_mm, 0.0, 0.0, &l))?;
                Some(t_a + t_f + alone.duration_s())
            }
        };
        let (cap, bottom) = caps(prev, p);
        if cap >= p.limits.v_max_mm_s() {
            return;
        }
        let Some(now_s) = time_s(prev, p, bottom) else {
            return;
        };
        let mut best = (now_s * (1.0 - KINK_SHARE_GAIN), None);
        for alpha in KINK_SHARES {
            let (Some(mut a), Some(mut b)) = (
                with_time_law_share(prev, alpha, t_f),
                with_time_law_share(p, alpha, t_f),
            ) else {
                continue;
            };
            // The last line is lowered as a whole only where the filter's window at the
            // vertex (`reach_mm` back, as [`Planner::share_at_junction`] has it) does not reach
            // the element before it, which planned with the line's higher acceleration, or
            // where the line starts from a stop. Where the filter settles whole there, nothing
            // before the stop is in the window; after a partial stand
            // ([`Planner::partial_hold_periods`]) the deceleration before it may be, and the
            // line's use of each axis counts it: at most the mean of the two elements' uses
            // (the filter's jerk is the range of the plan's acceleration over `T_f`).
            let lowers_prev = a.time_law_share < prev.time_law_share;
            let from_stop = a.cap_start_mm_s == 0.0;
            let partial_stand = from_stop && a.raw_cap_start_mm_s > 0.0;
            if lowers_prev && partial_stand {
                let n = self.window.len();
                let Some(before) = n.checked_sub(2).map(|i| &self.window[i]) else {
                    continue;
                };
                a.jerk_used_mm_s3 = a
                    .jerk_used_mm_s3
                    .zip_map(&before.jerk_used_mm_s3, |own, other| {
                        own.max(0.5 * (own + other))
                    });
            }
            let (cap_b, bottom_b) = caps(&a, &b);
            // Passed barely above its dip, a junction is slower than a stop
            // ([`STEP_CAP_MIN_PASS`], as [`Planner::cap_at_speed`]).
            if bottom_b <= bottom.max(STEP_CAP_MIN_PASS * (cap_b - bottom_b)) {
                continue;
            }
            let acc = a.limits.a_max_mm_s2().max(b.limits.a_max_mm_s2());
            let reach_mm = t_f * (acc * t_f + ((acc * t_f).powi(2) + cap_b * cap_b).sqrt());
            if lowers_prev {
                a.lowered_run_mm = if from_stop && !partial_stand {
                    f64::INFINITY
                } else {
                    a.seg.length_mm
                };
                if !((from_stop || reach_mm <= a.lowered_run_mm) && self.can_stop_with(&a)) {
                    continue;
                }
            } else if reach_mm > a.lowered_run_mm {
                // The window would reach back beyond the lines that took the share.
                continue;
            }
            b.lowered_run_mm = a.lowered_run_mm + b.seg.length_mm;
            if let Some(t_s) = time_s(&a, &b, bottom_b)
                && t_s < best.0
            {
                best = (t_s, Some((a, b)));
            }
        }
        if let Some((a, b)) = best.1 {
            *p = b;
            *self.window.back_mut().expect("checked above") = a;
        }
    }

    /// Joins `p` at speed to the window's last element under the time-law filter. The
    /// filter's window spans the junction, so its output near it mixes both elements'
    /// accelerations: within its reach both plan with the lower of the two
    /// ([`share_acceleration`]). Beyond it a line keeps its own: a line whose acceleration is
    /// the higher and which is long enough is split where the reach ends, only the part
    /// within reach taking the lower acceleration (the window's last element gets its tail
    /// within reach pushed after it; a split `p` keeps its head within reach and returns the
    /// rest, to follow it in the window).
    ///
    /// The reach: through the junction at most at `c` (`limit_mm_s`, its cap by the machine
    /// alone, which also bounds a feed override) and with the lower acceleration `a` on the
    /// part within reach, the plan runs at most at `v_r = √(c² + 2·a·L)` on the `L` nearest
    /// the junction, so it takes at least `L/v_r` to cross them. With `L = v_r·T_f` (solved:
    /// `L = T_f·(a·T_f + √((a·T_f)² + c²))`) the filter's window, `T_f` long, never holds both
    /// the other element and the part beyond `L`: while the filtered time law is on the
    /// element with the lower acceleration, every acceleration it averages is within it. The
    /// two parts of the split line meet without a turn; the step of the plan's acceleration
    /// between them is within `2·J·T_f/2`, which the filter turns into a jerk within `J`, as
    /// anywhere else.
    fn share_at_junction(
        &mut self,
        p: &mut Pending,
        (fed_mm_s, limit_mm_s): (f64, f64),
    ) -> Option<Pending> {
        let smoothing = self.smoothing?;
        let t_f = smoothing.time_law_s(self.config.period_s);
        let curve_acc = self.curve_acc_mm_s2(self.window.back()?, p, fed_mm_s);
        let last = self.window.back()?;
        // The lower of the two accelerations passes on through further junctions; the
        // vertex's own cap holds here only.
        let shared = last.shared_acc_mm_s2.min(p.shared_acc_mm_s2);
        let acc = shared.min(curve_acc);
        if last.limits.a_max_mm_s2() > acc && !self.can_lower_last(acc) {
            // The plan could no longer stop at the window's end from the speed it has
            // settled with the last element's acceleration lowered: `p` starts from rest
            // instead, which the plan can always reach, and the filters settle there.
            p.cap_start_mm_s = 0.0;
            p.cap_start_limit_mm_s = 0.0;
            p.raw_cap_start_mm_s = 0.0;
            p.kink_in = Vector3::zeros();
            p.low_cap = true;
            return None;
        }
        let prev = self.window.back_mut()?;
        let reach_mm = t_f * (acc * t_f + ((acc * t_f).powi(2) + limit_mm_s * limit_mm_s).sqrt());
        // Only where it pays: a clearly higher acceleration over most of the line.
        let splits = |q: &Pending| {
            q.limits.a_max_mm_s2() > SPLIT_ACC_GAIN * acc
                && reach_mm.is_finite()
                && reach_mm <= 0.5 * q.seg.length_mm
                && matches!(q.seg.path, SegmentPath::Line { .. })
                && !q.seg.aux.moves()
        };
        let (split_prev, split_p) = (splits(prev), splits(p));
        match split_prev
            .then(|| split_line(prev, prev.seg.length_mm - reach_mm))
            .flatten()
        {
            Some((head, mut tail)) => {
                *prev = head;
                tail.shared_acc_mm_s2 = shared;
                lower_acceleration(&mut tail, acc);
                tail.seq = self.next_seq;
                self.next_seq += 1;
                self.window.push_back(tail);
            }
            None => {
                prev.shared_acc_mm_s2 = shared;
                lower_acceleration(prev, acc);
            }
        }
        let rest = match split_p.then(|| split_line(p, reach_mm)).flatten() {
            Some((head, rest)) => {
                *p = head;
                Some(rest)
            }
            None => None,
        };
        p.shared_acc_mm_s2 = shared;
        lower_acceleration(p, acc);
        rest
    }

    /// The tangential acceleration the elements either side of the vertex from `a` into `b`,
    /// passed at speed (at most `v_mm_s`), may use in the jerk-limited mode. Along the curve
    /// the vertices approximate (their discrete curvature `κ̄`, averaged over this vertex and
    /// the one before, as [`Planner::smoothed_junction_limit_mm_s`] takes it), the normal jerk
    /// has a part `3·v·κ̄·a_t`, as on an arc ([`arc_limits`]): each axis's `3·v·|κ̄ᵢ|·a_t`
    /// is held within the jerk budget the elements leave it, shared in halves like the
    /// junction's other rules. Unbounded where the path does not turn.
    fn curve_acc_mm_s2(&self, a: &Pending, b: &Pending, v_mm_s: f64) -> f64 {
        if a.curve_fit.is_some() {
            // A chord run's curve: the elements' own limits hold it ([`curve`]).
            return f64::INFINITY;
        }
        let du = b.tangent_start - a.tangent_end;
        let kink_mean = 0.5 * (discrete_curvature(a, b) + a.kink_in);
        let l_mm = a.seg.length_mm.min(b.seg.length_mm);
        let mut acc = f64::INFINITY;
        for i in 0..3 {
            let k = kink_mean[i].abs().min(du[i].abs() / l_mm);
            if k > 0.0 && v_mm_s > 0.0 {
                let budget = 0.5
                    * (self.config.max_jerk_mm_s3[i]
                        - a.jerk_used_mm_s3[i].max(b.jerk_used_mm_s3[i]))
                    .max(0.0);
                acc = acc.min(budget / (3.0 * v_mm_s * k));
            }
        }
        acc
    }

    /// Highest speed through the junction from `a` into `b` (see the module documentation).
    fn junction_mm_s(&self, a: &Pending, b: &Pending) -> f64 {
        self.junction_caps(a, b).0
    }

    /// Highest speed through the junction from `a` into `b`: under the elements' feeds, and
    /// by the machine alone (the ceiling of an override above 100 %). The junction's own
    /// limits do not depend on the feed, so the first is the second under both elements'
    /// speed limits.
    fn junction_caps(&self, a: &Pending, b: &Pending) -> (f64, f64) {
        let raw = self.raw_junction_caps(a, b);
        self.dip_caps(a, b, raw)
    }

    /// [`junction_caps`](Self::junction_caps) before the time-law filter's dip.
    fn raw_junction_caps(&self, a: &Pending, b: &Pending) -> (f64, f64) {
        caps_under(self.junction_limit_mm_s(a, b), a, b)
    }

    /// How far the time-law filter rounds a V-shaped dip of the plan between elements of the
    /// accelerations `acc_a_mm_s2` and `acc_b_mm_s2`: `A·T_f/4` with the larger (0 without
    /// the filter). See [`Planner::dip_caps`].
    fn dip_depth_mm_s(&self, acc_a_mm_s2: f64, acc_b_mm_s2: f64) -> f64 {
        self.smoothing.map_or(0.0, |smoothing| {
            0.25 * acc_a_mm_s2.max(acc_b_mm_s2) * smoothing.time_law_s(self.config.period_s)
        })
    }

    /// The caps `(fed, limit)` lowered for the time-law filter's rounding of a dip.
    fn dip_caps(&self, a: &Pending, b: &Pending, (fed, limit): (f64, f64)) -> (f64, f64) {
        if self.smoothing.is_none() {
            return (fed, limit);
        }
        // The time-law filter rounds every dip of the speed: at a V-shaped dip to `c` with
        // the acceleration `A` either side, the filtered speed passes the dip's position at
        // `c + A·T_f/4`. So a cap below the speed of either neighbour is planned that much
        // lower, and one that leaves nothing is a stop, where the filter settles.
        let delta = self.dip_depth_mm_s(a.limits.a_max_mm_s2(), b.limits.a_max_mm_s2());
        let dip = |cap: f64, va: f64, vb: f64| {
            if cap < va.max(vb) {
                (cap - delta).max(0.0)
            } else {
                cap
            }
        };
        (
            dip(fed, a.limits.v_max_mm_s(), b.limits.v_max_mm_s()),
            dip(limit, a.v_limit_mm_s, b.v_limit_mm_s),
        )
    }

    /// The junction's own speed limit from its geometry and the axes' budgets (not the
    /// elements' speed limits).
    fn junction_limit_mm_s(&self, a: &Pending, b: &Pending) -> f64 {
        let cfg = &self.config;
        if cfg.corner_acc_mm_s2 == 0.0
            || matches!(a.blend, BlendMode::ExactStop | BlendMode::ExactPath)
        {
            return 0.0;
        }
        if let Some(smoothing) = self.smoothing {
            return self.smoothed_junction_limit_mm_s(a, b, &smoothing);
        }
        let t = cfg.period_s;
        let mut v = f64::INFINITY;
        let du = b.tangent_start - a.tangent_end;
        let du_norm = du.norm();
        if du_norm > 0.0 {
            v = v.min(t * cfg.corner_acc_mm_s2 / du_norm);
        }
        let dk = b.curvature_start - a.curvature_end;
        // Elements shorter than a period's travel put several junctions in one period: their
        // velocity changes add up within it (like the centripetal acceleration of the curve
        // they approximate, |Δu|/L being its curvature). Up to `1 + v·T/L` junctions fall
        // within one period, so each jump is held to the budget divided by that count; for
        // S-curves also v³·|Δuᵢ|·|Δu| ≤ L²·budget (the jerk v³κ² of that curve).
        let l_mm = a.seg.length_mm.min(b.seg.length_mm);
        let shared = |c: f64, d: f64| shared_jump_mm_s(c, d, t / l_mm);
        for i in 0..3 {
            let acc_budget =
                self.limits.max_acc_mm_s2[i] - a.acc_used_mm_s2[i].max(b.acc_used_mm_s2[i]);
            let d = du[i].abs();
            if d > 0.0 {
                v = v.min(shared(t * acc_budget, d));
            }
            if cfg.jerk_limited() {
                let jerk_budget = 0.5
                    * (cfg.max_jerk_mm_s3[i] - a.jerk_used_mm_s3[i].max(b.jerk_used_mm_s3[i]))
                        .max(0.0);
                if d > 0.0 {
                    v = v.min(shared(t * t * jerk_budget, d));
                    v = min_cbrt(v, l_mm * l_mm * jerk_budget / (d * du_norm));
                }
                let k = dk[i].abs();
                if k > 0.0 {
                    v = v.min((t * jerk_budget / k).sqrt());
                }
            }
        }
        v = v.min(aux_axes::junction_cap(cfg, a, b, t, cfg.jerk_limited()));
        v.max(0.0)
    }

    /// [`junction_limit_mm_s`](Self::junction_limit_mm_s) in the jerk-limited mode. The path
    /// is followed exactly up to the axis filters (two moving averages of `T_k` each), which
    /// turn a step `Δv` of an axis's velocity into a ramp: its acceleration reaches `Δv/T_k`
    /// and its jerk `Δv/T_k²`. So at speed `v` through a turn `Δu` of the tangent:
    ///
    /// - acceleration: `v·|Δuᵢ| ≤ T_k·(A_i − used_i)`, shared like the one-period rule among
    ///   the `1 + v·T_k/L` junctions of elements of length `L` within one filter time;
    /// - jerk: `v·|Δuᵢ| ≤ T_k²·(J_i − used_i)/2` (`T_k²·(J_i − used_i)` for a turn alone in
    ///   its filter time between two lines, as for a curvature step below). Junctions closer
    ///   than a filter time's travel add up: as the curve they approximate, whose own jerk
    ///   `v³·|Δuᵢ|·|Δu|/L² ≤ (J_i − used_i)/2` is bounded as the curvature of an arc is, and
    ///   through the change of the discrete curvature `Δu/L̄` from one vertex to the next,
    ///   held like a step of an arc's curvature;
    /// - a step of the curvature vector (an arc's end, or between vertices):
    ///   `v²·|Δκᵢ|·`[`PRECOMP_JERK`]` ≤ T_k·(J_i − used_i)/2`, or `T_k·(J_i − used_i)` where
    ///   the step is isolated: the tangent does not turn ([`ISOLATED_TURN`]) and both elements
    ///   last at least `2·T_k` at their top speed, so no other junction's step meets this one
    ///   in the filters' output, whose jerk is then the elements' own (within `used_i`) plus
    ///   this step's `v²·|Δκᵢ|/T_k`;
    /// - contour: the filters cut the corner by at most `v·|Δu|·2·T_k/8`, and where the
    ///   curvature steps they leave [`PRECOMP_STEP_RESIDUAL`] of an arc's pull,
    ///   `v²·|Δκ|·T_k²/12`, uncompensated; both are held within the tolerance
    ///   ([`Planner::filter_tolerance_mm`]). Along an arc the pull is pre-compensated.
    fn smoothed_junction_limit_mm_s(&self, a: &Pending, b: &Pending, smoothing: &Smoothing) -> f64 {
        if let Some(raw) = a.provisional {
            // Whether the motion passes `a`'s start vertex is not known yet: the rules must
            // hold either way.
            let (mut passed, mut stopped) = (*a, *a);
            passed.provisional = None;
            stopped.provisional = None;
            passed.kink_in = raw.kink;
            stopped.kink_in = Vector3::zeros();
            return self
                .smoothed_junction_limit_mm_s(&passed, b, smoothing)
                .min(self.smoothed_junction_limit_mm_s(&stopped, b, smoothing));
        }
        // A step alone in its filter time: both elements long enough that no other
        // junction's step reaches the filters' output while this one's does (`2·T_k` apart
        // in time). It then adds only to the elements' own jerk, and may take all the budget
        // they leave, not half of it (`alone` in [`Planner::junction_rules_mm_s`]). Long
        // enough at any speed they may run (`2·T_k` at their top speed, whatever blends may
        // still take of them); or only up to a speed `v_alone`: from the junction at most at
        // `v`, with at most `4·a` (the acceleration under a feed override up to 200 %),
        // the plan covers `L` no sooner than `2·T_k` where `L ≥ 2·T_k·v + 8·a·T_k²`. Only the
        // first counted until session 25: a polyline of 2 mm chords turning 4.5° each
        // (`sam-circle_lines.ngc`) was held to half the budget whatever its speed.
        let tk = smoothing.axis_s(self.config.period_s);
        let (a_mm, b_mm) = self.shortest_mm(a, b);
        if a_mm >= 2.0 * tk * a.v_limit_mm_s && b_mm >= 2.0 * tk * b.v_limit_mm_s {
            return self.junction_rules_mm_s(a, b, smoothing, true);
        }
        let v = self.junction_rules_mm_s(a, b, smoothing, false);
        let acc = a.limits.a_max_mm_s2().max(b.limits.a_max_mm_s2());
        let v_alone = (a_mm.min(b_mm) - 8.0 * acc * tk * tk) / (2.0 * tk);
        if v_alone > v {
            v.max(v_alone.min(self.junction_rules_mm_s(a, b, smoothing, true)))
        } else {
            v
        }
    }

    /// The rules of [`Planner::smoothed_junction_limit_mm_s`], with the junction's steps alone
    /// in their filter time (`alone`) or not.
    fn junction_rules_mm_s(
        &self,
        a: &Pending,
        b: &Pending,
        smoothing: &Smoothing,
        alone: bool,
    ) -> f64 {
        let cfg = &self.config;
        let tk = smoothing.axis_s(cfg.period_s);
        let mut v = f64::INFINITY;
        let du = b.tangent_start - a.tangent_end;
        let du_norm = du.norm();
        // On a chord run taken as a curve ([`curve`]) the elements' limits hold the curve's
        // centripetal acceleration and jerk: the vertex adds what it turns beyond the curve.
        let covered = a.curve_fit.is_some();
        let curve_turn = match a.curve_fit {
            Some(fit) => fit.curvature() * 0.5 * (a.seg.length_mm + b.seg.length_mm),
            None => Vector3::zeros(),
        };
        // Where it does, the axis filters' pull towards the curve's centre is pre-compensated
        // (`crate::interpolator::smooth`): the vertex cuts its corner by what it turns beyond.
        let cut_norm = (du - curve_turn).norm();
        if du_norm > 0.0 {
            v = v.min(tk * cfg.corner_acc_mm_s2 / du_norm);
            let tol_mm = self.filter_tolerance_mm(a.blend);
            if tol_mm > 0.0 {
                v = v.min(4.0 * tol_mm / (cut_norm * tk));
            }
        }
        let dk = b.curvature_start - a.curvature_end;
        let dk_norm = dk.norm();
        let tol_mm = self.filter_tolerance_mm(a.blend);
        if tol_mm > 0.0 && dk_norm > 0.0 {
            // Where the curvature steps, the pre-compensated filters still leave
            // `c·v²·|Δκ|·T_k²/12` of the pull they would take on a whole arc.
            v = v.min((12.0 * tol_mm / (PRECOMP_STEP_RESIDUAL * tk * tk * dk_norm)).sqrt());
        }
        // A polyline's curvature sits at its vertices: a change of it from one vertex to the
        // next is a step of the acceleration, as at an arc's end.
        let kink = discrete_curvature(a, b);
        let dk_vertex = kink - a.kink_in;
        // The curve the vertices approximate: its curvature averaged over this vertex and the
        // one before. Rounding of the written coordinates makes each vertex's own turn noisy;
        // the noise largely cancels between neighbours, the curve's turning does not.
        let kink_mean = 0.5 * (kink + a.kink_in);
        let kink_mean_norm = kink_mean.norm();
        let mean_mm = 0.5 * (a.seg.length_mm + b.seg.length_mm);
        let l_mm = a.seg.length_mm.min(b.seg.length_mm);
        // A step alone in its filter time, and only one kind of step here: a turn of the
        // tangent between elements of equal curvature (two lines), or a curvature step
        // without a turn ([`ISOLATED_TURN`]).
        let turn_alone = alone && dk_norm == 0.0;
        let curvature_alone = alone && du_norm <= ISOLATED_TURN;
        // The allowance below for the rounding of written vertices does not hold where they
        // were computed ([`refine`]): there a curvature that changes over a few short pieces,
        // each within the allowance, is the curve's own (it broke Z's jerk by up to 89 %).
        let exact = a.refined || b.refined;
        for i in 0..3 {
            let acc_budget =
                self.limits.max_acc_mm_s2[i] - a.acc_used_mm_s2[i].max(b.acc_used_mm_s2[i]);
            let jerk_budget = 0.5
                * (cfg.max_jerk_mm_s3[i] - a.jerk_used_mm_s3[i].max(b.jerk_used_mm_s3[i])).max(0.0);
            // A vertex moves the polyline off the smooth curve through its neighbours by about
            // `ε = |Δκ|·L̄²/8`; whatever the speed, the filtered setpoints then carry at most
            // `8ε/(T·T_k²)` of jerk from it (a third difference of two moving averages of a
            // deviation within ε), so a vertex within that bound charges nothing more. The
            // bound holds for half the budget: the deviations of a few vertices within one
            // filter span add up where they have the same sign (a bump of `3D_Chips`' Z over
            // chords of 16–95 µm took 102 % of its jerk at a 4 ms period with all of it).
            let noise_mm_s3 = |k: f64| k * mean_mm * mean_mm / (cfg.period_s * tk * tk);
            // On a chord run taken as a curve, the step the vertex adds to the curve's own.
            let d = (du[i] - curve_turn[i]).abs();
            if d > 0.0 {
                // The vertex's own velocity step and the centripetal acceleration of the curve
                // through it: `v·|Δuᵢ| + v²·κ̄ᵢ·T_k ≤ T_k·A_i` (never more than the sharing of
                // the one-period rule among the `1 + v·T_k/L` junctions within a filter time,
                // which takes `κ = |Δuᵢ|/L`).
                let k_curve = if covered {
                    0.0
                } else {
                    (tk * kink_mean[i].abs() / d).min(tk / l_mm)
                };
                v = v.min(shared_jump_mm_s(tk * acc_budget, d, k_curve));
                if exact || noise_mm_s3(d / mean_mm) > 0.5 * jerk_budget {
                    // A turn alone takes the whole budget, and then the jerk the contour
                    // pre-compensation adds to its step counts, as at a curvature step
                    // ([`PRECOMP_JERK`]: without it two lines of 24.5 and 37.1 mm turning by
                    // 1.2° at 123 mm/s broke Y's jerk by 1.3 % at 4 ms).
                    let (share, precomp) = if turn_alone {
                        (2.0, PRECOMP_JERK)
                    } else {
                        (1.0, 1.0)
                    };
                    let cap = tk * tk * share * jerk_budget / (precomp * d);
                    // A programmed arc's use of the axis at the junction's speed, as at a
                    // curvature step below (arcs meeting at a slight kink).
                    let holds = |v: f64, half: f64| precomp * v * d <= tk * tk * share * half;
                    v = v.min(self.cap_at_speed(a, b, i, cap, v, &holds, smoothing));
                }
            }
            // The jerk of following that curve, `v³·κ̄²·T`, lies along the tangent `T` (a
            // circle's axis `x = r·cos(v·t/r)` has `x''' = −(v/r)²·x'`): each axis takes
            // `v³·|κ̄|²·|Tᵢ| ≤ budget`, `|κ̄|` at most `|Δu|/L` (the vertex's own turn over the
            // shorter element), even where its own `Δuᵢ` is 0; and never less than
            // `v³·|κ̄ᵢ|·|κ̄|`, the part along the normal where the speed changes
            // ([`Planner::curve_acc_mm_s2`] bounds the rest).
            let k_n = kink_mean_norm.min(du_norm / l_mm);
            let t_i = a.tangent_end[i].abs().max(b.tangent_start[i].abs());
            let k_i = (k_n * t_i).max(kink_mean[i].abs().min(d / l_mm));
            if k_i > 0.0 && k_n > 0.0 && !covered {
                v = min_cbrt(v, jerk_budget / (k_i * k_n));
            }
            let k = dk[i].abs();
            if k > 0.0 {
                let step_budget = |half: f64| {
                    if curvature_alone {
                        isolated_step_budget(half, self.limits.max_feed_mm_s * d, tk)
                    } else {
                        half
                    }
                };
                let cap = (tk * step_budget(jerk_budget) / (PRECOMP_JERK * k)).sqrt();
                let holds = |v: f64, half: f64| PRECOMP_JERK * v * v * k <= tk * step_budget(half);
                v = v.min(self.cap_at_speed(a, b, i, cap, v, &holds, smoothing));
            }
            let k = dk_vertex[i].abs();
            if k > 0.0 && (exact || noise_mm_s3(k) > jerk_budget) {
                v = v.min((tk * jerk_budget / k).sqrt());
            }
        }
        v = v.min(aux_axes::junction_cap(cfg, a, b, tk, true));
        v.max(0.0)
    }

    /// A jerk rule of axis `i` ([`Planner::junction_rules_mm_s`]: a curvature step's, a
    /// turn's) with a programmed arc's use of the axis taken at the junction's speed rather
    /// than at its cap: `cap`, the rule with the elements' uses at their caps, raised as far as
    /// (at most) `ceiling` where `holds(v, half)`, `half` half of what the elements leave of
    /// the axis's jerk at `v` (the curvature step: `PRECOMP_JERK·v²·|Δκᵢ| ≤ T_k·budget`, the
    /// turn: `v·|Δuᵢ| ≤ T_k²·budget`, `budget` the step's share of it; `holds` must fail
    /// from some speed on, and keep failing above it).
    ///
    /// An arc's jerk along an axis is at most `(j_t + v³κ²)·|Tᵢ| + 3·v·κ·a_t·|Nᵢ|` (the
    /// tangential jerk, under the time-law filter within `2·a_t/T_f`, and the jerk of
    /// following the curve along the tangent; the normal part), `T` and `N` within the turn
    /// the arc makes within the axis filters' span either side of the junction. At its cap
    /// that is its whole budget (its split's parts add up to it in quadrature); at the lower
    /// speed a curvature step holds a junction to, the curve's part is far smaller, and the
    /// step may have what it leaves. A helix adds `v³κτ·|Bᵢ|` (its torsion, along the
    /// binormal). Lines and blend arcs keep their use at the cap, and so does every junction
    /// while a blend is chosen ([`Planner::steps_at_caps`]).
    #[allow(clippy::too_many_arguments)]
    fn cap_at_speed(
        &self,
        a: &Pending,
        b: &Pending,
        i: usize,
        cap: f64,
        ceiling: f64,
        holds: &dyn Fn(f64, f64) -> bool,
        smoothing: &Smoothing,
    ) -> f64 {
        let cfg = &self.config;
        let (tk, t_f) = (
            smoothing.axis_s(cfg.period_s),
            smoothing.time_law_s(cfg.period_s),
        );
        let used = |v: f64| {
            let a_use = arc_jerk_use_at(a, true, i, v, t_f, tk).unwrap_or(a.jerk_used_mm_s3[i]);
            let b_use = arc_jerk_use_at(b, false, i, v, t_f, tk).unwrap_or(b.jerk_used_mm_s3[i]);
            // Never more than at the caps (the arcs' parts add up to their budget there).
            a_use
                .max(b_use)
                .min(a.jerk_used_mm_s3[i].max(b.jerk_used_mm_s3[i]))
        };
        let arcs = arc_jerk_use_at(a, true, i, 0.0, t_f, tk).is_some()
            || arc_jerk_use_at(b, false, i, 0.0, t_f, tk).is_some();
        if !arcs || !ceiling.is_finite() || ceiling <= cap || self.steps_at_caps.get() {
            return cap;
        }
        let holds = |v: f64| holds(v, 0.5 * (cfg.max_jerk_mm_s3[i] - used(v)).max(0.0));
        let raised = if holds(ceiling) {
            ceiling
        } else if !holds(cap) {
            cap
        } else {
            let (mut lo, mut hi) = (cap, ceiling);
            // To the root itself, whatever the bracket: plans with different brackets around
            // one junction (another P's blends) must meet the same cap.
            for _ in 0..STEP_CAP_ITERATIONS {
                if hi - lo <= 1e-13 * hi {
                    break;
                }
                let mid = 0.5 * (lo + hi);
                if holds(mid) {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            lo
        };
        // A junction the dip made a stop stays one unless the plan would pass it clearly
        // faster than not at all: barely above the dip, the moves either side join the
        // time-law filter at the lower of their accelerations instead of running alone
        // (`arc_parabolic_blend.ngc`, a 0.25 mm full circle between two lines: 0.854 s →
        // 1.144 s passing at 0.11 mm/s).
        let delta = self.dip_depth_mm_s(a.limits.a_max_mm_s2(), b.limits.a_max_mm_s2());
        if cap <= delta && raised < (1.0 + STEP_CAP_MIN_PASS) * delta {
            return cap;
        }
        raised
    }

    /// The shortest `a` and `b`, either side of a junction, may still become: a line or an arc
    /// gives a corner's blend arc up to half of its programmed length, at `a`'s end and `b`'s start
    /// where the other is that arc (the junction's caps are computed before the line is
    /// shortened), and at `b`'s end where its tolerance may blend it.
    fn shortest_mm(&self, a: &Pending, b: &Pending) -> (f64, f64) {
        let trimmable = |p: &Pending| {
            !p.is_blend_arc && matches!(p.seg.path, SegmentPath::Line { .. } | SegmentPath::Arc(_))
        };
        let half = |p: &Pending, ends: usize| {
            if trimmable(p) {
                p.seg.length_mm - ends as f64 * 0.5 * p.full_length_mm
            } else {
                p.seg.length_mm
            }
        };
        let b_ends =
            usize::from(a.is_blend_arc) + usize::from(self.blend_tolerance_mm(b.blend) > 0.0);
        (half(a, usize::from(b.is_blend_arc)), half(b, b_ends))
    }

    /// The deviation from the path the axis filters may take under `blend`: half the G64 P
    /// tolerance (the corner blends take the other half), else `chord_tol_mm` (0: no limit).
    fn filter_tolerance_mm(&self, blend: BlendMode) -> f64 {
        match self.blend_tolerance_mm(blend) {
            p_mm if p_mm > 0.0 => 0.5 * p_mm,
            _ => self.config.chord_tol_mm,
        }
    }

    /// The G64 tolerance of a motion item ([`Planner::blend_tolerance_mm`]); 0 for anything
    /// else.
    fn item_tolerance_mm(&self, item: &Item) -> f64 {
        match item {
            Item::Motion(e) => self.blend_tolerance_mm(e.blend),
            _ => 0.0,
        }
    }

    /// The tolerance of a G64 corner: P, or for a bare G64 (P infinite, LinuxCNC's "no limit")
    /// `default_tolerance_mm` in the jerk-limited mode and 0 (an exact corner) otherwise; 0
    /// under G61 and G61.1.
    fn blend_tolerance_mm(&self, blend: BlendMode) -> f64 {
        match blend {
            BlendMode::Blend { p_mm, .. } if p_mm == f64::INFINITY && self.smoothing.is_some() => {
                self.config.default_tolerance_mm
            }
            BlendMode::Blend { p_mm, .. } if p_mm > 0.0 && p_mm.is_finite() => p_mm,
            _ => 0.0,
        }
    }

    /// The pending element of an arc (or a corner's blend arc) from `ends.0` to `ends.1`.
    #[allow(clippy::too_many_arguments)]
    fn arc_pending(
        &self,
        line: usize,
        rapid: bool,
        ends: (Vector3<f64>, Vector3<f64>),
        arc: ArcGeometry,
        feed_mm_s: f64,
        blend: BlendMode,
        aux: &AuxMove,
        programmed: bool,
    ) -> Result<Pending, PlanError> {
        let cfg = &self.config;
        let length_mm = arc.length_mm;
        if !(length_mm > 0.0 && length_mm <= profile::MAX_LENGTH_MM) {
            return Err(PlanError::Overflow { line });
        }
        let time_law_s = self.smoothing.map(|sm| sm.time_law_s(cfg.period_s));
        let mut a = arc_limits(
            &arc,
            feed_mm_s,
            &self.limits,
            cfg,
            ARC_SPLIT,
            programmed,
            time_law_s,
        );
        if programmed && let Some(smoothing) = self.smoothing {
            // A programmed arc long enough to run mostly at its cap takes more of the budget
            // for the curve and less for its tangential acceleration, where that is faster
            // from rest to rest (its ends' junction rules charge it its whole budget either
            // way, and its neighbours share its acceleration, as with any split).
            let t_f = smoothing.time_law_s(cfg.period_s);
            let v_ends = ARC_CRUISE_ENDS * a.v_max_mm_s;
            let time_s = |l: &ArcLimits| {
                let acc = l
                    .time_law_acc_mm_s2
                    .unwrap_or(l.acc_mm_s2.min(0.5 * l.jerk_mm_s3 * t_f));
                let (v, c) = (l.v_max_mm_s, v_ends.min(l.v_max_mm_s));
                let ramps_mm = (v * v - c * c) / acc;
                if length_mm >= ramps_mm {
                    (length_mm - ramps_mm) / v + 2.0 * (v - c) / acc
                } else {
                    2.0 * (((c * c + acc * length_mm).sqrt()) - c) / acc
                }
            };
            let mut best_s = time_s(&a) / ARC_CRUISE_GAIN;
            for split in ARC_CRUISE_SPLITS {
                let other = arc_limits(&arc, feed_mm_s, &self.limits, cfg, split, true, time_law_s);
                let t_s = time_s(&other);
                if t_s < best_s {
                    (a, best_s) = (other, t_s);
                }
            }
        }
        // The auxiliary axes follow the arc linearly in its length: no centripetal part.
        let aux_caps = aux_axes::caps(cfg, aux, length_mm);
        a.v_limit_mm_s = a.v_limit_mm_s.min(aux_caps.v_mm_s);
        a.v_max_mm_s = a.v_max_mm_s.min(aux_caps.v_mm_s);
        a.acc_mm_s2 = a.acc_mm_s2.min(aux_caps.acc_mm_s2);
        a.jerk_mm_s3 = a.jerk_mm_s3.min(aux_caps.jerk_mm_s3);
        // The time-law filter's plan: its acceleration, and the jerk `2·a/T_f` it makes.
        let (plan_acc_mm_s2, plan_jerk_mm_s3) =
            match (a.time_law_acc_mm_s2, time_law_s.filter(|_| !aux.moves())) {
                (Some(acc), Some(t_f)) => (acc, 2.0 * acc / t_f),
                _ => (a.acc_mm_s2, a.jerk_mm_s3),
            };
        let curvature = |s: f64| {
            let at = arc.point_at(s);
            let rel = at - arc.center_mm;
            let radial = rel - arc.normal * rel.dot(&arc.normal);
            let r = radial.norm();
            if r > 0.0 {
                -radial / (r * r)
            } else {
                Vector3::zeros()
            }
        };
        let (jerk_mm_s3, plan_jerk_mm_s3) = if cfg.jerk_limited() {
            (a.jerk_mm_s3, plan_jerk_mm_s3)
        } else {
            (f64::INFINITY, f64::INFINITY)
        };
        Ok(Pending {
            seg: moving(line, rapid, ends, SegmentPath::Arc(arc), length_mm),
            limits: profile_limits(
                cfg,
                self.smoothing,
                a.v_max_mm_s,
                plan_acc_mm_s2,
                plan_jerk_mm_s3,
                line,
            )?,
            blend,
            cap_start_mm_s: 0.0,
            cap_start_limit_mm_s: 0.0,
            v_limit_mm_s: a.v_limit_mm_s,
            full_length_mm: length_mm,
            tangent_start: arc.tangent_at(0.0),
            tangent_end: arc.tangent_at(1.0),
            curvature_start: curvature(0.0),
            curvature_end: curvature(1.0),
            aux_rate: aux_caps.rate,
            acc_used_mm_s2: a.axis_acc_mm_s2,
            jerk_used_mm_s3: if cfg.jerk_limited() {
                a.axis_jerk_mm_s3
            } else {
                Vector3::zeros()
            },
            alone: alone_limits(self.smoothing, a.v_max_mm_s, a.acc_mm_s2, jerk_mm_s3),
            kink_in: Vector3::zeros(),
            refined: false,
            provisional: None,
            seq: 0,
            low_cap: false,
            is_blend_arc: false,
            raw_cap_start_mm_s: 0.0,
            shared_acc_mm_s2: 0.0,
            curve_fit: None,
            curve_acc: None,
            reach_memo: None,
            pass_mark: None,
            acc_floor_mm_s2: f64::INFINITY,
            floor_reach_mm: 0.0,
            time_law_share: 1.0,
            lowered_run_mm: 0.0,
        })
        .map(|mut p| {
            p.shared_acc_mm_s2 = p.limits.a_max_mm_s2();
            p
        })
    }

    /// The pending element of `e` (`None` for a zero-length line).
    fn element(&self, e: &Element) -> Result<Option<Pending>, PlanError> {
        let line = e.line;
        let (limits, cfg) = (&self.limits, &self.config);
        if !e.end_mm.iter().all(|c| c.is_finite()) {
            return Err(PlanError::NonFiniteTarget { line });
        }
        if e.start_mm != self.position_mm || self.aux_pushed.is_some_and(|a| a != e.aux.start) {
            return Err(PlanError::Discontinuity { line });
        }
        // A move of the auxiliary axes alone: its path parameter is theirs (degrees for a
        // rotary-only move), so the X/Y/Z max feed means nothing there; their limits cap it.
        let aux_only = e.kind == ElementKind::Line && e.end_mm == e.start_mm;
        let max_feed = if aux_only {
            f64::INFINITY
        } else {
            limits.max_feed_mm_s
        };
        let feed_mm_s = if e.rapid {
            max_feed
        } else {
            match e.feed_mm_s {
                Some(f) if f > 0.0 && f.is_finite() => f.min(max_feed),
                other => {
                    return Err(PlanError::InvalidFeed {
                        line,
                        feed_mm_s: other,
                    });
                }
            }
        };
        let share = cfg.path_acc_share;
        let jerk = |budget: f64| {
            if cfg.jerk_limited() {
                budget
            } else {
                f64::INFINITY
            }
        };
        let mut p = match e.kind {
            ElementKind::Line => {
                let delta_mm = e.end_mm - self.position_mm;
                // Scaled norm: neither overflows for huge nor underflows for tiny moves.
                let scale_mm = delta_mm.amax();
                let (length_mm, direction) = if scale_mm == 0.0 {
                    match aux_axes::aux_only_length(&e.aux, line)? {
                        Some(length) => (length, aux_axes::NO_DIRECTION),
                        None => return Ok(None),
                    }
                } else {
                    if !scale_mm.is_finite() {
                        return Err(PlanError::Overflow { line });
                    }
                    let unit_scaled = delta_mm / scale_mm;
                    let norm_scaled = unit_scaled.norm();
                    let length_mm = scale_mm * norm_scaled;
                    if length_mm.is_nan() || length_mm > profile::MAX_LENGTH_MM {
                        return Err(PlanError::Overflow { line });
                    }
                    (length_mm, unit_scaled / norm_scaled)
                };
                let aux = aux_axes::caps(cfg, &e.aux, length_mm);
                let mut v_limit_mm_s = max_feed.min(aux.v_mm_s);
                let mut acc_mm_s2 = cfg.path_acc_mm_s2.min(aux.acc_mm_s2);
                let mut jerk_mm_s3 = aux.jerk_mm_s3;
                for i in 0..3 {
                    let u = direction[i].abs();
                    if u > 0.0 {
                        v_limit_mm_s = v_limit_mm_s.min(limits.max_vel_mm_s[i] / u);
                        acc_mm_s2 = acc_mm_s2.min(share * limits.max_acc_mm_s2[i] / u);
                        jerk_mm_s3 = jerk_mm_s3.min(share * cfg.max_jerk_mm_s3[i] / u);
                    }
                }
                let v_max_mm_s = v_limit_mm_s.min(feed_mm_s);
                let jerk_mm_s3 = jerk(jerk_mm_s3);
                let abs = direction.abs();
                Pending {
                    seg: moving(
                        line,
                        e.rapid,
                        (self.position_mm, e.end_mm),
                        SegmentPath::Line { direction },
                        length_mm,
                    ),
                    limits: profile_limits(
                        cfg,
                        self.smoothing,
                        v_max_mm_s,
                        acc_mm_s2,
                        jerk_mm_s3,
                        line,
                    )?,
                    blend: e.blend,
                    cap_start_mm_s: 0.0,
                    cap_start_limit_mm_s: 0.0,
                    v_limit_mm_s,
                    full_length_mm: length_mm,
                    tangent_start: direction,
                    tangent_end: direction,
                    curvature_start: Vector3::zeros(),
                    curvature_end: Vector3::zeros(),
                    aux_rate: aux.rate,
                    acc_used_mm_s2: abs * acc_mm_s2,
                    jerk_used_mm_s3: if cfg.jerk_limited() {
                        abs * jerk_mm_s3
                    } else {
                        Vector3::zeros()
                    },
                    alone: alone_limits(self.smoothing, v_max_mm_s, acc_mm_s2, jerk_mm_s3),
                    kink_in: Vector3::zeros(),
                    refined: false,
                    provisional: None,
                    seq: 0,
                    low_cap: false,
                    is_blend_arc: false,
                    raw_cap_start_mm_s: 0.0,
                    shared_acc_mm_s2: 0.0,
                    curve_fit: None,
                    curve_acc: None,
                    reach_memo: None,
                    pass_mark: None,
                    acc_floor_mm_s2: f64::INFINITY,
                    floor_reach_mm: 0.0,
                    time_law_share: 1.0,
                    lowered_run_mm: 0.0,
                }
            }
            ElementKind::Arc { .. } => {
                let arc = e.arc().ok_or(PlanError::InvalidArc { line })?;
                self.arc_pending(
                    line,
                    e.rapid,
                    (self.position_mm, e.end_mm),
                    arc,
                    feed_mm_s,
                    e.blend,
                    &e.aux,
                    true,
                )?
            }
        };
        p.seg.end_mm = e.end_mm;
        p.seg.aux = e.aux;
        p.shared_acc_mm_s2 = p.limits.a_max_mm_s2();
        Ok(Some(p))
    }
}

/// The backward pass's highest start speed from which an element of `length_mm` can end at
/// `v_end_mm_s`. For a trapezoid, [`profile::max_start_speed`]. A jerk-limited transition's
/// length `d(va, vb) = (va + vb)/2 · t(va − vb)` is not monotone in the lower speed (slowing a
/// little more can take less length), so a start speed found for one end speed could become
/// infeasible when a longer window raises that end speed; the pass uses instead the bound
/// `va · t(va − vb) ≥ d`, which decreases as `vb` rises: its largest `va` only grows with
/// `vb`, and every speed it allows is reachable.
///
/// The result is capped at `cap_mm_s` (the junction's speed): when the cap itself is within the
/// bound (or below `v_end_mm_s`), it is the result, without solving; this is the common case on
/// a path of tiny segments, whose junctions rather than their lengths bound the speed.
pub(super) fn start_reach_mm_s(
    length_mm: f64,
    v_end_mm_s: f64,
    cap_mm_s: f64,
    limits: &ProfileLimits,
) -> f64 {
    if limits.is_trapezoid() {
        return profile::max_start_speed(length_mm, v_end_mm_s, limits)
            .unwrap_or(0.0)
            .min(cap_mm_s);
    }
    if cap_mm_s <= v_end_mm_s {
        // The bound allows every speed up to `v_end_mm_s` at least.
        return cap_mm_s;
    }
    let a = limits.a_max_mm_s2();
    let j = match limits.shape() {
        JerkShape::Square => limits.j_max_mm_s3(),
        JerkShape::RaisedCosine => 0.5 * limits.j_max_mm_s3(),
    };
    let v_max = limits.v_max_mm_s();
    let transition_s = |dv: f64| {
        if dv >= a * a / j {
            dv / a + a / j
        } else {
            2.0 * (dv / j).sqrt()
        }
    };
    let fits = |va: f64| va * transition_s(va - v_end_mm_s) <= length_mm;
    // The speeds within the bound are an interval from `v_end_mm_s` up (as computed too: each
    // operation is monotone), so below, where `top` does not fit, every speed returned (one
    // that fits) is below `top`.
    let top = cap_mm_s.min(v_max);
    if fits(top) {
        return top;
    }
    // Closed form: with Δ = va − vb ≥ a²/j, va·(Δ/a + a/j) = L is a quadratic; below, with
    // 2·va·√(Δ/j) = L, the cubic va³ − vb·va² = L²j/4, solved by Newton from the right (the
    // cubic is convex there, so the iterates fall monotonically onto the root).
    let (vb, l) = (v_end_mm_s, length_mm);
    let c = a * a / j;
    // The regime of the root: the bound at Δ = a²/j, where both forms give t = 2a/j.
    let guess = if (vb + c) * (2.0 * a / j) <= l {
        let b = c - vb;
        0.5 * (-b + (b * b + 4.0 * a * l).sqrt())
    } else {
        // From the smaller of two upper bounds of the root: x²(x − vb) ≥ vb²·(x − vb) and
        // ≥ (x − vb)³ (`cbrt` only when the first is the larger).
        let k = 0.25 * l * l * j;
        let linear = k / (vb * vb);
        let mut x = vb
            + if linear * linear * linear <= k {
                linear
            } else {
                k.cbrt()
            };
        for _ in 0..12 {
            let f = x * x * (x - vb) - k;
            let df = x * (3.0 * x - 2.0 * vb);
            if df.is_nan() || df <= 0.0 {
                break;
            }
            let step = f / df;
            if step.is_nan() || step <= 0.0 {
                break;
            }
            x -= step;
            // Converged: the next step would be below rounding.
            if step <= 2.0 * f64::EPSILON * x {
                break;
            }
        }
        x
    };
    // The bound must hold as computed: step down a few ulps if the root's last bit is high.
    let mut va = guess.min(v_max).max(vb); // no panic even if vb > v_max or NaN
    for _ in 0..8 {
        if fits(va) {
            return va;
        }
        va = (va - va * 4.0 * f64::EPSILON).max(vb);
    }
    let (mut lo, mut hi) = (v_end_mm_s, v_max.min(guess.max(vb)));
    for _ in 0..64 {
        let mid = 0.5 * (lo + hi);
        if mid <= lo || mid >= hi {
            break;
        }
        if fits(mid) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    lo
}

/// The profile limits of an element, valid for [`profile`].
fn profile_limits(
    cfg: &PlannerConfig,
    smoothing: Option<Smoothing>,
    v_max_mm_s: f64,
    acc_mm_s2: f64,
    jerk_mm_s3: f64,
    line: usize,
) -> Result<ProfileLimits, PlanError> {
    // A speed or acceleration this low is a feed too small to run (the move would overflow).
    if !(v_max_mm_s >= profile::MIN_LIMIT && acc_mm_s2 >= profile::MIN_LIMIT) {
        return Err(PlanError::Overflow { line });
    }
    let clamp = |x: f64| x.clamp(profile::MIN_LIMIT, MAX_LIMIT);
    let (v, a) = (clamp(v_max_mm_s), clamp(acc_mm_s2));
    if let Some(smoothing) = smoothing {
        // Trapezoids under the time-law filter: its jerk is at most the range of the
        // acceleration over one filter time, `2·a/T_f`, held within the element's jerk.
        let a = a.min(clamp(0.5 * jerk_mm_s3 * smoothing.time_law_s(cfg.period_s)));
        return ProfileLimits::trapezoid(v, a).ok_or(PlanError::Overflow { line });
    }
    let limits = match cfg.profile {
        ProfileKind::Trapezoid => ProfileLimits::trapezoid(v, a),
        ProfileKind::SCurve => ProfileLimits::new(v, a, clamp(jerk_mm_s3), JerkShape::Square),
        ProfileKind::Smooth => ProfileLimits::new(v, a, clamp(jerk_mm_s3), JerkShape::RaisedCosine),
    };
    limits.ok_or(PlanError::Overflow { line })
}

/// The largest `v` with `v·d·(1 + v·k) ≤ c`: a velocity jump `v·d` shared among the
/// `1 + v·T/L` junctions of elements of length `L` that fall within a time `T` (`k = T/L`).
fn shared_jump_mm_s(c: f64, d: f64, k: f64) -> f64 {
    let c = c.max(0.0) / d;
    if k * c < 1e-12 {
        c
    } else {
        (2.0 * c) / (1.0 + (1.0 + 4.0 * k * c).sqrt())
    }
}

/// Most bisection steps of [`Planner::cap_at_speed`].
const STEP_CAP_ITERATIONS: usize = 64;

/// [`Planner::cap_at_speed`] turns a stop into a junction passed at speed only where its
/// dipped cap is at least this share of the dip's depth.
const STEP_CAP_MIN_PASS: f64 = 0.5;

/// A programmed arc's or helix's use of axis `i`'s jerk near its end (`at_end`) or start, at
/// the speed `v_mm_s` ([`Planner::cap_at_speed`]); `None` for anything else.
fn arc_jerk_use_at(
    p: &Pending,
    at_end: bool,
    i: usize,
    v_mm_s: f64,
    t_f: f64,
    tk: f64,
) -> Option<f64> {
    let SegmentPath::Arc(g) = p.seg.path else {
        return None;
    };
    if p.seg.aux.moves() || p.curve_fit.is_some() || p.is_blend_arc {
        return None;
    }
    let (t, kv) = if at_end {
        (p.tangent_end, p.curvature_end)
    } else {
        (p.tangent_start, p.curvature_start)
    };
    let kappa = kv.norm();
    if kappa <= 0.0 || kappa.is_nan() {
        return None;
    }
    let n = kv / kappa;
    // Within the filters' span either side the tangent and the normal turn by `2·v·T_k·κ`.
    let turn = (2.0 * v_mm_s * tk * kappa).min(1.0);
    let (t_i, n_i) = ((t[i].abs() + turn).min(1.0), (n[i].abs() + turn).min(1.0));
    // A helix's torsion `τ = sin α·cos α/r` adds `v³κτ` along the binormal; its curvature
    // `cos²α/r` is at most the projected circle's `1/r` taken here.
    let b_i = (t.cross(&n)[i].abs() + turn).min(1.0);
    let tau = g.helix_sin() * kappa;
    let (acc, v) = (p.limits.a_max_mm_s2(), v_mm_s);
    Some(
        (2.0 * acc / t_f + v * v * v * kappa * kappa) * t_i
            + 3.0 * v * kappa * acc * n_i
            + v * v * v * kappa * tau * b_i,
    )
}

/// The jerk budget of an isolated curvature step ([`ISOLATED_TURN`]): all that the elements
/// leave, `2·half_budget` (the rules of a junction each take half of it where several steps
/// may meet in the filters' output), less the jerk `v·|Δuᵢ|/T_k²` of the junction's tiny turn
/// at any speed up to the max feed (`jump_mm_s`: the max feed times `|Δuᵢ|`); never below
/// the half budget.
fn isolated_step_budget(half_budget: f64, jump_mm_s: f64, tk: f64) -> f64 {
    (2.0 * half_budget - jump_mm_s / (tk * tk)).max(half_budget)
}

/// The acceleration the middle of a long speed change of the filtered element `p` may run
/// at ([`Planner::split_for_acceleration`]): the whole of its move alone's, `min(A, J·T_f)`
/// with the time-law filter's length `t_f`; `None` for a line of a chord run, an element
/// that moves an auxiliary axis or has no move alone, and anything but a line or an arc.
fn split_acc_mm_s2(p: &Pending, t_f: f64) -> Option<f64> {
    if !matches!(p.seg.path, SegmentPath::Line { .. } | SegmentPath::Arc(_))
        || p.curve_acc.is_some()
        || p.seg.aux.moves()
    {
        return None;
    }
    let alone = p.alone?;
    Some(alone.a_max_mm_s2().min(alone.j_max_mm_s3() * t_f))
}

/// Under the time-law filter the acceleration of one element reaches the next through a
/// junction taken at speed (the filter's window spans it), so both plan with the lower of
/// their tangential accelerations.
fn share_acceleration(a: &mut Pending, b: &mut Pending) {
    let acc = a.shared_acc_mm_s2.min(b.shared_acc_mm_s2);
    for p in [a, b] {
        p.shared_acc_mm_s2 = acc;
        lower_acceleration(p, acc);
    }
}

/// Lowers `p`'s tangential acceleration to `acc_mm_s2` where it is higher.
fn lower_acceleration(p: &mut Pending, acc_mm_s2: f64) {
    if p.limits.a_max_mm_s2() > acc_mm_s2
        && let Some(lower) = ProfileLimits::trapezoid(p.limits.v_max_mm_s(), acc_mm_s2)
    {
        p.limits = lower;
    }
}

/// [`Planner::share_at_junction`] splits a line only where its own acceleration is above
/// this many times the lower one.
const SPLIT_ACC_GAIN: f64 = 1.2;

/// The shares of its tangential acceleration (and of the jerk the time-law filter makes of
/// it) a line joined at speed to a kinked vertex may plan with, leaving the rest of each
/// axis's jerk to the vertices ([`Planner::choose_kink_share`]).
const KINK_SHARES: [f64; 3] = [0.75, 0.5, 0.35];

/// A line takes a smaller share ([`KINK_SHARES`]) only where the estimate of its time is at
/// least this much shorter.
const KINK_SHARE_GAIN: f64 = 0.02;

/// The line `p` with the share `alpha` of its time-law acceleration (of its own limits,
/// `min(a, j·T_f/2)` from its move alone's) and of the jerk that makes of each axis, where
/// it plans with more; `None` if the limits do not come out.
fn with_time_law_share(p: &Pending, alpha: f64, t_f: f64) -> Option<Pending> {
    if p.time_law_share <= alpha {
        return Some(*p);
    }
    let own = p.alone?;
    let acc = alpha * own.a_max_mm_s2().min(0.5 * own.j_max_mm_s3() * t_f);
    let mut q = *p;
    q.limits = ProfileLimits::trapezoid(p.limits.v_max_mm_s(), acc.min(p.limits.a_max_mm_s2()))?;
    q.jerk_used_mm_s3 = p.jerk_used_mm_s3 * (alpha / p.time_law_share);
    q.shared_acc_mm_s2 = p.shared_acc_mm_s2.min(q.limits.a_max_mm_s2());
    q.time_law_share = alpha;
    Some(q)
}

/// Estimated time of the element `p` from a junction passed at `v0_mm_s` to one passed at
/// `v1_mm_s`, accelerating at its acceleration up to its top speed between them.
fn sawtooth_s(p: &Pending, v0_mm_s: f64, v1_mm_s: f64) -> f64 {
    let (length_mm, acc, v_max) = (
        p.full_length_mm,
        p.limits.a_max_mm_s2(),
        p.limits.v_max_mm_s(),
    );
    let (v0, v1) = (v0_mm_s.min(v_max), v1_mm_s.min(v_max));
    let peak = v_max.min((0.5 * (v0 * v0 + v1 * v1) + acc * length_mm).sqrt());
    let ramps_mm = (2.0 * peak * peak - v0 * v0 - v1 * v1) / (2.0 * acc);
    (2.0 * peak - v0 - v1) / acc + (length_mm - ramps_mm).max(0.0) / peak
}

/// Line `p` split `at_mm` from its start, into two lines that meet without a turn: the first
/// keeps `p`'s start and its junction, the second ends where `p` ends, bit for bit. Both keep
/// `p`'s limits and programmed length; the second starts with no kink, its junction capped by
/// those limits alone.
/// `None` for an arc or outside the line.
fn split_line(p: &Pending, at_mm: f64) -> Option<(Pending, Pending)> {
    let SegmentPath::Line { direction } = p.seg.path else {
        return None;
    };
    if !(at_mm > 0.0 && at_mm < p.seg.length_mm) {
        return None;
    }
    let at = p.seg.end_mm - direction * (p.seg.length_mm - at_mm);
    let (mut head, mut tail) = (*p, *p);
    head.seg.end_mm = at;
    head.seg.length_mm = at_mm;
    tail.seg.start_mm = at;
    tail.seg.length_mm = p.seg.length_mm - at_mm;
    tail.kink_in = Vector3::zeros();
    tail.curve_fit = None;
    tail.floor_reach_mm = 0.0;
    tail.provisional = None;
    tail.low_cap = false;
    tail.alone = p.alone;
    // The parts meet without a turn: the junction is capped by their speed limits alone.
    tail.cap_start_mm_s = p.limits.v_max_mm_s();
    tail.cap_start_limit_mm_s = p.v_limit_mm_s;
    tail.raw_cap_start_mm_s = tail.cap_start_mm_s;
    Some((head, tail))
}

/// A junction's caps `(fed, limit)` from its own limit `own_mm_s`: under both elements'
/// speed limits, with the programmed feeds and by the machine alone.
fn caps_under(own_mm_s: f64, a: &Pending, b: &Pending) -> (f64, f64) {
    let fed = own_mm_s
        .min(a.limits.v_max_mm_s())
        .min(b.limits.v_max_mm_s());
    let limit = own_mm_s.min(a.v_limit_mm_s).min(b.v_limit_mm_s);
    (fed, limit)
}

/// Caps an element of a plateau ([`Planner::finalize_junction`]) at `fed_mm_s` (and its
/// ceiling under a feed override at `limit_mm_s`).
#[inline]
fn cap_speed(p: &mut Pending, fed_mm_s: f64, limit_mm_s: f64) {
    if p.v_limit_mm_s > limit_mm_s {
        p.floor_reach_mm = 0.0;
    }
    if p.limits.v_max_mm_s() > fed_mm_s
        && let Some(lower) = ProfileLimits::trapezoid(fed_mm_s, p.limits.a_max_mm_s2())
    {
        p.limits = lower;
        curve::refresh_floor(p);
    }
    p.v_limit_mm_s = p.v_limit_mm_s.min(limit_mm_s);
    p.cap_start_mm_s = p.cap_start_mm_s.min(fed_mm_s);
    p.cap_start_limit_mm_s = p.cap_start_limit_mm_s.min(limit_mm_s);
    if let Some(alone) = p.alone
        && alone.v_max_mm_s() > fed_mm_s
    {
        p.alone = ProfileLimits::new(
            fed_mm_s,
            alone.a_max_mm_s2(),
            alone.j_max_mm_s3(),
            alone.shape(),
        );
    }
}

/// Relative margin by which `x` must exceed `v³` for [`min_cbrt`] to skip the cube root: far
/// above the roundings of `v·v·v` (3 ulps) and of `cbrt` (under 1 ulp).
const CBRT_SKIP_MARGIN: f64 = 1e-9;

/// `v.min(x.cbrt())`, bit for bit, without the cube root where it cannot be below `v`: where
/// `x` exceeds `v³` by [`CBRT_SKIP_MARGIN`] (`v` within `1e-30..=1e30`, so that `v³` is a
/// normal float), the root exceeds `v` by a third of that. The junction rules take the
/// minimum of many bounds, most of them far above the binding one; `cbrt` was 3.4 % of the
/// look-ahead's time on the tiny-segment benchmark.
#[inline]
pub(super) fn min_cbrt(v: f64, x: f64) -> f64 {
    if (1e-30..=1e30).contains(&v) && x > v * v * v * (1.0 + CBRT_SKIP_MARGIN) {
        return v;
    }
    v.min(x.cbrt())
}

/// Most taps of the axis filters' combined kernel the corner-cut estimate follows (two moving
/// averages of `N_k` samples: `2·N_k − 1` taps); longer filters are estimated from the first
/// ones, which over-estimates the cut (their later taps would weigh points nearer the corner).
const MAX_FILTER_TAPS: usize = 63;

/// How far the axis filters' output strays from the path where one move stops and the next
/// starts at once from the same point: the output is a weighted mean (the triangle kernel of
/// the two moving averages) of points `behind_mm[k]` before the corner on the first leg and
/// `ahead(k)` after it on the second; at each step its distance from the nearer leg is at most
/// `min(α·ā, (1 − α)·b̄)` times the sine of the turn (`α`, `ā`: the first leg's weight and
/// mean distance). The largest over the steps, without the sine.
fn corner_cut_mm(
    behind_mm: &[f64; MAX_FILTER_TAPS],
    ahead: impl Fn(usize) -> f64,
    smoothing: Smoothing,
) -> f64 {
    let n = smoothing.axis_periods.max(1);
    let taps = (2 * n - 1).min(MAX_FILTER_TAPS);
    // Weights of the triangle kernel: `min(k + 1, 2n − 1 − k)/n²`.
    let w = |k: usize| (k + 1).min(2 * n - 1 - k) as f64 / (n * n) as f64;
    let ahead_mm: Vec<f64> = (0..=taps).map(&ahead).collect();
    let mut worst: f64 = 0.0;
    // Output step `m`: tap `k` sees the input `m − k` samples after the corner (`< 0`: before).
    for m in 0..=taps {
        let (mut sa, mut sb) = (0.0, 0.0);
        for k in 0..taps {
            let at = m as isize - k as isize;
            if at < 0 {
                sa += w(k) * behind_mm[(-at - 1) as usize];
            } else {
                sb += w(k) * ahead_mm[at as usize];
            }
        }
        // α·ā = sa and (1 − α)·b̄ = sb (the weights sum to 1).
        worst = worst.max(sa.min(sb));
    }
    worst
}

/// Where the time-law filter's output stands behind the end of a filtered move that stops
/// (`profile`, the last element's), once that filter has settled (`N_f − 1` periods after
/// the plan stops): at each of the axis filters' last `2·N_k − 1` samples before then (index
/// `k`: `k + 1` periods before), the mean of the plan's distances behind its end over the
/// `N_f` samples the filter averages, each taken one period earlier than the sample's time on
/// the grid could be (a sample falls anywhere within its period of the end, and the distance
/// behind only grows backwards in time, so this over-estimates it and the corner cut of
/// [`corner_cut_mm`]). `None` where those samples reach back before the element's start.
fn filtered_stop_behind_mm(
    profile: &SpeedProfile,
    smoothing: Smoothing,
    period_s: f64,
) -> Option<[f64; MAX_FILTER_TAPS]> {
    let n_f = smoothing.time_law_periods.max(1);
    let taps = (2 * smoothing.axis_periods.max(1) - 1).min(MAX_FILTER_TAPS);
    let duration_s = profile.duration_s();
    if (taps + 1) as f64 * period_s > duration_s {
        return None;
    }
    // The plan's distance behind its end `m` periods before it stops (none at or after).
    let behind = |m: isize| {
        if m <= 0 {
            0.0
        } else {
            profile.length_mm() - profile.at(duration_s - m as f64 * period_s).s_mm
        }
    };
    let mut out = [0.0; MAX_FILTER_TAPS];
    for (k, d) in out.iter_mut().enumerate().take(taps) {
        // The sample `k + 1` periods before the filter settles averages the plan's samples
        // `k + 1 − (N_f − 1) + j` periods before its stop, `j < N_f`; one more for the grid.
        let sum: f64 = (0..n_f)
            .map(|j| behind((k + j + 2) as isize - n_f as isize))
            .sum();
        *d = sum / n_f as f64;
    }
    Some(out)
}

/// The discrete curvature `Δu/L̄` of the vertex from `a` into `b`: the turn of the tangent
/// over the mean length of the two elements.
fn discrete_curvature(a: &Pending, b: &Pending) -> Vector3<f64> {
    let mean_mm = 0.5 * (a.seg.length_mm + b.seg.length_mm);
    let du = b.tangent_start - a.tangent_end;
    if mean_mm > 0.0 && du.iter().all(|c| c.is_finite()) {
        du / mean_mm
    } else {
        Vector3::zeros()
    }
}

/// The rates `(D, J)` of the feed override's ramp of `k` (`|k'| ≤ D`, `|k''| ≤ J`) that keep
/// every axis within its limits on top of profiles using the share `s = path_acc_share` of
/// them (see [`crate::interpolator`] for the bounds): `D ≤ (1 − s)·A/V` and, with a jerk
/// limit, `D ≤ (1 − s)·Jₐ/(6·s·A)` and `J ≤ (1 − s)·Jₐ/(2·V)` for every axis (the
/// auxiliary axes the machine has included), `V = min(max_vel, max_feed)`. Without a jerk
/// limit `J` is `D` over four periods. `None` where `s = 1` leaves nothing.
pub fn override_ramp_rates(limits: &Limits, config: &PlannerConfig) -> Option<(f64, f64)> {
    let s = config.path_acc_share;
    let free = 1.0 - s;
    if free <= 0.0 || free.is_nan() {
        return None;
    }
    let jerk_limited = config.profile != ProfileKind::Trapezoid;
    let mut d = f64::INFINITY;
    let mut j = f64::INFINITY;
    let mut bound = |v: f64, a: f64, jerk: f64| {
        d = d.min(free * a / v);
        if jerk.is_finite() {
            if jerk_limited {
                d = d.min(free * jerk / (6.0 * s * a));
            }
            j = j.min(free * jerk / (2.0 * v));
        }
    };
    for i in 0..3 {
        let v = limits.max_vel_mm_s[i].min(limits.max_feed_mm_s);
        bound(v, limits.max_acc_mm_s2[i], config.max_jerk_mm_s3[i]);
    }
    // The auxiliary axes the machine has, likewise (their own speed bounds them).
    let aux = &config.aux;
    for i in 0..crate::gcode::AUX_LETTERS.len() {
        if aux.max_vel[i].is_finite() {
            bound(aux.max_vel[i], aux.max_acc[i], aux.max_jerk[i]);
        }
    }
    if !j.is_finite() {
        j = d / (4.0 * config.period_s);
    }
    Some((d, j))
}

/// Bisection steps of [`Planner::alone_at_axes`]'s search (the last step's share of the
/// difference, 2⁻⁸, is below half a percent of the axes' limits).
const ALONE_SEARCH_STEPS: usize = 8;

impl Planner {
    /// The limits a line run alone from rest to rest is planned with: `share`, the move's
    /// limits at `path_acc_share` of each axis's, raised towards the axes' whole limits as far
    /// as the feed override's ramp keeps its room. The share keeps the rest of each axis's
    /// budget for two things: the velocity steps of junctions passed at speed, which a move
    /// from rest to rest has none of (at each end it is at rest with no acceleration, so what
    /// runs before and after it never adds to its use of an axis, not even in the axis
    /// filters, whose moving averages keep the limits of what they average); and the ramp
    /// of `k` ([`override_ramp_rates`]), whose terms on top of a profile with the peak speed
    /// `v` and the peak acceleration `a` are at most `D·v` of acceleration and
    /// `3·D·a + J·v` of jerk along the path (with `k ≤ 1`; above 100 % `k` stays at 1 where
    /// a profile accelerates). So each axis keeps `|uᵢ|·(a + D·v) ≤ Aᵢ` and
    /// `|uᵢ|·(j + 3·D·a + J·v) ≤ Jᵢ` in every phase of the profile ([`alone_phases`]), the
    /// largest step towards the whole limits found by bisection (an arc's likewise with its curve's parts,
    /// [`arc_alone_at_axes`](Self::arc_alone_at_axes)). Moves of the auxiliary axes keep
    /// `share`.
    fn alone_at_axes(&self, p: &Pending, length_mm: f64, share: ProfileLimits) -> ProfileLimits {
        let Some(rates) = self.ramp_rates else {
            return share;
        };
        if p.seg.aux.moves() || share.is_trapezoid() {
            return share;
        }
        match p.seg.path {
            SegmentPath::Line { direction } => {
                self.line_alone_at_axes(direction, length_mm, share, rates)
            }
            SegmentPath::Arc(arc) => self.arc_alone_at_axes(&arc, length_mm, share, rates),
            _ => share,
        }
    }

    /// [`alone_at_axes`](Self::alone_at_axes) of a line along `direction`.
    fn line_alone_at_axes(
        &self,
        direction: Vector3<f64>,
        length_mm: f64,
        share: ProfileLimits,
        (d, jk): (f64, f64),
    ) -> ProfileLimits {
        let (acc, jerk) = (self.limits.max_acc_mm_s2, self.config.max_jerk_mm_s3);
        let (mut a_axes, mut j_axes) = (self.config.path_acc_mm_s2, f64::INFINITY);
        for i in 0..3 {
            let u = direction[i].abs();
            if u > 0.0 {
                a_axes = a_axes.min(acc[i] / u);
                j_axes = j_axes.min(jerk[i] / u);
            }
        }
        let (a0, j0) = (share.a_max_mm_s2(), share.j_max_mm_s3());
        let (da, dj) = ((a_axes - a0).max(0.0), (j_axes - j0).max(0.0));
        if !(da > 0.0 || dj > 0.0) {
            return share;
        }
        let at = |x: f64| {
            ProfileLimits::new(share.v_max_mm_s(), a0 + x * da, j0 + x * dj, share.shape())
        };
        let fits = |l: &ProfileLimits| {
            alone_phases(length_mm, l).is_some_and(|phases| {
                phases.iter().all(|&(v, a, j)| {
                    (0..3).all(|i| {
                        let u = direction[i].abs();
                        u * (a + d * v) <= acc[i] && u * (j + 3.0 * d * a + jk * v) <= jerk[i]
                    })
                })
            })
        };
        largest_fit(share, at, fits)
    }

    /// [`alone_at_axes`](Self::alone_at_axes) of an arc or a helix: its limits as
    /// [`arc_limits`] gives them with a larger `path_acc_share` (and the share's own where
    /// higher), kept where every axis's part of the centripetal acceleration `v²κ·|Nᵢ|`, of
    /// the jerk of following the curve (`v³κ²·|Tᵢ| + 3·v·κ·a·|Nᵢ| + v³κτ·|Bᵢ|`, each at the
    /// axis's largest share of the tangent, normal and binormal along the arc) and of the
    /// ramp's terms (`D·v·|Tᵢ|`; `3·D·(a·|Tᵢ| + v²κ·|Nᵢ|) + J·v·|Tᵢ|`) stays within its limits
    /// at the profile's peaks, all taken together.
    fn arc_alone_at_axes(
        &self,
        arc: &ArcGeometry,
        length_mm: f64,
        share: ProfileLimits,
        (d, jk): (f64, f64),
    ) -> ProfileLimits {
        let sin_a = arc.helix_sin();
        let cos_a = (1.0 - sin_a * sin_a).max(0.0).sqrt();
        let radius_mm = arc.start_radius_mm.min(arc.end_radius_mm);
        let kappa = cos_a * cos_a / radius_mm;
        let tau = sin_a * cos_a / radius_mm;
        // Each axis's share of the arc's plane (`pᵢ`) and of its axis (`nᵢ`), and its largest
        // share of the tangent along the arc.
        let (mut p_sh, mut n_sh, mut t_sh) = (Vector3::zeros(), Vector3::zeros(), Vector3::zeros());
        for i in 0..3 {
            n_sh[i] = arc.normal[i].abs().min(1.0);
            p_sh[i] = (1.0 - n_sh[i] * n_sh[i]).max(0.0).sqrt();
            t_sh[i] = (p_sh[i] * cos_a + n_sh[i] * sin_a).min(1.0);
        }
        let (acc, jerk) = (self.limits.max_acc_mm_s2, self.config.max_jerk_mm_s3);
        let s = self.config.path_acc_share;
        let feed = share.v_max_mm_s();
        // Towards the whole of the most loaded axis along the tangent, for the tangential
        // acceleration and jerk; the cap from the arc's limits at the larger share.
        let (mut a_tan, mut j_tan) = (self.config.path_acc_mm_s2, f64::INFINITY);
        for i in 0..3 {
            if t_sh[i] > 0.0 {
                a_tan = a_tan.min(acc[i] / t_sh[i]);
                j_tan = j_tan.min(jerk[i] / t_sh[i]);
            }
        }
        let (a0, j0) = (share.a_max_mm_s2(), share.j_max_mm_s3());
        let at = |x: f64| {
            let mut cfg = self.config;
            cfg.path_acc_share = s + x * (1.0 - s);
            let a = arc_limits(arc, feed, &self.limits, &cfg, ARC_SPLIT, true, None);
            ProfileLimits::new(
                a.v_max_mm_s.min(feed).max(share.v_max_mm_s()),
                (a0 + x * (a_tan - a0)).max(a0),
                (j0 + x * (j_tan - j0)).max(j0),
                share.shape(),
            )
        };
        let fits = |l: &ProfileLimits| {
            alone_phases(length_mm, l).is_some_and(|phases| {
                phases.iter().all(|&(v, a, j)| {
                    // The parts along the tangent, the (radial) normal and the binormal,
                    // each at its largest with the ramp's terms (`k ≤ 1`).
                    let acc_t = a + d * v;
                    let acc_n = v * v * kappa;
                    let jerk_t = j + v * v * v * kappa * kappa + 3.0 * d * a + jk * v;
                    let jerk_n = 3.0 * v * kappa * a + 3.0 * d * acc_n;
                    let jerk_b = v * v * v * kappa * tau;
                    // In the plane the tangent's part `cos α` (and the binormal's `sin α`)
                    // and the normal are at right angles: an axis sees at most `pᵢ` times
                    // their vector's length, and `nᵢ` times the part along the arc's axis.
                    let in_plane_acc = (cos_a * acc_t).hypot(acc_n);
                    let in_plane_jerk = (cos_a * jerk_t + sin_a * jerk_b).hypot(jerk_n);
                    (0..3).all(|i| {
                        let acc_i = p_sh[i] * in_plane_acc + n_sh[i] * sin_a * acc_t;
                        let jerk_i =
                            p_sh[i] * in_plane_jerk + n_sh[i] * (sin_a * jerk_t + cos_a * jerk_b);
                        acc_i <= acc[i] && jerk_i <= jerk[i]
                    })
                })
            })
        };
        largest_fit(share, at, fits)
    }
}

/// For each phase of the profile of a move of `length_mm` from rest to rest with `limits`:
/// its highest speed, its largest acceleration (magnitude) and its jerk (magnitude). Within a
/// phase the jerk is constant and the speed and the acceleration are monotone, so each is
/// largest at one of the phase's ends: a bound that increases with all three holds over the
/// phase where it holds for these.
fn alone_phases(length_mm: f64, limits: &ProfileLimits) -> Option<[(f64, f64, f64); 7]> {
    let profile = profile::plan(length_mm, 0.0, 0.0, limits)?;
    let t = profile.phase_start_times_s();
    let mut out = [(0.0, 0.0, 0.0); 7];
    for (k, phase) in out.iter_mut().enumerate() {
        let (start, end) = (profile.at(t[k]), profile.at(t[k + 1]));
        let mid = profile.at(0.5 * (t[k] + t[k + 1]));
        *phase = (
            start.v_mm_s.max(end.v_mm_s),
            start.a_mm_s2.abs().max(end.a_mm_s2.abs()),
            if t[k + 1] > t[k] {
                mid.j_mm_s3.abs()
            } else {
                0.0
            },
        );
    }
    Some(out)
}

/// The limits `at(x)` for the largest `x` in `[0, 1]` that `fits` finds (`at(1)` first, then
/// by bisection); `share` where none above 0 does.
fn largest_fit(
    share: ProfileLimits,
    at: impl Fn(f64) -> Option<ProfileLimits>,
    fits: impl Fn(&ProfileLimits) -> bool,
) -> ProfileLimits {
    if let Some(whole) = at(1.0).filter(&fits) {
        return whole;
    }
    let (mut lo, mut hi) = (0.0, 1.0);
    for _ in 0..ALONE_SEARCH_STEPS {
        let mid = 0.5 * (lo + hi);
        if at(mid).is_some_and(|l| fits(&l)) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    if lo > 0.0 {
        at(lo).unwrap_or(share)
    } else {
        share
    }
}

/// With smoothing, the S-curve limits of a move run alone from rest to rest (`None` where
/// they are not valid; the move is then filtered like the others).
fn alone_limits(
    smoothing: Option<Smoothing>,
    v_max_mm_s: f64,
    acc_mm_s2: f64,
    jerk_mm_s3: f64,
) -> Option<ProfileLimits> {
    smoothing?;
    let clamp = |x: f64| x.clamp(profile::MIN_LIMIT, MAX_LIMIT);
    ProfileLimits::new(
        clamp(v_max_mm_s),
        clamp(acc_mm_s2),
        clamp(jerk_mm_s3),
        JerkShape::Square,
    )
}

/// A moving segment's geometry, speeds not yet planned.
fn moving(
    line: usize,
    rapid: bool,
    (start_mm, end_mm): (Vector3<f64>, Vector3<f64>),
    path: SegmentPath,
    length_mm: f64,
) -> Segment {
    Segment {
        line,
        rapid,
        start_mm,
        end_mm,
        aux: AuxMove::default(),
        path,
        length_mm,
        v_start_mm_s: 0.0,
        v_peak_mm_s: 0.0,
        v_end_mm_s: 0.0,
        v_limit_mm_s: 0.0,
        v_start_limit_mm_s: 0.0,
        profile: None,
        hold_s: 0.0,
        start_time_s: 0.0,
        time_law: false,
        axis_filters: false,
    }
}

/// A segment without motion.
fn still(
    line: usize,
    at_mm: Vector3<f64>,
    path: SegmentPath,
    duration_s: f64,
    start_time_s: f64,
) -> Segment {
    Segment {
        line,
        rapid: false,
        start_mm: at_mm,
        end_mm: at_mm,
        aux: AuxMove::default(),
        path,
        length_mm: 0.0,
        v_start_mm_s: 0.0,
        v_peak_mm_s: 0.0,
        v_end_mm_s: 0.0,
        v_limit_mm_s: 0.0,
        v_start_limit_mm_s: 0.0,
        profile: None,
        hold_s: duration_s,
        start_time_s,
        time_law: false,
        axis_filters: false,
    }
}

/// Limits along an arc (see the module documentation).
struct ArcLimits {
    v_max_mm_s: f64,
    /// The same at the machine's max feed (whatever the feed asked for).
    v_limit_mm_s: f64,
    /// Path (tangential) acceleration.
    acc_mm_s2: f64,
    /// Path (tangential) jerk.
    jerk_mm_s3: f64,
    /// Largest acceleration and jerk of each axis on the arc.
    axis_acc_mm_s2: Vector3<f64>,
    axis_jerk_mm_s3: Vector3<f64>,
    /// Under the time-law filter, the plan's acceleration where the plane's axes allow more
    /// than `min(acc_mm_s2, jerk_mm_s3·T_f/2)` ([`arc_limits`]).
    time_law_acc_mm_s2: Option<f64>,
}

/// How an arc shares its jerk budget `J` in the jerk-limited mode: the tangential jerk
/// within `tangential·J`, the jerk of following the curve within `curve·J` (its cap), and
/// the normal part of the path acceleration, `3·v·κ·a_t`, within the rest in quadrature,
/// `√(1 − (tangential + curve)²)·J` (the normal is orthogonal to the tangent and binormal).
#[derive(Debug, Clone, Copy)]
struct ArcSplit {
    tangential: f64,
    curve: f64,
}

impl ArcSplit {
    fn normal(self) -> f64 {
        (1.0 - (self.tangential + self.curve).powi(2))
            .max(0.0)
            .sqrt()
    }
}

/// The split of every arc: `J/2` tangential, `J/4` for the curve, `√7/4` normal.
const ARC_SPLIT: ArcSplit = ArcSplit {
    tangential: 0.5,
    curve: 0.25,
};

/// The splits a programmed arc that runs mostly at its cap may take instead
/// ([`Planner::arc_pending`]): a larger share for the curve (a cap `1.22` and `1.34` times
/// higher) for a smaller tangential acceleration (`0.8` and `0.5` times).
const ARC_CRUISE_SPLITS: [ArcSplit; 2] = [
    ArcSplit {
        tangential: 0.4,
        curve: 0.45,
    },
    ArcSplit {
        tangential: 0.25,
        curve: 0.6,
    },
];

/// A programmed arc takes another split where that shortens its estimated time by this
/// factor at least: from and to `ARC_CRUISE_ENDS` times its cap with [`ARC_SPLIT`].
const ARC_CRUISE_GAIN: f64 = 1.05;
const ARC_CRUISE_ENDS: f64 = 0.5;

/// Limits along an arc (see the module documentation) with the jerk budget shared as `split`;
/// `from_axes`: the tangential acceleration and jerk may be what the axes leave beside the
/// curve's parts where that is more (programmed arcs; a blend arc keeps the split, which the
/// estimate of its corner's time is made for: with it, `blends_do_not_slow_a_program` found
/// a `G64 P0.1` 0.004 % slower than the exact corners).
fn arc_limits(
    arc: &ArcGeometry,
    feed_mm_s: f64,
    limits: &Limits,
    cfg: &PlannerConfig,
    split: ArcSplit,
    from_axes: bool,
    time_law_s: Option<f64>,
) -> ArcLimits {
    let sin_a = arc.helix_sin();
    let cos_a = (1.0 - sin_a * sin_a).max(0.0).sqrt();
    let share = cfg.path_acc_share;
    let mut v_max_mm_s = limits.max_feed_mm_s;
    let mut acc_budget_mm_s2 = f64::INFINITY;
    let mut jerk_budget_mm_s3 = f64::INFINITY;
    let mut acc_share = Vector3::zeros();
    let mut jerk_share = Vector3::zeros();
    // Each axis's largest share of the tangent and of the (radial, in-plane) normal.
    let mut tangent_share = Vector3::zeros();
    let mut normal_share = Vector3::zeros();
    let mut binormal_share = Vector3::zeros();
    for i in 0..3 {
        let n_i = arc.normal[i].abs().min(1.0);
        let p_i = (1.0 - n_i * n_i).max(0.0).sqrt();
        tangent_share[i] = (p_i * cos_a + n_i * sin_a).min(1.0);
        normal_share[i] = p_i;
        binormal_share[i] = (p_i * sin_a + n_i * cos_a).min(1.0);
        let speed_share = (p_i * cos_a + n_i * sin_a).min(1.0);
        if speed_share > 0.0 {
            v_max_mm_s = v_max_mm_s.min(limits.max_vel_mm_s[i] / speed_share);
        }
        acc_share[i] = (p_i + n_i * sin_a).min(1.0);
        // Along the helix axis, the jerk of a helix has three parts: the tangential jerk's
        // share `sin α`, and from following the curve (whose jerk is `v³·κ·√(κ² + τ²)` at
        // constant speed) the normal part `v³κ²·T` and the binormal (torsion) part
        // `v³κτ·B`, each `sin α·cos α` of it along the axis. A plane arc (α = 0) has none.
        jerk_share[i] = (p_i + n_i * (2.0 * sin_a).min(1.0)).min(1.0);
        if acc_share[i] > 0.0 {
            acc_budget_mm_s2 = acc_budget_mm_s2.min(share * limits.max_acc_mm_s2[i] / acc_share[i]);
        }
        if jerk_share[i] > 0.0 {
            jerk_budget_mm_s3 =
                jerk_budget_mm_s3.min(share * cfg.max_jerk_mm_s3[i] / jerk_share[i]);
        }
    }
    // A helix of radius r and helix angle α (pitch c = r·tan α per radian) has the curvature
    // κ = r/(r² + c²) = cos²α/r and the torsion τ = sin α·cos α/r: its path speed v moves the
    // point round the axis at the angular speed v·cos α/r. Its limits therefore take κ, not
    // the 1/r of its projected circle (for a plane arc, α = 0, they are the same):
    // - centripetal: v²·κ ≤ A·√3/2;
    // - chord: one period's step covers the angle v·T·cos α/r, and the chord of a helix bows
    //   only radially (its axial part is linear in the angle on both), so the in-plane rule
    //   holds for v·cos α: v ≤ 2·√(2rε − ε²)/(T·cos α);
    // - jerk: the jerk is (j_t − v³κ²)·T + 3·v·κ·a_t·N + v³κτ·B (Frenet). At constant speed
    //   the acceleration v²κ·N turns with N, whose rate is v·√(κ² + τ²) = v·cos α/r, so the
    //   jerk of following the curve is v³·κ·cos α/r = v³·cos³α/r² ≤ J/4. With |j_t| ≤ J/2
    //   the parts along T and B together stay within 3J/4, and the part along N, orthogonal
    //   to both, may take the rest of J in quadrature: 3·v·κ·a_t ≤ (√7/4)·J, so
    //   a_t ≤ √7·J·r/(12·v·cos²α). N is radial, so the helix axis sees none of it.
    let radius_mm = arc.start_radius_mm.min(arc.end_radius_mm);
    let curvature_per_mm = cos_a * cos_a / radius_mm;
    let centripetal_mm_s2 = acc_budget_mm_s2 * (0.75f64).sqrt();
    v_max_mm_s = v_max_mm_s.min((centripetal_mm_s2 / curvature_per_mm).sqrt());
    let eps = cfg.chord_tol_mm;
    if eps > 0.0 && eps < radius_mm {
        v_max_mm_s = v_max_mm_s
            .min(2.0 * (2.0 * radius_mm * eps - eps * eps).sqrt() / (cfg.period_s * cos_a));
    }
    if cfg.jerk_limited() {
        // v³·cos³α/r² ≤ J/4 (and 3·v·κ·a_t ≤ (√7/4)·J below), or the split's shares.
        v_max_mm_s = v_max_mm_s
            .min((split.curve * jerk_budget_mm_s3 * radius_mm * radius_mm).cbrt() / cos_a);
    }
    // The two axis filters of the jerk-limited mode would pull the circle in by about
    // `2·v²·T_k²/(24·κ⁻¹)`; the interpolator's contour pre-compensation
    // (`crate::interpolator::smooth`) moves their input out by exactly that, so the arc itself
    // has no speed limit from them (its ends have one, `Planner::smoothed_junction_limit_mm_s`).
    let v_limit_mm_s = v_max_mm_s;
    let v_max_mm_s = v_max_mm_s.min(feed_mm_s);
    // The tangential acceleration: half the budget (LinuxCNC's tangential ratio), leaving the
    // centripetal part `A·√3/2` in quadrature; or, where more, what each axis leaves of its
    // share beside the centripetal acceleration at the element's top speed, `a_t·|Tᵢ| +
    // v²κ·|Nᵢ| ≤ s·Aᵢ` (a steep helix moves its plane's axes by `cos α` of its path only: a
    // G2 of 0.86 mm radius rising 85 mm, LinuxCNC's `sam_violation1.ngc`, may accelerate
    // along its axis as a line does, not at half the plane axes' budget).
    let a_n_mm_s2 = v_max_mm_s * v_max_mm_s * curvature_per_mm;
    let mut by_axes_mm_s2 = f64::INFINITY;
    for i in 0..3 {
        if tangent_share[i] > 0.0 {
            let left = share * limits.max_acc_mm_s2[i] - a_n_mm_s2 * normal_share[i];
            by_axes_mm_s2 = by_axes_mm_s2.min(left.max(0.0) / tangent_share[i]);
        }
    }
    let acc_from_axes = from_axes && by_axes_mm_s2 > 0.5 * acc_budget_mm_s2;
    let mut acc_mm_s2 = if acc_from_axes {
        by_axes_mm_s2
    } else {
        0.5 * acc_budget_mm_s2
    }
    .min(cfg.path_acc_mm_s2);
    let mut jerk_mm_s3 = split.tangential * jerk_budget_mm_s3;
    // As the acceleration: where more, the tangential jerk each axis leaves beside the
    // curve's parts at the top speed, `j_t·|Tᵢ| + v³κ²·|Tᵢ| + 3·v·κ·a_t·|Nᵢ| + v³κτ·|Bᵢ| ≤
    // s·Jᵢ` (the binormal's share `sin α` in the plane, `cos α` along the axis).
    let mut axis_jerk_mm_s3 = jerk_share * jerk_budget_mm_s3;
    let mut time_law_acc_mm_s2 = None;
    if cfg.jerk_limited() {
        if v_max_mm_s > 0.0 {
            acc_mm_s2 = acc_mm_s2
                .min(split.normal() * jerk_budget_mm_s3 / (3.0 * v_max_mm_s * curvature_per_mm));
        }
        let v = v_max_mm_s;
        let curve = v * v * v * curvature_per_mm * curvature_per_mm;
        let normal = 3.0 * v * curvature_per_mm * acc_mm_s2;
        let torsion = v * v * v * curvature_per_mm * sin_a * cos_a / radius_mm;
        let parts = tangent_share * curve + normal_share * normal + binormal_share * torsion;
        let mut by_axes_mm_s3 = f64::INFINITY;
        for i in 0..3 {
            if tangent_share[i] > 0.0 {
                let left = share * cfg.max_jerk_mm_s3[i] - parts[i];
                by_axes_mm_s3 = by_axes_mm_s3.min(left.max(0.0) / tangent_share[i]);
            }
        }
        if from_axes && by_axes_mm_s3 > jerk_mm_s3 {
            jerk_mm_s3 = by_axes_mm_s3;
            axis_jerk_mm_s3 = axis_jerk_mm_s3.sup(&(tangent_share * jerk_mm_s3 + parts));
        }
        // A plane arc under the time-law filter: its plan's acceleration `a` comes out as the
        // tangential acceleration `a_t ≤ a` and jerk `j_t ≤ 2·a/T_f`, and an axis of the
        // plane moves along `T` and `N` by `(cos φ, sin φ)` (its share `pᵢ` of the plane), so
        // it sees the jerk `(j_t − v³κ²)·cos φ + 3·v·κ·a_t·sin φ`, at most
        // `pᵢ·√((2·a/T_f + v³κ²)² + (3·v·κ·a)²)`, and the acceleration at most
        // `pᵢ·√(a² + (v²κ)²)`: the largest `a` within `s·Jᵢ` and `s·Aᵢ` there, at the top
        // speed (both grow with `v`), where more than the split's or the sum's above.
        if let Some(t_f) = time_law_s.filter(|_| from_axes && sin_a == 0.0 && v > 0.0) {
            let k = curvature_per_mm;
            let a_n = v * v * k;
            let (alpha, beta) = (2.0 / t_f, 3.0 * v * k);
            let mut a_q = cfg.path_acc_mm_s2;
            for i in 0..3 {
                let p_i = normal_share[i];
                if p_i > 0.0 {
                    let j_i = share * cfg.max_jerk_mm_s3[i] / p_i;
                    let acc_i = share * limits.max_acc_mm_s2[i] / p_i;
                    // `(α·a + c)² + (β·a)² ≤ j²`: its positive root.
                    let qa = alpha * alpha + beta * beta;
                    let qb = 2.0 * alpha * curve;
                    let qc = curve * curve - j_i * j_i;
                    let root = if qc < 0.0 {
                        (-qb + (qb * qb - 4.0 * qa * qc).sqrt()) / (2.0 * qa)
                    } else {
                        0.0
                    };
                    a_q = a_q
                        .min(root)
                        .min((acc_i * acc_i - a_n * a_n).max(0.0).sqrt());
                }
            }
            // Each axis's use stays within what `axis_acc_mm_s2` and `axis_jerk_mm_s3` below
            // report for the plane (`s·Aᵢ`, `s·Jᵢ` of the most loaded axis); a move alone keeps
            // the split's limits, its profile's acceleration not filtered.
            if a_q > acc_mm_s2.min(0.5 * jerk_mm_s3 * t_f) {
                time_law_acc_mm_s2 = Some(a_q);
            }
        }
    } else {
        jerk_mm_s3 = f64::INFINITY;
    }
    ArcLimits {
        v_max_mm_s,
        v_limit_mm_s,
        acc_mm_s2,
        jerk_mm_s3,
        axis_acc_mm_s2: if acc_from_axes {
            (acc_share * acc_budget_mm_s2)
                .sup(&(tangent_share * acc_mm_s2 + normal_share * a_n_mm_s2))
        } else {
            acc_share * acc_budget_mm_s2
        },
        axis_jerk_mm_s3,
        time_law_acc_mm_s2,
    }
}

#[cfg(test)]
pub(crate) mod tests {

    /// The trapezoid of a moving segment: its phases and its acceleration.
    struct Parts {
        accel_mm_s2: f64,
        t_acc_s: f64,
        t_cruise_s: f64,
        t_dec_s: f64,
        is_triangle: bool,
    }

    fn parts(s: &Segment) -> Parts {
        let p = s.profile.expect("a moving segment");
        assert!(p.limits().is_trapezoid());
        let ph = p.phase_durations_s();
        Parts {
            accel_mm_s2: p.limits().a_max_mm_s2(),
            t_acc_s: ph[0] + ph[1] + ph[2],
            t_cruise_s: ph[3],
            t_dec_s: ph[4] + ph[5] + ph[6],
            is_triangle: ph[3] == 0.0,
        }
    }
    use super::*;
    use crate::gcode::{BlendMode, CompState, Plane, parse_program};
    use crate::gcode::{Element, ElementKind, Item};

    /// A straight move as the old G0/G1 front end gave it: a target, the start implied.
    #[derive(Debug, Clone, Copy)]
    pub(crate) struct Move {
        pub(crate) line: usize,
        pub(crate) rapid: bool,
        pub(crate) target_mm: Vector3<f64>,
        pub(crate) feed_mm_s: Option<f64>,
    }

    /// Plans straight moves from `start_mm`, each starting where the previous one ended.
    pub(crate) fn plan_moves(
        start_mm: Vector3<f64>,
        moves: &[Move],
        limits: &Limits,
    ) -> Result<Plan, PlanError> {
        let mut from = start_mm;
        let items: Vec<Item> = moves
            .iter()
            .map(|m| {
                let e = Element {
                    line: m.line,
                    col: 1,
                    kind: ElementKind::Line,
                    rapid: m.rapid,
                    start_mm: from,
                    end_mm: m.target_mm,
                    aux: Default::default(),
                    feed_mm_s: m.feed_mm_s,
                    blend: BlendMode::ExactStop,
                    comp: CompState::Off,
                    plane: Plane::Xy,
                };
                from = m.target_mm;
                Item::Motion(e)
            })
            .collect();
        plan_items(start_mm, &items, limits)
    }

    pub(crate) fn v(x: f64, y: f64, z: f64) -> Vector3<f64> {
        Vector3::new(x, y, z)
    }

    fn limits() -> Limits {
        Limits {
            max_vel_mm_s: v(100.0, 50.0, 20.0),
            max_acc_mm_s2: v(1000.0, 500.0, 200.0),
            max_feed_mm_s: 80.0,
        }
    }

    pub(crate) fn feed(line: usize, target_mm: Vector3<f64>, feed_mm_s: f64) -> Move {
        Move {
            line,
            rapid: false,
            target_mm,
            feed_mm_s: Some(feed_mm_s),
        }
    }

    fn rapid(line: usize, target_mm: Vector3<f64>) -> Move {
        Move {
            line,
            rapid: true,
            target_mm,
            feed_mm_s: None,
        }
    }

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() <= 1e-12 * a.abs().max(b.abs()).max(1.0)
    }

    #[test]
    fn trapezoid_along_x() {
        // 100 mm at 40 mm/s, 1000 mm/s²: ramps 0.04 s over 0.8 mm each, cruise 98.4 mm.
        let p = plan_moves(
            Vector3::zeros(),
            &[feed(1, v(100.0, 0.0, 0.0), 40.0)],
            &limits(),
        )
        .unwrap();
        let s = p.segments()[0];
        assert!(!parts(&s).is_triangle);
        assert_eq!(s.v_peak_mm_s, 40.0);
        assert_eq!(parts(&s).accel_mm_s2, 1000.0);
        assert!(close(parts(&s).t_acc_s, 0.04) && close(parts(&s).t_dec_s, 0.04));
        assert!(close(parts(&s).t_cruise_s, 98.4 / 40.0));
        // Duration of a trapezoid from rest to rest: L/v + v/a.
        assert!(close(p.duration_s(), 100.0 / 40.0 + 40.0 / 1000.0));
        assert!(close(s.distance_at(0.04), 0.8));
        assert!(close(p.position_at(0.04)[0], 0.8));
        assert!(close(p.position_at(p.duration_s() - 0.04)[0], 99.2));
        assert!(close(p.position_at(p.duration_s() / 2.0)[0], 50.0));
        assert_eq!(p.position_at(p.duration_s()), v(100.0, 0.0, 0.0));
        assert_eq!(p.position_at(1e9), v(100.0, 0.0, 0.0));
        assert_eq!(p.position_at(-1.0), Vector3::zeros());
        assert_eq!(p.position_at(f64::NAN), Vector3::zeros());
    }

    #[test]
    fn triangle_for_a_short_move() {
        // 0.4 mm at 1000 mm/s²: v² / a = 1.6 > 0.4, so the apex is sqrt(a L) = 20 mm/s.
        let p = plan_moves(
            Vector3::zeros(),
            &[feed(1, v(0.4, 0.0, 0.0), 40.0)],
            &limits(),
        )
        .unwrap();
        let s = p.segments()[0];
        assert!(parts(&s).is_triangle);
        assert!(close(s.v_peak_mm_s, 20.0));
        assert!(close(parts(&s).t_acc_s, 0.02) && close(parts(&s).t_dec_s, 0.02));
        // Duration of a triangle: 2 sqrt(L / a).
        assert!(close(p.duration_s(), 2.0 * (0.4f64 / 1000.0).sqrt()));
        assert!(close(p.position_at(0.02)[0], 0.2));
        assert!(close(s.speed_at(0.02), 20.0));
    }

    #[test]
    fn pure_y_move_is_limited_by_y() {
        // Rapid (max feed 80) but Y allows only 50 mm/s and 500 mm/s².
        let p = plan_moves(v(1.0, 2.0, 3.0), &[rapid(7, v(1.0, 102.0, 3.0))], &limits()).unwrap();
        let s = p.segments()[0];
        assert_eq!(s.line, 7);
        assert!(s.rapid);
        assert_eq!(s.v_peak_mm_s, 50.0);
        assert_eq!(parts(&s).accel_mm_s2, 500.0);
        assert!(close(p.duration_s(), 100.0 / 50.0 + 50.0 / 500.0));
        // X and Z do not move at all, bit for bit.
        for k in 0..=100 {
            let q = p.position_at(p.duration_s() * f64::from(k) / 100.0);
            assert_eq!((q[0], q[2]), (1.0, 3.0));
        }
    }

    #[test]
    fn diagonal_move_is_limited_by_the_tighter_axis() {
        // 45° in XY: |u_x| = |u_y| = 1/√2. Y is tighter: v ≤ 50 √2 ≈ 70.7 < 80, a ≤ 500 √2.
        let p = plan_moves(
            Vector3::zeros(),
            &[rapid(1, v(100.0, 100.0, 0.0))],
            &limits(),
        )
        .unwrap();
        let s = p.segments()[0];
        let sqrt2 = 2f64.sqrt();
        assert!(close(s.v_peak_mm_s, 50.0 * sqrt2));
        assert!(close(parts(&s).accel_mm_s2, 500.0 * sqrt2));
        assert!(close(s.length_mm, 100.0 * sqrt2));
        // Y runs exactly at its limits, X at half of its own.
        assert!(close(s.v_peak_mm_s * s.direction().unwrap()[1], 50.0));
        assert!(close(
            parts(&s).accel_mm_s2 * s.direction().unwrap()[1],
            500.0
        ));
        let hand_s = (100.0 * sqrt2) / (50.0 * sqrt2) + (50.0 * sqrt2) / (500.0 * sqrt2);
        assert!(close(p.duration_s(), hand_s));

        // A feed below every axis limit wins.
        let p = plan_moves(
            Vector3::zeros(),
            &[feed(1, v(3.0, 4.0, 0.0), 10.0)],
            &limits(),
        )
        .unwrap();
        let s = p.segments()[0];
        assert_eq!(s.v_peak_mm_s, 10.0);
        // u = (0.6, 0.8): a = min(1000/0.6, 500/0.8) = 625.
        assert!(close(parts(&s).accel_mm_s2, 625.0));
        assert!(close(p.duration_s(), 5.0 / 10.0 + 10.0 / 625.0));
    }

    #[test]
    fn feed_is_clamped_to_max_feed() {
        let p = plan_moves(
            Vector3::zeros(),
            &[feed(1, v(10.0, 0.0, 0.0), 1e6)],
            &limits(),
        )
        .unwrap();
        assert_eq!(p.segments()[0].v_peak_mm_s, 80.0);
    }

    #[test]
    fn segments_chain_and_zero_length_moves_are_skipped() {
        let moves = [
            feed(1, v(10.0, 0.0, 0.0), 20.0),
            feed(2, v(10.0, 0.0, 0.0), 20.0),
            rapid(3, v(10.0, 5.0, -2.0)),
            rapid(4, v(10.0, 5.0, -2.0)),
        ];
        let p = plan_moves(Vector3::zeros(), &moves, &limits()).unwrap();
        let segs = p.segments();
        assert_eq!(segs.len(), 2);
        assert_eq!((segs[0].line, segs[1].line), (1, 3));
        assert_eq!(segs[1].start_mm, segs[0].end_mm);
        assert_eq!(segs[1].start_time_s, segs[0].duration_s());
        assert_eq!(p.duration_s(), segs[1].end_time_s());
        assert_eq!(p.segment_index_at(0.0), Some(0));
        assert_eq!(p.segment_index_at(segs[1].start_time_s), Some(1));
        assert_eq!(p.segment_index_at(1e9), Some(1));
        assert_eq!(p.end_mm(), v(10.0, 5.0, -2.0));
        // At the junction both segments give the junction point.
        assert_eq!(p.position_at(segs[1].start_time_s), v(10.0, 0.0, 0.0));
    }

    #[test]
    fn empty_plan_stays_at_start() {
        let p = plan_moves(v(1.0, 2.0, 3.0), &[], &limits()).unwrap();
        assert_eq!(p.duration_s(), 0.0);
        assert_eq!(p.end_mm(), v(1.0, 2.0, 3.0));
        assert_eq!(p.position_at(5.0), v(1.0, 2.0, 3.0));
        assert_eq!(p.segment_index_at(0.0), None);
        assert_eq!(Plan::at_rest(v(1.0, 2.0, 3.0)), p);
    }

    #[test]
    fn rejects_bad_input() {
        let mut bad = limits();
        bad.max_acc_mm_s2[1] = 0.0;
        assert_eq!(
            plan_moves(Vector3::zeros(), &[], &bad),
            Err(PlanError::InvalidLimit {
                name: "max_acc_mm_s2.y",
                value: 0.0
            })
        );
        bad = limits();
        bad.max_feed_mm_s = f64::INFINITY;
        assert!(matches!(
            bad.validate(),
            Err(PlanError::InvalidLimit {
                name: "max_feed_mm_s",
                ..
            })
        ));
        bad = limits();
        bad.max_vel_mm_s[2] = f64::NAN;
        assert!(bad.validate().is_err());
        let l = limits();
        assert_eq!(
            plan_moves(v(f64::NAN, 0.0, 0.0), &[], &l),
            Err(PlanError::NonFiniteStart)
        );
        assert_eq!(
            plan_moves(
                Vector3::zeros(),
                &[rapid(4, v(f64::INFINITY, 0.0, 0.0))],
                &l
            ),
            Err(PlanError::NonFiniteTarget { line: 4 })
        );
        let no_feed = Move {
            line: 5,
            rapid: false,
            target_mm: v(1.0, 0.0, 0.0),
            feed_mm_s: None,
        };
        assert_eq!(
            plan_moves(Vector3::zeros(), &[no_feed], &l),
            Err(PlanError::InvalidFeed {
                line: 5,
                feed_mm_s: None
            })
        );
        assert_eq!(
            plan_moves(Vector3::zeros(), &[feed(6, v(1.0, 0.0, 0.0), -1.0)], &l),
            Err(PlanError::InvalidFeed {
                line: 6,
                feed_mm_s: Some(-1.0)
            })
        );
        assert_eq!(
            plan_moves(
                Vector3::zeros(),
                &[rapid(8, v(f64::MAX, -f64::MAX, 0.0))],
                &l
            ),
            Err(PlanError::Overflow { line: 8 })
        );
        assert_eq!(
            plan_moves(Vector3::zeros(), &[feed(9, v(1e9, 0.0, 0.0), 1e-300)], &l),
            Err(PlanError::Overflow { line: 9 })
        );
    }

    #[test]
    fn tiny_moves_are_planned_not_lost() {
        let target = v(1e-300, 0.0, 0.0);
        let p = plan_moves(Vector3::zeros(), &[rapid(1, target)], &limits()).unwrap();
        assert_eq!(p.segments().len(), 1);
        assert_eq!(p.end_mm(), target);
        assert!(p.duration_s() >= 0.0 && p.duration_s().is_finite());
    }

    #[test]
    fn trapezoid_with_boundary_speeds() {
        // 10 mm from 10 to 20 mm/s, cap 30, a = 100: d_acc = (900-100)/200 = 4,
        // d_dec = (900-400)/200 = 2.5, cruise 3.5 mm.
        let p = trapezoid(10.0, 10.0, 20.0, 30.0, 100.0).unwrap();
        assert!(close(p.t_acc_s, 0.2) && close(p.t_dec_s, 0.1));
        assert!(close(p.t_cruise_s, 3.5 / 30.0));
        // Too short for a cruise: apex² = a L + (v0² + v1²)/2 = 200 + 250.
        let p = trapezoid(2.0, 10.0, 20.0, 30.0, 100.0).unwrap();
        assert!(close(p.v_peak_mm_s, 450f64.sqrt()));
        assert_eq!(p.t_cruise_s, 0.0);
        // End speed out of reach within the length.
        assert_eq!(trapezoid(1.0, 0.0, 20.0, 30.0, 100.0), None);
        assert_eq!(trapezoid(1.0, 40.0, 0.0, 30.0, 100.0), None);
        assert_eq!(trapezoid(0.0, 0.0, 0.0, 30.0, 100.0), None);
    }

    #[test]
    fn plans_a_parsed_program() {
        let prog = parse_program(
            "G21 G90\nG0 X10\nG1 Y10 F1200\nG91 Z-1\n",
            "p.ngc",
            v(0.0, 0.0, 5.0),
        )
        .unwrap();
        let p = plan(&prog, &limits()).unwrap();
        let lines: Vec<usize> = p.segments().iter().map(|s| s.line).collect();
        assert_eq!(lines, vec![2, 3, 4]);
        assert_eq!(p.start_mm(), v(0.0, 0.0, 5.0));
        assert_eq!(p.end_mm(), v(10.0, 10.0, 4.0));
        // F1200 mm/min = 20 mm/s on Y (limit 50), Z move limited by Z's 20 mm/s.
        assert_eq!(p.segments()[1].v_peak_mm_s, 20.0);
        let z = p.segments()[2];
        assert!(parts(&z).is_triangle);
        assert!(close(z.v_peak_mm_s, 200f64.sqrt()));
    }

    fn plan_text(text: &str, limits: &Limits) -> Plan {
        let prog = parse_program(text, "p.ngc", Vector3::zeros()).unwrap();
        plan(&prog, limits).unwrap()
    }

    #[test]
    fn arcs_follow_the_circle_and_end_exactly() {
        // A clockwise half circle of radius 10 about (10, 0), then a helix of one turn.
        let p = plan_text("G21 F600\nG2 X20 Y0 I10\nG3 X20 Y0 Z-4 I-10\n", &limits());
        let (arc, helix) = (p.segments()[0], p.segments()[1]);
        assert!(matches!(arc.path, SegmentPath::Arc(_)));
        assert!(close(arc.length_mm, 10.0 * std::f64::consts::PI));
        let center = v(10.0, 0.0, 0.0);
        let mut last_distance = 0.0;
        for k in 0..=200 {
            let t = arc.duration_s() * f64::from(k) / 200.0;
            let q = arc.position_at(t);
            assert!(
                ((q - center).norm() - 10.0).abs() < 1e-9,
                "off the circle at {t}"
            );
            assert_eq!(q.z, 0.0);
            // Clockwise from (0,0) over the top: y ≥ 0.
            assert!(q.y >= -1e-12);
            let d = arc.distance_at(t);
            assert!(d >= last_distance);
            last_distance = d;
        }
        assert_eq!(arc.position_at(arc.duration_s()), v(20.0, 0.0, 0.0));
        assert!(close(arc.position_at(arc.duration_s() / 2.0).y, 10.0));
        // The helix: z falls in proportion to the distance travelled.
        for k in 0..=50 {
            let t = helix.duration_s() * f64::from(k) / 50.0;
            let q = helix.position_at(t);
            let s = helix.distance_at(t) / helix.length_mm;
            assert!((q.z + 4.0 * s).abs() < 1e-9);
            assert!(((q - v(10.0, 0.0, q.z)).norm() - 10.0).abs() < 1e-9);
        }
        assert_eq!(p.end_mm(), v(20.0, 0.0, -4.0));
    }

    #[test]
    fn arc_speed_is_held_by_the_centripetal_acceleration() {
        // r = 1 mm in XY: A = min(1000, 500) = 500, so v ≤ sqrt(500 · √3/2 · 1) ≈ 20.8 mm/s,
        // below the 80 mm/s feed; the path acceleration is A/2.
        let p = plan_text("G21 F4800\nG2 X2 Y0 I1\n", &limits());
        let s = p.segments()[0];
        assert!(close(s.v_peak_mm_s, (500.0 * 0.75f64.sqrt()).sqrt()));
        assert!(close(parts(&s).accel_mm_s2, 250.0));
        // A big radius: the feed, clamped to the plane axes' speeds (Y: 50 mm/s), wins.
        let p = plan_text("G21 F4800\nG2 X200 Y0 I100\n", &limits());
        assert!(close(p.segments()[0].v_peak_mm_s, 50.0));
    }

    #[test]
    fn dwells_and_stops_hold_still() {
        let p = plan_text("G21 G0 X1\nG4 P0.5\nM0\nG4 P0\nG0 X2\n", &limits());
        let kinds: Vec<SegmentPath> = p.segments().iter().map(|s| s.path).collect();
        assert!(matches!(kinds[1], SegmentPath::Dwell));
        assert!(matches!(kinds[2], SegmentPath::Stop { optional: false }));
        assert_eq!(kinds.len(), 4);
        let dwell = p.segments()[1];
        assert_eq!(dwell.duration_s(), 0.5);
        for k in 0..=10 {
            let t = dwell.start_time_s + 0.05 * f64::from(k);
            assert_eq!(p.position_at(t), v(1.0, 0.0, 0.0));
        }
        assert_eq!(p.segments()[2].duration_s(), 0.0);
        assert_eq!(p.segments()[3].start_time_s, dwell.end_time_s());
    }

    #[test]
    fn elements_must_chain() {
        let e = Element {
            line: 4,
            col: 1,
            kind: ElementKind::Line,
            rapid: true,
            start_mm: v(1.0, 0.0, 0.0),
            end_mm: v(2.0, 0.0, 0.0),
            aux: Default::default(),
            feed_mm_s: None,
            blend: BlendMode::ExactStop,
            comp: CompState::Off,
            plane: Plane::Xy,
        };
        assert_eq!(
            plan_items(Vector3::zeros(), &[Item::Motion(e)], &limits()),
            Err(PlanError::Discontinuity { line: 4 })
        );
    }

    mod arcs {
        use super::*;
        use proptest::prelude::*;

        proptest! {
            #![proptest_config(ProptestConfig::with_cases(64))]

            /// Sampled like the interpolator does, every axis keeps its speed and acceleration
            /// limits and the path stays on the circle.
            #[test]
            fn sampled_arcs_hold_the_axis_limits(
                plane in 0usize..3,
                cw in any::<bool>(),
                radius in 0.5..50.0f64,
                angle_deg in 10.0..700.0f64,
                helix in -20.0..20.0f64,
                feed in 100.0..20000.0f64,
                vel in proptest::array::uniform3(10.0..500.0f64),
                acc in proptest::array::uniform3(50.0..5000.0f64),
            ) {
                let (plane_code, a, b) = [("G17", 'X', 'Y'), ("G18", 'Z', 'X'), ("G19", 'Y', 'Z')][plane];
                let offset = ['I', 'J', 'K'][['X', 'Y', 'Z'].iter().position(|l| *l == a).unwrap()];
                let normal_letter = ['Z', 'Y', 'X'][plane];
                // Start at (r, 0) in plane coordinates about the origin; end at the angle.
                let theta = angle_deg.to_radians() * if cw { -1.0 } else { 1.0 };
                let turns = (angle_deg / 360.0).floor();
                let text = format!(
                    "G21 {plane_code} G0 {a}{radius} {b}0\n{} {a}{:.9} {b}{:.9} {normal_letter}{helix:.6} {offset}{} F{feed} P{}\n",
                    if cw { "G2" } else { "G3" },
                    radius * theta.cos(),
                    radius * theta.sin(),
                    -radius,
                    turns + 1.0,
                );
                let prog = parse_program(&text, "p", Vector3::zeros()).unwrap();
                let lim = Limits {
                    max_vel_mm_s: Vector3::from(vel),
                    max_acc_mm_s2: Vector3::from(acc),
                    max_feed_mm_s: 1000.0,
                };
                let p = plan(&prog, &lim).unwrap();
                let seg = *p.segments().last().unwrap();
                let SegmentPath::Arc(arc) = seg.path else { panic!("not an arc") };
                let period = (seg.duration_s() / 4000.0).min(0.001);
                let mut prev2 = seg.position_at(-period);
                let mut prev = seg.position_at(0.0);
                let mut k = 1.0;
                loop {
                    let t = k * period;
                    let q = seg.position_at(t);
                    let rel = q - arc.center_mm;
                    let in_plane = rel - arc.normal * rel.dot(&arc.normal);
                    prop_assert!((in_plane.norm() - radius).abs() < 1e-6 * radius.max(1.0));
                    for i in 0..3 {
                        let v_i = (q[i] - prev[i]).abs() / period;
                        let a_i = (q[i] - 2.0 * prev[i] + prev2[i]).abs() / (period * period);
                        prop_assert!(v_i <= lim.max_vel_mm_s[i] * 1.001 + 1e-6,
                            "axis {} speed {} > {}", i, v_i, lim.max_vel_mm_s[i]);
                        prop_assert!(a_i <= lim.max_acc_mm_s2[i] * 1.01 + 1e-3,
                            "axis {} acceleration {} > {}", i, a_i, lim.max_acc_mm_s2[i]);
                    }
                    if t >= seg.duration_s() {
                        prop_assert_eq!(q, seg.end_mm);
                        break;
                    }
                    prev2 = prev;
                    prev = q;
                    k += 1.0;
                }
            }
        }
    }

    proptest::proptest! {
        /// The S-curve backward bound: the returned start speed satisfies `va·t(va − vb) ≤ L`
        /// and is the largest that does (a hair above fails, unless it is the speed cap).
        #[test]
        fn s_curve_start_reach_is_the_largest_speed_within_the_bound(
            l in 1e-4..50.0f64,
            vb in 0.0..150.0f64,
            a in 50.0..5000.0f64,
            j in 1e3..1e6f64,
            smooth in proptest::bool::ANY,
        ) {
            let shape = if smooth { JerkShape::RaisedCosine } else { JerkShape::Square };
            let lim = ProfileLimits::new(200.0, a, j, shape).unwrap();
            let vb = vb.min(200.0);
            let va = start_reach_mm_s(l, vb, f64::INFINITY, &lim);
            let je = if smooth { 0.5 * j } else { j };
            let t = |dv: f64| if dv >= a * a / je { dv / a + a / je } else { 2.0 * (dv / je).sqrt() };
            proptest::prop_assert!(va >= vb && va <= 200.0);
            proptest::prop_assert!(va * t(va - vb) <= l, "{} over {}", va * t(va - vb), l);
            let above = va * (1.0 + 1e-12);
            proptest::prop_assert!(va == 200.0 || above * t(above - vb) > l);
            // And the profile the settle step plans from it exists.
            proptest::prop_assert!(profile::plan(l, va, vb, &lim).is_some());
        }

        /// The capped backward bound (which skips the solve when the cap is within the bound) is
        /// the uncapped one capped, to a few ulps where the cap is within rounding of it, and
        /// always within the bound.
        #[test]
        fn s_curve_start_reach_capped_is_the_uncapped_one_capped(
            l in 1e-4..50.0f64,
            vb in 0.0..150.0f64,
            cap_ratio in 0.0..3.0f64,
            near in proptest::bool::ANY,
            a in 50.0..5000.0f64,
            j in 1e3..1e6f64,
            smooth in proptest::bool::ANY,
            trapezoid in proptest::bool::ANY,
        ) {
            let shape = if smooth { JerkShape::RaisedCosine } else { JerkShape::Square };
            let j = if trapezoid { f64::INFINITY } else { j };
            let lim = ProfileLimits::new(200.0, a, j, shape).unwrap();
            let uncapped = start_reach_mm_s(l, vb, f64::INFINITY, &lim);
            // A cap near the uncapped bound, or anywhere from 0 to 3 times it.
            let cap = if near { uncapped * (1.0 + (cap_ratio - 1.5) * 1e-14) } else { uncapped * cap_ratio };
            let capped = start_reach_mm_s(l, vb, cap, &lim);
            let expected = uncapped.min(cap);
            proptest::prop_assert!(
                (capped - expected).abs() <= 16.0 * f64::EPSILON * expected,
                "capped {} expected {}", capped, expected
            );
            proptest::prop_assert!(capped <= cap);
            if !trapezoid && capped > vb {
                let je = if smooth { 0.5 * j } else { j };
                let t = |dv: f64| if dv >= a * a / je { dv / a + a / je } else { 2.0 * (dv / je).sqrt() };
                proptest::prop_assert!(capped * t(capped - vb) <= l);
            }
        }
    }

    /// Under the time-law filter a plane arc's plan accelerates at the largest `a` whose parts,
    /// taken in quadrature, keep each axis of its plane within `s·Jᵢ` at its top speed
    /// (`√((2·a/T_f + v³κ²)² + (3·v·κ·a)²)`, [`arc_limits`]): the axes meet that budget
    /// exactly, and the plan runs a good deal above the split's `J_t·T_f/2` (485 against
    /// 375 mm/s² on this 6.35 mm arc at 72 mm/s). A move alone, without the filter, keeps the
    /// split.
    #[test]
    fn a_plane_arc_s_time_law_acceleration_takes_its_parts_in_quadrature() {
        let lim = Limits {
            max_vel_mm_s: v(200.0, 200.0, 200.0),
            max_acc_mm_s2: v(2000.0, 2000.0, 2000.0),
            max_feed_mm_s: 200.0,
        };
        let cfg = PlannerConfig {
            period_s: 0.001,
            corner_acc_mm_s2: 2000.0,
            path_acc_share: 0.75,
            path_acc_mm_s2: f64::INFINITY,
            max_jerk_mm_s3: v(50_000.0, 50_000.0, 50_000.0),
            profile: ProfileKind::SCurve,
            chord_tol_mm: 0.001,
            default_tolerance_mm: 0.01,
            lookahead: 64,
            integer_periods: false,
            aux: AuxLimits::NONE,
            axis_filter_s: AXIS_FILTER_S,
        };
        let (r, t_f) = (6.35, 0.04);
        let arc = ArcGeometry::new(
            v(r, 0.0, 0.0),
            v(0.0, r, 0.0),
            v(0.0, 0.0, 0.0),
            v(0.0, 0.0, 1.0),
            0,
        )
        .unwrap();
        let l = arc_limits(&arc, 200.0, &lim, &cfg, ARC_SPLIT, true, Some(t_f));
        let a = l.time_law_acc_mm_s2.expect("more than the split gives");
        let split_mm_s2 = l.acc_mm_s2.min(0.5 * l.jerk_mm_s3 * t_f);
        assert!(
            a > 1.25 * split_mm_s2,
            "{a} against the split's {split_mm_s2} mm/s²"
        );
        let (top, k) = (l.v_max_mm_s, 1.0 / r);
        let jerk = (2.0 * a / t_f + top.powi(3) * k * k).hypot(3.0 * top * k * a);
        let budget = 0.75 * 50_000.0;
        assert!(
            (jerk - budget).abs() <= 1e-9 * budget,
            "{jerk} against {budget} mm/s³"
        );
        assert!(a.hypot(top * top * k) <= 0.75 * 2000.0);
        // Every axis's use reported for the junctions covers it.
        assert!((0..2).all(|i| l.axis_jerk_mm_s3[i] >= jerk * (1.0 - 1e-12)));
        let alone = arc_limits(&arc, 200.0, &lim, &cfg, ARC_SPLIT, true, None);
        assert_eq!(alone.time_law_acc_mm_s2, None);
        assert_eq!(
            (alone.acc_mm_s2, alone.jerk_mm_s3),
            (l.acc_mm_s2, l.jerk_mm_s3)
        );
    }

    /// The axis filters' time is refused outside the range the planner's rules are made
    /// for, with the value asked for.
    #[test]
    fn an_axis_filter_time_outside_its_range_is_refused() {
        let cfg = |axis_filter_s| PlannerConfig {
            axis_filter_s,
            profile: ProfileKind::SCurve,
            max_jerk_mm_s3: v(50_000.0, 50_000.0, 50_000.0),
            ..PlannerConfig::exact_stop()
        };
        for ok in [0.008, 0.012, 0.016] {
            assert_eq!(cfg(ok).validate(), Ok(()), "{ok} s");
        }
        for refused in [0.0, 0.004, 0.0161, 0.032, f64::NAN] {
            match cfg(refused).validate() {
                Err(e @ PlanError::InvalidAxisFilter { value_s }) => {
                    assert!(value_s == refused || value_s.is_nan() && refused.is_nan());
                    assert!(e.to_string().contains("0.008..=0.016 s"), "{e}");
                }
                other => panic!("{refused} s: {other:?}"),
            }
        }
    }
}
