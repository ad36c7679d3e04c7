//! G5 (cubic) and G5.1 (quadratic) splines, as LinuxCNC reads them (`convert_spline` in
//! `interp_convert.cc`), sampled into straight lines.
//!
//! Both are Bézier curves in the XY plane (G17 only, no Z), in program coordinates:
//! - `G5.1 X Y I J`: control points the current point `P0`, `P0 + (I, J)`, the end `(X, Y)`.
//!   I and J are both required.
//! - `G5 X Y I J P Q`: control points `P0`, `P0 + (I, J)`, `end + (P, Q)`, the end. P and Q
//!   are always required; I and J both or neither: without them the spline starts in the
//!   direction the previous G5 ended in (`(I, J)` is the previous `−(P, Q)`), which needs a G5
//!   right before it.
//!
//! I, J, P and Q are offsets (in the program's units) whatever G90.1/G91.1 says; X and Y follow
//! G90/G91. The curve is then mapped to the machine like every point (work offset, rotation,
//! G92, tool offset): an affine map, so the samples stay on the mapped curve.
//!
//! # Sampling
//!
//! The samples are at equal steps of the curve parameter `t`, `n` of them, on the exact curve.
//! A chord over `[t0, t0 + h]` departs from the curve by at most `h²/8 · max|B''|` (the error of
//! linear interpolation), and `B''` is constant (quadratic) or linear in `t` (cubic, so its
//! largest norm is at an end): `n = ⌈√(max|B''| / (8·tol))⌉` keeps every chord within `tol`
//! ([`Setup::spline_tol_mm`](super::Setup::spline_tol_mm), the planner's `chord_tol_mm`).

use std::collections::VecDeque;

use nalgebra::{Vector2, Vector3};

use super::{BlockError, State, err_at};
use crate::gcode::block::Block;
use crate::gcode::element::{CompState, Plane};
use crate::gcode::{ErrorKind, Item};

/// Most lines one spline is sampled into (a line's items are queued at once: this bounds the
/// interpreter's memory).
pub const MAX_SPLINE_SEGMENTS: usize = 100_000;

/// Smallest [`Setup::spline_tol_mm`](super::Setup::spline_tol_mm) accepted.
pub const MIN_SPLINE_TOL_MM: f64 = 1e-6;

/// How many equal steps of `t` keep every chord of a Bézier curve with control points
/// `points` within `tol_mm` of the curve.
pub(super) fn segments_for(points: &[Vector2<f64>], tol_mm: f64) -> f64 {
    let second = |p: &[Vector2<f64>]| p[0] - 2.0 * p[1] + p[2];
    let max_d2 = match points.len() {
        3 => 2.0 * second(points).norm(),
        _ => {
            6.0 * second(&points[0..3])
                .norm()
                .max(second(&points[1..4]).norm())
        }
    };
    (max_d2 / (8.0 * tol_mm)).sqrt().ceil().max(1.0)
}

/// The point at `t` of the Bézier curve with control points `points` (3 or 4).
pub(super) fn bezier_at(points: &[Vector2<f64>], t: f64) -> Vector2<f64> {
    let s = 1.0 - t;
    match points.len() {
        3 => points[0] * (s * s) + points[1] * (2.0 * s * t) + points[2] * (t * t),
        _ => {
            points[0] * (s * s * s)
                + points[1] * (3.0 * s * s * t)
                + points[2] * (3.0 * s * t * t)
                + points[3] * (t * t * t)
        }
    }
}

fn missing(col: usize, code: &'static str, letter: char, expected: &'static str) -> BlockError {
    err_at(
        col,
        ErrorKind::MissingWord {
            code: code.to_owned(),
            letter,
            expected,
        },
    )
}

