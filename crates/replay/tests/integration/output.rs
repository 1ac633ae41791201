//! The replay's outputs (vehicle-interfaces.md section 5) from a hand-made [`Replay`]:
//! `EST.mcap` read back with the `mcap` crate (channels, schemas, message counts, CRCs), every
//! message checked against its schema (field presence, JSON Schema validation, and Foxglove's
//! own schemas when `../shared` has them), `SUMMARY.json` against the contract, `TRAJ.csv`
//! read back, and errors for paths that cannot be written.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use mcap::records::Record;
use mcap::sans_io::{LinearReadEvent, LinearReader, LinearReaderOptions};
use nalgebra::{Matrix3, Quaternion, UnitQuaternion, Vector3};
use replay::{
    Association, CameraSample, Counts, Error, FrameEstimate, LandmarkEstimate, MapSnapshot,
    ParamEstimate, Phase, Replay, TruthErrors, summary_json, write_estimates, write_summary,
    write_trajectory,
};
use rig_model::Param;
use serde_json::Value;

const FOXGLOVE_SCHEMAS: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../../../shared/data/foxglove-jsonschema"
);

/// Topic, schema name, schema file in Foxglove's folder (for theirs).
const TOPICS: [(&str, &str, Option<&str>); 6] = [
    (
        "/est/pose",
        "foxglove.PoseInFrame",
        Some("PoseInFrame.json"),
    ),
    (
        "/est/trajectory",
        "foxglove.PosesInFrame",
        Some("PosesInFrame.json"),
    ),
    (
        "/est/landmarks",
        "foxglove.SceneUpdate",
        Some("SceneUpdate.json"),
    ),
    ("/est/camera", "stereonav.CameraEstimate", None),
    ("/est/frame", "stereonav.FrameInfo", None),
    ("/est/summary", "stereonav.Summary", None),
];

fn scratch(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("replay-output-{name}"));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn params(scale: f64) -> Vec<ParamEstimate> {
    Param::ALL
        .iter()
        .enumerate()
        .map(|(i, &param)| ParamEstimate {
            param,
            value: 1.0 + i as f64 * scale,
            // The last ones held fixed: sigma 0.
            sigma: if i < 7 { 0.01 * (i + 1) as f64 } else { 0.0 },
        })
        .collect()
}

/// A rotated, anisotropic covariance: `R diag(d) R^T`.
fn covariance(d: [f64; 3], yaw: f64, pitch: f64) -> [[f64; 3]; 3] {
    let r = UnitQuaternion::from_euler_angles(0.0, pitch, yaw).to_rotation_matrix();
    let c = r.matrix() * Matrix3::from_diagonal(&Vector3::from(d)) * r.matrix().transpose();
    core::array::from_fn(|i| core::array::from_fn(|j| c[(i, j)]))
}

fn landmark(id: u64, shift: f64) -> LandmarkEstimate {
    let k = id as f64;
    LandmarkEstimate {
        id,
        position: [k + shift, -0.5 * k, 5.0 + 0.01 * k],
        covariance: covariance([0.01 * (k + 1.0), 0.004, 0.0009], 0.3 * k, 0.1 * k),
        observations: 3 + id,
    }
}

