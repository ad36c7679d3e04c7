//! The path-deviation checker of issue 11's contour acceptance (`common/path_deviation.rs`)
//! checked itself: its distances against hand-computed values (a line, arcs in each plane, a
//! helix, a spiral arc) and against a dense sampling of random arcs, its tolerances against
//! the blend modes, its tracking against a search of every piece, and a setpoint stream moved
//! off the path is caught.

use std::f64::consts::{FRAC_PI_2, PI, TAU};

use canmotion::gcode::{ArcGeometry, Item, parse_program};
use canmotion::interpolator::Interpolator;
use canmotion::planner::{PlannerConfig, ProfileKind, plan_with};
use nalgebra::Vector3;

#[path = "common/path_deviation.rs"]
mod path_deviation;

// Only its machine (limits and planner configuration) is used here.
#[allow(dead_code)]
#[path = "common/random_programs.rs"]
mod random_programs;

use path_deviation::{
    AT_REST_MM, Checker, Deviation, Path, ROUND_MM, Tolerances, arc_distance_mm, measure,
    segment_distance_mm,
};

fn v(x: f64, y: f64, z: f64) -> Vector3<f64> {
    Vector3::new(x, y, z)
}

fn arc(
    start: Vector3<f64>,
    end: Vector3<f64>,
    centre: Vector3<f64>,
    normal: Vector3<f64>,
) -> ArcGeometry {
    ArcGeometry::new(start, end, centre, normal, 0).expect("an arc")
}

fn whole(a: &ArcGeometry, q: Vector3<f64>) -> f64 {
    arc_distance_mm(a, 0.0, 1.0, q).0
}

fn assert_close(got: f64, want: f64, what: &str) {
    assert!(
        (got - want).abs() <= 1e-9,
        "{what}: {got} mm, expected {want} mm"
    );
}

#[test]
fn distance_to_a_segment() {
    let (a, b) = (v(0.0, 0.0, 0.0), v(10.0, 0.0, 0.0));
    assert_close(segment_distance_mm(a, b, v(5.0, 3.0, 4.0)), 5.0, "beside");
    assert_close(
        segment_distance_mm(a, b, v(-3.0, 4.0, 0.0)),
        5.0,
        "before the start",
    );
    assert_close(
        segment_distance_mm(a, b, v(13.0, 0.0, 4.0)),
        5.0,
        "after the end",
    );
    assert_close(
        segment_distance_mm(a, a, v(3.0, 4.0, 0.0)),
        5.0,
        "zero length",
    );
}

#[test]
fn distance_to_an_arc_in_g17() {
    // G3 quarter from (10, 0) to (0, 10) about the origin, and the G2 three quarters.
    let ccw = arc(
        v(10.0, 0.0, 0.0),
        v(0.0, 10.0, 0.0),
        Vector3::zeros(),
        v(0.0, 0.0, 1.0),
    );
    assert_close(whole(&ccw, v(6.0, 8.0, 0.0)), 0.0, "on the arc");
    assert_close(whole(&ccw, v(9.0, 12.0, 0.0)), 5.0, "outside");
    assert_close(whole(&ccw, v(3.0, 4.0, 0.0)), 5.0, "inside");
    assert_close(whole(&ccw, v(9.0, 12.0, 1.0)), 26f64.sqrt(), "above");
    // (0, −10) is not on the quarter: the start is nearest.
    assert_close(
        whole(&ccw, v(0.0, -10.0, 0.0)),
        200f64.sqrt(),
        "past the start",
    );
    let cw = arc(
        v(10.0, 0.0, 0.0),
        v(0.0, 10.0, 0.0),
        Vector3::zeros(),
        v(0.0, 0.0, -1.0),
    );
    assert_close(whole(&cw, v(0.0, -12.0, 0.0)), 2.0, "on the long way round");
    assert_close(whole(&cw, v(6.0, 8.0, 0.0)), 40f64.sqrt(), "in the gap");
    // The centre is 10 from every point.
    assert_close(whole(&cw, Vector3::zeros()), 10.0, "centre");
}

