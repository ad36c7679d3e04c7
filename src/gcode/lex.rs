//! Line scanner: one text line into words (`letter` + value), parameter assignments and O-word
//! control, comments and markers stripped.
//!
//! The scanner knows the lexical rules (comments, numbers, markers, which letters exist) and
//! evaluates values (numbers, parameters, expressions: see [`super::expr`]) with the parameters
//! as they were before the line; what the words *mean* is decided by [`super::block`] and the
//! interpreter. It keeps its buffers from line to line, so scanning allocates little once they
//! have grown to the longest line.

use super::ErrorKind;
use super::expr::{ParamRef, Params, param_ref, real_value};

/// Largest magnitude accepted for any word's value. It keeps every later product (squares of
/// lengths, inch scaling, G91 accumulation) far away from overflow; 1e9 mm is 1000 km.
pub const MAX_ABS_VALUE: f64 = 1.0e9;

/// One word of a block: an upper-case letter and its value.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Word {
    /// Upper-case letter.
    pub letter: char,
    /// Value (evaluated).
    pub value: f64,
    /// 1-based column (in characters) of the letter.
    pub col: usize,
}

/// What a scanned line holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum LineKind {
    /// Nothing but blanks and comments.
    Blank,
    /// A `%` program marker (comments allowed beside it).
    Percent,
    /// A program number `O1234` (or `O<name>`) alone: a marker, no action.
    ProgramNumber,
    /// A `/` block, skipped because block delete is on.
    Skipped,
    /// Words (in [`Scanner::words`]) or parameter assignments, or both.
    Words,
    /// An O-word control line (in [`Scanner::control`]).
    Control,
}

/// The label of an O-word: a number or a `<name>`.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub(super) enum Label {
    /// `o101`.
    Number(u32),
    /// `o<name>`, lower-cased.
    Name(String),
}

impl std::fmt::Display for Label {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Label::Number(n) => write!(f, "o{n}"),
            Label::Name(n) => write!(f, "o<{n}>"),
        }
    }
}

/// The keyword of an O-word control line.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Keyword {
    Sub,
    EndSub,
    Call,
    Return,
    If,
    ElseIf,
    Else,
    EndIf,
    While,
    EndWhile,
    Do,
    Repeat,
    EndRepeat,
    Break,
    Continue,
}

impl Keyword {
    fn parse(word: &str) -> Option<Keyword> {
        Some(match word.to_ascii_lowercase().as_str() {
            "sub" => Keyword::Sub,
            "endsub" => Keyword::EndSub,
            "call" => Keyword::Call,
            "return" => Keyword::Return,
            "if" => Keyword::If,
            "elseif" => Keyword::ElseIf,
            "else" => Keyword::Else,
            "endif" => Keyword::EndIf,
            "while" => Keyword::While,
            "endwhile" => Keyword::EndWhile,
            "do" => Keyword::Do,
            "repeat" => Keyword::Repeat,
            "endrepeat" => Keyword::EndRepeat,
            "break" => Keyword::Break,
            "continue" => Keyword::Continue,
            _ => return None,
        })
    }

    /// The keyword as written in programs.
    pub fn name(self) -> &'static str {
        match self {
            Keyword::Sub => "sub",
            Keyword::EndSub => "endsub",
            Keyword::Call => "call",
            Keyword::Return => "return",
            Keyword::If => "if",
            Keyword::ElseIf => "elseif",
            Keyword::Else => "else",
            Keyword::EndIf => "endif",
            Keyword::While => "while",
            Keyword::EndWhile => "endwhile",
            Keyword::Do => "do",
            Keyword::Repeat => "repeat",
            Keyword::EndRepeat => "endrepeat",
            Keyword::Break => "break",
            Keyword::Continue => "continue",
        }
    }

    /// Whether bracketed values may follow the keyword: a condition (if, elseif, while), a
    /// count (repeat), a value (return, endsub) or arguments (call).
    fn takes_values(self) -> bool {
        matches!(
            self,
            Keyword::If
                | Keyword::ElseIf
                | Keyword::While
                | Keyword::Repeat
                | Keyword::Return
                | Keyword::EndSub
                | Keyword::Call
        )
    }
}

