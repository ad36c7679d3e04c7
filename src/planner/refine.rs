//! Chord refinement (jerk-limited mode): each chord of a run of G64 lines replaced by shorter
//! chords on a smooth curve through the run's vertices, within a share of the tolerance, where
//! its vertices turn by more than the axis filters take at the curve's speed.
//!
//! A polyline's vertex is a step `v·|Δu|` of the axis velocity. The axis filters spread it
//! over `2·T_k`, which leaves a jerk of up to `v·|Δu|/T_k²` in their output (the steps within
//! one filter time differ by at most one from one half of its window to the other, however
//! dense they are), so the vertex rule holds a vertex turning by `|Δu|` to `J·T_k²/|Δu|`:
//! 4.1 mm/s on `3D_Chips.ngc`'s half circles of 0.62 mm radius written as 16 chords of
//! 0.117 mm (0.196 rad a vertex, `T_k` = 8 ms), where the curve allows about 23 mm/s and the
//! trapezoid plan runs at 26–30. The same circle as 128 chords runs at its curvature's speed
//! (5 laps at F7500, demo machine at 1 ms: 5.65 s as 32 chords a lap, 1.18 s as 128).
//!
//! # The curve
//!
//! Over the chord `P_i P_{i+1}` (length `l`), the quintic Hermite curve with, at each end, the
//! tangent `T` and the curvature vector `K` of the circle through that vertex and its
//! neighbours (`P_{i−1}`, `P_i`, `P_{i+1}` at the start, `P_i`, `P_{i+1}`, `P_{i+2}` at the
//! end): first derivatives `m·T`, second derivatives `m²·K`, `m = l·(φ/2)/sin(φ/2)` the length
//! of a circular arc turning by the angle `φ` between the two tangents. The curves of
//! neighbouring chords meet with the same tangent and curvature, and a run whose vertices lie
//! on a circle becomes that circle (within 10⁻⁹ of its radius for chords of 11°).
//! Inside the chord its curvature passes from one end's to the other's about as a cubic
//! spline's does. Until session 33 the two circles' arcs themselves were blended with the
//! quintic smoothstep `w(u)`: where they differ, the term `w''·(C₂ − C₁)` overshoots the
//! curvature by up to about 1.5 times the step between them, its rate about 6 times the
//! step over the chord, and the jerk of following that, `v³·|dκ/ds|`, held the refined chords
//! of unequal length on `3D_Chips.ngc` to 9–13 mm/s (the Hermite curve: −5.6 % on its time,
//! −2.8 % on `LHchips4.ngc`, no corpus program slower).
//! At a run's ends the missing vertex is taken along the line beyond (where that is a G64 line
//! turning by at most [`MAX_TURN`], so the curve leaves it tangentially), else along the end
//! chord itself. The curve is cut into `n` chords at equal steps of `u`, `n` such that each of
//! their vertices steps the axis velocity by at most a tenth of `J·T_k²` at the speed the
//! curve allows, where half the look-ahead's window still holds a braking distance from that
//! speed in such pieces, else a quarter ([`pieces`]); at most [`MAX_PIECES`]; a chord that
//! needs fewer than 2 stays as it is. (A quarter and at most 16 before session 23: the vertex
//! rules then held the junctions between pieces below the curve's own cap, and their dips
//! (`A·T_f/4`) stopped the motion inside refined chords of `LHchips4`: 658.7 s, 597.3 s now.)
//!
//! The pieces' vertices are computed, not written with a program's decimals: the planner's
//! allowance for the rounding of written vertices (a vertex whose curvature step bounds its
//! deviation below the rounding's, `8ε/(T·T_k²)` of jerk) does not apply at them
//! (`Pending::refined`). With it, the curvature of a refined run changing over a few pieces,
//! each within that allowance, broke Z's jerk on `3D_Chips` and `LHchips4` by up to 89 %.
//!
//! # The tolerance
//!
//! The pieces all lie within `δ` of the chord they replace, `δ` the largest distance of their
//! vertices from it (a point's distance from a segment is convex along a segment, so largest
//! at its ends). A chord is refined only where `δ ≤` [`SHARE`]`·tol`, and its pieces go on with
//! the tolerance `tol − max(δ, δ_next)`, `δ_next` the next chord's, into which a blend at
//! their junction reaches; as [`super::smooth`] shares it, so that smoothing, refinement,
//! blends and the axis filters together stay within the tolerance of the programmed path.
//! The programmed vertices stay where they are.
//!
//! # Which lines
//!
//! Feed moves along a straight line in X/Y/Z longer than [`super::smooth::DENSE_MM`] (shorter
//! ones are the chord smoother's, whose vertices are dense at speed already) and at most
//! [`LONGEST_MM`], with the auxiliary axes still, under G64 with a tolerance, each starting
//! where the one before ends, none turning from it by more than [`MAX_TURN`]. Anything else
//! ends the run. A chord waits for the next one (its end's tangent and the next `δ`), so the
//! planner receives each two lines late.

