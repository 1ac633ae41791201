//! Vehicle logs (vehicle-interfaces.md section 4): one MCAP file per run, written with
//! [`LogWriter`], read whole with [`read_log`] or streamed with [`LogReader`].
//!
//! | topic | message encoding | schema (encoding `jsonschema`) | message | log time |
//! |---|---|---|---|---|
//! | `/fpga/features` | `stereonav.fpga-link.v1` | none | a chunk of the board's raw byte stream as received (any chunking; concatenate in log order) | arrival time, ns |
//! | `/odom` | `json` | `stereonav.Odometry` | `{"t_us": int, "vx": float, "vy": float, "vtheta": float}` ([`OdomSample`]) | `t_us * 1000` |
//! | `/rig` | `json` | `stereonav.Rig` | optional, at the start: the rig file's tables `camera`, `mount`, `estimate`, `prior`, `noise` as a JSON object (kept as text) | see [`LogWriter`] |
//! | `/truth/pose` | `json` | `stereonav.TruthPose` | simulator only, one per stereo frame: `{"t_us", "x", "y", "theta"}` ([`TruthPose`]) | `t_us * 1000` |
//! | `/truth/landmarks` | `json` | `stereonav.TruthLandmarks` | simulator only, once: `{"landmarks": [{"id", "x", "y", "z"}, ...]}` ([`TruthLandmark`]) | see [`LogWriter`] |
//! | `/truth/camera` | `json` | `stereonav.TruthCamera` | simulator only, once: `{"f", "cx", "cy", "baseline", "mount_x", "mount_y", "mount_z", "mount_roll", "mount_pitch", "mount_yaw"}` ([`TruthCamera`]) | see [`LogWriter`] |
//!
//! Units are those of vehicle-interfaces.md: metres, radians, pixels, microseconds (`t_us`,
//! on the clock of the board's packet timestamps); truth poses and landmarks are in the world
//! frame. The JSON Schema documents are in [`topics`]; every key they list is required, and
//! other keys are allowed (and ignored). Integers (`t_us`, `id`) must be written as JSON
//! integers; floats may be any JSON number. NaN and infinities cannot be written (JSON has
//! none).
//!
//! **Log order** is file order: the order the writer was called in (call it in arrival
//! order). A reader yields the records in that order, even where log times go backwards.
//!
//! **Foreign topics**: a channel is ours only if its topic, message encoding and schema name
//! match the table; the reader counts and names the others ([`Log::ignored_messages`],
//! [`Log::ignored_topics`]), so a ROS `/odom` in CDR is ignored, and a foreign MCAP file
//! reads as a log with no records ([`Log::has_vehicle_topics`] is false).
//!
//! **Damage**: a file cut short (power lost while recording) or damaged after its start
//! is read up to the last chunk whose CRC checks, and [`Log::truncated`] says why it stopped;
//! only a file that is not MCAP at all (wrong magic, empty), an I/O error, or a malformed
//! message on one of our topics is an [`Error`]. The writer closes a chunk every
//! [`CHUNK_SPAN_NS`] of log time, so a power loss costs about that much of the recording.
//!
//! The MCAP format itself is the `mcap` crate's; this crate only maps the topics.
#![forbid(unsafe_code)]
#![deny(missing_docs)]

mod damage;
mod error;
mod json;
mod raw;
mod reader;
mod recover;
pub mod topics;
mod types;
mod writer;

pub use damage::{Damage, LostSpan, MAX_KEPT_SPANS, SummaryState};
pub use error::{Error, NotMcap, Problem, Result};
pub use raw::{MAX_RECORD_LEN, RawChannel, RawMessage, RawReader, RawRecord, RawSchema};
pub use reader::{Log, LogReader, read_log};
pub use recover::{Recovery, recover};
pub use types::{OdomSample, Record, TruthCamera, TruthLandmark, TruthPose};
pub use writer::{CHUNK_SPAN_NS, CHUNK_TARGET_BYTES, LogWriter, MAX_MESSAGE_LEN};
