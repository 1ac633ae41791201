//! `stereonav simulate` end to end: the log, the rig and truth files, determinism, and
//! one-line errors.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failure is the test failing

use crate::common;

use std::path::{Path, PathBuf};
use std::process::Output;

use common::stereonav;

use serde_json::Value;
use vehicle_log::Record;

fn scratch(name: &str) -> PathBuf {
    common::scratch("simulate-cli", name)
}

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/scenarios")
        .join(name)
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn ok(out: &Output) {
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        out.stderr.is_empty(),
        "silent when stderr is not a terminal"
    );
}

/// A copy of a committed scenario (and its rig) in the scratch folder, edited by `edit`.
fn edited(name: &str, tag: &str, edit: impl Fn(String) -> String) -> PathBuf {
    let text = std::fs::read_to_string(fixture(&format!("{name}.toml"))).unwrap();
    let rig = format!("{name}.rig.toml");
    std::fs::copy(fixture(&rig), scratch(&rig)).unwrap();
    let path = scratch(&format!("{name}-{tag}.toml"));
    std::fs::write(&path, edit(text)).unwrap();
    path
}

#[test]
fn writes_the_log_the_rig_and_the_truth() {
    let scenario = fixture("paper-experiment.toml");
    let (log, rig, truth) = (
        scratch("pe.mcap"),
        scratch("pe.rig.toml"),
        scratch("pe.json"),
    );
    let out = stereonav(&[
        "simulate",
        s(&scenario),
        "--out",
        s(&log),
        "--rig",
        s(&rig),
        "--truth",
        s(&truth),
    ]);
    ok(&out);
    assert!(out.stdout.is_empty());
    // The rig file is the scenario's nominal rig, readable by calib.
    let rig_text = std::fs::read_to_string(&rig).unwrap();
    assert_eq!(
        rig_text,
        std::fs::read_to_string(fixture("paper-experiment.rig.toml")).unwrap()
    );
    // The log has the input channels, the rig and the truth.
    let read = vehicle_log::read_log(&log).unwrap();
    assert!(read.truncated.is_none());
    for topic in [
        "/rig",
        "/odom",
        "/fpga/features",
        "/truth/pose",
        "/truth/camera",
        "/truth/landmarks",
    ] {
        assert!(read.topics.contains(&topic), "{topic} in {:?}", read.topics);
    }
    let poses: Vec<_> = read
        .records
        .iter()
        .filter_map(|r| match r {
            Record::TruthPose(p) => Some(*p),
            _ => None,
        })
        .collect();
    let truth: Value = serde_json::from_str(&std::fs::read_to_string(&truth).unwrap()).unwrap();
    let trajectory = truth["trajectory"].as_array().unwrap();
    assert_eq!(trajectory.len(), poses.len());
    assert_eq!(trajectory.len(), 961);
    let last = trajectory.last().unwrap();
    assert_eq!(last["t_us"], poses.last().unwrap().t_us);
    assert_eq!(last["x"].as_f64().unwrap(), poses.last().unwrap().x);
    assert_eq!(truth["landmarks"].as_array().unwrap().len(), 5);
    assert_eq!(truth["camera"]["baseline"], 0.1164);
    assert_eq!(truth["seed"], 9);
}

#[test]
fn same_seed_same_bytes_other_seed_other_bytes() {
    let scenario = edited("warehouse", "short", |t| {
        t.replace("repeat = 3", "repeat = 1")
    });
    let run = |out: &Path, seed: Option<&str>| {
        let mut args = vec!["simulate", s(&scenario), "--out", s(out)];
        if let Some(seed) = seed {
            args.extend(["--seed", seed]);
        }
        ok(&stereonav(&args));
        std::fs::read(out).unwrap()
    };
    let a = run(&scratch("w1.mcap"), None);
    let b = run(&scratch("w2.mcap"), None);
    let c = run(&scratch("w3.mcap"), Some("7"));
    let d = run(&scratch("w4.mcap"), Some("2024")); // the scenario's own seed
    assert_eq!(a, b);
    assert_ne!(a, c);
    assert_eq!(a, d);
}

