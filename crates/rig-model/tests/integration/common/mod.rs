//! Helpers shared by the rig-model tests: random valid configurations (a proptest strategy),
//! central differences, tolerance checks, and a seeded Gaussian generator (xorshift64* plus
//! Box-Muller) so that Monte Carlo runs need no RNG crate and are identical on every run.
#![allow(dead_code, unreachable_pub, clippy::unwrap_used, clippy::expect_used)] // test helpers

use nalgebra::{Matrix3, Vector3};
use proptest::prelude::*;
use rig_model::{CameraParams, Measurement, Mount, Pose2};

/// Relative step of the central differences.
pub const REL_STEP: f64 = 1e-6;
/// Relative tolerance of analytic against numeric derivatives.
pub const REL_TOL: f64 = 1e-6;
/// Absolute tolerance of analytic against numeric derivatives (px or m per unit).
pub const ABS_TOL: f64 = 1e-6;

/// `cases` cases (or `PROPTEST_CASES`, when set, for longer hunts), with failures saved next to
/// the test file (`*.regressions`) for replay.
pub fn config(cases: u32) -> ProptestConfig {
    ProptestConfig {
        cases: std::env::var("PROPTEST_CASES")
            .ok()
            .and_then(|s| s.parse().ok())
            .unwrap_or(cases),
        failure_persistence: Some(Box::new(
            prop::test_runner::FileFailurePersistence::WithSource("regressions"),
        )),
        ..ProptestConfig::default()
    }
}

/// The nominal camera of vehicle-interfaces.md section 3, mounted 1 m up, looking straight up.
pub fn nominal_camera() -> CameraParams {
    CameraParams {
        vehicle: Default::default(),
        f: 700.0,
        cx: 376.0,
        cy: 240.0,
        baseline: 0.12,
        mount: Mount {
            x: 0.0,
            y: 0.0,
            z: 1.0,
            roll: 0.0,
            pitch: 0.0,
            yaw: 0.0,
        },
    }
}

/// A random valid configuration: camera, pose and a landmark in view.
#[derive(Debug, Clone, Copy)]
pub struct Case {
    pub camera: CameraParams,
    pub pose: Pose2,
    pub landmark: Vector3<f64>,
}

/// Camera parameters around f 700, cx 376, cy 240, baseline 0.12; mount x/y within 0.5 m,
/// z 0.5..2 m, roll/pitch/yaw within 0.4 rad.
pub fn camera_strategy() -> impl Strategy<Value = CameraParams> {
    (
        (
            640.0..760.0f64,
            346.0..406.0f64,
            210.0..270.0f64,
            0.10..0.14f64,
        ),
        (-0.5..0.5f64, -0.5..0.5f64, 0.5..2.0f64),
        (-0.4..0.4f64, -0.4..0.4f64, -0.4..0.4f64),
    )
        .prop_map(
            |((f, cx, cy, baseline), (x, y, z), (roll, pitch, yaw))| CameraParams {
                vehicle: Default::default(),
                f,
                cx,
                cy,
                baseline,
                mount: Mount {
                    x,
                    y,
                    z,
                    roll,
                    pitch,
                    yaw,
                },
            },
        )
}

/// A pose anywhere within 50 m of the origin, any heading (several turns either way).
pub fn pose_strategy() -> impl Strategy<Value = Pose2> {
    (-50.0..50.0f64, -50.0..50.0f64, -20.0..20.0f64).prop_map(|(x, y, t)| Pose2::new(x, y, t))
}

/// The world point seen by the rig midpoint at pixel `(u, v)` (a 752x480 image, kept 40 px
/// from the sides so that both cameras see it) and `height_m` above the camera in the robot
/// frame.
pub fn landmark_at(c: &CameraParams, pose: &Pose2, u: f64, v: f64, height_m: f64) -> Vector3<f64> {
    let ray_in_rig = Vector3::new((u - c.cx) / c.f, (v - c.cy) / c.f, 1.0);
    let ray_in_robot = c.mount.robot_from_rig_rotation() * ray_in_rig;
    // With roll and pitch within 0.4 rad and a half field of view under 0.6 rad the ray always
    // climbs (ray_in_robot.z > 0.4), so the landmark is in front of the cameras.
    assert!(ray_in_robot.z > 0.3, "ray does not climb: {ray_in_robot:?}");
    let p_in_rig = ray_in_rig * (height_m / ray_in_robot.z);
    pose.point_in_world(&(c.mount.translation() + c.mount.robot_from_rig_rotation() * p_in_rig))
}

/// A random valid configuration: landmark 1.5..4 m above the camera, within the field of view.
pub fn case_strategy() -> impl Strategy<Value = Case> {
    (
        camera_strategy(),
        pose_strategy(),
        (40.0..712.0f64, 10.0..470.0f64, 1.5..4.0f64),
    )
        .prop_map(|(camera, pose, (u, v, h))| Case {
            camera,
            pose,
            landmark: landmark_at(&camera, &pose, u, v, h),
        })
}

