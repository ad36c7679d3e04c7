//! The commissioning commands (`canmotion monitor|sdo|nmt|scan`) against simulated drives on the
//! in-process bus, and the command line's argument errors.
//!
//! Run with `--nocapture` to see each command's output as the command line prints it.

use std::path::Path;
use std::process::Command;
use std::sync::Arc;
use std::time::Duration;

use canopen_rs::Value;

use canmotion::bus::inproc::InProcBus;
use canmotion::bus::{Bus, Filter};
use canmotion::canopen::NmtState;
use canmotion::canopen::sdo_client::Mode;
use canmotion::commands::monitor::{self, MonitorOptions};
use canmotion::commands::scan::{self, ScanOptions};
use canmotion::commands::sdo::{self, ReadValue};
use canmotion::commands::{
    DecodeContext, NmtCommand, NmtTarget, Node, ObjectAddress, SdoType, ToolError, nmt,
};
use canmotion::config::{DriveDictionary, Machine};
use canmotion::sim::{SimDrive, runner};

fn dict() -> Arc<DriveDictionary> {
    Arc::new(
        DriveDictionary::parse(
            Path::new("cia402-servo.toml"),
            canmotion::config::machine::DEMO_DRIVE,
        )
        .expect("demo dictionary"),
    )
}

/// An in-process bus with simulated drives at `nodes`, returned once they have all booted.
fn bus_with(nodes: &[u8]) -> (Bus, runner::SimHandle) {
    let bus = Bus::InProc(InProcBus::new());
    let mut bootups = bus
        .open(&[Filter {
            id: 0x700,
            mask: 0x780,
        }])
        .unwrap();
    let d = dict();
    let drives = nodes.iter().map(|&n| SimDrive::new(d.clone(), n)).collect();
    let handle = runner::spawn(&bus, drives).expect("spawn drives");
    let mut missing: Vec<u8> = nodes.to_vec();
    while !missing.is_empty() {
        let f = bootups
            .recv_timeout(Duration::from_secs(5))
            .unwrap()
            .expect("boot-up within 5 s");
        missing.retain(|&n| f.id() != 0x700 + u16::from(n) || f.data() != [0]);
    }
    (bus, handle)
}

fn addr(s: &str) -> ObjectAddress {
    s.parse().unwrap()
}

#[test]
fn scan_finds_nodes_2_and_5_with_their_identity_and_nothing_else() {
    let (bus, _drives) = bus_with(&[2, 5]);
    let nodes = scan::scan(&bus, &ScanOptions::default()).expect("scan");
    let table = scan::format_table(&nodes);
    eprintln!("$ canmotion scan sim\n{table}{} node(s)", nodes.len());
    assert_eq!(nodes.iter().map(|n| n.node).collect::<Vec<_>>(), vec![2, 5]);
    for n in &nodes {
        assert!(n.answered_sdo);
        assert_eq!(n.device_type, Some(0x0002_0192));
        assert_eq!(n.vendor_id, Some(0x0000_0CA7));
        assert_eq!(n.product_code, Some(0x0000_0402));
        assert_eq!(n.revision, Some(0x0001_0000));
        assert_eq!(n.serial, Some(0));
        assert_eq!(n.name.as_deref(), Some("canmotion sim servo"));
        // 0x1017 = 0: no heartbeat, so no state.
        assert_eq!(n.heartbeat_ms, Some(0));
        assert_eq!(n.state, None);
    }
    assert!(
        table.contains(
            "   5  - (heartbeat off)  0x00020192  0x00000CA7  0x00000402  0x00010000  0x00000000  canmotion sim servo"
        ),
        "{table}"
    );
}

#[test]
fn scan_of_an_empty_bus_finds_nothing() {
    let bus = Bus::InProc(InProcBus::new());
    let opts = ScanOptions {
        timeout: Duration::from_millis(20),
        ..ScanOptions::default()
    };
    assert!(scan::scan(&bus, &opts).unwrap().is_empty());
}

