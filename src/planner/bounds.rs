//! Reference times to judge a plan by (issue 11's acceptance): what no planner can beat on a
//! path, and what a jerk-limited plan may cost over the trapezoid one.
//!
//! Pure functions of the items, the limits and a finished [`Plan`]; the planner never calls
//! them. `examples/corpus_times.rs` (`tools/corpus-times.sh`) and `tests/chorded_curves.rs`
//! do.
//!
//! Units in names: `_mm` millimetres, `_mm_s` mm/s, `_mm_s2` mm/s², `_mm_s3` mm/s³, `_s`
//! seconds, `_per_mm` curvature.
//!
//! # The curvature bound `T_lb`
//!
//! `T_lb = ∫ ds / v_cap(s)` over the tool-centre path, with
//! `v_cap = min(F, √(A/κ), (J/κ²)^(1/3))`:
//!
//! - `F`: the programmed feed clamped to `max_feed_mm_s` (rapids at `max_feed_mm_s`), and each
//!   axis's speed, `v·|u_i| ≤ max_vel_i`, along the direction of travel `u`;
//! - `κ`: the curvature. An arc has `1/r`, a helix of radius `r` and pitch `2πc` has
//!   `r/(r² + c²)`, not the `1/r` of its projected circle. A polyline (chords, as CAM writes a
//!   curve) has at each vertex between two lines the discrete curvature `θ / ((L₁ + L₂)/2)`
//!   (`θ` the turn angle, `L₁`, `L₂` the chords either side), applied over the half-chords
//!   either side of the vertex;
//! - `A`, `J`: the acceleration and jerk the axes allow in the plane the path turns in: the
//!   smallest `max_acc_i / p_i` and `max_jerk_i / p_i`, with `p_i` the share of axis `i` in that
//!   plane (`√(1 − b_i²)` for the binormal `b`; on a helix the planner's share
//!   `p_i + n_i·sin α`). A path turning in the XY plane of a machine with equal X and Y limits
//!   thus has `A = max_acc_x` all round, and a full circle of radius `r` at a feed `F` above the
//!   caps takes `2πr / min(√(A·r), (J·r²)^(1/3))`. Where the path reverses (`θ = π`) it turns
//!   in no plane: `A` and `J` are then those along `u`.
//!
//! Following a curve at speed `v` takes the centripetal acceleration `v²κ` and the jerk
//! `v³κ²` (at least: a helix's torsion adds to it), so no plan within those limits runs faster
//! anywhere; the bound ignores the time to change speed, which is what makes it a bound.
//!
//! # Exact stops and `T_ref`
//!
//! A jerk-limited start from rest to a cruise speed `v` takes `A/J` longer than the
//! trapezoid's (its acceleration ramps up and down in `A/J` each), and so does the stop: a run
//! from rest to rest costs `A/J` over its trapezoid plan, half at each end. Over the distance
//! the S-curve takes to reach `v` (in `t_s`, covering `v·t_s/2` by symmetry) the trapezoid
//! reaches `v` in `v/A` and cruises, so the end costs `(t_s − v/A)/2`: `A/(2J)` when
//! `v ≥ A²/J` (`t_s = v/A + A/J`), and `√(v/J) − v/(2A)` below, where the acceleration never
//! reaches `A` (`t_s = 2√(v/J)`). [`exact_stops`] counts the runs: the moving segments of the
//! trapezoid plan that start at rest (the first one, and one after each G61/G61.1 stop,
//! M0/M1, dwell or reversal), and adds for each [`run_cost_s`] at the highest speed of the run,
//! `A` and `J` along its starting direction. `T_ref = max(T_lb, T_trapezoid + Σ cost)`
//! ([`reference_time_s`]): `A/J` per exact stop, as issue 11 states it, for every run that
//! reaches `A²/J` (80 mm/s on the demo machine), less for the slower ones.
//!
//! That derivation assumes the S-curve reaches the trapezoid's peak. A run of one segment too
//! short for that (the trapezoid a triangle, the S-curve reaching neither its peak nor `A`)
//! costs more: a 1 mm move with `A = 1500 mm/s²` and `J = 37 500 mm/s³` takes `2√(L/A)` =
//! 51.6 ms as a trapezoid and `4·(L/2J)^⅓` = 94.9 ms as the time-optimal S-curve, 43.2 ms
//! more, beyond `A/J` = 40 ms. Such a run is charged at least its exact cost
//! (`lone_run_cost_s`: the time-optimal S-curve from rest to rest with the trapezoid's
//! limits and the machine's `J/A`, as the jerk-limited mode plans a move alone), so `T_ref`
//! stays what a jerk-limited plan cannot beat. Runs of several segments keep the estimate
//! above.

