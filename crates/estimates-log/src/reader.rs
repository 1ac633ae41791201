//! Reading `EST.mcap` back ([`read_estimates`]): the estimates file that
//! [`crate::write_estimates`] (or an [`crate::EstimatesWriter`]) writes, turned into the
//! [`Replay`] it came from, so that a viewer or a script can look at a replay without running
//! it again.
//!
//! What comes back, from which topic (the layouts are the writer's):
//!
//! - [`Replay::frames`]: one per `/est/frame` message (`stereonav.FrameInfo`), exactly;
//! - [`Replay::camera`]: one per `/est/camera` message (`stereonav.CameraEstimate`), exactly;
//! - [`Replay::maps`]: one per `/est/landmarks` message (`foxglove.SceneUpdate`): the id and
//!   observations from each entity's metadata, the position from its marker sphere, and the
//!   covariance rebuilt from its uncertainty ellipsoid (`R diag((d / 6)^2) R^T` for the
//!   3-sigma diameters `d` along the axes `R`), which is the written covariance to rounding; a
//!   landmark written without an ellipsoid (its covariance was not finite) comes back with a
//!   NaN covariance;
//! - everything else from `/est/summary` (`stereonav.Summary`): the final camera, the phase
//!   switch, whether phase 1 was skipped, the counts, the truth errors and the warnings. The
//!   final map is the last snapshot when it was taken at the last frame (the replay always
//!   takes one there), else the summary's landmarks with a diagonal covariance from their
//!   sigmas.
//!
//! `/est/pose` and `/est/trajectory` repeat what `/est/frame` holds and are not read. `null`
//! numbers (non-finite when written) come back as NaN. A file cut short is read as far as it
//! goes, with a warning in [`Replay::warnings`].

use std::path::Path;

use nalgebra::{Matrix3, UnitQuaternion, Vector3};
use rig_model::camera::Param;
use serde_json::Value;

use crate::error::MCAP_MAGIC;
use crate::topics::{CAMERA, ELLIPSOID_SIGMAS, FRAME, LANDMARKS, NS_PER_US, SUMMARY, US_PER_S};
use crate::{
    Association, CameraSample, Consistency, Counts, FrameEstimate, LandmarkEstimate, MapSnapshot,
    OdometryModel, OdometryWidened, ParamEstimate, Phase, ReadError, Replay, TruthErrors,
};

/// Reads the estimates file `EST.mcap` at `path` (written by [`crate::write_estimates`]) back
/// into a [`Replay`] (see the module docs for what comes back from where).
///
/// Errors: the file cannot be read, is not MCAP, has no `/est/frame` messages, or a message of
/// a topic read is malformed. A file cut short is not an error: what was read is returned,
/// with a warning.
pub fn read_estimates(path: impl AsRef<Path>) -> Result<Replay, ReadError> {
    let path = path.as_ref();
    let bytes = std::fs::read(path).map_err(|source| ReadError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    if !bytes.starts_with(MCAP_MAGIC) {
        return Err(ReadError::NotMcap {
            path: path.to_path_buf(),
            found: bytes.iter().take(MCAP_MAGIC.len()).copied().collect(),
        });
    }
    let stream = mcap::MessageStream::new(&bytes).map_err(|e| ReadError::Mcap {
        path: path.to_path_buf(),
        detail: e.to_string(),
    })?;
    let mut reader = Reader::new(path);
    let mut warnings = Vec::new();
    let mut any = false;
    for message in stream {
        let message = match message {
            Ok(m) => m,
            Err(e) if any => {
                warnings.push(format!(
                    "{} ends early ({e}): read as far as it goes",
                    path.display()
                ));
                break;
            }
            Err(e) => {
                return Err(ReadError::Mcap {
                    path: path.to_path_buf(),
                    detail: e.to_string(),
                });
            }
        };
        any = true;
        reader.message(&message.channel.topic, &message.data)?;
    }
    reader.finish(warnings)
}

/// Collects the messages of an estimates file.
#[derive(Debug)]
struct Reader<'p> {
    path: &'p Path,
    topics: Vec<String>,
    frames: Vec<FrameEstimate>,
    camera: Vec<CameraSample>,
    maps: Vec<MapSnapshot>,
    summary: Option<Value>,
    seen_frame_topic: bool,
}

