//! Fault injection: every kind of record (magic and header, chunk headers, compressed data,
//! message indexes, summary, footer) flipped and cut, in logs of our writer and of the
//! reference Python `mcap` writer (32 KiB zstd chunks). Never a panic, never an error but
//! for files too short to be MCAP, and nothing readable lost: every message of every chunk
//! whose bytes the damage spares comes out, and every message of a chunk whose CRC checked
//! is one that was written.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::print_stderr)]

use crate::common;

use std::collections::HashSet;
use std::io::Cursor;
use std::path::Path;

use common::layout::{Damage, Key, Layout};
use proptest::prelude::*;
use vehicle_log::{Error, LogReader, RawReader, RawRecord, Record, SummaryState};

fn fixture(name: &str) -> Vec<u8> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/logs")
        .join(name);
    std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// The logs damaged here: ours (1 s chunks) and the reference Python writer's (32 KiB).
const LOGS: [&str; 2] = ["paper-experiment.mcap", "paper-experiment-pymcap.mcap"];

/// What a damaged file gave.
#[derive(Debug)]
struct Outcome {
    /// Every message read.
    messages: Vec<Key>,
    /// The vehicle-level records (LogReader), Lost included.
    records: Vec<Record>,
    damage: vehicle_log::Damage,
}

/// Reads `bytes` damaged by `damage` with both readers and checks the contract; `None` for a
/// file too short to be MCAP.
fn check(layout: &Layout, bytes: &[u8], damage: &Damage, what: &str) -> Option<Outcome> {
    let damaged = damage.apply(bytes);
    let reader = match RawReader::new(Cursor::new(&damaged), "damaged.mcap") {
        Err(Error::NotMcap { .. }) if damaged.len() < 8 => return None,
        Err(err) => panic!("{what}: {err}"),
        Ok(reader) => reader,
    };
    let written: HashSet<&Key> = layout.messages().collect();
    let mut messages = Vec::new();
    let mut reader = reader;
    // The sweep checks what is lost; mending a single flipped bit (tested below) would turn
    // every one-flip copy into a search of seconds.
    reader.mend_bit_errors(false);
    for record in &mut reader {
        if let RawRecord::Message(m) = record.unwrap() {
            let key = Key {
                channel_id: m.channel_id,
                sequence: m.sequence,
                log_time: m.log_time,
                publish_time: m.publish_time,
                data: m.data,
            };
            if m.verified {
                assert!(
                    written.contains(&key),
                    "{what}: a verified message not written"
                );
            }
            messages.push(key);
        }
    }
    let got: HashSet<&Key> = messages.iter().collect();
    let lost: Vec<&Key> = layout
        .spared(|r| damage.touches(r))
        .filter(|k| !got.contains(k))
        .collect();
    assert!(
        lost.is_empty(),
        "{what}: {} messages of spared chunks lost (first at log time {}); damage {:?}",
        lost.len(),
        lost[0].log_time,
        reader.damage()
    );
    let damage_report = reader.damage().clone();
    assert!(
        damage_report.bytes_lost <= damaged.len() as u64,
        "{what}: {damage_report:?}"
    );
    if damage.flips.is_empty() && damage.cut.is_none() {
        assert!(damage_report.is_clean(), "{what}: {damage_report:?}");
    }
    let log = LogReader::new(Cursor::new(&damaged), "damaged.mcap")
        .and_then(|mut r| {
            r.mend_bit_errors(false);
            r.into_log()
        })
        .unwrap_or_else(|e| panic!("{what}: {e}"));
    assert_eq!(log.damage, damage_report, "{what}");
    Some(Outcome {
        messages,
        records: log.records,
        damage: damage_report,
    })
}

/// Offsets to damage in `range`: its ends, its middle and a few in between.
fn offsets(range: &std::ops::Range<u64>, rng: &mut common::Rng) -> Vec<u64> {
    if range.is_empty() {
        return Vec::new();
    }
    let (a, b) = (range.start, range.end - 1);
    let mut v = vec![
        a,
        (a + 1).min(b),
        a + (b - a) / 2,
        b.saturating_sub(1).max(a),
        b,
    ];
    v.extend((0..3).map(|_| a + rng.below(b - a + 1)));
    v.sort_unstable();
    v.dedup();
    v
}

