//! Reading vehicle logs, whole or streaming.

use std::collections::HashMap;
use std::fs::File;
use std::io::{ErrorKind, Read};
use std::path::{Path, PathBuf};

use mcap::McapError;
use mcap::records::{self, op};
use mcap::sans_io::{LinearReadEvent, LinearReader, LinearReaderOptions};

use crate::error::{Error, NotMcap, Result};
use crate::json;
use crate::topics::{self, Topic};
use crate::types::Record;

/// The largest record or chunk the reader accepts, bytes: a corrupt length must not make it
/// allocate without bound. Larger than any chunk [`crate::LogWriter`] writes.
pub const MAX_RECORD_LEN: usize = 256 << 20;

/// Bytes asked of the source per read when the MCAP reader needs less (it asks for a few
/// bytes at a time when reading record headers).
const MIN_READ: usize = 64 << 10;

/// Most bytes asked of the source per read (the MCAP reader asks again for the rest).
const MAX_READ: usize = 4 << 20;

/// A whole vehicle log, read by [`read_log`].
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub struct Log {
    /// The messages of the vehicle topics, in log order (the order they were written in).
    pub records: Vec<Record>,
    /// Things that looked wrong but did not stop the reading (a known topic with a foreign
    /// encoding, a message on an undeclared channel).
    pub warnings: Vec<String>,
    /// Why the log ended early, when it did: a file cut short while recording, or damaged.
    /// `records` then holds everything readable before that point.
    pub truncated: Option<String>,
    /// Messages on topics this crate does not know (or on foreign channels of known names).
    pub ignored_messages: u64,
    /// The names of those topics, each once, in the order they were met.
    pub ignored_topics: Vec<String>,
    /// The vehicle topics that have a channel in the log, each once, in the order they were met.
    pub topics: Vec<&'static str>,
}

impl Log {
    /// Whether the log has a `/fpga/features` or an `/odom` channel of ours (a foreign MCAP
    /// file has neither: `replay` refuses it).
    pub fn has_vehicle_topics(&self) -> bool {
        has_vehicle_topics(&self.topics)
    }
}

fn has_vehicle_topics(topics: &[&'static str]) -> bool {
    topics
        .iter()
        .any(|t| *t == topics::FEATURES || *t == topics::ODOM)
}

/// Reads the whole log at `path`.
///
/// A log cut short (or damaged after its start) is not an error: the result holds the
/// records read before that point and says why it stopped in [`Log::truncated`].
/// Errors: the file cannot be opened or read, it is not an MCAP file, or a message of a
/// vehicle topic is malformed.
pub fn read_log(path: impl AsRef<Path>) -> Result<Log> {
    LogReader::open(path)?.into_log()
}

/// Streams the records of a log in log order, holding one chunk of the file at a time.
///
/// Yields `Ok(record)` for each message of a vehicle topic; a malformed message yields one
/// `Err` and ends the iteration. A log that is cut short or damaged ends the iteration early
/// without an error; [`LogReader::truncated`] then says why. The counters and warnings
/// ([`LogReader::ignored_messages`], ...) grow as the reading goes.
pub struct LogReader<R = File> {
    source: R,
    mcap: LinearReader,
    state: State,
    done: bool,
}

impl<R> std::fmt::Debug for LogReader<R> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LogReader")
            .field("path", &self.state.path)
            .field("records", &self.state.records)
            .field("truncated", &self.state.truncated)
            .field("done", &self.done)
            .finish_non_exhaustive()
    }
}

impl LogReader<File> {
    /// Opens the log at `path` and checks that it is an MCAP file.
    pub fn open(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let file = File::open(path).map_err(|source| Error::Open {
            path: path.to_path_buf(),
            source,
        })?;
        Self::new(file, path)
    }
}

