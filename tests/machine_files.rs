//! What the machine-file loader refuses (README, "Machine files"): configurations that would
//! defeat the drives' supervision, or that the planner would not honour, are refused at load,
//! so that `plan` and `run` agree, each naming the file, the table and the key.

use std::path::Path;

use canmotion::config::machine::{DEMO_DRIVE, DEMO_MACHINE};
use canmotion::config::{ConfigError, DriveDictionary, Machine};

fn parse(text: &str) -> Result<Machine, ConfigError> {
    Machine::parse(Path::new("m.toml"), text, |rel| {
        DriveDictionary::parse(&Path::new("dictionaries/machines").join(rel), DEMO_DRIVE)
    })
}

/// The demo machine with the first `from` replaced by `to`: refused, with (table, key, message).
fn refused(from: &str, to: &str) -> (String, String, String) {
    assert!(DEMO_MACHINE.contains(from), "demo file lacks {from:?}");
    match parse(&DEMO_MACHINE.replacen(from, to, 1)) {
        Ok(_) => panic!("accepted {to:?}"),
        Err(ConfigError::Invalid {
            file,
            table,
            key,
            message,
        }) => {
            assert_eq!(file, Path::new("m.toml"));
            (table, key, message)
        }
        Err(e) => panic!("{to:?}: not an Invalid error: {e}"),
    }
}

fn assert_refused(from: &str, to: &str, table: &str, key: &str, says: &str) {
    let (t, k, m) = refused(from, to);
    assert_eq!((t.as_str(), k.as_str()), (table, key), "{to:?}: {m}");
    assert!(m.contains(says), "{to:?}: [{t}] {k}: {m}");
}

const X_SDO: &str = "{ index = 0x605A, sub = 0, value = 2 }";

#[test]
fn a_count_too_coarse_to_position_the_axis_is_refused() {
    // 305 mm of travel at 0.001 counts/mm: 0.3 counts. The axis never moved, and the run ended 0.
    assert_refused(
        "counts_per_mm = 1000.0",
        "counts_per_mm = 0.001",
        "axis X",
        "counts_per_mm",
        "fewer than 1000",
    );
}

#[test]
fn a_following_error_window_that_rounds_away_or_clamps_is_refused() {
    let fe = "following_error_mm = 2.0";
    // 0.1 count: rounds to 0.
    assert_refused(
        fe,
        "following_error_mm = 0.0001",
        "axis X",
        "following_error_mm",
        "0 counts in 0x6065",
    );
    // 5 counts: rounding alone trips it.
    assert_refused(
        fe,
        "following_error_mm = 0.005",
        "axis X",
        "following_error_mm",
        "fewer than 10",
    );
    // 1e10 counts: 0x6065 would be clamped at 2³¹−1 (jam detection off).
    let (t, k, m) = refused(fe, "following_error_mm = 1e7");
    assert_eq!((t.as_str(), k.as_str()), ("axis X", "following_error_mm"));
    assert!(m.contains("not below the 2147483647 counts"), "{m}");
    // As long as the travel: a jam is never seen.
    assert_refused(
        fe,
        "following_error_mm = 400.0",
        "axis X",
        "following_error_mm",
        "not shorter than the travel",
    );
    // The smallest window accepted: 10 counts.
    assert!(parse(&DEMO_MACHINE.replacen(fe, "following_error_mm = 0.01", 1)).is_ok());
}

#[test]
fn sdo_entries_may_not_override_what_the_gateway_owns() {
    for (index, sub, value) in [
        (0x1016, 1, 0), // the drives would stop watching the gateway
        (0x1017, 0, 0),
        (0x1005, 0, 0x81),
        (0x1006, 0, 0),
        (0x1007, 0, 0),
        (0x1014, 0, 0x8000_0081u32 as i64),
        (0x6007, 0, 0),
        (0x1400, 1, 0x8000_0201u32 as i64),
        (0x1600, 1, 0x6040_0010),
        (0x1800, 2, 240),
        (0x1A00, 0, 0),
        (0x6065, 0, 100_000),
        (0x607D, 1, -1_000_000),
        (0x607F, 0, 1_000_000_000),
        (0x6060, 0, 1),
        (0x60C2, 1, 10),
    ] {
        let entry = format!("{{ index = 0x{index:04X}, sub = {sub}, value = {value} }}");
        let (t, k, m) = refused(X_SDO, &entry);
        assert_eq!(
            (t.as_str(), k.as_str()),
            ("axis X", "sdo[0]"),
            "{entry}: {m}"
        );
        assert!(
            m.starts_with(&format!("0x{index:04X}:{sub:02X}: the gateway owns")),
            "{entry}: {m}"
        );
    }
    // The drive's own settings stay the machine file's to write.
    assert!(parse(DEMO_MACHINE).is_ok());
}

