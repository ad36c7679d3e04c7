//! Chord fairing (jerk-limited mode): the inner vertices of a run of G64 chords moved, within a
//! share of the tolerance, so that the curvature of the curve through them varies slowly.
//!
//! CAM output of a 3D surface (a ball-nose finishing pass, LinuxCNC's `3D_Chips.ngc` and
//! `LHchips4.ngc`) is a polyline within the CAM's own chordal tolerance of the surface: long
//! chords where the surface is flat, short ones where it bends, each vertex a little off the
//! smooth section of the surface. The discrete curvature of such a polyline zig-zags from vertex
//! to vertex (on `3D_Chips`: −0.06, −0.45, −0.06, −0.50 /mm along a section whose curvature is
//! about −0.25), and so does the curvature of any curve through its vertices: the refiner's
//! ([`super::refine`]) passes through them, and the jerk of following it, `v³·(κ² + |dκ/ds|)`,
//! held those programs to 5–12 mm/s where the trapezoid plan runs at 20–48.
//!
//! # The fairing
//!
//! With `K_i` the curvature vector of the parabola through three consecutive vertices (the
//! second difference over the chords' lengths `l₁`, `l₂`:
//! `K_i = 2·(l₂·(P_{i−1} − P_i) + l₁·(P_{i+1} − P_i))/(l₁·l₂·(l₁ + l₂))`), each inner vertex is
//! moved, step after step, so that its curvature approaches the mean of its neighbours'
//! (weighted by the inverse of the chords' lengths): `ΔP_i = −s·(K̄_i − K_i)·l₁·l₂/2` (moving
//! `P_i` by `d` changes `K_i` by about `−2·d/(l₁·l₂)`), [`STEP`] `= s`, every vertex within a
//! ball of radius `r_i` about its programmed place. The fixed point is a polyline whose
//! curvature is as linear as the balls allow: a discrete cubic smoothing spline with the
//! tolerance as its obstacle. A curvature Laplacian with the positions' umbrella weights (the
//! mean of the neighbours' *positions*) was tried first: on chords of unequal length its fixed
//! point makes `κ·l₁·l₂` uniform, not `κ`, and `3D_Chips` came out slower.
//!
//! Only rough vertices beside a chord longer than [`DENSE_MM`] move: runs of shorter chords
//! are the chord smoother's ([`super::smooth`]), and fairing them too took the look-ahead twice
//! the instructions on 20 µm chords; and rough means where the curvature's second difference
//! over the chords (per mm²) is above both `|K_i|²` (the curve's own jerk term) and
//! [`ROUGH_PER_MM2`]. A clean polyline of a circle or of any smooth curve
//! stays as it is: fairing it would only spend tolerance that the refiner needs (LinuxCNC's
//! `trochoidal.ngc`, 0.29 mm chords of circles under a bare G64, planned 2.5 times slower when
//! every vertex could move). The run's first and last chords keep their directions, so the
//! lines beyond meet them as programmed (collinear lines there are merged, and a small bump
//! between two long lines, `quick_arc.ngc`, stays the bump it is).
//!
//! At the ends of the vertices known (the run's ends, and the newest vertex while the run goes
//! on) the missing neighbour's curvature is taken as the vertex's own, not as zero: no pull
//! towards a straight end.
//!
//! # The tolerance
//!
//! `r_i` is [`SHARE`] of the tolerance of the lines either side, and at most [`CHORD_SHARE`] of
//! the shorter of its chords (the chords keep their order and about their lengths). A faired
//! chord is within `δ_j = max(d_j, d_{j+1})` of the programmed one (`d_i` the distance a vertex
//! moved: each point of the chord is a convex combination of its ends, as is the programmed
//! point it moved from), and each line goes on with the tolerance `tol − max(δ_j, δ_{j+1})`:
//! its own chord's, and the next one's, into which the junction's blend reaches (as
//! [`super::smooth`] shares it). The refiner and the blends and filters after it work within
//! what is left, so together they stay within `tol` of the programmed path.
//!
//! What the fairing spends, the refiner no longer has: where it would cut a chord as
//! programmed, the curve over the faired chord ([`super::refine::ChordCurve`]) must still sag
//! within its share of what is left ([`REFINE_MARGIN`]). Where it does not, the vertices that
//! shape that curve stay, and the rest are faired again ([`ROUNDS`]). A long chord between
//! short ones is where that binds: its curve bends much as its neighbours' vertices move.
//!
//! # Which lines, and when
//!
//! Feed moves along a straight line in X/Y/Z longer than [`SHORTEST_MM`] and at most
//! [`super::refine::LONGEST_MM`], with the auxiliary axes still, under G64 with a tolerance,
//! each starting where the one before ends and turning from it by at most
//! [`super::refine::MAX_TURN`] (the sharpest vertex the planner takes as a point of a curve).
//! Anything else ends the run. A vertex is final once [`AHEAD`] more are known: the fairing
//! runs [`ITERATIONS`] steps over the vertices not final each time `2·AHEAD + 1` of them have
//! come, and the oldest `AHEAD` become final (all of them at the run's end). Where no chord
//! longer than [`DENSE_MM`] has come since the last final vertex, every vertex but the newest
//! is final at once. The planner receives each line up to `2·AHEAD + 3` lines late, and two
//! lines late along short chords.

