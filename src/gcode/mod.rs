//! G-code front end (minimal): a whole program text into straight moves in absolute millimetres.
//!
//! This is the first stage of the motion pipeline (`gcode → planner → interp`). It reads the
//! G0/G1 subset of RS274/NGC and nothing else; a later front end (arcs, compensation, parameters)
//! replaces it behind the same [`Program`]/[`Move`] output, so downstream code never sees G-code.
//!
//! Units in names: `_mm` millimetres, `_mm_s` millimetres per second. Whatever the program's
//! units (G20 inch / G21 mm) and feed units (per minute), the output is always mm and mm/s.
//!
//! # What is read
//!
//! - Comments `( ... )` (not nested, closed on the same line) and `;` to the end of the line;
//!   upper or lower case; blanks anywhere between words and between a letter and its number.
//! - `%` alone on a line: the first one before any code opens the program, the next one ends it.
//! - `N` line numbers (first word of the line, ignored otherwise).
//! - G0 (rapid), G1 (feed): modal. Axis words on a line with no G0/G1 continue the modal motion;
//!   axis words before any motion code are an error.
//! - G20/G21 (inch/mm, default mm), G90/G91 (absolute/incremental, default absolute),
//!   G61/G61.1/G64 (accepted: this planner always stops exactly at block ends), G17, G94.
//! - F: feed in units per minute (mm/min under G21, in/min under G20), kept in mm/s, so a later
//!   G20/G21 does not change the physical speed. A G1 move with no F programmed yet is an error.
//! - M2/M30: end of program; everything after is ignored (not even scanned).
//! - S, T, M3/M4/M5, M6, M8/M9: accepted and ignored, each leaving a [`Note`].
//! - Axis words X, Y, Z only.
//!
//! Everything else (arcs, other G/M codes, `#` parameters, `[` expressions, O-words, other
//! letters) is an [`Error`] naming file, line and column.
//!
//! # Order within a line
//!
//! All words of a line are read before any takes effect, and every number on the line is in the
//! units in force *after* that line's G20/G21 (so `G20 G1 X1 F10` is 1 in at 10 in/min), and axis
//! words follow the line's G90/G91. Stop codes (M2/M30) act after the line's motion.

mod lex;

use std::fmt;

use nalgebra::Vector3;

pub use lex::MAX_ABS_VALUE;
use lex::Word;

/// Millimetres per inch (exact by definition).
pub const MM_PER_INCH: f64 = 25.4;

/// A parsed program: every move with its absolute target, computed before any motion starts.
#[derive(Debug, Clone, PartialEq)]
pub struct Program {
    /// Name of the source, as given to [`parse_program`] (used in messages).
    pub file: String,
    /// The machine position the program starts from (given by the caller).
    pub start_mm: Vector3<f64>,
    /// The moves in program order. Zero-length moves are kept (the planner skips them).
    pub moves: Vec<Move>,
    /// Words that were accepted but have no effect here (spindle, coolant, tools, G64).
    pub notes: Vec<Note>,
    /// How the program ended.
    pub end: ProgramEnd,
}

impl Program {
    /// The position after the last move (the start position if there is no move).
    pub fn end_mm(&self) -> Vector3<f64> {
        self.moves.last().map_or(self.start_mm, |m| m.target_mm)
    }
}

/// One straight move, in absolute machine millimetres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Move {
    /// 1-based line number in the source text (not the `N` number).
    pub line: usize,
    /// G0: runs at the machine's maximum speed, so it has no feed.
    pub rapid: bool,
    /// Absolute target position.
    pub target_mm: Vector3<f64>,
    /// Programmed path feed for G1 (always `Some` for G1, `None` for G0); finite and positive.
    pub feed_mm_s: Option<f64>,
}

/// A word that was accepted but ignored, kept so the operator can be told.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Note {
    /// 1-based line.
    pub line: usize,
    /// 1-based column (in characters) of the word.
    pub col: usize,
    /// What was ignored and why.
    pub text: String,
}

impl fmt::Display for Note {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:{}: {}", self.line, self.col, self.text)
    }
}

