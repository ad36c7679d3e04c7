//! Corpus time benchmark (issue 11's acceptance), run by `tools/corpus-times.sh [MACHINE]`:
//! every program of LinuxCNC's trajectory-planner corpus (`../shared/corpus/linuxcnc-tp/`)
//! that plans, timed in trapezoid and in jerk-limited mode on one machine, against the
//! reference time `T_ref` of [`canmotion::planner::bounds`].
//!
//! ```text
//! cargo run --release --example corpus_times -- [MACHINE] [--corpus DIR] [--check]
//! ```
//!
//! `MACHINE` (default `dictionaries/machines/demo-xyz.toml`) is rewritten into a temporary
//! directory as two variants: a 1 ms cycle (admitted up to 100 % bus load: nothing is sent),
//! no sync window, every axis's travel widened to
//! ±1000 mm (the corpus programs were written for other machines), relative paths made
//! absolute, and `[planner] profile = "trapezoid"` or `"s-curve"`. Each program is read with
//! the corpus test's setup (`tests/gcode_corpus.rs`: tools T1…T20 of radius 1 mm), passed
//! through cutter compensation, planned with each variant's `PlannerConfig`, and streamed
//! through the interpolator: a program's time is its number of cycles times the period, what
//! a run would take.
//!
//! One line per program on stdout, then the geometric mean of the ratio (and of `T_ref` over
//! the trapezoid time, and of the jerk-limited time over `T_ref`), the ten worst
//! programs and those above 1.5× whose jerk-limited time is not within 1.1× of `T_ref`.
//! Progress and the programs that do not plan go to stderr.
//!
//! With `--check`, each jerk-limited plan is also checked as the acceptance's second item asks,
//! at the benchmark's period: every axis's velocity, acceleration and jerk of the setpoints by
//! finite differences within 1 % of the machine's limits (`tests/common/setpoints.rs`), and
//! every setpoint's distance from the programmed path within the tolerance in force, under
//! 1 µm at rest and at the end, the end exact (`tests/common/path_deviation.rs`); the
//! programs that fail are listed last, and the exit status is 1 if any does.

use std::fs::File;
use std::io::BufReader;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use canmotion::compensation::Compensator;
use canmotion::config::Machine;
use canmotion::gateway::limits;
use canmotion::gcode::{Interpreter, Item, Setup, Tool, ToolTable};
use canmotion::interpolator::{Interpolator, Status};
use canmotion::planner::bounds::{curvature_bound_s, exact_stops, reference_time_s};
use canmotion::planner::{Plan, plan_items_with};
use nalgebra::Vector3;

#[path = "../tests/common/path_deviation.rs"]
mod path_deviation;
#[path = "../tests/common/setpoints.rs"]
mod setpoints;

/// Above this ratio a program must be within [`REF_SLACK`] of its `T_ref`.
const RATIO_TARGET: f64 = 1.5;
/// See [`RATIO_TARGET`].
const REF_SLACK: f64 = 1.1;
/// Programs listed as the worst.
const WORST: usize = 10;

fn main() -> ExitCode {
    match run() {
        Ok(true) => ExitCode::SUCCESS,
        Ok(false) => ExitCode::from(1),
        Err(e) => {
            eprintln!("corpus_times: {e}");
            ExitCode::FAILURE
        }
    }
}

struct Args {
    machine: PathBuf,
    corpus: PathBuf,
    /// Check every jerk-limited plan's limits and path deviation too.
    check: bool,
}

fn args() -> Result<Args, String> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut machine = None;
    let mut corpus = root.join("../shared/corpus/linuxcnc-tp");
    let mut check = false;
    let mut it = std::env::args().skip(1);
    while let Some(a) = it.next() {
        match a.as_str() {
            "--corpus" => corpus = it.next().ok_or("--corpus needs a directory")?.into(),
            "--check" => check = true,
            "-h" | "--help" => {
                return Err("usage: corpus_times [MACHINE] [--corpus DIR] [--check]".into());
            }
            _ if machine.is_none() && !a.starts_with('-') => machine = Some(PathBuf::from(a)),
            _ => return Err(format!("unexpected argument {a:?}")),
        }
    }
    Ok(Args {
        machine: machine.unwrap_or_else(|| root.join("dictionaries/machines/demo-xyz.toml")),
        corpus,
        check,
    })
}

