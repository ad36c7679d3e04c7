//! The start-up and orderly-end state machine ([`canmotion::master::startup::Sequence`]) against
//! simulated drives on a virtual bus and clock (`common/virtual_bus.rs`): no threads, no
//! sleeps, time-outs checked at their exact virtual instant.

mod common;
#[path = "common/virtual_bus.rs"]
mod virtual_bus;

use std::time::Duration;

use canmotion::bus::Frame;
use canmotion::canopen::sdo_client::SdoError;
use canmotion::canopen::{AbortCode, NmtState, index, value_bytes};
use canmotion::config::Machine;
use canmotion::master::startup::{
    AxisNode, BOOT_TIMEOUT, HEARTBEAT_CONSUMER_SUB, SDO_TIMEOUT, Sequence, StartupError, Step,
};
use canmotion::sim::SimDrive;
use canopen_rs::Value;
use common::{drive_dict, machine};
use virtual_bus::VirtualBus;

/// What the caller of the sequence does at [`Step::CheckPositions`].
#[derive(Clone, Copy, PartialEq)]
enum Verdict {
    Proceed,
    Refuse,
}

/// Runs `seq` on `bus` to its end, as `gateway::startup` drives it on a real bus; the
/// gateway's heartbeat (once asked for) runs while it does and is returned, to keep it going.
fn run(
    bus: &mut VirtualBus,
    seq: &mut Sequence<'_>,
    verdict: Verdict,
) -> (Result<(), StartupError>, Option<(Frame, Duration)>) {
    let mut heartbeat: Option<(Frame, Duration)> = None;
    let mut next_beat = Duration::MAX;
    let mut out = Vec::new();
    let mut step = seq.poll(bus.now, &mut out);
    loop {
        bus.send(&mut out);
        step = match step {
            Step::Done(r) => return (r, heartbeat),
            Step::StartHeartbeat { node, period } => {
                heartbeat = Some((
                    Frame::new(0x700 + u16::from(node), &[0x05]).unwrap(),
                    period,
                ));
                next_beat = bus.now;
                seq.poll(bus.now, &mut out)
            }
            Step::CheckPositions if verdict == Verdict::Proceed => seq.proceed(bus.now, &mut out),
            Step::CheckPositions => {
                seq.refuse(&mut out);
                seq.poll(bus.now, &mut out)
            }
            Step::Pending { poll_at } => {
                if let Some((f, period)) = heartbeat
                    && bus.now >= next_beat
                {
                    bus.send(&mut vec![f]);
                    next_beat += period;
                }
                match bus.recv() {
                    Some(f) => seq.on_frame(bus.now, &f, &mut out),
                    None => {
                        bus.advance(poll_at.min(next_beat));
                        if bus.now >= poll_at {
                            let step = seq.poll(bus.now, &mut out);
                            // A machine polled at its time goes on or names a later one.
                            if let Step::Pending { poll_at } = step {
                                assert!(
                                    poll_at > bus.now,
                                    "polled at {:?}, due again at {poll_at:?}",
                                    bus.now
                                );
                            }
                            step
                        } else {
                            Step::Pending { poll_at }
                        }
                    }
                }
            }
        };
    }
}

/// The drives of the demo machine (X, Y, Z on nodes 1, 2, 3), at `counts`.
fn drives(m: &Machine, counts: [i32; 3]) -> Vec<SimDrive> {
    m.axes
        .iter()
        .zip(counts)
        .map(|(a, c)| SimDrive::new(a.dictionary.clone(), a.node).with_position(c))
        .collect()
}

/// The SDO downloads the master sent to `node` (expedited: every object start-up writes fits in
/// 4 bytes), as (index, sub, bytes), in order.
fn downloads(bus: &VirtualBus, node: u8) -> Vec<(u16, u8, Vec<u8>)> {
    bus.log
        .iter()
        .filter(|(_, f)| f.id() == 0x600 + u16::from(node) && f.data()[0] & 0xE0 == 0x20)
        .map(|(_, f)| {
            let d = f.data();
            assert_eq!(d[0] & 0x03, 0x03, "expedited, size indicated: {f}");
            let len = 4 - usize::from((d[0] >> 2) & 3);
            (
                u16::from_le_bytes([d[1], d[2]]),
                d[3],
                d[4..4 + len].to_vec(),
            )
        })
        .collect()
}

/// NMT frames the master sent, as (command, node).
fn nmt(bus: &VirtualBus) -> Vec<(u8, u8)> {
    bus.log
        .iter()
        .filter(|(_, f)| f.id() == 0)
        .map(|(_, f)| (f.data()[0], f.data()[1]))
        .collect()
}