#[test]
fn rendered_mode() {
    let scenario = edited("paper-experiment", "rendered", |t| {
        t.replace("repeat = 2", "repeat = 1")
            .replace("length_m = 2.5 }", "length_m = 0.3 }")
            .replace("length_m = -2.5 }", "length_m = -0.3 }")
    });
    let (fast, rendered) = (scratch("pe-fast.mcap"), scratch("pe-rendered.mcap"));
    ok(&stereonav(&["simulate", s(&scenario), "--out", s(&fast)]));
    ok(&stereonav(&[
        "simulate",
        s(&scenario),
        "--out",
        s(&rendered),
        "--rendered",
    ]));
    let features = |p: &Path| -> Vec<u8> {
        vehicle_log::read_log(p)
            .unwrap()
            .records
            .iter()
            .filter_map(|r| match r {
                Record::Features { bytes, .. } => Some(bytes.clone()),
                _ => None,
            })
            .flatten()
            .collect()
    };
    let (f, r) = (features(&fast), features(&rendered));
    assert!(!r.is_empty());
    assert_ne!(f, r, "rendered features differ from projected ones");
}

/// Runs `stereonav simulate` on `text` and returns its one-line error.
fn error_for(tag: &str, edit: impl Fn(String) -> String) -> String {
    let scenario = edited("paper-square", tag, edit);
    let out = stereonav(&["simulate", s(&scenario), "--out", s(&scratch("never.mcap"))]);
    assert_eq!(
        out.status.code(),
        Some(1),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(err.lines().count(), 1, "one line: {err}");
    assert!(!err.contains("panicked"));
    assert!(
        err.contains(&format!("paper-square-{tag}.toml: ")),
        "names the file: {err}"
    );
    err
}

#[test]
fn bad_scenarios_give_one_line_errors() {
    let e = error_for("missing", |t| t.replace("seed = 5\n", ""));
    assert!(e.contains(": seed: missing key"), "{e}");
    let e = error_for("type", |t| {
        t.replace("pixel_px = 0.3", "pixel_px = \"0.3\"")
    });
    assert!(
        e.contains(": noise.pixel_px: wrong type: expected f64, found string \"0.3\""),
        "{e}"
    );
    let e = error_for("unknown", |t| {
        t.replace("[rates]", "[rates]\nframe_rate = 20")
    });
    assert!(
        e.contains(": rates.frame_rate: unknown key (known: odometry_hz, camera_hz"),
        "{e}"
    );
    let e = error_for("impossible", |t| {
        t.replace("baseline_m = 0.117", "baseline_m = 0.0")
    });
    assert!(e.contains(": camera.baseline_m: 0 must be positive"), "{e}");
    let e = error_for("syntax", |t| t.replace("[rates]", "[rates"));
    assert!(e.contains(": line ") && e.contains("not valid TOML"), "{e}");
    let e = error_for("rig", |t| {
        t.replace("paper-square.rig.toml", "missing.rig.toml")
    });
    assert!(
        e.contains(": rig: cannot read rig file") && e.contains("missing.rig.toml"),
        "{e}"
    );
}

#[test]
fn other_failures_are_one_line_too() {
    let one_line = |out: &Output, code: i32, needle: &str| {
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(code), "{err}");
        assert_eq!(err.lines().count(), 1, "{err}");
        assert!(
            err.starts_with("stereonav: ") && err.contains(needle),
            "{err}"
        );
    };
    let out = stereonav(&["simulate", "/nonexistent/scenario.toml", "--out", "x.mcap"]);
    one_line(&out, 1, "/nonexistent/scenario.toml: cannot read");
    let scenario = fixture("paper-experiment.toml");
    let out = stereonav(&["simulate", s(&scenario), "--out", "/nonexistent/dir/x.mcap"]);
    one_line(&out, 1, "/nonexistent/dir/x.mcap");
    let out = stereonav(&["simulate", s(&scenario)]);
    one_line(&out, 2, "--out");
    let out = stereonav(&[
        "simulate",
        s(&scenario),
        "--out",
        s(&scratch("x.mcap")),
        "--seed",
        "abc",
    ]);
    one_line(&out, 2, "--seed");
    let out = stereonav(&[
        "simulate",
        s(&scenario),
        "--out",
        s(&scratch("y.mcap")),
        "--truth",
        "/nonexistent/dir/t.json",
    ]);
    one_line(
        &out,
        1,
        "/nonexistent/dir/t.json: cannot write the truth file",
    );
}

