//! The streaming interpreter: lines in, [`Item`]s out, with the modal state in between.
//!
//! Each call to [`Iterator::next`] reads at most one more line (a line yields 0 to a few items:
//! G28 with axis words makes two moves), so memory is bounded by the longest line
//! ([`MAX_LINE_BYTES`]) and the tool table, whatever the file size.
//!
//! # Coordinates
//!
//! The state keeps the current point twice: in machine coordinates (what the axes do, the
//! output) and in program coordinates (the current work system, what G91 and omitted axis words
//! refer to), like LinuxCNC. A program point `p` maps to the machine as
//!
//! `machine = R(p + g92) + work_offset + tool_offset`
//!
//! with `R` the rotation of the work system about Z (G10 L2 R), as in LinuxCNC's canon layer.
//! When an offset changes, the machine point stays and the program point is recomputed: the
//! offset takes effect with the next move of each axis. An axis that a move leaves alone keeps
//! its machine coordinate bit for bit.
//!
//! # Order of execution within a line
//!
//! As RS274/NGC (LinuxCNC): units (G20/G21, first: every number of the line is read in the units
//! in force after it), feed mode, F, S, T, M6/M61, spindle, coolant, overrides, G4 dwell, plane,
//! cutter compensation, tool length offset, work system, path control, distance modes, G98/G99,
//! G10/G28/G30/G92, motion (with G53), then M0/M1/M2/M30.

use std::collections::{HashMap, VecDeque};
use std::f64::consts::FRAC_PI_2;
use std::io::BufRead;
use std::path::PathBuf;
use std::rc::Rc;

use nalgebra::Vector3;

use super::block::{Block, BlockError, Code, as_index, letter_bit};
use super::element::{
    AUX_LETTERS, AuxMove, AuxPos, BlendMode, CompState, Element, ElementKind, FULL_CIRCLE_EPS_MM,
    Plane,
};
use super::expr::Params;
use super::lex::{
    Control, Keyword, Label, LineKind, Scanner, Word, has_m99, peek_control, peek_program_number,
};
use super::tool_table::{MAX_TOOL_NUMBER, MAX_TOOL_SIZE_MM, Tool, ToolTable};
use super::{
    CallChain, CallSite, Dwell, Error, ErrorKind, Item, MM_PER_INCH, Note, ProgramEnd, Stop,
};

// The canned cycles live in their own file; as a child of this module they extend `State`.
#[path = "cycles.rs"]
mod cycles;
pub use cycles::MAX_CYCLE_ITEMS;
use cycles::{Cycle, CycleState, Spindle};

// The state carried from one interpretation to the next (`serve`'s MDI lines and jobs).
#[path = "carry.rs"]
mod carry;
pub use carry::Carry;

// G5/G5.1, also a child module extending `State`.
#[path = "splines.rs"]
mod splines;
pub use splines::{MAX_SPLINE_SEGMENTS, MIN_SPLINE_TOL_MM};

/// Longest line accepted, in bytes (terminator excluded). It bounds the reader's memory. The
/// bound of every file read line by line ([`crate::files::MAX_LINE_BYTES`]).
pub const MAX_LINE_BYTES: usize = crate::files::MAX_LINE_BYTES;

/// Largest machine coordinate magnitude the interpreter produces; beyond it a program is in
/// error (G91 accumulating, huge offsets).
pub const MAX_POSITION_MM: f64 = 1.0e12;

/// An arc radius below this is a zero-radius arc (LinuxCNC's 0.00005 in).
pub const MIN_ARC_RADIUS_MM: f64 = 0.00127;

/// How an interpretation starts: the machine's position and configuration.
#[derive(Debug, Clone, PartialEq)]
pub struct Setup {
    /// Where the machine is (machine coordinates): moves start here.
    pub start_mm: Vector3<f64>,
    /// Work offsets of G54, G55, G56, G57, G58, G59, G59.1, G59.2, G59.3 (machine coordinates
    /// of each system's origin). G54 is in force at the start.
    pub work_offsets_mm: [Vector3<f64>; 9],
    /// The G28 position (machine coordinates).
    pub g28_mm: Vector3<f64>,
    /// The G30 position (machine coordinates).
    pub g30_mm: Vector3<f64>,
    /// Tool radii and lengths; G10 L1 changes the interpreter's copy for the rest of the run.
    pub tools: ToolTable,
    /// Tool in the spindle at the start (0 = none); G43 without H and G41/G42 without D use
    /// the tool in the spindle.
    pub loaded_tool: u32,
    /// Arc end-point check (centre format): the distances from the centre to the start and to
    /// the end may differ by this much (2.54 times as much in an inch program, as LinuxCNC's
    /// inch tolerance)...
    pub arc_tolerance_mm: f64,
    /// ...or by this fraction of the larger radius, up to 100 times the absolute tolerance
    /// (LinuxCNC's rule). Within, the path spirals between the two radii, the radius changing
    /// in proportion to the angle, as LinuxCNC interpolates it; beyond, it is an error.
    pub arc_tolerance_rel: f64,
    /// Block delete switch: skip lines starting with `/` (LinuxCNC's default: on).
    pub block_delete: bool,
    /// Optional stop switch: M1 stops like M0 (LinuxCNC's default: on); off, M1 is noted
    /// and skipped.
    pub optional_stop: bool,
    /// Folders searched in order for `name.ngc` when `o<name> call` (or `123.ngc` for
    /// `o123 call`) names a subroutine the program has not defined: LinuxCNC's
    /// SUBROUTINE_PATH. Empty (the default): no file is searched.
    pub subroutine_path: Vec<PathBuf>,
    /// How many times M99 in the main program restarts it from its first line (on a
    /// controller, an endless program); after that, M99 ends it ([`ProgramEnd::M99`]).
    /// Above 0, the main program's text is kept in memory, within [`MAX_STORED_BYTES`].
    /// Default 0: M99 in the main program ends it.
    pub m99_restarts: u32,
    /// Largest distance between a G5/G5.1 spline and the lines it is sampled into (the
    /// planner's `chord_tol_mm`). Default [`DEFAULT_SPLINE_TOL_MM`].
    pub spline_tol_mm: f64,
    /// The state an earlier interpretation on this machine left ([`Program::carry`](super::Program::carry),
    /// [`Interpreter::carry`]): the modal state, offsets, tools and parameters start from it,
    /// and its work offsets, G28/G30 positions, tool table and loaded tool replace this
    /// setup's. The position is still [`Setup::start_mm`] (where the machine is). Default
    /// `None`: the defaults above, as at power-on.
    pub carry: Option<Carry>,
    /// Where the auxiliary axes A B C (degrees) U V W (mm) are, in machine coordinates.
    /// Default 0.
    pub start_aux: AuxPos,
    /// Which auxiliary axes the machine has, in the order of [`AUX_LETTERS`]: a program that
    /// moves another one is an error ([`ErrorKind::AxisNotConfigured`]). Default: none.
    pub aux_axes: [bool; 6],
    /// Which of them are wrapped rotary axes (LinuxCNC's WRAPPED_ROTARY): a G90 position is
    /// in `(−360°, 360°)`; as LinuxCNC's `unwrap_rotary` reads it, its magnitude is the
    /// position modulo a turn and its sign the direction of the move (`A-90`: the negative
    /// way round to 90°), unless [`Setup::aux_shortest`] says otherwise. The machine
    /// coordinate keeps counting whole turns. Default: none.
    pub aux_wrapped: [bool; 6],
    /// Which wrapped axes take a G90 position (then read modulo a turn, `A-90` = 270°) the
    /// shortest way round instead of LinuxCNC's signed direction. Default: none.
    pub aux_shortest: [bool; 6],
}

/// The default of [`Setup::spline_tol_mm`]: 1 µm, the planner's default chord tolerance.
pub const DEFAULT_SPLINE_TOL_MM: f64 = 0.001;

impl Setup {
    /// Defaults (LinuxCNC's): no work offsets, G28/G30 at machine zero, an empty tool table,
    /// no tool loaded, block delete and optional stop on, and the arc tolerance of LinuxCNC's
    /// interpreter: 2·√2·0.01 mm (an arc whose centre and end point were rounded to 0.01 mm
    /// passes) or 0.1 % of the radius, whichever is larger. CAM output with four decimals in
    /// inches carries radius errors of several µm on sub-millimetre arcs, so a tighter default
    /// would reject real programs.
    pub fn new(start_mm: Vector3<f64>) -> Setup {
        Setup {
            start_mm,
            work_offsets_mm: [Vector3::zeros(); 9],
            g28_mm: Vector3::zeros(),
            g30_mm: Vector3::zeros(),
            tools: ToolTable::new(),
            loaded_tool: 0,
            arc_tolerance_mm: 2.0 * std::f64::consts::SQRT_2 * 0.01,
            arc_tolerance_rel: 0.001,
            block_delete: true,
            optional_stop: true,
            subroutine_path: Vec::new(),
            m99_restarts: 0,
            spline_tol_mm: DEFAULT_SPLINE_TOL_MM,
            carry: None,
            start_aux: [0.0; 6],
            aux_axes: [false; 6],
            aux_wrapped: [false; 6],
            aux_shortest: [false; 6],
        }
    }

    fn validate(&self) -> Result<(), ErrorKind> {
        let point = |v: &Vector3<f64>| {
            v.iter()
                .all(|c| c.is_finite() && c.abs() <= MAX_POSITION_MM)
        };
        let bad = |what: &'static str| Err(ErrorKind::InvalidSetup { what });
        if !point(&self.start_mm)
            || !self
                .start_aux
                .iter()
                .all(|c| c.is_finite() && c.abs() <= MAX_POSITION_MM)
        {
            return Err(ErrorKind::NonFiniteStart);
        }
        if !self.work_offsets_mm.iter().all(point) {
            return bad("work_offsets_mm must be finite and at most 1e12 mm");
        }
        if !point(&self.g28_mm) || !point(&self.g30_mm) {
            return bad("g28_mm and g30_mm must be finite and at most 1e12 mm");
        }
        if !(self.arc_tolerance_mm > 0.0 && self.arc_tolerance_mm.is_finite()) {
            return bad("arc_tolerance_mm must be finite and greater than zero");
        }
        if !(self.arc_tolerance_rel > 0.0 && self.arc_tolerance_rel.is_finite()) {
            return bad("arc_tolerance_rel must be finite and greater than zero");
        }
        if !(self.spline_tol_mm >= MIN_SPLINE_TOL_MM && self.spline_tol_mm.is_finite()) {
            return bad("spline_tol_mm must be finite and at least 1e-6 mm");
        }
        // A negative radius swaps the side of G41/G42 (LinuxCNC's negative diameter).
        let tools_ok = self.tools.iter().all(|(_, t)| {
            t.radius_mm.abs() <= MAX_TOOL_SIZE_MM && t.length_mm.abs() <= MAX_TOOL_SIZE_MM
        });
        if !tools_ok {
            return bad("tool radii and lengths must be at most 10000 mm in magnitude");
        }
        Ok(())
    }
}

/// What a line asks of the program flow besides its items.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Flow {
    /// Go on with the next line.
    Next,
    /// The program ends.
    End(ProgramEnd),
    /// M98 P L: call numbered subprogram `number`, `count` times.
    Call { number: u32, count: u32, col: usize },
    /// M99: return from a numbered subprogram (or restart the main program).
    Return { col: usize },
}

/// The motion mode (modal group 1).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Motion {
    Rapid,
    Linear,
    Cw,
    Ccw,
    /// A canned cycle (G73, G74, G81…G86, G89).
    Cycle(Cycle),
    /// G5.
    Cubic,
    /// G5.1.
    Quadratic,
}

impl Motion {
    /// The G code ×10, as LinuxCNC's `#<_motion_mode>` reads it.
    fn tenths(self) -> f64 {
        match self {
            Motion::Rapid => 0.0,
            Motion::Linear => 10.0,
            Motion::Cw => 20.0,
            Motion::Ccw => 30.0,
            Motion::Cycle(c) => c.code()[1..].parse::<f64>().map_or(0.0, |g| g * 10.0),
            Motion::Cubic => 50.0,
            Motion::Quadratic => 51.0,
        }
    }
}

/// The modal state M70/M73 save and M72 restores (LinuxCNC's list, G7/G8 included, less what
/// has no effect here: spindle speed mode, coolant, override switches; the motion mode is not
/// saved).
#[derive(Debug, Clone, PartialEq)]
struct Modal {
    inch: bool,
    plane: Plane,
    comp: CompState,
    incremental: bool,
    inverse_time: bool,
    coord: usize,
    tool_offset_mm: Vector3<f64>,
    retract_to_r: bool,
    arc_absolute: bool,
    blend: BlendMode,
    feed_mm_s: Option<f64>,
    spindle: Spindle,
    /// G7 rather than G8 (lathe diameter mode).
    diameter_mode: bool,
}

/// A saved modal state, and whether it comes back when its subroutine returns (M73).
#[derive(Debug, Clone, PartialEq)]
struct Saved {
    modal: Modal,
    auto_restore: bool,
}

/// Modal state and positions.
#[derive(Debug, Clone)]
struct State {
    pos_mm: Vector3<f64>,
    /// The auxiliary axes' current position, machine coordinates. Their program coordinate is
    /// the machine's less the work system's origin and the G92/G52 offset
    /// ([`State::aux_offset`]); no rotation or tool offset applies to them.
    aux: AuxPos,
    /// The auxiliary axes' G92/G52 offsets (in force while `g92_on`).
    g92_aux: AuxPos,
    /// The auxiliary axes' origins in G54 … G59.3 (G10 L2/L20; 0 at the start).
    work_aux: [AuxPos; 9],
    aux_axes: [bool; 6],
    aux_wrapped: [bool; 6],
    aux_shortest: [bool; 6],
    prog_mm: Vector3<f64>,
    motion: Option<Motion>,
    plane: Plane,
    inch: bool,
    incremental: bool,
    arc_absolute: bool,
    inverse_time: bool,
    feed_mm_s: Option<f64>,
    blend: BlendMode,
    comp: CompState,
    /// The compensation G40 ended (with a radius), while no straight move came since: the
    /// next move may not be an arc (LinuxCNC's `arc_not_allowed`: that move returns the tool
    /// from its offset point to the programmed point).
    ended_comp: Option<CompState>,
    tool_offset_mm: Vector3<f64>,
    coord: usize,
    work_offsets_mm: [Vector3<f64>; 9],
    rotations_deg: [f64; 9],
    g92_mm: Vector3<f64>,
    g92_on: bool,
    g28_mm: Vector3<f64>,
    g30_mm: Vector3<f64>,
    tools: ToolTable,
    selected_tool: Option<u32>,
    loaded_tool: u32,
    arc_tolerance_mm: f64,
    arc_tolerance_rel: f64,
    optional_stop: bool,
    /// G99 (return to R) rather than G98 (to the initial level) in canned cycles.
    retract_to_r: bool,
    /// The spindle as M3/M4/M5/M19 left it (tapping and boring cycles check it).
    spindle: Spindle,
    /// Sticky values of the canned cycles.
    cycles: CycleState,
    /// Letters of the current line that something used ([`letter_bit`]).
    used: u32,
    /// The modal state saved by M70/M73 at each call level (0: the main program).
    saved: Vec<Option<Saved>>,
    /// G7 (X words are diameters) rather than G8.
    diameter_mode: bool,
    /// The start direction a G5 without I and J takes: the last G5's `−(P, Q)` (mm), while
    /// G5 stays the motion mode.
    spline_next: Option<nalgebra::Vector2<f64>>,
    /// See [`Setup::spline_tol_mm`].
    spline_tol_mm: f64,
    /// The last S word (`#<_rpm>`).
    speed_rpm: f64,
    /// The current line of its file (`#<_line>`, LinuxCNC's sequence number).
    line_number: f64,
}

