//! Plane geometry of C-type cutter compensation: where two offset elements meet.
//!
//! Everything here is 2-D, in the coordinates of the compensation plane (first axis, second
//! axis; see [`crate::gcode::Plane::axes`]), so "left" is a quarter turn counter-clockwise seen
//! from the positive end of the plane's normal axis. Offsets are signed: `d > 0` puts the tool
//! left of the direction of travel (G41), `d < 0` right (G42).
//!
//! A join looks at one *end* of each element: the offset point the element would have there if
//! it were compensated alone (B-type), the direction of travel there, and the offset curve (the
//! offset line, or the concentric offset circle of an arc). The corner's class comes from the
//! turn between the two directions; the join returns where the first offset element ends, where
//! the second begins, and the connecting elements in between.

use std::f64::consts::FRAC_PI_2;

use nalgebra::Vector2;

/// A point or a direction in the compensation plane, mm.
pub(crate) type V2 = Vector2<f64>;

/// Offset points of two elements at a corner closer than this (and turning less than a quarter
/// turn) make a tangent join: the elements meet at one of the two points, with no connector.
/// It absorbs the rounding of tangent line–arc and arc–arc joins in CAM output; the snap moves
/// an end along its tangent, so the distance to the programmed path changes by `gap²/(2r)`, far
/// below a count.
pub const TANGENT_GAP_MM: f64 = 1.0e-4;

/// Two offset curves that miss each other by less than this still meet (at the point of
/// closest approach): the miss is rounding.
pub const NEAR_MISS_MM: f64 = 1.0e-6;

/// `v` turned a quarter turn to the left (counter-clockwise).
pub(crate) fn left(v: V2) -> V2 {
    V2::new(-v.y, v.x)
}

/// z-component of `a × b`: positive when `b` turns left from `a`.
pub(crate) fn cross(a: V2, b: V2) -> f64 {
    a.x * b.y - a.y * b.x
}

/// The offset curve through the end of an element.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Curve {
    /// The offset line: through the end's point along its tangent.
    Line,
    /// The offset circle of an arc: the arc's centre, the offset radius at this end.
    Circle { center: V2, radius_mm: f64 },
}

/// One end of an offset element, as it would be if the element were offset alone.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct End {
    /// Offset line or circle.
    pub curve: Curve,
    /// The offset point (programmed end point plus `d` times the left normal).
    pub point: V2,
    /// Unit direction of travel at this end.
    pub tangent: V2,
}

/// A connecting element of a join, from the previous point to `to`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Conn {
    /// A straight connector.
    Line { to: V2 },
    /// A tool-radius arc about the programmed corner ([`super::OutsideCorners::Arc`]).
    Arc { center: V2, to: V2, ccw: bool },
}

/// The corner classes of C-type compensation, by the angle α between the two elements measured
/// on the workpiece side.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Class {
    /// The elements continue in the same direction (α = 180°, within [`TANGENT_GAP_MM`]).
    Tangent,
    /// 180° < α < 360°: an inside corner; both offsets end at their intersection.
    Shortened,
    /// 90° ≤ α < 180°: both offsets extend to meet.
    Extended,
    /// 0° ≤ α < 90°: both offsets extend by one tool radius and a line joins the two ends.
    Inserted,
    /// Any outside corner (α < 180°) with [`super::OutsideCorners::Arc`]: a tool-radius arc.
    Arc,
}

/// The result of a join.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Join {
    /// The corner's class.
    pub class: Class,
    /// Where the first offset element ends.
    pub end1: V2,
    /// Connectors from `end1` to `start2`, in order (at most three).
    pub conns: Vec<Conn>,
    /// Where the second offset element begins (`end1`, or the last connector's end).
    pub start2: V2,
}

