//! Cutter radius compensation end to end: G-code text → interpreter → compensator, with the
//! demo tool table (T1: radius 2 mm). Every expected point is worked out by hand from the
//! programmed shape, never copied from the output.

use std::f64::consts::TAU;
use std::path::Path;

use canmotion::compensation::{CompOptions, Compensator, OutsideCorners, compensate_program};
use canmotion::gcode::{
    CompState, Element, ElementKind, Error, ErrorKind, Interpreter, Item, Program, Setup, Tool,
    ToolTable, parse_program_with,
};
use nalgebra::{Vector2, Vector3};
use proptest::prelude::*;

const FILE: &str = "part.ngc";

fn demo_tools() -> ToolTable {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("dictionaries/tools/demo-tools.toml");
    ToolTable::load(&path).expect("demo tool table loads")
}

fn setup() -> Setup {
    let mut s = Setup::new(Vector3::zeros());
    s.tools = demo_tools();
    s
}

/// The interpreter's elements (the programmed path).
fn programmed(text: &str) -> Vec<Element> {
    Interpreter::new(text.as_bytes(), FILE, setup())
        .filter_map(|i| match i.expect("the program interprets") {
            Item::Motion(e) => Some(e),
            _ => None,
        })
        .collect()
}

/// The compensated items; checks continuity (bit for bit) and finiteness on the way.
fn compensate_with(text: &str, options: CompOptions) -> Result<Vec<Item>, Error> {
    let interp = Interpreter::new(text.as_bytes(), FILE, setup());
    let items: Vec<Item> = Compensator::new(interp, FILE, options).collect::<Result<_, _>>()?;
    let mut last: Option<Vector3<f64>> = None;
    for e in motions(&items) {
        assert!(
            e.start_mm
                .iter()
                .chain(e.end_mm.iter())
                .all(|c| c.is_finite()),
            "{e:?}"
        );
        if let Some(last) = last {
            assert_eq!(e.start_mm, last, "discontinuity before line {}", e.line);
        }
        last = Some(e.end_mm);
    }
    Ok(items)
}

/// The source's C-type outside corners (extended, inserted), which the square, D-shape, lens
/// and pocket tests below compute by hand; the default is LinuxCNC's arcs.
fn lines() -> CompOptions {
    CompOptions {
        outside_corners: OutsideCorners::Lines,
    }
}

fn compensate(text: &str) -> Result<Vec<Item>, Error> {
    compensate_with(text, CompOptions::default())
}

fn motions(items: &[Item]) -> Vec<Element> {
    items.iter().filter_map(Item::motion).copied().collect()
}

/// The compensated elements from the start-up move on.
fn comp_path(text: &str, options: CompOptions) -> Vec<Element> {
    let items = compensate_with(text, options).unwrap_or_else(|e| panic!("{e}"));
    motions(&items)
        .into_iter()
        .skip_while(|e| e.comp == CompState::Off)
        .collect()
}

fn close(a: Vector3<f64>, b: Vector3<f64>) -> bool {
    (a - b).norm() < 1e-9
}

/// Asserts a chain of straight elements through the XY points `points` (z = 0).
#[track_caller]
fn assert_polyline(path: &[Element], points: &[(f64, f64)]) {
    assert_eq!(path.len() + 1, points.len(), "{path:#?}");
    for (e, w) in path.iter().zip(points.windows(2)) {
        assert_eq!(e.kind, ElementKind::Line, "{e:?}");
        let (a, b) = (
            Vector3::new(w[0].0, w[0].1, 0.0),
            Vector3::new(w[1].0, w[1].1, 0.0),
        );
        assert!(
            close(e.start_mm, a) && close(e.end_mm, b),
            "line {}: {} -> {}, want {a} -> {b}",
            e.line,
            e.start_mm,
            e.end_mm
        );
    }
}

/// A 20 mm square with corners (0,0) and (20,20), entered from (−10,10) along +X onto the
/// middle of its left side and left the same way, clockwise (up the left side first) or
/// counter-clockwise (down first), under `code` (G41 or G42) with D1.
fn square(code: &str, clockwise: bool) -> String {
    let sides = if clockwise {
        "Y20\nX20\nY0\nX0\nY10\n"
    } else {
        "Y0\nX20\nY20\nX0\nY10\n"
    };
    format!("G21 G17 G90\nG0 X-10 Y10\n{code} D1\nG1 X0 Y10 F600\n{sides}G40 X-10\nM2\n")
}

#[test]
fn square_clockwise_with_g41_lies_2_mm_outside() {
    // Tool left of a clockwise path: outside. Each side on its offset line (x = −2, y = 22,
    // x = 22, y = −2); the right-angle corners (α = 90°) extended by the radius. Start-up:
    // +X then +Y is an inside corner for the tool, so it ends on y = 12 and x = −2. G40, as
    // in LinuxCNC: the last side ends at its offset end (−2,10), the exit runs from there.
    let path = comp_path(&square("G41", true), lines());
    assert_polyline(
        &path,
        &[
            (-10.0, 10.0),
            (-2.0, 12.0),
            (-2.0, 22.0),
            (22.0, 22.0),
            (22.0, -2.0),
            (-2.0, -2.0),
            (-2.0, 10.0),
            (-10.0, 10.0),
        ],
    );
    // Line numbers and the comp state as programmed: the start-up is line 4, the cancel 10.
    let lines: Vec<usize> = path.iter().map(|e| e.line).collect();
    assert_eq!(lines, [4, 5, 6, 7, 8, 9, 10]);
    assert!(
        matches!(path[1].comp, CompState::Left { tool: Some(1), radius_mm } if radius_mm == 2.0)
    );
    assert_eq!(path[6].comp, CompState::Off);
}

#[test]
fn square_counter_clockwise_with_g41_lies_2_mm_inside() {
    // Tool left of a counter-clockwise path: inside, on x = 2, y = 2, x = 18, y = 18, every
    // corner shortened to the intersection. The start-up (+X then −Y) is an outside corner
    // for the tool: extended by the radius. The last side ends at its offset end (2,10).
    let path = comp_path(&square("G41", false), lines());
    assert_polyline(
        &path,
        &[
            (-10.0, 10.0),
            (2.0, 12.0),
            (2.0, 2.0),
            (18.0, 2.0),
            (18.0, 18.0),
            (2.0, 18.0),
            (2.0, 10.0),
            (-10.0, 10.0),
        ],
    );
}

#[test]
fn square_with_g42_mirrors() {
    // Clockwise with the tool right: inside.
    let path = comp_path(&square("G42", true), lines());
    assert_polyline(
        &path,
        &[
            (-10.0, 10.0),
            (2.0, 8.0),
            (2.0, 18.0),
            (18.0, 18.0),
            (18.0, 2.0),
            (2.0, 2.0),
            (2.0, 10.0),
            (-10.0, 10.0),
        ],
    );
    // Counter-clockwise with the tool right: outside.
    let path = comp_path(&square("G42", false), lines());
    assert_polyline(
        &path,
        &[
            (-10.0, 10.0),
            (-2.0, 8.0),
            (-2.0, -2.0),
            (22.0, -2.0),
            (22.0, 22.0),
            (-2.0, 22.0),
            (-2.0, 10.0),
            (-10.0, 10.0),
        ],
    );
}

