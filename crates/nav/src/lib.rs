//! The navigator: the method's two phases in one object, fed with the board's stereo frames
//! and the odometry in time order, from any source (a log, a live link, Python arrays).
//!
//! 1. **Phase 1, self-calibration.** Every frame goes through the association
//!    ([`track::FrontEnd`]: left-right matching on the rectified rig, frame-to-frame tracking
//!    predicted by the odometry); every frame's confirmed tracks and the odometry since the
//!    frame before feed [`selfcal::smoother::Smoother`], the batch over every frame (every pose,
//!    every landmark and `C` at once), re-solved every half second. Between solves the pose is
//!    dead reckoning from the batch's last one.
//! 2. **The switch**, at the frame where the calibration became stable (the smoother's stable
//!    rule; its time is [`Navigator::phase_switch_t_us`]): the EKF starts from the batch's joint
//!    estimate of the last pose, every landmark and `C` with their covariance, so the frames of
//!    phase 1 are in the map and the map is in the first frame's world frame; the association
//!    continues with the calibrated camera. The phase-1 trajectory, smoothed, is
//!    [`Navigator::phase1_trajectory`]. The batch's buffer is bounded
//!    ([`selfcal::smoother::SmootherSettings::max_frames`]): when it is full the hand-over is
//!    forced, and so it is by [`Navigator::finish`] at the end of a log, so that phase 2
//!    always maps; [`Navigator::uninformed`] names the parameters the data did not give (they
//!    enter phase 2 with about their prior).
//! 3. **Phase 2, EKF SLAM** ([`vslam_ekf::Ekf`]): predict with the odometry between frames,
//!    update with the tracks bound to landmarks, confirm new landmarks
//!    ([`vslam_ekf::Candidates`]). A track not bound to a landmark is first matched against
//!    the map: each landmark predicted inside both images and not observed under another
//!    track this frame is a candidate, scored by its innovation's Mahalanobis distance
//!    (`S = H P H^T + R`, 4 dof); the best is taken if it is inside the gate and no other is
//!    (a lamp seen again after leaving the view keeps its landmark). A track that matches no
//!    landmark is a candidate for a new one once the tracker has confirmed it; clutter never
//!    passes both confirmations (the tracker's, and the consistency of its triangulations).
//!
//! Phase 1 can be skipped ([`NavSettings::skip_phase1`]): phase 2 then starts at the first
//! frame from the rig's nominal values and priors, as in the paper's experiment.
//!
//! Feed the odometry up to a frame's timestamp before the frame ([`Navigator::push_odometry`],
//! [`Navigator::push_frame`]); both must come in time order (a log's board frames arrive later
//! than the odometry of the same instant: sort by the data's timestamps, as `replay` does).
//! Every input is checked; a refusal is an [`Error`] and leaves the navigator as it was.
//!
//! `#![no_std]` with `alloc`, like the filter, so that the vehicle controller can run it.
#![no_std]
#![forbid(unsafe_code)]
#![deny(missing_docs)]
#![warn(clippy::indexing_slicing)]

#[cfg(not(feature = "alloc"))]
compile_error!("the nav crate needs the `alloc` feature (or `std`)");

extern crate alloc;
#[cfg(feature = "std")]
extern crate std;

mod error;
mod frame_pairs;
pub mod loops;
pub mod sequencer;

use alloc::collections::{BTreeMap, BTreeSet};
use alloc::vec::Vec;

use nalgebra::{Matrix3, Matrix4, Vector4};
use rig_model::camera::Param;
use rig_model::camera::{CameraParams, Pose2};
use rig_model::config::Rig;
use rig_model::handover::Handover;
use rig_model::handover::{BatchHandover, HandoverReason};
use rig_model::odometry::{Motion, OdomSample, OdometryFactor};
use selfcal::OdometryStep;
use selfcal::smoother::{Smoother, SmootherSettings};
use track::{FrontEnd, FrontEndSettings, Model, Pixel, TrackedFrame};
use vslam_ekf::chi2::chi2_quantile;
use vslam_ekf::{
    CameraCovariance, CandidateSettings, Candidates, Ekf, Increment, LandmarkId, Settings,
};

pub use error::Error;
pub use frame_pairs::{FramePairCalibration, FramePairSettings};

/// Odometry samples the navigator holds at most between two frames (100 s at 100 Hz): a live
/// stream with odometry and no frames does not grow it without bound.
pub const MAX_ODOMETRY_BUFFER: usize = 10_000;

/// How far past a frame's timestamp the odometry should be fed before the frame, microseconds.
/// A frame stamped `t` by the board was exposed at odometry-clock time `t - time_offset`
/// (vehicle-interfaces.md 1.2): with a negative offset that is after `t`, and the motion up to
/// the exposure needs odometry from after the stamp (without it the last sample is held, and a
/// clock offset of -12 ms wrecked the aisle's map). A log's reader (`replay`) feeds this much
/// ahead; a live caller can only feed what has arrived.
pub const ODOMETRY_LOOKAHEAD_US: u64 = 250_000;

/// Odometry kept before a frame's odometry-clock time beyond the one sample held into the
/// next interval, microseconds: the clock offset's estimate may move the next interval's
/// start back by this much (vehicle-interfaces.md 1.2).
const ODOMETRY_MARGIN_US: u64 = 200_000;

/// What the navigator runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum NavMode {
    /// The method: phase 1 by the batch over every frame, the switch, phase 2.
    #[default]
    Navigate,
    /// Phase 1 only, by the paper's frame pairs ([`FramePairCalibration`], with
    /// [`NavSettings::frame_pairs`]): no batch, no switch, no phase 2; the pose is dead
    /// reckoning. `stereonav calibrate` (`replay::calibrate_log`).
    CalibrateFramePairs,
}

/// The navigator's tuning.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NavSettings {
    /// What runs: the method, or phase 1 alone by frame pairs.
    pub mode: NavMode,
    /// Stereo matching and tracking.
    pub front_end: FrontEndSettings,
    /// Phase 1, the batch over every frame (and when it counts as stable: the switch).
    pub phase1: SmootherSettings,
    /// The filter.
    pub ekf: Settings,
    /// Landmark confirmation.
    pub candidates: CandidateSettings,
    /// Probability mass inside the map-matching gate (4 dof): 0.999 gives 18.47.
    pub map_match_probability: f64,
    /// Start phase 2 at the first frame from the rig's nominal values and priors.
    pub skip_phase1: bool,
    /// Phase 2 re-linearised by the batch: after the hand-over the batch goes on as a
    /// fixed-lag smoother over the last [`SmootherSettings::window`] frames with the filter's
    /// associations, and the filter is re-seeded with its joint estimate at every solve
    /// (docs/phase2.md, "Phase 2 re-linearised"). Off with the camera considered.
    pub smooth_phase2: bool,
    /// Phase 2's smoother over the landmarks near the vehicle when the map outgrows its
    /// budget ([`SmootherSettings::max_landmarks`]): started again from the filter's marginal
    /// over them whenever the vehicle moves on, and put back with the rest of the map carried
    /// by its cross-covariances (`vslam_ekf::Ekf::replace_marginal`). Off (the default), the
    /// smoother stops at the budget and the filter maps on alone: measured on the halls and
    /// the warehouse, the smoother near the vehicle was slower and not more accurate, and
    /// moved the hall maps' scale (docs/halls.md, "The smoother over part of the map").
    pub smooth_near_vehicle: bool,
    /// The pose counts as lost for map matching only while it is more than
    /// [`MATCH_MAX_POSE_SIGMA_M`] uncertain in the world *and* relative to the map around it:
    /// no landmark accepted in the last [`ANCHOR_FRAMES`] frames is within that sigma of it
    /// (the covariance of `L - p` in the vehicle's frame, the heading's share and every
    /// correlation in it), or a landmark predicted in view is not (a place mapped before, to
    /// be recognised by its constellation). Off (the default), the absolute sigma alone.
    pub relative_lost: bool,
    /// Hold (consider, not refine) in phase 2 every estimated camera parameter the motion so
    /// far cannot inform: all of them until the vehicle has translated
    /// [`NavSettings::min_translation_m`], and those with a structural trap
    /// (`selfcal::solver::structural_trap`: f with the head looking straight up, the camera
    /// height, the offsets before the vehicle turned). Otherwise a model error elsewhere
    /// (the camera wobbling while the odometry says the vehicle stands) is absorbed by them
    /// (docs/real-images.md).
    pub hold_unexcited: bool,
    /// Distance the odometry must have travelled (counting only its significant motion)
    /// before the camera parameters are refined in phase 2, metres.
    pub min_translation_m: f64,
    /// The frame pairs of [`NavMode::CalibrateFramePairs`] (unused otherwise).
    pub frame_pairs: FramePairSettings,
}

impl Default for NavSettings {
    /// The crates' defaults; phase 1 not skipped.
    fn default() -> Self {
        Self {
            mode: NavMode::Navigate,
            front_end: FrontEndSettings::default(),
            phase1: SmootherSettings::default(),
            ekf: Settings::default(),
            candidates: CandidateSettings::default(),
            map_match_probability: 0.999,
            skip_phase1: false,
            smooth_phase2: true,
            smooth_near_vehicle: false,
            relative_lost: false,
            hold_unexcited: true,
            min_translation_m: 0.05,
            frame_pairs: FramePairSettings::default(),
        }
    }
}

/// Which phase the navigator is in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Phase {
    /// Phase 1: self-calibration, dead reckoning.
    Calibrating,
    /// Phase 2: EKF SLAM.
    Navigating,
}

/// What one frame did.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct FrameOutcome {
    /// Landmarks updated at this frame, with their NIS (4 dof).
    pub accepted: Vec<(LandmarkId, f64)>,
    /// Landmarks whose observation the gate rejected.
    pub rejected: Vec<LandmarkId>,
    /// Landmarks added (confirmed tracks).
    pub added: Vec<LandmarkId>,
    /// Landmarks removed as false.
    pub removed: Vec<LandmarkId>,
    /// Tracks bound to an existing landmark by map matching at this frame.
    pub rematched: Vec<(u64, LandmarkId)>,
    /// Landmarks merged at this frame, `(kept, merged into it)`: two estimates of one lamp
    /// (never observed in the same frame, within their joint uncertainty of each other).
    pub merged: Vec<(LandmarkId, LandmarkId)>,
    /// The observations of landmarks the filter's update was given at this frame (those of
    /// [`FrameOutcome::accepted`] and [`FrameOutcome::rejected`]), each with the two board
    /// features it was made of: the navigator's own association, feature by feature.
    pub associations: Vec<Association>,
    /// Phase 1 solved at this frame (a new calibration estimate).
    pub solved: bool,
    /// The switch to phase 2 happened at this frame.
    pub switched: bool,
    /// The odometry did not cover the interval since the previous frame: the pose was held.
    pub no_odometry: bool,
}

impl FrameOutcome {
    /// The landmarks observed at this frame: updated or rejected by the gate.
    pub fn observed(&self) -> Vec<LandmarkId> {
        self.accepted
            .iter()
            .map(|(id, _)| *id)
            .chain(self.rejected.iter().copied())
            .collect()
    }
}

/// A landmark's observation the filter's update was given at a frame, and the board features
/// it was made of.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Association {
    /// The landmark.
    pub landmark: LandmarkId,
    /// Index of the left feature in the frame's left list as given to
    /// [`Navigator::push_frame`] (the board's raw list, before any lens mapping).
    pub left: usize,
    /// Index of the right feature in the frame's right list, likewise.
    pub right: usize,
    /// The gate accepted it: the landmark was updated with it (else it was rejected).
    pub accepted: bool,
}

