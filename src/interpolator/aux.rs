//! The auxiliary axes' samples (A B C in degrees, U V W in millimetres).
//!
//! A segment carries them linearly in its path distance ([`crate::planner::Segment::aux`]),
//! so each sample's values come from the same distance as its X/Y/Z point: the raw cursor's
//! without smoothing, the time-law filter's output with it. In the jerk-limited mode they then
//! pass through two moving averages of `N_k` periods each, as every X/Y/Z axis does
//! ([`super::smooth`]; no contour pre-compensation: they are linear in the path). Dwells and
//! stops hold them. Their values are unknown until the first moving segment is queued (it
//! says where they start); the end is exact: the last moving segment's end, bit for bit.
//!
//! No allocation after construction.

use super::filter::{AxisFilter, FilterKind, FilterSpec};
use crate::gcode::AuxPos;
use crate::planner::{Segment, Smoothing};

/// The state of the auxiliary axes' samples.
#[derive(Debug, Clone)]
pub struct AuxSampler {
    /// The latest sample (`None` before the first moving segment was queued).
    last: Option<AuxPos>,
    /// The latest raw (unfiltered) values: what a dwell or stop holds.
    raw: AuxPos,
    /// The end of the queued motion.
    queued_end: Option<AuxPos>,
    /// With the jerk-limited mode's filters: the two moving averages of each axis.
    filters: Option<Box<[[AxisFilter; 6]; 2]>>,
}

impl AuxSampler {
    /// Nothing known yet, no filters.
    pub fn new() -> AuxSampler {
        AuxSampler {
            last: None,
            raw: [0.0; 6],
            queued_end: None,
            filters: None,
        }
    }

    /// Applies the jerk-limited mode's axis filters (two moving averages of
    /// `spec.axis_periods` periods).
    pub fn with_filters(&mut self, spec: Smoothing, period_s: f64) {
        let axis = || {
            AxisFilter::new(
                FilterSpec {
                    kind: FilterKind::Linear,
                    time_s: spec.axis_periods.max(1) as f64 * period_s,
                },
                period_s,
            )
            .expect("a whole number of valid periods is a valid linear filter")
        };
        let mut filters = Box::new([
            std::array::from_fn(|_| axis()),
            std::array::from_fn(|_| axis()),
        ]);
        let at = self.last.unwrap_or(self.raw);
        for stage in filters.iter_mut() {
            for (i, f) in stage.iter_mut().enumerate() {
                f.reset(at[i]);
            }
        }
        self.filters = Some(filters);
    }

    /// A segment was queued: the first moving one says where the axes start.
    pub fn note_segment(&mut self, seg: &Segment) {
        if seg.length_mm <= 0.0 {
            return;
        }
        if self.last.is_none() {
            let at = seg.aux.start;
            self.last = Some(at);
            self.raw = at;
            if let Some(filters) = self.filters.as_mut() {
                for stage in filters.iter_mut() {
                    for (i, f) in stage.iter_mut().enumerate() {
                        f.reset(at[i]);
                    }
                }
            }
        }
        self.queued_end = Some(seg.aux.end);
    }

    /// The sample at `d_mm` along `seg` (a dwell or stop holds the latest raw values). Call
    /// once per sample, with or without filters.
    pub fn sample(&mut self, seg: &Segment, d_mm: f64) {
        if self.last.is_none() {
            return;
        }
        if seg.length_mm > 0.0 {
            self.raw = seg.aux_at_distance(d_mm);
        }
        self.sample_raw(self.raw);
    }

    /// The sample of the raw values `raw` (through the filters, if any).
    pub fn sample_raw(&mut self, raw: AuxPos) {
        if self.last.is_none() {
            return;
        }
        self.raw = raw;
        let mut out = raw;
        if let Some(filters) = self.filters.as_mut() {
            for stage in filters.iter_mut() {
                for (i, f) in stage.iter_mut().enumerate() {
                    out[i] = f.update(out[i]);
                }
            }
        }
        self.last = Some(out);
    }

    /// The end of the queued motion (once it is over): exact.
    pub fn finish(&mut self) {
        if let Some(end) = self.queued_end {
            self.raw = end;
            self.last = Some(end);
        }
    }

    /// The end of the queued motion (`None` before a moving segment).
    pub fn queued_end(&self) -> Option<AuxPos> {
        self.queued_end
    }

    /// Whether the filters hold nothing (always, without filters).
    pub fn is_settled(&self) -> bool {
        self.filters
            .as_ref()
            .is_none_or(|f| f.iter().flatten().all(AxisFilter::is_settled))
    }

    /// The latest sample (`None` before the first moving segment).
    pub fn last(&self) -> Option<&AuxPos> {
        self.last.as_ref()
    }
}

impl Default for AuxSampler {
    fn default() -> AuxSampler {
        AuxSampler::new()
    }
}
