//! Tests of the speed profiles: hand-computed cases, then seeded property runs of what the
//! look-ahead and the interpolator rely on.

use std::sync::atomic::{AtomicUsize, Ordering::Relaxed};

use proptest::prelude::*;
use proptest::test_runner::{Config, RngSeed, TestCaseError, TestRunner};

use super::*;

fn square(v: f64, a: f64, j: f64) -> ProfileLimits {
    ProfileLimits::new(v, a, j, JerkShape::Square).unwrap()
}

fn cosine(v: f64, a: f64, j: f64) -> ProfileLimits {
    ProfileLimits::new(v, a, j, JerkShape::RaisedCosine).unwrap()
}

fn trap(v: f64, a: f64) -> ProfileLimits {
    ProfileLimits::trapezoid(v, a).unwrap()
}

fn close(a: f64, b: f64, rel: f64) -> bool {
    (a - b).abs() <= rel * a.abs().max(b.abs()).max(1e-300)
}

#[track_caller]
fn assert_close(a: f64, b: f64, rel: f64) {
    assert!(close(a, b, rel), "{a} != {b} (rel {rel})");
}

#[track_caller]
fn assert_phases(p: &SpeedProfile, expected: [f64; 7]) {
    let got = p.phase_durations_s();
    for (g, e) in got.iter().zip(expected) {
        assert!(
            (g - e).abs() <= 1e-12 * (1.0 + e),
            "{got:?} != {expected:?}"
        );
    }
}

// ---------------------------------------------------------------------------------------------
// Hand-computed cases.

#[test]
fn textbook_symmetric_rest_to_rest() {
    // 001 eqs. 14–21 with v0 = 0: T1 = amax/J = 0.01 s, T2 = (v − J·T1²)/amax = 0.09 s,
    // ramp 2·T1 + T2 = 0.11 s over v/2 · 0.11 = 5.5 mm; 20 mm leave 9 mm of cruise at 100 mm/s.
    let p = plan(20.0, 0.0, 0.0, &square(100.0, 1000.0, 1e5)).unwrap();
    assert_eq!(p.method(), PeakMethod::AtVmax);
    assert_phases(&p, [0.01, 0.09, 0.01, 0.09, 0.01, 0.09, 0.01]);
    assert_close(p.duration_s(), 0.31, 1e-12);
    // Eq. 14 at T1: a = J·T1, v = J·T1²/2, s = J·T1³/6.
    let s = p.at(0.01);
    assert_close(s.a_mm_s2, 1000.0, 1e-12);
    assert_close(s.v_mm_s, 5.0, 1e-12);
    assert_close(s.s_mm, 1e5 * 1e-6 / 6.0, 1e-12);
    // Eq. 15 at T1 + T2: v = J·T1²/2 + amax·T2 = 95.
    assert_close(p.at(0.10).v_mm_s, 95.0, 1e-12);
    assert_close(p.at(0.11).s_mm, 5.5, 1e-12);
    // Mid-cruise and the mirrored ramp (eqs. 19–21).
    assert_eq!(p.at(0.15).v_mm_s, 100.0);
    assert_close(p.at(0.20).s_mm, 14.5, 1e-12);
    assert_close(p.at(0.21).v_mm_s, 95.0, 1e-12);
    assert_close(p.at(0.30).v_mm_s, 5.0, 1e-12);
    let end = p.at(0.31);
    assert_eq!((end.s_mm, end.v_mm_s, end.a_mm_s2), (20.0, 0.0, 0.0));
    // Jerk: +J, 0, −J, 0, −J, 0, +J.
    let jerks: Vec<f64> = [0.005, 0.05, 0.105, 0.15, 0.205, 0.25, 0.305]
        .iter()
        .map(|t| p.at(*t).j_mm_s3)
        .collect();
    assert_eq!(jerks, vec![1e5, 0.0, -1e5, 0.0, -1e5, 0.0, 1e5]);
}

#[test]
fn short_segment_peaks_below_amax() {
    // vA = amax²/J = 10 mm/s. A peak of 4 mm/s: Tj = √(4/J), D = 2·4·Tj; no constant
    // acceleration, no cruise, peak acceleration √(4·J) ≈ 632 < 1000. v0 = v1: the cubic.
    let tj = (4.0f64 / 1e5).sqrt();
    let l = 8.0 * tj;
    let p = plan(l, 0.0, 0.0, &square(100.0, 1000.0, 1e5)).unwrap();
    assert_eq!(p.method(), PeakMethod::Cubic);
    assert_close(p.v_cruise_mm_s(), 4.0, 1e-12);
    assert_phases(&p, [tj, 0.0, tj, 0.0, tj, 0.0, tj]);
    assert_close(p.at(tj).a_mm_s2, 4e5f64.sqrt(), 1e-12);
    assert_close(p.at(2.0 * tj).v_mm_s, 4.0, 1e-12);
    assert_close(p.at(2.0 * tj).s_mm, l / 2.0, 1e-12);
    // The same with equal non-zero boundary speeds: 10 → 14 → 10 over 2·(10+14)·√(4/J).
    let l = 2.0 * 24.0 * tj;
    let p = plan(l, 10.0, 10.0, &square(100.0, 1000.0, 1e5)).unwrap();
    assert_eq!(p.method(), PeakMethod::Cubic);
    assert_close(p.v_cruise_mm_s(), 14.0, 1e-12);
}

