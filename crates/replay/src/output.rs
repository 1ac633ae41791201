//! The replay's outputs (vehicle-interfaces.md section 5): `EST.mcap` for a viewer,
//! `SUMMARY.json` and `TRAJ.csv`.
//!
//! `EST.mcap` is JSON throughout: every channel has message encoding `json` and a schema with
//! encoding `jsonschema`. The trajectory and the map use Foxglove's well-known schemas
//! (`foxglove.PoseInFrame`, `foxglove.PosesInFrame`, `foxglove.SceneUpdate`, encoded as
//! Foxglove's JSON encoding: timestamps `{"sec", "nsec"}`, enums as their integer values), so
//! Foxglove's 3D panel draws them; the filter's own quantities use this project's schemas
//! (`stereonav.CameraEstimate`, `stereonav.FrameInfo`, `stereonav.Summary`), which the Plot and
//! Raw Messages panels read. The JSON Schema texts are written here.
//!
//! | topic             | schema                     | messages                                   |
//! |-------------------|----------------------------|--------------------------------------------|
//! | `/est/pose`       | `foxglove.PoseInFrame`     | one per frame                              |
//! | `/est/trajectory` | `foxglove.PosesInFrame`    | the path so far, about once a second       |
//! | `/est/landmarks`  | `foxglove.SceneUpdate`     | one per [`MapSnapshot`]                    |
//! | `/est/camera`     | `stereonav.CameraEstimate` | one per [`CameraSample`]                   |
//! | `/est/frame`      | `stereonav.FrameInfo`      | one per frame                              |
//! | `/est/summary`    | `stereonav.Summary`        | one, at the end ([`summary_json`])         |
//!
//! Log time (and publish time) is the data's `t_us` in nanoseconds; messages are written in
//! data-time order.
//!
//! **Numbers that are not finite.** JSON has no NaN or infinity. A non-finite number in this
//! project's messages and in `SUMMARY.json` is written as `null`, which their schemas allow
//! (`"type": ["number", "null"]`): it should not occur (a parameter that is not estimated has
//! sigma 0, not NaN), and if it does a reader sees it rather than a made-up value. Foxglove's
//! schemas allow no `null`, so a frame whose pose is not finite has no `/est/pose` message and
//! is left out of `/est/trajectory` (its `/est/frame` message still says what it was), a
//! landmark whose position is not finite is left out of `/est/landmarks`, and one whose
//! covariance is not finite has no uncertainty ellipsoid. `TRAJ.csv` prints such numbers as
//! `NaN`, `inf` or `-inf` (Rust's `f64` display, which `str::parse::<f64>` reads back).

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use mcap::records::MessageHeader;
use mcap::{Compression, WriteOptions};
use nalgebra::{Matrix3, Rotation3, UnitQuaternion};
use serde_json::{Value, json};

use crate::{
    CameraSample, Counts, Error, FrameEstimate, LandmarkEstimate, MapSnapshot, ParamEstimate,
    Replay, ReplayEnd, TruthErrors,
};

/// What `EST.mcap` is called in error messages.
const EST_FILE: &str = "EST.mcap";
/// What `SUMMARY.json` is called in error messages.
const SUMMARY_FILE: &str = "SUMMARY.json";
/// What `TRAJ.csv` is called in error messages.
const TRAJ_FILE: &str = "TRAJ.csv";

/// The frame every estimate is expressed in (vehicle-interfaces.md section 1: the robot's frame
/// at the first stereo frame).
const WORLD_FRAME: &str = "world";

/// Data time between two `/est/trajectory` messages, microseconds.
const TRAJECTORY_PERIOD_US: u64 = 1_000_000;

/// Most poses in one `/est/trajectory` message. Past it the path is thinned to every other
/// pose (and from then on only every second, fourth, ... frame is kept), so that a message, and
/// the file, stay bounded on a long log: a path of this many points draws smoothly.
const TRAJECTORY_MAX_POSES: usize = 1000;

/// Diameter of the sphere drawn at a landmark's position, metres.
const LANDMARK_MARKER_M: f64 = 0.08;

/// The uncertainty ellipsoid's half-axes are this many standard deviations.
const ELLIPSOID_SIGMAS: f64 = 3.0;

/// The landmark marker's colour, RGBA in 0..1 (opaque orange).
const MARKER_RGBA: [f64; 4] = [1.0, 0.55, 0.0, 1.0];

/// The uncertainty ellipsoid's colour, RGBA in 0..1 (translucent blue).
const ELLIPSOID_RGBA: [f64; 4] = [0.2, 0.5, 1.0, 0.25];

/// `SceneEntityDeletion.type` ALL: delete every entity of the topic (Foxglove's enum value).
const DELETE_ALL: u32 = 1;

const US_PER_S: u64 = 1_000_000;
const NS_PER_US: u64 = 1000;

/// Largest `t_us` whose Foxglove timestamp fits (`sec` is a `u32`). Its log time in
/// nanoseconds (about 4.3e18) fits 64 bits too.
const MAX_T_US: u64 = (u32::MAX as u64 + 1) * US_PER_S - 1;

/// Writes `EST.mcap` at `path`: the estimates of `replay` for a viewer (see the module docs
/// for the topics), with zstd chunks, CRCs and a summary section ([`EstimatesWriter`] fed in
/// data-time order).
///
/// Errors: the file cannot be created or written ([`Error::Output`]), the MCAP writer refuses
/// a record ([`Error::Mcap`]), or a timestamp is too late for a Foxglove timestamp
/// ([`Error::TimeOutOfRange`], found before the file is created). A file left by an error is
/// incomplete.
pub fn write_estimates(path: &Path, replay: &Replay) -> Result<(), Error> {
    let times = [
        (Topic::Frame, replay.frames.iter().map(|f| f.t_us).max()),
        (Topic::Camera, replay.camera.iter().map(|c| c.t_us).max()),
        (Topic::Landmarks, replay.maps.iter().map(|m| m.t_us).max()),
    ];
    for (topic, latest) in times {
        if let Some(t_us) = latest.filter(|t| *t > MAX_T_US) {
            return Err(time_error(path, topic, t_us));
        }
    }
    let mut items: Vec<(u64, Item)> =
        Vec::with_capacity(replay.frames.len() + replay.camera.len() + replay.maps.len());
    items.extend(
        replay
            .frames
            .iter()
            .enumerate()
            .map(|(i, f)| (f.t_us, Item::Frame(i))),
    );
    items.extend(
        replay
            .camera
            .iter()
            .enumerate()
            .map(|(i, c)| (c.t_us, Item::Camera(i))),
    );
    items.extend(
        replay
            .maps
            .iter()
            .enumerate()
            .map(|(i, m)| (m.t_us, Item::Map(i))),
    );
    items.sort_unstable();
    let mut writer = EstimatesWriter::create(path)?;
    for &(_, item) in &items {
        match item {
            Item::Frame(i) => {
                if let Some(frame) = replay.frames.get(i) {
                    writer.frame(frame)?;
                }
            }
            Item::Camera(i) => {
                if let Some(sample) = replay.camera.get(i) {
                    writer.camera(sample)?;
                }
            }
            Item::Map(i) => {
                if let Some(map) = replay.maps.get(i) {
                    writer.map(map)?;
                }
            }
        }
    }
    writer.finish(&summary_json(replay))
}

/// Writes `SUMMARY.json` at `path`: [`summary_json`], pretty-printed, with a final newline.
///
/// Errors: the file cannot be created or written ([`Error::Output`]).
pub fn write_summary(path: &Path, replay: &Replay) -> Result<(), Error> {
    write_summary_value(path, &summary_json(replay))
}

