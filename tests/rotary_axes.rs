//! The auxiliary axes A B C (rotary, degrees) and U V W (linear) end to end: the machine file's
//! keys, LinuxCNC's feed semantics (F is the X/Y/Z path speed when they move, else the U/V/W
//! one, else deg/min over the A/B/C length), G93, wrapped rotary axes, the tool-centre path of
//! `canmotion plan --path` against hand-computed points, every axis's limits by finite
//! differences in both profiles, and a run on the in-process bus that ends on the programmed
//! counts.

mod common;
#[path = "common/serve.rs"]
mod serve_rig;

use std::path::Path;
use std::process::Command;

use canmotion::bus::Bus;
use canmotion::bus::inproc::InProcBus;
use canmotion::config::{ConfigError, Machine};
use canmotion::gateway::{self, GatewayError, RunOptions, limits, plan_program};
use canmotion::gcode::{AuxPos, ErrorKind, Item, parse_program_with};
use canmotion::interpolator::Interpolator;
use canmotion::planner::{Plan, PlannerConfig, ProfileKind, SegmentPath, plan_with};
use nalgebra::Vector3;

fn xyza() -> Machine {
    Machine::load(Path::new("dictionaries/machines/demo-xyza.toml")).expect("demo-xyza")
}

/// demo-xyza with `wrap = "shortest"` on A.
fn xyza_shortest() -> Machine {
    let text = std::fs::read_to_string("dictionaries/machines/demo-xyza.toml").unwrap();
    assert!(text.contains("wrap = true"));
    parse_machine(&text.replace("wrap = true", "wrap = \"shortest\"")).expect("shortest A")
}

fn eight() -> Machine {
    Machine::load(Path::new("tests/programs/aux_axes.toml")).expect("aux_axes.toml")
}

fn program(name: &str) -> String {
    std::fs::read_to_string(Path::new("tests/programs").join(name)).expect("program")
}

/// The duration of each moving segment, by source line.
fn durations(plan: &Plan) -> Vec<(usize, f64)> {
    plan.segments()
        .iter()
        .filter(|s| matches!(s.path, SegmentPath::Line { .. } | SegmentPath::Arc(_)))
        .map(|s| (s.line, s.duration_s()))
        .collect()
}

fn assert_times(plan: &Plan, want: &[(usize, f64)]) {
    let got = durations(plan);
    assert_eq!(got.len(), want.len(), "{got:?}");
    for ((line, t), (want_line, want_t)) in got.iter().zip(want) {
        assert_eq!(line, want_line, "{got:?}");
        assert!(
            (t - want_t).abs() < 1e-6,
            "line {line}: {t} s, hand-computed {want_t} s"
        );
    }
}

/// Alone from rest to rest, a trapezoid over `length` at cruise `v` and acceleration `a`
/// lasts `length/v + v/a`.
fn trapezoid_s(length: f64, v: f64, a: f64) -> f64 {
    length / v + v / a
}

#[test]
fn feed_semantics_follow_linuxcnc() {
    // demo-xyza: X, Y 2000 mm/s², A 180 deg/s and 1800 deg/s², 75 % of each for the profiles.
    let m = xyza();
    let plan = plan_program(
        &m,
        "rotary_feed.ngc",
        &program("rotary_feed.ngc"),
        Vector3::zeros(),
    )
    .expect("plan");
    let share = 0.75;
    // Line 4, `G1 X10 A90 F600`: 10 mm at 10 mm/s; A moves 9 deg per mm, so its acceleration
    // caps the path's: 0.75·1800/9 = 150 mm/s².
    let l4 = trapezoid_s(10.0, 10.0, share * 1800.0 / 9.0);
    // Line 6, `G1 A180 F3600`: 90 deg at 60 deg/s, 0.75·1800 deg/s².
    let l6 = trapezoid_s(90.0, 60.0, share * 1800.0);
    // Line 8, under G20: the same (deg/min, never inches).
    // Line 10, `G91 X-5 Y5 A-45 F300`: 5√2 mm at 5 mm/s; A: 45/(5√2) = 6.364 deg/mm.
    let l10_len = 50f64.sqrt();
    let l10 = trapezoid_s(l10_len, 5.0, share * 1800.0 / (45.0 / l10_len));
    // Line 12, `G0 A0` from 225 on the wrapped A: +135 deg at A's 180 deg/s (no X/Y/Z feed cap).
    let l12 = trapezoid_s(135.0, 180.0, share * 1800.0);
    assert_times(&plan, &[(4, l4), (6, l6), (8, l6), (10, l10), (12, l12)]);
    assert!((l4 - 1.066_666_7).abs() < 1e-6 && (l6 - 1.544_444_4).abs() < 1e-6);
}