#[test]
fn asymmetric_both_at_amax() {
    // 20 → 90 → 60: d(20,90) = 55·(70/1000 + 0.01) = 4.4, d(90,60) = 75·(30/1000 + 0.01) = 3.
    let p = plan(7.4, 20.0, 60.0, &square(100.0, 1000.0, 1e5)).unwrap();
    assert_eq!(p.method(), PeakMethod::Quadratic);
    assert_close(p.v_cruise_mm_s(), 90.0, 1e-12);
    assert_phases(&p, [0.01, 0.06, 0.01, 0.0, 0.01, 0.02, 0.01]);
    assert_eq!(p.at(0.0).v_mm_s, 20.0);
    assert_eq!(p.at(p.duration_s()).v_mm_s, 60.0);
}

#[test]
fn asymmetric_one_side_below_amax() {
    // 0 → 90 → 85: d(0,90) = 45·(0.09 + 0.01) = 4.5 (reaches amax); the 5 mm/s drop does not:
    // Tj = √(5/J), d(90,85) = 175·Tj. Bracketed solve.
    let tj = (5.0f64 / 1e5).sqrt();
    let p = plan(4.5 + 175.0 * tj, 0.0, 85.0, &square(100.0, 1000.0, 1e5)).unwrap();
    assert_eq!(p.method(), PeakMethod::Bracketed);
    assert_close(p.v_cruise_mm_s(), 90.0, 1e-12);
    assert_phases(&p, [0.01, 0.08, 0.01, 0.0, tj, 0.0, tj]);
    assert_close(p.at(0.1 + tj).a_mm_s2, -(5.0f64 * 1e5).sqrt(), 1e-12);
}

#[test]
fn pure_cruise_and_one_sided_profiles() {
    let lim = square(50.0, 1000.0, 1e5);
    let p = plan(10.0, 50.0, 50.0, &lim).unwrap();
    assert_phases(&p, [0.0, 0.0, 0.0, 0.2, 0.0, 0.0, 0.0]);
    assert_eq!(p.at(0.1).s_mm, 5.0);
    assert_eq!(p.at(0.1).a_mm_s2, 0.0);
    // 0 → 50 exactly over d(0,50) = 25·(0.05 + 0.01) = 1.5 mm: all acceleration.
    let p = plan(1.5, 0.0, 50.0, &lim).unwrap();
    assert!(p.phase_durations_s()[3] < 1e-12);
    assert_close(p.duration_s(), 0.06, 1e-12);
}

#[test]
fn infeasible_speeds_are_refused() {
    let lim = square(200.0, 1000.0, 1e5);
    // d(0,100) = 50·(0.1 + 0.01) = 5.5 mm; the trapezoid bound of 001 eq. 18 would say 5 mm.
    assert!(plan(5.4, 0.0, 100.0, &lim).is_none());
    assert!(plan(5.4, 100.0, 0.0, &lim).is_none());
    assert!(plan(5.0, 0.0, 100.0, &trap(200.0, 1000.0)).is_some());
    assert_close(max_end_speed(5.5, 0.0, &lim).unwrap(), 100.0, 1e-12);
    assert_close(max_start_speed(5.5, 0.0, &lim).unwrap(), 100.0, 1e-12);
    // Below vA (10 mm/s): v·√(v/J) = L.
    let l = 4.0 * (4.0f64 / 1e5).sqrt();
    assert_close(max_end_speed(l, 0.0, &lim).unwrap(), 4.0, 1e-12);
    // From 20 mm/s, the same length with (20 + v1)·√((v1 − 20)/J) = (40 + 4)·√(4/J) → 24.
    let l = 44.0 * (4.0f64 / 1e5).sqrt();
    assert_close(max_end_speed(l, 20.0, &lim).unwrap(), 24.0, 1e-12);
    // Capped at vmax.
    assert_eq!(max_end_speed(1e3, 0.0, &lim), Some(200.0));
    // Domain.
    assert!(plan(0.0, 0.0, 0.0, &lim).is_none());
    assert!(plan(1.0, 201.0, 0.0, &lim).is_none());
    assert!(plan(1.0, 0.0, -1.0, &lim).is_none());
    assert!(plan(f64::NAN, 0.0, 0.0, &lim).is_none());
    assert!(max_end_speed(1.0, 300.0, &lim).is_none());
    assert!(ProfileLimits::new(f64::NAN, 1.0, 1.0, JerkShape::Square).is_none());
    assert!(ProfileLimits::new(1.0, 0.0, 1.0, JerkShape::Square).is_none());
    assert!(ProfileLimits::new(1.0, 1.0, -1.0, JerkShape::Square).is_none());
    assert!(ProfileLimits::new(1.0, f64::INFINITY, 1.0, JerkShape::Square).is_none());
}

#[test]
fn raised_cosine_rest_to_vmax() {
    // Pulses of peak J change the acceleration by J·Tj/2: Tj = 2·amax/J = 0.02 s; the plateau
    // (100 − amax·Tj)/amax = 0.08 s. Length of the ramp v/2 · (2·Tj + Ta) = 6 mm.
    let lim = cosine(100.0, 1000.0, 1e5);
    let p = plan(20.0, 0.0, 0.0, &lim).unwrap();
    assert_phases(&p, [0.02, 0.08, 0.02, 0.08, 0.02, 0.08, 0.02]);
    // Peak jerk mid-pulse, zero jerk and exactly amax at the pulse end.
    assert_close(p.at(0.01).j_mm_s3, 1e5, 1e-12);
    assert!(p.at(0.0).j_mm_s3 == 0.0 && p.at(0.02).j_mm_s3 == 0.0);
    assert_close(p.at(0.02).a_mm_s2, 1000.0, 1e-12);
    // End of the first pulse: v = J·Tj²/4, s = J/2·Tj³·(1/6 − 1/(4π²)).
    assert_close(p.at(0.02).v_mm_s, 1e5 * 4e-4 / 4.0, 1e-12);
    let s1 = 0.5e5 * 8e-6 * (1.0 / 6.0 - 1.0 / (4.0 * PI * PI));
    assert_close(p.at(0.02).s_mm, s1, 1e-12);
    assert_close(p.at(0.12).s_mm, 6.0, 1e-12);
    // Jerk continuous: small near every pulse edge.
    for t in [
        1e-6,
        0.02 - 1e-6,
        0.02 + 1e-6,
        0.1 - 1e-6,
        0.1 + 1e-6,
        0.12 - 1e-6,
    ] {
        assert!(
            p.at(t).j_mm_s3.abs() < 1.0,
            "jerk {} at {t}",
            p.at(t).j_mm_s3
        );
    }
}