/// Where a value came from, for error messages.
#[derive(Debug, Clone, Copy)]
struct At<'a> {
    path: &'a Path,
    topic: &'a str,
    index: usize,
}

impl At<'_> {
    fn bad(&self, field: &str, expected: &'static str, found: Option<&Value>) -> ReadError {
        let mut found = found.map_or_else(|| "nothing".to_string(), Value::to_string);
        if found.len() > 60 {
            found = found.chars().take(57).chain("...".chars()).collect();
        }
        ReadError::BadMessage {
            path: self.path.to_path_buf(),
            topic: self.topic.to_string(),
            index: self.index,
            field: field.to_string(),
            expected,
            found,
        }
    }

    /// A number; `null` is NaN (a non-finite number when written).
    fn float(&self, v: &Value, field: &str) -> Result<f64, ReadError> {
        let x = v.get(field);
        match x {
            Some(Value::Null) => Ok(f64::NAN),
            Some(Value::Number(n)) => n
                .as_f64()
                .ok_or_else(|| self.bad(field, "a number or null", x)),
            _ => Err(self.bad(field, "a number or null", x)),
        }
    }

    fn uint(&self, v: &Value, field: &str) -> Result<u64, ReadError> {
        let x = v.get(field);
        x.and_then(Value::as_u64)
            .ok_or_else(|| self.bad(field, "an integer >= 0", x))
    }

    fn array<'v>(&self, v: &'v Value, field: &str) -> Result<&'v Vec<Value>, ReadError> {
        let x = v.get(field);
        x.and_then(Value::as_array)
            .ok_or_else(|| self.bad(field, "an array", x))
    }

    fn phase(&self, v: &Value) -> Result<Phase, ReadError> {
        let x = v.get("phase");
        match x.and_then(Value::as_str) {
            Some("calibrating") => Ok(Phase::Calibrating),
            Some("navigating") => Ok(Phase::Navigating),
            _ => Err(self.bad("phase", "\"calibrating\" or \"navigating\"", x)),
        }
    }

    /// A JSON number or `null` (NaN) in an array.
    fn element(&self, v: &Value, field: &str) -> Result<f64, ReadError> {
        match v {
            Value::Null => Ok(f64::NAN),
            Value::Number(n) => n
                .as_f64()
                .ok_or_else(|| self.bad(field, "a number or null", Some(v))),
            _ => Err(self.bad(field, "a number or null", Some(v))),
        }
    }

    fn matrix3(&self, v: &Value, field: &str) -> Result<[[f64; 3]; 3], ReadError> {
        let rows = self.array(v, field)?;
        let mut m = [[0.0; 3]; 3];
        if rows.len() != 3 {
            return Err(self.bad(field, "3 rows", v.get(field)));
        }
        for (row, out) in rows.iter().zip(&mut m) {
            let cells = row
                .as_array()
                .filter(|c| c.len() == 3)
                .ok_or_else(|| self.bad(field, "rows of 3 numbers", Some(row)))?;
            for (cell, o) in cells.iter().zip(out.iter_mut()) {
                *o = self.element(cell, field)?;
            }
        }
        Ok(m)
    }

    /// `{name: {value, sigma}}` for every parameter of C and V, in [`Param::ALL`] order: V
    /// from `field` or from a `vehicle` object beside it (a summary's), and nominal with
    /// sigma 0 in files written before V existed.
    fn params(&self, v: &Value, field: &str) -> Result<Vec<ParamEstimate>, ReadError> {
        let object = v
            .get(field)
            .filter(|o| o.is_object())
            .ok_or_else(|| self.bad(field, "an object of parameters", v.get(field)))?;
        let vehicle = v.get("vehicle").filter(|o| o.is_object());
        let nominal = rig_model::CameraParams {
            vehicle: rig_model::Vehicle::NOMINAL,
            f: 0.0,
            cx: 0.0,
            cy: 0.0,
            baseline: 0.0,
            mount: rig_model::Mount::default(),
        };
        Param::ALL
            .iter()
            .map(|&param| {
                let found = object
                    .get(param.name())
                    .or_else(|| vehicle.and_then(|o| o.get(param.name())));
                let p = match found {
                    Some(p) => p,
                    None if param.is_vehicle() => {
                        return Ok(ParamEstimate {
                            param,
                            value: nominal.get(param),
                            sigma: 0.0,
                        });
                    }
                    None => return Err(self.bad(param.name(), "{value, sigma}", None)),
                };
                Ok(ParamEstimate {
                    param,
                    value: self.float(p, "value")?,
                    sigma: self.float(p, "sigma")?,
                })
            })
            .collect()
    }

    fn frame(&self, v: &Value) -> Result<FrameEstimate, ReadError> {
        let pose = v
            .get("pose")
            .ok_or_else(|| self.bad("pose", "{x, y, theta}", None))?;
        let observed = self
            .array(v, "observed")?
            .iter()
            .map(|id| {
                id.as_u64()
                    .ok_or_else(|| self.bad("observed", "landmark ids", Some(id)))
            })
            .collect::<Result<Vec<u64>, _>>()?;
        let nis = self
            .array(v, "nis")?
            .iter()
            .map(|n| Ok((self.uint(n, "id")?, self.float(n, "nis")?)))
            .collect::<Result<Vec<(u64, f64)>, _>>()?;
        // Absent in files written before the associations were recorded.
        let associations = match v.get("associations") {
            None => None,
            Some(_) => Some(
                self.array(v, "associations")?
                    .iter()
                    .map(|a| self.association(a))
                    .collect::<Result<Vec<Association>, _>>()?,
            ),
        };
        Ok(FrameEstimate {
            t_us: self.uint(v, "t_us")?,
            phase: self.phase(v)?,
            pose: [
                self.float(pose, "x")?,
                self.float(pose, "y")?,
                self.float(pose, "theta")?,
            ],
            pose_covariance: self.matrix3(v, "pose_covariance")?,
            observed,
            nis,
            rejected: u32::try_from(self.uint(v, "rejected")?).unwrap_or(u32::MAX),
            landmarks: usize::try_from(self.uint(v, "landmarks")?).unwrap_or(usize::MAX),
            associations,
        })
    }

    fn association(&self, a: &Value) -> Result<Association, ReadError> {
        let index = |field: &str| -> Result<usize, ReadError> {
            let i = self.uint(a, field)?;
            usize::try_from(i).map_err(|_| self.bad(field, "a feature index", a.get(field)))
        };
        let accepted = a.get("accepted");
        Ok(Association {
            id: self.uint(a, "id")?,
            left: index("left")?,
            right: index("right")?,
            accepted: accepted
                .and_then(Value::as_bool)
                .ok_or_else(|| self.bad("accepted", "true or false", accepted))?,
        })
    }

    fn camera(&self, v: &Value) -> Result<CameraSample, ReadError> {
        Ok(CameraSample {
            t_us: self.uint(v, "t_us")?,
            phase: self.phase(v)?,
            params: self.params(v, "params")?,
        })
    }

    fn xyz(&self, v: &Value, field: &str) -> Result<[f64; 3], ReadError> {
        let p = v
            .get(field)
            .ok_or_else(|| self.bad(field, "{x, y, z}", None))?;
        Ok([
            self.float(p, "x")?,
            self.float(p, "y")?,
            self.float(p, "z")?,
        ])
    }

    /// A `foxglove.SceneUpdate` of the writer's `scene_update_json` back into a snapshot at `t_us`.
    fn map(&self, v: &Value, t_us: u64) -> Result<MapSnapshot, ReadError> {
        let mut landmarks = Vec::new();
        for entity in self.array(v, "entities")? {
            let metadata = |key: &str| -> Option<u64> {
                entity
                    .get("metadata")?
                    .as_array()?
                    .iter()
                    .find(|kv| kv.get("key").and_then(Value::as_str) == Some(key))?
                    .get("value")?
                    .as_str()?
                    .parse()
                    .ok()
            };
            let id = metadata("id")
                .ok_or_else(|| self.bad("entities[].metadata.id", "a landmark id", None))?;
            let observations = metadata("observations").unwrap_or(0);
            let spheres = self.array(entity, "spheres")?;
            let marker = spheres
                .first()
                .ok_or_else(|| self.bad("entities[].spheres", "a marker sphere", None))?;
            let pose = marker
                .get("pose")
                .ok_or_else(|| self.bad("spheres[].pose", "a pose", None))?;
            let position = self.xyz(pose, "position")?;
            let covariance = match spheres.get(1) {
                Some(ellipsoid) => self.covariance(ellipsoid)?,
                None => [[f64::NAN; 3]; 3],
            };
            landmarks.push(LandmarkEstimate {
                id,
                position,
                covariance,
                observations,
            });
        }
        landmarks.sort_by_key(|l| l.id);
        Ok(MapSnapshot { t_us, landmarks })
    }

    /// The covariance whose 3-sigma ellipsoid the sphere primitive draws.
    fn covariance(&self, sphere: &Value) -> Result<[[f64; 3]; 3], ReadError> {
        let pose = sphere
            .get("pose")
            .ok_or_else(|| self.bad("spheres[].pose", "a pose", None))?;
        let q = pose
            .get("orientation")
            .ok_or_else(|| self.bad("spheres[].pose.orientation", "a quaternion", None))?;
        let [qx, qy, qz] = self.xyz(pose, "orientation")?;
        let qw = self.float(q, "w")?;
        let [dx, dy, dz] = self.xyz(sphere, "size")?;
        let axes = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(qw, qx, qy, qz))
            .to_rotation_matrix()
            .into_inner();
        let variance = |d: f64| (d / (2.0 * ELLIPSOID_SIGMAS)).powi(2);
        let m: Matrix3<f64> = axes
            * Matrix3::from_diagonal(&Vector3::new(variance(dx), variance(dy), variance(dz)))
            * axes.transpose();
        Ok(core::array::from_fn(|r| {
            core::array::from_fn(|c| m.get((r, c)).copied().unwrap_or(f64::NAN))
        }))
    }

    fn counts(&self, summary: &Value) -> Result<Counts, ReadError> {
        let c = summary
            .get("counts")
            .ok_or_else(|| self.bad("counts", "an object of counters", None))?;
        Ok(Counts {
            frames: self.uint(summary, "frames")?,
            corrupt: self.uint(summary, "corrupt")?,
            lost: self.uint(summary, "lost")?,
            bytes_skipped: self.uint(c, "bytes_skipped")?,
            frames_out_of_order: self.uint(c, "frames_out_of_order")?,
            odometry: self.uint(c, "odometry")?,
            stereo_matches: self.uint(c, "stereo_matches")?,
            tracks: self.uint(c, "tracks")?,
            confirmed_tracks: self.uint(c, "confirmed_tracks")?,
            pairs: self.uint(c, "pairs")?,
            landmark_pairs: self.uint(c, "landmark_pairs")?,
            tracker_resets: self.uint(c, "tracker_resets")?,
            // Absent from estimates files written before phase 1 became a batch.
            phase1_solves: self.uint(c, "phase1_solves").unwrap_or(0),
            // Absent from estimates files written before the reader recovered damaged logs.
            log_spans_lost: self.uint(c, "log_spans_lost").unwrap_or(0),
            log_bytes_lost: self.uint(c, "log_bytes_lost").unwrap_or(0),
            log_chunks_lost: self.uint(c, "log_chunks_lost").unwrap_or(0),
            log_time_lost_ms: self.uint(c, "log_time_lost_ms").unwrap_or(0),
            // Absent from estimates files written before the map-level guard (issue 35).
            landmarks_merged: self.uint(c, "landmarks_merged").unwrap_or(0),
            features_outside_field: self.uint(c, "features_outside_field").unwrap_or(0),
            // Absent from estimates files written before loops were closed by constellation.
            loops_closed: self.uint(c, "loops_closed").unwrap_or(0),
            lamps_held_mapped: self.uint(c, "lamps_held_mapped").unwrap_or(0),
            // Absent from estimates files written before the loop closure's gate.
            loops_refused: self.uint(c, "loops_refused").unwrap_or(0),
            // Absent from estimates files written before ROS 2 bags were read.
            images_left: self.uint(c, "images_left").unwrap_or(0),
            images_right: self.uint(c, "images_right").unwrap_or(0),
            images_unpaired: self.uint(c, "images_unpaired").unwrap_or(0),
            images_wrong_size: self.uint(c, "images_wrong_size").unwrap_or(0),
            images_unsupported: self.uint(c, "images_unsupported").unwrap_or(0),
            images_undecodable: self.uint(c, "images_undecodable").unwrap_or(0),
            image_frames_dropped: self.uint(c, "image_frames_dropped").unwrap_or(0),
        })
    }

    /// The summary's `odometry` (`summary_json`'s `odometry_json`).
    fn odometry(&self, o: &Value) -> Result<OdometryModel, ReadError> {
        let pair = |v: &Value, field: &str| -> Result<[f64; 2], ReadError> {
            let a = self.array(v, field)?;
            match a.as_slice() {
                [x, y] => Ok([self.element(x, field)?, self.element(y, field)?]),
                _ => Err(self.bad(field, "an array of two numbers", v.get(field))),
            }
        };
        let widened = match o.get("widened") {
            Some(Value::Null) | None => None,
            Some(w) => Some(OdometryWidened {
                t_us: self.uint(w, "t_us")?,
                span_s: self.float(w, "span_s")?,
                ratios: [
                    self.float(w, "translation_ratio")?,
                    self.float(w, "heading_ratio")?,
                ],
                variance_factors: pair(w, "variance_factors")?,
                time_constants_s: pair(w, "time_constants_s")?,
            }),
        };
        Ok(OdometryModel {
            stated: [
                self.float(o, "velocity")?,
                self.float(o, "yaw_rate")?,
                self.float(o, "velocity_tau")?,
                self.float(o, "yaw_rate_tau")?,
            ],
            used: [
                self.float(o, "used_velocity")?,
                self.float(o, "used_yaw_rate")?,
            ],
            widened,
        })
    }

    fn truth(&self, t: &Value) -> Result<TruthErrors, ReadError> {
        let objects: Vec<&Value> = ["camera", "vehicle"]
            .iter()
            .filter_map(|k| t.get(*k).filter(|c| c.is_object()))
            .collect();
        let camera = Param::ALL
            .iter()
            .filter_map(|&p| {
                let errors = objects.iter().find(|o| o.get(p.name()).is_some())?;
                Some(self.float(errors, p.name()).map(|e| (p, e)))
            })
            .collect::<Result<Vec<_>, ReadError>>()?;
        let count = |field: &str| -> Result<usize, ReadError> {
            Ok(usize::try_from(self.uint(t, field)?).unwrap_or(usize::MAX))
        };
        Ok(TruthErrors {
            landmark_rms: self.float(t, "landmark_rms_m")?,
            landmark_rms_aligned: self.float(t, "landmark_rms_aligned_m")?,
            landmarks_matched: count("landmarks_matched")?,
            landmarks_unmatched: count("landmarks_unmatched")?,
            // Absent from estimates files written before it was reported: none counted then.
            landmarks_duplicate: match t.get("landmarks_duplicate") {
                None => 0,
                Some(_) => count("landmarks_duplicate")?,
            },
            lamps_missed: count("lamps_missed")?,
            match_radius: self.float(t, "match_radius_m")?,
            ate_rms: self.float(t, "ate_rms_m")?,
            ate_max: self.float(t, "ate_max_m")?,
            heading_rms: self.float(t, "heading_rms_rad")?,
            camera,
            // Absent from estimates files written before it was reported.
            consistency: match t.get("consistency") {
                None | Some(Value::Null) => None,
                Some(c) => Some(Consistency {
                    pose_nees: self.float(c, "pose_nees")?,
                    pose_frames: usize::try_from(self.uint(c, "pose_frames")?)
                        .unwrap_or(usize::MAX),
                    final_pose_nees: self.float(c, "final_pose_nees")?,
                    state_nees: self.float(c, "state_nees")?,
                    state_dof: usize::try_from(self.uint(c, "state_dof")?).unwrap_or(usize::MAX),
                }),
            },
        })
    }

    /// The summary's landmarks, with a diagonal covariance from their sigmas.
    fn summary_landmarks(&self, summary: &Value) -> Result<Vec<LandmarkEstimate>, ReadError> {
        self.array(summary, "landmarks")?
            .iter()
            .map(|l| {
                let sigma = self.array(l, "sigma")?;
                let s = |i: usize| -> Result<f64, ReadError> {
                    let v = sigma
                        .get(i)
                        .ok_or_else(|| self.bad("landmarks[].sigma", "3 sigmas", None))?;
                    self.element(v, "landmarks[].sigma")
                };
                let (sx, sy, sz) = (s(0)?, s(1)?, s(2)?);
                Ok(LandmarkEstimate {
                    id: self.uint(l, "id")?,
                    position: [
                        self.float(l, "x")?,
                        self.float(l, "y")?,
                        self.float(l, "z")?,
                    ],
                    covariance: [
                        [sx * sx, 0.0, 0.0],
                        [0.0, sy * sy, 0.0],
                        [0.0, 0.0, sz * sz],
                    ],
                    observations: self.uint(l, "observations")?,
                })
            })
            .collect()
    }
}

