//! Scenario files (`fixtures/scenarios/*.toml`): the world, the path, the rates, the noise, the
//! true camera parameters `C`, the seed, the board's registers, clutter, link faults, and the
//! nominal rig file a user of the vehicle would have.
//!
//! Read with serde (`deny_unknown_fields` everywhere), then checked for impossible values.
//! Every error names the file, the key as a dotted path and the problem, on one line.
//!
//! Units are in the key names where they are not obvious (`_m`, `_deg`, `_us`, `_px`, `_dn`
//! for the sensor's digital numbers, 0..=255).

use std::path::{Path, PathBuf};

use harris_core::Registers;
use rig_model::{CameraParams, Mount, Rig};
use serde::Deserialize;

use crate::error::{Error, Result};

/// A whole scenario as read from its file, with the nominal rig it names.
#[derive(Debug, Clone, PartialEq)]
pub struct Scenario {
    /// What the file says.
    pub spec: ScenarioSpec,
    /// The nominal rig file named by `rig`, parsed.
    pub rig: Rig,
    /// The nominal rig file's text, as written by the user.
    pub rig_text: String,
    /// Where the nominal rig file is.
    pub rig_path: PathBuf,
    /// The scenario file's name, for messages.
    pub source_name: String,
}

/// The scenario file's tables.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScenarioSpec {
    /// One line saying what the scenario is for.
    #[serde(default)]
    pub description: String,
    /// Seed of every random draw of the run: the same seed gives the same bytes.
    pub seed: u64,
    /// The nominal rig file a user would have, relative to the scenario file.
    pub rig: String,
    /// The true camera parameters `C` (the nominal rig may differ).
    pub camera: TrueCamera,
    /// The board's detector registers.
    #[serde(default)]
    pub board: Board,
    /// Odometry and camera rates and the clock.
    #[serde(default)]
    pub rates: Rates,
    /// Sensor noise.
    pub noise: NoiseSpec,
    /// The lamps.
    pub world: World,
    /// The robot's path.
    pub path: PathSpec,
    /// Features that are not lamps.
    #[serde(default)]
    pub clutter: Clutter,
    /// The link from the board to the vehicle computer: latency and faults.
    #[serde(default)]
    pub link: Link,
    /// The rendered mode's optics, sensor and background.
    #[serde(default)]
    pub render: Render,
    /// What goes into the vehicle log besides the input channels.
    #[serde(default)]
    pub log: LogSpec,
}

/// The true camera parameters (vehicle-interfaces.md section 1) and the image size.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrueCamera {
    /// Image width, pixels (the board's `WIDTH`).
    pub width: usize,
    /// Image height, pixels (the board's `HEIGHT`).
    pub height: usize,
    /// Focal length, pixels.
    pub f_px: f64,
    /// Principal point column, pixels.
    pub cx_px: f64,
    /// Principal point row, pixels.
    pub cy_px: f64,
    /// Camera separation, metres.
    pub baseline_m: f64,
    /// The rig in the robot frame.
    pub mount: MountSpec,
}

/// The rig's pose in the robot frame; angles in degrees.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MountSpec {
    /// Forward, metres.
    pub x_m: f64,
    /// Left, metres.
    pub y_m: f64,
    /// Up, metres.
    pub z_m: f64,
    /// About x, degrees.
    pub roll_deg: f64,
    /// About y, degrees; positive tilts the optical axis toward the robot's front.
    pub pitch_deg: f64,
    /// About z, degrees.
    pub yaw_deg: f64,
}

/// The board's registers (board-icd.md section 1); the image size comes from `[camera]`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Board {
    /// `THRESHOLD`.
    pub threshold: i32,
    /// `MAX_FEATURES`, `1..=1023`.
    pub max_features: usize,
}

impl Default for Board {
    fn default() -> Self {
        Self {
            threshold: harris_core::DEFAULT_THRESHOLD,
            max_features: harris_core::DEFAULT_MAX_FEATURES,
        }
    }
}

/// Rates and the clock.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Rates {
    /// Odometry samples per second (at least the camera rate).
    pub odometry_hz: f64,
    /// Stereo frames per second.
    pub camera_hz: f64,
    /// Time of the first odometry sample on the vehicle's clock, microseconds.
    pub start_t_us: u64,
    /// Mid-exposure time of the first stereo frame after the first odometry sample, microseconds.
    pub camera_phase_us: u64,
    /// Frame counter of the first packet.
    pub first_frame: u32,
    /// The board's clock against the odometry's, seconds: a frame exposed at odometry-clock
    /// time `T` is stamped `T + board_clock_offset_s` (the vehicle's `time_offset`,
    /// vehicle-interfaces.md 1.2).
    pub board_clock_offset_s: f64,
}

impl Default for Rates {
    fn default() -> Self {
        Self {
            odometry_hz: 100.0,
            camera_hz: 20.0,
            start_t_us: 1_000_000,
            camera_phase_us: 0,
            first_frame: 0,
            board_clock_offset_s: 0.0,
        }
    }
}

/// Sensor noise, 1 sigma; zero turns a source off.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NoiseSpec {
    /// Pixel noise of each of `uL, vL, uR, vR` in fast mode, pixels.
    pub pixel_px: f64,
    /// Odometry white noise per sample on each of `vx, vy`, m/s.
    pub velocity_mps: f64,
    /// Odometry white noise per sample on `vtheta`, rad/s.
    pub yaw_rate_radps: f64,
    /// Odometry scale error: measured `vx, vy` are `(1 + e)` times the truth.
    #[serde(default)]
    pub velocity_scale_error: f64,
    /// Constant bias of the measured yaw rate, rad/s.
    #[serde(default)]
    pub yaw_rate_bias_radps: f64,
    /// Yaw rate scale error: measured `vtheta` is `(1 + e)` times the truth (plus the bias).
    #[serde(default)]
    pub yaw_rate_scale_error: f64,
    /// Time constant of the errors on `vx, vy`, seconds: a first-order Gauss-Markov process of
    /// stationary sigma [`Self::velocity_mps`] (vehicle-interfaces.md section 2, as real
    /// wheels slip for a while); 0 (the default): white.
    #[serde(default)]
    pub velocity_tau_s: f64,
    /// Time constant of the errors on `vtheta`, seconds, likewise.
    #[serde(default)]
    pub yaw_rate_tau_s: f64,
    /// Spread of the lamps' Harris responses in fast mode (sigma of the natural logarithm).
    #[serde(default = "default_response_spread")]
    pub response_log_sigma: f64,
}

