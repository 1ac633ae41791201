//! Why the filter refused an input or an operation. Every refusal leaves the filter's state,
//! covariance and map exactly as they were; only the health counts updates refused for lost
//! positive definiteness.

use rig_model::{Param, RigError};

use crate::LandmarkId;

/// A refused input or operation; the message names the problem and the values involved.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// The map holds [`crate::Settings::max_landmarks`] landmarks: no more are added.
    #[error("the map holds its most landmarks ({cap}): no more are added")]
    LandmarkCap {
        /// The cap.
        cap: usize,
    },
    /// A number that came in is NaN or infinite.
    #[error("{what} is not finite ({value})")]
    NonFinite {
        /// Which input (`"odometry vx"`, `"measurement uL of landmark 7"` ...).
        what: &'static str,
        /// The offending value.
        value: f64,
    },
    /// A measurement of a landmark has a NaN or infinite pixel coordinate.
    #[error("measurement of {id} has a non-finite pixel coordinate ({value})")]
    NonFiniteMeasurement {
        /// The landmark.
        id: LandmarkId,
        /// The offending coordinate.
        value: f64,
    },
    /// A measurement of a track has a NaN or infinite pixel coordinate.
    #[error("measurement of track {track} has a non-finite pixel coordinate ({value})")]
    NonFiniteTrackMeasurement {
        /// The caller's track id.
        track: u64,
        /// The offending coordinate.
        value: f64,
    },
    /// A rig, start or settings value is out of its range.
    #[error("{name} = {value} must be {expected}")]
    BadValue {
        /// The value, as `struct.field` or rig-file key.
        name: &'static str,
        /// Its value.
        value: f64,
        /// What it must be.
        expected: &'static str,
    },
    /// A camera parameter is listed twice in the rig's `estimate`.
    #[error("camera parameter {param} is listed twice in the rig's estimate list")]
    DuplicateEstimate {
        /// The parameter.
        param: Param,
    },
    /// An estimated camera parameter has neither a start variance nor a rig prior.
    #[error("camera parameter {param} is estimated but has no prior sigma and no start variance")]
    MissingPrior {
        /// The parameter.
        param: Param,
    },
    /// The start covariance of the estimated camera parameters is not positive definite.
    #[error("start covariance of the estimated camera parameters is not positive definite")]
    BadCameraCovariance,
    /// The start pose covariance is not symmetric positive semi-definite.
    #[error("start pose covariance is not symmetric positive semi-definite")]
    BadPoseCovariance,
    /// The start pose can only be set while the map is empty.
    #[error("start pose can only be set before any landmark is added ({landmarks} in the map)")]
    PoseAfterLandmarks {
        /// Landmarks already in the map.
        landmarks: usize,
    },
    /// A time step is negative.
    #[error("time step {dt_s} s is negative")]
    NegativeTimeStep {
        /// The step, seconds.
        dt_s: f64,
    },
    /// No odometry sample covers the start of the interval to predict over.
    #[error("no odometry sample at or before t = {t0_us} us (first at {first_us:?} us)")]
    NoOdometry {
        /// Start of the interval, microseconds.
        t0_us: u64,
        /// The first sample's time, if any.
        first_us: Option<u64>,
    },
    /// The interval to predict over ends before it starts.
    #[error("odometry interval ends at {t1_us} us, before its start {t0_us} us")]
    BackwardInterval {
        /// Start, microseconds.
        t0_us: u64,
        /// End, microseconds.
        t1_us: u64,
    },
    /// No landmark has this id (never added, or removed).
    #[error("{id} is not in the map")]
    UnknownLandmark {
        /// The id asked for.
        id: LandmarkId,
    },
    /// The same landmark appears twice in one update batch.
    #[error("{id} appears twice in one update batch")]
    DuplicateObservation {
        /// The landmark.
        id: LandmarkId,
    },
    /// The same track appears twice in one frame.
    #[error("track {track} appears twice in one frame")]
    DuplicateTrack {
        /// The caller's track id.
        track: u64,
    },
    /// A landmark cannot be projected at the current estimate (behind the camera, bad camera).
    #[error("{id} cannot be projected at the current estimate: {source}")]
    Projection {
        /// The landmark.
        id: LandmarkId,
        /// Why.
        source: RigError,
    },
    /// A measurement cannot be triangulated into a new landmark.
    #[error("measurement cannot be triangulated into a landmark: {source}")]
    Triangulation {
        /// Why.
        source: RigError,
    },
    /// The innovation covariance `S` of the batch is not positive definite (Cholesky failed):
    /// the covariance `P` has lost its positive definiteness. The update was not applied.
    #[error("innovation covariance of {observations} observations is not positive definite")]
    InnovationNotPositiveDefinite {
        /// Observations in the batch.
        observations: usize,
    },
    /// The update would have made a variance of the state non-positive (or NaN); it was not
    /// applied.
    #[error("update would make variance of state {index} non-positive ({before} -> {after})")]
    VarianceNotPositive {
        /// Index in the state vector.
        index: usize,
        /// Variance before the update.
        before: f64,
        /// Variance it would have had.
        after: f64,
    },
    /// The update would have made the state NaN or infinite; it was not applied.
    #[error("update would make state {index} non-finite")]
    StateNotFinite {
        /// Index in the state vector.
        index: usize,
    },
    /// The covariance of two landmarks' difference is not positive definite (`P` has lost its
    /// definiteness); nothing was merged.
    #[error("{a} and {b}: the covariance of their difference is not positive definite")]
    PairNotPositiveDefinite {
        /// The first landmark.
        a: LandmarkId,
        /// The second landmark.
        b: LandmarkId,
    },
    /// A landmark cannot be merged into itself.
    #[error("{id} cannot be merged into itself")]
    MergeIntoItself {
        /// The landmark.
        id: LandmarkId,
    },
    /// The landmark is already bound to the given track.
    #[error("{id} is already bound to track {track}")]
    LandmarkBound {
        /// The landmark.
        id: LandmarkId,
        /// The track it is bound to.
        track: u64,
    },
}
