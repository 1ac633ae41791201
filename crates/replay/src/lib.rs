//! Runs the navigation stack on a vehicle log (vehicle-interfaces.md sections 4 and 5): the
//! whole stack ([`Replayer`], [`replay_log`]) and phase 1 alone in batch ([`calibrate_log`]).
//!
//! The steps, each a crate of its own:
//!
//! 1. **Read** the MCAP log (`vehicle-log`): `/fpga/features` chunks, `/odom` samples and the
//!    optional `/rig`. A log cut short is read as far as it goes, with a warning.
//! 2. **Decode** the board's byte stream (`fpga-link`): the chunks are concatenated in log
//!    order and decoded; corrupt packets and lost frames are counted, never fatal.
//! 3. **Order by data time.** A frame reaches the log tens of milliseconds after the odometry of
//!    the same instant (exposure, read-out, the detector, the link), so log order is not
//!    time order. Frames and odometry are each ordered by their own timestamp (`t_us`, one
//!    clock) and merged, odometry first on a tie, so that every frame sees the odometry up to
//!    its instant.
//! 4. **Navigate** (`nav`): association, phase 1's self-calibration, the switch, phase 2's
//!    EKF SLAM.
//! 5. **Output**: `EST.mcap` (`estimates-log`), `SUMMARY.json`, `TRAJ.csv` ([`OutputFiles`]),
//!    and the trajectory and the truth in the TUM format that evo reads ([`TumWriter`]).
//!
//! **The replay streams.** [`Replayer`] reads the log record by record, orders frames and
//! odometry through a window of [`REORDER_US`] of data time, and hands each frame's estimate to
//! a [`ReplaySink`] once its pose is final (after phase 1's hand-over, or when phase 2's
//! fixed-lag smoother lets the frame go); the errors against the truth and the filter's
//! consistency are accumulated as the frames go by. Its memory is bounded by the map and the
//! windows, not by the log's length: a shift of eight hours replays in the memory of one
//! minute (docs/benchmarks.md, "A whole shift"). [`replay_log`] is the same into a
//! [`ReplayCollector`], for callers that want every estimate in memory (Python, the viewer).
//!
//! [`calibrate_log`] reads the whole log ([`read_vehicle_log`]) and runs the navigator in its
//! calibration-only mode ([`NavMode::CalibrateFramePairs`]): the association with the rig's
//! nominal parameters and priors, the paper's frame pairs calibrated once in batch over the
//! whole log (the result) and fed pair by pair to the incremental calibrator to find when the
//! estimate became stable, the hand-over time at which the vehicle would have switched to
//! phase 2.
//!
//! Errors are one line naming the file and the problem ([`Error`]); nothing here panics on any
//! input.
#![forbid(unsafe_code)]
#![deny(missing_docs)]

mod calibration_json;
mod error;
mod localization;
mod map;
mod navigate;
mod output;
mod stream;
mod tum;

use std::path::{Path, PathBuf};

use fpga_link::Decoder;
use rig_model::camera::ParamVector;
use rig_model::config::Rig;
use rig_model::handover::Handover;
use rig_model::odometry::OdomSample;
use selfcal::solve::{Calibration, SolveStatus};
use track::Pixel;
use vehicle_log::Record;

