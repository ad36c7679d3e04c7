//! `canmotion plan --plot`: what a user opens is a valid SVG or PNG with the four panels; an
//! extension that is neither is refused, naming the flag, before anything is written.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

const PROGRAM: &str = "\
G21 G90 G17
G0 X10 Y10
G1 Z-1 F300
G1 X30 F1500
G2 X30 Y10 I0 J5
G1 X12.5 Y17.25 Z-0.5 F900
G0 Z2
M2
";

fn plan_plot(dir: &Path, plot: &str) -> (PathBuf, Output) {
    let program = dir.join("p.ngc");
    std::fs::write(&program, PROGRAM).unwrap();
    let file = dir.join(plot);
    let out = Command::new(env!("CARGO_BIN_EXE_canmotion"))
        .arg("plan")
        .arg(&program)
        .arg("--plot")
        .arg(&file)
        .output()
        .unwrap();
    (file, out)
}

/// Every element closes, in order (a small well-formedness check: tags, attributes in quotes,
/// no stray `<`).
fn check_xml(text: &str) -> Result<Vec<String>, String> {
    let mut stack: Vec<String> = Vec::new();
    let mut names = Vec::new();
    let mut rest = text;
    while let Some(i) = rest.find('<') {
        let after = &rest[i + 1..];
        let end = after.find('>').ok_or("unclosed tag")?;
        let tag = &after[..end];
        if !tag.matches('"').count().is_multiple_of(2) || tag.contains('<') {
            return Err(format!("bad tag <{tag}>"));
        }
        if let Some(name) = tag.strip_prefix('/') {
            let open = stack.pop().ok_or(format!("</{name}> closes nothing"))?;
            if open != name.trim() {
                return Err(format!("<{open}> closed by </{name}>"));
            }
        } else if !tag.starts_with('?') && !tag.starts_with('!') {
            let name = tag
                .split_whitespace()
                .next()
                .ok_or("empty tag")?
                .to_string();
            names.push(name.clone());
            if !tag.ends_with('/') {
                stack.push(name);
            }
        }
        rest = &after[end + 1..];
    }
    if stack.is_empty() {
        Ok(names)
    } else {
        Err(format!("unclosed {stack:?}"))
    }
}

#[test]
fn an_svg_plot_is_valid_and_has_the_four_panels() {
    let dir = tempfile::tempdir().unwrap();
    let (file, out) = plan_plot(dir.path(), "plot.svg");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let svg = std::fs::read_to_string(&file).unwrap();
    let names = check_xml(&svg).unwrap();
    assert_eq!(names.first().map(String::as_str), Some("svg"));
    for title in [
        "Path feed (mm/s)",
        "Axis velocity (mm/s)",
        "Axis acceleration (mm/s²)",
        "Axis jerk (mm/s³)",
    ] {
        assert!(svg.contains(title), "no panel {title:?}");
    }
    assert!(svg.contains("time (s)"));
    // Each axis is named in the legends, once per mode.
    for axis in ["X", "Y", "Z"] {
        for mode in ["trapezoid", "s-curve"] {
            assert!(
                svg.contains(&format!("\n{axis} {mode}\n</text>")),
                "no legend for {axis} {mode}"
            );
        }
    }
}

#[test]
fn a_png_plot_is_a_png_of_the_plot_size() {
    let dir = tempfile::tempdir().unwrap();
    let (file, out) = plan_plot(dir.path(), "plot.PNG");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let png = std::fs::read(&file).unwrap();
    assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n");
    assert_eq!(&png[12..16], b"IHDR");
    let width = u32::from_be_bytes(png[16..20].try_into().unwrap());
    let height = u32::from_be_bytes(png[20..24].try_into().unwrap());
    assert_eq!((width, height), (1400, 1300));
}

#[test]
fn another_extension_is_refused_naming_the_flag() {
    let dir = tempfile::tempdir().unwrap();
    let (file, out) = plan_plot(dir.path(), "plot.pdf");
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("--plot"), "{stderr}");
    assert!(!file.exists());
}

/// The long polylines (the data, not the dashes of the limits nor the legend's marks) of each
/// of the four stacked panels, as (panel, stroke colour).
fn data_polylines(svg: &str) -> Vec<(usize, String)> {
    let panel_px = 1300 / 4;
    svg.split("<polyline")
        .skip(1)
        .filter_map(|p| {
            let tag = &p[..p.find('>')?];
            let stroke = tag.split("stroke=\"").nth(1)?.split('"').next()?;
            let points = tag.split("points=\"").nth(1)?.split('"').next()?;
            let pts: Vec<&str> = points.split_whitespace().collect();
            if pts.len() < 20 {
                return None;
            }
            let y: usize = pts[0].split(',').nth(1)?.parse().ok()?;
            Some((y / panel_px, stroke.to_string()))
        })
        .collect()
}

#[test]
fn the_plot_shows_the_program_in_both_modes() {
    let dir = tempfile::tempdir().unwrap();
    let (file, out) = plan_plot(dir.path(), "plot.svg");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let svg = std::fs::read_to_string(&file).unwrap();
    // The summary is the machine's own mode (the demo machine's): its program time is in
    // that run's legend entry.
    let stdout = String::from_utf8_lossy(&out.stdout);
    let time = stdout
        .lines()
        .find_map(|l| l.strip_prefix("program time"))
        .and_then(|l| l.split_whitespace().next())
        .expect("no program time in the summary");
    let own = match canmotion::config::Machine::demo().planner.profile {
        canmotion::planner::ProfileKind::Trapezoid => "trapezoid",
        _ => "(jerk-limited)",
    };
    let legend: Vec<&str> = svg
        .split("</text>")
        .filter_map(|t| t.rsplit('>').next())
        .map(str::trim)
        .collect();
    for label in ["trapezoid", "s-curve (jerk-limited)"] {
        let entry = legend
            .iter()
            .find(|t| t.starts_with(label) && t.contains(" s"))
            .unwrap_or_else(|| panic!("no legend entry {label:?} with its time in {legend:?}"));
        if entry.contains(own) {
            assert!(entry.contains(&format!("{time} s")), "{entry} vs {time}");
        }
    }
    // Two series per panel: the feed once per mode, every axis once per mode, each in its own
    // colour.
    let lines = data_polylines(&svg);
    for (panel, expected) in [(0, 2), (1, 6), (2, 6), (3, 6)] {
        let mut colours: Vec<&String> = lines
            .iter()
            .filter(|(p, _)| *p == panel)
            .map(|(_, c)| c)
            .collect();
        assert_eq!(colours.len(), expected, "panel {panel}: {lines:?}");
        colours.sort();
        colours.dedup();
        assert_eq!(
            colours.len(),
            expected,
            "panel {panel}: colours {colours:?}"
        );
    }
}
