//! Golden tests of the G-code front end: small programs → the exact item stream, and every
//! unsupported feature or program error → its message with line and column.
//!
//! Items are printed one per line in a fixed format (4 decimals, millimetres, machine
//! coordinates) so an expectation reads like the program's effect:
//! `3 line G1 (0,0,0)->(10,0,0) F20` or `4 arc G2 (..)->(..) c(..) n(0,0,-1) r5 turns0`.

use std::path::Path;

use canmotion::gcode::{
    BlendMode, CompState, Element, ElementKind, Error, Item, Program, ProgramEnd, Setup, ToolTable,
    parse_program_with,
};
use nalgebra::Vector3;

fn num(x: f64) -> String {
    let s = format!("{x:.4}");
    let s = s.trim_end_matches('0').trim_end_matches('.').to_string();
    if s == "-0" { "0".into() } else { s }
}

fn pt(v: &Vector3<f64>) -> String {
    format!("({},{},{})", num(v.x), num(v.y), num(v.z))
}

fn element(e: &Element) -> String {
    let feed = match e.feed_mm_s {
        Some(f) => format!(" F{}", num(f)),
        None => String::new(),
    };
    let blend = match e.blend {
        BlendMode::ExactPath => " G61".to_string(),
        BlendMode::ExactStop => " G61.1".to_string(),
        // The mode a program starts in: LinuxCNC's G64 without P.
        BlendMode::Blend { p_mm, q_mm } if p_mm == f64::INFINITY && q_mm == f64::INFINITY => {
            String::new()
        }
        BlendMode::Blend { p_mm, q_mm } => format!(" G64P{}Q{}", num(p_mm), num(q_mm)),
    };
    let comp = match e.comp {
        CompState::Off => String::new(),
        CompState::Left { tool, radius_mm } => format!(" left{tool:?}r{}", num(radius_mm)),
        CompState::Right { tool, radius_mm } => format!(" right{tool:?}r{}", num(radius_mm)),
    };
    let rapid = if e.rapid { "G0" } else { "G1" };
    match e.kind {
        ElementKind::Line => format!(
            "{} line {rapid} {}->{}{feed}{blend}{comp}",
            e.line,
            pt(&e.start_mm),
            pt(&e.end_mm)
        ),
        ElementKind::Arc {
            center_mm,
            normal,
            cw,
            turns,
            radius_mm,
        } => format!(
            "{} arc {} {}->{} c{} n{} r{} turns{turns}{feed}{blend}{comp}",
            e.line,
            if cw { "G2" } else { "G3" },
            pt(&e.start_mm),
            pt(&e.end_mm),
            pt(&center_mm),
            pt(&normal),
            num(radius_mm)
        ),
    }
}

fn dump_program(p: &Program) -> String {
    let mut out = Vec::new();
    for item in &p.items {
        out.push(match item {
            Item::Motion(e) => element(e),
            Item::Dwell(d) => format!("{} dwell {} s", d.line, num(d.seconds)),
            Item::Stop(s) => format!("{} stop{}", s.line, if s.optional { " M1" } else { " M0" }),
            Item::Note(_) | Item::End(_) => continue,
        });
    }
    out.push(match p.end {
        ProgramEnd::EndOfText => "end of text".to_string(),
        ProgramEnd::M2 { line } => format!("{line} end M2"),
        ProgramEnd::M30 { line } => format!("{line} end M30"),
        ProgramEnd::Percent { line } => format!("{line} end %"),
        ProgramEnd::M99 { line } => format!("{line} end M99"),
    });
    out.join("\n")
}

fn run_with(text: &str, setup: Setup) -> Result<Program, Error> {
    parse_program_with(text, "t.ngc", setup)
}

fn setup() -> Setup {
    Setup::new(Vector3::zeros())
}

fn demo_tools() -> ToolTable {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("dictionaries/tools/demo-tools.toml");
    ToolTable::load(&path).expect("demo tool table loads")
}

