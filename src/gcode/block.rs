//! One line's words, checked and sorted into modal groups before any takes effect.
//!
//! Only what can be decided from the line alone is checked here (known codes, one code per
//! modal group, each letter once, value domains); what depends on the modal state (which words
//! a modal G2 uses, whether a tool exists) is the interpreter's.

use std::fmt;

use super::ErrorKind;
use super::lex::Word;

/// A block-level error with its 1-based column.
pub(super) type BlockError = (usize, ErrorKind);

/// A G or M code: value in tenths (`G61.1` is 611), with the column of its word.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct Code {
    pub letter: char,
    pub tenths: u32,
    pub col: usize,
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

/// Modal groups (and the non-modal group 0) of the codes this front end executes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Group {
    Motion,
    NonModal,
    Plane,
    Distance,
    ArcDistance,
    FeedMode,
    Units,
    Comp,
    ToolLength,
    Coord,
    Path,
    Retract,
    LatheMode,
    SpindleMode,
    Stop,
    ToolChange,
    Spindle,
    Coolant,
    Override,
    ModalState,
}

impl Group {
    fn name(self) -> &'static str {
        match self {
            Group::Motion => "motion",
            Group::NonModal => "non-modal (group 0)",
            Group::Plane => "plane selection",
            Group::Distance => "distance mode",
            Group::ArcDistance => "arc centre mode",
            Group::FeedMode => "feed mode",
            Group::Units => "units",
            Group::Comp => "cutter compensation",
            Group::ToolLength => "tool length offset",
            Group::Coord => "coordinate system",
            Group::Path => "path control",
            Group::Retract => "canned cycle return",
            Group::LatheMode => "lathe diameter/radius",
            Group::SpindleMode => "spindle speed mode",
            Group::Stop => "program stop",
            Group::ToolChange => "tool change",
            Group::Spindle => "spindle",
            Group::Coolant => "coolant",
            Group::Override => "override switch",
            Group::ModalState => "modal state save/restore",
        }
    }

    fn index(self) -> usize {
        self as usize
    }
}

const GROUPS: usize = Group::ModalState as usize + 1;

