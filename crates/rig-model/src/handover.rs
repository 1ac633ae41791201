//! What the parts of the method hand each other: association gives phase 1 its frame pairs
//! ([`FramePair`] of [`LandmarkPair`]s); phase 1 gives phase 2 the calibrated camera
//! ([`Handover`] from the frame-pair solver, [`BatchHandover`] from the batch over every frame,
//! [`JointEstimate`] while the batch goes on as a fixed-lag smoother), each with its
//! observability report ([`ObservabilityReport`]).
//!
//! Plain data, here below both phases so that neither imports the other's solver.

use alloc::vec::Vec;

use nalgebra::{DMatrix, SMatrix, Vector3};

use crate::camera::{CameraParams, N_PARAMS, Param, Pose2};
use crate::odometry::Motion;
use crate::rig::Measurement;

/// A 10x10 matrix over the camera parameters, [`Param::ALL`] order.
pub type Mat10 = SMatrix<f64, N_PARAMS, N_PARAMS>;

/// One landmark seen at both instants of a frame pair.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LandmarkPair {
    /// `(uL, vL, uR, vR)` at the first instant.
    pub first: Measurement,
    /// `(uL, vL, uR, vR)` at the second instant.
    pub second: Measurement,
}

/// Two stereo frames close in time, the odometry motion between them, and the landmarks
/// associated across them.
#[derive(Debug, Clone, PartialEq)]
pub struct FramePair {
    /// Timestamp of the second frame, microseconds (for histories).
    pub t_us: u64,
    /// Motion from the first frame to the second, in the first frame's robot frame.
    pub motion: Motion,
    /// The landmarks seen in both.
    pub landmarks: Vec<LandmarkPair>,
}

/// How well one estimated parameter is constrained.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ParamObservability {
    /// The parameter.
    pub param: Param,
    /// Its prior sigma (rig file).
    pub prior_sigma: f64,
    /// Its sigma from the data alone (infinite when the data say nothing).
    pub data_sigma: f64,
    /// Its sigma from data and prior together.
    pub posterior_sigma: f64,
    /// Whether the data constrain it (`posterior_sigma <= observable_ratio * prior_sigma`).
    pub observable: bool,
    /// Why not, when it is not.
    pub reason: Option<&'static str>,
    /// Not observable because of a known trap of the rig and the path (upward head, planar
    /// motion, straight path), rather than for lack of data so far.
    pub structural: bool,
}

/// The observability analysis of the estimated parameters.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ObservabilityReport {
    /// One entry per estimated parameter.
    pub params: Vec<ParamObservability>,
    /// Largest absolute correlation between two estimated, observable parameters, and which.
    pub max_correlation: Option<(Param, Param, f64)>,
    /// Eigenvalues of the data's information matrix in prior-sigma units, ascending.
    pub information_eigenvalues: Vec<f64>,
}

impl ObservabilityReport {
    /// The parameters the data cannot give.
    pub fn unobservable(&self) -> impl Iterator<Item = &ParamObservability> {
        self.params.iter().filter(|p| !p.observable)
    }
}

/// What phase 1 hands to phase 2: the camera parameters with their covariance.
#[derive(Debug, Clone, PartialEq)]
pub struct Handover {
    /// The calibrated camera parameters.
    pub camera: CameraParams,
    /// Their covariance (zero rows for parameters not estimated or held at nominal).
    pub covariance: Mat10,
    /// Time of the frame at which calibration became stable, microseconds.
    pub t_us: u64,
    /// The observability report at hand-over.
    pub observability: ObservabilityReport,
}

/// One landmark of the batch.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BatchLandmark {
    /// World position, metres.
    pub position: Vector3<f64>,
    /// The track that saw it last (the one phase 2 keeps following).
    pub track: u64,
    /// Frame index of its first observation.
    pub first_frame: usize,
    /// Observations of it used.
    pub observations: u64,
}

/// Why the hand-over happened.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum HandoverReason {
    /// The stable rule fired.
    Stable,
    /// The buffer was full: the batch's `max_frames` frames, or a lamp needed a
    /// landmark beyond its `max_landmarks`.
    BufferFull,
    /// The caller asked for it (the end of a log).
    Requested,
}

/// What phase 1 hands to phase 2: the joint estimate at the last frame.
#[derive(Debug, Clone, PartialEq)]
pub struct BatchHandover {
    /// Time of the last frame, microseconds.
    pub t_us: u64,
    /// Why now.
    pub reason: HandoverReason,
    /// The camera parameters (the ones not estimated at nominal).
    pub camera: CameraParams,
    /// Their covariance (zero rows for the ones not estimated).
    pub camera_covariance: Mat10,
    /// The last frame's pose.
    pub pose: Pose2,
    /// The landmarks.
    pub landmarks: Vec<BatchLandmark>,
    /// The parameters in [`Self::covariance`], in its order: the rig's estimated ones that the
    /// data informed. The others are held at their nominal values (the batch was solved again
    /// without them) and enter phase 2 with their prior.
    pub estimated: Vec<Param>,
    /// Joint covariance of `[pose (3), estimated (in that order), landmarks (3 each)]`.
    pub covariance: DMatrix<f64>,
    /// Every frame's `(t_us, pose)`: the smoothed trajectory of phase 1.
    pub trajectory: Vec<(u64, Pose2)>,
    /// Which parameters the data informed, and why not the others.
    pub observability: ObservabilityReport,
}

impl BatchHandover {
    /// 1-sigma uncertainty of one camera parameter (0 for one not estimated).
    pub fn sigma(&self, p: Param) -> f64 {
        libm::sqrt(self.camera_covariance[(p.index(), p.index())].max(0.0))
    }

    /// The estimated parameters that the data did not inform (they enter phase 2 with about
    /// their prior).
    pub fn uninformed(&self) -> Vec<Param> {
        self.observability
            .params
            .iter()
            .filter(|p| !p.observable)
            .map(|p| p.param)
            .collect()
    }
}

/// The joint estimate of the last solve: what phase 2's filter is re-seeded with while the
/// batch goes on as a fixed-lag smoother.
#[derive(Debug, Clone, PartialEq)]
pub struct JointEstimate {
    /// Time of the frame solved last, microseconds.
    pub t_us: u64,
    /// Its pose.
    pub pose: Pose2,
    /// The camera parameters.
    pub camera: CameraParams,
    /// The parameters in [`Self::covariance`], in its order.
    pub estimated: Vec<Param>,
    /// The landmarks, in the batch's order (index = the batch's `add_landmark`).
    pub landmarks: Vec<Vector3<f64>>,
    /// Joint covariance of `[pose (3), estimated, landmarks (3 each)]`.
    pub covariance: DMatrix<f64>,
}
