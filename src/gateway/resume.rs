//! Resuming a program after a stop (`canmotion run PROGRAM --resume`).
//!
//! A run that stops in the middle of its program (a drive reset, a fault, a lost heartbeat)
//! records where: a [`ResumeState`], saved as TOML beside the program (`PROGRAM.resume`) or in
//! the file given with `--state`. It names the program (with a hash of its text), the machine
//! (with a hash of what shapes the motion: cycle, nodes, modes, scaling, limits), the position
//! the program was interpreted from, the interrupted motion element (index, source line, how
//! far along its path), that point on the path (the **stop point**), the cause, and where each
//! axis came to rest.
//!
//! [`resume_program`] continues from it, in this order; any refusal happens before a drive is
//! enabled, and leaves every drive Pre-operational:
//!
//! 1. The program text must hash as recorded, and the machine too: a changed program or machine
//!    is refused (run it from the start instead).
//! 2. The whole program is interpreted again from the recorded start position and planned with
//!    the same planner and limits: the modal state (units, offsets, feed, plane, tool) of the
//!    interrupted line is the original run's, and the recorded stop point must lie on the
//!    recorded element.
//! 3. The full start-up of every node runs again ([`super::startup`]: reset communication,
//!    identity, every setting written and read back, PDO remap read back, mode confirmed by
//!    0x6061): a drive that reset gets its whole configuration back. Steps 4 and 5 run within
//!    it, once position actual is read and every axis found inside its travel, before anything
//!    is written to a drive.
//! 4. Each axis's position actual must be within [`MAX_RETURN_MM`] of the stop point; further
//!    means the position was lost (an incremental encoder after a power cycle) or the machine
//!    was moved by hand: home it, or run from the start.
//! 5. The operator confirms a [`ResumePreview`] (node, line, stop point, each axis's position
//!    and distance, the move back if any). No confirmation, no motion.
//! 6. The drives are enabled at their actual positions (bumpless) and armed; if an axis moved
//!    by more than [`ARMED_DRIFT_MM`] since the confirmation, nothing moves.
//! 7. The axes move back to the stop point in a straight line at [`APPROACH_MM_S`] (when every
//!    axis is already within [`AT_STOP_POINT_MM`], that move is below the tolerance), then the
//!    rest of the interrupted element runs from the stop point, from rest, at its programmed
//!    feed, then the remaining elements along the same path as the original run (same
//!    elements, same limits; the look-ahead plans the speeds again from the restart, so near
//!    it they can differ from the original's).
//!
//! A resumed run that stops again records a new resume point in terms of the original program,
//! so resuming can repeat; a resumed run that completes leaves no resume point.
//!
//! The mapping from a plan's segments back to program elements relies on the planner making
//! one segment per element (exact stop); if that ever stops being true, the mapping check
//! refuses to record or resume rather than guess.

use std::fmt;
use std::io::{BufRead, Write};
use std::path::Path;

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use super::{
    GatewayError, MotionFailure, MotionSource, RunOptions, StopPoint, Summary, aux_of_counts,
    interpret_program, interpret_program_at, limits, plan_program_at,
};
use crate::bus::Bus;
use crate::config::{AxisMode, Machine};
use crate::gcode::{AuxMove, AuxPos, BlendMode, CompState, Element, ElementKind, Item, Plane};
use crate::planner::{Limits, Plan, SegmentPath, plan_items, plan_items_with};

/// Version of the resume file's layout.
pub const STATE_VERSION: u32 = 1;
/// Speed of the move back to the stop point, mm/s (further limited by the axes' limits).
pub const APPROACH_MM_S: f64 = 5.0;
/// An axis within this of the stop point is at it: the move back is below the tolerance.
pub const AT_STOP_POINT_MM: f64 = 0.01;
/// An axis further than this from the stop point has lost its position or was moved: refused.
pub const MAX_RETURN_MM: f64 = 10.0;
/// How far an axis may move between the confirmation and the arming (enabling at actual).
pub const ARMED_DRIFT_MM: f64 = 0.1;
/// Less than this of an element left at the stop counts as the element completed.
const MIN_REMAINDER_MM: f64 = 1e-4;

/// One axis as the stop left it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AxisAtStop {
    /// Axis letter.
    pub name: String,
    /// Node id.
    pub node: u8,
    /// `ip` or `csp`.
    pub mode: String,
    /// The last setpoint sent (where the stop left it), mm.
    pub stop_setpoint_mm: f64,
    /// The last position actual received, mm.
    pub stop_actual_mm: f64,
}

/// Where an interrupted run stopped, as saved for `run --resume` (see the module
/// documentation). Written and read as TOML.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ResumeState {
    /// [`STATE_VERSION`].
    pub version: u32,
    /// The program, as named on the command line.
    pub program: String,
    /// FNV-1a 64 of the program text (`fnv1a64:` and 16 hex digits).
    pub program_hash: String,
    /// The machine's name.
    pub machine: String,
    /// FNV-1a 64 of the machine settings that shape the motion ([`machine_fingerprint`]).
    pub machine_hash: String,
    /// Why the run stopped (the failure message).
    pub reason: String,
    /// Nodes the stop concerned (frozen by the alarm).
    pub nodes: Vec<u8>,
    /// Nodes that reset (boot-up) during the run; `run --resume` reconfigures every node anyway.
    pub reset_nodes: Vec<u8>,
    /// Where the program was interpreted from (the original run's armed position), mm.
    pub program_start_mm: [f64; 3],
    /// Index of the interrupted item in the interpreted program (equal to the number of items
    /// when the program's motion had completed).
    pub item: usize,
    /// Its source line.
    pub line: usize,
    /// How far along the element's path the stop point is, 0–1.
    pub fraction: f64,
    /// The stop point: the last point of the path streamed before the stop, mm.
    pub stop_point_mm: [f64; 3],
    /// The last program line completed before the stop (0: none).
    pub completed_line: usize,
    /// Each axis, machine order.
    pub axis: Vec<AxisAtStop>,
}

