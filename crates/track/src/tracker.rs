//! Frame-to-frame tracking of stereo measurements, with persistent track ids.
//!
//! **Prediction.** A track keeps its last measurement `z0` and the odometry motion since that
//! frame (composed frame by frame, so a track that missed frames is predicted across them).
//! `z0` is triangulated with the model's camera parameters into the robot frame of its
//! instant, the robot is moved by the motion (`(dx, dy, dtheta)`, the new pose in that frame),
//! and the point is projected: `z_hat = h(C, motion, L(C, z0))` ([`rig_model::rig::triangulate`],
//! [`rig_model::rig::project_with_jacobians`]).
//!
//! **Gate (Mahalanobis).** The innovation `z - z_hat` is judged against its covariance
//! `S = A (s^2 I) A^T + B Q B^T + G P_C G^T + (s^2 + e^2) I`, the rig model's Jacobians
//! carrying each source of error:
//! * `A = dz_hat/dz0`: the pixel noise `s` of the old measurement (the rig file's pixel sigma
//!   plus the Q12.4 rounding);
//! * `B = dz_hat/dmotion`, `Q` the odometry noise of the motion: white velocity noise per
//!   sample as in phase 1 (`sigma^2 dt^2 / n` for `n` samples over `dt`), plus a relative error
//!   `odometry_scale_sigma` of each component for what white noise misses (scale error, bias);
//! * `G = dz_hat/dC` (through both the triangulation and the projection), `P_C` the model's
//!   camera covariance: before calibration the rig file's priors, so a 3 % error of the
//!   baseline, which scales every predicted image motion by 3 %, stays inside the gate;
//! * the new measurement's own pixel noise `s`, and `e = extra_sigma_px` for what the model
//!   does not know (lens distortion, rolling shutter, a detector's bias on blurred lamps).
//!
//! A measurement is a candidate when `d^2 = (z - z_hat)^T S^-1 (z - z_hat) <= gate_chi2`
//! (default 18.47: 99.9 % of a chi-square with four degrees of freedom). The gate is thus in
//! pixels only through `S`: a few pixels for a lamp seen in the previous frame, wider after
//! missed frames, fast turns or with uncertain camera parameters.
//!
//! **Assignment.** Candidates are taken in increasing `d^2` (global nearest neighbour,
//! greedy, one-to-one). Before a track takes a measurement:
//! * if the track has another free candidate within `ambiguity_chi2` of this one, the frame is
//!   ambiguous for it: it takes nothing (a miss), and the measurements involved may not start
//!   tracks (they would likely duplicate it);
//! * if other free tracks want this measurement within `ambiguity_chi2`, the oldest track (the
//!   lowest id) takes it: two tracks claiming one measurement equally well are almost always
//!   one lamp tracked twice (after a track was restarted). A younger rival left without a
//!   measurement in this frame is ended as a duplicate.
//!
//! **Life cycle.** Every measurement no track took (and not withheld by an ambiguity) starts a
//! tentative track. A tentative track is ended at its first miss and confirmed at
//! `confirm_hits` consecutive hits: a lamp is seen in frame after frame where odometry says,
//! while clutter (reflections, random stereo matches) is not, so clutter rarely lives to be
//! confirmed. A confirmed track survives `max_misses` consecutive misses (a lamp hidden for a
//! moment, a lost packet) and is ended at the next. Ids count up from 0 and are never reused;
//! a lamp that leaves the view and comes back gets a new id (recognising it is the map's job,
//! phase 2). A frame without a motion (odometry missing) ends every track: nothing can be
//! predicted across it.

use alloc::vec::Vec;

use nalgebra::{Cholesky, Matrix3, Matrix4, U4};
use rig_model::camera::Pose2;
use rig_model::config::Noise;
use rig_model::odometry::Motion;
use rig_model::rig::{Measurement, RigError, project_with_jacobians, triangulate};

use crate::error::{SettingsError, check_count, check_real};
use crate::model::Model;

/// A track's id: unique for the life of a [`Tracker`], never reused.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct TrackId(pub u64);

impl core::fmt::Display for TrackId {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "track {}", self.0)
    }
}