#[test]
fn trapezoid_matches_the_exact_stop_planner() {
    let cases = [
        (10.0, 10.0, 20.0, 30.0, 100.0),
        (2.0, 10.0, 20.0, 30.0, 100.0),
        (100.0, 0.0, 0.0, 50.0, 500.0),
        (0.1, 0.0, 0.0, 50.0, 500.0),
        (5.0, 30.0, 0.0, 30.0, 100.0),
        (7.0, 30.0, 30.0, 30.0, 100.0),
    ];
    for (l, v0, v1, vmax, a) in cases {
        let old = super::super::trapezoid(l, v0, v1, vmax, a).unwrap();
        let new = plan(l, v0, v1, &trap(vmax, a)).unwrap();
        let ph = new.phase_durations_s();
        assert_eq!([ph[0], ph[2], ph[4], ph[6]], [0.0; 4]);
        assert_close(new.v_cruise_mm_s(), old.v_peak_mm_s, 1e-12);
        assert_close(ph[1], old.t_acc_s, 1e-12);
        assert_close(ph[5], old.t_dec_s, 1e-12);
        assert!((ph[3] - old.t_cruise_s).abs() <= 1e-12 * new.duration_s());
    }
    assert!(plan(1.0, 0.0, 20.0, &trap(30.0, 100.0)).is_none());
    assert!(plan(1.0, 40.0, 0.0, &trap(30.0, 100.0)).is_none());
}

#[test]
fn evaluation_is_exact_at_phase_starts_and_the_end() {
    for lim in [
        square(80.0, 900.0, 3e4),
        cosine(80.0, 900.0, 3e4),
        trap(80.0, 900.0),
    ] {
        let p = plan(9.0, 12.0, 30.0, &lim).unwrap();
        let t = p.phase_start_times_s();
        for k in 0..7 {
            if t[k + 1] > t[k] {
                let s = p.at(t[k]);
                let st = p.start[k];
                assert_eq!((s.s_mm, s.v_mm_s, s.a_mm_s2), (st.s, st.v, st.a));
            }
        }
        let end = p.at(p.duration_s());
        assert_eq!(end, p.at(p.duration_s() + 1.0));
        assert_eq!((end.s_mm, end.v_mm_s, end.a_mm_s2), (9.0, 30.0, 0.0));
        assert_eq!(p.at(-1.0).s_mm, 0.0);
        assert_eq!(p.at(f64::NAN).v_mm_s, 12.0);
    }
}

#[test]
fn stretches_the_000_worked_example() {
    // 000's program with stops at every junction (its Table 1, "zero-speed junctions"), T = 4 ms,
    // a = 200 mm/s²: each segment L/F + F/a, rounded up to whole periods:
    // 14.142/25 + 0.125 → 173, 20/25 + 0.125 → 232, 17.321/16.667 + 0.0833 → 281,
    // 10/16.667 + 0.0833 → 171; 857 periods (the paper's per-zone rounding reports 871).
    let seg = |l: f64, f: f64| (l, f / 60.0);
    let segments = [
        seg(200f64.sqrt(), 1500.0),
        seg(400f64.sqrt(), 1500.0),
        seg(300f64.sqrt(), 1000.0),
        seg(10.0, 1000.0),
    ];
    let mut total = 0;
    for (l, f) in segments {
        let p = plan(l, 0.0, 0.0, &trap(f, 200.0)).unwrap();
        assert_close(p.duration_s(), l / f + f / 200.0, 1e-12);
        let (q, stretch) = p.stretch_to_period(0.004).unwrap();
        assert_eq!(stretch.periods, (p.duration_s() / 0.004).ceil() as u64);
        assert!((q.duration_s() - stretch.periods as f64 * 0.004).abs() < 1e-12);
        assert!(stretch.v_cruise_after_mm_s < f);
        assert_eq!(q.at(q.duration_s()).s_mm, l);
        check_profile(&q, l, 0.0, 0.0).unwrap();
        total += stretch.periods;
    }
    assert_eq!(total, 173 + 232 + 281 + 171);
}

#[test]
fn stretch_without_slack_is_an_error() {
    // Accelerating over the whole segment to the reachable maximum leaves no freedom.
    let lim = square(100.0, 1000.0, 1e5);
    let v1 = max_end_speed(2.0, 0.0, &lim).unwrap();
    let p = plan(2.0, 0.0, v1, &lim).unwrap();
    let err = p.stretch_to_period(0.004).unwrap_err();
    assert!(matches!(err, StretchError::NoSlack { .. }), "{err:?}");
    assert!(matches!(
        p.stretch_to_period(0.0),
        Err(StretchError::InvalidPeriod { .. })
    ));
    // A pure cruise stretches by dipping below the boundary speed.
    let p = plan(10.0, 100.0, 100.0, &lim).unwrap();
    let (q, s) = p.stretch_to_period(0.003).unwrap();
    assert_eq!(s.periods, 34);
    assert!(s.v_cruise_after_mm_s < 100.0);
    check_profile(&q, 10.0, 100.0, 100.0).unwrap();
}

