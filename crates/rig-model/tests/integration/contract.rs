//! The geometry facts of vehicle-interfaces.md section 1 (frames, mount angles, disparity),
//! the errors for points behind the cameras and non-positive disparity, and NaN safety.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use crate::common;

use common::{case_strategy, nominal_camera};
use nalgebra::Vector3;
use proptest::prelude::*;
use rig_model::{
    CameraParams, Measurement, Mount, Param, Pose2, RigError, point_in_rig, project,
    project_with_jacobians, triangulate,
};
use std::f64::consts::FRAC_PI_2;

fn mount(x: f64, y: f64, z: f64, roll: f64, pitch: f64, yaw: f64) -> CameraParams {
    CameraParams {
        vehicle: Default::default(),
        mount: Mount {
            x,
            y,
            z,
            roll,
            pitch,
            yaw,
        },
        ..nominal_camera()
    }
}

/// The world point at `p_in_robot` for the robot at `pose`.
fn world(pose: &Pose2, p_in_robot: [f64; 3]) -> Vector3<f64> {
    pose.point_in_world(&Vector3::from(p_in_robot))
}

fn assert_close(what: &str, a: f64, b: f64, tol: f64) {
    assert!(
        (a - b).abs() <= tol,
        "{what}: {a} vs {b} (diff {})",
        (a - b).abs()
    );
}

proptest! {
    #![proptest_config(common::config(300))]

    /// Disparity `uL - uR = f B / zs` and `vL == vR` exactly, for any valid configuration.
    #[test]
    fn disparity_is_f_b_over_depth_and_rows_agree(case in case_strategy()) {
        let (c, pose, l) = (case.camera, case.pose, case.landmark);
        let z = project(&c, &pose, &l).unwrap();
        let zs = point_in_rig(&c, &pose, &l).z;
        let expected = c.f * c.baseline / zs;
        prop_assert!(((z[0] - z[2]) - expected).abs() <= 1e-9 * expected, "{} vs {expected}", z[0] - z[2]);
        prop_assert_eq!(z[1], z[3]);
        // The formula of section 1, written out independently of `point_in_rig`.
        let rz = nalgebra::Rotation3::from_axis_angle(&Vector3::z_axis(), -pose.theta);
        let p_r = rz * (l - Vector3::new(pose.x, pose.y, 0.0));
        let m = c.mount;
        let r_rs = nalgebra::Rotation3::from_axis_angle(&Vector3::z_axis(), m.yaw)
            * nalgebra::Rotation3::from_axis_angle(&Vector3::y_axis(), m.pitch)
            * nalgebra::Rotation3::from_axis_angle(&Vector3::x_axis(), m.roll);
        let s = r_rs.inverse() * (p_r - Vector3::new(m.x, m.y, m.z));
        let uv = [
            c.cx + c.f * (s.x + c.baseline / 2.0) / s.z,
            c.cy + c.f * s.y / s.z,
            c.cx + c.f * (s.x - c.baseline / 2.0) / s.z,
            c.cy + c.f * s.y / s.z,
        ];
        for k in 0..4 {
            prop_assert!((z[k] - uv[k]).abs() <= 1e-9 * uv[k].abs(), "measurement {k}: {} vs {}", z[k], uv[k]);
        }
    }

    /// Every mount rotation is a proper rotation equal to Rz(yaw) Ry(pitch) Rx(roll).
    #[test]
    fn mount_rotation_is_yaw_pitch_roll(case in case_strategy()) {
        let m = case.camera.mount;
        let r = m.robot_from_rig_rotation();
        prop_assert!((r * r.transpose() - nalgebra::Matrix3::identity()).norm() < 1e-12);
        prop_assert!((r.determinant() - 1.0).abs() < 1e-12);
        let expected = nalgebra::Rotation3::from_euler_angles(m.roll, m.pitch, m.yaw);
        prop_assert!((r - expected.matrix()).norm() < 1e-12);
    }
}