impl<'p> Reader<'p> {
    fn new(path: &'p Path) -> Self {
        Self {
            path,
            topics: Vec::new(),
            frames: Vec::new(),
            camera: Vec::new(),
            maps: Vec::new(),
            summary: None,
            seen_frame_topic: false,
        }
    }

    fn at<'a>(&'a self, topic: &'a str, index: usize) -> At<'a> {
        At {
            path: self.path,
            topic,
            index,
        }
    }

    fn parse(&self, topic: &str, index: usize, data: &[u8]) -> Result<Value, ReadError> {
        serde_json::from_slice(data).map_err(|e| ReadError::BadMessage {
            path: self.path.to_path_buf(),
            topic: topic.to_string(),
            index,
            field: "(message)".to_string(),
            expected: "a JSON object",
            found: e.to_string(),
        })
    }

    fn message(&mut self, topic: &str, data: &[u8]) -> Result<(), ReadError> {
        if !self.topics.iter().any(|t| t == topic) {
            self.topics.push(topic.to_string());
        }
        match topic {
            FRAME => {
                self.seen_frame_topic = true;
                let index = self.frames.len();
                let v = self.parse(topic, index, data)?;
                let frame = self.at(topic, index).frame(&v)?;
                self.frames.push(frame);
            }
            CAMERA => {
                let index = self.camera.len();
                let v = self.parse(topic, index, data)?;
                let sample = self.at(topic, index).camera(&v)?;
                self.camera.push(sample);
            }
            LANDMARKS => {
                let index = self.maps.len();
                let v = self.parse(topic, index, data)?;
                let at = self.at(topic, index);
                // The snapshot's time: the entities' timestamp, else the deletion's.
                let stamp = v
                    .get("deletions")
                    .and_then(Value::as_array)
                    .and_then(|d| d.first())
                    .and_then(|d| d.get("timestamp"))
                    .cloned();
                let t_us = match stamp {
                    Some(s) => at.uint(&s, "sec")? * US_PER_S + at.uint(&s, "nsec")? / NS_PER_US,
                    None => return Err(at.bad("deletions[0].timestamp", "a timestamp", None)),
                };
                let map = at.map(&v, t_us)?;
                self.maps.push(map);
            }
            SUMMARY => {
                let v = self.parse(topic, 0, data)?;
                self.summary = Some(v);
            }
            _ => {}
        }
        Ok(())
    }

