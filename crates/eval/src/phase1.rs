//! Frame pairs for phase 1 built from a simulated run with the simulator's own knowledge of
//! which lamp each feature shows: for analysing and testing the calibration apart from
//! association (the navigator associates features without that knowledge). The pairing itself
//! is the navigator's ([`track::labelled_pairs`], by [`track::PairBuilder`]), so that both pair frames alike.

use rig_model::handover::FramePair;
use track::{PairingScheme, labelled_pairs};

use sim::SimRun;

/// Disjoint frame pairs `stride` frames apart (`(0, stride)`, `(stride + 1, 2 stride + 1)`,
/// ...), with the logged odometry integrated between them and the lamps seen in both.
/// Disjoint, so that no frame's noise is counted in two pairs.
pub fn frame_pairs_by_lamp(run: &SimRun, stride: usize) -> Vec<FramePair> {
    frame_pairs_by_lamp_with(run, PairingScheme::Disjoint, stride)
}

/// Frame pairs of either scheme ([`track::pairs`]), built by the navigator's
/// [`track::PairBuilder`] with the lamp ids standing in for its track ids (every lamp seen in both
/// images counts as a confirmed track). Every pair is kept, even one without a lamp in common,
/// and the odometry may be held across any gap, as logged.
pub fn frame_pairs_by_lamp_with(
    run: &SimRun,
    scheme: PairingScheme,
    stride: usize,
) -> Vec<FramePair> {
    let frames = run.frames.iter().map(|frame| {
        let lamps = frame
            .lamp_measurements()
            .into_iter()
            .map(|(id, z)| (u64::from(id), z))
            .collect();
        (frame.t_us, lamps)
    });
    labelled_pairs(frames, &run.odometry, scheme, stride)
}