/// The letters a line may not hold unused, in the order they are reported.
const CHECKED: &str = "XYZIJKRPQDHL@^ABCUVW";

/// The bits ([`letter_bit`]) of [`CHECKED`]: X Y Z I J K R P Q (0 to 8), D H L (12 to 14),
/// `@` `^` (16, 17), A B C U V W (18 to 23).
const CHECKED_BITS: u32 = 0b11_1111 << 18 | 0b11 << 16 | 0b111 << 12 | 0b1_1111_1111;

/// The bits ([`letter_bit`]) of A B C U V W.
const AUX_BITS: u32 = 0b11_1111 << 18;

fn rotate_xy(v: Vector3<f64>, deg: f64) -> Vector3<f64> {
    if deg == 0.0 {
        return v;
    }
    let (s, c) = deg.to_radians().sin_cos();
    Vector3::new(v.x * c - v.y * s, v.x * s + v.y * c, v.z)
}

fn err_at(col: usize, kind: ErrorKind) -> BlockError {
    (col, kind)
}

fn missing(col: usize, code: Code, letter: char, expected: &'static str) -> BlockError {
    err_at(
        col,
        ErrorKind::MissingWord {
            code: code.to_string(),
            letter,
            expected,
        },
    )
}

/// The R word of G10 L1/L10/L11 in mm: negative too (LinuxCNC takes it; under G41/G42 a
/// negative radius swaps the side).
fn tool_radius(r: Word, scale: f64) -> Result<f64, BlockError> {
    let radius_mm = r.value * scale;
    if radius_mm.abs() > MAX_TOOL_SIZE_MM {
        return Err(invalid(r, "a tool radius of at most 10000 mm in magnitude"));
    }
    Ok(radius_mm)
}

fn invalid(word: Word, expected: &'static str) -> BlockError {
    err_at(
        word.col,
        ErrorKind::InvalidValue {
            word: format!("{}{}", word.letter, word.value),
            expected,
        },
    )
}

impl State {
    fn new(setup: Setup) -> State {
        State {
            pos_mm: setup.start_mm,
            aux: setup.start_aux,
            g92_aux: [0.0; 6],
            work_aux: [[0.0; 6]; 9],
            aux_axes: setup.aux_axes,
            aux_wrapped: setup.aux_wrapped,
            aux_shortest: setup.aux_shortest,
            prog_mm: setup.start_mm - setup.work_offsets_mm[0],
            motion: None,
            plane: Plane::Xy,
            inch: false,
            incremental: false,
            arc_absolute: false,
            inverse_time: false,
            feed_mm_s: None,
            // LinuxCNC starts in G64 without P (its canon's continuous mode, tolerance 0:
            // no limit), which the planner caps at `default_tolerance_mm`.
            blend: BlendMode::Blend {
                p_mm: f64::INFINITY,
                q_mm: f64::INFINITY,
            },
            comp: CompState::Off,
            ended_comp: None,
            tool_offset_mm: Vector3::zeros(),
            coord: 0,
            work_offsets_mm: setup.work_offsets_mm,
            rotations_deg: [0.0; 9],
            g92_mm: Vector3::zeros(),
            g92_on: false,
            g28_mm: setup.g28_mm,
            g30_mm: setup.g30_mm,
            tools: setup.tools,
            selected_tool: None,
            loaded_tool: setup.loaded_tool,
            arc_tolerance_mm: setup.arc_tolerance_mm,
            arc_tolerance_rel: setup.arc_tolerance_rel,
            optional_stop: setup.optional_stop,
            // LinuxCNC's interpreter starts in G99 (its retract mode's zero value, R_PLANE).
            retract_to_r: true,
            spindle: Spindle::Stopped,
            cycles: CycleState::default(),
            used: 0,
            saved: vec![None],
            diameter_mode: false,
            spline_next: None,
            spline_tol_mm: setup.spline_tol_mm,
            speed_rpm: 0.0,
            line_number: 0.0,
        }
    }

    /// LinuxCNC's system parameters this interpreter keeps, read-only, lengths in the program's
    /// units as they are now: #5070 (the last probe succeeded: none runs here, 0), #5161-#5163
    /// and #5181-#5183 (the G28 and G30 positions), #5210 (G92 on), #5211-#5213 (the G92/G52
    /// offsets), #5220 (the work system, 1 to 9), #5221-#5223 and #5230 for G54 and +20 for each
    /// next system (its origin and rotation), #5399 (M66's result: none runs here, 0), #5400 (the
    /// tool in the spindle), #5401-#5403 (the tool length offset in effect), #5410 (the tool's
    /// diameter), #5420-#5422 (the current point in the work system), #5599 (DEBUG output on,
    /// 1).
    fn system_parameters(&self, params: &mut Params) {
        let scale = self.scale();
        let mut set3 = |first: u32, v: Vector3<f64>| {
            for (i, c) in v.iter().enumerate() {
                params.set_system(first + i as u32, c / scale);
            }
        };
        set3(5161, self.g28_mm);
        set3(5181, self.g30_mm);
        set3(5211, self.g92_mm);
        for (k, offset) in self.work_offsets_mm.iter().enumerate() {
            set3(5221 + 20 * k as u32, *offset);
        }
        set3(5401, self.tool_offset_mm);
        set3(5420, self.prog_mm);
        for (k, r) in self.rotations_deg.iter().enumerate() {
            params.set_system(5230 + 20 * k as u32, *r);
        }
        let diameter = self
            .tools
            .get(self.loaded_tool)
            .map_or(0.0, |t| 2.0 * t.radius_mm / scale);
        params.set_predefined(self.predefined(scale));
        for (n, v) in [
            (5070, 0.0),
            (5210, if self.g92_on { 1.0 } else { 0.0 }),
            (5220, (self.coord + 1) as f64),
            (5399, 0.0),
            (5400, f64::from(self.loaded_tool)),
            (5410, diameter),
            (5599, 1.0),
        ] {
            params.set_system(n, v);
        }
    }

    /// The values of LinuxCNC's predefined named parameters kept here, in the order of
    /// [`PREDEFINED`](super::expr::PREDEFINED), as `lookup_named_param` computes them.
    fn predefined(&self, scale: f64) -> [f64; 33] {
        let flag = |b: bool| if b { 1.0 } else { 0.0 };
        let plane = match self.plane {
            Plane::Xy => 170.0,
            Plane::Zx => 180.0,
            Plane::Yz => 190.0,
        };
        let ccomp = match self.comp {
            CompState::Off => 400.0,
            CompState::Left { .. } => 410.0,
            CompState::Right { .. } => 420.0,
        };
        let coord = match self.coord {
            k @ 0..=5 => 540.0 + 10.0 * k as f64,
            k => 585.0 + k as f64,
        };
        let feed = self.feed_mm_s.map_or(0.0, |f| f * 60.0 / scale);
        [
            self.line_number,
            self.motion.map_or(800.0, Motion::tenths),
            plane,
            ccomp,
            flag(!self.inch),
            flag(self.inch),
            flag(!self.incremental),
            flag(self.incremental),
            flag(self.inverse_time),
            flag(!self.inverse_time),
            0.0,
            coord,
            flag(self.tool_offset_mm != Vector3::zeros()),
            // LinuxCNC's code: `_retract_r_plane` is G99, `_retract_old_z` G98.
            flag(self.retract_to_r),
            flag(!self.retract_to_r),
            1.0,
            0.0,
            flag(self.arc_absolute),
            flag(self.diameter_mode),
            flag(!self.diameter_mode),
            flag(self.spindle != Spindle::Stopped),
            flag(self.spindle == Spindle::Cw),
            feed,
            self.speed_rpm.abs(),
            f64::from(self.loaded_tool),
            self.selected_tool.map_or(-1.0, f64::from),
            self.prog_mm.x / scale,
            self.prog_mm.y / scale,
            self.prog_mm.z / scale,
            self.pos_mm.x / scale,
            self.pos_mm.y / scale,
            self.pos_mm.z / scale,
            0.0,
        ]
    }

    fn modal(&self) -> Modal {
        Modal {
            inch: self.inch,
            plane: self.plane,
            comp: self.comp,
            incremental: self.incremental,
            inverse_time: self.inverse_time,
            coord: self.coord,
            tool_offset_mm: self.tool_offset_mm,
            retract_to_r: self.retract_to_r,
            arc_absolute: self.arc_absolute,
            blend: self.blend,
            feed_mm_s: self.feed_mm_s,
            spindle: self.spindle,
            diameter_mode: self.diameter_mode,
        }
    }

    /// M72 (or a return after M73): the saved modes come back. Cutter compensation cannot be
    /// switched by a restore here (it needs its entry and exit moves): a restore that would
    /// turn it on, off or change it is refused, as is a plane change under it.
    fn restore(&mut self, m: &Modal, code: Code) -> Result<(), BlockError> {
        if m.comp != self.comp || (self.comp != CompState::Off && m.plane != self.plane) {
            return Err(err_at(
                code.col,
                ErrorKind::Unsupported {
                    what: format!("{code} changing cutter compensation or its plane"),
                    reason: "turn cutter compensation on or off with G41/G42/G40 and their moves",
                },
            ));
        }
        self.inch = m.inch;
        self.plane = m.plane;
        self.incremental = m.incremental;
        self.inverse_time = m.inverse_time;
        self.coord = m.coord;
        self.tool_offset_mm = m.tool_offset_mm;
        self.retract_to_r = m.retract_to_r;
        self.arc_absolute = m.arc_absolute;
        self.blend = m.blend;
        self.feed_mm_s = m.feed_mm_s;
        self.spindle = m.spindle;
        self.diameter_mode = m.diameter_mode;
        self.resync();
        Ok(())
    }

    /// A subroutine call: a new call level with nothing saved.
    fn enter_call(&mut self) {
        self.saved.push(None);
    }

    /// A subroutine return: its level goes, restoring what M73 saved there.
    fn leave_call(&mut self, line: usize, out: &mut VecDeque<Item>) -> Result<(), BlockError> {
        if self.saved.len() > 1
            && let Some(Some(saved)) = self.saved.pop()
            && saved.auto_restore
        {
            let code = Code {
                letter: 'M',
                tenths: 730,
                col: 0,
            };
            self.restore(&saved.modal, code)?;
            out.push_back(Item::Note(Note {
                line,
                col: 0,
                text: "M73: the modal state saved in the subroutine is restored on its return"
                    .to_owned(),
            }));
        }
        Ok(())
    }

    /// M70 … M73.
    fn modal_state(&mut self, code: Code) -> Result<(), BlockError> {
        let level = self.saved.len().saturating_sub(1);
        match code.tenths {
            700 | 730 => {
                let saved = Saved {
                    modal: self.modal(),
                    auto_restore: code.tenths == 730 && level > 0,
                };
                if let Some(slot) = self.saved.last_mut() {
                    *slot = Some(saved);
                }
            }
            710 => {
                if let Some(slot) = self.saved.last_mut() {
                    *slot = None;
                }
            }
            _ => {
                let modal = self
                    .saved
                    .last()
                    .and_then(|s| s.as_ref())
                    .map(|s| s.modal.clone())
                    .ok_or_else(|| err_at(code.col, ErrorKind::NoSavedModalState))?;
                self.restore(&modal, code)?;
            }
        }
        Ok(())
    }

    fn scale(&self) -> f64 {
        if self.inch { MM_PER_INCH } else { 1.0 }
    }

    fn rotation_deg(&self) -> f64 {
        self.rotations_deg[self.coord]
    }

    fn g92(&self) -> Vector3<f64> {
        if self.g92_on {
            self.g92_mm
        } else {
            Vector3::zeros()
        }
    }

    #[inline]
    fn to_machine(&self, prog: Vector3<f64>) -> Vector3<f64> {
        rotate_xy(prog + self.g92(), self.rotation_deg())
            + self.work_offsets_mm[self.coord]
            + self.tool_offset_mm
    }

    fn to_program(&self, machine: Vector3<f64>) -> Vector3<f64> {
        rotate_xy(
            machine - self.work_offsets_mm[self.coord] - self.tool_offset_mm,
            -self.rotation_deg(),
        ) - self.g92()
    }

    /// After an offset change: the machine stays, the program point moves.
    fn resync(&mut self) {
        self.prog_mm = self.to_program(self.pos_mm);
    }

    /// Marks a letter of the line as used and returns its word.
    #[inline]
    fn take(&mut self, b: &Block, letter: char) -> Option<Word> {
        let w = b.word(letter)?;
        self.used |= letter_bit(letter);
        Some(w)
    }

    /// Value of a length word in mm.
    #[inline]
    fn take_mm(&mut self, b: &Block, letter: char) -> Option<f64> {
        let scale = self.scale();
        self.take(b, letter).map(|w| w.value * scale)
    }

    /// The program-coordinate target of the line's axis words (G90/G91 applied).
    #[inline]
    fn prog_target(&mut self, b: &Block) -> Vector3<f64> {
        let mut p = self.prog_mm;
        for (i, letter) in ['X', 'Y', 'Z'].into_iter().enumerate() {
            if let Some(v) = self.take_mm(b, letter) {
                p[i] = if self.incremental { p[i] + v } else { v };
            }
        }
        p
    }

    /// The program-coordinate target of a G0/G1 line, polar words (`@` distance, `^` angle in
    /// degrees) included, as LinuxCNC: under G90 about the work system's origin (the word
    /// left out keeps the current point's distance or angle); under G91 both add to the
    /// current point's distance and angle about the origin (so not from the origin itself).
    #[inline]
    fn prog_target_polar(&mut self, b: &Block) -> Result<Vector3<f64>, BlockError> {
        let [d, a] = b.polar();
        let Some(first) = d.or(a) else {
            return Ok(self.prog_target(b));
        };
        if let Some(w) = b.word('X').or(b.word('Y')) {
            return Err(err_at(w.col, ErrorKind::PolarWithXy { letter: w.letter }));
        }
        let (x0, y0) = (self.prog_mm.x, self.prog_mm.y);
        let d_mm = self.take_mm(b, '@');
        let a_deg = self.take(b, '^').map(|w| w.value);
        let (r, theta) = if self.incremental {
            if x0 == 0.0 && y0 == 0.0 {
                return Err(err_at(first.col, ErrorKind::PolarFromOrigin));
            }
            (
                x0.hypot(y0) + d_mm.unwrap_or(0.0),
                y0.atan2(x0) + a_deg.unwrap_or(0.0).to_radians(),
            )
        } else {
            (
                d_mm.unwrap_or_else(|| x0.hypot(y0)),
                a_deg.map_or_else(|| y0.atan2(x0), f64::to_radians),
            )
        };
        let mut p = self.prog_target(b);
        p.x = r * theta.cos();
        p.y = r * theta.sin();
        Ok(p)
    }

