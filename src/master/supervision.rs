//! Supervision of the drives during the run, sans-I/O: the gateway's heartbeat consumer, EMCYs
//! told apart into faults and warnings by the statusword, beside the [`CyclicMaster`].
//!
//! It takes the frames the cyclic side receives ([`Supervision::on_frame`] with the time they
//! were read: heartbeats, boot-ups, EMCYs) and, once per cycle before [`CyclicMaster::cycle`],
//! [`Supervision::poll`] raises on the master what it found. It never reads a clock: the same
//! code runs on the real-time thread (with CLOCK_MONOTONIC) and on the virtual clock of the
//! tests, where a detection falls in an exact cycle.
//!
//! - **Heartbeat consumer** (CiA 301 §7.2.8.3.2.3): once a node's heartbeat has been seen, a
//!   silence longer than the machine's `gateway_consumer_ms` raises
//!   [`Alarm::HeartbeatLost`] in the first poll that sees it.
//! - **EMCY** (CiA 301 §7.2.7): the statusword decides what an EMCY was (CiA 402): with the fault
//!   bit (3) a fault, [`Alarm::Emcy`], which stops the group; without it a warning (bit 7, or a
//!   communication warning), counted in [`Supervision::warnings`] and the run goes on. The EMCY
//!   can arrive before the TPDO that carries the fault bit: one seen without it waits for a TPDO
//!   received in a later cycle. An EMCY from a drive in a fault already reported (its TPDO
//!   before it showed the fault bit, an alarm named it) did not fault it: it is counted as a
//!   warning (no new alarm, e.g. after a reset while the drive's fault reset is on its way).
//! - **Boot-up during the run**: the master freezes the node in its own
//!   [`CyclicMaster::on_frame`] (at once, in the cycle that reads it); here a boot-up counts as
//!   the node's heartbeat (it is one, state 0).
//! - **Missing process data** is the master's own check (it owns the TPDO bookkeeping).
//!
//! Nothing here allocates after [`Supervision::new`]: fixed arrays by [`MAX_AXES`], and a
//! warning list sized for [`WARNING_KINDS`] kinds (a further kind grows it once).

use std::time::Duration;

use super::alarm::{Alarm, axis_letter};
use super::cyclic::CyclicMaster;
use crate::bus::Frame;
use crate::canopen::{Emcy, NmtState, cob};
use crate::cia402::statusword as swb;
use crate::config::Machine;
use crate::config::machine::MAX_AXES;

/// How many occurrences of a warning keep their cycle.
pub const WARNING_CYCLES: usize = 8;

/// How many EMCYs can wait for their statusword at once. One waits a cycle or two; a drive that
/// floods EMCYs faster than TPDOs overflows it, and the overflow is only counted
/// ([`Supervision::lost_emcys`]): should one of them be a fault, the statusword's fault bit still
/// stops the run ([`Alarm::DriveFault`]).
pub const PENDING_EMCYS: usize = 4 * MAX_AXES;

/// How many kinds of warning (node, code) the summary holds without growing its list.
pub const WARNING_KINDS: usize = 4 * MAX_AXES;

/// An EMCY after which the drive kept running (its statusword without the fault bit 3: a warning,
/// bit 7, or a communication warning), counted.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Warning {
    /// Axis letter.
    pub axis: &'static str,
    /// Node.
    pub node: u8,
    /// EMCY code.
    pub code: u16,
    /// How many times.
    pub count: u32,
    /// Cycle of the first.
    pub first_cycle: u64,
    /// Cycle of the last.
    pub last_cycle: u64,
    /// The cycles of the first [`WARNING_CYCLES`] (the rest are only counted), to tie them to a
    /// late wake-up of the cyclic thread.
    pub cycles: [u64; WARNING_CYCLES],
}

