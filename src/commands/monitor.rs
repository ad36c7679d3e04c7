//! `canmotion monitor`: every frame on the bus, decoded, one line each, optionally logged in
//! candump's format; or a recorded candump log decoded the same way.
//!
//! A line is the candump log record of the frame, then what it means:
//!
//! ```text
//! (1700000000.123456) vcan0 201#1F0050C30000     RPDO1 node 1 (axis X): controlword 0x001F Enable operation, enable IP (bit 4); IP setpoint 50000 counts (50.000 mm)
//! (1700000000.123501) vcan0 080#                 SYNC
//! ```
//!
//! The controller's error frames are shown too, decoded per `linux/can/error.h`, and logged as
//! candump logs them (`20000040#0000000000000000`):
//!
//! ```text
//! (1700000000.125000) vcan0 20000040#0000000000000000 error frame: bus-off
//! ```

use std::fs::File;
use std::io::{BufReader, LineWriter, Write};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use super::ToolError;
use super::candump::{LogReader, LogRecord, Timestamp, error_record, frame_text};
use super::decode::{DecodeContext, decode};
use crate::bus::{Bus, ErrorFrame, Received};

/// When to stop, and where to log.
#[derive(Debug, Clone, Default)]
pub struct MonitorOptions {
    /// Write every frame to this file in candump's log format (`candump -L`, `canplayer`).
    pub log: Option<PathBuf>,
    /// Stop after this many frames.
    pub count: Option<u64>,
    /// Stop after this long (live monitoring only).
    pub duration: Option<Duration>,
}

/// The interface name a log records for `bus` (`sim` for the in-process bus).
pub fn iface_name(bus: &Bus) -> &str {
    match bus {
        Bus::InProc(_) => "sim",
        Bus::SocketCan(name) => name,
    }
}

/// The monitor's line for a record: the candump log record, padded, then the decoded text.
pub fn format_line(rec: &LogRecord, ctx: &DecodeContext) -> String {
    match &rec.frame {
        Received::Frame(f) => format!(
            "({}) {} {:<20} {}",
            rec.ts,
            rec.iface,
            frame_text(f),
            decode(f, ctx)
        ),
        Received::Error(e) => format_error_line(rec.ts, &rec.iface, e),
    }
}

/// The monitor's line for an error frame: timestamp, interface, the frame as candump logs it,
/// then what it says.
pub fn format_error_line(ts: Timestamp, iface: &str, e: &ErrorFrame) -> String {
    format!("({ts}) {iface} {:<20} error frame: {e}", e.text())
}

struct Sink<'a> {
    out: &'a mut dyn Write,
    log: Option<(PathBuf, LineWriter<File>)>,
}

impl Sink<'_> {
    fn open<'a>(out: &'a mut dyn Write, log: Option<&Path>) -> Result<Sink<'a>, ToolError> {
        let log = match log {
            Some(p) => {
                let f = File::create(p).map_err(|source| ToolError::Io {
                    file: p.to_path_buf(),
                    source,
                })?;
                Some((p.to_path_buf(), LineWriter::new(f)))
            }
            None => None,
        };
        Ok(Sink { out, log })
    }

    /// Log and print one record; `Ok(false)` when the output was closed (a pipe's reader left).
    fn put(&mut self, rec: &LogRecord, ctx: &DecodeContext) -> Result<bool, ToolError> {
        if let Some((path, w)) = &mut self.log {
            writeln!(w, "{rec}").map_err(|source| ToolError::Io {
                file: path.clone(),
                source,
            })?;
        }
        match writeln!(self.out, "{}", format_line(rec, ctx)) {
            Ok(()) => Ok(true),
            Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Ok(false),
            Err(source) => Err(ToolError::Io {
                file: PathBuf::from("stdout"),
                source,
            }),
        }
    }

    fn finish(&mut self) -> Result<(), ToolError> {
        if let Some((path, w)) = &mut self.log {
            w.flush().map_err(|source| ToolError::Io {
                file: path.clone(),
                source,
            })?;
        }
        match self.out.flush() {
            Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => Err(ToolError::Io {
                file: PathBuf::from("stdout"),
                source: e,
            }),
            _ => Ok(()),
        }
    }
}

