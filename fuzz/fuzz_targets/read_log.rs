//! The vehicle-log readers on arbitrary bytes: they never panic, every iteration ends (each
//! step consumes file bytes or yields a record held in memory), memory stays bounded (one
//! chunk at a time, at most `MAX_RECORD_LEN`; libFuzzer's -rss_limit_mb watches it), and the
//! damage report stays within the file.
#![no_main]

use std::io::Cursor;

use libfuzzer_sys::fuzz_target;
use vehicle_log::{LogReader, RawReader, RawRecord, Record};

fuzz_target!(|data: &[u8]| {
    let len = data.len() as u64;
    if let Ok(mut reader) = RawReader::new(Cursor::new(data), "fuzz.mcap") {
        for record in &mut reader {
            // Only an I/O error is an Err, and a Cursor has none.
            let record = record.expect("no I/O error on a Cursor");
            if let RawRecord::Lost(span) = &record {
                assert!(span.offset <= len);
            }
        }
        let damage = reader.damage();
        assert!(damage.bytes_lost <= len, "{damage:?}");
        assert!(damage.spans.len() as u64 <= damage.spans_total);
        assert!(reader.position() <= len);
    }
    if let Ok(reader) = LogReader::new(Cursor::new(data), "fuzz.mcap") {
        for record in reader {
            match record {
                Ok(Record::Lost(span)) => assert!(span.offset <= len),
                Ok(_) => {}
                // A malformed vehicle message ends the reading.
                Err(_) => break,
            }
        }
    }
});