use nalgebra::Vector3;

use super::profile::{self, JerkShape, ProfileLimits};
use super::{Limits, Plan, PlannerConfig, Segment, SegmentPath};
use crate::gcode::{ArcGeometry, Element, Item};

/// Curvature below this is straight (a turn of 1e-12 rad per mm).
const STRAIGHT_PER_MM: f64 = 1e-12;

/// The curvature bound `T_lb` of `items` (elements; dwells, stops, notes and the end add
/// nothing) under `limits` and `config`'s jerk limits (see the module documentation). Lines
/// of zero length are skipped; the vertex between the lines either side of them is a vertex.
pub fn curvature_bound_s<'a>(
    items: impl IntoIterator<Item = &'a Item>,
    limits: &Limits,
    config: &PlannerConfig,
) -> f64 {
    let mut total_s = 0.0;
    // The previous line: its direction, length, cap and the curvature at its start, waiting
    // for the vertex at its end.
    let mut prev: Option<PendingLine> = None;
    for item in items {
        let Item::Motion(e) = item else {
            continue;
        };
        let feed_mm_s = feed_mm_s(e, limits);
        match e.arc() {
            Some(arc) if arc.length_mm > 0.0 => {
                if let Some(p) = prev.take() {
                    total_s += p.time_s_with(Vertex::STRAIGHT, limits, config);
                }
                total_s += arc_time_s(&arc, feed_mm_s, limits, config);
            }
            _ => {
                let d = e.end_mm - e.start_mm;
                let length_mm = d.norm();
                if !(length_mm > 0.0 && length_mm.is_finite()) {
                    continue;
                }
                let u = d / length_mm;
                let cap_mm_s = feed_mm_s.min(axis_speed_cap(&u, limits));
                let mut kappa_start = Vertex::STRAIGHT;
                if let Some(p) = prev.take() {
                    let vertex = Vertex::between(&p.u, p.length_mm, &u, length_mm);
                    total_s += p.time_s_with(vertex, limits, config);
                    kappa_start = vertex;
                }
                prev = Some(PendingLine {
                    u,
                    length_mm,
                    cap_mm_s,
                    start: kappa_start,
                });
            }
        }
    }
    if let Some(p) = prev {
        total_s += p.time_s_with(Vertex::STRAIGHT, limits, config);
    }
    total_s
}

/// The runs from rest of a plan and what a jerk-limited plan pays for them
/// ([`exact_stops`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExactStops {
    /// Moving segments that start at rest (the first one included).
    pub count: usize,
    /// What a jerk-limited plan pays for the runs they start, summed: [`run_cost_s`], and for
    /// a run of one segment at least its exact cost (`lone_run_cost_s`).
    pub cost_s: f64,
}

/// What a jerk-limited run from rest to rest with the highest speed `v_mm_s` costs over the
/// trapezoid's with the acceleration `acc` (the module documentation derives it): `A/J` from
/// `v = A²/J` on, `2√(v/J) − v/A` below (which rises to `A/J` there); 0 without a jerk limit.
pub fn run_cost_s(v_mm_s: f64, acc_mm_s2: f64, jerk_mm_s3: f64) -> f64 {
    if !(jerk_mm_s3.is_finite() && v_mm_s > 0.0) {
        return 0.0;
    }
    if v_mm_s >= acc_mm_s2 * acc_mm_s2 / jerk_mm_s3 {
        acc_mm_s2 / jerk_mm_s3
    } else {
        (2.0 * (v_mm_s / jerk_mm_s3).sqrt() - v_mm_s / acc_mm_s2).max(0.0)
    }
}

