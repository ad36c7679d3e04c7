//! Cutter radius compensation (G41/G42, C-type): the programmed path into the tool-centre path.
//!
//! Second stage of the pipeline (`gcode → compensation → planner → interpolator`). A [`Compensator`]
//! wraps the interpreter's item stream and yields the same kind of stream, with every element
//! under G41/G42 moved to the tool centre: one tool radius left (G41) or right (G42) of the
//! programmed path, looking along the direction of travel in the compensation plane (G17 XY,
//! G18 ZX; the interpreter refuses G19). Pure: no I/O, no clock, no panic; memory is bounded
//! by [`MAX_HELD_ITEMS`]. [`compensate_program`] does the same for a whole [`Program`].
//!
//! Units in names: `_mm` millimetres, `_rad` radians; geometry is 2-D in the plane's own axes
//! (first, second: X Y under G17, Z X under G18) with the normal axis carried along.
//!
//! # Method (C-type, after the textbook chapter in `shared/seeds` 004)
//!
//! A line offsets to the parallel line, an arc to the concentric arc (radius `R − r` when the
//! arc turns toward the tool, `R + r` when it turns away; helices keep their axial motion).
//! Each element is held until the next element *in the plane* arrives, and the two offsets are
//! joined at the programmed corner by the angle α between the two elements measured on the
//! workpiece side (for an arc, its tangent at the corner):
//!
//! | α                  | class     | tool-centre path                                           |
//! |--------------------|-----------|------------------------------------------------------------|
//! | 180°               | tangent   | straight through (offset points closer than [`TANGENT_GAP_MM`]) |
//! | 180° < α < 360°    | shortened | both offsets end at their intersection (line–line, line–circle or circle–circle, the root nearest the corner) |
//! | 90° ≤ α < 180°     | extended  | both offsets extended along their tangents until they meet |
//! | 0° ≤ α < 90°       | inserted  | both extended by one tool radius, a straight line across   |
//!
//! An arc is extended along its end tangent (a straight connector), never along its circle;
//! only inside corners trim an arc. With [`OutsideCorners::Arc`] every outside corner
//! (α < 180°) is instead a tool-radius arc about the programmed corner, as LinuxCNC does. Tie
//! breaks: α = 90° is extended (the two constructions coincide there); an exact reversal
//! (α = 0° or 360°) goes round the tip (α = 0°), since the other reading has no intersection.
//!
//! # Start-up and cancel, as LinuxCNC computes them
//!
//! Read from LinuxCNC's `interp_convert.cc` and `interp_queue.cc` (`convert_straight_comp1`,
//! `convert_straight_comp2`, `convert_cutter_compensation_off`, `move_endpoint_and_flush`);
//! `tests/compensation.rs` checks each case against points computed by hand from them.
//!
//! - **Straight entry** (`convert_straight_comp1`): from the current point C to the programmed
//!   end P, the tool goes to P + r·n, n the unit normal of C→P on the tool's side (left for
//!   G41): the point offset perpendicular to the move's own direction, with no look-ahead.
//!   C→P not longer than r is refused ("Length of cutter compensation entry move is not
//!   greater than the tool radius": [`ErrorKind::CompensationEntryTooShort`]). C is the
//!   interpreter's point, the programmed one: after G40 and G41/G42 with no move between the
//!   tool still stands at the last offset point, and the move runs from there with the
//!   direction taken from the programmed point (so here: `e.start_mm` for the direction,
//!   the current output point for the start).
//! - **The corner after it** is an ordinary corner (`convert_straight_comp2` and
//!   `convert_arc_comp2` take the last move's direction from the programmed corner to the
//!   tool, which after an entry is square to C→P). Convex (β > 0.01 rad): the entry keeps
//!   its end P + r·n, then an `ARC_FEED` of radius r about the programmed corner (a straight
//!   traverse for G0) to the next element's offset start. Concave line to line: the entry's
//!   end moves back along C→P by r·tan(δ/2) (δ the turn), onto the intersection of the two
//!   offset lines. This is the join of this module with [`OutsideCorners::Arc`]; with
//!   [`OutsideCorners::Lines`] convex corners are extended or inserted instead (the
//!   source's C-type, not LinuxCNC's). LinuxCNC's reversal check on the moved end compares it
//!   with the entry's stored direction, which is the normal n, and always passes: an entry
//!   shorter than the corner's retreat runs back past its start, and is no gouge (here
//!   neither).
//! - **G40** (`convert_cutter_compensation_off`): the last move keeps its plain offset end
//!   (no corner join with what follows; queued moves along the tool axis stay there too), the
//!   interpreter's point becomes the programmed one, and the next move, whatever it is (one
//!   along the tool axis too), runs straight from the tool to its programmed end point. Here
//!   that move is the first element with G40 in force, in the plane or not; the interpreter
//!   keeps it even when its programmed length is 0 (G1 to the last programmed point, or a
//!   G0/G1 with no axis words, which LinuxCNC also runs as a move to its current point). The
//!   move right
//!   after G40 may not be an arc (`arc_not_allowed`, set whenever a radius was in force, also
//!   with no move between G41/G42 and G40; only a straight move clears it): the interpreter
//!   refuses it with [`ErrorKind::CompensationEndOnArc`].
//! - **What LinuxCNC refuses** and so do we: "Length of cutter compensation entry move is not
//!   greater than the tool radius", "The move just after exiting cutter compensation mode must
//!   be straight, not an arc", "Straight feed in concave corner cannot be reached by the tool
//!   without gouging" and "Arc to straight motion makes a corner the compensated tool can't
//!   fit in without gouging" (a move after the entry shorter than its corners take, an inside
//!   corner the tool cannot reach: [`ErrorKind::CompensationGouge`]), "Tool radius not less
//!   than arc radius with comp" ([`ErrorKind::CompensationArcTooSmall`]).
//! - **Where we differ and say so**: G41/G42 with the same side and radius right after G40 with
//!   no move between is unsupported (the elements carry only their comp state, so this stage
//!   would continue the last run where LinuxCNC starts a new one). LinuxCNC refuses a first
//!   move after G41/G42 with no motion in the plane (its entry length is 0); here it keeps
//!   the programmed point and the first move in the plane is the entry.
//!
//! An arc may be the start-up move, as LinuxCNC makes it (`convert_arc_comp1`): from the
//! current point to the programmed end moved one radius along the arc's radius there (inward
//! when the tool is inside the arc, outward when outside), about the centre on that radius
//! that is equally far from both; the corner after it joins as after any arc. What LinuxCNC
//! refuses is an error: an end point not farther than the radius from the start
//! ([`ErrorKind::CompensationEntryArcTooShort`]), the tool inside an arc not larger than it,
//! and no such centre ([`ErrorKind::CompensationEntryArcNoCentre`]). A move with no
//! motion in the plane (a Z plunge under G17) keeps the offset and is looked past: the corner
//! joins the elements on either side of it, and join connectors come after it, right before the
//! next element in the plane (as LinuxCNC queues them). A change of radius or side with no
//! move in the plane in between (G40, then G42 before the next move) ends one run at the last
//! element's plain offset end point and starts a new one from there.
//!
//! # Choices where the source is silent
//!
//! - Program end (M2/M30/%/end of text) with compensation on cancels it at the last point, as
//!   LinuxCNC does: the last element ends at its plain offset end point, and no move returns
//!   to the programmed path.
//! - A radius of 0 offsets nothing: the elements pass through bit for bit, with no start-up
//!   or cancel rules (LinuxCNC). A negative radius (G41.1 with a negative diameter, or a tool
//!   whose table radius is negative) swaps the side (LinuxCNC).
//! - Feed: every offset element keeps its programmed feed, so the tool centre moves at F (also
//!   what LinuxCNC does); under G93 the feed is the one the interpreter computed from the
//!   programmed length. Connectors take the feed, rapid flag, blend, comp state, line and
//!   column of the element after the corner (the corner is where that element begins).
//! - The auxiliary axes (A, B, C, U, V, W) are not offset, as in LinuxCNC: an element keeps
//!   its programmed auxiliary move, connectors hold them where the element before the corner
//!   left them, and a move of them alone is held and run at the offset point like a move along
//!   the tool axis.
//! - Axial motion (the plane's normal axis: Z under G17) belongs to the elements: a trimmed or
//!   extended line or helix still runs its whole programmed rise, from the height where it
//!   begins to the height where it ends; connectors are level, at the height where the element
//!   after the corner begins.
//! - An arc whose offset radius would be below [`MIN_ARC_RADIUS_MM`] (the interpreter's
//!   smallest arc) is an error: the tool is too big for that inside arc.
//! - Gouges: an element whose offset would run backwards once its corners are joined (it is
//!   shorter than what the corners take), and an inside corner whose offsets do not meet, are
//!   errors naming the element. The check is C-type's: one corner on each side of an element;
//!   a notch narrower than the tool over three or more elements is not seen.
//! - After an error the stream ends; the element held for look-ahead and what followed it are
//!   dropped, since their offset depends on what never came.
//! - Zero-length lines that a join produces are left out; an arc trimmed to nothing becomes a
//!   line between its end points.

