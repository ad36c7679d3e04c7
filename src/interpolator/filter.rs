//! Post-interpolation acceleration/deceleration filters, one per axis (source 004, 插补后加减速).
//!
//! The interpolator's samples go through a filter per axis before they become setpoints, so a
//! sudden change of an axis's velocity (a block that starts or stops, an exact stop) reaches
//! the drive spread over the filter time. Two kinds, as in the source:
//!
//! - **Linear** (直线型): the moving average of the last `N = round(time / period)` samples. A
//!   step of velocity becomes a straight ramp lasting exactly `N` periods, the filter time.
//!   The output is a convex combination of the last `N` inputs, so it never leaves their
//!   range, and its per-cycle steps and their differences (velocity and acceleration by finite
//!   differences) are averages of the input's: they never exceed the input's largest.
//! - **Exponential** (指数型): the first-order lag `y[k] = y[k−1] + α (x[k] − y[k−1])` with
//!   `α = 1 − e^(−T/τ)`, the exact discrete form of `V(t) = Vc (1 − e^(−t/τ))` (004 eq. 3-53):
//!   a step of velocity `v` gives the per-cycle velocity `v (1 − e^(−kT/τ))` at `t = kT`. Its
//!   steps are convex combinations of the input's too. The lag behind the input stays below
//!   `max|v| · T / (e^(T/τ) − 1)`, which is less than `max|v| · τ`.
//!
//! Both keep the source's **position-error accumulator** ([`AxisFilter::held_mm`]): what the
//! acceleration held back, `input − output`, released while the axis decelerates. The output
//! is computed as `input − held`, so the moment nothing is held the output is the input, bit
//! for bit: an axis ends exactly where it was commanded, never a rounding away. For the linear
//! filter the accumulator is exact: increments are kept as integers of 2⁻³² mm (0.23 pm), so the
//! sums never drift, and once the input has been still for `N − 1` cycles nothing is held.
//! The exponential filter only converges; it snaps to its input once the input is still and
//! less than [`EXP_SNAP_MM`] (1 nm) is held, that is after at most
//! `⌈ln(held / 1 nm) · τ / T⌉` still cycles. For an input that approaches its end
//! monotonically, the held amount keeps its sign, so the output never passes the end.
//!
//! Shaped like the interpolator (Ruckig): constructed with the period and the filter time
//! (all memory allocated then), then [`AxisFilter::update`] once per cycle, which never
//! allocates, blocks or panics. [`AxisFilter::is_settled`] says when the output has caught up,
//! so the end of a motion can wait for it.
//!
//! # Contour error
//!
//! Filtering each axis on its own bends the path, and this is the price of these filters (004:
//! "各坐标轴的实际合成位置可能不准确"). Where it does and does not:
//!
//! - **Straight lines: none**, whatever the acceleration, provided the axes that move together
//!   (X, Y, Z) have the same filter: the filters are linear and time-invariant, so axes moving in
//!   proportion stay in proportion, and the output only lags along the line. Different filters
//!   on X, Y and Z bend even straight lines while they accelerate.
//! - **Arcs at speed `v` on radius `r`**: the output runs on a smaller circle. With the linear
//!   filter of `N` periods the radius shrinks by `r (1 − sin(Nθ/2) / (N sin(θ/2)))`,
//!   `θ = vT/r`, which is about `v² T_f² / (24 r)` with `T_f = N T` (the tests check both). With the exponential
//!   filter, by `r (1 − α / |1 − e^(−T/τ) e^(−iθ)|)`, about `v² τ² / (2 r)`. The error grows
//!   with the square of the filter time and of the speed: doubling the filter time quadruples
//!   it. For the same lag (`T_f ≈ 2τ`) the exponential filter bends arcs three times as much as
//!   the linear one. Examples: 25 mm/s on r = 5 mm gives 0.33 µm with an 8 ms linear filter and
//!   1 µm with a 4 ms exponential one; 100 mm/s on r = 5 mm gives 5.3 µm and 16 µm.
//! - **Corners taken at speed** (blended moves; the present planner stops at every block end,
//!   so none yet): a 90° corner at `v` is cut by up to `v T_f / 8` with the linear filter.
//!
//! Keep the filter time to what the drives need (a few cycles smooth the setpoint steps), and
//! choose it with the fastest arc in mind.
//!
//! Units in names: `_mm` millimetres, `_s` seconds.

