//! Chorded curves (issue 11's acceptance): circles and ellipses of radius 0.5–50 mm written as
//! CAM writes them (chords of 10–50 µm, 4 decimals), planned in jerk-limited mode on the demo
//! machine at a 1 ms cycle, against the curvature bound `T_lb` of the curve the chords
//! approximate ([`canmotion::planner::bounds::curvature_bound_s`] of the exact polyline).
//!
//! Run with `--nocapture` (and `--ignored` for the acceptance) to see the table.

#[path = "common/chorded.rs"]
mod chorded;
mod common;
#[path = "common/setpoints.rs"]
mod setpoints;

use canmotion::config::Machine;
use canmotion::gateway::limits;
use canmotion::gcode::{Interpreter, Item, Setup};
use canmotion::interpolator::{Interpolator, Status};
use canmotion::planner::bounds::curvature_bound_s;
use canmotion::planner::{Limits, PlannerConfig, plan_items_with};
use chorded::ChordedCurve;
use nalgebra::Vector3;

/// The demo machine at a 1 ms cycle, in jerk-limited mode (planning only: the bus load of
/// 1 ms cycles, 74.5 % on the demo bus, does not matter here).
fn jerk_machine() -> Machine {
    common::machine(|text| {
        let text = text
            .replace("cycle_us = 4000", "cycle_us = 1000\nmax_load_percent = 100")
            .replace("window_us = 2000", "window_us = 0");
        format!("{text}\n[planner]\nprofile = \"s-curve\"\n")
    })
}

fn items(program: &str, start_mm: Vector3<f64>) -> Vec<Item> {
    Interpreter::new(program.as_bytes(), "curve.ngc", Setup::new(start_mm))
        .map(|item| item.expect("the curve interprets"))
        .filter(|item| !matches!(item, Item::Note(_)))
        .collect()
}

/// `T_lb` of the exact polyline of `curve` (its vertices on the curve).
fn curve_bound_s(curve: &ChordedCurve, limits: &Limits, config: &PlannerConfig) -> f64 {
    let items = items(&curve.program(None), curve.start_mm(None));
    curvature_bound_s(&items, limits, config)
}

/// `2πr / min(F, √(A·r), (J·r²)^⅓)` on the demo machine (X and Y alike).
fn circle_closed_form_s(r_mm: f64, feed_mm_s: f64, limits: &Limits, config: &PlannerConfig) -> f64 {
    let (a, j) = (limits.max_acc_mm_s2.x, config.max_jerk_mm_s3.x);
    assert_eq!(a, limits.max_acc_mm_s2.y);
    assert_eq!(j, config.max_jerk_mm_s3.y);
    let v = feed_mm_s
        .min(limits.max_feed_mm_s)
        .min((a * r_mm).sqrt())
        .min((j * r_mm * r_mm).cbrt());
    std::f64::consts::TAU * r_mm / v
}

