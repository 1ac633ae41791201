//! The odometry's errors with memory as states of the filter (`vslam_ekf::errors`,
//! `Settings::odometry_error_states`) against the default white equivalent: drives under a
//! ceiling of lamps (straights and U-turns, or one long straight), the reported velocities
//! carrying a real vehicle's odometry scale, yaw scale and bias and first-order Gauss-Markov
//! errors of 0.6 s (the simulator's process, vehicle-interfaces.md section 2; the rig states
//! the time constant), the filter estimating the vehicle's parameters and mapping the lamps as
//! it goes, from rest, its speeds changing at 0.4 m/s^2 and rad/s^2. The finding
//! (docs/vehicle.md, "The errors as states"): with the errors as states the odometry scale
//! ends 2 to 5 sigma high on every seed; with the white equivalent (the default) it is honest,
//! and so is the velocity-state form on these drives.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use crate::common;

use nalgebra::Vector3;
use rig_model::camera::{Param, Pose2};
use rig_model::odometry::{OdomSample, constant_velocity_motion, vehicle_jacobian};
use rig_model::project;
use vslam_ekf::{Ekf, LandmarkId, Settings};

/// Each estimated vehicle parameter's error over its sigma at the end of a drive (the clock
/// offset's 0 when it is not estimated).
#[derive(Debug)]
struct End {
    scale: f64,
    yaw_scale: f64,
    yaw_bias: f64,
    offset: f64,
}

impl End {
    fn worst(&self) -> f64 {
        self.scale
            .abs()
            .max(self.yaw_scale.abs())
            .max(self.yaw_bias.abs())
            .max(self.offset.abs())
    }
}

/// How the filter takes the odometry.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Model {
    /// The prediction's input, weighed by the white equivalent (the default).
    WhiteEquivalent,
    /// The prediction's input, its errors as states.
    ErrorStates,
    /// A measurement of the velocities, which are states with the errors.
    VelocityStates,
}

/// (speed m/s, yaw rate rad/s, seconds) of each leg.
type Legs = [(f64, f64, f64)];

/// A straight, a U-turn to the left, a straight back, one to the right: twice.
const LAPS: [(f64, f64, f64); 8] = {
    let u = core::f64::consts::PI / 0.4;
    [
        (0.5, 0.0, 6.0),
        (0.3, 0.4, u),
        (0.5, 0.0, 6.0),
        (0.3, -0.4, u),
        (0.5, 0.0, 6.0),
        (0.3, 0.4, u),
        (0.5, 0.0, 6.0),
        (0.3, -0.4, u),
    ]
};

/// One drive, seeded: frames at 20 Hz, odometry at 100 Hz, the vehicle starting from rest;
/// with `offset_us`, the board's clock that far ahead of the odometry's and the offset
/// estimated.
fn drive(seed: u64, model: Model, legs: &Legs) -> End {
    drive_with_offset(seed, model, legs, 0)
}

