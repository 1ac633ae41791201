//! A ROS 2 bag's camera images under the image planes (vehicle-interfaces.md 4.1): the left
//! camera's image in the left plane and the right camera's in the right, at the frame shown,
//! in gray exactly as the host's detector saw them (`host_board::gray_pixels`).
//!
//! **Memory.** A shift is hours of 20 Hz stereo images (a 752 x 480 gray pair is 0.7 MB: about
//! 50 GB an hour), so the viewer never holds them all, decoded or not. While the bag is loaded,
//! one pass runs them through the replay's board on the host ([`host_board::HostBoard`]) and keeps, per
//! stereo frame, only where its two images are in the bag: each one's log time and stamp
//! ([`FrameImages`], 40 bytes a frame, like the frame's features that the model keeps anyway).
//! The frame shown is read back when it is asked for ([`BagImages::read`]): the bag's MCAP
//! summary (its chunk index, read once) gives the chunks whose time range holds the image's log
//! time, the chunk is read and decompressed, the message on the camera's topic with that log
//! time and stamp is decoded by vehicle-log's ROS 2 reader and turned into gray pixels. An
//! [`ImageCache`] keeps the last [`CACHE_FRAMES`] frames decoded, so that stepping back and
//! forth or redrawing re-reads nothing; the viewer's memory for images is that cache and the
//! two textures of the frame shown, whatever the bag's length.
//!
//! Why not thumbnails kept in memory: the planes are where a person checks the board's
//! features against the pixels, so they need the image of the very frame whose features are
//! drawn over it, at full resolution. A hard memory cap on thumbnails of an hours-long bag
//! could keep only one frame in hundreds (or images of a few pixels), and the picture under the
//! features would be another frame's. Reading one frame back costs one chunk read and
//! decompressed (a few milliseconds), done only when the frame shown changes.
//!
//! A bag without an intact summary (cut short by a power loss, or damaged at its end) has no
//! chunk index to find a frame's chunk by: its features and estimates are shown as always, its
//! images are not, and the planes say why (`mcap recover` writes such a file again with one).

use std::collections::{BTreeMap, VecDeque};
use std::fmt;
use std::fs::File;
use std::io::{Cursor, Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use host_board::HostBoard;
use mcap::records::MessageHeader;
use mcap::sans_io::indexed_reader::{IndexedReadEvent, IndexedReader, IndexedReaderOptions};
use mcap::sans_io::summary_reader::{SummaryReadEvent, SummaryReader, SummaryReaderOptions};
use vehicle_log::{CameraImage, LogReader, Record, Ros2Topics, Side};

use crate::model::ImagePoint;

/// Frames whose decoded images [`ImageCache`] keeps: the frame shown and the few before it, so
/// that stepping back and forth re-reads nothing. Two gray images a frame.
pub const CACHE_FRAMES: usize = 4;

/// Where one camera image of a frame is in the bag.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ImageRef {
    /// The message's log time, ns (what the bag's chunk index is searched by).
    pub log_time_ns: u64,
    /// The image's `header.stamp`, us (tells it from another message of the same log time).
    pub stamp_us: u64,
}

/// Where the two images of one stereo frame are in the bag.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FrameImages {
    /// The frame's time: the left image's stamp, us (vehicle-interfaces.md 4.1).
    pub t_us: u64,
    /// The left image.
    pub left: ImageRef,
    /// The right image.
    pub right: ImageRef,
}

/// A bag's camera images, by frame: the index built at load time and the means to read a
/// frame's images back (see the module docs). Holds no pixels.
#[derive(Clone)]
pub struct BagImages {
    path: PathBuf,
    topics: Ros2Topics,
    /// The rig's `[camera]` size, pixels: what every image must have.
    size: [u32; 2],
    /// Sorted by `t_us` (stable: equal stamps keep the pairing's order).
    frames: Vec<FrameImages>,
    /// The bag's MCAP summary (schemas, channels, chunk index), or why there is none to use.
    summary: Result<Arc<mcap::Summary>, String>,
}

impl fmt::Debug for BagImages {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("BagImages")
            .field("path", &self.path)
            .field("topics", &self.topics)
            .field("size", &self.size)
            .field("frames", &self.frames.len())
            .field(
                "chunks",
                &self.summary.as_ref().map(|s| s.chunk_indexes.len()),
            )
            .finish()
    }
}

