//! End-to-end runs on the in-process bus: the gateway and simulated drives in one process, the
//! same code that runs on vcan0, without a kernel CAN stack.

mod common;

use canmotion::bus::Bus;
use canmotion::bus::inproc::InProcBus;
use canmotion::gateway::{self, GatewayError, RunOptions};
use canmotion::sim::{SimDrive, runner};
use common::*;

fn opts(program: &str, simulate: bool, log: Option<std::path::PathBuf>) -> RunOptions {
    RunOptions {
        program_name: "test.ngc".into(),
        program_text: program.into(),
        log,
        simulate,
        ..Default::default()
    }
}

#[test]
fn a_program_runs_end_to_end_and_lands_within_one_count() {
    end_to_end(machine(|t| t));
}

#[test]
fn a_program_runs_end_to_end_in_csp_too() {
    let m = machine(csp);
    assert!(
        m.axes
            .iter()
            .all(|a| a.mode == canmotion::config::AxisMode::Csp)
    );
    end_to_end(m);
}

fn end_to_end(m: canmotion::config::Machine) {
    let _one = one_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("out.csv");
    let bus = Bus::InProc(InProcBus::new());
    let o = opts(PROGRAM, true, Some(log.clone()));
    let other = opts(PROGRAM, true, None);
    let s = gateway::run(&m, &bus, &o).expect("run");
    // The run's figures went to its own progress handle, and to no other run's.
    let p = o.progress.read();
    assert_eq!(p.cycle, s.cycles, "{p:?}");
    assert_eq!(other.progress.read().cycle, 0);
    for (i, want) in PROGRAM_END_COUNTS.iter().enumerate() {
        assert_eq!(s.target_counts[i], *want, "axis {} setpoint", s.axes[i]);
        assert!(
            (s.final_counts[i] - want).abs() <= 1,
            "axis {}: {} vs {want}",
            s.axes[i],
            s.final_counts[i]
        );
    }
    let bit12 = s.bit12_cycle.expect("bit 12 seen");
    let first = s.first_motion_cycle.expect("moved");
    assert!(
        bit12 < first,
        "statusword bit 12 (cycle {bit12}) must come before the first moving setpoint (cycle {first})"
    );
    // No drive faulted (the run ended normally), so each held its following-error window. The
    // master's own figure, from the feedback PDOs, is reported; its largest value depends on
    // how late the feedback came (a virtual machine's host stalls this PC for 20 ms at times),
    // so it is checked where it is steady, below.
    assert!(s.max_ferr_mm.iter().all(|f| f.is_finite() && *f > 0.0));
    // The CSV has the stated columns and one row per cycle.
    let text = std::fs::read_to_string(&log).unwrap();
    let mut lines = text.lines();
    assert_eq!(
        lines.next().unwrap(),
        "cycle,t_s,X_cmd_mm,Y_cmd_mm,Z_cmd_mm,X_act_mm,Y_act_mm,Z_act_mm,X_ferr_mm,Y_ferr_mm,Z_ferr_mm"
    );
    let rows: Vec<Vec<f64>> = lines
        .map(|l| l.split(',').map(|x| x.parse().unwrap()).collect())
        .collect();
    assert_eq!(rows.len() as u64 + s.log_dropped, s.cycles);
    assert!(rows.iter().all(|r| r.len() == 11));
    // While an axis moves, its logged following error is typically a tenth of the window: the
    // feedback is compared with the setpoint the drive was following (comparing it with the
    // newest setpoint would add one period's travel, 0.4 to 0.8 mm here).
    for (i, a) in m.axes.iter().enumerate() {
        let mut moving: Vec<f64> = rows
            .windows(2)
            .filter(|w| (w[1][2 + i] - w[0][2 + i]).abs() > 1e-4)
            .map(|w| w[1][8 + i].abs())
            .collect();
        moving.sort_by(f64::total_cmp);
        let median = moving[moving.len() / 2];
        assert!(
            median < a.following_error_mm / 10.0,
            "axis {}: median following error {median} mm while moving",
            a.name
        );
    }
    let last = rows.last().unwrap();
    assert!(
        (last[4] - (-3.25)).abs() < 1e-9,
        "Z_cmd_mm at the end: {}",
        last[4]
    );
}

