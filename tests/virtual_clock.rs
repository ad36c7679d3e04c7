//! Fault, recovery, heartbeat, boot-up, bus-off, override and stop scenarios on a virtual clock
//! (tests/common/virtual_clock.rs): the sans-I/O master and simulated drives on an in-process
//! bus, no threads, no sleeps. Every detection is asserted in its exact cycle, derived from when
//! the drive sent what it sent and the rule the master applies:
//!
//! - a frame a drive sends at `t` is read by the first cycle at or after `t`;
//! - a TPDO answers the SYNC of cycle `k` and is read by cycle `k + 1`;
//! - cycle `k` runs at `k × period`.
//!
//! The real-time suites (tests/faults.rs, tests/recovery.rs, tests/bus_faults.rs, vcan0) keep what
//! only real time shows: the threads, the sockets, the tokio side, the command line.

mod common;
#[path = "common/virtual_clock.rs"]
mod virtual_clock;

use std::time::Duration;

use canmotion::canopen::cob;
use canmotion::cia402::statusword as swb;
use canmotion::config::Machine;
use canmotion::master::alarm::{Alarm, BusLoss, Signal};
use canmotion::master::cyclic::Phase;
use canmotion::sim::{Inject, SimDrive};
use common::{LONG, PROGRAM, PROGRAM_END_COUNTS, drive_dict, machine, ms};
use virtual_clock::Rig;

/// The demo machine's drives, with `inject` on the nodes named.
fn rig_with(m: Machine, inject: &[(u8, Inject)], program: &str) -> Rig {
    let dict = drive_dict(|t| t);
    let drives = m
        .axes
        .iter()
        .map(|a| {
            inject
                .iter()
                .filter(|(n, _)| *n == a.node)
                .fold(SimDrive::new(dict.clone(), a.node), |d, (_, i)| {
                    d.with_inject(*i)
                })
        })
        .collect();
    Rig::new(m, drives, program)
}

fn rig(inject: &[(u8, Inject)], program: &str) -> Rig {
    rig_with(machine(|t| t), inject, program)
}

/// Cycles enough for any of these runs (30 s of the demo's 4 ms).
const MAX_CYCLES: u64 = 7_500;

fn failure(r: &Rig) -> &Alarm {
    &r.master.failure().expect("a failure").alarm
}

/// The cycle whose time the failure was first seen in.
fn failed_cycle(r: &Rig) -> u64 {
    r.cycle_at_or_after(r.failed_at.expect("failed"))
}

/// The time of the last frame `base + node` sent by the drive.
fn last_sent(r: &Rig, base: u16, node: u8) -> Duration {
    r.sent_by(base, node).last().expect("sent").at
}

/// The first frame `base + node` with `data` the drive sent, and when.
fn first_sent(r: &Rig, base: u16, node: u8, data: &[u8]) -> Duration {
    r.sent_by(base, node)
        .find(|s| s.frame.data() == data)
        .expect("sent")
        .at
}

/// The stop after a failure: the frozen axes' setpoints stand still from the cycle that
/// detected it, and every other axis keeps within its velocity and acceleration limits (finite
/// differences of its setpoints, as in tests/common `limits_held`).
fn stop_checked(r: &Rig, frozen: &[usize]) {
    let k = failed_cycle(r);
    let p = r.machine.cycle_s();
    for (i, a) in r.machine.axes.iter().enumerate() {
        let cmd: Vec<f64> = r.records.iter().map(|rec| rec.cmd_mm[i]).collect();
        if frozen.contains(&i) {
            let from = (k as usize).saturating_sub(1);
            assert!(
                cmd[from..].windows(2).all(|w| w[0] == w[1]),
                "axis {} moved after it was frozen in cycle {k}",
                a.name
            );
            continue;
        }
        for w in cmd.windows(3) {
            let v = (w[2] - w[1]).abs() / p;
            let acc = (w[2] - 2.0 * w[1] + w[0]).abs() / (p * p);
            assert!(
                v <= a.max_vel_mm_s * (1.0 + 1e-6),
                "axis {}: {v} mm/s",
                a.name
            );
            assert!(
                acc <= a.max_acc_mm_s2 * (1.0 + 1e-6) + 1e-6,
                "axis {}: {acc} mm/s²",
                a.name
            );
        }
    }
}

