//! `canmotion serve` on the in-process bus, every scenario through its control socket: enable,
//! home (order, statusword bits 10 and 12, the home offset), jogs (the dead-man, the increment),
//! MDI then a program with no second start-up, abort on the path, a drive that resets and a
//! drive fault (alarm, reset, home, run again), a homing error, a program on an axis that is not
//! homed, and `status`/`watch` as JSON. The setpoints of every scenario keep the axis limits
//! (finite differences), across every change of mode. The same session runs on vcan0 in
//! tests/vcan/serve.rs.

mod common;
#[path = "common/serve.rs"]
mod serve_rig;

use std::time::{Duration, Instant};

use canmotion::config::Machine;
use canmotion::interpolator::OverrideRamp;
use canmotion::sim::{Inject, Targeted};
use common::*;
use serve_rig::{Client, Service, axis};

/// The demo machine with the homing and simulator tables of these tests: Z homes first on the
/// current position (offset -1 mm), X and Y together on home switches found from non-zero start
/// positions, with offsets.
fn machine() -> Machine {
    common::machine(serve_tables)
}

/// The machine file text with the tables of [`machine`].
fn serve_tables(text: String) -> String {
    let homing = |order: u32, method: &str, offset: f64, switch: Option<f64>, start: f64| {
        format!(
            "\n[axis.homing]\nmethod = {method}\nspeed_search_mm_s = 40.0\nspeed_zero_mm_s = 4.0\nacc_mm_s2 = 800.0\noffset_mm = {offset}\norder = {order}\ntimeout_ms = 10000\n\n[axis.sim]\nstart_mm = {start}\n{}\n",
            switch.map_or(String::new(), |s| format!("home_switch_mm = {s}"))
        )
    };
    let mut out = String::new();
    let mut axis = 0;
    for block in strip_tables(&text).split("\n[[axis]]\n") {
        if !out.is_empty() {
            out.push_str("\n[[axis]]\n");
            out.push_str(block.trim_end());
            out.push_str(&match axis {
                0 => homing(1, "21", 0.0, Some(-2.0), 6.0),
                1 => homing(1, "19", 5.0, Some(20.0), 12.0),
                _ => homing(0, "\"current\"", -1.0, None, -3.0),
            });
            axis += 1;
        } else {
            out.push_str(block);
        }
    }
    out
}

/// The machine file without any `[axis.homing]` or `[axis.sim]` table it has already.
fn strip_tables(text: &str) -> String {
    let mut out = String::new();
    let mut skipping = false;
    for line in text.lines() {
        let t = line.trim();
        if t.starts_with('[') {
            skipping = t == "[axis.homing]" || t == "[axis.sim]";
        }
        if !skipping {
            out.push_str(line);
            out.push('\n');
        }
    }
    out
}

/// The setpoints of the log from `from_cycle` on keep every axis's limits.
fn limits_from(m: &Machine, log: &std::path::Path, from_cycle: f64) {
    let rows: Vec<Vec<f64>> = read_csv(log)
        .into_iter()
        .filter(|r| r[0] >= from_cycle)
        .collect();
    limits_held_rows(m, &rows);
}

fn cycle(s: &serde_json::Value) -> f64 {
    s["cycle"].as_f64().unwrap()
}

fn actual(s: &serde_json::Value, i: usize) -> f64 {
    axis(s, i)["actual_mm"].as_f64().unwrap()
}

fn commanded(s: &serde_json::Value, i: usize) -> f64 {
    axis(s, i)["commanded_mm"].as_f64().unwrap()
}

/// Waits until every axis stands within one count of its setpoint.
fn settled(c: &mut Client, m: &Machine) -> serde_json::Value {
    let deadline = Instant::now() + Duration::from_secs(10);
    loop {
        let s = c.status();
        if s["state"] == "idle"
            && m.axes
                .iter()
                .enumerate()
                .all(|(i, a)| (actual(&s, i) - commanded(&s, i)).abs() <= 1.0 / a.counts_per_mm)
        {
            return s;
        }
        assert!(Instant::now() < deadline, "not settled: {s}");
        std::thread::sleep(Duration::from_millis(10));
    }
}

