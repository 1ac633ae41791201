//! `stereonav localize` end to end (vehicle-interfaces.md section 5): a map saved by the replay
//! of a committed log, the log localised on it (the pose unknown at the start), the summary's
//! and trajectory's contract, a log of another writer, and one-line errors on bad maps.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failure is the test failing

use crate::common;

use std::path::PathBuf;
use std::process::Output;

use common::{PARAMETERS, assert_one_line_error, fixture, s, stereonav};
use serde_json::Value;

fn scratch(name: &str) -> PathBuf {
    common::scratch("localize-cli", name)
}

fn ok(out: &Output) -> String {
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout.clone()).unwrap()
}

/// The map of `log` (a committed fixture), saved by `stereonav replay --save-map`.
fn map_of(log: &str, name: &str) -> PathBuf {
    let map = scratch(name);
    ok(&stereonav(&[
        "replay",
        s(&fixture(log)),
        "--save-map",
        s(&map),
    ]));
    map
}

/// The square drive localised on its own map: it fixes its position early, stays localised,
/// and the summary and trajectory hold the contract's keys and columns.
#[test]
fn a_log_localises_on_the_map_its_replay_saved() {
    let map = map_of("paper-square.mcap", "sq.map");
    let (summary, traj) = (scratch("sq-loc.json"), scratch("sq-loc.csv"));
    let text = ok(&stereonav(&[
        "localize",
        s(&fixture("paper-square.mcap")),
        "--map",
        s(&map),
        "--summary",
        s(&summary),
        "--trajectory",
        s(&traj),
    ]));
    assert!(text.contains("localised in"), "{text}");
    let doc: Value = serde_json::from_str(&std::fs::read_to_string(&summary).unwrap()).unwrap();
    for key in ["frames", "corrupt", "lost"] {
        assert!(doc[key].is_u64(), "{key}");
    }
    assert!(doc["phase_switch_t_us"].is_null());
    for key in ["t_us", "x", "y", "theta"] {
        assert!(!doc["pose"][key].is_null(), "pose.{key}");
    }
    for p in PARAMETERS {
        assert!(doc["camera"][p]["value"].is_f64(), "camera.{p}");
    }
    for p in [
        "odom_scale",
        "odom_yaw_scale",
        "odom_yaw_bias",
        "time_offset",
    ] {
        assert!(doc["vehicle"][p]["sigma"].is_f64(), "vehicle.{p}");
    }
    assert_eq!(doc["landmarks"].as_array().unwrap().len(), 5);
    let fixes = doc["localized_t_us"].as_array().unwrap();
    assert!(!fixes.is_empty(), "{doc}");
    assert!(doc["lamps_missing"].as_array().unwrap().is_empty(), "{doc}");
    let truth = &doc["truth"];
    let frames = truth["frames"].as_u64().unwrap();
    let localized = truth["localized_frames"].as_u64().unwrap();
    assert!(localized * 100 >= frames * 90, "{localized} of {frames}");
    assert!(truth["ate_rms_m"].as_f64().unwrap() < 0.02, "{truth}");
    assert_eq!(truth["wrong_frames"].as_u64(), Some(0));
    // The first fix within 3 s of the first frame.
    let csv = std::fs::read_to_string(&traj).unwrap();
    let mut lines = csv.lines();
    assert_eq!(lines.next(), Some("t_us,x,y,theta,localized"));
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    assert_eq!(rows.len() as u64, doc["frames_processed"].as_u64().unwrap());
    let t0: u64 = rows[0][0].parse().unwrap();
    assert!(fixes[0].as_u64().unwrap() - t0 <= 3_000_000, "{fixes:?}");
    for r in &rows {
        assert_eq!(r.len(), 5);
        assert!(r[4] == "0" || r[4] == "1");
        if r[4] == "1" {
            assert!(r[1].parse::<f64>().is_ok());
        }
    }
}

/// The same drive as written by the Python `mcap` package (32 KiB chunks) localises on the
/// map of our own writer's log alike.
#[test]
fn another_writer_s_log_localises() {
    let map = map_of("paper-experiment.mcap", "pe.map");
    let summary = scratch("pe-pymcap.json");
    ok(&stereonav(&[
        "localize",
        s(&fixture("paper-experiment-pymcap.mcap")),
        "--map",
        s(&map),
        "--rig",
        s(&fixture("paper-experiment.rig.toml")),
        "--summary",
        s(&summary),
    ]));
    let doc: Value = serde_json::from_str(&std::fs::read_to_string(&summary).unwrap()).unwrap();
    assert!(!doc["localized_t_us"].as_array().unwrap().is_empty());
    assert!(doc["truth"]["ate_rms_m"].as_f64().unwrap() < 0.02, "{doc}");
    assert_eq!(doc["truth"]["wrong_frames"].as_u64(), Some(0));
}

/// A file that is not a map, a damaged map and a missing one end with one line and a
/// non-zero exit, before any output is made.
#[test]
fn bad_maps_are_refused_with_one_line() {
    let log = fixture("paper-experiment.mcap");
    let out = stereonav(&["localize", s(&log), "--map", s(&log)]);
    assert_one_line_error(&out, "not a stereonav map");
    let map = map_of("paper-experiment.mcap", "pe-damaged.map");
    let mut bytes = std::fs::read(&map).unwrap();
    let at = bytes.len() / 2;
    bytes[at] ^= 0x10;
    let damaged = scratch("damaged.map");
    std::fs::write(&damaged, &bytes).unwrap();
    let traj = scratch("never.csv");
    let out = stereonav(&[
        "localize",
        s(&log),
        "--map",
        s(&damaged),
        "--trajectory",
        s(&traj),
    ]);
    assert_one_line_error(&out, "map is damaged");
    assert!(!traj.exists(), "no output before the map is read");
    let out = stereonav(&["localize", s(&log), "--map", "/nonexistent/x.map"]);
    assert_one_line_error(&out, "x.map");
}
