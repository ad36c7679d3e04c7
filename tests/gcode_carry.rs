//! Issue 14, items 2 and 3: one interpreter state across the MDI lines and jobs of one
//! `canmotion serve`, as LinuxCNC keeps it. Each MDI line and program runs through
//! `gcode::parse_mdi` / `parse_program_with` with `Setup::carry` set to what the last one left
//! (`Program::carry`), from where the machine is (the last one's end point).

use canmotion::gcode::{
    Carry, ErrorKind, MDI_FILE, Program, ProgramEnd, Setup, parse_mdi, parse_program_with,
};
use nalgebra::Vector3;

/// A machine: where it is, and the state the last MDI line or program left.
struct Machine {
    at_mm: Vector3<f64>,
    carry: Option<Carry>,
    /// The setup the machine file gives (offsets, tools).
    base: Setup,
}

impl Machine {
    fn new() -> Machine {
        Machine::with(Setup::new(Vector3::zeros()))
    }

    fn with(base: Setup) -> Machine {
        Machine {
            at_mm: base.start_mm,
            carry: None,
            base,
        }
    }

    fn setup(&self) -> Setup {
        let mut s = self.base.clone();
        s.start_mm = self.at_mm;
        s.carry = self.carry.clone();
        s
    }

    /// Takes up what a job left, as `serve` does after running it.
    fn ran(&mut self, p: Program) -> Program {
        self.at_mm = p.end_mm();
        self.carry = Some(p.carry.clone());
        p
    }

    fn mdi(&mut self, line: &str) -> Program {
        let p = parse_mdi(line, self.setup()).unwrap_or_else(|e| panic!("{line}: {e}"));
        self.ran(p)
    }

    fn run(&mut self, text: &str) -> Program {
        let p = parse_program_with(text, "part.ngc", self.setup()).unwrap();
        self.ran(p)
    }

    fn carry(&self) -> &Carry {
        self.carry.as_ref().expect("a carry")
    }
}

fn v(x: f64, y: f64, z: f64) -> Vector3<f64> {
    Vector3::new(x, y, z)
}

#[test]
fn mdi_g91_then_two_moves_of_1_mm_move_2_mm() {
    let mut m = Machine::new();
    m.mdi("G91");
    assert!(!m.carry().absolute());
    m.mdi("G0 X1");
    m.mdi("G0 X1");
    assert_eq!(m.at_mm, v(2.0, 0.0, 0.0));
}

#[test]
fn units_carry_between_mdi_lines() {
    let mut m = Machine::new();
    m.mdi("G20");
    assert!(m.carry().inch());
    m.mdi("G0 X1 Y2");
    assert_eq!(m.at_mm, v(25.4, 50.8, 0.0));
}

#[test]
fn a_g10_work_offset_set_in_mdi_is_used_by_the_next_program() {
    let mut m = Machine::new();
    m.mdi("G10 L2 P1 X5");
    assert_eq!(m.carry().work_offset_index(), 0);
    m.run("G0 X0\nM2\n");
    assert_eq!(m.at_mm, v(5.0, 0.0, 0.0));
    // And by the MDI lines after it, G10 offsets persisting through M2.
    m.mdi("G0 X1");
    assert_eq!(m.at_mm, v(6.0, 0.0, 0.0));
}

#[test]
fn the_carry_replaces_the_setups_offsets_and_tools() {
    // The machine file gives G55 at X100; an MDI G10 moves it to X7.
    let mut base = Setup::new(Vector3::zeros());
    base.work_offsets_mm[1] = v(100.0, 0.0, 0.0);
    let mut m = Machine::with(base);
    m.mdi("G55 G0 X1");
    assert_eq!(m.at_mm, v(101.0, 0.0, 0.0));
    assert_eq!(m.carry().work_offset_index(), 1);
    m.mdi("G10 L2 P2 X7");
    m.mdi("G0 X1");
    assert_eq!(m.at_mm, v(8.0, 0.0, 0.0));
    // A tool table change and the tool length offset carry too.
    m.mdi("G10 L1 P3 Z10");
    m.mdi("T3 M6");
    m.mdi("G43");
    m.mdi("G0 Z1");
    assert_eq!(m.at_mm, v(8.0, 0.0, 11.0));
    assert_eq!(m.carry().loaded_tool(), 3);
    assert!(m.carry().modal_summary().contains(" G43"));
}

