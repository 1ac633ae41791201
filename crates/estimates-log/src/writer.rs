//! Writing `EST.mcap` ([`write_estimates`], [`EstimatesWriter`]): the messages of every topic
//! of the crate docs, built from the replay's records. The summary message is
//! [`crate::summary_json`]'s.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use mcap::records::MessageHeader;
use mcap::{Compression, WriteOptions};
use nalgebra::{Matrix3, Rotation3, UnitQuaternion};
use serde_json::{Value, json};

use crate::summary::{landmark_sigma, params_json};
use crate::topics::{
    DELETE_ALL, ELLIPSOID_RGBA, ELLIPSOID_SIGMAS, JSON_ENCODING, JSONSCHEMA_ENCODING,
    LANDMARK_MARKER_M, MARKER_RGBA, MAX_T_US, NS_PER_US, TRAJECTORY_MAX_POSES,
    TRAJECTORY_PERIOD_US, Topic, US_PER_S, WORLD_FRAME,
};
use crate::{CameraSample, FrameEstimate, MapSnapshot, Replay, WriteError, summary_json};

/// Writes `EST.mcap` at `path`: the estimates of `replay` for a viewer (see the crate docs
/// for the topics), with zstd chunks, CRCs and a summary section ([`EstimatesWriter`] fed in
/// data-time order).
///
/// Errors: the file cannot be created or written ([`WriteError::Output`]), the MCAP writer
/// refuses a record ([`WriteError::Mcap`]), or a timestamp is too late for a Foxglove
/// timestamp ([`WriteError::TimeOutOfRange`], found before the file is created). A file left
/// by an error is incomplete.
pub fn write_estimates(path: &Path, replay: &Replay) -> Result<(), WriteError> {
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

/// Writes `EST.mcap` message by message (see the crate docs for the topics): call
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
    /// Errors: the file cannot be created or written ([`WriteError::Output`],
    /// [`WriteError::Mcap`]).
    pub fn create(path: &Path) -> Result<Self, WriteError> {
        let file = File::create(path).map_err(|source| WriteError::output(path, source))?;
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
            .map_err(|e| WriteError::mcap(path, e))?;
        let mut add = |topic: Topic| -> Result<Channel, WriteError> {
            let schema = topic
                .schema_bytes()
                .map_err(|e| WriteError::output(path, e.into()))?;
            let schema_id = mcap
                .add_schema(topic.schema_name(), JSONSCHEMA_ENCODING, &schema)
                .map_err(|e| WriteError::mcap(path, e))?;
            let id = mcap
                .add_channel(schema_id, topic.name(), JSON_ENCODING, &Default::default())
                .map_err(|e| WriteError::mcap(path, e))?;
            Ok(Channel { id, sequence: 0 })
        };
        // In this order ([`Topic::ALL`]): channel ids follow the table of the crate docs.
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
    pub fn frame(&mut self, frame: &FrameEstimate) -> Result<(), WriteError> {
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
    pub fn camera(&mut self, sample: &CameraSample) -> Result<(), WriteError> {
        self.write(Topic::Camera, sample.t_us, |_| camera_json(sample))
    }

    /// A map snapshot on `/est/landmarks`.
    pub fn map(&mut self, map: &MapSnapshot) -> Result<(), WriteError> {
        self.write(Topic::Landmarks, map.t_us, |stamp| {
            scene_update_json(map, stamp)
        })
    }

    /// The path up to the last frame (when not yet drawn), the summary on `/est/summary` at
    /// the latest time written, the last chunk, the summary section and the footer; flushes.
    pub fn finish(mut self, summary: &Value) -> Result<(), WriteError> {
        if let Some((t_us, pose)) = self.undrawn.take() {
            self.draw_trajectory(t_us, pose)?;
        }
        let end_us = self.latest_us;
        self.write(Topic::Summary, end_us, |_| summary.clone())?;
        self.mcap
            .finish()
            .map_err(|e| WriteError::mcap(&self.path, e))?;
        self.mcap
            .into_inner()
            .flush()
            .map_err(|source| WriteError::output(&self.path, source))
    }

    fn draw_trajectory(&mut self, t_us: u64, pose: [f64; 3]) -> Result<(), WriteError> {
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
    ) -> Result<(), WriteError> {
        if t_us > MAX_T_US {
            return Err(time_error(&self.path, topic, t_us));
        }
        let stamp = json!({
            "sec": t_us / US_PER_S,
            "nsec": (t_us % US_PER_S) * NS_PER_US,
        });
        let data = serde_json::to_vec(&message(stamp))
            .map_err(|e| WriteError::output(&self.path, e.into()))?;
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
            .map_err(|e| WriteError::mcap(&self.path, e))
    }
}

fn time_error(path: &Path, topic: Topic, t_us: u64) -> WriteError {
    WriteError::TimeOutOfRange {
        path: path.to_path_buf(),
        topic: topic.name(),
        t_us,
        max: MAX_T_US,
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

/// The [`ELLIPSOID_SIGMAS`]-sigma ellipsoid of a 3x3 covariance: its orientation (quaternion
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
    let mut info = json!({
        "t_us": frame.t_us,
        "phase": frame.phase.name(),
        "pose": {"x": x, "y": y, "theta": theta},
        "pose_covariance": frame.pose_covariance,
        "landmarks": frame.landmarks,
        "observed": frame.observed,
        "nis": nis,
        "rejected": frame.rejected,
    });
    // Left out when not recorded: an empty list would say "no association".
    if let (Some(associations), Some(object)) = (&frame.associations, info.as_object_mut()) {
        let list: Vec<Value> = associations
            .iter()
            .map(|a| json!({"id": a.id, "left": a.left, "right": a.right, "accepted": a.accepted}))
            .collect();
        object.insert("associations".to_string(), Value::Array(list));
    }
    info
}