use std::collections::VecDeque;

use nalgebra::Vector3;

use super::refine::{ChordCurve, vertex_tangent};
use super::smooth::{DENSE_MM, g64_chord, with_tolerance};
use crate::gcode::{Element, Item};

/// Share of a line's tolerance its vertices may move by.
pub const SHARE: f64 = 0.25;

/// Share of the shorter of its two chords a vertex may move by.
pub const CHORD_SHARE: f64 = 0.25;

/// Shortest chord of a run. Shorter ones are rounding noise the chord smoother
/// ([`super::smooth`]) takes, or points of a curve the planner follows as one (`curve.rs`).
pub const SHORTEST_MM: f64 = 0.02;

/// A vertex moves only where the second difference of the curvature vectors at it, over its
/// chords' mean length (per mm²; twice the rate of a curvature that zig-zags from vertex to
/// vertex), is above this and above its curvature squared. Evenly sampled smooth curves stay
/// well below (`y = 2·sin(x/3)` in chords of 0.25 mm: at most 0.006), CAM scatter well above
/// (`3D_Chips.ngc`: 1 to 10); 0.002 and 0.02 planned the corpus alike, to 0.3 %.
pub const ROUGH_PER_MM2: f64 = 0.02;

/// Where the refiner would cut a chord as programmed, the fairing keeps the curve over it
/// within this much of the refiner's share of what is left of the tolerance (the refiner's
/// pieces and tangents at a run's ends differ a little from the estimate); where it does not,
/// the vertices that shape that curve stay where they are, and the rest is faired again, up
/// to [`ROUNDS`] times. Without it, the fairing left a 1.66 mm chord of `LHchips4.ngc`
/// unrefined (a long chord's curve bends much as its short neighbours' vertices move), a kink
/// among refined pieces that stopped the motion (`tests/planner_limits.rs`,
/// `a_refined_chord_profile_runs_through_without_stops`).
pub const REFINE_MARGIN: f64 = 0.95;

/// See [`REFINE_MARGIN`]; after that many rounds every vertex not final stays.
pub const ROUNDS: usize = 4;

/// Vertices a vertex waits for before it is final.
pub const AHEAD: usize = 16;

/// Steps of the fairing each time `AHEAD` vertices become final (50 did as well as 400 on
/// `3D_Chips` and `LHchips4`, to 0.5 %).
pub const ITERATIONS: usize = 64;

/// The step `s` (see the module documentation): below 0.5, the iteration's stable bound.
pub const STEP: f64 = 0.3;