/// Settings of the tracker.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackerSettings {
    /// Gate on the squared Mahalanobis distance of the innovation (four degrees of freedom).
    pub gate_chi2: f64,
    /// Two candidates whose squared distances differ by at most this much are ambiguous.
    pub ambiguity_chi2: f64,
    /// Consecutive hits, from its start, that confirm a track.
    pub confirm_hits: u32,
    /// Consecutive misses a confirmed track survives.
    pub max_misses: u32,
    /// Relative 1-sigma error of each odometry motion component beyond its white noise.
    pub odometry_scale_sigma: f64,
    /// Pixel noise the model does not know, added to every coordinate of the innovation, px.
    pub extra_sigma_px: f64,
}

impl Default for TrackerSettings {
    fn default() -> Self {
        Self {
            gate_chi2: 18.47,
            ambiguity_chi2: 4.0,
            confirm_hits: 3,
            max_misses: 5,
            odometry_scale_sigma: 0.02,
            extra_sigma_px: 0.3,
        }
    }
}

impl TrackerSettings {
    /// Checks every field.
    pub fn validate(&self) -> Result<(), SettingsError> {
        check_real(
            "tracker.gate_chi2",
            self.gate_chi2,
            0.0,
            true,
            "positive and finite",
        )?;
        check_real(
            "tracker.ambiguity_chi2",
            self.ambiguity_chi2,
            0.0,
            false,
            "at least 0 and finite",
        )?;
        check_count(
            "tracker.confirm_hits",
            u64::from(self.confirm_hits),
            1,
            "at least 1",
        )?;
        check_real(
            "tracker.odometry_scale_sigma",
            self.odometry_scale_sigma,
            0.0,
            false,
            "at least 0 and finite",
        )?;
        check_real(
            "tracker.extra_sigma_px",
            self.extra_sigma_px,
            0.0,
            false,
            "at least 0 and finite",
        )
    }
}

/// One measurement of a frame assigned to a track.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Observation {
    /// The track.
    pub track: TrackId,
    /// Index of the measurement in the frame's list (for a [`crate::FrontEnd`], of its
    /// [`crate::StereoMatch`]es).
    pub index: usize,
    /// `(uL, vL, uR, vR)`, pixels.
    pub measurement: Measurement,
    /// Whether the track is confirmed (after this frame).
    pub confirmed: bool,
    /// Frames the track has been seen in, this one included.
    pub hits: u32,
}

/// A frame's measurements with the tracks they belong to.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct TrackedFrame {
    /// The frame's timestamp, microseconds.
    pub t_us: u64,
    /// One per track seen in this frame (tentative ones included), by increasing track id.
    pub observations: Vec<Observation>,
}

impl TrackedFrame {
    /// The observations of confirmed tracks.
    pub fn confirmed(&self) -> impl Iterator<Item = &Observation> {
        self.observations.iter().filter(|o| o.confirmed)
    }
}

/// A live track, as seen from outside.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackInfo {
    /// Its id.
    pub id: TrackId,
    /// Whether it is confirmed.
    pub confirmed: bool,
    /// Frames it was seen in.
    pub hits: u32,
    /// Consecutive frames it has been missed in, up to now.
    pub misses: u32,
    /// Timestamp of its first frame, microseconds.
    pub first_t_us: u64,
    /// Timestamp of the last frame it was seen in, microseconds.
    pub last_t_us: u64,
    /// Its last measurement.
    pub last: Measurement,
}

/// Counters of the tracker since it was made.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Hash)]
pub struct TrackerStats {
    /// Frames processed.
    pub frames: u64,
    /// Tracks started.
    pub started: u64,
    /// Tracks confirmed.
    pub confirmed: u64,
    /// Tracks ended by misses (tentative ones at their first).
    pub ended: u64,
    /// Tracks ended as duplicates of an older track.
    pub duplicates: u64,
    /// Track-frames skipped because two measurements were about equally likely.
    pub ambiguous: u64,
    /// Track-frames whose prediction failed (the point could not be triangulated or
    /// projected, or its covariance was not positive definite).
    pub unpredictable: u64,
    /// Frames without a usable motion, at which every live track was ended.
    pub resets: u64,
}

#[derive(Debug, Clone)]
struct Track {
    id: u64,
    last: Measurement,
    since_seen: Motion,
    hits: u32,
    misses: u32,
    confirmed: bool,
    first_t_us: u64,
    last_t_us: u64,
}

