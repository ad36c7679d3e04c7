//! `canmotion plan`: the offline pipeline as a user runs it, through the binary.
//!
//! What a user relies on: the path file is the tool-centre path, element after element with
//! no gap; the setpoints are what `run` would stream (one row per cycle, within the axis
//! limits, ending exactly at the program's end); a program that does not parse leaves no
//! output that looks whole, and the error names the file, line and column.

use std::path::{Path, PathBuf};
use std::process::Command;

use canmotion::config::Machine;

fn canmotion() -> Command {
    Command::new(env!("CARGO_BIN_EXE_canmotion"))
}

/// `canmotion plan ARGS...`, which must succeed; its standard output.
fn plan_ok<I, S>(args: I) -> String
where
    I: IntoIterator<Item = S>,
    S: AsRef<std::ffi::OsStr>,
{
    let out = canmotion().arg("plan").args(args).output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout).to_string();
    assert!(
        out.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    stdout
}

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

/// A machine file like the demo's, written into `dir` with absolute dictionary paths and
/// `program_table` in place of the demo's `[program]` table.
fn machine_file(dir: &Path, program_table: &str) -> PathBuf {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("dictionaries");
    let demo = std::fs::read_to_string(root.join("machines/demo-xyz.toml")).unwrap();
    let start = demo.find("[program]").expect("demo has a [program] table");
    let end = start + demo[start..].find("[[axis]]").unwrap();
    let text = format!("{}{program_table}\n\n{}", &demo[..start], &demo[end..]).replace(
        "../drives/cia402-servo.toml",
        &root.join("drives/cia402-servo.toml").display().to_string(),
    );
    write(dir, "machine.toml", &text)
}

const PROGRAM: &str = "\
(lines, a full circle, a helix, a dwell)
G21 G90 G17 F1200
G0 X10 Y10
G1 Z-1 F300
G1 X30 F1500
G2 X30 Y10 I0 J5
G3 X40 Y20 Z-2 R10
G4 P0.25
G1 X12.5 Y17.25 Z-0.5 F900
G0 Z2
M2
";