#[test]
fn sdo_read_write_round_trip() {
    let (bus, _drives) = bus_with(&[2, 5]);
    let n5 = Node(5);
    // Typed writes, read back typed and untyped.
    for (a, t, text, want) in [
        ("1017", SdoType::U16, "0x64", Value::Unsigned16(100)),
        (
            "6085",
            SdoType::U32,
            "20000000",
            Value::Unsigned32(20_000_000),
        ),
        ("607A:00", SdoType::I32, "-12345", Value::Integer32(-12345)),
        ("6060", SdoType::I8, "8", Value::Integer8(8)),
    ] {
        let written = sdo::write_text(&bus, n5, addr(a), t, text).expect("write");
        assert_eq!(written, want);
        let back = sdo::read(&bus, n5, addr(a), Some(t), Mode::Segmented).expect("read");
        assert_eq!(back, ReadValue::Typed(want), "{a}");
    }
    let r = sdo::read(
        &bus,
        n5,
        addr("0x607A"),
        Some(SdoType::I32),
        Mode::Segmented,
    )
    .unwrap();
    eprintln!("$ canmotion sdo read sim 5 0x607A i32\n{r}");
    assert_eq!(r.to_string(), "-12345 (0xFFFFCFC7)");
    // Untyped: the bytes, as a number with its hex.
    let r = sdo::read(&bus, n5, addr("1000"), None, Mode::Segmented).unwrap();
    eprintln!("$ canmotion sdo read sim 5 1000\n{r}");
    assert_eq!(r, ReadValue::Raw(vec![0x92, 0x01, 0x02, 0x00]));
    assert_eq!(r.to_string(), "131474 (0x00020192)");
    // Segmented upload of a string.
    let r = sdo::read(
        &bus,
        n5,
        addr("1008:00"),
        Some(SdoType::String),
        Mode::Segmented,
    )
    .unwrap();
    eprintln!("$ canmotion sdo read sim 5 1008:00 string\n{r}");
    assert!(
        r.to_string()
            .starts_with("\"canmotion sim servo\" (63 61 6E"),
        "{r}"
    );
    // The other node kept its own value.
    assert_eq!(
        sdo::read(
            &bus,
            Node(2),
            addr("1017"),
            Some(SdoType::U16),
            Mode::Segmented
        )
        .unwrap(),
        ReadValue::Typed(Value::Unsigned16(0))
    );
    // A type of the wrong length is named, not a generic abort.
    let e = sdo::read(&bus, n5, addr("1017"), Some(SdoType::U32), Mode::Segmented).unwrap_err();
    assert_eq!(
        e.to_string(),
        "node 5: SDO 1017:00 answered 2 byte(s), type u32 has 4"
    );
}

#[test]
fn sdo_aborts_name_node_object_and_code() {
    let (bus, _drives) = bus_with(&[5]);
    let e = sdo::write_text(&bus, Node(5), addr("1000"), SdoType::U32, "1").unwrap_err();
    eprintln!("$ canmotion sdo write sim 5 1000 u32 1\ncanmotion: error: {e}");
    assert!(matches!(e, ToolError::Gateway(_)));
    assert_eq!(
        e.to_string(),
        "node 5: SDO 1000:00 aborted with 0x06010002 (attempt to write a read-only object)"
    );
    let e = sdo::read(&bus, Node(5), addr("2345:00"), None, Mode::Segmented).unwrap_err();
    assert_eq!(
        e.to_string(),
        "node 5: SDO 2345:00 aborted with 0x06020000 (object does not exist in the object dictionary)"
    );
    let e = sdo::read(&bus, Node(5), addr("1018:09"), None, Mode::Segmented).unwrap_err();
    assert!(
        e.to_string()
            .contains("0x06090011 (sub-index does not exist)"),
        "{e}"
    );
    let e = sdo::write_text(&bus, Node(5), addr("6040"), SdoType::U32, "6").unwrap_err();
    assert!(e.to_string().contains("aborted with 0x06070010"), "{e}");
    let e = sdo::write_text(&bus, Node(5), addr("6060"), SdoType::I8, "11").unwrap_err();
    assert!(
        e.to_string()
            .contains("SDO 6060:00 aborted with 0x06090031 (value of parameter written too high)"),
        "{e}"
    );
    // Nobody at node 9.
    let e = sdo::read(&bus, Node(9), addr("1000"), None, Mode::Segmented).unwrap_err();
    assert!(
        e.to_string()
            .starts_with("node 9: no answer to SDO 1000:00"),
        "{e}"
    );
    // A value that does not fit its type never reaches the bus.
    let e = sdo::write_text(&bus, Node(5), addr("6040"), SdoType::U16, "70000").unwrap_err();
    assert_eq!(e.to_string(), "value for 6040:00: 70000 does not fit u16");
}