/// What went wrong with a resume file.
#[derive(Debug, thiserror::Error)]
pub enum StateError {
    /// Reading or writing failed.
    #[error("{file}: {source}")]
    Io {
        /// The file.
        file: String,
        /// Why.
        source: std::io::Error,
    },
    /// The file is not a regular file, is too large, or cannot be written where it is.
    #[error(transparent)]
    File(#[from] crate::files::FileError),
    /// The content is not a resume file of this version.
    #[error("{file}: not a canmotion resume file: {message}")]
    Format {
        /// The file.
        file: String,
        /// Why.
        message: String,
    },
}

impl ResumeState {
    /// Parse a resume file's text.
    pub fn parse(file: &Path, text: &str) -> Result<ResumeState, StateError> {
        let s: ResumeState = toml::from_str(text).map_err(|e| StateError::Format {
            file: file.display().to_string(),
            message: e.to_string(),
        })?;
        if s.version != STATE_VERSION {
            return Err(StateError::Format {
                file: file.display().to_string(),
                message: format!(
                    "version {} (this canmotion reads {STATE_VERSION})",
                    s.version
                ),
            });
        }
        Ok(s)
    }

    /// Read a resume file.
    pub fn load(file: &Path) -> Result<ResumeState, StateError> {
        let text = crate::files::read_text(file, crate::files::MAX_CONFIG_BYTES)?;
        ResumeState::parse(file, &text)
    }

    /// The file's text: a comment saying what it is, then the fields.
    pub fn to_toml(&self) -> String {
        let body = toml::to_string(self).expect("a resume state serialises");
        format!(
            "# canmotion resume point: where `{}` stopped. `canmotion run {} --resume` continues\n\
             # from here after a confirmation; delete this file to forget it.\n{body}",
            Escaped(&self.program),
            Escaped(&self.program)
        )
    }

    /// Write the file (through a partial file and a rename, so a reader never sees half; see
    /// [`crate::files::Output`]).
    pub fn save(&self, file: &Path) -> Result<(), StateError> {
        Ok(crate::files::write_output(file, self.to_toml().as_bytes())?)
    }

    fn stop_point(&self) -> Vector3<f64> {
        Vector3::from(self.stop_point_mm)
    }
}

/// FNV-1a, 64 bits: detects a changed file (not meant against forgery).
pub fn fnv1a64(bytes: &[u8]) -> String {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in bytes {
        h ^= u64::from(*b);
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    format!("fnv1a64:{h:016x}")
}

/// The hash of what in a machine shapes the motion and the positions: cycle, and per axis its
/// letter, node, mode, scaling, travel and limits.
pub fn machine_fingerprint(m: &Machine) -> String {
    let mut s = format!("{}|{}", m.name, m.cycle_us);
    for a in &m.axes {
        s.push_str(&format!(
            "|{} {} {:?} {:e} {:e} {:e} {:e} {:e}",
            a.name,
            a.node,
            a.mode,
            a.counts_per_mm,
            a.min_mm,
            a.max_mm,
            a.max_vel_mm_s,
            a.max_acc_mm_s2
        ));
    }
    fnv1a64(s.as_bytes())
}

fn mode_name(m: AxisMode) -> &'static str {
    match m {
        AxisMode::Ip => "ip",
        AxisMode::Csp => "csp",
    }
}

/// For each segment of `plan` (planned from `start_mm` over `items`), the index of the item it
/// came from. Each item is planned alone and the segments compared with the plan's; a plan
/// that is not one segment per element (a look-ahead planner) is an error, never a guess.
fn segment_items(
    start_mm: Vector3<f64>,
    items: &[Item],
    limits: &Limits,
    plan: &Plan,
) -> Result<Vec<usize>, String> {
    let mut out = Vec::with_capacity(plan.segments().len());
    let mut at_mm = start_mm;
    for (k, item) in items.iter().enumerate() {
        let alone =
            plan_items(at_mm, std::slice::from_ref(item), limits).map_err(|e| e.to_string())?;
        for seg in alone.segments() {
            let i = out.len();
            match plan.segments().get(i) {
                Some(s)
                    if s.line == seg.line
                        && s.start_mm == seg.start_mm
                        && s.end_mm == seg.end_mm
                        && s.length_mm == seg.length_mm => {}
                _ => {
                    return Err(format!(
                        "segment {i} of the plan is not the plan of element {k} alone"
                    ));
                }
            }
            out.push(k);
        }
        at_mm = alone.end_mm();
    }
    if out.len() != plan.segments().len() {
        return Err("the plan has segments no element accounts for".into());
    }
    Ok(out)
}

/// Where along its element (0–1) a plan's time falls, with the segment index.
fn fraction_at(plan: &Plan, t_s: f64) -> Option<(usize, f64)> {
    let s = plan.segment_index_at(t_s)?;
    let seg = &plan.segments()[s];
    let f = match seg.path {
        SegmentPath::Line { .. } | SegmentPath::Arc(_) if seg.length_mm > 0.0 => {
            (seg.distance_at(t_s - seg.start_time_s) / seg.length_mm).clamp(0.0, 1.0)
        }
        // A dwell (or stop) is done again in full.
        _ => 0.0,
    };
    Some((s, f))
}

/// The point at `fraction` of an element's path.
fn point_on(e: &Element, fraction: f64) -> Option<Vector3<f64>> {
    match e.kind {
        ElementKind::Line => Some(e.start_mm + (e.end_mm - e.start_mm) * fraction),
        ElementKind::Arc { .. } => e.arc().map(|a| a.point_at(fraction)),
    }
}

/// The rest of element `e` from `fraction` on, starting at `from_mm` (its point there). For an
/// arc, the remaining turns are chosen so that the sweep left is exactly the original's share;
/// `None` if no arc matches (never a guess).
fn remainder(e: &Element, fraction: f64, from_mm: Vector3<f64>) -> Option<Element> {
    if fraction <= 0.0 {
        return Some(*e);
    }
    match e.kind {
        ElementKind::Line => Some(Element {
            start_mm: from_mm,
            ..*e
        }),
        ElementKind::Arc {
            center_mm,
            normal,
            cw,
            ..
        } => {
            let orig = e.arc()?;
            let n = orig.normal;
            // The centre in the plane of the new start (a helix rises along the normal).
            let center = center_mm + n * (from_mm - center_mm).dot(&n);
            let d = from_mm - center;
            let radius_mm = (d - n * d.dot(&n)).norm();
            let want_sweep = orig.sweep_rad * (1.0 - fraction);
            let guess = (want_sweep / std::f64::consts::TAU).floor().max(0.0) as u32;
            let candidates = [guess.saturating_sub(1), guess, guess + 1];
            candidates.into_iter().find_map(|turns| {
                let r = Element {
                    start_mm: from_mm,
                    kind: ElementKind::Arc {
                        center_mm: center,
                        normal,
                        cw,
                        turns,
                        radius_mm,
                    },
                    ..*e
                };
                let g = r.arc()?;
                let helix_ok = (g.helix_mm - orig.helix_mm * (1.0 - fraction)).abs() <= 1e-6;
                ((g.sweep_rad - want_sweep).abs() <= 1e-6 && helix_ok).then_some(r)
            })
        }
    }
}

/// Where the stop of a run falls in terms of the original program.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Position {
    item: usize,
    fraction: f64,
}