fn every_kind_flipped_and_cut(name: &str) {
    let bytes = fixture(name);
    let layout = Layout::of(&bytes);
    assert!(
        layout.chunks.len() >= 3,
        "{name}: {} chunks",
        layout.chunks.len()
    );
    check(&layout, &bytes, &Damage::default(), name).unwrap();
    let mut rng = common::Rng(7);
    let mut cases = 0;
    for (class, ranges) in layout.classes() {
        // The first, a middle and the last record of the class.
        let n = ranges.len();
        let picked: Vec<_> = [0, n / 2, n.saturating_sub(1)]
            .into_iter()
            .filter_map(|i| ranges.get(i))
            .collect();
        for range in picked {
            for at in offsets(range, &mut rng) {
                let bit = (rng.below(8)) as u8;
                let flip = Damage {
                    flips: vec![(at, bit)],
                    cut: None,
                };
                check(
                    &layout,
                    &bytes,
                    &flip,
                    &format!("{name}: {class}: bit {bit} at {at}"),
                );
                let cut = Damage {
                    flips: Vec::new(),
                    cut: Some(at),
                };
                check(
                    &layout,
                    &bytes,
                    &cut,
                    &format!("{name}: {class}: cut at {at}"),
                );
                cases += 2;
            }
        }
    }
    eprintln!("{name}: {cases} damaged copies checked");
}

#[test]
fn every_kind_of_record_flipped_and_cut_in_a_log_of_our_writer() {
    every_kind_flipped_and_cut(LOGS[0]);
}

#[test]
fn every_kind_of_record_flipped_and_cut_in_a_log_of_the_python_writer() {
    every_kind_flipped_and_cut(LOGS[1]);
}

/// The vehicle records of the messages of chunk `i`.
fn lost_span_before(records: &[Record], first_after: usize) -> Option<&vehicle_log::LostSpan> {
    match records.get(first_after.checked_sub(1)?) {
        Some(Record::Lost(span)) => Some(span),
        _ => None,
    }
}

#[test]
fn a_damaged_chunk_is_one_lost_span_with_its_place_times_and_counts() {
    let bytes = fixture(LOGS[1]);
    let layout = Layout::of(&bytes);
    // The first chunk holds the channel records: the summary's stand in for them.
    for k in [0, layout.chunks.len() / 2] {
        let chunk = &layout.chunks[k];
        let at = chunk.data.start + (chunk.data.end - chunk.data.start) / 2;
        let damage = Damage {
            flips: vec![(at, 3)],
            cut: None,
        };
        let out = check(&layout, &bytes, &damage, &format!("chunk {k}")).unwrap();
        assert_eq!(out.damage.spans_total, 1, "{:?}", out.damage);
        assert_eq!(out.damage.chunks_lost, 1);
        assert_eq!(out.damage.summary, SummaryState::Intact);
        let span = &out.damage.spans[0];
        assert_eq!(span.offset, chunk.record.start);
        assert_eq!(span.bytes, chunk.record.end - chunk.record.start);
        assert!(span.exact_times);
        let first = chunk.messages.iter().map(|m| m.log_time).min();
        let last = chunk.messages.iter().map(|m| m.log_time).max();
        assert_eq!((span.start_ns, span.end_ns), (first, last));
        // Counts per topic, from the message index after the chunk.
        let mut expected = std::collections::BTreeMap::<String, u64>::new();
        for m in &chunk.messages {
            *expected
                .entry(layout.topics[&m.channel_id].clone())
                .or_default() += 1;
        }
        assert_eq!(span.messages.as_ref(), Some(&expected));
        assert_eq!(out.damage.messages_lost.as_ref(), Some(&expected));
        assert!(span.why.contains("CRC"), "{}", span.why);
        // Every other message is read, and in band the loss sits where the chunk was.
        assert_eq!(
            out.messages.len(),
            layout.messages().count() - chunk.messages.len()
        );
        let lost_at = out
            .records
            .iter()
            .position(|r| matches!(r, Record::Lost(_)))
            .unwrap();
        assert_eq!(lost_span_before(&out.records, lost_at + 1), Some(span));
        assert_eq!(
            out.records
                .iter()
                .filter(|r| matches!(r, Record::Lost(_)))
                .count(),
            1
        );
    }
}

/// A log of one channel in chunks of about 600 kB uncompressed (the mcap crate's writer):
/// several zstd blocks a chunk, so that a chunk's prefix holds whole blocks.
fn big_chunk_log(compression: Option<mcap::Compression>) -> Vec<u8> {
    let mut writer = mcap::WriteOptions::new()
        .compression(compression)
        .chunk_size(Some(600_000))
        .create(Cursor::new(Vec::new()))
        .unwrap();
    let channel = writer
        .add_channel(0, "/camera/raw", "raw-bytes", &Default::default())
        .unwrap();
    let mut rng = common::Rng(3);
    for i in 0..3000u32 {
        // Compressible (a few distinct bytes) but not to nothing.
        let data: Vec<u8> = (0..1000).map(|_| b"abcd"[rng.below(4) as usize]).collect();
        let header = mcap::records::MessageHeader {
            channel_id: channel,
            sequence: i,
            log_time: u64::from(i) * 1_000_000,
            publish_time: u64::from(i) * 1_000_000,
        };
        writer.write_to_known_channel(&header, &data).unwrap();
    }
    writer.finish().unwrap();
    writer.into_inner().into_inner()
}