pub use calibration_json::{calibration_json, is_estimated, solve_status_name};
pub use error::Error;
pub use estimates_log::topics::FRAME as ESTIMATES_FRAME_TOPIC;
pub use estimates_log::{
    Association, CameraSample, Consistency, Counts, EstimatesWriter, FrameEstimate,
    LandmarkEstimate, MapSnapshot, ParamEstimate, Phase, ReadError as EstimatesError, Replay,
    ReplayEnd, TruthErrors, end_summary_json, read_estimates, summary_json,
};
pub use localization::{
    LocalizeEnd, LocalizeTruth, LocalizedFrame, LocalizedTrajectoryWriter, MAX_LAMP_SIGMA_M,
    WEIGHED_SHOWN, WRONG_FIX_M, localize_log, localize_summary_json, localizer_for,
    map_with_new_lamps,
};
pub use localize::reloc::{Generation, Waiting, Weighed};
pub use localize::{LocalizerSettings, RelocSettings};
pub use map::saved_map;
pub use nav::{FramePairSettings, NavMode, NavSettings, Navigator};
pub use navigate::{
    LAMP_MATCH_RADIUS_M, LAMP_SEEN_FRAMES, MAP_SNAPSHOT_US, ReplayCollector, ReplaySink, Replayer,
    replay_log, replay_log_with_topics, truth_camera,
};
pub use output::{
    OutputFiles, TRAJ_TUM_FILE, TRUTH_TUM_FILE, TrajectoryWriter, write_estimates, write_summary,
    write_summary_value, write_trajectory, write_trajectory_tum,
};
pub use stream::{REORDER_US, check_topics};
pub use tum::{TUM_HEADER, TumWriter, tum_line};
pub use vehicle_log::Ros2Topics;

/// Where the rig came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum RigSource {
    /// Given by the caller (a rig file).
    Given,
    /// The log's `/rig` message.
    Log,
}

/// Phase 1 on a whole log.
#[derive(Debug, Clone, PartialEq)]
pub struct LogCalibration {
    /// The rig used: nominal parameters, what is estimated, priors, noise.
    pub rig: Rig,
    /// Where it came from.
    pub rig_source: RigSource,
    /// The batch calibration over every frame pair of the log.
    pub calibration: Calibration,
    /// The incremental calibration's hand-over to phase 2, when it became stable.
    pub handover: Option<Handover>,
    /// `(t_us, parameters, sigmas)` after each incremental solve, up to the hand-over.
    pub history: Vec<(u64, ParamVector, ParamVector)>,
    /// What was read, decoded, associated and paired.
    pub counts: Counts,
    /// Things that did not stop the replay but limit what it says (a truncated log, no
    /// odometry, a solve that did not converge), one line each.
    pub warnings: Vec<String>,
}

/// One decoded stereo frame: the board's features as pixels.
#[derive(Debug, Clone, PartialEq)]
pub struct DecodedFrame {
    /// The packet's timestamp, microseconds.
    pub t_us: u64,
    /// The left camera's features, in the board's order.
    pub left: Vec<Pixel>,
    /// The right camera's features, in the board's order.
    pub right: Vec<Pixel>,
}

/// A vehicle log read, decoded and ordered by data time: what the navigator is fed with.
#[derive(Debug, Clone)]
pub struct LogInput {
    /// The rig (given, or the log's `/rig`).
    pub rig: Rig,
    /// Where the rig came from.
    pub rig_source: RigSource,
    /// Stereo frames sorted by timestamp.
    pub frames: Vec<DecodedFrame>,
    /// Odometry sorted by timestamp.
    pub odometry: Vec<OdomSample>,
    /// What was read and decoded.
    pub counts: Counts,
    /// What limits the input, one line each.
    pub warnings: Vec<String>,
}

