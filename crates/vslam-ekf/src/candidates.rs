//! Landmark confirmation and the track-to-landmark map: the per-frame entry point.
//!
//! The association (crate `track`) hands over measurements keyed by its own persistent track
//! ids. A track bound to a landmark is an observation for the update; an unbound one is a
//! *candidate*, and becomes a landmark only after it was seen in `frames_to_confirm`
//! consecutive frames with consistent triangulations: each frame's world point must lie
//! within a Mahalanobis gate (3 dof) of the previous frame's, under the covariance of their
//! difference. That covariance is the pixel noise of both triangulations plus the odometry
//! noise accumulated between the two frames, carried to the point by the pose Jacobian; the
//! absolute pose and camera errors are shared by the two points and cancel to first order, so
//! they are left out, which keeps the gate tight (millimetres across, where a clutter feature
//! jumps by metres). A candidate missing from a frame starts again.
//!
//! A landmark the filter removes as false (too many gate rejections in a row) takes its track
//! with it: the track is *retired* and never re-confirmed, so a wrong association cannot
//! re-enter the map under the same track. A landmark the caller removes
//! ([`Candidates::remove_landmark`]) only unbinds its track, which may then confirm again.

use alloc::collections::{BTreeMap, BTreeSet};
use alloc::vec::Vec;

use nalgebra::{Matrix3, Vector3};
use rig_model::Measurement;

use crate::chi2::chi2_quantile;
use crate::error::Error;
use crate::filter::{Ekf, UpdateReport};
use crate::landmarks::LandmarkId;
use crate::views::{self, View};

/// Confirmation settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CandidateSettings {
    /// Consecutive frames, with consistent triangulations, before a track becomes a landmark.
    pub frames_to_confirm: u32,
    /// Probability mass inside the consistency gate between successive world points (3 dof):
    /// 0.999 gives 16.27.
    pub consistency_probability: f64,
    /// Observations used in one frame's update at most (0: as many as the cost model allows,
    /// [`observation_budget`]). The ones kept are spread over the image (a 4 x 4 grid of
    /// the left image, taken in turn) and, within a cell, the landmarks known longest first.
    pub max_observations: usize,
    /// Landmarks predicted inside both images at most: a confirmed candidate waits while
    /// that many are in view (a textured scene would otherwise add a landmark for every
    /// corner it has).
    pub max_in_view: usize,
    /// While the map holds more than [`CandidateSettings::prune_above`] landmarks, a landmark
    /// with at most this many observations that has not been observed for
    /// [`CandidateSettings::brief_frames`] frames is removed: features that come and go do
    /// not make the state grow without bound, and a lamp passed briefly in a small map stays.
    pub brief_observations: u64,
    /// See [`CandidateSettings::brief_observations`].
    pub prune_above: usize,
    /// See [`CandidateSettings::brief_observations`].
    pub brief_frames: u64,
    /// A confirmed candidate closer than this to a landmark is not added, and its track is
    /// retired: it is a second feature of the same thing (the two corners of a tube's end,
    /// a blurred corner's two maxima), metres.
    pub min_separation_m: f64,
    /// A candidate whose pair lies in the outer band beyond the field of use
    /// (`Ekf::in_outer_band`) is born from all its frames at once (`crate::views`), and
    /// only once that estimate's largest sigma is at most this share of its distance from
    /// the cameras: one far-out pair fixes a lamp's depth too poorly to start a landmark
    /// from. 0: born from one pair like the rest.
    pub outer_birth_relative_sigma: f64,
}

/// Observations one update may use when the state has `n` elements: the batch update costs
/// about `n^2` per observation (its timings at 1504 states are in docs/benchmarks.md, "Phase 2
/// EKF SLAM"), so the budget keeps `n^2 k` near 1e7, between 8 and 64 observations; half that
/// with the Joseph form (twice the work).
pub fn observation_budget(n: usize, joseph: bool) -> usize {
    #[allow(
        clippy::cast_precision_loss,
        clippy::cast_possible_truncation,
        clippy::cast_sign_loss
    )]
    let k = (1.0e7 / ((n.max(1) * n.max(1)) as f64)) as usize;
    let k = k.clamp(8, 64);
    if joseph { (k / 2).max(8) } else { k }
}

