//! ROS 2 bags (vehicle-interfaces.md 4.1): the `mcap` crate reads what the simulator writes,
//! with the `ros2` profile, the channels and `ros2msg` schemas of rosbag2's MCAP storage; a
//! hand-written CDR reader (independent of the writer) finds the stamps and fields; PNG images
//! are the rendered pixels exactly, and the board's detector finds on them the run's features.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failure is the test failing

use std::collections::{BTreeMap, BTreeSet};
use std::io::Cursor;

use crate::common;

use sim::BagImages;
use sim::bag::ros2msg_definition;
use sim::scenario::Segment;

/// The radtan experiment (raw images through EuRoC's lenses) cut to a few frames: a wait and a
/// short move.
fn short_radtan() -> sim::Scenario {
    let mut s = common::load("paper-experiment-radtan");
    s.spec.path.segments = vec![Segment::wait(0.1), Segment::straight(0.05)];
    s.spec.path.repeat = 1;
    s
}

fn bag(s: &sim::Scenario, images: BagImages) -> (sim::SimRun, Vec<u8>) {
    let (run, cursor) =
        sim::write_bag_to(s, images, Cursor::new(Vec::new()), &mut |_, _| {}).unwrap();
    (run, cursor.into_inner())
}

/// One message as read back.
struct Read {
    topic: String,
    encoding: String,
    schema: Option<(String, String, Vec<u8>)>,
    log_time: u64,
    sequence: u32,
    data: Vec<u8>,
}

fn messages(bytes: &[u8]) -> Vec<Read> {
    mcap::MessageStream::new(bytes)
        .unwrap()
        .map(|m| {
            let m = m.unwrap();
            Read {
                topic: m.channel.topic.clone(),
                encoding: m.channel.message_encoding.clone(),
                schema: m
                    .channel
                    .schema
                    .as_ref()
                    .map(|s| (s.name.clone(), s.encoding.clone(), s.data.to_vec())),
                log_time: m.log_time,
                sequence: m.sequence,
                data: m.data.to_vec(),
            }
        })
        .collect()
}

fn on<'a>(all: &'a [Read], topic: &str) -> Vec<&'a Read> {
    all.iter().filter(|m| m.topic == topic).collect()
}

/// A CDR reader (XCDR1 little-endian), written for this test apart from the writer.
struct Cdr<'a> {
    b: &'a [u8],
    at: usize,
}

impl<'a> Cdr<'a> {
    fn new(b: &'a [u8]) -> Self {
        assert_eq!(&b[..4], &[0, 1, 0, 0], "CDR_LE encapsulation");
        Self { b, at: 4 }
    }
    fn take(&mut self, n: usize, align: usize) -> &'a [u8] {
        // Alignment counts from the byte after the encapsulation header.
        self.at += (align - (self.at - 4) % align) % align;
        let s = &self.b[self.at..self.at + n];
        self.at += n;
        s
    }
    fn u8(&mut self) -> u8 {
        self.take(1, 1)[0]
    }
    fn u32(&mut self) -> u32 {
        u32::from_le_bytes(self.take(4, 4).try_into().unwrap())
    }
    fn i32(&mut self) -> i32 {
        i32::from_le_bytes(self.take(4, 4).try_into().unwrap())
    }
    fn f64(&mut self) -> f64 {
        f64::from_le_bytes(self.take(8, 8).try_into().unwrap())
    }
    fn string(&mut self) -> String {
        let n = self.u32() as usize;
        let s = self.take(n, 1);
        assert_eq!(s.last(), Some(&0), "a string ends with its NUL");
        String::from_utf8(s[..n - 1].to_vec()).unwrap()
    }
    fn bytes(&mut self) -> &'a [u8] {
        let n = self.u32() as usize;
        self.take(n, 1)
    }
    /// `std_msgs/Header`: stamp in microseconds and frame id.
    fn header(&mut self) -> (u64, String) {
        let sec = self.i32();
        let nanosec = self.u32();
        assert!(nanosec < 1_000_000_000 && nanosec.is_multiple_of(1000));
        (
            sec as u64 * 1_000_000 + u64::from(nanosec / 1000),
            self.string(),
        )
    }
    fn end(&self) {
        assert_eq!(self.at, self.b.len(), "the whole message is read");
    }
}

/// `sensor_msgs/msg/Image`: stamp, frame, height, width, pixels.
fn read_image(data: &[u8]) -> (u64, String, u32, u32, Vec<u8>) {
    let mut r = Cdr::new(data);
    let (t_us, frame) = r.header();
    let (height, width) = (r.u32(), r.u32());
    assert_eq!(r.string(), "mono8");
    assert_eq!(r.u8(), 0, "is_bigendian");
    assert_eq!(r.u32(), width, "step");
    let pixels = r.bytes().to_vec();
    r.end();
    (t_us, frame, height, width, pixels)
}

