//! Issue 11's contour acceptance: how far each streamed setpoint lies from the *programmed*
//! path (the interpreter's lines, arcs and helices, before the planner's blends and filters),
//! against the tolerance that applies there.
//!
//! Units in names: `_mm` millimetres; a ratio is a distance over its tolerance.
//!
//! # The tolerance
//!
//! An element's tolerance comes from the blend mode in force for it, as the acceptance list
//! states it: `G64 P<tol>` allows `tol`, a bare `G64` (P infinite, LinuxCNC's "no limit")
//! [`PlannerConfig::default_tolerance_mm`], and `G64 P0`, G61 and G61.1 `chord_tol_mm` (the
//! chord rule's deviation on curves; 0 when that is 0). The planner rounds the corner between
//! two elements by the tolerance of the first one, and its axis filters spread a corner over
//! both, so near a junction the larger of the two tolerances applies: each element is split
//! into two halves, the first with `max(previous, own)`, the second with `max(own, next)`
//! (a blend takes at most half of either element). Dwells and program stops in between do not
//! separate the neighbours. A sample's ratio is the smallest `distance / (tolerance + 1 nm)`
//! over those pieces (the nanometre is the rounding of a sample, as in `setpoints.rs`), so it
//! is within the tolerance exactly when its ratio is at most 1.
//!
//! # The distance
//!
//! Exact for lines. On an arc, helix or spiral arc (radius going linearly from the start
//! radius to the end radius, [`ArcGeometry::point_at`]) in any plane, the squared distance
//! `f(s) = |P(s) − q|²` is minimised over the piece's share of `s ∈ [0, 1]`: the piece is cut
//! into parts of at most 45° of sweep, a part whose lower bound (its midpoint's distance less
//! a bound of its half-length) cannot beat the best so far is skipped, and in a part where
//! `f'` goes from negative to positive the root is found by Newton's method kept inside the
//! bracket (bisection where a step would leave it) to machine precision; the ends of the parts
//! are candidates too. Every candidate is a point of the path, so a result is never smaller
//! than the true distance.
//!
//! # Tracking
//!
//! A setpoint is near the piece the plan is on, give or take the blends and the filters'
//! lag: [`Checker`] keeps a cursor on the nearest piece and searches a window around it (two
//! pieces and at least twice the last step plus 4 tolerances of path length either way). A
//! windowed ratio is an upper bound of the truth. Whenever it is above the worst ratio so far
//! (in particular above 1 before any violation is reported), and at rest when the windowed
//! distance is above [`AT_REST_MM`], the whole path is searched, pruned by the bounding
//! spheres of blocks of pieces; so the reported worst ratio and the distances at rest are
//! the true ones, and a sample is never reported off the path because the window was too
//! narrow.

#![allow(dead_code)] // each test binary uses its own part

use std::f64::consts::FRAC_PI_4;

use canmotion::gcode::{ArcGeometry, BlendMode, Element, ElementKind, Item};
use canmotion::interpolator::{InterpError, Interpolator};
use canmotion::planner::{Plan, PlannerConfig};
use nalgebra::Vector3;

/// Rounding allowed on top of a tolerance (a sample's coordinates are rounded to `f64`).
pub const ROUND_MM: f64 = 1e-9;

/// The largest distance from the path allowed where the setpoint stands still (exact stops,
/// dwells, program stops) and at the program's end: 1 µm.
pub const AT_REST_MM: f64 = 1e-3;

/// Pieces per block of the whole-path search.
const BLOCK: usize = 32;

/// Pieces at most in the cursor's window on either side.
const MAX_WINDOW: usize = 512;

/// The tolerances of issue 11's acceptance, from a planner configuration.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tolerances {
    /// G61, G61.1, G64 P0: the deviation the chord rule allows on curves.
    pub chord_tol_mm: f64,
    /// A bare G64.
    pub default_tolerance_mm: f64,
}

