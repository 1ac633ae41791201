//! Synthetic phase-1 data made from the rig model alone (independent of the simulator): a
//! known rig, five lamps, a slow path that turns, noisy stereo measurements and odometry.
//! Shared by the phase-1 tests and the phase-1 bench.

use nalgebra::Vector3;
use rig_model::camera::{CameraParams, Mount, N_PARAMS, Param, Pose2};
use rig_model::config::{Noise, Rig};
use rig_model::handover::{FramePair, LandmarkPair};
use rig_model::odometry::{Motion, constant_velocity_motion};

use super::Rng;

pub fn true_camera(pitch: f64) -> CameraParams {
    CameraParams {
        vehicle: Default::default(),
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

pub fn rig(nominal: CameraParams, estimate: &[Param]) -> Rig {
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
        lens: None,
        board: rig_model::Board::DEFAULT,
        width: 752,
        height: 480,
        nominal,
        estimate: estimate.to_vec(),
        prior,
        noise: Noise::white(0.3, 0.02, 0.01),
    }
}

/// Five lamps around the start, 3.5 m above the floor.
pub fn lamps() -> Vec<Vector3<f64>> {
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
pub fn pairs(truth: &CameraParams, turn_rate: f64, seed: u64, frames: usize) -> Vec<FramePair> {
    pairs_with(truth, turn_rate, seed, frames, false)
}

/// [`pairs`], optionally keeping every lamp in every frame even when it projects outside the
/// 752x480 image (a fixed workload for the bench: five landmarks in every pair).
pub fn pairs_with(
    truth: &CameraParams,
    turn_rate: f64,
    seed: u64,
    frames: usize,
    keep_all: bool,
) -> Vec<FramePair> {
    let mut rng = Rng::new(seed);
    let lamps = lamps();
    let mut pose = Pose2::default();
    let mut out = Vec::new();
    let mut prev: Option<Vec<Option<rig_model::Measurement>>> = None;
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
        let seen: Vec<Option<rig_model::Measurement>> = lamps
            .iter()
            .map(|l| {
                rig_model::project(truth, &pose, l)
                    .ok()
                    .filter(|z| {
                        keep_all
                            || (z[0] > 0.0
                                && z[0] < 752.0
                                && z[2] > 0.0
                                && z[1] > 0.0
                                && z[1] < 480.0)
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
