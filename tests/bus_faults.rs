//! Bus-level faults on the in-process bus: the simulated drive sends the error frame the
//! gateway's controller would report (bus-off, error-passive). The same scenarios run on vcan0
//! in tests/vcan/bus.rs, with the interface going down and a full transmit queue besides.

mod common;

use std::path::PathBuf;

use canmotion::bus::Bus;
use canmotion::bus::inproc::InProcBus;
use canmotion::gateway::{self, RunOptions};
use canmotion::master::alarm::{Alarm, BusLoss};
use canmotion::rt::period_stats::TimestampSource;
use canmotion::sim::{Inject, SimDrive, runner};
use common::*;

fn run(inject: Option<(u8, Inject)>, program: &str) -> Outcome {
    let _one = one_at_a_time();
    let machine = machine(|t| t);
    let bus = InProcBus::new();
    let dict = drive_dict(|t| t);
    let drives = machine
        .axes
        .iter()
        .map(|a| match inject {
            Some((n, i)) if n == a.node => SimDrive::new(dict.clone(), a.node).with_inject(i),
            _ => SimDrive::new(dict.clone(), a.node),
        })
        .collect();
    let _sims = runner::spawn(&Bus::InProc(bus.clone()), drives).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let log: PathBuf = dir.path().join("log.csv");
    let result = gateway::run(
        &machine,
        &Bus::InProc(bus),
        &RunOptions {
            program_name: "bus.ngc".into(),
            program_text: program.into(),
            log: Some(log.clone()),
            simulate: false,
            ..Default::default()
        },
    );
    Outcome {
        result,
        rows: read_csv(&log),
        machine,
    }
}

#[test]
fn bus_off_ends_the_run_in_the_next_cycle_with_every_setpoint_held() {
    let program = "G21 G90\nG1 X10 F3000\nG1 X70 Y60 Z-2 F4243\nM2\n";
    let o = run(Some((2, Inject::BusOff { after: ms(600) })), program);
    let f = failure(&o);
    assert!(
        matches!(
            f.alarm(),
            Alarm::BusLost {
                cause: BusLoss::BusOff { iface, .. },
                completed_line: Some(2),
                ..
            } if &**iface == "sim (in-process)"
        ) && f.failure.line == Some(3),
        "{f}"
    );
    let d = detection_s(f, 0.6);
    assert!(
        d <= o.machine.cycle_s() + 0.050,
        "detected {d} s after the bus-off"
    );
    // Nothing after the detection: the row of the detecting cycle holds every setpoint.
    let detected = f.detected_cycle.unwrap() as f64;
    assert_eq!(o.rows.last().unwrap()[0], detected + 1.0);
    for axis in 0..3 {
        frozen_after(&o, axis, f);
    }
    // Up to the cut, no step or acceleration beyond the limits (at the cut the drives hold the
    // last setpoint they got: nothing more can reach them).
    let upto = Outcome {
        result: Err(gateway::GatewayError::Bus(canmotion::bus::BusError::Closed)),
        rows: o.rows[..o.rows.len() - 1].to_vec(),
        machine: o.machine.clone(),
    };
    limits_held(&upto, &[0, 1, 2]);
}

#[test]
fn error_passive_is_counted_and_the_run_completes_with_the_sync_statistics() {
    let o = run(Some((3, Inject::ErrorPassive { after: ms(100) })), PROGRAM);
    let s = o.result.as_ref().expect("error-passive is only a warning");
    assert_eq!(s.bus.warnings.len(), 1, "{s}");
    assert_eq!(s.bus.warnings[0].count, 1);
    assert!(s.bus.warnings[0].what.contains("TX error-passive"), "{s}");
    assert_eq!(s.bus.tx_loss.cycles, 0);
    let sync = s.bus.sync_period.as_ref().expect("SYNC statistics");
    assert_eq!(sync.source, TimestampSource::SenderClock);
    assert_eq!(sync.periods, s.cycles - 2, "{s}");
    let text = s.to_string();
    assert!(
        text.contains("SYNC period       ")
            && text.contains("from the sender's clock (in-process bus): |deviation| p50 "),
        "{text}"
    );
}