const SDO_RX: u16 = 0x600;

/// The SDO writes of 0x6060 (mode of operation) in the recorded frames: (time, node, mode).
fn mode_writes(frames: &[(u64, canmotion::bus::Frame)]) -> Vec<(u64, u8, i8)> {
    frames
        .iter()
        .filter_map(|(t, f)| {
            let d = f.data();
            let node = f
                .id()
                .checked_sub(SDO_RX)
                .filter(|n| (1..=127).contains(n))?;
            (d.len() == 8 && d[0] & 0xE0 == 0x20 && d[1] == 0x60 && d[2] == 0x60)
                .then(|| (*t, node as u8, d[4] as i8))
        })
        .collect()
}

#[test]
fn a_session_enables_homes_in_order_jogs_runs_mdi_then_a_program_without_a_second_start_up() {
    let _one = one_at_a_time();
    let m = machine();
    let mut svc = Service::start(&m, Vec::new());
    let mut c = svc.client();
    let recorder = Recorder::start(&svc.bus);
    let s = c.status();
    assert_eq!(s["state"], "disabled", "{s}");
    // Nothing moves while disabled, and nothing on an axis that is not homed.
    let a = c.cmd("mdi G0 X1");
    assert!(a.starts_with("error: ") && a.contains("disabled"), "{a}");
    c.ok("enable");
    let enabled = c.status();
    let a = c.cmd("mdi G0 X1");
    assert!(a.starts_with("error: MDI:1: axis X is not homed"), "{a}");
    let part = svc.file("part.ngc", "G21 G90\nG1 X30 Y20 F3000\nG1 Z-2 F600\nM2\n");
    let a = c.cmd(&format!("run {}", part.display()));
    assert!(a.contains("axis X is not homed"), "{a}");

    // Home all: Z (order 0) first, then X and Y together.
    let before_home = c.status();
    assert!(
        (actual(&before_home, 0) - 6.0).abs() < 1e-3,
        "{before_home}"
    );
    let a = c.ok("home all");
    assert_eq!(a, "ok homed X Y Z");
    let homed = c.status();
    let after_home_cycle = cycle(&homed);
    for (i, offset) in [(0, 0.0), (1, 5.0), (2, -1.0)] {
        assert_eq!(axis(&homed, i)["homed"], true, "{homed}");
        assert!(
            (actual(&homed, i) - offset).abs() <= 1.0 / m.axes[i].counts_per_mm,
            "axis {i} at {} after homing, offset {offset}",
            actual(&homed, i)
        );
        assert_eq!(axis(&homed, i)["control"], "cyclic");
    }
    assert_eq!(homed["state"], "idle");

    // A continuous jog that nobody repeats stops by the dead-man.
    let jog_start = c.status();
    let x0 = commanded(&jog_start, 0);
    let t0 = Instant::now();
    let a = c.ok("jog X 20");
    assert!(a.contains("jogging X"), "{a}");
    let s = c.wait_state("idle", Duration::from_secs(5));
    let took = t0.elapsed().as_secs_f64();
    // Jogs run the jerk-limited profile whatever the machine's planner mode.
    let mut jog_config = m.planner;
    jog_config.profile = canmotion::planner::ProfileKind::SCurve;
    let ramp = OverrideRamp::for_machine(&canmotion::gateway::limits(&m), &jog_config).unwrap();
    let stop_s = ramp.ramp_time_s(1.0, 0.0);
    let timeout_s = f64::from(m.operation.jog_timeout_ms) / 1000.0;
    let travelled = commanded(&s, 0) - x0;
    assert!(travelled > 0.0, "{travelled}");
    assert!(
        travelled <= 20.0 * (timeout_s + 0.05) + 20.0 * stop_s,
        "jog went {travelled} mm: over the dead-man time plus the stopping distance"
    );
    assert!(
        took >= timeout_s && took <= timeout_s + stop_s + 0.5,
        "the jog stopped {took} s after it started (time-out {timeout_s} s)"
    );

    // Jerk-limited, by finite differences of the setpoints it streamed.
    jerk_within(&m, &svc.log, cycle(&jog_start), cycle(&s));

    // An incremental jog, to within one count.
    let y0 = commanded(&c.status(), 1);
    c.ok("jog Y 10 2.5");
    let s = settled(&mut c, &m);
    let counts = |mm: f64| (mm * 1000.0).round() as i64;
    assert!((counts(actual(&s, 1)) - counts(y0 + 2.5)).abs() <= 1, "{s}");

    // MDI, then a program: the drives stay enabled between the two.
    let a = c.ok("mdi G0 X10 Y10");
    assert!(a.starts_with("ok queued MDI"), "{a}");
    let s = settled(&mut c, &m);
    assert!((actual(&s, 0) - 10.0).abs() <= 1e-3 && (actual(&s, 1) - 10.0).abs() <= 1e-3);
    let a = c.ok(&format!("run {}", part.display()));
    assert!(a.starts_with("ok queued"), "{a}");
    let deadline = Instant::now() + Duration::from_secs(2);
    loop {
        let s = c.status();
        if s["program"] == part.display().to_string() {
            assert_eq!(s["state"], "running", "{s}");
            break;
        }
        assert!(Instant::now() < deadline, "the program did not start: {s}");
        std::thread::sleep(Duration::from_millis(5));
    }
    let s = settled(&mut c, &m);
    assert!((actual(&s, 0) - 30.0).abs() <= 1e-3, "{s}");
    assert!((actual(&s, 2) + 2.0).abs() <= 1e-3, "{s}");
    // The modal state carried from the program (its M2 reset to G90, G54 and G17).
    assert!(s["modal"].as_str().unwrap().contains("G90"), "{s}");

    // Valid JSON on watch too.
    let mut w = svc.client();
    writeln_watch(&mut w);
    for _ in 0..3 {
        let l = w.line();
        let json: serde_json::Value = serde_json::from_str(l.strip_prefix("ok ").unwrap()).unwrap();
        assert_eq!(json["state"], "idle");
        assert_eq!(json["axes"].as_array().unwrap().len(), 3);
    }
    drop(w);
    svc.quit().unwrap();
    let frames = recorder.stop();

    // One start-up: one NMT reset per node (or one broadcast), and one boot-up each.
    let resets = frames
        .iter()
        .filter(|(_, f)| f.id() == 0 && f.data().first() == Some(&0x81))
        .count();
    assert!(resets <= 3, "{resets} NMT resets during the session");
    let boots = frames
        .iter()
        .filter(|(_, f)| (0x701..=0x77F).contains(&f.id()) && f.data() == [0])
        .count();
    assert_eq!(boots, 0, "a drive booted again during the session");
    // Homing in order: Z in mode 6 (and back) before X and Y; X and Y together.
    let modes = mode_writes(&frames);
    let at = |node: u8, mode: i8| {
        modes
            .iter()
            .find(|(_, n, md)| *n == node && *md == mode)
            .unwrap_or_else(|| panic!("no 0x6060 = {mode} to node {node}: {modes:?}"))
            .0
    };
    assert!(at(3, 7) < at(1, 6) && at(3, 7) < at(2, 6), "{modes:?}");
    assert!(at(1, 6) < at(2, 7) && at(2, 6) < at(1, 7), "{modes:?}");
    // Statusword bits 10 and 12 seen from every homed drive while in mode 6.
    for node in 1..=3u8 {
        let (from, to) = (at(node, 6), at(node, 7));
        let seen = frames.iter().any(|(t, f)| {
            *t > from
                && *t < to
                && f.id() == 0x180 + u16::from(node)
                && f.data().len() >= 2
                && u16::from_le_bytes([f.data()[0], f.data()[1]]) & 0x1400 == 0x1400
        });
        assert!(
            seen,
            "node {node}: no statusword with bits 10 and 12 while homing"
        );
    }
    // Every setpoint within the limits: before homing, and from its end through jogs, MDI and
    // the program (homing re-references position actual, which the setpoint follows).
    let rows = read_csv(&svc.log);
    assert!(rows.len() > 100);
    limits_from(&m, &svc.log, after_home_cycle);
    // Homing to cyclic without a jump: from the drive's re-referencing of position actual (the
    // one step of the homing, a change of coordinates) on, each homed axis's setpoints keep its
    // limits through the end of homing and the return to the cyclic mode.
    let homing_rows: Vec<Vec<f64>> = rows
        .iter()
        .filter(|r| r[0] >= cycle(&before_home) && r[0] <= after_home_cycle)
        .cloned()
        .collect();
    let t = m.cycle_s();
    for (i, a) in m.axes.iter().enumerate() {
        let step = |k: usize| (homing_rows[k + 1][2 + i] - homing_rows[k][2 + i]).abs();
        let reref = (0..homing_rows.len() - 1)
            .filter(|k| step(*k) > a.max_vel_mm_s * t)
            .max()
            .unwrap_or(0);
        for w in homing_rows[reref + 1..].windows(3) {
            let v = (w[2][2 + i] - w[1][2 + i]) / t;
            let acc = (w[2][2 + i] - 2.0 * w[1][2 + i] + w[0][2 + i]) / (t * t);
            assert!(v.abs() <= a.max_vel_mm_s * 1.01, "{} homing: {v}", a.name);
            assert!(
                acc.abs() <= a.max_acc_mm_s2 * 1.01,
                "{} homing: {acc}",
                a.name
            );
        }
    }
    limits_from_to(
        &m,
        &rows
            .iter()
            .filter(|r| r[0] >= cycle(&enabled))
            .cloned()
            .collect::<Vec<_>>(),
        cycle(&before_home),
    );
}

