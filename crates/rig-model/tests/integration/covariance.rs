//! Covariance honesty: seeded Monte Carlo runs (20,000 samples, a fixed-seed xorshift with
//! Box-Muller) against the propagated covariances: pixel noise through the triangulation (rig,
//! robot and world frames), pose noise, camera-parameter noise, and all three together. Each
//! standard deviation must agree within 3 % (the sampling error alone is about 0.5 %), each
//! correlation within 0.03. Also: the covariances are symmetric positive definite.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use crate::common;

use common::{Rng, assert_covariance_matches, case_strategy, landmark_at, sample_covariance};
use nalgebra::{Matrix3, SMatrix, SVector, Vector3};
use proptest::prelude::*;
use rig_model::{CameraParams, Measurement, Mount, N_PARAMS, Param, Pose2, project, triangulate};

const SAMPLES: usize = 20_000;
const SIGMA_PX: f64 = 0.3;
const REL_SIGMA: f64 = 0.03;
const ABS_CORR: f64 = 0.03;

/// Configurations: the nominal rig looking straight up at a lamp near the centre and one near
/// a corner at 4 m; a tilted, offset mount with the robot turned.
fn scenes() -> Vec<(&'static str, CameraParams, Pose2, Vector3<f64>)> {
    let nominal = common::nominal_camera();
    let tilted = CameraParams {
        vehicle: Default::default(),
        mount: Mount {
            x: 0.3,
            y: -0.2,
            z: 1.6,
            roll: 0.25,
            pitch: -0.35,
            yaw: 0.3,
        },
        ..nominal
    };
    let origin = Pose2::default();
    let turned = Pose2::new(12.0, -7.0, 2.4);
    vec![
        (
            "nominal, centre, 2 m",
            nominal,
            origin,
            landmark_at(&nominal, &origin, 380.0, 250.0, 2.0),
        ),
        (
            "nominal, corner, 4 m",
            nominal,
            origin,
            landmark_at(&nominal, &origin, 700.0, 40.0, 4.0),
        ),
        (
            "tilted mount, turned robot, 3 m",
            tilted,
            turned,
            landmark_at(&tilted, &turned, 150.0, 400.0, 3.0),
        ),
    ]
}

#[test]
fn pixel_noise_covariance_matches_monte_carlo_in_rig_robot_and_world() {
    for (seed, (name, c, pose, l)) in scenes().into_iter().enumerate() {
        let z = project(&c, &pose, &l).unwrap();
        let tri = triangulate(&c, &z).unwrap();
        let mut rng = Rng::new(0x5eed_0000 + seed as u64);
        let mut in_rig = Vec::with_capacity(SAMPLES);
        let mut in_robot = Vec::with_capacity(SAMPLES);
        let mut in_world = Vec::with_capacity(SAMPLES);
        for _ in 0..SAMPLES {
            let noisy = triangulate(&c, &(z + rng.pixel_noise(SIGMA_PX))).unwrap();
            in_rig.push(noisy.p_in_rig);
            in_robot.push(noisy.p_in_robot(&c));
            in_world.push(noisy.p_in_world(&c, &pose));
        }
        let (_, s_rig) = sample_covariance(&in_rig);
        let (_, s_robot) = sample_covariance(&in_robot);
        let (_, s_world) = sample_covariance(&in_world);
        assert_covariance_matches(
            &format!("{name}: rig"),
            &tri.covariance_in_rig(SIGMA_PX),
            &s_rig,
            REL_SIGMA,
            ABS_CORR,
        );
        assert_covariance_matches(
            &format!("{name}: robot"),
            &tri.covariance_in_robot(&c, SIGMA_PX),
            &s_robot,
            REL_SIGMA,
            ABS_CORR,
        );
        assert_covariance_matches(
            &format!("{name}: world"),
            &tri.covariance_in_world(&c, &pose, SIGMA_PX, None, None),
            &s_world,
            REL_SIGMA,
            ABS_CORR,
        );
    }
}

