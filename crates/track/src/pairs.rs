//! Phase 1's frame pairs from tracked frames and odometry.
//!
//! Phase 1 compares each landmark triangulated at two instants with the odometry motion
//! between them (eq. (1), `selfcal::solver`). A pair's two frames are `stride` frames apart,
//! counted in frames pushed (a frame lost on the link shifts the count): far enough for the
//! motion to say something, near enough for the landmarks to stay in view. Two schemes:
//!
//! * [`PairingScheme::Disjoint`]: frames `(0, s)`, `(s + 1, 2s + 1)`, ...: blocks of `s + 1`
//!   frames, the first and last of each paired, the `s - 1` between unused. No frame is in two
//!   pairs, so no frame's pixel noise is counted twice; few pairs.
//! * [`PairingScheme::Interleaved`]: in each block of `2s` frames `[j 2s, j 2s + 2s)`, frame
//!   `k` of the first half is paired with `k + s`: `s` pairs per block, every frame used exactly
//!   once, pairs overlapping in time (their odometry intervals overlap, their pixel noise
//!   does not). About `s` times as many pairs from the same frames.
//!
//! A landmark pair is a track seen in both frames and confirmed by the second (a track
//! tentative at the first frame and confirmed since is the same lamp). A track id appearing
//! twice in one frame is ignored there, as are NaN or infinite measurements. The motion is
//! [`rig_model::odometry::integrate`]d between the two frames' timestamps; a pair whose
//! odometry does not cover the interval, or with fewer than `min_landmarks` landmarks, is not
//! emitted (and counted).
//!
//! Feed odometry and frames in time order (odometry at or before a frame's timestamp first):
//! the builder keeps only the frames still waiting for their partner and the odometry since the
//! oldest of them.

use alloc::collections::VecDeque;
use alloc::vec::Vec;

use rig_model::Measurement;
use rig_model::handover::{FramePair, LandmarkPair};
use rig_model::odometry::OdomSample;

use crate::error::{SettingsError, check_count};
use crate::odometry::OdometryBuffer;
use crate::tracker::{TrackId, TrackedFrame};

/// Which frames are paired.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum PairingScheme {
    /// `(0, s)`, `(s + 1, 2s + 1)`, ...: no frame in two pairs.
    #[default]
    Disjoint,
    /// `(k, k + s)` for `k` in each block `[j 2s, j 2s + s)`: every frame in exactly one pair.
    Interleaved,
}

impl PairingScheme {
    /// `"disjoint"` or `"interleaved"`.
    pub const fn name(self) -> &'static str {
        match self {
            Self::Disjoint => "disjoint",
            Self::Interleaved => "interleaved",
        }
    }

    /// The scheme with this name, if any.
    pub fn from_name(name: &str) -> Option<Self> {
        [Self::Disjoint, Self::Interleaved]
            .into_iter()
            .find(|s| s.name() == name)
    }
}

/// Settings of the pair builder.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct PairSettings {
    /// Which frames are paired.
    pub scheme: PairingScheme,
    /// Frames between the two of a pair (at least 1).
    pub stride: usize,
    /// Fewest landmarks a pair must have to be emitted.
    pub min_landmarks: usize,
    /// Longest an odometry sample may be held, microseconds: a longer gap is missing
    /// odometry, and a pair across it is not emitted.
    pub max_odometry_hold_us: u64,
}

impl Default for PairSettings {
    /// Disjoint pairs 40 frames (2 s at 20 Hz) apart, at least one landmark, odometry gaps of
    /// up to 1 s.
    fn default() -> Self {
        Self {
            scheme: PairingScheme::Disjoint,
            stride: 40,
            min_landmarks: 1,
            max_odometry_hold_us: 1_000_000,
        }
    }
}

impl PairSettings {
    /// Largest stride accepted: pairs 10^6 frames apart (14 hours at 20 Hz) have no landmark in
    /// common, and the builder holds up to `stride` frames.
    pub const MAX_STRIDE: usize = 1_000_000;

    /// Checks every field.
    pub fn validate(&self) -> Result<(), SettingsError> {
        check_count("pairs.stride", self.stride as u64, 1, "at least 1")?;
        if self.stride > Self::MAX_STRIDE {
            return Err(SettingsError::Count {
                name: "pairs.stride",
                value: self.stride as u64,
                expected: "at most 1000000",
            });
        }
        Ok(())
    }
}