/// Every axis's jerk within its limit (1 %) over the log's cycles `from..=to`.
fn jerk_within(m: &Machine, log: &std::path::Path, from: f64, to: f64) {
    let rows: Vec<Vec<f64>> = read_csv(log)
        .into_iter()
        .filter(|r| r[0] >= from && r[0] <= to)
        .collect();
    let t = m.cycle_s();
    for w in rows.windows(4) {
        for (i, a) in m.axes.iter().enumerate() {
            let p = |k: usize| w[k][2 + i];
            let jerk = (p(3) - 3.0 * p(2) + 3.0 * p(1) - p(0)) / (t * t * t);
            assert!(
                jerk.abs() <= a.max_jerk_mm_s3 * 1.01,
                "axis {} at cycle {}: jerk {jerk} mm/s³",
                a.name,
                w[3][0]
            );
        }
    }
}

fn writeln_watch(c: &mut Client) {
    let first = c.cmd("watch 20");
    let json: serde_json::Value = serde_json::from_str(first.strip_prefix("ok ").unwrap()).unwrap();
    assert!(json["cycle"].as_u64().is_some());
}

fn limits_from_to(m: &Machine, rows: &[Vec<f64>], to_cycle: f64) {
    let rows: Vec<Vec<f64>> = rows.iter().filter(|r| r[0] <= to_cycle).cloned().collect();
    limits_held_rows(m, &rows);
}

