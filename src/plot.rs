//! `canmotion plan --plot FILE.svg|FILE.png`: the path feed and each axis's velocity,
//! acceleration and jerk against time, by finite differences of the interpolated setpoints (the
//! stream `--setpoints` writes), in four stacked panels with the axis limits as dashed lines.
//! The program is drawn in both modes: the machine's own [`ProfileKind`] and [`other_mode`]
//! (trapezoid against jerk-limited), each run a [`Trace`], two series per quantity, the legend
//! naming each mode with its program time (or why it could not be planned).
//!
//! Memory is bounded whatever the program's length: each run's samples go into at most [`COLUMNS`]
//! time buckets, each keeping the smallest and largest value of every series; when the buckets
//! are full, neighbours merge and each bucket covers twice the time. Every extreme survives the
//! merge, so a one-cycle spike is still drawn.
//!
//! Text is drawn with an embedded font (DejaVu Sans Mono, `assets/fonts/`, under the Bitstream
//! Vera licence with DejaVu's changes in the public domain, see `DejaVu-LICENSE.txt`), so no
//! system font or fontconfig is needed.
//!
//! Units in names: `_mm` millimetres, `_mm_s` mm/s, `_mm_s2` mm/s², `_mm_s3` mm/s³, `_s` seconds.

use std::path::{Path, PathBuf};

use plotters::prelude::*;

use crate::config::Machine;
use crate::planner::ProfileKind;

/// Time buckets kept (about one per pixel column of the plot).
pub const COLUMNS: usize = 1200;

/// Size of the picture in pixels.
const SIZE_PX: (u32, u32) = (1400, 1300);

/// The embedded font.
static FONT: &[u8] = include_bytes!("../assets/fonts/DejaVuSansMono.ttf");

/// Panel titles, top to bottom.
pub const PANEL_TITLES: [&str; 4] = [
    "Path feed (mm/s)",
    "Axis velocity (mm/s)",
    "Axis acceleration (mm/s²)",
    "Axis jerk (mm/s³)",
];

/// The picture's format, from the file's extension.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PlotFormat {
    /// `.svg`
    Svg,
    /// `.png`
    Png,
}

impl PlotFormat {
    /// The format of `file` by its extension (case-insensitive); another extension is an error
    /// naming the flag.
    pub fn of(file: &Path) -> Result<PlotFormat, String> {
        let ext = file
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        match ext.as_deref() {
            Some("svg") => Ok(PlotFormat::Svg),
            Some("png") => Ok(PlotFormat::Png),
            _ => Err(format!(
                "--plot {}: the extension must be .svg or .png",
                file.display()
            )),
        }
    }
}

/// One time bucket: the smallest and largest value of every series in it.
#[derive(Debug, Clone)]
struct Bucket {
    t0_s: f64,
    t1_s: f64,
    lo: Vec<f64>,
    hi: Vec<f64>,
}

impl Bucket {
    fn new(series: usize, t_s: f64) -> Bucket {
        Bucket {
            t0_s: t_s,
            t1_s: t_s,
            lo: vec![f64::INFINITY; series],
            hi: vec![f64::NEG_INFINITY; series],
        }
    }

    fn merge(&mut self, other: &Bucket) {
        self.t1_s = other.t1_s;
        for i in 0..self.lo.len() {
            self.lo[i] = self.lo[i].min(other.lo[i]);
            self.hi[i] = self.hi[i].max(other.hi[i]);
        }
    }
}

/// One run's setpoint stream, cycle by cycle, decimated into at most [`COLUMNS`] buckets.
///
/// Series: 0 the path feed, then per machine axis `k`: `1 + 3k` velocity, `2 + 3k`
/// acceleration, `3 + 3k` jerk.
#[derive(Debug)]
pub struct Trace {
    period_s: f64,
    xyz: Vec<Option<usize>>,
    prev_mm: Option<Vec<f64>>,
    prev_vel_mm_s: Option<Vec<f64>>,
    prev_acc_mm_s2: Option<Vec<f64>>,
    /// Samples (cycles) received.
    samples: u64,
    /// Cycles per bucket.
    width: u64,
    current: Option<(Bucket, u64)>,
    buckets: Vec<Bucket>,
    vel: Vec<f64>,
    acc: Vec<f64>,
}

