//! `CameraUpdate::Consider` (Schmidt-Kalman): the update equals the dense Joseph-form update
//! with the gain's camera rows set to zero; the camera parameters and their covariance stay as
//! they were, the rest is updated and carries the camera's uncertainty.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use crate::common;

use common::*;
use nalgebra::{DMatrix, DVector};
use rig_model::Measurement;
use rig_model::project;
use vslam_ekf::{CameraUpdate, Ekf, LandmarkId, Settings};

fn consider() -> Settings {
    Settings {
        camera_update: CameraUpdate::Consider,
        ..Settings::default()
    }
}

/// The dense Schmidt update: `K` with zero camera rows, Joseph form.
fn dense_schmidt(ekf: &Ekf, batch: &[(LandmarkId, Measurement)]) -> (DVector<f64>, DMatrix<f64>) {
    let n = ekf.state_len();
    let k = batch.len();
    let mut h = DMatrix::zeros(4 * k, n);
    let mut nu = DVector::zeros(4 * k);
    for (j, (id, z)) in batch.iter().enumerate() {
        let (zhat, hj) = ekf.update_jacobian(*id).unwrap();
        h.view_mut((4 * j, 0), (4, n)).copy_from(&hj);
        nu.rows_mut(4 * j, 4).copy_from(&(z - zhat));
    }
    let p = &ekf.covariance();
    let r = DMatrix::identity(4 * k, 4 * k) * ekf.noise().pixel.powi(2);
    let s = &h * p * h.transpose() + &r;
    let mut gain = p * h.transpose() * s.try_inverse().unwrap();
    for param in ekf.estimated_parameters() {
        let i = ekf.camera_state_index(*param).unwrap();
        gain.row_mut(i).fill(0.0);
    }
    let i_kh = DMatrix::identity(n, n) - &gain * &h;
    let p_new = &i_kh * p * i_kh.transpose() + &gain * r * gain.transpose();
    let mut x_new = ekf.state() + gain * nu;
    x_new[2] = wrap(x_new[2]);
    (x_new, p_new)
}

fn measure(s: &Setup, rng: &mut TestRng, id: LandmarkId) -> (LandmarkId, Measurement) {
    let p = s.points.iter().find(|(i, _)| *i == id).unwrap().1;
    (
        id,
        noisy(rng, &project(&s.truth, &s.pose, &p).unwrap(), 0.3),
    )
}

/// One landmark at a time (the small state's sequential path) and a batch of ten on a map
/// large enough for the batch path: both equal the dense Schmidt update.
#[test]
fn the_update_equals_the_dense_schmidt_update() {
    for (seed, landmarks, batch_size) in [(1u64, 4usize, 1usize), (2, 6, 1), (3, 40, 10)] {
        // The linearisation points held (they follow the estimates by default, the covariance
        // sheared with them: no textbook update does).
        let settings = Settings {
            follow_points: false,
            ..consider()
        };
        let mut s = setup(300 + seed, 2, landmarks, settings);
        let mut rng = rng(seed);
        let ids: Vec<LandmarkId> = s.points.iter().map(|(id, _)| *id).collect();
        let batch: Vec<_> = ids
            .iter()
            .take(batch_size)
            .map(|id| measure(&s, &mut rng, *id))
            .collect();
        let (x_dense, p_dense) = dense_schmidt(&s.ekf, &batch);
        let x_before = s.ekf.state().clone();
        let report = s.ekf.update(&batch).unwrap();
        assert_eq!(report.accepted.len(), batch.len());
        let p = s.ekf.covariance();
        let p_err = max_abs(&(&p - &p_dense)) / max_abs(&p_dense);
        assert!(p_err < 1e-9, "seed {seed}: P relative error {p_err}");
        let dx = s.ekf.state() - &x_before;
        let dx_dense = &x_dense - &x_before;
        let x_err = (dx - &dx_dense).amax() / dx_dense.amax();
        assert!(x_err < 1e-9, "seed {seed}: dx relative error {x_err}");
        assert_spd(&p);
    }
}

/// Over a drive with many multi-landmark updates the camera parameters and their covariance do
/// not move; the landmarks' sigmas stay above what the same filter refining the camera claims.
#[test]
fn the_camera_stays_put_and_its_uncertainty_stays_in_the_map() {
    let mut s = setup(42, 2, 6, consider());
    let mut refine = setup(42, 2, 6, Settings::default());
    let camera = s.ekf.camera();
    let camera_cov = s.ekf.camera_covariance();
    let mut rng_a = rng(9);
    let mut rng_b = rng(9);
    for _ in 0..40 {
        drive(&mut s, &mut rng_a, 0.2, 0.05, 0.05);
        drive(&mut refine, &mut rng_b, 0.2, 0.05, 0.05);
    }
    assert_eq!(s.ekf.camera(), camera);
    assert_eq!(s.ekf.camera_covariance(), camera_cov);
    assert_spd(&s.ekf.covariance());
    let trace = |e: &Ekf| -> f64 { e.landmarks().map(|l| l.covariance.trace()).sum() };
    assert!(trace(&s.ekf) > trace(&refine.ekf));
    assert_ne!(refine.ekf.camera(), camera);
}