#[track_caller]
fn golden_with(text: &str, setup: Setup, expected: &str) {
    let p = run_with(text, setup).unwrap_or_else(|e| panic!("{e}"));
    let got = dump_program(&p);
    let expected = expected
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty())
        .collect::<Vec<_>>()
        .join("\n");
    assert_eq!(
        got, expected,
        "\n--- got:\n{got}\n--- expected:\n{expected}\n"
    );
}

#[track_caller]
fn golden(text: &str, expected: &str) {
    golden_with(text, setup(), expected);
}

#[test]
fn lines_modes_and_units() {
    golden(
        "%\n\
         (header)\n\
         N10 G21 G90 G17 G94 G61.1 ; setup\n\
         n20 g0 x10 y20 z5\n\
         N30 G1 X15 F600\n\
         Y25 (modal G1)\n\
         G91 X1 Y-1\n\
         G20 G90 X1 Y2 Z0.5 F10\n\
         G91G0Z.1\n\
         G1 X0 Y0 Z0 (zero length: no element)\n\
         M30\n\
         G2 X1 never read !\n\
         %\n",
        "4 line G0 (0,0,0)->(10,20,5) G61.1
         5 line G1 (10,20,5)->(15,20,5) F10 G61.1
         6 line G1 (15,20,5)->(15,25,5) F10 G61.1
         7 line G1 (15,25,5)->(16,24,5) F10 G61.1
         8 line G1 (16,24,5)->(25.4,50.8,12.7) F4.2333 G61.1
         9 line G0 (25.4,50.8,12.7)->(25.4,50.8,15.24) G61.1
         11 end M30",
    );
}

#[test]
fn arcs_ijk_and_r() {
    golden(
        "G21 G17 G90 F600\n\
         G2 X10 Y0 I5 J0\n\
         G3 X0 Y0 I-5\n\
         G0 X0 Y0\n\
         G2 X10 Y10 R10\n\
         G0 X0 Y0\n\
         G2 X10 Y10 R-10\n",
        "2 arc G2 (0,0,0)->(10,0,0) c(5,0,0) n(0,0,-1) r5 turns0 F10
         3 arc G3 (10,0,0)->(0,0,0) c(5,0,0) n(0,0,1) r5 turns0 F10
         5 arc G2 (0,0,0)->(10,10,0) c(10,0,0) n(0,0,-1) r10 turns0 F10
         6 line G0 (10,10,0)->(0,0,0)
         7 arc G2 (0,0,0)->(10,10,0) c(0,10,0) n(0,0,-1) r10 turns0 F10
         end of text",
    );
}

#[test]
fn arc_lengths_full_circles_and_helices() {
    let p = run_with(
        "G21 F600\nG2 X0 Y0 I5\nG3 J-1\nG3 X0 Y0 Z-6 I5 P3\n",
        setup(),
    )
    .unwrap();
    let e: Vec<&Element> = p.elements().collect();
    assert_eq!(e.len(), 3);
    // A full circle with I/J and the end equal to the start.
    assert!((e[0].length_mm() - 10.0 * std::f64::consts::PI).abs() < 1e-9);
    // No plane axis word: a full circle too (LinuxCNC), here about (0,-1).
    assert!((e[1].length_mm() - 2.0 * std::f64::consts::PI).abs() < 1e-9);
    // A helix of three turns dropping 6 mm.
    let helix = e[2].arc().unwrap();
    assert_eq!(helix.helix_mm, -6.0);
    assert!((helix.sweep_rad - 6.0 * std::f64::consts::PI).abs() < 1e-9);
    assert!((e[2].length_mm() - (30.0 * std::f64::consts::PI).hypot(6.0)).abs() < 1e-9);
    golden(
        "G21 F600\nG2 X0 Y0 I5\nG3 X0 Y0 Z-6 I5 P3\n",
        "2 arc G2 (0,0,0)->(0,0,0) c(5,0,0) n(0,0,-1) r5 turns0 F10
         3 arc G3 (0,0,0)->(0,0,-6) c(5,0,0) n(0,0,1) r5 turns2 F10
         end of text",
    );
}