fn default_response_spread() -> f64 {
    0.4
}

/// The lamps: an explicit list, grids with jitter, panels, and lamps added for this drive.
/// Ids count from 0 in this order: the list, then each grid row by row, then each panel's
/// points (four corners, or a tube's two ends), then `added`. `dark` turns lamps off without
/// renumbering the others, and `seed` fixes the grids' jitter apart from the run's noise, so
/// that scenarios with other noise seeds, dark lamps and added lamps can share one hall.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct World {
    /// Physical radius of a lamp that does not give its own, metres.
    #[serde(default = "default_lamp_radius")]
    pub lamp_radius_m: f64,
    /// Brightness of a lamp that does not give its own: the sensor value of a pixel wholly
    /// covered by the lamp, DN (above 255 saturates).
    #[serde(default = "default_lamp_radiance")]
    pub lamp_radiance_dn: f64,
    /// Median Harris response of a lamp in fast mode.
    #[serde(default = "default_lamp_response")]
    pub lamp_response: f64,
    /// Lamps one by one.
    #[serde(default)]
    pub lamps: Vec<LampSpec>,
    /// Regular grids of lamps.
    #[serde(default)]
    pub grids: Vec<GridSpec>,
    /// Lamps that are not points: rectangular panels and tubes, flat on the ceiling.
    #[serde(default)]
    pub panels: Vec<PanelSpec>,
    /// Lamps fitted since the hall was mapped (`added = [{ x_m = 3.75, y_m = 2.5, z_m = 7.0 }]`,
    /// the keys of `lamps`): appended after every other lamp, so their ids follow the last
    /// id of the hall and the hall's lamps keep theirs.
    #[serde(default)]
    pub added: Vec<LampSpec>,
    /// Ids of lamps that are there but off in this drive (`dark = [3, 17]`): never seen by
    /// the cameras, never drawn in rendered images, absent from the truth's landmarks; the
    /// other lamps keep their ids. A panel goes dark whole: list all its points.
    #[serde(default)]
    pub dark: Vec<u32>,
    /// Seed of the grids' jitter only (default: the scenario's `seed`): scenarios with the
    /// same grids and `world.seed` have their lamps in the same places, whatever their own
    /// seeds.
    #[serde(default)]
    pub seed: Option<u64>,
}

impl PanelSpec {
    /// How many landmarks the panel is: a tube's two ends or a panel's four corners (as
    /// [`crate::world::Panel::is_tube`] decides).
    pub fn point_count(&self) -> usize {
        // 7 (w / 2) < l / 2 exactly when 7 w < l: halving is exact.
        if 7.0 * self.width_m < self.length_m {
            2
        } else {
            4
        }
    }
}

/// A rectangular lamp flat on the ceiling (a panel, or a tube when it is narrow): rendered as
/// it is, and seen by the detector at its corners. Its landmarks (and truth) are its four
/// corners, or a tube's two ends (the middle of each end) when it is less than a seventh as
/// wide as it is long.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PanelSpec {
    /// Centre, metres.
    pub x_m: f64,
    /// Centre, metres.
    pub y_m: f64,
    /// Height above the floor, metres.
    pub z_m: f64,
    /// Along its axis, metres.
    pub length_m: f64,
    /// Across, metres.
    pub width_m: f64,
    /// Its axis from the world's x axis, degrees.
    #[serde(default)]
    pub yaw_deg: f64,
    /// Brightness, DN (default `world.lamp_radiance_dn`).
    pub radiance_dn: Option<f64>,
}

fn default_lamp_radius() -> f64 {
    0.003
}
fn default_lamp_radiance() -> f64 {
    400.0
}
fn default_lamp_response() -> f64 {
    5.0e7
}

/// One lamp in the world frame.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LampSpec {
    /// Metres.
    pub x_m: f64,
    /// Metres.
    pub y_m: f64,
    /// Height above the floor, metres.
    pub z_m: f64,
    /// Physical radius, metres (default `world.lamp_radius_m`).
    pub radius_m: Option<f64>,
    /// Brightness, DN (default `world.lamp_radiance_dn`).
    pub radiance_dn: Option<f64>,
}

/// A grid of `nx x ny` lamps from `(x0_m, y0_m)` with spacings `dx_m, dy_m`, each moved by
/// uniform jitter.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GridSpec {
    /// First lamp, metres.
    pub x0_m: f64,
    /// First lamp, metres.
    pub y0_m: f64,
    /// Height above the floor, metres.
    pub z_m: f64,
    /// Lamps along x.
    pub nx: usize,
    /// Lamps along y.
    pub ny: usize,
    /// Spacing along x, metres.
    pub dx_m: f64,
    /// Spacing along y, metres.
    pub dy_m: f64,
    /// Each lamp moves by up to this much along x and y, metres.
    #[serde(default)]
    pub jitter_xy_m: f64,
    /// Each lamp moves by up to this much along z, metres.
    #[serde(default)]
    pub jitter_z_m: f64,
    /// Physical radius, metres (default `world.lamp_radius_m`).
    pub radius_m: Option<f64>,
    /// Brightness, DN (default `world.lamp_radiance_dn`).
    pub radiance_dn: Option<f64>,
}