/// Writes a summary (from [`summary_json`] or [`end_summary_json`]) at `path`,
/// pretty-printed, with a final newline.
///
/// Errors: the file cannot be created or written ([`Error::Output`]).
pub fn write_summary_value(path: &Path, summary: &Value) -> Result<(), Error> {
    let write = || -> std::io::Result<()> {
        let mut w = BufWriter::new(File::create(path)?);
        serde_json::to_writer_pretty(&mut w, summary)?;
        w.write_all(b"\n")?;
        w.flush()
    };
    write().map_err(|source| output_error(SUMMARY_FILE, path, source))
}

/// Writes `TRAJ.csv` at `path`: a header `t_us,x,y,theta` and a row per frame of `replay`, in
/// its order ([`TrajectoryWriter`]).
///
/// Errors: the file cannot be created or written ([`Error::Output`]).
pub fn write_trajectory(path: &Path, replay: &Replay) -> Result<(), Error> {
    let mut w = TrajectoryWriter::create(path)?;
    for frame in &replay.frames {
        w.frame(frame)?;
    }
    w.finish()
}

/// Writes `TRAJ.csv` row by row: a header `t_us,x,y,theta`, then a row per frame. Numbers
/// are printed with Rust's `Display`, which reads back to the same `f64`.
#[derive(Debug)]
pub struct TrajectoryWriter {
    path: PathBuf,
    w: BufWriter<File>,
}

impl TrajectoryWriter {
    /// Creates (or truncates) the file at `path` and writes the header.
    ///
    /// Errors: the file cannot be created or written ([`Error::Output`]).
    pub fn create(path: &Path) -> Result<Self, Error> {
        let mut w = BufWriter::new(
            File::create(path).map_err(|source| output_error(TRAJ_FILE, path, source))?,
        );
        writeln!(w, "t_us,x,y,theta").map_err(|source| output_error(TRAJ_FILE, path, source))?;
        Ok(Self {
            path: path.to_path_buf(),
            w,
        })
    }

    /// A frame's row.
    pub fn frame(&mut self, frame: &FrameEstimate) -> Result<(), Error> {
        let [x, y, theta] = frame.pose;
        writeln!(self.w, "{},{x},{y},{theta}", frame.t_us)
            .map_err(|source| output_error(TRAJ_FILE, &self.path, source))
    }

    /// Flushes the file.
    pub fn finish(mut self) -> Result<(), Error> {
        self.w
            .flush()
            .map_err(|source| output_error(TRAJ_FILE, &self.path, source))
    }
}

/// The replay's output files written as the frames come (a [`crate::ReplaySink`]):
/// `EST.mcap` and `TRAJ.csv` when asked for; [`OutputFiles::finish`] adds the summary.
#[derive(Debug, Default)]
pub struct OutputFiles {
    estimates: Option<EstimatesWriter>,
    trajectory: Option<TrajectoryWriter>,
}

impl OutputFiles {
    /// Creates the files asked for.
    ///
    /// Errors: a file cannot be created ([`Error::Output`], [`Error::Mcap`]).
    pub fn create(estimates: Option<&Path>, trajectory: Option<&Path>) -> Result<Self, Error> {
        Ok(Self {
            estimates: estimates.map(EstimatesWriter::create).transpose()?,
            trajectory: trajectory.map(TrajectoryWriter::create).transpose()?,
        })
    }

    /// Ends the files: `EST.mcap` with its `/est/summary` message, and `SUMMARY.json` at
    /// `summary` when asked for.
    pub fn finish(self, end: &ReplayEnd, summary: Option<&Path>) -> Result<(), Error> {
        let value = end_summary_json(end);
        if let Some(w) = self.estimates {
            w.finish(&value)?;
        }
        if let Some(w) = self.trajectory {
            w.finish()?;
        }
        if let Some(path) = summary {
            write_summary_value(path, &value)?;
        }
        Ok(())
    }
}

impl crate::ReplaySink for OutputFiles {
    fn frame(&mut self, frame: &FrameEstimate) -> Result<(), Error> {
        if let Some(w) = &mut self.estimates {
            w.frame(frame)?;
        }
        if let Some(w) = &mut self.trajectory {
            w.frame(frame)?;
        }
        Ok(())
    }

    fn camera(&mut self, sample: &CameraSample) -> Result<(), Error> {
        match &mut self.estimates {
            Some(w) => w.camera(sample),
            None => Ok(()),
        }
    }

    fn map(&mut self, map: &MapSnapshot) -> Result<(), Error> {
        match &mut self.estimates {
            Some(w) => w.map(map),
            None => Ok(()),
        }
    }
}

/// What the summary is made of, borrowed from a [`Replay`] or a [`ReplayEnd`].
struct SummaryParts<'a> {
    counts: &'a Counts,
    phase_switch_t_us: Option<u64>,
    last_frame: Option<&'a FrameEstimate>,
    final_camera: &'a [ParamEstimate],
    landmarks: &'a [LandmarkEstimate],
    phase1_skipped: bool,
    warnings: &'a [String],
    frames_processed: u64,
    truth: Option<&'a TruthErrors>,
    log_damage: Option<&'a vehicle_log::Damage>,
}

/// The content of `SUMMARY.json`, and of the `/est/summary` message.
///
/// The keys of vehicle-interfaces.md section 5:
///
/// - `frames`, `corrupt`, `lost`: the decoder's counts (good packets, rejected packets, gaps in
///   the frame counter);
/// - `phase_switch_t_us`: when phase 2 started, or `null`;
/// - `pose`: `{t_us, x, y, theta}` at the last frame, or `null` when no frame was processed;
/// - `camera`: `{name: {value, sigma}}` for every parameter of `C` (the final estimate);
/// - `vehicle`: the same for every parameter of `V` (1.2);
/// - `landmarks`: `[{id, x, y, z, sigma: [sx, sy, sz], observations}]`, the final map;
///
/// and also:
///
/// - `phase1_skipped`: phase 2 ran from the rig's nominal values;
/// - `warnings`: one line each;
/// - `counts`: the other counters, by their [`Counts`] names, and `frames_processed` (the
///   frames in the trajectory);
/// - `truth`: `null`, or the errors against the simulator's truth: `landmark_rms_m`,
///   `landmark_rms_aligned_m`, `landmarks_matched`, `landmarks_unmatched`, `lamps_missed`,
///   `match_radius_m`, `ate_rms_m`, `ate_max_m`, `heading_rms_rad`, `camera` and `vehicle`
///   (`{name: estimate - truth}`);
/// - `log_damage`: `null` for a log read whole, or what the reader could not read:
///   `spans_total`, `bytes_lost`, `chunks_lost`, `messages_lost` (`{topic: n}` or `null`),
///   `header_damaged`, `tail_damaged`, `cut`, `summary` (`"intact"`, `"absent"` or
///   `"damaged: why"`), `unverified_chunks`, `repaired_chunks`, and `spans`, the first 100 stretches lost:
///   `{offset, bytes, start_ns, end_ns, exact_times, chunks, messages, why}`.
///
/// Non-finite numbers are `null` (see the module docs).
pub fn summary_json(replay: &Replay) -> Value {
    summary_value(&SummaryParts {
        counts: &replay.counts,
        phase_switch_t_us: replay.phase_switch_t_us,
        last_frame: replay.frames.last(),
        final_camera: &replay.final_camera,
        landmarks: &replay.landmarks,
        phase1_skipped: replay.phase1_skipped,
        warnings: &replay.warnings,
        frames_processed: replay.frames.len() as u64,
        truth: replay.truth.as_ref(),
        log_damage: replay.log_damage.as_ref(),
    })
}