    fn finish(mut self, mut warnings: Vec<String>) -> Result<Replay, ReadError> {
        if !self.seen_frame_topic {
            return Err(ReadError::NotEstimates {
                path: self.path.to_path_buf(),
                topics: self.topics,
            });
        }
        // Written in data-time order; sorted again so that a reader may binary-search.
        self.frames.sort_by_key(|f| f.t_us);
        self.camera.sort_by_key(|c| c.t_us);
        self.maps.sort_by_key(|m| m.t_us);
        let at = self.at(SUMMARY, 0);
        let last_frame_t = self.frames.last().map(|f| f.t_us);
        let last_map = self
            .maps
            .last()
            .filter(|m| Some(m.t_us) == last_frame_t)
            .map(|m| m.landmarks.clone());
        let Some(summary) = &self.summary else {
            warnings.push(format!(
                "{} has no {SUMMARY} message (cut short?): no counts, final camera from the last sample",
                self.path.display()
            ));
            let final_camera = self
                .camera
                .last()
                .map(|c| c.params.clone())
                .unwrap_or_default();
            let landmarks = self
                .maps
                .last()
                .map(|m| m.landmarks.clone())
                .unwrap_or_default();
            return Ok(Replay {
                phase_switch_t_us: self
                    .camera
                    .iter()
                    .find(|c| c.phase == Phase::Navigating)
                    .filter(|_| {
                        self.camera
                            .first()
                            .is_some_and(|c| c.phase == Phase::Calibrating)
                    })
                    .map(|c| c.t_us),
                frames: self.frames,
                camera: self.camera,
                maps: self.maps,
                landmarks,
                final_camera,
                phase1_skipped: false,
                counts: Counts::default(),
                truth: None,
                warnings,
                log_damage: None,
                odometry: None,
            });
        };
        let landmarks = match last_map {
            Some(l) => l,
            None => at.summary_landmarks(summary)?,
        };
        let phase_switch_t_us = match summary.get("phase_switch_t_us") {
            Some(Value::Null) | None => None,
            Some(_) => Some(at.uint(summary, "phase_switch_t_us")?),
        };
        let truth = match summary.get("truth") {
            Some(Value::Null) | None => None,
            Some(t) => Some(at.truth(t)?),
        };
        // Absent from estimates files written before it was reported.
        let odometry = match summary.get("odometry") {
            Some(Value::Null) | None => None,
            Some(o) => Some(at.odometry(o)?),
        };
        let mut written_warnings: Vec<String> = at
            .array(summary, "warnings")?
            .iter()
            .filter_map(|w| w.as_str().map(str::to_string))
            .collect();
        written_warnings.append(&mut warnings);
        Ok(Replay {
            final_camera: at.params(summary, "camera")?,
            phase1_skipped: summary
                .get("phase1_skipped")
                .and_then(Value::as_bool)
                .unwrap_or(false),
            counts: at.counts(summary)?,
            phase_switch_t_us,
            truth,
            landmarks,
            warnings: written_warnings,
            frames: self.frames,
            camera: self.camera,
            maps: self.maps,
            // The summary's `log_damage` is for readers of the file; its counts and warnings
            // say what was lost.
            log_damage: None,
            odometry,
        })
    }
}
