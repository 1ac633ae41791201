//! Localisation on a 10,000-lamp saved map (issue 20; target: at most 1 ms a frame on one
//! core): `cargo bench -p localize --bench localize_10k`.
//!
//! The hall of `tests/support` at the size of a large warehouse: a jittered grid of
//! 125 x 80 lamps at 2.5 m (312.5 m x 200 m), 7 m up, the map's lamps off by their 5 mm sigma,
//! the hall's rig (752x480, f = 250 px, baseline 0.12 m, 2.2 m up, pitched 0.05 rad).
//!
//! - `push_frame_localized_10k`: one frame (the five odometry samples before it, then
//!   `push_frame`) of a localiser that has fixed its position, while the vehicle drives on
//!   through the hall: the per-frame cost with the lamps in view. The frames are made
//!   outside the timing (`iter_custom`).
//! - `lamp_map_new_10k`: indexing the 10,000 lamps (the grid and the pair table
//!   `stereonav localize` builds).
//! - `reloc_frame_10k_*`: one frame of a localiser lost at the start: its first frame
//!   (`switched_on`: hypotheses generated from the pair table, each scored), its second
//!   (`scoring`: the hypotheses the first left, predicted and scored), and its fifth
//!   (`generating`: generation again, as every 4th frame while lost, and the live ones
//!   scored).
//!
//! `RELOC_TRACE=1` prints every frame of the setup's drive until the fix: the status, the
//! hypotheses (and the one nearest the truth), whether decisions wait on an incomplete
//! generation, and the last generation's look-ups.
#![allow(clippy::print_stderr, clippy::expect_used)] // a benchmark: its setup failing is a bug

#[path = "../tests/support/mod.rs"]
mod support;

use std::hint::black_box;
use std::time::{Duration, Instant};

use criterion::{BatchSize, Criterion, SamplingMode, criterion_group, criterion_main};
use localize::{LampMap, Localizer, LocalizerSettings, Status};
use rig_model::camera::Pose2;
use support::{Drive, Grid, Hall, Step, pose_error};

/// The hall's seed.
const SEED: u64 = 20;
/// Lamps along x and y.
const GRID_10K: (usize, usize) = (125, 80);

fn hall() -> Hall {
    Hall::new(Grid::jittered(GRID_10K.0, GRID_10K.1), SEED)
}

fn push(localizer: &mut Localizer, step: &Step) -> localize::FrameResult {
    for s in &step.odometry {
        localizer
            .push_odometry(*s)
            .expect("the synthetic odometry is in order");
    }
    localizer
        .push_frame(step.t_us, &step.left, &step.right)
        .expect("the synthetic frames are in order")
}

fn lamp_map_new(c: &mut Criterion) {
    let hall = hall();
    let radius = LocalizerSettings::default()
        .max_reach_m
        .min(2.0 * support::pair_radius_m(&support::rig()));
    let map = LampMap::new(hall.map.clone(), radius).expect("a valid map");
    eprintln!(
        "lamp_map_new_10k: {} lamps, {} triangles with sides up to {:.1} m",
        map.len(),
        map.triangle_count(),
        map.triangle_max_side_m()
    );
    let mut group = c.benchmark_group("map");
    group.sample_size(10);
    group.bench_function("lamp_map_new_10k", |b| {
        b.iter_batched(
            || hall.map.clone(),
            |lamps| LampMap::new(lamps, radius).expect("a valid map"),
            BatchSize::LargeInput,
        );
    });
    group.finish();
}

fn push_frame_localized(c: &mut Criterion) {
    let hall = hall();
    let mut localizer = support::localizer(hall.map.clone()).expect("a valid localiser");
    let start = Pose2::new(150.0, 100.0, 0.3);
    let mut drive = Drive::new(&hall, start, 1_000_000, SEED);
    // Until it has been localised for a second.
    let (mut frames, mut localized_run, mut fix_s) = (0_u32, 0_u32, None);
    let mut error = (f64::INFINITY, f64::INFINITY);
    while localized_run < 20 {
        let step = drive.step();
        let r = push(&mut localizer, &step);
        frames += 1;
        if std::env::var_os("RELOC_TRACE").is_some() {
            let reloc = localizer.relocalizer();
            let near = reloc
                .hypotheses()
                .iter()
                .map(|h| pose_error(&h.pose(), &step.truth).0)
                .fold(f64::INFINITY, f64::min);
            eprintln!(
                "frame {frames}: {:?}, {} observations, {} hypotheses (nearest the truth {near:.2} m), incomplete {}, last generation {:?}",
                r.status,
                r.observations,
                reloc.hypotheses().len(),
                reloc.incomplete(),
                reloc.last_generation
            );
        }
        error = r.pose.map_or(error, |p| pose_error(&p, &step.truth));
        if r.status == Status::Localized {
            fix_s.get_or_insert(f64::from(frames - 1) * 0.05);
            localized_run += 1;
        } else {
            localized_run = 0;
        }
        assert!(
            frames < 2_000,
            "the localiser did not localise on the 10,000-lamp map in 100 s"
        );
    }
    let (e, h) = error;
    eprintln!(
        "push_frame_localized_10k: fixed after {fix_s:?} s, {frames} frames in setup; error then {e:.4} m, {:.3} deg",
        h.to_degrees()
    );
    let mut timed = Stats::default();
    c.bench_function("push_frame_localized_10k", |b| {
        b.iter_custom(|iters| {
            let mut total = Duration::ZERO;
            for _ in 0..iters {
                let step = drive.step();
                let started = Instant::now();
                let r = push(&mut localizer, &step);
                let took = started.elapsed();
                total += took;
                timed.add(&step, &r, took);
                black_box(r);
            }
            total
        });
    });
    timed.report();
}

