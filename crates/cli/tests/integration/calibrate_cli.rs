//! `stereonav calibrate` end to end: the committed paper-calibration log against its truth,
//! the summary, the JSON document, and one-line errors on bad input.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failure is the test failing

use crate::common;

use std::path::{Path, PathBuf};
use std::process::Output;

use common::{PARAMETERS, assert_one_line_error, fixture, s, stereonav};

use serde_json::Value;

/// The truth of paper-calibration.mcap (its `/truth/camera`, fixtures/scenarios).
const TRUE_F: f64 = 721.0;
const TRUE_BASELINE_M: f64 = 0.1164;

fn scratch(name: &str) -> PathBuf {
    common::scratch("calibrate-cli", name)
}

/// Success with nothing on stderr (no warning), and the stdout text.
fn ok(out: &Output) -> String {
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        out.stderr.is_empty(),
        "no warning expected: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout.clone()).unwrap()
}

fn read_json(path: &Path) -> Value {
    let text = std::fs::read_to_string(path).unwrap();
    assert!(
        !text.contains("NaN") && !text.contains("Infinity"),
        "JSON has no NaN or infinity: {text}"
    );
    serde_json::from_str(&text).unwrap()
}

fn f64_at(v: &Value, pointer: &str) -> f64 {
    v.pointer(pointer)
        .and_then(Value::as_f64)
        .unwrap_or_else(|| panic!("{pointer} is not a number in {v}"))
}

/// The calibration reproduces the truth: f within 3 sigma and 0.2 %, the baseline within 1 mm.
fn assert_truth(doc: &Value) {
    let (f, sf) = (
        f64_at(doc, "/camera/f/value"),
        f64_at(doc, "/camera/f/sigma"),
    );
    let b = f64_at(doc, "/camera/baseline/value");
    assert!(sf > 0.0, "f sigma {sf}");
    assert!((f - TRUE_F).abs() <= 3.0 * sf, "f {f} sigma {sf}");
    assert!((f - TRUE_F).abs() <= 0.002 * TRUE_F, "f {f}");
    assert!((b - TRUE_BASELINE_M).abs() < 0.001, "baseline {b}");
}