/// One program's figures.
struct Row {
    name: String,
    trapezoid_s: f64,
    jerk_s: f64,
    t_lb_s: f64,
    t_ref_s: f64,
    stops: usize,
}

impl Row {
    fn ratio(&self) -> f64 {
        self.jerk_s / self.trapezoid_s
    }

    /// Above the ratio target and not explained by `T_ref`.
    fn flagged(&self) -> bool {
        self.ratio() > RATIO_TARGET && self.jerk_s > REF_SLACK * self.t_ref_s
    }

    fn print(&self) {
        println!(
            "{:<52} {:>10.3} {:>10.3} {:>6.3} {:>10.3} {:>10.3} {:>5}{}",
            self.name,
            self.trapezoid_s,
            self.jerk_s,
            self.ratio(),
            self.t_ref_s,
            self.t_lb_s,
            self.stops,
            if self.flagged() { "  !" } else { "" }
        );
    }
}

fn header() {
    println!(
        "{:<52} {:>10} {:>10} {:>6} {:>10} {:>10} {:>5}",
        "program", "trap_s", "jerk_s", "ratio", "T_ref_s", "T_lb_s", "stops"
    );
}

fn run() -> Result<bool, String> {
    let args = args()?;
    if !args.corpus.is_dir() {
        println!(
            "corpus {} is absent: nothing to time",
            args.corpus.display()
        );
        return Ok(true);
    }
    let corpus = args.corpus.canonicalize().unwrap_or(args.corpus);
    let dir = tempfile::tempdir().map_err(|e| format!("temporary directory: {e}"))?;
    let trapezoid = variant(&args.machine, "trapezoid", dir.path())?;
    let jerk = variant(&args.machine, "s-curve", dir.path())?;
    let mut files = Vec::new();
    ngc_files(&corpus, &mut files);
    files.sort();
    println!(
        "machine {} at a {} ms cycle, travel ±1000 mm; corpus {} ({} programs)",
        args.machine.display(),
        trapezoid.planner.period_s * 1e3,
        corpus.display(),
        files.len()
    );
    println!(
        "trap_s, jerk_s: program time (cycles × period) with profile \"trapezoid\" and \"s-curve\"; \
         T_ref_s = max(T_lb_s, trap_s + up to A/J per stop); ! = ratio > {RATIO_TARGET} and jerk_s > {REF_SLACK} × T_ref_s"
    );
    header();
    let mut rows = Vec::new();
    let mut failed = Vec::new();
    for (k, path) in files.iter().enumerate() {
        let name = path
            .strip_prefix(&corpus)
            .unwrap_or(path)
            .display()
            .to_string();
        eprintln!("[{}/{}] {name}", k + 1, files.len());
        match time_program(path, &name, &trapezoid, &jerk, args.check) {
            Ok((row, check)) => {
                row.print();
                if let Err(why) = check {
                    failed.push(format!("{name}: {why}"));
                }
                rows.push(row);
            }
            Err(why) => eprintln!("  skipped: {why}"),
        }
    }
    summary(&rows, files.len());
    if args.check {
        println!(
            "--check, jerk-limited plans at {} ms: {} of {} fail (limits within 1 %, the tolerance, at rest and at the end within 1 µm, the end exact){}",
            jerk.planner.period_s * 1e3,
            failed.len(),
            rows.len(),
            if failed.is_empty() { "" } else { ":" }
        );
        for f in &failed {
            println!("  {f}");
        }
    }
    Ok(failed.is_empty())
}

