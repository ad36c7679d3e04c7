//! Feed override and feed hold of `canmotion run`, from the operator to the cyclic thread.
//!
//! The operator's side (standard input keys, the `--control` Unix socket) turns each command
//! into the wanted state, a requested override and a hold flag, and publishes it with plain
//! atomic stores and a generation count; the cyclic thread polls the generation once per cycle
//! ([`Control::poll`]: two loads, no lock, no allocation) and hands a change to the
//! interpolator, where it takes effect from the next sample (see [`crate::interpolator`]). Each run
//! has its own state ([`super::RunOptions::control`], an `Arc` shared with the socket and the
//! keys that drive it), reset when the run starts.
//!
//! Commands, one per line: `override P` (P in percent, 0 to 200; above 100 % the motion goes
//! faster where the plan and the machine leave room, see [`crate::interpolator`]), `hold`, `resume`,
//! `status`; or a line of keys, each applied in turn: `+` / `-` (10 % up or down, within 0 to
//! 200 %), `0` to `9` (0 to 90 %), `f` (100 %), space or `h` (hold / resume).

use std::io::{BufRead, BufReader, Read, Write};
use std::os::unix::net::{UnixListener, UnixStream};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// Highest override accepted at run time, 200 %.
pub const MAX_REQUEST: f64 = crate::interpolator::MAX_OVERRIDE;

/// Why a command line was refused (it changes nothing).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CommandError {
    /// `override P` with P not a number.
    #[error("override '{text}': not a percentage (e.g. override 50)")]
    NotAPercentage {
        /// What was given.
        text: String,
    },
    /// `override P` with P outside 0 to 200 %.
    #[error("override {percent} %: must be between 0 and {} %", MAX_REQUEST * 100.0)]
    OutOfRange {
        /// What was given, %.
        percent: f64,
    },
    /// An empty line.
    #[error("empty line: override P, hold, resume, status, or keys + - 0-9 f h space")]
    Empty,
    /// Neither a command nor keys.
    #[error(
        "unknown command '{}': override P, hold, resume, status, or keys + - 0-9 f h space",
        line.escape_debug()
    )]
    Unknown {
        /// The line.
        line: String,
    },
    /// The line's bytes are not UTF-8.
    #[error("not UTF-8 (invalid byte at column {column})")]
    NotUtf8 {
        /// The first invalid byte, from 1.
        column: usize,
    },
    /// No run in progress, or its motion has no override ramp.
    #[error(
        "no feed override in this run: the machine's planner keeps no acceleration for it (path_acc_share = 1), or no run is in progress"
    )]
    NoOverride,
}

/// The wanted override and hold of the run in progress (see the module documentation).
#[derive(Debug)]
pub struct Control {
    /// Bumped by every change; the cyclic thread compares it with the last one it saw.
    generation: AtomicU64,
    /// Requested override, `f64` bits (fraction).
    requested: AtomicU64,
    held: AtomicBool,
    /// The run's motion can ramp its override (the machine's planner leaves a share free).
    available: AtomicBool,
    /// Serialises the writers' read-modify-write (never taken by the cyclic thread).
    writer: Mutex<()>,
}

impl Default for Control {
    fn default() -> Control {
        Control::new()
    }
}

impl Control {
    /// No run: 100 %, no hold, and no override available until [`Self::reset`].
    pub const fn new() -> Control {
        Control {
            generation: AtomicU64::new(0),
            requested: AtomicU64::new(0x3FF0_0000_0000_0000), // 1.0
            held: AtomicBool::new(false),
            available: AtomicBool::new(false),
            writer: Mutex::new(()),
        }
    }

    /// A run starts: 100 %, no hold; `available` says whether its motion can ramp.
    pub fn reset(&self, available: bool) {
        let _w = self.writer.lock().unwrap_or_else(|e| e.into_inner());
        self.requested.store(1.0f64.to_bits(), Ordering::Relaxed);
        self.held.store(false, Ordering::Relaxed);
        self.available.store(available, Ordering::Relaxed);
        self.generation.fetch_add(1, Ordering::Release);
    }