#[test]
fn plan_writes_a_continuous_path_and_setpoints_within_the_limits() {
    let dir = tempfile::tempdir().unwrap();
    let program = write(dir.path(), "p.ngc", PROGRAM);
    let path = dir.path().join("path.jsonl");
    let setpoints = dir.path().join("sp.csv");
    let stdout = plan_ok([
        &program,
        Path::new("--path"),
        &path,
        Path::new("--setpoints"),
        &setpoints,
    ]);
    assert!(
        stdout.contains("elements      7 (2 rapids, 2 arcs), 1 dwells"),
        "{stdout}"
    );

    // The path: one JSON object per element, each starting where the previous ended.
    let text = std::fs::read_to_string(&path).unwrap();
    let records: Vec<serde_json::Value> = text
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(records.len(), 7);
    let point = |v: &serde_json::Value| -> [f64; 3] {
        let a = v.as_array().unwrap();
        [0, 1, 2].map(|i| a[i].as_f64().unwrap())
    };
    let mut at = [0.0; 3];
    for r in &records {
        assert_eq!(point(&r["start"]), at, "gap before line {}", r["line"]);
        at = point(&r["end"]);
        let arc = r["kind"] == "arc";
        assert_eq!(r.get("center").is_some(), arc, "{r}");
        assert_eq!(r.get("normal").is_some(), arc, "{r}");
        assert_eq!(r.get("cw").is_some(), arc, "{r}");
    }
    let circle = &records[3];
    assert_eq!(
        (circle["line"].as_u64(), circle["kind"].as_str()),
        (Some(6), Some("arc"))
    );
    assert_eq!(point(&circle["center"]), [30.0, 15.0, -1.0]);
    assert_eq!(
        point(&circle["normal"]),
        [0.0, 0.0, -1.0],
        "G2 turns about -Z"
    );
    assert_eq!(circle["cw"], true);
    assert_eq!(circle["feed_mm_s"].as_f64(), Some(25.0), "F1500 mm/min");
    assert_eq!(records[0]["rapid"], true);
    assert_eq!(at, [12.5, 17.25, 2.0]);

    // The setpoints: every cycle, within the limits, from the start to the exact end.
    let machine = Machine::demo();
    let period_s = machine.cycle_s();
    let text = std::fs::read_to_string(&setpoints).unwrap();
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some("cycle,t_s,X_mm,Y_mm,Z_mm"));
    let rows: Vec<Vec<f64>> = lines
        .map(|l| l.split(',').map(|f| f.parse().unwrap()).collect())
        .collect();
    assert_eq!(&rows[0][2..], &[0.0, 0.0, 0.0]);
    assert_eq!(&rows.last().unwrap()[2..], &[12.5, 17.25, 2.0]);
    let cycles: u64 = stdout
        .lines()
        .find_map(|l| l.strip_prefix("setpoints"))
        .and_then(|l| l.split_whitespace().next())
        .and_then(|n| n.parse().ok())
        .expect("summary names the cycles");
    assert_eq!(rows.len() as u64, cycles);
    // 6 decimals in the file: allow their rounding in the differences.
    let round_mm = 2e-6;
    let mut dwell_rows = 0;
    for (k, w) in rows.windows(3).enumerate() {
        assert_eq!(w[0][0], k as f64);
        assert!((w[0][1] - k as f64 * period_s).abs() < 1e-9);
        for (i, axis) in machine.axes.iter().enumerate() {
            let step = (w[1][2 + i] - w[0][2 + i]).abs();
            assert!(
                step <= axis.max_vel_mm_s * period_s + round_mm,
                "cycle {k}: axis {} steps {step} mm",
                axis.name
            );
            let acc = (w[2][2 + i] - 2.0 * w[1][2 + i] + w[0][2 + i]).abs();
            assert!(
                acc <= axis.max_acc_mm_s2 * period_s * period_s * 1.01 + 2.0 * round_mm,
                "cycle {k}: axis {} accelerates {} mm/s²",
                axis.name,
                acc / (period_s * period_s)
            );
        }
        if w[1][2..] == w[0][2..] && w[1][2..] == [40.0, 20.0, -2.0] {
            dwell_rows += 1;
        }
    }
    // G4 P0.25 at 4 ms holds for 62 or 63 cycles (the samples straddle its ends).
    assert!(
        (61..=64).contains(&dwell_rows),
        "dwell held {dwell_rows} cycles"
    );
}

#[test]
fn a_program_that_does_not_parse_names_its_place_and_leaves_no_output() {
    let dir = tempfile::tempdir().unwrap();
    let program = write(
        dir.path(),
        "bad.ngc",
        "G21 G90 F600\nG1 X10\nG1 X20 Y1..5\nG1 X30\n",
    );
    let path = dir.path().join("path.jsonl");
    let setpoints = dir.path().join("sp.csv");
    let out = canmotion()
        .arg("plan")
        .arg(&program)
        .arg("--path")
        .arg(&path)
        .arg("--setpoints")
        .arg(&setpoints)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(stderr.contains("bad.ngc:3:"), "{stderr}");
    let left: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(left, vec!["bad.ngc".to_string()], "outputs left behind");
}

#[test]
fn the_machine_files_offsets_and_g28_position_apply() {
    let dir = tempfile::tempdir().unwrap();
    let machine = machine_file(
        dir.path(),
        "[program]\ng28_mm = [7.0, 8.0, -9.0]\nwork_offsets_mm = { G54 = [10.0, 20.0, -30.0], G55 = [100.0, 0.0, 0.0] }",
    );
    let program = write(
        dir.path(),
        "p.ngc",
        "G21 G90\nG0 X1 Y2 Z3\nG55 G0 X1\nG28\nM2\n",
    );
    let path = dir.path().join("path.jsonl");
    plan_ok([
        &program,
        Path::new("--machine"),
        &machine,
        Path::new("--path"),
        &path,
    ]);
    let ends: Vec<[f64; 3]> = std::fs::read_to_string(&path)
        .unwrap()
        .lines()
        .map(|l| {
            let v: serde_json::Value = serde_json::from_str(l).unwrap();
            let a = v["end"].as_array().unwrap();
            [0, 1, 2].map(|i| a[i].as_f64().unwrap())
        })
        .collect();
    assert_eq!(ends[0], [11.0, 22.0, -27.0], "G54 origin (10, 20, -30)");
    assert_eq!(
        ends[1],
        [101.0, 22.0, -27.0],
        "G55 origin (100, 0, 0): X1 there"
    );
    assert_eq!(
        *ends.last().unwrap(),
        [7.0, 8.0, -9.0],
        "the configured G28 position"
    );
}

