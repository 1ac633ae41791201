//! Frame pairs for phase 1 built from a simulated run with the simulator's own knowledge of
//! which lamp each feature shows: for analysing and testing the calibration apart from
//! association (the navigator associates features without that knowledge).

use std::collections::HashMap;

use calib::Measurement;
use calib::odometry::{OdomSample, integrate};
use calib::selfcal::{FramePair, LandmarkPair};

use crate::run::{FrameTruth, SimRun};

/// `(uL, vL, uR, vR)` of every lamp seen in both images of a frame, by lamp id.
pub fn lamp_measurements(frame: &FrameTruth) -> HashMap<u32, Measurement> {
    let right: HashMap<u32, (u16, u16)> = frame
        .right
        .features
        .iter()
        .filter_map(|f| Some((f.lamp?, (f.x_q4, f.y_q4))))
        .collect();
    let q = |v: u16| f64::from(v) / 16.0;
    frame
        .left
        .features
        .iter()
        .filter_map(|l| {
            let (rx, ry) = right.get(&l.lamp?)?;
            Some((
                l.lamp?,
                Measurement::new(q(l.x_q4), q(l.y_q4), q(*rx), q(*ry)),
            ))
        })
        .collect()
}

/// Disjoint frame pairs `stride` frames apart (`(0, stride)`, `(stride + 1, 2 stride + 1)`,
/// ...), with the logged odometry integrated between them and the lamps seen in both.
/// Disjoint, so that no frame's noise is counted in two pairs.
pub fn frame_pairs_by_lamp(run: &SimRun, stride: usize) -> Vec<FramePair> {
    let stride = stride.max(1);
    let odometry: Vec<OdomSample> = run
        .odometry
        .iter()
        .map(|s| OdomSample {
            t_us: s.t_us,
            vx: s.vx,
            vy: s.vy,
            vtheta: s.vtheta,
        })
        .collect();
    run.frames
        .windows(stride + 1)
        .step_by(stride + 1)
        .filter_map(|w| {
            let (first, last) = (w.first()?, w.last()?);
            let motion = integrate(&odometry, first.t_us, last.t_us)?;
            let (a, b) = (lamp_measurements(first), lamp_measurements(last));
            let mut landmarks: Vec<(u32, LandmarkPair)> = a
                .iter()
                .filter_map(|(id, za)| {
                    Some((
                        *id,
                        LandmarkPair {
                            first: *za,
                            second: *b.get(id)?,
                        },
                    ))
                })
                .collect();
            landmarks.sort_by_key(|(id, _)| *id);
            Some(FramePair {
                t_us: last.t_us,
                motion,
                landmarks: landmarks.into_iter().map(|(_, p)| p).collect(),
            })
        })
        .collect()
}
