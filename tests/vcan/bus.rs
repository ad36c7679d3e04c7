//! Bus-level faults and SYNC timing on vcan0 (issue 5): error frames between sockets, bus-off
//! (injected by the simulated drive as the error frame a controller would report), the interface
//! going down (ENETDOWN), a transmit queue held full (ENOBUFS, with the `plug` qdisc), an
//! error-passive warning, and the SYNC period statistics from kernel receive timestamps.
//!
//! Each fault test asserts the detection time, the message, and that no setpoint jumped.

use std::time::{Duration, Instant};

use canmotion::bus::BusError;
use canmotion::bus::error::class;
use canmotion::bus::{Bus, ErrorFrame, Filter, Port, Received};
use canmotion::gateway::{self, GatewayError, MotionFailure, RunOptions, Summary};
use canmotion::master::alarm::{Alarm, BusLoss};

use super::{BIN, IFACE, UML_MARGIN_S, common, lock, run_square, simdrive, simdrive_with};

fn vcan0() -> Bus {
    Bus::SocketCan(IFACE.into())
}

/// A port on vcan0 that receives `ids` and no error frames.
fn watch(ids: &[u16]) -> Box<dyn Port> {
    let f: Vec<Filter> = ids.iter().map(|&i| Filter::exact(i)).collect();
    let mut p = vcan0().open(&f).unwrap();
    p.set_error_mask(0).unwrap();
    p
}

/// Two moves at half the axes' speed (a stall of User-Mode Linux costs half the following
/// error): line 2 (X to 10 mm, about 0.25 s) completes before line 3 (a diagonal, X and Y at
/// 50 mm/s for over a second) is under way.
const TWO_MOVES: &str = "G21 G90\nG1 X10 F3000\nG1 X70 Y60 Z-2 F4243\nM2\n";

/// One diagonal, X and Y at 50 mm/s for over a second.
const SLOW: &str = "G21 G90\nG1 X60 Y60 Z-2 F4243\nM2\n";

fn run_in_thread(
    program: &'static str,
) -> (
    std::thread::JoinHandle<Result<Summary, GatewayError>>,
    tempfile::TempDir,
) {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("log.csv");
    let h = std::thread::spawn(move || {
        gateway::run(
            &common::machine(|t| t),
            &vcan0(),
            &RunOptions {
                program_name: "bus.ngc".into(),
                program_text: program.into(),
                log: Some(log),
                simulate: false,
                ..Default::default()
            },
        )
    });
    (h, dir)
}

/// Receive the drives' TPDOs on `watch` until every drive follows setpoints (statusword bit 12)
/// and X has moved 1 mm (20 s at most). Returns when this socket first saw bit 12 on every drive
/// (the gateway sees it at its next cycle, at the earliest the same instant).
fn until_moving(watch: &mut dyn Port) -> Instant {
    let deadline = Instant::now() + Duration::from_secs(20);
    let mut moving = [false; 3];
    let mut bit12 = [false; 3];
    let mut all_bit12 = None;
    while !moving.iter().all(|m| *m) {
        assert!(Instant::now() < deadline, "the motion did not start");
        if let Some(f) = watch.recv_timeout(Duration::from_millis(100)).unwrap()
            && (0x181..=0x183).contains(&f.id())
            && f.data().len() == 6
        {
            let sw = u16::from_le_bytes([f.data()[0], f.data()[1]]);
            let pos = i32::from_le_bytes(f.data()[2..6].try_into().unwrap());
            let i = usize::from(f.id() - 0x181);
            bit12[i] |= sw & 0x1000 != 0;
            if bit12.iter().all(|b| *b) {
                all_bit12.get_or_insert_with(Instant::now);
            }
            moving[i] = sw & 0x1000 != 0 && (i == 2 || pos.abs() > 1000);
        }
    }
    all_bit12.expect("bit 12 before motion")
}

/// Every commanded setpoint step within max velocity × period on every axis, through the whole
/// run (the acceleration is not asserted across a bus loss: nothing can be sent, and the drive
/// holds the last setpoint it got).
fn steps_within_limits(o: &common::Outcome) {
    let t = o.machine.cycle_s();
    for (i, a) in o.machine.axes.iter().enumerate() {
        for w in o.rows.windows(2) {
            let step = (w[1][2 + i] - w[0][2 + i]).abs();
            assert!(
                step <= a.max_vel_mm_s * t * 1.01,
                "axis {} at cycle {}: setpoint step {step} mm",
                a.name,
                w[1][0]
            );
        }
    }
}