/// What became of one mode's plan.
#[derive(Debug)]
enum Outcome {
    Planned {
        program_s: f64,
        trace: Box<Trace>,
    },
    /// The plan failed (a typed error, shown by its message); nothing of it is drawn.
    Failed {
        reason: String,
    },
}

/// One mode's run, as the plot shows it.
#[derive(Debug)]
struct Run {
    mode: ProfileKind,
    outcome: Outcome,
}

/// The name of a planner mode in the legend.
pub fn mode_label(mode: ProfileKind) -> &'static str {
    match mode {
        ProfileKind::Trapezoid => "trapezoid",
        ProfileKind::SCurve => "s-curve (jerk-limited)",
        ProfileKind::Smooth => "smooth (jerk-limited)",
    }
}

/// The short name of a mode, after an axis's name in the legend.
fn mode_short(mode: ProfileKind) -> &'static str {
    match mode {
        ProfileKind::Trapezoid => "trapezoid",
        ProfileKind::SCurve => "s-curve",
        ProfileKind::Smooth => "smooth",
    }
}

/// The mode the plot compares a machine's own mode with: the jerk-limited S-curve for a
/// trapezoid machine, the trapezoid for a jerk-limited one.
pub fn other_mode(mode: ProfileKind) -> ProfileKind {
    match mode {
        ProfileKind::Trapezoid => ProfileKind::SCurve,
        ProfileKind::SCurve | ProfileKind::Smooth => ProfileKind::Trapezoid,
    }
}

/// Collects the runs of one program (each mode's [`Trace`]) and draws them together at the end.
#[derive(Debug)]
pub struct PlotRecorder {
    file: PathBuf,
    format: PlotFormat,
    period_s: f64,
    names: Vec<String>,
    xyz: Vec<Option<usize>>,
    max_vel_mm_s: Vec<f64>,
    max_acc_mm_s2: Vec<f64>,
    max_jerk_mm_s3: Vec<f64>,
    runs: Vec<Run>,
}

impl Trace {
    /// An empty trace of `machine`'s axes.
    pub fn new(machine: &Machine) -> Trace {
        let n = machine.axes.len();
        Trace {
            period_s: machine.cycle_s(),
            xyz: machine.axes.iter().map(|a| a.xyz()).collect(),
            prev_mm: None,
            prev_vel_mm_s: None,
            prev_acc_mm_s2: None,
            samples: 0,
            width: 1,
            current: None,
            buckets: Vec::with_capacity(COLUMNS),
            vel: vec![0.0; n],
            acc: vec![0.0; n],
        }
    }

    fn series(&self) -> usize {
        1 + 3 * self.xyz.len()
    }

