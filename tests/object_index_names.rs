//! Object indices are named (issue 13, item 2): no CiA 301/402 object index appears as a raw
//! literal in `src/` outside the one table, `src/canopen/index.rs`.
//!
//! What is scanned: every `src/**/*.rs` except
//! - `src/canopen/index.rs`, the table itself;
//! - `src/canopen/emcy.rs`, the EMCY code table: EMCY codes share the number ranges (0x1000
//!   generic error, 0x6320 parameter error) but are not indices;
//! - test code: files named `tests.rs`, and the braces of any item under `#[cfg(test)]`.
//!
//! What counts: a hexadecimal literal of exactly four digits starting with 1 or 6 (`0x1xxx`,
//! CiA 301's communication area; `0x6xxx`, CiA 402's), in code: comments, string and character
//! literals are not code (messages and docs may cite indices for people). COB-IDs (0x180,
//! 0x700) have three digits and EMCY codes 0x8xxx another first digit, so neither matches. A
//! line may opt out with the comment `not an object index` (and a reason), for a constant that
//! merely has an index's shape, such as a CRC polynomial.

use std::path::{Path, PathBuf};

const EXEMPT: &str = "not an object index";

/// For each byte of `src`, whether it is code (not a comment, string or character literal).
fn code_mask(src: &[u8]) -> Vec<bool> {
    let n = src.len();
    let mut m = vec![true; n];
    let word = |i: usize| i > 0 && (src[i - 1].is_ascii_alphanumeric() || src[i - 1] == b'_');
    let mut i = 0;
    while i < n {
        let start = i;
        if src[i..].starts_with(b"//") {
            while i < n && src[i] != b'\n' {
                i += 1;
            }
        } else if src[i..].starts_with(b"/*") {
            let mut depth = 0;
            while i < n {
                if src[i..].starts_with(b"/*") {
                    depth += 1;
                    i += 2;
                } else if src[i..].starts_with(b"*/") {
                    depth -= 1;
                    i += 2;
                    if depth == 0 {
                        break;
                    }
                } else {
                    i += 1;
                }
            }
        } else if let Some(hashes) = raw_string_start(&src[i..]).filter(|_| !word(i)) {
            // r"..", r#".."#, br"..": ends at the quote followed by as many hashes.
            let open = src[i..].iter().position(|&c| c == b'"').unwrap();
            i += open + 1;
            loop {
                if i >= n {
                    break;
                }
                if src[i] == b'"'
                    && src[i + 1..]
                        .iter()
                        .take(hashes)
                        .filter(|&&c| c == b'#')
                        .count()
                        == hashes
                {
                    i += 1 + hashes;
                    break;
                }
                i += 1;
            }
        } else if src[i] == b'"' || (src[i..].starts_with(b"b\"") && !word(i)) {
            i += if src[i] == b'"' { 1 } else { 2 };
            while i < n && src[i] != b'"' {
                i += if src[i] == b'\\' { 2 } else { 1 };
            }
            i += 1;
        } else if src[i] == b'\'' {
            match char_literal_len(&src[i..]) {
                Some(len) => i += len,
                None => {
                    i += 1; // a lifetime
                    continue;
                }
            }
        } else {
            i += 1;
            continue;
        }
        for b in &mut m[start..i.min(n)] {
            *b = false;
        }
    }
    m
}

/// `r"`, `r#"`, `br##"` ...: the number of hashes.
fn raw_string_start(s: &[u8]) -> Option<usize> {
    let s = s.strip_prefix(b"b").unwrap_or(s);
    let s = s.strip_prefix(b"r")?;
    let hashes = s.iter().take_while(|&&c| c == b'#').count();
    (s.get(hashes) == Some(&b'"')).then_some(hashes)
}

/// The length of a character literal at the start of `s` (`'a'`, `'\n'`, `'\x7f'`,
/// `'\u{20AC}'`, a multi-byte character), or `None` for a lifetime.
fn char_literal_len(s: &[u8]) -> Option<usize> {
    let close = if s.get(1) == Some(&b'\\') {
        s.iter().skip(3).position(|&c| c == b'\'')? + 3
    } else {
        // One UTF-8 character, then the closing quote.
        let len = match s.get(1)? {
            c if *c < 0x80 => 1,
            c if *c >= 0xF0 => 4,
            c if *c >= 0xE0 => 3,
            _ => 2,
        };
        1 + len
    };
    (s.get(close) == Some(&b'\'') && close <= 12).then_some(close + 1)
}