/// `T_lb` against its closed form: a full circle at a feed below the curvature caps takes
/// `2πr/F`, above them `2πr/min(√(A·r), (J·r²)^⅓)`, as a G3 and as exact chords (whose
/// discrete curvature `θ/c` is `1/r` to `O((π/N)²)`); and an ellipse's exact chords give the
/// integral of its true curvature.
#[test]
fn curvature_bound_has_its_closed_form() {
    let machine = jerk_machine();
    let (limits, config) = (limits(&machine), machine.planner);
    for r_mm in [0.5, 2.0, 10.0, 50.0] {
        let a = limits.max_acc_mm_s2.x;
        let j = config.max_jerk_mm_s3.x;
        let cap_mm_s = (a * r_mm).sqrt().min((j * r_mm * r_mm).cbrt());
        for feed_mm_s in [0.5 * cap_mm_s.min(limits.max_feed_mm_s), 200.0] {
            let expected = circle_closed_form_s(r_mm, feed_mm_s, &limits, &config);
            let start = Vector3::new(r_mm, 0.0, 0.0);
            let g3 = format!(
                "G21 G90 G17 F{}\nG3 X{r_mm} Y0 I{} J0\nM2\n",
                feed_mm_s * 60.0,
                -r_mm
            );
            let arc = curvature_bound_s(&items(&g3, start), &limits, &config);
            assert!(
                (arc / expected - 1.0).abs() < 1e-9,
                "G3 r = {r_mm} at {feed_mm_s} mm/s: T_lb {arc} s, closed form {expected} s"
            );
            let curve = ChordedCurve {
                a_mm: r_mm,
                b_mm: r_mm,
                chord_mm: 0.02,
                laps: 1,
                feed_mm_s,
                tolerance_mm: 0.01,
            };
            // The polyline starts and ends at a point that is no vertex: its first and last
            // half-chords are straight, at the feed.
            let c = curve.first_chord_mm();
            let feed = feed_mm_s.min(limits.max_feed_mm_s);
            let v = std::f64::consts::TAU * r_mm / expected;
            let expected = expected - c / v + c / feed;
            let chords = curve_bound_s(&curve, &limits, &config);
            assert!(
                (chords / expected - 1.0).abs() < 1e-4,
                "{} at {feed_mm_s} mm/s: T_lb {chords} s, closed form {expected} s",
                curve.name()
            );
        }
    }
    // An ellipse: ∫ ds / min(F, √(A/κ), (J/κ²)^⅓) with κ(θ) = ab / (a² sin²θ + b² cos²θ)^(3/2)
    // and ds = √(a² sin²θ + b² cos²θ) dθ, by the midpoint rule.
    for (a_mm, b_mm) in [(5.0, 2.0), (50.0, 20.0)] {
        let (acc, jerk) = (limits.max_acc_mm_s2.x, config.max_jerk_mm_s3.x);
        let n = 200_000;
        let d_theta = std::f64::consts::TAU / n as f64;
        let expected: f64 = (0..n)
            .map(|k| {
                let (s, c) = ((k as f64 + 0.5) * d_theta).sin_cos();
                let q = a_mm * a_mm * s * s + b_mm * b_mm * c * c;
                let kappa = a_mm * b_mm / q.powf(1.5);
                let v = 200f64
                    .min((acc / kappa).sqrt())
                    .min((jerk / (kappa * kappa)).cbrt());
                q.sqrt() * d_theta / v
            })
            .sum();
        let curve = ChordedCurve {
            a_mm,
            b_mm,
            chord_mm: 0.02,
            laps: 1,
            feed_mm_s: 200.0,
            tolerance_mm: 0.01,
        };
        // The straight half-chords at the ends, at (a, 0) where κ = a/b².
        let kappa = a_mm / (b_mm * b_mm);
        let v = 200f64
            .min((acc / kappa).sqrt())
            .min((jerk / (kappa * kappa)).cbrt());
        let c = curve.first_chord_mm();
        let expected = expected - c / v + c / 200.0;
        let chords = curve_bound_s(&curve, &limits, &config);
        assert!(
            (chords / expected - 1.0).abs() < 1e-4,
            "{}: T_lb {chords} s, integral {expected} s",
            curve.name()
        );
    }
}

/// One curve's figures.
struct Timed {
    name: String,
    chords: usize,
    time_s: f64,
    t_lb_s: f64,
    /// `T_lb` of the 4-decimal polyline itself (its rounding adds discrete curvature).
    t_lb_written_s: f64,
}

/// Plans every curve of the acceptance set (4 decimals) in jerk-limited mode and streams it at
/// the machine's period; prints the table.
fn time_curves() -> Vec<Timed> {
    let machine = jerk_machine();
    let (limits, config) = (limits(&machine), machine.planner);
    let mut out = Vec::new();
    println!(
        "{:<28} {:>7} {:>9} {:>9} {:>7} {:>16}",
        "curve", "chords", "time_s", "T_lb_s", "ratio", "T_lb(written)_s"
    );
    for curve in ChordedCurve::acceptance_set() {
        let start = curve.start_mm(Some(4));
        let items = items(&curve.program(Some(4)), start);
        let timed = Timed {
            name: curve.name(),
            chords: curve.chords_per_lap() * curve.laps as usize,
            time_s: streamed_time_s(&items, start, &limits, &config),
            t_lb_s: curve_bound_s(&curve, &limits, &config),
            t_lb_written_s: curvature_bound_s(&items, &limits, &config),
        };
        println!(
            "{:<28} {:>7} {:>9.3} {:>9.3} {:>7.3} {:>16.3}",
            timed.name,
            timed.chords,
            timed.time_s,
            timed.t_lb_s,
            timed.time_s / timed.t_lb_s,
            timed.t_lb_written_s
        );
        out.push(timed);
    }
    out
}