/// How a program ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ProgramEnd {
    /// The text ran out without an end code.
    EndOfText,
    /// M2 on this line.
    M2 {
        /// 1-based line.
        line: usize,
    },
    /// M30 on this line.
    M30 {
        /// 1-based line.
        line: usize,
    },
    /// A closing `%` marker on this line.
    Percent {
        /// 1-based line.
        line: usize,
    },
}

/// A parse error: where it is and what is wrong. Displays as `file:line:col: message`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{file}:{line}:{col}: {kind}")]
pub struct Error {
    /// Name of the source, as given to [`parse_program`].
    pub file: String,
    /// 1-based line (0 for errors that concern no line, such as a bad start position).
    pub line: usize,
    /// 1-based column in characters (0 when there is no line).
    pub col: usize,
    /// What is wrong.
    pub kind: ErrorKind,
}

/// What is wrong with a program.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ErrorKind {
    /// Valid G-code that this front end does not execute.
    #[error("unsupported: {what} ({reason})")]
    Unsupported {
        /// The code or word, e.g. `G2`, `axis 'A'`.
        what: String,
        /// Why, and when it will be supported.
        reason: &'static str,
    },
    /// A letter with no number after it.
    #[error("expected a number after '{letter}'")]
    ExpectedNumber {
        /// The letter.
        letter: char,
    },
    /// A number that is not `[+-]digits[.digits]`.
    #[error("malformed number '{text}' after '{letter}'")]
    MalformedNumber {
        /// The letter.
        letter: char,
        /// The text as written.
        text: String,
    },
    /// A number beyond [`MAX_ABS_VALUE`].
    #[error("number '{text}' after '{letter}' is out of range (at most 1e9 in magnitude)")]
    NumberOutOfRange {
        /// The letter.
        letter: char,
        /// The text as written.
        text: String,
    },
    /// A character that starts no word, comment or marker.
    #[error("unexpected character {ch:?}")]
    UnexpectedChar {
        /// The character.
        ch: char,
    },
    /// `(` with no `)` on the same line.
    #[error("comment '(' is not closed on this line")]
    UnclosedComment,
    /// `(` inside a comment.
    #[error("nested comment: '(' inside a comment")]
    NestedComment,
    /// `)` with no comment open.
    #[error("')' without a matching '('")]
    UnmatchedParen,
    /// `%` with other words on its line, or twice.
    #[error("'%' must be alone on its line (program start/end marker)")]
    MisplacedPercent,
    /// The same letter twice on one line (G and M excepted).
    #[error("word '{letter}' appears twice on one line")]
    RepeatedWord {
        /// The letter.
        letter: char,
    },
    /// Two codes of the same modal group on one line, e.g. G0 and G1.
    #[error("{first} and {second} on one line are both {group} codes (one per line)")]
    ModalConflict {
        /// The modal group, e.g. `motion`, `units`.
        group: &'static str,
        /// The first code, e.g. `G0`.
        first: String,
        /// The second code, e.g. `G1`.
        second: String,
    },
    /// A value that is not valid for its letter (G1.23, M-1, N1.5, F0, S-5, T2.5).
    #[error("invalid {word}: expected {expected}")]
    InvalidValue {
        /// The word as written, e.g. `F0`.
        word: String,
        /// What was expected.
        expected: &'static str,
    },
    /// A G1 move and no F programmed so far.
    #[error(
        "G1 move with no feed rate: program F (mm/min, or in/min under G20) on this line or before"
    )]
    MissingFeed,
    /// Axis words and no motion mode (G0/G1) in force.
    #[error("axis words with no motion mode in force: add G0 or G1")]
    AxisWithoutMotion,
    /// An `N` word that is not the first word of its line.
    #[error("line number 'N' must be the first word of the line")]
    LineNumberNotFirst,
    /// The caller's start position has a NaN or infinite coordinate.
    #[error("start position is not finite")]
    NonFiniteStart,
}

