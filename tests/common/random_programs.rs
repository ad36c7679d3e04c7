//! Random programs for the setpoint checks (`planner_limits`, `override_limits`): lines of
//! every length, rapids, arcs and helices, changing feeds, under G64, on a machine whose
//! planner keeps a quarter of each axis's acceleration and jerk for the junctions (and the
//! feed override).

use canmotion::planner::{Limits, PlannerConfig, ProfileKind};
use nalgebra::Vector3;
use proptest::prelude::*;

pub const T: f64 = 0.004;

pub fn limits() -> Limits {
    Limits {
        max_vel_mm_s: Vector3::new(200.0, 150.0, 100.0),
        max_acc_mm_s2: Vector3::new(2000.0, 1500.0, 1000.0),
        max_feed_mm_s: 200.0,
    }
}

pub fn config(profile: ProfileKind) -> PlannerConfig {
    PlannerConfig {
        period_s: T,
        corner_acc_mm_s2: 1500.0,
        path_acc_share: 0.75,
        path_acc_mm_s2: f64::INFINITY,
        max_jerk_mm_s3: Vector3::new(50_000.0, 40_000.0, 20_000.0),
        profile,
        chord_tol_mm: 0.001,
        default_tolerance_mm: 0.01,
        lookahead: 64,
        integer_periods: false,
        aux: canmotion::planner::AuxLimits::NONE,
        axis_filter_s: canmotion::planner::AXIS_FILTER_S,
    }
}

/// One move of a generated program.
#[derive(Debug, Clone)]
pub enum Move {
    /// A line by this offset, at this feed (mm/s); rapid if no feed.
    Line(Vector3<f64>, Option<f64>),
    /// An XY arc about the centre at `(cx, cy)` from the current point, turning by `turn_rad`
    /// (positive: counter-clockwise), with a Z rise, at this feed.
    Arc(f64, f64, f64, f64, f64),
}

pub fn a_move() -> impl Strategy<Value = Move> {
    let len = prop_oneof![0.001..0.05f64, 0.05..2.0f64, 2.0..40.0f64];
    let dir = (-1.0..1.0f64, -1.0..1.0f64, -0.5..0.5f64);
    let feed = prop_oneof![Just(None), (5.0..180.0f64).prop_map(Some)];
    let line = (len, dir, feed).prop_map(|(l, (x, y, z), f)| {
        let d = Vector3::new(x, y, z);
        let d = if d.norm() < 1e-3 {
            Vector3::x()
        } else {
            d.normalize()
        };
        Move::Line(d * l, f)
    });
    let arc = (
        -10.0..10.0f64,
        -10.0..10.0f64,
        -6.0..6.0f64,
        -1.0..1.0f64,
        5.0..150.0f64,
    )
        .prop_map(|(cx, cy, turn, dz, f)| Move::Arc(cx, cy, turn, dz, f));
    prop_oneof![4 => line, 1 => arc]
}

/// The program text of `moves` from the origin, under G64.
pub fn program(moves: &[Move]) -> String {
    let mut text = String::from("G21 G90 G17 G64\n");
    let mut at = Vector3::zeros();
    for m in moves {
        match *m {
            Move::Line(d, feed) => {
                at += d;
                match feed {
                    Some(f) => text.push_str(&format!(
                        "G1 X{:.6} Y{:.6} Z{:.6} F{:.3}\n",
                        at.x,
                        at.y,
                        at.z,
                        f * 60.0
                    )),
                    None => text.push_str(&format!("G0 X{:.6} Y{:.6} Z{:.6}\n", at.x, at.y, at.z)),
                }
            }
            Move::Arc(cx, cy, turn, dz, f) => {
                let (i, j) = (cx, cy);
                let r = (i * i + j * j).sqrt();
                if r < 0.5 || turn.abs() < 0.05 {
                    continue;
                }
                let centre = Vector3::new(at.x + i, at.y + j, 0.0);
                let a0 = (-j).atan2(-i);
                let a1 = a0 + turn.clamp(-6.0, 6.0);
                let end = Vector3::new(centre.x + r * a1.cos(), centre.y + r * a1.sin(), at.z + dz);
                text.push_str(&format!(
                    "{} X{:.6} Y{:.6} Z{:.6} I{:.6} J{:.6} F{:.3}\n",
                    if turn > 0.0 { "G3" } else { "G2" },
                    end.x,
                    end.y,
                    end.z,
                    i,
                    j,
                    f * 60.0
                ));
                // The interpreter ends the arc on the written end point.
                at = as_written(end, 6);
            }
        }
    }
    text.push_str("M2\n");
    text
}

