//! What a replay of a whole log produces ([`Replay`]): the estimates at every stereo frame, the
//! map, the camera parameters over time, the phase switch, the counters and, when the log
//! carries simulator truth, the errors. [`crate::write_estimates`] turns it into `EST.mcap`
//! and [`crate::read_estimates`] back; the replay writes `SUMMARY.json` and `TRAJ.csv` from
//! it too (vehicle-interfaces.md section 5).

use rig_model::camera::Param;

/// The navigator's phase at a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Phase {
    /// Phase 1: self-calibration; the pose is dead reckoning from the odometry.
    Calibrating,
    /// Phase 2: EKF SLAM with the camera parameters in the state.
    Navigating,
}

impl Phase {
    /// `"calibrating"` or `"navigating"`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Calibrating => "calibrating",
            Self::Navigating => "navigating",
        }
    }
}

/// One camera parameter's estimate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ParamEstimate {
    /// The parameter.
    pub param: Param,
    /// Its value (the nominal one when it is not estimated).
    pub value: f64,
    /// Its 1-sigma (0 when it is held fixed).
    pub sigma: f64,
}

impl ParamEstimate {
    /// Every parameter of C with its 1-sigma from a covariance in [`Param::ALL`] order (0 for
    /// a parameter held fixed; NaN stays NaN), [`Param::ALL`] order.
    pub fn all(
        camera: &rig_model::CameraParams,
        covariance: &nalgebra::SMatrix<f64, { rig_model::N_PARAMS }, { rig_model::N_PARAMS }>,
    ) -> Vec<Self> {
        Param::ALL
            .iter()
            .map(|&param| {
                let v = covariance
                    .get((param.index(), param.index()))
                    .copied()
                    .unwrap_or(0.0);
                Self {
                    param,
                    value: camera.get(param),
                    sigma: if v.is_nan() {
                        f64::NAN
                    } else {
                        v.max(0.0).sqrt()
                    },
                }
            })
            .collect()
    }
}

/// One landmark of the map.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LandmarkEstimate {
    /// The landmark's id (stable for its life).
    pub id: u64,
    /// World position, metres.
    pub position: [f64; 3],
    /// Its 3x3 covariance, row-major, square metres.
    pub covariance: [[f64; 3]; 3],
    /// Updates it took part in.
    pub observations: u64,
}

impl LandmarkEstimate {
    /// Per-axis 1-sigma, metres (NaN stays NaN: a broken covariance must not look exact).
    pub fn sigma(&self) -> [f64; 3] {
        core::array::from_fn(|i| {
            let v = self.covariance[i][i];
            if v.is_nan() {
                f64::NAN
            } else {
                v.max(0.0).sqrt()
            }
        })
    }
}

/// The estimate at one stereo frame.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameEstimate {
    /// The frame's timestamp (board clock), microseconds.
    pub t_us: u64,
    /// The phase the frame was processed in.
    pub phase: Phase,
    /// Robot pose `(X, Y, theta)` in the world frame (metres, radians).
    pub pose: [f64; 3],
    /// Its 3x3 covariance, row-major.
    pub pose_covariance: [[f64; 3]; 3],
    /// Landmarks observed (updated) at this frame, by id.
    pub observed: Vec<u64>,
    /// Each accepted observation's NIS (4 dof) at this frame, by landmark id.
    pub nis: Vec<(u64, f64)>,
    /// Observations rejected by the gate at this frame.
    pub rejected: u32,
    /// Landmarks in the map after the frame.
    pub landmarks: usize,
    /// The observations of landmarks the filter's update was given at this frame (accepted
    /// and rejected), each with the two board features it was made of: the navigator's own
    /// association (`nav::Association`). `None` when the source did not record them (an
    /// estimates file written before they were, a localisation run).
    pub associations: Option<Vec<Association>>,
}

/// An observation of a landmark the filter's update was given at a frame, and the two board
/// features it was made of.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Association {
    /// The landmark's id.
    pub id: u64,
    /// Index of the left feature in the frame's left list as the board sent it (the vehicle
    /// log's `/fpga/features`, raw: before any lens mapping).
    pub left: usize,
    /// Index of the right feature in the frame's right list, likewise.
    pub right: usize,
    /// The gate accepted it (the landmark was updated with it); else it was rejected.
    pub accepted: bool,
}