/// Monitor `bus` live: print every frame to `out` (and log it) until `opts.count` frames or
/// `opts.duration` (forever when neither is given). Error frames of every class are shown (and
/// counted) too. Returns the number of frames seen.
pub fn monitor(
    bus: &Bus,
    ctx: &DecodeContext,
    opts: &MonitorOptions,
    out: &mut dyn Write,
) -> Result<u64, ToolError> {
    let mut port = bus.open(&[])?;
    port.set_error_mask(crate::bus::error::class::ALL)?;
    let iface = iface_name(bus).to_string();
    let mut sink = Sink::open(out, opts.log.as_deref())?;
    let deadline = opts.duration.map(|d| Instant::now() + d);
    let mut n = 0u64;
    while opts.count.is_none_or(|c| n < c) {
        let wait = match deadline {
            Some(d) => {
                let now = Instant::now();
                if now >= d {
                    break;
                }
                (d - now).min(Duration::from_millis(200))
            }
            None => Duration::from_millis(200),
        };
        let frame = match port.recv_any(wait)? {
            None => continue,
            Some(Received::Frame(f)) => f,
            Some(Received::Error(e)) => {
                n += 1;
                if !sink.put(&error_record(Timestamp::now(), &iface, e), ctx)? {
                    break;
                }
                continue;
            }
        };
        let rec = LogRecord {
            ts: Timestamp::now(),
            iface: iface.clone(),
            frame: Received::Frame(frame),
        };
        n += 1;
        if !sink.put(&rec, ctx)? {
            break;
        }
    }
    sink.finish()?;
    Ok(n)
}

/// Decode a recorded candump log from `input` (named `name` in errors) to `out`, logging it
/// again to `opts.log` if given, up to `opts.count` frames. A malformed line stops with
/// `name:line: why`, after the lines before it were printed. Returns the number of frames.
pub fn replay_reader(
    name: &str,
    input: impl std::io::BufRead,
    ctx: &DecodeContext,
    opts: &MonitorOptions,
    out: &mut dyn Write,
) -> Result<u64, ToolError> {
    let mut sink = Sink::open(out, opts.log.as_deref())?;
    let mut n = 0u64;
    for rec in LogReader::new(name, input) {
        if opts.count.is_some_and(|c| n >= c) {
            break;
        }
        let rec = rec?;
        n += 1;
        if !sink.put(&rec, ctx)? {
            break;
        }
    }
    sink.finish()?;
    Ok(n)
}

/// [`replay_reader`] on a file.
pub fn replay(
    path: &Path,
    ctx: &DecodeContext,
    opts: &MonitorOptions,
    out: &mut dyn Write,
) -> Result<u64, ToolError> {
    // A regular file only (a FIFO would block); its lines are bounded as they are read.
    let f = crate::files::open_input(path)?;
    replay_reader(
        &path.display().to_string(),
        BufReader::new(f),
        ctx,
        opts,
        out,
    )
}

