//! The paper's 19-element filter (pose, five lamps, the baseline): one prediction and one
//! update with all five lamps, the per-frame work of phase 2. Target: at most 10 us.
//!
//! `cargo bench -p vslam-ekf --bench step_19`
// Benchmarks set up known-good data: a failure is a bug to see at once, as in the tests.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::Vector3;
use rig_model::camera::{CameraParams, Mount, N_PARAMS, Param, Pose2};
use rig_model::config::{Noise, Rig};
use rig_model::{Measurement, project};
use vslam_ekf::{CovarianceUpdate, Ekf, LandmarkId, Settings};

fn rig() -> Rig {
    let mut prior = [None; N_PARAMS];
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
                ..Mount::default()
            },
        },
        estimate: vec![Param::Baseline],
        prior,
        noise: Noise::white(0.3, 0.02, 0.01),
    }
}

/// The paper experiment's five lamps seen from the origin, in the filter.
fn filter(form: CovarianceUpdate) -> (Ekf, Vec<(LandmarkId, Measurement)>) {
    let rig = rig();
    let settings = Settings {
        covariance_update: form,
        ..Settings::default()
    };
    let mut ekf = Ekf::from_prior(&rig, settings).expect("valid rig");
    let lamps = [
        Vector3::new(-0.05, 0.20, 3.30),
        Vector3::new(0.60, -0.25, 3.10),
        Vector3::new(1.25, 0.30, 3.55),
        Vector3::new(0.90, -0.15, 3.20),
        Vector3::new(0.25, 0.10, 3.45),
    ];
    let mut batch = Vec::new();
    for l in lamps {
        let z = project(&rig.nominal, &Pose2::default(), &l).expect("in view");
        let id = ekf.add_landmark(&z).expect("adds");
        batch.push((id, z));
    }
    (ekf, batch)
}

fn bench(c: &mut Criterion) {
    for (name, form) in [
        ("step_19", CovarianceUpdate::Auto),
        ("step_19_factored", CovarianceUpdate::Factored),
    ] {
        let (mut ekf, batch) = filter(form);
        assert_eq!(ekf.state_len(), 19);
        let mut sign = 1.0;
        c.bench_function(name, |b| {
            b.iter(|| {
                // Back and forth, so that the fixed measurements stay consistent.
                sign = -sign;
                ekf.predict(sign * 0.01, 0.0, sign * 0.002, 0.05)
                    .expect("predicts");
                let report = ekf.update(black_box(&batch)).expect("updates");
                black_box(report.accepted.len())
            });
        });
        assert_eq!(ekf.landmark_count(), 5, "no landmark lost to the gate");
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