use serde::Deserialize;

/// Increments of the linear filter are integers of this fraction of a millimetre (2⁻³² mm).
const QUANTA_PER_MM: f64 = 4_294_967_296.0;

/// The exponential filter snaps to its (still) input once less than this is held back.
pub const EXP_SNAP_MM: f64 = 1e-6;

/// The longest filter accepted, in periods (the linear filter keeps one increment per period).
pub const MAX_FILTER_PERIODS: f64 = 1e6;

/// The kind of a post-interpolation filter (the machine file's `filter.kind`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum FilterKind {
    /// Moving average over the filter time: velocity steps become linear ramps.
    Linear,
    /// First-order lag with the filter time as time constant: exponential velocity changes.
    Exponential,
}

/// A filter's kind and time (the ramp time of a linear filter, the time constant of an
/// exponential one).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FilterSpec {
    /// Linear or exponential.
    pub kind: FilterKind,
    /// Ramp time (linear) or time constant (exponential), s; 0 passes the input through.
    pub time_s: f64,
}

/// Why a filter could not be built.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum FilterError {
    /// The period is not finite or not positive.
    #[error("filter period {period_s} s must be finite and greater than zero")]
    InvalidPeriod {
        /// The offending period.
        period_s: f64,
    },
    /// The filter time is negative or not finite.
    #[error("filter time {time_s} s must be finite and not negative")]
    InvalidTime {
        /// The offending time.
        time_s: f64,
    },
    /// The filter time is more than [`MAX_FILTER_PERIODS`] periods.
    #[error("filter time {time_s} s is more than {MAX_FILTER_PERIODS} periods of {period_s} s")]
    TooLong {
        /// The filter time.
        time_s: f64,
        /// The period.
        period_s: f64,
    },
}

/// A post-interpolation filter for one axis. See the module documentation.
#[derive(Debug, Clone)]
pub struct AxisFilter {
    kind: Kind,
    /// The latest input (the rest position after a reset).
    in_mm: f64,
    /// The latest output.
    out_mm: f64,
}

#[derive(Debug, Clone)]
enum Kind {
    Linear(Linear),
    Exponential(Exponential),
}

/// Moving average of `n` samples, kept as the position-error accumulator: with the last `n − 1`
/// input increments `a₁ … a_{n−1}` (oldest first), `input − average = Σ i·aᵢ / n`.
#[derive(Debug, Clone)]
struct Linear {
    /// The last `n − 1` increments in quanta, a ring whose oldest entry is at `next`.
    ring: Box<[i64]>,
    next: usize,
    /// `Σ aᵢ`.
    sum: i128,
    /// `Σ i·aᵢ`: `n` times what is held back.
    weighted: i128,
    /// Entries of the ring that are not zero.
    nonzero: usize,
    /// `1 / (n · QUANTA_PER_MM)`.
    to_mm: f64,
}

/// First-order lag kept as its error register: `held = e^(−T/τ) · (held + increment)`.
#[derive(Debug, Clone)]
struct Exponential {
    /// `e^(−T/τ)`, 0 for τ = 0.
    keep: f64,
    held_mm: f64,
}