mod geometry;

use std::collections::VecDeque;
use std::f64::consts::TAU;
use std::iter::FusedIterator;

use nalgebra::Vector3;
use serde::Deserialize;

use crate::gcode::{
    ArcGeometry, AuxMove, CompState, Element, ElementKind, Error, ErrorKind, Item,
    MIN_ARC_RADIUS_MM, Plane, Program,
};
use geometry::{Conn, Curve, End, Join, V2, left};
pub use geometry::{NEAR_MISS_MM, TANGENT_GAP_MM};

/// Items held while compensation waits for the next element in the plane (moves along the
/// plane's axis, dwells, stops, notes). More is an error: the program has to move in the plane
/// sooner.
pub const MAX_HELD_ITEMS: usize = 64;

/// A straight move whose motion in the plane is shorter than this counts as a move along the
/// plane's axis: it keeps the offset point, and its tiny in-plane part is dropped.
pub const MIN_PLANE_MOVE_MM: f64 = 1.0e-6;

/// An offset element may come out this much "backwards" from its corner joins (rounding) before
/// it is a gouge.
pub const GOUGE_TOLERANCE_MM: f64 = 1.0e-7;

/// An offset arc shorter than this is output as a straight line between its end points.
const MIN_ARC_LENGTH_MM: f64 = 1.0e-6;