impl Tolerances {
    /// The tolerances `config` plans with.
    pub fn of(config: &PlannerConfig) -> Tolerances {
        Tolerances {
            chord_tol_mm: config.chord_tol_mm,
            default_tolerance_mm: config.default_tolerance_mm,
        }
    }

    /// The tolerance of an element planned under `blend` (see the module documentation).
    pub fn of_blend(&self, blend: BlendMode) -> f64 {
        match blend {
            BlendMode::Blend { p_mm, .. } if p_mm == f64::INFINITY => self.default_tolerance_mm,
            BlendMode::Blend { p_mm, .. } if p_mm > 0.0 && p_mm.is_finite() => p_mm,
            _ => self.chord_tol_mm,
        }
    }
}

/// The geometry of a piece of an element.
#[derive(Debug, Clone, Copy)]
pub enum Shape {
    /// The segment from `a` to `b`.
    Line { a: Vector3<f64>, b: Vector3<f64> },
    /// The arc's points for `s` in `[s0, s1]`.
    Arc { arc: ArcGeometry, s0: f64, s1: f64 },
}

impl Shape {
    /// A sphere holding every point of the shape: its centre and radius.
    fn bounding_sphere(&self) -> (Vector3<f64>, f64) {
        match *self {
            Shape::Line { a, b } => ((a + b) * 0.5, (b - a).norm() * 0.5),
            Shape::Arc { arc, s0, s1 } => {
                let mid = 0.5 * (s0 + s1);
                (arc.point_at(mid), half_reach_mm(&arc, s1 - s0))
            }
        }
    }

    /// Length of the piece (an upper bound on a spiral arc).
    fn length_mm(&self) -> f64 {
        match *self {
            Shape::Line { a, b } => (b - a).norm(),
            Shape::Arc { arc, s0, s1 } => 2.0 * half_reach_mm(&arc, s1 - s0),
        }
    }

    /// The distance from `q` to the shape.
    pub fn distance_mm(&self, q: Vector3<f64>) -> f64 {
        match *self {
            Shape::Line { a, b } => segment_distance_mm(a, b, q),
            Shape::Arc { arc, s0, s1 } => arc_distance_mm(&arc, s0, s1, q).0,
        }
    }
}

/// The largest distance from `P(s)` to any point of the arc within `ds/2` of `s` in the
/// parameter: half of `ds` times a bound of `|P'|`.
fn half_reach_mm(arc: &ArcGeometry, ds: f64) -> f64 {
    let r_max = arc.start_radius_mm.max(arc.end_radius_mm);
    let speed = (r_max * arc.sweep_rad).hypot(arc.helix_mm)
        + (arc.end_radius_mm - arc.start_radius_mm).abs();
    0.5 * ds.abs() * speed
}