#[test]
fn a_log_cut_inside_a_chunk_reads_what_its_prefix_holds() {
    for compression in [
        Some(mcap::Compression::Zstd),
        Some(mcap::Compression::Lz4),
        None,
    ] {
        let bytes = big_chunk_log(compression);
        let layout = Layout::of(&bytes);
        let chunk = &layout.chunks[1];
        let cut = chunk.data.start + (chunk.data.end - chunk.data.start) * 3 / 4;
        let damage = Damage {
            flips: Vec::new(),
            cut: Some(cut),
        };
        let what = format!("{compression:?} cut at {cut}");
        let out = check(&layout, &bytes, &damage, &what).unwrap();
        let before = layout.chunks[0].messages.len();
        // More than the whole chunk before the cut: part of the cut chunk is read, a prefix
        // of its messages.
        let got = out.messages.len();
        assert!(got > before, "{what}: {got} <= {before}");
        assert!(got < before + chunk.messages.len());
        assert_eq!(out.messages[before..], chunk.messages[..got - before]);
        assert!(out.damage.cut);
        assert_eq!(out.damage.unverified_chunks, 1);
        let span = out.damage.spans.last().unwrap();
        assert!(span.why.contains("cut short"), "{}", span.why);
        assert_eq!(span.start_ns, out.messages.last().map(|m| m.log_time));
        assert_eq!(span.end_ns, chunk.messages.last().map(|m| m.log_time));
    }
}

#[test]
fn a_vehicle_log_cut_inside_a_chunk_keeps_every_whole_chunk_and_says_it_is_cut() {
    for name in LOGS {
        let bytes = fixture(name);
        let layout = Layout::of(&bytes);
        let chunk = &layout.chunks[layout.chunks.len() / 2];
        // Half the log, inside a compressed chunk (the case).
        let cut = chunk.data.start + (chunk.data.end - chunk.data.start) / 2;
        let damage = Damage {
            flips: Vec::new(),
            cut: Some(cut),
        };
        let out = check(&layout, &bytes, &damage, &format!("{name} cut at {cut}")).unwrap();
        let before: usize = layout
            .chunks
            .iter()
            .take_while(|c| c.record.end <= cut)
            .map(|c| c.messages.len())
            .sum();
        assert!(out.messages.len() >= before);
        assert!(matches!(out.records.last(), Some(Record::Lost(_))));
        let log = LogReader::new(Cursor::new(damage.apply(&bytes)), "cut.mcap")
            .unwrap()
            .into_log()
            .unwrap();
        assert!(log.has_vehicle_topics(), "{name}: {:?}", log.topics);
        assert!(log.truncated.unwrap().contains("cut short"));
    }
}

#[test]
fn the_first_chunk_and_the_summary_damaged_together_orphan_no_message() {
    // The Python writer declares every channel in the first chunk only: with the summary's
    // CRC failing too, the channels that still parse in the summary stand in for them.
    let bytes = fixture(LOGS[1]);
    let layout = Layout::of(&bytes);
    let first = &layout.chunks[0];
    let damage = Damage {
        flips: vec![
            ((first.data.start + first.data.end) / 2, 7),
            (layout.summary.end - 20, 1),
        ],
        cut: None,
    };
    let out = check(&layout, &bytes, &damage, "first chunk and summary").unwrap();
    assert!(matches!(out.damage.summary, SummaryState::Damaged { .. }));
    let vehicle = out
        .records
        .iter()
        .filter(|r| matches!(r, Record::Odom(_)))
        .count();
    assert!(vehicle > 4000, "{vehicle}");
}

#[test]
fn a_damaged_magic_is_read_past_and_reported() {
    for name in LOGS {
        let bytes = fixture(name);
        let layout = Layout::of(&bytes);
        for at in [0, 3, 7] {
            let damage = Damage {
                flips: vec![(at, 1)],
                cut: None,
            };
            let out = check(&layout, &bytes, &damage, &format!("{name} magic {at}")).unwrap();
            assert_eq!(out.messages.len(), layout.messages().count());
            assert!(out.damage.header_damaged);
            assert!(!out.damage.is_clean());
            // Cut as well (no closing magic): a chunk whose CRC checks still shows it is MCAP.
            let both = Damage {
                flips: vec![(at, 1)],
                cut: Some(bytes.len() as u64 / 2),
            };
            let out = check(&layout, &bytes, &both, &format!("{name} magic {at}, cut")).unwrap();
            assert!(!out.messages.is_empty());
        }
    }
}

