//! Canned cycles on arbitrary input: the bytes as a program, and a program built from the
//! bytes (cycle codes, G80, planes, distance and return modes, spindle words, and X Y Z R Q P L
//! F words with values taken from the bytes), so that most inputs reach the cycles' arithmetic
//! rather than a syntax error. The interpreter must not panic; its elements must chain, with
//! finite points and positive feeds; no line may queue more than [`MAX_CYCLE_ITEMS`] items
//! (a cycle's pecks and repeats are bounded); and the planner must accept what it yields.

use nalgebra::Vector3;

use crate::gcode::{Interpreter, Item, MAX_CYCLE_ITEMS, Setup};
use crate::planner::{Limits, plan_items};

/// The interpreter and the planner on `data` as a program, then on the program built from it.
pub fn program(data: &[u8]) {
    check(data);
    check(generate(data).as_bytes());
}

/// A program of canned-cycle lines from the bytes: per line a code, a mask of words, and one
/// byte per word for its value.
fn generate(data: &[u8]) -> String {
    const CODES: [&str; 26] = [
        "G81", "G82", "G83", "G73", "G84", "G74", "G85", "G86", "G89", "G80", "G0", "G1", "G98",
        "G99", "G90", "G91", "G17", "G18", "G19", "G20", "G21", "M3", "M4", "M5", "G93", "",
    ];
    const LETTERS: [char; 8] = ['X', 'Y', 'Z', 'R', 'Q', 'P', 'L', 'F'];
    let mut text = String::from("G21 G90 G94 F300 M3\n");
    let mut bytes = data.iter().copied();
    while let Some(b) = bytes.next() {
        text.push_str(CODES[usize::from(b) % CODES.len()]);
        let mask = bytes.next().unwrap_or(0);
        for (k, letter) in LETTERS.iter().enumerate() {
            if mask & (1 << k) == 0 {
                continue;
            }
            let v = bytes.next().unwrap_or(0);
            let value = match letter {
                // Non-negative words: small values, zero included (an error to report).
                'Q' | 'P' | 'F' => f64::from(v) / 8.0,
                'L' => f64::from(v % 5),
                _ => f64::from(v as i8) / 4.0,
            };
            text.push_str(&format!(" {letter}{value}"));
        }
        text.push('\n');
    }
    text
}

fn check(data: &[u8]) {
    let start = Vector3::new(1.0, -2.0, 3.0);
    let mut position = start;
    let mut items = Vec::new();
    let (mut line, mut on_line) = (0, 0);
    for item in Interpreter::new(data, "fuzz.ngc", Setup::new(start)).take(5000) {
        let item = match item {
            Ok(item) => item,
            Err(e) => {
                let _ = e.to_string();
                break;
            }
        };
        if let Item::Motion(e) = &item {
            assert_eq!(e.start_mm, position, "elements must chain");
            assert!(e.end_mm.iter().all(|c| c.is_finite()));
            assert_eq!(e.rapid, e.feed_mm_s.is_none());
            if let Some(f) = e.feed_mm_s {
                assert!(f.is_finite() && f > 0.0, "feed {f}");
            }
            position = e.end_mm;
            if e.line == line {
                on_line += 1;
                assert!(
                    on_line <= MAX_CYCLE_ITEMS + 8,
                    "line {line} queues too much"
                );
            } else {
                (line, on_line) = (e.line, 1);
            }
        }
        items.push(item);
    }
    let limits = Limits {
        max_vel_mm_s: Vector3::new(500.0, 500.0, 200.0),
        max_acc_mm_s2: Vector3::new(5000.0, 5000.0, 2000.0),
        max_feed_mm_s: 500.0,
    };
    if let Ok(plan) = plan_items(start, &items, &limits) {
        let _ = plan.position_at(plan.duration_s() * 0.5);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn generated_programs_reach_the_cycles() {
        // G98 G81, then words X (2), Z (-2), R (1), F (1): a whole drilling line.
        let text = generate(&[12, 0, 0, 0b1000_1101, 8, 0xF8, 4, 8]);
        assert_eq!(text, "G21 G90 G94 F300 M3\nG98\nG81 X2 Z-2 R1 F1\n");
        let p = crate::gcode::parse_program(&text, "t", Vector3::zeros()).unwrap();
        assert_eq!(p.elements().count(), 4);
    }
}
