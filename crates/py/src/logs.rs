//! Vehicle logs (`vehicle-interfaces.md` section 4) read whole for analysis: [`read_log`].
//!
//! The log is read with `vehicle_log::read_log` with the GIL released and handed to Python as
//! it was logged: the board's byte stream (every `/fpga/features` chunk concatenated in log
//! order, undecoded), the odometry in log order, the first `/rig` message's text and the
//! simulator's truth. Nothing is sorted, decoded or estimated here; the Python wrapper decodes
//! the stream with `stereonav.StreamDecoder`.
//!
//! A file without the vehicle topics is refused as the replay refuses it, with the replay's
//! message; a file that cannot be opened or read, is not MCAP, or has a malformed vehicle
//! message raises `stereonav.InputError` naming it, with the `OSError` as the cause when the
//! operating system refused the file. A damaged or cut log is not an error: every record that
//! can still be read is here, `damage` says what was lost and where ([`LogDamage`],
//! [`LostSpan`]) and `truncated` says why it ends early.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use numpy::ndarray::Array2;
use numpy::{IntoPyArray, PyArray1, PyArray2};
use pyo3::prelude::*;
use pyo3::types::PyBytes;
use rig_model::Rig;
use vehicle_log::{OdomSample, Record, TruthCamera, TruthLandmark, TruthPose};

use crate::calibration::replay_error;
use crate::input_error;
use crate::rig::PyRig;

/// Timestamps `(K,)` and values `(K, 3)` of a time series.
type TimeSeries<'py> = (Bound<'py, PyArray1<u64>>, Bound<'py, PyArray2<f64>>);

/// Landmark ids `(N,)` and world positions `(N, 3)`.
type Landmarks<'py> = (Bound<'py, PyArray1<u64>>, Bound<'py, PyArray2<f64>>);

/// The contents of a vehicle log, as logged. Arrays are copied out on access.
#[pyclass(module = "stereonav._native", frozen)]
pub(crate) struct LogContents {
    /// The file read.
    path: PathBuf,
    /// Every `/fpga/features` chunk concatenated in log order.
    stream: Vec<u8>,
    /// `/fpga/features` messages.
    chunks: usize,
    /// `/odom` samples in log order.
    odometry: Vec<OdomSample>,
    /// The first `/rig` message's text.
    rig_json: Option<String>,
    /// `/truth/pose` messages in log order.
    truth_poses: Vec<TruthPose>,
    /// The first `/truth/landmarks` message.
    truth_landmarks: Vec<TruthLandmark>,
    /// The first `/truth/camera` message.
    truth_camera: Option<TruthCamera>,
    /// The reader's warnings.
    warnings: Vec<String>,
    /// Why the log ends early, when it does.
    truncated: Option<String>,
    /// Messages on topics that are not vehicle topics.
    ignored_messages: u64,
    /// Those topics, each once, in the order met.
    ignored_topics: Vec<String>,
    /// The vehicle topics with a channel in the log, each once, in the order met.
    topics: Vec<&'static str>,
    /// What could not be read.
    damage: vehicle_log::Damage,
}

/// One stretch of a log that could not be read (`vehicle_log::LostSpan`).
#[pyclass(module = "stereonav._native", frozen)]
#[derive(Clone)]
pub(crate) struct LostSpan(vehicle_log::LostSpan);

#[pymethods]
impl LostSpan {
    /// File offset of the first byte not used.
    #[getter]
    fn offset(&self) -> u64 {
        self.0.offset
    }

    /// Bytes of the file not used.
    #[getter]
    fn bytes(&self) -> u64 {
        self.0.bytes
    }

    /// Log time (ns) of the first message lost, or of the last good one before (see
    /// `exact_times`); None at the start.
    #[getter]
    fn start_ns(&self) -> Option<u64> {
        self.0.start_ns
    }

    /// Log time (ns) of the last message lost, or of the first good one after; None when
    /// nothing good came after.
    #[getter]
    fn end_ns(&self) -> Option<u64> {
        self.0.end_ns
    }

