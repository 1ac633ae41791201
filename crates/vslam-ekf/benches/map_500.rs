//! A 500-lamp map (1504 states: pose, 500 lamps, f and the baseline): one frame's update with
//! 5 and with 10 lamps in view, in each covariance form. Target: at most 5 ms on one core.
//!
//! `cargo bench -p vslam-ekf --bench map_500`
// Benchmarks set up known-good data: a failure is a bug to see at once, as in the tests.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::Vector3;
use rig_model::camera::{CameraParams, Mount, N_PARAMS, Param, Pose2};
use rig_model::config::{Noise, Rig};
use rig_model::{Measurement, project};
use vslam_ekf::{CovarianceUpdate, Ekf, LandmarkId, Settings};

const LAMPS: usize = 500;

fn rig() -> Rig {
    let mut prior = [None; N_PARAMS];
    prior[Param::F.index()] = Some(20.0);
    prior[Param::Baseline.index()] = Some(0.006);
    Rig {
        lens: None,
        board: rig_model::Board::DEFAULT,
        width: 752,
        height: 480,
        nominal: CameraParams {
            vehicle: Default::default(),
            f: 700.0,
            cx: 376.0,
            cy: 240.0,
            baseline: 0.12,
            mount: Mount {
                z: 0.8,
                pitch: 0.2,
                ..Mount::default()
            },
        },
        estimate: vec![Param::F, Param::Baseline],
        prior,
        noise: Noise::white(0.3, 0.02, 0.01),
    }
}

/// 500 lamps spread over the view from the origin (the update's cost depends only on the
/// state size and the lamps observed), mixed by a prediction and an update.
fn filter() -> (Ekf, Vec<(LandmarkId, Measurement)>) {
    let rig = rig();
    let c = rig.nominal;
    let mut ekf = Ekf::from_prior(&rig, Settings::default()).expect("valid rig");
    let mut all = Vec::with_capacity(LAMPS);
    for k in 0..LAMPS {
        #[allow(clippy::cast_precision_loss)]
        let (i, j, d) = ((k % 25) as f64, ((k / 25) % 20) as f64, (k % 7) as f64);
        let (u, v, depth) = (30.0 + 28.0 * i, 30.0 + 21.0 * j, 2.0 + 0.3 * d);
        let p_rig = Vector3::new(
            (u - c.cx) * depth / c.f - c.baseline / 2.0,
            (v - c.cy) * depth / c.f,
            depth,
        );
        let p = c.mount.translation() + c.mount.robot_from_rig_rotation() * p_rig;
        let z = project(&c, &Pose2::default(), &p).expect("in view");
        let id = ekf.add_landmark(&z).expect("adds");
        all.push((id, z));
    }
    ekf.predict(0.0, 0.0, 0.0, 0.1).expect("predicts");
    let first: Vec<_> = all.iter().step_by(50).copied().collect();
    ekf.update(&first).expect("updates");
    (ekf, all)
}

fn bench(c: &mut Criterion) {
    let (base, all) = filter();
    assert_eq!(base.state_len(), 3 + 3 * LAMPS + 2);
    let mut group = c.benchmark_group("map_500");
    group.sample_size(30);
    for form in [
        CovarianceUpdate::Joseph,
        CovarianceUpdate::Factored,
        CovarianceUpdate::Auto,
    ] {
        for seen in [5, 10] {
            let mut ekf = base.clone();
            ekf.set_covariance_update(form);
            let mut next = 0;
            group.bench_function(format!("update_{seen}_{form:?}").to_lowercase(), |b| {
                b.iter(|| {
                    // A different set of lamps every frame, spread over the map.
                    let batch: Vec<_> = (0..seen).map(|k| all[(next + 37 * k) % LAMPS]).collect();
                    next = (next + 1) % LAMPS;
                    let report = ekf.update(black_box(&batch)).expect("updates");
                    black_box(report.accepted.len())
                });
            });
            assert_eq!(ekf.landmark_count(), LAMPS, "no landmark lost to the gate");
        }
    }
    let mut ekf = base.clone();
    group.bench_function("predict", |b| {
        b.iter(|| {
            ekf.predict(black_box(0.0), 0.0, 0.0, 0.05)
                .expect("predicts")
        });
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
