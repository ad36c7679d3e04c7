//! Issue 15 item 5, the smaller gaps: G52 local offsets, spiral arcs within LinuxCNC's
//! tolerance, fractional line numbers, G5/G5.1 splines, G7/G8, predefined named parameters,
//! G10 L20 on a rotated system. Each has a program in `tests/programs/`, planned through
//! `canmotion plan --path` and compared with hand-computed points (to 0.001 mm); the variants
//! that stay errors are matched by kind, line and column.

use std::path::Path;
use std::process::Command;

use canmotion::gcode::{ElementKind, ErrorKind, parse_program};
use nalgebra::Vector3;

/// An element of the path file: source line, kind, rapid, end, centre (arcs).
type Record = (u64, String, bool, [f64; 3], Option<[f64; 3]>);

fn plan_path(program: &str) -> Vec<Record> {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("path.jsonl");
    let out = Command::new(env!("CARGO_BIN_EXE_canmotion"))
        .arg("plan")
        .arg(
            Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("tests/programs")
                .join(program),
        )
        .arg("--path")
        .arg(&path)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    let point = |v: &serde_json::Value| -> Option<[f64; 3]> {
        let a = v.as_array()?;
        Some([0, 1, 2].map(|i| a[i].as_f64().unwrap()))
    };
    let mut at = [0.0; 3];
    std::fs::read_to_string(&path)
        .unwrap()
        .lines()
        .map(|l| {
            let v: serde_json::Value = serde_json::from_str(l).unwrap();
            assert_eq!(point(&v["start"]), Some(at), "continuity: {v}");
            at = point(&v["end"]).unwrap();
            (
                v["line"].as_u64().unwrap(),
                v["kind"].as_str().unwrap().to_owned(),
                v["rapid"].as_bool().unwrap(),
                at,
                point(&v["center"]),
            )
        })
        .collect()
}

fn close(a: [f64; 3], b: [f64; 3]) -> bool {
    (0..3).all(|k| (a[k] - b[k]).abs() <= 0.001)
}

/// An expected element: source line, kind, rapid, end, centre (arcs).
type Want<'a> = (u64, &'a str, bool, [f64; 3], Option<[f64; 3]>);

#[track_caller]
fn check(program: &str, expected: &[Want]) {
    let path = plan_path(program);
    for (i, (got, want)) in path.iter().zip(expected).enumerate() {
        let centre_ok = match (got.4, want.4) {
            (Some(a), Some(b)) => close(a, b),
            (None, None) => true,
            _ => false,
        };
        assert!(
            got.0 == want.0
                && got.1 == want.1
                && got.2 == want.2
                && close(got.3, want.3)
                && centre_ok,
            "{program}: element {i}: got {got:?}, expected {want:?}"
        );
    }
    assert_eq!(path.len(), expected.len(), "{program}: {path:?}");
}

const R: bool = true;
const F: bool = false;

#[test]
fn g52_offsets_the_work_system_locally_and_g92_1_clears_it() {
    check(
        "g52.ngc",
        &[
            (4, "line", R, [5.0, 0.0, 1.0], None),
            // G52 X10 Y20 on G54 (X5): program 0,0 is machine 15,20.
            (6, "line", R, [15.0, 20.0, 1.0], None),
            (7, "line", F, [20.0, 20.0, 1.0], None),
            // G52 X0 Y0: back on G54.
            (9, "line", R, [5.0, 0.0, 1.0], None),
            // G52 Z-1 keeps X and Y (0): Z0 is machine -1.
            (11, "line", R, [5.0, 0.0, -1.0], None),
            // G92.1 clears the shared register: Z1 is machine 1.
            (13, "line", R, [5.0, 0.0, 1.0], None),
        ],
    );
    // G52 needs an axis word, and takes the axis words for itself.
    let e = parse_program("G21\nG52\n", "p", Vector3::zeros()).unwrap_err();
    assert_eq!((e.line, e.col), (2, 1));
    assert!(matches!(e.kind, ErrorKind::MissingWord { .. }), "{e}");
    let e = parse_program("G21\nG1 G52 X1 F60\n", "p", Vector3::zeros()).unwrap_err();
    assert!(
        matches!(e.kind, ErrorKind::AxisWordsClaimedTwice { .. }),
        "{e}"
    );
}

