//! Corner blends under G64 P: the tangent arc that replaces a sharp corner within the
//! tolerance (`shared/seeds` 001), where it is faster than the corner, between any two of
//! lines and plane arcs (line–line, line–arc, arc–line, arc–arc, as LinuxCNC's blendmath.c).
//!
//! Between two lines the arc has a closed form ([`Planner::blend_arc`]). Where an arc takes
//! part ([`Corner`]), the blend circle of radius `ρ` touches both elements on the corner's
//! inside: its centre lies at `ρ` from a line and at `R − ρ` from an arc's centre where the
//! blend lies inside the arc's circle (the arc turns the way the corner does), `R + ρ` where it
//! lies outside; so it is the intersection of an offset line and an offset circle (a quadratic)
//! or of two offset circles. Of the solutions, the one nearest the corner whose tangent points
//! lie on the elements near the corner, with the direction of travel. Its deviation is the
//! largest distance of the blend from the pieces of the path it replaces (at least
//! `|corner − c_b| − ρ`, where it passes nearest the corner); `ρ` is the one of a grid of radii
//! (independent of the tolerance) within the tolerance and the room (the radii from 0 up,
//! where both grow with `ρ`) that the estimate of the corner's time ([`CornerCost`]) says is
//! fastest, if faster than the sharp corner. The
//! arcs are trimmed to the tangent points: the same centre, normal and direction, rebuilt with
//! `Planner::arc_pending` (their limits depend on the radius, not on the sweep, so they stay).
//! A blend is taken only where the plan can still follow it from its settled speeds
//! (`Planner::still_reachable`).
//!
//! Helices (an arc whose end rises along its normal) and elements not in one plane keep their
//! corners sharp: a planar blend would leave the helix by its rise over the blend's span, and
//! the trimmed helix would no longer meet the blend; so would arcs with extra full turns
//! whose trimming crosses a turn (checked), and arcs whose auxiliary axes move
//! (`aux_axes::keeps_corner`), as lines.

#[cfg(test)]
use std::f64::consts::PI;
use std::f64::consts::{FRAC_PI_2, TAU};

use super::*;

/// A corner's blend arc ([`Planner::blend_arc`]).
pub(super) struct Blend {
    pub(super) arc: Pending,
    /// The elements either side as the blend leaves them: `a` ends and `b` starts where the
    /// arc touches them (a line shortened, an arc trimmed).
    a: Pending,
    b: Pending,
    /// Highest speeds where the arc begins and ends (`Planner::junction_caps`).
    pub(super) cap_in: (f64, f64),
    pub(super) cap_out: (f64, f64),
}

impl Blend {
    /// Ends `prev` (the element before the corner) and starts `next` (the one after it) where
    /// the blend arc touches them; their limits stay (an arc's depend on its radius, not on
    /// its sweep) and so does their programmed length (`full_length_mm`).
    pub(super) fn trim(&self, prev: &mut Pending, next: &mut Pending) {
        prev.seg.end_mm = self.a.seg.end_mm;
        prev.seg.path = self.a.seg.path;
        prev.seg.length_mm = self.a.seg.length_mm;
        prev.tangent_end = self.a.tangent_end;
        prev.curvature_end = self.a.curvature_end;
        next.seg.start_mm = self.b.seg.start_mm;
        next.seg.path = self.b.seg.path;
        next.seg.length_mm = self.b.seg.length_mm;
        next.tangent_start = self.b.tangent_start;
        next.curvature_start = self.b.curvature_start;
    }
}

impl Planner {
    /// The tangent arc that replaces the corner from `a` into `b` under G64 P, or `None`
    /// where the corner stays sharp: no tolerance (P0), auxiliary axes moving, no turn, not in
    /// one plane (helices), two pieces of a refined chord, or an arc no faster than the sharp
    /// corner. Two lines:
    /// [`blend_lines`](Self::blend_lines); an arc on either side:
    /// [`blend_curves`](Self::blend_curves).
    pub(super) fn blend_arc(
        &self,
        a: &Pending,
        b: &Pending,
    ) -> Result<Option<Box<Blend>>, PlanError> {
        let BlendMode::Blend { .. } = a.blend else {
            return Ok(None);
        };
        if aux_axes::keeps_corner(a, b) || a.is_blend_arc || b.is_blend_arc {
            return Ok(None);
        }
        if a.refined && b.refined {
            // Two pieces of a refined chord ([`super::refine`]) lie on its curvature-continuous
            // curve and turn by that curve's own turn: a chord run taken as a curve
            // ([`super::curve`]). A tangent arc between them would step the curvature from 0
            // to `1/r` and back at every piece, each step a junction of its own (3D_Chips.ngc:
            // 187 s with them, 165 s without; LHchips4.ngc 649 s, 548 s).
            return Ok(None);
        }
        let blend = match (a.seg.path, b.seg.path) {
            (SegmentPath::Line { .. }, SegmentPath::Line { .. }) => self.blend_lines(a, b)?,
            (
                SegmentPath::Line { .. } | SegmentPath::Arc(_),
                SegmentPath::Line { .. } | SegmentPath::Arc(_),
            ) => self.blend_curves(a, b),
            _ => None,
        };
        Ok(blend.filter(|blend| self.still_reachable(blend)))
    }

    /// Whether the plan can still follow `blend` from where it stands. The window's first
    /// element starts at the settled speed, which the plan chose so that the window could
    /// stop at its end; the blend shortens `a` (the window's last element), so the backward
    /// bound is walked again from `b`'s end, through the arc and `a` shortened (with the
    /// accelerations they will share in the jerk-limited mode, as `Planner::push` shares
    /// them), back to the first element, or to a junction whose own cap binds (the bound there
    /// cannot have dropped, so nothing before it changes).
    fn still_reachable(&self, blend: &Blend) -> bool {
        let n = self.window.len();
        let (mut a, mut arc, mut b) = (blend.a, blend.arc, blend.b);
        if self.smoothing.is_some() {
            if blend.cap_in.0 > 0.0 {
                share_acceleration(&mut a, &mut arc);
            }
            if blend.cap_out.0 > 0.0 {
                share_acceleration(&mut arc, &mut b);
            }
        }
        let v_settled = self.v_settled_mm_s;
        let cap = |j: usize, p: &Pending| {
            if j == 0 { v_settled } else { p.cap_start_mm_s }
        };
        let v_b = start_reach_mm_s(b.seg.length_mm, 0.0, blend.cap_out.0, &b.limits);
        let mut v = start_reach_mm_s(arc.seg.length_mm, v_b, blend.cap_in.0, &arc.limits);
        for j in (0..n).rev() {
            let p = if j + 1 == n { &a } else { &self.window[j] };
            let cap_j = cap(j, p);
            v = start_reach_mm_s(p.seg.length_mm, v, cap_j, &p.limits);
            if j == 0 {
                return v >= v_settled;
            }
            if v >= cap_j {
                return true;
            }
        }
        true
    }