/// An EMCY waiting for the statusword that says what it was.
#[derive(Debug, Clone, Copy)]
struct PendingEmcy {
    /// Axis, machine order.
    axis: usize,
    code: u16,
    /// The master's cycle number when a poll first saw it (`None` until then).
    seen_cycle: Option<u64>,
    /// The drive was in a fault already reported when the EMCY came (its last TPDO showed the
    /// fault bit, and an alarm named it): the EMCY is not what faulted it (a drive in fault
    /// reports, say, a SYNC it missed meanwhile). Such an EMCY is counted as a warning and
    /// raises no new alarm, also not once the alarm is reset while the drive's fault reset is
    /// still on its way. A fault not reported yet (its EMCY later than the TPDO) still raises
    /// one.
    faulted_before: bool,
}

/// The supervision of one run's drives (see the module documentation).
#[derive(Debug)]
pub struct Supervision {
    n: usize,
    nodes: [u8; MAX_AXES],
    letters: [&'static str; MAX_AXES],
    consumer: Duration,
    last_heartbeat: [Option<Duration>; MAX_AXES],
    pending: [Option<PendingEmcy>; PENDING_EMCYS],
    pending_len: usize,
    lost_emcys: u64,
    warnings: Vec<Warning>,
    /// Per axis: the drive is in fault (its last TPDO shows the bit) and that fault is
    /// reported: an alarm names its node, or an EMCY of it raised one.
    fault_reported: [bool; MAX_AXES],
}

impl Supervision {
    /// The supervision of `machine`'s axes, with its `[heartbeat] gateway_consumer_ms`.
    pub fn new(machine: &Machine) -> Supervision {
        let mut nodes = [0; MAX_AXES];
        let mut letters = [""; MAX_AXES];
        for (i, a) in machine.axes.iter().take(MAX_AXES).enumerate() {
            nodes[i] = a.node;
            letters[i] = axis_letter(&a.name);
        }
        Supervision {
            n: machine.axes.len().min(MAX_AXES),
            nodes,
            letters,
            consumer: Duration::from_millis(u64::from(machine.heartbeat.gateway_consumer_ms)),
            last_heartbeat: [None; MAX_AXES],
            pending: [None; PENDING_EMCYS],
            pending_len: 0,
            lost_emcys: 0,
            warnings: Vec::with_capacity(WARNING_KINDS),
            fault_reported: [false; MAX_AXES],
        }
    }

    fn axis(&self, node: u8) -> Option<usize> {
        self.nodes[..self.n].iter().position(|&n| n == node)
    }

    /// A frame received at `now`: a heartbeat (or boot-up) or an EMCY of one of the axes'
    /// nodes; anything else is ignored. `master` is as it was before the frame (its feedback
    /// tells whether the drive was in fault already).
    pub fn on_frame(&mut self, now: Duration, f: &Frame, master: &CyclicMaster) {
        if f.is_remote() {
            return;
        }
        let id = f.id();
        if let Some(node) = id.checked_sub(cob::HEARTBEAT)
            && let Ok(node) = u8::try_from(node)
            && let Some(i) = self.axis(node)
        {
            if let [state] = f.data()
                && NmtState::from_byte(*state).is_some()
            {
                self.last_heartbeat[i] = Some(now);
            }
            return;
        }
        if let Some(e) = Emcy::from_frame(f)
            && e.code != 0
            && let Some(i) = self.axis(e.node)
        {
            let faulted = self.fault_reported[i]
                && master
                    .feedback(i)
                    .is_some_and(|fb| fb.statusword & swb::FAULT != 0);
            self.emcy(i, e.code, faulted);
        }
    }

    /// The last heartbeat of `node` was at `at` (one seen before the run, by start-up).
    pub fn seed_heartbeat(&mut self, node: u8, at: Duration) {
        if let Some(i) = self.axis(node) {
            let last = &mut self.last_heartbeat[i];
            *last = Some(last.map_or(at, |l| l.max(at)));
        }
    }

    /// An EMCY `code` of `node` seen before the run (by start-up): decided like one received now.
    pub fn seed_emcy(&mut self, node: u8, code: u16) {
        if code != 0
            && let Some(i) = self.axis(node)
        {
            self.emcy(i, code, false);
        }
    }