/// The path file's records: (line, kind, start, end, centre of an arc).
type Record = (u64, String, [f64; 3], [f64; 3], Option<[f64; 3]>);

fn plan_path(program: &str, machine: Option<&Path>) -> Vec<Record> {
    let dir = tempfile::tempdir().unwrap();
    let file = write(dir.path(), "square.ngc", program);
    let path = dir.path().join("path.jsonl");
    let mut args = vec![file.as_path(), Path::new("--path"), &path];
    if let Some(m) = machine {
        args.extend([Path::new("--machine"), m]);
    }
    plan_ok(args);
    let point = |v: &serde_json::Value| -> [f64; 3] {
        let a = v.as_array().unwrap();
        [0, 1, 2].map(|i| a[i].as_f64().unwrap())
    };
    std::fs::read_to_string(&path)
        .unwrap()
        .lines()
        .map(|l| {
            let v: serde_json::Value = serde_json::from_str(l).unwrap();
            (
                v["line"].as_u64().unwrap(),
                v["kind"].as_str().unwrap().to_string(),
                point(&v["start"]),
                point(&v["end"]),
                v.get("center").map(point),
            )
        })
        .collect()
}

fn near(a: [f64; 3], b: [f64; 3]) -> bool {
    (0..3).all(|i| (a[i] - b[i]).abs() <= 1e-9)
}

/// The straight elements of a program line: (start, end) in the plane.
fn lines_of(path: &[Record], line: u64) -> Vec<([f64; 3], [f64; 3])> {
    path.iter()
        .filter(|r| r.0 == line && r.1 == "line")
        .map(|r| (r.2, r.3))
        .collect()
}

/// The demo machine with the demo tool table, tool 1 loaded, and `outside_corners = MODE`.
fn corners_machine(dir: &Path, mode: &str) -> PathBuf {
    let tools = Path::new(env!("CARGO_MANIFEST_DIR")).join("dictionaries/tools/demo-tools.toml");
    machine_file(
        dir,
        &format!(
            "[program]\ntool_table = {:?}\nloaded_tool = 1\noutside_corners = {mode:?}",
            tools.display().to_string()
        ),
    )
}

/// A 20 mm square (corners (20, 20) and (40, 40)), entered and left diagonally from (10, 10) at
/// the corner (20, 20), with the tool 1 of the demo table (radius 2 mm). Lines 4 to 7 are the
/// four sides, in the order `sides` gives their far corners.
fn square(g4x: &str, sides: [(f64, f64); 4]) -> String {
    let mut p = format!("G21 G90 G17 F600\nG0 X10 Y10 Z0\n{g4x} D1 G1 X20 Y20\n");
    for (x, y) in sides {
        p.push_str(&format!("G1 X{x} Y{y}\n"));
    }
    p.push_str("G40 G1 X10 Y10\nM2\n");
    p
}