impl Default for CandidateSettings {
    fn default() -> Self {
        Self {
            frames_to_confirm: 3,
            consistency_probability: 0.999,
            max_observations: 0,
            max_in_view: 48,
            brief_observations: 5,
            prune_above: 200,
            brief_frames: 20,
            min_separation_m: 0.05,
            outer_birth_relative_sigma: 0.05,
        }
    }
}

/// At most `budget` of a frame's observations: a 4 x 4 grid over the left image taken in
/// turn, so that they stay spread over the image (the pose and the camera parameters are
/// best informed by lamps in every direction), and within a cell the landmarks with at most
/// `brief` observations first (a new landmark gets its first updates), then those with the
/// most (the best known anchor the pose). Keeps the input order otherwise.
fn select_observations(
    ekf: &Ekf,
    batch: Vec<(LandmarkId, Measurement)>,
    budget: usize,
    brief: u64,
    frame: u64,
) -> Vec<(LandmarkId, Measurement)> {
    if batch.len() <= budget {
        return batch;
    }
    const CELLS: usize = 4;
    let (w, h) = ekf.image_size();
    let (w, h) = (f64::from(w.max(1)), f64::from(h.max(1)));
    let cell_of = |z: &Measurement| {
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let c = |x: f64, size: f64| ((x / size * CELLS as f64).max(0.0) as usize).min(CELLS - 1);
        c(z[1], h) * CELLS + c(z[0], w)
    };
    let mut cells: Vec<Vec<usize>> = alloc::vec![Vec::new(); CELLS * CELLS];
    for (i, (_, z)) in batch.iter().enumerate() {
        if let Some(cell) = cells.get_mut(cell_of(z)) {
            cell.push(i);
        }
    }
    for cell in &mut cells {
        cell.sort_by_key(|&i| {
            let id = batch.get(i).map(|(id, _)| *id);
            let seen = id.and_then(|id| ekf.observations_of(id)).unwrap_or(0);
            // A landmark still brief first: else a crowded frame never updates a new one,
            // and it is pruned as brief once out of view (issue 35: lamps passed once along
            // a wall were mapped and then lost).
            (seen > brief, core::cmp::Reverse(seen), id)
        });
        cell.reverse(); // taken from the back
    }
    // The round starts at a cell that moves on each frame: with fewer observations to take
    // than cells holding some, a fixed start left the last cells (the image's bottom row)
    // without a turn, and a lamp passed once there was bound for 15 frames and never
    // updated (issue 35, the radtan hall's last row).
    #[allow(clippy::cast_possible_truncation)] // a cell index
    let start = (frame % cells.len() as u64) as usize;
    cells.rotate_left(start);
    let mut keep = alloc::vec![false; batch.len()];
    let mut kept = 0;
    while kept < budget {
        let mut any = false;
        for cell in &mut cells {
            if kept >= budget {
                break;
            }
            if let Some(i) = cell.pop() {
                if let Some(k) = keep.get_mut(i) {
                    *k = true;
                }
                kept += 1;
                any = true;
            }
        }
        if !any {
            break;
        }
    }
    batch
        .into_iter()
        .zip(keep)
        .filter_map(|(o, k)| k.then_some(o))
        .collect()
}

/// A candidate's last sighting.
#[derive(Debug, Clone, PartialEq)]
struct Pending {
    hits: u32,
    last_frame: u64,
    point: Vector3<f64>,
    /// Covariance of `point` from the pixel noise.
    covariance: Matrix3<f64>,
    /// Its frames since it was last found inconsistent (the latest [`views::MAX_VIEWS`]).
    views: Vec<View>,
    /// The dead reckoning's covariance accumulated over `views` (summed, a bound over the
    /// seconds they span).
    drift: Matrix3<f64>,
}

