//! Files written by other tools: extra topics, foreign encodings, other compressions,
//! malformed messages, and the third-party files in shared/data.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use crate::common;

use std::collections::BTreeMap;
use std::io::Cursor;

use common::{exact, shared_data};
use mcap::records::MessageHeader;
use mcap::{Compression, WriteOptions};
use vehicle_log::{Error, LogReader, OdomSample, Problem, Record, read_log, topics};

/// Writes a file with the mcap crate directly: our topics, plus what `extra` adds.
struct RawLog {
    writer: mcap::Writer<Cursor<Vec<u8>>>,
    sequence: u32,
}

impl RawLog {
    fn new(compression: Option<Compression>) -> Self {
        let writer = WriteOptions::new()
            .compression(compression)
            .chunk_size(Some(4096))
            .create(Cursor::new(Vec::new()))
            .unwrap();
        Self {
            writer,
            sequence: 0,
        }
    }
    fn channel(&mut self, topic: &str, encoding: &str, schema: Option<(&str, &str)>) -> u16 {
        let schema_id = match schema {
            Some((name, doc)) => self
                .writer
                .add_schema(name, "jsonschema", doc.as_bytes())
                .unwrap(),
            None => 0,
        };
        self.writer
            .add_channel(schema_id, topic, encoding, &BTreeMap::new())
            .unwrap()
    }
    fn message(&mut self, channel_id: u16, log_time: u64, data: &[u8]) {
        self.sequence += 1;
        let header = MessageHeader {
            channel_id,
            sequence: self.sequence,
            log_time,
            publish_time: log_time,
        };
        self.writer.write_to_known_channel(&header, data).unwrap();
    }
    fn finish(mut self) -> Vec<u8> {
        self.writer.finish().unwrap();
        self.writer.into_inner().into_inner()
    }
}

fn read(bytes: Vec<u8>) -> vehicle_log::Result<vehicle_log::Log> {
    LogReader::new(Cursor::new(bytes), "raw.mcap")?.into_log()
}