/// Every chorded curve's jerk-limited setpoints keep each axis's velocity, acceleration and
/// jerk within its limits (1 %, by finite differences at the machine's period) and end
/// exactly (what `tests/gcode_corpus.rs` checks on the corpus, here on the acceptance's
/// curves, whose vertices the normal-jerk rule `Planner::curve_acc_mm_s2` slows).
#[test]
fn chorded_curves_keep_every_axis_within_its_limits() {
    let broken = limits_broken(ChordedCurve::program, &[Some(4)]);
    assert!(broken.is_empty(), "limits broken:\n{}", broken.join("\n"));
}

/// The same curves in the XZ plane (G18), as written (4 decimals) and exact, keep every
/// axis within its limits. Z has 40 % of X's jerk: where the curve runs along Z its jerk
/// `v³κ²` lies along Z, while the vertex's turn `Δu` lies along X. Seen failing before the
/// curve's jerk rule took the tangent's share: the exact `circle r10` broke Z's jerk by
/// 1.1 % and the exact `ellipse 50x20` by 4.0 %.
#[test]
fn chorded_curves_in_the_xz_plane_keep_every_axis_within_its_limits() {
    let broken = limits_broken(ChordedCurve::program_xz, &[Some(4), None]);
    assert!(broken.is_empty(), "limits broken:\n{}", broken.join("\n"));
}

/// The acceptance's curves, written by `program` with each of `decimals`, planned in the
/// jerk-limited mode: each ends where it began, and the limits it breaks are listed.
fn limits_broken(
    program: fn(&ChordedCurve, Option<usize>) -> String,
    decimals: &[Option<usize>],
) -> Vec<String> {
    let machine = jerk_machine();
    let (limits, config) = (limits(&machine), machine.planner);
    let mut broken = Vec::new();
    for curve in ChordedCurve::acceptance_set() {
        for &decimals in decimals {
            let start = curve.start_mm(decimals);
            let items = items(&program(&curve, decimals), start);
            let plan = plan_items_with(start, &items, &limits, &config).expect("the curve plans");
            assert_eq!(plan.end_mm(), start, "{} ends where it began", curve.name());
            if let Err(e) = setpoints::limits_hold(plan, &limits, &config) {
                broken.push(format!("{}, decimals {decimals:?}: {e}", curve.name()));
            }
        }
    }
    broken
}

/// The jerk-limited plan of every chorded curve is slower than the curve's bound: `T_lb` is a
/// bound the planner cannot beat within the machine's limits.
#[test]
fn chorded_curves_take_at_least_their_curvature_bound() {
    for t in time_curves() {
        assert!(
            t.time_s >= t.t_lb_s,
            "{}: {} s, below T_lb {} s",
            t.name,
            t.time_s,
            t.t_lb_s
        );
    }
}

/// Issue 11's acceptance: the jerk-limited time of every chorded curve is within 1.10× of its
/// `T_lb`.
#[test]
#[ignore = "issue 11: the jerk-limited mode takes 1.10–2.45× T_lb on these curves (measured 2026-11-29, session 35: circles 1.10–1.18×, the 50×20 mm ellipse 1.29×, the 5×2 mm ellipse 2.45×, which no plan within the axes' acceleration alone takes under 1.10× T_lb: see the README, session 31); the target is 1.10×"]
fn chorded_curves_run_within_1_10_of_their_curvature_bound() {
    let slow: Vec<String> = time_curves()
        .into_iter()
        .filter(|t| t.time_s > 1.10 * t.t_lb_s)
        .map(|t| format!("{}: {:.3}× T_lb", t.name, t.time_s / t.t_lb_s))
        .collect();
    assert!(
        slow.is_empty(),
        "slower than 1.10 × T_lb:\n{}",
        slow.join("\n")
    );
}

