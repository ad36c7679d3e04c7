//! The cyclic thread's side of the bus: what it receives besides feedback (the controller's
//! error frames), how it sends a cycle's frames by a deadline, and the SYNC period statistics.
//!
//! - **Error frames** ([`crate::bus::error`]). Warnings (error-warning level, error-passive,
//!   protocol and transceiver errors, missing ACKs) are logged and counted for the summary; the
//!   run goes on. **Bus-off** is a fault, and so is the interface going down (ENETDOWN) or away:
//!   the controller sends nothing more, so the gateway cannot stop the drives along their path.
//!   It ends the run at once with every setpoint held where it was, and says that each drive stops
//!   by its heartbeat consumer (0x1016) when the gateway's heartbeat stops arriving.
//! - **A full transmit queue** (ENOBUFS). Each frame of a cycle (SYNC first, then the RPDOs) is
//!   retried until the cycle's send deadline: the end of the synchronous window (0x1007) after
//!   the cycle's start, or half a cycle when there is no window (a drive discards a synchronous
//!   RPDO outside the window anyway). What cannot be queued by then is dropped, counted and
//!   reported; when the SYNC itself cannot be queued the cycle's RPDOs are not sent either (the
//!   drives would latch them a period late). A drive that misses its setpoint holds the last one,
//!   so every lost cycle adds `v·T` to its lag behind the plan: [`tolerated_lost_cycles`] is the
//!   largest run of lost cycles that keeps this lag inside every axis's following-error window
//!   (0x6065) at full speed, and one more is a fault that stops the run.
//! - **SYNC period statistics** ([`crate::rt::period_stats`]) from the kernel's receive
//!   timestamps of the SYNC frames on a socket of their own ([`crate::bus::sync_tap`]), or from
//!   the sending clock on the in-process bus.

use std::sync::Arc;
use std::time::Duration;

use crate::bus::error::{self, Severity};
use crate::bus::sync_tap::SyncTap;
use crate::bus::{BusError, ErrorFrame, Frame, Port, Received, TrySend};
use crate::config::Machine;
use crate::rt::period_stats::{PeriodStats, PeriodSummary, TimestampSource};

use crate::master::alarm::{Alarm, BusLoss, SharedBusError};
use crate::master::cyclic::CyclicMaster;
use crate::master::supervision::Supervision;

/// The longest run of lost cycles a fault is declared after, whatever the following-error
/// windows allow: the master's own alarm on missing process data (50 cycles) comes no later.
pub const MAX_TOLERATED_LOST_CYCLES: u32 = 50;

/// The SYNC tap is read every this many cycles (32 SYNCs fit its receive buffer many times).
const TAP_READ_EVERY: u64 = 32;

/// How long to wait between two attempts at a full transmit queue.
const RETRY_PAUSE: Duration = Duration::from_micros(50);

/// The largest number of consecutive cycles whose setpoints may be lost before the run stops:
/// per axis `⌊following_error_mm / (max_vel_mm_s · T)⌋` (a drive holding its last setpoint falls
/// behind by `v·T` per lost cycle, and faults once the lag passes 0x6065), the smallest over the
/// axes, at least 1 and at most [`MAX_TOLERATED_LOST_CYCLES`].
///
/// The demo machine at 4 ms: X and Y 2 mm / (200 mm/s · 4 ms) = 2.5, Z 1 mm / (100 mm/s · 4 ms)
/// = 2.5: two lost cycles in a row are tolerated, the third stops the run.
pub fn tolerated_lost_cycles(machine: &Machine) -> u32 {
    let t = machine.cycle_s();
    machine
        .axes
        .iter()
        .map(|a| (a.following_error_mm / (a.max_vel_mm_s * t)).floor())
        .fold(f64::INFINITY, f64::min)
        .clamp(1.0, f64::from(MAX_TOLERATED_LOST_CYCLES)) as u32
}