/// The path: segments driven one after the other, each from rest to rest, `repeat` times.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PathSpec {
    /// Speed limit, m/s.
    pub max_speed_mps: f64,
    /// Acceleration limit (speeding up and braking), m/s^2.
    pub max_accel_mps2: f64,
    /// Yaw-rate limit, degrees/s.
    pub max_yaw_rate_degps: f64,
    /// Yaw acceleration limit, degrees/s^2.
    pub max_yaw_accel_degps2: f64,
    /// Lateral acceleration limit on arcs, m/s^2.
    #[serde(default = "default_lateral_accel")]
    pub max_lateral_accel_mps2: f64,
    /// How many times the segments are driven.
    #[serde(default = "default_repeat")]
    pub repeat: usize,
    /// The robot's pose at the first stereo frame, in the world frame
    /// (`start = { x_m = 12.0, y_m = 6.0, yaw_deg = 120.0 }`; default: all zero). The lamps
    /// and every truth pose (`/truth/pose`, the truth file) are in the world frame. With the
    /// default the world frame is the robot's frame at the first frame, as in the method
    /// (vehicle-interfaces.md section 1); with a start pose it is the hall's frame, the
    /// frame the lamps are given in, in which a vehicle that starts anywhere in a mapped hall
    /// can be judged. Replay compares its trajectory with the truth without aligning the two,
    /// so judge a run that starts away from zero with a localiser, not replay.
    #[serde(default)]
    pub start: PoseSpec,
    /// The segments.
    pub segments: Vec<Segment>,
}

/// A planar pose in the world frame.
#[derive(Debug, Clone, Copy, PartialEq, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PoseSpec {
    /// Metres.
    pub x_m: f64,
    /// Metres.
    pub y_m: f64,
    /// Heading from the world's x axis, degrees (counter-clockwise).
    pub yaw_deg: f64,
}

impl PoseSpec {
    /// As the rig model's pose (theta in radians, not wrapped).
    pub fn pose(&self) -> rig_model::Pose2 {
        rig_model::Pose2::new(self.x_m, self.y_m, self.yaw_deg.to_radians())
    }
}

fn default_lateral_accel() -> f64 {
    1.0
}
fn default_repeat() -> usize {
    1
}

/// What a path segment does.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SegmentKind {
    /// Straight ahead (`length_m`, negative: backwards; optional `speed_mps`).
    Straight,
    /// Turn in place (`angle_deg`, positive: counter-clockwise, to the left; optional
    /// `yaw_rate_degps`).
    Turn,
    /// Drive along a circular arc (`radius_m`, `angle_deg`, positive: to the left; optional
    /// `speed_mps`).
    Arc,
    /// Stand still (`duration_s`).
    Wait,
    /// Carried while the camera is blind (pushed, towed, lifted): over `duration_s` the
    /// vehicle goes to the absolute world pose `x_m, y_m, yaw_deg`, and the board sends no
    /// packets; its frame counter jumps over the frames it did not send, as a board that ran
    /// on while the vehicle computer was off or the camera covered (a receiver counts them
    /// lost). `odometry` says what the odometry sends meanwhile (default `"none"`). The path
    /// goes on from the new pose.
    Moved,
}

/// What the odometry sends while the vehicle is carried (a `"moved"` segment).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum MovedOdometry {
    /// Nothing: the vehicle computer was off (a gap in `/odom`; the sample before the gap
    /// is the vehicle at rest before it was switched off).
    #[default]
    None,
    /// Samples at the odometry rate reporting rest (the wheels did not turn): the truth is
    /// zero velocities, measured like any sample at rest (white noise and yaw-rate bias).
    Zero,
}

impl MovedOdometry {
    /// The name in scenario files.
    pub fn name(self) -> &'static str {
        match self {
            Self::None => "none",
            Self::Zero => "zero",
        }
    }
}

impl SegmentKind {
    /// The name in scenario files.
    pub fn name(self) -> &'static str {
        match self {
            Self::Straight => "straight",
            Self::Turn => "turn",
            Self::Arc => "arc",
            Self::Wait => "wait",
            Self::Moved => "moved",
        }
    }

    /// The keys a segment of this kind needs, and the ones it may have.
    fn keys(self) -> (&'static [&'static str], &'static [&'static str]) {
        match self {
            Self::Straight => (&["length_m"], &["speed_mps"]),
            Self::Turn => (&["angle_deg"], &["yaw_rate_degps"]),
            Self::Arc => (&["radius_m", "angle_deg"], &["speed_mps"]),
            Self::Wait => (&["duration_s"], &[]),
            Self::Moved => (&["duration_s", "x_m", "y_m", "yaw_deg"], &["odometry"]),
        }
    }
}

/// One piece of the path: `{ kind = "straight", length_m = 2.0 }`,
/// `{ kind = "turn", angle_deg = 90.0 }`, `{ kind = "arc", radius_m = 3.0, angle_deg = 180.0 }`,
/// `{ kind = "wait", duration_s = 1.0 }`,
/// `{ kind = "moved", duration_s = 8.0, x_m = 4.0, y_m = 9.0, yaw_deg = -30.0, odometry = "none" }`;
/// each from rest to rest.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Segment {
    /// What the segment does; it says which of the other keys are needed.
    pub kind: SegmentKind,
    /// Straight: metres (negative: backwards).
    pub length_m: Option<f64>,
    /// Turn and arc: degrees (positive: to the left).
    pub angle_deg: Option<f64>,
    /// Arc: metres.
    pub radius_m: Option<f64>,
    /// Wait and moved: seconds.
    pub duration_s: Option<f64>,
    /// Straight and arc: speed limit of this segment, m/s (at most the path's).
    pub speed_mps: Option<f64>,
    /// Turn: yaw-rate limit of this segment, degrees/s (at most the path's).
    pub yaw_rate_degps: Option<f64>,
    /// Moved: where to, world frame, metres.
    pub x_m: Option<f64>,
    /// Moved: where to, world frame, metres.
    pub y_m: Option<f64>,
    /// Moved: the heading it is left at, world frame, degrees.
    pub yaw_deg: Option<f64>,
    /// Moved: what the odometry sends meanwhile (default `"none"`).
    pub odometry: Option<MovedOdometry>,
}

impl Segment {
    fn empty(kind: SegmentKind) -> Self {
        Self {
            kind,
            length_m: None,
            angle_deg: None,
            radius_m: None,
            duration_s: None,
            speed_mps: None,
            yaw_rate_degps: None,
            x_m: None,
            y_m: None,
            yaw_deg: None,
            odometry: None,
        }
    }

