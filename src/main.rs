//! The `canmotion` command line. Everything it does lives in the library; see `src/lib.rs`.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};

use canmotion::bus::Bus;
use canmotion::config::{DriveDictionary, Machine};
use canmotion::files::{self, MAX_CONFIG_BYTES};
use canmotion::gateway::resume::{self, ResumePreview, ResumeState};
use canmotion::gateway::{self, RunOptions};
use canmotion::sim::{SimDrive, runner};

/// Standard output failed (a full disk, a closed pipe): reported, never a panic.
#[derive(Debug, thiserror::Error)]
#[error("standard output: cannot write: {0}")]
struct StdoutError(std::io::Error);

/// `println!` that returns [`StdoutError`] from the enclosing function instead of panicking.
macro_rules! outln {
    ($($arg:tt)*) => {
        std::io::Write::write_fmt(
            &mut std::io::stdout().lock(),
            format_args!("{}\n", format_args!($($arg)*)),
        )
        .map_err(StdoutError)?
    };
}

/// `print!` that returns [`StdoutError`] from the enclosing function instead of panicking.
macro_rules! out {
    ($($arg:tt)*) => {
        std::io::Write::write_fmt(&mut std::io::stdout().lock(), format_args!($($arg)*))
            .map_err(StdoutError)?
    };
}

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
        /// Continue the program from where an earlier run stopped (its resume point, see
        /// --state): every node is configured again, and nothing moves before a confirmation.
        #[arg(long)]
        resume: bool,
        /// Confirm the resume without asking (for scripts).
        #[arg(long, requires = "resume")]
        yes: bool,
        /// The resume point: written when the motion stops before the end of the program, read
        /// by --resume. Default: PROGRAM.resume beside the program file.
        #[arg(long, value_name = "FILE")]
        state: Option<PathBuf>,
        /// Listen on this Unix-domain socket for feed override and hold commands, one per line
        /// (`override 50`, `hold`, `resume`, `status`), each answered `ok ...` or `error: ...`.
        #[arg(long, value_name = "PATH")]
        control: Option<PathBuf>,
        /// Do not read override and hold keys from standard input (they are read unless the
        /// program comes from it or a resume asks there for its confirmation).
        #[arg(long)]
        no_keys: bool,
    },
    /// A long-running gateway: start the drives once, then take enable, home, jog, MDI and
    /// programs on a control socket (one command per line; see the README's "Machine
    /// operation"). SIGTERM or `quit` ends it in order.
    Serve {
        /// Machine file (the embedded demo machine when omitted).
        #[arg(long)]
        machine: Option<PathBuf>,
        /// Bus: `sim` (in-process bus with simulated drives) or a SocketCAN interface.
        /// Default: the machine file's `bus.interface`.
        #[arg(long)]
        bus: Option<String>,
        /// The control socket (default: the machine file's `[operation] control_socket`,
        /// /run/canmotion.sock).
        #[arg(long, value_name = "PATH")]
        control: Option<PathBuf>,
        /// Write one CSV row per cycle to this file.
        #[arg(long)]
        log: Option<PathBuf>,
    },
    /// CiA 402 fault reset (controlword bit 7), verified: the statusword must leave Fault and
    /// stay out; reports 0x603F before and after. Exit status 1 if a fault did not clear.
    Reset {
        /// SocketCAN interface (vcan0, can0).
        iface: String,
        /// Node id 1-127, or `all` (every CiA 402 drive a scan finds).
        #[arg(value_name = "NODE|all")]
        target: canmotion::commands::NmtTarget,
        /// How long the drive has to leave Fault after the reset.
        #[arg(long, value_name = "MS", default_value_t = 1000)]
        timeout_ms: u64,
        /// How long it must then stay out of Fault.
        #[arg(long, value_name = "MS", default_value_t = 500)]
        observe_ms: u64,
    },
    /// Plan a program offline (no bus): summary, tool-centre path, setpoints.
    Plan {
        /// The program (`-` for standard input).
        program: PathBuf,
        /// Machine file (the embedded demo machine when omitted).
        #[arg(long)]
        machine: Option<PathBuf>,
        /// Write the compensated tool-centre path here, one JSON object per element per line.
        #[arg(long, value_name = "FILE.jsonl")]
        path: Option<PathBuf>,
        /// Write the interpolated setpoints here, one CSV row per cycle (what `run` streams).
        #[arg(long, value_name = "FILE.csv")]
        setpoints: Option<PathBuf>,
        /// Plot the path feed and each axis's velocity, acceleration and jerk against time
        /// (finite differences of the setpoints), limits dashed; the extension (.svg, .png)
        /// picks the format.
        #[arg(long, value_name = "FILE.svg|FILE.png")]
        plot: Option<PathBuf>,
        /// Feed override at planning time, 1 to 200 %: every programmed feed scaled by it
        /// (capped by the machine's limits as usual), rapids up to 100 %.
        #[arg(long, value_name = "PERCENT", value_parser = parse_plan_override)]
        r#override: Option<f64>,
        /// M99 in the main program restarts it endlessly on a controller: plan this many
        /// restarts, then end at M99 (default 0: the plan ends at the first M99).
        #[arg(long, value_name = "N", default_value_t = 0)]
        m99_restarts: u32,
    },
    /// Lower the program's F words to the machine's per-axis velocity and acceleration limits
    /// (source 002's feed optimiser); the rest of the program is copied byte for byte.
    Optimize {
        /// The program (`-` for standard input).
        program: PathBuf,
        /// The optimised program to write.
        #[arg(short = 'o', long, value_name = "OUT.ngc")]
        output: PathBuf,
        /// Machine file (the embedded demo machine when omitted).
        #[arg(long)]
        machine: Option<PathBuf>,
        /// Do not follow each changed F by a `(canmotion optimize: was F...)` comment.
        #[arg(long)]
        no_trace: bool,
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
        /// The home switch of NODE's axis for homing mode 6, at COUNTS of position actual as it
        /// reads at power-on (methods 19/20 see it active above, 21/22 below). Without one the
        /// switch methods end in a homing error at the software position limits 0x607D.
        /// Repeatable, one per node.
        #[arg(long = "home-switch", value_name = "NODE:COUNTS", value_parser = parse_home_switch)]
        home_switches: Vec<(u8, i32)>,
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
        command: canmotion::commands::NmtCommand,
        /// Node id 1-127, or `all`.
        #[arg(value_name = "NODE|all")]
        target: canmotion::commands::NmtTarget,
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
        node: canmotion::commands::Node,
        /// Object, hex: 0x6040:00, 1018:4.
        #[arg(value_name = "INDEX[:SUB]")]
        address: canmotion::commands::ObjectAddress,
        /// u8 u16 u32 u64 i8 i16 i32 i64 f32 f64 string.
        #[arg(value_name = "TYPE")]
        data_type: Option<canmotion::commands::SdoType>,
        /// Ask for a block upload (CiA 301 §7.2.4.3.9; a node without it may answer with a
        /// normal upload, which is followed).
        #[arg(long)]
        block: bool,
    },
    /// Download a value to an object.
    Write {
        /// SocketCAN interface (vcan0, can0).
        iface: String,
        /// Node id 1-127.
        node: canmotion::commands::Node,
        /// Object, hex: 0x6040:00, 1018:4.
        #[arg(value_name = "INDEX[:SUB]")]
        address: canmotion::commands::ObjectAddress,
        /// u8 u16 u32 u64 i8 i16 i32 i64 f32 f64 string.
        #[arg(value_name = "TYPE")]
        data_type: canmotion::commands::SdoType,
        /// The value (decimal, 0x hex, negative for signed types; text for string).
        #[arg(allow_hyphen_values = true)]
        value: String,
    },
}