#[test]
fn g41_on_a_clockwise_square_runs_two_millimetres_outside_with_extended_corners() {
    // Clockwise: up the left side first; G41 keeps the tool left of the motion: outside. With
    // `outside_corners = "lines"` (the source's C-type; the default is LinuxCNC's arcs).
    let dir = tempfile::tempdir().unwrap();
    let lines = corners_machine(dir.path(), "lines");
    let path = plan_path(
        &square(
            "G41",
            [(20.0, 40.0), (40.0, 40.0), (40.0, 20.0), (20.0, 20.0)],
        ),
        Some(&lines),
    );
    // Each side is one straight element on the line 2 mm outside it; the three corners the
    // sides share are outside corners of 90°, extended until the offsets meet.
    let sides: Vec<_> = (4..=7).map(|l| lines_of(&path, l)).collect();
    for s in &sides {
        assert_eq!(s.len(), 1, "{path:?}");
    }
    let (left, top, right, bottom) = (sides[0][0], sides[1][0], sides[2][0], sides[3][0]);
    assert!(left.0[0] == 18.0 && left.1[0] == 18.0, "{left:?}");
    assert!(top.0[1] == 42.0 && top.1[1] == 42.0, "{top:?}");
    assert!(right.0[0] == 42.0 && right.1[0] == 42.0, "{right:?}");
    assert!(bottom.0[1] == 18.0 && bottom.1[1] == 18.0, "{bottom:?}");
    assert!(near(left.1, [18.0, 42.0, 0.0]) && near(top.0, left.1));
    assert!(near(top.1, [42.0, 42.0, 0.0]) && near(right.0, top.1));
    assert!(near(right.1, [42.0, 18.0, 0.0]) && near(bottom.0, right.1));
    // Start-up (45° inside corner with the left side: shortened): the diagonal's offset
    // (y = x + 2√2) meets the side's offset at 18 + 2√2. G40 as in LinuxCNC: the bottom side
    // ends at its offset end (20, 18), with no corner join to the exit move.
    let meet = 18.0 + 2.0 * std::f64::consts::SQRT_2;
    assert!((left.0[1] - meet).abs() < 1e-9, "{left:?}");
    assert!(near(bottom.1, [20.0, 18.0, 0.0]), "{bottom:?}");
    // … and nothing else: start-up, four sides, the exit back at the programmed (10, 10).
    assert_eq!(path.len(), 1 + 1 + 4 + 1, "{path:?}");
    assert!(near(path.last().unwrap().3, [10.0, 10.0, 0.0]));
}

#[test]
fn g41_on_a_counter_clockwise_square_runs_two_millimetres_inside_with_shortened_corners() {
    let path = plan_path(
        &square(
            "G41",
            [(40.0, 20.0), (40.0, 40.0), (20.0, 40.0), (20.0, 20.0)],
        ),
        None,
    );
    let sides: Vec<_> = (4..=7).map(|l| lines_of(&path, l)).collect();
    for s in &sides {
        assert_eq!(s.len(), 1, "{path:?}");
    }
    let (bottom, right, top, left) = (sides[0][0], sides[1][0], sides[2][0], sides[3][0]);
    assert!(bottom.0[1] == 22.0 && bottom.1[1] == 22.0, "{bottom:?}");
    assert!(right.0[0] == 38.0 && right.1[0] == 38.0, "{right:?}");
    assert!(top.0[1] == 38.0 && top.1[1] == 38.0, "{top:?}");
    assert!(left.0[0] == 22.0 && left.1[0] == 22.0, "{left:?}");
    // Inside corners of 270° (on the workpiece side): the offsets end at their intersection.
    assert!(near(bottom.1, [38.0, 22.0, 0.0]) && near(right.0, bottom.1));
    assert!(near(right.1, [38.0, 38.0, 0.0]) && near(top.0, right.1));
    assert!(near(top.1, [22.0, 38.0, 0.0]) && near(left.0, top.1));
    assert!(near(path.last().unwrap().3, [10.0, 10.0, 0.0]));
}