/// A chorded circle runs lap after lap at one pace: every lap but the first two (from rest)
/// and the last two (to rest) takes the same time within 2 %. The look-ahead settles what it can when
/// its window is full and keeps the rest; it used to keep just what a stop at the window's end
/// needed from the settled speed, and a vertex whose curve then lowered the accelerations
/// within its reach could no longer be planned from there: it fell back to its own junction
/// rules, a dip to 18 mm/s at 50 mm/s. From the fifth lap of the 2 mm circle on, every lap
/// took 0.31 s instead of 0.25 s (`Planner::replan`'s reserve).
#[test]
fn a_chorded_circle_keeps_its_pace_lap_after_lap() {
    let machine = jerk_machine();
    let (limits, config) = (limits(&machine), machine.planner);
    for curve in ChordedCurve::acceptance_set()
        .into_iter()
        .filter(|c| c.a_mm == c.b_mm && c.laps >= 8)
    {
        let laps_s: Vec<f64> = laps(&curve, &limits, &config).iter().map(|l| l.0).collect();
        let inner = &laps_s[2..laps_s.len() - 2];
        let fastest = inner.iter().copied().fold(f64::INFINITY, f64::min);
        let slowest = inner.iter().copied().fold(0.0, f64::max);
        assert!(
            slowest <= 1.02 * fastest,
            "{}: laps of {fastest:.4}–{slowest:.4} s: {laps_s:.4?}",
            curve.name()
        );
    }
}

/// A chorded circle whose speed its centripetal acceleration caps runs its laps at nearly
/// that cap: the 10 mm circle of 30 µm chords (4 decimals) at a mean speed of at least 0.92 of
/// `√(A·r)` on every lap but the first two and the last two (its jerk allows 171 mm/s, the
/// feed 200). The vertices' rounding costs the axes' jerk, not their acceleration, so the
/// curve may take nearly all of each axis's acceleration (`CURVE_ACC_BUDGET`,
/// `src/planner/curve.rs`). Seen failing at 0.883 when the curve had 0.85 of the acceleration
/// as of the jerk (session 34); 0.937 since.
#[test]
fn a_chorded_circle_runs_near_its_centripetal_cap() {
    let machine = jerk_machine();
    let (limits, config) = (limits(&machine), machine.planner);
    let curve = acceptance_circle(10.0);
    let acc = limits.max_acc_mm_s2.x;
    assert_eq!(acc, limits.max_acc_mm_s2.y);
    let cap_mm_s = (acc * curve.a_mm).sqrt();
    let jerk_mm_s3 = config.max_jerk_mm_s3.x.min(config.max_jerk_mm_s3.y);
    let jerk_cap_mm_s = (jerk_mm_s3 * curve.a_mm * curve.a_mm).cbrt();
    assert!(
        cap_mm_s < jerk_cap_mm_s.min(curve.feed_mm_s),
        "the centripetal acceleration caps this circle"
    );
    let laps = laps(&curve, &limits, &config);
    for (k, (lap_s, lap_mm)) in laps.iter().enumerate().take(laps.len() - 2).skip(2) {
        let mean_mm_s = lap_mm / lap_s;
        assert!(
            mean_mm_s >= 0.92 * cap_mm_s,
            "lap {k}: {mean_mm_s:.1} mm/s, {:.3} of √(A·r) = {cap_mm_s:.1} mm/s",
            mean_mm_s / cap_mm_s
        );
    }
}

/// The acceptance set's circle of radius `r_mm`.
fn acceptance_circle(r_mm: f64) -> ChordedCurve {
    ChordedCurve::acceptance_set()
        .into_iter()
        .find(|c| c.a_mm == r_mm && c.b_mm == r_mm)
        .expect("the acceptance set has the circle")
}