/// A scanned O-word control line.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Control {
    pub label: Label,
    pub keyword: Keyword,
    /// 1-based column of the O.
    pub col: usize,
    /// The bracketed values after the keyword (condition, count, return value, call arguments).
    pub values: Vec<f64>,
}

/// A lexical error with its 1-based column.
pub(super) type LexError = (usize, ErrorKind);

/// Scans lines; reuse one for a whole program.
#[derive(Debug, Default)]
pub(super) struct Scanner {
    chars: Vec<char>,
    /// The words of the last line scanned, in line order.
    pub words: Vec<Word>,
    /// The text of a `(MSG, ...)` comment on the last line, with its column.
    pub message: Option<(usize, String)>,
    /// The parameter assignments of the last line, in order (they take effect after the line is
    /// read, all together).
    pub assignments: Vec<(ParamRef, f64)>,
    /// The O-word of the last line if it was a control line.
    pub control: Option<Control>,
    /// The label of the last line if it was a program number (`O1234` alone).
    pub program: Option<Label>,
}

fn unsupported(what: impl Into<String>, reason: &'static str) -> ErrorKind {
    ErrorKind::Unsupported {
        what: what.into(),
        reason,
    }
}

impl Scanner {
    /// Scans one line (without its terminator), evaluating values with `params`. With
    /// `block_delete` on, a line whose first non-blank character is `/` is skipped unread.
    pub fn scan(
        &mut self,
        line: &str,
        block_delete: bool,
        params: &Params,
    ) -> Result<LineKind, LexError> {
        self.chars.clear();
        if line.is_ascii() {
            // Most lines: one char per byte, copied as a run of known length.
            self.chars.extend(line.bytes().map(char::from));
        } else {
            self.chars.extend(line.chars());
        }
        self.words.clear();
        self.message = None;
        self.assignments.clear();
        self.control = None;
        self.program = None;
        let chars: &[char] = &self.chars;
        let mut i = 0;
        while chars.get(i).is_some_and(|c| c.is_whitespace()) {
            i += 1;
        }
        if chars.get(i) == Some(&'/') {
            if block_delete {
                return Ok(LineKind::Skipped);
            }
            i += 1;
        }
        let mut percent_col = 0;
        while let Some(&c) = chars.get(i) {
            let col = i + 1;
            if percent_col != 0 && !(c.is_whitespace() || c == '(' || c == ';') {
                return Err((
                    if c == '%' { col } else { percent_col },
                    ErrorKind::MisplacedPercent,
                ));
            }
            match c {
                c if c.is_whitespace() => i += 1,
                '(' => {
                    let end = comment_end(chars, i)?;
                    // Only a `(MSG, ...)` comment is kept: the others are looked at where they
                    // are, with no string made (CAM output has one on many lines).
                    let body = chars.get(i + 1..end).unwrap_or_default();
                    let start = body.iter().position(|c| !c.is_whitespace());
                    let trimmed = start.map_or(&[][..], |k| body.get(k..).unwrap_or_default());
                    if let (Some(head), Some(rest)) = (trimmed.get(..4), trimmed.get(4..))
                        && head
                            .iter()
                            .zip("msg,".chars())
                            .all(|(a, b)| a.eq_ignore_ascii_case(&b))
                    {
                        let rest: String = rest.iter().collect();
                        self.message = Some((col, rest.trim().to_owned()));
                    }
                    i = end + 1;
                }
                ')' => return Err((col, ErrorKind::UnmatchedParen)),
                ';' => break,
                '%' => {
                    if !self.words.is_empty() || !self.assignments.is_empty() {
                        return Err((col, ErrorKind::MisplacedPercent));
                    }
                    percent_col = col;
                    i += 1;
                }
                '/' => return Err((col, ErrorKind::MisplacedBlockDelete)),
                '#' => {
                    let r = param_ref(chars, &mut i, params, 0)?;
                    while chars.get(i).is_some_and(|c| *c == ' ' || *c == '\t') {
                        i += 1;
                    }
                    if chars.get(i) != Some(&'=') {
                        return Err((
                            i + 1,
                            ErrorKind::ExpressionSyntax {
                                expected: "'=' after the parameter of an assignment",
                            },
                        ));
                    }
                    i += 1;
                    let value = real_value(chars, &mut i, params, 0, '=')?;
                    self.assignments.push((r, value));
                }
                // Polar coordinates: @ distance, ^ angle (degrees).
                '@' | '^' => {
                    let letter = c;
                    i += 1;
                    let value =
                        real_value(chars, &mut i, params, 0, letter).map_err(|(c, k)| match k {
                            ErrorKind::ExpectedNumber { letter: l } if l == letter => (col, k),
                            _ => (c, k),
                        })?;
                    if value.abs() > MAX_ABS_VALUE {
                        return Err((col, ErrorKind::NumberOutOfRange { letter, value }));
                    }
                    self.words.push(Word { letter, value, col });
                }
                c if c.is_ascii_alphabetic() => {
                    let letter = c.to_ascii_uppercase();
                    match letter {
                        'G' | 'M' | 'N' | 'X' | 'Y' | 'Z' | 'I' | 'J' | 'K' | 'R' | 'P' | 'Q'
                        | 'F' | 'S' | 'T' | 'D' | 'H' | 'L' | 'A' | 'B' | 'C' | 'U' | 'V' | 'W' => {
                            i += 1;
                            let value = real_value(chars, &mut i, params, 0, letter).map_err(
                                |(c, k)| match k {
                                    // No value at all: point at the letter that lacks it.
                                    ErrorKind::ExpectedNumber { letter: l } if l == letter => {
                                        (col, k)
                                    }
                                    _ => (c, k),
                                },
                            )?;
                            if value.abs() > MAX_ABS_VALUE {
                                return Err((col, ErrorKind::NumberOutOfRange { letter, value }));
                            }
                            self.words.push(Word { letter, value, col });
                        }
                        'O' => {
                            let only_n = self.words.iter().all(|w| w.letter == 'N');
                            if !only_n || !self.assignments.is_empty() {
                                return Err((
                                    col,
                                    o_for_zero(chars, i, &self.words, &self.assignments)
                                        .unwrap_or(ErrorKind::ProgramNumberNotAlone),
                                ));
                            }
                            let control = scan_o_word(chars, i, params)?;
                            self.words.clear();
                            return Ok(match control {
                                OWord::Control(control) => {
                                    self.control = Some(control);
                                    LineKind::Control
                                }
                                OWord::Program(label) => {
                                    self.program = Some(label);
                                    LineKind::ProgramNumber
                                }
                            });
                        }
                        'E' => {
                            return Err((
                                col,
                                unsupported("word 'E'", "E (extruder / lathe pitch) is not read"),
                            ));
                        }
                        _ => return Err((col, ErrorKind::UnknownLetter { letter })),
                    }
                }
                c => return Err((col, ErrorKind::UnexpectedChar { ch: c })),
            }
        }
        Ok(if percent_col != 0 {
            LineKind::Percent
        } else if self.words.is_empty() && self.assignments.is_empty() {
            LineKind::Blank
        } else {
            LineKind::Words
        })
    }
}

