//! Live figures of a run for the progress display of `canmotion run`.
//!
//! The cyclic thread stores them once per cycle with plain atomic stores (no lock, no
//! allocation, nothing that can block it); the display reads them from another thread a few
//! times per second. Each run has its own ([`super::RunOptions::progress`], an `Arc` shared
//! with whoever displays it), so runs in one process (tests) do not see each other's figures;
//! storing costs the cyclic thread the same whether anyone reads them or not.
//!
//! Units in names: `_mm` millimetres, `_mm_s` mm/s.

use std::sync::atomic::{AtomicU64, Ordering};

/// The figures of the run in progress (see the module docs).
#[derive(Debug)]
pub struct Progress {
    cycle: AtomicU64,
    /// Program line in execution, 0 for none.
    line: AtomicU64,
    /// `f64` bits.
    feed_mm_s: AtomicU64,
    /// `f64` bits.
    max_following_error_mm: AtomicU64,
    /// `f64` bits: effective and requested feed override.
    override_effective: AtomicU64,
    override_requested: AtomicU64,
    /// Bit 0: hold asked; bit 1: standing still in it.
    hold: AtomicU64,
}

/// What [`Progress::read`] returns.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProgressSnapshot {
    /// Cycles run so far.
    pub cycle: u64,
    /// Program line in execution (while streaming).
    pub line: Option<usize>,
    /// Path speed of the setpoints in the last cycle.
    pub feed_mm_s: f64,
    /// Largest following error of any axis since the run started.
    pub max_following_error_mm: f64,
    /// Effective feed override (fraction; ramps towards the requested one).
    pub override_effective: f64,
    /// Requested feed override (fraction).
    pub override_requested: f64,
    /// A feed hold is asked for.
    pub hold: bool,
    /// The hold has brought the motion to standstill.
    pub held: bool,
}

impl Progress {
    /// Nothing run yet: cycle 0, no line, 100 %.
    pub const fn new() -> Progress {
        Progress {
            cycle: AtomicU64::new(0),
            line: AtomicU64::new(0),
            feed_mm_s: AtomicU64::new(0),
            max_following_error_mm: AtomicU64::new(0),
            override_effective: AtomicU64::new(0x3FF0_0000_0000_0000),
            override_requested: AtomicU64::new(0x3FF0_0000_0000_0000),
            hold: AtomicU64::new(0),
        }
    }

    /// Stores the motion's feed override figures (the cyclic thread).
    pub fn store_override(&self, effective: f64, requested: f64, hold: bool, held: bool) {
        self.override_effective
            .store(effective.to_bits(), Ordering::Relaxed);
        self.override_requested
            .store(requested.to_bits(), Ordering::Relaxed);
        self.hold
            .store(u64::from(hold) | u64::from(held) << 1, Ordering::Relaxed);
    }

    /// Stores one cycle's figures (the cyclic thread).
    pub fn store(
        &self,
        cycle: u64,
        line: Option<usize>,
        feed_mm_s: f64,
        max_following_error_mm: f64,
    ) {
        self.cycle.store(cycle, Ordering::Relaxed);
        self.line
            .store(line.map_or(0, |l| l as u64), Ordering::Relaxed);
        self.feed_mm_s.store(feed_mm_s.to_bits(), Ordering::Relaxed);
        self.max_following_error_mm
            .store(max_following_error_mm.to_bits(), Ordering::Relaxed);
    }

    /// The latest figures (each consistent on its own; together within a cycle).
    pub fn read(&self) -> ProgressSnapshot {
        let line = self.line.load(Ordering::Relaxed);
        ProgressSnapshot {
            cycle: self.cycle.load(Ordering::Relaxed),
            line: (line > 0).then_some(line as usize),
            feed_mm_s: f64::from_bits(self.feed_mm_s.load(Ordering::Relaxed)),
            max_following_error_mm: f64::from_bits(
                self.max_following_error_mm.load(Ordering::Relaxed),
            ),
            override_effective: f64::from_bits(self.override_effective.load(Ordering::Relaxed)),
            override_requested: f64::from_bits(self.override_requested.load(Ordering::Relaxed)),
            hold: self.hold.load(Ordering::Relaxed) & 1 != 0,
            held: self.hold.load(Ordering::Relaxed) & 2 != 0,
        }
    }
}

impl Default for Progress {
    fn default() -> Progress {
        Progress::new()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_store_is_read_back() {
        let p = Progress::new();
        assert_eq!(p.read().line, None);
        p.store(7, Some(12), 25.5, 0.004);
        p.store_override(0.25, 0.5, true, false);
        assert_eq!(
            p.read(),
            ProgressSnapshot {
                cycle: 7,
                line: Some(12),
                feed_mm_s: 25.5,
                max_following_error_mm: 0.004,
                override_effective: 0.25,
                override_requested: 0.5,
                hold: true,
                held: false,
            }
        );
    }
}