fn w(index: u16, sub: u8, v: Value) -> (u16, u8, Vec<u8>) {
    (index, sub, value_bytes(&v))
}

#[test]
fn a_clean_start_writes_the_objects_in_order_remaps_and_returns_positions() {
    let m = machine(|t| t);
    let mut bus = VirtualBus::new(drives(&m, [1234, -2000, -40000]));
    let mut seq = Sequence::start_up(&m);
    let (r, heartbeat) = run(&mut bus, &mut seq, Verdict::Proceed);
    assert_eq!(r, Ok(()));
    assert_eq!(seq.positions(), [1234, -2000, -40000]);
    assert_eq!(
        heartbeat.map(|(f, p)| (f.id(), p)),
        Some((0x77F, Duration::from_millis(100)))
    );
    // NMT: reset communication of every node first, start of every node last.
    assert_eq!(
        nmt(&bus),
        [
            (0x82, 1),
            (0x82, 2),
            (0x82, 3),
            (0x01, 1),
            (0x01, 2),
            (0x01, 3)
        ]
    );
    let first_nmt_start = bus
        .log
        .iter()
        .position(|(_, f)| f.id() == 0 && f.data()[0] == 0x01)
        .unwrap();
    assert!(
        bus.log[first_nmt_start..]
            .iter()
            .all(|(_, f)| !(0x601..=0x67F).contains(&f.id())),
        "no SDO after NMT start"
    );
    // Exactly what today's start-up writes to X (node 1, 1000 counts/mm, travel [-5, 300] mm,
    // 200 mm/s), in this order.
    use Value::*;
    let x = vec![
        w(0x1017, 0, Unsigned16(100)),
        w(0x1016, 1, Unsigned32(0x007F_01F4)),
        w(0x605A, 0, Integer16(2)),
        w(0x6085, 0, Unsigned32(20_000_000)),
        w(0x6065, 0, Unsigned32(2000)),
        w(0x6066, 0, Unsigned16(10)),
        w(0x607D, 1, Integer32(-5000)),
        w(0x607D, 2, Integer32(300_000)),
        w(0x607F, 0, Unsigned32(300_000)),
        // RPDO2 and TPDO2 are valid in the dictionary: switched off; 3 and 4 already are.
        w(0x1401, 1, Unsigned32(0x8000_0301)),
        w(0x1801, 1, Unsigned32(0x8000_0281)),
        // RPDO1 remap, CiA 301 §7.5.2.35–36.
        w(0x1400, 1, Unsigned32(0x8000_0201)),
        w(0x1600, 0, Unsigned8(0)),
        w(0x1600, 1, Unsigned32(0x6040_0010)),
        w(0x1600, 2, Unsigned32(0x60C1_0120)),
        w(0x1600, 0, Unsigned8(2)),
        w(0x1400, 2, Unsigned8(1)),
        w(0x1400, 1, Unsigned32(0x201)),
        // TPDO1.
        w(0x1800, 1, Unsigned32(0x8000_0181)),
        w(0x1A00, 0, Unsigned8(0)),
        w(0x1A00, 1, Unsigned32(0x6041_0010)),
        w(0x1A00, 2, Unsigned32(0x6064_0020)),
        w(0x1A00, 0, Unsigned8(2)),
        w(0x1800, 2, Unsigned8(1)),
        w(0x1800, 1, Unsigned32(0x181)),
        // SYNC, IP period (4 ms = 4 × 10^-3 s), mode 7.
        w(0x1005, 0, Unsigned32(0x80)),
        w(0x1006, 0, Unsigned32(4000)),
        w(0x1007, 0, Unsigned32(2000)),
        w(0x60C0, 0, Integer16(0)),
        w(0x60C2, 1, Unsigned8(4)),
        w(0x60C2, 2, Integer8(-3)),
        w(0x6060, 0, Integer8(7)),
    ];
    assert_eq!(downloads(&bus, 1), x);
    // Z (node 3): 2000 counts/mm, travel [-100, 5] mm, 100 mm/s, no machine-file writes.
    let z = downloads(&bus, 3);
    assert_eq!(
        z[..7],
        [
            w(0x1017, 0, Unsigned16(100)),
            w(0x1016, 1, Unsigned32(0x007F_01F4)),
            w(0x6065, 0, Unsigned32(2000)),
            w(0x6066, 0, Unsigned16(10)),
            w(0x607D, 1, Integer32(-200_000)),
            w(0x607D, 2, Integer32(10_000)),
            w(0x607F, 0, Unsigned32(300_000)),
        ]
    );
    assert_eq!(z.len(), x.len() - 2);
    // The axes are configured one after another.
    let first_sdo = |node: u16| {
        bus.log
            .iter()
            .position(|(_, f)| f.id() == 0x600 + node && f.data()[0] & 0xE0 == 0x20)
            .unwrap()
    };
    let last_sdo = |node: u16| {
        bus.log
            .iter()
            .rposition(|(_, f)| f.id() == 0x600 + node)
            .unwrap()
    };
    assert!(last_sdo(1) < first_sdo(2) && last_sdo(2) < first_sdo(3));
    // The drives: Operational, remapped, mode 7 displayed.
    for d in &bus.drives {
        let n = i64::from(d.node());
        assert_eq!(d.nmt_state(), NmtState::Operational);
        assert_eq!(d.od().int(index::RPDO_COMMUNICATION, 1), 0x200 + n);
        assert_eq!(d.od().int(index::RPDO_MAPPING, 2), 0x60C1_0120);
        assert_eq!(d.od().int(index::TPDO_MAPPING, 2), 0x6064_0020);
        assert_eq!(
            d.od().int(index::RPDO_COMMUNICATION + 1, 1),
            0x8000_0300 + n
        );
        assert_eq!(d.od().int(index::MODES_DISPLAY, 0), 7);
        assert_eq!(
            d.od()
                .int(index::CONSUMER_HEARTBEAT_TIME, HEARTBEAT_CONSUMER_SUB),
            0x007F_01F4
        );
    }
}