#[test]
fn spiral_arcs_within_the_tolerance_are_planned_as_linuxcnc_interpolates_them() {
    check(
        "spiral.ngc",
        &[
            (3, "line", R, [110.0, 100.0, 0.0], None),
            (5, "arc", F, [89.98, 100.0, 0.0], Some([100.0, 100.0, 0.0])),
            (6, "line", R, [140.0, 100.0, 0.0], None),
            (8, "arc", F, [59.965, 100.0, 0.0], Some([100.0, 100.0, 0.0])),
        ],
    );
    // The radius changes in proportion to the angle: half way round, it is the mean radius.
    let text = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/programs/spiral.ngc"),
    )
    .unwrap();
    let p = parse_program(&text, "spiral.ngc", Vector3::zeros()).unwrap();
    let arcs: Vec<_> = p
        .elements()
        .filter(|e| matches!(e.kind, ElementKind::Arc { .. }))
        .map(|e| e.arc().unwrap())
        .collect();
    let mid = |k: usize| arcs[k].point_at(0.5);
    assert!(
        (mid(0) - Vector3::new(100.0, 110.01, 0.0)).norm() < 1e-9,
        "{}",
        mid(0)
    );
    assert!(
        (mid(1) - Vector3::new(100.0, 59.9825, 0.0)).norm() < 1e-9,
        "{}",
        mid(1)
    );
}

#[test]
fn spiral_arcs_beyond_linuxcnc_s_tolerance_stay_errors() {
    // 3 mm off on a 10 m radius: 0.03 % of it, but more than 100 times 0.0283 mm.
    let e = parse_program(
        "G21 F600\nG0 X10000\nG3 X-10003 Y0 I-10000 J0\n",
        "p",
        Vector3::zeros(),
    )
    .unwrap_err();
    assert_eq!((e.line, e.col), (3, 1));
    assert!(
        matches!(e.kind, ErrorKind::ArcRadiusMismatch { tolerance_mm, .. }
            if (tolerance_mm - 2.828427).abs() < 1e-6),
        "{e}"
    );
    // 0.1 mm off a 5 mm radius: 2 % and more than 0.0283 mm.
    let e = parse_program("G21 F60\nG0 X10\nG2 X0.1 Y0 I-5", "p", Vector3::zeros()).unwrap_err();
    assert!(matches!(e.kind, ErrorKind::ArcRadiusMismatch { .. }), "{e}");
    // An inch program has the inch tolerance, 0.002828 in: 0.0025 in off a 1 in radius is
    // a spiral there (it would not be in mm: 0.0635 mm and 0.25 %).
    let p = parse_program(
        "G20 F10\nG0 X1 Y0\nG3 X-1.0025 Y0 I-1 J0\n",
        "p",
        Vector3::zeros(),
    )
    .unwrap();
    let arc = p.elements().last().unwrap().arc().unwrap();
    assert!((arc.end_radius_mm - 1.0025 * 25.4).abs() < 1e-9);
    let e = parse_program(
        "G21 F10\nG0 X25.4 Y0\nG3 X-25.4635 Y0 I-25.4 J0\n",
        "p",
        Vector3::zeros(),
    )
    .unwrap_err();
    assert!(matches!(e.kind, ErrorKind::ArcRadiusMismatch { .. }), "{e}");
}

#[test]
fn fractional_line_numbers_are_read() {
    check(
        "line_numbers.ngc",
        &[
            (2, "line", R, [1.0, 0.0, 0.0], None),
            (3, "line", R, [2.0, 3.0, 0.0], None),
        ],
    );
    let e = parse_program("N-5 G0 X1\n", "p", Vector3::zeros()).unwrap_err();
    assert_eq!((e.line, e.col), (1, 1));
    assert!(matches!(e.kind, ErrorKind::InvalidValue { .. }), "{e}");
    // An N word before an O-word may be fractional too.
    let p = parse_program(
        "o1 sub\nG0 X#1\no1 endsub\nN7.5 o1 call [4]\n",
        "p",
        Vector3::zeros(),
    )
    .unwrap();
    assert_eq!(p.end_mm(), Vector3::new(4.0, 0.0, 0.0));
}

