//! The prediction with the vehicle's parameters in the state (vehicle-interfaces.md 1.2):
//! `pose' = pose (+) m(V)`, so `P` moves as `[F G] P [F G]^T + Q` over the pose and V, and the
//! pose's cross-covariance with everything else as `F P_rx + G P_Vx`; checked against the
//! dense product over two predictions.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use crate::common;

use nalgebra::{DMatrix, Matrix3, Matrix3x4};
use rig_model::Param;
use rig_model::odometry::Motion;
use vslam_ekf::{Ekf, Increment, Settings};

#[test]
fn prediction_carries_the_vehicle_parameters_uncertainty_into_the_pose() {
    let estimate = [
        Param::Baseline,
        Param::OdomScale,
        Param::OdomYawBias,
        Param::TimeOffset,
    ];
    let rig = common::rig(common::random_camera(&mut common::rng(3)), &estimate);
    let mut ekf = Ekf::from_prior(&rig, Settings::default()).unwrap();
    let steps = [
        (
            Motion {
                dx: 0.05,
                dy: 0.001,
                dtheta: 0.01,
                dt_s: 0.05,
                samples: 5,
            },
            Matrix3x4::new(
                -0.05, 0.0, 0.0, 0.02, -0.001, 0.0, 0.0, 0.001, 0.0, -0.01, -0.05, 0.003,
            ),
        ),
        (
            Motion {
                dx: 0.04,
                dy: -0.002,
                dtheta: -0.02,
                dt_s: 0.05,
                samples: 5,
            },
            Matrix3x4::new(
                -0.04, 0.0, 0.0, -0.01, 0.002, 0.0, 0.0, 0.0, 0.0, 0.02, -0.05, -0.001,
            ),
        ),
    ];
    for (motion, jv) in steps {
        let inc = Increment {
            motion,
            covariance: Matrix3::from_diagonal(&nalgebra::Vector3::new(1e-6, 2e-6, 3e-7)),
        };
        let before = ekf.covariance();
        let theta = ekf.pose().theta;
        let n = before.nrows();
        // Dense Jacobian of the whole state.
        let mut f = DMatrix::<f64>::identity(n, n);
        let (s, c) = (theta.sin(), theta.cos());
        f[(0, 2)] = -s * motion.dx - c * motion.dy;
        f[(1, 2)] = c * motion.dx - s * motion.dy;
        let rot = Matrix3::new(c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0);
        for p in estimate.iter().filter(|p| p.is_vehicle()) {
            let col = ekf.camera_state_index(*p).unwrap();
            let g = rot * jv.column(p.index() - rig_model::N_CAMERA);
            for r in 0..3 {
                f[(r, col)] = g[r];
            }
        }
        let mut q = DMatrix::<f64>::zeros(n, n);
        let qr = rot * inc.covariance * rot.transpose();
        for r in 0..3 {
            for k in 0..3 {
                q[(r, k)] = qr[(r, k)];
            }
        }
        let want = &f * &before * f.transpose() + q;
        ekf.predict_increment_vehicle(&inc, &jv).unwrap();
        let got = ekf.covariance();
        let err = (&got - &want).amax();
        assert!(err <= 1e-12 * want.amax(), "max difference {err}");
    }
    // The pose now carries the odometry scale's uncertainty.
    assert!(ekf.pose_covariance()[(0, 0)] > 1e-6);
}