/// 25 frames 0.1 s apart (10 in phase 1, 15 in phase 2), phase-1 camera solves and a sample
/// per phase-2 frame, a map each second, truth errors.
fn synthetic() -> Replay {
    let t0 = 1_000_000u64;
    let frames: Vec<FrameEstimate> = (0..25u64)
        .map(|k| {
            let t = k as f64 * 0.1;
            let phase = if k < 10 {
                Phase::Calibrating
            } else {
                Phase::Navigating
            };
            let observed: Vec<u64> = if k < 10 { vec![] } else { vec![1, 2, k % 3] };
            FrameEstimate {
                t_us: t0 + k * 100_000,
                phase,
                pose: [0.3 * t + 1.0 / 3.0, 0.01 * t * t, 0.05 * t - 0.1],
                pose_covariance: covariance([1e-4 * (t + 1.0), 2e-4, 1e-5], 0.2, 0.0),
                nis: observed
                    .iter()
                    .map(|&id| (id, 1.0 + 0.1 * id as f64))
                    .collect(),
                associations: Some(
                    observed
                        .iter()
                        .enumerate()
                        .map(|(i, &id)| Association {
                            id,
                            left: i,
                            right: i + 1,
                            accepted: true,
                        })
                        .collect(),
                ),
                observed,
                rejected: (k % 4) as u32,
                landmarks: if k < 10 { 0 } else { 3 },
            }
        })
        .collect();
    let mut camera = vec![
        CameraSample {
            t_us: t0 + 400_000,
            phase: Phase::Calibrating,
            params: params(0.1),
        },
        CameraSample {
            t_us: t0 + 900_000,
            phase: Phase::Calibrating,
            params: params(0.11),
        },
    ];
    camera.extend(
        frames
            .iter()
            .filter(|f| f.phase == Phase::Navigating)
            .map(|f| CameraSample {
                t_us: f.t_us,
                phase: Phase::Navigating,
                params: params(0.12),
            }),
    );
    let maps = vec![
        MapSnapshot {
            t_us: t0 + 1_000_000,
            landmarks: vec![landmark(0, 0.0), landmark(1, 0.0)],
        },
        MapSnapshot {
            t_us: t0 + 2_000_000,
            landmarks: vec![landmark(0, 0.01), landmark(1, 0.01), landmark(2, 0.0)],
        },
        MapSnapshot {
            t_us: t0 + 2_400_000,
            landmarks: vec![landmark(0, 0.02), landmark(2, 0.01), landmark(7, 0.0)],
        },
    ];
    Replay {
        landmarks: maps.last().unwrap().landmarks.clone(),
        final_camera: params(0.12),
        phase_switch_t_us: Some(t0 + 1_000_000),
        phase1_skipped: false,
        counts: Counts {
            frames: 25,
            corrupt: 1,
            lost: 2,
            bytes_skipped: 40,
            frames_out_of_order: 0,
            odometry: 250,
            stereo_matches: 75,
            tracks: 9,
            confirmed_tracks: 6,
            pairs: 3,
            landmark_pairs: 12,
            tracker_resets: 0,
            phase1_solves: 4,
            ..Counts::default()
        },
        truth: Some(TruthErrors {
            landmark_rms: 0.02,
            landmark_rms_aligned: 0.01,
            landmarks_matched: 3,
            landmarks_unmatched: 0,
            landmarks_duplicate: 0,
            lamps_missed: 1,
            match_radius: 0.1,
            ate_rms: 0.015,
            ate_max: 0.04,
            heading_rms: 0.002,
            camera: Param::ALL.iter().map(|&p| (p, 1e-3)).collect(),
            consistency: None,
        }),
        warnings: vec!["mount_yaw is held at its nominal value: test".to_string()],
        log_damage: None,
        odometry: Some(estimates_log::OdometryModel {
            stated: [0.02, 0.01, 0.0, 0.0],
            used: [0.2, 0.1],
            widened: Some(estimates_log::OdometryWidened {
                t_us: 9_000_000,
                span_s: 1.0,
                ratios: [100.0, 50.0],
                variance_factors: [100.0, 100.0],
                time_constants_s: [0.6, 0.0],
            }),
        }),
        frames,
        camera,
        maps,
    }
}

/// What `EST.mcap` holds, read back with every CRC checked.
#[derive(Debug, Default)]
struct Est {
    /// Schema id to (name, encoding, document).
    schemas: BTreeMap<u16, (String, String, Value)>,
    /// Channel id to (topic, schema id, message encoding).
    channels: BTreeMap<u16, (String, u16, String)>,
    /// (topic, log time, message) in file order.
    messages: Vec<(String, u64, Value)>,
    /// (compression, uncompressed CRC) of each chunk (only when read with `emit_chunks`).
    chunks: Vec<(String, u32)>,
    data_section_crc: Option<u32>,
    summary_crc: Option<u32>,
}

impl Est {
    fn messages_on(&self, topic: &str) -> Vec<&Value> {
        self.messages
            .iter()
            .filter(|(t, _, _)| t == topic)
            .map(|(_, _, m)| m)
            .collect()
    }

    fn schema_of(&self, topic: &str) -> &(String, String, Value) {
        let (_, schema_id, _) = self
            .channels
            .values()
            .find(|(t, _, _)| t == topic)
            .unwrap_or_else(|| panic!("no channel {topic}"));
        &self.schemas[schema_id]
    }
}

fn read_est(bytes: &[u8], emit_chunks: bool) -> Est {
    let options = LinearReaderOptions::default()
        .with_validate_chunk_crcs(true)
        .with_validate_data_section_crc(true)
        .with_validate_summary_section_crc(true)
        .with_emit_chunks(emit_chunks);
    let mut reader = LinearReader::new_with_options(options);
    let mut rest = bytes;
    let mut est = Est::default();
    let mut past_data_end = false;
    while let Some(event) = reader.next_event() {
        let record = match event.expect("a valid MCAP file with valid CRCs") {
            LinearReadEvent::ReadRequest(need) => {
                let n = need.min(rest.len());
                let (now, later) = rest.split_at(n);
                reader.insert(n).copy_from_slice(now);
                reader.notify_read(n);
                rest = later;
                continue;
            }
            LinearReadEvent::Record { opcode, data } => {
                mcap::parse_record(opcode, data).unwrap().into_owned()
            }
        };
        match record {
            Record::Schema { header, data } => {
                let document: Value = serde_json::from_slice(&data).unwrap();
                let entry = (header.name, header.encoding, document);
                if let Some(old) = est.schemas.insert(header.id, entry.clone()) {
                    assert_eq!(old, entry, "schema {} repeated differently", header.id);
                }
            }
            Record::Channel(c) => {
                let entry = (c.topic, c.schema_id, c.message_encoding);
                if let Some(old) = est.channels.insert(c.id, entry.clone()) {
                    assert_eq!(old, entry, "channel {} repeated differently", c.id);
                }
            }
            Record::Message { header, data } => {
                assert!(!past_data_end);
                let (topic, _, _) = &est.channels[&header.channel_id];
                let message: Value = serde_json::from_slice(&data)
                    .unwrap_or_else(|e| panic!("{topic}: not JSON: {e}"));
                assert_eq!(header.publish_time, header.log_time);
                est.messages.push((topic.clone(), header.log_time, message));
            }
            Record::Chunk { header, .. } => {
                est.chunks
                    .push((header.compression, header.uncompressed_crc));
            }
            Record::DataEnd(end) => {
                past_data_end = true;
                est.data_section_crc = Some(end.data_section_crc);
            }
            Record::Footer(footer) => est.summary_crc = Some(footer.summary_crc),
            _ => {}
        }
    }
    assert!(rest.is_empty(), "{} bytes after the footer", rest.len());
    est
}