/// No axis's setpoint moves after the failure was detected.
fn all_held_after(o: &common::Outcome, f: &MotionFailure) {
    for axis in 0..o.machine.axes.len() {
        common::frozen_after(o, axis, f);
    }
}

fn outcome(result: Result<Summary, GatewayError>, dir: &tempfile::TempDir) -> common::Outcome {
    common::Outcome {
        result,
        rows: common::read_csv(&dir.path().join("log.csv")),
        machine: common::machine(|t| t),
    }
}

#[test]
fn vcan0_carries_error_frames_to_the_sockets_whose_mask_has_their_class() {
    let _g = lock();
    // What the kernel does with an error frame a socket sends is what it does with one a
    // controller's driver reports: every other socket with the class in its error mask gets it,
    // whatever its identifier filters.
    let mut controller = watch(&[0x7FF]);
    let mut all = vcan0().open(&[Filter::exact(0x7FF)]).unwrap();
    all.set_error_mask(class::ALL).unwrap();
    let mut none = watch(&[]);
    let mut default = vcan0().open(&[]).unwrap();
    controller
        .send_error(&ErrorFrame::error_passive(128, 96))
        .unwrap();
    controller.send_error(&ErrorFrame::bus_off()).unwrap();
    let second = Duration::from_secs(1);
    assert_eq!(
        all.recv_any(second).unwrap(),
        Some(Received::Error(ErrorFrame::error_passive(128, 96)))
    );
    assert_eq!(
        all.recv_any(second).unwrap(),
        Some(Received::Error(ErrorFrame::bus_off()))
    );
    // The default mask is bus-off only; recv_timeout reports it as an error.
    match default.recv_timeout(second) {
        Err(e) => assert_eq!(
            e.to_string(),
            "CAN interface 'vcan0': controller is bus-off"
        ),
        Ok(f) => panic!("expected the bus-off, got {f:?}"),
    }
    assert_eq!(none.recv_any(Duration::ZERO).unwrap(), None);
}

#[test]
fn vcan0_monitor_prints_error_frames_decoded() {
    let _g = lock();
    let mut mon = std::process::Command::new(BIN)
        .args(["monitor", "--bus", IFACE, "--count", "1"])
        .stdout(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let mut controller = watch(&[0x7FF]);
    let deadline = Instant::now() + Duration::from_secs(10);
    // The monitor prints nothing when it is ready: send until it has seen one.
    while mon.try_wait().unwrap().is_none() {
        assert!(Instant::now() < deadline, "monitor saw no error frame");
        controller.send_error(&ErrorFrame::bus_off()).unwrap();
        let _ = controller.recv_timeout(Duration::from_millis(20));
    }
    let out = mon.wait_with_output().unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.trim_end()
            .ends_with("vcan0 20000040#0000000000000000 error frame: bus-off"),
        "{text}"
    );
}

#[test]
fn vcan0_bus_off_stops_the_run_within_a_cycle_and_the_drives_stop_by_their_heartbeat_consumer() {
    let _g = lock();
    let _drives = simdrive_with(&[1, 2, 3], None, &["--inject", "1:bus-off@600ms"]);
    let mut emcy = watch(&[0x81, 0x82, 0x83]);
    let (h, dir) = run_in_thread(TWO_MOVES);
    let result = h.join().unwrap();
    let ended = Instant::now();
    let o = outcome(result, &dir);
    let f = common::failure(&o);
    assert!(
        matches!(
            f.alarm(),
            Alarm::BusLost {
                cause: BusLoss::BusOff { iface, .. },
                completed_line: Some(2),
                ..
            } if &**iface == "vcan0"
        ) && f.failure.line == Some(3),
        "{f}"
    );
    // Detected in the cycle after the error frame arrived.
    let d = common::detection_s(f, 0.6);
    let cycle = o.machine.cycle_s();
    assert!(
        d <= cycle + UML_MARGIN_S,
        "detected {d} s after the bus-off"
    );
    // Setpoints held from the detection on, no step beyond max velocity × period before.
    all_held_after(&o, f);
    steps_within_limits(&o);
    let detected = f.detected_cycle.unwrap() as f64;
    assert_eq!(
        o.rows.last().unwrap()[0],
        detected + 1.0,
        "cycles after the bus-off"
    );
    // The gateway sent nothing more, so every drive's heartbeat consumer fires: EMCY 0x8130
    // within the consumer time of the gateway's last heartbeat (at most one producer period
    // before the run returned).
    let bound = Duration::from_millis(u64::from(o.machine.heartbeat.drive_consumer_ms))
        + Duration::from_secs_f64(cycle + UML_MARGIN_S);
    let mut seen = [false; 3];
    while !seen.iter().all(|s| *s) {
        assert!(
            ended.elapsed() < bound,
            "no EMCY 0x8130 from every drive within {bound:?}: {seen:?}"
        );
        if let Some(f) = emcy.recv_timeout(Duration::from_millis(20)).unwrap()
            && f.data().len() == 8
            && u16::from_le_bytes([f.data()[0], f.data()[1]]) == 0x8130
        {
            seen[usize::from(f.id() - 0x81)] = true;
        }
    }
}