/// [`summary_json`] of a streaming replay's end (the same keys and values as of the
/// [`Replay`] of the same log).
pub fn end_summary_json(end: &ReplayEnd) -> Value {
    summary_value(&SummaryParts {
        counts: &end.counts,
        phase_switch_t_us: end.phase_switch_t_us,
        last_frame: end.last_frame.as_ref(),
        final_camera: &end.final_camera,
        landmarks: &end.landmarks,
        phase1_skipped: end.phase1_skipped,
        warnings: &end.warnings,
        frames_processed: end.frames_processed,
        truth: end.truth.as_ref(),
        log_damage: end.log_damage.as_ref(),
    })
}

fn summary_value(s: &SummaryParts<'_>) -> Value {
    let c = s.counts;
    let pose = s.last_frame.map_or(Value::Null, |f| {
        let [x, y, theta] = f.pose;
        json!({"t_us": f.t_us, "x": x, "y": y, "theta": theta})
    });
    json!({
        "frames": c.frames,
        "corrupt": c.corrupt,
        "lost": c.lost,
        "phase_switch_t_us": s.phase_switch_t_us,
        "pose": pose,
        "camera": params_json(camera_part(s.final_camera)),
        "vehicle": params_json(vehicle_part(s.final_camera)),
        "landmarks": s.landmarks.iter().map(landmark_json).collect::<Vec<_>>(),
        "phase1_skipped": s.phase1_skipped,
        "warnings": s.warnings,
        "counts": counts_json(c, s.frames_processed),
        "truth": s.truth.map_or(Value::Null, truth_json),
        "log_damage": s.log_damage.map_or(Value::Null, damage_json),
    })
}

/// Lost stretches listed in the summary's `log_damage` (the counts hold the totals).
const MAX_SUMMARY_SPANS: usize = 100;

fn damage_json(d: &vehicle_log::Damage) -> Value {
    let summary = match &d.summary {
        vehicle_log::SummaryState::Intact => "intact".to_owned(),
        vehicle_log::SummaryState::Damaged { why } => format!("damaged: {why}"),
        _ => "absent".to_owned(),
    };
    let spans: Vec<Value> = d
        .spans
        .iter()
        .take(MAX_SUMMARY_SPANS)
        .map(|s| {
            json!({
                "offset": s.offset,
                "bytes": s.bytes,
                "start_ns": s.start_ns,
                "end_ns": s.end_ns,
                "exact_times": s.exact_times,
                "chunks": s.chunks,
                "messages": s.messages,
                "why": s.why,
            })
        })
        .collect();
    json!({
        "spans_total": d.spans_total,
        "bytes_lost": d.bytes_lost,
        "chunks_lost": d.chunks_lost,
        "messages_lost": d.messages_lost,
        "header_damaged": d.header_damaged,
        "tail_damaged": d.tail_damaged,
        "cut": d.cut,
        "summary": summary,
        "unverified_chunks": d.unverified_chunks,
        "repaired_chunks": d.repaired_chunks,
        "spans": spans,
    })
}

fn output_error(file: &'static str, path: &Path, source: std::io::Error) -> Error {
    Error::Output {
        file,
        path: path.to_path_buf(),
        source,
    }
}

/// The estimates of `C` only.
fn camera_part(params: &[ParamEstimate]) -> impl Iterator<Item = &ParamEstimate> {
    params.iter().filter(|p| !p.param.is_vehicle())
}

/// The estimates of `V` only.
fn vehicle_part(params: &[ParamEstimate]) -> impl Iterator<Item = &ParamEstimate> {
    params.iter().filter(|p| p.param.is_vehicle())
}

fn params_json<'a>(params: impl Iterator<Item = &'a ParamEstimate>) -> Value {
    Value::Object(
        params
            .map(|p| {
                (
                    p.param.name().to_owned(),
                    json!({"value": p.value, "sigma": p.sigma}),
                )
            })
            .collect(),
    )
}

fn landmark_json(l: &LandmarkEstimate) -> Value {
    let [x, y, z] = l.position;
    json!({
        "id": l.id,
        "x": x,
        "y": y,
        "z": z,
        "sigma": landmark_sigma(l),
        "observations": l.observations,
    })
}

/// Per-axis 1-sigma of a landmark, metres; NaN where the variance is NaN (written `null`),
/// where [`LandmarkEstimate::sigma`] would say 0 (perfectly known).
fn landmark_sigma(l: &LandmarkEstimate) -> [f64; 3] {
    let [[xx, _, _], [_, yy, _], [_, _, zz]] = l.covariance;
    [xx, yy, zz].map(|v| if v.is_nan() { v } else { v.max(0.0).sqrt() })
}

/// The counters the summary does not hold at its top level, and the frames processed.
fn counts_json(c: &Counts, frames_processed: u64) -> Value {
    let mut map = serde_json::Map::new();
    map.insert("frames_processed".to_string(), json!(frames_processed));
    for (name, value) in c.named() {
        if !matches!(name, "frames" | "corrupt" | "lost") {
            map.insert(name.to_string(), json!(value));
        }
    }
    Value::Object(map)
}

fn truth_json(t: &TruthErrors) -> Value {
    let errors = |vehicle: bool| -> serde_json::Map<String, Value> {
        t.camera
            .iter()
            .filter(|(param, _)| param.is_vehicle() == vehicle)
            .map(|(param, error)| (param.name().to_owned(), json!(error)))
            .collect()
    };
    json!({
        "landmark_rms_m": t.landmark_rms,
        "landmark_rms_aligned_m": t.landmark_rms_aligned,
        "landmarks_matched": t.landmarks_matched,
        "landmarks_unmatched": t.landmarks_unmatched,
        "lamps_missed": t.lamps_missed,
        "match_radius_m": t.match_radius,
        "ate_rms_m": t.ate_rms,
        "ate_max_m": t.ate_max,
        "heading_rms_rad": t.heading_rms,
        "camera": errors(false),
        "vehicle": errors(true),
        "consistency": t.consistency.map(|c| json!({
            "pose_nees": c.pose_nees,
            "pose_frames": c.pose_frames,
            "final_pose_nees": c.final_pose_nees,
            "state_nees": c.state_nees,
            "state_dof": c.state_dof,
        })),
    })
}

/// The channels of `EST.mcap`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Topic {
    Pose,
    Trajectory,
    Landmarks,
    Camera,
    Frame,
    Summary,
}

impl Topic {
    fn name(self) -> &'static str {
        match self {
            Self::Pose => "/est/pose",
            Self::Trajectory => "/est/trajectory",
            Self::Landmarks => "/est/landmarks",
            Self::Camera => "/est/camera",
            Self::Frame => "/est/frame",
            Self::Summary => "/est/summary",
        }
    }

    fn schema_name(self) -> &'static str {
        match self {
            Self::Pose => "foxglove.PoseInFrame",
            Self::Trajectory => "foxglove.PosesInFrame",
            Self::Landmarks => "foxglove.SceneUpdate",
            Self::Camera => "stereonav.CameraEstimate",
            Self::Frame => "stereonav.FrameInfo",
            Self::Summary => "stereonav.Summary",
        }
    }

    fn schema(self) -> Value {
        match self {
            Self::Pose => schema::pose_in_frame(),
            Self::Trajectory => schema::poses_in_frame(),
            Self::Landmarks => schema::scene_update(),
            Self::Camera => schema::camera_estimate(),
            Self::Frame => schema::frame_info(),
            Self::Summary => schema::summary(),
        }
    }
}