    /// The cyclic thread: the wanted `(override, hold)` if it changed since generation `seen`
    /// (updated).
    pub fn poll(&self, seen: &mut u64) -> Option<(f64, bool)> {
        let g = self.generation.load(Ordering::Acquire);
        if g == *seen {
            return None;
        }
        *seen = g;
        Some((
            f64::from_bits(self.requested.load(Ordering::Relaxed)),
            self.held.load(Ordering::Relaxed),
        ))
    }

    /// The wanted state now.
    pub fn wanted(&self) -> (f64, bool) {
        (
            f64::from_bits(self.requested.load(Ordering::Relaxed)),
            self.held.load(Ordering::Relaxed),
        )
    }

    /// One line as received (bytes, without its newline): the answer, `ok ...` or
    /// `error: ...`.
    pub fn answer(&self, line: &[u8]) -> String {
        match std::str::from_utf8(line) {
            Ok(text) => match self.apply_line(text) {
                Ok(ok) => ok,
                Err(e) => format!("error: {e}"),
            },
            Err(e) => format!(
                "error: {}",
                CommandError::NotUtf8 {
                    column: e.valid_up_to() + 1
                }
            ),
        }
    }

    /// Applies one line of commands or keys; the answer (`ok ...`) or why not.
    pub fn apply_line(&self, line: &str) -> Result<String, CommandError> {
        let line = line.trim_end_matches(['\n', '\r']);
        let words: Vec<&str> = line.split_whitespace().collect();
        let _w = self.writer.lock().unwrap_or_else(|e| e.into_inner());
        let (mut requested, mut held) = self.wanted();
        match words.as_slice() {
            ["status"] => return Ok(format!("ok {}", describe(requested, held))),
            ["override", p] => {
                let percent: f64 =
                    p.trim_end_matches('%')
                        .parse()
                        .map_err(|_| CommandError::NotAPercentage {
                            text: (*p).to_string(),
                        })?;
                if !(0.0..=MAX_REQUEST * 100.0).contains(&percent) {
                    return Err(CommandError::OutOfRange { percent });
                }
                requested = percent / 100.0;
            }
            ["hold"] => held = true,
            ["resume"] => held = false,
            [] if line.is_empty() => return Err(CommandError::Empty),
            _ if line.chars().all(|c| "+-0123456789fh ".contains(c)) => {
                for c in line.chars() {
                    match c {
                        '+' => requested = (requested + 0.1).min(MAX_REQUEST),
                        '-' => requested = (requested - 0.1).max(0.0),
                        // Tenths are exact in decimal: round away the binary remainder.
                        '0'..='9' => requested = f64::from(c as u8 - b'0') / 10.0,
                        'f' => requested = 1.0,
                        _ => held = !held, // space or h
                    }
                    requested = (requested * 1000.0).round() / 1000.0;
                }
            }
            _ => {
                return Err(CommandError::Unknown {
                    line: line.to_string(),
                });
            }
        }
        if !self.available.load(Ordering::Relaxed) {
            return Err(CommandError::NoOverride);
        }
        self.requested.store(requested.to_bits(), Ordering::Relaxed);
        self.held.store(held, Ordering::Relaxed);
        self.generation.fetch_add(1, Ordering::Release);
        Ok(format!("ok {}", describe(requested, held)))
    }
}

fn describe(requested: f64, held: bool) -> String {
    let mut s = format!("override {:.0} %", requested * 100.0);
    if held {
        s += ", hold";
    }
    s
}

/// Longest command line accepted, on the socket and on standard input, bytes (the newline
/// excluded). Commands are a few words; anything longer is refused without being kept whole.
pub const MAX_LINE_BYTES: usize = 4096;

/// What [`read_line_bounded`] found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LineRead {
    /// A whole line is in the buffer (without its `\n`), or the last bytes before the end of
    /// the input.
    Line,
    /// More than the bound without a newline: the buffer holds the first `max` bytes, the rest
    /// of the line is still unread (see [`skip_line`]).
    TooLong,
    /// The end of the input, nothing pending.
    Eof,
}