#[test]
fn inverse_time_feed_takes_one_over_f_minutes() {
    let m = xyza();
    let plan = plan_program(
        &m,
        "rotary_g93.ngc",
        &program("rotary_g93.ngc"),
        Vector3::zeros(),
    )
    .expect("plan");
    let share = 0.75;
    let segs = plan.segments();
    // Line 3, `G93 G1 X10 A90 F30`: 2 s for 10 mm, 5 mm/s, plus the ramps.
    assert_eq!(segs[0].line, 3);
    assert!((segs[0].v_peak_mm_s - 5.0).abs() < 1e-12);
    assert!((segs[0].duration_s() - trapezoid_s(10.0, 5.0, share * 1800.0 / 9.0)).abs() < 1e-9);
    // Line 5, `G1 A180 F60` (rotary only): 90 deg in 1 s.
    assert_eq!(segs[1].line, 5);
    assert!((segs[1].v_peak_mm_s - 90.0).abs() < 1e-12);
    assert!((segs[1].duration_s() - trapezoid_s(90.0, 90.0, share * 1800.0)).abs() < 1e-9);
    // Line 7, the half circle of radius 5 in 3 s, A following.
    let arc = segs.iter().find(|s| s.line == 7).expect("the arc");
    assert!((arc.length_mm - 5.0 * std::f64::consts::PI).abs() < 1e-12);
    assert!((arc.v_peak_mm_s - 5.0 * std::f64::consts::PI / 3.0).abs() < 1e-9);
    assert_eq!((arc.aux.start[0], arc.aux.end[0]), (180.0, 270.0));
    // Its midpoint in time is on the circle, A halfway (linear in the path).
    let mid = arc.start_time_s + 0.5 * arc.duration_s();
    let p = plan.position_at(mid);
    assert!(((p - Vector3::new(15.0, 0.0, 0.0)).norm() - 5.0).abs() < 1e-9);
    let a = arc.aux_at(0.5 * arc.duration_s())[0];
    let s = arc.distance_at(0.5 * arc.duration_s());
    assert!((a - (180.0 + 90.0 * s / arc.length_mm)).abs() < 1e-9);

    // F must be on every G93 feed line, rotary-only ones too: the error names line and column.
    let e = parse_program_with(
        "G93 G1 A10 F60\nG1 A20\n",
        "t.ngc",
        m.setup(Vector3::zeros()),
    )
    .unwrap_err();
    assert_eq!((e.line, e.col), (2, 1));
    assert!(matches!(
        e.kind,
        ErrorKind::MissingInverseTimeFeed { code: "G1" }
    ));
}

#[test]
fn a_wrapped_axis_turns_as_linuxcnc_or_the_shortest_way() {
    let ends = |m: &Machine| -> Vec<(usize, f64)> {
        let p = parse_program_with(
            &program("rotary_wrap.ngc"),
            "rotary_wrap.ngc",
            m.setup(Vector3::zeros()),
        )
        .expect("interpret");
        p.items
            .iter()
            .filter_map(|i| match i {
                Item::Motion(e) => Some((e.line, e.aux.end[0])),
                _ => None,
            })
            .collect()
    };
    // `wrap = true`, LinuxCNC's `unwrap_rotary`: the word's magnitude is the position in the
    // turn, its sign the direction (the program's comments work each line out).
    assert_eq!(
        ends(&xyza()),
        [
            (6, 350.0),
            (8, 370.0),
            (10, 90.0),
            (12, -630.0),
            (14, -540.0)
        ]
    );
    // `wrap = "shortest"`: -90 is 270, each move the short way round.
    assert_eq!(
        ends(&xyza_shortest()),
        [
            (6, -10.0),
            (8, 10.0),
            (10, -90.0),
            (12, -810.0),
            (14, -900.0)
        ]
    );
    let m = xyza();
    // 360 and beyond is no absolute position of a wrapped axis (LinuxCNC refuses it too).
    let e = parse_program_with("G0 A400\n", "t.ngc", m.setup(Vector3::zeros())).unwrap_err();
    assert_eq!((e.line, e.col), (1, 4));
    assert!(matches!(
        e.kind,
        ErrorKind::WrappedPositionOutOfRange { letter: 'A', .. }
    ));
    // The wrapped axis has no travel limits; the counts keep counting turns.
    plan_program(&m, "w.ngc", "G91 G0 A-36100\n", Vector3::zeros()).expect("no travel limit");
}

#[test]
fn u_v_w_are_linear_axes_with_their_own_feed() {
    let m = eight();
    let plan =
        plan_program(&m, "aux_uvw.ngc", &program("aux_uvw.ngc"), Vector3::zeros()).expect("plan");
    let share = 0.75;
    let r2 = 200f64.sqrt();
    assert_times(
        &plan,
        &[
            // U/V only: 10√2 mm at 10 mm/s, each of U and V at 1/√2 of the path.
            (3, trapezoid_s(r2, 10.0, share * 1000.0 * r2 / 10.0)),
            // X with U following: 10 mm at 10 mm/s, U's 750 mm/s² caps the path's.
            (5, trapezoid_s(10.0, 10.0, share * 1000.0)),
            // W alone in inches: 25.4 mm at 25.4 mm/s.
            (7, trapezoid_s(25.4, 25.4, share * 1000.0)),
            // A and B alone: 50 deg at 50 deg/s, B at 0.8 of the path.
            (9, trapezoid_s(50.0, 50.0, share * 1800.0 / 0.8)),
            // U with A following: 5 mm at 10 mm/s, A at 6 deg/mm.
            (11, trapezoid_s(5.0, 10.0, share * 1800.0 / 6.0)),
        ],
    );
}