/// The jerk-limited plan of `curve` (written with 4 decimals), lap by lap: each lap's time and
/// length. The chords are lines 2, 3, …: lap `k` is lines `2 + k·n` to `1 + (k + 1)·n`.
fn laps(curve: &ChordedCurve, limits: &Limits, config: &PlannerConfig) -> Vec<(f64, f64)> {
    let start = curve.start_mm(Some(4));
    let items = items(&curve.program(Some(4)), start);
    let plan = plan_items_with(start, &items, limits, config).expect("the curve plans");
    let n = curve.chords_per_lap();
    let mut laps = vec![(0.0, 0.0); curve.laps as usize];
    let last = laps.len() - 1;
    for s in plan.segments().iter().filter(|s| s.line >= 2) {
        let lap = &mut laps[((s.line - 2) / n).min(last)];
        lap.0 += s.duration_s();
        lap.1 += s.length_mm;
    }
    laps
}

/// The program time of `items` planned with `config` and streamed at its period; the plan
/// ends where it began.
fn streamed_time_s(
    items: &[Item],
    start: Vector3<f64>,
    limits: &Limits,
    config: &PlannerConfig,
) -> f64 {
    let plan = plan_items_with(start, items, limits, config).expect("the program plans");
    assert_eq!(plan.end_mm(), start, "the program ends where it began");
    let mut interp = Interpolator::new(plan, config.period_s).expect("interpolator");
    let mut q = Vector3::zeros();
    while interp.update(&mut q) != Status::Finished {}
    interp.elapsed_s()
}

/// A circle written as CAM writes it (chords of 10–30 µm, 4 decimals) runs in the
/// jerk-limited mode about as fast as the same circle written as G3 arcs: within 10 %. The
/// chords' vertices are charged only what they turn beyond the curve their run approximates,
/// whose centripetal acceleration and jerk the lines take from their own budget as the arc
/// does (`src/planner/curve.rs`). Before that they were charged against the budget each
/// vertex's elements left: 1.6× (10 mm, 30 µm) to 4.2× (0.5 mm, 10 µm) the arcs' time.
#[test]
fn a_chorded_circle_runs_as_fast_as_its_arc() {
    let machine = jerk_machine();
    let (limits, config) = (limits(&machine), machine.planner);
    let mut slow = Vec::new();
    for curve in ChordedCurve::acceptance_set()
        .into_iter()
        .filter(|c| c.a_mm == c.b_mm && c.a_mm <= 10.0)
    {
        let start = curve.start_mm(Some(4));
        let chords_s = streamed_time_s(
            &items(&curve.program(Some(4)), start),
            start,
            &limits,
            &config,
        );
        let r = curve.a_mm;
        let mut g3 = format!(
            "G21 G90 G17 G64 P{} F{}\n",
            curve.tolerance_mm,
            curve.feed_mm_s * 60.0
        );
        for _ in 0..curve.laps {
            g3.push_str(&format!("G3 X{r} Y0 I{} J0\n", -r));
        }
        g3.push_str("M2\n");
        let arcs_s = streamed_time_s(&items(&g3, start), start, &limits, &config);
        println!("{}: chords {chords_s:.3} s, G3 {arcs_s:.3} s", curve.name());
        if chords_s > 1.10 * arcs_s {
            slow.push(format!(
                "{}: {chords_s:.3} s against the arcs' {arcs_s:.3} s",
                curve.name()
            ));
        }
    }
    assert!(
        slow.is_empty(),
        "chords slower than their arcs:\n{}",
        slow.join("\n")
    );
}