/// How outside corners (α < 180°) are joined.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum OutsideCorners {
    /// The source's C-type classes: extended (90° ≤ α < 180°) and inserted (α < 90°), with
    /// straight extensions and insertions. Not LinuxCNC's path: chosen by the machine file.
    Lines,
    /// A tool-radius arc about the programmed corner, for every outside corner, as LinuxCNC
    /// joins them (the default: a program's path is the one LinuxCNC computes).
    #[default]
    Arc,
}

/// Options of the compensation stage.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CompOptions {
    /// How outside corners are joined.
    pub outside_corners: OutsideCorners,
}

/// The offset of one run of compensation: signed radius (`> 0` left, G41) and plane.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Key {
    d: f64,
    plane: Plane,
}

/// A programmed element in the compensation plane.
#[derive(Debug, Clone, Copy)]
enum Geo {
    Line {
        from: V2,
        to: V2,
        /// Unit direction.
        t: V2,
    },
    Arc {
        center: V2,
        /// Radius at the start and at the end (a spiral within the arc tolerance may differ).
        r0: f64,
        r1: f64,
        /// Unit vectors from the centre to the start and to the end.
        u0: V2,
        u1: V2,
        /// Counter-clockwise seen from the positive end of the plane's axis.
        ccw: bool,
        /// Angle turned (extra turns included).
        sweep: f64,
        /// The element's axis (unit, ± the plane's normal).
        normal: Vector3<f64>,
    },
}

impl Geo {
    /// The element in plane coordinates; `Err` with what is wrong for a geometry compensation
    /// cannot use (not finite, no motion in the plane, an arc about another axis).
    fn of(e: &Element, plane: Plane) -> Result<Geo, &'static str> {
        let (a, b, n) = plane.axes();
        if !finite(&e.start_mm) || !finite(&e.end_mm) {
            return Err("a coordinate is not finite");
        }
        let p0 = V2::new(e.start_mm[a], e.start_mm[b]);
        let p1 = V2::new(e.end_mm[a], e.end_mm[b]);
        match e.kind {
            ElementKind::Line => {
                let len = (p1 - p0).norm();
                if !(len > 0.0 && len.is_finite()) {
                    return Err("no motion in the compensation plane");
                }
                Ok(Geo::Line {
                    from: p0,
                    to: p1,
                    t: (p1 - p0) / len,
                })
            }
            ElementKind::Arc { .. } => {
                let g = e.arc().ok_or("degenerate arc (zero radius or no axis)")?;
                if g.normal[a].abs() > 1e-9 || g.normal[b].abs() > 1e-9 || !finite(&g.center_mm) {
                    return Err("an arc about another axis than the compensation plane's");
                }
                let center = V2::new(g.center_mm[a], g.center_mm[b]);
                let (r0, r1) = ((p0 - center).norm(), (p1 - center).norm());
                if !(r0 > 0.0 && r1 > 0.0 && r0.is_finite() && r1.is_finite()) {
                    return Err("degenerate arc (an end point on the centre)");
                }
                Ok(Geo::Arc {
                    center,
                    r0,
                    r1,
                    u0: (p0 - center) / r0,
                    u1: (p1 - center) / r1,
                    ccw: g.normal[n] > 0.0,
                    sweep: g.sweep_rad,
                    normal: g.normal,
                })
            }
        }
    }

    /// The plain (B-type) offset ends at the start and at the end, for the signed offset `d`.
    fn offset(&self, d: f64) -> Result<(End, End), ErrorKind> {
        match *self {
            Geo::Line { from, to, t } => {
                let shift = left(t) * d;
                Ok((
                    End {
                        curve: Curve::Line,
                        point: from + shift,
                        tangent: t,
                    },
                    End {
                        curve: Curve::Line,
                        point: to + shift,
                        tangent: t,
                    },
                ))
            }
            Geo::Arc {
                center,
                r0,
                r1,
                u0,
                u1,
                ccw,
                ..
            } => {
                let s = if ccw { 1.0 } else { -1.0 };
                let (rho0, rho1) = (r0 - s * d, r1 - s * d);
                let rho_min = rho0.min(rho1);
                // Finite: the radii and the offset are.
                if rho_min < MIN_ARC_RADIUS_MM {
                    return Err(ErrorKind::CompensationArcTooSmall {
                        arc_radius_mm: r0,
                        tool_radius_mm: d.abs(),
                        offset_radius_mm: rho_min,
                    });
                }
                Ok((
                    End {
                        curve: Curve::Circle {
                            center,
                            radius_mm: rho0,
                        },
                        point: center + u0 * rho0,
                        tangent: left(u0) * s,
                    },
                    End {
                        curve: Curve::Circle {
                            center,
                            radius_mm: rho1,
                        },
                        point: center + u1 * rho1,
                        tangent: left(u1) * s,
                    },
                ))
            }
        }
    }
}