#[test]
fn an_axis_the_machine_lacks_is_a_typed_error() {
    let m = xyza();
    let e = parse_program_with(
        "G0 X1\nG1 X2 B10 F100\n",
        "t.ngc",
        m.setup(Vector3::zeros()),
    )
    .unwrap_err();
    assert_eq!((e.line, e.col), (2, 7));
    assert_eq!(e.kind, ErrorKind::AxisNotConfigured { letter: 'B' });
    // Axis words where nothing reads them are refused, never skipped.
    for text in [
        "G10 L1 P1 R1 A10\n",
        "G28 A0\n",
        "G0 Z1\nG81 Z-1 R0 A5 F100\n",
    ] {
        let e = parse_program_with(text, "t.ngc", m.setup(Vector3::zeros())).unwrap_err();
        assert!(
            matches!(e.kind, ErrorKind::Unsupported { .. }),
            "{text}: {e}"
        );
    }
}

#[test]
fn work_offsets_move_the_auxiliary_axes_origins() {
    let m = eight();
    let text = "G10 L2 P2 A100 U-3\nG55 G1 A10 U1 F3600\nG10 L20 P2 A0\nG1 A5\n\
                G92 A1\nG1 A2\nG54 G1 A5 U0\nM2\n";
    let p = parse_program_with(text, "t.ngc", m.setup(Vector3::zeros())).expect("interpret");
    let ends: Vec<(usize, f64, f64)> = p
        .items
        .iter()
        .filter_map(|i| match i {
            Item::Motion(e) => Some((e.line, e.aux.end[0], e.aux.end[3])),
            _ => None,
        })
        .collect();
    assert_eq!(
        ends,
        [
            // G55's A origin is 100, its U origin -3.
            (2, 110.0, -2.0),
            // G10 L20: A reads 0 at 110 in G55.
            (4, 115.0, -2.0),
            // G92 A1 at 115: the G92 offset is 115 - 110 - 1 = 4; A2 is 110 + 4 + 2.
            (6, 116.0, -2.0),
            // G54 (origin 0) with the G92 offset still in force: A5 is 9; U0 is 0.
            (7, 9.0, 0.0),
        ]
    );
}

#[test]
fn g92_and_g52_offset_the_auxiliary_axes() {
    let m = eight();
    let text = "G0 A10\nG92 A0\nG1 A20 F3600\nG91 G1 A-5\nG90 G92.1\nG1 A5\n\
                G52 U2\nG1 U1 F600\nG53 G0 U0\nG92.2\nG1 U1\nG92.3\nG1 U1.5\nM2\n";
    let p = parse_program_with(text, "t.ngc", m.setup(Vector3::zeros())).expect("interpret");
    let ends: Vec<(usize, f64, f64)> = p
        .items
        .iter()
        .filter_map(|i| match i {
            Item::Motion(e) => Some((e.line, e.aux.end[0], e.aux.end[3])),
            _ => None,
        })
        .collect();
    assert_eq!(
        ends,
        [
            (1, 10.0, 0.0),
            // G92 A0 there: A reads 0 at machine 10, so A20 is machine 30.
            (3, 30.0, 0.0),
            (4, 25.0, 0.0),
            // G92.1 cleared it.
            (6, 5.0, 0.0),
            // G52 U2: U1 is machine 3; G53 ignores the offset.
            (8, 5.0, 3.0),
            (9, 5.0, 0.0),
            // G92.2 suspends the offset, G92.3 brings it back.
            (11, 5.0, 1.0),
            (13, 5.0, 3.5),
        ]
    );
    // On a wrapped axis the turn counts from the offset reading: A reads 0 at machine 100, so
    // A350 is +350 (LinuxCNC's rule: a positive word turns the positive way), machine 450, or
    // -10 the shortest way, machine 90.
    let text = "G0 A100\nG92 A0\nG0 A350\nM2\n";
    for (m, want) in [(xyza(), 450.0), (xyza_shortest(), 90.0)] {
        let p = parse_program_with(text, "t.ngc", m.setup(Vector3::zeros())).expect("interpret");
        let last = p
            .items
            .iter()
            .rev()
            .find_map(|i| match i {
                Item::Motion(e) => Some(e.aux.end[0]),
                _ => None,
            })
            .unwrap();
        assert_eq!(last, want);
    }
}

/// `demo-xyza.toml` as edited into `text`, loaded from its place (its dictionaries beside it).
fn xyza_from(text: &str) -> Machine {
    Machine::parse(
        Path::new("dictionaries/machines/demo-xyza.toml"),
        text,
        |rel| {
            canmotion::config::DriveDictionary::load(&Path::new("dictionaries/machines").join(rel))
        },
    )
    .expect("machine")
}

fn parse_machine(text: &str) -> Result<Machine, ConfigError> {
    Machine::parse(Path::new("m.toml"), text, |rel| {
        canmotion::config::DriveDictionary::load(&Path::new("dictionaries/machines").join(rel))
    })
}

