//! Scrubbing the warehouse log in the viewer. Target: no frame over 50 ms while scrubbing.
//!
//! The warehouse log (fast mode, the scenario's seed) is simulated, replayed with
//! `pairs.stride = 10` and loaded into the viewer once; then the viewer draws frames at a
//! fixed 1280x800 headless, at a new time each frame, as a slider dragged back and forth does:
//!
//! - `ui_and_tessellation`: one egui pass of the whole viewer (the frame lookup, the image
//!   marks recomputed for the new frame, the map, the plots) and the tessellation of its shapes
//!   into triangles: everything the CPU does for a frame in the window, short of handing the
//!   triangles to OpenGL;
//! - `software_raster`: the same frame rasterised on the CPU (what a screenshot costs; a GPU
//!   or llvmpipe does this part in the window).
//!
//! Before criterion's timings it prints the worst, the 99th percentile and the mean over a
//! scrub of 400 positions (`cargo bench -p viewer --bench scrub`), and what the frames ask of
//! a software OpenGL renderer ([`viewer::fill_estimate`]: deterministic, unlike frame times in
//! a window). Whole frames in a real window: `examples/window_scrub.rs`.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::print_stdout)]

use std::path::Path;
use std::time::{Duration, Instant};

use criterion::{Criterion, criterion_group, criterion_main};
use replay::NavSettings;
use viewer::{Headless, LoadOptions, MIN_SCREENSHOT_SIZE, Model, Viewer};

/// The warehouse log, simulated, replayed and loaded.
fn warehouse() -> Model {
    let scenario =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/scenarios/warehouse.toml");
    let sc = sim::Scenario::load(&scenario).unwrap();
    let run = sim::simulate(&sc, sim::Mode::Fast).unwrap();
    let path = std::env::temp_dir().join(format!("bench-viewer-{}.mcap", std::process::id()));
    run.write_log(&path).unwrap();
    let mut settings = NavSettings::default();
    settings.pairs.stride = 10;
    let started = Instant::now();
    let model = viewer::load(
        &path,
        &LoadOptions {
            rig: None,
            settings,
        },
        &mut |_, _| {},
    )
    .unwrap();
    println!(
        "warehouse: {} frames, {:.1} s, {} landmarks, {} features; replayed and loaded in {:.2} s",
        model.replay.frames.len(),
        model.duration_s(),
        model.replay.landmarks.len(),
        model.features.points.len(),
        started.elapsed().as_secs_f64()
    );
    std::fs::remove_file(&path).ok();
    model
}

/// `n` times sweeping the log forward then back, as a slider dragged to and fro.
fn scrub_times(duration_s: f64, n: usize) -> Vec<f64> {
    (0..n)
        .map(|i| {
            let phase = (i as f64 / n as f64) * 2.0;
            let x = if phase <= 1.0 { phase } else { 2.0 - phase };
            // An irrational step so that consecutive positions land on different frames.
            (x * duration_s + i as f64 * 0.618_034).rem_euclid(duration_s.max(1e-9))
        })
        .collect()
}

fn summary(name: &str, mut times: Vec<Duration>) {
    times.sort();
    let ms = |d: Duration| d.as_secs_f64() * 1e3;
    let mean = times.iter().map(|d| ms(*d)).sum::<f64>() / times.len().max(1) as f64;
    let p99 = times
        .get(times.len() * 99 / 100)
        .copied()
        .unwrap_or_default();
    let worst = times.last().copied().unwrap_or_default();
    println!(
        "{name}: {} frames, mean {mean:.2} ms, 99th percentile {:.2} ms, worst {:.2} ms",
        times.len(),
        ms(p99),
        ms(worst)
    );
}

fn bench(c: &mut Criterion) {
    let model = warehouse();
    let duration = model.duration_s();
    let mut headless = Headless::new(Viewer::new(model), MIN_SCREENSHOT_SIZE);
    // Warm up: fonts, plot memory, the first layout.
    for _ in 0..3 {
        headless.run_frame();
    }
    let times = scrub_times(duration, 400);
    let mut ui_times = Vec::with_capacity(times.len());
    let mut raster_times = Vec::with_capacity(times.len());
    let mut fill: Vec<viewer::FillEstimate> = Vec::with_capacity(times.len());
    for t in &times {
        headless.viewer_mut().set_time(*t);
        let started = Instant::now();
        headless.run_frame();
        ui_times.push(started.elapsed());
        fill.extend(headless.fill_estimate());
        let started = Instant::now();
        std::hint::black_box(headless.render());
        raster_times.push(started.elapsed());
    }
    let most = |f: fn(&viewer::FillEstimate) -> f64| fill.iter().map(f).fold(0.0, f64::max);
    let mean = |f: fn(&viewer::FillEstimate) -> f64| {
        fill.iter().map(f).sum::<f64>() / fill.len().max(1) as f64
    };
    println!(
        "scrubbing the warehouse at 1280x800: triangles a frame mean {:.0}, most {:.0}; \
         pixels of the 4x4 blocks they touch (software OpenGL's fill) mean {:.2} M, most {:.2} M \
         ({:.2} M pixels covered on average)",
        mean(|e| e.triangles as f64),
        most(|e| e.triangles as f64),
        mean(|e| e.block_pixels) / 1e6,
        most(|e| e.block_pixels) / 1e6,
        mean(|e| e.covered_pixels) / 1e6,
    );
    summary("  ui_and_tessellation", ui_times);
    summary("  software_raster", raster_times);

    let mut group = c.benchmark_group("scrub_warehouse_1280x800");
    group.sample_size(20);
    let mut k = 0usize;
    group.bench_function("ui_and_tessellation", |b| {
        b.iter(|| {
            k = (k + 1) % times.len();
            headless
                .viewer_mut()
                .set_time(times.get(k).copied().unwrap_or(0.0));
            headless.run_frame()
        });
    });
    group.bench_function("software_raster", |b| {
        b.iter(|| headless.render());
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