/// The moving segments of `plan` that start at rest, i.e. at a speed of at most one period's
/// acceleration (`A·T`, with `A` along the segment's direction and `T` = `config.period_s`):
/// a trapezoid plan passes a reversal at such a speed rather than at exactly 0. Each starts a
/// run that ends where the next one starts (or at the plan's end); see the module
/// documentation for its cost.
pub fn exact_stops(plan: &Plan, limits: &Limits, config: &PlannerConfig) -> ExactStops {
    let mut stops = ExactStops {
        count: 0,
        cost_s: 0.0,
    };
    // The run under way: its highest speed, and A and J at its start.
    let mut run: Option<(f64, f64, f64)> = None;
    // Its moving segments so far, and the first of them.
    let mut run_segments = 0usize;
    let mut first: Option<&Segment> = None;
    let run_cost = |run: Option<(f64, f64, f64)>, segments: usize, first: Option<&Segment>| {
        run.map_or(0.0, |(v, acc, jerk)| {
            let lone = first.filter(|_| segments == 1);
            run_cost_s(v, acc, jerk).max(lone.map_or(0.0, |seg| lone_run_cost_s(seg, acc, jerk)))
        })
    };
    for seg in plan.segments() {
        let u = match &seg.path {
            SegmentPath::Line { direction } => *direction,
            SegmentPath::Arc(arc) => arc.tangent_at(0.0),
            SegmentPath::Dwell | SegmentPath::Stop { .. } => continue,
        };
        if seg.profile.is_none() || seg.length_mm.is_nan() || seg.length_mm <= 0.0 {
            continue;
        }
        let acc_mm_s2 = along(&u, &limits.max_acc_mm_s2).min(config.path_acc_mm_s2);
        if seg.v_start_mm_s <= acc_mm_s2 * config.period_s {
            stops.cost_s += run_cost(run.take(), run_segments, first);
            stops.count += 1;
            run = Some((0.0, acc_mm_s2, along(&u, &config.max_jerk_mm_s3)));
            (run_segments, first) = (0, Some(seg));
        }
        if let Some(r) = run.as_mut() {
            r.0 = r.0.max(seg.v_peak_mm_s);
            run_segments += 1;
        }
    }
    stops.cost_s += run_cost(run, run_segments, first);
    stops
}

/// What the time-optimal jerk-limited profile of a run of one segment, from rest to rest,
/// takes beyond the trapezoid's: with the trapezoid's speed and acceleration limits and the
/// jerk `a·J/A` (the machine's `J/A` along the segment, `acc_mm_s2` and `jerk_mm_s3`), as the
/// jerk-limited mode plans such a move ([`run_cost_s`] assumes the S-curve reaches the
/// trapezoid's peak; over a move too short for that it takes longer). 0 where the segment
/// has no profile. The segment ends at rest: the next run starts there, or the plan ends.
fn lone_run_cost_s(seg: &Segment, acc_mm_s2: f64, jerk_mm_s3: f64) -> f64 {
    let Some(trapezoid) = seg.profile else {
        return 0.0;
    };
    let limits = trapezoid.limits();
    if !jerk_mm_s3.is_finite() {
        return 0.0;
    }
    let jerk = limits.a_max_mm_s2() * jerk_mm_s3 / acc_mm_s2;
    ProfileLimits::new(
        limits.v_max_mm_s(),
        limits.a_max_mm_s2(),
        jerk,
        JerkShape::Square,
    )
    .and_then(|l| profile::plan(seg.length_mm, 0.0, 0.0, &l))
    .map_or(0.0, |s| (s.duration_s() - trapezoid.duration_s()).max(0.0))
}

