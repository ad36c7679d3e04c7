//! The operator's command lines on arbitrary bytes, read as the control socket and the standard
//! input keys read them ([`read_line_bounded`], bounded to [`MAX_LINE_BYTES`]): no panic, every
//! answer `ok ...` or `error: ...`, the wanted override within 0 to 200 %, and the key reader
//! going through the whole input whatever it holds.

use crate::gateway::control::{
    Control, LineRead, MAX_LINE_BYTES, MAX_REQUEST, read_keys, read_line_bounded, skip_line,
};

/// Every line of `data` answered by a control state with a run in progress, then `data` again
/// through the key reader.
pub fn lines(data: &[u8]) {
    let control = Control::new();
    control.reset(true);
    let mut input = data;
    let mut line = Vec::new();
    loop {
        line.clear();
        match read_line_bounded(&mut input, &mut line, MAX_LINE_BYTES) {
            Ok(LineRead::Line) => {
                assert!(line.len() <= MAX_LINE_BYTES);
                let answer = control.answer(&line);
                assert!(
                    answer.starts_with("ok ") || answer.starts_with("error: "),
                    "{answer}"
                );
                let (requested, _) = control.wanted();
                assert!((0.0..=MAX_REQUEST).contains(&requested), "{requested}");
            }
            Ok(LineRead::TooLong) => {
                assert_eq!(line.len(), MAX_LINE_BYTES);
                skip_line(&mut input).expect("a slice does not fail");
            }
            Ok(LineRead::Eof) => break,
            Err(e) => panic!("a slice does not fail: {e}"),
        }
    }
    let keys = Control::new();
    keys.reset(true);
    let mut report = Vec::new();
    let mut input = data;
    read_keys(&mut input, &keys, &mut report);
    assert!(input.is_empty(), "the key reader stopped before the end");
    let (requested, _) = keys.wanted();
    assert!((0.0..=MAX_REQUEST).contains(&requested), "{requested}");
}
