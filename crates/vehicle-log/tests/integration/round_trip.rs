//! Writing a log and reading it back (vehicle-interfaces.md section 4).
#![allow(clippy::unwrap_used, clippy::expect_used)]

use crate::common;

use std::collections::BTreeMap;
use std::io::Cursor;

use common::{Rng, exact, log_bytes, sample, stream_of, tmp, write_records};
use vehicle_log::{
    Error, LogReader, LogWriter, MAX_MESSAGE_LEN, OdomSample, Problem, Record, TruthLandmark,
    read_log, topics,
};

#[test]
fn a_written_log_reads_back_equal_and_bit_exact() {
    let records = sample(1, 3);
    let path = tmp("round_trip.mcap");
    let mut writer = LogWriter::create(&path).unwrap();
    write_records(&mut writer, &records);
    writer.finish().unwrap();

    let log = read_log(&path).unwrap();
    assert_eq!(log.records.len(), records.len());
    assert_eq!(log.records, records);
    assert_eq!(exact(&log.records), exact(&records));
    assert_eq!(log.truncated, None);
    assert!(log.warnings.is_empty(), "{:?}", log.warnings);
    assert_eq!((log.ignored_messages, log.ignored_topics.len()), (0, 0));
    assert_eq!(
        log.topics,
        [
            topics::RIG,
            topics::TRUTH_CAMERA,
            topics::TRUTH_LANDMARKS,
            topics::ODOM,
            topics::FEATURES,
            topics::TRUTH_POSE
        ]
    );
    assert!(log.has_vehicle_topics());
}

#[test]
fn the_streaming_reader_yields_the_same_records() {
    let records = sample(2, 2);
    let bytes = log_bytes(&records);
    let mut reader = LogReader::new(Cursor::new(&bytes), "in memory").unwrap();
    let mut streamed = Vec::new();
    for record in &mut reader {
        streamed.push(record.unwrap());
    }
    assert_eq!(exact(&streamed), exact(&records));
    assert_eq!(reader.truncated(), None);
    assert!(reader.has_vehicle_topics());
    assert!(reader.next().is_none(), "fused");
}

#[test]
fn chunk_boundaries_of_the_byte_stream_are_kept() {
    let mut rng = Rng(7);
    let mut enc = fpga_link::Encoder::starting_at(0);
    let stream: Vec<u8> = (0..20)
        .flat_map(|i| common::packet(&mut rng, &mut enc, 1_000_000 + 50_000 * i, 500))
        .collect();
    // Sizes 0, 1, odd, and one chunk larger than the writer's chunk target.
    let mut sizes = vec![0, 1, 2, 0, 3, 1_100_000];
    sizes.extend((0..200).map(|_| rng.below(700) as usize));
    let mut records = Vec::new();
    let mut at = 0;
    for (i, size) in sizes.into_iter().cycle().enumerate() {
        if at == stream.len() {
            break;
        }
        let end = (at + size).min(stream.len());
        records.push(Record::Features {
            log_time_ns: 1_000_000_000 + i as u64 * 100_000,
            bytes: stream[at..end].to_vec(),
        });
        at = end;
    }
    let log = LogReader::new(Cursor::new(log_bytes(&records)), "chunks")
        .unwrap()
        .into_log()
        .unwrap();
    assert_eq!(log.records, records);
    let read_stream = stream_of(&log.records);
    assert_eq!(read_stream, stream);

    // The board's decoder finds every packet in the concatenated chunks.
    let mut decoder = fpga_link::Decoder::new();
    let mut frames = 0;
    for record in &log.records {
        let Record::Features { bytes, .. } = record else {
            continue;
        };
        let mut rest = bytes.as_slice();
        loop {
            let (used, event) = decoder.decode(rest);
            rest = &rest[used..];
            match event {
                Some(fpga_link::Event::Frame(_)) => frames += 1,
                Some(fpga_link::Event::Corrupt(c)) => panic!("corrupt packet: {c}"),
                None => break,
            }
        }
    }
    assert_eq!(frames, 20);
}

