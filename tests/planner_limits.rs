//! What a machine builder relies on from the look-ahead: whatever the program (long and tiny
//! lines, reversals, arcs, changing feeds), the setpoints sampled every period keep every
//! axis within its velocity and acceleration limits and, with S-curves, its jerk limit, all
//! computed by finite differences as a drive sees them; nothing is NaN; the end is exact.
//! Seeded random programs (proptest), trapezoid and S-curve modes.

use canmotion::gcode::{Program, parse_program};
use canmotion::interpolator::{Interpolator, OverrideRamp};
use canmotion::planner::{Limits, Plan, PlannerConfig, ProfileKind, SegmentPath, plan_with};
use nalgebra::Vector3;
use proptest::prelude::*;

#[path = "common/setpoints.rs"]
mod setpoints;

#[path = "common/random_programs.rs"]
mod random_programs;

#[path = "common/path_deviation.rs"]
mod path_deviation;

use random_programs::{
    T, a_kinked_polyline, a_move, a_run_joined_at_speed, config, limits, program,
};

/// The setpoints of `plan` (of `prog`) keep every axis's limits (`common::setpoints`) and
/// stay within the tolerance of the programmed path (`common::path_deviation`).
fn limits_and_path_hold(prog: &Program, plan: Plan, l: &Limits, cfg: &PlannerConfig) {
    setpoints::limits_hold(plan.clone(), l, cfg).unwrap();
    path_deviation::measure_items(prog.start_mm, &prog.items, plan, cfg)
        .unwrap()
        .check()
        .unwrap();
}

/// The filters of `Smoothing::for_machine` on the test machine: the axis filters' `T_k`
/// (8 ms in whole periods, at least 2) and the time-law filter's `T_f` (the smallest A/J,
/// 37.5 ms, in whole periods).
fn filter_times_s() -> (f64, f64) {
    (
        (0.008 / T).ceil().max(2.0) * T,
        (0.0375f64 / T - 1e-9).ceil() * T,
    )
}

/// The plan of `text` (jerk-limited, the random programs' limits), and the speed at the end
/// of line `line`'s last straight segment (the part of a line within the time-law filter's
/// reach of the next element may be split off).
fn plan_to_line_end(text: &str, line: usize) -> (Program, Plan, f64) {
    let cfg = config(ProfileKind::SCurve);
    let prog = parse_program(text, "junction.ngc", Vector3::zeros()).unwrap();
    let plan = plan_with(&prog, &limits(), &cfg).unwrap();
    let v_end = plan
        .segments()
        .iter()
        .rfind(|s| s.line == line && matches!(s.path, SegmentPath::Line { .. }))
        .unwrap()
        .v_end_mm_s;
    (prog, plan, v_end)
}

/// How much lower than its cap the time-law filter's rounding plans a V-shaped dip between
/// two lines along X: `A·T_f/4` at their acceleration `J_x·share·T_f/2`.
fn line_dip_mm_s(cfg: &PlannerConfig) -> f64 {
    let (_, t_f) = filter_times_s();
    0.25 * (0.5 * cfg.path_acc_share * cfg.max_jerk_mm_s3.x * t_f) * t_f
}

/// Plans `text` and checks its setpoints (see `common::setpoints`).
fn check(text: &str, profile: ProfileKind) -> Result<(), TestCaseError> {
    check_with(text, config(profile))
}

fn check_with(text: &str, cfg: PlannerConfig) -> Result<(), TestCaseError> {
    let prog = parse_program(text, "random.ngc", Vector3::zeros())
        .map_err(|e| TestCaseError::fail(format!("{e}\n{text}")))?;
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

    #[test]
    fn with_integer_periods_too(moves in prop::collection::vec(a_move(), 1..20), s_curve in any::<bool>()) {
        let profile = if s_curve { ProfileKind::SCurve } else { ProfileKind::Trapezoid };
        check_with(&program(&moves), PlannerConfig { integer_periods: true, ..config(profile) })?;
    }
}

/// Plans `text` and checks the distance of its setpoints from the programmed path (see
/// `common::path_deviation`).
fn check_tolerance(text: &str, profile: ProfileKind) -> Result<(), TestCaseError> {
    let cfg = config(profile);
    let prog = parse_program(text, "random.ngc", Vector3::zeros())
        .map_err(|e| TestCaseError::fail(format!("{e}\n{text}")))?;
    let plan = plan_with(&prog, &limits(), &cfg).map_err(|e| TestCaseError::fail(e.to_string()))?;
    let report = path_deviation::measure_items(prog.start_mm, &prog.items, plan, &cfg)
        .map_err(|e| TestCaseError::fail(e.to_string()))?;
    report
        .check()
        .map_err(|e| TestCaseError::fail(format!("{e}\n{text}")))
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 96, ..ProptestConfig::default() })]

    /// Issue 11's contour acceptance on random programs (bare G64: the default tolerance),
    /// jerk-limited mode.
    #[test]
    fn s_curve_setpoints_stay_within_the_tolerance(moves in prop::collection::vec(a_move(), 1..30)) {
        check_tolerance(&program(&moves), ProfileKind::SCurve)?;
    }

    /// The same in the trapezoid mode.
    #[test]
    fn trapezoid_setpoints_stay_within_the_tolerance(moves in prop::collection::vec(a_move(), 1..30)) {
        check_tolerance(&program(&moves), ProfileKind::Trapezoid)?;
    }
}

