//! Bodies of the fuzz targets, shared by `fuzz/` (libFuzzer: `cargo fuzz run NAME`) and by the
//! seeded short runs of `tests/fuzz_smoke.rs`, which put every target through a few thousand
//! mutated inputs in the ordinary test suite.
//!
//! Each body takes arbitrary bytes, feeds them to one parser or loader, and panics only where an
//! invariant a user relies on breaks (a parser must return an error, never panic). [`Mutator`]
//! is the suite's input generator: deterministic from a seed, it mutates real files (the
//! repository's dictionaries, programs, logs) byte- and line-wise, so that the short run reaches
//! past the first syntax check.

pub mod candump;
pub mod control;
pub mod cycles;
pub mod eds;
pub mod gcode;
pub mod machine;
pub mod subroutines;

/// A deterministic generator of fuzz inputs from seed files (xorshift64*; no dependency).
#[derive(Debug, Clone)]
pub struct Mutator {
    state: u64,
}

impl Mutator {
    /// A generator whose sequence depends only on `seed`.
    pub fn new(seed: u64) -> Mutator {
        Mutator {
            state: seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1,
        }
    }

    /// The next pseudo-random number.
    pub fn next_u64(&mut self) -> u64 {
        let mut x = self.state;
        x ^= x >> 12;
        x ^= x << 25;
        x ^= x >> 27;
        self.state = x;
        x.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }

    /// A number in `0..n` (`n > 0`).
    pub fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n.max(1) as u64) as usize
    }

    /// One input: a seed (or nothing) with 1 to 8 mutations: byte flips, interesting bytes
    /// (`\0`, `\r`, `\n`, `=`, `[`, `]`, `"`, `#`, `-`, digits, 0xFF), deletions, duplications of
    /// a span, lines swapped or repeated, splices of two seeds.
    pub fn mutate(&mut self, seeds: &[&[u8]]) -> Vec<u8> {
        const INTERESTING: &[u8] = b"\0\r\n=[]\"#-.09eE+ \t\xff\x80{}:,";
        let mut data: Vec<u8> = if seeds.is_empty() || self.below(16) == 0 {
            (0..self.below(64)).map(|_| self.next_u64() as u8).collect()
        } else {
            seeds[self.below(seeds.len())].to_vec()
        };
        for _ in 0..1 + self.below(8) {
            let len = data.len();
            match self.below(8) {
                0 if len > 0 => {
                    let i = self.below(len);
                    data[i] ^= 1 << self.below(8);
                }
                1 if len > 0 => {
                    let i = self.below(len);
                    data[i] = INTERESTING[self.below(INTERESTING.len())];
                }
                2 => {
                    let i = self.below(len + 1);
                    data.insert(i, INTERESTING[self.below(INTERESTING.len())]);
                }
                3 if len > 0 => {
                    let i = self.below(len);
                    let n = 1 + self.below((len - i).min(32));
                    data.drain(i..i + n);
                }
                4 if len > 0 => {
                    let i = self.below(len);
                    let n = 1 + self.below((len - i).min(64));
                    let span: Vec<u8> = data[i..i + n].to_vec();
                    let at = self.below(len + 1);
                    data.splice(at..at, span);
                }
                5 | 6 => {
                    // Whole lines: swap two, or repeat one.
                    let mut lines: Vec<Vec<u8>> =
                        data.split(|b| *b == b'\n').map(<[u8]>::to_vec).collect();
                    let n = lines.len();
                    let (a, b) = (self.below(n), self.below(n));
                    if self.below(2) == 0 {
                        lines.swap(a, b);
                    } else {
                        let l = lines[a].clone();
                        lines.insert(b, l);
                    }
                    data = lines.join(&b'\n');
                }
                7 if !seeds.is_empty() => {
                    let other = seeds[self.below(seeds.len())];
                    let cut = self.below(data.len() + 1);
                    let from = self.below(other.len() + 1);
                    data.truncate(cut);
                    data.extend_from_slice(&other[from..]);
                }
                _ => {}
            }
        }
        data
    }
}

/// Runs `body` on `cases` inputs mutated from `seeds` (and on each seed as it is), from the
/// generator's `seed`. A panic names the case so that it can be replayed.
pub fn run_seeded(seeds: &[&[u8]], cases: usize, seed: u64, body: impl Fn(&[u8])) {
    for s in seeds {
        body(s);
    }
    let mut m = Mutator::new(seed);
    for case in 0..cases {
        let data = m.mutate(seeds);
        let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| body(&data)));
        if let Err(p) = r {
            eprintln!(
                "fuzz case {case} (seed {seed}) panicked on {} bytes: {:?}",
                data.len(),
                String::from_utf8_lossy(&data[..data.len().min(400)])
            );
            std::panic::resume_unwind(p);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_mutator_is_deterministic_and_changes_its_input() {
        let seeds: &[&[u8]] = &[b"G1 X10 Y20\nG0 Z5\n", b"[bus]\ninterface = \"sim\"\n"];
        let a: Vec<Vec<u8>> = {
            let mut m = Mutator::new(7);
            (0..50).map(|_| m.mutate(seeds)).collect()
        };
        let b: Vec<Vec<u8>> = {
            let mut m = Mutator::new(7);
            (0..50).map(|_| m.mutate(seeds)).collect()
        };
        assert_eq!(a, b);
        assert!(a.iter().filter(|d| !seeds.contains(&d.as_slice())).count() > 40);
    }
}