fn summary(rows: &[Row], programs: usize) {
    println!();
    if rows.is_empty() {
        println!("no program planned");
        return;
    }
    let log_mean = rows.iter().map(|r| r.ratio().ln()).sum::<f64>() / rows.len() as f64;
    let max = rows.iter().map(Row::ratio).fold(0.0, f64::max);
    println!(
        "{} of {programs} programs plan; jerk-limited / trapezoid time: geometric mean {:.3}, max {:.3}",
        rows.len(),
        log_mean.exp(),
        max
    );
    // What the physics of the jerk limit alone costs: `T_ref ≥ trap_s` (a start from rest
    // costs `A/J` more with a jerk limit), so a planner that took exactly `T_ref` on every
    // program would show the first mean; the second is how far the plans are from it.
    let geo = |f: &dyn Fn(&Row) -> f64| {
        (rows.iter().map(|r| f(r).ln()).sum::<f64>() / rows.len() as f64).exp()
    };
    println!(
        "reference: T_ref / trapezoid time geometric mean {:.3} (the ratio a plan taking exactly T_ref everywhere would show); jerk-limited / T_ref geometric mean {:.3}",
        geo(&|r| r.t_ref_s / r.trapezoid_s),
        geo(&|r| r.jerk_s / r.t_ref_s)
    );
    let mut worst: Vec<&Row> = rows.iter().collect();
    worst.sort_by(|a, b| b.ratio().total_cmp(&a.ratio()));
    println!("the {WORST} worst:");
    header();
    for r in worst.iter().take(WORST) {
        r.print();
    }
    let flagged: Vec<&&Row> = worst.iter().filter(|r| r.flagged()).collect();
    println!(
        "{} programs above {RATIO_TARGET}× and not within {REF_SLACK}× of T_ref{}",
        flagged.len(),
        if flagged.is_empty() { "" } else { ":" }
    );
    for r in flagged {
        println!(
            "  {} ({:.3}×, {:.3}× T_ref)",
            r.name,
            r.ratio(),
            r.jerk_s / r.t_ref_s
        );
    }
}

/// Times one program in both modes, with the check of its jerk-limited plan where `check`
/// asks for it (`Ok(())` otherwise); why not, when it does not plan.
fn time_program(
    path: &Path,
    name: &str,
    trapezoid: &Machine,
    jerk: &Machine,
    check: bool,
) -> Result<(Row, Result<(), String>), String> {
    let items = interpret(path, name, trapezoid)?;
    let start = Vector3::zeros();
    let (trap_limits, jerk_limits) = (limits(trapezoid), limits(jerk));
    let trap_plan = plan_items_with(start, &items, &trap_limits, &trapezoid.planner)
        .map_err(|e| format!("trapezoid: {e}"))?;
    let jerk_plan = plan_items_with(start, &items, &jerk_limits, &jerk.planner)
        .map_err(|e| format!("s-curve: {e}"))?;
    let t_lb_s = curvature_bound_s(&items, &jerk_limits, &jerk.planner);
    // The stops of the trapezoid plan, priced at the jerk limits.
    let stops = exact_stops(&trap_plan, &jerk_limits, &jerk.planner);
    let checked = if check {
        check_plan(start, &items, &jerk_plan, &jerk_limits, &jerk.planner)
    } else {
        Ok(())
    };
    let trapezoid_s = streamed_s(trap_plan, trapezoid.planner.period_s)?;
    let jerk_s = streamed_s(jerk_plan, jerk.planner.period_s)?;
    if trapezoid_s <= 0.0 {
        return Err("no motion".into());
    }
    let row = Row {
        name: name.to_string(),
        trapezoid_s,
        jerk_s,
        t_lb_s,
        t_ref_s: reference_time_s(t_lb_s, trapezoid_s, &stops),
        stops: stops.count,
    };
    Ok((row, checked))
}

/// The acceptance's check of a jerk-limited plan (see the module documentation): the first
/// limit it breaks, else how far it strays from the path beyond the tolerance.
fn check_plan(
    start: Vector3<f64>,
    items: &[Item],
    plan: &Plan,
    limits: &canmotion::planner::Limits,
    config: &canmotion::planner::PlannerConfig,
) -> Result<(), String> {
    setpoints::limits_hold(plan.clone(), limits, config)?;
    path_deviation::measure_items(start, items, plan.clone(), config)
        .map_err(|e| e.to_string())?
        .check()
        .map_err(|e| e.to_string())
}

/// The time a run of `plan` takes: its samples times the period.
fn streamed_s(plan: Plan, period_s: f64) -> Result<f64, String> {
    let mut interp = Interpolator::new(plan, period_s).map_err(|e| e.to_string())?;
    let mut q = Vector3::zeros();
    loop {
        match interp.update(&mut q) {
            Status::Finished => return Ok(interp.elapsed_s()),
            Status::Working { .. } => {}
            other => return Err(format!("interpolator: {other:?}")),
        }
    }
}