fn drive_with_offset(seed: u64, model: Model, legs: &Legs, offset_us: u64) -> End {
    let mut rng = common::rng(seed);
    let mut truth = common::random_camera(&mut rng);
    truth.mount.roll *= 0.1;
    truth.mount.pitch *= 0.1;
    let mut estimate = vec![Param::OdomScale, Param::OdomYawScale, Param::OdomYawBias];
    if offset_us > 0 {
        estimate.push(Param::TimeOffset);
    }
    let mut rig = common::rig(truth, &estimate);
    let tau = 0.6;
    rig.noise.velocity_tau = tau;
    rig.noise.yaw_rate_tau = tau;
    let (scale, yaw_scale, yaw_bias) = (1.01, 1.01, 0.002);
    let settings = Settings {
        odometry_error_states: model == Model::ErrorStates,
        odometry_velocity_states: model == Model::VelocityStates,
        ..Settings::default()
    };
    let mut ekf = Ekf::from_prior(&rig, settings).unwrap();
    // Lamps 3 m above the cameras on a jittered 1.5 m grid.
    let lamps: Vec<Vector3<f64>> = (0..400)
        .map(|k| {
            let (i, j) = (f64::from(k % 20), f64::from(k / 20));
            Vector3::new(
                -6.0 + 1.5 * i + common::uniform(&mut rng, -0.3, 0.3),
                -12.0 + 1.5 * j + common::uniform(&mut rng, -0.3, 0.3),
                truth.mount.z + 3.0,
            )
        })
        .collect();
    let mut ids: Vec<Option<LandmarkId>> = vec![None; lamps.len()];
    // The reported odometry's errors, stationary from the start.
    let sigma = [rig.noise.velocity, rig.noise.velocity, rig.noise.yaw_rate];
    let mut e = sigma.map(|s| s * common::normal(&mut rng));
    let period_us = 10_000_u64;
    let phi = (-1e-6 * period_us as f64 / tau).exp();
    let mut pose = Pose2::default();
    let mut samples: Vec<OdomSample> = Vec::new();
    let mut t_us = 0_u64;
    let mut last_frame: Option<u64> = None;
    // The vehicle's velocities move to each leg's at 0.4 m/s^2 and 0.4 rad/s^2 at most.
    let (mut v, mut w) = (0.0_f64, 0.0_f64);
    let toward = |from: f64, to: f64| from + (to - from).clamp(-0.004, 0.004);
    for &(leg_v, leg_w, secs) in legs {
        for _ in 0..(secs / 0.01).round() as u64 {
            (v, w) = (toward(v, leg_v), toward(w, leg_w));
            samples.push(OdomSample {
                t_us,
                vx: scale * v + e[0],
                vy: e[1],
                vtheta: yaw_scale * w + yaw_bias + e[2],
            });
            for (ek, s) in e.iter_mut().zip(sigma) {
                *ek = phi * *ek + (1.0 - phi * phi).sqrt() * s * common::normal(&mut rng);
            }
            pose = constant_velocity_motion(v, 0.0, w, 0.01).apply(&pose);
            t_us += period_us;
            if !t_us.is_multiple_of(50_000) {
                continue;
            }
            // A frame at t_us: the sample that starts there is not reported yet, and the
            // prediction holds the last one to the frame.
            // Exposed at t_us on the odometry's clock, stamped by the board's.
            let stamp = t_us + offset_us;
            if let Some(t0) = last_frame {
                let v_est = ekf.camera().vehicle;
                let jv = vehicle_jacobian(&samples, t0, stamp, &v_est).unwrap();
                ekf.predict_odometry_vehicle(&samples, (t0, stamp), &rig.noise, &v_est, &jv)
                    .unwrap();
            }
            last_frame = Some(stamp);
            let mut batch = Vec::new();
            let mut new = Vec::new();
            for (k, lamp) in lamps.iter().enumerate() {
                let Ok(z) = project(&truth, &pose, lamp) else {
                    continue;
                };
                let inside = |u: f64, v: f64| u > 20.0 && u < 732.0 && v > 20.0 && v < 460.0;
                if !(inside(z[0], z[1]) && inside(z[2], z[3])) {
                    continue;
                }
                let z = common::noisy(&mut rng, &z, rig.noise.pixel);
                match ids[k] {
                    Some(id) if ekf.contains(id) => batch.push((id, z)),
                    _ => new.push((k, z)),
                }
            }
            ekf.update(&batch).unwrap();
            for (k, z) in new {
                ids[k] = ekf.add_landmark(&z).ok();
            }
        }
    }
    let c = ekf.camera();
    let cov = ekf.camera_covariance();
    let normalised = |p: Param, truth: f64| (c.get(p) - truth) / cov[(p.index(), p.index())].sqrt();
    End {
        scale: normalised(Param::OdomScale, scale),
        yaw_scale: normalised(Param::OdomYawScale, yaw_scale),
        yaw_bias: normalised(Param::OdomYawBias, yaw_bias),
        offset: if offset_us > 0 {
            normalised(Param::TimeOffset, 1e-6 * offset_us as f64)
        } else {
            0.0
        },
    }
}

