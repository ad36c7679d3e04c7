//! Cyclic interpolator: samples a [`Plan`] once per control period (the CANopen SYNC period).
//!
//! Third stage of the pipeline (`gcode → planner → interp → setpoints`). Shaped like Ruckig:
//! constructed with the cycle time, then [`Interpolator::update`] once per cycle, which never
//! allocates, blocks or panics and answers with a [`Status`]. Sample `k` (k = 1, 2, ...) is the
//! plan's position at `t = k · period_s`, computed from `k` (not by adding periods) so there is
//! no drift however long the program runs.
//!
//! The first sample whose time reaches the plan's end is exactly the plan's final point (bit
//! for bit) and comes with [`Status::Finished`]; every later call returns that point again.
//!
//! Units in names: `_mm` millimetres, `_s` seconds.

use nalgebra::Vector3;

use crate::planner::Plan;

/// A sample time within this fraction of a period before the plan's end counts as the end, so
/// that rounding in `k · period_s` never adds one extra period of standing still.
const END_SNAP_PERIODS: f64 = 1e-9;

/// What one [`Interpolator::update`] produced.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Status {
    /// The sample lies inside the plan, on a segment of this source line.
    Working {
        /// 1-based source line of the segment being executed.
        line: usize,
    },
    /// The sample is the plan's final point (this call and every later one).
    Finished,
}

/// Why an interpolator could not be built.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum InterpError {
    /// The period is not finite or not positive.
    #[error("interpolation period {period_s} s must be finite and greater than zero")]
    InvalidPeriod {
        /// The offending period.
        period_s: f64,
    },
}

/// Samples a plan at a fixed period. See the module documentation.
#[derive(Debug, Clone)]
pub struct Interpolator {
    plan: Plan,
    period_s: f64,
    /// Number of samples produced so far.
    samples: u64,
    /// Segment of the latest sample; only moves forward.
    segment: usize,
    finished: bool,
}

impl Interpolator {
    /// Prepares to sample `plan` every `period_s` seconds, starting at the plan's start.
    pub fn new(plan: Plan, period_s: f64) -> Result<Interpolator, InterpError> {
        if !(period_s > 0.0 && period_s.is_finite()) {
            return Err(InterpError::InvalidPeriod { period_s });
        }
        Ok(Interpolator {
            plan,
            period_s,
            samples: 0,
            segment: 0,
            finished: false,
        })
    }

    /// Produces the next sample into `out_mm`: the position one period after the previous
    /// sample (the first call gives the position at `period_s`). No allocation, no panic.
    pub fn update(&mut self, out_mm: &mut Vector3<f64>) -> Status {
        self.samples = self.samples.saturating_add(1);
        if !self.finished {
            // Exact for any realistic count (< 2^53 samples).
            let t_s = self.samples as f64 * self.period_s;
            let end_s = self.plan.duration_s();
            if t_s < end_s - END_SNAP_PERIODS * self.period_s {
                let segments = self.plan.segments();
                while segments
                    .get(self.segment + 1)
                    .is_some_and(|next| next.start_time_s <= t_s)
                {
                    self.segment += 1;
                }
                if let Some(seg) = segments.get(self.segment) {
                    *out_mm = seg.position_at(t_s - seg.start_time_s);
                    return Status::Working { line: seg.line };
                }
            }
            self.finished = true;
            self.segment = self.plan.segments().len().saturating_sub(1);
        }
        *out_mm = self.plan.end_mm();
        Status::Finished
    }

    /// Source line of the segment of the latest sample (the first segment's before any
    /// sample, the last one's once finished); `None` for a plan without motion.
    pub fn current_line(&self) -> Option<usize> {
        self.plan.segments().get(self.segment).map(|s| s.line)
    }

    /// Time of the latest sample since the start: `k · period_s` after `k` calls to
    /// [`update`](Self::update) (it keeps counting after the end).
    pub fn elapsed_s(&self) -> f64 {
        self.samples as f64 * self.period_s
    }

    /// Whether the final point has been produced.
    pub fn is_finished(&self) -> bool {
        self.finished
    }

    /// The interpolation period.
    pub fn period_s(&self) -> f64 {
        self.period_s
    }

    /// The plan being sampled.
    pub fn plan(&self) -> &Plan {
        &self.plan
    }