/// Writes the three files of `replay` in a fresh folder; returns the folder.
fn write_all(name: &str, replay: &Replay) -> PathBuf {
    let dir = scratch(name);
    write_estimates(&dir.join("EST.mcap"), replay).unwrap();
    write_summary(&dir.join("SUMMARY.json"), replay).unwrap();
    write_trajectory(&dir.join("TRAJ.csv"), replay).unwrap();
    dir
}

/// The frames (index) at which `/est/trajectory` is written: the first frame with a finite
/// pose, then each at least a second after the last one written, and the last frame.
fn trajectory_frames(replay: &Replay) -> Vec<usize> {
    let mut out: Vec<usize> = Vec::new();
    let mut last_us: Option<u64> = None;
    let n = replay.frames.len();
    for (i, f) in replay.frames.iter().enumerate() {
        if !f.pose.iter().all(|v| v.is_finite()) {
            continue;
        }
        if last_us.is_none_or(|l| f.t_us >= l + 1_000_000) || i + 1 == n {
            out.push(i);
            last_us = Some(f.t_us);
        }
    }
    out
}

#[test]
fn est_mcap_reads_back_with_every_channel_and_valid_crcs() {
    let replay = synthetic();
    let dir = write_all("readback", &replay);
    for file in ["EST.mcap", "SUMMARY.json", "TRAJ.csv"] {
        assert!(dir.join(file).is_file(), "{file} missing");
    }
    let bytes = std::fs::read(dir.join("EST.mcap")).unwrap();
    let est = read_est(&bytes, false);

    // Channels and schemas: one each per topic, JSON messages, jsonschema schemas.
    assert_eq!(est.channels.len(), TOPICS.len());
    assert_eq!(est.schemas.len(), TOPICS.len());
    for (topic, schema_name, _) in TOPICS {
        let (name, encoding, document) = est.schema_of(topic);
        assert_eq!(name, schema_name, "{topic}");
        assert_eq!(encoding, "jsonschema", "{topic}");
        assert_eq!(document["title"], schema_name, "{topic}");
        let (_, _, message_encoding) = est.channels.values().find(|(t, _, _)| t == topic).unwrap();
        assert_eq!(message_encoding, "json", "{topic}");
    }

    // Message counts.
    let n = replay.frames.len();
    let counts: BTreeMap<&str, usize> = TOPICS
        .iter()
        .map(|(t, _, _)| (*t, est.messages_on(t).len()))
        .collect();
    assert_eq!(counts["/est/pose"], n);
    assert_eq!(counts["/est/frame"], n);
    assert_eq!(counts["/est/camera"], replay.camera.len());
    assert_eq!(counts["/est/landmarks"], replay.maps.len());
    assert_eq!(counts["/est/summary"], 1);
    assert_eq!(counts["/est/trajectory"], trajectory_frames(&replay).len());
    assert_eq!(trajectory_frames(&replay), [0, 10, 20, 24]);

    // Log time is t_us in ns, in data-time order; the summary is last.
    assert!(est.messages.windows(2).all(|w| w[0].1 <= w[1].1));
    for (topic, log_time, message) in &est.messages {
        if let Some(t_us) = message.get("t_us").and_then(Value::as_u64) {
            assert_eq!(*log_time, t_us * 1000, "{topic}");
        }
        if let Some(stamp) = message.get("timestamp") {
            let ns =
                stamp["sec"].as_u64().unwrap() * 1_000_000_000 + stamp["nsec"].as_u64().unwrap();
            assert_eq!(*log_time, ns, "{topic}");
        }
    }
    let (last_topic, last_time, summary) = est.messages.last().unwrap();
    assert_eq!(last_topic, "/est/summary");
    assert_eq!(*last_time, replay.frames.last().unwrap().t_us * 1000);
    assert_eq!(*summary, summary_json(&replay));

    // The pose messages carry the poses; theta is the rotation about z.
    for (frame, pose) in replay.frames.iter().zip(est.messages_on("/est/pose")) {
        assert_eq!(pose["frame_id"], "world");
        let p = &pose["pose"]["position"];
        assert_eq!(p["x"].as_f64().unwrap(), frame.pose[0]);
        assert_eq!(p["y"].as_f64().unwrap(), frame.pose[1]);
        assert_eq!(p["z"].as_f64().unwrap(), 0.0);
        let o = &pose["pose"]["orientation"];
        let q = UnitQuaternion::from_quaternion(Quaternion::new(
            o["w"].as_f64().unwrap(),
            o["x"].as_f64().unwrap(),
            o["y"].as_f64().unwrap(),
            o["z"].as_f64().unwrap(),
        ));
        let (roll, pitch, yaw) = q.euler_angles();
        assert!(roll.abs() < 1e-12 && pitch.abs() < 1e-12);
        assert!((yaw - frame.pose[2]).abs() < 1e-12);
    }
    // The last trajectory holds the whole path (it is shorter than the cap).
    let trajectories = est.messages_on("/est/trajectory");
    let path = trajectories.last().unwrap()["poses"].as_array().unwrap();
    assert_eq!(path.len(), n);
    for (frame, pose) in replay.frames.iter().zip(path) {
        assert_eq!(pose["position"]["x"].as_f64().unwrap(), frame.pose[0]);
    }
    assert_eq!(trajectories[1]["poses"].as_array().unwrap().len(), 11);

    // Camera and frame messages.
    for (sample, message) in replay.camera.iter().zip(est.messages_on("/est/camera")) {
        assert_eq!(message["phase"], sample.phase.name());
        for p in &sample.params {
            assert_eq!(
                message["params"][p.param.name()]["value"].as_f64().unwrap(),
                p.value
            );
            assert_eq!(
                message["params"][p.param.name()]["sigma"].as_f64().unwrap(),
                p.sigma
            );
        }
    }
    for (frame, message) in replay.frames.iter().zip(est.messages_on("/est/frame")) {
        assert_eq!(message["phase"], frame.phase.name());
        assert_eq!(
            message["observed"].as_array().unwrap().len(),
            frame.observed.len()
        );
        assert_eq!(message["nis"].as_array().unwrap().len(), frame.nis.len());
        assert_eq!(
            message["rejected"].as_u64().unwrap(),
            u64::from(frame.rejected)
        );
        assert_eq!(
            message["pose_covariance"][0][1].as_f64().unwrap(),
            frame.pose_covariance[0][1]
        );
    }

    // Landmarks: every previous entity deleted, then one entity per landmark.
    for (map, update) in replay.maps.iter().zip(est.messages_on("/est/landmarks")) {
        assert_eq!(update["deletions"][0]["type"], 1);
        let entities = update["entities"].as_array().unwrap();
        assert_eq!(entities.len(), map.landmarks.len());
        for (l, e) in map.landmarks.iter().zip(entities) {
            assert_eq!(e["id"], format!("landmark-{}", l.id));
            assert_eq!(e["frame_id"], "world");
            assert_eq!(e["spheres"].as_array().unwrap().len(), 2);
        }
    }

    // CRCs: chunks zstd with a CRC, data and summary sections with theirs (the reader above
    // checked them all).
    let with_chunks = read_est(&bytes, true);
    assert!(!with_chunks.chunks.is_empty());
    for (compression, crc) in &with_chunks.chunks {
        assert_eq!(compression, "zstd");
        assert_ne!(*crc, 0);
    }
    assert_ne!(est.data_section_crc, Some(0));
    assert!(est.data_section_crc.is_some());
    assert_ne!(est.summary_crc, Some(0));
    assert!(est.summary_crc.is_some());

    // The summary section's statistics agree.
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    let stats = summary.stats.unwrap();
    assert_eq!(stats.message_count, est.messages.len() as u64);
    assert_eq!(usize::from(stats.channel_count as u16), TOPICS.len());
    for (id, (topic, _, _)) in &est.channels {
        assert_eq!(
            stats.channel_message_counts.get(id).copied().unwrap_or(0),
            counts[topic.as_str()] as u64,
            "{topic}"
        );
    }
}