/// The element waiting for the next one in the plane (the source's CS register).
#[derive(Debug, Clone)]
struct Open {
    /// As it came (line, column, feed... and the programmed geometry).
    e: Element,
    key: Key,
    geo: Geo,
    /// Its plain offset end, for the next join.
    end: End,
    /// Lines: the point of the offset line its length is measured from (the joined start, or
    /// for a start-up move the offset of the programmed start).
    check_from: V2,
    /// Arcs: angle cut off the start by the previous join (negative: added).
    start_trim: f64,
    /// The start-up move of its run.
    startup: bool,
}

/// The compensation stage: an iterator of items over an iterator of items.
///
/// It holds one element (the last one in the plane, until the next arrives) and the items that
/// came after it (at most [`MAX_HELD_ITEMS`]). Items other than motion keep their order
/// relative to the motion. Output elements start where the previous one ended, bit for bit,
/// and keep line, column, feed, blend, plane, rapid and comp state as they came.
pub struct Compensator<I> {
    input: I,
    file: String,
    options: CompOptions,
    out: VecDeque<Result<Item, Error>>,
    open: Option<Open>,
    held: Vec<Item>,
    /// Where the last output element ended (the first element's start until then).
    pos_mm: Option<Vector3<f64>>,
    done: bool,
}

