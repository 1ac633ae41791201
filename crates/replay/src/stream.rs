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
use nav::sequencer::{Sequenced, Sequencer};
use rig_model::odometry::OdomSample;
use track::Pixel;
use vehicle_log::{LogReader, Record, TruthCamera, TruthLandmark, TruthPose};

use crate::{Counts, DecodedFrame, Error};

pub use nav::sequencer::REORDER_US;

/// Most untimed bytes of input read before the log's `/rig` when no rig was given.
const MAX_BYTES_BEFORE_RIG: u64 = 64 << 20;

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
    /// Opens the log at `path` (an MCAP file, or an error).
    pub(crate) fn open(path: &Path) -> Result<Self, Error> {
        let reader = LogReader::open(path)?;
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
        })
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
                self.hold_frames(frames);
                self.window.end();
                let stats = self.decoder.stats();
                self.counts.frames = stats.packets;
                self.counts.corrupt = stats.corrupt;
                self.counts.lost = stats.lost;
                self.counts.bytes_skipped = stats.bytes_skipped;
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

    fn hold_frames(&mut self, frames: Vec<DecodedFrame>) {
        for frame in frames {
            self.window.push_frame(frame.t_us, frame);
        }
        self.counts.frames_out_of_order = self.window.frames_out_of_order();
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