/// A run of long moves joined at speed, for the parts a long move is planned in
/// (`planner_limits`' `a_long_filtered_line_accelerates_at_its_whole_acceleration_between_its_ends`): lines
/// of 3–40 mm turning by up to about 14° at each vertex (a slight rise or fall in Z too), and
/// arcs and helices tangent to them, at random feeds, under `G64 P0.05`.
#[allow(dead_code)] // not every test binary runs these
pub fn a_run_joined_at_speed() -> impl Strategy<Value = String> {
    let step = (
        0.0..1.0f64,
        -0.25..0.25f64,
        3.0..40.0f64,
        -0.1..0.1f64,
        20.0..200.0f64,
        (2.0..15.0f64, 0.3..3.0f64, any::<bool>(), -1.5..1.5f64),
    );
    prop::collection::vec(step, 2..9).prop_map(|steps| {
        let mut text = String::from("G21 G90 G17 G64 P0.05\n");
        let (mut at, mut heading) = (Vector3::zeros(), 0.0f64);
        for (kind, turn, len, slope, feed, (r, sweep, left, dz)) in steps {
            let u = Vector3::new(heading.cos(), heading.sin(), 0.0);
            if kind < 0.7 {
                heading += turn;
                let u = Vector3::new(heading.cos(), heading.sin(), slope);
                at += u * len;
                text.push_str(&format!(
                    "G1 X{:.6} Y{:.6} Z{:.6} F{:.1}\n",
                    at.x,
                    at.y,
                    at.z,
                    feed * 60.0
                ));
            } else {
                // Tangent to the last direction: the centre on its left (G3) or right (G2).
                let side = if left { 1.0 } else { -1.0 };
                let n = Vector3::new(-u.y, u.x, 0.0) * side;
                let centre = at + n * r;
                let a0 = (-n.y).atan2(-n.x);
                let a1 = a0 + side * sweep;
                let end = Vector3::new(centre.x + r * a1.cos(), centre.y + r * a1.sin(), at.z + dz);
                text.push_str(&format!(
                    "{} X{:.6} Y{:.6} Z{:.6} I{:.6} J{:.6} F{:.1}\n",
                    if left { "G3" } else { "G2" },
                    end.x,
                    end.y,
                    end.z,
                    n.x * r,
                    n.y * r,
                    feed * 60.0
                ));
                at = as_written(end, 6);
                heading += side * sweep;
            }
        }
        text.push_str("M2\n");
        text
    })
}

/// A polyline whose vertices turn a little each (`planner_limits`'
/// `a_polygon_of_slight_kinks_trades_acceleration_for_its_vertices`): chords of 0.15–4 mm
/// turning by up to about 12° each, mostly one way (a CAM curve written as sparse chords) and
/// now and then the other, a slight rise or fall in Z, at random feeds, under a bare `G64` or
/// `G64 P0.005`–`P0.05`, with now and then a sharp corner (a stop) among them.
#[allow(dead_code)] // not every test binary runs these
pub fn a_kinked_polyline() -> impl Strategy<Value = String> {
    let step = (
        0.15..4.0f64,
        0.0..0.21f64,
        0.0..1.0f64,
        -0.05..0.05f64,
        20.0..200.0f64,
    );
    (
        prop::option::of(0.005..0.05f64),
        prop::collection::vec(step, 3..40),
    )
        .prop_map(|(tolerance, steps)| {
            let mut text = match tolerance {
                Some(p) => format!("G21 G90 G17 G64 P{p:.4}\n"),
                None => String::from("G21 G90 G17 G64\n"),
            };
            let (mut at, mut heading) = (Vector3::zeros(), 0.0f64);
            for (len, turn, kind, slope, feed) in steps {
                heading += if kind < 0.85 {
                    turn
                } else if kind < 0.95 {
                    -turn
                } else {
                    1.5
                };
                at += Vector3::new(heading.cos(), heading.sin(), slope) * len;
                text.push_str(&format!(
                    "G1 X{:.4} Y{:.4} Z{:.4} F{:.1}\n",
                    at.x,
                    at.y,
                    at.z,
                    feed * 60.0
                ));
                at = as_written(at, 4);
            }
            text.push_str("M2\n");
            text
        })
}

/// `at` as a program writes it with `decimals` decimals (where the interpreter puts it).
#[allow(dead_code)] // not every test binary runs the generators that use it
fn as_written(at: Vector3<f64>, decimals: usize) -> Vector3<f64> {
    at.map(|c| format!("{c:.decimals$}").parse().unwrap())
}
