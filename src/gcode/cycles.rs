//! Canned cycles (G73, G74, G81…G86, G89; G80 cancels; G98/G99 choose the return level),
//! expanded into the interpreter's ordinary lines and dwells as LinuxCNC's interpreter expands
//! them (`interp_cycles.cc`, RS274/NGC §3.5.16), so that compensation, the planner, the
//! optimiser and the resume point see nothing new.
//!
//! # Geometry
//!
//! A cycle works in the plane in force, in program coordinates. Two coordinates place the hole
//! (X and Y in G17, Z and X in G18, Y and Z in G19), the third is the drill axis (Z, Y, X), and
//! along it:
//!
//! - the **initial level**: the drill-axis coordinate before the first line of a run of
//!   cycles (a line with any other motion, G0…G3 or G80, ends the run; changing from one cycle
//!   to another does not);
//! - **R**, the retract plane; under G91 an increment from the initial level;
//! - the **bottom**, the drill-axis word (Z in G17); under G91 an increment from R. R below the
//!   bottom is an error;
//! - the **clear level** the cycle returns to: R under G99, the initial level under G98 (or R
//!   if the initial level is below it). G99 is in force at the start, as in LinuxCNC.
//!
//! On each cycle line: if the initial level is below R, a rapid along the drill axis up to R.
//! Then, for each of the L repeats (L is not sticky; under G91 each repeat moves the hole by
//! the line's in-plane words from the previous hole, under G90 it drills the same hole again):
//! on the first repeat, if the tool is above R, a rapid in the plane to the hole at its level
//! and a rapid down to R; otherwise a rapid to the hole at the clear level and, if the clear
//! level is above R, a rapid down to R. Then the cycle's own moves (feed `F`, rapid `R`, dwell
//! `P` seconds; δ is LinuxCNC's peck clearance, 0.010 in = 0.254 mm):
//!
//! | cycle | moves at the hole |
//! |---|---|
//! | G81 drill | F bottom, R clear |
//! | G82 drill, dwell | F bottom, P, R clear |
//! | G83 peck drill | for each peck depth d = R − Q, R − 2Q, … above the bottom: F d, R to R, R to d + δ; then F bottom, R clear |
//! | G73 chip break | for each d: F d, R to d + δ; then F bottom, R clear |
//! | G84 right-hand tap, G74 left-hand tap | F bottom, P (if given), F clear |
//! | G85 bore, feed out | F bottom, F R, R clear |
//! | G86 bore, spindle stop, rapid out | F bottom, P, R clear |
//! | G89 bore, dwell, feed out | F bottom, P, F clear |
//!
//! The cycle's moves run in exact path mode (G61), as in LinuxCNC; the mode in force comes
//! back after the line. A cycle is modal: a later line with only axis words (X or Y in G17)
//! drills again with the sticky R, bottom, Q and P. R and the bottom (and Q, and P for G82,
//! G86, G89) are needed on the first line of a cycle; P of G74/G84 defaults to the last P of
//! any cycle (0 at first). A dwell of 0 s is left out.
//!
//! This front end does not drive the spindle: G86's spindle stop and restart, and the tapping
//! cycles' reversal at the bottom (with feed and spindle overrides off), are LinuxCNC's and not
//! made here. The path is the same; the spindle is the operator's. LinuxCNC's checks of the
//! spindle direction (M3 for G84, M4 for G74, turning for G86) are kept, from the M3/M4/M5/M19
//! words of the program.

use std::collections::VecDeque;

use nalgebra::Vector3;

use super::{BlockError, State, err_at, invalid};
use crate::gcode::block::{Block, as_index};
use crate::gcode::element::{BlendMode, CompState};
use crate::gcode::lex::Word;
use crate::gcode::{Dwell, ErrorKind, Item, MM_PER_INCH};

/// Most moves and dwells one canned-cycle line may make (pecks times repeats): the items of a
/// line are queued at once, so this bounds the interpreter's memory.
pub const MAX_CYCLE_ITEMS: usize = 100_000;

/// LinuxCNC's peck clearance (`G83_RAPID_DELTA`): 0.010 inch.
const PECK_CLEARANCE_IN: f64 = 0.010;

/// A canned cycle this front end expands.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Cycle {
    G73,
    G74,
    G81,
    G82,
    G83,
    G84,
    G85,
    G86,
    G89,
}

impl Cycle {
    /// The cycle of a G code in tenths (`810` is G81).
    pub(super) fn from_tenths(tenths: u32) -> Option<Cycle> {
        Some(match tenths {
            730 => Cycle::G73,
            740 => Cycle::G74,
            810 => Cycle::G81,
            820 => Cycle::G82,
            830 => Cycle::G83,
            840 => Cycle::G84,
            850 => Cycle::G85,
            860 => Cycle::G86,
            890 => Cycle::G89,
            _ => return None,
        })
    }

    /// The G code.
    pub(super) fn code(self) -> &'static str {
        match self {
            Cycle::G73 => "G73",
            Cycle::G74 => "G74",
            Cycle::G81 => "G81",
            Cycle::G82 => "G82",
            Cycle::G83 => "G83",
            Cycle::G84 => "G84",
            Cycle::G85 => "G85",
            Cycle::G86 => "G86",
            Cycle::G89 => "G89",
        }
    }

    /// Whether it takes P (a dwell at the bottom), and whether P is required on its first line.
    fn dwell(self) -> Option<bool> {
        match self {
            Cycle::G82 | Cycle::G86 | Cycle::G89 => Some(true),
            Cycle::G74 | Cycle::G84 => Some(false),
            _ => None,
        }
    }

    /// Whether it pecks (takes Q).
    fn pecks(self) -> bool {
        matches!(self, Cycle::G73 | Cycle::G83)
    }
}