impl<R: Read> LogReader<R> {
    /// Starts reading a log from `source`, checking that it starts with the MCAP magic;
    /// `name` stands for the source in messages (a path, usually).
    pub fn new(mut source: R, name: impl Into<PathBuf>) -> Result<Self> {
        let path = name.into();
        let mut magic = [0u8; 8];
        let len = read_up_to(&mut source, &mut magic).map_err(|source| Error::Read {
            path: path.clone(),
            source,
        })?;
        check_magic(&magic, len).map_err(|why| Error::NotMcap {
            path: path.clone(),
            why,
        })?;
        let options = LinearReaderOptions::default()
            .with_prevalidate_chunk_crcs(true)
            .with_validate_data_section_crc(true)
            .with_validate_summary_section_crc(true)
            .with_record_length_limit(MAX_RECORD_LEN);
        let mut mcap = LinearReader::new_with_options(options);
        let written = mcap
            .insert(magic.len())
            .iter_mut()
            .zip(magic)
            .map(|(to, from)| *to = from)
            .count();
        mcap.notify_read(written);
        Ok(Self {
            source,
            mcap,
            state: State::new(path),
            done: false,
        })
    }

    /// Reads the rest of the log into a [`Log`].
    pub fn into_log(mut self) -> Result<Log> {
        let mut records = Vec::new();
        for record in &mut self {
            records.push(record?);
        }
        let state = self.state;
        Ok(Log {
            records,
            warnings: state.warnings,
            truncated: state.truncated,
            ignored_messages: state.ignored_messages,
            ignored_topics: state.ignored_topics,
            topics: state.topics,
        })
    }

    /// Passes up to about `need` more bytes of the source to the MCAP reader.
    fn fill(&mut self, need: usize) -> Result<()> {
        let buf = self.mcap.insert(need.clamp(MIN_READ, MAX_READ));
        let n = loop {
            match self.source.read(buf) {
                Ok(n) => break n,
                Err(err) if err.kind() == ErrorKind::Interrupted => continue,
                Err(source) => {
                    return Err(Error::Read {
                        path: self.state.path.clone(),
                        source,
                    });
                }
            }
        };
        self.mcap.notify_read(n);
        Ok(())
    }
}

impl<R> LogReader<R> {
    /// The file (or the name given to [`LogReader::new`]).
    pub fn path(&self) -> &Path {
        &self.state.path
    }

    /// Why the log ended early, once it has (see [`Log::truncated`]).
    pub fn truncated(&self) -> Option<&str> {
        self.state.truncated.as_deref()
    }

    /// Warnings so far (see [`Log::warnings`]).
    pub fn warnings(&self) -> &[String] {
        &self.state.warnings
    }

    /// Messages of unknown topics so far (see [`Log::ignored_messages`]).
    pub fn ignored_messages(&self) -> u64 {
        self.state.ignored_messages
    }

    /// Unknown topics so far (see [`Log::ignored_topics`]).
    pub fn ignored_topics(&self) -> &[String] {
        &self.state.ignored_topics
    }

    /// Vehicle topics so far (see [`Log::topics`]).
    pub fn topics(&self) -> &[&'static str] {
        &self.state.topics
    }

    /// Whether a `/fpga/features` or `/odom` channel of ours has been met so far (see
    /// [`Log::has_vehicle_topics`]).
    pub fn has_vehicle_topics(&self) -> bool {
        has_vehicle_topics(&self.state.topics)
    }
}

impl<R: Read> Iterator for LogReader<R> {
    type Item = Result<Record>;

    fn next(&mut self) -> Option<Self::Item> {
        while !self.done {
            let step = match self.mcap.next_event() {
                None => Step::End,
                Some(Err(err)) => Step::Broken(err),
                Some(Ok(LinearReadEvent::ReadRequest(need))) => Step::Read(need),
                Some(Ok(LinearReadEvent::Record { opcode, data })) => {
                    self.state.record(opcode, data)
                }
            };
            match step {
                Step::Nothing => {}
                Step::Read(need) => {
                    if let Err(err) = self.fill(need) {
                        self.done = true;
                        return Some(Err(err));
                    }
                }
                Step::Record(record) => {
                    self.state.records += 1;
                    return Some(Ok(record));
                }
                Step::Bad(err) => {
                    self.done = true;
                    return Some(Err(err));
                }
                Step::Broken(err) => {
                    self.state.broken(&err);
                    self.done = true;
                }
                Step::End => self.done = true,
            }
        }
        None
    }
}

