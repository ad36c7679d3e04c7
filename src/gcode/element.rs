//! Path elements: the interpreter's output, the input of compensation and of the planner.
//!
//! Every coordinate here is in millimetres, in machine coordinates (work offsets, G92, the
//! coordinate-system rotation and the tool length offset already applied): the position the axes
//! must reach. Feeds are path speeds in mm/s.

use std::f64::consts::{PI, TAU};

use nalgebra::Vector3;

/// The auxiliary axes in the order of [`AuxPos`]: the rotary axes A, B, C (degrees) and the
/// secondary linear axes U, V, W (millimetres), as RS274/NGC names them.
pub const AUX_LETTERS: [char; 6] = ['A', 'B', 'C', 'U', 'V', 'W'];

/// Positions of the auxiliary axes, in the order of [`AUX_LETTERS`]: A, B, C in degrees, U, V,
/// W in millimetres (machine coordinates).
pub type AuxPos = [f64; 6];

/// How the auxiliary axes move over an element: linearly in the path parameter, from `start`
/// to `end` (LinuxCNC's trajectory planner carries them the same way, on arcs too).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct AuxMove {
    /// Where they are at the element's start (the previous element's `end`, bit for bit).
    pub start: AuxPos,
    /// Where they are at its end.
    pub end: AuxPos,
}

impl AuxMove {
    /// No motion of the auxiliary axes: they stay at `at`.
    pub fn still(at: AuxPos) -> AuxMove {
        AuxMove { start: at, end: at }
    }

    /// Whether any auxiliary axis moves.
    pub fn moves(&self) -> bool {
        self.start != self.end
    }

    /// `end − start`, per axis.
    pub fn delta(&self) -> AuxPos {
        std::array::from_fn(|i| self.end[i] - self.start[i])
    }

    /// The positions at fraction `f` of the way: exactly `start` at `f <= 0` and exactly `end`
    /// at `f >= 1`; the second half is measured back from the end (as a line's points), and an
    /// axis that does not move keeps its value bit for bit.
    pub fn at(&self, f: f64) -> AuxPos {
        if f.is_nan() || f <= 0.0 {
            return self.start;
        }
        if f >= 1.0 {
            return self.end;
        }
        std::array::from_fn(|i| {
            let (a, b) = (self.start[i], self.end[i]);
            if a == b {
                a
            } else if f <= 0.5 {
                a + (b - a) * f
            } else {
                b - (b - a) * (1.0 - f)
            }
        })
    }

    /// The length of the path parameter of a move without X/Y/Z motion (LinuxCNC's canon):
    /// the Euclidean length of the U/V/W motion if they move, else that of the A/B/C motion
    /// (degrees). 0 when no auxiliary axis moves.
    pub fn length(&self) -> f64 {
        let d = self.delta();
        let uvw = d[3].hypot(d[4]).hypot(d[5]);
        if uvw > 0.0 {
            uvw
        } else {
            d[0].hypot(d[1]).hypot(d[2])
        }
    }

    /// Whether the move is rotary only (A/B/C move, U/V/W do not): then, without X/Y/Z
    /// motion, the feed is in degrees per minute.
    pub fn rotary_only(&self) -> bool {
        let d = self.delta();
        d[3] == 0.0 && d[4] == 0.0 && d[5] == 0.0 && (d[0] != 0.0 || d[1] != 0.0 || d[2] != 0.0)
    }
}

/// Two arc end points closer than this (in the arc's plane) make a full circle.
pub const FULL_CIRCLE_EPS_MM: f64 = 1e-7;

/// The working plane of arcs and cutter compensation (G17, G18, G19).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Plane {
    /// G17: the XY plane, arcs about +Z.
    Xy,
    /// G18: the ZX plane, arcs about +Y (first axis Z, second X, as in RS274/NGC).
    Zx,
    /// G19: the YZ plane, arcs about +X.
    Yz,
}

impl Plane {
    /// Indices (0 = X, 1 = Y, 2 = Z) of the plane's first axis, second axis and normal axis,
    /// ordered so that `first × second = normal`.
    pub fn axes(self) -> (usize, usize, usize) {
        match self {
            Plane::Xy => (0, 1, 2),
            Plane::Zx => (2, 0, 1),
            Plane::Yz => (1, 2, 0),
        }
    }

    /// The G code that selects the plane.
    pub fn code(self) -> &'static str {
        match self {
            Plane::Xy => "G17",
            Plane::Zx => "G18",
            Plane::Yz => "G19",
        }
    }
}