/// The feeds of a plan's elements, mm/s (0 for rapids).
fn feeds(program: &str) -> Vec<f64> {
    let text = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/programs")
            .join(program),
    )
    .unwrap();
    parse_program(&text, program, Vector3::zeros())
        .unwrap()
        .elements()
        .map(|e| e.feed_mm_s.unwrap_or(0.0))
        .collect()
}

#[test]
fn m70_to_m73_save_invalidate_and_restore_the_modal_state() {
    check(
        "modal_state.ngc",
        &[
            (3, "line", R, [10.0, 10.0, 0.0], None),
            // G20 G91 after M70: X1 is 25.4 mm further, at 60 in/min.
            (6, "line", F, [35.4, 10.0, 0.0], None),
            // M72: G21 G90 F600 again.
            (8, "line", F, [20.0, 10.0, 0.0], None),
            // In o<inc>, after M73: G91 F300.
            (12, "line", F, [20.0, 15.0, 0.0], None),
            // Its return restored G90 F600.
            (15, "line", F, [20.0, 0.0, 0.0], None),
        ],
    );
    assert_eq!(feeds("modal_state.ngc"), [0.0, 25.4, 10.0, 5.0, 10.0]);
    let err = |text: &str| parse_program(text, "p", Vector3::zeros()).unwrap_err();
    // Nothing saved; invalidated by M71; saved at another call level.
    for (text, line, col) in [
        ("G21\n  M72\n", 2, 3),
        ("M70\nM71\nM72\n", 3, 1),
        ("M70\no1 sub\nM72\no1 endsub\no1 call\n", 3, 1),
    ] {
        let e = err(text);
        assert_eq!(
            (e.line, e.col, &e.kind),
            (line, col, &ErrorKind::NoSavedModalState),
            "{text}"
        );
    }
    // G7/G8 belong to the saved state (LinuxCNC's list).
    check(
        "modal_lathe.ngc",
        &[
            (3, "line", R, [10.0, 0.0, 0.0], None),
            (6, "line", F, [5.0, 0.0, 0.0], None),
            (8, "line", F, [10.0, 0.0, 0.0], None),
        ],
    );
    // A restore that would switch cutter compensation is refused.
    let e = err("G21 F60\nM70\nG41.1 D2\nM72\n");
    assert_eq!((e.line, e.col), (4, 1));
    assert!(e.is_unsupported(), "{e}");
}

#[test]
fn system_parameters_read_the_interpreter_s_state() {
    check(
        "system_params.ngc",
        &[
            // G55 at machine (100, 50).
            (5, "line", R, [110.0, 70.0, 2.0], None),
            // #5420 (X now, 10) + 5; #5242 (G55's Y origin, 50).
            (6, "line", R, [115.0, 100.0, 2.0], None),
            // #5220 (work system 2); #5599 (1) + #5070 (0) + #5399 (0).
            (7, "line", R, [102.0, 51.0, 2.0], None),
            // Under G20, #5422 is Z in inches (2 mm); half of it.
            (9, "line", R, [102.0, 51.0, 1.0], None),
        ],
    );
    // Read-only, and the ones not kept are named.
    let e = parse_program("G21\n#5220 = 1\n", "p", Vector3::zeros()).unwrap_err();
    assert_eq!(e.line, 2);
    assert!(e.is_unsupported(), "{e}");
    let e = parse_program("G21\nG0 X#5001\n", "p", Vector3::zeros()).unwrap_err();
    assert_eq!((e.line, e.col), (2, 5));
    assert_eq!(e.unsupported_feature(), Some("system parameter #5001"));
}

