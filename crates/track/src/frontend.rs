//! Stereo matching and tracking chained per frame, with the odometry between frames.

use alloc::vec::Vec;

use rig_model::Measurement;
use rig_model::odometry::OdomSample;

use crate::error::SettingsError;
use crate::model::Model;
use crate::odometry::OdometryBuffer;
use crate::stereo::{Pixel, StereoMatch, StereoMatcher, StereoSettings, StereoStats};
use crate::tracker::{TrackedFrame, Tracker, TrackerSettings};

/// Settings of the [`FrontEnd`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrontEndSettings {
    /// Left-right matching.
    pub stereo: StereoSettings,
    /// Frame-to-frame tracking.
    pub tracker: TrackerSettings,
    /// Longest an odometry sample may be held between two frames, microseconds; across a
    /// longer gap the motion is unknown and every track ends.
    pub max_odometry_hold_us: u64,
}

impl Default for FrontEndSettings {
    fn default() -> Self {
        Self {
            stereo: StereoSettings::default(),
            tracker: TrackerSettings::default(),
            max_odometry_hold_us: 1_000_000,
        }
    }
}

/// The association of one vehicle: each stereo frame's features are matched left to right and
/// the measurements tracked from the previous frame, predicted with the odometry between the
/// two frames' timestamps.
///
/// Feed odometry and frames in time order (the odometry up to a frame's timestamp before the
/// frame). The [`crate::tracker::Observation::index`] of each observation refers to
/// [`stereo_matches`](Self::stereo_matches) of that frame.
#[derive(Debug, Clone)]
pub struct FrontEnd {
    model: Model,
    matcher: StereoMatcher,
    tracker: Tracker,
    odometry: OdometryBuffer,
    last_t_us: Option<u64>,
    matches: Vec<StereoMatch>,
    measurements: Vec<Measurement>,
    stereo_stats: StereoStats,
}

impl FrontEnd {
    /// A front end with this sensor model and these settings.
    pub fn new(model: Model, settings: FrontEndSettings) -> Result<Self, SettingsError> {
        Ok(Self {
            model,
            matcher: StereoMatcher::new(settings.stereo)?,
            tracker: Tracker::new(settings.tracker)?,
            odometry: OdometryBuffer::new(settings.max_odometry_hold_us),
            last_t_us: None,
            matches: Vec::new(),
            measurements: Vec::new(),
            stereo_stats: StereoStats::default(),
        })
    }

    /// The sensor model in use.
    pub fn model(&self) -> &Model {
        &self.model
    }

    /// Replaces the sensor model (after a calibration); tracks carry on.
    pub fn set_model(&mut self, model: Model) {
        self.model = model;
    }

    /// The tracker (its live tracks and counters).
    pub fn tracker(&self) -> &Tracker {
        &self.tracker
    }

    /// The left-right matching counters, summed over all frames.
    pub fn stereo_stats(&self) -> StereoStats {
        self.stereo_stats
    }

    /// Odometry samples refused (NaN or infinite).
    pub fn odometry_refused(&self) -> u64 {
        self.odometry.refused()
    }

    /// The last frame's stereo matches.
    pub fn stereo_matches(&self) -> &[StereoMatch] {
        &self.matches
    }

    /// Adds an odometry sample.
    pub fn push_odometry(&mut self, sample: OdomSample) {
        self.odometry.push(sample);
    }

    /// Processes one stereo frame's features (pixels, see [`Pixel::from_q4`]).
    pub fn push_frame(&mut self, t_us: u64, left: &[Pixel], right: &[Pixel]) -> TrackedFrame {
        let stats = self
            .matcher
            .match_frame(&self.model, left, right, &mut self.matches);
        self.stereo_stats.add(&stats);
        self.measurements.clear();
        self.measurements
            .extend(self.matches.iter().map(|m| m.measurement));
        let motion = self.last_t_us.and_then(|t0| self.odometry.motion(t0, t_us));
        let frame = self
            .tracker
            .update(&self.model, t_us, motion.as_ref(), &self.measurements);
        self.last_t_us = Some(t_us);
        self.odometry.forget_before(t_us);
        frame
    }
}

#[cfg(test)]
#[allow(clippy::indexing_slicing, clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::model::tests::rig;
    use alloc::vec;
    use nalgebra::Vector3;
    use rig_model::camera::Pose2;
    use rig_model::odometry::integrate;
    use rig_model::project;

    #[test]
    fn lamps_seen_from_a_turning_robot_keep_their_tracks() {
        let rig = rig();
        let model = Model::from_rig(&rig);
        let mut fe = FrontEnd::new(model.clone(), FrontEndSettings::default()).unwrap();
        let lamps = [
            Vector3::new(1.0, 0.3, 3.3),
            Vector3::new(1.4, -0.4, 3.1),
            Vector3::new(0.8, -0.1, 3.5),
        ];
        // 100 Hz odometry, 20 Hz frames: 0.1 m/s forward turning at 0.3 rad/s.
        let odom: Vec<OdomSample> = (0..=300)
            .map(|k| OdomSample {
                t_us: k * 10_000,
                vx: 0.1,
                vy: 0.0,
                vtheta: 0.3,
            })
            .collect();
        let mut next = 0;
        for k in 0..60u64 {
            let t = k * 50_000;
            while odom.get(next).is_some_and(|s| s.t_us <= t) {
                fe.push_odometry(odom[next]);
                next += 1;
            }
            let m = integrate(&odom, 0, t).unwrap();
            let pose = m.apply(&Pose2::default());
            let (mut left, mut right) = (Vec::new(), Vec::new());
            for l in &lamps {
                let z = project(&rig.nominal, &pose, l).unwrap();
                left.push(Pixel::new(z[0], z[1]));
                right.push(Pixel::new(z[2], z[3]));
            }
            right.reverse();
            let f = fe.push_frame(t, &left, &right);
            let ids: Vec<u64> = f.observations.iter().map(|o| o.track.0).collect();
            assert_eq!(ids, vec![0, 1, 2], "frame {k}");
            for o in &f.observations {
                let sm = fe.stereo_matches()[o.index];
                assert_eq!(sm.left, o.track.0 as usize);
                assert_eq!(sm.right, 2 - o.track.0 as usize);
            }
        }
        assert_eq!(fe.tracker().stats().confirmed, 3);
    }
}
