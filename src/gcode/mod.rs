//! G-code front end: a streaming reader and modal interpreter of the LinuxCNC / RS274/NGC
//! dialect, from program text to path [`Element`]s in machine millimetres.
//!
//! First stage of the motion pipeline (`gcode → compensation → planner → interpolator`). Downstream
//! code never sees G-code: it gets [`Item`]s (lines, arcs and helices, dwells, program stops,
//! notes, the end) from an [`Interpreter`] over any [`std::io::BufRead`], one line read at a
//! time, so memory stays bounded whatever the file size. [`parse_program`] collects a whole
//! text into a [`Program`] for callers that want it at once.
//!
//! Units in names: `_mm` millimetres, `_mm_s` mm/s, `_s` seconds, `_deg` degrees. Whatever the
//! program's units (G20 inch / G21 mm), the output is in mm and mm/s, in machine coordinates:
//! work offsets (G54…G59.3, G10 L2/L20, rotation), G92 offsets and the tool length offset
//! (G43/G43.1/G43.2/G44) are applied, so an element's points are the axis positions.
//!
//! # What is read
//!
//! - Comments `( ... )` (not nested, closed on the same line; `(MSG, text)` becomes a note) and
//!   `;` to the end of the line; upper or lower case; blanks between words and between a letter
//!   and its number; several words per line; `N` line numbers (first word).
//! - `%` alone on a line: the first one before any code opens the program, the next one ends it.
//!   `O1234` (or `O<name>`) alone on a line is a program number and is skipped.
//! - Block delete `/` at the start of a line: skipped while [`Setup::block_delete`] is on.
//! - Motion (modal, also for axis words on lines with no G word): G0, G1, G2/G3 (IJK centre or R
//!   radius, negative R for more than 180°, full circles when the end equals the start, helices
//!   with the third axis, `P` turns), G80 (motion off), the canned cycles G73, G74, G81…G86,
//!   G89 with R Q P L and G98/G99 (expanded into lines and dwells: `cycles.rs`). G53
//!   (non-modal: G0/G1 in machine
//!   coordinates), G28/G30 (rapid to the stored position, via the axis words' point if any),
//!   G28.1/G30.1 (store the current position). Polar words on G0/G1: `@` distance, `^` angle
//!   (degrees) about the work system's origin (G91: added to the current distance and angle).
//!   Centre-format arcs whose end is off the circle within LinuxCNC's tolerance are spirals.
//!   G5.1 (quadratic) and G5 (cubic) splines in G17, sampled into lines on the exact curve
//!   within [`Setup::spline_tol_mm`] (`splines.rs`).
//! - Auxiliary axes A B C (degrees) and U V W on G0/G1/G2/G3/G53 moves, G92/G52 and G10
//!   L2/L20, for the axes [`Setup::aux_axes`] names; carried linearly in the path parameter
//!   ([`AuxMove`]), F as LinuxCNC's canon reads it (X/Y/Z path speed, else U/V/W, else deg/min
//!   over the A/B/C length), wrapped rotary axes as LinuxCNC turns them, or the shortest way ([`Setup::aux_wrapped`]).
//! - Modes: G17/G18/G19, G20/G21, G90/G91, G90.1/G91.1, G93/G94 (inverse time: F on every feed
//!   line; changing the mode clears the feed), G61/G61.1/G64 P Q, G40/G41/G42 D /G41.1/G42.1 D L
//!   (as LinuxCNC reads them: D0 the tool in the spindle, a negative diameter swaps the side,
//!   L only in G18 and only 0 or 9), G43 H/G43.1/G43.2/G44 H/G49, G54…G59.3, G7/G8 (under G7
//!   X words are diameters, halved as they are read; I, K, R stay radii).
//! - G4 P (dwell, seconds), G10 L1 P R Z (tool table), G10 L10/L11 P Z R (tool touch-off; R
//!   negative too), G10 L2/L20 P X Y Z R (work offsets and rotation, L20 on rotated systems), G52 (local offset, in the G92 register),
//!   G92/G92.1/G92.2/G92.3; line numbers `N`, fractional too.
//! - M0/M1 (program stops), M2/M30 (end: nothing after them is read), M6 and M61 Q (set the
//!   tool in the spindle), M70/M71/M72/M73 (save, invalidate, restore, auto-restore the modal
//!   state, per call level), and F, S, T, M3/M4/M5/M19, M7/M8/M9, M48…M53, G97 accepted:
//!   the ones without a motion effect leave a [`Note`].
//!
//! - Parameters `#1`…`#4999` and `#<name>` (local to a call, global when the name starts with
//!   `_`), LinuxCNC's system parameters #5070, #5161…, #5220, #5420… (read-only, see
//!   `State::system_parameters`), LinuxCNC's predefined named parameters `#<_x>`,
//!   `#<_motion_mode>`... (read-only, `expr::PREDEFINED`), assignments (all of a line's take effect after it is read), expressions `[ ]` with
//!   LinuxCNC's operators and functions, and O-word flow control: `sub`/`endsub`/`call`/`return`,
//!   `if`/`elseif`/`else`/`endif`, `while`/`endwhile`, `do`/`while`, `repeat`/`endrepeat`,
//!   `break`, `continue`; computed call labels (`o[#1+2] call`); subroutine files
//!   (`o<name> call` loads `name.ngc` from [`Setup::subroutine_path`], errors inside name that
//!   file and the calls that led there: [`Error::called_from`]); Fanuc-style `O100` ... `M99`
//!   subprograms called by `M98 P L` (read ahead when they follow the call), and M99 in the
//!   main program (restarts it [`Setup::m99_restarts`] times, then ends it). Subroutine bodies,
//!   lines read ahead, and a loop or `if` of the main program while it runs, are kept in memory
//!   (at most [`MAX_STORED_BYTES`]); everything else streams.
//!
//! Everything else is an [`Error`] naming file, line and column, never a silent skip: the
//! G87/G88 cycles, G33/G76 and other spindle-synchronised motion, G95/G96, G38 probing, NURBS
//! (G5.2/G5.3), polar words on arcs and splines, A/B/C/U/V/W words anywhere but on G0/G1/G2/G3/G53 moves (and
//! their motion under cutter compensation), the other system parameters, spirals beyond the
//! tolerance, computed labels on anything but `call` are [`ErrorKind::Unsupported`]; a
//! subroutine neither defined nor found as a file is [`ErrorKind::UndefinedSubroutine`].
//!
//! Every number of a line is read in the units in force *after* that line's G20/G21, and a feed
//! keeps its physical speed when the units change later.
//!
//! One machine, one state: [`Setup::carry`] starts an interpretation from what the last one on
//! the machine left ([`Program::carry`], [`Interpreter::carry`]: modes, offsets, tools,
//! parameters, with M2/M30's resets), as `canmotion serve` runs MDI lines ([`parse_mdi`]) and
//! programs one after the other; see [`Carry`].