#[test]
fn distance_to_an_arc_in_g18_and_g19() {
    // G18 (normal Y): from Z10 towards X10, a quarter about the origin.
    let zx = arc(
        v(0.0, 0.0, 10.0),
        v(10.0, 0.0, 0.0),
        Vector3::zeros(),
        v(0.0, 1.0, 0.0),
    );
    assert_close(zx.sweep_rad, FRAC_PI_2, "G18 sweep");
    assert_close(
        whole(&zx, v(9.0, 2.0, 12.0)),
        29f64.sqrt(),
        "G18 outside, off the plane",
    );
    assert_close(
        whole(&zx, v(-10.0, 0.0, 0.0)),
        200f64.sqrt(),
        "G18 past the start",
    );
    // G19 (normal X): from Y10 towards Z10.
    let yz = arc(
        v(0.0, 10.0, 0.0),
        v(0.0, 0.0, 10.0),
        Vector3::zeros(),
        v(1.0, 0.0, 0.0),
    );
    assert_close(yz.sweep_rad, FRAC_PI_2, "G19 sweep");
    assert_close(whole(&yz, v(3.0, 6.0, 8.0)), 3.0, "G19 off the plane");
    assert_close(whole(&yz, v(0.0, 3.0, 4.0)), 5.0, "G19 inside");
}

#[test]
fn distance_to_a_helix() {
    // One turn of radius 10 rising 2π (c = 1 mm/rad) about Z.
    let h = ArcGeometry::new(
        v(10.0, 0.0, 0.0),
        v(10.0, 0.0, TAU),
        Vector3::zeros(),
        v(0.0, 0.0, 1.0),
        0,
    )
    .unwrap();
    assert_close(h.sweep_rad, TAU, "a full turn");
    // On the axis within the rise: the radius.
    assert_close(whole(&h, v(0.0, 0.0, PI)), 10.0, "on the axis");
    // Radially out from P(θ) by 2: 244 − 240·cos δ + δ² is smallest at δ = 0.
    let theta: f64 = 2.0;
    let q = v(12.0 * theta.cos(), 12.0 * theta.sin(), theta);
    assert_close(whole(&h, q), 2.0, "radially out");
    // Along the binormal of P(θ) by 0.5: in its normal plane, well within the curvature.
    let s = theta / TAU;
    let t = h.tangent_at(s);
    let inward = -v(theta.cos(), theta.sin(), 0.0);
    let b = t.cross(&inward);
    assert_close(whole(&h, h.point_at(s) + b * 0.5), 0.5, "binormal");
    // Below the start on the axis: the start is nearest (√(100 + 9)).
    assert_close(whole(&h, v(0.0, 0.0, -3.0)), 109f64.sqrt(), "below");
    // Three turns: the middle turn is nearest to a point at its height.
    let h3 = ArcGeometry::new(
        v(10.0, 0.0, 0.0),
        v(10.0, 0.0, 3.0),
        Vector3::zeros(),
        v(0.0, 0.0, 1.0),
        2,
    )
    .unwrap();
    assert_close(whole(&h3, v(11.0, 0.0, 1.0)), 1.0, "second of three turns");
}