#[test]
fn polar_coordinates_place_g0_g1_moves_about_the_origin() {
    let h = 5.0 * std::f64::consts::FRAC_1_SQRT_2;
    check(
        "polar.ngc",
        &[
            // G54 at (100, 100): @10 ^0 is program (10, 0).
            (4, "line", R, [110.0, 100.0, 0.0], None),
            // ^90 alone keeps the distance, 10.
            (5, "line", F, [100.0, 110.0, 0.0], None),
            // @20 alone keeps the angle, 90°.
            (6, "line", F, [100.0, 120.0, 0.0], None),
            // G91: distance 20 - 10, angle 90° + 90°.
            (7, "line", F, [90.0, 100.0, 0.0], None),
            (8, "line", R, [100.0 + h, 100.0 + h, 1.0], None),
        ],
    );
    let err = |text: &str| parse_program(text, "p", Vector3::zeros()).unwrap_err();
    let e = err("G21\nG0 @2 X1\n");
    assert_eq!(
        (e.line, e.col, &e.kind),
        (2, 7, &ErrorKind::PolarWithXy { letter: 'X' })
    );
    let e = err("G21 G91\nG0 ^10\n");
    assert_eq!(
        (e.line, e.col, &e.kind),
        (2, 4, &ErrorKind::PolarFromOrigin)
    );
    for (text, col) in [("G21 F60\nG2 @5 ^90 R5\n", 4), ("G21\nG28 @1\n", 5)] {
        let e = err(text);
        assert_eq!((e.line, e.col), (2, col), "{text}");
        assert!(e.is_unsupported(), "{text}: {e}");
    }
}

#[test]
fn g10_l10_and_l11_touch_tools_off_at_the_current_point() {
    check(
        "touch_off.ngc",
        &[
            // G54 Z origin at -50: Z10 is machine -40.
            (4, "line", R, [0.0, 0.0, -40.0], None),
            // L10: tool 1 is 10 long (Z reads 0 here); under G43 H1, Z5 is -50 + 10 + 5.
            (7, "line", R, [0.0, 0.0, -35.0], None),
            // L11 against G59.3 (Z -60): tool 2 is -35 + 60 = 25 long; Z0 is -50 + 25.
            (11, "line", R, [0.0, 0.0, -25.0], None),
            // G92 Z1 (here, Z reads 1), then L10 counts it: tool 3 is -25 + 50 - g92 - 0
            // where g92 = -1 (the point read 0, now 1): 26 long; Z-2 is -50 - 1 + 26 - 2.
            (15, "line", R, [0.0, 0.0, -27.0], None),
        ],
    );
    let text = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/programs/touch_off.ngc"),
    )
    .unwrap();
    let mut it = canmotion::gcode::Interpreter::new(
        text.as_bytes(),
        "t",
        canmotion::gcode::Setup::new(Vector3::zeros()),
    );
    for item in it.by_ref() {
        item.unwrap();
    }
    let tools = it.tools();
    assert_eq!(tools.get(1).unwrap().length_mm, 10.0);
    assert_eq!(tools.get(2).unwrap().length_mm, 25.0);
    assert_eq!(tools.get(2).unwrap().radius_mm, 1.5);
    assert_eq!(tools.get(3).unwrap().length_mm, 26.0);
    let e = parse_program("G21\nG10 L10 P1 X0 Z0\n", "p", Vector3::zeros()).unwrap_err();
    assert_eq!((e.line, e.col), (2, 12));
    assert!(e.is_unsupported(), "{e}");
}

/// The point at `t` of the Bézier curve with control points `p` (3 or 4, XY), written out
/// independently of the interpreter's.
fn bezier(p: &[[f64; 2]], t: f64) -> [f64; 2] {
    let s = 1.0 - t;
    let w: Vec<f64> = if p.len() == 3 {
        vec![s * s, 2.0 * s * t, t * t]
    } else {
        vec![s * s * s, 3.0 * s * s * t, 3.0 * s * t * t, t * t * t]
    };
    let mut out = [0.0; 2];
    for (pk, wk) in p.iter().zip(&w) {
        out[0] += pk[0] * wk;
        out[1] += pk[1] * wk;
    }
    out
}