/// Reads one line into `buf` (appending: bytes read before an error, e.g. a read time-out, stay
/// there for the next call), never holding more than `max` bytes of it.
pub fn read_line_bounded<R: BufRead + ?Sized>(
    input: &mut R,
    buf: &mut Vec<u8>,
    max: usize,
) -> std::io::Result<LineRead> {
    loop {
        let available = match input.fill_buf() {
            Ok(b) => b,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(e),
        };
        if available.is_empty() {
            return Ok(if buf.is_empty() {
                LineRead::Eof
            } else {
                LineRead::Line
            });
        }
        let room = max.saturating_sub(buf.len());
        match available.iter().position(|b| *b == b'\n') {
            Some(i) if i <= room => {
                buf.extend_from_slice(&available[..i]);
                input.consume(i + 1);
                return Ok(LineRead::Line);
            }
            _ if available.len() > room => {
                let n = room;
                buf.extend_from_slice(&available[..n]);
                input.consume(n);
                return Ok(LineRead::TooLong);
            }
            _ => {
                let n = available.len();
                buf.extend_from_slice(available);
                input.consume(n);
            }
        }
    }
}

/// Consumes the rest of a line through its `\n`, keeping nothing; `false` when the input ended
/// first.
pub fn skip_line<R: BufRead + ?Sized>(input: &mut R) -> std::io::Result<bool> {
    loop {
        let available = match input.fill_buf() {
            Ok(b) => b,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(e),
        };
        if available.is_empty() {
            return Ok(false);
        }
        match available.iter().position(|b| *b == b'\n') {
            Some(i) => {
                input.consume(i + 1);
                return Ok(true);
            }
            None => {
                let n = available.len();
                input.consume(n);
            }
        }
    }
}

/// At most this many clients connected to the control socket at once; one more is told so and
/// closed.
pub const MAX_CONNECTIONS: usize = 8;

/// A partial line (bytes without their newline) older than this closes its connection.
pub const LINE_TIMEOUT: Duration = Duration::from_secs(2);

/// How often a connection's thread looks up from a blocking read (to see the socket closing).
const POLL: Duration = Duration::from_millis(100);

/// Why the `--control` socket could not be opened.
#[derive(Debug, thiserror::Error)]
pub enum ControlSocketError {
    /// A process listens at the path (a connection to it succeeded).
    #[error(
        "{}: another process is listening on this control socket (a connection to it succeeded): stop it, or give another --control path",
        path.display()
    )]
    InUse {
        /// The socket path.
        path: PathBuf,
    },
    /// Something that is not a socket is at the path; it is not replaced.
    #[error("{}: exists and is not a socket: not replaced, give another --control path", path.display())]
    NotASocket {
        /// The path.
        path: PathBuf,
    },
    /// Listening failed.
    #[error("{}: cannot listen: {source}", path.display())]
    Bind {
        /// The socket path.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
}

