//! Steps 1-3 of the crate docs as a stream: the log read record by record, the board's byte
//! stream decoded as it comes, and frames and odometry put in data-time order through a
//! bounded reorder window, so that a replay holds a few seconds of input whatever the log's
//! length.
//!
//! The order is the one a sort of the whole log gives (frames and odometry each by their own
//! `t_us`, stable, odometry up to [`nav::ODOMETRY_LOOKAHEAD_US`] past a frame ahead of it), as
//! long as no frame reaches the log more than [`REORDER_US`] of data time after a later one:
//! a frame is let out once a frame [`REORDER_US`] later has been read and the odometry has
//! reached past its look-ahead. A frame later than that (out of the window) is still
//! replayed, in arrival order; the navigator then refuses it if it is older than the frame
//! before, and the replay counts it.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use fpga_link::{Decoder, Event};
use host_board::HostBoard;
use nav::sequencer::{Sequenced, Sequencer};
use rig_model::odometry::OdomSample;
use track::Pixel;
use vehicle_log::{
    CameraImage, LogReader, Record, Role, Ros2Topics, Side, TruthCamera, TruthLandmark, TruthPose,
};

use crate::{Counts, DecodedFrame, Error};

pub use nav::sequencer::REORDER_US;

/// Most untimed bytes of input read before the log's `/rig` when no rig was given.
const MAX_BYTES_BEFORE_RIG: u64 = 64 << 20;

/// Most camera images of a ROS 2 bag held before the host board starts (the preamble reads
/// until every named topic has a channel; a recorder declares them at its start).
const MAX_IMAGES_BEFORE_START: usize = 256;

/// One input of the navigator, in data-time order.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Input {
    /// An odometry sample.
    Odometry(OdomSample),
    /// A decoded stereo frame.
    Frame(DecodedFrame),
}

/// The simulator's truth as it streams by: the landmarks and camera (once), and the poses of
/// the frames not yet done with (bounded: poses older than the frames let out are dropped).
#[derive(Debug, Clone, Default)]
pub(crate) struct TruthStream {
    pub(crate) landmarks: Vec<TruthLandmark>,
    pub(crate) camera: Option<TruthCamera>,
    poses: BTreeMap<u64, TruthPose>,
    /// Whether the log has any truth record.
    pub(crate) any: bool,
}

impl TruthStream {
    /// The true pose at exactly `t_us`, if the log has one (and it is not yet forgotten).
    pub(crate) fn pose_at(&self, t_us: u64) -> Option<&TruthPose> {
        self.poses.get(&t_us)
    }

    /// Forgets the poses before `t_us`.
    pub(crate) fn forget_before(&mut self, t_us: u64) {
        self.poses = self.poses.split_off(&t_us);
    }
}

/// A vehicle log as a stream of navigator inputs in data-time order (see the module docs).
pub(crate) struct LogStream {
    path: PathBuf,
    reader: LogReader,
    decoder: Decoder,
    /// The window that puts frames and odometry in data-time order (`nav::sequencer`).
    window: Sequencer<DecodedFrame>,
    ended: bool,
    /// The first `/rig` message's text.
    pub(crate) rig_text: Option<String>,
    pub(crate) truth: TruthStream,
    pub(crate) counts: Counts,
    /// Bytes of `/fpga/features` read so far.
    feature_bytes: u64,
    /// A stretch of the log was lost before its first board bytes or odometry.
    lost_before_data: bool,
    /// A ROS 2 bag's camera images: the board on the host (`None` for the board's stream, or
    /// until [`LogStream::start_host_board`]).
    host: Option<HostBoard>,
    /// Images (or undecodable image messages) read before the host board started.
    early_images: Vec<Result<CameraImage, (Side, String)>>,
}

impl std::fmt::Debug for LogStream {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LogStream")
            .field("path", &self.path)
            .field("held", &self.window.held())
            .field("ended", &self.ended)
            .finish_non_exhaustive()
    }
}

impl LogStream {
    /// Opens the log at `path` (an MCAP file, or an error); with `topics`, a ROS 2 bag whose
    /// named camera and odometry topics are the input (vehicle-interfaces.md 4.1).
    pub(crate) fn open(path: &Path, topics: Option<&Ros2Topics>) -> Result<Self, Error> {
        if let Some(t) = topics {
            check_topics(t)?;
        }
        let mut reader = LogReader::open(path)?;
        if let Some(topics) = topics {
            reader.set_ros2_topics(topics.clone());
        }
        Ok(Self {
            path: path.to_path_buf(),
            reader,
            decoder: Decoder::new(),
            window: Sequencer::new(),
            ended: false,
            rig_text: None,
            truth: TruthStream::default(),
            counts: Counts::default(),
            feature_bytes: 0,
            lost_before_data: false,
            host: None,
            early_images: Vec::new(),
        })
    }