    /// The tangent arc that replaces the corner from line `a` into line `b` under G64 P
    /// (`shared/seeds` 001), or `None` where the corner stays sharp: no tolerance (P0), no
    /// turn, or an arc no faster than the sharp corner's one-period junction speed.
    ///
    /// With the turn angle `θ` (the interior angle is `θ' = π − θ`), an arc of radius `r`
    /// touches both lines at `r·tan(θ/2)` from the corner and passes `r/cos(θ/2) − r` from it,
    /// so the tolerance `δ` allows `r ≤ δ·cos(θ/2)/(1 − cos(θ/2))` (001's
    /// `r = δ sin(θ'/2)/(1 − sin(θ'/2))`), and each line gives at most half of its programmed
    /// length (it may be blended at both ends). Within those bounds the radius is the smallest
    /// that lets the arc reach the speed of its neighbours (a larger one would deviate more for
    /// nothing): the centripetal limit grows as `√r`, the jerk of circular motion as `r^⅔`, so
    /// `r_need = r_max · (v_target/v_arc(r_max))^1.5`. On the arc every axis's centripetal
    /// acceleration and jerk stay within its share ([`arc_limits`]).
    fn blend_lines(&self, a: &Pending, b: &Pending) -> Result<Option<Box<Blend>>, PlanError> {
        let tol_mm = self.blend_tolerance_mm(a.blend);
        let (SegmentPath::Line { direction: u1 }, SegmentPath::Line { direction: u2 }) =
            (a.seg.path, b.seg.path)
        else {
            return Ok(None);
        };
        if tol_mm.is_nan() || tol_mm <= 0.0 || self.config.corner_acc_mm_s2 == 0.0 {
            return Ok(None);
        }
        let cos_turn = u1.dot(&u2).clamp(-1.0, 1.0);
        let half = 0.5 * cos_turn.acos();
        let (sin_h, cos_h) = half.sin_cos();
        // Nearly straight on (nothing to gain) or nearly a reversal (no room for an arc).
        if sin_h < 1e-6 || cos_h < 1e-3 {
            return Ok(None);
        }
        let tan_h = sin_h / cos_h;
        let tol_mm = if self.smoothing.is_some() {
            0.5 * tol_mm
        } else {
            tol_mm
        };
        let r_tol = tol_mm * cos_h / (1.0 - cos_h);
        let room_mm = 0.5 * a.full_length_mm.min(b.full_length_mm);
        // What is left of `a` after a blend at its start must keep some length.
        let room_mm = room_mm.min(a.seg.length_mm - 1e-9 * a.full_length_mm);
        let r_max = r_tol.min(room_mm / tan_h);
        if !(r_max > 0.0 && r_max.is_finite()) {
            return Ok(None);
        }
        let corner = a.seg.end_mm;
        let normal = u1.cross(&u2);
        let line = b.seg.line;
        let rapid = a.seg.rapid && b.seg.rapid;
        let feed_mm_s = a.limits.v_max_mm_s().min(b.limits.v_max_mm_s());
        // An arc runs at most at the feed: where the sharp corner already does, nothing to gain
        // (and no arc to build, on a path of tiny segments).
        let v_sharp = self.junction_mm_s(a, b);
        if v_sharp >= feed_mm_s {
            return Ok(None);
        }
        let arc_at = |r: f64| -> Result<Option<(Pending, f64)>, PlanError> {
            let tangent_mm = r * tan_h;
            let p1 = corner - u1 * tangent_mm;
            let p2 = corner + u2 * tangent_mm;
            let center = corner + (u2 - u1).normalize() * (r / cos_h);
            let Some(geometry) = ArcGeometry::new(p1, p2, center, normal, 0) else {
                return Ok(None);
            };
            let arc = self.arc_pending(
                line,
                rapid,
                (p1, p2),
                geometry,
                feed_mm_s,
                a.blend,
                &AuxMove::default(),
                false,
            )?;
            Ok(Some((arc, tangent_mm)))
        };
        let Some((mut arc, mut tangent_mm)) = arc_at(r_max)? else {
            return Ok(None);
        };
        let v_arc = arc.limits.v_max_mm_s();
        if v_arc > feed_mm_s {
            let r = r_max * (feed_mm_s / v_arc).powf(1.5);
            if let Some(smaller) = arc_at(r)? {
                (arc, tangent_mm) = smaller;
            }
        }
        arc.is_blend_arc = true;
        // The speeds into and out of the arc: tangent, so only its curvature (S-curves) and
        // the neighbours' limits bound them.
        let cap_in = self.junction_caps(a, &arc);
        let cap_out = self.junction_caps(&arc, b);
        let v_blend = arc.limits.v_max_mm_s().min(cap_in.0).min(cap_out.0);
        // Round the corner only where it is faster: the arc is run at a constant speed, which
        // the chord tolerance and the centripetal limit may keep low, so a small arc can take
        // longer than slowing down for the sharp corner (see `corner_cost_s`). Line–line
        // corners keep this rule rather than `CornerCost`'s (arc blends): choosing them by
        // `CornerCost` lost up to 3 % on line programs of the corpus in the jerk-limited mode
        // and changed which corners the smoothed junction rules meet, one of which then
        // broke a jerk limit on `performance/3D_Chips.ngc`.
        let (acc, jerk) = (
            a.limits.a_max_mm_s2().min(b.limits.a_max_mm_s2()),
            a.limits.j_max_mm_s3().min(b.limits.j_max_mm_s3()),
        );
        let room = a.full_length_mm.min(b.full_length_mm);
        let v_cruise = feed_mm_s.min((v_sharp * v_sharp + acc * room).sqrt());
        let blended = corner_cost_s(v_cruise, v_blend, acc, jerk) + arc.seg.length_mm / v_blend
            - 2.0 * tangent_mm / v_cruise;
        if !(v_blend > v_sharp && blended < corner_cost_s(v_cruise, v_sharp, acc, jerk)) {
            return Ok(None);
        }
        let (mut a_after, mut b_after) = (*a, *b);
        a_after.seg.end_mm = arc.seg.start_mm;
        a_after.seg.length_mm -= tangent_mm;
        b_after.seg.start_mm = arc.seg.end_mm;
        b_after.seg.length_mm -= tangent_mm;
        Ok(Some(Box::new(Blend {
            arc,
            a: a_after,
            b: b_after,
            cap_in,
            cap_out,
        })))
    }

    /// The speed through the corner from `a` into `b` left sharp, as the plan would pass it:
    /// with a programmed arc's use of the axes at that speed ([`Planner::cap_at_speed`]),
    /// though the blend's own caps are chosen with the uses at the caps its estimate was
    /// made for (`steps_at_caps`). A blend is taken only where faster than that corner.
    fn sharp_corner_mm_s(&self, a: &Pending, b: &Pending) -> f64 {
        let at_caps = self.steps_at_caps.replace(false);
        let v = self.junction_mm_s(a, b);
        self.steps_at_caps.set(at_caps);
        v
    }

