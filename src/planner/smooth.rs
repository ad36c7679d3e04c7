//! Chord smoothing (jerk-limited mode): the vertices of a dense run of G64 lines moved onto the
//! smooth curve the run approximates, within a share of the tolerance.
//!
//! CAM output describes a curve by chords whose end points are rounded to the program's
//! decimals: LinuxCNC's `performance/contour.ngc` is a 1-inch circle of 10 000 chords of
//! 16 µm written with 4 decimals of an inch, so each vertex sits up to 1.3 µm off the circle
//! and the chords' directions scatter by ±0.16 rad about the tangent. Followed as written,
//! every vertex is a kink the axes must take, and a jerk-limited plan crawls through them
//! (2 mm/s where the circle allows 200). The run is a smooth curve *within the tolerance*,
//! and a machine that may leave the path by `tol` may follow that curve instead.
//!
//! Each inner vertex `P_i` of a run moves towards `M_i`, the centre of the least-squares
//! parabola through `P_{i−W} … P_{i+W}` (Savitzky–Golay: `M_i = Σ c_j·P_{i+j}`,
//! `c_j = (3(3W² + 3W − 1) − 15j²)/((2W + 1)(4W² + 4W − 3))`), across the window's chord
//! `P_{i+W} − P_{i−W}` only: `Q_i` is `P_i` plus the part of `M_i − P_i` square to that chord.
//! The vertices keep their places along the run (a feed change stays where it was programmed,
//! a straight run stays as it is) and only what bends it moves. A parabola follows a curve to
//! second order, so unlike a moving average the smoothing does not pull a circle inwards (a
//! triangular mean of 8 chords either side moved the vertices of a 0.5 mm circle of 10 µm
//! chords by 1.3 µm, and where the vertices it smoothed met those it left, that step was a new
//! kink: 3× slower than without smoothing); what moves is the rounding noise. `W` is chosen per
//! vertex, the largest of `W_MAX`, `W_MAX/2`, …, 2 that keeps the smoothed run within
//! [`SHARE`] of the tolerance of the programmed one (else the vertex stays), and only where the
//! run is rough ([`ROUGH_RAD`]).
//!
//! # The bound, and how the rest of the tolerance is shared
//!
//! For a smoothed chord `Q_{i−1} Q_i`, let `a`, `b` be the nearest points of the programmed
//! polyline to its ends, at distances `d_{i−1}`, `d_i`. A point `(1 − t)·Q_{i−1} + t·Q_i` is
//! within `max(d_{i−1}, d_i)` of `(1 − t)·a + t·b` on the chord `a b`; and every point of that
//! chord is within `s` of the polyline between `a` and `b`, where `s` is the largest distance
//! of that piece's vertices from the line `a b` (the piece projects onto the whole chord, so
//! some point of it shares the point's projection, and its distance from the line is largest at
//! a vertex). So the smoothed chord stays within `δ_i = max(d_{i−1}, d_i) + s` of the program.
//! A vertex is accepted only where the chords on both sides of it, the one after taken to the
//! next vertex as programmed, keep `δ ≤ SHARE·tol`; the programmed vertex (`W = 0`) always
//! passes that (the previous vertex was accepted with it), so the run is never worse than as
//! written.
//!
//! The planner rounds a junction and filters the axes within the G64 tolerance of the element
//! before it, measured from the path it is given. So each element of the run goes on with the
//! tolerance `tol − max(δ_i, δ_{i+1})` (its own chord's deviation, and the next one's, into
//! which the junction's blend reaches): blends, filters and smoothing together stay within
//! `tol` of the programmed path. The run's first element and its last vertex are kept as
//! programmed, so the elements before and after the run keep theirs.
//!
//! # Which lines
//!
//! Feed moves (not rapids) along a straight line in X/Y/Z no longer than [`DENSE_MM`], with the
//! auxiliary axes still, under G64 with a tolerance (`P`, or the machine's
//! `default_tolerance_mm` for a bare G64), each starting exactly where the one before ends, all
//! with the same blend mode, none turning from the one before by more than [`CORNER_RAD`].
//! Anything else (an arc, a rapid, a longer line, a dwell, a note, another blend mode, a corner,
//! the end) ends the run: its last vertex stays where it was programmed. A vertex waits for the `W_MAX` that follow it, so the
//! planner receives each element `W_MAX + 2` lines late, and all of them at the run's end.

