//! Reading vehicle logs, whole or streaming, on top of the damage-tolerant [`RawReader`].

use std::collections::HashMap;
use std::fs::File;
use std::io::{Read, Seek};
use std::path::{Path, PathBuf};

use crate::damage::{Damage, LostSpan};
use crate::error::{Error, Result};
use crate::json;
use crate::raw::{CutAt, RawChannel, RawMessage, RawReader, RawRecord};
use crate::ros2::{Decoded, Plan, Role, Ros2Topics, Side};
use crate::topics::{self, Topic};
use crate::types::Record;

/// A whole vehicle log, read by [`read_log`].
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub struct Log {
    /// The messages of the vehicle topics, in log order (the order they were written in),
    /// with a [`Record::Lost`] at each place where data that may have held some of them
    /// could not be read.
    pub records: Vec<Record>,
    /// Things that looked wrong but did not stop the reading (a known topic with a foreign
    /// encoding, a message on an undeclared channel, damage: one line each).
    pub warnings: Vec<String>,
    /// Why the log ends early, when the file is cut short (power lost while recording):
    /// `records` then holds everything readable before the cut.
    pub truncated: Option<String>,
    /// Messages on topics this crate does not know (or on foreign channels of known names).
    pub ignored_messages: u64,
    /// The names of those topics, each once, in the order they were met.
    pub ignored_topics: Vec<String>,
    /// The vehicle topics that have a channel in the log, each once, in the order they were met.
    pub topics: Vec<&'static str>,
    /// What could not be read, in total (the spans are also in `records`).
    pub damage: Damage,
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
/// A damaged log is not an error: the result holds every record that could still be read,
/// with [`Record::Lost`] where data was lost, [`Log::damage`] totals the losses and
/// [`Log::truncated`] says whether the file is cut short. Errors: the file cannot be opened
/// or read, it is not an MCAP file, or a message of a vehicle topic is malformed where the
/// log shows no damage (or inside a chunk whose CRC checks).
pub fn read_log(path: impl AsRef<Path>) -> Result<Log> {
    LogReader::open(path)?.into_log()
}

/// Streams the records of a log in log order, holding one chunk of the file at a time.
///
/// Yields `Ok(record)` for each message of a vehicle topic, and [`Record::Lost`] where data
/// that may have held some could not be read (just before the next good record: reset any
/// stream decoder there). A malformed message yields one `Err` and ends the iteration, unless
/// it comes from an unverified part of a damaged log (then it is dropped with a warning). The
/// counters, warnings and [`LogReader::damage`] grow as the reading goes.
pub struct LogReader<R = File> {
    raw: RawReader<R>,
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
        Ok(Self {
            raw: RawReader::open(path)?,
            state: State::new(path.to_path_buf()),
            done: false,
        })
    }
}

