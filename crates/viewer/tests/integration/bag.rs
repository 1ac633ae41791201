//! A ROS 2 bag (vehicle-interfaces.md 4.1) written here: `sensor_msgs/msg/Image` `mono8` from
//! two cameras under a ceiling of lamps and `nav_msgs/msg/Odometry`, `ros2msg` schemas as
//! rosbag2 stores them, CDR messages (a small writer below), zstd chunks. The viewer loads it
//! from its topics as `stereonav view BAG --left --right --odom` does, replayed or localised on
//! a map made from it, and draws each frame's camera images under the features:
//!
//! - the images read back are the pixels written, for every frame;
//! - in a screenshot, the pixels of each plane around a lamp's projection are the bright blob
//!   of that camera's image (and dark where the other camera has its blob), and not without the
//!   images;
//! - the memory for images does not grow with the bag: scrubbing every frame of a bag and of
//!   one four times as long leaves the same few frames decoded, and the index holds a fixed
//!   size per frame, no pixels;
//! - a bag cut short (no summary, so no chunk index) is shown with its features, the planes
//!   saying why there is no image, and a warning.

use std::collections::BTreeMap;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use nalgebra::Vector3;
use replay::{NavSettings, Ros2Topics};
use rig_model::{Pose2, Rig};
use viewer::images::CACHE_FRAMES;
use viewer::{Frame, Headless, LoadOptions, MIN_SCREENSHOT_SIZE, Model, Viewer, image_to_screen};

/// The cameras' size, pixels.
const W: u32 = 320;
const H: u32 = 240;
/// Frames a second, and odometry samples a second.
const FRAME_HZ: u64 = 20;
const ODOM_HZ: u64 = 40;
/// The robot drives along x at this speed, m/s.
const SPEED: f64 = 0.4;
/// The bag's first stamp, us (a real clock's).
const T0_US: u64 = 1_700_000_000_000_000;
/// A lamp's image: a disk of this radius (pixels), blurred by a Gaussian of this sigma.
const LAMP_RADIUS_PX: f64 = 2.0;
const BLUR_PX: f64 = 1.0;
/// Screenshots that show a lamp (4 image pixels across) about 15 screen pixels across: room
/// for the image's pixels between the feature's dot and the landmark's ring drawn over it.
const BIG: [u32; 2] = [4096, 2560];
/// The ceiling's and a lamp's gray levels.
const CEILING: f64 = 25.0;
const LAMP: f64 = 245.0;
/// A lamp's glow: its peak over the ceiling and its sigma, pixels.
const GLOW: f64 = 40.0;
const GLOW_PX: f64 = 6.0;
/// The roof's beams across the aisle: height (m), pitch (m), width (m) and light over the
/// ceiling's.
const BEAM_Z_M: f64 = 4.3;
const BEAM_PITCH_M: f64 = 0.8;
const BEAM_WIDTH_M: f64 = 0.1;
const BEAM: f64 = 30.0;

const RIG: &str = "
[camera]
width = 320
height = 240
f = 250.0
cx = 160.0
cy = 120.0
baseline = 0.12

[mount]
x = 0.0
y = 0.0
z = 1.0
roll = 0.0
pitch = 0.0
yaw = 0.0