/// Distance from `q` to the segment from `a` to `b` (exact).
pub fn segment_distance_mm(a: Vector3<f64>, b: Vector3<f64>, q: Vector3<f64>) -> f64 {
    let d = b - a;
    let l2 = d.norm_squared();
    let t = if l2 > 0.0 {
        ((q - a).dot(&d) / l2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (a + d * t - q).norm()
}

/// `P(s)`, `P'(s)` and `P''(s)` of the arc (derivatives in `s`).
fn arc_derivatives(arc: &ArcGeometry, s: f64) -> [Vector3<f64>; 3] {
    let theta = s * arc.sweep_rad;
    let dr = arc.end_radius_mm - arc.start_radius_mm;
    let r = arc.start_radius_mm + s * dr;
    let (sin, cos) = theta.sin_cos();
    let radial = arc.u * cos + arc.v * sin;
    let along = arc.v * cos - arc.u * sin;
    let p = arc.point_at(s);
    let d1 = along * (r * arc.sweep_rad) + radial * dr + arc.normal * arc.helix_mm;
    let d2 = radial * (-r * arc.sweep_rad * arc.sweep_rad) + along * (2.0 * dr * arc.sweep_rad);
    [p, d1, d2]
}

/// Distance from `q` to the arc's points for `s` in `[s0, s1]`, and the `s` where it is
/// reached (see the module documentation).
pub fn arc_distance_mm(arc: &ArcGeometry, s0: f64, s1: f64, q: Vector3<f64>) -> (f64, f64) {
    let parts = ((s1 - s0) * arc.sweep_rad / FRAC_PI_4).ceil().max(1.0);
    let n = if parts.is_finite() && parts < 1e6 {
        parts as usize
    } else {
        1_000_000
    };
    let ds = (s1 - s0) / n as f64;
    let reach = half_reach_mm(arc, ds);
    let at = |k: usize| if k == n { s1 } else { s0 + ds * k as f64 };
    let mut best = ((arc.point_at(s0) - q).norm(), s0);
    let end = ((arc.point_at(s1) - q).norm(), s1);
    if end.0 < best.0 {
        best = end;
    }
    // The parts nearest first, so the bound prunes the others.
    let mut order: Vec<(f64, usize)> = (0..n)
        .map(|k| {
            let mid = 0.5 * (at(k) + at(k + 1));
            (((arc.point_at(mid) - q).norm() - reach).max(0.0), k)
        })
        .collect();
    order.sort_by(|x, y| x.0.total_cmp(&y.0));
    for (bound, k) in order {
        if bound >= best.0 {
            break;
        }
        let (a, b) = (at(k), at(k + 1));
        for s in [a, b] {
            let d = (arc.point_at(s) - q).norm();
            if d < best.0 {
                best = (d, s);
            }
        }
        if let Some(s) = local_minimum(arc, a, b, q) {
            let d = (arc.point_at(s) - q).norm();
            if d < best.0 {
                best = (d, s);
            }
        }
    }
    best
}

/// Where `f(s) = |P(s) − q|²` has its minimum inside `[a, b]`, if `f'` goes from negative at
/// `a` to positive at `b`: Newton's method on `f'` kept inside the bracket.
fn local_minimum(arc: &ArcGeometry, a: f64, b: f64, q: Vector3<f64>) -> Option<f64> {
    let slope = |s: f64| {
        let [p, d1, d2] = arc_derivatives(arc, s);
        let w = p - q;
        (2.0 * w.dot(&d1), 2.0 * (d1.norm_squared() + w.dot(&d2)))
    };
    let (fa, _) = slope(a);
    let (fb, _) = slope(b);
    if !(fa < 0.0 && fb > 0.0) {
        return None;
    }
    // Steps shorter than this move the point by less than 1e-13 mm.
    let resolution = 1e-13 / (2.0 * half_reach_mm(arc, 1.0)).max(1e-300);
    let (mut lo, mut hi) = (a, b);
    let mut s = 0.5 * (a + b);
    for _ in 0..100 {
        let (f1, f2) = slope(s);
        if f1 == 0.0 {
            return Some(s);
        }
        if f1 < 0.0 {
            lo = s;
        } else {
            hi = s;
        }
        let newton = s - f1 / f2;
        let next = if f2 > 0.0 && newton > lo && newton < hi {
            newton
        } else {
            0.5 * (lo + hi)
        };
        if (next - s).abs() <= resolution || hi - lo <= resolution {
            return Some(next);
        }
        s = next;
    }
    Some(s)
}

/// One piece of the path: half an element, or a whole one whose two halves have the same
/// tolerance.
#[derive(Debug, Clone, Copy)]
pub struct Piece {
    pub shape: Shape,
    /// Index of its element among the path's elements.
    pub element: usize,
    /// The element's source line.
    pub line: usize,
    /// The tolerance here.
    pub tolerance_mm: f64,
    centre_mm: Vector3<f64>,
    radius_mm: f64,
    length_mm: f64,
}

impl Piece {
    fn new(shape: Shape, element: usize, line: usize, tolerance_mm: f64) -> Piece {
        let (centre_mm, radius_mm) = shape.bounding_sphere();
        Piece {
            shape,
            element,
            line,
            tolerance_mm,
            centre_mm,
            radius_mm,
            length_mm: shape.length_mm(),
        }
    }
}

/// A run of [`BLOCK`] pieces with a sphere around all of them.
#[derive(Debug, Clone, Copy)]
struct Block {
    first: usize,
    end: usize,
    centre_mm: Vector3<f64>,
    radius_mm: f64,
    max_tolerance_mm: f64,
}

/// The programmed path, cut into pieces with their tolerance.
#[derive(Debug, Clone)]
pub struct Path {
    pub pieces: Vec<Piece>,
    blocks: Vec<Block>,
    /// Where the program starts and ends.
    pub start_mm: Vector3<f64>,
    pub end_mm: Vector3<f64>,
}

/// The nearest piece to a point, by ratio.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Nearest {
    pub piece: usize,
    pub distance_mm: f64,
    pub tolerance_mm: f64,
    pub ratio: f64,
}

impl Nearest {
    const NONE: Nearest = Nearest {
        piece: 0,
        distance_mm: f64::INFINITY,
        tolerance_mm: 0.0,
        ratio: f64::INFINITY,
    };
}

impl Path {
    /// The path of `items` (elements; dwells, stops, notes and the end add no geometry)
    /// from `start_mm`, with the tolerances `tol`.
    pub fn new<'a>(
        start_mm: Vector3<f64>,
        items: impl IntoIterator<Item = &'a Item>,
        tol: &Tolerances,
    ) -> Path {
        let elements: Vec<&Element> = items
            .into_iter()
            .filter_map(|i| match i {
                Item::Motion(e) => Some(e),
                _ => None,
            })
            .collect();
        let own: Vec<f64> = elements.iter().map(|e| tol.of_blend(e.blend)).collect();
        let mut pieces = Vec::with_capacity(elements.len());
        for (k, e) in elements.iter().enumerate() {
            let before = if k > 0 {
                own[k - 1].max(own[k])
            } else {
                own[k]
            };
            let after = own.get(k + 1).map_or(own[k], |n| n.max(own[k]));
            let arc = match e.kind {
                ElementKind::Arc { .. } => e.arc(),
                ElementKind::Line => None,
            };
            let halves = |s0: f64, s1: f64| match arc {
                Some(arc) => Shape::Arc { arc, s0, s1 },
                None => {
                    let d = e.end_mm - e.start_mm;
                    Shape::Line {
                        a: if s0 == 0.0 {
                            e.start_mm
                        } else {
                            e.start_mm + d * s0
                        },
                        b: if s1 == 1.0 {
                            e.end_mm
                        } else {
                            e.start_mm + d * s1
                        },
                    }
                }
            };
            if before == after {
                pieces.push(Piece::new(halves(0.0, 1.0), k, e.line, before));
            } else {
                pieces.push(Piece::new(halves(0.0, 0.5), k, e.line, before));
                pieces.push(Piece::new(halves(0.5, 1.0), k, e.line, after));
            }
        }
        let end_mm = elements.last().map_or(start_mm, |e| e.end_mm);
        if pieces.is_empty() {
            let shape = Shape::Line {
                a: start_mm,
                b: start_mm,
            };
            pieces.push(Piece::new(shape, 0, 0, tol.chord_tol_mm));
        }
        let blocks = pieces
            .chunks(BLOCK)
            .enumerate()
            .map(|(b, chunk)| {
                let mut lo = Vector3::repeat(f64::INFINITY);
                let mut hi = Vector3::repeat(f64::NEG_INFINITY);
                for p in chunk {
                    lo = lo.inf(&p.centre_mm.add_scalar(-p.radius_mm));
                    hi = hi.sup(&p.centre_mm.add_scalar(p.radius_mm));
                }
                Block {
                    first: b * BLOCK,
                    end: b * BLOCK + chunk.len(),
                    centre_mm: (lo + hi) * 0.5,
                    radius_mm: (hi - lo).norm() * 0.5,
                    max_tolerance_mm: chunk.iter().map(|p| p.tolerance_mm).fold(0.0, f64::max),
                }
            })
            .collect();
        Path {
            pieces,
            blocks,
            start_mm,
            end_mm,
        }
    }

    /// What a distance to piece `k` is divided by: its tolerance (and the rounding), or 1.
    fn scale_mm(&self, k: usize, metric: Metric) -> f64 {
        match metric {
            Metric::Ratio => self.pieces[k].tolerance_mm + ROUND_MM,
            Metric::Distance => 1.0,
        }
    }

    /// The ratio (or distance) of `q` to piece `k`.
    fn to_piece(&self, q: Vector3<f64>, k: usize, metric: Metric) -> Nearest {
        let p = &self.pieces[k];
        let d = p.shape.distance_mm(q);
        Nearest {
            piece: k,
            distance_mm: d,
            tolerance_mm: p.tolerance_mm,
            ratio: d / self.scale_mm(k, metric),
        }
    }

    /// The nearest of pieces `lo..=hi`; on a tie the later one (the path goes forward).
    fn nearest_in(&self, q: Vector3<f64>, lo: usize, hi: usize, metric: Metric) -> Nearest {
        let mut best = Nearest::NONE;
        for k in lo..=hi {
            let p = &self.pieces[k];
            let gap = ((q - p.centre_mm).norm() - p.radius_mm).max(0.0);
            if gap / self.scale_mm(k, metric) > best.ratio {
                continue;
            }
            let n = self.to_piece(q, k, metric);
            if n.ratio <= best.ratio {
                best = n;
            }
        }
        best
    }

    /// The nearest piece in the window of `cursor` (see the module documentation) for a
    /// sample `step_mm` from the previous one.
    pub fn nearest_near(
        &self,
        q: Vector3<f64>,
        cursor: usize,
        step_mm: f64,
        metric: Metric,
    ) -> Nearest {
        let reach = 2.0 * step_mm + 4.0 * self.pieces[cursor].tolerance_mm + 1e-3;
        let (mut lo, mut back) = (cursor, 0.0);
        while lo > 0 && (cursor - lo < 2 || back < reach) && cursor - lo < MAX_WINDOW {
            lo -= 1;
            back += self.pieces[lo].length_mm;
        }
        let (mut hi, mut ahead) = (cursor, 0.0);
        while hi + 1 < self.pieces.len()
            && (hi - cursor < 2 || ahead < reach)
            && hi - cursor < MAX_WINDOW
        {
            hi += 1;
            ahead += self.pieces[hi].length_mm;
        }
        self.nearest_in(q, lo, hi, metric)
    }

    /// The nearest piece of the whole path, no worse than `known` (a result already found
    /// with the same metric).
    pub fn nearest(&self, q: Vector3<f64>, known: Nearest, metric: Metric) -> Nearest {
        let mut best = known;
        for b in &self.blocks {
            let gap = ((q - b.centre_mm).norm() - b.radius_mm).max(0.0);
            let scale = match metric {
                Metric::Ratio => b.max_tolerance_mm + ROUND_MM,
                Metric::Distance => 1.0,
            };
            if gap / scale >= best.ratio {
                continue;
            }
            for k in b.first..b.end {
                let p = &self.pieces[k];
                let gap = ((q - p.centre_mm).norm() - p.radius_mm).max(0.0);
                if gap / self.scale_mm(k, metric) >= best.ratio {
                    continue;
                }
                let n = self.to_piece(q, k, metric);
                if n.ratio < best.ratio {
                    best = n;
                }
            }
        }
        best
    }

    /// The smallest distance from `q` to the path (every piece measured: for tests).
    pub fn brute_force_distance_mm(&self, q: Vector3<f64>) -> f64 {
        self.pieces
            .iter()
            .map(|p| p.shape.distance_mm(q))
            .fold(f64::INFINITY, f64::min)
    }
}