impl AxisFilter {
    /// A filter as `spec` says for a cycle of `period_s`, at rest at 0 (see [`Self::reset`]).
    ///
    /// A linear filter averages `N = round(time_s / period_s)` samples (nearest integer, halves
    /// away from zero, at least 1; `N = 1` passes the input through); its ramps last `N`
    /// periods. The machine file accepts only whole multiples of its cycle, so there the ramp
    /// time is exactly the time written.
    pub fn new(spec: FilterSpec, period_s: f64) -> Result<AxisFilter, FilterError> {
        if !(period_s > 0.0 && period_s.is_finite()) {
            return Err(FilterError::InvalidPeriod { period_s });
        }
        let time_s = spec.time_s;
        if !(time_s >= 0.0 && time_s.is_finite()) {
            return Err(FilterError::InvalidTime { time_s });
        }
        let periods = time_s / period_s;
        if periods > MAX_FILTER_PERIODS {
            return Err(FilterError::TooLong { time_s, period_s });
        }
        let kind = match spec.kind {
            FilterKind::Linear => {
                // At most MAX_FILTER_PERIODS, so the cast is exact.
                let n = periods.round().max(1.0) as usize;
                Kind::Linear(Linear {
                    ring: vec![0; n - 1].into_boxed_slice(),
                    next: 0,
                    sum: 0,
                    weighted: 0,
                    nonzero: 0,
                    to_mm: 1.0 / (n as f64 * QUANTA_PER_MM),
                })
            }
            FilterKind::Exponential => Kind::Exponential(Exponential {
                keep: if time_s == 0.0 {
                    0.0
                } else {
                    (-period_s / time_s).exp()
                },
                held_mm: 0.0,
            }),
        };
        Ok(AxisFilter {
            kind,
            in_mm: 0.0,
            out_mm: 0.0,
        })
    }

    /// At rest at `at_mm`: nothing held, the next input is measured from there. No allocation.
    pub fn reset(&mut self, at_mm: f64) {
        self.in_mm = at_mm;
        self.out_mm = at_mm;
        match &mut self.kind {
            Kind::Linear(l) => {
                l.ring.fill(0);
                l.next = 0;
                l.sum = 0;
                l.weighted = 0;
                l.nonzero = 0;
            }
            Kind::Exponential(e) => e.held_mm = 0.0,
        }
    }

    /// The next output for this cycle's input. No allocation, no panic.
    ///
    /// A non-finite input is passed through as the output (so that the checks downstream see
    /// it) and leaves the filter as it was; an input so far from the previous one that their
    /// difference overflows restarts the filter at rest there.
    pub fn update(&mut self, input_mm: f64) -> f64 {
        if !input_mm.is_finite() {
            return input_mm;
        }
        let step_mm = input_mm - self.in_mm;
        if !step_mm.is_finite() {
            self.reset(input_mm);
            return input_mm;
        }
        self.in_mm = input_mm;
        let held_mm = match &mut self.kind {
            Kind::Linear(l) => l.push(step_mm),
            Kind::Exponential(e) => e.push(step_mm),
        };
        // Nothing held: the input itself, not `input − 0` (which would turn −0 into +0).
        self.out_mm = if held_mm == 0.0 {
            input_mm
        } else {
            input_mm - held_mm
        };
        self.out_mm
    }

    /// Whether the output has caught up: it equals the latest input and nothing is held, so
    /// the same input again gives the same output.
    pub fn is_settled(&self) -> bool {
        match &self.kind {
            Kind::Linear(l) => l.nonzero == 0,
            Kind::Exponential(e) => e.held_mm == 0.0,
        }
    }

    /// The position-error accumulator: latest input minus latest output.
    pub fn held_mm(&self) -> f64 {
        match &self.kind {
            Kind::Linear(l) => l.weighted as f64 * l.to_mm,
            Kind::Exponential(e) => e.held_mm,
        }
    }

    /// The latest output.
    pub fn output_mm(&self) -> f64 {
        self.out_mm
    }

    /// Samples a linear filter averages (its ramp time in periods); `None` for an exponential
    /// filter.
    pub fn periods(&self) -> Option<usize> {
        match &self.kind {
            Kind::Linear(l) => Some(l.ring.len() + 1),
            Kind::Exponential(_) => None,
        }
    }
}

