//! A simulated run as a ROS 2 bag (vehicle-interfaces.md 4.1): the rendered images of both
//! cameras and the odometry, as a robot without the board records them (rosbag2's MCAP
//! storage), with the simulator's truth beside them.
//!
//! | topic | message encoding | schema (encoding) | message | log time |
//! |---|---|---|---|---|
//! | `/cam0/image_raw`, `/cam1/image_raw` | `cdr` | `sensor_msgs/msg/Image` (`ros2msg`) | the left, right image: `mono8`, `step` = width | stamp + [`IMAGE_DELAY_US`] |
//! | `/cam0/image_raw/compressed`, `/cam1/image_raw/compressed` | `cdr` | `sensor_msgs/msg/CompressedImage` (`ros2msg`) | the same images as `png` or `jpeg` (8-bit gray) | stamp + [`IMAGE_DELAY_US`] |
//! | `/odom` | `cdr` | `nav_msgs/msg/Odometry` (`ros2msg`) | each odometry sample: `twist.twist.linear.x`, `.y` = `vx`, `vy`, `twist.twist.angular.z` = `vtheta`; `pose.pose` the samples integrated from the first (frame `odom`, child `base_link`); covariances zero | stamp |
//! | `/truth/pose`, `/truth/landmarks`, `/truth/camera` | `json` | vehicle-log's (`jsonschema`) | as in a vehicle log | as in a vehicle log |
//!
//! Stamps (`header.stamp`) are the frame's `t_us` (the board's clock, as in a vehicle log) and
//! the odometry sample's `t_us`: `sec = t_us / 10^6`, `nanosec` the rest in nanoseconds. The
//! images are raw through the scenario's lenses when its rig has `[lens.*]` tables
//! ([`crate::Renderer::with_lens`]), with the sensor's noise, 8 bits: those from which the
//! rendered mode's features are detected. The bag has the `ros2` profile; schemas are the
//! message definitions as rosbag2 writes them (`ros2msg`: the type's `.msg` text, then each
//! type it uses after a line of 80 `=` and `MSG: package/Type`), messages are CDR
//! (little-endian, XCDR1). No `/fpga/features` and no `/rig`: a robot without the board has
//! neither; the rig file goes beside the bag.
//!
//! Written as it is simulated: a batch of frames is rendered over the machine's threads, its
//! images encoded there, then written with the odometry up to them, and dropped; so memory
//! holds one batch's images whatever the run's length.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufWriter, Seek, Write};
use std::path::Path;

use image::ImageEncoder;
use mcap::records::MessageHeader;
use mcap::{Compression, WriteOptions};
use rig_model::Pose2;
use vehicle_log::topics;

use crate::error::{Error, Result};
use crate::motion::{OdomSample, integrate, us_to_s};
use crate::render::StereoImages;
use crate::run::{FrameTruth, Mode, Plan, SimRun, truth_camera, truth_landmarks};
use crate::scenario::Scenario;

/// The left camera's raw images.
pub const LEFT_IMAGE_TOPIC: &str = "/cam0/image_raw";
/// The right camera's raw images.
pub const RIGHT_IMAGE_TOPIC: &str = "/cam1/image_raw";
/// The left camera's compressed images.
pub const LEFT_COMPRESSED_TOPIC: &str = "/cam0/image_raw/compressed";
/// The right camera's compressed images.
pub const RIGHT_COMPRESSED_TOPIC: &str = "/cam1/image_raw/compressed";
/// The odometry.
pub const ODOM_TOPIC: &str = "/odom";
/// The images' `header.frame_id`, left and right.
pub const IMAGE_FRAME_IDS: [&str; 2] = ["cam0", "cam1"];
/// The odometry's `header.frame_id`.
pub const ODOM_FRAME_ID: &str = "odom";
/// The odometry's `child_frame_id`.
pub const ODOM_CHILD_FRAME_ID: &str = "base_link";
/// An image is logged this long after its stamp (exposure, read-out and transport to the
/// recorder), microseconds.
pub const IMAGE_DELAY_US: u64 = 8_000;
/// The JPEG quality when none is given.
pub const DEFAULT_JPEG_QUALITY: u8 = 90;

