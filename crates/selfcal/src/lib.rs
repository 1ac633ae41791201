//! Phase 1 of the method: self-calibration of the camera parameters `C` (and the vehicle's
//! `V`) while the vehicle moves, before the map exists.
//!
//! The paper's frame-pair solver, one module per step of the method:
//!
//! * [`residual`]: eq. (1), relative landmark motion: `E_L = L_t - (Rot_z(dtheta) L_{t+1} +
//!   dT)` for landmarks triangulated at two instants ([`residual::relative_landmark_motion`]),
//!   whitened by its covariance from the pixel and the odometry noise.
//! * [`step`]: eq. (2), the Levenberg-Marquardt step `dC = -(J^T W J + k D)^-1 J^T W E_L`
//!   ([`step::levenberg_marquardt_step`]).
//! * [`solve`]: the Levenberg-Marquardt loop over frame pairs ([`calibrate`], with
//!   [`SolverSettings`], [`Calibration`], [`SolveStatus`]): Huber loss, priors, adaptive
//!   damping.
//! * [`observability`]: what the data say about each estimated parameter against its prior,
//!   and the known traps of the rig and the path ([`structural_trap`]).
//! * [`calibrator`]: the incremental calibrator fed pair by pair ([`SelfCalibrator`]) and the
//!   rule that decides when `C` is stable ([`StableRule`]).
//!
//! And the batch that the navigator uses:
//!
//! * [`smoother`]: the batch over every frame: every pose, lamp and estimated parameter solved
//!   together, handing phase 2 the joint estimate ([`rig_model::handover::BatchHandover`]).
//!
//! Every settings type checks itself (`validate`, [`Error`]). What phase 1 takes in (frame
//! pairs) and gives out (the hand-overs) is plain data in [`rig_model::handover`], so that
//! association and phase 2 need nothing of this crate. [`solver`] keeps the frame-pair
//! solver's names at their former paths.
//!
//! Builds without `std` (with `alloc`; nalgebra with `libm`) so that firmware can link it.
#![cfg_attr(not(feature = "std"), no_std)]
#![forbid(unsafe_code)]
#![deny(missing_docs)]

extern crate alloc;

pub mod calibrator;
pub mod error;
pub mod observability;
pub mod residual;
pub mod smoother;
pub mod solve;
pub mod solver;
pub mod step;

pub use calibrator::{SelfCalibrator, StableRule};
pub use error::Error;
pub use observability::structural_trap;
pub use smoother::{
    CONSISTENCY_SPANS_S, OdometryConsistency, OdometryStep, OdometryWidening, STRONG_HEADING_LIMIT,
    Smoother, SmootherSettings, heading_strongly_worse, judge_odometry, long_run_ratio,
    trajectory_consistency, widened_odometry_covariance,
};
pub use solve::{Calibration, SolveStatus, SolverSettings, calibrate};
