//! The feed optimiser, `canmotion optimize` (source 002, Chen De-cun): lower a program's F words
//! so that every feed move respects the machine's per-axis velocity and acceleration limits,
//! and write the program back, byte for byte, except the F words that change.
//!
//! Pure: text in, text out plus an [`OptimizeReport`]. The geometry of every move comes from the
//! crate's own interpreter ([`crate::gcode::Interpreter`] on [`Machine::setup`]), so offsets,
//! units, arcs, subroutines and loops are read exactly as `plan` and `run` read them. The path
//! is the programmed one (cutter compensation does not change which feed a block may have).
//!
//! # The limits, per block
//!
//! Units in names: `_mm` millimetres, `_mm_s` mm/s, `_mm_s2` mm/s². `u` is a block's unit
//! direction (for an arc: its unit tangent), `v_max_i`, `a_max_i` the limits of axis `i`.
//!
//! 1. **Velocity.** A line's feed F moves axis `i` at `F·|u_i|`, so `F ≤ min_i v_max_i / |u_i|`.
//!    An arc's tangent turns: the worst tangent over the arc's extent counts (the largest
//!    `|t_i|` the arc reaches, found from the circle's extreme angles).
//! 2. **Acceleration between blocks** (002's two passes). Axis `i` of block `k` runs at
//!    `v_k,i = F_k·u_k,i`. From `v² = v0² + 2a(x − x0)` with the axis limit, the axis can only
//!    change its speed between neighbouring blocks by what its travel in the block allows:
//!    - forward pass, first block to last, the speed reached entering block `k` from block
//!      `k−1`: `v_k,i² ≤ v_k−1,i² + 2·a_max_i·|Δx_k,i|`;
//!    - backward pass, last block to first, the same comparison from block `k+1` back to `k`
//!      (the deceleration out of block `k`): `v_k,i² ≤ v_k+1,i² + 2·a_max_i·|Δx_k,i|`,
//!
//!    where `Δx_k,i` is the axis's travel in block `k` (`L_k·|u_k,i|`; for an arc, `L_k` times
//!    the tangent at the end concerned) and the neighbour's speed counts only when the axis keeps
//!    its direction. 002 splits one speed change between two blocks whose axis speeds have
//!    opposite signs; here an axis that reverses goes through zero inside the block, so the
//!    block must reach its speed from (or come back to) rest: `v_k,i² ≤ 2·a_max_i·|Δx_k,i|`, the
//!    stricter of the two readings. A block after (before) a rapid, a dwell, a stop, an
//!    inverse-time block or the program's start (end) is entered (left) from rest.
//!
//!    Lowering one block only ever lowers the bound of its neighbours, so the two passes repeat
//!    until nothing changes; a short block lowers its neighbours to a ramp
//!    `F_k−1² = F_k² + 2·a·L_k−1` (for one axis on a straight line).
//!
//! A feed is never raised. G93 (inverse time) blocks are left alone and reported. Rapids have
//! no F. Each changed F is written in the units in force on its line (G20: inch/min, four
//! decimals; G21: mm/min, three decimals), rounded down. Since F is modal, a line that relied on
//! the F of a line whose F changed gets its own F word, with its original value.

use std::collections::BTreeMap;
use std::fmt;

use nalgebra::Vector3;

use crate::config::Machine;
use crate::gcode::{Element, ElementKind, Error, Interpreter, Item, MM_PER_INCH};

/// What to write besides the new F words.
#[derive(Debug, Clone, Copy)]
pub struct OptimizeOptions {
    /// Follow each changed F by a comment with the value it replaced, e.g.
    /// `F600 (canmotion optimize: was F1200)`.
    pub trace: bool,
}

impl Default for OptimizeOptions {
    fn default() -> Self {
        OptimizeOptions { trace: true }
    }
}

/// Why a block's feed was lowered.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Cause {
    /// An axis's velocity limit (X = 0, Y = 1, Z = 2).
    Velocity(usize),
    /// An axis's acceleration limit between neighbouring blocks.
    Acceleration(usize),
}

