//! The `canmotion` command line. Everything it does lives in the library; see `src/lib.rs`.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};

use canmotion::bus::Bus;
use canmotion::config::{DriveDictionary, Machine};
use canmotion::gateway::{self, RunOptions};
use canmotion::sim::{SimDrive, runner};

/// The demo program run when `canmotion run` is given no program.
const DEMO_PROGRAM: &str = include_str!("../examples/demo.ngc");

#[derive(Parser)]
#[command(
    name = "canmotion",
    version,
    about = "CAN-bus motion gateway: G-code to CiA 402 servo drives over CANopen"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run a G-code program on the machine's drives.
    Run {
        /// The program (`-` for standard input; the embedded demo when omitted).
        program: Option<PathBuf>,
        /// Machine file (the embedded demo machine, dictionaries/machines/demo-xyz.toml, when omitted).
        #[arg(long)]
        machine: Option<PathBuf>,
        /// Bus: `sim` (in-process bus with simulated drives) or a SocketCAN interface (vcan0, can0).
        /// Default: the machine file's `bus.interface`.
        #[arg(long)]
        bus: Option<String>,
        /// Write one CSV row per cycle to this file.
        #[arg(long)]
        log: Option<PathBuf>,
    },
    /// Simulated CiA 402 drives as real peers on a bus.
    Simdrive {
        /// SocketCAN interface (or `sim`, which is only useful in tests).
        #[arg(long)]
        bus: String,
        /// Node ids to simulate (repeat for several drives).
        #[arg(long = "node", required = true, value_parser = clap::value_parser!(u8).range(1..=127))]
        nodes: Vec<u8>,
        /// Drive dictionary (default: the embedded dictionaries/drives/cia402-servo.toml).
        #[arg(long)]
        dictionary: Option<PathBuf>,
        /// Misbehave, for fault tests: following-error@T, silent@T, reboot@T (T after the drive
        /// starts following setpoints, e.g. 1.5s or 200ms) or drop-rpdo=P%; `NODE:` first aims
        /// it at one node. Repeatable.
        #[arg(long = "inject", value_name = "SPEC")]
        injects: Vec<canmotion::sim::Targeted>,
    },
}

fn main() -> ExitCode {
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| "warn".into()),
        )
        .with_writer(std::io::stderr)
        .init();
    match real_main() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("canmotion: error: {e}");
            ExitCode::FAILURE
        }
    }
}

fn real_main() -> Result<(), Box<dyn std::error::Error>> {
    match Cli::parse().command {
        Command::Run {
            program,
            machine,
            bus,
            log,
        } => {
            let machine = match machine {
                Some(p) => Machine::load(&p)?,
                None => Machine::demo(),
            };
            let (name, text) = match program {
                Some(p) if p.as_os_str() == "-" => {
                    let mut text = String::new();
                    std::io::Read::read_to_string(&mut std::io::stdin(), &mut text)
                        .map_err(|e| format!("<stdin>: cannot read: {e}"))?;
                    ("<stdin>".to_string(), text)
                }
                Some(p) => {
                    let text = std::fs::read_to_string(&p)
                        .map_err(|e| format!("{}: cannot read: {e}", p.display()))?;
                    (p.display().to_string(), text)
                }
                None => (
                    "examples/demo.ngc (embedded)".to_string(),
                    DEMO_PROGRAM.to_string(),
                ),
            };
            let bus_arg = bus.unwrap_or_else(|| machine.interface.clone());
            let bus = Bus::from_arg(&bus_arg);
            let simulate = matches!(bus, Bus::InProc(_));
            println!(
                "canmotion: {} on machine '{}' ({} axes, {} µs cycle) over {}{}",
                name,
                machine.name,
                machine.axes.len(),
                machine.cycle_us,
                bus.name(),
                if simulate {
                    " with simulated drives"
                } else {
                    ""
                }
            );
            let summary = gateway::run(
                &machine,
                &bus,
                &RunOptions {
                    program_name: name,
                    program_text: text,
                    log: log.clone(),
                    simulate,
                },
            )?;
            println!("{summary}");
            if let Some(l) = log {
                println!("log               {}", l.display());
            }
            Ok(())
        }
        Command::Simdrive {
            bus,
            nodes,
            dictionary,
            injects,
        } => {
            let dict = std::sync::Arc::new(match dictionary {
                Some(p) => DriveDictionary::load(&p)?,
                None => DriveDictionary::parse(
                    std::path::Path::new("dictionaries/drives/cia402-servo.toml"),
                    canmotion::config::machine::DEMO_DRIVE,
                )?,
            });
            let bus = Bus::from_arg(&bus);
            let drives = nodes
                .iter()
                .map(|&n| {
                    injects
                        .iter()
                        .filter(|t| t.node.is_none_or(|m| m == n))
                        .fold(SimDrive::new(dict.clone(), n), |d, t| {
                            d.with_inject(t.inject)
                        })
                })
                .collect();
            let handle = runner::spawn(&bus, drives)?;
            eprintln!(
                "canmotion simdrive: nodes {:?} on {} ({}); Ctrl-C to stop",
                nodes,
                bus.name(),
                dict.name
            );
            handle.wait()?;
            Ok(())
        }
    }
}
