//! Collinear lines merged (jerk-limited mode): a run of G64 lines that continue one another
//! along one straight line becomes one line. It sits after the chord smoother and refiner
//! ([`super::smooth`], [`super::refine`]): a chorded curve's written vertices that happen to
//! line up (4-decimal rounding along a flat part of `contour.ngc`) stay for the smoother,
//! whose parabolas count chords; its pieces never merge.
//!
//! CAM and hand-written programs split straight moves into many short lines (LinuxCNC's
//! `performance/straight_short_lines_X.ngc`: 1000 lines of 25 µm along X). Their junctions
//! turn by nothing, yet each is a junction: the look-ahead plans the run through the
//! time-law filter, whose trapezoids keep their acceleration within `J·T_f/2` so that the
//! filter's output stays within the jerk limit wherever the acceleration reverses within one
//! filter time, and the run from rest to rest takes 1.6 times its trapezoid time. The same
//! motion as one line is a move alone, planned as an exact time-optimal S-curve
//! (`Planner::push_item`).
//!
//! # Which lines
//!
//! Two lines merge where the path stays exactly what was programmed and nothing but the
//! junction is lost: both straight X/Y/Z moves with the auxiliary axes still, both rapids or
//! both feed moves at the same feed, under the same G64 blend mode (not G61 or G61.1, where a
//! program asks for the junction), the same cutter compensation and plane, the second
//! starting exactly where the first ends, in the same direction, and the vertex between them
//! within [`COLLINEAR_MM`] of the line that replaces them. A run merges once it is as long as
//! [`CollinearMerger::new`]'s `min_mm`; shorter runs pass on as written. The merged line
//! carries the first line's source line and column: a run reports its first line while it
//! moves.
//!
//! The merger holds the run until the next item shows whether it continues it; any other item
//! (an arc, a dwell, a note, a stop, the end) first passes the run on.

use std::collections::VecDeque;

use nalgebra::Vector3;

use crate::gcode::{BlendMode, Element, ElementKind, Item};

/// Largest distance of a merged vertex from the line that replaces it: a nanometre, far below
/// any machine's resolution and the rounding of written coordinates; lines that turn by more
/// stay apart.
pub const COLLINEAR_MM: f64 = 1e-6;

/// The run of collinear lines held back, and the items ready for the planner.
#[derive(Debug, Clone, Default)]
pub(super) struct CollinearMerger {
    /// The lines of the current run, oldest first; one line once merged.
    run: Vec<Element>,
    /// Whether the run is merged: as long as [`CollinearMerger::min_mm`] at least.
    merged: bool,
    /// Length of the run.
    run_mm: f64,
    /// Shortest run merged: see [`CollinearMerger::new`].
    min_mm: f64,
    /// What the planner receives next, in order.
    pub out: VecDeque<Item>,
}

impl CollinearMerger {
    /// A merger of runs at least `min_mm` long. Shorter runs stay as written: where a dense
    /// chorded curve's written vertices happen to line up (a 50 mm circle of 50 µm chords with
    /// 4 decimals lines up two or three near its flat parts), one longer chord among the
    /// short ones is a vertex the axis filters see apart from the curve (1.10 → 1.64× `T_lb`
    /// on that circle when every such pair merged). The planner takes the axis filters' span
    /// at the max feed, `2·T_k·F`, beyond which a straight stretch is never part of a curve
    /// they see.
    pub fn new(min_mm: f64) -> CollinearMerger {
        CollinearMerger {
            min_mm,
            ..CollinearMerger::default()
        }
    }

    /// Takes the next item; items ready for the planner go to `out`.
    pub fn push(&mut self, item: Item) {
        if let Item::Motion(e) = &item
            && mergeable(e)
        {
            let (Some(first), Some(last)) = (self.run.first(), self.run.last()) else {
                self.start(*e);
                return;
            };
            if !continues(first.start_mm, last, e) {
                self.flush();
                self.start(*e);
                return;
            }
            self.run_mm += (e.end_mm - e.start_mm).norm();
            if self.merged {
                self.run[0].end_mm = e.end_mm;
            } else {
                self.run.push(*e);
                if self.run_mm >= self.min_mm {
                    let end_mm = e.end_mm;
                    self.run.truncate(1);
                    self.run[0].end_mm = end_mm;
                    self.merged = true;
                }
            }
            return;
        }
        self.flush();
        self.out.push_back(item);
    }

    /// Starts a run with `e`.
    fn start(&mut self, e: Element) {
        self.run_mm = (e.end_mm - e.start_mm).norm();
        self.merged = false;
        self.run.push(e);
    }

    /// Passes the run on: merged, or as written.
    pub fn flush(&mut self) {
        self.out.extend(self.run.drain(..).map(Item::Motion));
        self.merged = false;
        self.run_mm = 0.0;
    }
}