#[test]
fn hostile_inputs_never_panic() {
    let values = [
        0.0,
        -1.0,
        1e-300,
        1e-12,
        1e-3,
        1.0,
        1e3,
        1e9,
        1e12,
        1e300,
        f64::INFINITY,
        f64::NAN,
    ];
    for &v in &values {
        for &a in &values {
            for &j in &values {
                for shape in [JerkShape::Square, JerkShape::RaisedCosine] {
                    let Some(lim) = ProfileLimits::new(v, a, j, shape) else {
                        continue;
                    };
                    for &l in &values {
                        for &v0 in &values {
                            let _ = max_end_speed(l, v0, &lim);
                            for &v1 in &values {
                                if let Some(p) = plan(l, v0, v1, &lim) {
                                    check_profile(&p, l, v0, v1).unwrap();
                                    let _ = p.stretch_to_period(1e-3);
                                }
                            }
                        }
                    }
                }
            }
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Invariants.

/// What a planner relies on, for any profile (time-optimal or stretched).
fn check_profile(p: &SpeedProfile, l: f64, v0: f64, v1: f64) -> Result<(), String> {
    let lim = p.limits();
    let (vmax, amax, jmax) = (lim.v_max_mm_s(), lim.a_max_mm_s2(), lim.j_max_mm_s3());
    let tol = 1e-9;
    let dur = p.duration_s();
    let ph = p.phase_durations_s();
    if !(dur.is_finite() && dur > 0.0) || ph.iter().any(|d| d.is_nan() || *d < 0.0) {
        return Err(format!("bad durations {ph:?}"));
    }
    let t = p.phase_start_times_s();
    // Phase by phase, the end of each non-empty phase meets the start of the next, and the last
    // one meets (L, v1, 0): the length is exact and the state continuous.
    let end = State {
        s: l,
        v: v1,
        a: 0.0,
    };
    let mut last_end = None;
    for (k, &dk) in ph.iter().enumerate() {
        if dk == 0.0 {
            continue;
        }
        let (st, _) = p.eval_phase(k, dk);
        let next = if k < 6 { p.start[k + 1] } else { end };
        let ds = (st.s - next.s).abs();
        let dv = (st.v - next.v).abs();
        let da = (st.a - next.a).abs();
        if ds > tol * l || dv > tol * vmax || (!lim.is_trapezoid() && da > tol * amax) {
            return Err(format!("phase {k} ends at {st:?}, next starts at {next:?}"));
        }
        last_end = Some(st);
    }
    if let Some(st) = last_end {
        let ok_a = lim.is_trapezoid() || st.a.abs() <= tol * amax;
        if (st.s - l).abs() > tol * l || (st.v - v1).abs() > tol * vmax || !ok_a {
            return Err(format!("ends at {st:?}, not ({l}, {v1}, 0)"));
        }
    }
    let first = p.at(0.0);
    let last = p.at(dur);
    // A trapezoid's acceleration jumps at the start (right-continuous).
    let a0 = if lim.is_trapezoid() {
        0.0
    } else {
        first.a_mm_s2
    };
    if (first.s_mm, first.v_mm_s, a0) != (0.0, v0, 0.0) {
        return Err(format!("starts at {first:?}"));
    }
    if last
        != (Sample {
            s_mm: l,
            v_mm_s: v1,
            a_mm_s2: 0.0,
            j_mm_s3: 0.0,
        })
    {
        return Err(format!("ends at {last:?}"));
    }
    // Samples: uniform, and on both sides of every phase boundary.
    let mut prev_s = 0.0;
    let n = 48;
    let mut times = [0.0; 48 + 16];
    for (i, ti) in times.iter_mut().take(n + 1).enumerate() {
        *ti = dur * i as f64 / n as f64;
    }
    for k in 1..8 {
        times[n + 2 * k - 1] = t[k] * (1.0 - 1e-12);
        times[n + 2 * k] = t[k];
    }
    times.sort_by(f64::total_cmp);
    for &ti in &times {
        let s = p.at(ti);
        let finite = s.s_mm.is_finite()
            && s.v_mm_s.is_finite()
            && s.a_mm_s2.is_finite()
            && s.j_mm_s3.is_finite();
        if !finite
            || s.v_mm_s < -tol * vmax
            || s.v_mm_s > vmax * (1.0 + tol)
            || s.a_mm_s2.abs() > amax * (1.0 + tol)
            || s.j_mm_s3.abs() > jmax * (1.0 + tol)
            || !(0.0..=l).contains(&s.s_mm)
            || s.s_mm < prev_s - tol * l
        {
            return Err(format!("at {ti}: {s:?}"));
        }
        prev_s = s.s_mm;
    }
    Ok(())
}

/// One random case: limits drawn on the scales of the problem (so that every regime occurs),
/// boundary speeds from a mix of special values, fractions and the reachability limits.
#[derive(Debug, Clone, Copy)]
struct Case {
    l: f64,
    v0: f64,
    v1: f64,
    lim: ProfileLimits,
}

fn cases() -> impl Strategy<Value = Case> {
    let kind = prop_oneof![1 => Just(0u8), 3 => Just(1u8), 3 => Just(2u8)];
    let speed = (0u8..8, 0.0..1.0f64);
    (
        kind,
        0.0..5.0f64,   // log10 amax
        -4.0..0.0f64,  // log10 amax/jmax (duration of a jerk phase)
        -2.0..2.0f64,  // log10 vmax/vA
        -3.0..1.5f64,  // log10 L / d(0, vmax)
        speed.clone(), // v0
        speed,         // v1
    )
        .prop_map(|(kind, la, ltj, lv, ll, (m0, f0), (m1, f1))| {
            let a = 10f64.powf(la);
            let j = a / 10f64.powf(ltj);
            let vmax = (a * a / j) * 10f64.powf(lv);
            let lim = match kind {
                0 => trap(vmax, a),
                1 => square(vmax, a, j),
                _ => cosine(vmax, a, j),
            };
            let l = transition_length_mm(0.0, vmax, &lim) * 10f64.powf(ll);
            let pick = |mode: u8, frac: f64| match mode {
                0 => Some(0.0),
                1 => Some(vmax),
                2 | 3 => Some(vmax * frac),
                4 => Some(vmax * frac * frac * frac),
                _ => None, // from the other speed
            };
            let (mut v0, mut v1) = (pick(m0, f0), pick(m1, f1));
            let derive = |mode: u8, other: f64| {
                let r = max_end_speed(l, other, &lim).unwrap();
                match mode {
                    5 => r,
                    6 => (r * (1.0 + 1e-9)).min(vmax),
                    _ => other,
                }
            };
            match (v0, v1) {
                (Some(x), None) => v1 = Some(derive(m1, x)),
                (None, Some(x)) => v0 = Some(derive(m0, x)),
                (None, None) => {
                    v0 = Some(vmax * f0);
                    v1 = Some(derive(m1, vmax * f0));
                }
                _ => {}
            }
            Case {
                l,
                v0: v0.unwrap(),
                v1: v1.unwrap(),
                lim,
            }
        })
}

fn config(default_cases: u32) -> Config {
    let cases = std::env::var("PROPTEST_CASES")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(default_cases);
    Config {
        cases,
        rng_seed: RngSeed::Fixed(0x5c0e_7e57),
        failure_persistence: None,
        ..Config::default()
    }
}

macro_rules! ensure {
    ($cond:expr, $($fmt:tt)*) => {
        let ok: bool = $cond;
        if !ok {
            return Err(TestCaseError::fail(format!($($fmt)*)));
        }
    };
}

fn shape_of(lim: &ProfileLimits, shape: JerkShape) -> ProfileLimits {
    ProfileLimits::new(
        lim.v_max_mm_s(),
        lim.a_max_mm_s2(),
        lim.j_max_mm_s3(),
        shape,
    )
    .unwrap()
}

/// Counters of what the property run covered.
#[derive(Default)]
struct Coverage {
    feasible: AtomicUsize,
    infeasible: AtomicUsize,
    methods: [AtomicUsize; 4],
    cruise: AtomicUsize,
    below_amax: AtomicUsize,
}

fn check_case(c: Case, cov: &Coverage) -> Result<(), TestCaseError> {
    let Case { l, v0, v1, lim } = c;
    let vmax = lim.v_max_mm_s();
    let p = plan(l, v0, v1, &lim);
    // `None` exactly when the reachability functions say so.
    let feasible = if v1 >= v0 {
        v1 <= max_end_speed(l, v0, &lim).unwrap()
    } else {
        v0 <= max_start_speed(l, v1, &lim).unwrap()
    };
    ensure!(p.is_some() == feasible, "plan {p:?}, feasible {feasible}");
    // The reachability limits are feasible, and 1e-9 above them is not.
    for (from_start, v) in [(true, v0), (false, v1)] {
        let r = if from_start {
            max_end_speed(l, v, &lim)
        } else {
            max_start_speed(l, v, &lim)
        }
        .unwrap();
        ensure!(r >= v && r <= vmax, "reach {r} from {v}");
        let ends = |w: f64| {
            if from_start {
                plan(l, v, w, &lim)
            } else {
                plan(l, w, v, &lim)
            }
        };
        ensure!(ends(r).is_some(), "reach {r} from {v} infeasible");
        let above = r * (1.0 + 1e-9);
        if above <= vmax {
            ensure!(
                ends(above).is_none(),
                "above reach {above} from {v} feasible"
            );
            // The closed form is the definition: the speed change takes the whole length.
            let d = transition_length_mm(v, r, &lim);
            ensure!(close(d, l, 1e-9), "reach {r} from {v}: d = {d}, L = {l}");
        }
    }
    let Some(p) = p else {
        cov.infeasible.fetch_add(1, Relaxed);
        return Ok(());
    };
    cov.feasible.fetch_add(1, Relaxed);
    let method = p.method() as usize;
    cov.methods[method.min(3)].fetch_add(1, Relaxed);
    let ph = p.phase_durations_s();
    if ph[3] > 1e-9 * p.duration_s() {
        cov.cruise.fetch_add(1, Relaxed);
    }
    if !lim.is_trapezoid() && (ph[1] == 0.0 || ph[5] == 0.0) && ph[0] > 0.0 {
        cov.below_amax.fetch_add(1, Relaxed);
    }
    check_profile(&p, l, v0, v1).map_err(TestCaseError::fail)?;
    // The peak is vmax, or the transitions take the whole length (the solve converged).
    if p.method() == PeakMethod::AtVmax {
        ensure!(p.v_cruise_mm_s() == vmax, "{p:?}");
    } else {
        // Within a few ulps of the largest feasible peak (the length of the transitions is
        // ill-conditioned in the peak when it is barely above a boundary speed).
        let vp = p.v_cruise_mm_s();
        let above = vp * (1.0 + 32.0 * f64::EPSILON);
        let d = transition_length_mm(v0, above, &lim) + transition_length_mm(above, v1, &lim);
        ensure!(above > vmax || d > l, "peak {vp} not the largest: {p:?}");
    }
    // Never faster than the trapezoid with the same amax; cosine never faster than square.
    let tp = plan(l, v0, v1, &trap(vmax, lim.a_max_mm_s2()));
    ensure!(tp.is_some(), "S-curve feasible, trapezoid not");
    let tp = tp.unwrap().duration_s();
    ensure!(
        tp <= p.duration_s() * (1.0 + 1e-12),
        "trapezoid {tp} > {p:?}"
    );
    if lim.shape() == JerkShape::RaisedCosine && !lim.is_trapezoid() {
        let sq = plan(l, v0, v1, &shape_of(&lim, JerkShape::Square));
        ensure!(sq.is_some(), "cosine feasible, square not");
        let sq = sq.unwrap().duration_s();
        ensure!(sq <= p.duration_s() * (1.0 + 1e-12), "square {sq} > {p:?}");
    }
    Ok(())
}

fn run_invariants(default_cases: u32) {
    let cov = Coverage::default();
    let mut runner = TestRunner::new(config(default_cases));
    runner
        .run(&cases(), |c| check_case(c, &cov))
        .unwrap_or_else(|e| panic!("{e}"));
    let n = |c: &AtomicUsize| c.load(Relaxed);
    let methods: Vec<usize> = cov.methods.iter().map(n).collect();
    eprintln!(
        "feasible {}, infeasible {}, methods [at vmax, quadratic, cubic, bracketed] {methods:?}, \
         with cruise {}, a jerk phase below amax {}",
        n(&cov.feasible),
        n(&cov.infeasible),
        n(&cov.cruise),
        n(&cov.below_amax)
    );
    if runner.config().cases >= 2000 {
        assert!(n(&cov.infeasible) > 0 && n(&cov.cruise) > 0 && n(&cov.below_amax) > 0);
        assert!(methods.iter().all(|m| *m > 0), "{methods:?}");
    }
}

#[test]
fn invariants_hold_over_random_inputs() {
    run_invariants(200_000);
}

/// `cargo test --lib planner::profile -- --ignored` (about a minute in debug).
#[test]
#[ignore]
fn invariants_hold_over_millions_of_random_inputs() {
    run_invariants(10_000_000);
}

// ---------------------------------------------------------------------------------------------
// Time optimality against a numeric reference.

/// A speed change integrated phase by phase with constant jerk (independent of the
/// mean-speed length formula of the module): `(duration, length)`.
fn reference_transition(va: f64, vb: f64, a: f64, j: f64) -> (f64, f64) {
    let dv = (vb - va).abs();
    let sg = if vb < va { -1.0 } else { 1.0 };
    let (tj, ap) = if j.is_infinite() {
        (0.0, a)
    } else if dv * j >= a * a {
        (a / j, a)
    } else {
        ((dv / j).sqrt(), (dv * j).sqrt())
    };
    let ta = if dv > 0.0 {
        (dv / ap - tj).max(0.0)
    } else {
        0.0
    };
    // A trapezoid's acceleration jumps (its jerk phases are empty).
    let (mut s, mut v) = (0.0, va);
    let mut acc = if j.is_infinite() { sg * ap } else { 0.0 };
    for (dur, jerk) in [(tj, sg * j), (ta, 0.0), (tj, -sg * j)] {
        if dur > 0.0 {
            s += dur * (v + dur * (acc / 2.0 + dur * jerk / 6.0));
            v += dur * (acc + dur * jerk / 2.0);
            acc += dur * jerk;
        }
    }
    (2.0 * tj + ta, s)
}

/// Shortest duration over a fine grid of cruise speeds `vc` in `(0, vmax]` (including dips
/// below the boundary speeds, outside the family), refined by bisection at the edge of the
/// feasible set. `(best in the family, best with a dip)`.
fn reference_duration(c: &Case) -> (Option<f64>, Option<f64>) {
    let lim = &c.lim;
    let a = lim.a_max_mm_s2();
    let j = match lim.shape() {
        JerkShape::Square => lim.j_max_mm_s3(),
        JerkShape::RaisedCosine => lim.j_max_mm_s3() / 2.0,
    };
    let vmax = lim.v_max_mm_s();
    let time = |vc: f64| {
        let (t0, d0) = reference_transition(c.v0, vc, a, j);
        let (t1, d1) = reference_transition(vc, c.v1, a, j);
        // Tolerant of the rounding of a profile that takes the whole length.
        let rest = c.l - d0 - d1;
        (rest >= -1e-12 * c.l).then(|| t0 + t1 + rest.max(0.0) / vc)
    };
    let lo = c.v0.max(c.v1);
    let mut best: [Option<f64>; 2] = [None, None];
    let mut consider = |vc: f64, t: Option<f64>| {
        let i = usize::from(vc < lo);
        if let Some(t) = t {
            best[i] = Some(best[i].map_or(t, |b: f64| b.min(t)));
        }
    };
    let n = 1500;
    let grid = |i: usize| vmax * i as f64 / n as f64;
    for i in 1..=n {
        let vc = grid(i);
        let t = time(vc);
        consider(vc, t);
        // At the edge of the feasible set, the last feasible speed by bisection.
        if t.is_some() && i < n && time(grid(i + 1)).is_none() {
            let (mut f, mut g) = (vc, grid(i + 1));
            for _ in 0..80 {
                let m = 0.5 * (f + g);
                if time(m).is_some() { f = m } else { g = m }
            }
            consider(f, time(f));
        }
    }
    for vc in [lo, vmax] {
        if vc > 0.0 {
            consider(vc, time(vc));
        }
    }
    (best[0], best[1])
}

#[test]
fn no_slower_than_a_numeric_reference() {
    run_reference(5000);
}

#[test]
#[ignore]
fn no_slower_than_a_numeric_reference_long() {
    run_reference(500_000);
}

fn run_reference(default_cases: u32) {
    let dips_faster = AtomicUsize::new(0);
    let compared = AtomicUsize::new(0);
    let mut runner = TestRunner::new(config(default_cases));
    runner
        .run(&cases(), |c| {
            let Some(p) = plan(c.l, c.v0, c.v1, &c.lim) else {
                return Ok(());
            };
            let (family, dip) = reference_duration(&c);
            let reference = family.ok_or_else(|| TestCaseError::fail("reference infeasible"))?;
            let t = p.duration_s();
            ensure!(t <= reference * (1.0 + 1e-6), "{t} > reference {reference}");
            compared.fetch_add(1, Relaxed);
            // Dipping below the boundary speeds (outside the family) is never faster.
            if dip.is_some_and(|d| d < t * (1.0 - 1e-9)) {
                dips_faster.fetch_add(1, Relaxed);
            }
            Ok(())
        })
        .unwrap_or_else(|e| panic!("{e}"));
    eprintln!("compared {}", compared.load(Relaxed));
    assert_eq!(dips_faster.load(Relaxed), 0);
}

// ---------------------------------------------------------------------------------------------
// Sampled like the interpolator samples, and stretched to whole periods.

/// Central differences of positions sampled every `T` agree with `v` and `a` within the Taylor
/// bounds `jmax·T²/6` and `jmax·T/3` (`amax·T/2` for `v` of a trapezoid, whose `a` jumps).
#[test]
fn finite_differences_agree_with_v_and_a() {
    let samples = AtomicUsize::new(0);
    let periods = prop_oneof![Just(1.0), Just(2.0), Just(4.0), 0.5..4.0f64];
    let mut runner = TestRunner::new(config(5000));
    runner
        .run(&(cases(), periods), |(c, period_ms)| {
            let Some(p) = plan(c.l, c.v0, c.v1, &c.lim) else {
                return Ok(());
            };
            // A period of at most a tenth of the profile, so that there are samples to compare.
            let t = (period_ms * 1e-3).min(p.duration_s() / 10.0);
            let (amax, jmax) = (c.lim.a_max_mm_s2(), c.lim.j_max_mm_s3());
            // Inside the segment only: it holds at L after its end.
            let steps = (p.duration_s() / t).floor().min(20_000.0) as usize;
            let stride = (steps / 2000).max(1);
            let round = 8.0 * f64::EPSILON * c.l;
            for k in (1..steps).step_by(stride) {
                let tk = k as f64 * t;
                let (sm, s0, sp) = (p.at(tk - t), p.at(tk), p.at(tk + t));
                let v_fd = (sp.s_mm - sm.s_mm) / (2.0 * t);
                let a_fd = (sp.s_mm - 2.0 * s0.s_mm + sm.s_mm) / (t * t);
                let v_tol = if c.lim.is_trapezoid() {
                    amax * t / 2.0
                } else {
                    jmax * t * t / 6.0
                };
                let v_err = (v_fd - s0.v_mm_s).abs();
                ensure!(
                    v_err <= v_tol * 1.000_001 + round / t,
                    "t {tk}: v {} vs {v_fd}",
                    s0.v_mm_s
                );
                if !c.lim.is_trapezoid() {
                    let a_err = (a_fd - s0.a_mm_s2).abs();
                    let a_tol = jmax * t / 3.0 * 1.000_001 + round / (t * t);
                    ensure!(a_err <= a_tol, "t {tk}: a {} vs {a_fd}", s0.a_mm_s2);
                }
                samples.fetch_add(1, Relaxed);
            }
            Ok(())
        })
        .unwrap_or_else(|e| panic!("{e}"));
    eprintln!("compared {} samples", samples.load(Relaxed));
}

/// A stretched profile lasts a whole number of periods, keeps the length, the boundary speeds
/// and the limits, and only ever lowers the cruise; or there was no slack.
#[test]
fn stretch_to_whole_periods() {
    let (stretched, no_slack) = (AtomicUsize::new(0), AtomicUsize::new(0));
    let periods = prop_oneof![Just(1.0), Just(2.0), Just(4.0), 0.25..8.0f64];
    let mut runner = TestRunner::new(config(20_000));
    runner
        .run(&(cases(), periods), |(c, period_ms)| {
            let Some(p) = plan(c.l, c.v0, c.v1, &c.lim) else {
                return Ok(());
            };
            let t = period_ms * 1e-3;
            match p.stretch_to_period(t) {
                Ok((q, s)) => {
                    ensure!(s.periods == (p.duration_s() / t).ceil() as u64, "{s:?}");
                    let whole = s.periods as f64 * t;
                    let dur = q.duration_s();
                    ensure!((dur - whole).abs() <= 1e-9 * whole, "{dur} vs {whole}");
                    ensure!(dur >= p.duration_s() * (1.0 - 1e-15), "{dur} shorter");
                    ensure!(s.v_cruise_after_mm_s <= s.v_cruise_before_mm_s, "{s:?}");
                    check_profile(&q, c.l, c.v0, c.v1).map_err(TestCaseError::fail)?;
                    stretched.fetch_add(1, Relaxed);
                }
                Err(StretchError::NoSlack {
                    target_s,
                    longest_s,
                }) => {
                    ensure!(longest_s < target_s, "{longest_s} ≥ {target_s}");
                    no_slack.fetch_add(1, Relaxed);
                }
                Err(e) => return Err(TestCaseError::fail(e.to_string())),
            }
            Ok(())
        })
        .unwrap_or_else(|e| panic!("{e}"));
    eprintln!(
        "stretched {}, no slack {}",
        stretched.load(Relaxed),
        no_slack.load(Relaxed)
    );
}

#[test]
fn stopping_first_can_take_less_length_than_a_slow_start() {
    // Outside the family on purpose: from 0.4 to 4 mm/s below amax (vA = 10 mm/s),
    // d(0.4, 4) = 4.4·√(3.6/J) > d(0.4, 0) + d(0, 4) = 0.4·√(0.4/J) + 4·√(4/J). A profile that
    // stops and starts again fits where the direct one does not; `plan` (001's family: up,
    // cruise, down) refuses, and the look-ahead never asks (its passes stay within the direct
    // reach). Speeds reachable below v0 need not form an interval for the same reason.
    let lim = square(100.0, 1000.0, 1e5);
    let direct = transition_length_mm(0.4, 4.0, &lim);
    let stop_and_go = transition_length_mm(0.4, 0.0, &lim) + transition_length_mm(0.0, 4.0, &lim);
    assert_close(direct, 4.4 * (3.6f64 / 1e5).sqrt(), 1e-12);
    assert!(stop_and_go < direct);
    let l = 0.5 * (stop_and_go + direct);
    assert!(plan(l, 0.4, 4.0, &lim).is_none());
    assert!(max_end_speed(l, 0.4, &lim).unwrap() < 4.0);
    // Slowing to v0/3 takes more length than stopping.
    let v0 = 6.0;
    assert!(transition_length_mm(v0, v0 / 3.0, &lim) > transition_length_mm(v0, 0.0, &lim));
}

// ---------------------------------------------------------------------------------------------
// The fast paths against plain bisections.

/// The largest `x ∈ [lo, hi]` with `pred(x)` (`pred(lo)` true, false above the crossing), by
/// bisection down to adjacent floats: the slow reference of the solves.
fn bisect(lo: f64, hi: f64, pred: impl Fn(f64) -> bool) -> f64 {
    if pred(hi) {
        return hi;
    }
    let (mut lo, mut hi) = (lo, hi);
    loop {
        let mid = 0.5 * (lo + hi);
        if mid <= lo || mid >= hi {
            return lo;
        }
        if pred(mid) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
}

/// Cases like the look-ahead's on tiny segments: close boundary speeds (or one the reach of the
/// other), short lengths, every jerk regime.
fn near_cases() -> impl Strategy<Value = Case> {
    (
        prop_oneof![Just(JerkShape::Square), Just(JerkShape::RaisedCosine)],
        0.0..5.0f64,  // log10 amax
        -4.0..0.0f64, // log10 amax/jmax
        -2.0..2.0f64, // log10 vmax/vA
        -6.0..0.0f64, // log10 L / d(0, vmax)
        0.0..1.0f64,  // v0 / vmax
        -8.0..0.0f64, // log10 |v1 − v0| / v0
        0u8..3,       // v1 below v0, above it, or the reach
    )
        .prop_map(|(shape, la, ltj, lv, ll, f0, ld, mode)| {
            let a = 10f64.powf(la);
            let j = a / 10f64.powf(ltj);
            let vmax = (a * a / j) * 10f64.powf(lv);
            let lim = ProfileLimits::new(vmax, a, j, shape).unwrap();
            let l = transition_length_mm(0.0, vmax, &lim) * 10f64.powf(ll);
            let v0 = vmax * f0;
            let v1 = match mode {
                0 => v0 * (1.0 - 10f64.powf(ld)),
                1 => (v0 * (1.0 + 10f64.powf(ld))).min(vmax),
                _ => max_end_speed(l, v0, &lim).unwrap(),
            };
            Case { l, v0, v1, lim }
        })
}

/// The seeded solve of the peak (Newton in `√(vp − max(v0, v1))`, then the bracketed
/// refinement) finds the peak a bisection of `D(vp) ≤ L` finds, and the seed alone is already
/// that close (else the refinement would silently fall back to slow bisection steps).
#[test]
fn seeded_peak_matches_a_bisection() {
    let mut runner = TestRunner::new(config(100_000));
    let bracketed = AtomicUsize::new(0);
    runner
        .run(&prop_oneof![cases(), near_cases()], |c| {
            let Case { l, v0, v1, lim } = c;
            let k = lim.kin();
            let vmax = lim.v_max_mm_s();
            if lim.is_trapezoid() || k.length(v0, v1) > l || k.two_lengths(v0, vmax, v1).0 <= l {
                return Ok(());
            }
            let (vp, method) = peak_speed(&k, l, v0, v1, vmax);
            let m = v0.max(v1);
            let reference = bisect(m, vmax, |vp| k.two_lengths(v0, vp, v1).0 <= l);
            ensure!(k.two_lengths(v0, vp, v1).0 <= l, "peak {vp} too high");
            let ulps = 64.0 * f64::EPSILON * reference;
            ensure!(
                (vp - reference).abs() <= ulps,
                "{method:?} peak {vp}, bisection {reference}"
            );
            if method == PeakMethod::Bracketed {
                bracketed.fetch_add(1, Relaxed);
                let seed = k.peak_seed(l, v0, v1);
                ensure!(
                    (seed - reference).abs() <= ulps.max(1e-12 * (reference - m)),
                    "seed {seed}, bisection {reference}"
                );
            }
            Ok(())
        })
        .unwrap_or_else(|e| panic!("{e}"));
    assert!(bracketed.load(Relaxed) > 10_000);
}

/// The cubic's Newton from an upper bound finds the root a bisection finds, over the scales of
/// `p` and `q` the solves meet (and beyond).
#[test]
fn cubic_root_matches_a_bisection() {
    let mut runner = TestRunner::new(config(100_000));
    let scale = prop_oneof![Just(0.0), (-12.0..12.0f64).prop_map(|e| 10f64.powf(e))];
    runner
        .run(&(scale, -12.0..12.0f64), |(p, lq)| {
            let q = 10f64.powf(lq);
            let x = cubic_root(p, q);
            let hi = q.cbrt().min(if p > 0.0 { q / p } else { f64::INFINITY }) * 2.0;
            let reference = bisect(0.0, hi, |x| x * (x * x + p) <= q);
            ensure!(
                (x - reference).abs() <= 4.0 * f64::EPSILON * reference,
                "cubic_root({p}, {q}) = {x}, bisection {reference}"
            );
            Ok(())
        })
        .unwrap_or_else(|e| panic!("{e}"));
}