/// One frame's two images read back: 8-bit gray, row-major, [`StereoGray::size`], or why an
/// image could not be read (one line).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct StereoGray {
    /// The frame's time, us.
    pub t_us: u64,
    /// Width and height, pixels.
    pub size: [u32; 2],
    /// The left image's pixels.
    pub left: Result<Vec<u8>, String>,
    /// The right image's pixels.
    pub right: Result<Vec<u8>, String>,
}

impl StereoGray {
    /// Bytes of pixels held.
    pub fn pixel_bytes(&self) -> usize {
        [&self.left, &self.right]
            .iter()
            .map(|r| r.as_ref().map_or(0, Vec::len))
            .sum()
    }
}

impl BagImages {
    /// The frames indexed, in time order.
    pub fn frames(&self) -> &[FrameImages] {
        &self.frames
    }

    /// The images' size, pixels (the rig's `[camera]`).
    pub fn size(&self) -> [u32; 2] {
        self.size
    }

    /// Why no image can be read back (the bag has no usable summary), if so.
    pub fn unavailable(&self) -> Option<&str> {
        self.summary.as_ref().err().map(String::as_str)
    }

    /// Bytes the index holds on the heap: a fixed size per frame, no pixels (the summary's
    /// chunk index, read from the file, aside).
    pub fn index_bytes(&self) -> usize {
        self.frames.capacity() * size_of::<FrameImages>()
    }

    /// Where the images of the frame at exactly `t_us` are, if the bag has them.
    pub fn frame_at(&self, t_us: u64) -> Option<&FrameImages> {
        let i = self.frames.partition_point(|f| f.t_us < t_us);
        self.frames.get(i).filter(|f| f.t_us == t_us)
    }

    /// Reads the two images of the frame at `t_us` from the bag and turns them into gray
    /// pixels. Errors (one line): no frame at that time, or no usable summary; an image that
    /// cannot be read is an `Err` in [`StereoGray`], the other one still read.
    pub fn read(&self, t_us: u64) -> Result<StereoGray, String> {
        let refs = self
            .frame_at(t_us)
            .ok_or_else(|| format!("the bag has no stereo frame at {t_us} us"))?;
        let summary = self.summary.as_ref().map_err(Clone::clone)?;
        let mut file = File::open(&self.path)
            .map_err(|e| format!("cannot open {}: {e}", self.path.display()))?;
        let mut read = |side: Side, r: &ImageRef| self.read_image(&mut file, summary, side, r);
        let left = read(Side::Left, &refs.left);
        let right = read(Side::Right, &refs.right);
        Ok(StereoGray {
            t_us,
            size: self.size,
            left,
            right,
        })
    }

    /// One image, found through the chunk index by its log time on its camera's topic.
    fn read_image(
        &self,
        file: &mut File,
        summary: &mcap::Summary,
        side: Side,
        r: &ImageRef,
    ) -> Result<Vec<u8>, String> {
        let topic = match side {
            Side::Left => &self.topics.left,
            Side::Right => &self.topics.right,
        };
        let at = format!("{topic} image at log time {} ns", r.log_time_ns);
        let options = IndexedReaderOptions::new()
            .include_topics([topic.clone()])
            .starting_at(r.log_time_ns)
            .ending_at(r.log_time_ns)
            .with_record_length_limit(vehicle_log::MAX_RECORD_LEN);
        let mut reader = IndexedReader::new_with_options(summary, options)
            .map_err(|e| format!("{at}: the bag's index: {e}"))?;
        let mut buf = Vec::new();
        let mut problem = None;
        while let Some(event) = reader.next_event() {
            match event.map_err(|e| format!("{at}: {e}"))? {
                IndexedReadEvent::ReadChunkRequest { offset, length } => {
                    buf.resize(length, 0);
                    file.seek(SeekFrom::Start(offset))
                        .and_then(|_| file.read_exact(&mut buf))
                        .map_err(|e| format!("{at}: reading {length} bytes at {offset}: {e}"))?;
                    reader
                        .insert_chunk_record_data(offset, &buf)
                        .map_err(|e| format!("{at}: the chunk at {offset}: {e}"))?;
                }
                IndexedReadEvent::Message { header, data } => {
                    let Some(channel) = summary.channels.get(&header.channel_id) else {
                        continue;
                    };
                    match decode_image(&self.path, &self.topics, channel, &header, data) {
                        Ok(image) if image.t_us == r.stamp_us => {
                            return gray(&image, self.size).map_err(|e| format!("{at}: {e}"));
                        }
                        // Another image logged at the same nanosecond: not this one.
                        Ok(_) => {}
                        Err(e) => problem = Some(format!("{at}: {e}")),
                    }
                }
            }
        }
        Err(problem.unwrap_or_else(|| format!("{at} is not in the bag's index")))
    }
}