impl fmt::Display for Cause {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Cause::Velocity(i) => write!(f, "{} velocity limit", AXES[*i]),
            Cause::Acceleration(i) => write!(f, "{} acceleration limit", AXES[*i]),
        }
    }
}

const AXES: [char; 3] = ['X', 'Y', 'Z'];

/// The largest reduction of a feed.
#[derive(Debug, Clone, PartialEq)]
pub struct Reduction {
    /// 1-based source line.
    pub line: usize,
    /// The feed the line had, in mm/s.
    pub from_mm_s: f64,
    /// The feed written, in mm/s.
    pub to_mm_s: f64,
    /// What limited it.
    pub cause: Cause,
}

/// What the optimiser did.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct OptimizeReport {
    /// Feed moves (G1/G2/G3 elements) examined, G93 ones included.
    pub blocks_examined: u64,
    /// Lines whose feed was lowered.
    pub lines_lowered: u64,
    /// Lines that got an F word with their original feed, because the modal F they relied on
    /// changed.
    pub lines_feed_kept: u64,
    /// Lines of G93 (inverse time) feed moves, left alone.
    pub inverse_time_lines: Vec<usize>,
    /// Lines calling subroutine files whose feed moves were left alone (their F words are in
    /// another file).
    pub subroutine_file_lines: Vec<usize>,
    /// Lines of feed moves of the auxiliary axes (A B C U V W), left alone: the passes know
    /// the X/Y/Z limits only.
    pub aux_axis_lines: Vec<usize>,
    /// The largest relative reduction.
    pub largest: Option<Reduction>,
}

impl OptimizeReport {
    /// The summary as `canmotion optimize` prints it.
    pub fn summary(&self) -> String {
        let mut s = format!(
            "blocks examined   {}\nlines lowered     {}\n",
            self.blocks_examined, self.lines_lowered
        );
        if self.lines_feed_kept > 0 {
            s += &format!(
                "F kept            {} line(s) got an F word with their original feed (the modal F they relied on changed)\n",
                self.lines_feed_kept
            );
        }
        if let Some(r) = &self.largest {
            s += &format!(
                "largest reduction line {}: {:.3} -> {:.3} mm/min (-{:.1} %), {}\n",
                r.line,
                r.from_mm_s * 60.0,
                r.to_mm_s * 60.0,
                100.0 * (1.0 - r.to_mm_s / r.from_mm_s),
                r.cause
            );
        }
        if let Some(first) = self.inverse_time_lines.first() {
            s += &format!(
                "inverse time      {} G93 line(s) left alone (first: line {first}): their F is a time, not a feed\n",
                self.inverse_time_lines.len()
            );
        }
        if let Some(first) = self.aux_axis_lines.first() {
            s += &format!(
                "A B C U V W       {} feed move(s) of the auxiliary axes left alone (first: line {first}): the feed optimiser knows the X/Y/Z limits only\n",
                self.aux_axis_lines.len()
            );
        }
        if let Some(first) = self.subroutine_file_lines.first() {
            s += &format!(
                "subroutine files  the feed moves of {} call(s) left alone (first: line {first}): their F words are in the subroutine's file\n",
                self.subroutine_file_lines.len()
            );
        }
        s
    }
}

/// The optimised program and what was done.
#[derive(Debug, Clone, PartialEq)]
pub struct Optimized {
    /// The program with its new F words (bytes: a Latin-1 comment is kept as it was).
    pub text: Vec<u8>,
    /// What changed.
    pub report: OptimizeReport,
}

/// Per-axis limits on X, Y, Z (`None`: the machine has no such axis; moving it is `plan`'s error).
struct AxisLimits {
    vel_mm_s: [Option<f64>; 3],
    acc_mm_s2: [Option<f64>; 3],
}