/// `X2O`: an `O` at `o` right after the digits of the line's last word, where no O-word may
/// be, is most likely the letter typed for a zero. From that word's letter, the run of digits,
/// points and O's is the word as written; with its O's as zeros, what was meant. `None` after
/// an assignment (the digits may be its value).
fn o_for_zero(
    chars: &[char],
    o: usize,
    words: &[Word],
    assignments: &[(ParamRef, f64)],
) -> Option<ErrorKind> {
    if !assignments.is_empty() {
        return None;
    }
    let last = words.last()?;
    if !o
        .checked_sub(1)
        .and_then(|k| chars.get(k))
        .is_some_and(char::is_ascii_digit)
    {
        return None;
    }
    let start = last.col.checked_sub(1)?;
    let mut end = o + 1;
    while chars
        .get(end)
        .is_some_and(|c| c.is_ascii_digit() || matches!(c, '.' | 'o' | 'O'))
    {
        end += 1;
    }
    let written: String = chars.get(start..end)?.iter().collect();
    let mut suggested = String::with_capacity(written.len());
    suggested.push(*chars.get(start)?);
    suggested.extend(written.chars().skip(1).map(|c| match c {
        'o' | 'O' => '0',
        c => c,
    }));
    Some(ErrorKind::LetterOForZero { written, suggested })
}