#[test]
fn abort_stops_a_program_on_its_path_and_keeps_the_drives_enabled() {
    let _one = one_at_a_time();
    let m = machine();
    let mut svc = Service::start(&m, Vec::new());
    let mut c = svc.client();
    c.ok("enable");
    c.ok("home all");
    let start = c.status();
    let (x0, y0) = (commanded(&start, 0), commanded(&start, 1));
    let long = svc.file("long.ngc", "G21 G90\nG1 X150 Y150 F8485\nM2\n");
    c.ok(&format!("run {}", long.display()));
    c.wait_state("running", Duration::from_secs(2));
    std::thread::sleep(Duration::from_millis(400));
    c.ok("abort");
    let s = settled(&mut c, &m);
    assert!(s["alarm"].is_null(), "{s}");
    let x = actual(&s, 0);
    assert!(x > x0 + 1.0 && x < 149.0, "stopped at X {x}");
    // On the path: every setpoint on the line from the start to (150, 150).
    let dir = nalgebra::Vector2::new(150.0 - x0, 150.0 - y0).normalize();
    for r in read_csv(&svc.log).iter().filter(|r| r[0] >= cycle(&start)) {
        let p = nalgebra::Vector2::new(r[2] - x0, r[3] - y0);
        let off = (p - dir * p.dot(&dir)).norm();
        assert!(off < 1e-6, "cycle {}: {off} mm off the path", r[0]);
    }
    limits_from(&m, &svc.log, cycle(&start));
    // Still enabled: the next job runs.
    c.ok("mdi G0 X20 Y20");
    let s = settled(&mut c, &m);
    assert!((actual(&s, 0) - 20.0).abs() <= 1e-3, "{s}");
    svc.quit().unwrap();
}