/// The `--control` socket: a Unix-domain stream socket at a path, one line in, one line out
/// (`ok ...` or `error: ...`). Each client has a thread of its own (at most
/// [`MAX_CONNECTIONS`]), so an idle or slow client delays nobody: a command is published to the
/// cyclic thread as soon as its line is complete. A line is at most [`MAX_LINE_BYTES`] (a longer
/// one is answered `error: ...` and its connection closed, without being read whole), and a
/// partial line closes its connection after [`LINE_TIMEOUT`]. Removed when dropped.
#[derive(Debug)]
pub struct ControlSocket {
    path: PathBuf,
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl ControlSocket {
    /// Listens at `path` for commands to `control` (a run's). A socket file left by a dead
    /// process (a connection is refused) is replaced; a live one, or anything else at the path,
    /// is refused.
    pub fn bind(path: &Path, control: Arc<Control>) -> Result<ControlSocket, ControlSocketError> {
        ControlSocket::bind_with(path, control)
    }

    /// Listens at `path`, each line of a client answered by `handler` (as [`Self::bind`]).
    pub fn bind_with(
        path: &Path,
        handler: Arc<dyn Handler>,
    ) -> Result<ControlSocket, ControlSocketError> {
        let control = handler;
        let listener = listen(path)?;
        let stop = Arc::new(AtomicBool::new(false));
        let stopped = stop.clone();
        let thread = std::thread::Builder::new()
            .name("canmotion-control".into())
            .spawn(move || accept_loop(&listener, control, &stopped))
            .map_err(|source| ControlSocketError::Bind {
                path: path.to_path_buf(),
                source,
            })?;
        Ok(ControlSocket {
            path: path.to_path_buf(),
            stop,
            thread: Some(thread),
        })
    }

    /// Where it listens.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

fn listen(path: &Path) -> Result<UnixListener, ControlSocketError> {
    let bind_error = |source| ControlSocketError::Bind {
        path: path.to_path_buf(),
        source,
    };
    match UnixListener::bind(path) {
        Ok(l) => Ok(l),
        Err(e) if e.kind() == std::io::ErrorKind::AddrInUse => {
            use std::os::unix::fs::FileTypeExt;
            let is_socket = std::fs::symlink_metadata(path)
                .map(|m| m.file_type().is_socket())
                .map_err(bind_error)?;
            if !is_socket {
                return Err(ControlSocketError::NotASocket {
                    path: path.to_path_buf(),
                });
            }
            match UnixStream::connect(path) {
                Ok(_) => Err(ControlSocketError::InUse {
                    path: path.to_path_buf(),
                }),
                // Nobody listens: the file of a process that died without removing it.
                Err(e) if e.kind() == std::io::ErrorKind::ConnectionRefused => {
                    tracing::warn!("{}: stale control socket replaced", path.display());
                    std::fs::remove_file(path).map_err(bind_error)?;
                    UnixListener::bind(path).map_err(bind_error)
                }
                Err(e) => Err(bind_error(e)),
            }
        }
        Err(e) => Err(bind_error(e)),
    }
}

fn accept_loop(listener: &UnixListener, control: Arc<dyn Handler>, stop: &Arc<AtomicBool>) {
    let mut clients: Vec<std::thread::JoinHandle<()>> = Vec::new();
    for conn in listener.incoming() {
        if stop.load(Ordering::Acquire) {
            break;
        }
        let Ok(mut conn) = conn else { continue };
        clients.retain(|c| !c.is_finished());
        if clients.len() >= MAX_CONNECTIONS {
            let _ = conn.set_write_timeout(Some(POLL));
            let _ = writeln!(
                conn,
                "error: {MAX_CONNECTIONS} control clients are connected already: closing"
            );
            continue;
        }
        let stop = stop.clone();
        let control = control.clone();
        if let Ok(t) = std::thread::Builder::new()
            .name("canmotion-control-client".into())
            .spawn(move || serve(conn, control.as_ref(), &stop))
        {
            clients.push(t);
        }
    }
    for c in clients {
        let _ = c.join();
    }
}

/// A client's stream as [`read_line_bounded`] reads it: ends the reads when the socket closes,
/// and times the partial line (bytes received after the last newline).
struct ClientStream<'a> {
    conn: UnixStream,
    stop: &'a AtomicBool,
    partial_since: Option<Instant>,
}

impl ClientStream<'_> {
    fn partial_expired(&self) -> bool {
        self.partial_since
            .is_some_and(|t| t.elapsed() >= LINE_TIMEOUT)
    }
}

impl Read for ClientStream<'_> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        if self.stop.load(Ordering::Acquire) {
            return Err(std::io::Error::other("control socket closing"));
        }
        if self.partial_expired() {
            return Err(std::io::ErrorKind::TimedOut.into());
        }
        let n = self.conn.read(buf)?;
        match buf[..n].iter().rposition(|b| *b == b'\n') {
            Some(i) if i + 1 == n => self.partial_since = None,
            Some(_) => self.partial_since = Some(Instant::now()),
            None if n > 0 => {
                self.partial_since.get_or_insert_with(Instant::now);
            }
            None => {}
        }
        Ok(n)
    }
}

fn serve(conn: UnixStream, control: &dyn Handler, stop: &AtomicBool) {
    let _ = conn.set_read_timeout(Some(POLL));
    let _ = conn.set_write_timeout(Some(LINE_TIMEOUT));
    let Ok(mut out) = conn.try_clone() else {
        return;
    };
    let mut input = BufReader::with_capacity(
        1024,
        ClientStream {
            conn,
            stop,
            partial_since: None,
        },
    );
    let mut line = Vec::with_capacity(128);
    loop {
        match read_line_bounded(&mut input, &mut line, MAX_LINE_BYTES) {
            Ok(LineRead::Line) => {
                let r = control.handle(&line, &mut out, stop);
                line.clear();
                if r.is_err() {
                    return;
                }
                continue;
            }
            Ok(LineRead::TooLong) => {
                let _ = writeln!(
                    out,
                    "error: line longer than {MAX_LINE_BYTES} bytes: closing the connection"
                );
                return;
            }
            Ok(LineRead::Eof) => return,
            Err(_) if input.get_ref().partial_expired() => {
                let _ = writeln!(
                    out,
                    "error: no end of line within {} s: closing the connection",
                    LINE_TIMEOUT.as_secs()
                );
                return;
            }
            // Nothing for a while (bytes so far stay in `line`): an idle client may stay.
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) =>
            {
                continue;
            }
            Err(_) => return,
        }
    }
}