#[test]
fn arrival_order_is_kept_even_where_log_times_go_backwards() {
    let odom = |t_us| {
        Record::Odom(OdomSample {
            t_us,
            vx: 0.5,
            vy: 0.0,
            vtheta: 0.1,
        })
    };
    let features = |log_time_ns, byte| Record::Features {
        log_time_ns,
        bytes: vec![byte; 3],
    };
    // Features arriving late, stamped by a host clock behind the odometry's.
    let records = vec![
        odom(1_000),
        features(900_000, 1),
        odom(1_010),
        features(2_000_000, 2),
        features(1_000_000, 3),
        odom(1_005),
        odom(0),
        features(0, 4),
    ];
    let log = LogReader::new(Cursor::new(log_bytes(&records)), "order")
        .unwrap()
        .into_log()
        .unwrap();
    assert_eq!(log.records, records);
}

#[test]
fn channels_schemas_and_log_times_are_as_the_interface_says() {
    let records = sample(3, 2);
    let bytes = log_bytes(&records);

    let summary = mcap::Summary::read(&bytes).unwrap().expect("a summary");
    let mut found = BTreeMap::new();
    for channel in summary.channels.values() {
        let schema = channel
            .schema
            .as_ref()
            .map(|s| (s.name.clone(), s.encoding.clone()));
        found.insert(
            channel.topic.clone(),
            (channel.message_encoding.clone(), schema),
        );
    }
    let json = |name: &str| {
        (
            "json".to_owned(),
            Some((name.to_owned(), "jsonschema".to_owned())),
        )
    };
    let expected = BTreeMap::from([
        (
            "/fpga/features".to_owned(),
            ("stereonav.fpga-link.v1".to_owned(), None),
        ),
        ("/odom".to_owned(), json("stereonav.Odometry")),
        ("/rig".to_owned(), json("stereonav.Rig")),
        ("/truth/camera".to_owned(), json("stereonav.TruthCamera")),
        (
            "/truth/landmarks".to_owned(),
            json("stereonav.TruthLandmarks"),
        ),
        ("/truth/pose".to_owned(), json("stereonav.TruthPose")),
    ]);
    assert_eq!(found, expected);
    let footer = mcap::read::footer(&bytes).unwrap();
    assert_ne!(footer.summary_crc, 0, "summary CRC written");
    assert!(!summary.chunk_indexes.is_empty());
    for chunk in &summary.chunk_indexes {
        assert_eq!(chunk.compression, "zstd");
    }
    // Chunks span at most a second of log time.
    for chunk in &summary.chunk_indexes {
        assert!(chunk.message_end_time - chunk.message_start_time < vehicle_log::CHUNK_SPAN_NS);
    }

    // Every message's log and publish times; the untimed ones take the first timed
    // message's time.
    let first_timed_ns = records
        .iter()
        .find_map(|r| match r {
            Record::Odom(s) => Some(s.t_us * 1000),
            Record::Features { log_time_ns, .. } => Some(*log_time_ns),
            _ => None,
        })
        .unwrap();
    let messages: Vec<_> = mcap::MessageStream::new(&bytes)
        .unwrap()
        .map(|m| m.unwrap())
        .collect();
    assert_eq!(messages.len(), records.len());
    let mut sequences = BTreeMap::<String, u32>::new();
    for (message, record) in messages.iter().zip(&records) {
        let expected_ns = match record {
            Record::Features { log_time_ns, .. } => *log_time_ns,
            Record::Odom(s) => s.t_us * 1000,
            Record::TruthPose(p) => p.t_us * 1000,
            _ => first_timed_ns,
        };
        assert_eq!(
            (message.log_time, message.publish_time),
            (expected_ns, expected_ns)
        );
        let sequence = sequences.entry(message.channel.topic.clone()).or_default();
        assert_eq!(message.sequence, *sequence);
        *sequence += 1;
        if let Record::Odom(s) = record {
            let value: serde_json::Value = serde_json::from_slice(&message.data).unwrap();
            assert_eq!(value["t_us"].as_u64(), Some(s.t_us));
            assert!(value["vx"].is_number());
        }
    }
}