/// Joins the end `e1` of one offset element to the start `e2` of the next, at the programmed
/// corner `corner`, for the signed offset `d` (≠ 0). `arc_corners` selects a tool-radius arc for
/// outside corners. `None` when an inside corner's offsets do not intersect.
pub(crate) fn join(e1: &End, e2: &End, corner: V2, d: f64, arc_corners: bool) -> Option<Join> {
    let r = d.abs();
    let (p1, t1, p2, t2) = (e1.point, e1.tangent, e2.point, e2.tangent);
    let turn_sin = cross(t1, t2);
    let turn_cos = t1.dot(&t2);
    // Signed turn from t1 to t2 in (−π, π]. α = π + sign(d)·θ is the angle on the workpiece
    // side (the workpiece is right of the path under G41, left under G42).
    let theta = turn_sin.atan2(turn_cos);
    // An exact reversal has no side: the tool goes round the tip (α = 0°, never 360°).
    let reversal = turn_sin == 0.0 && turn_cos < 0.0;
    let inside = !reversal && theta * d.signum() > 0.0;
    let both_lines = e1.curve == Curve::Line && e2.curve == Curve::Line;
    let gap = (p2 - p1).norm();
    let near_tangent = turn_cos > 0.0 && gap <= TANGENT_GAP_MM;
    let half_turn_tan = (0.5 * theta.abs()).tan();

    if near_tangent && !both_lines {
        // Keep the arc's own point: a line's end moves along its tangent instead.
        let at = if e1.curve == Curve::Line { p2 } else { p1 };
        return Some(Join {
            class: Class::Tangent,
            end1: at,
            conns: Vec::new(),
            start2: at,
        });
    }
    if inside {
        let at = if both_lines {
            // Both offset lines cut back by r·tan(θ/2) from their offset points: the exact
            // intersection, well conditioned at small turns.
            p1 - t1 * (r * half_turn_tan)
        } else {
            intersect(e1, e2, corner)?
        };
        return Some(Join {
            class: if theta == 0.0 {
                Class::Tangent
            } else {
                Class::Shortened
            },
            end1: at,
            conns: Vec::new(),
            start2: at,
        });
    }
    if arc_corners && gap > TANGENT_GAP_MM {
        return Some(Join {
            class: Class::Arc,
            end1: p1,
            // Outside corners turn away from the tool: clockwise under G41, counter-clockwise
            // under G42 (this also settles the direction round the tip of a reversal).
            conns: vec![Conn::Arc {
                center: corner,
                to: p2,
                ccw: d < 0.0,
            }],
            start2: p2,
        });
    }
    let mut conns = Vec::new();
    let (class, x1, x2) = if !reversal && theta.abs() <= FRAC_PI_2 {
        // Extended: both offset tangents meet r·tan(θ/2) beyond the offset points.
        let x = p1 + t1 * (r * half_turn_tan);
        let class = if theta == 0.0 {
            Class::Tangent
        } else {
            Class::Extended
        };
        (class, x, x)
    } else {
        // Inserted: each offset extended by one tool radius, then a straight line across.
        (Class::Inserted, p1 + t1 * r, p2 - t2 * r)
    };
    let end1 = if e1.curve == Curve::Line {
        x1
    } else {
        conns.push(Conn::Line { to: x1 });
        p1
    };
    if x2 != x1 {
        conns.push(Conn::Line { to: x2 });
    }
    let start2 = if e2.curve == Curve::Line {
        x2
    } else {
        conns.push(Conn::Line { to: p2 });
        p2
    };
    Some(Join {
        class,
        end1,
        conns,
        start2,
    })
}