/// Brings vcan0 back up however the test ends.
struct LinkUp;

impl Drop for LinkUp {
    fn drop(&mut self) {
        let _ = std::process::Command::new("ip")
            .args(["link", "set", IFACE, "up"])
            .status();
    }
}

#[test]
fn vcan0_interface_going_down_stops_the_run_like_a_bus_off() {
    let _g = lock();
    let _drives = simdrive(&[1, 2, 3], None);
    let mut w = watch(&[0x181, 0x182, 0x183]);
    let (h, dir) = run_in_thread(SLOW);
    until_moving(w.as_mut());
    let _up = LinkUp;
    let ok = std::process::Command::new("ip")
        .args(["link", "set", IFACE, "down"])
        .status()
        .unwrap();
    assert!(ok.success(), "ip link set vcan0 down");
    let down = Instant::now();
    let result = h.join().unwrap();
    let took = down.elapsed();
    let o = outcome(result, &dir);
    let f = common::failure(&o);
    assert!(
        matches!(
            f.alarm(),
            Alarm::BusLost { cause: BusLoss::Port(e), .. }
                if matches!(&*e.0, BusError::InterfaceDown { iface } if iface == "vcan0")
        ),
        "{f}"
    );
    // The whole run ended within a cycle of the interface going down (plus UML's scheduling).
    assert!(
        took.as_secs_f64() <= o.machine.cycle_s() + UML_MARGIN_S,
        "the run ended {took:?} after the interface went down"
    );
    all_held_after(&o, f);
    steps_within_limits(&o);
}

/// A `plug` qdisc on vcan0 that takes at most `limit` bytes (a CAN frame is 16): released (it
/// passes everything) until [`Plug::block`], then it holds every frame and, once full, refuses
/// the next with ENOBUFS, as a controller whose frames nobody acknowledges. Removed on drop.
///
/// It is attached before anything runs: attaching a root qdisc deactivates the device for a
/// moment, and a send in that moment fails with ENOBUFS too.
struct Plug;

fn tc(args: &[&str]) {
    let out = std::process::Command::new("tc")
        .args(args)
        .output()
        .expect("tc (iproute2)");
    assert!(
        out.status.success(),
        "tc {}: {} (is sch_plug loaded? tools/in-vcan.sh loads it)",
        args.join(" "),
        String::from_utf8_lossy(&out.stderr)
    );
}

impl Plug {
    fn new(limit_bytes: u32) -> Plug {
        let limit = limit_bytes.to_string();
        tc(&[
            "qdisc", "add", "dev", IFACE, "root", "plug", "limit", &limit,
        ]);
        let plug = Plug;
        tc(&[
            "qdisc",
            "change",
            "dev",
            IFACE,
            "root",
            "plug",
            "release_indefinite",
        ]);
        plug
    }

    fn block(&self) {
        tc(&["qdisc", "change", "dev", IFACE, "root", "plug", "block"]);
    }
}

impl Drop for Plug {
    fn drop(&mut self) {
        let _ = std::process::Command::new("tc")
            .args(["qdisc", "del", "dev", IFACE, "root"])
            .status();
    }
}