/// `plan --override`: a percentage from 1 to 200.
/// The machine file given with `--machine`, or the embedded demo machine.
fn machine_or_demo(
    path: Option<&std::path::Path>,
) -> Result<Machine, canmotion::config::ConfigError> {
    match path {
        Some(p) => Machine::load(p),
        None => Ok(Machine::demo()),
    }
}

/// `--home-switch NODE:COUNTS`.
fn parse_home_switch(s: &str) -> Result<(u8, i32), String> {
    let (node, counts) = s
        .split_once(':')
        .ok_or_else(|| format!("{s:?}: expected NODE:COUNTS, e.g. 1:-2000"))?;
    let node: u8 = node
        .trim()
        .parse()
        .ok()
        .filter(|n| (1..=127).contains(n))
        .ok_or_else(|| format!("{node:?}: a node id is 1..=127"))?;
    let counts: i32 = counts
        .trim()
        .parse()
        .map_err(|_| format!("{counts:?}: a position in counts (INT32)"))?;
    Ok((node, counts))
}

fn parse_plan_override(s: &str) -> Result<f64, String> {
    let percent: f64 = s
        .trim_end_matches('%')
        .parse()
        .map_err(|_| format!("'{s}' is not a percentage (e.g. 50 for 50 %)"))?;
    canmotion::offline::check_override(percent / 100.0)?;
    Ok(percent)
}