/// The distance from `q` to the segment `a`–`b`.
fn to_segment(q: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let len2 = dx * dx + dy * dy;
    let u = if len2 == 0.0 {
        0.0
    } else {
        (((q[0] - a[0]) * dx + (q[1] - a[1]) * dy) / len2).clamp(0.0, 1.0)
    };
    (q[0] - a[0] - u * dx).hypot(q[1] - a[1] - u * dy)
}

#[test]
fn g5_and_g5_1_splines_are_sampled_on_the_curve_within_the_chord_tolerance() {
    let path = plan_path("splines.ngc");
    // The default machine's chord_tol_mm.
    let tol_mm = canmotion::gcode::DEFAULT_SPLINE_TOL_MM;
    let curves: [(u64, Vec<[f64; 2]>); 3] = [
        (4, vec![[0.0, 20.0], [10.0, 30.0], [20.0, 20.0]]),
        (
            5,
            vec![[20.0, 20.0], [25.0, 30.0], [35.0, 30.0], [40.0, 20.0]],
        ),
        // No I J: the start direction is the last G5's -(P, Q) = (5, -10).
        (
            6,
            vec![[40.0, 20.0], [45.0, 10.0], [55.0, 10.0], [60.0, 20.0]],
        ),
    ];
    let mut at = [0.0, 20.0];
    for (line, points) in &curves {
        let lines: Vec<&Record> = path.iter().filter(|r| r.0 == *line).collect();
        let n = lines.len();
        assert!(n > 10, "line {line}: {n} lines");
        for (k, r) in lines.iter().enumerate() {
            assert_eq!((r.1.as_str(), r.2), ("line", F), "line {line}: {r:?}");
            assert_eq!(r.3[2], 0.0);
            let t = (k + 1) as f64 / n as f64;
            let want = bezier(points, t);
            assert!(
                close(r.3, [want[0], want[1], 0.0]),
                "line {line}: sample {k} at {:?}, curve at t = {t}: {want:?}",
                r.3
            );
            // Every chord stays within the tolerance of the curve between its samples.
            let end = [r.3[0], r.3[1]];
            let t0 = k as f64 / n as f64;
            for j in 0..=50 {
                let q = bezier(points, t0 + (t - t0) * j as f64 / 50.0);
                let d = to_segment(q, at, end);
                assert!(d <= tol_mm + 1e-9, "line {line}: chord {k} is {d} mm off");
            }
            at = end;
        }
    }
    // Hand-computed: the ends, and the middles of the cubics (t = 1/2 is a sample when the
    // count is even): (P0 + 3 P1 + 3 P2 + P3) / 8.
    let ends: Vec<[f64; 3]> = [4, 5, 6]
        .iter()
        .map(|l| path.iter().rfind(|r| r.0 == *l).unwrap().3)
        .collect();
    assert_eq!(
        ends,
        vec![[20.0, 20.0, 0.0], [40.0, 20.0, 0.0], [60.0, 20.0, 0.0]]
    );
    for (line, middle) in [(5, [30.0, 27.5, 0.0]), (6, [50.0, 12.5, 0.0])] {
        let lines: Vec<&Record> = path.iter().filter(|r| r.0 == line).collect();
        // 92 lines each (⌈√(6·√125 / 0.008)⌉): t = 1/2 is sample 46.
        assert!(
            lines.len().is_multiple_of(2),
            "line {line}: {}",
            lines.len()
        );
        assert!(close(lines[lines.len() / 2 - 1].3, middle), "line {line}");
    }
    assert_eq!(path.last().unwrap().3, [70.0, 20.0, 0.0]);

    // LinuxCNC's errors, with line and column.
    let err = |text: &str| parse_program(text, "p", Vector3::zeros()).unwrap_err();
    let e = err("G21 F60\nG18 G5.1 X1 I1 J1\n");
    assert_eq!(
        (e.line, e.col, e.kind),
        (
            2,
            5,
            ErrorKind::SplinePlane {
                code: "G5.1",
                plane: "G18"
            }
        )
    );
    let e = err("G21 F60\nG5.1 X1 Z1 I1 J1\n");
    assert_eq!(
        (e.line, e.col, e.kind),
        (
            2,
            9,
            ErrorKind::SplineAxis {
                code: "G5.1",
                letter: 'Z'
            }
        )
    );
    let e = err("G21\nG5.1 X1 I1 J1\n");
    assert_eq!(
        (e.line, e.col, e.kind),
        (2, 1, ErrorKind::MissingFeed { code: "G5.1" })
    );
    for (text, line, letter) in [
        ("G21 F60\nG5.1 X1 I1\n", 2, 'J'),
        ("G21 F60\nG5 X1 Y1 P1 Q1\n", 2, 'I'),
        ("G21 F60\nG5 X1 I1 J1 P1\n", 2, 'Q'),
        ("G21 F60\nG5 X1 J1 P1 Q1\n", 2, 'I'),
        // The continuation needs a G5 right before.
        ("G21 F60\nG5 X1 I1 J1 P1 Q1\nG1 X2\nG5 X3 P1 Q1\n", 4, 'I'),
    ] {
        let e = err(text);
        assert!(
            matches!(&e.kind, ErrorKind::MissingWord { letter: l, .. } if *l == letter)
                && (e.line, e.col) == (line, 1),
            "{text}: {e}"
        );
    }
    let e = err("G21 F60 G41.1 D2\nG0 X10\nG5.1 X20 I1 J1\n");
    assert_eq!(
        (e.line, e.kind),
        (3, ErrorKind::SplineWithCompensation { code: "G5.1" })
    );
    // A spline the bound would cut into more than MAX_SPLINE_SEGMENTS lines is refused.
    let mut setup = canmotion::gcode::Setup::new(Vector3::zeros());
    setup.spline_tol_mm = canmotion::gcode::MIN_SPLINE_TOL_MM;
    let e = canmotion::gcode::parse_program_with(
        "G21 F60\nG5.1 X1000000 I500000 J500000\n",
        "p",
        setup,
    )
    .unwrap_err();
    assert!(
        matches!(e.kind, ErrorKind::SplineTooLong { code: "G5.1", max, .. } if max == canmotion::gcode::MAX_SPLINE_SEGMENTS)
            && (e.line, e.col) == (2, 1),
        "{e}"
    );
    let e = err("G21 F60\nG5.2 X1 Y1 P1\n");
    assert_eq!((e.line, e.col), (2, 1));
    assert!(e.is_unsupported(), "{e}");
}