/// A channel's id and the sequence number of its next message.
#[derive(Debug, Clone, Copy)]
struct Channel {
    id: u16,
    sequence: u32,
}

/// The channels of `EST.mcap`, one field per [`Topic`] (no lookup that could fail).
#[derive(Debug, Clone, Copy)]
struct Channels {
    pose: Channel,
    trajectory: Channel,
    landmarks: Channel,
    camera: Channel,
    frame: Channel,
    summary: Channel,
}

impl Channels {
    fn get_mut(&mut self, topic: Topic) -> &mut Channel {
        match topic {
            Topic::Pose => &mut self.pose,
            Topic::Trajectory => &mut self.trajectory,
            Topic::Landmarks => &mut self.landmarks,
            Topic::Camera => &mut self.camera,
            Topic::Frame => &mut self.frame,
            Topic::Summary => &mut self.summary,
        }
    }
}

/// Something to write, in data-time order: the index of a frame, camera sample or map.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
enum Item {
    // The order of the variants breaks ties of time: a frame, then the camera sample and the
    // map taken after it.
    Frame(usize),
    Camera(usize),
    Map(usize),
}

/// The path drawn on `/est/trajectory`: every `stride`-th frame with a finite pose, at most
/// [`TRAJECTORY_MAX_POSES`] poses.
#[derive(Debug)]
struct Path2d {
    poses: Vec<[f64; 3]>,
    stride: u64,
    seen: u64,
}

impl Path2d {
    fn new() -> Self {
        Self {
            poses: Vec::new(),
            stride: 1,
            seen: 0,
        }
    }

    fn push(&mut self, pose: [f64; 3]) {
        if self.seen.is_multiple_of(self.stride) {
            self.poses.push(pose);
            if self.poses.len() > TRAJECTORY_MAX_POSES {
                let mut keep = false;
                self.poses.retain(|_| {
                    keep = !keep;
                    keep
                });
                self.stride = self.stride.saturating_mul(2);
            }
        }
        self.seen = self.seen.saturating_add(1);
    }

    /// The kept poses as Foxglove poses, then `last` if it was not the last kept.
    fn poses_json(&self, last: [f64; 3]) -> Vec<Value> {
        let kept_last = self.poses.last().is_some_and(|p| *p == last);
        let tail = (!kept_last).then_some(last);
        self.poses
            .iter()
            .copied()
            .chain(tail)
            .map(|[x, y, theta]| planar_pose_json(x, y, theta))
            .collect()
    }
}

/// Writes `EST.mcap` message by message (see the module docs for the topics): call
/// [`Self::frame`], [`Self::camera`] and [`Self::map`] in data-time order (a frame, then the
/// camera sample and the map taken after it), then [`Self::finish`] with the summary. Holds
/// the path drawn on `/est/trajectory` (at most [`TRAJECTORY_MAX_POSES`] poses) and one
/// chunk, whatever the log's length.
pub struct EstimatesWriter {
    path: PathBuf,
    mcap: mcap::Writer<BufWriter<File>>,
    channels: Channels,
    trajectory: Path2d,
    last_trajectory_us: Option<u64>,
    /// The last frame, when its pose was finite and `/est/trajectory` has not drawn it yet.
    undrawn: Option<(u64, [f64; 3])>,
    /// The latest log time written, microseconds.
    latest_us: u64,
}

impl std::fmt::Debug for EstimatesWriter {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("EstimatesWriter")
            .field("path", &self.path)
            .field("channels", &self.channels)
            .finish_non_exhaustive()
    }
}

impl EstimatesWriter {
    /// Creates (or truncates) the file at `path`, writes the magic and header and adds every
    /// channel with its schema, so that a reader finds all six even when some have no message.
    ///
    /// Errors: the file cannot be created or written ([`Error::Output`], [`Error::Mcap`]).
    pub fn create(path: &Path) -> Result<Self, Error> {
        let file = File::create(path).map_err(|source| output_error(EST_FILE, path, source))?;
        let options = WriteOptions::new()
            .compression(Some(Compression::Zstd))
            .chunk_size(Some(vehicle_log::CHUNK_TARGET_BYTES))
            // One thread, as vehicle-log's writer: an output file does not need a zstd worker
            // per CPU.
            .compression_threads(0)
            .library(format!(
                "stereonav replay {} ({})",
                env!("CARGO_PKG_VERSION"),
                mcap::LIBRARY_IDENTIFIER
            ));
        let mut mcap = options
            .create(BufWriter::new(file))
            .map_err(|e| mcap_error(path, e))?;
        let mut add = |topic: Topic| -> Result<Channel, Error> {
            let schema = serde_json::to_vec(&topic.schema())
                .map_err(|e| output_error(EST_FILE, path, e.into()))?;
            let schema_id = mcap
                .add_schema(topic.schema_name(), "jsonschema", &schema)
                .map_err(|e| mcap_error(path, e))?;
            let id = mcap
                .add_channel(schema_id, topic.name(), "json", &Default::default())
                .map_err(|e| mcap_error(path, e))?;
            Ok(Channel { id, sequence: 0 })
        };
        // In this order: channel ids follow the table of the module docs.
        let channels = Channels {
            pose: add(Topic::Pose)?,
            trajectory: add(Topic::Trajectory)?,
            landmarks: add(Topic::Landmarks)?,
            camera: add(Topic::Camera)?,
            frame: add(Topic::Frame)?,
            summary: add(Topic::Summary)?,
        };
        Ok(Self {
            path: path.to_path_buf(),
            mcap,
            channels,
            trajectory: Path2d::new(),
            last_trajectory_us: None,
            undrawn: None,
            latest_us: 0,
        })
    }

    /// A frame: `/est/frame`, and `/est/pose` and (about once a second) `/est/trajectory` when
    /// its pose is finite.
    pub fn frame(&mut self, frame: &FrameEstimate) -> Result<(), Error> {
        self.write(Topic::Frame, frame.t_us, |_| frame_info_json(frame))?;
        self.undrawn = None;
        if !frame.pose.iter().all(|v| v.is_finite()) {
            return Ok(());
        }
        self.write(Topic::Pose, frame.t_us, |stamp| {
            let [x, y, theta] = frame.pose;
            json!({
                "timestamp": stamp,
                "frame_id": WORLD_FRAME,
                "pose": planar_pose_json(x, y, theta),
            })
        })?;
        self.trajectory.push(frame.pose);
        let due = self
            .last_trajectory_us
            .is_none_or(|last| frame.t_us >= last.saturating_add(TRAJECTORY_PERIOD_US));
        if due {
            self.draw_trajectory(frame.t_us, frame.pose)?;
        } else {
            self.undrawn = Some((frame.t_us, frame.pose));
        }
        Ok(())
    }

    /// A camera sample on `/est/camera`.
    pub fn camera(&mut self, sample: &CameraSample) -> Result<(), Error> {
        self.write(Topic::Camera, sample.t_us, |_| camera_json(sample))
    }

    /// A map snapshot on `/est/landmarks`.
    pub fn map(&mut self, map: &MapSnapshot) -> Result<(), Error> {
        self.write(Topic::Landmarks, map.t_us, |stamp| {
            scene_update_json(map, stamp)
        })
    }

