//! Helpers of the phase-1 tests: the rig model's test helpers (its seeded Gaussian generator
//! among them) and the synthetic frame pairs.
#![allow(dead_code, unreachable_pub, clippy::unwrap_used, clippy::expect_used)] // test helpers

#[path = "../../../../rig-model/tests/integration/common/mod.rs"]
mod rig_model;
pub mod synthetic;

pub use rig_model::*;
