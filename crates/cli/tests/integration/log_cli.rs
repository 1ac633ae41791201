//! `stereonav log check` and `stereonav log recover` end to end: an undamaged committed log
//! (exit 0), damaged and cut copies of it (exit 1, the damage named with its offsets and
//! log times, what a replay will use), the JSON report, a recovered log that checks clean and
//! holds every readable message, and one-line errors on bad input.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failure is the test failing

use crate::common;

use std::path::PathBuf;

use common::{assert_one_line_error, fixture, s, stereonav};
use serde_json::Value;
use vehicle_log::Record;

fn scratch(name: &str) -> PathBuf {
    common::scratch("log-cli", name)
}

/// A copy of a committed log with bit `bit` of byte `at` flipped (and cut to `cut` bytes).
fn damaged(name: &str, out: &str, flips: &[(usize, u8)], cut: Option<usize>) -> PathBuf {
    let mut bytes = std::fs::read(fixture(name)).unwrap();
    for &(at, bit) in flips {
        bytes[at] ^= 1 << bit;
    }
    if let Some(cut) = cut {
        bytes.truncate(cut);
    }
    let path = scratch(out);
    std::fs::write(&path, bytes).unwrap();
    path
}

/// The vehicle records of a log (no Lost markers).
fn data_records(path: &std::path::Path) -> Vec<Record> {
    vehicle_log::read_log(path)
        .unwrap()
        .records
        .into_iter()
        .filter(|r| !matches!(r, Record::Lost(_)))
        .collect()
}