/// A correlated 3x3 pose covariance: 5 cm, 8 cm, 0.02 rad.
fn pose_covariance() -> Matrix3<f64> {
    let s = Vector3::new(0.05, 0.08, 0.02);
    let r = Matrix3::new(1.0, 0.3, -0.2, 0.3, 1.0, 0.4, -0.2, 0.4, 1.0);
    Matrix3::from_diagonal(&s) * r * Matrix3::from_diagonal(&s)
}

/// A camera covariance: f 5 px, cx/cy 2 px, baseline 2 mm, mount 1 cm and 5 mrad, with
/// f and baseline correlated; the vehicle's parameters (which a triangulation does not use)
/// with small variances too.
fn camera_covariance() -> SMatrix<f64, N_PARAMS, N_PARAMS> {
    let s = SVector::<f64, N_PARAMS>::from_column_slice(&[
        5.0, 2.0, 2.0, 0.002, 0.01, 0.01, 0.01, 0.005, 0.005, 0.005, 0.01, 0.01, 0.001, 0.01,
    ]);
    let mut r = SMatrix::<f64, N_PARAMS, N_PARAMS>::identity();
    let (f, b) = (Param::F.index(), Param::Baseline.index());
    r[(f, b)] = -0.5;
    r[(b, f)] = -0.5;
    let (x, pitch) = (Param::MountX.index(), Param::MountPitch.index());
    r[(x, pitch)] = 0.3;
    r[(pitch, x)] = 0.3;
    SMatrix::from_diagonal(&s) * r * SMatrix::from_diagonal(&s)
}

fn sample<const N: usize>(rng: &mut Rng, chol: &SMatrix<f64, N, N>) -> SVector<f64, N> {
    chol * SVector::<f64, N>::from_fn(|_, _| rng.gauss())
}

#[test]
fn pose_covariance_propagation_matches_monte_carlo() {
    let pc = pose_covariance();
    let chol = pc.cholesky().unwrap().l();
    for (seed, (name, c, pose, l)) in scenes().into_iter().enumerate() {
        let tri = triangulate(&c, &project(&c, &pose, &l).unwrap()).unwrap();
        let mut rng = Rng::new(0xb0b0_0000 + seed as u64);
        let samples: Vec<_> = (0..SAMPLES)
            .map(|_| {
                let d = sample(&mut rng, &chol);
                tri.p_in_world(
                    &c,
                    &Pose2::new(pose.x + d.x, pose.y + d.y, pose.theta + d.z),
                )
            })
            .collect();
        let (_, s) = sample_covariance(&samples);
        let predicted = tri.covariance_in_world(&c, &pose, 0.0, Some(&pc), None);
        // The world z of a landmark does not depend on the planar pose: both are zero.
        assert!(
            predicted[(2, 2)] == 0.0 && s[(2, 2)] < 1e-24,
            "{name}: z variance {predicted} {s}"
        );
        let top = |m: &Matrix3<f64>| {
            let mut t = *m;
            t[(2, 2)] = 1.0; // make the 2x2 comparison well defined
            t
        };
        assert_covariance_matches(
            &format!("{name}: pose"),
            &top(&predicted),
            &top(&s),
            REL_SIGMA,
            ABS_CORR,
        );
    }
}

#[test]
fn camera_covariance_propagation_matches_monte_carlo() {
    let cc = camera_covariance();
    let chol = cc.cholesky().unwrap().l();
    for (seed, (name, c, pose, l)) in scenes().into_iter().enumerate() {
        let z = project(&c, &pose, &l).unwrap();
        let tri = triangulate(&c, &z).unwrap();
        let mut rng = Rng::new(0xca11_0000 + seed as u64);
        let samples: Vec<_> = (0..SAMPLES)
            .map(|_| {
                let noisy = CameraParams::from_vector(&(c.to_vector() + sample(&mut rng, &chol)));
                triangulate(&noisy, &z).unwrap().p_in_world(&noisy, &pose)
            })
            .collect();
        let (_, s) = sample_covariance(&samples);
        let predicted = tri.covariance_in_world(&c, &pose, 0.0, None, Some(&cc));
        assert_covariance_matches(
            &format!("{name}: camera"),
            &predicted,
            &s,
            REL_SIGMA,
            ABS_CORR,
        );
    }
}