/// The clock the sender reads while it retries; a test gives it a fake one.
pub trait Clock {
    /// Monotonic time, ns.
    fn now_ns(&mut self) -> u64;
    /// Wait `d`.
    fn pause(&mut self, d: Duration);
}

/// CLOCK_MONOTONIC and a thread sleep.
#[derive(Debug, Default)]
pub struct MonotonicClock;

impl Clock for MonotonicClock {
    fn now_ns(&mut self) -> u64 {
        crate::rt::now_ns()
    }
    fn pause(&mut self, d: Duration) {
        std::thread::sleep(d);
    }
}

/// Frames the cyclic thread could not queue by their cycle's deadline.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct TxLoss {
    /// Cycles that lost at least one frame.
    pub cycles: u64,
    /// SYNC frames lost.
    pub syncs: u64,
    /// RPDOs (setpoints) lost, including those not sent because their SYNC was lost.
    pub setpoints: u64,
    /// The longest run of consecutive cycles with a loss.
    pub longest_run: u32,
    /// The run of lost cycles tolerated before a fault ([`tolerated_lost_cycles`]).
    pub tolerated_run: u32,
    /// The first cycle with a loss.
    pub first_cycle: Option<u64>,
}

impl std::fmt::Display for TxLoss {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "transmit queue full (ENOBUFS) in {} cycles from cycle {}: {} SYNC and {} setpoints not sent, at most {} cycles in a row (a fault after {})",
            self.cycles,
            self.first_cycle.unwrap_or(0),
            self.syncs,
            self.setpoints,
            self.longest_run,
            self.tolerated_run
        )
    }
}

/// How one cycle's sending went.
#[derive(Debug)]
pub enum CycleSent {
    /// Every frame was queued.
    All,
    /// Some frames could not be queued by the deadline.
    Lost {
        /// Whether the SYNC was among them.
        sync: bool,
        /// RPDOs not queued.
        setpoints: usize,
        /// Consecutive cycles with a loss, this one included.
        run: u32,
    },
    /// The port failed otherwise.
    Failed(BusError),
}

/// Sends each cycle's frames by its deadline and keeps count of what it could not.
#[derive(Debug)]
pub struct CycleSender {
    run: u32,
    loss: TxLoss,
}

impl CycleSender {
    /// A sender that declares a fault after `tolerated` consecutive lost cycles.
    pub fn new(tolerated: u32) -> CycleSender {
        CycleSender {
            run: 0,
            loss: TxLoss {
                tolerated_run: tolerated,
                ..TxLoss::default()
            },
        }
    }

    /// The losses so far.
    pub fn loss(&self) -> &TxLoss {
        &self.loss
    }

    /// Whether the current run of lost cycles is longer than tolerated.
    pub fn run_too_long(&self) -> bool {
        self.run > self.loss.tolerated_run
    }

    /// Queue `frames` (the SYNC, identifier `sync_cob_id`, first when present) on `port`,
    /// retrying a full queue until `deadline_ns` on `clock`. Each frame is tried at least once.
    pub fn send(
        &mut self,
        port: &mut dyn Port,
        frames: &[Frame],
        sync_cob_id: u16,
        deadline_ns: u64,
        cycle: u64,
        clock: &mut dyn Clock,
    ) -> CycleSent {
        let mut unsent = None;
        'frames: for (k, f) in frames.iter().enumerate() {
            loop {
                match port.try_send(f) {
                    Ok(TrySend::Queued) => continue 'frames,
                    Ok(TrySend::QueueFull) => {
                        if clock.now_ns() + RETRY_PAUSE.as_nanos() as u64 > deadline_ns {
                            unsent = Some(k);
                            break 'frames;
                        }
                        clock.pause(RETRY_PAUSE);
                    }
                    Err(e) => return CycleSent::Failed(e),
                }
            }
        }
        let Some(k) = unsent else {
            self.run = 0;
            return CycleSent::All;
        };
        let sync = frames[k].id() == sync_cob_id;
        let setpoints = frames[k..].iter().filter(|f| f.id() != sync_cob_id).count();
        self.run += 1;
        self.loss.cycles += 1;
        self.loss.syncs += u64::from(sync);
        self.loss.setpoints += setpoints as u64;
        self.loss.longest_run = self.loss.longest_run.max(self.run);
        self.loss.first_cycle.get_or_insert(cycle);
        CycleSent::Lost {
            sync,
            setpoints,
            run: self.run,
        }
    }
}