/// How the path may pass the end of an element (the G61/G61.1/G64 mode in force for it).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum BlendMode {
    /// G61: exact path; the corner is followed exactly (the planner may keep some speed only
    /// where the path is tangent).
    ExactPath,
    /// G61.1: exact stop; the machine comes to rest at the element's end.
    ExactStop,
    /// G64: blending allowed, within the tolerances.
    Blend {
        /// P: largest deviation from the programmed corner, where the planner may round a
        /// corner (between lines and plane arcs) with a tangent arc; 0 keeps every corner
        /// exact. A G64
        /// without P gives infinity, LinuxCNC's "no limit", which the planner caps at the
        /// machine's `default_tolerance_mm` (jerk-limited mode) or keeps exact (trapezoids).
        p_mm: f64,
        /// Q: naive-CAM tolerance (collinear short segments within it may be merged); 0
        /// disables the detector. Without Q it equals P, as in LinuxCNC.
        q_mm: f64,
    },
}

/// Cutter radius compensation in force for an element (G40/G41/G42/G41.1/G42.1). Recorded
/// here; the offset itself is computed by the compensation stage.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum CompState {
    /// G40: no compensation.
    Off,
    /// G41 / G41.1: the tool is left of the path, looking along the direction of travel.
    Left {
        /// Tool whose radius is used (`None` for G41.1, which gives the diameter directly).
        tool: Option<u32>,
        /// Tool radius.
        radius_mm: f64,
    },
    /// G42 / G42.1: the tool is right of the path.
    Right {
        /// Tool whose radius is used (`None` for G42.1).
        tool: Option<u32>,
        /// Tool radius.
        radius_mm: f64,
    },
}

/// The shape of an element.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ElementKind {
    /// A straight line from `start_mm` to `end_mm`.
    Line,
    /// A circular arc or a helix (G2/G3).
    Arc {
        /// Centre, in the plane of the start point (`(center − start) · normal = 0`).
        center_mm: Vector3<f64>,
        /// Unit vector about which the motion turns counter-clockwise (right-hand rule): the
        /// plane's axis for G3 and its opposite for G2, so `+Z` for G3 in G17 and `−Z` for G2.
        normal: Vector3<f64>,
        /// G2 (clockwise seen from the positive end of the plane's axis); redundant with the
        /// sign of `normal`, kept for readers of the path.
        cw: bool,
        /// Extra full turns before reaching the end (`P` − 1).
        turns: u32,
        /// Radius at the start (the end may differ by up to the arc tolerance: the path
        /// then spirals between the two radii, as LinuxCNC does).
        radius_mm: f64,
    },
}

/// One motion element, in machine millimetres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Element {
    /// 1-based source line.
    pub line: usize,
    /// 1-based column of the word that made the move (its motion code, or the first axis
    /// word under a modal motion).
    pub col: usize,
    /// Line or arc.
    pub kind: ElementKind,
    /// G0 (and the moves of G28/G30): at the machine's rapid speed, no feed.
    pub rapid: bool,
    /// Where it starts: the previous element's `end_mm`, bit for bit.
    pub start_mm: Vector3<f64>,
    /// Where it ends.
    pub end_mm: Vector3<f64>,
    /// The auxiliary axes (A B C U V W) over the element, linear in the path parameter.
    pub aux: AuxMove,
    /// Path feed, in units of the path parameter ([`Element::length_mm`]) per second: mm/s
    /// with X/Y/Z motion, else mm/s of U/V/W, else deg/s of A/B/C; `None` for rapids. Under
    /// G93 (inverse time) it is the element's length divided by the programmed time.
    pub feed_mm_s: Option<f64>,
    /// The blending mode in force.
    pub blend: BlendMode,
    /// The cutter compensation in force.
    pub comp: CompState,
    /// The working plane in force (arcs lie in it; compensation offsets in it).
    pub plane: Plane,
}

impl Element {
    /// The circle or helix of an arc; `None` for a line or a degenerate arc (zero radius).
    pub fn arc(&self) -> Option<ArcGeometry> {
        match self.kind {
            ElementKind::Line => None,
            ElementKind::Arc {
                center_mm,
                normal,
                turns,
                ..
            } => ArcGeometry::new(self.start_mm, self.end_mm, center_mm, normal, turns),
        }
    }

    /// Path length: the straight distance, or the arc (helix) length. A line without X/Y/Z
    /// motion takes the length of its auxiliary axes' motion ([`AuxMove::length`]; degrees
    /// for a rotary-only move), as LinuxCNC's canon does for the feed.
    pub fn length_mm(&self) -> f64 {
        match self.arc() {
            Some(arc) => arc.length_mm,
            None => {
                let xyz = (self.end_mm - self.start_mm).norm();
                if xyz > 0.0 { xyz } else { self.aux.length() }
            }
        }
    }