    /// The machine point of a program target; axes whose program coordinate does not change
    /// keep their machine coordinate exactly.
    #[inline]
    fn machine_of(&self, prog: Vector3<f64>) -> Vector3<f64> {
        let mut m = self.to_machine(prog);
        let same = |i: usize| prog[i] == self.prog_mm[i];
        if self.rotation_deg() == 0.0 {
            for i in 0..3 {
                if same(i) {
                    m[i] = self.pos_mm[i];
                }
            }
        } else {
            if same(0) && same(1) {
                m[0] = self.pos_mm[0];
                m[1] = self.pos_mm[1];
            }
            if same(2) {
                m[2] = self.pos_mm[2];
            }
        }
        m
    }

    #[inline]
    fn check_position(&self, col: usize, m: &Vector3<f64>) -> Result<(), BlockError> {
        if m.iter()
            .all(|c| c.is_finite() && c.abs() <= MAX_POSITION_MM)
        {
            Ok(())
        } else {
            Err(err_at(col, ErrorKind::PositionOutOfRange))
        }
    }

    fn lookup_tool(&self, number: u32, col: usize, letter: char) -> Result<Tool, BlockError> {
        self.tools.get(number).ok_or_else(|| {
            err_at(
                col,
                ErrorKind::ToolNotFound {
                    tool: number,
                    letter,
                },
            )
        })
    }

    /// The tool a D or H word names, or the tool in the spindle without it.
    fn tool_word(
        &mut self,
        b: &Block,
        letter: char,
        code: Code,
    ) -> Result<(u32, Tool), BlockError> {
        match self.take(b, letter) {
            Some(w) => {
                let n = as_index(w.value)
                    .filter(|n| *n <= MAX_TOOL_NUMBER)
                    .ok_or_else(|| invalid(w, "a tool number from 0 to 99999"))?;
                Ok((n, self.lookup_tool(n, w.col, letter)?))
            }
            None => Ok((
                self.loaded_tool,
                self.lookup_tool(self.loaded_tool, code.col, letter)?,
            )),
        }
    }

    /// Executes one checked line; items go to `out`. Returns what the line asks of the flow
    /// (the end, an M98 call, an M99 return).
    fn execute(
        &mut self,
        b: &Block,
        line: usize,
        out: &mut VecDeque<Item>,
    ) -> Result<Flow, BlockError> {
        self.used = 0;
        let note = |out: &mut VecDeque<Item>, col: usize, text: String| {
            out.push_back(Item::Note(Note { line, col, text }));
        };
        // G7/G8 first, as LinuxCNC's reader: under G7 (from this line on) every X word is a
        // diameter, halved before any code uses it; I, K and R stay radii.
        if let Some(code) = b.lathe_mode() {
            self.diameter_mode = code.tenths == 70;
        }
        let halved;
        let b = if self.diameter_mode && b.word('X').is_some() {
            halved = b.with_x_halved();
            &halved
        } else {
            b
        };

        // Units first: every number of the line is in the units in force after it.
        if let Some(units) = b.units() {
            let inch = units.tenths == 200;
            if inch != self.inch && self.comp != CompState::Off {
                return Err(err_at(
                    units.col,
                    ErrorKind::CompensationActive {
                        code: units.to_string(),
                    },
                ));
            }
            self.inch = inch;
        }
        let scale = self.scale();

        if let Some(mode) = b.feed_mode() {
            let inverse = mode.tenths == 930;
            if inverse != self.inverse_time {
                // A feed in one mode means nothing in the other: a new F is required.
                self.feed_mm_s = None;
            }
            self.inverse_time = inverse;
        }
        let inverse_f = if self.inverse_time {
            b.word('F').map(|w| w.value).filter(|f| *f > 0.0)
        } else {
            if let Some(w) = b.word('F') {
                // F0 is legal; a feed move needs a positive feed afterwards.
                self.feed_mm_s = Some(w.value * scale / 60.0).filter(|f| *f > 0.0);
            }
            None
        };

        if let Some(s) = b.word('S') {
            self.speed_rpm = s.value;
            note(
                out,
                s.col,
                format!(
                    "S{}: spindle speed recorded (spindle control is out of scope)",
                    s.value
                ),
            );
        }
        if let Some(t) = b.word('T') {
            // The domain check made it a non-negative integer.
            let n = as_index(t.value).unwrap_or(0);
            self.selected_tool = Some(n);
            note(
                out,
                t.col,
                format!("T{n}: tool selected (tool changes are out of scope)"),
            );
        }
        if let Some(code) = b.tool_change() {
            if code.tenths == 60 {
                if let Some(n) = self.selected_tool {
                    self.loaded_tool = n;
                }
                note(
                    out,
                    code.col,
                    format!(
                        "M6: tool {} is now the tool in the spindle for G43 and G41/G42 (the change itself is out of scope)",
                        self.loaded_tool
                    ),
                );
            } else {
                let q = self
                    .take(b, 'Q')
                    .ok_or_else(|| missing(code.col, code, 'Q', "the tool number"))?;
                self.loaded_tool = as_index(q.value)
                    .filter(|n| *n <= MAX_TOOL_NUMBER)
                    .ok_or_else(|| invalid(q, "a tool number from 0 to 99999"))?;
                note(
                    out,
                    code.col,
                    format!(
                        "M61: tool {} set as the tool in the spindle",
                        self.loaded_tool
                    ),
                );
            }
        }
        if let Some(code) = b.spindle() {
            self.spindle = Spindle::after(code.tenths);
        }
        for (code, what) in [
            (b.spindle(), "spindle control is out of scope"),
            (b.coolant(), "coolant control is out of scope"),
            (b.coolant2, "coolant control is out of scope"),
            (
                b.override_switch(),
                "override switches are not handled by the interpreter",
            ),
            (
                b.spindle_mode(),
                "spindle RPM mode is the only mode: no effect",
            ),
        ] {
            if let Some(code) = code {
                note(out, code.col, format!("{code}: {what}"));
            }
        }

        let non_modal = b.non_modal();
        if let Some(code) = non_modal.filter(|c| c.tenths == 40) {
            let p = self
                .take(b, 'P')
                .ok_or_else(|| missing(code.col, code, 'P', "the dwell time in seconds"))?;
            if p.value < 0.0 {
                return Err(invalid(p, "a dwell time of 0 s or more"));
            }
            out.push_back(Item::Dwell(Dwell {
                line,
                col: code.col,
                seconds: p.value,
            }));
        }

        if let Some(code) = b.plane() {
            let plane = match code.tenths {
                170 => Plane::Xy,
                180 => Plane::Zx,
                _ => Plane::Yz,
            };
            if plane != self.plane && self.comp != CompState::Off {
                return Err(err_at(
                    code.col,
                    ErrorKind::CompensationActive {
                        code: code.to_string(),
                    },
                ));
            }
            self.plane = plane;
        }

        if let Some(code) = b.comp() {
            self.cutter_comp(b, code, scale)?;
        }
        if let Some(code) = b.tool_length() {
            self.tool_length(b, code, scale)?;
        }
        if let Some(code) = b.coord() {
            let index = match code.tenths {
                540..=590 => (code.tenths - 540) / 10,
                t => t - 591 + 6,
            } as usize;
            if index != self.coord && self.comp != CompState::Off {
                return Err(err_at(
                    code.col,
                    ErrorKind::CompensationActive {
                        code: code.to_string(),
                    },
                ));
            }
            self.coord = index.min(8);
            self.resync();
        }
        if let Some(code) = b.path() {
            self.blend = match code.tenths {
                610 => BlendMode::ExactPath,
                611 => BlendMode::ExactStop,
                _ => {
                    let p = match self.take(b, 'P') {
                        Some(w) if w.value < 0.0 => {
                            return Err(invalid(w, "a tolerance of 0 or more"));
                        }
                        Some(w) => w.value * scale,
                        // LinuxCNC: no limit; the planner caps it (`default_tolerance_mm`).
                        None => f64::INFINITY,
                    };
                    let q = match self.take(b, 'Q') {
                        Some(w) if w.value < 0.0 => {
                            return Err(invalid(w, "a tolerance of 0 or more"));
                        }
                        Some(w) => w.value * scale,
                        None => p,
                    };
                    BlendMode::Blend { p_mm: p, q_mm: q }
                }
            };
        }
        if let Some(code) = b.distance() {
            self.incremental = code.tenths == 910;
        }
        if let Some(code) = b.arc_distance() {
            self.arc_absolute = code.tenths == 901;
        }
        if let Some(code) = b.retract() {
            self.retract_to_r = code.tenths == 990;
        }

        // Codes that take the axis words for themselves.
        let consumer = non_modal
            .filter(|c| matches!(c.tenths, 100 | 280 | 300 | 520 | 920))
            .or(b.tool_length().filter(|c| matches!(c.tenths, 431 | 432)));
        if let (Some(first), Some(motion)) = (consumer, b.motion().filter(|m| m.tenths != 800)) {
            return Err(err_at(
                motion.col,
                ErrorKind::AxisWordsClaimedTwice {
                    first: first.to_string(),
                    second: motion.to_string(),
                },
            ));
        }
        if let Some(code) = non_modal {
            match code.tenths {
                100 => self.g10(b, code, scale)?,
                280 | 300 => self.home(b, code, line, out)?,
                281 => self.g28_mm = self.pos_mm,
                301 => self.g30_mm = self.pos_mm,
                920 => {
                    if b.first_axis().is_none() {
                        return Err(missing(code.col, code, 'X', "at least one axis word"));
                    }
                    let q = rotate_xy(
                        self.pos_mm - self.work_offsets_mm[self.coord] - self.tool_offset_mm,
                        -self.rotation_deg(),
                    );
                    let base = self.g92();
                    for (i, letter) in ['X', 'Y', 'Z'].into_iter().enumerate() {
                        self.g92_mm[i] = match self.take_mm(b, letter) {
                            Some(v) => q[i] - v,
                            None => base[i],
                        };
                    }
                    let base = self.aux_g92();
                    let words = self.aux_words(b)?;
                    let work = self.work_aux[self.coord];
                    for (i, w) in words.iter().enumerate() {
                        self.g92_aux[i] = w.map_or(base[i], |v| self.aux[i] - work[i] - v);
                    }
                    self.g92_on = true;
                    self.resync();
                }
                // G52: a local offset, in the register G92 uses (as LinuxCNC): the given
                // axes' offsets are the words themselves; G92.1 or G52 X0 Y0 Z0 clears it.
                520 => {
                    if b.first_axis().is_none() {
                        return Err(missing(code.col, code, 'X', "at least one axis word"));
                    }
                    let base = self.g92();
                    for (i, letter) in ['X', 'Y', 'Z'].into_iter().enumerate() {
                        self.g92_mm[i] = self.take_mm(b, letter).unwrap_or(base[i]);
                    }
                    let base = self.aux_g92();
                    let words = self.aux_words(b)?;
                    for (i, w) in words.iter().enumerate() {
                        self.g92_aux[i] = w.unwrap_or(base[i]);
                    }
                    self.g92_on = true;
                    self.resync();
                }
                921 => {
                    self.g92_mm = Vector3::zeros();
                    self.g92_aux = [0.0; 6];
                    self.g92_on = false;
                    self.resync();
                }
                922 => {
                    self.g92_on = false;
                    self.resync();
                }
                923 => {
                    self.g92_on = true;
                    self.resync();
                }
                _ => {}
            }
        }

        if consumer.is_none() {
            self.motion(
                b,
                line,
                non_modal.filter(|c| c.tenths == 530),
                inverse_f,
                out,
            )?;
        }

        if let Some(code) = b.modal_state() {
            self.modal_state(code)?;
        }

        let call = match b.stop() {
            Some(code) if code.tenths == 980 => {
                let p = self.take(b, 'P').ok_or_else(|| {
                    missing(code.col, code, 'P', "the number of the subprogram to call")
                })?;
                let number = as_index(p.value)
                    .ok_or_else(|| invalid(p, "a program number (a non-negative integer)"))?;
                // The domain check made L a non-negative integer.
                let count = self
                    .take(b, 'L')
                    .map_or(1, |l| as_index(l.value).unwrap_or(0));
                Some(Flow::Call {
                    number,
                    count,
                    col: code.col,
                })
            }
            _ => None,
        };

        self.check_unused(b)?;

        if let Some(call) = call {
            return Ok(call);
        }
        Ok(match b.stop() {
            Some(code) if code.tenths == 0 || code.tenths == 10 => {
                let optional = code.tenths == 10;
                if optional && !self.optional_stop {
                    note(
                        out,
                        code.col,
                        "M1: optional stop skipped (the optional stop switch is off)".to_owned(),
                    );
                } else {
                    out.push_back(Item::Stop(Stop {
                        line,
                        col: code.col,
                        optional,
                    }));
                }
                Flow::Next
            }
            Some(code) if code.tenths == 20 => Flow::End(ProgramEnd::M2 { line }),
            Some(code) if code.tenths == 990 => Flow::Return { col: code.col },
            Some(_) => Flow::End(ProgramEnd::M30 { line }),
            None => Flow::Next,
        })
    }