fn main() -> ExitCode {
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| "warn".into()),
        )
        .with_writer(std::io::stderr)
        .init();
    let result = real_main().and_then(|()| {
        // What is still buffered must reach the output too, or be an error.
        std::io::Write::flush(&mut std::io::stdout()).map_err(|e| StdoutError(e).into())
    });
    // A reader that went away (`canmotion plan ... | head`) wanted no more: quiet, and the
    // status a shell shows for SIGPIPE.
    let broken_pipe = result.as_ref().is_err_and(|e| {
        e.downcast_ref::<StdoutError>()
            .is_some_and(|s| s.0.kind() == std::io::ErrorKind::BrokenPipe)
    });
    if let Err(e) = &result
        && !broken_pipe
    {
        eprintln!("canmotion: error: {e}");
    }
    // A run stopped by SIGINT or SIGTERM exits as the signal would have ended it (130, 143),
    // once the drives are disabled, the resume point saved and the control socket removed.
    if let Some(signal) = canmotion::rt::signal::STOP.first() {
        if result.is_ok() {
            eprintln!(
                "canmotion: {} received as the program ended: it ran to its end",
                signal.name()
            );
        }
        return ExitCode::from(signal.exit_code());
    }
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(_) if broken_pipe => ExitCode::from(141),
        Err(_) => ExitCode::FAILURE,
    }
}

/// Standard input as the resume confirmation reads it: a line read on a thread of its own, so
/// that a stop signal (SIGINT, SIGTERM: blocked in every thread, see
/// [`canmotion::rt::signal`]) cancels the question instead of waiting for an answer.
struct AnswerOrSignal;

impl std::io::Read for AnswerOrSignal {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            let mut line = String::new();
            let _ = std::io::stdin().read_line(&mut line);
            let _ = tx.send(line);
        });
        loop {
            match rx.recv_timeout(std::time::Duration::from_millis(50)) {
                Ok(line) => {
                    let n = line.len().min(buf.len());
                    buf[..n].copy_from_slice(&line.as_bytes()[..n]);
                    return Ok(n);
                }
                Err(std::sync::mpsc::RecvTimeoutError::Timeout)
                    if canmotion::rt::signal::STOP.count() == 0 => {}
                // A signal, or nobody to answer: no.
                Err(_) => return Ok(0),
            }
        }
    }
}

/// Ask the operator to confirm a resume on the terminal (`--yes`: confirmed without asking).
/// Without a terminal on standard input there is nobody to ask: no.
fn confirm(preview: &ResumePreview, yes: bool) -> bool {
    use std::io::IsTerminal;
    use std::io::Write;
    let mut stdout = std::io::stdout().lock();
    if yes {
        // Nobody confirms a resume whose preview could not be shown.
        return writeln!(stdout, "{preview}\nconfirmed by --yes").is_ok();
    }
    if !std::io::stdin().is_terminal() {
        let _ = writeln!(stdout, "{preview}");
        eprintln!(
            "canmotion: standard input is not a terminal, nobody to confirm the resume: use --yes from a script"
        );
        return false;
    }
    resume::ask(
        preview,
        &mut std::io::BufReader::new(AnswerOrSignal),
        &mut std::io::stderr(),
    )
}

/// The progress line of `run` on a terminal: program line, feed and largest following error,
/// read a few times per second from the figures the cyclic thread stores
/// (the run's [`gateway::progress::Progress`]); drawn only once the program streams.
struct ProgressLine {
    stop: std::sync::mpsc::Sender<()>,
    thread: std::thread::JoinHandle<()>,
}