    /// The blend of a corner where an arc takes part (see the module documentation), or
    /// `None` where the corner stays sharp. Errors building the arcs (none are expected: their
    /// lengths are positive and finite) keep the corner sharp too.
    fn blend_curves(&self, a: &Pending, b: &Pending) -> Option<Box<Blend>> {
        let tol_mm = self.blend_tolerance_mm(a.blend);
        if tol_mm.is_nan() || tol_mm <= 0.0 || self.config.corner_acc_mm_s2 == 0.0 {
            return None;
        }
        // The jerk-limited mode's axis filters take the other half.
        let tol_mm = if self.smoothing.is_some() {
            0.5 * tol_mm
        } else {
            tol_mm
        };
        let (ca, room_a, spiral_a) = curve_near(a, true)?;
        let (cb, room_b, spiral_b) = curve_near(b, false)?;
        // A spiral arc (end radius off its start radius) is blended as the circle of its radius
        // at the corner; the trimmed spiral then strays from the programmed one by at most the
        // radius change, which the tolerance pays for.
        let tol_mm = tol_mm - spiral_a - spiral_b;
        let corner_mm = a.seg.end_mm;
        let corner = Corner::new(corner_mm, (ca, room_a), (cb, room_b))?;
        let feed_mm_s = a.limits.v_max_mm_s().min(b.limits.v_max_mm_s());
        let v_sharp = self.sharp_corner_mm_s(a, b);
        if v_sharp >= feed_mm_s {
            return None;
        }
        let top = corner.grid_top(tol_mm)?;
        let cost = CornerCost::new(self, a, b, v_sharp);
        // The radius: of a grid that does not depend on the tolerance (ratio 2^¼), the one
        // the estimate says is fastest (the arc's speed comes from its radius, but it runs at
        // the slower side's feed and takes more of both sides as it grows). A larger
        // tolerance only adds candidates, so the estimate's choice never gets worse as P
        // grows. The largest radius within the tolerance, off the grid, was a candidate too
        // until session 24: a larger P lost the smaller P's, and a jerk-limited plan was 2.6 %
        // slower at P0.03 than at P0.02 (`tests/blends.rs`).
        let candidates = (0..=top).rev().map(|k| corner.grid_radius_mm(k));
        let mut best: Option<(f64, Box<Blend>)> = None;
        for rho in candidates {
            let Some(circle) = corner.within(rho, tol_mm) else {
                continue;
            };
            let Some((arc, a_after, b_after)) = self.blend_pieces(a, b, &circle, feed_mm_s) else {
                continue;
            };
            // The junction caps as between two lines: a line with its programmed length (its
            // caps are computed before it is shortened, `Planner::shortest_mm`), an arc as
            // trimmed (its tangent at the new end differs).
            let line = |p: &Pending| matches!(p.seg.path, SegmentPath::Line { .. });
            let cap_a = if line(a) { *a } else { a_after };
            let cap_b = if line(b) { *b } else { b_after };
            let cap_in = self.junction_caps(&cap_a, &arc);
            let cap_out = self.junction_caps(&arc, &cap_b);
            let v_blend = arc.limits.v_max_mm_s().min(cap_in.0).min(cap_out.0);
            if v_blend.is_nan() || v_blend <= v_sharp {
                continue;
            }
            let cost_s = cost.blended_s(
                &arc,
                (cap_in.0, cap_out.0),
                (circle.taken_a_mm, circle.taken_b_mm),
            );
            if best.as_ref().is_none_or(|(c, _)| cost_s < *c) {
                let blend = Box::new(Blend {
                    arc,
                    a: a_after,
                    b: b_after,
                    cap_in,
                    cap_out,
                });
                best = Some((cost_s, blend));
            }
        }
        // Only where faster than the sharp corner (`blend_lines`).
        best.filter(|(cost_s, _)| *cost_s < cost.sharp_s)
            .map(|(_, blend)| blend)
    }

    /// The blend arc along `circle`, and `a` and `b` as it leaves them.
    fn blend_pieces(
        &self,
        a: &Pending,
        b: &Pending,
        circle: &TangentCircle,
        feed_mm_s: f64,
    ) -> Option<(Pending, Pending, Pending)> {
        let (p1, p2) = (circle.p1_mm, circle.p2_mm);
        let geometry = ArcGeometry::new(p1, p2, circle.center_mm, circle.normal, 0)?;
        // Its sweep as the chord says (well conditioned), and never shorter than the chord.
        let chord_mm = (p2 - p1).norm();
        let arc_chord_mm = 2.0 * circle.radius_mm * (0.5 * geometry.sweep_rad).sin();
        if (geometry.sweep_rad - circle.sweep_rad).abs() > 1e-6
            || (arc_chord_mm - chord_mm).abs() > 1e-9 * (1.0 + chord_mm)
            || chord_mm > geometry.length_mm
        {
            return None;
        }
        let rapid = a.seg.rapid && b.seg.rapid;
        let mut arc = self
            .arc_pending(
                b.seg.line,
                rapid,
                (p1, p2),
                geometry,
                feed_mm_s,
                a.blend,
                &AuxMove::default(),
                false,
            )
            .ok()?;
        arc.is_blend_arc = true;
        let a_after = self.trimmed(a, p1, circle.taken_a_mm, circle.taken_a, true)?;
        let b_after = self.trimmed(b, p2, circle.taken_b_mm, circle.taken_b, false)?;
        let keeps_length = |p: &Pending| p.seg.length_mm > 1e-9 * p.full_length_mm;
        (keeps_length(&a_after) && keeps_length(&b_after)).then_some((arc, a_after, b_after))
    }

    /// `p` as a blend leaves it: trimmed at its end (`at_end`) or at its start to `at_mm`, a
    /// line by `taken_mm`, an arc by `taken_rad` of its sweep.
    fn trimmed(
        &self,
        p: &Pending,
        at_mm: Vector3<f64>,
        taken_mm: f64,
        taken_rad: f64,
        at_end: bool,
    ) -> Option<Pending> {
        let mut after = *p;
        let ends = if at_end {
            (p.seg.start_mm, at_mm)
        } else {
            (at_mm, p.seg.end_mm)
        };
        match p.seg.path {
            SegmentPath::Line { .. } => after.seg.length_mm -= taken_mm,
            SegmentPath::Arc(g) => {
                let trimmed = trimmed_arc(ends, &g, g.sweep_rad - taken_rad)?;
                let rebuilt = self.rebuilt_arc(p, ends, trimmed)?;
                after.seg.path = rebuilt.seg.path;
                after.seg.length_mm = rebuilt.seg.length_mm;
                if at_end {
                    after.tangent_end = rebuilt.tangent_end;
                    after.curvature_end = rebuilt.curvature_end;
                } else {
                    after.tangent_start = rebuilt.tangent_start;
                    after.curvature_start = rebuilt.curvature_start;
                }
            }
            _ => return None,
        }
        (after.seg.start_mm, after.seg.end_mm) = ends;
        Some(after)
    }

    /// `p`'s arc rebuilt on the trimmed geometry (`Planner::arc_pending`, so every arc limit
    /// follows the shorter arc), with no motion of the auxiliary axes (a blended corner has
    /// none).
    fn rebuilt_arc(
        &self,
        p: &Pending,
        ends: (Vector3<f64>, Vector3<f64>),
        geometry: ArcGeometry,
    ) -> Option<Pending> {
        self.arc_pending(
            p.seg.line,
            p.seg.rapid,
            ends,
            geometry,
            p.limits.v_max_mm_s(),
            p.blend,
            &AuxMove::still(p.seg.aux.end),
            !p.is_blend_arc,
        )
        .ok()
    }
}