/// The intersection of the two offset curves nearest to the programmed corner.
fn intersect(e1: &End, e2: &End, corner: V2) -> Option<V2> {
    let roots = match (e1.curve, e2.curve) {
        (Curve::Line, Curve::Line) => {
            let den = cross(e1.tangent, e2.tangent);
            if den == 0.0 {
                return None;
            }
            let s = cross(e2.point - e1.point, e2.tangent) / den;
            [Some(e1.point + e1.tangent * s), None]
        }
        (Curve::Line, Curve::Circle { center, radius_mm }) => {
            line_circle(e1.point, e1.tangent, center, radius_mm)?
        }
        (Curve::Circle { center, radius_mm }, Curve::Line) => {
            line_circle(e2.point, e2.tangent, center, radius_mm)?
        }
        (
            Curve::Circle {
                center: c1,
                radius_mm: r1,
            },
            Curve::Circle {
                center: c2,
                radius_mm: r2,
            },
        ) => circle_circle(c1, r1, c2, r2)?,
    };
    roots
        .into_iter()
        .flatten()
        .filter(|p| p.iter().all(|c| c.is_finite()))
        .min_by(|a, b| (a - corner).norm().total_cmp(&(b - corner).norm()))
}

/// Where the line through `p` along the unit `t` meets the circle (`c`, `radius`).
fn line_circle(p: V2, t: V2, c: V2, radius: f64) -> Option<[Option<V2>; 2]> {
    let w = p - c;
    let along = w.dot(&t);
    let dist = cross(t, w).abs();
    let mut disc = (radius - dist) * (radius + dist);
    if disc < 0.0 {
        if dist - radius > NEAR_MISS_MM {
            return None;
        }
        disc = 0.0;
    }
    let root = disc.sqrt();
    Some([Some(p + t * (-along - root)), Some(p + t * (-along + root))])
}

/// Where two circles meet.
fn circle_circle(c1: V2, r1: f64, c2: V2, r2: f64) -> Option<[Option<V2>; 2]> {
    let dc = c2 - c1;
    let dist = dc.norm();
    if dist == 0.0 || !dist.is_finite() {
        return None;
    }
    let e = dc / dist;
    // Distance from c1 to the chord through the two intersections, along e.
    let a = (dist * dist + (r1 - r2) * (r1 + r2)) / (2.0 * dist);
    let mut h2 = (r1 - a) * (r1 + a);
    if h2 < 0.0 {
        if a.abs() - r1 > NEAR_MISS_MM {
            return None;
        }
        h2 = 0.0;
    }
    let h = h2.sqrt();
    let mid = c1 + e * a;
    Some([Some(mid + left(e) * h), Some(mid - left(e) * h)])
}

#[cfg(test)]
mod tests {
    use super::*;

    fn v(x: f64, y: f64) -> V2 {
        V2::new(x, y)
    }

    fn close(a: V2, b: V2) -> bool {
        (a - b).norm() < 1e-12
    }

    fn line_end(point: V2, tangent: V2) -> End {
        End {
            curve: Curve::Line,
            point,
            tangent: tangent.normalize(),
        }
    }

    #[test]
    fn inside_right_angle_shortens_both_lines_by_the_radius() {
        // +X then +Y under G41 (tool left): a left turn, the tool inside; α = 270°.
        // Offsets y = 2 and x = 8 meet at (8, 2).
        let e1 = line_end(v(10.0, 2.0), v(1.0, 0.0));
        let e2 = line_end(v(8.0, 0.0), v(0.0, 1.0));
        let j = join(&e1, &e2, v(10.0, 0.0), 2.0, false).unwrap();
        assert_eq!(j.class, Class::Shortened);
        assert!(close(j.end1, v(8.0, 2.0)), "{}", j.end1);
        assert_eq!(j.end1, j.start2);
        assert!(j.conns.is_empty());
    }