fn heartbeats(lines: &[String], node: u8) -> Vec<String> {
    let tag = format!("heartbeat node {node}: ");
    lines
        .iter()
        .filter_map(|l| l.split_once(&tag).map(|(_, s)| s.to_string()))
        .collect()
}

fn watch(bus: &Bus, ms: u64) -> Vec<String> {
    let mut out = Vec::new();
    let opts = MonitorOptions {
        duration: Some(Duration::from_millis(ms)),
        ..MonitorOptions::default()
    };
    monitor::monitor(bus, &DecodeContext::new(), &opts, &mut out).expect("monitor");
    String::from_utf8(out)
        .unwrap()
        .lines()
        .map(str::to_string)
        .collect()
}

#[test]
fn nmt_start_makes_the_heartbeat_report_operational() {
    let (bus, _drives) = bus_with(&[2, 5]);
    sdo::write_text(&bus, Node(2), addr("1017"), SdoType::U16, "20").unwrap();
    let before = watch(&bus, 100);
    assert_eq!(
        heartbeats(&before, 2).last().map(String::as_str),
        Some("pre-operational"),
        "{before:#?}"
    );

    let f = nmt::send(&bus, NmtCommand::Start, NmtTarget::Node(Node(2))).unwrap();
    eprintln!("$ canmotion nmt sim start 2\nNMT start: node 2 ({f})");
    assert_eq!(f.to_string(), "000#0102");
    let after = watch(&bus, 150);
    eprintln!("$ canmotion monitor --bus sim (150 ms)");
    for l in after.iter().take(3) {
        eprintln!("{l}");
    }
    let hb = heartbeats(&after, 2);
    assert!(hb.len() >= 3, "{after:#?}");
    assert_eq!(hb.last().map(String::as_str), Some("operational"));
    assert!(heartbeats(&after, 5).is_empty(), "node 5 has no heartbeat");

    let nodes = scan::scan(&bus, &ScanOptions::default()).unwrap();
    eprintln!("$ canmotion scan sim\n{}", scan::format_table(&nodes));
    assert_eq!(nodes[0].node, 2);
    assert_eq!(nodes[0].state, Some(NmtState::Operational));
    assert_eq!(nodes[0].heartbeat_ms, Some(20));
    assert_eq!(nodes[1].state, None);

    // Stopped: no SDO answer, still listed from its heartbeat.
    nmt::send(&bus, NmtCommand::Stop, NmtTarget::All).unwrap();
    let nodes = scan::scan(&bus, &ScanOptions::default()).unwrap();
    eprintln!(
        "$ canmotion nmt sim stop all; canmotion scan sim\n{}",
        scan::format_table(&nodes)
    );
    assert_eq!(nodes.len(), 1, "{nodes:?}");
    assert_eq!(nodes[0].node, 2);
    assert_eq!(nodes[0].state, Some(NmtState::Stopped));
    assert!(!nodes[0].answered_sdo);

    // Reset communication: boot-up, then 0x1017 is back to its default (no heartbeat).
    nmt::send(&bus, NmtCommand::PreOperational, NmtTarget::All).unwrap();
    let lines = {
        let b = bus.clone();
        let w = std::thread::spawn(move || watch(&b, 150));
        std::thread::sleep(Duration::from_millis(30));
        nmt::send(&bus, NmtCommand::ResetCommunication, NmtTarget::All).unwrap();
        w.join().unwrap()
    };
    let text = lines.join("\n");
    assert!(
        text.contains("NMT reset communication: all nodes"),
        "{text}"
    );
    assert!(
        text.contains("boot-up node 2") && text.contains("boot-up node 5"),
        "{text}"
    );
}

#[test]
fn live_monitor_decodes_sdo_traffic_with_the_machine() {
    let (bus, _drives) = bus_with(&[1]);
    let ctx = DecodeContext::from_machine(&Machine::demo());
    let b = bus.clone();
    let w = std::thread::spawn(move || {
        let mut out = Vec::new();
        let opts = MonitorOptions {
            count: Some(4),
            duration: Some(Duration::from_secs(5)),
            ..MonitorOptions::default()
        };
        monitor::monitor(&b, &ctx, &opts, &mut out).unwrap();
        String::from_utf8(out).unwrap()
    });
    std::thread::sleep(Duration::from_millis(50));
    sdo::write_text(&bus, Node(1), addr("6040"), SdoType::U16, "6").unwrap();
    sdo::write_text(&bus, Node(1), addr("1000"), SdoType::U32, "0").unwrap_err();
    let text = w.join().unwrap();
    eprintln!(
        "$ canmotion monitor --bus sim --machine dictionaries/machines/demo-xyz.toml\n{text}"
    );
    let decoded: Vec<&str> = text
        .lines()
        .map(|l| &l[l.find(" sim ").unwrap() + 26..])
        .collect();
    assert_eq!(
        decoded,
        vec![
            "SDO node 1 download request 6040:00 Controlword: 06 00 = 6 (0x0006)",
            "SDO node 1 download response 6040:00 Controlword: ok",
            "SDO node 1 download request 1000:00 Device type: 00 00 00 00 = 0 (0x00000000)",
            "SDO node 1 abort by server 1000:00 Device type: 0x06010002 (attempt to write a read-only object)",
        ],
        "{text}"
    );
}

