//! Where the records of an undamaged MCAP file lie, and which messages each chunk holds, read
//! with the `mcap` crate from the file's summary (its chunk index): damage that does not touch
//! a chunk's bytes must not lose its messages. Shared by the fault-injection tests and the
//! damage Monte Carlo example (`examples/damage_mc.rs`).
#![allow(dead_code, unreachable_pub, clippy::unwrap_used, clippy::expect_used)]

use std::collections::HashMap;
use std::ops::Range;

use mcap::records::{self, op};

/// A message, identified by everything it holds.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct Key {
    pub channel_id: u16,
    pub sequence: u32,
    pub log_time: u64,
    pub publish_time: u64,
    pub data: Vec<u8>,
}

/// One chunk record and what follows it up to the next chunk.
#[derive(Debug, Clone)]
pub struct ChunkSpan {
    /// The chunk record, header included.
    pub record: Range<u64>,
    /// Its compressed records.
    pub data: Range<u64>,
    /// Its message index records.
    pub index: Range<u64>,
    /// Its messages in order.
    pub messages: Vec<Key>,
}

/// The layout of an undamaged file.
#[derive(Debug, Clone)]
pub struct Layout {
    pub len: u64,
    /// Magic and header record.
    pub head: Range<u64>,
    pub chunks: Vec<ChunkSpan>,
    /// Summary section (schemas, channels, indexes, statistics, summary offsets).
    pub summary: Range<u64>,
    /// Footer record and closing magic.
    pub footer: Range<u64>,
    /// Topic of each channel.
    pub topics: HashMap<u16, String>,
}

fn le_u64(b: &[u8], at: usize) -> u64 {
    u64::from_le_bytes(b[at..at + 8].try_into().unwrap())
}

impl Layout {
    /// The layout of the undamaged `bytes` (panics on a file without a chunk index).
    pub fn of(bytes: &[u8]) -> Layout {
        let len = bytes.len() as u64;
        let summary = mcap::Summary::read(bytes).unwrap().expect("a summary");
        assert!(!summary.chunk_indexes.is_empty(), "a chunk index");
        let header_len = le_u64(bytes, 9);
        let footer_at = len - 8 - 29;
        let summary_start = le_u64(bytes, footer_at as usize + 9);
        let mut chunks = Vec::new();
        let mut indexes = summary.chunk_indexes.clone();
        indexes.sort_by_key(|c| c.chunk_start_offset);
        for c in &indexes {
            let start = c.chunk_start_offset;
            let end = start + c.chunk_length;
            let record = &bytes[start as usize..end as usize];
            assert_eq!(record[0], op::CHUNK);
            let body = &record[9..];
            let Ok(records::Record::Chunk { header, data }) = mcap::parse_record(op::CHUNK, body)
            else {
                panic!("chunk at {start}");
            };
            let data_at = c.compressed_data_offset().unwrap();
            let mut messages = Vec::new();
            for r in mcap::read::ChunkReader::new(header, &data).unwrap() {
                if let records::Record::Message { header, data } = r.unwrap() {
                    messages.push(Key {
                        channel_id: header.channel_id,
                        sequence: header.sequence,
                        log_time: header.log_time,
                        publish_time: header.publish_time,
                        data: data.into_owned(),
                    });
                }
            }
            let index_start = c
                .message_index_offsets
                .values()
                .min()
                .copied()
                .unwrap_or(end);
            chunks.push(ChunkSpan {
                record: start..end,
                data: data_at..end,
                index: index_start..index_start + c.message_index_length,
                messages,
            });
        }
        Layout {
            len,
            head: 0..8 + 9 + header_len,
            chunks,
            summary: summary_start..footer_at,
            footer: footer_at..len,
            topics: summary
                .channels
                .iter()
                .map(|(id, c)| (*id, c.topic.clone()))
                .collect(),
        }
    }

    /// The byte ranges of each kind of record, for damage aimed at each: magic and header,
    /// chunk headers, compressed data, message indexes, summary, footer.
    pub fn classes(&self) -> Vec<(&'static str, Vec<Range<u64>>)> {
        vec![
            ("magic and header", vec![self.head.clone()]),
            (
                "chunk header",
                self.chunks
                    .iter()
                    .map(|c| c.record.start..c.data.start)
                    .collect(),
            ),
            (
                "compressed data",
                self.chunks.iter().map(|c| c.data.clone()).collect(),
            ),
            (
                "message index",
                self.chunks
                    .iter()
                    .map(|c| c.index.clone())
                    .filter(|r| !r.is_empty())
                    .collect(),
            ),
            ("summary", vec![self.summary.clone()]),
            ("footer", vec![self.footer.clone()]),
        ]
    }

    /// Every message, in file order.
    pub fn messages(&self) -> impl Iterator<Item = &Key> {
        self.chunks.iter().flat_map(|c| &c.messages)
    }

    /// The messages of the chunks whose bytes `touched(range)` says the damage spares.
    pub fn spared<'a>(
        &'a self,
        touched: impl Fn(&Range<u64>) -> bool + 'a,
    ) -> impl Iterator<Item = &'a Key> {
        self.chunks
            .iter()
            .filter(move |c| !touched(&c.record))
            .flat_map(|c| &c.messages)
    }
}

/// Damage done to a file: bit flips at byte offsets, and a cut.
#[derive(Debug, Clone, Default)]
pub struct Damage {
    /// (byte offset, bit) flipped.
    pub flips: Vec<(u64, u8)>,
    /// The file is cut to this length.
    pub cut: Option<u64>,
}

impl Damage {
    pub fn apply(&self, bytes: &[u8]) -> Vec<u8> {
        let mut out = bytes.to_vec();
        for &(at, bit) in &self.flips {
            if let Some(b) = out.get_mut(at as usize) {
                *b ^= 1 << bit;
            }
        }
        if let Some(cut) = self.cut {
            out.truncate(cut as usize);
        }
        out
    }

    /// Whether the damage touches the bytes `range` (a flip inside, or a cut before its end).
    pub fn touches(&self, range: &Range<u64>) -> bool {
        self.flips.iter().any(|(at, _)| range.contains(at))
            || self.cut.is_some_and(|c| c < range.end)
    }
}