#[test]
fn the_machine_file_names_the_wrong_key_for_the_kind() {
    let text = std::fs::read_to_string("dictionaries/machines/demo-xyza.toml").unwrap();
    let key_of = |edited: String| match parse_machine(&edited) {
        Err(ConfigError::Invalid { table, key, .. }) => (table, key),
        other => panic!("expected an invalid key, got {other:?}"),
    };
    assert_eq!(
        key_of(text.replace("counts_per_deg = 100.0", "counts_per_mm = 100.0")),
        ("axis A".into(), "counts_per_mm".into())
    );
    assert_eq!(
        key_of(text.replacen("counts_per_mm = 1000.0", "counts_per_deg = 1000.0", 1)),
        ("axis X".into(), "counts_per_deg".into())
    );
    assert_eq!(
        key_of(text.replace("kind = \"rotary\"", "kind = \"linear\"")),
        ("axis A".into(), "counts_per_deg".into())
    );
    assert_eq!(
        key_of(text.replacen(
            "counts_per_mm = 1000.0",
            "kind = \"rotary\"\ncounts_per_deg = 1000.0",
            1
        )),
        ("axis X".into(), "kind".into())
    );
    let linear_a = text
        .replace("kind = \"rotary\"", "")
        .replace("counts_per_deg = 100.0", "counts_per_mm = 100.0");
    assert_eq!(key_of(linear_a), ("axis A".into(), "wrap".into()));
    let sideways = text.replace("wrap = true", "wrap = \"sideways\"");
    assert_eq!(key_of(sideways), ("axis A".into(), "wrap".into()));
}

/// Samples `plan` as the cyclic loop streams it and checks every axis, the auxiliary ones
/// included, against its limits by finite differences (1 %, and rounding): velocity,
/// acceleration, and jerk in the jerk-limited mode; the end exact.
fn limits_hold(plan: Plan, m: &Machine, cfg: &PlannerConfig) -> Result<(), String> {
    let lim = limits(m);
    // Per channel (X Y Z, then A B C U V W): velocity, acceleration and jerk limits.
    let max: [[f64; 3]; 9] = std::array::from_fn(|i| {
        if i < 3 {
            [
                lim.max_vel_mm_s[i],
                lim.max_acc_mm_s2[i],
                cfg.max_jerk_mm_s3[i],
            ]
        } else {
            let k = i - 3;
            [cfg.aux.max_vel[k], cfg.aux.max_acc[k], cfg.aux.max_jerk[k]]
        }
    });
    let end_aux: AuxPos = plan
        .segments()
        .iter()
        .rev()
        .find(|s| s.length_mm > 0.0)
        .map_or([0.0; 6], |s| s.aux.end);
    let start_aux: AuxPos = plan
        .segments()
        .iter()
        .find(|s| s.length_mm > 0.0)
        .map_or([0.0; 6], |s| s.aux.start);
    let end = plan.end_mm();
    let t = cfg.period_s;
    // `Interpolator::new` applies the plan's filters (the jerk-limited mode's).
    let mut interp = Interpolator::new(plan, t).map_err(|e| e.to_string())?;
    let row = |p: Vector3<f64>, aux: &AuxPos| -> [f64; 9] {
        let mut r = [0.0; 9];
        r[..3].copy_from_slice(p.as_slice());
        r[3..].copy_from_slice(aux);
        r
    };
    let mut s = [row(interp.last_mm(), &start_aux); 4];
    let jerk = cfg.profile != ProfileKind::Trapezoid;
    let mut k = 0u64;
    while !interp.is_finished() {
        k += 1;
        let mut q = Vector3::zeros();
        interp.update(&mut q);
        let aux = *interp.aux().ok_or("no auxiliary values while moving")?;
        s.rotate_left(1);
        s[3] = row(q, &aux);
        for i in 0..9 {
            let x = |j: usize| s[j][i];
            if !x(3).is_finite() {
                return Err(format!("sample {k}: channel {i} is {}", x(3)));
            }
            let v = (x(3) - x(2)).abs() / t;
            let a = (x(3) - 2.0 * x(2) + x(1)).abs() / (t * t);
            let j = (x(3) - 3.0 * x(2) + 3.0 * x(1) - x(0)).abs() / (t * t * t);
            let [vm, am, jm] = max[i];
            if v > vm * 1.01 + 1e-9 / t {
                return Err(format!("sample {k}: axis {i} velocity {v} > {vm}"));
            }
            if k >= 2 && a > am * 1.01 + 1e-9 / (t * t) {
                return Err(format!("sample {k}: axis {i} acceleration {a} > {am}"));
            }
            if jerk && k >= 3 && j > jm * 1.01 + 1e-9 / (t * t * t) {
                return Err(format!("sample {k}: axis {i} jerk {j} > {jm}"));
            }
        }
    }
    let want = row(end, &end_aux);
    if s[3] != want {
        return Err(format!("ends at {:?}, not at {want:?}", s[3]));
    }
    Ok(())
}