/// Counters over the navigator's life.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct NavStats {
    /// Frames processed.
    pub frames: u64,
    /// Odometry samples accepted.
    pub odometry: u64,
    /// Frames at which the odometry did not reach back to the previous frame.
    pub frames_without_odometry: u64,
    /// Phase-1 solves of the batch.
    pub phase1_solves: u64,
    /// Odometry samples dropped because no frame came for too long (the buffer is bounded,
    /// [`MAX_ODOMETRY_BUFFER`]).
    pub odometry_dropped: u64,
    /// Tracks bound to an existing landmark by map matching.
    pub rematched: u64,
    /// Observations the filter's gate rejected.
    pub rejected: u64,
    /// Updates the filter refused (state left as it was).
    pub refused_updates: u64,
    /// Solves of phase 2's fixed-lag smoother.
    pub phase2_solves: u64,
    /// Joint estimates of the smoother the filter could not take (it went on without).
    pub phase2_reseeds_refused: u64,
    /// Of those, joint estimates outside the filter's uncertainty (pose and camera beyond
    /// the chi-square gate of [`RESEED_PROBABILITY`] under the filter's covariance): the
    /// smoother started again from the filter.
    pub phase2_reseeds_inconsistent: u64,
    /// The frame count when the smoother stopped because the map outgrew
    /// [`SmootherSettings::max_landmarks`] (0: it did not; never with
    /// [`NavSettings::smooth_near_vehicle`]).
    pub phase2_smoother_stopped_at: u64,
    /// With [`NavSettings::smooth_near_vehicle`]: times phase 2's smoother started again from
    /// the filter over the landmarks near the vehicle (a landmark observed that it did not
    /// carry, its budget full, a merge).
    pub phase2_smoother_restarts: u64,
    /// Times phase 2's own odometry check widened the model, the first widening included
    /// when it was phase 2's ([`Navigator::check_phase2_odometry`]).
    pub phase2_odometry_widenings: u64,
    /// Whether phase 2's check widened the model first (the batch had not): from the
    /// heading's ratio alone ([`selfcal::heading_strongly_worse`]).
    pub phase2_widened_first: bool,
    /// Loops closed: lamps held while the pose was lost ([`MATCH_MAX_POSE_SIGMA_M`])
    /// recognised as a constellation of landmarks, and the filter updated with them.
    pub loops_closed: u64,
    /// Frames whose held lamps fitted several places (nothing closed).
    pub loops_ambiguous: u64,
    /// Frames whose held lamps fitted one place that the lost pose's covariance rules out
    /// ([`LOOP_MAX_CORRECTION_D2`]; nothing closed).
    pub loops_refused: u64,
    /// Observations held out of the map while the pose was lost (a lamp mapped from a lost
    /// pose would tell the filter where it is; counted per frame).
    pub held_while_lost: u64,
    /// Lamps held while lost and mapped from their held positions once the loop was closed
    /// (or, no place recognised, once the navigator gave up holding).
    pub held_mapped: u64,
    /// Times the navigator, lost, recognised no place in [`LOOP_GIVE_UP_LAMPS`] held lamps
    /// and mapped on as on new ground.
    pub loops_given_up: u64,
    /// Board features the lens model could not map into the rectified image (dropped).
    pub features_unmapped: u64,
    /// Board features mapped, but outside the field of use and left out
    /// ([`vslam_ekf::Settings::max_off_axis_deg`]).
    pub features_outside_field: u64,
    /// Stereo pairs in the outer band beyond the field of use whose noise the lens stretches
    /// more than `vslam_ekf::Settings::outer_max_noise_gain`, left out.
    pub observations_outer_unused: u64,
    /// Bound observations the update's budget left out (`CandidateSettings::max_observations`).
    pub observations_skipped: u64,
    /// Brief landmarks removed (`CandidateSettings::brief_observations`).
    pub landmarks_pruned: u64,
    /// Landmarks merged into another: a lamp mapped twice ([`FrameOutcome::merged`]).
    pub landmarks_merged: u64,
    /// Distance the odometry travelled, counting only motion beyond 3 sigma of its noise
    /// in each frame interval, metres.
    pub significant_translation_m: f64,
    /// Rotation the odometry turned, the same way, radians.
    pub significant_rotation_rad: f64,
    /// Changes of speed between frame intervals, summed, counting a change only once it
    /// exceeds 0.05 m/s from the last counted speed (the clock offset's excitation), m/s.
    pub significant_speed_change_mps: f64,
    /// The odometry's noise model widened because the batch's residuals showed the odometry
    /// worse or its errors longer-lived than the rig file states
    /// ([`selfcal::OdometryWidening`]).
    pub odometry_widened: Option<selfcal::OdometryWidening>,
}

/// A parameter estimated this many of its prior sigmas or more from its nominal value is named
/// in a warning ([`Navigator::pulled_from_prior`]).
pub const PULLED_PRIOR_SIGMAS: f64 = 3.0;

/// The two phases of the method in one object (see the crate docs).
#[derive(Debug, Clone)]
pub struct Navigator {
    rig: Rig,
    settings: NavSettings,
    front_end: FrontEnd,
    smoother: Smoother,
    ekf: Option<Ekf>,
    candidates: Candidates,
    /// Odometry since (and including the last sample before) the previous frame.
    odometry: Vec<OdomSample>,
    last_odometry_t: Option<u64>,
    /// The speed at the last counted change ([`NavStats::significant_speed_change_mps`]).
    counted_speed: Option<f64>,
    last_frame_t: Option<u64>,
    /// Dead reckoning (phase 1).
    pose: Pose2,
    pose_covariance: Matrix3<f64>,
    phase_switch_t_us: Option<u64>,
    match_gate: f64,
    stats: NavStats,
    /// Map landmark -> its index in the smoother, while the smoother runs in phase 2.
    smoothed: BTreeMap<LandmarkId, usize>,
    /// Lamps held out of the map while the pose is lost ([`MATCH_MAX_POSE_SIGMA_M`]).
    held: loops::Held,
    /// Lost, the held lamps recognised no place: lamps are mapped again until the pose is
    /// found.
    gave_up_holding: bool,
    /// Landmarks the filter accepted lately, with the frame ([`NavSettings::relative_lost`]).
    anchors: BTreeMap<LandmarkId, u64>,
    /// Landmarks within [`MERGE_SEARCH_M`] of each other that were observed in the same frame:
    /// two lamps, never merged. `(smaller id, larger id)`.
    co_observed: BTreeSet<(LandmarkId, LandmarkId)>,
    /// The 3-dof chi-square bound under which two landmarks never observed together are one
    /// (the map-match probability's).
    merge_gate: f64,
    /// Phase 1 by frame pairs, in [`NavMode::CalibrateFramePairs`].
    frame_pairs: Option<FramePairCalibration>,
    /// Phase 2's trajectory for its odometry check ([`Navigator::check_phase2_odometry`]):
    /// phase 1's batch's poses, then the filter's pose at each frame, with the odometry's
    /// motion from the frame before and its covariance under the model in use; the last
    /// [`PHASE2_TRACK_FRAMES`].
    phase2_track: Vec<(Pose2, Option<OdometryStep>)>,
    /// The smoother's widening last taken ([`Navigator::sync_odometry`]) or given to it by
    /// phase 2's own check ([`Navigator::check_phase2_odometry`]).
    smoother_widening: Option<selfcal::OdometryWidening>,
}

impl Navigator {
    /// A navigator for this rig, at the world origin (the robot at the first frame).
    pub fn new(rig: Rig, settings: NavSettings) -> Result<Self, Error> {
        let p = settings.map_match_probability;
        if !(p.is_finite() && p > 0.0 && p < 1.0) {
            return Err(Error::Settings {
                name: "map_match_probability",
                value: p,
                expected: "strictly between 0 and 1",
            });
        }
        settings.phase1.validate()?;
        let front_end = FrontEnd::new(Model::from_rig(&rig), settings.front_end)?;
        let candidates = Candidates::new(settings.candidates)?;
        let frame_pairs = match settings.mode {
            NavMode::Navigate => None,
            NavMode::CalibrateFramePairs => {
                if settings.skip_phase1 {
                    return Err(Error::Settings {
                        name: "skip_phase1",
                        value: 1.0,
                        expected: "off in the calibration-only mode (it has only phase 1)",
                    });
                }
                Some(FramePairCalibration::new(&rig, &settings.frame_pairs)?)
            }
        };
        let ekf = if settings.skip_phase1 {
            Some(Ekf::from_prior(&rig, settings.ekf)?)
        } else {
            // Checks the filter's settings and the rig now, not at the switch (there is none
            // in the calibration-only mode).
            if frame_pairs.is_none() {
                Ekf::from_prior(&rig, settings.ekf)?;
            }
            None
        };
        let smoother = Smoother::new(rig.clone(), settings.phase1);
        let navigator = Self {
            rig,
            settings,
            front_end,
            smoother,
            ekf,
            candidates,
            odometry: Vec::new(),
            last_odometry_t: None,
            counted_speed: None,
            last_frame_t: None,
            pose: Pose2::default(),
            pose_covariance: Matrix3::zeros(),
            phase_switch_t_us: None,
            match_gate: chi2_quantile(p, 4.0),
            stats: NavStats::default(),
            smoothed: BTreeMap::new(),
            held: loops::Held::new(),
            gave_up_holding: false,
            anchors: BTreeMap::new(),
            co_observed: BTreeSet::new(),
            merge_gate: chi2_quantile(p, 3.0),
            frame_pairs,
            phase2_track: Vec::new(),
            smoother_widening: None,
        };
        Ok(navigator)
    }

    /// The rig.
    pub fn rig(&self) -> &Rig {
        &self.rig
    }

    /// The estimated parameters whose estimate is [`PULLED_PRIOR_SIGMAS`] or more of their
    /// prior sigmas from the rig file's nominal value, as `(parameter, estimate, nominal,
    /// prior sigma, posterior sigma)`: either the rig file's nominal value or prior is wrong,
    /// or a model error (odometry worse than stated, a standing vehicle taken for
    /// information) pulled it there (issue 36).
    pub fn pulled_from_prior(&self) -> Vec<(Param, f64, f64, f64, f64)> {
        let (camera, cov) = self.camera();
        self.rig
            .estimate
            .iter()
            .filter_map(|&p| {
                let prior = self.rig.prior.get(p.index()).copied().flatten()?;
                let (value, nominal) = (camera.get(p), self.rig.nominal.get(p));
                let variance = cov.get((p.index(), p.index())).copied().unwrap_or(0.0);
                let sigma = libm::sqrt(variance.max(0.0));
                (prior > 0.0 && libm::fabs(value - nominal) >= PULLED_PRIOR_SIGMAS * prior)
                    .then_some((p, value, nominal, prior, sigma))
            })
            .collect()
    }

    /// The odometry's noise model in use: the rig file's, or wider when the batch's residuals
    /// showed the odometry worse than stated ([`NavStats::odometry_widened`]).
    pub fn odometry_noise(&self) -> rig_model::Noise {
        let (kt, kh) = self
            .stats
            .odometry_widened
            .map_or((1.0, 1.0), |w| w.factors);
        rig_model::Noise {
            velocity: self.rig.noise.velocity * libm::sqrt(kt),
            yaw_rate: self.rig.noise.yaw_rate * libm::sqrt(kh),
            ..self.rig.noise
        }
    }

    /// The settings.
    pub fn settings(&self) -> &NavSettings {
        &self.settings
    }

    /// The current phase.
    pub fn phase(&self) -> Phase {
        if self.ekf.is_some() {
            Phase::Navigating
        } else {
            Phase::Calibrating
        }
    }

    /// When phase 2 started (the frame at which phase 1 became stable); `None` before, or
    /// when phase 1 was skipped.
    pub fn phase_switch_t_us(&self) -> Option<u64> {
        self.phase_switch_t_us
    }

    /// The filter (phase 2).
    pub fn ekf(&self) -> Option<&Ekf> {
        self.ekf.as_ref()
    }

    /// The track-to-landmark bookkeeping (phase 2).
    pub fn candidates(&self) -> &Candidates {
        &self.candidates
    }