/// `sensor_msgs/msg/CompressedImage`: stamp, frame, format, data.
fn read_compressed(data: &[u8]) -> (u64, String, String, Vec<u8>) {
    let mut r = Cdr::new(data);
    let (t_us, frame) = r.header();
    let format = r.string();
    let bytes = r.bytes().to_vec();
    r.end();
    (t_us, frame, format, bytes)
}

#[test]
fn a_png_bag_has_ros2_channels_schemas_and_the_rendered_pixels() {
    let s = short_radtan();
    let (run, bytes) = bag(&s, BagImages::Png);
    assert!(run.frames.len() >= 4, "{} frames", run.frames.len());
    // The ros2 profile.
    let header = mcap::read::LinearReader::new(&bytes)
        .unwrap()
        .find_map(|r| match r.unwrap() {
            mcap::records::Record::Header(h) => Some(h),
            _ => None,
        })
        .unwrap();
    assert_eq!(header.profile, "ros2");
    let all = messages(&bytes);
    // Channels: topic -> (message encoding, schema name, schema encoding).
    let channels: BTreeMap<&str, (&str, &str, &str)> = all
        .iter()
        .map(|m| {
            let (name, encoding, _) = m.schema.as_ref().unwrap();
            (
                m.topic.as_str(),
                (m.encoding.as_str(), name.as_str(), encoding.as_str()),
            )
        })
        .collect();
    let image = ("cdr", "sensor_msgs/msg/CompressedImage", "ros2msg");
    let json = |name| ("json", name, "jsonschema");
    assert_eq!(
        channels,
        BTreeMap::from([
            ("/cam0/image_raw/compressed", image),
            ("/cam1/image_raw/compressed", image),
            ("/odom", ("cdr", "nav_msgs/msg/Odometry", "ros2msg")),
            ("/truth/camera", json("stereonav.TruthCamera")),
            ("/truth/landmarks", json("stereonav.TruthLandmarks")),
            ("/truth/pose", json("stereonav.TruthPose")),
        ])
    );
    for m in &all {
        let (name, encoding, data) = m.schema.as_ref().unwrap();
        if encoding == "ros2msg" {
            assert_eq!(std::str::from_utf8(data).unwrap(), ros2msg_definition(name));
        }
    }
    let odom_def = ros2msg_definition("nav_msgs/msg/Odometry");
    assert!(odom_def.contains(&format!("{}\nMSG: std_msgs/Header\n", "=".repeat(80))));
    assert!(
        odom_def.contains(
            "MSG: geometry_msgs/TwistWithCovariance\nTwist twist\nfloat64[36] covariance\n"
        )
    );
    // Log order is log-time order.
    assert!(all.windows(2).all(|w| w[0].log_time <= w[1].log_time));
    // One image a camera a frame, stamped with the frame's t_us, PNG of the raw bag's pixels.
    let (_, raw_bytes) = bag(&s, BagImages::Raw);
    let raw = messages(&raw_bytes);
    let regs = s.registers();
    for (side, (topic, raw_topic, frame_id)) in [
        ("/cam0/image_raw/compressed", "/cam0/image_raw", "cam0"),
        ("/cam1/image_raw/compressed", "/cam1/image_raw", "cam1"),
    ]
    .into_iter()
    .enumerate()
    {
        let (png, raw) = (on(&all, topic), on(&raw, raw_topic));
        assert_eq!(png.len(), run.frames.len());
        assert_eq!(raw.len(), run.frames.len());
        for ((p, r), f) in png.iter().zip(&raw).zip(&run.frames) {
            let (t_us, frame, format, data) = read_compressed(&p.data);
            assert_eq!(
                (t_us, frame.as_str(), format.as_str()),
                (f.t_us, frame_id, "png")
            );
            assert_eq!(p.log_time, (f.t_us + sim::bag::IMAGE_DELAY_US) * 1000);
            let decoded =
                image::load_from_memory_with_format(&data, image::ImageFormat::Png).unwrap();
            assert_eq!(decoded.color(), image::ColorType::L8);
            let (rt, rframe, height, width, pixels) = read_image(&r.data);
            assert_eq!((rt, rframe.as_str()), (f.t_us, frame_id));
            assert_eq!((width as usize, height as usize), (regs.width, regs.height));
            assert_eq!(decoded.as_bytes(), pixels.as_slice(), "PNG is lossless");
            // The pixels are those the run's features were detected on.
            let features = if side == 0 { &f.left } else { &f.right };
            let detection = harris_core::detect(&pixels, &regs).unwrap();
            assert_eq!(detection.features, features.board_features());
        }
        assert!(
            png.iter()
                .enumerate()
                .all(|(i, m)| m.sequence as usize == i)
        );
    }
    // The lamps are in the images: every frame has lamp features.
    assert!(
        run.frames
            .iter()
            .all(|f| f.left.features.iter().any(|x| x.lamp.is_some()))
    );
}

