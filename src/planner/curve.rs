//! Chord polylines as curves, in the jerk-limited mode.
//!
//! CAM writes curves as runs of short lines whose vertices turn a little each. The junction
//! rules of [`Planner::smoothed_junction_limit_mm_s`] charged the curve such a run approximates
//! (its centripetal acceleration `v²κ̄` and the jerk of following it, `v³κ̄²`) against the
//! budget the elements leave each axis at the vertex (a quarter of the acceleration, an eighth
//! of the jerk with the default `path_acc_share`), with the curvature `κ̄` of one or two
//! vertices, which the rounding of the written coordinates makes noisy: a 10 mm circle of
//! 30 µm chords (4 decimals) ran at 42–71 mm/s where a G2 of that radius runs at 98 mm/s, and
//! a 0.5 mm circle of 10 µm chords at 2–6 mm/s against the G2's 13.
//!
//! Here the lines of a dense run take the curve from their own budget, as an arc does
//! ([`super::arc_limits`]):
//!
//! - **Curvature.** At each vertex the run's curvature is estimated over a window of its last
//!   chords: the turn of the tangent from the chord `m` back to the newest one, over the
//!   distance between their midpoints. The window is the longest (of 2, 4, 8, … up to 64
//!   chords) that the axis filters still average over at the speed its curvature allows (their
//!   output spans `2·v·T_k`): their output follows the polyline's curvature averaged over about
//!   that, and a longer window could average away a tighter part they still see. The
//!   rounding's error on a chord's direction, `ε/L`, then weighs `1/m` as much against the
//!   window's turn as against one vertex's. A vertex turning more than [`CURVE_MAX_TURN`], a
//!   blended corner, an arc, a stop or auxiliary axes end the run.
//! - **Dense runs only.** Two chords at least within the axis filters' reach `v·T_k`, at the
//!   speed the curve allows and at the speed the vertex's own rules allow without the curve
//!   taken: sparser vertices are steps of the axis velocity each, as the junction rules have
//!   them (LinuxCNC's `trochoidal.ngc`, 0.29 mm chords; `contour.ngc`, whose 2.5 µm inch
//!   rounding on 16 µm chords holds it at 3 mm/s vertex by vertex).
//! - **Limits.** The lines either side of the vertex take the curve of curvature `κ` (normal
//!   `N`, tangent `T`) within [`CURVE_ACC_BUDGET`] of each axis's acceleration and
//!   [`CURVE_JERK_BUDGET`] of its jerk, and the rate at which
//!   its curvature vector changes beyond its turn, `ρ = d(κN)/ds + κ²·T` (estimated over at
//!   least twice the window and the axis filters' span `2·v·T_k`, from the curvature
//!   estimated at every vertex of the run, taken as a curve or not): at constant speed the
//!   jerk of following it is `v³·(κ²·|Tᵢ| + |ρᵢ|)`. The run's cap holds the centripetal
//!   acceleration `v²κ·|Nᵢ|` within [`CENTRIPETAL_SHARE`] of that budget and this jerk within
//!   [`CURVE_JERK_SHARE`]: a steady curve uses most of `A` and `J`, as `T_lb` counts.
//! - **The tangential acceleration at speed.** Where the speed changes, the budget left at
//!   that speed goes to the tangential acceleration: `a(v)`, the largest `a_t` with
//!   `a_t·|Tᵢ| + w²κ·|Nᵢ|` and `(2·a_t/T_f + w³κ²)·|Tᵢ| + w³·|ρᵢ| + 3·w·κ·a_t·|Nᵢ|` within
//!   the budget at `w = v + a_t·T_f` (the time law passes the acceleration on over `T_f`,
//!   within which the speed rises by at most `a_t·T_f`; its jerk is at most `2·a_t/T_f`),
//!   [`CurveFit::acc_at`]. It falls with `v`: at rest, about a line's `J·T_f/2`; at the cap,
//!   what the shares leave. Each line plans with `a(v)` at the faster end of its speed
//!   change, in both passes of the look-ahead ([`reach_mm_s`]): on runs of short chords, a
//!   time-optimal parameterisation of the curve at chord resolution (a TOPP whose
//!   acceleration bound depends on the speed). The backward pass keeps the pair
//!   `(a, valid up to)` it took last ([`Pending::reach_memo`]) as a candidate, so its bound at
//!   an element never falls as the bound after it rises, and the speed already settled stays
//!   within reach; the walks that check a change against that speed
//!   ([`Planner::can_come_down`], [`Planner::can_stop_with`]) take the acceleration valid up
//!   to each element's cap (its floor, [`Pending::acc_floor_mm_s2`]), or the backward pass's
//!   own reach where that is not enough. The pass never reaches less than the floor does: it
//!   takes the last pair as it is only where that pair's acceleration is at least the
//!   floor's (a pair kept on a tie at the speed limit had a lower one, and a pass then came
//!   down slower than the walks had checked: `NoProfile` on a generated profile, its seed in
//!   `tests/planner_limits.proptest-regressions`).
//! - **The filter's reach.** The time-law filter's output at a point has the jerk
//!   `(a⁺ − a⁻)/T_f` and the acceleration the mean of `a` over `T_f`, with `a⁺`, `a⁻` the
//!   plan's accelerations where it is at the two ends of the filter's window, up to `c·T_f/2`
//!   either side of that point at the cap `c` (the erosion below holds it there). So the
//!   budget a point's curve leaves for `2·a_t/T_f` must hold for the acceleration of every
//!   line within that reach, not its own only: each line plans with the curves within reach
//!   of it too, taken together coefficient by coefficient (each axis's share of the
//!   tangential acceleration `|Tᵢ|`, of the centripetal `κ·|Nᵢ|`, and of the jerk of following
//!   the curve `κ²·|Tᵢ| + |ρᵢ|`, the larger: [`Charge`], [`CurveFit::worst`]): those before
//!   the vertex back through the window where the look-ahead's backward pass still comes
//!   down to the speed the plan has settled ([`Planner::merge_back`]; else the vertex keeps
//!   the old rules), those after it as they come. That pass takes each line's pairs known
//!   valid, its floor's and the one it kept, the better ([`floor_back_reach`]: one or two
//!   speed changes a line; the pass's own where that does not come down), and stops where
//!   the marks of earlier passes show it would come down ([`PassMark`]): on 200 000 spiral
//!   chords it visits about 110 elements a walk instead of the window's 550. With each
//!   line's own curve only, a curvature that steps from 0.3 to −0.3 /mm between pieces of
//!   0.3–1.5 mm broke Z's jerk by 4.7 % (`tests/planner_limits.rs`,
//!   `chorded_profiles_of_changing_curvature_keep_every_limit`). The rounding of the written
//!   coordinates makes the curvature's rate, and with it `qᵢ`, noisy by a factor of two
//!   from vertex to vertex: the walk back is skipped where the charge taken back last (a
//!   little wider, [`WIDEN`]) covers the vertex's, and takes only the lines whose charge does
//!   not. A line within reach of the curves held ahead whose own vertex is not taken (the
//!   run's end, a vertex turning too much or too sparse, a computed vertex) plans with their
//!   charges too ([`Planner::hold_on`]): after a
//!   curve of 0.254 /mm, a chord of a piece of −0.104 /mm decelerated at its own 300 mm/s²
//!   within `T_f` of the curve's +290, and Z's jerk ran 2.5–5.6 % over (two seeds of
//!   `chorded_profiles_of_changing_curvature_keep_every_limit`, found at 5000 cases). Such a
//!   line that goes well beyond the last charge held ahead is split where it ends
//!   ([`SPLIT_BEYOND`]); the rest plans as any line beyond, under the cap that held the whole
//!   line where one did (a line of 3.2 mm after a stop, taken whole by the walk back of the
//!   tight curve after it, ran at 2 mm/s for 2.8 s on `LHchips4`). Before session 23 a line
//!   longer than the caps' reach kept its own acceleration whole, its start within reach
//!   too. (Where the walk back is skipped, holding the vertex's own charge ahead instead of
//!   the one taken back last is as safe and a little faster on the corpus, `wheels` −3.2 %,
//!   but more walks back follow: the look-ahead 339 → 291 k segments/s on the spiral. Not
//!   kept.)
//!   (Taking the larger of the charges taken back within the last reach walks back
//!   less often, 15 % faster on 200 000 spiral chords, but plans `LHchips4` 9 % and
//!   `line-contouring-xz` 16 % slower.)
//! - **The vertex's own rules.** The junction rules then charge the vertex only what it
//!   turns beyond the curve, `Δu − κ·L̄` (its velocity step against the curve's, the corner
//!   its filters cut beyond the pull the interpolator pre-compensates), not the curve
//!   again; and the curve's use of each axis at the speed through the junction, which is
//!   lower than at the cap where the vertex's own rules bind
//!   ([`Planner::curve_junction_mm_s`]).
//! - **Vertices not taken, on refined pieces.** Where a vertex between pieces of a refined
//!   chord is not taken (the window too short to erode back, the plan settled), its own
//!   rules take each of its steps alone; the steps of a curvature that turns within the axis
//!   filters' span add up there. The sum within a span, the second difference of the
//!   directions `u(s) − 2·u(s − v·T_k) + u(s − 2·v·T_k)`, is held within what the elements
//!   leave of each axis's jerk ([`Planner::span_cap_mm_s`]).
//! - **Erosion instead of dips.** The time-law filter's output at a point is the mean speed of
//!   the plan over one filter time `T_f` around it. A cap `c` that holds for the plan over
//!   `c·T_f` on either side of an element holds for that mean too (the plan cannot leave that
//!   stretch within `T_f`), the plateau argument of [`Planner::finalize_junction`]. So each
//!   element's cap is applied to every element within `c·T_f` before it (back through the
//!   window, [`Planner::erode_back`]) and after it (as they come, [`CurveState::cap_at`]), and a
//!   junction between such elements below its neighbours only by their caps needs no dip.
//!   Where that stretch reaches an element longer than it, the junction with it is dipped as
//!   any other (`A·T_f/4`, or a stop); where it reaches the settled part of the plan (not at
//!   rest), or the plan could no longer come down to it from the speed it has settled, the
//!   vertex keeps the old rules. A vertex of a run whose own rules cap it below its lines is
//!   held the same way, as a cap of the run (since session 34; dipped, the lines'
//!   `A·T_f/4` took all of a cap a little under theirs, [`Planner::start_caps`]).
//! - **Caps on a grid.** The caps are rounded down to a grid of steps of [`CAP_STEP`]: a curve
//!   whose caps differ by the rounding's noise from vertex to vertex then has equal caps
//!   along stretches, and the walk back through the window stops at the first element whose
//!   ceiling, and that of all before it within reach ([`Pending::floor_reach_mm`]), is
//!   already as low.
//!
//! The acceptance's chorded curves (`tests/chorded_curves.rs`) and the corpus keep every
//! axis's limits and the tolerance with this (`tests/gcode_corpus.rs`, sampled at 3, 4 and 5 ms).

use std::collections::VecDeque;

use nalgebra::Vector3;

use super::profile::ProfileLimits;
use super::{Pending, Planner, SegmentPath, Smoothing, cap_speed, caps_under};
use crate::gcode::BlendMode;

/// Largest turn `|Δu|` of a vertex between two lines that is taken as a point of a curve
/// (about 20°); sharper corners keep the junction rules alone.
pub(super) const CURVE_MAX_TURN: f64 = 0.35;

/// Chords kept for the curvature's window.
const CHORD_HISTORY: usize = 65;

/// Share of each axis's jerk a line of a chord run may use for its curve and its tangential
/// acceleration together; what is left is the vertices' own, beyond the curve. The rounding
/// of written coordinates turns each chord's direction by up to `2ε/L` (`3·10⁻³` rad on
/// 30 µm chords with 4 decimals), and the axis filters pass a velocity step `v·Δu` on as the
/// jerk `v·Δu/T_k²`: at 130 mm/s with `T_k` = 8 ms, 6·10³ mm/s³ for one such vertex, an
/// eighth of the demo machine's jerk, on top of the curve's.
const CURVE_JERK_BUDGET: f64 = 0.85;