use std::collections::VecDeque;

use nalgebra::Vector3;

use super::smooth::{DENSE_MM, closest_on_segment, g64_chord, with_tolerance};
use crate::gcode::{BlendMode, Element, ElementKind, Item};

/// Largest turn of a vertex inside a run (radians): [`super::curve::CURVE_MAX_TURN`], the
/// sharpest vertex the planner takes as a point of a curve. Sharper ones are corners.
pub const MAX_TURN: f64 = super::curve::CURVE_MAX_TURN;

/// Longest chord refined. Longer ones bow out beyond any tolerance a program writes with
/// G64 P before they turn enough to matter.
pub const LONGEST_MM: f64 = 2.0;

/// Share of a chord's tolerance its refinement may take.
pub const SHARE: f64 = 0.25;

/// Most chords one chord becomes.
pub const MAX_PIECES: usize = 32;

/// Share of the smallest jerk limit a vertex of the refined chords may take as its velocity
/// step through the axis filters at the curve's speed, where half the look-ahead's window
/// still holds a braking distance from that speed in such pieces ([`pieces`]).
const VERTEX_JERK_SHARE: f64 = 0.1;

/// The share where the finer one's pieces would be shorter than that: the pieces fill the
/// window, which must hold a braking distance (a circle of 1° chords of 0.35 mm at 150 mm/s
/// cut into pieces of 17 µm ran 6.8 s instead of 4.3 s with a window of 64 elements).
const COARSE_VERTEX_JERK_SHARE: f64 = 0.25;

/// What the refiner needs of the machine.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct Machine {
    /// Length `T_k` of each axis filter.
    pub axis_filter_s: f64,
    /// Smallest acceleration and jerk limit of X, Y and Z.
    pub acc_mm_s2: f64,
    pub jerk_mm_s3: f64,
    /// Highest path feed.
    pub max_feed_mm_s: f64,
    /// The look-ahead's window, in elements ([`super::PlannerConfig::lookahead`]).
    pub lookahead: usize,
}

/// A chord of the run, refined or not yet.
#[derive(Debug, Clone)]
struct Chord {
    e: Element,
    /// Its tolerance (`tol` above).
    tol_mm: f64,
    /// The curve's tangent at its start.
    t0: Vector3<f64>,
    /// The run's vertex before it and after it, where known.
    prev: Option<Vector3<f64>>,
    next: Option<Vector3<f64>>,
    /// Its new inner vertices (none: as programmed) and their deviation `δ`.
    inner: Vec<Vector3<f64>>,
    delta_mm: f64,
}

/// The run being refined, and the items ready for the planner.
#[derive(Debug, Clone, Default)]
pub(super) struct ChordRefiner {
    machine: Machine,
    /// A refined chord waiting for the next one's `δ`.
    ready: Option<Chord>,
    /// The run's last chord, waiting for the tangent at its end.
    last: Option<Chord>,
    /// The direction of the last line passed on outside a run and where it ends, under G64
    /// (a run starting there may leave it tangentially).
    before: Option<(Vector3<f64>, Vector3<f64>)>,
    /// What the planner receives next, in order, each with whether it is a piece of a
    /// refined chord.
    pub out: VecDeque<(Item, bool)>,
}

