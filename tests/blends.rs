//! Issue 11, item 3: blends for every element pair. Under `G64 P` the planner rounds the
//! corners between lines and plane arcs (line–line, line–arc, arc–line, arc–arc) with tangent
//! arcs within the tolerance, where that is faster than the sharp corner. On random programs
//! of lines and arcs joined at corners (every other element an arc, so that every corner
//! has one: line–line corners keep the rule they had before), in both modes: the program
//! time never exceeds the exact corners' (P0) nor grows with P (within the slack of the
//! per-corner estimate that chooses the blends, `slack_smaller_p`), and
//! every setpoint keeps every axis's limits and stays within P of the programmed path.

use canmotion::gcode::{Interpreter, Item, Setup, Tool, parse_program};
use canmotion::planner::{
    Plan, PlannerConfig, ProfileKind, SegmentPath, plan_items_with, plan_with,
};
use nalgebra::Vector3;
use proptest::prelude::*;

#[path = "common/setpoints.rs"]
mod setpoints;

#[path = "common/random_programs.rs"]
#[allow(dead_code)] // its limits and configuration only
mod random_programs;

#[path = "common/path_deviation.rs"]
mod path_deviation;

use random_programs::{config, limits};

/// One element of a generated program: it leaves the previous element's end turned by
/// `turn_rad` (a corner: never tangent, never a reversal), and is a line of `length_mm` or,
/// with a radius, an arc of that radius turning by `sweep_rad` (positive: counter-clockwise),
/// at `feed_mm_s`.
#[derive(Debug, Clone, Copy)]
struct Piece {
    turn_rad: f64,
    length_mm: f64,
    arc: Option<(f64, f64)>,
    feed_mm_s: f64,
}

fn a_piece() -> impl Strategy<Value = Piece> {
    let turn = (0.15..2.8f64, any::<bool>()).prop_map(|(t, left)| if left { t } else { -t });
    let arc = (0.5..20.0f64, 0.2..3.0f64, any::<bool>())
        .prop_map(|(r, s, ccw)| (r, if ccw { s } else { -s }));
    let arc = prop_oneof![1 => Just(None), 2 => arc.prop_map(Some)];
    (turn, 0.3..25.0f64, arc, 20.0..180.0f64).prop_map(|(turn_rad, length_mm, arc, feed_mm_s)| {
        Piece {
            turn_rad,
            length_mm,
            arc,
            feed_mm_s,
        }
    })
}

/// An arc piece: every other piece is one, so that every corner has an arc on a side
/// (line–line corners are blended as before this item, by their own rule).
fn an_arc() -> impl Strategy<Value = Piece> {
    (a_piece(), 0.5..20.0f64, 0.2..3.0f64, any::<bool>()).prop_map(|(p, r, s, ccw)| Piece {
        arc: Some((r, if ccw { s } else { -s })),
        ..p
    })
}

fn rotate(d: Vector3<f64>, angle: f64) -> Vector3<f64> {
    let (s, c) = angle.sin_cos();
    Vector3::new(d.x * c - d.y * s, d.x * s + d.y * c, 0.0)
}

/// The XY program of `pieces` from the origin, with the G64 P word left as `{P}`.
fn program(pieces: &[Piece]) -> String {
    let mut text = String::from("G21 G90 G17 G64 P{P}\n");
    let mut at = Vector3::zeros();
    let mut dir = Vector3::x();
    let round = |p: Vector3<f64>| p.map(|c| format!("{c:.6}").parse::<f64>().unwrap());
    for p in pieces {
        dir = rotate(dir, p.turn_rad);
        let f = p.feed_mm_s * 60.0;
        match p.arc {
            None => {
                at = round(at + dir * p.length_mm);
                text.push_str(&format!("G1 X{:.6} Y{:.6} F{f:.3}\n", at.x, at.y));
            }
            Some((r, sweep)) => {
                // The centre on the left of the direction for a counter-clockwise arc.
                let left = rotate(dir, std::f64::consts::FRAC_PI_2);
                let centre = at + left * (r * sweep.signum());
                let end = round(centre + rotate(at - centre, sweep));
                let ij = centre - at;
                text.push_str(&format!(
                    "{} X{:.6} Y{:.6} I{:.6} J{:.6} F{f:.3}\n",
                    if sweep > 0.0 { "G3" } else { "G2" },
                    end.x,
                    end.y,
                    ij.x,
                    ij.y
                ));
                // The tangent at the end (the interpreter ends on the written point).
                let radial = (end - centre).normalize();
                dir = rotate(radial, std::f64::consts::FRAC_PI_2 * sweep.signum());
                at = end;
            }
        }
    }
    text.push_str("M2\n");
    text
}

/// A chord tolerance of 10 µm lets arcs run fast enough for blends to matter.
fn cfg(profile: ProfileKind) -> PlannerConfig {
    PlannerConfig {
        chord_tol_mm: 0.01,
        ..config(profile)
    }
}