/// Parameter names are those of the contract, in its order, and `Display` prints them.
#[test]
fn parameter_names_follow_the_contract() {
    let names: Vec<String> = Param::ALL.iter().map(ToString::to_string).collect();
    assert_eq!(
        names,
        [
            "f",
            "cx",
            "cy",
            "baseline",
            "mount_x",
            "mount_y",
            "mount_z",
            "mount_roll",
            "mount_pitch",
            "mount_yaw",
            "odom_scale",
            "odom_yaw_scale",
            "odom_yaw_bias",
            "time_offset"
        ]
    );
    assert_eq!(rig_model::N_PARAMS, 14);
    assert!(Param::CAMERA.iter().all(|p| !p.is_vehicle()));
    assert!(Param::VEHICLE.iter().all(|p| p.is_vehicle()));
    assert_eq!(
        Param::CAMERA
            .iter()
            .chain(&Param::VEHICLE)
            .copied()
            .collect::<Vec<_>>(),
        Param::ALL
    );
}

/// All mount angles zero: optical axis straight up and rig x = robot x. A point straight
/// above the rig projects to `(cx + fB/2z, cy, cx - fB/2z, cy)`, whatever the mount offset
/// and the robot's pose.
#[test]
fn zero_angles_look_straight_up() {
    let c = mount(0.3, -0.2, 1.1, 0.0, 0.0, 0.0);
    for pose in [
        Pose2::default(),
        Pose2::new(5.0, -3.0, 2.0),
        Pose2::new(-1.0, 8.0, -4.0),
    ] {
        for h in [0.5, 2.0, 7.5] {
            let l = world(&pose, [0.3, -0.2, 1.1 + h]);
            let z = project(&c, &pose, &l).unwrap();
            let half = c.f * c.baseline / (2.0 * h);
            assert_close("uL", z[0], c.cx + half, 1e-9);
            assert_close("vL", z[1], c.cy, 1e-9);
            assert_close("uR", z[2], c.cx - half, 1e-9);
            assert_close("vR", z[3], c.cy, 1e-9);
        }
    }
    // Robot forward (+x) is image +u, robot left (+y) is image +v.
    let pose = Pose2::new(2.0, 1.0, 0.5);
    let ahead = project(&c, &pose, &world(&pose, [1.3, -0.2, 3.1])).unwrap();
    assert!(
        ahead[0] > c.cx && ahead[2] > c.cx,
        "ahead must be right of centre: {ahead:?}"
    );
    assert_close("ahead: v", ahead[1], c.cy, 1e-9);
    let left = project(&c, &pose, &world(&pose, [0.3, 0.8, 3.1])).unwrap();
    assert!(
        left[1] > c.cy,
        "left must be below centre (v grows along rig +y): {left:?}"
    );
    assert_close("left: (uL + uR) / 2", (left[0] + left[2]) / 2.0, c.cx, 1e-9);
}

/// Positive pitch tilts the optical axis toward the robot's front: the point on the robot ray
/// `(sin p, 0, cos p)` from the rig is on the optical axis, and a point ahead of and above the
/// robot moves toward the image centre as pitch grows from 0 to its direction.
#[test]
fn positive_pitch_tilts_the_axis_forward() {
    for pitch in [0.1, 0.3, -0.2] {
        let c = mount(0.0, 0.0, 1.0, 0.0, pitch, 0.0);
        let l = world(
            &Pose2::default(),
            [2.0 * pitch.sin(), 0.0, 1.0 + 2.0 * pitch.cos()],
        );
        let z = project(&c, &Pose2::default(), &l).unwrap();
        assert_close(
            &format!("pitch {pitch}: centre u"),
            (z[0] + z[2]) / 2.0,
            c.cx,
            1e-9,
        );
        assert_close(&format!("pitch {pitch}: v"), z[1], c.cy, 1e-9);
    }
    // A lamp 1 m ahead and 2 m above the camera: its direction is 0.46 rad forward.
    let l = Vector3::new(1.0, 0.0, 3.0);
    let mut last = f64::INFINITY;
    for k in 0..=9 {
        let pitch = 0.05 * f64::from(k);
        let c = mount(0.0, 0.0, 1.0, 0.0, pitch, 0.0);
        let z = project(&c, &Pose2::default(), &l).unwrap();
        let off = (z[0] + z[2]) / 2.0 - c.cx;
        assert!(
            off > 0.0 && off < last,
            "pitch {pitch}: offset {off} px after {last} px"
        );
        assert_close("v stays on the centre row", z[1], c.cy, 1e-9);
        last = off;
    }
}