#[test]
fn vcan0_a_transmit_queue_held_full_stops_the_run_after_the_tolerated_lost_cycles() {
    let _g = lock();
    let plug = Plug::new(160);
    let _drives = simdrive(&[1, 2, 3], None);
    let mut w = watch(&[0x181, 0x182, 0x183]);
    // Every SYNC the gateway queues reaches this socket through the local loopback (also while
    // the plug takes it in); one it cannot queue does not. The buffer holds the whole run, so
    // no SYNC is lost to a reader that is late (as the test thread is inside UML).
    let mut syncs = vcan0().sync_tap(0x80).unwrap().unwrap();
    syncs.set_receive_buffer(8 << 20).unwrap();
    let (h, dir) = run_in_thread(SLOW);
    until_moving(w.as_mut());
    plug.block();
    let deadline = Instant::now() + Duration::from_secs(20);
    while !h.is_finished() {
        assert!(Instant::now() < deadline, "the run did not end");
        let _ = w.recv_timeout(Duration::from_millis(20));
    }
    drop(plug);
    let queued = syncs.drain(|_| {}).unwrap() as u64;
    let o = outcome(h.join().unwrap(), &dir);
    let f = common::failure(&o);
    let tolerated = gateway::cyclic_bus::tolerated_lost_cycles(&o.machine);
    assert_eq!(tolerated, 2);
    // Stopped by the first run of lost cycles longer than tolerated, and nothing was lost before
    // the queue was held.
    assert!(
        matches!(
            f.alarm(),
            Alarm::TxQueueFull {
                iface,
                run: 3,
                tolerated_run: 2,
                lost_cycles: 3
            } if &**iface == "vcan0"
        ),
        "{f}"
    );
    // Detected in the third cycle in a row that could not queue its frames (the alarm's
    // `run: 3` above). The SYNCs cross-check it: at most `tolerated + 1` cycles up to the
    // detection lost theirs. A lost cycle may still have queued its SYNC into a slot the held
    // queue freed and lost only its setpoints, and the stop after the detection may queue one
    // more the same way (seen in CI, 2026-11-25: detected in cycle 32 with 33 SYNCs queued).
    let detected = f.detected_cycle.unwrap();
    assert!(
        queued <= detected + 1 && detected <= queued + u64::from(tolerated) + 1,
        "detected in cycle {detected} with {queued} SYNCs queued: {f}"
    );
    // The stop the gateway commanded kept every axis within its velocity and acceleration
    // limits (what the drives received of it is another matter: the queue stayed full).
    common::limits_held(&o, &[0, 1, 2]);
}

#[test]
fn vcan0_error_passive_is_a_warning_counted_in_the_summary() {
    let _g = lock();
    let _drives = simdrive_with(&[1, 2, 3], None, &["--inject", "2:error-passive@100ms"]);
    let s = gateway::run(
        &common::machine(|t| t),
        &vcan0(),
        &RunOptions {
            program_name: "common::PROGRAM".into(),
            program_text: common::PROGRAM.into(),
            log: None,
            simulate: false,
            ..Default::default()
        },
    )
    .expect("error-passive does not stop the run");
    assert_eq!(s.bus.warnings.len(), 1, "{s}");
    let w = &s.bus.warnings[0];
    assert_eq!(
        (w.what.as_str(), w.count),
        (
            "controller: RX error-passive, TX error-passive; error counters TX 128, RX 128",
            1
        )
    );
    assert!(
        s.to_string().contains(
            "warning           CAN error frame: controller: RX error-passive, TX error-passive"
        ),
        "{s}"
    );
}

#[test]
fn vcan0_run_reports_the_sync_period_from_kernel_timestamps() {
    let _g = lock();
    let _drives = simdrive(&[1, 2, 3], None);
    let out = run_square();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{stdout}");
    let line = |prefix: &str| {
        stdout
            .lines()
            .find(|l| l.starts_with(prefix))
            .unwrap_or_else(|| panic!("no {prefix:?} line in {stdout}"))
            .to_string()
    };
    let sync = line("SYNC period");
    assert!(
        sync.contains(
            "periods of 4000 µs from kernel receive timestamps on vcan0: |deviation| p50 "
        ),
        "{sync}"
    );
    // One SYNC per cycle but the last (the run ends without one): as many periods as cycles
    // less two.
    let periods: u64 = sync.split_whitespace().nth(2).unwrap().parse().unwrap();
    let cycles = line("cycles");
    let all: u64 = cycles
        .split(", ")
        .nth(1)
        .and_then(|s| s.split_whitespace().next())
        .unwrap()
        .parse()
        .unwrap();
    assert_eq!(periods, all - 2, "{sync}\n{cycles}");
    // The overrun count, singular or plural: "(0 overruns)", "(1 overrun)", "(2 overruns)".
    assert!(
        cycles.contains(" overruns)") || cycles.contains("(1 overrun)"),
        "{cycles}"
    );
}
