//! `canmotion serve` on vcan0: the service and the simulated drives as separate processes, the
//! session through the control socket (enable, home all in order, a dead-man jog, an
//! incremental jog, MDI then a program, SIGTERM's orderly end), the setpoints within the limits.

use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use super::serve_rig::Client;
use super::{BIN, IFACE, ROOT, lock, simdrive_with};
use canmotion::config::Machine;

/// The demo machine's switches for `simdrive` (counts): X and Y at -2 mm, Z at 2 mm.
const SWITCHES: [&str; 6] = [
    "--home-switch",
    "1:-2000",
    "--home-switch",
    "2:-2000",
    "--home-switch",
    "3:4000",
];

/// The demo machine file.
fn machine_file() -> String {
    format!("{ROOT}/dictionaries/machines/demo-xyz.toml")
}

/// `canmotion serve` on vcan0 with the demo machine, its socket (and its CSV log, `serve.csv`,
/// with `log`) in a new temporary folder; a client connected to it.
fn start_serve(log: bool) -> (tempfile::TempDir, std::process::Child, Client) {
    let dir = tempfile::tempdir().unwrap();
    let sock = dir.path().join("cm.sock");
    let mut cmd = Command::new(BIN);
    cmd.current_dir(ROOT)
        .args([
            "serve",
            "--bus",
            IFACE,
            "--machine",
            &machine_file(),
            "--control",
        ])
        .arg(&sock);
    if log {
        cmd.arg("--log").arg(dir.path().join("serve.csv"));
    }
    let service = cmd
        .stdout(Stdio::null())
        .stderr(Stdio::inherit())
        .spawn()
        .expect("start canmotion serve");
    let c = Client::connect(&sock, Duration::from_secs(20));
    (dir, service, c)
}

/// Waits (10 s at most) for the service's exit; it must be a success.
fn ended_in_order(service: &mut std::process::Child) {
    let deadline = Instant::now() + Duration::from_secs(10);
    let code = loop {
        if let Some(st) = service.try_wait().unwrap() {
            break st;
        }
        assert!(Instant::now() < deadline, "serve did not end");
        std::thread::sleep(Duration::from_millis(20));
    };
    assert!(code.success(), "serve ended with {code}");
}

#[test]
fn vcan0_serve_homes_jogs_runs_mdi_then_a_program_and_ends_in_order_on_sigterm() {
    let _g = lock();
    let _drives = simdrive_with(&[1, 2, 3], None, &SWITCHES);
    let (dir, mut service, mut c) = start_serve(true);
    let csv = dir.path().join("serve.csv");
    let m = Machine::load(std::path::Path::new(&machine_file())).unwrap();
    let status = |c: &mut Client| c.status();
    assert_eq!(status(&mut c)["state"], "disabled");
    c.ok("enable");
    let a = c.cmd(&format!("run {ROOT}/tests/programs/square.ngc"));
    assert!(a.contains("axis X is not homed"), "{a}");
    let a = c.ok("home all");
    assert_eq!(a, "ok homed X Y Z");
    let s = status(&mut c);
    for (i, offset) in [(0, -2.0), (1, -2.0), (2, 2.0)] {
        let act = s["axes"][i]["actual_mm"].as_f64().unwrap();
        assert!(
            (act - offset).abs() <= 1.0 / m.axes[i].counts_per_mm,
            "axis {i} at {act} after homing: {s}"
        );
    }
    let homed_cycle = s["cycle"].as_f64().unwrap();
    // A jog nobody repeats stops by the dead-man within its time-out and the stop.
    let t0 = Instant::now();
    c.ok("jog X 10");
    c.wait_state("idle", Duration::from_secs(5));
    let took = t0.elapsed().as_secs_f64();
    assert!((0.5..2.5).contains(&took), "the jog took {took} s");
    // An incremental jog, to within one count.
    let y0 = status(&mut c)["axes"][1]["commanded_mm"].as_f64().unwrap();
    c.ok("jog Y 5 1.5");
    let deadline = Instant::now() + Duration::from_secs(5);
    loop {
        let s = status(&mut c);
        let act = s["axes"][1]["actual_mm"].as_f64().unwrap();
        if s["state"] == "idle" && ((act - (y0 + 1.5)) * 1000.0).abs() <= 1.0 {
            break;
        }
        assert!(Instant::now() < deadline, "{s}");
        std::thread::sleep(Duration::from_millis(20));
    }
    c.ok("mdi G0 X10 Y10");
    c.ok(&format!("run {ROOT}/tests/programs/square.ngc"));
    let deadline = Instant::now() + Duration::from_secs(30);
    loop {
        let s = status(&mut c);
        if s["state"] == "idle" {
            let x = s["axes"][0]["actual_mm"].as_f64().unwrap();
            assert!((x - 15.0).abs() <= 0.002, "{s}");
            break;
        }
        assert!(s["alarm"].is_null(), "{s}");
        assert!(Instant::now() < deadline, "{s}");
        std::thread::sleep(Duration::from_millis(20));
    }
    // SIGTERM: the orderly end.
    let pid = service.id() as i32;
    unsafe {
        libc::kill(pid, libc::SIGTERM);
    }
    ended_in_order(&mut service);
    // Every setpoint from the end of homing on within the limits.
    let rows = super::common::read_csv(&csv);
    let rows: Vec<Vec<f64>> = rows.into_iter().filter(|r| r[0] >= homed_cycle).collect();
    assert!(rows.len() > 100);
    super::common::limits_held_rows(&m, &rows);
}