/// An image's gray pixels, `size` as the rig's `[camera]` says, checked to be whole.
fn gray(image: &CameraImage, size: [u32; 2]) -> Result<Vec<u8>, String> {
    let [w, h] = size;
    let pixels = host_board::gray_pixels(&image.payload, w, h).map_err(|e| e.to_string())?;
    let expected = w as usize * h as usize;
    if pixels.len() != expected {
        return Err(format!(
            "{} gray pixels, not the {expected} of {w}x{h}",
            pixels.len()
        ));
    }
    Ok(pixels)
}

/// One message of a bag's camera topic decoded into an image by vehicle-log's ROS 2 reader
/// (the one reading of the format): the message, with its channel and schema, is written
/// into a one-message MCAP file in memory and read back with the bag's topics named.
///
/// vehicle-log decodes messages only as a [`LogReader`] yields them; a decoder of one message
/// by its channel's schema, public in `vehicle_log::ros2`, would make this copy unnecessary.
fn decode_image(
    name: &Path,
    topics: &Ros2Topics,
    channel: &mcap::Channel<'_>,
    header: &MessageHeader,
    data: &[u8],
) -> Result<CameraImage, String> {
    let wrap = |e: mcap::McapError| format!("cannot wrap the message for decoding: {e}");
    let mut writer = mcap::WriteOptions::new()
        .compression(None)
        .create(Cursor::new(Vec::new()))
        .map_err(wrap)?;
    let schema_id = match &channel.schema {
        Some(s) => writer
            .add_schema(&s.name, &s.encoding, &s.data)
            .map_err(wrap)?,
        None => 0,
    };
    let channel_id = writer
        .add_channel(
            schema_id,
            &channel.topic,
            &channel.message_encoding,
            &BTreeMap::new(),
        )
        .map_err(wrap)?;
    writer
        .write_to_known_channel(
            &MessageHeader {
                channel_id,
                ..*header
            },
            data,
        )
        .map_err(wrap)?;
    writer.finish().map_err(wrap)?;
    let bytes = writer.into_inner().into_inner();
    let mut reader = LogReader::new(Cursor::new(bytes), name).map_err(|e| e.to_string())?;
    reader.set_ros2_topics(topics.clone());
    for record in reader {
        match record.map_err(|e| e.to_string())? {
            Record::Image(image) => return Ok(image),
            Record::BadImage { problem, .. } => return Err(problem),
            _ => {}
        }
    }
    Err("the message holds no image".to_owned())
}

/// The decoded images of the last frames shown, at most [`CACHE_FRAMES`], most recent last.
#[derive(Debug, Default)]
pub struct ImageCache {
    entries: VecDeque<(u64, Result<Arc<StereoGray>, String>)>,
}

impl ImageCache {
    /// An empty cache.
    pub fn new() -> Self {
        Self::default()
    }

    /// The images of the frame at `t_us`: from the cache, or read from the bag (and kept,
    /// the oldest frame dropped past [`CACHE_FRAMES`]).
    pub fn frame(&mut self, images: &BagImages, t_us: u64) -> Result<Arc<StereoGray>, String> {
        let entry = match self.entries.iter().position(|(t, _)| *t == t_us) {
            Some(i) => self.entries.remove(i),
            None => None,
        };
        let entry = entry.unwrap_or_else(|| (t_us, images.read(t_us).map(Arc::new)));
        let out = entry.1.clone();
        self.entries.push_back(entry);
        while self.entries.len() > CACHE_FRAMES {
            self.entries.pop_front();
        }
        out
    }

    /// Frames held.
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    /// Whether no frame is held.
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// Bytes of pixels held.
    pub fn pixel_bytes(&self) -> usize {
        self.entries
            .iter()
            .filter_map(|(_, e)| e.as_ref().ok())
            .map(|g| g.pixel_bytes())
            .sum()
    }
}