/// The camera parameters after a phase-1 solve or a phase-2 frame.
#[derive(Debug, Clone, PartialEq)]
pub struct CameraSample {
    /// Timestamp, microseconds.
    pub t_us: u64,
    /// The phase that produced it.
    pub phase: Phase,
    /// Every parameter of C, [`Param::ALL`] order.
    pub params: Vec<ParamEstimate>,
}

/// The map at one instant.
#[derive(Debug, Clone, PartialEq)]
pub struct MapSnapshot {
    /// Timestamp, microseconds.
    pub t_us: u64,
    /// Every landmark, by id.
    pub landmarks: Vec<LandmarkEstimate>,
}

/// What the replay counted.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Hash)]
pub struct Counts {
    /// Good packets (stereo frames) decoded.
    pub frames: u64,
    /// Packets rejected by the decoder.
    pub corrupt: u64,
    /// Frames lost (gaps in the board's frame counter).
    pub lost: u64,
    /// Bytes of the stream that were not part of a good packet.
    pub bytes_skipped: u64,
    /// Frames whose timestamp was earlier than the frame before it in the stream (sorted).
    pub frames_out_of_order: u64,
    /// Odometry samples.
    pub odometry: u64,
    /// Stereo measurements (left-right matches) over all frames.
    pub stereo_matches: u64,
    /// Tracks started.
    pub tracks: u64,
    /// Tracks confirmed.
    pub confirmed_tracks: u64,
    /// Frame pairs built for phase 1.
    pub pairs: u64,
    /// Landmark pairs in them.
    pub landmark_pairs: u64,
    /// Frames at which the odometry was missing, so that every track was restarted.
    pub tracker_resets: u64,
    /// Solves of phase 1's batch over every frame (the replay's phase 1).
    pub phase1_solves: u64,
    /// Stretches of the log file lost to damage (bad CRCs, broken records, a cut chunk's
    /// unreadable rest): [`vehicle_log::Damage::spans_total`].
    pub log_spans_lost: u64,
    /// Bytes of the log file in them.
    pub log_bytes_lost: u64,
    /// Chunk records lost in them, wholly or in part.
    pub log_chunks_lost: u64,
    /// Log time the lost stretches covered, milliseconds (where both ends are known).
    pub log_time_lost_ms: u64,
    /// Landmarks merged into another as the same lamp by the navigator's map-level guard
    /// (`nav::NavStats::landmarks_merged`).
    pub landmarks_merged: u64,
    /// Board features outside the navigator's field of use through a lens, left out
    /// (`nav::NavStats::features_outside_field`).
    pub features_outside_field: u64,
    /// Loops closed by the constellation of lamps held while the pose was lost
    /// (`nav::NavStats::loops_closed`).
    pub loops_closed: u64,
    /// Frames whose held lamps fitted one place that the lost pose's covariance rules out,
    /// refused as a lattice alias (`nav::NavStats::loops_refused`).
    pub loops_refused: u64,
    /// Lamps held while the pose was lost and mapped from where they were held
    /// (`nav::NavStats::held_mapped`).
    pub lamps_held_mapped: u64,
    /// Left camera images read from a ROS 2 bag (vehicle-interfaces.md 4.1; 0 for the
    /// board's stream).
    pub images_left: u64,
    /// Right camera images read from a ROS 2 bag.
    pub images_right: u64,
    /// Images without a partner within a quarter of the frame interval (frames with one
    /// image).
    pub images_unpaired: u64,
    /// Images of another size than the rig's `[camera]`.
    pub images_wrong_size: u64,
    /// Images of an encoding or format that is not read.
    pub images_unsupported: u64,
    /// Images whose bytes or message do not decode.
    pub images_undecodable: u64,
    /// Stereo frames lost because one of their images could not be read.
    pub image_frames_dropped: u64,
}

