//! Shared helpers of the filter tests: random rigs with tilted and rotated mounts, filters
//! with correlated covariances, the measurement function of the state written out from the
//! documented layout (independent of the filter's own code), and a dense textbook EKF.
#![allow(dead_code, unreachable_pub)]

use nalgebra::{DMatrix, DVector, Matrix3, Vector3, Vector4};
use rand::{Rng, RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use rig_model::camera::{CameraParams, Mount, N_PARAMS, Param, Pose2};
use rig_model::config::{Noise, Rig};
use rig_model::{Measurement, project};
use vslam_ekf::{CameraCovariance, CameraStart, Ekf, LandmarkId, Settings};

pub type TestRng = ChaCha8Rng;

pub fn rng(seed: u64) -> TestRng {
    ChaCha8Rng::seed_from_u64(seed)
}

pub fn normal(rng: &mut TestRng) -> f64 {
    StandardNormal.sample(rng)
}

pub fn uniform(rng: &mut TestRng, lo: f64, hi: f64) -> f64 {
    lo + (hi - lo) * rng.random::<f64>()
}

/// 1-sigma prior of each parameter for the random rigs.
pub fn prior_sigma(p: Param) -> f64 {
    match p {
        Param::F => 20.0,
        Param::Cx | Param::Cy => 5.0,
        Param::Baseline => 0.005,
        Param::MountX | Param::MountY | Param::MountZ => 0.02,
        Param::MountRoll | Param::MountPitch | Param::MountYaw => 0.02,
        Param::OdomScale | Param::OdomYawScale => 0.02,
        Param::OdomYawBias => 0.005,
        Param::TimeOffset => 0.02,
    }
}

pub fn noise() -> Noise {
    Noise::white(0.3, 0.02, 0.01)
}

pub fn rig(nominal: CameraParams, estimate: &[Param]) -> Rig {
    let mut prior = [None; N_PARAMS];
    for &p in estimate {
        prior[p.index()] = Some(prior_sigma(p));
    }
    Rig {
        lens: None,
        board: rig_model::Board::DEFAULT,
        width: 752,
        height: 480,
        nominal,
        estimate: estimate.to_vec(),
        prior,
        noise: noise(),
    }
}

/// A camera with a tilted and rotated mount.
pub fn random_camera(rng: &mut TestRng) -> CameraParams {
    CameraParams {
        vehicle: Default::default(),
        f: uniform(rng, 650.0, 750.0),
        cx: uniform(rng, 360.0, 390.0),
        cy: uniform(rng, 230.0, 250.0),
        baseline: uniform(rng, 0.1, 0.14),
        mount: Mount {
            x: uniform(rng, -0.3, 0.3),
            y: uniform(rng, -0.2, 0.2),
            z: uniform(rng, 0.6, 1.2),
            roll: uniform(rng, -0.3, 0.3),
            pitch: uniform(rng, -0.4, 0.4),
            yaw: uniform(rng, -1.0, 1.0),
        },
    }
}

/// A random subset of the camera parameters, in a random order, `count` of them.
pub fn random_estimate(rng: &mut TestRng, count: usize) -> Vec<Param> {
    let mut all = Param::CAMERA.to_vec();
    for i in (1..all.len()).rev() {
        let j = rng.random_range(0..=i);
        all.swap(i, j);
    }
    all.truncate(count);
    all
}

/// A world point seen at pixel `(u, v)` of the left image at depth `depth` along the optical
/// axis, from `pose`.
pub fn point_in_view(c: &CameraParams, pose: &Pose2, u: f64, v: f64, depth: f64) -> Vector3<f64> {
    let p_rig = Vector3::new(
        (u - c.cx) * depth / c.f - c.baseline / 2.0,
        (v - c.cy) * depth / c.f,
        depth,
    );
    let p_robot = c.mount.translation() + c.mount.robot_from_rig_rotation() * p_rig;
    pose.point_in_world(&p_robot)
}

pub fn random_point_in_view(rng: &mut TestRng, c: &CameraParams, pose: &Pose2) -> Vector3<f64> {
    let u = uniform(rng, 150.0, 600.0);
    let v = uniform(rng, 100.0, 380.0);
    let depth = uniform(rng, 1.5, 4.0);
    point_in_view(c, pose, u, v, depth)
}

pub fn noisy(rng: &mut TestRng, z: &Measurement, sigma: f64) -> Measurement {
    z + Vector4::from_fn(|_, _| sigma * normal(rng))
}

/// A random symmetric positive definite covariance of the estimated parameters (their prior
/// sigmas, random correlations).
pub fn random_camera_covariance(rng: &mut TestRng, estimate: &[Param]) -> CameraCovariance {
    let m = estimate.len();
    let b = DMatrix::from_fn(m, m, |_, _| normal(rng));
    let corr = &b * b.transpose() + DMatrix::identity(m, m) * (m as f64);
    let d = DVector::from_fn(m, |i, _| 1.0 / corr[(i, i)].sqrt());
    let mut cov = CameraCovariance::zeros();
    for (a, pa) in estimate.iter().enumerate() {
        for (bb, pb) in estimate.iter().enumerate() {
            cov[(pa.index(), pb.index())] =
                corr[(a, bb)] * d[a] * d[bb] * prior_sigma(*pa) * prior_sigma(*pb);
        }
    }
    cov
}

/// The measurement of landmark `slot` written out from the documented state layout
/// `[X, Y, theta, L_1..L_N, C_est]`, with `base` supplying the parameters not estimated.
pub fn h_of_state(
    x: &DVector<f64>,
    estimate: &[Param],
    base: &CameraParams,
    landmark_index: usize,
) -> Measurement {
    let pose = Pose2::new(x[0], x[1], x[2]);
    let c = camera_of_state(x, estimate, base);
    let l = Vector3::new(
        x[landmark_index],
        x[landmark_index + 1],
        x[landmark_index + 2],
    );
    project(&c, &pose, &l).expect("landmark in view")
}

pub fn camera_of_state(x: &DVector<f64>, estimate: &[Param], base: &CameraParams) -> CameraParams {
    let c0 = x.len() - estimate.len();
    let mut c = *base;
    for (k, p) in estimate.iter().enumerate() {
        c.set(*p, x[c0 + k]);
    }
    c
}

/// A filter on a random tilted rig with `landmarks` landmarks and correlations everywhere:
/// a random start pose covariance, landmarks added along a short drive with updates between.
pub struct Setup {
    pub ekf: Ekf,
    /// The camera the measurements are made with.
    pub truth: CameraParams,
    /// True landmark positions, by id.
    pub points: Vec<(LandmarkId, Vector3<f64>)>,
    /// True pose.
    pub pose: Pose2,
}

pub fn setup(seed: u64, estimated: usize, landmarks: usize, settings: Settings) -> Setup {
    let mut rng = rng(seed);
    let truth = random_camera(&mut rng);
    let estimate = random_estimate(&mut rng, estimated);
    let mut start_camera = truth;
    for p in &estimate {
        start_camera.set(*p, truth.get(*p) + prior_sigma(*p) * normal(&mut rng));
    }
    let rig = rig(truth, &estimate);
    let start = CameraStart {
        camera: start_camera,
        covariance: random_camera_covariance(&mut rng, &estimate),
    };
    let mut ekf = Ekf::new(&rig, &start, settings).expect("valid start");
    let b = Matrix3::from_fn(|_, _| 0.01 * normal(&mut rng));
    let pose = Pose2::new(0.1, -0.2, 0.3);
    ekf.set_start_pose(pose, &(b * b.transpose()))
        .expect("valid pose");
    let mut s = Setup {
        ekf,
        truth,
        points: Vec::new(),
        pose,
    };
    for k in 0..landmarks {
        let p = random_point_in_view(&mut rng, &truth, &s.pose);
        let z = project(&truth, &s.pose, &p).expect("in view");
        let id = s.ekf.add_landmark(&noisy(&mut rng, &z, 0.3)).expect("adds");
        s.points.push((id, p));
        if k % 2 == 1 {
            drive(&mut s, &mut rng, 0.1, 0.02, 0.05);
        }
    }
    s
}

/// Moves the true pose and predicts the filter with the odometry (noiseless truth), then
/// updates with every landmark still in view.
pub fn drive(s: &mut Setup, rng: &mut TestRng, vx: f64, vtheta: f64, dt: f64) {
    let m = rig_model::odometry::constant_velocity_motion(vx, 0.0, vtheta, dt);
    s.pose = m.apply(&s.pose);
    s.ekf.predict(vx, 0.0, vtheta, dt).expect("predicts");
    let batch: Vec<(LandmarkId, Measurement)> = s
        .points
        .iter()
        .filter(|(id, _)| s.ekf.contains(*id))
        .filter_map(|(id, p)| {
            let z = project(&s.truth, &s.pose, p).ok()?;
            Some((*id, noisy(rng, &z, 0.3)))
        })
        .collect();
    s.ekf.update(&batch).expect("updates");
}

/// The textbook EKF update with dense `H` and the Joseph form, for comparison.
pub fn dense_update(
    ekf: &Ekf,
    batch: &[(LandmarkId, Measurement)],
) -> (DVector<f64>, DMatrix<f64>) {
    let n = ekf.state_len();
    let k = batch.len();
    let mut h = DMatrix::zeros(4 * k, n);
    let mut nu = DVector::zeros(4 * k);
    for (j, (id, z)) in batch.iter().enumerate() {
        let (zhat, hj) = ekf.update_jacobian(*id).expect("known");
        h.view_mut((4 * j, 0), (4, n)).copy_from(&hj);
        nu.rows_mut(4 * j, 4).copy_from(&(z - zhat));
    }
    let p = &ekf.covariance();
    let r = DMatrix::identity(4 * k, 4 * k) * ekf.noise().pixel.powi(2);
    let s = &h * p * h.transpose() + &r;
    let s_inv = s.try_inverse().expect("invertible S");
    let gain = p * h.transpose() * s_inv;
    let i_kh = DMatrix::identity(n, n) - &gain * &h;
    let p_new = &i_kh * p * i_kh.transpose() + &gain * r * gain.transpose();
    let mut x_new = ekf.state() + gain * nu;
    x_new[2] = wrap(x_new[2]);
    (x_new, p_new)
}

pub fn wrap(a: f64) -> f64 {
    let w = a.sin().atan2(a.cos());
    if w <= -std::f64::consts::PI {
        w + 2.0 * std::f64::consts::PI
    } else {
        w
    }
}

pub fn max_abs(m: &DMatrix<f64>) -> f64 {
    m.iter().fold(0.0, |a: f64, v| a.max(v.abs()))
}

/// Full symmetric positive definiteness: exact symmetry and a Cholesky factorisation.
pub fn assert_spd(p: &DMatrix<f64>) {
    assert_eq!(p, &p.transpose(), "P not exactly symmetric");
    assert!(
        p.clone().cholesky().is_some(),
        "P not positive definite: smallest eigenvalue {}",
        p.clone().symmetric_eigenvalues().min()
    );
}

/// Silences the unused warning for `Rng` when a test file does not draw integers.
pub fn _uses(rng: &mut TestRng) -> u32 {
    rng.next_u32()
}