    fn cutter_comp(&mut self, b: &Block, code: Code, scale: f64) -> Result<(), BlockError> {
        if code.tenths == 400 {
            // LinuxCNC's `convert_cutter_compensation_off`: with a radius in force, the next
            // move (whatever it is) leaves the offset path, and must be straight.
            if let CompState::Left { radius_mm, .. } | CompState::Right { radius_mm, .. } =
                self.comp
                && radius_mm != 0.0
            {
                self.ended_comp = Some(self.comp);
            }
            self.comp = CompState::Off;
            return Ok(());
        }
        if self.comp != CompState::Off {
            return Err(err_at(
                code.col,
                ErrorKind::CompensationAlreadyOn {
                    code: code.to_string(),
                },
            ));
        }
        if self.plane == Plane::Yz {
            return Err(err_at(
                code.col,
                ErrorKind::Unsupported {
                    what: format!("{code} in the YZ plane (G19)"),
                    reason: "cutter compensation works in the XY (G17) and ZX (G18) planes",
                },
            ));
        }
        // What a D word means follows LinuxCNC's `convert_cutter_compensation_on`; a negative
        // radius (from a negative G41.1/G42.1 diameter) swaps the side in the compensation
        // stage, as LinuxCNC does.
        let (tool, radius_mm) = if code.tenths == 411 || code.tenths == 421 {
            let d = self
                .take(b, 'D')
                .ok_or_else(|| missing(code.col, code, 'D', "the tool diameter"))?;
            if let Some(l) = self.take(b, 'L') {
                self.lathe_orientation(code, l)?;
            }
            (None, d.value * scale / 2.0)
        } else {
            match self.take(b, 'D') {
                Some(w) => {
                    // A whole number to within 0.0001; D0 is the tool in the spindle (pocket 0
                    // of LinuxCNC's non-random tool changer), not "no tool".
                    let rounded = w.value.round();
                    let n = as_index(rounded)
                        .filter(|n| *n <= MAX_TOOL_NUMBER && (w.value - rounded).abs() < 1e-4)
                        .ok_or_else(|| invalid(w, "a tool number from 0 to 99999"))?;
                    let n = if n == 0 { self.loaded_tool } else { n };
                    (Some(n), self.lookup_tool(n, w.col, 'D')?.radius_mm)
                }
                None => {
                    let (n, t) = self.tool_word(b, 'D', code)?;
                    (Some(n), t.radius_mm)
                }
            }
        };
        let comp = if code.tenths / 10 == 41 {
            CompState::Left { tool, radius_mm }
        } else {
            CompState::Right { tool, radius_mm }
        };
        if self.ended_comp == Some(comp) {
            // The compensation stage sees the elements' comp states only, so it would take the
            // next move as the continuation of the last run, where LinuxCNC starts a new one.
            return Err(err_at(
                code.col,
                ErrorKind::Unsupported {
                    what: format!(
                        "{code} right after G40 with the same side and radius and no move between"
                    ),
                    reason: "program a straight move between the G40 and the next G41/G42",
                },
            ));
        }
        self.comp = comp;
        Ok(())
    }

    /// The L word of G41.1/G42.1 (a lathe tool's orientation), as LinuxCNC takes it: only in
    /// the ZX plane (G18); orientations 0 and 9 put the controlled point at the nose centre,
    /// which is what the compensation stage computes; 1 to 8 move it to an imaginary tool tip,
    /// which is not supported.
    fn lathe_orientation(&self, code: Code, l: Word) -> Result<(), BlockError> {
        if self.plane != Plane::Zx {
            return Err(invalid(
                l,
                "no L outside the ZX plane: the lathe tool orientation of G41.1/G42.1 needs G18",
            ));
        }
        if (1.0..=8.0).contains(&l.value) {
            return Err(err_at(
                l.col,
                ErrorKind::Unsupported {
                    what: format!("{code} with tool orientation L{}", l.value),
                    reason: "only orientations 0 and 9 (the controlled point at the nose centre)",
                },
            ));
        }
        Ok(())
    }

    fn tool_length(&mut self, b: &Block, code: Code, scale: f64) -> Result<(), BlockError> {
        let axis = Vector3::new(0.0, 0.0, 1.0);
        match code.tenths {
            430 | 440 => {
                let (_, t) = self.tool_word(b, 'H', code)?;
                let sign = if code.tenths == 430 { 1.0 } else { -1.0 };
                self.tool_offset_mm = axis * (sign * t.length_mm);
            }
            431 | 432 => {
                let mut offset = Vector3::zeros();
                let mut any = false;
                for (i, letter) in ['X', 'Y', 'Z'].into_iter().enumerate() {
                    if let Some(w) = self.take(b, letter) {
                        offset[i] = w.value * scale;
                        any = true;
                    }
                }
                if code.tenths == 432 && !any {
                    let (_, t) = self.tool_word(b, 'H', code)?;
                    offset = axis * t.length_mm;
                    any = true;
                }
                if !any {
                    return Err(missing(code.col, code, 'Z', "the offset as axis words"));
                }
                self.tool_offset_mm = if code.tenths == 431 {
                    offset
                } else {
                    self.tool_offset_mm + offset
                };
            }
            _ => self.tool_offset_mm = Vector3::zeros(),
        }
        self.resync();
        Ok(())
    }

    fn g10(&mut self, b: &Block, code: Code, scale: f64) -> Result<(), BlockError> {
        let l = self
            .take(b, 'L')
            .ok_or_else(|| missing(code.col, code, 'L', "L1, L2, L10, L11 or L20"))?;
        let p = self
            .take(b, 'P')
            .ok_or_else(|| missing(code.col, code, 'P', "the tool or coordinate system number"))?;
        match l.value as u32 {
            1 => {
                let n = as_index(p.value)
                    .filter(|n| (1..=MAX_TOOL_NUMBER).contains(n))
                    .ok_or_else(|| invalid(p, "a tool number from 1 to 99999"))?;
                let mut tool = self.tools.get(n).unwrap_or(Tool::NONE);
                if let Some(r) = self.take(b, 'R') {
                    tool.radius_mm = tool_radius(r, scale)?;
                }
                if let Some(z) = self.take(b, 'Z') {
                    let length_mm = z.value * scale;
                    if length_mm.abs() > MAX_TOOL_SIZE_MM {
                        return Err(invalid(z, "a tool length of at most 10000 mm"));
                    }
                    tool.length_mm = length_mm;
                }
                for letter in ['X', 'Y'] {
                    if let Some(w) = b.word(letter) {
                        return Err(err_at(
                            w.col,
                            ErrorKind::Unsupported {
                                what: format!("G10 L1 with {letter}"),
                                reason: "lathe tool offsets are not supported: give R (radius) and Z (length)",
                            },
                        ));
                    }
                }
                self.tools.insert(n, tool);
            }
            2 | 20 => {
                let index = as_index(p.value)
                    .filter(|n| *n <= 9)
                    .ok_or_else(|| invalid(p, "a coordinate system number from 0 (current) to 9"))?
                    as usize;
                let index = if index == 0 { self.coord } else { index - 1 };
                if l.value as u32 == 2 {
                    for (i, letter) in ['X', 'Y', 'Z'].into_iter().enumerate() {
                        if let Some(v) = self.take(b, letter) {
                            self.work_offsets_mm[index][i] = v.value * scale;
                        }
                    }
                    if let Some(r) = self.take(b, 'R') {
                        self.rotations_deg[index] = r.value;
                    }
                } else {
                    self.g10_l20(b, index);
                }
                // The auxiliary axes: L2 sets the origin, L20 moves it so that the current
                // position reads the word (G92/G52 counted).
                let words = self.aux_words(b)?;
                let g92 = self.aux_g92();
                for (i, w) in words.iter().enumerate() {
                    if let Some(v) = *w {
                        let origin = if l.value as u32 == 2 {
                            v
                        } else {
                            self.aux[i] - g92[i] - v
                        };
                        if !(origin.is_finite() && origin.abs() <= MAX_POSITION_MM) {
                            return Err(err_at(code.col, ErrorKind::PositionOutOfRange));
                        }
                        self.work_aux[index][i] = origin;
                    }
                }
                if !self.work_offsets_mm[index]
                    .iter()
                    .all(|c| c.abs() <= MAX_POSITION_MM)
                {
                    return Err(err_at(code.col, ErrorKind::PositionOutOfRange));
                }
                if index == self.coord {
                    self.resync();
                }
            }
            // Tool touch-off (LinuxCNC): the length (and R radius) of tool P such that, with
            // its offset applied, the current point reads Z in the current work system (L10,
            // G92 included) or in G59.3 (L11, without G92). Rotation is about Z: no effect.
            10 | 11 => {
                let n = as_index(p.value)
                    .filter(|n| (1..=MAX_TOOL_NUMBER).contains(n))
                    .ok_or_else(|| invalid(p, "a tool number from 1 to 99999"))?;
                for letter in ['X', 'Y'] {
                    if let Some(w) = b.word(letter) {
                        return Err(err_at(
                            w.col,
                            ErrorKind::Unsupported {
                                what: format!("G10 L{} with {letter}", l.value),
                                reason: "lathe tool offsets are not supported: give Z (and R)",
                            },
                        ));
                    }
                }
                let mut tool = self.tools.get(n).unwrap_or(Tool::NONE);
                if let Some(z) = self.take(b, 'Z') {
                    let (origin_z, g92_z) = if l.value as u32 == 10 {
                        (self.work_offsets_mm[self.coord].z, self.g92().z)
                    } else {
                        (self.work_offsets_mm[8].z, 0.0)
                    };
                    let length_mm = self.pos_mm.z - origin_z - g92_z - z.value * scale;
                    if length_mm.abs() > MAX_TOOL_SIZE_MM {
                        return Err(invalid(
                            z,
                            "a touch-off giving a tool length of at most 10000 mm",
                        ));
                    }
                    tool.length_mm = length_mm;
                }
                if let Some(r) = self.take(b, 'R') {
                    tool.radius_mm = tool_radius(r, scale)?;
                }
                self.tools.insert(n, tool);
            }
            _ => {
                return Err(invalid(
                    l,
                    "L1, L10 or L11 (tool), L2 or L20 (coordinate system)",
                ));
            }
        }
        Ok(())
    }

    /// G10 L20: system `index`'s origin moves so that the current point reads the line's
    /// X, Y, Z there (the axes not given keep their reading), with the rotation the line
    /// leaves (R, else the system's own), G92 counted and the tool offset not, as LinuxCNC's
    /// `find_current_in_system_without_tlo`. In a rotated system a given X or Y moves the
    /// origin along both machine axes; R alone only turns the system about its origin.
    fn g10_l20(&mut self, b: &Block, index: usize) {
        let old_rotation = self.rotations_deg[index];
        let old_origin = self.work_offsets_mm[index];
        let g92 = self.g92();
        let q = self.pos_mm - self.tool_offset_mm;
        // The current point as it reads in system `index` now.
        let mut p = rotate_xy(q - old_origin, -old_rotation) - g92;
        let given = ['X', 'Y', 'Z'].map(|letter| self.take_mm(b, letter));
        let rotation = self.take(b, 'R').map_or(old_rotation, |r| r.value);
        for (i, v) in given.iter().enumerate() {
            if let Some(v) = v {
                p[i] = *v;
            }
        }
        let origin = q - rotate_xy(p + g92, rotation);
        let mut o = old_origin;
        if given[0].is_some() || given[1].is_some() {
            o.x = origin.x;
            o.y = origin.y;
        }
        if given[2].is_some() {
            o.z = origin.z;
        }
        self.work_offsets_mm[index] = o;
        self.rotations_deg[index] = rotation;
    }

    /// G28 / G30: via the axis words' point (if any), then to the stored position.
    fn home(
        &mut self,
        b: &Block,
        code: Code,
        line: usize,
        out: &mut VecDeque<Item>,
    ) -> Result<(), BlockError> {
        if self.comp != CompState::Off {
            return Err(err_at(
                code.col,
                ErrorKind::CompensationActive {
                    code: code.to_string(),
                },
            ));
        }
        let home = if code.tenths == 280 {
            self.g28_mm
        } else {
            self.g30_mm
        };
        let given: [bool; 3] = [
            b.word('X').is_some(),
            b.word('Y').is_some(),
            b.word('Z').is_some(),
        ];
        let target = if given.iter().any(|g| *g) {
            let prog = self.prog_target(b);
            let via = self.machine_of(prog);
            self.check_position(code.col, &via)?;
            self.push_line(line, code.col, true, via, None, out);
            let mut target = via;
            for i in 0..3 {
                if given[i] {
                    target[i] = home[i];
                }
            }
            target
        } else {
            home
        };
        self.push_line(line, code.col, true, target, None, out);
        self.resync();
        Ok(())
    }

    /// Emits a straight move from the current point to `end_mm` (nothing if it has no length)
    /// and makes `end_mm` the current point.
    fn push_line(
        &mut self,
        line: usize,
        col: usize,
        rapid: bool,
        end_mm: Vector3<f64>,
        feed_mm_s: Option<f64>,
        out: &mut VecDeque<Item>,
    ) {
        let aux = self.aux;
        self.push_move(line, col, rapid, (end_mm, aux), feed_mm_s, out);
    }

    /// [`push_line`](Self::push_line) with the auxiliary axes' end too.
    fn push_move(
        &mut self,
        line: usize,
        col: usize,
        rapid: bool,
        (end_mm, aux_end): (Vector3<f64>, AuxPos),
        feed_mm_s: Option<f64>,
        out: &mut VecDeque<Item>,
    ) {
        // The first straight move after G40 is kept even with no length: it is the exit move
        // that takes the tool from its offset point back to the programmed point.
        if end_mm != self.pos_mm || aux_end != self.aux || self.ended_comp.is_some() {
            out.push_back(Item::Motion(Element {
                line,
                col,
                kind: ElementKind::Line,
                rapid,
                start_mm: self.pos_mm,
                end_mm,
                aux: AuxMove {
                    start: self.aux,
                    end: aux_end,
                },
                feed_mm_s,
                blend: self.blend,
                comp: self.comp,
                plane: self.plane,
            }));
        }
        self.pos_mm = end_mm;
        self.aux = aux_end;
    }

    /// The auxiliary axes' G92/G52 offsets in force.
    fn aux_g92(&self) -> AuxPos {
        if self.g92_on { self.g92_aux } else { [0.0; 6] }
    }

    /// The auxiliary axes' offsets in force: the work system's origin plus G92/G52 (no
    /// rotation or tool offset applies to them).
    fn aux_offset(&self) -> AuxPos {
        let g92 = self.aux_g92();
        let work = self.work_aux[self.coord];
        std::array::from_fn(|i| work[i] + g92[i])
    }

    /// The values of the line's A B C U V W words (U V W in mm), for G92 and G52; an axis the
    /// machine lacks is an error.
    fn aux_words(&mut self, b: &Block) -> Result<[Option<f64>; 6], BlockError> {
        let mut out = [None; 6];
        if b.present() & AUX_BITS == 0 {
            return Ok(out);
        }
        let scale = self.scale();
        for (i, letter) in AUX_LETTERS.into_iter().enumerate() {
            if let Some(w) = self.take(b, letter) {
                if !self.aux_axes[i] {
                    return Err(err_at(w.col, ErrorKind::AxisNotConfigured { letter }));
                }
                out[i] = Some(if i >= 3 { w.value * scale } else { w.value });
            }
        }
        Ok(out)
    }

    /// The auxiliary axes' target of the line's A B C U V W words (G90/G91 applied; U V W in
    /// the program's units, A B C in degrees; a wrapped axis under G90 as
    /// [`Setup::aux_wrapped`] says).
    fn aux_target(&mut self, b: &Block) -> Result<AuxPos, BlockError> {
        self.aux_target_in(b, false)
    }

