//! The candump log reader on arbitrary bytes: it must return an error (naming the line),
//! never panic, and read lines in bounded memory; a record it reads re-formats to a line that
//! reads back as the same record (what `monitor --log` writes, `monitor --replay` reads).

use crate::commands::candump::{LogReader, parse_line};

/// The log reader on `data` as a log, and each record through its line and back.
pub fn log(data: &[u8]) {
    for rec in LogReader::new("fuzz.log", data).take(10_000) {
        match rec {
            Ok(rec) => {
                let line = rec.to_string();
                let back = parse_line(&line)
                    .unwrap_or_else(|e| panic!("{line:?} does not read back: {e}"))
                    .unwrap_or_else(|| panic!("{line:?} reads back as a blank line"));
                assert_eq!(back, rec, "{line:?}");
            }
            Err(e) => {
                let _ = e.to_string();
                break;
            }
        }
    }
    // One line as given, whatever its bytes.
    if let Ok(text) = std::str::from_utf8(data) {
        let _ = parse_line(text);
    }
}