#[test]
fn a_clean_run_ends_on_the_program_end_with_no_alarm() {
    let mut r = rig(&[], PROGRAM);
    r.run_to_end(MAX_CYCLES);
    assert_eq!(r.master.failure(), None);
    assert!(r.sup.warnings().is_empty());
    for (i, want) in PROGRAM_END_COUNTS.iter().enumerate() {
        assert!(
            (r.master.final_counts()[i] - want).abs() <= 1,
            "{:?}",
            r.master.final_counts()
        );
    }
}

#[test]
fn heartbeat_loss_is_detected_in_the_first_cycle_past_the_consumer_time() {
    let mut r = rig(&[(2, Inject::NoHeartbeat { after: ms(300) })], LONG);
    r.run_to_end(MAX_CYCLES);
    // The last heartbeat is read by the first cycle at or after it; the loss by the first cycle
    // whose silence since that one exceeds the consumer time (500 ms = 125 cycles: cycle +126).
    let read = r.cycle_at_or_after(last_sent(&r, cob::HEARTBEAT, 2));
    let consumer = r.sup.consumer();
    let k = read + (consumer.as_nanos() / r.period.as_nanos()) as u64 + 1;
    assert_eq!(failed_cycle(&r), k);
    assert_eq!(
        *failure(&r),
        Alarm::HeartbeatLost {
            axis: "Y",
            node: 2,
            silent_ms: (r.cycle_time(k) - r.cycle_time(read)).as_millis() as u64,
            consumer_ms: 500,
        }
    );
    // Raised by the supervision before the cycle ran: the master counts it in the cycle before.
    assert_eq!(r.master.failure_cycle, Some(k - 1));
    assert!(r.master.fault_stop());
    // Its process data kept coming to the end: only the heartbeat told.
    let tpdo = r.machine.axes[1].feedback_pdo.cob_id;
    let last_hb = last_sent(&r, cob::HEARTBEAT, 2);
    let after = r
        .drive_frames
        .iter()
        .filter(|s| s.frame.id() == tpdo && s.at > last_hb)
        .count() as u64;
    assert!(after >= k - read, "{after} TPDOs after the last heartbeat");
    stop_checked(&r, &[1]);
}

#[test]
fn a_boot_up_during_the_run_freezes_its_node_in_the_cycle_that_reads_it() {
    let mut r = rig(&[(1, Inject::Reboot { after: ms(300) })], LONG);
    r.run_to_end(MAX_CYCLES);
    let boot = first_sent(&r, cob::HEARTBEAT, 1, &[0x00]);
    let k = r.cycle_at_or_after(boot);
    assert_eq!(failed_cycle(&r), k);
    assert!(
        matches!(
            failure(&r),
            Alarm::BootUp {
                axis: "X",
                node: 1,
                ..
            }
        ),
        "{:?}",
        failure(&r)
    );
    assert_eq!(r.master.reset_nodes(), [1]);
    // From that cycle on, node 1 gets no RPDO at all.
    let rpdo = r.machine.axes[0].setpoint_pdo.cob_id;
    assert!(
        !r.master_frames
            .iter()
            .any(|s| s.at >= r.cycle_time(k) && s.frame.id() == rpdo),
        "an RPDO to the reset node"
    );
    stop_checked(&r, &[0]);
}

#[test]
fn a_fault_emcy_is_decided_by_the_tpdo_after_it_one_cycle_later() {
    let mut r = rig(&[(3, Inject::PersistentFault { after: ms(300) })], LONG);
    r.run_to_end(MAX_CYCLES);
    let emcy = r.sent_by(cob::EMCY, 3).next().expect("an EMCY").at;
    // The EMCY is read in cycle k with a statusword from before the fault; the TPDO answering
    // cycle k's SYNC carries the fault bit and decides it in cycle k + 1.
    let k = r.cycle_at_or_after(emcy);
    assert_eq!(failed_cycle(&r), k + 1);
    assert_eq!(
        *failure(&r),
        Alarm::Emcy {
            axis: "Z",
            node: 3,
            code: 0x4310
        }
    );
    assert!(r.sup.warnings().is_empty());
    assert!(r.master.fault_stop());
    assert_eq!(r.master.frozen_nodes(), [3]);
    stop_checked(&r, &[2]);
}