    /// Whether `start_ns..end_ns` is the lost messages' own span (else: the bounds set by
    /// the good messages around the loss).
    #[getter]
    fn exact_times(&self) -> bool {
        self.0.exact_times
    }

    /// Chunk records lost, wholly or in part.
    #[getter]
    fn chunks(&self) -> u64 {
        self.0.chunks
    }

    /// Messages lost per topic, or None when nothing tells.
    #[getter]
    fn messages(&self) -> Option<BTreeMap<String, u64>> {
        self.0.messages.clone()
    }

    /// What was wrong, one line.
    #[getter]
    fn why(&self) -> &str {
        &self.0.why
    }

    fn __repr__(&self) -> String {
        format!(
            "<stereonav.LostSpan at offset {}, {} bytes: {}>",
            self.0.offset, self.0.bytes, self.0.why
        )
    }
}

/// What could not be read in a log, in total (`vehicle_log::Damage`).
#[pyclass(module = "stereonav._native", frozen)]
pub(crate) struct LogDamage(pub(crate) vehicle_log::Damage);

#[pymethods]
impl LogDamage {
    /// Whether anything is damaged (a loss, the magic or header, the summary, the closing
    /// magic, a cut).
    #[getter]
    fn damaged(&self) -> bool {
        !self.0.is_clean()
    }

    /// The first `MAX_KEPT_SPANS` (256) spans lost, in file order.
    #[getter]
    fn spans(&self) -> Vec<LostSpan> {
        self.0.spans.iter().cloned().map(LostSpan).collect()
    }

    /// Spans lost in all.
    #[getter]
    fn spans_total(&self) -> u64 {
        self.0.spans_total
    }

    /// Bytes of the file not used, in all.
    #[getter]
    fn bytes_lost(&self) -> u64 {
        self.0.bytes_lost
    }

    /// Chunk records lost (wholly or in part), in all.
    #[getter]
    fn chunks_lost(&self) -> u64 {
        self.0.chunks_lost
    }

    /// Messages lost per topic (by the summary's statistics, or the spans' counts), or None
    /// when nothing counts them.
    #[getter]
    fn messages_lost(&self) -> Option<BTreeMap<String, u64>> {
        self.0.messages_lost.clone()
    }

    /// The magic or the header record at the start is damaged (the file was read past it).
    #[getter]
    fn header_damaged(&self) -> bool {
        self.0.header_damaged
    }

    /// The closing magic is damaged.
    #[getter]
    fn tail_damaged(&self) -> bool {
        self.0.tail_damaged
    }

    /// The file is cut short.
    #[getter]
    fn cut(&self) -> bool {
        self.0.cut
    }

    /// The summary section: "intact", "damaged" or "absent".
    #[getter]
    fn summary(&self) -> &'static str {
        match self.0.summary {
            vehicle_log::SummaryState::Intact => "intact",
            vehicle_log::SummaryState::Damaged { .. } => "damaged",
            _ => "absent",
        }
    }

    /// Why the summary could not be used, or None.
    #[getter]
    fn summary_problem(&self) -> Option<&str> {
        match &self.0.summary {
            vehicle_log::SummaryState::Damaged { why } => Some(why),
            _ => None,
        }
    }

    /// Chunks read without a CRC check (cut by the end of the file, or without a CRC).
    #[getter]
    fn unverified_chunks(&self) -> u64 {
        self.0.unverified_chunks
    }

    /// Chunks mended: one flipped bit explained their damage, and their CRC checks after it.
    #[getter]
    fn repaired_chunks(&self) -> u64 {
        self.0.repaired_chunks
    }

    fn __repr__(&self) -> String {
        if self.0.is_clean() {
            return "<stereonav.LogDamage: none>".to_owned();
        }
        format!(
            "<stereonav.LogDamage: {} spans, {} bytes, {} chunks lost; summary {}{}>",
            self.0.spans_total,
            self.0.bytes_lost,
            self.0.chunks_lost,
            self.summary(),
            if self.0.cut { ", cut" } else { "" }
        )
    }
}

