//! Why a log could not be read or written.
//!
//! A log that is cut short (power lost while recording) or damaged is not an error: the
//! reader returns what it could read and says what it lost (see [`crate::Log::damage`] and
//! [`crate::Log::truncated`]).

use std::path::PathBuf;

/// Errors of this crate.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// The log file could not be opened.
    #[error("cannot open {}: {source}", path.display())]
    Open {
        /// The file.
        path: PathBuf,
        /// What the operating system said.
        #[source]
        source: std::io::Error,
    },
    /// Reading the log failed (an I/O error, not the end of the file).
    #[error("cannot read {}: {source}", path.display())]
    Read {
        /// The file, or the name given to the reader.
        path: PathBuf,
        /// What the operating system said.
        #[source]
        source: std::io::Error,
    },
    /// The log file could not be created.
    #[error("cannot create {}: {source}", path.display())]
    Create {
        /// The file.
        path: PathBuf,
        /// What the operating system said.
        #[source]
        source: std::io::Error,
    },
    /// The file is not an MCAP file: it is empty, ends inside the magic, or neither starts
    /// with the magic nor ends like an MCAP file nor holds a chunk whose CRC checks.
    #[error("{} is not an MCAP file: {why}", path.display())]
    NotMcap {
        /// The file, or the name given to the reader.
        path: PathBuf,
        /// What was found instead.
        why: NotMcap,
    },
    /// A ROS 2 topic named for a role cannot be read as that role (section 4.1): another
    /// type, another encoding, a schema without the fields.
    #[error("{}: topic {topic} ({role}): {problem}", path.display())]
    Ros2Topic {
        /// The file, or the name given to the reader.
        path: PathBuf,
        /// The topic.
        topic: String,
        /// What it was named for.
        role: crate::ros2::Role,
        /// What does not fit, one line.
        problem: String,
    },
    /// A message of the named ROS 2 odometry topic cannot be decoded by its schema.
    #[error("{}: {topic} message {index}: {problem}", path.display())]
    BadRos2Message {
        /// The file, or the name given to the reader.
        path: PathBuf,
        /// The topic.
        topic: String,
        /// The message's index on that topic, counting from 0.
        index: u64,
        /// What was wrong.
        problem: String,
    },
    /// A message on one of the vehicle topics does not hold what section 4 says it holds.
    #[error("{}: {topic} message {index}: {problem}", path.display())]
    BadMessage {
        /// The file, or the name given to the reader.
        path: PathBuf,
        /// The topic.
        topic: &'static str,
        /// The message's index on that topic, counting from 0.
        index: u64,
        /// What was wrong.
        problem: Problem,
    },
    /// A value given to the writer cannot be logged.
    #[error("cannot log {topic}: {problem}")]
    BadInput {
        /// The topic it was for.
        topic: &'static str,
        /// What was wrong.
        problem: Problem,
    },
    /// A message is larger than a log may hold.
    #[error("{topic} message of {len} bytes is larger than the {max} bytes a log message may have")]
    TooLarge {
        /// The topic it was for.
        topic: &'static str,
        /// Its length.
        len: usize,
        /// The largest length allowed ([`crate::MAX_MESSAGE_LEN`]).
        max: usize,
    },
    /// Writing the log failed in the output stream.
    #[error("writing the log failed: {source}")]
    Write {
        /// What the stream said.
        #[source]
        source: std::io::Error,
    },
    /// [`crate::recover`] was asked to write over the log it reads.
    #[error("{} is the log being recovered: write the recovered log to another file", path.display())]
    SameFile {
        /// The file.
        path: PathBuf,
    },
    /// The MCAP writer refused an operation (not an I/O error).
    #[error("the MCAP writer failed: {detail}")]
    Mcap {
        /// The MCAP library's message.
        detail: String,
    },
}

/// What a file that is not an MCAP file starts with.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum NotMcap {
    /// The file is empty.
    #[error("it is empty")]
    Empty,
    /// The file ends inside the magic (a log cut before its first 8 bytes).
    #[error("it ends after {len} bytes, inside the {magic_len}-byte MCAP magic")]
    ShorterThanMagic {
        /// Bytes in the file.
        len: usize,
        /// Length of the magic.
        magic_len: usize,
    },
    /// The first bytes are not the magic.
    #[error("it starts with {found}, not the MCAP magic {expected}")]
    BadMagic {
        /// The first bytes found, in hex.
        found: String,
        /// The magic, in hex.
        expected: String,
    },
}

/// What is wrong with a JSON message (read from a log, or given to the writer).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum Problem {
    /// The bytes are not JSON.
    #[error("not JSON: {detail}")]
    NotJson {
        /// The JSON parser's message (with line and column).
        detail: String,
    },
    /// The JSON is not an object (`{...}`).
    #[error("expected a JSON object, found {found}")]
    NotObject {
        /// The kind of JSON value found.
        found: &'static str,
    },
    /// A required key is absent.
    #[error("missing key \"{key}\"")]
    MissingKey {
        /// The key, as a path (`landmarks[3].x`).
        key: String,
    },
    /// A key holds a value of the wrong type or out of range.
    #[error("key \"{key}\": expected {expected}, found {found}")]
    WrongType {
        /// The key, as a path (`landmarks[3].id`).
        key: String,
        /// What it should hold.
        expected: &'static str,
        /// What it holds (as JSON, shortened).
        found: String,
    },
    /// A float is NaN or infinite, which JSON cannot represent.
    #[error("key \"{key}\" is {value}: JSON has no NaN or infinity")]
    NotFinite {
        /// The key, as a path.
        key: String,
        /// The value given.
        value: f64,
    },
}

impl Error {
    /// Converts an error of the MCAP writer.
    pub(crate) fn from_mcap_write(err: mcap::McapError) -> Self {
        match err {
            mcap::McapError::Io(source) => Error::Write { source },
            other => Error::Mcap {
                detail: other.to_string(),
            },
        }
    }
}

/// Results of this crate.
pub type Result<T, E = Error> = std::result::Result<T, E>;
