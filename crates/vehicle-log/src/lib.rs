//! Vehicle logs (vehicle-interfaces.md section 4): one MCAP file per run, written with
//! [`LogWriter`], read whole with [`read_log`] or streamed with [`LogReader`] (or, every
//! topic, with [`RawReader`]).
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
//! **Damage**: a log is written on a vehicle, so it may be cut anywhere (power lost) or
//! damaged (bit errors); the readers use every record they can still read, as `mcap recover`
//! does ([`RawReader`] walks the records itself; the `mcap` crate's readers stop at the first
//! error):
//!
//! - a chunk whose CRC fails, that does not decompress or names an unknown compression is
//!   skipped, and reading goes on at the next record; every other chunk is read;
//! - schemas and channels come from the summary section first when it is intact (found
//!   through the footer, its CRC checked), so a damaged first chunk, where writers put the
//!   channel records, orphans no later message;
//! - where the record framing is lost (an unknown opcode, a length past the end or over the
//!   next chunk, a chunk whose two lengths disagree and neither checks), reading resumes at
//!   the next chunk of the summary's chunk index, or else at the next plausible chunk record
//!   found by scanning; damaged message indexes, statistics, summary or footer never stop it;
//! - a file whose magic or header is damaged is read all the same when it ends like an MCAP
//!   file or holds a chunk whose CRC checks ([`Damage::header_damaged`]); anything else that
//!   does not start with the magic stays [`Error::NotMcap`];
//! - a chunk cut by the end of the file yields the whole records of its readable prefix
//!   (zstd and lz4 decode block by block: a zstd chunk smaller than one 128 KiB block has
//!   none), without a CRC check ([`Damage::unverified_chunks`]).
//!
//! What is lost is told in band, [`Record::Lost`] with a [`LostSpan`] (file offset and bytes,
//! the log-time span, messages per topic when the message index or summary tells, why) just
//! before the next good record, where a stream decoder must be reset; and in total,
//! [`Log::damage`] ([`Damage`]). [`Log::truncated`] says whether the file is cut short. Only
//! a file that is not MCAP, an I/O error, or a malformed message on one of our topics where
//! no damage explains it (inside a chunk whose CRC checks, or in a log without chunks and
//! without damage) is an [`Error`]. The writer closes a chunk every [`CHUNK_SPAN_NS`] of log
//! time, so a power loss or a damaged chunk costs about that much of the recording.
//! [`recover`] writes every readable record of a damaged file to a clean one.
//!
//! The MCAP records are parsed and written by the `mcap` crate; this crate maps the topics
//! and finds its way through damage.
#![forbid(unsafe_code)]
#![deny(missing_docs)]

mod damage;
mod error;
mod json;
mod raw;
mod reader;
mod recover;
pub mod ros2;
pub mod topics;
mod types;
mod writer;

pub use damage::{Damage, LostSpan, MAX_KEPT_SPANS, SummaryState};
pub use error::{Error, NotMcap, Problem, Result};
pub use raw::{MAX_RECORD_LEN, RawChannel, RawMessage, RawReader, RawRecord, RawSchema};
pub use reader::{Log, LogReader, read_log};
pub use recover::{Recovery, recover};
pub use ros2::{CameraImage, ImagePayload, Role, Ros2Topics, Side};
pub use types::{OdomSample, Record, TruthCamera, TruthLandmark, TruthPose};
pub use writer::{CHUNK_SPAN_NS, CHUNK_TARGET_BYTES, LogWriter, MAX_MESSAGE_LEN};