impl ProgressLine {
    fn start(
        total_lines: u64,
        figures: std::sync::Arc<gateway::progress::Progress>,
    ) -> ProgressLine {
        use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
        let (stop, stopped) = std::sync::mpsc::channel::<()>();
        let thread = std::thread::spawn(move || {
            let bar =
                ProgressBar::with_draw_target(Some(total_lines), ProgressDrawTarget::hidden());
            bar.set_style(
                ProgressStyle::with_template(
                    "{elapsed_precise} [{wide_bar}] line {pos}/{len}  {msg}",
                )
                .expect("template")
                .progress_chars("=> "),
            );
            let mut shown = false;
            while let Err(std::sync::mpsc::RecvTimeoutError::Timeout) =
                stopped.recv_timeout(std::time::Duration::from_millis(250))
            {
                let p = figures.read();
                let Some(line) = p.line else { continue };
                if !shown {
                    bar.set_draw_target(ProgressDrawTarget::stderr());
                    shown = true;
                }
                bar.set_position(line as u64);
                let hold = match (p.hold, p.held) {
                    (_, true) => "  HOLD",
                    (true, false) => "  HOLD (stopping)",
                    _ => "",
                };
                bar.set_message(format!(
                    "feed {:8.3} mm/s  override {:3.0} % (asked {:.0} %){hold}  max following error {:.4} mm",
                    p.feed_mm_s,
                    p.override_effective * 100.0,
                    p.override_requested * 100.0,
                    p.max_following_error_mm
                ));
            }
            bar.finish_and_clear();
        });
        ProgressLine { stop, thread }
    }

    fn finish(self) {
        let _ = self.stop.send(());
        let _ = self.thread.join();
    }
}