/// Frames rendered and encoded per batch of worker threads: the images held at once.
const BAG_BATCH: usize = 16;
/// A chunk of the bag is closed once it holds this many bytes (uncompressed).
const CHUNK_BYTES: u64 = 4 << 20;
/// The CDR encapsulation header: XCDR1, little-endian (`CDR_LE`), no options.
const CDR_LE_HEADER: [u8; 4] = [0x00, 0x01, 0x00, 0x00];
/// The line that introduces each dependency in a `ros2msg` definition.
const DEFINITION_SEPARATOR: &str =
    "================================================================================";
const NS_PER_US: u64 = 1000;
const US_PER_S: u64 = 1_000_000;

/// How the images go into the bag.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BagImages {
    /// `sensor_msgs/msg/Image`, `mono8`.
    Raw,
    /// `sensor_msgs/msg/CompressedImage`, format `png` (lossless).
    Png,
    /// `sensor_msgs/msg/CompressedImage`, format `jpeg`, 8-bit gray at this quality (1-100).
    Jpeg {
        /// The encoder's quality, 1 (worst) to 100.
        quality: u8,
    },
}

impl BagImages {
    /// `"raw"`, `"png"` or `"jpeg"`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Raw => "raw",
            Self::Png => "png",
            Self::Jpeg { .. } => "jpeg",
        }
    }

    /// The image topics, left and right.
    pub fn topics(self) -> [&'static str; 2] {
        match self {
            Self::Raw => [LEFT_IMAGE_TOPIC, RIGHT_IMAGE_TOPIC],
            Self::Png | Self::Jpeg { .. } => [LEFT_COMPRESSED_TOPIC, RIGHT_COMPRESSED_TOPIC],
        }
    }

    /// The images' ROS 2 message type.
    pub fn message_type(self) -> &'static str {
        match self {
            Self::Raw => "sensor_msgs/msg/Image",
            Self::Png | Self::Jpeg { .. } => "sensor_msgs/msg/CompressedImage",
        }
    }
}