/// Roll and yaw follow `R_RS = Rz(yaw) Ry(pitch) Rx(roll)`: positive roll tilts the axis toward
/// robot -y (right); yaw pi/2 turns rig x to robot y, so a point to the left is at +u.
#[test]
fn roll_and_yaw_conventions() {
    let roll = 0.3;
    let c = mount(0.0, 0.0, 1.0, roll, 0.0, 0.0);
    let l = world(
        &Pose2::default(),
        [0.0, -2.0 * f64::sin(roll), 1.0 + 2.0 * f64::cos(roll)],
    );
    let z = project(&c, &Pose2::default(), &l).unwrap();
    assert_close("roll: centre u", (z[0] + z[2]) / 2.0, c.cx, 1e-9);
    assert_close("roll: v", z[1], c.cy, 1e-9);

    let c = mount(0.0, 0.0, 1.0, 0.0, 0.0, FRAC_PI_2);
    let z = project(
        &c,
        &Pose2::default(),
        &world(&Pose2::default(), [0.0, 1.0, 3.0]),
    )
    .unwrap();
    assert!(
        (z[0] + z[2]) / 2.0 > c.cx + 100.0,
        "yaw pi/2: left point at {z:?}"
    );
    assert_close("yaw pi/2: v", z[1], c.cy, 1e-9);
}

/// World frame: at the first frame world = robot; a robot at theta = pi/2 sees a point at world
/// +Y as robot-forward, and measures it exactly as a robot at theta = 0 measures a point at +X.
#[test]
fn world_frame_conventions() {
    let c = nominal_camera();
    let p = Vector3::new(1.5, -0.4, 3.0);
    assert_eq!(Pose2::default().point_in_robot(&p), p);
    let (x, y) = (4.0, -2.0);
    let turned = Pose2::new(x, y, FRAC_PI_2);
    let p_r = turned.point_in_robot(&Vector3::new(x, y + 1.0, 3.0));
    assert!(
        (p_r - Vector3::new(1.0, 0.0, 3.0)).norm() < 1e-12,
        "{p_r:?}"
    );
    let a = project(&c, &turned, &Vector3::new(x, y + 1.0, 3.0)).unwrap();
    let b = project(&c, &Pose2::default(), &Vector3::new(1.0, 0.0, 3.0)).unwrap();
    assert!((a - b).norm() < 1e-9, "{a:?} vs {b:?}");
    // Odometry convention of section 2: moving forward at theta = pi/2 increases world Y.
    let fwd = turned.point_in_world(&Vector3::new(1.0, 0.0, 0.0));
    assert!(
        (fwd - Vector3::new(x, y + 1.0, 0.0)).norm() < 1e-12,
        "{fwd:?}"
    );
}