/// How one item of a (resumed) motion maps onto the original program.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Origin {
    /// The move back to the stop point.
    Approach,
    /// Original item `item`, from `from` of its path on (0 for a whole element).
    Item { item: usize, from: f64 },
}

/// A motion in the making: the items it plans from, their origins in the original program, and
/// the plan once made.
struct Motion {
    /// The original program's items.
    program: Vec<Item>,
    program_start_mm: Vector3<f64>,
    /// The items planned in this run, and where each comes from.
    items: Vec<(Item, Origin)>,
    plan: Option<(Vector3<f64>, Plan)>,
    /// The position of the run's start in the original program (for a stop in the approach).
    start: Position,
    /// The last line completed before the run's start (0: none).
    completed_before: usize,
}

impl Motion {
    /// Map a stop in this run's plan to a position in the original program.
    fn position_of(&self, limits: &Limits, stop: &StopPoint) -> Result<Position, String> {
        let (start_mm, plan) = self.plan.as_ref().ok_or("no motion was planned")?;
        let items: Vec<Item> = self.items.iter().map(|(i, _)| i.clone()).collect();
        let map = segment_items(*start_mm, &items, limits, plan)?;
        let Some((s, g)) = fraction_at(plan, stop.plan_time_s) else {
            return Ok(self.start);
        };
        let mut p = match self.items[map[s]].1 {
            Origin::Approach => return Ok(self.start),
            Origin::Item { item, from } => Position {
                item,
                fraction: from + g * (1.0 - from),
            },
        };
        // Less than a trace of the element left: it is done.
        let e = match &self.program[p.item] {
            Item::Motion(e) => Some(e),
            _ => None,
        };
        if let Some(e) = e
            && e.length_mm() * (1.0 - p.fraction) < MIN_REMAINDER_MM
        {
            p = Position {
                item: p.item + 1,
                fraction: 0.0,
            };
        }
        Ok(p)
    }

    /// The resume state for a stop of this run.
    fn state_after(
        &self,
        machine: &Machine,
        opts: &RunOptions,
        failure: &MotionFailure,
    ) -> Option<ResumeState> {
        let stop = failure.stop.as_ref()?;
        let p = match self.position_of(&limits(machine), stop) {
            Ok(p) => p,
            Err(e) => {
                tracing::warn!("no resume point recorded: {e}");
                return None;
            }
        };
        let (line, point) = match self.program.get(p.item) {
            Some(Item::Motion(e)) => (e.line, point_on(e, p.fraction)?),
            Some(Item::Dwell(d)) => (d.line, self.start_of(p.item)),
            Some(Item::Stop(s)) => (s.line, self.start_of(p.item)),
            Some(Item::Note(_) | Item::End(_)) | None => (
                stop.completed_line.unwrap_or(self.completed_before),
                self.start_of(p.item),
            ),
        };
        Some(ResumeState {
            version: STATE_VERSION,
            program: opts.program_name.clone(),
            program_hash: fnv1a64(opts.program_text.as_bytes()),
            machine: machine.name.clone(),
            machine_hash: machine_fingerprint(machine),
            reason: failure.to_string(),
            nodes: stop.frozen_nodes.clone(),
            reset_nodes: stop.reset_nodes.clone(),
            program_start_mm: self.program_start_mm.into(),
            item: p.item,
            line,
            fraction: p.fraction,
            stop_point_mm: point.into(),
            completed_line: stop.completed_line.unwrap_or(self.completed_before),
            axis: machine
                .axes
                .iter()
                .enumerate()
                .map(|(i, a)| AxisAtStop {
                    name: a.name.clone(),
                    node: a.node,
                    mode: mode_name(a.mode).into(),
                    stop_setpoint_mm: stop.rest_setpoint_mm.get(i).copied().unwrap_or(0.0),
                    stop_actual_mm: a
                        .counts_to_mm(stop.rest_actual_counts.get(i).copied().unwrap_or(0)),
                })
                .collect(),
        })
    }

