//! Topic names, encodings and the JSON Schema documents of vehicle-interfaces.md section 4.
//!
//! A channel is one of ours only when its topic, its message encoding and its schema name
//! all match; anything else (a ROS `/odom` in CDR, say) is a foreign topic and is ignored.

/// The board's raw byte stream, chunks as received.
pub const FEATURES: &str = "/fpga/features";
/// Message encoding of [`FEATURES`]: the board's stream, board-icd.md section 3.
pub const FEATURES_ENCODING: &str = "stereonav.fpga-link.v1";
/// Odometry samples.
pub const ODOM: &str = "/odom";
/// The rig file's tables as JSON, at the start of a log (optional).
pub const RIG: &str = "/rig";
/// Simulator truth: the robot's pose at each stereo frame.
pub const TRUTH_POSE: &str = "/truth/pose";
/// Simulator truth: the landmarks (lamps), once.
pub const TRUTH_LANDMARKS: &str = "/truth/landmarks";
/// Simulator truth: the camera parameters, once.
pub const TRUTH_CAMERA: &str = "/truth/camera";

/// Message encoding of every JSON topic.
pub const JSON_ENCODING: &str = "json";
/// Schema encoding of every JSON topic's schema.
pub const JSONSCHEMA_ENCODING: &str = "jsonschema";

/// Schema name of [`ODOM`].
pub const ODOMETRY_SCHEMA_NAME: &str = "stereonav.Odometry";
/// Schema name of [`RIG`].
pub const RIG_SCHEMA_NAME: &str = "stereonav.Rig";
/// Schema name of [`TRUTH_POSE`].
pub const TRUTH_POSE_SCHEMA_NAME: &str = "stereonav.TruthPose";
/// Schema name of [`TRUTH_LANDMARKS`].
pub const TRUTH_LANDMARKS_SCHEMA_NAME: &str = "stereonav.TruthLandmarks";
/// Schema name of [`TRUTH_CAMERA`].
pub const TRUTH_CAMERA_SCHEMA_NAME: &str = "stereonav.TruthCamera";

/// JSON Schema of [`ODOM`] messages (vehicle-interfaces.md section 2).
pub const ODOMETRY_SCHEMA: &str = r#"{
  "$schema": "https://json-schema.org/draft/2020-12/schema",
  "title": "stereonav.Odometry",
  "description": "Robot-frame velocities, each held constant from t_us until the next sample",
  "type": "object",
  "properties": {
    "t_us": { "type": "integer", "minimum": 0, "description": "Timestamp, microseconds, on the clock of the board's packet timestamps" },
    "vx": { "type": "number", "description": "Velocity along robot x (forward), m/s" },
    "vy": { "type": "number", "description": "Velocity along robot y (left), m/s" },
    "vtheta": { "type": "number", "description": "Yaw rate about robot z (up), rad/s" }
  },
  "required": ["t_us", "vx", "vy", "vtheta"]
}"#;

/// JSON Schema of [`RIG`] messages: the rig file's tables (vehicle-interfaces.md section 3).
///
/// Documentation for viewers; this crate checks only that a rig message is a JSON object.
pub const RIG_SCHEMA: &str = r#"{
  "$schema": "https://json-schema.org/draft/2020-12/schema",
  "title": "stereonav.Rig",
  "description": "The rig file's tables (nominal camera, mount, parameters to estimate, priors, noise)",
  "type": "object",
  "properties": {
    "camera": {
      "type": "object",
      "description": "Nominal values from the datasheet",
      "properties": {
        "width": { "type": "integer", "minimum": 1, "description": "px" },
        "height": { "type": "integer", "minimum": 1, "description": "px" },
        "f": { "type": "number", "description": "Focal length, px" },
        "cx": { "type": "number", "description": "Principal point column, px" },
        "cy": { "type": "number", "description": "Principal point row, px" },
        "baseline": { "type": "number", "description": "Camera separation, m" }
      },
      "required": ["width", "height", "f", "cx", "cy", "baseline"]
    },
    "mount": {
      "type": "object",
      "description": "Rig pose in the robot frame, m and rad, R = Rz(yaw) Ry(pitch) Rx(roll)",
      "properties": {
        "x": { "type": "number" },
        "y": { "type": "number" },
        "z": { "type": "number" },
        "roll": { "type": "number" },
        "pitch": { "type": "number" },
        "yaw": { "type": "number" }
      },
      "required": ["x", "y", "z", "roll", "pitch", "yaw"]
    },
    "estimate": {
      "type": "object",
      "description": "Camera parameters to estimate; the others stay nominal",
      "properties": {
        "parameters": {
          "type": "array",
          "items": { "enum": ["f", "cx", "cy", "baseline", "mount_x", "mount_y", "mount_z", "mount_roll", "mount_pitch", "mount_yaw"] }
        }
      }
    },
    "prior": {
      "type": "object",
      "description": "1-sigma uncertainty of each estimated nominal value",
      "additionalProperties": { "type": "number" }
    },
    "noise": {
      "type": "object",
      "properties": {
        "pixel": { "type": "number", "description": "px, 1 sigma, each of uL vL uR vR" },
        "velocity": { "type": "number", "description": "m/s, 1 sigma per odometry sample, each of vx vy" },
        "yaw_rate": { "type": "number", "description": "rad/s, 1 sigma per odometry sample" }
      }
    }
  },
  "required": ["camera", "mount"]
}"#;

