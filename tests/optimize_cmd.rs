//! `canmotion optimize`: the feed optimiser as a user runs it, through the binary, on the demo
//! machine (X, Y: 200 mm/s, 2000 mm/s²; Z: 100 mm/s, 1000 mm/s²).
//!
//! What a user relies on: a feed over an axis's limit comes down exactly to the limit (the
//! slowest axis of a diagonal decides); a short block comes down to what its axis can reach in
//! it, and its neighbours ramp to it, as source 002's formulas give; the output runs (it plans,
//! with no element over the limits) and a second optimisation changes nothing; only F words
//! change, a line that relied on a changed modal F gets its own; a program with nothing to
//! change comes out byte for byte; a program that does not parse writes nothing.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn canmotion() -> Command {
    Command::new(env!("CARGO_BIN_EXE_canmotion"))
}

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

/// Runs `canmotion optimize` on `text`; the output text (if written) and the process output.
fn optimize(dir: &Path, text: &str, extra: &[&str]) -> (Option<String>, Output) {
    let program = write(dir, "in.ngc", text);
    let out = dir.join("out.ngc");
    let _ = std::fs::remove_file(&out);
    let output = canmotion()
        .arg("optimize")
        .arg(&program)
        .arg("-o")
        .arg(&out)
        .args(extra)
        .output()
        .unwrap();
    (std::fs::read_to_string(&out).ok(), output)
}

fn optimized(dir: &Path, text: &str) -> String {
    let (out, output) = optimize(dir, text, &["--no-trace"]);
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    out.expect("the output is written")
}

/// 2000 mm/s² over 1 mm from rest, in mm/min: √(2·2000·1)·60.
fn mm_min(mm_s: f64) -> String {
    let v = (mm_s * 60.0 * 1000.0 + 1e-6).floor() / 1000.0;
    format!("{v:.3}")
        .trim_end_matches('0')
        .trim_end_matches('.')
        .to_string()
}

#[test]
fn a_feed_over_an_axis_limit_comes_down_exactly_to_it() {
    let dir = tempfile::tempdir().unwrap();
    // 250 mm/s along X (limit 200 mm/s); 600 inch/min = 254 mm/s along Y in inches.
    let out = optimized(dir.path(), "G21 G90\nG1 X100 F15000\nG20\nG1 Y2 F600\nM2\n");
    assert_eq!(out, "G21 G90\nG1 X100 F12000\nG20\nG1 Y2 F472.4409\nM2\n");
}

#[test]
fn a_diagonal_gets_the_slowest_axis() {
    let dir = tempfile::tempdir().unwrap();
    // 45° in XZ: X allows 200·√2, Z 100·√2 mm/s.
    let out = optimized(dir.path(), "G1 X100 Z100 F30000\n");
    let expected = mm_min(100.0 * 2f64.sqrt());
    assert_eq!(expected, "8485.281");
    assert_eq!(out, format!("G1 X100 Z100 F{expected}\n"));
    // An arc counts its worst tangent: a full circle in XY reaches |t_x| = |t_y| = 1.
    let out = optimized(dir.path(), "G1 X10 F1000\nG2 X10 Y0 I5 J0 F20000\n");
    assert_eq!(out, "G1 X10 F1000\nG2 X10 Y0 I5 J0 F12000\n");
}

#[test]
fn a_short_block_is_limited_by_acceleration_and_its_neighbours_ramp() {
    let dir = tempfile::tempdir().unwrap();
    let program = "\
G21 G90 G17
G0 X0 Y0
G1 X50 F6000
X51
X52
Y0.1
X53
X54
X100
M2
";
    let out = optimized(dir.path(), program);
    // 002: v² = v0² + 2·a·Δx per axis. The 0.1 mm Y block starts and ends with Y at rest:
    // √(2·2000·0.1) = 20 mm/s. The X blocks next to it end (start) with X at rest:
    // √(2·2000·1) = 63.246 mm/s; the ones before (after) them ramp: √(63.246² + 2·2000·1) =
    // 89.443 mm/s; the 50 mm blocks keep 100 mm/s (√(89.443² + 2·2000·50) > 100).
    let r1 = mm_min((2.0 * 2000.0 * 1.0f64).sqrt());
    let r2 = mm_min((2.0 * 2.0 * 2000.0 * 1.0f64).sqrt());
    assert_eq!((r1.as_str(), r2.as_str()), ("3794.733", "5366.563"));
    let expected = format!(
        "\
G21 G90 G17
G0 X0 Y0
G1 X50 F6000
X51 F{r2}
X52 F{r1}
Y0.1 F1200
X53 F{r1}
X54 F{r2}
X100 F6000
M2
"
    );
    // The last line relied on the modal F6000 of line 3: it gets its own.
    assert_eq!(out, expected);

    // With the trace (the default), each changed F says what it was; the output stays a
    // program that plans.
    let (out, output) = optimize(dir.path(), program, &[]);
    let out = out.unwrap();
    assert!(
        out.contains(&format!("X51 F{r2} (canmotion optimize: was F6000)\n")),
        "{out}"
    );
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(stdout.contains("blocks examined   7"), "{stdout}");
    assert!(stdout.contains("lines lowered     5"), "{stdout}");
    assert!(
        stdout.contains(
            "largest reduction line 6: 6000.000 -> 1200.000 mm/min (-80.0 %), Y acceleration limit"
        ),
        "{stdout}"
    );
}

