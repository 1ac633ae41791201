//! Logs cut short, damaged, or not logs at all: never a panic, a prefix of the records or a
//! clear error.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use crate::common;

use std::cell::RefCell;
use std::io::{Cursor, Seek, SeekFrom, Write};
use std::rc::Rc;

use common::{Rng, log_bytes, sample, tmp, write_records};
use vehicle_log::{Error, Log, LogReader, LogWriter, NotMcap, Record, read_log};

fn read(bytes: &[u8]) -> vehicle_log::Result<Log> {
    LogReader::new(Cursor::new(bytes), "damaged.mcap")?.into_log()
}

/// The records without the [`Record::Lost`] markers.
fn data(records: &[Record]) -> Vec<Record> {
    records
        .iter()
        .filter(|r| !matches!(r, Record::Lost(_)))
        .cloned()
        .collect()
}

fn assert_prefix(got: &[Record], all: &[Record], what: &str) {
    let got = data(got);
    assert!(got.len() <= all.len(), "{what}");
    assert!(got == all[..got.len()], "{what}");
}

#[test]
fn a_log_cut_at_any_offset_reads_a_prefix_of_its_records() {
    let records = sample(11, 3);
    let bytes = log_bytes(&records);
    let len = bytes.len();
    let full = read(&bytes).unwrap();
    assert_eq!(full.records.len(), records.len());

    // Every offset near the start and the end (header, summary, footer), and a stride
    // through the data section.
    let mut cuts: Vec<usize> = (0..300).chain(len.saturating_sub(600)..len).collect();
    cuts.extend((300..len).step_by(37));
    let mut previous = 0;
    cuts.sort_unstable();
    cuts.dedup();
    for cut in cuts {
        match read(&bytes[..cut]) {
            Err(Error::NotMcap { why, .. }) => {
                assert!(cut < mcap::MAGIC.len(), "cut {cut}: {why}");
                let expected = if cut == 0 {
                    NotMcap::Empty
                } else {
                    NotMcap::ShorterThanMagic {
                        len: cut,
                        magic_len: 8,
                    }
                };
                assert_eq!(why, expected);
            }
            Err(other) => panic!("cut at {cut} of {len}: {other}"),
            Ok(log) => {
                assert!(cut >= mcap::MAGIC.len());
                let reason = log.truncated.as_deref().expect("a cut log says so");
                assert!(reason.contains("cut short"), "cut {cut}: {reason}");
                assert_prefix(&log.records, &records, &format!("cut {cut}"));
                // More bytes never read fewer records.
                let n = data(&log.records).len();
                assert!(n >= previous, "cut {cut}");
                previous = n;
            }
        }
    }
    // Cut inside the summary: every record was read.
    let log = read(&bytes[..len - 10]).unwrap();
    assert_eq!(log.records.len(), records.len());
    assert!(log.truncated.unwrap().contains("summary"));
}

#[test]
fn a_cut_log_file_on_disk_reads_a_prefix() {
    let records = sample(12, 2);
    let bytes = log_bytes(&records);
    let path = tmp("cut.mcap");
    std::fs::write(&path, &bytes[..bytes.len() * 2 / 3]).unwrap();
    let log = read_log(&path).unwrap();
    assert!(log.truncated.is_some());
    assert!(!log.records.is_empty());
    assert_prefix(&log.records, &records, "two thirds");
}

/// A seekable output whose bytes can be looked at while the writer still holds it, as a
/// power loss would leave them on disk.
#[derive(Clone, Default)]
struct Shared(Rc<RefCell<Cursor<Vec<u8>>>>);