/// Byte ranges of the bodies of `#[cfg(test)]` items.
fn test_spans(src: &[u8], m: &[bool]) -> Vec<(usize, usize)> {
    const ATTR: &[u8] = b"#[cfg(test)]";
    let mut spans = Vec::new();
    let mut from = 0;
    while let Some(at) = src[from..].windows(ATTR.len()).position(|w| w == ATTR) {
        let at = from + at;
        from = at + ATTR.len();
        if !m[at] {
            continue;
        }
        let mut j = from;
        while j < src.len() && !(m[j] && (src[j] == b'{' || src[j] == b';')) {
            j += 1;
        }
        if j >= src.len() || src[j] == b';' {
            continue; // `#[cfg(test)] mod tests;`: the file is skipped by its name
        }
        let mut depth = 0;
        let mut k = j;
        while k < src.len() {
            if m[k] && src[k] == b'{' {
                depth += 1;
            } else if m[k] && src[k] == b'}' {
                depth -= 1;
                if depth == 0 {
                    break;
                }
            }
            k += 1;
        }
        spans.push((at, k + 1));
    }
    spans
}

/// Raw object indices in `src`: (line, literal).
fn raw_indices(src: &str) -> Vec<(usize, String)> {
    let b = src.as_bytes();
    let m = code_mask(b);
    let tests = test_spans(b, &m);
    let lines: Vec<&str> = src.lines().collect();
    let ident = |c: u8| c.is_ascii_alphanumeric() || c == b'_';
    let mut out = Vec::new();
    for i in 0..b.len().saturating_sub(5) {
        let lit = &b[i..i + 6];
        if !(m[i]
            && lit.starts_with(b"0x")
            && (lit[2] == b'1' || lit[2] == b'6')
            && lit[3..].iter().all(u8::is_ascii_hexdigit)
            && (i == 0 || !ident(b[i - 1]))
            && b.get(i + 6 + suffix_len(&b[i + 6..]))
                .is_none_or(|&c| !ident(c)))
        {
            continue;
        }
        if tests.iter().any(|&(a, z)| (a..z).contains(&i)) {
            continue;
        }
        let line = b[..i].iter().filter(|&&c| c == b'\n').count();
        if lines[line].contains(EXEMPT) {
            continue;
        }
        out.push((line + 1, String::from_utf8_lossy(lit).into_owned()));
    }
    out
}

/// The length of an integer literal's type suffix at the start of `s` (`u16` in `0x6040u16`).
fn suffix_len(s: &[u8]) -> usize {
    let (s, sep) = match s.strip_prefix(b"_") {
        Some(rest) => (rest, 1),
        None => (s, 0),
    };
    let n = [
        "u8", "u16", "u32", "u64", "u128", "usize", "i8", "i16", "i32", "i64", "i128", "isize",
    ]
    .iter()
    .filter(|t| s.starts_with(t.as_bytes()))
    .map(|t| t.len())
    .max()
    .unwrap_or(0);
    if n == 0 { 0 } else { sep + n }
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

#[test]
fn no_raw_object_index_outside_the_table() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut files = Vec::new();
    rust_files(&root.join("src"), &mut files);
    files.sort();
    let skip = [
        root.join("src/canopen/index.rs"),
        root.join("src/canopen/emcy.rs"),
    ];
    let mut found = Vec::new();
    for f in files
        .iter()
        .filter(|f| !skip.contains(f) && f.file_name().is_some_and(|n| n != "tests.rs"))
    {
        for (line, lit) in raw_indices(&std::fs::read_to_string(f).unwrap()) {
            found.push(format!(
                "{}:{line}: {lit}",
                f.strip_prefix(root).unwrap().display()
            ));
        }
    }
    assert!(
        found.is_empty(),
        "raw object indices; name them in src/canopen/index.rs and use the names:\n{}",
        found.join("\n")
    );
}

#[test]
fn the_scan_finds_indices_in_code_only() {
    let src = r##"
use x;
/// The statusword 0x6041, in a doc comment.
fn f(od: &Od) -> u16 {
    let s = "0x6040 in a string";
    let r = r#"0x1016 in a raw "string""#;
    let c = '"'; let l: &'static str = "";
    od.int(0x6041, 0) + od.int(0x1017, 0) // 0x1018 in a comment
}
/* 0x1000 in a block /* nested */ comment */
const COB: u16 = 0x180; const EMCY: u16 = 0x8130; const BIG: u32 = 0x1000_0000;
const POLY: u16 = 0x1021; // not an object index: a CRC polynomial
fn g() -> u16 { 0x60C2 }
#[cfg(test)]
mod tests {
    fn t() { let _ = 0x6064; }
}
fn h() -> u16 { 0x607a }
fn k() -> u16 { 0x6040u16 + 0x6041_u16 }
"##;
    let found: Vec<(usize, String)> = raw_indices(src);
    assert_eq!(
        found,
        [
            (8, "0x6041".to_string()),
            (8, "0x1017".to_string()),
            (13, "0x60C2".to_string()),
            (18, "0x607a".to_string()),
            (19, "0x6040".to_string()),
            (19, "0x6041".to_string()),
        ]
    );
}