/// Share of each axis's acceleration a line of a chord run may use for its curve and its
/// tangential acceleration together. The same vertex reaches the axes' acceleration only as
/// `v·Δu/T_k`, 50 mm/s² (2.5 % of the demo machine's `A`), and the vertex's own rule
/// (`v·|Δuᵢ − κᵢ·L̄| ≤ T_k·(Aᵢ − usedᵢ)`, [`Planner::junction_rules_mm_s`]) dips any vertex
/// that needs more than this leaves it. The jerk's 0.85 until session 35: a curve whose cap
/// its centripetal acceleration sets (a 10 mm circle of 30 µm chords) ran at 126 mm/s where
/// 0.95 lets it run at 133 (`tests/chorded_curves.rs`: 1.212 → 1.153 × `T_lb`).
const CURVE_ACC_BUDGET: f64 = 0.95;

/// Share of that budget the centripetal acceleration `v²κ·|Nᵢ|` may take at the run's cap:
/// at the cap the tangential acceleration is what the rest leaves. (0.9 until session 34:
/// near the cap the braking distance, with the little tangential acceleration left, outgrew
/// a window of 1000 elements of 30 µm chords, and a 10 mm circle stopped every few laps; the
/// default `lookahead` is 2000 since.)
const CENTRIPETAL_SHARE: f64 = 0.97;

/// Share of that budget the jerk of following the curve, `v³κ²·|Tᵢ|`, may take at the cap
/// (0.8 until session 34).
const CURVE_JERK_SHARE: f64 = 0.95;

/// How much wider a curve's charge is taken for its neighbours ([`Charge::widened`]).
const WIDEN: f64 = 0.02;

/// How much further back than the time-law filter's reach a curve is taken by the lines
/// before it ([`Planner::merge_back`]): the reach varies with the noisy cap from vertex to
/// vertex, and a walk back is needed only where a vertex's reach goes beyond the last one's.
const BACK_MARGIN: f64 = 1.25;

/// [`Planner::hold_on`] splits a line longer than this many times the reach of what is held
/// ahead of it.
const SPLIT_BEYOND: f64 = 1.5;

/// Relative step of the grid the caps are rounded down to.
pub(super) const CAP_STEP: f64 = 0.01;

/// What the planner keeps of the current run of chords.
#[derive(Debug, Clone, Default)]
pub(super) struct CurveState {
    /// The recent lines of the run: direction and the path distance of their midpoint (from
    /// [`CurveState::pushed_mm`]'s origin).
    chords: VecDeque<(Vector3<f64>, f64)>,
    /// Half the length of each of [`CurveState::chords`] (their extents, for
    /// [`Planner::span_cap_mm_s`]).
    chord_half_mm: VecDeque<f64>,
    /// The curvature vectors of the run's vertices taken, with their path distances.
    kappas: VecDeque<(Vector3<f64>, f64)>,
    /// Caps that hold ahead: `(until_mm, cap_mm_s)`, every element starting before `until_mm`
    /// capped at `cap_mm_s` (path distances as [`CurveState::pushed_mm`]).
    ahead: Vec<(f64, f64)>,
    /// Curves that hold ahead: `(until_mm, charge)`, every line of a chord run starting
    /// before `until_mm` planning its tangential acceleration with `charge` too
    /// ([`Planner::take_curve_vertex`], [`CurveState::worst_ahead`]).
    ahead_fits: VecDeque<(f64, Charge)>,
    /// The last charge taken back through the window ([`Planner::merge_back`]): from where
    /// (path distance), until where it is held ahead, and the charge (widened).
    last_back: Option<(f64, f64, Charge)>,
    /// Path distance at the end of everything pushed (blends' trims taken off).
    pub(super) pushed_mm: f64,
    /// The curve of the last vertex taken: the budgets a line within reach of the curves held
    /// ahead plans with ([`Planner::hold_on`]).
    last_fit: Option<CurveFit>,
    /// The part beyond the reach of what is held ahead of a line [`Planner::hold_on`] split,
    /// pushed after it.
    pub(super) held_rest: Option<Pending>,
    /// What [`Planner::merge_back`] changed (kept to reuse its memory).
    undo: Vec<Changed>,
    /// The [`Pending::reach_memo`]s and [`Pending::pass_mark`]s [`Planner::merge_back`]'s
    /// backward pass replaced, with their window's indices.
    memos: Vec<Visited>,
}

/// An element [`Planner::merge_back`]'s backward pass visited, as it was: its window's index,
/// its [`Pending::reach_memo`] and its [`Pending::pass_mark`].
type Visited = (usize, Option<(f64, f64)>, Option<PassMark>);

/// What the look-ahead's backward pass found at an element last, and what of the element it
/// took: the bound at its start (its cap applied) from the bound at its end. While these are
/// the element's, a later pass that comes to its end at `end_mm_s` or faster finds at least
/// `start_mm_s` at its start: a step is monotone in the speed after it with the element's
/// limits, length and pair ([`reach_with`] takes the pair as a candidate: what the pass took
/// is what it stored), and in the cap. A chain of marks down to the window's start, each
/// link's end within the start of the mark after it, then shows that a pass would come down
/// to the settled speed without running it ([`Planner::marks_come_down`]).
#[derive(Debug, Clone, Copy)]
pub(super) struct PassMark {
    start_mm_s: f64,
    end_mm_s: f64,
    cap_mm_s: f64,
    limits: ProfileLimits,
    length_mm: f64,
    /// The pair of a line of a chord run ([`Pending::reach_memo`]); `None` on other elements.
    memo: Option<(f64, f64)>,
}

impl PassMark {
    /// The mark of a pass that found `start_mm_s` at `p`'s start with the cap `cap_mm_s`, from
    /// `end_mm_s` at its end, `p` holding the pair the pass took; `None` on a line of a chord
    /// run without one (its step is not monotone then).
    pub(super) fn of(
        p: &Pending,
        start_mm_s: f64,
        end_mm_s: f64,
        cap_mm_s: f64,
    ) -> Option<PassMark> {
        let memo = match p.curve_acc {
            Some(_) => Some(p.reach_memo?),
            None => None,
        };
        Some(PassMark {
            start_mm_s,
            end_mm_s,
            cap_mm_s,
            limits: p.limits,
            length_mm: p.seg.length_mm,
            memo,
        })
    }

    /// Whether the mark is still `p`'s, with the cap `cap_mm_s` a pass would take now.
    fn holds(&self, p: &Pending, cap_mm_s: f64) -> bool {
        cap_mm_s >= self.cap_mm_s
            && p.seg.length_mm == self.length_mm
            && p.limits == self.limits
            && p.curve_acc.is_some() == self.memo.is_some()
            && (self.memo.is_none() || p.reach_memo == self.memo)
    }
}

/// A line [`Planner::merge_back`] changed, as it was.
#[derive(Debug, Clone, Copy)]
struct Changed {
    /// Its index in the window.
    at: usize,
    charge: Charge,
    /// Its [`Pending::reach_memo`].
    memo: Option<(f64, f64)>,
    /// Its [`Pending::acc_floor_mm_s2`].
    floor_mm_s2: f64,
}

impl CurveState {
    /// Forgets the run (a stop, a dwell, the program's end: the filters settle there).
    pub(super) fn reset(&mut self) {
        self.end_run();
        self.ahead.clear();
        self.ahead_fits.clear();
        self.last_back = None;
        self.last_fit = None;
    }

    /// Ends the run of chords (a corner blended).
    pub(super) fn end_run(&mut self) {
        self.chords.clear();
        self.chord_half_mm.clear();
        self.kappas.clear();
    }

    /// Adds a line of `length_mm` with the direction `u` whose midpoint lies at `mid_mm` to
    /// the run's chords, forgetting the oldest beyond [`CHORD_HISTORY`].
    fn push_chord(&mut self, u: Vector3<f64>, mid_mm: f64, length_mm: f64) {
        if self.chords.len() >= CHORD_HISTORY {
            self.chords.pop_front();
            self.chord_half_mm.pop_front();
        }
        self.chords.push_back((u, mid_mm));
        self.chord_half_mm.push_back(0.5 * length_mm);
    }

    /// The lowest cap that holds at `at_mm` (`None`: none), forgetting those that ended.
    pub(super) fn cap_at(&mut self, at_mm: f64) -> Option<f64> {
        self.ahead.retain(|&(until, _)| until > at_mm);
        self.ahead.iter().map(|&(_, c)| c).reduce(f64::min)
    }

    /// `fit` made to charge every axis what the curves held ahead at `at_mm` do
    /// ([`CurveFit::worst`]), forgetting those that ended.
    fn worst_ahead(&mut self, at_mm: f64, fit: CurveFit) -> CurveFit {
        let mut worst = fit.charge;
        let mut ended = false;
        for (until, c) in &self.ahead_fits {
            if *until > at_mm {
                worst = worst.sup(c);
            } else {
                ended = true;
            }
        }
        if ended {
            self.ahead_fits.retain(|&(until, _)| until > at_mm);
        }
        fit.worst(&worst)
    }

    fn hold_fit_ahead(&mut self, until_mm: f64, charge: Charge) {
        // Dominated entries go: one charging at least as much that holds as far.
        if self
            .ahead_fits
            .iter()
            .any(|(until, c)| *until >= until_mm && c.covers(&charge))
        {
            return;
        }
        self.ahead_fits
            .retain(|(until, c)| !(*until <= until_mm && charge.covers(c)));
        self.ahead_fits.push_back((until_mm, charge));
    }

    /// The farthest path distance up to which a charge is held ahead of `at_mm` (`at_mm`
    /// where none is).
    fn fits_until_mm(&self, at_mm: f64) -> f64 {
        self.ahead_fits
            .iter()
            .map(|&(until, _)| until)
            .fold(at_mm, f64::max)
    }

    fn hold_ahead(&mut self, until_mm: f64, cap_mm_s: f64) {
        // Dominated entries go: a lower cap that holds as far.
        if self
            .ahead
            .iter()
            .any(|&(until, c)| c <= cap_mm_s && until >= until_mm)
        {
            return;
        }
        self.ahead
            .retain(|&(until, c)| !(c >= cap_mm_s && until <= until_mm));
        self.ahead.push((until_mm, cap_mm_s));
    }
}

/// Whether `p` runs straight with nothing else moving: a line of a chord run.
fn chord(p: &Pending) -> bool {
    matches!(p.seg.path, SegmentPath::Line { .. }) && !p.is_blend_arc && !p.seg.aux.moves()
}

/// The cap `c` rounded down to the grid of [`CAP_STEP`].
fn on_grid(c: f64) -> f64 {
    if !(c > 0.0 && c.is_finite()) {
        return c;
    }
    let step = (1.0 + CAP_STEP).ln();
    let k = (c.ln() / step).floor();
    let g = (k * step).exp();
    if g > c { c } else { g }
}

/// A curve's charge on each axis `i` per unit of the time law, for
/// [`CurveFit::acc_at`]: at the speed `w` and the tangential acceleration `a_t` the
/// acceleration `a_t·tᵢ + w²·mᵢ` and the jerk `(2·a_t/T_f)·tᵢ + w³·qᵢ + 3·w·a_t·mᵢ`. Fits
/// within the time-law filter's reach of each other are taken together coefficient by
/// coefficient ([`CurveFit::worst`]): the filter's output at a point follows that point's
/// curve, with the tangential acceleration of the plan around it.
#[derive(Debug, Clone, Copy)]
struct Charge {
    /// `|Tᵢ|`.
    t: Vector3<f64>,
    /// `κ·|Nᵢ|`.
    m: Vector3<f64>,
    /// `κ²·|Tᵢ| + |ρᵢ|`, with `ρ` the curvature's rate beyond its turn.
    q: Vector3<f64>,
}

impl Charge {
    /// Each coefficient the larger of `self`'s and `other`'s.
    fn sup(&self, other: &Charge) -> Charge {
        Charge {
            t: self.t.sup(&other.t),
            m: self.m.sup(&other.m),
            q: self.q.sup(&other.q),
        }
    }

    /// Whether every coefficient of `self` is at least `other`'s.
    fn covers(&self, other: &Charge) -> bool {
        let ge = |a: &Vector3<f64>, b: &Vector3<f64>| (0..3).all(|i| a[i] >= b[i]);
        ge(&self.t, &other.t) && ge(&self.m, &other.m) && ge(&self.q, &other.q)
    }

    /// The charge a little wider ([`WIDEN`] of each coefficient and of the largest it may
    /// have on a curve of curvature `kappa`: `1` for a share of the tangent, `κ`, `κ²`), so
    /// that it covers those of the vertices after it on a curve that changes slowly.
    fn widened(&self, kappa: f64) -> Charge {
        let widen = |c: Vector3<f64>, most: f64| c.map(|x| x * (1.0 + WIDEN) + WIDEN * most);
        Charge {
            t: widen(self.t, 1.0),
            m: widen(self.m, kappa),
            q: widen(self.q, kappa * kappa),
        }
    }

