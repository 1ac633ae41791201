//! The channels of `EST.mcap` (topic, schema name, JSON Schema) and the constants its writer
//! and reader share.
//!
//! Every channel has message encoding [`JSON_ENCODING`] and a schema with encoding
//! [`JSONSCHEMA_ENCODING`] (the same as vehicle logs'). The JSON Schema documents are the data
//! files `schemas/<schema name>.json` of this crate, pretty-printed; the schema record written
//! holds the same document in compact form ([`Topic::schema_bytes`]: keys in the files' order,
//! which is sorted, no whitespace).

pub use vehicle_log::topics::{JSON_ENCODING, JSONSCHEMA_ENCODING};

/// What `EST.mcap` is called in error messages.
pub const EST_FILE: &str = "EST.mcap";

/// The robot's pose at each frame (`foxglove.PoseInFrame`).
pub const POSE: &str = "/est/pose";
/// The path so far, about once a second (`foxglove.PosesInFrame`).
pub const TRAJECTORY: &str = "/est/trajectory";
/// The map snapshots (`foxglove.SceneUpdate`).
pub const LANDMARKS: &str = "/est/landmarks";
/// The camera samples (`stereonav.CameraEstimate`).
pub const CAMERA: &str = "/est/camera";
/// The filter at each frame (`stereonav.FrameInfo`): the topic whose presence makes an MCAP
/// file an estimates file.
pub const FRAME: &str = "/est/frame";
/// The summary, once at the end (`stereonav.Summary`).
pub const SUMMARY: &str = "/est/summary";

/// The frame every estimate is expressed in (vehicle-interfaces.md section 1: the robot's frame
/// at the first stereo frame).
pub const WORLD_FRAME: &str = "world";

/// Data time between two `/est/trajectory` messages, microseconds.
pub const TRAJECTORY_PERIOD_US: u64 = 1_000_000;

/// Most poses in one `/est/trajectory` message. Past it the path is thinned to every other
/// pose (and from then on only every second, fourth, ... frame is kept), so that a message, and
/// the file, stay bounded on a long log: a path of this many points draws smoothly.
pub const TRAJECTORY_MAX_POSES: usize = 1000;

/// Diameter of the sphere drawn at a landmark's position, metres.
pub const LANDMARK_MARKER_M: f64 = 0.08;

/// The uncertainty ellipsoid's half-axes are this many standard deviations (its diameters
/// twice this many).
pub const ELLIPSOID_SIGMAS: f64 = 3.0;

/// The landmark marker's colour, RGBA in 0..1 (opaque orange).
pub const MARKER_RGBA: [f64; 4] = [1.0, 0.55, 0.0, 1.0];

/// The uncertainty ellipsoid's colour, RGBA in 0..1 (translucent blue).
pub const ELLIPSOID_RGBA: [f64; 4] = [0.2, 0.5, 1.0, 0.25];

/// `SceneEntityDeletion.type` ALL: delete every entity of the topic (Foxglove's enum value).
pub const DELETE_ALL: u32 = 1;

/// Microseconds in a second.
pub const US_PER_S: u64 = 1_000_000;
/// Nanoseconds in a microsecond (log time is `t_us` in nanoseconds).
pub const NS_PER_US: u64 = 1000;

/// Largest `t_us` whose Foxglove timestamp fits (`sec` is a `u32`). Its log time in
/// nanoseconds (about 4.3e18) fits 64 bits too.
pub const MAX_T_US: u64 = (u32::MAX as u64 + 1) * US_PER_S - 1;

/// The channels of `EST.mcap`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Topic {
    /// [`POSE`].
    Pose,
    /// [`TRAJECTORY`].
    Trajectory,
    /// [`LANDMARKS`].
    Landmarks,
    /// [`CAMERA`].
    Camera,
    /// [`FRAME`].
    Frame,
    /// [`SUMMARY`].
    Summary,
}

