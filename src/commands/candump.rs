//! candump's log format, as `candump -L` (and `candump -l`) writes it and `canplayer` reads it:
//! one frame a line,
//!
//! ```text
//! (1700000000.123456) vcan0 181#3716E8030000
//! (1700000000.124001) vcan0 080#
//! (1700000000.200000) vcan0 701#R
//! ```
//!
//! a timestamp in seconds with six decimals between parentheses, the interface, and the frame in
//! `cansend` syntax: three hex digits of identifier, `#`, the data as hex pairs (or `R` and an
//! optional length digit for a remote frame). The parser also accepts `.` between data bytes
//! (`cansend`'s readability separator), blank lines and `#` comment lines, and a trailing `T`/`R`
//! direction token (newer can-utils). Error frames, as candump and `canmotion monitor` log them
//! (eight hex digits of identifier with `CAN_ERR_FLAG` 0x2000_0000 set:
//! `20000040#0000000000000000`), are read as [`ErrorFrame`]s, so a monitor's log replays. It
//! refuses what [`Frame`] cannot hold, other 29-bit identifiers and CAN FD (`##`), with a message
//! naming the line; a line longer than [`crate::files::MAX_LINE_BYTES`] is refused unread.

use std::fmt;
use std::io::BufRead;
use std::time::{SystemTime, UNIX_EPOCH};

use crate::bus::error::{CAN_ERR_FLAG, parse_error_frame};
use crate::bus::{ErrorFrame, Frame, Received};

/// A timestamp with microsecond resolution, as candump logs it (seconds since the epoch).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Default)]
pub struct Timestamp {
    /// Whole seconds.
    pub secs: u64,
    /// Microseconds, below 1 000 000.
    pub micros: u32,
}

impl Timestamp {
    /// The wall clock now.
    pub fn now() -> Timestamp {
        let d = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .unwrap_or_default();
        Timestamp {
            secs: d.as_secs(),
            micros: d.subsec_micros(),
        }
    }
}

impl fmt::Display for Timestamp {
    /// `1700000000.123456`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}.{:06}", self.secs, self.micros)
    }
}

/// One line of a candump log.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LogRecord {
    /// When the frame was received.
    pub ts: Timestamp,
    /// The interface it was received on (`vcan0`).
    pub iface: String,
    /// The frame: a data or remote frame, or an error frame.
    pub frame: Received,
}

/// A frame in `cansend` syntax as candump logs it: `181#3716E8030000`, `080#`, `701#R`,
/// `701#R1` (a remote frame with a length shows the length digit).
pub fn frame_text(frame: &Frame) -> String {
    let mut s = format!("{:03X}#", frame.id());
    if frame.is_remote() {
        s.push('R');
        if frame.dlc() > 0 {
            s.push_str(&frame.dlc().to_string());
        }
    } else {
        for b in frame.data() {
            s.push_str(&format!("{b:02X}"));
        }
    }
    s
}

/// A data, remote or error frame as candump logs it ([`frame_text`], [`ErrorFrame::text`]).
pub fn received_text(frame: &Received) -> String {
    match frame {
        Received::Frame(f) => frame_text(f),
        Received::Error(e) => e.text(),
    }
}

/// Parse a frame as candump logs it: [`parse_frame`], or an error frame
/// (`20000040#0000000000000000`, eight hex digits of identifier with `CAN_ERR_FLAG` set).
pub fn parse_received(s: &str) -> Result<Received, String> {
    let id = s.split_once('#').map_or(s, |(id, _)| id);
    if id.len() == 8
        && u32::from_str_radix(id, 16).is_ok_and(|id| id & CAN_ERR_FLAG != 0)
        && !s.contains("##")
    {
        return parse_error_frame(s)
            .map(Received::Error)
            .ok_or_else(|| format!("error frame {s:?}: expected up to 8 data bytes in hex"));
    }
    parse_frame(s).map(Received::Frame)
}

/// An error frame's record, as the live monitor logs it.
pub fn error_record(ts: Timestamp, iface: &str, e: ErrorFrame) -> LogRecord {
    LogRecord {
        ts,
        iface: iface.to_string(),
        frame: Received::Error(e),
    }
}