    fn t_end_s(&self) -> f64 {
        self.buckets.last().map_or(0.0, |b| b.t1_s)
    }
    /// The setpoint of every machine axis for the next cycle.
    pub fn push(&mut self, position_mm: &[f64]) {
        let t_s = self.samples as f64 * self.period_s;
        self.samples += 1;
        let series = self.series();
        let (mut bucket, count) = self
            .current
            .take()
            .unwrap_or_else(|| (Bucket::new(series, t_s), 0));
        bucket.t1_s = t_s;
        if let Some(prev) = &self.prev_mm {
            let mut feed2 = 0.0;
            for k in 0..position_mm.len() {
                self.vel[k] = (position_mm[k] - prev[k]) / self.period_s;
                if self.xyz[k].is_some() {
                    feed2 += self.vel[k] * self.vel[k];
                }
                record(&mut bucket, 1 + 3 * k, self.vel[k]);
            }
            record(&mut bucket, 0, feed2.sqrt());
            if let Some(pv) = &self.prev_vel_mm_s {
                for k in 0..position_mm.len() {
                    self.acc[k] = (self.vel[k] - pv[k]) / self.period_s;
                    record(&mut bucket, 2 + 3 * k, self.acc[k]);
                    if let Some(pa) = &self.prev_acc_mm_s2 {
                        record(
                            &mut bucket,
                            3 + 3 * k,
                            (self.acc[k] - pa[k]) / self.period_s,
                        );
                    }
                }
                match &mut self.prev_acc_mm_s2 {
                    Some(pa) => pa.copy_from_slice(&self.acc),
                    None => self.prev_acc_mm_s2 = Some(self.acc.clone()),
                }
            }
            match &mut self.prev_vel_mm_s {
                Some(pv) => pv.copy_from_slice(&self.vel),
                None => self.prev_vel_mm_s = Some(self.vel.clone()),
            }
        }
        match &mut self.prev_mm {
            Some(p) => p.copy_from_slice(position_mm),
            None => self.prev_mm = Some(position_mm.to_vec()),
        }
        if count + 1 < self.width {
            self.current = Some((bucket, count + 1));
            return;
        }
        self.buckets.push(bucket);
        if self.buckets.len() == COLUMNS {
            // Full: neighbours merge, each bucket now covers twice the time.
            let mut merged = Vec::with_capacity(COLUMNS);
            for pair in self.buckets.chunks(2) {
                let mut b = pair[0].clone();
                if let Some(second) = pair.get(1) {
                    b.merge(second);
                }
                merged.push(b);
            }
            self.buckets = merged;
            self.width *= 2;
        }
    }
}

impl PlotRecorder {
    /// A recorder for `machine`'s axes that will draw into `file` (its extension picks the
    /// format).
    pub fn new(machine: &Machine, file: &Path) -> Result<PlotRecorder, String> {
        let format = PlotFormat::of(file)?;
        Ok(PlotRecorder {
            file: file.to_path_buf(),
            format,
            period_s: machine.cycle_s(),
            names: machine.axes.iter().map(|a| a.name.clone()).collect(),
            xyz: machine.axes.iter().map(|a| a.xyz()).collect(),
            max_vel_mm_s: machine.axes.iter().map(|a| a.max_vel_mm_s).collect(),
            max_acc_mm_s2: machine.axes.iter().map(|a| a.max_acc_mm_s2).collect(),
            max_jerk_mm_s3: machine.axes.iter().map(|a| a.max_jerk_mm_s3).collect(),
            runs: Vec::with_capacity(2),
        })
    }

    /// Adds the run of `mode`, `program_s` long by its plan, sampled into `trace`.
    pub fn add_run(&mut self, mode: ProfileKind, program_s: f64, mut trace: Trace) {
        if let Some((b, _)) = trace.current.take() {
            trace.buckets.push(b);
        }
        self.runs.push(Run {
            mode,
            outcome: Outcome::Planned {
                program_s,
                trace: Box::new(trace),
            },
        });
    }

    /// Records that `mode` could not be planned, and why: the legend says so, the other runs
    /// are drawn as usual.
    pub fn add_failed_run(&mut self, mode: ProfileKind, reason: &str) {
        // One line of the legend: the first line of the message, shortened.
        let mut reason: String = reason
            .lines()
            .next()
            .unwrap_or("")
            .chars()
            .take(90)
            .collect();
        if reason.is_empty() {
            reason.push_str("no reason given");
        }
        self.runs.push(Run {
            mode,
            outcome: Outcome::Failed { reason },
        });
    }

    /// The file the picture is for.
    pub fn file(&self) -> &Path {
        &self.file
    }