    /// Where item `k` of the original program starts (its end, for `k` past the last).
    fn start_of(&self, k: usize) -> Vector3<f64> {
        let mut at = self.program_start_mm;
        for item in self.program.iter().take(k) {
            if let Item::Motion(e) = item {
                at = e.end_mm;
            }
        }
        at
    }
}

/// A program run from its start, keeping its plan to record a resume point.
struct FromStartRecorded<'a> {
    opts: &'a RunOptions,
    motion: Option<Motion>,
}

impl MotionSource for FromStartRecorded<'_> {
    fn check(
        &mut self,
        machine: &Machine,
        start_mm: Vector3<f64>,
        start_counts: &[i32],
    ) -> Result<(), GatewayError> {
        plan_program_at(
            machine,
            &self.opts.program_name,
            &self.opts.program_text,
            start_mm,
            aux_of_counts(machine, start_counts),
        )
        .map(|_| ())
    }

    fn plan(
        &mut self,
        machine: &Machine,
        armed_mm: Vector3<f64>,
        armed_aux: AuxPos,
    ) -> Result<Plan, GatewayError> {
        let plan = plan_program_at(
            machine,
            &self.opts.program_name,
            &self.opts.program_text,
            armed_mm,
            armed_aux,
        )?;
        let program = interpret_program_at(
            machine,
            &self.opts.program_name,
            &self.opts.program_text,
            armed_mm,
            armed_aux,
        )?;
        self.motion = Some(Motion {
            items: program
                .items
                .iter()
                .enumerate()
                .map(|(k, i)| (i.clone(), Origin::Item { item: k, from: 0.0 }))
                .collect(),
            program: program.items,
            program_start_mm: armed_mm,
            plan: Some((armed_mm, plan.clone())),
            start: Position {
                item: 0,
                fraction: 0.0,
            },
            completed_before: 0,
        });
        Ok(plan)
    }
}

/// What a run (from the start or resumed) came to, and the resume point if it stopped before
/// the end of its program.
#[derive(Debug)]
pub struct RunOutcome {
    /// The run's result.
    pub result: Result<Summary, GatewayError>,
    /// Where it stopped, when the motion stopped mid-program.
    pub resume: Option<ResumeState>,
}

fn outcome(
    machine: &Machine,
    opts: &RunOptions,
    result: Result<Summary, GatewayError>,
    motion: Option<&Motion>,
) -> RunOutcome {
    let resume = match (&result, motion) {
        (Err(GatewayError::Motion(f)), Some(m)) => m.state_after(machine, opts, f),
        _ => None,
    };
    RunOutcome { result, resume }
}

/// [`super::run`], and the resume point when the motion stops before the end of the program.
pub fn run_program(machine: &Machine, bus: &Bus, opts: &RunOptions) -> RunOutcome {
    let mut source = FromStartRecorded { opts, motion: None };
    let result = super::run_with(machine, bus, opts, &mut source);
    outcome(machine, opts, result, source.motion.as_ref())
}

/// One axis in a [`ResumePreview`].
#[derive(Debug, Clone, PartialEq)]
pub struct PreviewAxis {
    /// Axis letter.
    pub name: String,
    /// Node.
    pub node: u8,
    /// Position actual now, mm.
    pub now_mm: f64,
    /// Its coordinate of the stop point, mm (`None` for an axis the program does not move).
    pub stop_mm: Option<f64>,
    /// Whether its drive reset during the interrupted run.
    pub reset: bool,
}

/// What a resume will do, for the operator to confirm.
#[derive(Debug, Clone, PartialEq)]
pub struct ResumePreview {
    /// The program.
    pub program: String,
    /// Why it stopped.
    pub reason: String,
    /// The interrupted line.
    pub line: usize,
    /// How far along it, 0–1.
    pub fraction: f64,
    /// The last line completed (0: none).
    pub completed_line: usize,
    /// The stop point, mm.
    pub stop_point_mm: Vector3<f64>,
    /// Whether the program's motion had completed (only the move back to its end remains).
    pub motion_done: bool,
    /// The axes.
    pub axes: Vec<PreviewAxis>,
    /// The largest distance of an axis from the stop point, mm.
    pub max_distance_mm: f64,
    /// Speed of the move back, mm/s.
    pub approach_mm_s: f64,
}

use crate::files::Escaped;

impl fmt::Display for ResumePreview {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let p = self.stop_point_mm;
        // Everything that comes from a file is shown escaped: it must not redraw the screen.
        writeln!(f, "resume {} at line {}", Escaped(&self.program), self.line)?;
        writeln!(f, "  stopped by      {}", Escaped(&self.reason))?;
        if self.motion_done {
            writeln!(
                f,
                "  stop point      X{:.4} Y{:.4} Z{:.4} mm: the program's end (its motion had completed)",
                p[0], p[1], p[2]
            )?;
        } else {
            let done = if self.completed_line == 0 {
                "no line completed".to_string()
            } else {
                format!("line {} completed", self.completed_line)
            };
            writeln!(
                f,
                "  stop point      X{:.4} Y{:.4} Z{:.4} mm, {:.1} % into line {} ({done})",
                p[0],
                p[1],
                p[2],
                self.fraction * 100.0,
                self.line
            )?;
        }
        for a in &self.axes {
            let reset = if a.reset { ", its drive reset" } else { "" };
            match a.stop_mm {
                Some(s) => writeln!(
                    f,
                    "  axis {} (node {})  at {:.4} mm, {:.4} mm from the stop point{reset}",
                    Escaped(&a.name),
                    a.node,
                    a.now_mm,
                    (a.now_mm - s).abs()
                )?,
                None => writeln!(
                    f,
                    "  axis {} (node {})  at {:.4} mm, held{reset}",
                    Escaped(&a.name),
                    a.node,
                    a.now_mm
                )?,
            }
        }
        if self.max_distance_mm > AT_STOP_POINT_MM {
            write!(
                f,
                "  the axes move back to the stop point in a straight line at {} mm/s, ",
                self.approach_mm_s
            )?;
        } else {
            write!(
                f,
                "  the axes are at the stop point (within {AT_STOP_POINT_MM} mm), "
            )?;
        }
        if self.motion_done {
            write!(f, "and the program ends there")
        } else {
            write!(f, "then the program continues from line {}", self.line)
        }
    }
}

