//! `stereonav replay` end to end (vehicle-interfaces.md section 5): the committed paper logs,
//! the three output files, a log cut short, and one-line errors on bad input.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failure is the test failing

use crate::common;

use std::path::{Path, PathBuf};
use std::process::Output;

use common::{PARAMETERS, assert_one_line_error, fixture, s, stereonav};
use serde_json::Value;

fn scratch(name: &str) -> PathBuf {
    common::scratch("replay-cli", name)
}

fn ok(out: &Output) -> String {
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout.clone()).unwrap()
}

fn is_number(v: &Value) -> bool {
    v.is_f64() || v.is_i64() || v.is_u64()
}

/// The summary holds at least the contract's keys, with their types.
fn assert_contract(doc: &Value, frames: usize) {
    assert_eq!(doc["frames"].as_u64(), Some(frames as u64), "{doc}");
    assert!(doc["corrupt"].is_u64() && doc["lost"].is_u64());
    assert!(doc["phase_switch_t_us"].is_u64() || doc["phase_switch_t_us"].is_null());
    for key in ["x", "y", "theta"] {
        assert!(is_number(&doc["pose"][key]), "pose.{key}");
    }
    assert!(doc["pose"]["t_us"].is_u64());
    for p in PARAMETERS {
        assert!(is_number(&doc["camera"][p]["value"]), "camera.{p}");
        assert!(is_number(&doc["camera"][p]["sigma"]), "camera.{p}");
    }
    for l in doc["landmarks"].as_array().unwrap() {
        assert!(l["id"].is_u64() && l["observations"].is_u64(), "{l}");
        for key in ["x", "y", "z"] {
            assert!(is_number(&l[key]), "{l}");
        }
        let sigma = l["sigma"].as_array().unwrap();
        assert_eq!(sigma.len(), 3);
        assert!(sigma.iter().all(is_number));
    }
}

