//! The simulator's vehicle errors (vehicle-interfaces.md 1.2): odometry scale, yaw-rate scale
//! and bias on the reported odometry, and the board's clock offset on the frames' stamps, with
//! the truth's V saying so.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::Path;

#[test]
fn odometry_errors_and_the_clock_offset_are_applied_and_told() {
    let path =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/scenarios/aisle-vehicle.toml");
    let mut sc = sim::Scenario::load(&path).unwrap();
    // Noise off: the reported odometry is exactly the truth through V.
    sc.spec.noise.velocity_mps = 0.0;
    sc.spec.noise.yaw_rate_radps = 0.0;
    let run = sim::simulate(&sc, sim::Mode::Fast).unwrap();
    let v = run.camera.vehicle;
    assert_eq!(
        (
            v.odom_scale,
            v.odom_yaw_scale,
            v.odom_yaw_bias,
            v.time_offset
        ),
        (1.015, 1.005, 0.002, 0.012)
    );
    for (m, t) in run.odometry.iter().zip(&run.odometry_truth) {
        assert_eq!(m.t_us, t.t_us);
        let (vx, vy, vtheta) = v.reported_velocities(t.vx, t.vy, t.vtheta);
        assert!((m.vx - vx).abs() < 1e-12 && (m.vy - vy).abs() < 1e-12);
        assert!((m.vtheta - vtheta).abs() < 1e-12);
    }
    // Frames exposed at the camera's ticks (on the odometry clock), stamped 12 ms later.
    let rates = &sc.spec.rates;
    for (k, f) in run.frames.iter().enumerate().take(50) {
        let exposed = rates.start_t_us + (k as u64) * 50_000;
        assert_eq!(f.t_us, exposed + 12_000, "frame {k}");
    }
    // The truth in the log says so too.
    let truth = sim::run::truth_camera(&run.camera);
    assert_eq!(truth.time_offset, 0.012);
    assert_eq!(truth.odom_yaw_scale, 1.005);
}
