//! The cost of one frame on real images (issue 16): the navigator fed the EuRoC standing
//! log's frames (about 400 features a camera of real texture, ../shared/data), and the same
//! frames' features laid over a warehouse drive whose map holds about 170 landmarks (a
//! textured ceiling with lamps: every frame has 400+ features a camera besides the lamps, and
//! the state is 500+ elements). Target: at most 5 ms a frame on one core.
//!
//! `cargo bench -p replay --bench real_frames` (skips, printing why, without ../shared).
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::print_stdout)]

use std::path::Path;
use std::time::{Duration, Instant};

use criterion::{Criterion, criterion_group, criterion_main};
use replay::{LogInput, NavSettings, Navigator, read_vehicle_log};

fn euroc() -> Option<LogInput> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/euroc-v101-static");
    let text = std::fs::read_to_string(dir.join("rig.toml")).ok()?;
    let rig = rig_model::config::Rig::from_toml_str(&text, "rig.toml").ok()?;
    read_vehicle_log(&dir.join("log.mcap"), Some(rig)).ok()
}

fn warehouse() -> LogInput {
    let scenario =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/scenarios/warehouse.toml");
    let sc = sim::Scenario::load(&scenario).unwrap();
    let run = sim::simulate(&sc, sim::Mode::Fast).unwrap();
    let path = std::env::temp_dir().join(format!("bench-real-{}.mcap", std::process::id()));
    run.write_log(&path).unwrap();
    let input = read_vehicle_log(&path, None).unwrap();
    std::fs::remove_file(&path).ok();
    input
}

/// Feeds frames `range` of `input` (odometry up to each frame first), timing each frame's
/// `push_frame`; `overlay` adds another log's features to each frame (cycled).
fn feed(
    nav: &mut Navigator,
    input: &LogInput,
    range: std::ops::Range<usize>,
    overlay: Option<&LogInput>,
    times: &mut Vec<Duration>,
) {
    let start_t = input.frames.get(range.start).map_or(0, |f| f.t_us);
    let mut next = input.odometry.partition_point(|s| s.t_us < start_t);
    for (k, f) in input
        .frames
        .iter()
        .enumerate()
        .take(range.end)
        .skip(range.start)
    {
        while let Some(s) = input.odometry.get(next).filter(|s| s.t_us <= f.t_us) {
            nav.push_odometry(*s).ok();
            next += 1;
        }
        let (mut left, mut right) = (f.left.clone(), f.right.clone());
        if let Some(o) = overlay.and_then(|o| o.frames.get(k % o.frames.len().max(1))) {
            left.extend_from_slice(&o.left);
            right.extend_from_slice(&o.right);
        }
        let started = Instant::now();
        nav.push_frame(f.t_us, &left, &right).ok();
        times.push(started.elapsed());
    }
}

fn summary(name: &str, times: &mut [Duration], nav: &Navigator) {
    times.sort();
    let ms = |d: Duration| d.as_secs_f64() * 1e3;
    let mean = times.iter().map(|d| ms(*d)).sum::<f64>() / times.len().max(1) as f64;
    let state = nav.ekf().map_or(0, vslam_ekf::Ekf::state_len);
    println!(
        "{name}: {} frames, per frame mean {mean:.2} ms, median {:.2} ms, 95 % {:.2} ms, max {:.2} ms; state {state}, landmarks {}",
        times.len(),
        ms(times[times.len() / 2]),
        ms(times[times.len() * 95 / 100]),
        ms(times[times.len() - 1]),
        nav.ekf().map_or(0, vslam_ekf::Ekf::landmark_count),
    );
}

fn bench(c: &mut Criterion) {
    let Some(real) = euroc() else {
        println!("real_frames: skipped, ../shared/data/euroc-v101-static is absent");
        return;
    };
    let wh = warehouse();
    let warm = 3000.min(wh.frames.len().saturating_sub(100));
    // Per-frame distributions, printed before criterion's means.
    let mut nav = Navigator::new(real.rig.clone(), NavSettings::default()).unwrap();
    let mut times = Vec::new();
    feed(&mut nav, &real, 0..real.frames.len(), None, &mut times);
    summary("euroc, whole log (no flags)", &mut times, &nav);
    // A map of several hundred landmarks from the real scene itself: no cap on the landmarks
    // in view (phase 1 skipped: its batch is capped), so that every frame updates a large state.
    let mut big = NavSettings {
        skip_phase1: true,
        ..NavSettings::default()
    };
    big.candidates.max_in_view = 1000;
    let mut nav = Navigator::new(real.rig.clone(), big).unwrap();
    let mut times = Vec::new();
    feed(&mut nav, &real, 0..real.frames.len(), None, &mut times);
    summary(
        "euroc, no cap on landmarks in view (--skip-phase1)",
        &mut times,
        &nav,
    );
    let mut nav = Navigator::new(wh.rig.clone(), NavSettings::default()).unwrap();
    feed(&mut nav, &wh, 0..warm, None, &mut Vec::new());
    let mut times = Vec::new();
    feed(&mut nav, &wh, warm..warm + 100, Some(&real), &mut times);
    summary("warehouse map + euroc texture", &mut times, &nav);

    let mut group = c.benchmark_group("real_frames");
    group.sample_size(10);
    group.bench_function("euroc_log_95_frames", |b| {
        b.iter(|| {
            let mut nav = Navigator::new(real.rig.clone(), NavSettings::default()).unwrap();
            feed(&mut nav, &real, 0..real.frames.len(), None, &mut Vec::new());
        });
    });
    let mut warmed = Navigator::new(wh.rig.clone(), NavSettings::default()).unwrap();
    feed(&mut warmed, &wh, 0..warm, None, &mut Vec::new());
    group.bench_function("warehouse_map_euroc_texture_100_frames", |b| {
        b.iter_batched(
            || warmed.clone(),
            |mut nav| {
                feed(
                    &mut nav,
                    &wh,
                    warm..warm + 100,
                    Some(&real),
                    &mut Vec::new(),
                )
            },
            criterion::BatchSize::LargeInput,
        );
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