#[test]
fn planes_g18_g19_and_centre_modes() {
    golden(
        "G21 F60\n\
         G18 G2 X10 Z0 I5 K0\n\
         G19 G3 Y10 Z0 J5 K0\n\
         G17 G90.1 G0 X0 Y0 Z0\n\
         G2 X20 Y0 I10 J0\n\
         G91.1 G2 X0 Y0 I-10 J0\n",
        "2 arc G2 (0,0,0)->(10,0,0) c(5,0,0) n(0,-1,0) r5 turns0 F1
         3 arc G3 (10,0,0)->(10,10,0) c(10,5,0) n(1,0,0) r5 turns0 F1
         4 line G0 (10,10,0)->(0,0,0)
         5 arc G2 (0,0,0)->(20,0,0) c(10,0,0) n(0,0,-1) r10 turns0 F1
         6 arc G2 (20,0,0)->(0,0,0) c(10,0,0) n(0,0,-1) r10 turns0 F1
         end of text",
    );
}

#[test]
fn inches() {
    golden(
        "G20 G90 F10\nG0 X1\nG2 X3 Y0 I1 J0\nG21 G1 X0\n",
        "2 line G0 (0,0,0)->(25.4,0,0)
         3 arc G2 (25.4,0,0)->(76.2,0,0) c(50.8,0,0) n(0,0,-1) r25.4 turns0 F4.2333
         4 line G1 (76.2,0,0)->(0,0,0) F4.2333
         end of text",
    );
}

#[test]
fn work_offsets_g92_and_rotation() {
    let mut s = setup();
    s.work_offsets_mm[0] = Vector3::new(100.0, 0.0, -10.0);
    s.work_offsets_mm[1] = Vector3::new(200.0, 50.0, 0.0);
    golden_with(
        "G0 X1 Y1 Z1\n\
         G55 X1\n\
         G54\n\
         G92 X0 Y0\n\
         G0 X5\n\
         G92.2 X5\n\
         G92.3 X5\n\
         G92.1\n\
         G10 L2 P2 X300 Y0\n\
         G55 G0 X0 Y0\n\
         G10 L20 P2 X10\n\
         G0 X10\n\
         G10 L2 P1 X0 Y0 Z0 R90\n\
         G54 G0 X10 Y0\n",
        s,
        // Axes a move leaves alone keep their machine position (G55 X1 keeps Y and Z); G92.2
        // suspends the G92 offset (line 6 moves in plain G54) and G92.3 restores it; G10 L20
        // makes the current point X10 of G55; G54 rotated by 90° maps X10 to machine Y10.
        "1 line G0 (0,0,0)->(101,1,-9)
         2 line G0 (101,1,-9)->(201,1,-9)
         5 line G0 (201,1,-9)->(206,1,-9)
         6 line G0 (206,1,-9)->(105,1,-9)
         7 line G0 (105,1,-9)->(206,1,-9)
         10 line G0 (206,1,-9)->(300,0,-9)
         14 line G0 (300,0,-9)->(0,10,-9)
         end of text",
    );
}

#[test]
fn tool_length_compensation_with_the_demo_table() {
    let mut s = setup();
    s.tools = demo_tools();
    golden_with(
        "G21 G0 Z0\n\
         T1 M6\n\
         G43 H1 Z10\n\
         G0 X5 (Z stays)\n\
         G49 Z10\n\
         G43 Z0 (the tool in the spindle: 1)\n\
         G44 H2 Z0\n\
         G43.1 Z-3\n\
         G0 Z0\n\
         G43.2 H3\n\
         G0 Z0\n\
         G49\n\
         G0 Z0\n",
        s,
        "3 line G0 (0,0,0)->(0,0,60)
         4 line G0 (0,0,60)->(5,0,60)
         5 line G0 (5,0,60)->(5,0,10)
         6 line G0 (5,0,10)->(5,0,50)
         7 line G0 (5,0,50)->(5,0,-62.5)
         9 line G0 (5,0,-62.5)->(5,0,-3)
         11 line G0 (5,0,-3)->(5,0,38.2)
         13 line G0 (5,0,38.2)->(5,0,0)
         end of text",
    );
}