/// What answers the lines of a control socket's clients.
pub trait Handler: Send + Sync + 'static {
    /// Answers one line (bytes, without its newline) on `out`: one answer line, or, for a
    /// command that streams (`watch`), lines until the client goes or `stop` is set. An error
    /// closes the connection.
    fn handle(&self, line: &[u8], out: &mut UnixStream, stop: &AtomicBool) -> std::io::Result<()>;
}

impl Handler for Control {
    fn handle(&self, line: &[u8], out: &mut UnixStream, _stop: &AtomicBool) -> std::io::Result<()> {
        writeln!(out, "{}", self.answer(line))
    }
}

impl Drop for ControlSocket {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Release);
        // Wake the accept with a connection of our own.
        let _ = UnixStream::connect(&self.path);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
        let _ = std::fs::remove_file(&self.path);
    }
}

/// Applies the lines of `input` (operator keys, commands) to `control` until the input ends.
/// A refused line, a line that is not UTF-8 and a line longer than [`MAX_LINE_BYTES`] (skipped
/// without being kept) are reported to `report` with their line number, and reading goes on.
pub fn read_keys<R: BufRead + ?Sized>(input: &mut R, control: &Control, report: &mut dyn Write) {
    let mut line = Vec::with_capacity(128);
    let mut number = 0u64;
    loop {
        line.clear();
        let read = read_line_bounded(input, &mut line, MAX_LINE_BYTES);
        number += 1;
        let problem = match read {
            Ok(LineRead::Eof) => return,
            Ok(LineRead::Line) => match std::str::from_utf8(&line) {
                Ok(text) => control.apply_line(text).err().map(|e| e.to_string()),
                Err(e) => Some(format!(
                    "{}, ignored",
                    CommandError::NotUtf8 {
                        column: e.valid_up_to() + 1
                    }
                )),
            },
            Ok(LineRead::TooLong) => match skip_line(input) {
                Ok(_) => Some(format!("longer than {MAX_LINE_BYTES} bytes, skipped")),
                Err(e) => {
                    let _ = writeln!(report, "canmotion: standard input: {e}");
                    return;
                }
            },
            Err(e) => {
                let _ = writeln!(report, "canmotion: standard input: {e}");
                return;
            }
        };
        if let Some(p) = problem {
            let _ = writeln!(report, "canmotion: standard input line {number}: {p}");
        }
    }
}