/// Steps 1-3 of the crate docs: read, decode, order by data time (`rig`: instead of the
/// log's `/rig`).
pub fn read_vehicle_log(path: &Path, rig: Option<Rig>) -> Result<LogInput, Error> {
    let log = vehicle_log::read_log(path)?;
    if !log.has_vehicle_topics() {
        return Err(Error::NotVehicleLog {
            path: path.to_path_buf(),
            topics: log.ignored_topics.clone(),
        });
    }
    let mut warnings = Vec::new();
    if let Some(why) = &log.truncated {
        warnings.push(format!(
            "the log ends early ({why}): replayed as far as it goes"
        ));
    }
    warnings.extend(log.warnings.iter().cloned());

    let mut chunks: Vec<&[u8]> = Vec::new();
    let mut odometry: Vec<OdomSample> = Vec::new();
    let mut logged_rig: Option<&str> = None;
    for record in &log.records {
        match record {
            Record::Features { bytes, .. } => chunks.push(bytes),
            Record::Odom(s) => odometry.push(OdomSample {
                t_us: s.t_us,
                vx: s.vx,
                vy: s.vy,
                vtheta: s.vtheta,
            }),
            // The first /rig counts (the rig is logged once, at the start).
            Record::Rig(text) if logged_rig.is_none() => logged_rig = Some(text),
            _ => {}
        }
    }
    let lost_before_data = log
        .records
        .iter()
        .take_while(|r| !matches!(r, Record::Features { .. } | Record::Odom(_)))
        .any(|r| matches!(r, Record::Lost(_)))
        || log.damage.header_damaged;
    let (rig, rig_source) = choose_rig(path, rig, logged_rig, lost_before_data, &mut warnings)?;

    let mut counts = Counts {
        log_spans_lost: log.damage.spans_total,
        log_bytes_lost: log.damage.bytes_lost,
        log_chunks_lost: log.damage.chunks_lost,
        log_time_lost_ms: navigate::time_lost_ms(&log.damage),
        ..Counts::default()
    };
    let (mut frames, stats) = decode_stream(&chunks);
    counts.frames = stats.packets;
    counts.corrupt = stats.corrupt;
    counts.lost = stats.lost;
    counts.bytes_skipped = stats.bytes_skipped;
    counts.frames_out_of_order = frames
        .windows(2)
        .filter(|w| matches!(w, [a, b] if b.t_us < a.t_us))
        .count() as u64;
    // Data time, not arrival: both sorts are stable, so equal timestamps keep log order.
    frames.sort_by_key(|f| f.t_us);
    odometry.sort_by_key(|s| s.t_us);
    counts.odometry = odometry.len() as u64;
    if counts.frames == 0 {
        warnings.push("no stereo frame could be decoded from /fpga/features".to_string());
    }
    if counts.odometry == 0 {
        warnings.push("no odometry on /odom: the vehicle's motion is unknown".to_string());
    }
    Ok(LogInput {
        rig,
        rig_source,
        frames,
        odometry,
        counts,
        warnings,
    })
}

/// The board's byte stream, given as the chunks of `/fpga/features` in log order, decoded:
/// the good frames in stream order (not sorted by time) and the decoder's counters. Corrupt
/// packets and garbage are skipped and counted, never fatal.
pub fn decode_stream(chunks: &[&[u8]]) -> (Vec<DecodedFrame>, fpga_link::Stats) {
    let mut decoder = Decoder::new();
    let mut frames = Vec::new();
    for chunk in chunks {
        stream::decode_chunk(&mut decoder, chunk, &mut frames);
    }
    stream::decode_end(&mut decoder, &mut frames);
    (frames, decoder.stats())
}