#[test]
fn point_behind_or_level_with_the_cameras_is_an_error_with_its_depth() {
    let c = nominal_camera(); // 1 m up, looking up
    let pose = Pose2::new(1.0, 2.0, 0.3);
    for (height, depth) in [(0.5, -0.5), (1.0, 0.0), (-3.0, -4.0)] {
        let l = world(&pose, [0.2, 0.1, height]);
        let expected = RigError::BehindCamera { depth_m: depth };
        match project(&c, &pose, &l) {
            Err(RigError::BehindCamera { depth_m }) => {
                assert_close("depth", depth_m, depth, 1e-12);
            }
            other => panic!("height {height}: expected {expected:?}, got {other:?}"),
        }
        assert!(matches!(
            project_with_jacobians(&c, &pose, &l),
            Err(RigError::BehindCamera { depth_m }) if (depth_m - depth).abs() < 1e-12
        ));
    }
    let msg = RigError::BehindCamera { depth_m: -0.5 }.to_string();
    assert!(msg.contains("-0.5") && msg.contains("behind"), "{msg}");
}

#[test]
fn non_positive_disparity_is_an_error_with_its_value() {
    let c = nominal_camera();
    for (ul, ur) in [(400.0, 400.0), (390.0, 400.5), (-1.0, 0.0)] {
        let z = Measurement::new(ul, 240.0, ur, 240.0);
        assert_eq!(
            triangulate(&c, &z),
            Err(RigError::NonPositiveDisparity {
                disparity_px: ul - ur
            })
        );
    }
    let msg = RigError::NonPositiveDisparity {
        disparity_px: -10.5,
    }
    .to_string();
    assert!(msg.contains("-10.5"), "{msg}");
}

#[test]
fn triangulation_rejects_bad_focal_length_and_baseline() {
    let z = Measurement::new(400.0, 240.0, 380.0, 240.0);
    for (param, value) in [
        (Param::F, 0.0),
        (Param::F, -700.0),
        (Param::F, f64::INFINITY),
        (Param::Baseline, 0.0),
        (Param::Baseline, -0.12),
        (Param::Baseline, f64::NEG_INFINITY),
    ] {
        let mut c = nominal_camera();
        c.set(param, value);
        assert_eq!(
            triangulate(&c, &z),
            Err(RigError::BadCamera { param, value })
        );
    }
    let mut c = nominal_camera();
    c.f = f64::NAN;
    assert!(matches!(
        triangulate(&c, &z),
        Err(RigError::BadCamera { param: Param::F, value }) if value.is_nan()
    ));
    let msg = RigError::BadCamera {
        param: Param::Baseline,
        value: -0.12,
    }
    .to_string();
    assert!(msg.contains("baseline") && msg.contains("-0.12"), "{msg}");
}

/// `RigError::BadCamera` says f and baseline must be positive and finite, and `triangulate`
/// enforces it; `project` does not, and measures with a negative or NaN focal length or
/// baseline as if nothing were wrong (negative disparity, NaN pixels). Minimal input:
/// `project(&CameraParams { f: f64::NAN, ..nominal }, &Pose2::default(), &(0, 0, 3))` is `Ok`
/// with four NaN pixels.
#[test]

fn projection_rejects_bad_focal_length_and_baseline() {
    let l = Vector3::new(0.0, 0.0, 3.0);
    for (param, value) in [
        (Param::F, f64::NAN),
        (Param::F, -700.0),
        (Param::Baseline, -0.12),
        (Param::Baseline, 0.0),
    ] {
        let mut c = nominal_camera();
        c.set(param, value);
        let r = project(&c, &Pose2::default(), &l);
        assert!(
            matches!(r, Err(RigError::BadCamera { .. })),
            "{param} = {value}: {r:?}"
        );
        let r = project_with_jacobians(&c, &Pose2::default(), &l).map(|(z, _)| z);
        assert!(
            matches!(r, Err(RigError::BadCamera { .. })),
            "{param} = {value}: {r:?}"
        );
    }
}

fn any_f64() -> impl Strategy<Value = f64> {
    prop_oneof![
        Just(f64::NAN),
        Just(f64::INFINITY),
        Just(f64::NEG_INFINITY),
        Just(0.0),
        Just(-0.0),
        Just(f64::MIN_POSITIVE),
        Just(f64::MAX),
        -1e3..1e3f64,
        any::<f64>(),
    ]
}