/// Written vertices of a chorded curve that happen to line up stay apart: on the 50 mm circle
/// of 50 µm chords with 4 decimals, two or three chords near its flat parts are collinear, and
/// merging them (`src/planner/merge.rs`, which merges only straight runs as long as the axis
/// filters' span at the max feed) made one longer chord among the short ones, a vertex the
/// filters saw apart from the curve: 1.10 → 1.64× `T_lb`. The jerk-limited plan keeps every
/// segment within the circle's longest written chord.
#[test]
fn collinear_chords_of_a_curve_stay_apart() {
    let machine = jerk_machine();
    let (limits, config) = (limits(&machine), machine.planner);
    let curve = acceptance_circle(50.0);
    let start = curve.start_mm(Some(4));
    let items = items(&curve.program(Some(4)), start);
    let longest_chord_mm = items
        .iter()
        .filter_map(|i| match i {
            Item::Motion(e) => Some((e.end_mm - e.start_mm).norm()),
            _ => None,
        })
        .fold(0.0, f64::max);
    let plan = plan_items_with(start, &items, &limits, &config).expect("the circle plans");
    let longest_mm = plan
        .segments()
        .iter()
        .map(|s| s.length_mm)
        .fold(0.0, f64::max);
    assert!(
        longest_mm <= longest_chord_mm + 1e-9,
        "a segment of {longest_mm} mm, the longest chord {longest_chord_mm} mm"
    );
}

/// A chorded spiral whose curvature rises steadily (a clothoid of 10 µm chords to 20 /mm,
/// 6 decimals, as LinuxCNC's `quick-tests/spiral_tangent_test.ngc` writes one) runs through
/// every vertex near its curve's own speed: within its middle, no line starts under half of
/// `min(F, √(A/κ), (J/κ²)^⅓)` at its curvature. Until session 34 a vertex whose own rules
/// capped it a little under its lines' caps was dipped by the time-law filter's `A·T_f/4`
/// to a near-stop: 0.35 of that speed at worst here (2.06 mm/s), 4.27 s for the spiral;
/// held as a cap of the run now (`Planner::start_caps`), 0.70 and 2.92 s.
#[test]
fn a_chorded_spiral_runs_through_its_vertices_near_its_curve_s_speed() {
    let machine = jerk_machine();
    let (limits, config) = (limits(&machine), machine.planner);
    let (chord_mm, chords, kappa_max) = (0.01, 2000usize, 20.0);
    let length_mm = chord_mm * chords as f64;
    let mut text = String::from("G21 G90 G17 G64 F12000\n");
    let (mut x, mut y) = (0.0f64, 0.0f64);
    let mut kappa_at_line = Vec::with_capacity(chords);
    for k in 0..chords {
        // The heading θ(s) = κ_max·s²/(2L) at the chord's middle.
        let s_mid = (k as f64 + 0.5) * chord_mm;
        let theta = kappa_max * s_mid * s_mid / (2.0 * length_mm);
        x += chord_mm * theta.cos();
        y += chord_mm * theta.sin();
        text.push_str(&format!("G1 X{x:.6} Y{y:.6}\n"));
        kappa_at_line.push(kappa_max * (k as f64 + 1.0) * chord_mm / length_mm);
    }
    text.push_str("M2\n");
    let items = items(&text, Vector3::zeros());
    let plan = plan_items_with(Vector3::zeros(), &items, &limits, &config).expect("it plans");
    let (a, j) = (limits.max_acc_mm_s2.x, config.max_jerk_mm_s3.x);
    let f = limits.max_feed_mm_s;
    let mut slowest: Option<(usize, f64, f64)> = None;
    for s in plan.segments() {
        // The chords are lines 2 …; their middle 10–90 %.
        let Some(k) = s.line.checked_sub(2) else {
            continue;
        };
        if k < chords / 10 || k > chords * 9 / 10 {
            continue;
        }
        let kappa = kappa_at_line[k];
        let v_ref = f.min((a / kappa).sqrt()).min((j / (kappa * kappa)).cbrt());
        let share = s.v_start_mm_s / v_ref;
        if slowest.is_none_or(|(_, _, worst)| share < worst) {
            slowest = Some((s.line, s.v_start_mm_s, share));
        }
    }
    let (line, v, share) = slowest.expect("the spiral's lines are planned");
    assert!(
        share >= 0.5,
        "line {line} starts at {v:.2} mm/s, {share:.3} of its curve's speed"
    );
}
