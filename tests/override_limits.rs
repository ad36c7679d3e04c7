//! What an operator relies on from the feed override and the feed hold while a program runs:
//! whatever the program and whenever the override changes (0 to 200 %) or a hold or resume
//! comes, the setpoints keep every axis within its velocity and acceleration limits and, with
//! S-curves, its jerk limit (finite differences, within 1 %, as in `planner_limits`), and the
//! path within the machine's max feed; the change moves the effective override on the very
//! next cycle (above 100 %, where the plan leaves room); the program still ends exactly on its
//! end point.

use canmotion::gcode::parse_program;
use canmotion::interpolator::{Interpolator, MAX_OVERRIDE, OverrideRamp, Status};
use canmotion::planner::{Plan, PlannerConfig, ProfileKind, plan_with};
use nalgebra::Vector3;
use proptest::prelude::*;

#[path = "common/setpoints.rs"]
mod setpoints;

#[path = "common/random_programs.rs"]
mod random_programs;

use random_programs::{T, a_move, a_run_joined_at_speed, config, limits, program};

/// The plan of `text` on the test machine in `profile`, its planner configuration, and the
/// override ramp the machine allows.
fn planned(text: &str, profile: ProfileKind) -> (Plan, PlannerConfig, OverrideRamp) {
    let prog = parse_program(text, "test.ngc", Vector3::zeros()).unwrap();
    let cfg = config(profile);
    let plan = plan_with(&prog, &limits(), &cfg).unwrap();
    let ramp = OverrideRamp::for_machine(&limits(), &cfg).unwrap();
    (plan, cfg, ramp)
}

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
        4 => prop_oneof![Just(0.0), Just(1.0), Just(2.0), 0.0..=2.0f64].prop_map(Command::Override),
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
        // Above 100 % the plan may keep `k` where it is (it accelerates there).
        if let Some((before, target)) = pending.take()
            && !interp.is_finished()
            && before != target
            && (target <= 1.0 || before < 1.0)
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
                interp.requested_override().min(MAX_OVERRIDE)
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
        final_override in 0.2..=2.0f64,
    ) {
        check(&program(&moves), ProfileKind::Trapezoid, &schedule, final_override)?;
    }

    #[test]
    fn s_curve_setpoints_keep_the_limits_under_override_and_hold(
        moves in prop::collection::vec(a_move(), 1..30),
        schedule in a_schedule(),
        final_override in 0.2..=2.0f64,
    ) {
        check(&program(&moves), ProfileKind::SCurve, &schedule, final_override)?;
    }

    /// The same with axis filters longer than the default 8 ms (`[planner] axis_filter_ms`):
    /// a hold still stops within the limits once the filters have settled.
    #[test]
    fn s_curve_setpoints_with_longer_axis_filters_keep_the_limits_under_override_and_hold(
        moves in prop::collection::vec(a_move(), 1..30),
        schedule in a_schedule(),
        final_override in 0.2..=2.0f64,
        axis_filter_s in prop_oneof![Just(0.012), Just(0.016)],
    ) {
        let cfg = PlannerConfig { axis_filter_s, ..config(ProfileKind::SCurve) };
        check_with(&program(&moves), cfg, &schedule, final_override)?;
    }

    /// Long moves joined at speed: the middles of long elements planned at their whole
    /// acceleration (`Planner::split_for_acceleration`), under override, hold and resume.
    #[test]
    fn s_curve_runs_joined_at_speed_keep_the_limits_under_override_and_hold(
        text in a_run_joined_at_speed(),
        schedule in a_schedule(),
        final_override in 0.2..=2.0f64,
    ) {
        check(&text, ProfileKind::SCurve, &schedule, final_override)?;
    }

    #[test]
    fn smooth_setpoints_keep_the_limits_under_override_and_hold(
        moves in prop::collection::vec(a_move(), 1..30),
        schedule in a_schedule(),
        final_override in 0.2..=2.0f64,
    ) {
        check(&program(&moves), ProfileKind::Smooth, &schedule, final_override)?;
    }

    #[test]
    fn blended_corners_keep_the_limits_under_override_and_hold(
        moves in prop::collection::vec(a_move(), 1..30),
        schedule in a_schedule(),
        final_override in 0.2..=2.0f64,
    ) {
        // G64 P0.5 with a chord tolerance of 10 µm: many corners become arcs (trapezoid).
        let cfg = PlannerConfig { chord_tol_mm: 0.01, ..config(ProfileKind::Trapezoid) };
        let text = program(&moves).replacen("G64", "G64 P0.5", 1);
        check_with(&text, cfg, &schedule, final_override)?;
    }
}