/// What a search minimises.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Metric {
    /// Distance over tolerance.
    Ratio,
    /// Distance.
    Distance,
}

/// A sample and how far it is from the path.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Measured {
    /// 1-based sample number (the first `Interpolator::update`'s is 1).
    pub sample: u64,
    /// Source line of the nearest element.
    pub line: usize,
    pub position_mm: Vector3<f64>,
    pub distance_mm: f64,
    pub tolerance_mm: f64,
    /// `distance / (tolerance + ROUND_MM)`.
    pub ratio: f64,
}

/// What [`Checker`] found.
#[derive(Debug, Clone, PartialEq)]
pub struct Report {
    /// Samples measured.
    pub samples: u64,
    /// The sample with the largest ratio (`None` without samples).
    pub worst: Option<Measured>,
    /// Where the setpoint stood still for at least two samples after it had moved, the first
    /// sample of each such run (the run that lasts to the end is [`Report::end`]'s).
    pub stops: Vec<Measured>,
    /// The last sample.
    pub end: Option<Measured>,
    /// The program's end point, which the last sample must be bit for bit.
    pub expected_end_mm: Vector3<f64>,
    /// Samples whose windowed search was followed by a search of the whole path.
    pub whole_path_searches: u64,
}

/// Why a run of setpoints fails the acceptance.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Deviation {
    #[error(
        "sample {sample} at {position_mm:?} is {distance_mm} mm from the path near line {line}, \
         over its tolerance {tolerance_mm} mm (ratio {ratio})"
    )]
    OffPath {
        sample: u64,
        line: usize,
        position_mm: Vector3<f64>,
        distance_mm: f64,
        tolerance_mm: f64,
        ratio: f64,
    },
    #[error(
        "at rest from sample {sample} at {position_mm:?}, {distance_mm} mm from the path near \
         line {line} (at most {AT_REST_MM} mm)"
    )]
    OffPathAtRest {
        sample: u64,
        line: usize,
        position_mm: Vector3<f64>,
        distance_mm: f64,
    },
    #[error("the last sample is {end_mm:?}, not the program's end {expected_mm:?}")]
    EndNotExact {
        end_mm: Vector3<f64>,
        expected_mm: Vector3<f64>,
    },
    #[error("no sample")]
    NoSample,
}

