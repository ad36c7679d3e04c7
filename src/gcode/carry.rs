//! The interpreter state that lives on from one interpretation to the next on the same machine:
//! MDI lines and queued programs of `canmotion serve` share one state, as LinuxCNC's
//! interpreter does across MDI and auto runs.
//!
//! A child of `interpreter` (it reads and writes `State`'s private fields).

use std::fmt::Write as _;

use nalgebra::Vector3;

use super::cycles::{CycleState, Spindle};
use super::{BlendMode, Motion, Plane, Saved, State, ToolTable};
use crate::gcode::MM_PER_INCH;
use crate::gcode::element::CompState;
use crate::gcode::expr::Params;

/// What one interpretation leaves for the next on the same machine (set
/// [`Setup::carry`](super::Setup::carry) to it; [`Program::carry`](crate::gcode::Program::carry)
/// and [`Interpreter::carry`](super::Interpreter::carry) give it).
///
/// It holds the whole modal state but the position (the next interpretation starts where the
/// machine is, [`Setup::start_mm`](super::Setup::start_mm)): units, distance modes (G90/G91,
/// G90.1/G91.1), plane, feed mode and F, motion mode, path control, retract mode, lathe mode,
/// active work system, the G54–G59.3 offsets and rotations as G10 left them, the G92/G52
/// offset, the tool length offset in force, the tool table with its G10 L1/L10/L11 changes,
/// the selected and loaded tools, the G28/G30 positions, the canned cycles' sticky values, the
/// modal state M70 saved in the main program, and the parameters: `#1`–`#4999`, named globals
/// (`#<_name>`) and the main program's named locals. (`#5161`–`#5390` read the carried G28/G30
/// positions, G92 offset and work offsets.)
///
/// Cutter compensation is never carried on: the compensation stage cancels it at the end of
/// every stream (the last element ends at its plain offset point), so the next interpretation
/// starts under G40 from where the tool stands.
#[derive(Debug, Clone, PartialEq)]
pub struct Carry {
    motion: Option<Motion>,
    plane: Plane,
    inch: bool,
    incremental: bool,
    arc_absolute: bool,
    inverse_time: bool,
    feed_mm_s: Option<f64>,
    blend: BlendMode,
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
    retract_to_r: bool,
    spindle: Spindle,
    cycles: CycleState,
    saved: Option<Saved>,
    diameter_mode: bool,
    spline_next: Option<nalgebra::Vector2<f64>>,
    speed_rpm: f64,
    params: Params,
}

impl Carry {
    /// The active work system: 0 = G54 … 5 = G59, 6 = G59.1, 7 = G59.2, 8 = G59.3.
    pub fn work_offset_index(&self) -> usize {
        self.coord
    }

    /// The G92/G52 offset in force (zero when G92.1/G92.2 cleared or suspended it), mm.
    pub fn g92_offset_mm(&self) -> Vector3<f64> {
        if self.g92_on {
            self.g92_mm
        } else {
            Vector3::zeros()
        }
    }

    /// Inch units (G20) rather than mm (G21).
    pub fn inch(&self) -> bool {
        self.inch
    }

    /// Absolute distance mode (G90) rather than incremental (G91).
    pub fn absolute(&self) -> bool {
        !self.incremental
    }

    /// The feed in force (G94), mm/s; `None` until an F was given (and under G93, whose F
    /// counts for one line only).
    pub fn feed_mm_s(&self) -> Option<f64> {
        self.feed_mm_s
    }

    /// The tool table, with the G10 L1/L10/L11 changes made so far.
    pub fn tools(&self) -> &ToolTable {
        &self.tools
    }

    /// The tool in the spindle (0 = none).
    pub fn loaded_tool(&self) -> u32 {
        self.loaded_tool
    }

    /// The origins of G54 … G59.3 (machine mm), as G10 L2/L20 left them.
    pub fn work_offsets_mm(&self) -> &[Vector3<f64>; 9] {
        &self.work_offsets_mm
    }

    /// The modes in force as a controller displays them, for `status`: the motion mode when
    /// one is set (`G0`, `G1`, `G2`, `G3`, `G5`, `G5.1`, a canned cycle, `G80`), then units,
    /// distance mode, plane, feed mode, work system, `G40` (compensation is never carried
    /// on), `G43` when a tool length offset is in force else `G49`, `G92` when a G92/G52
    /// offset is in force, `G90.1` when arc centres are absolute, `G7` under lathe diameter
    /// mode, the feed `F` in program units per minute when one is set (G94), and the loaded
    /// tool `T`. E.g. `G1 G21 G90 G17 G94 G54 G40 G49 F600 T1`.
    pub fn modal_summary(&self) -> String {
        let mut s = String::new();
        if let Some(m) = self.motion {
            let code = match m {
                Motion::Rapid => "G0",
                Motion::Linear => "G1",
                Motion::Cw => "G2",
                Motion::Ccw => "G3",
                Motion::Cycle(c) => c.code(),
                Motion::Cubic => "G5",
                Motion::Quadratic => "G5.1",
            };
            s.push_str(code);
            s.push(' ');
        }
        s.push_str(if self.inch { "G20" } else { "G21" });
        s.push_str(if self.incremental { " G91" } else { " G90" });
        s.push_str(match self.plane {
            Plane::Xy => " G17",
            Plane::Zx => " G18",
            Plane::Yz => " G19",
        });
        s.push_str(if self.inverse_time { " G93" } else { " G94" });
        s.push(' ');
        s.push_str(
            [
                "G54", "G55", "G56", "G57", "G58", "G59", "G59.1", "G59.2", "G59.3",
            ][self.coord.min(8)],
        );
        s.push_str(" G40");
        s.push_str(if self.tool_offset_mm == Vector3::zeros() {
            " G49"
        } else {
            " G43"
        });
        if self.g92_on && self.g92_mm != Vector3::zeros() {
            s.push_str(" G92");
        }
        if self.arc_absolute {
            s.push_str(" G90.1");
        }
        if self.diameter_mode {
            s.push_str(" G7");
        }
        if let Some(f) = self.feed_mm_s {
            let scale = if self.inch { MM_PER_INCH } else { 1.0 };
            let _ = write!(s, " F{}", round6(f * 60.0 / scale));
        }
        let _ = write!(s, " T{}", self.loaded_tool);
        s
    }
}

