//! Projection and triangulation undo each other: a world landmark projected and triangulated
//! comes back (via `p_in_world`) to 1e-9 relative, and so does a point given in the rig frame.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use crate::common;

use common::{camera_strategy, case_strategy};
use nalgebra::Vector3;
use proptest::prelude::*;
use rig_model::rig::project_rig_point;
use rig_model::{point_in_rig, project, project_with_jacobians, triangulate};

fn close(a: &Vector3<f64>, b: &Vector3<f64>, rel: f64) -> bool {
    (a - b).norm() <= rel * b.norm().max(1.0)
}

proptest! {
    #![proptest_config(common::config(500))]

    /// `triangulate(project(L)).p_in_world == L`, and `p_in_robot`, `p_in_rig` agree with the
    /// forward chain.
    #[test]
    fn world_landmark_round_trip(case in case_strategy()) {
        let (c, pose, l) = (case.camera, case.pose, case.landmark);
        let z = project(&c, &pose, &l).unwrap();
        let tri = triangulate(&c, &z).unwrap();
        let back = tri.p_in_world(&c, &pose);
        prop_assert!(close(&back, &l, 1e-9), "L {l:?} came back as {back:?}");
        let p_rig = point_in_rig(&c, &pose, &l);
        prop_assert!(close(&tri.p_in_rig, &p_rig, 1e-9), "rig {p_rig:?} vs {:?}", tri.p_in_rig);
        let p_robot = pose.point_in_robot(&l);
        prop_assert!(close(&tri.p_in_robot(&c), &p_robot, 1e-9));
        // And the Jacobian version measures the same.
        let (z2, _) = project_with_jacobians(&c, &pose, &l).unwrap();
        prop_assert_eq!(z, z2);
    }

    /// A rig-frame point (anywhere in front, even far outside the image) projects and
    /// triangulates back to itself.
    #[test]
    fn rig_point_round_trip(
        c in camera_strategy(),
        x in -5.0..5.0f64,
        y in -5.0..5.0f64,
        zs in 0.05..50.0f64,
    ) {
        let p = Vector3::new(x, y, zs);
        let z = project_rig_point(&c, &p).unwrap();
        let back = triangulate(&c, &z).unwrap().p_in_rig;
        prop_assert!(close(&back, &p, 1e-9), "{p:?} came back as {back:?}");
    }

    /// A measurement triangulated and projected again gives the same four pixels when it is
    /// consistent (vL == vR).
    #[test]
    fn measurement_round_trip(
        c in camera_strategy(),
        ul in 0.0..752.0f64,
        disparity in 0.5..120.0f64,
        v in 0.0..480.0f64,
    ) {
        let z = rig_model::Measurement::new(ul, v, ul - disparity, v);
        let p = triangulate(&c, &z).unwrap().p_in_rig;
        let again = project_rig_point(&c, &p).unwrap();
        prop_assert!((again - z).norm() <= 1e-9 * z.norm(), "{z:?} -> {p:?} -> {again:?}");
    }
}
