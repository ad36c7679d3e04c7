//! What an operator relies on from the feed override and the feed hold while a program runs:
//! whatever the program and whenever the override changes (0 to 100 %) or a hold or resume
//! comes, the setpoints keep every axis within its velocity and acceleration limits and, with
//! S-curves, its jerk limit (finite differences, within 1 %, as in `planner_limits`); the
//! change moves the effective override on the very next cycle; the program still ends
//! exactly on its end point.

use canmotion::gcode::parse_program;
use canmotion::interp::{Interpolator, OverrideRamp, Status};
use canmotion::planner::{Plan, PlannerConfig, ProfileKind, plan_with};
use nalgebra::Vector3;
use proptest::prelude::*;

#[path = "common/setpoints.rs"]
mod setpoints;

#[path = "common/random_programs.rs"]
mod random_programs;

use random_programs::{T, a_move, config, limits, program};

/// What the operator does at some cycle.
#[derive(Debug, Clone, Copy)]
enum Command {
    /// Override to this fraction.
    Override(f64),
    Hold,
    Resume,
}

fn a_command() -> impl Strategy<Value = Command> {
    prop_oneof![
        3 => prop_oneof![Just(0.0), Just(1.0), 0.0..=1.0f64].prop_map(Command::Override),
        1 => Just(Command::Hold),
        1 => Just(Command::Resume),
    ]
}

/// Commands with the cycle each comes at (ascending), the earliest at cycle 1.
fn a_schedule() -> impl Strategy<Value = Vec<(u64, Command)>> {
    prop::collection::vec((1..400u64, a_command()), 0..12).prop_map(|steps| {
        let mut at = 0;
        steps
            .into_iter()
            .map(|(gap, c)| {
                at += gap;
                (at, c)
            })
            .collect()
    })
}

/// Plans `text`, samples it while `schedule` acts on it, then resumes at `final_override`
/// so that it finishes; checks the limits, the end, and that every command moves `k` on
/// the next sample whenever its target differs.
fn check(
    text: &str,
    profile: ProfileKind,
    schedule: &[(u64, Command)],
    final_override: f64,
) -> Result<(), TestCaseError> {
    check_with(text, config(profile), schedule, final_override)
}

