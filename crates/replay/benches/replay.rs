//! Replay speed: the whole stack (read, decode, order, navigator, truth errors) on the three
//! committed paper logs and on a freshly simulated warehouse log, against the data's duration.
//! Targets: the paper scenarios at least 100x real time, the warehouse at least 20x.
//!
//! `cargo bench -p replay --bench replay` (prints the real-time factors before criterion's
//! timings).
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::print_stdout)]

use std::path::{Path, PathBuf};
use std::time::Instant;

use criterion::{Criterion, criterion_group, criterion_main};
use replay::{NavSettings, replay_log};

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/logs")
        .join(name)
}

/// The warehouse log, simulated once (fast mode, seed of the scenario file).
fn warehouse_log() -> PathBuf {
    let scenario =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/scenarios/warehouse.toml");
    let sc = sim::Scenario::load(&scenario).unwrap();
    let run = sim::simulate(&sc, sim::Mode::Fast).unwrap();
    let path = std::env::temp_dir().join(format!("bench-warehouse-{}.mcap", std::process::id()));
    run.write_log(&path).unwrap();
    path
}

fn cases() -> Vec<(&'static str, PathBuf, NavSettings)> {
    let skip = NavSettings {
        skip_phase1: true,
        ..NavSettings::default()
    };
    let fast = NavSettings::default();
    vec![
        ("paper_experiment", fixture("paper-experiment.mcap"), skip),
        ("paper_square", fixture("paper-square.mcap"), skip),
        (
            "paper_calibration",
            fixture("paper-calibration.mcap"),
            NavSettings::default(),
        ),
        ("warehouse", warehouse_log(), fast),
    ]
}

fn bench(c: &mut Criterion) {
    let cases = cases();
    for (name, path, settings) in &cases {
        // One timed run first, for the real-time factor.
        let started = Instant::now();
        let r = replay_log(path, None, settings, &mut |_, _| {}).unwrap();
        let took = started.elapsed().as_secs_f64();
        let span = match (r.frames.first(), r.frames.last()) {
            (Some(a), Some(b)) => (b.t_us - a.t_us) as f64 * 1e-6,
            _ => 0.0,
        };
        println!(
            "{name}: {} frames, {span:.1} s of data in {took:.3} s: {:.0}x real time, {} landmarks",
            r.frames.len(),
            span / took,
            r.landmarks.len()
        );
    }
    let mut group = c.benchmark_group("replay");
    group.sample_size(10);
    for (name, path, settings) in &cases {
        group.bench_function(*name, |b| {
            b.iter(|| replay_log(path, None, settings, &mut |_, _| {}).unwrap());
        });
    }
    group.finish();
    if let Some((_, path, _)) = cases.last() {
        std::fs::remove_file(path).ok();
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