#[test]
fn g42_mirrors_g41_and_outside_corners_can_be_arcs() {
    // G42 on the counter-clockwise square is outside, like G41 on the clockwise one.
    let ccw = [(40.0, 20.0), (40.0, 40.0), (20.0, 40.0), (20.0, 20.0)];
    let dir = tempfile::tempdir().unwrap();
    let lines = corners_machine(dir.path(), "lines");
    let path = plan_path(&square("G42", ccw), Some(&lines));
    let sides: Vec<_> = (4..=7).map(|l| lines_of(&path, l)[0]).collect();
    assert!(sides[0].0[1] == 18.0 && near(sides[0].1, [42.0, 18.0, 0.0]));
    assert!(near(sides[1].1, [42.0, 42.0, 0.0]));
    assert!(near(sides[2].1, [18.0, 42.0, 0.0]));

    // With the default `outside_corners = "arc"` (LinuxCNC's) each outside corner is a 2 mm
    // arc about the programmed corner, from one side's offset to the next's.
    let machine = corners_machine(dir.path(), "arc");
    assert_eq!(
        plan_path(&square("G42", ccw), None),
        plan_path(&square("G42", ccw), Some(&machine))
    );
    let path = plan_path(&square("G42", ccw), Some(&machine));
    let arcs: Vec<&Record> = path.iter().filter(|r| r.1 == "arc").collect();
    assert_eq!(arcs.len(), 3, "{path:?}");
    for (arc, (corner, from, to)) in arcs.iter().zip([
        ([40.0, 20.0, 0.0], [40.0, 18.0, 0.0], [42.0, 20.0, 0.0]),
        ([40.0, 40.0, 0.0], [42.0, 40.0, 0.0], [40.0, 42.0, 0.0]),
        ([20.0, 40.0, 0.0], [20.0, 42.0, 0.0], [18.0, 40.0, 0.0]),
    ]) {
        assert!(near(arc.4.unwrap(), corner), "{arc:?}");
        assert!(near(arc.2, from) && near(arc.3, to), "{arc:?}");
    }
    let sides: Vec<_> = (4..=7).map(|l| lines_of(&path, l)[0]).collect();
    assert!(near(sides[0].1, [40.0, 18.0, 0.0]), "{sides:?}");
    assert!(near(sides[1].0, [42.0, 20.0, 0.0]) && near(sides[1].1, [42.0, 40.0, 0.0]));
}

/// `plan --setpoints` of `PROGRAM` on `machine` (the demo's when `None`): the rows' axis columns.
fn setpoint_rows(dir: &Path, machine: Option<&Path>) -> Vec<Vec<f64>> {
    let program = write(dir, "p.ngc", PROGRAM);
    let setpoints = dir.join("sp.csv");
    let mut args = vec![program.as_path(), Path::new("--setpoints"), &setpoints];
    if let Some(m) = machine {
        args.extend([Path::new("--machine"), m]);
    }
    plan_ok(args);
    std::fs::read_to_string(&setpoints)
        .unwrap()
        .lines()
        .skip(1)
        .map(|l| l.split(',').skip(2).map(|f| f.parse().unwrap()).collect())
        .collect()
}

/// The demo machine with `filter = FILTER` on X, Y and Z.
fn filtered_machine_file(dir: &Path, filter: &str) -> PathBuf {
    let plain = machine_file(dir, "[program]");
    let mut text = String::new();
    for line in std::fs::read_to_string(&plain).unwrap().lines() {
        text.push_str(line);
        text.push('\n');
        if line.starts_with("following_error_timeout_ms") {
            text.push_str(&format!("filter = {filter}\n"));
        }
    }
    assert_eq!(text.matches("\nfilter = ").count(), 3);
    write(dir, "filtered.toml", &text)
}