#[test]
fn a_missing_node_is_named() {
    let _one = one_at_a_time();
    let m = machine(|t| t);
    let bus = InProcBus::new();
    let dict = drive_dict(|t| t);
    let _drives = runner::spawn(
        &Bus::InProc(bus.clone()),
        vec![SimDrive::new(dict.clone(), 1), SimDrive::new(dict, 2)],
    )
    .unwrap();
    let err = gateway::run(&m, &Bus::InProc(bus), &opts(PROGRAM, false, None)).unwrap_err();
    assert!(matches!(err, GatewayError::MissingNodes { .. }), "{err}");
    let msg = err.to_string();
    assert!(
        msg.contains("axis Z (node 3)") && !msg.contains("node 1"),
        "{msg}"
    );
}

#[test]
fn a_wrong_identity_is_refused_before_any_motion() {
    let _one = one_at_a_time();
    let m = machine(|t| t);
    let bus = InProcBus::new();
    let good = drive_dict(|t| t);
    // Node 2 is another revision of the drive.
    let other = drive_dict(|t| t.replace("0x00010000", "0x00020000"));
    assert_eq!(other.identity.revision, 0x0002_0000);
    let _drives = runner::spawn(
        &Bus::InProc(bus.clone()),
        vec![
            SimDrive::new(good.clone(), 1),
            SimDrive::new(other, 2),
            SimDrive::new(good, 3),
        ],
    )
    .unwrap();
    let err = gateway::run(&m, &Bus::InProc(bus), &opts(PROGRAM, false, None)).unwrap_err();
    let msg = err.to_string();
    assert!(
        matches!(err, GatewayError::WrongIdentity { node: 2, .. }),
        "{msg}"
    );
    assert!(
        msg.contains("revision 0x1018:3 is 0x00020000") && msg.contains("expects 0x00010000"),
        "{msg}"
    );
}

#[test]
fn a_following_error_fault_stops_the_group_and_names_the_axis() {
    following_error_fault(machine(|t| t));
}

#[test]
fn a_following_error_fault_in_csp_too() {
    following_error_fault(machine(csp));
}

fn following_error_fault(m: canmotion::config::Machine) {
    let _one = one_at_a_time();
    // X's motor jams 100 ms into the motion: its following error outgrows the window (0x6065)
    // and the drive faults with EMCY 0x8611. (A window too narrow to hold, which once provoked
    // this, is refused at load now: it would trip on rounding alone.)
    let bus = Bus::InProc(InProcBus::new());
    let dict = drive_dict(|t| t);
    let drives = m
        .axes
        .iter()
        .map(|a| {
            let d = SimDrive::new(dict.clone(), a.node);
            if a.node == 1 {
                d.with_inject(canmotion::sim::Inject::FollowingError { after: ms(100) })
            } else {
                d
            }
        })
        .collect();
    let sims = runner::spawn(&bus, drives).unwrap();
    let err = gateway::run(&m, &bus, &opts(PROGRAM, false, None)).unwrap_err();
    drop(sims);
    let msg = err.to_string();
    assert!(msg.contains("axis X (node 1)"), "{msg}");
    assert!(msg.contains("following error"), "{msg}");
    assert!(msg.contains("last program line"), "{msg}");
}

#[test]
fn a_program_that_does_not_parse_moves_nothing() {
    let _one = one_at_a_time();
    let m = machine(|t| t);
    let bus = Bus::InProc(InProcBus::new());
    // Line 3 is bad: no motion may start, so no drive is even touched.
    let err = gateway::run(
        &m,
        &bus,
        &opts("G21 G90\nG1 X1 F100\nG1 X2 Y\n", true, None),
    )
    .unwrap_err();
    assert!(matches!(err, GatewayError::Program(_)), "{err}");
    assert!(err.to_string().starts_with("test.ngc:3:"), "{err}");
}

#[test]
fn a_move_out_of_travel_is_refused_before_motion() {
    let _one = one_at_a_time();
    let m = machine(|t| t);
    let bus = Bus::InProc(InProcBus::new());
    let err = gateway::run(
        &m,
        &bus,
        &opts("G21 G90\nG1 X10 F600\nG1 Z20\n", true, None),
    )
    .unwrap_err();
    let msg = err.to_string();
    assert!(
        msg.starts_with("test.ngc:3: axis Z would move to 20.0000 mm, outside its travel"),
        "{msg}"
    );
}

