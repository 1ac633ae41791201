//! Why a scenario could not be loaded or a run could not be simulated or written.

use std::path::PathBuf;

/// Errors of this crate. Every message is one line naming the file (or topic), the key and the
/// problem, so that a command-line tool can print it as it is.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// A file could not be read.
    #[error("{}: cannot read: {reason}", path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// What the operating system said.
        reason: String,
    },
    /// A file could not be written.
    #[error("{}: cannot write: {reason}", path.display())]
    Write {
        /// The file.
        path: PathBuf,
        /// What the operating system said.
        reason: String,
    },
    /// The scenario file is not valid TOML.
    #[error("{source_name}: line {line}: not valid TOML: {reason}")]
    Syntax {
        /// The file the text came from.
        source_name: String,
        /// The line of the problem, counting from 1.
        line: usize,
        /// The parser's reason, on one line.
        reason: String,
    },
    /// A key of the scenario is missing, unknown, of the wrong type or has an impossible value.
    #[error("{source_name}: {key}: {problem}")]
    Key {
        /// The file the text came from.
        source_name: String,
        /// The key, as a dotted path (`path.segments[2].length_m`).
        key: String,
        /// What is wrong with it.
        problem: String,
    },
    /// The scenario's nominal rig file is unusable (the message names that file).
    #[error(transparent)]
    Rig(#[from] rig_model::RigFileError),
    /// The board's encoder refused a frame (cannot happen for registers that validate).
    #[error("encoding frame {frame}: {source}")]
    Encode {
        /// Index of the stereo frame in the run.
        frame: usize,
        /// The encoder's reason.
        #[source]
        source: fpga_link::EncodeError,
    },
    /// The board's detector refused an image (cannot happen for registers that validate).
    #[error("detecting features of frame {frame}: {source}")]
    Detect {
        /// Index of the stereo frame in the run.
        frame: usize,
        /// The detector's reason.
        #[source]
        source: harris_core::Error,
    },
    /// Writing the vehicle log failed.
    #[error(transparent)]
    Log(#[from] vehicle_log::Error),
}

/// Results of this crate.
pub type Result<T, E = Error> = std::result::Result<T, E>;