impl ChordRefiner {
    pub fn new(machine: Machine) -> ChordRefiner {
        ChordRefiner {
            machine,
            ..Default::default()
        }
    }

    /// Takes the next item; `tol_mm` is its G64 tolerance (0: none).
    pub fn push(&mut self, item: Item, tol_mm: f64) {
        let e = match item {
            Item::Motion(e) => e,
            other => {
                self.end_run(None);
                self.before = None;
                self.out.push_back((other, false));
                return;
            }
        };
        let dir = unit(&e);
        if eligible(&e, tol_mm) {
            if let Some(last) = self.last.take() {
                let u = unit(&last.e);
                if last.e.end_mm == e.start_mm && u.angle(&dir) <= MAX_TURN {
                    let (a, b) = (last.e.end_mm - last.e.start_mm, e.end_mm - e.start_mm);
                    let t = vertex_tangent(a, b);
                    let mut last = last;
                    last.next = Some(e.end_mm);
                    let prev = Some(last.e.start_mm);
                    self.refined(last, t);
                    let mut c = Chord::new(e, tol_mm, t);
                    c.prev = prev;
                    self.last = Some(c);
                    return;
                }
                self.last = Some(last);
                self.end_run(None);
            }
            let t0 = match self.before.take() {
                Some((d, at)) if at == e.start_mm && d.angle(&dir) <= MAX_TURN => d,
                _ => dir,
            };
            self.last = Some(Chord::new(e, tol_mm, t0));
            return;
        }
        // The line after a run: the run's curve may end tangent to it.
        let next = (e.kind == ElementKind::Line && tol_mm > 0.0 && !e.rapid).then_some(dir);
        self.end_run(next.filter(|_| self.last.as_ref().is_some_and(|l| l.e.end_mm == e.start_mm)));
        self.before = (e.kind == ElementKind::Line
            && tol_mm > 0.0
            && matches!(e.blend, BlendMode::Blend { .. })
            && e.start_mm != e.end_mm)
            .then_some((dir, e.end_mm));
        self.out.push_back((Item::Motion(e), false));
    }

    /// Ends the run: everything goes to `out`.
    pub fn flush(&mut self) {
        self.end_run(None);
        self.before = None;
    }

    /// Ends the run; `next`: the direction of the line after it, where its curve may end
    /// tangent to that.
    fn end_run(&mut self, next: Option<Vector3<f64>>) {
        if let Some(last) = self.last.take() {
            let own = unit(&last.e);
            let t1 = next.filter(|d| d.angle(&own) <= MAX_TURN).unwrap_or(own);
            self.refined(last, t1);
        }
        if let Some(ready) = self.ready.take() {
            self.emit(ready, 0.0);
        }
    }

    /// `c` refined with the tangent `t1` at its end: becomes the ready chord, the one ready
    /// before it goes out.
    fn refined(&mut self, mut c: Chord, t1: Vector3<f64>) {
        let (p0, p1) = (c.e.start_mm, c.e.end_mm);
        let l = (p1 - p0).norm();
        let phi = c.t0.angle(&t1);
        let n = pieces(&self.machine, &c.e, l, phi);
        if n >= 2 {
            let curve = ChordCurve::new(c.prev, p0, p1, c.next, c.t0, t1);
            let inner: Vec<Vector3<f64>> = (1..n).map(|k| curve.at(k as f64 / n as f64)).collect();
            let delta = inner
                .iter()
                .map(|q| distance_to_segment(*q, p0, p1))
                .fold(0.0, f64::max);
            if delta <= SHARE * c.tol_mm && inner.iter().all(|q| q.iter().all(|x| x.is_finite())) {
                c.inner = inner;
                c.delta_mm = delta;
            }
        }
        if let Some(ready) = self.ready.take() {
            self.emit(ready, c.delta_mm);
        }
        self.ready = Some(c);
    }