#[test]
fn square_outside_with_corner_arcs() {
    // OutsideCorners::Arc: the sides keep their programmed length on the offset lines and each
    // outside corner is a clockwise quarter of radius 2 about the programmed corner.
    let path = comp_path(
        &square("G41", true),
        CompOptions {
            outside_corners: OutsideCorners::Arc,
        },
    );
    let corners = [(0.0, 20.0), (20.0, 20.0), (20.0, 0.0)];
    let arcs: Vec<&Element> = path
        .iter()
        .filter(|e| matches!(e.kind, ElementKind::Arc { .. }))
        .collect();
    // The fourth corner (0,0) too; the start-up and cancel corners are inside ones.
    assert_eq!(arcs.len(), 4, "{path:#?}");
    for (arc, (cx, cy)) in arcs.iter().zip(corners.iter().chain([(0.0, 0.0)].iter())) {
        let ElementKind::Arc {
            center_mm,
            cw,
            radius_mm,
            ..
        } = arc.kind
        else {
            unreachable!()
        };
        assert!(close(center_mm, Vector3::new(*cx, *cy, 0.0)), "{arc:?}");
        assert!(cw && (radius_mm - 2.0).abs() < 1e-12);
        let g = arc.arc().unwrap();
        assert!((g.sweep_rad - TAU / 4.0).abs() < 1e-12);
        for k in 0..=8 {
            let p = g.point_at(f64::from(k) / 8.0);
            assert!(((p - center_mm).norm() - 2.0).abs() < 1e-9);
        }
    }
    // The first side: from the start-up's end (−2,12) up to (−2,20), then the arc to (0,22).
    assert!(close(path[1].end_mm, Vector3::new(-2.0, 20.0, 0.0)));
    assert!(close(path[2].end_mm, Vector3::new(0.0, 22.0, 0.0)));
    assert!(close(path[3].end_mm, Vector3::new(20.0, 22.0, 0.0)));
}

/// A full clockwise circle about (10,0), radius 10, entered and left tangentially along +Y at
/// (0,0).
fn circle(code: &str) -> String {
    format!("G0 X0 Y-10\n{code} D1\nG1 X0 Y0 F600\nG2 X0 Y0 I10 J0\nG40 G1 X0 Y10\n")
}

#[test]
fn circle_offsets_concentric() {
    // Clockwise: G41 puts the tool outside (radius 12), G42 inside (radius 8).
    for (code, radius, x) in [("G41", 12.0, -2.0), ("G42", 8.0, 2.0)] {
        let path = comp_path(&circle(code), lines());
        assert_eq!(path.len(), 3, "{path:#?}");
        let start = Vector3::new(x, 0.0, 0.0);
        assert!(close(path[0].end_mm, start), "{code}: {}", path[0].end_mm);
        let ElementKind::Arc {
            center_mm,
            cw,
            radius_mm,
            turns,
            ..
        } = path[1].kind
        else {
            panic!("{code}: not an arc: {:?}", path[1]);
        };
        assert!(cw && turns == 0);
        assert!(close(center_mm, Vector3::new(10.0, 0.0, 0.0)));
        assert!((radius_mm - radius).abs() < 1e-12);
        let g = path[1].arc().unwrap();
        assert!((g.sweep_rad - TAU).abs() < 1e-12, "{code}: full circle");
        for k in 0..=32 {
            let p = g.point_at(f64::from(k) / 32.0);
            assert!(((p - center_mm).norm() - radius).abs() < 1e-9);
        }
        assert!(close(path[2].start_mm, start));
        assert!(close(path[2].end_mm, Vector3::new(0.0, 10.0, 0.0)));
    }
}

/// A "D": up the left edge (0,5)→(0,20), clockwise half circle about (0,10) to (0,0), up to
/// (0,5); entered and left along X at y = 5.
fn d_shape(code: &str) -> String {
    format!("G0 X-10 Y5\n{code} D1\nG1 X0 Y5 F600\nY20\nG2 X0 Y0 I0 J-10\nG1 Y5\nG40 X-10\n")
}

#[test]
fn line_arc_joins_outside_are_extended_along_the_tangent() {
    // G41 on the clockwise D: outside. Edge on x = −2, arc radius 12. The corners turn right
    // by 90° (α = 90°): the edge extends 2 mm to (−2,22), a straight connector along the
    // arc's tangent reaches the arc's offset start (0,22); at the bottom the arc ends at
    // (0,−2), a connector to (−2,−2), the edge from there to its offset end (−2,5) (G40).
    let path = comp_path(&d_shape("G41"), lines());
    assert_eq!(path.len(), 7, "{path:#?}");
    assert_polyline(
        &path[..3],
        &[(-10.0, 5.0), (-2.0, 7.0), (-2.0, 22.0), (0.0, 22.0)],
    );
    assert_eq!(path[2].line, 5, "the connector belongs to the arc's corner");
    let g = path[3].arc().expect("arc");
    assert!(close(g.center_mm, Vector3::new(0.0, 10.0, 0.0)));
    assert!((g.start_radius_mm - 12.0).abs() < 1e-12 && (g.end_radius_mm - 12.0).abs() < 1e-12);
    assert!((g.sweep_rad - TAU / 2.0).abs() < 1e-12);
    assert!(close(path[3].end_mm, Vector3::new(0.0, -2.0, 0.0)));
    assert_polyline(
        &path[4..],
        &[(0.0, -2.0), (-2.0, -2.0), (-2.0, 5.0), (-10.0, 5.0)],
    );

    // The same with corner arcs: radius 2 about (0,20) and (0,0).
    let path = comp_path(
        &d_shape("G41"),
        CompOptions {
            outside_corners: OutsideCorners::Arc,
        },
    );
    assert_eq!(path.len(), 7, "{path:#?}");
    assert!(close(path[1].end_mm, Vector3::new(-2.0, 20.0, 0.0)));
    let corner = path[2].arc().expect("corner arc");
    assert!(close(corner.center_mm, Vector3::new(0.0, 20.0, 0.0)));
    assert!((corner.start_radius_mm - 2.0).abs() < 1e-12);
    assert!(close(path[2].end_mm, Vector3::new(0.0, 22.0, 0.0)));
    let corner = path[4].arc().expect("corner arc");
    assert!(close(corner.center_mm, Vector3::new(0.0, 0.0, 0.0)));
    assert!(close(path[4].end_mm, Vector3::new(-2.0, 0.0, 0.0)));
}

