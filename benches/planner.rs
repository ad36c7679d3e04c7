//! Planning throughput (issue 4): segments per second of the look-ahead alone (the items are
//! interpreted beforehand), and of the whole front end (parse + compensate + plan), on
//! LinuxCNC's `performance/circle_small_segments_ncd.ngc` (when `../shared/corpus` is present)
//! and on a generated program of 1,000,000 tiny segments, with the demo machine's planner in
//! trapezoid and S-curve mode.
//!
//! `cargo bench --bench planner`

use std::hint::black_box;
use std::io::BufReader;
use std::path::Path;

use canmotion::compensation::{CompOptions, Compensator};
use canmotion::config::Machine;
use canmotion::gateway::limits;
use canmotion::gcode::{Interpreter, Item};
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

/// Plans every item of `items`; returns the number of segments.
fn plan_all<'a>(
    items: impl Iterator<Item = std::borrow::Cow<'a, Item>>,
    machine: &Machine,
    config: &PlannerConfig,
) -> usize {
    let mut p = Planner::with_config(Vector3::zeros(), &limits(machine), config).unwrap();
    let mut n = 0;
    for item in items {
        p.push(&item).unwrap();
        n += p.drain().map(black_box).count();
    }
    p.finish().unwrap();
    n + p.drain().map(black_box).count()
}

/// The look-ahead alone, on items interpreted beforehand.
fn plan(items: &[Item], machine: &Machine, config: &PlannerConfig) -> usize {
    plan_all(
        items.iter().map(std::borrow::Cow::Borrowed),
        machine,
        config,
    )
}

/// Parse, compensate and plan the whole text.
fn front_end(text: &str, machine: &Machine, config: &PlannerConfig) -> usize {
    let interp = Interpreter::new(
        BufReader::new(text.as_bytes()),
        "bench.ngc",
        canmotion::gcode::Setup::new(Vector3::zeros()),
    );
    let items = Compensator::new(interp, "bench.ngc", CompOptions::default())
        .map(|i| std::borrow::Cow::Owned(i.unwrap()));
    plan_all(items, machine, config)
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
        for profile in [ProfileKind::Trapezoid, ProfileKind::SCurve] {
            let config = PlannerConfig {
                profile,
                ..machine.planner
            };
            let n = plan(&its, &machine, &config);
            g.throughput(Throughput::Elements(n as u64));
            g.bench_function(
                format!("look-ahead {name} {profile:?} ({n} segments)"),
                |b| b.iter(|| plan(black_box(&its), &machine, &config)),
            );
            g.bench_function(format!("parse+compensate+plan {name} {profile:?}"), |b| {
                b.iter(|| front_end(black_box(text), &machine, &config))
            });
        }
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