impl AxisLimits {
    fn of(machine: &Machine) -> AxisLimits {
        let mut l = AxisLimits {
            vel_mm_s: [None; 3],
            acc_mm_s2: [None; 3],
        };
        for ax in &machine.axes {
            if let Some(i) = ax.xyz() {
                let v = l.vel_mm_s[i].map_or(ax.max_vel_mm_s, |v: f64| v.min(ax.max_vel_mm_s));
                let a = l.acc_mm_s2[i].map_or(ax.max_acc_mm_s2, |a: f64| a.min(ax.max_acc_mm_s2));
                l.vel_mm_s[i] = Some(v);
                l.acc_mm_s2[i] = Some(a);
            }
        }
        l
    }
}

/// A tangent component below this counts as zero (the axis does not move).
const TANGENT_EPS: f64 = 1e-9;

/// A feed move that takes part in the passes.
struct Block {
    line: usize,
    /// The feed programmed (mm/s).
    programmed_mm_s: f64,
    /// The feed allowed so far (mm/s).
    feed_mm_s: f64,
    cause: Option<Cause>,
    length_mm: f64,
    start_tangent: Vector3<f64>,
    end_tangent: Vector3<f64>,
    /// Entered from rest (the previous item was no feed move of the passes).
    after_rest: bool,
    /// Left to rest.
    before_rest: bool,
    inch: bool,
}

/// Relative slack before a feed counts as over a bound (rounding of the written F words).
const REL_TOL: f64 = 1e-7;
/// Absolute slack (mm/s): a thousandth of a mm/min.
const ABS_TOL_MM_S: f64 = 1e-3 / 60.0;

fn over(feed_mm_s: f64, bound_mm_s: f64) -> bool {
    feed_mm_s > bound_mm_s * (1.0 + REL_TOL) + ABS_TOL_MM_S
}

/// The largest `|t_i|` an element's tangent reaches, per axis.
fn worst_tangent(e: &Element) -> Vector3<f64> {
    match e.arc() {
        None => {
            let d = e.end_mm - e.start_mm;
            let n = d.norm();
            if n > 0.0 {
                (d / n).abs()
            } else {
                Vector3::zeros()
            }
        }
        Some(arc) => {
            let mut worst = arc.tangent_at(0.0).abs().sup(&arc.tangent_at(1.0).abs());
            for i in 0..3 {
                // The circle's part of t_i is ∝ −u_i sin θ + v_i cos θ = A cos(θ − φ).
                let phi = (-arc.u[i]).atan2(arc.v[i]);
                let mut theta = phi.rem_euclid(std::f64::consts::PI);
                while theta <= arc.sweep_rad {
                    worst = worst.sup(&arc.tangent_at(theta / arc.sweep_rad).abs());
                    theta += std::f64::consts::PI;
                }
            }
            worst
        }
    }
}

fn tangents(e: &Element) -> (Vector3<f64>, Vector3<f64>) {
    match (e.kind, e.arc()) {
        (ElementKind::Arc { .. }, Some(arc)) => (arc.tangent_at(0.0), arc.tangent_at(1.0)),
        _ => {
            let d = e.end_mm - e.start_mm;
            let n = d.norm();
            let u = if n > 0.0 { d / n } else { Vector3::zeros() };
            (u, u)
        }
    }
}

/// The acceleration bound on a block's feed (mm/s) from a neighbour's axis speeds: `own` is
/// the block's tangent at the shared end, `theirs` the neighbour's there with its feed
/// (`None`: rest).
fn accel_bound(
    lim: &AxisLimits,
    length_mm: f64,
    own: &Vector3<f64>,
    neighbour: Option<(&Vector3<f64>, f64)>,
) -> Option<(f64, usize)> {
    let mut best: Option<(f64, usize)> = None;
    for i in 0..3 {
        let s = own[i].abs();
        let Some(a) = lim.acc_mm_s2[i] else { continue };
        if s < TANGENT_EPS {
            continue;
        }
        let from_mm_s = match neighbour {
            Some((t, f)) if t[i] * own[i] > 0.0 => f * t[i].abs(),
            _ => 0.0,
        };
        let v_mm_s = (from_mm_s * from_mm_s + 2.0 * a * length_mm * s).sqrt();
        let bound = v_mm_s / s;
        if best.is_none_or(|(b, _)| bound < b) {
            best = Some((bound, i));
        }
    }
    best
}