    /// Smallest box holding the whole element (for travel checks): an arc can leave the box of
    /// its end points.
    pub fn bounds_mm(&self) -> (Vector3<f64>, Vector3<f64>) {
        let mut lo = self.start_mm.inf(&self.end_mm);
        let mut hi = self.start_mm.sup(&self.end_mm);
        if let Some(arc) = self.arc() {
            let r_max = arc.start_radius_mm.max(arc.end_radius_mm);
            for i in 0..3 {
                // Circle part: c_i + r (cos θ u_i + sin θ v_i), extreme at θ = atan2(v_i, u_i)
                // (+π for the minimum), if the sweep reaches it.
                let amp = arc.u[i].hypot(arc.v[i]);
                if amp > 0.0 {
                    let peak = arc.v[i].atan2(arc.u[i]).rem_euclid(TAU);
                    let helix_lo = (arc.helix_mm * arc.normal[i]).min(0.0);
                    let helix_hi = (arc.helix_mm * arc.normal[i]).max(0.0);
                    if arc.sweep_rad >= peak {
                        hi[i] = hi[i].max(arc.center_mm[i] + r_max * amp + helix_hi);
                    }
                    if arc.sweep_rad >= (peak + PI).rem_euclid(TAU) {
                        lo[i] = lo[i].min(arc.center_mm[i] - r_max * amp + helix_lo);
                    }
                }
            }
        }
        (lo, hi)
    }
}

/// The geometry of an arc element, derived once from its end points, centre and normal.
///
/// Point at fraction `s ∈ [0, 1]` of the way:
/// `center + r(s) (cos(s·sweep) u + sin(s·sweep) v) + s·helix·normal`, with the radius going
/// linearly from the start radius to the end radius.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ArcGeometry {
    /// Centre, in the plane of the start point.
    pub center_mm: Vector3<f64>,
    /// Unit axis; the motion turns counter-clockwise about it.
    pub normal: Vector3<f64>,
    /// Unit vector from the centre towards the start, in the plane.
    pub u: Vector3<f64>,
    /// `normal × u`: the direction of travel at the start (in the plane).
    pub v: Vector3<f64>,
    /// Distance from the centre to the start, in the plane; > 0.
    pub start_radius_mm: f64,
    /// Distance from the centre to the end, in the plane.
    pub end_radius_mm: f64,
    /// Angle turned, extra full turns included; in `(0, 2π (turns + 1)]`.
    pub sweep_rad: f64,
    /// Travel along the normal from start to end (the helix's rise; 0 for a plane arc).
    pub helix_mm: f64,
    /// Path length (helix length with the mean radius).
    pub length_mm: f64,
}

impl ArcGeometry {
    /// The geometry of the arc from `start_mm` to `end_mm` about `center_mm`, turning
    /// counter-clockwise about `normal` (any length), with `turns` extra full turns. `None`
    /// when the start is on the axis or a value is not finite.
    pub fn new(
        start_mm: Vector3<f64>,
        end_mm: Vector3<f64>,
        center_mm: Vector3<f64>,
        normal: Vector3<f64>,
        turns: u32,
    ) -> Option<ArcGeometry> {
        let n_len = normal.norm();
        if !(n_len.is_finite() && n_len > 0.0) {
            return None;
        }
        let normal = normal / n_len;
        let d0 = start_mm - center_mm;
        let d0p = d0 - normal * d0.dot(&normal);
        let start_radius_mm = d0p.norm();
        if !(start_radius_mm.is_finite() && start_radius_mm > 0.0) {
            return None;
        }
        let u = d0p / start_radius_mm;
        let v = normal.cross(&u);
        let d1 = end_mm - center_mm;
        let d1p = d1 - normal * d1.dot(&normal);
        let end_radius_mm = d1p.norm();
        let chord = d1p - d0p;
        let mut angle = d1p.dot(&v).atan2(d1p.dot(&u));
        if angle < 0.0 {
            angle += TAU;
        }
        if chord.norm() <= FULL_CIRCLE_EPS_MM || angle <= 0.0 {
            angle = TAU;
        }
        let sweep_rad = angle + TAU * f64::from(turns);
        let helix_mm = (end_mm - start_mm).dot(&normal);
        let planar_mm = sweep_rad * 0.5 * (start_radius_mm + end_radius_mm);
        let length_mm = planar_mm.hypot(helix_mm);
        let all_finite = [end_radius_mm, sweep_rad, helix_mm, length_mm]
            .iter()
            .all(|x| x.is_finite());
        all_finite.then_some(ArcGeometry {
            center_mm,
            normal,
            u,
            v,
            start_radius_mm,
            end_radius_mm,
            sweep_rad,
            helix_mm,
            length_mm,
        })
    }

    /// Point at fraction `s` of the way (0 = start, 1 = end; not clamped).
    pub fn point_at(&self, s: f64) -> Vector3<f64> {
        let theta = s * self.sweep_rad;
        let r = self.start_radius_mm + s * (self.end_radius_mm - self.start_radius_mm);
        let (sin, cos) = theta.sin_cos();
        self.center_mm + (self.u * cos + self.v * sin) * r + self.normal * (s * self.helix_mm)
    }