#[test]
fn the_localising_drive_starts_in_the_hall_and_is_carried_blind() {
    let scenario = fixture("hall-localize.toml");
    let (log, truth) = (scratch("hall-localize.mcap"), scratch("hall-localize.json"));
    ok(&stereonav(&[
        "simulate",
        s(&scenario),
        "--out",
        s(&log),
        "--truth",
        s(&truth),
    ]));
    let read = vehicle_log::read_log(&log).unwrap();
    let mut odom_t = Vec::new();
    let mut poses = Vec::new();
    let mut landmarks = Vec::new();
    let mut stream = Vec::new();
    for r in &read.records {
        match r {
            Record::Odom(o) => odom_t.push(o.t_us),
            Record::TruthPose(p) => poses.push(*p),
            Record::TruthLandmarks(l) => landmarks.clone_from(l),
            Record::Features { bytes, .. } => stream.extend_from_slice(bytes),
            _ => {}
        }
    }
    // The truth is the hall's: the start pose, the lit lamps with the hall's ids, the added
    // lamps after them.
    let first = poses[0];
    assert_eq!((first.x, first.y), (12.0, 6.0));
    assert!((first.theta - 120f64.to_radians()).abs() < 1e-12);
    let ids: Vec<u32> = landmarks.iter().map(|l| l.id).collect();
    assert_eq!(ids.len(), 66);
    for dark in [13, 24, 25, 37, 43, 46, 56] {
        assert!(!ids.contains(&dark), "dark lamp {dark} in the truth");
    }
    assert_eq!(&ids[63..], [70, 71, 72]);
    let json: Value = serde_json::from_str(&std::fs::read_to_string(&truth).unwrap()).unwrap();
    assert_eq!(json["landmarks"].as_array().unwrap().len(), 66);
    // 8 s without odometry (the vehicle computer was off) and without frames; the board's
    // counter jumps over the frames it did not send.
    let gap = |t: &[u64]| t.windows(2).map(|w| w[1] - w[0]).max().unwrap();
    assert!(gap(&odom_t) >= 8_000_000, "{}", gap(&odom_t));
    let pose_t: Vec<u64> = poses.iter().map(|p| p.t_us).collect();
    assert!(gap(&pose_t) >= 8_000_000);
    let mut decoder = fpga_link::Decoder::new();
    let mut rest = stream.as_slice();
    let mut frames = 0;
    loop {
        let (used, event) = decoder.decode(rest);
        rest = &rest[used..];
        match event {
            Some(fpga_link::Event::Frame(_)) => frames += 1,
            Some(_) => {}
            None => break,
        }
    }
    assert_eq!(frames, poses.len());
    // 8 s at 20 Hz: the exposures strictly inside it (159 or 160, as the carry falls
    // against the camera's clock).
    let lost = decoder.stats().lost;
    assert!((159..=160).contains(&lost), "{lost}");
}

/// `--ros2`: a ROS 2 bag of the rendered run (vehicle-interfaces.md 4.1), its truth beside it;
/// a JPEG quality outside 1-100 is a usage error.
#[test]
fn ros2_writes_a_bag_of_the_rendered_images() {
    let scenario = edited("paper-experiment-radtan", "bag", |t| {
        t.replace("repeat = 2", "repeat = 1")
            .replace("duration_s = 1.0", "duration_s = 0.1")
            .replace("length_m = 2.5", "length_m = 0.05")
            .replace("length_m = -2.5", "length_m = -0.05")
    });
    let (bag, truth) = (scratch("radtan.mcap"), scratch("radtan.json"));
    let out = stereonav(&[
        "simulate",
        s(&scenario),
        "--out",
        s(&bag),
        "--ros2",
        "png",
        "--truth",
        s(&truth),
    ]);
    ok(&out);
    let bytes = std::fs::read(&bag).unwrap();
    assert!(bytes.starts_with(b"\x89MCAP0\r\n"));
    let has = |needle: &[u8]| bytes.windows(needle.len()).any(|w| w == needle);
    for needle in [
        &b"ros2"[..],
        b"/cam0/image_raw/compressed",
        b"/cam1/image_raw/compressed",
        b"sensor_msgs/msg/CompressedImage",
        b"nav_msgs/msg/Odometry",
        b"\x89PNG",
    ] {
        assert!(has(needle), "{}", String::from_utf8_lossy(needle));
    }
    assert!(!has(b"/fpga/features"));
    // The truth topics read as a vehicle log's; the truth file agrees.
    let read = vehicle_log::read_log(&bag).unwrap();
    let poses = read
        .records
        .iter()
        .filter(|r| matches!(r, Record::TruthPose(_)))
        .count();
    let truth: Value = serde_json::from_str(&std::fs::read_to_string(&truth).unwrap()).unwrap();
    assert_eq!(truth["mode"], "rendered");
    assert_eq!(truth["trajectory"].as_array().unwrap().len(), poses);
    assert!(poses > 10, "{poses} frames");
    let out = stereonav(&[
        "simulate",
        s(&scenario),
        "--out",
        s(&bag),
        "--ros2",
        "jpeg",
        "--jpeg-quality",
        "0",
    ]);
    common::assert_one_line_error(&out, "--jpeg-quality");
    assert_eq!(out.status.code(), Some(2));
}
