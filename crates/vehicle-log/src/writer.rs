//! Writing vehicle logs.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufWriter, Seek, Write};
use std::path::Path;

use mcap::records::MessageHeader;
use mcap::{Compression, WriteOptions};

use crate::error::{Error, Problem, Result};
use crate::json;
use crate::topics::{JSONSCHEMA_ENCODING, Topic};
use crate::types::{OdomSample, TruthCamera, TruthLandmark, TruthPose};

/// The largest message a log may hold, bytes. The reader refuses larger records (a corrupt
/// length must not make it allocate without bound), so the writer refuses them too.
pub const MAX_MESSAGE_LEN: usize = 64 << 20;

/// A chunk is closed once it holds this many uncompressed bytes (the MCAP crate's default).
pub const CHUNK_TARGET_BYTES: u64 = 1 << 20;

/// A chunk is closed once its messages span this much log time, nanoseconds: a recording
/// cut by a power loss loses at most the chunk being written, so about this long.
pub const CHUNK_SPAN_NS: u64 = 1_000_000_000;

/// Largest `t_us` whose log time in nanoseconds fits 64 bits.
const MAX_T_US: u64 = u64::MAX / NS_PER_US;

const NS_PER_US: u64 = 1000;

/// Writes a vehicle log (vehicle-interfaces.md section 4) as MCAP: zstd-compressed chunks
/// with CRCs, message indexes and a summary section.
///
/// Messages are written in call order, which is the order a reader returns them in: call it
/// in arrival order. Chunks are streamed to `W` as they fill (at most [`CHUNK_TARGET_BYTES`]
/// uncompressed or [`CHUNK_SPAN_NS`] of log time), so memory stays small whatever the log's
/// length. Channels and schemas are added on the first message of each topic.
///
/// The messages without a time of their own (`/rig`, `/truth/landmarks`, `/truth/camera`)
/// take the log time of the message before them; written before any timed message, they wait
/// and are written, in call order, just ahead of the first timed message with its log time
/// (or with log time 0 by [`LogWriter::finish`] if none comes).
///
/// Call [`LogWriter::finish`] to write the summary and see any error. (A writer dropped
/// without it is finished by the `mcap` crate's `Drop`, which ignores errors and loses
/// untimed messages still waiting.)
pub struct LogWriter<W: Write + Seek> {
    mcap: mcap::Writer<W>,
    channels: [Option<u16>; Topic::ALL.len()],
    sequences: [u32; Topic::ALL.len()],
    /// Log time of the first message of the chunk being written, if any.
    chunk_start_ns: Option<u64>,
    /// Log time of the last message written, if any.
    last_ns: Option<u64>,
    /// Untimed messages waiting for a timed one.
    pending: Vec<(Topic, Vec<u8>)>,
}

impl<W: Write + Seek> std::fmt::Debug for LogWriter<W> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LogWriter")
            .field("channels", &self.channels)
            .field("sequences", &self.sequences)
            .field("last_ns", &self.last_ns)
            .field("pending", &self.pending.len())
            .finish_non_exhaustive()
    }
}

impl LogWriter<BufWriter<File>> {
    /// Creates (or truncates) the file at `path` and starts a log in it.
    pub fn create(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let file = File::create(path).map_err(|source| Error::Create {
            path: path.to_path_buf(),
            source,
        })?;
        Self::new(BufWriter::new(file))
    }
}

impl<W: Write + Seek> LogWriter<W> {
    /// Starts a log in `w` (writes the MCAP magic and header).
    pub fn new(w: W) -> Result<Self> {
        let options = WriteOptions::new()
            .compression(Some(Compression::Zstd))
            .chunk_size(Some(CHUNK_TARGET_BYTES))
            // One thread: the default spawns a zstd worker per physical CPU for each writer,
            // which a vehicle recording 200 kB/s does not need and cannot spare.
            .compression_threads(0)
            .library(format!(
                "stereonav vehicle-log {} ({})",
                env!("CARGO_PKG_VERSION"),
                mcap::LIBRARY_IDENTIFIER
            ));
        let mcap = options.create(w).map_err(Error::from_mcap_write)?;
        Ok(Self {
            mcap,
            channels: [None; Topic::ALL.len()],
            sequences: [0; Topic::ALL.len()],
            chunk_start_ns: None,
            last_ns: None,
            pending: Vec::new(),
        })
    }

    /// Logs a chunk of the board's byte stream on `/fpga/features`, received at
    /// `log_time_ns`. The chunk is kept as given (its boundaries read back unchanged); an
    /// empty chunk is logged too.
    pub fn features(&mut self, log_time_ns: u64, bytes: &[u8]) -> Result<()> {
        self.timed(Topic::Features, log_time_ns, bytes)
    }

    /// Logs an odometry sample on `/odom`, at log time `t_us * 1000`. Refuses NaN and
    /// infinite velocities, which JSON cannot carry.
    pub fn odom(&mut self, sample: &OdomSample) -> Result<()> {
        let log_time_ns = log_time_ns(Topic::Odom, sample.t_us)?;
        let data = json::encode_odom(sample).map_err(|problem| bad(Topic::Odom, problem))?;
        self.timed(Topic::Odom, log_time_ns, &data)
    }

    /// Logs the rig file's tables on `/rig`, as JSON text, kept as given. Refuses text that
    /// is not a JSON object.
    pub fn rig_json(&mut self, json_object: &str) -> Result<()> {
        json::object(json_object.as_bytes()).map_err(|problem| bad(Topic::Rig, problem))?;
        self.untimed(Topic::Rig, json_object.as_bytes().to_vec())
    }