use std::collections::VecDeque;

use nalgebra::Vector3;

use crate::gcode::{BlendMode, Element, ElementKind, Item};

/// Largest half-width of the smoothing window, in chords. 16 chords of 16 µm either side
/// bring `contour.ngc`'s jerk-limited time from 66.8 s to 1.7 s (8: 4.5 s).
pub const W_MAX: usize = 16;

/// Share of an element's tolerance the smoothing may take; the blends and the axis filters
/// share the rest.
pub const SHARE: f64 = 0.25;

/// Longest line of a run. Rounding to a program's decimals moves a vertex by a micrometre or
/// so, which turns a chord by `ε/L`: 0.16 rad on `contour.ngc`'s 16 µm chords, below 0.013 rad
/// on chords of 0.1 mm and more, which the planner's vertex rules take at speed. Longer chords
/// that turn irregularly are the part's shape (a CAM surface's, `3D_Chips.ngc`): smoothing them
/// within a share of the tolerance would only reshape them.
pub const DENSE_MM: f64 = 0.1;

/// A vertex that turns the run by more than this is a corner: the run ends there and the next
/// begins. 0.6 rad (34°) passes the scatter of 4-decimal chords of a curve (±0.16 rad on
/// `contour.ngc`) and stops at the corners of a part. Spread over the chords beside it, a
/// corner would become several sharp kinks instead of one, each a stop.
pub const CORNER_RAD: f64 = 0.6;

/// A vertex is smoothed only where the turns around it scatter by more than this (radians):
/// where the chords are rough, not where they already follow their curve (clean CAM output,
/// whose smoothing would only spend tolerance the blends and filters could use). The scatter
/// a 1 ms plan's vertex rule lets pass at speed is of this order.
pub const ROUGH_RAD: f64 = 0.01;

/// Chords either side of a vertex searched for the nearest place to its smoothed position.
const NEAREST_CHORDS: usize = 3;

/// A place on the programmed polyline of a run: chord `seg` (from vertex `seg` to `seg + 1`)
/// at the point `at`.
#[derive(Debug, Clone, Copy)]
struct OnPath {
    seg: usize,
    at: Vector3<f64>,
}

/// A smoothed vertex: where it is, how far from the programmed run, and its nearest place on
/// it.
#[derive(Debug, Clone, Copy)]
struct Smoothed {
    q: Vector3<f64>,
    d: f64,
    near: OnPath,
    /// The bound `δ` of the chord that ends here (from the previous smoothed vertex).
    delta_in: f64,
}

/// The run being smoothed, and the items ready for the planner.
#[derive(Debug, Clone, Default)]
pub(super) struct ChordSmoother {
    /// Programmed vertices of the run from `pts_base` (absolute index; vertex 0 is where the
    /// run's first line starts), as far back as a window or a bound may still reach.
    pts: VecDeque<Vector3<f64>>,
    pts_base: usize,
    /// Beside `pts`: the unit direction of the chord from each vertex to the next (zero for
    /// the last), and each vertex's roughness (0 until its neighbours are known), see
    /// [`ChordSmoother::roughness`].
    units: VecDeque<Vector3<f64>>,
    rough: VecDeque<f64>,
    /// The run's lines not yet passed on; the first goes from vertex `line_base` to the next.
    lines: VecDeque<Element>,
    line_base: usize,
    /// Final smoothed vertices from `line_base` on.
    done: VecDeque<Smoothed>,
    /// The run's tolerance and blend mode (`None`: no run).
    tol_mm: f64,
    blend: Option<BlendMode>,
    /// What the planner receives next, in order.
    pub out: VecDeque<Item>,
}