    /// Straight ahead for `length_m` (negative: backwards).
    pub fn straight(length_m: f64) -> Self {
        Self {
            length_m: Some(length_m),
            ..Self::empty(SegmentKind::Straight)
        }
    }

    /// Turn in place by `angle_deg` (positive: to the left).
    pub fn turn(angle_deg: f64) -> Self {
        Self {
            angle_deg: Some(angle_deg),
            ..Self::empty(SegmentKind::Turn)
        }
    }

    /// An arc of `radius_m` through `angle_deg` (positive: to the left).
    pub fn arc(radius_m: f64, angle_deg: f64) -> Self {
        Self {
            radius_m: Some(radius_m),
            angle_deg: Some(angle_deg),
            ..Self::empty(SegmentKind::Arc)
        }
    }

    /// Stand still for `duration_s`.
    pub fn wait(duration_s: f64) -> Self {
        Self {
            duration_s: Some(duration_s),
            ..Self::empty(SegmentKind::Wait)
        }
    }

    /// Carried over `duration_s` to the world pose `(x_m, y_m, yaw_deg)` while the camera is
    /// blind, the odometry sending what `odometry` says.
    pub fn moved(
        duration_s: f64,
        x_m: f64,
        y_m: f64,
        yaw_deg: f64,
        odometry: MovedOdometry,
    ) -> Self {
        Self {
            duration_s: Some(duration_s),
            x_m: Some(x_m),
            y_m: Some(y_m),
            yaw_deg: Some(yaw_deg),
            odometry: Some(odometry),
            ..Self::empty(SegmentKind::Moved)
        }
    }

    /// Which keys the segment has.
    fn given(&self) -> [(&'static str, bool); 10] {
        [
            ("length_m", self.length_m.is_some()),
            ("angle_deg", self.angle_deg.is_some()),
            ("radius_m", self.radius_m.is_some()),
            ("duration_s", self.duration_s.is_some()),
            ("speed_mps", self.speed_mps.is_some()),
            ("yaw_rate_degps", self.yaw_rate_degps.is_some()),
            ("x_m", self.x_m.is_some()),
            ("y_m", self.y_m.is_some()),
            ("yaw_deg", self.yaw_deg.is_some()),
            ("odometry", self.odometry.is_some()),
        ]
    }
}

/// Features that are not lamps (fast mode; in rendered mode the background makes its own).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Clutter {
    /// Mean number of spurious features per image, independent in left and right (Poisson).
    pub per_image: f64,
    /// Mean number of spurious stereo pairs per frame: the same row in both images, a random
    /// disparity (reflections, sprinkler heads), not the same from frame to frame.
    pub stereo_per_frame: f64,
}

impl Default for Clutter {
    fn default() -> Self {
        Self {
            per_image: 0.0,
            stereo_per_frame: 0.0,
        }
    }
}

/// How the chunks of the byte stream are cut.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Chunking {
    /// One chunk per packet (a UDP datagram per frame).
    Packet,
    /// Chunks of random length across packet boundaries (serial or USB reads).
    Random,
}

/// The link: when the board's bytes arrive and what goes wrong.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Link {
    /// From mid-exposure to the first byte of the frame's packet on the link (half the
    /// exposure, read-out, the detector's pipeline), microseconds.
    pub ready_latency_us: u64,
    /// Link speed, bytes per second.
    pub rate_bytes_per_s: f64,
    /// From a chunk's last byte on the link to its log time, microseconds.
    pub host_latency_us: u64,
    /// Uniform random extra host latency, `0..=jitter`, microseconds.
    pub host_jitter_us: u64,
    /// Probability that a packet is lost whole.
    pub loss_probability: f64,
    /// Probability that one bit of a packet is flipped.
    pub bit_flip_probability: f64,
    /// How the stream is cut into chunks.
    pub chunking: Chunking,
    /// Shortest random chunk, bytes.
    pub chunk_min_bytes: usize,
    /// Longest random chunk, bytes.
    pub chunk_max_bytes: usize,
}

impl Default for Link {
    fn default() -> Self {
        Self {
            ready_latency_us: 15_000,
            rate_bytes_per_s: 1.0e6,
            host_latency_us: 500,
            host_jitter_us: 500,
            loss_probability: 0.0,
            bit_flip_probability: 0.0,
            chunking: Chunking::Packet,
            chunk_min_bytes: 1,
            chunk_max_bytes: 512,
        }
    }
}

/// Which roof beams the background has.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Beams {
    /// A plain roof.
    None,
    /// Beams running along world x.
    X,
    /// Beams running along world y.
    Y,
    /// Both: a grid.
    Both,
}

/// The rendered mode: optics, sensor and background.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Render {
    /// Gaussian blur of the optics, 1 sigma, pixels.
    pub optics_blur_px: f64,
    /// Read noise, 1 sigma, DN.
    pub read_noise_dn: f64,
    /// Photo-electrons per DN for shot noise; 0 turns shot noise off.
    pub electrons_per_dn: f64,
    /// Height of the roof plane above the floor, metres.
    pub roof_z_m: f64,
    /// Roof brightness, DN.
    pub roof_dn: f64,
    /// Roof beams.
    pub beams: Beams,
    /// Distance between beams, metres.
    pub beam_spacing_m: f64,
    /// Width of a beam, metres.
    pub beam_width_m: f64,
    /// Beam brightness, DN.
    pub beam_dn: f64,
    /// A bright reflection along the middle of each beam (a lamp mirrored in a metal beam),
    /// DN; 0: none.
    pub beam_highlight_dn: f64,
    /// Width of the reflection, metres.
    pub beam_highlight_width_m: f64,
}

impl Default for Render {
    fn default() -> Self {
        Self {
            optics_blur_px: 0.8,
            read_noise_dn: 1.5,
            electrons_per_dn: 20.0,
            roof_z_m: 6.0,
            roof_dn: 40.0,
            beams: Beams::Both,
            beam_spacing_m: 3.0,
            beam_width_m: 0.3,
            beam_dn: 70.0,
            beam_highlight_dn: 0.0,
            beam_highlight_width_m: 0.02,
        }
    }
}