impl<I> Compensator<I>
where
    I: Iterator<Item = Result<Item, Error>>,
{
    /// Compensates `items` (an [`crate::gcode::Interpreter`], or any stream in its order);
    /// `file` names the source in errors.
    pub fn new(items: I, file: impl Into<String>, options: CompOptions) -> Compensator<I> {
        Compensator {
            input: items,
            file: file.into(),
            options,
            out: VecDeque::new(),
            open: None,
            held: Vec::new(),
            pos_mm: None,
            done: false,
        }
    }

    /// The options in force.
    pub fn options(&self) -> CompOptions {
        self.options
    }

    fn error(&self, e: &Element, kind: ErrorKind) -> Error {
        Error {
            file: self.file.clone(),
            line: e.line,
            col: e.col,
            kind,
            called_from: None,
        }
    }

    fn geometry_error(&self, e: &Element, what: &'static str) -> Error {
        self.error(e, ErrorKind::CompensationGeometry { what })
    }

    fn gouge(&self, e: &Element, d: f64, what: &'static str) -> Error {
        self.error(
            e,
            ErrorKind::CompensationGouge {
                tool_radius_mm: d.abs(),
                what,
            },
        )
    }

    fn pos(&self) -> Vector3<f64> {
        self.pos_mm.unwrap_or_else(Vector3::zeros)
    }

    fn accept(&mut self, item: Item) -> Result<(), Error> {
        match item {
            Item::Motion(e) => self.motion(e),
            Item::End(_) => {
                self.finish()?;
                self.out.push_back(Ok(item));
                Ok(())
            }
            other => {
                if self.open.is_some() {
                    self.hold(other)
                } else {
                    self.out.push_back(Ok(other));
                    Ok(())
                }
            }
        }
    }

    /// The run an element belongs to; `None` without compensation (or with a zero radius).
    fn key(&self, e: &Element) -> Result<Option<Key>, Error> {
        let d = match e.comp {
            CompState::Off => return Ok(None),
            CompState::Left { radius_mm, .. } => radius_mm,
            CompState::Right { radius_mm, .. } => -radius_mm,
        };
        if !d.is_finite() {
            return Err(self.geometry_error(e, "the tool radius is not finite"));
        }
        Ok((d != 0.0).then_some(Key { d, plane: e.plane }))
    }

    fn motion(&mut self, e: Element) -> Result<(), Error> {
        if self.pos_mm.is_none() {
            self.pos_mm = Some(e.start_mm);
        }
        let Some(open) = self.open.take() else {
            return match self.key(&e)? {
                Some(key) if in_plane(&e, key.plane) => self.start_up(e, key),
                _ => {
                    let passed = Element {
                        start_mm: self.pos(),
                        ..e
                    };
                    self.push(passed)
                }
            };
        };
        let Some(key) = self.key(&e)? else {
            // After G40 the next move of any kind leaves the offset path (LinuxCNC).
            return self.cancel(open, e);
        };
        if !in_plane(&e, open.key.plane) {
            self.open = Some(open);
            return self.hold(Item::Motion(e));
        }
        if key == open.key {
            self.corner(open, e)
        } else {
            self.open = Some(open);
            self.finish()?;
            self.start_up(e, key)
        }
    }

    /// Opens a start-up move: from the current point, uncompensated, to the join with the next.
    fn start_up(&mut self, e: Element, key: Key) -> Result<(), Error> {
        if let ElementKind::Arc { cw, .. } = e.kind {
            return self.start_up_arc(e, key, if cw { "G2" } else { "G3" });
        }
        let geo = Geo::of(&e, key.plane).map_err(|w| self.geometry_error(&e, w))?;
        // LinuxCNC's `convert_straight_comp1` measures from the programmed start (its current
        // point; after G40 the tool may still be at the last offset point).
        let length_mm =
            (plane_point(&e.end_mm, key.plane) - plane_point(&e.start_mm, key.plane)).norm();
        if length_mm <= key.d.abs() {
            return Err(self.error(
                &e,
                ErrorKind::CompensationEntryTooShort {
                    code: if e.rapid { "G0" } else { "G1" },
                    length_mm,
                    tool_radius_mm: key.d.abs(),
                },
            ));
        }
        // Its offset line begins one radius over from the programmed start.
        let (start, end) = geo.offset(key.d).map_err(|k| self.error(&e, k))?;
        let check_from = start.point;
        self.open = Some(Open {
            e,
            key,
            geo,
            end,
            check_from,
            start_trim: 0.0,
            startup: true,
        });
        Ok(())
    }

    /// Opens an arc as the start-up move, as LinuxCNC's `convert_arc_comp1` makes it: from the
    /// current, uncompensated point to the programmed end moved one tool radius along the
    /// arc's radius there (toward the centre when the tool is inside the arc, away when
    /// outside), about the centre on that radius that is as far from the start as from the
    /// end. Its end keeps the programmed arc's tangent, so the corner after it joins as after
    /// any arc; an inside corner trims it on its own circle.
    fn start_up_arc(&mut self, e: Element, key: Key, code: &'static str) -> Result<(), Error> {
        let geo = Geo::of(&e, key.plane).map_err(|w| self.geometry_error(&e, w))?;
        let Geo::Arc {
            center,
            r0,
            u1,
            ccw,
            normal,
            ..
        } = geo
        else {
            return Err(self.geometry_error(&e, "an arc without an arc's geometry"));
        };
        let r = key.d.abs();
        let start = plane_point(&self.pos(), key.plane);
        if (start - plane_point(&e.start_mm, key.plane)).norm() > TANGENT_GAP_MM {
            // A new run right after another (G40 and G41/G42 with no move between): the tool
            // is at the last run's offset point, not at the arc's programmed start. LinuxCNC
            // computes such an arc from the programmed start and moves from the tool.
            return Err(self.error(
                &e,
                ErrorKind::Unsupported {
                    what: format!(
                        "{code} as the start-up move right after another compensation run"
                    ),
                    reason: "program a straight move between the G40 and the next G41/G42",
                },
            ));
        }
        let end = plane_point(&e.end_mm, key.plane);
        let chord_mm = (end - start).norm();
        if chord_mm <= r {
            return Err(self.error(
                &e,
                ErrorKind::CompensationEntryArcTooShort {
                    code,
                    chord_mm,
                    tool_radius_mm: r,
                },
            ));
        }
        // LinuxCNC's TOOL_INSIDE_ARC: left of a counter-clockwise arc, right of a clockwise one.
        let inside = (key.d > 0.0) == ccw;
        if inside && r0 <= r {
            return Err(self.error(
                &e,
                ErrorKind::CompensationArcTooSmall {
                    arc_radius_mm: r0,
                    tool_radius_mm: r,
                    offset_radius_mm: r0 - r,
                },
            ));
        }
        let to = end + if inside { -u1 } else { u1 } * r;
        // The centre lies on the line from the new end toward the programmed centre, at
        // c_len = (|start − to| / 2) / cos A from the new end, A the angle at the new end
        // between that line and the chord to the start (negative: beyond the end, on the far
        // side; LinuxCNC keeps that too).
        let toward = center - to;
        let toward_len = toward.norm();
        let chord = start - to;
        let cos_a = if toward_len > 0.0 {
            toward.dot(&chord) / (toward_len * chord.norm())
        } else {
            0.0
        };
        // LinuxCNC's TOLERANCE_EQUAL.
        if cos_a.is_nan() || cos_a.abs() < 1e-4 {
            return Err(self.error(
                &e,
                ErrorKind::CompensationEntryArcNoCentre {
                    code,
                    tool_radius_mm: r,
                },
            ));
        }
        let c_len = 0.5 * chord.norm() / cos_a;
        let new_center = to + toward / toward_len * c_len;
        let radius_mm = c_len.abs();
        if !(radius_mm >= MIN_ARC_RADIUS_MM && radius_mm.is_finite()) {
            return Err(self.error(
                &e,
                ErrorKind::CompensationArcTooSmall {
                    arc_radius_mm: r0,
                    tool_radius_mm: r,
                    offset_radius_mm: radius_mm,
                },
            ));
        }
        let (v0, v1) = (
            (start - new_center) / radius_mm,
            (to - new_center) / radius_mm,
        );
        // From the start to the new end the way the arc turns, in (0, 2π] (LinuxCNC's
        // find_turn), plus the programmed extra turns.
        let s = if ccw { 1.0 } else { -1.0 };
        let mut sweep = s * geometry::cross(v0, v1).atan2(v0.dot(&v1));
        if sweep <= 0.0 {
            sweep += TAU;
        }
        if let ElementKind::Arc { turns, .. } = e.kind {
            sweep += TAU * f64::from(turns);
        }
        self.open = Some(Open {
            e,
            key,
            geo: Geo::Arc {
                center: new_center,
                r0: radius_mm,
                r1: radius_mm,
                u0: v0,
                u1: v1,
                ccw,
                sweep,
                normal,
            },
            end: End {
                curve: Curve::Circle {
                    center: new_center,
                    radius_mm,
                },
                point: to,
                // The programmed arc's direction at its end: LinuxCNC classifies the next
                // corner by it.
                tangent: left(u1) * s,
            },
            check_from: V2::zeros(),
            start_trim: 0.0,
            startup: true,
        });
        Ok(())
    }

    /// The next element of the same run: join the open one to it, open it.
    fn corner(&mut self, open: Open, e: Element) -> Result<(), Error> {
        let key = open.key;
        let geo = Geo::of(&e, key.plane).map_err(|w| self.geometry_error(&e, w))?;
        let (start, end) = geo.offset(key.d).map_err(|k| self.error(&e, k))?;
        let join = self.join(&open, &start, &e)?;
        self.emit_open(&open, join.end1)?;
        self.release(key.plane)?;
        self.connect(&e, key.plane, &join.conns)?;
        let (check_from, start_trim) = match geo {
            Geo::Line { .. } => (join.start2, 0.0),
            Geo::Arc {
                center, u0, ccw, ..
            } => (V2::zeros(), trim_start(center, u0, ccw, join.start2)),
        };
        self.open = Some(Open {
            e,
            key,
            geo,
            end,
            check_from,
            start_trim,
            startup: false,
        });
        Ok(())
    }

    /// The cancel move, as LinuxCNC's G40 makes it (`convert_cutter_compensation_off`, then
    /// `convert_straight` with compensation off): the open element ends at its plain offset end
    /// point (no corner join), and the first move after G40, whatever it is (one along the
    /// tool axis too), runs straight from there to its programmed end point. An arc there is
    /// an error; the interpreter refuses it first, this is for other item streams.
    fn cancel(&mut self, open: Open, e: Element) -> Result<(), Error> {
        if let ElementKind::Arc { cw, .. } = e.kind {
            return Err(self.error(
                &e,
                ErrorKind::CompensationEndOnArc {
                    code: if cw { "G2" } else { "G3" },
                },
            ));
        }
        self.emit_open(&open, open.end.point)?;
        self.release(open.key.plane)?;
        self.push(Element {
            start_mm: self.pos(),
            ..e
        })
    }

    /// The join of the open element's end to the start `start` of `e`'s offset, at the
    /// programmed corner (where `e` begins).
    fn join(&self, open: &Open, start: &End, e: &Element) -> Result<Join, Error> {
        let corner = plane_point(&e.start_mm, open.key.plane);
        let arcs = self.options.outside_corners == OutsideCorners::Arc;
        geometry::join(&open.end, start, corner, open.key.d, arcs).ok_or_else(|| {
            self.gouge(
                e,
                open.key.d,
                "the tool-centre paths of the inside corner where this move begins do not meet",
            )
        })
    }

    /// Ends the open element at its plain offset end point (program end, or a new run).
    fn finish(&mut self) -> Result<(), Error> {
        if let Some(open) = self.open.take() {
            self.emit_open(&open, open.end.point)?;
            self.release(open.key.plane)?;
        }
        Ok(())
    }

    /// Outputs the open element, ending at `end` (a point of its offset curve).
    fn emit_open(&mut self, open: &Open, end: V2) -> Result<(), Error> {
        let e = &open.e;
        let n = open.key.plane.axes().2;
        let end_mm = plane_to_3d(end, e.end_mm[n], open.key.plane);
        match open.geo {
            Geo::Line { t, .. } => {
                // A straight start-up move is never a gouge: LinuxCNC checks the direction of
                // its (moved) end against the normal of the move, which it always keeps.
                if !open.startup && (end - open.check_from).dot(&t) < -GOUGE_TOLERANCE_MM {
                    return Err(self.gouge(
                        e,
                        open.key.d,
                        "this element is shorter than its corners take (its tool-centre path would run backwards)",
                    ));
                }
                self.push(Element {
                    kind: ElementKind::Line,
                    start_mm: self.pos(),
                    end_mm,
                    ..*e
                })
            }
            Geo::Arc {
                center,
                u1,
                ccw,
                sweep,
                normal,
                ..
            } => {
                let sweep = sweep - open.start_trim - trim_end(center, u1, ccw, end);
                let start_mm = self.pos();
                let radius_mm = (plane_point(&start_mm, open.key.plane) - center).norm();
                if sweep * radius_mm < -GOUGE_TOLERANCE_MM {
                    return Err(self.gouge(
                        e,
                        open.key.d,
                        "this arc is shorter than its corners take (its tool-centre arc would run backwards)",
                    ));
                }
                let center_mm = plane_to_3d(center, start_mm[n], open.key.plane);
                let arc = (sweep * radius_mm > MIN_ARC_LENGTH_MM)
                    .then(|| ArcGeometry::new(start_mm, end_mm, center_mm, normal, 0))
                    .flatten();
                let kind = match arc {
                    Some(g) => ElementKind::Arc {
                        center_mm,
                        normal,
                        cw: !ccw,
                        // The end points give the angle modulo a turn; the sweep says how many.
                        turns: ((sweep - g.sweep_rad) / TAU).round().max(0.0) as u32,
                        radius_mm,
                    },
                    None => ElementKind::Line,
                };
                self.push(Element {
                    kind,
                    start_mm,
                    end_mm,
                    ..*e
                })
            }
        }
    }

    /// Outputs a join's connectors, with the metadata of `e` (the element after the corner).
    fn connect(&mut self, e: &Element, plane: Plane, conns: &[Conn]) -> Result<(), Error> {
        let n = plane.axes().2;
        for conn in conns {
            let start_mm = self.pos();
            let z = start_mm[n];
            let (kind, end_mm) = match *conn {
                Conn::Line { to } => (ElementKind::Line, plane_to_3d(to, z, plane)),
                Conn::Arc { center, to, ccw } => {
                    let mut normal = Vector3::zeros();
                    normal[n] = if ccw { 1.0 } else { -1.0 };
                    let center_mm = plane_to_3d(center, z, plane);
                    let end_mm = plane_to_3d(to, z, plane);
                    let radius_mm = (plane_point(&start_mm, plane) - center).norm();
                    let kind = match ArcGeometry::new(start_mm, end_mm, center_mm, normal, 0) {
                        Some(_) => ElementKind::Arc {
                            center_mm,
                            normal,
                            cw: !ccw,
                            turns: 0,
                            radius_mm,
                        },
                        None => ElementKind::Line,
                    };
                    (kind, end_mm)
                }
            };
            // The auxiliary axes (A, B, C, U, V, W) stand at the corner: the element after it
            // moves them (LinuxCNC's inserted arcs carry no rotary motion either).
            self.push(Element {
                kind,
                start_mm,
                end_mm,
                aux: AuxMove::still(e.aux.start),
                ..*e
            })?;
        }
        Ok(())
    }

    /// Holds an item that came after the open element.
    fn hold(&mut self, item: Item) -> Result<(), Error> {
        if let Item::Motion(e) = &item
            && (!finite(&e.start_mm) || !finite(&e.end_mm))
        {
            return Err(self.geometry_error(e, "a coordinate is not finite"));
        }
        if self.held.len() >= MAX_HELD_ITEMS {
            let (line, col) = self.open.as_ref().map_or((0, 0), |o| (o.e.line, o.e.col));
            return Err(Error {
                file: self.file.clone(),
                line,
                col,
                kind: ErrorKind::CompensationLookAhead {
                    max: MAX_HELD_ITEMS,
                },
                called_from: None,
            });
        }
        self.held.push(item);
        Ok(())
    }

    /// Outputs the held items; moves along the plane's axis stay at the current offset point.
    fn release(&mut self, plane: Plane) -> Result<(), Error> {
        let n = plane.axes().2;
        let held = std::mem::take(&mut self.held);
        for item in held {
            match item {
                Item::Motion(e) => {
                    let mut end_mm = self.pos();
                    end_mm[n] = e.end_mm[n];
                    self.push(Element {
                        kind: ElementKind::Line,
                        start_mm: self.pos(),
                        end_mm,
                        ..e
                    })?;
                }
                other => self.out.push_back(Ok(other)),
            }
        }
        Ok(())
    }

    /// Queues an output element (a line of no length is left out) and moves the current point.
    fn push(&mut self, e: Element) -> Result<(), Error> {
        if let Some(e) = self.output(e)? {
            self.out.push_back(Ok(Item::Motion(e)));
        }
        Ok(())
    }

    /// What [`Self::push`] queues (`None` for a line of no length), with the current point
    /// moved: for the caller that hands it out directly.
    fn output(&mut self, e: Element) -> Result<Option<Element>, Error> {
        Ok(self.keep(&e)?.then_some(e))
    }

    /// Whether [`Self::output`] keeps `e`; moves the current point to its end if so.
    fn keep(&mut self, e: &Element) -> Result<bool, Error> {
        if !finite(&e.start_mm) || !finite(&e.end_mm) {
            return Err(self.geometry_error(e, "a coordinate is not finite"));
        }
        // The auxiliary axes pass through unchanged: a move of them alone is kept.
        if e.kind == ElementKind::Line && e.start_mm == e.end_mm && !e.aux.moves() {
            return Ok(false);
        }
        self.pos_mm = Some(e.end_mm);
        Ok(true)
    }

    /// An element with no compensation open nor asked for: what [`Self::motion`] does with it,
    /// done in place (the element is not copied) and handed back rather than queued; `false`
    /// when it is left out.
    fn pass(&mut self, e: &mut Element) -> Result<bool, Error> {
        e.start_mm = *self.pos_mm.get_or_insert(e.start_mm);
        self.keep(e)
    }
}