impl fmt::Display for LogRecord {
    /// The log line, without its newline: `(1700000000.123456) vcan0 181#3716E8030000`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "({}) {} {}",
            self.ts,
            self.iface,
            received_text(&self.frame)
        )
    }
}

fn parse_timestamp(s: &str) -> Result<Timestamp, String> {
    let inner = s
        .strip_prefix('(')
        .and_then(|r| r.strip_suffix(')'))
        .ok_or_else(|| format!("expected a timestamp like (1700000000.123456), found {s:?}"))?;
    let (secs, frac) = inner
        .split_once('.')
        .ok_or_else(|| format!("timestamp {s:?} has no decimal point"))?;
    if secs.is_empty() || !secs.bytes().all(|b| b.is_ascii_digit()) {
        return Err(format!("timestamp {s:?}: seconds are not a number"));
    }
    if frac.is_empty() || frac.len() > 9 || !frac.bytes().all(|b| b.is_ascii_digit()) {
        return Err(format!(
            "timestamp {s:?}: expected 1 to 9 digits after the decimal point"
        ));
    }
    let secs: u64 = secs
        .parse()
        .map_err(|_| format!("timestamp {s:?}: seconds out of range"))?;
    // Scale the fraction to nine digits, keep microseconds.
    let nanos: u32 = format!("{frac:0<9}").parse().expect("nine digits");
    Ok(Timestamp {
        secs,
        micros: nanos / 1000,
    })
}

/// Parse a frame in `cansend` syntax (`181#3716E8030000`, `080#`, `701#R`, `701#R1`,
/// `601#40.00.10.00`).
pub fn parse_frame(s: &str) -> Result<Frame, String> {
    if s.contains("##") {
        return Err(format!("{s:?} is a CAN FD frame, which is not supported"));
    }
    let (id, data) = s
        .split_once('#')
        .ok_or_else(|| format!("expected a frame like 181#3716E803, found {s:?}"))?;
    if id.is_empty() || !id.bytes().all(|b| b.is_ascii_hexdigit()) {
        return Err(format!("frame {s:?}: the identifier is not hexadecimal"));
    }
    if id.len() == 8 {
        return Err(format!(
            "frame {s:?} has a 29-bit identifier, which is not supported"
        ));
    }
    if id.len() != 3 {
        return Err(format!(
            "frame {s:?}: an 11-bit identifier has 3 hex digits (8 for 29-bit)"
        ));
    }
    let id = u16::from_str_radix(id, 16).map_err(|_| format!("frame {s:?}: bad identifier"))?;
    if id > 0x7FF {
        return Err(format!("frame {s:?}: identifier above 0x7FF"));
    }
    if let Some(r) = data.strip_prefix(['R', 'r']) {
        let len = match r {
            "" => 0,
            d if d.len() == 1 && d.as_bytes()[0].is_ascii_digit() => d.as_bytes()[0] - b'0',
            _ => {
                return Err(format!(
                    "frame {s:?}: expected R or R0..R8 for a remote frame"
                ));
            }
        };
        return Frame::remote(id, len).ok_or_else(|| format!("frame {s:?}: remote length above 8"));
    }
    let hex: Vec<u8> = data.bytes().filter(|&b| b != b'.').collect();
    if !hex.len().is_multiple_of(2) {
        return Err(format!("frame {s:?}: odd number of hex digits in the data"));
    }
    if hex.len() > 16 {
        return Err(format!(
            "frame {s:?}: {} data bytes, a classic CAN frame has at most 8",
            hex.len() / 2
        ));
    }
    let mut bytes = Vec::with_capacity(8);
    for pair in hex.chunks(2) {
        let digits = std::str::from_utf8(pair).map_err(|_| format!("frame {s:?}: bad data"))?;
        let b = u8::from_str_radix(digits, 16)
            .map_err(|_| format!("frame {s:?}: {digits:?} is not a hex byte"))?;
        bytes.push(b);
    }
    Frame::new(id, &bytes).ok_or_else(|| format!("frame {s:?}: invalid"))
}