/// Every property `schema` declares is present in `value`, recursively (Foxglove's schemas
/// have no `required`). `null` is accepted where the schema allows it.
fn check_presence(schema: &Value, value: &Value, at: &str) {
    if value.is_null() {
        let allows_null = schema["type"] == "null"
            || schema["type"]
                .as_array()
                .is_some_and(|t| t.iter().any(|t| t == "null"))
            || schema["oneOf"]
                .as_array()
                .is_some_and(|o| o.iter().any(|s| s["type"] == "null"));
        assert!(allows_null, "{at}: null where the schema allows none");
        return;
    }
    if let Some(branches) = schema["oneOf"].as_array() {
        // Our nullable objects: the branch that is not `null`.
        for branch in branches.iter().filter(|b| b["type"] != "null") {
            if branch.get("properties").is_some() {
                check_presence(branch, value, at);
            }
        }
    }
    if let Some(properties) = schema["properties"].as_object() {
        let object = value
            .as_object()
            .unwrap_or_else(|| panic!("{at}: not an object: {value}"));
        for (key, sub) in properties {
            let field = object
                .get(key)
                .unwrap_or_else(|| panic!("{at}: field {key} missing"));
            check_presence(sub, field, &format!("{at}.{key}"));
        }
    }
    if let (Some(items), Some(array)) = (schema.get("items"), value.as_array()) {
        for (i, item) in array.iter().enumerate() {
            check_presence(items, item, &format!("{at}[{i}]"));
        }
    }
}

