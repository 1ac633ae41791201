//! One phase-1 solve: 5 landmarks over 200 frame pairs (the 2 ms target).
//!
//! `cargo bench -p selfcal --bench selfcal`

use criterion::{Criterion, criterion_group, criterion_main};
use rig_model::camera::Param;
use rig_model::config::Rig;
use selfcal::solve::{SolverSettings, calibrate};

#[path = "../tests/integration/common/mod.rs"]
mod common;

/// The synthetic data of the phase-1 tests: tilted head, turns, nominal f and baseline off by
/// a few percent, 200 frame pairs of five lamps.
fn data() -> (Rig, Vec<rig_model::handover::FramePair>) {
    let truth = common::synthetic::true_camera(0.3);
    let mut nominal = truth;
    nominal.f = 680.0;
    nominal.baseline = 0.118;
    let rig = common::synthetic::rig(nominal, &[Param::F, Param::Baseline]);
    (
        rig,
        common::synthetic::pairs_with(&truth, 0.3, 1, 201, true),
    )
}

fn bench(c: &mut Criterion) {
    let (rig, pairs) = data();
    let settings = SolverSettings::default();
    c.bench_function("selfcal_5_landmarks_200_pairs_f_baseline", |b| {
        b.iter(|| calibrate(&pairs, &rig, &rig.nominal, &settings));
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