#[test]
fn g28_g30_and_g53() {
    let mut s = setup();
    s.g28_mm = Vector3::new(0.0, 0.0, 100.0);
    s.g30_mm = Vector3::new(-50.0, -50.0, 100.0);
    s.work_offsets_mm[0] = Vector3::new(10.0, 10.0, 10.0);
    golden_with(
        "G0 X1 Y1 Z1\n\
         G28 Z5\n\
         G91 G28 X0\n\
         G90 G28\n\
         G53 G0 X-20 Y-20\n\
         G28.1\n\
         G30 Y0\n\
         G28\n",
        s,
        "1 line G0 (0,0,0)->(11,11,11)
         2 line G0 (11,11,11)->(11,11,15)
         2 line G0 (11,11,15)->(11,11,100)
         3 line G0 (11,11,100)->(0,11,100)
         4 line G0 (0,11,100)->(0,0,100)
         5 line G0 (0,0,100)->(-20,-20,100)
         7 line G0 (-20,-20,100)->(-20,10,100)
         7 line G0 (-20,10,100)->(-20,-50,100)
         8 line G0 (-20,-50,100)->(-20,-20,100)
         end of text",
    );
}

#[test]
fn feed_modes_blending_dwell_stops() {
    golden(
        "G21 G93 G1 X10 F6\n\
         G2 X20 I5 F60\n\
         G94 F120 G64 P0.05 Q0.01\n\
         G1 X0\n\
         G64 P0.1\n\
         G4 P1.5\n\
         G64 P0 X1\n\
         G64 X0\n\
         G61 Y1\n\
         M0\n\
         M1\n\
         M2\n",
        "1 line G1 (0,0,0)->(10,0,0) F1
         2 arc G2 (10,0,0)->(20,0,0) c(15,0,0) n(0,0,-1) r5 turns0 F15.708
         4 line G1 (20,0,0)->(0,0,0) F2 G64P0.05Q0.01
         6 dwell 1.5 s
         7 line G1 (0,0,0)->(1,0,0) F2 G64P0Q0
         8 line G1 (1,0,0)->(0,0,0) F2
         9 line G1 (0,0,0)->(0,1,0) F2 G61
         10 stop M0
         11 stop M1
         12 end M2",
    );
    let mut s = setup();
    s.optional_stop = false;
    let p = run_with("M1\nM2\n", s).unwrap();
    assert!(p.items.is_empty());
    assert!(p.notes[0].text.starts_with("M1: optional stop skipped"));
}

#[test]
fn cutter_compensation_state_and_the_tool_table() {
    let mut s = setup();
    s.tools = demo_tools();
    golden_with(
        "G21 F60\n\
         G41 D1 G1 X10\n\
         G40 G1 X20\n\
         G10 L1 P1 R3.5 Z40\n\
         G42 D1 G1 X30\n\
         G40\n\
         G41.1 D4 G1 X40\n\
         G40\n\
         T2 M6\n\
         G42 G1 X50\n",
        s,
        "2 line G1 (0,0,0)->(10,0,0) F1 leftSome(1)r2
         3 line G1 (10,0,0)->(20,0,0) F1
         5 line G1 (20,0,0)->(30,0,0) F1 rightSome(1)r3.5
         7 line G1 (30,0,0)->(40,0,0) F1 leftNoner2
         10 line G1 (40,0,0)->(50,0,0) F1 rightSome(2)r3
         end of text",
    );
}

#[test]
fn parameters_expressions_and_o_words() {
    golden(
        "G21 F60\n\
         #1 = 2\n\
         #<step> = [#1 * 1.5]\n\
         o100 sub\n\
           G1 X[#1 * 10]\n\
         o100 endsub\n\
         o100 call [1]\n\
         o100 call [#<step>]\n\
         o1 repeat [2]\n\
           G91 Y#1\n\
         o1 endrepeat\n\
         G90\n\
         #2 = 0\n\
         o2 while [#2 LT 2]\n\
           #2 = [#2 + 1]\n\
           o3 if [#2 EQ 1]\n\
             Z1\n\
           o3 else\n\
             Z2\n\
           o3 endif\n\
         o2 endwhile\n\
         o4 do\n\
           X0\n\
           o4 break\n\
         o4 while [1]\n\
         M2\n",
        "5 line G1 (0,0,0)->(10,0,0) F1
         5 line G1 (10,0,0)->(30,0,0) F1
         10 line G1 (30,0,0)->(30,2,0) F1
         10 line G1 (30,2,0)->(30,4,0) F1
         17 line G1 (30,4,0)->(30,4,1) F1
         19 line G1 (30,4,1)->(30,4,2) F1
         23 line G1 (30,4,2)->(0,4,2) F1
         26 end M2",
    );
}

