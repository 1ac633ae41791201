//! Frame pairs for phase 1 built from a simulated run with the simulator's own knowledge of
//! which lamp each feature shows: for analysing and testing the calibration apart from
//! association (the navigator associates features without that knowledge). The pairing itself
//! is the navigator's ([`track::PairBuilder`]), so that both pair frames alike.

use rig_model::Measurement;
use rig_model::handover::FramePair;
use track::{Observation, PairBuilder, PairSettings, PairingScheme, TrackId, TrackedFrame};

use sim::SimRun;

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
            builder.push_odometry(*s);
        }
        let mut lamps: Vec<(u32, Measurement)> = frame.lamp_measurements().into_iter().collect();
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