impl Topic {
    /// Every channel, in the order the writer adds them (channel ids 0 to 5).
    pub const ALL: [Self; 6] = [
        Self::Pose,
        Self::Trajectory,
        Self::Landmarks,
        Self::Camera,
        Self::Frame,
        Self::Summary,
    ];

    /// The topic name.
    pub fn name(self) -> &'static str {
        match self {
            Self::Pose => POSE,
            Self::Trajectory => TRAJECTORY,
            Self::Landmarks => LANDMARKS,
            Self::Camera => CAMERA,
            Self::Frame => FRAME,
            Self::Summary => SUMMARY,
        }
    }

    /// The schema name (the JSON Schema's `title`).
    pub fn schema_name(self) -> &'static str {
        match self {
            Self::Pose => "foxglove.PoseInFrame",
            Self::Trajectory => "foxglove.PosesInFrame",
            Self::Landmarks => "foxglove.SceneUpdate",
            Self::Camera => "stereonav.CameraEstimate",
            Self::Frame => "stereonav.FrameInfo",
            Self::Summary => "stereonav.Summary",
        }
    }

    /// The JSON Schema document, as its data file holds it (pretty-printed).
    ///
    /// Foxglove's schemas are written from its message reference (field names, types, enum
    /// values); the viewer recognises them by name. Like Foxglove's, they inline every
    /// sub-schema (Foxglove resolves no `$ref`). This project's objects require every property
    /// and allow no other; a number that may not be finite is `["number", "null"]`.
    pub fn schema(self) -> &'static str {
        match self {
            Self::Pose => include_str!("../schemas/foxglove.PoseInFrame.json"),
            Self::Trajectory => include_str!("../schemas/foxglove.PosesInFrame.json"),
            Self::Landmarks => include_str!("../schemas/foxglove.SceneUpdate.json"),
            Self::Camera => include_str!("../schemas/stereonav.CameraEstimate.json"),
            Self::Frame => include_str!("../schemas/stereonav.FrameInfo.json"),
            Self::Summary => include_str!("../schemas/stereonav.Summary.json"),
        }
    }

    /// The schema record's data: [`Self::schema`] in compact JSON. Fails only on a data file
    /// that is not JSON (the tests read every one).
    pub fn schema_bytes(self) -> Result<Vec<u8>, serde_json::Error> {
        let document: serde_json::Value = serde_json::from_str(self.schema())?;
        serde_json::to_vec(&document)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_schema_file_is_json_titled_by_its_schema_name() {
        for topic in Topic::ALL {
            let document: serde_json::Value = serde_json::from_str(topic.schema()).unwrap();
            assert_eq!(document["title"], topic.schema_name(), "{topic:?}");
        }
    }

    /// The files are kept in the form they were generated in (`serde_json`'s pretty printer,
    /// keys sorted, a final newline), so that their compact form is the schema written.
    #[test]
    fn every_schema_file_is_in_canonical_form() {
        for topic in Topic::ALL {
            let document: serde_json::Value = serde_json::from_str(topic.schema()).unwrap();
            let pretty = serde_json::to_string_pretty(&document).unwrap() + "\n";
            assert!(pretty == topic.schema(), "{}", topic.schema_name());
            let compact = topic.schema_bytes().unwrap();
            let stripped: String = topic
                .schema()
                .lines()
                .map(str::trim_start)
                .map(|l| l.replace("\": ", "\":"))
                .collect();
            assert_eq!(String::from_utf8(compact).unwrap(), stripped);
        }
    }

    #[test]
    fn topic_names_are_distinct_and_under_est() {
        for (i, a) in Topic::ALL.iter().enumerate() {
            assert!(a.name().starts_with("/est/"));
            for b in &Topic::ALL[i + 1..] {
                assert_ne!(a.name(), b.name());
                assert_ne!(a.schema_name(), b.schema_name());
            }
        }
    }
}