    /// Logs the simulator's true pose at a stereo frame on `/truth/pose`, at log time
    /// `t_us * 1000`.
    pub fn truth_pose(&mut self, pose: &TruthPose) -> Result<()> {
        let log_time_ns = log_time_ns(Topic::TruthPose, pose.t_us)?;
        let data =
            json::encode_truth_pose(pose).map_err(|problem| bad(Topic::TruthPose, problem))?;
        self.timed(Topic::TruthPose, log_time_ns, &data)
    }

    /// Logs the simulator's landmarks on `/truth/landmarks` (once per log).
    pub fn truth_landmarks(&mut self, landmarks: &[TruthLandmark]) -> Result<()> {
        let data = json::encode_truth_landmarks(landmarks)
            .map_err(|problem| bad(Topic::TruthLandmarks, problem))?;
        self.untimed(Topic::TruthLandmarks, data)
    }

    /// Logs the simulator's true camera parameters on `/truth/camera` (once per log).
    pub fn truth_camera(&mut self, camera: &TruthCamera) -> Result<()> {
        let data = json::encode_truth_camera(camera)
            .map_err(|problem| bad(Topic::TruthCamera, problem))?;
        self.untimed(Topic::TruthCamera, data)
    }

    /// Closes the chunk being written and flushes `W`, so that everything logged so far
    /// survives a power loss (as far as `W` and the operating system keep it).
    pub fn flush(&mut self) -> Result<()> {
        self.mcap.flush().map_err(Error::from_mcap_write)?;
        self.chunk_start_ns = None;
        Ok(())
    }

    /// Writes any waiting messages, the last chunk, the summary section and the footer,
    /// flushes and returns `W`.
    pub fn finish(mut self) -> Result<W> {
        self.write_pending(self.last_ns.unwrap_or(0))?;
        self.mcap.finish().map_err(Error::from_mcap_write)?;
        let mut w = self.mcap.into_inner();
        w.flush().map_err(|source| Error::Write { source })?;
        Ok(w)
    }

    fn untimed(&mut self, topic: Topic, data: Vec<u8>) -> Result<()> {
        check_len(topic, &data)?;
        match self.last_ns {
            Some(log_time_ns) => self.write(topic, log_time_ns, &data),
            None => {
                self.pending.push((topic, data));
                Ok(())
            }
        }
    }

    fn timed(&mut self, topic: Topic, log_time_ns: u64, data: &[u8]) -> Result<()> {
        check_len(topic, data)?;
        self.write_pending(log_time_ns)?;
        self.write(topic, log_time_ns, data)
    }

    fn write_pending(&mut self, log_time_ns: u64) -> Result<()> {
        for (topic, data) in std::mem::take(&mut self.pending) {
            self.write(topic, log_time_ns, &data)?;
        }
        Ok(())
    }

    fn write(&mut self, topic: Topic, log_time_ns: u64, data: &[u8]) -> Result<()> {
        let channel_id = self.channel(topic)?;
        if let Some(start) = self.chunk_start_ns
            && log_time_ns.saturating_sub(start) >= CHUNK_SPAN_NS
        {
            self.flush()?;
        }
        let sequence = &mut self.sequences[topic.index()];
        let header = MessageHeader {
            channel_id,
            sequence: *sequence,
            log_time: log_time_ns,
            publish_time: log_time_ns,
        };
        *sequence = sequence.wrapping_add(1);
        self.mcap
            .write_to_known_channel(&header, data)
            .map_err(Error::from_mcap_write)?;
        self.chunk_start_ns.get_or_insert(log_time_ns);
        self.last_ns = Some(log_time_ns);
        Ok(())
    }

    /// The channel of `topic`, added (with its schema) on first use.
    fn channel(&mut self, topic: Topic) -> Result<u16> {
        if let Some(id) = self.channels[topic.index()] {
            return Ok(id);
        }
        let schema_id = match topic.schema() {
            Some((name, document)) => self
                .mcap
                .add_schema(name, JSONSCHEMA_ENCODING, document.as_bytes())
                .map_err(Error::from_mcap_write)?,
            None => 0,
        };
        let id = self
            .mcap
            .add_channel(
                schema_id,
                topic.name(),
                topic.message_encoding(),
                &BTreeMap::new(),
            )
            .map_err(Error::from_mcap_write)?;
        self.channels[topic.index()] = Some(id);
        Ok(id)
    }
}

fn bad(topic: Topic, problem: Problem) -> Error {
    Error::BadInput {
        topic: topic.name(),
        problem,
    }
}

fn check_len(topic: Topic, data: &[u8]) -> Result<()> {
    if data.len() > MAX_MESSAGE_LEN {
        return Err(Error::TooLarge {
            topic: topic.name(),
            len: data.len(),
            max: MAX_MESSAGE_LEN,
        });
    }
    Ok(())
}

/// `t_us * 1000`, refusing times whose nanoseconds do not fit 64 bits.
fn log_time_ns(topic: Topic, t_us: u64) -> Result<u64> {
    if t_us > MAX_T_US {
        return Err(bad(
            topic,
            Problem::WrongType {
                key: "t_us".to_owned(),
                expected: "at most 18446744073709551 (the log time in ns must fit 64 bits)",
                found: t_us.to_string(),
            },
        ));
    }
    Ok(t_us * NS_PER_US)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn max_t_us_matches_the_message() {
        assert_eq!(MAX_T_US, 18_446_744_073_709_551);
        assert!(log_time_ns(Topic::Odom, MAX_T_US).is_ok());
        assert!(log_time_ns(Topic::Odom, MAX_T_US + 1).is_err());
    }
}