impl Report {
    /// The acceptance: every sample within its tolerance, the stops and the end within
    /// [`AT_REST_MM`] of the path, the last sample exactly the program's end.
    pub fn check(&self) -> Result<(), Deviation> {
        let (Some(worst), Some(end)) = (self.worst, self.end) else {
            return Err(Deviation::NoSample);
        };
        if worst.ratio > 1.0 {
            return Err(Deviation::OffPath {
                sample: worst.sample,
                line: worst.line,
                position_mm: worst.position_mm,
                distance_mm: worst.distance_mm,
                tolerance_mm: worst.tolerance_mm,
                ratio: worst.ratio,
            });
        }
        for m in self.stops.iter().chain(std::iter::once(&end)) {
            if m.distance_mm > AT_REST_MM {
                return Err(Deviation::OffPathAtRest {
                    sample: m.sample,
                    line: m.line,
                    position_mm: m.position_mm,
                    distance_mm: m.distance_mm,
                });
            }
        }
        if end.position_mm != self.expected_end_mm {
            return Err(Deviation::EndNotExact {
                end_mm: end.position_mm,
                expected_mm: self.expected_end_mm,
            });
        }
        Ok(())
    }

    /// The largest distance at rest (stops and the end).
    pub fn max_at_rest_mm(&self) -> f64 {
        self.stops
            .iter()
            .chain(self.end.iter())
            .map(|m| m.distance_mm)
            .fold(0.0, f64::max)
    }
}

