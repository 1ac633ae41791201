//! Helpers shared by the command-line tests.
#![allow(dead_code, unreachable_pub, clippy::expect_used)] // test helpers; not every suite uses all

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// Runs the `stereonav` binary built for these tests.
pub fn stereonav(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_stereonav"))
        .args(args)
        .output()
        .expect("stereonav runs")
}

/// A file path in a scratch directory of this test process, per suite.
pub fn scratch(suite: &str, name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("stereonav-{suite}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    dir.join(name)
}

/// The error contract: non-zero exit, exactly one line on stderr naming the problem, no panic.
pub fn assert_one_line_error(out: &Output, needle: &str) {
    assert!(!out.status.success(), "expected failure");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(
        stderr.trim_end().lines().count(),
        1,
        "one line, got: {stderr}"
    );
    assert!(
        stderr.contains(needle),
        "{stderr:?} should mention {needle:?}"
    );
    assert!(!stderr.contains("panicked"), "{stderr}");
}

/// The camera parameters of C in `Param::ALL` order, as the JSON documents name them.
pub const PARAMETERS: [&str; 10] = [
    "f",
    "cx",
    "cy",
    "baseline",
    "mount_x",
    "mount_y",
    "mount_z",
    "mount_roll",
    "mount_pitch",
    "mount_yaw",
];

/// A committed log or rig file of `fixtures/logs`.
pub fn fixture(name: &str) -> PathBuf {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/logs")
        .join(name);
    assert!(path.exists(), "{} is missing", path.display());
    path
}

/// A path as a command-line argument.
pub fn s(p: &Path) -> &str {
    p.to_str().expect("UTF-8 test path")
}