#[test]
fn pixel_pose_and_camera_noise_together_match_monte_carlo() {
    let (pc, cc) = (pose_covariance(), camera_covariance());
    let (pl, cl) = (pc.cholesky().unwrap().l(), cc.cholesky().unwrap().l());
    for (seed, (name, c, pose, l)) in scenes().into_iter().enumerate() {
        let z = project(&c, &pose, &l).unwrap();
        let tri = triangulate(&c, &z).unwrap();
        let mut rng = Rng::new(0xa11_0000 + seed as u64);
        let samples: Vec<_> = (0..SAMPLES)
            .map(|_| {
                let zn: Measurement = z + rng.pixel_noise(SIGMA_PX);
                let cn = CameraParams::from_vector(&(c.to_vector() + sample(&mut rng, &cl)));
                let d = sample(&mut rng, &pl);
                let pn = Pose2::new(pose.x + d.x, pose.y + d.y, pose.theta + d.z);
                triangulate(&cn, &zn).unwrap().p_in_world(&cn, &pn)
            })
            .collect();
        let (_, s) = sample_covariance(&samples);
        let predicted = tri.covariance_in_world(&c, &pose, SIGMA_PX, Some(&pc), Some(&cc));
        assert_covariance_matches(&format!("{name}: all"), &predicted, &s, REL_SIGMA, ABS_CORR);
    }
}

/// The generator itself: mean 0, variance 1, no lag-1 correlation, symmetric tails.
#[test]
fn box_muller_generator_is_standard_normal() {
    let mut rng = Rng::new(42);
    let n = 200_000;
    let xs: Vec<f64> = (0..n).map(|_| rng.gauss()).collect();
    let mean = xs.iter().sum::<f64>() / n as f64;
    let var = xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1) as f64;
    let lag = xs.windows(2).map(|w| w[0] * w[1]).sum::<f64>() / (n - 1) as f64;
    let beyond_2 = xs.iter().filter(|x| x.abs() > 2.0).count() as f64 / n as f64;
    assert!(mean.abs() < 0.01, "mean {mean}");
    assert!((var - 1.0).abs() < 0.01, "variance {var}");
    assert!(lag.abs() < 0.01, "lag-1 correlation {lag}");
    assert!((beyond_2 - 0.0455).abs() < 0.002, "P(|x| > 2) = {beyond_2}");
}

proptest! {
    #![proptest_config(common::config(300))]

    /// Covariances are symmetric positive definite in every frame, with and without pose and
    /// camera uncertainty.
    #[test]
    fn covariances_are_symmetric_positive_definite(case in case_strategy()) {
        let (c, pose, l) = (case.camera, case.pose, case.landmark);
        let tri = triangulate(&c, &project(&c, &pose, &l).unwrap()).unwrap();
        let (pc, cc) = (pose_covariance(), camera_covariance());
        for (name, m) in [
            ("rig", tri.covariance_in_rig(SIGMA_PX)),
            ("robot", tri.covariance_in_robot(&c, SIGMA_PX)),
            ("world", tri.covariance_in_world(&c, &pose, SIGMA_PX, None, None)),
            ("world + pose + camera", tri.covariance_in_world(&c, &pose, SIGMA_PX, Some(&pc), Some(&cc))),
        ] {
            let asym = (m - m.transpose()).norm();
            prop_assert!(asym <= 1e-12 * m.norm(), "{name}: asymmetric by {asym}");
            let eig = m.symmetric_eigen().eigenvalues;
            prop_assert!(eig.min() > 0.0, "{name}: eigenvalues {eig:?}");
        }
        // Robot and world covariances are rotations of the rig covariance: same eigenvalues.
        let e_rig = tri.covariance_in_rig(SIGMA_PX).symmetric_eigen().eigenvalues.sum();
        let e_world = tri.covariance_in_world(&c, &pose, SIGMA_PX, None, None).trace();
        prop_assert!((e_rig - e_world).abs() <= 1e-9 * e_rig, "trace {e_rig} vs {e_world}");
    }
}
