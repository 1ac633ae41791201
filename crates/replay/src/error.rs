//! Why a log could not be replayed. Every message is one line naming the file and the problem.

use std::path::PathBuf;

/// Errors of [`crate::calibrate_log`], the replay and the writers of its outputs.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// The log could not be read: missing or unreadable file, not an MCAP file, or a malformed
    /// message on a vehicle topic (vehicle-log's message names the file and the problem).
    #[error(transparent)]
    Log(#[from] vehicle_log::Error),
    /// An MCAP file without the vehicle topics (written by another tool).
    #[error(
        "{} is not a vehicle log: it has no /fpga/features or /odom channel in this project's encodings (its topics: {})",
        path.display(),
        if topics.is_empty() { "none".to_string() } else { topics.join(", ") }
    )]
    NotVehicleLog {
        /// The file.
        path: PathBuf,
        /// The topics it has instead.
        topics: Vec<String>,
    },
    /// A ROS 2 bag with camera images replayed without naming its topics.
    #[error(
        "{} is a ROS 2 bag without the board's /fpga/features: name its camera and odometry topics with --left, --right and --odom (its camera topics: {}; odometry: {})",
        path.display(),
        cameras.join(", "),
        if odometry.is_empty() { "none".to_string() } else { odometry.join(", ") }
    )]
    Ros2TopicsNotNamed {
        /// The file.
        path: PathBuf,
        /// Its image topics with their types.
        cameras: Vec<String>,
        /// Its odometry topics.
        odometry: Vec<String>,
    },
    /// One topic named for two roles of a ROS 2 bag's replay.
    #[error(
        "{first} and {second} both name {topic}: the left camera, the right camera and the odometry are three topics"
    )]
    TopicNamedTwice {
        /// The first option that named it.
        first: &'static str,
        /// The second.
        second: &'static str,
        /// The topic.
        topic: String,
    },
    /// A topic named for the replay of a ROS 2 bag is not in it.
    #[error(
        "{}: {option} {topic}: the bag has no such topic (its topics: {})",
        path.display(),
        if topics.is_empty() { "none".to_string() } else {
            topics.iter().map(|(t, ty)| if ty.is_empty() { t.clone() } else { format!("{t} ({ty})") }).collect::<Vec<_>>().join(", ")
        }
    )]
    MissingTopic {
        /// The file.
        path: PathBuf,
        /// The option that named it (`--left`, ...).
        option: &'static str,
        /// The topic named.
        topic: String,
        /// The bag's other topics and their types.
        topics: Vec<(String, String)>,
    },
    /// The rig's `[board]` registers cannot run the host's detector on a bag's images.
    #[error("{}: the rig's [camera] size and [board] registers cannot run the board's detector: {problem}", path.display())]
    HostBoard {
        /// The file.
        path: PathBuf,
        /// Why.
        problem: String,
    },
    /// No rig was given and the log has no `/rig` message (or lost it to damage).
    #[error(
        "{}: no rig: {} and no rig file was given",
        path.display(),
        if *lost_to_damage {
            "the log's start is damaged (its /rig message was in a lost stretch: see `stereonav log check`)"
        } else {
            "the log has no /rig message"
        }
    )]
    NoRig {
        /// The file.
        path: PathBuf,
        /// The log lost a stretch before its first readable data: the `/rig` message, written
        /// at the start, was most likely in it.
        lost_to_damage: bool,
    },
    /// The log's `/rig` message is not a usable rig (the message names the key and problem).
    #[error(transparent)]
    BadRig(#[from] rig_model::RigFileError),
    /// A setting of the replay is out of range.
    #[error("replay settings: {0}")]
    Settings(#[from] track::SettingsError),
    /// The navigator refused its settings or the rig.
    #[error("navigator: {0}")]
    Navigator(#[from] nav::Error),
    /// The localiser refused the map or its settings.
    #[error("localiser: {0}")]
    Localize(String),
    /// The map has no rig (imported from a lighting plan without one) and none was given.
    #[error(
        "the map has no rig{}: give the vehicle's rig file (--rig RIG.toml)",
        plan.as_ref().map_or(String::new(), |p| format!(" (it was imported from the lighting plan {p} without one)"))
    )]
    MapWithoutRig {
        /// The plan the map was imported from, when it says.
        plan: Option<String>,
    },
    /// An output file (`EST.mcap`, `SUMMARY.json`, `TRAJ.csv`) could not be created or
    /// written.
    #[error("cannot write {file}: {}: {source}", path.display())]
    Output {
        /// Which output.
        file: &'static str,
        /// The path given for it.
        path: PathBuf,
        /// What the operating system said.
        #[source]
        source: std::io::Error,
    },
    /// The MCAP writer refused a record of `EST.mcap` (not an I/O error).
    #[error("cannot write EST.mcap: {}: the MCAP writer failed: {detail}", path.display())]
    Mcap {
        /// The path given for it.
        path: PathBuf,
        /// What the writer said.
        detail: String,
    },
    /// A timestamp too late for `EST.mcap` (a Foxglove timestamp holds whole seconds in a
    /// `u32`).
    #[error(
        "cannot write EST.mcap: {}: {topic} at t_us {t_us} is later than the largest time a Foxglove timestamp holds ({max} us)",
        path.display()
    )]
    TimeOutOfRange {
        /// The path given for it.
        path: PathBuf,
        /// The topic of the message.
        topic: &'static str,
        /// Its time, microseconds.
        t_us: u64,
        /// The largest time allowed, microseconds.
        max: u64,
    },
}

/// `EST.mcap`'s writer's errors as the replay's (the same variants, the same messages).
impl From<estimates_log::WriteError> for Error {
    fn from(e: estimates_log::WriteError) -> Self {
        use estimates_log::WriteError;
        match e {
            WriteError::Output { path, source } => Self::Output {
                file: estimates_log::topics::EST_FILE,
                path,
                source,
            },
            WriteError::Mcap { path, detail } => Self::Mcap { path, detail },
            WriteError::TimeOutOfRange {
                path,
                topic,
                t_us,
                max,
            } => Self::TimeOutOfRange {
                path,
                topic,
                t_us,
                max,
            },
        }
    }
}