/// What the vehicle log holds besides `/fpga/features` and `/odom`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LogSpec {
    /// Write the nominal rig as `/rig`.
    pub rig: bool,
    /// Write the ground truth on `/truth/...`.
    pub truth: bool,
}

impl Default for LogSpec {
    fn default() -> Self {
        Self {
            rig: true,
            truth: true,
        }
    }
}

impl Scenario {
    /// Reads a scenario file and the nominal rig file it names (relative to its folder).
    pub fn load(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::Read {
            path: path.to_path_buf(),
            reason: e.to_string(),
        })?;
        let base = path.parent().unwrap_or_else(|| Path::new(""));
        Self::from_toml_str(&text, &path.display().to_string(), base)
    }

    /// Parses a scenario's TOML text; `source_name` names it in errors and the rig file is
    /// looked for relative to `base_dir`.
    pub fn from_toml_str(text: &str, source_name: &str, base_dir: &Path) -> Result<Self> {
        let spec = ScenarioSpec::from_toml_str(text, source_name)?;
        let rig_path = base_dir.join(&spec.rig);
        let rig_text = std::fs::read_to_string(&rig_path).map_err(|e| Error::Key {
            source_name: source_name.to_string(),
            key: "rig".to_string(),
            problem: format!("cannot read rig file {}: {e}", rig_path.display()),
        })?;
        let rig = Rig::from_toml_str(&rig_text, &rig_path.display().to_string())?;
        let scenario = Self {
            spec,
            rig,
            rig_text,
            rig_path,
            source_name: source_name.to_string(),
        };
        scenario.check_rig()?;
        Ok(scenario)
    }

    /// A scenario from parts already in memory (tests, other tools).
    pub fn from_parts(spec: ScenarioSpec, rig: Rig, source_name: &str) -> Result<Self> {
        spec.validate(source_name)?;
        let scenario = Self {
            rig_text: rig.to_toml(),
            rig,
            spec,
            rig_path: PathBuf::new(),
            source_name: source_name.to_string(),
        };
        scenario.check_rig()?;
        Ok(scenario)
    }

    /// The same scenario with another seed.
    #[must_use]
    pub fn with_seed(mut self, seed: u64) -> Self {
        self.spec.seed = seed;
        self
    }

    /// The same scenario with its lamps laid out from another seed (`[world] seed`): the
    /// jittered grids jittered afresh.
    #[must_use]
    pub fn with_world_seed(mut self, seed: u64) -> Self {
        self.spec.world.seed = Some(seed);
        self
    }

    /// The nominal rig must describe the same sensor as the truth.
    fn check_rig(&self) -> Result<()> {
        let cam = &self.spec.camera;
        let (w, h) = (self.rig.width as usize, self.rig.height as usize);
        if (w, h) != (cam.width, cam.height) {
            return Err(Error::Key {
                source_name: self.source_name.clone(),
                key: "rig".to_string(),
                problem: format!(
                    "the rig file {} says {w}x{h} but camera.width x camera.height is {}x{}",
                    self.rig_path.display(),
                    cam.width,
                    cam.height
                ),
            });
        }
        Ok(())
    }

    /// The true camera parameters `C`.
    pub fn true_camera(&self) -> CameraParams {
        let n = &self.spec.noise;
        CameraParams {
            vehicle: rig_model::Vehicle {
                odom_scale: 1.0 + n.velocity_scale_error,
                odom_yaw_scale: 1.0 + n.yaw_rate_scale_error,
                odom_yaw_bias: n.yaw_rate_bias_radps,
                time_offset: self.spec.rates.board_clock_offset_s,
            },
            ..self.spec.camera.params()
        }
    }

    /// The board's registers.
    pub fn registers(&self) -> Registers {
        Registers {
            width: self.spec.camera.width,
            height: self.spec.camera.height,
            threshold: self.spec.board.threshold,
            max_features: self.spec.board.max_features,
        }
    }
}

impl TrueCamera {
    /// As the rig model's parameters (angles in radians).
    pub fn params(&self) -> CameraParams {
        let m = &self.mount;
        CameraParams {
            vehicle: Default::default(),
            f: self.f_px,
            cx: self.cx_px,
            cy: self.cy_px,
            baseline: self.baseline_m,
            mount: Mount {
                x: m.x_m,
                y: m.y_m,
                z: m.z_m,
                roll: m.roll_deg.to_radians(),
                pitch: m.pitch_deg.to_radians(),
                yaw: m.yaw_deg.to_radians(),
            },
        }
    }
}

impl ScenarioSpec {
    /// Parses and checks a scenario's TOML text (without reading its rig file).
    pub fn from_toml_str(text: &str, source_name: &str) -> Result<Self> {
        let line_of = |span: Option<std::ops::Range<usize>>| {
            span.map_or(1, |s| {
                text.get(..s.start)
                    .map_or(1, |before| before.matches('\n').count() + 1)
            })
        };
        let de = toml::Deserializer::parse(text).map_err(|e| Error::Syntax {
            source_name: source_name.to_string(),
            line: line_of(e.span()),
            reason: one_line(e.message()),
        })?;
        let spec: Self = serde_path_to_error::deserialize(de).map_err(|e| {
            let path = e.path().to_string();
            let line = line_of(e.inner().span());
            let (key, problem) = describe_serde_error(&path, e.inner().message());
            Error::Key {
                source_name: source_name.to_string(),
                key,
                problem: format!("{problem} (line {line})"),
            }
        })?;
        spec.validate(source_name)?;
        Ok(spec)
    }

    /// Checks every value for what the simulator can do with it.
    pub fn validate(&self, source_name: &str) -> Result<()> {
        let mut v = Validator {
            source_name,
            error: None,
        };
        self.check(&mut v);
        match v.error {
            Some(e) => Err(e),
            None => Ok(()),
        }
    }

