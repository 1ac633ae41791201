//! Landmarks seen as points relative to the vehicle (`Ekf::update_relative`,
//! `Ekf::add_landmark_relative`): how a loop is closed with the lamps held while the pose was
//! lost, and how the held lamps are mapped once it is.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use crate::common::*;
use crate::update::loop_closure_setup;
use nalgebra::{DMatrix, DVector, Matrix3, Vector3};
use rig_model::camera::Pose2;
use vslam_ekf::{Ekf, Error, LandmarkId, RelativeObservation};

/// `R(theta)^T (L - p)` horizontally, `L_z`: a landmark from the vehicle.
fn relative(pose: &Pose2, l: &Vector3<f64>) -> Vector3<f64> {
    let (s, c) = pose.theta.sin_cos();
    let (dx, dy) = (l.x - pose.x, l.y - pose.y);
    Vector3::new(c * dx + s * dy, -s * dx + c * dy, l.z)
}

/// Each landmark of the setup seen from the true pose, with 2 cm of noise.
fn observations(
    points: &[(LandmarkId, Vector3<f64>)],
    pose: &Pose2,
    rng: &mut TestRng,
) -> Vec<RelativeObservation> {
    let sigma = 0.02;
    points
        .iter()
        .map(|(id, p)| RelativeObservation {
            id: *id,
            position: relative(pose, p) + Vector3::from_fn(|_, _| sigma * normal(rng)),
            covariance: Matrix3::from_diagonal_element(sigma * sigma),
        })
        .collect()
}

/// The relative observations' model at state `x` (pose first, landmarks at their indices).
fn h(ekf: &Ekf, x: &DVector<f64>, o: &RelativeObservation) -> Vector3<f64> {
    let i = ekf.landmark_state_index(o.id).unwrap();
    relative(
        &Pose2::new(x[0], x[1], x[2]),
        &Vector3::new(x[i], x[i + 1], x[i + 2]),
    )
}

/// The maximum a posteriori cost's gradient at the filter's state, in sigmas of its
/// covariance: `P0^-1 (x - x0) - sum H^T R^-1 (z - h(x))`, `H` by central differences.
fn step_to_optimum(
    ekf: &Ekf,
    batch: &[RelativeObservation],
    x0: &DVector<f64>,
    p0_inv: &DMatrix<f64>,
) -> f64 {
    let x = ekf.state().clone();
    let mut dx = &x - x0;
    dx[2] = wrap(dx[2]);
    let mut gradient = p0_inv * &dx;
    for o in batch {
        let r_inv = o.covariance.try_inverse().unwrap();
        let nu = o.position - h(ekf, &x, o);
        let w = r_inv * nu;
        for k in 0..x.len() {
            let e = 1e-6;
            let (mut xp, mut xm) = (x.clone(), x.clone());
            xp[k] += e;
            xm[k] -= e;
            let col = (h(ekf, &xp, o) - h(ekf, &xm, o)) / (2.0 * e);
            gradient[k] -= col.dot(&w);
        }
    }
    gradient.dot(&(ekf.covariance() * &gradient)).sqrt()
}

/// From a pose lost by a metre and five degrees, linearised first at the prior's (wrong)
/// mean, the iterated update reaches the maximum a posteriori estimate of the prior and four
/// relative observations, and the pose is inside its posterior's 99.9 % ellipse.
#[test]
fn a_relative_update_reaches_the_maximum_a_posteriori_estimate() {
    for seed in 0..8 {
        let (mut s, _, x0, p0) = loop_closure_setup(5100 + seed);
        let p0_inv = p0.clone().try_inverse().unwrap();
        let mut rng = rng(5200 + seed);
        let batch = observations(&s.points, &s.pose, &mut rng);
        let report = s.ekf.update_relative(&batch, s.ekf.pose()).unwrap();
        assert_eq!(
            report.accepted.len(),
            batch.len(),
            "seed {seed}: {report:?}"
        );
        let step = step_to_optimum(&s.ekf, &batch, &x0, &p0_inv);
        assert!(step < 0.05, "seed {seed}: step to the optimum {step} sigma");
        let pose = s.ekf.pose();
        let e = Vector3::new(
            pose.x - s.pose.x,
            pose.y - s.pose.y,
            wrap(pose.theta - s.pose.theta),
        );
        let nees = e.dot(&(s.ekf.pose_covariance().try_inverse().unwrap() * e));
        assert!(nees < 16.3, "seed {seed}: pose NEES {nees}, error {e:?}");
    }
}

/// A pose five metres off (a grid spacing and more) found from a guess near the truth: the
/// guess is only where the first pass is linearised; the answer is the same optimum.
#[test]
fn a_guess_is_only_where_the_relative_update_starts() {
    for seed in 0..6 {
        let (mut s, _, _, _) = loop_closure_setup(5300 + seed);
        let mut rng = rng(5400 + seed);
        let batch = observations(&s.points, &s.pose, &mut rng);
        let mut from_mean = s.ekf.clone();
        from_mean.update_relative(&batch, s.ekf.pose()).unwrap();
        let guess = Pose2::new(s.pose.x + 0.3, s.pose.y - 0.2, s.pose.theta + 0.05);
        s.ekf.update_relative(&batch, guess).unwrap();
        let d = (s.ekf.state() - from_mean.state()).amax();
        assert!(d < 1e-6, "seed {seed}: the two starts differ by {d}");
    }
}