/// A 4-axis program that joins moves at speed: X/Y/Z with A at changing rates, A alone, arcs
/// with A, CAM chords wrapped round the A axis, rapids, under G64 (blending allowed).
fn four_axis_program() -> String {
    let mut s = String::from("G21 G90 G64 P0.01\nG0 X1 Y1 Z-1\nG1 X10 A30 F3000\n");
    s += "G1 X20 Y5 A90\nG1 X30 Y5\nG1 A180\nG2 X40 Y5 I5 J0 A270\nG1 X40 Y10 A280\n";
    // Chords of a helix wrapped on A: 0.2 mm in X and 3 deg per step (the wrapped A takes
    // them the short way past 360), Z waving.
    for k in 0..120 {
        let x = 40.0 + 0.2 * f64::from(k);
        let a = (280.0 + 3.0 * f64::from(k)).rem_euclid(360.0);
        let z = -1.0 + 0.5 * (f64::from(k) * 0.2).sin();
        s += &format!("G1 X{x:.4} Z{z:.4} A{a:.4} F2400\n");
    }
    s += "G1 A-10 F6000\nG0 X1 Y1 A0\nG1 X5 Y8 Z-2 A45 F1200\nG3 X1 Y8 I-2 J0 A0\nM2\n";
    s
}

/// A small seeded generator of 4-axis moves (X Y Z A, lines and arcs), deterministic.
fn random_program(seed: u64) -> String {
    let mut x = seed
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    let mut next = move || {
        x = x
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((x >> 11) as f64) / ((1u64 << 53) as f64)
    };
    let mut s = String::from("G21 G90 G64\n");
    let (mut px, mut py) = (0.0f64, 0.0f64);
    for _ in 0..25 {
        let r = next();
        let a = (next() - 0.5) * 300.0;
        let f = 300.0 + 5000.0 * next();
        if r < 0.15 {
            s += &format!("G1 A{a:.3} F{:.1}\n", f * 2.0);
        } else if r < 0.3 {
            // A quarter circle, A following.
            let rad = 1.0 + 5.0 * next();
            let (ex, ey) = (px + rad, py + rad);
            if ex < 250.0 && ey < 150.0 {
                s += &format!("G3 X{ex:.3} Y{ey:.3} I{rad:.3} J0 A{a:.3} F{f:.1}\n");
                (px, py) = (ex, ey);
            }
        } else {
            px = (px + (next() - 0.3) * 20.0).clamp(0.0, 250.0);
            py = (py + (next() - 0.3) * 20.0).clamp(0.0, 150.0);
            let z = -next() * 5.0;
            let g = if r < 0.4 { "G0" } else { "G1" };
            s += &format!("{g} X{px:.3} Y{py:.3} Z{z:.3} A{a:.3} F{f:.1}\n");
        }
    }
    s + "M2\n"
}

#[test]
fn every_axis_keeps_its_limits_in_both_profiles() {
    let m = xyza();
    let lim = limits(&m);
    let mut programs = vec![
        four_axis_program(),
        program("rotary_feed.ngc"),
        program("rotary_g93.ngc"),
        program("rotary_wrap.ngc"),
    ];
    programs.extend((1..=12).map(random_program));
    for profile in [ProfileKind::Trapezoid, ProfileKind::SCurve] {
        let cfg = PlannerConfig {
            profile,
            ..m.planner
        };
        for (n, text) in programs.iter().enumerate() {
            let mut setup = m.setup(Vector3::zeros());
            setup.start_aux = [0.0; 6];
            let prog = parse_program_with(text, "p.ngc", setup).expect("interpret");
            let plan = plan_with(&prog, &lim, &cfg).expect("plan");
            limits_hold(plan, &m, &cfg)
                .unwrap_or_else(|e| panic!("{profile:?}, program {n}: {e}\n{text}"));
        }
    }
    // The eight-axis machine too.
    let m = eight();
    for profile in [ProfileKind::Trapezoid, ProfileKind::SCurve] {
        let cfg = PlannerConfig {
            profile,
            ..m.planner
        };
        let text = program("aux_uvw.ngc").replace("G61.1", "G64");
        let prog = parse_program_with(&text, "aux_uvw.ngc", m.setup(Vector3::zeros())).unwrap();
        let plan = plan_with(&prog, &limits(&m), &cfg).expect("plan");
        limits_hold(plan, &m, &cfg).unwrap_or_else(|e| panic!("{profile:?}: {e}"));
    }
}

