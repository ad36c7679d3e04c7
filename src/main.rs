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
        /// it at one node. bus-off@T and error-passive@T send the error frame the gateway's CAN
        /// controller would report. Repeatable.
        #[arg(long = "inject", value_name = "SPEC")]
        injects: Vec<canmotion::sim::Targeted>,
    },
    /// Decode the bus's traffic per CiA 301/402, one line per frame (candump, decoded).
    Monitor {
        /// SocketCAN interface (vcan0, can0); not with --replay.
        #[arg(long, required_unless_present = "replay")]
        bus: Option<String>,
        /// Machine file: decode its PDO mappings (controlword, statusword, positions in mm).
        #[arg(long)]
        machine: Option<PathBuf>,
        /// Also write every frame to FILE in candump's log format (candump -L, canplayer).
        #[arg(long, value_name = "FILE")]
        log: Option<PathBuf>,
        /// Decode a recorded candump log instead of a live bus.
        #[arg(long, value_name = "FILE", conflicts_with = "bus")]
        replay: Option<PathBuf>,
        /// Stop after N frames.
        #[arg(long, value_name = "N")]
        count: Option<u64>,
    },
    /// Read or write one object of a node over SDO.
    Sdo {
        #[command(subcommand)]
        op: SdoOp,
    },
    /// Send an NMT command (start, stop, preop, reset, reset-comm) to a node or to all.
    Nmt {
        /// SocketCAN interface (vcan0, can0).
        iface: String,
        /// start | stop | preop | reset | reset-comm.
        #[arg(value_name = "COMMAND")]
        command: canmotion::tools::NmtCommand,
        /// Node id 1-127, or `all`.
        #[arg(value_name = "NODE|all")]
        target: canmotion::tools::NmtTarget,
    },
    /// List the CANopen nodes on a bus: node id, NMT state, device type, identity, name.
    Scan {
        /// SocketCAN interface (vcan0, can0).
        iface: String,
        /// How long each node has to answer one SDO request.
        #[arg(long, value_name = "N", default_value_t = 100)]
        timeout_ms: u64,
    },
    /// Drive dictionaries: import a vendor's EDS/DCF.
    Dict {
        #[command(subcommand)]
        command: DictCommand,
    },
}

/// `canmotion dict` operations.
#[derive(Subcommand)]
enum DictCommand {
    /// Convert an EDS or DCF (CiA 306) into a drive dictionary (TOML); notes on every conversion
    /// are comments in the output, and the output is checked to load.
    Import {
        /// The EDS or DCF file.
        file: PathBuf,
        /// The dictionary to write, e.g. dictionaries/drives/NAME.toml.
        #[arg(short = 'o', long)]
        output: PathBuf,
        /// Resolve $NODEID for this node (default: a DCF's [DeviceComissioning] NodeID, else the
        /// values stay "$NODEID+..." and follow the node the dictionary is used for).
        #[arg(long, value_parser = clap::value_parser!(u8).range(1..=127))]
        node: Option<u8>,
    },
}