/// The curve of `p` near its end (`at_end`) or its start, how much of it a blend there may
/// take (half its programmed length, a length on a line; on an arc the same share of its
/// sweep, at most a quarter turn, and never all of what is left), and how far a spiral arc's
/// radius strays from the circle's; `None` for a helix, a blend arc, or no motion.
fn curve_near(p: &Pending, at_end: bool) -> Option<(Curve, f64, f64)> {
    if p.is_blend_arc {
        return None;
    }
    let left = 1.0 - 1e-9;
    match p.seg.path {
        SegmentPath::Line { direction } => {
            let room = (0.5 * p.full_length_mm).min(p.seg.length_mm * left);
            (direction.norm() > 0.5 && room > 0.0).then_some((
                Curve::Line { dir: direction },
                room,
                0.0,
            ))
        }
        SegmentPath::Arc(g) => {
            // A helix keeps its corners (see the module documentation).
            if g.helix_mm != 0.0 || g.length_mm <= 0.0 {
                return None;
            }
            let mm_per_rad = g.length_mm / g.sweep_rad;
            let room = (0.5 * p.full_length_mm / mm_per_rad)
                .min(g.sweep_rad * left)
                .min(FRAC_PI_2);
            let radius_mm = if at_end {
                g.end_radius_mm
            } else {
                g.start_radius_mm
            };
            let curve = Curve::Circle {
                center_mm: g.center_mm,
                radius_mm,
                normal: g.normal,
            };
            Some((curve, room, (g.end_radius_mm - g.start_radius_mm).abs()))
        }
        _ => None,
    }
}

/// The arc of `arc`'s circle (centre, normal, direction) between `ends`, turning by `sweep_rad`
/// (full turns included), or `None` if the geometry does not come out so.
pub(super) fn trimmed_arc(
    (start_mm, end_mm): (Vector3<f64>, Vector3<f64>),
    arc: &ArcGeometry,
    sweep_rad: f64,
) -> Option<ArcGeometry> {
    if sweep_rad.is_nan() || sweep_rad <= 0.0 {
        return None;
    }
    let turns = (sweep_rad / TAU).floor();
    for t in [turns, turns - 1.0] {
        if !(t >= 0.0 && t < f64::from(u32::MAX)) {
            continue;
        }
        let g = ArcGeometry::new(start_mm, end_mm, arc.center_mm, arc.normal, t as u32)?;
        if (g.sweep_rad - sweep_rad).abs() <= 1e-6 * sweep_rad.max(1.0) {
            return Some(g);
        }
    }
    None
}

/// An estimate of the time a corner costs, sharp or blended, for choosing between them (the
/// profiles are planned exactly afterwards).
struct CornerCost {
    /// The speeds the elements reach near the corner, either side.
    pub(super) v_a: f64,
    pub(super) v_b: f64,
    /// The accelerations either side: each element's own in the trapezoid mode, the lower of
    /// the two under the time-law filter (joined elements share it, `share_acceleration`).
    acc: (f64, f64),
    /// The accelerations either side where the sharp corner stops in the jerk-limited mode
    /// (each move runs alone there, as an exact S-curve), the shared one where it does not;
    /// and the jerk.
    sharp_acc: (f64, f64),
    jerk: f64,
    /// Each element's acceleration away from the corner: under the time-law filter the shared
    /// one holds within the filter's reach of the corner only (`Planner::share_at_junction`
    /// splits a line there), the element's own beyond it, and the whole of its move alone
    /// (`J·T_f`) in the middle of a long speed change (`Planner::split_for_acceleration`).
    far: (f64, f64),
    /// The time-law filter's length (0 in the trapezoid mode).
    t_f: f64,
    /// What joining the two through the time-law filter costs (jerk-limited mode).
    joined_s: f64,
    /// The sharp corner's cost.
    sharp_s: f64,
    smoothing: bool,
}

impl CornerCost {
    /// The sharp corner from `a` into `b` at `v_sharp`: each side loses against cruising at
    /// the speed it reaches near the corner the time of one way of `corner_cost_s`.
    fn new(planner: &Planner, a: &Pending, b: &Pending, v_sharp: f64) -> CornerCost {
        let (acc_a, acc_b) = (a.limits.a_max_mm_s2(), b.limits.a_max_mm_s2());
        let lower = acc_a.min(acc_b);
        let acc = if planner.smoothing.is_some() {
            (lower, lower)
        } else {
            (acc_a, acc_b)
        };
        let jerk = a.limits.j_max_mm_s3().min(b.limits.j_max_mm_s3());
        let reach = |p: &Pending, acc: f64| {
            p.limits
                .v_max_mm_s()
                .min((v_sharp * v_sharp + acc * p.full_length_mm).sqrt())
        };
        // In the jerk-limited mode a corner that stops lets the moves either side run alone,
        // as exact S-curves without the time-law filter and with their higher acceleration;
        // joined by a blend they pass through it, which costs its settling time where the
        // motion stops next. Beyond that the filtered plan's dips and shared accelerations
        // make the estimate rougher there: a blend must save at least that settling time.
        let period_s = planner.config.period_s;
        let t_f = planner.smoothing.map_or(0.0, |s| s.time_law_s(period_s));
        let far_acc = |p: &Pending, own: f64| match super::split_acc_mm_s2(p, t_f) {
            Some(split) if t_f > 0.0 => own.max(split),
            _ => own,
        };
        let far = (far_acc(a, acc_a), far_acc(b, acc_b));
        let (joined_s, sharp_acc) = match planner.smoothing {
            Some(smoothing) if v_sharp == 0.0 => {
                let alone =
                    |p: &Pending, own: f64| p.alone.map_or(own, |x| own.max(x.a_max_mm_s2()));
                let sharp_acc = (alone(a, acc_a), alone(b, acc_b));
                (2.0 * smoothing.time_law_s(period_s), sharp_acc)
            }
            Some(smoothing) => (smoothing.time_law_s(period_s), (lower, lower)),
            None => (0.0, (lower, lower)),
        };
        let mut cost = CornerCost {
            v_a: reach(a, far.0),
            v_b: reach(b, far.1),
            acc,
            sharp_acc,
            jerk,
            far,
            t_f,
            joined_s,
            sharp_s: 0.0,
            smoothing: planner.smoothing.is_some(),
        };
        cost.sharp_s = if cost.smoothing && v_sharp == 0.0 {
            // (Alone: each move's whole profile at its own higher acceleration.)
            cost.corner_s((v_sharp, v_sharp), sharp_acc, sharp_acc)
        } else {
            cost.corner_s((v_sharp, v_sharp), acc, cost.far)
        };
        cost
    }

    /// The dips to `v.0` at the end of `a` and to `v.1` at the start of `b`, one way each, at
    /// the acceleration `near` within the time-law filter's reach of the corner and `far`
    /// beyond it.
    fn corner_s(&self, v: (f64, f64), near: (f64, f64), far: (f64, f64)) -> f64 {
        self.dip_s(self.v_a, v.0, near.0, far.0) + self.dip_s(self.v_b, v.1, near.1, far.1)
    }