/// Which way the spindle turns, as the program's M3/M4/M5/M19 left it (tapping and G86 check
/// it, as LinuxCNC does).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub(super) enum Spindle {
    #[default]
    Stopped,
    Cw,
    Ccw,
}

impl Spindle {
    /// The state after M3 (30), M4 (40), M5 (50) or M19 (190, orientation: not turning).
    pub(super) fn after(tenths: u32) -> Spindle {
        match tenths {
            30 => Spindle::Cw,
            40 => Spindle::Ccw,
            _ => Spindle::Stopped,
        }
    }
}

/// A sticky cycle value as written (program units), with the units it was written in.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Written {
    value: f64,
    inch: bool,
}

impl Written {
    fn in_units(self, inch: bool) -> f64 {
        match (self.inch, inch) {
            (false, true) => self.value / MM_PER_INCH,
            (true, false) => self.value * MM_PER_INCH,
            _ => self.value,
        }
    }
}

/// What canned cycles keep from line to line (LinuxCNC's `cycle_r`, `cycle_cc`, `cycle_q`,
/// `cycle_p`, `cycle_il`).
#[derive(Debug, Clone, Default, PartialEq)]
pub(super) struct CycleState {
    r: Option<Written>,
    bottom: Option<Written>,
    q: Option<Written>,
    p_s: f64,
    /// The initial level of the current run of cycles (drill-axis program coordinate, mm).
    pub(super) initial_mm: Option<f64>,
}

/// The values one cycle line runs with, in program units (the arithmetic of the peck depths
/// is LinuxCNC's, in the program's units, so that a peck lands where LinuxCNC's lands).
struct Plan {
    cycle: Cycle,
    /// Absolute R and bottom.
    r_u: f64,
    bottom_u: f64,
    q_u: f64,
    dwell_s: f64,
    repeats: u32,
    /// Hole in the plane (mm) before the first repeat, and the step of each repeat.
    hole_mm: (f64, f64),
    step_mm: (f64, f64),
    initial_mm: f64,
}

/// Emits one cycle line's moves, counting them against [`MAX_CYCLE_ITEMS`].
struct Emitter<'a> {
    state: &'a mut State,
    out: &'a mut VecDeque<Item>,
    line: usize,
    col: usize,
    code: &'static str,
    feed_mm_s: f64,
    /// Indices of the first plane axis, the second, and the drill axis.
    axes: (usize, usize, usize),
    hole_mm: (f64, f64),
    steps: usize,
}

impl Emitter<'_> {
    fn count(&mut self) -> Result<(), BlockError> {
        self.steps += 1;
        if self.steps > MAX_CYCLE_ITEMS {
            return Err(err_at(
                self.col,
                ErrorKind::CycleTooLong {
                    code: self.code,
                    max: MAX_CYCLE_ITEMS,
                },
            ));
        }
        Ok(())
    }

    /// A straight move to the hole at drill-axis level `level_mm`.
    fn go(&mut self, rapid: bool, level_mm: f64) -> Result<(), BlockError> {
        self.count()?;
        let (a, c, n) = self.axes;
        let mut p: Vector3<f64> = self.state.prog_mm;
        p[a] = self.hole_mm.0;
        p[c] = self.hole_mm.1;
        p[n] = level_mm;
        let m = self.state.machine_of(p);
        self.state.check_position(self.col, &m)?;
        let feed = (!rapid).then_some(self.feed_mm_s);
        self.state
            .push_line(self.line, self.col, rapid, m, feed, self.out);
        self.state.prog_mm = p;
        Ok(())
    }

    fn rapid(&mut self, level_mm: f64) -> Result<(), BlockError> {
        self.go(true, level_mm)
    }

    fn feed(&mut self, level_mm: f64) -> Result<(), BlockError> {
        self.go(false, level_mm)
    }

    fn dwell(&mut self, seconds: f64) -> Result<(), BlockError> {
        self.count()?;
        if seconds > 0.0 {
            self.out.push_back(Item::Dwell(Dwell {
                line: self.line,
                col: self.col,
                seconds,
            }));
        }
        Ok(())
    }
}

fn missing_word(
    col: usize,
    code: &'static str,
    letter: char,
    expected: &'static str,
) -> BlockError {
    err_at(
        col,
        ErrorKind::MissingWord {
            code: code.to_owned(),
            letter,
            expected,
        },
    )
}