fn skip_blanks(chars: &[char], i: &mut usize) {
    while chars.get(*i).is_some_and(|c| c.is_whitespace()) {
        *i += 1;
    }
}

/// Where a line's O-word starts, past blanks, a block delete `/` (if `slash`) and an N word
/// (fractional too); `None` if the line does not start with one.
fn o_word_start(chars: &[char], slash: bool) -> Option<usize> {
    let mut i = 0;
    skip_blanks(chars, &mut i);
    if slash && chars.get(i) == Some(&'/') {
        i += 1;
        skip_blanks(chars, &mut i);
    }
    if chars.get(i).is_some_and(|c| c.eq_ignore_ascii_case(&'n')) {
        i += 1;
        while chars
            .get(i)
            .is_some_and(|c| c.is_ascii_digit() || c.is_whitespace() || *c == '.')
        {
            i += 1;
        }
    }
    chars
        .get(i)
        .is_some_and(|c| c.eq_ignore_ascii_case(&'o'))
        .then_some(i)
}

/// The label and keyword of an O-word line, read without evaluating anything (to find the end
/// of a subroutine or loop while storing its lines). `None` if the line is no control line.
pub(super) fn peek_control(line: &str) -> Option<(Label, Keyword)> {
    let chars: Vec<char> = line.chars().take(256).collect();
    let i = o_word_start(&chars, true)?;
    let (label, mut k) = o_label(&chars, i, None).ok()?;
    skip_blanks(&chars, &mut k);
    let start = k;
    while chars.get(k).is_some_and(|c| c.is_ascii_alphabetic()) {
        k += 1;
    }
    let word: String = chars.get(start..k)?.iter().collect();
    Some((label, Keyword::parse(&word)?))
}

/// The program number of a line that is only `O1234` (or `O<name>`), comments and an `N` word
/// aside, read without evaluating anything (an M98 call looks ahead for its subprogram).
pub(super) fn peek_program_number(line: &str) -> Option<Label> {
    let chars: Vec<char> = line.chars().take(256).collect();
    let i = o_word_start(&chars, false)?;
    let (label, mut k) = o_label(&chars, i, None).ok()?;
    skip_blanks(&chars, &mut k);
    match chars.get(k) {
        None | Some('(' | ';') => Some(label),
        _ => None,
    }
}

/// Whether a line holds the word M99 (comments and `#<names>` aside), read without evaluating
/// anything: the end of a numbered subprogram (`O100` ... `M99`).
pub(super) fn has_m99(line: &str) -> bool {
    let chars: Vec<char> = line.chars().filter(|c| !c.is_whitespace()).collect();
    let mut i = 0;
    while let Some(&c) = chars.get(i) {
        i += 1;
        match c {
            '(' => {
                while chars.get(i).is_some_and(|c| *c != ')') {
                    i += 1;
                }
            }
            ';' => return false,
            '<' => {
                while chars.get(i).is_some_and(|c| *c != '>') {
                    i += 1;
                }
            }
            'm' | 'M' => {
                let start = i;
                while chars.get(i).is_some_and(char::is_ascii_digit) {
                    i += 1;
                }
                let digits: String = chars.get(start..i).unwrap_or_default().iter().collect();
                let point_zero = chars.get(i) != Some(&'.')
                    || chars
                        .get(i + 1..)
                        .unwrap_or_default()
                        .iter()
                        .take_while(|c| c.is_ascii_digit())
                        .all(|c| *c == '0');
                if digits.parse::<u32>() == Ok(99) && point_zero {
                    return true;
                }
            }
            _ => {}
        }
    }
    false
}