    /// One way of a dip from `v_cruise` to `v` against cruising: the last part, within the
    /// reach `L = T_f·(a·T_f + √((a·T_f)² + v²))` of the corner
    /// (`Planner::share_at_junction`), at `near`, the rest at `far`.
    fn dip_s(&self, v_cruise: f64, v: f64, near: f64, far: f64) -> f64 {
        if self.t_f == 0.0 || near >= far {
            return 0.5 * corner_cost_s(v_cruise, v, near.min(far), self.jerk);
        }
        if v_cruise <= 0.0 || v >= v_cruise {
            return 0.0;
        }
        // The time lost from `u` down to `w` at `acc`, against cruising at `v_cruise`.
        let lost = |u: f64, w: f64, acc: f64| (u - w) / acc * (1.0 - (u + w) / (2.0 * v_cruise));
        let at = near * self.t_f;
        let reach_mm = self.t_f * (at + (at * at + v * v).sqrt());
        let v_r = (v * v + 2.0 * near * reach_mm).sqrt().min(v_cruise);
        lost(v_r, v, near) + lost(v_cruise, v_r, far)
    }

    /// The blended corner: `arc` instead of `taken_mm` of each element, entered under `v_in`
    /// and left under `v_out`. The speed dips to the lower end of the arc and ramps up along
    /// it (under its own limit) towards the higher one: charging the whole arc at the lower
    /// end's speed overstated a blend whose caps differ (a tight arc into a wide one), and
    /// kept a sharp corner 20 times slower (`tests/blends.rs`'s recorded case).
    fn blended_s(&self, arc: &Pending, (v_in, v_out): (f64, f64), taken_mm: (f64, f64)) -> f64 {
        // Under the time-law filter, elements joined at speed share the lower of their
        // accelerations (`share_acceleration`): a tight arc slows its neighbours' ramps, at
        // the corner and at their other ends, `v/2·(1/a' − 1/a)` each against cruising.
        let arc_acc = arc.limits.a_max_mm_s2();
        let (acc, arc_acc, ramps_s) = if self.smoothing {
            let acc = self.acc.0.min(arc_acc);
            let ramps_s = 0.5 * self.v_a * (1.0 / acc - 1.0 / self.sharp_acc.0)
                + 0.5 * self.v_b * (1.0 / acc - 1.0 / self.sharp_acc.1);
            ((acc, acc), acc, ramps_s)
        } else {
            (self.acc, arc_acc, 0.0)
        };
        let (len_mm, v_arc) = (arc.seg.length_mm, arc.limits.v_max_mm_s());
        // The speeds at the arc's ends: each reachable from the other along the arc.
        let v_in = v_in.min(v_arc);
        let v_out = v_out.min(v_arc);
        let v0 = v_in.min((v_out * v_out + 2.0 * arc_acc * len_mm).sqrt());
        let v1 = v_out.min((v0 * v0 + 2.0 * arc_acc * len_mm).sqrt());
        // The ramps from either end meet where their speeds are equal.
        let meet_mm =
            ((v1 * v1 - v0 * v0 + 2.0 * arc_acc * len_mm) / (4.0 * arc_acc)).clamp(0.0, len_mm);
        let arc_s =
            ramp_s(v0, arc_acc, v_arc, meet_mm) + ramp_s(v1, arc_acc, v_arc, len_mm - meet_mm);
        let far = (self.far.0.max(acc.0), self.far.1.max(acc.1));
        self.joined_s + ramps_s + self.corner_s((v0, v1), acc, far) + arc_s
            - taken_mm.0 / self.v_a
            - taken_mm.1 / self.v_b
    }
}

/// The time to run `dist_mm` from `v0`, accelerating at `acc` up to `v_max`.
fn ramp_s(v0: f64, acc: f64, v_max: f64, dist_mm: f64) -> f64 {
    let v0 = v0.min(v_max);
    let ramp_mm = (v_max * v_max - v0 * v0) / (2.0 * acc);
    if dist_mm <= ramp_mm {
        ((v0 * v0 + 2.0 * acc * dist_mm).sqrt() - v0) / acc
    } else {
        (v_max - v0) / acc + (dist_mm - ramp_mm) / v_max
    }
}

/// The ratio of consecutive radii on the grid of candidate blends (`Planner::blend_curves`):
/// 2^¼, so that the largest radius of the grid within a tolerance is at most 19 % under the
/// largest within it.
const GRID_RATIO: f64 = 1.189_207_115_002_721;

/// The grid's first radius, per millimetre of the path the blend may take (both rooms).
const GRID_START: f64 = 1e-4;

/// The grid's last radius: `GRID_START·GRID_RATIO^GRID_MAX_STEPS` is `MAX_RADIUS_PER_ROOM`.
const GRID_MAX_STEPS: i32 = 94;

/// An element's path near a corner, as the blend sees it: a line, or the circle of a plane arc.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Curve {
    /// A straight line, travelled along the unit vector `dir`.
    Line { dir: Vector3<f64> },
    /// A circle about `center_mm` of radius `radius_mm`, travelled counter-clockwise about the
    /// unit vector `normal`.
    Circle {
        center_mm: Vector3<f64>,
        radius_mm: f64,
        normal: Vector3<f64>,
    },
}

impl Curve {
    /// The direction of travel at `p` (a point of the curve).
    fn tangent(&self, p: Vector3<f64>) -> Vector3<f64> {
        match *self {
            Curve::Line { dir } => dir,
            Curve::Circle {
                center_mm, normal, ..
            } => normal.cross(&(p - center_mm)).normalize(),
        }
    }

    /// Where a circle of radius `rho` centred at `center` touches it: the foot of the
    /// perpendicular on a line, the point of the circle towards `center` on a circle.
    fn touch(&self, corner: Vector3<f64>, center: Vector3<f64>) -> Vector3<f64> {
        match *self {
            Curve::Line { dir } => corner + dir * (center - corner).dot(&dir),
            Curve::Circle {
                center_mm,
                radius_mm,
                ..
            } => center_mm + (center - center_mm).normalize() * radius_mm,
        }
    }

    /// How far along the curve `to` lies after `from` (both on it): a distance on a line, an
    /// angle in `(−π, π]` on a circle; and the same as a path length.
    fn ahead(&self, from: Vector3<f64>, to: Vector3<f64>) -> (f64, f64) {
        match *self {
            Curve::Line { dir } => {
                let d = (to - from).dot(&dir);
                (d, d)
            }
            Curve::Circle {
                center_mm,
                radius_mm,
                normal,
            } => {
                let (r0, r1) = (from - center_mm, to - center_mm);
                let angle = normal.dot(&r0.cross(&r1)).atan2(r0.dot(&r1));
                (angle, angle * radius_mm)
            }
        }
    }

    /// Distance from `q` (in the curve's plane) to its piece from `from` to `to` (`to` ahead).
    fn piece_distance_mm(&self, from: Vector3<f64>, to: Vector3<f64>, q: Vector3<f64>) -> f64 {
        let ends = (q - from).norm().min((q - to).norm());
        match *self {
            Curve::Line { .. } => {
                let d = to - from;
                let l2 = d.norm_squared();
                if l2 == 0.0 {
                    return ends;
                }
                let s = ((q - from).dot(&d) / l2).clamp(0.0, 1.0);
                (from + d * s - q).norm()
            }
            Curve::Circle {
                center_mm,
                radius_mm,
                ..
            } => {
                let (span, _) = self.ahead(from, to);
                let (at, _) = self.ahead(from, q);
                if (q - center_mm).norm() > 0.0 && at >= 0.0 && at <= span {
                    ((q - center_mm).norm() - radius_mm).abs()
                } else {
                    ends
                }
            }
        }
    }
}