/// Ask the operator on `output` and read the answer from `input`: only `yes` confirms.
pub fn ask(preview: &ResumePreview, input: &mut dyn BufRead, output: &mut dyn Write) -> bool {
    let _ = writeln!(output, "{preview}");
    let _ = write!(output, "Type yes to resume, anything else to cancel: ");
    let _ = output.flush();
    let mut answer = String::new();
    match input.read_line(&mut answer) {
        Ok(n) if n > 0 => answer.trim() == "yes",
        _ => false,
    }
}

/// Continues an interrupted program (see the module documentation).
struct Resumption<'a> {
    state: &'a ResumeState,
    motion: Motion,
    confirm: &'a mut dyn FnMut(&ResumePreview) -> bool,
    confirmed_mm: Option<Vector3<f64>>,
}

impl Resumption<'_> {
    fn stop_point(&self) -> Vector3<f64> {
        self.state.stop_point()
    }
}

impl MotionSource for Resumption<'_> {
    fn check(
        &mut self,
        machine: &Machine,
        start_mm: Vector3<f64>,
        start_counts: &[i32],
    ) -> Result<(), GatewayError> {
        let target = self.stop_point();
        let mut axes = Vec::new();
        let mut max_distance_mm: f64 = 0.0;
        for (a, c) in machine.axes.iter().zip(start_counts) {
            let now_mm = a.counts_to_mm(*c);
            let stop_mm = a.xyz().map(|k| target[k]);
            if let Some(s) = stop_mm {
                let d = (now_mm - s).abs();
                if d > MAX_RETURN_MM {
                    return Err(GatewayError::Resume(format!(
                        "not resuming: axis {} (node {}) is at {now_mm:.4} mm, {d:.4} mm from the stop point {s:.4} mm (more than {MAX_RETURN_MM} mm): its position was lost (an incremental encoder after a reset?) or the machine was moved; home it, or run the program from the start",
                        a.name, a.node
                    )));
                }
                max_distance_mm = max_distance_mm.max(d);
            }
            axes.push(PreviewAxis {
                name: a.name.clone(),
                node: a.node,
                now_mm,
                stop_mm,
                reset: self.state.reset_nodes.contains(&a.node),
            });
        }
        let preview = ResumePreview {
            program: self.state.program.clone(),
            reason: self.state.reason.clone(),
            line: self.state.line,
            fraction: self.state.fraction,
            completed_line: self.state.completed_line,
            stop_point_mm: target,
            motion_done: self.state.item >= self.motion.program.len(),
            axes,
            max_distance_mm,
            approach_mm_s: APPROACH_MM_S,
        };
        if !(self.confirm)(&preview) {
            return Err(GatewayError::Resume(format!(
                "resume of {} at line {} not confirmed: nothing moved",
                self.state.program, self.state.line
            )));
        }
        self.confirmed_mm = Some(start_mm);
        Ok(())
    }

    fn plan(
        &mut self,
        machine: &Machine,
        armed_mm: Vector3<f64>,
        armed_aux: AuxPos,
    ) -> Result<Plan, GatewayError> {
        let confirmed = self.confirmed_mm.unwrap_or(armed_mm);
        for a in &machine.axes {
            if let Some(k) = a.xyz() {
                let d = (armed_mm[k] - confirmed[k]).abs();
                if d > ARMED_DRIFT_MM {
                    return Err(GatewayError::Resume(format!(
                        "not resuming: axis {} (node {}) moved {d:.4} mm between the confirmation and the enable",
                        a.name, a.node
                    )));
                }
            }
        }
        let target = self.stop_point();
        let approach = Element {
            line: self.state.line,
            col: 0,
            kind: ElementKind::Line,
            rapid: false,
            start_mm: armed_mm,
            end_mm: target,
            // Programs that move the auxiliary axes are not resumed (`prepare`): they stay
            // where the drives are.
            aux: AuxMove::still(armed_aux),
            feed_mm_s: Some(APPROACH_MM_S),
            blend: BlendMode::ExactStop,
            comp: CompState::Off,
            plane: Plane::Xy,
        };
        let mut items = vec![(Item::Motion(approach), Origin::Approach)];
        items.extend(
            self.motion
                .items
                .iter()
                .cloned()
                .map(|(item, origin)| match item {
                    Item::Motion(e) => (
                        Item::Motion(Element {
                            aux: AuxMove::still(armed_aux),
                            ..e
                        }),
                        origin,
                    ),
                    other => (other, origin),
                }),
        );
        let planned: Vec<Item> = items.iter().map(|(i, _)| i.clone()).collect();
        let plan = plan_items_with(armed_mm, &planned, &limits(machine), &machine.planner)
            .map_err(|source| GatewayError::Plan {
                file: self.state.program.clone(),
                source,
            })?;
        self.motion.items = items;
        self.motion.plan = Some((armed_mm, plan.clone()));
        Ok(plan)
    }

    fn completed_line(&self) -> Option<usize> {
        (self.state.completed_line > 0).then_some(self.state.completed_line)
    }
}