#[test]
fn g7_reads_x_words_as_diameters_and_g8_as_radii() {
    check(
        "lathe_diameter.ngc",
        &[
            // G7 on the line: X20 is a radius of 10.
            (3, "line", R, [10.0, 0.0, 0.0], None),
            (4, "line", F, [15.0, 0.0, -10.0], None),
            // X50 is 25; I stays a radius: the centre is 10 away along X.
            (5, "arc", F, [25.0, 0.0, -20.0], Some([25.0, 0.0, -10.0])),
            // G91: X-10 (diameter) is -5.
            (6, "line", F, [20.0, 0.0, -20.0], None),
            (7, "line", R, [30.0, 0.0, -20.0], None),
        ],
    );
    let text = "G21 G7\n";
    let mut it = canmotion::gcode::Interpreter::new(
        text.as_bytes(),
        "p",
        canmotion::gcode::Setup::new(Vector3::zeros()),
    );
    assert!(!it.diameter_mode());
    it.next();
    assert!(it.diameter_mode());
    // `#<_lathe_diameter_mode>` reads it.
    let p = parse_program(
        "G21 G7\nG0 X[#<_lathe_diameter_mode> * 10 + #<_lathe_radius_mode>]\n",
        "p",
        Vector3::zeros(),
    )
    .unwrap();
    assert_eq!(p.end_mm(), Vector3::new(5.0, 0.0, 0.0));
}