/// The run being faired, and the items ready for the refiner.
#[derive(Debug, Clone, Default)]
pub(super) struct ChordFairer {
    /// Programmed and faired vertices of the run from `vbase` (absolute index; vertex 0 is
    /// where the run's first line starts).
    p: VecDeque<Vector3<f64>>,
    q: VecDeque<Vector3<f64>>,
    vbase: usize,
    /// Vertices below this are final.
    nfinal: usize,
    /// The run's lines not passed on, with their tolerances; the first goes from vertex
    /// `lbase` to the next.
    lines: VecDeque<(Element, f64)>,
    lbase: usize,
    /// The last chord of the run longer than [`DENSE_MM`] (absolute index of its start).
    last_long: Option<usize>,
    /// Scratch: the programmed and faired curvature vectors, the balls' radii.
    k: Vec<Option<Vector3<f64>>>,
    radius: Vec<f64>,
    /// What the refiner receives next, in order.
    pub out: VecDeque<Item>,
}

impl ChordFairer {
    /// Takes the next item. `tol_mm` is the tolerance the planner would round its corners by
    /// under the element's blend mode (0: none). Items ready for the refiner go to `out`.
    pub fn push(&mut self, item: &Item, tol_mm: f64) {
        if let Item::Motion(e) = item
            && g64_chord(e, tol_mm, SHORTEST_MM, super::refine::LONGEST_MM)
        {
            let continues = self.lines.back().is_some_and(|(last, _)| {
                last.end_mm == e.start_mm
                    && (last.end_mm - last.start_mm).angle(&(e.end_mm - e.start_mm))
                        <= super::refine::MAX_TURN
            });
            if !continues {
                self.flush();
                self.p.push_back(e.start_mm);
                self.q.push_back(e.start_mm);
                self.nfinal = 1;
            }
            self.p.push_back(e.end_mm);
            self.q.push_back(e.end_mm);
            self.lines.push_back((*e, tol_mm));
            let n = self.vbase + self.p.len();
            if (e.end_mm - e.start_mm).norm() > DENSE_MM {
                self.last_long = Some(n - 2);
            }
            if self.last_long.is_none_or(|j| j + 1 < self.nfinal) {
                // No chord longer than the smoother's since the final vertices: the vertices
                // before the newest stay as they are (see `fair`), and are final at once.
                self.nfinal = n - 1;
                self.emit(false);
            } else if n - self.nfinal > 2 * AHEAD + 1 {
                self.fair(n, false);
                self.nfinal += AHEAD;
                self.emit(false);
            }
            return;
        }
        self.flush();
        self.out.push_back(item.clone());
    }

    /// Ends the run: every line goes to `out`.
    pub fn flush(&mut self) {
        if !self.lines.is_empty() {
            let n = self.vbase + self.p.len();
            self.fair(n, true);
            self.nfinal = n;
            self.emit(true);
        }
        self.p.clear();
        self.q.clear();
        self.lines.clear();
        self.vbase = 0;
        self.lbase = 0;
        self.nfinal = 0;
        self.last_long = None;
    }

    /// Length of the programmed chord from vertex `i` (absolute).
    fn chord_mm(&self, i: usize) -> f64 {
        (self.p[i + 1 - self.vbase] - self.p[i - self.vbase]).norm()
    }

    /// Tolerance of the line from vertex `i` (absolute), not passed on yet.
    fn tol_mm(&self, i: usize) -> f64 {
        self.lines[i - self.lbase].1
    }

    /// Whether the refiner ([`super::refine`]) would cut the chord from vertex `j` (absolute)
    /// as programmed but no longer as faired: the curve over it ([`ChordCurve`]) sags by more
    /// than its share of what the fairing leaves of the tolerance ([`REFINE_MARGIN`] of it).
    fn spoils_refinement(&self, j: usize, n: usize) -> bool {
        if j < self.vbase || j < self.lbase || j + 1 >= n || self.chord_mm(j) <= DENSE_MM {
            return false;
        }
        let tol = self.tol_mm(j);
        let sag = |pts: &VecDeque<Vector3<f64>>| {
            let p = |i: usize| pts[i - self.vbase];
            let (p0, p1) = (p(j), p(j + 1));
            let prev = (j > self.vbase).then(|| p(j - 1));
            let next = (j + 2 < n).then(|| p(j + 2));
            let own = (p1 - p0).normalize();
            let t0 = prev.map_or(own, |a| vertex_tangent(p0 - a, p1 - p0));
            let t1 = next.map_or(own, |b| vertex_tangent(p1 - p0, b - p1));
            ChordCurve::new(prev, p0, p1, next, t0, t1).sag_mm()
        };
        if sag(&self.p) > super::refine::SHARE * tol {
            return false;
        }
        let after = if j + 2 < n { self.moved_mm(j + 2) } else { 0.0 };
        let spent = self.moved_mm(j).max(self.moved_mm(j + 1)).max(after);
        spent > 0.0 && sag(&self.q) > REFINE_MARGIN * super::refine::SHARE * (tol - spent)
    }