/// Lowers the feeds of `blocks` to the velocity and acceleration limits (see the module docs).
/// One step of a pass: lowers block `k`'s feed to what each axis's acceleration allows from
/// its neighbour (the previous block going forward, the next going backward; none across a
/// rest). Whether it changed.
fn lower_to_bound(lim: &AxisLimits, blocks: &mut [Block], k: usize, forward: bool) -> bool {
    let b = &blocks[k];
    let (tangent, neighbour) = if forward {
        let prev = (!b.after_rest && k > 0).then(|| &blocks[k - 1]);
        (
            &b.start_tangent,
            prev.map(|p| (&p.end_tangent, p.feed_mm_s)),
        )
    } else {
        let next = (!b.before_rest && k + 1 < blocks.len()).then(|| &blocks[k + 1]);
        (
            &b.end_tangent,
            next.map(|n| (&n.start_tangent, n.feed_mm_s)),
        )
    };
    match accel_bound(lim, b.length_mm, tangent, neighbour) {
        Some((bound, axis)) if over(b.feed_mm_s, bound) => {
            blocks[k].feed_mm_s = bound;
            blocks[k].cause = Some(Cause::Acceleration(axis));
            true
        }
        _ => false,
    }
}

fn run_passes(lim: &AxisLimits, blocks: &mut [Block]) {
    // At most this many forward + backward sweeps; each lowering is by more than the tolerance,
    // so the passes end, and in practice within a few sweeps.
    const MAX_SWEEPS: usize = 10_000;
    for _ in 0..MAX_SWEEPS {
        let mut changed = false;
        for k in 0..blocks.len() {
            changed |= lower_to_bound(lim, blocks, k, true);
        }
        for k in (0..blocks.len()).rev() {
            changed |= lower_to_bound(lim, blocks, k, false);
        }
        if !changed {
            return;
        }
    }
}

/// An F word found in a line of text: its byte range (letter to end of value).
#[derive(Debug, Clone, Copy, PartialEq)]
struct FWord {
    start: usize,
    end: usize,
}

/// Finds the F word of a line (outside comments, brackets and parameter names) and where the
/// code of the line ends (before a `;` comment and trailing blanks).
fn scan_line(line: &(impl AsRef<[u8]> + ?Sized)) -> (Option<FWord>, usize) {
    let b = line.as_ref();
    let mut i = 0;
    let mut depth = 0usize;
    let mut f = None;
    let mut code_end = b.len();
    while i < b.len() {
        match b[i] {
            b'(' => {
                while i < b.len() && b[i] != b')' {
                    i += 1;
                }
            }
            b';' => {
                code_end = i;
                break;
            }
            b'<' => {
                while i < b.len() && b[i] != b'>' {
                    i += 1;
                }
            }
            b'[' => depth += 1,
            b']' => depth = depth.saturating_sub(1),
            b'F' | b'f' if depth == 0 && f.is_none() => {
                let start = i;
                let end = value_end(b, i + 1);
                f = Some(FWord { start, end });
                i = end;
                continue;
            }
            _ => {}
        }
        i += 1;
    }
    while code_end > 0 && matches!(b[code_end - 1], b' ' | b'\t' | b'\r' | b'\n') {
        code_end -= 1;
    }
    (f, code_end)
}