mod block;
mod element;
mod expr;
mod interpreter;
mod lex;
mod tool_table;
// `splines.rs` and `cycles.rs` are children of `interpreter`.

use std::fmt;
use std::io::BufRead;

use nalgebra::Vector3;

pub use element::{
    AUX_LETTERS, ArcGeometry, AuxMove, AuxPos, BlendMode, CompState, Element, ElementKind,
    FULL_CIRCLE_EPS_MM, Plane,
};
pub use expr::{MAX_NAMED_PARAMETERS, MAX_NESTING, MAX_USER_PARAMETER};
pub use interpreter::{
    Carry, DEFAULT_SPLINE_TOL_MM, Interpreter, MAX_CALL_DEPTH, MAX_CYCLE_ITEMS, MAX_IDLE_LINES,
    MAX_LINE_BYTES, MAX_POSITION_MM, MAX_SPLINE_SEGMENTS, MAX_STORED_BYTES, MDI_FILE,
    MIN_ARC_RADIUS_MM, MIN_SPLINE_TOL_MM, Setup,
};
pub use lex::MAX_ABS_VALUE;
pub use tool_table::{MAX_TOOL_NUMBER, MAX_TOOL_SIZE_MM, Tool, ToolTable};

/// The lines of `text` as the [`Interpreter`] reads them, each with its terminator: a line ends
/// at `\n`, `\r\n` or a lone `\r`. Line `k` of the interpreter's errors is item `k − 1`.
pub fn split_lines_inclusive(text: &[u8]) -> impl Iterator<Item = &[u8]> {
    let mut rest = text;
    std::iter::from_fn(move || {
        if rest.is_empty() {
            return None;
        }
        let end = match rest.iter().position(|b| *b == b'\n' || *b == b'\r') {
            Some(i) if rest[i] == b'\r' && rest.get(i + 1) == Some(&b'\n') => i + 2,
            Some(i) => i + 1,
            None => rest.len(),
        };
        let (line, tail) = rest.split_at(end);
        rest = tail;
        Some(line)
    })
}

/// Millimetres per inch (exact by definition).
pub const MM_PER_INCH: f64 = 25.4;

/// One output of the interpreter, in program order.
// Items pass through the stages one at a time, by value: boxing the element (the large variant
// since it carries the auxiliary axes) would allocate once per motion line in the front end.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, PartialEq)]
pub enum Item {
    /// A line, arc or helix.
    Motion(Element),
    /// G4: stay still.
    Dwell(Dwell),
    /// M0, or M1 with the optional stop switch on: wait for the operator.
    Stop(Stop),
    /// Something accepted without a motion effect (spindle, coolant, tool selection, messages).
    Note(Note),
    /// The program ended; always the last item.
    End(ProgramEnd),
}

impl Item {
    /// The motion element, if this is one.
    pub fn motion(&self) -> Option<&Element> {
        match self {
            Item::Motion(e) => Some(e),
            _ => None,
        }
    }
}

/// G4 P: a pause of the motion.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Dwell {
    /// 1-based line.
    pub line: usize,
    /// 1-based column of the G4 word.
    pub col: usize,
    /// How long, ≥ 0.
    pub seconds: f64,
}

/// M0 / M1: a program stop; the program resumes when the operator says so.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Stop {
    /// 1-based line.
    pub line: usize,
    /// 1-based column of the M word.
    pub col: usize,
    /// M1 (optional stop) rather than M0.
    pub optional: bool,
}

/// A word that was accepted without a motion effect, kept so the operator can be told.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Note {
    /// 1-based line.
    pub line: usize,
    /// 1-based column (in characters) of the word.
    pub col: usize,
    /// What it was and why it has no effect.
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
    /// M99 in the main program on this line, after the restarts [`Setup::m99_restarts`]
    /// allows (on a controller, M99 there restarts the program endlessly).
    M99 {
        /// 1-based line.
        line: usize,
    },
}

/// A whole program, interpreted before any motion starts (see [`parse_program`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Program {
    /// Name of the source (used in messages).
    pub file: String,
    /// The machine position the program starts from.
    pub start_mm: Vector3<f64>,
    /// Motion elements, dwells and stops in program order (no notes, no end).
    pub items: Vec<Item>,
    /// Words accepted without a motion effect.
    pub notes: Vec<Note>,
    /// How the program ended.
    pub end: ProgramEnd,
    /// The state after the last item (after M2/M30's resets if it ended so), for the next
    /// interpretation on the machine ([`Setup::carry`]).
    pub carry: Carry,
}

impl Program {
    /// Runs an interpreter to the end and collects its output; the first error stops it.
    pub fn collect<R: BufRead>(mut interpreter: Interpreter<R>) -> Result<Program, Error> {
        let (mut items, mut notes, mut end) = (Vec::new(), Vec::new(), ProgramEnd::EndOfText);
        for item in interpreter.by_ref() {
            match item? {
                Item::Note(note) => notes.push(note),
                Item::End(e) => end = e,
                other => items.push(other),
            }
        }
        Ok(Program {
            file: interpreter.file().to_owned(),
            start_mm: interpreter.start_mm(),
            items,
            notes,
            end,
            carry: interpreter.carry(),
        })
    }

    /// The motion elements in order.
    pub fn elements(&self) -> impl DoubleEndedIterator<Item = &Element> + '_ {
        self.items.iter().filter_map(|i| match i {
            Item::Motion(e) => Some(e),
            _ => None,
        })
    }

    /// The position after the last element (the start position if there is none).
    pub fn end_mm(&self) -> Vector3<f64> {
        self.elements().last().map_or(self.start_mm, |e| e.end_mm)
    }
}

/// Interprets a whole program text with the default [`Setup`] (no offsets, empty tool table)
/// from `start_mm`, the machine's actual position, so G91 and omitted axis words resolve
/// against where the machine really is. `file` only names the source in errors. Never panics,
/// whatever the text.
pub fn parse_program(text: &str, file: &str, start_mm: Vector3<f64>) -> Result<Program, Error> {
    parse_program_with(text, file, Setup::new(start_mm))
}

