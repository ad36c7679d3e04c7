//! How far one program's setpoints stray from its programmed path (issue 11's contour
//! acceptance), on one machine:
//!
//! ```text
//! cargo run --release --example path_deviation -- MACHINE.toml PROGRAM.ngc
//! ```
//!
//! The program is read with the machine's setup (tools, offsets) from the origin, passed
//! through its cutter compensation, planned with its `[planner]` configuration and limits, and
//! sampled every period as the cyclic loop streams it. Each setpoint is measured against the
//! tool-centre path as programmed (before blends and filters) and the tolerance in force there
//! (see `tests/common/path_deviation.rs`): the worst ratio of distance to tolerance with its
//! line, sample and position, the distance wherever the setpoint stands still and at the end,
//! and whether the end is exact. Exits with 1 when the acceptance fails, 2 on an error.

use std::fs::File;
use std::io::BufReader;
use std::path::PathBuf;
use std::process::ExitCode;

use canmotion::compensation::Compensator;
use canmotion::config::Machine;
use canmotion::gateway::limits;
use canmotion::gcode::{Interpreter, Item};
use canmotion::planner::plan_items_with;
use nalgebra::Vector3;

#[path = "../tests/common/path_deviation.rs"]
mod path_deviation;

use path_deviation::{AT_REST_MM, Measured};

/// Stops listed one by one at most (the largest distance is always given).
const LISTED_STOPS: usize = 20;

fn main() -> ExitCode {
    match run() {
        Ok(true) => ExitCode::SUCCESS,
        Ok(false) => ExitCode::from(1),
        Err(e) => {
            eprintln!("path_deviation: {e}");
            ExitCode::from(2)
        }
    }
}

fn run() -> Result<bool, String> {
    let mut args = std::env::args().skip(1);
    let (Some(machine_path), Some(program_path), None) = (args.next(), args.next(), args.next())
    else {
        return Err("usage: path_deviation MACHINE.toml PROGRAM.ngc".into());
    };
    let (machine_path, program_path) = (PathBuf::from(machine_path), PathBuf::from(program_path));
    let machine = Machine::load(&machine_path).map_err(|e| e.to_string())?;
    let name = program_path.display().to_string();
    let file = File::open(&program_path).map_err(|e| format!("{name}: {e}"))?;
    let start = Vector3::zeros();
    let interpreter = Interpreter::new(BufReader::new(file), &name, machine.setup(start));
    let mut items = Vec::new();
    for item in Compensator::new(interpreter, &name, machine.program.compensation) {
        match item.map_err(|e| e.to_string())? {
            Item::Note(_) => {}
            item => items.push(item),
        }
    }
    let config = &machine.planner;
    let plan = plan_items_with(start, &items, &limits(&machine), config)
        .map_err(|e| format!("{name}: {e}"))?;
    let duration_s = plan.duration_s();
    let report = path_deviation::measure_items(start, &items, plan, config)
        .map_err(|e| format!("{name}: {e}"))?;
    let elements = items
        .iter()
        .filter(|i| matches!(i, Item::Motion(_)))
        .count();
    println!(
        "{name} on {}: profile {:?}, period {} ms, chord_tol_mm {}, default_tolerance_mm {}",
        machine_path.display(),
        config.profile,
        config.period_s * 1e3,
        config.chord_tol_mm,
        config.default_tolerance_mm
    );
    println!(
        "{elements} elements, {} samples ({duration_s:.3} s planned), {} searches of the whole path",
        report.samples, report.whole_path_searches
    );
    match report.worst {
        Some(w) => println!("worst: {}", describe(&w)),
        None => println!("worst: no sample"),
    }
    println!(
        "{} stops, largest distance at rest {:.3e} mm (at most {AT_REST_MM} mm)",
        report.stops.len(),
        report.max_at_rest_mm()
    );
    for s in report.stops.iter().take(LISTED_STOPS) {
        println!(
            "  stop at sample {} near line {}: {:.3e} mm",
            s.sample, s.line, s.distance_mm
        );
    }
    if report.stops.len() > LISTED_STOPS {
        println!("  ... {} more", report.stops.len() - LISTED_STOPS);
    }
    if let Some(end) = report.end {
        println!(
            "end at sample {}: {:.3e} mm from the path, {}",
            end.sample,
            end.distance_mm,
            if end.position_mm == report.expected_end_mm {
                "exactly the program's end".to_string()
            } else {
                format!("not the program's end {:?}", report.expected_end_mm)
            }
        );
    }
    match report.check() {
        Ok(()) => {
            println!("within the tolerance");
            Ok(true)
        }
        Err(e) => {
            println!("FAILS: {e}");
            Ok(false)
        }
    }
}

fn describe(m: &Measured) -> String {
    format!(
        "ratio {:.4} ({:.4e} mm against {} mm) near line {}, sample {}, at ({:.4}, {:.4}, {:.4})",
        m.ratio,
        m.distance_mm,
        m.tolerance_mm,
        m.line,
        m.sample,
        m.position_mm.x,
        m.position_mm.y,
        m.position_mm.z
    )
}
