//! The auxiliary axes (A B C in degrees, U V W in millimetres) in the planner.
//!
//! An element carries them linearly in its path parameter `s` ([`crate::gcode::AuxMove`]):
//! over an element of length `L` (the X/Y/Z path length, or for a move without X/Y/Z motion
//! the U/V/W length, else the A/B/C angle), axis `i` moves by `Δᵢ` at the rate
//! `wᵢ = Δᵢ/L` per unit of `s`. Its velocity, acceleration and jerk are the path's times
//! `|wᵢ|` (no centripetal part: it is linear in `s`, on arcs too), so the element's limits are
//! capped as for an X/Y/Z axis along a line:
//!
//! - speed `v ≤ max_velᵢ/|wᵢ|`,
//! - acceleration `a ≤ s·max_accᵢ/|wᵢ|`, jerk `j ≤ s·max_jerkᵢ/|wᵢ|` (`s`: the share of
//!   [`super::PlannerConfig::path_acc_share`]).
//!
//! At a junction taken at speed `v` the axis's velocity steps by `v·|Δwᵢ|`; the profiles use at
//! most `s` of its acceleration and jerk on either side, so the step is held to what is left,
//! with the rules the X/Y/Z axes follow (`super::Planner::junction_limit_mm_s`): within one
//! period `T` (trapezoids), or the axis filters' `T_k` (the jerk-limited mode), and shared among
//! the junctions of short elements within that time:
//! `v·|Δwᵢ|·(1 + v·T/L) ≤ T·(1 − s)·max_accᵢ`, and for the jerk-limited profiles also
//! `v·|Δwᵢ| ≤ T²·(1 − s)·max_jerkᵢ/2`.
//!
//! A corner where an auxiliary axis moves on either side is never rounded by a blend arc
//! (the arc would have to carry them): it stays exact, and the junction rule above bounds it.

use nalgebra::Vector3;

use super::{MAX_LIMIT, Pending, PlanError, PlannerConfig, profile, shared_jump_mm_s};
use crate::gcode::{AUX_LETTERS, AuxMove, AuxPos};

/// Limits of the auxiliary axes A B C (deg/s, deg/s², deg/s³) and U V W (mm/s, mm/s², mm/s³),
/// in the order of [`AUX_LETTERS`]; an axis the machine does not have keeps infinite limits
/// (the interpreter refuses programs that move it).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AuxLimits {
    /// Maximum speed of each axis.
    pub max_vel: AuxPos,
    /// Maximum acceleration of each axis.
    pub max_acc: AuxPos,
    /// Maximum jerk of each axis (the jerk-limited profiles and the jerk-limited mode).
    pub max_jerk: AuxPos,
}

impl AuxLimits {
    /// No auxiliary axes: no limits.
    pub const NONE: AuxLimits = AuxLimits {
        max_vel: [f64::INFINITY; 6],
        max_acc: [f64::INFINITY; 6],
        max_jerk: [f64::INFINITY; 6],
    };

    /// Checks that every limit is positive and at most [`MAX_LIMIT`], or infinite (no axis).
    pub fn validate(&self) -> Result<(), PlanError> {
        const VEL: [&str; 6] = [
            "aux.max_vel.a",
            "aux.max_vel.b",
            "aux.max_vel.c",
            "aux.max_vel.u",
            "aux.max_vel.v",
            "aux.max_vel.w",
        ];
        const ACC: [&str; 6] = [
            "aux.max_acc.a",
            "aux.max_acc.b",
            "aux.max_acc.c",
            "aux.max_acc.u",
            "aux.max_acc.v",
            "aux.max_acc.w",
        ];
        const JERK: [&str; 6] = [
            "aux.max_jerk.a",
            "aux.max_jerk.b",
            "aux.max_jerk.c",
            "aux.max_jerk.u",
            "aux.max_jerk.v",
            "aux.max_jerk.w",
        ];
        for i in 0..AUX_LETTERS.len() {
            for (name, value) in [
                (VEL[i], self.max_vel[i]),
                (ACC[i], self.max_acc[i]),
                (JERK[i], self.max_jerk[i]),
            ] {
                if !((value > 0.0 && value <= MAX_LIMIT) || value == f64::INFINITY) {
                    return Err(PlanError::InvalidLimit { name, value });
                }
            }
        }
        Ok(())
    }
}