    fn check(&self, v: &mut Validator<'_>) {
        let c = &self.camera;
        v.range_usize(
            "camera.width",
            c.width,
            harris_core::MIN_SIZE,
            harris_core::MAX_SIZE,
        );
        v.range_usize(
            "camera.height",
            c.height,
            harris_core::MIN_SIZE,
            harris_core::MAX_SIZE,
        );
        v.positive("camera.f_px", c.f_px);
        v.finite("camera.cx_px", c.cx_px);
        v.finite("camera.cy_px", c.cy_px);
        v.positive("camera.baseline_m", c.baseline_m);
        let m = &c.mount;
        for (key, x) in [
            ("camera.mount.x_m", m.x_m),
            ("camera.mount.y_m", m.y_m),
            ("camera.mount.z_m", m.z_m),
        ] {
            v.finite(key, x);
        }
        for (key, x) in [
            ("camera.mount.roll_deg", m.roll_deg),
            ("camera.mount.pitch_deg", m.pitch_deg),
            ("camera.mount.yaw_deg", m.yaw_deg),
        ] {
            v.within(key, x, -180.0, 180.0);
        }
        v.range_usize(
            "board.max_features",
            self.board.max_features,
            1,
            harris_core::MAX_FEATURES_LIMIT,
        );
        let r = &self.rates;
        v.within("rates.camera_hz", r.camera_hz, 0.1, 1000.0);
        v.within("rates.odometry_hz", r.odometry_hz, 0.1, 10_000.0);
        if r.odometry_hz < r.camera_hz {
            v.fail(
                "rates.odometry_hz",
                format!(
                    "{} Hz is below the camera rate {} Hz (the odometry rate is at least the camera rate)",
                    r.odometry_hz, r.camera_hz
                ),
            );
        }
        if r.start_t_us > 1 << 50 {
            v.fail("rates.start_t_us", format!("{} is too large", r.start_t_us));
        }
        if r.camera_phase_us > 60_000_000 {
            v.fail(
                "rates.camera_phase_us",
                format!("{} us is more than a minute", r.camera_phase_us),
            );
        }
        let n = &self.noise;
        v.non_negative("noise.pixel_px", n.pixel_px);
        v.non_negative("noise.velocity_mps", n.velocity_mps);
        v.non_negative("noise.yaw_rate_radps", n.yaw_rate_radps);
        v.within("noise.velocity_tau_s", n.velocity_tau_s, 0.0, 3600.0);
        v.within("noise.yaw_rate_tau_s", n.yaw_rate_tau_s, 0.0, 3600.0);
        v.within(
            "noise.velocity_scale_error",
            n.velocity_scale_error,
            -0.5,
            0.5,
        );
        v.within(
            "noise.yaw_rate_bias_radps",
            n.yaw_rate_bias_radps,
            -1.0,
            1.0,
        );
        v.within(
            "noise.yaw_rate_scale_error",
            n.yaw_rate_scale_error,
            -0.5,
            0.5,
        );
        v.within(
            "rates.board_clock_offset_s",
            r.board_clock_offset_s,
            -1.0,
            1.0,
        );
        v.within("noise.response_log_sigma", n.response_log_sigma, 0.0, 3.0);
        let w = &self.world;
        v.within(
            "world.lamp_radius_m",
            w.lamp_radius_m,
            1e-5,
            MAX_LAMP_RADIUS_M,
        );
        v.positive("world.lamp_radiance_dn", w.lamp_radiance_dn);
        v.within(
            "world.lamp_response",
            w.lamp_response,
            1.0,
            f64::from(i32::MAX),
        );
        if w.lamps.is_empty() && w.grids.is_empty() && w.panels.is_empty() && w.added.is_empty() {
            v.fail(
                "world",
                "no lamps: give world.lamps, world.grids, world.panels or world.added".to_string(),
            );
        }
        for (i, l) in w.lamps.iter().enumerate() {
            v.lamp(&format!("world.lamps[{i}]"), l);
        }
        let mut total = w.lamps.len();
        for (i, g) in w.grids.iter().enumerate() {
            let k = |name: &str| format!("world.grids[{i}].{name}");
            v.finite(&k("x0_m"), g.x0_m);
            v.finite(&k("y0_m"), g.y0_m);
            v.finite(&k("z_m"), g.z_m);
            v.range_usize(&k("nx"), g.nx, 1, 10_000);
            v.range_usize(&k("ny"), g.ny, 1, 10_000);
            v.positive(&k("dx_m"), g.dx_m);
            v.positive(&k("dy_m"), g.dy_m);
            v.non_negative(&k("jitter_xy_m"), g.jitter_xy_m);
            v.non_negative(&k("jitter_z_m"), g.jitter_z_m);
            if let Some(r) = g.radius_m {
                v.within(&k("radius_m"), r, 1e-5, MAX_LAMP_RADIUS_M);
            }
            if let Some(r) = g.radiance_dn {
                v.positive(&k("radiance_dn"), r);
            }
            total = total.saturating_add(g.nx.saturating_mul(g.ny));
        }
        for (i, q) in w.panels.iter().enumerate() {
            let k = |name: &str| format!("world.panels[{i}].{name}");
            v.finite(&k("x_m"), q.x_m);
            v.finite(&k("y_m"), q.y_m);
            v.finite(&k("z_m"), q.z_m);
            v.within(&k("length_m"), q.length_m, 1e-3, 10.0);
            v.within(&k("width_m"), q.width_m, 1e-3, 10.0);
            v.finite(&k("yaw_deg"), q.yaw_deg);
            if let Some(r) = q.radiance_dn {
                v.positive(&k("radiance_dn"), r);
            }
            total = total.saturating_add(q.point_count());
        }
        for (i, l) in w.added.iter().enumerate() {
            v.lamp(&format!("world.added[{i}]"), l);
        }
        if total.saturating_add(w.added.len()) > 1_000_000 {
            v.fail(
                "world",
                format!(
                    "{} lamps; at most 1000000",
                    total.saturating_add(w.added.len())
                ),
            );
        } else {
            check_dark(v, w, total);
        }
        let p = &self.path;
        v.within("path.max_speed_mps", p.max_speed_mps, 1e-3, 20.0);
        v.within("path.max_accel_mps2", p.max_accel_mps2, 1e-3, 20.0);
        v.within("path.max_yaw_rate_degps", p.max_yaw_rate_degps, 1e-2, 720.0);
        v.within(
            "path.max_yaw_accel_degps2",
            p.max_yaw_accel_degps2,
            1e-2,
            7200.0,
        );
        v.within(
            "path.max_lateral_accel_mps2",
            p.max_lateral_accel_mps2,
            1e-3,
            20.0,
        );
        v.range_usize("path.repeat", p.repeat, 1, 10_000);
        v.within("path.start.x_m", p.start.x_m, -MAX_WORLD_M, MAX_WORLD_M);
        v.within("path.start.y_m", p.start.y_m, -MAX_WORLD_M, MAX_WORLD_M);
        v.within("path.start.yaw_deg", p.start.yaw_deg, -360.0, 360.0);
        if p.segments.is_empty() {
            v.fail("path.segments", "no segments".to_string());
        }
        for (i, s) in p.segments.iter().enumerate() {
            let k = |name: &str| format!("path.segments[{i}].{name}");
            let (needed, optional) = s.kind.keys();
            for (name, present) in s.given() {
                if !present && needed.contains(&name) {
                    v.fail(
                        &k(name),
                        format!("missing key (a \"{}\" segment needs it)", s.kind.name()),
                    );
                }
            }
            for (name, present) in s.given() {
                if present && !needed.contains(&name) && !optional.contains(&name) {
                    let keys: Vec<&str> = needed.iter().chain(optional).copied().collect();
                    v.fail(
                        &k(name),
                        format!(
                            "not a key of a \"{}\" segment (its keys: kind, {})",
                            s.kind.name(),
                            keys.join(", ")
                        ),
                    );
                }
            }
            if let Some(x) = s.length_m {
                v.within(&k("length_m"), x, -10_000.0, 10_000.0);
            }
            if let Some(x) = s.angle_deg {
                v.within(&k("angle_deg"), x, -36_000.0, 36_000.0);
            }
            if let Some(x) = s.radius_m {
                v.within(&k("radius_m"), x, 1e-2, 10_000.0);
            }
            if let Some(x) = s.duration_s {
                if s.kind == SegmentKind::Moved {
                    // Carrying the vehicle takes time.
                    v.positive(&k("duration_s"), x);
                }
                v.within(&k("duration_s"), x, 0.0, 100_000.0);
            }
            for (name, x) in [("x_m", s.x_m), ("y_m", s.y_m)] {
                if let Some(x) = x {
                    v.within(&k(name), x, -MAX_WORLD_M, MAX_WORLD_M);
                }
            }
            if let Some(x) = s.yaw_deg {
                v.within(&k("yaw_deg"), x, -360.0, 360.0);
            }
            if let Some(x) = s.speed_mps {
                v.within(&k("speed_mps"), x, 1e-3, p.max_speed_mps);
            }
            if let Some(x) = s.yaw_rate_degps {
                v.within(&k("yaw_rate_degps"), x, 1e-2, p.max_yaw_rate_degps);
            }
        }
        if v.error.is_none() {
            let duration = crate::motion::path_duration_s(p);
            if duration > MAX_DURATION_S {
                v.fail(
                    "path",
                    format!("the path takes {duration:.0} s; at most {MAX_DURATION_S} s"),
                );
            } else if duration * r.odometry_hz > 1e7 || duration * r.camera_hz > 1e6 {
                v.fail(
                    "rates",
                    format!(
                        "{duration:.0} s at these rates is more than 10 million odometry samples or 1 million frames"
                    ),
                );
            }
        }
        let cl = &self.clutter;
        v.within("clutter.per_image", cl.per_image, 0.0, 1000.0);
        v.within("clutter.stereo_per_frame", cl.stereo_per_frame, 0.0, 1000.0);
        let l = &self.link;
        v.within("link.rate_bytes_per_s", l.rate_bytes_per_s, 100.0, 1e10);
        v.within("link.loss_probability", l.loss_probability, 0.0, 1.0);
        v.within(
            "link.bit_flip_probability",
            l.bit_flip_probability,
            0.0,
            1.0,
        );
        v.range_usize("link.chunk_min_bytes", l.chunk_min_bytes, 1, 1 << 20);
        v.range_usize(
            "link.chunk_max_bytes",
            l.chunk_max_bytes,
            l.chunk_min_bytes.max(1),
            1 << 20,
        );
        for (key, x) in [
            ("link.ready_latency_us", l.ready_latency_us),
            ("link.host_latency_us", l.host_latency_us),
            ("link.host_jitter_us", l.host_jitter_us),
        ] {
            if x > 60_000_000 {
                v.fail(key, format!("{x} us is more than a minute"));
            }
        }
        let rd = &self.render;
        v.within("render.optics_blur_px", rd.optics_blur_px, 0.1, 20.0);
        v.within("render.read_noise_dn", rd.read_noise_dn, 0.0, 100.0);
        v.within("render.electrons_per_dn", rd.electrons_per_dn, 0.0, 1e6);
        v.finite("render.roof_z_m", rd.roof_z_m);
        v.within("render.roof_dn", rd.roof_dn, 0.0, 255.0);
        v.within("render.beam_dn", rd.beam_dn, 0.0, 255.0);
        v.positive("render.beam_spacing_m", rd.beam_spacing_m);
        v.within(
            "render.beam_width_m",
            rd.beam_width_m,
            0.0,
            rd.beam_spacing_m,
        );
        if rd.roof_z_m <= c.mount.z_m {
            v.fail(
                "render.roof_z_m",
                format!(
                    "{} m is not above the cameras (camera.mount.z_m = {} m)",
                    rd.roof_z_m, c.mount.z_m
                ),
            );
        }
    }
}