impl Linear {
    /// Takes this cycle's increment; returns what is held back, mm.
    fn push(&mut self, step_mm: f64) -> f64 {
        let len = self.ring.len();
        let Some(slot) = self.ring.get_mut(self.next) else {
            return 0.0; // n = 1: nothing is ever held
        };
        // Saturating cast; a step of more than 2³¹ mm per cycle is not a motion.
        let q = (step_mm * QUANTA_PER_MM).round() as i64;
        let old = std::mem::replace(slot, q);
        self.next = if self.next + 1 == len {
            0
        } else {
            self.next + 1
        };
        // The window slides: every weight drops by one (the oldest to zero) and the new
        // increment comes in with weight n − 1. Exact in i128: at most 2⁶³ · 2⁴⁰.
        self.weighted += len as i128 * i128::from(q) - self.sum;
        self.sum += i128::from(q) - i128::from(old);
        self.nonzero = self.nonzero + usize::from(q != 0) - usize::from(old != 0);
        self.weighted as f64 * self.to_mm
    }
}

impl Exponential {
    /// Takes this cycle's increment; returns what is held back, mm.
    fn push(&mut self, step_mm: f64) -> f64 {
        let held_mm = (self.held_mm + step_mm) * self.keep;
        self.held_mm = if step_mm == 0.0 && held_mm.abs() <= EXP_SNAP_MM {
            0.0
        } else {
            held_mm
        };
        self.held_mm
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const T: f64 = 0.001;

    fn linear(time_s: f64) -> AxisFilter {
        AxisFilter::new(
            FilterSpec {
                kind: FilterKind::Linear,
                time_s,
            },
            T,
        )
        .unwrap()
    }

    fn exponential(time_s: f64) -> AxisFilter {
        AxisFilter::new(
            FilterSpec {
                kind: FilterKind::Exponential,
                time_s,
            },
            T,
        )
        .unwrap()
    }

    /// Outputs for `inputs`, from rest at the first input.
    fn run(f: &mut AxisFilter, inputs: &[f64]) -> Vec<f64> {
        f.reset(inputs[0]);
        inputs.iter().map(|x| f.update(*x)).collect()
    }

    #[test]
    fn a_velocity_step_becomes_a_linear_ramp_lasting_the_filter_time() {
        let mut f = linear(0.008);
        assert_eq!(f.periods(), Some(8));
        let v_mm_s = 50.0;
        // At rest at 10 mm, then 50 mm/s from the first cycle on.
        f.reset(10.0);
        let mut prev = 10.0;
        for k in 1..=20u32 {
            let y = f.update(10.0 + v_mm_s * T * f64::from(k));
            let v = (y - prev) / T;
            prev = y;
            // Averaging 8 samples of which min(k, 8) have moved: the speed climbs by v/8 per
            // cycle and is reached in the 8th, 8 ms after the step.
            let expect = v_mm_s * f64::from(k.min(8)) / 8.0;
            assert!(
                (v - expect).abs() < 1e-6,
                "cycle {k}: {v} mm/s, not {expect}"
            );
        }
        // At constant speed the filter lags by (N − 1)/2 periods of travel.
        assert!((f.held_mm() - v_mm_s * T * 3.5).abs() < 1e-9);
    }

    #[test]
    fn the_linear_filter_ends_bit_for_bit_at_the_end_and_never_passes_it() {
        // Awkward decimal steps so that sums and averages do not come out round.
        let end = 12.345_678_9;
        let mut inputs: Vec<f64> = (0..37)
            .map(|k| 0.1 + (end - 0.1) * f64::from(k) / 37.0)
            .collect();
        inputs.push(end);
        inputs.extend([end; 20]);
        let mut f = linear(0.007);
        let out = run(&mut f, &inputs);
        for (k, y) in out.iter().enumerate() {
            assert!(*y <= end, "cycle {k}: {y} beyond {end}");
        }
        // The input stops at index 37; 6 (= N − 1) still cycles later nothing is held.
        for (k, y) in out.iter().enumerate().skip(37) {
            let settled = k >= 37 + 6;
            assert_eq!(f_settled_at(&inputs, 0.007, k), settled, "cycle {k}");
            if settled {
                assert_eq!(*y, end, "cycle {k}");
            } else {
                assert!(*y < end, "cycle {k}");
            }
        }
    }

    /// Whether a linear filter of `time_s` is settled after the inputs up to `k`.
    fn f_settled_at(inputs: &[f64], time_s: f64, k: usize) -> bool {
        let mut f = linear(time_s);
        run(&mut f, &inputs[..=k]);
        f.is_settled()
    }

    #[test]
    fn a_velocity_step_becomes_an_exponential_rise() {
        let tau_s = 0.004;
        let mut f = exponential(tau_s);
        let v_mm_s = 80.0;
        f.reset(-3.0);
        let mut prev = -3.0;
        for k in 1..=100 {
            let y = f.update(-3.0 + v_mm_s * T * f64::from(k));
            let v = (y - prev) / T;
            prev = y;
            // 004 eq. 3-53, V(t) = Vc (1 − e^(−t/τ)), at t = kT.
            let expect = v_mm_s * (1.0 - (-f64::from(k) * T / tau_s).exp());
            assert!(
                (v - expect).abs() < 1e-6,
                "cycle {k}: {v} mm/s, not {expect}"
            );
        }
        // The lag at constant speed: v T / (e^(T/τ) − 1), a little under v τ.
        let lag = v_mm_s * T / ((T / tau_s).exp() - 1.0);
        assert!((f.held_mm() - lag).abs() < 1e-6 * lag, "{}", f.held_mm());
        assert!(lag < v_mm_s * tau_s);
    }

    #[test]
    fn the_exponential_filter_ends_bit_for_bit_and_never_passes_the_end() {
        let end = -7.654_321;
        let mut f = exponential(0.005);
        f.reset(0.0);
        let mut k = 0;
        let mut y = 0.0;
        while k < 30 {
            k += 1;
            y = f.update(end * f64::from(k) / 30.0);
            assert!(y >= end);
        }
        let held = f.held_mm();
        // Still input: the held amount decays by e^(−T/τ) a cycle and snaps below 1 nm.
        let bound = ((held.abs() / EXP_SNAP_MM).ln() * 0.005 / T).ceil() as usize + 1;
        let mut still = 0;
        while !f.is_settled() {
            still += 1;
            assert!(still <= bound, "not settled after {still} still cycles");
            let next = f.update(end);
            assert!(next >= end && next <= y, "{next} left [{end}, {y}]");
            y = next;
        }
        assert_eq!(y, end);
        assert_eq!(f.update(end), end);
    }

    #[test]
    fn zero_time_passes_the_input_through() {
        for mut f in [linear(0.0), exponential(0.0), linear(0.0004)] {
            f.reset(1.0);
            for x in [1.5, -2.25, 7.0, 7.0] {
                assert_eq!(f.update(x), x);
                assert!(f.is_settled());
            }
        }
    }

    #[test]
    fn bad_periods_and_times_are_refused() {
        let spec = |time_s| FilterSpec {
            kind: FilterKind::Linear,
            time_s,
        };
        for p in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            assert!(matches!(
                AxisFilter::new(spec(0.008), p),
                Err(FilterError::InvalidPeriod { .. })
            ));
        }
        for t in [-0.001, f64::NAN, f64::INFINITY] {
            assert!(matches!(
                AxisFilter::new(spec(t), T),
                Err(FilterError::InvalidTime { .. })
            ));
        }
        // A million periods is the longest.
        assert!(AxisFilter::new(spec(1000.0), T).is_ok());
        assert_eq!(
            AxisFilter::new(spec(1000.1), T).unwrap_err(),
            FilterError::TooLong {
                time_s: 1000.1,
                period_s: T
            }
        );
    }

