//! Statistics of a periodic event's timing: how far each period between two consecutive events
//! (SYNC frames) deviates from the nominal one, as percentiles of |deviation| and its maximum.
//!
//! Sans-I/O: the caller hands in timestamps (ns, any clock whose differences are meaningful).
//! Memory is allocated once, in [`PeriodStats::new`]: recording never allocates, so the cyclic
//! thread can do it. The histogram has 1 µs bins up to [`RANGE_US`]; larger deviations are
//! counted above it, and the maximum is kept exactly.

use std::time::Duration;

/// Deviations up to this many µs are binned at 1 µs; above, only counted (and the maximum kept).
pub const RANGE_US: usize = 100_000;

/// Where the timestamps came from, for the reader of the figures.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum TimestampSource {
    /// The kernel's receive timestamps of the SYNC frames on this interface (SO_TIMESTAMPNS).
    KernelRx(String),
    /// The sender's clock, read right after each SYNC was handed to the bus (the in-process bus
    /// has no kernel).
    SenderClock,
}

impl std::fmt::Display for TimestampSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            TimestampSource::KernelRx(iface) => {
                write!(f, "kernel receive timestamps on {iface}")
            }
            TimestampSource::SenderClock => f.write_str("the sender's clock (in-process bus)"),
        }
    }
}

/// Accumulates period deviations.
#[derive(Debug, Clone)]
pub struct PeriodStats {
    period_ns: u64,
    last_ns: Option<u64>,
    bins: Vec<u32>,
    above: u64,
    count: u64,
    max_dev_ns: u64,
    min_period_ns: u64,
    max_period_ns: u64,
}

impl PeriodStats {
    /// Statistics against the nominal `period`.
    pub fn new(period: Duration) -> PeriodStats {
        PeriodStats {
            period_ns: period.as_nanos() as u64,
            last_ns: None,
            bins: vec![0; RANGE_US + 1],
            above: 0,
            count: 0,
            max_dev_ns: 0,
            min_period_ns: u64::MAX,
            max_period_ns: 0,
        }
    }

    /// An event at `t_ns`. A timestamp before the previous one (a step of the wall clock) starts
    /// over from it rather than count a negative period.
    pub fn record(&mut self, t_ns: u64) {
        if let Some(last) = self.last_ns
            && t_ns >= last
        {
            let p = t_ns - last;
            let dev = p.abs_diff(self.period_ns);
            let us = (dev / 1000) as usize;
            if us <= RANGE_US {
                self.bins[us] += 1;
            } else {
                self.above += 1;
            }
            self.count += 1;
            self.max_dev_ns = self.max_dev_ns.max(dev);
            self.min_period_ns = self.min_period_ns.min(p);
            self.max_period_ns = self.max_period_ns.max(p);
        }
        self.last_ns = Some(t_ns);
    }

    /// Periods measured so far.
    pub fn count(&self) -> u64 {
        self.count
    }

    /// The |deviation| at or below which a fraction `q` (0–1) of the periods lie (nearest rank,
    /// 1 µs resolution); `None` before the first period.
    pub fn quantile(&self, q: f64) -> Option<Duration> {
        if self.count == 0 {
            return None;
        }
        let rank = ((q.clamp(0.0, 1.0) * self.count as f64).ceil() as u64).max(1);
        let mut seen = 0u64;
        for (us, n) in self.bins.iter().enumerate() {
            seen += u64::from(*n);
            if seen >= rank {
                return Some(Duration::from_micros(us as u64));
            }
        }
        Some(Duration::from_nanos(self.max_dev_ns))
    }

    /// The figures, once there is at least one period.
    pub fn summary(&self, source: TimestampSource) -> Option<PeriodSummary> {
        Some(PeriodSummary {
            nominal: Duration::from_nanos(self.period_ns),
            periods: self.count,
            p50: self.quantile(0.50)?,
            p99: self.quantile(0.99)?,
            p999: self.quantile(0.999)?,
            max: Duration::from_nanos(self.max_dev_ns),
            shortest: Duration::from_nanos(self.min_period_ns),
            longest: Duration::from_nanos(self.max_period_ns),
            source,
        })
    }
}

