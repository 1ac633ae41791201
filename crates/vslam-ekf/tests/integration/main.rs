//! The integration tests of the EKF SLAM filter, one module per subject, in one test binary:
//! one link of the crate's dependencies instead of one per file (docs/testing.md).
//! A new file here needs its `mod` line below; a file directly in `tests/` would be a test
//! binary of its own.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failure is the test failing

mod candidates;
mod common;
mod consider;
mod jacobians;
mod merge;
mod odometry_errors;
mod relative;
mod simulation;
mod update;
mod vehicle;