/// Error frames the run went on after, counted by what they said.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BusWarning {
    /// The decoded error frame.
    pub what: String,
    /// How many.
    pub count: u64,
    /// Cycle of the first.
    pub first_cycle: u64,
    /// Cycle of the last.
    pub last_cycle: u64,
}

impl std::fmt::Display for BusWarning {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "CAN error frame: {} ×{} (cycles {}–{})",
            self.what, self.count, self.first_cycle, self.last_cycle
        )
    }
}

/// What the cyclic thread's bus side reports at the end of a run.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct BusReport {
    /// Error frames that were warnings.
    pub warnings: Vec<BusWarning>,
    /// Frames that could not be queued in time.
    pub tx_loss: TxLoss,
    /// SYNC period statistics, once two SYNCs were seen.
    pub sync_period: Option<PeriodSummary>,
    /// Whether the bus was lost (bus-off, interface down).
    pub bus_lost: bool,
}

impl std::fmt::Display for BusReport {
    /// One line each, as in the run's summary: error-frame warnings, frames not sent, the SYNC
    /// period statistics (nothing when there is nothing to say).
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        for w in &self.warnings {
            writeln!(f, "warning           {w}")?;
        }
        if self.tx_loss.cycles > 0 {
            writeln!(f, "warning           {}", self.tx_loss)?;
        }
        if let Some(s) = &self.sync_period {
            writeln!(f, "SYNC period       {s}")?;
        }
        Ok(())
    }
}

/// The cyclic thread's bus side: receive, send, watch, measure.
pub struct CyclicBus {
    iface: Arc<str>,
    sync_cob_id: u16,
    budget_ns: u64,
    sender: CycleSender,
    clock: MonotonicClock,
    /// Warnings keyed by class and the detail bytes (not the counters, which change each time).
    warnings: Vec<((u32, [u8; 6]), BusWarning)>,
    tap: Option<SyncTap>,
    sync_stats: PeriodStats,
    start_ns: u64,
    line: Option<usize>,
    completed_line: Option<usize>,
    lost: bool,
    measure_calls: u64,
}

impl CyclicBus {
    /// For `machine` on the interface named `iface`, with a SYNC tap when the bus has one.
    /// Asks `port` for every error frame.
    pub fn new(
        machine: &Machine,
        iface: &str,
        port: &mut dyn Port,
        tap: Option<SyncTap>,
    ) -> Result<CyclicBus, BusError> {
        port.set_error_mask(error::class::ALL)?;
        let period_ns = u64::from(machine.cycle_us) * 1000;
        let budget_ns = match machine.sync_window_us {
            0 => period_ns / 2,
            w => u64::from(w) * 1000,
        };
        Ok(CyclicBus {
            iface: Arc::from(iface),
            sync_cob_id: machine.sync_cob_id,
            budget_ns,
            sender: CycleSender::new(tolerated_lost_cycles(machine)),
            clock: MonotonicClock,
            warnings: Vec::new(),
            tap,
            sync_stats: PeriodStats::new(Duration::from_nanos(period_ns)),
            start_ns: crate::rt::now_ns(),
            line: None,
            completed_line: None,
            lost: false,
            measure_calls: 0,
        })
    }

    /// Whether the bus is gone: nothing more is to be sent on it.
    pub fn lost(&self) -> bool {
        self.lost
    }