#[test]
fn paper_calibration_log_gives_the_truth_with_the_logs_rig() {
    let json = scratch("paper.json");
    let out = stereonav(&[
        "calibrate",
        s(&fixture("paper-calibration.mcap")),
        "--out",
        s(&json),
    ]);
    let stdout = ok(&out);
    let doc = read_json(&json);
    assert_truth(&doc);

    assert_eq!(doc["status"], "converged");
    assert!(doc["iterations"].as_u64().unwrap() >= 1);
    assert_eq!(doc["rig_source"], "log");
    // Every parameter, with the rig's nominal value; only f and the baseline estimated.
    let camera = doc["camera"].as_object().unwrap();
    assert_eq!(camera.len(), 10);
    for name in PARAMETERS {
        let p = &camera[name];
        let estimated = p["estimated"].as_bool().unwrap();
        assert_eq!(estimated, name == "f" || name == "baseline", "{name}");
        if !estimated {
            assert_eq!(p["value"], p["nominal"], "{name}");
            assert_eq!(p["sigma"].as_f64(), Some(0.0), "{name}");
        }
    }
    assert_eq!(f64_at(&doc, "/camera/f/nominal"), 700.0);
    assert_eq!(f64_at(&doc, "/camera/baseline/nominal"), 0.12);
    // One observability record per estimated parameter, with every field.
    let records = doc["observability"].as_array().unwrap();
    let names: Vec<&str> = records
        .iter()
        .map(|r| r["parameter"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["f", "baseline"]);
    for r in records {
        for key in ["prior_sigma", "posterior_sigma"] {
            assert!(r[key].as_f64().unwrap() > 0.0, "{r}");
        }
        assert!(r["data_sigma"].is_f64() || r["data_sigma"].is_null(), "{r}");
        assert_eq!(r["observable"], true);
        assert!(r["reason"].is_null());
    }
    assert!(doc["max_correlation"]["value"].as_f64().unwrap().abs() <= 1.0);
    // History: the start (nominal) first, a value of C and V a row in "parameters" order;
    // the last row is the estimate.
    let history = doc["history"].as_array().unwrap();
    assert!(history.len() >= 2);
    assert_eq!(doc["parameters"].as_array().unwrap().len(), 14);
    assert!(
        history
            .iter()
            .all(|row| row.as_array().unwrap().len() == 14)
    );
    assert_eq!(history[0][0].as_f64(), Some(700.0));
    assert_eq!(
        history.last().unwrap()[0].as_f64(),
        Some(f64_at(&doc, "/camera/f/value"))
    );
    // The incremental calibration becomes stable before the end of the drive, and the camera
    // it hands over is already within the accuracy bounds.
    let handover = &doc["handover"];
    let t_handover = handover["t_us"].as_u64().unwrap();
    assert!(t_handover < 182_000_000, "{t_handover}");
    let b = f64_at(handover, "/camera/baseline/value");
    assert!((b - 0.1164).abs() < 0.001, "{handover}");
    for solve in doc["incremental"].as_array().unwrap() {
        assert_eq!(solve["values"].as_array().unwrap().len(), 14);
        assert!(solve["t_us"].is_u64());
    }
    let counts = &doc["counts"];
    assert_eq!(counts["frames"], 3641);
    assert_eq!(
        (&counts["corrupt"], &counts["lost"]),
        (&0.into(), &0.into())
    );
    assert!(counts["pairs"].as_u64().unwrap() > 50);
    assert_eq!(doc["warnings"].as_array().unwrap().len(), 0);

    // The summary says the same, in a few lines.
    assert!(stdout.contains("status: converged"), "{stdout}");
    assert!(stdout.contains("rig: the log's /rig message"), "{stdout}");
    let f_line = stdout
        .lines()
        .find(|l| l.trim_start().starts_with("f "))
        .unwrap();
    assert!(
        f_line.contains(" ± ") && f_line.contains("(nominal 700)"),
        "{f_line}"
    );
    assert!(
        stdout.contains(&format!("hand-over to phase 2: at t_us {t_handover}")),
        "{stdout}"
    );
    assert!(
        stdout.contains("3641 frames, 0 corrupt, 0 lost"),
        "{stdout}"
    );
    assert!(stdout.lines().count() <= 12, "short: {stdout}");
}

#[test]
fn an_explicit_rig_file_gives_the_same_calibration() {
    let json = scratch("explicit.json");
    let out = stereonav(&[
        "calibrate",
        s(&fixture("paper-calibration.mcap")),
        "--rig",
        s(&fixture("paper-calibration.rig.toml")),
        "--out",
        s(&json),
    ]);
    let stdout = ok(&out);
    assert!(stdout.contains("rig: "), "{stdout}");
    assert!(stdout.contains("paper-calibration.rig.toml"), "{stdout}");
    let doc = read_json(&json);
    assert_eq!(doc["rig_source"], "given");
    assert_truth(&doc);
}

#[test]
fn a_rig_that_differs_from_the_logs_is_a_warning_on_stderr() {
    // paper-experiment's rig: another mount, so another calibration, but a valid run.
    let out = stereonav(&[
        "calibrate",
        s(&fixture("paper-calibration.mcap")),
        "--rig",
        s(&fixture("paper-experiment.rig.toml")),
    ]);
    assert!(out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr
            .lines()
            .any(|l| l.starts_with("stereonav: warning: ") && l.contains("differs")),
        "{stderr}"
    );
}

#[test]
fn interleaved_pairs_and_another_stride_are_taken() {
    let json = scratch("interleaved.json");
    let out = stereonav(&[
        "calibrate",
        s(&fixture("paper-calibration.mcap")),
        "--stride",
        "20",
        "--pairing",
        "interleaved",
        "--out",
        s(&json),
    ]);
    ok(&out);
    let doc = read_json(&json);
    // Interleaved pairs use every frame once: about twice the pairs of disjoint ones at the
    // same stride, and more than the default's 40-frame disjoint pairs.
    assert!(
        doc["counts"]["pairs"].as_u64().unwrap() > 100,
        "{}",
        doc["counts"]
    );
    assert!((f64_at(&doc, "/camera/baseline/value") - TRUE_BASELINE_M).abs() < 0.001);
}

#[test]
fn a_missing_log_is_one_line() {
    let missing = scratch("no-such-log.mcap");
    let out = stereonav(&["calibrate", s(&missing)]);
    assert_one_line_error(&out, "no-such-log.mcap");
    // The operating system's reason said once, not once per cause.
    let stderr = String::from_utf8_lossy(&out.stderr);
    let parts: Vec<&str> = stderr.trim_end().split(": ").collect();
    for (i, part) in parts.iter().enumerate() {
        assert!(
            !parts[i + 1..].contains(part),
            "{part:?} repeats in {stderr}"
        );
    }
}

#[test]
fn a_text_file_is_not_a_log() {
    let out = stereonav(&["calibrate", s(&fixture("paper-calibration.rig.toml"))]);
    assert_one_line_error(&out, "not an MCAP file");
}

#[test]
fn a_rig_with_a_missing_key_is_one_line_naming_the_key() {
    let text = std::fs::read_to_string(fixture("paper-calibration.rig.toml")).unwrap();
    let rig = scratch("no-baseline.rig.toml");
    let edited: String = text
        .lines()
        .filter(|l| !l.starts_with("baseline ="))
        .map(|l| format!("{l}\n"))
        .collect();
    assert_ne!(edited, text);
    std::fs::write(&rig, edited).unwrap();
    let out = stereonav(&[
        "calibrate",
        s(&fixture("paper-calibration.mcap")),
        "--rig",
        s(&rig),
    ]);
    assert_one_line_error(&out, "[camera] baseline: missing key");
    assert!(String::from_utf8_lossy(&out.stderr).contains("no-baseline.rig.toml"));
}

#[test]
fn a_missing_rig_file_is_one_line() {
    let out = stereonav(&[
        "calibrate",
        s(&fixture("paper-calibration.mcap")),
        "--rig",
        s(&scratch("no-such.rig.toml")),
    ]);
    assert_one_line_error(&out, "no-such.rig.toml");
}

#[test]
fn stride_zero_is_one_line() {
    let out = stereonav(&[
        "calibrate",
        s(&fixture("paper-calibration.mcap")),
        "--stride",
        "0",
    ]);
    assert_one_line_error(&out, "stride");
    let out = stereonav(&[
        "calibrate",
        s(&fixture("paper-calibration.mcap")),
        "--pairing",
        "sometimes",
    ]);
    assert_one_line_error(&out, "sometimes");
}

#[test]
fn an_unwritable_out_path_is_one_line() {
    let out = stereonav(&[
        "calibrate",
        s(&fixture("paper-calibration.mcap")),
        "--out",
        s(&scratch("no-such-dir").join("result.json")),
    ]);
    assert_one_line_error(&out, "result.json");
}

/// An MCAP file written by another tool (ROS 2, in the shared data folder when it exists) is
/// refused in one line naming its topics.
#[test]
fn a_foreign_mcap_file_is_not_a_vehicle_log() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/foreign-mcap");
    let Ok(entries) = std::fs::read_dir(&dir) else {
        eprintln!("skipped: {} is absent", dir.display());
        return;
    };
    let files: Vec<PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "mcap"))
        .collect();
    if files.is_empty() {
        eprintln!("skipped: no .mcap file in {}", dir.display());
    }
    for file in files {
        let out = stereonav(&["calibrate", s(&file)]);
        assert_one_line_error(&out, "is not a vehicle log");
    }
}