impl Counts {
    /// Every counter by name (the JSON keys and Python names), in field order.
    pub fn named(&self) -> [(&'static str, u64); 29] {
        [
            ("frames", self.frames),
            ("corrupt", self.corrupt),
            ("lost", self.lost),
            ("bytes_skipped", self.bytes_skipped),
            ("frames_out_of_order", self.frames_out_of_order),
            ("odometry", self.odometry),
            ("stereo_matches", self.stereo_matches),
            ("tracks", self.tracks),
            ("confirmed_tracks", self.confirmed_tracks),
            ("pairs", self.pairs),
            ("landmark_pairs", self.landmark_pairs),
            ("tracker_resets", self.tracker_resets),
            ("phase1_solves", self.phase1_solves),
            ("log_spans_lost", self.log_spans_lost),
            ("log_bytes_lost", self.log_bytes_lost),
            ("log_chunks_lost", self.log_chunks_lost),
            ("log_time_lost_ms", self.log_time_lost_ms),
            ("landmarks_merged", self.landmarks_merged),
            ("features_outside_field", self.features_outside_field),
            ("loops_closed", self.loops_closed),
            ("loops_refused", self.loops_refused),
            ("lamps_held_mapped", self.lamps_held_mapped),
            ("images_left", self.images_left),
            ("images_right", self.images_right),
            ("images_unpaired", self.images_unpaired),
            ("images_wrong_size", self.images_wrong_size),
            ("images_unsupported", self.images_unsupported),
            ("images_undecodable", self.images_undecodable),
            ("image_frames_dropped", self.image_frames_dropped),
        ]
    }
}

/// Errors against the simulator's truth, when the log carries it.
#[derive(Debug, Clone, PartialEq)]
pub struct TruthErrors {
    /// Root mean square of the 3-D position error of the landmarks matched to a lamp, metres.
    pub landmark_rms: f64,
    /// The same after the best planar rigid motion (x, y, heading) of the map onto the lamps,
    /// metres: the map's own error, without the uncertainty of where phase 2 started (the
    /// robot's dead-reckoned pose at the switch anchors the map).
    pub landmark_rms_aligned: f64,
    /// Landmarks matched to a lamp (the nearest lamp within `match_radius`, one-to-one).
    pub landmarks_matched: usize,
    /// Landmarks not matched to a lamp (clutter, or a lamp's second landmark).
    pub landmarks_unmatched: usize,
    /// Of the unmatched, those within the match radius of a lamp another landmark was matched
    /// to: a lamp mapped twice.
    pub landmarks_duplicate: usize,
    /// Lamps seen by both cameras at some frame with no landmark matched to them.
    pub lamps_missed: usize,
    /// The radius used to match landmarks to lamps, metres.
    pub match_radius: f64,
    /// Absolute trajectory error: RMS of the position error over the frames with a true pose,
    /// metres (no alignment: the world frame is the robot at the first frame, as in the truth).
    pub ate_rms: f64,
    /// Largest position error over those frames, metres.
    pub ate_max: f64,
    /// RMS heading error over those frames, radians.
    pub heading_rms: f64,
    /// Final camera parameter errors (estimate minus truth), [`Param::ALL`] order.
    pub camera: Vec<(Param, f64)>,
    /// The filter's consistency against the truth (only from a replay, not in the summary).
    pub consistency: Option<Consistency>,
}

/// NEES of phase 2's filter against the truth: how honest its covariance is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Consistency {
    /// Mean pose NEES (3 degrees of freedom) over the phase-2 frames with a true pose.
    pub pose_nees: f64,
    /// Frames in [`Self::pose_nees`].
    pub pose_frames: usize,
    /// Pose NEES at the last such frame.
    pub final_pose_nees: f64,
    /// Full-state NEES at the end: pose, every landmark within 10 cm of a lamp, the estimated
    /// camera parameters.
    pub state_nees: f64,
    /// Its degrees of freedom.
    pub state_dof: usize,
}

/// What a streaming replay (`replay::Replayer`) ends with: everything of a [`Replay`] but
/// the series of frames, camera samples and maps, which went to its `replay::ReplaySink` as
/// they came; bounded by the map, whatever the log's length.
#[derive(Debug, Clone, PartialEq)]
pub struct ReplayEnd {
    /// The last frame's estimate (final), if any frame was processed.
    pub last_frame: Option<FrameEstimate>,
    /// The first frame's timestamp, microseconds.
    pub first_t_us: Option<u64>,
    /// Frames processed (the rows of the trajectory).
    pub frames_processed: u64,
    /// Of them, frames processed in phase 2.
    pub phase2_frames: u64,
    /// The final map.
    pub landmarks: Vec<LandmarkEstimate>,
    /// The final camera parameters (every one of C).
    pub final_camera: Vec<ParamEstimate>,
    /// When phase 2 started (see [`Replay::phase_switch_t_us`]).
    pub phase_switch_t_us: Option<u64>,
    /// Phase 1 was skipped (see [`Replay::phase1_skipped`]).
    pub phase1_skipped: bool,
    /// What was read, decoded and associated.
    pub counts: Counts,
    /// Errors against the truth, when the log has it.
    pub truth: Option<TruthErrors>,
    /// Things that did not stop the replay but limit what it says, one line each.
    pub warnings: Vec<String>,
    /// What the log lost to damage, when it is damaged (`None`: every record was read).
    pub log_damage: Option<vehicle_log::Damage>,
    /// The error the final map's landmarks share, from the filter's joint covariance: the
    /// covariance of a rigid motion `(tx, ty, tz, yaw)` of the whole map about the point
    /// `(x, y)` (the landmarks' centroid), as `(point, covariance)`; `None` without a map of
    /// at least two landmarks (crate `map-file`'s `CommonError`, docs/maps.md).
    pub map_common_error: Option<([f64; 2], [[f64; 4]; 4])>,
    /// The odometry's noise model used (see [`Replay::odometry`]).
    pub odometry: Option<OdometryModel>,
}

