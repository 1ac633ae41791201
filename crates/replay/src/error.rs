//! Why a log could not be replayed. Every message is one line naming the file and the problem.

use std::path::PathBuf;

/// Errors of [`crate::calibrate_log`].
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// The log could not be read: missing or unreadable file, not an MCAP file, or a malformed
    /// message on a vehicle topic (vehicle-log's message names the file and the problem).
    #[error(transparent)]
    Log(#[from] vehicle_log::Error),
    /// An MCAP file without the vehicle topics (written by another tool).
    #[error(
        "{} is not a vehicle log: it has no /fpga/features or /odom channel in this project's encodings (its topics: {})",
        path.display(),
        if topics.is_empty() { "none".to_string() } else { topics.join(", ") }
    )]
    NotVehicleLog {
        /// The file.
        path: PathBuf,
        /// The topics it has instead.
        topics: Vec<String>,
    },
    /// No rig was given and the log has no `/rig` message.
    #[error(
        "{}: no rig: the log has no /rig message and no rig file was given",
        path.display()
    )]
    NoRig {
        /// The file.
        path: PathBuf,
    },
    /// The log's `/rig` message is not a usable rig (the message names the key and problem).
    #[error(transparent)]
    BadRig(#[from] calib::RigFileError),
    /// A setting of the replay is out of range.
    #[error("replay settings: {0}")]
    Settings(#[from] track::SettingsError),
}