#[test]
fn g92_offsets_persist_across_a_program_that_ends_with_m2() {
    let mut m = Machine::new();
    m.mdi("G0 X10");
    m.mdi("G92 X0");
    assert_eq!(m.carry().g92_offset_mm(), v(10.0, 0.0, 0.0));
    m.run("G0 X1\nM2\n");
    assert_eq!(m.at_mm, v(11.0, 0.0, 0.0));
    assert_eq!(m.carry().g92_offset_mm(), v(10.0, 0.0, 0.0));
    m.mdi("G0 X0");
    assert_eq!(m.at_mm, v(10.0, 0.0, 0.0));
    m.mdi("G92.1");
    assert_eq!(m.carry().g92_offset_mm(), Vector3::zeros());
}

#[test]
fn m2_resets_the_distance_mode_and_the_end_of_text_does_not() {
    let mut m = Machine::new();
    let p = m.run("G91\nG0 X1\nM2\n");
    assert_eq!(p.end, ProgramEnd::M2 { line: 3 });
    assert!(m.carry().absolute());
    m.mdi("G0 X5");
    assert_eq!(m.at_mm, v(5.0, 0.0, 0.0));

    let mut m = Machine::new();
    let p = m.run("G91\nG0 X1\n");
    assert_eq!(p.end, ProgramEnd::EndOfText);
    assert!(!m.carry().absolute());
    m.mdi("G0 X5");
    assert_eq!(m.at_mm, v(6.0, 0.0, 0.0));

    // `%` ends a program as the end of the text does: no resets.
    let mut m = Machine::new();
    m.run("%\nG91\n%\n");
    assert!(!m.carry().absolute());
}

#[test]
fn m2_and_m30_reset_linuxcncs_list_and_nothing_else() {
    for end in ["M2", "M30"] {
        let mut m = Machine::new();
        m.mdi("G10 L2 P2 X50");
        let text = format!("G20 G55 G18 G91 G93 G90.1\nG1 X1 F2\nG92 X0\nM3 S1000\n{end}\n");
        m.run(&text);
        let c = m.carry();
        // Reset: G54, G17, G90, G94 (the G93 feed cleared), G40, M5, G1.
        assert_eq!(c.work_offset_index(), 0, "{end}");
        assert!(c.absolute(), "{end}");
        assert_eq!(c.feed_mm_s(), None, "{end}");
        // Kept: units, arc distance mode, the G92 offset.
        assert!(c.inch(), "{end}");
        assert_eq!(
            c.modal_summary(),
            "G1 G20 G90 G17 G94 G54 G40 G49 G92 G90.1 T0",
            "{end}"
        );
        // G92 X0 was taken in G55 (origin X50) at machine X 25.4 (G91 X1 inch from 0).
        assert!(
            (c.g92_offset_mm() - v(-24.6, 0.0, 0.0)).norm() < 1e-9,
            "{end}"
        );
        // Motion mode G1 after M2: axis words alone move at the (G94) feed given next.
        m.mdi("F60");
        let p = m.mdi("X0");
        let e = p.elements().next().expect("a move");
        assert!(!e.rapid);
        assert_eq!(e.feed_mm_s, Some(60.0 * 25.4 / 60.0));
        // In G54 (origin 0) with the G92 offset: program X0 is machine X −24.6.
        assert!(
            (m.at_mm - v(-24.6, 0.0, 0.0)).norm() < 1e-9,
            "{end}: {}",
            m.at_mm
        );
    }
}

#[test]
fn a_program_that_fails_leaves_nothing_to_carry() {
    let mut m = Machine::new();
    m.mdi("G91 F600");
    let before = m.carry().clone();
    let e = parse_program_with("G90 G21\nG0 X1\nG0 Q1\nM2\n", "part.ngc", m.setup()).unwrap_err();
    assert_eq!((e.file.as_str(), e.line), ("part.ngc", 3));
    // Nothing ran: the machine keeps its carry, and the next line runs as before the job.
    assert_eq!(m.carry(), &before);
    m.mdi("G0 X1");
    assert_eq!(m.at_mm, v(1.0, 0.0, 0.0));
    m.mdi("G0 X1");
    assert_eq!(m.at_mm, v(2.0, 0.0, 0.0));
}