#[test]
fn predefined_named_parameters_read_the_interpreter_s_state() {
    check(
        "named_params.ngc",
        &[
            (3, "line", R, [10.0, 20.0, 5.0], None),
            // G92 puts the program origin at (10, 20): #<_abs_x> + #<_abs_y> is 30.
            (5, "line", F, [40.0, 20.0, 5.0], None),
            // #<_x> (30) + #<_metric> (1).
            (6, "line", R, [40.0, 51.0, 5.0], None),
            // #<_plane> (170) / 100 + #<_motion_mode> (G0: 0) - 5.
            (7, "line", R, [40.0, 51.0, -3.3], None),
            // #<_coord_system> (540) / 10 + EXISTS (1) + #<_feed> (600) / 100 + level 0.
            (8, "line", R, [71.0, 51.0, -3.3], None),
            // The subroutine returns #<_call_level> (1) * 5; #<_value_returned> is 1.
            (13, "line", R, [71.0, 26.0, -3.3], None),
        ],
    );
    // Read-only, and the ones LinuxCNC has but this front end does not keep are named.
    let e = parse_program("G21\n#<_x> = 1\n", "p", Vector3::zeros()).unwrap_err();
    assert_eq!(
        (e.line, e.kind),
        (
            2,
            ErrorKind::ReadOnlyParameter {
                name: "_x".to_owned()
            }
        )
    );
    let e = parse_program("G21\nG0 X#<_mist>\n", "p", Vector3::zeros()).unwrap_err();
    assert_eq!(e.line, 2);
    assert_eq!(
        e.unsupported_feature(),
        Some("predefined parameter #<_mist>")
    );
    // LinuxCNC's INI and HAL readers: named as unsupported, with line and column.
    for (text, name) in [
        (
            "G21\nG0 X#<_ini[AXIS_X]MAX_VELOCITY>\n",
            "#<_ini[axis_x]max_velocity>",
        ),
        (
            "G21\nG0 X[1 + #<_hal[motion.spindle-speed]>]\n",
            "#<_hal[motion.spindle-speed]>",
        ),
    ] {
        let e = parse_program(text, "p", Vector3::zeros()).unwrap_err();
        assert_eq!(e.line, 2, "{e}");
        assert_eq!(
            e.unsupported_feature(),
            Some(format!("parameter {name}").as_str()),
            "{e}"
        );
    }
    // EXISTS knows them; a global of one's own still works.
    let p = parse_program(
        "G21\n#<_mine> = 2\nG0 X[EXISTS[#<_mist>] + EXISTS[#<_nope>] + #<_mine>]\n",
        "p",
        Vector3::zeros(),
    )
    .unwrap();
    assert_eq!(p.end_mm(), Vector3::new(3.0, 0.0, 0.0));
    // #<_line> is the line of the file (LinuxCNC's sequence number), not the N word.
    let p = parse_program("G21\n\nN10 G0 X#<_line>\n", "p", Vector3::zeros()).unwrap();
    assert_eq!(p.end_mm(), Vector3::new(3.0, 0.0, 0.0));
}

#[test]
fn g10_l20_sets_a_rotated_system_and_g10_takes_a_negative_radius() {
    check(
        "g10_rotated.ngc",
        &[
            // G54 at (100, 0) turned 90°: (10, 4) is machine (100 - 4, 10).
            (4, "line", R, [96.0, 10.0, 0.0], None),
            // L20 X0: the point reads X0 and still Y4, so the origin is (96, 10) - R(0, 4)
            // = (100, 10); (5, 4) is (100 - 4, 10 + 5).
            (6, "line", R, [96.0, 15.0, 0.0], None),
            // L20 X0 Y0 R0: the origin is here, unturned.
            (8, "line", R, [97.0, 17.0, 0.0], None),
        ],
    );
    let text = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/programs/g10_rotated.ngc"),
    )
    .unwrap();
    let mut it = canmotion::gcode::Interpreter::new(
        text.as_bytes(),
        "t",
        canmotion::gcode::Setup::new(Vector3::zeros()),
    );
    for item in it.by_ref() {
        item.unwrap();
    }
    assert_eq!(it.tools().get(1).unwrap().radius_mm, -2.0);
    assert_eq!(it.tools().get(2).unwrap().radius_mm, -1.5);
}