fn check_with(
    text: &str,
    cfg: PlannerConfig,
    schedule: &[(u64, Command)],
    final_override: f64,
) -> Result<(), TestCaseError> {
    let prog = parse_program(text, "random.ngc", Vector3::zeros())
        .map_err(|e| TestCaseError::fail(format!("{e}\n{text}")))?;
    let plan = plan_with(&prog, &limits(), &cfg).map_err(|e| TestCaseError::fail(e.to_string()))?;
    let ramp = OverrideRamp::for_machine(&limits(), &cfg).unwrap();
    let interp = Interpolator::new(plan, T).unwrap().with_override_ramp(ramp);
    let last_at = schedule.last().map_or(0, |(at, _)| *at);
    let mut next = 0;
    // (k before the command, the command's target) of the command applied before the sample.
    let mut pending: Option<(f64, f64)> = None;
    let mut drive = |k: u64, interp: &mut Interpolator| -> Result<(), String> {
        if let Some((before, target)) = pending.take()
            && !interp.is_finished()
            && before != target
            && interp.effective_override() == before
        {
            return Err(format!(
                "sample {}: k stayed at {before} after a change to {target}",
                k - 1
            ));
        }
        let before = interp.effective_override();
        let mut applied = false;
        while next < schedule.len() && schedule[next].0 == k {
            match schedule[next].1 {
                Command::Override(x) => interp.set_override(x),
                Command::Hold => interp.hold(),
                Command::Resume => interp.resume(),
            }
            .map_err(|e| e.to_string())?;
            next += 1;
            applied = true;
        }
        if k == last_at + 1 {
            interp.resume().map_err(|e| e.to_string())?;
            interp
                .set_override(final_override)
                .map_err(|e| e.to_string())?;
            applied = true;
        }
        if applied {
            let target = if interp.is_held() {
                0.0
            } else {
                interp.requested_override().min(1.0)
            };
            pending = Some((before, target));
        }
        if k > last_at + 1_000_000 {
            return Err("not finished a million cycles after the last command".into());
        }
        Ok(())
    };
    setpoints::limits_hold_driven(interp, &limits(), &cfg, &mut drive)
        .map_err(|e| TestCaseError::fail(format!("{e}\nschedule {schedule:?}\n{text}")))
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    #[test]
    fn trapezoid_setpoints_keep_the_limits_under_override_and_hold(
        moves in prop::collection::vec(a_move(), 1..30),
        schedule in a_schedule(),
        final_override in 0.2..=1.0f64,
    ) {
        check(&program(&moves), ProfileKind::Trapezoid, &schedule, final_override)?;
    }

    #[test]
    fn s_curve_setpoints_keep_the_limits_under_override_and_hold(
        moves in prop::collection::vec(a_move(), 1..30),
        schedule in a_schedule(),
        final_override in 0.2..=1.0f64,
    ) {
        check(&program(&moves), ProfileKind::SCurve, &schedule, final_override)?;
    }

    #[test]
    fn smooth_setpoints_keep_the_limits_under_override_and_hold(
        moves in prop::collection::vec(a_move(), 1..30),
        schedule in a_schedule(),
        final_override in 0.2..=1.0f64,
    ) {
        check(&program(&moves), ProfileKind::Smooth, &schedule, final_override)?;
    }

    #[test]
    fn blended_corners_keep_the_limits_under_override_and_hold(
        moves in prop::collection::vec(a_move(), 1..30),
        schedule in a_schedule(),
        final_override in 0.2..=1.0f64,
    ) {
        // G64 P0.5 with a chord tolerance of 10 µm: many corners become arcs (trapezoid).
        let cfg = PlannerConfig { chord_tol_mm: 0.01, ..config(ProfileKind::Trapezoid) };
        let text = program(&moves).replacen("G64", "G64 P0.5", 1);
        check_with(&text, cfg, &schedule, final_override)?;
    }
}

/// A hold in the middle of a long line at full speed: standstill within the time the ramp
/// predicts (plus a period of rounding), on the line and short of its end, at the same point
/// cycle after cycle; a resume takes the program to its exact end.
#[test]
fn a_hold_stops_on_the_path_in_the_predicted_time_and_a_resume_finishes() {
    for profile in [
        ProfileKind::Trapezoid,
        ProfileKind::SCurve,
        ProfileKind::Smooth,
    ] {
        let text = "G21 G90 G64 G1 X120 Y40 F6000\nG1 X0 Y0\nM2\n";
        let prog = parse_program(text, "hold.ngc", Vector3::zeros()).unwrap();
        let cfg = config(profile);
        let plan = plan_with(&prog, &limits(), &cfg).unwrap();
        let reference = plan.clone();
        let ramp = OverrideRamp::for_machine(&limits(), &cfg).unwrap();
        let mut interp = Interpolator::new(plan, T).unwrap().with_override_ramp(ramp);
        let mut p = Vector3::zeros();
        // Cruise on the first line, then hold.
        for _ in 0..150 {
            assert!(matches!(interp.update(&mut p), Status::Working { line: 1 }));
        }
        assert_eq!(interp.effective_override(), 1.0);
        interp.hold().unwrap();
        let predicted_s = ramp.ramp_time_s(1.0, 0.0);
        let mut cycles = 0u64;
        let line = loop {
            cycles += 1;
            match interp.update(&mut p) {
                Status::Held { line } => break line,
                Status::Working { .. } => {}
                other => panic!("{profile:?}: {other:?} while holding"),
            }
            assert!(
                cycles as f64 * T <= predicted_s + T,
                "{profile:?}: still moving {cycles} cycles after the hold (ramp {predicted_s} s)"
            );
        };
        assert!(interp.is_standing_still() && interp.is_held());
        assert_eq!(interp.effective_override(), 0.0);
        // On the first line, strictly inside it: distance to the line below a nanometre.
        assert_eq!(line, 1);
        let dir = Vector3::new(120.0, 40.0, 0.0).normalize();
        let along = p.dot(&dir);
        assert!(
            along > 1.0 && along < Vector3::new(120.0, 40.0, 0.0).norm() - 1.0,
            "{profile:?}: held at {p:?}, not inside the line"
        );
        assert!(
            (p - dir * along).norm() <= 1e-9,
            "{profile:?}: {p:?} off the line"
        );
        assert_eq!(p, reference.position_at(interp.plan_time_s()));
        let held = p;
        for _ in 0..500 {
            assert_eq!(interp.update(&mut p), Status::Held { line: 1 });
            assert_eq!(p, held, "{profile:?}: the held point moved");
        }
        interp.resume().unwrap();
        interp.update(&mut p);
        assert!(interp.effective_override() > 0.0, "resume moves k at once");
        loop {
            if interp.update(&mut p) == Status::Finished {
                break;
            }
        }
        assert_eq!(p, reference.end_mm(), "{profile:?}: the end is exact");
        assert_eq!(interp.plan_time_s(), reference.duration_s());
    }
}

