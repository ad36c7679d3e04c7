//! What a machine builder relies on from the look-ahead: whatever the program (long and tiny
//! lines, reversals, arcs, changing feeds), the setpoints sampled every period keep every
//! axis within its velocity and acceleration limits and, with S-curves, its jerk limit, all
//! computed by finite differences as a drive sees them; nothing is NaN; the end is exact.
//! Seeded random programs (proptest), trapezoid and S-curve modes.

use canmotion::gcode::parse_program;
use canmotion::planner::{ProfileKind, plan_with};
use nalgebra::Vector3;
use proptest::prelude::*;

#[path = "common/setpoints.rs"]
mod setpoints;

#[path = "common/random_programs.rs"]
mod random_programs;

use random_programs::{a_move, config, limits, program};

/// Plans `text` and checks its setpoints (see `common::setpoints`).
fn check(text: &str, profile: ProfileKind) -> Result<(), TestCaseError> {
    let prog = parse_program(text, "random.ngc", Vector3::zeros())
        .map_err(|e| TestCaseError::fail(format!("{e}\n{text}")))?;
    let cfg = config(profile);
    let plan = plan_with(&prog, &limits(), &cfg).map_err(|e| TestCaseError::fail(e.to_string()))?;
    setpoints::limits_hold(plan, &limits(), &cfg).map_err(TestCaseError::fail)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 96, ..ProptestConfig::default() })]

    #[test]
    fn trapezoid_setpoints_keep_every_axis_within_its_limits(moves in prop::collection::vec(a_move(), 1..30)) {
        check(&program(&moves), ProfileKind::Trapezoid)?;
    }

    #[test]
    fn s_curve_setpoints_keep_every_axis_within_its_limits(moves in prop::collection::vec(a_move(), 1..30)) {
        check(&program(&moves), ProfileKind::SCurve)?;
    }
}

#[test]
fn a_circle_of_tiny_lines_keeps_the_centripetal_acceleration() {
    // 2000 chords of a 10 mm circle (31 µm each, ~25 per period at speed): the velocity
    // turns a little at each junction but a lot within a period.
    let mut text = String::from("G21 G90 G64 G0 X10 Y0\n");
    for k in 1..=2000 {
        let a = k as f64 / 2000.0 * std::f64::consts::TAU;
        text.push_str(&format!(
            "G1 X{:.6} Y{:.6} F9000\n",
            10.0 * a.cos(),
            10.0 * a.sin()
        ));
    }
    text.push_str("M2\n");
    check(&text, ProfileKind::Trapezoid).unwrap();
    check(&text, ProfileKind::SCurve).unwrap();
}
