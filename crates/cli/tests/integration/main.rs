//! The integration tests of the `stereonav` command line, run as a process, one module per subject, in one test binary:
//! one link of the crate's dependencies instead of one per file (docs/testing.md).
//! A new file here needs its `mod` line below; a file directly in `tests/` would be a test
//! binary of its own.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failure is the test failing

mod calibrate_cli;
mod common;
mod fpga_cli;
mod harris_cli;
mod localize_cli;
mod log_cli;
mod map_import_cli;
mod replay_cli;
mod rig_import_cli;
mod simulate_cli;
mod view_cli;