fn validator(schema: &Value, what: &str) -> jsonschema::Validator {
    jsonschema::validator_for(schema).unwrap_or_else(|e| panic!("{what}: not a usable schema: {e}"))
}

fn validate_all(validator: &jsonschema::Validator, messages: &[&Value], what: &str) {
    for (i, message) in messages.iter().enumerate() {
        let errors: Vec<String> = validator
            .iter_errors(message)
            .map(|e| format!("{} at {}", e, e.instance_path()))
            .collect();
        assert!(errors.is_empty(), "{what} message {i}: {errors:?}");
    }
}

#[test]
fn every_message_has_every_field_of_its_embedded_schema_and_validates() {
    let replay = synthetic();
    let dir = write_all("embedded-schemas", &replay);
    let est = read_est(&std::fs::read(dir.join("EST.mcap")).unwrap(), false);
    for (topic, _, _) in TOPICS {
        let (_, _, schema) = est.schema_of(topic);
        jsonschema::meta::validate(schema)
            .unwrap_or_else(|e| panic!("{topic}: the embedded schema is not JSON Schema: {e}"));
        let messages = est.messages_on(topic);
        assert!(!messages.is_empty(), "{topic}");
        for (i, m) in messages.iter().enumerate() {
            check_presence(schema, m, &format!("{topic}[{i}]"));
        }
        validate_all(&validator(schema, topic), &messages, topic);
    }
}

/// Every property path a schema declares (`a.b[].c`).
fn property_paths(schema: &Value, at: &str, out: &mut BTreeSet<String>) {
    if let Some(properties) = schema["properties"].as_object() {
        for (key, sub) in properties {
            let path = format!("{at}.{key}");
            out.insert(path.clone());
            property_paths(sub, &path, out);
        }
    }
    if let Some(items) = schema.get("items") {
        property_paths(items, &format!("{at}[]"), out);
    }
}

fn collect_refs(value: &Value, out: &mut Vec<String>) {
    match value {
        Value::Object(map) => {
            for (k, v) in map {
                if k == "$ref"
                    && let Some(r) = v.as_str()
                {
                    out.push(r.to_owned());
                }
                collect_refs(v, out);
            }
        }
        Value::Array(items) => items.iter().for_each(|v| collect_refs(v, out)),
        _ => {}
    }
}

#[test]
fn foxglove_messages_validate_against_foxglove_schemas() {
    let folder = Path::new(FOXGLOVE_SCHEMAS);
    if !folder.is_dir() {
        eprintln!(
            "skipped: {} is absent (Foxglove's JSON schemas)",
            folder.display()
        );
        return;
    }
    let replay = synthetic();
    let dir = write_all("foxglove-schemas", &replay);
    let est = read_est(&std::fs::read(dir.join("EST.mcap")).unwrap(), false);
    for (topic, schema_name, file) in TOPICS {
        let Some(file) = file else { continue };
        let text = std::fs::read_to_string(folder.join(file)).unwrap();
        let theirs: Value = serde_json::from_str(&text).unwrap();
        assert_eq!(theirs["title"], schema_name, "{file}");
        // Any $ref must resolve: building the validator resolves them (no remote or file
        // retrieval is compiled in, so only references inside the document can).
        let mut refs = Vec::new();
        collect_refs(&theirs, &mut refs);
        let validator = validator(&theirs, file);
        // (A reference that does not resolve fails that build.)
        let dangling = serde_json::json!({"$ref": "#/$defs/missing"});
        assert!(jsonschema::validator_for(&dangling).is_err());
        for r in &refs {
            assert!(r.starts_with('#'), "{file}: external $ref {r}");
        }
        let messages = est.messages_on(topic);
        validate_all(&validator, &messages, file);
        for (i, m) in messages.iter().enumerate() {
            check_presence(&theirs, m, &format!("{file}: {topic}[{i}]"));
        }
        // The schema written into EST.mcap declares the same fields as Foxglove's.
        let (_, _, ours) = est.schema_of(topic);
        let (mut a, mut b) = (BTreeSet::new(), BTreeSet::new());
        property_paths(ours, "", &mut a);
        property_paths(&theirs, "", &mut b);
        assert_eq!(a, b, "{topic}: fields differ from {file}");
    }
}

fn keys(value: &Value) -> BTreeSet<&str> {
    value
        .as_object()
        .unwrap_or_else(|| panic!("not an object: {value}"))
        .keys()
        .map(String::as_str)
        .collect()
}

fn set<'a>(names: &[&'a str]) -> BTreeSet<&'a str> {
    names.iter().copied().collect()
}