    #[test]
    fn outside_classes_by_angle() {
        // +X then turning right by 60° under G41: outside, α = 120°, extended by 2·tan 30°.
        let t2 = v(0.5, -(3f64.sqrt()) / 2.0);
        let e1 = line_end(v(10.0, 2.0), v(1.0, 0.0));
        let e2 = line_end(v(10.0, 0.0) + left(t2) * 2.0, t2);
        let j = join(&e1, &e2, v(10.0, 0.0), 2.0, false).unwrap();
        assert_eq!(j.class, Class::Extended);
        let lam = 2.0 * (30f64.to_radians()).tan();
        assert!(close(j.end1, v(10.0 + lam, 2.0)), "{}", j.end1);
        // Exactly 90°: extended, the extension is one radius.
        let e2 = line_end(v(12.0, 0.0), v(0.0, -1.0));
        let j = join(&e1, &e2, v(10.0, 0.0), 2.0, false).unwrap();
        assert_eq!(j.class, Class::Extended);
        assert!(close(j.end1, v(12.0, 2.0)), "{}", j.end1);
        // A turn of 135° (α = 45°): each extended by r, a line across.
        let t2 = v(-1.0, -1.0).normalize();
        let p2 = v(10.0, 0.0) + left(t2) * 2.0;
        let e2 = line_end(p2, t2);
        let j = join(&e1, &e2, v(10.0, 0.0), 2.0, false).unwrap();
        assert_eq!(j.class, Class::Inserted);
        assert!(close(j.end1, v(12.0, 2.0)));
        assert!(close(j.start2, p2 - t2 * 2.0));
        assert_eq!(j.conns, vec![Conn::Line { to: j.start2 }]);
        // A reversal goes round the tip under both sides.
        for d in [2.0, -2.0] {
            let e1 = line_end(v(10.0, d), v(1.0, 0.0));
            let e2 = line_end(v(10.0, -d), v(-1.0, 0.0));
            let j = join(&e1, &e2, v(10.0, 0.0), d, false).unwrap();
            assert_eq!(j.class, Class::Inserted);
            assert!(close(j.end1, v(12.0, d)));
            assert!(close(j.start2, v(12.0, -d)));
            let j = join(&e1, &e2, v(10.0, 0.0), d, true).unwrap();
            assert_eq!(
                j.conns,
                vec![Conn::Arc {
                    center: v(10.0, 0.0),
                    to: v(10.0, -d),
                    ccw: d < 0.0
                }]
            );
        }
    }

    #[test]
    fn line_into_inside_arc_meets_the_offset_circle() {
        // A line heading 30° below +X into (10,0), then a counter-clockwise arc about (10,10)
        // (R 10) leaving along +X: a left turn of 30°, inside under G41 (d = 2). The arc turns
        // toward the tool: offset circle radius 8, offset start (10,2).
        let t1 = v(30f64.to_radians().cos(), -(30f64.to_radians().sin()));
        let e1 = line_end(v(10.0, 0.0) + left(t1) * 2.0, t1);
        let e2 = End {
            curve: Curve::Circle {
                center: v(10.0, 10.0),
                radius_mm: 8.0,
            },
            point: v(10.0, 2.0),
            tangent: v(1.0, 0.0),
        };
        let j = join(&e1, &e2, v(10.0, 0.0), 2.0, false).unwrap();
        assert_eq!(j.class, Class::Shortened);
        // On the circle and on the offset line, near the corner.
        assert!(((j.end1 - v(10.0, 10.0)).norm() - 8.0).abs() < 1e-9);
        assert!((cross(t1, j.end1 - e1.point)).abs() < 1e-9);
        assert!((j.end1 - v(10.0, 2.0)).norm() < 2.0);
    }

    #[test]
    fn missing_circles_do_not_intersect() {
        assert!(circle_circle(v(0.0, 0.0), 1.0, v(5.0, 0.0), 1.0).is_none());
        assert!(circle_circle(v(0.0, 0.0), 1.0, v(0.0, 0.0), 1.0).is_none());
        let [a, b] = circle_circle(v(0.0, 0.0), 1.0, v(2.0, 0.0), 1.0).unwrap();
        assert!(close(a.unwrap(), v(1.0, 0.0)) && close(b.unwrap(), v(1.0, 0.0)));
        assert!(line_circle(v(0.0, 3.0), v(1.0, 0.0), v(0.0, 0.0), 2.0).is_none());
        let [a, b] = line_circle(v(-5.0, 0.0), v(1.0, 0.0), v(0.0, 0.0), 2.0).unwrap();
        assert!(close(a.unwrap(), v(-2.0, 0.0)) && close(b.unwrap(), v(2.0, 0.0)));
    }
}