fn real_main() -> Result<(), Box<dyn std::error::Error>> {
    match Cli::parse().command {
        Command::Plan {
            program,
            machine,
            path,
            setpoints,
            plot,
            r#override,
            m99_restarts,
        } => {
            if let Some(p) = &plot {
                canmotion::plot::PlotFormat::of(p)?;
            }
            let machine = machine_or_demo(machine.as_deref())?;
            let opts = canmotion::offline::PlanOptions {
                path_out: path,
                setpoints_out: setpoints,
                plot_out: plot,
                feed_override: r#override.map(|p| p / 100.0),
                m99_restarts,
            };
            let start_mm = nalgebra::Vector3::zeros();
            let summary = if program.as_os_str() == "-" {
                canmotion::offline::plan_stream(
                    &machine,
                    std::io::stdin().lock(),
                    "<stdin>",
                    start_mm,
                    &opts,
                )?
            } else {
                canmotion::offline::plan_file(&machine, &program, start_mm, &opts)?
            };
            out!("{}", summary.report(&machine));
            Ok(())
        }
        Command::Optimize {
            program,
            output,
            machine,
            no_trace,
        } => {
            let machine = machine_or_demo(machine.as_deref())?;
            // Bytes, bounded, read as `plan` reads them (a Latin-1 comment is no error).
            let (name, text) = if program.as_os_str() == "-" {
                let stdin = std::path::Path::new("<stdin>");
                let text = files::read_to_end_bounded(std::io::stdin(), stdin, MAX_CONFIG_BYTES)?;
                ("<stdin>".to_string(), text)
            } else {
                let text = files::read_bounded(&program, MAX_CONFIG_BYTES)?;
                (program.display().to_string(), text)
            };
            let opts = canmotion::optimize::OptimizeOptions { trace: !no_trace };
            let done = canmotion::optimize::optimize(
                &machine,
                &text,
                &name,
                nalgebra::Vector3::zeros(),
                &opts,
            )?;
            files::write_output(&output, &done.text)?;
            out!("{}", done.report.summary());
            outln!("wrote             {}", output.display());
            Ok(())
        }
        Command::Serve {
            machine,
            bus,
            control,
            log,
        } => {
            let machine = machine_or_demo(machine.as_deref())?;
            canmotion::rt::signal::route_stop_signals()
                .map_err(|e| format!("cannot route SIGINT and SIGTERM: {e}"))?;
            let bus = Bus::from_arg(&bus.unwrap_or_else(|| machine.interface.clone()));
            let simulate = matches!(bus, Bus::InProc(_));
            let opts = canmotion::gateway::serve::ServeOptions {
                control_path: control.unwrap_or_else(|| machine.operation.control_socket.clone()),
                simulate,
                injects: Vec::new(),
                log,
            };
            outln!(
                "canmotion serve: machine '{}' ({} axes, {} µs cycle) over {}{}; control socket {}",
                files::Escaped(&machine.name),
                machine.axes.len(),
                machine.cycle_us,
                bus.name(),
                if simulate {
                    " with simulated drives"
                } else {
                    ""
                },
                opts.control_path.display()
            );
            canmotion::gateway::serve::serve(&machine, &bus, &opts)?;
            // SIGTERM and SIGINT are how a service is asked to end: after the orderly end the
            // exit status is 0 (not the 143 of a `run` cut short).
            if let Some(signal) = canmotion::rt::signal::STOP.first() {
                outln!("canmotion serve: {signal:?}: ended in order");
                canmotion::rt::signal::STOP.handled();
            } else {
                outln!("canmotion serve: ended in order");
            }
            Ok(())
        }
        Command::Run {
            program,
            machine,
            bus,
            log,
            resume,
            yes,
            state,
            control,
            no_keys,
        } => {
            let program_on_stdin = program.as_ref().is_some_and(|p| p.as_os_str() == "-");
            let state_given = state.is_some();
            let state = state.or_else(|| match &program {
                Some(p) if p.as_os_str() != "-" => {
                    let mut s = p.as_os_str().to_owned();
                    s.push(".resume");
                    Some(PathBuf::from(s))
                }
                _ => None,
            });
            let machine = machine_or_demo(machine.as_deref())?;
            let (name, text) = match program {
                Some(p) if p.as_os_str() == "-" => {
                    let mut text = String::new();
                    std::io::Read::read_to_string(&mut std::io::stdin(), &mut text)
                        .map_err(|e| format!("<stdin>: cannot read: {e}"))?;
                    ("<stdin>".to_string(), text)
                }
                Some(p) => {
                    // A regular file (not a FIFO or /dev/zero), read as `plan` reads it.
                    let mut bytes = Vec::new();
                    std::io::Read::read_to_end(&mut files::open_input(&p)?, &mut bytes)
                        .map_err(|e| format!("{}: cannot read: {e}", p.display()))?;
                    let text = String::from_utf8_lossy(&bytes).into_owned();
                    (p.display().to_string(), text)
                }
                None => (
                    "examples/demo.ngc (embedded)".to_string(),
                    DEMO_PROGRAM.to_string(),
                ),
            };
            // From here on SIGINT and SIGTERM stop the run in order (no thread is running yet).
            canmotion::rt::signal::route_stop_signals()
                .map_err(|e| format!("cannot route SIGINT and SIGTERM: {e}"))?;
            let bus_arg = bus.unwrap_or_else(|| machine.interface.clone());
            let bus = Bus::from_arg(&bus_arg);
            let simulate = matches!(bus, Bus::InProc(_));
            outln!(
                "canmotion: {} on machine '{}' ({} axes, {} µs cycle) over {}{}",
                name,
                files::Escaped(&machine.name),
                machine.axes.len(),
                machine.cycle_us,
                bus.name(),
                if simulate {
                    " with simulated drives"
                } else {
                    ""
                }
            );
            let opts = RunOptions {
                program_name: name,
                program_text: text,
                log: log.clone(),
                simulate,
                ..RunOptions::default()
            };
            let _control = control
                .as_deref()
                .map(|path| gateway::control::ControlSocket::bind(path, opts.control.clone()))
                .transpose()?;
            if !(no_keys || program_on_stdin || resume && !yes) {
                gateway::control::spawn_stdin_keys(opts.control.clone());
            }
            let progress = std::io::IsTerminal::is_terminal(&std::io::stderr()).then(|| {
                ProgressLine::start(
                    opts.program_text.lines().count() as u64,
                    opts.progress.clone(),
                )
            });
            let outcome = if resume {
                let path = state.as_deref().ok_or(
                    "--resume needs --state FILE when the program comes from standard input or is the embedded demo",
                )?;
                let st = ResumeState::load(path)?;
                resume::resume_program(&machine, &bus, &opts, &st, &mut |p| confirm(p, yes))
            } else {
                resume::run_program(&machine, &bus, &opts)
            };
            if let Some(p) = progress {
                p.finish();
            }
            let summary = match outcome.result {
                Ok(s) => s,
                Err(e) => {
                    if let gateway::GatewayError::Motion(f) = &e {
                        // The cycle and bus figures up to the stop: they matter most when it
                        // failed.
                        eprint!(
                            "cycles            {} in all ({})\n{}",
                            f.timing.cycles,
                            f.timing.overruns_text(),
                            f.bus
                        );
                    }
                    let hint = match (outcome.resume, &state) {
                        (Some(st), Some(path)) => match st.save(path) {
                            Ok(()) => format!(
                                "\nresume point saved in {}: line {} at X{:.4} Y{:.4} Z{:.4} mm; once the cause is fixed, `canmotion run {} --resume{}` continues from there",
                                path.display(),
                                st.line,
                                st.stop_point_mm[0],
                                st.stop_point_mm[1],
                                st.stop_point_mm[2],
                                st.program,
                                if state_given { format!(" --state {}", path.display()) } else { String::new() },
                            ),
                            Err(se) => format!("\nno resume point saved: {se}"),
                        },
                        (Some(_), None) => "\nno resume point saved: give --state FILE for a program from standard input".to_string(),
                        // A resumed motion moved and stopped where no resume point could be
                        // recorded: the old one no longer describes the machine.
                        (None, Some(path))
                            if resume && matches!(&e, gateway::GatewayError::Motion(f) if f.stop.is_some()) =>
                        {
                            match std::fs::remove_file(path) {
                                Ok(()) => format!(
                                    "\nno resume point could be recorded; the old one ({}) was removed: run the program from the start",
                                    path.display()
                                ),
                                Err(_) => String::new(),
                            }
                        }
                        _ => String::new(),
                    };
                    return Err(format!("{e}{hint}").into());
                }
            };
            outln!("{summary}");
            if let Some(l) = log {
                outln!("log               {}", l.display());
            }
            // The program ran to its end: a resume point of it is done with.
            if let Some(path) = &state
                && ResumeState::load(path).is_ok_and(|st| {
                    st.program_hash == resume::fnv1a64(opts.program_text.as_bytes())
                })
            {
                std::fs::remove_file(path)
                    .map_err(|e| format!("{}: cannot remove: {e}", path.display()))?;
                outln!(
                    "resume point      {} removed (the program completed)",
                    path.display()
                );
            }
            Ok(())
        }
        Command::Reset {
            iface,
            target,
            timeout_ms,
            observe_ms,
        } => {
            use canmotion::commands::reset;
            let bus = Bus::from_arg(&iface);
            let nodes = match target {
                canmotion::commands::NmtTarget::Node(n) => vec![n.0],
                canmotion::commands::NmtTarget::All => {
                    let found = reset::drives_on(&bus)?;
                    if found.is_empty() {
                        return Err(format!("no CiA 402 drive answered on {}", bus.name()).into());
                    }
                    found
                }
            };
            let opts = reset::ResetOptions {
                deadline: std::time::Duration::from_millis(timeout_ms),
                observe: std::time::Duration::from_millis(observe_ms),
                ..reset::ResetOptions::default()
            };
            let reports = reset::reset(&bus, &nodes, &opts)?;
            let mut failed = Vec::new();
            for r in &reports {
                if r.ok() {
                    outln!("{r}");
                } else {
                    failed.push(r.to_string());
                }
            }
            if failed.is_empty() {
                Ok(())
            } else {
                Err(failed.join("\ncanmotion: error: ").into())
            }
        }
        Command::Simdrive {
            bus,
            nodes,
            dictionary,
            injects,
            home_switches,
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
                        .with_sim_setup(canmotion::sim::SimSetup {
                            home_switch_counts: home_switches
                                .iter()
                                .rev()
                                .find(|(node, _)| *node == n)
                                .map(|(_, c)| *c),
                            ..Default::default()
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
            use canmotion::commands::{DecodeContext, monitor};
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
                    block,
                },
        } => {
            let mode = if block {
                canmotion::canopen::sdo_client::Mode::Block
            } else {
                canmotion::canopen::sdo_client::Mode::Segmented
            };
            let v = canmotion::commands::sdo::read(
                &Bus::from_arg(&iface),
                node,
                address,
                data_type,
                mode,
            )?;
            outln!("{v}");
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
            let v = canmotion::commands::sdo::write_text(&bus, node, address, data_type, &value)?;
            let v = canmotion::commands::args::format_value(&v);
            outln!("node {node}: {address} = {v} written");
            Ok(())
        }
        Command::Nmt {
            iface,
            command,
            target,
        } => {
            let f = canmotion::commands::nmt::send(&Bus::from_arg(&iface), command, target)?;
            outln!("NMT {command}: {target} ({f})");
            Ok(())
        }
        Command::Scan { iface, timeout_ms } => {
            use canmotion::commands::scan;
            let bus = Bus::from_arg(&iface);
            let opts = scan::ScanOptions {
                timeout: std::time::Duration::from_millis(timeout_ms),
                ..scan::ScanOptions::default()
            };
            let nodes = scan::scan(&bus, &opts)?;
            out!("{}", scan::format_table(&nodes));
            outln!("{} node(s) on {}", nodes.len(), bus.name());
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
            outln!("{}", imported.summary());
            outln!("wrote             {}", output.display());
            Ok(())
        }
    }
}