/// The central-difference step for a variable at `x`.
pub fn step(x: f64) -> f64 {
    REL_STEP * x.abs().max(1.0)
}

/// Central difference of a vector function of one variable at `x`.
pub fn central<const N: usize>(
    x: f64,
    g: impl Fn(f64) -> nalgebra::SVector<f64, N>,
) -> nalgebra::SVector<f64, N> {
    let h = step(x);
    (g(x + h) - g(x - h)) / (2.0 * h)
}

/// Checks `analytic` against `numeric` entry by entry: `|a - n| <= REL_TOL |n| + ABS_TOL`.
/// `what` names the column in the failure message.
pub fn check_column<const N: usize>(
    what: &str,
    analytic: &nalgebra::SVector<f64, N>,
    numeric: &nalgebra::SVector<f64, N>,
) -> Result<(), TestCaseError> {
    for i in 0..N {
        let (a, n) = (analytic[i], numeric[i]);
        let tol = REL_TOL * n.abs() + ABS_TOL;
        if (a - n).abs() > tol || a.is_nan() || n.is_nan() {
            return Err(TestCaseError::fail(format!(
                "{what}, row {i}: analytic {a:.12e} vs numeric {n:.12e} (diff {:.3e} > tol {tol:.3e})",
                (a - n).abs()
            )));
        }
    }
    Ok(())
}

/// xorshift64* with a fixed seed and Box-Muller Gaussians.
#[derive(Debug, Clone)]
pub struct Rng {
    state: u64,
    spare: Option<f64>,
}

impl Rng {
    pub fn new(seed: u64) -> Self {
        Self {
            state: seed.max(1),
            spare: None,
        }
    }

    pub fn next_u64(&mut self) -> u64 {
        let mut x = self.state;
        x ^= x >> 12;
        x ^= x << 25;
        x ^= x >> 27;
        self.state = x;
        x.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }

    /// Uniform in (0, 1]: never 0, so that `ln` is finite.
    pub fn uniform(&mut self) -> f64 {
        #[allow(clippy::cast_precision_loss)] // 53 bits fit f64 exactly
        let k = (self.next_u64() >> 11) as f64;
        (k + 1.0) / 9_007_199_254_740_992.0
    }

    /// A standard normal sample (Box-Muller, both halves used).
    pub fn gauss(&mut self) -> f64 {
        if let Some(s) = self.spare.take() {
            return s;
        }
        let r = (-2.0 * self.uniform().ln()).sqrt();
        let a = 2.0 * std::f64::consts::PI * self.uniform();
        self.spare = Some(r * a.sin());
        r * a.cos()
    }

    /// Four independent `N(0, sigma^2)` pixel errors.
    pub fn pixel_noise(&mut self, sigma: f64) -> Measurement {
        Measurement::new(self.gauss(), self.gauss(), self.gauss(), self.gauss()) * sigma
    }
}

/// Sample covariance of 3-vectors.
pub fn sample_covariance(samples: &[Vector3<f64>]) -> (Vector3<f64>, Matrix3<f64>) {
    #[allow(clippy::cast_precision_loss)]
    let n = samples.len() as f64;
    let mean = samples.iter().fold(Vector3::zeros(), |a, s| a + s) / n;
    let cov = samples.iter().fold(Matrix3::zeros(), |a, s| {
        let d = s - mean;
        a + d * d.transpose()
    }) / (n - 1.0);
    (mean, cov)
}

/// Compares a Monte Carlo covariance with a predicted one: each standard deviation within
/// `rel_sigma` (relative), each correlation coefficient within `abs_corr`.
pub fn assert_covariance_matches(
    what: &str,
    predicted: &Matrix3<f64>,
    sampled: &Matrix3<f64>,
    rel_sigma: f64,
    abs_corr: f64,
) {
    for i in 0..3 {
        let (sp, ss) = (predicted[(i, i)].sqrt(), sampled[(i, i)].sqrt());
        assert!(
            (sp - ss).abs() <= rel_sigma * sp,
            "{what}: sigma[{i}] predicted {sp:.6e}, Monte Carlo {ss:.6e} ({:+.2}%)\npredicted {predicted:.6e}\nsampled {sampled:.6e}",
            100.0 * (ss - sp) / sp
        );
        // Variances (the diagonal) likewise, at twice the tolerance.
        let (vp, vs) = (predicted[(i, i)], sampled[(i, i)]);
        assert!(
            (vp - vs).abs() <= 2.0 * rel_sigma * vp,
            "{what}: var[{i}] predicted {vp:.6e}, Monte Carlo {vs:.6e}"
        );
    }
    for i in 0..3 {
        for j in (i + 1)..3 {
            let rp = predicted[(i, j)] / (predicted[(i, i)] * predicted[(j, j)]).sqrt();
            let rs = sampled[(i, j)] / (sampled[(i, i)] * sampled[(j, j)]).sqrt();
            assert!(
                (rp - rs).abs() <= abs_corr,
                "{what}: correlation[{i},{j}] predicted {rp:.4}, Monte Carlo {rs:.4}"
            );
        }
    }
}
