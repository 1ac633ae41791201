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

mod common;

use std::time::{Duration, Instant};

use criterion::{Criterion, criterion_group, criterion_main};
use viewer::{Headless, MIN_SCREENSHOT_SIZE, Model, Viewer};

/// The warehouse log, simulated, replayed and loaded.
fn warehouse() -> Model {
    let path = common::simulate_warehouse("bench-viewer").unwrap();
    let started = Instant::now();
    let model = common::load(&path).unwrap();
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

/// Durations in milliseconds.
fn ms(times: &[Duration]) -> Vec<f64> {
    times.iter().map(|d| d.as_secs_f64() * 1e3).collect()
}

fn bench(c: &mut Criterion) {
    let model = warehouse();
    let duration = model.duration_s();
    let mut headless = Headless::new(Viewer::new(model), MIN_SCREENSHOT_SIZE);
    // Warm up: fonts, plot memory, the first layout.
    for _ in 0..3 {
        headless.run_frame();
    }
    let times = common::scrub_times(duration, 400);
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
    println!(
        "{}",
        common::summary("  ui_and_tessellation", ms(&ui_times))
    );
    println!(
        "{}",
        common::summary("  software_raster", ms(&raster_times))
    );

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