/// Six seeds of [`LAPS`] under `model` (with a clock offset of `offset_us`, estimated, when
/// not 0): every estimated vehicle parameter inside 3 sigma, or the seeds that are not.
fn assert_honest(model: Model, offset_us: u64) {
    let outside: Vec<String> = (0..6)
        .map(|seed| (seed, drive_with_offset(seed, model, &LAPS, offset_us)))
        .filter(|(_, end)| end.worst() >= 3.0)
        .map(|(seed, end)| format!("seed {seed}: {end:?}"))
        .collect();
    assert!(outside.is_empty(), "{}", outside.join("\n"));
}

/// The default model (the white equivalent of the stated memory): every vehicle parameter
/// inside 3 sigma on six seeds of straights and U-turns.
#[test]
fn the_white_equivalent_keeps_the_vehicle_parameters_honest() {
    assert_honest(Model::WhiteEquivalent, 0);
}

/// The errors as states: the odometry scale ends 3.1 to 4.9 sigma high on all six seeds of
/// the same drives (the yaw scale and bias honest). Not fixed: docs/vehicle.md, "The errors
/// as states". Fails until it is.
#[test]
#[ignore = "the errors as states bias the odometry scale (docs/vehicle.md); fails"]
fn the_error_states_keep_the_vehicle_parameters_honest() {
    assert_honest(Model::ErrorStates, 0);
}

/// The same on one long straight (20 m at 0.5 m/s): the scale 1.7 to 3.7 sigma high (mean
/// 2.8) with the errors as states.
#[test]
#[ignore = "the errors as states bias the odometry scale (docs/vehicle.md); fails"]
fn the_error_states_keep_the_scale_honest_on_a_straight() {
    let scales: Vec<f64> = (0..6)
        .map(|seed| drive(seed, Model::ErrorStates, &[(0.5, 0.0, 40.0)]).scale)
        .collect();
    let mean = scales.iter().sum::<f64>() / 6.0;
    assert!(
        mean.abs() < 1.0,
        "mean normalised scale error {mean:.2}: {scales:?}"
    );
}

/// The velocity-state form (the odometry a measurement of the velocities, `Settings::
/// odometry_velocity_states`, its acceleration 0.2 m/s^2 and rad/s^2 by default): every
/// vehicle parameter inside 3 sigma on the same drives (within 1.6 sigma). With an
/// acceleration of 0.5 the scale ends 1.6 to 3.3 sigma low, with 2.0 about 9 sigma low: the
/// form is honest only while the velocities' model is smooth against the errors'. It fails
/// on the generated halls (docs/vehicle.md, "The velocity-state form").
#[test]
fn the_velocity_states_keep_the_vehicle_parameters_honest() {
    assert_honest(Model::VelocityStates, 0);
}

/// A clock offset of 12 ms estimated as well: the white equivalent keeps it (and the rest)
/// inside 3 sigma.
#[test]
fn the_white_equivalent_keeps_the_clock_offset_honest() {
    assert_honest(Model::WhiteEquivalent, 12_000);
}

/// The velocity-state form with the 12 ms clock offset estimated: the offset ends 35 to 40 ms
/// off at a sigma of 3.5 ms on all six seeds (9.7 to 11 sigma; the other parameters honest).
/// Noise-free odometry recovers it since the state is the frame's mean; with the odometry's
/// errors, every slope of the reported samples tried as its regressor is correlated with the
/// innovation (docs/vehicle.md, "The velocity-state form"). Fails until fixed.
#[test]
#[ignore = "the velocity-state form biases the clock offset (docs/vehicle.md); fails"]
fn the_velocity_states_keep_the_clock_offset_honest() {
    assert_honest(Model::VelocityStates, 12_000);
}