impl State {
    /// A G5 (`cubic`) or G5.1 line: its lines go to `out` and the current point moves to its
    /// end. `feed_mm_s` is the feed of the line (`None` in G93: `inverse_f` then gives it).
    pub(super) fn spline(
        &mut self,
        b: &Block,
        line: usize,
        col: usize,
        cubic: bool,
        inverse_f: Option<f64>,
        out: &mut VecDeque<Item>,
    ) -> Result<(), BlockError> {
        let code = if cubic { "G5" } else { "G5.1" };
        // LinuxCNC's order of checks.
        if self.comp != CompState::Off {
            return Err(err_at(col, ErrorKind::SplineWithCompensation { code }));
        }
        if self.inverse_time {
            if inverse_f.is_none() {
                return Err(err_at(col, ErrorKind::MissingInverseTimeFeed { code }));
            }
        } else if self.feed_mm_s.is_none() {
            return Err(err_at(col, ErrorKind::MissingFeed { code }));
        }
        if self.plane != Plane::Xy {
            return Err(err_at(
                col,
                ErrorKind::SplinePlane {
                    code,
                    plane: self.plane.code(),
                },
            ));
        }
        if let Some(w) = b.word('Z') {
            return Err(err_at(w.col, ErrorKind::SplineAxis { code, letter: 'Z' }));
        }
        let start = self.prog_mm;
        let end = self.prog_target(b);
        let scale = self.scale();
        let xy = |v: Vector3<f64>| Vector2::new(v.x, v.y);
        let (p0, p3) = (xy(start), xy(end));
        let i = self.take(b, 'I');
        let j = self.take(b, 'J');
        let p1 = match (i, j) {
            (Some(i), Some(j)) => p0 + Vector2::new(i.value, j.value) * scale,
            (None, None) if cubic => match self.spline_next {
                Some(d) => p0 + d,
                None => {
                    return Err(missing(
                        col,
                        code,
                        'I',
                        "I and J: the first G5 of a series gives its start direction (later ones may leave both out to continue the previous G5)",
                    ));
                }
            },
            (Some(_), None) | (None, Some(_)) | (None, None) => {
                let letter = if i.is_some() { 'J' } else { 'I' };
                let expected = if cubic {
                    "both I and J, or neither (to continue the previous G5's direction)"
                } else {
                    "both I and J: the control point, relative to the start"
                };
                return Err(missing(col, code, letter, expected));
            }
        };
        let points: Vec<Vector2<f64>> = if cubic {
            let p = self.take(b, 'P');
            let q = self.take(b, 'Q');
            let (Some(p), Some(q)) = (p, q) else {
                let letter = if p.is_some() { 'Q' } else { 'P' };
                return Err(missing(
                    col,
                    code,
                    letter,
                    "both P and Q: the second control point, relative to the end",
                ));
            };
            let pq = Vector2::new(p.value, q.value) * scale;
            self.spline_next = Some(-pq);
            vec![p0, p1, p3 + pq, p3]
        } else {
            vec![p0, p1, p3]
        };
        let n = segments_for(&points, self.spline_tol_mm);
        if n.is_nan() || n > MAX_SPLINE_SEGMENTS as f64 {
            return Err(err_at(
                col,
                ErrorKind::SplineTooLong {
                    code,
                    segments: n,
                    tol_mm: self.spline_tol_mm,
                    max: MAX_SPLINE_SEGMENTS,
                },
            ));
        }
        // Within the bound: exact.
        let n = n as usize;
        let m_end = self.machine_of(end);
        self.check_position(col, &m_end)?;
        let mut samples = Vec::with_capacity(n);
        for k in 1..n {
            let p = bezier_at(&points, k as f64 / n as f64);
            let mut m = self.to_machine(Vector3::new(p.x, p.y, start.z));
            m.z = self.pos_mm.z;
            self.check_position(col, &m)?;
            samples.push(m);
        }
        samples.push(m_end);
        let feed_mm_s = match inverse_f {
            // G93: the whole spline in 1/F minutes.
            Some(f) if self.inverse_time => {
                let mut length = 0.0;
                let mut at = self.pos_mm;
                for m in &samples {
                    length += (m - at).norm();
                    at = *m;
                }
                Some(length * f / 60.0)
            }
            _ => self.feed_mm_s,
        };
        for m in samples {
            self.push_line(line, col, false, m, feed_mm_s, out);
        }
        self.prog_mm = end;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p(x: f64, y: f64) -> Vector2<f64> {
        Vector2::new(x, y)
    }

    #[test]
    fn the_segment_count_is_the_chord_error_bound() {
        // Quadratic: B'' = 2 (P0 - 2 P1 + P2) = (0, -40); n = ⌈√(40 / 0.008)⌉ = 71.
        let quad = [p(0.0, 0.0), p(10.0, 10.0), p(20.0, 0.0)];
        assert_eq!(segments_for(&quad, 0.001), 71.0);
        // A straight "curve" takes one line.
        let straight = [p(0.0, 0.0), p(1.0, 0.0), p(2.0, 0.0)];
        assert_eq!(segments_for(&straight, 0.001), 1.0);
        // The bound holds: the worst chord of the quadratic (its middle) is within 0.001 mm.
        let n = segments_for(&quad, 0.001);
        for k in 0..n as usize {
            let (t0, t1) = (k as f64 / n, (k + 1) as f64 / n);
            let (a, b) = (bezier_at(&quad, t0), bezier_at(&quad, t1));
            let mid = bezier_at(&quad, (t0 + t1) / 2.0);
            let chord = b - a;
            let off = (mid - a).perp(&chord).abs() / chord.norm();
            assert!(off <= 0.001 + 1e-12, "chord {k}: {off}");
        }
        // Cubic: the end points and the middle, (P0 + 3 P1 + 3 P2 + P3) / 8.
        let cubic = [p(0.0, 0.0), p(0.0, 8.0), p(8.0, 8.0), p(8.0, 0.0)];
        assert_eq!(bezier_at(&cubic, 0.0), cubic[0]);
        assert_eq!(bezier_at(&cubic, 1.0), cubic[3]);
        assert_eq!(bezier_at(&cubic, 0.5), p(4.0, 6.0));
    }
}