    /// The association.
    pub fn front_end(&self) -> &FrontEnd {
        &self.front_end
    }

    /// Phase 1's batch (its latest solve and the history of C).
    pub fn smoother(&self) -> &Smoother {
        &self.smoother
    }

    /// Phase 1 by frame pairs, in [`NavMode::CalibrateFramePairs`].
    pub fn frame_pairs(&self) -> Option<&FramePairCalibration> {
        self.frame_pairs.as_ref()
    }

    /// The lamps held out of the map while the pose is lost ([`loops::Held::positions`]).
    pub fn held_lamps(&self) -> Vec<(u64, nalgebra::Vector3<f64>, u32)> {
        self.held.positions()
    }

    /// The hand-over to phase 2 (camera parameters and covariance), once it happened: the
    /// camera part of [`Self::batch_handover`].
    pub fn handover(&self) -> Option<Handover> {
        self.smoother.handover().map(|b| Handover {
            camera: b.camera,
            covariance: b.camera_covariance,
            t_us: b.t_us,
            observability: b.observability.clone(),
        })
    }

    /// Phase 1's whole hand-over (the batch's joint estimate and smoothed trajectory).
    pub fn batch_handover(&self) -> Option<&BatchHandover> {
        self.smoother.handover()
    }

    /// The smoothed poses of every frame of phase 1, `(t_us, pose)`, once phase 2 started.
    pub fn phase1_trajectory(&self) -> &[(u64, Pose2)] {
        self.smoother
            .handover()
            .map_or(&[], |h| h.trajectory.as_slice())
    }

    /// The estimated parameters phase 1's data did not inform at the hand-over (they entered
    /// phase 2 with about their prior), and why the hand-over happened.
    pub fn uninformed(&self) -> Option<(HandoverReason, Vec<Param>)> {
        self.smoother.handover().map(|h| (h.reason, h.uninformed()))
    }

    /// Ends phase 1 if it is still running (the end of a log): the batch solves once more and
    /// phase 2 starts from it, so that the frames seen so far are mapped even when the
    /// calibration never became stable. Returns whether the switch happened now.
    ///
    /// In phase 2 with the smoother running, the smoother solves once more over the frames
    /// since its last solve and the filter takes its estimate (the final map is the batch's).
    pub fn finish(&mut self) -> Result<bool, Error> {
        if self.frame_pairs.is_some() {
            return Ok(false);
        }
        if self.ekf.is_some() || self.settings.skip_phase1 {
            if self.smoother.is_mapping() && self.smoother.flush() {
                self.reseed();
            }
            if let Some(ekf) = self.ekf.as_mut() {
                // The map is read whole from here on: its covariance written out once.
                ekf.settle();
            }
            self.merge_duplicates();
            return Ok(false);
        }
        let Some(t) = self.last_frame_t else {
            return Ok(false);
        };
        if self.smoother.finish().is_none() {
            return Ok(false);
        }
        // The last solve may have widened the odometry's model.
        self.sync_odometry();
        self.switch(t)?;
        Ok(true)
    }

    /// The current estimate of the vehicle's parameters V: the filter's in phase 2, the
    /// batch's in phase 1 (a prediction does not change it).
    fn vehicle(&self) -> rig_model::Vehicle {
        self.ekf
            .as_ref()
            .map_or_else(|| self.smoother.camera().vehicle, |e| e.camera().vehicle)
    }

    /// The odometry samples a batch needs to integrate the interval `[t0_us, t1_us]` (board
    /// stamps) again for another clock offset: those within [`ODOMETRY_MARGIN_US`] of the
    /// interval at the current estimate `vehicle`. None unless V is estimated.
    fn samples_around(
        &self,
        t0_us: u64,
        t1_us: u64,
        vehicle: &rig_model::Vehicle,
        estimates_vehicle: bool,
    ) -> Vec<OdomSample> {
        if !estimates_vehicle {
            return Vec::new();
        }
        let from = vehicle
            .odometry_time_us(t0_us)
            .saturating_sub(ODOMETRY_MARGIN_US / 2);
        let to = vehicle
            .odometry_time_us(t1_us)
            .saturating_add(ODOMETRY_MARGIN_US / 2);
        let first = self
            .odometry
            .partition_point(|s| s.t_us <= from)
            .saturating_sub(1);
        let last = self.odometry.partition_point(|s| s.t_us <= to);
        self.odometry
            .get(first..last)
            .map(<[OdomSample]>::to_vec)
            .unwrap_or_default()
    }

    /// Takes the batch's widening of the odometry's noise model (issue 36, item 2;
    /// [`selfcal::OdometryWidening`]) into the front end's gates; every later frame's
    /// odometry is integrated with it ([`Self::odometry_noise`]).
    fn sync_odometry(&mut self) {
        let widening = self.smoother.odometry_widening();
        if widening == self.smoother_widening {
            return;
        }
        self.smoother_widening = widening;
        self.stats.odometry_widened = widening;
        self.set_odometry_gates();
    }

    /// The front end's gates from the odometry's noise model in use.
    fn set_odometry_gates(&mut self) {
        let noise = self.odometry_noise();
        let mut model = self.front_end.model().clone();
        model.noise.velocity = noise.velocity;
        model.noise.yaw_rate = noise.yaw_rate;
        self.front_end.set_model(model);
    }

    /// Phase 2 goes on checking the odometry (issue 36, item 2): the filter's trajectory since
    /// the hand-over (phase 1's batch's before it) against the odometry over the batch's spans
    /// ([`selfcal::trajectory_consistency`], judged as the batch judges its own,
    /// [`selfcal::judge_odometry`]), every [`PHASE2_ODOMETRY_CHECK_FRAMES`] frames. Phase 2's
    /// smoother does not judge it: its window (5 s) holds fewer than the first span's eight
    /// windows, and it looks too often for a first widening on a few.
    ///
    /// A model the batch has widened already is refined: a phase 1 that handed over early (its
    /// landmark budget full in a dense hall after 14 s) widened it from the one-second span
    /// alone, before the three-second span had the windows that show the errors' memory, and
    /// left the odometry stated 2 to 3 times too good in variance over longer spans. The
    /// filter's relative poses over three seconds are a centimetre or two good where lamps
    /// are in view, which adds to the residuals: the check can only widen too much, not too
    /// little.
    ///
    /// A model the batch has not widened (a phase 1 ended by a short frame budget, before the
    /// first span's windows; odometry that turns worse later) is widened first only on the
    /// heading's ratio ([`selfcal::heading_strongly_worse`]): the filter's relative translations
    /// over a second are too coarse for a first judgement (their ratio reaches 46 with odometry
    /// as good as stated), its relative headings are not (at most 2.8 on the white Monte
    /// Carlos, 43 to 110 with 0.6 s of memory stated as white). Once the heading has shown
    /// it, both axes are judged as the batch judges them (the translation then widened by its
    /// ratio against the filter, which may be several times too much: honest, not accurate).
    /// A widening reaches the smoother's stored factors ([`Smoother::widen_odometry`]).
    fn check_phase2_odometry(&mut self, t_us: u64, step: Option<OdometryStep>) {
        let Some(ekf) = self.ekf.as_ref() else {
            return;
        };
        let so_far = self.stats.odometry_widened;
        if so_far.is_some() && self.smoother.is_mapping() {
            // The batch's widening is refined from the filter's own trajectory once the
            // smoother has stopped (its solves pull the filter's poses towards the odometry
            // they weigh, which shrinks the residuals the refinement judges).
            self.phase2_track.clear();
            return;
        }
        self.phase2_track.push((ekf.pose(), step));
        if self.phase2_track.len() > PHASE2_TRACK_FRAMES {
            let excess = self.phase2_track.len() - PHASE2_TRACK_FRAMES;
            self.phase2_track.drain(..excess);
        }
        if !self
            .stats
            .frames
            .is_multiple_of(PHASE2_ODOMETRY_CHECK_FRAMES)
        {
            return;
        }
        let poses: Vec<Pose2> = self.phase2_track.iter().map(|(p, _)| *p).collect();
        let steps: Vec<Option<OdometryStep>> =
            self.phase2_track.iter().skip(1).map(|(_, s)| *s).collect();
        let spans = selfcal::CONSISTENCY_SPANS_S
            .map(|span| selfcal::trajectory_consistency(&poses, &steps, span));
        if so_far.is_none() && !selfcal::heading_strongly_worse(&spans) {
            return;
        }
        let Some(((kt, kh), w)) = selfcal::judge_odometry(spans, so_far, t_us, true) else {
            return;
        };
        self.stats.odometry_widened = Some(w);
        // The smoother takes it too, running or not: started again later, it must judge on
        // from this model, not from the one it last saw.
        self.smoother.widen_odometry(kt, kh, w);
        self.smoother_widening = Some(w);
        if kt <= 1.0 && kh <= 1.0 {
            return;
        }
        self.stats.phase2_widened_first |= so_far.is_none();
        // The stored steps under the model now in use, as the batch rescales its factors.
        for (_, s) in &mut self.phase2_track {
            if let Some((_, cov)) = s {
                *cov = selfcal::widened_odometry_covariance(cov, kt, kh);
            }
        }
        self.stats.phase2_odometry_widenings += 1;
        self.set_odometry_gates();
    }

    /// Adds a frame interval's odometry motion to the excitation when it is significant (beyond
    /// 3 sigma of its noise: a standing vehicle's noise is not motion).
    fn excite(&mut self, m: &Motion, cov: &Matrix3<f64>) {
        let d = nalgebra::Vector2::new(m.dx, m.dy);
        let c2 = cov.fixed_view::<2, 2>(0, 0).into_owned();
        if let Some(inv) = c2.try_inverse()
            && d.dot(&(inv * d)) > 9.0
        {
            self.stats.significant_translation_m += d.norm();
        }
        let s = cov[(2, 2)];
        if s > 0.0 && m.dtheta * m.dtheta > 9.0 * s {
            self.stats.significant_rotation_rad += m.dtheta.abs();
        }
        if m.dt_s > 0.0 {
            let speed = d.norm() / m.dt_s;
            match self.counted_speed {
                Some(last) if (speed - last).abs() >= 0.05 => {
                    self.stats.significant_speed_change_mps += (speed - last).abs();
                    self.counted_speed = Some(speed);
                }
                Some(_) => {}
                None => self.counted_speed = Some(speed),
            }
        }
    }

    /// The estimated camera parameters the motion so far cannot inform
    /// ([`NavSettings::hold_unexcited`]).
    pub fn unexcited(&self) -> Vec<Param> {
        if !self.settings.hold_unexcited {
            return Vec::new();
        }
        self.not_excited()
    }

    /// The health check the hold makes true by construction: estimated camera parameters
    /// the motion so far cannot inform whose phase-2 sigma is nevertheless below 80 % of
    /// their prior's, as `(param, sigma, prior sigma)`. Not empty means information came from
    /// a model error (with [`NavSettings::hold_unexcited`] off, the camera moving while the
    /// odometry says the vehicle stands shrinks the baseline: docs/real-images.md).
    pub fn spurious_information(&self) -> Vec<(Param, f64, f64)> {
        let Some(ekf) = &self.ekf else {
            return Vec::new();
        };
        let cov = ekf.camera_covariance();
        self.not_excited()
            .into_iter()
            .filter_map(|p| {
                let prior = self.rig.prior.get(p.index()).copied().flatten()?;
                let sigma = <f64 as nalgebra::ComplexField>::sqrt(
                    cov.get((p.index(), p.index()))?.max(0.0),
                );
                (sigma < 0.8 * prior).then_some((p, sigma, prior))
            })
            .collect()
    }