impl Default for AuxLimits {
    fn default() -> AuxLimits {
        AuxLimits::NONE
    }
}

/// What the auxiliary axes allow an element: its rates `wᵢ` and the caps on its path speed,
/// acceleration and jerk (infinite where no auxiliary axis moves).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct AuxCaps {
    pub rate: AuxPos,
    pub v_mm_s: f64,
    pub acc_mm_s2: f64,
    pub jerk_mm_s3: f64,
}

/// The caps of an element of path length `length` over which the auxiliary axes move as `aux`.
pub(super) fn caps(cfg: &PlannerConfig, aux: &AuxMove, length: f64) -> AuxCaps {
    let mut c = AuxCaps {
        rate: [0.0; 6],
        v_mm_s: f64::INFINITY,
        acc_mm_s2: f64::INFINITY,
        jerk_mm_s3: f64::INFINITY,
    };
    if !aux.moves() || length.is_nan() || length <= 0.0 {
        return c;
    }
    let lim = &cfg.aux;
    let share = cfg.path_acc_share;
    for (i, d) in aux.delta().into_iter().enumerate() {
        let w = d / length;
        c.rate[i] = w;
        let w = w.abs();
        if w > 0.0 {
            c.v_mm_s = c.v_mm_s.min(lim.max_vel[i] / w);
            c.acc_mm_s2 = c.acc_mm_s2.min(share * lim.max_acc[i] / w);
            c.jerk_mm_s3 = c.jerk_mm_s3.min(share * lim.max_jerk[i] / w);
        }
    }
    c
}

/// The path length of a line without X/Y/Z motion: `None` if the auxiliary axes do not move
/// either (a move of no length, left out).
pub(super) fn aux_only_length(aux: &AuxMove, line: usize) -> Result<Option<f64>, PlanError> {
    if !aux.moves() {
        return Ok(None);
    }
    if !aux.end.iter().all(|c| c.is_finite()) {
        return Err(PlanError::NonFiniteTarget { line });
    }
    let length = aux.length();
    if !(length > 0.0 && length <= profile::MAX_LENGTH_MM) {
        return Err(PlanError::Overflow { line });
    }
    Ok(Some(length))
}

/// The highest speed through the junction from `a` into `b` that the auxiliary axes' velocity
/// steps allow (see the module documentation): `t_s` is the period (trapezoids and the
/// jerk-limited profiles) or the axis filters' time (the jerk-limited mode), `jerk` whether the
/// jerk rule applies.
pub(super) fn junction_cap(
    cfg: &PlannerConfig,
    a: &Pending,
    b: &Pending,
    t_s: f64,
    jerk: bool,
) -> f64 {
    let mut v = f64::INFINITY;
    if a.aux_rate == b.aux_rate {
        return v;
    }
    let free = (1.0 - cfg.path_acc_share).max(0.0);
    let l_mm = a.seg.length_mm.min(b.seg.length_mm);
    for i in 0..AUX_LETTERS.len() {
        let d = (b.aux_rate[i] - a.aux_rate[i]).abs();
        if d > 0.0 {
            v = v.min(shared_jump_mm_s(
                t_s * free * cfg.aux.max_acc[i],
                d,
                t_s / l_mm,
            ));
            if jerk {
                v = v.min(t_s * t_s * 0.5 * free * cfg.aux.max_jerk[i] / d);
            }
        }
    }
    v.max(0.0)
}

/// Whether the corner from `a` into `b` must stay exact: an auxiliary axis moves on either side
/// (a blend arc would not carry it).
pub(super) fn keeps_corner(a: &Pending, b: &Pending) -> bool {
    a.seg.aux.moves() || b.seg.aux.moves()
}

/// A line without X/Y/Z motion has no direction in X/Y/Z.
pub(super) const NO_DIRECTION: Vector3<f64> = Vector3::new(0.0, 0.0, 0.0);
