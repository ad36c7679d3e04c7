//! The worked example of `shared/seeds` 000 (Chen & Feng, 2010) on its own parameters
//! (`dictionaries/machines/seed000.toml`: T = 4 ms, corner a_max = 0.5 g, path acceleration
//! 200 mm/s²). The paper's Table 1: stopping at every junction 809…871 periods (3.484 s), its
//! own method 3.236 s; the issue asks for at most 3.20 s with no limit broken.

use std::path::Path;

use canmotion::config::Machine;
use canmotion::gateway::plan_program;
use canmotion::interpolator::Interpolator;
use canmotion::planner::PlannerConfig;
use nalgebra::Vector3;

fn seed000() -> (Machine, String) {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let m = Machine::load(&root.join("dictionaries/machines/seed000.toml")).expect("machine");
    let text = std::fs::read_to_string(root.join("tests/programs/seed000.ngc")).unwrap();
    (m, text)
}

#[test]
fn the_worked_example_runs_in_at_most_3_20_s_with_continuous_junction_speeds() {
    let (m, text) = seed000();
    let plan = plan_program(&m, "seed000.ngc", &text, Vector3::zeros()).expect("plan");
    let segs = plan.segments();
    assert_eq!(segs.len(), 4);
    assert!(
        plan.duration_s() <= 3.20,
        "program time {} s",
        plan.duration_s()
    );

    // Each junction speed is eq. 5's, v = T·a / √(2(1 − cos θ)), under the two feeds (25 and
    // 16.67 mm/s), computed here from the program's points.
    let p: [Vector3<f64>; 5] = [
        [0.0, 0.0, 0.0],
        [10.0, 10.0, 0.0],
        [0.0, 0.0, 14.142],
        [0.0, 10.0, 0.0],
        [10.0, 10.0, 0.0],
    ]
    .map(Vector3::from);
    let feed = [25.0, 25.0, 1000.0 / 60.0, 1000.0 / 60.0];
    let (t, a): (f64, f64) = (0.004, 0.5 * 9806.65);
    for k in 0..3 {
        let u1 = (p[k + 1] - p[k]).normalize();
        let u2 = (p[k + 2] - p[k + 1]).normalize();
        let eq5 = t * a / (2.0 * (1.0 - u1.dot(&u2))).sqrt();
        let want = eq5.min(feed[k]).min(feed[k + 1]);
        assert!(
            (segs[k].v_end_mm_s - want).abs() < 1e-9,
            "junction {k}: {} mm/s, eq. 5 gives {want}",
            segs[k].v_end_mm_s
        );
        assert_eq!(segs[k].v_end_mm_s, segs[k + 1].v_start_mm_s);
    }
    assert_eq!((segs[0].v_start_mm_s, segs[3].v_end_mm_s), (0.0, 0.0));

    // Stopping at every junction, the same machine takes longer (the paper: 3.484 s with its
    // whole periods).
    let mut stop = m.clone();
    stop.planner = PlannerConfig {
        corner_acc_mm_s2: 0.0,
        ..m.planner
    };
    let stopped = plan_program(&stop, "seed000.ngc", &text, Vector3::zeros()).unwrap();
    assert!(
        (3.40..3.50).contains(&stopped.duration_s()),
        "{}",
        stopped.duration_s()
    );
}

#[test]
fn the_worked_example_breaks_no_limit_on_the_setpoints() {
    let (m, text) = seed000();
    no_limit_broken(&m, &text);
}

/// The setpoints of the example on `m` keep the axis and path limits, and the end is exact.
fn no_limit_broken(m: &Machine, text: &str) {
    let plan = plan_program(m, "seed000.ngc", text, Vector3::zeros()).unwrap();
    let end = plan.end_mm();
    let t = m.cycle_s();
    let mut interp = Interpolator::new(plan, t).unwrap();
    let mut samples = vec![Vector3::zeros()];
    let mut q = Vector3::zeros();
    while !interp.is_finished() {
        interp.update(&mut q);
        samples.push(q);
    }
    assert_eq!(*samples.last().unwrap(), end);
    let (vel, acc) = (200.0, 4903.325);
    for w in samples.windows(3) {
        let step = w[1] - w[0];
        let second = w[2] - 2.0 * w[1] + w[0];
        for (i, (d1, d2)) in step.iter().zip(second.iter()).enumerate() {
            let (v, a) = (d1.abs() / t, d2.abs() / (t * t));
            assert!(v <= vel, "axis {i}: {v} mm/s");
            assert!(a <= acc * 1.01, "axis {i}: {a} mm/s²");
        }
        // Path speed within the programmed feed (25 mm/s); path acceleration within the
        // corner's 0.5 g for the turn of the velocity vector plus the 200 mm/s² the profiles on
        // either side may use (when a junction falls on a sample, as with whole periods, one
        // second difference holds both).
        let v = (w[1] - w[0]).norm() / t;
        assert!(v <= 25.0 * 1.0001, "path speed {v}");
        let a = (w[2] - 2.0 * w[1] + w[0]).norm() / (t * t);
        assert!(a <= (acc + 200.0) * 1.01, "path acceleration {a}");
    }
}

#[test]
fn with_integer_periods_every_element_ends_on_a_sample_as_in_the_paper() {
    // 000's option: each element lasts a whole number of periods (the paper's 809 periods,
    // 3.236 s), its end point an interpolation point, with the same junction speeds.
    let (m, text) = seed000();
    let free = plan_program(&m, "seed000.ngc", &text, Vector3::zeros()).unwrap();
    let mut whole = m.clone();
    whole.planner.integer_periods = true;
    let plan = plan_program(&whole, "seed000.ngc", &text, Vector3::zeros()).unwrap();
    let t = whole.planner.period_s;
    for (s, f) in plan.segments().iter().zip(free.segments()) {
        let periods = s.duration_s() / t;
        assert!(
            (periods - periods.round()).abs() < 1e-6,
            "line {}: {periods} periods",
            s.line
        );
        assert_eq!(
            (s.v_start_mm_s, s.v_end_mm_s),
            (f.v_start_mm_s, f.v_end_mm_s)
        );
        assert!(s.duration_s() >= f.duration_s() && s.duration_s() < f.duration_s() + t);
    }
    let periods = (plan.duration_s() / t).round();
    assert!(periods <= 800.0, "{periods} periods (the paper: 809)");
    // Each element's end is a sample, exactly where the element ends.
    let mut interp = Interpolator::new(plan.clone(), t).unwrap();
    let mut q = Vector3::zeros();
    let mut k = 0u64;
    let ends: Vec<(u64, Vector3<f64>)> = plan
        .segments()
        .iter()
        .map(|s| ((s.end_time_s() / t).round() as u64, s.end_mm))
        .collect();
    for (at, end) in ends {
        while k < at {
            interp.update(&mut q);
            k += 1;
        }
        assert!((q - end).norm() < 1e-9, "sample {k}: {q:?} against {end:?}");
    }
    no_limit_broken(&whole, &text);
}