/// At 50 % a feed-limited program takes twice as long in real time and follows the same path.
#[test]
fn half_override_takes_twice_the_time_on_the_same_path() {
    let text = "G21 G90 G1 X50 F600\nM2\n";
    let prog = parse_program(text, "half.ngc", Vector3::zeros()).unwrap();
    let cfg = config(ProfileKind::SCurve);
    let plan = plan_with(&prog, &limits(), &cfg).unwrap();
    let duration_s = plan.duration_s();
    let ramp = OverrideRamp::for_machine(&limits(), &cfg).unwrap();
    let mut interp = Interpolator::new(plan, T).unwrap().with_override_ramp(ramp);
    interp.set_override(0.5).unwrap();
    let mut p = Vector3::zeros();
    let mut cycles = 0u64;
    while interp.update(&mut p) != Status::Finished {
        cycles += 1;
        assert!(p.y == 0.0 && p.z == 0.0);
    }
    let real_s = cycles as f64 * T;
    // The ramp from 100 % to 50 % at the start gains a little.
    assert!(
        (real_s - 2.0 * duration_s).abs() < ramp.ramp_time_s(1.0, 0.5),
        "{real_s} s at 50 % for a {duration_s} s plan"
    );
    assert_eq!(p, Vector3::new(50.0, 0.0, 0.0));
}

/// Above 100 % the runtime override stays at 100 % (time scaling above 1 breaks limits the
/// plan already uses); it is still what was asked for that the getter reports.
#[test]
fn overrides_above_100_percent_run_at_100_percent() {
    let text = "G21 G90 G1 X50 F6000\nM2\n";
    let prog = parse_program(text, "fast.ngc", Vector3::zeros()).unwrap();
    let cfg = config(ProfileKind::Trapezoid);
    let plan = plan_with(&prog, &limits(), &cfg).unwrap();
    let total = Interpolator::new(plan.clone(), T).unwrap().total_samples();
    let ramp = OverrideRamp::for_machine(&limits(), &cfg).unwrap();
    let mut interp = Interpolator::new(plan, T).unwrap().with_override_ramp(ramp);
    interp.set_override(1.5).unwrap();
    assert_eq!(interp.requested_override(), 1.5);
    let mut p = Vector3::zeros();
    let mut cycles = 0;
    loop {
        cycles += 1;
        if interp.update(&mut p) == Status::Finished {
            break;
        }
        assert_eq!(interp.effective_override(), 1.0);
    }
    assert_eq!(cycles, total);
    assert!(interp.set_override(f64::NAN).is_err());
    assert!(interp.set_override(-0.1).is_err());
    let mut bare = Interpolator::new(Plan::at_rest(Vector3::zeros()), T).unwrap();
    assert!(
        bare.hold()
            .unwrap_err()
            .to_string()
            .contains("need an override ramp")
    );
}