/// A recorded start-up and two cycles of axis X (node 1) as `candump -L vcan0` writes them.
const RECORDED: &str = "\
(1700000000.000000) vcan0 701#00
(1700000000.010000) vcan0 601#4000100000000000
(1700000000.010250) vcan0 581#4300100092010200
(1700000000.011000) vcan0 601#2B17100064000000
(1700000000.011250) vcan0 581#6017100000000000
(1700000000.012000) vcan0 601#2F60600007000000
(1700000000.012250) vcan0 581#8060600022000008
(1700000000.020000) vcan0 000#0100
(1700000000.120000) vcan0 701#05
(1700000000.200000) vcan0 201#1F0050C30000
(1700000000.200100) vcan0 080#
(1700000000.200400) vcan0 181#3716E8030000
(1700000000.204000) vcan0 201#1F0051C30000
(1700000000.204100) vcan0 080#02
(1700000000.204400) vcan0 181#3736E9030000
(1700000000.205000) vcan0 081#1186210000000000
(1700000000.206000) vcan0 182#0102
(1700000000.207000) vcan0 123#DEADBEEF
";

const DECODED: &[&str] = &[
    "(1700000000.000000) vcan0 701#00               boot-up node 1",
    "(1700000000.010000) vcan0 601#4000100000000000 SDO node 1 upload request 1000:00 Device type",
    "(1700000000.010250) vcan0 581#4300100092010200 SDO node 1 upload response 1000:00 Device type: 92 01 02 00 = 131474 (0x00020192)",
    "(1700000000.011000) vcan0 601#2B17100064000000 SDO node 1 download request 1017:00 Producer heartbeat time: 64 00 = 100 (0x0064)",
    "(1700000000.011250) vcan0 581#6017100000000000 SDO node 1 download response 1017:00 Producer heartbeat time: ok",
    "(1700000000.012000) vcan0 601#2F60600007000000 SDO node 1 download request 6060:00 Modes of operation: 07 = 7 (0x07)",
    "(1700000000.012250) vcan0 581#8060600022000008 SDO node 1 abort by server 6060:00 Modes of operation: 0x08000022 (data cannot be transferred or stored because of the present device state)",
    "(1700000000.020000) vcan0 000#0100             NMT start: all nodes",
    "(1700000000.120000) vcan0 701#05               heartbeat node 1: operational",
    "(1700000000.200000) vcan0 201#1F0050C30000     RPDO1 node 1 (axis X): controlword 0x001F Enable operation, enable IP (bit 4); IP setpoint 50000 counts (50.000 mm)",
    "(1700000000.200100) vcan0 080#                 SYNC",
    "(1700000000.200400) vcan0 181#3716E8030000     TPDO1 node 1 (axis X): statusword 0x1637 Operation enabled, target reached, IP active; position actual 1000 counts (1.000 mm)",
    "(1700000000.204000) vcan0 201#1F0051C30000     RPDO1 node 1 (axis X): controlword 0x001F Enable operation, enable IP (bit 4); IP setpoint 50001 counts (50.001 mm)",
    "(1700000000.204100) vcan0 080#02               SYNC counter 2",
    "(1700000000.204400) vcan0 181#3736E9030000     TPDO1 node 1 (axis X): statusword 0x3637 Operation enabled, target reached, IP active, bit 13; position actual 1001 counts (1.001 mm)",
    "(1700000000.205000) vcan0 081#1186210000000000 EMCY node 1: 0x8611 following error, error register 0x21",
    "(1700000000.206000) vcan0 182#0102             TPDO1 node 2 (axis Y): statusword 0x0201 (no valid state) [2 bytes, the mapping has 6 (drives answer EMCY 0x8210)]",
    "(1700000000.207000) vcan0 123#DEADBEEF         unknown COB-ID 0x123: DE AD BE EF",
];

