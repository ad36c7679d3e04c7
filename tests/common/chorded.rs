//! Chorded curves, as CAM writes them (issue 11's acceptance): circles and ellipses of radius
//! 0.5–50 mm as polylines of 10–50 µm chords, coordinates with 4 decimals.
//!
//! A curve starts at `(a, 0, 0)`, the point the interpreter is given as its start, so the
//! program is the curve alone (no approach move), run for a number of laps long enough that
//! the start and the stop weigh little against the time along the curve.

use std::fmt::Write;

use nalgebra::Vector3;

/// An ellipse `(a cos θ, b sin θ)` in the XY plane (a circle when `a = b`), counter-clockwise.
#[derive(Debug, Clone)]
pub struct ChordedCurve {
    /// Semi-axis along X.
    pub a_mm: f64,
    /// Semi-axis along Y.
    pub b_mm: f64,
    /// Mean chord length: the polyline has `ceil(perimeter / chord)` chords per lap, at equal
    /// steps of θ (on an ellipse they are longer near the ends of the minor axis).
    pub chord_mm: f64,
    /// Laps.
    pub laps: u32,
    /// Programmed feed (the F word is in mm/min).
    pub feed_mm_s: f64,
    /// The `G64 P` tolerance the program is written with.
    pub tolerance_mm: f64,
}

impl ChordedCurve {
    /// A name for messages: `circle r10 c30um x8` or `ellipse 5x2 c20um x10`.
    pub fn name(&self) -> String {
        let shape = if self.a_mm == self.b_mm {
            format!("circle r{}", self.a_mm)
        } else {
            format!("ellipse {}x{}", self.a_mm, self.b_mm)
        };
        format!(
            "{shape} c{}um x{}",
            (self.chord_mm * 1e3).round(),
            self.laps
        )
    }

    /// Chords per lap.
    pub fn chords_per_lap(&self) -> usize {
        (self.perimeter_mm() / self.chord_mm).ceil() as usize
    }

    /// Length of the first chord (exact vertices), as long as the last one.
    pub fn first_chord_mm(&self) -> f64 {
        let theta = std::f64::consts::TAU / self.chords_per_lap() as f64;
        (self.a_mm * (theta.cos() - 1.0)).hypot(self.b_mm * theta.sin())
    }

    /// Perimeter (Ramanujan's second approximation; exact for a circle).
    pub fn perimeter_mm(&self) -> f64 {
        let (a, b) = (self.a_mm, self.b_mm);
        let h = ((a - b) / (a + b)).powi(2);
        std::f64::consts::PI * (a + b) * (1.0 + 3.0 * h / (10.0 + (4.0 - 3.0 * h).sqrt()))
    }

    /// The start point, as written (`decimals`, or exact for `None`).
    pub fn start_mm(&self, decimals: Option<usize>) -> Vector3<f64> {
        Vector3::new(round(self.a_mm, decimals), 0.0, 0.0)
    }

    /// The program: G21 G90 G17, `G64 P<tolerance>`, the feed, one G1 per chord, M2.
    /// Coordinates with `decimals` decimals (4 as CAM writes them), or exact (shortest
    /// round-trip form) for `None`: then the polyline's vertices lie on the curve.
    pub fn program(&self, decimals: Option<usize>) -> String {
        let n = self.chords_per_lap();
        let mut out = String::with_capacity(24 * n * self.laps as usize + 64);
        let _ = writeln!(
            out,
            "G21 G90 G17 G64 P{} F{}",
            self.tolerance_mm,
            self.feed_mm_s * 60.0
        );
        for _ in 0..self.laps {
            for k in 1..=n {
                // The last vertex of a lap is the start again, bit for bit.
                let theta = if k == n {
                    0.0
                } else {
                    std::f64::consts::TAU * k as f64 / n as f64
                };
                let (x, y) = (self.a_mm * theta.cos(), self.b_mm * theta.sin());
                let _ = writeln!(out, "G1 X{} Y{}", fmt(x, decimals), fmt(y, decimals));
            }
        }
        out.push_str("M2\n");
        out
    }

    /// The same curve in the XZ plane (G18): the program of [`program`](Self::program) with
    /// Z for Y. Z is the demo machine's slower axis (half X's acceleration, 40 % of its jerk),
    /// so the rules that share the axes' budgets must tell them apart.
    #[allow(dead_code)] // not every test binary runs the XZ curves
    pub fn program_xz(&self, decimals: Option<usize>) -> String {
        self.program(decimals)
            .replacen("G17", "G18", 1)
            .replace(" Y", " Z")
    }

    /// The set the acceptance runs: circles of radius 0.5, 2, 10 and 50 mm and two ellipses,
    /// with chords of 10 to 50 µm, at 200 mm/s (above the curvature caps of the small ones on
    /// the demo machine) under `G64 P0.01`; each curve about 3 s of motion at its bound.
    pub fn acceptance_set() -> Vec<ChordedCurve> {
        let curve = |a_mm, b_mm, chord_um: f64, laps| ChordedCurve {
            a_mm,
            b_mm,
            chord_mm: chord_um * 1e-3,
            laps,
            feed_mm_s: 200.0,
            tolerance_mm: 0.01,
        };
        vec![
            curve(0.5, 0.5, 10.0, 25),
            curve(2.0, 2.0, 20.0, 15),
            curve(10.0, 10.0, 30.0, 8),
            curve(50.0, 50.0, 50.0, 2),
            curve(5.0, 2.0, 20.0, 10),
            curve(50.0, 20.0, 50.0, 2),
        ]
    }
}

fn round(v: f64, decimals: Option<usize>) -> f64 {
    match decimals {
        Some(d) => fmt(v, Some(d)).parse().unwrap_or(v),
        None => v,
    }
}

fn fmt(v: f64, decimals: Option<usize>) -> String {
    let s = match decimals {
        Some(d) => format!("{v:.d$}"),
        None => format!("{v}"),
    };
    // "-0.0000" is 0.
    if s.trim_start_matches('-')
        .trim_matches(|c| c == '0' || c == '.')
        .is_empty()
    {
        "0".into()
    } else {
        s
    }
}