/// Counters of the pair builder.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Hash)]
pub struct PairStats {
    /// Frames pushed.
    pub frames: u64,
    /// Odometry samples pushed (refused ones included).
    pub odometry: u64,
    /// Odometry samples refused (NaN or infinite).
    pub odometry_refused: u64,
    /// Pairs emitted.
    pub pairs: u64,
    /// Pairs not emitted: the odometry did not cover their interval.
    pub no_motion: u64,
    /// Pairs not emitted: fewer than `min_landmarks` landmarks.
    pub too_few_landmarks: u64,
}

/// A frame waiting for its partner.
#[derive(Debug, Clone)]
struct Held {
    t_us: u64,
    /// By increasing id, each id once.
    tracks: Vec<(TrackId, Measurement)>,
}

/// `(id, measurement)` of the chosen observations, sorted by id, finite, ids seen twice
/// dropped.
fn clean<'a>(
    obs: impl Iterator<Item = &'a crate::tracker::Observation>,
) -> Vec<(TrackId, Measurement)> {
    let mut v: Vec<(TrackId, Measurement)> = obs
        .filter(|o| o.measurement.iter().all(|x| x.is_finite()))
        .map(|o| (o.track, o.measurement))
        .collect();
    v.sort_by_key(|(id, _)| *id);
    let mut out: Vec<(TrackId, Measurement)> = Vec::with_capacity(v.len());
    let mut dup: Option<TrackId> = None;
    for (id, z) in v {
        if out.last().is_some_and(|(last, _)| *last == id) {
            out.pop();
            dup = Some(id);
        } else if dup != Some(id) {
            out.push((id, z));
        }
    }
    out
}

/// Builds phase 1's frame pairs from tracked frames and odometry fed in time order.
#[derive(Debug, Clone)]
pub struct PairBuilder {
    settings: PairSettings,
    odometry: OdometryBuffer,
    held: VecDeque<Held>,
    last_tracks: Vec<TrackId>,
    stats: PairStats,
}

impl PairBuilder {
    /// A builder with these settings.
    pub fn new(settings: PairSettings) -> Result<Self, SettingsError> {
        settings.validate()?;
        Ok(Self {
            settings,
            odometry: OdometryBuffer::new(settings.max_odometry_hold_us),
            held: VecDeque::new(),
            last_tracks: Vec::new(),
            stats: PairStats::default(),
        })
    }

    /// The settings.
    pub fn settings(&self) -> &PairSettings {
        &self.settings
    }

    /// The counters so far.
    pub fn stats(&self) -> PairStats {
        PairStats {
            odometry_refused: self.odometry.refused(),
            ..self.stats
        }
    }

    /// The tracks of the last pair emitted, in the order of its landmarks.
    pub fn last_pair_tracks(&self) -> &[TrackId] {
        &self.last_tracks
    }

    /// Adds an odometry sample (NaN or infinite ones are refused and counted).
    pub fn push_odometry(&mut self, sample: OdomSample) {
        self.stats.odometry += 1;
        self.odometry.push(sample);
    }

    /// Adds the next frame; returns the pair it completes, if any.
    pub fn push_frame(&mut self, frame: &TrackedFrame) -> Option<FramePair> {
        let s = self.settings.stride as u64;
        let index = self.stats.frames;
        self.stats.frames += 1;
        // Where the frame sits in its block: first of a pair, second of one, or unused.
        let (first, second) = match self.settings.scheme {
            PairingScheme::Disjoint => {
                let pos = index % (s + 1);
                (pos == 0, pos == s)
            }
            PairingScheme::Interleaved => {
                let pos = index % (2 * s);
                (pos < s, pos >= s)
            }
        };
        let mut pair = None;
        if first {
            self.held.push_back(Held {
                t_us: frame.t_us,
                tracks: clean(frame.observations.iter()),
            });
        } else if second && let Some(held) = self.held.pop_front() {
            pair = self.pair(&held, frame);
        }
        let oldest = self
            .held
            .front()
            .map_or(frame.t_us, |h| h.t_us.min(frame.t_us));
        self.odometry.forget_before(oldest);
        pair
    }