    /// Everything received since the last cycle: feedback to `master`, heartbeats and EMCYs to
    /// `sup` (stamped `now`), error frames counted or, for a bus-off, the end of the run. An error of the port other than the bus going away is
    /// returned (the caller stops the run with it).
    pub fn receive(
        &mut self,
        port: &mut dyn Port,
        master: &mut CyclicMaster,
        sup: &mut Supervision,
        now: Duration,
        cycle: u64,
    ) -> Result<(), BusError> {
        // The program line whose predecessor just completed.
        if master.line() != self.line {
            self.completed_line = self.line.or(self.completed_line);
            self.line = master.line();
        }
        loop {
            match port.recv_any(Duration::ZERO) {
                Ok(Some(Received::Frame(f))) => {
                    sup.on_frame(now, &f, master);
                    master.on_frame(&f);
                }
                Ok(Some(Received::Error(e))) => self.on_error_frame(&e, master, cycle),
                Ok(None) => return Ok(()),
                Err(e) if e.is_bus_lost() => {
                    self.bus_lost(BusLoss::Port(SharedBusError(Arc::new(e))), master, cycle);
                    return Ok(());
                }
                Err(e) => return Err(e),
            }
        }
    }

    fn on_error_frame(&mut self, e: &ErrorFrame, master: &mut CyclicMaster, cycle: u64) {
        match e.severity() {
            Severity::BusOff => {
                let frame = (e.class() != error::class::BUS_OFF).then_some(*e);
                let cause = BusLoss::BusOff {
                    iface: self.iface.clone(),
                    frame,
                };
                self.bus_lost(cause, master, cycle);
            }
            Severity::Warning => {
                let d = e.data();
                let key = (
                    e.class() & !error::class::COUNTERS,
                    [d[0], d[1], d[2], d[3], d[4], d[5]],
                );
                match self.warnings.iter_mut().find(|(k, _)| *k == key) {
                    Some((_, w)) => {
                        w.count += 1;
                        w.last_cycle = cycle;
                    }
                    None => {
                        tracing::warn!("CAN interface '{}': error frame: {e}", self.iface);
                        self.warnings.push((
                            key,
                            BusWarning {
                                what: e.to_string(),
                                count: 1,
                                first_cycle: cycle,
                                last_cycle: cycle,
                            },
                        ));
                    }
                }
            }
            Severity::Info => tracing::info!("CAN interface '{}': {e}", self.iface),
        }
    }

    /// End the run: nothing can be sent any more.
    fn bus_lost(&mut self, cause: BusLoss, master: &mut CyclicMaster, cycle: u64) {
        if self.lost {
            return;
        }
        self.lost = true;
        let t_s = (crate::rt::now_ns() - self.start_ns) as f64 * 1e-9;
        master.bus_lost(Alarm::BusLost {
            cause,
            cycle,
            t_s,
            completed_line: self.completed_line,
        });
    }