impl ChordSmoother {
    /// Takes the next item. `tol_mm` is the tolerance the planner would round its corners by
    /// under the element's blend mode (0: none). Items ready for the planner go to `out`.
    pub fn push(&mut self, item: &Item, tol_mm: f64) {
        if let Item::Motion(e) = item
            && eligible(e, tol_mm)
        {
            // A corner (a turn of more than CORNER_RAD) ends the run and starts the next:
            // the planner takes it as the corner it is, and no window reaches across it.
            let corner = self.lines.back().is_some_and(|last| {
                let (u, v) = (last.end_mm - last.start_mm, e.end_mm - e.start_mm);
                u.angle(&v) > CORNER_RAD
            });
            let continues = self.blend == Some(e.blend)
                && self.pts.back() == Some(&e.start_mm)
                && self.tol_mm == tol_mm
                && !corner;
            if !continues {
                self.flush();
                self.blend = Some(e.blend);
                self.tol_mm = tol_mm;
                self.push_vertex(e.start_mm);
            }
            self.push_vertex(e.end_mm);
            self.lines.push_back(*e);
            self.advance(false);
            return;
        }
        self.flush();
        self.out.push_back(item.clone());
    }

    /// Ends the run: every line goes to `out`.
    pub fn flush(&mut self) {
        if self.blend.is_some() {
            self.advance(true);
        }
        self.pts.clear();
        self.units.clear();
        self.rough.clear();
        self.lines.clear();
        self.done.clear();
        self.pts_base = 0;
        self.line_base = 0;
        self.blend = None;
    }

    /// Programmed vertex `i` (absolute).
    fn p(&self, i: usize) -> Vector3<f64> {
        self.pts[i - self.pts_base]
    }

    /// Smoothed vertex `i` (absolute), final.
    fn q(&self, i: usize) -> Smoothed {
        self.done[i - self.line_base]
    }

    /// Smoothes the vertices whose windows are complete (all of them at the run's end) and
    /// passes on the lines whose tolerance is then known.
    fn advance(&mut self, ended: bool) {
        let m = self.pts_base + self.pts.len() - 1; // the last vertex known
        loop {
            let i = self.line_base + self.done.len();
            let fixed = i <= 1 || i == m && ended;
            if i > m || !fixed && i + W_MAX > m && !ended {
                break;
            }
            let s = if fixed {
                self.programmed(i)
            } else {
                self.smooth(i, W_MAX.min(i).min(m - i))
            };
            self.done.push_back(s);
        }
        // Line `j` (from vertex j to j + 1) goes once vertex j + 2 is final, or at the end.
        while !self.lines.is_empty() {
            let j = self.line_base;
            let final_to = self.line_base + self.done.len(); // vertices below are final
            let next_delta = if j + 2 < final_to {
                self.q(j + 2).delta_in
            } else if ended && j + 1 == m {
                0.0
            } else {
                break;
            };
            let (a, b) = (self.q(j), self.q(j + 1));
            let mut e = self.lines.pop_front().expect("checked");
            e.start_mm = a.q;
            e.end_mm = b.q;
            let spent = b.delta_in.max(next_delta);
            if spent > 0.0 {
                e.blend = with_tolerance(e.blend, self.tol_mm - spent);
            }
            self.out.push_back(Item::Motion(e));
            self.done.pop_front();
            self.line_base += 1;
        }
        // Keep the vertices a window or a bound may still reach: from the nearest place of the
        // last final vertex (within W_MAX of it) on.
        let keep_from = (self.line_base + self.done.len()).saturating_sub(2 * W_MAX + 2);
        while self.pts_base < keep_from.min(self.line_base) {
            self.pts.pop_front();
            self.units.pop_front();
            self.rough.pop_front();
            self.pts_base += 1;
        }
    }

    /// Vertex `i` as programmed.
    fn programmed(&self, i: usize) -> Smoothed {
        let at = self.p(i);
        let prev = (i > self.line_base).then(|| self.q(i - 1));
        let near = OnPath { seg: i, at };
        let delta_in = prev.map_or(0.0, |a| chord_bound(self, &a, 0.0, near));
        Smoothed {
            q: at,
            d: 0.0,
            near,
            delta_in,
        }
    }