/// Prepare the motion of a resume: the program interpreted and checked against the state.
fn prepare(machine: &Machine, opts: &RunOptions, state: &ResumeState) -> Result<Motion, String> {
    let hash = fnv1a64(opts.program_text.as_bytes());
    if hash != state.program_hash {
        return Err(format!(
            "not resuming: {} changed since the stop ({hash}, the resume point was recorded with {}): run it from the start",
            opts.program_name, state.program_hash
        ));
    }
    let mh = machine_fingerprint(machine);
    if mh != state.machine_hash || machine.name != state.machine {
        return Err(format!(
            "not resuming: machine '{}' ({mh}) is not the one the resume point was recorded on ('{}', {})",
            machine.name, state.machine, state.machine_hash
        ));
    }
    let start = Vector3::from(state.program_start_mm);
    let program = interpret_program(machine, &opts.program_name, &opts.program_text, start)
        .map_err(|e| e.to_string())?;
    let items = program.items;
    // A resume point records X, Y and Z only.
    if let Some(e) = items.iter().find_map(|i| match i {
        Item::Motion(e) if e.aux.moves() => Some(e),
        _ => None,
    }) {
        return Err(format!(
            "not resuming: {} line {} moves an A, B, C, U, V or W axis, and a resume point does not record them yet: run it from the start",
            opts.program_name, e.line
        ));
    }
    let target = state.stop_point();
    let rest: Vec<(Item, Origin)> = match items.get(state.item) {
        None if state.item == items.len() => Vec::new(),
        None => {
            return Err(format!(
                "the resume point names element {} of {}, which has {}",
                state.item,
                opts.program_name,
                items.len()
            ));
        }
        Some(item) => {
            let first = match item {
                Item::Motion(e) => {
                    let on_path =
                        point_on(e, state.fraction).is_some_and(|p| (p - target).norm() <= 1e-6);
                    if e.line != state.line || !on_path {
                        return Err(format!(
                            "the resume point (line {}, {:?} mm) is not on element {} of {} (line {}): not resuming",
                            state.line, state.stop_point_mm, state.item, opts.program_name, e.line
                        ));
                    }
                    let r = remainder(e, state.fraction, target).ok_or_else(|| {
                        format!(
                            "line {}: the rest of the arc from the stop point cannot be expressed exactly: not resuming",
                            e.line
                        )
                    })?;
                    Item::Motion(r)
                }
                other => other.clone(),
            };
            std::iter::once((
                first,
                Origin::Item {
                    item: state.item,
                    from: state.fraction,
                },
            ))
            .chain(
                items
                    .iter()
                    .enumerate()
                    .skip(state.item + 1)
                    .map(|(k, i)| (i.clone(), Origin::Item { item: k, from: 0.0 })),
            )
            .collect()
        }
    };
    Ok(Motion {
        program: items,
        program_start_mm: start,
        items: rest,
        plan: None,
        start: Position {
            item: state.item,
            fraction: state.fraction,
        },
        completed_before: state.completed_line,
    })
}