/// What the timed frames were.
#[derive(Debug, Default)]
struct Stats {
    frames: u64,
    localized: u64,
    false_fix: u64,
    matched: u64,
    expected: u64,
    in_view: u64,
    slowest: Duration,
}

impl Stats {
    fn add(&mut self, step: &Step, r: &localize::FrameResult, took: Duration) {
        self.frames += 1;
        self.in_view += step.lamps_in_view as u64;
        self.slowest = self.slowest.max(took);
        if r.status == Status::Localized {
            self.localized += 1;
            self.matched += r.matched.len() as u64;
            self.expected += r.expected as u64;
            let (e, h) = r
                .pose
                .map_or((f64::INFINITY, 0.0), |p| pose_error(&p, &step.truth));
            if e > support::FALSE_FIX_M || h > support::FALSE_FIX_RAD {
                self.false_fix += 1;
            }
        }
    }

    #[allow(clippy::cast_precision_loss)]
    fn report(&self) {
        let n = self.frames.max(1) as f64;
        let l = self.localized.max(1) as f64;
        eprintln!(
            "push_frame_localized_10k: {} frames timed ({:.0} s of driving), {:.2} % localised, {} off the truth; lamps in view {:.1}, expected {:.1}, matched {:.1} a frame; slowest frame {:?}",
            self.frames,
            n * 0.05,
            100.0 * self.localized as f64 / n,
            self.false_fix,
            self.in_view as f64 / n,
            self.expected as f64 / l,
            self.matched as f64 / l,
            self.slowest
        );
    }
}

fn reloc_frame(c: &mut Criterion) {
    let hall = hall();
    let mut localizer = support::localizer(hall.map.clone()).expect("a valid localiser");
    let start = Pose2::new(150.0, 100.0, 0.3);
    let mut drive = Drive::new(&hall, start, 1_000_000, SEED);
    // A generating frame takes seconds on this map: criterion's fewest samples, one frame each.
    let mut group = c.benchmark_group("reloc");
    group
        .sample_size(10)
        .sampling_mode(SamplingMode::Flat)
        .warm_up_time(Duration::from_millis(1))
        .measurement_time(Duration::from_secs(5));
    // Frames pushed so far; each case is the frame after its count.
    let mut pushed = 0;
    for (name, frames_before) in [
        ("reloc_frame_10k_switched_on", 0),
        ("reloc_frame_10k_scoring", 1),
        ("reloc_frame_10k_generating", 4),
    ] {
        while pushed < frames_before {
            let step = drive.step();
            push(&mut localizer, &step);
            pushed += 1;
        }
        let lost = localizer.clone();
        let step = drive.step();
        let started = Instant::now();
        let r = push(&mut localizer, &step);
        let once = started.elapsed();
        eprintln!(
            "{name}: frame {} of the run, {:?} after it; hypotheses live before it {}, after it {}; generated at it {}; {} observations; once {once:?}",
            frames_before + 1,
            r.status,
            lost.hypotheses().len(),
            r.hypotheses,
            localizer.stats().hypotheses - lost.stats().hypotheses,
            r.observations
        );
        group.bench_function(name, |b| {
            b.iter_batched(
                || lost.clone(),
                |mut l| {
                    let r = push(&mut l, &step);
                    (l, r)
                },
                BatchSize::LargeInput,
            );
        });
        pushed += 1;
    }
    group.finish();
}

criterion_group!(benches, push_frame_localized, lamp_map_new, reloc_frame);
criterion_main!(benches);
