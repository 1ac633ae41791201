//! The integration tests of the viewer, one module per subject, in one test binary:
//! one link of the crate's dependencies instead of one per file (docs/testing.md).
//! A new file here needs its `mod` line below; a file directly in `tests/` would be a test
//! binary of its own.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failure is the test failing

mod bag;
mod lens;
mod screenshot;

use std::path::PathBuf;

/// A file in this test's directory under Cargo's `target/tmp` (`viewer-SUITE/TEST`): a rerun
/// overwrites it, and `cargo clean` removes it (libtest names each test's thread after the
/// test).
fn scratch(suite: &str, name: &str) -> PathBuf {
    let test = std::thread::current()
        .name()
        .unwrap_or("main")
        .replace("::", "-");
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("viewer-{suite}"))
        .join(test);
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}