/// A stereo frame found by the load pass: its time, the left and right features (the board's
/// Harris on the host, in the board's order) and where its images are.
pub(crate) struct IndexedFrame {
    pub(crate) left: Vec<ImagePoint>,
    pub(crate) right: Vec<ImagePoint>,
    pub(crate) images: FrameImages,
}

/// The load pass over a bag's images: pairs them as the replay's host board does, runs the
/// board's detector on both images of each frame (the features the navigator got: same
/// pairing, same registers, same order), and keeps each frame's features and where its images
/// are, never the pixels. Feed it the bag's [`Record::Image`]s in log order.
pub(crate) struct Indexer {
    board: HostBoard,
    frames: Vec<IndexedFrame>,
}

impl Indexer {
    /// Errors: registers the board's detector cannot run with.
    pub(crate) fn new(regs: harris_core::Registers) -> Result<Self, harris_core::Error> {
        Ok(Self {
            board: HostBoard::new(regs)?,
            frames: Vec::new(),
        })
    }

    /// Takes an image of the bag, in log order.
    pub(crate) fn push(&mut self, image: CameraImage) {
        self.board.push(image);
        self.drain();
    }

    /// The frames the host board lets out, as the replay's: a lone image, or a frame with an
    /// image the detector cannot read, is none.
    fn drain(&mut self) {
        let points = |features: &[harris_core::Feature]| -> Vec<ImagePoint> {
            features
                .iter()
                .map(|f| {
                    let p = track::Pixel::from_q4(f.x_q4, f.y_q4);
                    // Pixels of a 4095-pixel image at most, in sixteenths: exact in f32.
                    [p.u as f32, p.v as f32]
                })
                .collect()
        };
        while let Some(f) = self.board.pop() {
            self.frames.push(IndexedFrame {
                left: points(&f.left),
                right: points(&f.right),
                images: FrameImages {
                    t_us: f.t_us,
                    left: ImageRef {
                        log_time_ns: f.log_time_ns[0],
                        stamp_us: f.t_us,
                    },
                    right: ImageRef {
                        log_time_ns: f.log_time_ns[1],
                        stamp_us: f.right_t_us,
                    },
                },
            });
        }
    }

    /// No more images: the frames, sorted by time, and the bag's image index over them.
    /// `summary_intact`: vehicle-log found the bag's summary intact (else why not).
    pub(crate) fn finish(
        mut self,
        path: &Path,
        topics: &Ros2Topics,
        size: [u32; 2],
        summary_intact: Result<(), String>,
    ) -> (Vec<IndexedFrame>, BagImages) {
        self.board.end();
        self.drain();
        let mut frames = self.frames;
        // Stable: equal stamps keep the pairing's order, as the replay's sequencer does.
        frames.sort_by_key(|f| f.images.t_us);
        let summary = summary_intact
            .and_then(|()| read_summary(path))
            .map(Arc::new);
        let images = BagImages {
            path: path.to_path_buf(),
            topics: topics.clone(),
            size,
            frames: frames.iter().map(|f| f.images).collect(),
            summary,
        };
        (frames, images)
    }
}

/// The bag's MCAP summary section (schemas, channels, chunk index), through its footer.
fn read_summary(path: &Path) -> Result<mcap::Summary, String> {
    let fail = |e: &dyn fmt::Display| format!("the bag's summary cannot be read ({e})");
    let mut file = File::open(path).map_err(|e| fail(&e))?;
    let len = file.metadata().map_err(|e| fail(&e))?.len();
    let mut reader = SummaryReader::new_with_options(
        SummaryReaderOptions::default()
            .with_file_size(len)
            .with_record_length_limit(vehicle_log::MAX_RECORD_LEN),
    );
    while let Some(event) = reader.next_event() {
        match event.map_err(|e| fail(&e))? {
            SummaryReadEvent::ReadRequest(n) => {
                let read = file.read(reader.insert(n)).map_err(|e| fail(&e))?;
                reader.notify_read(read);
            }
            SummaryReadEvent::SeekRequest(to) => {
                let at = file.seek(to).map_err(|e| fail(&e))?;
                reader.notify_seeked(at);
            }
        }
    }
    let summary = reader
        .finish()
        .ok_or_else(|| "the bag has no summary section".to_owned())?;
    if summary.chunk_indexes.is_empty() {
        return Err("the bag's summary has no chunk index".to_owned());
    }
    Ok(summary)
}