/// The end of the value of a word starting at `i` (after its letter): a number, a bracketed
/// expression or a parameter reference.
fn value_end(b: &[u8], mut i: usize) -> usize {
    while i < b.len() && matches!(b[i], b' ' | b'\t') {
        i += 1;
    }
    match b.get(i) {
        Some(b'[') => bracket_end(b, i),
        Some(b'#') => {
            i += 1;
            match b.get(i) {
                Some(b'<') => {
                    while i < b.len() && b[i] != b'>' {
                        i += 1;
                    }
                    (i + 1).min(b.len())
                }
                Some(b'[') => bracket_end(b, i),
                Some(b'#') => value_end(b, i),
                _ => {
                    while i < b.len() && b[i].is_ascii_digit() {
                        i += 1;
                    }
                    i
                }
            }
        }
        _ => {
            if matches!(b.get(i), Some(b'+' | b'-')) {
                i += 1;
            }
            while i < b.len() && (b[i].is_ascii_digit() || b[i] == b'.') {
                i += 1;
            }
            i
        }
    }
}

fn bracket_end(b: &[u8], mut i: usize) -> usize {
    let mut depth = 0usize;
    while i < b.len() {
        match b[i] {
            b'[' => depth += 1,
            b']' => {
                depth -= 1;
                if depth == 0 {
                    return i + 1;
                }
            }
            _ => {}
        }
        i += 1;
    }
    i
}

/// mm/s per unit of F (mm/min or inch/min).
fn mm_s_per_f(inch: bool) -> f64 {
    if inch { MM_PER_INCH / 60.0 } else { 1.0 / 60.0 }
}

/// The F value for `feed_mm_s` in the line's units, rounded down to the units' resolution.
fn f_value(feed_mm_s: f64, inch: bool) -> String {
    let decimals = if inch { 4 } else { 3 };
    let scale = 10f64.powi(decimals);
    // The 1e-6 absorbs the binary noise of a value already at the resolution (6000 mm/min
    // computed as 5999.999999999999).
    let q = (feed_mm_s / mm_s_per_f(inch) * scale + 1e-6).floor() / scale;
    let s = format!("{q:.*}", decimals as usize);
    let s = s.trim_end_matches('0').trim_end_matches('.');
    s.to_string()
}

/// What a line of the output gets.
#[derive(Debug, Clone)]
struct LineEdit {
    /// The new F value text.
    value: String,
    /// The trace comment, if any.
    comment: Option<String>,
}

/// Per-line facts gathered from the interpretation.
#[derive(Debug, Clone)]
struct LineFeeds {
    /// Lowest programmed feed of the line's feed moves (mm/s).
    programmed_mm_s: f64,
    /// Lowest allowed feed (mm/s).
    allowed_mm_s: f64,
    cause: Option<Cause>,
    inch: bool,
}