/// `canmotion sdo` operations. INDEX and SUB are hexadecimal (`0x6040:00`, `1018:4`); NODE and
/// VALUE decimal or `0x` hex; TYPE one of u8 u16 u32 u64 i8 i16 i32 i64 f32 f64 string.
#[derive(Subcommand)]
enum SdoOp {
    /// Upload an object and print its value (and hex); raw bytes without TYPE.
    Read {
        /// SocketCAN interface (vcan0, can0).
        iface: String,
        /// Node id 1-127.
        node: canmotion::tools::Node,
        /// Object, hex: 0x6040:00, 1018:4.
        #[arg(value_name = "INDEX[:SUB]")]
        address: canmotion::tools::ObjectAddress,
        /// u8 u16 u32 u64 i8 i16 i32 i64 f32 f64 string.
        #[arg(value_name = "TYPE")]
        data_type: Option<canmotion::tools::SdoType>,
    },
    /// Download a value to an object.
    Write {
        /// SocketCAN interface (vcan0, can0).
        iface: String,
        /// Node id 1-127.
        node: canmotion::tools::Node,
        /// Object, hex: 0x6040:00, 1018:4.
        #[arg(value_name = "INDEX[:SUB]")]
        address: canmotion::tools::ObjectAddress,
        /// u8 u16 u32 u64 i8 i16 i32 i64 f32 f64 string.
        #[arg(value_name = "TYPE")]
        data_type: canmotion::tools::SdoType,
        /// The value (decimal, 0x hex, negative for signed types; text for string).
        #[arg(allow_hyphen_values = true)]
        value: String,
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
            let summary = match gateway::run(
                &machine,
                &bus,
                &RunOptions {
                    program_name: name,
                    program_text: text,
                    log: log.clone(),
                    simulate,
                },
            ) {
                Ok(s) => s,
                Err(gateway::GatewayError::Motion(f)) => {
                    // The cycle and bus figures up to the stop: they matter most when it failed.
                    eprint!(
                        "cycles            {} in all ({} overruns)\n{}",
                        f.timing.cycles, f.timing.overruns, f.bus
                    );
                    return Err(gateway::GatewayError::Motion(f).into());
                }
                Err(e) => return Err(e.into()),
            };
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
        Command::Monitor {
            bus,
            machine,
            log,
            replay,
            count,
        } => {
            use canmotion::tools::{DecodeContext, monitor};
            let ctx = match machine {
                Some(p) => DecodeContext::from_machine(&Machine::load(&p)?),
                None => DecodeContext::new(),
            };
            let opts = monitor::MonitorOptions {
                log,
                count,
                duration: None,
            };
            let mut out = std::io::stdout().lock();
            match (replay, bus) {
                (Some(file), _) => monitor::replay(&file, &ctx, &opts, &mut out)?,
                (None, Some(b)) => monitor::monitor(&Bus::from_arg(&b), &ctx, &opts, &mut out)?,
                (None, None) => unreachable!("clap requires --bus or --replay"),
            };
            Ok(())
        }
        Command::Sdo {
            op:
                SdoOp::Read {
                    iface,
                    node,
                    address,
                    data_type,
                },
        } => {
            let v = canmotion::tools::sdo::read(&Bus::from_arg(&iface), node, address, data_type)?;
            println!("{v}");
            Ok(())
        }
        Command::Sdo {
            op:
                SdoOp::Write {
                    iface,
                    node,
                    address,
                    data_type,
                    value,
                },
        } => {
            let bus = Bus::from_arg(&iface);
            let v = canmotion::tools::sdo::write_text(&bus, node, address, data_type, &value)?;
            let v = canmotion::tools::args::format_value(&v);
            println!("node {node}: {address} = {v} written");
            Ok(())
        }
        Command::Nmt {
            iface,
            command,
            target,
        } => {
            let f = canmotion::tools::nmt::send(&Bus::from_arg(&iface), command, target)?;
            println!("NMT {command}: {target} ({f})");
            Ok(())
        }
        Command::Scan { iface, timeout_ms } => {
            use canmotion::tools::scan;
            let bus = Bus::from_arg(&iface);
            let opts = scan::ScanOptions {
                timeout: std::time::Duration::from_millis(timeout_ms),
                ..scan::ScanOptions::default()
            };
            let nodes = scan::scan(&bus, &opts)?;
            print!("{}", scan::format_table(&nodes));
            println!("{} node(s) on {}", nodes.len(), bus.name());
            Ok(())
        }
        Command::Dict {
            command: DictCommand::Import { file, output, node },
        } => {
            let opts = canmotion::eds::ImportOptions {
                node,
                ..Default::default()
            };
            let imported = canmotion::eds::import_to_file(&file, &output, &opts)?;
            println!("{}", imported.summary());
            println!("wrote             {}", output.display());
            Ok(())
        }
    }
}
