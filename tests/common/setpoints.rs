//! The setpoint check of the planner tests: a plan sampled every period as the cyclic loop
//! streams it, with every axis's velocity, acceleration and (for S-curves) jerk computed by
//! finite differences, as a drive sees them.

use canmotion::interpolator::Interpolator;
use canmotion::planner::{Limits, Plan, PlannerConfig, ProfileKind};
use nalgebra::Vector3;

/// Checks the samples of `plan` against `limits` and `config` within 1 % (and a nanometre of
/// rounding per sample): no NaN, velocity, acceleration and, unless trapezoid, jerk per axis,
/// and the last sample exactly the plan's end. The error names the sample and the axis.
#[allow(dead_code)] // not every test binary samples without override
pub fn limits_hold(plan: Plan, limits: &Limits, config: &PlannerConfig) -> Result<(), String> {
    let interp = Interpolator::new(plan, config.period_s).map_err(|e| e.to_string())?;
    limits_hold_driven(interp, limits, config, &mut |_, _| Ok(()))
}

/// [`limits_hold`] of an interpolator that `drive` may act on (override, hold, resume) before
/// each sample `k` (1, 2, ...); an error of `drive` ends the check with it.
#[allow(dead_code)] // not every test binary drives the override
pub fn limits_hold_driven(
    mut interp: Interpolator,
    limits: &Limits,
    config: &PlannerConfig,
    drive: &mut dyn FnMut(u64, &mut Interpolator) -> Result<(), String>,
) -> Result<(), String> {
    let t = config.period_s;
    let end = interp.queued_end_mm();
    // The last four samples (oldest first).
    let mut s = [Vector3::zeros(); 4];
    s[3] = interp.last_mm();
    let mut k = 0u64;
    let (slack, round) = (1.01, 1e-9);
    let jerk = config.profile != ProfileKind::Trapezoid;
    while !interp.is_finished() {
        let mut q = Vector3::zeros();
        k += 1;
        drive(k, &mut interp)?;
        interp.update(&mut q);
        if !q.iter().all(|c| c.is_finite()) {
            return Err(format!("sample {k}: {q:?}"));
        }
        s.rotate_left(1);
        s[3] = q;
        let d1 = s[3] - s[2];
        let d2 = s[3] - 2.0 * s[2] + s[1];
        let d3 = s[3] - 3.0 * s[2] + 3.0 * s[1] - s[0];
        let feed = d1.norm() / t;
        if feed > limits.max_feed_mm_s * slack + round / t {
            return Err(format!("sample {k}: path speed {feed} mm/s"));
        }
        for i in 0..3 {
            let v = d1[i].abs() / t;
            if v > limits.max_vel_mm_s[i] * slack + round / t {
                return Err(format!("sample {k}: axis {i} velocity {v} mm/s"));
            }
            let a = d2[i].abs() / (t * t);
            if k >= 2 && a > limits.max_acc_mm_s2[i] * slack + round / (t * t) {
                return Err(format!("sample {k}: axis {i} acceleration {a} mm/s²"));
            }
            let j = d3[i].abs() / (t * t * t);
            if jerk && k >= 3 && j > config.max_jerk_mm_s3[i] * slack + round / (t * t * t) {
                return Err(format!("sample {k}: axis {i} jerk {j} mm/s³"));
            }
        }
    }
    if s[3] != end {
        return Err(format!("ends at {:?}, not at {end:?}", s[3]));
    }
    Ok(())
}