/// Phase 1 in batch on the vehicle log at `path`.
///
/// `rig` is the rig file's content; without it the log's `/rig` message is used. Errors: the
/// file cannot be read or is not MCAP, it is an MCAP file without the vehicle topics, a
/// vehicle message is malformed, there is no rig, or `settings` are out of range. `settings`
/// are the navigator's, run in its calibration-only mode ([`NavMode::CalibrateFramePairs`]:
/// its association, then [`NavSettings::frame_pairs`]). A log cut
/// short, a stream with corrupt packets, or a log with too little data for a calibration are
/// not errors: the result says so in its counts, warnings and [`Calibration::status`].
pub fn calibrate_log(
    path: impl AsRef<Path>,
    rig: Option<Rig>,
    settings: &NavSettings,
) -> Result<LogCalibration, Error> {
    let path = path.as_ref();
    let input = read_vehicle_log(path, rig)?;
    let LogInput {
        rig,
        rig_source,
        frames,
        odometry,
        mut counts,
        mut warnings,
    } = input;

    // Checked here as well as by the navigator so that a bad pairing stays the replay's own
    // `Error::Settings` (as before the navigator ran it), not a navigator error.
    settings.frame_pairs.pairs.validate()?;
    let mut navigator = Navigator::new(
        rig.clone(),
        NavSettings {
            mode: NavMode::CalibrateFramePairs,
            ..*settings
        },
    )?;
    let mut next_odom = odometry.iter().peekable();
    for frame in &frames {
        while let Some(s) = next_odom.next_if(|s| s.t_us <= frame.t_us) {
            navigator.push_odometry(*s)?;
        }
        navigator.push_frame(frame.t_us, &frame.left, &frame.right)?;
    }
    let front_end = navigator.front_end();
    let tracker = front_end.tracker().stats();
    counts.stereo_matches = front_end.stereo_stats().matches;
    counts.tracks = tracker.started;
    counts.confirmed_tracks = tracker.confirmed;
    counts.tracker_resets = tracker.resets;
    // Never None: the navigator was made in the calibration-only mode.
    let phase1 = navigator.frame_pairs().ok_or(nav::Error::Settings {
        name: "mode",
        value: 0.0,
        expected: "the calibration-only mode",
    })?;
    let pairs = phase1.pairs();
    counts.pairs = pairs.len() as u64;
    counts.landmark_pairs = pairs.iter().map(|p| p.landmarks.len() as u64).sum();

    let calibration = phase1.calibrate();
    add_warnings(&counts, &calibration, &mut warnings);
    Ok(LogCalibration {
        handover: phase1.handover().cloned(),
        history: phase1.history().to_vec(),
        rig,
        rig_source,
        calibration,
        counts,
        warnings,
    })
}

/// The given rig, or else the log's; a warning when both exist and differ.
fn choose_rig(
    path: &Path,
    given: Option<Rig>,
    logged: Option<&str>,
    lost_before_data: bool,
    warnings: &mut Vec<String>,
) -> Result<(Rig, RigSource), Error> {
    let source_name = format!("{} /rig", path.display());
    match (given, logged) {
        (Some(rig), logged) => {
            warnings.extend(logged.and_then(|text| rig_differs(path, &rig, text)));
            Ok((rig, RigSource::Given))
        }
        (None, Some(text)) => Ok((Rig::from_json_str(text, &source_name)?, RigSource::Log)),
        (None, None) => Err(Error::NoRig {
            path: PathBuf::from(path),
            lost_to_damage: lost_before_data,
        }),
    }
}

/// The warning when the rig given differs from the log's `/rig` message (`text`).
pub(crate) fn rig_differs(path: &Path, given: &Rig, text: &str) -> Option<String> {
    let source_name = format!("{} /rig", path.display());
    Rig::from_json_str(text, &source_name)
        .is_ok_and(|logged| logged != *given)
        .then(|| {
            format!(
                "{}: the rig given differs from the log's /rig message; using the one given",
                path.display()
            )
        })
}

fn add_warnings(counts: &Counts, calibration: &Calibration, warnings: &mut Vec<String>) {
    if counts.tracker_resets > 0 {
        warnings.push(format!(
            "the odometry was missing at {} frames: tracks were restarted there",
            counts.tracker_resets
        ));
    }
    match calibration.status {
        SolveStatus::Converged => {}
        SolveStatus::NoData => warnings.push(format!(
            "no usable frame pair ({} pairs): the camera parameters are the nominal ones",
            counts.pairs
        )),
        SolveStatus::MaxIterations => warnings.push(format!(
            "the phase-1 solver stopped at its iteration limit ({} iterations): best estimate returned",
            calibration.iterations
        )),
        SolveStatus::Stalled => warnings.push(
            "the phase-1 solver stalled (no step lowered the cost): best estimate returned"
                .to_string(),
        ),
    }
    for p in calibration.observability.unobservable() {
        warnings.push(format!(
            "{} is held at its nominal value: {}",
            p.param,
            p.reason.unwrap_or("the data do not constrain it")
        ));
    }
}