/// Simulates `scenario` in the rendered mode and writes it as a ROS 2 bag to `path` (created or
/// truncated); returns the run (its frames, features and truth, as [`crate::simulate`] gives
/// them). `progress(frames_done, frames_total)` is called after each batch.
pub fn write_bag(
    scenario: &Scenario,
    images: BagImages,
    path: &Path,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<SimRun> {
    let file = File::create(path).map_err(|e| Error::Write {
        path: path.to_path_buf(),
        reason: e.to_string(),
    })?;
    let (run, mut w) = write_bag_to(scenario, images, BufWriter::new(file), progress)?;
    w.flush().map_err(|e| Error::Write {
        path: path.to_path_buf(),
        reason: e.to_string(),
    })?;
    Ok(run)
}

/// [`write_bag`] into `w`; returns the run and `w`.
pub fn write_bag_to<W: Write + Seek>(
    scenario: &Scenario,
    images: BagImages,
    w: W,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<(SimRun, W)> {
    if let BagImages::Jpeg { quality } = images
        && !(1..=100).contains(&quality)
    {
        return Err(Error::JpegQuality { quality });
    }
    let plan = Plan::new(scenario, Mode::Rendered)?;
    let mut bag = Bag::new(w, images)?;
    let truth = scenario.spec.log.truth;
    let first_us = plan
        .odometry
        .first()
        .map(|s| s.t_us)
        .into_iter()
        .chain(plan.first_stamp_us())
        .min()
        .unwrap_or(0);
    if truth {
        let camera = serde_json::to_vec(&truth_camera(&plan.camera)).map_err(json_error)?;
        #[derive(serde::Serialize)]
        struct Landmarks {
            landmarks: Vec<vehicle_log::TruthLandmark>,
        }
        let landmarks = serde_json::to_vec(&Landmarks {
            landmarks: truth_landmarks(&plan.landmarks),
        })
        .map_err(json_error)?;
        let at = first_us.saturating_mul(NS_PER_US);
        bag.write(Channel::TruthCamera, at, &camera)?;
        bag.write(Channel::TruthLandmarks, at, &landmarks)?;
    }
    let mut odometry = OdometryWriter::new(&plan.odometry);
    let mut frames = Vec::with_capacity(plan.frame_count());
    plan.frames(
        BAG_BATCH,
        &|frame, stereo| {
            let stereo = stereo.ok_or(Error::NoImages { frame: frame.index })?;
            encode_images(frame, &stereo, images)
        },
        &mut |frame, [left, right]| {
            let stamp_ns = frame.t_us.saturating_mul(NS_PER_US);
            odometry.write_until(&mut bag, stamp_ns)?;
            if truth {
                let pose = serde_json::to_vec(&vehicle_log::TruthPose {
                    t_us: frame.t_us,
                    x: frame.pose.x,
                    y: frame.pose.y,
                    theta: frame.pose.theta,
                })
                .map_err(json_error)?;
                bag.write(Channel::TruthPose, stamp_ns, &pose)?;
            }
            let logged_ns = frame
                .t_us
                .saturating_add(IMAGE_DELAY_US)
                .saturating_mul(NS_PER_US);
            odometry.write_until(&mut bag, logged_ns)?;
            bag.write(Channel::Left, logged_ns, &left)?;
            bag.write(Channel::Right, logged_ns, &right)?;
            frames.push(frame);
            Ok(())
        },
        progress,
    )?;
    odometry.write_until(&mut bag, u64::MAX)?;
    let w = bag.finish()?;
    Ok((plan.finish(frames)?, w))
}

fn json_error(e: serde_json::Error) -> Error {
    Error::Json {
        reason: e.to_string(),
    }
}

/// The channels of the bag.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Channel {
    Left,
    Right,
    Odom,
    TruthPose,
    TruthLandmarks,
    TruthCamera,
}

impl Channel {
    const ALL: [Channel; 6] = [
        Channel::Left,
        Channel::Right,
        Channel::Odom,
        Channel::TruthPose,
        Channel::TruthLandmarks,
        Channel::TruthCamera,
    ];
}

/// The bag being written: the MCAP writer, its channels (added on their first message) and
/// their sequence numbers.
struct Bag<W: Write + Seek> {
    mcap: mcap::Writer<W>,
    images: BagImages,
    ids: [Option<u16>; Channel::ALL.len()],
    sequences: [u32; Channel::ALL.len()],
}

impl<W: Write + Seek> Bag<W> {
    fn new(w: W, images: BagImages) -> Result<Self> {
        let options = WriteOptions::new()
            .profile("ros2")
            // Raw images compress; PNG and JPEG do not.
            .compression(match images {
                BagImages::Raw => Some(Compression::Zstd),
                BagImages::Png | BagImages::Jpeg { .. } => None,
            })
            .chunk_size(Some(CHUNK_BYTES))
            .compression_threads(0)
            .library(format!(
                "stereonav sim {} ({})",
                env!("CARGO_PKG_VERSION"),
                mcap::LIBRARY_IDENTIFIER
            ));
        Ok(Self {
            mcap: options.create(w)?,
            images,
            ids: [None; Channel::ALL.len()],
            sequences: [0; Channel::ALL.len()],
        })
    }

    /// The topic, message encoding, schema name, schema encoding and schema of a channel.
    fn describe(
        &self,
        channel: Channel,
    ) -> (
        &'static str,
        &'static str,
        &'static str,
        &'static str,
        String,
    ) {
        let ros = |topic: &'static str, name: &'static str| {
            (topic, "cdr", name, "ros2msg", ros2msg_definition(name))
        };
        let json = |topic: &'static str, name: &'static str, schema: &'static str| {
            (
                topic,
                topics::JSON_ENCODING,
                name,
                topics::JSONSCHEMA_ENCODING,
                schema.to_string(),
            )
        };
        let [left, right] = self.images.topics();
        match channel {
            Channel::Left => ros(left, self.images.message_type()),
            Channel::Right => ros(right, self.images.message_type()),
            Channel::Odom => ros(ODOM_TOPIC, "nav_msgs/msg/Odometry"),
            Channel::TruthPose => json(
                topics::TRUTH_POSE,
                topics::TRUTH_POSE_SCHEMA_NAME,
                topics::TRUTH_POSE_SCHEMA,
            ),
            Channel::TruthLandmarks => json(
                topics::TRUTH_LANDMARKS,
                topics::TRUTH_LANDMARKS_SCHEMA_NAME,
                topics::TRUTH_LANDMARKS_SCHEMA,
            ),
            Channel::TruthCamera => json(
                topics::TRUTH_CAMERA,
                topics::TRUTH_CAMERA_SCHEMA_NAME,
                topics::TRUTH_CAMERA_SCHEMA,
            ),
        }
    }

    fn write(&mut self, channel: Channel, log_time_ns: u64, data: &[u8]) -> Result<()> {
        let index = channel as usize;
        let channel_id = match self.ids.get(index).copied().flatten() {
            Some(id) => id,
            None => {
                let (topic, encoding, schema_name, schema_encoding, schema) =
                    self.describe(channel);
                let schema_id =
                    self.mcap
                        .add_schema(schema_name, schema_encoding, schema.as_bytes())?;
                let id = self
                    .mcap
                    .add_channel(schema_id, topic, encoding, &BTreeMap::new())?;
                if let Some(slot) = self.ids.get_mut(index) {
                    *slot = Some(id);
                }
                id
            }
        };
        let sequence = self.sequences.get(index).copied().unwrap_or(0);
        if let Some(s) = self.sequences.get_mut(index) {
            *s = s.wrapping_add(1);
        }
        let header = MessageHeader {
            channel_id,
            sequence,
            log_time: log_time_ns,
            publish_time: log_time_ns,
        };
        self.mcap.write_to_known_channel(&header, data)?;
        Ok(())
    }

    fn finish(mut self) -> Result<W> {
        self.mcap.finish()?;
        Ok(self.mcap.into_inner())
    }
}