impl LogContents {
    /// Collects the records of a log read from `path`, in log order.
    fn new(path: PathBuf, log: vehicle_log::Log) -> Self {
        let mut contents = Self {
            path,
            stream: Vec::new(),
            chunks: 0,
            odometry: Vec::new(),
            rig_json: None,
            truth_poses: Vec::new(),
            truth_landmarks: Vec::new(),
            truth_camera: None,
            warnings: log.warnings,
            truncated: log.truncated,
            ignored_messages: log.ignored_messages,
            ignored_topics: log.ignored_topics,
            topics: log.topics,
            damage: log.damage,
        };
        let mut landmarks_seen = false;
        for record in log.records {
            match record {
                Record::Features { bytes, .. } => {
                    contents.stream.extend_from_slice(&bytes);
                    contents.chunks += 1;
                }
                Record::Odom(sample) => contents.odometry.push(sample),
                // The rig and the truth's landmarks and camera are logged once; the first
                // counts, as in the replay.
                Record::Rig(text) if contents.rig_json.is_none() => {
                    contents.rig_json = Some(text);
                }
                Record::TruthPose(pose) => contents.truth_poses.push(pose),
                Record::TruthLandmarks(landmarks) if !landmarks_seen => {
                    landmarks_seen = true;
                    contents.truth_landmarks = landmarks;
                }
                Record::TruthCamera(camera) if contents.truth_camera.is_none() => {
                    contents.truth_camera = Some(camera);
                }
                _ => {}
            }
        }
        contents
    }

    /// The name of the `/rig` message in errors, as the replay names it.
    fn rig_source(&self) -> String {
        format!("{} /rig", self.path.display())
    }
}

/// Reads the vehicle log at `path` whole; refuses a file without the vehicle topics with the
/// replay's error.
fn read_contents(path: &Path) -> Result<LogContents, replay::Error> {
    let log = vehicle_log::read_log(path)?;
    if !log.has_vehicle_topics() {
        return Err(replay::Error::NotVehicleLog {
            path: path.to_path_buf(),
            topics: log.ignored_topics,
        });
    }
    Ok(LogContents::new(path.to_path_buf(), log))
}

/// The ten camera parameters of the simulator's truth, in `Param::CAMERA` order.
fn truth_camera_vector(t: &TruthCamera) -> Vec<f64> {
    let c = replay::truth_camera(t);
    rig_model::Param::CAMERA.iter().map(|&p| c.get(p)).collect()
}

/// Rows of three values as a `(K, 3)` array.
fn rows3<'py, T>(
    py: Python<'py>,
    items: &[T],
    row: impl Fn(&T) -> [f64; 3],
) -> Bound<'py, PyArray2<f64>> {
    Array2::from_shape_fn((items.len(), 3), |(i, k)| row(&items[i])[k]).into_pyarray(py)
}