fn odom_json(t_us: u64) -> Vec<u8> {
    format!(r#"{{"t_us": {t_us}, "vx": 0.25, "vy": -0.0, "vtheta": 1e-3, "extra": [1, 2]}}"#)
        .into_bytes()
}

#[test]
fn unknown_topics_and_foreign_channels_are_ignored_and_counted() {
    for compression in [Some(Compression::Zstd), Some(Compression::Lz4), None] {
        let mut raw = RawLog::new(compression);
        let odom = raw.channel(
            "/odom",
            "json",
            Some(("stereonav.Odometry", topics::ODOMETRY_SCHEMA)),
        );
        let features = raw.channel("/fpga/features", "stereonav.fpga-link.v1", None);
        let image = raw.channel("/camera/left/image_raw", "raw-bytes", None);
        let ros_odom = raw.channel("/odom", "cdr", None);
        let other_schema = raw.channel("/truth/pose", "json", Some(("geometry.Pose", "{}")));
        let diagnostics = raw.channel("/diagnostics", "json", None);
        let mut expected = Vec::new();
        let mut ignored = 0;
        for i in 0..300u64 {
            let t_us = 1_000_000 + i * 10_000;
            raw.message(image, t_us * 1000, &vec![i as u8; 2000]);
            raw.message(ros_odom, t_us * 1000, &[0, 1, 0, 0, 9, 9]);
            raw.message(other_schema, t_us * 1000, b"{\"position\": 1}");
            ignored += 3;
            raw.message(odom, t_us * 1000, &odom_json(t_us));
            expected.push(Record::Odom(OdomSample {
                t_us,
                vx: 0.25,
                vy: -0.0,
                vtheta: 1e-3,
            }));
            if i % 5 == 0 {
                raw.message(features, t_us * 1000 + 3, &[i as u8, 0x5A]);
                raw.message(diagnostics, t_us * 1000, b"{}");
                ignored += 1;
                expected.push(Record::Features {
                    log_time_ns: t_us * 1000 + 3,
                    bytes: vec![i as u8, 0x5A],
                });
            }
        }
        let log = read(raw.finish()).unwrap();
        assert_eq!(exact(&log.records), exact(&expected), "{compression:?}");
        assert_eq!(log.ignored_messages, ignored);
        assert_eq!(
            log.ignored_topics,
            [
                "/camera/left/image_raw",
                "/odom",
                "/truth/pose",
                "/diagnostics"
            ]
        );
        assert_eq!(log.topics, ["/odom", "/fpga/features"]);
        assert_eq!(log.warnings.len(), 2, "{:?}", log.warnings);
        assert!(log.warnings[0].contains("\"cdr\""), "{}", log.warnings[0]);
        assert!(
            log.warnings[1].contains("geometry.Pose"),
            "{}",
            log.warnings[1]
        );
        assert_eq!(log.truncated, None);
        assert!(log.has_vehicle_topics());
    }
}

#[test]
fn a_json_topic_without_a_schema_is_still_ours() {
    let mut raw = RawLog::new(Some(Compression::Zstd));
    let odom = raw.channel("/odom", "json", None);
    raw.message(odom, 5_000, &odom_json(5));
    let log = read(raw.finish()).unwrap();
    assert_eq!(log.records.len(), 1);
    assert!(log.has_vehicle_topics());
}

#[test]
fn a_malformed_odometry_message_is_an_error_naming_topic_index_and_problem() {
    let cases: [(&[u8], &str); 5] = [
        (
            br#"{"t_us": 3, "vx": 0, "vy": 0}"#,
            r#"missing key "vtheta""#,
        ),
        (
            br#"{"t_us": -3, "vx": 0, "vy": 0, "vtheta": 0}"#,
            r#"key "t_us": expected a non-negative integer, found -3"#,
        ),
        (
            br#"{"t_us": 3, "vx": null, "vy": 0, "vtheta": 0}"#,
            r#"key "vx": expected a number, found null"#,
        ),
        (br#"[3, 0, 0, 0]"#, "expected a JSON object, found an array"),
        (b"\xff\xfe", "not JSON"),
    ];
    for (bad, problem) in cases {
        let mut raw = RawLog::new(Some(Compression::Zstd));
        let odom = raw.channel(
            "/odom",
            "json",
            Some(("stereonav.Odometry", topics::ODOMETRY_SCHEMA)),
        );
        for t_us in 0..4 {
            raw.message(odom, t_us * 1000, &odom_json(t_us));
        }
        raw.message(odom, 4000, bad);
        raw.message(odom, 5000, &odom_json(5));
        let bytes = raw.finish();

        let err = read(bytes.clone()).unwrap_err();
        assert!(
            matches!(
                &err,
                Error::BadMessage {
                    topic: "/odom",
                    index: 4,
                    ..
                }
            ),
            "{err:?}"
        );
        let text = err.to_string();
        assert!(
            text.starts_with(&format!("raw.mcap: /odom message 4: {problem}")),
            "{text}"
        );

        // Streaming: the good records, then the error, then nothing.
        let mut reader = LogReader::new(Cursor::new(bytes), "raw.mcap").unwrap();
        for _ in 0..4 {
            assert!(matches!(reader.next(), Some(Ok(Record::Odom(_)))));
        }
        assert!(matches!(reader.next(), Some(Err(Error::BadMessage { .. }))));
        assert!(reader.next().is_none());
    }
}

#[test]
fn a_rig_message_that_is_not_an_object_is_an_error() {
    let mut raw = RawLog::new(None);
    let rig = raw.channel("/rig", "json", Some(("stereonav.Rig", topics::RIG_SCHEMA)));
    raw.message(rig, 0, b"\"camera\"");
    let err = read(raw.finish()).unwrap_err();
    assert!(matches!(
        &err,
        Error::BadMessage {
            topic: "/rig",
            index: 0,
            problem: Problem::NotObject { found: "a string" },
            ..
        }
    ));
    assert_eq!(
        err.to_string(),
        "raw.mcap: /rig message 0: expected a JSON object, found a string"
    );
}

#[test]
fn the_nav2_turtlebot_file_opens_and_has_no_vehicle_topics() {
    let Some(data) = shared_data() else {
        eprintln!("skipped: shared/data is absent");
        return;
    };
    let path = data.join("foreign-mcap/nav2_turtlebot.mcap");
    if !path.is_file() {
        eprintln!("skipped: {} is absent", path.display());
        return;
    }
    let log = read_log(&path).unwrap();
    eprintln!(
        "nav2: {} ignored messages on {:?}; warnings {:?}; truncated {:?}",
        log.ignored_messages, log.ignored_topics, log.warnings, log.truncated
    );
    assert!(log.records.is_empty());
    assert!(!log.has_vehicle_topics());
    assert_eq!(log.truncated, None);
    assert!(log.ignored_messages > 0);
    for topic in ["/odom", "/tf", "/amcl_pose"] {
        assert!(log.ignored_topics.iter().any(|t| t == topic), "{topic}");
    }
    // Its /odom is ROS's, in CDR: named in a warning.
    assert!(log.warnings.iter().any(|w| w.starts_with("channel /odom ")));
}

#[test]
fn the_euroc_static_log_reads() {
    let Some(data) = shared_data() else {
        eprintln!("skipped: shared/data is absent");
        return;
    };
    let path = data.join("euroc-v101-static/log.mcap");
    if !path.is_file() {
        eprintln!("skipped: {} is absent", path.display());
        return;
    }
    let log = read_log(&path).unwrap();
    let mut counts = BTreeMap::<&str, usize>::new();
    for record in &log.records {
        let kind = match record {
            Record::Features { .. } => "features",
            Record::Odom(_) => "odom",
            Record::Rig(_) => "rig",
            Record::TruthPose(_) => "truth_pose",
            Record::TruthLandmarks(_) => "truth_landmarks",
            Record::TruthCamera(_) => "truth_camera",
            _ => "other",
        };
        *counts.entry(kind).or_default() += 1;
    }
    // The board's decoder on the concatenated chunks.
    let mut decoder = fpga_link::Decoder::new();
    let mut frames = Vec::new();
    for record in &log.records {
        let Record::Features { bytes, .. } = record else {
            continue;
        };
        let mut rest = bytes.as_slice();
        loop {
            let (used, event) = decoder.decode(rest);
            rest = &rest[used..];
            match event {
                Some(fpga_link::Event::Frame(f)) => {
                    frames.push((f.t_us(), f.left().count(), f.right().count()))
                }
                Some(fpga_link::Event::Corrupt(c)) => panic!("corrupt packet: {c}"),
                None => break,
            }
        }
    }
    while decoder.decode_end().is_some() {}
    let odom: Vec<&OdomSample> = log
        .records
        .iter()
        .filter_map(|r| match r {
            Record::Odom(s) => Some(s),
            _ => None,
        })
        .collect();
    eprintln!(
        "euroc: {counts:?}; topics {:?}; ignored {} on {:?}; warnings {:?}; truncated {:?}",
        log.topics, log.ignored_messages, log.ignored_topics, log.warnings, log.truncated
    );
    eprintln!(
        "euroc: {} packets, t_us {:?}..{:?}, features per side min/max {:?}/{:?}; stats {:?}",
        frames.len(),
        frames.first().map(|f| f.0),
        frames.last().map(|f| f.0),
        frames.iter().map(|f| f.1.min(f.2)).min(),
        frames.iter().map(|f| f.1.max(f.2)).max(),
        decoder.stats()
    );
    eprintln!(
        "euroc: odom t_us {:?}..{:?}, max |v| {:?}",
        odom.first().map(|s| s.t_us),
        odom.last().map(|s| s.t_us),
        odom.iter()
            .map(|s| s.vx.abs().max(s.vy.abs()).max(s.vtheta.abs()))
            .fold(0.0, f64::max)
    );
    if let Some(Record::Rig(rig)) = log.records.iter().find(|r| matches!(r, Record::Rig(_))) {
        eprintln!("euroc: rig {rig}");
    }
    assert_eq!(log.truncated, None);
    assert!(log.has_vehicle_topics());
    assert_eq!(frames.len(), 95, "one packet per stereo pair");
    assert_eq!(decoder.stats().corrupt, 0);
    assert!(!odom.is_empty());
}