#[test]
fn monitor_replays_a_recorded_log() {
    let dir = tempfile::tempdir().unwrap();
    let rec = dir.path().join("startup.log");
    std::fs::write(&rec, RECORDED).unwrap();
    let again = dir.path().join("again.log");
    let ctx = DecodeContext::from_machine(&Machine::demo());
    let mut out = Vec::new();
    let opts = MonitorOptions {
        log: Some(again.clone()),
        ..MonitorOptions::default()
    };
    let n = monitor::replay(&rec, &ctx, &opts, &mut out).unwrap();
    let text = String::from_utf8(out).unwrap();
    eprintln!(
        "$ canmotion monitor --replay startup.log --machine dictionaries/machines/demo-xyz.toml\n{text}"
    );
    assert_eq!(n, DECODED.len() as u64);
    assert_eq!(text.lines().collect::<Vec<_>>(), DECODED);
    // --log writes the same candump log back.
    assert_eq!(std::fs::read_to_string(&again).unwrap(), RECORDED);
    // Without a machine, PDOs are raw by COB-ID range and SDO objects unnamed.
    let raw = monitor::decode_log("startup.log", RECORDED, &DecodeContext::new()).unwrap();
    assert!(
        raw[9].ends_with("RPDO1 node 1: 1F 00 50 C3 00 00"),
        "{}",
        raw[9]
    );
    assert!(raw[3].ends_with("SDO node 1 download request 1017:00: 64 00 = 100 (0x0064)"));
}

#[test]
fn a_malformed_log_line_names_file_and_line() {
    let e = monitor::decode_log(
        "bad.log",
        "(1700000000.000000) vcan0 701#00\n(1700000000.1) vcan0 701\n",
        &DecodeContext::new(),
    )
    .unwrap_err();
    assert_eq!(
        e.to_string(),
        "bad.log:2: expected a frame like 181#3716E803, found \"701\""
    );
}

// ---- the command line ----

fn canmotion(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_canmotion"))
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .expect("run canmotion")
}

