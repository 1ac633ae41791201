//! `stereonav log recover`: every readable record of a damaged MCAP file, written again as a
//! clean one.

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

use mcap::records::MessageHeader;
use mcap::{Compression, WriteOptions};

use crate::damage::Damage;
use crate::error::{Error, Result};
use crate::raw::{RawReader, RawRecord};
use crate::writer::CHUNK_TARGET_BYTES;

/// What [`recover`] wrote and what it could not.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
#[non_exhaustive]
pub struct Recovery {
    /// Schemas written.
    pub schemas: u64,
    /// Channels written.
    pub channels: u64,
    /// Messages written.
    pub messages: u64,
    /// Messages written per topic.
    pub messages_per_topic: BTreeMap<String, u64>,
    /// Messages not written because no readable channel record declares their channel
    /// (its record was lost and the summary does not have it).
    pub undeclared: u64,
    /// Channels whose schema was lost: written without a schema (schema id 0).
    pub schemaless: Vec<String>,
    /// What the input lost.
    pub damage: Damage,
}

/// Reads the MCAP file `input` as [`RawReader`] does (every readable schema, channel and
/// message, past any damage) and writes them to `output` as a clean MCAP file: in the same
/// order, with their ids, sequence numbers and times, in zstd chunks with CRCs, message
/// indexes and a summary section. Attachments and metadata records are not copied.
/// `progress(done, total)` is called with the bytes of `input` read so far.
///
/// Errors: `output` is `input` ([`Error::SameFile`]), `input` cannot be read or is not MCAP,
/// `output` cannot be written.
pub fn recover(
    input: &Path,
    output: &Path,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<Recovery> {
    if same_file(input, output) {
        return Err(Error::SameFile {
            path: output.to_path_buf(),
        });
    }
    let mut reader = RawReader::open(input)?;
    let file = File::create(output).map_err(|source| Error::Create {
        path: output.to_path_buf(),
        source,
    })?;
    let mut writer = WriteOptions::new()
        .compression(Some(Compression::Zstd))
        .chunk_size(Some(CHUNK_TARGET_BYTES))
        .compression_threads(0)
        .library(format!(
            "stereonav log recover {} ({})",
            env!("CARGO_PKG_VERSION"),
            mcap::LIBRARY_IDENTIFIER
        ))
        .create(BufWriter::new(file))
        .map_err(Error::from_mcap_write)?;
    let mut recovery = Recovery::default();
    // Input ids to the ids the writer gave (the same, unless two records had equal content).
    let mut schemas: HashMap<u16, u16> = HashMap::new();
    let mut channels: HashMap<u16, (u16, String)> = HashMap::new();
    let total = reader.file_len();
    let mut records = 0u64;
    while let Some(record) = reader.next() {
        records += 1;
        if records.is_multiple_of(4096) {
            progress(reader.position(), total);
        }
        match record? {
            RawRecord::Schema(schema) => {
                let id = writer
                    .add_schema_with_id(schema.id, &schema.name, &schema.encoding, &schema.data)
                    .map_err(Error::from_mcap_write)?;
                schemas.insert(schema.id, id);
                recovery.schemas += 1;
            }
            RawRecord::Channel(channel) => {
                let schema_id = match channel.schema_id {
                    0 => 0,
                    id => schemas.get(&id).copied().unwrap_or_else(|| {
                        recovery.schemaless.push(channel.topic.clone());
                        0
                    }),
                };
                let id = writer
                    .add_channel_with_id(
                        channel.id,
                        schema_id,
                        &channel.topic,
                        &channel.message_encoding,
                        &channel.metadata,
                    )
                    .map_err(Error::from_mcap_write)?;
                channels.insert(channel.id, (id, channel.topic));
                recovery.channels += 1;
            }
            RawRecord::Message(message) => {
                let Some((id, topic)) = channels.get(&message.channel_id) else {
                    recovery.undeclared += 1;
                    continue;
                };
                let header = MessageHeader {
                    channel_id: *id,
                    sequence: message.sequence,
                    log_time: message.log_time,
                    publish_time: message.publish_time,
                };
                writer
                    .write_to_known_channel(&header, &message.data)
                    .map_err(Error::from_mcap_write)?;
                recovery.messages += 1;
                *recovery
                    .messages_per_topic
                    .entry(topic.clone())
                    .or_default() += 1;
            }
            RawRecord::Lost(_) => {}
        }
    }
    progress(total, total);
    writer.finish().map_err(Error::from_mcap_write)?;
    writer
        .into_inner()
        .flush()
        .map_err(|source| Error::Write { source })?;
    recovery.damage = reader.damage().clone();
    Ok(recovery)
}

/// Whether two paths name the same file (as far as the file system tells).
fn same_file(a: &Path, b: &Path) -> bool {
    if a == b {
        return true;
    }
    match (std::fs::canonicalize(a), std::fs::canonicalize(b)) {
        (Ok(a), Ok(b)) => a == b,
        _ => false,
    }
}