#[test]
fn the_feed_carries_between_mdi_lines() {
    let mut m = Machine::new();
    assert_eq!(m.mdi("G0 X0").carry.feed_mm_s(), None);
    m.mdi("F600");
    assert_eq!(m.carry().feed_mm_s(), Some(10.0));
    let p = m.mdi("G1 X10");
    assert_eq!(p.elements().next().unwrap().feed_mm_s, Some(10.0));
    // Without a carry a feed move has no feed: an error.
    let e = parse_mdi("G1 X10", Setup::new(Vector3::zeros())).unwrap_err();
    assert!(matches!(e.kind, ErrorKind::MissingFeed { .. }), "{e}");
}

#[test]
fn parameters_carry_between_mdi_lines_and_into_programs() {
    let mut m = Machine::new();
    m.mdi("#<_depth> = 3");
    m.mdi("#100 = 4");
    m.mdi("#1 = 5");
    m.mdi("G0 Z#<_depth> X#100 Y#1");
    assert_eq!(m.at_mm, v(4.0, 5.0, 3.0));
    m.run("#<_depth> = [#<_depth> + 1]\nG0 Z#<_depth>\nM2\n");
    assert_eq!(m.at_mm, v(4.0, 5.0, 4.0));
    m.mdi("G0 Z[#<_depth> * 2]");
    assert_eq!(m.at_mm, v(4.0, 5.0, 8.0));
}

#[test]
fn empty_and_comment_lines_carry_the_state_through() {
    let mut m = Machine::new();
    m.mdi("G20 G91 F10");
    let before = m.carry().clone();
    for line in ["", "   ", "(just a comment)", "; another"] {
        let p = m.mdi(line);
        assert!(p.items.is_empty(), "{line:?}");
        assert_eq!(m.carry(), &before, "{line:?}");
    }
}

#[test]
fn the_modal_summary_reads_as_a_controller_shows_it() {
    let mut m = Machine::new();
    assert_eq!(
        m.mdi("").carry.modal_summary(),
        "G21 G90 G17 G94 G54 G40 G49 T0"
    );
    m.mdi("T1 M6 F600");
    assert_eq!(
        m.carry().modal_summary(),
        "G21 G90 G17 G94 G54 G40 G49 F600 T1"
    );
    m.mdi("G0 G20 G91 G18 G59.3 X0");
    assert_eq!(
        m.carry().modal_summary(),
        "G0 G20 G91 G18 G94 G59.3 G40 G49 F23.622047 T1"
    );
    assert_eq!(m.carry().work_offset_index(), 8);
}

#[test]
fn mdi_refuses_what_needs_more_lines_with_its_column() {
    let m = Machine::new();
    let err = |line: &str| parse_mdi(line, m.setup()).unwrap_err();
    for (line, col, what) in [
        ("G0 X5 G41.1 D2", 7, "cutter compensation in MDI (G41.1)"),
        ("G42 D1 G1 X5 F100", 1, "cutter compensation in MDI (G42)"),
        ("M98 P100", 1, "M98 in MDI"),
        ("G0 X1 M99", 7, "M99 in MDI"),
        ("o100 sub", 1, "subroutine definitions in MDI"),
    ] {
        let e = err(line);
        assert_eq!(e.file, MDI_FILE, "{line}");
        assert_eq!((e.line, e.col), (1, col), "{line}");
        match &e.kind {
            ErrorKind::Unsupported { what: w, .. } => assert_eq!(w, what, "{line}"),
            other => panic!("{line}: {other:?}"),
        }
        assert!(e.to_string().starts_with(&format!("MDI:1:{col}: ")), "{e}");
    }
    // G40 is fine, and so is a syntax error's place.
    parse_mdi("G40", m.setup()).unwrap();
    let e = err("G0 X1 Q");
    assert!(e.to_string().starts_with("MDI:1:7: "), "{e}");
}

#[test]
fn a_program_ending_under_compensation_carries_g40() {
    let mut base = Setup::new(Vector3::zeros());
    base.tools.insert(
        1,
        canmotion::gcode::Tool {
            radius_mm: 1.0,
            length_mm: 0.0,
        },
    );
    let mut m = Machine::with(base);
    m.run("G41 D1 G1 X10 F600\nG1 Y10\n");
    assert!(m.carry().modal_summary().contains(" G40 "));
    // The next line is not compensated: it goes to its programmed point.
    m.mdi("G0 X0 Y0");
    assert_eq!(m.at_mm, v(0.0, 0.0, 0.0));
}