/// A corner between two elements in one plane, as the blend sees it.
#[derive(Debug, Clone, Copy)]
pub(super) struct Corner {
    /// The programmed corner: where `a` ends and `b` starts.
    pub(super) corner_mm: Vector3<f64>,
    /// The element before the corner, and how much of it a blend may take: a length on a
    /// line, an angle on a circle.
    pub(super) a: Curve,
    pub(super) room_a: f64,
    /// The element after it, and how much of it a blend may take.
    pub(super) b: Curve,
    pub(super) room_b: f64,
    /// The unit normal of the plane about which the path turns counter-clockwise at the
    /// corner (so the corner's inside is on the left of the direction of travel).
    turn_normal: Vector3<f64>,
    /// The largest blend radius: [`MAX_RADIUS_PER_ROOM`] times the rooms' path lengths.
    max_radius_mm: f64,
}

/// The largest blend radius, per millimetre of the path the blend may take (both rooms).
/// Where both elements curve away from the blend (outside their circles), ever larger
/// circles touch them with a vanishing sweep and a deviation that tends to the distance of
/// their common tangent: a bound keeps the arc's geometry well conditioned (its sweep at
/// least about a thousandth of a radian).
const MAX_RADIUS_PER_ROOM: f64 = 1e3;

/// A circle tangent to both elements of a [`Corner`], on its inside.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct TangentCircle {
    pub(super) center_mm: Vector3<f64>,
    pub(super) radius_mm: f64,
    /// Unit normal about which the blend turns counter-clockwise.
    pub(super) normal: Vector3<f64>,
    /// Where it touches `a` and `b`.
    pub(super) p1_mm: Vector3<f64>,
    pub(super) p2_mm: Vector3<f64>,
    /// How much of `a` (before the corner) and of `b` (after it) it takes: a length on a
    /// line, an angle on a circle; and the same as path lengths.
    pub(super) taken_a: f64,
    pub(super) taken_b: f64,
    pub(super) taken_a_mm: f64,
    pub(super) taken_b_mm: f64,
    /// The angle of the blend arc from `p1_mm` to `p2_mm`, in `(0, π)`.
    pub(super) sweep_rad: f64,
    /// The largest distance of the blend arc from the programmed path it replaces.
    pub(super) deviation_mm: f64,
}

/// Two unit normals closer than this (or a line's direction this close to a plane) are
/// taken as one plane.
const PLANE_EPS: f64 = 1e-9;

impl Corner {
    /// The corner from `a` into `b` at `corner_mm`, or `None` where a blend cannot round it:
    /// the two are not in one plane (a line out of an arc's plane, arcs of different planes),
    /// the path is (nearly) tangent there (nothing to round) or (nearly) reverses (no room).
    pub(super) fn new(
        corner_mm: Vector3<f64>,
        (a, room_a): (Curve, f64),
        (b, room_b): (Curve, f64),
    ) -> Option<Corner> {
        let (t1, t2) = (a.tangent(corner_mm), b.tangent(corner_mm));
        let cross = t1.cross(&t2);
        let plane = match (a, b) {
            (Curve::Circle { normal, .. }, _) | (_, Curve::Circle { normal, .. }) => normal,
            _ => cross.try_normalize(0.0)?,
        };
        for c in [a, b] {
            let in_plane = match c {
                Curve::Line { dir } => dir.dot(&plane).abs() <= PLANE_EPS,
                Curve::Circle {
                    center_mm, normal, ..
                } => {
                    normal.cross(&plane).norm() <= PLANE_EPS
                        && (center_mm - corner_mm).dot(&plane).abs()
                            <= PLANE_EPS * (1.0 + (center_mm - corner_mm).norm())
                }
            };
            if !in_plane {
                return None;
            }
        }
        let half_turn_rad = 0.5 * t1.dot(&t2).clamp(-1.0, 1.0).acos();
        let (sin_h, cos_h) = half_turn_rad.sin_cos();
        // The same limits as between two lines.
        if sin_h < 1e-6 || cos_h < 1e-3 || !(room_a > 0.0 && room_b > 0.0) {
            return None;
        }
        let side = cross.dot(&plane);
        let turn_normal = if side >= 0.0 { plane } else { -plane };
        let room_mm = |c: Curve, room: f64| match c {
            Curve::Line { .. } => room,
            Curve::Circle { radius_mm, .. } => room * radius_mm,
        };
        let max_radius_mm = MAX_RADIUS_PER_ROOM * (room_mm(a, room_a) + room_mm(b, room_b));
        Some(Corner {
            max_radius_mm,
            corner_mm,
            a,
            room_a,
            b,
            room_b,
            turn_normal,
        })
    }

    /// The circle of radius `rho` tangent to both elements on the corner's inside, touching
    /// `a` before the corner and `b` after it within their rooms, or `None`. Its centre lies
    /// at `rho` from a line, on its inside, and at `R ∓ rho` from a circle's centre (`−` where
    /// the blend lies inside that circle, the circle turning the way the corner does): the
    /// intersection of two offset lines, an offset line and an offset circle (a quadratic) or
    /// two offset circles; of the solutions, the nearest the corner whose tangent points lie
    /// on the elements near the corner, with the direction of travel.
    pub(super) fn tangent_circle(&self, rho: f64) -> Option<TangentCircle> {
        if !(rho > 0.0 && rho <= self.max_radius_mm) {
            return None;
        }
        let m = self.turn_normal;
        let corner = self.corner_mm;
        enum Offset {
            Line(Vector3<f64>, Vector3<f64>),
            Circle(Vector3<f64>, f64),
        }
        let offset = |c: Curve| match c {
            Curve::Line { dir } => Some(Offset::Line(corner + m.cross(&dir) * rho, dir)),
            Curve::Circle {
                center_mm,
                radius_mm,
                normal,
            } => {
                let r = radius_mm - normal.dot(&m).signum() * rho;
                (r > 0.0).then_some(Offset::Circle(center_mm, r))
            }
        };
        let line_circle = |q: Vector3<f64>, d: Vector3<f64>, c: Vector3<f64>, r: f64| {
            // |q + λd − c|² = r²
            let w = q - c;
            let half_b = w.dot(&d);
            let disc = half_b * half_b - (w.norm_squared() - r * r);
            if disc.is_nan() || disc < 0.0 {
                return Vec::new();
            }
            let root = disc.sqrt();
            vec![q + d * (-half_b - root), q + d * (-half_b + root)]
        };
        let candidates = match (offset(self.a)?, offset(self.b)?) {
            (Offset::Line(q1, d1), Offset::Line(q2, d2)) => {
                let den = d1.cross(&d2).dot(&m);
                if den == 0.0 {
                    return None;
                }
                vec![q1 + d1 * ((q2 - q1).cross(&d2).dot(&m) / den)]
            }
            (Offset::Line(q, d), Offset::Circle(c, r))
            | (Offset::Circle(c, r), Offset::Line(q, d)) => line_circle(q, d, c, r),
            (Offset::Circle(c1, r1), Offset::Circle(c2, r2)) => {
                let e = c2 - c1;
                let d = e.norm();
                if d.is_nan() || d <= 0.0 {
                    return None;
                }
                let e = e / d;
                let along = (r1 * r1 - r2 * r2 + d * d) / (2.0 * d);
                let h2 = r1 * r1 - along * along;
                if h2.is_nan() || h2 < 0.0 {
                    return None;
                }
                let h = h2.sqrt();
                let across = m.cross(&e);
                vec![c1 + e * along + across * h, c1 + e * along - across * h]
            }
        };
        candidates
            .into_iter()
            .filter_map(|center| self.check(center, rho))
            .min_by(|x, y| {
                let dx = (x.center_mm - corner).norm();
                let dy = (y.center_mm - corner).norm();
                dx.total_cmp(&dy)
            })
    }