#[test]
fn distance_to_a_spiral_arc() {
    // A quarter from radius 10 to 11 (the end radius differs, as the arc tolerance allows):
    // P(s) = (10 + s)(cos(sπ/2), sin(sπ/2)).
    let sp = arc(
        v(10.0, 0.0, 0.0),
        v(0.0, 11.0, 0.0),
        Vector3::zeros(),
        v(0.0, 0.0, 1.0),
    );
    assert_close(sp.end_radius_mm, 11.0, "end radius");
    assert_close(
        whole(&sp, Vector3::zeros()),
        10.0,
        "centre: the smallest radius",
    );
    // f(s) = r² + 400 − 40 r sin(sπ/2) decreases up to s = 1 (f'(1) = 22 − 40 < 0): the end.
    assert_close(whole(&sp, v(0.0, 20.0, 0.0)), 9.0, "beyond the end");
    assert_close(
        whole(&sp, sp.point_at(0.5) + v(0.0, 0.0, 3.0)),
        3.0,
        "above the middle",
    );
    // In the plane, along the normal of P(0.5).
    let side = v(0.0, 0.0, 1.0).cross(&sp.tangent_at(0.5));
    let (d, s) = arc_distance_mm(&sp, 0.0, 1.0, sp.point_at(0.5) + side * 0.01);
    assert_close(d, 0.01, "beside the middle");
    assert!((s - 0.5).abs() < 1e-9, "at s = {s}");
    // A part of it: [0, 0.25] has its end nearest to P(0.5).
    let (d, s) = arc_distance_mm(&sp, 0.0, 0.25, sp.point_at(0.5));
    assert_eq!(s, 0.25);
    assert_close(d, (sp.point_at(0.25) - sp.point_at(0.5)).norm(), "a part");
}

/// A deterministic stream of numbers in [0, 1).
struct Lcg(u64);

impl Lcg {
    fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }

    fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.next()
    }
}

/// Random arcs (any plane, helices, spirals, several turns) and points near them: the
/// distance is never more than a sampling of 200 000 points gives, nor less than it by more
/// than the sampling's resolution allows.
#[test]
fn arc_distances_agree_with_a_dense_sampling() {
    let mut rng = Lcg(11);
    for case in 0..60 {
        let normal = [v(0.0, 0.0, 1.0), v(0.0, 1.0, 0.0), v(1.0, 0.0, 0.0)][case % 3]
            * if case % 2 == 0 { 1.0 } else { -1.0 };
        let (a, b, _) = match case % 3 {
            0 => (0, 1, 2),
            1 => (2, 0, 1),
            _ => (1, 2, 0),
        };
        let r0 = rng.range(0.2, 20.0);
        let r1 = r0 * (1.0 + rng.range(-0.05, 0.05));
        let a0 = rng.range(0.0, TAU);
        let a1 = rng.range(0.0, TAU);
        let mut start = Vector3::zeros();
        start[a] = r0 * a0.cos();
        start[b] = r0 * a0.sin();
        let mut end = start;
        end[a] = r1 * a1.cos();
        end[b] = r1 * a1.sin();
        end += normal * rng.range(-30.0, 30.0) * f64::from(u8::from(case % 4 != 0));
        let turns = (case % 5) as u32 / 2;
        let g = ArcGeometry::new(start, end, Vector3::zeros(), normal, turns).unwrap();
        let n = 200_000;
        let spacing = g.length_mm / n as f64 + (r1 - r0).abs() / n as f64;
        for _ in 0..20 {
            let s = rng.range(-0.1, 1.1);
            let scale = [0.001, 0.1, 1.0, 10.0][rng.range(0.0, 4.0) as usize];
            let off = v(
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
            ) * scale;
            let q = g.point_at(s) + off;
            let (d, _) = arc_distance_mm(&g, 0.0, 1.0, q);
            let dense = (0..=n)
                .map(|k| (g.point_at(k as f64 / n as f64) - q).norm())
                .fold(f64::INFINITY, f64::min);
            assert!(
                d <= dense + 1e-12 && d >= dense - spacing,
                "case {case}: {d} mm against {dense} mm sampled ({g:?}, q {q:?})"
            );
        }
    }
}

fn items(text: &str) -> Vec<Item> {
    parse_program(text, "t.ngc", Vector3::zeros())
        .expect("program")
        .items
}

const TOL: Tolerances = Tolerances {
    chord_tol_mm: 0.001,
    default_tolerance_mm: 0.01,
};