/// Parse one log line. `Ok(None)` for a blank line or a `#` comment.
pub fn parse_line(line: &str) -> Result<Option<LogRecord>, String> {
    let line = line.trim();
    if line.is_empty() || line.starts_with('#') {
        return Ok(None);
    }
    let mut tokens = line.split_whitespace();
    let (Some(ts), Some(iface), Some(frame)) = (tokens.next(), tokens.next(), tokens.next()) else {
        return Err(format!(
            "expected \"(TIMESTAMP) IFACE ID#DATA\", found {line:?}"
        ));
    };
    match (tokens.next(), tokens.next()) {
        (None, _) | (Some("T" | "R"), None) => {}
        (Some(extra), _) => return Err(format!("unexpected {extra:?} after the frame")),
    }
    let ts = parse_timestamp(ts)?;
    let frame = parse_received(frame)?;
    Ok(Some(LogRecord {
        ts,
        iface: iface.to_string(),
        frame,
    }))
}

/// Parse a whole log; the first malformed line gives `file:line: message`.
pub fn parse_log(file: &str, text: &str) -> Result<Vec<LogRecord>, super::ToolError> {
    LogReader::new(file, text.as_bytes()).collect()
}

/// Reads a log line by line, yielding records or the first error (`file:line: message`).
pub struct LogReader<R> {
    file: String,
    input: R,
    line: usize,
    buf: Vec<u8>,
    failed: bool,
}

impl<R: BufRead> LogReader<R> {
    /// Read from `input`; `file` names it in errors.
    pub fn new(file: &str, input: R) -> LogReader<R> {
        LogReader {
            file: file.to_string(),
            input,
            line: 0,
            buf: Vec::new(),
            failed: false,
        }
    }
}