#[test]
fn a_jammed_motor_is_stopped_in_the_cycle_after_the_tpdo_that_shows_it() {
    let mut r = rig(&[(2, Inject::FollowingError { after: ms(400) })], LONG);
    r.run_to_end(MAX_CYCLES);
    // The first TPDO of node 2 with the following-error bit (13) or the fault bit (3): it
    // answers the SYNC of cycle j and is read in cycle j + 1, which stops the group.
    let tpdo = r.machine.axes[1].feedback_pdo.cob_id;
    let first = r
        .drive_frames
        .iter()
        .find(|s| {
            s.frame.id() == tpdo
                && u16::from_le_bytes([s.frame.data()[0], s.frame.data()[1]])
                    & (swb::OP_MODE_SPECIFIC_13 | swb::FAULT)
                    != 0
        })
        .expect("the jam shows in a TPDO");
    let sw = u16::from_le_bytes([first.frame.data()[0], first.frame.data()[1]]);
    let j = r.cycle_at_or_after(first.at);
    assert_eq!(failed_cycle(&r), j + 1);
    match failure(&r) {
        Alarm::FollowingError {
            axis: "Y",
            node: 2,
            statusword,
        } => assert_eq!(*statusword, sw),
        Alarm::DriveFault {
            axis: "Y",
            node: 2,
            statusword,
        } => assert_eq!(*statusword, sw),
        // The drive faulted with its EMCY read by then: the supervision decides it before
        // the cycle's own check of the statusword.
        Alarm::Emcy {
            axis: "Y",
            node: 2,
            code: 0x8611,
        } => {
            assert_ne!(sw & swb::FAULT, 0);
            let emcy = r.sent_by(cob::EMCY, 2).next().expect("its EMCY").at;
            assert!(r.cycle_at_or_after(emcy) <= j + 1);
        }
        a => panic!("{a}"),
    }
    stop_checked(&r, &[1]);
}

#[test]
fn a_warning_emcy_is_counted_in_the_cycle_after_it_and_the_run_completes() {
    let mut r = rig(
        &[(
            1,
            Inject::Warning {
                code: 0x4210,
                after: ms(300),
            },
        )],
        LONG,
    );
    r.run_to_end(MAX_CYCLES);
    assert_eq!(r.master.failure(), None);
    let emcy = r.sent_by(cob::EMCY, 1).next().expect("an EMCY").at;
    let k = r.cycle_at_or_after(emcy);
    let w = r.sup.warnings();
    assert_eq!(w.len(), 1, "{w:?}");
    assert_eq!(
        (w[0].axis, w[0].node, w[0].code, w[0].count),
        ("X", 1, 0x4210, 1)
    );
    assert_eq!((w[0].first_cycle, w[0].last_cycle), (k + 1, k + 1));
    // The drive kept its warning bit and no fault bit.
    let sw = r.drives[0].statusword();
    assert_eq!(sw & (swb::WARNING | swb::FAULT), swb::WARNING);
}

#[test]
fn a_silent_drive_is_missing_process_data_51_cycles_after_its_last_tpdo() {
    let mut r = rig(&[(2, Inject::Silent { after: ms(300) })], LONG);
    r.run_to_end(MAX_CYCLES);
    let tpdo = r.machine.axes[1].feedback_pdo.cob_id;
    let last = r
        .drive_frames
        .iter()
        .rfind(|s| s.frame.id() == tpdo)
        .unwrap()
        .at;
    // The last TPDO answers the SYNC of cycle j and is read in cycle j + 1 (stamped j); the
    // master declares it stale once more than 50 cycles separate them: cycle j + 51. Its
    // heartbeat consumer (500 ms) would take longer.
    let j = r.cycle_at_or_after(last);
    assert_eq!(failed_cycle(&r), j + 51);
    assert_eq!(
        *failure(&r),
        Alarm::MissingProcessData {
            axis: "Y",
            node: 2,
            tpdo_cob: tpdo,
            silent_cycles: Some(51),
        }
    );
    stop_checked(&r, &[1]);
}