#[test]
fn summary_has_the_contract_keys_and_types() {
    let replay = synthetic();
    let dir = write_all("summary", &replay);
    let text = std::fs::read_to_string(dir.join("SUMMARY.json")).unwrap();
    assert!(text.ends_with('\n'));
    let s: Value = serde_json::from_str(&text).unwrap();
    assert_eq!(s, summary_json(&replay));

    assert_eq!(
        keys(&s),
        set(&[
            "frames",
            "corrupt",
            "lost",
            "phase_switch_t_us",
            "pose",
            "camera",
            "vehicle",
            "landmarks",
            "phase1_skipped",
            "warnings",
            "counts",
            "truth",
            "log_damage",
            "odometry",
        ])
    );
    assert_eq!(s["log_damage"], Value::Null);
    assert_eq!(s["frames"].as_u64(), Some(25));
    assert_eq!(s["corrupt"].as_u64(), Some(1));
    assert_eq!(s["lost"].as_u64(), Some(2));
    assert_eq!(s["phase_switch_t_us"].as_u64(), Some(2_000_000));
    assert_eq!(s["phase1_skipped"], false);
    assert_eq!(s["warnings"][0], replay.warnings[0]);

    let last = replay.frames.last().unwrap();
    assert_eq!(keys(&s["pose"]), set(&["t_us", "x", "y", "theta"]));
    assert_eq!(s["pose"]["t_us"].as_u64(), Some(last.t_us));
    assert_eq!(s["pose"]["x"].as_f64(), Some(last.pose[0]));
    assert_eq!(s["pose"]["y"].as_f64(), Some(last.pose[1]));
    assert_eq!(s["pose"]["theta"].as_f64(), Some(last.pose[2]));

    // C under "camera", V under "vehicle" (vehicle-interfaces.md section 5).
    let names: Vec<&str> = Param::CAMERA.iter().map(|p| p.name()).collect();
    assert_eq!(keys(&s["camera"]), set(&names));
    let vehicle_names: Vec<&str> = Param::VEHICLE.iter().map(|p| p.name()).collect();
    assert_eq!(keys(&s["vehicle"]), set(&vehicle_names));
    for p in &replay.final_camera {
        let table = if p.param.is_vehicle() {
            "vehicle"
        } else {
            "camera"
        };
        let c = &s[table][p.param.name()];
        assert_eq!(keys(c), set(&["value", "sigma"]));
        assert_eq!(c["value"].as_f64(), Some(p.value));
        assert_eq!(c["sigma"].as_f64(), Some(p.sigma));
    }

    let landmarks = s["landmarks"].as_array().unwrap();
    assert_eq!(landmarks.len(), replay.landmarks.len());
    for (l, j) in replay.landmarks.iter().zip(landmarks) {
        assert_eq!(
            keys(j),
            set(&["id", "x", "y", "z", "sigma", "observations"])
        );
        assert_eq!(j["id"].as_u64(), Some(l.id));
        assert_eq!(j["x"].as_f64(), Some(l.position[0]));
        assert_eq!(j["y"].as_f64(), Some(l.position[1]));
        assert_eq!(j["z"].as_f64(), Some(l.position[2]));
        let sigma: Vec<f64> = j["sigma"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        assert_eq!(sigma, l.sigma());
        assert_eq!(j["observations"].as_u64(), Some(l.observations));
    }

    assert_eq!(
        keys(&s["counts"]),
        set(&[
            "frames_processed",
            "bytes_skipped",
            "frames_out_of_order",
            "odometry",
            "stereo_matches",
            "tracks",
            "confirmed_tracks",
            "pairs",
            "landmark_pairs",
            "tracker_resets",
            "phase1_solves",
            "log_spans_lost",
            "log_bytes_lost",
            "log_chunks_lost",
            "log_time_lost_ms",
            "landmarks_merged",
            "features_outside_field",
            "loops_closed",
            "loops_refused",
            "lamps_held_mapped",
            "images_left",
            "images_right",
            "images_unpaired",
            "images_wrong_size",
            "images_unsupported",
            "images_undecodable",
            "image_frames_dropped",
        ])
    );
    assert!(s["counts"].as_object().unwrap().values().all(Value::is_u64));
    assert_eq!(s["counts"]["odometry"].as_u64(), Some(250));
    assert_eq!(s["counts"]["frames_processed"].as_u64(), Some(25));

    let truth = &s["truth"];
    assert_eq!(
        keys(truth),
        set(&[
            "landmark_rms_m",
            "landmark_rms_aligned_m",
            "landmarks_matched",
            "landmarks_unmatched",
            "landmarks_duplicate",
            "lamps_missed",
            "match_radius_m",
            "ate_rms_m",
            "ate_max_m",
            "heading_rms_rad",
            "camera",
            "vehicle",
            "consistency",
        ])
    );
    assert!(truth["consistency"].is_null());
    for k in [
        "landmark_rms_m",
        "landmark_rms_aligned_m",
        "match_radius_m",
        "ate_rms_m",
        "ate_max_m",
        "heading_rms_rad",
    ] {
        assert!(truth[k].is_f64(), "{k}");
    }
    for k in [
        "landmarks_matched",
        "landmarks_unmatched",
        "landmarks_duplicate",
        "lamps_missed",
    ] {
        assert!(truth[k].is_u64(), "{k}");
    }
    assert_eq!(truth["ate_rms_m"].as_f64(), Some(0.015));
    assert_eq!(keys(&truth["camera"]), set(&names));
    assert_eq!(keys(&truth["vehicle"]), set(&vehicle_names));
    assert_eq!(truth["camera"]["f"].as_f64(), Some(1e-3));

    // Without truth, phase switch or frames: nulls.
    let mut bare = replay.clone();
    bare.truth = None;
    bare.phase_switch_t_us = None;
    bare.frames.clear();
    let s = summary_json(&bare);
    assert!(s["truth"].is_null());
    assert!(s["phase_switch_t_us"].is_null());
    assert!(s["pose"].is_null());
}

#[test]
fn trajectory_csv_reads_back_to_the_same_numbers() {
    let replay = synthetic();
    let dir = write_all("csv", &replay);
    let text = std::fs::read_to_string(dir.join("TRAJ.csv")).unwrap();
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some("t_us,x,y,theta"));
    let rows: Vec<&str> = lines.collect();
    assert_eq!(rows.len(), replay.frames.len());
    for (frame, row) in replay.frames.iter().zip(rows) {
        let cells: Vec<&str> = row.split(',').collect();
        assert_eq!(cells.len(), 4, "{row}");
        assert_eq!(cells[0].parse::<u64>().unwrap(), frame.t_us);
        for (cell, value) in cells[1..].iter().zip(frame.pose) {
            assert_eq!(
                cell.parse::<f64>().unwrap().to_bits(),
                value.to_bits(),
                "{row}"
            );
        }
    }
}