#[test]
fn a_homing_error_names_the_node_and_the_cause_and_leaves_the_machine_holding() {
    let _one = one_at_a_time();
    // X's drive has no home switch.
    let m = common::machine(|t| serve_tables(t).replacen("home_switch_mm = -2\n", "\n", 1));
    let mut svc = Service::start(&m, Vec::new());
    let mut c = svc.client();
    c.ok("enable");
    let a = c.cmd("home X");
    assert!(a.starts_with("error: axis X (node 1): homing error"), "{a}");
    assert!(a.contains("home switch was not found"), "{a}");
    let s = c.status();
    assert_eq!(s["state"], "idle", "{s}");
    assert_eq!(axis(&s, 0)["homed"], false);
    assert_eq!(axis(&s, 0)["control"], "cyclic");
    assert!(
        s["homing_error"].as_str().unwrap().contains("node 1"),
        "{s}"
    );
    // The other axes still home.
    c.ok("home Y");
    svc.quit().unwrap();
}

#[test]
fn a_drive_that_resets_leaves_an_alarm_until_reset_then_home_and_run_work_again() {
    let _one = one_at_a_time();
    let m = machine();
    let mut svc = Service::start(
        &m,
        vec![Targeted {
            node: Some(2),
            inject: Inject::Reboot {
                after: Duration::from_millis(2500),
            },
        }],
    );
    let mut c = svc.client();
    c.ok("enable");
    c.ok("home all");
    // Y stays near its home switch (the search back to it is slow).
    let long = svc.file("long.ngc", "G21 G90\nG1 X150 Y22 F3000\nM2\n");
    c.ok(&format!("run {}", long.display()));
    let s = c.wait_state("alarm", Duration::from_secs(10));
    assert_eq!(s["alarm"]["kind"], "BootUp", "{s}");
    assert_eq!(s["alarm"]["node"], 2, "{s}");
    assert_eq!(s["queued"], 0);
    let a = c.cmd("mdi G0 X1");
    assert!(a.starts_with("error: alarm"), "{a}");
    let a = c.ok("reset");
    assert!(a.contains("enabled"), "{a}");
    let s = c.status();
    assert_eq!(s["state"], "idle", "{s}");
    assert_eq!(axis(&s, 1)["homed"], false, "{s}");
    let a = c.cmd(&format!("run {}", long.display()));
    assert!(a.contains("is not homed"), "{a}");
    c.ok("home all");
    let short = svc.file("short.ngc", "G21 G90\nG1 X20 Y25 F3000\nM2\n");
    c.ok(&format!("run {}", short.display()));
    let s = settled(&mut c, &m);
    assert!((actual(&s, 1) - 25.0).abs() <= 1e-3, "{s}");
    svc.quit().unwrap();
}