/// The README's main job: paper-experiment with its rig, phase 1 skipped as in the paper.
#[test]
fn paper_experiment_writes_the_three_files_and_a_human_summary() {
    let (est, summary, traj) = (
        scratch("pe-est.mcap"),
        scratch("pe-summary.json"),
        scratch("pe-traj.csv"),
    );
    let out = stereonav(&[
        "replay",
        s(&fixture("paper-experiment.mcap")),
        "--rig",
        s(&fixture("paper-experiment.rig.toml")),
        "--skip-phase1",
        "--out",
        s(&est),
        "--summary",
        s(&summary),
        "--trajectory",
        s(&traj),
    ]);
    let text = ok(&out);
    assert!(
        out.stderr.is_empty(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(text.contains("map: 5 landmarks"), "{text}");
    assert!(text.contains("baseline:"), "{text}");
    assert!(text.contains("landmark RMS"), "{text}");
    assert!(text.contains("trajectory error RMS"), "{text}");
    let doc: Value = serde_json::from_str(&std::fs::read_to_string(&summary).unwrap()).unwrap();
    assert_contract(&doc, 961);
    assert_eq!(doc["landmarks"].as_array().unwrap().len(), 5);
    assert!(doc["phase_switch_t_us"].is_null());
    assert!(doc["truth"]["camera"]["baseline"].as_f64().unwrap().abs() <= 0.0005);
    let csv = std::fs::read_to_string(&traj).unwrap();
    let mut lines = csv.lines();
    assert_eq!(lines.next(), Some("t_us,x,y,theta"));
    let rows: Vec<Vec<f64>> = lines
        .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
        .collect();
    assert_eq!(rows.len(), 961);
    assert!(rows.iter().all(|r| r.len() == 4));
    assert!(rows.windows(2).all(|w| w[0][0] < w[1][0]));
    let bytes = std::fs::read(&est).unwrap();
    assert!(bytes.starts_with(b"\x89MCAP0\r\n") && bytes.ends_with(b"\x89MCAP0\r\n"));
}

/// The whole method on paper-calibration with the log's own /rig: the switch is reported.
#[test]
fn paper_calibration_reports_the_phase_switch() {
    let summary = scratch("pc-summary.json");
    let out = stereonav(&[
        "replay",
        s(&fixture("paper-calibration.mcap")),
        "--summary",
        s(&summary),
    ]);
    let text = ok(&out);
    assert!(text.contains("phase 1 handed over at t = "), "{text}");
    let doc: Value = serde_json::from_str(&std::fs::read_to_string(&summary).unwrap()).unwrap();
    assert!(doc["phase_switch_t_us"].as_u64().unwrap() > 1_000_000);
    assert_eq!(doc["landmarks"].as_array().unwrap().len(), 5);
    assert_eq!(doc["truth"]["landmarks_unmatched"].as_u64(), Some(0));
}

/// A log cut short (power lost while recording) is replayed as far as it goes, with a warning.
#[test]
fn a_log_cut_short_is_replayed_with_a_warning() {
    let bytes = std::fs::read(fixture("paper-experiment.mcap")).unwrap();
    let cut = scratch("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() * 2 / 3]).unwrap();
    let summary = scratch("cut-summary.json");
    let out = stereonav(&[
        "replay",
        s(&cut),
        "--rig",
        s(&fixture("paper-experiment.rig.toml")),
        "--skip-phase1",
        "--summary",
        s(&summary),
    ]);
    ok(&out);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("warning") && stderr.contains("ends early"),
        "{stderr}"
    );
    assert!(!stderr.contains("panicked"));
    let doc: Value = serde_json::from_str(&std::fs::read_to_string(&summary).unwrap()).unwrap();
    let frames = doc["frames"].as_u64().unwrap();
    assert!(frames > 100 && frames < 961, "{frames}");
}

#[test]
fn a_missing_log_is_one_line() {
    let out = stereonav(&["replay", s(&scratch("no-such-log.mcap"))]);
    assert_one_line_error(&out, "no-such-log.mcap");
}

#[test]
fn a_text_file_is_not_a_log() {
    let out = stereonav(&["replay", s(&fixture("paper-experiment.rig.toml"))]);
    assert_one_line_error(&out, "not an MCAP file");
}

#[test]
fn a_foreign_mcap_file_is_not_a_vehicle_log() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data/foreign-mcap/nav2_turtlebot.mcap");
    if !path.exists() {
        eprintln!("skipped: {} is absent", path.display());
        return;
    }
    let out = stereonav(&["replay", s(&path)]);
    assert_one_line_error(&out, "is not a vehicle log");
}

/// Rig files with a missing key, a wrong type, an unknown parameter: one line naming it.
#[test]
fn bad_rig_files_are_one_line_naming_the_problem() {
    let text = std::fs::read_to_string(fixture("paper-experiment.rig.toml")).unwrap();
    let without_baseline: String = text
        .lines()
        .filter(|l| !l.starts_with("baseline ="))
        .map(|l| format!("{l}\n"))
        .collect();
    let cases = [
        (
            "missing",
            without_baseline,
            "[camera] baseline: missing key",
        ),
        (
            "type",
            text.replacen("f = 700.0", "f = \"seven hundred\"", 1),
            "f",
        ),
        (
            "unknown",
            text.replacen("parameters = [\"baseline\"]", "parameters = [\"zoom\"]", 1),
            "zoom",
        ),
    ];
    for (tag, edited, needle) in cases {
        assert_ne!(edited, text, "{tag}");
        let rig = scratch(&format!("{tag}.rig.toml"));
        std::fs::write(&rig, edited).unwrap();
        let out = stereonav(&[
            "replay",
            s(&fixture("paper-experiment.mcap")),
            "--rig",
            s(&rig),
        ]);
        assert_one_line_error(&out, needle);
        assert!(
            String::from_utf8_lossy(&out.stderr).contains(&format!("{tag}.rig.toml")),
            "{tag}"
        );
    }
}

#[test]
fn an_unwritable_output_is_one_line() {
    let out = stereonav(&[
        "replay",
        s(&fixture("paper-experiment.mcap")),
        "--skip-phase1",
        "--summary",
        s(&scratch("no-such-dir/summary.json")),
    ]);
    assert_one_line_error(&out, "summary.json");
}

#[test]
fn stride_zero_is_one_line() {
    let out = stereonav(&[
        "replay",
        s(&fixture("paper-experiment.mcap")),
        "--stride",
        "0",
    ]);
    assert_one_line_error(&out, "stride");
}

/// `--save-map` writes the run's map: the summary's landmarks with their covariance, every
/// parameter of C and V at its final value, and the rig; it reads back through `map-file`.
#[test]
fn save_map_writes_the_summary_s_map() {
    let (summary, map) = (scratch("sq-summary.json"), scratch("sq.map"));
    let out = stereonav(&[
        "replay",
        s(&fixture("paper-square.mcap")),
        "--summary",
        s(&summary),
        "--save-map",
        s(&map),
    ]);
    ok(&out);
    let doc: Value = serde_json::from_str(&std::fs::read_to_string(&summary).unwrap()).unwrap();
    let saved = map_file::Map::load(&map).unwrap();
    let landmarks = doc["landmarks"].as_array().unwrap();
    assert_eq!(saved.landmarks.len(), landmarks.len());
    for (l, j) in saved.landmarks.iter().zip(landmarks) {
        assert_eq!(l.id, j["id"].as_u64().unwrap());
        assert_eq!(l.position[0], j["x"].as_f64().unwrap());
        assert_eq!(l.covariance[2][2].sqrt(), j["sigma"][2].as_f64().unwrap());
    }
    assert_eq!(saved.parameters.len(), rig_model::Param::ALL.len());
    let baseline = saved
        .parameters
        .iter()
        .find(|p| p.param == rig_model::Param::Baseline)
        .unwrap();
    assert_eq!(
        baseline.value,
        doc["camera"]["baseline"]["value"].as_f64().unwrap()
    );
    assert!(saved.source_log.ends_with("paper-square.mcap"));
}