    /// Vertex `i` smoothed with the widest window up to `w_max` that keeps both of its chords
    /// within the share of the tolerance.
    fn smooth(&self, i: usize, w_max: usize) -> Smoothed {
        let limit = SHARE * self.tol_mm;
        let prev = self.q(i - 1);
        let next = OnPath {
            seg: i + 1,
            at: self.p(i + 1),
        };
        if w_max < 2 || self.roughness(i, w_max) < ROUGH_RAD {
            return self.programmed(i);
        }
        let mut w = w_max;
        while w > 1 {
            // Savitzky–Golay: the centre of the least-squares parabola through the window,
            // `Σ c_j·P_{i+j}` with `c_j = (3(3w² + 3w − 1) − 15j²)/((2w + 1)(4w² + 4w − 3))`.
            let (wf, mut sum) = (w as f64, Vector3::zeros());
            let norm = (2.0 * wf + 1.0) * (4.0 * wf * wf + 4.0 * wf - 3.0);
            // The window's vertices by iterator (up to 33 of them, at every vertex).
            let p_i = self.p(i);
            let window = (i - w - self.pts_base)..=(i + w - self.pts_base);
            for (j, &p_j) in self.pts.range(window).enumerate() {
                let k = j.abs_diff(w) as f64;
                let c = (3.0 * (3.0 * wf * wf + 3.0 * wf - 1.0) - 15.0 * k * k) / norm;
                sum += (p_j - p_i) * c;
            }
            // Across the window's chord only: the vertex keeps its place along the run (where
            // the feed changes, say), and only what bends the run moves.
            let shift = sum;
            let along = self.p(i + w) - self.p(i - w);
            let l2 = along.norm_squared();
            let q = if l2 > 0.0 {
                self.p(i) + shift - along * (shift.dot(&along) / l2)
            } else {
                self.p(i) + shift
            };
            // Q_i moved across the run by about the rounding: its nearest place is on a chord
            // beside P_i (a farther one could only be nearer, so the bound stays safe).
            let reach = w.min(NEAREST_CHORDS);
            let near = self.nearest(q, i - reach, i + reach);
            let d = (q - near.at).norm();
            if d <= limit {
                let delta_in = chord_bound(self, &prev, d, near);
                let delta_out = d + self.sag(near, next);
                if delta_in <= limit && delta_out <= limit {
                    return Smoothed {
                        q,
                        d,
                        near,
                        delta_in,
                    };
                }
            }
            w /= 2;
        }
        self.programmed(i)
    }

    /// Appends a programmed vertex, with the direction of the chord that ends there and the
    /// roughness of the vertex two back, whose neighbours are now known.
    fn push_vertex(&mut self, p: Vector3<f64>) {
        if let Some(&last) = self.pts.back() {
            *self.units.back_mut().expect("beside pts") = (p - last).normalize();
        }
        self.pts.push_back(p);
        self.units.push_back(Vector3::zeros());
        self.rough.push_back(0.0);
        let n = self.pts.len();
        if n >= 5 {
            // Vertex n − 3 (of the deque): its turn against the mean of its neighbours'.
            let u = |k: usize| self.units[k];
            let turn = |k: usize| u(k) - u(k - 1);
            let j = n - 3;
            self.rough[j] = (turn(j) - 0.5 * (turn(j - 1) + turn(j + 1))).norm();
        }
    }

    /// How rough the chords within `w` of vertex `i` are: the largest
    /// `|Δu_j − (Δu_{j−1} + Δu_{j+1})/2|` over the vertices `j` whose neighbours lie in the
    /// window, where `Δu_j` is the change of the unit chord direction at vertex `j`. A curve's
    /// turns change smoothly, even where its curvature changes fast (the centre of a spiral),
    /// and leave this near 0; rounding noise flips the turns from vertex to vertex.
    fn roughness(&self, i: usize, w: usize) -> f64 {
        ((i + 2 - w)..(i + w - 1))
            .map(|j| self.rough[j - self.pts_base])
            .fold(0.0, f64::max)
    }