    /// Draws the picture: the bytes of the SVG or PNG file. The caller writes them with
    /// [`crate::files::write_output`], like every other output.
    pub fn render(self) -> Result<Vec<u8>, String> {
        static REGISTER: std::sync::Once = std::sync::Once::new();
        REGISTER.call_once(|| {
            // The embedded font is valid: this cannot fail.
            let _ = plotters::style::register_font("sans-serif", FontStyle::Normal, FONT);
        });
        let err = |e: String| format!("{}: cannot draw the plot: {e}", self.file.display());
        match self.format {
            PlotFormat::Svg => {
                let mut svg = String::new();
                {
                    let root = SVGBackend::with_string(&mut svg, SIZE_PX).into_drawing_area();
                    self.draw(&root).map_err(err)?;
                    root.present().map_err(|e| err(e.to_string()))?;
                }
                Ok(svg.into_bytes())
            }
            PlotFormat::Png => {
                let (w, h) = SIZE_PX;
                let mut rgb = vec![0u8; w as usize * h as usize * 3];
                {
                    let root = BitMapBackend::with_buffer(&mut rgb, SIZE_PX).into_drawing_area();
                    self.draw(&root).map_err(err)?;
                    root.present().map_err(|e| err(e.to_string()))?;
                }
                let mut bytes = Vec::new();
                let mut encoder = png::Encoder::new(&mut bytes, w, h);
                encoder.set_color(png::ColorType::Rgb);
                encoder.set_depth(png::BitDepth::Eight);
                // A plot is mostly flat colour: the best compression keeps the file small
                // (about 5× smaller than the default here) at a few tens of ms.
                encoder.set_compression(png::Compression::Best);
                encoder.set_adaptive_filter(png::AdaptiveFilterType::Adaptive);
                let mut writer = encoder.write_header().map_err(|e| err(e.to_string()))?;
                writer
                    .write_image_data(&rgb)
                    .map_err(|e| err(e.to_string()))?;
                writer.finish().map_err(|e| err(e.to_string()))?;
                Ok(bytes)
            }
        }
    }

    /// The runs in drawing order: the trapezoid first, under the jerk-limited run.
    fn ordered_runs(&self) -> Vec<&Run> {
        let mut runs: Vec<&Run> = self.runs.iter().collect();
        runs.sort_by_key(|r| r.mode != ProfileKind::Trapezoid);
        runs
    }