#[test]
fn the_tolerance_follows_the_blend_mode_and_the_larger_at_a_junction() {
    let text = "G21 G90 G17\nG64 P0.05 G1 X10 F600\nG64 G1 Y10\nG64 P0 G1 X0\nG61 G1 Y0\n\
                G61.1 G1 X-10\nG64 P0.2 G1 Y-10\n";
    let path = Path::new(Vector3::zeros(), &items(text), &TOL);
    let tol: Vec<(usize, f64)> = path
        .pieces
        .iter()
        .map(|p| (p.line, p.tolerance_mm))
        .collect();
    assert_eq!(
        tol,
        [
            (2, 0.05),
            (3, 0.05),
            (3, 0.01),
            (4, 0.01),
            (4, 0.001),
            (5, 0.001),
            (6, 0.001),
            (6, 0.2),
            (7, 0.2),
        ]
    );
    // Half-way along line 3 (X10 Y5 is its middle) both halves meet.
    assert_eq!(path.pieces[1].shape.distance_mm(v(10.0, 5.0, 0.0)), 0.0);
}

/// Every sample's ratio, by a search of every piece.
fn brute_force_worst(path: &Path, samples: &[Vector3<f64>]) -> (f64, usize) {
    samples
        .iter()
        .enumerate()
        .map(|(k, q)| {
            let r = path
                .pieces
                .iter()
                .map(|p| p.shape.distance_mm(*q) / (p.tolerance_mm + ROUND_MM))
                .fold(f64::INFINITY, f64::min);
            (r, k + 1)
        })
        .fold((0.0, 0), |a, b| if b.0 > a.0 { b } else { a })
}

fn samples(text: &str, cfg: &PlannerConfig) -> (Vec<Item>, Vec<Vector3<f64>>) {
    let prog = parse_program(text, "t.ngc", Vector3::zeros()).unwrap();
    let plan = plan_with(&prog, &random_programs::limits(), cfg).unwrap();
    let mut interp = Interpolator::new(plan, cfg.period_s).unwrap();
    let mut out = Vec::new();
    let mut q = Vector3::zeros();
    while !interp.is_finished() {
        interp.update(&mut q);
        out.push(q);
    }
    (prog.items, out)
}

/// A program that passes the same places again (a square twice, then tiny chords of a
/// circle over it), blended: the cursor's window finds the same worst ratio as a search of
/// every piece, on the same sample.
#[test]
fn the_tracking_finds_what_a_search_of_every_piece_finds() {
    let mut text = String::from("G21 G90 G17 G64 P0.02 G0 X0 Y0\n");
    for _ in 0..2 {
        text.push_str("G1 X20 F6000\nY20\nX0\nY0\n");
    }
    text.push_str("G64 P0.005\n");
    for k in 0..=400 {
        let a = k as f64 / 400.0 * TAU;
        text.push_str(&format!(
            "G1 X{:.4} Y{:.4}\n",
            10.0 + 10.0 * a.cos(),
            10.0 * a.sin()
        ));
    }
    text.push_str("G3 X20 Y0 Z2 I-10 J0 P2\nM2\n");
    for profile in [ProfileKind::Trapezoid, ProfileKind::SCurve] {
        let cfg = random_programs::config(profile);
        let (items, qs) = samples(&text, &cfg);
        let path = Path::new(Vector3::zeros(), &items, &Tolerances::of(&cfg));
        let mut checker = Checker::new(&path);
        for q in &qs {
            checker.push(*q);
        }
        let report = checker.finish();
        let worst = report.worst.unwrap();
        let (ratio, sample) = brute_force_worst(&path, &qs);
        assert_eq!(
            (worst.ratio, worst.sample),
            (ratio, sample as u64),
            "{profile:?}"
        );
        assert!(
            report.whole_path_searches < qs.len() as u64 / 10,
            "{profile:?}: {} searches of the whole path for {} samples",
            report.whole_path_searches,
            qs.len()
        );
        println!(
            "{profile:?}: worst ratio {ratio} at sample {sample} of {}, {} whole-path searches",
            qs.len(),
            report.whole_path_searches
        );
    }
}