    /// The tangent circle about `center` of radius `rho`, if it touches both elements within
    /// their rooms, with the direction of travel.
    fn check(&self, center: Vector3<f64>, rho: f64) -> Option<TangentCircle> {
        let (m, corner) = (self.turn_normal, self.corner_mm);
        if !center.iter().all(|c| c.is_finite()) {
            return None;
        }
        let p1 = self.a.touch(corner, center);
        let p2 = self.b.touch(corner, center);
        let (taken_a, taken_a_mm) = self.a.ahead(p1, corner);
        let (taken_b, taken_b_mm) = self.b.ahead(corner, p2);
        if !(taken_a > 0.0 && taken_a <= self.room_a && taken_b > 0.0 && taken_b <= self.room_b) {
            return None;
        }
        // The blend runs counter-clockwise about `m` from p1 to p2, tangent to both.
        let (r1, r2) = (p1 - center, p2 - center);
        let along = |r: Vector3<f64>, t: Vector3<f64>| m.cross(&r).dot(&t) > 0.999 * rho;
        if !(along(r1, self.a.tangent(p1)) && along(r2, self.b.tangent(p2))) {
            return None;
        }
        let sweep_rad = m.dot(&r1.cross(&r2)).atan2(r1.dot(&r2));
        if sweep_rad.is_nan() || sweep_rad <= 0.0 {
            return None;
        }
        // The deviation: from the corner to the blend (where the blend passes nearest it), and
        // from points along the blend to the pieces of the path it replaces.
        let mut deviation_mm = (corner - center).norm() - rho;
        const SAMPLES: u32 = 16;
        for k in 1..SAMPLES {
            let angle = sweep_rad * f64::from(k) / f64::from(SAMPLES);
            let (sin, cos) = angle.sin_cos();
            let q = center + r1 * cos + m.cross(&r1) * sin;
            let d = self
                .a
                .piece_distance_mm(p1, corner, q)
                .min(self.b.piece_distance_mm(corner, p2, q));
            deviation_mm = deviation_mm.max(d);
        }
        Some(TangentCircle {
            center_mm: center,
            radius_mm: rho,
            normal: m,
            p1_mm: p1,
            p2_mm: p2,
            taken_a,
            taken_b,
            taken_a_mm,
            taken_b_mm,
            sweep_rad,
            deviation_mm,
        })
    }

    /// The first radius of the grid of candidate blends: `GRID_START` of the rooms' path
    /// lengths (independent of the tolerance).
    pub(super) fn grid_start_mm(&self) -> f64 {
        GRID_START * self.max_radius_mm / MAX_RADIUS_PER_ROOM
    }

    /// The grid's `k`-th radius, `grid_start_mm·GRID_RATIO^k`.
    pub(super) fn grid_radius_mm(&self, k: i32) -> f64 {
        self.grid_start_mm() * GRID_RATIO.powi(k)
    }

    /// The circle of radius `rho` touching both elements, if it keeps within `tol_mm`.
    fn within(&self, rho: f64, tol_mm: f64) -> Option<TangentCircle> {
        self.tangent_circle(rho)
            .filter(|t| t.deviation_mm <= tol_mm)
    }

    /// The index `k` of the largest radius of the grid within `tol_mm` of the corner and the
    /// rooms, or `None` where not even its first is.
    ///
    /// The radii that fit need not be one interval: where an element curves away from the
    /// blend, much larger circles may touch both elements again within the tolerance (with a
    /// vanishing sweep). The blend keeps to the interval from 0, where the deviation and the
    /// lengths taken grow with the radius: the grid is climbed from its start until a radius
    /// no longer fits.
    pub(super) fn grid_top(&self, tol_mm: f64) -> Option<i32> {
        if !(tol_mm > 0.0 && tol_mm.is_finite()) {
            return None;
        }
        let mut k = -1;
        while k < GRID_MAX_STEPS && self.within(self.grid_radius_mm(k + 1), tol_mm).is_some() {
            k += 1;
        }
        (k >= 0).then_some(k)
    }

