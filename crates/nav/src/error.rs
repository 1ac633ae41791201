//! Why the navigator refused an input; the message is one line naming the problem.

/// A refused input, setting or operation. The navigator is left as it was.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// A setting is out of its range.
    #[error("navigator setting {name} = {value} must be {expected}")]
    Settings {
        /// The setting.
        name: &'static str,
        /// Its value.
        value: f64,
        /// What it must be.
        expected: &'static str,
    },
    /// Phase 1 refused its settings otherwise than by a field out of range.
    #[error("phase 1: {0}")]
    Phase1(selfcal::Error),
    /// The association's settings are out of range.
    #[error("association settings: {0}")]
    Association(#[from] track::SettingsError),
    /// The filter refused (settings, rig, an update that would lose positive definiteness).
    #[error("phase 2 filter: {0}")]
    Filter(#[from] vslam_ekf::Error),
    /// An input value is NaN or infinite.
    #[error("{what} at t = {t_us} us is not finite ({value})")]
    NonFinite {
        /// Which input.
        what: &'static str,
        /// Its timestamp, microseconds.
        t_us: u64,
        /// The value.
        value: f64,
    },
    /// An odometry sample older than the previous one.
    #[error(
        "odometry sample at t = {t_us} us is older than the previous one ({last_us} us): feed odometry in time order"
    )]
    OdometryOutOfOrder {
        /// The sample's timestamp.
        t_us: u64,
        /// The previous sample's.
        last_us: u64,
    },
    /// A frame older than the previous one.
    #[error(
        "stereo frame at t = {t_us} us is older than the previous one ({last_us} us): feed frames in time order"
    )]
    FrameOutOfOrder {
        /// The frame's timestamp.
        t_us: u64,
        /// The previous frame's.
        last_us: u64,
    },
}

impl Error {
    /// The kind of refusal, without its values: `"settings"`, `"association settings"`,
    /// `"filter"`, `"non-finite input"`, `"odometry out of order"`, `"frame out of order"`
    /// (to count refusals by kind).
    pub fn kind(&self) -> &'static str {
        match self {
            Self::Settings { .. } | Self::Phase1(_) => "settings",
            Self::Association(_) => "association settings",
            Self::Filter(_) => "filter",
            Self::NonFinite { .. } => "non-finite input",
            Self::OdometryOutOfOrder { .. } => "odometry out of order",
            Self::FrameOutOfOrder { .. } => "frame out of order",
        }
    }
}

impl From<selfcal::Error> for Error {
    /// A phase-1 setting out of range is a navigator setting out of range (same message).
    fn from(e: selfcal::Error) -> Self {
        match e {
            selfcal::Error::Setting {
                name,
                value,
                expected,
                ..
            } => Self::Settings {
                name,
                value,
                expected,
            },
            other => Self::Phase1(other),
        }
    }
}