#[test]
fn a_drive_fault_leaves_an_alarm_until_reset_then_home_and_run_work_again() {
    let _one = one_at_a_time();
    let m = machine();
    let mut svc = Service::start(
        &m,
        vec![Targeted {
            node: Some(1),
            inject: Inject::Fault {
                after: Duration::from_millis(2000),
            },
        }],
    );
    let mut c = svc.client();
    c.ok("enable");
    c.ok("home all");
    let start = c.status();
    let long = svc.file("long.ngc", "G21 G90\nG1 X150 Y22 F3000\nM2\n");
    c.ok(&format!("run {}", long.display()));
    c.ok(&format!("run {}", long.display()));
    let s = c.wait_state("alarm", Duration::from_secs(10));
    // The fault's EMCY or its statusword, whichever arrives first.
    assert!(
        s["alarm"]["kind"] == "Emcy" || s["alarm"]["kind"] == "DriveFault",
        "{s}"
    );
    assert_eq!(s["alarm"]["node"], 1, "{s}");
    assert_eq!(s["queued"], 0, "the queue is cleared: {s}");
    let deadline = Instant::now() + Duration::from_secs(3);
    while c.status()["phase"] != "Disabled" {
        assert!(Instant::now() < deadline, "{}", c.status());
        std::thread::sleep(Duration::from_millis(10));
    }
    // The group stopped within its limits (the faulted axis frozen).
    limits_from(&m, &svc.log, cycle(&start));
    let a = c.cmd("home all");
    assert!(a.starts_with("error: alarm: axis X (node 1)"), "{a}");
    let a = c.ok("reset");
    assert!(a.contains("enabled"), "{a}");
    let s = c.status();
    assert_eq!(s["state"], "idle", "{s}");
    assert!(s["alarm"].is_null(), "{s}");
    assert_eq!(axis(&s, 0)["homed"], false, "{s}");
    c.ok("home all");
    let short = svc.file("short.ngc", "G21 G90\nG1 X20 Y25 F3000\nM2\n");
    c.ok(&format!("run {}", short.display()));
    let s = settled(&mut c, &m);
    assert!((actual(&s, 0) - 20.0).abs() <= 1e-3, "{s}");
    svc.quit().unwrap();
}

