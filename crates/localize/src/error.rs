//! The localiser's errors: one line each, naming the problem.

use thiserror::Error;

/// What the localiser refuses.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum Error {
    /// The map has no lamps.
    #[error("the map has no landmarks to localise on")]
    EmptyMap,
    /// The map has more lamps than the index holds.
    #[error("the map has {lamps} landmarks, more than the localiser indexes")]
    MapTooLarge {
        /// How many.
        lamps: usize,
    },
    /// A lamp with a non-finite position or covariance, or a negative variance.
    #[error("map landmark {id} has a non-finite position or an invalid covariance")]
    BadLamp {
        /// Its id.
        id: u64,
    },
    /// The map's common error is not a finite symmetric covariance.
    #[error("the map's common error is not a finite symmetric 4x4 covariance")]
    BadCommonError,
    /// A setting out of range.
    #[error("localiser setting {name} = {value} is out of range")]
    Settings {
        /// Which.
        name: &'static str,
        /// Its value.
        value: f64,
    },
    /// A front-end setting out of range.
    #[error(transparent)]
    FrontEnd(#[from] track::SettingsError),
    /// The camera parameters cannot project.
    #[error("the map's camera cannot be used: {0}")]
    Camera(#[from] rig_model::RigError),
    /// A non-finite input.
    #[error("{what} at t = {t_us} us is not finite ({value})")]
    NonFinite {
        /// What.
        what: &'static str,
        /// When.
        t_us: u64,
        /// The value.
        value: f64,
    },
    /// An odometry sample older than the previous one.
    #[error("odometry at t = {t_us} us is older than the previous sample ({last_us} us)")]
    OdometryOutOfOrder {
        /// Its time.
        t_us: u64,
        /// The previous sample's.
        last_us: u64,
    },
    /// A frame older than the previous one.
    #[error("frame at t = {t_us} us is older than the previous frame ({last_us} us)")]
    FrameOutOfOrder {
        /// Its time.
        t_us: u64,
        /// The previous frame's.
        last_us: u64,
    },
}