    #[test]
    fn a_non_finite_input_passes_through_and_leaves_the_state_alone() {
        let mut f = linear(0.004);
        f.reset(0.0);
        f.update(1.0);
        let held = f.held_mm();
        assert!(f.update(f64::NAN).is_nan());
        assert_eq!(f.held_mm(), held);
        for _ in 0..3 {
            f.update(1.0);
        }
        assert_eq!(f.update(1.0), 1.0);
    }

    #[test]
    fn a_line_stays_a_line_and_an_arc_shrinks_as_documented() {
        // Straight line in 3-D with a velocity step: every output point on the line.
        let dir = [0.6, -0.48, 0.64];
        for make in [linear as fn(f64) -> AxisFilter, exponential] {
            let mut axes = [make(0.008), make(0.008), make(0.008)];
            for f in &mut axes {
                f.reset(1.0);
            }
            for k in 1..200 {
                let s = 40.0 * T * f64::from(k.min(120));
                let y: Vec<f64> = (0..3)
                    .map(|a| axes[a].update(1.0 + dir[a] * s) - 1.0)
                    .collect();
                let along = y[0] * dir[0] + y[1] * dir[1] + y[2] * dir[2];
                let off = (0..3)
                    .map(|a| (y[a] - along * dir[a]).powi(2))
                    .sum::<f64>()
                    .sqrt();
                // Within the linear filter's quantum of 2⁻³² mm per increment.
                assert!(off < 1e-9, "cycle {k}: {off} mm off the line");
            }
        }
        // A circle at constant speed: the steady-state radius error of the documentation.
        let (r, v, tf) = (5.0, 100.0, 0.008);
        let theta = v * T / r;
        let n = 8.0;
        let linear_err = r * (1.0 - (n * theta / 2.0).sin() / (n * (theta / 2.0).sin()));
        let keep: f64 = (-T / tf).exp();
        let h = (1.0 - keep) / (1.0 + keep * keep - 2.0 * keep * theta.cos()).sqrt();
        let exp_err = r * (1.0 - h);
        for (mut fx, mut fy, expect, approx) in [
            (
                linear(tf),
                linear(tf),
                linear_err,
                v * v * tf * tf / (24.0 * r),
            ),
            (
                exponential(tf),
                exponential(tf),
                exp_err,
                v * v * tf * tf / (2.0 * r),
            ),
        ] {
            fx.reset(r);
            fy.reset(0.0);
            let mut radius = 0.0;
            for k in 1..=2000 {
                let phi = theta * f64::from(k);
                radius = fx.update(r * phi.cos()).hypot(fy.update(r * phi.sin()));
            }
            assert!(
                (r - radius - expect).abs() < 2e-9,
                "{} vs {expect}",
                r - radius
            );
            assert!(
                (expect - approx).abs() < 0.05 * approx,
                "{expect} vs ≈{approx}"
            );
        }
        // 100 mm/s on r = 5 mm: 5.3 µm (linear 8 ms), 16 µm (exponential 4 ms), as documented.
        assert!((linear_err - 0.0053).abs() < 0.0001, "{linear_err}");
        let keep4: f64 = (-T / 0.004).exp();
        let h4 = (1.0 - keep4) / (1.0 + keep4 * keep4 - 2.0 * keep4 * theta.cos()).sqrt();
        assert!((r * (1.0 - h4) - 0.016).abs() < 0.001, "{}", r * (1.0 - h4));
    }