#[test]
fn line_arc_joins_inside_meet_on_the_offset_circle() {
    // G42 on the clockwise D: inside. Edge on x = 2, arc radius 8 about (0,10); they meet
    // where x = 2 cuts that circle: y = 10 ± √60. The start-up corner is outside for the
    // tool (extended by the radius); the last edge ends at its offset end (2,5) (G40).
    let path = comp_path(&d_shape("G42"), lines());
    assert_eq!(path.len(), 5, "{path:#?}");
    let r60 = 60f64.sqrt();
    assert_polyline(&path[..2], &[(-10.0, 5.0), (2.0, 3.0), (2.0, 10.0 + r60)]);
    let g = path[2].arc().expect("arc");
    assert!(close(g.center_mm, Vector3::new(0.0, 10.0, 0.0)));
    assert!((g.start_radius_mm - 8.0).abs() < 1e-12);
    // Clockwise from atan2(√60, 2) to −atan2(√60, 2).
    assert!((g.sweep_rad - 2.0 * r60.atan2(2.0)).abs() < 1e-12);
    assert_polyline(&path[3..], &[(2.0, 10.0 - r60), (2.0, 5.0), (-10.0, 5.0)]);
}

/// A lens: the arc of the circle about (−6,0) from (0,−8) to (0,8) and the arc of the circle
/// about (6,0) back, both radius 10, counter-clockwise; entered along the first arc's tangent
/// (0.8, 0.6) and left along its end tangent (−0.8, 0.6) after a second lap of the first arc.
fn lens(code: &str) -> String {
    format!(
        "G0 X-8 Y-14\n{code} D1\nG1 X0 Y-8 F600\nG3 X0 Y8 I-6 J8\nG3 X0 Y-8 I6 J-8\n\
         G3 X0 Y8 I-6 J8\nG40 G1 X-8 Y14\n"
    )
}

#[test]
fn arc_arc_joins() {
    // G41: the tool inside, both arcs radius 8. The corners (turning left by 73.7°) are
    // inside: the circles of radius 8 about (±6,0) meet at (0, ±√28).
    let path = comp_path(&lens("G41"), lines());
    assert_eq!(path.len(), 5, "{path:#?}");
    let r28 = 28f64.sqrt();
    let pts = [
        Vector3::new(-1.2, -6.4, 0.0),
        Vector3::new(0.0, r28, 0.0),
        Vector3::new(0.0, -r28, 0.0),
        Vector3::new(-1.2, 6.4, 0.0),
    ];
    assert!(close(path[0].end_mm, pts[0]), "{}", path[0].end_mm);
    for (k, center) in [(1, -6.0), (2, 6.0), (3, -6.0)] {
        let g = path[k].arc().expect("arc");
        assert!(close(g.center_mm, Vector3::new(center, 0.0, 0.0)));
        assert!((g.start_radius_mm - 8.0).abs() < 1e-12);
        assert!((g.end_radius_mm - 8.0).abs() < 1e-12);
        assert!(close(path[k].start_mm, pts[k - 1]) && close(path[k].end_mm, pts[k]));
    }

    // G42: the tool outside, radius 12; the corners are outside with α = 106.3°, extended by
    // 2·tan(36.87°) = 1.5 along both tangents: from (1.2,9.6) to (0,10.5) to (−1.2,9.6).
    let path = comp_path(&lens("G42"), lines());
    let conns: Vec<&Element> = path
        .iter()
        .filter(|e| e.kind == ElementKind::Line && e.comp != CompState::Off && e.line != 3)
        .collect();
    assert_eq!(conns.len(), 4, "{path:#?}");
    assert!(close(conns[0].start_mm, Vector3::new(1.2, 9.6, 0.0)));
    assert!(close(conns[0].end_mm, Vector3::new(0.0, 10.5, 0.0)));
    assert!(close(conns[1].end_mm, Vector3::new(-1.2, 9.6, 0.0)));
    assert!(close(conns[2].end_mm, Vector3::new(0.0, -10.5, 0.0)));
    assert!(close(conns[3].end_mm, Vector3::new(1.2, -9.6, 0.0)));
}

#[test]
fn errors_name_file_line_and_column() {
    // The tool (radius 2) in a counter-clockwise inside arc of radius 2 under G41.
    let text = "G0 X-10 Y0\nG41 D1\nG1 X0 Y0 F600\nX10\n  G3 X14 Y0 I2 J0\nG40 G1 X20\n";
    let e = compensate(text).unwrap_err();
    assert!(matches!(e.kind, ErrorKind::CompensationArcTooSmall { .. }));
    assert_eq!(
        e.to_string(),
        "part.ngc:5:3: tool radius 2.0000 mm is too big for this arc of radius 2.0000 mm: the tool-centre arc would have radius 0.0000 mm (use a smaller tool or a larger arc)"
    );
    // A 3 mm wide slot bottom between two inside corners: each takes 2 mm of it.
    let text = "G0 X-10 Y0\nG41 D1\nG1 X0 Y0 F600\nX10\nY3\nX0\nG40 X-10\n";
    let e = compensate(text).unwrap_err();
    assert_eq!(
        e.to_string(),
        "part.ngc:5:1: cutter compensation with tool radius 2.0000 mm would gouge: this element is shorter than its corners take (its tool-centre path would run backwards)"
    );
    // Cancel on an arc.
    let text = "G0 X-10 Y0\nG41 D1\nG1 X0 Y0 F600\nX10\nG40 G3 X20 Y0 R5\n";
    let e = compensate(text).unwrap_err();
    assert_eq!((e.line, e.col), (5, 5));
    assert!(matches!(
        e.kind,
        ErrorKind::CompensationEndOnArc { code: "G3" }
    ));
}

#[test]
fn tool_0_and_g40_programs_pass_through_unchanged() {
    for text in [
        "G0 X-10 Y0\nG41 D0\nG1 X0 Y0 F600\nX10\nG2 X20 Y0 R5\nG40 G1 X30\n",
        "G0 X-10 Y0 Z5\nG1 X0 Y0 Z0 F600\nG3 X0 Y0 I5 J0 Z-1\nM2\n",
    ] {
        let plain: Vec<Item> = Interpreter::new(text.as_bytes(), FILE, setup())
            .collect::<Result<_, _>>()
            .unwrap();
        assert_eq!(compensate(text).unwrap(), plain);
    }
}