    /// The curvature vector at vertex `i` (absolute) of `pts`, from its chords' lengths;
    /// `None` where a neighbour is not among the `n` known.
    fn curvature(&self, pts: &VecDeque<Vector3<f64>>, i: usize, n: usize) -> Option<Vector3<f64>> {
        (i > self.vbase && i + 1 < n).then(|| {
            let (l1, l2) = (self.chord_mm(i - 1), self.chord_mm(i));
            let (a, b, c) = (
                pts[i - 1 - self.vbase],
                pts[i - self.vbase],
                pts[i + 1 - self.vbase],
            );
            ((a - b) * l2 + (c - b) * l1) * (2.0 / (l1 * l2 * (l1 + l2)))
        })
    }

    /// Fairs the vertices not final but the last of the `n` known (`ended`: the run ended
    /// there, and the last chord keeps its direction too).
    fn fair(&mut self, n: usize, ended: bool) {
        let from = self.nfinal.max(1);
        if from + 1 >= n {
            return;
        }
        // Only a vertex beside a chord longer than the smoother's moves: runs of short chords
        // are its ([`DENSE_MM`]).
        if !(from - 1..n - 1).any(|j| self.chord_mm(j) > DENSE_MM) {
            for i in from..n - 1 {
                self.q[i - self.vbase] = self.p[i - self.vbase];
            }
            return;
        }
        // Curvatures are needed from the vertex before the first that moves.
        let lo = from - 1;
        // Which vertices are rough, and how far each may move.
        self.k.clear();
        for i in lo..n {
            let k = self.curvature(&self.p, i, n);
            self.k.push(k);
        }
        self.radius.clear();
        for i in from..n - 1 {
            let end_chord = i == 1 || ended && i + 2 == n;
            let beside_long = self.chord_mm(i - 1).max(self.chord_mm(i)) > DENSE_MM;
            let kb = self.k[i - lo].expect("an inner vertex");
            let ka = self.k[i - 1 - lo].unwrap_or(kb);
            let kc = self.k[i + 1 - lo].unwrap_or(kb);
            let (l1, l2) = (self.chord_mm(i - 1), self.chord_mm(i));
            let rate = (ka - kb * 2.0 + kc).norm() / (0.5 * (l1 + l2));
            let rough = rate > kb.norm_squared().max(ROUGH_PER_MM2);
            let r = if rough && beside_long && !end_chord {
                (SHARE * self.tol_mm(i - 1).min(self.tol_mm(i))).min(CHORD_SHARE * l1.min(l2))
            } else {
                0.0
            };
            self.radius.push(r);
            if r == 0.0 {
                self.q[i - self.vbase] = self.p[i - self.vbase];
            }
        }
        for round in 0..=ROUNDS {
            if self.radius.iter().all(|&r| r == 0.0) {
                return;
            }
            self.steps(lo, from, n);
            let spoiled: Vec<usize> = (from.saturating_sub(2)..n - 1)
                .filter(|&j| self.spoils_refinement(j, n))
                .collect();
            if spoiled.is_empty() {
                return;
            }
            for i in from..n - 1 {
                let shapes = spoiled.iter().any(|&j| i + 1 >= j && i <= j + 2);
                if shapes || round == ROUNDS {
                    self.radius[i - from] = 0.0;
                    self.q[i - self.vbase] = self.p[i - self.vbase];
                }
            }
        }
    }

