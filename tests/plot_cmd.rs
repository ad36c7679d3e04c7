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
    // Each axis is named in the legends.
    for axis in ["X", "Y", "Z"] {
        assert!(
            svg.contains(&format!("\n{axis}\n</text>")),
            "no legend for {axis}"
        );
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