    fn pair(&mut self, first: &Held, frame: &TrackedFrame) -> Option<FramePair> {
        let second = clean(frame.confirmed());
        let mut landmarks = Vec::new();
        self.last_tracks.clear();
        let mut a = first.tracks.iter().peekable();
        for (id, z) in &second {
            while a.next_if(|(x, _)| x < id).is_some() {}
            if let Some((_, z0)) = a.next_if(|(x, _)| x == id) {
                landmarks.push(LandmarkPair {
                    first: *z0,
                    second: *z,
                });
                self.last_tracks.push(*id);
            }
        }
        let Some(motion) = self.odometry.motion(first.t_us, frame.t_us) else {
            self.stats.no_motion += 1;
            self.last_tracks.clear();
            return None;
        };
        if landmarks.len() < self.settings.min_landmarks {
            self.stats.too_few_landmarks += 1;
            self.last_tracks.clear();
            return None;
        }
        self.stats.pairs += 1;
        Some(FramePair {
            t_us: frame.t_us,
            motion,
            landmarks,
        })
    }
}

/// Frame pairs from measurements whose landmarks are already labelled (the simulator's lamp
/// ids, a caller's ids): the frames in time order, each `(t_us, [(label, measurement)])`, with
/// the odometry in time order. Built by [`PairBuilder`] with each label standing in for a
/// confirmed track, so that labelled pairs are paired exactly as the navigator's are; every
/// pair is kept, even one without a landmark in common, the odometry may be held across any
/// gap, and a pair whose first frame precedes the odometry is left out. A `stride` out of
/// range is clamped to `1..=`[`PairSettings::MAX_STRIDE`].
pub fn labelled_pairs(
    frames: impl IntoIterator<Item = (u64, Vec<(u64, Measurement)>)>,
    odometry: &[OdomSample],
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
    let mut odometry = odometry.iter().peekable();
    let mut pairs = Vec::new();
    for (t_us, mut landmarks) in frames {
        while let Some(s) = odometry.next_if(|s| s.t_us <= t_us) {
            builder.push_odometry(*s);
        }
        landmarks.sort_by_key(|(label, _)| *label);
        let tracked = TrackedFrame {
            t_us,
            observations: landmarks
                .into_iter()
                .enumerate()
                .map(
                    |(index, (label, measurement))| crate::tracker::Observation {
                        track: TrackId(label),
                        index,
                        measurement,
                        confirmed: true,
                        hits: 1,
                    },
                )
                .collect(),
        };
        pairs.extend(builder.push_frame(&tracked));
    }
    pairs
}

