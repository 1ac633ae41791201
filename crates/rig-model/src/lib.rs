//! The stereo rig model that every part of the method shares.
//!
//! * [`camera`]: the camera parameters `C` (`f, cx, cy, baseline, mount_x .. mount_yaw`) and
//!   the planar robot pose (vehicle-interfaces.md section 1).
//! * [`rig`]: projection of a world point to the four measurements `(uL, vL, uR, vR)` with its
//!   analytic Jacobians with respect to the pose, the landmark and every camera parameter, and
//!   stereo triangulation with covariance propagation.
//! * [`config`] (feature `alloc`): the rig configuration: nominal `C`, what to estimate, priors,
//!   noise; [`rig_file`] (feature `rig-file`, on with `std`) reads and writes it as TOML (section 3) and JSON.
//! * [`lens`]: real lenses (section 1.1); [`stereo_rectify`]: a raw stereo calibration
//!   rectified as OpenCV's `stereoRectify` does (section 5, `stereonav rig import`);
//!   [`import`] (feature `std`): rig files from Kalibr, ROS and OpenCV calibrations, for the
//!   command line's `rig import` and Python's `stereonav.import_rig`.
//! * [`odometry`]: odometry samples and their integration into motion (section 2).
//! * [`handover`] (feature `alloc`): what the phases hand each other (frame pairs, phase 1's
//!   calibration and map).
//!
//! Phase 1's solvers live in the `selfcal` crate, phase 2's filter in `vslam-ekf`; both build
//! on this one and on nothing of each other.
//!
//! Builds without `std` (with `alloc`; nalgebra with `libm`) so that firmware can link it.
#![cfg_attr(not(feature = "std"), no_std)]
#![forbid(unsafe_code)]
#![deny(missing_docs)]

#[cfg(feature = "alloc")]
extern crate alloc;

pub mod camera;
#[cfg(feature = "alloc")]
pub mod config;
#[cfg(feature = "alloc")]
pub mod handover;
#[cfg(feature = "std")]
pub mod import;
pub mod lens;
pub mod odometry;
pub mod rig;
#[cfg(feature = "rig-file")]
pub mod rig_file;
pub mod stereo_rectify;

pub use camera::{CameraParams, Mount, N_CAMERA, N_PARAMS, Param, ParamVector, Pose2, Vehicle};
#[cfg(feature = "alloc")]
pub use config::{Board, Noise, Rig};
pub use rig::{
    Measurement, ProjectionJacobians, Projector, RigError, Triangulation, point_in_rig, project,
    project_with_jacobians, triangulate,
};
#[cfg(feature = "rig-file")]
pub use rig_file::{RIG_FILE_KEYS, RigFileError};