    fn draw<DB: DrawingBackend>(
        &self,
        root: &DrawingArea<DB, plotters::coord::Shift>,
    ) -> Result<(), String>
    where
        DB::ErrorType: 'static,
    {
        let e = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
        root.fill(&WHITE).map_err(e)?;
        let panels = root.split_evenly((4, 1));
        let runs = self.ordered_runs();
        let traces = || {
            runs.iter().filter_map(|r| match &r.outcome {
                Outcome::Planned { trace, .. } => Some(&**trace),
                Outcome::Failed { .. } => None,
            })
        };
        let t_end_s = traces().map(Trace::t_end_s).fold(self.period_s, f64::max);
        let n = self.names.len();
        let max_feed_mm_s = self
            .xyz
            .iter()
            .zip(&self.max_vel_mm_s)
            .filter(|(x, _)| x.is_some())
            .map(|(_, v)| *v)
            .fold(0.0, f64::max);
        for (p, area) in panels.iter().enumerate() {
            // (series, axis label or None for the feed, colour index, limit)
            let lines: Vec<(usize, Option<&str>, usize, f64)> = match p {
                0 => vec![(0, None, FEED, max_feed_mm_s)],
                _ => (0..n)
                    .map(|k| {
                        let limit = match p {
                            1 => self.max_vel_mm_s[k],
                            2 => self.max_acc_mm_s2[k],
                            _ => self.max_jerk_mm_s3[k],
                        };
                        (p + 3 * k, Some(self.names[k].as_str()), k, limit)
                    })
                    .collect(),
            };
            let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
            for (s, _, _, limit) in &lines {
                for b in traces().flat_map(|t| &t.buckets) {
                    if b.lo[*s] <= b.hi[*s] {
                        lo = lo.min(b.lo[*s]);
                        hi = hi.max(b.hi[*s]);
                    }
                }
                hi = hi.max(*limit);
                if p > 0 {
                    lo = lo.min(-*limit);
                }
            }
            if p == 0 {
                lo = 0.0;
            }
            if !(lo.is_finite() && hi.is_finite()) {
                (lo, hi) = (-1.0, 1.0);
            }
            let pad = ((hi - lo) * 0.05).max(1e-9);
            let mut chart = ChartBuilder::on(area)
                .caption(PANEL_TITLES[p], ("sans-serif", 20))
                .margin(8)
                .x_label_area_size(40)
                .y_label_area_size(90)
                .build_cartesian_2d(0.0..t_end_s, (lo - pad)..(hi + pad))
                .map_err(e)?;
            let unit = ["mm/s", "mm/s", "mm/s²", "mm/s³"][p];
            chart
                .configure_mesh()
                .x_desc("time (s)")
                .y_desc(unit)
                .label_style(("sans-serif", 13))
                .draw()
                .map_err(e)?;
            for (s, axis, colour, limit) in &lines {
                for run in &runs {
                    let colour = run_colour(*colour, run.mode);
                    let label = match (axis, &run.outcome) {
                        (None, Outcome::Planned { program_s, .. }) => {
                            // The first run is the machine's mode: its setpoints and summary
                            // are the command's.
                            let own = if std::ptr::eq(*run, &self.runs[0]) {
                                ", the machine's mode"
                            } else {
                                ""
                            };
                            format!("{}: {program_s:.3} s{own}", mode_label(run.mode))
                        }
                        (None, Outcome::Failed { reason }) => {
                            format!("{}: not planned: {reason}", mode_label(run.mode))
                        }
                        (Some(a), _) => format!("{a} {}", mode_short(run.mode)),
                    };
                    let Outcome::Planned { trace, .. } = &run.outcome else {
                        // Named in the feed panel's legend only, with why.
                        if axis.is_none() {
                            chart
                                .draw_series(LineSeries::new(std::iter::empty(), colour))
                                .map_err(e)?
                                .label(label)
                                .legend(move |(x, y)| {
                                    PathElement::new(vec![(x, y), (x + 16, y)], colour)
                                });
                        }
                        continue;
                    };
                    let points = trace
                        .buckets
                        .iter()
                        .filter(|b| b.lo[*s] <= b.hi[*s])
                        .flat_map(|b| {
                            let t = 0.5 * (b.t0_s + b.t1_s);
                            [(t, b.lo[*s]), (t, b.hi[*s])]
                        });
                    chart
                        .draw_series(LineSeries::new(points, colour))
                        .map_err(e)?
                        .label(label)
                        .legend(move |(x, y)| {
                            PathElement::new(vec![(x, y), (x + 16, y)], colour.stroke_width(3))
                        });
                }
                let style = base_colour(*colour).stroke_width(1);
                for v in if p == 0 {
                    vec![*limit]
                } else {
                    vec![*limit, -*limit]
                } {
                    chart
                        .draw_series(DashedLineSeries::new([(0.0, v), (t_end_s, v)], 6, 4, style))
                        .map_err(e)?;
                }
            }
            chart
                .configure_series_labels()
                .background_style(WHITE.mix(0.8))
                .border_style(BLACK)
                .label_font(("sans-serif", 13))
                .draw()
                .map_err(e)?;
        }
        Ok(())
    }
}

/// The colour index of the path feed.
const FEED: usize = usize::MAX;

/// Colours of the axes, in order (more axes than colours reuse them).
const AXIS_COLOURS: [(u8, u8, u8); 6] = [
    (31, 119, 180),
    (214, 39, 40),
    (44, 160, 44),
    (148, 103, 189),
    (255, 127, 14),
    (23, 190, 207),
];