#[test]
fn junctions_keep_speed_where_the_rotary_rate_holds() {
    // Two moves with the same A rate (9 deg/mm) in a straight line join at speed; a change of
    // the rate at the junction (A stops) brings the speed down to what A's velocity step
    // allows, and never rounds the corner.
    let m = xyza();
    let lim = limits(&m);
    let plan_of = |text: &str| {
        let prog = parse_program_with(text, "j.ngc", m.setup(Vector3::zeros())).unwrap();
        plan_with(&prog, &lim, &m.planner).unwrap()
    };
    let same = plan_of("G64\nG1 X10 A90 F600\nG1 X20 A180\n");
    assert_eq!(same.segments()[0].v_end_mm_s, 10.0);
    let change = plan_of("G64 P0.1\nG1 X10 A90 F600\nG1 X20 Y1\n");
    let v = change.segments()[0].v_end_mm_s;
    // A's step is v·9 deg/s within one period and the 25 % left of A's 1800 deg/s².
    let bound = 0.004 * 0.25 * 1800.0 / 9.0;
    assert!(v > 0.0 && v <= bound * (1.0 + 1e-9), "{v} vs {bound}");
    assert_eq!(change.segments().len(), 2, "no blend arc across an A move");
}

fn canmotion() -> Command {
    Command::new(env!("CARGO_BIN_EXE_canmotion"))
}

/// The `--path` records of `program` on `machine`: line, start, end and the auxiliary axes.
fn path_records(machine: &str, program: &str) -> Vec<serde_json::Value> {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("path.jsonl");
    let out = canmotion()
        .args(["plan", "--machine", machine, program, "--path"])
        .arg(&path)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    std::fs::read_to_string(&path)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect()
}

fn close(v: &serde_json::Value, want: &[f64]) -> bool {
    let got: Vec<f64> = v
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    got.len() == want.len() && got.iter().zip(want).all(|(a, b)| (a - b).abs() <= 1e-3)
}

#[test]
fn plan_path_prints_the_auxiliary_axes_at_hand_computed_points() {
    let xyza = "dictionaries/machines/demo-xyza.toml";
    let r = path_records(xyza, "tests/programs/rotary_feed.ngc");
    // (line, start, end, A [start, end] as shown: modulo 360 on the wrapped A)
    type Record = (u64, [f64; 3], [f64; 3], [f64; 2]);
    let want: [Record; 5] = [
        (4, [0.0, 0.0, 0.0], [10.0, 0.0, 0.0], [0.0, 90.0]),
        (6, [10.0, 0.0, 0.0], [10.0, 0.0, 0.0], [90.0, 180.0]),
        (8, [10.0, 0.0, 0.0], [10.0, 0.0, 0.0], [180.0, 270.0]),
        (10, [10.0, 0.0, 0.0], [5.0, 5.0, 0.0], [270.0, 225.0]),
        (12, [5.0, 5.0, 0.0], [5.0, 5.0, 0.0], [225.0, 0.0]),
    ];
    assert_eq!(r.len(), want.len());
    for (rec, (line, start, end, a)) in r.iter().zip(want) {
        assert_eq!(rec["line"], line);
        assert!(
            close(&rec["start"], &start) && close(&rec["end"], &end),
            "{rec}"
        );
        assert!(close(&rec["A"], &a), "{rec}");
    }
    assert!((r[3]["feed_mm_s"].as_f64().unwrap() - 5.0).abs() < 1e-9);
    let r = path_records(xyza, "tests/programs/rotary_wrap.ngc");
    let shown: Vec<[f64; 2]> = vec![
        [0.0, 350.0],
        [350.0, 10.0],
        [10.0, 90.0],
        [90.0, 90.0],
        [90.0, 180.0],
    ];
    for (rec, a) in r.iter().zip(&shown) {
        assert!(close(&rec["A"], a), "{rec}");
    }
    let r = path_records(xyza, "tests/programs/rotary_g93.ngc");
    assert!(close(&r[2]["A"], &[180.0, 270.0]) && close(&r[2]["center"], &[15.0, 0.0, 0.0]));
    assert!((r[2]["feed_mm_s"].as_f64().unwrap() - 5.0 * std::f64::consts::PI / 3.0).abs() < 1e-9);
    let r = path_records("tests/programs/aux_axes.toml", "tests/programs/aux_uvw.ngc");
    assert!(close(&r[0]["U"], &[0.0, 10.0]) && close(&r[0]["V"], &[0.0, -10.0]));
    assert!(close(&r[2]["W"], &[0.0, 25.4]));
    assert!(close(&r[3]["A"], &[0.0, 30.0]) && close(&r[3]["B"], &[0.0, 40.0]));
    // An X/Y/Z machine's records are as before: no auxiliary columns.
    let r = path_records(
        "dictionaries/machines/demo-xyz.toml",
        "tests/programs/square.ngc",
    );
    assert!(r.iter().all(|rec| rec.get("A").is_none()));
}