#[pymethods]
impl LogContents {
    /// The board's byte stream: every `/fpga/features` chunk concatenated in log order.
    #[getter]
    fn stream<'py>(&self, py: Python<'py>) -> Bound<'py, PyBytes> {
        PyBytes::new(py, &self.stream)
    }

    /// Number of `/fpga/features` messages (chunks of the stream).
    #[getter]
    fn chunks(&self) -> usize {
        self.chunks
    }

    /// Odometry as logged, in log order: `(t_us (S,), vx vy vtheta (S, 3))`.
    #[getter]
    fn odometry<'py>(&self, py: Python<'py>) -> TimeSeries<'py> {
        let o = &self.odometry;
        (
            o.iter()
                .map(|s| s.t_us)
                .collect::<Vec<_>>()
                .into_pyarray(py),
            rows3(py, o, |s| [s.vx, s.vy, s.vtheta]),
        )
    }

    /// The first `/rig` message's text (a JSON object), or None.
    #[getter]
    fn rig_json(&self) -> Option<&str> {
        self.rig_json.as_deref()
    }

    /// The first `/rig` message as a rig, or None when the log has none. Raises
    /// `stereonav.InputError` naming the key and the problem when it is not a valid rig.
    fn rig(&self, py: Python<'_>) -> PyResult<Option<PyRig>> {
        self.rig_json
            .as_deref()
            .map(|text| {
                Rig::from_json_str(text, &self.rig_source())
                    .map(|rig| PyRig { rig })
                    .map_err(|e| input_error(py, e.to_string()))
            })
            .transpose()
    }

    /// The simulator's poses, in log order: `(t_us (F,), x y theta (F, 3))`; empty without.
    #[getter]
    fn truth_poses<'py>(&self, py: Python<'py>) -> TimeSeries<'py> {
        let p = &self.truth_poses;
        (
            p.iter()
                .map(|s| s.t_us)
                .collect::<Vec<_>>()
                .into_pyarray(py),
            rows3(py, p, |s| [s.x, s.y, s.theta]),
        )
    }

    /// The simulator's landmarks: `(id (N,), x y z (N, 3))`; empty without.
    #[getter]
    fn truth_landmarks<'py>(&self, py: Python<'py>) -> Landmarks<'py> {
        let l = &self.truth_landmarks;
        (
            l.iter()
                .map(|m| u64::from(m.id))
                .collect::<Vec<_>>()
                .into_pyarray(py),
            rows3(py, l, |m| [m.x, m.y, m.z]),
        )
    }

    /// The simulator's camera parameters, 10 values in `CAMERA_PARAMETERS` order, or None.
    #[getter]
    fn truth_camera<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyArray1<f64>>> {
        self.truth_camera
            .as_ref()
            .map(|c| truth_camera_vector(c).into_pyarray(py))
    }

    /// What looked wrong but did not stop the reading, one line each.
    #[getter]
    fn warnings(&self) -> Vec<String> {
        self.warnings.clone()
    }

    /// Why the log ends early (cut short), or None.
    #[getter]
    fn truncated(&self) -> Option<&str> {
        self.truncated.as_deref()
    }

    /// What could not be read.
    #[getter]
    fn damage(&self) -> LogDamage {
        LogDamage(self.damage.clone())
    }

    /// Messages on topics that are not vehicle topics.
    #[getter]
    fn ignored_messages(&self) -> u64 {
        self.ignored_messages
    }

    /// Those topics, each once, in the order met.
    #[getter]
    fn ignored_topics(&self) -> Vec<String> {
        self.ignored_topics.clone()
    }

    /// The vehicle topics with a channel in the log, each once, in the order met.
    #[getter]
    fn topics(&self) -> Vec<&'static str> {
        self.topics.clone()
    }
}

/// Reads the vehicle log (MCAP) at `path` whole, with the GIL released. Raises
/// `stereonav.InputError` for a file that cannot be opened or read (the `OSError` is the
/// `__cause__`), is not MCAP, has a malformed vehicle message, or has no vehicle topics (the
/// replay's message, naming the topics it has).
#[pyfunction]
pub(crate) fn read_log(py: Python<'_>, path: PathBuf) -> PyResult<LogContents> {
    py.detach(|| read_contents(&path))
        .map_err(|e| replay_error(py, &e))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn truth_camera_is_in_parameter_order() {
        let t = TruthCamera {
            f: 1.0,
            cx: 2.0,
            cy: 3.0,
            baseline: 4.0,
            mount_x: 5.0,
            mount_y: 6.0,
            mount_z: 7.0,
            mount_roll: 8.0,
            mount_pitch: 9.0,
            mount_yaw: 10.0,
            odom_scale: 1.0,
            odom_yaw_scale: 1.0,
            odom_yaw_bias: 0.0,
            time_offset: 0.0,
        };
        let names = [
            "f",
            "cx",
            "cy",
            "baseline",
            "mount_x",
            "mount_y",
            "mount_z",
            "mount_roll",
            "mount_pitch",
            "mount_yaw",
        ];
        let values = truth_camera_vector(&t);
        assert_eq!(values.len(), names.len());
        for (param, value) in rig_model::Param::CAMERA.iter().zip(values) {
            let expected = names
                .iter()
                .position(|n| *n == param.name())
                .map(|i| i as f64 + 1.0);
            assert_eq!(Some(value), expected, "{}", param.name());
        }
    }
}
