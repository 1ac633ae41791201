//! What a vehicle log holds.

use serde::{Deserialize, Serialize};

use crate::damage::LostSpan;

/// One odometry sample on `/odom` (vehicle-interfaces.md section 2): robot-frame velocities,
/// each held constant from `t_us` until the next sample. The rig model's type, so that what
/// is read from a log goes into the estimators as it is.
pub use rig_model::odometry::OdomSample;

/// Simulator truth on `/truth/pose`: the robot's planar pose in the world frame at one
/// stereo frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TruthPose {
    /// Timestamp of the stereo frame (the packet's), microseconds.
    pub t_us: u64,
    /// World X, m.
    pub x: f64,
    /// World Y, m.
    pub y: f64,
    /// Heading, rad.
    pub theta: f64,
}

/// One landmark (lamp) of simulator truth on `/truth/landmarks`, in the world frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TruthLandmark {
    /// The simulator's landmark id.
    pub id: u32,
    /// World X, m.
    pub x: f64,
    /// World Y, m.
    pub y: f64,
    /// World Z (height), m.
    pub z: f64,
}

/// Simulator truth on `/truth/camera`: the true camera parameters `C`
/// (vehicle-interfaces.md section 1) and the true vehicle parameters `V` (1.2; absent in logs
/// of simulators that do not model them: nominal).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TruthCamera {
    /// Focal length, px.
    pub f: f64,
    /// Principal point column, px.
    pub cx: f64,
    /// Principal point row, px.
    pub cy: f64,
    /// Camera separation, m.
    pub baseline: f64,
    /// Rig origin in the robot frame, x, m.
    pub mount_x: f64,
    /// Rig origin in the robot frame, y, m.
    pub mount_y: f64,
    /// Rig origin in the robot frame, z, m.
    pub mount_z: f64,
    /// Mount roll, rad.
    pub mount_roll: f64,
    /// Mount pitch, rad (positive tilts the optical axis toward the robot's front).
    pub mount_pitch: f64,
    /// Mount yaw, rad.
    pub mount_yaw: f64,
    /// Reported `vx, vy` = `odom_scale` x true.
    #[serde(default = "one")]
    pub odom_scale: f64,
    /// Reported `vtheta` = `odom_yaw_scale` x true + `odom_yaw_bias`.
    #[serde(default = "one")]
    pub odom_yaw_scale: f64,
    /// Rad/s added to every reported `vtheta`.
    #[serde(default)]
    pub odom_yaw_bias: f64,
    /// S: a board timestamp `t` was exposed at odometry-clock time `t - time_offset`.
    #[serde(default)]
    pub time_offset: f64,
}

const fn one() -> f64 {
    1.0
}

/// One message of a vehicle log, in log order.
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub enum Record {
    /// A chunk of the board's raw byte stream on `/fpga/features`, as received; concatenate
    /// the chunks in log order to get the stream.
    Features {
        /// Arrival time, nanoseconds (the message's log time).
        log_time_ns: u64,
        /// The bytes.
        bytes: Vec<u8>,
    },
    /// An odometry sample on `/odom`, or on the named ROS 2 odometry topic of a bag.
    Odom(OdomSample),
    /// The rig file's tables on `/rig`: the message's text, a JSON object, as logged.
    Rig(String),
    /// Simulator truth: the pose at a stereo frame.
    TruthPose(TruthPose),
    /// Simulator truth: every landmark.
    TruthLandmarks(Vec<TruthLandmark>),
    /// Simulator truth: the camera parameters.
    TruthCamera(TruthCamera),
    /// A camera image of a ROS 2 bag (vehicle-interfaces.md 4.1; only when the reader was
    /// given the topics, [`crate::LogReader::set_ros2_topics`]).
    Image(crate::ros2::CameraImage),
    /// A message of a named camera topic that does not decode by its schema: counted by the
    /// caller, like an image it cannot read.
    BadImage {
        /// Which camera.
        side: crate::ros2::Side,
        /// The message's log time, ns.
        log_time_ns: u64,
        /// What was wrong, one line.
        problem: String,
    },
    /// Data that could not be read (a damaged chunk, bytes skipped where the framing was
    /// lost, the rest of a chunk cut by the end of the file), at the place of the loss: just
    /// before the next good record. A stream decoder should be reset here (the bytes before
    /// and after do not join); the span says how much log time was lost.
    Lost(LostSpan),
}
