//! The jerk-limited mode's filters on the samples ([`crate::planner::Smoothing`]): a moving
//! average of the path parameter (the time-law filter), then two moving averages of each axis
//! (the geometry filter). See [`crate::planner`]'s documentation for why and how the plan is
//! made for them.
//!
//! - **Time law.** The interpolator's raw cursor gives the distance `s` travelled along the
//!   whole path at each sample; the filter keeps the last `N_f` of them and puts the point at
//!   their mean, `path(mean)`. The path is untouched (no contour error): only the speed along
//!   it is smoothed, and its jerk is bounded by the range of the plan's acceleration over
//!   `T_f = N_f·T`, divided by `T_f`. When the last `N_f` values are equal, the mean is that
//!   value itself, bit for bit.
//! - **Geometry.** Each axis then passes through two linear [`AxisFilter`]s of `N_k` periods,
//!   which spread a step of an axis's velocity (a corner, a chord's vertex) over `2·T_k` and
//!   keep the end exact (their position-error accumulator). A move planned alone from where
//!   they have settled bypasses them ([`crate::planner::Segment::axis_filters`]); they are
//!   switched only at rest, off only once settled, on again settled where the motion stands.
//!
//! - **Contour pre-compensation.** A moving average pulls a curve towards its centre: a circle
//!   of curvature `κ` run at `v` comes out of the two axis filters with its radius scaled by
//!   `G = D(vκT)²`, `D(θ) = sin(N_k·θ/2)/(N_k·sin(θ/2))` (the gain of an `N_k`-sample moving
//!   average at the angular rate `vκ`; about `1 − v²κ²σ²/2`, `σ² = 2·(N_k² − 1)·T²/12`). So
//!   each point enters the axis filters moved outwards by `(1/G − 1)/κ` along the curvature
//!   vector `K` of the circle through the path's points at `s − h`, `s` and `s + h`
//!   ([`precompensation`], `h =` [`PRECOMP_REACH`]`·v·T_k`): on an arc that is exactly
//!   the steady-state pull, which then vanishes, and the arc costs no contour error at any
//!   speed. The three-point curvature averages `K` over `±h` with a triangular weight, so the
//!   offset ramps in and out continuously where the curvature steps (an arc's end, a
//!   polyline's vertex): it removes about three quarters of the deviation there and adds a
//!   few per cent to the jerk of the step (`crate::planner`'s junction rules count both).
//!   The window never reaches across a stop: on a path that stands still the filters' output
//!   is a mean of points on one side only, which stay on the path.
//!
//! All memory is taken at construction; [`Smoother::filter_distance`] and [`Smoother::filter_point`] never allocate.

use nalgebra::Vector3;

use super::filter::{AxisFilter, FilterKind, FilterSpec};
use crate::planner::Smoothing;

/// The state of the filters.
#[derive(Debug, Clone)]
pub struct Smoother {
    spec: Smoothing,
    /// The last `N_f` raw path distances, a ring; `next` is where the next one goes.
    ring: Box<[f64]>,
    next: usize,
    /// How many of the latest raw distances in a row are equal (capped at `N_f`).
    still: usize,
    /// Whether the time-law filter is on (off for moves planned alone, see
    /// [`crate::planner::Segment::time_law`]).
    time_law: bool,
    /// The two filters of each axis, in order.
    axes: [[AxisFilter; 3]; 2],
    /// Whether the axis filters are on (off for moves planned alone from where they had
    /// settled, see [`crate::planner::Segment::axis_filters`]).
    axes_on: bool,
    /// The plan times of the last `settle_periods + 1` samples, a ring (`next_tau` next):
    /// the oldest is a plan time whose point the output has certainly reached.
    taus: Box<[f64]>,
    next_tau: usize,
    /// The filtered path distance of the previous sample (for [`Smoother::speed`]).
    prev_s_mm: f64,
}

/// The reach `h` of the contour pre-compensation's window on each side of the point, in
/// units of `v·T_k` (see the module documentation).
pub const PRECOMP_REACH: f64 = 2.0;

impl Smoother {
    /// At rest at path distance 0 and point `start_mm`.
    pub fn new(spec: Smoothing, period_s: f64, start_mm: Vector3<f64>) -> Smoother {
        let n_f = spec.time_law_periods.max(1);
        let axis = || {
            let mut f = AxisFilter::new(
                FilterSpec {
                    kind: FilterKind::Linear,
                    time_s: spec.axis_periods.max(1) as f64 * period_s,
                },
                period_s,
            )
            .expect("a whole number of valid periods is a valid linear filter");
            f.reset(0.0);
            f
        };
        let mut axes = [[axis(), axis(), axis()], [axis(), axis(), axis()]];
        for stage in &mut axes {
            for (i, f) in stage.iter_mut().enumerate() {
                f.reset(start_mm[i]);
            }
        }
        Smoother {
            spec,
            ring: vec![0.0; n_f].into_boxed_slice(),
            next: 0,
            still: n_f,
            time_law: true,
            axes,
            axes_on: true,
            taus: vec![0.0; spec.settle_periods() + 1].into_boxed_slice(),
            next_tau: 0,
            prev_s_mm: 0.0,
        }
    }