    /// Send this cycle's `frames`; the cycle's deadline was `cycle_deadline_ns` (its start on
    /// the schedule). A loss is counted, and a run of them longer than the drives tolerate, or a
    /// failing port, stops the run through `master`. Returns a port error to keep.
    pub fn send(
        &mut self,
        port: &mut dyn Port,
        frames: &[Frame],
        cycle_deadline_ns: u64,
        master: &mut CyclicMaster,
        cycle: u64,
    ) -> Option<SharedBusError> {
        if self.lost {
            return None;
        }
        let deadline = cycle_deadline_ns + self.budget_ns;
        let sent = self.sender.send(
            port,
            frames,
            self.sync_cob_id,
            deadline,
            cycle,
            &mut self.clock,
        );
        // The SYNC went out now (or not at all): on a bus without kernel timestamps, this is
        // the best time there is.
        if self.tap.is_none() && frames.first().is_some_and(|f| f.id() == self.sync_cob_id) {
            if matches!(sent, CycleSent::Lost { sync: true, .. }) {
                // A missing SYNC shows as a long period.
            } else {
                self.sync_stats.record(crate::rt::now_ns());
            }
        }
        match sent {
            CycleSent::All => None,
            CycleSent::Lost {
                sync,
                setpoints,
                run,
            } => {
                if run == 1 {
                    tracing::warn!(
                        "CAN interface '{}': transmit queue full (ENOBUFS): cycle {cycle} lost {}{setpoints} setpoints",
                        self.iface,
                        if sync { "its SYNC and " } else { "" }
                    );
                }
                if self.sender.run_too_long() {
                    let l = self.sender.loss();
                    master.alarm(
                        0,
                        Alarm::TxQueueFull {
                            iface: self.iface.clone(),
                            run,
                            tolerated_run: l.tolerated_run,
                            lost_cycles: l.cycles,
                        },
                    );
                }
                None
            }
            CycleSent::Failed(e) if e.is_bus_lost() => {
                self.bus_lost(BusLoss::Port(SharedBusError(Arc::new(e))), master, cycle);
                None
            }
            CycleSent::Failed(e) => {
                let error = SharedBusError(Arc::new(e));
                master.alarm(
                    0,
                    Alarm::Bus {
                        error: error.clone(),
                    },
                );
                Some(error)
            }
        }
    }

    /// Read the SYNC tap (after sending), every `TAP_READ_EVERY` calls: the timestamps are
    /// the kernel's, so reading late costs nothing but buffer, and each read is a system call
    /// or two.
    pub fn measure(&mut self) {
        self.measure_calls += 1;
        if self.measure_calls.is_multiple_of(TAP_READ_EVERY) {
            self.read_tap();
        }
    }

    fn read_tap(&mut self) {
        let stats = &mut self.sync_stats;
        if let Some(tap) = &mut self.tap {
            // A failing tap only costs the statistics.
            let _ = tap.drain(|t| stats.record(t));
        }
    }