/// Plans `text` in the jerk-limited mode with axis filters of `axis_filter_s` and checks its
/// setpoints' limits and their distance from the programmed path.
fn check_axis_filter(text: &str, axis_filter_s: f64) -> Result<(), TestCaseError> {
    let cfg = PlannerConfig {
        axis_filter_s,
        ..config(ProfileKind::SCurve)
    };
    let fail = |e: String| TestCaseError::fail(format!("{e}\n{text}"));
    let prog =
        parse_program(text, "random.ngc", Vector3::zeros()).map_err(|e| fail(e.to_string()))?;
    let plan = plan_with(&prog, &limits(), &cfg).map_err(|e| fail(e.to_string()))?;
    setpoints::limits_hold(plan.clone(), &limits(), &cfg).map_err(fail)?;
    path_deviation::measure_items(prog.start_mm, &prog.items, plan, &cfg)
        .map_err(|e| fail(e.to_string()))?
        .check()
        .map_err(|e| fail(e.to_string()))
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    /// `[planner] axis_filter_ms`: with axis filters longer than the default 8 ms (up to the
    /// 16 ms allowed), random programs and kinked polylines keep every axis's limits and
    /// the tolerance.
    #[test]
    fn longer_axis_filters_keep_the_limits_and_the_tolerance(
        moves in prop::collection::vec(a_move(), 1..30),
        polyline in a_kinked_polyline(),
        axis_filter_s in prop_oneof![Just(0.01), Just(0.012), Just(0.016)],
    ) {
        check_axis_filter(&program(&moves), axis_filter_s)?;
        check_axis_filter(&polyline, axis_filter_s)?;
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

/// Distance from `q` to the polyline through `points`.
fn distance_to_polyline(q: Vector3<f64>, points: &[Vector3<f64>]) -> f64 {
    points
        .windows(2)
        .map(|w| {
            let d = w[1] - w[0];
            let l2 = d.norm_squared();
            let s = if l2 > 0.0 {
                ((q - w[0]).dot(&d) / l2).clamp(0.0, 1.0)
            } else {
                0.0
            };
            (w[0] + d * s - q).norm()
        })
        .fold(f64::INFINITY, f64::min)
}

/// Lines under `G64 P<tol>`: the setpoints keep the limits and never leave the programmed
/// polyline by more than the tolerance; the blend arcs are counted.
fn check_blends(
    offsets: &[(Vector3<f64>, f64)],
    tol_mm: f64,
    profile: ProfileKind,
) -> Result<(usize, f64), TestCaseError> {
    let mut text = format!("G21 G90 G17 G64 P{tol_mm:.4}\n");
    let mut points = vec![Vector3::zeros()];
    let mut at = Vector3::zeros();
    for (d, f) in offsets {
        let next = at + d;
        let written: Vector3<f64> = next.map(|c| format!("{c:.6}").parse().unwrap());
        if written == at {
            continue;
        }
        at = written;
        points.push(at);
        text.push_str(&format!(
            "G1 X{:.6} Y{:.6} Z{:.6} F{:.3}\n",
            at.x,
            at.y,
            at.z,
            f * 60.0
        ));
    }
    text.push_str("M2\n");
    let prog = parse_program(&text, "blend.ngc", Vector3::zeros())
        .map_err(|e| TestCaseError::fail(format!("{e}\n{text}")))?;
    // A chord tolerance of 10 µm lets arcs run fast enough to be worth blending.
    let cfg = PlannerConfig {
        chord_tol_mm: 0.01,
        ..config(profile)
    };
    let plan = plan_with(&prog, &limits(), &cfg).map_err(|e| TestCaseError::fail(e.to_string()))?;
    let arcs = plan
        .segments()
        .iter()
        .filter(|s| matches!(s.path, SegmentPath::Arc(_)))
        .count();
    // The active tolerance: G64 P, or under P0 the chord tolerance, which the jerk-limited
    // mode's axis filters may take at a corner taken at speed (no blend arc rounds it).
    let allowed_mm = if tol_mm > 0.0 || plan.smoothing().is_none() {
        tol_mm
    } else {
        cfg.chord_tol_mm
    };
    let mut interp = Interpolator::new(plan.clone(), T).unwrap();
    let mut q = Vector3::zeros();
    while !interp.is_finished() {
        interp.update(&mut q);
        let d = distance_to_polyline(q, &points);
        if d > allowed_mm + 1e-9 {
            return Err(TestCaseError::fail(format!(
                "sample {q:?} is {d} mm off the programmed path (G64 P{tol_mm})\n{text}"
            )));
        }
    }
    let duration_s = plan.duration_s();
    setpoints::limits_hold(plan, &limits(), &cfg).map_err(TestCaseError::fail)?;
    Ok((arcs, duration_s))
}

fn a_line() -> impl Strategy<Value = (Vector3<f64>, f64)> {
    let len = prop_oneof![0.05..2.0f64, 2.0..40.0f64];
    let dir = (-1.0..1.0f64, -1.0..1.0f64, -0.3..0.3f64);
    (len, dir, 20.0..180.0f64).prop_map(|(l, (x, y, z), f)| {
        let d = Vector3::new(x, y, z);
        let d = if d.norm() < 1e-3 {
            Vector3::x()
        } else {
            d.normalize()
        };
        (d * l, f)
    })
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    #[test]
    fn blended_corners_stay_within_g64_p_and_the_limits(
        lines in prop::collection::vec(a_line(), 2..25),
        tol in prop_oneof![0.005..0.1f64, 0.1..3.0f64],
        s_curve in any::<bool>(),
    ) {
        let profile = if s_curve { ProfileKind::SCurve } else { ProfileKind::Trapezoid };
        check_blends(&lines, tol, profile)?;
    }
}

#[test]
fn a_square_under_g64_p_is_rounded_where_that_is_faster() {
    let square: Vec<(Vector3<f64>, f64)> = [(1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0)]
        .iter()
        .map(|&(x, y)| (Vector3::new(x, y, 0.0) * 50.0, 150.0))
        .collect();
    for profile in [ProfileKind::Trapezoid, ProfileKind::SCurve] {
        let (sharp_arcs, sharp_s) = check_blends(&square, 0.0, profile).unwrap();
        assert_eq!(sharp_arcs, 0, "G64 P0 keeps the corners");
        // 1 µm would allow only arcs slower than the sharp corner's junction speed.
        let (arcs, t) = check_blends(&square, 0.001, profile).unwrap();
        assert_eq!((arcs, t), (0, sharp_s), "{profile:?}");
        // 1 mm: never slower than the sharp corners.
        let (arcs, t) = check_blends(&square, 1.0, profile).unwrap();
        assert!(t <= sharp_s, "{profile:?}: {t} s against {sharp_s} s sharp");
        if profile == ProfileKind::Trapezoid {
            // With a trapezoid the three corners are rounded, and that pays.
            assert_eq!(arcs, 3);
            assert!(t < sharp_s - 0.01, "{t} s against {sharp_s} s sharp");
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    /// Issue 11, item 4: a helix's limits come from its true curvature `κ = r/(r² + c²)` and its
    /// torsion, not from its projected circle. Steep helices (small radius, long pitch, as in
    /// LinuxCNC's `sam_violation1.ngc`) in every plane, both profiles: the setpoints keep every
    /// axis's velocity, acceleration and jerk, and the helix runs faster than the projected
    /// circle's centripetal limit `√(A·√3/2·r)` would allow once the pitch dominates.
    #[test]
    fn steep_helices_keep_the_limits_and_run_at_their_curvature(
        radius in 0.2..5.0f64,
        pitch_per_turn in 1.0..60.0f64,
        turns in 0.25..3.0f64,
        plane in 0..3usize,
        s_curve in any::<bool>(),
    ) {
        let (code, a, b, n, i_word, j_word) = [
            ("G17", 'X', 'Y', 'Z', 'I', 'J'),
            ("G18", 'Z', 'X', 'Y', 'K', 'I'),
            ("G19", 'Y', 'Z', 'X', 'J', 'K'),
        ][plane];
        let theta = turns * std::f64::consts::TAU;
        let text = format!(
            "G21 G90 {code} G0 {a}{r:.6} {b}0 {n}0\nG3 {a}{ea:.6} {b}{eb:.6} {n}{h:.6} {i_word}{ci:.6} {j_word}0 P{p} F6000\nM2\n",
            r = radius,
            ea = radius * theta.cos(),
            eb = radius * theta.sin(),
            h = pitch_per_turn * turns,
            ci = -radius,
            p = turns.ceil() as u32,
        );
        let profile = if s_curve { ProfileKind::SCurve } else { ProfileKind::Trapezoid };
        let cfg = config(profile);
        let prog = parse_program(&text, "helix.ngc", Vector3::zeros())
            .map_err(|e| TestCaseError::fail(format!("{e}\n{text}")))?;
        let plan = plan_with(&prog, &limits(), &cfg).map_err(|e| TestCaseError::fail(e.to_string()))?;
        let peak = plan
            .segments()
            .iter()
            .filter(|s| matches!(s.path, SegmentPath::Arc(_)))
            .map(|s| s.v_peak_mm_s)
            .fold(0.0, f64::max);
        let c = pitch_per_turn / std::f64::consts::TAU;
        let cos2 = radius * radius / (radius * radius + c * c);
        // The smallest acceleration share the helix can see, and the circle's bound.
        let a_min = 0.75 * 1000.0;
        let circle_v = (a_min * 0.75f64.sqrt() * radius).sqrt();
        if cos2 < 0.05 && !s_curve && turns > 1.0 {
            prop_assert!(peak > 1.5 * circle_v, "peak {peak} mm/s, projected circle {circle_v} mm/s\n{text}");
        }
        setpoints::limits_hold(plan, &limits(), &cfg).map_err(|e| TestCaseError::fail(format!("{e}\n{text}")))?;
    }
}

/// Issue 11, item 4: a steep helix moves the axes of its plane by `cos α` of its path only,
/// so it may accelerate along its axis almost as a straight line does: its tangential
/// acceleration is what each axis leaves beside the centripetal part at its top speed
/// (`a_t·|Tᵢ| + v²κ·|Nᵢ| ≤ s·Aᵢ`), not half the budget of the plane's axes (LinuxCNC's
/// tangential ratio). The helix of LinuxCNC's `sam_violation1.ngc` (a G2 of 0.86 mm radius in
/// G18 rising 85.6 mm along Y over 26°) took 0.953 s in trapezoid mode against 0.559 s for
/// the straight line of its length; both profiles now take at most 5 % longer than the line,
/// and keep every axis's limits.
#[test]
fn a_steep_helix_accelerates_along_its_axis_as_a_line_does() {
    let l = limits();
    for profile in [ProfileKind::Trapezoid, ProfileKind::SCurve] {
        let cfg = config(profile);
        let helix = "G21 G90 G18 G0 X77.876 Y0 Z-2.433\n\
             G2 X78.232 Y85.598 Z-2.167 I-0.320 K0.798 F12000\nM2\n";
        let line = "G21 G90 G18 G0 X77.876 Y0 Z-2.433\nG1 X77.876 Y85.599 Z-2.433 F12000\nM2\n";
        let time = |text: &str| {
            let prog = parse_program(text, "helix.ngc", Vector3::zeros()).unwrap();
            let plan = plan_with(&prog, &l, &cfg).unwrap();
            let moving = plan
                .segments()
                .iter()
                .filter(|s| s.line == 2 && s.profile.is_some())
                .map(|s| s.duration_s())
                .sum::<f64>();
            setpoints::limits_hold(plan, &l, &cfg).unwrap();
            moving
        };
        let (helix_s, line_s) = (time(helix), time(line));
        assert!(
            helix_s <= 1.05 * line_s,
            "{profile:?}: the helix {helix_s} s, the line {line_s} s"
        );
    }
}

/// Issue 11, item 2: a bare `G64` (LinuxCNC's "no limit") allows the machine's
/// `default_tolerance_mm` in the jerk-limited mode, never more: there the 1° corners of a
/// 360-gon are passed faster than under `G64 P0`, whose corners keep within `chord_tol_mm`.
/// Trapezoids plan both alike. A program without G61/G64 words starts in a bare `G64`, as in
/// LinuxCNC (it started in `G64 P0` until session 30).
#[test]
fn bare_g64_deviates_within_the_default_tolerance() {
    let corners: Vec<Vector3<f64>> = (0..=360)
        .map(|k| {
            let a = f64::from(k).to_radians();
            Vector3::new(20.0 * a.cos(), 20.0 * a.sin(), 0.0)
        })
        .map(|p| p.map(|c| format!("{c:.6}").parse().unwrap()))
        .collect();
    let run = |g64: &str, profile: ProfileKind| {
        let mut text = format!("G21 G90 G17 {g64} F9000\n");
        for p in &corners[1..] {
            text.push_str(&format!("G1 X{:.6} Y{:.6}\n", p.x, p.y));
        }
        text.push_str("M2\n");
        let prog = parse_program(&text, "polygon.ngc", corners[0]).unwrap();
        let cfg = PlannerConfig {
            default_tolerance_mm: 0.02,
            ..config(profile)
        };
        let plan = plan_with(&prog, &limits(), &cfg).unwrap();
        let mut interp = Interpolator::new(plan.clone(), T).unwrap();
        let mut q = Vector3::zeros();
        let mut worst: f64 = 0.0;
        while !interp.is_finished() {
            interp.update(&mut q);
            worst = worst.max(distance_to_polyline(q, &corners));
        }
        setpoints::limits_hold(plan.clone(), &limits(), &cfg).unwrap();
        (worst, plan.duration_s())
    };
    let (bare_mm, bare_s) = run("G64", ProfileKind::SCurve);
    let (exact_mm, exact_s) = run("G64 P0", ProfileKind::SCurve);
    assert!(bare_mm <= 0.02 + 1e-9, "{bare_mm} mm off the polygon");
    // A program that writes neither G61 nor G64 runs in LinuxCNC's start mode, a bare G64.
    let (unsaid_mm, unsaid_s) = run("", ProfileKind::SCurve);
    assert_eq!((unsaid_mm, unsaid_s), (bare_mm, bare_s), "no G64 word");
    let chord_tol_mm = config(ProfileKind::SCurve).chord_tol_mm;
    assert!(
        exact_mm <= chord_tol_mm + 1e-9,
        "{exact_mm} mm off the polygon"
    );
    assert!(
        bare_s < exact_s,
        "bare G64 {bare_s} s against G64 P0 {exact_s} s"
    );
    let (_, bare_s) = run("G64", ProfileKind::Trapezoid);
    let (_, exact_s) = run("G64 P0", ProfileKind::Trapezoid);
    assert_eq!(
        bare_s, exact_s,
        "trapezoids plan a bare G64 as G64 P0 for now"
    );
}

/// Issue 11: the jerk-limited mode's axis filters would pull a circle towards its centre by
/// `v²·κ·σ²/2` (3.8 µm for 60 mm/s on a 5 mm radius at `T_k` = 8 ms); the interpolator moves
/// their input out by exactly that, so an arc runs at its own limits (centripetal, jerk,
/// chord) under `G61` too, and stays within a fraction of a micrometre of its circle. Before
/// the pre-compensation the arc was slowed until the pull fitted `chord_tol_mm`.
#[test]
fn arcs_keep_to_their_circle_at_their_own_speed_limits() {
    for r in [5.0, 20.0, 50.0] {
        let text = format!("G21 G90 G17 G61\nG2 X0 Y0 I{r} J0 F9000\nM2\n");
        let prog = parse_program(&text, "circle.ngc", Vector3::zeros()).unwrap();
        let centre = Vector3::new(r, 0.0, 0.0);
        let sample = |profile: ProfileKind| {
            let cfg = config(profile);
            let plan = plan_with(&prog, &limits(), &cfg).unwrap();
            let peak = plan
                .segments()
                .iter()
                .map(|s| s.v_peak_mm_s)
                .fold(0.0, f64::max);
            let mut interp = Interpolator::new(plan.clone(), T).unwrap();
            let mut q = Vector3::zeros();
            let mut worst: f64 = 0.0;
            while !interp.is_finished() {
                interp.update(&mut q);
                worst = worst.max(((q - centre).norm() - r).abs());
            }
            setpoints::limits_hold(plan, &limits(), &cfg).unwrap();
            (worst, peak)
        };
        let (worst_mm, peak) = sample(ProfileKind::SCurve);
        let (_, trapezoid_peak) = sample(ProfileKind::Trapezoid);
        assert!(worst_mm < 1e-4, "r = {r}: {worst_mm} mm off the circle");
        // The trapezoid's peak is the centripetal or feed limit; the jerk-limited one may be
        // lower only by the jerk of following the curve, v³/r² ≤ J/4 (and its share rules).
        let j = config(ProfileKind::SCurve).max_jerk_mm_s3;
        let jerk_bound = (0.25 * 0.75 * j.x.min(j.y) * r * r).cbrt();
        assert!(
            peak >= 0.999 * trapezoid_peak.min(jerk_bound),
            "r = {r}: {peak} mm/s against {trapezoid_peak} (jerk bound {jerk_bound})"
        );
    }
}

/// Issue 11: consecutive moves from rest to rest (each planned alone, as an exact S-curve) at
/// sharp corners under a tiny tolerance, as CAM writes engraving. Through the axis filters
/// the end of one would mix with the start of the next and cut the corner (0.38 µm on
/// LinuxCNC's `546_simplfied.ngc`, against its `G64 P0.0001`), so the filters settled at
/// each corner first (14 ms at 1 ms). But each exact S-curve keeps the limits and its path on
/// its own: where the filters have settled, a move alone bypasses them and leaves nothing in
/// them, so the next starts at once, nothing stands between them or at the end, and every
/// setpoint lies on the polyline (`546_simplfied.ngc` 1.305 → 1.123 s at 1 ms).
#[test]
fn moves_alone_run_back_to_back_on_their_exact_path() {
    let corners = [
        Vector3::new(0.724, 12.368, 0.0),
        Vector3::new(0.678, 12.278, 0.0),
        Vector3::new(0.557, 12.351, 0.0),
        Vector3::new(0.564, 12.384, 0.0),
        Vector3::new(0.707, 12.315, 0.0),
        Vector3::new(0.608, 12.398, 0.0),
        Vector3::new(0.668, 12.412, 0.0),
    ];
    let mut text = String::from("G21 G90 G17 G64 P0.0001 F800\n");
    for p in &corners[1..] {
        text.push_str(&format!("G1 X{:.3} Y{:.3}\n", p.x, p.y));
    }
    text.push_str("M2\n");
    let prog = parse_program(&text, "zigzag.ngc", corners[0]).unwrap();
    let cfg = config(ProfileKind::SCurve);
    let plan = plan_with(&prog, &limits(), &cfg).unwrap();
    let segs = plan.segments();
    assert_eq!(
        segs.len(),
        corners.len() - 1,
        "stands between the moves: {segs:#?}"
    );
    for s in segs {
        assert!(
            s.length_mm > 0.0 && !s.time_law && !s.axis_filters,
            "line {}: a move alone through the filters",
            s.line
        );
    }
    let mut interp = Interpolator::new(plan.clone(), T).unwrap();
    let mut q = Vector3::zeros();
    let mut worst: f64 = 0.0;
    while !interp.is_finished() {
        interp.update(&mut q);
        worst = worst.max(distance_to_polyline(q, &corners));
    }
    assert!(worst <= 1e-9, "{worst} mm off the zigzag");
    assert_eq!(q, corners[corners.len() - 1]);
    setpoints::limits_hold(plan, &limits(), &cfg).unwrap();
}

/// A move from rest to rest takes more of each axis than `path_acc_share`: the share keeps
/// the rest for the velocity steps of junctions passed at speed, which such a move has none
/// of, and for the feed override's ramp, whose terms it leaves room for with its own peaks
/// (`Planner::alone_at_axes`). On the demo machine a rapid of 50.8 mm along X then runs at
/// more than 1500 mm/s² and ends sooner than at the share; and a hold (or a lower override)
/// asked at any point of it, while it accelerates, cruises or brakes, keeps every axis's
/// limits at 1 ms, as does the resume. With the axes' whole limits instead, the hold asked
/// at sample 50 (while it accelerates) made X's jerk 51 101 mm/s³ against 50 000.
#[test]
fn a_move_alone_takes_the_axes_beyond_the_share_and_keeps_the_override_ramp_s_room() {
    let (l, cfg) = demo_s_curve();
    let text = "G21 G90 G17 G64 P0.01\nG0 X-50.8\nG1 X-4 F3000\nG1 X10 Y1\nM2\n";
    let prog = parse_program(text, "rapid.ngc", Vector3::zeros()).unwrap();
    let plan = plan_with(&prog, &l, &cfg).unwrap();
    let first = plan.segments()[0];
    let profile = first.profile.expect("the rapid moves");
    assert!(!first.time_law, "the rapid runs alone");
    let share = cfg.path_acc_share;
    assert!(profile.limits().a_max_mm_s2() > share * l.max_acc_mm_s2.x);
    let at_share = canmotion::planner::profile::plan(
        first.length_mm,
        0.0,
        0.0,
        &canmotion::planner::profile::ProfileLimits::new(
            profile.limits().v_max_mm_s(),
            share * l.max_acc_mm_s2.x,
            share * cfg.max_jerk_mm_s3.x,
            profile.limits().shape(),
        )
        .unwrap(),
    )
    .unwrap();
    assert!(
        first.duration_s() < 0.99 * at_share.duration_s(),
        "{} s against {} s at the share",
        first.duration_s(),
        at_share.duration_s()
    );
    holds_keep_the_limits(&plan, first.duration_s(), 7, &l, &cfg);
}

/// The same for arcs and helices: a helix of 3 mm radius rising 40 mm, run alone from rest to
/// rest, takes its limits from a larger share of the axes only where its centripetal
/// acceleration, the jerk of following it and the ramp's terms all fit (phase by phase), so a
/// hold asked anywhere on it keeps every axis's limits at 1 ms, as does the resume. Taken
/// towards the axes' whole limits without that check, the hold asked at sample 37 made Z's
/// jerk 20 273 mm/s³ against 20 000.
#[test]
fn an_arc_alone_keeps_the_override_ramp_s_room() {
    let (l, cfg) = demo_s_curve();
    let text = "G21 G90 G17 G61\nG2 X6 Y0 Z40 I3 J0 F12000\nM2\n";
    let prog = parse_program(text, "arc.ngc", Vector3::zeros()).unwrap();
    let plan = plan_with(&prog, &l, &cfg).unwrap();
    let first = plan.segments()[0];
    assert!(matches!(first.path, SegmentPath::Arc(_)) && !first.time_law);
    holds_keep_the_limits(&plan, first.duration_s(), 3, &l, &cfg);
}

/// A hold asked at every `step`-th sample of the first `span_s` of `plan` (and a resume 400
/// samples later) keeps every axis's limits, sampled at the planner's period.
fn holds_keep_the_limits(plan: &Plan, span_s: f64, step: usize, l: &Limits, cfg: &PlannerConfig) {
    let ramp = OverrideRamp::for_machine(l, cfg).unwrap();
    let t = cfg.period_s;
    let end = (span_s / t).ceil() as u64;
    for hold_at in (1..end).step_by(step) {
        let interp = Interpolator::new(plan.clone(), t)
            .unwrap()
            .with_override_ramp(ramp);
        let mut drive = |k: u64, interp: &mut Interpolator| {
            if k == hold_at {
                interp.hold().map_err(|e| e.to_string())?;
            }
            if k == hold_at + 400 {
                interp.resume().map_err(|e| e.to_string())?;
            }
            Ok(())
        };
        setpoints::limits_hold_driven(interp, l, cfg, &mut drive)
            .unwrap_or_else(|e| panic!("hold at sample {hold_at}: {e}"));
    }
}

/// Where a move alone has bypassed the axis filters, the filtered move after it turns them
/// on at rest: they start settled at the point the move ended, exactly. They started at the
/// latest sample, which a move ending on a sample (that sample already belongs to the next
/// segment) left a period short of its end: 6–8 nm on the demo machine, and the next move's
/// first samples pulled that in as a jerk of up to 16 % over X's limit (LinuxCNC's
/// `rickg-arcs.ngc`, found with the moves alone at the axes' whole limits). Here the rapid's
/// length is found so that it ends on a sample, and the sample there is its end point.
#[test]
fn the_axis_filters_turn_on_at_the_exact_end_of_a_move_alone() {
    let (l, cfg) = demo_s_curve();
    let plan_of = |x_mm: f64| {
        let text = format!("G21 G90 G17 G64 P0.01\nG0 X{x_mm}\nG1 X10 F3000\nG1 X20 Y1\nM2\n");
        let prog = parse_program(&text, "rapid.ngc", Vector3::zeros()).unwrap();
        plan_with(&prog, &l, &cfg).unwrap()
    };
    // The rapid's duration grows with its length: bisect for 400 periods exactly.
    let t = cfg.period_s;
    let target_s = 400.0 * t;
    let (mut lo, mut hi) = (-80.0, -10.0);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if plan_of(mid).segments()[0].duration_s() > target_s {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let plan = plan_of(hi);
    let first = plan.segments()[0];
    assert!(
        !first.time_law && !first.axis_filters,
        "a move alone, filters bypassed"
    );
    assert!(
        (first.end_time_s() - target_s).abs() < 1e-12,
        "{}",
        first.end_time_s()
    );
    assert!(plan.segments()[1].axis_filters, "the next move is filtered");
    let mut interp = Interpolator::new(plan.clone(), t).unwrap();
    let mut q = Vector3::zeros();
    for _ in 0..400 {
        interp.update(&mut q);
    }
    assert!(
        (q - first.end_mm).norm() < 1e-12,
        "{q:?} at the rapid's end {:?}",
        first.end_mm
    );
    setpoints::limits_hold(plan, &l, &cfg).unwrap();
}

/// The other side of `moves_alone_run_back_to_back_on_their_exact_path`: a move alone that
/// starts while the axis filters still hold a filtered run (stopped at a sharp corner, the
/// plan standing only until the time-law filter has settled) keeps them on, so nothing
/// steps. Where their mix with the next move could cut the corner beyond the tolerance
/// (`G64 P0.0001`) they settle there. The planner counts the filters' settling time from the
/// first sample standing at a move's end, up to a period after it: counted from the end, it
/// took the move after such a stand as bypassing filters that had not settled, the
/// interpolator kept them on, and the corner after it was cut by 0.12 µm (found by this test
/// in session 30, after the bypass had landed that session; the corpus had not met it).
/// Every limit holds at 1 ms and the polyline keeps its tolerance.
#[test]
fn a_move_alone_after_a_filtered_run_keeps_the_filters_until_they_settle() {
    let (l, cfg) = demo_s_curve();
    let corners = [
        Vector3::new(0.0, 0.0, 0.0),
        Vector3::new(10.0, 0.0, 0.0),
        Vector3::new(20.0, 0.3, 0.0),
        Vector3::new(20.0, 10.0, 0.0),
        Vector3::new(19.0, 10.0, 0.0),
        Vector3::new(19.0, 11.0, 0.0),
    ];
    for p_mm in ["0.0001", "0.05"] {
        // The run under P0.05 (its slight kink passed at speed), the moves alone under P.
        let mut text = String::from("G21 G90 G17 G64 P0.05 F3000\n");
        for (k, p) in corners[1..].iter().enumerate() {
            let mode = if k == 2 {
                format!("G64 P{p_mm} ")
            } else {
                String::new()
            };
            text += &format!("{mode}G1 X{:.3} Y{:.3}\n", p.x, p.y);
        }
        text += "M2\n";
        let prog = parse_program(&text, "run.ngc", corners[0]).unwrap();
        let plan = plan_with(&prog, &l, &cfg).unwrap();
        let moving = |line: usize| {
            plan.segments()
                .iter()
                .find(|s| s.line == line && s.profile.is_some())
                .unwrap()
        };
        // The run is filtered and stops; the move alone after it starts before the axis
        // filters have settled, and keeps them.
        assert!(
            moving(3).time_law && !moving(4).time_law,
            "{:#?}",
            plan.segments()
        );
        assert!(moving(4).axis_filters, "line 4 bypassed unsettled filters");
        if p_mm == "0.0001" {
            // Its mix with the next move would cut the corner: the filters settle there
            // (with a period to spare), and the moves alone after it bypass them.
            let segs = plan.segments();
            let after_4 = segs
                .iter()
                .position(|s| std::ptr::eq(s, moving(4)))
                .unwrap()
                + 1;
            let stand_s: f64 = segs[after_4..]
                .iter()
                .take_while(|s| s.profile.is_none())
                .map(|s| s.duration_s())
                .sum();
            // Two moving averages of 8 ms at 1 ms settle in 14 periods.
            assert!(stand_s >= 0.014 - 1e-9, "a stand of {stand_s} s");
        }
        limits_and_path_hold(&prog, plan, &l, &cfg);
    }
}

/// Issue 11: on an arc the jerk of the motion is `(j_t − v³κ²)·T + 3·v·κ·a_t·N`, two
/// orthogonal parts, so with `|j_t| ≤ J/2` and `v³κ² ≤ J/4` the path acceleration may take
/// `3·v·κ·a_t ≤ (√7/4)·J` (`(3/4)² + (√7/4)² = 1`), not the `J/4` a plain sum of the three
/// parts left it: a short arc in the jerk-limited mode speeds up 2.6 times as hard as before
/// (seen in the setpoints), and every axis still keeps its limits.
#[test]
fn arcs_accelerate_with_the_whole_jerk_budget() {
    let cfg = config(ProfileKind::SCurve);
    let l = limits();
    // The arcs are in XY: the budgets are the smaller of X's and Y's, times the share.
    let jerk = cfg.path_acc_share * cfg.max_jerk_mm_s3.x.min(cfg.max_jerk_mm_s3.y);
    let acc = cfg.path_acc_share * l.max_acc_mm_s2.x.min(l.max_acc_mm_s2.y);
    for r in [2.0, 3.0, 5.0] {
        let text = format!(
            "G21 G90 G17 G61\nG3 X0 Y{d} I0 J{r} F9000\nM2\n",
            d = 2.0 * r
        );
        let prog = parse_program(&text, "arc.ngc", Vector3::zeros()).unwrap();
        let plan = plan_with(&prog, &l, &cfg).unwrap();
        let v_max = (acc * 0.75f64.sqrt() * r)
            .sqrt()
            .min((0.25 * jerk * r * r).cbrt());
        let before = jerk * r / (12.0 * v_max);
        let now = (7.0f64.sqrt() / 4.0 * jerk * r / (3.0 * v_max)).min(0.5 * acc);
        let mut interp = Interpolator::new(plan.clone(), T).unwrap();
        let (mut q, mut prev) = (Vector3::zeros(), Vector3::zeros());
        let mut speeds = Vec::new();
        while !interp.is_finished() {
            interp.update(&mut q);
            speeds.push((q - prev).norm() / T);
            prev = q;
        }
        let a_seen = speeds
            .windows(2)
            .map(|w| (w[1] - w[0]).abs() / T)
            .fold(0.0, f64::max);
        assert!(
            a_seen > 0.9 * now && a_seen > 1.5 * before,
            "r = {r}: path acceleration {a_seen} mm/s² (bound {now}, before {before})"
        );
        setpoints::limits_hold(plan, &l, &cfg).unwrap();
    }
}

/// Issue 11, the time-law filter's dips: on an arc of CAM chords of 16 µm written in inches
/// with 4 decimals (LinuxCNC's `performance/contour.ngc`, at a 1 ms cycle), the rounding turns
/// many vertices sharply and their caps are low, below the `A·T_f/4` by which the filter
/// rounds a V-shaped dip, so each was planned as a stop and the filters settled there (tens of
/// milliseconds each). A plateau at the cap over the filter's reach on either side keeps the
/// filtered speed under it without stopping: the arc runs with hardly a stop, within the limits
/// and the tolerance.
#[test]
fn dense_low_caps_are_a_plateau_not_stops() {
    let n = 10_000.0;
    let point = |k: u32| {
        let a = std::f64::consts::TAU * f64::from(k) / n;
        (a.sin(), a.cos())
    };
    let (x, y) = point(1000);
    let mut text = format!("G20 G90 G17 G64 F9999\nG1 X{x:.4} Y{y:.4}\n");
    for k in 1001..1400 {
        let (x, y) = point(k);
        text.push_str(&format!("G1 X{x:.4} Y{y:.4}\n"));
    }
    text.push_str("M2\n");
    let prog = parse_program(&text, "contour.ngc", Vector3::zeros()).unwrap();
    // A window of 256 elements (4 mm of these chords): the random programs' 64 hold 1 mm,
    // against about 13 mm of braking from the arc's speed, and there the plan also stops
    // where the window leaves no room to lower the acceleration of its last line at a
    // junction (`Planner::share_at_junction`: 4 stops along the arc at 64 elements, none at
    // 256, session 22).
    let cfg = PlannerConfig {
        period_s: 0.001,
        lookahead: 256,
        ..config(ProfileKind::SCurve)
    };
    let plan = plan_with(&prog, &limits(), &cfg).unwrap();
    let stops = plan
        .segments()
        .iter()
        .filter(|s| s.line > 2 && s.line < 401 && s.v_end_mm_s == 0.0)
        .count();
    // 304 of the 398 vertices stopped (9.05 s) before the plateaus; what remains is where
    // the run of low caps begins, before any is known to be dense, and the last chords
    // (4 stops, 0.78 s; 13 with a window of 64 elements).
    assert!(
        stops <= 5,
        "{stops} stops on the arc ({} s)",
        plan.duration_s()
    );
    limits_and_path_hold(&prog, plan, &limits(), &cfg);
    // With the random programs' window, more stops, within every limit still.
    holds_jerk_limited_at_1_ms(&prog);
}

/// Issue 11: where a line meets an arc tangentially, the acceleration steps by `v²/r` towards
/// the centre, which the axis filters spread over `2·T_k` (jerk `v²/(r·T_k)`). Each of a
/// junction's rules took half of the jerk budget its elements leave, for steps that may meet
/// in the filters' output; an isolated step (no turn of the tangent, both elements longer than
/// `2·T_k` at their top speed) takes all of it (session 13: `√2` times the old cap). What the
/// arc leaves is taken at the junction's speed (session 26): along an axis it uses
/// `(2·a/T_f + v³/r²)·(|Tᵢ| + θ) + 3·v·a/r·(|Nᵢ| + θ)` (`θ = 2·v·T_k/r`, the turn within
/// the filters' span), its whole budget only at its cap. The line runs into the arc at the
/// speed where `1.05·v²/r ≤ T_k·(J_y − use_y(v))`, more than 1.5 times the cap with the arc's
/// use at its cap (20.1 mm/s, after the time-law filter's dip), and every axis keeps its
/// limits and the path its tolerance.
#[test]
fn an_isolated_curvature_step_takes_the_whole_jerk_budget() {
    let l = limits();
    let cfg = config(ProfileKind::SCurve);
    let r = 10.0;
    // A line along X, a quarter circle of radius r (CCW, centre above: the step is along Y),
    // a line along Y.
    let text = format!(
        "G21 G90 G17 G64 P0.05\nG1 X30 F9000\nG3 X{x} Y{r} I0 J{r}\nG1 Y40\nM2\n",
        x = 30.0 + r
    );
    let (prog, plan, v_end) = plan_to_line_end(&text, 2);
    let arc_acc = plan
        .segments()
        .iter()
        .find(|s| s.line == 3 && matches!(s.path, SegmentPath::Arc(_)))
        .and_then(|s| s.profile)
        .unwrap()
        .limits()
        .a_max_mm_s2();
    let (t_k, t_f) = filter_times_s();
    let share = cfg.path_acc_share;
    let dip = line_dip_mm_s(&cfg);
    // With the arc's use of Y at its cap (the share of Y's jerk its motion may use).
    let at_cap =
        (t_k * (cfg.max_jerk_mm_s3.y - share * cfg.max_jerk_mm_s3.x.min(cfg.max_jerk_mm_s3.y)) * r
            / 1.05)
            .sqrt()
            - dip;
    // The junction's cap before the dip keeps the rule with the arc's use at that speed.
    let v = v_end + dip;
    let turn = (2.0 * v * t_k / r).min(1.0);
    let use_y = (2.0 * arc_acc / t_f + v.powi(3) / (r * r)) * turn + 3.0 * v * arc_acc / r;
    assert!(
        1.05 * v * v / r <= t_k * (cfg.max_jerk_mm_s3.y - use_y) * (1.0 + 1e-9),
        "junction {v} mm/s before the dip: 1.05·v²/r = {} over T_k·(J − use) = {}",
        1.05 * v * v / r,
        t_k * (cfg.max_jerk_mm_s3.y - use_y)
    );
    assert!(
        v_end > 1.5 * at_cap,
        "junction {v_end} mm/s, with the arc's use at its cap {at_cap}"
    );
    limits_and_path_hold(&prog, plan, &l, &cfg);
}

/// The same for a line into a helix it is tangent to (a quarter turn of radius 10 mm rising
/// at `sin α = 0.2`): the helix uses Y's jerk at the junction's speed, its torsion's part
/// along the binormal included, not its whole budget (`0.75·J_y` there); the junction is passed
/// more than 1.5 times as fast, within every limit.
#[test]
fn a_curvature_step_into_a_helix_takes_what_the_helix_leaves_at_its_speed() {
    let l = limits();
    let cfg = config(ProfileKind::SCurve);
    let (r, sin_a) = (10.0f64, 0.2f64);
    let cos_a = (1.0 - sin_a * sin_a).sqrt();
    // The helix from (30, 0, 0), CCW about +Z (centre at y = r): its tangent there is
    // (cos α, 0, sin α); the line before runs along it.
    let rise = 0.5 * std::f64::consts::PI * r * sin_a / cos_a;
    let (x0, z0) = (30.0 - 30.0 * cos_a, -30.0 * sin_a);
    let text = format!(
        "G21 G90 G17 G64 P0.05\nG0 X{x0:.9} Y0 Z{z0:.9}\nG1 X30 Y0 Z0 F9000\n\
         G3 X{x} Y{r} Z{rise:.9} I0 J{r}\nG1 Y{y}\nM2\n",
        x = 30.0 + r,
        y = r + 30.0
    );
    let (prog, plan, v_end) = plan_to_line_end(&text, 3);
    let (t_k, _) = filter_times_s();
    let share = cfg.path_acc_share;
    // The helix's budget: Z takes `min(2·sin α, 1)` of its jerk, X and Y all of theirs.
    let budget = (share * cfg.max_jerk_mm_s3.x)
        .min(share * cfg.max_jerk_mm_s3.y)
        .min(share * cfg.max_jerk_mm_s3.z / (2.0 * sin_a).min(1.0));
    let at_cap = (t_k * (cfg.max_jerk_mm_s3.y - budget) * r / 1.05).sqrt() - line_dip_mm_s(&cfg);
    assert!(
        v_end > 1.5 * at_cap,
        "junction {v_end} mm/s, with the helix's use at its cap {at_cap}"
    );
    limits_and_path_hold(&prog, plan, &l, &cfg);
}

/// Issue 11: where a move planned through the time-law filter stops (a sharp corner), the plan
/// stood still until both the time-law filter and the axis filters had settled before the next
/// move started. Only the time-law filter must (the time law switches at rest); the axis
/// filters settle only where mixing the two legs could cut the corner beyond the tolerance, as
/// after a move planned alone: under `G64 P0.05` the next move starts `2·(N_k − 1)` periods
/// sooner, under `G64 P0.00001` the axis filters still settle. Every axis keeps its limits, the
/// path its tolerance.
#[test]
fn a_filtered_stop_waits_for_the_axis_filters_only_where_the_corner_needs_it() {
    let l = limits();
    let cfg = config(ProfileKind::SCurve);
    // `Smoothing::for_machine`: N_f covers the smallest A/J (37.5 ms), N_k 8 ms, at least 2.
    let n_f = (0.0375f64 / T - 1e-9).ceil();
    let n_k = (0.008 / T - 1e-9).ceil().max(2.0);
    for (p, y, settled) in [(0.05, 0.05, false), (0.00001, 0.0001, true)] {
        // The second line is reached at speed (a slight turn), so it runs through the
        // time-law filter, and stops at the right angle after it.
        let text = format!("G21 G90 G17 G64 P{p}\nG1 X10 F6000\nG1 X20 Y{y}\nG1 X20 Y20\nM2\n");
        let prog = parse_program(&text, "stop.ngc", Vector3::zeros()).unwrap();
        let plan = plan_with(&prog, &l, &cfg).unwrap();
        let second = plan.segments().iter().find(|s| s.line == 3).unwrap();
        assert!(
            second.v_start_mm_s > 0.0 && second.time_law,
            "P{p}: {second:?}"
        );
        let still_s: f64 = plan
            .segments()
            .iter()
            .filter(|s| s.line == 3 && s.length_mm == 0.0)
            .map(|s| s.duration_s())
            .sum();
        let expected = if settled {
            n_f - 1.0 + 2.0 * (n_k - 1.0)
        } else {
            n_f - 1.0
        };
        assert!(
            (still_s / T - expected).abs() < 1e-6,
            "P{p}: stood still {} periods at the corner, expected {expected}",
            still_s / T
        );
        limits_and_path_hold(&prog, plan, &l, &cfg);
    }
}

/// Issue 11: a turn of the tangent between two long lines steps each axis's velocity by
/// `v·|Δuᵢ|`, which the axis filters spread over `2·T_k` (jerk `v·|Δuᵢ|/T_k²`). Alone in the
/// filters' output (both lines longer than `2·T_k` at their top speed, no curvature step), it
/// now takes the whole jerk budget the lines leave, not half: the corner is passed twice as
/// fast (less the time-law filter's dip), and every axis keeps its limits.
#[test]
fn a_turn_alone_takes_the_whole_jerk_budget() {
    let l = limits();
    let cfg = config(ProfileKind::SCurve);
    let turn = 4f64.to_radians();
    let (x, y) = (30.0 + 30.0 * turn.cos(), 30.0 * turn.sin());
    let text = format!("G21 G90 G17 G64 P0.05\nG1 X30 F9000\nG1 X{x:.6} Y{y:.6}\nM2\n");
    let prog = parse_program(&text, "turn.ngc", Vector3::zeros()).unwrap();
    let plan = plan_with(&prog, &l, &cfg).unwrap();
    // The line's last segment (a long line may be planned in pieces) ends at the junction.
    let first = plan.segments().iter().rfind(|s| s.line == 2).unwrap();
    let u2 = Vector3::new(x - 30.0, y, 0.0).normalize();
    let du_y = u2.y.abs();
    // The second line's tangential jerk on Y, `|u_y|·share·min_i J_i/|u_i|`.
    let jerk_t = (cfg.path_acc_share * cfg.max_jerk_mm_s3.x / u2.x.abs())
        .min(cfg.path_acc_share * cfg.max_jerk_mm_s3.y / u2.y.abs());
    let left = cfg.max_jerk_mm_s3.y - du_y * jerk_t;
    let (t_k, _) = filter_times_s();
    let dip = line_dip_mm_s(&cfg);
    // The whole budget counts what the contour pre-compensation adds to the step.
    let cap = |budget: f64| t_k * t_k * budget / du_y;
    let (now, before) = (
        cap(left) / canmotion::planner::PRECOMP_JERK - dip,
        cap(0.5 * left) - dip,
    );
    assert!(
        first.v_end_mm_s > 0.99 * now && first.v_end_mm_s <= now * (1.0 + 1e-9),
        "junction {} mm/s, expected {now} (before: {before})",
        first.v_end_mm_s
    );
    limits_and_path_hold(&prog, plan, &l, &cfg);
}

/// A turn alone takes the whole jerk budget its lines leave, and the contour
/// pre-compensation adds to its step as to a curvature step's (found by
/// `a_run_joined_at_speed_keeps_every_limit`): two lines of 24.5 and 37.1 mm turning by 1.2°
/// (Y's direction steps by 0.02) passed at 123 mm/s broke Y's jerk by 1.3 % at 4 ms, the
/// step's own `v·|Δu_y|/T_k²` and the line's tangential jerk just within the limit.
#[test]
fn a_turn_alone_counts_what_the_precompensation_adds_to_its_step() {
    let l = limits();
    let cfg = config(ProfileKind::SCurve);
    let text = "G21 G90 G17 G64 P0.05\nG1 X24.505672 Y0 Z0.955678 F10817.7\n\
                G1 X61.5784 Y-0.756143 Z2.140166 F10492.6\nM2\n";
    let prog = parse_program(text, "turn.ngc", Vector3::zeros()).unwrap();
    let plan = plan_with(&prog, &l, &cfg).unwrap();
    limits_and_path_hold(&prog, plan, &l, &cfg);
}

/// Issue 11: a junction whose own cap `c` the time-law filter's dip (`A·T_f/4`) leaves
/// nothing of is a stop. When both moves through it are filtered, the plan stood there until
/// the filter had settled (`T_f`), so that its output stopped at the corner; passing it at `c`
/// is enough, which a stand of `T_f − 2·√(c·T_f/A)` gives. Here a right angle between two
/// filtered moves: the plan stands there for part of `T_f` only, and every axis keeps its
/// limits, the path its tolerance.
#[test]
fn a_stop_between_filtered_moves_stands_only_until_the_corner_is_within_its_cap() {
    let l = limits();
    let cfg = config(ProfileKind::SCurve);
    let n_f = (0.0375f64 / T - 1e-9).ceil();
    // Lines 3 and 4 are reached or left at speed through slight turns (so both run through the
    // time-law filter), and meet at a right angle.
    let text = "G21 G90 G17 G64 P0.05\nG1 X10 F6000\nG1 X20 Y0.05\nG1 X20 Y20\n\
                G1 X20.05 Y30\nG1 X20.05 Y40\nM2\n";
    let prog = parse_program(text, "corner.ngc", Vector3::zeros()).unwrap();
    let plan = plan_with(&prog, &l, &cfg).unwrap();
    // A line's last moving segment (a long line may be planned in parts) ends at its end.
    let seg = |line: usize| {
        plan.segments()
            .iter()
            .rfind(|s| s.line == line && s.length_mm > 0.0)
            .unwrap()
    };
    assert!(seg(3).time_law && seg(3).v_end_mm_s == 0.0, "{:?}", seg(3));
    assert!(seg(4).time_law && seg(4).v_end_mm_s > 0.0, "{:?}", seg(4));
    let still_periods: f64 = plan
        .segments()
        .iter()
        .filter(|s| s.line == 3 && s.length_mm == 0.0)
        .map(|s| s.duration_s())
        .sum::<f64>()
        / T;
    assert!(
        still_periods > 0.5 && still_periods < n_f - 1.5,
        "stood {still_periods} periods at the corner (the time-law filter settles in {})",
        n_f - 1.0
    );
    limits_and_path_hold(&prog, plan, &l, &cfg);
}

/// Issue 11: under the time-law filter, elements joined at speed planned with the lower of
/// their two accelerations, since the filter's window spans the junction. A long line into a
/// small arc then crawled all its length at the arc's tangential acceleration. Only the part of
/// the line within the filter's reach of the junction needs it: here 30 mm lines before and
/// after a tangent half circle of 2 mm radius (its tangential acceleration 40 % of theirs)
/// reach the speed their own acceleration allows over (nearly) their length (63 % before
/// the change), and every axis keeps its limits, the path its tolerance.
#[test]
fn a_long_line_keeps_its_acceleration_beyond_the_filter_s_reach_of_a_small_arc() {
    let l = limits();
    let cfg = config(ProfileKind::SCurve);
    let text = "G21 G90 G17 G64 P0.01\nG1 X30 F12000\nG3 X30 Y4 I0 J2\nG1 X0 Y4\nM2\n";
    let prog = parse_program(text, "small_arc.ngc", Vector3::zeros()).unwrap();
    let plan = plan_with(&prog, &l, &cfg).unwrap();
    // The lines' own tangential acceleration under the time-law filter: `J·T_f/2`.
    let (_, t_f) = filter_times_s();
    let acc = 0.5 * cfg.path_acc_share * cfg.max_jerk_mm_s3.x * t_f;
    let arc_acc = plan
        .segments()
        .iter()
        .filter(|s| s.line == 3)
        .map(|s| s.profile.unwrap().limits().a_max_mm_s2())
        .fold(f64::INFINITY, f64::min);
    assert!(
        arc_acc < 0.8 * acc,
        "the arc's acceleration {arc_acc} mm/s²"
    );
    for line in [2, 4] {
        let peak = plan
            .segments()
            .iter()
            .filter(|s| s.line == line)
            .map(|s| s.v_peak_mm_s)
            .fold(0.0, f64::max);
        // From (nearly) rest to (nearly) rest over 30 mm: √(a·L) at the line's own
        // acceleration, less what the part within reach costs.
        let own = (acc * 30.0).sqrt();
        assert!(
            peak > 0.95 * own,
            "line {line} peaks at {peak} mm/s; its own acceleration reaches {own} mm/s \
             (the arc's {} mm/s)",
            (arc_acc * 30.0).sqrt()
        );
    }
    limits_and_path_hold(&prog, plan, &l, &cfg);
}

/// Issue 11: the time-law filter's jerk is the range of the plan's acceleration over one
/// filter length, so a filtered run plans at `J·T_f/2`, half of what its axes allow, wherever
/// its acceleration may reverse within `T_f`. A long line passed at speed at both ends (a kink
/// in the middle of a long move, LinuxCNC's `long-kink.ngc`) keeps that acceleration only
/// within `T_f` (plus two periods) of its ends, where its neighbours' accelerations meet it in
/// the filter (at the program's start none does), and either side of its peak, and changes
/// speed with the whole `J·T_f` between: the line takes less time than its plain trapezoid
/// from the same end speeds, and every axis keeps its limits at the 4 ms period.
#[test]
fn a_long_filtered_line_accelerates_at_its_whole_acceleration_between_its_ends() {
    let l = limits();
    let cfg = config(ProfileKind::SCurve);
    let text = "G21 G90 G17 G64 P0.05\nG1 X40 F12000\nG1 X40.5 Y0.05\nG1 X80 Y0.05\nM2\n";
    let prog = parse_program(text, "long_kink.ngc", Vector3::zeros()).unwrap();
    let plan = plan_with(&prog, &l, &cfg).unwrap();
    let (_, t_f) = filter_times_s();
    let half = 0.5 * cfg.path_acc_share * cfg.max_jerk_mm_s3.x * t_f;
    let whole = (cfg.path_acc_share * l.max_acc_mm_s2.x).min(2.0 * half);
    for line in [2, 4] {
        let segs: Vec<_> = plan
            .segments()
            .iter()
            .filter(|s| s.line == line && s.profile.is_some())
            .collect();
        let acc = |s: &canmotion::planner::Segment| s.profile.unwrap().limits().a_max_mm_s2();
        let (first, last) = (segs[0], segs[segs.len() - 1]);
        assert!(
            segs.iter().any(|s| acc(s) == whole),
            "line {line}: no part at {whole} mm/s²: {segs:#?}"
        );
        // The parts that end at its junctions keep the filtered run's acceleration for the
        // filter's length and two periods; the program's start (from rest, with nothing
        // before it in the filter) needs none.
        let ends = if line == 2 {
            vec![last]
        } else {
            vec![first, last]
        };
        assert_eq!(acc(first) == whole, line == 2, "{first:?}");
        for s in ends {
            assert!(acc(s) <= half * (1.0 + 1e-12), "line {line}: {s:?}");
            assert!(
                s.duration_s() >= t_f + 2.0 * T,
                "line {line}: {} s at an end",
                s.duration_s()
            );
        }
        let length_mm: f64 = segs.iter().map(|s| s.length_mm).sum();
        let time_s: f64 = segs.iter().map(|s| s.duration_s()).sum();
        let plain = canmotion::planner::profile::ProfileLimits::trapezoid(first.v_limit_mm_s, half)
            .and_then(|lim| {
                canmotion::planner::profile::plan(
                    length_mm,
                    first.v_start_mm_s,
                    last.v_end_mm_s,
                    &lim,
                )
            })
            .unwrap()
            .duration_s();
        assert!(
            time_s < 0.9 * plain,
            "line {line}: {time_s} s, its trapezoid at {half} mm/s² {plain} s"
        );
    }
    limits_and_path_hold(&prog, plan, &l, &cfg);
}

/// The same for a helix between tangent lines: its middle part is an arc of the same helix
/// at its whole tangential acceleration, its ends keep the filtered run's, and the setpoints
/// keep every limit and the path (a part's helix must start where the last ended: its centre
/// moves up with it).
#[test]
fn a_long_filtered_helix_accelerates_at_its_whole_acceleration_between_its_ends() {
    let l = limits();
    let cfg = config(ProfileKind::SCurve);
    // The lines rise as the helix does (8 mm over half a turn of 20 mm: 0.1273 mm/mm).
    let text = "G21 G90 G17 G64 P0.05\nG0 Z-2.546\nG1 X20 Z0 F6000\nG3 X20 Y40 Z8 I0 J20\n\
                G1 X0 Y40 Z10.546\nM2\n";
    let prog = parse_program(text, "helix.ngc", Vector3::zeros()).unwrap();
    let plan = plan_with(&prog, &l, &cfg).unwrap();
    let segs: Vec<_> = plan
        .segments()
        .iter()
        .filter(|s| s.line == 4 && s.profile.is_some())
        .collect();
    let acc = |s: &canmotion::planner::Segment| s.profile.unwrap().limits().a_max_mm_s2();
    assert!(
        segs.len() >= 2 && segs.iter().all(|s| matches!(s.path, SegmentPath::Arc(_))),
        "{segs:#?}"
    );
    let (first, last) = (segs[0], segs[segs.len() - 1]);
    assert!(
        segs.iter()
            .any(|s| acc(s) > 1.5 * acc(first).max(acc(last))),
        "{segs:#?}"
    );
    limits_and_path_hold(&prog, plan, &l, &cfg);
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    /// Long moves joined at speed keep every axis's limits in the jerk-limited mode, their
    /// middles at the whole acceleration, and stay within the tolerance.
    #[test]
    fn a_run_joined_at_speed_keeps_every_limit(text in a_run_joined_at_speed()) {
        check(&text, ProfileKind::SCurve)?;
        check_tolerance(&text, ProfileKind::SCurve)?;
    }
}

/// A CAM surface's profile written as chords: tangent arcs whose curvature changes from one to
/// the next (`(κ, length)` each), as chords of `chord_mm` with 4 decimals, in the XY or the XZ
/// plane, under G64 P0.1 at a feed above what the curve allows.
fn chorded_profile(pieces: &[(f64, f64)], chord_mm: f64, xz: bool) -> String {
    let mut text = String::from("G21 G90 G64 P0.1\nG1 X0 Y0 Z0 F6000\n");
    let other = if xz { 'Z' } else { 'Y' };
    let (mut x, mut y, mut heading) = (0.0f64, 0.0f64, 0.0f64);
    for &(kappa, length_mm) in pieces {
        let n = ((length_mm / chord_mm) as usize).max(1);
        let step = length_mm / n as f64;
        for _ in 0..n {
            // The chord of the arc over `step`: along the heading at its middle.
            heading += 0.5 * kappa * step;
            x += step * heading.cos();
            y += step * heading.sin();
            heading += 0.5 * kappa * step;
            text.push_str(&format!("X{x:.4} {other}{y:.4}\n"));
        }
    }
    text.push_str("M2\n");
    text
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    /// The chord refiner replaces such chords by pieces on a curve through their vertices, whose
    /// curvature turns within a few pieces where the profile's does: at a 1 ms period (eight
    /// periods of axis filter) the jerk-limited setpoints keep every axis's limits and the
    /// tolerance.
    #[test]
    fn chorded_profiles_of_changing_curvature_keep_every_limit(
        pieces in prop::collection::vec((-0.3..0.3f64, 0.3..1.5f64), 20..40),
        chord_mm in 0.12..0.5f64,
        xz in any::<bool>(),
    ) {
        let text = chorded_profile(&pieces, chord_mm, xz);
        let prog = parse_program(&text, "profile.ngc", Vector3::zeros())
            .map_err(|e| TestCaseError::fail(format!("{e}\n{text}")))?;
        let cfg = PlannerConfig {
            period_s: 0.001,
            ..config(ProfileKind::SCurve)
        };
        let plan = plan_with(&prog, &limits(), &cfg).map_err(|e| TestCaseError::fail(e.to_string()))?;
        setpoints::limits_hold(plan.clone(), &limits(), &cfg).map_err(TestCaseError::fail)?;
        path_deviation::measure_items(prog.start_mm, &prog.items, plan, &cfg)
            .map_err(|e| TestCaseError::fail(e.to_string()))?
            .check()
            .map_err(|e| TestCaseError::fail(e.to_string()))?;
    }
}

/// A chorded profile whose curvature flips from −0.16 to +0.14 /mm within one chord of
/// 0.45 mm, which the refiner cuts into pieces of 27 µm: at about 30 mm/s a span of the axis
/// filters (`v·T_k`, 0.24 mm) holds nine of their vertices, whose curvature steps add up
/// within it. Its look-ahead window (64 elements) is too short to take them as a curve, and
/// the vertices' own rules, each step alone, let Y's jerk reach 41 314 mm/s³ against 40 000
/// (a seed `chorded_profiles_of_changing_curvature_keep_every_limit` found at 1500 cases).
/// The sum of the steps within a span is now held (`Planner::span_cap_mm_s`).
#[test]
fn a_curvature_that_flips_within_a_refined_chord_keeps_every_limit() {
    let pieces = [
        (-0.25781813621075955, 0.3),
        (0.21392483863064107, 0.8138178885031598),
        (0.09209629668220308, 0.40618634341300835),
        (0.057539940342513494, 1.4774325186736423),
        (-0.12538674812940365, 0.8380012180803494),
        (-0.2956162037509016, 1.4256647380079257),
        (-0.2223453606242931, 0.921663343090673),
        (-0.07379639557647312, 0.6356714631503861),
        (-0.1555596995820181, 0.3),
        (0.14277706249132888, 0.3),
        (0.1921955582050216, 1.3540391602950699),
        (0.23430198383492323, 0.9533922109843574),
        (0.21674612551369016, 1.3083974616889793),
        (-0.11898435049946975, 0.6768609810291666),
        (0.0, 0.3),
        (0.0, 0.3),
        (0.0, 0.3),
        (0.0, 0.3),
        (0.0, 0.3),
        (0.0, 0.3),
    ];
    chorded_profile_holds(&pieces, 0.44503909190064816, false);
}

/// A chorded profile whose look-ahead split a line where the time-law filter's reach ends:
/// the junction inside it kept the feed as its cap (100 mm/s), above the first part's limit
/// (17.6 mm/s, its curve's), and the backward pass, finding no profile from a bound above that
/// limit, came down to rest there: the element before could no longer come down from the
/// speed already settled, and planning failed (`NoProfile`, line 21; a seed
/// `chorded_profiles_of_changing_curvature_keep_every_limit` found at 1500 cases). The pass
/// now takes the bound at the element's limit (`curve::back_reach`).
#[test]
fn a_line_split_under_a_curve_s_cap_plans_and_keeps_every_limit() {
    let pieces = [
        (0.26246285051865326, 1.0553800058687504),
        (0.1761342843793399, 0.9847699270092057),
        (-0.24423827895854888, 0.3),
        (-0.2511972526975261, 1.0234734942491526),
        (-0.18853323120289803, 0.3),
        (-0.23014830303339406, 1.2365818098779813),
        (-0.23314033823545932, 1.4060707903671863),
        (-0.24605654081478187, 0.6873362214865476),
        (0.0, 0.3),
        (-0.06700862883411707, 0.6745951903638271),
        (-0.11287961599719025, 0.5718117976132093),
        (-0.1432327995742675, 1.4816808490205058),
        (0.2590582946411056, 1.2323885710681721),
        (-0.18984732881539776, 0.8498172676438337),
        (0.2068264872926902, 0.8017690568596364),
        (0.11283693454041231, 0.3),
        (0.0, 0.3),
        (0.0, 0.3),
        (0.0, 0.3),
        (0.0, 0.3),
    ];
    chorded_profile_holds(&pieces, 0.4990572801386788, true);
}

/// The jerk-limited plan of [`chorded_profile`] at a 1 ms period keeps every limit and stays
/// within the tolerance of the programmed path.
fn chorded_profile_holds(pieces: &[(f64, f64)], chord_mm: f64, xz: bool) {
    let text = chorded_profile(pieces, chord_mm, xz);
    let prog = parse_program(&text, "profile.ngc", Vector3::zeros()).unwrap();
    holds_jerk_limited_at_1_ms(&prog);
}

/// The jerk-limited plan of `prog` with the random programs' limits and planner at a 1 ms
/// period keeps every limit and stays within the tolerance of the programmed path.
fn holds_jerk_limited_at_1_ms(prog: &Program) {
    let cfg = PlannerConfig {
        period_s: 0.001,
        ..config(ProfileKind::SCurve)
    };
    let plan = plan_with(prog, &limits(), &cfg).unwrap();
    limits_and_path_hold(prog, plan, &limits(), &cfg);
}

/// A junction among short lines whose cap the time-law filter's dip would take to nothing is
/// passed on a plateau (the elements within `c·T_f` either side capped at `c`), not a stop,
/// also where no other junction within reach stops. These vertices are LinuxCNC's
/// `performance/random_lines_0.001in.ngc`, lines 50–70 (a random walk of 1 µm steps, in mm):
/// the junction at the end of line 22 here stopped (the plan came down to rest from
/// 0.49 mm/s and the filter settled, 53 ms); it is now passed at 0.20 mm/s within a plateau at
/// 0.31 mm/s.
#[test]
fn a_lone_low_cap_among_short_lines_is_passed_on_a_plateau() {
    let (l, cfg) = demo_s_curve();
    let text = "G21 G90 G64 Q0.0002\nG0 X0.024109 Y0.021846 Z0.003172\nG1 F999\n\
        X0.023950 Y0.022778 Z0.002587\nX0.023681 Y0.023543 Z0.001979\n\
        X0.023350 Y0.024265 Z0.001541\nX0.022803 Y0.024978 Z0.000897\n\
        X0.022343 Y0.025590 Z0.000100\nX0.022104 Y0.026144 Z-0.000795\n\
        X0.022004 Y0.026579 Z-0.001534\nX0.022063 Y0.027250 Z-0.002244\n\
        X0.022431 Y0.027850 Z-0.003163\nX0.022356 Y0.028239 Z-0.004140\n\
        X0.022562 Y0.028290 Z-0.005109\nX0.022386 Y0.028121 Z-0.006096\n\
        X0.022227 Y0.028169 Z-0.006993\nX0.022433 Y0.028560 Z-0.007883\n\
        X0.022883 Y0.028628 Z-0.008876\nX0.022987 Y0.028684 Z-0.009822\n\
        X0.023312 Y0.028663 Z-0.010719\nX0.023752 Y0.028624 Z-0.011648\n\
        X0.024061 Y0.028419 Z-0.012436\nX0.024211 Y0.027822 Z-0.013217\n\
        M2\n";
    let prog = parse_program(text, "random_lines.ngc", Vector3::zeros()).unwrap();
    let plan = plan_with(&prog, &l, &cfg).unwrap();
    let line_22 = plan
        .segments()
        .iter()
        .rfind(|s| s.line == 22 && s.profile.is_some())
        .unwrap();
    assert!(
        line_22.v_end_mm_s > 0.1,
        "the motion stops at the end of line 22 ({} mm/s)",
        line_22.v_end_mm_s
    );
    limits_and_path_hold(&prog, plan, &l, &cfg);
}

/// The demo machine's limits and planner, jerk-limited at a 1 ms period (`tools/corpus-times.sh`'s
/// setting).
fn demo_s_curve() -> (Limits, PlannerConfig) {
    let machine_file = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("dictionaries/machines/demo-xyz.toml");
    let mut machine = canmotion::config::Machine::load(&machine_file).unwrap();
    machine.planner.period_s = 0.001;
    machine.planner.profile = ProfileKind::SCurve;
    (canmotion::gateway::limits(&machine), machine.planner)
}

/// No move of `plan` holds under `v_mm_s` for longer than `t_s` (a crawl a user sees).
fn no_crawl(plan: &Plan, v_mm_s: f64, t_s: f64) {
    for s in plan.segments().iter().filter(|s| s.profile.is_some()) {
        assert!(
            s.v_peak_mm_s >= v_mm_s || s.duration_s() <= t_s,
            "line {}: {:.4} mm at most at {:.3} mm/s for {:.3} s",
            s.line,
            s.length_mm,
            s.v_peak_mm_s,
            s.duration_s()
        );
    }
}

/// A line that ends in a stop, after a low junction cap, is not crossed at a crawl. On
/// LinuxCNC's `performance/line-contouring-xz.ngc` (these vertices are from its lines
/// 894–905, under its bare `G64`) the chord before the stop at `X-16.345 Z5.668` ran at
/// 0.11 mm/s for 1.53 s: the look-ahead planned its profile under the cap of the junction at
/// its start (dipped to 0.11 mm/s), where the acceleration its curve left was valid up to
/// 10 mm/s. It now rises to about 2.5 mm/s within the line (0.13 s).
#[test]
fn a_line_between_a_low_cap_and_a_stop_does_not_crawl() {
    let (l, cfg) = demo_s_curve();
    let text = "G90 G21 G64 Q0.03\nG0 X-15.851 Y-8.612 Z6.356\nG1 F100000\n\
        X-15.856 Z6.35\nZ6.343\nX-16.181 Z5.887\nX-16.253 Z5.802\nX-16.345 Z5.668\n\
        X-16.352 Z5.648\nX-16.36 Z5.646\nX-16.416 Z5.563\nX-16.427 Z5.55\nX-16.742 Z5.106\n\
        X-16.755 Z5.102\nX-16.763 Z5.092\nM2\n";
    let prog = parse_program(text, "contouring.ngc", Vector3::zeros()).unwrap();
    let plan = plan_with(&prog, &l, &cfg).unwrap();
    no_crawl(&plan, 1.0, 0.1);
    limits_and_path_hold(&prog, plan, &l, &cfg);
}

/// A chord profile under `G64 P0.1` whose chords the refiner cuts into pieces (vertices from
/// LinuxCNC's `performance/LHchips4.ngc`, lines 1705–1722) runs through without a stop: the
/// pieces are fine enough that the junction rules between them hold about the curve's own
/// speed. With a quarter of `J·T_k²` per vertex (before session 23), the junctions of the
/// 1 mm chord's pieces were held at 6–13 mm/s against the curve's 15, and their dips
/// (`A·T_f/4`, 8 mm/s) stopped the motion twice inside that chord.
#[test]
fn a_refined_chord_profile_runs_through_without_stops() {
    let (l, cfg) = demo_s_curve();
    let vertices = [
        (6.048, -12.253),
        (5.819, -12.247),
        (5.591, -12.258),
        (5.364, -12.285),
        (5.139, -12.328),
        (4.912, -12.389),
        (4.688, -12.463),
        (4.469, -12.549),
        (4.255, -12.647),
        (3.245, -13.067),
        (3.044, -13.162),
        (2.85, -13.271),
        (2.665, -13.394),
        (2.488, -13.529),
        (1.225, -14.611),
        (1.053, -14.756),
        (0.89, -14.912),
    ];
    let mut text = "G21 G90 G64 P0.1\nG0 X6.275 Z-12.275\nG1 F7500\n".to_string();
    for (x, z) in vertices {
        text.push_str(&format!("X{x} Z{z}\n"));
    }
    text.push_str("M2\n");
    let prog = parse_program(&text, "chips.ngc", Vector3::zeros()).unwrap();
    let plan = plan_with(&prog, &l, &cfg).unwrap();
    let moves: Vec<_> = plan
        .segments()
        .iter()
        .filter(|s| s.profile.is_some() && !s.rapid)
        .collect();
    let stops: Vec<usize> = moves[..moves.len() - 1]
        .iter()
        .filter(|s| s.v_end_mm_s == 0.0)
        .map(|s| s.line)
        .collect();
    assert!(stops.is_empty(), "stops at the end of lines {stops:?}");
    limits_and_path_hold(&prog, plan, &l, &cfg);
}

/// A programmed arc that runs mostly at its cap takes more of the jerk budget for the curve
/// and less for its tangential acceleration (`ArcSplit` in `src/planner/mod.rs`): three turns
/// of a 10 mm circle run at its centripetal limit, 114 mm/s, in 1.89 s, where the split of
/// every arc (`v³κ² ≤ J/4`) held them to 97.9 mm/s, 2.10 s; within every limit.
#[test]
fn a_long_arc_runs_at_its_centripetal_limit() {
    let (l, cfg) = demo_s_curve();
    let text = "G21 G90 G64 P0.01\nG0 X10 Y0\nG2 X10 Y0 I-10 J0 P3 F12000\nM2\n";
    let prog = parse_program(text, "turns.ngc", Vector3::zeros()).unwrap();
    let plan = plan_with(&prog, &l, &cfg).unwrap();
    let peak = plan
        .segments()
        .iter()
        .filter(|s| s.line == 3)
        .map(|s| s.v_peak_mm_s)
        .fold(0.0, f64::max);
    assert!(peak > 110.0, "peak {peak:.2} mm/s");
    limits_and_path_hold(&prog, plan, &l, &cfg);
}

/// A vertex whose neighbours are long enough at the speed it is passed that no other
/// vertex's step meets its own in the axis filters' output takes the whole jerk budget the
/// elements leave, not half of it: a polygon of 2 mm chords turning 4.5° each (LinuxCNC's
/// `quick-tests/sam-circle_lines.ngc` is such a spiral) was passed at a median of 5 mm/s
/// (15.4 s for two laps) when only elements long enough at the max feed counted; it now
/// takes 11.6 s at a median of 18 mm/s.
#[test]
fn a_polygon_of_sparse_vertices_gives_each_vertex_the_whole_budget() {
    let (l, cfg) = demo_s_curve();
    let r_mm = 1.0 / 2.25f64.to_radians().sin();
    let mut text = format!("G21 G90 G64\nG1 X{r_mm:.4} Y0 F6000\n");
    for k in 1..=160 {
        let th = (4.5 * f64::from(k)).to_radians();
        text += &format!("X{:.4} Y{:.4}\n", r_mm * th.cos(), r_mm * th.sin());
    }
    text += "M2\n";
    let prog = parse_program(&text, "polygon.ngc", Vector3::zeros()).unwrap();
    let plan = plan_with(&prog, &l, &cfg).unwrap();
    let mut vertices: Vec<f64> = plan
        .segments()
        .iter()
        .filter(|s| s.profile.is_some() && s.line > 3)
        .map(|s| s.v_start_mm_s)
        .collect();
    vertices.sort_by(f64::total_cmp);
    let median = vertices[vertices.len() / 2];
    assert!(median >= 15.0, "median vertex speed {median:.2} mm/s");
    limits_and_path_hold(&prog, plan, &l, &cfg);
}

/// The charge of a curve is held ahead over the time-law filter's reach at the speed the
/// plan may run there, which is never above the max feed. A gentle curve's cap is far above
/// it (here 30 mm of a 2 m radius, whose cap is some 5 m/s): held over `cap·T_f/2`, its
/// charge reached a 7 mm Z line after the corner, which the walk back of the tight curve
/// after it then slowed whole (1.03 s at 12 mm/s instead of 0.27 s; on LinuxCNC's
/// `performance/3D_Chips.ngc` a 6.8 mm Z line ran at 6 mm/s for 2 s).
#[test]
fn a_line_beyond_the_reach_of_a_gentle_curve_does_not_crawl() {
    let (l, cfg) = demo_s_curve();
    let r_mm = 2000.0;
    let mut text = String::from("G21 G90 G64 P0.1\nG1 F12000\n");
    let arc = |k: u32| {
        let th = f64::from(k) * 0.05 / r_mm;
        (r_mm * th.sin(), r_mm * (1.0 - th.cos()))
    };
    for k in 1..=600 {
        let (x, y) = arc(k);
        text += &format!("X{x:.6} Y{y:.6}\n");
    }
    let y = arc(600).1;
    // A 7 mm Z line, then a quarter circle of 0.5 mm in 10 µm chords turning it to +Y.
    text += "Z7\n";
    let (r, n) = (0.5, 78);
    for k in 1..=n {
        let ph = f64::from(k) / f64::from(n) * std::f64::consts::FRAC_PI_2;
        text += &format!(
            "Y{:.4} Z{:.4}\n",
            y + r * (1.0 - ph.cos()),
            7.0 + r * ph.sin()
        );
    }
    text += &format!("Y{:.4}\nM2\n", y + r + 3.0);
    let prog = parse_program(&text, "gentle.ngc", Vector3::zeros()).unwrap();
    let plan = plan_with(&prog, &l, &cfg).unwrap();
    let z_line_s: f64 = plan
        .segments()
        .iter()
        .filter(|s| s.line == 603)
        .map(|s| s.duration_s())
        .sum();
    assert!(z_line_s < 0.4, "the Z line takes {z_line_s:.3} s");
    limits_and_path_hold(&prog, plan, &l, &cfg);
}

/// A line that starts within the reach of the curves before it plans with their charges
/// (session 22); where it goes well beyond, only its part within reach does. These vertices
/// are LinuxCNC's `performance/LHchips4.ngc`, lines 6787–6801 (feeds left out): the Z line of
/// 3.2 mm after the stop at `X11.908 Y6.893` was taken whole by the walk back of the tight
/// curve after it and ran at 2.04 mm/s for 2.84 s (0.8 mm/s²); split where the charges end,
/// it takes 0.18 s.
#[test]
fn a_line_held_with_the_charges_before_it_does_not_crawl() {
    let (l, cfg) = demo_s_curve();
    let text = "G21 G90 G64 P0.1\nG0 X13.496 Y7.289 Z-16.319\nG1 F16663\n\
        Y7.28 Z-10.885\nY7.261 Z-10.539\nY7.226 Z-10.194\nY7.175 Z-9.851\nY7.108 Z-9.51\n\
        Y6.781 Z-8.219\nY5.658 Z-7.502\nX11.908 Y6.893\nZ-10.683\nY6.999 Z-11.068\n\
        Y7.088 Z-11.458\nY7.161 Z-11.85\nY7.217 Z-12.246\nY7.255 Z-12.643\nY7.277 Z-13.042\n\
        M2\n";
    let prog = parse_program(text, "held.ngc", Vector3::zeros()).unwrap();
    let plan = plan_with(&prog, &l, &cfg).unwrap();
    no_crawl(&plan, 5.0, 0.3);
    limits_and_path_hold(&prog, plan, &l, &cfg);
}

/// Issue 11: under the time-law filter a line's acceleration `a` reaches each axis as the jerk
/// `2·a/T_f` wherever the plan's acceleration reverses, as at the bottom of every dip, and a
/// vertex passed at speed keeps half of what the lines leave: an eighth of each axis's jerk
/// with `a = J·T_f/2`. A polygon whose vertices turn a little each (as LinuxCNC's
/// `quick-tests/sam-circle_lines.ngc`: chords of 2 mm and less turning 4.5°, bare `G64`) ran
/// its dips at what that eighth allows. Its lines now plan with a smaller share of their
/// acceleration where that is estimated faster, which leaves the vertices more: here 2.5 mm
/// chords, most of their lines (from where the vertices' jerk rule binds) with about half
/// the filtered run's acceleration, the polygon within 1.25 times its trapezoid time (1.30
/// before, 1.19 now), and every axis within its limits at 1 ms.
#[test]
fn a_polygon_of_slight_kinks_trades_acceleration_for_its_vertices() {
    let (l, cfg) = demo_s_curve();
    let turn = 4.5f64.to_radians();
    let radius_mm = 1.25 / (0.5 * turn).sin();
    let start = Vector3::new(radius_mm, 0.0, 0.0);
    let mut text = String::from("G21 G90 G64\nG1 F6000\n");
    for k in 1..=40 {
        let at = f64::from(k) * turn;
        text += &format!(
            "X{:.4} Y{:.4}\n",
            radius_mm * at.cos(),
            radius_mm * at.sin()
        );
    }
    text += "M2\n";
    let prog = parse_program(&text, "polygon.ngc", start).unwrap();
    let plan = plan_with(&prog, &l, &cfg).unwrap();
    let trapezoid = PlannerConfig {
        profile: ProfileKind::Trapezoid,
        ..cfg
    };
    let trapezoid_s = plan_with(&prog, &l, &trapezoid).unwrap().duration_s();
    assert!(
        plan.duration_s() < 1.25 * trapezoid_s,
        "{} s against the trapezoid's {trapezoid_s} s",
        plan.duration_s()
    );
    let (_, t_f) = filter_times_s();
    let half = 0.5 * cfg.path_acc_share * cfg.max_jerk_mm_s3.x.min(cfg.max_jerk_mm_s3.y) * t_f;
    let lowered = plan
        .segments()
        .iter()
        .filter(|s| {
            s.profile
                .is_some_and(|p| p.limits().a_max_mm_s2() <= 0.6 * half)
        })
        .count();
    assert!(lowered >= 30, "{lowered} of 40 lines plan with less");
    limits_and_path_hold(&prog, plan, &l, &cfg);
}

/// Issue 11: arcs of CAM output meet at slight kinks where their written centres do not
/// quite agree (LinuxCNC's `spreadsheeterrors.ngc`: 0.1–1.3° between arcs of 70–500 mm whose
/// ends stray from their circles by up to 15 µm, too far for a blend under `G64 P0.01`). A
/// kink's velocity step through the axis filters takes what the arcs leave of each axis's
/// jerk; at the speed a kink holds the junction to, an arc uses far less than at its cap
/// (its curve's part `v³κ²` and `3·v·κ·a_t` fall with the speed), and the rule takes the
/// arcs' use at the junction's speed (`Planner::cap_at_speed`), as the curvature steps
/// have since session 26. Twelve arcs of 60–110 mm turning by 1° at each junction (their
/// ends 20 µm off their circles), demo machine at 1 ms: faster than their trapezoid plan,
/// whose one-period rule holds the kinks to 28–38 mm/s (2.35 s against 2.85; 3.56 s
/// before), every junction passed at least at 50 mm/s (77; 18.6 before), limits at 1 and
/// 4 ms and the tolerance.
#[test]
fn arcs_meeting_at_slight_kinks_are_passed_at_speed() {
    let (l, cfg) = demo_s_curve();
    let mut text = String::from("G21 G90 G17 G64 P0.01\nG1 X0 Y0 F12000\n");
    let (mut p, mut heading) = (Vector3::zeros(), 0.0f64);
    for k in 0..12 {
        let r = 60.0 + 50.0 * f64::from(k % 3) / 2.0;
        // Clockwise: the centre lies to the right of the heading.
        let c = p + r * Vector3::new(heading.sin(), -heading.cos(), 0.0);
        let sweep = 12f64.to_radians();
        let a0 = (p.y - c.y).atan2(p.x - c.x);
        let end = c + (r + 0.02) * Vector3::new((a0 - sweep).cos(), (a0 - sweep).sin(), 0.0);
        text += &format!(
            "G2 X{:.4} Y{:.4} I{:.4} J{:.4}\n",
            end.x,
            end.y,
            c.x - p.x,
            c.y - p.y
        );
        // The next arc starts turned a further degree.
        heading -= sweep + 1f64.to_radians();
        p = Vector3::new(
            format!("{:.4}", end.x).parse().unwrap(),
            format!("{:.4}", end.y).parse().unwrap(),
            0.0,
        );
    }
    text += "M2\n";
    let prog = parse_program(&text, "arcs.ngc", Vector3::zeros()).unwrap();
    let plan = plan_with(&prog, &l, &cfg).unwrap();
    let trapezoid = PlannerConfig {
        profile: ProfileKind::Trapezoid,
        ..cfg
    };
    let trapezoid_s = plan_with(&prog, &l, &trapezoid).unwrap().duration_s();
    let segs = plan.segments();
    let slowest = segs
        .windows(2)
        .filter(|w| w[0].line != w[1].line && w[0].line > 2 && w[1].profile.is_some())
        .map(|w| w[0].v_end_mm_s)
        .fold(f64::INFINITY, f64::min);
    assert!(
        plan.duration_s() < trapezoid_s,
        "{} s against the trapezoid's {trapezoid_s} s",
        plan.duration_s()
    );
    assert!(slowest >= 50.0, "a junction passed at {slowest} mm/s");
    limits_and_path_hold(&prog, plan.clone(), &l, &cfg);
    let four = PlannerConfig {
        period_s: 0.004,
        ..cfg
    };
    setpoints::limits_hold(plan_with(&prog, &l, &four).unwrap(), &l, &four).unwrap();
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    /// Polylines of slight kinks, whose lines may take a smaller share of their time-law
    /// acceleration, keep every axis's limits in the jerk-limited mode at 4 and 1 ms and stay
    /// within the tolerance.
    #[test]
    fn a_kinked_polyline_keeps_every_limit(text in a_kinked_polyline()) {
        check(&text, ProfileKind::SCurve)?;
        check_with(&text, PlannerConfig { period_s: 0.001, ..config(ProfileKind::SCurve) })?;
        check_tolerance(&text, ProfileKind::SCurve)?;
    }
}

/// Motion safety, found by `a_kinked_polyline_keeps_every_limit` at a 1 ms period (session 29)
/// and present before that session's change (at `0bf4946`: 20 858 mm/s³): the refined chord
/// of line 10 bends down and up again in Z within about 0.35 mm (its neighbours rise by 3.0 %,
/// 2.1 % and 3.6 % of their length), and at about 40 mm/s the curve's Z acceleration swung from
/// −62 to +87 mm/s² within 14 ms, Z's jerk 20 889 mm/s³ against 20 000 (4.4 % over): its
/// vertices, taken as points of a curve at the run's start, took the curvature's rate from the
/// estimate before the run (1.7 mm back, not the 0.54 mm baseline), six times too low.
#[test]
fn a_refined_chord_bending_in_z_keeps_z_s_jerk_at_1_ms() {
    let text = "G21 G90 G17 G64\nG1 X0.1489 Y0.0179 Z0 F1200\nG1 X0.2923 Y0.0618 F1200\n\
        G1 X0.4265 Y0.1287 F1200\nG1 X0.5460 Y0.2194 F1200\nG1 X0.9146 Y0.5400 F1200\n\
        G1 X1.0107 Y0.6552 F1200\nG1 X1.7800 Y1.9958 F1200\n\
        G1 X3.3705 Y5.0168 Z0.1028 F5821.6\nG1 X3.6643 Y5.6152 Z0.1167 F4756.8\n\
        G1 X4.9791 Y8.3920 Z0.2275 F10154.9\nM2\n";
    let cfg = PlannerConfig {
        period_s: 0.001,
        ..config(ProfileKind::SCurve)
    };
    let prog = parse_program(text, "refined_z.ngc", Vector3::zeros()).unwrap();
    let plan = plan_with(&prog, &limits(), &cfg).unwrap();
    setpoints::limits_hold(plan, &limits(), &cfg).unwrap();
}