    /// Whether the input is a ROS 2 bag's images (topics named).
    pub(crate) fn is_bag(&self) -> bool {
        self.reader.ros2_topics().is_some()
    }

    /// Starts the board on the host for a bag's images with `regs` (the rig's `[camera]`
    /// size and `[board]` registers), and feeds it the images read so far. Nothing for the
    /// board's stream.
    pub(crate) fn start_host_board(&mut self, regs: harris_core::Registers) -> Result<(), Error> {
        if !self.is_bag() || self.host.is_some() {
            return Ok(());
        }
        let host = HostBoard::new(regs).map_err(|e| Error::HostBoard {
            path: self.path.clone(),
            problem: e.to_string(),
        })?;
        self.host = Some(host);
        for image in std::mem::take(&mut self.early_images) {
            self.image(image);
        }
        Ok(())
    }

    /// What limits the input, one line each, once the log has been read: no frame, no
    /// odometry, and what became of a bag's images.
    pub(crate) fn input_warnings(&self) -> Vec<String> {
        let mut warnings = Vec::new();
        let topics = self.reader.ros2_topics();
        if let Some(images) = self.image_counts() {
            warnings.extend(image_warnings(images));
        }
        if self.counts.frames == 0 {
            warnings.push(match topics {
                None => "no stereo frame could be decoded from /fpga/features".to_string(),
                Some(t) => format!(
                    "no stereo frame could be made from the images of {} and {}",
                    t.left, t.right
                ),
            });
        }
        if self.counts.odometry == 0 {
            let topic = topics.map_or("/odom", |t| t.odom.as_str());
            warnings.push(format!(
                "no odometry on {topic}: the vehicle's motion is unknown"
            ));
        }
        warnings
    }

    /// The host board's image counts (a bag's), if it ran.
    pub(crate) fn image_counts(&self) -> Option<&host_board::ImageCounts> {
        self.host.as_ref().map(HostBoard::counts)
    }

    /// `(bytes read, file size)`.
    pub(crate) fn progress(&self) -> (u64, u64) {
        let size = self.reader.file_len();
        (self.reader.position().min(size), size)
    }

    /// The underlying reader (its warnings, topics, truncation).
    pub(crate) fn reader(&self) -> &LogReader {
        &self.reader
    }

    /// Reads until the log's first board bytes or odometry (and, when `need_rig`, its `/rig`)
    /// have been met, or the log ends. Nothing is let out. Errors: the log has no vehicle
    /// topics (a foreign MCAP file), no rig is given and the log has none before
    /// [`MAX_BYTES_BEFORE_RIG`] of data, or the reading fails.
    pub(crate) fn preamble(&mut self, need_rig: bool) -> Result<(), Error> {
        if self.is_bag() {
            return self.bag_preamble(need_rig);
        }
        loop {
            let data = self.feature_bytes > 0 || self.counts.odometry > 0;
            let have_rig = !need_rig || self.rig_text.is_some();
            if self.ended || (data && have_rig) {
                break;
            }
            if need_rig && self.feature_bytes > MAX_BYTES_BEFORE_RIG {
                break;
            }
            self.pump()?;
        }
        if !self.reader.has_vehicle_topics() {
            if let Some(e) = ros2_hint(&self.path, self.reader.foreign_channels()) {
                return Err(e);
            }
            return Err(Error::NotVehicleLog {
                path: self.path.clone(),
                topics: self.reader.ignored_topics().to_vec(),
            });
        }
        if need_rig && self.rig_text.is_none() {
            return Err(Error::NoRig {
                path: self.path.clone(),
                lost_to_damage: self.lost_before_data || self.reader.damage().header_damaged,
            });
        }
        Ok(())
    }

    /// [`LogStream::preamble`] of a ROS 2 bag: reads until every named topic has its channel
    /// (and, when `need_rig`, the `/rig` is met), or the bag ends. Errors: a named topic the
    /// bag does not have, or one of another type (from the reader).
    fn bag_preamble(&mut self, need_rig: bool) -> Result<(), Error> {
        loop {
            let all_met = self.reader.ros2_met().len() == Role::ALL.len();
            let have_rig = !need_rig || self.rig_text.is_some();
            if self.ended || (all_met && have_rig) {
                break;
            }
            if self.early_images.len() > MAX_IMAGES_BEFORE_START {
                break;
            }
            self.pump()?;
        }
        let topics = self
            .reader
            .ros2_topics()
            .cloned()
            .unwrap_or_else(|| Ros2Topics {
                left: String::new(),
                right: String::new(),
                odom: String::new(),
            });
        for role in Role::ALL {
            if self.ended && !self.reader.ros2_met().iter().any(|(r, _)| *r == role) {
                return Err(Error::MissingTopic {
                    path: self.path.clone(),
                    option: role.option(),
                    topic: topics.topic(role).to_owned(),
                    // The bag's topics: those named for the other roles, and the rest.
                    topics: self.reader.bag_topics(),
                });
            }
        }
        if need_rig && self.rig_text.is_none() {
            return Err(Error::NoRig {
                path: self.path.clone(),
                lost_to_damage: self.lost_before_data || self.reader.damage().header_damaged,
            });
        }
        Ok(())
    }