    /// The estimated camera parameters the motion so far cannot inform (whatever the hold).
    /// The vehicle's parameters are never held: a parameter of V the motion does not excite
    /// has no effect on the prediction (the yaw scale without turns, the odometry scale
    /// standing), so it cannot take information from a model error the way C can, and
    /// holding it would stop the smoother until the first turn.
    fn not_excited(&self) -> Vec<Param> {
        let tilted = self.rig.nominal.mount.is_tilted();
        let rotation = self.stats.significant_rotation_rad;
        let moved = self.stats.significant_translation_m >= self.settings.min_translation_m;
        self.rig
            .estimate
            .iter()
            .copied()
            .filter(|p| !p.is_vehicle())
            .filter(|&p| {
                !moved
                    || selfcal::solver::structural_trap(
                        p,
                        tilted,
                        rotation,
                        self.stats.significant_speed_change_mps,
                    )
                    .is_some()
            })
            .collect()
    }

    /// Whether phase 2 runs with the fixed-lag smoother ([`NavSettings::smooth_phase2`]; not
    /// with the camera considered, whose values must stay phase 1's).
    fn smooths_phase2(&self) -> bool {
        self.settings.smooth_phase2
            && self.settings.ekf.camera_update != vslam_ekf::CameraUpdate::Consider
    }

    /// Final poses of frames the smoother has marginalised (or of every kept frame when it
    /// stopped) since the last call, oldest first: the fixed-lag smoothed trajectory.
    pub fn take_smoothed(&mut self) -> Vec<(u64, Pose2)> {
        self.smoother.take_smoothed()
    }

    /// The timestamp of the oldest frame phase 2's smoother still holds, while it runs: the
    /// poses of that frame and later ones may still change ([`Self::take_smoothed`]).
    pub fn smoothing_since_t_us(&self) -> Option<u64> {
        if self.smoother.is_mapping() {
            self.smoother.window_start_t_us()
        } else {
            None
        }
    }

    /// The poses of the frames the smoother still holds (final only at the end of a log).
    pub fn smoother_window(&self) -> Vec<(u64, Pose2)> {
        if self.smoother.is_mapping() {
            self.smoother.window_poses()
        } else {
            Vec::new()
        }
    }

    /// The filter takes the smoother's last joint estimate.
    fn reseed(&mut self) {
        self.stats.phase2_solves += 1;
        let (Some(ekf), Some(joint)) = (self.ekf.as_mut(), self.smoother.joint()) else {
            return;
        };
        // A solve far outside the filter's own uncertainty is a linearisation gone wrong, not
        // information: after a loop closed through a long dark stretch the window's
        // marginalised prior (linearised where dead reckoning had put it) pulled a solve to an
        // odometry scale of 0.70 and a clock offset of 118 ms (docs/halls.md, "Loops"). The
        // filter keeps its own estimate and the smoother starts again from it.
        let consistent = reseed_distance(ekf, &joint)
            .is_some_and(|d2| d2 <= chi2_quantile(RESEED_PROBABILITY, reseed_dof(&joint)));
        if !consistent {
            self.stats.phase2_reseeds_refused += 1;
            self.stats.phase2_reseeds_inconsistent += 1;
            self.smoother.stop_mapping();
            return;
        }
        let index = &self.smoothed;
        // The smoother carrying every landmark, its joint is the filter's new state;
        // otherwise the rest of the map follows its marginal.
        let result = if index.len() >= ekf.landmark_count() {
            ekf.set_joint(&joint, |id| index.get(&id).copied())
        } else {
            ekf.replace_marginal(&joint, |id| index.get(&id).copied())
                .map(|_| ())
        };
        if result.is_err() {
            self.stats.phase2_reseeds_refused += 1;
        } else {
            self.pose = joint.pose;
        }
    }

    /// Counters.
    pub fn stats(&self) -> NavStats {
        self.stats
    }

    /// Timestamp of the last frame processed.
    pub fn last_frame_t_us(&self) -> Option<u64> {
        self.last_frame_t
    }

    /// The robot's pose and its covariance: the filter's in phase 2, dead reckoning before.
    pub fn pose(&self) -> (Pose2, Matrix3<f64>) {
        match &self.ekf {
            Some(ekf) => (ekf.pose(), ekf.pose_covariance()),
            None => (self.pose, self.pose_covariance),
        }
    }

    /// The camera parameters (every one of C) and their covariance: the filter's in phase 2,
    /// phase 1's latest solve before (the rig's nominal values and prior variances before the
    /// first solve).
    pub fn camera(&self) -> (CameraParams, CameraCovariance) {
        if let Some(ekf) = &self.ekf {
            return (ekf.camera(), ekf.camera_covariance());
        }
        (self.smoother.camera(), self.smoother.camera_covariance())
    }

    /// Adds an odometry sample (robot-frame velocities held from `t_us` until the next one).
    /// Samples must come in time order; one older than the previous is refused.
    pub fn push_odometry(&mut self, sample: OdomSample) -> Result<(), Error> {
        for (what, value) in [
            ("odometry vx", sample.vx),
            ("odometry vy", sample.vy),
            ("odometry vtheta", sample.vtheta),
        ] {
            if !value.is_finite() {
                return Err(Error::NonFinite {
                    what,
                    t_us: sample.t_us,
                    value,
                });
            }
        }
        if let Some(last) = self.last_odometry_t
            && sample.t_us < last
        {
            return Err(Error::OdometryOutOfOrder {
                t_us: sample.t_us,
                last_us: last,
            });
        }
        self.last_odometry_t = Some(sample.t_us);
        self.front_end.push_odometry(sample);
        if let Some(pairs) = &mut self.frame_pairs {
            pairs.push_odometry(sample);
        }
        if self.odometry.len() >= MAX_ODOMETRY_BUFFER {
            // No frame for a long time: the oldest samples go (a frame after the gap finds no
            // odometry back to the frame before and holds the pose, counted).
            self.odometry.drain(..MAX_ODOMETRY_BUFFER / 2);
            self.stats.odometry_dropped += (MAX_ODOMETRY_BUFFER / 2) as u64;
        }
        self.odometry.push(sample);
        self.stats.odometry += 1;
        Ok(())
    }

    /// Processes one stereo frame: the board's left and right features (pixels, see
    /// [`Pixel::from_q4`]) at `t_us`, after the odometry up to `t_us`. Frames must come in time
    /// order.
    pub fn push_frame(
        &mut self,
        t_us: u64,
        left: &[Pixel],
        right: &[Pixel],
    ) -> Result<FrameOutcome, Error> {
        if let Some(last) = self.last_frame_t
            && t_us < last
        {
            return Err(Error::FrameOutOfOrder {
                t_us,
                last_us: last,
            });
        }
        for p in left.iter().chain(right) {
            if !(p.u.is_finite() && p.v.is_finite()) {
                return Err(Error::NonFinite {
                    what: "feature pixel coordinate",
                    t_us,
                    value: if p.u.is_finite() { p.v } else { p.u },
                });
            }
        }
        let mut outcome = FrameOutcome::default();
        // The motion since the previous frame, for the batch (phase 1, and phase 2's smoother),
        // integrated for the current estimate of the vehicle's parameters V (1.2): over the
        // odometry-clock interval the frames were exposed in, with the true velocities.
        let mut phase1_motion = None;
        let estimates_vehicle = self.rig.estimate.iter().any(|p| p.is_vehicle());
        let vehicle = self.vehicle();
        if let Some(t0) = self.last_frame_t {
            let noise = self.odometry_noise();
            let moved = match Increment::from_odometry_vehicle(
                &self.odometry,
                t0,
                t_us,
                &noise,
                &vehicle,
                estimates_vehicle,
            ) {
                Ok((inc, reported, jv)) => {
                    match &mut self.ekf {
                        // The filter's odometry errors as states (`vslam_ekf::errors`): its
                        // own motion and noise; the batch's factor below stays the white
                        // equivalent's.
                        Some(ekf) if !ekf.error_axes().is_empty() => ekf.predict_odometry_vehicle(
                            &self.odometry,
                            (t0, t_us),
                            &noise,
                            &vehicle,
                            &jv,
                        )?,
                        Some(ekf) => {
                            // The yaw scale's column from the yaw rate reported before the
                            // interval (errors in the variables; the batch keeps `jv`). Only
                            // for yaw-rate errors white as far as the navigator knows: with
                            // memory (stated, or seen by the widening) that stretch shares
                            // the interval's errors (0.66 across 250 ms at 0.6 s) and is only
                            // a staler regressor.
                            let white = noise.yaw_rate_tau == 0.0
                                && self
                                    .stats
                                    .odometry_widened
                                    .is_none_or(|w| w.factors.1 <= 1.0);
                            let mut jf = jv;
                            if white
                                && let Some(c) = rig_model::odometry::filter_yaw_scale_column(
                                    &self.odometry,
                                    t0,
                                    t_us,
                                    &vehicle,
                                )
                            {
                                jf.set_column(1, &c);
                            }
                            ekf.predict_increment_vehicle(&inc, &jf)?
                        }
                        None => {
                            let (pose, f, q) = inc.apply(&self.pose);
                            self.pose = pose;
                            let p = f * self.pose_covariance * f.transpose() + q;
                            self.pose_covariance = 0.5 * (p + p.transpose());
                        }
                    }
                    phase1_motion = Some(OdometryFactor {
                        motion: inc.motion,
                        covariance: reported,
                        vehicle,
                        vehicle_jacobian: jv,
                        frames_us: (t0, t_us),
                        samples: self.samples_around(t0, t_us, &vehicle, estimates_vehicle),
                    });
                    true
                }
                Err(vslam_ekf::Error::NoOdometry { .. }) => false,
                Err(e) => return Err(e.into()),
            };
            if !moved {
                outcome.no_odometry = true;
                self.stats.frames_without_odometry += 1;
            }
        }
        if let Some(o) = &phase1_motion {
            self.excite(&o.motion, &o.covariance);
            self.held.add_motion(&o.covariance);
        }
        self.last_frame_t = Some(t_us);
        // Keep the last sample at or before this frame's odometry-clock time (less a margin
        // for the clock offset's estimate to move): it is held into the next interval. And the
        // stretch before it that the filter's yaw-scale column is taken from.
        let keep_until = vehicle.odometry_time_us(t_us).min(t_us).saturating_sub(
            ODOMETRY_MARGIN_US
                + rig_model::odometry::INSTRUMENT_GAP_US
                + rig_model::odometry::INSTRUMENT_WINDOW_US,
        );
        let keep_from = self
            .odometry
            .partition_point(|s| s.t_us <= keep_until)
            .saturating_sub(1);
        self.odometry.drain(..keep_from);
        self.stats.frames += 1;

        // Real lenses (vehicle-interfaces.md 1.1): the board's raw features into the rectified
        // model; a feature that cannot be mapped is dropped and counted.
        let rectified = track::rectify_features(
            &self.rig,
            left,
            right,
            self.settings
                .ekf
                .outer_off_axis_deg
                .max(self.settings.ekf.max_off_axis_deg)
                .to_radians(),
        );
        let (left, right) = match &rectified {
            Some(r) => {
                self.stats.features_unmapped += r.dropped;
                self.stats.features_outside_field += r.outside_field;
                (r.left.pixels.as_slice(), r.right.pixels.as_slice())
            }
            None => (left, right),
        };
        let mut tracked = self.front_end.push_frame(t_us, left, right);
        // With a lens: where pairs are used (`rig_model::lens::StereoField`).
        let field = self.rig.lens.is_some().then(|| {
            self.settings
                .ekf
                .stereo_field(&self.rig.nominal, self.rig.noise.pixel)
        });
        if let Some(field) = &field {
            // The outer band's pairs whose noise the lens stretches too much are not used.
            let pixel_noise = self.front_end.model().pixel_noise;
            let before = tracked.observations.len();
            tracked.observations.retain(|o| {
                field.reaches(&o.measurement, &pixel_noise.gains(&o.measurement).into())
            });
            self.stats.observations_outer_unused += (before - tracked.observations.len()) as u64;
        }
        // Phase 1's batch and the frame pairs take the field of use only: the outer band's
        // pairs would update everything there (`vslam_ekf::Settings::outer_off_axis_deg`).
        let inner = (self.frame_pairs.is_some() || self.ekf.is_none()).then(|| {
            let mut t = tracked.clone();
            if let Some(field) = &field {
                t.observations
                    .retain(|o| field.inner_contains(&o.measurement));
            }
            t
        });
        if let (Some(pairs), Some(inner)) = (&mut self.frame_pairs, &inner) {
            pairs.push_frame(inner);
            return Ok(outcome);
        }
        if self.ekf.is_none()
            && let Some(inner) = &inner
        {
            // The frame's motion goes to phase 1's batch; phase 2 takes it only from the next
            // frame on (the frame of the switch is the batch's last).
            self.phase1(inner, phase1_motion.take(), &mut outcome)?;
        }
        // The frame of the switch is the batch's last: its pixels are in the hand-over already.
        if self.ekf.is_some() && !outcome.switched {
            let held = self.unexcited();
            if let Some(ekf) = self.ekf.as_mut() {
                ekf.set_held(&held);
            }
            self.phase2(&tracked, &mut outcome)?;
            let step = phase1_motion.as_ref().map(|o| (o.motion, o.covariance));
            self.smooth(&tracked, phase1_motion, &outcome);
            self.check_phase2_odometry(tracked.t_us, step);
        }
        // The associations name the features the front end was given: with a lens, the
        // rectified ones, whose indices skip the features the lens dropped.
        if let Some(r) = &rectified {
            outcome.associations.retain_mut(|a| {
                match (r.left.raw_index.get(a.left), r.right.raw_index.get(a.right)) {
                    (Some(&l), Some(&rr)) => {
                        (a.left, a.right) = (l, rr);
                        true
                    }
                    _ => false,
                }
            });
        }
        Ok(outcome)
    }