#[test]
fn files_that_are_not_mcap_are_still_refused() {
    let png = b"\x89PNG\r\n\x1a\n\0\0\0\rIHDR\0\0\0\x01\0\0\0\x01\x08\0\0\0\0:~\x9bU";
    for bytes in [&png[..], b"", b"\x89MCA", &[0x06; 4000][..]] {
        let err = RawReader::new(Cursor::new(bytes), "x.mcap").unwrap_err();
        assert!(matches!(err, Error::NotMcap { .. }), "{err}");
    }
    // Our own log without its magic and without its end is not refused: its chunks check.
    let bytes = fixture(LOGS[0]);
    let mut headless = bytes[..bytes.len() - 100].to_vec();
    headless[..8].copy_from_slice(b"PNG junk");
    assert!(RawReader::new(Cursor::new(headless), "x.mcap").is_ok());
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]

    /// Random bit flips and a random cut, anywhere.
    #[test]
    fn random_flips_and_cuts_lose_only_what_they_touch(
        log in 0usize..2,
        flips in proptest::collection::vec((0.0f64..1.0, 0u8..8), 0..11),
        cut in proptest::option::of(0.0f64..1.0),
    ) {
        let bytes = fixture(LOGS[log]);
        let layout = layout_of(log, &bytes);
        let len = bytes.len() as f64;
        let damage = Damage {
            flips: flips.iter().map(|&(x, bit)| ((x * len) as u64, bit)).collect(),
            cut: cut.map(|x| (x * len) as u64),
        };
        check(&layout, &bytes, &damage, &format!("{damage:?}"));
    }
}

/// The layouts of the two logs, computed once.
fn layout_of(log: usize, bytes: &[u8]) -> Layout {
    use std::sync::OnceLock;
    static LAYOUTS: [OnceLock<Layout>; 2] = [OnceLock::new(), OnceLock::new()];
    LAYOUTS[log].get_or_init(|| Layout::of(bytes)).clone()
}

/// One flipped bit in a chunk (its compressed records, its stored CRC, its size field) is
/// mended, vouched for by the CRC: every message comes out as written and nothing is lost;
/// two flipped bits in one chunk are not mended (the chunk is lost, nothing wrong comes out).
#[test]
fn a_chunk_with_one_flipped_bit_is_mended() {
    let bytes = fixture(LOGS[1]);
    let layout = Layout::of(&bytes);
    let read = |damaged: &[u8]| {
        LogReader::new(Cursor::new(damaged.to_vec()), "damaged.mcap")
            .and_then(LogReader::into_log)
            .unwrap()
    };
    let clean = read(&bytes);
    let chunk = &layout.chunks[layout.chunks.len() / 2];
    // The chunk record: opcode, length, start and end times, uncompressed size (at +25), CRC
    // (at +33), compression, records length, records.
    let crc_at = chunk.record.start as usize + 1 + 8 + 8 + 8 + 8;
    let size_at = chunk.record.start as usize + 1 + 8 + 8 + 8;
    let data_at = (chunk.data.start + (chunk.data.end - chunk.data.start) / 3) as usize;
    for (what, at, bit) in [
        ("compressed records", data_at, 5),
        ("stored CRC", crc_at + 1, 2),
        ("uncompressed size", size_at + 2, 6),
    ] {
        let mut damaged = bytes.clone();
        damaged[at] ^= 1 << bit;
        let log = read(&damaged);
        assert_eq!(log.damage.repaired_chunks, 1, "{what}: {:?}", log.damage);
        assert_eq!(log.damage.spans_total, 0, "{what}: {:?}", log.damage);
        assert_eq!(log.records, clean.records, "{what}");
    }
    let mut twice = bytes.clone();
    twice[data_at] ^= 1 << 5;
    twice[data_at + 40] ^= 1 << 1;
    let log = read(&twice);
    assert_eq!(log.damage.repaired_chunks, 0, "{:?}", log.damage);
    assert_eq!(log.damage.chunks_lost, 1, "{:?}", log.damage);
    assert!(
        log.records
            .iter()
            .all(|r| matches!(r, Record::Lost(_)) || clean.records.contains(r)),
        "a record that was not written"
    );
}