/// What a G code is: its group, or why it is not executed.
enum Known {
    In(Group),
    Unsupported(&'static str),
    Unknown,
}

#[inline]
fn classify_g(tenths: u32) -> Known {
    use Known::*;
    match tenths {
        0 | 10 | 20 | 30 | 800 => In(Group::Motion),
        // Splines (see `splines.rs`).
        50 | 51 => In(Group::Motion),
        // Canned cycles (see `cycles.rs`).
        730 | 740 | 810..=860 | 890 => In(Group::Motion),
        40 | 100 | 280 | 281 | 300 | 301 | 520 | 530 | 920..=923 => In(Group::NonModal),
        170 | 180 | 190 => In(Group::Plane),
        900 | 910 => In(Group::Distance),
        901 | 911 => In(Group::ArcDistance),
        930 | 940 => In(Group::FeedMode),
        200 | 210 => In(Group::Units),
        400 | 410 | 411 | 420 | 421 => In(Group::Comp),
        430 | 431 | 432 | 440 | 490 => In(Group::ToolLength),
        540 | 550 | 560 | 570 | 580 | 590 | 591 | 592 | 593 => In(Group::Coord),
        610 | 611 | 640 => In(Group::Path),
        980 | 990 => In(Group::Retract),
        70 | 80 => In(Group::LatheMode),
        970 => In(Group::SpindleMode),
        52 | 53 => Unsupported("NURBS (G5.2, G5.3) are not supported: use G5 or G5.1"),
        150 | 160 => Unsupported(
            "Fanuc polar mode (G15/G16) is not supported: use LinuxCNC's polar words @ (distance) and ^ (angle)",
        ),
        171 | 181 | 191 => Unsupported("the UVW planes are not supported: the machine has X, Y, Z"),
        330 | 331 | 760 => {
            Unsupported("spindle-synchronised motion (threading, rigid tapping) is not supported")
        }
        380..=389 => Unsupported("probing is not supported"),
        870 => Unsupported(
            "the back boring cycle needs spindle orientation (M19), which is out of scope",
        ),
        880 => Unsupported(
            "the G88 boring cycle stops for the operator to retract the spindle by hand: use G86 or G89",
        ),
        950 => Unsupported("feed per revolution is spindle-synchronised: not supported"),
        960 => Unsupported("constant surface speed is spindle-synchronised: not supported"),
        500 | 510 | 680 | 690 => Unsupported("scaling and G68 rotation are not supported"),
        _ => Unknown,
    }
}

#[inline]
fn classify_m(number: u32) -> Known {
    use Known::*;
    match number {
        0 | 1 | 2 | 30 | 98 | 99 => In(Group::Stop),
        6 | 61 => In(Group::ToolChange),
        3..=5 | 19 => In(Group::Spindle),
        7..=9 => In(Group::Coolant),
        48..=53 => In(Group::Override),
        60 => Unsupported("pallet change pause is not supported"),
        62..=68 => Unsupported("digital and analog I/O is not supported"),
        70..=73 => In(Group::ModalState),
        100..=199 => Unsupported("user-defined M codes are not supported"),
        _ => Unknown,
    }
}

/// The letters a block may hold (besides G and M), in a fixed order for the word table.
const LETTERS: [char; 24] = [
    'X', 'Y', 'Z', 'I', 'J', 'K', 'R', 'P', 'Q', 'F', 'S', 'T', 'D', 'H', 'L', 'N', '@', '^', 'A',
    'B', 'C', 'U', 'V', 'W',
];

/// The index of `letter` in [`LETTERS`] (a `match`, not a search: it runs for every word).
#[inline]
fn letter_index(letter: char) -> Option<usize> {
    let k = match letter {
        'X' => 0,
        'Y' => 1,
        'Z' => 2,
        'I' => 3,
        'J' => 4,
        'K' => 5,
        'R' => 6,
        'P' => 7,
        'Q' => 8,
        'F' => 9,
        'S' => 10,
        'T' => 11,
        'D' => 12,
        'H' => 13,
        'L' => 14,
        'N' => 15,
        '@' => 16,
        '^' => 17,
        'A' => 18,
        'B' => 19,
        'C' => 20,
        'U' => 21,
        'V' => 22,
        'W' => 23,
        _ => return None,
    };
    debug_assert_eq!(LETTERS.get(k), Some(&letter));
    Some(k)
}

/// The bit of `letter` in [`Block::present`] (bit k for `LETTERS[k]`), 0 for other letters.
#[inline]
pub(super) fn letter_bit(letter: char) -> u32 {
    letter_index(letter).map_or(0, |k| 1 << k)
}

/// The bits ([`letter_bit`]) of X, Y, Z, `@`, `^` and A B C U V W: the words that make a move.
const AXIS_BITS: u32 = 0b11_1111 << 18 | 0b11 << 16 | 0b111;

/// The words of one line, checked and sorted into modal groups.
#[derive(Debug, Default, Clone)]
pub(super) struct Block {
    groups: [Option<Code>; GROUPS],
    words: [Option<Word>; LETTERS.len()],
    /// The letters present, one bit each ([`letter_bit`]): most lines use few of them, and
    /// the interpreter's check for unused words is one mask test.
    present: u32,
    /// The second coolant code of `M7 M8` (both on one line is allowed).
    pub coolant2: Option<Code>,
}

fn invalid(word: &Word, expected: &'static str) -> BlockError {
    (
        word.col,
        ErrorKind::InvalidValue {
            word: format!("{}{}", word.letter, word.value),
            expected,
        },
    )
}

/// A G or M value as tenths: non-negative, at most one decimal.
#[inline]
fn code_tenths(word: &Word) -> Option<u32> {
    let tenths = word.value * 10.0;
    let rounded = tenths.round();
    if word.value < 0.0 || (tenths - rounded).abs() > 1e-6 || rounded > f64::from(u32::MAX) {
        return None;
    }
    // In range and integral: the cast is exact.
    Some(rounded as u32)
}

/// Whether `value` is a non-negative integer that fits a `u32`.
pub(super) fn as_index(value: f64) -> Option<u32> {
    (value >= 0.0 && value.fract() == 0.0 && value <= f64::from(u32::MAX)).then_some(value as u32)
}

impl Block {
    /// A block of `words` (see [`Block::read_into`]).
    #[cfg(test)]
    pub fn read(words: &[Word]) -> Result<Block, BlockError> {
        let mut block = Block::default();
        block.read_into(words)?;
        Ok(block)
    }