/// What one frame did.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct FrameReport {
    /// The filter's update with the bound tracks.
    pub update: UpdateReport,
    /// Tracks confirmed this frame and the landmarks made of them.
    pub added: Vec<(u64, LandmarkId)>,
    /// Landmarks removed as false this frame, with their (now retired) tracks.
    pub removed: Vec<(u64, LandmarkId)>,
    /// Measurements of retired tracks, ignored.
    pub ignored: usize,
    /// Candidates still waiting for confirmation.
    pub pending: usize,
    /// Bound observations left out of the update by its budget
    /// ([`CandidateSettings::max_observations`]).
    pub skipped: usize,
    /// Brief landmarks removed ([`CandidateSettings::brief_observations`]).
    pub pruned: Vec<LandmarkId>,
    /// Confirmed candidates not added for being closer than
    /// [`CandidateSettings::min_separation_m`] to a landmark (their tracks retired).
    pub merged: usize,
}

/// Track-keyed front door of the filter: binds tracks to landmarks, confirms new ones.
#[derive(Debug, Clone)]
pub struct Candidates {
    settings: CandidateSettings,
    gate: f64,
    frame: u64,
    pending: BTreeMap<u64, Pending>,
    landmark_of: BTreeMap<u64, LandmarkId>,
    track_of: BTreeMap<LandmarkId, u64>,
    retired: BTreeSet<u64>,
    /// The frame each landmark was last observed in (accepted by the gate, or added).
    last_seen: BTreeMap<LandmarkId, u64>,
}

impl Candidates {
    /// Empty bookkeeping.
    pub fn new(settings: CandidateSettings) -> Result<Self, Error> {
        if settings.frames_to_confirm == 0 {
            return Err(Error::BadValue {
                name: "CandidateSettings.frames_to_confirm",
                value: 0.0,
                expected: "at least 1",
            });
        }
        let p = settings.consistency_probability;
        if !(p.is_finite() && p > 0.0 && p < 1.0) {
            return Err(Error::BadValue {
                name: "CandidateSettings.consistency_probability",
                value: p,
                expected: "strictly between 0 and 1",
            });
        }
        Ok(Self {
            settings,
            gate: chi2_quantile(p, 3.0),
            frame: 0,
            pending: BTreeMap::new(),
            landmark_of: BTreeMap::new(),
            track_of: BTreeMap::new(),
            retired: BTreeSet::new(),
            last_seen: BTreeMap::new(),
        })
    }

    /// The landmark a track is bound to.
    pub fn landmark_of(&self, track: u64) -> Option<LandmarkId> {
        self.landmark_of.get(&track).copied()
    }

    /// The track a landmark is bound to.
    pub fn track_of(&self, id: LandmarkId) -> Option<u64> {
        self.track_of.get(&id).copied()
    }

