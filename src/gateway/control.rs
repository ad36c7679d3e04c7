//! Feed override and feed hold of `canmotion run`, from the operator to the cyclic thread.
//!
//! The operator's side (standard input keys, the `--control` Unix socket) turns each command
//! into the wanted state, a requested override and a hold flag, and publishes it with plain
//! atomic stores and a generation count; the cyclic thread polls the generation once per cycle
//! ([`Control::poll`]: two loads, no lock, no allocation) and hands a change to the
//! interpolator, where it takes effect from the next sample (see [`crate::interp`]). One run at
//! a time per process, as for [`super::progress::PROGRESS`]: the state lives in one static,
//! [`CONTROL`], reset when a run starts.
//!
//! Commands, one per line: `override P` (P in percent, 0 to 200; above 100 % the motion goes
//! faster where the plan and the machine leave room, see [`crate::interp`]), `hold`, `resume`,
//! `status`; or a line of keys, each applied in turn: `+` / `-` (10 % up or down, within 0 to
//! 200 %), `0` to `9` (0 to 90 %), `f` (100 %), space or `h` (hold / resume).

use std::io::{BufRead, BufReader, Write};
use std::os::unix::net::{UnixListener, UnixStream};
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

/// Highest override accepted at run time, 200 %.
pub const MAX_REQUEST: f64 = crate::interp::MAX_OVERRIDE;

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

/// The control of the run in progress.
pub static CONTROL: Control = Control::new();

impl Control {
    const fn new() -> Control {
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

    /// Applies one line of commands or keys; the answer (`ok ...`) or why not.
    pub fn apply_line(&self, line: &str) -> Result<String, String> {
        let line = line.trim_end_matches(['\n', '\r']);
        let words: Vec<&str> = line.split_whitespace().collect();
        let _w = self.writer.lock().unwrap_or_else(|e| e.into_inner());
        let (mut requested, mut held) = self.wanted();
        match words.as_slice() {
            ["status"] => return Ok(format!("ok {}", describe(requested, held))),
            ["override", p] => {
                let percent: f64 = p
                    .trim_end_matches('%')
                    .parse()
                    .map_err(|_| format!("override '{p}': not a percentage (e.g. override 50)"))?;
                if !(0.0..=MAX_REQUEST * 100.0).contains(&percent) {
                    return Err(format!(
                        "override {percent} %: must be between 0 and {} %",
                        MAX_REQUEST * 100.0
                    ));
                }
                requested = percent / 100.0;
            }
            ["hold"] => held = true,
            ["resume"] => held = false,
            [] if line.is_empty() => {
                return Err(
                    "empty line: override P, hold, resume, status, or keys + - 0-9 f h space"
                        .into(),
                );
            }
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
                return Err(format!(
                    "unknown command '{line}': override P, hold, resume, status, or keys + - 0-9 f h space"
                ));
            }
        }
        if !self.available.load(Ordering::Relaxed) {
            return Err(
                "no feed override in this run: the machine's planner keeps no acceleration for it (path_acc_share = 1), or no run is in progress"
                    .into(),
            );
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

/// The `--control` socket: a Unix-domain stream socket at a path, one line in, one line out
/// (`ok ...` or `error: ...`), any number of clients one after another. Removed when dropped.
#[derive(Debug)]
pub struct ControlSocket {
    path: PathBuf,
    stop: std::sync::Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl ControlSocket {
    /// Listens at `path` (which must not exist).
    pub fn bind(path: &Path) -> std::io::Result<ControlSocket> {
        let listener = UnixListener::bind(path).map_err(|e| {
            std::io::Error::new(e.kind(), format!("{}: cannot listen: {e}", path.display()))
        })?;
        let stop = std::sync::Arc::new(AtomicBool::new(false));
        let stopped = stop.clone();
        let thread = std::thread::Builder::new()
            .name("canmotion-control".into())
            .spawn(move || {
                for conn in listener.incoming() {
                    if stopped.load(Ordering::Acquire) {
                        return;
                    }
                    if let Ok(conn) = conn {
                        serve(conn);
                    }
                }
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

fn serve(conn: UnixStream) {
    let Ok(mut out) = conn.try_clone() else {
        return;
    };
    for line in BufReader::new(conn).lines() {
        let Ok(line) = line else { return };
        let answer = match CONTROL.apply_line(&line) {
            Ok(ok) => ok,
            Err(e) => format!("error: {e}"),
        };
        if writeln!(out, "{answer}").is_err() {
            return;
        }
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

/// Reads commands and keys from standard input, one line at a time, for as long as it is
/// open; errors go to standard error. The thread is left to end with the process.
pub fn spawn_stdin_keys() {
    let _ = std::thread::Builder::new()
        .name("canmotion-keys".into())
        .spawn(|| {
            let stdin = std::io::stdin();
            for line in stdin.lock().lines() {
                let Ok(line) = line else { return };
                if let Err(e) = CONTROL.apply_line(&line) {
                    eprintln!("canmotion: {e}");
                }
            }
        });
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lines_and_keys_set_the_wanted_state() {
        let c = Control::new();
        let mut seen = 0;
        assert!(c.apply_line("override 50").is_err(), "no run: refused");
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
        for bad in ["override 201", "override x", "stop", ""] {
            assert!(
                c.apply_line(bad)
                    .unwrap_err()
                    .contains(if bad == "override 201" {
                        "between 0 and 200 %"
                    } else if bad == "override x" {
                        "not a percentage"
                    } else {
                        "override P, hold, resume"
                    })
            );
        }
        assert_eq!(c.wanted(), (1.5, false), "a refused line changes nothing");
    }
}