#[test]
fn a_sync_cob_id_on_another_objects_identifier_is_refused() {
    for (id, says) in [
        (0x181, "feedback PDO of axis X (node 1)"), // node 1's TPDO 1
        (0x201, "setpoint PDO of axis X (node 1)"),
        (0x82, "EMCY of axis Y (node 2)"),
        (0x581, "restricted CAN-ID"), // node 1's SDO response
        (0x603, "restricted CAN-ID"), // node 3's SDO request
        (0x701, "restricted CAN-ID"), // node 1's heartbeat
        (0x77F, "restricted CAN-ID"), // the gateway's own heartbeat (gateway_node 0x7F)
        (0x7E5, "restricted CAN-ID"), // LSS
    ] {
        let (t, k, m) = refused("cob_id = 0x80", &format!("cob_id = 0x{id:X}"));
        assert_eq!(
            (t.as_str(), k.as_str()),
            ("sync", "cob_id"),
            "0x{id:X}: {m}"
        );
        assert!(m.contains(says), "0x{id:X}: {m}");
    }
    // A free identifier is fine.
    assert!(parse(&DEMO_MACHINE.replacen("cob_id = 0x80", "cob_id = 0x90", 1)).is_ok());
    // The gateway's heartbeat on a drive's: refused on the axis's node.
    let (t, k, m) = refused("gateway_node = 0x7F", "gateway_node = 2");
    assert_eq!((t.as_str(), k.as_str()), ("axis Y", "node"), "{m}");
}

#[test]
fn a_mapping_start_up_would_reject_is_refused_at_load() {
    let (t, k, m) = refused(
        "mapping = [0x60400010, 0x60C10120]",
        "mapping = [0x60400010, 0x60C10120, 0x60400010]",
    );
    assert_eq!(
        (t.as_str(), k.as_str()),
        ("axis X", "setpoint_pdo.mapping[2]")
    );
    assert!(
        m.contains("mapped twice (also setpoint_pdo.mapping[0])"),
        "{m}"
    );
    let (t, k, m) = refused(
        "mapping = [0x60410010, 0x60640020]",
        "mapping = [0x60410010, 0x60640020, 0x60410010]",
    );
    assert_eq!(
        (t.as_str(), k.as_str()),
        ("axis X", "feedback_pdo.mapping[2]"),
        "{m}"
    );
    // Feedback every 240th SYNC: the cyclic thread would stop on "no process data".
    assert_refused(
        "feedback_pdo = { number = 1, transmission = 1,",
        "feedback_pdo = { number = 1, transmission = 240,",
        "axis X",
        "feedback_pdo.transmission",
        "on every SYNC",
    );
    assert_refused(
        "feedback_pdo = { number = 1, transmission = 1,",
        "feedback_pdo = { number = 1, transmission = 2,",
        "axis X",
        "feedback_pdo.transmission",
        "on every SYNC",
    );
}