    /// [`aux_target`](Self::aux_target), in machine coordinates (G53: absolute, no offset)
    /// when `machine`.
    fn aux_target_in(&mut self, b: &Block, machine: bool) -> Result<AuxPos, BlockError> {
        let mut t = self.aux;
        if b.present() & AUX_BITS == 0 {
            return Ok(t);
        }
        let scale = self.scale();
        let off = if machine { [0.0; 6] } else { self.aux_offset() };
        let incremental = self.incremental && !machine;
        for (i, letter) in AUX_LETTERS.into_iter().enumerate() {
            let Some(w) = self.take(b, letter) else {
                continue;
            };
            if !self.aux_axes[i] {
                return Err(err_at(w.col, ErrorKind::AxisNotConfigured { letter }));
            }
            let v = if i >= 3 { w.value * scale } else { w.value };
            t[i] = if incremental {
                t[i] + v
            } else if self.aux_wrapped[i] && !machine {
                if v.abs() >= 360.0 {
                    return Err(err_at(
                        w.col,
                        ErrorKind::WrappedPositionOutOfRange {
                            letter,
                            value_deg: v,
                        },
                    ));
                }
                let current = t[i] - off[i];
                if self.aux_shortest[i] {
                    // The shortest way from where the axis reads (modulo a turn) to `v`;
                    // half a turn goes the positive way.
                    let mut d = (v - current).rem_euclid(360.0);
                    if d > 180.0 {
                        d -= 360.0;
                    }
                    t[i] + d
                } else {
                    // LinuxCNC's `unwrap_rotary`: `|v|` in the turn where the axis reads, then
                    // on round in the direction of `v`'s sign (−0 is negative) if behind it.
                    let mut r = v.abs() + (current / 360.0).floor() * 360.0;
                    if v.is_sign_negative() {
                        if r > current {
                            r -= 360.0;
                        }
                    } else if r < current {
                        r += 360.0;
                    }
                    r + off[i]
                }
            } else {
                v + off[i]
            };
            if !(t[i].is_finite() && t[i].abs() <= MAX_POSITION_MM) {
                return Err(err_at(w.col, ErrorKind::PositionOutOfRange));
            }
        }
        Ok(t)
    }

    fn motion(
        &mut self,
        b: &Block,
        line: usize,
        g53: Option<Code>,
        inverse_f: Option<f64>,
        out: &mut VecDeque<Item>,
    ) -> Result<(), BlockError> {
        let code = b.motion();
        let first_axis = b.first_axis();
        let previous = self.motion;
        if let Some(code) = code {
            self.motion = match code.tenths {
                0 => Some(Motion::Rapid),
                10 => Some(Motion::Linear),
                20 => Some(Motion::Cw),
                30 => Some(Motion::Ccw),
                50 => Some(Motion::Cubic),
                51 => Some(Motion::Quadratic),
                t => match Cycle::from_tenths(t) {
                    Some(cycle) => Some(Motion::Cycle(cycle)),
                    None => {
                        if let Some(w) = first_axis {
                            return Err(err_at(w.col, ErrorKind::AxisWithG80));
                        }
                        None
                    }
                },
            };
        }
        // Any other motion (G80 included) ends a run of canned cycles: the next one takes its
        // initial level afresh.
        if (code.is_some() || first_axis.is_some())
            && !matches!(self.motion, Some(Motion::Cycle(_)))
        {
            self.cycles.initial_mm = None;
        }
        // Only G5 right after G5 may leave I and J out.
        if self.motion != Some(Motion::Cubic) {
            self.spline_next = None;
        }
        let on_line = code.filter(|c| c.tenths != 800);
        if on_line.is_none() && first_axis.is_none() {
            if let Some(g53) = g53 {
                return Err(missing(
                    g53.col,
                    g53,
                    'X',
                    "axis words (G0 or G1 in machine coordinates)",
                ));
            }
            return Ok(());
        }
        let Some(mode) = self.motion else {
            let col = first_axis.map_or(0, |w| w.col);
            return Err(err_at(col, ErrorKind::AxisWithoutMotion));
        };
        let col = on_line.map_or_else(|| first_axis.map_or(0, |w| w.col), |c| c.col);
        let rapid = mode == Motion::Rapid;
        // The length is asked for under G93 only (a square root, or an arc's geometry, per
        // move otherwise spent for nothing).
        let feed = |state: &State,
                    length_mm: &dyn Fn() -> f64|
         -> Result<Option<f64>, BlockError> {
            if rapid {
                return Ok(None);
            }
            let name = match mode {
                Motion::Linear => "G1",
                Motion::Cw => "G2",
                _ => "G3",
            };
            if state.inverse_time {
                let f = inverse_f
                    .ok_or_else(|| err_at(col, ErrorKind::MissingInverseTimeFeed { code: name }))?;
                Ok(Some(length_mm() * f / 60.0))
            } else {
                state
                    .feed_mm_s
                    .map(Some)
                    .ok_or_else(|| err_at(col, ErrorKind::MissingFeed { code: name }))
            }
        };
        if let Some(g53) = g53 {
            if !matches!(mode, Motion::Rapid | Motion::Linear) {
                return Err(err_at(g53.col, ErrorKind::G53NeedsStraightMotion));
            }
            if self.comp != CompState::Off {
                return Err(err_at(
                    g53.col,
                    ErrorKind::CompensationActive {
                        code: g53.to_string(),
                    },
                ));
            }
            let mut m = self.pos_mm;
            for (i, letter) in ['X', 'Y', 'Z'].into_iter().enumerate() {
                if let Some(v) = self.take_mm(b, letter) {
                    m[i] = v;
                }
            }
            self.check_position(col, &m)?;
            let aux = self.aux_target_in(b, true)?;
            let f = feed(self, &|| line_length(m - self.pos_mm, &self.aux, &aux))?;
            let f = rotary_feed(self, m, &aux, f);
            self.push_move(line, col, rapid, (m, aux), f, out);
            self.ended_comp = None;
            self.resync();
            return Ok(());
        }
        match mode {
            // G0/G1 alone only sets the mode, but right after G40 it is a move to the current
            // point, as in LinuxCNC: the exit move back to the programmed point.
            Motion::Rapid | Motion::Linear if first_axis.is_none() => {
                if self.ended_comp.is_some() && on_line.is_some() {
                    let f = feed(self, &|| 0.0)?;
                    self.push_line(line, col, rapid, self.pos_mm, f, out);
                    self.ended_comp = None;
                }
            }
            Motion::Rapid | Motion::Linear => {
                let prog = self.prog_target_polar(b)?;
                let m = self.machine_of(prog);
                self.check_position(col, &m)?;
                let aux = self.aux_target(b)?;
                let f = feed(self, &|| line_length(m - self.pos_mm, &self.aux, &aux))?;
                let f = rotary_feed(self, m, &aux, f);
                self.push_move(line, col, rapid, (m, aux), f, out);
                self.prog_mm = prog;
                self.ended_comp = None;
            }
            Motion::Cubic | Motion::Quadratic => {
                self.spline(b, line, col, mode == Motion::Cubic, inverse_f, out)?;
            }
            Motion::Cycle(cycle) => {
                self.canned_cycle(b, line, col, cycle, previous != Some(mode), out)?;
            }
            Motion::Cw | Motion::Ccw => {
                if self.ended_comp.is_some() {
                    return Err(err_at(
                        col,
                        ErrorKind::CompensationEndOnArc {
                            code: if mode == Motion::Cw { "G2" } else { "G3" },
                        },
                    ));
                }
                let element = self.arc(b, line, col, mode == Motion::Cw)?;
                let mut element = element;
                element.feed_mm_s = feed(self, &|| element.length_mm())?;
                out.push_back(Item::Motion(element));
            }
        }
        Ok(())
    }

    /// Builds the arc of a G2/G3 line and moves the current point to its end.
    fn arc(&mut self, b: &Block, line: usize, col: usize, cw: bool) -> Result<Element, BlockError> {
        if let Some(w) = b.polar().into_iter().flatten().next() {
            return Err(err_at(
                w.col,
                ErrorKind::Unsupported {
                    what: format!("polar coordinate word '{}' on an arc", w.letter),
                    reason: "polar coordinates are read on G0 and G1 moves only",
                },
            ));
        }
        let (a, c, n) = self.plane.axes();
        let axis_letters = ['X', 'Y', 'Z'];
        let offset_letters = ['I', 'J', 'K'];
        // Without either plane axis word the end is the start in the plane: a full circle in
        // centre format (LinuxCNC), impossible in radius format.
        if b.word(axis_letters[a]).is_none()
            && b.word(axis_letters[c]).is_none()
            && b.word('R').is_some()
        {
            return Err(err_at(
                col,
                ErrorKind::ArcMissingPlaneAxes {
                    plane: self.plane.code(),
                    first: axis_letters[a],
                    second: axis_letters[c],
                },
            ));
        }
        if let Some(w) = b.word(offset_letters[n]) {
            return Err(err_at(
                w.col,
                ErrorKind::ArcWordWrongPlane {
                    letter: offset_letters[n],
                    plane: self.plane.code(),
                },
            ));
        }
        let start = self.prog_mm;
        let mut end = self.prog_target(b);
        let scale = self.scale();
        let ia = self.take(b, offset_letters[a]);
        let ic = self.take(b, offset_letters[c]);
        let r_word = self.take(b, 'R');
        let turns = match self.take(b, 'P') {
            Some(p) => {
                as_index(p.value)
                    .filter(|t| (1..=10_000).contains(t))
                    .ok_or_else(|| invalid(p, "a whole number of turns from 1 to 10000"))?
                    - 1
            }
            None => 0,
        };
        let chord = (end[a] - start[a]).hypot(end[c] - start[c]);
        let full = chord <= FULL_CIRCLE_EPS_MM;
        let (ca, cc) = match (r_word, ia.or(ic)) {
            (Some(_), Some(w)) => return Err(err_at(w.col, ErrorKind::ArcBothFormats)),
            (None, None) => {
                return Err(err_at(
                    col,
                    ErrorKind::ArcNoCentre {
                        plane: self.plane.code(),
                    },
                ));
            }
            (None, Some(_)) => {
                let off = |w: Option<Word>| w.map_or(0.0, |w| w.value * scale);
                let (ca, cc) = if self.arc_absolute {
                    (off(ia), off(ic))
                } else {
                    (start[a] + off(ia), start[c] + off(ic))
                };
                let r1 = (start[a] - ca).hypot(start[c] - cc);
                let r2 = (end[a] - ca).hypot(end[c] - cc);
                if r1 < MIN_ARC_RADIUS_MM || r2 < MIN_ARC_RADIUS_MM {
                    return Err(err_at(col, ErrorKind::ArcZeroRadius));
                }
                // LinuxCNC's rule (interp_arc.cc): a spiral within the absolute tolerance, or
                // within the relative one up to 100 times the absolute one; an inch program
                // has the inch tolerance (0.002828 in: 2.54 times the metric 0.02828 mm).
                let abs_mm = self.arc_tolerance_mm * if self.inch { 2.54 } else { 1.0 };
                let error_mm = (r1 - r2).abs();
                let relative_mm = abs_mm.max(self.arc_tolerance_rel * r1.max(r2));
                // The tolerance broken: the relative one if it is, else the 100-times cap.
                let tolerance_mm = if error_mm <= relative_mm && error_mm > 100.0 * abs_mm {
                    100.0 * abs_mm
                } else {
                    relative_mm
                };
                if error_mm > tolerance_mm {
                    return Err(err_at(
                        col,
                        ErrorKind::ArcRadiusMismatch {
                            start_radius_mm: r1,
                            end_radius_mm: r2,
                            tolerance_mm,
                        },
                    ));
                }
                (ca, cc)
            }
            (Some(r), None) => {
                if full {
                    return Err(err_at(r.col, ErrorKind::ArcRadiusFullCircle));
                }
                let radius = r.value * scale;
                let abs_r = radius.abs();
                let half = chord / 2.0;
                if half - abs_r > MIN_ARC_RADIUS_MM {
                    return Err(err_at(
                        r.col,
                        ErrorKind::ArcRadiusTooSmall {
                            radius_mm: abs_r,
                            half_chord_mm: half,
                        },
                    ));
                }
                let half = half.min(abs_r);
                let mid_a = (start[a] + end[a]) / 2.0;
                let mid_c = (start[c] + end[c]) / 2.0;
                let heading = (end[c] - start[c]).atan2(end[a] - start[a]);
                let theta = if cw == (radius > 0.0) {
                    heading - FRAC_PI_2
                } else {
                    heading + FRAC_PI_2
                };
                let offset = (abs_r * abs_r - half * half).max(0.0).sqrt();
                (mid_a + offset * theta.cos(), mid_c + offset * theta.sin())
            }
        };
        if full {
            end[a] = start[a];
            end[c] = start[c];
        }
        let mut center = start;
        center[a] = ca;
        center[c] = cc;
        let m_end = self.machine_of(end);
        self.check_position(col, &m_end)?;
        let aux_end = self.aux_target(b)?;
        let center_mm = self.to_machine(center);
        let mut normal = Vector3::zeros();
        normal[n] = if cw { -1.0 } else { 1.0 };
        let normal = rotate_xy(normal, self.rotation_deg());
        let radius_mm = (start[a] - ca).hypot(start[c] - cc);
        let element = Element {
            line,
            col,
            kind: ElementKind::Arc {
                center_mm,
                normal,
                cw,
                turns,
                radius_mm,
            },
            rapid: false,
            start_mm: self.pos_mm,
            end_mm: m_end,
            aux: AuxMove {
                start: self.aux,
                end: aux_end,
            },
            feed_mm_s: None,
            blend: self.blend,
            comp: self.comp,
            plane: self.plane,
        };
        if element.arc().is_none() {
            return Err(err_at(col, ErrorKind::ArcZeroRadius));
        }
        self.pos_mm = m_end;
        self.aux = aux_end;
        self.prog_mm = end;
        Ok(element)
    }

    /// Every word that needs a user must have found one.
    fn check_unused(&self, b: &Block) -> Result<(), BlockError> {
        // Every line runs this; nearly all pass.
        if b.present() & CHECKED_BITS & !self.used == 0 {
            return Ok(());
        }
        for letter in CHECKED.chars() {
            if self.used & letter_bit(letter) != 0 {
                continue;
            }
            if let Some(w) = b.word(letter) {
                let kind = match letter {
                    'X' | 'Y' | 'Z' => ErrorKind::AxisWithoutMotion,
                    'A' | 'B' | 'C' | 'U' | 'V' | 'W' => ErrorKind::Unsupported {
                        what: format!("axis word '{letter}' here"),
                        reason: "A, B, C, U, V and W are read on G0, G1, G2, G3 and G53 moves and \
                                 by G92, G52 and G10 L2/L20 only: not on G28/G30, canned cycles or \
                                 splines",
                    },
                    '@' | '^' => ErrorKind::Unsupported {
                        what: format!("polar coordinate word '{letter}' here"),
                        reason: "polar coordinates are read on G0 and G1 moves only",
                    },
                    _ => ErrorKind::UnusedWord {
                        letter,
                        users: match letter {
                            'I' | 'J' | 'K' => "an arc (G2/G3) in a plane that has this axis",
                            'R' => "an R-format arc (G2/G3), G10 or a canned cycle",
                            'P' => {
                                "G4, G10, G64, an arc (turns) or a cycle with a dwell (G74, G82, G84, G86, G89)"
                            }
                            'Q' => "G64, M61 or a peck drilling cycle (G73, G83)",
                            'D' => "G41/G42 (tool number) or G41.1/G42.1 (diameter)",
                            'H' => "G43, G43.2 or G44",
                            _ => "G10, G41.1/G42.1 or a canned cycle (repeats)",
                        },
                    },
                };
                return Err(err_at(w.col, kind));
            }
        }
        Ok(())
    }
}