    /// [`ITERATIONS`] steps of the fairing of the vertices from `from` to `n − 2` (absolute),
    /// with the curvatures from `lo = from − 1` on.
    fn steps(&mut self, lo: usize, from: usize, n: usize) {
        for _ in 0..ITERATIONS {
            self.k.clear();
            for i in lo..n {
                let k = self.curvature(&self.q, i, n);
                self.k.push(k);
            }
            for i in from..n - 1 {
                let r = self.radius[i - from];
                if r == 0.0 {
                    continue;
                }
                let (l1, l2) = (self.chord_mm(i - 1), self.chord_mm(i));
                let kb = self.k[i - lo].expect("an inner vertex");
                let ka = self.k[i - 1 - lo].unwrap_or(kb);
                let kc = self.k[i + 1 - lo].unwrap_or(kb);
                let mean = (ka / l1 + kc / l2) / (1.0 / l1 + 1.0 / l2);
                let p = self.p[i - self.vbase];
                let mut q = self.q[i - self.vbase] - (mean - kb) * (STEP * 0.5 * l1 * l2);
                let d = (q - p).norm();
                if d > r {
                    q = p + (q - p) * (r / d);
                }
                self.q[i - self.vbase] = q;
            }
        }
    }

    /// How far vertex `i` (absolute) moved.
    fn moved_mm(&self, i: usize) -> f64 {
        (self.q[i - self.vbase] - self.p[i - self.vbase]).norm()
    }