    /// The path up to the last frame (when not yet drawn), the summary on `/est/summary` at
    /// the latest time written, the last chunk, the summary section and the footer; flushes.
    pub fn finish(mut self, summary: &Value) -> Result<(), Error> {
        if let Some((t_us, pose)) = self.undrawn.take() {
            self.draw_trajectory(t_us, pose)?;
        }
        let end_us = self.latest_us;
        self.write(Topic::Summary, end_us, |_| summary.clone())?;
        self.mcap.finish().map_err(|e| mcap_error(&self.path, e))?;
        self.mcap
            .into_inner()
            .flush()
            .map_err(|source| output_error(EST_FILE, &self.path, source))
    }

    fn draw_trajectory(&mut self, t_us: u64, pose: [f64; 3]) -> Result<(), Error> {
        let poses = self.trajectory.poses_json(pose);
        self.write(Topic::Trajectory, t_us, |stamp| {
            json!({
                "timestamp": stamp,
                "frame_id": WORLD_FRAME,
                "poses": poses,
            })
        })?;
        self.last_trajectory_us = Some(t_us);
        Ok(())
    }

    /// Writes one message on `topic` at log time `t_us`; `message` is given the Foxglove
    /// timestamp of `t_us`.
    fn write(
        &mut self,
        topic: Topic,
        t_us: u64,
        message: impl FnOnce(Value) -> Value,
    ) -> Result<(), Error> {
        if t_us > MAX_T_US {
            return Err(time_error(&self.path, topic, t_us));
        }
        let stamp = json!({
            "sec": t_us / US_PER_S,
            "nsec": (t_us % US_PER_S) * NS_PER_US,
        });
        let data = serde_json::to_vec(&message(stamp))
            .map_err(|e| output_error(EST_FILE, &self.path, e.into()))?;
        let log_time = t_us * NS_PER_US; // cannot overflow: t_us <= MAX_T_US
        let channel = self.channels.get_mut(topic);
        let header = MessageHeader {
            channel_id: channel.id,
            sequence: channel.sequence,
            log_time,
            publish_time: log_time,
        };
        channel.sequence = channel.sequence.wrapping_add(1);
        self.latest_us = self.latest_us.max(t_us);
        self.mcap
            .write_to_known_channel(&header, &data)
            .map_err(|e| mcap_error(&self.path, e))
    }
}

fn time_error(path: &Path, topic: Topic, t_us: u64) -> Error {
    Error::TimeOutOfRange {
        path: path.to_path_buf(),
        topic: topic.name(),
        t_us,
        max: MAX_T_US,
    }
}

fn mcap_error(path: &Path, error: mcap::McapError) -> Error {
    match error {
        mcap::McapError::Io(source) => output_error(EST_FILE, path, source),
        other => Error::Mcap {
            path: path.to_path_buf(),
            detail: other.to_string(),
        },
    }
}

/// A Foxglove `Pose` for the planar pose `(x, y, theta)`: position `(x, y, 0)`, orientation
/// the rotation by `theta` about z.
fn planar_pose_json(x: f64, y: f64, theta: f64) -> Value {
    let (s, c) = (0.5 * theta).sin_cos();
    json!({
        "position": {"x": x, "y": y, "z": 0.0},
        "orientation": {"x": 0.0, "y": 0.0, "z": s, "w": c},
    })
}

fn vector3_json([x, y, z]: [f64; 3]) -> Value {
    json!({"x": x, "y": y, "z": z})
}

fn color_json([r, g, b, a]: [f64; 4]) -> Value {
    json!({"r": r, "g": g, "b": b, "a": a})
}

fn sphere_json(position: [f64; 3], orientation: [f64; 4], size: [f64; 3], rgba: [f64; 4]) -> Value {
    let [qx, qy, qz, qw] = orientation;
    json!({
        "pose": {
            "position": vector3_json(position),
            "orientation": {"x": qx, "y": qy, "z": qz, "w": qw},
        },
        "size": vector3_json(size),
        "color": color_json(rgba),
    })
}

/// The `ELLIPSOID_SIGMAS`-sigma ellipsoid of a 3x3 covariance: its orientation (quaternion
/// `[x, y, z, w]` whose rotation takes the sphere's axes to the principal axes) and its
/// diameters along them. `None` when the covariance is not finite. Negative eigenvalues (a
/// covariance that lost definiteness to rounding) count as 0.
fn ellipsoid(covariance: &[[f64; 3]; 3]) -> Option<([f64; 4], [f64; 3])> {
    let m = Matrix3::from_row_iterator(covariance.iter().flatten().copied());
    if !m.iter().all(|v| v.is_finite()) {
        return None;
    }
    let eigen = (0.5 * (m + m.transpose())).symmetric_eigen();
    let mut axes = eigen.eigenvectors;
    // A rotation needs a right-handed basis.
    if axes.determinant() < 0.0 {
        axes.column_mut(2).neg_mut();
    }
    let q = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix(&axes));
    let diameter = |lambda: f64| 2.0 * ELLIPSOID_SIGMAS * lambda.max(0.0).sqrt();
    let [l0, l1, l2] = [
        eigen.eigenvalues.x,
        eigen.eigenvalues.y,
        eigen.eigenvalues.z,
    ];
    let size = [diameter(l0), diameter(l1), diameter(l2)];
    let orientation = [q.i, q.j, q.k, q.w];
    (orientation.iter().chain(&size).all(|v| v.is_finite())).then_some((orientation, size))
}

/// The `foxglove.SceneUpdate` of a map snapshot: delete the previous landmarks (some may have
/// left the map), then one entity per landmark with a marker sphere and, when its covariance
/// is finite, the translucent uncertainty ellipsoid.
fn scene_update_json(map: &MapSnapshot, stamp: Value) -> Value {
    let entities: Vec<Value> = map
        .landmarks
        .iter()
        .filter(|l| l.position.iter().all(|v| v.is_finite()))
        .map(|l| {
            let identity = [0.0, 0.0, 0.0, 1.0];
            let mut spheres = vec![sphere_json(
                l.position,
                identity,
                [LANDMARK_MARKER_M; 3],
                MARKER_RGBA,
            )];
            if let Some((orientation, size)) = ellipsoid(&l.covariance) {
                spheres.push(sphere_json(l.position, orientation, size, ELLIPSOID_RGBA));
            }
            let [sx, sy, sz] = landmark_sigma(l);
            json!({
                "timestamp": stamp,
                "frame_id": WORLD_FRAME,
                "id": format!("landmark-{}", l.id),
                "lifetime": {"sec": 0, "nsec": 0},
                "frame_locked": false,
                "metadata": [
                    {"key": "id", "value": l.id.to_string()},
                    {"key": "observations", "value": l.observations.to_string()},
                    {"key": "sigma_m", "value": format!("{sx} {sy} {sz}")},
                ],
                "arrows": [],
                "cubes": [],
                "spheres": spheres,
                "cylinders": [],
                "lines": [],
                "triangles": [],
                "texts": [],
                "models": [],
            })
        })
        .collect();
    json!({
        "deletions": [{"timestamp": stamp, "type": DELETE_ALL, "id": ""}],
        "entities": entities,
    })
}

fn camera_json(sample: &CameraSample) -> Value {
    json!({
        "t_us": sample.t_us,
        "phase": sample.phase.name(),
        "params": params_json(sample.params.iter()),
    })
}

fn frame_info_json(frame: &FrameEstimate) -> Value {
    let [x, y, theta] = frame.pose;
    let nis: Vec<Value> = frame
        .nis
        .iter()
        .map(|(id, nis)| json!({"id": id, "nis": nis}))
        .collect();
    json!({
        "t_us": frame.t_us,
        "phase": frame.phase.name(),
        "pose": {"x": x, "y": y, "theta": theta},
        "pose_covariance": frame.pose_covariance,
        "landmarks": frame.landmarks,
        "observed": frame.observed,
        "nis": nis,
        "rejected": frame.rejected,
    })
}

