//! Offline planning, `canmotion plan`: the whole pipeline up to the setpoints, with no bus.
//!
//! The program streams through the stages (`gcode → compensation → planner → interpolator`) one item
//! at a time, so memory is bounded by the look-ahead windows whatever the file's size. What
//! comes out is a [`PlanSummary`] and, on request, the tool-centre path (JSON Lines) and the
//! setpoints `run` would stream (CSV, one row per cycle).
//!
//! Units in names: `_mm` millimetres, `_mm_s` mm/s, `_s` seconds.

use std::io::BufRead;
use std::path::{Path, PathBuf};

use nalgebra::Vector3;
use serde::Serialize;

use crate::compensation::Compensator;
use crate::config::Machine;
use crate::gateway::{GatewayError, check_element, limits};
use crate::gcode::{Element, ElementKind, Interpreter, Item};
use crate::interpolator::filter::AxisFilter;
use crate::interpolator::{Interpolator, Status};
use crate::planner::{Limits, Planner, PlannerConfig, ProfileKind, Segment, SegmentPath};
use crate::plot::{PlotRecorder, Trace};

/// What to write besides the summary.
#[derive(Debug, Clone, Default)]
pub struct PlanOptions {
    /// The compensated tool-centre path, one JSON object per element per line.
    pub path_out: Option<PathBuf>,
    /// The interpolated setpoints, one CSV row per cycle.
    pub setpoints_out: Option<PathBuf>,
    /// A plot of the setpoints' feed, velocity, acceleration and jerk (`.svg` or `.png`), of
    /// the program planned in the machine's mode and in the other one (trapezoid or
    /// jerk-limited, see [`crate::plot::other_mode`]).
    pub plot_out: Option<PathBuf>,
    /// Feed override applied at planning time, as a fraction (`None`: 100 %): every
    /// programmed feed is scaled by it and capped by the machine's limits as usual; rapids
    /// follow it up to 100 % (they already run at the machine's fastest). Must lie in
    /// `0.01..=2` (see [`check_override`]).
    pub feed_override: Option<f64>,
    /// How many times M99 in the main program (an endless program) restarts it before the
    /// plan ends there ([`crate::gcode::Setup::m99_restarts`]; 0: M99 ends it).
    pub m99_restarts: u32,
}

/// Largest planning-time feed override (200 %).
pub const MAX_PLAN_OVERRIDE: f64 = 2.0;

/// A fraction shown as a percentage, to at most two decimals with trailing zeros dropped:
/// `Percent(2.01)` is `201`, `Percent(0.505)` is `50.5` (never `200.99999999999997`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Percent(pub f64);

impl std::fmt::Display for Percent {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let s = format!("{:.2}", self.0 * 100.0);
        let s = if s.contains('.') {
            s.trim_end_matches('0').trim_end_matches('.')
        } else {
            &s
        };
        f.write_str(if s == "-0" { "0" } else { s })
    }
}

/// Checks a planning-time override fraction: finite, 1 % to 200 %.
pub fn check_override(fraction: f64) -> Result<f64, String> {
    if (0.01..=MAX_PLAN_OVERRIDE).contains(&fraction) {
        Ok(fraction)
    } else {
        Err(format!(
            "feed override {} % must be between 1 % and {} %",
            Percent(fraction),
            Percent(MAX_PLAN_OVERRIDE)
        ))
    }
}

/// What a plan amounts to.
#[derive(Debug, Clone, PartialEq)]
pub struct PlanSummary {
    /// The planning-time feed override, when one was given.
    pub feed_override: Option<f64>,
    /// Motion elements of the tool-centre path (lines and arcs, rapids included).
    pub elements: u64,
    /// Of which rapids (G0, G28/G30 moves).
    pub rapids: u64,
    /// Of which arcs and helices.
    pub arcs: u64,
    /// Path length of all elements.
    pub length_mm: f64,
    /// Path length of the feed moves only.
    pub feed_length_mm: f64,
    /// Time the program takes (motion, dwells), from the plan.
    pub program_s: f64,
    /// Highest path speed of a feed move in the plan.
    pub max_feed_mm_s: f64,
    /// Highest path speed of a rapid in the plan.
    pub max_rapid_mm_s: f64,
    /// Dwells (G4) and program stops (M0/M1).
    pub dwells: u64,
    /// See `dwells`.
    pub stops: u64,
    /// Words accepted without a motion effect (spindle, coolant, tools).
    pub notes: u64,
    /// Smallest and largest machine coordinates the tool centre reaches.
    pub bounds_mm: Option<(Vector3<f64>, Vector3<f64>)>,
    /// Setpoint rows written (cycles), when setpoints were asked for.
    pub cycles: Option<u64>,
}

