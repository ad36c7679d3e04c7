//! Line scanner: one text line into words (`letter` + number), comments and markers stripped.
//!
//! The scanner knows the lexical rules only (comments, numbers, which letters this front end
//! reads at all); what the words *mean* is decided by the block interpreter in `mod.rs`.

use super::ErrorKind;

/// Largest magnitude accepted for any number in a program. It keeps every later product
/// (squares of lengths, inch scaling, G91 accumulation) far away from overflow; 1e9 mm is 1000 km.
pub const MAX_ABS_VALUE: f64 = 1.0e9;

/// One word of a block: an upper-case letter and its value.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Word {
    /// Upper-case letter.
    pub letter: char,
    /// Parsed value.
    pub value: f64,
    /// The number as written (sign and digits), for messages.
    pub text: String,
    /// 1-based column (in characters) of the letter.
    pub col: usize,
}

impl Word {
    /// The word as a person wrote it, upper-cased: `X-1.5`, `G61.1`.
    pub fn display(&self) -> String {
        format!("{}{}", self.letter, self.text)
    }
}

/// A scanned line.
#[derive(Debug, Default, Clone, PartialEq)]
pub(super) struct Scanned {
    /// The words, in line order.
    pub words: Vec<Word>,
    /// The line is a `%` program marker (nothing but comments beside it).
    pub percent: bool,
}

/// A lexical error with its 1-based column.
pub(super) type LexError = (usize, ErrorKind);

/// Why a letter is not read by this front end, or `None` if it is.
fn unsupported_letter(letter: char) -> Option<(String, &'static str)> {
    let reason = match letter {
        'G' | 'M' | 'N' | 'X' | 'Y' | 'Z' | 'F' | 'S' | 'T' => return None,
        'A' | 'B' | 'C' | 'U' | 'V' | 'W' => {
            return Some((
                format!("axis '{letter}'"),
                "only the X, Y and Z axes are supported",
            ));
        }
        'O' => {
            return Some((
                "O-word".to_owned(),
                "subroutines and control flow arrive with the full G-code front end",
            ));
        }
        'I' | 'J' | 'K' | 'R' => "arc words arrive with the full G-code front end",
        'P' | 'Q' | 'L' => "it belongs to codes this G0/G1 front end does not support",
        'D' | 'H' => "tool compensation arrives with the full G-code front end",
        _ => "it is not a word of this G0/G1 front end",
    };
    Some((format!("word '{letter}'"), reason))
}

fn unsupported(what: &str, reason: &'static str) -> ErrorKind {
    ErrorKind::Unsupported {
        what: what.to_owned(),
        reason,
    }
}

/// Scans one line (without its line terminator). `chars` is a reusable buffer.
pub(super) fn scan_line(line: &str, chars: &mut Vec<char>) -> Result<Scanned, LexError> {
    chars.clear();
    chars.extend(line.chars());
    let chars: &[char] = chars;
    let mut out = Scanned::default();
    let mut percent_col = 0;
    let mut i = 0;
    while let Some(&c) = chars.get(i) {
        let col = i + 1;
        match c {
            c if c.is_whitespace() => i += 1,
            '(' => {
                let mut j = i + 1;
                loop {
                    match chars.get(j) {
                        None => return Err((col, ErrorKind::UnclosedComment)),
                        Some(')') => break,
                        Some('(') => return Err((j + 1, ErrorKind::NestedComment)),
                        Some(_) => j += 1,
                    }
                }
                i = j + 1;
            }
            ')' => return Err((col, ErrorKind::UnmatchedParen)),
            ';' => break,
            '%' => {
                if out.percent || !out.words.is_empty() {
                    return Err((col, ErrorKind::MisplacedPercent));
                }
                out.percent = true;
                percent_col = col;
                i += 1;
            }
            '/' => {
                return Err((
                    col,
                    unsupported("block delete '/'", "optional blocks are not supported"),
                ));
            }
            '#' => return Err((col, param_error())),
            '[' => return Err((col, expr_error())),
            c if c.is_ascii_alphabetic() => {
                if out.percent {
                    return Err((percent_col, ErrorKind::MisplacedPercent));
                }
                let letter = c.to_ascii_uppercase();
                if let Some((what, reason)) = unsupported_letter(letter) {
                    return Err((col, ErrorKind::Unsupported { what, reason }));
                }
                let (word, next) = scan_number(chars, i, letter)?;
                out.words.push(word);
                i = next;
            }
            c => return Err((col, ErrorKind::UnexpectedChar { ch: c })),
        }
    }
    Ok(out)
}