    /// Checks every word of a line into `self`, whatever it held; the first problem in line
    /// order is reported. The interpreter keeps one block for every line, so that a line
    /// costs no copy of it (it is some 800 bytes).
    pub fn read_into(&mut self, words: &[Word]) -> Result<(), BlockError> {
        *self = Block::default();
        let block = self;
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
                    match classify_g(tenths) {
                        Known::In(group) => block.set_code(group, code)?,
                        Known::Unsupported(reason) => {
                            return Err((
                                word.col,
                                ErrorKind::Unsupported {
                                    what: code.to_string(),
                                    reason,
                                },
                            ));
                        }
                        Known::Unknown => {
                            return Err((
                                word.col,
                                ErrorKind::UnknownCode {
                                    code: code.to_string(),
                                },
                            ));
                        }
                    }
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
                    match classify_m(tenths / 10) {
                        // M7 and M8 together are allowed (mist and flood).
                        Known::In(Group::Coolant) => match block.get(Group::Coolant) {
                            Some(first)
                                if block.coolant2.is_none()
                                    && first.tenths != 90
                                    && code.tenths != 90
                                    && first.tenths != code.tenths =>
                            {
                                block.coolant2 = Some(code);
                            }
                            _ => block.set_code(Group::Coolant, code)?,
                        },
                        Known::In(group) => block.set_code(group, code)?,
                        Known::Unsupported(reason) => {
                            return Err((
                                word.col,
                                ErrorKind::Unsupported {
                                    what: code.to_string(),
                                    reason,
                                },
                            ));
                        }
                        Known::Unknown => {
                            return Err((
                                word.col,
                                ErrorKind::UnknownCode {
                                    code: code.to_string(),
                                },
                            ));
                        }
                    }
                }
                letter => {
                    if letter == 'N' && i != 0 {
                        return Err((word.col, ErrorKind::LineNumberNotFirst));
                    }
                    let Some(slot) = letter_index(letter).and_then(|k| block.words.get_mut(k))
                    else {
                        return Err((word.col, ErrorKind::UnknownLetter { letter }));
                    };
                    if slot.is_some() {
                        return Err((word.col, ErrorKind::RepeatedWord { letter }));
                    }
                    *slot = Some(*word);
                    block.present |= letter_bit(letter);
                    check_domain(word)?;
                }
            }
        }
        Ok(())
    }

    /// The letters present ([`letter_bit`]).
    pub fn present(&self) -> u32 {
        self.present
    }

    #[inline]
    fn set_code(&mut self, group: Group, code: Code) -> Result<(), BlockError> {
        let Some(slot) = self.groups.get_mut(group.index()) else {
            return Ok(());
        };
        // G80 beside another motion code is ignored (LinuxCNC: `G80 G0` is a common preamble).
        if group == Group::Motion {
            match slot {
                Some(first) if first.tenths == 800 && code.tenths != 800 => {
                    *slot = Some(code);
                    return Ok(());
                }
                Some(first) if code.tenths == 800 && first.tenths != 800 => return Ok(()),
                _ => {}
            }
        }
        if let Some(first) = slot {
            return Err((
                code.col,
                ErrorKind::ModalConflict {
                    group: group.name(),
                    first: first.to_string(),
                    second: code.to_string(),
                },
            ));
        }
        *slot = Some(code);
        Ok(())
    }

    #[inline]
    fn get(&self, group: Group) -> Option<Code> {
        self.groups.get(group.index()).copied().flatten()
    }

    /// The word for `letter` (one of X Y Z I J K R P Q F S T D H L N).
    #[inline]
    pub fn word(&self, letter: char) -> Option<Word> {
        letter_index(letter)
            .and_then(|k| self.words.get(k))
            .copied()
            .flatten()
    }

    /// The first axis word of the line (by column).
    pub fn first_axis(&self) -> Option<Word> {
        // Every line asks: read the slots where they are (collecting the five words into an
        // array first cost a tenth of the front end's time, in stack copies).
        if self.present & AXIS_BITS == 0 {
            return None;
        }
        let mut first: Option<&Word> = None;
        for k in [0, 1, 2, 16, 17, 18, 19, 20, 21, 22, 23] {
            if let Some(Some(w)) = self.words.get(k)
                && first.is_none_or(|f| w.col < f.col)
            {
                first = Some(w);
            }
        }
        first.copied()
    }

    /// The polar coordinate words: `@` (distance) and `^` (angle, degrees).
    pub fn polar(&self) -> [Option<Word>; 2] {
        [self.word('@'), self.word('^')]
    }

    /// G0, G1, G2, G3, G80 or a canned cycle (G73, G74, G81…G86, G89).
    pub fn motion(&self) -> Option<Code> {
        self.get(Group::Motion)
    }
    /// G4, G10, G28, G28.1, G30, G30.1, G53, G92, G92.1, G92.2, G92.3.
    pub fn non_modal(&self) -> Option<Code> {
        self.get(Group::NonModal)
    }
    /// G17, G18, G19.
    pub fn plane(&self) -> Option<Code> {
        self.get(Group::Plane)
    }
    /// G90, G91.
    pub fn distance(&self) -> Option<Code> {
        self.get(Group::Distance)
    }
    /// G90.1, G91.1.
    pub fn arc_distance(&self) -> Option<Code> {
        self.get(Group::ArcDistance)
    }
    /// G93, G94.
    pub fn feed_mode(&self) -> Option<Code> {
        self.get(Group::FeedMode)
    }
    /// G20, G21.
    pub fn units(&self) -> Option<Code> {
        self.get(Group::Units)
    }
    /// G40, G41, G41.1, G42, G42.1.
    pub fn comp(&self) -> Option<Code> {
        self.get(Group::Comp)
    }
    /// G43, G43.1, G43.2, G44, G49.
    pub fn tool_length(&self) -> Option<Code> {
        self.get(Group::ToolLength)
    }
    /// G54 … G59.3.
    pub fn coord(&self) -> Option<Code> {
        self.get(Group::Coord)
    }
    /// G61, G61.1, G64.
    pub fn path(&self) -> Option<Code> {
        self.get(Group::Path)
    }
    /// G98, G99 (the canned cycles' return level).
    pub fn retract(&self) -> Option<Code> {
        self.get(Group::Retract)
    }
    /// G97 (spindle RPM mode, the only one: noted).
    pub fn spindle_mode(&self) -> Option<Code> {
        self.get(Group::SpindleMode)
    }
    /// M0, M1, M2, M30, M98, M99.
    pub fn stop(&self) -> Option<Code> {
        self.get(Group::Stop)
    }
    /// M6, M61.
    pub fn tool_change(&self) -> Option<Code> {
        self.get(Group::ToolChange)
    }
    /// M3, M4, M5, M19.
    pub fn spindle(&self) -> Option<Code> {
        self.get(Group::Spindle)
    }
    /// M7, M8, M9 (see also [`Block::coolant2`]).
    pub fn coolant(&self) -> Option<Code> {
        self.get(Group::Coolant)
    }
    /// M48 … M53.
    pub fn override_switch(&self) -> Option<Code> {
        self.get(Group::Override)
    }
    /// M70 … M73.
    pub fn lathe_mode(&self) -> Option<Code> {
        self.get(Group::LatheMode)
    }

    /// This block with its X word halved: under G7 an X word is a diameter (LinuxCNC halves
    /// it as it reads it, whatever code uses it).
    pub fn with_x_halved(&self) -> Block {
        let mut b = self.clone();
        if let Some(w) = b.words[0].as_mut() {
            w.value /= 2.0;
        }
        b
    }

    pub fn modal_state(&self) -> Option<Code> {
        self.get(Group::ModalState)
    }
}