#[test]
fn a_node_that_never_boots_is_missing_at_the_boot_deadline_exactly() {
    let m = machine(|t| t);
    // No drive at node 3.
    let mut d = drives(&m, [0; 3]);
    d.pop();
    let mut bus = VirtualBus::new(d);
    let mut seq = Sequence::start_up(&m);
    let (r, heartbeat) = run(&mut bus, &mut seq, Verdict::Proceed);
    assert_eq!(
        r,
        Err(StartupError::MissingNodes {
            missing: vec![AxisNode {
                axis: "Z".into(),
                node: 3
            }],
            timeout: BOOT_TIMEOUT,
        })
    );
    // Reset communication went out at 0; the failure at the deadline, not a tick before or
    // after.
    assert_eq!(
        bus.log.iter().find(|(_, f)| f.id() == 0).unwrap().0,
        Duration::ZERO
    );
    assert_eq!(bus.now, BOOT_TIMEOUT);
    assert!(heartbeat.is_none());
    assert_eq!(nmt(&bus), [(0x82, 1), (0x82, 2), (0x82, 3)]);
    assert!(
        bus.log
            .iter()
            .all(|(_, f)| !(0x601..=0x67F).contains(&f.id()))
    );
    let msg = r.unwrap_err().to_string();
    assert!(
        msg.starts_with("no boot-up from axis Z (node 3) within 3000 ms"),
        "{msg}"
    );
}

#[test]
fn a_wrong_identity_is_refused_before_anything_is_written() {
    let m = machine(|t| t);
    let other = drive_dict(|t| t.replace("0x00010000", "0x00020000"));
    let mut d = drives(&m, [0; 3]);
    d[1] = SimDrive::new(other, 2);
    let mut bus = VirtualBus::new(d);
    let mut seq = Sequence::start_up(&m);
    let (r, _) = run(&mut bus, &mut seq, Verdict::Proceed);
    match r {
        Err(StartupError::WrongIdentity {
            axis,
            node: 2,
            object,
            expected: 0x0001_0000,
            found: 0x0002_0000,
            ..
        }) => assert_eq!((axis.as_str(), object), ("Y", "revision 0x1018:3")),
        other => panic!("{other:?}"),
    }
    assert!((1..=3).all(|n| downloads(&bus, n).is_empty()));
    assert_eq!(nmt(&bus), [(0x82, 1), (0x82, 2), (0x82, 3)]);
}

#[test]
fn a_nodes_abort_is_typed_with_node_object_and_code() {
    let m = machine(|t| t);
    // This drive's max profile velocity is read-only.
    let ro = drive_dict(|t| {
        t.replace(
            "name = \"Max profile velocity\"\ntype = \"u32\"\naccess = \"rw\"",
            "name = \"Max profile velocity\"\ntype = \"u32\"\naccess = \"ro\"",
        )
    });
    let mut d = drives(&m, [0; 3]);
    d[0] = SimDrive::new(ro, 1);
    let mut bus = VirtualBus::new(d);
    let mut seq = Sequence::start_up(&m);
    let (r, _) = run(&mut bus, &mut seq, Verdict::Proceed);
    assert_eq!(
        r,
        Err(StartupError::Sdo {
            node: 1,
            index: index::MAX_PROFILE_VELOCITY,
            sub: 0,
            error: SdoError::Aborted {
                code: AbortCode::READ_ONLY
            },
        })
    );
    // Nothing after the abort: no further write, no NMT start.
    assert_eq!(
        downloads(&bus, 1).last().unwrap().0,
        index::MAX_PROFILE_VELOCITY
    );
    assert!(downloads(&bus, 2).is_empty());
    assert_eq!(nmt(&bus).len(), 3);
}