fn param_error() -> ErrorKind {
    unsupported(
        "parameter '#'",
        "parameters arrive with the full G-code front end",
    )
}

fn expr_error() -> ErrorKind {
    unsupported(
        "expression '['",
        "expressions arrive with the full G-code front end",
    )
}

/// Scans the number after the letter at `at`. Blanks between the letter and the number are
/// allowed (RS274 ignores them); blanks inside the number are not.
fn scan_number(chars: &[char], at: usize, letter: char) -> Result<(Word, usize), LexError> {
    let col = at + 1;
    let mut j = at + 1;
    while chars.get(j).is_some_and(|c| *c == ' ' || *c == '\t') {
        j += 1;
    }
    match chars.get(j) {
        Some('#') => return Err((j + 1, param_error())),
        Some('[') => return Err((j + 1, expr_error())),
        Some(c) if *c == '+' || *c == '-' || *c == '.' || c.is_ascii_digit() => {}
        _ => return Err((col, ErrorKind::ExpectedNumber { letter })),
    }
    let start = j;
    if matches!(chars.get(j), Some('+' | '-')) {
        j += 1;
    }
    // The token runs over every digit, point and sign so that "1.2.3", "1-2" and "--1" are
    // reported whole as malformed rather than as a stray character after a valid prefix.
    let mut digits = 0usize;
    let mut dots = 0usize;
    let mut inner_signs = 0usize;
    while let Some(&c) = chars.get(j) {
        match c {
            '0'..='9' => digits += 1,
            '.' => dots += 1,
            '+' | '-' => inner_signs += 1,
            _ => break,
        }
        j += 1;
    }
    let text: String = chars.get(start..j).unwrap_or_default().iter().collect();
    if digits == 0 || dots > 1 || inner_signs > 0 {
        return Err((col, ErrorKind::MalformedNumber { letter, text }));
    }
    let value = match text.parse::<f64>() {
        Ok(v) => v,
        Err(_) => return Err((col, ErrorKind::MalformedNumber { letter, text })),
    };
    if !value.is_finite() || value.abs() > MAX_ABS_VALUE {
        return Err((col, ErrorKind::NumberOutOfRange { letter, text }));
    }
    Ok((
        Word {
            letter,
            value,
            text,
            col,
        },
        j,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scan(line: &str) -> Result<Scanned, LexError> {
        scan_line(line, &mut Vec::new())
    }

    fn words(line: &str) -> Vec<(char, f64, usize)> {
        scan(line)
            .unwrap()
            .words
            .iter()
            .map(|w| (w.letter, w.value, w.col))
            .collect()
    }

    #[test]
    fn words_numbers_and_comments() {
        assert_eq!(
            words("g1x-1.5 Y.5 (c) z+2. ;rest X"),
            vec![('G', 1.0, 1), ('X', -1.5, 3), ('Y', 0.5, 9), ('Z', 2.0, 17)]
        );
        assert_eq!(words("G 1 X 10"), vec![('G', 1.0, 1), ('X', 10.0, 5)]);
        assert_eq!(words("(only a comment)"), vec![]);
        assert_eq!(words(""), vec![]);
    }

    #[test]
    fn percent_marker() {
        let s = scan(" % (start)").unwrap();
        assert!(s.percent && s.words.is_empty());
        assert_eq!(scan("G0 %").unwrap_err(), (4, ErrorKind::MisplacedPercent));
        assert_eq!(scan("% G0").unwrap_err(), (1, ErrorKind::MisplacedPercent));
        assert_eq!(scan("%%").unwrap_err(), (2, ErrorKind::MisplacedPercent));
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
                    1,
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
    fn columns_count_characters() {
        assert_eq!(words("(é) X1"), vec![('X', 1.0, 5)]);
    }
}