/// The colour of axis `index`, or of the feed ([`FEED`]).
fn base_colour(index: usize) -> RGBColor {
    let (r, g, b) = if index == FEED {
        (40, 40, 40)
    } else {
        AXIS_COLOURS[index % AXIS_COLOURS.len()]
    };
    RGBColor(r, g, b)
}

/// A run's colour: the jerk-limited run in the full colour, the trapezoid run (drawn under it)
/// in a light tint of it, so the two of each series tell apart.
fn run_colour(index: usize, mode: ProfileKind) -> RGBColor {
    let c = base_colour(index);
    match mode {
        ProfileKind::Trapezoid => {
            let tint = |v: u8| ((u16::from(v) * 45 + 255 * 55) / 100) as u8;
            RGBColor(tint(c.0), tint(c.1), tint(c.2))
        }
        ProfileKind::SCurve | ProfileKind::Smooth => c,
    }
}

fn record(b: &mut Bucket, series: usize, v: f64) {
    if v.is_finite() {
        b.lo[series] = b.lo[series].min(v);
        b.hi[series] = b.hi[series].max(v);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn memory_stays_bounded_and_extremes_survive_decimation() {
        let machine = Machine::demo();
        let mut r = PlotRecorder::new(&machine, Path::new("x.svg")).unwrap();
        let n = machine.axes.len();
        // Both modes' runs, each decimated on its own: the recorder holds at most two traces
        // of `COLUMNS` buckets, whatever the programs' lengths.
        for (mode, spike) in [
            (ProfileKind::Trapezoid, 77_777),
            (ProfileKind::SCurve, 12_345),
        ] {
            let mut t = Trace::new(&machine);
            let mut p = vec![0.0; n];
            for c in 0..100_000u64 {
                // X moves 0.1 mm per cycle except one cycle with a 1 mm step.
                p[0] += if c == spike { 1.0 } else { 0.1 };
                t.push(&p);
            }
            assert!(t.buckets.len() <= COLUMNS);
            let peak = t.buckets.iter().map(|b| b.hi[1]).fold(f64::MIN, f64::max);
            assert!((peak - 1.0 / machine.cycle_s()).abs() < 1e-6, "{peak}");
            r.add_run(mode, 100.0, t);
        }
        assert_eq!(r.runs.len(), 2);
        assert_eq!(PlotFormat::of(Path::new("a.PNG")), Ok(PlotFormat::Png));
        assert!(
            PlotFormat::of(Path::new("a.pdf"))
                .unwrap_err()
                .contains("--plot")
        );
    }

    #[test]
    fn a_mode_that_failed_to_plan_is_named_in_the_legend_and_the_other_still_drawn() {
        let machine = Machine::demo();
        let mut r = PlotRecorder::new(&machine, Path::new("x.svg")).unwrap();
        let mut t = Trace::new(&machine);
        let mut p = vec![0.0; machine.axes.len()];
        for c in 0..500 {
            p[0] = 0.0005 * f64::from(c).powi(2);
            t.push(&p);
        }
        r.add_run(ProfileKind::Trapezoid, 0.5, t);
        r.add_failed_run(ProfileKind::SCurve, "p.ngc: no jerk limit\nsecond line");
        let svg = String::from_utf8(r.render().unwrap()).unwrap();
        assert!(svg.contains("trapezoid: 0.500 s"), "{svg}");
        assert!(
            svg.contains("s-curve (jerk-limited): not planned: p.ngc: no jerk limit"),
            "{svg}"
        );
        assert!(!svg.contains("second line"));
    }

    #[test]
    fn the_other_mode_is_the_trapezoid_or_the_s_curve() {
        assert_eq!(other_mode(ProfileKind::Trapezoid), ProfileKind::SCurve);
        assert_eq!(other_mode(ProfileKind::SCurve), ProfileKind::Trapezoid);
        assert_eq!(other_mode(ProfileKind::Smooth), ProfileKind::Trapezoid);
        assert_ne!(
            run_colour(0, ProfileKind::Trapezoid),
            run_colour(0, ProfileKind::SCurve)
        );
    }
}
