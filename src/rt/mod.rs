//! The cyclic real-time loop: its own thread, woken at absolute deadlines
//! (`clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME)`), at SCHED_FIFO with locked memory when
//! the process is permitted, never bursting a backlog after an overrun.

pub mod period_stats;
pub mod signal;

use std::time::Duration;

/// A monotonic timestamp in nanoseconds (CLOCK_MONOTONIC).
pub fn now_ns() -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: clock_gettime writes into the timespec we own.
    unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
}

/// Sleep until the absolute monotonic time `deadline_ns`.
pub fn sleep_until_ns(deadline_ns: u64) {
    let ts = libc::timespec {
        tv_sec: (deadline_ns / 1_000_000_000) as libc::time_t,
        tv_nsec: (deadline_ns % 1_000_000_000) as libc::c_long,
    };
    loop {
        // SAFETY: a plain syscall with a timespec we own; no remaining-time output with ABSTIME.
        let r = unsafe {
            libc::clock_nanosleep(
                libc::CLOCK_MONOTONIC,
                libc::TIMER_ABSTIME,
                &ts,
                std::ptr::null_mut(),
            )
        };
        if r != libc::EINTR {
            return;
        }
    }
}

/// What the real-time set-up achieved, to tell the user.
#[derive(Debug, Clone, Default)]
pub struct RtSetup {
    /// SCHED_FIFO priority in force, if any.
    pub fifo_priority: Option<i32>,
    /// Whether memory is locked.
    pub memory_locked: bool,
    /// Why not, where not.
    pub notes: Vec<String>,
}

impl std::fmt::Display for RtSetup {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.fifo_priority {
            Some(p) => write!(f, "SCHED_FIFO priority {p}")?,
            None => write!(f, "normal scheduling")?,
        }
        write!(
            f,
            ", memory {}",
            if self.memory_locked {
                "locked"
            } else {
                "not locked"
            }
        )?;
        for n in &self.notes {
            write!(f, "; {n}")?;
        }
        Ok(())
    }
}

/// The SCHED_FIFO priority of the cyclic thread: `CANMOTION_RT_PRIORITY` (1–99), 0 for normal
/// scheduling, default 80.
///
/// 0 is for User-Mode Linux (the vcan0 suite): its guest runs every process on one host thread,
/// and a SCHED_FIFO thread inside it starves the simulated drives' process.
pub fn priority_from_env() -> i32 {
    std::env::var("CANMOTION_RT_PRIORITY")
        .ok()
        .and_then(|v| v.parse().ok())
        .filter(|p| (0..=99).contains(p))
        .unwrap_or(80)
}

/// Try to make the calling thread real-time: SCHED_FIFO at `priority` (none when 0) and locked
/// memory. Failures are reported, not fatal: the loop still runs, with more jitter.
pub fn make_realtime(priority: i32) -> RtSetup {
    let mut s = RtSetup::default();
    let param = libc::sched_param {
        sched_priority: priority,
    };
    // SAFETY: sets the scheduling policy of the calling thread (pid 0).
    let r = if priority == 0 {
        0
    } else {
        unsafe { libc::sched_setscheduler(0, libc::SCHED_FIFO, &param) }
    };
    if priority == 0 {
        s.notes
            .push("SCHED_FIFO off (CANMOTION_RT_PRIORITY=0)".into());
    } else if r == 0 {
        s.fifo_priority = Some(priority);
    } else {
        s.notes.push(format!(
            "SCHED_FIFO not permitted ({}); run as root or grant CAP_SYS_NICE / an rtprio limit",
            std::io::Error::last_os_error()
        ));
    }
    match lock_memory() {
        Ok(()) => s.memory_locked = true,
        Err(e) => s.notes.push(format!("mlockall failed ({e})")),
    }
    s
}

/// Lock the process's memory, once per process: `MCL_FUTURE` keeps every later mapping locked,
/// and a second `mlockall` would walk every mapping again under the process's memory-map lock,
/// stalling any other thread that maps memory (another cyclic loop in the same process, as in
/// the test binaries) for milliseconds.
fn lock_memory() -> std::io::Result<()> {
    static LOCKED: std::sync::OnceLock<Result<(), i32>> = std::sync::OnceLock::new();
    let locked = *LOCKED.get_or_init(|| {
        // SAFETY: locks the process's pages; no pointers involved.
        let r = unsafe { libc::mlockall(libc::MCL_CURRENT | libc::MCL_FUTURE) };
        if r == 0 {
            Ok(())
        } else {
            Err(std::io::Error::last_os_error().raw_os_error().unwrap_or(0))
        }
    });
    locked.map_err(std::io::Error::from_raw_os_error)
}

/// Cycle timing statistics kept by the loop.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Timing {
    /// Cycles run.
    pub cycles: u64,
    /// Cycles whose work ended after the next deadline (skipped, never burst).
    pub overruns: u64,
    /// Largest lateness of a wake-up after its deadline.
    pub max_wake_late: Duration,
    /// The latest wake-ups more than half a period late (a drive then sees a late SYNC).
    pub late_wakes: LateWakes,
}

impl Timing {
    /// `N overruns`, or `1 overrun`.
    pub fn overruns_text(&self) -> String {
        match self.overruns {
            1 => "1 overrun".to_string(),
            n => format!("{n} overruns"),
        }
    }
}

