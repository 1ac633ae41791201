//! Reading `EST.mcap` back (`replay::read_estimates`, the estimates-log crate's reader): a
//! replay comes back from its estimates file.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::{Path, PathBuf};

use replay::{EstimatesError, Replay, read_estimates};

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/logs")
        .join(name)
}

/// A file under Cargo's `target/tmp` (as `streaming.rs`'s): each test uses its own names, a
/// rerun overwrites them, and `cargo clean` removes them.
fn scratch(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("replay-estimates-reader");
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

fn close(a: &[[f64; 3]; 3], b: &[[f64; 3]; 3]) -> bool {
    let scale = a.iter().flatten().fold(0.0_f64, |m, v| m.max(v.abs()));
    a.iter()
        .flatten()
        .zip(b.iter().flatten())
        .all(|(x, y)| (x - y).abs() <= 1e-9 * scale.max(1e-300))
}

fn assert_round_trip(original: &Replay, back: &Replay) {
    assert_eq!(back.frames, original.frames);
    assert_eq!(back.camera, original.camera);
    assert_eq!(back.final_camera, original.final_camera);
    assert_eq!(back.phase_switch_t_us, original.phase_switch_t_us);
    assert_eq!(back.phase1_skipped, original.phase1_skipped);
    assert_eq!(back.counts, original.counts);
    assert_eq!(back.truth, original.truth);
    assert_eq!(back.warnings, original.warnings);
    assert_eq!(back.maps.len(), original.maps.len());
    for (a, b) in original.maps.iter().zip(&back.maps) {
        assert_eq!(a.t_us, b.t_us);
        assert_eq!(a.landmarks.len(), b.landmarks.len());
        for (la, lb) in a.landmarks.iter().zip(&b.landmarks) {
            assert_eq!(
                (la.id, la.position, la.observations),
                (lb.id, lb.position, lb.observations)
            );
            assert!(close(&la.covariance, &lb.covariance), "{la:?} {lb:?}");
        }
    }
    assert_eq!(back.landmarks.len(), original.landmarks.len());
    for (la, lb) in original.landmarks.iter().zip(&back.landmarks) {
        assert_eq!((la.id, la.position), (lb.id, lb.position));
        assert!(close(&la.covariance, &lb.covariance));
    }
}

#[test]
fn a_replay_comes_back_from_its_estimates_file() {
    let settings = replay::NavSettings {
        skip_phase1: true,
        ..replay::NavSettings::default()
    };
    let original = replay::replay_log(
        fixture("paper-experiment.mcap"),
        None,
        &settings,
        &mut |_, _| {},
    )
    .unwrap();
    let est = scratch("pe.mcap");
    replay::write_estimates(&est, &original).unwrap();
    let back = read_estimates(&est).unwrap();
    assert_round_trip(&original, &back);
}

#[test]
fn the_phase_switch_and_both_phases_come_back() {
    let original = replay::replay_log(
        fixture("paper-calibration.mcap"),
        None,
        &replay::NavSettings::default(),
        &mut |_, _| {},
    )
    .unwrap();
    assert!(original.phase_switch_t_us.is_some());
    let est = scratch("pc.mcap");
    replay::write_estimates(&est, &original).unwrap();
    assert_round_trip(&original, &read_estimates(&est).unwrap());
}

#[test]
fn bad_files_are_one_line_errors() {
    let missing = read_estimates(scratch("missing.mcap")).unwrap_err();
    assert!(matches!(missing, EstimatesError::Io { .. }), "{missing}");
    let text = scratch("text.mcap");
    std::fs::write(&text, "not mcap at all").unwrap();
    let e = read_estimates(&text).unwrap_err();
    assert!(e.to_string().contains("is not an MCAP file"), "{e}");
    // A vehicle log is MCAP without /est/frame.
    let e = read_estimates(fixture("paper-experiment.mcap")).unwrap_err();
    assert!(e.to_string().contains("/fpga/features"), "{e}");
    assert!(matches!(e, EstimatesError::NotEstimates { .. }));
    for e in [missing, e] {
        assert_eq!(e.to_string().lines().count(), 1);
    }
}

#[test]
fn a_file_cut_short_is_read_as_far_as_it_goes() {
    let settings = replay::NavSettings {
        skip_phase1: true,
        ..replay::NavSettings::default()
    };
    let original = replay::replay_log(
        fixture("paper-experiment.mcap"),
        None,
        &settings,
        &mut |_, _| {},
    )
    .unwrap();
    let est = scratch("cut-src.mcap");
    replay::write_estimates(&est, &original).unwrap();
    let bytes = std::fs::read(&est).unwrap();
    let cut = scratch("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    let back = read_estimates(&cut).unwrap();
    assert!(!back.frames.is_empty() && back.frames.len() < original.frames.len());
    assert!(
        back.warnings.iter().any(|w| w.contains("ends early")),
        "{:?}",
        back.warnings
    );
    assert_eq!(back.frames[..], original.frames[..back.frames.len()]);
}