/// Plans `text` under `G64 P<p_mm>` and checks every setpoint against the limits and the
/// tolerance; the plan back.
fn plan_and_check(template: &str, p_mm: f64, profile: ProfileKind) -> Result<Plan, TestCaseError> {
    let text = template.replace("{P}", &format!("{p_mm}"));
    let cfg = cfg(profile);
    let prog = parse_program(&text, "blends.ngc", Vector3::zeros())
        .map_err(|e| TestCaseError::fail(format!("{e}\n{text}")))?;
    let plan = plan_with(&prog, &limits(), &cfg)
        .map_err(|e| TestCaseError::fail(format!("{e}\n{text}")))?;
    setpoints::limits_hold(plan.clone(), &limits(), &cfg)
        .map_err(|e| TestCaseError::fail(format!("P{p_mm} {profile:?}: {e}\n{text}")))?;
    let report = path_deviation::measure_items(prog.start_mm, &prog.items, plan.clone(), &cfg)
        .map_err(|e| TestCaseError::fail(e.to_string()))?;
    report
        .check()
        .map_err(|e| TestCaseError::fail(format!("P{p_mm} {profile:?}: {e}\n{text}")))?;
    Ok(plan)
}

/// How much slower than the plan with the next smaller P a blended plan may be, per mode.
/// Whether a corner is blended, and with which radius, is chosen per corner by an estimate
/// of its time (`CornerCost` in `src/planner/blend.rs`) among a grid of radii that does not
/// depend on P; the look-ahead then plans the profiles exactly. The estimate cannot see what
/// follows the corner: in the trapezoid mode a larger blend before a stop (the program's end)
/// replaces a line's braking by the arc's, weaker under its centripetal share, and costs up to
/// 2.3 % (seen in 10 × 5000 random programs, session 24). The jerk-limited mode takes a blend
/// only where it saves the time-law filter's delay too; it was never slower until session 28,
/// when settling began to run the long speed changes of filtered elements at their whole
/// acceleration (`Planner::split_for_acceleration`), which the estimate does not see: a larger
/// blend moves length between the elements it joins and the arc. Up to 0.064 % seen in
/// 5 × 3000 random programs (5 cases slower than with the smaller P, none slower than P0);
/// 0.8 % while blend arcs were not split, 7.7 % with a first form of the split that needed a
/// cruise at each peak. Until session 34 the estimate charged a whole dip at the lower of
/// the accelerations either side, and 4 of 9000 jerk-limited random programs broke the
/// slack (up to +0.5 % against a smaller P and +0.12 % against P0; +1.9 % in the case that
/// failed CI, now in the regressions file): it now charges the shared acceleration within
/// the time-law filter's reach of the corner only, and the whole acceleration of a long speed
/// change beyond it. 1 of 48 000 still does (+1 %, two blends of neighbouring corners sharing
/// an arc's length).
fn slack_smaller_p(profile: ProfileKind) -> f64 {
    match profile {
        ProfileKind::Trapezoid => 0.03,
        _ => 0.005,
    }
}

/// The tolerances, in increasing order. From 0.02 mm: the jerk-limited mode's axis filters
/// may take half of P at a corner, and `chord_tol_mm` (0.01 mm here) under P0, so a smaller P
/// would give them less room than P0 (issue 11 item 2's budget), whatever the blends do.
const TOLERANCES_MM: [f64; 5] = [0.0, 0.02, 0.05, 0.1, 0.5];

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]

    /// Every tolerance's plan keeps the limits and stays within P of the programmed path.
    #[test]
    fn blends_keep_to_p_and_the_limits(
        pairs in prop::collection::vec((a_piece(), an_arc()), 1..4),
        s_curve in any::<bool>(),
    ) {
        let profile = if s_curve { ProfileKind::SCurve } else { ProfileKind::Trapezoid };
        let pieces: Vec<Piece> = pairs.into_iter().flat_map(|(p, arc)| [p, arc]).collect();
        let template = program(&pieces);
        for p_mm in TOLERANCES_MM {
            plan_and_check(&template, p_mm, profile)?;
        }
    }

    /// Issue 11 item 3: a blend never makes a program slower than its exact corners (P0), and
    /// the time never grows with P (within `slack_smaller_p`).
    #[test]
    fn blends_do_not_slow_a_program(
        pairs in prop::collection::vec((a_piece(), an_arc()), 1..4),
        s_curve in any::<bool>(),
    ) {
        let profile = if s_curve { ProfileKind::SCurve } else { ProfileKind::Trapezoid };
        let pieces: Vec<Piece> = pairs.into_iter().flat_map(|(p, arc)| [p, arc]).collect();
        let template = program(&pieces);
        let mut exact_s = None;
        let mut last_s = f64::INFINITY;
        for p_mm in TOLERANCES_MM {
            let t_s = plan_and_check(&template, p_mm, profile)?.duration_s();
            let exact = *exact_s.get_or_insert(t_s);
            prop_assert!(
                t_s <= exact + 1e-9,
                "{profile:?}: P{p_mm} takes {t_s} s, exact corners {exact} s\n{template}"
            );
            prop_assert!(
                t_s <= last_s * (1.0 + slack_smaller_p(profile)) + 1e-9,
                "{profile:?}: P{p_mm} takes {t_s} s, a smaller P {last_s} s\n{template}"
            );
            last_s = t_s;
        }
    }
}