    /// Number of calls to [`update`](Self::update) needed to reach [`Status::Finished`]
    /// from the start (1 for a plan without motion).
    pub fn total_samples(&self) -> u64 {
        let periods = self.plan.duration_s() / self.period_s;
        let k = (periods - END_SNAP_PERIODS).ceil().max(1.0);
        // Saturating float-to-int cast: a plan too long to count is "forever".
        k as u64
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gcode::{BlendMode, CompState, Element, ElementKind, Item, Plane};
    use crate::planner::{Limits, PlanError, plan_items};
    use proptest::prelude::*;

    /// A straight move as the old G0/G1 front end gave it: a target, the start implied.
    #[derive(Debug, Clone, Copy)]
    struct Move {
        line: usize,
        rapid: bool,
        target_mm: Vector3<f64>,
        feed_mm_s: Option<f64>,
    }

    /// Plans straight moves from `start_mm`, each starting where the previous one ended.
    fn plan_moves(
        start_mm: Vector3<f64>,
        moves: &[Move],
        limits: &Limits,
    ) -> Result<Plan, PlanError> {
        let mut from = start_mm;
        let items: Vec<Item> = moves
            .iter()
            .map(|m| {
                let e = Element {
                    line: m.line,
                    col: 1,
                    kind: ElementKind::Line,
                    rapid: m.rapid,
                    start_mm: from,
                    end_mm: m.target_mm,
                    feed_mm_s: m.feed_mm_s,
                    blend: BlendMode::ExactStop,
                    comp: CompState::Off,
                    plane: Plane::Xy,
                };
                from = m.target_mm;
                Item::Motion(e)
            })
            .collect();
        plan_items(start_mm, &items, limits)
    }

    fn v(x: f64, y: f64, z: f64) -> Vector3<f64> {
        Vector3::new(x, y, z)
    }

    fn limits() -> Limits {
        Limits {
            max_vel_mm_s: v(100.0, 100.0, 50.0),
            max_acc_mm_s2: v(1000.0, 1000.0, 500.0),
            max_feed_mm_s: 100.0,
        }
    }

    fn feed(line: usize, target_mm: Vector3<f64>, feed_mm_s: f64) -> Move {
        Move {
            line,
            rapid: false,
            target_mm,
            feed_mm_s: Some(feed_mm_s),
        }
    }

    /// Runs to the end; returns the samples and statuses (first `Finished` included).
    fn run(interp: &mut Interpolator) -> Vec<(Vector3<f64>, Status)> {
        let mut out = Vec::new();
        let mut p = Vector3::zeros();
        loop {
            let status = interp.update(&mut p);
            out.push((p, status));
            if status == Status::Finished {
                return out;
            }
        }
    }

    #[test]
    fn samples_follow_the_plan_and_end_exactly() {
        let target = v(10.1, -3.3, 0.7);
        let plan = plan_moves(Vector3::zeros(), &[feed(3, target, 20.0)], &limits()).unwrap();
        let reference = plan.clone();
        let mut interp = Interpolator::new(plan, 0.001).unwrap();
        assert_eq!(interp.current_line(), Some(3));
        let samples = run(&mut interp);
        assert_eq!(samples.len() as u64, interp.total_samples());
        for (k, (p, status)) in samples.iter().enumerate() {
            if *status != Status::Finished {
                assert_eq!(*status, Status::Working { line: 3 });
                assert_eq!(*p, reference.position_at((k + 1) as f64 * 0.001));
            }
        }
        let (last, status) = *samples.last().unwrap();
        assert_eq!(status, Status::Finished);
        assert_eq!(last, target);
        assert!(interp.is_finished());
        assert!((interp.elapsed_s() - samples.len() as f64 * 0.001).abs() < 1e-12);
        // Keeps returning the final point.
        let mut p = Vector3::zeros();
        for _ in 0..3 {
            assert_eq!(interp.update(&mut p), Status::Finished);
            assert_eq!(p, target);
        }
        assert_eq!(interp.current_line(), Some(3));
    }

    #[test]
    fn reports_the_line_of_each_segment() {
        let moves = [
            feed(1, v(1.0, 0.0, 0.0), 10.0),
            feed(2, v(1.0, 0.0, 0.0), 10.0),
            feed(5, v(1.0, 1.0, 0.0), 10.0),
        ];
        let plan = plan_moves(Vector3::zeros(), &moves, &limits()).unwrap();
        let mut interp = Interpolator::new(plan, 0.002).unwrap();
        let mut lines: Vec<usize> = run(&mut interp)
            .iter()
            .filter_map(|(_, s)| match s {
                Status::Working { line } => Some(*line),
                Status::Finished => None,
            })
            .collect();
        lines.dedup();
        assert_eq!(lines, vec![1, 5]);
        assert_eq!(interp.current_line(), Some(5));
    }

    #[test]
    fn exact_multiple_of_the_period_ends_without_an_extra_sample() {
        // 100 mm at 50 mm/s, a = 1000 (X): duration 2.05 s, which is 2050 periods of 1 ms.
        let plan = plan_moves(
            Vector3::zeros(),
            &[feed(1, v(100.0, 0.0, 0.0), 50.0)],
            &limits(),
        )
        .unwrap();
        assert!((plan.duration_s() - 2.05).abs() < 1e-12);
        let mut interp = Interpolator::new(plan, 0.001).unwrap();
        assert_eq!(interp.total_samples(), 2050);
        assert_eq!(run(&mut interp).len(), 2050);
    }

    #[test]
    fn empty_plan_finishes_at_once() {
        let mut interp = Interpolator::new(Plan::at_rest(v(1.0, 2.0, 3.0)), 0.004).unwrap();
        assert_eq!(interp.current_line(), None);
        assert_eq!(interp.total_samples(), 1);
        let mut p = Vector3::zeros();
        assert_eq!(interp.update(&mut p), Status::Finished);
        assert_eq!(p, v(1.0, 2.0, 3.0));
    }

    #[test]
    fn rejects_bad_periods() {
        for period_s in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            assert!(Interpolator::new(Plan::at_rest(Vector3::zeros()), period_s).is_err());
        }
    }

