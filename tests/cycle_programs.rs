//! Canned cycles through the binary: `canmotion plan --path` on the programs of
//! `tests/programs/cycles_*.ngc`, and the path it writes compared with points worked out by
//! hand from LinuxCNC's cycle definitions (to 0.001 mm), element by element: source line, rapid
//! or feed, end point. The programs fit the demo machine's travel.

use std::path::Path;
use std::process::Command;

/// An element of the path file: source line, rapid, start, end, feed (mm/s; 0 for rapids).
type Record = (u64, bool, [f64; 3], [f64; 3], Option<f64>);

fn plan_path(program: &str) -> Vec<Record> {
    let dir = tempfile::tempdir().unwrap();
    let program = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/programs")
        .join(program);
    let path = dir.path().join("path.jsonl");
    let out = Command::new(env!("CARGO_BIN_EXE_canmotion"))
        .arg("plan")
        .arg(&program)
        .arg("--path")
        .arg(&path)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    let point = |v: &serde_json::Value| -> [f64; 3] {
        let a = v.as_array().unwrap();
        [0, 1, 2].map(|i| a[i].as_f64().unwrap())
    };
    std::fs::read_to_string(&path)
        .unwrap()
        .lines()
        .map(|l| {
            let v: serde_json::Value = serde_json::from_str(l).unwrap();
            assert_eq!(v["kind"], "line", "cycles make straight moves: {v}");
            (
                v["line"].as_u64().unwrap(),
                v["rapid"].as_bool().unwrap(),
                point(&v["start"]),
                point(&v["end"]),
                v["feed_mm_s"].as_f64(),
            )
        })
        .collect()
}

/// R: rapid, F: feed.
const R: bool = true;
const F: bool = false;

#[track_caller]
fn check(program: &str, feed_mm_s: f64, expected: &[(u64, bool, [f64; 3])]) {
    let path = plan_path(program);
    let mut at = [0.0; 3];
    for (i, record) in path.iter().enumerate() {
        let (line, rapid, start, end, feed) = *record;
        assert_eq!(
            start, at,
            "element {i} (line {line}) starts where the last ended"
        );
        at = end;
        if !rapid {
            assert_eq!(feed, Some(feed_mm_s), "element {i}: feed");
        }
        let Some(&(want_line, want_rapid, want_end)) = expected.get(i) else {
            panic!("{program}: element {i} (line {line}, {end:?}) more than expected");
        };
        let close = (0..3).all(|k| (end[k] - want_end[k]).abs() <= 0.001);
        assert!(
            (line, rapid) == (want_line, want_rapid) && close,
            "{program}: element {i}: got line {line} rapid {rapid} to {end:?}, \
             expected line {want_line} rapid {want_rapid} to {want_end:?}"
        );
    }
    assert_eq!(path.len(), expected.len(), "{program}: number of elements");
}