#[test]
fn notes_record_what_has_no_motion_effect() {
    let p = run_with(
        "T1 M6\nS1000 M3 M8\nG98 G97\n(MSG, Insert the part)\nM5 M9\nM2\n",
        setup(),
    )
    .unwrap();
    let notes: Vec<String> = p.notes.iter().map(|n| n.to_string()).collect();
    assert_eq!(
        notes,
        vec![
            "1:1: T1: tool selected (tool changes are out of scope)",
            "1:4: M6: tool 1 is now the tool in the spindle for G43 and G41/G42 (the change itself is out of scope)",
            "2:1: S1000: spindle speed recorded (spindle control is out of scope)",
            "2:7: M3: spindle control is out of scope",
            "2:10: M8: coolant control is out of scope",
            "3:5: G97: spindle RPM mode is the only mode: no effect",
            "4:1: message: Insert the part",
            "5:1: M5: spindle control is out of scope",
            "5:4: M9: coolant control is out of scope",
        ]
    );
}

/// (program, line, col, message) for each unsupported feature and each program error.
const ERRORS: &[(&str, usize, usize, &str)] = &[
    (
        "G0 X1 F100\nG81 X1 Y1 Z-1",
        2,
        1,
        "G81 needs R: the retract plane on the first line of a cycle",
    ),
    (
        "G0 X1 F100\nG81 X1 Y1 Z1 R0.5",
        2,
        14,
        "G81: the retract plane R (0.5000 mm) is below the hole bottom Z (1.0000 mm)",
    ),
    (
        "G0 X1 F100\nG83 X1 Y1 Z-1 R1 Q0",
        2,
        18,
        "invalid Q0: expected a peck depth greater than 0",
    ),
    (
        "G0 X1 F100 M3\nG88 X1 Y1 Z-1 R1 P1",
        2,
        1,
        "unsupported: G88 (the G88 boring cycle stops for the operator to retract the spindle by hand: use G86 or G89)",
    ),
    (
        "G0 X1 F100 M3\nG87 X1 Y1 Z-1 R1 I1 J1 K1",
        2,
        1,
        "unsupported: G87 (the back boring cycle needs spindle orientation (M19), which is out of scope)",
    ),
    (
        "G33 Z-1 K1",
        1,
        1,
        "unsupported: G33 (spindle-synchronised motion (threading, rigid tapping) is not supported)",
    ),
    (
        "G76 P1",
        1,
        1,
        "unsupported: G76 (spindle-synchronised motion (threading, rigid tapping) is not supported)",
    ),
    (
        "G95",
        1,
        1,
        "unsupported: G95 (feed per revolution is spindle-synchronised: not supported)",
    ),
    (
        "G96 S100",
        1,
        1,
        "unsupported: G96 (constant surface speed is spindle-synchronised: not supported)",
    ),
    (
        "G38.2 Z-1",
        1,
        1,
        "unsupported: G38.2 (probing is not supported)",
    ),
    (
        "G5.2 X1 Y1 P1",
        1,
        1,
        "unsupported: G5.2 (NURBS (G5.2, G5.3) are not supported: use G5 or G5.1)",
    ),
    (
        "G5.3",
        1,
        1,
        "unsupported: G5.3 (NURBS (G5.2, G5.3) are not supported: use G5 or G5.1)",
    ),
    (
        "G0 X1 A90",
        1,
        7,
        "unsupported: axis word 'A': the machine has no A axis (add an [[axis]] with name = \"A\" to the machine file)",
    ),
    (
        "G2 @1 ^30 R1 F60",
        1,
        4,
        "unsupported: polar coordinate word '@' on an arc (polar coordinates are read on G0 and G1 moves only)",
    ),
    (
        "M60",
        1,
        1,
        "unsupported: M60 (pallet change pause is not supported)",
    ),
    (
        "M101",
        1,
        1,
        "unsupported: M101 (user-defined M codes are not supported)",
    ),
    (
        "G10 L11 P1 Y0",
        1,
        12,
        "unsupported: G10 L11 with Y (lathe tool offsets are not supported: give Z (and R))",
    ),
    (
        "G0 X#5001",
        1,
        5,
        "unsupported: system parameter #5001 (of LinuxCNC's system parameters (#5000 and above), these are kept, read-only: #5070, #5161-#5163, #5181-#5183, #5210-#5213, #5220, #5221-#5223 and #5230 per work system (+20 each), #5399, #5400-#5403, #5410, #5420-#5422, #5599)",
    ),
    (
        "G17 G41.1 D2\nG40\nG19 G41.1 D2",
        3,
        5,
        "unsupported: G41.1 in the YZ plane (G19) (cutter compensation works in the XY (G17) and ZX (G18) planes)",
    ),
    (
        "G21 F60\nG0 X10\nG2 X0.1 Y0 I-5",
        3,
        1,
        "unsupported: spiral arc (the end point is off the circle: radius 5.0000 mm to the start, 4.9000 mm to the end, tolerance 0.0283 mm)",
    ),
    (
        "G21 F60\nG2 X20 I5",
        2,
        1,
        "unsupported: spiral arc (the end point is off the circle: radius 5.0000 mm to the start, 15.0000 mm to the end, tolerance 0.0283 mm)",
    ),
    (
        "o<probe> call",
        1,
        1,
        "subroutine o<probe> is not defined: define it with 'sub' before the call, or put probe.ngc in a folder of the machine file's [program] subroutine_path (searched: no subroutine_path is set)",
    ),
    (
        "G21 F60\nG2 X30 R10",
        2,
        8,
        "arc radius 10.0000 mm cannot reach the end point (15.0000 mm away from the middle of the chord)",
    ),
    (
        "G21 F60\nG2 X0 Y0 R10",
        2,
        10,
        "R-format arc with the end point equal to the start: use I/J/K for a full circle",
    ),
    (
        "G21 F60\nG2 Z1 R10",
        2,
        1,
        "arc in the G17 plane needs X or Y",
    ),
    (
        "G21 F60\nG2 X1 R10 I1",
        2,
        11,
        "arc with both R and a centre offset: use one format",
    ),
    (
        "G21 F60\nG2 X1",
        2,
        1,
        "arc in the G17 plane without R or centre offsets",
    ),
    (
        "G2 X1 I1 K1",
        1,
        10,
        "K is not an arc centre word in the G17 plane",
    ),
    ("G41 D9", 1, 5, "tool 9 (D9) is not in the tool table"),
    ("G43 H7", 1, 5, "tool 7 (H7) is not in the tool table"),
    (
        "G1 X1",
        1,
        1,
        "G1 move with no feed rate: program F (mm/min, or in/min under G20) on this line or before",
    ),
    (
        "G93 G1 X1 F1\nX2",
        2,
        1,
        "G1 move in inverse time mode (G93) without F on its line",
    ),
    (
        "X1",
        1,
        1,
        "axis words with no motion mode in force: add G0, G1, G2 or G3",
    ),
    (
        "G0 I1 X1",
        1,
        4,
        "word 'I' has nothing to use it: it belongs to an arc (G2/G3) in a plane that has this axis",
    ),
    (
        "G28 G1 X1",
        1,
        5,
        "G28 and G1 both use the axis words of this line",
    ),
    ("G4", 1, 1, "G4 needs P: the dwell time in seconds"),
    ("G0 X1 X2", 1, 7, "word 'X' appears twice on one line"),
    (
        "G0 G1",
        1,
        4,
        "G0 and G1 on one line are both motion codes (one per line)",
    ),
    ("G12.5", 1, 1, "unknown code G12.5"),
    ("G0 X[1/0]", 1, 7, "division by zero"),
    (
        "G0 X#<undefined>",
        1,
        5,
        "parameter #<undefined> is not defined",
    ),
    (
        "o1 while [1]\nG0 X1",
        1,
        1,
        "o1 is never closed: no 'o1 endwhile' before the end of the program",
    ),
    (
        "o1 endwhile",
        1,
        1,
        "o1 endwhile needs to follow its opening line",
    ),
    (
        "G0 X1 (unclosed",
        1,
        7,
        "comment '(' is not closed on this line",
    ),
    ("G0 X1.2.3", 1, 5, "malformed number '1.2.3' after 'X'"),
    ("G0 X1 $", 1, 7, "unexpected character '$'"),
    (
        "G41 D0 G0 X1\nG42",
        2,
        1,
        "G42 while cutter compensation is on: cancel it with G40 first",
    ),
];