/// The tool-centre path of a program, with the corpus test's setup
/// (`tests/gcode_corpus.rs`): T1…T20 of radius 1 mm and length 20 + n mm.
fn interpret(path: &Path, name: &str, machine: &Machine) -> Result<Vec<Item>, String> {
    let mut tools = ToolTable::new();
    for n in 1..=20u32 {
        tools.insert(
            n,
            Tool {
                radius_mm: 1.0,
                length_mm: 20.0 + f64::from(n),
            },
        );
    }
    let mut setup = Setup::new(Vector3::zeros());
    setup.tools = tools;
    let file = File::open(path).map_err(|e| format!("cannot open: {e}"))?;
    let items = Compensator::new(
        Interpreter::new(BufReader::new(file), name, setup),
        name,
        machine.program.compensation,
    );
    let mut out = Vec::new();
    for item in items {
        match item.map_err(|e| e.to_string())? {
            Item::Note(_) => {}
            item => out.push(item),
        }
    }
    Ok(out)
}

/// Writes `machine`'s variant for the benchmark into `dir` and loads it (see the module
/// documentation).
fn variant(machine: &Path, profile: &str, dir: &Path) -> Result<Machine, String> {
    let text =
        std::fs::read_to_string(machine).map_err(|e| format!("{}: {e}", machine.display()))?;
    let mut doc: toml::Table =
        toml::from_str(&text).map_err(|e| format!("{}: {e}", machine.display()))?;
    let base = machine
        .parent()
        .unwrap_or(Path::new("."))
        .canonicalize()
        .map_err(|e| format!("{}: {e}", machine.display()))?;
    let absolute = |v: &mut toml::Value| {
        if let Some(rel) = v.as_str() {
            *v = toml::Value::String(base.join(rel).display().to_string());
        }
    };
    let table = |doc: &mut toml::Table, name: &str| -> Result<toml::Table, String> {
        match doc.remove(name) {
            None => Ok(toml::Table::new()),
            Some(toml::Value::Table(t)) => Ok(t),
            Some(_) => Err(format!("{}: [{name}] is not a table", machine.display())),
        }
    };
    let mut bus = table(&mut doc, "bus")?;
    bus.insert("cycle_us".into(), toml::Value::Integer(1000));
    // Planning only: a 1 ms cycle may need more of the bus than the file admits.
    bus.insert("max_load_percent".into(), toml::Value::Float(100.0));
    doc.insert("bus".into(), bus.into());
    let mut sync = table(&mut doc, "sync")?;
    sync.insert("window_us".into(), toml::Value::Integer(0));
    doc.insert("sync".into(), sync.into());
    let mut planner = table(&mut doc, "planner")?;
    planner.insert("profile".into(), toml::Value::String(profile.into()));
    doc.insert("planner".into(), planner.into());
    if let Some(toml::Value::Table(program)) = doc.get_mut("program")
        && let Some(v) = program.get_mut("tool_table")
    {
        absolute(v);
    }
    if let Some(toml::Value::Array(axes)) = doc.get_mut("axis") {
        for axis in axes.iter_mut().filter_map(toml::Value::as_table_mut) {
            axis.insert("min_mm".into(), toml::Value::Float(-1000.0));
            axis.insert("max_mm".into(), toml::Value::Float(1000.0));
            if let Some(v) = axis.get_mut("dictionary") {
                absolute(v);
            }
        }
    }
    let stem = machine
        .file_stem()
        .map_or("machine".into(), |s| s.to_string_lossy().into_owned());
    let out = dir.join(format!("{stem}-{profile}.toml"));
    let text = toml::to_string(&doc).map_err(|e| format!("{}: {e}", out.display()))?;
    std::fs::write(&out, text).map_err(|e| format!("{}: {e}", out.display()))?;
    Machine::load(&out).map_err(|e| e.to_string())
}

fn ngc_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for entry in entries.flatten() {
        let path = entry.path();
        if path.is_dir() {
            ngc_files(&path, out);
        } else if path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("ngc"))
        {
            out.push(path);
        }
    }
}