    /// The nearest place to `q` on the programmed chords from vertex `from` to vertex `to`.
    fn nearest(&self, q: Vector3<f64>, from: usize, to: usize) -> OnPath {
        let mut best = OnPath {
            seg: from,
            at: self.p(from),
        };
        let mut best_d = f64::INFINITY;
        for seg in from..to {
            let at = closest_on_segment(q, self.p(seg), self.p(seg + 1));
            let d = (q - at).norm_squared();
            if d < best_d {
                best_d = d;
                best = OnPath { seg, at };
            }
        }
        best
    }

    /// The largest distance of the programmed vertices between `a` and `b` from the line
    /// through them (from the point, where they coincide).
    fn sag(&self, a: OnPath, b: OnPath) -> f64 {
        let (a, b) = if a.seg <= b.seg { (a, b) } else { (b, a) };
        ((a.seg + 1)..=b.seg)
            .map(|v| distance_to_line(self.p(v), a.at, b.at))
            .fold(0.0, f64::max)
    }
}

/// The bound `δ` of the smoothed chord from `a` to a vertex at distance `d` from the
/// programmed run, nearest to it at `near`.
fn chord_bound(s: &ChordSmoother, a: &Smoothed, d: f64, near: OnPath) -> f64 {
    a.d.max(d) + s.sag(a.near, near)
}

/// A line the smoother may move the ends of: see the module documentation.
fn eligible(e: &Element, tol_mm: f64) -> bool {
    g64_chord(e, tol_mm, 0.0, DENSE_MM)
}

/// A feed move along a straight line in X/Y/Z longer than `above_mm` and at most `up_to_mm`,
/// with the auxiliary axes still, under G64 with a tolerance `tol_mm`: a chord the smoother
/// or the refiner ([`super::refine`]) may reshape within that tolerance.
pub(super) fn g64_chord(e: &Element, tol_mm: f64, above_mm: f64, up_to_mm: f64) -> bool {
    let l_mm = (e.end_mm - e.start_mm).norm();
    e.kind == ElementKind::Line
        && !e.rapid
        && tol_mm > 0.0
        && tol_mm.is_finite()
        && matches!(e.blend, BlendMode::Blend { .. })
        && e.aux.start == e.aux.end
        && e.start_mm != e.end_mm
        && l_mm > above_mm
        && l_mm <= up_to_mm
        && e.start_mm
            .iter()
            .chain(e.end_mm.iter())
            .all(|c| c.is_finite())
}

/// `blend` with its G64 tolerance set to `tol_mm`.
pub(super) fn with_tolerance(blend: BlendMode, tol_mm: f64) -> BlendMode {
    match blend {
        BlendMode::Blend { q_mm, .. } => BlendMode::Blend {
            p_mm: tol_mm.max(0.0),
            q_mm,
        },
        other => other,
    }
}

pub(super) fn closest_on_segment(
    q: Vector3<f64>,
    a: Vector3<f64>,
    b: Vector3<f64>,
) -> Vector3<f64> {
    let ab = b - a;
    let l2 = ab.norm_squared();
    if l2 == 0.0 {
        return a;
    }
    let t = ((q - a).dot(&ab) / l2).clamp(0.0, 1.0);
    a + ab * t
}