/// A wake-up of the cyclic thread more than half a period after its deadline.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct LateWake {
    /// The cycle it started ([`Timing::cycles`] after it).
    pub cycle: u64,
    /// How late.
    pub late: Duration,
}

/// The latest [`LATE_WAKES`] late wake-ups, in a fixed ring: recording one on the cyclic path
/// allocates nothing.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct LateWakes {
    ring: [LateWake; LATE_WAKES],
    /// How many were recorded in all (the ring keeps the latest).
    pub total: u64,
}

/// How many late wake-ups [`LateWakes`] keeps.
pub const LATE_WAKES: usize = 32;

impl LateWakes {
    /// Record one.
    pub fn push(&mut self, w: LateWake) {
        self.ring[(self.total % LATE_WAKES as u64) as usize] = w;
        self.total += 1;
    }

    /// The ones kept, oldest first.
    pub fn iter(&self) -> impl Iterator<Item = &LateWake> {
        let n = self.total.min(LATE_WAKES as u64) as usize;
        let start = (self.total as usize).wrapping_sub(n) % LATE_WAKES;
        (0..n).map(move |k| &self.ring[(start + k) % LATE_WAKES])
    }
}

/// A periodic schedule with absolute deadlines.
#[derive(Debug)]
pub struct Ticker {
    period_ns: u64,
    next_ns: u64,
    /// The timing so far.
    pub timing: Timing,
}

impl Ticker {
    /// The first deadline is one period from now.
    pub fn new(period: Duration) -> Ticker {
        let period_ns = period.as_nanos() as u64;
        Ticker {
            period_ns,
            next_ns: now_ns() + period_ns,
            timing: Timing::default(),
        }
    }

    /// Sleep until the next deadline, then move it one period on. After an overrun the missed
    /// deadlines are dropped (counted), not run back to back.
    pub fn wait(&mut self) {
        sleep_until_ns(self.next_ns);
        self.woke(now_ns());
    }

    /// The deadline the next [`Ticker::wait`] sleeps to (CLOCK_MONOTONIC, ns).
    pub fn next_deadline_ns(&self) -> u64 {
        self.next_ns
    }

    /// The deadline of the cycle running now (the one the last wait slept to), ns.
    pub fn this_deadline_ns(&self) -> u64 {
        self.next_ns - self.period_ns
    }

    /// The bookkeeping of a wake-up at `now_ns` for the deadline slept to: lateness, the next
    /// deadline one period on along the original grid, and any deadline already past counted as
    /// an overrun and skipped.
    fn woke(&mut self, now_ns: u64) {
        let late = Duration::from_nanos(now_ns.saturating_sub(self.next_ns));
        self.timing.max_wake_late = self.timing.max_wake_late.max(late);
        self.timing.cycles += 1;
        if late.as_nanos() as u64 > self.period_ns / 2 {
            self.timing.late_wakes.push(LateWake {
                cycle: self.timing.cycles,
                late,
            });
        }
        self.next_ns += self.period_ns;
        if now_ns >= self.next_ns {
            let missed = (now_ns - self.next_ns) / self.period_ns + 1;
            self.timing.overruns += missed;
            self.next_ns += missed * self.period_ns;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_overrun_skips_deadlines_instead_of_bursting() {
        let mut t = Ticker::new(Duration::from_millis(1));
        t.wait();
        std::thread::sleep(Duration::from_millis(5));
        let before = t.timing.overruns;
        t.wait();
        let after_overrun = now_ns();
        t.wait();
        // The next wait after an overrun still sleeps (no back-to-back burst).
        assert!(now_ns() > after_overrun);
        assert!(t.timing.overruns > before, "{:?}", t.timing);
    }

    #[test]
    fn deadlines_stay_on_the_grid_and_every_skipped_one_is_counted() {
        let ms = 1_000_000;
        let mut t = Ticker {
            period_ns: ms,
            next_ns: 10 * ms,
            timing: Timing::default(),
        };
        t.woke(10 * ms + 30_000); // 30 µs late: no overrun, the grid holds
        assert_eq!((t.next_deadline_ns(), t.timing.overruns), (11 * ms, 0));
        assert_eq!(t.this_deadline_ns(), 10 * ms);
        t.woke(13 * ms + 500_000); // woke 2.5 periods late: deadlines 12 and 13 ms are gone
        assert_eq!((t.next_deadline_ns(), t.timing.overruns), (14 * ms, 2));
        t.woke(14 * ms); // on time again, no catching up
        assert_eq!((t.next_deadline_ns(), t.timing.overruns), (15 * ms, 2));
        assert_eq!(t.timing.cycles, 3);
        assert_eq!(t.timing.max_wake_late, Duration::from_micros(2500));
        // Only the wake-up more than half a period late is kept, with its cycle.
        let late: Vec<LateWake> = t.timing.late_wakes.iter().copied().collect();
        assert_eq!(
            late,
            [LateWake {
                cycle: 2,
                late: Duration::from_micros(2500)
            }]
        );
    }

    #[test]
    fn the_late_wake_ring_keeps_the_latest() {
        let mut r = LateWakes::default();
        for c in 0..(LATE_WAKES as u64 + 5) {
            r.push(LateWake {
                cycle: c,
                late: Duration::ZERO,
            });
        }
        let cycles: Vec<u64> = r.iter().map(|w| w.cycle).collect();
        assert_eq!(cycles, (5..LATE_WAKES as u64 + 5).collect::<Vec<_>>());
    }
}