/// `v` rounded to 6 decimals, so that F600 reads `600` rather than `600.0000000000001`.
fn round6(v: f64) -> f64 {
    (v * 1e6).round() / 1e6
}

impl State {
    /// What this state leaves for the next interpretation (`params` is the interpreter's
    /// store: only the user's parameters are kept).
    pub(super) fn carry(&self, params: &Params) -> Carry {
        Carry {
            motion: self.motion,
            plane: self.plane,
            inch: self.inch,
            incremental: self.incremental,
            arc_absolute: self.arc_absolute,
            inverse_time: self.inverse_time,
            feed_mm_s: self.feed_mm_s,
            blend: self.blend,
            tool_offset_mm: self.tool_offset_mm,
            coord: self.coord,
            work_offsets_mm: self.work_offsets_mm,
            rotations_deg: self.rotations_deg,
            g92_mm: self.g92_mm,
            g92_on: self.g92_on,
            g28_mm: self.g28_mm,
            g30_mm: self.g30_mm,
            tools: self.tools.clone(),
            selected_tool: self.selected_tool,
            loaded_tool: self.loaded_tool,
            retract_to_r: self.retract_to_r,
            spindle: self.spindle,
            cycles: self.cycles.clone(),
            saved: self.saved.first().cloned().flatten(),
            diameter_mode: self.diameter_mode,
            spline_next: self.spline_next,
            speed_rpm: self.speed_rpm,
            params: params.carried(),
        }
    }

    /// Takes up a carried state (the position stays `start_mm`'s: the program point is
    /// recomputed through the carried offsets). Returns the parameters to start with.
    pub(super) fn resume(&mut self, c: Carry) -> Params {
        self.motion = c.motion;
        self.plane = c.plane;
        self.inch = c.inch;
        self.incremental = c.incremental;
        self.arc_absolute = c.arc_absolute;
        self.inverse_time = c.inverse_time;
        self.feed_mm_s = c.feed_mm_s;
        self.blend = c.blend;
        self.comp = CompState::Off;
        self.ended_comp = None;
        self.tool_offset_mm = c.tool_offset_mm;
        self.coord = c.coord;
        self.work_offsets_mm = c.work_offsets_mm;
        self.rotations_deg = c.rotations_deg;
        self.g92_mm = c.g92_mm;
        self.g92_on = c.g92_on;
        self.g28_mm = c.g28_mm;
        self.g30_mm = c.g30_mm;
        self.tools = c.tools;
        self.selected_tool = c.selected_tool;
        self.loaded_tool = c.loaded_tool;
        self.retract_to_r = c.retract_to_r;
        self.spindle = c.spindle;
        self.cycles = c.cycles;
        self.saved = vec![c.saved];
        self.diameter_mode = c.diameter_mode;
        self.spline_next = c.spline_next;
        self.speed_rpm = c.speed_rpm;
        self.resync();
        c.params
    }

    /// M2/M30's resets, LinuxCNC's list (its G-code manual, "M2, M30 Program End",
    /// `docs/src/gcode/m-code.adoc`, and `convert_stop` in `interp_convert.cc`): origin
    /// offsets to the default (G54 becomes the work system), plane G17, distance mode G90,
    /// feed mode G94 (a G93 feed means nothing under G94: the feed is cleared, as a mode change
    /// does here), cutter compensation off (G40), spindle stopped (M5), motion mode G1. Feed and
    /// speed overrides (M48) and coolant (M9) are not interpreter state here.
    ///
    /// What persists, as in LinuxCNC: the G92/G52 offset (LinuxCNC keeps G92 offsets unless
    /// `DISABLE_G92_PERSISTENCE` is set: `docs/src/gcode/coordinates.adoc`), the G10 work
    /// offsets and tool table, the units, the arc distance mode, the tool length offset, the
    /// loaded tool, the feed (under G94) and the parameters.
    pub(super) fn program_end(&mut self) {
        self.coord = 0;
        self.plane = Plane::Xy;
        self.incremental = false;
        if self.inverse_time {
            self.feed_mm_s = None;
        }
        self.inverse_time = false;
        self.comp = CompState::Off;
        self.ended_comp = None;
        self.spindle = Spindle::Stopped;
        self.motion = Some(Motion::Linear);
        self.spline_next = None;
        self.resync();
    }
}