/// Reads commands and keys from standard input ([`read_keys`]) for as long as it is open;
/// problems go to standard error. The thread is left to end with the process.
pub fn spawn_stdin_keys(control: Arc<Control>) {
    let _ = std::thread::Builder::new()
        .name("canmotion-keys".into())
        .spawn(move || {
            read_keys(
                &mut std::io::stdin().lock(),
                &control,
                &mut std::io::stderr(),
            )
        });
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Cursor;

    /// A control state of a test's own, with a run in progress (override available).
    fn running() -> Arc<Control> {
        let c = Arc::new(Control::new());
        c.reset(true);
        c
    }

    /// `size` bytes of `x` made as they are read (nothing of the size is held), then `tail`.
    struct HugeLine {
        left: u64,
        chunk: Vec<u8>,
        tail: Cursor<Vec<u8>>,
    }

    impl HugeLine {
        fn new(size: u64, tail: &[u8]) -> HugeLine {
            HugeLine {
                left: size,
                chunk: vec![b'x'; 64 * 1024],
                tail: Cursor::new(tail.to_vec()),
            }
        }
    }

    impl Read for HugeLine {
        fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
            if self.left == 0 {
                return self.tail.read(buf);
            }
            let n = buf.len().min(self.chunk.len()).min(self.left as usize);
            buf[..n].copy_from_slice(&self.chunk[..n]);
            self.left -= n as u64;
            Ok(n)
        }
    }

    #[test]
    fn a_line_is_read_up_to_its_bound_and_the_rest_skipped() {
        let mut r = BufReader::with_capacity(7, Cursor::new(b"abc\r\ndefghij\nk".to_vec()));
        let mut buf = Vec::new();
        assert_eq!(
            read_line_bounded(&mut r, &mut buf, 5).unwrap(),
            LineRead::Line
        );
        assert_eq!(buf, b"abc\r");
        buf.clear();
        assert_eq!(
            read_line_bounded(&mut r, &mut buf, 5).unwrap(),
            LineRead::TooLong
        );
        assert_eq!(buf, b"defgh");
        assert!(skip_line(&mut r).unwrap());
        buf.clear();
        assert_eq!(
            read_line_bounded(&mut r, &mut buf, 5).unwrap(),
            LineRead::Line
        );
        assert_eq!(buf, b"k");
        buf.clear();
        assert_eq!(
            read_line_bounded(&mut r, &mut buf, 5).unwrap(),
            LineRead::Eof
        );
        // Exactly the bound is a line.
        let mut r = Cursor::new(b"12345\n".to_vec());
        assert_eq!(
            read_line_bounded(&mut r, &mut buf, 5).unwrap(),
            LineRead::Line
        );
        assert_eq!(buf, b"12345");
    }

    #[test]
    fn keys_go_on_after_a_line_that_is_not_utf8() {
        let c = running();
        let mut report = Vec::new();
        read_keys(&mut Cursor::new(b"\xff\xfe\nh\n".to_vec()), &c, &mut report);
        assert_eq!(c.wanted(), (1.0, true), "the h after the bad line holds");
        let report = String::from_utf8(report).unwrap();
        assert!(
            report.contains("standard input line 1: not UTF-8"),
            "{report}"
        );
        assert_eq!(report.lines().count(), 1, "{report}");
    }

    #[test]
    fn a_huge_key_line_is_skipped_without_being_kept() {
        let c = running();
        let mut report = Vec::new();
        let mut input = BufReader::new(HugeLine::new(300 << 20, b"\nh\n"));
        read_keys(&mut input, &c, &mut report);
        assert_eq!(c.wanted(), (1.0, true), "the h after the long line holds");
        let report = String::from_utf8(report).unwrap();
        assert!(
            report.contains("standard input line 1: longer than 4096 bytes, skipped"),
            "{report}"
        );
        // The bounded read itself never holds more than the bound.
        let mut buf = Vec::new();
        let mut input = BufReader::new(HugeLine::new(64 << 20, b"\n"));
        assert_eq!(
            read_line_bounded(&mut input, &mut buf, MAX_LINE_BYTES).unwrap(),
            LineRead::TooLong
        );
        assert_eq!(buf.len(), MAX_LINE_BYTES);
    }

    fn client(path: &Path) -> UnixStream {
        let s = UnixStream::connect(path).unwrap();
        s.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
        s
    }

    fn answer_of(s: &UnixStream) -> String {
        let mut line = String::new();
        BufReader::new(s).read_line(&mut line).unwrap();
        line
    }

    #[test]
    fn idle_and_half_line_clients_do_not_delay_a_hold() {
        let c = running();
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("ctl");
        let _socket = ControlSocket::bind(&path, c.clone()).unwrap();
        let idle = client(&path);
        let mut half = client(&path);
        half.write_all(b"overr").unwrap();
        let mut seen = 0;
        c.poll(&mut seen);
        let t0 = Instant::now();
        let mut second = client(&path);
        second.write_all(b"hold\n").unwrap();
        assert_eq!(answer_of(&second), "ok override 100 %, hold\n");
        assert!(
            t0.elapsed() < Duration::from_millis(500),
            "{:?}",
            t0.elapsed()
        );
        assert_eq!(c.poll(&mut seen), Some((1.0, true)), "published at once");
        // The half line times out; the idle client may stay and is answered afterwards.
        assert_eq!(
            answer_of(&half),
            "error: no end of line within 2 s: closing the connection\n"
        );
        assert!(t0.elapsed() >= LINE_TIMEOUT, "{:?}", t0.elapsed());
        (&idle).write_all(b"status\n").unwrap();
        assert_eq!(answer_of(&idle), "ok override 100 %, hold\n");
    }

    #[test]
    fn a_64_mb_line_is_refused_after_4_kib_without_being_read_whole() {
        let c = running();
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("ctl");
        let _socket = ControlSocket::bind(&path, c.clone()).unwrap();
        let s = client(&path);
        s.set_write_timeout(Some(Duration::from_secs(5))).unwrap();
        let chunk = vec![b'x'; 64 * 1024];
        let mut written = 0usize;
        let mut w = &s;
        let closed = loop {
            if written >= 64 << 20 {
                break false;
            }
            match w.write(&chunk) {
                Ok(n) => written += n,
                Err(_) => break true,
            }
        };
        assert!(closed, "the server read all {written} bytes");
        assert!(
            written < 8 << 20,
            "{written} bytes went in before the close"
        );
        assert_eq!(
            answer_of(&s),
            "error: line longer than 4096 bytes: closing the connection\n"
        );
        // Others are still served.
        let mut other = client(&path);
        other.write_all(b"status\n").unwrap();
        assert_eq!(answer_of(&other), "ok override 100 %\n");
    }

    #[test]
    fn a_stale_socket_is_replaced_a_live_one_or_a_file_refused() {
        let c = running();
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("ctl");
        // A listener dropped without removing its file: what a killed process leaves.
        drop(UnixListener::bind(&path).unwrap());
        assert!(path.exists());
        let live = ControlSocket::bind(&path, c.clone()).expect("stale socket replaced");
        assert!(matches!(
            ControlSocket::bind(&path, c.clone()),
            Err(ControlSocketError::InUse { path: p }) if p == path
        ));
        let mut s = client(&path);
        s.write_all(b"status\n").unwrap();
        assert_eq!(
            answer_of(&s),
            "ok override 100 %\n",
            "the live one still serves"
        );
        drop(live);
        assert!(!path.exists(), "removed when dropped");
        let file = dir.path().join("file");
        std::fs::write(&file, b"keep me").unwrap();
        assert!(matches!(
            ControlSocket::bind(&file, c.clone()),
            Err(ControlSocketError::NotASocket { .. })
        ));
        assert_eq!(std::fs::read(&file).unwrap(), b"keep me");
    }

    #[test]
    fn lines_and_keys_set_the_wanted_state() {
        let c = Control::new();
        let mut seen = 0;
        assert_eq!(
            c.apply_line("override 50"),
            Err(CommandError::NoOverride),
            "no run: refused"
        );
        c.reset(true);
        assert_eq!(c.poll(&mut seen), Some((1.0, false)));
        assert_eq!(c.poll(&mut seen), None);
        assert_eq!(c.apply_line("override 50").unwrap(), "ok override 50 %");
        assert_eq!(c.poll(&mut seen), Some((0.5, false)));
        assert_eq!(c.apply_line("hold").unwrap(), "ok override 50 %, hold");
        assert_eq!(c.poll(&mut seen), Some((0.5, true)));
        c.apply_line("resume").unwrap();
        c.apply_line("++").unwrap();
        assert_eq!(c.wanted(), (0.7, false));
        c.apply_line("9-").unwrap();
        assert_eq!(c.wanted(), (0.8, false));
        c.apply_line("f+").unwrap();
        assert_eq!(c.wanted(), (1.1, false));
        c.apply_line("f++++++++++++").unwrap();
        assert_eq!(c.wanted(), (2.0, false), "+ stops at 200 %");
        c.apply_line(" ").unwrap();
        assert_eq!(c.wanted(), (2.0, true));
        c.apply_line("h0").unwrap();
        assert_eq!(c.wanted(), (0.0, false));
        assert_eq!(c.apply_line("override 150").unwrap(), "ok override 150 %");
        assert_eq!(
            c.apply_line("override 201"),
            Err(CommandError::OutOfRange { percent: 201.0 })
        );
        assert_eq!(
            c.apply_line("override x"),
            Err(CommandError::NotAPercentage { text: "x".into() })
        );
        assert_eq!(
            c.apply_line("stop"),
            Err(CommandError::Unknown {
                line: "stop".into()
            })
        );
        assert_eq!(c.apply_line(""), Err(CommandError::Empty));
        assert_eq!(c.wanted(), (1.5, false), "a refused line changes nothing");
    }
}