/// JSON Schema of [`TRUTH_POSE`] messages.
pub const TRUTH_POSE_SCHEMA: &str = r#"{
  "$schema": "https://json-schema.org/draft/2020-12/schema",
  "title": "stereonav.TruthPose",
  "description": "Simulator truth: the robot's planar pose in the world frame at a stereo frame",
  "type": "object",
  "properties": {
    "t_us": { "type": "integer", "minimum": 0, "description": "Timestamp of the stereo frame, microseconds" },
    "x": { "type": "number", "description": "World X, m" },
    "y": { "type": "number", "description": "World Y, m" },
    "theta": { "type": "number", "description": "Heading, rad" }
  },
  "required": ["t_us", "x", "y", "theta"]
}"#;

/// JSON Schema of [`TRUTH_LANDMARKS`] messages.
pub const TRUTH_LANDMARKS_SCHEMA: &str = r#"{
  "$schema": "https://json-schema.org/draft/2020-12/schema",
  "title": "stereonav.TruthLandmarks",
  "description": "Simulator truth: every landmark (lamp) in the world frame",
  "type": "object",
  "properties": {
    "landmarks": {
      "type": "array",
      "items": {
        "type": "object",
        "properties": {
          "id": { "type": "integer", "minimum": 0, "maximum": 4294967295 },
          "x": { "type": "number", "description": "m" },
          "y": { "type": "number", "description": "m" },
          "z": { "type": "number", "description": "m" }
        },
        "required": ["id", "x", "y", "z"]
      }
    }
  },
  "required": ["landmarks"]
}"#;

/// JSON Schema of [`TRUTH_CAMERA`] messages.
pub const TRUTH_CAMERA_SCHEMA: &str = r#"{
  "$schema": "https://json-schema.org/draft/2020-12/schema",
  "title": "stereonav.TruthCamera",
  "description": "Simulator truth: the camera parameters C (vehicle-interfaces.md section 1) and the vehicle parameters V (1.2, optional: nominal when absent)",
  "type": "object",
  "properties": {
    "f": { "type": "number", "description": "Focal length, px" },
    "cx": { "type": "number", "description": "px" },
    "cy": { "type": "number", "description": "px" },
    "baseline": { "type": "number", "description": "m" },
    "mount_x": { "type": "number", "description": "m" },
    "mount_y": { "type": "number", "description": "m" },
    "mount_z": { "type": "number", "description": "m" },
    "mount_roll": { "type": "number", "description": "rad" },
    "mount_pitch": { "type": "number", "description": "rad" },
    "mount_yaw": { "type": "number", "description": "rad" },
    "odom_scale": { "type": "number", "description": "reported vx, vy = odom_scale x true (default 1)" },
    "odom_yaw_scale": { "type": "number", "description": "reported vtheta = odom_yaw_scale x true + odom_yaw_bias (default 1)" },
    "odom_yaw_bias": { "type": "number", "description": "rad/s (default 0)" },
    "time_offset": { "type": "number", "description": "s: a board timestamp t was exposed at odometry-clock time t - time_offset (default 0)" }
  },
  "required": ["f", "cx", "cy", "baseline", "mount_x", "mount_y", "mount_z", "mount_roll", "mount_pitch", "mount_yaw"]
}"#;

/// The topics this crate knows.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub(crate) enum Topic {
    Features,
    Odom,
    Rig,
    TruthPose,
    TruthLandmarks,
    TruthCamera,
}

impl Topic {
    pub(crate) const ALL: [Topic; 6] = [
        Topic::Features,
        Topic::Odom,
        Topic::Rig,
        Topic::TruthPose,
        Topic::TruthLandmarks,
        Topic::TruthCamera,
    ];

    pub(crate) fn name(self) -> &'static str {
        match self {
            Topic::Features => FEATURES,
            Topic::Odom => ODOM,
            Topic::Rig => RIG,
            Topic::TruthPose => TRUTH_POSE,
            Topic::TruthLandmarks => TRUTH_LANDMARKS,
            Topic::TruthCamera => TRUTH_CAMERA,
        }
    }

    pub(crate) fn message_encoding(self) -> &'static str {
        match self {
            Topic::Features => FEATURES_ENCODING,
            _ => JSON_ENCODING,
        }
    }

    /// Schema name and JSON Schema document, `None` for the schemaless byte stream.
    pub(crate) fn schema(self) -> Option<(&'static str, &'static str)> {
        match self {
            Topic::Features => None,
            Topic::Odom => Some((ODOMETRY_SCHEMA_NAME, ODOMETRY_SCHEMA)),
            Topic::Rig => Some((RIG_SCHEMA_NAME, RIG_SCHEMA)),
            Topic::TruthPose => Some((TRUTH_POSE_SCHEMA_NAME, TRUTH_POSE_SCHEMA)),
            Topic::TruthLandmarks => Some((TRUTH_LANDMARKS_SCHEMA_NAME, TRUTH_LANDMARKS_SCHEMA)),
            Topic::TruthCamera => Some((TRUTH_CAMERA_SCHEMA_NAME, TRUTH_CAMERA_SCHEMA)),
        }
    }

    pub(crate) fn from_name(name: &str) -> Option<Topic> {
        Topic::ALL.into_iter().find(|t| t.name() == name)
    }

    pub(crate) fn index(self) -> usize {
        self as usize
    }
}
