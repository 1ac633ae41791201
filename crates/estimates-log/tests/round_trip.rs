//! `EST.mcap` written and read back: the schema records are the data files, the channels come
//! in [`Topic::ALL`] order, and a replay comes back equal (covariances to rounding: they
//! travel as ellipsoids).
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::{Path, PathBuf};

use estimates_log::{
    Association, CameraSample, Consistency, Counts, EstimatesWriter, FrameEstimate,
    LandmarkEstimate, MapSnapshot, ParamEstimate, Phase, ReadError, Replay, Topic, TruthErrors,
    read_estimates, summary_json, topics, write_estimates,
};
use rig_model::camera::Param;

/// A file under Cargo's `target/tmp`: each test of this file uses its own names, a
/// rerun overwrites them, and `cargo clean` removes them.
fn scratch(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("estimates-log");
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

fn params(t: f64) -> Vec<ParamEstimate> {
    Param::ALL
        .iter()
        .enumerate()
        .map(|(i, &param)| ParamEstimate {
            param,
            value: 1.0 + i as f64 + t,
            sigma: 0.01 * i as f64,
        })
        .collect()
}

fn landmark(id: u64, t: f64) -> LandmarkEstimate {
    let (a, b) = (1e-4 * (1.0 + t), 2e-5);
    LandmarkEstimate {
        id,
        position: [id as f64 + 0.25, -0.5 * t, 3.0],
        covariance: [[a, b, 0.0], [b, 2.0 * a, -b], [0.0, -b, 3.0 * a]],
        observations: 7 * id,
    }
}

/// Two frames of phase 1, three of phase 2 (one with a NaN in its covariance), camera samples
/// and maps, counts, truth with consistency, warnings.
fn synthetic() -> Replay {
    let frames: Vec<FrameEstimate> = (0..5u64)
        .map(|i| {
            let t = i as f64;
            let mut pose_covariance = [[1e-6 * (1.0 + t), 0.0, 0.0], [0.0, 2e-6, 0.0], [0.0; 3]];
            if i == 3 {
                pose_covariance[2][2] = f64::NAN;
            }
            FrameEstimate {
                t_us: 1_000_000 + 50_000 * i,
                phase: if i < 2 {
                    Phase::Calibrating
                } else {
                    Phase::Navigating
                },
                pose: [0.1 * t, -0.01 * t, 0.002 * t],
                pose_covariance,
                observed: (0..i).collect(),
                nis: (0..i).map(|id| (id, 0.5 + id as f64)).collect(),
                rejected: u32::try_from(i % 2).unwrap(),
                landmarks: usize::try_from(i).unwrap(),
                // Frame 0 as a file written before the associations were recorded.
                associations: (i > 0).then(|| {
                    (0..i)
                        .map(|id| Association {
                            id,
                            left: usize::try_from(2 * id).unwrap(),
                            right: usize::try_from(2 * id + 1).unwrap(),
                            accepted: id + 1 < i || i % 2 == 0,
                        })
                        .collect()
                }),
            }
        })
        .collect();
    let camera: Vec<CameraSample> = frames
        .iter()
        .enumerate()
        .map(|(i, f)| CameraSample {
            t_us: f.t_us,
            phase: f.phase,
            params: params(i as f64),
        })
        .collect();
    let maps: Vec<MapSnapshot> = frames[2..]
        .iter()
        .enumerate()
        .map(|(i, f)| MapSnapshot {
            t_us: f.t_us,
            landmarks: (0..=i as u64).map(|id| landmark(id, i as f64)).collect(),
        })
        .collect();
    let truth = TruthErrors {
        landmark_rms: 0.001,
        landmark_rms_aligned: 0.0008,
        landmarks_matched: 3,
        landmarks_unmatched: 0,
        landmarks_duplicate: 0,
        lamps_missed: 1,
        match_radius: 0.1,
        ate_rms: 0.002,
        ate_max: 0.004,
        heading_rms: 0.0005,
        camera: Param::ALL.iter().map(|&p| (p, 1e-5)).collect(),
        consistency: Some(Consistency {
            pose_nees: 2.9,
            pose_frames: 3,
            final_pose_nees: 3.1,
            state_nees: 12.5,
            state_dof: 14,
        }),
    };
    Replay {
        landmarks: maps.last().unwrap().landmarks.clone(),
        final_camera: params(4.0),
        phase_switch_t_us: Some(frames[2].t_us),
        phase1_skipped: false,
        counts: Counts {
            frames: 5,
            corrupt: 1,
            odometry: 100,
            pairs: 2,
            phase1_solves: 1,
            ..Counts::default()
        },
        truth: Some(truth),
        warnings: vec!["a warning".to_string()],
        log_damage: None,
        odometry: Some(estimates_log::OdometryModel {
            stated: [0.02, 0.01, 0.0, 0.6],
            used: [0.23, 0.1],
            widened: Some(estimates_log::OdometryWidened {
                t_us: 9_062_000,
                span_s: 1.0,
                ratios: [135.1, 23.6],
                variance_factors: [135.1, 100.0],
                time_constants_s: [0.0, 0.55],
            }),
        }),
        frames,
        camera,
        maps,
    }
}

fn close(a: &[[f64; 3]; 3], b: &[[f64; 3]; 3]) -> bool {
    a.iter()
        .flatten()
        .zip(b.iter().flatten())
        .all(|(x, y)| (x - y).abs() <= 1e-15)
}

#[test]
fn a_replay_written_comes_back_equal() {
    let original = synthetic();
    let path = scratch("round-trip.mcap");
    write_estimates(&path, &original).unwrap();
    let back = read_estimates(&path).unwrap();
    assert_eq!(back.frames.len(), original.frames.len());
    for (a, b) in original.frames.iter().zip(&back.frames) {
        // NaN != NaN: compare the covariance apart.
        let (mut a, mut b) = (a.clone(), b.clone());
        assert_eq!(
            a.pose_covariance[2][2].is_nan(),
            b.pose_covariance[2][2].is_nan()
        );
        a.pose_covariance[2][2] = 0.0;
        b.pose_covariance[2][2] = 0.0;
        assert_eq!(a, b);
    }
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
}

#[test]
fn the_writer_fed_by_hand_equals_write_estimates() {
    let replay = synthetic();
    let whole = scratch("whole.mcap");
    write_estimates(&whole, &replay).unwrap();
    let by_hand = scratch("by-hand.mcap");
    let mut w = EstimatesWriter::create(&by_hand).unwrap();
    let mut camera = replay.camera.iter().peekable();
    let mut maps = replay.maps.iter().peekable();
    for frame in &replay.frames {
        w.frame(frame).unwrap();
        while let Some(c) = camera.next_if(|c| c.t_us <= frame.t_us) {
            w.camera(c).unwrap();
        }
        while let Some(m) = maps.next_if(|m| m.t_us <= frame.t_us) {
            w.map(m).unwrap();
        }
    }
    w.finish(&summary_json(&replay)).unwrap();
    assert!(std::fs::read(&whole).unwrap() == std::fs::read(&by_hand).unwrap());
}

#[test]
fn the_schemas_written_are_the_data_files_in_channel_order() {
    let path = scratch("schemas.mcap");
    write_estimates(&path, &synthetic()).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    let summary = mcap::read::Summary::read(&bytes).unwrap().unwrap();
    let mut channels: Vec<_> = summary.channels.values().collect();
    channels.sort_by_key(|c| c.id);
    assert_eq!(channels.len(), Topic::ALL.len());
    for (channel, topic) in channels.iter().zip(Topic::ALL) {
        assert_eq!(channel.topic, topic.name());
        assert_eq!(channel.message_encoding, topics::JSON_ENCODING);
        let schema = channel.schema.as_ref().unwrap();
        assert_eq!(schema.name, topic.schema_name());
        assert_eq!(schema.encoding, topics::JSONSCHEMA_ENCODING);
        assert!(
            schema.data[..] == topic.schema_bytes().unwrap()[..],
            "{}",
            schema.name
        );
        // The data file, without its layout.
        let file: serde_json::Value = serde_json::from_str(topic.schema()).unwrap();
        let written: serde_json::Value = serde_json::from_slice(&schema.data).unwrap();
        assert_eq!(file, written);
    }
}

#[test]
fn a_time_past_the_foxglove_range_is_an_error_before_the_file() {
    let mut replay = synthetic();
    replay.frames.last_mut().unwrap().t_us = topics::MAX_T_US + 1;
    let path = scratch("late.mcap");
    let _ = std::fs::remove_file(&path);
    let err = write_estimates(&path, &replay).unwrap_err();
    assert!(
        err.to_string().contains(topics::FRAME),
        "{err}: names the topic"
    );
    assert!(!path.exists());
}

#[test]
fn a_file_that_is_not_an_estimates_file_is_a_read_error() {
    let path = scratch("text.mcap");
    std::fs::write(&path, "not mcap").unwrap();
    assert!(matches!(
        read_estimates(&path),
        Err(ReadError::NotMcap { .. })
    ));
}