    fn of(tangent: Vector3<f64>, normal: Vector3<f64>, kappa: f64, rate: Vector3<f64>) -> Charge {
        let t = tangent.abs();
        Charge {
            t,
            m: normal.abs() * kappa,
            q: t * (kappa * kappa) + rate.abs(),
        }
    }
}

/// What a line of a chord run uses of each axis on its curve, at a speed: kept with the
/// element ([`Pending::curve_fit`]) so that the junction at its end can take it at the speed
/// the junction allows ([`Planner::curve_junction_mm_s`]), and ([`Pending::curve_acc`]) so
/// that the look-ahead gives it the tangential acceleration its speed leaves
/// ([`CurveFit::acc_at`]).
#[derive(Debug, Clone, Copy)]
pub(super) struct CurveFit {
    tangent: Vector3<f64>,
    normal: Vector3<f64>,
    kappa: f64,
    /// The rate of change of the curvature vector along the path beyond its turn with the
    /// tangent (`d(κN)/ds + κ²·T = κ'·N + κτ·B`): at constant speed `v`, `v³·|rateᵢ|` of
    /// jerk on each axis besides the `v³κ²·|Tᵢ|` of the turn.
    rate: Vector3<f64>,
    /// What it charges each axis per unit of speed and acceleration ([`CurveFit::acc_at`]).
    charge: Charge,
    /// The element's tangential acceleration by its other rules (a ceiling).
    acc_mm_s2: f64,
    /// The line's own use, before the curve.
    base_acc_used_mm_s2: Vector3<f64>,
    base_jerk_used_mm_s3: Vector3<f64>,
    /// The speed its use is set for.
    pub(super) v_mm_s: f64,
    /// Each axis's budget for the curve and the tangential acceleration ([`CURVE_ACC_BUDGET`],
    /// [`CURVE_JERK_BUDGET`]).
    acc_budget_mm_s2: Vector3<f64>,
    jerk_budget_mm_s3: Vector3<f64>,
    /// The time-law filter's length.
    t_f: f64,
    /// The run's cap at this curvature.
    pub(super) cap_mm_s: f64,
}

impl CurveFit {
    /// The curvature vector `κ·N` of the fit.
    pub(super) fn curvature(&self) -> Vector3<f64> {
        self.normal * self.kappa
    }

    /// A fit that charges every axis at least what `self` and `charge` charge it at any
    /// speed and tangential acceleration: each of its coefficients the larger of the two. Its
    /// [`acc_at`](Self::acc_at) is at most `self`'s. The geometry (`tangent`, `normal`,
    /// `kappa`, `rate`) stays `self`'s: [`use_at`](Self::use_at) charges the element's own.
    fn worst(&self, charge: &Charge) -> CurveFit {
        CurveFit {
            charge: self.charge.sup(charge),
            ..*self
        }
    }

    /// The fit for an element whose speed is held within `v_mm_s`: its acceleration need hold
    /// up to there only ([`acc_at`](Self::acc_at) takes the cap as the highest speed).
    fn within(self, v_mm_s: f64) -> CurveFit {
        CurveFit {
            cap_mm_s: self.cap_mm_s.min(v_mm_s),
            ..self
        }
    }

    /// Whether `self` and `other`, both charging `charge`, have the same
    /// [`acc_at`](Self::acc_at) but for their caps.
    fn same_but_cap(&self, other: &CurveFit) -> bool {
        self.acc_mm_s2 == other.acc_mm_s2
            && self.acc_budget_mm_s2 == other.acc_budget_mm_s2
            && self.jerk_budget_mm_s3 == other.jerk_budget_mm_s3
            && self.t_f == other.t_f
    }

    /// The fit with the tangent `tangent` (the line after the vertex).
    fn with_tangent(mut self, tangent: Vector3<f64>) -> CurveFit {
        self.tangent = tangent;
        self.charge = Charge::of(tangent, self.normal, self.kappa, self.rate);
        self
    }

    /// The largest tangential acceleration `a_t` whose time law keeps every axis within its
    /// budget at the speed `w`: the acceleration `a_t·|Tᵢ| + w²κ·|Nᵢ|` and the jerk
    /// `(j_t + w³κ²)·|Tᵢ| + 3·w·κ·a_t·|Nᵢ|`, with the time law's jerk `j_t ≤ 2·a_t/T_f` (the
    /// filter's window sees the plan's acceleration change by at most `2·a_t`). Falls with `w`.
    fn acc_raw(&self, w: f64) -> f64 {
        let Charge { t, m, q } = &self.charge;
        let (w2, w3) = (w * w, w * w * w);
        let mut a_t = self.acc_mm_s2;
        for i in 0..3 {
            if t[i] > 0.0 {
                a_t = a_t.min((self.acc_budget_mm_s2[i] - w2 * m[i]) / t[i]);
            }
            let per_acc = 2.0 * t[i] / self.t_f + 3.0 * w * m[i];
            if per_acc > 0.0 {
                a_t = a_t.min((self.jerk_budget_mm_s3[i] - w3 * q[i]) / per_acc);
            }
        }
        a_t.max(0.0)
    }