    /// A random program: each axis of each target either moves to a new value or stays.
    fn moves_strategy() -> impl Strategy<Value = (Vector3<f64>, Vec<Move>)> {
        let coord = -50.0..50.0f64;
        let start = (coord.clone(), coord.clone(), coord.clone()).prop_map(|(x, y, z)| v(x, y, z));
        let axis = proptest::option::weighted(0.7, coord);
        let step = (
            [axis.clone(), axis.clone(), axis],
            any::<bool>(),
            5.0..300.0f64,
        );
        (start, proptest::collection::vec(step, 1..6)).prop_map(|(start, steps)| {
            let mut position = start;
            let mut moves = Vec::new();
            for (line, (axes, rapid, feed_mm_s)) in steps.into_iter().enumerate() {
                for (i, a) in axes.iter().enumerate() {
                    if let Some(a) = a {
                        position[i] = *a;
                    }
                }
                moves.push(Move {
                    line: line + 1,
                    rapid,
                    target_mm: position,
                    feed_mm_s: (!rapid).then_some(feed_mm_s),
                });
            }
            (start, moves)
        })
    }

    fn limits_strategy() -> impl Strategy<Value = Limits> {
        let vel = 10.0..500.0f64;
        let acc = 50.0..5000.0f64;
        (
            [vel.clone(), vel.clone(), vel.clone()],
            [acc.clone(), acc.clone(), acc],
            vel,
        )
            .prop_map(|(vel, acc, feed)| Limits {
                max_vel_mm_s: Vector3::from(vel),
                max_acc_mm_s2: Vector3::from(acc),
                max_feed_mm_s: feed,
            })
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(128))]

        #[test]
        fn sampled_setpoints_hold_the_axis_limits(
            (start, moves) in moves_strategy(),
            limits in limits_strategy(),
            period_s in 0.0005..0.004f64,
        ) {
            let plan = plan_moves(start, &moves, &limits).unwrap();
            let final_mm = moves.last().unwrap().target_mm;
            let mut interp = Interpolator::new(plan, period_s).unwrap();
            // Two samples at rest before the start, so the first differences see the start.
            let mut prev2 = start;
            let mut prev = start;
            let mut p = Vector3::zeros();
            let mut finished_at = None;
            let mut k = 0u64;
            // A few samples past the end: holding still must not break the limits either.
            while finished_at.is_none_or(|f| k < f + 3) {
                k += 1;
                let status = interp.update(&mut p);
                prop_assert!(p.iter().all(|c| c.is_finite()), "NaN at sample {}", k);
                for i in 0..3 {
                    let vel = (p[i] - prev[i]).abs() / period_s;
                    let acc = (p[i] - 2.0 * prev[i] + prev2[i]).abs() / (period_s * period_s);
                    prop_assert!(
                        vel <= limits.max_vel_mm_s[i] * (1.0 + 1e-9) + 1e-6,
                        "axis {} velocity {} > {} at sample {}", i, vel, limits.max_vel_mm_s[i], k
                    );
                    prop_assert!(
                        acc <= limits.max_acc_mm_s2[i] * 1.01,
                        "axis {} acceleration {} > {} at sample {}", i, acc, limits.max_acc_mm_s2[i], k
                    );
                }
                if status == Status::Finished && finished_at.is_none() {
                    finished_at = Some(k);
                    prop_assert_eq!(k, interp.total_samples());
                }
                if finished_at.is_some() {
                    prop_assert_eq!(status, Status::Finished);
                    prop_assert_eq!(p, final_mm);
                }
                prev2 = prev;
                prev = p;
            }
        }
    }
}