/// SYNC period statistics as a run reports them.
#[derive(Debug, Clone, PartialEq)]
pub struct PeriodSummary {
    /// The configured period.
    pub nominal: Duration,
    /// Periods measured (SYNC frames − 1).
    pub periods: u64,
    /// Median |deviation| from the nominal period.
    pub p50: Duration,
    /// 99th percentile of |deviation|.
    pub p99: Duration,
    /// 99.9th percentile of |deviation|.
    pub p999: Duration,
    /// Largest |deviation|.
    pub max: Duration,
    /// Shortest period.
    pub shortest: Duration,
    /// Longest period.
    pub longest: Duration,
    /// Where the timestamps came from.
    pub source: TimestampSource,
}

fn us(d: Duration) -> String {
    format!("{} µs", d.as_micros())
}

impl std::fmt::Display for PeriodSummary {
    /// `60000 periods of 1000 µs from kernel receive timestamps on vcan0: |deviation| p50 12 µs,
    /// p99 85 µs, p99.9 310 µs, max 2100 µs (periods 0–3100 µs)`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} periods of {} from {}: |deviation| p50 {}, p99 {}, p99.9 {}, max {} (periods {}–{})",
            self.periods,
            us(self.nominal),
            self.source,
            us(self.p50),
            us(self.p99),
            us(self.p999),
            us(self.max),
            self.shortest.as_micros(),
            us(self.longest),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const MS: u64 = 1_000_000;

    #[test]
    fn percentiles_of_a_known_set() {
        let mut s = PeriodStats::new(Duration::from_millis(1));
        let mut t = 0;
        s.record(t);
        // 1000 periods: 990 exact, 9 late by 50 µs, 1 by 3 ms (an overrun).
        for i in 0..1000 {
            t += match i {
                0..990 => MS,
                990..999 => MS + 50_000,
                _ => 4 * MS,
            };
            s.record(t);
        }
        let r = s.summary(TimestampSource::SenderClock).unwrap();
        assert_eq!(r.periods, 1000);
        assert_eq!(r.p50, Duration::ZERO);
        assert_eq!(r.p99, Duration::ZERO); // rank 990
        assert_eq!(r.p999, Duration::from_micros(50)); // rank 999
        assert_eq!(r.max, Duration::from_millis(3));
        assert_eq!(r.longest, Duration::from_millis(4));
        assert_eq!(
            r.to_string(),
            "1000 periods of 1000 µs from the sender's clock (in-process bus): |deviation| p50 0 µs, \
             p99 0 µs, p99.9 50 µs, max 3000 µs (periods 1000–4000 µs)"
        );
    }

    #[test]
    fn early_periods_count_as_much_as_late_ones_and_clock_steps_are_skipped() {
        let mut s = PeriodStats::new(Duration::from_millis(1));
        for t in [0, 700_000, 1_700_000, 500_000, 1_500_000] {
            s.record(t);
        }
        assert_eq!(s.count(), 3);
        assert_eq!(s.quantile(1.0), Some(Duration::from_micros(300)));
        assert_eq!(
            PeriodStats::new(Duration::from_millis(1)).summary(TimestampSource::SenderClock),
            None
        );
    }

    #[test]
    fn deviations_beyond_the_bins_still_set_the_maximum() {
        let mut s = PeriodStats::new(Duration::from_millis(1));
        s.record(0);
        s.record(MS + 200_000 * 1000);
        assert_eq!(s.quantile(0.5), Some(Duration::from_millis(200)));
    }

    proptest! {
        #[test]
        fn quantiles_are_ordered_and_bounded_by_the_max(periods in proptest::collection::vec(0u64..5 * MS, 1..300)) {
            let mut s = PeriodStats::new(Duration::from_millis(1));
            let mut t = 0;
            s.record(t);
            for p in &periods {
                t += p;
                s.record(t);
            }
            let r = s.summary(TimestampSource::SenderClock).unwrap();
            prop_assert!(r.p50 <= r.p99 && r.p99 <= r.p999 && r.p999 <= r.max);
            let exact_max = periods.iter().map(|p| p.abs_diff(MS)).max().unwrap();
            prop_assert_eq!(r.max, Duration::from_nanos(exact_max));
            prop_assert!(r.max - r.p999 <= r.max); // no underflow
            prop_assert!(r.p999.as_nanos() as u64 <= exact_max);
        }
    }
}