    /// The path speed of the filtered time law at this sample's filtered distance `s_mm`
    /// (a backward difference; call once per sample, after [`Smoother::filter_distance`]).
    pub fn speed(&mut self, s_mm: f64, period_s: f64) -> f64 {
        let v = (s_mm - self.prev_s_mm).max(0.0) / period_s;
        self.prev_s_mm = s_mm;
        v
    }

    /// How far the pre-compensation's window reaches on each side at speed `v_mm_s`.
    pub fn reach_mm(&self, v_mm_s: f64, period_s: f64) -> f64 {
        PRECOMP_REACH * v_mm_s * self.spec.axis_s(period_s)
    }

    /// The filters this smoother applies.
    pub fn spec(&self) -> Smoothing {
        self.spec
    }

    /// Whether the time-law filter is on.
    pub fn time_law(&self) -> bool {
        self.time_law
    }

    /// Turns the time-law filter on or off, at rest at the raw path distance `rest_mm` (the
    /// planner switches only where the motion stands still and the filter has settled, so the
    /// output does not move).
    pub fn set_time_law(&mut self, on: bool, rest_mm: f64) {
        self.time_law = on;
        self.ring.fill(rest_mm);
        self.still = self.ring.len();
    }

    /// Whether the axis filters are on.
    pub fn axis_filters(&self) -> bool {
        self.axes_on
    }

    /// Turns the axis filters on or off, at rest at `rest_mm` (the point the output stands
    /// at). They are turned off only where they have settled (their output is `rest_mm`),
    /// so that the output does not move; otherwise they stay on (the planner turns them off
    /// only after their settling time, which an override never shortens: it does not speed
    /// up stills). On again, they start settled at `rest_mm`. Returns whether they are on.
    pub fn set_axis_filters(&mut self, on: bool, rest_mm: Vector3<f64>) -> bool {
        if on && !self.axes_on {
            for stage in &mut self.axes {
                for (i, f) in stage.iter_mut().enumerate() {
                    f.reset(rest_mm[i]);
                }
            }
            self.axes_on = true;
        } else if !on && self.axes_on && self.axes.iter().flatten().all(AxisFilter::is_settled) {
            self.axes_on = false;
        }
        self.axes_on
    }

    /// Takes the raw path distance of this sample and gives the filtered one.
    pub fn filter_distance(&mut self, raw_mm: f64) -> f64 {
        if !self.time_law {
            return raw_mm;
        }
        let n = self.ring.len();
        let last = self.ring[(self.next + n - 1) % n];
        if raw_mm == last {
            self.still = (self.still + 1).min(n);
        } else {
            self.still = 1;
        }
        self.ring[self.next] = raw_mm;
        self.next = (self.next + 1) % n;
        if self.still >= n {
            return raw_mm;
        }
        // Relative to the newest value: the sum stays small and precise on a long path.
        let sum: f64 = self.ring.iter().map(|s| s - raw_mm).sum();
        (raw_mm + sum / n as f64).min(raw_mm)
    }

    /// Records the plan time of this sample (see [`Smoother::reached_plan_time_s`]).
    pub fn note_plan_time(&mut self, tau_s: f64) {
        self.taus[self.next_tau] = tau_s;
        self.next_tau = (self.next_tau + 1) % self.taus.len();
    }

    /// A plan time whose point the filtered output has reached: the plan time of the sample
    /// one settling time ago (the filters put the output at a mean of the points since, on a
    /// path that only moves forward).
    pub fn reached_plan_time_s(&self) -> f64 {
        self.taus[self.next_tau]
    }

    /// Passes the point on the path through the axis filters (where they are on).
    pub fn filter_point(&mut self, point_mm: Vector3<f64>) -> Vector3<f64> {
        let mut out = point_mm;
        if !self.axes_on {
            return out;
        }
        for stage in &mut self.axes {
            for (i, f) in stage.iter_mut().enumerate() {
                out[i] = f.update(out[i]);
            }
        }
        out
    }

    /// Whether the output stands where the input does: the last `N_f` raw distances are
    /// equal and the axis filters hold nothing.
    pub fn is_settled(&self) -> bool {
        self.still >= self.ring.len() && self.axes.iter().flatten().all(AxisFilter::is_settled)
    }
}