    /// The tangential acceleration the element may plan with where it runs at most at
    /// `v_mm_s`: the time-law filter passes it on over its length `T_f`, within which the
    /// speed rises by at most `a_t·T_f` (not beyond the run's cap), so `a_t` must hold at
    /// `w = min(v + a_t·T_f, cap)`: the fixed point of `a ↦ acc_raw(w(a))`, found within
    /// [`ACC_TOL`] from below (always valid). The third iterate from `acc_raw(v)`, which this
    /// took until session 25, could be a third of it where the curve is tight: 34 mm/s² on
    /// `3D_Chips`'s refined bends, whose fixed point is near 120, a crawl of 0.5 s a bend.
    pub(super) fn acc_at(&self, v_mm_s: f64) -> f64 {
        if v_mm_s >= self.cap_mm_s {
            // Every iterate is at `v_mm_s` itself.
            return self.acc_raw(v_mm_s);
        }
        // The iterates of `a ↦ acc_raw(w(a))` from `acc_raw(v)` close in on the fixed point
        // from both sides: the odd ones valid (`w` falls with `a`), the even ones above it.
        // Where the third and the second are still apart, a bisection between them.
        let a0 = self.acc_raw(v_mm_s);
        let a1 = self.acc_raw(self.reach_in_t_f(v_mm_s, a0));
        let a2 = self.acc_raw(self.reach_in_t_f(v_mm_s, a1));
        let (mut lo, mut hi) = (self.acc_raw(self.reach_in_t_f(v_mm_s, a2)), a2);
        for _ in 0..ACC_STEPS {
            if hi - lo <= ACC_TOL * hi {
                break;
            }
            let mid = 0.5 * (lo + hi);
            if self.valid_at(mid, v_mm_s) {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        lo
    }

    /// The highest speed within one time-law filter time of `v_mm_s` at the acceleration
    /// `a_mm_s2`, not beyond the run's cap: `w = min(v + a·T_f, cap)`.
    fn reach_in_t_f(&self, v_mm_s: f64, a_mm_s2: f64) -> f64 {
        (v_mm_s + a_mm_s2 * self.t_f).min(self.cap_mm_s).max(v_mm_s)
    }

    /// Whether the tangential acceleration `a_mm_s2` keeps the axes within their budgets
    /// where the element runs at most at `v_mm_s` (see [`acc_at`](Self::acc_at)); then also
    /// at any lower speed.
    pub(super) fn valid_at(&self, a_mm_s2: f64, v_mm_s: f64) -> bool {
        a_mm_s2 <= self.acc_raw(self.reach_in_t_f(v_mm_s, a_mm_s2))
    }

    /// Sets `p`'s use of the axes for the curve at speed `v_mm_s`: the acceleration
    /// `a_t·|Tᵢ| + v²κ·|Nᵢ|` and the jerk `(2·a_t/T_f + v³κ²)·|Tᵢ| + 3·v·κ·a_t·|Nᵢ|` of each
    /// axis with the acceleration `a_t` it plans with at that speed, at least the line's own.
    pub(super) fn use_at(p: &mut Pending, v_mm_s: f64, t_f: f64) {
        let Some(fit) = p.curve_fit.as_mut() else {
            return;
        };
        fit.v_mm_s = v_mm_s;
        let k = fit.kappa;
        let a_t = fit.acc_at(v_mm_s);
        let (a_n, j_curve) = (v_mm_s * v_mm_s * k, v_mm_s * v_mm_s * v_mm_s * k * k);
        let j_t = 2.0 * a_t / t_f;
        for i in 0..3 {
            let (t_i, n_i) = (fit.tangent[i].abs(), fit.normal[i].abs());
            p.acc_used_mm_s2[i] = fit.base_acc_used_mm_s2[i].max(a_t * t_i + a_n * n_i);
            p.jerk_used_mm_s3[i] = fit.base_jerk_used_mm_s3[i].max(
                (j_t + j_curve) * t_i
                    + v_mm_s * v_mm_s * v_mm_s * fit.rate[i].abs()
                    + 3.0 * v_mm_s * k * a_t * n_i,
            );
        }
    }
}

/// The highest speed `p` may reach from `v_from_mm_s` over its length (the end speed from a
/// start, or a start speed back from an end: the same reach) within `vmax_mm_s`, and the
/// tangential acceleration that reaches it: with no curve, the element's own; on a chord run
/// taken as a curve, one that its curve allows up to the speed reached
/// ([`CurveFit::valid_at`]), the largest speed of a speed change being at its faster end.
/// `None` where [`super::profile::max_end_speed`] has none (a start above `vmax_mm_s`).
pub(super) fn reach_mm_s(p: &Pending, v_from_mm_s: f64, vmax_mm_s: f64) -> Option<(f64, f64, f64)> {
    let reach = |a: f64| {
        ProfileLimits::trapezoid(vmax_mm_s, a)
            .and_then(|l| super::profile::max_end_speed(p.seg.length_mm, v_from_mm_s, &l))
    };
    let a_static = p.limits.a_max_mm_s2();
    let v_static = reach(a_static)?;
    // [`reach_with`] asks again for the reach with the element's own acceleration, and may
    // ask twice for another one (the floor's where the pair kept is the floor's, as
    // [`Planner::memo_pushed`] leaves it): each is computed once, the reach being a function
    // of the acceleration alone here (`max_end_speed` was 13 % of the look-ahead's time on
    // tiny segments).
    let last = std::cell::Cell::new((f64::NAN, f64::NAN));
    Some(reach_with(p, |a| {
        if a == a_static {
            return v_static;
        }
        let (a_last, v_last) = last.get();
        if a == a_last {
            return v_last;
        }
        let v = reach(a).unwrap_or(v_from_mm_s);
        last.set((a, v));
        v
    }))
}

/// One step of the look-ahead's backward pass: the highest start speed of `p`, within its
/// start's cap `cap_mm_s`, from which it can end at `v_next_mm_s`, or at its own speed limit
/// where that is lower (the bound after it holds for every lower speed too); on a line of a
/// chord run, with the acceleration it takes (NaN elsewhere) and the pair it keeps
/// ([`Pending::reach_memo`]; `None` where there is none to keep). A bound above the limit
/// found no profile, and the pass came down to rest there: a line split in two keeps its
/// feed as the cap of the junction inside it, above its first part's limit where a curve
/// lowered that, and the plan could no longer come down to the first part from the speed
/// it had settled (`NoProfile` on a random chorded profile, seen at 1500 cases).
pub(super) fn back_reach(
    p: &Pending,
    v_next_mm_s: f64,
    cap_mm_s: f64,
) -> (f64, f64, Option<(f64, f64)>) {
    let v_next_mm_s = v_next_mm_s.min(p.limits.v_max_mm_s());
    if p.curve_acc.is_none() {
        let v = super::start_reach_mm_s(p.seg.length_mm, v_next_mm_s, cap_mm_s, &p.limits);
        return (v, f64::NAN, None);
    }
    let (v, a, valid) =
        reach_mm_s(p, v_next_mm_s, p.limits.v_max_mm_s()).unwrap_or((0.0, f64::NAN, 0.0));
    (v.min(cap_mm_s), a, a.is_finite().then_some((a, valid)))
}

/// A step of the backward pass with the pairs known valid: the floor's, the acceleration
/// valid at every speed up to the element's speed limit ([`Pending::acc_floor_mm_s2`]), and
/// the one kept last ([`Pending::reach_memo`]), whichever reaches higher, with that pair. A
/// lower bound of [`back_reach`]'s speed for one or two speed changes (no curve's acceleration
/// to find); the look-ahead's passes, which take the pair as a candidate, never find less.
/// `None` where `p` is no line of a chord run or `v_next_mm_s` is above its limit.
#[inline]
pub(super) fn floor_back_reach(
    p: &Pending,
    v_next_mm_s: f64,
    cap_mm_s: f64,
) -> Option<(f64, (f64, f64))> {
    p.curve_acc.as_ref()?;
    let v_max = p.limits.v_max_mm_s();
    let a_static = p.limits.a_max_mm_s2();
    let reach = |a: f64| {
        ProfileLimits::trapezoid(v_max, a)
            .and_then(|l| super::profile::max_end_speed(p.seg.length_mm, v_next_mm_s, &l))
    };
    let a = a_static.min(p.acc_floor_mm_s2);
    let mut best = (reach(a)?, (a, v_max));
    if let Some((a_m, valid)) = p.reach_memo {
        let a_m = a_m.min(a_static);
        // Most often the pair kept is the floor's own ([`Planner::memo_pushed`]): the same
        // reach, which cannot reach higher within `valid`.
        if a_m == a {
            return Some((best.0.min(cap_mm_s), best.1));
        }
        let v = reach(a_m)?.min(valid);
        if v > best.0 {
            best = (v, (a_m, valid));
        }
    }
    Some((best.0.min(cap_mm_s), best.1))
}

/// A lower bound of [`reach_mm_s`]'s speed, without a speed limit: `√(v² + 2·a·L)` with the
/// acceleration the element may plan with at any speed up to its cap
/// ([`Pending::acc_floor_mm_s2`]). Cheap: the walks back through a braking distance
/// ([`Planner::can_come_down`]) take it element by element; the look-ahead's backward pass
/// reaches at least as high.
pub(super) fn reach_free_mm_s(p: &Pending, v_from_mm_s: f64) -> f64 {
    let a = p.limits.a_max_mm_s2().min(p.acc_floor_mm_s2);
    (v_from_mm_s * v_from_mm_s + 2.0 * a * p.seg.length_mm).sqrt()
}

/// [`reach_mm_s`]'s speed without a speed limit: `√(v² + 2·a·L)` with the acceleration the
/// look-ahead's backward pass would take ([`reach_with`]).
pub(super) fn reach_exact_mm_s(p: &Pending, v_from_mm_s: f64) -> f64 {
    reach_with(p, |a| {
        (v_from_mm_s * v_from_mm_s + 2.0 * a * p.seg.length_mm).sqrt()
    })
    .0
}

/// The direction of the chord whose midpoint is nearest to `at_mm` along the path (the
/// first of equally near ones), by bisection: the chords' midpoints rise along the run.
fn nearest_chord(chords: &VecDeque<(Vector3<f64>, f64)>, at_mm: f64) -> Option<Vector3<f64>> {
    let d = |k: usize| (chords[k].1 - at_mm).abs();
    // The first midpoint at or beyond `at_mm`; the distances fall before it and rise from it.
    let after = chords.partition_point(|&(_, s)| s < at_mm);
    let mut best = after.checked_sub(1);
    while let Some(k) = best
        && k > 0
        && d(k - 1) == d(k)
    {
        best = Some(k - 1);
    }
    let best = match best {
        Some(k) if after < chords.len() && d(after) < d(k) => after,
        Some(k) => k,
        None if after < chords.len() => after,
        None => return None,
    };
    Some(chords[best].0)
}

/// Sets `p`'s [`Pending::acc_floor_mm_s2`] for its curve and its cap.
pub(super) fn refresh_floor(p: &mut Pending) {
    p.acc_floor_mm_s2 = p
        .curve_acc
        .as_ref()
        .map_or(f64::INFINITY, |fit| fit.acc_at(p.limits.v_max_mm_s()));
}

/// The reach `(speed, acceleration)` with `reach` giving the speed an acceleration reaches,
/// and the speed up to which that acceleration is known valid: the curve's acceleration where
/// its own reach with its largest one ends (valid there, so at the lower speed it reaches
/// too), then, where it is valid at the speed it reaches, the curve's acceleration at that
/// lower speed, and where it is not, the highest speed `v` that the acceleration valid up to
/// `v` reaches (by bisection: where the curve leaves next to nothing at the first speed, a
/// line of 1.2 mm before a stop on `stellabee1` crawled at 1.9 mm/s for 1.27 s); or the pair
/// the backward pass took last ([`Pending::reach_memo`]) within the speed it is valid to,
/// whichever reaches higher. With the last pair a candidate, the
/// backward pass's bound at an element never falls as the bound after it rises, so the
/// speed the plan settled at the window's start stays within it (the odd iterates alone
/// are not monotone in the speed they start from).
fn reach_with(p: &Pending, reach: impl Fn(f64) -> f64) -> (f64, f64, f64) {
    let a_static = p.limits.a_max_mm_s2();
    let Some(fit) = p.curve_acc.as_ref() else {
        return (reach(a_static), a_static, f64::INFINITY);
    };
    // The last pair, where it reaches about as high as it is valid: a fresh one could hardly
    // do better (the look-ahead's passes meet most elements several times at such speeds).
    let memo = p.reach_memo.map(|(a_m, v_valid)| {
        let a_m = a_m.min(a_static);
        (reach(a_m), a_m, v_valid)
    });
    let a_floor = a_static.min(p.acc_floor_mm_s2);
    if let Some(m) = memo
        && m.0 <= m.2
        && m.0 >= MEMO_TIGHT * m.2
        && m.1 >= a_floor
    {
        return m;
    }
    let memo = memo.map(|(v, a, v_valid)| (v.min(v_valid), a, v_valid));
    let v_up = reach(a_static);
    let a1 = a_static.min(fit.acc_at(v_up));
    let v1 = reach(a1);
    let mut best = (v1, a1, v_up);
    // The acceleration valid up to the cap, which the walks back take.
    let v_floor = reach(a_floor);
    if v_floor > best.0 {
        best = (v_floor, a_floor, p.limits.v_max_mm_s());
    }
    let a2 = a_static.min(fit.acc_at(v1));
    if a2 > a1 {
        let v2 = reach(a2);
        if fit.valid_at(a2, v2) {
            best = (v2, a2, v2);
        } else if v1 >= best.0 {
            // Between the two: the highest speed `v` the acceleration valid up to `v`
            // reaches (`reach(a(v)) ≥ v`, `a(v)` falling with `v`), by bisection.
            let (mut lo, mut hi) = (v1, v2);
            for _ in 0..FIXED_POINT_STEPS {
                let mid = 0.5 * (lo + hi);
                if reach(a_static.min(fit.acc_at(mid))) >= mid {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            if lo > v1 {
                best = (lo, a_static.min(fit.acc_at(lo)), lo);
            }
        }
    }
    match memo {
        Some(m) if m.0 > best.0 => m,
        _ => best,
    }
}

/// Times at most the curvature rate's baseline is shortened to the span of the axis filters
/// at the cap it gives ([`Planner::curve_estimate`]).
const RATE_ROUNDS: usize = 3;

/// A baseline is shortened again only where the cap shortens it below this share of the last.
const RATE_SHRINK: f64 = 0.9;

/// The curvature rate is taken over a shorter baseline (from the nearest estimate within it)
/// where the nearest estimate a baseline back lies further than this many baselines
/// ([`Planner::curve_estimate`]).
const RATE_FAR: f64 = 1.5;

/// Most steps of [`CurveFit::acc_at`]'s search for its fixed point, and the relative width of
/// the bracket at which it stops.
const ACC_STEPS: usize = 16;
const ACC_TOL: f64 = 0.01;

/// Bisection steps of [`reach_with`]'s search for the speed the curve's acceleration reaches
/// where it is valid.
const FIXED_POINT_STEPS: usize = 12;

/// [`reach_with`] takes the last pair as it is where it reaches this share of the speed it is
/// valid to.
const MEMO_TIGHT: f64 = 0.99;

/// A line's curve at a vertex (tangent `tangent`, curvature vector `kappa`, curvature rate
/// `rate`): its cap and what it uses of each axis at a speed; `None` where it does not turn
/// or leaves no tangential acceleration at its cap.
fn curve_limits(
    planner: &Planner,
    tangent: Vector3<f64>,
    kappa: Vector3<f64>,
    rate: Vector3<f64>,
    v_max_mm_s: f64,
    smoothing: &Smoothing,
) -> Option<CurveFit> {
    let k = kappa.norm();
    if !(k > 0.0 && k.is_finite()) {
        return None;
    }
    let n = kappa / k;
    let cfg = &planner.config;
    let t_f = smoothing.time_law_s(cfg.period_s);
    let acc_budget_mm_s2 = planner.limits.max_acc_mm_s2 * CURVE_ACC_BUDGET;
    let jerk_budget_mm_s3 = cfg.max_jerk_mm_s3 * CURVE_JERK_BUDGET;
    // The cap: each axis's part of the centripetal acceleration `v²κ·|Nᵢ|` within
    // [`CENTRIPETAL_SHARE`] of its budget, and of the jerk of following the curve,
    // `v³κ²·|Tᵢ|`, within [`CURVE_JERK_SHARE`].
    let (mut v2, mut v3) = (f64::INFINITY, f64::INFINITY);
    for i in 0..3 {
        let (t_i, n_i) = (tangent[i].abs(), n[i].abs());
        if n_i > 0.0 {
            v2 = v2.min(CENTRIPETAL_SHARE * acc_budget_mm_s2[i] / (k * n_i));
        }
        let q_i = k * k * t_i + rate[i].abs();
        if q_i > 0.0 {
            v3 = v3.min(CURVE_JERK_SHARE * jerk_budget_mm_s3[i] / q_i);
        }
    }
    let v = super::min_cbrt(v2.sqrt(), v3);
    let fit = CurveFit {
        tangent,
        normal: n,
        kappa: k,
        rate,
        charge: Charge::of(tangent, n, k, rate),
        acc_mm_s2: cfg.path_acc_mm_s2,
        base_acc_used_mm_s2: Vector3::zeros(),
        base_jerk_used_mm_s3: Vector3::zeros(),
        v_mm_s: v.min(v_max_mm_s),
        acc_budget_mm_s2,
        jerk_budget_mm_s3,
        t_f,
        cap_mm_s: v,
    };
    // What the budgets leave for the tangential acceleration at the cap: the run's speed may
    // still change there, slowly (on a straight run, a line's `J·T_f/2`).
    if !(v.is_finite() && v > 0.0 && fit.acc_raw(v) > 0.0) {
        return None;
    }
    Some(fit)
}

impl Planner {
    /// Keeps, for the lines of chord runs among the window's last `count` elements (just
    /// pushed), their floor's pair ([`floor_back_reach`], [`Pending::reach_memo`]) and the
    /// mark of a backward pass from a stop at the window's end with it: their bounds then
    /// never fall below that as the bound after them rises with more elements ([`reach_with`]
    /// alone is not monotone in it), so that what the walks check against now (the floor,
    /// [`Planner::can_come_down`]) stays within reach.
    pub(super) fn memo_pushed(&mut self, count: usize) {
        let n = self.window.len();
        let mut v_next = 0.0;
        for k in (n.saturating_sub(count)..n).rev() {
            let e = &mut self.window[k];
            let cap = e.cap_start_mm_s;
            let Some((start, pair)) = floor_back_reach(e, v_next, cap) else {
                return;
            };
            e.reach_memo = Some(pair);
            e.pass_mark = PassMark::of(e, start, v_next, cap);
            v_next = start;
        }
    }

    /// Takes the vertex from the window's last element into `p` as a point of a curve where
    /// it is one: caps the last element (and those within reach of it) with the curve's
    /// limits, records the cap for the elements to come, and marks the vertex covered
    /// ([`Pending::curve_fit`]); returns the junction's own limit with the curve taken
    /// (`None`: not taken, nothing changed but the run's record). Jerk-limited mode only.
    pub(super) fn take_curve_vertex(&mut self, p: &mut Pending) -> Option<f64> {
        let taken = self.take_curve_vertex_inner(p);
        if taken.is_none() {
            self.hold_on(p);
        }
        taken
    }

    /// A line whose vertex is not taken as a point of a curve (the run's end, a vertex that
    /// turns too much or whose chords are too sparse, a computed one) but that starts within
    /// the time-law filter's reach of the curves held ahead plans its tangential acceleration
    /// with their charges ([`CurveState::worst_ahead`]) as a line of the run does: the filter's
    /// window mixes its acceleration with theirs. A line that goes well beyond the last charge
    /// held ahead ([`SPLIT_BEYOND`]) is split where it ends, and only the part within takes
    /// the charges; the rest stays under the cap that held the whole line where one did
    /// ([`Planner::erode_ahead`]). A line the caps do not hold whole and that cannot be split
    /// so (the charges reach beyond the caps) keeps its own acceleration, as before session
    /// 23, when every such line did (no failure seen; splitting them costs the corpus 0.03 %).
    fn hold_on(&mut self, p: &mut Pending) {
        let (Some(smoothing), Some(template)) = (self.smoothing, self.curve.last_fit) else {
            return;
        };
        let at_mm = self.curve.pushed_mm;
        if p.curve_acc.is_some()
            || !chord(p)
            || !self
                .curve
                .ahead_fits
                .iter()
                .any(|&(until, _)| until > at_mm)
        {
            return;
        }
        let Some(cap) = self.curve.cap_at(at_mm) else {
            return;
        };
        let t_f = smoothing.time_law_s(self.config.period_s);
        // Only the part of the line within the reach of the charges held ahead needs them: a
        // line that goes well beyond is split where the last of them ends, the rest planned
        // as any line beyond, within the cap that holds the whole line where one does (a line
        // of 3.2 mm after a stop crawled at 2 mm/s for 2.8 s on `LHchips4`: a later curve's
        // walk back took it whole, with the charge of that tight curve).
        let held_whole = p.seg.length_mm <= cap * t_f;
        let reach_mm = self.curve.fits_until_mm(at_mm) - at_mm;
        if reach_mm > 0.0
            && reach_mm <= cap * t_f
            && p.seg.length_mm > SPLIT_BEYOND * reach_mm
            && let Some((head, mut rest)) = super::split_line(p, reach_mm)
        {
            if held_whole {
                super::cap_speed(&mut rest, cap, cap);
            }
            *p = head;
            self.curve.held_rest = Some(rest);
        } else if !held_whole {
            return;
        }
        // The budgets of the curves taken; the line's own charge is its tangent's alone.
        let straight = CurveFit {
            tangent: p.tangent_start,
            normal: Vector3::zeros(),
            kappa: 0.0,
            rate: Vector3::zeros(),
            charge: Charge::of(p.tangent_start, Vector3::zeros(), 0.0, Vector3::zeros()),
            acc_mm_s2: p.limits.a_max_mm_s2(),
            cap_mm_s: f64::INFINITY,
            ..template
        };
        let fit = self
            .curve
            .worst_ahead(at_mm, straight)
            .within(p.limits.v_max_mm_s().min(cap));
        if fit.acc_raw(fit.cap_mm_s) <= 0.0 {
            return;
        }
        p.curve_acc = Some(fit);
        p.reach_memo = None;
        refresh_floor(p);
    }

    fn take_curve_vertex_inner(&mut self, p: &mut Pending) -> Option<f64> {
        let smoothing = self.smoothing?;
        let Some(prev) = self.window.back() else {
            self.curve.end_run();
            return None;
        };
        let du = p.tangent_start - prev.tangent_end;
        let vertex = chord(prev)
            && chord(p)
            && self.config.corner_acc_mm_s2 > 0.0
            && !matches!(prev.blend, BlendMode::ExactStop | BlendMode::ExactPath)
            && du.norm() <= CURVE_MAX_TURN;
        let p_mid = self.curve.pushed_mm + 0.5 * p.seg.length_mm;
        if !vertex {
            self.curve.end_run();
            if chord(p) {
                self.curve
                    .push_chord(p.tangent_start, p_mid, p.seg.length_mm);
            }
            return None;
        }
        if self.curve.chords.is_empty() {
            let mid = self.curve.pushed_mm - 0.5 * prev.seg.length_mm;
            self.curve
                .push_chord(prev.tangent_end, mid, prev.seg.length_mm);
        }
        self.curve
            .push_chord(p.tangent_start, p_mid, p.seg.length_mm);
        let (estimate, s_vertex_mm) = self.curve_estimate(prev, &smoothing)?;
        // Every estimate goes into the record the curvature's rate is taken from, the vertex
        // taken or not: a rate over a baseline that skipped the vertices not taken reached
        // back to the last one taken, and understated a curvature that turns between.
        if self.curve.kappas.len() >= CHORD_HISTORY {
            self.curve.kappas.pop_front();
        }
        self.curve
            .kappas
            .push_back((estimate.curvature(), s_vertex_mm));
        // Dense chords only: at least two within the axis filters' reach at the speed the
        // curve allows, so that the filters' output follows the curve. Sparser vertices are
        // steps of the axis velocity each, which the junction rules hold.
        let mean_mm = 0.5 * (prev.seg.length_mm + p.seg.length_mm);
        let tk = smoothing.axis_s(self.config.period_s);
        let v_dense = estimate.cap_mm_s.min(prev.limits.v_max_mm_s());
        if 2.0 * mean_mm > v_dense * tk {
            return None;
        }
        // Nor where the vertex's own rules, before the curve is taken, hold the speed so low
        // that the chords are sparse there: the rounding of the written coordinates (a turn
        // far from the curve's) then binds vertex by vertex, as the junction rules have it.
        if 2.0 * mean_mm > self.junction_limit_mm_s(prev, p) * tk {
            return None;
        }
        // The curve taken tentatively: the element's use of the axes for it at the speed it
        // may run, and the vertex's own rules with it.
        let t_f = smoothing.time_law_s(self.config.period_s);
        let (acc_used, jerk_used) = (prev.acc_used_mm_s2, prev.jerk_used_mm_s3);
        let mut fit = estimate;
        // Its tangential acceleration by its other rules, a ceiling.
        fit.acc_mm_s2 = prev.limits.a_max_mm_s2();
        fit.base_acc_used_mm_s2 = acc_used;
        fit.base_jerk_used_mm_s3 = jerk_used;
        let prev = self.window.back_mut().expect("checked above");
        prev.curve_fit = Some(fit);
        CurveFit::use_at(prev, fit.v_mm_s, t_f);
        let prev = self.window.back().expect("checked above");
        let own_mm_s = self.junction_limit_mm_s(prev, p);
        let cap = on_grid(fit.cap_mm_s);
        if 2.0 * mean_mm > own_mm_s * tk || !self.erode_back(cap, &smoothing) {
            let prev = self.window.back_mut().expect("checked above");
            prev.curve_fit = None;
            (prev.acc_used_mm_s2, prev.jerk_used_mm_s3) = (acc_used, jerk_used);
            return None;
        }
        // The time-law filter's output at a point is made of the plan's accelerations up to
        // `cap·T_f/2` either side of it (module documentation): the lines within that of
        // the vertex plan their tangential acceleration with its curve too, those before it
        // here, those after it as they come. Where the charge taken back last covers the
        // vertex's, from as far back and held ahead up to the line before the vertex, the
        // lines within reach already plan with at least this curve's: it is held further
        // ahead, and the walk back is not needed.
        let fit_reach_mm = 0.5 * cap * t_f;
        let wide = fit.charge.widened(fit.kappa);
        let from_mm = self.curve.pushed_mm - fit_reach_mm;
        let prev_start_mm =
            self.curve.pushed_mm - self.window.back().expect("checked above").seg.length_mm;
        let until_mm = self.curve.pushed_mm + fit_reach_mm;
        // Ahead, no element with X/Y/Z motion runs above the max feed: a gentle curve's cap
        // far above it held its charge up to 147 mm ahead, over a 6.8 mm Z line after a stop
        // that then crawled at 6 mm/s for 2 s (`3D_Chips`, session 25).
        let held_cap = cap.min(self.limits.max_feed_mm_s);
        let hold_until_mm = self.curve.pushed_mm + 0.5 * held_cap * t_f;
        let covering = self
            .curve
            .last_back
            .filter(|&(back_from_mm, last_until_mm, c)| {
                back_from_mm <= from_mm
                    && from_mm - back_from_mm <= fit_reach_mm
                    && prev_start_mm < last_until_mm
                    && c.covers(&fit.charge)
            });
        if let Some((back_from_mm, last_until_mm, c)) = covering {
            if until_mm > last_until_mm {
                self.curve.last_back = Some((back_from_mm, until_mm, c));
                self.curve.hold_fit_ahead(hold_until_mm, c);
            }
        } else {
            // The walk goes a little further back than the reach ([`BACK_MARGIN`]), whose
            // noise would otherwise end the cover at most vertices.
            let back_from_mm = self.curve.pushed_mm - BACK_MARGIN * fit_reach_mm;
            if !self.merge_back(&fit.charge, &wide, self.curve.pushed_mm - back_from_mm) {
                let prev = self.window.back_mut().expect("checked above");
                prev.curve_fit = None;
                (prev.acc_used_mm_s2, prev.jerk_used_mm_s3) = (acc_used, jerk_used);
                return None;
            }
            self.curve.last_back = Some((back_from_mm, until_mm, wide));
            self.curve.hold_fit_ahead(hold_until_mm, wide);
        }
        self.hold_cap_ahead(cap, t_f);
        // The element after the vertex plans with the tangential acceleration the curve
        // leaves at its speed ([`Pending::curve_acc`]), and that of every curve held ahead
        // over it; not passed on through further junctions beyond the time-law filter's
        // reach, as the lower of two accelerations is, since one noisy vertex would slow a
        // whole run.
        let mut fit_p = fit.with_tangent(p.tangent_start);
        fit_p.acc_mm_s2 = p.limits.a_max_mm_s2();
        let mut fit_p = self.curve.worst_ahead(self.curve.pushed_mm, fit_p);
        // The caps held ahead hold `p` where it is within their reach (`erode_ahead`).
        if let Some(c) = self.curve.cap_at(self.curve.pushed_mm)
            && p.seg.length_mm <= c * t_f
        {
            fit_p = fit_p.within(c);
        }
        p.curve_acc = Some(fit_p);
        p.reach_memo = None;
        refresh_floor(p);
        self.curve.last_fit = Some(fit);
        let prev = self.window.back().expect("checked above");
        if prev.curve_acc.is_none() {
            // The run's first vertex: the element before takes its curve where the plan can
            // still stop at its end.
            let mut last = *prev;
            let mut fit_prev = fit;
            fit_prev.acc_mm_s2 = prev.limits.a_max_mm_s2();
            let start_mm = self.curve.pushed_mm - prev.seg.length_mm;
            let fit_prev = self
                .curve
                .worst_ahead(start_mm, fit_prev)
                .within(prev.limits.v_max_mm_s());
            last.curve_acc = Some(fit_prev);
            refresh_floor(&mut last);
            // The pair the look-ahead's pass takes from a stop at its end: its bound then
            // never falls below that as the bound after it rises ([`reach_with`]).
            let reach =
                reach_mm_s(&last, 0.0, last.limits.v_max_mm_s()).filter(|r| r.1.is_finite());
            last.reach_memo = reach.map(|(_, a, valid)| (a, valid));
            last.pass_mark = reach.and_then(|(v, _, _)| {
                let cap = last.cap_start_mm_s;
                PassMark::of(&last, v.min(cap), 0.0, cap)
            });
            if self.can_stop_with(&last) {
                *self.window.back_mut().expect("checked above") = last;
            }
        }
        Some(own_mm_s)
    }

    /// Makes the lines of chord runs within `reach_mm` before the window's end whose charge
    /// does not cover `charge` plan their tangential acceleration with `wide` too
    /// ([`CurveFit::worst`]), where the look-ahead's backward pass from a stop at the
    /// window's end still comes down to the speed the plan has settled with the
    /// accelerations lowered; `false`, with nothing changed, where it could not.
    fn merge_back(&mut self, charge: &Charge, wide: &Charge, reach_mm: f64) -> bool {
        let n = self.window.len();
        let mut behind_mm = 0.0;
        let mut first = n;
        let mut k = n;
        while k > 0 && behind_mm < reach_mm {
            k -= 1;
            let e = &self.window[k];
            if e.curve_acc
                .as_ref()
                .is_some_and(|f| !f.charge.covers(charge))
            {
                first = k;
            }
            behind_mm += e.seg.length_mm;
        }
        if first == n {
            return true;
        }
        // In place, with what changed kept to undo it where the plan could not stop.
        let mut undo = std::mem::take(&mut self.curve.undo);
        undo.clear();
        // The lines whose charge `wide` covers take it as it is, and share one floor: the
        // acceleration valid at the highest of their caps is valid at each's
        // ([`CurveFit::acc_at`] falls as the cap rises).
        let mut shared: Option<CurveFit> = None;
        let mut shared_v_max = 0.0;
        for (k, e) in self.window.range_mut(first..).enumerate() {
            // In place: a curve is large, and copying it in and out cost more than the rest.
            let Some(merged) = e.curve_acc.as_mut().filter(|f| !f.charge.covers(charge)) else {
                continue;
            };
            let was = merged.charge;
            undo.push(Changed {
                at: first + k,
                charge: was,
                memo: e.reach_memo,
                floor_mm_s2: e.acc_floor_mm_s2,
            });
            // Its speed is held within its limits (the erosion of the caps of the curves
            // within reach among them): the acceleration need hold up to there only
            // (`worst(wide).within(v_max)`).
            let v_max = e.limits.v_max_mm_s();
            merged.charge = was.sup(wide);
            merged.cap_mm_s = merged.cap_mm_s.min(v_max);
            e.reach_memo = None;
            if wide.covers(&was) {
                match shared.as_mut() {
                    None => (shared, shared_v_max) = (Some(*merged), v_max),
                    Some(s) if s.same_but_cap(merged) && shared_v_max == v_max => {
                        s.cap_mm_s = s.cap_mm_s.max(merged.cap_mm_s);
                        e.acc_floor_mm_s2 = f64::NAN;
                        continue;
                    }
                    Some(_) => {}
                }
            }
            refresh_floor(e);
        }
        if let Some(s) = shared {
            let floor = s.acc_at(shared_v_max);
            for &Changed { at: k, .. } in &undo {
                let e = &mut self.window[k];
                if e.acc_floor_mm_s2.is_nan() {
                    e.acc_floor_mm_s2 = floor;
                }
            }
        }
        // The look-ahead's backward pass, from a stop at the window's end: the plan must
        // still come down to the speed it has settled at the window's start. Each line of a
        // run keeps the pair it takes ([`Pending::reach_memo`]), as in the look-ahead, so
        // that its bound never falls below this one as the bound after it rises (a line's
        // reach with its best acceleration is not monotone in the speed after it, and the
        // bounds after the lines changed may have fallen).
        let mut memos = std::mem::take(&mut self.curve.memos);
        memos.clear();
        // The pairs known valid first ([`floor_back_reach`]); where that does not come
        // down, the pass's own (the curve's acceleration at each line's speed).
        let mut ok = false;
        for floor in [true, false] {
            memos.clear();
            ok = self.backward_pass_reaches_start(&mut memos, floor);
            for &(k, memo, mark) in memos.iter().rev().filter(|_| !ok) {
                let e = &mut self.window[k];
                (e.reach_memo, e.pass_mark) = (memo, mark);
            }
            if ok {
                break;
            }
        }
        if !ok {
            for &Changed {
                at: k,
                charge,
                memo,
                floor_mm_s2: floor,
            } in &undo
            {
                let e = &mut self.window[k];
                if let Some(f) = e.curve_acc.as_mut() {
                    f.charge = charge;
                }
                e.reach_memo = memo;
                e.acc_floor_mm_s2 = floor;
            }
        }
        self.curve.memos = memos;
        self.curve.undo = undo;
        ok
    }

    /// The look-ahead's backward pass ([`Planner::replan`]) from a stop at the window's end,
    /// keeping each line's pair ([`Pending::reach_memo`]) and each element's mark
    /// ([`Pending::pass_mark`]; those they had, with their window's indices, in `memos`):
    /// whether it comes down to the speed the plan has settled at the window's start. It
    /// stops where the marks before it show that it would ([`Planner::marks_come_down`]).
    fn backward_pass_reaches_start(&mut self, memos: &mut Vec<Visited>, floor: bool) -> bool {
        let mut v_next = 0.0;
        // The highest link of the marks known to fail: the chain is looked at again once the
        // pass has come down to it.
        let mut failing = isize::MAX;
        for k in (0..self.window.len()).rev() {
            let e = &mut self.window[k];
            let cap = if k == 0 {
                f64::INFINITY
            } else {
                e.cap_start_mm_s
            };
            // With the pairs known valid first: one or two speed changes a line.
            let (v, pair) = floor
                .then(|| floor_back_reach(e, v_next, cap))
                .flatten()
                .map(|(v, pair)| (v, Some(pair)))
                .unwrap_or_else(|| {
                    let (v, _, pair) = back_reach(e, v_next, cap);
                    (v, pair)
                });
            memos.push((k, e.reach_memo, e.pass_mark));
            if pair.is_some() {
                e.reach_memo = pair;
            }
            e.pass_mark = PassMark::of(e, v, v_next, cap);
            v_next = v;
            if k > 0 && failing >= k as isize - 1 {
                match self.marks_come_down(k, v) {
                    Ok(()) => {
                        // Every link below the first holds, whatever the pass finds later.
                        self.window.set_marks_ok(k - 1, self.v_settled_mm_s);
                        return true;
                    }
                    Err(j) => failing = j,
                }
            }
        }
        v_next >= self.v_settled_mm_s
    }

    /// Whether the marks of the window's elements before `k` ([`Pending::pass_mark`]) show
    /// that the backward pass, at `v_mm_s` at `k`'s start, comes down to the speed the plan
    /// has settled: each still its element's, its end within the start after it (which no
    /// pass makes faster than the element's speed limit), the first's start at least the
    /// settled speed. `Err` with the highest link that fails (−1: the settled speed).
    fn marks_come_down(&self, k: usize, v_mm_s: f64) -> Result<(), isize> {
        // The links from the window's start that an earlier walk found to hold, the elements
        // unchanged since ([`super::window::Window`]).
        let ok_below = self.window.marks_ok_below(self.v_settled_mm_s);
        let mut start = v_mm_s;
        for j in (0..k).rev() {
            // Past the first link (from `v_mm_s`), each link is the one checked before.
            if j + 1 < k && j < ok_below {
                return Ok(());
            }
            let e = &self.window[j];
            let cap = if j == 0 {
                f64::INFINITY
            } else {
                e.cap_start_mm_s
            };
            match e.pass_mark {
                Some(m)
                    if m.end_mm_s <= start
                        && m.holds(e, cap)
                        && self.window[j + 1].cap_start_mm_s <= e.limits.v_max_mm_s() =>
                {
                    start = m.start_mm_s;
                }
                _ => return Err(j as isize),
            }
        }
        if start >= self.v_settled_mm_s {
            Ok(())
        } else {
            Err(-1)
        }
    }

    /// Whether the window's last element may plan with the acceleration `acc_mm_s2`: the
    /// plan must still stop at its end from the speed it has settled
    /// ([`can_stop_with`](Self::can_stop_with)).
    pub(super) fn can_lower_last(&self, acc_mm_s2: f64) -> bool {
        let Some(last) = self.window.back() else {
            return true;
        };
        let mut last = *last;
        super::lower_acceleration(&mut last, acc_mm_s2);
        self.can_stop_with(&last)
    }

    /// Whether the plan could still stop at the window's end from the speed it has settled
    /// with `last` in place of the window's last element: back from that stop at each
    /// element's acceleration ([`reach_free_mm_s`]) to a junction whose own cap is lower
    /// (nothing before it changes) or to the window's start.
    pub(super) fn can_stop_with(&self, last: &Pending) -> bool {
        let n = self.window.len();
        if n == 0 {
            return true;
        }
        // The cheap bound first; where it does not reach, the backward pass's own.
        self.come_down(n - 1, reach_free_mm_s(last, 0.0), reach_free_mm_s)
            || self.come_down(n - 1, reach_exact_mm_s(last, 0.0), reach_exact_mm_s)
    }

    /// Whether the plan can still come down to `to_mm_s` at the start of the window's
    /// element `at` from the speed it has settled: back from there at each element's
    /// acceleration ([`reach_free_mm_s`]) to a junction whose own cap is lower (nothing before
    /// it changes) or to the window's start.
    pub(super) fn can_come_down(&self, at: usize, to_mm_s: f64) -> bool {
        if at == 0 {
            return self.v_settled_mm_s <= to_mm_s;
        }
        self.come_down(
            at - 1,
            reach_free_mm_s(&self.window[at - 1], to_mm_s),
            reach_free_mm_s,
        )
    }

    /// [`can_come_down`](Self::can_come_down) with `bound` the highest speed at the start of
    /// the element `k` from which the plan comes down.
    fn come_down(&self, mut k: usize, mut bound: f64, reach: fn(&Pending, f64) -> f64) -> bool {
        loop {
            let start = if k == 0 {
                self.v_settled_mm_s
            } else {
                self.window[k].cap_start_mm_s
            };
            if start <= bound {
                return true;
            }
            if k == 0 {
                return false;
            }
            k -= 1;
            bound = reach(&self.window[k], bound);
        }
    }

    /// The junction's own limit from the window's last element, a line of a chord run taken
    /// as a curve, into `p`: its rules charge what the curve uses of each axis at the speed
    /// through the junction, which is lower where the vertex's own rules bind, and a lower use
    /// leaves them more. The largest speed `v` whose own limit with the use at `v` is at
    /// least `v` (a few bisection steps from the limit with the use at the element's speed,
    /// which is valid); the element keeps the use at that speed.
    pub(super) fn curve_junction_mm_s(&mut self, p: &Pending, own_mm_s: f64) -> f64 {
        let (Some(smoothing), Some(prev)) = (self.smoothing, self.window.back()) else {
            return own_mm_s;
        };
        let Some(fit) = prev.curve_fit else {
            return own_mm_s;
        };
        if own_mm_s >= fit.v_mm_s {
            return own_mm_s;
        }
        let t_f = smoothing.time_law_s(self.config.period_s);
        let own_at = |planner: &mut Planner, v: f64| {
            let a = planner.window.back_mut().expect("checked above");
            CurveFit::use_at(a, v, t_f);
            let a = planner.window.back().expect("checked above");
            planner.junction_limit_mm_s(a, p)
        };
        let mut lo = own_mm_s;
        let mut hi = own_at(self, lo).min(fit.v_mm_s);
        for _ in 0..3 {
            if hi <= lo * 1.01 {
                break;
            }
            let mid = 0.5 * (lo + hi);
            if own_at(self, mid) >= mid {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        let a = self.window.back_mut().expect("checked above");
        CurveFit::use_at(a, lo, t_f);
        lo
    }

    /// The cap the axis filters put on the vertex from the window's last line `a` into `p`,
    /// both lines of a run of chords, one a piece of a refined chord, where the vertex is not
    /// taken as a point of the curve (`∞` elsewhere).
    ///
    /// A vertex steps the axis velocity by `v·Δu`. Through two moving averages of `T_k` each,
    /// at a constant speed `v`, the jerk is `v·(Σ_{W₁}Δu − Σ_{W₂}Δu)/T_k²`, `W₁` and `W₂` the
    /// last two spans `B = v·T_k` of the path before the output point `s`; the turns within a
    /// span add up to the difference of the directions at its ends, so the jerk is
    /// `v·|u(s) − 2·u(s − B) + u(s − 2B)|/T_k²`. The vertex's own rules take each vertex's
    /// velocity step (`v·|Δuᵢ|/T_k²`), curvature step (`v²·|Δκᵢ|/T_k`) and the curve's
    /// following (`v³·κ²·|Tᵢ|`) one by one, each within half of what the elements leave of
    /// the axis's jerk: where a computed curvature turns over a few pieces (a refined chord
    /// whose curve changes sign within the span), the steps within one span add up (Y's jerk
    /// 3–5 % over on random chorded profiles, where the look-ahead's window was too short to
    /// take the vertices as a curve). This holds their sum, the second difference, within
    /// all of it, for every `s` from the vertex to the end of `p` (the next vertex's check
    /// takes those after) and every span up to `v·T_k` (a larger speed's spans do not cover
    /// a lower one's): the pairs of chords `s − B` and `s − 2B` meet, each from the smallest
    /// span at which they do ([`smallest_span_mm`]). A run longer than the chords kept
    /// ([`CHORD_HISTORY`]) holds the speed so that the spans stay within them.
    pub(super) fn span_cap_mm_s(&self, a: &Pending, p: &Pending, smoothing: &Smoothing) -> f64 {
        let chords = &self.curve.chords;
        let halves = &self.curve.chord_half_mm;
        let n = chords.len();
        let x = self.curve.pushed_mm;
        let l_b = p.seg.length_mm;
        if !(a.refined || p.refined)
            || !chord(a)
            || !chord(p)
            || n < 2
            || (chords[n - 1].1 - (x + 0.5 * l_b)).abs() > 1e-9 * (1.0 + x.abs())
        {
            return f64::INFINITY;
        }
        let tk = smoothing.axis_s(self.config.period_s);
        // Chord `k`'s extent; the first reaches back without end: before the first chord kept
        // the path is taken as its direction (a corner that began the run is its own
        // junction's rules'; where the history was cut, see `within` below).
        let extent = |k: usize| {
            let (mid, half) = (chords[k].1, halves[k]);
            let start = if k == 0 {
                f64::NEG_INFINITY
            } else {
                mid - half
            };
            (start, mid + half)
        };
        let u_b = chords[n - 1].0;
        // Every pair of chords (`j₁` at `s − B`, `j₂` at `s − 2B`) that some `s` in
        // `[x, x + L_b]` meets at some span up to `B`, with the smallest such span `B*`
        // ([`smallest_span_mm`]) and what it adds to the jerk, `|u_b − 2·u_j₁ + u_j₂|`.
        let mut pairs: Vec<(f64, Vector3<f64>)> = Vec::new();
        for j1 in (0..n).rev() {
            let r1 = extent(j1);
            // `p₂ ≤ p₁`, and `2·p₁ − p₂` lies in `[x, x + L_b]`: `p₂ ≥ 2·a₁ − x − L_b`.
            let lowest = 2.0 * r1.0 - x - l_b;
            for j2 in (0..=j1).rev() {
                let r2 = extent(j2);
                if r2.1 < lowest {
                    break;
                }
                if let Some(b_mm) = smallest_span_mm(r1, r2, x, l_b) {
                    let w = (u_b - 2.0 * chords[j1].0 + chords[j2].0).abs();
                    pairs.push((b_mm, w));
                }
            }
        }
        pairs.sort_by(|p, q| p.0.total_cmp(&q.0));
        let budget = Vector3::from_fn(|i, _| {
            (self.config.max_jerk_mm_s3[i] - a.jerk_used_mm_s3[i].max(p.jerk_used_mm_s3[i]))
                .max(0.0)
        });
        let cap_with = |env: &Vector3<f64>| {
            (0..3)
                .filter(|&i| env[i] > 0.0)
                .map(|i| tk * tk * budget[i] / env[i])
                .fold(f64::INFINITY, f64::min)
        };
        // The history's reach: where it was cut, no span reaches beyond it.
        let within = if n >= CHORD_HISTORY {
            (x - (chords[0].1 - halves[0])) / (2.0 * tk)
        } else {
            f64::INFINITY
        };
        // The spans up to `v·T_k`: the largest `v` whose pairs within keep the rule.
        let mut env = Vector3::zeros();
        let mut below_mm = 0.0;
        for (b_mm, w) in pairs {
            if b_mm > below_mm {
                let cap = cap_with(&env);
                if cap * tk < b_mm {
                    return cap.max(below_mm / tk).min(within);
                }
                below_mm = b_mm;
            }
            env = env.sup(&w);
        }
        cap_with(&env).max(below_mm / tk).min(within)
    }

    /// The curve's limits at the element `prev`, from the longest valid window of chords
    /// ending at the newest one (see the module documentation).
    fn curve_estimate(&self, prev: &Pending, smoothing: &Smoothing) -> Option<(CurveFit, f64)> {
        let chords = &self.curve.chords;
        let n = chords.len();
        if n < 2 {
            return None;
        }
        let tk = smoothing.axis_s(self.config.period_s);
        let v_max = prev.limits.v_max_mm_s();
        let (u_new, s_new) = chords[n - 1];
        // Whether the cap at `kappa` allows `x` (without its roots: each axis's
        // `x²·κ·|Nᵢ|` and `x³·κ²·|Tᵢ|` within their shares).
        let allows = |kappa: Vector3<f64>, x: f64| {
            let k = kappa.norm();
            (0..3).all(|i| {
                let (t_i, n_i) = (prev.tangent_end[i].abs(), kappa[i].abs());
                x * x * n_i <= CENTRIPETAL_SHARE * CURVE_ACC_BUDGET * self.limits.max_acc_mm_s2[i]
                    && x * x * x * k * k * t_i
                        <= CURVE_JERK_SHARE * CURVE_JERK_BUDGET * self.config.max_jerk_mm_s3[i]
            })
        };
        // The turn `θ` between the window's end chords over the distance between their
        // midpoints, along the difference of their directions (the normal midway): exact on
        // an arc (the difference's length is `2·sin(θ/2)`).
        let kappa_over = |m: usize| {
            let (u_old, s_old) = chords[n - 1 - m];
            let w_mm = s_new - s_old;
            let du = u_new - u_old;
            let chord = du.norm();
            (w_mm > 0.0).then(|| {
                let theta = 2.0 * (0.5 * chord).min(1.0).asin();
                let kappa = if chord > 0.0 {
                    du * (theta / (chord * w_mm))
                } else {
                    Vector3::zeros()
                };
                (kappa, w_mm)
            })
        };
        // The first window that turns, then the longest valid one: valid where the axis
        // filters average over at least its length at the speed its curvature allows.
        let mut best = None;
        let mut m = 2usize.min(n - 1);
        loop {
            if let Some((kappa, w_mm)) = kappa_over(m)
                && kappa.norm() > 0.0
            {
                let x = w_mm / tk;
                let valid = x <= v_max && allows(kappa, x);
                if best.is_none() || valid {
                    best = Some((kappa, w_mm));
                }
                // On a refined chord's pieces the vertices are computed, with no rounding to
                // average away: the first window is the curve's own curvature, which a longer
                // one would smear over the chords where it turns.
                if !valid || prev.refined {
                    break;
                }
            }
            if m == n - 1 {
                break;
            }
            m = (2 * m).min(n - 1);
        }
        let (best, w_mm) = best?;
        // The rate of change of the curve's curvature vector, from the estimate a baseline
        // back (each estimate holds midway along its window). The axis filters, two moving
        // averages each `B = v·T_k` long at the speed `v` the curve runs at, pass on the
        // curvature's rate averaged over `B` (the derivative of the first average is the
        // difference quotient over `B`, which the second only averages): on a refined chord's
        // pieces, whose computed vertices carry no rounding, the rate is taken over `B`.
        // Written chords take it over `2·B` (and at least two windows), which keeps the
        // rounding's noise on each estimate from reaching it divided by a short distance.
        // That speed is the cap the rate itself sets: from the speed the curvature alone
        // would allow, the baseline is shortened to the cap it gives, and again, while it
        // shrinks ([`RATE_ROUNDS`]). Taken at the curvature's speed over `2·B` and over
        // windows of four pieces, the rate of a curvature that turns within a few pieces
        // (`LHchips4.ngc`: 95 µm pieces of a refined chord, `κ` from 0.10 to −0.04 /mm in
        // 0.4 mm at 55 mm/s) came out at half what the filters pass on: X's jerk +3 % at
        // 1 ms on the demo machine.
        let kappas = &self.curve.kappas;
        let s_vertex = s_new - 0.5 * w_mm;
        let j_min = self.config.max_jerk_mm_s3.min();
        let k2 = best.norm_squared().max(f64::MIN_POSITIVE);
        let v_k = super::min_cbrt(v_max, CURVE_JERK_SHARE * CURVE_JERK_BUDGET * j_min / k2);
        // Its turn with the tangent, `−κ²·T`, is taken at the tangent midway (the chord
        // there), where the difference quotient has it.
        // The estimate a baseline back: where the nearest one that far back is much further
        // (the run began since, and the estimates before its start are far apart), the
        // nearest within the baseline instead, at least half of it back: the rate over a
        // shorter baseline, not averaged away. Over the far one, a refined chord whose curve
        // bends down and up in Z within 0.35 mm had its rate understated six times, and Z's
        // jerk ran 4.4 % over at 1 ms (`a_refined_chord_bending_in_z_keeps_z_s_jerk_at_1_ms`).
        let rate_over = |baseline_mm: f64| {
            let far = kappas
                .iter()
                .rev()
                .find(|&&(_, s)| s_vertex - s >= baseline_mm);
            let near = kappas
                .iter()
                .rev()
                .take_while(|&&(_, s)| s_vertex - s < baseline_mm)
                .last()
                .filter(|&&(_, s)| s_vertex - s >= 0.5 * baseline_mm);
            let old = match (far, near) {
                (Some(far), Some(near)) if s_vertex - far.1 > RATE_FAR * baseline_mm => Some(near),
                (far, _) => far,
            };
            old.copied().map_or(Vector3::zeros(), |(k_old, s)| {
                let mid = 0.5 * (s_vertex + s);
                let u_mid = nearest_chord(chords, mid).unwrap_or(prev.tangent_end);
                let k_mean = 0.5 * (best.norm() + k_old.norm());
                (best - k_old) / (s_vertex - s) + u_mid * (k_mean * k_mean)
            })
        };
        let span = if prev.refined { 1.0 } else { 2.0 };
        let baseline = |v_mm_s: f64| (2.0 * w_mm).max(span * v_mm_s * tk);
        let fit_over = |baseline_mm: f64| {
            let rate = rate_over(baseline_mm);
            curve_limits(self, prev.tangent_end, best, rate, v_max, smoothing)
        };
        let mut baseline_mm = baseline(v_k);
        let mut fit = fit_over(baseline_mm)?;
        for _ in 0..RATE_ROUNDS {
            let shorter_mm = baseline(fit.cap_mm_s.min(v_max));
            if shorter_mm >= RATE_SHRINK * baseline_mm {
                break;
            }
            baseline_mm = shorter_mm;
            fit = fit_over(baseline_mm)?;
        }
        Some((fit, s_vertex))
    }

    /// The caps `(raw, dipped)` of the junction from the window's last element into `p` (see
    /// [`Planner::raw_junction_caps`] and [`Planner::dip_caps`]), taking the vertex as a point
    /// of a chord run where it is one ([`take_curve_vertex`](Self::take_curve_vertex)) and
    /// the caps held ahead ([`erode_ahead`](Self::erode_ahead)). Within a run, the caps hold
    /// over the filter's reach either side, so a junction below its neighbours only by theirs
    /// is no dip. `None` at the start.
    pub(super) fn start_caps(&mut self, p: &mut Pending) -> Option<((f64, f64), (f64, f64))> {
        let taken = self.take_curve_vertex(p);
        let ahead = self.curve.cap_at(self.curve.pushed_mm);
        let (p_short, ahead_mm_s) = self.erode_ahead(p, ahead);
        let prev = self.window.back()?;
        let own = self.junction_limit_mm_s(prev, p);
        let own = match (taken, self.smoothing) {
            (Some(_), _) => self.curve_junction_mm_s(p, own),
            (None, Some(smoothing)) => own.min(self.span_cap_mm_s(prev, p, &smoothing)),
            (None, None) => own,
        };
        let prev = self.window.back()?;
        let in_run = prev.curve_fit.is_some() && p_short;
        let raw = caps_under(own.min(ahead_mm_s), prev, p);
        let covered = in_run && own >= prev.limits.v_max_mm_s().min(p.limits.v_max_mm_s());
        let dipped = if covered {
            raw
        } else {
            self.dip_caps(prev, p, raw)
        };
        // A vertex of a run whose own cap is below its lines' is held as a cap of the run
        // instead of dipped: over `c·T_f` back ([`erode_back`](Self::erode_back)) and ahead,
        // so that the filtered speed passes it within its cap (the plateau argument above).
        // Dipped, the lines' `A·T_f/4` took all of a cap a little under theirs: on
        // `spiral_tangent_test`'s 10 µm chords at 8 mm/s, a vertex's cap 1 % under its lines'
        // became 0.5 mm/s.
        if in_run
            && dipped.0 < raw.0
            && let Some(smoothing) = self.smoothing
        {
            let c = on_grid(raw.1);
            if c > 0.0 && c.is_finite() && self.erode_back(c, &smoothing) {
                let t_f = smoothing.time_law_s(self.config.period_s);
                self.hold_cap_ahead(c, t_f);
                cap_speed(p, c, c);
                let prev = self.window.back()?;
                let raw = caps_under(own.min(ahead_mm_s).min(c), prev, p);
                return Some((raw, raw));
            }
        }
        Some((raw, dipped))
    }

    /// Holds the cap `c` of the vertex at the end of the window over its reach `c·T_f` ahead
    /// (`t_f`), at most the max feed's: no element with X/Y/Z motion runs above it.
    fn hold_cap_ahead(&mut self, c: f64, t_f: f64) {
        let held = c.min(self.limits.max_feed_mm_s);
        self.curve.hold_ahead(self.curve.pushed_mm + held * t_f, c);
    }

    /// The caps held ahead, on the next element `p` at the end of the window: one within
    /// their reach (`cap·T_f`) is capped, and `(true, ∞)` returned; a longer one is not, and
    /// `(false, cap)` is the cap of the junction at its start, which is then dipped as any
    /// other.
    pub(super) fn erode_ahead(&self, p: &mut Pending, ahead: Option<f64>) -> (bool, f64) {
        let (Some(smoothing), Some(cap)) = (self.smoothing, ahead) else {
            return (false, f64::INFINITY);
        };
        if p.seg.length_mm <= cap * smoothing.time_law_s(self.config.period_s) {
            cap_speed(p, cap, cap);
            (true, f64::INFINITY)
        } else {
            (false, cap)
        }
    }

    /// [`erode_ahead`](Self::erode_ahead) for a corner's blend arc and the element after it,
    /// whose junction caps are already set: a longer element's is dipped here (`A·T_f/4`
    /// with the larger of its acceleration and `before_acc_mm_s2`, or a stop).
    pub(super) fn erode_ahead_blend(
        &self,
        p: &mut Pending,
        ahead: Option<f64>,
        before_acc_mm_s2: f64,
    ) {
        let (Some(smoothing), Some(cap)) = (self.smoothing, ahead) else {
            return;
        };
        let t_f = smoothing.time_law_s(self.config.period_s);
        if p.seg.length_mm <= cap * t_f {
            cap_speed(p, cap, cap);
        } else {
            let delta = self.dip_depth_mm_s(p.limits.a_max_mm_s2(), before_acc_mm_s2);
            let c = (cap - delta).max(0.0);
            p.cap_start_mm_s = p.cap_start_mm_s.min(c);
            p.cap_start_limit_mm_s = p.cap_start_limit_mm_s.min(c);
            p.raw_cap_start_mm_s = p.raw_cap_start_mm_s.min(cap);
        }
    }

    /// Caps the window's last element at `cap` and every element before it within
    /// `cap·T_f`; the junction with a longer element there is dipped (`A·T_f/4`, or a stop).
    /// `false`, with nothing changed, where that reaches the settled part of the plan or
    /// where the plan could no longer come down to it from the speed it has settled.
    fn erode_back(&mut self, cap: f64, smoothing: &Smoothing) -> bool {
        let n = self.window.len();
        let t_f = smoothing.time_law_s(self.config.period_s);
        let reach_mm = cap * t_f;
        // Dry run: the first element capped (`j`), and whether the junction at its start is
        // dipped. `covered_mm`: the length of the elements from `j` to the last, exclusive.
        let last = &self.window[n - 1];
        if last.v_limit_mm_s <= cap && last.floor_reach_mm >= reach_mm {
            return true;
        }
        let mut j = n - 1;
        let mut covered_mm = 0.0;
        let mut dip = false;
        // Nothing before the window's start leaks into the filter where the plan stood
        // there until the time-law filter settled (the program's start, or a stop).
        let rest_before = self.v_settled_mm_s == 0.0 && self.time_law_unsettled.is_none();
        while covered_mm < reach_mm {
            if j == 0 {
                if rest_before {
                    break;
                }
                return false;
            }
            let e = &self.window[j - 1];
            let left_mm = reach_mm - covered_mm - e.seg.length_mm;
            if e.v_limit_mm_s <= cap && e.floor_reach_mm >= left_mm {
                break;
            }
            if e.v_limit_mm_s > cap && e.seg.length_mm > reach_mm {
                dip = true;
                break;
            }
            covered_mm += e.seg.length_mm;
            j -= 1;
        }
        // The junction at `j`'s start: dipped where the element before is long.
        let first = &self.window[j];
        let mut c_j = first.cap_start_mm_s.min(cap);
        if dip {
            let delta = self.dip_depth_mm_s(
                first.limits.a_max_mm_s2(),
                self.window[j - 1].limits.a_max_mm_s2(),
            );
            c_j = c_j.min((cap - delta).max(0.0));
        }
        // Can the plan still come down to `c_j` there? Back from it at each element's
        // acceleration, to a junction whose own cap is lower (nothing before it changes) or
        // to the speed the plan has settled at the window's start.
        if !self.can_come_down(j, c_j) {
            return false;
        }
        // Apply: `behind_mm`, what lies within reach before each element's start.
        let mut behind_mm = reach_mm;
        // By iterator: on tiny segments the run capped is often over a hundred long.
        for (k, e) in (j..n).zip(self.window.range_mut(j..)).rev() {
            if k < n - 1 {
                behind_mm -= e.seg.length_mm;
            }
            let was = e.v_limit_mm_s;
            cap_speed(e, cap, cap);
            // A provisional junction's plateau comes no higher than the cap. Its ceiling
            // stays: it also sets how far before it the plan waits for the plateau
            // (`Planner::held_from`), whose elements may still be slowed.
            if let Some(raw) = e.provisional.as_mut() {
                raw.fed_mm_s = raw.fed_mm_s.min(cap);
            }
            e.raw_cap_start_mm_s = e.raw_cap_start_mm_s.min(cap);
            // Everything within `behind_mm` before it is now within its ceiling.
            if was >= cap {
                e.floor_reach_mm = e.floor_reach_mm.max(behind_mm);
            }
        }
        let first = &mut self.window[j];
        first.cap_start_mm_s = first.cap_start_mm_s.min(c_j);
        first.cap_start_limit_mm_s = first.cap_start_limit_mm_s.min(c_j);
        if let Some(raw) = first.provisional.as_mut() {
            raw.fed_mm_s = raw.fed_mm_s.min(c_j);
        }
        if j > 0 && c_j == 0.0 {
            first.low_cap = true;
        }
        true
    }
}

/// The smallest span `B` at which the axis filters' spans ending at some `s` in
/// `[x, x + l_b]` have `s − B` in `r1` and `s − 2B` in `r2` (extents `(start, end)`), `None`
/// where none do. Such an `s` exists where the three intervals `r1 + B`, `r2 + 2B` and
/// `[x, x + l_b]` meet, which holds, pair by pair, on an interval of `B ≥ 0`.
fn smallest_span_mm(r1: (f64, f64), r2: (f64, f64), x: f64, l_b: f64) -> Option<f64> {
    let ((a1, b1), (a2, b2)) = (r1, r2);
    let lo = (a1 - b2).max(x - b1).max(0.5 * (x - b2)).max(0.0);
    let hi = (b1 - a2).min(x + l_b - a1).min(0.5 * (x + l_b - a2));
    (lo <= hi).then_some(lo)
}

/// Links `p`'s [`Pending::floor_reach_mm`] to the element before it.
pub(super) fn link_floor(prev: &Pending, p: &mut Pending) {
    p.floor_reach_mm = if prev.v_limit_mm_s <= p.v_limit_mm_s {
        prev.floor_reach_mm + prev.seg.length_mm
    } else {
        0.0
    };
}

#[cfg(test)]
mod tests {
    use super::super::{Limits, PlannerConfig, ProfileKind};
    use super::*;
    use proptest::prelude::*;

    /// The demo machine's limits at a 1 ms period, in the jerk-limited mode.
    fn s_curve_planner() -> Planner {
        let limits = Limits {
            max_vel_mm_s: Vector3::new(200.0, 200.0, 100.0),
            max_acc_mm_s2: Vector3::new(2000.0, 2000.0, 1000.0),
            max_feed_mm_s: 200.0,
        };
        let config = PlannerConfig {
            period_s: 0.001,
            corner_acc_mm_s2: 1000.0,
            path_acc_share: 0.75,
            max_jerk_mm_s3: Vector3::new(50_000.0, 50_000.0, 20_000.0),
            profile: ProfileKind::SCurve,
            ..PlannerConfig::exact_stop()
        };
        Planner::with_config(Vector3::zeros(), &limits, &config).unwrap()
    }

    /// A line of a chord run plans with the largest tangential acceleration its curve's
    /// budget leaves wherever the time-law filter carries it (`valid_at`), within 1 % from
    /// below: on a tight bend (radius 0.16 mm) the third iterate of `a ↦ acc_raw(v + a·T_f)`,
    /// which `acc_at` took until session 25, is well below it (34 against about 120 mm/s² on
    /// `3D_Chips`' refined bends), and its pieces crawled.
    #[test]
    fn a_curve_s_acceleration_at_a_speed_is_its_budget_s_fixed_point() {
        let planner = s_curve_planner();
        let smoothing = planner.smoothing().expect("jerk-limited");
        for (radius_mm, v_mm_s) in [(0.16, 0.0), (0.16, 2.0), (0.5, 5.0), (10.0, 40.0)] {
            let tangent = Vector3::new(0.0, 0.8, 0.6);
            let kappa = Vector3::new(1.0 / radius_mm, 0.0, 0.0);
            let fit = curve_limits(
                &planner,
                tangent,
                kappa,
                Vector3::zeros(),
                200.0,
                &smoothing,
            )
            .expect("a curve");
            let a = fit.acc_at(v_mm_s);
            assert!(fit.valid_at(a, v_mm_s), "r {radius_mm}: {a} not valid");
            assert!(
                !fit.valid_at(1.02 * a, v_mm_s) || a >= fit.acc_mm_s2,
                "r {radius_mm} at {v_mm_s} mm/s: {a} mm/s² is not within 2 % of the fixed point"
            );
        }
    }

    proptest! {
        /// The smallest span at which two chords meet the axis filters' spans ending on the
        /// next line is where a search over the spans first finds the three intervals of the
        /// end point (`[x, x + L_b]`, `r1 + B`, `r2 + 2B`) meeting.
        #[test]
        fn the_smallest_span_is_a_search_s(
            a1 in -3.0..0.5f64,
            l1 in 0.0..1.5f64,
            a2 in -4.0..0.5f64,
            l2 in 0.0..1.5f64,
            l_b in 0.0..0.5f64,
        ) {
            let (r1, r2) = ((a1, a1 + l1), (a2, a2 + l2));
            let found = smallest_span_mm(r1, r2, 0.0, l_b);
            let meets = |b: f64, slack: f64| {
                let lo = (a1 + b).max(a2 + 2.0 * b).max(0.0);
                let hi = (a1 + l1 + b).min(a2 + l2 + 2.0 * b).min(l_b);
                lo <= hi + slack
            };
            let step = 1e-4;
            let searched = (0..=60_000).map(|k| k as f64 * step).find(|&b| meets(b, 0.0));
            match (found, searched) {
                (Some(b), Some(c)) => {
                    prop_assert!(c >= b - 1e-9 && c <= b + step + 1e-9, "{b} vs {c}");
                    prop_assert!(meets(b, 1e-9), "{b} does not meet");
                    prop_assert!(b < 1e-6 || !meets(b - 1e-6, 0.0), "{b} is not the least");
                }
                (None, Some(c)) => prop_assert!(false, "none, the search found {c}"),
                // The meeting lies between two of the search's spans.
                (Some(b), None) => prop_assert!(meets(b, 1e-9), "{b}, the search found none"),
                (None, None) => {}
            }
        }

        /// The bisection finds the chord a scan of every chord finds (the first of equally
        /// near ones), midpoints repeated and the point outside the run included.
        #[test]
        fn nearest_chord_is_the_scan_s(
            steps in proptest::collection::vec(prop_oneof![Just(0.0), 0.0..2.0f64], 0..40),
            at in -1.0..45.0f64,
        ) {
            let mut s = 0.0;
            let chords: VecDeque<(Vector3<f64>, f64)> = steps
                .iter()
                .enumerate()
                .map(|(k, step)| {
                    s += step;
                    (Vector3::new(k as f64, 0.0, 0.0), s)
                })
                .collect();
            let scan = chords
                .iter()
                .min_by(|a, b| (a.1 - at).abs().total_cmp(&(b.1 - at).abs()))
                .map(|c| c.0);
            prop_assert_eq!(nearest_chord(&chords, at), scan);
        }
    }
}