/// The JSON Schema documents of `EST.mcap`'s channels. Foxglove's are written from its
/// message reference (field names, types, enum values); the viewer recognises them by name.
/// Like Foxglove's, they inline every sub-schema (Foxglove resolves no `$ref`).
mod schema {
    use rig_model::camera::Param;
    use serde_json::{Map, Value, json};

    fn number(description: &str) -> Value {
        json!({"type": "number", "description": description})
    }

    /// A float that is `null` when it was not finite (see the module docs of `output`).
    fn float(description: &str) -> Value {
        json!({"type": ["number", "null"], "description": description})
    }

    fn integer(description: &str) -> Value {
        json!({"type": "integer", "minimum": 0, "description": description})
    }

    fn string(description: &str) -> Value {
        json!({"type": "string", "description": description})
    }

    fn boolean(description: &str) -> Value {
        json!({"type": "boolean", "description": description})
    }

    fn array(items: Value, description: &str) -> Value {
        json!({"type": "array", "items": items, "description": description})
    }

    fn object(title: &str, description: &str, properties: &[(&str, Value)]) -> Value {
        let properties: Map<String, Value> = properties
            .iter()
            .map(|(k, v)| ((*k).to_owned(), v.clone()))
            .collect();
        json!({
            "title": title,
            "description": description,
            "type": "object",
            "properties": properties,
        })
    }

    /// An object of this project's: every property is required, no other is allowed.
    fn strict_object(title: &str, description: &str, properties: &[(&str, Value)]) -> Value {
        let mut o = object(title, description, properties);
        let required: Vec<&str> = properties.iter().map(|(k, _)| *k).collect();
        if let Some(map) = o.as_object_mut() {
            map.insert("required".to_owned(), json!(required));
            map.insert("additionalProperties".to_owned(), json!(false));
        }
        o
    }

    fn time(description: &str) -> Value {
        json!({
            "type": "object",
            "title": "time",
            "description": description,
            "properties": {
                "sec": {"type": "integer", "minimum": 0},
                "nsec": {"type": "integer", "minimum": 0, "maximum": 999_999_999},
            },
        })
    }

    fn duration(description: &str) -> Value {
        json!({
            "type": "object",
            "title": "duration",
            "description": description,
            "properties": {
                "sec": {"type": "integer"},
                "nsec": {"type": "integer", "minimum": 0, "maximum": 999_999_999},
            },
        })
    }

    fn vector3(description: &str) -> Value {
        object(
            "foxglove.Vector3",
            description,
            &[
                ("x", number("x coordinate length")),
                ("y", number("y coordinate length")),
                ("z", number("z coordinate length")),
            ],
        )
    }

    fn point3(description: &str) -> Value {
        object(
            "foxglove.Point3",
            description,
            &[
                ("x", number("x coordinate position")),
                ("y", number("y coordinate position")),
                ("z", number("z coordinate position")),
            ],
        )
    }

    fn quaternion(description: &str) -> Value {
        object(
            "foxglove.Quaternion",
            description,
            &[
                ("x", number("x value")),
                ("y", number("y value")),
                ("z", number("z value")),
                ("w", number("w value")),
            ],
        )
    }

    fn pose(description: &str) -> Value {
        object(
            "foxglove.Pose",
            description,
            &[
                ("position", vector3("Point denoting position in 3D space")),
                (
                    "orientation",
                    quaternion("Quaternion denoting orientation in 3D space"),
                ),
            ],
        )
    }

    fn color(description: &str) -> Value {
        object(
            "foxglove.Color",
            description,
            &[
                ("r", number("Red value between 0 and 1")),
                ("g", number("Green value between 0 and 1")),
                ("b", number("Blue value between 0 and 1")),
                ("a", number("Alpha value between 0 and 1")),
            ],
        )
    }

    fn enumeration(title: &str, description: &str, values: &[(&str, u32)]) -> Value {
        let one_of: Vec<Value> = values
            .iter()
            .map(|(name, value)| json!({"title": name, "const": value}))
            .collect();
        json!({"title": title, "description": description, "oneOf": one_of})
    }

    /// `foxglove.PoseInFrame`.
    pub(super) fn pose_in_frame() -> Value {
        object(
            "foxglove.PoseInFrame",
            "A timestamped pose for an object or reference frame in 3D space",
            &[
                ("timestamp", time("Timestamp of pose")),
                (
                    "frame_id",
                    string("Frame of reference for pose position and orientation"),
                ),
                ("pose", pose("Pose in 3D space")),
            ],
        )
    }

    /// `foxglove.PosesInFrame`.
    pub(super) fn poses_in_frame() -> Value {
        object(
            "foxglove.PosesInFrame",
            "An array of timestamped poses for an object or reference frame in 3D space",
            &[
                ("timestamp", time("Timestamp of pose")),
                (
                    "frame_id",
                    string("Frame of reference for pose position and orientation"),
                ),
                (
                    "poses",
                    array(pose("Pose in 3D space"), "Poses in 3D space"),
                ),
            ],
        )
    }

    fn primitive(title: &str, description: &str, fields: &[(&str, Value)]) -> Value {
        let mut properties = vec![("pose", pose("Position and orientation of the primitive"))];
        properties.extend(fields.iter().cloned());
        object(title, description, &properties)
    }