proptest! {
    #![proptest_config(common::config(2000))]

    /// NaN, infinities and extreme values anywhere never panic: every function returns a value
    /// or an error.
    #[test]
    fn nan_and_extreme_inputs_never_panic(
        cam in proptest::collection::vec(any_f64(), rig_model::N_PARAMS),
        pose in proptest::collection::vec(any_f64(), 3),
        l in proptest::collection::vec(any_f64(), 3),
        z in proptest::collection::vec(any_f64(), 4),
        sigma in any_f64(),
    ) {
        let c = CameraParams::from_vector(&rig_model::ParamVector::from_column_slice(&cam));
        let pose = Pose2::new(pose[0], pose[1], pose[2]);
        let l = Vector3::new(l[0], l[1], l[2]);
        let z = Measurement::from_column_slice(&z);
        let _ = project(&c, &pose, &l);
        let _ = project_with_jacobians(&c, &pose, &l);
        let _ = point_in_rig(&c, &pose, &l);
        for c in [c, nominal_camera()] {
            if let Ok(tri) = triangulate(&c, &z) {
                let _ = tri.covariance_in_rig(sigma);
                let _ = tri.covariance_in_robot(&c, sigma);
                let _ = tri.p_in_world(&c, &pose);
                let pc = nalgebra::Matrix3::from_element(sigma);
                let cc = nalgebra::SMatrix::<f64, { rig_model::N_PARAMS }, { rig_model::N_PARAMS }>::from_element(sigma);
                let _ = tri.covariance_in_world(&c, &pose, sigma, Some(&pc), Some(&cc));
            }
        }
    }

    /// A NaN anywhere in the landmark or pose is an error, never `Ok` with NaN pixels, for
    /// tilted mounts and for a level one.
    #[test]
    fn nan_landmark_or_pose_is_an_error(case in case_strategy(), which in 0usize..6, level in any::<bool>()) {
        let (mut c, mut pose, mut l) = (case.camera, case.pose, case.landmark);
        if level {
            c.mount.roll = 0.0;
            c.mount.pitch = 0.0;
        }
        match which {
            0 => pose.x = f64::NAN,
            1 => pose.y = f64::NAN,
            2 => pose.theta = f64::NAN,
            k => l[k - 3] = f64::NAN,
        }
        let r = project(&c, &pose, &l);
        prop_assert!(r.is_err(), "NaN input {which} (level mount: {level}): {r:?}");
        prop_assert!(project_with_jacobians(&c, &pose, &l).is_err());
    }

    /// A NaN column (uL or uR) is a `NonPositiveDisparity` error with a NaN value.
    #[test]
    fn nan_column_is_a_disparity_error(ul in 0.0..752.0f64, d in 1.0..50.0f64, v in 0.0..480.0f64, right in any::<bool>()) {
        let mut z = Measurement::new(ul, v, ul - d, v);
        z[if right { 2 } else { 0 }] = f64::NAN;
        let r = triangulate(&nominal_camera(), &z);
        prop_assert!(
            matches!(r, Err(RigError::NonPositiveDisparity { disparity_px }) if disparity_px.is_nan()),
            "{r:?}"
        );
    }
}

/// A NaN row (vL or vR) is accepted: `triangulate` returns `Ok` with `ys = NaN` (and NaN in
/// the Jacobians), where a NaN column is an error. Minimal input: nominal camera,
/// `(uL, vL, uR, vR) = (0, NaN, -1, 0)` gives `Ok(p_in_rig = (-45.18, NaN, 84.0))`.
#[test]

fn nan_row_is_an_error() {
    for k in [1, 3] {
        let mut z = Measurement::new(0.0, 0.0, -1.0, 0.0);
        z[k] = f64::NAN;
        let r = triangulate(&nominal_camera(), &z);
        assert!(r.is_err(), "NaN in measurement {k}: {r:?}");
    }
}