    /// Phase 1: the frame into the batch; the switch when it is stable (or its buffer full).
    fn phase1(
        &mut self,
        tracked: &TrackedFrame,
        motion: Option<OdometryFactor>,
        outcome: &mut FrameOutcome,
    ) -> Result<(), Error> {
        let observations: Vec<(u64, rig_model::Measurement)> = tracked
            .observations
            .iter()
            .filter(|o| o.confirmed)
            .map(|o| (o.track.0, o.measurement))
            .collect();
        let tentative: Vec<(u64, rig_model::Measurement)> = tracked
            .observations
            .iter()
            .filter(|o| !o.confirmed)
            .map(|o| (o.track.0, o.measurement))
            .collect();
        outcome.solved = self
            .smoother
            .add_frame(tracked.t_us, motion, &observations, &tentative);
        if outcome.solved {
            self.stats.phase1_solves += 1;
            if let Some(p) = self.smoother.last_pose() {
                self.pose = p;
            }
            self.sync_odometry();
        }
        if self.smoother.handover().is_none() {
            return Ok(());
        }
        self.switch(tracked.t_us)?;
        outcome.switched = true;
        Ok(())
    }

    /// Phase 2 from the batch's hand-over.
    fn switch(&mut self, t_us: u64) -> Result<(), Error> {
        let Some(batch) = self.smoother.handover() else {
            return Ok(());
        };
        let (ekf, ids) = Ekf::from_batch(&self.rig, batch, self.settings.ekf)?;
        for (l, id) in batch.landmarks.iter().zip(&ids) {
            self.candidates.bind(&ekf, l.track, *id)?;
        }
        let model = self
            .front_end
            .model()
            .with_camera(batch.camera, batch.camera_covariance);
        self.front_end.set_model(model);
        self.pose = batch.pose;
        self.smoothed = ids.iter().enumerate().map(|(j, id)| (*id, j)).collect();
        self.ekf = Some(ekf);
        self.phase_switch_t_us = Some(t_us);
        // A model the batch has not widened is checked from the batch's trajectory on: a
        // phase 1 ended by a short frame budget saw fewer than the first span's windows.
        self.phase2_track.clear();
        if self.stats.odometry_widened.is_none() {
            let (poses, steps) = self.smoother.odometry_track();
            self.phase2_track
                .extend(poses.into_iter().zip(core::iter::once(None).chain(steps)));
        }
        if self.smooths_phase2() {
            self.smoother.start_mapping();
        } else {
            self.smoother.stop_mapping();
            self.smoother.take_smoothed();
        }
        Ok(())
    }

    /// Phase 2's smoother takes the frame with the filter's associations (the observations
    /// the filter accepted, the landmarks it created), and the filter is re-seeded when it
    /// solved. The frame of the switch is the batch's last already.
    fn smooth(
        &mut self,
        tracked: &TrackedFrame,
        motion: Option<OdometryFactor>,
        outcome: &FrameOutcome,
    ) {
        if outcome.switched || !self.smooths_phase2() {
            return;
        }
        let Some(ekf) = self.ekf.as_ref() else {
            return;
        };
        // While the pose is lost the filter dead-reckons the lamps it holds (`loops::Held`):
        // a smoother's solve would move the pose under them. It starts again from the filter
        // once the loop is closed.
        if lost_for_matching(ekf, &self.anchors, self.settings.relative_lost) {
            if self.smoother.is_mapping() {
                self.smoother.stop_mapping();
            }
            return;
        }
        let held = !ekf.held().is_empty();
        if self.smoother.is_mapping() && held {
            // A parameter held: the smoother would refine it; the filter goes on alone until
            // nothing is held, then the smoother starts again from the filter.
            self.smoother.stop_mapping();
            return;
        }
        let near = self.settings.smooth_near_vehicle;
        let budget = self.settings.phase1.max_landmarks;
        if !self.smoother.is_mapping() {
            let over_budget = ekf.landmark_count() > budget;
            let stopped = self.stats.phase2_smoother_stopped_at > 0;
            if !held && (near || !(over_budget || stopped)) {
                self.restart_smoother(tracked.t_us, motion.as_ref(), outcome);
            }
            return;
        }
        for id in &outcome.removed {
            self.smoothed.remove(id);
        }
        // The smoother carries the landmarks near the vehicle; a landmark observed outside
        // them, one more than its budget, or a merge (a constraint it does not hold) starts
        // it again from the filter, over the landmarks near the vehicle then
        // (docs/halls.md, "The smoother over part of the map").
        let outside = outcome
            .accepted
            .iter()
            .any(|(id, _)| !self.smoothed.contains_key(id));
        let full = self.smoother.landmarks().len() + outcome.added.len() > budget;
        if near && (outside || full || !outcome.merged.is_empty()) {
            self.stats.phase2_smoother_restarts += 1;
            self.restart_smoother(tracked.t_us, motion.as_ref(), outcome);
            return;
        }
        let measurement_of = |id: LandmarkId| {
            let track = self.candidates.track_of(id)?;
            tracked
                .observations
                .iter()
                .find(|o| o.track.0 == track)
                .map(|o| (track, o.measurement))
        };
        let mut observations: Vec<(usize, rig_model::Measurement)> = Vec::new();
        let mut added: Vec<(LandmarkId, u64, rig_model::Measurement)> = Vec::new();
        // Pairs in the outer band update only their own landmark in the filter
        // (`Ekf::in_outer_band`): the smoother, which would let them move everything, leaves
        // them out.
        for id in &outcome.added {
            if let Some((track, z)) = measurement_of(*id)
                && !ekf.in_outer_band(&z)
            {
                added.push((*id, track, z));
            }
        }
        for (id, _) in &outcome.accepted {
            if let (Some(&j), Some((_, z))) = (self.smoothed.get(id), measurement_of(*id))
                && !ekf.in_outer_band(&z)
            {
                observations.push((j, z));
            }
        }
        let pose = ekf.pose();
        for (id, track, z) in added {
            let Some(l) = ekf.landmark(id) else {
                continue;
            };
            let j = self.smoother.add_landmark(l.position, track);
            self.smoothed.insert(id, j);
            observations.push((j, z));
        }
        // Landmarks the filter holds that the smoother does not (created while it was not
        // told), or more than its budget: it stops, and the filter maps on alone.
        if !near
            && (ekf.landmark_count() > self.smoothed.len()
                || self.smoother.landmarks().len() > budget)
        {
            self.smoother.stop_mapping();
            self.stats.phase2_smoother_stopped_at = self.stats.frames;
            return;
        }
        if self
            .smoother
            .add_mapped_frame(tracked.t_us, motion, pose, &observations)
        {
            self.sync_odometry();
            self.reseed();
        }
    }

    /// Starts phase 2's smoother again from the filter's marginal over the pose, the camera
    /// and the landmarks near the vehicle: the ones observed in this frame, then the nearest
    /// to a point [`SMOOTHER_LOOK_AHEAD_M`] ahead along the direction of travel (the lamps
    /// about to come into view), up to two thirds of the budget (the rest is for lamps mapped
    /// from here on).
    fn restart_smoother(
        &mut self,
        t_us: u64,
        motion: Option<&OdometryFactor>,
        outcome: &FrameOutcome,
    ) {
        let Some(ekf) = self.ekf.as_ref() else {
            return;
        };
        if !self.settings.smooth_near_vehicle {
            let (joint, ids) = ekf.joint(t_us);
            if self.smoother.restart_mapping(&joint) {
                self.smoothed = ids.iter().enumerate().map(|(j, id)| (*id, j)).collect();
            }
            return;
        }
        let budget = self.settings.phase1.max_landmarks;
        let mut chosen: Vec<LandmarkId> = Vec::with_capacity(budget);
        for id in outcome
            .observed()
            .into_iter()
            .chain(outcome.added.iter().copied())
        {
            if ekf.contains(id) && !chosen.contains(&id) && chosen.len() < budget {
                chosen.push(id);
            }
        }
        let pose = ekf.pose();
        let ahead = match motion {
            Some(m) if m.motion.dx < 0.0 => -SMOOTHER_LOOK_AHEAD_M,
            _ => SMOOTHER_LOOK_AHEAD_M,
        };
        let (cx, cy) = (
            pose.x + ahead * libm::cos(pose.theta),
            pose.y + ahead * libm::sin(pose.theta),
        );
        // Positions only: `Ekf::landmarks` would form every covariance block.
        let mut rest: Vec<(f64, LandmarkId)> = ekf
            .landmark_positions()
            .filter(|(id, _)| !chosen.contains(id))
            .map(|(id, p)| (libm::hypot(p.x - cx, p.y - cy), id))
            .collect();
        rest.sort_by(|a, b| a.0.total_cmp(&b.0));
        let fill = (2 * budget / 3).max(chosen.len());
        chosen.extend(rest.iter().take(fill - chosen.len()).map(|(_, id)| *id));
        let Ok(joint) = ekf.joint_of(t_us, &chosen) else {
            return;
        };
        if self.smoother.restart_mapping(&joint) {
            self.smoothed = chosen.iter().enumerate().map(|(j, id)| (*id, j)).collect();
        }
    }