#[test]
fn pocket_with_fillets_cam_style() {
    // A 60 × 30 pocket with 5 mm corner fillets, counter-clockwise with G41 (tool inside),
    // plunged before the start-up, entered from below the bottom edge. All joins but the
    // start-up and cancel are tangent: sides on x = 2, 58 and y = 2, 28, fillets about their
    // own centres with radius 5 − 2 = 3. The start-up (+Y into +X: outside for the tool,
    // α = 90°) ends at (28,2); after G40 the last line ends at its offset end (30,2), and
    // the exit runs from there (LinuxCNC).
    let text = "G21 G17 G90 G94\nG0 Z5\nG0 X30 Y-10\nG1 Z-1 F300\nG41 D1\nG1 X30 Y0 F600\n\
                X55\nG3 X60 Y5 I0 J5\nG1 Y25\nG3 X55 Y30 I-5 J0\nG1 X5\nG3 X0 Y25 I0 J-5\n\
                G1 Y5\nG3 X5 Y0 I5 J0\nG1 X30\nG40 Y-10\nG0 Z5\nM2\n";
    let path = comp_path(text, lines());
    let z = -1.0;
    let p = |x: f64, y: f64| Vector3::new(x, y, z);
    let want_lines = [
        (6, p(30.0, -10.0), p(28.0, 2.0)),
        (7, p(28.0, 2.0), p(55.0, 2.0)),
        (9, p(58.0, 5.0), p(58.0, 25.0)),
        (11, p(55.0, 28.0), p(5.0, 28.0)),
        (13, p(2.0, 25.0), p(2.0, 5.0)),
        (15, p(5.0, 2.0), p(30.0, 2.0)),
        (16, p(30.0, 2.0), p(30.0, -10.0)),
    ];
    let want_arcs = [
        (8, p(55.0, 5.0), p(55.0, 2.0), p(58.0, 5.0)),
        (10, p(55.0, 25.0), p(58.0, 25.0), p(55.0, 28.0)),
        (12, p(5.0, 25.0), p(5.0, 28.0), p(2.0, 25.0)),
        (14, p(5.0, 5.0), p(2.0, 5.0), p(5.0, 2.0)),
    ];
    assert_eq!(
        path.len(),
        want_lines.len() + want_arcs.len() + 1,
        "{path:#?}"
    );
    for (line, a, b) in want_lines {
        let e = path.iter().find(|e| e.line == line).unwrap();
        assert_eq!(e.kind, ElementKind::Line);
        assert!(
            close(e.start_mm, a) && close(e.end_mm, b),
            "line {line}: {e:?}"
        );
    }
    for (line, c, a, b) in want_arcs {
        let e = path.iter().find(|e| e.line == line).unwrap();
        let g = e.arc().expect("arc");
        assert!(close(g.center_mm, c), "line {line}: {e:?}");
        assert!((g.start_radius_mm - 3.0).abs() < 1e-9 && (g.end_radius_mm - 3.0).abs() < 1e-9);
        assert!(
            (g.sweep_rad - TAU / 4.0).abs() < 1e-9,
            "line {line}: a quarter"
        );
        assert!(
            close(e.start_mm, a) && close(e.end_mm, b),
            "line {line}: {e:?}"
        );
    }
    // The retract after the cancel, from the programmed exit point.
    let last = path.last().unwrap();
    assert_eq!(last.line, 17);
    assert!(close(last.start_mm, p(30.0, -10.0)));
    assert!(close(last.end_mm, Vector3::new(30.0, -10.0, 5.0)));
}

#[test]
fn whole_programs_too() {
    // The same square through Program: the items compensated, notes and end kept.
    let text = square("G41", true);
    let program = parse_program_with(&text, FILE, setup()).unwrap();
    let done: Program = compensate_program(&program, CompOptions::default()).unwrap();
    assert_eq!(done.end, program.end);
    assert_eq!(done.notes, program.notes);
    assert_eq!(done.start_mm, program.start_mm);
    let streamed = compensate(&text).unwrap();
    let streamed: Vec<Item> = streamed
        .into_iter()
        .filter(|i| !matches!(i, Item::Note(_) | Item::End(_)))
        .collect();
    assert_eq!(done.items, streamed);
}

/// The signed distance of `p` left of the line through `a` along unit `t`.
fn left_distance(p: Vector2<f64>, a: Vector2<f64>, t: Vector2<f64>) -> f64 {
    t.x * (p.y - a.y) - t.y * (p.x - a.x)
}

fn xy(v: &Vector3<f64>) -> Vector2<f64> {
    Vector2::new(v.x, v.y)
}

/// A convex polygon: `n` vertices on a circle, at increasing angles, counter-clockwise.
fn polygon(n: usize, radius: f64, center: (f64, f64), gaps: &[f64]) -> Vec<(f64, f64)> {
    let total: f64 = gaps.iter().take(n).sum();
    let mut angle = 0.0f64;
    (0..n)
        .map(|i| {
            let p = (
                center.0 + radius * angle.cos(),
                center.1 + radius * angle.sin(),
            );
            angle += TAU * gaps[i] / total;
            p
        })
        .collect()
}