/// Why `plan` failed: the program (with its place), the machine, or an output file.
#[derive(Debug, thiserror::Error)]
pub enum OfflineError {
    /// The program or the machine refused it (parse error, travel, planning).
    #[error(transparent)]
    Gateway(#[from] GatewayError),
    /// An output file could not be written (or is a directory).
    #[error(transparent)]
    File(#[from] crate::files::FileError),
    /// The plot could not be made (its extension, or drawing it).
    #[error("{0}")]
    Plot(String),
    /// The feed override is out of range.
    #[error("{0}")]
    Override(String),
    /// A planned segment did not continue the motion (a planner bug, reported, never sampled).
    #[error("{file}: {source}")]
    Sampling {
        /// Program file.
        file: String,
        /// Why.
        source: crate::interpolator::InterpError,
    },
}

/// One line of the `--path` output.
#[derive(Serialize)]
struct PathRecord {
    line: usize,
    kind: &'static str,
    rapid: bool,
    start: [f64; 3],
    end: [f64; 3],
    #[serde(skip_serializing_if = "Option::is_none")]
    center: Option<[f64; 3]>,
    #[serde(skip_serializing_if = "Option::is_none")]
    normal: Option<[f64; 3]>,
    #[serde(skip_serializing_if = "Option::is_none")]
    cw: Option<bool>,
    feed_mm_s: f64,
    /// The machine's auxiliary axes, `"A": [start, end]` (degrees, modulo 360 on a wrapped
    /// axis; U V W in mm); none on an X/Y/Z machine.
    #[serde(flatten)]
    aux: std::collections::BTreeMap<&'static str, [f64; 2]>,
}

/// The names of the auxiliary axes in the `--path` output.
const AUX_NAMES: [&str; 6] = ["A", "B", "C", "U", "V", "W"];

/// The machine's auxiliary axes: their index in [`crate::gcode::AuxPos`] and whether they
/// wrap.
fn aux_columns(machine: &Machine) -> Vec<(usize, bool)> {
    machine
        .axes
        .iter()
        .filter_map(|a| a.aux().map(|i| (i, a.wrap)))
        .collect()
}

/// A wrapped rotary axis's position as shown: modulo 360° (LinuxCNC's WRAPPED_ROTARY).
fn shown(value: f64, wrap: bool) -> f64 {
    if wrap { value.rem_euclid(360.0) } else { value }
}

fn xyz(v: &Vector3<f64>) -> [f64; 3] {
    [v.x, v.y, v.z]
}

/// An output file: see [`crate::files::Output`] (atomic for a regular file, in place through a
/// symlink or to a device, a directory refused).
type Out = crate::files::Output;

fn json_err(out: &Out, e: serde_json::Error) -> OfflineError {
    OfflineError::File(crate::files::FileError::Write {
        path: out.path().to_path_buf(),
        source: e.into(),
    })
}

/// Plans `reader` (named `name` in messages) on `machine` from `start_mm`, streaming, and writes
/// what `opts` asks for. Nothing is written past the first error, which names the file, line
/// and column.
pub fn plan_stream<R: BufRead>(
    machine: &Machine,
    reader: R,
    name: &str,
    start_mm: Vector3<f64>,
    opts: &PlanOptions,
) -> Result<PlanSummary, OfflineError> {
    let mut setup = machine.setup(start_mm);
    setup.m99_restarts = opts.m99_restarts;
    let interpreter = Compensator::new(
        Interpreter::new(reader, name, setup),
        name,
        machine.program.compensation,
    );
    let scale = opts.feed_override.unwrap_or(1.0);
    check_override(scale).map_err(OfflineError::Override)?;
    let mut plan_limits = limits(machine);
    // Rapids run at `max_feed`: scaling it scales them, and caps the scaled feeds below 100 %
    // exactly as the unscaled ones were capped (`min(x·f, x·max) = x·min(f, max)`).
    plan_limits.max_feed_mm_s *= scale.min(1.0);
    let mut planner =
        Planner::with_config(start_mm, &plan_limits, &machine.planner).map_err(|source| {
            GatewayError::Plan {
                file: name.to_string(),
                source,
            }
        })?;
    let mut path_out = opts.path_out.as_deref().map(Out::create).transpose()?;
    let aux_cols = aux_columns(machine);
    let mut plot = opts
        .plot_out
        .as_deref()
        .map(|file| -> Result<PlotRecorder, OfflineError> {
            // Refused before planning, not after.
            crate::files::check_output(file)?;
            PlotRecorder::new(machine, file).map_err(OfflineError::Plot)
        })
        .transpose()?;
    let mut setpoints = if opts.setpoints_out.is_some() || plot.is_some() {
        Some(Setpoints::new(
            machine,
            opts.setpoints_out.as_deref(),
            plot.as_ref().map(|_| Trace::new(machine)),
            start_mm,
            name,
            planner.smoothing(),
        )?)
    } else {
        None
    };
    // The same program in the other mode, for the plot only: planned from the same items, side
    // by side, so a program read once (stdin) is planned twice too. Its failure is shown in the
    // plot, never the command's.
    let mut other = plot
        .as_ref()
        .map(|_| OtherMode::new(machine, &plan_limits, start_mm, name));
    let mut summary = PlanSummary {
        feed_override: opts.feed_override,
        elements: 0,
        rapids: 0,
        arcs: 0,
        length_mm: 0.0,
        feed_length_mm: 0.0,
        program_s: 0.0,
        max_feed_mm_s: 0.0,
        max_rapid_mm_s: 0.0,
        dwells: 0,
        stops: 0,
        notes: 0,
        bounds_mm: None,
        cycles: None,
    };
    for item in interpreter {
        let item = item.map_err(GatewayError::from)?;
        match &item {
            Item::Motion(e) => {
                check_element(machine, name, e)?;
                summary.add_element(e);
                if let Some(out) = path_out.as_mut() {
                    write_path_record(out, e, &aux_cols)?;
                }
            }
            Item::Dwell(_) => summary.dwells += 1,
            Item::Stop(_) => summary.stops += 1,
            Item::Note(_) => summary.notes += 1,
            Item::End(_) => {}
        }
        let item = match item {
            Item::Motion(mut e) if scale != 1.0 => {
                e.feed_mm_s = e.feed_mm_s.map(|f| f * scale);
                Item::Motion(e)
            }
            other => other,
        };
        planner.push(&item).map_err(|source| GatewayError::Plan {
            file: name.to_string(),
            source,
        })?;
        while let Some(seg) = planner.pop() {
            summary.add_segment(&seg);
            if let Some(sp) = setpoints.as_mut() {
                sp.push(seg)?;
            }
        }
        if let Some(Ok(o)) = other.as_mut()
            && let Err(e) = o.push(&item)
        {
            other = Some(Err((o.mode, e.to_string())));
        }
    }
    planner.finish().map_err(|source| GatewayError::Plan {
        file: name.to_string(),
        source,
    })?;
    while let Some(seg) = planner.pop() {
        summary.add_segment(&seg);
        if let Some(sp) = setpoints.as_mut() {
            sp.push(seg)?;
        }
    }
    summary.program_s = planner.time_s();
    if let Some(sp) = setpoints {
        let (cycles, trace) = sp.finish()?;
        if opts.setpoints_out.is_some() {
            summary.cycles = Some(cycles);
        }
        if let (Some(plot), Some(trace)) = (plot.as_mut(), trace) {
            plot.add_run(machine.planner.profile, summary.program_s, trace);
        }
    }
    if let Some(mut plot) = plot {
        match other.map(|o| o.and_then(OtherMode::finish)) {
            Some(Ok((mode, program_s, trace))) => plot.add_run(mode, program_s, trace),
            Some(Err((mode, reason))) => plot.add_failed_run(mode, &reason),
            None => {}
        }
        let file = plot.file().to_path_buf();
        let bytes = plot.render().map_err(OfflineError::Plot)?;
        crate::files::write_output(&file, &bytes)?;
    }
    if let Some(out) = path_out {
        out.finish()?;
    }
    Ok(summary)
}

/// Plans a program file; see [`plan_stream`].
pub fn plan_file(
    machine: &Machine,
    program: &Path,
    start_mm: Vector3<f64>,
    opts: &PlanOptions,
) -> Result<PlanSummary, OfflineError> {
    let name = program.display().to_string();
    // A regular file only: a FIFO would block, a device never end.
    let file = crate::files::open_input(program)?;
    plan_stream(
        machine,
        std::io::BufReader::with_capacity(1 << 16, file),
        &name,
        start_mm,
        opts,
    )
}

fn write_path_record(
    out: &mut Out,
    e: &Element,
    aux_cols: &[(usize, bool)],
) -> Result<(), OfflineError> {
    let (kind, center, normal, cw) = match e.kind {
        ElementKind::Line => ("line", None, None, None),
        ElementKind::Arc {
            center_mm,
            normal,
            cw,
            ..
        } => ("arc", Some(xyz(&center_mm)), Some(xyz(&normal)), Some(cw)),
    };
    let record = PathRecord {
        line: e.line,
        kind,
        rapid: e.rapid,
        start: xyz(&e.start_mm),
        end: xyz(&e.end_mm),
        center,
        normal,
        cw,
        // Rapids have no programmed feed: 0 in the file, the planner uses the machine's.
        feed_mm_s: e.feed_mm_s.unwrap_or(0.0),
        aux: aux_cols
            .iter()
            .map(|&(i, wrap)| {
                (
                    AUX_NAMES[i],
                    [shown(e.aux.start[i], wrap), shown(e.aux.end[i], wrap)],
                )
            })
            .collect(),
    };
    let mut line = serde_json::to_vec(&record).map_err(|e| json_err(out, e))?;
    line.push(b'\n');
    Ok(out.write_all(&line)?)
}

impl PlanSummary {
    /// The summary as `plan` prints it.
    pub fn report(&self, machine: &Machine) -> String {
        let mut s = format!(
            "elements      {} ({} rapids, {} arcs), {} dwells, {} program stops, {} notes\n",
            self.elements, self.rapids, self.arcs, self.dwells, self.stops, self.notes
        );
        s += &format!(
            "length        {:.3} mm ({:.3} mm at feed)\n",
            self.length_mm, self.feed_length_mm
        );
        match self.feed_override {
            Some(x) => {
                s += &format!(
                    "program time  {:.3} s at {} % feed override\n",
                    self.program_s,
                    Percent(x)
                )
            }
            None => s += &format!("program time  {:.3} s\n", self.program_s),
        }
        s += &format!(
            "max feed      {:.3} mm/s ({:.0} mm/min); rapids up to {:.3} mm/s\n",
            self.max_feed_mm_s,
            self.max_feed_mm_s * 60.0,
            self.max_rapid_mm_s
        );
        if let Some((lo, hi)) = self.bounds_mm {
            s += "extent       ";
            for (i, letter) in ["X", "Y", "Z"].iter().enumerate() {
                s += &format!(" {letter} [{:.3}, {:.3}]", lo[i], hi[i]);
            }
            s += " mm\n";
        }
        if let Some(cycles) = self.cycles {
            s += &format!("setpoints     {cycles} cycles of {} µs\n", machine.cycle_us);
        }
        s
    }

    fn add_element(&mut self, e: &Element) {
        let length_mm = e.length_mm();
        self.elements += 1;
        self.length_mm += length_mm;
        if e.rapid {
            self.rapids += 1;
        } else {
            self.feed_length_mm += length_mm;
        }
        if matches!(e.kind, ElementKind::Arc { .. }) {
            self.arcs += 1;
        }
        let (lo, hi) = e.bounds_mm();
        let (lo, hi) = (lo.inf(&e.start_mm), hi.sup(&e.start_mm));
        self.bounds_mm = Some(match self.bounds_mm {
            Some((l, h)) => (l.inf(&lo), h.sup(&hi)),
            None => (lo, hi),
        });
    }

    fn add_segment(&mut self, s: &Segment) {
        if matches!(s.path, SegmentPath::Line { .. } | SegmentPath::Arc(_)) {
            let max = if s.rapid {
                &mut self.max_rapid_mm_s
            } else {
                &mut self.max_feed_mm_s
            };
            *max = max.max(s.v_peak_mm_s);
        }
    }
}

/// The `--setpoints` writer: samples segments as they settle, one row per cycle, each axis
/// through its post-interpolation filter as `run` streams it, until every filter has settled,
/// into the CSV file and the plot, whichever were asked for.
struct Setpoints {
    out: Option<Out>,
    plot: Option<Trace>,
    /// The row being written, one position per machine axis.
    row_mm: Vec<f64>,
    interp: Interpolator,
    /// For each machine axis, its X/Y/Z index (`None`: held at its start).
    axes: Vec<Option<usize>>,
    /// For each machine axis, its index among the auxiliary axes.
    aux: Vec<Option<usize>>,
    held_mm: Vec<f64>,
    filters: Vec<Option<AxisFilter>>,
    period_s: f64,
    cycle: u64,
    name: String,
}

impl Setpoints {
    fn new(
        machine: &Machine,
        file: Option<&Path>,
        plot: Option<Trace>,
        start_mm: Vector3<f64>,
        name: &str,
        smoothing: Option<crate::planner::Smoothing>,
    ) -> Result<Setpoints, OfflineError> {
        let mut out = file.map(Out::create).transpose()?;
        let period_s = machine.cycle_s();
        let mut interp = Interpolator::streaming(start_mm, period_s).map_err(|source| {
            OfflineError::Sampling {
                file: name.to_string(),
                source,
            }
        })?;
        if let Some(spec) = smoothing {
            interp = interp.with_smoothing(spec);
        }
        let mut header = String::from("cycle,t_s");
        for a in &machine.axes {
            let unit = match a.kind {
                crate::config::AxisKind::Rotary => "deg",
                crate::config::AxisKind::Linear => "mm",
            };
            header.push_str(&format!(",{}_{unit}", a.name));
        }
        header.push('\n');
        if let Some(out) = out.as_mut() {
            out.write_all(header.as_bytes())?;
        }
        let mut filters = Vec::with_capacity(machine.axes.len());
        for a in &machine.axes {
            let filter = a
                .filter
                .map(|spec| AxisFilter::new(spec, period_s))
                .transpose()
                .map_err(|e| {
                    GatewayError::Config(crate::config::ConfigError::Invalid {
                        file: machine.file.clone(),
                        table: format!("axis {}", a.name),
                        key: "filter.time_ms".into(),
                        message: e.to_string(),
                    })
                })?;
            filters.push(filter.map(|mut f| {
                f.reset(a.xyz().map_or(0.0, |k| start_mm[k]));
                f
            }));
        }
        let mut sp = Setpoints {
            out,
            plot,
            row_mm: vec![0.0; machine.axes.len()],
            interp,
            axes: machine.axes.iter().map(|a| a.xyz()).collect(),
            aux: machine.axes.iter().map(|a| a.aux()).collect(),
            held_mm: vec![0.0; machine.axes.len()],
            filters,
            period_s,
            cycle: 0,
            name: name.to_string(),
        };
        // Row 0: where the machine is when the motion starts.
        sp.row(start_mm)?;
        Ok(sp)
    }

    fn push(&mut self, seg: Segment) -> Result<(), OfflineError> {
        self.interp
            .push(seg)
            .map_err(|source| OfflineError::Sampling {
                file: self.name.clone(),
                source,
            })?;
        self.drain()
    }

    /// Samples every cycle that the queued segments cover.
    fn drain(&mut self) -> Result<(), OfflineError> {
        let mut p = Vector3::zeros();
        while !self.interp.needs_segments() {
            match self.interp.update(&mut p) {
                Status::Working { .. } | Status::Held { .. } => self.row(p)?,
                Status::Finished => {
                    self.row(p)?;
                    break;
                }
                Status::Starved => break,
            }
        }
        Ok(())
    }

    fn row(&mut self, p: Vector3<f64>) -> Result<(), OfflineError> {
        let aux = self.interp.aux();
        for (i, axis) in self.axes.iter().enumerate() {
            let v = match (axis, self.aux[i], aux) {
                (Some(k), ..) => p[*k],
                (None, Some(j), Some(aux)) => aux[j],
                _ => self.held_mm[i],
            };
            self.row_mm[i] = self.filters[i].as_mut().map_or(v, |f| f.update(v));
        }
        if let Some(plot) = self.plot.as_mut() {
            plot.push(&self.row_mm);
        }
        let cycle = self.cycle;
        self.cycle += 1;
        let Some(out) = self.out.as_mut() else {
            return Ok(());
        };
        let mut s = format!("{},{:.6}", cycle, cycle as f64 * self.period_s);
        for v in &self.row_mm {
            s.push_str(&format!(",{v:.6}"));
        }
        s.push('\n');
        Ok(out.write_all(s.as_bytes())?)
    }

    /// Ends the stream: the cycles written, and the plot's trace if there is one.
    fn finish(mut self) -> Result<(u64, Option<Trace>), OfflineError> {
        self.interp.close();
        self.drain()?;
        // The end waits for the filters, as in `run`: their output reaches the end exactly.
        while !self.filters.iter().flatten().all(AxisFilter::is_settled) {
            self.row(self.interp.last_mm())?;
        }
        let cycles = self.cycle;
        if let Some(out) = self.out {
            out.finish()?;
        }
        Ok((cycles, self.plot))
    }
}

/// The program planned and sampled a second time in the other mode, for the plot: the same
/// machine and limits, only [`PlannerConfig::profile`] differs.
struct OtherMode {
    mode: ProfileKind,
    planner: Planner,
    setpoints: Setpoints,
    name: String,
}

/// What [`OtherMode`] keeps of a failure: its mode, and the message.
type OtherFailure = (ProfileKind, String);

impl OtherMode {
    fn new(
        machine: &Machine,
        plan_limits: &Limits,
        start_mm: Vector3<f64>,
        name: &str,
    ) -> Result<OtherMode, OtherFailure> {
        let mode = crate::plot::other_mode(machine.planner.profile);
        let config = PlannerConfig {
            profile: mode,
            ..machine.planner
        };
        let fail = |e: OfflineError| (mode, e.to_string());
        let planner = Planner::with_config(start_mm, plan_limits, &config)
            .map_err(|source| {
                OfflineError::from(GatewayError::Plan {
                    file: name.to_string(),
                    source,
                })
            })
            .map_err(fail)?;
        let setpoints = Setpoints::new(
            machine,
            None,
            Some(Trace::new(machine)),
            start_mm,
            name,
            planner.smoothing(),
        )
        .map_err(fail)?;
        Ok(OtherMode {
            mode,
            planner,
            setpoints,
            name: name.to_string(),
        })
    }

    fn plan_error(&self, source: crate::planner::PlanError) -> OfflineError {
        GatewayError::Plan {
            file: self.name.clone(),
            source,
        }
        .into()
    }

    fn push(&mut self, item: &Item) -> Result<(), OfflineError> {
        self.planner.push(item).map_err(|e| self.plan_error(e))?;
        while let Some(seg) = self.planner.pop() {
            self.setpoints.push(seg)?;
        }
        Ok(())
    }

    /// Ends the plan: its mode, program time and trace.
    fn finish(mut self) -> Result<(ProfileKind, f64, Trace), OtherFailure> {
        let mode = self.mode;
        let result: Result<_, OfflineError> = (|| {
            self.planner.finish().map_err(|e| self.plan_error(e))?;
            while let Some(seg) = self.planner.pop() {
                self.setpoints.push(seg)?;
            }
            let program_s = self.planner.time_s();
            let (_, trace) = self.setpoints.finish()?;
            Ok((program_s, trace))
        })();
        match result {
            Ok((program_s, Some(trace))) => Ok((mode, program_s, trace)),
            // Not reached: `new` gives the setpoints a trace.
            Ok((_, None)) => Err((mode, "no trace was kept".into())),
            Err(e) => Err((mode, e.to_string())),
        }
    }
}
