//! Every analytic Jacobian of the rig model against central differences (relative step 1e-6),
//! over a few hundred random valid configurations: any pose and heading, landmarks 1.5..4 m
//! above the camera and in view, cameras around the nominal one with mounts within 0.5 m and
//! 0.4 rad. Each block, and each camera parameter on its own, is named in the failure message.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use crate::common;

use common::{Case, case_strategy, central, check_column};
use nalgebra::Vector3;
use proptest::prelude::*;
use rig_model::{
    CameraParams, Measurement, Param, Pose2, project, project_with_jacobians, triangulate,
};

/// The measurements of `landmark`, panicking only if a test case left the field of view (the
/// strategy keeps it inside, and the steps are tiny).
fn measure(c: &CameraParams, pose: &Pose2, landmark: &Vector3<f64>) -> Measurement {
    project(c, pose, landmark).expect("test landmark in view")
}

fn with_param(c: &CameraParams, p: Param, value: f64) -> CameraParams {
    let mut c = *c;
    c.set(p, value);
    c
}

fn check_projection(case: &Case) -> Result<(), TestCaseError> {
    let Case {
        camera: c,
        pose,
        landmark,
    } = *case;
    let (z, jac) = project_with_jacobians(&c, &pose, &landmark).expect("in view");
    prop_assert_eq!(
        z,
        measure(&c, &pose, &landmark),
        "project and project_with_jacobians agree"
    );

    // Pose block: X, Y, theta.
    let pose_cols = [
        (
            "pose X",
            central(pose.x, |v| measure(&c, &Pose2 { x: v, ..pose }, &landmark)),
        ),
        (
            "pose Y",
            central(pose.y, |v| measure(&c, &Pose2 { y: v, ..pose }, &landmark)),
        ),
        (
            "pose theta",
            central(pose.theta, |v| {
                measure(&c, &Pose2 { theta: v, ..pose }, &landmark)
            }),
        ),
    ];
    for (k, (name, numeric)) in pose_cols.iter().enumerate() {
        check_column(name, &jac.pose.column(k).into_owned(), numeric)?;
    }

    // Landmark block: world x, y, z.
    for (k, name) in ["landmark x", "landmark y", "landmark z"]
        .into_iter()
        .enumerate()
    {
        let numeric = central(landmark[k], |v| {
            let mut l = landmark;
            l[k] = v;
            measure(&c, &pose, &l)
        });
        check_column(name, &jac.landmark.column(k).into_owned(), &numeric)?;
    }

    // Each camera parameter on its own.
    for p in Param::ALL {
        let numeric = central(c.get(p), |v| {
            measure(&with_param(&c, p, v), &pose, &landmark)
        });
        check_column(
            &format!("camera parameter {p}"),
            &jac.camera.column(p.index()).into_owned(),
            &numeric,
        )?;
    }
    Ok(())
}

fn check_triangulation(case: &Case) -> Result<(), TestCaseError> {
    let Case {
        camera: c,
        pose,
        landmark,
    } = *case;
    let z = measure(&c, &pose, &landmark);
    let tri = triangulate(&c, &z).expect("positive disparity");
    let p_rig = |c: &CameraParams, z: &Measurement| triangulate(c, z).expect("valid").p_in_rig;

    // d p_in_rig / d (uL, vL, uR, vR).
    for (k, name) in ["uL", "vL", "uR", "vR"].into_iter().enumerate() {
        let numeric = central(z[k], |v| {
            let mut zz = z;
            zz[k] = v;
            p_rig(&c, &zz)
        });
        check_column(
            &format!("triangulation jac_measurement column {name}"),
            &tri.jac_measurement.column(k).into_owned(),
            &numeric,
        )?;
    }

    // d p_in_rig / d C: f, cx, cy, baseline vary, the mount does not enter p_in_rig.
    for p in Param::ALL {
        let numeric = central(c.get(p), |v| p_rig(&with_param(&c, p, v), &z));
        check_column(
            &format!("triangulation jac_camera column {p}"),
            &tri.jac_camera.column(p.index()).into_owned(),
            &numeric,
        )?;
    }

    // d p_in_world / d (X, Y, theta), measurement fixed.
    let jac_pose = tri.jac_pose(&c, &pose);
    let pose_cols = [
        (
            "X",
            central(pose.x, |v| tri.p_in_world(&c, &Pose2 { x: v, ..pose })),
        ),
        (
            "Y",
            central(pose.y, |v| tri.p_in_world(&c, &Pose2 { y: v, ..pose })),
        ),
        (
            "theta",
            central(pose.theta, |v| {
                tri.p_in_world(&c, &Pose2 { theta: v, ..pose })
            }),
        ),
    ];
    for (k, (name, numeric)) in pose_cols.iter().enumerate() {
        check_column(
            &format!("triangulation jac_pose column {name}"),
            &jac_pose.column(k).into_owned(),
            numeric,
        )?;
    }

    // d p_in_world / d C, all ten columns, measurement fixed.
    let jac_c = tri.jac_camera_in_world(&c, &pose);
    for p in Param::ALL {
        let numeric = central(c.get(p), |v| {
            let cc = with_param(&c, p, v);
            triangulate(&cc, &z).expect("valid").p_in_world(&cc, &pose)
        });
        check_column(
            &format!("triangulation jac_camera_in_world column {p}"),
            &jac_c.column(p.index()).into_owned(),
            &numeric,
        )?;
    }
    Ok(())
}

proptest! {
    #![proptest_config(common::config(400))]

    /// Pose, landmark and each of the ten camera columns of `project_with_jacobians`.
    #[test]
    fn projection_jacobians_match_central_differences(case in case_strategy()) {
        check_projection(&case)?;
    }

    /// `jac_measurement`, `jac_camera`, `jac_pose` and `jac_camera_in_world` of the
    /// triangulation.
    #[test]
    fn triangulation_jacobians_match_central_differences(case in case_strategy()) {
        check_triangulation(&case)?;
    }
}

/// The landmark Jacobian is minus the translation part of the pose Jacobian rotated into the
/// world (moving the robot by `d` is moving the landmark by `-d`), an independent identity.
#[test]
fn landmark_and_pose_translation_jacobians_are_opposite() {
    let c = common::nominal_camera();
    let pose = Pose2::new(3.0, -2.0, 0.7);
    let landmark = common::landmark_at(&c, &pose, 500.0, 100.0, 2.5);
    let (_, jac) = project_with_jacobians(&c, &pose, &landmark).unwrap();
    for k in 0..2 {
        let diff = jac.pose.column(k) + jac.landmark.column(k);
        assert!(diff.norm() < 1e-12, "column {k}: {diff:?}");
    }
}