/// The odometry's noise model a replay used (issue 36): the rig file's, and how the navigator
/// widened it when the batch's residuals showed the odometry worse than stated.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OdometryModel {
    /// The rig file's `[noise]` `velocity` (m/s), `yaw_rate` (rad/s), `velocity_tau` and
    /// `yaw_rate_tau` (s).
    pub stated: [f64; 4],
    /// The `velocity` and `yaw_rate` in use at the end (the stated ones unless widened).
    pub used: [f64; 2],
    /// The widening, when there was one.
    pub widened: Option<OdometryWidened>,
}

/// How the odometry's noise model was widened ([`OdometryModel::widened`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OdometryWidened {
    /// The frame at which it was first widened, board time, microseconds.
    pub t_us: u64,
    /// The span of the check that first showed it, seconds.
    pub span_s: f64,
    /// The variance ratios over that span then, `(translation, heading)`.
    pub ratios: [f64; 2],
    /// The variance factors applied in all, `(translation, heading)`.
    pub variance_factors: [f64; 2],
    /// The errors' time constants seen, `(translation, heading)`, seconds (0: none seen).
    pub time_constants_s: [f64; 2],
}

/// A whole log replayed.
#[derive(Debug, Clone, PartialEq)]
pub struct Replay {
    /// One per stereo frame processed, in time order.
    pub frames: Vec<FrameEstimate>,
    /// The camera parameters over time (every phase-1 solve, then every phase-2 frame).
    pub camera: Vec<CameraSample>,
    /// The map about once a second of data time, and at the end.
    pub maps: Vec<MapSnapshot>,
    /// The final map.
    pub landmarks: Vec<LandmarkEstimate>,
    /// The final camera parameters (every one of C).
    pub final_camera: Vec<ParamEstimate>,
    /// When phase 2 started (`None`: phase 1 never became stable, or was skipped: then
    /// [`Replay::phase1_skipped`]).
    pub phase_switch_t_us: Option<u64>,
    /// Phase 1 was skipped: phase 2 ran from the rig's nominal values and priors.
    pub phase1_skipped: bool,
    /// What was read, decoded and associated.
    pub counts: Counts,
    /// Errors against the truth, when the log has it.
    pub truth: Option<TruthErrors>,
    /// Things that did not stop the replay but limit what it says, one line each.
    pub warnings: Vec<String>,
    /// What the log lost to damage, when it is damaged (`None`: every record was read, or the
    /// replay was read back from an estimates file, whose counts and warnings say it).
    pub log_damage: Option<vehicle_log::Damage>,
    /// The odometry's noise model used (`None`: not known, as for estimates files written
    /// before it was reported).
    pub odometry: Option<OdometryModel>,
}

impl Replay {
    /// The replay made of a streaming replay's end and the series its sink collected.
    pub fn from_parts(
        end: ReplayEnd,
        frames: Vec<FrameEstimate>,
        camera: Vec<CameraSample>,
        maps: Vec<MapSnapshot>,
    ) -> Self {
        Self {
            frames,
            camera,
            maps,
            landmarks: end.landmarks,
            final_camera: end.final_camera,
            phase_switch_t_us: end.phase_switch_t_us,
            phase1_skipped: end.phase1_skipped,
            counts: end.counts,
            truth: end.truth,
            warnings: end.warnings,
            log_damage: end.log_damage,
            odometry: end.odometry,
        }
    }
}