/// A hold in the middle of a long line at full speed: standstill within the time a ramp with
/// the acceleration and jerk the cruise leaves unused predicts (plus a period of rounding), on
/// the line and short of its end, at the same point cycle after cycle; a resume takes the
/// program to its exact end.
#[test]
fn a_hold_stops_on_the_path_in_the_predicted_time_and_a_resume_finishes() {
    for profile in [
        ProfileKind::Trapezoid,
        ProfileKind::SCurve,
        ProfileKind::Smooth,
    ] {
        let text = "G21 G90 G64 G1 X120 Y40 F6000\nG1 X0 Y0\nM2\n";
        let (plan, _, ramp) = planned(text, profile);
        let reference = plan.clone();
        let mut interp = Interpolator::new(plan, T).unwrap().with_override_ramp(ramp);
        let mut p = Vector3::zeros();
        // Cruise on the first line, then hold.
        for _ in 0..150 {
            assert!(matches!(interp.update(&mut p), Status::Working { line: 1 }));
        }
        assert_eq!(interp.effective_override(), 1.0);
        interp.hold().unwrap();
        // The hold ramps down on the cruise, with the acceleration and jerk the profile leaves
        // unused there: `|k'|·v ≤ a`, `|k''|·v ≤ j` (`k'` over four periods for trapezoids).
        let limits_on_line = *reference.segments()[0].profile.unwrap().limits();
        let (a, j) = (limits_on_line.a_max_mm_s2(), limits_on_line.j_max_mm_s3());
        let d = a / 100.0;
        let quiet = OverrideRamp::new(
            d,
            if j.is_finite() {
                j / 100.0
            } else {
                d / (4.0 * T)
            },
        );
        let predicted_s = quiet.unwrap().ramp_time_s(1.0, 0.0);
        assert!(
            predicted_s < 0.6 * ramp.ramp_time_s(1.0, 0.0),
            "{profile:?}"
        );
        let mut cycles = 0u64;
        let line = loop {
            cycles += 1;
            match interp.update(&mut p) {
                Status::Held { line } => break line,
                Status::Working { .. } => {}
                other => panic!("{profile:?}: {other:?} while holding"),
            }
            // The jerk-limited mode's filters take their settling time on top.
            let settle_s = interp
                .smoothing()
                .map_or(0.0, |s| s.settle_periods() as f64 * T);
            assert!(
                cycles as f64 * T <= predicted_s + settle_s + T,
                "{profile:?}: still moving {cycles} cycles after the hold (ramp {predicted_s} s, filters {settle_s} s)"
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
    let (plan, _, ramp) = planned(text, ProfileKind::SCurve);
    let duration_s = plan.duration_s();
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

/// Runs `text` with the override set to `fraction` before the first sample, checking the
/// limits; the number of cycles, the highest speed of each axis, and the highest effective
/// override while the plan time is within the first segment's acceleration.
fn run_at(text: &str, profile: ProfileKind, fraction: f64) -> (u64, Vector3<f64>, f64) {
    let (plan, cfg, ramp) = planned(text, profile);
    let first = plan.segments()[0];
    let accel_end_s = first.start_time_s + first.profile.unwrap().phase_start_times_s()[3];
    let mut interp = Interpolator::new(plan.clone(), T)
        .unwrap()
        .with_override_ramp(ramp);
    interp.set_override(fraction).unwrap();
    let (mut p, mut prev) = (Vector3::zeros(), Vector3::zeros());
    let (mut cycles, mut fastest, mut k_accel) = (0, Vector3::zeros(), 0.0f64);
    loop {
        cycles += 1;
        let status = interp.update(&mut p);
        fastest = fastest.sup(&((p - prev).abs() / T));
        prev = p;
        if interp.plan_time_s() <= accel_end_s {
            k_accel = k_accel.max(interp.effective_override());
        }
        if status == Status::Finished {
            break;
        }
    }
    assert_eq!(p, plan.end_mm());
    let interp = Interpolator::new(plan, T).unwrap().with_override_ramp(ramp);
    let mut schedule = |k: u64, i: &mut Interpolator| {
        if k == 1 {
            i.set_override(fraction).map_err(|e| e.to_string())?;
        }
        Ok(())
    };
    setpoints::limits_hold_driven(interp, &limits(), &cfg, &mut schedule).unwrap();
    (cycles, fastest, k_accel)
}

/// Above 100 % a feed-limited line runs faster: its cruise at the programmed feed times the
/// override, and the whole program in less time, within the limits. While the plan accelerates
/// the override stays at 100 % (the plan uses the axes' acceleration there).
#[test]
fn an_override_above_100_percent_speeds_up_the_cruise_within_the_limits() {
    for profile in [ProfileKind::Trapezoid, ProfileKind::SCurve] {
        // X at 50 mm/s (F3000) on a 200 mm/s axis: 150 % gives 75 mm/s.
        let text = "G21 G90 G1 X200 F3000\nM2\n";
        let (at_100, fastest_100, _) = run_at(text, profile, 1.0);
        let (at_150, fastest_150, k_accel) = run_at(text, profile, 1.5);
        assert_eq!(
            k_accel, 1.0,
            "{profile:?}: above 100 % while the plan accelerates"
        );
        assert!(
            (fastest_100.x - 50.0).abs() < 0.01,
            "{profile:?}: {fastest_100:?}"
        );
        assert!(
            (fastest_150.x - 75.0).abs() < 0.01,
            "{profile:?}: {fastest_150:?} at 150 %"
        );
        // The cruise is most of the line: the time shrinks by about a third.
        let ratio = at_150 as f64 / at_100 as f64;
        assert!(
            ratio > 0.66 && ratio < 0.75,
            "{profile:?}: {at_150} against {at_100} cycles"
        );
    }
}

/// The override goes no faster than the machine: Y at 100 mm/s (F6000) on a 150 mm/s axis
/// reaches 150 mm/s at 200 %, not 200.
#[test]
fn an_override_above_100_percent_stops_at_the_axis_speed_limit() {
    for profile in [ProfileKind::Trapezoid, ProfileKind::SCurve] {
        let (_, fastest, _) = run_at("G21 G90 G1 Y300 F6000\nM2\n", profile, 2.0);
        let vy = limits().max_vel_mm_s.y;
        assert!(
            fastest.y <= vy * (1.0 + 1e-9) && fastest.y > 0.99 * vy,
            "{profile:?}: {fastest:?}"
        );
    }
}

/// The requested value is reported as asked, and bad values are refused.
#[test]
fn the_requested_override_is_reported_and_bad_values_refused() {
    let (plan, _, ramp) = planned("G21 G1 X5 F600\nM2\n", ProfileKind::Trapezoid);
    let mut interp = Interpolator::new(plan, T).unwrap().with_override_ramp(ramp);
    interp.set_override(2.5).unwrap();
    assert_eq!(interp.requested_override(), 2.5);
    assert_eq!(MAX_OVERRIDE, 2.0);
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

/// A dwell is not shortened above 100 %: at 200 % the machine stands still at the dwell's point
/// for the whole of `G4 P1`, while the moves around it run faster.
#[test]
fn a_dwell_lasts_its_time_above_100_percent() {
    let text = "G21 G90 G1 X40 F1200\nG4 P1\nG1 X80\nM2\n";
    let (plan, _, ramp) = planned(text, ProfileKind::Trapezoid);
    let at_100 = Interpolator::new(plan.clone(), T).unwrap().total_samples();
    let mut interp = Interpolator::new(plan, T).unwrap().with_override_ramp(ramp);
    interp.set_override(2.0).unwrap();
    let (mut p, mut cycles, mut still) = (Vector3::zeros(), 0u64, 0u64);
    loop {
        cycles += 1;
        let status = interp.update(&mut p);
        if p.x == 40.0 {
            still += 1;
        }
        if status == Status::Finished {
            break;
        }
    }
    assert!(
        still as f64 * T >= 1.0 - T,
        "stood {still} cycles at the dwell"
    );
    assert!(cycles < at_100, "{cycles} cycles at 200 % against {at_100}");
}

/// The README's figure for a hold on the demo machine: at 200 mm/s on an X line (`G1 X150
/// F12000`, held in the cruise) the motion stands still within 0.15 s and 15 mm, where the
/// general ramp alone takes 0.5 s. `cargo test --release --test override_limits
/// a_hold_on_the_demo_machine -- --nocapture` prints the figures.
#[test]
fn a_hold_on_the_demo_machine_stops_within_0_15_s_on_a_line() {
    let m = canmotion::config::Machine::demo();
    let l = canmotion::gateway::limits(&m);
    let ramp = OverrideRamp::for_machine(&l, &m.planner).unwrap();
    let prog = parse_program("G21 G90 G1 X150 F12000\nM2\n", "d.ngc", Vector3::zeros()).unwrap();
    let plan = plan_with(&prog, &l, &m.planner).unwrap();
    let mut interp = Interpolator::new(plan, m.cycle_s())
        .unwrap()
        .with_override_ramp(ramp);
    let mut p = Vector3::zeros();
    for _ in 0..100 {
        interp.update(&mut p);
    }
    let from = p.x;
    interp.hold().unwrap();
    let mut cycles = 0u64;
    while !matches!(interp.update(&mut p), Status::Held { .. }) {
        cycles += 1;
    }
    let (took_s, travel_mm) = (cycles as f64 * m.cycle_s(), p.x - from);
    println!("hold at 200 mm/s: {took_s:.3} s, {travel_mm:.1} mm");
    assert!(
        took_s <= 0.15 && travel_mm <= 15.0,
        "{took_s} s, {travel_mm} mm"
    );
    assert!(ramp.ramp_time_s(1.0, 0.0) >= 0.5);
}