#[test]
fn a_silent_sdo_server_is_our_time_out_not_the_nodes_abort() {
    let m = machine(|t| t);
    let mut bus = VirtualBus::new(drives(&m, [0; 3]));
    // Node 2 boots and beats, but its SDO answers never reach the bus.
    bus.lose(|f| f.id() == 0x582);
    let mut seq = Sequence::start_up(&m);
    let (r, _) = run(&mut bus, &mut seq, Verdict::Proceed);
    assert_eq!(
        r,
        Err(StartupError::Sdo {
            node: 2,
            index: index::DEVICE_TYPE,
            sub: 0,
            error: SdoError::TimedOut {
                timeout: SDO_TIMEOUT
            },
        })
    );
    // The request, then our abort (0x05040000) exactly one time-out later.
    let to_2: Vec<_> = bus.log.iter().filter(|(_, f)| f.id() == 0x602).collect();
    assert_eq!(to_2.len(), 2, "{to_2:?}");
    assert_eq!(to_2[0].1.data()[0], 0x40);
    assert_eq!(to_2[1].0 - to_2[0].0, SDO_TIMEOUT);
    assert_eq!(
        to_2[1].1.data(),
        [0x80, 0x00, 0x10, 0x00, 0x00, 0x00, 0x04, 0x05]
    );
    assert_eq!(bus.now, to_2[1].0);
    let msg = r.unwrap_err().to_string();
    assert!(!msg.contains("aborted by the node"), "{msg}");
}

#[test]
fn a_mode_never_displayed_is_refused_one_second_after_the_first_read() {
    let m = machine(|t| t);
    let mut bus = VirtualBus::new(drives(&m, [0; 3]));
    // Node 1's modes of operation display (0x6061) always answers 0, whatever 0x6060 holds.
    bus.tamper(|f| {
        let d = f.data();
        if f.id() == 0x581 && d[0] == 0x4F && d[1..4] == [0x61, 0x60, 0x00] {
            let mut d: [u8; 8] = d.try_into().unwrap();
            d[4] = 0;
            return Frame::new(f.id(), &d);
        }
        Some(f)
    });
    let mut seq = Sequence::start_up(&m);
    let (r, _) = run(&mut bus, &mut seq, Verdict::Proceed);
    assert_eq!(
        r,
        Err(StartupError::ModeNotConfirmed {
            axis: "X".into(),
            node: 1,
            mode: 7,
            found: 0,
        })
    );
    // Read every 10 ms from the first read; the answer to the read at +1000 ms is not yet
    // past the second, the one to the read at +1010 ms is, and ends it.
    let reads: Vec<Duration> = bus
        .log
        .iter()
        .filter(|(_, f)| f.id() == 0x601 && f.data()[..4] == [0x40, 0x61, 0x60, 0x00])
        .map(|(t, _)| *t)
        .collect();
    assert_eq!(reads.len(), 102);
    assert!(
        reads
            .windows(2)
            .all(|w| w[1] - w[0] == Duration::from_millis(10))
    );
    assert_eq!(bus.now - reads[0], Duration::from_millis(1010));
    assert!(downloads(&bus, 2).is_empty());
}

#[test]
fn an_axis_outside_its_travel_is_refused_and_the_drives_stay_pre_operational() {
    let m = machine(|t| t);
    // X at -10 mm, travel [-5, 300].
    let mut bus = VirtualBus::new(drives(&m, [-10_000, 0, 0]));
    let mut seq = Sequence::start_up(&m);
    let (r, _) = run(&mut bus, &mut seq, Verdict::Proceed);
    assert_eq!(
        r,
        Err(StartupError::OutsideTravel {
            axis: "X".into(),
            node: 1,
            position_mm: -10.0,
            min_mm: -5.0,
            max_mm: 300.0,
        })
    );
    assert_eq!(seq.positions(), [-10_000, 0, 0]);
    // Position actual was read from every axis, nothing written, Pre-operational sent.
    assert!((1..=3).all(|n| downloads(&bus, n).is_empty()));
    assert_eq!(
        nmt(&bus),
        [
            (0x82, 1),
            (0x82, 2),
            (0x82, 3),
            (0x80, 1),
            (0x80, 2),
            (0x80, 3)
        ]
    );
    for d in &bus.drives {
        assert_eq!(d.nmt_state(), NmtState::PreOperational);
        // The dictionary's own limits and consumer entry, untouched.
        assert_eq!(d.od().int(index::CONSUMER_HEARTBEAT_TIME, 1), 0);
        assert_eq!(d.od().int(index::MODES_OF_OPERATION, 0), 0);
    }
}