/// An observation outside the prior's gate is left out and reported rejected.
#[test]
fn a_relative_observation_outside_the_gate_is_rejected() {
    let (mut s, _, _, _) = loop_closure_setup(5500);
    let mut rng = rng(5501);
    let mut batch = observations(&s.points, &s.pose, &mut rng);
    // The last landmark 40 m from where it is seen, at a 2 cm sigma.
    batch.last_mut().unwrap().position.x += 40.0;
    let report = s.ekf.update_relative(&batch, s.pose).unwrap();
    let bad = batch.last().unwrap().id;
    assert_eq!(report.rejected.len(), 1, "{report:?}");
    assert_eq!(report.rejected[0].id, bad);
    assert_eq!(report.accepted.len(), batch.len() - 1);
}

/// Bad input is refused and leaves the filter as it was.
#[test]
fn bad_relative_observations_are_refused() {
    let (s, _, _, _) = loop_closure_setup(5600);
    let mut rng = rng(5601);
    let good = observations(&s.points, &s.pose, &mut rng);
    let mut nan = good.clone();
    nan[0].position.y = f64::NAN;
    let mut unknown = good.clone();
    unknown[0].id = LandmarkId(999);
    let mut twice = good.clone();
    twice[1].id = twice[0].id;
    let mut singular = good.clone();
    singular[0].covariance = Matrix3::zeros();
    for (what, batch) in [
        ("NaN", nan),
        ("unknown", unknown),
        ("twice", twice),
        ("singular", singular),
    ] {
        let mut ekf = s.ekf.clone();
        let err = ekf.update_relative(&batch, s.pose).unwrap_err();
        assert_eq!(ekf.state(), s.ekf.state(), "{what}: {err}");
        match (what, &err) {
            ("NaN", Error::NonFinite { .. })
            | ("unknown", Error::UnknownLandmark { .. })
            | ("twice", Error::DuplicateObservation { .. })
            | ("singular", Error::InnovationNotPositiveDefinite { .. }) => {}
            _ => panic!("{what}: {err:?}"),
        }
    }
    let mut ekf = s.ekf.clone();
    let guess = Pose2::new(f64::INFINITY, 0.0, 0.0);
    assert!(ekf.update_relative(&good, guess).is_err());
}

/// A landmark added relative to the vehicle: at `p + R(theta) v`, its covariance
/// `G P_pose G^T + R Sigma R^T` and its cross-covariances `G P_pose,.` (G its Jacobian in the
/// pose), as the textbook augmentation.
#[test]
fn a_landmark_added_relative_to_the_vehicle_has_the_joint_covariance() {
    for seed in 0..4 {
        let mut s = setup(5700 + seed, 2, 3, vslam_ekf::Settings::default());
        let mut rng = rng(5800 + seed);
        for _ in 0..4 {
            drive(&mut s, &mut rng, 0.3, 0.1, 0.1);
        }
        let p_before = s.ekf.covariance();
        let n = s.ekf.state_len();
        let pose = s.ekf.pose();
        let v = Vector3::new(1.5, -0.7, 6.0);
        let sigma = Matrix3::new(4e-4, 1e-4, 0.0, 1e-4, 9e-4, 2e-4, 0.0, 2e-4, 1e-3);
        let id = s.ekf.add_landmark_relative(&v, &sigma).unwrap();
        let (sn, cs) = pose.theta.sin_cos();
        let rot = Matrix3::new(cs, -sn, 0.0, sn, cs, 0.0, 0.0, 0.0, 1.0);
        let want = Vector3::new(pose.x, pose.y, 0.0) + rot * v;
        let i = s.ekf.landmark_state_index(id).unwrap();
        let got = s.ekf.state().fixed_rows::<3>(i).into_owned();
        assert!((got - want).amax() < 1e-12, "seed {seed}");
        // G over the whole old state (only the pose's columns are non-zero).
        let mut g = DMatrix::zeros(3, n);
        g[(0, 0)] = 1.0;
        g[(1, 1)] = 1.0;
        g[(0, 2)] = -sn * v.x - cs * v.y;
        g[(1, 2)] = cs * v.x - sn * v.y;
        let p = s.ekf.covariance();
        // The old states keep their order around the new landmark's rows.
        let old: Vec<usize> = (0..p.nrows()).filter(|k| !(i..i + 3).contains(k)).collect();
        let p_old = DMatrix::from_fn(n, n, |r, c| p[(old[r], old[c])]);
        assert!((&p_old - &p_before).amax() < 1e-12, "seed {seed}");
        let cross = DMatrix::from_fn(3, n, |r, c| p[(i + r, old[c])]);
        let want_cross = &g * &p_before;
        assert!((cross - &want_cross).amax() < 1e-10, "seed {seed}");
        let block = DMatrix::from_fn(3, 3, |r, c| p[(i + r, i + c)]);
        let rs = rot * sigma * rot.transpose();
        let want_block = &g * &p_before * g.transpose() + DMatrix::from_fn(3, 3, |r, c| rs[(r, c)]);
        assert!((block - want_block).amax() < 1e-10, "seed {seed}");
    }
}
