//! The machine-file loader on arbitrary bytes: [`Machine::parse`] must return an error, never
//! panic, and a machine it accepts keeps every promise its validation makes (README, "Machine
//! files"): limits within what the planner honours, a following-error window the drive can
//! supervise, no `sdo` entry on an object the gateway owns, SYNC on a CAN-ID of its own, PDOs
//! start-up can configure, and a configuration the planner and the override ramp accept.

use std::collections::BTreeSet;
use std::path::Path;

use crate::canopen::index;
use crate::config::machine::{
    DEMO_DRIVE, DRIVE_VELOCITY_HEADROOM, GATEWAY_OWNED, HOMING_TIMEOUT_MS, JOG_TIMEOUT_MS,
    MAX_AXES, MIN_AXIS_LIMIT, MIN_FOLLOWING_ERROR_COUNTS, MIN_PATH_ACC_SHARE, MIN_TRAVEL_COUNTS,
    RESTRICTED_CAN_IDS,
};
use crate::config::{DriveDictionary, Machine, PdoConfig};
use crate::planner::MAX_LIMIT;

/// [`Machine::parse`] on `data` as a machine file (its dictionaries are the demo drive's).
pub fn machine_file(data: &[u8]) {
    let text = String::from_utf8_lossy(data);
    let parsed = Machine::parse(Path::new("fuzz.toml"), &text, |rel| {
        DriveDictionary::parse(&Path::new("dictionaries/machines").join(rel), DEMO_DRIVE)
    });
    match parsed {
        Err(e) => {
            let _ = e.to_string();
        }
        Ok(m) => invariants(&m),
    }
}

fn invariants(m: &Machine) {
    assert!((1..=MAX_AXES).contains(&m.axes.len()));
    assert!(
        m.axes.iter().any(|a| a.xyz().is_some()),
        "no X, Y or Z axis"
    );
    let hb = m.heartbeat;
    assert!((1..=127).contains(&hb.gateway_node));
    assert!(JOG_TIMEOUT_MS.contains(&m.operation.jog_timeout_ms));
    let f = m.operation.unhomed_jog_fraction;
    assert!(f > 0.0 && f <= 1.0, "unhomed_jog_fraction {f}");
    let names: BTreeSet<_> = m.axes.iter().map(|a| a.name.as_str()).collect();
    let nodes: BTreeSet<_> = m.axes.iter().map(|a| a.node).collect();
    assert_eq!((names.len(), nodes.len()), (m.axes.len(), m.axes.len()));
    let sync = m.sync_cob_id;
    assert!(
        !RESTRICTED_CAN_IDS
            .iter()
            .any(|(lo, hi, _)| (*lo..=*hi).contains(&sync)),
        "SYNC 0x{sync:03X} restricted"
    );
    let in_range = |v: f64| (MIN_AXIS_LIMIT..=MAX_LIMIT).contains(&v);
    for a in &m.axes {
        assert!((1..=127).contains(&a.node) && a.node != hb.gateway_node);
        for v in [a.max_vel_mm_s, a.max_acc_mm_s2, a.max_jerk_mm_s3] {
            assert!(in_range(v), "axis {}: limit {v}", a.name);
        }
        let travel_mm = a.max_mm - a.min_mm;
        assert!(travel_mm * a.counts_per_mm >= MIN_TRAVEL_COUNTS);
        let window = a.mm_to_counts(a.following_error_mm);
        assert!(
            f64::from(window) >= MIN_FOLLOWING_ERROR_COUNTS && window < i32::MAX,
            "axis {}: window {window} counts",
            a.name
        );
        assert!(a.following_error_mm < travel_mm);
        assert!(a.max_vel_mm_s * a.counts_per_mm * DRIVE_VELOCITY_HEADROOM <= f64::from(u32::MAX));
        for w in &a.sdo {
            assert!(
                !GATEWAY_OWNED
                    .iter()
                    .any(|(lo, hi, ..)| (*lo..=*hi).contains(&w.index)),
                "axis {}: sdo 0x{:04X}",
                a.name,
                w.index
            );
        }
        if let Some(h) = &a.homing {
            assert!(
                (a.min_mm..=a.max_mm).contains(&h.offset_mm),
                "axis {}",
                a.name
            );
            assert!(HOMING_TIMEOUT_MS.contains(&h.timeout_ms));
            if h.moves() {
                for v in [h.speed_search_mm_s, h.speed_zero_mm_s] {
                    assert!(v > 0.0 && v <= a.max_vel_mm_s, "axis {}: {v}", a.name);
                    assert!(v * a.counts_per_mm <= f64::from(u32::MAX));
                }
                assert!(h.acc_mm_s2 > 0.0 && h.acc_mm_s2 <= a.max_acc_mm_s2);
            }
        }
        for v in [Some(a.sim.start_mm), a.sim.home_switch_mm]
            .into_iter()
            .flatten()
            .chain(a.sim.limit_switches_mm.into_iter().flatten())
        {
            assert!(
                (v * a.counts_per_mm).abs() < f64::from(i32::MAX),
                "axis {}",
                a.name
            );
        }
        let pdo = |p: &PdoConfig| {
            let mut seen = BTreeSet::new();
            assert!(p.mapping.iter().all(|e| seen.insert((e.index, e.sub))));
            assert!(p.len_bytes() <= 8);
            assert_ne!(p.cob_id, sync);
        };
        pdo(&a.setpoint_pdo);
        pdo(&a.feedback_pdo);
        assert_eq!(a.feedback_pdo.transmission, 1);
        assert_ne!(crate::canopen::cob::EMCY + u16::from(a.node), sync);
        // What the cyclic master reads from the process data is there.
        assert!(a.feedback_pdo.offset_of(index::STATUSWORD, 0).is_some());
        assert!(
            a.feedback_pdo
                .offset_of(index::POSITION_ACTUAL, 0)
                .is_some()
        );
        let (si, ss) = a.mode.setpoint_object();
        assert!(a.setpoint_pdo.offset_of(index::CONTROLWORD, 0).is_some());
        assert!(a.setpoint_pdo.offset_of(si, ss).is_some());
    }
    let p = &m.planner;
    assert!((MIN_PATH_ACC_SHARE..=1.0).contains(&p.path_acc_share));
    assert!(in_range(p.path_acc_mm_s2) || p.path_acc_mm_s2 == f64::INFINITY);
    p.validate().expect("the planner's configuration");
    crate::gateway::limits(m)
        .validate()
        .expect("the planner's limits");
    assert!(m.bus_load().percent <= m.max_load_percent);
}