impl<R: Read + Seek> LogReader<R> {
    /// Starts reading a log from `source`, checking that it is an MCAP file (see
    /// [`RawReader::new`]); `name` stands for the source in messages (a path, usually).
    pub fn new(source: R, name: impl Into<PathBuf>) -> Result<Self> {
        let path = name.into();
        Ok(Self {
            raw: RawReader::new(source, path.clone())?,
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
        let damage = self.raw.damage().clone();
        let state = self.state;
        Ok(Log {
            records,
            warnings: state.warnings,
            truncated: state.truncated,
            ignored_messages: state.ignored_messages,
            ignored_topics: state.ignored_topics,
            topics: state.topics,
            damage,
        })
    }

    /// Ends the reading: why the file ends early, and one warning line for the damage.
    fn finish(&mut self) {
        let n = self.state.records;
        self.state.truncated = self.raw.cut_at().map(|cut| match cut {
            CutAt::Data => format!(
                "the file ends inside its data section, after {n} records: cut short \
                 (power lost while recording?)"
            ),
            CutAt::Summary => {
                format!("the file ends inside its summary section: cut short after all {n} records")
            }
        });
        let damage = self.raw.damage();
        if let Some(line) = damage_line(damage) {
            self.state.warnings.push(line);
        }
    }
}

/// One line for a log's damage other than the cut (which [`Log::truncated`] tells), or
/// `None` when there is none.
fn damage_line(damage: &Damage) -> Option<String> {
    let mut parts = Vec::new();
    if damage.header_damaged {
        parts.push("its magic or header record is damaged".to_owned());
    }
    let lost: Vec<&LostSpan> = damage
        .spans
        .iter()
        .filter(|s| !s.why.contains("(cut short)"))
        .collect();
    let cut_spans = damage.spans.len() - lost.len();
    let spans = damage.spans_total.saturating_sub(cut_spans as u64);
    if spans > 0 {
        let first = lost.first().map_or(String::new(), |s| {
            format!(", the first at offset {}: {}", s.offset, s.why)
        });
        parts.push(format!(
            "{spans} stretches lost ({} bytes, {} chunks){first}",
            damage.bytes_lost, damage.chunks_lost
        ));
    }
    if let crate::damage::SummaryState::Damaged { why } = &damage.summary {
        parts.push(format!("its summary section is unusable ({why})"));
    }
    if damage.tail_damaged {
        parts.push("its closing magic is damaged".to_owned());
    }
    if damage.repaired_chunks > 0 {
        parts.push(format!(
            "{} chunks had one flipped bit, mended (their CRC checks)",
            damage.repaired_chunks
        ));
    }
    (!parts.is_empty()).then(|| format!("the log is damaged: {}", parts.join("; ")))
}

impl<R> LogReader<R> {
    /// The file (or the name given to [`LogReader::new`]).
    pub fn path(&self) -> &Path {
        &self.state.path
    }

    /// Why the log ends early, once the reading has ended (see [`Log::truncated`]).
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

    /// Reads the ROS 2 bag's named camera and odometry topics (vehicle-interfaces.md 4.1)
    /// instead of the board's stream and the JSON odometry: their images come out as
    /// [`Record::Image`] (or [`Record::BadImage`]), their odometry as [`Record::Odom`]. Call
    /// it before reading. A named topic of another type or encoding, or whose schema lacks
    /// a field read, ends the reading with [`Error::Ros2Topic`].
    pub fn set_ros2_topics(&mut self, topics: Ros2Topics) {
        self.state.ros2 = Some(topics);
    }

    /// The named ROS 2 topics, when set.
    pub fn ros2_topics(&self) -> Option<&Ros2Topics> {
        self.state.ros2.as_ref()
    }

    /// The named ROS 2 roles met so far, with their topic's type (`pkg/Type`).
    pub fn ros2_met(&self) -> &[(Role, String)] {
        &self.state.ros2_met
    }

    /// Messages read so far per ROS 2 role, in [`Role::index`] order.
    pub fn ros2_counts(&self) -> [u64; 3] {
        self.state.ros2_counts
    }

    /// Every foreign channel met so far, each topic once: `(topic, schema name)` (`""`
    /// without a schema). A ROS 2 bag's topics and types, for messages that help name them.
    pub fn foreign_channels(&self) -> &[(String, String)] {
        &self.state.foreign
    }

    /// ROS 2 odometry samples left out so far because a velocity was not finite.
    pub fn nonfinite_odometry(&self) -> u64 {
        self.state.nonfinite_odometry
    }

    /// Every topic with a channel so far but the vehicle topics: the named ROS 2 topics met,
    /// then the foreign ones, `(topic, schema name)`; for messages that list a bag's topics.
    pub fn bag_topics(&self) -> Vec<(String, String)> {
        let named = self.state.ros2.as_ref().map_or(Vec::new(), |t| {
            self.state
                .ros2_met
                .iter()
                .map(|(r, ty)| (t.topic(*r).to_owned(), ty.clone()))
                .collect()
        });
        named
            .into_iter()
            .chain(self.state.foreign.iter().cloned())
            .collect()
    }

    /// Messages read so far on each of [`LogReader::foreign_channels`], in its order.
    pub fn foreign_messages(&self) -> &[u64] {
        &self.state.foreign_messages
    }

    /// Whether chunks damaged by one flipped bit are mended (on by default:
    /// [`RawReader::mend_bit_errors`]).
    pub fn mend_bit_errors(&mut self, on: bool) {
        self.raw.mend_bit_errors(on);
    }

    /// What could not be read so far; complete once the iteration has ended.
    pub fn damage(&self) -> &Damage {
        self.raw.damage()
    }

    /// How far the reading has come, bytes of the file (for progress bars).
    pub fn position(&self) -> u64 {
        self.raw.position()
    }

    /// The file's length, bytes.
    pub fn file_len(&self) -> u64 {
        self.raw.file_len()
    }

    /// Messages read so far per vehicle topic (decoded and yielded), in
    /// [`Topic`](crate::topics) order: `(topic, count)`.
    pub fn messages_read(&self) -> Vec<(&'static str, u64)> {
        Topic::ALL
            .iter()
            .map(|t| (t.name(), self.state.counts[t.index()]))
            .filter(|(_, n)| *n > 0)
            .collect()
    }
}

impl<R: Read + Seek> Iterator for LogReader<R> {
    type Item = Result<Record>;

    fn next(&mut self) -> Option<Self::Item> {
        while !self.done {
            let step = match self.raw.next() {
                None => {
                    self.done = true;
                    self.finish();
                    return None;
                }
                Some(Err(err)) => Step::Bad(err),
                Some(Ok(RawRecord::Schema(schema))) => {
                    self.state
                        .schemas
                        .insert(schema.id, (schema.name, schema.encoding, schema.data));
                    Step::Nothing
                }
                Some(Ok(RawRecord::Channel(channel))) => match self.state.channel(channel) {
                    Ok(()) => Step::Nothing,
                    Err(err) => Step::Bad(err),
                },
                Some(Ok(RawRecord::Message(message))) => {
                    // Outside a chunk whose CRC checks, a malformed message is the writer's
                    // only in a file without chunks and without damage so far; in a chunked
                    // file, a message outside the chunks is where damaged framing led.
                    let trusted =
                        message.verified || (!self.raw.chunked() && self.raw.damage().is_clean());
                    self.state.message(&message, trusted)
                }
                Some(Ok(RawRecord::Lost(span))) if self.state.concerns_us(&span) => {
                    Step::Record(Record::Lost(span))
                }
                Some(Ok(_)) => Step::Nothing,
            };
            match step {
                Step::Nothing => {}
                Step::Record(record) => {
                    if !matches!(record, Record::Lost(_)) {
                        self.state.records += 1;
                    }
                    return Some(Ok(record));
                }
                Step::Bad(err) => {
                    self.done = true;
                    return Some(Err(err));
                }
            }
        }
        None
    }
}

impl<R: Read + Seek> std::iter::FusedIterator for LogReader<R> {}

/// What one raw record leads to.
enum Step {
    Nothing,
    Record(Record),
    Bad(Error),
}

/// What a channel is to this reader.
#[derive(Debug, Clone, Copy)]
enum Channel {
    Ours(Topic),
    /// A named topic of a ROS 2 bag; its plan is in [`State::plans`].
    Ros2(Role),
    Foreign,
}

/// Bookkeeping of the reading, apart from the MCAP reader so both can be borrowed at once.
#[derive(Debug)]
struct State {
    path: PathBuf,
    /// Schema id to schema name, encoding and document.
    schemas: HashMap<u16, (String, String, Vec<u8>)>,
    channels: HashMap<u16, Channel>,
    /// The ROS 2 topics to read, when given.
    ros2: Option<Ros2Topics>,
    /// How to read each named ROS 2 channel, by channel id.
    plans: HashMap<u16, Plan>,
    /// Messages read per ROS 2 role.
    ros2_counts: [u64; 3],
    /// The ROS 2 roles whose topic has a channel, with its type, in the order they were met.
    ros2_met: Vec<(Role, String)>,
    /// Every foreign channel's topic and schema name (`""` for none), each topic once.
    foreign: Vec<(String, String)>,
    /// Foreign channel id to its index in `foreign`.
    foreign_index: HashMap<u16, usize>,
    /// Messages per entry of `foreign`.
    foreign_messages: Vec<u64>,
    /// Messages met per vehicle topic, for error messages.
    counts: [u64; Topic::ALL.len()],
    /// Records yielded.
    records: u64,
    ignored_messages: u64,
    ignored_topics: Vec<String>,
    topics: Vec<&'static str>,
    warnings: Vec<String>,
    truncated: Option<String>,
    warned_undeclared_channel: bool,
    /// Malformed vehicle messages dropped from unverified parts of a damaged log.
    dropped_malformed: u64,
    /// ROS 2 odometry samples left out for a velocity that is not finite.
    nonfinite_odometry: u64,
}

impl State {
    fn new(path: PathBuf) -> Self {
        Self {
            path,
            schemas: HashMap::new(),
            channels: HashMap::new(),
            ros2: None,
            plans: HashMap::new(),
            ros2_counts: [0; 3],
            ros2_met: Vec::new(),
            foreign: Vec::new(),
            foreign_index: HashMap::new(),
            foreign_messages: Vec::new(),
            counts: [0; Topic::ALL.len()],
            records: 0,
            ignored_messages: 0,
            ignored_topics: Vec::new(),
            topics: Vec::new(),
            warnings: Vec::new(),
            truncated: None,
            warned_undeclared_channel: false,
            dropped_malformed: 0,
            nonfinite_odometry: 0,
        }
    }

    /// Whether a lost span may have held messages of our channels (or nothing tells).
    fn concerns_us(&self, span: &LostSpan) -> bool {
        span.messages.as_ref().is_none_or(|m| {
            m.iter().any(|(topic, n)| {
                *n > 0
                    && (Topic::from_name(topic).is_some()
                        || self.ros2.as_ref().is_some_and(|r| r.role(topic).is_some()))
            })
        })
    }

    fn channel(&mut self, channel: RawChannel) -> Result<()> {
        let schema = self.schemas.get(&channel.schema_id);
        let schema_name = schema.map(|(name, _, _)| name.as_str());
        let role = self.ros2.as_ref().and_then(|r| r.role(&channel.topic));
        let kind = match (role, Topic::from_name(&channel.topic)) {
            (Some(role), _) => {
                let plan = Plan::new(
                    role,
                    &channel.message_encoding,
                    schema.map(|(n, e, d)| (n.as_str(), e.as_str(), d.as_slice())),
                )
                .map_err(|problem| Error::Ros2Topic {
                    path: self.path.clone(),
                    topic: channel.topic.clone(),
                    role,
                    problem,
                })?;
                if !self.ros2_met.iter().any(|(r, _)| *r == role) {
                    // The type as the file names it, as for the foreign channels.
                    let name = schema_name.unwrap_or(plan.type_name());
                    self.ros2_met.push((role, name.to_owned()));
                }
                self.plans.insert(channel.id, plan);
                Channel::Ros2(role)
            }
            // With the camera topics named, the board's stream and the JSON odometry are
            // not read: the named topics are the input.
            (None, Some(topic @ (Topic::Features | Topic::Odom))) if self.ros2.is_some() => {
                self.warnings.push(format!(
                    "channel {} is ignored: the camera and odometry topics were named",
                    topic.name()
                ));
                Channel::Foreign
            }
            (None, Some(topic)) => {
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
            (None, None) => Channel::Foreign,
        };
        match kind {
            Channel::Ours(topic) => {
                if !self.topics.contains(&topic.name()) {
                    self.topics.push(topic.name());
                }
            }
            Channel::Ros2(_) => {}
            Channel::Foreign => {
                let at = match self.foreign.iter().position(|(t, _)| *t == channel.topic) {
                    Some(at) => at,
                    None => {
                        self.foreign.push((
                            channel.topic.clone(),
                            schema_name.unwrap_or_default().to_owned(),
                        ));
                        self.foreign_messages.push(0);
                        self.foreign.len() - 1
                    }
                };
                self.foreign_index.insert(channel.id, at);
                if !self.ignored_topics.contains(&channel.topic) {
                    self.ignored_topics.push(channel.topic);
                }
            }
        }
        self.channels.insert(channel.id, kind);
        Ok(())
    }

    /// A message of a named ROS 2 topic.
    fn ros2_message(&mut self, message: &RawMessage, role: Role, trusted: bool) -> Step {
        let count = &mut self.ros2_counts[role.index()];
        let index = *count;
        *count += 1;
        let Some(plan) = self.plans.get(&message.channel_id) else {
            return Step::Nothing;
        };
        let side = match role {
            Role::Left => Some(Side::Left),
            Role::Right => Some(Side::Right),
            Role::Odom => None,
        };
        match (plan.decode(&message.data), side) {
            (Ok((t_us, Decoded::Image(payload))), Some(side)) => {
                Step::Record(Record::Image(crate::ros2::CameraImage {
                    side,
                    t_us,
                    log_time_ns: message.log_time,
                    payload,
                }))
            }
            (Ok((_, Decoded::Odom(sample))), None) => Step::Record(Record::Odom(sample)),
            // A sample with a NaN says nothing of the motion: left out and told, while the
            // samples around it carry the drive on.
            (Ok((t_us, Decoded::NonFinite(what))), None) => {
                self.nonfinite_odometry += 1;
                let topic = self.ros2.as_ref().map_or("", |r| r.topic(role));
                if self.nonfinite_odometry == 1 {
                    self.warnings.push(format!(
                        "{topic} message {index} (stamp {t_us} us): {what}: left out (and any \
                         more such: see the count in the report)"
                    ));
                }
                Step::Nothing
            }
            // A plan decodes what its role reads; anything else cannot come out of it.
            (Ok(_), _) => Step::Nothing,
            // An image that does not decode is counted by the caller, like one whose pixels
            // it cannot read: one bad frame does not end a drive.
            (Err(problem), Some(side)) => Step::Record(Record::BadImage {
                side,
                log_time_ns: message.log_time,
                problem,
            }),
            (Err(problem), None) => {
                let topic = self
                    .ros2
                    .as_ref()
                    .map_or(String::new(), |r| r.topic(role).to_owned());
                if trusted {
                    Step::Bad(Error::BadRos2Message {
                        path: self.path.clone(),
                        topic,
                        index,
                        problem,
                    })
                } else {
                    self.dropped_malformed += 1;
                    if self.dropped_malformed == 1 {
                        self.warnings.push(format!(
                            "{topic} message {index} (log time {} ns) is malformed ({problem}) in \
                             a part of the damaged log no CRC covers: dropped as damage (and any \
                             more such)",
                            message.log_time
                        ));
                    }
                    Step::Nothing
                }
            }
        }
    }

    /// A message; `trusted`: a malformed one is an error (it comes from a chunk whose CRC
    /// checks, or the log shows no damage), else it is dropped with a warning.
    fn message(&mut self, message: &RawMessage, trusted: bool) -> Step {
        let data = message.data.as_slice();
        let topic = match self.channels.get(&message.channel_id) {
            Some(Channel::Ours(topic)) => *topic,
            Some(Channel::Ros2(role)) => return self.ros2_message(message, *role, trusted),
            Some(Channel::Foreign) => {
                self.ignored_messages += 1;
                if let Some(&at) = self.foreign_index.get(&message.channel_id)
                    && let Some(n) = self.foreign_messages.get_mut(at)
                {
                    *n += 1;
                }
                return Step::Nothing;
            }
            None => {
                self.ignored_messages += 1;
                if !self.warned_undeclared_channel {
                    self.warned_undeclared_channel = true;
                    self.warnings.push(format!(
                        "message on channel {}, which no channel record declares: ignored \
                         (and any more such)",
                        message.channel_id
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
                log_time_ns: message.log_time,
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
            Err(problem) if trusted => Step::Bad(Error::BadMessage {
                path: self.path.clone(),
                topic: topic.name(),
                index,
                problem,
            }),
            Err(problem) => {
                self.dropped_malformed += 1;
                if self.dropped_malformed == 1 {
                    self.warnings.push(format!(
                        "{} message {index} (log time {} ns) is malformed ({problem}) in a part \
                         of the damaged log no CRC covers: dropped as damage (and any more such)",
                        topic.name(),
                        message.log_time
                    ));
                }
                Step::Nothing
            }
        }
    }
}