/// Traverses the polygon with `code` (G41.1/G42.1 with the diameter), entering along the first
/// side's line, going once round and along the first side again, leaving along its line.
fn polygon_program(vertices: &[(f64, f64)], code: &str, diameter: f64) -> String {
    let (x0, y0) = vertices[0];
    let (x1, y1) = vertices[1];
    let len = (x1 - x0).hypot(y1 - y0);
    let (tx, ty) = ((x1 - x0) / len, (y1 - y0) / len);
    let mut text = format!(
        "G0 X{} Y{}\n{code} D{diameter}\nG1 X{x0} Y{y0} F600\n",
        x0 - 10.0 * tx,
        y0 - 10.0 * ty
    );
    for &(x, y) in vertices[1..]
        .iter()
        .chain([vertices[0], vertices[1]].iter())
    {
        text.push_str(&format!("X{x} Y{y}\n"));
    }
    text.push_str(&format!("G40 X{} Y{}\n", x1 + 10.0 * tx, y1 + 10.0 * ty));
    text
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    /// Random convex polygons, either direction, either side: every offset side lies exactly
    /// one radius from its programmed side on the tool's side, consecutive offsets meet where
    /// the hand formula puts the corner, the output is continuous and finite.
    #[test]
    fn convex_polygons(
        n in 3usize..10,
        gaps in proptest::collection::vec(0.3f64..1.0, 10),
        radius in 10.0f64..80.0,
        cx in -50.0f64..50.0,
        cy in -50.0f64..50.0,
        tool_r in 0.25f64..4.0,
        clockwise in any::<bool>(),
        left in any::<bool>(),
        arcs in any::<bool>(),
    ) {
        let mut vertices = polygon(n, radius, (cx, cy), &gaps);
        if clockwise {
            vertices.reverse();
        }
        let code = if left { "G41.1" } else { "G42.1" };
        let text = polygon_program(&vertices, code, 2.0 * tool_r);
        // The programmed sides as the interpreter reads them (after the positioning G0 and the
        // start-up: n sides plus the first again, then the cancel).
        let prog = programmed(&text);
        prop_assert_eq!(prog.len(), n + 4);
        let sides = &prog[2..prog.len() - 1];
        let r = prog[2].comp;
        let d = match r {
            CompState::Left { radius_mm, .. } => radius_mm,
            CompState::Right { radius_mm, .. } => -radius_mm,
            CompState::Off => unreachable!(),
        };
        let dir = |e: &Element| (xy(&e.end_mm) - xy(&e.start_mm)).normalize();
        // Inside (tool toward the polygon's interior): skip the rare polygon whose short side
        // cannot hold both corners (a gouge, tested elsewhere).
        let inside = left != clockwise;
        if inside {
            for k in 0..sides.len() {
                let len = (xy(&sides[k].end_mm) - xy(&sides[k].start_mm)).norm();
                let take = |a: &Element, b: &Element| {
                    let (ta, tb) = (dir(a), dir(b));
                    let turn = (ta.x * tb.y - ta.y * tb.x).atan2(ta.dot(&tb)).abs();
                    tool_r * (turn / 2.0).tan()
                };
                let before = if k == 0 { 0.0 } else { take(&sides[k - 1], &sides[k]) };
                let after = if k + 1 == sides.len() { 0.0 } else { take(&sides[k], &sides[k + 1]) };
                prop_assume!(len > before + after + 1e-6);
            }
        }
        let options = CompOptions {
            outside_corners: if arcs { OutsideCorners::Arc } else { OutsideCorners::Lines },
        };
        let out = compensate_with(&text, options).unwrap_or_else(|e| panic!("{e}\n{text}"));
        let out = motions(&out);
        // Every output element of a side's line: its offset (parallel, at d) or a connector
        // of the corner where it begins (no nearer the corner than the radius).
        for (k, side) in sides.iter().enumerate() {
            let t = dir(side);
            let a = xy(&side.start_mm);
            let of_side: Vec<&Element> = out.iter().filter(|e| e.line == side.line).collect();
            let parallel: Vec<&&Element> = of_side
                .iter()
                .filter(|e| {
                    e.kind == ElementKind::Line
                        && (xy(&e.end_mm) - xy(&e.start_mm)).normalize().dot(&t) > 1.0 - 1e-9
                })
                .collect();
            prop_assert_eq!(parallel.len(), 1, "side {} of\n{}\n{:#?}", k, text, of_side);
            let off = parallel[0];
            for p in [xy(&off.start_mm), xy(&off.end_mm)] {
                prop_assert!((left_distance(p, a, t) - d).abs() < 1e-9);
            }
            for conn in of_side.iter().filter(|e| !std::ptr::eq(**e, *parallel[0])) {
                for p in [xy(&conn.start_mm), xy(&conn.end_mm)] {
                    prop_assert!((p - a).norm() >= tool_r - 1e-9);
                }
                if let Some(g) = conn.arc() {
                    prop_assert!(arcs && !inside);
                    prop_assert!((g.start_radius_mm - tool_r).abs() < 1e-9);
                    prop_assert!((xy(&g.center_mm) - a).norm() < 1e-9);
                }
            }
            // Where the previous side's offset meets this one (no connector between): the
            // offset lines' intersection, vertex + d (n1 + n2) / (1 + t1·t2).
            if k > 0 && of_side.len() == 1 {
                let t1 = dir(&sides[k - 1]);
                let n1 = Vector2::new(-t1.y, t1.x);
                let n2 = Vector2::new(-t.y, t.x);
                let want = a + (n1 + n2) * (d / (1.0 + t1.dot(&t)));
                prop_assert!((xy(&off.start_mm) - want).norm() < 1e-9);
            }
        }
    }
}

/// The `--path` records of `canmotion plan` on `tests/programs/<program>`: (line, rapid, start,
/// end, arc centre and clockwise flag).
type Record = (u64, bool, [f64; 3], [f64; 3], Option<([f64; 3], bool)>);