    /// Passes `c` on as its chords, with the tolerance it and the next chord (`δ_next`) leave.
    fn emit(&mut self, c: Chord, next_delta_mm: f64) {
        if c.inner.is_empty() && next_delta_mm == 0.0 {
            self.out.push_back((Item::Motion(c.e), false));
            return;
        }
        let spent = c.delta_mm.max(next_delta_mm);
        let blend = with_tolerance(c.e.blend, c.tol_mm - spent);
        let mut from = c.e.start_mm;
        for to in c.inner.iter().copied().chain(std::iter::once(c.e.end_mm)) {
            let mut e = c.e;
            e.start_mm = from;
            e.end_mm = to;
            e.blend = blend;
            self.out.push_back((Item::Motion(e), !c.inner.is_empty()));
            from = to;
        }
    }
}

impl Chord {
    fn new(e: Element, tol_mm: f64, t0: Vector3<f64>) -> Chord {
        Chord {
            e,
            tol_mm,
            t0,
            prev: None,
            next: None,
            inner: Vec::new(),
            delta_mm: 0.0,
        }
    }
}

/// How many chords a chord of length `l_mm` whose curve turns by `phi` becomes: enough that
/// each vertex, turning by about `φ/n`, steps the axis velocity by at most what the filters
/// take at the curve's speed `v` (the feed, `√(A/κ)` and `(J/κ²)^(1/3)` at `κ = φ/L`):
/// `v·φ/n ≤ s·J·T_k²`, `s` = [`VERTEX_JERK_SHARE`] where the pieces stay at least
/// `v²/(A·lookahead)` long (half the window then holds the braking distance `v²/2A`), at
/// least as many as with [`COARSE_VERTEX_JERK_SHARE`]; at most [`MAX_PIECES`]; 1 where that
/// is enough already.
fn pieces(m: &Machine, e: &Element, l_mm: f64, phi: f64) -> usize {
    if !(phi > 0.0 && l_mm > 0.0 && m.axis_filter_s > 0.0) {
        return 1;
    }
    let kappa = phi / l_mm;
    let v = e
        .feed_mm_s
        .unwrap_or(f64::INFINITY)
        .min(m.max_feed_mm_s)
        .min((m.acc_mm_s2 / kappa).sqrt())
        .min((m.jerk_mm_s3 / (kappa * kappa)).cbrt());
    let step = v * phi / (m.jerk_mm_s3 * m.axis_filter_s.powi(2));
    // Half the window holds a braking distance from the curve's speed in such pieces.
    let shortest_mm = v * v / (m.acc_mm_s2 * m.lookahead as f64);
    let n = (step / COARSE_VERTEX_JERK_SHARE).ceil().max(
        (step / VERTEX_JERK_SHARE)
            .ceil()
            .min((l_mm / shortest_mm).floor()),
    );
    if n.is_finite() && n >= 1.0 {
        (n as usize).min(MAX_PIECES)
    } else {
        1
    }
}

/// The curve over a chord `p0 p1` of a run: the quintic Hermite curve with each end's tangent
/// (`t0`, `t1`) and the curvature of the circle through that end and its neighbours (`prev`,
/// `next`; virtual ones along the tangents at a run's ends), taken square to the tangent, so
/// that neighbouring chords' curves meet with equal tangent and curvature (see the module
/// documentation).
#[derive(Debug, Clone, Copy)]
pub(super) struct ChordCurve {
    p0: Vector3<f64>,
    p1: Vector3<f64>,
    /// The tangents times the arc length `m`, the curvatures times `m²`.
    d0: Vector3<f64>,
    d1: Vector3<f64>,
    k0: Vector3<f64>,
    k1: Vector3<f64>,
}