/// `world.dark`: every id is a lamp of the hall (not an added one), listed once, and a panel's
/// points are dark together (the renderer draws a panel whole or not at all). `hall` is the
/// number of lamps before `world.added`.
fn check_dark(v: &mut Validator<'_>, w: &World, hall: usize) {
    // The id ranges of the panels' points: after the list and the grids.
    let mut panels = Vec::with_capacity(w.panels.len());
    let mut first = hall - w.panels.iter().map(PanelSpec::point_count).sum::<usize>();
    for q in &w.panels {
        panels.push(first..first + q.point_count());
        first += q.point_count();
    }
    for (i, &id) in w.dark.iter().enumerate() {
        let key = format!("world.dark[{i}]");
        let index = usize::try_from(id).unwrap_or(usize::MAX);
        if index >= hall {
            let known = if hall == 0 {
                "there are none before world.added".to_string()
            } else {
                format!("the hall's lamps are 0..={}", hall - 1)
            };
            let added = if index < hall + w.added.len() {
                format!(
                    " (lamp {id} is world.added[{}]: leave it out instead)",
                    index - hall
                )
            } else {
                String::new()
            };
            v.fail(&key, format!("no lamp {id}: {known}{added}"));
            continue;
        }
        if let Some(j) = w
            .dark
            .get(..i)
            .and_then(|b| b.iter().position(|&d| d == id))
        {
            v.fail(&key, format!("lamp {id} is already dark (world.dark[{j}])"));
        }
        if let Some((p, ids)) = panels.iter().enumerate().find(|(_, r)| r.contains(&index))
            && let Some(missing) = ids
                .clone()
                .find(|&m| !w.dark.iter().any(|&d| d as usize == m))
        {
            v.fail(
                &key,
                format!(
                    "lamp {id} is a point of world.panels[{p}] (lamps {}..={}), which goes dark whole: lamp {missing} is not listed",
                    ids.start,
                    ids.end - 1
                ),
            );
        }
    }
}

