//! Planning throughput (issue 4): segments per second of the look-ahead alone (the items are
//! interpreted beforehand), of the whole front end (parse + compensate + plan), and of the
//! whole pipeline up to the setpoints (parse + compensate + plan + interpolate: every cycle of
//! the program sampled as `run` streams it), on
//! LinuxCNC's `performance/circle_small_segments_ncd.ngc` (when `../shared/corpus` is present)
//! and on a generated program of 1,000,000 tiny segments, with the demo machine's planner in
//! trapezoid and S-curve mode.
//!
//! Each program's duration is printed first, for the ratio of the time it runs to the time the
//! pipeline takes.
//!
//! The front end alone (parse + compensate, no planning) is timed too, in source lines per
//! second.
//!
//! `cargo bench --bench planner`

use std::hint::black_box;
use std::io::BufReader;
use std::path::Path;

use canmotion::compensation::{CompOptions, Compensator};
use canmotion::config::Machine;
use canmotion::gateway::limits;
use canmotion::gcode::{Interpreter, Item};
use canmotion::interpolator::{Interpolator, Status};
use canmotion::planner::{Planner, PlannerConfig, ProfileKind};
use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use nalgebra::Vector3;

/// A spiral of `n` chords of about 20 µm at 50 mm/s (G64), inside the demo machine's travel.
fn tiny_segments(n: usize) -> String {
    let mut text = String::with_capacity(n * 24);
    text.push_str("G21 G90 G17 G64\nG0 X50 Y50 Z0\nF3000\n");
    for k in 1..=n {
        let a = k as f64 * 0.002;
        let r = 10.0 + (k % 2000) as f64 * 0.0005;
        text.push_str(&format!(
            "G1 X{:.4} Y{:.4}\n",
            50.0 + r * a.cos(),
            50.0 + r * a.sin()
        ));
    }
    text.push_str("M2\n");
    text
}

fn items(text: &str) -> Vec<Item> {
    Interpreter::new(
        BufReader::new(text.as_bytes()),
        "bench.ngc",
        canmotion::gcode::Setup::new(Vector3::zeros()),
    )
    .map(|i| i.expect("the program interprets"))
    .collect()
}

/// Plans every item of `items`; returns the number of segments. With `sample`, every segment
/// goes on to an interpolator at the machine's cycle, which samples all it can as it comes.
fn plan_all<'a>(
    items: impl Iterator<Item = std::borrow::Cow<'a, Item>>,
    machine: &Machine,
    config: &PlannerConfig,
    sample: bool,
) -> usize {
    let mut p = Planner::with_config(Vector3::zeros(), &limits(machine), config).unwrap();
    let mut interp = Interpolator::streaming(Vector3::zeros(), machine.cycle_s()).unwrap();
    let mut at = Vector3::zeros();
    let mut n = 0;
    let mut take = |p: &mut Planner, interp: &mut Interpolator| {
        let mut n = 0;
        for seg in p.drain() {
            n += 1;
            if sample {
                interp.push(seg).unwrap();
                while !interp.needs_segments() {
                    if interp.update(&mut at) == Status::Finished {
                        break;
                    }
                    black_box(&at);
                }
            } else {
                black_box(seg);
            }
        }
        n
    };
    for item in items {
        p.push(&item).unwrap();
        n += take(&mut p, &mut interp);
    }
    p.finish().unwrap();
    n += take(&mut p, &mut interp);
    if sample {
        interp.close();
        while interp.update(&mut at) != Status::Finished {
            black_box(&at);
        }
    }
    n
}

/// The look-ahead alone, on items interpreted beforehand.
fn plan(items: &[Item], machine: &Machine, config: &PlannerConfig) -> usize {
    plan_all(
        items.iter().map(std::borrow::Cow::Borrowed),
        machine,
        config,
        false,
    )
}

/// Parse, compensate and plan the whole text (and sample it, with `sample`).
fn front_end(text: &str, machine: &Machine, config: &PlannerConfig, sample: bool) -> usize {
    let interp = Interpreter::new(
        BufReader::new(text.as_bytes()),
        "bench.ngc",
        canmotion::gcode::Setup::new(Vector3::zeros()),
    );
    let items = Compensator::new(interp, "bench.ngc", CompOptions::default())
        .map(|i| std::borrow::Cow::Owned(i.unwrap()));
    plan_all(items, machine, config, sample)
}

/// Parse and compensate the whole text, without planning; returns the number of items.
fn parse_compensate(text: &str) -> usize {
    let interp = Interpreter::new(
        BufReader::new(text.as_bytes()),
        "bench.ngc",
        canmotion::gcode::Setup::new(Vector3::zeros()),
    );
    Compensator::new(interp, "bench.ngc", CompOptions::default()).fold(0, |n, i| {
        black_box(i.unwrap());
        n + 1
    })
}

fn bench(c: &mut Criterion) {
    let machine = Machine::demo();
    let mut programs = vec![("tiny-1M".to_string(), tiny_segments(1_000_000))];
    let corpus = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/corpus/linuxcnc-tp/performance/circle_small_segments_ncd.ngc");
    match std::fs::read_to_string(&corpus) {
        Ok(text) => programs.push(("circle_small_segments_ncd".to_string(), text)),
        Err(_) => println!("{} is absent: skipping it", corpus.display()),
    }
    let mut g = c.benchmark_group("planner");
    g.sample_size(10);
    for (name, text) in &programs {
        let its = items(text);
        // Throughput in source lines: the front end's own measure, independent of the profile.
        let lines = text.lines().count();
        g.throughput(Throughput::Elements(lines as u64));
        g.bench_function(format!("parse+compensate {name} ({lines} lines)"), |b| {
            b.iter(|| parse_compensate(black_box(text)))
        });
        for profile in [ProfileKind::Trapezoid, ProfileKind::SCurve] {
            let config = PlannerConfig {
                profile,
                ..machine.planner
            };
            let n = plan(&its, &machine, &config);
            let duration_s = {
                let mut p =
                    Planner::with_config(Vector3::zeros(), &limits(&machine), &config).unwrap();
                its.iter().for_each(|i| p.push(i).unwrap());
                p.finish().unwrap();
                p.time_s()
            };
            println!("{name} {profile:?}: {n} segments, the program runs {duration_s:.1} s");
            g.throughput(Throughput::Elements(n as u64));
            g.bench_function(
                format!("look-ahead {name} {profile:?} ({n} segments)"),
                |b| b.iter(|| plan(black_box(&its), &machine, &config)),
            );
            g.bench_function(format!("parse+compensate+plan {name} {profile:?}"), |b| {
                b.iter(|| front_end(black_box(text), &machine, &config, false))
            });
            g.bench_function(
                format!("parse+compensate+plan+interpolate {name} {profile:?}"),
                |b| b.iter(|| front_end(black_box(text), &machine, &config, true)),
            );
        }
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