/// Measures setpoints one at a time against a [`Path`].
pub struct Checker<'a> {
    path: &'a Path,
    cursor: usize,
    previous: Option<Vector3<f64>>,
    moved: bool,
    /// The run of equal samples in progress is recorded as the last stop.
    at_rest: bool,
    last: Option<Measured>,
    report: Report,
}

impl<'a> Checker<'a> {
    pub fn new(path: &'a Path) -> Checker<'a> {
        Checker {
            path,
            cursor: 0,
            previous: None,
            moved: false,
            at_rest: false,
            last: None,
            report: Report {
                samples: 0,
                worst: None,
                stops: Vec::new(),
                end: None,
                expected_end_mm: path.end_mm,
                whole_path_searches: 0,
            },
        }
    }

    /// Measures the next sample.
    pub fn push(&mut self, q: Vector3<f64>) {
        self.report.samples += 1;
        let still = self.previous == Some(q);
        let step = self.previous.map_or(0.0, |p| (q - p).norm());
        let mut n = self.path.nearest_near(q, self.cursor, step, Metric::Ratio);
        let worst = self.report.worst.map_or(0.0, |w| w.ratio);
        if n.ratio > worst || n.ratio.is_nan() {
            self.report.whole_path_searches += 1;
            n = self.path.nearest(q, n, Metric::Ratio);
        }
        if n.ratio.is_finite() {
            self.cursor = n.piece;
        }
        let m = self.measured(q, n);
        if self.report.worst.is_none() || m.ratio > worst {
            self.report.worst = Some(m);
        }
        if still {
            // One measure per run of equal samples, by distance alone.
            if !self.at_rest && self.moved {
                let mut first = self.at_rest_measure(q, step);
                first.sample -= 1;
                self.report.stops.push(first);
                self.at_rest = true;
            }
        } else {
            self.at_rest = false;
            self.moved |= self.previous.is_some();
        }
        self.previous = Some(q);
        self.last = Some(m);
    }

    fn measured(&self, q: Vector3<f64>, n: Nearest) -> Measured {
        Measured {
            sample: self.report.samples,
            line: self.path.pieces[n.piece].line,
            position_mm: q,
            distance_mm: n.distance_mm,
            tolerance_mm: n.tolerance_mm,
            ratio: n.distance_mm / (n.tolerance_mm + ROUND_MM),
        }
    }

    /// The current sample `q` measured by its distance to the path alone (the whole path
    /// searched when the window finds it over [`AT_REST_MM`] away).
    fn at_rest_measure(&mut self, q: Vector3<f64>, step_mm: f64) -> Measured {
        let mut n = self
            .path
            .nearest_near(q, self.cursor, step_mm, Metric::Distance);
        if n.distance_mm > AT_REST_MM || n.distance_mm.is_nan() {
            self.report.whole_path_searches += 1;
            n = self.path.nearest(q, n, Metric::Distance);
        }
        self.measured(q, n)
    }

    /// The report; the last sample is the end.
    pub fn finish(mut self) -> Report {
        if let Some(last) = self.last {
            if self.at_rest {
                self.report.stops.pop();
            }
            let mut end = self.at_rest_measure(last.position_mm, 0.0);
            end.sample = last.sample;
            self.report.end = Some(end);
        }
        self.report
    }
}

/// Samples `plan` as `setpoints::limits_hold` does (`Interpolator::update` every period until
/// it is finished) and measures every sample against `path`.
pub fn measure(path: &Path, plan: Plan, period_s: f64) -> Result<Report, InterpError> {
    let mut interp = Interpolator::new(plan, period_s)?;
    let mut checker = Checker::new(path);
    let mut q = Vector3::zeros();
    while !interp.is_finished() {
        interp.update(&mut q);
        checker.push(q);
    }
    Ok(checker.finish())
}

/// [`measure`] of the plan of `items` from `start_mm`, with `config`'s tolerances.
pub fn measure_items(
    start_mm: Vector3<f64>,
    items: &[Item],
    plan: Plan,
    config: &PlannerConfig,
) -> Result<Report, InterpError> {
    let path = Path::new(start_mm, items, &Tolerances::of(config));
    measure(&path, plan, config.period_s)
}