    /// Phase 2: map matching of unbound tracks, then the filter's update and confirmation.
    fn phase2(&mut self, tracked: &TrackedFrame, outcome: &mut FrameOutcome) -> Result<(), Error> {
        let Some(ekf) = self.ekf.as_mut() else {
            return Ok(());
        };
        // Landmarks observed under a track of this frame.
        let observed: Vec<LandmarkId> = tracked
            .observations
            .iter()
            .filter_map(|o| self.candidates.landmark_of(o.track.0))
            .collect();
        // Map matching: unbound tracks against the landmarks predicted in view and not
        // observed under another track.
        let unbound: Vec<usize> = tracked
            .observations
            .iter()
            .enumerate()
            .filter(|(_, o)| {
                self.candidates.landmark_of(o.track.0).is_none()
                    && !self.candidates.is_retired(o.track.0)
            })
            .map(|(i, _)| i)
            .collect();
        // While the pose is lost its unbound tracks are held out of the map (a lamp mapped
        // anew from a lost pose would tell the filter where it is) until their constellation
        // is recognised among the landmarks (`loops`), or there are so many that the vehicle
        // must be on new ground.
        let lost = lost_for_matching(ekf, &self.anchors, self.settings.relative_lost);
        if !lost {
            self.held.clear();
            self.gave_up_holding = false;
        }
        let mut held: Vec<u64> = Vec::new();
        if !unbound.is_empty() && lost && !self.gave_up_holding {
            let closed = match recognise(ekf, tracked, &unbound, &mut self.held, self.stats.frames)
            {
                Recognised::Place { pairs, guess } => close_loop(
                    ekf,
                    &mut self.held,
                    &mut self.candidates,
                    &pairs,
                    guess,
                    &mut self.stats,
                    outcome,
                )?,
                Recognised::Ambiguous => {
                    self.stats.loops_ambiguous += 1;
                    false
                }
                Recognised::Inconsistent => {
                    self.stats.loops_refused += 1;
                    false
                }
                Recognised::Nothing => false,
            };
            if !closed
                && (self.held.mature() >= LOOP_GIVE_UP_LAMPS || self.held.len() >= LOOP_MAX_HELD)
            {
                // That many lamps seen well and no place recognised: new ground, mapped from
                // where they were held, and mapping goes on as before until the pose is found.
                map_held(ekf, &self.held, &mut self.candidates, &[], &mut self.stats)?;
                self.held.clear();
                self.gave_up_holding = true;
                self.stats.loops_given_up += 1;
            }
            if !closed && !self.gave_up_holding {
                held = unbound
                    .iter()
                    .filter_map(|&i| tracked.observations.get(i))
                    .map(|o| o.track.0)
                    .filter(|&t| self.candidates.landmark_of(t).is_none())
                    .collect();
                self.stats.held_while_lost += held.len() as u64;
            }
        } else if !unbound.is_empty() {
            // The landmarks in view, and those near it: a match is unique only if no other
            // landmark the feature might be, in view or just outside it, is in its gate.
            let reached = ekf.landmarks_reached();
            let mut in_view = reached.clone();
            // A landmark in the far band is a candidate only if its ray is within
            // `FAR_MATCH_CONE_RAD` of an unbound feature's: the far band of a tall hall holds
            // dozens of landmarks, most of them passive in the local session, whose
            // covariances cost a quarter of the frame to form (profile in docs/benchmarks.md,
            // "The far band").
            let camera = ekf.camera();
            let ray = |u: f64, v: f64| {
                nalgebra::Vector3::new((u - camera.cx) / camera.f, (v - camera.cy) / camera.f, 1.0)
                    .normalize()
            };
            let rays: Vec<nalgebra::Vector3<f64>> = unbound
                .iter()
                .filter_map(|&i| tracked.observations.get(i))
                .map(|o| ray(o.measurement.x, o.measurement.y))
                .collect();
            let cos_cone = libm::cos(FAR_MATCH_CONE_RAD);
            let mut far: Vec<LandmarkId> = Vec::new();
            in_view.retain(|(id, z)| {
                !ekf.in_far_band(z) || {
                    let r = ray(z.x, z.y);
                    let near = rays.iter().any(|t| t.dot(&r) >= cos_cone);
                    if near {
                        far.push(*id);
                    }
                    near
                }
            });
            // The far band's landmarks with the bound of their innovation covariance (exact
            // but for landmarks passive in the filter's local session, whose exact blocks
            // cost O(n^2) each).
            let predicted: Vec<(LandmarkId, Vector4<f64>, Matrix4<f64>)> = in_view
                .iter()
                .filter_map(|&(id, _)| {
                    let (z, s) = if far.contains(&id) {
                        ekf.predict_measurement_bound(id).ok()?
                    } else {
                        ekf.predict_measurement(id).ok()?
                    };
                    Some((id, z, s))
                })
                .chain(ekf.landmarks_near_view(NEAR_VIEW_SIGMAS, &reached))
                .filter(|(id, _, _)| !observed.contains(id))
                .filter_map(|(id, z, s)| Some((id, z, s.try_inverse()?)))
                .collect();
            let mut taken: Vec<LandmarkId> = Vec::new();
            for &i in &unbound {
                let Some(o) = tracked.observations.get(i) else {
                    continue;
                };
                let mut best: Option<(LandmarkId, f64)> = None;
                let mut inside = 0usize;
                for (id, z, s_inv) in &predicted {
                    let nu = o.measurement - z;
                    let d2 = nu.dot(&(s_inv * nu));
                    if !(d2.is_finite() && d2 <= self.match_gate) {
                        continue;
                    }
                    inside += 1;
                    if best.is_none_or(|(_, b)| d2 < b) {
                        best = Some((*id, d2));
                    }
                }
                if let Some((id, _)) = best
                    && inside == 1
                    && !taken.contains(&id)
                {
                    self.candidates.bind(ekf, o.track.0, id)?;
                    taken.push(id);
                    outcome.rematched.push((o.track.0, id));
                    self.stats.rematched += 1;
                }
            }
        }
        // Bound tracks are observations; unbound ones become candidates once the tracker has
        // confirmed them.
        let frame: Vec<(u64, rig_model::Measurement)> = tracked
            .observations
            .iter()
            .filter(|o| o.confirmed || self.candidates.landmark_of(o.track.0).is_some())
            .filter(|o| !held.contains(&o.track.0))
            .map(|o| (o.track.0, o.measurement))
            .collect();
        // Each bound landmark's stereo match, taken before the update (which may remove a
        // landmark and its binding): `(landmark, left, right)`, indices of the features given
        // to the front end.
        let matches = self.front_end.stereo_matches();
        let bound: Vec<(LandmarkId, usize, usize)> = tracked
            .observations
            .iter()
            .filter_map(|o| {
                let id = self.candidates.landmark_of(o.track.0)?;
                let m = matches.get(o.index)?;
                Some((id, m.left, m.right))
            })
            .collect();
        let report = match self.candidates.observe(ekf, &frame) {
            Ok(r) => r,
            Err(e) => {
                self.stats.refused_updates += 1;
                return Err(e.into());
            }
        };
        outcome.accepted = report
            .update
            .accepted
            .iter()
            .map(|g| (g.id, g.nis))
            .collect();
        outcome.rejected = report.update.rejected.iter().map(|g| g.id).collect();
        if self.settings.relative_lost {
            let frame = self.stats.frames;
            for (id, _) in &outcome.accepted {
                self.anchors.insert(*id, frame);
            }
            self.anchors
                .retain(|_, f| frame.saturating_sub(*f) <= ANCHOR_FRAMES);
        }
        let accepted = report.update.accepted.iter().map(|g| (g.id, true));
        let rejected = report.update.rejected.iter().map(|g| (g.id, false));
        outcome.associations = accepted
            .chain(rejected)
            .filter_map(|(id, accepted)| {
                let &(_, left, right) = bound.iter().find(|(l, _, _)| *l == id)?;
                Some(Association {
                    landmark: id,
                    left,
                    right,
                    accepted,
                })
            })
            .collect();
        self.stats.rejected += outcome.rejected.len() as u64;
        outcome.added = report.added.iter().map(|(_, id)| *id).collect();
        outcome.removed = report.removed.iter().map(|(_, id)| *id).collect();
        outcome.removed.extend(report.pruned.iter().copied());
        self.stats.observations_skipped += report.skipped as u64;
        self.stats.landmarks_pruned += report.pruned.len() as u64;
        // The map-level guard against a lamp mapped twice: the frame's co-observations noted,
        // then each new landmark (and, every `MERGE_PASS_FRAMES`, every landmark) against its
        // neighbours. While the smoother maps, it holds the landmarks as it saw them and its
        // re-seed would undo a merge: the guard waits for it to stop (or for `finish`).
        self.note_co_observed(&outcome.observed());
        if !self.smoother.is_mapping() {
            let merged = if self.stats.frames.is_multiple_of(MERGE_PASS_FRAMES) {
                self.merge_twins(None)
            } else if outcome.added.is_empty() {
                Vec::new()
            } else {
                let added = outcome.added.clone();
                self.merge_twins(Some(&added))
            };
            outcome
                .added
                .retain(|id| !merged.iter().any(|(_, d)| d == id));
            outcome.merged = merged;
        }
        Ok(())
    }

    /// Notes the pairs of landmarks within [`MERGE_SEARCH_M`] of each other among those
    /// observed in one frame: two lamps, never to be merged.
    fn note_co_observed(&mut self, ids: &[LandmarkId]) {
        let Some(ekf) = self.ekf.as_ref() else {
            return;
        };
        let near: Vec<(LandmarkId, nalgebra::Vector3<f64>)> = ids
            .iter()
            .filter_map(|&id| ekf.landmark_position(id).map(|p| (id, p)))
            .collect();
        for (i, (a, pa)) in near.iter().enumerate() {
            for (b, pb) in near.iter().skip(i + 1) {
                if (pa - pb).norm() <= MERGE_SEARCH_M {
                    self.co_observed.insert(ordered(*a, *b));
                }
            }
        }
    }

    /// Merges every pair of landmarks that are one lamp mapped twice: never observed in the
    /// same frame, within [`MERGE_SEARCH_M`] of each other and within their joint uncertainty
    /// (the 3-dof gate of the map-match probability). The older landmark is kept and takes
    /// the other's track when it has none; the filter merges the two consistently
    /// ([`Ekf::merge_landmarks`]). Run on every new landmark and every
    /// `MERGE_PASS_FRAMES` frames in phase 2, and by [`Navigator::finish`] before the map is
    /// final. Returns how many landmarks were merged into another.
    pub fn merge_duplicates(&mut self) -> usize {
        let merged = self.merge_twins(None);
        merged.len()
    }

    /// [`Navigator::merge_duplicates`] over `among` (every landmark: `None`) against all.
    fn merge_twins(&mut self, among: Option<&[LandmarkId]>) -> Vec<(LandmarkId, LandmarkId)> {
        let Some(ekf) = self.ekf.as_mut() else {
            return Vec::new();
        };
        let mut merged: Vec<(LandmarkId, LandmarkId)> = Vec::new();
        let all: Vec<(LandmarkId, nalgebra::Vector3<f64>)> = ekf.landmark_positions().collect();
        let probe: Vec<LandmarkId> = match among {
            Some(ids) => ids.to_vec(),
            None => all.iter().map(|(id, _)| *id).collect(),
        };
        for id in probe {
            let Some(position_id) = ekf.landmark_position(id) else {
                continue;
            };
            let mut best: Option<(LandmarkId, f64)> = None;
            let mut inside: Vec<LandmarkId> = Vec::new();
            for &(other, position) in &all {
                // The distance first: the pass compares every two landmarks.
                if other == id
                    || (position - position_id).norm() > MERGE_SEARCH_M
                    || !ekf.contains(other)
                    || self.co_observed.contains(&ordered(id, other))
                {
                    continue;
                }
                // A lower bound first (cheap while the filter works locally), then exactly.
                if ekf
                    .landmark_pair_distance_bound(id, other)
                    .is_ok_and(|d2| d2 > self.merge_gate)
                {
                    continue;
                }
                let Ok(d2) = ekf.landmark_pair_distance(id, other) else {
                    continue;
                };
                if d2 <= self.merge_gate {
                    inside.push(other);
                    if best.is_none_or(|(_, b)| d2 < b) {
                        best = Some((other, d2));
                    }
                }
            }
            // Two candidates in the gate: which lamp it is, is not known (a regular grid seen
            // with an uncertain pose); no merge. Unless the candidates are one lamp mapped
            // three times or more: every two of them never observed together, inside the gate
            // of each other and at one point (within [`MERGE_SAME_POINT_M`]; the first pass
            // merges the nearest, the next the others).
            let one_lamp = |ekf: &Ekf| {
                inside.iter().enumerate().all(|(i, &a)| {
                    inside.iter().skip(i + 1).all(|&b| {
                        let near = match (ekf.landmark_position(a), ekf.landmark_position(b)) {
                            (Some(pa), Some(pb)) => (pa - pb).norm() <= MERGE_SAME_POINT_M,
                            _ => false,
                        };
                        near && !self.co_observed.contains(&ordered(a, b))
                            && ekf
                                .landmark_pair_distance(a, b)
                                .is_ok_and(|d2| d2 <= self.merge_gate)
                    })
                })
            };
            let Some((other, _)) = best.filter(|_| inside.len() == 1 || one_lamp(ekf)) else {
                continue;
            };
            let (keep, drop) = ordered(id, other);
            let drop_track = self.candidates.track_of(drop);
            let keep_track = self.candidates.track_of(keep);
            if ekf.merge_landmarks(keep, drop).is_err() {
                continue;
            }
            if let Some(t) = drop_track {
                self.candidates.forget_track(t);
                if keep_track.is_none() {
                    // Cannot fail: `keep` is in the filter.
                    let _ = self.candidates.bind(ekf, t, keep);
                }
            }
            // What was noted of the dropped landmark is now the kept one's.
            let pairs: Vec<(LandmarkId, LandmarkId)> = self
                .co_observed
                .iter()
                .filter(|(a, b)| *a == drop || *b == drop)
                .copied()
                .collect();
            for (a, b) in pairs {
                self.co_observed.remove(&(a, b));
                let other = if a == drop { b } else { a };
                if other != keep {
                    self.co_observed.insert(ordered(keep, other));
                }
            }
            self.smoothed.remove(&drop);
            self.stats.landmarks_merged += 1;
            merged.push((keep, drop));
        }
        merged
    }
}