/// Cutter compensation moves X/Y to the tool centre and leaves A as programmed, as LinuxCNC's
/// does: each offset side turns A by its programmed 30°, and each outside corner's tool-radius
/// arc (about the programmed corner, radius 2) holds A where the move before it left it; a
/// move of A alone runs at the offset end point, as a move along the tool axis does.
/// By hand: the entry (LinuxCNC's `convert_straight_comp1`) ends on the left side's offset
/// x = 18 at y = 18 + 2√2 (the inside corner with the diagonal); the sides run 2 mm outside the
/// square; G40's move runs from the last offset end (20, 18) back to (10, 10).
#[test]
fn cutter_compensation_carries_the_auxiliary_axes() {
    let r = path_records(
        "dictionaries/machines/demo-xyza.toml",
        "tests/programs/rotary_comp.ngc",
    );
    let meet = 18.0 + 2.0 * std::f64::consts::SQRT_2;
    // (line, end x/y, A [start, end], arc centre)
    type Record = (u64, [f64; 2], [f64; 2], Option<[f64; 2]>);
    let want: [Record; 11] = [
        (4, [10.0, 10.0], [0.0, 0.0], None),
        (5, [18.0, meet], [0.0, 10.0], None),
        (6, [18.0, 40.0], [10.0, 40.0], None),
        (7, [20.0, 42.0], [40.0, 40.0], Some([20.0, 40.0])),
        (7, [40.0, 42.0], [40.0, 70.0], None),
        // A alone: held until the next move in the plane, then run at the offset end.
        (8, [40.0, 42.0], [70.0, 80.0], None),
        (9, [42.0, 40.0], [80.0, 80.0], Some([40.0, 40.0])),
        (9, [42.0, 20.0], [80.0, 100.0], None),
        (10, [40.0, 18.0], [100.0, 100.0], Some([40.0, 20.0])),
        (10, [20.0, 18.0], [100.0, 130.0], None),
        (11, [10.0, 10.0], [130.0, 140.0], None),
    ];
    assert_eq!(r.len(), want.len(), "{r:?}");
    for (rec, (line, end, a, centre)) in r.iter().zip(want) {
        assert_eq!(rec["line"], line, "{rec}");
        assert!(close(&rec["end"], &[end[0], end[1], 0.0]), "{rec}");
        assert!(close(&rec["A"], &a), "{rec}");
        match centre {
            Some(c) => assert!(close(&rec["center"], &[c[0], c[1], 0.0]), "{rec}"),
            None => assert_eq!(rec["kind"], "line", "{rec}"),
        }
    }
    // And it plans within every axis's limits (A's included) in both profiles.
    let m = xyza();
    let text = program("rotary_comp.ngc");
    let prog = gateway::interpret_program(&m, "rotary_comp.ngc", &text, Vector3::zeros())
        .expect("interprets and compensates");
    for profile in [ProfileKind::Trapezoid, ProfileKind::SCurve] {
        let cfg = PlannerConfig {
            profile,
            ..m.planner
        };
        let plan = plan_with(&prog, &limits(&m), &cfg).expect("plans");
        limits_hold(plan, &m, &cfg).unwrap_or_else(|e| panic!("{profile:?}: {e}"));
    }
}

#[test]
fn a_run_on_the_in_process_bus_ends_on_the_programmed_counts() {
    let _one = common::one_at_a_time();
    let m = xyza();
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("log.csv");
    let bus = Bus::InProc(InProcBus::new());
    let opts = RunOptions {
        program_name: "rotary_feed.ngc".into(),
        program_text: program("rotary_feed.ngc"),
        log: Some(log.clone()),
        simulate: true,
        ..Default::default()
    };
    let s: Result<_, GatewayError> = gateway::run(&m, &bus, &opts);
    let s = s.expect("run");
    // X 5 mm, Y 5 mm at 1000 counts/mm; A at 360 deg (the wrapped axis turned once), 100/deg.
    let want = [5000, 5000, 0, 36000];
    for (i, w) in want.iter().enumerate() {
        assert_eq!(s.target_counts[i], *w, "axis {}", s.axes[i]);
        assert!(
            (s.final_counts[i] - w).abs() <= 1,
            "axis {}: {} vs {w}",
            s.axes[i],
            s.final_counts[i]
        );
    }
    let rows = common::read_csv(&log);
    common::limits_held_all(&m, &rows);
}

/// The programs of LinuxCNC's trajectory-planner corpus (`../shared/corpus/linuxcnc-tp`, when
/// present) that move an auxiliary axis: refused on an X/Y/Z machine with the axis named, they
/// plan on one that has it, and their setpoints keep every axis's limits in both profiles.
#[test]
fn corpus_programs_with_auxiliary_axes_plan_within_the_limits() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/corpus/linuxcnc-tp");
    let Ok(groups) = std::fs::read_dir(&dir) else {
        println!("corpus {} is absent: skipping", dir.display());
        return;
    };
    let mut files: Vec<_> = groups
        .flatten()
        .filter(|g| g.path().is_dir())
        .flat_map(|g| std::fs::read_dir(g.path()).unwrap().flatten())
        .map(|f| f.path())
        .filter(|p| p.extension().is_some_and(|e| e.eq_ignore_ascii_case("ngc")))
        .collect();
    files.sort();
    let m = eight();
    let xyz = Machine::load(Path::new("dictionaries/machines/demo-xyz.toml")).unwrap();
    let mut planned = Vec::new();
    for path in &files {
        let text = std::fs::read_to_string(path).unwrap();
        let name = path.strip_prefix(&dir).unwrap().display().to_string();
        match parse_program_with(&text, &name, xyz.setup(Vector3::zeros())) {
            Err(e) if matches!(e.kind, ErrorKind::AxisNotConfigured { .. }) => {}
            _ => continue,
        }
        let prog = parse_program_with(&text, &name, m.setup(Vector3::zeros()))
            .unwrap_or_else(|e| panic!("{e}"));
        for profile in [ProfileKind::Trapezoid, ProfileKind::SCurve] {
            let cfg = PlannerConfig {
                profile,
                ..m.planner
            };
            let plan =
                plan_with(&prog, &limits(&m), &cfg).unwrap_or_else(|e| panic!("{name}: {e}"));
            limits_hold(plan, &m, &cfg).unwrap_or_else(|e| panic!("{name} {profile:?}: {e}"));
        }
        planned.push(name);
    }
    println!("newly planned with auxiliary axes: {planned:?}");
    if !files.is_empty() {
        assert!(planned.len() >= 5, "{planned:?}");
    }
}