/// Where a track or a measurement stands during one frame's assignment.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Slot {
    Free,
    /// Track: took measurement `m`; measurement: taken.
    Taken(usize),
    /// Track: ambiguous this frame; measurement: withheld from starting a track.
    Withheld,
}

#[derive(Debug, Clone, Copy)]
struct Candidate {
    d2: f64,
    track: usize,
    meas: usize,
}

/// The predicted measurement of a tracked landmark and its covariance.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Prediction {
    /// `(uL, vL, uR, vR)` expected in the new frame, pixels.
    pub measurement: Measurement,
    /// Its covariance from the old measurement's pixel noise, the motion's noise and the
    /// camera parameters' covariance (without the new measurement's noise), px^2.
    pub covariance: Matrix4<f64>,
}

/// The odometry noise of a motion: white noise per sample (as phase 1 models it; errors with
/// memory as their white equivalent) plus a
/// relative error `scale_sigma` of each component. Covariance of `(dx, dy, dtheta)`.
pub fn motion_covariance(motion: &Motion, noise: &Noise, scale_sigma: f64) -> Matrix3<f64> {
    let finite_sq = |s: f64| if s.is_finite() { s * s } else { 0.0 };
    #[allow(clippy::cast_precision_loss)] // a sample count far below 2^53
    let n = motion.samples.max(1) as f64;
    let white = finite_sq(motion.dt_s) / n;
    let k = finite_sq(scale_sigma);
    // Errors with memory as their white equivalent (`Noise::white_equivalent`).
    let noise = &noise.white_equivalent(motion.dt_s / n);
    Matrix3::from_diagonal(&nalgebra::Vector3::new(
        finite_sq(noise.velocity) * white + k * finite_sq(motion.dx),
        finite_sq(noise.velocity) * white + k * finite_sq(motion.dy),
        finite_sq(noise.yaw_rate) * white + k * finite_sq(motion.dtheta),
    ))
}

/// Predicts where a landmark last measured as `last` appears after the robot moved by
/// `motion` (expressed in the robot frame of `last`'s instant), with the covariance of that
/// prediction; `motion_cov` is the motion's covariance ([`motion_covariance`]).
pub fn predict(
    model: &Model,
    last: &Measurement,
    motion: &Motion,
    motion_cov: &Matrix3<f64>,
) -> Result<Prediction, RigError> {
    let c = &model.camera;
    let tri = triangulate(c, last)?;
    // The robot frame at `last`'s instant serves as the world: the landmark's coordinates
    // there, and the new pose in it.
    let origin = Pose2::default();
    let landmark = tri.p_in_robot(c);
    let pose = motion.apply(&origin);
    let (measurement, jac) = project_with_jacobians(c, &pose, &landmark)?;
    let robot_from_rig = c.mount.robot_from_rig_rotation();
    let a = jac.landmark * robot_from_rig * tri.jac_measurement;
    let g = jac.camera + jac.landmark * tri.jac_camera_in_world(c, &origin);
    let pixel = if model.pixel_noise.is_uniform() {
        a * a.transpose() * model.pixel_variance_px2()
    } else {
        a * Matrix4::from_diagonal(&model.measurement_variances_px2(last)) * a.transpose()
    };
    let covariance = pixel
        + jac.pose * motion_cov * jac.pose.transpose()
        + g * model.camera_covariance * g.transpose();
    if !covariance.iter().all(|v| v.is_finite()) {
        return Err(RigError::NonFinite {
            what: "prediction covariance",
        });
    }
    Ok(Prediction {
        measurement,
        covariance,
    })
}

/// A prediction ready for gating.
struct Gate {
    z: Measurement,
    chol: Cholesky<f64, U4>,
    /// `trace(S)`: `|dz|^2 > gate * trace(S)` is outside the gate without solving.
    trace: f64,
}

fn finite_motion(m: &Motion) -> bool {
    m.dx.is_finite() && m.dy.is_finite() && m.dtheta.is_finite() && m.dt_s.is_finite()
}

/// The frame-to-frame tracker.
#[derive(Debug, Clone)]
pub struct Tracker {
    settings: TrackerSettings,
    tracks: Vec<Track>,
    next_id: u64,
    stats: TrackerStats,
}