/// Optimises the feeds of `text` (named `name` in errors) for `machine`, interpreted from
/// `start_mm`. A program that does not interpret is an error naming its line and column.
///
/// The text is bytes, read by the same interpreter as `plan` and `run`: the same line ends
/// (`\n`, `\r\n`, `\r`), and bytes that are not UTF-8 accepted where they are (comments).
pub fn optimize(
    machine: &Machine,
    text: &[u8],
    name: &str,
    start_mm: Vector3<f64>,
    opts: &OptimizeOptions,
) -> Result<Optimized, Error> {
    let lim = AxisLimits::of(machine);
    let lines: Vec<&[u8]> = crate::gcode::split_lines_inclusive(text).collect();
    let f_words: Vec<Option<FWord>> = lines.iter().map(|l| scan_line(l).0).collect();
    let has_f = |line: usize| f_words.get(line - 1).is_some_and(|f| f.is_some());

    // The motions in execution order: a feed block of the passes (index into `blocks`), a
    // rapid or G93 move (line), or something that brings the machine to rest.
    enum Step {
        Feed(usize),
        Other(usize),
        Rest,
    }
    let mut blocks: Vec<Block> = Vec::new();
    let mut steps: Vec<Step> = Vec::new();
    let mut report = OptimizeReport::default();
    let mut interp = Interpreter::new(text, name, machine.setup(start_mm));
    let mut rest = true;
    while let Some(item) = interp.next() {
        let e = match item? {
            Item::Motion(e) => e,
            Item::Note(_) => continue,
            _ => {
                rest = true;
                steps.push(Step::Rest);
                continue;
            }
        };
        let length_mm = e.length_mm();
        let feed = e.feed_mm_s.filter(|_| !e.rapid);
        // A move of a subroutine file carries its call's line, which has no F word to lower:
        // it is left alone, and the moves around it are planned from rest.
        if interp.in_subroutine_file() {
            if feed.is_some() && report.subroutine_file_lines.last() != Some(&e.line) {
                report.subroutine_file_lines.push(e.line);
            }
            rest = true;
            steps.push(Step::Other(e.line));
            continue;
        }
        if feed.is_some() {
            report.blocks_examined += 1;
        }
        match feed {
            Some(_) if e.aux.moves() => {
                if report.aux_axis_lines.last() != Some(&e.line) {
                    report.aux_axis_lines.push(e.line);
                }
                rest = true;
                steps.push(Step::Other(e.line));
            }
            Some(_) if interp.inverse_time() => {
                if report.inverse_time_lines.last() != Some(&e.line) {
                    report.inverse_time_lines.push(e.line);
                }
                rest = true;
                steps.push(Step::Other(e.line));
            }
            // A move that goes nowhere does not take part (its F word stays as it is).
            Some(_) if length_mm.is_nan() || length_mm <= 0.0 => steps.push(Step::Other(e.line)),
            Some(f) => {
                let worst = worst_tangent(&e);
                let mut feed_mm_s = f;
                let mut cause = None;
                for i in 0..3 {
                    if let Some(v) = lim.vel_mm_s[i]
                        && worst[i] > TANGENT_EPS
                        && over(feed_mm_s, v / worst[i])
                    {
                        feed_mm_s = v / worst[i];
                        cause = Some(Cause::Velocity(i));
                    }
                }
                let (start_tangent, end_tangent) = tangents(&e);
                blocks.push(Block {
                    line: e.line,
                    programmed_mm_s: f,
                    feed_mm_s,
                    cause,
                    length_mm,
                    start_tangent,
                    end_tangent,
                    after_rest: rest,
                    before_rest: false,
                    inch: interp.inch(),
                });
                steps.push(Step::Feed(blocks.len() - 1));
                rest = false;
            }
            None => {
                rest = true;
                steps.push(Step::Other(e.line));
            }
        }
    }
    if let Some(last) = blocks.last_mut() {
        last.before_rest = true;
    }
    // A rest between two blocks is marked on both sides.
    for k in 1..blocks.len() {
        if blocks[k].after_rest {
            blocks[k - 1].before_rest = true;
        }
    }
    run_passes(&lim, &mut blocks);

    // Per line: the lowest feed any of its executions may have (a line run several times, in a
    // loop or a subroutine, gets one F word: the lowest, so no execution is raised).
    let mut per_line: BTreeMap<usize, LineFeeds> = BTreeMap::new();
    for b in &blocks {
        let entry = per_line.entry(b.line).or_insert(LineFeeds {
            programmed_mm_s: b.programmed_mm_s,
            allowed_mm_s: b.feed_mm_s,
            cause: b.cause,
            inch: b.inch,
        });
        entry.programmed_mm_s = entry.programmed_mm_s.min(b.programmed_mm_s);
        if b.feed_mm_s < entry.allowed_mm_s {
            entry.allowed_mm_s = b.feed_mm_s;
            entry.cause = b.cause;
        }
    }
    let lowered = |lf: &LineFeeds| {
        // Lowered when the value written would be below what the line has.
        let q = if lf.inch { 1e-4 } else { 1e-3 } * mm_s_per_f(lf.inch);
        lf.allowed_mm_s < lf.programmed_mm_s - q
    };

    let mut edits: BTreeMap<usize, LineEdit> = BTreeMap::new();
    for (&line, lf) in &per_line {
        if !lowered(lf) {
            continue;
        }
        let to_mm_s = lf.allowed_mm_s;
        report.lines_lowered += 1;
        let relative = to_mm_s / lf.programmed_mm_s;
        if report
            .largest
            .as_ref()
            .is_none_or(|r| relative < r.to_mm_s / r.from_mm_s)
        {
            report.largest = Some(Reduction {
                line,
                from_mm_s: lf.programmed_mm_s,
                to_mm_s,
                cause: lf.cause.unwrap_or(Cause::Velocity(0)),
            });
        }
        edits.insert(
            line,
            LineEdit {
                value: f_value(to_mm_s, lf.inch),
                comment: opts.trace.then(|| {
                    format!(
                        "(canmotion optimize: was F{})",
                        f_value(lf.programmed_mm_s, lf.inch)
                    )
                }),
            },
        );
    }

    // Modal F: walk the motions in execution order; after a line whose F changed, the output's
    // modal feed differs from the original's until a line with an F word of its own.
    let mut differs = false;
    let mut kept: BTreeMap<usize, LineEdit> = BTreeMap::new();
    for step in &steps {
        let line = match step {
            Step::Feed(k) => blocks[*k].line,
            Step::Other(line) => *line,
            Step::Rest => continue,
        };
        if edits.contains_key(&line) {
            differs = true;
        } else if has_f(line) {
            differs = false;
        } else if differs && let Step::Feed(_) = step {
            let lf = &per_line[&line];
            kept.entry(line).or_insert_with(|| LineEdit {
                value: f_value(lf.programmed_mm_s, lf.inch),
                comment: None,
            });
        }
    }
    report.lines_feed_kept = kept.len() as u64;
    edits.extend(kept);

    let mut out: Vec<u8> = Vec::with_capacity(text.len() + 64 * edits.len());
    for (idx, l) in lines.iter().enumerate() {
        match edits.get(&(idx + 1)) {
            None => out.extend_from_slice(l),
            Some(edit) => {
                let (f, code_end) = scan_line(l);
                let comment = edit
                    .comment
                    .as_ref()
                    .map(|c| format!(" {c}"))
                    .unwrap_or_default();
                match f {
                    Some(f) => {
                        // The F word in place, its letter's case kept; the trace at the end of
                        // the code.
                        let code_end = code_end.max(f.end);
                        out.extend_from_slice(&l[..f.start + 1]);
                        out.extend_from_slice(edit.value.as_bytes());
                        out.extend_from_slice(&l[f.end..code_end]);
                        out.extend_from_slice(comment.as_bytes());
                        out.extend_from_slice(&l[code_end..]);
                    }
                    None => {
                        out.extend_from_slice(&l[..code_end]);
                        out.extend_from_slice(b" F");
                        out.extend_from_slice(edit.value.as_bytes());
                        out.extend_from_slice(comment.as_bytes());
                        out.extend_from_slice(&l[code_end..]);
                    }
                }
            }
        }
    }
    Ok(Optimized { text: out, report })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn f_words_are_found_outside_comments_and_expressions() {
        let (f, end) = scan_line("G1 X[FIX[2.5]] (F99) F 1200 ; F5\n");
        let f = f.unwrap();
        assert_eq!(
            &"G1 X[FIX[2.5]] (F99) F 1200 ; F5\n"[f.start..f.end],
            "F 1200"
        );
        assert_eq!(end, 27);
        let line = "g1x1f[#<feed>*2]\r\n";
        let f = scan_line(line).0.unwrap();
        assert_eq!(&line[f.start..f.end], "f[#<feed>*2]");
        let line = "G1 X1 F#<feed>";
        let f = scan_line(line).0.unwrap();
        assert_eq!(&line[f.start..f.end], "F#<feed>");
        assert_eq!(scan_line("o<fast> sub").0, None);
    }

    #[test]
    fn values_are_rounded_down_to_the_units_resolution() {
        assert_eq!(f_value(100.0, false), "6000");
        assert_eq!(f_value(6000.0 / 60.0 - 1e-13, false), "6000");
        assert_eq!(f_value(12.345_678, false), "740.74");
        assert_eq!(f_value(25.4 / 60.0 * 12.5, true), "12.5");
    }
}