impl ChordCurve {
    pub fn new(
        prev: Option<Vector3<f64>>,
        p0: Vector3<f64>,
        p1: Vector3<f64>,
        next: Option<Vector3<f64>>,
        t0: Vector3<f64>,
        t1: Vector3<f64>,
    ) -> ChordCurve {
        let l = (p1 - p0).norm();
        let square = |k: Vector3<f64>, t: Vector3<f64>| k - t * k.dot(&t);
        let k0 = square(circle_curvature(prev.unwrap_or(p0 - t0 * l), p0, p1), t0);
        let k1 = square(circle_curvature(p0, p1, next.unwrap_or(p1 + t1 * l)), t1);
        let half = 0.5 * t0.angle(&t1);
        let m = if half > 1e-6 {
            l * half / half.sin()
        } else {
            l
        };
        ChordCurve {
            p0,
            p1,
            d0: t0 * m,
            d1: t1 * m,
            k0: k0 * (m * m),
            k1: k1 * (m * m),
        }
    }

    /// The point at the parameter `u` (0 at `p0`, 1 at `p1`).
    pub fn at(&self, u: f64) -> Vector3<f64> {
        let (u2, u3) = (u * u, u * u * u);
        let (u4, u5) = (u3 * u, u3 * u2);
        let h0 = 1.0 - 10.0 * u3 + 15.0 * u4 - 6.0 * u5;
        let h1 = u - 6.0 * u3 + 8.0 * u4 - 3.0 * u5;
        let h2 = 0.5 * u2 - 1.5 * u3 + 1.5 * u4 - 0.5 * u5;
        let h3 = 0.5 * u3 - u4 + 0.5 * u5;
        let h4 = -4.0 * u3 + 7.0 * u4 - 3.0 * u5;
        let h5 = 10.0 * u3 - 15.0 * u4 + 6.0 * u5;
        self.p0 * h0 + self.d0 * h1 + self.k0 * h2 + self.k1 * h3 + self.d1 * h4 + self.p1 * h5
    }

    /// The largest distance from the chord of the points at `u = k/8`, about the refiner's
    /// `δ` for the chord.
    pub fn sag_mm(&self) -> f64 {
        (1..8)
            .map(|k| distance_to_segment(self.at(k as f64 / 8.0), self.p0, self.p1))
            .fold(0.0, f64::max)
    }
}

/// The curvature vector at `b` of the circle through `a`, `b` and `c` (towards its centre,
/// `1/r` long); zero where they are collinear.
fn circle_curvature(a: Vector3<f64>, b: Vector3<f64>, c: Vector3<f64>) -> Vector3<f64> {
    let (x, y) = (a - c, b - c);
    let w = x.cross(&y);
    let w2 = w.norm_squared();
    if w2.is_nan() || w2 <= 1e-30 * x.norm_squared() * y.norm_squared() {
        return Vector3::zeros();
    }
    let centre = c + (y * x.norm_squared() - x * y.norm_squared()).cross(&w) / (2.0 * w2);
    let to = centre - b;
    to / to.norm_squared()
}

/// The unit tangent at vertex `B` of the circle through `A`, `B` and `C`, from the chords
/// `a = B − A` and `b = C − B`.
pub(super) fn vertex_tangent(a: Vector3<f64>, b: Vector3<f64>) -> Vector3<f64> {
    let t = a * b.norm_squared() + b * a.norm_squared();
    t / t.norm()
}

/// The unit direction of a line.
fn unit(e: &Element) -> Vector3<f64> {
    (e.end_mm - e.start_mm)
        .try_normalize(0.0)
        .unwrap_or_else(Vector3::zeros)
}

/// A line the refiner may replace: see the module documentation.
fn eligible(e: &Element, tol_mm: f64) -> bool {
    g64_chord(e, tol_mm, DENSE_MM, LONGEST_MM)
}