    fn colors_and_indices() -> [(&'static str, Value); 2] {
        [
            (
                "colors",
                array(
                    color("A color in RGBA format"),
                    "Per-vertex colors (if given, as many as `points`)",
                ),
            ),
            (
                "indices",
                array(
                    json!({"type": "integer", "minimum": 0}),
                    "Indices into `points` and `colors`",
                ),
            ),
        ]
    }

    /// `foxglove.SceneUpdate`, with every primitive of `foxglove.SceneEntity`.
    pub(super) fn scene_update() -> Value {
        let [colors, indices] = colors_and_indices();
        let arrow = primitive(
            "foxglove.ArrowPrimitive",
            "A primitive representing an arrow",
            &[
                ("shaft_length", number("Length of the arrow shaft")),
                ("shaft_diameter", number("Diameter of the arrow shaft")),
                ("head_length", number("Length of the arrow head")),
                ("head_diameter", number("Diameter of the arrow head")),
                ("color", color("Color of the arrow")),
            ],
        );
        let cube = primitive(
            "foxglove.CubePrimitive",
            "A primitive representing a cube or rectangular prism",
            &[
                ("size", vector3("Size of the cube along each axis")),
                ("color", color("Color of the cube")),
            ],
        );
        let sphere = primitive(
            "foxglove.SpherePrimitive",
            "A primitive representing a sphere or ellipsoid",
            &[
                (
                    "size",
                    vector3("Size (diameter) of the sphere along each axis"),
                ),
                ("color", color("Color of the sphere")),
            ],
        );
        let cylinder = primitive(
            "foxglove.CylinderPrimitive",
            "A primitive representing a cylinder, elliptic cylinder, or truncated cone",
            &[
                ("size", vector3("Size of the cylinder's bounding box")),
                (
                    "bottom_scale",
                    number("0-1, ratio of the bottom diameter to size.x/size.y"),
                ),
                (
                    "top_scale",
                    number("0-1, ratio of the top diameter to size.x/size.y"),
                ),
                ("color", color("Color of the cylinder")),
            ],
        );
        let line = primitive(
            "foxglove.LinePrimitive",
            "A primitive representing a series of points connected by lines",
            &[
                (
                    "type",
                    enumeration(
                        "foxglove.LineType",
                        "Drawing primitive to use for lines",
                        &[("LINE_STRIP", 0), ("LINE_LOOP", 1), ("LINE_LIST", 2)],
                    ),
                ),
                ("thickness", number("Width of the line")),
                (
                    "scale_invariant",
                    boolean("Whether `thickness` is in pixels (true) or metres (false)"),
                ),
                (
                    "points",
                    array(point3("A point in 3D space"), "Points along the line"),
                ),
                ("color", color("Solid color of the whole line")),
                colors.clone(),
                indices.clone(),
            ],
        );
        let triangles = primitive(
            "foxglove.TriangleListPrimitive",
            "A primitive representing a set of triangles",
            &[
                (
                    "points",
                    array(
                        point3("A point in 3D space"),
                        "Vertices, taken three at a time",
                    ),
                ),
                ("color", color("Solid color of the whole shape")),
                colors,
                indices,
            ],
        );
        let text = primitive(
            "foxglove.TextPrimitive",
            "A primitive representing a text label",
            &[
                (
                    "billboard",
                    boolean("Whether the text always faces the camera (true)"),
                ),
                (
                    "font_size",
                    number("Font size (height of one line of text)"),
                ),
                (
                    "scale_invariant",
                    boolean("Whether `font_size` is in pixels (true) or metres (false)"),
                ),
                ("color", color("Color of the text")),
                ("text", string("Text")),
            ],
        );
        let model = primitive(
            "foxglove.ModelPrimitive",
            "A primitive representing a 3D model file",
            &[
                ("scale", vector3("Scale factor along each axis")),
                (
                    "color",
                    color("Color of the whole model if `override_color` is true"),
                ),
                (
                    "override_color",
                    boolean("Whether to use `color` instead of the model's materials"),
                ),
                ("url", string("URL of the model file")),
                ("media_type", string("Media type of the embedded model")),
                (
                    "data",
                    json!({"type": "string", "contentEncoding": "base64", "description": "Embedded model"}),
                ),
            ],
        );
        let key_value = object(
            "foxglove.KeyValuePair",
            "A key with its associated value",
            &[("key", string("Key")), ("value", string("Value"))],
        );
        let entity = object(
            "foxglove.SceneEntity",
            "A visual element in a 3D scene, made of primitives sharing a frame of reference",
            &[
                ("timestamp", time("Timestamp of the entity")),
                ("frame_id", string("Frame of reference")),
                (
                    "id",
                    string("Identifier of the entity, unique on its topic"),
                ),
                (
                    "lifetime",
                    duration("Time after `timestamp` at which the entity is removed (0: never)"),
                ),
                (
                    "frame_locked",
                    boolean("Whether the entity follows `frame_id` as it moves (true)"),
                ),
                (
                    "metadata",
                    array(key_value, "Additional key-value metadata"),
                ),
                ("arrows", array(arrow, "Arrow primitives")),
                ("cubes", array(cube, "Cube primitives")),
                ("spheres", array(sphere, "Sphere primitives")),
                ("cylinders", array(cylinder, "Cylinder primitives")),
                ("lines", array(line, "Line primitives")),
                ("triangles", array(triangles, "Triangle list primitives")),
                ("texts", array(text, "Text primitives")),
                ("models", array(model, "Model primitives")),
            ],
        );
        let deletion = object(
            "foxglove.SceneEntityDeletion",
            "Command to remove previously published entities",
            &[
                (
                    "timestamp",
                    time("Only matching entities earlier than this are deleted"),
                ),
                (
                    "type",
                    enumeration(
                        "foxglove.SceneEntityDeletionType",
                        "Type of deletion action to perform",
                        &[("MATCHING_ID", 0), ("ALL", 1)],
                    ),
                ),
                (
                    "id",
                    string("Identifier which must match if `type` is MATCHING_ID"),
                ),
            ],
        );
        object(
            "foxglove.SceneUpdate",
            "An update to the entities displayed in a 3D scene",
            &[
                ("deletions", array(deletion, "Scene entities to delete")),
                (
                    "entities",
                    array(entity, "Scene entities to add or replace"),
                ),
            ],
        )
    }

    /// `{name: {value, sigma}}` for every parameter of `parameters`.
    fn params(description: &str, parameters: &[Param]) -> Value {
        let estimate = strict_object(
            "stereonav.ParamEstimate",
            "One camera parameter's estimate",
            &[
                (
                    "value",
                    float("The value (the nominal one when not estimated)"),
                ),
                ("sigma", float("Its 1-sigma (0 when held fixed)")),
            ],
        );
        let properties: Vec<(&str, Value)> = parameters
            .iter()
            .map(|p| (p.name(), estimate.clone()))
            .collect();
        let title = if parameters.iter().all(|p| p.is_vehicle()) {
            "stereonav.VehicleParams"
        } else {
            "stereonav.CameraParams"
        };
        strict_object(title, description, &properties)
    }

    fn phase() -> Value {
        json!({
            "type": "string",
            "enum": ["calibrating", "navigating"],
            "description": "Phase 1 (self-calibration) or phase 2 (EKF SLAM)",
        })
    }

    fn t_us(description: &str) -> Value {
        integer(description)
    }

    fn schema_uri(mut schema: Value) -> Value {
        if let Some(map) = schema.as_object_mut() {
            map.insert(
                "$schema".to_owned(),
                json!("https://json-schema.org/draft/2020-12/schema"),
            );
        }
        schema
    }

    /// `stereonav.CameraEstimate`.
    pub(super) fn camera_estimate() -> Value {
        schema_uri(strict_object(
            "stereonav.CameraEstimate",
            "The camera parameters after a phase-1 solve or a phase-2 frame",
            &[
                ("t_us", t_us("Timestamp, microseconds")),
                ("phase", phase()),
                ("params", params("Every parameter of C and V", &Param::ALL)),
            ],
        ))
    }

    fn matrix3(description: &str) -> Value {
        let row = json!({"type": "array", "items": {"type": ["number", "null"]}, "minItems": 3, "maxItems": 3});
        json!({
            "type": "array",
            "items": row,
            "minItems": 3,
            "maxItems": 3,
            "description": description,
        })
    }

    /// `stereonav.FrameInfo`.
    pub(super) fn frame_info() -> Value {
        let nis = strict_object(
            "stereonav.Nis",
            "An accepted observation's normalised innovation squared",
            &[
                ("id", integer("The landmark's id")),
                ("nis", float("NIS, 4 degrees of freedom")),
            ],
        );
        schema_uri(strict_object(
            "stereonav.FrameInfo",
            "The filter at one stereo frame",
            &[
                ("t_us", t_us("The frame's timestamp, microseconds")),
                ("phase", phase()),
                (
                    "pose",
                    strict_object(
                        "stereonav.Pose2",
                        "Robot pose in the world frame",
                        &[
                            ("x", float("metres")),
                            ("y", float("metres")),
                            ("theta", float("radians")),
                        ],
                    ),
                ),
                (
                    "pose_covariance",
                    matrix3("Covariance of (x, y, theta), row-major"),
                ),
                ("landmarks", integer("Landmarks in the map after the frame")),
                (
                    "observed",
                    array(integer("A landmark id"), "Landmarks updated at this frame"),
                ),
                ("nis", array(nis, "NIS of each accepted observation")),
                ("rejected", integer("Observations rejected by the gate")),
            ],
        ))
    }

    /// `stereonav.Summary` (vehicle-interfaces.md section 5, and `SUMMARY.json`).
    pub(super) fn summary() -> Value {
        let pose = strict_object(
            "stereonav.FinalPose",
            "The pose at the last frame",
            &[
                ("t_us", t_us("microseconds")),
                ("x", float("metres")),
                ("y", float("metres")),
                ("theta", float("radians")),
            ],
        );
        let landmark = strict_object(
            "stereonav.Landmark",
            "A landmark of the final map",
            &[
                ("id", integer("Stable id")),
                ("x", float("metres")),
                ("y", float("metres")),
                ("z", float("metres")),
                (
                    "sigma",
                    json!({"type": "array", "items": {"type": ["number", "null"]}, "minItems": 3, "maxItems": 3, "description": "1-sigma along x, y, z, metres"}),
                ),
                ("observations", integer("Updates it took part in")),
            ],
        );
        let counts = strict_object(
            "stereonav.Counts",
            "The other counters",
            &[
                ("frames_processed", integer("Frames in the trajectory")),
                (
                    "bytes_skipped",
                    integer("Stream bytes outside good packets"),
                ),
                (
                    "frames_out_of_order",
                    integer("Frames earlier than the one before"),
                ),
                ("odometry", integer("Odometry samples")),
                (
                    "stereo_matches",
                    integer("Left-right matches over all frames"),
                ),
                ("tracks", integer("Tracks started")),
                ("confirmed_tracks", integer("Tracks confirmed")),
                ("pairs", integer("Phase-1 frame pairs")),
                ("landmark_pairs", integer("Landmark pairs in them")),
                (
                    "tracker_resets",
                    integer("Frames where every track was restarted"),
                ),
                (
                    "phase1_solves",
                    integer("Solves of phase 1's batch over every frame"),
                ),
                (
                    "log_spans_lost",
                    integer("Stretches of the log file lost to damage"),
                ),
                ("log_bytes_lost", integer("Bytes of the log file in them")),
                ("log_chunks_lost", integer("Chunk records lost in them")),
                (
                    "log_time_lost_ms",
                    integer("Log time they covered, milliseconds"),
                ),
            ],
        );
        let counts_by_topic = json!({
            "oneOf": [
                {"type": "null"},
                {"type": "object", "additionalProperties": {"type": "integer", "minimum": 0}},
            ],
            "description": "Messages by topic, when known",
        });
        let nullable_integer = |description: &str| json!({"type": ["integer", "null"], "minimum": 0, "description": description});
        let span = strict_object(
            "stereonav.LostSpan",
            "A stretch of the log that could not be read",
            &[
                ("offset", integer("File offset of its first byte")),
                ("bytes", integer("Bytes not used")),
                (
                    "start_ns",
                    nullable_integer(
                        "Log time of the first message lost, or the last good one before",
                    ),
                ),
                (
                    "end_ns",
                    nullable_integer(
                        "Log time of the last message lost, or the first good one after",
                    ),
                ),
                (
                    "exact_times",
                    boolean("The times are the lost messages' own, not bounds"),
                ),
                ("chunks", integer("Chunk records lost")),
                ("messages", counts_by_topic.clone()),
                ("why", string("What was wrong, one line")),
            ],
        );
        let damage = strict_object(
            "stereonav.LogDamage",
            "What the reader could not read in the log",
            &[
                ("spans_total", integer("Stretches lost")),
                ("bytes_lost", integer("Bytes lost")),
                ("chunks_lost", integer("Chunk records lost")),
                ("messages_lost", counts_by_topic),
                (
                    "header_damaged",
                    boolean("The magic or header record is damaged"),
                ),
                ("tail_damaged", boolean("The closing magic is damaged")),
                ("cut", boolean("The file is cut short")),
                (
                    "summary",
                    string("The summary section: intact, absent or damaged: why"),
                ),
                (
                    "unverified_chunks",
                    integer("Chunks used without a CRC check"),
                ),
                (
                    "repaired_chunks",
                    integer("Chunks mended: one flipped bit, their CRC checks after it"),
                ),
                ("spans", array(span, "The first 100 stretches lost")),
            ],
        );
        let camera_errors: Vec<(&str, Value)> = Param::CAMERA
            .iter()
            .map(|p| (p.name(), float("estimate minus truth")))
            .collect();
        let vehicle_errors: Vec<(&str, Value)> = Param::VEHICLE
            .iter()
            .map(|p| (p.name(), float("estimate minus truth")))
            .collect();
        let truth = strict_object(
            "stereonav.TruthErrors",
            "Errors against the simulator's truth",
            &[
                (
                    "landmark_rms_m",
                    float("RMS landmark position error, metres"),
                ),
                (
                    "landmark_rms_aligned_m",
                    float("The same after the best planar rigid alignment, metres"),
                ),
                ("landmarks_matched", integer("Landmarks matched to a lamp")),
                (
                    "landmarks_unmatched",
                    integer("Landmarks matched to no lamp"),
                ),
                (
                    "lamps_missed",
                    integer("Lamps seen with no landmark matched"),
                ),
                (
                    "match_radius_m",
                    float("Landmark-lamp match radius, metres"),
                ),
                ("ate_rms_m", float("RMS absolute trajectory error, metres")),
                ("ate_max_m", float("Largest position error, metres")),
                ("heading_rms_rad", float("RMS heading error, radians")),
                (
                    "camera",
                    object(
                        "stereonav.CameraErrors",
                        "Final camera parameter errors, by name",
                        &camera_errors,
                    ),
                ),
                (
                    "vehicle",
                    object(
                        "stereonav.VehicleErrors",
                        "Final vehicle parameter errors, by name",
                        &vehicle_errors,
                    ),
                ),
                (
                    "consistency",
                    json!({"oneOf": [{"type": "null"}, strict_object(
                        "stereonav.Consistency",
                        "The filter's NEES against the truth (null without a phase 2)",
                        &[
                            ("pose_nees", float("Mean pose NEES over the phase-2 frames (3 dof)")),
                            ("pose_frames", integer("Frames in pose_nees")),
                            ("final_pose_nees", float("Pose NEES at the last such frame")),
                            ("state_nees", float("Full-state NEES at the end")),
                            ("state_dof", integer("Its degrees of freedom")),
                        ],
                    )]}),
                ),
            ],
        );
        let nullable = |schema: Value| json!({"oneOf": [{"type": "null"}, schema]});
        schema_uri(strict_object(
            "stereonav.Summary",
            "A whole log replayed (SUMMARY.json)",
            &[
                ("frames", integer("Good packets (stereo frames) decoded")),
                ("corrupt", integer("Packets rejected by the decoder")),
                ("lost", integer("Frames lost (gaps in the frame counter)")),
                (
                    "phase_switch_t_us",
                    json!({"type": ["integer", "null"], "minimum": 0, "description": "When phase 2 started"}),
                ),
                ("pose", nullable(pose)),
                (
                    "camera",
                    params("The final camera parameters C", &Param::CAMERA),
                ),
                (
                    "vehicle",
                    params("The final vehicle parameters V", &Param::VEHICLE),
                ),
                ("landmarks", array(landmark, "The final map")),
                (
                    "phase1_skipped",
                    boolean("Phase 2 ran from the nominal values"),
                ),
                (
                    "warnings",
                    array(json!({"type": "string"}), "One line each"),
                ),
                ("counts", counts),
                ("truth", nullable(truth)),
                ("log_damage", nullable(damage)),
            ],
        ))
    }
}
