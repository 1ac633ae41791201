//! The simulator's speed against real time.
//!
//! * `warehouse_fast`: the whole `warehouse` scenario (236.8 s of driving, 4736 stereo
//!   frames, 23,700 odometry samples) in fast mode, log written to memory: needs to be at
//!   least 200x real time, that is under 1.18 s.
//! * `rendered_frame`: one stereo frame of the warehouse in rendered mode (both images drawn
//!   with sensor noise, the board's detector run on both, on one thread): needs 20 frames
//!   per second, that is under 50 ms (`simulate` spreads frames over the cores besides).
//! * `warehouse_rendered_67_frames`: a whole rendered run of 67 frames (3.3 s of driving), on all cores.
//!
//! `cargo bench -p sim --bench simulate`

#![allow(clippy::unwrap_used, clippy::expect_used)] // a bench that cannot load its scenario fails

use std::hint::black_box;
use std::io::Cursor;
use std::path::Path;
use std::time::Duration;

use criterion::{Criterion, criterion_group, criterion_main};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

fn warehouse() -> sim::Scenario {
    let path =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/scenarios/warehouse.toml");
    sim::Scenario::load(&path).unwrap()
}

fn bench(c: &mut Criterion) {
    let scenario = warehouse();
    let mut group = c.benchmark_group("sim");
    group
        .sample_size(10)
        .measurement_time(Duration::from_secs(10));
    group.bench_function("warehouse_fast", |b| {
        b.iter(|| {
            let run = sim::simulate(&scenario, sim::Mode::Fast).unwrap();
            black_box(run.write_log_to(Cursor::new(Vec::new())).unwrap())
        });
    });
    let run = sim::simulate(&scenario, sim::Mode::Fast).unwrap();
    let regs = scenario.registers();
    let renderer = sim::Renderer::new(
        scenario.true_camera(),
        &regs,
        scenario.spec.render,
        run.landmarks.clone(),
    );
    let poses: Vec<rig_model::Pose2> = run.frames.iter().step_by(37).map(|f| f.pose).collect();
    let mut k = 0;
    group.bench_function("rendered_frame", |b| {
        b.iter(|| {
            k = (k + 1) % poses.len();
            let mut left = ChaCha8Rng::seed_from_u64(k as u64);
            let mut right = ChaCha8Rng::seed_from_u64(k as u64 + 1);
            let images = renderer.render(&poses[k], Some((&mut left, &mut right)));
            let l = harris_core::detect(&images.left, &regs).unwrap();
            let r = harris_core::detect(&images.right, &regs).unwrap();
            black_box((l, r))
        });
    });
    let mut short = scenario.clone();
    short.spec.path.segments.truncate(2);
    short.spec.path.segments[0] = sim::scenario::Segment::wait(0.2);
    short.spec.path.segments[1] = sim::scenario::Segment::straight(1.2);
    short.spec.path.repeat = 1;
    let frames = sim::simulate(&short, sim::Mode::Fast).unwrap().frames.len();
    assert_eq!(frames, 67);
    group.bench_function("warehouse_rendered_67_frames", |b| {
        b.iter(|| black_box(sim::simulate(&short, sim::Mode::Rendered).unwrap()));
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