/// The odometry samples as `nav_msgs/msg/Odometry`, written in order up to a log time, with the
/// pose integrated from the first sample.
struct OdometryWriter<'a> {
    samples: &'a [OdomSample],
    next: usize,
    pose: Pose2,
}

impl<'a> OdometryWriter<'a> {
    fn new(samples: &'a [OdomSample]) -> Self {
        Self {
            samples,
            next: 0,
            pose: Pose2::new(0.0, 0.0, 0.0),
        }
    }

    /// Writes every sample not yet written whose stamp is at most `ns`.
    fn write_until<W: Write + Seek>(&mut self, bag: &mut Bag<W>, ns: u64) -> Result<()> {
        while let Some(s) = self.samples.get(self.next) {
            let stamp_ns = s.t_us.saturating_mul(NS_PER_US);
            if stamp_ns > ns {
                break;
            }
            bag.write(Channel::Odom, stamp_ns, &odometry_message(s, &self.pose)?)?;
            if let Some(n) = self.samples.get(self.next + 1) {
                let dt_s = us_to_s(n.t_us.saturating_sub(s.t_us));
                self.pose = integrate(&self.pose, s.vx, s.vy, s.vtheta, dt_s);
            }
            self.next += 1;
        }
        Ok(())
    }
}

/// The two images of a frame as messages.
fn encode_images(
    frame: &FrameTruth,
    stereo: &StereoImages,
    images: BagImages,
) -> Result<[Vec<u8>; 2]> {
    let one =
        |pixels: &[u8], frame_id: &str| image_message(frame, stereo, pixels, frame_id, images);
    Ok([
        one(&stereo.left, IMAGE_FRAME_IDS[0])?,
        one(&stereo.right, IMAGE_FRAME_IDS[1])?,
    ])
}

