//! Why a map file was refused.

use std::path::PathBuf;

/// A map file that cannot be read or written; every message names the file and the problem.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// The operating system refused the file.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// What the system said.
        source: std::io::Error,
    },
    /// The file does not start with the map header line: another format.
    #[error("{source_name}: not a stereonav map (no '{magic}' header line)", magic = crate::MAGIC)]
    NotAMap {
        /// The file, as named in messages.
        source_name: String,
    },
    /// A map of a format version this build does not read.
    #[error(
        "{source_name}: map format version {found} is newer than this stereonav reads (up to {supported})"
    )]
    NewerVersion {
        /// The file.
        source_name: String,
        /// The file's version.
        found: u32,
        /// The newest version read here.
        supported: u32,
    },
    /// The header line is malformed.
    #[error("{source_name}: bad map header: {detail}")]
    BadHeader {
        /// The file.
        source_name: String,
        /// What is wrong.
        detail: String,
    },
    /// The body is shorter or longer than the header says: a cut or appended file.
    #[error(
        "{source_name}: the map body is {found} bytes, the header says {expected}: the file is cut or damaged"
    )]
    Length {
        /// The file.
        source_name: String,
        /// Bytes the header announces.
        expected: u64,
        /// Bytes present.
        found: u64,
    },
    /// The body's CRC-32 differs from the header's: the file is damaged.
    #[error(
        "{source_name}: the map is damaged (CRC-32 {found:08x}, the header says {expected:08x})"
    )]
    Checksum {
        /// The file.
        source_name: String,
        /// The header's CRC.
        expected: u32,
        /// The body's.
        found: u32,
    },
    /// The body is not the documented JSON (a missing key, a wrong type, a bad value).
    #[error("{source_name}: {detail}")]
    Content {
        /// The file.
        source_name: String,
        /// What is wrong, naming the key.
        detail: String,
    },
    /// A map that cannot be written (a non-finite value).
    #[error("cannot write the map: {detail}")]
    Invalid {
        /// What is wrong.
        detail: String,
    },
    /// A lighting plan (`stereonav map import`) that cannot make a map: the line and what is
    /// wrong on it.
    #[error("{source_name}:{line}: {problem}")]
    Plan {
        /// The plan, as named in messages.
        source_name: String,
        /// The line (1-based; for a problem of the whole file, where the text was expected).
        line: usize,
        /// What is wrong.
        problem: crate::PlanProblem,
    },
    /// The sigma given for the lamps whose row has none is not a positive number of metres.
    #[error("the default lamp sigma {value} m is not a positive, finite number")]
    BadDefaultSigma {
        /// The sigma given.
        value: f64,
    },
}