    /// The end-of-run report.
    pub fn report(mut self) -> BusReport {
        self.read_tap();
        let source = match self.tap {
            Some(_) => TimestampSource::KernelRx(self.iface.to_string()),
            None => TimestampSource::SenderClock,
        };
        BusReport {
            warnings: self.warnings.into_iter().map(|(_, w)| w).collect(),
            tx_loss: self.sender.loss().clone(),
            sync_period: self.sync_stats.summary(source),
            bus_lost: self.lost,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::master::cyclic::Phase;

    /// A port whose transmit queue is full for the frames numbered in `full_at` (counting every
    /// attempt), recording what it queued.
    /// Whether the queue is full at attempt `n` for this frame.
    type IsFull = Box<dyn Fn(usize, &Frame) -> bool + Send>;

    struct FullQueue {
        attempts: usize,
        full: IsFull,
        queued: Vec<Frame>,
    }

    impl Port for FullQueue {
        fn send(&mut self, _: &Frame) -> Result<(), BusError> {
            unreachable!("the cyclic path never waits in send")
        }
        fn recv_timeout(&mut self, _: Duration) -> Result<Option<Frame>, BusError> {
            Ok(None)
        }
        fn set_filters(&mut self, _: &[crate::bus::Filter]) -> Result<(), BusError> {
            Ok(())
        }
        fn try_send(&mut self, f: &Frame) -> Result<TrySend, BusError> {
            self.attempts += 1;
            if (self.full)(self.attempts, f) {
                Ok(TrySend::QueueFull)
            } else {
                self.queued.push(*f);
                Ok(TrySend::Queued)
            }
        }
    }

    fn full_queue(full: impl Fn(usize, &Frame) -> bool + Send + 'static) -> FullQueue {
        FullQueue {
            attempts: 0,
            full: Box::new(full),
            queued: Vec::new(),
        }
    }

    /// Time that passes only when the sender pauses.
    struct FakeClock {
        now_ns: u64,
        pauses: u32,
    }

    impl Clock for FakeClock {
        fn now_ns(&mut self) -> u64 {
            self.now_ns
        }
        fn pause(&mut self, d: Duration) {
            self.pauses += 1;
            self.now_ns += d.as_nanos() as u64;
        }
    }

    fn frames() -> Vec<Frame> {
        vec![
            Frame::new(0x80, &[]).unwrap(),
            Frame::new(0x201, &[1; 6]).unwrap(),
            Frame::new(0x202, &[2; 6]).unwrap(),
            Frame::new(0x203, &[3; 6]).unwrap(),
        ]
    }

    #[test]
    fn a_briefly_full_queue_is_retried_within_the_deadline_and_nothing_is_lost() {
        // Full for the first three attempts at RPDO 2 (150 µs), deadline 2 ms away.
        let mut port = full_queue(|n, f| f.id() == 0x202 && n <= 5);
        let mut clock = FakeClock {
            now_ns: 0,
            pauses: 0,
        };
        let mut s = CycleSender::new(2);
        let r = s.send(&mut port, &frames(), 0x80, 2_000_000, 7, &mut clock);
        assert!(matches!(r, CycleSent::All), "{r:?}");
        assert_eq!(port.queued, frames());
        assert_eq!(clock.pauses, 3);
        assert_eq!(
            s.loss(),
            &TxLoss {
                tolerated_run: 2,
                ..TxLoss::default()
            }
        );
    }

    #[test]
    fn what_cannot_be_queued_by_the_deadline_is_counted_never_sent_late() {
        let mut port = full_queue(|_, f| f.id() == 0x202);
        let mut clock = FakeClock {
            now_ns: 0,
            pauses: 0,
        };
        let mut s = CycleSender::new(2);
        let r = s.send(&mut port, &frames(), 0x80, 1_000_000, 7, &mut clock);
        assert!(
            matches!(
                r,
                CycleSent::Lost {
                    sync: false,
                    setpoints: 2,
                    run: 1
                }
            ),
            "{r:?}"
        );
        // SYNC and the first RPDO went; RPDO 2 was retried up to the deadline, RPDO 3 dropped
        // with it rather than sent after the deadline.
        assert_eq!(port.queued, frames()[..2]);
        assert!(clock.now_ns <= 1_000_000);
        assert_eq!(s.loss().setpoints, 2);
        assert_eq!(s.loss().first_cycle, Some(7));
    }

    #[test]
    fn a_lost_sync_takes_its_setpoints_with_it() {
        let mut port = full_queue(|_, f| f.id() == 0x80);
        let mut clock = FakeClock {
            now_ns: 0,
            pauses: 0,
        };
        let mut s = CycleSender::new(2);
        let r = s.send(&mut port, &frames(), 0x80, 500_000, 1, &mut clock);
        assert!(
            matches!(
                r,
                CycleSent::Lost {
                    sync: true,
                    setpoints: 3,
                    run: 1
                }
            ),
            "{r:?}"
        );
        assert!(port.queued.is_empty());
        assert_eq!((s.loss().syncs, s.loss().setpoints), (1, 3));
    }

    #[test]
    fn the_run_of_lost_cycles_resets_when_a_cycle_gets_through() {
        let mut s = CycleSender::new(2);
        let mut clock = FakeClock {
            now_ns: 0,
            pauses: 0,
        };
        let mut full = full_queue(|_, _| true);
        let mut ok = full_queue(|_, _| false);
        for _ in 0..2 {
            s.send(&mut full, &frames(), 0x80, 0, 1, &mut clock);
        }
        assert!(!s.run_too_long());
        s.send(&mut ok, &frames(), 0x80, 0, 3, &mut clock);
        s.send(&mut full, &frames(), 0x80, 0, 4, &mut clock);
        assert!(!s.run_too_long());
        assert_eq!((s.loss().cycles, s.loss().longest_run), (3, 2));
        s.send(&mut full, &frames(), 0x80, 0, 5, &mut clock);
        s.send(&mut full, &frames(), 0x80, 0, 6, &mut clock);
        assert!(s.run_too_long());
    }

    #[test]
    fn the_tolerated_run_follows_the_following_error_window() {
        let m = Machine::demo();
        assert_eq!(m.cycle_us, 4000);
        assert_eq!(tolerated_lost_cycles(&m), 2);
    }

    /// A master, its bus side, and a port that fills up on demand: the whole path of a lost
    /// cycle, without a bus.
    #[test]
    fn consecutive_lost_cycles_beyond_the_tolerance_stop_the_run_with_the_count() {
        let m = Machine::demo();
        let mut master = CyclicMaster::new(&m);
        let mut port = full_queue(|_, _| true);
        let mut bus = CyclicBus::new(&m, "vcan0", &mut port, None).unwrap();
        let mut out = Vec::new();
        for cycle in 1..=3 {
            out.clear();
            master.cycle(0x80, &mut out);
            bus.send(&mut port, &out, crate::rt::now_ns(), &mut master, cycle);
            if cycle < 3 {
                assert_eq!(master.failure(), None, "cycle {cycle}");
            }
        }
        let f = master.failure().expect("a fault after 3 lost cycles");
        assert!(
            matches!(
                &f.alarm,
                Alarm::TxQueueFull {
                    iface,
                    run: 3,
                    tolerated_run: 2,
                    lost_cycles: 3
                } if &**iface == "vcan0"
            ),
            "{f}"
        );
        let r = bus.report();
        assert_eq!((r.tx_loss.cycles, r.tx_loss.syncs), (3, 3));
        assert!(!r.bus_lost);
    }

    /// Bus-off through the receive path: the run ends in the same cycle, nothing more is sent.
    #[test]
    fn a_bus_off_error_frame_ends_the_run_at_once_and_says_how_the_drives_stop() {
        let m = Machine::demo();
        let bus_ = crate::bus::inproc::InProcBus::new();
        let mut port = bus_.port(&[]);
        let mut controller = bus_.port(&[]);
        let mut master = CyclicMaster::new(&m);
        let mut sup = Supervision::new(&m);
        let mut bus = CyclicBus::new(&m, "can0", &mut port, None).unwrap();
        controller
            .send_error(&ErrorFrame::error_passive(130, 2))
            .unwrap();
        bus.receive(&mut port, &mut master, &mut sup, Duration::ZERO, 1)
            .unwrap();
        assert_eq!(master.failure(), None, "error-passive is a warning");
        controller.send_error(&ErrorFrame::bus_off()).unwrap();
        bus.receive(&mut port, &mut master, &mut sup, Duration::ZERO, 2)
            .unwrap();
        assert!(bus.lost());
        assert_eq!(master.phase(), Phase::Done);
        let f = master.failure().unwrap();
        assert!(
            matches!(
                &f.alarm,
                Alarm::BusLost {
                    cause: BusLoss::BusOff { iface, frame: None },
                    cycle: 2,
                    completed_line: None,
                    ..
                } if &**iface == "can0"
            ),
            "{f}"
        );
        // The message says how the drives stop.
        assert!(
            f.to_string()
                .starts_with("CAN interface 'can0': controller bus-off, detected in cycle 2, ")
                && f.to_string().contains("heartbeat consumer (0x1016)"),
            "{f}"
        );
        let mut out = Vec::new();
        master.cycle(0x80, &mut out);
        assert!(out.is_empty(), "frames after bus-off: {out:?}");
        let r = bus.report();
        assert!(r.bus_lost);
        assert_eq!(r.warnings.len(), 1);
        assert_eq!(
            r.warnings[0].to_string(),
            "CAN error frame: controller: RX error-passive, TX error-passive; error counters TX 130, RX 2 ×1 (cycles 1–1)"
        );
    }
}