fn plan_path(program: &str, machine: Option<&Path>) -> Vec<Record> {
    let dir = tempfile::tempdir().unwrap();
    let program = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/programs")
        .join(program);
    let path = dir.path().join("path.jsonl");
    let mut cmd = std::process::Command::new(env!("CARGO_BIN_EXE_canmotion"));
    cmd.arg("plan").arg(&program).arg("--path").arg(&path);
    if let Some(m) = machine {
        cmd.arg("--machine").arg(m);
    }
    let out = cmd.output().unwrap();
    assert!(
        out.status.success(),
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    let point = |v: &serde_json::Value| -> [f64; 3] {
        let a = v.as_array().unwrap();
        [0, 1, 2].map(|i| a[i].as_f64().unwrap())
    };
    std::fs::read_to_string(&path)
        .unwrap()
        .lines()
        .map(|l| {
            let v: serde_json::Value = serde_json::from_str(l).unwrap();
            let arc = (v["kind"] == "arc").then(|| (point(&v["center"]), v["cw"] == true));
            (
                v["line"].as_u64().unwrap(),
                v["rapid"].as_bool().unwrap(),
                point(&v["start"]),
                point(&v["end"]),
                arc,
            )
        })
        .collect()
}

/// A machine file like the demo's with `outside_corners = "lines"` (the source's C-type
/// corners; the demo's default is LinuxCNC's arcs).
fn lines_corner_machine(dir: &Path) -> std::path::PathBuf {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("dictionaries");
    let demo = std::fs::read_to_string(root.join("machines/demo-xyz.toml")).unwrap();
    let text = demo
        .replace("[program]", "[program]\noutside_corners = \"lines\"")
        .replace("../", &format!("{}/", root.display()));
    let file = dir.join("machine.toml");
    std::fs::write(&file, text).unwrap();
    file
}

/// An expected element: line, end point, and for an arc its centre and direction (cw).
type Want = (u64, [f64; 2], Option<([f64; 2], bool)>);

/// Compares the path (z = 0 throughout) element by element with `want`, to 0.001 mm; the
/// first element is the positioning rapid from the machine's start (0, 0, 0).
#[track_caller]
fn check_path(path: &[Record], want: &[Want]) {
    let near = |a: [f64; 3], b: [f64; 2]| {
        (a[0] - b[0]).abs() <= 0.001 && (a[1] - b[1]).abs() <= 0.001 && a[2].abs() <= 0.001
    };
    assert_eq!(path.len(), want.len(), "{path:#?}");
    let mut at = [0.0; 3];
    for (i, (got, want)) in path.iter().zip(want).enumerate() {
        let (line, _, start, end, arc) = *got;
        assert_eq!(start, at, "element {i} starts where the last ended");
        at = end;
        let (want_line, want_end, want_arc) = *want;
        let arc_ok = match (arc, want_arc) {
            (None, None) => true,
            (Some((c, cw)), Some((wc, wcw))) => near(c, wc) && cw == wcw,
            _ => false,
        };
        assert!(
            line == want_line && near(end, want_end) && arc_ok,
            "element {i}: got line {line} to {end:?} arc {arc:?}, want line {want_line} to \
             {want_end:?} arc {want_arc:?}"
        );
    }
}

/// LinuxCNC's entry arc (`convert_arc_comp1`): it starts at the current, uncompensated point;
/// its end is the programmed end moved one tool radius along the arc's radius (outward when the
/// tool is outside the arc, inward when inside); its centre lies on that radius, as far from
/// the end as from the start.
///
/// Run 1 (lines 3–7): G41.1 D-4 is G42 with radius 2 (LinuxCNC swaps the side of a negative
/// diameter). The G3 about (100,100) from (100,90) to (110,100) has the tool outside: end
/// (112,100). Centre (112 − t, 100) with t² = (12 − t)² + 10² (distance to the start
/// (100,90)): t = 244/24 = 61/6, centre (100 + 11/6, 100). The line up from (110,100) is
/// tangent to the arc: its offset x = 112 starts where the arc ends. The exit (G40, straight
/// on up) ends the last element at its offset end (112,110), then runs to (110,120), as in
/// LinuxCNC (its G40 leaves the last move at its offset end point).
///
/// Run 2 (lines 8–12): G41 radius 2, the same arc 50 mm lower with the tool inside: end
/// (108,50), centre (108 − t, 50) with t² = (8 − t)² + 10²: t = 164/16 = 10.25, centre
/// (97.75, 50). The turn into −X (line 11) is inside: the arc ends where its circle meets the
/// line's offset y = 48, nearest the corner: x = 97.75 + √(10.25² − 2²) = 97.75 + √101.0625
/// (LinuxCNC's arc-to-line case takes the same root). Exit straight on: (90,48) to (80,50).
#[test]
fn an_arc_starts_compensation_as_in_linuxcnc() {
    let x = 97.75 + 101.0625f64.sqrt();
    let path = plan_path("comp_arc_entry.ngc", None);
    check_path(
        &path,
        &[
            (3, [100.0, 90.0], None),
            (
                5,
                [112.0, 100.0],
                Some(([100.0 + 11.0 / 6.0, 100.0], false)),
            ),
            (6, [112.0, 110.0], None),
            (7, [110.0, 120.0], None),
            (8, [100.0, 40.0], None),
            (10, [x, 48.0], Some(([97.75, 50.0], false))),
            (11, [90.0, 48.0], None),
            (12, [80.0, 50.0], None),
        ],
    );
    // The entry arcs keep their radius: start and end on one circle.
    for (k, r) in [(1, 61.0 / 6.0), (5, 10.25)] {
        let (_, _, s, e, arc) = path[k];
        let (c, _) = arc.unwrap();
        for p in [s, e] {
            assert!(
                ((p[0] - c[0]).hypot(p[1] - c[1]) - r).abs() < 1e-9,
                "{:?}",
                path[k]
            );
        }
    }
}

/// An outside corner after an entry arc (G42, radius 2): the entry arc as in run 1 above ends
/// at (112,100) heading +Y; the line into −X turns left, away from the tool. With the default
/// `outside_corners = "arc"` (LinuxCNC's) the corner is a counter-clockwise arc of radius 2
/// about the programmed corner (110,100) from (112,100) to the line's offset start (110,102);
/// with `outside_corners = "lines"` (C-type, α = 90°) both offsets are extended by 2·tan 45° = 2
/// to meet at (112,102).
#[test]
fn an_outside_corner_after_an_entry_arc() {
    let entry = (
        5,
        [112.0, 100.0],
        Some(([100.0 + 11.0 / 6.0, 100.0], false)),
    );
    let dir = tempfile::tempdir().unwrap();
    let machine = lines_corner_machine(dir.path());
    check_path(
        &plan_path("comp_arc_entry_corner.ngc", None),
        &[
            (3, [100.0, 90.0], None),
            entry,
            (6, [110.0, 102.0], Some(([110.0, 100.0], false))),
            (6, [90.0, 102.0], None),
            (7, [80.0, 100.0], None),
        ],
    );
    check_path(
        &plan_path("comp_arc_entry_corner.ngc", Some(&machine)),
        &[
            (3, [100.0, 90.0], None),
            entry,
            (6, [112.0, 102.0], None),
            (6, [90.0, 102.0], None),
            (7, [80.0, 100.0], None),
        ],
    );
}

/// The path's geometry alone (the comp state of the elements differs between G41 and G42).
fn shapes(path: &[Element]) -> Vec<(ElementKind, Vector3<f64>, Vector3<f64>)> {
    path.iter()
        .map(|e| (e.kind, e.start_mm, e.end_mm))
        .collect()
}

#[test]
fn d_words_mean_what_they_mean_in_linuxcnc() {
    let program = |head: &str| {
        format!("G0 X-10 Y0\n{head}\nG1 X0 Y0 F600\nX10\nG3 X20 Y10 I0 J10\nG1 Y20\nG40 X0\n")
    };
    let g42 = comp_path(&program("G42.1 D4"), CompOptions::default());
    assert_eq!(g42.len(), 5, "{g42:#?}");
    // A negative G41.1 diameter is G42 with its magnitude (LinuxCNC swaps the side of a
    // negative radius), and the other way round.
    let swapped = comp_path(&program("G41.1 D-4"), CompOptions::default());
    assert_eq!(shapes(&swapped), shapes(&g42));
    let g41 = comp_path(&program("G41.1 D4"), CompOptions::default());
    let swapped = comp_path(&program("G42.1 D-4"), CompOptions::default());
    assert_eq!(shapes(&swapped), shapes(&g41));
    assert_ne!(shapes(&g41), shapes(&g42));

    // G41/G42 D is a tool number: LinuxCNC takes it to within 0.0001 of a whole number, and
    // refuses a negative one.
    let d1 = comp_path(&program("G41 D1"), CompOptions::default());
    assert_eq!(shapes(&d1), shapes(&g41));
    let near = comp_path(&program("G41 D1.00001"), CompOptions::default());
    assert_eq!(shapes(&near), shapes(&d1));
    let e = compensate(&program("G41 D-1")).unwrap_err();
    assert_eq!((e.line, e.col), (2, 5));
    assert!(matches!(e.kind, ErrorKind::InvalidValue { .. }), "{e}");
    let e = compensate(&program("G42 D1.5")).unwrap_err();
    assert_eq!((e.line, e.col), (2, 5));

    // A negative radius in the tool table swaps the side too (LinuxCNC's negative diameter).
    let mut s = setup();
    s.tools.insert(
        7,
        Tool {
            radius_mm: -2.0,
            length_mm: 0.0,
        },
    );
    let text = program("G41 D7");
    let interp = Interpreter::new(text.as_bytes(), FILE, s);
    let items: Vec<Item> = Compensator::new(interp, FILE, CompOptions::default())
        .collect::<Result<_, _>>()
        .unwrap();
    let d7: Vec<Element> = motions(&items)
        .into_iter()
        .skip_while(|e| e.comp == CompState::Off)
        .collect();
    assert_eq!(shapes(&d7), shapes(&g42));

    // D0 is the tool in the spindle (LinuxCNC's pocket 0), not "no tool".
    let mut s = setup();
    s.loaded_tool = 1;
    let text = program("G41 D0");
    let interp = Interpreter::new(text.as_bytes(), FILE, s);
    let items: Vec<Item> = Compensator::new(interp, FILE, CompOptions::default())
        .collect::<Result<_, _>>()
        .unwrap();
    let d0: Vec<Element> = motions(&items)
        .into_iter()
        .skip_while(|e| e.comp == CompState::Off)
        .collect();
    assert_eq!(shapes(&d0), shapes(&d1));
}

#[test]
fn g41_1_l_is_a_lathe_orientation_in_g18_only() {
    let program = |plane: &str, l: &str| {
        format!("{plane}\nG0 X-10 Y0 Z0\nG41.1 D4 {l}\nG1 X0 Y0 Z0 F600\nG40 X10\n")
    };
    // LinuxCNC: "G41.1 with L word, but plane is not G18".
    let e = compensate(&program("G17", "L2")).unwrap_err();
    assert_eq!((e.line, e.col), (3, 10));
    assert!(matches!(e.kind, ErrorKind::InvalidValue { .. }), "{e}");
    // Orientations 1–8 move the controlled point off the nose centre: not supported.
    let e = compensate(&program("G18", "L3")).unwrap_err();
    assert_eq!((e.line, e.col), (3, 10));
    assert!(matches!(e.kind, ErrorKind::Unsupported { .. }), "{e}");
    // 0 and 9 leave it at the nose centre: the same path as without L.
    let plain = compensate(&program("G18", "")).unwrap();
    for l in ["L0", "L9"] {
        assert_eq!(compensate(&program("G18", l)).unwrap(), plain);
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    /// Random entry arcs, either direction, either side: the tool-centre arc starts at the
    /// current point, ends one radius from the programmed end along the arc's radius (inward
    /// when the tool is inside the arc), turns the programmed way, and its centre lies on that
    /// radius as far from both ends: A + w·t with w the unit vector from the new end A toward
    /// the programmed centre and t = |S − A|² / (2 w·(S − A)) (from |A + w t − S| = |t|).
    /// Entries LinuxCNC refuses are errors of their kinds.
    #[test]
    fn entry_arcs(
        cx in -20.0f64..20.0,
        cy in -20.0f64..20.0,
        big_r in 3.0f64..40.0,
        a0 in 0.0f64..TAU,
        sweep in 0.2f64..(TAU - 0.2),
        ccw in any::<bool>(),
        left in any::<bool>(),
        tool_r in 0.25f64..2.5,
    ) {
        let s = if ccw { 1.0 } else { -1.0 };
        let a1 = a0 + s * sweep;
        let start = Vector2::new(cx + big_r * a0.cos(), cy + big_r * a0.sin());
        let end = Vector2::new(cx + big_r * a1.cos(), cy + big_r * a1.sin());
        let code = if left { "G41.1" } else { "G42.1" };
        let arc = if ccw { "G3" } else { "G2" };
        let text = format!(
            "G90.1\nG0 X{} Y{}\n{code} D{}\n{arc} X{} Y{} I{cx} J{cy} F600\n",
            start.x, start.y, 2.0 * tool_r, end.x, end.y
        );
        // The arc as the interpreter reads it (printed coordinates are rounded).
        let prog = programmed(&text);
        let p = prog[1];
        let (s0, e0) = (xy(&p.start_mm), xy(&p.end_mm));
        let center = xy(&p.arc().unwrap().center_mm);
        let r0 = (s0 - center).norm();
        let u1 = (e0 - center).normalize();
        let inside = left == ccw;
        let to = e0 + if inside { -u1 } else { u1 } * tool_r;
        let w = (center - to).normalize();
        let denom = 2.0 * w.dot(&(s0 - to));
        let result = compensate(&text);
        let chord = (e0 - s0).norm();
        let cos_a = w.dot(&(s0 - to).normalize());
        // Away from LinuxCNC's refusal thresholds, the path; on the refused side, the errors.
        if chord <= tool_r - 1e-6 {
            let e = result.unwrap_err();
            prop_assert!(matches!(e.kind, ErrorKind::CompensationEntryArcTooShort { .. }), "{}", e);
        } else if inside && r0 <= tool_r - 1e-6 {
            let e = result.unwrap_err();
            prop_assert!(matches!(e.kind, ErrorKind::CompensationArcTooSmall { .. }), "{}", e);
        } else if chord > tool_r + 1e-6
            && !(inside && r0 <= tool_r + 1e-6)
            && cos_a.abs() > 1e-3
        {
            let out = motions(&result.unwrap_or_else(|e| panic!("{e}\n{text}")));
            prop_assert_eq!(out.len(), 2);
            let e = out[1];
            let ElementKind::Arc { center_mm, cw, turns, .. } = e.kind else {
                panic!("not an arc: {e:?}");
            };
            prop_assert_eq!(cw, !ccw);
            prop_assert_eq!(turns, 0);
            let t = (s0 - to).norm_squared() / denom;
            let want_center = to + w * t;
            let tol = 1e-6 * (1.0 + t.abs());
            prop_assert!((xy(&center_mm) - want_center).norm() < tol, "{} vs {}\n{}", center_mm, want_center, text);
            prop_assert!((xy(&e.start_mm) - s0).norm() < 1e-9);
            prop_assert!((xy(&e.end_mm) - to).norm() < 1e-9);
            let g = e.arc().unwrap();
            prop_assert!((g.start_radius_mm - g.end_radius_mm).abs() < tol);
        }
    }
}

/// Like [`check_path`], in three dimensions: (line, end, arc centre and clockwise flag).
type Want3 = (u64, [f64; 3], Option<([f64; 3], bool)>);

#[track_caller]
fn check_path_xyz(path: &[Record], want: &[Want3]) {
    let near = |a: [f64; 3], b: [f64; 3]| (0..3).all(|i| (a[i] - b[i]).abs() <= 0.001);
    assert_eq!(path.len(), want.len(), "{path:#?}");
    let mut at = [0.0; 3];
    for (i, (got, want)) in path.iter().zip(want).enumerate() {
        let (line, _, start, end, arc) = *got;
        assert_eq!(start, at, "element {i} starts where the last ended");
        at = end;
        let (want_line, want_end, want_arc) = *want;
        let arc_ok = match (arc, want_arc) {
            (None, None) => true,
            (Some((c, cw)), Some((wc, wcw))) => near(c, wc) && cw == wcw,
            _ => false,
        };
        assert!(
            line == want_line && near(end, want_end) && arc_ok,
            "element {i}: got line {line} to {end:?} arc {arc:?}, want line {want_line} to \
             {want_end:?} arc {want_arc:?}"
        );
    }
}

/// A straight entry into an acute inside corner (G41, radius 2), as LinuxCNC computes it, and
/// a G40 exit move not in line with the last move.
///
/// Entry, line 5 (`convert_straight_comp1`): from the current point C = (7,0) to the
/// programmed end P1 = (10,0), 3 mm > r; α = atan2(P1 − C) + π/2 = π/2, so the tool is sent
/// to P1 + r (cos α, sin α) = (10,2).
///
/// Line 6 (`convert_straight_comp2`), from (10,0) to (0,10): θ = atan2((10,2) − (10,0)) =
/// π/2, α = atan2(10, −10) = 3π/4; for LEFT θ < α so θ = 5π/2, β = θ − α − π/2 = 5π/4 >
/// π + 0.01: concave. Line to line: the half corner (β + π)/2 = 9π/8, the retreat
/// r / tan(9π/8) = 2 / tan(π/8) = 4.828427 along θ + π/2 = 3π (−X) from (10,2): the entry's
/// end is moved to (5.171573, 2) (`move_endpoint_and_flush`; its direction check compares
/// with the entry's normal, so running back past C is not a gouge there). The line ends at
/// (0,10) + r (cos 5π/4, sin 5π/4) = (−1.414214, 8.585786).
///
/// Line 7, G40 (`convert_cutter_compensation_off`): the last move keeps its end, the
/// interpreter's point becomes the programmed (0,10), and the G1 runs straight from the tool
/// at (−1.414214, 8.585786) to (0,20). No outside corner: the same with either corner mode.
/// The old code refused the entry as a gouge and joined the exit at the corner.
#[test]
fn a_straight_entry_into_an_acute_inside_corner_as_in_linuxcnc() {
    let retreat = 2.0 / (std::f64::consts::PI / 8.0).tan();
    let h = std::f64::consts::SQRT_2;
    let want: [Want; 4] = [
        (3, [7.0, 0.0], None),
        (5, [10.0 - retreat, 2.0], None),
        (6, [-h, 10.0 - h], None),
        (7, [0.0, 20.0], None),
    ];
    check_path(&plan_path("comp_entry_acute.ngc", None), &want);
    let dir = tempfile::tempdir().unwrap();
    let machine = lines_corner_machine(dir.path());
    check_path(&plan_path("comp_entry_acute.ngc", Some(&machine)), &want);
}

/// A straight entry onto an outside corner of 135° (G41, radius 2), and a G40 exit move not
/// in line.
///
/// Entry, line 5 (`convert_straight_comp1`): C = (10,20), P1 = (20,20), α = 0 + π/2: the
/// tool goes to (20,22).
///
/// Line 6 (`convert_straight_comp2`), from (20,20) to (30,10): θ = π/2, α = −π/4, β = θ − α −
/// π/2 = π/4 > 0.01 and below π − 0.01: convex, an arc is needed. The entry keeps its end
/// (20,22); `ARC_FEED` clockwise (turn −1 for LEFT) about the programmed corner (20,20) to
/// (20,20) + r (cos π/4, sin π/4) = (21.414214, 21.414214); then the line to (30,10) + the
/// same = (31.414214, 11.414214).
///
/// Line 7, G40: the last move keeps its end; the G1 runs to (40,10). The old code joined the
/// exit to the last move as an inside corner (ending the last move short of its end).
///
/// With `outside_corners = "lines"` the corner is the C-type extension instead (not
/// LinuxCNC's, a machine file's choice; the default is LinuxCNC's arc): both offsets run on to their intersection, y = 22
/// with the line through (21.414214, 21.414214) along (1,−1): x = 20 + 2√2 − 2 = 20.828427.
#[test]
fn a_straight_entry_onto_an_outside_corner_as_in_linuxcnc() {
    let h = std::f64::consts::SQRT_2;
    let dir = tempfile::tempdir().unwrap();
    let machine = lines_corner_machine(dir.path());
    check_path(
        &plan_path("comp_entry_obtuse.ngc", None),
        &[
            (3, [10.0, 20.0], None),
            (5, [20.0, 22.0], None),
            (6, [20.0 + h, 20.0 + h], Some(([20.0, 20.0], true))),
            (6, [30.0 + h, 10.0 + h], None),
            (7, [40.0, 10.0], None),
        ],
    );
    check_path(
        &plan_path("comp_entry_obtuse.ngc", Some(&machine)),
        &[
            (3, [10.0, 20.0], None),
            (5, [18.0 + 2.0 * h, 22.0], None),
            (6, [30.0 + h, 10.0 + h], None),
            (7, [40.0, 10.0], None),
        ],
    );
}

/// G40 and then a move along the tool axis: that move is the exit, as in LinuxCNC (its G40
/// ends the last move at its offset end (30,2) and puts the interpreter's point back on the
/// programmed (30,0); the next move, whatever it is, runs from the tool to its programmed end).
/// So the G0 Z5 of line 8 runs from (30,2,0) to (30,0,5); the rest is uncompensated, and the
/// arc of line 11 is allowed (the straight moves before it cleared LinuxCNC's
/// `arc_not_allowed`): clockwise about (45,5,0). The old code kept the axial move at the offset
/// point and refused the arc as unsupported.
#[test]
fn after_g40_a_move_along_the_tool_axis_is_the_exit_move() {
    check_path_xyz(
        &plan_path("comp_cancel_axial.ngc", None),
        &[
            (3, [10.0, 0.0, 0.0], None),
            (5, [20.0, 2.0, 0.0], None),
            (6, [30.0, 2.0, 0.0], None),
            (8, [30.0, 0.0, 5.0], None),
            (9, [40.0, 5.0, 5.0], None),
            (10, [40.0, 5.0, 0.0], None),
            (11, [50.0, 5.0, 0.0], Some(([45.0, 5.0, 0.0], true))),
        ],
    );
}

/// The compensated items of `tests/programs/<program>`, or the first error.
fn compensate_file(program: &str) -> Result<Vec<Item>, Error> {
    let text = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/programs")
            .join(program),
    )
    .unwrap();
    let interp = Interpreter::new(text.as_bytes(), program, setup());
    Compensator::new(interp, program, CompOptions::default()).collect()
}

/// What LinuxCNC refuses around straight entries and G40:
/// - G41, G40 with no move between, then an arc: its G40 sets `arc_not_allowed` whenever a
///   radius is in force ("The move just after exiting cutter compensation mode must be
///   straight, not an arc"); the old code ran the arc uncompensated;
/// - a straight entry not longer than the tool radius (`convert_straight_comp1`: "Length of
///   cutter compensation entry move is not greater than the tool radius"): 1.5 mm with radius
///   2; the old code accepted it.
#[test]
fn linuxcnc_refuses_an_arc_after_g40_and_a_short_straight_entry() {
    let e = compensate_file("comp_g40_arc.ngc").unwrap_err();
    assert_eq!((e.line, e.col), (6, 1), "{e}");
    assert!(
        matches!(e.kind, ErrorKind::CompensationEndOnArc { code: "G2" }),
        "{e}"
    );
    let e = compensate_file("comp_entry_short.ngc").unwrap_err();
    assert_eq!((e.line, e.col), (5, 1), "{e}");
    assert!(
        matches!(
            e.kind,
            ErrorKind::CompensationEntryTooShort { code: "G1", length_mm, tool_radius_mm }
                if length_mm == 1.5 && tool_radius_mm == 2.0
        ),
        "{e}"
    );
}