impl<R: Read> std::iter::FusedIterator for LogReader<R> {}

/// What one event of the MCAP reader leads to.
enum Step {
    Nothing,
    Read(usize),
    Record(Record),
    Bad(Error),
    Broken(McapError),
    End,
}

/// What a channel is to this reader.
#[derive(Debug, Clone, Copy)]
enum Channel {
    Ours(Topic),
    Foreign,
}

/// Bookkeeping of the reading, apart from the MCAP reader so both can be borrowed at once.
#[derive(Debug)]
struct State {
    path: PathBuf,
    /// Schema id to schema name.
    schemas: HashMap<u16, String>,
    channels: HashMap<u16, Channel>,
    /// Messages met per vehicle topic, for error messages.
    counts: [u64; Topic::ALL.len()],
    /// Records yielded.
    records: u64,
    ignored_messages: u64,
    ignored_topics: Vec<String>,
    topics: Vec<&'static str>,
    warnings: Vec<String>,
    truncated: Option<String>,
    /// The data end record was read: what follows is the summary, which repeats schemas
    /// and channels.
    past_data_end: bool,
    warned_undeclared_channel: bool,
}

impl State {
    fn new(path: PathBuf) -> Self {
        Self {
            path,
            schemas: HashMap::new(),
            channels: HashMap::new(),
            counts: [0; Topic::ALL.len()],
            records: 0,
            ignored_messages: 0,
            ignored_topics: Vec::new(),
            topics: Vec::new(),
            warnings: Vec::new(),
            truncated: None,
            past_data_end: false,
            warned_undeclared_channel: false,
        }
    }

    fn record(&mut self, opcode: u8, data: &[u8]) -> Step {
        if self.past_data_end {
            return Step::Nothing;
        }
        if opcode == op::DATA_END {
            self.past_data_end = true;
            return Step::Nothing;
        }
        if !matches!(opcode, op::SCHEMA | op::CHANNEL | op::MESSAGE) {
            return Step::Nothing;
        }
        match mcap::parse_record(opcode, data) {
            Err(err) => Step::Broken(err),
            Ok(records::Record::Schema { header, .. }) => {
                self.schemas.insert(header.id, header.name);
                Step::Nothing
            }
            Ok(records::Record::Channel(channel)) => {
                self.channel(channel);
                Step::Nothing
            }
            Ok(records::Record::Message { header, data }) => self.message(&header, &data),
            Ok(_) => Step::Nothing,
        }
    }

    fn channel(&mut self, channel: records::Channel) {
        let schema_name = self.schemas.get(&channel.schema_id).map(String::as_str);
        let kind = match Topic::from_name(&channel.topic) {
            Some(topic) => {
                let encoding_ok = channel.message_encoding == topic.message_encoding();
                // The byte stream takes no schema (one is ignored); a JSON topic may omit its
                // schema but must not name another.
                let schema_ok = match (topic.schema(), schema_name) {
                    (Some((expected, _)), Some(found)) => found == expected,
                    _ => true,
                };
                if encoding_ok && schema_ok {
                    Channel::Ours(topic)
                } else {
                    let expected_schema = topic.schema().map_or("none", |(name, _)| name);
                    self.warnings.push(format!(
                        "channel {} has message encoding {:?} and schema {:?}, not {:?} and {:?}: \
                         ignored as a foreign topic",
                        channel.topic,
                        channel.message_encoding,
                        schema_name.unwrap_or("none"),
                        topic.message_encoding(),
                        expected_schema,
                    ));
                    Channel::Foreign
                }
            }
            None => Channel::Foreign,
        };
        match kind {
            Channel::Ours(topic) => {
                if !self.topics.contains(&topic.name()) {
                    self.topics.push(topic.name());
                }
            }
            Channel::Foreign => {
                if !self.ignored_topics.contains(&channel.topic) {
                    self.ignored_topics.push(channel.topic);
                }
            }
        }
        self.channels.insert(channel.id, kind);
    }

