//! The ten real EuRoC V1_01 stereo frames in ../shared/data (left and right), when present:
//! the detector equals the integer reference at the default registers and at other thresholds
//! and caps, whole-image and row by row with the board-sized stream. Skipped, with a message,
//! when the data is absent.
#![allow(clippy::print_stderr)] // says why the real-frame tests are skipped
#![cfg(feature = "alloc")] // the whole-image calls and the references need `alloc`

use crate::common;

use std::path::{Path, PathBuf};

use common::{assert_features_eq, assert_matches_reference, regs, run_stream};
use harris_core::{BoardStream, DEFAULT_MAX_FEATURES, DEFAULT_THRESHOLD, Registers};

/// `(threshold, max_features)`: the board's defaults, then lower and higher thresholds, a
/// negative one (every pixel a candidate), a cap that overflows, and nothing at all.
const SETTINGS: [(i32, usize); 6] = [
    (DEFAULT_THRESHOLD, DEFAULT_MAX_FEATURES),
    (0, 1023),
    (1 << 14, 1023),
    (1 << 22, 1023),
    (-1, 64),
    (i32::MAX, 1),
];

fn frames(side: &str) -> Option<Vec<PathBuf>> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data/euroc-v101-stereo")
        .join(side);
    let Ok(entries) = std::fs::read_dir(&dir) else {
        eprintln!("{} is absent: real-frame tests skipped", dir.display());
        return None;
    };
    let mut paths: Vec<PathBuf> = entries
        .filter_map(|e| Some(e.ok()?.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "png"))
        .collect();
    paths.sort();
    Some(paths)
}

fn check_frame(path: &Path) {
    let img = image::open(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .into_luma8();
    let (w, h) = (img.width() as usize, img.height() as usize);
    assert_eq!((w, h), (752, 480), "{}", path.display());
    let pixels = img.as_raw();
    for (threshold, max_features) in SETTINGS {
        let r = regs(w, h, threshold, max_features);
        let what = format!(
            "{} threshold {threshold} cap {max_features}",
            path.display()
        );
        let expected = assert_matches_reference(pixels, &r, &what);
        if (threshold, max_features) == (DEFAULT_THRESHOLD, DEFAULT_MAX_FEATURES) {
            assert_eq!(r, Registers::default());
            assert!(
                !expected.features.is_empty(),
                "{what}: a real frame has corners"
            );
            let mut stream = Box::new(BoardStream::new(r).unwrap_or_else(|e| panic!("{e}")));
            let (features, overflow) = run_stream(&mut *stream, pixels, &r);
            assert_features_eq(
                &features,
                &expected.features,
                &format!("{what}, BoardStream"),
            );
            assert_eq!(overflow, expected.overflow);
        }
        if threshold == -1 {
            assert!(
                expected.overflow,
                "{what}: a negative threshold overflows a cap of 64"
            );
        }
    }
}

fn check_side(side: &str) {
    let Some(paths) = frames(side) else { return };
    assert_eq!(paths.len(), 10, "{side}: ten frames");
    // One thread per frame: the reference is slow at opt-level 1.
    std::thread::scope(|s| {
        for path in &paths {
            s.spawn(move || check_frame(path));
        }
    });
}

#[test]
fn left_frames_equal_reference() {
    check_side("left");
}

#[test]
fn right_frames_equal_reference() {
    check_side("right");
}