#[test]
fn ellipsoid_is_the_three_sigma_ellipsoid_of_the_covariance() {
    let mut replay = synthetic();
    let l = LandmarkEstimate {
        id: 42,
        position: [1.0, 2.0, 5.0],
        covariance: covariance([0.04, 0.01, 0.0025], 0.7, -0.4),
        observations: 9,
    };
    replay.maps = vec![MapSnapshot {
        t_us: 2_000_000,
        landmarks: vec![l],
    }];
    let dir = write_all("ellipsoid", &replay);
    let est = read_est(&std::fs::read(dir.join("EST.mcap")).unwrap(), false);
    let update = est.messages_on("/est/landmarks")[0];
    let spheres = update["entities"][0]["spheres"].as_array().unwrap();
    let marker = &spheres[0];
    assert_eq!(marker["pose"]["position"]["z"].as_f64(), Some(5.0));
    assert!(marker["color"]["a"].as_f64().unwrap() >= 1.0);
    let ellipsoid = &spheres[1];
    assert!(ellipsoid["color"]["a"].as_f64().unwrap() < 1.0);
    let o = &ellipsoid["pose"]["orientation"];
    let q = UnitQuaternion::from_quaternion(Quaternion::new(
        o["w"].as_f64().unwrap(),
        o["x"].as_f64().unwrap(),
        o["y"].as_f64().unwrap(),
        o["z"].as_f64().unwrap(),
    ));
    let size = &ellipsoid["size"];
    // Diameter 2 * 3 sigma along each axis: variance (d / 6)^2.
    let var = |d: &Value| (d.as_f64().unwrap() / 6.0).powi(2);
    let d = Vector3::new(var(&size["x"]), var(&size["y"]), var(&size["z"]));
    let r = q.to_rotation_matrix();
    let rebuilt = r.matrix() * Matrix3::from_diagonal(&d) * r.matrix().transpose();
    let given = Matrix3::from_row_iterator(l.covariance.iter().flatten().copied());
    assert!((rebuilt - given).norm() < 1e-12, "{rebuilt} vs {given}");
}

#[test]
fn long_trajectories_are_thinned_and_end_at_the_last_pose() {
    let mut replay = synthetic();
    let n = 5000u64;
    replay.frames = (0..n)
        .map(|k| FrameEstimate {
            t_us: 10_000 * k,
            phase: Phase::Navigating,
            pose: [k as f64 * 0.01, 0.0, 0.0],
            pose_covariance: [[0.0; 3]; 3],
            observed: vec![],
            nis: vec![],
            rejected: 0,
            landmarks: 0,
            associations: Some(vec![]),
        })
        .collect();
    let dir = write_all("long", &replay);
    let est = read_est(&std::fs::read(dir.join("EST.mcap")).unwrap(), false);
    let trajectories = est.messages_on("/est/trajectory");
    assert_eq!(trajectories.len(), trajectory_frames(&replay).len());
    for t in &trajectories {
        let poses = t["poses"].as_array().unwrap();
        assert!(poses.len() <= 1001, "{}", poses.len());
        assert_eq!(poses[0]["position"]["x"].as_f64(), Some(0.0));
    }
    let last = trajectories.last().unwrap()["poses"].as_array().unwrap();
    assert!(last.len() > 500);
    assert_eq!(
        last.last().unwrap()["position"]["x"].as_f64(),
        Some((n - 1) as f64 * 0.01)
    );
    // In time order along the path.
    let xs: Vec<f64> = last
        .iter()
        .map(|p| p["position"]["x"].as_f64().unwrap())
        .collect();
    assert!(xs.windows(2).all(|w| w[0] < w[1]));
}