/// A straight X/Y/Z move under G64 with the auxiliary axes still.
fn mergeable(e: &Element) -> bool {
    e.kind == ElementKind::Line
        && matches!(e.blend, BlendMode::Blend { .. })
        && e.aux.start == e.aux.end
        && e.start_mm != e.end_mm
        && e.start_mm
            .iter()
            .chain(e.end_mm.iter())
            .all(|c| c.is_finite())
}

/// Whether `next` continues the run from `start_mm` whose last line is `last`, along the same
/// straight line (see the module documentation).
fn continues(start_mm: Vector3<f64>, last: &Element, next: &Element) -> bool {
    if next.start_mm != last.end_mm
        || next.rapid != last.rapid
        || next.feed_mm_s != last.feed_mm_s
        || next.blend != last.blend
        || next.comp != last.comp
        || next.plane != last.plane
        || next.aux.start != last.aux.end
    {
        return false;
    }
    let (a, b) = (last.end_mm - last.start_mm, next.end_mm - next.start_mm);
    if a.dot(&b) <= 0.0 {
        return false;
    }
    // The vertex's distance from the merged line.
    let chord = next.end_mm - start_mm;
    let off = last.end_mm - start_mm;
    let l2 = chord.norm_squared();
    l2 > 0.0 && (off - chord * (off.dot(&chord) / l2)).norm() <= COLLINEAR_MM
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gcode::{Interpreter, Setup};

    fn merged(text: &str) -> Vec<Item> {
        merged_from(text, 1.0)
    }

    fn merged_from(text: &str, min_mm: f64) -> Vec<Item> {
        let mut m = CollinearMerger::new(min_mm);
        for item in Interpreter::new(text.as_bytes(), "t.ngc", Setup::new(Vector3::zeros())) {
            m.push(item.expect("interprets"));
        }
        m.flush();
        m.out.into_iter().collect()
    }

    fn lines(items: &[Item]) -> Vec<(usize, Vector3<f64>, Vector3<f64>)> {
        items
            .iter()
            .filter_map(|i| match i {
                Item::Motion(e) => Some((e.line, e.start_mm, e.end_mm)),
                _ => None,
            })
            .collect()
    }

    #[test]
    fn a_straight_run_of_short_lines_becomes_one_line() {
        let items = merged("G21 G64 P0.01\nG1 X0.5 F600\nX1\nX1.5\nX2\nM2\n");
        assert_eq!(
            lines(&items),
            vec![(2, Vector3::zeros(), Vector3::new(2.0, 0.0, 0.0))]
        );
        assert!(matches!(items.last(), Some(Item::End(_))));
    }

    #[test]
    fn a_run_shorter_than_the_shortest_merged_stays_as_written() {
        let text = "G21 G64 P0.01\nG1 X0.5 F600\nX1\nX1.5\nX2\nY1\nX3 Y2\nX4 Y3\nM2\n";
        // 2 mm along X, then 1 mm along Y, then 2.83 mm along the diagonal.
        let lines = lines(&merged_from(text, 3.0));
        assert_eq!(lines.len(), 7, "{lines:?}");
        let lines = self::lines(&merged_from(text, 2.0));
        assert_eq!(lines.len(), 3, "{lines:?}");
        assert_eq!(lines[0].2, Vector3::new(2.0, 0.0, 0.0));
        assert_eq!(lines[2].1, Vector3::new(2.0, 1.0, 0.0));
    }

    #[test]
    fn a_turn_a_reversal_a_feed_change_or_exact_path_keep_their_junction() {
        let cases = [
            "G21 G64 P0.01\nG1 X1 F600\nX2 Y0.001\nM2\n",
            "G21 G64 P0.01\nG1 X1 F600\nX0.5\nM2\n",
            "G21 G64 P0.01\nG1 X1 F600\nX2 F300\nM2\n",
            "G21 G61\nG1 X1 F600\nX2\nM2\n",
            "G21 G64 P0.01\nG1 X1 F600\nG0 X2\nM2\n",
            "G21 G64 P0.01\nG1 X1 F600\nG4 P0.1\nX2\nM2\n",
        ];
        for text in cases {
            assert_eq!(lines(&merged(text)).len(), 2, "{text}");
        }
    }

    #[test]
    fn a_diagonal_merges_only_where_its_vertex_is_on_the_merged_line() {
        // (1, 1, 1) lies on the line from the origin to (3, 3, 3); (1, 1.0001, 1) does not.
        assert_eq!(
            lines(&merged("G21 G64 P0.01\nG1 X1 Y1 Z1 F600\nX3 Y3 Z3\nM2\n")).len(),
            1
        );
        assert_eq!(
            lines(&merged(
                "G21 G64 P0.01\nG1 X1 Y1.0001 Z1 F600\nX3 Y3 Z3\nM2\n"
            ))
            .len(),
            2
        );
    }
}