/// Parses a whole program. Moves get absolute targets, starting from `start_mm` (the machine's
/// actual position), so G91 and partial axis words resolve against where the machine really is.
///
/// `file` only names the source in errors. Never panics, whatever the text.
pub fn parse_program(text: &str, file: &str, start_mm: Vector3<f64>) -> Result<Program, Error> {
    let err = |line: usize, col: usize, kind: ErrorKind| Error {
        file: file.to_owned(),
        line,
        col,
        kind,
    };
    if !start_mm.iter().all(|v| v.is_finite()) {
        return Err(err(0, 0, ErrorKind::NonFiniteStart));
    }
    let mut state = State {
        motion: None,
        inch: false,
        incremental: false,
        feed_mm_s: None,
        position_mm: start_mm,
    };
    let mut moves = Vec::new();
    let mut notes = Vec::new();
    let mut end = ProgramEnd::EndOfText;
    let mut opened = false;
    let mut code_seen = false;
    let mut chars = Vec::new();
    for (index, text_line) in text.lines().enumerate() {
        let line = index + 1;
        let scanned =
            lex::scan_line(text_line, &mut chars).map_err(|(col, k)| err(line, col, k))?;
        if scanned.percent {
            if !opened && !code_seen {
                opened = true;
                continue;
            }
            end = ProgramEnd::Percent { line };
            break;
        }
        if scanned.words.is_empty() {
            continue;
        }
        code_seen = true;
        let block = Block::read(&scanned.words).map_err(|(col, k)| err(line, col, k))?;
        let stop = state
            .execute(&block, line, &mut moves, &mut notes)
            .map_err(|(col, k)| err(line, col, k))?;
        if let Some(stop) = stop {
            end = stop;
            break;
        }
    }
    Ok(Program {
        file: file.to_owned(),
        start_mm,
        moves,
        notes,
        end,
    })
}

type BlockError = (usize, ErrorKind);

/// Modal state carried from line to line.
#[derive(Debug, Clone, Copy)]
struct State {
    /// `Some(true)` G0, `Some(false)` G1.
    motion: Option<bool>,
    inch: bool,
    incremental: bool,
    feed_mm_s: Option<f64>,
    position_mm: Vector3<f64>,
}

/// A G or M code: value in tenths (`G61.1` is 611), with the column of its word.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Code {
    letter: char,
    tenths: u32,
    col: usize,
}

impl fmt::Display for Code {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.tenths.is_multiple_of(10) {
            write!(f, "{}{}", self.letter, self.tenths / 10)
        } else {
            write!(
                f,
                "{}{}.{}",
                self.letter,
                self.tenths / 10,
                self.tenths % 10
            )
        }
    }
}

/// The words of one line, checked and sorted into modal groups, before any takes effect.
#[derive(Debug, Default)]
struct Block<'a> {
    motion: Option<Code>,
    plane: Option<Code>,
    units: Option<Code>,
    path: Option<Code>,
    distance: Option<Code>,
    feed_mode: Option<Code>,
    stop: Option<Code>,
    spindle: Option<Code>,
    tool_change: Option<Code>,
    coolant: Option<Code>,
    axes: [Option<&'a Word>; 3],
    feed: Option<&'a Word>,
    speed: Option<&'a Word>,
    tool: Option<&'a Word>,
}

/// Why a G code (in tenths) is not supported.
fn g_reason(tenths: u32) -> &'static str {
    match tenths {
        20 | 30 => "arcs arrive with the full G-code front end",
        40 => "dwell arrives with the full G-code front end",
        50..=53 => "splines arrive with the full G-code front end",
        171..=199 => "only the XY plane (G17) is supported; planes matter for arcs",
        400..=429 => "cutter radius compensation arrives with the full G-code front end",
        430..=499 => "tool length compensation arrives with the full G-code front end",
        100..=109 | 520..=599 | 920..=929 => {
            "coordinate systems and offsets arrive with the full G-code front end"
        }
        280..=309 => "reference-point returns are not supported",
        330..=339 | 760 => "threading is not supported",
        380..=389 => "probing is not supported",
        730 | 740 | 800..=899 => "canned cycles arrive with the full G-code front end",
        900..=909 | 911..=919 => "arc centre modes arrive with the full G-code front end",
        930 | 950 => "only units-per-minute feed (G94) is supported",
        _ => "not handled by the minimal G0/G1 front end",
    }
}