/// The label at `at` (on the O) and the index after it. With `params`, a computed label
/// (`o#1`, `o[#1+2]`) is evaluated to a number; without, it is an error.
fn o_label(chars: &[char], at: usize, params: Option<&Params>) -> Result<(Label, usize), LexError> {
    let col = at + 1;
    let mut j = at + 1;
    while chars.get(j).is_some_and(|c| *c == ' ' || *c == '\t') {
        j += 1;
    }
    if chars.get(j) == Some(&'<') {
        let start = j + 1;
        while chars.get(j).is_some_and(|c| *c != '>') {
            j += 1;
        }
        if chars.get(j).is_none() {
            return Err((col, ErrorKind::MalformedOWord));
        }
        let name: String = chars
            .get(start..j)
            .unwrap_or_default()
            .iter()
            .filter(|c| !c.is_whitespace())
            .flat_map(|c| c.to_lowercase())
            .collect();
        if name.is_empty() {
            return Err((col, ErrorKind::MalformedOWord));
        }
        return Ok((Label::Name(name), j + 1));
    }
    let start = j;
    while chars.get(j).is_some_and(|c| c.is_ascii_digit()) {
        j += 1;
    }
    let digits: String = chars.get(start..j).unwrap_or_default().iter().collect();
    match digits.parse::<u32>() {
        Ok(n) => Ok((Label::Number(n), j)),
        Err(_) if matches!(chars.get(start), Some('#' | '[')) => {
            let Some(params) = params else {
                return Err((start + 1, ErrorKind::MalformedOWord));
            };
            let mut k = start;
            let value = real_value(chars, &mut k, params, 0, 'O')?;
            let n = (value >= 0.0 && value.fract() == 0.0 && value <= f64::from(u32::MAX))
                .then_some(value as u32)
                .ok_or((start + 1, ErrorKind::ComputedLabel { value }))?;
            Ok((Label::Number(n), k))
        }
        Err(_) => Err((col, ErrorKind::MalformedOWord)),
    }
}

/// Index of the `)` closing the comment opened at `open`.
fn comment_end(chars: &[char], open: usize) -> Result<usize, LexError> {
    let mut j = open + 1;
    loop {
        match chars.get(j) {
            None => return Err((open + 1, ErrorKind::UnclosedComment)),
            Some(')') => return Ok(j),
            Some('(') => return Err((j + 1, ErrorKind::NestedComment)),
            Some(_) => j += 1,
        }
    }
}

/// An O-word line: a program number alone, or a control line.
enum OWord {
    Program(Label),
    Control(Control),
}