    fn message(&mut self, header: &records::MessageHeader, data: &[u8]) -> Step {
        let topic = match self.channels.get(&header.channel_id) {
            Some(Channel::Ours(topic)) => *topic,
            Some(Channel::Foreign) => {
                self.ignored_messages += 1;
                return Step::Nothing;
            }
            None => {
                self.ignored_messages += 1;
                if !self.warned_undeclared_channel {
                    self.warned_undeclared_channel = true;
                    self.warnings.push(format!(
                        "message on channel {}, which no channel record declares: ignored \
                         (and any more such)",
                        header.channel_id
                    ));
                }
                return Step::Nothing;
            }
        };
        let count = &mut self.counts[topic.index()];
        let index = *count;
        *count += 1;
        let decoded = match topic {
            Topic::Features => Ok(Record::Features {
                log_time_ns: header.log_time,
                bytes: data.to_vec(),
            }),
            Topic::Odom => json::decode_odom(data).map(Record::Odom),
            Topic::Rig => json::decode_rig(data).map(Record::Rig),
            Topic::TruthPose => json::decode_truth_pose(data).map(Record::TruthPose),
            Topic::TruthLandmarks => json::decode_truth_landmarks(data).map(Record::TruthLandmarks),
            Topic::TruthCamera => json::decode_truth_camera(data).map(Record::TruthCamera),
        };
        match decoded {
            Ok(record) => Step::Record(record),
            Err(problem) => Step::Bad(Error::BadMessage {
                path: self.path.clone(),
                topic: topic.name(),
                index,
                problem,
            }),
        }
    }

    /// Records why the log ended early.
    fn broken(&mut self, err: &McapError) {
        let n = self.records;
        self.truncated = Some(match (err, self.past_data_end) {
            (McapError::UnexpectedEof, false) => format!(
                "the file ends inside its data section, after {n} records: cut short \
                 (power lost while recording?)"
            ),
            (McapError::UnexpectedEof, true) => {
                format!("the file ends inside its summary section: cut short after all {n} records")
            }
            (err, false) => format!("the log is unreadable after {n} records: {err}"),
            (err, true) => {
                format!("the summary section is unreadable ({err}), after all {n} records")
            }
        });
    }
}

/// Reads until `buf` is full or the source ends; returns the bytes read.
fn read_up_to(source: &mut impl Read, buf: &mut [u8]) -> std::io::Result<usize> {
    let mut len = 0;
    while let Some(rest) = buf.get_mut(len..) {
        if rest.is_empty() {
            break;
        }
        match source.read(rest) {
            Ok(0) => break,
            Ok(n) => len += n,
            Err(err) if err.kind() == ErrorKind::Interrupted => {}
            Err(err) => return Err(err),
        }
    }
    Ok(len)
}

/// Checks the first `len` bytes of `start` against the MCAP magic.
fn check_magic(start: &[u8], len: usize) -> Result<(), NotMcap> {
    let found = start.get(..len).unwrap_or(start);
    if found == mcap::MAGIC {
        return Ok(());
    }
    if found.is_empty() {
        return Err(NotMcap::Empty);
    }
    if found.len() < mcap::MAGIC.len() && mcap::MAGIC.starts_with(found) {
        return Err(NotMcap::ShorterThanMagic {
            len: found.len(),
            magic_len: mcap::MAGIC.len(),
        });
    }
    Err(NotMcap::BadMagic {
        found: hex(found),
        expected: hex(mcap::MAGIC),
    })
}

fn hex(bytes: &[u8]) -> String {
    bytes
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect::<Vec<_>>()
        .join(" ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn magic_checks() {
        assert_eq!(check_magic(mcap::MAGIC, 8), Ok(()));
        assert_eq!(check_magic(&[0; 8], 0), Err(NotMcap::Empty));
        assert_eq!(
            check_magic(mcap::MAGIC, 5),
            Err(NotMcap::ShorterThanMagic {
                len: 5,
                magic_len: 8
            })
        );
        assert_eq!(
            check_magic(b"PK\x03\x04", 4).unwrap_err().to_string(),
            "it starts with 50 4b 03 04, not the MCAP magic 89 4d 43 41 50 30 0d 0a"
        );
    }
}
