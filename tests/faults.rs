//! Fault reactions on the in-process bus: simulated drives told to misbehave mid-motion. Each
//! test checks the reported message, the detection time, and that no healthy axis's setpoint
//! broke its velocity or acceleration limit while the group stopped. The same scenarios run on
//! vcan0 in tests/vcan.rs.

mod common;

use std::path::PathBuf;

use canmotion::bus::Bus;
use canmotion::bus::inproc::InProcBus;
use canmotion::cia402::State;
use canmotion::config::Machine;
use canmotion::gateway::{self, RunOptions};
use canmotion::master::alarm::{Alarm, LateAxis};
use canmotion::sim::{Inject, SimDrive, runner};
use common::*;

fn run(machine: Machine, inject: &[(u8, Inject)], program: &str) -> Outcome {
    let _one = one_at_a_time();
    let bus = InProcBus::new();
    let dict = drive_dict(|t| t);
    let drives = machine
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
    let _sims = runner::spawn(&Bus::InProc(bus.clone()), drives).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let log: PathBuf = dir.path().join("log.csv");
    let result = gateway::run(
        &machine,
        &Bus::InProc(bus),
        &RunOptions {
            program_name: "fault.ngc".into(),
            program_text: program.into(),
            log: Some(log.clone()),
            simulate: false,
            ..Default::default()
        },
    );
    let text = std::fs::read_to_string(&log).unwrap();
    let rows = text
        .lines()
        .skip(1)
        .map(|l| l.split(',').map(|x| x.parse().unwrap()).collect())
        .collect();
    Outcome {
        result,
        rows,
        machine,
    }
}

#[test]
fn a_following_error_fault_freezes_the_axis_and_stops_the_group() {
    let o = run(
        machine(|t| t),
        &[(2, Inject::FollowingError { after: ms(400) })],
        LONG,
    );
    let f = failure(&o);
    assert!(
        matches!(
            f.alarm(),
            Alarm::FollowingError {
                axis: "Y",
                node: 2,
                ..
            } | Alarm::Emcy {
                axis: "Y",
                node: 2,
                code: 0x8611
            }
        ),
        "{f}"
    );
    assert_eq!(f.failure.line, Some(2), "{f}");
    // The window is 2 mm at 100 mm/s: 20 ms, plus the 10 ms time-out, plus the PDO round trip.
    let d = detection_s(f, 0.4);
    assert!(d < 0.130, "detected {d} s after the jam");
    frozen_after(&o, 1, f);
    limits_held(&o, &[0, 2]);
}

// A silent drive (missing process data, in its exact cycle) and a reboot mid-motion (boot-up,
// in the cycle that reads it) run on the virtual clock: tests/virtual_clock.rs.

#[test]
fn lost_rpdos_do_not_stop_a_run() {
    // 5 % of setpoints lost: the drive holds its last one for that cycle and catches up.
    let o = run(
        machine(|t| t),
        &[
            (1, Inject::DropRpdo { percent: 5.0 }),
            (2, Inject::DropRpdo { percent: 5.0 }),
        ],
        PROGRAM,
    );
    let s = o.result.as_ref().expect("the run completes");
    for (i, want) in PROGRAM_END_COUNTS.iter().enumerate() {
        assert!((s.final_counts[i] - want).abs() <= 1, "{s}");
    }
}

#[test]
fn a_warning_emcy_is_counted_and_the_run_goes_on() {
    // EMCY 0x4210 with statusword bit 7 (warning) and not bit 3 (fault), mid-motion.
    let o = run(
        machine(|t| t),
        &[(
            1,
            Inject::Warning {
                code: 0x4210,
                after: ms(300),
            },
        )],
        LONG,
    );
    let summary = o.result.as_ref().unwrap_or_else(|e| panic!("{e}"));
    let w = summary
        .warnings
        .iter()
        .find(|w| w.code == 0x4210)
        .unwrap_or_else(|| panic!("no warning 0x4210 counted: {summary}"));
    assert_eq!((w.node, w.count), (1, 1), "{summary}");
    assert!(
        summary
            .to_string()
            .contains("axis X (node 1): EMCY 0x4210 device temperature ×1"),
        "{summary}"
    );
}

/// A drive that takes 2.6 s to reach Operation enabled (a brake to release).
const SLOW_ENABLE: Inject = Inject::SlowEnable {
    delay: std::time::Duration::from_millis(2600),
};

#[test]
fn a_slow_drive_is_accepted_within_its_enable_timeout() {
    let o = run(
        machine(|t| {
            t.replace(
                "following_error_timeout_ms = 10",
                "enable_timeout_ms = 4000\nfollowing_error_timeout_ms = 10",
            )
        }),
        &[(1, SLOW_ENABLE)],
        PROGRAM,
    );
    assert_eq!(o.machine.axes[0].enable_timeout_ms, 4000);
    let summary = o.result.as_ref().unwrap_or_else(|e| panic!("{e}"));
    assert!(summary.streaming_cycles > 0, "{summary}");
}

#[test]
fn a_slow_drive_is_refused_after_the_default_enable_timeout() {
    let o = run(machine(|t| t), &[(1, SLOW_ENABLE)], PROGRAM);
    assert_eq!(o.machine.axes[0].enable_timeout_ms, 2000);
    let f = failure(&o);
    // Detected at the time-out, not before: no other axis named.
    let Alarm::EnableTimeout { late } = f.alarm() else {
        panic!("{f}")
    };
    assert_eq!(
        late.iter().copied().collect::<Vec<_>>(),
        [LateAxis {
            axis: "X",
            node: 1,
            state: Some(State::SwitchedOn),
            enable_timeout_ms: 2000
        }],
        "{f}"
    );
    let t = f.detected_cycle.unwrap() as f64 * f.period_s;
    assert!(t > 2.0, "detected {t} s into the run");
}