/// Two landmarks further apart than this are never compared by the merge guard, metres: lamps
/// are metres apart, and a lamp's second landmark lies where the drift of its day put it.
pub const MERGE_SEARCH_M: f64 = 1.0;

/// Landmarks closer than this to each other are at one point: several of them in one
/// landmark's merge gate are one lamp mapped three times or more, not a grid's neighbours
/// (two features of one thing closer than this never become two landmarks:
/// `SmootherSettings::min_separation_m`), metres.
pub const MERGE_SAME_POINT_M: f64 = 0.05;

/// How far outside the image, in standard deviations of its predicted pixel, a landmark still
/// counts for map matching's uniqueness ([`vslam_ekf::Ekf::landmarks_near_view`]).
const NEAR_VIEW_SIGMAS: f64 = 3.0;

/// A landmark predicted in the far band is tried for an unbound feature only within this
/// angle of the feature's ray, radians: 8 degrees, a landmark 10 m off with the pose 0.5 m
/// uncertain (the most map matching allows, `MATCH_MAX_POSE_SIGMA_M`) is 3 degrees off.
const FAR_MATCH_CONE_RAD: f64 = 0.14;

/// Frames between phase 2's looks at the odometry ([`Navigator::check_phase2_odometry`]; 5 s
/// at 20 Hz).
const PHASE2_ODOMETRY_CHECK_FRAMES: u64 = 100;

/// Frames of phase 2's trajectory the odometry check keeps (120 s at 20 Hz: the batch's last
/// look needs 32 windows of 3 s).
const PHASE2_TRACK_FRAMES: usize = 2400;

/// Frames between the merge guard's passes over the whole map (5 s at 20 Hz).
const MERGE_PASS_FRAMES: u64 = 100;

/// A pair of landmark ids, the smaller first.
/// A smoother's joint estimate is taken by the filter only while its pose and camera lie
/// inside this probability's chi-square gate of the filter's own estimate and covariance.
pub const RESEED_PROBABILITY: f64 = 0.9999;

/// Map matching binds a single track to a landmark only while the pose's position sigma is
/// at most this, metres; beyond it returning lamps are bound as a constellation only.
pub const MATCH_MAX_POSE_SIGMA_M: f64 = 0.5;

/// Lamps held while lost (seen in [`loops::MIN_FRAMES`] frames) after which, with no place
/// recognised, the navigator maps again (new ground).
pub const LOOP_GIVE_UP_LAMPS: usize = 30;

/// A lamp held while lost is mapped when the loop closes only if its position relative to
/// the vehicle is known this well (one sigma, metres): dead reckoning since it was seen
/// makes the older ones too uncertain to be worth a landmark (they are mapped when seen
/// again).
const HELD_MAP_MAX_SIGMA_M: f64 = 0.05;

/// Lamps held at most (a bound on memory): beyond, the navigator maps them and goes on
/// mapping as on new ground.
const LOOP_MAX_HELD: usize = 400;

/// Largest squared Mahalanobis distance (x, y, heading) of the correction a recognised place
/// implies, under the lost pose's covariance, for the loop to be closed. The right closures
/// of the seventeen hall-loop variants imply 0.6 to 27 (the dead-reckoned covariance is a
/// little optimistic after 100 m); hall 30 with odometry memory recognised its lamp grid
/// two rows off at 466 to 758 (8.5 m in y with the heading 1.7 degrees off, where the pose
/// was 7 m uncertain in y but its heading tied to it). Beyond this the place is taken for a
/// lattice alias and the lamps stay held. The lost pose's uncertainty grows while it is
/// held, so an alias refused now may pass later (hall 30 does): this is a gross check, not
/// a test between the place and its lattice shifts.
pub const LOOP_MAX_CORRECTION_D2: f64 = 100.0;

/// Rotation a constellation may make beyond three sigma of the heading, radians.
const LOOP_ROTATION_FLOOR_RAD: f64 = 0.02;

/// When phase 2's smoother starts again over the landmarks near the vehicle, they are the
/// nearest to a point this far ahead along the direction of travel, metres: about the
/// distance from the vehicle to the front of a ceiling camera's view at 4 to 6 m.
pub const SMOOTHER_LOOK_AHEAD_M: f64 = 3.0;

/// Degrees of freedom of [`reseed_distance`]: the pose and the estimated parameters.
fn reseed_dof(joint: &rig_model::handover::JointEstimate) -> f64 {
    #[allow(clippy::cast_precision_loss)] // a handful of parameters
    let n = (3 + joint.estimated.len()) as f64;
    n
}

/// The squared Mahalanobis distance of the joint estimate's pose and estimated parameters
/// from the filter's, under the filter's covariance of them; `None` when it cannot be
/// computed (a parameter the filter does not estimate, a singular block, NaN).
fn reseed_distance(ekf: &Ekf, joint: &rig_model::handover::JointEstimate) -> Option<f64> {
    let mut rows: Vec<usize> = alloc::vec![0, 1, 2];
    for &p in &joint.estimated {
        rows.push(ekf.camera_state_index(p)?);
    }
    let n = rows.len();
    let pose = ekf.pose();
    let camera = ekf.camera();
    let d = nalgebra::DVector::<f64>::from_iterator(
        n,
        [
            joint.pose.x - pose.x,
            joint.pose.y - pose.y,
            rig_model::camera::wrap_angle(joint.pose.theta - pose.theta),
        ]
        .into_iter()
        .chain(
            joint
                .estimated
                .iter()
                .map(|&p| joint.camera.get(p) - camera.get(p)),
        ),
    );
    let mut entries: Vec<f64> = Vec::with_capacity(n * n);
    for &rj in &rows {
        for &ri in &rows {
            entries.push(ekf.covariance_entry(ri, rj)?);
        }
    }
    let cov = nalgebra::DMatrix::<f64>::from_vec(n, n, entries);
    let d2 = d.dot(&cov.cholesky()?.solve(&d));
    d2.is_finite().then_some(d2)
}

fn ordered(a: LandmarkId, b: LandmarkId) -> (LandmarkId, LandmarkId) {
    if a <= b { (a, b) } else { (b, a) }
}

/// The pose is lost: its position more than [`MATCH_MAX_POSE_SIGMA_M`] uncertain along x or y.
fn pose_lost(ekf: &Ekf) -> bool {
    let c = ekf.pose_covariance();
    c.m11.max(c.m22) > MATCH_MAX_POSE_SIGMA_M * MATCH_MAX_POSE_SIGMA_M
}

/// Whether the pose is lost for map matching: [`pose_lost`], and with `relative`
/// ([`NavSettings::relative_lost`]) lost relative to the map around it as well: no landmark of
/// `anchors` (accepted lately) within [`MATCH_MAX_POSE_SIGMA_M`] of it, or a landmark predicted
/// in view that is not.
fn lost_for_matching(ekf: &Ekf, anchors: &BTreeMap<LandmarkId, u64>, relative: bool) -> bool {
    if !pose_lost(ekf) {
        return false;
    }
    if !relative {
        return true;
    }
    let near =
        |id: &LandmarkId| relative_sigma_m(ekf, *id).is_some_and(|s| s <= MATCH_MAX_POSE_SIGMA_M);
    // Anchored first: the landmarks in view are projected only for an anchored pose.
    if !anchors.keys().any(near) {
        return true;
    }
    ekf.landmarks_reached()
        .iter()
        .any(|(id, _)| !anchors.contains_key(id) && !near(id))
}

/// Frames a landmark the filter accepted anchors the pose ([`NavSettings::relative_lost`]):
/// one second at 20 Hz, a lamp tracked through a turn.
pub const ANCHOR_FRAMES: u64 = 20;

/// The pose's sigma relative to landmark `id`: the larger axis of the covariance of the
/// landmark's horizontal position in the vehicle's frame, `R(theta)^T (L - p)`, over the
/// landmark, the pose and the heading with their correlations, metres. `None` for an unknown
/// landmark or a covariance that cannot be read.
fn relative_sigma_m(ekf: &Ekf, id: LandmarkId) -> Option<f64> {
    let i = ekf.landmark_state_index(id)?;
    let rows = [i, i + 1, 0, 1, 2];
    let l = ekf.landmark_position(id)?;
    let pose = ekf.pose();
    let (dx, dy) = (l.x - pose.x, l.y - pose.y);
    let (s, c) = (libm::sin(pose.theta), libm::cos(pose.theta));
    // d/d(L, p, theta) of R^T (L - p): R^T [I, -I, d(R^T)/dtheta (L - p)].
    let j = nalgebra::SMatrix::<f64, 2, 5>::new(
        c,
        s,
        -c,
        -s,
        -s * dx + c * dy,
        -s,
        c,
        s,
        -c,
        -c * dx - s * dy,
    );
    let entries: Option<Vec<f64>> = rows
        .iter()
        .flat_map(|&rb| rows.iter().map(move |&ra| ekf.covariance_entry(ra, rb)))
        .collect();
    let p = nalgebra::SMatrix::<f64, 5, 5>::from_column_slice(&entries?);
    let cov = j * p * j.transpose();
    let (a, b, d) = (cov.m11, cov.m22, cov.m12);
    // The larger eigenvalue of the symmetric 2 x 2.
    let largest = 0.5 * (a + b) + libm::sqrt(0.25 * (a - b) * (a - b) + d * d);
    (largest.is_finite() && largest >= 0.0).then(|| libm::sqrt(largest))
}

/// What the lamps held while lost recognised ([`recognise`]).
enum Recognised {
    /// A place: its `(track, landmark)` pairs and where it puts the vehicle.
    Place {
        pairs: Vec<(u64, LandmarkId)>,
        guess: Pose2,
    },
    /// Several places fit.
    Ambiguous,
    /// One place fits, but the correction it implies is far beyond the lost pose's
    /// uncertainty ([`LOOP_MAX_CORRECTION_D2`]).
    Inconsistent,
    /// Nothing yet.
    Nothing,
}