    /// Unit tangent (direction of travel) at fraction `s`.
    pub fn tangent_at(&self, s: f64) -> Vector3<f64> {
        let theta = s * self.sweep_rad;
        let r = self.start_radius_mm + s * (self.end_radius_mm - self.start_radius_mm);
        let (sin, cos) = theta.sin_cos();
        let t = (self.v * cos - self.u * sin) * (r * self.sweep_rad)
            + (self.u * cos + self.v * sin) * (self.end_radius_mm - self.start_radius_mm)
            + self.normal * self.helix_mm;
        let n = t.norm();
        if n > 0.0 { t / n } else { self.v }
    }

    /// Sine of the helix angle: the share of the path along the normal (0 for a plane arc).
    pub fn helix_sin(&self) -> f64 {
        if self.length_mm > 0.0 {
            (self.helix_mm.abs() / self.length_mm).min(1.0)
        } else {
            0.0
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn v(x: f64, y: f64, z: f64) -> Vector3<f64> {
        Vector3::new(x, y, z)
    }

    fn close(a: Vector3<f64>, b: Vector3<f64>) -> bool {
        (a - b).norm() < 1e-9
    }

    #[test]
    fn quarter_circle_ccw_and_cw() {
        let g = ArcGeometry::new(
            v(10.0, 0.0, 0.0),
            v(0.0, 10.0, 0.0),
            v(0.0, 0.0, 0.0),
            v(0.0, 0.0, 1.0),
            0,
        )
        .unwrap();
        assert!((g.sweep_rad - PI / 2.0).abs() < 1e-12);
        assert!((g.length_mm - 5.0 * PI).abs() < 1e-12);
        assert!(close(
            g.point_at(0.5),
            v(10.0 / 2f64.sqrt(), 10.0 / 2f64.sqrt(), 0.0)
        ));
        assert!(close(g.tangent_at(0.0), v(0.0, 1.0, 0.0)));
        // The same end points clockwise: three quarters.
        let g = ArcGeometry::new(
            v(10.0, 0.0, 0.0),
            v(0.0, 10.0, 0.0),
            v(0.0, 0.0, 0.0),
            v(0.0, 0.0, -1.0),
            0,
        )
        .unwrap();
        assert!((g.sweep_rad - 1.5 * PI).abs() < 1e-12);
        assert!(close(g.point_at(1.0 / 3.0), v(0.0, -10.0, 0.0)));
    }

    #[test]
    fn full_circle_turns_and_helix() {
        let g = ArcGeometry::new(
            v(1.0, 0.0, 0.0),
            v(1.0, 0.0, 3.0),
            Vector3::zeros(),
            v(0.0, 0.0, 1.0),
            2,
        )
        .unwrap();
        assert!((g.sweep_rad - 3.0 * TAU).abs() < 1e-12);
        assert_eq!(g.helix_mm, 3.0);
        assert!((g.length_mm - (3.0 * TAU).hypot(3.0)).abs() < 1e-12);
        assert!(close(g.point_at(1.0 / 3.0), v(1.0, 0.0, 1.0)));
        assert!(close(g.point_at(1.0), v(1.0, 0.0, 3.0)));
    }

    #[test]
    fn degenerate_arcs_have_no_geometry() {
        assert!(
            ArcGeometry::new(
                Vector3::zeros(),
                v(1.0, 0.0, 0.0),
                Vector3::zeros(),
                v(0.0, 0.0, 1.0),
                0
            )
            .is_none()
        );
        assert!(
            ArcGeometry::new(
                v(1.0, 0.0, 0.0),
                v(1.0, 0.0, 0.0),
                Vector3::zeros(),
                Vector3::zeros(),
                0
            )
            .is_none()
        );
    }

    #[test]
    fn arc_bounds_include_the_bulge() {
        // Semicircle from (10,0) to (-10,0) counter-clockwise over +Y: reaches y = 10.
        let e = Element {
            line: 1,
            col: 1,
            kind: ElementKind::Arc {
                center_mm: Vector3::zeros(),
                normal: v(0.0, 0.0, 1.0),
                cw: false,
                turns: 0,
                radius_mm: 10.0,
            },
            rapid: false,
            start_mm: v(10.0, 0.0, 0.0),
            end_mm: v(-10.0, 0.0, 0.0),
            aux: AuxMove::default(),
            feed_mm_s: Some(1.0),
            blend: BlendMode::ExactStop,
            comp: CompState::Off,
            plane: Plane::Xy,
        };
        let (lo, hi) = e.bounds_mm();
        assert!(close(lo, v(-10.0, 0.0, 0.0)), "{lo}");
        assert!(close(hi, v(10.0, 10.0, 0.0)), "{hi}");
    }
}