#[test]
fn non_finite_numbers_give_valid_json() {
    let mut replay = synthetic();
    replay.frames[3].pose[0] = f64::NAN;
    replay.frames[4].pose_covariance[1][1] = f64::INFINITY;
    replay.frames[12].nis[0].1 = f64::NAN;
    replay.camera[0].params[0].sigma = f64::NAN;
    replay.final_camera[1].value = f64::NAN;
    replay.landmarks[0].covariance[0][0] = f64::NAN;
    replay.maps[0].landmarks[0].covariance[2][1] = f64::NAN;
    replay.maps[1].landmarks[0].position[2] = f64::INFINITY;
    let dir = write_all("non-finite", &replay);
    let est = read_est(&std::fs::read(dir.join("EST.mcap")).unwrap(), false);

    assert_eq!(est.messages_on("/est/pose").len(), replay.frames.len() - 1);
    assert_eq!(est.messages_on("/est/frame").len(), replay.frames.len());
    assert!(est.messages_on("/est/frame")[3]["pose"]["x"].is_null());
    let maps = est.messages_on("/est/landmarks");
    // No ellipsoid for a covariance with NaN; no entity for a position that is not finite.
    assert_eq!(
        maps[0]["entities"][0]["spheres"].as_array().unwrap().len(),
        1
    );
    assert_eq!(maps[1]["entities"].as_array().unwrap().len(), 2);
    for (topic, _, _) in TOPICS {
        let (_, _, schema) = est.schema_of(topic);
        validate_all(&validator(schema, topic), &est.messages_on(topic), topic);
    }
    let folder = Path::new(FOXGLOVE_SCHEMAS);
    if folder.is_dir() {
        for (topic, _, file) in TOPICS {
            let Some(file) = file else { continue };
            let text = std::fs::read_to_string(folder.join(file)).unwrap();
            let theirs: Value = serde_json::from_str(&text).unwrap();
            validate_all(&validator(&theirs, file), &est.messages_on(topic), file);
        }
    }

    let s: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("SUMMARY.json")).unwrap()).unwrap();
    assert!(s["camera"]["cx"]["value"].is_null());
    assert!(s["landmarks"][0]["sigma"][0].is_null());

    let text = std::fs::read_to_string(dir.join("TRAJ.csv")).unwrap();
    let row = text.lines().nth(4).unwrap();
    assert!(
        row.split(',')
            .nth(1)
            .unwrap()
            .parse::<f64>()
            .unwrap()
            .is_nan()
    );
}

#[test]
fn an_empty_replay_writes_valid_files() {
    let replay = Replay {
        frames: vec![],
        camera: vec![],
        maps: vec![],
        landmarks: vec![],
        final_camera: params(0.0),
        phase_switch_t_us: None,
        phase1_skipped: true,
        counts: Counts::default(),
        truth: None,
        warnings: vec![],
        log_damage: None,
        odometry: None,
    };
    let dir = write_all("empty", &replay);
    let est = read_est(&std::fs::read(dir.join("EST.mcap")).unwrap(), false);
    assert_eq!(est.channels.len(), TOPICS.len());
    assert_eq!(est.messages.len(), 1);
    assert_eq!(est.messages[0].1, 0);
    assert_eq!(
        std::fs::read_to_string(dir.join("TRAJ.csv")).unwrap(),
        "t_us,x,y,theta\n"
    );
    let s: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("SUMMARY.json")).unwrap()).unwrap();
    assert!(s["pose"].is_null());
    assert_eq!(s["phase1_skipped"], true);
}

#[test]
fn a_path_in_a_missing_folder_is_an_error_naming_it() {
    let replay = synthetic();
    let missing = scratch("missing").join("no-such-folder");
    type Writer = fn(&Path, &Replay) -> Result<(), Error>;
    let writers: [(&str, &str, Writer); 3] = [
        ("EST.mcap", "out.mcap", write_estimates),
        ("SUMMARY.json", "sum.json", write_summary),
        ("TRAJ.csv", "traj.csv", write_trajectory),
    ];
    for (what, name, write) in writers {
        let path = missing.join(name);
        let err = write(&path, &replay).unwrap_err();
        assert!(matches!(err, Error::Output { .. }), "{err:?}");
        let message = err.to_string();
        assert!(
            message.starts_with(&format!("cannot write {what}: ")),
            "{message}"
        );
        assert!(message.contains(&path.display().to_string()), "{message}");
        assert!(!message.contains('\n'), "{message}");
        assert!(!path.exists());
    }
}

#[test]
fn a_time_past_the_foxglove_range_is_an_error() {
    let mut replay = synthetic();
    replay.frames.last_mut().unwrap().t_us = u64::MAX / 1000;
    let path = scratch("late").join("EST.mcap");
    let _ = std::fs::remove_file(&path);
    let err = write_estimates(&path, &replay).unwrap_err();
    assert!(matches!(err, Error::TimeOutOfRange { .. }), "{err:?}");
    let message = err.to_string();
    assert!(message.contains(&path.display().to_string()), "{message}");
    assert!(message.contains("/est/frame"), "{message}");
    assert!(!path.exists(), "no file is started");
}