/// The same setpoints moved by 5 µm across the path are reported off it under G61 (chord
/// tolerance 1 µm), with the distance, the tolerance and the ratio.
#[test]
fn a_setpoint_stream_moved_off_the_path_is_caught() {
    let text = "G21 G90 G17 G61\nG1 X20 F3000\nG1 Y10\nG2 X30 Y20 I10 J0\nG4 P0.1\nG1 X40\nM2\n";
    let cfg = random_programs::config(ProfileKind::SCurve);
    let (items, qs) = samples(text, &cfg);
    let path = Path::new(Vector3::zeros(), &items, &Tolerances::of(&cfg));
    let run = |offset: Vector3<f64>| {
        let mut checker = Checker::new(&path);
        for q in &qs {
            checker.push(q + offset);
        }
        checker.finish()
    };
    // As planned: within the tolerance, stops on the path, the end exact.
    let report = run(Vector3::zeros());
    report.check().expect("the setpoints as planned");
    // The dwell (a G61 corner is passed at rest for an instant, not two samples).
    assert!(
        report
            .stops
            .iter()
            .any(|s| s.position_mm == v(30.0, 20.0, 0.0)),
        "stops: {:?}",
        report.stops
    );
    assert!(report.max_at_rest_mm() < 1e-9);
    // Moved by 5 µm along Z: every sample is 5 µm off, 5× the chord tolerance.
    let report = run(v(0.0, 0.0, 0.005));
    match report.check() {
        Err(Deviation::OffPath {
            ratio,
            distance_mm,
            tolerance_mm,
            ..
        }) => {
            // 5 µm across, on top of the up to 1 µm the arc's chord rule allows in the plane.
            assert!((0.005..=0.00510).contains(&distance_mm), "{distance_mm} mm");
            assert_eq!(tolerance_mm, 0.001);
            // (Down to the offset alone: the moves alone bypass the axis filters, exactly on
            // the path; a ratio is over the tolerance plus 1 nm.)
            assert!((4.999..=5.1).contains(&ratio), "ratio {ratio}");
        }
        other => panic!("expected OffPath, got {other:?}"),
    }
}

/// Under G64 P0.01 a stream moved by 5 µm is within the tolerance on the way, but not at the
/// dwell's stop (1 µm); moved by 0.5 µm it is within both, and its end is not exact.
#[test]
fn a_stream_off_the_path_at_rest_or_at_the_end_is_caught() {
    let text = "G21 G90 G17 G64 P0.01\nG1 X20 F3000\nG1 Y10\nG4 P0.1\nG1 X0\nM2\n";
    let cfg = random_programs::config(ProfileKind::SCurve);
    let (items, qs) = samples(text, &cfg);
    let path = Path::new(Vector3::zeros(), &items, &Tolerances::of(&cfg));
    let run = |offset: Vector3<f64>| {
        let mut checker = Checker::new(&path);
        for q in &qs {
            checker.push(q + offset);
        }
        checker.finish()
    };
    run(Vector3::zeros()).check().expect("as planned");
    let report = run(v(0.0, 0.0, 0.005));
    // 5 µm across the plane of the path, on top of what the blends and filters take.
    let worst = report.worst.unwrap().ratio;
    assert!((0.4999..=1.0).contains(&worst), "ratio {worst}");
    match report.check() {
        Err(Deviation::OffPathAtRest {
            line, distance_mm, ..
        }) => {
            assert!(
                matches!(line, 3 | 5),
                "the dwell is between lines 3 and 5: {line}"
            );
            assert!((distance_mm - 0.005).abs() < 1e-9, "{distance_mm} mm");
        }
        other => panic!("expected OffPathAtRest, got {other:?}"),
    }
    let report = run(v(0.0, 0.0, 0.0005));
    assert!(report.max_at_rest_mm() <= AT_REST_MM);
    assert!(matches!(report.check(), Err(Deviation::EndNotExact { .. })));
    // The same through `measure`, as planned.
    let prog = parse_program(text, "t.ngc", Vector3::zeros()).unwrap();
    let plan = plan_with(&prog, &random_programs::limits(), &cfg).unwrap();
    let report = measure(&path, plan, cfg.period_s).unwrap();
    assert_eq!(report.samples, qs.len() as u64);
    report.check().expect("measured as planned");
}
