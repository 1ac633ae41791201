//! Phase 1 on synthetic data made here from the rig model (independent of the simulator):
//! a known rig, a path, noisy stereo measurements and odometry.
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use calib::camera::{CameraParams, Mount, N_PARAMS, Param, Pose2};
use calib::config::{Noise, Rig};
use calib::odometry::{Motion, constant_velocity_motion};
use calib::selfcal::{FramePair, LandmarkPair, SolveStatus, SolverSettings, calibrate};
use common::Rng;
use nalgebra::Vector3;

fn true_camera(pitch: f64) -> CameraParams {
    CameraParams {
        f: 702.0,
        cx: 376.0,
        cy: 240.0,
        baseline: 0.1215,
        mount: Mount {
            x: 0.3,
            y: 0.0,
            z: 1.2,
            roll: 0.0,
            pitch,
            yaw: 0.0,
        },
    }
}

fn rig(nominal: CameraParams, estimate: &[Param]) -> Rig {
    let mut prior = [None; N_PARAMS];
    for p in estimate {
        prior[p.index()] = Some(match p {
            Param::F => 30.0,
            Param::Baseline => 0.01,
            Param::MountX | Param::MountY | Param::MountZ => 0.1,
            _ => 0.05,
        });
    }
    Rig {
        width: 752,
        height: 480,
        nominal,
        estimate: estimate.to_vec(),
        prior,
        noise: Noise {
            pixel: 0.3,
            velocity: 0.02,
            yaw_rate: 0.01,
        },
    }
}

/// Five lamps around the start, 3.5 m above the floor.
fn lamps() -> Vec<Vector3<f64>> {
    vec![
        Vector3::new(1.5, 0.0, 3.5),
        Vector3::new(2.2, 0.7, 3.4),
        Vector3::new(2.0, -0.8, 3.6),
        Vector3::new(1.0, 0.6, 3.5),
        Vector3::new(1.2, -0.5, 3.45),
    ]
}

/// Frame pairs along a slow path (0.2 m/s, turning at `turn_rate`), 20 Hz frames,
/// odometry at 100 Hz with noise, pixel noise 0.3 px.
fn pairs(truth: &CameraParams, turn_rate: f64, seed: u64, frames: usize) -> Vec<FramePair> {
    let mut rng = Rng::new(seed);
    let lamps = lamps();
    let mut pose = Pose2::default();
    let mut out = Vec::new();
    let mut prev: Option<Vec<Option<calib::Measurement>>> = None;
    let mut measured = Motion::default();
    for k in 0..frames {
        // Odometry over 50 ms: 5 samples of 10 ms, each with noise.
        let mut motion = Motion::default();
        let mut true_motion = Motion::default();
        let w = turn_rate * if (k / 40) % 2 == 0 { 1.0 } else { -1.0 };
        for _ in 0..5 {
            true_motion = true_motion.then(&constant_velocity_motion(0.2, 0.0, w, 0.01));
            motion = motion.then(&constant_velocity_motion(
                0.2 + 0.02 * rng.gauss(),
                0.02 * rng.gauss(),
                w + 0.01 * rng.gauss(),
                0.01,
            ));
        }
        let seen: Vec<Option<calib::Measurement>> = lamps
            .iter()
            .map(|l| {
                calib::project(truth, &pose, l)
                    .ok()
                    .filter(|z| {
                        z[0] > 0.0 && z[0] < 752.0 && z[2] > 0.0 && z[1] > 0.0 && z[1] < 480.0
                    })
                    .map(|z| z + rng.pixel_noise(0.3))
            })
            .collect();
        if let Some(prev) = &prev {
            let landmarks = prev
                .iter()
                .zip(&seen)
                .filter_map(|(a, b)| {
                    Some(LandmarkPair {
                        first: (*a)?,
                        second: (*b)?,
                    })
                })
                .collect();
            // The odometry measured while moving from the previous frame to this one.
            out.push(FramePair {
                t_us: 50_000 * k as u64,
                motion: measured,
                landmarks,
            });
        }
        prev = Some(seen);
        pose = true_motion.apply(&pose);
        measured = motion;
    }
    out
}

