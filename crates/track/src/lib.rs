//! The navigator's association: which features are which lamp, from frame to frame, without
//! knowing the answer (the simulator's lamp ids are for judging it, never for running it).
//!
//! Data flows one way, each stage a module that can be used alone:
//!
//! 1. [`stereo`]: left-right matching on the rectified rig. A left and a right feature are one
//!    lamp when they lie on the same row (within a gate set by the pixel noise) at a positive
//!    disparity that puts the lamp between a nearest and a farthest depth (`d = f B / z`).
//!    Matches are one-to-one and mutual; a feature with two nearly equally good partners is
//!    dropped, not guessed. Output: [`rig_model::Measurement`]s `(uL, vL, uR, vR)` in pixels.
//! 2. [`tracker`]: frame-to-frame tracking with persistent, never reused [`TrackId`]s. Each
//!    track's last measurement is triangulated, moved by the odometry motion since it was
//!    seen, and projected into the new frame; measurements are gated by the Mahalanobis
//!    distance of the innovation (pixel noise of both frames, odometry noise and the camera
//!    parameters' uncertainty, all propagated through the rig model's Jacobians) and assigned
//!    one-to-one by increasing distance, with ambiguity rejection. A track is *confirmed*
//!    after a few consecutive hits, so isolated clutter never reaches the estimators.
//! 3. [`pairs`]: phase 1's frame pairs ([`rig_model::handover::FramePair`]): two frames `stride`
//!    frames apart ([`PairingScheme::Disjoint`] or [`PairingScheme::Interleaved`]), the
//!    odometry integrated between their timestamps, and the confirmed tracks seen in both.
//!
//! [`FrontEnd`] chains 1 and 2 with an [`OdometryBuffer`] for the motion between frames; it
//! is what a replay or the vehicle runs per frame. [`Model`] holds what every stage assumes
//! about the sensors: the current camera parameters with their covariance (the rig file's
//! priors before calibration, phase 1's result after it) and the noise model.
//!
//! `#![no_std]` with `alloc` (tracks and pairs live on the heap); nothing panics on any input,
//! and NaN or infinite values are rejected where they enter, never propagated into a track.
#![no_std]
#![forbid(unsafe_code)]
#![deny(missing_docs)]
#![warn(clippy::indexing_slicing)]

#[cfg(not(feature = "alloc"))]
compile_error!(
    "the track crate needs the `alloc` feature (or `std`): its tracks and pairs live on the heap"
);

#[cfg(feature = "alloc")]
extern crate alloc;
#[cfg(feature = "std")]
extern crate std;

#[cfg(feature = "alloc")]
mod error;
#[cfg(feature = "alloc")]
mod frontend;
#[cfg(feature = "alloc")]
pub mod model;
#[cfg(feature = "alloc")]
pub mod odometry;
#[cfg(feature = "alloc")]
pub mod pairs;
#[cfg(feature = "alloc")]
pub mod stereo;
#[cfg(feature = "alloc")]
pub mod tracker;

#[cfg(feature = "alloc")]
pub use error::SettingsError;
#[cfg(feature = "alloc")]
pub use frontend::{FrontEnd, FrontEndSettings};
#[cfg(feature = "alloc")]
pub use model::Model;
#[cfg(feature = "alloc")]
pub use odometry::OdometryBuffer;
#[cfg(feature = "alloc")]
pub use pairs::{PairBuilder, PairSettings, PairStats, PairingScheme, labelled_pairs};
#[cfg(feature = "alloc")]
pub use stereo::{
    Pixel, RectifiedFeatures, RectifiedSide, StereoMatch, StereoMatcher, StereoSettings,
    StereoStats, rectify_features,
};
#[cfg(feature = "alloc")]
pub use tracker::{
    Observation, TrackId, TrackInfo, TrackedFrame, Tracker, TrackerSettings, TrackerStats,
};