impl Tracker {
    /// A tracker with no tracks.
    pub fn new(settings: TrackerSettings) -> Result<Self, SettingsError> {
        settings.validate()?;
        Ok(Self {
            settings,
            tracks: Vec::new(),
            next_id: 0,
            stats: TrackerStats::default(),
        })
    }

    /// The settings.
    pub fn settings(&self) -> &TrackerSettings {
        &self.settings
    }

    /// The counters so far.
    pub fn stats(&self) -> TrackerStats {
        self.stats
    }

    /// The live tracks, by increasing id.
    pub fn tracks(&self) -> impl Iterator<Item = TrackInfo> + '_ {
        self.tracks.iter().map(|t| TrackInfo {
            id: TrackId(t.id),
            confirmed: t.confirmed,
            hits: t.hits,
            misses: t.misses,
            first_t_us: t.first_t_us,
            last_t_us: t.last_t_us,
            last: t.last,
        })
    }

    /// Tracks started so far (the next id).
    pub fn tracks_started(&self) -> u64 {
        self.next_id
    }

    /// Processes one frame: `motion` is the robot's motion since the previous frame (in the
    /// previous frame's robot frame), `None` when unknown; `measurements` are the frame's
    /// stereo measurements. Returns the observations of the tracks seen in this frame.
    pub fn update(
        &mut self,
        model: &Model,
        t_us: u64,
        motion: Option<&Motion>,
        measurements: &[Measurement],
    ) -> TrackedFrame {
        self.stats.frames += 1;
        match motion {
            Some(m) if finite_motion(m) => {
                for t in &mut self.tracks {
                    t.since_seen = t.since_seen.then(m);
                }
            }
            _ => {
                if !self.tracks.is_empty() {
                    self.stats.resets += 1;
                    self.stats.ended += self.tracks.len() as u64;
                    self.tracks.clear();
                }
            }
        }

        let gates = self.gates(model);
        let valid: Vec<bool> = measurements
            .iter()
            .map(|z| z.iter().all(|v| v.is_finite()))
            .collect();
        let (track_slots, meas_slots, yielded) = self.assign(&gates, measurements, &valid);

        // Apply: hits, misses, confirmation, ends.
        let mut observations = Vec::new();
        let settings = self.settings;
        let mut stats = self.stats;
        let mut kept = Vec::with_capacity(self.tracks.len());
        for (k, mut t) in core::mem::take(&mut self.tracks).into_iter().enumerate() {
            let slot = track_slots.get(k).copied().unwrap_or(Slot::Free);
            let hit = match slot {
                Slot::Taken(m) => measurements.get(m).map(|z| (m, *z)),
                _ => None,
            };
            if let Some((m, z)) = hit {
                t.last = z;
                t.since_seen = Motion::default();
                t.hits = t.hits.saturating_add(1);
                t.misses = 0;
                t.last_t_us = t_us;
                if !t.confirmed && t.hits >= settings.confirm_hits {
                    t.confirmed = true;
                    stats.confirmed += 1;
                }
                observations.push(Observation {
                    track: TrackId(t.id),
                    index: m,
                    measurement: z,
                    confirmed: t.confirmed,
                    hits: t.hits,
                });
                kept.push(t);
                continue;
            }
            t.misses = t.misses.saturating_add(1);
            if yielded.get(k).copied().unwrap_or(false) {
                stats.duplicates += 1;
            } else if !t.confirmed || t.misses > settings.max_misses {
                stats.ended += 1;
            } else {
                kept.push(t);
            }
        }
        self.tracks = kept;

        // Start tentative tracks on the measurements nobody took.
        let camera = model.camera;
        for (m, z) in measurements.iter().enumerate() {
            let free = meas_slots.get(m) == Some(&Slot::Free);
            if !(free && valid.get(m) == Some(&true) && triangulate(&camera, z).is_ok()) {
                continue;
            }
            let id = self.next_id;
            // 2^64 ids: at a million tracks a second, half a million years.
            self.next_id = self.next_id.saturating_add(1);
            let confirmed = settings.confirm_hits <= 1;
            stats.started += 1;
            if confirmed {
                stats.confirmed += 1;
            }
            self.tracks.push(Track {
                id,
                last: *z,
                since_seen: Motion::default(),
                hits: 1,
                misses: 0,
                confirmed,
                first_t_us: t_us,
                last_t_us: t_us,
            });
            observations.push(Observation {
                track: TrackId(id),
                index: m,
                measurement: *z,
                confirmed,
                hits: 1,
            });
        }
        self.stats = stats;
        TrackedFrame { t_us, observations }
    }

    /// The gate of every live track (`None` when its prediction failed).
    fn gates(&mut self, model: &Model) -> Vec<Option<Gate>> {
        let extra = self.settings.extra_sigma_px;
        let noise_new = model.pixel_variance_px2() + extra * extra;
        let mut failed = 0;
        let gates = self
            .tracks
            .iter()
            .map(|t| {
                let q = motion_covariance(
                    &t.since_seen,
                    &model.noise,
                    self.settings.odometry_scale_sigma,
                );
                let gate = predict(model, &t.last, &t.since_seen, &q)
                    .ok()
                    .and_then(|p| {
                        let s = if model.pixel_noise.is_uniform() {
                            p.covariance + Matrix4::identity() * noise_new
                        } else {
                            let r = model
                                .measurement_variances_px2(&p.measurement)
                                .add_scalar(extra * extra);
                            p.covariance + Matrix4::from_diagonal(&r)
                        };
                        let trace = s.trace();
                        let chol = s.cholesky()?;
                        Some(Gate {
                            z: p.measurement,
                            chol,
                            trace,
                        })
                    });
                if gate.is_none() {
                    failed += 1;
                }
                gate
            })
            .collect();
        self.stats.unpredictable += failed;
        gates
    }

    /// Greedy one-to-one assignment by increasing distance with ambiguity rejection. Returns
    /// each track's and each measurement's slot, and which tracks yielded a measurement to an
    /// older track.
    fn assign(
        &mut self,
        gates: &[Option<Gate>],
        measurements: &[Measurement],
        valid: &[bool],
    ) -> (Vec<Slot>, Vec<Slot>, Vec<bool>) {
        let gate_chi2 = self.settings.gate_chi2;
        let margin = self.settings.ambiguity_chi2;
        // Candidates, grouped by track (the outer loop) with each track's range.
        let mut cands: Vec<Candidate> = Vec::new();
        let mut track_range = Vec::with_capacity(gates.len());
        // The measurements by left row: a gate scans only the rows its bound can reach
        // (`|dv| <= |dz| <= sqrt(gate trace)`), so association is O(tracks log m + pairs in
        // reach), not O(tracks m).
        let mut by_row: Vec<(f64, usize)> = measurements
            .iter()
            .enumerate()
            .filter(|&(m, z)| valid.get(m) == Some(&true) && z.y.is_finite())
            .map(|(m, z)| (z.y, m))
            .collect();
        by_row.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        for (t, gate) in gates.iter().enumerate() {
            let start = cands.len();
            if let Some(g) = gate {
                let reach = libm::sqrt(gate_chi2 * g.trace);
                let row = g.z.y;
                let lo = by_row.partition_point(|(v, _)| *v < row - reach);
                for &(v, m) in by_row.iter().skip(lo) {
                    if v > row + reach {
                        break;
                    }
                    let Some(z) = measurements.get(m) else {
                        continue;
                    };
                    let dz = z - g.z;
                    // NaN-safe: a NaN distance is not inside.
                    let may_be_inside = dz.norm_squared() <= gate_chi2 * g.trace;
                    if !may_be_inside {
                        continue;
                    }
                    let d2 = dz.dot(&g.chol.solve(&dz));
                    if d2.is_finite() && d2 <= gate_chi2 {
                        cands.push(Candidate {
                            d2,
                            track: t,
                            meas: m,
                        });
                    }
                }
                // In measurement order, as a scan of every measurement would give them.
                if let Some(mine) = cands.get_mut(start..) {
                    mine.sort_by_key(|c| c.meas);
                }
            }
            track_range.push(start..cands.len());
        }
        // The same candidates grouped by measurement.
        let mut by_meas: Vec<usize> = (0..cands.len()).collect();
        by_meas.sort_by_key(|&c| cands.get(c).map_or(usize::MAX, |x| x.meas));
        let meas_range = |m: usize| {
            let key = |c: &usize| cands.get(*c).map_or(usize::MAX, |x| x.meas);
            let lo = by_meas.partition_point(|c| key(c) < m);
            let hi = by_meas.partition_point(|c| key(c) <= m);
            lo..hi
        };
        let mut order: Vec<usize> = (0..cands.len()).collect();
        order.sort_by(|&a, &b| match (cands.get(a), cands.get(b)) {
            (Some(x), Some(y)) => {
                x.d2.total_cmp(&y.d2)
                    .then(x.track.cmp(&y.track))
                    .then(x.meas.cmp(&y.meas))
            }
            _ => a.cmp(&b),
        });

        let mut track_slots = alloc::vec![Slot::Free; gates.len()];
        let mut meas_slots = alloc::vec![Slot::Free; measurements.len()];
        let mut yielded = alloc::vec![false; gates.len()];
        let ids: Vec<u64> = self.tracks.iter().map(|t| t.id).collect();
        for &c in &order {
            let Some(&Candidate { d2, track, meas }) = cands.get(c) else {
                continue;
            };
            if track_slots.get(track) != Some(&Slot::Free)
                || meas_slots.get(meas) != Some(&Slot::Free)
            {
                continue;
            }
            // Another free measurement about as close to this track: ambiguous.
            let range = track_range.get(track).cloned().unwrap_or(0..0);
            let rivals: Vec<usize> = cands
                .get(range)
                .unwrap_or_default()
                .iter()
                .filter(|x| {
                    x.meas != meas
                        && meas_slots.get(x.meas) == Some(&Slot::Free)
                        && x.d2 <= d2 + margin
                })
                .map(|x| x.meas)
                .collect();
            if !rivals.is_empty() {
                self.stats.ambiguous += 1;
                if let Some(s) = track_slots.get_mut(track) {
                    *s = Slot::Withheld;
                }
                for m in rivals.into_iter().chain(core::iter::once(meas)) {
                    if let Some(s) = meas_slots.get_mut(m) {
                        *s = Slot::Withheld;
                    }
                }
                continue;
            }
            // Other free tracks about as close to this measurement: the oldest takes it.
            let mut winner = track;
            for &k in by_meas.get(meas_range(meas)).unwrap_or_default() {
                let Some(x) = cands.get(k) else { continue };
                if x.track != track
                    && track_slots.get(x.track) == Some(&Slot::Free)
                    && x.d2 <= d2 + margin
                {
                    let older = ids.get(x.track) < ids.get(winner);
                    let loser = if older {
                        core::mem::replace(&mut winner, x.track)
                    } else {
                        x.track
                    };
                    if let Some(y) = yielded.get_mut(loser) {
                        *y = true;
                    }
                }
            }
            if let Some(y) = yielded.get_mut(winner) {
                *y = false;
            }
            if let Some(s) = track_slots.get_mut(winner) {
                *s = Slot::Taken(meas);
            }
            if let Some(s) = meas_slots.get_mut(meas) {
                *s = Slot::Taken(winner);
            }
        }
        (track_slots, meas_slots, yielded)
    }
}