/// `T_ref = max(T_lb, T_trapezoid + Σ run cost)`: the time a jerk-limited plan of a program should
/// take at most, from its curvature bound `t_lb_s` ([`curvature_bound_s`]), its trapezoid
/// plan's time and that plan's exact stops ([`exact_stops`]).
pub fn reference_time_s(t_lb_s: f64, trapezoid_s: f64, stops: &ExactStops) -> f64 {
    t_lb_s.max(trapezoid_s + stops.cost_s)
}

/// A line waiting for the vertex at its end.
struct PendingLine {
    u: Vector3<f64>,
    length_mm: f64,
    cap_mm_s: f64,
    start: Vertex,
}

impl PendingLine {
    /// Its time: the first half under the start vertex's cap, the second under the end's
    /// (straight where the next element is an arc, or there is none).
    fn time_s_with(&self, end: Vertex, limits: &Limits, config: &PlannerConfig) -> f64 {
        let half_mm = 0.5 * self.length_mm;
        half_mm / self.start.cap_mm_s(self.cap_mm_s, &self.u, limits, config)
            + half_mm / end.cap_mm_s(self.cap_mm_s, &self.u, limits, config)
    }
}

/// A polyline vertex: its discrete curvature and the plane it turns in.
#[derive(Debug, Clone, Copy)]
struct Vertex {
    kappa_per_mm: f64,
    /// Unit binormal (`u₁ × u₂`); `None` at a reversal or where it does not turn.
    binormal: Option<Vector3<f64>>,
}

impl Vertex {
    const STRAIGHT: Vertex = Vertex {
        kappa_per_mm: 0.0,
        binormal: None,
    };

    fn between(u1: &Vector3<f64>, l1_mm: f64, u2: &Vector3<f64>, l2_mm: f64) -> Vertex {
        let cross = u1.cross(u2);
        // atan2 keeps small turns exact, where acos(u₁·u₂) loses them to rounding.
        let theta = cross.norm().atan2(u1.dot(u2));
        let kappa_per_mm = theta / (0.5 * (l1_mm + l2_mm));
        let n = cross.norm();
        Vertex {
            kappa_per_mm,
            binormal: (n > 1e-12).then(|| cross / n),
        }
    }

    /// The speed cap on a half-chord next to this vertex, `feed_cap` on a line along `u`.
    fn cap_mm_s(
        &self,
        feed_cap_mm_s: f64,
        u: &Vector3<f64>,
        limits: &Limits,
        config: &PlannerConfig,
    ) -> f64 {
        if self.kappa_per_mm.is_nan() || self.kappa_per_mm <= STRAIGHT_PER_MM {
            return feed_cap_mm_s;
        }
        let share = match self.binormal {
            Some(b) => b.map(|b_i| (1.0 - b_i * b_i).max(0.0).sqrt()),
            None => u.map(f64::abs),
        };
        curve_cap_mm_s(feed_cap_mm_s, self.kappa_per_mm, &share, limits, config)
    }
}

/// `min(feed, √(A/κ), (J/κ²)^(1/3))`, with `A` and `J` the axes' limits over their `share` of
/// the plane of the turn.
fn curve_cap_mm_s(
    feed_cap_mm_s: f64,
    kappa_per_mm: f64,
    share: &Vector3<f64>,
    limits: &Limits,
    config: &PlannerConfig,
) -> f64 {
    let acc_mm_s2 = along(share, &limits.max_acc_mm_s2);
    let jerk_mm_s3 = along(share, &config.max_jerk_mm_s3);
    feed_cap_mm_s
        .min((acc_mm_s2 / kappa_per_mm).sqrt())
        .min((jerk_mm_s3 / (kappa_per_mm * kappa_per_mm)).cbrt())
}