    /// Every binding, `(track, landmark)`, by track.
    pub fn bindings(&self) -> impl Iterator<Item = (u64, LandmarkId)> + '_ {
        self.landmark_of.iter().map(|(&t, &l)| (t, l))
    }

    /// Whether a track was retired with a false landmark.
    pub fn is_retired(&self, track: u64) -> bool {
        self.retired.contains(&track)
    }

    /// Candidates waiting for confirmation.
    pub fn pending_count(&self) -> usize {
        self.pending.len()
    }

    /// The consistency gate's bound (3 dof).
    pub fn gate_bound(&self) -> f64 {
        self.gate
    }

    /// Binds a track to an existing landmark (map matching found it again under a new track).
    /// A track already bound elsewhere, or a landmark bound to another track, is rebound.
    pub fn bind(&mut self, ekf: &Ekf, track: u64, id: LandmarkId) -> Result<(), Error> {
        if !ekf.contains(id) {
            return Err(Error::UnknownLandmark { id });
        }
        self.forget_track(track);
        if let Some(old) = self.track_of.remove(&id) {
            self.landmark_of.remove(&old);
        }
        self.landmark_of.insert(track, id);
        self.track_of.insert(id, track);
        Ok(())
    }

    /// Forgets everything about a track: binding, candidacy, retirement.
    pub fn forget_track(&mut self, track: u64) {
        self.pending.remove(&track);
        self.retired.remove(&track);
        if let Some(id) = self.landmark_of.remove(&track) {
            self.track_of.remove(&id);
        }
    }

    /// Removes a landmark from the filter and unbinds its track (which may confirm again).
    pub fn remove_landmark(&mut self, ekf: &mut Ekf, id: LandmarkId) -> Result<(), Error> {
        ekf.remove_landmark(id)?;
        if let Some(track) = self.track_of.remove(&id) {
            self.landmark_of.remove(&track);
        }
        Ok(())
    }

    /// One stereo frame: updates the filter with the bound tracks, removes false landmarks,
    /// advances the candidates and adds the confirmed ones. Call after predicting to the
    /// frame's time. On an error from the update nothing changes.
    pub fn observe(
        &mut self,
        ekf: &mut Ekf,
        frame: &[(u64, Measurement)],
    ) -> Result<FrameReport, Error> {
        let mut seen: Vec<u64> = Vec::with_capacity(frame.len());
        for (track, z) in frame {
            if let Some(&value) = z.iter().find(|v| !v.is_finite()) {
                return Err(Error::NonFiniteTrackMeasurement {
                    track: *track,
                    value,
                });
            }
            if seen.contains(track) {
                return Err(Error::DuplicateTrack { track: *track });
            }
            seen.push(*track);
        }
        let mut report = FrameReport::default();
        let mut batch = Vec::new();
        let mut unbound: Vec<(u64, Measurement)> = Vec::new();
        for &(track, z) in frame {
            if self.retired.contains(&track) {
                report.ignored += 1;
                continue;
            }
            match self.landmark_of.get(&track) {
                Some(&id) if ekf.contains(id) => batch.push((id, z)),
                _ => unbound.push((track, z)),
            }
        }
        let budget = match self.settings.max_observations {
            0 => ekf.observation_budget(),
            k => k,
        };
        // Seen is tracked: a landmark the budget leaves out of this update is still in view
        // (it is not brief while it is).
        for (id, _) in &batch {
            self.last_seen.insert(*id, self.frame + 1);
        }
        let batch = select_observations(
            ekf,
            batch,
            budget,
            self.settings.brief_observations,
            self.frame,
        );
        report.skipped = frame.len() - report.ignored - unbound.len() - batch.len();
        report.update = ekf.update(&batch)?;
        // Bindings to landmarks the caller removed from the filter directly.
        let stale: Vec<u64> = self
            .landmark_of
            .iter()
            .filter(|(_, id)| !ekf.contains(**id))
            .map(|(&t, _)| t)
            .collect();
        for track in stale {
            if let Some(id) = self.landmark_of.remove(&track) {
                self.track_of.remove(&id);
                if report.update.removed.contains(&id) {
                    self.retired.insert(track);
                    report.removed.push((track, id));
                }
            }
        }
        self.frame += 1;
        // Brief landmarks not seen for a while leave the state.
        let now = self.frame;
        let crowded = ekf.landmark_count() > self.settings.prune_above;
        let brief: Vec<LandmarkId> = self
            .last_seen
            .iter()
            .filter(|_| crowded)
            .filter(|&(&id, &seen)| {
                now.saturating_sub(seen) > self.settings.brief_frames
                    && ekf
                        .observations_of(id)
                        .is_some_and(|o| o <= self.settings.brief_observations)
            })
            .map(|(&id, _)| id)
            .collect();
        for id in brief {
            self.last_seen.remove(&id);
            if ekf.remove_landmark(id).is_ok() {
                report.pruned.push(id);
                if let Some(track) = self.track_of.remove(&id) {
                    self.landmark_of.remove(&track);
                    self.retired.insert(track);
                }
            }
        }
        self.last_seen.retain(|id, _| ekf.contains(*id));
        // Counted once, when the first candidate is ready (a projection of every landmark).
        let mut in_view: Option<usize> = None;
        let motion = ekf.take_motion_covariance();
        let camera = ekf.camera();
        let pose = ekf.pose();
        let sigma = ekf.noise().pixel;
        for (track, z) in unbound {
            let Ok(tri) = rig_model::triangulate(&camera, &z) else {
                self.pending.remove(&track);
                continue;
            };
            let point = tri.p_in_world(&camera, &pose);
            let covariance = if ekf.pixel_noise().is_uniform() {
                tri.covariance_in_world(&camera, &pose, sigma, None, None)
            } else {
                let r = nalgebra::Vector4::from(ekf.measurement_variances(&z));
                tri.covariance_in_world_of(&camera, &pose, &r, None, None)
            };
            let gp = tri.jac_pose(&camera, &pose);
            let (hits, mut track_views, drift) = match self.pending.remove(&track) {
                Some(prev) if prev.last_frame + 1 == self.frame => {
                    let joint = prev.covariance + covariance + gp * motion * gp.transpose();
                    let delta = point - prev.point;
                    let consistent = joint
                        .cholesky()
                        .map(|c| delta.dot(&c.solve(&delta)))
                        .is_some_and(|d2| d2 <= self.gate);
                    if consistent {
                        (prev.hits + 1, prev.views, prev.drift + motion)
                    } else {
                        (1, Vec::new(), Matrix3::zeros())
                    }
                }
                _ => (1, Vec::new(), Matrix3::zeros()),
            };
            views::push_view(&mut track_views, View { pose, z });
            let confirmed = hits >= self.settings.frames_to_confirm;
            // Far out, the frames together decide, and only once they fix the point well.
            let from_views = (confirmed
                && self.settings.outer_birth_relative_sigma > 0.0
                && ekf.in_outer_band(&z))
            .then(|| {
                self.triangulated_from_views(ekf, &camera, &pose, &track_views, point, &drift)
            });
            let ready = confirmed && from_views.as_ref().is_none_or(Option::is_some);
            let from_views = from_views.flatten();
            let birth_point = from_views.as_ref().map_or(point, |(p, _, _)| *p);
            let room = ready && {
                let seen = *in_view.get_or_insert_with(|| ekf.visible_landmarks().len());
                seen + report.added.len() < self.settings.max_in_view
            };
            if ready
                && ekf.landmark_positions().any(|(_, position)| {
                    (position - birth_point).norm() < self.settings.min_separation_m
                })
            {
                // A second feature of something already mapped.
                self.retired.insert(track);
                report.merged += 1;
                continue;
            }
            if room {
                let added = match &from_views {
                    Some((position, jacobian, noise)) => {
                        ekf.add_landmark_from_views(position, jacobian, noise)
                    }
                    None => ekf.add_landmark(&z),
                };
                if let Ok(id) = added {
                    self.landmark_of.insert(track, id);
                    self.track_of.insert(id, track);
                    self.last_seen.insert(id, self.frame);
                    report.added.push((track, id));
                }
            } else {
                self.pending.insert(
                    track,
                    Pending {
                        hits,
                        last_frame: self.frame,
                        point,
                        covariance,
                        views: track_views,
                        drift,
                    },
                );
            }
        }
        let now = self.frame;
        self.pending.retain(|_, p| p.last_frame == now);
        report.pending = self.pending.len();
        Ok(report)
    }

    /// A far-out candidate triangulated from its frames (`crate::views`), if the frames
    /// agree (their residual inside the gate's probability) and fix the point to within
    /// [`CandidateSettings::outer_birth_relative_sigma`] of its distance: the point, its
    /// camera derivative and its covariance (pixels and the dead reckoning over the frames,
    /// which moves the point rigidly with the pose).
    fn triangulated_from_views(
        &self,
        ekf: &Ekf,
        camera: &rig_model::CameraParams,
        pose: &rig_model::Pose2,
        track_views: &[View],
        start: Vector3<f64>,
        drift: &Matrix3<f64>,
    ) -> Option<(Vector3<f64>, rig_model::rig::Jac3xC, Matrix3<f64>)> {
        if track_views.len() < 2 {
            return None;
        }
        let variances = |h: &Measurement| ekf.measurement_variances(h);
        let mut t = views::triangulate_views(camera, track_views, start, variances)?;
        #[allow(clippy::cast_precision_loss)] // a few hundred rows
        let dof = (t.rows - 3) as f64;
        if t.chi2 > chi2_quantile(self.settings.consistency_probability, dof) {
            return None;
        }
        views::add_vehicle_sensitivity(camera, track_views, pose, &mut t, variances);
        let range = rig_model::point_in_rig(camera, pose, &t.position).norm();
        let g = crate::landmarks::carried_by_pose(pose, &t.position);
        let noise = t.covariance + g * drift * g.transpose();
        let largest = noise.symmetric_eigenvalues().max();
        let bound = self.settings.outer_birth_relative_sigma * range;
        (largest.is_finite() && largest <= bound * bound).then_some((
            t.position,
            t.camera_jacobian,
            noise,
        ))
    }
}