/// Reads an O-word at `at` (on the O). Alone on its line (comments aside) it is a program number;
/// followed by a keyword it is a control line, whose bracketed values are evaluated.
fn scan_o_word(chars: &[char], at: usize, params: &Params) -> Result<OWord, LexError> {
    let col = at + 1;
    let computed = {
        let mut j = at + 1;
        while chars.get(j).is_some_and(|c| *c == ' ' || *c == '\t') {
            j += 1;
        }
        matches!(chars.get(j), Some('#' | '['))
    };
    let (label, next) = o_label(chars, at, Some(params))?;
    let mut k = next;
    let mut keyword = None;
    let mut values = Vec::new();
    loop {
        match chars.get(k) {
            Some(c) if c.is_whitespace() => k += 1,
            Some('(') => k = comment_end(chars, k)? + 1,
            None | Some(';') => break,
            Some(c) if c.is_ascii_alphabetic() && keyword.is_none() => {
                let start = k;
                while chars.get(k).is_some_and(|c| c.is_ascii_alphabetic()) {
                    k += 1;
                }
                let word: String = chars.get(start..k).unwrap_or_default().iter().collect();
                keyword = Some(Keyword::parse(&word).ok_or_else(|| {
                    (
                        start + 1,
                        ErrorKind::UnknownKeyword {
                            word: word.to_ascii_lowercase(),
                        },
                    )
                })?);
            }
            Some('[') if keyword.is_some_and(Keyword::takes_values) => {
                if values.len() >= 30 {
                    return Err((k + 1, ErrorKind::ControlValue { keyword: "call" }));
                }
                values.push(real_value(chars, &mut k, params, 0, 'O')?);
            }
            Some(_) => return Err((k + 1, ErrorKind::MalformedOWord)),
        }
    }
    let Some(keyword) = keyword else {
        if computed {
            return Err((col, ErrorKind::MalformedOWord));
        }
        return Ok(OWord::Program(label));
    };
    if computed && keyword != Keyword::Call {
        // Loops, ifs and definitions are matched with their ends before anything is evaluated.
        return Err((
            col,
            unsupported(
                format!("computed O-word label on '{}'", keyword.name()),
                "only a call may compute its label: loops, ifs and subroutine definitions need a written number or <name>",
            ),
        ));
    }
    let count_ok = match keyword {
        Keyword::If | Keyword::ElseIf | Keyword::While | Keyword::Repeat => values.len() == 1,
        Keyword::Return | Keyword::EndSub => values.len() <= 1,
        Keyword::Call => true,
        _ => values.is_empty(),
    };
    if !count_ok {
        return Err((
            col,
            ErrorKind::ControlValue {
                keyword: keyword.name(),
            },
        ));
    }
    Ok(OWord::Control(Control {
        label,
        keyword,
        col,
        values,
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scan(line: &str) -> Result<LineKind, LexError> {
        Scanner::default().scan(line, true, &Params::default())
    }

    fn words(line: &str) -> Vec<(char, f64, usize)> {
        let mut s = Scanner::default();
        s.scan(line, false, &Params::default()).unwrap();
        s.words.iter().map(|w| (w.letter, w.value, w.col)).collect()
    }

    #[test]
    fn words_numbers_and_comments() {
        assert_eq!(
            words("g1x-1.5 Y.5 (c) z+2. ;rest X"),
            vec![('G', 1.0, 1), ('X', -1.5, 3), ('Y', 0.5, 9), ('Z', 2.0, 17)]
        );
        assert_eq!(words("G 1 X 10"), vec![('G', 1.0, 1), ('X', 10.0, 5)]);
        assert_eq!(words("G91.1 i1 J2 k3 R4 P5 Q6 D7 H8 L9"), {
            let mut v = vec![('G', 91.1, 1)];
            for (k, l) in "IJKRPQDHL".chars().enumerate() {
                v.push((l, (k + 1) as f64, 7 + 3 * k));
            }
            v
        });
        assert_eq!(
            words("X[1+2] Y-[2] Z#1"),
            vec![('X', 3.0, 1), ('Y', -2.0, 8), ('Z', 0.0, 14)]
        );
        assert_eq!(scan("(only a comment)"), Ok(LineKind::Blank));
        assert_eq!(scan(""), Ok(LineKind::Blank));
    }

    #[test]
    fn assignments_take_effect_after_the_line() {
        let mut s = Scanner::default();
        let mut p = Params::default();
        p.set(&ParamRef::Number(1), 1.0).unwrap();
        assert_eq!(
            s.scan("#1=[#1+1] X#1 #<a> = 2", false, &p),
            Ok(LineKind::Words)
        );
        assert_eq!(s.words[0].value, 1.0);
        assert_eq!(
            s.assignments,
            vec![
                (ParamRef::Number(1), 2.0),
                (ParamRef::Name("a".into()), 2.0)
            ]
        );
        assert_eq!(s.scan("#2 3", false, &p).unwrap_err().0, 4);
    }

    #[test]
    fn markers_and_control() {
        assert_eq!(scan(" % (start)"), Ok(LineKind::Percent));
        assert_eq!(scan("G0 %").unwrap_err(), (4, ErrorKind::MisplacedPercent));
        assert_eq!(scan("% G0").unwrap_err(), (1, ErrorKind::MisplacedPercent));
        assert_eq!(scan("%%").unwrap_err(), (2, ErrorKind::MisplacedPercent));
        assert_eq!(scan("O1234 (part)"), Ok(LineKind::ProgramNumber));
        assert_eq!(scan("o<part> ;x"), Ok(LineKind::ProgramNumber));
        assert_eq!(
            scan("G0 O12").unwrap_err(),
            (4, ErrorKind::ProgramNumberNotAlone)
        );
        assert_eq!(scan("O").unwrap_err(), (1, ErrorKind::MalformedOWord));
        let mut s = Scanner::default();
        let p = Params::default();
        assert_eq!(
            s.scan("N5 o101 while [1 lt 2] (loop)", true, &p),
            Ok(LineKind::Control)
        );
        assert_eq!(
            s.control,
            Some(Control {
                label: Label::Number(101),
                keyword: Keyword::While,
                col: 4,
                values: vec![1.0]
            })
        );
        s.scan("o<Sub> call [1] [2+1]", true, &p).unwrap();
        let c = s.control.clone().unwrap();
        assert_eq!(
            (c.label, c.values),
            (Label::Name("sub".into()), vec![1.0, 3.0])
        );
        assert_eq!(
            s.scan("o1 goto", true, &p).unwrap_err().1,
            ErrorKind::UnknownKeyword {
                word: "goto".into()
            }
        );
        assert_eq!(s.scan("o1 while", true, &p).unwrap_err().0, 1);
        assert_eq!(
            peek_control(" /N10 O<a b> EndSub [3]"),
            Some((Label::Name("ab".into()), Keyword::EndSub))
        );
        assert_eq!(peek_control("G0 X1"), None);
    }

    #[test]
    fn block_delete() {
        assert_eq!(scan("  /G0 X1"), Ok(LineKind::Skipped));
        assert_eq!(
            words("/N5 G0 X1"),
            vec![('N', 5.0, 2), ('G', 0.0, 5), ('X', 1.0, 8)]
        );
        assert_eq!(
            scan("G0 /X1").unwrap_err(),
            (4, ErrorKind::MisplacedBlockDelete)
        );
    }

    #[test]
    fn messages() {
        let mut s = Scanner::default();
        let p = Params::default();
        s.scan("G0 X1 ( msg, Tool change! )", true, &p).unwrap();
        assert_eq!(s.message, Some((7, "Tool change!".to_owned())));
        s.scan("(message)", true, &p).unwrap();
        assert_eq!(s.message, None);
    }

    #[test]
    fn malformed_numbers() {
        for (line, text) in [
            ("X1.2.3", "1.2.3"),
            ("X-", "-"),
            ("X--1", "--1"),
            ("X1-2", "1-2"),
            ("X.", "."),
        ] {
            assert_eq!(
                scan(line).unwrap_err(),
                (
                    2,
                    ErrorKind::MalformedNumber {
                        letter: 'X',
                        text: text.to_owned()
                    }
                ),
                "{line}"
            );
        }
    }

    #[test]
    fn the_letter_o_typed_for_a_zero_is_named() {
        // `X2O`: the O right after the digit, pointing at the O.
        assert_eq!(
            scan("G1 X2O F100").unwrap_err(),
            (
                6,
                ErrorKind::LetterOForZero {
                    written: "X2O".into(),
                    suggested: "X20".into()
                }
            )
        );
        let e = scan("G1 x1.5o0o Y2").unwrap_err();
        assert_eq!(
            e.1,
            ErrorKind::LetterOForZero {
                written: "x1.5o0o".into(),
                suggested: "x1.5000".into()
            }
        );
        assert_eq!(
            e.1.to_string(),
            "the letter O in 'x1.5o0o' looks typed for a zero: did you mean 'x1.5000'?"
        );
        assert_eq!(
            scan("G0 X1O5").unwrap_err().1,
            ErrorKind::LetterOForZero {
                written: "X1O5".into(),
                suggested: "X105".into()
            }
        );
        // An O-word after a blank or after an assignment's value is still a misplaced program
        // number; a control line after N stays valid.
        assert_eq!(
            scan("#1=2O").unwrap_err(),
            (5, ErrorKind::ProgramNumberNotAlone)
        );
        assert_eq!(
            scan("G0 X2 O12").unwrap_err(),
            (7, ErrorKind::ProgramNumberNotAlone)
        );
        assert_eq!(scan("N10O1234"), Ok(LineKind::ProgramNumber));
    }

    #[test]
    fn letters_after_a_word_letter_say_what_they_were_taken_for() {
        // `FOO`: F, then `OO` where its value should be.
        let e = scan("G1 X1 FOO").unwrap_err();
        assert_eq!(
            e,
            (
                8,
                ErrorKind::NotANumber {
                    letter: 'F',
                    text: "OO".into()
                }
            )
        );
        assert_eq!(
            e.1.to_string(),
            "'F' is followed by 'OO', which is neither a number nor a function"
        );
        // A function name without its brackets.
        let e = scan("G1 X sin 30").unwrap_err();
        assert_eq!(
            e,
            (
                6,
                ErrorKind::FunctionWithoutBracket {
                    letter: 'X',
                    name: "SIN".into()
                }
            )
        );
        assert_eq!(
            e.1.to_string(),
            "'X' is followed by the function name SIN, which needs its argument in brackets: SIN[...]"
        );
    }

    #[test]
    fn columns_count_characters() {
        assert_eq!(words("(é) X1"), vec![('X', 1.0, 5)]);
    }
}