    /// Passes on the lines whose tolerance is known: line `j` once vertex `j + 2` is final,
    /// or all at the run's end.
    fn emit(&mut self, ended: bool) {
        let n = self.vbase + self.p.len();
        while !self.lines.is_empty() {
            let j = self.lbase;
            if !(ended || j + 2 < self.nfinal) {
                break;
            }
            let after = if j + 2 < n { self.moved_mm(j + 2) } else { 0.0 };
            let spent = self.moved_mm(j).max(self.moved_mm(j + 1)).max(after);
            let (mut e, tol_mm) = self.lines.pop_front().expect("checked");
            e.start_mm = self.q[j - self.vbase];
            e.end_mm = self.q[j + 1 - self.vbase];
            if spent > 0.0 {
                e.blend = with_tolerance(e.blend, tol_mm - spent);
            }
            self.out.push_back(Item::Motion(e));
            self.lbase += 1;
        }
        // Keep two vertices before the first one not final, for the curvatures.
        while self.vbase + 2 < self.nfinal.min(self.lbase) {
            self.p.pop_front();
            self.q.pop_front();
            self.vbase += 1;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gcode::{BlendMode, parse_program};
    use crate::planner::refine::tests::polyline;
    use crate::planner::smooth::closest_on_segment;

    const TOL_MM: f64 = 0.1;

    /// A CAM section of a surface: points on `y = 2·sin(x/3)` with chords alternating between
    /// about `steps.0` and `steps.1` mm along X, each point off the curve across it by up to
    /// ±`noise_mm` (a deterministic scatter, as a CAM's chordal tolerance leaves them).
    fn cam_section(n: usize, steps: (f64, f64), noise_mm: f64) -> Vec<(f64, f64)> {
        let mut x = 0.0f64;
        (0..n)
            .map(|k| {
                x += if k % 2 == 0 { steps.0 } else { steps.1 };
                let (y, dy) = (2.0 * (x / 3.0).sin(), 2.0 / 3.0 * (x / 3.0).cos());
                let off = noise_mm * ((k * 7919 % 13) as f64 / 6.0 - 1.0);
                let nrm = (1.0 + dy * dy).sqrt();
                (x - dy / nrm * off, y + off / nrm)
            })
            .collect()
    }

    /// The program's items, and what the fairer makes of them; `each` sees the items pushed
    /// so far and what has come out, after each push.
    fn run_with(text: &str, mut each: impl FnMut(&[Item], &[Item])) -> (Vec<Item>, Vec<Item>) {
        let program = parse_program(text, "t.ngc", Vector3::zeros()).expect("parses");
        let mut f = ChordFairer::default();
        let mut out = Vec::new();
        for (k, item) in program.items.iter().enumerate() {
            let tol = match item {
                Item::Motion(e) if matches!(e.blend, BlendMode::Blend { .. }) => TOL_MM,
                _ => 0.0,
            };
            f.push(item, tol);
            out.extend(f.out.drain(..));
            each(&program.items[..=k], &out);
        }
        f.flush();
        out.extend(f.out.drain(..));
        (program.items, out)
    }

    fn run(text: &str) -> (Vec<Item>, Vec<Item>) {
        run_with(text, |_, _| {})
    }

    fn lines(items: &[Item]) -> Vec<Element> {
        items
            .iter()
            .filter_map(Item::motion)
            .filter(|e| !e.rapid)
            .copied()
            .collect()
    }

    fn tolerance(e: &Element) -> f64 {
        match e.blend {
            BlendMode::Blend { p_mm, .. } => p_mm,
            _ => 0.0,
        }
    }

    /// The largest distance from the programmed path of 16 points along a line.
    fn deviation(e: &Element, path: &[Element]) -> f64 {
        (0..=16)
            .map(|k| e.start_mm + (e.end_mm - e.start_mm) * (k as f64 / 16.0))
            .map(|q| {
                path.iter()
                    .map(|p| (q - closest_on_segment(q, p.start_mm, p.end_mm)).norm())
                    .fold(f64::INFINITY, f64::min)
            })
            .fold(0.0, f64::max)
    }

    fn turn(a: &Element, b: &Element) -> f64 {
        (a.end_mm - a.start_mm).angle(&(b.end_mm - b.start_mm))
    }

    /// The largest rate of the curvature vector (its second difference over the chords, per
    /// mm²) at the inner vertices of a chain of lines.
    fn largest_rate(path: &[Element]) -> f64 {
        let pts: Vec<Vector3<f64>> = std::iter::once(path[0].start_mm)
            .chain(path.iter().map(|e| e.end_mm))
            .collect();
        let k: Vec<Vector3<f64>> = pts
            .windows(3)
            .map(|w| {
                let (l1, l2) = ((w[1] - w[0]).norm(), (w[2] - w[1]).norm());
                ((w[0] - w[1]) * l2 + (w[2] - w[1]) * l1) * (2.0 / (l1 * l2 * (l1 + l2)))
            })
            .collect();
        k.windows(3)
            .zip(pts.windows(4))
            .map(|(k, p)| {
                let l = 0.5 * ((p[2] - p[1]).norm() + (p[3] - p[2]).norm());
                (k[0] - k[1] * 2.0 + k[2]).norm() / l
            })
            .fold(0.0, f64::max)
    }

    #[test]
    fn a_cam_section_becomes_fair_within_a_quarter_of_the_tolerance() {
        let (programmed, faired) = run(&polyline(&cam_section(200, (0.1, 0.4), 0.01)));
        let (p, f) = (lines(&programmed), lines(&faired));
        assert_eq!(p.len(), f.len(), "one element per programmed line");
        for (a, b) in p.iter().zip(&f) {
            assert_eq!((a.line, a.col, a.feed_mm_s), (b.line, b.col, b.feed_mm_s));
        }
        for w in f.windows(2) {
            assert_eq!(w[0].end_mm, w[1].start_mm, "line {}", w[1].line);
        }
        // The run's first and last chords stay as programmed, bit for bit.
        assert_eq!((f[0].start_mm, f[0].end_mm), (p[0].start_mm, p[0].end_mm));
        let last = p.len() - 1;
        assert_eq!(
            (f[last].start_mm, f[last].end_mm),
            (p[last].start_mm, p[last].end_mm)
        );
        // Every vertex within its ball, every line within the tolerance with what it leaves.
        let mut moved = 0;
        for (a, b) in p.iter().zip(&f) {
            let d = (b.end_mm - a.end_mm).norm();
            assert!(d <= SHARE * TOL_MM + 1e-12, "line {}: moved {d}", a.line);
            moved += usize::from(d > 0.0);
            let dev = deviation(b, &p);
            assert!(
                dev + tolerance(b) <= TOL_MM + 1e-12,
                "line {}: {dev} off, {} left",
                b.line,
                tolerance(b)
            );
        }
        assert!(moved > p.len() / 2, "{moved} of {} vertices moved", p.len());
        // And the curvature varies far more slowly: what the jerk of following it pays.
        let (before, after) = (largest_rate(&p), largest_rate(&f));
        assert!(after < before / 10.0, "rate {before} → {after} /mm²");
    }

    #[test]
    fn a_clean_curve_stays_as_it_is() {
        // Chords of 0.29 mm on a circle of 5 mm (LinuxCNC's trochoidal.ngc), and the CAM
        // section's curve in even chords of 0.25 mm without scatter: nothing is rough, nothing
        // moves.
        let circle: Vec<(f64, f64)> = (0..=110)
            .map(|k| k as f64 * 0.058)
            .map(|a| (5.0 * a.cos(), 5.0 * a.sin()))
            .collect();
        for points in [circle, cam_section(200, (0.25, 0.25), 0.0)] {
            let (programmed, faired) = run(&polyline(&points));
            let (p, f) = (lines(&programmed), lines(&faired));
            let moved = p.iter().zip(&f).filter(|(a, b)| a != b).count();
            assert_eq!(moved, 0, "{moved} of {} lines changed", p.len());
        }
    }

    #[test]
    fn runs_of_short_chords_are_the_smoother_s_and_pass_two_lines_late() {
        // The CAM section's scatter on chords of 30 and 60 µm: rough, but no chord longer
        // than the smoother's; nothing moves, and each line comes out as soon as the one two
        // after it has come.
        let points = cam_section(300, (0.03, 0.06), 0.005);
        let (programmed, out) = run_with(&polyline(&points), |pushed, out| {
            let (p, o) = (lines(pushed), lines(out));
            assert!(
                o.len() + 2 >= p.len(),
                "{} lines out of {}",
                o.len(),
                p.len()
            );
        });
        assert_eq!(lines(&programmed), lines(&out));
    }

    #[test]
    fn corners_and_other_items_end_the_run_where_they_are() {
        // Two scattered sections meeting at a corner (of about 0.6 rad), then a long line, an arc, and a
        // dwell: the corner's vertex stays, and every item comes out in order.
        let a = cam_section(60, (0.1, 0.4), 0.01);
        let (x1, y1) = *a.last().unwrap();
        let (c, s) = (1f64.cos(), 1f64.sin());
        let section = cam_section(60, (0.1, 0.4), 0.01);
        let (x0, y0) = section[0];
        let b: Vec<(f64, f64)> = section
            .iter()
            .map(|&(x, y)| (x - x0, y - y0))
            .map(|(x, y)| (x1 + c * x + s * y, y1 - s * x + c * y))
            .collect();
        let mut text = polyline(&[a, b[1..].to_vec()].concat()).replace("G4 P0.1\nM2\n", "");
        text.push_str("G1 X100 Y0\nG2 X110 Y0 I5 J0\nG4 P0.1\nM2\n");
        let (programmed, faired) = run(&text);
        assert_eq!(programmed.len(), faired.len());
        for (a, b) in programmed.iter().zip(&faired) {
            match (a, b) {
                (Item::Motion(a), Item::Motion(b)) => assert_eq!(
                    (a.line, a.kind, a.rapid, a.feed_mm_s),
                    (b.line, b.kind, b.rapid, b.feed_mm_s)
                ),
                (a, b) => assert_eq!(a, b),
            }
        }
        let (p, f) = (lines(&programmed), lines(&faired));
        let corner = p
            .iter()
            .position(|e| (e.end_mm - Vector3::new(x1, y1, 0.0)).norm() < 1e-6)
            .expect("the corner");
        assert!(
            turn(&p[corner], &p[corner + 1]) > super::super::refine::MAX_TURN,
            "a corner"
        );
        assert!(
            f[..corner].iter().any(|e| e != &p[e.line - p[0].line]),
            "the first section moves"
        );
        assert_eq!(f[corner].end_mm, p[corner].end_mm, "the corner stays");
        assert_eq!(f[corner + 1].start_mm, p[corner + 1].start_mm);
        // The long line and the arc as programmed.
        assert_eq!(&f[f.len() - 2..], &p[p.len() - 2..]);
    }
}
