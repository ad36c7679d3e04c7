//! Cost of the cyclic part of a run, per cycle, for 6 axes: `Interpolator::update` on the plan of
//! a program of lines, arcs and a helix, the post-interpolation filter of each of the 6 axes (X,
//! Y, Z from the sample, and three more fed from combinations of them, standing for A, B, C),
//! and the conversion of the 6 setpoints to counts. The machine is
//! `dictionaries/machines/bench-6ax-2ms.toml` (6 axes, 2 ms cycle).
//!
//! A second group runs the same cycle (no filter) at a feed override of 200 %, on the machine's
//! own look-ahead plan of that program and of a circle of 0.05 mm segments: above 100 % every
//! cycle checks that the override can still come down under the plan's ceiling in time, a walk
//! over the segments ahead (most of them on the tiny-segment circle).
//!
//! `cargo bench --bench cyclic`

use std::hint::black_box;
use std::path::Path;
use std::time::{Duration, Instant};

use canmotion::config::Machine;
use canmotion::interpolator::filter::{AxisFilter, FilterKind, FilterSpec};
use canmotion::interpolator::{Interpolator, OverrideRamp};
use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::Vector3;

/// A pocket outline with rounded corners, a helical plunge and a diagonal: lines and arcs at
/// 50 mm/s, rapids at the machine's speed.
const PROGRAM: &str = "\
G21 G90 G17
G0 X10 Y10 Z5
G1 Z-1 F600
G1 X60 F3000
G3 X70 Y20 I0 J10
G1 Y60
G3 X60 Y70 I-10 J0
G1 X20
G3 X10 Y60 I0 J-10
G1 Y20
G2 X30 Y20 Z-2 I10 J0
G1 X40 Y40 Z-1
G2 X40 Y40 I5 J5
G0 Z5
M2
";

fn machine() -> Machine {
    Machine::load(
        &Path::new(env!("CARGO_MANIFEST_DIR")).join("dictionaries/machines/bench-6ax-2ms.toml"),
    )
    .expect("the bench machine loads")
}

/// The six axis inputs of one sample: X, Y, Z, and three combinations for A, B, C.
fn inputs(p: &Vector3<f64>) -> [f64; 6] {
    [p.x, p.y, p.z, p.x + p.y, p.y - p.z, 0.5 * p.x + p.z]
}

fn bench_cycle(c: &mut Criterion) {
    let m = machine();
    assert_eq!(m.axes.len(), 6);
    let period_s = m.cycle_s();
    let start = Vector3::zeros();
    let program = canmotion::gcode::parse_program(PROGRAM, "bench.ngc", start).unwrap();
    let plan = canmotion::planner::plan(&program, &canmotion::gateway::limits(&m)).unwrap();
    let fresh = Interpolator::new(plan, period_s).unwrap();
    let samples = fresh.total_samples();
    assert!(samples > 1000, "{samples} cycles");

    let specs = [
        ("none", None),
        (
            "linear 8 ms",
            Some(FilterSpec {
                kind: FilterKind::Linear,
                time_s: 0.008,
            }),
        ),
        (
            "exponential 4 ms",
            Some(FilterSpec {
                kind: FilterKind::Exponential,
                time_s: 0.004,
            }),
        ),
    ];
    for (name, spec) in specs {
        let mut filters: Vec<Option<AxisFilter>> = (0..6)
            .map(|_| spec.map(|s| AxisFilter::new(s, period_s).unwrap()))
            .collect();
        c.bench_function(&format!("cyclic/6 axes/{name}"), |b| {
            // One iteration is one cycle; the interpolator is renewed (untimed) when the
            // program ends, so that every timed cycle samples the plan.
            b.iter_custom(|iters| {
                let mut total = Duration::ZERO;
                let mut done = 0;
                while done < iters {
                    let mut interp = fresh.clone();
                    let at = inputs(&start);
                    for (f, x) in filters.iter_mut().zip(at) {
                        if let Some(f) = f {
                            f.reset(x);
                        }
                    }
                    let n = (iters - done).min(samples);
                    let mut p = Vector3::zeros();
                    let mut counts = [0i32; 6];
                    let t0 = Instant::now();
                    for _ in 0..n {
                        black_box(interp.update(&mut p));
                        let x = inputs(black_box(&p));
                        for (i, a) in m.axes.iter().enumerate() {
                            let y = match &mut filters[i] {
                                Some(f) => f.update(x[i]),
                                None => x[i],
                            };
                            counts[i] = a.mm_to_counts(y);
                        }
                        black_box(&counts);
                    }
                    total += t0.elapsed();
                    done += n;
                }
                total
            })
        });
    }
}

/// A circle of radius 20 mm as 2,513 lines of 0.05 mm at 50 mm/s.
fn tiny_circle() -> String {
    let n = 2513;
    let mut text = String::from("G21 G90 G17 G64\nG0 X20 Y0\n");
    for i in 1..=n {
        let a = std::f64::consts::TAU * i as f64 / n as f64;
        text += &format!("G1 X{:.6} Y{:.6} F3000\n", 20.0 * a.cos(), 20.0 * a.sin());
    }
    text + "M2\n"
}

fn bench_override(c: &mut Criterion) {
    let m = machine();
    let period_s = m.cycle_s();
    let start = Vector3::zeros();
    let limits = canmotion::gateway::limits(&m);
    let ramp = OverrideRamp::for_machine(&limits, &m.planner).unwrap();
    // The jerk-limited mode: the time-law filter and the two axis filters run in `update`.
    let s_curve = canmotion::planner::PlannerConfig {
        profile: canmotion::planner::ProfileKind::SCurve,
        ..m.planner
    };
    for (name, text, config) in [
        ("pocket", PROGRAM.to_string(), m.planner),
        ("tiny circle", tiny_circle(), m.planner),
        ("pocket, s-curve filters", PROGRAM.to_string(), s_curve),
        ("tiny circle, s-curve filters", tiny_circle(), s_curve),
    ] {
        let program = canmotion::gcode::parse_program(&text, "bench.ngc", start).unwrap();
        let plan = canmotion::planner::plan_with(&program, &limits, &config).unwrap();
        assert_eq!(
            plan.smoothing().is_some(),
            config.profile == canmotion::planner::ProfileKind::SCurve
        );
        let mut fresh = Interpolator::new(plan, period_s)
            .unwrap()
            .with_override_ramp(ramp);
        fresh.set_override(2.0).unwrap();
        c.bench_function(&format!("cyclic/6 axes/override 200 %/{name}"), |b| {
            b.iter_custom(|iters| {
                let mut total = Duration::ZERO;
                let mut done = 0;
                while done < iters {
                    let mut interp = fresh.clone();
                    let mut p = Vector3::zeros();
                    let mut counts = [0i32; 6];
                    let t0 = Instant::now();
                    while done < iters {
                        let status = black_box(interp.update(&mut p));
                        let x = inputs(black_box(&p));
                        for (i, a) in m.axes.iter().enumerate() {
                            counts[i] = a.mm_to_counts(x[i]);
                        }
                        black_box(&counts);
                        done += 1;
                        if status == canmotion::interpolator::Status::Finished {
                            break;
                        }
                    }
                    total += t0.elapsed();
                }
                total
            })
        });
    }
}

criterion_group!(benches, bench_cycle, bench_override);
criterion_main!(benches);
