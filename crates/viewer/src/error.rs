//! Why a file could not be viewed or a screenshot written. Every message is one line naming the
//! file and the problem.

use std::path::PathBuf;

/// Errors of [`crate::load`], [`crate::screenshot`] and [`crate::run_window`].
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// The file could not be read as a vehicle log: missing or unreadable, not MCAP, or a
    /// malformed vehicle message (vehicle-log's message names the file and the problem).
    #[error(transparent)]
    Log(#[from] vehicle_log::Error),
    /// The vehicle log could not be replayed (no rig, bad settings; replay's message).
    #[error(transparent)]
    Replay(#[from] replay::Error),
    /// The estimates file could not be read (estimates-log's message).
    #[error(transparent)]
    Estimates(#[from] estimates_log::ReadError),
    /// The saved map could not be read (map-file's message names the file and the problem).
    #[error(transparent)]
    Map(#[from] map_file::Error),
    /// A map was given with a file that is not a vehicle log (an estimates file, say).
    #[error(
        "{} is not a vehicle log (/fpga/features, /odom): only a vehicle log can be localised on the map {}",
        path.display(),
        map.display()
    )]
    MapNeedsVehicleLog {
        /// The file.
        path: PathBuf,
        /// The map given.
        map: PathBuf,
    },
    /// The log's `/rig` message is not a usable rig.
    #[error(transparent)]
    Rig(#[from] rig_model::RigFileError),
    /// An MCAP file that is neither a vehicle log nor an estimates file.
    #[error(
        "{} is neither a vehicle log (/fpga/features, /odom) nor an estimates file of stereonav replay (/est/frame) (its topics: {}){}",
        path.display(),
        if topics.is_empty() { "none".to_string() } else { topics.join(", ") },
        truncated.as_ref().map_or_else(String::new, |why| format!("; it ends early: {why}"))
    )]
    NotViewable {
        /// The file.
        path: PathBuf,
        /// The topics it has.
        topics: Vec<String>,
        /// Why the file ended early, when it did (a file cut before its channels).
        truncated: Option<String>,
    },
    /// A screenshot size outside the accepted range.
    #[error(
        "screenshot size {width}x{height}: it must be at least {min_width}x{min_height} and at most {max} pixels a side"
    )]
    BadSize {
        /// Width asked for, pixels.
        width: u32,
        /// Height asked for, pixels.
        height: u32,
        /// Smallest width accepted.
        min_width: u32,
        /// Smallest height accepted.
        min_height: u32,
        /// Largest side accepted.
        max: u32,
    },
    /// A time outside the log.
    #[error("time {time_s} s is outside the log, which spans 0 to {end_s:.3} s")]
    TimeOutsideLog {
        /// The time asked for, seconds from the first frame.
        time_s: f64,
        /// The log's last time, seconds from the first frame.
        end_s: f64,
    },
    /// The screenshot could not be written.
    #[error("cannot write the screenshot {}: {source}", path.display())]
    Png {
        /// The path given for it.
        path: PathBuf,
        /// What the encoder or the operating system said.
        #[source]
        source: image::ImageError,
    },
    /// There is no display to open a window on.
    #[error(
        "no display to open the viewer's window on (neither DISPLAY nor WAYLAND_DISPLAY is set): run it on a desktop, under xvfb-run, or take a screenshot with --screenshot OUT.png"
    )]
    NoDisplay,
    /// The window could not be opened (the windowing system's or OpenGL's message).
    #[error("cannot open the viewer's window (DISPLAY={display:?}): {detail}")]
    Window {
        /// The `DISPLAY` variable (empty when unset).
        display: String,
        /// What eframe said.
        detail: String,
    },
}