/// [`parse_program`] with a full [`Setup`] (work offsets, tool table, G28 position...).
pub fn parse_program_with(text: &str, file: &str, setup: Setup) -> Result<Program, Error> {
    Program::collect(Interpreter::new(text.as_bytes(), file, setup))
}

/// Interprets MDI input (one line, or a few, each a block) as a program named [`MDI_FILE`]
/// (errors read `MDI:1:col: ...`), from `setup` with [`Setup::carry`] set to what the last MDI
/// line or program left; the result's [`Program::carry`] is for the next one. A line that is
/// empty or only a comment gives no items and carries the state through. What MDI refuses:
/// [`Interpreter::mdi`]. On an error nothing ran: keep the carry you had.
pub fn parse_mdi(text: &str, setup: Setup) -> Result<Program, Error> {
    Program::collect(Interpreter::mdi(text.as_bytes(), setup))
}

/// An error: where it is and what is wrong. Displays as `file:line:col: message`, or
/// `file:line: message` with no column, or `file: message` when it concerns no line (a read
/// error, a bad setup).
///
/// An error inside a subroutine file names that file and its line, then the calls that led
/// there: `sub.ngc:3:5: message (called from main.ngc:12)`.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{}{kind}{}", Place { file, line: *line, col: *col }, Calls(called_from.as_deref()))]
pub struct Error {
    /// Name of the source (the subroutine file's path when the line is in one).
    pub file: String,
    /// 1-based line (0 for errors that concern no line: a bad setup, a read error).
    pub line: usize,
    /// 1-based column in characters (0 when there is no line).
    pub col: usize,
    /// What is wrong.
    pub kind: ErrorKind,
    /// When `file` is a subroutine file: the call lines that led to it (`None` otherwise;
    /// boxed, to keep errors small).
    pub called_from: Option<Box<CallChain>>,
}

/// The lines that called the subroutines an error is in, innermost first.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CallChain(pub Vec<CallSite>);

/// A line that called a subroutine.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CallSite {
    /// The file of the calling line.
    pub file: String,
    /// Its 1-based line.
    pub line: usize,
}

/// ` (called from a:3, from b:12)`, or nothing.
struct Calls<'a>(Option<&'a CallChain>);

impl fmt::Display for Calls<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let sites = self.0.map_or(&[][..], |c| c.0.as_slice());
        for (i, site) in sites.iter().enumerate() {
            let sep = if i == 0 { " (called from " } else { ", from " };
            write!(f, "{sep}{}:{}", site.file, site.line)?;
        }
        if !sites.is_empty() {
            f.write_str(")")?;
        }
        Ok(())
    }
}

/// `file:line:col: `, without the parts that are 0 (unknown).
struct Place<'a> {
    file: &'a str,
    line: usize,
    col: usize,
}

impl fmt::Display for Place<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match (self.line, self.col) {
            (0, _) => write!(f, "{}: ", self.file),
            (line, 0) => write!(f, "{}:{line}: ", self.file),
            (line, col) => write!(f, "{}:{line}:{col}: ", self.file),
        }
    }
}

/// The folders searched for a subroutine file, or `none`.
struct Searched<'a>(&'a [String]);

impl fmt::Display for Searched<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.0.is_empty() {
            return f.write_str("no subroutine_path is set");
        }
        f.write_str(&self.0.join(", "))
    }
}

/// `'F' is followed by ` after a word's letter; `found ` inside an expression.
struct FollowedBy(char);

impl fmt::Display for FollowedBy {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.0.is_ascii_alphabetic() {
            write!(f, "'{}' is followed by ", self.0)
        } else {
            f.write_str("found ")
        }
    }
}

/// ` after line N` when lines were read, else nothing.
struct AfterLine(usize);

impl fmt::Display for AfterLine {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.0 {
            0 => Ok(()),
            n => write!(f, " after line {n}"),
        }
    }
}

impl Error {
    /// Whether this is valid G-code that this front end does not execute (as opposed to a
    /// mistake in the program).
    pub fn is_unsupported(&self) -> bool {
        self.unsupported_feature().is_some()
    }

    /// The unsupported feature, e.g. `G81` or `spiral arc`, if this is such an error.
    pub fn unsupported_feature(&self) -> Option<&str> {
        match &self.kind {
            ErrorKind::Unsupported { what, .. } => Some(what),
            ErrorKind::ArcRadiusMismatch { .. } => Some("spiral arc"),
            // Valid G-code for a machine with that axis.
            ErrorKind::AxisNotConfigured { letter } => Some(match letter {
                'A' => "axis A (not on this machine)",
                'B' => "axis B (not on this machine)",
                'C' => "axis C (not on this machine)",
                'U' => "axis U (not on this machine)",
                'V' => "axis V (not on this machine)",
                _ => "axis W (not on this machine)",
            }),
            _ => None,
        }
    }
}