#[test]
fn limits_the_planner_would_not_honour_are_refused_on_their_key() {
    for (from, to, key) in [
        (
            "max_jerk_mm_s3 = 50000.0",
            "max_jerk_mm_s3 = 1e-300",
            "max_jerk_mm_s3",
        ),
        (
            "max_vel_mm_s = 200.0",
            "max_vel_mm_s = 1e300",
            "max_vel_mm_s",
        ),
        (
            "max_vel_mm_s = 200.0",
            "max_vel_mm_s = 1e10",
            "max_vel_mm_s",
        ),
        (
            "max_vel_mm_s = 200.0",
            "max_vel_mm_s = 1e-5",
            "max_vel_mm_s",
        ),
        (
            "max_acc_mm_s2 = 2000.0",
            "max_acc_mm_s2 = 2e9",
            "max_acc_mm_s2",
        ),
        (
            "max_acc_mm_s2 = 2000.0",
            "max_acc_mm_s2 = 1e-300",
            "max_acc_mm_s2",
        ),
    ] {
        let (t, k, m) = refused(from, to);
        assert_eq!((t.as_str(), k.as_str()), ("axis X", key), "{to}: {m}");
        assert!(m.contains("0.001..=1e9"), "{to}: {m}");
    }
    // Within the planner's range, but 0x607F (counts/s, UNSIGNED32) cannot hold it.
    assert_refused(
        "max_vel_mm_s = 200.0",
        "max_vel_mm_s = 1e7",
        "axis X",
        "max_vel_mm_s",
        "0x607F",
    );
    let planner = "[program]";
    for (to, key, says) in [
        (
            "[planner]\npath_acc_mm_s2 = 1e-300\n\n[program]",
            "path_acc_mm_s2",
            "0.001..=1e9",
        ),
        (
            "[planner]\npath_acc_share = 1e-300\n\n[program]",
            "path_acc_share",
            "0.001..=1",
        ),
        (
            "[planner]\ncorner_acc_mm_s2 = 1e300\n\n[program]",
            "corner_acc_mm_s2",
            "0..=1e9",
        ),
        (
            "[planner]\naxis_filter_ms = 4\n\n[program]",
            "axis_filter_ms",
            "8..=16 ms",
        ),
        (
            "[planner]\naxis_filter_ms = 20\n\n[program]",
            "axis_filter_ms",
            "8..=16 ms",
        ),
    ] {
        assert_refused(planner, to, "planner", key, says);
    }
}

/// `[planner] axis_filter_ms` sets the jerk-limited mode's axis filters (8 ms without it),
/// and the plan's filters follow it.
#[test]
fn the_axis_filter_time_is_the_machine_file_s() {
    let machine = |extra: &str| {
        parse(&DEMO_MACHINE.replacen("[program]", &format!("{extra}[program]"), 1))
            .expect("the machine parses")
    };
    let default = machine("");
    assert_eq!(default.planner.axis_filter_s, 0.008);
    let longer = machine("[planner]\naxis_filter_ms = 12\nprofile = \"s-curve\"\n\n");
    assert_eq!(longer.planner.axis_filter_s, 0.012);
    let limits = canmotion::gateway::limits(&longer);
    let smoothing = canmotion::planner::Smoothing::for_machine(&limits, &longer.planner)
        .expect("the jerk-limited mode filters");
    // 12 ms is three of the demo machine's 4 ms periods.
    let axis_s = smoothing.axis_s(longer.planner.period_s);
    assert!((axis_s - 0.012).abs() < 1e-12, "{axis_s} s");
}