/// Blend arcs in a plan: its arcs beyond the program's own.
fn blend_count(plan: &Plan, programmed_arcs: usize) -> usize {
    let arcs = plan
        .segments()
        .iter()
        .filter(|s| matches!(s.path, SegmentPath::Arc(_)))
        .count();
    arcs - programmed_arcs
}

/// A line, an arc, an arc the other way and a line, every junction a corner (LinuxCNC's
/// `arc-arc-convex.ngc` in millimetres): under `G64 P0.05` the trapezoid plan rounds all
/// three corners that involve an arc, and is faster for it; the jerk-limited mode never
/// slower. Before this item only line–line corners were blended: no blend here.
#[test]
fn corners_with_arcs_are_blended_where_that_is_faster() {
    let template =
        "G21 G90 G17 G64 P{P}\nG1 X2.54 F1500\nG2 X5.08 R2.54\nG3 X7.62 R5.08\nG1 X20.32\nM2\n";
    for profile in [ProfileKind::Trapezoid, ProfileKind::SCurve] {
        let exact = plan_and_check(template, 0.0, profile).unwrap();
        assert_eq!(blend_count(&exact, 2), 0, "P0 keeps the corners");
        let blended = plan_and_check(template, 0.05, profile).unwrap();
        let (t, t0) = (blended.duration_s(), exact.duration_s());
        assert!(t <= t0, "{profile:?}: {t} s against {t0} s exact");
        if profile == ProfileKind::Trapezoid {
            assert_eq!(blend_count(&blended, 2), 3, "line–arc, arc–arc, arc–line");
            // (0.834 s against 0.880 since session 30, whose arcs accelerate with what the
            // axes leave beside their centripetal part; more than 0.05 s less before.)
            assert!(t < 0.96 * t0, "{t} s against {t0} s exact");
        }
    }
}

/// A helix keeps its corners (a planar blend would leave it), and so does a line out of an
/// arc's plane; the plan still keeps the limits and the tolerance.
#[test]
fn helices_and_corners_out_of_the_plane_stay_sharp() {
    let helix = "G21 G90 G17 G64 P{P}\nG1 X10 F3000\nG3 X20 Y0 Z2 I5 J0\nG1 X20 Y-10\nM2\n";
    let out_of_plane =
        "G21 G90 G17 G64 P{P}\nG1 X10 Z5 F3000\nG3 X20 Y0 I5 J0\nG1 X20 Y-10 Z0\nM2\n";
    for profile in [ProfileKind::Trapezoid, ProfileKind::SCurve] {
        let plan = plan_and_check(helix, 0.5, profile).unwrap();
        assert_eq!(blend_count(&plan, 1), 0, "{profile:?}: helix");
        let plan = plan_and_check(out_of_plane, 0.5, profile).unwrap();
        assert_eq!(blend_count(&plan, 1), 0, "{profile:?}: out of the plane");
    }
}

/// A blend shortens the element before it; where the element before that had already settled
/// its end speed (the start of the shortened one), the shortened element must still be able to
/// slow from it. LinuxCNC's `performance/Pasta.ngc` and `LHchips4.ngc` on the demo machine at
/// a 1 ms cycle (`tools/corpus-times.sh`) failed with `NoProfile` before the plan checked it.
#[test]
fn a_blend_leaves_the_settled_speeds_reachable() {
    let corpus =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/corpus/linuxcnc-tp");
    if !corpus.is_dir() {
        println!("corpus {} is absent: skipping", corpus.display());
        return;
    }
    let machine_file = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("dictionaries/machines/demo-xyz.toml");
    let mut machine = canmotion::config::Machine::load(&machine_file).unwrap();
    machine.planner.period_s = 0.001;
    let limits = canmotion::gateway::limits(&machine);
    for name in ["performance/Pasta.ngc", "performance/LHchips4.ngc"] {
        // The corpus test's tools (`tests/gcode_corpus.rs`).
        let mut setup = Setup::new(Vector3::zeros());
        for n in 1..=20u32 {
            let tool = Tool {
                radius_mm: 1.0,
                length_mm: 20.0 + f64::from(n),
            };
            setup.tools.insert(n, tool);
        }
        let file = std::fs::File::open(corpus.join(name)).unwrap();
        let interpreter = Interpreter::new(std::io::BufReader::new(file), name, setup);
        let items: Vec<Item> = interpreter.map(|item| item.unwrap()).collect();
        let plan = plan_items_with(Vector3::zeros(), &items, &limits, &machine.planner);
        assert!(plan.is_ok(), "{name}: {:?}", plan.err());
    }
}