impl State {
    /// Runs one line of a canned cycle: `first` when the previous motion mode was not this
    /// cycle (R, the bottom, and Q or P are then required), `col` the column its moves are
    /// reported at (the cycle code's, or the first axis word's).
    pub(super) fn canned_cycle(
        &mut self,
        b: &Block,
        line: usize,
        col: usize,
        cycle: Cycle,
        first: bool,
        out: &mut VecDeque<Item>,
    ) -> Result<(), BlockError> {
        let plan = self.cycle_plan(b, col, cycle, first)?;
        let feed_mm_s = self.feed_mm_s.unwrap_or(f64::NAN);
        // LinuxCNC runs every cycle in exact path mode.
        let blend = std::mem::replace(&mut self.blend, BlendMode::ExactPath);
        let axes = self.plane.axes();
        let retract_to_r = self.retract_to_r;
        let inch = self.inch;
        let scale = self.scale();
        let mut e = Emitter {
            state: self,
            out,
            line,
            col,
            code: cycle.code(),
            feed_mm_s,
            axes,
            hole_mm: plan.hole_mm,
            steps: 0,
        };
        let result = expand(&mut e, &plan, retract_to_r, inch, scale);
        self.blend = blend;
        result
    }

    /// Reads and checks the words of a cycle line (LinuxCNC's checks, in its order) and
    /// updates the sticky values.
    fn cycle_plan(
        &mut self,
        b: &Block,
        col: usize,
        cycle: Cycle,
        first: bool,
    ) -> Result<Plan, BlockError> {
        let code = cycle.code();
        if b.first_axis().is_none() {
            return Err(missing_word(
                col,
                code,
                'X',
                "at least one axis word (the hole position or the bottom)",
            ));
        }
        if self.inverse_time {
            return Err(err_at(col, ErrorKind::CycleInverseTime { code }));
        }
        if self.feed_mm_s.is_none() {
            return Err(err_at(col, ErrorKind::MissingFeed { code }));
        }
        if self.comp != CompState::Off {
            return Err(err_at(
                col,
                ErrorKind::CompensationActive {
                    code: code.to_owned(),
                },
            ));
        }
        let inch = self.inch;
        let scale = self.scale();
        let (a, c, n) = self.plane.axes();
        let letters = ['X', 'Y', 'Z'];

        let r_word = self.take(b, 'R');
        let r_written = match (r_word, self.cycles.r) {
            (Some(w), _) => w.value,
            (None, Some(r)) if !first => r.in_units(inch),
            _ => {
                return Err(missing_word(
                    col,
                    code,
                    'R',
                    "the retract plane on the first line of a cycle",
                ));
            }
        };
        let repeats = match self.take(b, 'L') {
            Some(w) => match as_index(w.value) {
                Some(l) if l > 0 => l,
                _ => return Err(invalid(w, "a repeat count of 1 or more")),
            },
            None => 1,
        };
        let bottom_written = match (self.take(b, letters[n]), self.cycles.bottom) {
            (Some(w), _) => w.value,
            (None, Some(z)) if !first => z.in_units(inch),
            _ => {
                return Err(missing_word(
                    col,
                    code,
                    letters[n],
                    "the bottom of the hole on the first line of a cycle",
                ));
            }
        };
        let here = self.prog_mm;
        let initial_mm = *self.cycles.initial_mm.get_or_insert(here[n]);
        let (r_u, bottom_u) = if self.incremental {
            let r = r_written + initial_mm / scale;
            (r, r + bottom_written)
        } else {
            (r_written, bottom_written)
        };
        if r_u < bottom_u {
            return Err(err_at(
                r_word.map_or(col, |w: Word| w.col),
                ErrorKind::CycleRetractBelowBottom {
                    code,
                    axis: letters[n],
                    r_mm: r_u * scale,
                    bottom_mm: bottom_u * scale,
                },
            ));
        }
        let dwell_s = match cycle.dwell() {
            None => 0.0,
            Some(required) => match self.take(b, 'P') {
                Some(w) if w.value < 0.0 => return Err(invalid(w, "a dwell time of 0 s or more")),
                Some(w) => w.value,
                None if required && first => {
                    return Err(missing_word(
                        col,
                        code,
                        'P',
                        "the dwell at the bottom, in seconds",
                    ));
                }
                None => self.cycles.p_s,
            },
        };
        let q_u = if cycle.pecks() {
            match (self.take(b, 'Q'), self.cycles.q) {
                (Some(w), _) if w.value <= 0.0 => {
                    return Err(invalid(w, "a peck depth greater than 0"));
                }
                (Some(w), _) => w.value,
                (None, Some(q)) if !first => q.in_units(inch),
                _ => return Err(missing_word(col, code, 'Q', "the depth of each peck")),
            }
        } else {
            0.0
        };
        let (needed, fix) = match cycle {
            Cycle::G84 => ([Spindle::Cw, Spindle::Cw], ("clockwise", "M3")),
            Cycle::G74 => ([Spindle::Ccw, Spindle::Ccw], ("counter-clockwise", "M4")),
            Cycle::G86 => ([Spindle::Cw, Spindle::Ccw], ("", "M3 or M4")),
            _ => ([self.spindle; 2], ("", "")),
        };
        if !needed.contains(&self.spindle) {
            return Err(err_at(
                col,
                ErrorKind::CycleSpindle {
                    code,
                    needed: if fix.0.is_empty() {
                        "either way"
                    } else {
                        fix.0
                    },
                    fix: fix.1,
                },
            ));
        }

        let plane_word = |s: &mut State, i: usize| s.take_mm(b, letters[i]);
        let (wa, wc) = (plane_word(self, a), plane_word(self, c));
        let (hole_mm, step_mm) = if self.incremental {
            ((here[a], here[c]), (wa.unwrap_or(0.0), wc.unwrap_or(0.0)))
        } else {
            ((wa.unwrap_or(here[a]), wc.unwrap_or(here[c])), (0.0, 0.0))
        };

        self.cycles.r = Some(Written {
            value: r_written,
            inch,
        });
        self.cycles.bottom = Some(Written {
            value: bottom_written,
            inch,
        });
        if cycle.pecks() {
            self.cycles.q = Some(Written { value: q_u, inch });
        }
        if cycle.dwell().is_some() {
            self.cycles.p_s = dwell_s;
        }
        Ok(Plan {
            cycle,
            r_u,
            bottom_u,
            q_u,
            dwell_s,
            repeats,
            hole_mm,
            step_mm,
            initial_mm,
        })
    }
}