    /// The largest tangent circle within `tol_mm` of the corner and the rooms (in the
    /// interval from 0, as [`grid_top`](Self::grid_top)): the grid's top, bisected up to the
    /// next radius.
    #[cfg(test)]
    fn largest_within(&self, tol_mm: f64) -> Option<TangentCircle> {
        let k = self.grid_top(tol_mm);
        let (mut lo, mut hi) = match k {
            Some(k) => (self.grid_radius_mm(k), self.grid_radius_mm(k + 1)),
            None if tol_mm > 0.0 && tol_mm.is_finite() => (0.0, self.grid_start_mm()),
            None => return None,
        };
        for _ in 0..64 {
            let mid = 0.5 * (lo + hi);
            if mid <= lo || mid >= hi {
                break;
            }
            if self.within(mid, tol_mm).is_some() {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        self.within(lo, tol_mm)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn v(x: f64, y: f64) -> Vector3<f64> {
        Vector3::new(x, y, 0.0)
    }

    const Z: Vector3<f64> = Vector3::new(0.0, 0.0, 1.0);

    /// Distance from `q` to the line through `p` along `dir`, and to a circle.
    fn to_line(q: Vector3<f64>, p: Vector3<f64>, dir: Vector3<f64>) -> f64 {
        let w = q - p;
        (w - dir * w.dot(&dir)).norm()
    }

    /// Checks what `tangent_circle` promises: tangency (the centre at ρ from a line, at
    /// `R ∓ ρ` from a circle's centre), the tangent points on the elements before and after
    /// the corner, and the blend's direction of travel equal to theirs there.
    fn check_tangency(c: &Corner, t: &TangentCircle) {
        let rho = t.radius_mm;
        for (curve, p, before) in [(c.a, t.p1_mm, true), (c.b, t.p2_mm, false)] {
            match curve {
                Curve::Line { dir } => {
                    assert!((to_line(t.center_mm, c.corner_mm, dir) - rho).abs() < 1e-9);
                    assert!(to_line(p, c.corner_mm, dir) < 1e-9, "on the line");
                    let along = (p - c.corner_mm).dot(&dir);
                    assert!(if before { along < 0.0 } else { along > 0.0 });
                }
                Curve::Circle {
                    center_mm,
                    radius_mm,
                    normal,
                } => {
                    let inside = normal.dot(&t.normal) > 0.0;
                    let want = if inside {
                        radius_mm - rho
                    } else {
                        radius_mm + rho
                    };
                    assert!(((t.center_mm - center_mm).norm() - want).abs() < 1e-9);
                    assert!(
                        ((p - center_mm).norm() - radius_mm).abs() < 1e-9,
                        "on the circle"
                    );
                    let (ahead, _) = if before {
                        curve.ahead(p, c.corner_mm)
                    } else {
                        curve.ahead(c.corner_mm, p)
                    };
                    assert!(ahead > 0.0);
                }
            }
            assert!(
                ((p - t.center_mm).norm() - rho).abs() < 1e-9,
                "on the blend"
            );
            let blend_dir = t.normal.cross(&(p - t.center_mm)).normalize();
            assert!((blend_dir - curve.tangent(p)).norm() < 1e-9, "tangent");
        }
        let nearest = (c.corner_mm - t.center_mm).norm() - rho;
        assert!(t.deviation_mm >= nearest - 1e-12);
    }

    /// Every kind of corner with an arc, the blend inside and outside the arc's circle.
    fn corners() -> Vec<Corner> {
        let line_x = Curve::Line { dir: v(1.0, 0.0) };
        let line_y = Curve::Line { dir: v(0.0, 1.0) };
        let circle = |cx: f64, cy: f64, r: f64, n: f64| Curve::Circle {
            center_mm: v(cx, cy),
            radius_mm: r,
            normal: Z * n,
        };
        let at = |a: Curve, b: Curve| Corner::new(Vector3::zeros(), (a, 1.0), (b, 1.0)).unwrap();
        vec![
            // Along +X, then a counter-clockwise arc leaving upwards-left (concave: inside).
            at(line_x, circle(-3.0, 0.0, 3.0, 1.0)),
            // The same arc clockwise: leaving downwards... convex side.
            at(line_x, circle(-3.0, 0.0, 3.0, -1.0)),
            // Arc into a line: counter-clockwise arc about (0, −2) arriving at the origin going
            // −X, then the line up +Y.
            at(circle(0.0, -2.0, 2.0, 1.0), line_y),
            // Clockwise arc about (0, 2) arriving going −X... then up.
            at(circle(0.0, 2.0, 2.0, -1.0), line_y),
            // Arc into arc, both ways round.
            at(circle(0.0, -2.0, 2.0, 1.0), circle(-1.5, 0.0, 1.5, -1.0)),
            at(circle(0.0, -2.0, 2.0, 1.0), circle(1.0, 0.0, 1.0, 1.0)),
            at(circle(0.0, 2.0, 2.0, -1.0), circle(3.0, 0.0, 3.0, 1.0)),
        ]
    }

    #[test]
    fn the_blend_circle_touches_both_elements_on_the_inside() {
        for (k, c) in corners().iter().enumerate() {
            for rho in [1e-3, 0.01, 0.1] {
                let t = c
                    .tangent_circle(rho)
                    .unwrap_or_else(|| panic!("corner {k}: no circle of {rho}"));
                check_tangency(c, &t);
            }
        }
    }

    #[test]
    fn the_largest_blend_keeps_to_the_tolerance() {
        for (k, c) in corners().iter().enumerate() {
            for tol in [1e-3, 0.01, 0.05] {
                let t = c.largest_within(tol).unwrap();
                check_tangency(c, &t);
                assert!(t.deviation_mm <= tol, "corner {k}: {}", t.deviation_mm);
                // The largest: a little more deviates too much (the rooms are ample).
                let wider = c.tangent_circle(t.radius_mm * 1.001).unwrap();
                assert!(wider.deviation_mm > tol, "corner {k}, tol {tol}");
                // The deviation is where the blend passes the corner, for these arcs.
                let nearest = (c.corner_mm - t.center_mm).norm() - t.radius_mm;
                assert!((t.deviation_mm - nearest).abs() < 1e-3 * tol, "corner {k}");
            }
        }
    }

    #[test]
    fn between_two_lines_it_is_seed_001s_arc() {
        // The closed form of `blend_lines`: r = δ·cos(θ/2)/(1 − cos(θ/2)) for a turn θ.
        let theta = 1.0f64;
        let c = Corner::new(
            Vector3::zeros(),
            (Curve::Line { dir: v(1.0, 0.0) }, 10.0),
            (
                Curve::Line {
                    dir: v(theta.cos(), theta.sin()),
                },
                10.0,
            ),
        )
        .unwrap();
        let tol = 0.01;
        let t = c.largest_within(tol).unwrap();
        let h = (0.5 * theta).cos();
        assert!((t.radius_mm / (tol * h / (1.0 - h)) - 1.0).abs() < 1e-9);
        check_tangency(&c, &t);
    }

    #[test]
    fn the_room_bounds_what_a_blend_takes() {
        let c = Corner::new(
            Vector3::zeros(),
            (Curve::Line { dir: v(1.0, 0.0) }, 0.05),
            (
                Curve::Circle {
                    center_mm: v(-3.0, 0.0),
                    radius_mm: 3.0,
                    normal: Z,
                },
                0.02,
            ),
        )
        .unwrap();
        let t = c.largest_within(1.0).unwrap();
        assert!(t.taken_a <= 0.05 && t.taken_b <= 0.02);
        assert!(t.deviation_mm < 1.0);
        assert!(c.tangent_circle(t.radius_mm * 1.01).is_none());
    }

    #[test]
    fn elements_not_in_one_plane_and_tangent_joins_are_not_blended() {
        let arc = Curve::Circle {
            center_mm: v(-3.0, 0.0),
            radius_mm: 3.0,
            normal: Z,
        };
        let rising = Curve::Line {
            dir: Vector3::new(1.0, 0.0, 1.0).normalize(),
        };
        assert!(Corner::new(Vector3::zeros(), (rising, 1.0), (arc, 1.0)).is_none());
        let tilted = Curve::Circle {
            center_mm: v(-3.0, 0.0),
            radius_mm: 3.0,
            normal: Vector3::new(0.0, 0.1, 1.0).normalize(),
        };
        assert!(
            Corner::new(
                Vector3::zeros(),
                (Curve::Line { dir: v(0.0, 1.0) }, 1.0),
                (tilted, 1.0)
            )
            .is_none()
        );
        // Tangent: the line along +Y into a counter-clockwise arc about (−3, 0).
        assert!(
            Corner::new(
                Vector3::zeros(),
                (Curve::Line { dir: v(0.0, 1.0) }, 1.0),
                (arc, 1.0)
            )
            .is_none()
        );
    }

    #[test]
    fn a_trimmed_arc_keeps_its_circle() {
        let g = ArcGeometry::new(v(1.0, 0.0), v(-1.0, 0.0), Vector3::zeros(), Z, 1).unwrap();
        let end = v(0.0, 1.0);
        let t = trimmed_arc((g.point_at(0.0), end), &g, g.sweep_rad - 0.5 * PI).unwrap();
        assert!((t.sweep_rad - 2.5 * PI).abs() < 1e-12);
        assert_eq!((t.center_mm, t.normal), (g.center_mm, g.normal));
        assert!(trimmed_arc((g.point_at(0.0), end), &g, 1.0).is_none());
    }
}