#[test]
fn every_error_with_its_position() {
    let mut wrong = Vec::new();
    for &(text, line, col, message) in ERRORS {
        let expected = format!("t.ngc:{line}:{col}: {message}");
        match run_with(text, setup()) {
            Ok(_) => wrong.push(format!("{text:?}: no error, expected {expected}")),
            Err(e) => {
                if e.to_string() != expected {
                    wrong.push(format!("{text:?}:\n   got {e}\n  want {expected}"));
                }
                if message.starts_with("unsupported: ") != e.is_unsupported() {
                    wrong.push(format!("{text:?}: is_unsupported() is wrong"));
                }
            }
        }
    }
    assert!(wrong.is_empty(), "\n{}", wrong.join("\n"));
}

#[test]
fn arc_tolerance_is_configurable() {
    // 0.05 mm off on a 5 mm radius: beyond the default, within a looser tolerance.
    let text = "G21 F60\nG0 X10\nG2 X0.05 Y0 I-5 J0\n";
    assert!(run_with(text, setup()).is_err());
    let mut s = setup();
    s.arc_tolerance_mm = 0.1;
    let p = run_with(text, s).unwrap();
    let arc = p.elements().next_back().unwrap().arc().unwrap();
    assert!((arc.end_radius_mm - arc.start_radius_mm).abs() > 1e-4);
}