#[test]
fn cycles_in_the_xy_plane_follow_the_hand_computed_path() {
    check(
        "cycles_g17.ngc",
        5.0,
        &[
            (3, R, [0.0, 0.0, 4.0]),
            // G98 G81: initial level 4, R 1, bottom -3.
            (5, R, [10.0, 10.0, 4.0]),
            (5, R, [10.0, 10.0, 1.0]),
            (5, F, [10.0, 10.0, -3.0]),
            (5, R, [10.0, 10.0, 4.0]),
            // Sticky: X20 drills again.
            (6, R, [20.0, 10.0, 4.0]),
            (6, R, [20.0, 10.0, 1.0]),
            (6, F, [20.0, 10.0, -3.0]),
            (6, R, [20.0, 10.0, 4.0]),
            // G99 G83 Q2: pecks to -1 and -3, each out to R and back to 0.254 above.
            (7, R, [30.0, 10.0, 4.0]),
            (7, R, [30.0, 10.0, 1.0]),
            (7, F, [30.0, 10.0, -1.0]),
            (7, R, [30.0, 10.0, 1.0]),
            (7, R, [30.0, 10.0, -0.746]),
            (7, F, [30.0, 10.0, -3.0]),
            (7, R, [30.0, 10.0, 1.0]),
            (7, R, [30.0, 10.0, -2.746]),
            (7, F, [30.0, 10.0, -5.0]),
            (7, R, [30.0, 10.0, 1.0]),
            // G73 Q1.5 at R already: pecks to -0.5, -2, -3.5, each backing off 0.254.
            (8, R, [40.0, 10.0, 1.0]),
            (8, F, [40.0, 10.0, -0.5]),
            (8, R, [40.0, 10.0, -0.246]),
            (8, F, [40.0, 10.0, -2.0]),
            (8, R, [40.0, 10.0, -1.746]),
            (8, F, [40.0, 10.0, -3.5]),
            (8, R, [40.0, 10.0, -3.246]),
            (8, F, [40.0, 10.0, -4.0]),
            (8, R, [40.0, 10.0, 1.0]),
            // G82 P0.5 (the dwell is no element).
            (9, R, [50.0, 10.0, 1.0]),
            (9, F, [50.0, 10.0, -2.0]),
            (9, R, [50.0, 10.0, 1.0]),
            (11, R, [50.0, 10.0, 4.0]),
            // G91 G98 G85 L3: R = 4 - 3 = 1, bottom 1 - 4 = -3, holes 10, 20 apart.
            (13, R, [60.0, 30.0, 4.0]),
            (13, R, [60.0, 30.0, 1.0]),
            (13, F, [60.0, 30.0, -3.0]),
            (13, F, [60.0, 30.0, 1.0]),
            (13, R, [60.0, 30.0, 4.0]),
            (13, R, [70.0, 50.0, 4.0]),
            (13, R, [70.0, 50.0, 1.0]),
            (13, F, [70.0, 50.0, -3.0]),
            (13, F, [70.0, 50.0, 1.0]),
            (13, R, [70.0, 50.0, 4.0]),
            (13, R, [80.0, 70.0, 4.0]),
            (13, R, [80.0, 70.0, 1.0]),
            (13, F, [80.0, 70.0, -3.0]),
            (13, F, [80.0, 70.0, 1.0]),
            (13, R, [80.0, 70.0, 4.0]),
        ],
    );
}

#[test]
fn cycles_in_the_zx_and_yz_planes_follow_the_hand_computed_path() {
    check(
        "cycles_g18_g19.ngc",
        4.0,
        &[
            (3, R, [50.0, 60.0, 0.0]),
            // G18 G98 G81: the hole at Z -2, X 55; Y from the initial 60 to R 50, bottom 40.
            (5, R, [55.0, 60.0, -2.0]),
            (5, R, [55.0, 50.0, -2.0]),
            (5, F, [55.0, 40.0, -2.0]),
            (5, R, [55.0, 60.0, -2.0]),
            (6, R, [60.0, 60.0, -2.0]),
            (6, R, [60.0, 50.0, -2.0]),
            (6, F, [60.0, 40.0, -2.0]),
            (6, R, [60.0, 60.0, -2.0]),
            // G99 G84: feed in, dwell, feed out to R.
            (7, R, [65.0, 60.0, -2.0]),
            (7, R, [65.0, 50.0, -2.0]),
            (7, F, [65.0, 40.0, -2.0]),
            (7, F, [65.0, 50.0, -2.0]),
            (9, R, [65.0, 60.0, -2.0]),
            // G19 G91 G98 G83 L2: initial X 65, R 63, bottom 51, Q 4: pecks to 59 and 55.
            (11, R, [65.0, 65.0, -5.0]),
            (11, R, [63.0, 65.0, -5.0]),
            (11, F, [59.0, 65.0, -5.0]),
            (11, R, [63.0, 65.0, -5.0]),
            (11, R, [59.254, 65.0, -5.0]),
            (11, F, [55.0, 65.0, -5.0]),
            (11, R, [63.0, 65.0, -5.0]),
            (11, R, [55.254, 65.0, -5.0]),
            (11, F, [51.0, 65.0, -5.0]),
            (11, R, [65.0, 65.0, -5.0]),
            (11, R, [65.0, 70.0, -8.0]),
            (11, R, [63.0, 70.0, -8.0]),
            (11, F, [59.0, 70.0, -8.0]),
            (11, R, [63.0, 70.0, -8.0]),
            (11, R, [59.254, 70.0, -8.0]),
            (11, F, [55.0, 70.0, -8.0]),
            (11, R, [63.0, 70.0, -8.0]),
            (11, R, [55.254, 70.0, -8.0]),
            (11, F, [51.0, 70.0, -8.0]),
            (11, R, [65.0, 70.0, -8.0]),
            (13, R, [50.0, 70.0, -8.0]),
        ],
    );
}