impl<I> Iterator for Compensator<I>
where
    I: Iterator<Item = Result<Item, Error>>,
{
    type Item = Result<Item, Error>;

    fn next(&mut self) -> Option<Self::Item> {
        loop {
            if let Some(item) = self.out.pop_front() {
                return Some(item);
            }
            if self.done {
                return None;
            }
            let step = match self.input.next() {
                None => {
                    self.done = true;
                    self.finish()
                }
                Some(Err(e)) => Err(e),
                // Most programs run without compensation: their elements go straight out,
                // in the item they came in, not through the queue (a copy each way).
                Some(Ok(mut item)) => {
                    if self.open.is_none()
                        && self.out.is_empty()
                        && let Item::Motion(e) = &mut item
                        && matches!(e.comp, CompState::Off)
                    {
                        match self.pass(e) {
                            Ok(true) => return Some(Ok(item)),
                            Ok(false) => Ok(()),
                            Err(e) => Err(e),
                        }
                    } else {
                        self.accept(item)
                    }
                }
            };
            if let Err(e) = step {
                self.open = None;
                self.held.clear();
                self.out.push_back(Err(e));
                self.done = true;
            }
        }
    }
}

impl<I> FusedIterator for Compensator<I> where I: Iterator<Item = Result<Item, Error>> {}