impl<R: BufRead> Iterator for LogReader<R> {
    type Item = Result<LogRecord, super::ToolError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.failed {
            return None;
        }
        loop {
            self.line += 1;
            let err = |message: String, line: usize, file: &str| super::ToolError::Log {
                file: file.to_string(),
                line,
                message,
            };
            // A bounded line: `/dev/zero` or a log with no line ends must not fill memory.
            match crate::files::read_bounded_line(
                &mut self.input,
                &mut self.buf,
                crate::files::MAX_LINE_BYTES,
                std::path::Path::new(&self.file),
                self.line,
            ) {
                Ok(false) => return None,
                Ok(true) => {}
                Err(e) => {
                    self.failed = true;
                    return Some(Err(super::ToolError::File(e)));
                }
            }
            let Ok(text) = std::str::from_utf8(&self.buf) else {
                self.failed = true;
                return Some(Err(err(
                    "not UTF-8 text".to_string(),
                    self.line,
                    &self.file,
                )));
            };
            match parse_line(text) {
                Ok(None) => continue,
                Ok(Some(r)) => return Some(Ok(r)),
                Err(message) => {
                    self.failed = true;
                    return Some(Err(err(message, self.line, &self.file)));
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn candump_lines_parse() {
        let r = parse_line("(1700000000.123456) vcan0 181#3716E8030000")
            .unwrap()
            .unwrap();
        assert_eq!(
            r.ts,
            Timestamp {
                secs: 1_700_000_000,
                micros: 123_456
            }
        );
        assert_eq!(r.iface, "vcan0");
        assert_eq!(
            r.frame,
            Received::Frame(Frame::new(0x181, &[0x37, 0x16, 0xE8, 3, 0, 0]).unwrap())
        );
        assert_eq!(r.to_string(), "(1700000000.123456) vcan0 181#3716E8030000");
        let sync = parse_line("(0.5) can0 080#").unwrap().unwrap();
        assert_eq!(sync.frame, Received::Frame(Frame::new(0x080, &[]).unwrap()));
        assert_eq!(sync.ts.micros, 500_000);
        let rtr = parse_line("(1.000000) vcan0 701#R").unwrap().unwrap();
        assert_eq!(rtr.frame, Received::Frame(Frame::remote(0x701, 0).unwrap()));
        assert_eq!(rtr.to_string(), "(1.000000) vcan0 701#R");
        let rtr1 = parse_line("(1.000000) vcan0 701#R1").unwrap().unwrap();
        assert_eq!(
            rtr1.frame,
            Received::Frame(Frame::remote(0x701, 1).unwrap())
        );
        assert_eq!(rtr1.to_string(), "(1.000000) vcan0 701#R1");
        let dots = parse_line("(1.000000) vcan0 601#40.00.10.00.00.00.00.00 R")
            .unwrap()
            .unwrap();
        assert_eq!(
            dots.frame,
            Received::Frame(Frame::new(0x601, &[0x40, 0, 0x10, 0, 0, 0, 0, 0]).unwrap())
        );
        // An error frame, as candump and the monitor log it.
        let bus_off = parse_line("(1.000000) vcan0 20000040#0000000000000000")
            .unwrap()
            .unwrap();
        assert_eq!(bus_off.frame, Received::Error(ErrorFrame::bus_off()));
        assert_eq!(
            bus_off.to_string(),
            "(1.000000) vcan0 20000040#0000000000000000"
        );
        assert_eq!(parse_line("   ").unwrap(), None);
        assert_eq!(parse_line("# a comment").unwrap(), None);
    }

    #[test]
    fn malformed_lines_say_why() {
        for (line, why) in [
            ("1700000000.1 vcan0 181#00", "timestamp"),
            ("(17x.1) vcan0 181#00", "not a number"),
            ("(1700000000) vcan0 181#00", "decimal point"),
            ("(1.0) vcan0", "expected"),
            ("(1.0) vcan0 18100", "expected a frame"),
            ("(1.0) vcan0 181#0", "odd number"),
            ("(1.0) vcan0 181#001122334455667788", "at most 8"),
            ("(1.0) vcan0 181#GG", "not a hex byte"),
            ("(1.0) vcan0 800#00", "above 0x7FF"),
            ("(1.0) vcan0 18#00", "3 hex digits"),
            ("(1.0) vcan0 12345678#00", "29-bit"),
            ("(1.0) vcan0 123##100", "CAN FD"),
            ("(1.0) vcan0 701#R9", "remote length"),
            ("(1.0) vcan0 181#00 extra", "unexpected"),
        ] {
            let e = parse_line(line).unwrap_err();
            assert!(e.contains(why), "{line:?}: {e}");
        }
    }

    #[test]
    fn errors_name_file_and_line() {
        let text = "(1.000000) vcan0 080#\n\n(2.000000) vcan0 181#0\n";
        let e = parse_log("bus.log", text).unwrap_err().to_string();
        assert!(e.starts_with("bus.log:3: "), "{e}");
        let ok = parse_log("bus.log", "(1.000000) vcan0 080#\n# c\n(2.0) vcan0 080#01").unwrap();
        assert_eq!(ok.len(), 2);
    }

    fn arb_record() -> impl Strategy<Value = LogRecord> {
        (
            0u64..=99_999_999_999,
            0u32..1_000_000,
            "[a-z][a-z0-9_-]{0,14}",
            0u16..=0x7FF,
            any::<bool>(),
            proptest::collection::vec(any::<u8>(), 0..=8),
        )
            .prop_map(|(secs, micros, iface, id, rtr, data)| LogRecord {
                ts: Timestamp { secs, micros },
                iface,
                frame: Received::Frame(if rtr {
                    Frame::remote(id, data.len() as u8).unwrap()
                } else {
                    Frame::new(id, &data).unwrap()
                }),
            })
    }

    proptest! {
        #[test]
        fn write_then_parse_is_identity(recs in proptest::collection::vec(arb_record(), 0..20)) {
            let text: String = recs.iter().map(|r| format!("{r}\n")).collect();
            let back = parse_log("p.log", &text).unwrap();
            prop_assert_eq!(back, recs);
        }

        #[test]
        fn parser_never_panics_on_random_lines(line in "\\PC{0,60}") {
            let _ = parse_line(&line);
        }

        #[test]
        fn parser_never_panics_on_near_misses(
            line in "\\(?[0-9.]{0,14}\\)? ?[a-z0-9]{0,5} ?[0-9A-Fa-f#Rr.]{0,22} ?[TR]?"
        ) {
            let _ = parse_line(&line);
        }
    }
}