#[test]
fn vcan0_serve_reports_a_homing_error_with_its_node_and_aborts_a_program_on_its_path() {
    let _g = lock();
    // X's drive has no home switch; Y's and Z's have.
    let _drives = simdrive_with(&[1, 2, 3], None, &SWITCHES[2..]);
    let (dir, mut service, mut c) = start_serve(false);
    c.ok("enable");
    let a = c.cmd("home X");
    assert!(
        a.starts_with("error: axis X (node 1): homing error")
            && a.contains("home switch was not found"),
        "{a}"
    );
    let s = c.status();
    assert_eq!(s["state"], "idle", "{s}");
    assert_eq!(s["axes"][0]["control"], "cyclic", "{s}");
    c.ok("home Y Z");
    // The failed search left X at or past its negative limit, where a program's lines would end
    // outside the travel. A jog of the unhomed axis (reduced speed, no travel check) brings it
    // in.
    let x = c.status()["axes"][0]["commanded_mm"].as_f64().unwrap();
    assert!(x <= -4.9, "X at {x}");
    c.ok("jog X 5 3");
    let deadline = Instant::now() + Duration::from_secs(5);
    loop {
        let s = c.status();
        let x1 = s["axes"][0]["actual_mm"].as_f64().unwrap();
        if s["state"] == "idle" && ((x1 - (x + 3.0)) * 1000.0).abs() <= 1.5 {
            break;
        }
        assert!(Instant::now() < deadline, "{s}");
        std::thread::sleep(Duration::from_millis(20));
    }
    let prog = dir.path().join("long.ngc");
    std::fs::write(&prog, "G21 G90\nG1 Y150 F3000\nM2\n").unwrap();
    c.ok(&format!("run {}", prog.display()));
    let deadline = Instant::now() + Duration::from_secs(5);
    while c.status()["program"].is_null() {
        assert!(Instant::now() < deadline);
        std::thread::sleep(Duration::from_millis(10));
    }
    std::thread::sleep(Duration::from_millis(500));
    c.ok("abort");
    let s = c.wait_state("idle", Duration::from_secs(5));
    let y = s["axes"][1]["commanded_mm"].as_f64().unwrap();
    assert!(y > 0.0 && y < 149.0, "{s}");
    assert!(s["alarm"].is_null(), "{s}");
    assert_eq!(c.cmd("quit"), "ok bye");
    ended_in_order(&mut service);
}

#[test]
fn vcan0_serve_stays_up_in_alarm_after_a_drive_fault_and_works_again_after_reset() {
    let _g = lock();
    // Y's drive faults once (EMCY 0x2310), 5 s after it first followed setpoints.
    let mut args = SWITCHES.to_vec();
    args.extend(["--inject", "2:fault@5s"]);
    let _drives = simdrive_with(&[1, 2, 3], None, &args);
    let (dir, mut service, mut c) = start_serve(false);
    c.ok("enable");
    c.ok("home all");
    let prog = dir.path().join("long.ngc");
    std::fs::write(&prog, "G21 G90\nG1 X150 Y150 F1200\nM2\n").unwrap();
    c.ok(&format!("run {}", prog.display()));
    let s = c.wait_state("alarm", Duration::from_secs(15));
    assert_eq!(s["alarm"]["node"], 2, "{s}");
    assert!(
        s["alarm"]["kind"] == "Emcy" || s["alarm"]["kind"] == "DriveFault",
        "{s}"
    );
    let a = c.cmd(&format!("run {}", prog.display()));
    assert!(a.starts_with("error: alarm"), "{a}");
    let deadline = Instant::now() + Duration::from_secs(5);
    while c.status()["phase"] != "Disabled" {
        assert!(Instant::now() < deadline, "{}", c.status());
        std::thread::sleep(Duration::from_millis(20));
    }
    let a = c.ok("reset");
    assert!(a.contains("enabled"), "{a}");
    let a = c.cmd("mdi G0 Y10");
    assert!(a.contains("is not homed"), "{a}");
    c.ok("home all");
    c.ok("mdi G0 X10 Y10");
    let deadline = Instant::now() + Duration::from_secs(10);
    loop {
        let s = c.status();
        if s["state"] == "idle"
            && (s["axes"][1]["actual_mm"].as_f64().unwrap() - 10.0).abs() < 0.002
        {
            break;
        }
        assert!(s["alarm"].is_null(), "{s}");
        assert!(Instant::now() < deadline, "{s}");
        std::thread::sleep(Duration::from_millis(20));
    }
    assert_eq!(c.cmd("quit"), "ok bye");
    ended_in_order(&mut service);
}