/// Continue the program of `opts` from `state` (see the module documentation); `confirm` is
/// asked once the drives are configured and their positions known, before anything is enabled.
pub fn resume_program(
    machine: &Machine,
    bus: &Bus,
    opts: &RunOptions,
    state: &ResumeState,
    confirm: &mut dyn FnMut(&ResumePreview) -> bool,
) -> RunOutcome {
    let motion = match prepare(machine, opts, state) {
        Ok(m) => m,
        Err(e) => {
            return RunOutcome {
                result: Err(GatewayError::Resume(e)),
                resume: None,
            };
        }
    };
    let mut source = Resumption {
        state,
        motion,
        confirm,
        confirmed_mm: None,
    };
    let result = super::run_with(machine, bus, opts, &mut source);
    let mut out = outcome(machine, opts, result, Some(&source.motion));
    // A stop before the motion started leaves the old resume point as it was.
    if matches!(&out.result, Err(GatewayError::Motion(f)) if f.stop.is_none()) {
        out.resume = Some(state.clone());
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn machine() -> Machine {
        Machine::demo()
    }

    const PROGRAM: &str =
        "G21 G90\nG1 X40 Y30 Z-1 F6000\nG2 X60 Y50 R20 F3000\nG1 Z-2 F600\nG0 X10 Y10\nM2\n";

    fn opts(text: &str) -> RunOptions {
        RunOptions {
            program_name: "t.ngc".into(),
            program_text: text.into(),
            log: None,
            simulate: false,
            ..Default::default()
        }
    }

    /// The motion a run from `start` would record, planned.
    fn original(start: Vector3<f64>) -> Motion {
        let m = machine();
        let o = opts(PROGRAM);
        let mut src = FromStartRecorded {
            opts: &o,
            motion: None,
        };
        src.plan(&m, start, [0.0; 6]).unwrap();
        src.motion.unwrap()
    }

    fn stop_at(plan: &Plan, t: f64) -> StopPoint {
        StopPoint {
            plan_time_s: t,
            path_mm: plan.position_at(t),
            line: None,
            completed_line: None,
            frozen_nodes: vec![1],
            reset_nodes: vec![1],
            rest_setpoint_mm: vec![0.0; 3],
            rest_actual_counts: vec![0; 3],
        }
    }

    fn failure(stop: StopPoint) -> MotionFailure {
        MotionFailure {
            failure: crate::master::alarm::Failure {
                alarm: crate::master::alarm::Alarm::BootUp {
                    axis: "X",
                    node: 1,
                    completed_line: None,
                },
                line: None,
            },
            detected_cycle: None,
            bit12_cycle: None,
            first_motion_cycle: None,
            period_s: 0.004,
            bit12_to_failure_s: None,
            detected_ns: None,
            stop: Some(stop),
            timing: Default::default(),
            bus: Default::default(),
        }
    }

    #[test]
    fn fnv_is_the_reference_function() {
        assert_eq!(fnv1a64(b""), "fnv1a64:cbf29ce484222325");
        assert_eq!(fnv1a64(b"a"), "fnv1a64:af63dc4c8601ec8c");
        assert_ne!(fnv1a64(b"G1 X1\n"), fnv1a64(b"G1 X1 \n"));
    }

    #[test]
    fn the_rest_of_a_run_is_the_original_plan_after_the_stop() {
        let m = machine();
        let start = Vector3::new(1.0, 2.0, 0.0);
        let orig = original(start);
        let (_, plan) = orig.plan.clone().unwrap();
        let segs = plan.segments();
        // Stop in the middle of every segment (the arc included), then resume from there.
        for (s, seg) in segs.iter().enumerate() {
            let t = seg.start_time_s + 0.37 * seg.duration_s();
            let state = orig
                .state_after(&m, &opts(PROGRAM), &failure(stop_at(&plan, t)))
                .unwrap();
            assert_eq!(state.line, seg.line);
            // The stop point is the plan's point at the stop.
            let p = plan.position_at(t);
            assert!(
                (Vector3::from(state.stop_point_mm) - p).norm() < 1e-9,
                "{s}"
            );
            let f = state.fraction;
            // The machine came to rest a little further along.
            let armed = p + Vector3::new(0.8, -0.3, 0.1);
            let mut r = Resumption {
                state: &state,
                motion: prepare(&m, &opts(PROGRAM), &state).unwrap(),
                confirm: &mut |_| true,
                confirmed_mm: Some(armed),
            };
            let rplan = r.plan(&m, armed, [0.0; 6]).unwrap();
            let rs = rplan.segments();
            // Approach, the rest of the interrupted element, then the original segments.
            assert_eq!(rs[0].start_mm, armed);
            assert_eq!(rs[0].end_mm, rs[1].start_mm);
            assert!((rs[1].start_mm - p).norm() < 1e-9);
            assert_eq!(rs[1].end_mm, seg.end_mm);
            assert_eq!(rs[1].line, seg.line);
            assert!(
                (rs[1].length_mm - seg.length_mm * (1.0 - f)).abs() < 1e-6,
                "segment {s}: {} of {} from {f}",
                rs[1].length_mm,
                seg.length_mm
            );
            assert_eq!(rs.len() - 2, segs.len() - s - 1);
            // The same path after it (the speeds near the restart come from the new plan's
            // look-ahead: it starts from rest at the stop point).
            for (a, b) in rs[2..].iter().zip(&segs[s + 1..]) {
                assert_eq!(
                    (a.line, a.start_mm, a.end_mm, a.path, a.length_mm),
                    (b.line, b.start_mm, b.end_mm, b.path, b.length_mm),
                    "segment after {s}"
                );
            }
            assert_eq!(rplan.end_mm(), plan.end_mm());
            // A second stop, in the rest of the interrupted element, maps back onto the
            // original element: resuming twice follows the same path.
            let t2 = rs[1].start_time_s + 0.5 * rs[1].duration_s();
            let g = rs[1].distance_at(t2 - rs[1].start_time_s) / rs[1].length_mm;
            let again = r
                .motion
                .state_after(&m, &opts(PROGRAM), &failure(stop_at(&rplan, t2)))
                .unwrap();
            assert_eq!(again.item, state.item);
            assert!(
                (again.fraction - (f + g * (1.0 - f))).abs() < 1e-9,
                "{}",
                again.fraction
            );
            let q = rplan.position_at(t2);
            assert!(
                (Vector3::from(again.stop_point_mm) - q).norm() < 1e-6,
                "segment {s}: {:?} vs {q:?}",
                again.stop_point_mm
            );
            // A stop in the approach keeps the old resume point.
            let t0 = 0.5 * rs[0].duration_s();
            let same = r
                .motion
                .state_after(&m, &opts(PROGRAM), &failure(stop_at(&rplan, t0)))
                .unwrap();
            assert_eq!((same.item, same.fraction), (state.item, state.fraction));
        }
    }

    #[test]
    fn a_stop_at_the_very_end_of_an_element_resumes_with_the_next() {
        let m = machine();
        let orig = original(Vector3::zeros());
        let (_, plan) = orig.plan.clone().unwrap();
        let first = plan.segments()[0];
        let state = orig
            .state_after(
                &m,
                &opts(PROGRAM),
                &failure(stop_at(&plan, first.end_time_s())),
            )
            .unwrap();
        assert_eq!(state.line, plan.segments()[1].line);
        assert_eq!(state.fraction, 0.0);
        // And past the end of the plan: only the move back to the end remains.
        let state = orig
            .state_after(
                &m,
                &opts(PROGRAM),
                &failure(stop_at(&plan, plan.duration_s())),
            )
            .unwrap();
        let resumed = prepare(&m, &opts(PROGRAM), &state).unwrap();
        assert!(resumed.items.is_empty());
        assert_eq!(Vector3::from(state.stop_point_mm), plan.end_mm());
    }

    #[test]
    fn a_changed_program_or_machine_is_refused() {
        let m = machine();
        let orig = original(Vector3::zeros());
        let (_, plan) = orig.plan.clone().unwrap();
        let state = orig
            .state_after(&m, &opts(PROGRAM), &failure(stop_at(&plan, 0.5)))
            .unwrap();
        let changed = PROGRAM.replace("F3000", "F3001");
        let e = prepare(&m, &opts(&changed), &state).err().unwrap();
        assert!(e.contains("t.ngc changed since the stop"), "{e}");
        let mut other = m.clone();
        other.axes[1].max_acc_mm_s2 *= 2.0;
        let e = prepare(&other, &opts(PROGRAM), &state).err().unwrap();
        assert!(
            e.contains("is not the one the resume point was recorded on"),
            "{e}"
        );
    }

    #[test]
    fn a_program_that_moves_an_auxiliary_axis_is_not_resumed() {
        let m = Machine::load(std::path::Path::new("dictionaries/machines/demo-xyza.toml"))
            .expect("demo-xyza");
        let text = "G1 X10 A90 F600\nG1 X20 F600\nM2\n";
        let o = opts(text);
        let mut src = FromStartRecorded {
            opts: &o,
            motion: None,
        };
        src.plan(&m, Vector3::zeros(), [0.0; 6]).unwrap();
        let orig = src.motion.unwrap();
        let (_, plan) = orig.plan.clone().unwrap();
        let mut stop = stop_at(&plan, plan.segments()[1].start_time_s + 0.1);
        stop.rest_setpoint_mm = vec![0.0; 4];
        stop.rest_actual_counts = vec![0; 4];
        let state = orig.state_after(&m, &o, &failure(stop)).unwrap();
        let e = prepare(&m, &o, &state).err().unwrap();
        assert!(e.contains("line 1 moves an A, B, C, U, V or W axis"), "{e}");
    }

    #[test]
    fn the_state_file_round_trips_and_is_strict() {
        let m = machine();
        let orig = original(Vector3::new(0.1, 0.2, 0.3));
        let (_, plan) = orig.plan.clone().unwrap();
        let state = orig
            .state_after(&m, &opts(PROGRAM), &failure(stop_at(&plan, 0.7)))
            .unwrap();
        let text = state.to_toml();
        assert!(text.starts_with("# canmotion resume point"), "{text}");
        let back = ResumeState::parse(Path::new("s.resume"), &text).unwrap();
        assert_eq!(back, state);
        let bad = format!("{text}\nextra = 1\n");
        let e = ResumeState::parse(Path::new("s.resume"), &bad).unwrap_err();
        assert!(
            e.to_string()
                .starts_with("s.resume: not a canmotion resume file"),
            "{e}"
        );
        let old = text.replace("version = 1", "version = 0");
        assert!(ResumeState::parse(Path::new("s.resume"), &old).is_err());
    }

    #[test]
    fn only_yes_confirms() {
        let preview = ResumePreview {
            program: "p.ngc".into(),
            reason: "axis X (node 1): boot-up during the run".into(),
            line: 3,
            fraction: 0.25,
            completed_line: 2,
            stop_point_mm: Vector3::new(1.0, 2.0, 3.0),
            motion_done: false,
            axes: vec![PreviewAxis {
                name: "X".into(),
                node: 1,
                now_mm: 1.5,
                stop_mm: Some(1.0),
                reset: true,
            }],
            max_distance_mm: 0.5,
            approach_mm_s: APPROACH_MM_S,
        };
        for (answer, ok) in [("yes\n", true), ("y\n", false), ("\n", false), ("", false)] {
            let mut out = Vec::new();
            let got = ask(&preview, &mut answer.as_bytes(), &mut out);
            assert_eq!(got, ok, "{answer:?}");
            let text = String::from_utf8(out).unwrap();
            assert!(text.contains("resume p.ngc at line 3"), "{text}");
            assert!(
                text.contains(
                    "axis X (node 1)  at 1.5000 mm, 0.5000 mm from the stop point, its drive reset"
                ),
                "{text}"
            );
            assert!(
                text.contains("25.0 % into line 3 (line 2 completed)"),
                "{text}"
            );
            assert!(
                text.contains("move back to the stop point in a straight line at 5 mm/s"),
                "{text}"
            );
        }
    }

    #[test]
    fn text_from_the_file_is_shown_escaped() {
        let m = machine();
        let orig = original(Vector3::zeros());
        let (_, plan) = orig.plan.clone().unwrap();
        let state = ResumeState {
            program: "p\u{1b}[2J.ngc".into(),
            reason: "\u{1b}[2J\u{1b}[1;1Hall clear, \u{202E}safe\r".into(),
            ..orig
                .state_after(&m, &opts(PROGRAM), &failure(stop_at(&plan, 0.5)))
                .unwrap()
        };
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("p.ngc.resume");
        state.save(&file).unwrap();
        let loaded = ResumeState::load(&file).unwrap();
        let preview = ResumePreview {
            program: loaded.program.clone(),
            reason: loaded.reason.clone(),
            line: 3,
            fraction: 0.25,
            completed_line: 2,
            stop_point_mm: Vector3::new(1.0, 2.0, 3.0),
            motion_done: false,
            axes: vec![PreviewAxis {
                name: "X\u{1b}[31m".into(),
                node: 1,
                now_mm: 1.5,
                stop_mm: None,
                reset: false,
            }],
            max_distance_mm: 0.5,
            approach_mm_s: APPROACH_MM_S,
        };
        let text = preview.to_string();
        assert!(!text.contains(['\u{1b}', '\r', '\u{202E}']), "{text:?}");
        assert!(
            text.contains("stopped by      \\u{1b}[2J\\u{1b}[1;1Hall clear, \\u{202e}safe\\r"),
            "{text}"
        );
        assert!(text.contains("resume p\\u{1b}[2J.ngc at line 3"), "{text}");
        assert!(text.contains("axis X\\u{1b}[31m (node 1)"), "{text}");
    }
}