#[test]
fn o_word_branches_loops_and_returns() {
    golden(
        "G21 F60\n\
         o10 sub\n\
           o11 if [#1 GT 2]\n\
             o10 return [#1 * 2]\n\
           o11 elseif [#1 EQ 2]\n\
             G1 Y2\n\
           o11 else\n\
             G1 Y1\n\
           o11 endif\n\
         o10 endsub [0]\n\
         o10 call [1]\n\
         o10 call [2]\n\
         o10 call [3]\n\
         G1 X#<_value>\n\
         #2 = 0\n\
         o20 while [#2 LT 5]\n\
           #2 = [#2 + 1]\n\
           o21 if [#2 EQ 2]\n\
             o20 continue\n\
           o21 endif\n\
           o22 if [#2 EQ 4]\n\
             o20 break\n\
           o22 endif\n\
           G91 G1 Z1\n\
         o20 endwhile\n\
         G90\n\
         M2\n",
        "8 line G1 (0,0,0)->(0,1,0) F1
         6 line G1 (0,1,0)->(0,2,0) F1
         14 line G1 (0,2,0)->(6,2,0) F1
         24 line G1 (6,2,0)->(6,2,1) F1
         24 line G1 (6,2,1)->(6,2,2) F1
         27 end M2",
    );
}

#[test]
fn rotated_coordinate_systems_rotate_arcs_too() {
    // G18 half circle in a system rotated by 90° about Z: the ZX plane becomes the ZY plane
    // and the arc's axis turns from −Y to +X.
    golden(
        "G21 F60\nG10 L2 P1 R90\nG18 G2 X10 Z0 I5 K0\n",
        "3 arc G2 (0,0,0)->(0,10,0) c(0,5,0) n(1,0,0) r5 turns0 F1
         end of text",
    );
}