fn distance_to_line(p: Vector3<f64>, a: Vector3<f64>, b: Vector3<f64>) -> f64 {
    let ab = b - a;
    let l = ab.norm();
    if l == 0.0 {
        return (p - a).norm();
    }
    (p - a).cross(&ab).norm() / l
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gcode::parse_program;

    const TOL_MM: f64 = 0.01;

    /// A circle of `n` chords of radius `r_mm`, written with `decimals`, after a G0 to its
    /// start; `laps` of it.
    fn chorded_circle(r_mm: f64, n: usize, decimals: usize, laps: usize) -> String {
        let mut text = format!("G21 G90 G64 F3000\nG0 X{r_mm:.decimals$} Y0\n");
        for k in 1..=n * laps {
            let a = std::f64::consts::TAU * k as f64 / n as f64;
            let (x, y) = (r_mm * a.cos(), r_mm * a.sin());
            text.push_str(&format!("G1 X{x:.decimals$} Y{y:.decimals$}\n"));
        }
        text.push_str("G4 P0.1\nM2\n");
        text
    }

    fn run(text: &str) -> (Vec<Item>, Vec<Item>) {
        let program = parse_program(text, "t.ngc", Vector3::zeros()).expect("parses");
        let mut s = ChordSmoother::default();
        let mut out = Vec::new();
        for item in &program.items {
            let tol = match item {
                Item::Motion(e) if matches!(e.blend, BlendMode::Blend { .. }) => TOL_MM,
                _ => 0.0,
            };
            s.push(item, tol);
            out.extend(s.out.drain(..));
        }
        s.flush();
        out.extend(s.out.drain(..));
        (program.items, out)
    }

    fn lines(items: &[Item]) -> Vec<Element> {
        items.iter().filter_map(Item::motion).copied().collect()
    }

    fn distance_to_polyline(q: Vector3<f64>, path: &[Element]) -> f64 {
        path.iter()
            .map(|e| (q - closest_on_segment(q, e.start_mm, e.end_mm)).norm())
            .fold(f64::INFINITY, f64::min)
    }

    /// The largest distance from the programmed path of 16 points along each line, and of its
    /// ends.
    fn deviation(e: &Element, path: &[Element]) -> f64 {
        (0..=16)
            .map(|k| e.start_mm + (e.end_mm - e.start_mm) * (k as f64 / 16.0))
            .map(|q| distance_to_polyline(q, path))
            .fold(0.0, f64::max)
    }

    fn turn(a: &Element, b: &Element) -> f64 {
        let (u, v) = (a.end_mm - a.start_mm, b.end_mm - b.start_mm);
        u.angle(&v)
    }

    fn tolerance(e: &Element) -> f64 {
        match e.blend {
            BlendMode::Blend { p_mm, .. } if p_mm.is_finite() => p_mm,
            _ => TOL_MM,
        }
    }

    #[test]
    fn a_rounded_circle_becomes_smooth_within_a_quarter_of_the_tolerance() {
        // 25.4 mm, 10 000 chords of 16 µm, 4 decimals of an inch (LinuxCNC's contour.ngc) as
        // 2.54 µm steps: here 3 decimals of a mm on 2000 chords of 80 µm, 1 µm steps.
        let (programmed, smoothed) = run(&chorded_circle(25.4, 2000, 3, 1));
        let (p, s) = (lines(&programmed), lines(&smoothed));
        assert_eq!(p.len(), s.len(), "one element per programmed line");
        for (a, b) in p.iter().zip(&s) {
            assert_eq!((a.line, a.col, a.feed_mm_s), (b.line, b.col, b.feed_mm_s));
        }
        for w in s.windows(2) {
            assert_eq!(
                w[0].end_mm, w[1].start_mm,
                "line {}: the path is continuous",
                w[1].line
            );
        }
        assert_eq!(
            s.last().unwrap().end_mm,
            p.last().unwrap().end_mm,
            "the run ends exact"
        );
        assert_eq!(s[1].start_mm, p[1].start_mm, "its first line is kept");
        let mut worst = 0.0f64;
        for e in &s {
            let d = deviation(e, &p);
            worst = worst.max(d);
            assert!(
                d <= SHARE * TOL_MM + 1e-12,
                "line {}: {d} mm off the program",
                e.line
            );
        }
        assert!(worst > 0.0, "something moved");
        // The rounding noise of the chords' turns: programmed, up to 2 µm / 80 µm; smoothed,
        // the circle's own 3.1 mrad and a little.
        let max_turn = |v: &[Element]| {
            v[2..]
                .windows(2)
                .map(|w| turn(&w[0], &w[1]))
                .fold(0.0, f64::max)
        };
        let (before, after) = (max_turn(&p), max_turn(&s));
        assert!(before > 0.01, "the program is noisy: {before}");
        // Where the turns scatter by less than ROUGH_RAD the vertices stay.
        assert!(
            after < 0.0032 + ROUGH_RAD && after < 0.5 * before,
            "smoothed turns at most {after} rad (programmed {before})"
        );
    }

    #[test]
    fn every_line_keeps_the_tolerance_its_neighbours_leave() {
        let (programmed, smoothed) = run(&chorded_circle(5.0, 700, 3, 2));
        let (p, s) = (lines(&programmed), lines(&smoothed));
        for (k, e) in s.iter().enumerate() {
            // Its own deviation and the next line's, into which its corner's blend reaches,
            // leave what the planner is told it may use.
            let own = deviation(e, &p);
            let next = s.get(k + 1).map_or(0.0, |n| deviation(n, &p));
            assert!(
                tolerance(e) + own.max(next) <= TOL_MM + 1e-9,
                "line {}: tolerance {} with {own} and {next} mm spent",
                e.line,
                tolerance(e)
            );
            assert!(tolerance(e) >= (1.0 - SHARE) * TOL_MM - 1e-12);
        }
    }

    #[test]
    fn a_corner_ends_the_run_where_it_is() {
        // Two legs of 50 µm chords with a 1 µm zigzag, meeting at a right angle at (5, 0).
        let mut text = String::from("G21 G90 G64 P0.01 F3000\nG0 X0 Y0\n");
        for k in 1..=100 {
            let y = if k % 2 == 1 && k < 100 { 0.001 } else { 0.0 };
            text.push_str(&format!("G1 X{:.3} Y{y:.3}\n", 0.05 * k as f64));
        }
        for k in 1..=100 {
            let x = if k % 2 == 1 { 5.001 } else { 5.0 };
            text.push_str(&format!("G1 X{x:.3} Y{:.3}\n", 0.05 * k as f64));
        }
        text.push_str("M2\n");
        let (programmed, smoothed) = run(&text);
        let (p, s) = (lines(&programmed), lines(&smoothed));
        let corner = Vector3::new(5.0, 0.0, 0.0);
        assert!(s.iter().any(|e| e.end_mm == corner), "the corner stays");
        let worst = s.iter().map(|e| deviation(e, &p)).fold(0.0, f64::max);
        assert!(worst <= SHARE * TOL_MM + 1e-12, "{worst}");
        let moved = p
            .iter()
            .zip(&s)
            .filter(|(a, b)| a.end_mm != b.end_mm)
            .count();
        assert!(
            moved > 150,
            "the zigzags are smoothed: {moved} vertices moved"
        );
    }

    #[test]
    fn other_items_pass_in_order_and_end_the_run() {
        let text = "G21 G90 G64 P0.01 F600\nG1 X0.05 Y0.001\nG1 X0.1 Y0.0\nG1 X0.15 Y0.001\n\
                    G1 X0.2 Y0\nG4 P0.5\nG1 X0.25 Y0.001\nG2 X0.45 Y0.001 R0.1\nG0 X1\n\
                    G1 X1.05\nG61\nG1 X1.1\nG1 X1.15 Y0.001\nG1 X1.2\nM2\n";
        let (programmed, smoothed) = run(text);
        assert_eq!(programmed.len(), smoothed.len());
        for (a, b) in programmed.iter().zip(&smoothed) {
            match (a, b) {
                (Item::Motion(a), Item::Motion(b)) => {
                    assert_eq!(a.line, b.line);
                    // Only the run of four lines has vertices that may move, the ends of
                    // its second and third; the rest keep their ends.
                    if ![3, 4, 5].contains(&a.line) {
                        assert_eq!(
                            (a.start_mm, a.end_mm),
                            (b.start_mm, b.end_mm),
                            "line {}",
                            a.line
                        );
                    }
                }
                (a, b) => assert_eq!(a, b),
            }
        }
        let end_of = |items: &[Item], line: usize| {
            lines(items)
                .iter()
                .find(|e| e.line == line)
                .map(|e| e.end_mm)
        };
        assert_ne!(
            end_of(&programmed, 3),
            end_of(&smoothed, 3),
            "the zigzag's middle vertex moves"
        );
    }
}