impl Write for Shared {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.0.borrow_mut().write(buf)
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

impl Seek for Shared {
    fn seek(&mut self, pos: SeekFrom) -> std::io::Result<u64> {
        self.0.borrow_mut().seek(pos)
    }
}

#[test]
fn power_lost_while_recording_loses_at_most_the_chunk_being_written() {
    let records = sample(13, 4);
    let out = Shared::default();
    let mut writer = LogWriter::new(out.clone()).unwrap();
    let mut best = 0;
    for (i, record) in records.iter().enumerate() {
        write_records(&mut writer, std::slice::from_ref(record));
        if i % 7 != 0 {
            continue;
        }
        // The bytes on disk at this moment, with the writer still running.
        let snapshot = out.0.borrow().get_ref().clone();
        let log = read(&snapshot).unwrap();
        assert!(log.truncated.is_some(), "after record {i}");
        assert_prefix(&log.records, &records, &format!("after record {i}"));
        let n = data(&log.records).len();
        assert!(n >= best);
        best = n;
        // Chunks close every second of log time: the loss is at most about 1.1 s of
        // records (100 odometry + 20 packets in several chunks + 20 poses a second).
        let lost = i + 1 - n;
        assert!(lost < 400, "after record {i}: {lost} records lost");
    }
    // flush() makes everything so far readable.
    writer.flush().unwrap();
    let snapshot = out.0.borrow().get_ref().clone();
    assert_eq!(read(&snapshot).unwrap().records.len(), records.len());
    drop(writer);
}

#[test]
fn garbage_and_empty_files_are_clear_errors() {
    let path = tmp("empty.mcap");
    std::fs::write(&path, b"").unwrap();
    let err = read_log(&path).unwrap_err();
    assert_eq!(
        err.to_string(),
        format!("{} is not an MCAP file: it is empty", path.display())
    );

    let path = tmp("text.mcap");
    std::fs::write(&path, b"t_us,x,y,theta\n0,0,0,0\n").unwrap();
    let err = read_log(&path).unwrap_err();
    assert_eq!(
        err.to_string(),
        format!(
            "{} is not an MCAP file: it starts with 74 5f 75 73 2c 78 2c 79, \
             not the MCAP magic 89 4d 43 41 50 30 0d 0a",
            path.display()
        )
    );

    let mut rng = Rng(99);
    for len in [1, 7, 8, 9, 100, 5000] {
        let bytes: Vec<u8> = (0..len).map(|_| rng.next_u64() as u8).collect();
        assert!(matches!(read(&bytes), Err(Error::NotMcap { .. })), "{len}");
    }
}

#[test]
fn garbage_after_the_magic_never_panics() {
    let mut rng = Rng(5);
    for round in 0..300 {
        let len = rng.below(3000) as usize;
        let mut bytes = mcap::MAGIC.to_vec();
        bytes.extend((0..len).map(|_| rng.next_u64() as u8));
        // Sometimes a plausible record header: a chunk or a message opcode with a small or
        // huge length.
        if round % 3 == 0 && bytes.len() > 17 {
            bytes[8] = [0x01, 0x04, 0x05, 0x06][round % 4];
            let record_len: u64 = if round % 2 == 0 { 40 } else { u64::MAX - 3 };
            bytes[9..17].copy_from_slice(&record_len.to_le_bytes());
        }
        match read(&bytes) {
            Ok(log) => assert!(log.truncated.is_some(), "round {round}"),
            Err(Error::BadMessage { .. }) => {}
            Err(other) => panic!("round {round}: {other}"),
        }
    }
}

#[test]
fn flipped_bits_never_panic_and_never_pass_unnoticed() {
    let records = sample(21, 2);
    let bytes = log_bytes(&records);
    let mut rng = Rng(77);
    for _ in 0..400 {
        let mut damaged = bytes.clone();
        let at = rng.below(damaged.len() as u64) as usize;
        damaged[at] ^= 1 << rng.below(8);
        match read(&damaged) {
            Ok(log) => {
                // Records come only from chunks whose CRC checks: each is one of ours, in
                // order, and any loss is reported.
                let mut all = records.iter();
                for record in &data(&log.records) {
                    assert!(
                        all.any(|r| r == record),
                        "flip at {at}: a record not written: {record:?}\n{:?}",
                        log.damage
                    );
                }
                if data(&log.records) != records {
                    assert!(!log.damage.is_clean(), "flip at {at}: loss not reported");
                }
            }
            Err(Error::NotMcap { .. }) => assert!(at < 8),
            // A flip that turns a record into a message outside the chunks' CRCs.
            Err(Error::BadMessage { .. }) => {}
            Err(other) => panic!("flip at {at}: {other}"),
        }
    }
}

#[test]
fn a_missing_file_names_its_path() {
    let path = tmp("does-not-exist.mcap");
    let err = read_log(&path).unwrap_err();
    assert!(matches!(err, Error::Open { .. }));
    assert!(
        err.to_string()
            .starts_with(&format!("cannot open {}: ", path.display())),
        "{err}"
    );
    let dir_err = read_log(tmp("")).unwrap_err();
    assert!(
        matches!(dir_err, Error::Read { .. } | Error::Open { .. }),
        "{dir_err:?}"
    );
}
