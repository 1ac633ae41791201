//! The frame-pair solver's public names at their paths from before it was split by equation
//! (`selfcal::solver::calibrate`, ...), so that code written against them goes on building.
//! New code names the modules: [`crate::residual`] (eq. (1)), [`crate::step`] (eq. (2)),
//! [`crate::solve`], [`crate::observability`] and [`crate::calibrator`].

pub use crate::calibrator::{SelfCalibrator, StableRule};
pub use crate::observability::structural_trap;
pub use crate::solve::{Calibration, SolveStatus, SolverSettings, calibrate};
