//! Frame pairs for phase 1 built from a simulated run with the simulator's own knowledge of
//! which lamp each feature shows: for analysing and testing the calibration apart from
//! association (the navigator associates features without that knowledge). The pairing itself
//! is the navigator's ([`track::PairBuilder`]), so that both pair frames alike.

use std::collections::HashMap;

use calib::Measurement;
use calib::odometry::OdomSample;
use calib::selfcal::FramePair;
use track::{Observation, PairBuilder, PairSettings, PairingScheme, TrackId, TrackedFrame};

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
    frame_pairs_by_lamp_with(run, PairingScheme::Disjoint, stride)
}

/// Frame pairs of either scheme ([`track::pairs`]), built by the navigator's
/// [`PairBuilder`] with the lamp ids standing in for its track ids (every lamp seen in both
/// images counts as a confirmed track). Every pair is kept, even one without a lamp in common,
/// and the odometry may be held across any gap, as logged.
pub fn frame_pairs_by_lamp_with(
    run: &SimRun,
    scheme: PairingScheme,
    stride: usize,
) -> Vec<FramePair> {
    let settings = PairSettings {
        scheme,
        stride: stride.clamp(1, PairSettings::MAX_STRIDE),
        min_landmarks: 0,
        max_odometry_hold_us: u64::MAX,
    };
    let Ok(mut builder) = PairBuilder::new(settings) else {
        return Vec::new();
    };
    let mut odometry = run.odometry.iter().peekable();
    let mut pairs = Vec::new();
    for frame in &run.frames {
        while let Some(s) = odometry.next_if(|s| s.t_us <= frame.t_us) {
            builder.push_odometry(OdomSample {
                t_us: s.t_us,
                vx: s.vx,
                vy: s.vy,
                vtheta: s.vtheta,
            });
        }
        let mut lamps: Vec<(u32, Measurement)> = lamp_measurements(frame).into_iter().collect();
        lamps.sort_by_key(|(id, _)| *id);
        let tracked = TrackedFrame {
            t_us: frame.t_us,
            observations: lamps
                .into_iter()
                .enumerate()
                .map(|(index, (id, measurement))| Observation {
                    track: TrackId(u64::from(id)),
                    index,
                    measurement,
                    confirmed: true,
                    hits: 1,
                })
                .collect(),
        };
        pairs.extend(builder.push_frame(&tracked));
    }
    pairs
}
