//! Corner blends under G64 P: the tangent arc that replaces a sharp corner within the
//! tolerance (`shared/seeds` 001), where it is faster than the corner.

use super::*;

/// A corner's blend arc ([`Planner::blend_arc`]).
pub(super) struct Blend {
    pub(super) arc: Pending,
    /// Distance from the corner to where the arc touches each line.
    pub(super) tangent_mm: f64,
    /// Highest speeds where the arc begins and ends (`Planner::junction_caps`).
    pub(super) cap_in: (f64, f64),
    pub(super) cap_out: (f64, f64),
}

impl Planner {
    /// The tangent arc that replaces the corner from line `a` into line `b` under G64 P
    /// (`shared/seeds` 001), or `None` where the corner stays sharp: no tolerance (P0), not two
    /// lines, no turn, or an arc no faster than the sharp corner's one-period junction speed.
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
    pub(super) fn blend_arc(&self, a: &Pending, b: &Pending) -> Result<Option<Blend>, PlanError> {
        let BlendMode::Blend { .. } = a.blend else {
            return Ok(None);
        };
        if aux_axes::keeps_corner(a, b) {
            return Ok(None);
        }
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
        // longer than slowing down for the sharp corner (see `corner_cost_s`).
        let (acc, jerk) = (
            a.limits.a_max_mm_s2().min(b.limits.a_max_mm_s2()),
            a.limits.j_max_mm_s3().min(b.limits.j_max_mm_s3()),
        );
        let room = a.full_length_mm.min(b.full_length_mm);
        let v_cruise = feed_mm_s.min((v_sharp * v_sharp + acc * room).sqrt());
        let arc_len = arc.seg.length_mm;
        let blended = corner_cost_s(v_cruise, v_blend, acc, jerk) + arc_len / v_blend
            - 2.0 * tangent_mm / v_cruise;
        if !(v_blend > v_sharp && blended < corner_cost_s(v_cruise, v_sharp, acc, jerk)) {
            return Ok(None);
        }
        Ok(Some(Blend {
            arc,
            tangent_mm,
            cap_in,
            cap_out,
        }))
    }
}