/// The run plans from where the drives stand, the auxiliary axes included: with A at 45° at
/// power-on, a program that never moves A leaves it there, and a G91 move of A counts from
/// there (a plan from 0 would send A to 0 in one cycle, which the step check refuses).
#[test]
fn a_run_starts_the_auxiliary_axes_where_the_drives_stand() {
    let _one = common::one_at_a_time();
    // A is the file's last axis: its `[axis.sim]` goes at the end.
    let text = std::fs::read_to_string("dictionaries/machines/demo-xyza.toml").unwrap()
        + "[axis.sim]\nstart_mm = 45.0\n";
    let m = xyza_from(&text);
    assert_eq!(m.axes[3].sim.start_mm, 45.0);
    for (program, want_a) in [
        ("G1 X5 F600\nM2\n", 4500),
        ("G91 G1 X1 A90 F600\nM2\n", 13500),
    ] {
        let bus = Bus::InProc(InProcBus::new());
        let opts = RunOptions {
            program_name: "t.ngc".into(),
            program_text: program.into(),
            simulate: true,
            ..Default::default()
        };
        let s = gateway::run(&m, &bus, &opts).unwrap_or_else(|e| panic!("{program}: {e}"));
        assert_eq!(s.target_counts[3], want_a, "{program}");
        assert!(
            (s.final_counts[3] - want_a).abs() <= 1,
            "{program}: {:?}",
            s.final_counts
        );
    }
}

/// `canmotion serve` on the XYZA machine: MDI lines, a program and a jog move A from where its
/// drive stands (45° at power-on), from one job to the next, and the X/Y/Z-only jobs leave it
/// there.
#[test]
fn serve_jobs_chain_the_auxiliary_axes() {
    let _one = common::one_at_a_time();
    let text = std::fs::read_to_string("dictionaries/machines/demo-xyza.toml")
        .unwrap()
        .replace("require_homing = true", "require_homing = false")
        + "[axis.sim]\nstart_mm = 45.0\n";
    let m = xyza_from(&text);
    let mut svc = serve_rig::Service::start(&m, Vec::new());
    let mut c = svc.client();
    c.ok("enable");
    let settled = |c: &mut serve_rig::Client| {
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs(10);
        loop {
            let s = c.status();
            let at = |i: usize, k: &str| serve_rig::axis(&s, i)[k].as_f64().unwrap();
            if s["state"] == "idle"
                && m.axes.iter().enumerate().all(|(i, a)| {
                    (at(i, "actual_mm") - at(i, "commanded_mm")).abs() <= 1.0 / a.counts_per_mm
                })
            {
                return s;
            }
            assert!(std::time::Instant::now() < deadline, "not settled: {s}");
            std::thread::sleep(std::time::Duration::from_millis(10));
        }
    };
    let a_of = |s: &serde_json::Value| serve_rig::axis(s, 3)["commanded_mm"].as_f64().unwrap();
    c.ok("mdi G0 X1");
    let s = settled(&mut c);
    assert_eq!(a_of(&s), 45.0, "{s}");
    c.ok("mdi G91 G1 A10 F3600");
    let s = settled(&mut c);
    assert!((a_of(&s) - 55.0).abs() < 1e-9, "{s}");
    // The wrapped A: `A-0` is 0 the negative way round (LinuxCNC: the sign gives the
    // direction), from 55 back to 0.
    c.ok("mdi G90 G0 A-0");
    let s = settled(&mut c);
    assert!(a_of(&s).abs() < 1e-9, "{s}");
    let prog = svc.file("a.ngc", "G21 G90\nG1 X2 A30 F600\nG1 X3\nM2\n");
    c.ok(&format!("run {}", prog.display()));
    let s = settled(&mut c);
    assert!((a_of(&s) - 30.0).abs() < 1e-9, "{s}");
    // An incremental jog of A, at 90 deg/s, by -15 deg; X stays.
    let a = c.ok("jog A 90 -15");
    assert!(a.contains("jog A"), "{a}");
    let s = settled(&mut c);
    assert!((a_of(&s) - 15.0).abs() < 1e-9, "{s}");
    assert!((serve_rig::axis(&s, 0)["commanded_mm"].as_f64().unwrap() - 3.0).abs() < 1e-9);
    svc.quit().unwrap();
}