/// The monitor's lines for a log given as text (tests and tools).
pub fn decode_log(name: &str, text: &str, ctx: &DecodeContext) -> Result<Vec<String>, ToolError> {
    let mut out = Vec::new();
    replay_reader(
        name,
        text.as_bytes(),
        ctx,
        &MonitorOptions::default(),
        &mut out,
    )?;
    Ok(String::from_utf8_lossy(&out)
        .lines()
        .map(str::to_string)
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bus::inproc::InProcBus;
    use crate::bus::{Filter, Frame};

    #[test]
    fn lines_start_with_the_log_record() {
        let rec = LogRecord {
            ts: Timestamp {
                secs: 1_700_000_000,
                micros: 42,
            },
            iface: "vcan0".into(),
            frame: Received::Frame(Frame::new(0x080, &[]).unwrap()),
        };
        assert_eq!(
            format_line(&rec, &DecodeContext::new()),
            "(1700000000.000042) vcan0 080#                 SYNC"
        );
    }

    #[test]
    fn live_monitor_prints_and_logs_what_others_send() {
        let bus = InProcBus::new();
        let dir = tempfile::tempdir().unwrap();
        let log = dir.path().join("bus.log");
        let b = Bus::InProc(bus.clone());
        let sender = std::thread::spawn(move || {
            let mut p = bus.port(&[Filter::exact(0x7FF)]);
            std::thread::sleep(Duration::from_millis(50));
            for f in [
                Frame::new(0x000, &[1, 0]).unwrap(),
                Frame::new(0x080, &[]).unwrap(),
                Frame::new(0x705, &[5]).unwrap(),
            ] {
                crate::bus::Port::send(&mut p, &f).unwrap();
            }
        });
        let mut out = Vec::new();
        let opts = MonitorOptions {
            log: Some(log.clone()),
            count: Some(3),
            duration: Some(Duration::from_secs(5)),
        };
        let n = monitor(&b, &DecodeContext::new(), &opts, &mut out).unwrap();
        sender.join().unwrap();
        assert_eq!(n, 3);
        let text = String::from_utf8(out).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        assert!(
            lines[0].ends_with("sim 000#0100             NMT start: all nodes"),
            "{text}"
        );
        assert!(
            lines[2].ends_with("heartbeat node 5: operational"),
            "{text}"
        );
        let logged = std::fs::read_to_string(&log).unwrap();
        let recs = crate::commands::candump::parse_log("bus.log", &logged).unwrap();
        assert_eq!(
            recs.iter().map(|r| r.frame).collect::<Vec<_>>(),
            vec![
                Received::Frame(Frame::new(0x000, &[1, 0]).unwrap()),
                Received::Frame(Frame::new(0x080, &[]).unwrap()),
                Received::Frame(Frame::new(0x705, &[5]).unwrap())
            ]
        );
        assert!(recs.iter().all(|r| r.iface == "sim"));
    }

    #[test]
    fn live_monitor_decodes_error_frames_and_logs_them_as_candump_does() {
        let bus = InProcBus::new();
        let dir = tempfile::tempdir().unwrap();
        let log = dir.path().join("bus.log");
        let b = Bus::InProc(bus.clone());
        let sender = std::thread::spawn(move || {
            let mut p = bus.port(&[Filter::exact(0x7FF)]);
            std::thread::sleep(Duration::from_millis(50));
            crate::bus::Port::send_error(&mut p, &ErrorFrame::error_passive(128, 0)).unwrap();
            crate::bus::Port::send_error(&mut p, &ErrorFrame::bus_off()).unwrap();
        });
        let mut out = Vec::new();
        let opts = MonitorOptions {
            log: Some(log.clone()),
            count: Some(2),
            duration: Some(Duration::from_secs(5)),
        };
        let n = monitor(&b, &DecodeContext::new(), &opts, &mut out).unwrap();
        sender.join().unwrap();
        assert_eq!(n, 2);
        let text = String::from_utf8(out).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        assert!(
            lines[0].ends_with(
                "sim 20000204#0030000000008000 error frame: controller: RX error-passive, TX error-passive; error counters TX 128, RX 0"
            ),
            "{text}"
        );
        assert!(
            lines[1].ends_with("sim 20000040#0000000000000000 error frame: bus-off"),
            "{text}"
        );
        let logged = std::fs::read_to_string(&log).unwrap();
        assert!(
            logged.ends_with(" sim 20000040#0000000000000000\n"),
            "{logged}"
        );
        // What the monitor logs, the monitor replays, line for line as it showed it live.
        let mut replayed = Vec::new();
        let n = replay(
            &log,
            &DecodeContext::new(),
            &MonitorOptions::default(),
            &mut replayed,
        )
        .unwrap();
        assert_eq!(n, 2);
        assert_eq!(String::from_utf8(replayed).unwrap(), text);
    }

    #[test]
    fn replay_stops_at_a_malformed_line_with_its_number() {
        let mut out = Vec::new();
        let e = replay_reader(
            "rec.log",
            "(1.000000) vcan0 080#\n(2.000000) vcan0 080#XYZ\n".as_bytes(),
            &DecodeContext::new(),
            &MonitorOptions::default(),
            &mut out,
        )
        .unwrap_err()
        .to_string();
        assert!(e.starts_with("rec.log:2: frame"), "{e}");
        assert_eq!(String::from_utf8(out).unwrap().lines().count(), 1);
    }
}