    fn emcy(&mut self, axis: usize, code: u16, faulted_before: bool) {
        match self.pending.get_mut(self.pending_len) {
            Some(slot) => {
                *slot = Some(PendingEmcy {
                    axis,
                    code,
                    seen_cycle: None,
                    faulted_before,
                });
                self.pending_len += 1;
            }
            None => self.lost_emcys += 1,
        }
    }

    /// Once per cycle at `now`, before [`CyclicMaster::cycle`]: raise on `master` a lost
    /// heartbeat and every fault EMCY, and count the warnings.
    pub fn poll(&mut self, now: Duration, master: &mut CyclicMaster) {
        let named = master.failure().and_then(|f| f.alarm.node());
        for i in 0..self.n {
            let in_fault = master
                .feedback(i)
                .is_some_and(|fb| fb.statusword & swb::FAULT != 0);
            self.fault_reported[i] =
                in_fault && (self.fault_reported[i] || named == Some(self.nodes[i]));
        }
        for i in 0..self.n {
            if let Some(at) = self.last_heartbeat[i] {
                let silent = now.saturating_sub(at);
                if silent > self.consumer {
                    master.alarm(
                        self.nodes[i],
                        Alarm::HeartbeatLost {
                            axis: self.letters[i],
                            node: self.nodes[i],
                            silent_ms: silent.as_millis() as u64,
                            consumer_ms: self.consumer.as_millis() as u64,
                        },
                    );
                }
            }
        }
        // The cycle about to run: the number the cyclic thread's timing gives it (its late
        // wake-ups name the same numbers).
        let cycle = master.cycle_number() + 1;
        let mut kept = 0;
        for k in 0..self.pending_len {
            let Some(mut p) = self.pending[k] else {
                continue;
            };
            let seen = *p.seen_cycle.get_or_insert(master.cycle_number());
            let keep = match master.feedback(p.axis) {
                None => true,
                Some(fb) if fb.statusword & swb::FAULT != 0 && !p.faulted_before => {
                    self.fault_reported[p.axis] = true;
                    master.alarm(
                        self.nodes[p.axis],
                        Alarm::Emcy {
                            axis: self.letters[p.axis],
                            node: self.nodes[p.axis],
                            code: p.code,
                        },
                    );
                    false
                }
                // No TPDO since the EMCY yet.
                Some(fb) if fb.cycle <= seen => true,
                Some(_) => {
                    self.count_warning(p.axis, p.code, cycle);
                    false
                }
            };
            if keep {
                self.pending[kept] = Some(p);
                kept += 1;
            }
        }
        for slot in &mut self.pending[kept..self.pending_len] {
            *slot = None;
        }
        self.pending_len = kept;
    }

    fn count_warning(&mut self, axis: usize, code: u16, cycle: u64) {
        let node = self.nodes[axis];
        match self
            .warnings
            .iter_mut()
            .find(|w| w.node == node && w.code == code)
        {
            Some(w) => {
                if let Some(c) = w.cycles.get_mut(w.count as usize) {
                    *c = cycle;
                }
                w.count += 1;
                w.last_cycle = cycle;
            }
            None => self.warnings.push(Warning {
                axis: self.letters[axis],
                node,
                code,
                count: 1,
                first_cycle: cycle,
                last_cycle: cycle,
                cycles: {
                    let mut c = [0; WARNING_CYCLES];
                    c[0] = cycle;
                    c
                },
            }),
        }
    }

    /// The warnings counted so far, in the order of their first occurrence.
    pub fn warnings(&self) -> &[Warning] {
        &self.warnings
    }

    /// The warnings, for the run's summary.
    pub fn into_warnings(self) -> Vec<Warning> {
        self.warnings
    }

    /// EMCYs dropped because [`PENDING_EMCYS`] were already waiting.
    pub fn lost_emcys(&self) -> u64 {
        self.lost_emcys
    }