/// A G or M value as tenths: non-negative, at most one decimal.
fn code_tenths(word: &Word) -> Option<u32> {
    let tenths = word.value * 10.0;
    let rounded = tenths.round();
    if word.value < 0.0 || (tenths - rounded).abs() > 1e-6 || rounded > f64::from(u32::MAX) {
        return None;
    }
    // In range and integral: the cast is exact.
    Some(rounded as u32)
}

fn is_nonneg_integer(value: f64) -> bool {
    value >= 0.0 && value.fract() == 0.0
}

fn invalid(word: &Word, expected: &'static str) -> BlockError {
    (
        word.col,
        ErrorKind::InvalidValue {
            word: word.display(),
            expected,
        },
    )
}

impl<'a> Block<'a> {
    /// Checks every word of a line; the first problem in line order is reported.
    fn read(words: &'a [Word]) -> Result<Block<'a>, BlockError> {
        let mut block = Block::default();
        for (i, word) in words.iter().enumerate() {
            match word.letter {
                'G' => {
                    let tenths = code_tenths(word)
                        .ok_or_else(|| invalid(word, "a G code such as G1 or G61.1"))?;
                    let code = Code {
                        letter: 'G',
                        tenths,
                        col: word.col,
                    };
                    let (slot, group) = match tenths {
                        0 | 10 => (&mut block.motion, "motion"),
                        170 => (&mut block.plane, "plane"),
                        200 | 210 => (&mut block.units, "units"),
                        610 | 611 | 640 => (&mut block.path, "path control"),
                        900 | 910 => (&mut block.distance, "distance mode"),
                        940 => (&mut block.feed_mode, "feed mode"),
                        _ => {
                            return Err((
                                word.col,
                                ErrorKind::Unsupported {
                                    what: code.to_string(),
                                    reason: g_reason(tenths),
                                },
                            ));
                        }
                    };
                    set_code(slot, code, group)?;
                }
                'M' => {
                    let tenths = code_tenths(word)
                        .filter(|t| t.is_multiple_of(10))
                        .ok_or_else(|| invalid(word, "an M code such as M2 or M30"))?;
                    let code = Code {
                        letter: 'M',
                        tenths,
                        col: word.col,
                    };
                    let (slot, group) = match tenths / 10 {
                        2 | 30 => (&mut block.stop, "program stop"),
                        3..=5 => (&mut block.spindle, "spindle"),
                        6 => (&mut block.tool_change, "tool change"),
                        8 | 9 => (&mut block.coolant, "coolant"),
                        n => {
                            let reason = match n {
                                0 | 1 => "program pause is not supported yet",
                                _ => "not handled by the minimal G0/G1 front end",
                            };
                            return Err((
                                word.col,
                                ErrorKind::Unsupported {
                                    what: code.to_string(),
                                    reason,
                                },
                            ));
                        }
                    };
                    set_code(slot, code, group)?;
                }
                'N' => {
                    if i != 0 {
                        return Err((word.col, ErrorKind::LineNumberNotFirst));
                    }
                    if !is_nonneg_integer(word.value) {
                        return Err(invalid(word, "a non-negative integer line number"));
                    }
                }
                'X' => set_word(&mut block.axes[0], word)?,
                'Y' => set_word(&mut block.axes[1], word)?,
                'Z' => set_word(&mut block.axes[2], word)?,
                'F' => {
                    set_word(&mut block.feed, word)?;
                    if word.value <= 0.0 {
                        return Err(invalid(word, "a feed rate greater than zero"));
                    }
                }
                'S' => {
                    set_word(&mut block.speed, word)?;
                    if word.value < 0.0 {
                        return Err(invalid(word, "a non-negative spindle speed"));
                    }
                }
                'T' => {
                    set_word(&mut block.tool, word)?;
                    if !is_nonneg_integer(word.value) {
                        return Err(invalid(word, "a non-negative integer tool number"));
                    }
                }
                // The scanner only lets the letters above through.
                other => {
                    return Err((
                        word.col,
                        ErrorKind::Unsupported {
                            what: format!("word '{other}'"),
                            reason: "it is not a word of this G0/G1 front end",
                        },
                    ));
                }
            }
        }
        Ok(block)
    }
}

fn set_code(slot: &mut Option<Code>, code: Code, group: &'static str) -> Result<(), BlockError> {
    if let Some(first) = slot {
        return Err((
            code.col,
            ErrorKind::ModalConflict {
                group,
                first: first.to_string(),
                second: code.to_string(),
            },
        ));
    }
    *slot = Some(code);
    Ok(())
}

fn set_word<'a>(slot: &mut Option<&'a Word>, word: &'a Word) -> Result<(), BlockError> {
    if slot.is_some() {
        return Err((
            word.col,
            ErrorKind::RepeatedWord {
                letter: word.letter,
            },
        ));
    }
    *slot = Some(word);
    Ok(())
}