    /// The next input in data-time order; `None` at the end of the log.
    pub(crate) fn next_input(&mut self) -> Result<Option<Input>, Error> {
        loop {
            if let Some(input) = self.window.pop() {
                return Ok(Some(match input {
                    Sequenced::Odometry(s) => Input::Odometry(s),
                    Sequenced::Frame(_, f) => Input::Frame(f),
                }));
            }
            if self.ended {
                return Ok(None);
            }
            self.pump()?;
        }
    }

    /// Reads one record of the log (or notes its end).
    fn pump(&mut self) -> Result<(), Error> {
        match self.reader.next() {
            None => {
                self.ended = true;
                let mut frames = Vec::new();
                decode_end(&mut self.decoder, &mut frames);
                if let Some(host) = &mut self.host {
                    host.end();
                    host_frames(host, &mut frames);
                }
                self.hold_frames(frames);
                self.window.end();
                let stats = self.decoder.stats();
                self.counts.frames = stats.packets;
                self.counts.corrupt = stats.corrupt;
                self.counts.lost = stats.lost;
                self.counts.bytes_skipped = stats.bytes_skipped;
                if let Some(images) = self.host.as_ref().map(HostBoard::counts) {
                    let c = &mut self.counts;
                    c.frames = images.frames;
                    c.images_left = images.left;
                    c.images_right = images.right;
                    c.images_unpaired = images.unpaired;
                    c.images_wrong_size = images.wrong_size;
                    c.images_unsupported = images.unsupported;
                    c.images_undecodable = images.undecodable;
                    c.image_frames_dropped = images.frames_dropped;
                }
            }
            Some(Err(e)) => return Err(e.into()),
            Some(Ok(record)) => self.record(record),
        }
        Ok(())
    }

    fn record(&mut self, record: Record) {
        match record {
            Record::Features { bytes, .. } => {
                self.feature_bytes = self.feature_bytes.saturating_add(bytes.len() as u64);
                let mut frames = Vec::new();
                decode_chunk(&mut self.decoder, &bytes, &mut frames);
                self.hold_frames(frames);
            }
            Record::Odom(s) => {
                self.counts.odometry += 1;
                self.window.push_odometry(OdomSample {
                    t_us: s.t_us,
                    vx: s.vx,
                    vy: s.vy,
                    vtheta: s.vtheta,
                });
            }
            Record::Image(image) => self.image(Ok(image)),
            Record::BadImage { side, problem, .. } => self.image(Err((side, problem))),
            // The first /rig counts (the rig is logged once, at the start).
            Record::Rig(text) if self.rig_text.is_none() => self.rig_text = Some(text),
            // The reader counts what was lost; the board stream's decoder resynchronises
            // after the gap by itself (a packet cut by it fails its CRC).
            Record::Lost(_) if self.feature_bytes == 0 && self.counts.odometry == 0 => {
                self.lost_before_data = true;
            }
            Record::TruthPose(p) => {
                self.truth.any = true;
                self.truth.poses.insert(p.t_us, p);
            }
            Record::TruthLandmarks(l) => {
                self.truth.any = true;
                if self.truth.landmarks.is_empty() {
                    self.truth.landmarks = l;
                }
            }
            Record::TruthCamera(c) => {
                self.truth.any = true;
                if self.truth.camera.is_none() {
                    self.truth.camera = Some(c);
                }
            }
            _ => {}
        }
    }

    /// A bag's camera image (or an image message that did not decode): to the host board,
    /// or held until it starts.
    fn image(&mut self, image: Result<CameraImage, (Side, String)>) {
        let Some(host) = &mut self.host else {
            self.early_images.push(image);
            return;
        };
        match image {
            Ok(image) => host.push(image),
            Err((side, problem)) => host.push_undecodable(side, &problem),
        }
        let mut frames = Vec::new();
        host_frames(host, &mut frames);
        self.hold_frames(frames);
    }