[estimate]
parameters = [\"baseline\"]

[prior]
baseline = 0.006

[noise]
pixel = 0.3
velocity = 0.005
yaw_rate = 0.01
";

/// The line between a type and each of its dependencies in `ros2msg` text.
fn separator() -> String {
    "=".repeat(80)
}

fn msgdef(fields: &str, deps: &[(&str, &str)]) -> String {
    let mut text = format!("{}\n", fields.trim());
    for (name, body) in deps {
        text.push_str(&format!("{}\nMSG: {name}\n{}\n", separator(), body.trim()));
    }
    text
}

const HEADER: &str = "builtin_interfaces/Time stamp\nstring frame_id";
const TIME: &str = "int32 sec\nuint32 nanosec";

fn image_schema() -> String {
    msgdef(
        "std_msgs/Header header\nuint32 height\nuint32 width\nstring encoding\n\
         uint8 is_bigendian\nuint32 step\nuint8[] data",
        &[
            ("std_msgs/Header", HEADER),
            ("builtin_interfaces/Time", TIME),
        ],
    )
}

fn odometry_schema() -> String {
    msgdef(
        "std_msgs/Header header\nstring child_frame_id\n\
         geometry_msgs/PoseWithCovariance pose\ngeometry_msgs/TwistWithCovariance twist",
        &[
            ("std_msgs/Header", HEADER),
            ("builtin_interfaces/Time", TIME),
            (
                "geometry_msgs/PoseWithCovariance",
                "Pose pose\nfloat64[36] covariance",
            ),
            (
                "geometry_msgs/Pose",
                "Point position\nQuaternion orientation",
            ),
            ("geometry_msgs/Point", "float64 x\nfloat64 y\nfloat64 z"),
            (
                "geometry_msgs/Quaternion",
                "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1",
            ),
            (
                "geometry_msgs/TwistWithCovariance",
                "Twist twist\nfloat64[36] covariance",
            ),
            ("geometry_msgs/Twist", "Vector3  linear\nVector3  angular"),
            ("geometry_msgs/Vector3", "float64 x\nfloat64 y\nfloat64 z"),
        ],
    )
}

/// Little-endian CDR (XCDR1, as ROS 2 writes it): a 4-byte encapsulation header, then each
/// primitive aligned to its size from the end of the header.
struct Cdr(Vec<u8>);

impl Cdr {
    fn new() -> Self {
        Self(vec![0, 1, 0, 0])
    }
    fn align(&mut self, n: usize) {
        while !(self.0.len() - 4).is_multiple_of(n) {
            self.0.push(0);
        }
    }
    fn u32(&mut self, v: u32) {
        self.align(4);
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    fn f64(&mut self, v: f64) {
        self.align(8);
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    fn string(&mut self, s: &str) {
        self.u32(u32::try_from(s.len() + 1).unwrap());
        self.0.extend_from_slice(s.as_bytes());
        self.0.push(0);
    }
    fn header(&mut self, t_us: u64, frame_id: &str) {
        self.u32(u32::try_from(t_us / 1_000_000).unwrap());
        self.u32(u32::try_from((t_us % 1_000_000) * 1000).unwrap());
        self.string(frame_id);
    }
}

fn image_message(t_us: u64, pixels: &[u8]) -> Vec<u8> {
    let mut c = Cdr::new();
    c.header(t_us, "camera");
    c.u32(H);
    c.u32(W);
    c.string("mono8");
    c.0.push(0); // is_bigendian
    c.u32(W); // step
    c.u32(u32::try_from(pixels.len()).unwrap());
    c.0.extend_from_slice(pixels);
    c.0
}

fn odometry_message(t_us: u64, vx: f64) -> Vec<u8> {
    let mut c = Cdr::new();
    c.header(t_us, "odom");
    c.string("base_link");
    for v in [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0] {
        c.f64(v); // pose: position, orientation
    }
    for _ in 0..36 {
        c.f64(0.0);
    }
    for v in [vx, 0.0, 0.0, 0.0, 0.0, 0.0] {
        c.f64(v); // twist: linear, angular
    }
    for _ in 0..36 {
        c.f64(0.0);
    }
    c.0
}

fn topics() -> Ros2Topics {
    Ros2Topics {
        left: "/cam0/image_raw".into(),
        right: "/cam1/image_raw".into(),
        odom: "/wheel/odom".into(),
    }
}

fn rig() -> Rig {
    Rig::from_toml_str(RIG, "bag test rig").unwrap()
}

/// The lamps: two rows along the aisle, 3 m above the rig.
fn lamps() -> Vec<Vector3<f64>> {
    (0..8)
        .flat_map(|i| {
            let x = -1.2 + 0.9 * f64::from(i);
            [
                Vector3::new(x, -0.7 + 0.05 * f64::from(i), 4.0),
                Vector3::new(x + 0.3, 0.6, 4.0),
            ]
        })
        .collect()
}

fn pose_at(frame: u64) -> Pose2 {
    Pose2 {
        x: SPEED * frame as f64 / FRAME_HZ as f64,
        y: 0.0,
        theta: 0.0,
    }
}

/// Where each lamp is in the left and right images at a pose: `[uL, vL, uR, vR]`.
fn projections(rig: &Rig, pose: &Pose2) -> Vec<[f64; 4]> {
    lamps()
        .iter()
        .filter_map(|l| rig_model::project(&rig.nominal, pose, l).ok())
        .map(|m| [m[0], m[1], m[2], m[3]])
        .collect()
}

/// One camera's image: the lamps' blurred disks, each in a faint glow, over a dark ceiling
/// with lighter beams across the aisle (integer coordinates at pixel centres, as the
/// board's). `beam_at(u)` is the beams' light seen through column `u`.
fn render(centres: &[[f64; 2]], beam_at: impl Fn(f64) -> f64) -> Vec<u8> {
    let mut out = vec![0_u8; (W * H) as usize];
    for y in 0..H {
        for x in 0..W {
            let mut light = CEILING + beam_at(f64::from(x));
            for [u, v] in centres {
                let r2 = (f64::from(x) - u).powi(2) + (f64::from(y) - v).powi(2);
                // A disk's edge blurred: the normal CDF across it, approximated by a logistic.
                let edge = 1.0 / (1.0 + (1.702 * (r2.sqrt() - LAMP_RADIUS_PX) / BLUR_PX).exp());
                light += (LAMP - CEILING) * edge + GLOW * (-r2 / (2.0 * GLOW_PX * GLOW_PX)).exp();
            }
            out[(y * W + x) as usize] = light.round().clamp(0.0, 255.0) as u8;
        }
    }
    out
}

/// The beams' light through image column `u` of the camera whose centre is at `centre_x`
/// (world x, metres): beams across the aisle every [`BEAM_PITCH_M`], their edges blurred.
fn beams(rig: &Rig, centre_x: f64, u: f64) -> f64 {
    let depth = BEAM_Z_M - rig.nominal.mount.z;
    let x = centre_x + (u - rig.nominal.cx) * depth / rig.nominal.f;
    let from_beam = (x / BEAM_PITCH_M - (x / BEAM_PITCH_M).round()).abs() * BEAM_PITCH_M;
    let px = (from_beam - BEAM_WIDTH_M / 2.0) * rig.nominal.f / depth;
    BEAM / (1.0 + (1.702 * px / BLUR_PX).exp())
}

/// The two images of a frame.
fn images_at(rig: &Rig, frame: u64) -> [Vec<u8>; 2] {
    let pose = pose_at(frame);
    let p = projections(rig, &pose);
    let half_baseline = rig.nominal.baseline / 2.0;
    [
        render(&p.iter().map(|m| [m[0], m[1]]).collect::<Vec<_>>(), |u| {
            beams(rig, pose.x - half_baseline, u)
        }),
        render(&p.iter().map(|m| [m[2], m[3]]).collect::<Vec<_>>(), |u| {
            beams(rig, pose.x + half_baseline, u)
        }),
    ]
}

/// Writes a bag of `frames` stereo frames and the odometry (as a recorder does: messages in
/// stamp order, log time = stamp), in zstd chunks of a few images each. With `cut`, the file
/// is cut there (a power loss: no summary).
fn write_bag(path: &Path, frames: u64, cut: Option<f64>) {
    let rig = rig();
    let file = std::fs::File::create(path).unwrap();
    let mut w = mcap::WriteOptions::new()
        .profile("ros2")
        .chunk_size(Some(200 << 10))
        .create(BufWriter::new(file))
        .unwrap();
    let image = w
        .add_schema(
            "sensor_msgs/msg/Image",
            "ros2msg",
            image_schema().as_bytes(),
        )
        .unwrap();
    let odometry = w
        .add_schema(
            "nav_msgs/msg/Odometry",
            "ros2msg",
            odometry_schema().as_bytes(),
        )
        .unwrap();
    let none = BTreeMap::new();
    let t = topics();
    let left = w.add_channel(image, &t.left, "cdr", &none).unwrap();
    let right = w.add_channel(image, &t.right, "cdr", &none).unwrap();
    let odom = w.add_channel(odometry, &t.odom, "cdr", &none).unwrap();
    let mut sequence = 0;
    let mut put = |w: &mut mcap::Writer<_>, channel_id: u16, t_us: u64, data: &[u8]| {
        sequence += 1;
        let header = mcap::records::MessageHeader {
            channel_id,
            sequence,
            log_time: t_us * 1000,
            publish_time: t_us * 1000,
        };
        w.write_to_known_channel(&header, data).unwrap();
    };
    let odom_step = 1_000_000 / ODOM_HZ;
    let frame_step = 1_000_000 / FRAME_HZ;
    let end_us = frames * frame_step;
    let mut next_odom = 0;
    for k in 0..frames {
        let t = k * frame_step;
        while next_odom <= t + frame_step / 2 && next_odom <= end_us {
            let m = odometry_message(T0_US + next_odom, SPEED);
            put(&mut w, odom, T0_US + next_odom, &m);
            next_odom += odom_step;
        }
        let [l, r] = images_at(&rig, k);
        put(&mut w, left, T0_US + t, &image_message(T0_US + t, &l));
        // The right camera's stamp a little later, as two free-running cameras': paired
        // within a quarter of the frame interval.
        put(
            &mut w,
            right,
            T0_US + t + 700,
            &image_message(T0_US + t + 700, &r),
        );
    }
    w.finish().unwrap();
    drop(w);
    if let Some(fraction) = cut {
        let bytes = std::fs::read(path).unwrap();
        std::fs::write(path, &bytes[..(bytes.len() as f64 * fraction) as usize]).unwrap();
    }
}

fn scratch(name: &str) -> PathBuf {
    crate::scratch("bag", name)
}

fn options() -> LoadOptions {
    LoadOptions {
        rig: Some(rig()),
        settings: NavSettings {
            skip_phase1: true,
            ..NavSettings::default()
        },
        map: None,
        topics: Some(topics()),
    }
}

fn load_bag(path: &Path, options: &LoadOptions) -> Model {
    viewer::load(path, options, &mut |_, _| {}).unwrap()
}

fn pixel(frame: &Frame, x: f32, y: f32) -> [u8; 3] {
    let (x, y) = (x.floor() as u32, y.floor() as u32);
    let i = ((y * frame.width + x) * 4) as usize;
    [frame.rgba[i], frame.rgba[i + 1], frame.rgba[i + 2]]
}

/// Whether the screenshot is bright and grey (a lamp's image under the tint) on most of a
/// circle of `radius` screen pixels around `at`: inside the lamp's disk, between the
/// feature's dot and the landmark's ring drawn over it.
fn bright_around(frame: &Frame, at: egui::Pos2, radius: f32) -> bool {
    let bright = (0..8)
        .filter(|k| {
            let a = std::f32::consts::TAU * *k as f32 / 8.0;
            let [r, g, b] = pixel(frame, at.x + radius * a.cos(), at.y + radius * a.sin());
            let (max, min) = (r.max(g).max(b), r.min(g).min(b));
            min > 120 && max - min < 12
        })
        .count();
    bright >= 6
}

/// Whether the screenshot is dark at `at` (the ceiling's image, or no image at all).
fn dark_at(frame: &Frame, at: egui::Pos2) -> bool {
    pixel(frame, at.x, at.y).iter().all(|&c| c < 60)
}

#[test]
fn a_bags_images_are_drawn_under_its_features_at_every_frame() {
    let rig = rig();
    let path = scratch("hall.mcap");
    let frames = 60;
    write_bag(&path, frames, None);
    let model = load_bag(&path, &options());
    assert!(model.warnings.is_empty(), "{:?}", model.warnings);
    let images = model.images.clone().expect("a bag's images");
    assert!(images.unavailable().is_none());
    assert_eq!(images.frames().len(), frames as usize);
    assert_eq!(model.replay.frames.len(), frames as usize);
    // Every frame's images read back are the pixels written, and its features are the
    // board's detector's on them (a lamp at least in each image).
    for (k, f) in images.frames().iter().enumerate() {
        assert_eq!(f.t_us, T0_US + k as u64 * 50_000);
        let read = images.read(f.t_us).unwrap();
        let [l, r] = images_at(&rig, k as u64);
        assert!(read.left.as_ref() == Ok(&l), "frame {k}: left");
        assert!(read.right.as_ref() == Ok(&r), "frame {k}: right");
        let (fl, fr) = model.features.at(f.t_us).unwrap();
        assert!(!fl.is_empty() && !fr.is_empty(), "frame {k}");
    }
    // The navigator mapped the lamps from these features.
    assert!(!model.replay.landmarks.is_empty());

    // A screenshot 1.5 s in: each lamp's blob in its camera's plane, dark at the other
    // camera's position of it; without the images, no blob.
    let k = 30;
    let t_s = model.seconds(T0_US + k * 50_000);
    let mut bare = model.clone();
    bare.images = None;
    let shot = viewer::screenshot(model, Some(t_s), BIG).unwrap();
    let without = viewer::screenshot(bare, Some(t_s), BIG).unwrap();
    let out = scratch("bag-screenshot.png");
    viewer::write_png(&out, &shot.frame).unwrap();
    let size = [f64::from(W), f64::from(H)];
    let regions = shot.regions;
    let scale = regions.left_image.width() / W as f32;
    assert!(scale > 3.0, "{regions:?}");
    let inside = |m: &[f64; 4]| {
        let margin = LAMP_RADIUS_PX + 12.0;
        [m[0], m[2]]
            .iter()
            .all(|u| *u > margin && *u < size[0] - margin)
            && m[1] > margin
            && m[1] < size[1] - margin
    };
    let seen: Vec<[f64; 4]> = projections(&rig, &pose_at(k))
        .into_iter()
        .filter(inside)
        .collect();
    assert!(seen.len() >= 3, "{seen:?}");
    // Between the dot (2.5 px) and the ring (6 px), inside the lamp's disk.
    let radius = 4.0;
    for m in &seen {
        let left = image_to_screen(regions.left_image, size, m[0], m[1]);
        let right = image_to_screen(regions.right_image, size, m[2], m[3]);
        assert!(bright_around(&shot.frame, left, radius), "left {m:?}");
        assert!(bright_around(&shot.frame, right, radius), "right {m:?}");
        assert!(!bright_around(&without.frame, left, radius), "{m:?}");
        // The right image's blob is the disparity away from the left's.
        let left_in_right = image_to_screen(regions.right_image, size, m[0], m[1]);
        assert!(dark_at(&shot.frame, left_in_right), "{m:?}");
    }
    // The ceiling between the lamps is the image's dark gray, not the empty plane's.
    let between = image_to_screen(regions.left_image, size, 160.0, 5.0);
    assert!(dark_at(&shot.frame, between));
    assert_ne!(
        pixel(&shot.frame, between.x, between.y),
        pixel(&without.frame, between.x, between.y)
    );
}

#[test]
fn memory_for_images_does_not_grow_with_the_bag() {
    let mut sizes = Vec::new();
    for frames in [20, 80] {
        let path = scratch(&format!("long-{frames}.mcap"));
        write_bag(&path, frames, None);
        let model = load_bag(&path, &options());
        let images = model.images.clone().unwrap();
        assert_eq!(images.frames().len(), frames as usize);
        // The index: a fixed size per frame, no pixels.
        let per_frame = images.index_bytes() as f64 / frames as f64;
        assert!(per_frame <= 64.0, "{per_frame} bytes a frame");
        // Every frame shown in turn, forth and back.
        let times: Vec<f64> = model
            .replay
            .frames
            .iter()
            .map(|f| model.seconds(f.t_us))
            .collect();
        let mut headless = Headless::new(Viewer::new(model), MIN_SCREENSHOT_SIZE);
        for t in times.iter().chain(times.iter().rev()) {
            headless.viewer_mut().set_time(*t);
            headless.run_frame();
        }
        let cache = headless.viewer().image_cache().unwrap();
        assert_eq!(cache.len(), CACHE_FRAMES);
        assert_eq!(cache.pixel_bytes(), CACHE_FRAMES * 2 * (W * H) as usize);
        sizes.push((cache.len(), cache.pixel_bytes()));
    }
    assert_eq!(
        sizes[0], sizes[1],
        "the same few frames, four times the bag"
    );
}

#[test]
fn a_bag_localised_on_its_map_shows_its_images() {
    let rig = rig();
    let path = scratch("localise.mcap");
    write_bag(&path, 40, None);
    let settings = options().settings;
    let replayer =
        replay::Replayer::open_with_topics(&path, Some(&topics()), Some(rig.clone()), &settings)
            .unwrap();
    let end = replayer
        .run(&mut replay::ReplayCollector::default(), &mut |_, _| {})
        .unwrap();
    let map_path = scratch("localise.map");
    replay::saved_map(&end, &rig, &path)
        .save(&map_path)
        .unwrap();
    let options = LoadOptions {
        map: Some(map_path),
        ..options()
    };
    let model = load_bag(&path, &options);
    assert!(model.localization.is_some());
    let images = model.images.clone().unwrap();
    assert_eq!(images.frames().len(), 40);
    let t_s = model.seconds(T0_US + 20 * 50_000);
    let shot = viewer::screenshot(model, Some(t_s), BIG).unwrap();
    let size = [f64::from(W), f64::from(H)];
    let lit = projections(&rig, &pose_at(20))
        .iter()
        .filter(|m| m[0] > 20.0 && m[0] < 300.0 && m[1] > 20.0 && m[1] < 220.0)
        .filter(|m| {
            let at = image_to_screen(shot.regions.left_image, size, m[0], m[1]);
            bright_around(&shot.frame, at, 4.0)
        })
        .count();
    assert!(lit >= 3, "{lit}");
}

#[test]
fn a_bag_cut_short_is_shown_without_its_images_and_says_why() {
    let path = scratch("cut.mcap");
    write_bag(&path, 40, Some(0.7));
    let model = load_bag(&path, &options());
    let images = model.images.clone().unwrap();
    let why = images.unavailable().expect("no chunk index");
    assert!(why.contains("no summary section"), "{why}");
    assert!(
        model
            .warnings
            .iter()
            .any(|w| w.contains("camera images cannot be shown")),
        "{:?}",
        model.warnings
    );
    // Its features are there all the same.
    assert!(!model.features.frames.is_empty());
    assert!(images.read(images.frames()[0].t_us).is_err());
    let last = model.replay.frames.last().unwrap().t_us;
    let shot = viewer::screenshot(model, None, MIN_SCREENSHOT_SIZE).unwrap();
    let plane = shot.regions.left_image;
    // No lamp's image where the lamps are ...
    let size = [f64::from(W), f64::from(H)];
    let rig = rig();
    for m in projections(&rig, &pose_at((last - T0_US) / 50_000)) {
        if m[0] > 20.0 && m[0] < 300.0 && m[1] > 20.0 && m[1] < 220.0 {
            let at = image_to_screen(plane, size, m[0], m[1]);
            assert!(!bright_around(&shot.frame, at, 4.0), "{m:?}");
        }
    }
    // ... and the plane's text at its top, light grey on the dark plane.
    let text = (plane.top() as u32..plane.top() as u32 + 40)
        .flat_map(|y| (plane.left() as u32..plane.right() as u32).map(move |x| (x, y)))
        .filter(|&(x, y)| {
            let [r, g, b] = pixel(&shot.frame, x as f32, y as f32);
            r > 100 && r == g && g == b
        })
        .count();
    assert!(text > 100, "{text}");
}
