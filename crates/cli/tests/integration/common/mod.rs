//! Helpers shared by the command-line tests.
#![allow(dead_code, unreachable_pub, clippy::expect_used)] // test helpers; not every suite uses all

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::Mutex;

/// Runs the `stereonav` binary built for these tests.
pub fn stereonav(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_stereonav"))
        .args(args)
        .output()
        .expect("stereonav runs")
}

/// A file path in this test's scratch directory: `target/tmp/stereonav-SUITE/TEST` (Cargo's
/// `CARGO_TARGET_TMPDIR`, which `cargo clean` removes), emptied the first time the test asks
/// for it in this process, so that a run neither reads an earlier run's files nor leaves a new
/// directory behind for each process (one per test under nextest) as `/tmp/NAME-PID` did.
pub fn scratch(suite: &str, name: &str) -> PathBuf {
    static EMPTIED: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());
    // libtest names each test's thread after the test; "main" when tests run on one thread.
    let test = std::thread::current()
        .name()
        .unwrap_or("main")
        .replace(|c: char| !c.is_ascii_alphanumeric() && c != '_', "-");
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("stereonav-{suite}"))
        .join(test);
    let mut emptied = EMPTIED
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    if !emptied.contains(&dir) {
        // Absent on a first run: nothing to remove.
        let _ = std::fs::remove_dir_all(&dir);
        emptied.push(dir.clone());
    }
    std::fs::create_dir_all(&dir).expect("scratch dir");
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