    /// A random stream: a start and per-cycle velocities (mm/s) as runs of equal values, with
    /// runs at rest, then still.
    fn stream() -> impl Strategy<Value = Vec<f64>> {
        let run = (prop_oneof![Just(0.0), -300.0..300.0f64], 1usize..40);
        (-500.0..500.0f64, proptest::collection::vec(run, 1..12)).prop_map(|(start, runs)| {
            let mut x = vec![start];
            let mut p = start;
            for (v, len) in runs {
                for _ in 0..len {
                    p += v * T;
                    x.push(p);
                }
            }
            x
        })
    }

    /// Largest |first| and |second| difference of `x`, as if at rest before and after.
    fn max_diffs(x: &[f64]) -> (f64, f64) {
        let mut ext = vec![x[0]; 2];
        ext.extend_from_slice(x);
        ext.push(*x.last().unwrap());
        let v = ext
            .windows(2)
            .map(|w| (w[1] - w[0]).abs())
            .fold(0.0, f64::max);
        let a = ext
            .windows(3)
            .map(|w| (w[2] - 2.0 * w[1] + w[0]).abs())
            .fold(0.0, f64::max);
        (v, a)
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(256))]

        #[test]
        fn the_linear_filter_is_the_moving_average_holds_the_limits_and_ends_exactly(
            inputs in stream(),
            n in 1usize..40,
        ) {
            let mut f = linear(n as f64 * T);
            prop_assert_eq!(f.periods(), Some(n));
            let end = *inputs.last().unwrap();
            // Still for the filter's length after the input stops.
            let mut x = inputs.clone();
            x.extend(std::iter::repeat_n(end, n + 2));
            let scale = x.iter().fold(1.0f64, |m, v| m.max(v.abs()));
            let tol = scale * 1e-14 + 4.0 / QUANTA_PER_MM;
            f.reset(x[0]);
            let mut y = Vec::with_capacity(x.len());
            for k in 0..x.len() {
                y.push(f.update(x[k]));
                prop_assert!(y[k].is_finite());
                // The moving average of the last n inputs (the first repeated before the start).
                let avg = (0..n).map(|j| x[k.saturating_sub(j)]).sum::<f64>() / n as f64;
                prop_assert!((y[k] - avg).abs() <= tol * n as f64, "cycle {}: {} vs {}", k, y[k], avg);
                // Settled exactly when the input has not moved in the last n − 1 cycles, and then
                // exactly at the input.
                let settled = (0..n - 1).all(|j| j >= k || x[k - j] == x[k - j - 1]);
                prop_assert_eq!(f.is_settled(), settled, "cycle {}", k);
                if settled {
                    prop_assert_eq!(y[k], x[k]);
                }
            }
            prop_assert_eq!(*y.last().unwrap(), end);
            let (vx, ax) = max_diffs(&x);
            let (vy, ay) = max_diffs(&y);
            prop_assert!(vy <= vx + tol, "velocity {} > {}", vy / T, vx / T);
            prop_assert!(ay <= ax + 2.0 * tol, "acceleration {} > {}", ay / (T * T), ax / (T * T));
        }

        #[test]
        fn the_exponential_filter_holds_the_limits_lags_within_its_bound_and_ends_exactly(
            inputs in stream(),
            tau_periods in 0.2..40.0f64,
        ) {
            let tau_s = tau_periods * T;
            let mut f = exponential(tau_s);
            let end = *inputs.last().unwrap();
            let mut x = inputs.clone();
            let (vx, ax) = max_diffs(&x);
            // Long enough to settle: the lag decays by e^(−T/τ) a cycle down to 1 nm.
            let still = ((vx * tau_periods / EXP_SNAP_MM).max(1.0).ln() * tau_periods).ceil() as usize + 2;
            x.extend(std::iter::repeat_n(end, still));
            let y = run(&mut f, &x);
            prop_assert!(f.is_settled());
            prop_assert_eq!(*y.last().unwrap(), end);
            let scale = x.iter().fold(1.0f64, |m, v| m.max(v.abs()));
            let tol = scale * 1e-14;
            let lag_bound = vx / ((T / tau_s).exp() - 1.0);
            for k in 0..y.len() {
                prop_assert!(y[k].is_finite());
                prop_assert!((x[k] - y[k]).abs() <= lag_bound + tol, "cycle {}: lag {}", k, x[k] - y[k]);
            }
            let (vy, ay) = max_diffs(&y);
            // The final snap moves by at most EXP_SNAP_MM.
            prop_assert!(vy <= vx + tol + EXP_SNAP_MM, "velocity {} > {}", vy / T, vx / T);
            prop_assert!(ay <= ax + 2.0 * (tol + EXP_SNAP_MM), "acceleration {} > {}", ay / (T * T), ax / (T * T));
        }
    }
}