#[test]
fn a_log_without_messages_reads_back_empty() {
    let bytes = LogWriter::new(Cursor::new(Vec::new()))
        .unwrap()
        .finish()
        .unwrap()
        .into_inner();
    let log = LogReader::new(Cursor::new(bytes), "empty log")
        .unwrap()
        .into_log()
        .unwrap();
    assert!(log.records.is_empty());
    assert_eq!(log.truncated, None);
    assert!(!log.has_vehicle_topics());
}

#[test]
fn untimed_messages_alone_are_kept() {
    let records = vec![
        Record::Rig("{}".to_owned()),
        Record::TruthLandmarks(vec![]),
        Record::TruthLandmarks(vec![TruthLandmark {
            id: 3,
            x: 1.0,
            y: 2.0,
            z: 3.0,
        }]),
    ];
    let log = LogReader::new(Cursor::new(log_bytes(&records)), "untimed")
        .unwrap()
        .into_log()
        .unwrap();
    assert_eq!(log.records, records);
    assert!(!log.has_vehicle_topics());
}

#[test]
fn the_writer_refuses_what_json_or_the_log_cannot_hold() {
    let mut writer = LogWriter::new(Cursor::new(Vec::new())).unwrap();
    let err = writer
        .odom(&OdomSample {
            t_us: 5,
            vx: 0.0,
            vy: f64::NAN,
            vtheta: 0.0,
        })
        .unwrap_err();
    assert!(matches!(
        &err,
        Error::BadInput { topic: "/odom", problem: Problem::NotFinite { key, .. } } if key == "vy"
    ));
    assert_eq!(
        err.to_string(),
        "cannot log /odom: key \"vy\" is NaN: JSON has no NaN or infinity"
    );

    let err = writer
        .truth_landmarks(&[TruthLandmark {
            id: 1,
            x: 0.0,
            y: f64::INFINITY,
            z: 0.0,
        }])
        .unwrap_err();
    assert_eq!(
        err.to_string(),
        "cannot log /truth/landmarks: key \"landmarks[0].y\" is inf: JSON has no NaN or infinity"
    );

    let err = writer.rig_json("[1, 2]").unwrap_err();
    assert_eq!(
        err.to_string(),
        "cannot log /rig: expected a JSON object, found an array"
    );
    assert!(matches!(
        writer.rig_json("{\"camera\": "),
        Err(Error::BadInput {
            problem: Problem::NotJson { .. },
            ..
        })
    ));

    let err = writer
        .odom(&OdomSample {
            t_us: u64::MAX,
            vx: 0.0,
            vy: 0.0,
            vtheta: 0.0,
        })
        .unwrap_err();
    assert!(err.to_string().contains("must fit 64 bits"), "{err}");

    let err = writer
        .features(0, &vec![0; MAX_MESSAGE_LEN + 1])
        .unwrap_err();
    assert!(matches!(err, Error::TooLarge { len, .. } if len == MAX_MESSAGE_LEN + 1));

    // Refused calls leave nothing behind.
    let bytes = writer.finish().unwrap().into_inner();
    let log = LogReader::new(Cursor::new(bytes), "refused")
        .unwrap()
        .into_log()
        .unwrap();
    assert!(log.records.is_empty());
    assert_eq!(log.truncated, None);
}

#[test]
fn create_reports_the_path_it_could_not_create() {
    let path = tmp("no such folder").join("log.mcap");
    let err = LogWriter::create(&path).unwrap_err();
    assert!(matches!(err, Error::Create { .. }));
    assert!(err.to_string().contains("no such folder"), "{err}");
}