/// The moves of one cycle line (see the module documentation).
fn expand(
    e: &mut Emitter<'_>,
    plan: &Plan,
    retract_to_r: bool,
    inch: bool,
    scale: f64,
) -> Result<(), BlockError> {
    let n = e.axes.2;
    let r_mm = plan.r_u * scale;
    let bottom_mm = plan.bottom_u * scale;
    let mut level_mm = e.state.prog_mm[n];
    let mut old_mm = plan.initial_mm;
    if old_mm < r_mm {
        // Below R: straight up to it where the tool is.
        let (a, c, _) = e.axes;
        e.hole_mm = (e.state.prog_mm[a], e.state.prog_mm[c]);
        e.rapid(r_mm)?;
        old_mm = r_mm;
        level_mm = r_mm;
    }
    let clear_mm = if retract_to_r { r_mm } else { old_mm };
    let mut hole = plan.hole_mm;
    for k in 0..plan.repeats {
        hole = (hole.0 + plan.step_mm.0, hole.1 + plan.step_mm.1);
        e.hole_mm = hole;
        if k == 0 && level_mm > r_mm {
            e.rapid(level_mm)?;
            e.rapid(r_mm)?;
        } else {
            e.rapid(clear_mm)?;
            if clear_mm > r_mm {
                e.rapid(r_mm)?;
            }
        }
        match plan.cycle {
            Cycle::G81 => {
                e.feed(bottom_mm)?;
                e.rapid(clear_mm)?;
            }
            Cycle::G82 | Cycle::G86 => {
                e.feed(bottom_mm)?;
                e.dwell(plan.dwell_s)?;
                e.rapid(clear_mm)?;
            }
            Cycle::G74 | Cycle::G84 | Cycle::G89 => {
                e.feed(bottom_mm)?;
                e.dwell(plan.dwell_s)?;
                e.feed(clear_mm)?;
            }
            Cycle::G85 => {
                e.feed(bottom_mm)?;
                e.feed(r_mm)?;
                e.rapid(clear_mm)?;
            }
            Cycle::G73 | Cycle::G83 => {
                let delta_u = if inch {
                    PECK_CLEARANCE_IN
                } else {
                    PECK_CLEARANCE_IN * MM_PER_INCH
                };
                let mut depth_u = plan.r_u - plan.q_u;
                while depth_u > plan.bottom_u {
                    e.feed(depth_u * scale)?;
                    if plan.cycle == Cycle::G83 {
                        e.rapid(r_mm)?;
                    }
                    e.rapid((depth_u + delta_u) * scale)?;
                    depth_u -= plan.q_u;
                }
                e.feed(bottom_mm)?;
                e.rapid(clear_mm)?;
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use nalgebra::Vector3;

    use crate::gcode::{BlendMode, Error, ErrorKind, Item, parse_program};

    /// One output item, reduced to what a cycle decides: a rapid or feed move to a point, or a
    /// dwell.
    #[derive(Debug, Clone, Copy, PartialEq)]
    enum S {
        R([f64; 3]),
        F([f64; 3]),
        D(f64),
    }

    fn items(text: &str) -> Vec<S> {
        let p = parse_program(text, "t.ngc", Vector3::zeros()).unwrap_or_else(|e| panic!("{e}"));
        let mut at = p.start_mm;
        p.items
            .iter()
            .filter_map(|i| match i {
                Item::Motion(e) => {
                    assert_eq!(e.start_mm, at, "elements chain");
                    at = e.end_mm;
                    let end = [e.end_mm.x, e.end_mm.y, e.end_mm.z];
                    Some(if e.rapid {
                        S::R(end)
                    } else {
                        let f = e.feed_mm_s.expect("a feed");
                        assert!((f - 10.0).abs() < 1e-9, "F600 mm/min, not {f}");
                        S::F(end)
                    })
                }
                Item::Dwell(d) => Some(S::D(d.seconds)),
                _ => None,
            })
            .collect()
    }

    fn near(a: S, b: S) -> bool {
        let close = |p: [f64; 3], q: [f64; 3]| (0..3).all(|i| (p[i] - q[i]).abs() <= 0.001);
        match (a, b) {
            (S::R(p), S::R(q)) | (S::F(p), S::F(q)) => close(p, q),
            (S::D(s), S::D(t)) => (s - t).abs() <= 1e-9,
            _ => false,
        }
    }

    #[track_caller]
    fn assert_path(text: &str, expected: &[S]) {
        let got = items(text);
        let same =
            got.len() == expected.len() && got.iter().zip(expected).all(|(g, e)| near(*g, *e));
        assert!(
            same,
            "program:\n{text}\ngot:\n{}\nexpected:\n{}",
            got.iter().map(|s| format!("{s:?}\n")).collect::<String>(),
            expected
                .iter()
                .map(|s| format!("{s:?}\n"))
                .collect::<String>()
        );
    }

    fn error(text: &str) -> Error {
        parse_program(text, "t.ngc", Vector3::zeros()).expect_err("an error")
    }

    /// A plane and its letters: the two that place the hole, then the drill axis (LinuxCNC:
    /// G17 X Y / Z, G18 Z X / Y, G19 Y Z / X), with their indices in machine (X, Y, Z) order.
    struct PlaneCase {
        code: &'static str,
        letters: [char; 3],
        index: [usize; 3],
    }

    const PLANES: [PlaneCase; 3] = [
        PlaneCase {
            code: "G17",
            letters: ['X', 'Y', 'Z'],
            index: [0, 1, 2],
        },
        PlaneCase {
            code: "G18",
            letters: ['Z', 'X', 'Y'],
            index: [2, 0, 1],
        },
        PlaneCase {
            code: "G19",
            letters: ['Y', 'Z', 'X'],
            index: [1, 2, 0],
        },
    ];

    /// A step of a cycle at its hole: feed or rapid to a drill-axis level, to the clear level,
    /// or a dwell.
    #[derive(Clone, Copy)]
    enum B {
        F(f64),
        R(f64),
        FClear,
        RClear,
        D(f64),
    }

    /// Each cycle with its extra words and its moves at a hole, for R = 2, bottom = −3, Q = 2,
    /// P = 0.5 (pecks at 0 and −2; δ = 0.254 mm), worked out by hand from LinuxCNC's
    /// `interp_cycles.cc`.
    fn cycles() -> Vec<(&'static str, &'static str, &'static str, Vec<B>)> {
        use B::*;
        vec![
            ("G81", "", "M3", vec![F(-3.0), RClear]),
            ("G82", "P0.5", "M3", vec![F(-3.0), D(0.5), RClear]),
            (
                "G83",
                "Q2",
                "M3",
                vec![
                    F(0.0),
                    R(2.0),
                    R(0.254),
                    F(-2.0),
                    R(2.0),
                    R(-1.746),
                    F(-3.0),
                    RClear,
                ],
            ),
            (
                "G73",
                "Q2",
                "M3",
                vec![F(0.0), R(0.254), F(-2.0), R(-1.746), F(-3.0), RClear],
            ),
            ("G84", "P0.5", "M3", vec![F(-3.0), D(0.5), FClear]),
            ("G74", "P0.5", "M4", vec![F(-3.0), D(0.5), FClear]),
            ("G85", "", "M3", vec![F(-3.0), F(2.0), RClear]),
            ("G86", "P0.5", "M3", vec![F(-3.0), D(0.5), RClear]),
            ("G89", "P0.5", "M3", vec![F(-3.0), D(0.5), FClear]),
        ]
    }

    /// `holes`: for each hole, its in-plane point, the levels of the rapids that bring the
    /// tool to it (the first at the hole), and its clear level; the program starts with a
    /// rapid to (0, 0, 10) and ends with one to `end_level`.
    fn expected(
        plane: &PlaneCase,
        body: &[B],
        holes: &[((f64, f64), &[f64], f64)],
        end_level: f64,
    ) -> Vec<S> {
        let point = |a: f64, b: f64, n: f64| {
            let mut p = [0.0; 3];
            p[plane.index[0]] = a;
            p[plane.index[1]] = b;
            p[plane.index[2]] = n;
            p
        };
        let mut out = vec![S::R(point(0.0, 0.0, 10.0))];
        let mut last = (0.0, 0.0);
        for &((a, b), approach, clear) in holes {
            for level in approach {
                out.push(S::R(point(a, b, *level)));
            }
            for step in body {
                out.push(match *step {
                    B::F(n) => S::F(point(a, b, n)),
                    B::R(n) => S::R(point(a, b, n)),
                    B::FClear => S::F(point(a, b, clear)),
                    B::RClear => S::R(point(a, b, clear)),
                    B::D(s) => S::D(s),
                });
            }
            last = (a, b);
        }
        out.push(S::R(point(last.0, last.1, end_level)));
        // A move to where the tool already is makes no element (G85's rapid to a clear level
        // equal to R).
        let mut at = [0.0; 3];
        out.retain(|s| match s {
            S::R(p) | S::F(p) if *p == at => false,
            S::R(p) | S::F(p) => {
                at = *p;
                true
            }
            S::D(_) => true,
        });
        out
    }

    fn program(plane: &PlaneCase, lines: &[&str]) -> String {
        let [a, b, n] = plane.letters;
        lines
            .iter()
            .map(|l| {
                l.replace("{A}", &a.to_string())
                    .replace("{B}", &b.to_string())
                    .replace("{N}", &n.to_string())
                    .replace("{plane}", plane.code)
                    + "\n"
            })
            .collect()
    }

    #[test]
    fn every_cycle_in_every_plane_in_absolute_mode() {
        for plane in &PLANES {
            for (code, words, spindle, body) in cycles() {
                let first = format!("G98 {code} {{A}}5 {{B}}6 {{N}}-3 R2 {words}");
                let text = program(
                    plane,
                    &[
                        "G21 {plane} G90 G94",
                        "G0 {A}0 {B}0 {N}10",
                        &format!("F600 {spindle}"),
                        &first,
                        // Sticky: only the hole changes.
                        "{A}8",
                        // G99: back to R from now on.
                        "G99 {B}9",
                        // At R already: straight across at R.
                        "{A}5",
                        "G80",
                        "G0 {N}10",
                        "M2",
                    ],
                );
                let holes: [((f64, f64), &[f64], f64); 4] = [
                    ((5.0, 6.0), &[10.0, 2.0], 10.0),
                    ((8.0, 6.0), &[10.0, 2.0], 10.0),
                    ((8.0, 9.0), &[10.0, 2.0], 2.0),
                    ((5.0, 9.0), &[2.0], 2.0),
                ];
                assert_path(&text, &expected(plane, &body, &holes, 10.0));
            }
        }
    }

    #[test]
    fn every_cycle_in_every_plane_in_incremental_mode_with_repeats() {
        for plane in &PLANES {
            for (code, words, spindle, body) in cycles() {
                // Initial level 10: R = 10 − 8 = 2, bottom = R − 5 = −3.
                let first = format!("G91 G98 {code} {{A}}5 {{B}}6 {{N}}-5 R-8 L2 {words}");
                let text = program(
                    plane,
                    &[
                        "G21 {plane} G90 G94",
                        "G0 {A}0 {B}0 {N}10",
                        &format!("F600 {spindle}"),
                        &first,
                        // L is not sticky; the hole moves from the last one.
                        "{A}1",
                        "G99 {B}-2",
                        "{A}-1",
                        "G80",
                        "G90 G0 {N}10",
                        "M2",
                    ],
                );
                let holes: [((f64, f64), &[f64], f64); 5] = [
                    ((5.0, 6.0), &[10.0, 2.0], 10.0),
                    ((10.0, 12.0), &[10.0, 2.0], 10.0),
                    ((11.0, 12.0), &[10.0, 2.0], 10.0),
                    ((11.0, 10.0), &[10.0, 2.0], 2.0),
                    ((10.0, 10.0), &[2.0], 2.0),
                ];
                assert_path(&text, &expected(plane, &body, &holes, 10.0));
            }
        }
    }

    #[test]
    fn a_g18_peck_in_incremental_inch_mode_written_out() {
        use S::*;
        // G20: every number in inches; the peck clearance is 0.010 in. G18: Z and X place the
        // hole, Y is the drill axis. Initial Y = 1 in; R = 1 − 0.5 = 0.5 in; bottom 0.15 in.
        let text = "G20 G18 G90 G94\nG0 X0 Y1 Z0\nF23.622047244094489\n\
                    G91 G99 G83 Z1 X2 Y-0.35 R-0.5 Q0.1\nG80\nM2\n";
        let p = |x: f64, y: f64, z: f64| [x * 25.4, y * 25.4, z * 25.4];
        assert_path(
            text,
            &[
                R(p(0.0, 1.0, 0.0)),
                R(p(2.0, 1.0, 1.0)),
                R(p(2.0, 0.5, 1.0)),
                F(p(2.0, 0.4, 1.0)),
                R(p(2.0, 0.5, 1.0)),
                R(p(2.0, 0.41, 1.0)),
                F(p(2.0, 0.3, 1.0)),
                R(p(2.0, 0.5, 1.0)),
                R(p(2.0, 0.31, 1.0)),
                F(p(2.0, 0.2, 1.0)),
                R(p(2.0, 0.5, 1.0)),
                R(p(2.0, 0.21, 1.0)),
                F(p(2.0, 0.15, 1.0)),
                R(p(2.0, 0.5, 1.0)),
            ],
        );
    }

    #[test]
    fn a_g19_chip_break_under_a_work_offset_written_out() {
        use S::*;
        // G55 at (100, 0, -50); G19: Y and Z place the hole, X is the drill axis. From X 30
        // (program), R 20, bottom 12.5, Q 3: pecks at 17, 14 (then 11 is past the bottom).
        let text = "G10 L2 P2 X100 Z-50\nG55 G21 G19 G90\nG0 X30 Y1 Z2\nF600\n\
                    G98 G73 Y4 Z5 X12.5 R20 Q3\nM2\n";
        let p = |x: f64, y: f64, z: f64| [x + 100.0, y, z - 50.0];
        assert_path(
            text,
            &[
                R(p(30.0, 1.0, 2.0)),
                R(p(30.0, 4.0, 5.0)),
                R(p(20.0, 4.0, 5.0)),
                F(p(17.0, 4.0, 5.0)),
                R(p(17.254, 4.0, 5.0)),
                F(p(14.0, 4.0, 5.0)),
                R(p(14.254, 4.0, 5.0)),
                F(p(12.5, 4.0, 5.0)),
                R(p(30.0, 4.0, 5.0)),
            ],
        );
    }

    #[test]
    fn below_r_the_tool_first_rises_to_r_where_it_is() {
        use S::*;
        // From Z 0, R 3 is above: up to R at (1, 1), then across at R; G98 then returns to R,
        // since the initial level is below it.
        assert_path(
            "G0 X1 Y1\nG98 G81 X5 Y5 Z-2 R3 F600\n",
            &[
                R([1.0, 1.0, 0.0]),
                R([1.0, 1.0, 3.0]),
                R([5.0, 5.0, 3.0]),
                F([5.0, 5.0, -2.0]),
                R([5.0, 5.0, 3.0]),
            ],
        );
    }

    #[test]
    fn l_repeats_in_absolute_mode_drill_the_same_hole_again() {
        use S::*;
        assert_path(
            "G0 Z5\nG98 G81 X1 Y1 Z-1 R1 L2 F600\n",
            &[
                R([0.0, 0.0, 5.0]),
                R([1.0, 1.0, 5.0]),
                R([1.0, 1.0, 1.0]),
                F([1.0, 1.0, -1.0]),
                R([1.0, 1.0, 5.0]),
                R([1.0, 1.0, 1.0]),
                F([1.0, 1.0, -1.0]),
                R([1.0, 1.0, 5.0]),
            ],
        );
    }

    #[test]
    fn the_initial_level_lasts_until_another_motion() {
        use S::*;
        // G99 first (back to R at 2), then G98 with another cycle: the initial level is still
        // the Z before the first cycle (4), not where the second one starts.
        assert_path(
            "G0 Z4\nG99 G81 X1 Z-1 R2 F600\nG98 G82 X2 Z-1 R1 P1\n",
            &[
                R([0.0, 0.0, 4.0]),
                R([1.0, 0.0, 4.0]),
                R([1.0, 0.0, 2.0]),
                F([1.0, 0.0, -1.0]),
                R([1.0, 0.0, 2.0]),
                R([2.0, 0.0, 2.0]),
                R([2.0, 0.0, 1.0]),
                F([2.0, 0.0, -1.0]),
                D(1.0),
                R([2.0, 0.0, 4.0]),
            ],
        );
        // A G0 between ends the run: the second cycle's initial level is 6.
        assert_path(
            "G0 Z4\nG99 G81 X1 Z-1 R2 F600\nG0 Z6\nG98 G81 X2 Z-1 R2\n",
            &[
                R([0.0, 0.0, 4.0]),
                R([1.0, 0.0, 4.0]),
                R([1.0, 0.0, 2.0]),
                F([1.0, 0.0, -1.0]),
                R([1.0, 0.0, 2.0]),
                R([1.0, 0.0, 6.0]),
                R([2.0, 0.0, 6.0]),
                R([2.0, 0.0, 2.0]),
                F([2.0, 0.0, -1.0]),
                R([2.0, 0.0, 6.0]),
            ],
        );
    }

    #[test]
    fn cycle_moves_run_in_exact_path_mode_and_the_mode_comes_back() {
        let p = parse_program(
            "G64 P0.1\nG0 Z5\nG81 X1 Z-1 R1 F600\nG80\nG1 X3\n",
            "t.ngc",
            Vector3::zeros(),
        )
        .unwrap();
        let blends: Vec<_> = p.elements().map(|e| (e.line, e.blend)).collect();
        let blend = BlendMode::Blend {
            p_mm: 0.1,
            q_mm: 0.1,
        };
        assert_eq!(blends.first(), Some(&(2, blend)));
        assert!(
            blends
                .iter()
                .filter(|(line, _)| *line == 3)
                .all(|(_, b)| *b == BlendMode::ExactPath)
        );
        assert_eq!(blends.last(), Some(&(5, blend)));
    }

    #[test]
    fn errors_name_line_column_and_cause() {
        let missing = |code: &'static str, letter: char| move |k: &ErrorKind| matches!(k, ErrorKind::MissingWord { code: c, letter: l, .. } if c == code && *l == letter);
        type Check = Box<dyn Fn(&ErrorKind) -> bool>;
        let cases: Vec<(&str, usize, usize, Check)> = vec![
            (
                "G0 Z5\nG81 X1 Y1 Z-1 F600",
                2,
                1,
                Box::new(missing("G81", 'R')),
            ),
            (
                "G0 Z5\nG81 X1 Y1 R1 F600",
                2,
                1,
                Box::new(missing("G81", 'Z')),
            ),
            (
                "G18 G0 Y5\nG81 X1 Z1 R1 F600",
                2,
                1,
                Box::new(missing("G81", 'Y')),
            ),
            (
                "G19 G0 X5\nG81 Y1 Z1 R1 F600",
                2,
                1,
                Box::new(missing("G81", 'X')),
            ),
            (
                "G0 Z5\nG83 X1 Z-1 R1 F600",
                2,
                1,
                Box::new(missing("G83", 'Q')),
            ),
            (
                "G0 Z5\nG73 X1 Z-1 R1 F600",
                2,
                1,
                Box::new(missing("G73", 'Q')),
            ),
            (
                "G0 Z5\nG82 X1 Z-1 R1 F600",
                2,
                1,
                Box::new(missing("G82", 'P')),
            ),
            ("G0 Z5\nG81 R1 F600", 2, 1, Box::new(missing("G81", 'X'))),
            // A cycle after G80, or after another cycle, needs its R again.
            (
                "G0 Z5\nG81 X1 Z-1 R1 F600\nG80\nG81 X2",
                4,
                1,
                Box::new(missing("G81", 'R')),
            ),
            (
                "G0 Z5\nG81 X1 Z-1 R1 F600\nG82 X2 P1",
                3,
                1,
                Box::new(missing("G82", 'R')),
            ),
            (
                "G0 Z5\nG83 X1 Z-1 R1 Q0 F600",
                2,
                15,
                Box::new(|k| matches!(k, ErrorKind::InvalidValue { word, .. } if word == "Q0")),
            ),
            (
                "G0 Z5\nG83 X1 Z-1 R1 Q-1 F600",
                2,
                15,
                Box::new(|k| matches!(k, ErrorKind::InvalidValue { word, .. } if word == "Q-1")),
            ),
            (
                "G0 Z5\nG81 X1 Z-1 R1 L0 F600",
                2,
                15,
                Box::new(|k| matches!(k, ErrorKind::InvalidValue { word, .. } if word == "L0")),
            ),
            (
                "G0 Z5\nG81 X1 Z-1 R-2 F600",
                2,
                12,
                Box::new(|k| {
                    *k == ErrorKind::CycleRetractBelowBottom {
                        code: "G81",
                        axis: 'Z',
                        r_mm: -2.0,
                        bottom_mm: -1.0,
                    }
                }),
            ),
            (
                // G91: R 1 above the initial 5 is 6, the bottom 2 above R is 8.
                "G0 Z5\nG91 G81 X1 Z2 R1 F600",
                2,
                15,
                Box::new(
                    |k| matches!(k, ErrorKind::CycleRetractBelowBottom { r_mm, bottom_mm, .. } if *r_mm == 6.0 && *bottom_mm == 8.0),
                ),
            ),
            (
                "G0 Z5\nG41.1 D2\nG0 X10\nG81 X20 Z-1 R1 F600",
                4,
                1,
                Box::new(|k| matches!(k, ErrorKind::CompensationActive { code } if code == "G81")),
            ),
            (
                "G0 Z5\nG93 G81 X1 Z-1 R1 F600",
                2,
                5,
                Box::new(|k| *k == ErrorKind::CycleInverseTime { code: "G81" }),
            ),
            (
                "G0 Z5\nG81 X1 Z-1 R1",
                2,
                1,
                Box::new(|k| *k == ErrorKind::MissingFeed { code: "G81" }),
            ),
            (
                "G0 Z5\nG84 X1 Z-1 R1 F600",
                2,
                1,
                Box::new(|k| {
                    *k == ErrorKind::CycleSpindle {
                        code: "G84",
                        needed: "clockwise",
                        fix: "M3",
                    }
                }),
            ),
            (
                "M3\nG74 X1 Z-1 R1 F600",
                2,
                1,
                Box::new(|k| {
                    matches!(
                        k,
                        ErrorKind::CycleSpindle {
                            code: "G74",
                            fix: "M4",
                            ..
                        }
                    )
                }),
            ),
            (
                "M3\nM5\nG86 X1 Z-1 R1 P1 F600",
                3,
                1,
                Box::new(|k| matches!(k, ErrorKind::CycleSpindle { code: "G86", .. })),
            ),
            (
                "G0 Z5\nG81 X1 Z-1 R1 P1 F600",
                2,
                15,
                Box::new(|k| matches!(k, ErrorKind::UnusedWord { letter: 'P', .. })),
            ),
            (
                "G0 Z5\nG81 X1 Z-1 R1 Q1 F600",
                2,
                15,
                Box::new(|k| matches!(k, ErrorKind::UnusedWord { letter: 'Q', .. })),
            ),
            (
                "G0 Z5\nG83 X1 Z-1000 R0 Q0.001 F600",
                2,
                1,
                Box::new(|k| {
                    *k == ErrorKind::CycleTooLong {
                        code: "G83",
                        max: super::MAX_CYCLE_ITEMS,
                    }
                }),
            ),
            (
                // Pecks too small to change the depth in floating point: still bounded.
                "G0 Z5\nG73 X1 Z-100000000 R100000000 Q0.000000001 F600",
                2,
                1,
                Box::new(|k| matches!(k, ErrorKind::CycleTooLong { .. })),
            ),
            (
                "G0 Z5\nG88 X1 Z-1 R1 P1 F600",
                2,
                1,
                Box::new(|k| matches!(k, ErrorKind::Unsupported { what, .. } if what == "G88")),
            ),
            (
                "G0 Z5\nG87 X1 Z-1 R1 I1 J1 K1 F600",
                2,
                1,
                Box::new(|k| matches!(k, ErrorKind::Unsupported { what, .. } if what == "G87")),
            ),
            (
                "G76 P1 Z-1 I1 J1 K1",
                1,
                1,
                Box::new(|k| matches!(k, ErrorKind::Unsupported { what, .. } if what == "G76")),
            ),
        ];
        for (text, line, col, check) in cases {
            let e = error(text);
            assert_eq!((e.line, e.col), (line, col), "{text:?}: {e}");
            assert!(check(&e.kind), "{text:?}: {e}");
        }
    }

    #[test]
    fn messages_say_what_to_do() {
        let e = error("G0 Z5\nG81 X1 Z-1 F600");
        assert_eq!(
            e.to_string(),
            "t.ngc:2:1: G81 needs R: the retract plane on the first line of a cycle"
        );
        let e = error("G0 Z5\nG81 X1 Z-1 R-2 F600");
        assert_eq!(
            e.to_string(),
            "t.ngc:2:12: G81: the retract plane R (-2.0000 mm) is below the hole bottom Z (-1.0000 mm)"
        );
        let e = error("G84 X1 Z-1 R1 F600");
        assert_eq!(
            e.to_string(),
            "t.ngc:1:1: G84 needs the spindle turning clockwise: program M3 before it"
        );
    }
}
