//! Homing mode (CiA 402-2, mode 6) of the simulated drive: the switches of the simulated axis,
//! the legs each homing method runs, and the demand profile the drive generates itself.
//!
//! # How this drive reads CiA 402-2
//!
//! - **Home offset (0x607C).** CiA 402-2 draws the home offset as the distance from the zero
//!   position to the home position, and says the zero position is "offset from the home position
//!   by adding the home offset". This drive reads it as: once homing is attained, position
//!   actual (0x6064) *at the home position* equals 0x607C. It is the reading of most servo
//!   drives (and the one the machine file's `offset_mm` documents: the axis's machine coordinate
//!   at the switch), and it makes methods 35/37 "position actual becomes 0x607C".
//! - **Where the drive stops.** The home position is the switch edge. The search for zero runs
//!   through the edge at 0x6099:2 and decelerates with 0x609A; the drive then returns to the edge
//!   and stops there, so position actual = 0x607C when homing is attained.
//! - **Switch sides.** Methods 19/20 ("positive home switch") see the home switch active on the
//!   positive side of its edge, methods 21/22 ("negative home switch") on the negative side.
//!   Method 19 ends moving negative off the switch, 20 positive onto it, 21 positive off it,
//!   22 negative onto it (the edge/direction rules of methods 3–6 without the index pulse).
//!   17/18 search the negative/positive limit switch and home on its edge, moving off it.
//! - **Homing error.** A search that reaches a limit switch it is not looking for (or, on a drive
//!   with no limit switches, the software position limits 0x607D) stops with the homing
//!   acceleration and sets bit 13: the home switch was never found.
//! - **Software limits.** 0x607D is not applied to the homing motion: the position is not known
//!   until homing ends (most drives ignore it in mode 6).
//! - **Statusword** bits 13/12/10 follow the CiA 402-2 table: 0/0/0 in progress, 0/0/1
//!   interrupted or not started, 0/1/0 attained with the motor still settling, 0/1/1 attained,
//!   1/0/0 error with the motor moving, 1/0/1 error at standstill.
//!
//! Positions here are in counts of the motor's physical frame: where the switches are. The drive
//! reports positions in its own frame, which homing shifts so that the home is 0x607C.

/// Where the simulated axis's switches are and where its motor starts: options of the
/// simulated drive only, in counts of the physical frame (position actual before any homing).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct SimSetup {
    /// Position at power-on.
    pub start_counts: i32,
    /// The home switch's edge; `None`: no home switch (switch methods end in a homing error).
    pub home_switch_counts: Option<i32>,
    /// Negative and positive limit switches (active at and beyond each); `None`: none, and the
    /// searches stop at the software position limits 0x607D instead.
    pub limit_switches_counts: Option<[i32; 2]>,
}

/// Where homing stands (what statusword bits 10, 12 and 13 report in mode 6).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum HomingStatus {
    /// Never started since power-on (or since the last reset of the node).
    NotStarted,
    /// Running: searching, or returning to the home position.
    InProgress,
    /// Stopped before the end: bit 4 cleared, halt, a mode change or leaving Operation enabled.
    Interrupted,
    /// The home position was found: position actual there is the home offset.
    Attained,
    /// The switch was never found.
    Error,
}

/// The homing methods this drive runs (CiA 402-2 numbering; also its 0x60E3).
pub const SUPPORTED_METHODS: [i8; 8] = [17, 18, 19, 20, 21, 22, 35, 37];

/// A switch of the simulated axis.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Switch {
    /// The home switch, active on its positive side (methods 19, 20).
    HomePositive,
    /// The home switch, active on its negative side (methods 21, 22).
    HomeNegative,
    /// The negative limit switch.
    NegativeLimit,
    /// The positive limit switch.
    PositiveLimit,
}

/// One leg of a homing method: move in `dir` (±1) at the search speed (`fast`) or the zero
/// speed until `switch` reads `until`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Leg {
    pub dir: f64,
    pub fast: bool,
    pub switch: Switch,
    pub until: bool,
}

/// The switches' edges for one homing run (physical counts).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Switches {
    pub home: Option<f64>,
    pub limits: [f64; 2],
}

impl Switches {
    /// Whether `s` is active at physical position `x`.
    pub fn active(&self, s: Switch, x: f64) -> bool {
        match s {
            Switch::HomePositive => self.home.is_some_and(|h| x >= h),
            Switch::HomeNegative => self.home.is_some_and(|h| x <= h),
            Switch::NegativeLimit => x <= self.limits[0],
            Switch::PositiveLimit => x >= self.limits[1],
        }
    }

    /// The edge of `s` (the home position when `s` ends the method).
    pub fn edge(&self, s: Switch) -> Option<f64> {
        match s {
            Switch::HomePositive | Switch::HomeNegative => self.home,
            Switch::NegativeLimit => Some(self.limits[0]),
            Switch::PositiveLimit => Some(self.limits[1]),
        }
    }
}