#[cfg(test)]
#[allow(clippy::indexing_slicing, clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::tracker::Observation;
    use alloc::vec;
    use rig_model::odometry::integrate;

    fn obs(id: u64, x: f64, confirmed: bool) -> Observation {
        Observation {
            track: TrackId(id),
            index: 0,
            measurement: Measurement::new(x, 1.0, x - 10.0, 1.0),
            confirmed,
            hits: 1,
        }
    }

    fn frame(k: u64, obs: Vec<Observation>) -> TrackedFrame {
        TrackedFrame {
            t_us: 1_000 + 50_000 * k,
            observations: obs,
        }
    }

    fn odom(t_us: u64) -> OdomSample {
        OdomSample {
            t_us,
            vx: 0.1,
            vy: 0.0,
            vtheta: 0.2,
        }
    }

    /// The (first, second) frame indices of the pairs emitted over `n` frames.
    fn indices(scheme: PairingScheme, stride: usize, n: u64) -> Vec<(u64, u64)> {
        let mut b = PairBuilder::new(PairSettings {
            scheme,
            stride,
            ..PairSettings::default()
        })
        .unwrap();
        let mut out = Vec::new();
        for k in 0..n {
            // Frame k carries a track whose measurement says k.
            let f = frame(k, vec![obs(7, k as f64 + 100.0, true)]);
            b.push_odometry(odom(f.t_us));
            if let Some(p) = b.push_frame(&f) {
                let lm = p.landmarks[0];
                out.push(((lm.first[0] - 100.0) as u64, (lm.second[0] - 100.0) as u64));
                assert_eq!(p.t_us, f.t_us);
            }
        }
        out
    }

    #[test]
    fn disjoint_and_interleaved_schemes_pair_the_documented_frames() {
        assert_eq!(
            indices(PairingScheme::Disjoint, 3, 13),
            vec![(0, 3), (4, 7), (8, 11)]
        );
        assert_eq!(
            indices(PairingScheme::Interleaved, 3, 14),
            vec![(0, 3), (1, 4), (2, 5), (6, 9), (7, 10), (8, 11)]
        );
        assert_eq!(indices(PairingScheme::Disjoint, 1, 5), vec![(0, 1), (2, 3)]);
        assert_eq!(
            indices(PairingScheme::Interleaved, 1, 5),
            vec![(0, 1), (2, 3)]
        );
        // Every frame used exactly once by the interleaved scheme.
        let mut used: Vec<u64> = indices(PairingScheme::Interleaved, 4, 40)
            .into_iter()
            .flat_map(|(a, b)| [a, b])
            .collect();
        used.sort_unstable();
        assert_eq!(used, (0..40).collect::<Vec<_>>());
    }

    #[test]
    fn only_tracks_confirmed_by_the_second_frame_and_seen_in_both_pair() {
        let mut b = PairBuilder::new(PairSettings {
            stride: 2,
            ..PairSettings::default()
        })
        .unwrap();
        let samples: Vec<OdomSample> = (0..30).map(|k| odom(k * 10_000)).collect();
        for s in samples.iter().take(2) {
            b.push_odometry(*s);
        }
        // Track 1 tentative then confirmed; 2 only in the first; 3 unconfirmed at the second;
        // 4 twice in the second frame (ignored); 5 NaN in the first.
        let mut nan = obs(5, 0.0, true);
        nan.measurement[0] = f64::NAN;
        let f0 = frame(
            0,
            vec![
                obs(1, 10.0, false),
                obs(2, 20.0, true),
                obs(3, 30.0, false),
                obs(4, 40.0, true),
                nan,
            ],
        );
        assert!(b.push_frame(&f0).is_none());
        for s in samples.iter().skip(2).take(10) {
            b.push_odometry(*s);
        }
        assert!(b.push_frame(&frame(1, vec![])).is_none());
        for s in samples.iter().skip(12) {
            b.push_odometry(*s);
        }
        let f2 = frame(
            2,
            vec![
                obs(1, 11.0, true),
                obs(3, 31.0, false),
                obs(4, 41.0, true),
                obs(4, 42.0, true),
                obs(5, 51.0, true),
            ],
        );
        let p = b.push_frame(&f2).unwrap();
        assert_eq!(b.last_pair_tracks(), &[TrackId(1)]);
        assert_eq!(p.landmarks.len(), 1);
        assert_eq!(p.landmarks[0].first[0], 10.0);
        assert_eq!(p.landmarks[0].second[0], 11.0);
        assert_eq!(p.motion, integrate(&samples, f0.t_us, f2.t_us).unwrap());
    }

    #[test]
    fn pairs_without_odometry_or_landmarks_are_counted_not_emitted() {
        let mut b = PairBuilder::new(PairSettings {
            stride: 1,
            min_landmarks: 2,
            ..PairSettings::default()
        })
        .unwrap();
        let two = || vec![obs(1, 10.0, true), obs(2, 20.0, true)];
        // No odometry yet.
        b.push_frame(&frame(0, two()));
        assert!(b.push_frame(&frame(1, two())).is_none());
        b.push_odometry(odom(0));
        b.push_frame(&frame(2, two()));
        assert!(b.push_frame(&frame(3, vec![obs(1, 10.0, true)])).is_none());
        b.push_frame(&frame(4, two()));
        assert!(b.push_frame(&frame(5, two())).is_some());
        // A NaN sample is refused; a 2 s gap is missing odometry.
        b.push_odometry(OdomSample {
            vx: f64::NAN,
            ..odom(300_000)
        });
        b.push_frame(&frame(40, two()));
        assert!(b.push_frame(&frame(41, two())).is_none());
        let st = b.stats();
        assert_eq!(
            (
                st.frames,
                st.pairs,
                st.no_motion,
                st.too_few_landmarks,
                st.odometry,
                st.odometry_refused
            ),
            (8, 1, 2, 1, 2, 1)
        );
    }

    #[test]
    fn settings_are_checked() {
        for stride in [0, PairSettings::MAX_STRIDE + 1] {
            let s = PairSettings {
                stride,
                ..PairSettings::default()
            };
            assert!(PairBuilder::new(s).is_err(), "{stride}");
        }
        assert_eq!(
            PairingScheme::from_name("interleaved"),
            Some(PairingScheme::Interleaved)
        );
        assert_eq!(
            PairingScheme::from_name("disjoint"),
            Some(PairingScheme::Disjoint)
        );
        assert_eq!(PairingScheme::from_name("Disjoint"), None);
    }
}
