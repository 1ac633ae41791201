//! Phase 1 of the method: self-calibration of the camera parameters `C` (and the vehicle's
//! `V`) while the vehicle moves, before the map exists.
//!
//! * [`solver`]: the paper's frame-pair solver: eq. (1), `L_t = Rot_z(dtheta) L_{t+1} + dT`,
//!   over landmarks triangulated at two instants, and its Levenberg-Marquardt step eq. (2),
//!   with the observability analysis and the incremental calibrator that decides when `C` is
//!   stable ([`solver::SelfCalibrator`], [`solver::StableRule`]).
//! * [`smoother`]: the batch over every frame that the navigator uses: every pose, lamp and
//!   estimated parameter solved together, handing phase 2 the joint estimate
//!   ([`rig_model::handover::BatchHandover`]).
//!
//! What phase 1 takes in (frame pairs) and gives out (the hand-overs) is plain data in
//! [`rig_model::handover`], so that association and phase 2 need nothing of this crate.
//!
//! Builds without `std` (with `alloc`; nalgebra with `libm`) so that firmware can link it.
#![cfg_attr(not(feature = "std"), no_std)]
#![forbid(unsafe_code)]
#![deny(missing_docs)]

extern crate alloc;

pub mod error;
pub mod smoother;
pub mod solver;

pub use error::Error;
pub use smoother::SmootherSettings;
pub use solver::{SolverSettings, StableRule};
