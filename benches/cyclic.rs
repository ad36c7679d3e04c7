//! Cost of the cyclic part of a run, per cycle, for 6 axes: `Interpolator::update` on the plan of
//! a program of lines, arcs and a helix, the post-interpolation filter of each of the 6 axes (X,
//! Y, Z from the sample, and three more fed from combinations of them, standing for A, B, C),
//! and the conversion of the 6 setpoints to counts. The machine is
//! `dictionaries/machines/bench-6ax-2ms.toml` (6 axes, 2 ms cycle).
//!
//! `cargo bench --bench cyclic`

use std::hint::black_box;
use std::path::Path;
use std::time::{Duration, Instant};

use canmotion::config::Machine;
use canmotion::interp::Interpolator;
use canmotion::interp::filter::{AxisFilter, FilterKind, FilterSpec};
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

criterion_group!(benches, bench_cycle);
criterion_main!(benches);