/// The path length of a straight move by `xyz_mm`, the auxiliary axes going from `from` to
/// `to`: the X/Y/Z distance, else that of U/V/W, else that of A/B/C (degrees), as
/// [`Element::length_mm`].
fn line_length(xyz_mm: Vector3<f64>, from: &AuxPos, to: &AuxPos) -> f64 {
    let xyz = xyz_mm.norm();
    if xyz > 0.0 {
        xyz
    } else {
        AuxMove {
            start: *from,
            end: *to,
        }
        .length()
    }
}

/// The feed of a straight move to `end_mm` and `aux`: a rotary-only move (no X/Y/Z, U/V/W
/// motion) takes F in degrees per minute, whatever G20/G21 (LinuxCNC's canon), so the inch
/// scaling of the G94 feed is undone there. G93 feeds are times: nothing to undo.
fn rotary_feed(
    state: &State,
    end_mm: Vector3<f64>,
    aux: &AuxPos,
    feed_mm_s: Option<f64>,
) -> Option<f64> {
    let rotary_only = end_mm == state.pos_mm
        && AuxMove {
            start: state.aux,
            end: *aux,
        }
        .rotary_only();
    match feed_mm_s {
        Some(f) if rotary_only && !state.inverse_time => Some(f / state.scale()),
        other => other,
    }
}

/// Gives the items of a subroutine file's line the line and column of its call.
fn relabel(item: &mut Item, line: usize, col: usize) {
    let place = match item {
        Item::Motion(e) => (&mut e.line, &mut e.col),
        Item::Dwell(d) => (&mut d.line, &mut d.col),
        Item::Stop(s) => (&mut s.line, &mut s.col),
        Item::Note(n) => (&mut n.line, &mut n.col),
        Item::End(end) => {
            relabel_end(end, line);
            return;
        }
    };
    *place.0 = line;
    *place.1 = col;
}

fn relabel_end(end: &mut ProgramEnd, to: usize) {
    match end {
        ProgramEnd::EndOfText => {}
        ProgramEnd::M2 { line }
        | ProgramEnd::M30 { line }
        | ProgramEnd::Percent { line }
        | ProgramEnd::M99 { line } => *line = to,
    }
}

/// Deepest subroutine call nesting.
pub const MAX_CALL_DEPTH: usize = 64;

/// Most bytes of program text kept in memory for subroutine bodies and for the loop or `if`
/// being run from the main stream (the only text the interpreter keeps).
pub const MAX_STORED_BYTES: usize = 16 * 1024 * 1024;

/// Most lines run inside loops and subroutines without producing any item: a loop that never
/// moves is reported rather than run forever.
pub const MAX_IDLE_LINES: usize = 1_000_000;

/// Stored program lines: (1-based source line, text), with each line's O-word (label and
/// keyword) parsed once, for the jumps of loops and `if`s.
#[derive(Debug)]
struct Body {
    lines: Vec<(usize, String)>,
    controls: Vec<Option<(Label, Keyword)>>,
    /// The file the lines are from (the program, or a subroutine file).
    file: Rc<str>,
}

impl Body {
    fn new(lines: Vec<(usize, String)>, file: Rc<str>) -> Lines {
        let controls = lines.iter().map(|(_, t)| peek_control(t)).collect();
        Rc::new(Body {
            lines,
            controls,
            file,
        })
    }

    /// What the body counts against [`MAX_STORED_BYTES`]: its text and a fixed overhead per
    /// line and per body (so empty bodies are not free either).
    fn bytes(&self) -> usize {
        BODY_OVERHEAD + self.lines.iter().map(|(_, t)| t.len() + 16).sum::<usize>()
    }
}

type Lines = Rc<Body>;

/// Bytes counted for each stored body besides its lines.
const BODY_OVERHEAD: usize = 64;

/// A body being run from memory: a subroutine call, or a loop / `if` of the main stream.
#[derive(Debug)]
struct Frame {
    lines: Lines,
    /// Index of the next line to run.
    pc: usize,
    /// A subroutine call (an o-word call has its own parameter scope).
    sub: bool,
    /// An M98 call: the passes left, this one included (M98 L). M98 subprograms share the
    /// caller's parameters, as in LinuxCNC.
    m98_passes: Option<u32>,
    /// Where a subroutine was called from.
    call: Option<CallAt>,
    /// Remaining passes of each running `repeat`, by the index of its line.
    repeats: HashMap<usize, u64>,
}

impl Frame {
    fn new(lines: Lines, sub: bool) -> Frame {
        Frame {
            lines,
            pc: 0,
            sub,
            m98_passes: None,
            call: None,
            repeats: HashMap::new(),
        }
    }

    /// An o-word subroutine call, with its own parameter scope.
    fn scoped(&self) -> bool {
        self.sub && self.m98_passes.is_none()
    }
}

/// The line that called a subroutine.
#[derive(Debug, Clone)]
struct CallAt {
    file: Rc<str>,
    line: usize,
    col: usize,
}

/// The streaming interpreter of [`crate::gcode`]: lines in, [`Item`]s out, one line read per
/// step, with the modal state (units, distance and feed modes, plane, offsets, tool length,
/// compensation, parameters) in between; machine coordinates out.
///
/// Yields [`Item`]s in program order and ends with exactly one [`Item::End`]; after an error
/// (or the end) it yields nothing more.
pub struct Interpreter<R> {
    reader: R,
    file: String,
    start_mm: Vector3<f64>,
    state: State,
    params: Params,
    scanner: Scanner,
    /// The block of the line being run, kept from line to line (see [`Block::read_into`]).
    block: Block,
    buf: Vec<u8>,
    /// The last line ended with `\r`: a `\n` next belongs to it.
    cr_pending: bool,
    queue: VecDeque<Item>,
    /// Lines read from the reader.
    line: usize,
    /// Source line being run (for errors).
    at: usize,
    frames: Vec<Frame>,
    subs: HashMap<Label, Lines>,
    /// Numbered subprograms (`O100` ... `M99`), called by M98 only.
    m98_subs: HashMap<u32, Lines>,
    /// The program's name, shared by the bodies stored from it.
    main_file: Rc<str>,
    subroutine_path: Vec<PathBuf>,
    /// Lines read from the source but not run yet: an M98 call read ahead to find its
    /// subprogram. (Source line, text.)
    ahead: VecDeque<(usize, Vec<u8>)>,
    /// Every line read from the source, kept while M99 may restart the main program.
    record: Option<Vec<Vec<u8>>>,
    /// Index in `record` of the next line to read again after a restart.
    replay_at: usize,
    restarts_left: u32,
    /// A program number (`O1`) was seen: later ones begin M98 subprograms.
    program_number_seen: bool,
    stored_bytes: usize,
    /// The next control line was jumped to as the next branch of an `if`.
    branch_pending: bool,
    idle_lines: usize,
    block_delete: bool,
    opened: bool,
    code_seen: bool,
    done: bool,
    pending_error: Option<Error>,
    /// An MDI line ([`Interpreter::mdi`]): what needs later lines is refused.
    mdi: bool,
}

/// The name an MDI line goes by in errors and items' file (`MDI:1:7: ...`).
pub const MDI_FILE: &str = "MDI";

impl<R: BufRead> Interpreter<R> {
    /// An interpreter reading `reader` (named `file` in errors), starting from `setup`.
    ///
    /// A bad setup (a position that is not finite, a tolerance ≤ 0) is reported as the first
    /// item, an error at line 0.
    pub fn new(reader: R, file: impl Into<String>, mut setup: Setup) -> Interpreter<R> {
        let file = file.into();
        let carry = setup.carry.take();
        let pending_error = setup.validate().err().map(|kind| Error {
            file: file.clone(),
            line: 0,
            col: 0,
            kind,
            called_from: None,
        });
        let main_file: Rc<str> = Rc::from(file.as_str());
        let subroutine_path = setup.subroutine_path.clone();
        let restarts_left = setup.m99_restarts;
        let start_mm = setup.start_mm;
        let block_delete = setup.block_delete;
        let mut state = State::new(setup);
        let params = match carry {
            Some(carry) => state.resume(carry),
            None => Params::default(),
        };
        Interpreter {
            reader,
            file,
            start_mm,
            block_delete,
            state,
            params,
            scanner: Scanner::default(),
            block: Block::default(),
            buf: Vec::new(),
            cr_pending: false,
            queue: VecDeque::new(),
            line: 0,
            at: 0,
            frames: Vec::new(),
            subs: HashMap::new(),
            m98_subs: HashMap::new(),
            main_file,
            subroutine_path,
            ahead: VecDeque::new(),
            record: (restarts_left > 0).then(Vec::new),
            replay_at: 0,
            restarts_left,
            program_number_seen: false,
            stored_bytes: 0,
            branch_pending: false,
            idle_lines: 0,
            opened: false,
            code_seen: false,
            done: false,
            pending_error,
            mdi: false,
        }
    }

    /// An interpreter of MDI input (`canmotion serve`'s `mdi` command): `reader` holds one
    /// line (or a few, each a block), named [`MDI_FILE`] in errors, run from `setup` (with
    /// [`Setup::carry`] set to what the last MDI line or program left).
    ///
    /// What needs lines that MDI input does not have is refused as
    /// [`ErrorKind::Unsupported`] with its line and column: subroutine definitions (`o… sub`,
    /// `O100` subprograms), M98/M99, and cutter compensation (G41/G42/G41.1/G42.1: the
    /// compensation stage joins an offset element to the *next* one, which an MDI line
    /// never has, and cancels compensation at the end of each stream, so every MDI move
    /// would be an entry move; LinuxCNC's path would differ, so none is made). G40 is
    /// accepted. `o<name> call` of a subroutine file is accepted.
    pub fn mdi(reader: R, setup: Setup) -> Interpreter<R> {
        let mut interpreter = Interpreter::new(reader, MDI_FILE, setup);
        interpreter.mdi = true;
        interpreter
    }

    /// What this interpretation leaves for the next one on the machine, as of the line read
    /// last: after M2/M30, with their resets. Give it to the next [`Setup::carry`]. After an
    /// error the state is partway through the failing line: keep the carry the run started
    /// from ([`Program::collect`](super::Program::collect) gives none then).
    pub fn carry(&self) -> Carry {
        self.state.carry(&self.params)
    }

    /// The name given for the source.
    pub fn file(&self) -> &str {
        &self.file
    }

    /// Where the machine was at the start ([`Setup::start_mm`]).
    pub fn start_mm(&self) -> Vector3<f64> {
        self.start_mm
    }

    /// Number of lines read from the source so far.
    pub fn line(&self) -> usize {
        self.line
    }

    /// The current point in machine coordinates (after the line read last: items of that line
    /// may still be queued).
    pub fn position_mm(&self) -> Vector3<f64> {
        self.state.pos_mm
    }

    /// Whether inch units (G20) are in force after the line read last (the units the F words
    /// of that line's items were read in).
    pub fn inch(&self) -> bool {
        self.state.inch
    }

    /// Whether lathe diameter mode (G7: X words are diameters) is in force after the line
    /// read last, rather than G8.
    pub fn diameter_mode(&self) -> bool {
        self.state.diameter_mode
    }

    /// Whether inverse-time feed (G93) is in force after the line read last.
    pub fn inverse_time(&self) -> bool {
        self.state.inverse_time
    }

    /// Whether the line read last is in a subroutine file (its items carry the line and
    /// column of the call in the program).
    pub fn in_subroutine_file(&self) -> bool {
        self.file_call().is_some()
    }

    /// The interpreter's tool table, with the G10 L1 changes made so far.
    pub fn tools(&self) -> &ToolTable {
        &self.state.tools
    }

    /// An error at column `col` of the line being run, in the file it is from; inside a
    /// subroutine file, with the calls that led there.
    fn error(&self, col: usize, kind: ErrorKind) -> Error {
        let file = self
            .frames
            .last()
            .map_or(&self.main_file, |f| &f.lines.file);
        let called_from = (**file != *self.main_file).then(|| {
            Box::new(CallChain(
                self.frames
                    .iter()
                    .rev()
                    .filter_map(|f| f.call.as_ref())
                    .map(|c| CallSite {
                        file: c.file.to_string(),
                        line: c.line,
                    })
                    .collect(),
            ))
        });
        Error {
            file: file.to_string(),
            line: self.at,
            col,
            kind,
            called_from,
        }
    }

    /// The call, in the program itself, of the outermost subroutine file being run: the items
    /// of a subroutine file's lines carry that call's line and column, so that everything
    /// downstream (planner messages, the feed optimiser, the resume point) refers to lines of
    /// the program.
    fn file_call(&self) -> Option<&CallAt> {
        self.frames
            .iter()
            .find(|f| *f.lines.file != *self.main_file)
            .and_then(|f| f.call.as_ref())
    }

    /// Reads one line into `buf` (terminator stripped); `false` at the end of the input.
    ///
    /// A line ends at `\n`, `\r` or `\r\n`, as in LinuxCNC: a program saved with CR-only
    /// endings must not merge its lines into one (a retract and a traverse would become one
    /// diagonal move through the part). The `\n` of a `\r\n` may come in a later read than its
    /// `\r`; `cr_pending` carries that over, so each ending counts once.
    fn read_raw_line(&mut self) -> Result<bool, Error> {
        self.buf.clear();
        let mut read_any = false;
        loop {
            let available = match self.reader.fill_buf() {
                Ok(b) => b,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
                Err(e) => {
                    return Err(Error {
                        file: self.file.clone(),
                        line: 0,
                        col: 0,
                        kind: ErrorKind::Read {
                            lines_read: self.line,
                            message: e.to_string(),
                        },
                        called_from: None,
                    });
                }
            };
            if available.is_empty() {
                self.cr_pending = false;
                break;
            }
            if std::mem::take(&mut self.cr_pending) && available[0] == b'\n' {
                self.reader.consume(1);
                continue;
            }
            read_any = true;
            let end = available.iter().position(|b| *b == b'\n' || *b == b'\r');
            let take = end.unwrap_or(available.len());
            // Keep at most one byte past the bound: enough to tell an overlong line.
            let room = (MAX_LINE_BYTES + 1).saturating_sub(self.buf.len());
            self.buf.extend_from_slice(&available[..take.min(room)]);
            match end {
                Some(i) => {
                    self.cr_pending = available[i] == b'\r';
                    self.reader.consume(i + 1);
                    break;
                }
                None => {
                    let n = available.len();
                    self.reader.consume(n);
                    if self.buf.len() > MAX_LINE_BYTES {
                        break;
                    }
                }
            }
        }
        if !read_any {
            return Ok(false);
        }
        self.line += 1;
        self.at = self.line;
        if self.buf.len() > MAX_LINE_BYTES {
            return Err(self.error(
                1,
                ErrorKind::LineTooLong {
                    max_bytes: MAX_LINE_BYTES,
                },
            ));
        }
        Ok(true)
    }