#[test]
fn tilted_camera_with_turns_recovers_f_and_baseline() {
    let truth = true_camera(0.3);
    let mut nominal = truth;
    nominal.f = 680.0;
    nominal.baseline = 0.118;
    let rig = rig(nominal, &[Param::F, Param::Baseline]);
    let data = pairs(&truth, 0.3, 1, 200);
    let cal = calibrate(&data, &rig, &nominal, &SolverSettings::default());
    println!(
        "{:?} after {} iterations ({} accepted): f {} baseline {} chi2/dof {}",
        cal.status,
        cal.iterations,
        cal.history.len() - 1,
        cal.camera.f,
        cal.camera.baseline,
        cal.reduced_chi2
    );
    assert!(matches!(cal.status, SolveStatus::Converged));
    assert!(cal.observability.unobservable().next().is_none());
    assert!(
        (cal.camera.f - truth.f).abs() < 3.0 * cal.sigma(Param::F) + 0.5,
        "f {} sigma {}",
        cal.camera.f,
        cal.sigma(Param::F)
    );
    assert!(
        (cal.camera.baseline - truth.baseline).abs() < 0.001,
        "baseline {}",
        cal.camera.baseline
    );
}

#[test]
fn upward_camera_reports_f_unobservable_and_still_gets_the_baseline() {
    let truth = true_camera(0.0);
    let mut nominal = truth;
    nominal.f = 690.0;
    nominal.baseline = 0.118;
    let rig = rig(nominal, &[Param::F, Param::Baseline]);
    let data = pairs(&truth, 0.3, 2, 200);
    let cal = calibrate(&data, &rig, &nominal, &SolverSettings::default());
    println!(
        "{:?} {} {} {:?}",
        cal.status, cal.camera.f, cal.camera.baseline, cal.observability
    );
    let f = cal
        .observability
        .params
        .iter()
        .find(|p| p.param == Param::F)
        .unwrap();
    assert!(!f.observable);
    assert!(f.reason.unwrap().contains("straight up"), "{:?}", f.reason);
    assert_eq!(cal.camera.f, 690.0, "held at nominal");
    assert!(
        (cal.camera.baseline - truth.baseline).abs() < 0.002,
        "baseline {}",
        cal.camera.baseline
    );
}

#[test]
fn straight_path_cannot_give_the_mount_offsets() {
    let truth = true_camera(0.3);
    let rig_ = rig(truth, &[Param::Baseline, Param::MountY, Param::MountZ]);
    let straight = calibrate(
        &pairs(&truth, 0.0, 3, 200),
        &rig_,
        &truth,
        &SolverSettings::default(),
    );
    let unobs: Vec<Param> = straight
        .observability
        .unobservable()
        .map(|p| p.param)
        .collect();
    println!("{:?}", straight.observability);
    assert!(
        unobs.contains(&Param::MountY) && unobs.contains(&Param::MountZ),
        "{unobs:?}"
    );
    assert!(!unobs.contains(&Param::Baseline));
    let turning = calibrate(
        &pairs(&truth, 0.4, 3, 200),
        &rig_,
        &truth,
        &SolverSettings::default(),
    );
    let unobs: Vec<Param> = turning
        .observability
        .unobservable()
        .map(|p| p.param)
        .collect();
    println!("{:?}", turning.observability);
    assert!(!unobs.contains(&Param::MountY), "{unobs:?}");
    assert!(
        unobs.contains(&Param::MountZ),
        "height never observable: {unobs:?}"
    );
}

#[test]
fn no_data_returns_the_nominal_values() {
    let nominal = true_camera(0.2);
    let rig = rig(nominal, &[Param::F]);
    let cal = calibrate(&[], &rig, &nominal, &SolverSettings::default());
    assert_eq!(cal.status, SolveStatus::NoData);
    assert_eq!(cal.camera, nominal);
}

#[test]
fn incremental_calibration_becomes_stable_and_hands_over() {
    use calib::selfcal::{SelfCalibrator, StableRule};
    let truth = true_camera(0.3);
    let mut nominal = truth;
    nominal.f = 680.0;
    nominal.baseline = 0.118;
    let rule = StableRule {
        min_pairs: 100,
        ..StableRule::default()
    };
    let mut cal = SelfCalibrator::new(
        rig(nominal, &[Param::F, Param::Baseline]),
        SolverSettings::default(),
        rule,
        20,
    );
    assert!(cal.handover().is_none());
    for pair in pairs(&truth, 0.3, 4, 400) {
        cal.add_pair(pair);
    }
    let hand = cal.handover().expect("stable within 400 pairs");
    assert!(hand.t_us > 0 && cal.history().len() == 399 / 20);
    let sigma_f = hand.covariance[(Param::F.index(), Param::F.index())].sqrt();
    assert!(
        (hand.camera.f - truth.f).abs() < 3.0 * sigma_f + 0.5,
        "f {}",
        hand.camera.f
    );
    assert!((hand.camera.baseline - truth.baseline).abs() < 0.0015);
    // Stability needs the parameters to have settled: not before the minimum number of pairs.
    assert!(hand.t_us >= 50_000 * 100);
}
