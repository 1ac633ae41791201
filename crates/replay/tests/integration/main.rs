//! The integration tests of replaying vehicle logs, one module per subject, in one test binary:
//! one link of the crate's dependencies instead of one per file (docs/testing.md).
//! A new file here needs its `mod` line below; a file directly in `tests/` would be a test
//! binary of its own.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failure is the test failing

mod calibrate_log;
mod estimates_reader;
mod hall;
mod lens;
mod lighting_plan;
mod mapped_once;
mod navigate;
mod output;
mod real_log;
mod ros2_bag;
mod slipping_wheels;
mod streaming;
mod vehicle;

/// A committed scenario of `fixtures/scenarios` (`name` with its `.toml`).
fn scenario(name: &str) -> sim::Scenario {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/scenarios")
        .join(name);
    sim::Scenario::load(&path).unwrap()
}