impl State {
    /// Applies one checked line; returns how the program ended if it did on this line.
    fn execute(
        &mut self,
        block: &Block<'_>,
        line: usize,
        moves: &mut Vec<Move>,
        notes: &mut Vec<Note>,
    ) -> Result<Option<ProgramEnd>, BlockError> {
        let mut note = |col: usize, text: String| notes.push(Note { line, col, text });
        for word in [block.speed, block.tool].into_iter().flatten() {
            let what = if word.letter == 'S' {
                "spindle speed"
            } else {
                "tool selection"
            };
            note(
                word.col,
                format!(
                    "ignored {} ({what} is not handled by the motion gateway)",
                    word.display()
                ),
            );
        }
        for (code, what) in [
            (block.tool_change, "tool change"),
            (block.spindle, "spindle control"),
            (block.coolant, "coolant control"),
        ] {
            if let Some(code) = code {
                note(
                    code.col,
                    format!("ignored {code} ({what} is not handled by the motion gateway)"),
                );
            }
        }
        if let Some(code) = block.path.filter(|c| c.tenths == 640) {
            note(
                code.col,
                format!("{code} accepted: this planner stops exactly at every block end (as G61)"),
            );
        }
        if let Some(units) = block.units {
            self.inch = units.tenths == 200;
        }
        if let Some(distance) = block.distance {
            self.incremental = distance.tenths == 910;
        }
        let scale_mm = if self.inch { MM_PER_INCH } else { 1.0 };
        if let Some(feed) = block.feed {
            self.feed_mm_s = Some(feed.value * scale_mm / 60.0);
        }
        if let Some(motion) = block.motion {
            self.motion = Some(motion.tenths == 0);
        }
        let first_axis = block.axes.iter().flatten().min_by_key(|w| w.col);
        if let Some(first_axis) = first_axis {
            let rapid = self
                .motion
                .ok_or((first_axis.col, ErrorKind::AxisWithoutMotion))?;
            let feed_mm_s = if rapid {
                None
            } else {
                let col = block.motion.map_or(first_axis.col, |c| c.col);
                Some(self.feed_mm_s.ok_or((col, ErrorKind::MissingFeed))?)
            };
            let mut target_mm = self.position_mm;
            for (axis, word) in block.axes.iter().enumerate() {
                if let Some(word) = word {
                    let value_mm = word.value * scale_mm;
                    target_mm[axis] = if self.incremental {
                        target_mm[axis] + value_mm
                    } else {
                        value_mm
                    };
                }
            }
            self.position_mm = target_mm;
            moves.push(Move {
                line,
                rapid,
                target_mm,
                feed_mm_s,
            });
        }
        Ok(block.stop.map(|stop| {
            if stop.tenths == 20 {
                ProgramEnd::M2 { line }
            } else {
                ProgramEnd::M30 { line }
            }
        }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn v(x: f64, y: f64, z: f64) -> Vector3<f64> {
        Vector3::new(x, y, z)
    }

    fn parse(text: &str) -> Result<Program, Error> {
        parse_program(text, "prog.ngc", Vector3::zeros())
    }

    fn mv(line: usize, rapid: bool, target_mm: Vector3<f64>, feed_mm_s: Option<f64>) -> Move {
        Move {
            line,
            rapid,
            target_mm,
            feed_mm_s,
        }
    }

    #[test]
    fn golden_program() {
        let text = "%\n\
                    (header: a comment line)\n\
                    N10 G21 G90 G17 G94 G61 ; setup\n\
                    n20 g0 x10 y20 z5\n\
                    N30 G1 X15 F600\n\
                    Y25 (modal G1 continues)\n\
                    G91 X1 Y-1\n\
                    G20 G90 X1 Y2 Z0.5 F10\n\
                    \n\
                    G91G0Z.1\n\
                    M30\n\
                    G2 X1 garbage after the end is never read !\n\
                    %\n";
        let p = parse_program(text, "golden.ngc", v(1.0, 2.0, 3.0)).unwrap();
        let expected = vec![
            mv(4, true, v(10.0, 20.0, 5.0), None),
            mv(5, false, v(15.0, 20.0, 5.0), Some(10.0)),
            mv(6, false, v(15.0, 25.0, 5.0), Some(10.0)),
            mv(7, false, v(16.0, 24.0, 5.0), Some(10.0)),
            mv(8, false, v(25.4, 50.8, 12.7), Some(10.0 * 25.4 / 60.0)),
            mv(10, true, v(25.4, 50.8, 12.7 + 0.1 * 25.4), None),
        ];
        assert_eq!(p.moves, expected);
        assert_eq!(p.end, ProgramEnd::M30 { line: 11 });
        assert_eq!(p.start_mm, v(1.0, 2.0, 3.0));
        assert_eq!(p.end_mm(), v(25.4, 50.8, 12.7 + 0.1 * 25.4));
        assert!(p.notes.is_empty());
        assert_eq!(p.file, "golden.ngc");
    }

    #[test]
    fn incremental_from_the_callers_start() {
        let p = parse_program("G91 G1 X1 F60\nY-2\nG90 Z7", "p", v(5.0, 5.0, 5.0)).unwrap();
        assert_eq!(
            p.moves,
            vec![
                mv(1, false, v(6.0, 5.0, 5.0), Some(1.0)),
                mv(2, false, v(6.0, 3.0, 5.0), Some(1.0)),
                mv(3, false, v(6.0, 3.0, 7.0), Some(1.0)),
            ]
        );
        assert_eq!(p.end, ProgramEnd::EndOfText);
    }

    #[test]
    fn feed_keeps_physical_speed_across_unit_changes() {
        let p = parse("G20 G1 X1 F60\nG21 X50").unwrap();
        assert_eq!(p.moves[0].feed_mm_s, Some(25.4));
        assert_eq!(p.moves[1].feed_mm_s, Some(25.4));
        assert_eq!(p.moves[1].target_mm, v(50.0, 0.0, 0.0));
    }

    #[test]
    fn zero_length_and_motion_only_lines() {
        let p = parse("G1 F100\nG0\nX0\nG91 X0 Y0").unwrap();
        assert_eq!(
            p.moves,
            vec![
                mv(3, true, Vector3::zeros(), None),
                mv(4, true, Vector3::zeros(), None)
            ]
        );
    }

    #[test]
    fn ignored_words_leave_notes() {
        let p = parse("T1 M6\nS1000 M3 M8\nG64\nG0 X1\nM5 M9\nM2\nX5").unwrap();
        assert_eq!(p.moves.len(), 1);
        assert_eq!(p.end, ProgramEnd::M2 { line: 6 });
        let at: Vec<(usize, usize)> = p.notes.iter().map(|n| (n.line, n.col)).collect();
        assert_eq!(
            at,
            vec![
                (1, 1),
                (1, 4),
                (2, 1),
                (2, 7),
                (2, 10),
                (3, 1),
                (5, 1),
                (5, 4)
            ]
        );
        assert_eq!(
            p.notes[2].to_string(),
            "2:1: ignored S1000 (spindle speed is not handled by the motion gateway)"
        );
        assert!(p.notes[5].text.starts_with("G64 accepted"));
    }

    #[test]
    fn percent_markers() {
        let p = parse("%\nG0 X1\n%\nG0 X2").unwrap();
        assert_eq!(p.moves.len(), 1);
        assert_eq!(p.end, ProgramEnd::Percent { line: 3 });
        // Without an opening marker a % after code ends the program too.
        let p = parse("G0 X1\n%\n@@@").unwrap();
        assert_eq!(p.end, ProgramEnd::Percent { line: 2 });
    }

    #[test]
    fn crlf_and_tabs() {
        let p = parse("G0\tX1\r\nY2\r\n").unwrap();
        assert_eq!(p.moves[1].target_mm, v(1.0, 2.0, 0.0));
    }

    /// (program, line, col, message) for every error kind.
    const ERRORS: &[(&str, usize, usize, &str)] = &[
        (
            "G0 X1\nG91\nX1 G2 Y1",
            3,
            4,
            "unsupported: G2 (arcs arrive with the full G-code front end)",
        ),
        (
            "G0 A1",
            1,
            4,
            "unsupported: axis 'A' (only the X, Y and Z axes are supported)",
        ),
        (
            "G0 X1 I2",
            1,
            7,
            "unsupported: word 'I' (arc words arrive with the full G-code front end)",
        ),
        (
            "G0 X#1",
            1,
            5,
            "unsupported: parameter '#' (parameters arrive with the full G-code front end)",
        ),
        (
            "#1=2",
            1,
            1,
            "unsupported: parameter '#' (parameters arrive with the full G-code front end)",
        ),
        (
            "G0 X[1+2]",
            1,
            5,
            "unsupported: expression '[' (expressions arrive with the full G-code front end)",
        ),
        (
            "o100 sub",
            1,
            1,
            "unsupported: O-word (subroutines and control flow arrive with the full G-code front end)",
        ),
        (
            "/G0 X1",
            1,
            1,
            "unsupported: block delete '/' (optional blocks are not supported)",
        ),
        (
            "G54",
            1,
            1,
            "unsupported: G54 (coordinate systems and offsets arrive with the full G-code front end)",
        ),
        (
            "G61.2",
            1,
            1,
            "unsupported: G61.2 (not handled by the minimal G0/G1 front end)",
        ),
        (
            "M0",
            1,
            1,
            "unsupported: M0 (program pause is not supported yet)",
        ),
        (
            "G1 F100 X1\nM1",
            2,
            1,
            "unsupported: M1 (program pause is not supported yet)",
        ),
        (
            "M7",
            1,
            1,
            "unsupported: M7 (not handled by the minimal G0/G1 front end)",
        ),
        ("G1 F100\nG0 X1\nX", 3, 1, "expected a number after 'X'"),
        ("G0 X1 Y", 1, 7, "expected a number after 'Y'"),
        ("G0 Xa", 1, 4, "expected a number after 'X'"),
        ("G0 X1.2.3", 1, 4, "malformed number '1.2.3' after 'X'"),
        ("G0 X1-2", 1, 4, "malformed number '1-2' after 'X'"),
        ("G0 X-", 1, 4, "malformed number '-' after 'X'"),
        (
            "G0 X12345678901",
            1,
            4,
            "number '12345678901' after 'X' is out of range (at most 1e9 in magnitude)",
        ),
        ("G0 X1 !", 1, 7, "unexpected character '!'"),
        (
            "G0 X1 (comment",
            1,
            7,
            "comment '(' is not closed on this line",
        ),
        ("G0 (a (b) c)", 1, 7, "nested comment: '(' inside a comment"),
        ("G0 X1)", 1, 6, "')' without a matching '('"),
        (
            "G0 X1 %",
            1,
            7,
            "'%' must be alone on its line (program start/end marker)",
        ),
        ("G0 X1 x2", 1, 7, "word 'X' appears twice on one line"),
        ("G1 F1 F2", 1, 7, "word 'F' appears twice on one line"),
        (
            "G0 G1 X1",
            1,
            4,
            "G0 and G1 on one line are both motion codes (one per line)",
        ),
        (
            "G20 G21",
            1,
            5,
            "G20 and G21 on one line are both units codes (one per line)",
        ),
        (
            "M3 M5",
            1,
            4,
            "M3 and M5 on one line are both spindle codes (one per line)",
        ),
        (
            "G1.23",
            1,
            1,
            "invalid G1.23: expected a G code such as G1 or G61.1",
        ),
        (
            "M-2",
            1,
            1,
            "invalid M-2: expected an M code such as M2 or M30",
        ),
        (
            "M2.5",
            1,
            1,
            "invalid M2.5: expected an M code such as M2 or M30",
        ),
        (
            "N1.5 G0",
            1,
            1,
            "invalid N1.5: expected a non-negative integer line number",
        ),
        (
            "G1 F0 X1",
            1,
            4,
            "invalid F0: expected a feed rate greater than zero",
        ),
        (
            "G1 F-5",
            1,
            4,
            "invalid F-5: expected a feed rate greater than zero",
        ),
        (
            "S-5",
            1,
            1,
            "invalid S-5: expected a non-negative spindle speed",
        ),
        (
            "T2.5",
            1,
            1,
            "invalid T2.5: expected a non-negative integer tool number",
        ),
        (
            "G0 X1\nG1 Y2",
            2,
            1,
            "G1 move with no feed rate: program F (mm/min, or in/min under G20) on this line or before",
        ),
        (
            "G1\n\nY2 X1",
            3,
            1,
            "G1 move with no feed rate: program F (mm/min, or in/min under G20) on this line or before",
        ),
        (
            "X1",
            1,
            1,
            "axis words with no motion mode in force: add G0 or G1",
        ),
        (
            "G0 X1 N5",
            1,
            7,
            "line number 'N' must be the first word of the line",
        ),
    ];

    #[test]
    fn every_error_kind_with_its_position() {
        for &(text, line, col, message) in ERRORS {
            let e = parse(text).expect_err(text);
            assert_eq!((e.line, e.col), (line, col), "{text:?}: {e}");
            assert_eq!(
                e.to_string(),
                format!("prog.ngc:{line}:{col}: {message}"),
                "{text:?}"
            );
        }
    }

    #[test]
    fn non_finite_start_is_an_error() {
        let e = parse_program("G0 X1", "p", v(f64::NAN, 0.0, 0.0)).unwrap_err();
        assert_eq!(e.kind, ErrorKind::NonFiniteStart);
        assert_eq!(e.to_string(), "p:0:0: start position is not finite");
    }

    #[test]
    fn first_error_in_the_program_wins() {
        let e = parse("G0 X1\nG2 X1\nG3 X1").unwrap_err();
        assert_eq!((e.line, e.col), (2, 1));
    }

    fn check_program(text: &str) {
        if let Ok(p) = parse_program(text, "fuzz", v(1.0, -2.0, 3.0)) {
            for m in &p.moves {
                assert!(m.target_mm.iter().all(|c| c.is_finite()));
                assert_eq!(m.rapid, m.feed_mm_s.is_none());
                if let Some(f) = m.feed_mm_s {
                    assert!(f.is_finite() && f > 0.0);
                }
            }
        }
    }

    proptest! {
        #[test]
        fn never_panics_on_any_string(text in any::<String>()) {
            check_program(&text);
        }

        #[test]
        fn never_panics_on_any_bytes(bytes in proptest::collection::vec(any::<u8>(), 0..400)) {
            check_program(&String::from_utf8_lossy(&bytes));
        }

        #[test]
        fn never_panics_on_gcode_like_text(
            text in "[GgMmNXxYyZzFfSTIA#%0-9 .+\\-();\n]{0,300}"
        ) {
            check_program(&text);
        }
    }
}