/// One camera's image as `sensor_msgs/msg/Image` or `sensor_msgs/msg/CompressedImage`.
fn image_message(
    frame: &FrameTruth,
    stereo: &StereoImages,
    pixels: &[u8],
    frame_id: &str,
    images: BagImages,
) -> Result<Vec<u8>> {
    let too_large = |what: &'static str| Error::TooLarge {
        what,
        len: stereo.width.max(stereo.height),
    };
    let width = u32::try_from(stereo.width).map_err(|_| too_large("image width"))?;
    let height = u32::try_from(stereo.height).map_err(|_| too_large("image height"))?;
    let mut cdr = Cdr::new();
    cdr.header(frame.t_us, frame_id)?;
    match images {
        BagImages::Raw => {
            cdr.u32(height);
            cdr.u32(width);
            cdr.string("mono8")?;
            cdr.u8(0); // is_bigendian
            cdr.u32(width); // step: one byte a pixel
            cdr.bytes(pixels)?;
        }
        BagImages::Png | BagImages::Jpeg { .. } => {
            let mut data = Vec::new();
            let encoded = match images {
                BagImages::Jpeg { quality } => {
                    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut data, quality)
                        .write_image(pixels, width, height, image::ExtendedColorType::L8)
                }
                _ => image::codecs::png::PngEncoder::new(&mut data).write_image(
                    pixels,
                    width,
                    height,
                    image::ExtendedColorType::L8,
                ),
            };
            encoded.map_err(|e| Error::ImageEncode {
                frame: frame.index,
                format: images.name(),
                reason: e.to_string(),
            })?;
            cdr.string(images.name())?;
            cdr.bytes(&data)?;
        }
    }
    Ok(cdr.finish())
}

/// One odometry sample as `nav_msgs/msg/Odometry` at the integrated `pose`.
fn odometry_message(s: &OdomSample, pose: &Pose2) -> Result<Vec<u8>> {
    let mut cdr = Cdr::new();
    cdr.header(s.t_us, ODOM_FRAME_ID)?;
    cdr.string(ODOM_CHILD_FRAME_ID)?;
    // pose.pose: position, orientation (a rotation about z by theta), covariance.
    let (sin, cos) = (pose.theta / 2.0).sin_cos();
    for v in [pose.x, pose.y, 0.0, 0.0, 0.0, sin, cos] {
        cdr.f64(v);
    }
    for _ in 0..36 {
        cdr.f64(0.0);
    }
    // twist.twist: linear, angular, covariance.
    for v in [s.vx, s.vy, 0.0, 0.0, 0.0, s.vtheta] {
        cdr.f64(v);
    }
    for _ in 0..36 {
        cdr.f64(0.0);
    }
    Ok(cdr.finish())
}

/// A CDR message being written (XCDR1, little-endian: what ROS 2's default middleware sends
/// and rosbag2 stores). Written here rather than taken from a crate: a few primitives suffice,
/// and it is the test side's writer of the bags the stack's reader reads, so it must not share
/// the reader's code (vehicle-log's ROS 2 reader decodes CDR on its own).
///
/// Each primitive is aligned to its size, counted from the end of the 4-byte encapsulation
/// header; a string is its length with the terminating NUL (`uint32`), its bytes and the NUL;
/// a sequence is its count (`uint32`) and its elements; a fixed array its elements alone.
struct Cdr {
    buf: Vec<u8>,
}

impl Cdr {
    fn new() -> Self {
        Self {
            buf: CDR_LE_HEADER.to_vec(),
        }
    }

    fn align(&mut self, size: usize) {
        while !(self.buf.len() - CDR_LE_HEADER.len()).is_multiple_of(size) {
            self.buf.push(0);
        }
    }

    fn u8(&mut self, v: u8) {
        self.buf.push(v);
    }