/// The squared Mahalanobis distance of the correction from `pose` to `guess` (x, y and the
/// heading, wrapped) under the pose's covariance `cov`; `None` when `cov` cannot be
/// inverted.
fn correction_d2(pose: &Pose2, cov: &Matrix3<f64>, guess: &Pose2) -> Option<f64> {
    let d = nalgebra::Vector3::new(
        guess.x - pose.x,
        guess.y - pose.y,
        rig_model::camera::wrap_angle(guess.theta - pose.theta),
    );
    let inverse = cov.try_inverse()?;
    let d2 = d.dot(&(inverse * d));
    d2.is_finite().then_some(d2)
}

/// Map matching while the pose is lost (more than [`MATCH_MAX_POSE_SIGMA_M`] uncertain): the
/// frame's unbound observations are triangulated into the held lamps ([`loops::Held`]), whose
/// constellation is matched onto the landmarks within reach of the lost pose's uncertainty
/// ([`loops::constellation`]).
fn recognise(
    ekf: &Ekf,
    tracked: &TrackedFrame,
    unbound: &[usize],
    held: &mut loops::Held,
    frame: u64,
) -> Recognised {
    let camera = ekf.camera();
    let pose = ekf.pose();
    let sigma = ekf.noise().pixel;
    for &i in unbound {
        let Some(o) = tracked.observations.get(i) else {
            continue;
        };
        let Ok(tri) = rig_model::triangulate(&camera, &o.measurement) else {
            continue;
        };
        let position = tri.p_in_world(&camera, &pose);
        let covariance = if ekf.pixel_noise().is_uniform() {
            tri.covariance_in_world(&camera, &pose, sigma, None, None)
        } else {
            let r = Vector4::from(ekf.measurement_variances(&o.measurement));
            tri.covariance_in_world_of(&camera, &pose, &r, None, None)
        };
        let systematic =
            tri.covariance_in_world(&camera, &pose, 0.0, None, Some(&ekf.camera_covariance()));
        held.add(o.track.0, position, &covariance, &systematic, frame);
    }
    let cov = ekf.pose_covariance();
    let sigma_theta = libm::sqrt(cov.m33);
    let max_rotation = 3.0 * sigma_theta + LOOP_ROTATION_FLOOR_RAD;
    // A held lamp's landmark is within three sigma of the pose's uncertainty carried to it
    // (position, and heading times its distance from the vehicle).
    let sigma_position = libm::sqrt(
        cov.fixed_view::<2, 2>(0, 0)
            .symmetric_eigenvalues()
            .max()
            .max(0.0),
    );
    let map: Vec<(LandmarkId, nalgebra::Vector3<f64>)> = ekf.landmark_positions().collect();
    let reach = |p: &nalgebra::Vector3<f64>| {
        let d = libm::hypot(p.x - pose.x, p.y - pose.y);
        3.0 * (sigma_position + d * sigma_theta) + loops::PAIR_TOLERANCE_M
    };
    let candidates = held.candidates(&map, reach);
    let (pairs, motion) = match loops::constellation(&candidates, max_rotation) {
        loops::Found::Unique { pairs, motion } => (pairs, motion),
        loops::Found::Ambiguous => return Recognised::Ambiguous,
        loops::Found::None => return Recognised::Nothing,
    };
    // The motion lays the dead-reckoned world onto the map: the vehicle with it.
    let (angle, tx, ty) = motion;
    let (s, c) = (libm::sin(angle), libm::cos(angle));
    let guess = Pose2::new(
        c * pose.x - s * pose.y + tx,
        s * pose.x + c * pose.y + ty,
        rig_model::camera::wrap_angle(pose.theta + angle),
    );
    // A place whose correction the lost pose's own covariance rules out is a lattice alias
    // (a regular grid of lamps laid rows off), not the place: nothing is closed.
    if correction_d2(&pose, &cov, &guess).is_some_and(|d2| d2 > LOOP_MAX_CORRECTION_D2) {
        return Recognised::Inconsistent;
    }
    Recognised::Place { pairs, guess }
}

/// Closes a loop the held lamps recognised: the filter updated with the `pairs`' held lamps
/// as points relative to the vehicle (linearised first at `guess`, then iterated:
/// [`Ekf::update_relative`]), their tracks bound to the landmarks, and the other held lamps
/// mapped ([`map_held`]). Returns whether the filter took the update; either way nothing is
/// held afterwards.
fn close_loop(
    ekf: &mut Ekf,
    held: &mut loops::Held,
    candidates: &mut Candidates,
    pairs: &[(u64, LandmarkId)],
    guess: Pose2,
    stats: &mut NavStats,
    outcome: &mut FrameOutcome,
) -> Result<bool, Error> {
    let dead_reckoned = ekf.pose();
    let observations = held.relative_observations(pairs, &dead_reckoned);
    let batch: Vec<vslam_ekf::RelativeObservation> = observations.iter().map(|(_, o)| *o).collect();
    // The other lamps, relative to the vehicle before the update moves it.
    let others: Vec<(u64, loops::Relative)> = held
        .mature_keys()
        .into_iter()
        .filter(|k| !pairs.iter().any(|(t, _)| t == k))
        .filter_map(|k| Some((k, held.relative(k, &dead_reckoned)?)))
        .collect();
    held.clear();
    let Ok(report) = ekf.update_relative(&batch, guess) else {
        stats.refused_updates += 1;
        return Ok(false);
    };
    stats.loops_closed += 1;
    for (track, o) in &observations {
        if report.accepted.iter().any(|g| g.id == o.id) {
            candidates.bind(ekf, *track, o.id)?;
            outcome.rematched.push((*track, o.id));
            stats.rematched += 1;
        }
    }
    map_held(ekf, held, candidates, &others, stats)?;
    Ok(true)
}

/// Maps held lamps from where they were held relative to the vehicle
/// ([`Ekf::add_landmark_relative`]): `given` (taken before a loop's update moved the vehicle),
/// or, when empty, every lamp `held` has seen in [`loops::MIN_FRAMES`] frames relative to the
/// vehicle now. A lamp is left out when its relative position is more than
/// [`HELD_MAP_MAX_SIGMA_M`] uncertain, or when it would land within
/// [`loops::CONFLICT_RADIUS_M`] of a landmark (it may be that landmark a little off: map
/// matching decides when it is seen again).
fn map_held(
    ekf: &mut Ekf,
    held: &loops::Held,
    candidates: &mut Candidates,
    given: &[(u64, loops::Relative)],
    stats: &mut NavStats,
) -> Result<(), Error> {
    let now = ekf.pose();
    let lamps: Vec<(u64, loops::Relative)> = if given.is_empty() {
        held.mature_keys()
            .into_iter()
            .filter_map(|k| Some((k, held.relative(k, &now)?)))
            .collect()
    } else {
        given.to_vec()
    };
    let (s, c) = (libm::sin(now.theta), libm::cos(now.theta));
    for (track, r) in lamps {
        let cov = r.covariance;
        if candidates.landmark_of(track).is_some()
            || cov.m11.max(cov.m22) > HELD_MAP_MAX_SIGMA_M * HELD_MAP_MAX_SIGMA_M
        {
            continue;
        }
        let p = r.position;
        let (wx, wy) = (now.x + c * p.x - s * p.y, now.y + s * p.x + c * p.y);
        let near = ekf.landmark_positions().any(|(_, q)| {
            libm::hypot(q.x - wx, q.y - wy) < loops::CONFLICT_RADIUS_M
                && (q.z - p.z).abs() < loops::HEIGHT_TOLERANCE_M
        });
        if near {
            continue;
        }
        if let Ok(id) = ekf.add_landmark_relative(&p, &cov) {
            candidates.bind(ekf, track, id)?;
            stats.held_mapped += 1;
        }
    }
    Ok(())
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use rig_model::camera::Mount;
    use rig_model::config::Noise;

    /// Hall 30's alias (its numbers rounded): the pose 7 m uncertain along y but its heading
    /// tied to it, the place two lamp rows (8.5 m) off with the heading barely turned, is far
    /// beyond the pose's reach; the same shift with the turn the correlation asks for, and a
    /// right closure of the loop variants, are within it.
    #[test]
    fn a_correction_against_the_lost_pose_s_covariance() {
        let pose = Pose2::new(30.0, 15.0, 0.0);
        // sigma x 0.5 m, y 7 m, heading 0.1 rad, y and the heading correlated at 0.999.
        let (sx, sy, st) = (0.5_f64, 7.0_f64, 0.1_f64);
        let cov = Matrix3::new(
            sx * sx,
            0.0,
            0.0,
            0.0,
            sy * sy,
            0.999 * sy * st,
            0.0,
            0.999 * sy * st,
            st * st,
        );
        let shifted = |dy: f64, dtheta: f64| Pose2::new(30.0, 15.0 + dy, dtheta);
        let alias = correction_d2(&pose, &cov, &shifted(-8.5, -0.03)).unwrap();
        assert!(alias > LOOP_MAX_CORRECTION_D2, "{alias}");
        let along = correction_d2(&pose, &cov, &shifted(-8.5, -8.5 * 0.999 * st / sy)).unwrap();
        assert!(along < 2.0, "{along}");
        let small = correction_d2(&pose, &cov, &shifted(0.7, 0.0)).unwrap();
        assert!(small < LOOP_MAX_CORRECTION_D2, "{small}");
        assert!(correction_d2(&pose, &Matrix3::zeros(), &shifted(1.0, 0.0)).is_none());
    }

    fn rig() -> Rig {
        Rig {
            lens: None,
            board: rig_model::Board::DEFAULT,
            width: 752,
            height: 480,
            nominal: CameraParams {
                vehicle: Default::default(),
                f: 700.0,
                cx: 376.0,
                cy: 240.0,
                baseline: 0.12,
                mount: Mount {
                    z: 0.8,
                    ..Mount::default()
                },
            },
            estimate: Vec::new(),
            prior: [None; rig_model::N_PARAMS],
            noise: Noise::white(0.3, 0.02, 0.01),
        }
    }

    /// A landmark placed from a pose a metre uncertain in the world shares that uncertainty:
    /// the pose is known relative to it to what the pixels give, centimetres; driving on
    /// blind, the odometry's drift grows the relative sigma, and with no landmark accepted
    /// lately the pose counts as lost for map matching ([`NavSettings::relative_lost`]).
    #[test]
    fn a_pose_uncertain_in_the_world_is_known_relative_to_the_lamps_it_placed() {
        let rig = rig();
        let mut ekf = Ekf::from_prior(&rig, Settings::default()).unwrap();
        let start = Pose2::new(20.0, 0.0, 0.0);
        let cov = Matrix3::from_diagonal(&nalgebra::Vector3::new(1.0, 1.0, 0.004));
        ekf.set_start_pose(start, &cov).unwrap();
        let lamp = nalgebra::Vector3::new(21.0, 0.5, 7.8);
        let z = rig_model::project(&rig.nominal, &start, &lamp).unwrap();
        let id = ekf.add_landmark(&z).unwrap();
        let relative = relative_sigma_m(&ekf, id).unwrap();
        assert!(relative < 0.05, "relative sigma {relative} m");
        let anchors: BTreeMap<LandmarkId, u64> = [(id, 0)].into_iter().collect();
        assert!(pose_lost(&ekf));
        assert!(!lost_for_matching(&ekf, &anchors, true));
        assert!(lost_for_matching(&ekf, &anchors, false));
        // Blind at 1 m/s: dead reckoning alone between the pose and the lamp, its drift
        // growing as the heading's sigma times the distance.
        let mut blind_s = 0.0;
        while relative_sigma_m(&ekf, id).unwrap() <= MATCH_MAX_POSE_SIGMA_M && blind_s < 200.0 {
            ekf.predict(1.0, 0.0, 0.0, 0.05).unwrap();
            blind_s += 0.05;
        }
        assert!(
            (30.0..100.0).contains(&blind_s),
            "relative sigma {} m after {blind_s} s",
            relative_sigma_m(&ekf, id).unwrap()
        );
        assert!(lost_for_matching(&ekf, &anchors, true));
    }
}
