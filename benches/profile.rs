//! Cost of the 1-D speed profiles: `plan` (look-ahead thread, per segment and pass) and `at`
//! (cyclic interpolator, every period for every axis).
//!
//! `cargo bench --bench profile`

use std::hint::black_box;

use canmotion::planner::profile::{
    JerkShape, PeakMethod, ProfileLimits, SpeedProfile, max_end_speed, plan,
};
use criterion::{Criterion, criterion_group, criterion_main};

fn limits(shape: JerkShape) -> ProfileLimits {
    ProfileLimits::new(200.0, 2000.0, 5.0e4, shape).unwrap()
}

/// One segment for each way of finding the peak: (name, L, v0, v1, expected method).
const CASES: [(&str, f64, f64, f64, PeakMethod); 4] = [
    ("at_vmax", 100.0, 0.0, 50.0, PeakMethod::AtVmax),
    ("quadratic", 20.0, 10.0, 60.0, PeakMethod::Quadratic),
    ("cubic", 0.5, 5.0, 5.0, PeakMethod::Cubic),
    ("bracketed", 3.0, 0.0, 55.0, PeakMethod::Bracketed),
];

fn bench_plan(c: &mut Criterion) {
    for shape in [JerkShape::Square, JerkShape::RaisedCosine] {
        let lim = limits(shape);
        for (name, l, v0, v1, method) in CASES {
            // The cases are chosen for the square pulses; raised-cosine ones (half the
            // effective jerk) may fall in another regime.
            let p = plan(l, v0, v1, &lim).unwrap();
            if shape == JerkShape::Square {
                assert_eq!(p.method(), method, "{name}");
            }
            c.bench_function(&format!("plan/{shape:?}/{name}"), |b| {
                b.iter(|| plan(black_box(l), black_box(v0), black_box(v1), &lim))
            });
        }
    }
    let trap = ProfileLimits::trapezoid(200.0, 2000.0).unwrap();
    c.bench_function("plan/trapezoid", |b| {
        b.iter(|| plan(black_box(20.0), black_box(10.0), black_box(60.0), &trap))
    });
    let lim = limits(JerkShape::Square);
    c.bench_function("max_end_speed/amax", |b| {
        b.iter(|| max_end_speed(black_box(5.0), black_box(10.0), &lim))
    });
    c.bench_function("max_end_speed/below_amax", |b| {
        b.iter(|| max_end_speed(black_box(0.2), black_box(10.0), &lim))
    });
    let p = plan(20.0, 10.0, 60.0, &lim).unwrap();
    c.bench_function("stretch_to_period/4ms", |b| {
        b.iter(|| black_box(&p).stretch_to_period(black_box(0.004)))
    });
}

/// `at` at successive periods of 1 ms over the whole profile, one call per iteration.
fn bench_at(c: &mut Criterion) {
    for shape in [JerkShape::Square, JerkShape::RaisedCosine] {
        let p: SpeedProfile = plan(100.0, 0.0, 0.0, &limits(shape)).unwrap();
        let n = (p.duration_s() / 1e-3) as usize;
        let mut k = 0usize;
        c.bench_function(&format!("at/{shape:?}"), |b| {
            b.iter(|| {
                k = if k >= n { 0 } else { k + 1 };
                black_box(&p).at(black_box(k as f64 * 1e-3))
            })
        });
    }
}

criterion_group!(benches, bench_plan, bench_at);
criterion_main!(benches);