    fn hold_frames(&mut self, frames: Vec<DecodedFrame>) {
        for frame in frames {
            self.window.push_frame(frame.t_us, frame);
        }
        self.counts.frames_out_of_order = self.window.frames_out_of_order();
    }
}

/// What became of a bag's camera images, one warning per kind of loss (with its first case).
pub(crate) fn image_warnings(images: &host_board::ImageCounts) -> Vec<String> {
    let mut out = Vec::new();
    if images.unpaired > 0 {
        out.push(format!(
            "{} of {} camera images had no partner within a quarter of the frame interval \
             (frames with one image): left out",
            images.unpaired,
            images.left + images.right
        ));
    }
    if images.pairing_forced > 0 {
        out.push(format!(
            "the bag's images are far from stamp order: {} pairings were decided before their \
             partner could have come (held images past {} or {} MiB); reorder the bag by log \
             time (e.g. `mcap sort`)",
            images.pairing_forced,
            host_board::pair::MAX_HELD,
            host_board::pair::MAX_HELD_BYTES >> 20
        ));
    }
    if images.bad_images() > 0 {
        out.push(format!(
            "{} camera images could not be read ({} of the wrong size, {} of an encoding not \
             read, {} undecodable), {} stereo frames lost; the first: {}",
            images.bad_images(),
            images.wrong_size,
            images.unsupported,
            images.undecodable,
            images.frames_dropped,
            images.first_problems.join("; ")
        ));
    }
    out
}

/// The error for a ROS 2 bag with camera images replayed without its topics named, if the
/// foreign channels are such a bag's.
pub(crate) fn ros2_hint(path: &Path, channels: &[(String, String)]) -> Option<Error> {
    let of = |types: &[&str]| -> Vec<String> {
        channels
            .iter()
            .filter(|(_, ty)| {
                types
                    .iter()
                    .any(|t| vehicle_log::ros2::msgdef::normalise_type_name(ty) == *t)
            })
            .map(|(topic, ty)| format!("{topic} ({ty})"))
            .collect()
    };
    let cameras = of(&["sensor_msgs/Image", "sensor_msgs/CompressedImage"]);
    let odometry = of(&["nav_msgs/Odometry"]);
    (!cameras.is_empty()).then(|| Error::Ros2TopicsNotNamed {
        path: path.to_path_buf(),
        cameras,
        odometry,
    })
}

/// The three topics of a bag's replay are three: one topic named for two roles is refused.
pub fn check_topics(t: &Ros2Topics) -> Result<(), Error> {
    for (i, a) in Role::ALL.into_iter().enumerate() {
        for b in Role::ALL.into_iter().skip(i + 1) {
            if t.topic(a) == t.topic(b) {
                return Err(Error::TopicNamedTwice {
                    first: a.option(),
                    second: b.option(),
                    topic: t.topic(a).to_owned(),
                });
            }
        }
    }
    Ok(())
}

/// The stereo frames the host board has ready, as pixels onto `frames`.
fn host_frames(host: &mut HostBoard, frames: &mut Vec<DecodedFrame>) {
    let px = |x: &harris_core::Feature| Pixel::from_q4(x.x_q4, x.y_q4);
    while let Some(f) = host.pop() {
        frames.push(DecodedFrame {
            t_us: f.t_us,
            left: f.left.iter().map(px).collect(),
            right: f.right.iter().map(px).collect(),
        });
    }
}

/// A chunk of the board's byte stream through `decoder`: its good frames onto `frames`.
pub(crate) fn decode_chunk(decoder: &mut Decoder, chunk: &[u8], frames: &mut Vec<DecodedFrame>) {
    let mut rest = chunk;
    loop {
        let (used, event) = decoder.decode(rest);
        rest = rest.get(used..).unwrap_or_default();
        match event {
            Some(event) => take_event(event, frames),
            None => break,
        }
    }
}

/// The end of the stream: the frames `decoder` still holds onto `frames`.
pub(crate) fn decode_end(decoder: &mut Decoder, frames: &mut Vec<DecodedFrame>) {
    while let Some(event) = decoder.decode_end() {
        take_event(event, frames);
    }
}

/// A decoder event: a good frame is kept as pixels, a corrupt packet only counted (by the
/// decoder).
fn take_event(event: Event<'_>, frames: &mut Vec<DecodedFrame>) {
    if let Event::Frame(f) = event {
        let px = |x: fpga_link::Feature| Pixel::from_q4(x.x_q4, x.y_q4);
        frames.push(DecodedFrame {
            t_us: f.t_us(),
            left: f.left().map(px).collect(),
            right: f.right().map(px).collect(),
        });
    }
}