#[test]
fn a_machine_without_x_y_or_z_is_refused_on_its_axis() {
    // Only the Z axis, renamed A.
    let z = &DEMO_MACHINE[DEMO_MACHINE.rfind("[[axis]]").unwrap()..];
    let head = &DEMO_MACHINE[..DEMO_MACHINE.find("[[axis]]").unwrap()];
    let text = format!("{head}{}", z.replacen("name = \"Z\"", "name = \"A\"", 1));
    match parse(&text) {
        Err(ConfigError::Invalid {
            table,
            key,
            message,
            ..
        }) => {
            assert_eq!((table.as_str(), key.as_str()), ("axis A", "name"));
            assert!(message.contains("X, Y or Z"), "{message}");
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn a_bad_dictionary_names_the_key_and_never_echoes_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let machine = |dict: &str| {
        let p = dir.path().join("m.toml");
        let text = DEMO_MACHINE.replace("../drives/cia402-servo.toml", dict);
        std::fs::write(&p, text).unwrap();
        Machine::load(&p).unwrap_err()
    };
    // Missing: the key, then the path.
    let e = machine("no-such-dictionary.toml");
    match &e {
        ConfigError::Referenced {
            table, key, source, ..
        } => {
            assert_eq!((table.as_str(), key.as_str()), ("axis X", "dictionary"));
            assert!(
                matches!(
                    **source,
                    ConfigError::File(canmotion::files::FileError::Read { .. })
                ),
                "{source:?}"
            );
        }
        other => panic!("{other:?}"),
    }
    let msg = e.to_string();
    assert!(msg.contains("m.toml: [axis X] dictionary: "), "{msg}");
    assert!(
        msg.contains("no-such-dictionary.toml: cannot read"),
        "{msg}"
    );

    // Not a dictionary (a shadow file): its line and column, never its contents.
    let secret = "root:$6$Zq1sEcReThAsH$abcdefghijklmnop:19000:0:99999:7:::\n";
    let shadow = dir.path().join("shadow");
    std::fs::write(&shadow, format!("{secret}daemon:*:19000:0:99999:7:::\n")).unwrap();
    let e = machine(&shadow.display().to_string());
    let msg = e.to_string();
    match &e {
        ConfigError::Referenced { key, source, .. } => {
            assert_eq!(key, "dictionary");
            assert!(matches!(**source, ConfigError::Parse { .. }), "{source:?}");
        }
        other => panic!("{other:?}"),
    }
    assert!(msg.contains("[axis X] dictionary: "), "{msg}");
    assert!(msg.contains("shadow: line 1, column "), "{msg}");
    for part in ["root", "EcReT", "19000", "daemon", "$6$"] {
        assert!(!msg.contains(part), "the message echoes {part:?}: {msg}");
    }
}

#[test]
fn every_machine_file_in_the_repository_still_loads() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("dictionaries/machines");
    let mut n = 0;
    for entry in std::fs::read_dir(dir).unwrap() {
        let p = entry.unwrap().path();
        if p.extension().is_some_and(|e| e == "toml") {
            match Machine::load(&p) {
                // Six axes at 1 ms on 1 Mbit/s: the bus-load example, refused on purpose.
                Err(ConfigError::Invalid { table, key, .. })
                    if p.ends_with("bench-6ax-1ms.toml") =>
                {
                    assert_eq!((table.as_str(), key.as_str()), ("bus", "cycle_us"));
                }
                Err(e) => panic!("{e}"),
                Ok(_) => {}
            }
            n += 1;
        }
    }
    assert!(n >= 6, "{n} machine files");
}

#[test]
fn a_dictionary_without_the_pdo_objects_start_up_writes_is_refused_at_load() {
    // No RPDO 4 communication object: start-up switches every unused PDO off, so `run` would
    // end on an SDO abort that `plan` never saw.
    let a = DEMO_DRIVE.find("[[object]]\nindex = 0x1403").unwrap();
    let b = DEMO_DRIVE.find("[[object]]\nindex = 0x1600").unwrap();
    let drive = format!("{}{}", &DEMO_DRIVE[..a], &DEMO_DRIVE[b..]);
    let e = Machine::parse(Path::new("m.toml"), DEMO_MACHINE, |rel| {
        DriveDictionary::parse(&Path::new("dictionaries/machines").join(rel), &drive)
    })
    .unwrap_err();
    match e {
        ConfigError::Invalid {
            table,
            key,
            message,
            ..
        } => {
            assert_eq!((table.as_str(), key.as_str()), ("axis X", "dictionary"));
            assert!(
                message.starts_with("start-up writes 0x1403:01"),
                "{message}"
            );
        }
        other => panic!("{other}"),
    }
}

#[test]
fn an_enable_timeout_outside_its_bounds_is_refused_on_its_key() {
    let from = "following_error_timeout_ms = 10";
    for bad in ["0", "60001"] {
        assert_refused(
            from,
            &format!("enable_timeout_ms = {bad}\n{from}"),
            "axis X",
            "enable_timeout_ms",
            &format!("{bad} outside 1..=60000 ms"),
        );
    }
    let m = parse(&DEMO_MACHINE.replacen(from, &format!("enable_timeout_ms = 60000\n{from}"), 1))
        .unwrap();
    assert_eq!(m.axes[0].enable_timeout_ms, 60_000);
    assert_eq!(m.axes[1].enable_timeout_ms, 2000);
}

/// The homing test machine (tests/machines/homing-xyz.toml): each axis's simulated drive, built
/// from the file with `SimDrive::for_axis`, starts at `[axis.sim] start_mm`, and homing it with
/// the objects `[axis.homing]` gives (in counts, as the master writes them) moves it to its
/// simulated home switch and ends with position actual = `offset_mm`, in the file's order.
#[test]
fn a_machine_files_homing_and_sim_tables_home_its_simulated_drives() {
    use std::time::Duration;

    use canmotion::canopen::index;
    use canmotion::canopen::sdo_server::SdoTarget;
    use canmotion::cia402::{controlword as cw, statusword as sw};
    use canmotion::sim::{HomingStatus, SimDrive};
    use canopen_rs::Value;

    let m = Machine::load(Path::new("tests/machines/homing-xyz.toml")).expect("loads");
    let mut axes: Vec<_> = m.axes.iter().collect();
    axes.sort_by_key(|a| a.homing.as_ref().expect("every axis homes").order);
    assert_eq!(
        axes.iter().map(|a| a.name.as_str()).collect::<Vec<_>>(),
        ["Z", "X", "Y"],
        "Z homes first"
    );
    for a in axes {
        let h = a.homing.as_ref().unwrap();
        let mut d = SimDrive::for_axis(a);
        let mut now = Duration::ZERO;
        let mut out = Vec::new();
        d.boot(now, &mut out);
        let start = d.position_counts();
        assert_eq!(start, a.mm_to_counts(a.sim.start_mm), "axis {}", a.name);
        assert_ne!(
            a.sim.start_mm, h.offset_mm,
            "axis {}: homing must move",
            a.name
        );
        let write = |d: &mut SimDrive, index: u16, sub: u8, v: Value| {
            let mut buf = [0u8; 8];
            let n = v.encode_le(&mut buf).unwrap();
            d.sdo_write(index, sub, &buf[..n])
                .unwrap_or_else(|e| panic!("axis {}: {index:04X}:{sub}: {e}", a.name));
        };
        let counts_u32 = |x: f64| Value::Unsigned32((x * a.counts_per_mm).round() as u32);
        let method = h.drive_method().expect("a drive method");
        write(&mut d, index::HOMING_METHOD, 0, Value::Integer8(method));
        write(
            &mut d,
            index::HOMING_SPEEDS,
            1,
            counts_u32(h.speed_search_mm_s),
        );
        write(
            &mut d,
            index::HOMING_SPEEDS,
            2,
            counts_u32(h.speed_zero_mm_s),
        );
        write(
            &mut d,
            index::HOMING_ACCELERATION,
            0,
            counts_u32(h.acc_mm_s2),
        );
        let offset = a.mm_to_counts(h.offset_mm);
        write(&mut d, index::HOME_OFFSET, 0, Value::Integer32(offset));
        write(&mut d, index::MODES_OF_OPERATION, 0, Value::Integer8(6));
        for c in [
            cw::SHUTDOWN,
            cw::SWITCH_ON_CMD,
            cw::ENABLE_OPERATION_CMD,
            cw::ENABLE_OPERATION_CMD | cw::HOMING_START,
        ] {
            write(&mut d, index::CONTROLWORD, 0, Value::Unsigned16(c));
        }
        // Virtual time, to a deadline of the axis's homing time-out.
        let deadline = Duration::from_millis(u64::from(h.timeout_ms));
        let mut moved = 0i32;
        while d.homing_status() == HomingStatus::InProgress
            || d.statusword() & sw::TARGET_REACHED == 0
        {
            assert!(now < deadline, "axis {}: homing did not end", a.name);
            now += Duration::from_millis(1);
            d.poll(now, &mut out);
            moved = moved.max((d.position_counts() - start).abs());
        }
        assert_eq!(d.homing_status(), HomingStatus::Attained, "axis {}", a.name);
        let s = d.statusword();
        assert_ne!(s & sw::HOMING_ATTAINED, 0);
        assert_eq!(s & sw::HOMING_ERROR, 0);
        assert_eq!(d.position_counts(), offset, "axis {}", a.name);
        assert!(moved > 1000, "axis {}: moved {moved} counts", a.name);
    }
}