/// The optimiser on its own output changes nothing, and the output plans with every element
/// within the axes' velocity limits.
#[test]
fn the_output_plans_within_the_limits_and_a_second_pass_changes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let program = "\
(a pocket, CAM style: short segments, an arc, a plunge, modal feeds)
G21 G90 G17
G0 X10 Y10 Z5
G1 Z-1 F6000 ; plunge: Z is limited to 100 mm/s
G1 X40 Y12 F18000
X40.2 Y12.3
X40.3 Y12.7
X40.35 Y13.2
G3 X19.65 Y13.2 I-10.35 J6.8
G1 X10 Y30 Z-2
G1 X10 Y10
G0 Z5
M2
";
    let (out, output) = optimize(dir.path(), program, &[]);
    assert!(output.status.success(), "{output:?}");
    let out = out.unwrap();
    assert_ne!(out, program);
    // Only F words and their traces changed: every line still starts as it did.
    for (a, b) in program.lines().zip(out.lines()) {
        let code = a.split(';').next().unwrap().trim_end();
        let code = code.split(" F").next().unwrap();
        assert!(b.starts_with(code), "{a:?} became {b:?}");
    }
    assert_eq!(program.lines().count(), out.lines().count());

    let again = dir.path().join("again.ngc");
    let first = write(dir.path(), "first.ngc", &out);
    let o = canmotion()
        .args(["optimize"])
        .arg(&first)
        .arg("-o")
        .arg(&again)
        .output()
        .unwrap();
    assert!(o.status.success());
    assert_eq!(std::fs::read_to_string(&again).unwrap(), out);
    assert!(String::from_utf8_lossy(&o.stdout).contains("lines lowered     0"));

    let path = dir.path().join("path.jsonl");
    let o = canmotion()
        .arg("plan")
        .arg(&first)
        .arg("--path")
        .arg(&path)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let vmax = [200.0, 200.0, 100.0];
    let mut feeds = 0;
    for line in std::fs::read_to_string(&path).unwrap().lines() {
        let rec: serde_json::Value = serde_json::from_str(line).unwrap();
        if rec["rapid"].as_bool().unwrap() {
            continue;
        }
        feeds += 1;
        let f = rec["feed_mm_s"].as_f64().unwrap();
        let p = |k: &str| -> Vec<f64> {
            rec[k]
                .as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_f64().unwrap())
                .collect()
        };
        let (s, e) = (p("start"), p("end"));
        let worst: Vec<f64> = if rec["kind"] == "arc" {
            // Sample the arc's tangent (a plane arc about Z here).
            let c = p("center");
            let r = (s[0] - c[0]).hypot(s[1] - c[1]);
            let a0 = (s[1] - c[1]).atan2(s[0] - c[0]);
            let mut a1 = (e[1] - c[1]).atan2(e[0] - c[0]);
            if a1 <= a0 {
                a1 += std::f64::consts::TAU;
            }
            let dz = e[2] - s[2];
            let len = ((a1 - a0) * r).hypot(dz);
            let mut w = vec![0.0f64; 3];
            for k in 0..=1000 {
                let a = a0 + (a1 - a0) * k as f64 / 1000.0;
                let t = [
                    -a.sin() * r * (a1 - a0) / len,
                    a.cos() * r * (a1 - a0) / len,
                    dz / len,
                ];
                for i in 0..3 {
                    w[i] = w[i].max(t[i].abs());
                }
            }
            w
        } else {
            let d: Vec<f64> = (0..3).map(|i| e[i] - s[i]).collect();
            let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            d.iter().map(|x| x.abs() / n).collect()
        };
        for i in 0..3 {
            assert!(
                f * worst[i] <= vmax[i] * (1.0 + 1e-6),
                "line {}: axis {i} at {} mm/s",
                rec["line"],
                f * worst[i]
            );
        }
    }
    assert_eq!(feeds, 8);
}

#[test]
fn a_program_with_nothing_to_change_comes_out_byte_for_byte() {
    let dir = tempfile::tempdir().unwrap();
    let program = "%\r\n(header) \r\nG21 G90\r\n  G0 X0 Y0\r\nG1 X10 F600 ; slow\r\ng2 x20 y0 i5 j0\r\nG93 G1 X30 F2\r\nG94\r\nM2\r\n%\r\n";
    let (out, output) = optimize(dir.path(), program, &[]);
    assert!(output.status.success(), "{output:?}");
    assert_eq!(out.unwrap().as_bytes(), program.as_bytes());
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(stdout.contains("lines lowered     0"), "{stdout}");
    // Inverse time is said to be left alone.
    assert!(
        stdout.contains("1 G93 line(s) left alone (first: line 7)"),
        "{stdout}"
    );
}

#[test]
fn an_inverse_time_block_is_left_alone_and_its_neighbours_are_optimised() {
    let dir = tempfile::tempdir().unwrap();
    // G93 F1000: 10 mm in 1/1000 min (167 mm/s); the G94 line asks 250 mm/s.
    let out = optimized(dir.path(), "G93 G1 X10 F1000\nG94 G1 X110 F15000\nM2\n");
    assert_eq!(out, "G93 G1 X10 F1000\nG94 G1 X110 F12000\nM2\n");
}

#[test]
fn a_program_that_does_not_parse_writes_nothing_and_names_the_line() {
    let dir = tempfile::tempdir().unwrap();
    let (out, output) = optimize(dir.path(), "G1 X10 F15000\nG1 X20 Q\nM2\n", &[]);
    assert!(!output.status.success());
    assert_eq!(out, None);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(stderr.contains("in.ngc:2:"), "{stderr}");
}
