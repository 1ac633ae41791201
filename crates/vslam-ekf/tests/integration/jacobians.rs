//! The filter's linearisations against numerical differentiation: the observation Jacobian
//! `H` over the whole state, the prediction's `F` and `Q` (and `Q` against a Monte Carlo of
//! the held-noise odometry), and the new landmark's covariance against the dense
//! augmented-state Jacobian.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use crate::common;

use common::*;
use nalgebra::{DMatrix, DVector, Matrix3, Vector3};
use rig_model::camera::{Param, Pose2};
use rig_model::odometry::{OdomSample, constant_velocity_motion, integrate};
use rig_model::{project, triangulate};
use vslam_ekf::{Ekf, Increment, Settings};

/// Central-difference step for state component `i`, relative to its magnitude.
fn step(x: f64) -> f64 {
    1e-6 * x.abs().max(1.0)
}

/// `H` of every landmark against central differences of the measurement function over the
/// full state (pose, every landmark, the estimated camera), on tilted and rotated mounts with
/// every size of camera block.
#[test]
fn observation_jacobian_matches_numerical_differentiation_over_the_full_state() {
    for seed in 0..12 {
        let estimated = [0, 1, 3, 10][seed as usize % 4];
        let s = setup(seed, estimated, 4, Settings::default());
        let ekf = &s.ekf;
        let estimate = ekf.estimated_parameters().to_vec();
        let base = ekf.camera();
        let x = ekf.state().clone();
        let n = x.len();
        for (id, _) in &s.points {
            let li = ekf.landmark_state_index(*id).unwrap();
            let (z, h) = ekf.measurement_jacobian(*id).unwrap();
            assert!((z - h_of_state(&x, &estimate, &base, li)).norm() < 1e-9);
            let mut numeric = DMatrix::zeros(4, n);
            for i in 0..n {
                let e = step(x[i]);
                let mut plus = x.clone();
                let mut minus = x.clone();
                plus[i] += e;
                minus[i] -= e;
                let d = (h_of_state(&plus, &estimate, &base, li)
                    - h_of_state(&minus, &estimate, &base, li))
                    / (2.0 * e);
                numeric.set_column(i, &d);
            }
            for i in 0..n {
                let (a, b) = (h.column(i), numeric.column(i));
                let err = (a - b).norm();
                let block = if i < 3 {
                    "pose".to_string()
                } else if i >= n - estimate.len() {
                    format!("camera {}", estimate[i - (n - estimate.len())])
                } else {
                    format!("landmark state {i}")
                };
                assert!(
                    err <= 1e-5 * (1.0 + b.norm()),
                    "seed {seed} {id} column {i} ({block}): analytic {a} numeric {b}"
                );
            }
        }
    }
}

/// The prediction's `F` against central differences of the arc model, and the filter's
/// covariance after a prediction against the dense `F_full P F_full^T + Q`.
#[test]
fn prediction_jacobian_and_covariance_propagation() {
    let noise = noise();
    for &(vx, vy, w, dt) in &[
        (0.3, 0.0, 0.0, 0.05),
        (0.25, 0.05, 0.4, 0.05),
        (-0.2, 0.1, -1.2, 0.3),
        (0.0, 0.0, 0.35, 0.01),
    ] {
        let inc = Increment::from_velocities(vx, vy, w, dt, &noise).unwrap();
        for pose in [Pose2::new(0.0, 0.0, 0.0), Pose2::new(1.5, -2.0, 2.8)] {
            let (next, f, _) = inc.apply(&pose);
            let truth = constant_velocity_motion(vx, vy, w, dt).apply(&pose);
            assert!((next.x - truth.x).abs() + (next.y - truth.y).abs() < 1e-15);
            let v = |p: &Pose2| Vector3::new(p.x, p.y, p.theta);
            for k in 0..3 {
                let e = 1e-6;
                let mut plus = v(&pose);
                let mut minus = plus;
                plus[k] += e;
                minus[k] -= e;
                let to_pose = |a: Vector3<f64>| Pose2::new(a.x, a.y, a.z);
                let d = (v(&inc.apply(&to_pose(plus)).0) - v(&inc.apply(&to_pose(minus)).0))
                    / (2.0 * e);
                assert!(
                    (d - f.column(k)).norm() < 1e-9,
                    "F column {k}: {d} vs {}",
                    f.column(k)
                );
            }
        }
    }

    // The filter applies exactly F P F^T + Q to the pose rows and columns, O(n). (With the
    // first estimates, the default, `F`'s heading column starts where the previous prediction
    // left the pose: `update::linearisation_point_tests` checks that form.)
    let settings = Settings {
        first_estimate_prediction: false,
        ..Settings::default()
    };
    let mut s = setup(3, 2, 5, settings);
    let before = s.ekf.covariance().clone();
    let pose = s.ekf.pose();
    let inc = Increment::from_velocities(0.3, 0.02, 0.5, 0.1, &noise).unwrap();
    let (_, f, q) = inc.apply(&pose);
    s.ekf.predict(0.3, 0.02, 0.5, 0.1).unwrap();
    let n = before.nrows();
    let mut f_full = DMatrix::identity(n, n);
    f_full.view_mut((0, 0), (3, 3)).copy_from(&f);
    let mut expected = &f_full * &before * f_full.transpose();
    let mut qq = expected.view_mut((0, 0), (3, 3));
    qq += q;
    let err = max_abs(&(s.ekf.covariance() - &expected));
    assert!(err < 1e-14 * max_abs(&expected), "{err}");
    assert_spd(&s.ekf.covariance());
}