/// Value domains that hold whatever the codes on the line.
fn check_domain(word: &Word) -> Result<(), BlockError> {
    match word.letter {
        // LinuxCNC reads fractional line numbers (N4567.789) too.
        'N' if word.value < 0.0 => Err(invalid(word, "a non-negative line number")),
        'F' if word.value < 0.0 => Err(invalid(word, "a feed rate of 0 or more")),
        'S' if word.value < 0.0 => Err(invalid(word, "a non-negative spindle speed")),
        'T' | 'H' if as_index(word.value).is_none() => {
            Err(invalid(word, "a non-negative integer tool number"))
        }
        'L' if as_index(word.value).is_none() => Err(invalid(word, "a non-negative integer")),
        // D may be negative: a G41.1/G42.1 diameter below zero swaps the side (LinuxCNC);
        // G41/G42 refuse a negative tool number themselves.
        // Q may be negative: G5's end control point. M61, G64 and the cycles check their own.
        _ => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gcode::lex::Scanner;

    fn read(line: &str) -> Result<Block, BlockError> {
        let mut s = Scanner::default();
        s.scan(line, false, &crate::gcode::expr::Params::default())
            .expect("scans");
        Block::read(&s.words)
    }

    #[test]
    fn every_letter_has_its_own_slot() {
        for (k, l) in LETTERS.iter().enumerate() {
            assert_eq!(letter_index(*l), Some(k));
        }
        assert_eq!(letter_index('G'), None);
    }

    #[test]
    fn the_axis_bits_are_the_axis_letters() {
        let bits = "XYZ@^ABCUVW".chars().fold(0, |m, c| m | letter_bit(c));
        assert_eq!(bits, AXIS_BITS);
        let b = read("G0 X1 Y2").unwrap();
        assert_eq!(b.present(), letter_bit('X') | letter_bit('Y'));
        assert!(read("G4 P1").unwrap().first_axis().is_none());
    }

    #[test]
    fn groups_and_words() {
        let b = read("N10 G17 G21 G90 G91.1 G94 G40 G49 G54 G64 G0 X1 Y2 Z3 F100 S5 M3 M8 T1 M6")
            .unwrap();
        assert_eq!(b.plane().unwrap().tenths, 170);
        assert_eq!(b.motion().unwrap().to_string(), "G0");
        assert_eq!(b.arc_distance().unwrap().to_string(), "G91.1");
        assert_eq!(b.word('F').unwrap().value, 100.0);
        assert_eq!(b.first_axis().unwrap().letter, 'X');
        assert_eq!(b.tool_change().unwrap().to_string(), "M6");
        let b = read("M7 M8").unwrap();
        assert_eq!(
            (b.coolant().unwrap().tenths, b.coolant2.unwrap().tenths),
            (70, 80)
        );
        assert!(read("M8 M9").is_err());
    }

    #[test]
    fn conflicts_and_domains() {
        assert_eq!(
            read("G0 G1").unwrap_err().1.to_string(),
            "G0 and G1 on one line are both motion codes (one per line)"
        );
        assert_eq!(
            read("G4 P1 G28").unwrap_err().1.to_string(),
            "G4 and G28 on one line are both non-modal (group 0) codes (one per line)"
        );
        assert_eq!(read("X1 X2").unwrap_err().0, 4);
        assert_eq!(read("G80 G0").unwrap().motion().unwrap().to_string(), "G0");
        assert_eq!(read("G1 G80").unwrap().motion().unwrap().to_string(), "G1");
        assert_eq!(
            read("G1 F-1").unwrap_err().1.to_string(),
            "invalid F-1: expected a feed rate of 0 or more"
        );
        assert_eq!(read("G81 X1").unwrap().motion().unwrap().to_string(), "G81");
        assert_eq!(
            read("G88 X1").unwrap_err().1.to_string(),
            "unsupported: G88 (the G88 boring cycle stops for the operator to retract the spindle by hand: use G86 or G89)"
        );
        assert_eq!(
            read("G12.5").unwrap_err().1.to_string(),
            "unknown code G12.5"
        );
    }
}