    /// Reads the next line of the main program into `buf`: one read ahead before, else the
    /// next line of the source. `at` is its line.
    fn read_line(&mut self) -> Result<bool, Error> {
        if let Some((line, bytes)) = self.ahead.pop_front() {
            self.stored_bytes = self.stored_bytes.saturating_sub(bytes.len() + 16);
            self.buf = bytes;
            self.at = line;
            return Ok(true);
        }
        self.pull_line()
    }

    /// The next line of the source into `buf`: again from the record after an M99 restart,
    /// else from the reader (recorded while a restart may come).
    fn pull_line(&mut self) -> Result<bool, Error> {
        if let Some(bytes) = self.record.as_ref().and_then(|r| r.get(self.replay_at)) {
            self.buf.clear();
            self.buf.extend_from_slice(bytes);
            self.replay_at += 1;
            self.line += 1;
            self.at = self.line;
            return Ok(true);
        }
        if !self.read_raw_line()? {
            return Ok(false);
        }
        if self.record.is_some() {
            self.stored_bytes += self.buf.len() + 16;
            if self.stored_bytes > MAX_STORED_BYTES {
                return Err(self.error(
                    1,
                    ErrorKind::StoredTooLarge {
                        max_bytes: MAX_STORED_BYTES,
                    },
                ));
            }
        }
        if let Some(record) = &mut self.record {
            record.push(self.buf.clone());
            self.replay_at = record.len();
        }
        Ok(true)
    }

    /// The text of the line in `buf`.
    fn buf_text(&self) -> String {
        String::from_utf8_lossy(&self.buf).into_owned()
    }

    /// Reads and runs one line (from the innermost frame, or the reader), queueing its items.
    fn step(&mut self) -> Result<(), Error> {
        if let Some(frame) = self.frames.last_mut() {
            if let Some((line, text)) = frame.lines.lines.get(frame.pc).cloned() {
                frame.pc += 1;
                self.idle_lines += 1;
                if self.idle_lines > MAX_IDLE_LINES {
                    self.at = line;
                    return Err(self.error(
                        0,
                        ErrorKind::NoProgress {
                            lines: MAX_IDLE_LINES,
                        },
                    ));
                }
                return self.run_line(line, &text, true);
            }
            // The end of a body: a subroutine returns, a loop of the main stream is done (and
            // its lines are let go).
            if let Some(frame) = self.frames.last_mut()
                && let Some(passes) = frame.m98_passes
                && passes > 1
            {
                frame.m98_passes = Some(passes - 1);
                frame.pc = 0;
                return Ok(());
            }
            if let Some(f) = self.frames.pop() {
                if f.scoped() {
                    self.params.pop_scope();
                } else if !f.sub {
                    self.stored_bytes = self.stored_bytes.saturating_sub(f.lines.bytes());
                }
                if f.sub {
                    self.leave_call(f.call)?;
                }
            }
            return Ok(());
        }
        if !self.read_line()? {
            self.queue.push_back(Item::End(ProgramEnd::EndOfText));
            self.done = true;
            return Ok(());
        }
        // The line is run from its read buffer, not copied: whatever `run_line` reads next
        // (a loop's lines, an M98 read ahead) comes into a new one.
        let buf = std::mem::take(&mut self.buf);
        let run = match std::str::from_utf8(&buf) {
            Ok(text) => self.run_line(self.at, text, false),
            Err(_) => {
                let text = String::from_utf8_lossy(&buf).into_owned();
                self.run_line(self.at, &text, false)
            }
        };
        if self.buf.capacity() == 0 {
            // Nothing else was read: the allocation serves the next line.
            self.buf = buf;
        }
        run
    }

    fn run_line(&mut self, line: usize, text: &str, in_frame: bool) -> Result<(), Error> {
        self.at = line;
        if text.contains('#') {
            self.state.line_number = line as f64;
            self.state.system_parameters(&mut self.params);
        }
        let kind = self
            .scanner
            .scan(text, self.block_delete, &self.params)
            .map_err(|(col, k)| self.error(col, k))?;
        if let Some((col, text)) = self.scanner.message.take() {
            self.queue.push_back(Item::Note(Note {
                line,
                col,
                text: format!("message: {text}"),
            }));
        }
        let pending = std::mem::take(&mut self.branch_pending);
        match kind {
            LineKind::Blank | LineKind::Skipped => {}
            LineKind::ProgramNumber => {
                let label = self.scanner.program.take();
                match label {
                    // The program's own number comes first; a later one begins a numbered
                    // subprogram, which runs only when M98 calls it.
                    Some(Label::Number(number)) if self.code_seen || self.program_number_seen => {
                        self.define_m98(number, in_frame)?;
                    }
                    _ => self.program_number_seen = true,
                }
            }
            LineKind::Percent => {
                if in_frame {
                    return Err(self.error(1, ErrorKind::MisplacedPercent));
                }
                if !self.opened && !self.code_seen {
                    self.opened = true;
                } else {
                    self.queue
                        .push_back(Item::End(ProgramEnd::Percent { line }));
                    self.done = true;
                }
            }
            LineKind::Words => {
                self.code_seen = true;
                let mut flow = Flow::Next;
                if !self.scanner.words.is_empty() {
                    self.block
                        .read_into(&self.scanner.words)
                        .map_err(|(col, k)| self.error(col, k))?;
                    if self.mdi && !in_frame {
                        self.check_mdi(&self.block)?;
                    }
                    let first_item = self.queue.len();
                    flow = self
                        .state
                        .execute(&self.block, line, &mut self.queue)
                        .map_err(|(col, k)| self.error(col, k))?;
                    if let Some(call) = self.file_call() {
                        let (line, col) = (call.line, call.col);
                        for item in self.queue.iter_mut().skip(first_item) {
                            relabel(item, line, col);
                        }
                        if let Flow::End(end) = &mut flow {
                            relabel_end(end, line);
                        }
                    }
                }
                let col = self.scanner.words.first().map_or(1, |w| w.col);
                for (r, value) in std::mem::take(&mut self.scanner.assignments) {
                    self.params.set(&r, value).map_err(|k| self.error(col, k))?;
                }
                match flow {
                    Flow::Next => {}
                    Flow::End(end) => {
                        if matches!(end, ProgramEnd::M2 { .. } | ProgramEnd::M30 { .. }) {
                            self.state.program_end();
                        }
                        self.queue.push_back(Item::End(end));
                        self.done = true;
                    }
                    Flow::Call { number, count, col } => self.call_m98(number, count, col)?,
                    Flow::Return { col } => self.m99(line, col)?,
                }
            }
            LineKind::Control => {
                self.code_seen = true;
                if let Some(control) = self.scanner.control.take() {
                    self.control(control, line, text, in_frame, pending)?;
                }
            }
        }
        Ok(())
    }

    /// Refuses in MDI input what needs lines it does not have (see [`Interpreter::mdi`]);
    /// lines of a subroutine file called from MDI run as in a program.
    fn check_mdi(&self, b: &Block) -> Result<(), Error> {
        if let Some(code) = b.comp().filter(|c| c.tenths != 400) {
            return Err(self.error(
                code.col,
                ErrorKind::Unsupported {
                    what: format!("cutter compensation in MDI ({code})"),
                    reason: "compensation joins each move to the next one, which an MDI line does not have: run it in a program",
                },
            ));
        }
        if let Some(code) = b.stop().filter(|c| matches!(c.tenths, 980 | 990)) {
            return Err(self.error(
                code.col,
                ErrorKind::Unsupported {
                    what: format!("{code} in MDI"),
                    reason: "numbered subprograms live in a program file: run it as a program",
                },
            ));
        }
        Ok(())
    }

    /// Keeps `text` of stored lines within [`MAX_STORED_BYTES`].
    fn store(
        &mut self,
        lines: &mut Vec<(usize, String)>,
        line: usize,
        text: String,
        col: usize,
    ) -> Result<(), Error> {
        self.stored_bytes += text.len() + 16;
        if self.stored_bytes > MAX_STORED_BYTES {
            return Err(self.error(
                col,
                ErrorKind::StoredTooLarge {
                    max_bytes: MAX_STORED_BYTES,
                },
            ));
        }
        lines.push((line, text));
        Ok(())
    }

    /// Reads lines from the reader up to and including the line `label end`.
    fn capture(
        &mut self,
        label: &Label,
        end: Keyword,
        col: usize,
        lines: &mut Vec<(usize, String)>,
    ) -> Result<(), Error> {
        let start = self.at;
        loop {
            if !self.read_line()? {
                self.at = start;
                return Err(self.error(
                    col,
                    ErrorKind::UnclosedControl {
                        label: label.to_string(),
                        end: end.name(),
                    },
                ));
            }
            let text = self.buf_text();
            let found = peek_control(&text).is_some_and(|(l, k)| l == *label && k == end);
            self.store(lines, self.at, text, col)?;
            if found {
                self.at = start;
                return Ok(());
            }
        }
    }

    /// Index in the innermost frame of the first line at or after `from` (forward) or before
    /// `from` (backward) with `label` and one of `keywords`.
    fn find_control(
        &self,
        label: &Label,
        keywords: &[Keyword],
        from: usize,
        forward: bool,
    ) -> Option<(usize, Keyword)> {
        let frame = self.frames.last()?;
        let controls = &frame.lines.controls;
        let matches = |i: usize| match controls.get(i) {
            Some(Some((l, k))) if l == label && keywords.contains(k) => Some((i, *k)),
            _ => None,
        };
        if forward {
            (from..controls.len()).find_map(matches)
        } else {
            (0..from.min(controls.len())).rev().find_map(matches)
        }
    }

    fn jump(&mut self, to: usize) {
        if let Some(frame) = self.frames.last_mut() {
            frame.pc = to;
        }
    }

    fn mismatch(&self, c: &Control, expected: &'static str) -> Error {
        self.error(
            c.col,
            ErrorKind::ControlMismatch {
                what: format!("{} {}", c.label, c.keyword.name()),
                expected,
            },
        )
    }

    /// A subroutine called from `call` returned: the modal state M73 saved in it comes back
    /// (a note on the call's line, in the program).
    fn leave_call(&mut self, call: Option<CallAt>) -> Result<(), Error> {
        let line = match self.file_call() {
            Some(outer) => outer.line,
            None => call.map_or(self.at, |c| c.line),
        };
        self.state
            .leave_call(line, &mut self.queue)
            .map_err(|(col, k)| self.error(col, k))
    }

    /// The line being run as a call site.
    fn call_here(&self, line: usize, col: usize) -> CallAt {
        let file = self
            .frames
            .last()
            .map_or(&self.main_file, |f| &f.lines.file)
            .clone();
        CallAt { file, line, col }
    }