#[test]
fn run_streams_the_compensated_tool_centre_path() {
    let _one = one_at_a_time();
    // A 20 mm square cut clockwise with G41 D1 (the demo tool table: radius 2 mm): the tool
    // centre runs 2 mm outside each side, round each outside corner on a 2 mm arc about it (the
    // default `outside_corners = "arc"`, LinuxCNC's), and the program ends at its cancel
    // move's end.
    let program = "G21 G90 G17 F1800\nG0 X10 Y10 Z0\nG41 D1 G1 X20 Y20\nG1 Y40\nG1 X40\nG1 Y20\nG1 X20\nG40 G1 X10 Y10\nM2\n";
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("out.csv");
    let bus = Bus::InProc(InProcBus::new());
    let m = canmotion::config::Machine::demo();
    let s = gateway::run(&m, &bus, &opts(program, true, Some(log.clone()))).expect("run");
    assert_eq!(s.target_counts, vec![10_000, 10_000, 0]);
    let rows: Vec<Vec<f64>> = std::fs::read_to_string(&log)
        .unwrap()
        .lines()
        .skip(1)
        .map(|l| l.split(',').map(|x| x.parse().unwrap()).collect())
        .collect();
    // Columns: cycle, t_s, X_cmd_mm, Y_cmd_mm, ...
    let corners = [(20.0, 40.0), (40.0, 40.0), (40.0, 20.0)];
    let on_path = |x: f64, y: f64| {
        let left = (x - 18.0).abs() < 1e-6 && (20.0..=40.0).contains(&y);
        let top = (y - 42.0).abs() < 1e-6 && (20.0..=40.0).contains(&x);
        let right = (x - 42.0).abs() < 1e-6 && (20.0..=40.0).contains(&y);
        let bottom = (y - 18.0).abs() < 1e-6 && (20.0..=40.0).contains(&x);
        let arc = corners
            .iter()
            .any(|&(cx, cy)| ((x - cx).hypot(y - cy) - 2.0).abs() < 1e-6);
        left || top || right || bottom || arc
    };
    // Every setpoint inside the square's neighbourhood (away from the diagonal entry and exit)
    // is on the offset path, and the cut went all the way round it.
    let round: Vec<&Vec<f64>> = rows
        .iter()
        .filter(|r| r[2] > 17.0 && r[3] > 17.0 && (r[2] > 21.0 || r[3] > 21.0))
        .collect();
    let off: Vec<_> = round.iter().filter(|r| !on_path(r[2], r[3])).collect();
    assert!(
        off.is_empty(),
        "off the offset path: {:?}",
        &off[..off.len().min(5)]
    );
    // Round each corner: some setpoint near the middle of its arc (30 µm a cycle at F1800).
    let h = std::f64::consts::FRAC_1_SQRT_2 * 2.0;
    for (corner, (dx, dy)) in corners.iter().zip([(-h, h), (h, h), (h, -h)]) {
        let mid = (corner.0 + dx, corner.1 + dy);
        assert!(
            round
                .iter()
                .any(|r| (r[2] - mid.0).abs() < 0.02 && (r[3] - mid.1).abs() < 0.02),
            "never round the corner {corner:?}"
        );
    }
}