    /// The gateway's heartbeat consumer time.
    pub fn consumer(&self) -> Duration {
        self.consumer
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cia402::statusword as sw;

    const MS: Duration = Duration::from_millis(1);

    /// The demo machine's feedback TPDO of axis `i` (statusword, then position actual).
    fn tpdo(master: &CyclicMaster, i: usize, statusword: u16) -> Frame {
        let mut d = [0u8; 6];
        d[..2].copy_from_slice(&statusword.to_le_bytes());
        Frame::new(master.axes()[i].tpdo_cob, &d).unwrap()
    }

    fn emcy(node: u8, code: u16) -> Frame {
        let c = code.to_le_bytes();
        Frame::new(
            cob::EMCY + u16::from(node),
            &[c[0], c[1], 0x81, 0, 0, 0, 0, 0],
        )
        .unwrap()
    }

    fn cycle(master: &mut CyclicMaster) {
        let mut out = Vec::new();
        master.cycle(0x80, &mut out);
    }

    #[test]
    fn a_heartbeat_silence_longer_than_the_consumer_time_is_lost_in_that_poll() {
        let m = Machine::demo();
        let mut master = CyclicMaster::new(&m);
        let mut sup = Supervision::new(&m);
        let consumer = sup.consumer();
        let hb = Frame::new(cob::HEARTBEAT + 2, &[NmtState::Operational.byte()]).unwrap();
        sup.on_frame(10 * MS, &hb, &master);
        // Exactly the consumer time: still fine; one nanosecond more: lost.
        sup.poll(10 * MS + consumer, &mut master);
        assert_eq!(master.failure(), None);
        sup.poll(10 * MS + consumer + Duration::from_nanos(1), &mut master);
        let f = master.failure().expect("heartbeat lost");
        assert_eq!(
            f.alarm,
            Alarm::HeartbeatLost {
                axis: "Y",
                node: 2,
                silent_ms: consumer.as_millis() as u64,
                consumer_ms: consumer.as_millis() as u64,
            }
        );
    }

    #[test]
    fn a_node_never_heard_is_not_declared_lost() {
        let m = Machine::demo();
        let mut master = CyclicMaster::new(&m);
        let mut sup = Supervision::new(&m);
        sup.poll(Duration::from_secs(100), &mut master);
        assert_eq!(master.failure(), None);
    }

    #[test]
    fn an_emcy_before_the_tpdo_with_the_fault_bit_is_a_fault() {
        let m = Machine::demo();
        let mut master = CyclicMaster::new(&m);
        let mut sup = Supervision::new(&m);
        master.on_frame(&tpdo(&master, 0, 0x0237));
        cycle(&mut master);
        // The EMCY arrives first; the TPDO of the same cycle still shows no fault: it waits.
        sup.on_frame(MS, &emcy(1, 0x2310), &master);
        master.on_frame(&tpdo(&master, 0, 0x0237));
        sup.poll(MS, &mut master);
        assert_eq!(master.failure(), None);
        assert!(sup.warnings().is_empty());
        cycle(&mut master);
        master.on_frame(&tpdo(&master, 0, 0x0237 | sw::FAULT));
        sup.poll(2 * MS, &mut master);
        assert_eq!(
            master.failure().map(|f| &f.alarm),
            Some(&Alarm::Emcy {
                axis: "X",
                node: 1,
                code: 0x2310
            })
        );
        assert!(sup.warnings().is_empty());
    }

    #[test]
    fn an_emcy_from_a_drive_already_in_fault_raises_no_new_alarm_after_the_reset() {
        // `canmotion serve`: node 1 faults (its EMCY, then the fault bit): the alarm. While it
        // stands, the faulted drive reports a SYNC it missed (a late wake-up of the host); the
        // operator's reset comes before the drive's next TPDO, which still shows the fault (its
        // fault reset is on its way). The late EMCY is no new alarm: the drive was in fault
        // before it.
        let m = Machine::demo();
        let mut master = CyclicMaster::service(&m);
        let mut sup = Supervision::new(&m);
        master.on_frame(&tpdo(&master, 0, 0x0250));
        cycle(&mut master);
        sup.on_frame(MS, &emcy(1, 0x2310), &master);
        master.on_frame(&tpdo(&master, 0, 0x0218));
        sup.poll(MS, &mut master);
        let code = |master: &CyclicMaster| match master.failure().map(|f| &f.alarm) {
            Some(Alarm::Emcy { code, .. }) => Some(*code),
            _ => None,
        };
        assert_eq!(code(&master), Some(0x2310));
        cycle(&mut master);
        master.on_frame(&tpdo(&master, 0, 0x0218));
        sup.poll(2 * MS, &mut master);
        cycle(&mut master);
        sup.on_frame(3 * MS, &emcy(1, 0x8100), &master);
        master.reset_alarm().expect("reset");
        master.on_frame(&tpdo(&master, 0, 0x0218));
        sup.poll(3 * MS, &mut master);
        cycle(&mut master);
        master.on_frame(&tpdo(&master, 0, 0x0218));
        sup.poll(4 * MS, &mut master);
        assert_eq!(master.failure(), None);
        // Told to the run's summary as what the drive reported.
        let w = &sup.warnings()[0];
        assert_eq!((w.node, w.code, w.count), (1, 0x8100, 1));
        // A drive that faults anew after the reset (its TPDO without the fault bit before the
        // EMCY) is an alarm again.
        cycle(&mut master);
        master.on_frame(&tpdo(&master, 0, 0x0250));
        sup.poll(5 * MS, &mut master);
        cycle(&mut master);
        sup.on_frame(6 * MS, &emcy(1, 0x2310), &master);
        master.on_frame(&tpdo(&master, 0, 0x0218));
        sup.poll(6 * MS, &mut master);
        assert_eq!(code(&master), Some(0x2310));
    }

    #[test]
    fn the_late_emcy_of_a_fault_no_alarm_reported_is_an_alarm() {
        // A drive that faults while disabled, its EMCY later than the TPDO with the fault bit
        // (an EMCY inhibit time, say): nothing reported that fault yet, so its EMCY does.
        let m = Machine::demo();
        let mut master = CyclicMaster::service(&m);
        let mut sup = Supervision::new(&m);
        master.on_frame(&tpdo(&master, 0, 0x0218));
        sup.poll(MS, &mut master);
        cycle(&mut master);
        sup.on_frame(2 * MS, &emcy(1, 0x2310), &master);
        master.on_frame(&tpdo(&master, 0, 0x0218));
        sup.poll(2 * MS, &mut master);
        assert_eq!(
            master.failure().map(|f| &f.alarm),
            Some(&Alarm::Emcy {
                axis: "X",
                node: 1,
                code: 0x2310
            })
        );
    }

    #[test]
    fn an_emcy_without_the_fault_bit_in_a_later_tpdo_is_a_counted_warning() {
        let m = Machine::demo();
        let mut master = CyclicMaster::new(&m);
        let mut sup = Supervision::new(&m);
        for k in 1..=3u64 {
            sup.on_frame(MS, &emcy(3, 0x4210), &master);
            master.on_frame(&tpdo(&master, 2, 0x0237 | sw::WARNING));
            sup.poll(MS, &mut master);
            // Seen in this cycle; the TPDO read with it does not count as later.
            assert_eq!(
                sup.warnings().first().map(|w| w.count),
                Some(k as u32 - 1).filter(|&c| c > 0)
            );
            cycle(&mut master);
            master.on_frame(&tpdo(&master, 2, 0x0237 | sw::WARNING));
            sup.poll(MS, &mut master);
            cycle(&mut master);
        }
        assert_eq!(master.failure(), None);
        let w = &sup.warnings()[0];
        assert_eq!((w.axis, w.node, w.code, w.count), ("Z", 3, 0x4210, 3));
        // The cycle numbers are those of the cycles the warnings were counted for.
        assert_eq!((w.first_cycle, w.last_cycle), (2, 6));
        assert_eq!(w.cycles[..3], [2, 4, 6]);
    }
}