#[test]
fn plan_setpoints_of_a_filtered_machine_end_at_the_program_end_within_the_limits() {
    let dir = tempfile::tempdir().unwrap();
    let plain = setpoint_rows(dir.path(), None);
    let machine = Machine::demo();
    let period_s = machine.cycle_s();
    let end = [12.5, 17.25, 2.0];
    assert_eq!(plain.last().unwrap()[..], end);
    for (filter, linear_cycles) in [
        (r#"{ kind = "linear", time_ms = 24 }"#, Some(6)),
        (r#"{ kind = "exponential", time_ms = 8 }"#, None),
    ] {
        let file = filtered_machine_file(dir.path(), filter);
        let rows = setpoint_rows(dir.path(), Some(&file));
        assert_eq!(rows[0][..], [0.0, 0.0, 0.0]);
        assert_eq!(rows.last().unwrap()[..], end, "{filter}");
        // 6 decimals in the file: allow their rounding in the differences.
        let round_mm = 2e-6;
        for (k, w) in rows.windows(3).enumerate() {
            for (i, axis) in machine.axes.iter().enumerate() {
                let step = (w[1][i] - w[0][i]).abs();
                assert!(
                    step <= axis.max_vel_mm_s * period_s + round_mm,
                    "{filter} cycle {k}: axis {} steps {step} mm",
                    axis.name
                );
                let acc = (w[2][i] - 2.0 * w[1][i] + w[0][i]).abs();
                assert!(
                    acc <= axis.max_acc_mm_s2 * period_s * period_s * 1.01 + 2.0 * round_mm,
                    "{filter} cycle {k}: axis {} accelerates {} mm/s²",
                    axis.name,
                    acc / (period_s * period_s)
                );
            }
        }
        match linear_cycles {
            Some(n) => {
                // The moving average of the unfiltered setpoints over n cycles (the start
                // repeated before it), and the end n − 1 cycles after theirs.
                assert_eq!(rows.len(), plain.len() + n - 1);
                for (k, row) in rows.iter().enumerate() {
                    for i in 0..3 {
                        let avg = (0..n)
                            .map(|j| plain[k.saturating_sub(j).min(plain.len() - 1)][i])
                            .sum::<f64>()
                            / n as f64;
                        assert!((row[i] - avg).abs() <= 2e-6, "cycle {k} axis {i}");
                    }
                }
            }
            None => assert!(rows.len() > plain.len()),
        }
    }
}

/// The `program time` of `plan`'s report, s.
fn program_time_s(stdout: &str) -> f64 {
    let line = stdout
        .lines()
        .find(|l| l.starts_with("program time"))
        .unwrap_or_else(|| panic!("no program time in {stdout}"));
    line.split_whitespace().nth(2).unwrap().parse().unwrap()
}

#[test]
fn plan_override_scales_the_feeds_and_the_program_time() {
    let dir = tempfile::tempdir().unwrap();
    // Feed-limited: long lines at 10 mm/s, where acceleration takes a few ms of 20 s.
    let program = write(
        dir.path(),
        "slow.ngc",
        "G21 G90 G1 X100 F600\nG1 Y100\nG1 X0 Y0\nM2\n",
    );
    let time_at = |percent: Option<&str>| {
        let mut args = vec![program.as_os_str()];
        if let Some(p) = percent {
            args.extend([std::ffi::OsStr::new("--override"), std::ffi::OsStr::new(p)]);
        }
        let stdout = plan_ok(args);
        if let Some(p) = percent {
            assert!(
                stdout.contains(&format!("at {p} % feed override")),
                "{stdout}"
            );
        }
        program_time_s(&stdout)
    };
    let full = time_at(None);
    let half = time_at(Some("50"));
    let double = time_at(Some("200"));
    assert!((full - 34.14).abs() < 0.1, "{full} s at 100 %");
    assert!(
        (half / full - 2.0).abs() < 0.01,
        "50 %: {half} s against {full} s"
    );
    assert!(
        (full / double - 2.0).abs() < 0.01,
        "200 %: {double} s against {full} s"
    );
    assert_eq!(time_at(Some("100")), full);
}

#[test]
fn plan_override_out_of_range_is_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let program = write(dir.path(), "p.ngc", PROGRAM);
    for bad in ["0", "300", "0.5", "fast"] {
        let out = canmotion()
            .arg("plan")
            .arg(&program)
            .arg("--override")
            .arg(bad)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "--override {bad} accepted");
        assert!(stderr.contains("--override"), "{stderr}");
        let why = if bad == "fast" {
            "is not a percentage".to_string()
        } else {
            "must be between 1 % and 200 %".to_string()
        };
        assert!(stderr.contains(&why), "--override {bad}: {stderr}");
    }
}
