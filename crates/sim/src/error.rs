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
    /// Writing a ROS 2 bag's MCAP records failed.
    #[error("writing the ROS 2 bag: {0}")]
    Bag(#[from] mcap::McapError),
    /// A JPEG quality outside 1 to 100.
    #[error("JPEG quality {quality}: expected 1 to 100")]
    JpegQuality {
        /// The quality asked for.
        quality: u8,
    },
    /// An image of a frame could not be encoded.
    #[error("encoding frame {frame} as {format}: {reason}")]
    ImageEncode {
        /// Index of the stereo frame in the run.
        frame: usize,
        /// `png` or `jpeg`.
        format: &'static str,
        /// The encoder's reason.
        reason: String,
    },
    /// A time does not fit a ROS 2 stamp (`int32` seconds).
    #[error(
        "t_us {t_us} does not fit a ROS 2 stamp: expected at most {} s",
        i32::MAX
    )]
    Stamp {
        /// The time, microseconds.
        t_us: u64,
    },
    /// Something too long for a CDR length (`uint32`).
    #[error("{what} of {len} bytes: a CDR length holds at most {} bytes", u32::MAX)]
    TooLarge {
        /// What it is.
        what: &'static str,
        /// Its length.
        len: usize,
    },
    /// A frame of the rendered mode came without its images (cannot happen).
    #[error("frame {frame} has no images: a bag needs the rendered mode")]
    NoImages {
        /// Index of the stereo frame in the run.
        frame: usize,
    },
    /// A truth message could not be written as JSON (cannot happen for finite values).
    #[error("truth as JSON: {reason}")]
    Json {
        /// The serializer's reason.
        reason: String,
    },
}

/// Results of this crate.
pub type Result<T, E = Error> = std::result::Result<T, E>;