/// The offset that moves the path point `p` (`behind` and `ahead`: the window's points at
/// `s − h` and `s + h`, relative to `p`; see the module documentation) so that the two axis filters of
/// `n_k` samples, run at `v_mm_s`, bring their output back onto the circle through the three
/// points: `−(1/G − 1)·K/κ²`, `K` the curvature vector of that circle. Zero where the points
/// are collinear (a line, or a window cut to nothing at a stop), or at rest.
pub fn precompensation(
    behind: Vector3<f64>,
    ahead: Vector3<f64>,
    v_mm_s: f64,
    n_k: usize,
    period_s: f64,
) -> Vector3<f64> {
    // The circumcentre of 0, a, b is `c = ((|a|²·b − |b|²·a) × w) / (2|w|²)`, `w = a × b`;
    // its curvature vector `c/|c|²` is `2|w|²·x/|x|²` with `x` that numerator, which tends
    // to 0 with `w` (no division by a vanishing `|w|`).
    let (a, b) = (behind, ahead);
    let w = a.cross(&b);
    let x = (b * a.norm_squared() - a * b.norm_squared()).cross(&w);
    let x2 = x.norm_squared();
    // (NaN fails these too.)
    if x2.is_nan() || x2 <= 0.0 || v_mm_s.is_nan() || v_mm_s <= 0.0 {
        return Vector3::zeros();
    }
    let k_vec = x * (2.0 * w.norm_squared() / x2);
    let kappa = k_vec.norm();
    let n = n_k as f64;
    let theta = v_mm_s * kappa * period_s;
    // (1/G − 1)/κ² with G = D(θ)²; its series `σ²v²/2·(1 + …)` where θ is small.
    let scale = if theta < 1e-4 {
        (n * n - 1.0) / 6.0 * (v_mm_s * period_s).powi(2)
    } else {
        let d = (0.5 * n * theta).sin() / (n * (0.5 * theta).sin());
        let g = d * d;
        if g.is_nan() || g <= 0.25 {
            // Far beyond any speed the planner allows on such a curve: no correction rather
            // than a huge one.
            return Vector3::zeros();
        }
        (1.0 / g - 1.0) / (kappa * kappa)
    };
    -k_vec * scale
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spec(n_f: usize, n_k: usize) -> Smoothing {
        Smoothing {
            time_law_periods: n_f,
            axis_periods: n_k,
        }
    }

    #[test]
    fn a_still_input_comes_out_exactly_after_the_filter_time() {
        let mut s = Smoother::new(spec(4, 2), 0.001, Vector3::zeros());
        let mut out = Vec::new();
        for raw in [0.1, 0.30000000000000004, 0.7, 0.7, 0.7, 0.7, 0.7] {
            out.push(s.filter_distance(raw));
        }
        // The mean of the last four, then exactly the still value once four are equal.
        assert!((out[0] - 0.025).abs() < 1e-15);
        assert!((out[3] - (0.1 + 0.30000000000000004 + 1.4) / 4.0).abs() < 1e-15);
        assert_eq!(out[6], 0.7);
        assert!(out.windows(2).all(|w| w[1] >= w[0]), "{out:?}");
    }

    #[test]
    fn the_axis_filters_turn_off_only_once_settled_and_on_again_without_a_step() {
        let (a, b) = (Vector3::new(1.0, 2.0, 3.0), Vector3::new(1.5, 2.0, 3.0));
        let mut s = Smoother::new(spec(1, 3), 0.001, a);
        // Moving: the output trails the input, and the filters stay on.
        assert_ne!(s.filter_point(b), b);
        assert!(
            s.set_axis_filters(false, b),
            "turned off while holding motion"
        );
        for _ in 0..4 {
            s.filter_point(b);
        }
        assert!(!s.set_axis_filters(false, b));
        // Off: the points pass as they are.
        let c = Vector3::new(2.0, 2.5, 3.0);
        assert_eq!(s.filter_point(c), c);
        // On again where the motion stands: settled there, the next point filtered from it.
        assert!(s.set_axis_filters(true, c));
        assert!(s.is_settled());
        assert_eq!(s.filter_point(c), c);
        let d = Vector3::new(2.3, 2.5, 3.0);
        let out = s.filter_point(d);
        assert!(out.x > c.x && out.x < c.x + 0.3 / 3.0 + 1e-12, "{out:?}");
    }

    #[test]
    fn the_axis_filters_settle_on_the_point_bit_for_bit() {
        let end = Vector3::new(1.0 / 3.0, -2.0 / 7.0, 5.0);
        let mut s = Smoother::new(spec(1, 3), 0.001, Vector3::zeros());
        let mut last = Vector3::zeros();
        for _ in 0..(2 * 2 + 1) {
            last = s.filter_point(end);
        }
        assert_eq!(last, end);
        assert!(s.is_settled());
    }
}