#[test]
fn the_callers_refusal_writes_nothing_and_leaves_the_drives_pre_operational() {
    let m = machine(|t| t);
    let mut bus = VirtualBus::new(drives(&m, [0; 3]));
    let mut seq = Sequence::start_up(&m);
    let (r, _) = run(&mut bus, &mut seq, Verdict::Refuse);
    assert_eq!(r, Err(StartupError::Refused));
    assert!((1..=3).all(|n| downloads(&bus, n).is_empty()));
    assert_eq!(&nmt(&bus)[3..], [(0x80, 1), (0x80, 2), (0x80, 3)]);
    assert!(
        bus.drives
            .iter()
            .all(|d| d.nmt_state() == NmtState::PreOperational)
    );
}

#[test]
fn the_orderly_end_switches_heartbeat_consumption_off_and_no_drive_complains() {
    let m = machine(|t| t);
    let mut bus = VirtualBus::new(drives(&m, [0; 3]));
    let mut start = Sequence::start_up(&m);
    let (r, heartbeat) = run(&mut bus, &mut start, Verdict::Proceed);
    assert_eq!(r, Ok(()));
    let heartbeat = heartbeat.expect("the gateway's heartbeat");
    // A while on the bus with the gateway beating, then the end of the motion: every drive to
    // Pre-operational (as the cyclic thread's end does).
    let t = bus.now + Duration::from_secs(1);
    bus.run_until(t, Some(heartbeat));
    bus.send(
        &mut (1..=3)
            .map(|n| Frame::new(0, &[0x80, n]).unwrap())
            .collect(),
    );
    let mut end = Sequence::orderly_end(&m);
    let (r, _) = run(&mut bus, &mut end, Verdict::Proceed);
    assert_eq!(r, Ok(()));
    // 0x1016:1 = 0 written and read back, on every node.
    for n in 1..=3u8 {
        let reads = bus
            .log
            .iter()
            .filter(|(_, f)| {
                f.id() == 0x600 + u16::from(n) && f.data()[..4] == [0x40, 0x16, 0x10, 0x01]
            })
            .count();
        assert!(
            reads >= 2,
            "node {n}: 0x1016:1 read back ({reads} reads in all)"
        );
        assert_eq!(
            downloads(&bus, n).last().unwrap(),
            &w(0x1016, 1, Value::Unsigned32(0))
        );
    }
    // The gateway's heartbeat stops: no EMCY from any drive in the next 2 s, and none is in
    // Fault or has left Pre-operational.
    let ended = bus.log.len();
    let t = bus.now + Duration::from_secs(2);
    bus.run_until(t, None);
    let emcys: Vec<_> = bus.log[ended..]
        .iter()
        .filter(|(_, f)| (0x081..=0x0FF).contains(&f.id()))
        .collect();
    assert!(emcys.is_empty(), "{emcys:?}");
    for d in &bus.drives {
        assert_eq!(d.od().int(index::CONSUMER_HEARTBEAT_TIME, 1), 0);
        assert_eq!(d.nmt_state(), NmtState::PreOperational);
    }
}

#[test]
fn without_the_orderly_end_every_drive_reports_the_lost_heartbeat() {
    // The control for the test above: the same run, the heartbeat stops with consumption still
    // on, and every drive sends EMCY 0x8130 some 500 ms later (what issue 13's defect 1 saw).
    let m = machine(|t| t);
    let mut bus = VirtualBus::new(drives(&m, [0; 3]));
    let mut start = Sequence::start_up(&m);
    let (r, heartbeat) = run(&mut bus, &mut start, Verdict::Proceed);
    assert_eq!(r, Ok(()));
    let t = bus.now + Duration::from_secs(1);
    bus.run_until(t, heartbeat);
    let ended = bus.log.len();
    let t = bus.now + Duration::from_secs(2);
    bus.run_until(t, None);
    let mut from: Vec<u16> = bus.log[ended..]
        .iter()
        .filter(|(_, f)| (0x081..=0x0FF).contains(&f.id()) && f.data()[..2] == [0x30, 0x81])
        .map(|(_, f)| f.id() - 0x80)
        .collect();
    from.dedup();
    assert_eq!(from, [1, 2, 3]);
}