/// Compensates a whole [`Program`] (its items; notes, end, file and start are kept): for
/// callers that interpret a program before planning it.
pub fn compensate_program(program: &Program, options: CompOptions) -> Result<Program, Error> {
    let items = Compensator::new(
        program.items.iter().cloned().map(Ok),
        program.file.clone(),
        options,
    )
    .collect::<Result<Vec<_>, _>>()?;
    Ok(Program {
        file: program.file.clone(),
        start_mm: program.start_mm,
        items,
        notes: program.notes.clone(),
        end: program.end,
        carry: program.carry.clone(),
    })
}

fn finite(v: &Vector3<f64>) -> bool {
    v.iter().all(|c| c.is_finite())
}

/// Whether an element moves in the plane (every arc does).
fn in_plane(e: &Element, plane: Plane) -> bool {
    match e.kind {
        ElementKind::Arc { .. } => true,
        ElementKind::Line => {
            let (a, b, _) = plane.axes();
            (e.end_mm[a] - e.start_mm[a]).hypot(e.end_mm[b] - e.start_mm[b]) > MIN_PLANE_MOVE_MM
        }
    }
}

fn plane_point(p: &Vector3<f64>, plane: Plane) -> V2 {
    let (a, b, _) = plane.axes();
    V2::new(p[a], p[b])
}

fn plane_to_3d(p: V2, axial: f64, plane: Plane) -> Vector3<f64> {
    let (a, b, n) = plane.axes();
    let mut v = Vector3::zeros();
    v[a] = p.x;
    v[b] = p.y;
    v[n] = axial;
    v
}

/// Angle cut off the start of an arc (centre, unit start radius `u0`) when it begins at `p`
/// instead, in (−π, π]; positive when `p` lies ahead.
fn trim_start(center: V2, u0: V2, ccw: bool, p: V2) -> f64 {
    let q = p - center;
    let s = if ccw { 1.0 } else { -1.0 };
    s * geometry::cross(u0, q).atan2(u0.dot(&q))
}

/// Angle cut off the end of an arc (unit end radius `u1`) when it ends at `p` instead.
fn trim_end(center: V2, u1: V2, ccw: bool, p: V2) -> f64 {
    let q = p - center;
    let s = if ccw { 1.0 } else { -1.0 };
    s * geometry::cross(q, u1).atan2(q.dot(&u1))
}

#[cfg(test)]
mod tests;