/// `Q` of a frame interval against a Monte Carlo of the held-noise odometry: each sample's
/// velocities perturbed once and held for its period, integrated with calib's integrator.
#[test]
fn process_noise_matches_a_monte_carlo_of_held_velocity_noise() {
    let noise = noise();
    // 100 Hz samples of a turning drive, integrated over 0.53 s (the ends split samples).
    let samples: Vec<OdomSample> = (0..80)
        .map(|k| OdomSample {
            t_us: 1_000_000 + k * 10_000,
            vx: 0.25 + 0.001 * k as f64,
            vy: 0.02,
            vtheta: 0.6 - 0.01 * k as f64,
        })
        .collect();
    let (t0, t1) = (1_003_000, 1_533_000);
    let inc = Increment::from_odometry(&samples, t0, t1, &noise).unwrap();
    let exact = integrate(&samples, t0, t1).unwrap();
    assert!((inc.motion.dx - exact.dx).abs() < 1e-15 && (inc.motion.dy - exact.dy).abs() < 1e-15);
    let mut rng = rng(42);
    let runs = 20_000;
    let mut sum = Vector3::zeros();
    let mut sum_sq = Matrix3::zeros();
    for _ in 0..runs {
        let noisy: Vec<OdomSample> = samples
            .iter()
            .map(|s| OdomSample {
                vx: s.vx + noise.velocity * normal(&mut rng),
                vy: s.vy + noise.velocity * normal(&mut rng),
                vtheta: s.vtheta + noise.yaw_rate * normal(&mut rng),
                ..*s
            })
            .collect();
        let m = integrate(&noisy, t0, t1).unwrap();
        let d = Vector3::new(m.dx - exact.dx, m.dy - exact.dy, m.dtheta - exact.dtheta);
        sum += d;
        sum_sq += d * d.transpose();
    }
    let mean = sum / runs as f64;
    let cov = sum_sq / runs as f64 - mean * mean.transpose();
    for i in 0..3 {
        for j in 0..3 {
            let scale = (inc.covariance[(i, i)] * inc.covariance[(j, j)]).sqrt();
            let err = (cov[(i, j)] - inc.covariance[(i, j)]).abs() / scale;
            assert!(
                err < 0.04,
                "({i},{j}): monte carlo {} model {}",
                cov[(i, j)],
                inc.covariance[(i, j)]
            );
        }
    }
}