    fn u32(&mut self, v: u32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    fn i32(&mut self, v: i32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    fn f64(&mut self, v: f64) {
        self.align(8);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    fn string(&mut self, s: &str) -> Result<()> {
        let len = u32::try_from(s.len() + 1).map_err(|_| Error::TooLarge {
            what: "string",
            len: s.len(),
        })?;
        self.u32(len);
        self.buf.extend_from_slice(s.as_bytes());
        self.buf.push(0);
        Ok(())
    }

    /// A `uint8[]` sequence.
    fn bytes(&mut self, b: &[u8]) -> Result<()> {
        let len = u32::try_from(b.len()).map_err(|_| Error::TooLarge {
            what: "uint8[]",
            len: b.len(),
        })?;
        self.u32(len);
        self.buf.extend_from_slice(b);
        Ok(())
    }

    /// A `std_msgs/Header`: the stamp of `t_us` (`builtin_interfaces/Time`) and the frame.
    fn header(&mut self, t_us: u64, frame_id: &str) -> Result<()> {
        let sec = i32::try_from(t_us / US_PER_S).map_err(|_| Error::Stamp { t_us })?;
        // Below 10^9: the remainder of a division by 10^6, times 1000.
        let nanosec =
            u32::try_from((t_us % US_PER_S) * NS_PER_US).map_err(|_| Error::Stamp { t_us })?;
        self.i32(sec);
        self.u32(nanosec);
        self.string(frame_id)
    }

    fn finish(self) -> Vec<u8> {
        self.buf
    }
}

/// The `.msg` text of each ROS 2 message type the bag uses (Humble and Jazzy alike; field
/// types, names, order and constants' defaults as there, without the comments).
const MESSAGE_DEFINITIONS: [(&str, &str); 12] = [
    (
        "sensor_msgs/Image",
        "std_msgs/Header header\nuint32 height\nuint32 width\nstring encoding\n\
         uint8 is_bigendian\nuint32 step\nuint8[] data\n",
    ),
    (
        "sensor_msgs/CompressedImage",
        "std_msgs/Header header\nstring format\nuint8[] data\n",
    ),
    (
        "nav_msgs/Odometry",
        "std_msgs/Header header\nstring child_frame_id\n\
         geometry_msgs/PoseWithCovariance pose\ngeometry_msgs/TwistWithCovariance twist\n",
    ),
    (
        "std_msgs/Header",
        "builtin_interfaces/Time stamp\nstring frame_id\n",
    ),
    ("builtin_interfaces/Time", "int32 sec\nuint32 nanosec\n"),
    (
        "geometry_msgs/PoseWithCovariance",
        "Pose pose\nfloat64[36] covariance\n",
    ),
    (
        "geometry_msgs/Pose",
        "Point position\nQuaternion orientation\n",
    ),
    ("geometry_msgs/Point", "float64 x\nfloat64 y\nfloat64 z\n"),
    (
        "geometry_msgs/Quaternion",
        "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n",
    ),
    (
        "geometry_msgs/TwistWithCovariance",
        "Twist twist\nfloat64[36] covariance\n",
    ),
    ("geometry_msgs/Twist", "Vector3 linear\nVector3 angular\n"),
    ("geometry_msgs/Vector3", "float64 x\nfloat64 y\nfloat64 z\n"),
];

/// The primitive types of `.msg` files.
const PRIMITIVES: [&str; 14] = [
    "bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16", "int32",
    "uint32", "int64", "uint64", "string",
];

/// The complete `ros2msg` definition of a message type (`sensor_msgs/msg/Image`) as rosbag2
/// writes it: the type's `.msg` text, then each type it uses, depth first in the order of
/// their names, once each, as a line of 80 `=`, a line `MSG: package/Type` and its text.
pub fn ros2msg_definition(message_type: &str) -> String {
    fn text(name: &str) -> &'static str {
        MESSAGE_DEFINITIONS
            .iter()
            .find(|(n, _)| *n == name)
            .map_or("", |(_, t)| t)
    }
    /// The message types a `.msg` text uses, by full name (`package/Type`), sorted.
    fn dependencies(text: &str, package: &str) -> Vec<String> {
        let mut out: Vec<String> = text
            .lines()
            .filter_map(|line| line.split_whitespace().next())
            .map(|t| t.split('[').next().unwrap_or(t))
            .filter(|t| !t.starts_with('#') && !PRIMITIVES.contains(t))
            .map(|t| {
                if t.contains('/') {
                    t.to_string()
                } else {
                    format!("{package}/{t}")
                }
            })
            .collect();
        out.sort();
        out.dedup();
        out
    }
    fn append(name: &str, seen: &mut Vec<String>, out: &mut String) {
        let body = text(name);
        out.push_str(body);
        let package = name.split('/').next().unwrap_or("");
        for dependency in dependencies(body, package) {
            if seen.contains(&dependency) {
                continue;
            }
            seen.push(dependency.clone());
            out.push('\n');
            out.push_str(DEFINITION_SEPARATOR);
            out.push_str("\nMSG: ");
            out.push_str(&dependency);
            out.push('\n');
            append(&dependency, seen, out);
        }
    }
    let name = message_type.replacen("/msg/", "/", 1);
    let mut out = String::new();
    append(&name, &mut Vec::new(), &mut out);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cdr_aligns_from_the_end_of_the_encapsulation_header() {
        let mut cdr = Cdr::new();
        cdr.u8(7);
        cdr.string("ab").unwrap_or_default();
        cdr.u8(1);
        cdr.f64(0.5);
        let b = cdr.finish();
        assert_eq!(
            b,
            [
                0, 1, 0, 0, // encapsulation
                7, 0, 0, 0, // u8, padding to 4
                3, 0, 0, 0, b'a', b'b', 0, // string: length with the NUL
                1, // u8 at offset 11
                0, 0, 0, 0, // padding to 16
                0, 0, 0, 0, 0, 0, 0xe0, 0x3f, // 0.5
            ]
        );
    }

    #[test]
    fn a_stamp_is_seconds_and_nanoseconds() {
        let mut cdr = Cdr::new();
        cdr.header(1_234_567_891, "cam0").unwrap_or_default();
        let b = cdr.finish();
        assert_eq!(&b[4..8], &1234i32.to_le_bytes());
        assert_eq!(&b[8..12], &567_891_000u32.to_le_bytes());
        assert_eq!(&b[12..16], &5u32.to_le_bytes());
        assert_eq!(&b[16..], b"cam0\0");
        assert!(Cdr::new().header(u64::MAX, "x").is_err());
    }

    #[test]
    fn definitions_are_as_rosbag2_writes_them() {
        let d = ros2msg_definition("nav_msgs/msg/Odometry");
        let names: Vec<&str> = d.lines().filter_map(|l| l.strip_prefix("MSG: ")).collect();
        assert_eq!(
            names,
            [
                "geometry_msgs/PoseWithCovariance",
                "geometry_msgs/Pose",
                "geometry_msgs/Point",
                "geometry_msgs/Quaternion",
                "geometry_msgs/TwistWithCovariance",
                "geometry_msgs/Twist",
                "geometry_msgs/Vector3",
                "std_msgs/Header",
                "builtin_interfaces/Time",
            ]
        );
        assert!(d.starts_with("std_msgs/Header header\nstring child_frame_id\n"));
        let sep = format!("\n\n{}\nMSG: std_msgs/Header\n", "=".repeat(80));
        assert!(d.contains(&sep), "{d}");
        let image = ros2msg_definition("sensor_msgs/msg/Image");
        assert_eq!(
            image.lines().filter(|l| l.starts_with("MSG: ")).count(),
            2,
            "{image}"
        );
        assert!(ros2msg_definition("sensor_msgs/msg/CompressedImage").contains("string format\n"));
    }
}