#[test]
fn odometry_decodes_by_hand_to_the_run_s_samples() {
    let s = short_radtan();
    let (run, bytes) = bag(&s, BagImages::Jpeg { quality: 90 });
    let all = messages(&bytes);
    let odom = on(&all, "/odom");
    assert_eq!(odom.len(), run.odometry.len());
    let mut pose = rig_model::Pose2::new(0.0, 0.0, 0.0);
    for (i, (m, sample)) in odom.iter().zip(&run.odometry).enumerate() {
        assert_eq!(m.log_time, sample.t_us * 1000);
        let mut r = Cdr::new(&m.data);
        assert_eq!(r.header(), (sample.t_us, "odom".to_string()));
        assert_eq!(r.string(), "base_link");
        let position = [r.f64(), r.f64(), r.f64()];
        let orientation = [r.f64(), r.f64(), r.f64(), r.f64()];
        let pose_covariance: Vec<f64> = (0..36).map(|_| r.f64()).collect();
        let linear = [r.f64(), r.f64(), r.f64()];
        let angular = [r.f64(), r.f64(), r.f64()];
        let twist_covariance: Vec<f64> = (0..36).map(|_| r.f64()).collect();
        r.end();
        assert_eq!(linear, [sample.vx, sample.vy, 0.0]);
        assert_eq!(angular, [0.0, 0.0, sample.vtheta]);
        assert!(
            pose_covariance
                .iter()
                .chain(&twist_covariance)
                .all(|&c| c == 0.0)
        );
        // The pose: the samples before this one integrated from the first.
        assert_eq!(position, [pose.x, pose.y, 0.0], "sample {i}");
        let (sin, cos) = (pose.theta / 2.0).sin_cos();
        assert_eq!(orientation, [0.0, 0.0, sin, cos]);
        if let Some(next) = run.odometry.get(i + 1) {
            let dt = (next.t_us - sample.t_us) as f64 * 1e-6;
            pose = sim::integrate(&pose, sample.vx, sample.vy, sample.vtheta, dt);
        }
    }
    // JPEG: a gray image of the sensor's size, close to the raw pixels.
    let (_, raw_bytes) = bag(&s, BagImages::Raw);
    let raw = messages(&raw_bytes);
    let jpeg = on(&all, "/cam0/image_raw/compressed");
    assert_eq!(jpeg.len(), run.frames.len());
    for (j, r) in jpeg.iter().zip(on(&raw, "/cam0/image_raw")) {
        let (_, _, format, data) = read_compressed(&j.data);
        assert_eq!(format, "jpeg");
        let decoded = image::load_from_memory_with_format(&data, image::ImageFormat::Jpeg)
            .unwrap()
            .to_luma8();
        let (_, _, _, _, pixels) = read_image(&r.data);
        assert_eq!(decoded.len(), pixels.len());
        let mean_error = decoded
            .iter()
            .zip(&pixels)
            .map(|(a, b)| f64::from(a.abs_diff(*b)))
            .sum::<f64>()
            / pixels.len() as f64;
        assert!(mean_error < 2.0, "{mean_error} DN");
    }
    // The truth, as a vehicle log carries it.
    let poses = on(&all, "/truth/pose");
    assert_eq!(poses.len(), run.frames.len());
    for (m, f) in poses.iter().zip(&run.frames) {
        let p: vehicle_log::TruthPose = serde_json::from_slice(&m.data).unwrap();
        assert_eq!(
            (p.t_us, p.x, p.y, p.theta),
            (f.t_us, f.pose.x, f.pose.y, f.pose.theta)
        );
        assert_eq!(m.log_time, f.t_us * 1000);
    }
    let landmarks: serde_json::Value =
        serde_json::from_slice(&on(&all, "/truth/landmarks")[0].data).unwrap();
    assert_eq!(landmarks["landmarks"].as_array().unwrap().len(), 5);
    let camera: vehicle_log::TruthCamera =
        serde_json::from_slice(&on(&all, "/truth/camera")[0].data).unwrap();
    assert_eq!(camera.baseline, run.camera.baseline);
    let topics: BTreeSet<&str> = all.iter().map(|m| m.topic.as_str()).collect();
    assert!(!topics.contains("/fpga/features") && !topics.contains("/rig"));
}

#[test]
fn a_bag_s_run_is_the_rendered_run() {
    // The bag's run is the rendered mode's: the same frames and features, the same stream.
    let s = short_radtan();
    let (run, _) = bag(&s, BagImages::Png);
    let rendered = sim::simulate(&s, sim::Mode::Rendered).unwrap();
    assert_eq!(run, rendered);
    assert!(matches!(
        sim::write_bag_to(
            &s,
            BagImages::Jpeg { quality: 0 },
            Cursor::new(Vec::new()),
            &mut |_, _| {}
        ),
        Err(sim::Error::JpegQuality { quality: 0 })
    ));
}