#[test]
fn work_offsets_persist_across_jobs_and_a_program_runs_from_a_line() {
    let _one = one_at_a_time();
    // No homing needed here.
    let m = common::machine(|t| {
        serve_tables(t).replace("require_homing = true", "require_homing = false")
    });
    assert!(!m.operation.require_homing);
    let mut svc = Service::start(&m, Vec::new());
    let mut c = svc.client();
    c.ok("enable");
    // G10 L2 in MDI sets G54's origin; a program's G0 X0 Y0 goes there.
    c.ok("mdi G10 L2 P1 X5 Y7");
    let a = c.ok("mdi G0 X0 Y0");
    assert!(a.starts_with("ok queued MDI"), "{a}");
    let s = settled(&mut c, &m);
    assert!(
        (actual(&s, 0) - 5.0).abs() <= 1e-3 && (actual(&s, 1) - 7.0).abs() <= 1e-3,
        "{s}"
    );
    let prog = svc.file(
        "offsets.ngc",
        "G21 G90\nG0 X1 Y1\nG1 X10 F3000\nG1 Y10\nG1 X2\nM2\n",
    );
    c.ok(&format!("run {}", prog.display()));
    let s = settled(&mut c, &m);
    assert!(
        (actual(&s, 0) - 7.0).abs() <= 1e-3 && (actual(&s, 1) - 17.0).abs() <= 1e-3,
        "{s}"
    );
    // G91 in MDI stays for the next MDI line.
    c.ok("mdi G91");
    c.ok("mdi G0 X1");
    let s = settled(&mut c, &m);
    assert!((actual(&s, 0) - 8.0).abs() <= 1e-3, "{s}");
    c.ok("mdi G90");
    // A job queued while another runs starts where that one ends.
    c.ok("mdi G0 X30 Y30");
    std::thread::sleep(Duration::from_millis(30));
    assert_eq!(c.status()["state"], "mdi");
    c.ok("mdi G0 X31");
    let s = settled(&mut c, &m);
    assert!(
        (actual(&s, 0) - 36.0).abs() <= 1e-3 && (actual(&s, 1) - 37.0).abs() <= 1e-3,
        "{s}"
    );
    // From line 4 (`G1 Y10`): a rapid to where it starts (X10 Y1 in G54), then lines 4 and 5.
    c.ok("mdi G0 X3 Y10");
    settled(&mut c, &m);
    c.ok(&format!("run {} from 4", prog.display()));
    let deadline = Instant::now() + Duration::from_secs(2);
    while c.status()["program"].is_null() {
        assert!(Instant::now() < deadline);
        std::thread::sleep(Duration::from_millis(5));
    }
    let s = settled(&mut c, &m);
    assert!(
        (actual(&s, 0) - 7.0).abs() <= 1e-3 && (actual(&s, 1) - 17.0).abs() <= 1e-3,
        "{s}"
    );
    let rows = read_csv(&svc.log);
    // The lead-in ends at rest where line 4 starts (X 15, Y 8), and line 3 (Y = 8 from X 6) is
    // not run again: the last job never runs along Y = 8 before that point.
    let from = rows
        .iter()
        .rposition(|r| (r[2] - 8.0).abs() < 1e-6 && (r[3] - 17.0).abs() < 1e-6)
        .expect("the start of the run from line 4");
    let tail = &rows[from..];
    // (The stop falls between two samples: the closest sample is within a count.)
    let dist = |r: &Vec<f64>| ((r[2] - 15.0).powi(2) + (r[3] - 8.0).powi(2)).sqrt();
    let at = (0..tail.len())
        .min_by(|a, b| dist(&tail[*a]).total_cmp(&dist(&tail[*b])))
        .unwrap();
    assert!(
        dist(&tail[at]) < 1e-3,
        "line 4's start not reached: {:?}",
        tail[at]
    );
    assert!(
        tail[..at].iter().all(|r| r[3] > 8.0 + 1e-6),
        "line 3 ran again"
    );
    let a = c.cmd(&format!("run {} from 40", prog.display()));
    assert_eq!(a, "error: no motion from line 40 on");
    svc.quit().unwrap();
}

#[test]
fn a_hold_is_reported_and_resume_finishes_the_program() {
    let _one = one_at_a_time();
    let m = common::machine(|t| {
        serve_tables(t).replace("require_homing = true", "require_homing = false")
    });
    let mut svc = Service::start(&m, Vec::new());
    let mut c = svc.client();
    c.ok("enable");
    let long = svc.file("long.ngc", "G21 G90\nG1 X80 F6000\nM2\n");
    c.ok(&format!("run {}", long.display()));
    let deadline = Instant::now() + Duration::from_secs(2);
    while c.status()["program"].is_null() {
        assert!(Instant::now() < deadline);
        std::thread::sleep(Duration::from_millis(5));
    }
    std::thread::sleep(Duration::from_millis(200));
    let a = c.ok("hold");
    assert!(a.contains("hold"), "{a}");
    let s = c.wait_state("held", Duration::from_secs(3));
    let x = actual(&s, 0);
    assert!(x > 6.0 && x < 80.0, "{s}");
    std::thread::sleep(Duration::from_millis(200));
    assert_eq!(c.status()["state"], "held");
    c.ok("resume");
    let s = settled(&mut c, &m);
    assert!((actual(&s, 0) - 80.0).abs() <= 1e-3, "{s}");
    svc.quit().unwrap();
}