/// What is wrong with a program.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ErrorKind {
    /// Valid G-code that this front end does not execute.
    #[error("unsupported: {what} ({reason})")]
    Unsupported {
        /// The code or word, e.g. `G81`, `axis word 'A'`.
        what: String,
        /// Why.
        reason: &'static str,
    },
    /// A G or M code that RS274/NGC does not define.
    #[error("unknown code {code}")]
    UnknownCode {
        /// The code, e.g. `G12.5`.
        code: String,
    },
    /// A letter that is no word of RS274/NGC.
    #[error("'{letter}' is not a G-code word")]
    UnknownLetter {
        /// The letter.
        letter: char,
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
    /// A value beyond [`MAX_ABS_VALUE`].
    #[error("value {value} of '{letter}' is out of range (at most 1e9 in magnitude)")]
    NumberOutOfRange {
        /// The letter.
        letter: char,
        /// The value.
        value: f64,
    },
    /// An expression that does not parse.
    #[error("malformed expression: expected {expected}")]
    ExpressionSyntax {
        /// What was expected.
        expected: &'static str,
    },
    /// Brackets, functions or `#` nested too deeply.
    #[error("expression nested more than {max} levels deep")]
    ExpressionTooDeep {
        /// The limit.
        max: usize,
    },
    /// A function or operator outside its domain.
    #[error("math error: {what}")]
    MathDomain {
        /// What.
        what: &'static str,
    },
    /// `/` or `MOD` by zero.
    #[error("division by zero")]
    DivisionByZero,
    /// A named parameter read before it was set.
    #[error("parameter #<{name}> is not defined")]
    UndefinedParameter {
        /// The name.
        name: String,
    },
    /// `#` of a value that is no parameter number.
    #[error("#{value} is not a parameter number (an integer from 1)")]
    ParameterNumber {
        /// The value.
        value: f64,
    },
    /// Too many named parameters in one scope.
    #[error("more than {max} named parameters")]
    TooManyParameters {
        /// The limit.
        max: usize,
    },
    /// An unknown function name before `[`.
    #[error("unknown function {name}")]
    UnknownFunction {
        /// The name.
        name: String,
    },
    /// An O-word with an unknown keyword.
    #[error("unknown O-word keyword '{word}'")]
    UnknownKeyword {
        /// The keyword.
        word: String,
    },
    /// An O-word with the wrong number of bracketed values.
    #[error("wrong number of [values] after '{keyword}'")]
    ControlValue {
        /// The keyword.
        keyword: &'static str,
    },
    /// A `repeat` count below 0, above 1e12 or not a number.
    #[error("repeat count {value} is out of range: it must be 0 or more (at most 1e12)")]
    RepeatCount {
        /// The count as evaluated.
        value: f64,
    },
    /// An O-word control line out of place (`endwhile` without `while`...).
    #[error("{what} needs {expected}")]
    ControlMismatch {
        /// The line, e.g. `o101 endwhile`.
        what: String,
        /// What was missing.
        expected: &'static str,
    },
    /// A subroutine, loop or `if` whose end never comes.
    #[error("{label} is never closed: no '{label} {end}' before the end of the program")]
    UnclosedControl {
        /// The label.
        label: String,
        /// The keyword that closes it.
        end: &'static str,
    },
    /// A call of a subroutine neither defined before nor found as a file on the subroutine
    /// path.
    #[error(
        "subroutine {label} is not defined: define it with 'sub' before the call, or put {file_name} in a folder of the machine file's [program] subroutine_path (searched: {})",
        Searched(searched)
    )]
    UndefinedSubroutine {
        /// The label.
        label: String,
        /// The file that was looked for, e.g. `probe.ngc`.
        file_name: String,
        /// The folders searched, in order (empty: no subroutine path is set).
        searched: Vec<String>,
    },
    /// A called subroutine's name that cannot name a file.
    #[error(
        "subroutine {label} cannot be looked up as a file: file names of subroutines hold only lowercase letters, digits, '-' and '_' (as in LinuxCNC)"
    )]
    SubroutineName {
        /// The label.
        label: String,
    },
    /// A subroutine file that could not be read.
    #[error("cannot read subroutine file {path}: {message}")]
    SubroutineFile {
        /// The file.
        path: String,
        /// Why.
        message: String,
    },
    /// A subroutine file without the definition of its subroutine.
    #[error(
        "subroutine file {path} does not define {label}: it needs a '{label} sub' line and a '{label} endsub' line after it"
    )]
    SubroutineFileWithoutSub {
        /// The file.
        path: String,
        /// The label.
        label: String,
    },
    /// Polar coordinates and X or Y on one line.
    #[error(
        "polar coordinates (@ distance, ^ angle) and {letter} on one line: give the point one way"
    )]
    PolarWithXy {
        /// X or Y.
        letter: char,
    },
    /// Incremental polar coordinates from the origin, where no angle is defined.
    #[error(
        "incremental polar coordinates (G91 @ ^) from the origin of the work system: the angle there is undefined"
    )]
    PolarFromOrigin,
    /// M72 with no modal state saved at this call level.
    #[error(
        "M72: no modal state to restore at this call level (save it with M70 or M73 first; M71 and the end of the subroutine that saved it discard it)"
    )]
    NoSavedModalState,
    /// `M98 P<n>` with no `O<n>` ... `M99` subprogram after the call.
    #[error(
        "M98 P{number}: no subprogram O{number} (an 'O{number}' line, its lines, then M99) follows in the program"
    )]
    SubprogramNotFound {
        /// The program number.
        number: u32,
    },
    /// A computed O-word label (`o[#1+2] call`) that is no label number.
    #[error("computed O-word label {value} is not a non-negative integer")]
    ComputedLabel {
        /// The value computed.
        value: f64,
    },
    /// Calls nested too deeply.
    #[error("subroutine calls nested more than {max} deep")]
    CallTooDeep {
        /// The limit.
        max: usize,
    },
    /// Subroutine and loop bodies too large to keep.
    #[error("subroutines and loop bodies hold more than {max_bytes} bytes")]
    StoredTooLarge {
        /// The limit.
        max_bytes: usize,
    },
    /// A loop running without producing anything.
    #[error("{lines} lines ran in loops or subroutines without any motion or output")]
    NoProgress {
        /// The limit.
        lines: usize,
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
    /// `/` anywhere but at the start of a line.
    #[error("block delete '/' must be the first character of the line")]
    MisplacedBlockDelete,
    /// An `O` word with no number or name.
    #[error("O-word with no number or <name>")]
    MalformedOWord,
    /// A program number with other words on its line.
    #[error("a program number (O-word) must be alone on its line")]
    ProgramNumberNotAlone,
    /// An `O` right after the digits of a word's value (`X2O`): most likely the letter O typed
    /// for a zero, since an O-word could not be there.
    #[error("the letter O in '{written}' looks typed for a zero: did you mean '{suggested}'?")]
    LetterOForZero {
        /// The word as written, e.g. `X2O`, `X1O5`.
        written: String,
        /// The word with its O's as zeros, e.g. `X20`.
        suggested: String,
    },
    /// Letters where a word's value should be that name no function: `FOO` is `F`, then `OO`.
    #[error("{}'{text}', which is neither a number nor a function", FollowedBy(*letter))]
    NotANumber {
        /// The word's letter (`[`, `#` or `=` inside an expression, a parameter or an
        /// assignment).
        letter: char,
        /// The letters, as written.
        text: String,
    },
    /// A function name with no `[` after it, where a word's value should be: `X SIN 30`.
    #[error(
        "{}the function name {name}, which needs its argument in brackets: {name}[...]",
        FollowedBy(*letter)
    )]
    FunctionWithoutBracket {
        /// The word's letter (as for [`ErrorKind::NotANumber`]).
        letter: char,
        /// The function, upper case, e.g. `SIN`.
        name: String,
    },
    /// A line longer than [`MAX_LINE_BYTES`].
    #[error("line longer than {max_bytes} bytes")]
    LineTooLong {
        /// The limit.
        max_bytes: usize,
    },
    /// The input could not be read (the error has no line or column: line 0).
    #[error("cannot read the program{}: {message}", AfterLine(*lines_read))]
    Read {
        /// How many lines were read whole before the error.
        lines_read: usize,
        /// The I/O error.
        message: String,
    },
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
    /// A value that is not valid for its letter (G1.23, M-1, N-5, F0, S-5, T2.5).
    #[error("invalid {word}: expected {expected}")]
    InvalidValue {
        /// The word as written, e.g. `F0`.
        word: String,
        /// What was expected.
        expected: &'static str,
    },
    /// A code without a word it needs (G4 without P, G10 without L).
    #[error("{code} needs {letter}: {expected}")]
    MissingWord {
        /// The code.
        code: String,
        /// The missing letter.
        letter: char,
        /// What it gives.
        expected: &'static str,
    },
    /// A word that no code on the line (nor the modal motion) uses.
    #[error("word '{letter}' has nothing to use it: it belongs to {users}")]
    UnusedWord {
        /// The letter.
        letter: char,
        /// The codes that use it.
        users: &'static str,
    },
    /// A feed move and no F programmed so far (units per minute mode).
    #[error(
        "{code} move with no feed rate: program F (mm/min, or in/min under G20) on this line or before"
    )]
    MissingFeed {
        /// G1, G2 or G3.
        code: &'static str,
    },
    /// A feed move in inverse time mode without F on its line.
    #[error("{code} move in inverse time mode (G93) without F on its line")]
    MissingInverseTimeFeed {
        /// G1, G2 or G3.
        code: &'static str,
    },
    /// Axis words and no motion mode in force.
    #[error("axis words with no motion mode in force: add G0, G1, G2 or G3")]
    AxisWithoutMotion,
    /// A word of an axis (A B C U V W) the machine does not have.
    #[error(
        "unsupported: axis word '{letter}': the machine has no {letter} axis (add an [[axis]] with name = \"{letter}\" to the machine file)"
    )]
    AxisNotConfigured {
        /// The axis letter.
        letter: char,
    },
    /// An absolute (G90) position of a wrapped rotary axis outside (−360°, 360°), as LinuxCNC
    /// refuses it.
    #[error(
        "{letter}{value_deg}: a wrapped rotary axis takes absolute positions between -360 and 360 degrees (exclusive)"
    )]
    WrappedPositionOutOfRange {
        /// The axis letter.
        letter: char,
        /// The position given.
        value_deg: f64,
    },
    /// Axis words with G80 on the line.
    #[error("axis words with G80 (motion off)")]
    AxisWithG80,
    /// Two codes on one line that both take the axis words (G28 and G1).
    #[error("{first} and {second} both use the axis words of this line")]
    AxisWordsClaimedTwice {
        /// The first code.
        first: String,
        /// The second code.
        second: String,
    },
    /// G53 with G2/G3.
    #[error("G53 needs straight motion (G0 or G1)")]
    G53NeedsStraightMotion,
    /// An `N` word that is not the first word of its line.
    #[error("line number 'N' must be the first word of the line")]
    LineNumberNotFirst,
    /// An arc with neither of its plane's axis words.
    #[error("arc in the {plane} plane needs {first} or {second}")]
    ArcMissingPlaneAxes {
        /// G17, G18, G19.
        plane: &'static str,
        /// The plane's first axis.
        first: char,
        /// The plane's second axis.
        second: char,
    },
    /// An offset word along the plane's normal (K in G17).
    #[error("{letter} is not an arc centre word in the {plane} plane")]
    ArcWordWrongPlane {
        /// The letter.
        letter: char,
        /// G17, G18, G19.
        plane: &'static str,
    },
    /// R and I/J/K on one arc.
    #[error("arc with both R and a centre offset: use one format")]
    ArcBothFormats,
    /// An arc with neither R nor I/J/K.
    #[error("arc in the {plane} plane without R or centre offsets")]
    ArcNoCentre {
        /// G17, G18, G19.
        plane: &'static str,
    },
    /// The centre is on the start or end point.
    #[error("zero-radius arc (centre on the start or end point)")]
    ArcZeroRadius,
    /// The end point is not on the circle through the start (centre format): the arc would be
    /// a spiral, which this front end does not execute.
    #[error(
        "unsupported: spiral arc (the end point is off the circle: radius {start_radius_mm:.4} mm to the start, {end_radius_mm:.4} mm to the end, tolerance {tolerance_mm:.4} mm)"
    )]
    ArcRadiusMismatch {
        /// Centre to start, in the plane.
        start_radius_mm: f64,
        /// Centre to end, in the plane.
        end_radius_mm: f64,
        /// The tolerance that was broken.
        tolerance_mm: f64,
    },
    /// An R-format arc too small to reach its end point.
    #[error(
        "arc radius {radius_mm:.4} mm cannot reach the end point ({half_chord_mm:.4} mm away from the middle of the chord)"
    )]
    ArcRadiusTooSmall {
        /// |R|.
        radius_mm: f64,
        /// Half the chord.
        half_chord_mm: f64,
    },
    /// An R-format arc with the end equal to the start.
    #[error("R-format arc with the end point equal to the start: use I/J/K for a full circle")]
    ArcRadiusFullCircle,
    /// A D or H word naming a tool that is not in the tool table.
    #[error("tool {tool} ({letter}{tool}) is not in the tool table")]
    ToolNotFound {
        /// The tool number.
        tool: u32,
        /// D or H.
        letter: char,
    },
    /// G41/G42 while compensation is already on.
    #[error("{code} while cutter compensation is on: cancel it with G40 first")]
    CompensationAlreadyOn {
        /// The code.
        code: String,
    },
    /// A change that cutter compensation forbids (plane, units, work system, G53, G28).
    #[error("{code} is not allowed while cutter compensation is on: cancel it with G40 first")]
    CompensationActive {
        /// The code.
        code: String,
    },
    /// Cutter compensation: the tool is too big for an inside arc (its tool-centre arc would
    /// have a radius below [`MIN_ARC_RADIUS_MM`]).
    #[error(
        "tool radius {tool_radius_mm:.4} mm is too big for this arc of radius {arc_radius_mm:.4} mm: the tool-centre arc would have radius {offset_radius_mm:.4} mm (use a smaller tool or a larger arc)"
    )]
    CompensationArcTooSmall {
        /// The programmed radius.
        arc_radius_mm: f64,
        /// The tool radius.
        tool_radius_mm: f64,
        /// The offset radius it would take (≤ 0 or below the smallest arc).
        offset_radius_mm: f64,
    },
    /// Cutter compensation would cut into the part.
    #[error("cutter compensation with tool radius {tool_radius_mm:.4} mm would gouge: {what}")]
    CompensationGouge {
        /// The tool radius.
        tool_radius_mm: f64,
        /// What happens, e.g. the element is shorter than its corners take.
        what: &'static str,
    },
    /// An arc as the start-up move of cutter compensation whose end point is not farther than
    /// the tool radius from the current point (LinuxCNC refuses it too).
    #[error(
        "{code} cannot start cutter compensation: its end point is {chord_mm:.4} mm from the current point, not more than the tool radius {tool_radius_mm:.4} mm (start farther away)"
    )]
    CompensationEntryArcTooShort {
        /// G2 or G3.
        code: &'static str,
        /// Distance from the current point to the programmed end point.
        chord_mm: f64,
        /// The tool radius.
        tool_radius_mm: f64,
    },
    /// A straight start-up move of cutter compensation not longer in the plane than the tool
    /// radius (LinuxCNC's `convert_straight_comp1` refuses it: "Length of cutter compensation
    /// entry move is not greater than the tool radius").
    #[error(
        "{code} cannot start cutter compensation: it is {length_mm:.4} mm long in the plane, not more than the tool radius {tool_radius_mm:.4} mm (start farther away)"
    )]
    CompensationEntryTooShort {
        /// G0 or G1.
        code: &'static str,
        /// Length in the compensation plane, from the programmed start to the programmed end.
        length_mm: f64,
        /// The tool radius.
        tool_radius_mm: f64,
    },
    /// An arc as the start-up move of cutter compensation for which no tool-centre arc runs
    /// from the current point to the offset end point with its centre on the end point's
    /// radius (LinuxCNC: "tool radius not less than arc radius with comp").
    #[error(
        "{code} cannot start cutter compensation: no tool-centre arc runs from the current point to the end point's offset with tool radius {tool_radius_mm:.4} mm (start farther from the end point, or use a smaller tool)"
    )]
    CompensationEntryArcNoCentre {
        /// G2 or G3.
        code: &'static str,
        /// The tool radius.
        tool_radius_mm: f64,
    },
    /// An arc as the first move after G40 (LinuxCNC refuses it too).
    #[error(
        "{code} cannot end cutter compensation: the first move after G40 must be a straight G0 or G1 move"
    )]
    CompensationEndOnArc {
        /// G2 or G3.
        code: &'static str,
    },
    /// Too many items after an element under cutter compensation before the next move in the
    /// plane (which the corner needs).
    #[error(
        "cutter compensation needs the next move in the plane after this one, and {max} items came without one (moves along the tool axis, dwells, stops, notes)"
    )]
    CompensationLookAhead {
        /// The limit.
        max: usize,
    },
    /// An element cutter compensation cannot use (not finite, an arc about another axis).
    #[error("cutter compensation cannot use this move: {what}")]
    CompensationGeometry {
        /// What is wrong.
        what: &'static str,
    },
    /// A position beyond [`MAX_POSITION_MM`].
    #[error("position out of range (more than 1e12 mm from machine zero)")]
    PositionOutOfRange,
    /// The caller's start position is not finite.
    #[error("start position is not finite")]
    NonFiniteStart,
    /// A [`Setup`] value out of its domain.
    #[error("invalid setup: {what}")]
    InvalidSetup {
        /// What is wrong.
        what: &'static str,
    },
    /// A canned cycle whose retract plane R is below the bottom of its hole.
    #[error(
        "{code}: the retract plane R ({r_mm:.4} mm) is below the hole bottom {axis} ({bottom_mm:.4} mm)"
    )]
    CycleRetractBelowBottom {
        /// The cycle, e.g. `G81`.
        code: &'static str,
        /// The drill axis of the plane (Z in G17, Y in G18, X in G19).
        axis: char,
        /// The R plane, program coordinate (mm).
        r_mm: f64,
        /// The hole bottom, program coordinate (mm).
        bottom_mm: f64,
    },
    /// A canned cycle in inverse time feed mode (LinuxCNC refuses it too).
    #[error("{code}: canned cycles cannot run in inverse time feed mode (G93): program G94 first")]
    CycleInverseTime {
        /// The cycle.
        code: &'static str,
    },
    /// A canned cycle line that would make more moves and dwells than the interpreter holds
    /// for one line ([`MAX_CYCLE_ITEMS`]).
    #[error(
        "{code} makes more than {max} moves and dwells on one line (pecks times repeats): use a larger Q or fewer repeats (L)"
    )]
    CycleTooLong {
        /// The cycle.
        code: &'static str,
        /// The limit.
        max: usize,
    },
    /// A G5/G5.1 spline outside the XY plane (LinuxCNC: "Splines must be in the XY plane").
    #[error("{code} draws splines in the XY plane only: program G17 first (the plane is {plane})")]
    SplinePlane {
        /// G5 or G5.1.
        code: &'static str,
        /// The plane in force, e.g. `G18`.
        plane: &'static str,
    },
    /// A G5/G5.1 spline with an axis word other than X and Y (LinuxCNC: "Splines may not have
    /// motion in Z, A, B, or C").
    #[error("{code} moves X and Y only: {letter} is not allowed on a spline")]
    SplineAxis {
        /// G5 or G5.1.
        code: &'static str,
        /// The letter.
        letter: char,
    },
    /// A spline under cutter compensation (LinuxCNC: "Cannot convert spline with cutter
    /// radius compensation").
    #[error("{code} cannot run under cutter compensation: cancel it with G40 first")]
    SplineWithCompensation {
        /// G5 or G5.1.
        code: &'static str,
    },
    /// A spline that would take more lines than [`MAX_SPLINE_SEGMENTS`] to stay within the
    /// chord tolerance.
    #[error(
        "{code} would take {segments} lines to stay within the chord tolerance {tol_mm} mm (at most {max}): split the spline or raise [planner] chord_tol_mm"
    )]
    SplineTooLong {
        /// G5 or G5.1.
        code: &'static str,
        /// The lines it would take.
        segments: f64,
        /// The tolerance.
        tol_mm: f64,
        /// The limit.
        max: usize,
    },
    /// An assignment to one of LinuxCNC's predefined named parameters (LinuxCNC: "Cannot
    /// assign to read-only parameter").
    #[error("parameter #<{name}> is read-only: it is one of LinuxCNC's predefined parameters")]
    ReadOnlyParameter {
        /// The name.
        name: String,
    },
    /// A tapping or boring cycle with the spindle not turning as it must (LinuxCNC's check).
    #[error("{code} needs the spindle turning {needed}: program {fix} before it")]
    CycleSpindle {
        /// The cycle.
        code: &'static str,
        /// The direction it needs, e.g. `clockwise`.
        needed: &'static str,
        /// The code that starts it, e.g. `M3`.
        fix: &'static str,
    },
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn v(x: f64, y: f64, z: f64) -> Vector3<f64> {
        Vector3::new(x, y, z)
    }

    #[test]
    fn the_stream_ends_once_and_stays_ended() {
        let mut it = Interpreter::new(
            "G0 X1\nM2\nG0 X2\n".as_bytes(),
            "p",
            Setup::new(Vector3::zeros()),
        );
        assert!(matches!(it.next(), Some(Ok(Item::Motion(_)))));
        assert_eq!(it.next(), Some(Ok(Item::End(ProgramEnd::M2 { line: 2 }))));
        assert_eq!(it.next(), None);
        assert_eq!(it.next(), None);
        // The line after M2 is never read.
        assert_eq!(it.line(), 2);
        let mut it = Interpreter::new(
            "G0 X1\nG0 Q\nG0 X2\n".as_bytes(),
            "p",
            Setup::new(Vector3::zeros()),
        );
        assert!(matches!(it.next(), Some(Ok(Item::Motion(_)))));
        let e = it.next().unwrap().unwrap_err();
        assert_eq!((e.line, e.col), (2, 4));
        assert_eq!(it.next(), None);
        let items: Vec<_> =
            Interpreter::new("".as_bytes(), "p", Setup::new(Vector3::zeros())).collect();
        assert_eq!(items, vec![Ok(Item::End(ProgramEnd::EndOfText))]);
    }

    /// Fails every read after handing out `text`.
    struct FailsAfter<'a>(&'a [u8]);

    impl std::io::Read for FailsAfter<'_> {
        fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
            if self.0.is_empty() {
                return Err(std::io::Error::other("disk on fire"));
            }
            let n = self.0.len().min(buf.len());
            buf[..n].copy_from_slice(&self.0[..n]);
            self.0 = &self.0[n..];
            Ok(n)
        }
    }

    #[test]
    fn errors_with_no_place_show_none() {
        // A read error has no line or column: the lines read before it are said instead.
        let read = |text: &'static str| {
            let reader = std::io::BufReader::new(FailsAfter(text.as_bytes()));
            let items: Vec<_> =
                Interpreter::new(reader, "p.ngc", Setup::new(v(0.0, 0.0, 0.0))).collect();
            items.into_iter().find_map(Result::err).unwrap()
        };
        let e = read("");
        assert_eq!(
            e.kind,
            ErrorKind::Read {
                lines_read: 0,
                message: "disk on fire".into()
            }
        );
        assert_eq!((e.line, e.col), (0, 0));
        assert_eq!(
            e.to_string(),
            "p.ngc: cannot read the program: disk on fire"
        );
        let e = read("G0 X1\nG0 X2\n");
        assert_eq!(
            e.to_string(),
            "p.ngc: cannot read the program after line 2: disk on fire"
        );
        // A bad setup concerns no line either.
        let e = parse_program("G0 X1", "p.ngc", v(f64::NAN, 0.0, 0.0)).unwrap_err();
        assert_eq!(e.line, 0);
        assert!(e.to_string().starts_with("p.ngc: "), "{e}");
    }

    #[test]
    fn percent_markers() {
        let p = parse_program("%\nG0 X1\n%\nG0 X2", "p", Vector3::zeros()).unwrap();
        assert_eq!(p.elements().count(), 1);
        assert_eq!(p.end, ProgramEnd::Percent { line: 3 });
        let p = parse_program("G0 X1\n%\n@@@", "p", Vector3::zeros()).unwrap();
        assert_eq!(p.end, ProgramEnd::Percent { line: 2 });
    }

    #[test]
    fn crlf_tabs_and_bad_utf8() {
        let p = parse_program("G0\tX1\r\nY2\r\n", "p", Vector3::zeros()).unwrap();
        assert_eq!(p.end_mm(), v(1.0, 2.0, 0.0));
        // Invalid UTF-8 inside a comment is harmless; outside, it is an error.
        let bytes = b"G0 X1 (\xff\xfe)\nG0 Y\xff\n";
        let items: Vec<_> =
            Interpreter::new(&bytes[..], "p", Setup::new(Vector3::zeros())).collect();
        assert!(matches!(items[0], Ok(Item::Motion(_))));
        let e = items[1].clone().unwrap_err();
        assert_eq!((e.line, e.col), (2, 4));
    }

    /// The items of `lines` joined by `ending`, read through a 1-byte buffer (so that a
    /// `\r\n` is split across reads) and through a large one.
    fn items_with_ending(lines: &[&str], ending: &str) -> Vec<Result<Item, Error>> {
        let text: String = lines.iter().map(|l| format!("{l}{ending}")).collect();
        let small: Vec<_> = Interpreter::new(
            std::io::BufReader::with_capacity(1, text.as_bytes()),
            "p",
            Setup::new(Vector3::zeros()),
        )
        .collect();
        let large: Vec<_> =
            Interpreter::new(text.as_bytes(), "p", Setup::new(Vector3::zeros())).collect();
        assert_eq!(small, large, "ending {ending:?}");
        large
    }

    #[test]
    fn cr_lf_and_crlf_all_end_lines() {
        let program = ["G21 G90", "G0 Z5", "X100 Y100", "", "M2"];
        let lf = items_with_ending(&program, "\n");
        // Retract, then traverse: two moves, never one diagonal.
        let moves: Vec<_> = lf
            .iter()
            .filter_map(|i| match i {
                Ok(Item::Motion(e)) => Some(e.end_mm),
                _ => None,
            })
            .collect();
        assert_eq!(moves, vec![v(0.0, 0.0, 5.0), v(100.0, 100.0, 5.0)]);
        assert_eq!(lf.last(), Some(&Ok(Item::End(ProgramEnd::M2 { line: 5 }))));
        assert_eq!(items_with_ending(&program, "\r"), lf);
        assert_eq!(items_with_ending(&program, "\r\n"), lf);

        let bad = ["G21 G90", "G0 Z5", "G0 Q1", "M2"];
        for ending in ["\n", "\r", "\r\n"] {
            let e = items_with_ending(&bad, ending)
                .into_iter()
                .find_map(Result::err)
                .expect("an error");
            assert_eq!((e.line, e.col), (3, 4), "ending {ending:?}");
        }
        // A lone LF after a CR line is a line of its own only when it is not that CR's pair.
        let p = parse_program("G0 X1\n\rG0 Q1\n", "p", Vector3::zeros()).unwrap_err();
        assert_eq!(p.line, 3);
        // The optimiser's line split agrees.
        let lines: Vec<_> = split_lines_inclusive(b"a\rb\r\nc\n\rd").collect();
        assert_eq!(lines, [&b"a\r"[..], b"b\r\n", b"c\n", b"\r", b"d"]);
    }

    #[test]
    fn a_negative_repeat_count_says_so() {
        let e = parse_program(
            "G0 X1\no1 repeat [-5]\nG0 X2\no1 endrepeat\n",
            "p",
            Vector3::zeros(),
        )
        .unwrap_err();
        assert_eq!((e.line, e.col), (2, 1));
        assert_eq!(e.kind, ErrorKind::RepeatCount { value: -5.0 });
        assert!(e.to_string().contains("must be 0 or more"), "{e}");
    }

    #[test]
    fn long_lines_are_refused_not_buffered() {
        let text = format!("G0 X1 ({})\n", "a".repeat(MAX_LINE_BYTES));
        let e = parse_program(&text, "p", Vector3::zeros()).unwrap_err();
        assert_eq!(
            e.kind,
            ErrorKind::LineTooLong {
                max_bytes: MAX_LINE_BYTES
            }
        );
    }

    #[test]
    fn bad_setups_are_reported_at_line_zero() {
        let e = parse_program("G0 X1", "p", v(f64::NAN, 0.0, 0.0)).unwrap_err();
        assert_eq!(e.to_string(), "p: start position is not finite");
        let mut s = Setup::new(Vector3::zeros());
        s.arc_tolerance_mm = 0.0;
        let e = parse_program_with("G0 X1", "p", s).unwrap_err();
        assert!(matches!(e.kind, ErrorKind::InvalidSetup { .. }));
    }

    #[test]
    fn endless_loops_without_motion_are_stopped() {
        let e = parse_program(
            "o1 while [1]\n#1 = [#1 + 1]\no1 endwhile\n",
            "p",
            Vector3::zeros(),
        )
        .unwrap_err();
        assert_eq!(
            e.kind,
            ErrorKind::NoProgress {
                lines: MAX_IDLE_LINES
            }
        );
        let e = parse_program(
            "o1 sub\no1 call\no1 endsub\no1 call\n",
            "p",
            Vector3::zeros(),
        )
        .unwrap_err();
        assert_eq!(
            e.kind,
            ErrorKind::CallTooDeep {
                max: MAX_CALL_DEPTH
            }
        );
        assert_eq!(e.line, 2);
    }

    #[test]
    fn loops_of_the_main_program_let_their_lines_go() {
        // 20 MB of loops in a row: more than MAX_STORED_BYTES in total, one at a time.
        let comment = "c".repeat(1000);
        let block = format!("o1 repeat [1] ({comment})\nG0 X1\nG0 X0\no1 endrepeat\n");
        let count = 20 * 1024 * 1024 / block.len();
        let text = block.repeat(count);
        let elements = Interpreter::new(text.as_bytes(), "p", Setup::new(Vector3::zeros()))
            .map(|i| i.unwrap())
            .filter(|i| matches!(i, Item::Motion(_)))
            .count();
        assert_eq!(elements, 2 * count);
        // Subroutine bodies are kept, within the bound.
        let sub = format!("o<s{{}}> sub\n({comment})\no<s{{}}> endsub\n");
        let text: String = (0..20_000)
            .map(|k| sub.replace("{}", &k.to_string()))
            .collect();
        let e = parse_program(&text, "p", Vector3::zeros()).unwrap_err();
        assert_eq!(
            e.kind,
            ErrorKind::StoredTooLarge {
                max_bytes: MAX_STORED_BYTES
            }
        );
    }

    /// Runs a program and checks what every consumer relies on: finite values, continuity,
    /// one End at the end. At most `limit` items are read (a loop may legitimately be endless).
    fn check_program(text: &str) {
        let start = v(1.0, -2.0, 3.0);
        let mut position = start;
        let mut ended = false;
        for item in Interpreter::new(text.as_bytes(), "fuzz", Setup::new(start)).take(10_000) {
            assert!(!ended, "an item after the end");
            match item {
                Ok(Item::Motion(e)) => {
                    assert_eq!(e.start_mm, position);
                    assert!(e.end_mm.iter().all(|c| c.is_finite()));
                    assert_eq!(e.rapid, e.feed_mm_s.is_none());
                    if let Some(f) = e.feed_mm_s {
                        assert!(f.is_finite() && f > 0.0, "feed {f}");
                    }
                    if let ElementKind::Arc { radius_mm, .. } = e.kind {
                        assert!(radius_mm > 0.0);
                        let arc = e.arc().expect("arc geometry");
                        assert!(arc.length_mm.is_finite() && arc.length_mm > 0.0);
                    }
                    position = e.end_mm;
                }
                Ok(Item::Dwell(d)) => assert!(d.seconds >= 0.0 && d.seconds.is_finite()),
                Ok(Item::End(_)) => ended = true,
                Ok(_) => {}
                Err(e) => {
                    let _ = e.to_string();
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
            text in "[GgMmNXxYyZzFfIJKRPQDHLOST#<>%\\[\\]=/*+\\-0-9 .();\n]{0,300}"
        ) {
            check_program(&text);
        }

        #[test]
        fn never_panics_on_plausible_blocks(
            lines in proptest::collection::vec(
                (
                    prop::sample::select(vec![
                        "G0", "G1", "G2", "G3", "G17", "G18", "G19", "G20", "G21", "G90", "G91",
                        "G90.1", "G91.1", "G93", "G94", "G28", "G30", "G53 G0", "G92", "G92.1",
                        "G92.2", "G92.3", "G43.1", "G49", "G10 L2 P1", "G10 L20 P0", "G4", "G54",
                        "G55", "G64", "G61", "G40", "G41.1", "M0", "M1", "",
                    ]),
                    proptest::collection::vec(
                        (prop::sample::select(vec!['X', 'Y', 'Z', 'I', 'J', 'K', 'R', 'P', 'F', 'D', 'Q']),
                         -50.0..50.0f64),
                        0..5,
                    ),
                ),
                0..30,
            )
        ) {
            let mut text = String::new();
            for (code, words) in lines {
                text.push_str(code);
                for (letter, value) in words {
                    text.push_str(&format!(" {letter}{value:.3}"));
                }
                text.push('\n');
            }
            check_program(&text);
        }
    }
}