/// The new landmark's covariance and cross-covariances against the dense augmented-state
/// formula: `J = [dg/dx, dg/dz]` by central differences of the triangulation over the whole
/// state and the four pixels, `P_new = J blockdiag(P, R) J^T`.
#[test]
fn new_landmark_covariance_matches_the_dense_augmented_jacobian() {
    for seed in 0..8 {
        let estimated = [1, 4, 10, 0][seed as usize % 4];
        let mut s = setup(100 + seed, estimated, 3, Settings::default());
        let estimate = s.ekf.estimated_parameters().to_vec();
        let base = s.ekf.camera();
        let x = s.ekf.state().clone();
        let p = s.ekf.covariance().clone();
        let n = x.len();
        let mut rng = rng(seed);
        let point = random_point_in_view(&mut rng, &s.truth, &s.pose);
        let z = noisy(&mut rng, &project(&s.truth, &s.pose, &point).unwrap(), 0.3);
        // g(x, z): triangulate with the state's camera at the state's pose.
        let g = |x: &DVector<f64>, z: &rig_model::Measurement| {
            let c = camera_of_state(x, &estimate, &base);
            let pose = Pose2::new(x[0], x[1], x[2]);
            triangulate(&c, z).unwrap().p_in_world(&c, &pose)
        };
        let mut jx = DMatrix::zeros(3, n);
        for i in 0..n {
            let e = step(x[i]);
            let (mut plus, mut minus) = (x.clone(), x.clone());
            plus[i] += e;
            minus[i] -= e;
            jx.set_column(i, &((g(&plus, &z) - g(&minus, &z)) / (2.0 * e)));
        }
        let mut jz = DMatrix::zeros(3, 4);
        for i in 0..4 {
            let e = 1e-4;
            let (mut plus, mut minus) = (z, z);
            plus[i] += e;
            minus[i] -= e;
            jz.set_column(i, &((g(&x, &plus) - g(&x, &minus)) / (2.0 * e)));
        }
        let sigma2 = s.ekf.noise().pixel.powi(2);
        let cross = &jx * &p; // 3 x n
        let pll = &jx * &p * jx.transpose() + &jz * jz.transpose() * sigma2;

        let id = s.ekf.add_landmark(&z).unwrap();
        let li = s.ekf.landmark_state_index(id).unwrap();
        let p2 = s.ekf.covariance();
        assert_eq!(p2.nrows(), n + 3);
        assert!((s.ekf.landmark(id).unwrap().position - g(&x, &z)).norm() < 1e-12);
        let old = |i: usize| if i < li { i } else { i - 3 };
        let scale = max_abs(&pll);
        for a in 0..3 {
            for b in 0..3 {
                let err = (p2[(li + a, li + b)] - pll[(a, b)]).abs();
                assert!(
                    err < 1e-6 * scale,
                    "seed {seed} P_LL ({a},{b}): {err} of {scale}"
                );
            }
            for i in (0..n + 3).filter(|i| !(li..li + 3).contains(i)) {
                let err = (p2[(li + a, i)] - cross[(a, old(i))]).abs();
                let sc = (pll[(a, a)] * p[(old(i), old(i))]).sqrt().max(1e-30);
                assert!(err < 1e-6 * sc, "seed {seed} P_Lx ({a},{i}): {err} of {sc}");
                assert_eq!(p2[(li + a, i)], p2[(i, li + a)]);
            }
        }
        // The old states' block is untouched.
        for j in 0..n {
            for i in 0..n {
                let (i2, j2) = (
                    if i < li { i } else { i + 3 },
                    if j < li { j } else { j + 3 },
                );
                assert_eq!(p2[(i2, j2)], p[(i, j)]);
            }
        }
        assert_spd(&p2);
    }
}

/// A filter straight from the rig's priors: zero pose covariance and only the estimated
/// parameters in the state.
#[test]
fn start_from_prior_and_handover_rules() {
    let mut rng = rng(7);
    let truth = random_camera(&mut rng);
    let rig = rig(truth, &[Param::Baseline, Param::F]);
    let ekf = Ekf::from_prior(&rig, Settings::default()).unwrap();
    assert_eq!(ekf.state_len(), 5);
    assert_eq!(ekf.pose_covariance(), Matrix3::zeros());
    assert_eq!(ekf.camera(), truth);
    let cov = ekf.camera_covariance();
    assert_eq!(cov[(Param::F.index(), Param::F.index())], 400.0);
    assert_eq!(
        cov[(Param::Baseline.index(), Param::Baseline.index())],
        0.005f64.powi(2)
    );
    assert_eq!(cov[(Param::Cx.index(), Param::Cx.index())], 0.0);
    // A hand-over that held f at nominal (zero row): f enters with its prior variance,
    // uncorrelated; the baseline keeps phase 1's variance.
    let mut start = vslam_ekf::CameraStart::from_prior(&rig);
    start.covariance = vslam_ekf::CameraCovariance::zeros();
    start.covariance[(Param::Baseline.index(), Param::Baseline.index())] = 1e-8;
    start.camera.baseline = 0.118;
    let ekf = Ekf::new(&rig, &start, Settings::default()).unwrap();
    let cov = ekf.camera_covariance();
    assert_eq!(cov[(Param::F.index(), Param::F.index())], 400.0);
    assert_eq!(
        cov[(Param::Baseline.index(), Param::Baseline.index())],
        1e-8
    );
    assert_eq!(cov[(Param::F.index(), Param::Baseline.index())], 0.0);
    assert_eq!(ekf.camera().baseline, 0.118);
    // The state order is the rig's estimate order.
    assert_eq!(ekf.camera_state_index(Param::Baseline), Some(3));
    assert_eq!(ekf.camera_state_index(Param::F), Some(4));
    assert_eq!(ekf.camera_state_index(Param::Cx), None);
}