/// Waits for `cond` on the progress figures, up to `within`; panics with `what` past it.
fn wait_for(
    figures: &gateway::progress::Progress,
    what: &str,
    within: std::time::Duration,
    cond: impl Fn(&gateway::progress::ProgressSnapshot) -> bool,
) -> gateway::progress::ProgressSnapshot {
    let deadline = std::time::Instant::now() + within;
    loop {
        let p = figures.read();
        if cond(&p) {
            return p;
        }
        assert!(
            std::time::Instant::now() < deadline,
            "{what}: not within {within:?}; now {p:?}"
        );
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
}

/// One line to the control socket, its answer back.
fn control(path: &std::path::Path, line: &str) -> String {
    use std::io::{BufRead, Write};
    let mut s =
        std::os::unix::net::UnixStream::connect(path).expect("connect to the control socket");
    writeln!(s, "{line}").unwrap();
    let mut answer = String::new();
    std::io::BufReader::new(s).read_line(&mut answer).unwrap();
    answer.trim_end().to_string()
}

/// `LONG`'s diagonal at 66.7 mm/s (F4000): room for 150 % (100 mm/s) under the machine's 200,
/// and time to get there after a resume wherever the hold came.
const SLOW_DIAGONAL: &str = "G21 G90\nG1 X150 Y150 Z-4 F4000\nM2\n";

#[test]
fn a_hold_from_the_control_socket_stops_the_drives_on_the_path_and_a_resume_finishes() {
    let _one = one_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("hold.csv");
    let sock = dir.path().join("control.sock");
    let o = opts(SLOW_DIAGONAL, true, Some(log.clone()));
    let figures = o.progress.clone();
    let socket = gateway::control::ControlSocket::bind(&sock, o.control.clone()).unwrap();
    let m = machine(|t| t);
    let run = {
        let m = m.clone();
        std::thread::spawn(move || {
            let bus = Bus::InProc(InProcBus::new());
            gateway::run(&m, &bus, &o)
        })
    };
    let secs = std::time::Duration::from_secs;
    wait_for(&figures, "streaming at speed", secs(20), |p| {
        p.feed_mm_s > 20.0
    });
    assert_eq!(control(&sock, "hold"), "ok override 100 %, hold");
    let held = wait_for(&figures, "standstill in the hold", secs(10), |p| p.held);
    assert_eq!(held.override_effective, 0.0);
    // The run goes on, held, for 100 cycles: the drives stay enabled, following.
    wait_for(&figures, "100 cycles held", secs(10), |p| {
        p.cycle >= held.cycle + 100 && p.held
    });
    assert!(!run.is_finished(), "the run ended during the hold");
    // The rest of the line at 150 %.
    assert_eq!(control(&sock, "override 150"), "ok override 150 %, hold");
    assert!(control(&sock, "override 300").starts_with("error: override 300 %"));
    assert_eq!(control(&sock, "resume"), "ok override 150 %");
    let s = run
        .join()
        .unwrap()
        .expect("the run finishes after the resume");
    drop(socket);
    assert!(!sock.exists(), "the socket is removed");
    // Ends at the program's end (X150 Y150 Z-4: 1000, 1000 and 2000 counts/mm).
    let end = [150_000, 150_000, -8000];
    for (i, want) in end.iter().enumerate() {
        assert_eq!(s.target_counts[i], *want, "axis {}", s.axes[i]);
        assert!((s.final_counts[i] - want).abs() <= 1, "axis {}", s.axes[i]);
    }
    // The log: 100 cycles or more of constant setpoints strictly inside the line.
    let text = std::fs::read_to_string(&log).unwrap();
    let rows: Vec<Vec<f64>> = text
        .lines()
        .skip(1)
        .map(|l| l.split(',').map(|x| x.parse().unwrap()).collect())
        .collect();
    let cmd = |r: &Vec<f64>| [r[2], r[3], r[4]];
    let mut longest = (0usize, [0.0; 3]);
    let mut run_len = 0;
    for w in rows.windows(2) {
        let p = cmd(&w[1]);
        let inside = p[0] > 1.0 && p[0] < 149.0;
        run_len = if cmd(&w[0]) == p && inside {
            run_len + 1
        } else {
            0
        };
        if run_len > longest.0 {
            longest = (run_len, p);
        }
    }
    assert!(longest.0 >= 100, "held {} cycles at most", longest.0);
    // After the resume the path ran faster than programmed, up to 150 % of it.
    let fastest = rows
        .windows(2)
        .map(|w| {
            let (a, b) = (cmd(&w[0]), cmd(&w[1]));
            let d = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
            (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt() / (w[1][1] - w[0][1])
        })
        .fold(0.0, f64::max);
    assert!(
        fastest > 1.3 * 66.67 && fastest < 1.5 * 66.67 * 1.01,
        "fastest {fastest} mm/s at 150 %"
    );
    let p = longest.1;
    // On the diagonal: Z = -4·X/150 (within the log's rounding).
    assert!(
        (p[0] - p[1]).abs() < 1e-3 && (p[2] + 4.0 * p[0] / 150.0).abs() < 1e-3,
        "{p:?}"
    );
}

/// X and Y with `min_mm = 10`: drives at 0 stand outside the travel (and their home offsets,
/// which must lie in the travel, move to its new end).
fn travel_from_10(t: String) -> String {
    t.replace("min_mm = -5.0", "min_mm = 10.0")
        .replace("offset_mm = -2.0", "offset_mm = 10.0")
}

/// The demo machine's drives at `counts` (machine order) on a fresh bus, recorded.
fn drives_at(
    m: &canmotion::config::Machine,
    counts: [i32; 3],
) -> (Bus, runner::SimHandle, Recorder) {
    let bus = Bus::InProc(InProcBus::new());
    let dict = drive_dict(|t| t);
    let drives = m
        .axes
        .iter()
        .zip(counts)
        .map(|(a, c)| SimDrive::new(dict.clone(), a.node).with_position(c))
        .collect();
    let rec = Recorder::start(&bus);
    let sims = runner::spawn(&bus, drives).unwrap();
    (bus, sims, rec)
}

#[test]
fn drives_outside_the_travel_are_refused_before_anything_is_written() {
    let _one = one_at_a_time();
    let m = machine(travel_from_10);
    // `plan` accepts the program (extent X [0, 30]); enabling at 0 would make the drives pull
    // towards their software limits on their own.
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("out.csv");
    let (bus, sims, rec) = drives_at(&m, [0, 0, 0]);
    let err = gateway::run(
        &m,
        &bus,
        &opts("G21 G90\nG1 X30 Y30 F1200\nM2\n", false, Some(log.clone())),
    )
    .unwrap_err();
    drop(sims);
    let frames = rec.stop();
    match &err {
        GatewayError::StartOutsideTravel {
            axis,
            node,
            position_mm,
            min_mm,
            max_mm,
        } => {
            assert_eq!((axis.as_str(), *node), ("X", 1), "{err}");
            assert_eq!((*position_mm, *min_mm, *max_mm), (0.0, 10.0, 300.0));
        }
        other => panic!("expected StartOutsideTravel, got {other}"),
    }
    let msg = err.to_string();
    assert!(
        msg.starts_with("axis X (node 1) is at 0.0000 mm, outside its travel [10, 300] mm"),
        "{msg}"
    );
    assert!(msg.contains("jog the axis into its travel"), "{msg}");
    // Nothing written: no SDO download at all (so no 0x607D), no NMT start, no process data,
    // no cycle logged.
    let sdo_requests: Vec<_> = frames
        .iter()
        .filter(|(_, f)| (0x601..=0x67F).contains(&f.id()))
        .collect();
    assert!(
        !sdo_requests.is_empty(),
        "position actual was read over SDO"
    );
    for (_, f) in &sdo_requests {
        let d = f.data();
        assert_ne!(d[0] & 0xE0, 0x20, "an SDO download: {f:?}");
        assert_ne!(u16::from_le_bytes([d[1], d[2]]), 0x607D, "{f:?}");
    }
    assert!(
        !frames
            .iter()
            .any(|(_, f)| f.id() == 0 && f.data().first() == Some(&0x01)),
        "an NMT start was sent"
    );
    let rpdos = frames
        .iter()
        .filter(|(_, f)| (0x201..=0x203).contains(&f.id()))
        .count();
    assert_eq!(rpdos, 0, "setpoints were sent");
    assert!(!log.exists(), "cycles ran");
}

#[test]
fn drives_inside_the_travel_start_where_they_stand() {
    let _one = one_at_a_time();
    let m = machine(travel_from_10);
    // X at 20 mm, Y at 15 mm: inside the travel that starts at 10.
    let (bus, sims, rec) = drives_at(&m, [20_000, 15_000, 0]);
    let s = gateway::run(
        &m,
        &bus,
        &opts("G21 G90\nG1 X30 Y30 F3000\nM2\n", false, None),
    )
    .expect("a start inside the travel runs");
    drop(sims);
    drop(rec);
    assert!((s.final_counts[0] - 30_000).abs() <= 1, "{s}");
    assert!((s.final_counts[1] - 30_000).abs() <= 1, "{s}");
}
