//! SIGINT and SIGTERM during `canmotion run`: counted, never acted on where they land.
//!
//! [`route_stop_signals`] blocks both signals in the calling thread, and so in every thread it
//! spawns afterwards, and waits for them in a thread of its own (`sigwait`): no handler runs on
//! an interrupted thread, and no system call anywhere sees `EINTR`. Each signal bumps a count in
//! [`STOP`]; the cyclic thread reads it once per cycle (one atomic load) and turns the first
//! into a stop on the path (a feed hold, then the drives disabled, see
//! [`crate::master::cyclic::CyclicMaster::stop_on_path`]) and the second into the fault stop.
//! The process exits with [`Signal::exit_code`] (128 + the signal number) once the run has
//! wound down.

use std::sync::atomic::{AtomicBool, AtomicI32, AtomicU32, Ordering};

/// The stop signal type lives with the alarms that name it (the sans-I/O master cannot import
/// this module); signals themselves are process-wide, so their counts stay statics here.
pub use crate::master::alarm::Signal;

/// The stop signals received (see the module documentation).
#[derive(Debug)]
pub struct StopSignals {
    count: AtomicU32,
    /// The first and the latest signal's number (0: none).
    first: AtomicI32,
    latest: AtomicI32,
    /// [`route_stop_signals`] was called: the count belongs to the process, not to one run.
    routed: AtomicBool,
}

/// The process's stop signals.
pub static STOP: StopSignals = StopSignals {
    count: AtomicU32::new(0),
    first: AtomicI32::new(0),
    latest: AtomicI32::new(0),
    routed: AtomicBool::new(false),
};

impl StopSignals {
    /// How many stop signals arrived.
    pub fn count(&self) -> u32 {
        self.count.load(Ordering::Acquire)
    }

    /// The first one.
    pub fn first(&self) -> Option<Signal> {
        Signal::from_number(self.first.load(Ordering::Acquire))
    }

    /// The latest one.
    pub fn latest(&self) -> Option<Signal> {
        Signal::from_number(self.latest.load(Ordering::Acquire))
    }

    /// One more signal (from the signal thread; tests call it directly).
    pub fn record(&self, signal: Signal) {
        let _ =
            self.first
                .compare_exchange(0, signal.number(), Ordering::AcqRel, Ordering::Acquire);
        self.latest.store(signal.number(), Ordering::Release);
        self.count.fetch_add(1, Ordering::AcqRel);
    }

    /// A run starts. In a process whose signals are routed here the count is kept (a signal
    /// between routing and the run's start must stop it); anywhere else (a library user, a test
    /// recording signals by hand) it starts again from none, so nothing leaks from one run to
    /// the next.
    pub fn begin_run(&self) {
        if !self.routed.load(Ordering::Acquire) {
            self.clear();
        }
    }

    /// The signals so far were handled as a request to end (`canmotion serve`'s orderly end):
    /// they no longer set the exit status.
    pub fn handled(&self) {
        self.clear();
    }

    fn clear(&self) {
        self.count.store(0, Ordering::Release);
        self.first.store(0, Ordering::Release);
        self.latest.store(0, Ordering::Release);
    }
}

/// Routes SIGINT and SIGTERM to [`STOP`]: call it before any other thread is started (threads
/// started earlier keep the default action, which ends the process).
pub fn route_stop_signals() -> std::io::Result<()> {
    // SAFETY: `sigset_t` is plain data; sigemptyset/sigaddset initialise it before any use.
    let mut set: libc::sigset_t = unsafe { std::mem::zeroed() };
    // SAFETY: `set` is a valid, exclusively borrowed sigset_t.
    unsafe {
        libc::sigemptyset(&mut set);
        libc::sigaddset(&mut set, libc::SIGINT);
        libc::sigaddset(&mut set, libc::SIGTERM);
    }
    // SAFETY: `set` is initialised; the old mask is not wanted (null is allowed).
    let r = unsafe { libc::pthread_sigmask(libc::SIG_BLOCK, &set, std::ptr::null_mut()) };
    if r != 0 {
        return Err(std::io::Error::from_raw_os_error(r));
    }
    STOP.clear();
    STOP.routed.store(true, Ordering::Release);
    std::thread::Builder::new()
        .name("canmotion-signals".into())
        .spawn(move || {
            loop {
                let mut signal: libc::c_int = 0;
                // SAFETY: `set` is an initialised sigset_t owned by this thread, `signal` a
                // valid out pointer; both signals are blocked in every thread, so they queue for
                // this wait.
                let r = unsafe { libc::sigwait(&set, &mut signal) };
                if r != 0 {
                    continue;
                }
                if let Some(s) = Signal::from_number(signal) {
                    STOP.record(s);
                }
            }
        })?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exit_codes_and_names() {
        assert_eq!(Signal::Int.exit_code(), 130);
        assert_eq!(Signal::Term.exit_code(), 143);
        assert_eq!(Signal::Term.name(), "SIGTERM");
    }

    #[test]
    fn a_count_of_its_own_records_first_and_latest() {
        let s = StopSignals {
            count: AtomicU32::new(0),
            first: AtomicI32::new(0),
            latest: AtomicI32::new(0),
            routed: AtomicBool::new(false),
        };
        s.record(Signal::Term);
        s.record(Signal::Int);
        assert_eq!(
            (s.count(), s.first(), s.latest()),
            (2, Some(Signal::Term), Some(Signal::Int))
        );
        s.begin_run();
        assert_eq!((s.count(), s.first()), (0, None), "a run starts from none");
    }
}