#[test]
fn an_undamaged_log_checks_clean_with_exit_status_0() {
    for name in ["paper-experiment.mcap", "paper-experiment-pymcap.mcap"] {
        let log = fixture(name);
        let out = stereonav(&["log", "check", s(&log)]);
        let stdout = String::from_utf8_lossy(&out.stdout);
        assert!(out.status.success(), "{name}: {stdout}");
        assert!(stdout.contains("no damage found"), "{stdout}");
        assert!(stdout.contains("summary section intact"), "{stdout}");
        assert!(stdout.contains("/fpga/features: "), "{stdout}");
        assert!(
            stdout.contains("/odom: 4801 messages read, 0 lost"),
            "{stdout}"
        );
        assert!(
            out.stderr.is_empty(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
}

#[test]
fn a_damaged_log_is_reported_with_offsets_times_and_exit_status_1() {
    // Two flips in the compressed data of a chunk in the middle of the Python-written log
    // (one alone would be mended).
    let log = damaged(
        "paper-experiment-pymcap.mcap",
        "flipped.mcap",
        &[(200_000, 4), (200_040, 1)],
        None,
    );
    let out = stereonav(&["log", "check", s(&log)]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert_eq!(out.status.code(), Some(1), "{stdout}");
    assert!(stdout.contains("DAMAGED"), "{stdout}");
    assert!(stdout.contains("lost: 1 spans"), "{stdout}");
    assert!(stdout.contains("offset "), "{stdout}");
    assert!(stdout.contains("log time "), "{stdout}");
    assert!(stdout.contains("what a replay will use:"), "{stdout}");
    // The lost odometry is counted, by the summary's statistics.
    let odom = stdout
        .lines()
        .find(|l| l.trim_start().starts_with("/odom:"))
        .unwrap();
    assert!(!odom.ends_with(" 0 lost"), "{odom}");
    assert!(!odom.contains("unknown"), "{odom}");

    // The same as JSON.
    let out = stereonav(&["log", "check", "--json", s(&log)]);
    assert_eq!(out.status.code(), Some(1));
    let doc: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(doc["damage"]["damaged"], true);
    assert_eq!(doc["damage"]["summary"], "intact");
    assert_eq!(doc["damage"]["chunks_lost"], 1);
    let span = &doc["damage"]["spans"][0];
    assert!(span["offset"].as_u64().unwrap() <= 200_000);
    assert!(span["offset"].as_u64().unwrap() + span["bytes"].as_u64().unwrap() > 200_000);
    assert!(span["start_ns"].as_u64().unwrap() <= span["end_ns"].as_u64().unwrap());
    assert!(span["messages"]["/odom"].as_u64().unwrap() > 0);
    let read = doc["topics"]["/odom"]["read"].as_u64().unwrap();
    let lost = doc["topics"]["/odom"]["lost"].as_u64().unwrap();
    assert_eq!(read + lost, 4801);
}

#[test]
fn a_log_cut_in_half_is_reported_cut_and_still_has_its_vehicle_topics() {
    let len = std::fs::metadata(fixture("paper-experiment.mcap"))
        .unwrap()
        .len() as usize;
    let log = damaged("paper-experiment.mcap", "half.mcap", &[], Some(len / 2));
    let out = stereonav(&["log", "check", s(&log)]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert_eq!(out.status.code(), Some(1), "{stdout}");
    assert!(stdout.contains("cut short"), "{stdout}");
    assert!(
        stdout.contains("no summary section: the file is cut before it"),
        "{stdout}"
    );
    assert!(stdout.contains("/fpga/features: "), "{stdout}");
    assert!(!stdout.contains("/odom: 0 messages"), "{stdout}");
}

#[test]
fn recover_writes_a_clean_log_of_every_readable_message() {
    let log = damaged(
        "paper-experiment-pymcap.mcap",
        "to-recover.mcap",
        &[(13, 2), (120_000, 0), (300_000, 6)],
        Some(440_000),
    );
    let out_path = scratch("recovered.mcap");
    let out = stereonav(&["log", "recover", s(&log), s(&out_path)]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(stdout.contains("messages recovered from"), "{stdout}");
    assert!(stdout.contains("dropped:"), "{stdout}");
    assert!(stdout.contains("lost: "), "{stdout}");
    // The recovered log checks clean and holds what the damaged one reads.
    let check = stereonav(&["log", "check", s(&out_path)]);
    assert!(
        check.status.success(),
        "{}",
        String::from_utf8_lossy(&check.stdout)
    );
    assert_eq!(data_records(&out_path), data_records(&log));
    // Foreign topics too: every message of the damaged log, of any topic, was written.
    let raw = vehicle_log::RawReader::open(&log).unwrap();
    let messages = raw
        .filter(|r| matches!(r, Ok(vehicle_log::RawRecord::Message(_))))
        .count();
    assert!(
        stdout.contains(&format!(" {messages} messages recovered")),
        "{stdout}"
    );

    // An undamaged log: nothing dropped.
    let clean = scratch("recovered-clean.mcap");
    let out = stereonav(&[
        "log",
        "recover",
        s(&fixture("paper-experiment.mcap")),
        s(&clean),
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success());
    assert!(stdout.contains("dropped: nothing"), "{stdout}");
    assert_eq!(
        data_records(&clean),
        data_records(&fixture("paper-experiment.mcap"))
    );
}

#[test]
fn bad_input_is_one_line_and_non_zero() {
    let missing = scratch("does-not-exist.mcap");
    let out = stereonav(&["log", "check", s(&missing)]);
    assert_one_line_error(&out, "cannot open");
    assert!(out.stdout.is_empty());

    let text = scratch("not-a-log.mcap");
    std::fs::write(&text, b"t_us,x,y,theta\n0,0,0,0\n").unwrap();
    let out = stereonav(&["log", "check", s(&text)]);
    assert_one_line_error(&out, "is not an MCAP file");
    let out = stereonav(&["log", "recover", s(&text), s(&scratch("out.mcap"))]);
    assert_one_line_error(&out, "is not an MCAP file");

    let empty = scratch("empty.mcap");
    std::fs::write(&empty, b"").unwrap();
    assert_one_line_error(&stereonav(&["log", "check", s(&empty)]), "it is empty");

    // OUT == IN is refused before anything is written.
    let log = damaged("paper-experiment.mcap", "same.mcap", &[], None);
    let before = std::fs::read(&log).unwrap();
    let out = stereonav(&["log", "recover", s(&log), s(&log)]);
    assert_one_line_error(&out, "is the log being recovered");
    assert_eq!(std::fs::read(&log).unwrap(), before);
    let dotted = log.parent().unwrap().join(".").join("same.mcap");
    let out = stereonav(&["log", "recover", s(&log), s(&dotted)]);
    assert_one_line_error(&out, "is the log being recovered");

    let out = stereonav(&["log", "recover", s(&log), "/nonexistent-dir/out.mcap"]);
    assert_one_line_error(&out, "cannot create /nonexistent-dir/out.mcap");
}

#[test]
fn a_log_with_one_flipped_bit_is_mended_and_still_reported() {
    let log = damaged(
        "paper-experiment-pymcap.mcap",
        "one-flip.mcap",
        &[(200_000, 4)],
        None,
    );
    let out = stereonav(&["log", "check", s(&log)]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert_eq!(out.status.code(), Some(1), "{stdout}");
    assert!(stdout.contains("mended 1 chunks"), "{stdout}");
    let out = stereonav(&["log", "check", "--json", s(&log)]);
    let doc: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(doc["damage"]["repaired_chunks"], 1);
    assert_eq!(doc["damage"]["spans_total"], 0);
    assert_eq!(doc["topics"]["/odom"]["read"], 4801);
}