fn stderr(o: &std::process::Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

#[test]
fn cli_argument_errors_exit_non_zero_with_a_usage_message() {
    for (args, why) in [
        (
            &["sdo", "write", "vcan0", "1", "0x6040", "u16"][..],
            "<VALUE>",
        ),
        (&["sdo", "read", "vcan0", "1"][..], "<INDEX[:SUB]>"),
        (
            &["sdo", "read", "vcan0", "0", "0x6040"][..],
            "outside 1..=127",
        ),
        (
            &["sdo", "read", "vcan0", "1", "0x6040:zz"][..],
            "not an object address",
        ),
        (
            &["sdo", "read", "vcan0", "1", "6040", "u128"][..],
            "unknown type",
        ),
        (&["nmt", "vcan0", "go", "1"][..], "unknown NMT command"),
        (&["nmt", "vcan0", "start", "200"][..], "outside 1..=127"),
        (&["nmt", "vcan0", "start"][..], "<NODE|all>"),
        (&["scan"][..], "<IFACE>"),
        (
            &["scan", "vcan0", "--timeout-ms", "soon"][..],
            "invalid value",
        ),
        (&["monitor"][..], "--bus"),
        (
            &["monitor", "--bus", "vcan0", "--replay", "x.log"][..],
            "cannot be used with",
        ),
    ] {
        let o = canmotion(args);
        let e = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {e}");
        assert!(e.starts_with("error: "), "{args:?}: {e}");
        // A missing or conflicting argument shows the usage line; an invalid value points
        // at --help after saying what is wrong with it.
        assert!(
            e.contains("Usage: canmotion") || e.contains("try '--help'"),
            "{args:?}: {e}"
        );
        assert!(e.contains(why), "{args:?}: {e}");
    }
    let e = stderr(&canmotion(&["sdo", "write", "vcan0", "1", "0x6040", "u16"]));
    assert!(
        e.contains("Usage: canmotion sdo write <IFACE> <NODE> <INDEX[:SUB]> <TYPE> <VALUE>"),
        "{e}"
    );
}

#[test]
fn cli_value_and_replay_errors_exit_1() {
    let o = canmotion(&["sdo", "write", "sim", "1", "6040", "u16", "70000"]);
    assert_eq!(o.status.code(), Some(1));
    assert_eq!(
        stderr(&o).trim(),
        "canmotion: error: value for 6040:00: 70000 does not fit u16"
    );
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("bad.log");
    std::fs::write(&bad, "(1.000000) vcan0 080#\n(2.000000) vcan0 080#1\n").unwrap();
    let o = canmotion(&["monitor", "--replay", bad.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o).contains(&format!("{}:2: frame \"080#1\": odd number", bad.display())),
        "{}",
        stderr(&o)
    );
    assert_eq!(
        String::from_utf8_lossy(&o.stdout).trim(),
        "(1.000000) vcan0 080#                 SYNC"
    );
}

#[test]
fn cli_replays_with_the_machine_file() {
    let dir = tempfile::tempdir().unwrap();
    let rec = dir.path().join("startup.log");
    std::fs::write(&rec, RECORDED).unwrap();
    let o = canmotion(&[
        "monitor",
        "--replay",
        rec.to_str().unwrap(),
        "--machine",
        "dictionaries/machines/demo-xyz.toml",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    assert_eq!(out.lines().collect::<Vec<_>>(), DECODED);
    let o = canmotion(&["monitor", "--replay", rec.to_str().unwrap(), "--count", "2"]);
    assert_eq!(String::from_utf8_lossy(&o.stdout).lines().count(), 2);
}

/// Issue 13, defect 3: SDO transfers of any length. A drive dictionary with a 1000-byte DOMAIN
/// and a 34-byte device name; `NodeIo` downloads and uploads them segmented and block against
/// the simulated drive, and `sdo read` returns the name whole (canopen-rs's client stopped at
/// 32 bytes and reported that as the node's abort).
#[test]
fn sdo_transfers_of_any_length_segmented_and_block() {
    use canmotion::canopen::sdo_client::Mode;
    use canmotion::gateway::io::NodeIo;
    let name = "canmotion simulated servo, 34 byte";
    assert_eq!(name.len(), 34);
    let text = canmotion::config::machine::DEMO_DRIVE.replace(
        "default = \"canmotion sim servo\"",
        &format!("default = {name:?}"),
    ) + "\n[[object]]\nindex = 0x2000\nname = \"Data block\"\ntype = \"domain\"\naccess = \"rw\"\ndefault = \"\"\n";
    let d = Arc::new(DriveDictionary::parse(Path::new("long.toml"), &text).expect("dictionary"));
    let bus = Bus::InProc(InProcBus::new());
    let mut bootups = bus.open(&[Filter::exact(0x705)]).unwrap();
    let _drives = runner::spawn(&bus, vec![SimDrive::new(d, 5)]).expect("spawn");
    bootups
        .recv_timeout(Duration::from_secs(5))
        .unwrap()
        .expect("boot-up within 5 s");
    let r = sdo::read(
        &bus,
        Node(5),
        addr("1008"),
        Some(SdoType::String),
        Mode::Segmented,
    )
    .expect("a 34-byte name");
    assert_eq!(r, ReadValue::Text(name.as_bytes().to_vec()));
    let r = sdo::read(
        &bus,
        Node(5),
        addr("1008"),
        Some(SdoType::String),
        Mode::Block,
    )
    .expect("a 34-byte name, block");
    assert_eq!(r, ReadValue::Text(name.as_bytes().to_vec()));
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    rt.block_on(async {
        let io = NodeIo::start(&bus, &[5]).unwrap();
        for (i, mode) in [Mode::Segmented, Mode::Block].into_iter().enumerate() {
            let data: Vec<u8> = (0..1000).map(|k| (k * 13 + i * 7) as u8).collect();
            io.download(5, 0x2000, 0, &data, mode)
                .await
                .expect("download");
            for up in [Mode::Segmented, Mode::Block] {
                assert_eq!(
                    io.upload_with(5, 0x2000, 0, up).await.expect("upload"),
                    data,
                    "down {mode:?}, up {up:?}"
                );
            }
        }
        // Beyond what the drive keeps (64 KiB): the node's abort, named as such.
        let big = vec![0u8; canmotion::canopen::MAX_OBJECT_BYTES + 1];
        match io.download(5, 0x2000, 0, &big, Mode::Segmented).await {
            Err(canmotion::gateway::GatewayError::SdoAbort { node: 5, code, .. }) => {
                assert_eq!(code, canmotion::canopen::AbortCode::LENGTH_TOO_HIGH)
            }
            other => panic!("{other:?}"),
        }
    });
}