/// The smallest `limit_i / |share_i|` (infinite where no axis has a share).
fn along(share: &Vector3<f64>, limit: &Vector3<f64>) -> f64 {
    (0..3)
        .filter(|&i| share[i].abs() > 0.0)
        .map(|i| limit[i] / share[i].abs())
        .fold(f64::INFINITY, f64::min)
}

/// The programmed feed, clamped to the machine's; rapids at the machine's.
fn feed_mm_s(e: &Element, limits: &Limits) -> f64 {
    match e.feed_mm_s {
        Some(f) if !e.rapid && f > 0.0 => f.min(limits.max_feed_mm_s),
        _ => limits.max_feed_mm_s,
    }
}

/// Each axis's speed along `u`.
fn axis_speed_cap(u: &Vector3<f64>, limits: &Limits) -> f64 {
    along(u, &limits.max_vel_mm_s)
}

/// Pieces an arc whose radius changes (a spiral) is integrated over.
const SPIRAL_PIECES: usize = 64;

/// `∫ ds / v_cap` over an arc or helix.
fn arc_time_s(arc: &ArcGeometry, feed_mm_s: f64, limits: &Limits, config: &PlannerConfig) -> f64 {
    // The shares of the planner's arc limits: p_i in the arc's plane, n_i along its axis.
    let sin_a = arc.helix_sin();
    let cos_a = (1.0 - sin_a * sin_a).max(0.0).sqrt();
    let mut speed_share = Vector3::zeros();
    let mut acc_share = Vector3::zeros();
    for i in 0..3 {
        let n_i = arc.normal[i].abs().min(1.0);
        let p_i = (1.0 - n_i * n_i).max(0.0).sqrt();
        speed_share[i] = (p_i * cos_a + n_i * sin_a).min(1.0);
        acc_share[i] = (p_i + n_i * sin_a).min(1.0);
    }
    let feed_cap_mm_s = feed_mm_s.min(along(&speed_share, &limits.max_vel_mm_s));
    // Rise per radian: the pitch over 2π.
    let c_mm = if arc.sweep_rad > 0.0 {
        arc.helix_mm / arc.sweep_rad
    } else {
        0.0
    };
    let cap_at = |r_mm: f64| {
        let kappa_per_mm = r_mm / (r_mm * r_mm + c_mm * c_mm);
        curve_cap_mm_s(feed_cap_mm_s, kappa_per_mm, &acc_share, limits, config)
    };
    if arc.start_radius_mm == arc.end_radius_mm {
        return arc.length_mm / cap_at(arc.start_radius_mm);
    }
    // Midpoint rule over equal pieces of the sweep (the radius is linear in it).
    let piece_mm = arc.length_mm / SPIRAL_PIECES as f64;
    (0..SPIRAL_PIECES)
        .map(|k| {
            let s = (k as f64 + 0.5) / SPIRAL_PIECES as f64;
            let r_mm = arc.start_radius_mm + s * (arc.end_radius_mm - arc.start_radius_mm);
            piece_mm / cap_at(r_mm)
        })
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gcode::{BlendMode, CompState, ElementKind, Plane};

    fn limits() -> Limits {
        Limits {
            max_vel_mm_s: Vector3::new(200.0, 200.0, 100.0),
            max_acc_mm_s2: Vector3::new(2000.0, 2000.0, 1000.0),
            max_feed_mm_s: 200.0,
        }
    }

    fn config() -> PlannerConfig {
        PlannerConfig {
            max_jerk_mm_s3: Vector3::new(50_000.0, 50_000.0, 20_000.0),
            ..PlannerConfig::exact_stop()
        }
    }

    fn line(from: Vector3<f64>, to: Vector3<f64>, feed_mm_s: f64) -> Item {
        Item::Motion(Element {
            line: 1,
            col: 1,
            kind: ElementKind::Line,
            rapid: false,
            start_mm: from,
            end_mm: to,
            aux: Default::default(),
            feed_mm_s: Some(feed_mm_s),
            blend: BlendMode::ExactPath,
            comp: CompState::Off,
            plane: Plane::Xy,
        })
    }

    #[test]
    fn a_run_costs_a_over_j_once_it_reaches_full_acceleration_and_less_below() {
        let (a, j) = (2000.0, 50_000.0);
        // A²/J = 80 mm/s.
        assert!((run_cost_s(80.0, a, j) - a / j).abs() < 1e-15);
        assert_eq!(run_cost_s(150.0, a, j), a / j);
        // 20 mm/s: 2·√(20/50000) − 20/2000 = 0.03.
        assert!((run_cost_s(20.0, a, j) - 0.03).abs() < 1e-15);
        assert_eq!(run_cost_s(20.0, a, f64::INFINITY), 0.0);
    }

    /// Runs start at the start, after a reversal, a dwell and an M0, not at a straight
    /// junction; each costs what its highest speed (10 mm/s, below A²/J) makes it.
    #[test]
    fn exact_stops_count_the_runs_from_rest_of_a_trapezoid_plan() {
        let x = |v: f64| Vector3::new(v, 0.0, 0.0);
        let blend = |item: Item| match item {
            Item::Motion(mut e) => {
                e.blend = BlendMode::Blend {
                    p_mm: 0.0,
                    q_mm: 0.0,
                };
                Item::Motion(e)
            }
            other => other,
        };
        let items = [
            blend(line(x(0.0), x(10.0), 10.0)),
            blend(line(x(10.0), x(0.0), 10.0)),
            Item::Dwell(crate::gcode::Dwell {
                line: 3,
                col: 1,
                seconds: 0.5,
            }),
            blend(line(x(0.0), x(5.0), 10.0)),
            blend(line(x(5.0), x(10.0), 10.0)),
            Item::Stop(crate::gcode::Stop {
                line: 6,
                col: 1,
                optional: false,
            }),
            blend(line(x(10.0), x(20.0), 10.0)),
        ];
        let config = PlannerConfig {
            period_s: 0.001,
            corner_acc_mm_s2: 2000.0,
            path_acc_share: 0.75,
            ..config()
        };
        let plan = super::super::plan_items_with(Vector3::zeros(), &items, &limits(), &config)
            .expect("plans");
        let stops = exact_stops(&plan, &limits(), &config);
        assert_eq!(stops.count, 4);
        // The run of two lines costs `run_cost_s` at its peak (10 mm/s, below A²/J); the
        // three of one line each what their S-curve from rest to rest takes beyond their
        // trapezoid with its limits (1500 mm/s², and the jerk 1500·J/A = 37 500 mm/s³):
        // `2·√(v/J) − v/A` at the same cruise (the trapezoid passes the reversal at up to
        // `A·T`, not 0, and is up to a period the shorter there).
        let run = run_cost_s(10.0, 2000.0, 50_000.0);
        let lone = 2.0 * (10.0f64 / 37_500.0).sqrt() - 10.0 / 1500.0;
        assert!(lone > run);
        let expected = run + 3.0 * lone;
        assert!(
            stops.cost_s >= expected - 1e-12 && stops.cost_s < expected + 1e-3,
            "{stops:?}, expected {expected}"
        );
    }

    #[test]
    fn a_move_too_short_to_reach_its_trapezoid_s_peak_costs_its_exact_s_curve() {
        // 1 mm along X from rest to rest: the trapezoid (1500 mm/s² with the share) peaks at
        // √(L·A) = 38.7 mm/s in 2·√(L/A); the S-curve (37 500 mm/s³) reaches neither that
        // peak nor A, in 4·(L/2J)^⅓. It costs more than A/J over the trapezoid, and more
        // than `run_cost_s` at the trapezoid's peak says.
        let config = PlannerConfig {
            period_s: 0.001,
            path_acc_share: 0.75,
            ..config()
        };
        let items = [line(Vector3::zeros(), Vector3::new(1.0, 0.0, 0.0), 100.0)];
        let plan = super::super::plan_items_with(Vector3::zeros(), &items, &limits(), &config)
            .expect("plans");
        let stops = exact_stops(&plan, &limits(), &config);
        assert_eq!(stops.count, 1);
        let trapezoid_s = plan.duration_s();
        assert!((trapezoid_s - 2.0 * (1.0f64 / 1500.0).sqrt()).abs() < 1e-9);
        let s_curve_s = 4.0 * (1.0f64 / (2.0 * 37_500.0)).cbrt();
        assert!(
            (stops.cost_s - (s_curve_s - trapezoid_s)).abs() < 1e-9,
            "{stops:?} against {}",
            s_curve_s - trapezoid_s
        );
        assert!(stops.cost_s > 2000.0 / 50_000.0);
        assert!(stops.cost_s > run_cost_s((1500.0f64).sqrt(), 2000.0, 50_000.0));
    }

    #[test]
    fn a_straight_line_runs_at_its_feed_or_its_axes_speed() {
        let x = line(Vector3::zeros(), Vector3::new(100.0, 0.0, 0.0), 50.0);
        assert!((curvature_bound_s([&x], &limits(), &config()) - 2.0).abs() < 1e-12);
        // Z alone: 100 mm/s, whatever the max feed.
        let z = line(Vector3::zeros(), Vector3::new(0.0, 0.0, -100.0), 1000.0);
        assert!((curvature_bound_s([&z], &limits(), &config()) - 1.0).abs() < 1e-12);
    }

    #[test]
    fn a_helix_is_capped_by_its_own_curvature() {
        // r = 1, pitch 2π·1 per turn (c = 1): κ = 1/2, not 1.
        let e = Item::Motion(Element {
            line: 1,
            col: 1,
            kind: ElementKind::Arc {
                center_mm: Vector3::new(0.0, 0.0, 0.0),
                normal: Vector3::z(),
                cw: false,
                turns: 0,
                radius_mm: 1.0,
            },
            rapid: false,
            start_mm: Vector3::new(1.0, 0.0, 0.0),
            end_mm: Vector3::new(-1.0, 0.0, std::f64::consts::PI),
            aux: Default::default(),
            feed_mm_s: Some(200.0),
            blend: BlendMode::ExactPath,
            comp: CompState::Off,
            plane: Plane::Xy,
        });
        let Item::Motion(el) = &e else { unreachable!() };
        let arc = el.arc().expect("arc");
        // 45° helix: the Z axis has the share sin α·1 = 0.707 of the acceleration, X and Y 1.
        let acc = 2000.0f64.min(1000.0 / std::f64::consts::FRAC_1_SQRT_2);
        let jerk = 50_000.0f64.min(20_000.0 / std::f64::consts::FRAC_1_SQRT_2);
        let kappa = 0.5;
        // Z's speed: v·sin α ≤ 100.
        let v = (100.0 / std::f64::consts::FRAC_1_SQRT_2)
            .min((acc / kappa).sqrt())
            .min((jerk / (kappa * kappa)).cbrt());
        let t = curvature_bound_s([&e], &limits(), &config());
        assert!((t - arc.length_mm / v).abs() < 1e-9 * t, "{t}");
    }

    #[test]
    fn a_square_corner_of_chords_pays_its_discrete_curvature_over_the_half_chords() {
        let (a, b, c) = (
            Vector3::zeros(),
            Vector3::new(1.0, 0.0, 0.0),
            Vector3::new(1.0, 1.0, 0.0),
        );
        let items = [line(a, b, 200.0), line(b, c, 200.0)];
        let kappa = std::f64::consts::FRAC_PI_2;
        let v = 200f64
            .min((2000.0 / kappa).sqrt())
            .min((50_000.0 / (kappa * kappa)).cbrt());
        let expected = 1.0 / 200.0 + 1.0 / v;
        let t = curvature_bound_s(&items, &limits(), &config());
        assert!((t - expected).abs() < 1e-12, "{t} vs {expected}");
    }
}