#[test]
fn bus_off_ends_the_run_in_the_cycle_that_reads_it_and_nothing_more_is_sent() {
    let mut r = rig(&[(1, Inject::BusOff { after: ms(300) })], LONG);
    r.run_to_end(MAX_CYCLES);
    let k = r.cycle_at_or_after(r.error_frames[0]);
    let f = failure(&r).clone();
    let Alarm::BusLost {
        cause: BusLoss::BusOff { iface, frame: None },
        cycle,
        ..
    } = &f
    else {
        panic!("{f}")
    };
    assert_eq!(&**iface, "vcan0");
    // Read by the receive of cycle k, which ends the run: that cycle sends nothing.
    assert_eq!((*cycle, failed_cycle(&r)), (k, k));
    assert_eq!(r.master.phase(), Phase::Done);
    assert!(
        !r.master_frames.iter().any(|s| s.at >= r.cycle_time(k)),
        "a frame sent after the bus-off"
    );
    // Every setpoint held where it was.
    assert!(r.master.fault_stop());
    assert_eq!(r.master.frozen_nodes(), [1, 2, 3]);
}

#[test]
fn a_stop_on_the_path_holds_then_disables_with_no_axis_frozen() {
    let mut r = rig(&[], LONG);
    r.run_until(MAX_CYCLES, |r| r.master.phase() == Phase::Streaming);
    for _ in 0..100 {
        r.step();
    }
    let at = r.next_cycle();
    r.master.stop_on_path(Alarm::Signal {
        signal: Some(Signal::Int),
    });
    r.run_to_end(MAX_CYCLES);
    assert_eq!(
        *failure(&r),
        Alarm::Signal {
            signal: Some(Signal::Int)
        }
    );
    assert!(!r.master.fault_stop());
    assert!(r.master.frozen_nodes().is_empty());
    // Stopped on the path: the last streamed point is the plan's point, short of the end.
    let m = r.master.motion().unwrap();
    assert!(m.is_standing_still() && m.reached_plan_time_s() < m.duration_s());
    assert!(r.master.failure_cycle.unwrap() > at);
}

#[test]
fn a_second_stop_signal_escalates_to_the_fault_stop_in_that_cycle() {
    let mut r = rig(&[], LONG);
    r.run_until(MAX_CYCLES, |r| r.master.phase() == Phase::Streaming);
    for _ in 0..100 {
        r.step();
    }
    r.master.stop_on_path(Alarm::Signal {
        signal: Some(Signal::Int),
    });
    for _ in 0..5 {
        r.step();
    }
    let at = r.master.cycle_number();
    r.master.alarm(
        0,
        Alarm::SignalEscalated {
            first: Some(Signal::Int),
            latest: Some(Signal::Term),
        },
    );
    r.run_to_end(MAX_CYCLES);
    // The first alarm stays the run's; the escalation turned it into the fault stop at once.
    assert_eq!(r.master.failure_cycle, Some(at));
    assert!(r.master.fault_stop());
}

#[test]
fn half_override_mid_run_keeps_the_limits_and_ends_on_the_program_end() {
    let mut full = rig(&[], LONG);
    full.run_to_end(MAX_CYCLES);
    let mut r = rig(&[], LONG);
    r.run_until(MAX_CYCLES, |r| r.master.phase() == Phase::Streaming);
    for _ in 0..50 {
        r.step();
    }
    r.master.set_override(0.5, false);
    r.step();
    assert_eq!(r.master.motion().unwrap().requested_override(), 0.5);
    r.run_to_end(MAX_CYCLES);
    assert_eq!(r.master.failure(), None);
    assert_eq!(r.master.final_counts(), full.master.final_counts());
    assert!(r.master.streaming_cycles > full.master.streaming_cycles);
    // Every setpoint step within max velocity × period.
    for (i, a) in r.machine.axes.iter().enumerate() {
        let vmax = a.max_vel_mm_s * r.machine.cycle_s() * (1.0 + 1e-9);
        for w in r.records.windows(2) {
            let step = (w[1].cmd_mm[i] - w[0].cmd_mm[i]).abs();
            assert!(step <= vmax, "axis {}: step {step} mm", a.name);
        }
    }
}