    /// Finds `name.ngc` (`123.ngc` for `o123`) in the first folder of the subroutine path that
    /// has it, and stores the subroutine it defines (the lines between its `sub` and `endsub`;
    /// the rest of the file is not run). Errors are at the calling line.
    fn load_sub_file(&mut self, label: &Label, col: usize) -> Result<Lines, Error> {
        let name = match label {
            Label::Name(name) => name.clone(),
            Label::Number(n) => n.to_string(),
        };
        if !name
            .chars()
            .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '-' || c == '_')
        {
            return Err(self.error(
                col,
                ErrorKind::SubroutineName {
                    label: label.to_string(),
                },
            ));
        }
        let file_name = format!("{name}.ngc");
        let Some(path) = self
            .subroutine_path
            .iter()
            .map(|dir| dir.join(&file_name))
            .find(|p| p.is_file())
        else {
            return Err(self.error(
                col,
                ErrorKind::UndefinedSubroutine {
                    label: label.to_string(),
                    file_name,
                    searched: self
                        .subroutine_path
                        .iter()
                        .map(|d| d.display().to_string())
                        .collect(),
                },
            ));
        };
        let shown = path.display().to_string();
        let room = MAX_STORED_BYTES.saturating_sub(self.stored_bytes) as u64;
        let bytes = crate::files::read_bounded(&path, room).map_err(|e| {
            self.error(
                col,
                ErrorKind::SubroutineFile {
                    path: shown.clone(),
                    message: e.to_string(),
                },
            )
        })?;
        let lines: Vec<(usize, String)> = super::split_lines_inclusive(&bytes)
            .map(|l| {
                let end = l
                    .iter()
                    .rposition(|b| *b != b'\n' && *b != b'\r')
                    .map_or(0, |i| i + 1);
                String::from_utf8_lossy(&l[..end]).into_owned()
            })
            .enumerate()
            .map(|(i, t)| (i + 1, t))
            .collect();
        let is =
            |t: &str, k: Keyword| peek_control(t).is_some_and(|(l, kw)| l == *label && kw == k);
        let start = lines.iter().position(|(_, t)| is(t, Keyword::Sub));
        let end = start.and_then(|s| {
            lines
                .iter()
                .skip(s + 1)
                .position(|(_, t)| is(t, Keyword::EndSub))
                .map(|k| s + 1 + k)
        });
        let (Some(start), Some(end)) = (start, end) else {
            return Err(self.error(
                col,
                ErrorKind::SubroutineFileWithoutSub {
                    path: shown,
                    label: label.to_string(),
                },
            ));
        };
        let body: Vec<(usize, String)> = lines[start + 1..end].to_vec();
        let body = Body::new(body, Rc::from(shown.as_str()));
        self.stored_bytes += body.bytes();
        if self.stored_bytes > MAX_STORED_BYTES {
            return Err(self.error(
                col,
                ErrorKind::StoredTooLarge {
                    max_bytes: MAX_STORED_BYTES,
                },
            ));
        }
        self.subs.insert(label.clone(), body.clone());
        Ok(body)
    }

    /// `O<number>` after the program started: stores the lines up to and including the next
    /// line with M99 as subprogram `number` and goes on after them.
    fn define_m98(&mut self, number: u32, in_frame: bool) -> Result<(), Error> {
        if self.mdi && !in_frame {
            return Err(self.error(
                1,
                ErrorKind::Unsupported {
                    what: "subprogram definitions in MDI".to_owned(),
                    reason: "numbered subprograms live in a program file: run it as a program",
                },
            ));
        }
        let label = Label::Number(number);
        let mut body = Vec::new();
        let file;
        if in_frame {
            let here = self.frames.last().map_or(0, |f| f.pc.saturating_sub(1));
            let Some(frame) = self.frames.last() else {
                return Ok(());
            };
            let end = frame
                .lines
                .lines
                .iter()
                .skip(here + 1)
                .position(|(_, t)| has_m99(t))
                .map(|k| here + 1 + k)
                .ok_or_else(|| {
                    self.error(
                        1,
                        ErrorKind::UnclosedControl {
                            label: label.to_string(),
                            end: "M99",
                        },
                    )
                })?;
            body = frame.lines.lines[here + 1..=end].to_vec();
            file = frame.lines.file.clone();
            self.stored_bytes += body.iter().map(|(_, t)| t.len() + 16).sum::<usize>();
            self.jump(end + 1);
        } else {
            let start = self.at;
            loop {
                if !self.read_line()? {
                    self.at = start;
                    return Err(self.error(
                        1,
                        ErrorKind::UnclosedControl {
                            label: label.to_string(),
                            end: "M99",
                        },
                    ));
                }
                let text = self.buf_text();
                let done = has_m99(&text);
                self.store(&mut body, self.at, text, 1)?;
                if done {
                    break;
                }
            }
            self.at = start;
            file = self.main_file.clone();
        }
        self.stored_bytes += BODY_OVERHEAD;
        if self.stored_bytes > MAX_STORED_BYTES {
            return Err(self.error(
                1,
                ErrorKind::StoredTooLarge {
                    max_bytes: MAX_STORED_BYTES,
                },
            ));
        }
        if let Some(old) = self.m98_subs.insert(number, Body::new(body, file)) {
            self.stored_bytes = self.stored_bytes.saturating_sub(old.bytes());
        }
        Ok(())
    }

    /// M98 P`number` L`count`: runs the subprogram `count` times. One not defined yet is
    /// looked for further on in the program (LinuxCNC: it follows the call), reading ahead;
    /// the lines read on the way run afterwards, as the program goes on.
    fn call_m98(&mut self, number: u32, count: u32, col: usize) -> Result<(), Error> {
        if count == 0 {
            return Ok(());
        }
        let body = match self.m98_subs.get(&number) {
            Some(body) => body.clone(),
            None => self.find_m98(number, col)?,
        };
        if self.frames.iter().filter(|f| f.sub).count() >= MAX_CALL_DEPTH {
            return Err(self.error(
                col,
                ErrorKind::CallTooDeep {
                    max: MAX_CALL_DEPTH,
                },
            ));
        }
        self.state.enter_call();
        let mut frame = Frame::new(body, true);
        frame.m98_passes = Some(count);
        frame.call = Some(self.call_here(self.at, col));
        self.frames.push(frame);
        Ok(())
    }

    /// Reads ahead (keeping the lines in `ahead`) to the subprogram `O<number>` ... `M99` and
    /// stores it.
    fn find_m98(&mut self, number: u32, col: usize) -> Result<Lines, Error> {
        let at = self.at;
        let mut start: Option<usize> = None;
        let mut i = 0;
        loop {
            while let Some((_, bytes)) = self.ahead.get(i) {
                let text = String::from_utf8_lossy(bytes);
                match start {
                    None if peek_program_number(&text) == Some(Label::Number(number)) => {
                        start = Some(i);
                    }
                    Some(s) if has_m99(&text) => {
                        let lines: Vec<(usize, String)> = self
                            .ahead
                            .drain(s..=i)
                            .map(|(n, b)| (n, String::from_utf8_lossy(&b).into_owned()))
                            .collect();
                        // The O line is not part of the body; the lines stay counted, as
                        // the body's.
                        let body: Vec<(usize, String)> = lines.into_iter().skip(1).collect();
                        let body = Body::new(body, self.main_file.clone());
                        self.stored_bytes += BODY_OVERHEAD;
                        self.m98_subs.insert(number, body.clone());
                        self.at = at;
                        return Ok(body);
                    }
                    _ => {}
                }
                i += 1;
            }
            let more = self.pull_line().inspect_err(|_| self.at = at)?;
            let line = self.at;
            self.at = at;
            if !more {
                return Err(self.error(col, ErrorKind::SubprogramNotFound { number }));
            }
            self.stored_bytes += self.buf.len() + 16;
            if self.stored_bytes > MAX_STORED_BYTES {
                return Err(self.error(
                    col,
                    ErrorKind::StoredTooLarge {
                        max_bytes: MAX_STORED_BYTES,
                    },
                ));
            }
            let bytes = std::mem::take(&mut self.buf);
            self.ahead.push_back((line, bytes));
        }
    }

    /// M99: the end of an M98 subprogram's pass; in the main program, a restart (within
    /// [`Setup::m99_restarts`]) or the end.
    fn m99(&mut self, line: usize, col: usize) -> Result<(), Error> {
        match self.frames.iter().rposition(|f| f.sub) {
            Some(i) if self.frames[i].m98_passes.is_some() => {
                self.frames.truncate(i + 1);
                if let Some(frame) = self.frames.last_mut() {
                    // The end of the body passes or pops it.
                    frame.pc = frame.lines.lines.len();
                }
                Ok(())
            }
            Some(_) => Err(self.error(
                col,
                ErrorKind::ControlMismatch {
                    what: "M99".to_owned(),
                    expected: "to end an M98 subprogram (an o-word subroutine ends with endsub)",
                },
            )),
            None if self.restarts_left > 0 && self.record.is_some() => {
                self.restarts_left -= 1;
                for f in std::mem::take(&mut self.frames) {
                    self.stored_bytes = self.stored_bytes.saturating_sub(f.lines.bytes());
                }
                for (_, bytes) in std::mem::take(&mut self.ahead) {
                    self.stored_bytes = self.stored_bytes.saturating_sub(bytes.len() + 16);
                }
                self.replay_at = 0;
                self.line = 0;
                self.opened = false;
                self.code_seen = false;
                self.program_number_seen = false;
                self.queue.push_back(Item::Note(Note {
                    line,
                    col,
                    text: format!(
                        "M99: the program restarts from its first line ({} restart(s) left)",
                        self.restarts_left
                    ),
                }));
                Ok(())
            }
            None => {
                self.queue.push_back(Item::End(ProgramEnd::M99 { line }));
                self.done = true;
                Ok(())
            }
        }
    }

    /// Runs an O-word control line.
    fn control(
        &mut self,
        c: Control,
        line: usize,
        text: &str,
        in_frame: bool,
        branch: bool,
    ) -> Result<(), Error> {
        use Keyword::*;
        let value = c.values.first().copied().unwrap_or(0.0);
        // Index of this line in the innermost frame.
        let here = self.frames.last().map_or(0, |f| f.pc.saturating_sub(1));
        match c.keyword {
            Sub if self.mdi && !in_frame => {
                return Err(self.error(
                    c.col,
                    ErrorKind::Unsupported {
                        what: "subroutine definitions in MDI".to_owned(),
                        reason: "define the subroutine in a file on the subroutine_path, or run it as a program",
                    },
                ));
            }
            Sub => {
                let mut body = Vec::new();
                let mut file = self.main_file.clone();
                if in_frame {
                    let end = self
                        .find_control(&c.label, &[EndSub], here + 1, true)
                        .ok_or_else(|| self.mismatch(&c, "its endsub in the same body"))?
                        .0;
                    if let Some(frame) = self.frames.last() {
                        body = frame
                            .lines
                            .lines
                            .get(here + 1..end)
                            .unwrap_or_default()
                            .to_vec();
                        file = frame.lines.file.clone();
                    }
                    let bytes: usize = body.iter().map(|(_, t)| t.len() + 16).sum();
                    self.stored_bytes += bytes + BODY_OVERHEAD;
                    if self.stored_bytes > MAX_STORED_BYTES {
                        return Err(self.error(
                            c.col,
                            ErrorKind::StoredTooLarge {
                                max_bytes: MAX_STORED_BYTES,
                            },
                        ));
                    }
                    self.jump(end + 1);
                } else {
                    self.capture(&c.label, EndSub, c.col, &mut body)?;
                    if let Some((_, end)) = body.pop() {
                        // The endsub line is not kept; the body's overhead is.
                        self.stored_bytes =
                            (self.stored_bytes + BODY_OVERHEAD).saturating_sub(end.len() + 16);
                    }
                }
                // A redefinition frees what the old body held.
                if let Some(old) = self.subs.insert(c.label, Body::new(body, file)) {
                    self.stored_bytes = self.stored_bytes.saturating_sub(old.bytes());
                }
            }
            Call => {
                let body = match self.subs.get(&c.label) {
                    Some(body) => body.clone(),
                    None => self.load_sub_file(&c.label, c.col)?,
                };
                if self.frames.iter().filter(|f| f.sub).count() >= MAX_CALL_DEPTH {
                    return Err(self.error(
                        c.col,
                        ErrorKind::CallTooDeep {
                            max: MAX_CALL_DEPTH,
                        },
                    ));
                }
                self.params.push_scope(&c.values);
                self.state.enter_call();
                let mut frame = Frame::new(body, true);
                frame.call = Some(self.call_here(line, c.col));
                self.frames.push(frame);
            }
            Return | EndSub => {
                match self.frames.iter().rev().find(|f| f.sub) {
                    None => return Err(self.mismatch(&c, "to be inside a subroutine")),
                    Some(f) if !f.scoped() => {
                        return Err(self.mismatch(
                            &c,
                            "to be inside an o-word subroutine (an M98 subprogram ends with M99)",
                        ));
                    }
                    Some(_) => {}
                }
                let mut call = None;
                while let Some(f) = self.frames.pop() {
                    if f.sub {
                        self.params.pop_scope();
                        call = f.call;
                        break;
                    }
                }
                self.leave_call(call)?;
                self.params.set_returned(c.values.first().copied());
            }
            If | While | Do | Repeat if !in_frame => {
                // Run the whole structure from memory, this line first.
                let end = match c.keyword {
                    If => EndIf,
                    While => EndWhile,
                    Do => While,
                    _ => EndRepeat,
                };
                let mut lines = Vec::new();
                self.store(&mut lines, line, text.to_owned(), c.col)?;
                self.capture(&c.label, end, c.col, &mut lines)?;
                self.stored_bytes += BODY_OVERHEAD;
                self.frames
                    .push(Frame::new(Body::new(lines, self.main_file.clone()), false));
            }
            _ if !in_frame => return Err(self.mismatch(&c, "to follow its opening line")),
            If => {
                if value == 0.0 {
                    self.next_branch(&c, here + 1)?;
                }
            }
            ElseIf if branch => {
                if value == 0.0 {
                    self.next_branch(&c, here + 1)?;
                }
            }
            // Reached after running the previous branch: the if is done.
            ElseIf | Else => {
                let end = self
                    .find_control(&c.label, &[EndIf], here + 1, true)
                    .ok_or_else(|| self.mismatch(&c, "an endif after it"))?
                    .0;
                self.jump(end + 1);
            }
            EndIf | Do => {}
            While => {
                let opener = self.find_control(&c.label, &[Do, While, EndWhile], here, false);
                if let Some((do_at, Do)) = opener {
                    // The end of a do loop.
                    if value != 0.0 {
                        self.jump(do_at + 1);
                    }
                } else if value == 0.0 {
                    let end = self
                        .find_control(&c.label, &[EndWhile], here + 1, true)
                        .ok_or_else(|| self.mismatch(&c, "an endwhile after it"))?
                        .0;
                    self.jump(end + 1);
                }
            }
            EndWhile => {
                let start = self
                    .find_control(&c.label, &[While], here, false)
                    .ok_or_else(|| self.mismatch(&c, "a while before it"))?
                    .0;
                self.jump(start);
            }
            Repeat => {
                if !(0.0..=1e12).contains(&value) {
                    return Err(self.error(c.col, ErrorKind::RepeatCount { value }));
                }
                let count = value.round() as u64;
                if count == 0 {
                    let end = self
                        .find_control(&c.label, &[EndRepeat], here + 1, true)
                        .ok_or_else(|| self.mismatch(&c, "an endrepeat after it"))?
                        .0;
                    self.jump(end + 1);
                } else if let Some(frame) = self.frames.last_mut() {
                    frame.repeats.insert(here, count);
                }
            }
            EndRepeat => {
                let start = self
                    .find_control(&c.label, &[Repeat], here, false)
                    .ok_or_else(|| self.mismatch(&c, "a repeat before it"))?
                    .0;
                if let Some(frame) = self.frames.last_mut() {
                    let left = frame
                        .repeats
                        .get(&start)
                        .copied()
                        .unwrap_or(1)
                        .saturating_sub(1);
                    if left > 0 {
                        frame.repeats.insert(start, left);
                        frame.pc = start + 1;
                    } else {
                        frame.repeats.remove(&start);
                    }
                }
            }
            Break => {
                let end = self
                    .find_control(&c.label, &[EndWhile, EndRepeat, While], here + 1, true)
                    .ok_or_else(|| self.mismatch(&c, "the end of its loop after it"))?
                    .0;
                self.jump(end + 1);
            }
            Continue => {
                let (start, kind) = self
                    .find_control(&c.label, &[While, Do, Repeat], here, false)
                    .ok_or_else(|| self.mismatch(&c, "the start of its loop before it"))?;
                let to = match kind {
                    While => Some(start),
                    Do => self
                        .find_control(&c.label, &[While], here + 1, true)
                        .map(|(i, _)| i),
                    _ => self
                        .find_control(&c.label, &[EndRepeat], here + 1, true)
                        .map(|(i, _)| i),
                }
                .ok_or_else(|| self.mismatch(&c, "the end of its loop after it"))?;
                self.jump(to);
            }
        }
        Ok(())
    }

    /// After a false `if`/`elseif` at `from - 1`: goes to the next `elseif` (to test it), past
    /// the `else`, or past the `endif`.
    fn next_branch(&mut self, c: &Control, from: usize) -> Result<(), Error> {
        let (at, kind) = self
            .find_control(
                &c.label,
                &[Keyword::ElseIf, Keyword::Else, Keyword::EndIf],
                from,
                true,
            )
            .ok_or_else(|| self.mismatch(c, "an endif after it"))?;
        match kind {
            Keyword::ElseIf => {
                self.branch_pending = true;
                self.jump(at);
            }
            _ => self.jump(at + 1),
        }
        Ok(())
    }
}

impl<R: BufRead> Iterator for Interpreter<R> {
    type Item = Result<Item, Error>;

    fn next(&mut self) -> Option<Self::Item> {
        if let Some(e) = self.pending_error.take() {
            self.done = true;
            return Some(Err(e));
        }
        loop {
            if let Some(item) = self.queue.pop_front() {
                self.idle_lines = 0;
                return Some(Ok(item));
            }
            if self.done {
                return None;
            }
            if let Err(e) = self.step() {
                self.done = true;
                self.queue.clear();
                return Some(Err(e));
            }
        }
    }
}

impl<R: BufRead> std::iter::FusedIterator for Interpreter<R> {}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_checked_bits_are_the_checked_letters() {
        let bits = CHECKED.chars().fold(0, |m, c| m | letter_bit(c));
        assert_eq!(bits, CHECKED_BITS);
        assert!(CHECKED.chars().all(|c| letter_bit(c) != 0));
    }
}