#[cfg(test)]
#[allow(clippy::indexing_slicing, clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::model::tests::rig;
    use alloc::vec;
    use nalgebra::Vector3;
    use rig_model::project;

    /// Measurements of world points from a pose, with the model's own camera.
    fn seen(model: &Model, pose: &Pose2, points: &[Vector3<f64>]) -> Vec<Measurement> {
        points
            .iter()
            .map(|p| project(&model.camera, pose, p).unwrap())
            .collect()
    }

    fn lamps() -> Vec<Vector3<f64>> {
        vec![
            Vector3::new(1.0, 0.3, 3.3),
            Vector3::new(1.4, -0.4, 3.1),
            Vector3::new(0.8, -0.1, 3.5),
        ]
    }

    fn step(theta: f64) -> Motion {
        Motion {
            dx: 0.05,
            dy: 0.0,
            dtheta: theta,
            dt_s: 0.05,
            samples: 5,
        }
    }

    #[test]
    fn prediction_matches_the_projection_and_its_covariance_is_sane() {
        let model = Model::from_rig(&rig());
        let lamp = Vector3::new(1.0, 0.3, 3.3);
        let m = step(0.02);
        let z0 = project(&model.camera, &Pose2::default(), &lamp).unwrap();
        let z1 = project(&model.camera, &m.apply(&Pose2::default()), &lamp).unwrap();
        let q = motion_covariance(&m, &model.noise, 0.02);
        let p = predict(&model, &z0, &m, &q).unwrap();
        assert!(
            (p.measurement - z1).norm() < 1e-9,
            "{:?} {:?}",
            p.measurement,
            z1
        );
        let s = p.covariance;
        assert!((s - s.transpose()).norm() < 1e-9 * s.norm());
        assert!(s.symmetric_eigenvalues().iter().all(|&e| e >= -1e-9));
        // The prior on f and B moves the prediction by at most a few pixels here.
        assert!(s.trace() > 0.0 && s.trace() < 50.0, "{s}");
    }

    #[test]
    fn tracks_follow_lamps_with_stable_ids_and_get_confirmed() {
        let model = Model::from_rig(&rig());
        let mut tracker = Tracker::new(TrackerSettings::default()).unwrap();
        let mut pose = Pose2::default();
        let mut ids = Vec::new();
        for k in 0..10 {
            let m = step(0.03);
            if k > 0 {
                pose = m.apply(&pose);
            }
            let z = seen(&model, &pose, &lamps());
            let frame = tracker.update(&model, k * 50_000, (k > 0).then_some(&m), &z);
            let got: Vec<(u64, usize, bool)> = frame
                .observations
                .iter()
                .map(|o| (o.track.0, o.index, o.confirmed))
                .collect();
            assert_eq!(got.len(), 3, "frame {k}: {got:?}");
            ids = got.iter().map(|g| g.0).collect();
            assert_eq!(ids, vec![0, 1, 2], "frame {k}");
            assert!(got.iter().all(|g| g.2 == (k >= 2)), "frame {k}: {got:?}");
        }
        assert_eq!(ids.len(), 3);
        let st = tracker.stats();
        assert_eq!((st.started, st.confirmed, st.ended), (3, 3, 0));
    }

    #[test]
    fn misses_end_tracks_and_ids_are_never_reused() {
        let model = Model::from_rig(&rig());
        let settings = TrackerSettings {
            max_misses: 2,
            ..TrackerSettings::default()
        };
        let mut tracker = Tracker::new(settings).unwrap();
        let still = Motion::default();
        let z = seen(&model, &Pose2::default(), &lamps()[..1]);
        for k in 0..3 {
            tracker.update(&model, k, Some(&still), &z);
        }
        assert!(tracker.tracks().all(|t| t.confirmed));
        // Three misses: survives two, ended at the third.
        for k in 3..5 {
            assert!(
                tracker
                    .update(&model, k, Some(&still), &[])
                    .observations
                    .is_empty()
            );
            assert_eq!(tracker.tracks().count(), 1);
        }
        tracker.update(&model, 5, Some(&still), &[]);
        assert_eq!(tracker.tracks().count(), 0);
        // Seen again: a new id.
        let f = tracker.update(&model, 6, Some(&still), &z);
        assert_eq!(f.observations[0].track, TrackId(1));
        // A tentative track ends at its first miss.
        tracker.update(&model, 7, Some(&still), &[]);
        assert_eq!(tracker.tracks().count(), 0);
        // An unknown motion ends every track.
        tracker.update(&model, 8, Some(&still), &z);
        tracker.update(&model, 9, None, &z);
        assert_eq!(
            tracker.tracks().map(|t| t.id.0).collect::<Vec<_>>(),
            vec![3]
        );
        assert_eq!(tracker.stats().resets, 1);
    }

    #[test]
    fn clutter_that_does_not_move_with_the_odometry_is_not_followed() {
        let model = Model::from_rig(&rig());
        let mut tracker = Tracker::new(TrackerSettings::default()).unwrap();
        let m = step(0.0);
        let z = seen(&model, &Pose2::default(), &lamps()[..1]);
        tracker.update(&model, 0, None, &z);
        // The same measurement again although the robot moved 5 cm: about 12 px off.
        let f = tracker.update(&model, 1, Some(&m), &z);
        assert_eq!(f.observations[0].track, TrackId(1));
        assert_eq!(tracker.tracks().count(), 1);
    }

    #[test]
    fn two_equally_good_measurements_are_not_guessed() {
        let model = Model::from_rig(&rig());
        let mut tracker = Tracker::new(TrackerSettings::default()).unwrap();
        let still = Motion::default();
        let z = seen(&model, &Pose2::default(), &lamps()[..1])[0];
        for k in 0..3 {
            tracker.update(&model, k, Some(&still), &[z]);
        }
        // Two measurements half a pixel either side of the prediction.
        let a = z + Measurement::new(0.5, 0.0, 0.5, 0.0);
        let b = z - Measurement::new(0.5, 0.0, 0.5, 0.0);
        let f = tracker.update(&model, 3, Some(&still), &[a, b]);
        assert!(f.observations.is_empty(), "{f:?}");
        assert_eq!(tracker.stats().ambiguous, 1);
        assert_eq!(tracker.tracks().count(), 1, "the confirmed track coasts");
        // One clearly better: taken.
        let c = z + Measurement::new(3.0, 0.0, 3.0, 0.0);
        let f = tracker.update(&model, 4, Some(&still), &[c, z]);
        assert_eq!(f.observations.len(), 2);
        assert_eq!(
            (f.observations[0].track, f.observations[0].index),
            (TrackId(0), 1)
        );
    }

    #[test]
    fn a_duplicate_track_yields_to_the_older_one() {
        let model = Model::from_rig(&rig());
        let mut tracker = Tracker::new(TrackerSettings::default()).unwrap();
        let still = Motion::default();
        let z = seen(&model, &Pose2::default(), &lamps()[..1])[0];
        let nudge = Measurement::new(0.2, 0.1, 0.2, 0.1);
        // Two measurements of one lamp start two tracks (as after a stereo double match).
        tracker.update(&model, 0, Some(&still), &[z, z + nudge]);
        assert_eq!(tracker.tracks().count(), 2);
        let f = tracker.update(&model, 1, Some(&still), &[z + nudge * 0.5]);
        assert_eq!(f.observations.len(), 1);
        assert_eq!(f.observations[0].track, TrackId(0));
        assert_eq!(tracker.tracks().count(), 1);
        assert_eq!(tracker.stats().duplicates, 1);
    }

    #[test]
    fn bad_values_never_panic_nor_enter_a_track() {
        let mut model = Model::from_rig(&rig());
        let mut tracker = Tracker::new(TrackerSettings::default()).unwrap();
        let nan = Measurement::new(f64::NAN, 1.0, 2.0, 3.0);
        let backwards = Measurement::new(100.0, 100.0, 120.0, 100.0);
        let f = tracker.update(&model, 0, None, &[nan, backwards]);
        assert!(f.observations.is_empty());
        let z = seen(&model, &Pose2::default(), &lamps()[..1]);
        tracker.update(&model, 1, None, &z);
        let bad_motion = Motion {
            dx: f64::NAN,
            ..Motion::default()
        };
        tracker.update(&model, 2, Some(&bad_motion), &z);
        assert_eq!(tracker.stats().resets, 1);
        model.camera.baseline = f64::NAN;
        let f = tracker.update(&model, 3, Some(&Motion::default()), &z);
        assert!(f.observations.is_empty());
        assert!(tracker.stats().unpredictable >= 1);
        model.camera_covariance[(0, 0)] = f64::INFINITY;
        model.camera.baseline = 0.12;
        tracker.update(&model, 4, Some(&Motion::default()), &z);
    }

    #[test]
    fn settings_are_checked() {
        for s in [
            TrackerSettings {
                gate_chi2: 0.0,
                ..TrackerSettings::default()
            },
            TrackerSettings {
                ambiguity_chi2: f64::NAN,
                ..TrackerSettings::default()
            },
            TrackerSettings {
                confirm_hits: 0,
                ..TrackerSettings::default()
            },
            TrackerSettings {
                extra_sigma_px: -1.0,
                ..TrackerSettings::default()
            },
        ] {
            let e = Tracker::new(s).unwrap_err();
            assert!(alloc::format!("{e}").starts_with("tracker."), "{e}");
        }
    }
}
