//! Why `EST.mcap` could not be written ([`WriteError`]) or read ([`ReadError`]). Every message
//! is one line naming the file and the problem.

use std::path::{Path, PathBuf};

use crate::topics::{EST_FILE, FRAME};

/// The MCAP file's magic, at its start.
pub(crate) const MCAP_MAGIC: &[u8] = b"\x89MCAP0\r\n";

/// Why `EST.mcap` could not be written.
///
/// Not `non_exhaustive`: the replay maps every variant onto its own error of the same name.
#[derive(Debug, thiserror::Error)]
pub enum WriteError {
    /// The file could not be created or written.
    #[error("cannot write {EST_FILE}: {}: {source}", path.display())]
    Output {
        /// The path given for it.
        path: PathBuf,
        /// What the operating system said.
        #[source]
        source: std::io::Error,
    },
    /// The MCAP writer refused a record (not an I/O error).
    #[error("cannot write {EST_FILE}: {}: the MCAP writer failed: {detail}", path.display())]
    Mcap {
        /// The path given for it.
        path: PathBuf,
        /// What the writer said.
        detail: String,
    },
    /// A timestamp too late for a Foxglove timestamp (whole seconds in a `u32`).
    #[error(
        "cannot write {EST_FILE}: {}: {topic} at t_us {t_us} is later than the largest time a Foxglove timestamp holds ({max} us)",
        path.display()
    )]
    TimeOutOfRange {
        /// The path given for it.
        path: PathBuf,
        /// The topic of the message.
        topic: &'static str,
        /// Its time, microseconds.
        t_us: u64,
        /// The largest time allowed, microseconds.
        max: u64,
    },
}

impl WriteError {
    pub(crate) fn output(path: &Path, source: std::io::Error) -> Self {
        Self::Output {
            path: path.to_path_buf(),
            source,
        }
    }

    pub(crate) fn mcap(path: &Path, error: mcap::McapError) -> Self {
        match error {
            mcap::McapError::Io(source) => Self::output(path, source),
            other => Self::Mcap {
                path: path.to_path_buf(),
                detail: other.to_string(),
            },
        }
    }
}

/// Why an estimates file could not be read. Every message is one line naming the file and the
/// problem.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ReadError {
    /// The file could not be read.
    #[error("cannot read {}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// What the operating system said.
        #[source]
        source: std::io::Error,
    },
    /// The file does not start with MCAP's magic.
    #[error("{} is not an MCAP file (it starts with {found:02x?}, MCAP files with {MCAP_MAGIC:02x?})", path.display())]
    NotMcap {
        /// The file.
        path: PathBuf,
        /// Its first bytes (at most 8).
        found: Vec<u8>,
    },
    /// The MCAP reader failed before the first message.
    #[error("{}: unreadable MCAP: {detail}", path.display())]
    Mcap {
        /// The file.
        path: PathBuf,
        /// What the reader said.
        detail: String,
    },
    /// An MCAP file with no `/est/frame` channel.
    #[error(
        "{} is not an estimates file of stereonav replay: it has no {FRAME} messages (its topics: {})",
        path.display(),
        if topics.is_empty() { "none".to_string() } else { topics.join(", ") }
    )]
    NotEstimates {
        /// The file.
        path: PathBuf,
        /// The topics it has.
        topics: Vec<String>,
    },
    /// A message is not what its topic's schema says.
    #[error("{}: {topic} message {index}: {field}: expected {expected}, found {found}", path.display())]
    BadMessage {
        /// The file.
        path: PathBuf,
        /// The topic.
        topic: String,
        /// The message's index on its topic, from 0.
        index: usize,
        /// The field (a JSON path).
        field: String,
        /// What the schema wants.
        expected: &'static str,
        /// What was there (shortened).
        found: String,
    },
}