/// Largest lamp radius, metres: the simulator's lamps are points, drawn as small disks.
pub const MAX_LAMP_RADIUS_M: f64 = 0.5;

/// Largest world coordinate of a start pose or a move, metres (a hall is far smaller).
pub const MAX_WORLD_M: f64 = 100_000.0;

/// Longest path a scenario may have, seconds (12 hours: a long shift; the simulator holds
/// the whole run in memory, about 3 MiB per simulated minute of the warehouse).
pub const MAX_DURATION_S: f64 = 43_200.0;

/// Collects the first impossible value.
struct Validator<'a> {
    source_name: &'a str,
    error: Option<Error>,
}

impl Validator<'_> {
    fn fail(&mut self, key: &str, problem: String) {
        if self.error.is_none() {
            self.error = Some(Error::Key {
                source_name: self.source_name.to_string(),
                key: key.to_string(),
                problem,
            });
        }
    }

    fn finite(&mut self, key: &str, x: f64) {
        if !x.is_finite() {
            self.fail(key, format!("{x} is not a finite number"));
        }
    }

    fn positive(&mut self, key: &str, x: f64) {
        if !(x > 0.0 && x.is_finite()) {
            self.fail(key, format!("{x} must be positive"));
        }
    }

    fn non_negative(&mut self, key: &str, x: f64) {
        if !(x >= 0.0 && x.is_finite()) {
            self.fail(key, format!("{x} must be zero or positive"));
        }
    }

    fn within(&mut self, key: &str, x: f64, lo: f64, hi: f64) {
        if !(lo..=hi).contains(&x) {
            self.fail(key, format!("{x} is outside {lo}..={hi}"));
        }
    }

    /// A lamp of `world.lamps` or `world.added`; `key` is its dotted path.
    fn lamp(&mut self, key: &str, l: &LampSpec) {
        self.finite(&format!("{key}.x_m"), l.x_m);
        self.finite(&format!("{key}.y_m"), l.y_m);
        self.finite(&format!("{key}.z_m"), l.z_m);
        if let Some(r) = l.radius_m {
            self.within(&format!("{key}.radius_m"), r, 1e-5, MAX_LAMP_RADIUS_M);
        }
        if let Some(r) = l.radiance_dn {
            self.positive(&format!("{key}.radiance_dn"), r);
        }
    }

    fn range_usize(&mut self, key: &str, x: usize, lo: usize, hi: usize) {
        if !(lo..=hi).contains(&x) {
            self.fail(key, format!("{x} is outside {lo}..={hi}"));
        }
    }
}

/// Turns serde's message and path into the key and a plain problem: `missing field `x``
/// names `x` as the key, `unknown field` likewise.
fn describe_serde_error(path: &str, message: &str) -> (String, String) {
    let join = |field: &str| {
        if path == "." || path.is_empty() {
            field.to_string()
        } else {
            format!("{path}.{field}")
        }
    };
    let message = one_line(message);
    let backticked = |rest: &str| rest.split('`').nth(1).map(str::to_string);
    if let Some(rest) = message.strip_prefix("missing field ")
        && let Some(field) = backticked(rest)
    {
        return (join(&field), "missing key".to_string());
    }
    if let Some(rest) = message.strip_prefix("unknown field ")
        && let Some(field) = backticked(rest)
    {
        let expected = rest
            .split_once(", expected ")
            .map(|(_, e)| {
                let e = e.strip_prefix("one of ").unwrap_or(e);
                format!(" (known: {})", e.replace('`', ""))
            })
            .unwrap_or_default();
        // serde_path_to_error's path already ends with the unknown key.
        let key = if path.ends_with(&field) {
            path.to_string()
        } else {
            join(&field)
        };
        return (key, format!("unknown key{expected}"));
    }
    if let Some(rest) = message.strip_prefix("unknown variant ") {
        return (
            path.to_string(),
            format!("unknown value {}", rest.replace('`', "\"")),
        );
    }
    if let Some(rest) = message.strip_prefix("invalid type: ") {
        let (found, expected) = rest.split_once(", expected ").unwrap_or((rest, "?"));
        return (
            path.to_string(),
            format!("wrong type: expected {expected}, found {found}"),
        );
    }
    if let Some(rest) = message.strip_prefix("invalid value: ") {
        let (found, expected) = rest.split_once(", expected ").unwrap_or((rest, "?"));
        return (
            path.to_string(),
            format!(
                "impossible value: expected {expected}, found {}",
                found.replace('`', "")
            ),
        );
    }
    let key = if path == "." {
        "(top level)".to_string()
    } else {
        path.to_string()
    };
    (key, message)
}

fn one_line(s: &str) -> String {
    s.split_whitespace().collect::<Vec<_>>().join(" ")
}