fn distance_to_segment(q: Vector3<f64>, a: Vector3<f64>, b: Vector3<f64>) -> f64 {
    (q - closest_on_segment(q, a, b)).norm()
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;
    use crate::gcode::parse_program;

    const TOL_MM: f64 = 0.1;

    /// The demo machine at 1 ms: 8 ms axis filters.
    fn machine() -> Machine {
        Machine {
            axis_filter_s: 0.008,
            acc_mm_s2: 2000.0,
            jerk_mm_s3: 50_000.0,
            max_feed_mm_s: 200.0,
            lookahead: 1000,
        }
    }

    /// A G64 P0.1 run at F7500 through `points` after a G0 to the first, then a dwell.
    pub(in crate::planner) fn polyline(points: &[(f64, f64)]) -> String {
        let (x0, y0) = points[0];
        let mut text = format!("G21 G90 G64 P{TOL_MM} F7500\nG0 X{x0:.6} Y{y0:.6}\n");
        for (x, y) in &points[1..] {
            text.push_str(&format!("G1 X{x:.6} Y{y:.6}\n"));
        }
        text.push_str("G4 P0.1\nM2\n");
        text
    }

    /// `laps` of a circle of `n` chords of radius `r_mm` about the origin.
    fn circle(r_mm: f64, n: usize, laps: usize) -> Vec<(f64, f64)> {
        (0..=n * laps)
            .map(|k| std::f64::consts::TAU * k as f64 / n as f64)
            .map(|a| (r_mm * a.cos(), r_mm * a.sin()))
            .collect()
    }

    /// The program's items, and what the refiner makes of them (with the flags).
    fn run(text: &str) -> (Vec<Item>, Vec<(Item, bool)>) {
        let program = parse_program(text, "t.ngc", Vector3::zeros()).expect("parses");
        let mut r = ChordRefiner::new(machine());
        let mut out = Vec::new();
        for item in &program.items {
            let tol = match item {
                Item::Motion(e) if matches!(e.blend, BlendMode::Blend { .. }) => TOL_MM,
                _ => 0.0,
            };
            r.push(item.clone(), tol);
            out.extend(r.out.drain(..));
        }
        r.flush();
        out.extend(r.out.drain(..));
        (program.items, out)
    }

    fn lines(items: impl IntoIterator<Item = Item>) -> Vec<Element> {
        items
            .into_iter()
            .filter_map(|i| i.motion().copied())
            .collect()
    }

    fn tolerance(e: &Element) -> f64 {
        match e.blend {
            BlendMode::Blend { p_mm, .. } => p_mm,
            _ => 0.0,
        }
    }

    fn distance_to_polyline(q: Vector3<f64>, path: &[Element]) -> f64 {
        path.iter()
            .map(|e| distance_to_segment(q, e.start_mm, e.end_mm))
            .fold(f64::INFINITY, f64::min)
    }

    #[test]
    fn a_coarse_circle_becomes_finer_chords_on_the_same_circle() {
        // 3D_Chips' half circles: 0.62 mm radius, 16 chords a half circle (0.117 mm).
        let r = 0.62;
        let (program, out) = run(&polyline(&circle(r, 32, 2)));
        let before = lines(program);
        let after = lines(out.iter().map(|(i, _)| i.clone()));
        assert!(
            after.len() >= 3 * before.len(),
            "{} → {}",
            before.len(),
            after.len()
        );
        // One chain, from the same start to the same end, bit for bit, through every
        // programmed vertex.
        for w in after.windows(2) {
            assert_eq!(w[0].end_mm, w[1].start_mm);
        }
        assert_eq!(after[0].start_mm, before[0].start_mm);
        assert_eq!(after.last().unwrap().end_mm, before.last().unwrap().end_mm);
        let mut ends = after.iter().map(|e| e.end_mm);
        for e in &before[1..] {
            assert!(ends.any(|q| q == e.end_mm), "vertex {:?} kept", e.end_mm);
        }
        // Inside the run (the G0's neighbour and the last chord have one circle each), the
        // new vertices lie on the circle the programmed ones lie on (to their 6 decimals; a
        // chord sags by 2.8 µm), and each turns by a
        // fraction of a programmed vertex's 0.196 rad.
        let inner = &after[after.len() / 4..3 * after.len() / 4];
        for e in inner {
            let radius = Vector3::new(e.end_mm.x, e.end_mm.y, 0.0).norm();
            assert!((radius - r).abs() < 1e-6, "{radius}");
        }
        for w in inner.windows(2) {
            let (u, v) = (w[0].end_mm - w[0].start_mm, w[1].end_mm - w[1].start_mm);
            assert!(u.angle(&v) < 0.196 / 3.0, "{}", u.angle(&v));
        }
        // The pieces are flagged, and go on with the tolerance the chords' sag leaves.
        assert!(
            out.iter()
                .filter(|(i, _)| i.motion().is_some_and(|e| !e.rapid))
                .all(|(_, refined)| *refined)
        );
        let sag = r * (1.0 - (std::f64::consts::PI / 32.0).cos());
        for e in &after {
            let p = tolerance(e);
            assert!(p <= TOL_MM && p >= TOL_MM - 1.01 * sag, "{p}");
        }
    }

    #[test]
    fn every_piece_stays_within_its_share_and_leaves_the_rest_of_the_tolerance() {
        // An ellipse of chords of 0.2–0.5 mm, written with 3 decimals.
        let pts: Vec<(f64, f64)> = (0..=120)
            .map(|k| std::f64::consts::TAU * k as f64 / 120.0)
            .map(|a| {
                (
                    (5.0 * a.cos() * 1000.0).round() / 1000.0,
                    (2.0 * a.sin() * 1000.0).round() / 1000.0,
                )
            })
            .collect();
        let (program, out) = run(&polyline(&pts));
        let before = lines(program);
        let after = lines(out.into_iter().map(|(i, _)| i));
        assert!(after.len() > before.len());
        for e in &after {
            // A piece's points are within its chord's δ of the program, and δ plus the
            // tolerance it goes on with is at most the program's.
            let d = (0..=8)
                .map(|k| e.start_mm + (e.end_mm - e.start_mm) * (k as f64 / 8.0))
                .map(|q| distance_to_polyline(q, &before))
                .fold(0.0, f64::max);
            assert!(d <= SHARE * TOL_MM + 1e-12, "{d}");
            assert!(d + tolerance(e) <= TOL_MM + 1e-12, "{d} + {}", tolerance(e));
        }
    }

    #[test]
    fn corners_short_and_long_lines_and_other_items_pass_as_they_are() {
        // A square of 1 mm sides (90° corners), then chords of 0.05 mm (the smoother's) and a
        // 3 mm line, with a dwell between.
        let text = "G21 G90 G64 P0.1 F3000\nG1 X1\nY1\nX0\nY0\nG4 P0.5\n\
                    G1 X0.05 Y0.001\nX0.1 Y0.004\nX0.15 Y0.009\nX3.15\nM2\n";
        let (program, out) = run(text);
        let program: Vec<Item> = program
            .into_iter()
            .filter(|i| !matches!(i, Item::Note(_)))
            .collect();
        let out: Vec<Item> = out
            .into_iter()
            .map(|(i, refined)| {
                assert!(!refined);
                i
            })
            .filter(|i| !matches!(i, Item::Note(_)))
            .collect();
        assert_eq!(out, program);
    }

    #[test]
    fn the_tangent_and_curvature_of_the_circle_through_three_points() {
        let r = 2.0;
        let at = |a: f64| Vector3::new(r * a.cos(), r * a.sin(), 0.0);
        let (a, b, c) = (at(0.1), at(0.5), at(1.4));
        let t = vertex_tangent(b - a, c - b);
        let expected = Vector3::new(-(0.5f64).sin(), (0.5f64).cos(), 0.0);
        assert!((t - expected).norm() < 1e-12, "{t:?}");
        // And its curvature vector there: towards the centre, 1/r long; none on a line.
        let k = circle_curvature(a, b, c);
        assert!((k + at(0.5) / (r * r)).norm() < 1e-12, "{k:?}");
        let line = |x: f64| Vector3::new(x, 2.0 * x, -x);
        assert_eq!(
            circle_curvature(line(0.0), line(0.3), line(1.0)),
            Vector3::zeros()
        );
    }
}