/// The legs of `method` from physical position `x`: `None` for a method without motion
/// (35, 37) or one this drive does not run. The last leg's switch edge is the home position.
pub(super) fn legs(method: i8, sw: &Switches, x: f64) -> Option<Vec<Leg>> {
    use Switch::*;
    let leg = |dir: f64, fast: bool, switch: Switch, until: bool| Leg {
        dir,
        fast,
        switch,
        until,
    };
    let (home, on_home) = match method {
        19 | 20 => (HomePositive, sw.active(HomePositive, x)),
        21 | 22 => (HomeNegative, sw.active(HomeNegative, x)),
        _ => (HomePositive, false),
    };
    Some(match method {
        17 if sw.active(NegativeLimit, x) => vec![leg(1.0, false, NegativeLimit, false)],
        17 => vec![
            leg(-1.0, true, NegativeLimit, true),
            leg(1.0, false, NegativeLimit, false),
        ],
        18 if sw.active(PositiveLimit, x) => vec![leg(-1.0, false, PositiveLimit, false)],
        18 => vec![
            leg(1.0, true, PositiveLimit, true),
            leg(-1.0, false, PositiveLimit, false),
        ],
        // Positive home switch: off it moving negative.
        19 if on_home => vec![leg(-1.0, false, home, false)],
        19 => vec![leg(1.0, true, home, true), leg(-1.0, false, home, false)],
        // Positive home switch: onto it moving positive.
        20 if on_home => vec![leg(-1.0, true, home, false), leg(1.0, false, home, true)],
        20 => vec![
            leg(1.0, true, home, true),
            leg(-1.0, true, home, false),
            leg(1.0, false, home, true),
        ],
        // Negative home switch: off it moving positive.
        21 if on_home => vec![leg(1.0, false, home, false)],
        21 => vec![leg(-1.0, true, home, true), leg(1.0, false, home, false)],
        // Negative home switch: onto it moving negative.
        22 if on_home => vec![leg(1.0, true, home, false), leg(-1.0, false, home, true)],
        22 => vec![
            leg(-1.0, true, home, true),
            leg(1.0, true, home, false),
            leg(-1.0, false, home, true),
        ],
        _ => return None,
    })
}

/// The demand velocity one step later: `v` toward `target` by at most `acc·dt`.
pub(super) fn ramp(v: f64, target: f64, acc: f64, dt: f64) -> f64 {
    v + (target - v).clamp(-acc * dt, acc * dt)
}

/// One step of a point-to-point move of the demand `x` (velocity `v`) to `target`, at most
/// `vmax` and `acc`: the new velocity, and whether the move has ended (then `x` is `target`).
/// The velocity toward the target is bounded by the braking distance (`√(2·acc·d)`) and by
/// `d/dt`, so the last step lands on the target instead of passing it.
pub(super) fn approach(x: f64, v: f64, target: f64, vmax: f64, acc: f64, dt: f64) -> (f64, bool) {
    let d = target - x;
    // Within a fraction of a count and all but stopped: the end (a snap of at most two steps'
    // ramp).
    if d.abs() < 0.25 && v.abs() <= 2.0 * acc * dt {
        return (0.0, true);
    }
    let want = d.signum() * vmax.min((2.0 * acc * d.abs()).sqrt()).min(d.abs() / dt);
    (ramp(v, want, acc, dt), false)
}

/// A homing run's state inside the drive.
#[derive(Debug, Clone)]
pub(super) struct HomingRun {
    pub status: HomingStatus,
    pub legs: Vec<Leg>,
    /// The leg being run.
    pub leg: usize,
    pub switches: Switches,
    /// The demand's velocity, counts/s.
    pub v: f64,
    /// Decelerating to a stop (interrupted, or a homing error).
    pub stopping: bool,
    /// Returning to the home position (the reported frame's home offset).
    pub goto: Option<f64>,
}

impl Default for HomingRun {
    fn default() -> HomingRun {
        HomingRun {
            status: HomingStatus::NotStarted,
            legs: Vec::new(),
            leg: 0,
            switches: Switches {
                home: None,
                limits: [f64::NEG_INFINITY, f64::INFINITY],
            },
            v: 0.0,
            stopping: false,
            goto: None,
        }
    }
}

impl HomingRun {
    /// Stop where the motion is, with the homing acceleration, as `status`.
    pub fn stop(&mut self, status: HomingStatus) {
        self.status = status;
        self.stopping = self.v != 0.0;
        self.goto = None;
    }
}

impl SimSetup {
    /// The machine file's `[axis.sim]` of `axis` in counts; the limit switches default to the
    /// axis's travel (`min_mm`, `max_mm`).
    pub fn for_axis(axis: &crate::config::AxisConfig) -> SimSetup {
        let o = &axis.sim;
        let [lo, hi] = o.limit_switches_mm.unwrap_or([axis.min_mm, axis.max_mm]);
        SimSetup {
            start_counts: axis.mm_to_counts(o.start_mm),
            home_switch_counts: o.home_switch_mm.map(|h| axis.mm_to_counts(h)),
            limit_switches_counts: Some([axis.mm_to_counts(lo), axis.mm_to_counts(hi)]),
        }
    }
}
