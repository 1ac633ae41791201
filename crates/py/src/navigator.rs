//! The whole stack for Python: the navigator of crate `nav` (both phases of the method, the
//! switch, association and map matching) fed frame by frame, and the replay of a vehicle log
//! (crate `replay`) with its outputs `EST.mcap`, `SUMMARY.json` and `TRAJ.csv`
//! (`vehicle-interfaces.md` section 5).
//!
//! Inputs are plain NumPy arrays, checked here:
//!
//! * odometry: `t_us` (S,) uint64 and `vx, vy, vtheta` (S, 3) float64, sorted by time and not
//!   older than the odometry already pushed;
//! * a stereo frame: `t_us` and the left and right features as `(N, 2)` float64 pixels
//!   `u, v` (the board's `x_q4 / 16`, `y_q4 / 16`).
//!
//! Results come back as tuples of arrays that the typed wrappers of
//! `python/stereonav/navigation.py` turn into structured arrays. Per-frame phases are codes
//! into [`PHASES`].
//!
//! A bad value (a shape, a NaN, a timestamp out of order, a setting out of range, a rig file
//! or a log that cannot be used) raises `stereonav.InputError` naming it, and leaves the
//! navigator as it was; a frame whose update the filter refuses (its covariance lost positive
//! definiteness) raises `stereonav.Error`. The replay and every call that steps the navigator
//! run with the GIL released. The navigator lives behind a mutex only because Python classes
//! must be `Sync`, as `filter::Filter` does: mutating calls borrow it exclusively through
//! pyo3 and never lock; readers lock without ever releasing the GIL, so no lock is ever waited
//! on.

use std::path::PathBuf;
use std::sync::{Mutex, MutexGuard, PoisonError};

use numpy::ndarray::{Array2, Array3, ArrayView1, ArrayView2};
use numpy::{IntoPyArray, PyArray1, PyArray2, PyArray3, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;
use replay::{
    CameraSample, FrameEstimate, LandmarkEstimate, NavSettings, ParamEstimate, Phase, Replay,
    ReplayCollector, Replayer,
};
use rig_model::odometry::OdomSample;
use rig_model::{N_CAMERA, Param};
use selfcal::smoother::SmootherSettings;
use track::Pixel;

use crate::calibration::{file_error, replay_error};
use crate::filter::stereonav_error;
use crate::rig::PyRig;
use crate::{FileError, input_error};

/// The phases in the order of their codes in the per-frame arrays (`phase[i]` indexes this).
pub(crate) const PHASES: [Phase; 2] = [Phase::Calibrating, Phase::Navigating];
/// Fields of a `(S, 3)` odometry row, in column order.
const ODOMETRY_FIELDS: [&str; 3] = ["vx", "vy", "vtheta"];
/// Fields of a `(N, 2)` feature row, in column order.
const PIXEL_FIELDS: [&str; 2] = ["u", "v"];

type U64Array<'py> = Bound<'py, PyArray1<u64>>;
type F64Array<'py> = Bound<'py, PyArray1<f64>>;
/// The landmarks handed back: ids (N,), positions (N, 3), covariances (N, 3, 3),
/// observations (N,).
type LandmarkTuple<'py> = (
    U64Array<'py>,
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray3<f64>>,
    U64Array<'py>,
);
/// Every accepted observation of a replay: `t_us` (K,), landmark ids (K,), NIS (K,).
type NisTuple<'py> = (U64Array<'py>, U64Array<'py>, F64Array<'py>);
/// The camera parameters over time: `t_us` (K,), phase codes (K,), values (K, 10), sigmas
/// (K, 10).
type CameraHistoryTuple<'py> = (
    U64Array<'py>,
    Bound<'py, PyArray1<u8>>,
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray2<f64>>,
);
/// Every camera parameter: values (10,) and sigmas (10,), `Param::ALL` order.
type CameraTuple<'py> = (F64Array<'py>, F64Array<'py>);
/// The code of a phase: its index in [`PHASES`].
fn phase_code(phase: Phase) -> u8 {
    match phase {
        Phase::Calibrating => 0,
        Phase::Navigating => 1,
    }
}

fn phase_of(phase: nav::Phase) -> Phase {
    match phase {
        nav::Phase::Calibrating => Phase::Calibrating,
        nav::Phase::Navigating => Phase::Navigating,
    }
}

/// The navigator's settings: the defaults, with phase 1 skipped or not and phase 1's batch
/// holding at most `phase1_frames` frames (default when None), checked.
fn nav_settings(
    skip_phase1: bool,
    phase1_frames: Option<usize>,
    consider_camera: bool,
) -> Result<NavSettings, String> {
    let defaults = NavSettings::default();
    let settings = NavSettings {
        skip_phase1,
        ekf: vslam_ekf::Settings {
            camera_update: if consider_camera {
                vslam_ekf::CameraUpdate::Consider
            } else {
                vslam_ekf::CameraUpdate::Refine
            },
            ..defaults.ekf
        },
        phase1: SmootherSettings {
            max_frames: phase1_frames.unwrap_or(defaults.phase1.max_frames),
            ..defaults.phase1
        },
        ..defaults
    };
    settings.phase1.validate().map_err(|e| e.to_string())?;
    Ok(settings)
}

/// The Python exception for a refusal of the navigator while stepping:
/// `stereonav.InputError` when the caller's value was wrong (not finite, out of time order),
/// `stereonav.Error` when the filter's own numbers refused the frame's update.
fn step_error(py: Python<'_>, err: nav::Error) -> PyErr {
    let message = err.to_string();
    match err {
        nav::Error::NonFinite { .. }
        | nav::Error::OdometryOutOfOrder { .. }
        | nav::Error::FrameOutOfOrder { .. }
        | nav::Error::Settings { .. }
        | nav::Error::Association(_) => input_error(py, message),
        _ => stereonav_error(py, message),
    }
}

/// Values and sigmas of the camera parameters as two `(10,)` arrays in `Param::CAMERA` order
/// (NaN for a parameter missing from `params`, which the replay never leaves out).
fn camera_tuple<'py>(py: Python<'py>, params: &[ParamEstimate]) -> CameraTuple<'py> {
    group_tuple(py, params, &Param::CAMERA)
}

/// Values and sigmas of the vehicle parameters `V` as two `(4,)` arrays in `Param::VEHICLE`
/// order (NaN for a parameter missing from `params`).
fn vehicle_tuple<'py>(py: Python<'py>, params: &[ParamEstimate]) -> CameraTuple<'py> {
    group_tuple(py, params, &Param::VEHICLE)
}

fn group_tuple<'py>(
    py: Python<'py>,
    params: &[ParamEstimate],
    group: &[Param],
) -> CameraTuple<'py> {
    let estimate = |param: Param| params.iter().find(|p| p.param == param);
    let (values, sigmas): (Vec<f64>, Vec<f64>) = group
        .iter()
        .map(|&param| estimate(param).map_or((f64::NAN, f64::NAN), |p| (p.value, p.sigma)))
        .unzip();
    (values.into_pyarray(py), sigmas.into_pyarray(py))
}

fn landmark_tuple<'py>(py: Python<'py>, all: &[LandmarkEstimate]) -> LandmarkTuple<'py> {
    let n = all.len();
    (
        all.iter()
            .map(|l| l.id)
            .collect::<Vec<_>>()
            .into_pyarray(py),
        Array2::from_shape_fn((n, 3), |(i, k)| all[i].position[k]).into_pyarray(py),
        Array3::from_shape_fn((n, 3, 3), |(i, a, b)| all[i].covariance[a][b]).into_pyarray(py),
        all.iter()
            .map(|l| l.observations)
            .collect::<Vec<_>>()
            .into_pyarray(py),
    )
}

/// Every frame of a replay, one row a frame (`replay::FrameEstimate`).
#[pyclass(module = "stereonav._native", frozen, get_all)]
pub(crate) struct ReplayFrames {
    /// `(F,)`: the frame's time.
    t_us: Py<PyArray1<u64>>,
    /// `(F,)`: the phase, an index into `phase_names()`.
    phase: Py<PyArray1<u8>>,
    /// `(F, 3)`: the pose `X, Y, theta` after the frame.
    pose: Py<PyArray2<f64>>,
    /// `(F, 3, 3)`: its covariance.
    pose_covariance: Py<PyArray3<f64>>,
    /// `(F,)`: landmark observations the gate let through.
    accepted: Py<PyArray1<u64>>,
    /// `(F,)`: landmark observations the gate left out.
    rejected: Py<PyArray1<u64>>,
    /// `(F,)`: landmarks in the map after the frame.
    landmarks: Py<PyArray1<u64>>,
}

impl ReplayFrames {
    fn new(py: Python<'_>, frames: &[FrameEstimate]) -> Self {
        let n = frames.len();
        let column = |f: fn(&FrameEstimate) -> u64| {
            frames
                .iter()
                .map(f)
                .collect::<Vec<_>>()
                .into_pyarray(py)
                .unbind()
        };
        Self {
            t_us: column(|f| f.t_us),
            phase: frames
                .iter()
                .map(|f| phase_code(f.phase))
                .collect::<Vec<_>>()
                .into_pyarray(py)
                .unbind(),
            pose: Array2::from_shape_fn((n, 3), |(i, k)| frames[i].pose[k])
                .into_pyarray(py)
                .unbind(),
            pose_covariance: Array3::from_shape_fn((n, 3, 3), |(i, a, b)| {
                frames[i].pose_covariance[a][b]
            })
            .into_pyarray(py)
            .unbind(),
            accepted: column(|f| f.nis.len() as u64),
            rejected: column(|f| u64::from(f.rejected)),
            landmarks: column(|f| f.landmarks as u64),
        }
    }
}

fn nis_tuple<'py>(py: Python<'py>, frames: &[FrameEstimate]) -> NisTuple<'py> {
    let (mut t_us, mut ids, mut nis) = (Vec::new(), Vec::new(), Vec::new());
    for frame in frames {
        for &(id, value) in &frame.nis {
            t_us.push(frame.t_us);
            ids.push(id);
            nis.push(value);
        }
    }
    (
        t_us.into_pyarray(py),
        ids.into_pyarray(py),
        nis.into_pyarray(py),
    )
}

fn camera_history_tuple<'py>(py: Python<'py>, samples: &[CameraSample]) -> CameraHistoryTuple<'py> {
    let k = samples.len();
    let mut values = Array2::from_elem((k, N_CAMERA), f64::NAN);
    let mut sigmas = Array2::from_elem((k, N_CAMERA), f64::NAN);
    for (row, sample) in samples.iter().enumerate() {
        for p in &sample.params {
            if let (Some(v), Some(s)) = (
                values.get_mut((row, p.param.index())),
                sigmas.get_mut((row, p.param.index())),
            ) {
                *v = p.value;
                *s = p.sigma;
            }
        }
    }
    (
        samples
            .iter()
            .map(|s| s.t_us)
            .collect::<Vec<_>>()
            .into_pyarray(py),
        samples
            .iter()
            .map(|s| phase_code(s.phase))
            .collect::<Vec<_>>()
            .into_pyarray(py),
        values.into_pyarray(py),
        sigmas.into_pyarray(py),
    )
}

/// The names of the phases, in the order of the per-frame phase codes.
#[pyfunction]
pub(crate) fn phase_names() -> Vec<&'static str> {
    PHASES.iter().map(|p| p.name()).collect()
}

/// The whole stack on the vehicle log at `log_path` (`replay::replay_log`): read, decode,
/// order by data time, then the navigator frame by frame (phase 1, the switch, phase 2),
/// with the errors against the simulator's truth when the log has it.
///
/// `rig` None uses the log's `/rig` message. `skip_phase1` starts phase 2 at the first frame from the rig's
/// nominal values and priors; `phase1_frames` bounds phase 1's batch (default when None);
/// `consider_camera` keeps phase 2 from refining the camera parameters
/// (`vslam_ekf::CameraUpdate::Consider`). `save_map` writes the map the run built (its
/// landmarks with their covariance, the calibrated C and V, the rig) as `--save-map` does
/// (`replay::saved_map`, docs/maps.md). `left`, `right` and `odom` (all three or none) name
/// a ROS 2 bag's camera and odometry topics, read instead of the board's stream as
/// `--left --right --odom` do (`crate::bags::ros2_topics`). Raises `stereonav.InputError` for
/// a log that cannot be read or is not a vehicle log, topics named badly or missing from the
/// bag, a bad rig, a setting out of range or a map that cannot be written; a log cut short is
/// replayed as far as it goes, with a warning. The GIL is released during the run.
#[pyfunction]
#[pyo3(
    name = "replay",
    signature = (
        log_path, rig, skip_phase1, phase1_frames, consider_camera, save_map,
        left = None, right = None, odom = None
    )
)]
#[allow(clippy::too_many_arguments)] // the Python call's keywords, checked by its wrapper
pub(crate) fn replay_log(
    py: Python<'_>,
    log_path: PathBuf,
    rig: Option<PyRef<'_, PyRig>>,
    skip_phase1: bool,
    phase1_frames: Option<usize>,
    consider_camera: bool,
    save_map: Option<PathBuf>,
    left: Option<String>,
    right: Option<String>,
    odom: Option<String>,
) -> PyResult<ReplayResult> {
    let settings = nav_settings(skip_phase1, phase1_frames, consider_camera)
        .map_err(|e| input_error(py, e.to_string()))?;
    let topics = crate::bags::ros2_topics(left, right, odom).map_err(|e| input_error(py, e))?;
    let rig = rig.map(|r| r.rig.clone());
    // `replay::replay_log_with_topics`, keeping the rig used and the run's end for the saved
    // map.
    let replay = py
        .detach(|| -> Result<Replay, FileError> {
            let replayer = Replayer::open_with_topics(&log_path, topics.as_ref(), rig, &settings)?;
            let rig_used = replayer.rig().clone();
            let mut collected = ReplayCollector::default();
            let end = replayer.run(&mut collected, &mut |_, _| {})?;
            if let Some(path) = &save_map {
                replay::saved_map(&end, &rig_used, &log_path).save(path)?;
            }
            Ok(Replay::from_parts(
                end,
                collected.frames,
                collected.camera,
                collected.maps,
            ))
        })
        .map_err(|e| file_error(py, &*e))?;
    Ok(ReplayResult { replay })
}

/// A whole log replayed (`replay::Replay`). Arrays are copied out on access.
#[pyclass(module = "stereonav._native", frozen)]
pub(crate) struct ReplayResult {
    replay: Replay,
}

#[pymethods]
impl ReplayResult {
    /// The content of `SUMMARY.json` (`replay::summary_json`) as JSON text; non-finite
    /// numbers are `null`.
    fn summary_json(&self) -> String {
        replay::summary_json(&self.replay).to_string()
    }

    /// Every frame, as columns.
    #[getter]
    fn frames(&self, py: Python<'_>) -> ReplayFrames {
        ReplayFrames::new(py, &self.replay.frames)
    }

    /// Every accepted observation: `(t_us (K,), landmark id (K,), NIS (K,))`, in frame order.
    #[getter]
    fn nis<'py>(&self, py: Python<'py>) -> NisTuple<'py> {
        nis_tuple(py, &self.replay.frames)
    }

    /// The camera parameters after every phase-1 solve, then every phase-2 frame:
    /// `(t_us (K,), phase (K,), values (K, 10), sigmas (K, 10))`.
    #[getter]
    fn camera_history<'py>(&self, py: Python<'py>) -> CameraHistoryTuple<'py> {
        camera_history_tuple(py, &self.replay.camera)
    }

    /// The final camera parameters: `(values (10,), sigmas (10,))`.
    #[getter]
    fn camera<'py>(&self, py: Python<'py>) -> CameraTuple<'py> {
        camera_tuple(py, &self.replay.final_camera)
    }

    /// The final vehicle parameters `V`: `(values (4,), sigmas (4,))`, `VEHICLE_PARAMETERS`
    /// order (SUMMARY.json's `vehicle`).
    #[getter]
    fn vehicle<'py>(&self, py: Python<'py>) -> CameraTuple<'py> {
        vehicle_tuple(py, &self.replay.final_camera)
    }

    /// The final map, by id: `(ids (N,), positions (N, 3), covariances (N, 3, 3),
    /// observations (N,))`.
    #[getter]
    fn landmarks<'py>(&self, py: Python<'py>) -> LandmarkTuple<'py> {
        landmark_tuple(py, &self.replay.landmarks)
    }

    /// The map about once a second of data time and at the end: `[(t_us, landmarks), ...]`.
    #[getter]
    fn maps<'py>(&self, py: Python<'py>) -> Vec<(u64, LandmarkTuple<'py>)> {
        self.replay
            .maps
            .iter()
            .map(|m| (m.t_us, landmark_tuple(py, &m.landmarks)))
            .collect()
    }

    /// When phase 2 started, or None (phase 1 never stable, or skipped).
    #[getter]
    fn phase_switch_t_us(&self) -> Option<u64> {
        self.replay.phase_switch_t_us
    }

    /// Phase 1 was skipped.
    #[getter]
    fn phase1_skipped(&self) -> bool {
        self.replay.phase1_skipped
    }

    /// `[(name, count), ...]`: what was read, decoded and associated.
    #[getter]
    fn counts(&self) -> Vec<(&'static str, u64)> {
        self.replay.counts.named().to_vec()
    }

    /// What limits the result without stopping it, one line each.
    #[getter]
    fn warnings(&self) -> Vec<String> {
        self.replay.warnings.clone()
    }

    /// Writes `EST.mcap` (`replay::write_estimates`). Raises `stereonav.InputError` naming
    /// the file when it cannot be written. The GIL is released.
    fn write_estimates(&self, py: Python<'_>, path: PathBuf) -> PyResult<()> {
        let replay = &self.replay;
        py.detach(|| replay::write_estimates(&path, replay))
            .map_err(|e| replay_error(py, &e))
    }

    /// Writes `SUMMARY.json` (`replay::write_summary`). Raises as `write_estimates`.
    fn write_summary(&self, py: Python<'_>, path: PathBuf) -> PyResult<()> {
        let replay = &self.replay;
        py.detach(|| replay::write_summary(&path, replay))
            .map_err(|e| replay_error(py, &e))
    }

    /// Writes `TRAJ.csv` (`replay::write_trajectory`). Raises as `write_estimates`.
    fn write_trajectory(&self, py: Python<'_>, path: PathBuf) -> PyResult<()> {
        let replay = &self.replay;
        py.detach(|| replay::write_trajectory(&path, replay))
            .map_err(|e| replay_error(py, &e))
    }

    /// Writes the trajectory in the TUM format (`replay::write_trajectory_tum`, as
    /// `stereonav replay --trajectory-tum`). Raises as `write_estimates`.
    fn write_trajectory_tum(&self, py: Python<'_>, path: PathBuf) -> PyResult<()> {
        let replay = &self.replay;
        py.detach(|| replay::write_trajectory_tum(&path, replay))
            .map_err(|e| replay_error(py, &e))
    }
}

/// Odometry samples from `t_us` (S,) and `vx, vy, vtheta` (S, 3): finite, sorted by time, and
/// none older than `last_us` (the newest sample already pushed).
fn odometry_samples(
    t_us: &ArrayView1<'_, u64>,
    values: &ArrayView2<'_, f64>,
    last_us: Option<u64>,
) -> Result<Vec<OdomSample>, String> {
    if values.ncols() != ODOMETRY_FIELDS.len() || values.nrows() != t_us.len() {
        return Err(format!(
            "odometry values have shape ({}, {}), expected ({}, 3) = (vx, vy, vtheta)",
            values.nrows(),
            values.ncols(),
            t_us.len()
        ));
    }
    let mut out: Vec<OdomSample> = Vec::with_capacity(t_us.len());
    for (row, (&t, v)) in t_us.iter().zip(values.rows()).enumerate() {
        let mut sample = [0.0; 3];
        for ((slot, &value), field) in sample.iter_mut().zip(v.iter()).zip(ODOMETRY_FIELDS) {
            if !value.is_finite() {
                return Err(format!(
                    "odometry[{row}] {field} is {value}, not a finite number"
                ));
            }
            *slot = value;
        }
        match out.last() {
            Some(previous) if t < previous.t_us => {
                return Err(format!(
                    "odometry[{row}] t_us {t} is before odometry[{}] t_us {}: samples must be \
                     sorted by time",
                    row - 1,
                    previous.t_us
                ));
            }
            None => {
                if let Some(last) = last_us.filter(|&last| t < last) {
                    return Err(format!(
                        "odometry[{row}] t_us {t} is before the last sample pushed (t_us \
                         {last}): feed odometry in time order"
                    ));
                }
            }
            _ => {}
        }
        let [vx, vy, vtheta] = sample;
        out.push(OdomSample {
            t_us: t,
            vx,
            vy,
            vtheta,
        });
    }
    Ok(out)
}

/// The features of one image from `(N, 2)` pixels `u, v`, each finite; `side` names the
/// image (`"left"`, `"right"`) in messages.
fn pixels(side: &str, a: &ArrayView2<'_, f64>) -> Result<Vec<Pixel>, String> {
    if a.ncols() != PIXEL_FIELDS.len() {
        return Err(format!(
            "{side} has shape ({}, {}), expected (N, 2) = (u, v) pixels",
            a.nrows(),
            a.ncols()
        ));
    }
    let mut out = Vec::with_capacity(a.nrows());
    for (row, values) in a.rows().into_iter().enumerate() {
        let mut p = [0.0; 2];
        for ((slot, &v), field) in p.iter_mut().zip(values.iter()).zip(PIXEL_FIELDS) {
            if !v.is_finite() {
                return Err(format!("{side}[{row}] {field} is {v}, not a finite number"));
            }
            *slot = v;
        }
        out.push(Pixel::new(p[0], p[1]));
    }
    Ok(out)
}

/// What one frame of the navigator did (`nav::FrameOutcome`).
#[pyclass(module = "stereonav._native", frozen, get_all)]
pub(crate) struct FrameOutcome {
    /// `(A,)`: landmarks updated at this frame.
    accepted: Py<PyArray1<u64>>,
    /// `(A,)`: their NIS (4 dof).
    accepted_nis: Py<PyArray1<f64>>,
    /// `(R,)`: landmarks whose observation the gate left out.
    rejected: Py<PyArray1<u64>>,
    /// `(K,)`: landmarks added.
    added: Py<PyArray1<u64>>,
    /// `(D,)`: landmarks removed as false.
    removed: Py<PyArray1<u64>>,
    /// `(M, 2)`: `(track, landmark)` pairs bound by map matching.
    rematched: Py<PyArray2<u64>>,
    /// Phase 1 solved at this frame.
    solved: bool,
    /// The switch to phase 2 happened at this frame.
    switched: bool,
    /// The odometry did not reach back to the previous frame: the pose was held.
    no_odometry: bool,
}

impl FrameOutcome {
    fn new(py: Python<'_>, o: &nav::FrameOutcome) -> Self {
        let ids = |ids: &[vslam_ekf::LandmarkId]| {
            ids.iter()
                .map(|id| id.0)
                .collect::<Vec<_>>()
                .into_pyarray(py)
                .unbind()
        };
        Self {
            accepted: o
                .accepted
                .iter()
                .map(|(id, _)| id.0)
                .collect::<Vec<_>>()
                .into_pyarray(py)
                .unbind(),
            accepted_nis: o
                .accepted
                .iter()
                .map(|(_, nis)| *nis)
                .collect::<Vec<_>>()
                .into_pyarray(py)
                .unbind(),
            rejected: ids(&o.rejected),
            added: ids(&o.added),
            removed: ids(&o.removed),
            rematched: Array2::from_shape_fn((o.rematched.len(), 2), |(i, k)| {
                let (track, id) = o.rematched[i];
                if k == 0 { track } else { id.0 }
            })
            .into_pyarray(py)
            .unbind(),
            solved: o.solved,
            switched: o.switched,
            no_odometry: o.no_odometry,
        }
    }
}

/// The navigator and the newest odometry time it took (so that a batch of odometry can be
/// checked whole before any of it is pushed).
#[derive(Debug)]
struct State {
    navigator: nav::Navigator,
    last_odometry_t_us: Option<u64>,
}

/// The two phases of the method in one object (`nav::Navigator`), fed with odometry and the
/// board's stereo frames in time order.
#[pyclass(module = "stereonav._native")]
#[derive(Debug)]
pub(crate) struct Navigator {
    state: Mutex<State>,
}

impl Navigator {
    /// Exclusive access for a mutating call (pyo3's borrow of `&mut self` already made it
    /// exclusive: no locking).
    fn state_mut(&mut self) -> &mut State {
        self.state.get_mut().unwrap_or_else(PoisonError::into_inner)
    }

    /// Shared access for a reader. Readers never release the GIL while holding it, and
    /// writers never lock, so this never waits.
    fn locked(&self) -> MutexGuard<'_, State> {
        self.state.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// Steps the navigator with one frame, the GIL released.
    fn step<'py>(
        &mut self,
        py: Python<'py>,
        t_us: u64,
        left: &[Pixel],
        right: &[Pixel],
    ) -> PyResult<FrameOutcome> {
        let navigator = &mut self.state_mut().navigator;
        let outcome = py
            .detach(|| navigator.push_frame(t_us, left, right))
            .map_err(|e| step_error(py, e))?;
        Ok(FrameOutcome::new(py, &outcome))
    }
}

#[pymethods]
impl Navigator {
    /// A navigator for the rig, at the world origin. `skip_phase1` starts phase 2 at the first frame from the rig's
    /// nominal values and priors; `phase1_frames` bounds phase 1's batch (default when None);
    /// `consider_camera` keeps phase 2 from refining the camera
    /// parameters. Raises `stereonav.InputError` for a bad rig or setting.
    #[new]
    #[pyo3(signature = (rig, skip_phase1, phase1_frames, consider_camera))]
    fn new(
        py: Python<'_>,
        rig: PyRef<'_, PyRig>,
        skip_phase1: bool,
        phase1_frames: Option<usize>,
        consider_camera: bool,
    ) -> PyResult<Self> {
        let rig = rig.rig.clone();
        let settings = nav_settings(skip_phase1, phase1_frames, consider_camera)
            .map_err(|e| input_error(py, e.to_string()))?;
        let navigator =
            nav::Navigator::new(rig, settings).map_err(|e| input_error(py, e.to_string()))?;
        Ok(Self {
            state: Mutex::new(State {
                navigator,
                last_odometry_t_us: None,
            }),
        })
    }

    /// Adds odometry samples `(t_us (S,), vx vy vtheta (S, 3))`, sorted by time and none
    /// older than those already pushed. Nothing is added when a value is bad
    /// (`stereonav.InputError`). The GIL is released.
    fn push_odometry(
        &mut self,
        py: Python<'_>,
        t_us: PyReadonlyArray1<'_, u64>,
        values: PyReadonlyArray2<'_, f64>,
    ) -> PyResult<()> {
        let state = self.state_mut();
        let samples = odometry_samples(
            &t_us.as_array(),
            &values.as_array(),
            state.last_odometry_t_us,
        )
        .map_err(|m| input_error(py, m))?;
        let result = py.detach(|| -> Result<(), nav::Error> {
            for sample in &samples {
                state.navigator.push_odometry(*sample)?;
                state.last_odometry_t_us = Some(sample.t_us);
            }
            Ok(())
        });
        result.map_err(|e| step_error(py, e))
    }

    /// The end of the drive (or of a log): phase 1, if still running, hands over now; in
    /// phase 2 the smoother solves over its last frames and the filter takes its estimate.
    /// Returns whether phase 1 handed over now. Raises `stereonav.Error` when phase 2 cannot
    /// start from the hand-over. The GIL is released.
    fn finish(&mut self, py: Python<'_>) -> PyResult<bool> {
        let state = self.state_mut();
        py.detach(|| state.navigator.finish())
            .map_err(|e| step_error(py, e))
    }

    /// Processes one stereo frame at `t_us`: the left `(N, 2)` and right `(M, 2)` features
    /// in pixels `u, v`. Returns `(accepted ids, accepted NIS, rejected ids, added ids,
    /// removed ids, rematched (K, 2) (track, landmark), solved, switched, no_odometry)`.
    /// Raises `stereonav.InputError` for a bad shape, a non-finite pixel or a frame older
    /// than the previous one (nothing changes), `stereonav.Error` when the filter refuses the
    /// frame's update. The GIL is released.
    fn push_frame<'py>(
        &mut self,
        py: Python<'py>,
        t_us: u64,
        left: PyReadonlyArray2<'py, f64>,
        right: PyReadonlyArray2<'py, f64>,
    ) -> PyResult<FrameOutcome> {
        let left = pixels("left", &left.as_array()).map_err(|m| input_error(py, m))?;
        let right = pixels("right", &right.as_array()).map_err(|m| input_error(py, m))?;
        self.step(py, t_us, &left, &right)
    }

    /// `"calibrating"` (phase 1) or `"navigating"` (phase 2).
    #[getter]
    fn phase(&self) -> &'static str {
        phase_of(self.locked().navigator.phase()).name()
    }

    /// When phase 2 started; None before, or when phase 1 was skipped.
    #[getter]
    fn phase_switch_t_us(&self) -> Option<u64> {
        self.locked().navigator.phase_switch_t_us()
    }

    /// Timestamp of the last frame processed, or None.
    #[getter]
    fn last_frame_t_us(&self) -> Option<u64> {
        self.locked().navigator.last_frame_t_us()
    }

    /// The pose `(X, Y, theta)`, (3,): the filter's in phase 2, dead reckoning before.
    #[getter]
    fn pose<'py>(&self, py: Python<'py>) -> F64Array<'py> {
        let (p, _) = self.locked().navigator.pose();
        vec![p.x, p.y, p.theta].into_pyarray(py)
    }

    /// The pose covariance, (3, 3).
    #[getter]
    fn pose_covariance<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        let (_, c) = self.locked().navigator.pose();
        Array2::from_shape_fn((3, 3), |(i, j)| c[(i, j)]).into_pyarray(py)
    }

    /// Every camera parameter: `(values (10,), sigmas (10,))`, `CAMERA_PARAMETERS` order.
    #[getter]
    fn camera<'py>(&self, py: Python<'py>) -> CameraTuple<'py> {
        let (c, cov) = self.locked().navigator.camera();
        camera_tuple(py, &ParamEstimate::all(&c, &cov))
    }

    /// Every vehicle parameter `V`: `(values (4,), sigmas (4,))`, `VEHICLE_PARAMETERS` order.
    #[getter]
    fn vehicle<'py>(&self, py: Python<'py>) -> CameraTuple<'py> {
        let (c, cov) = self.locked().navigator.camera();
        vehicle_tuple(py, &ParamEstimate::all(&c, &cov))
    }

    /// The camera covariance, (10, 10), `CAMERA_PARAMETERS` order.
    #[getter]
    fn camera_covariance<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        let (_, cov) = self.locked().navigator.camera();
        Array2::from_shape_fn((N_CAMERA, N_CAMERA), |(i, j)| cov[(i, j)]).into_pyarray(py)
    }

    /// The map, by id: `(ids (N,), positions (N, 3), covariances (N, 3, 3), observations
    /// (N,))`; empty in phase 1.
    #[getter]
    fn landmarks<'py>(&self, py: Python<'py>) -> LandmarkTuple<'py> {
        let state = self.locked();
        let mut all: Vec<LandmarkEstimate> = state
            .navigator
            .ekf()
            .map(|ekf| {
                ekf.landmarks()
                    .map(|l| LandmarkEstimate {
                        id: l.id.0,
                        position: [l.position.x, l.position.y, l.position.z],
                        covariance: core::array::from_fn(|r| {
                            core::array::from_fn(|c| l.covariance[(r, c)])
                        }),
                        observations: l.observations,
                    })
                    .collect()
            })
            .unwrap_or_default();
        all.sort_by_key(|l| l.id);
        landmark_tuple(py, &all)
    }

    /// `[(name, count), ...]`: the navigator's counters (`nav::NavStats`).
    #[getter]
    fn stats(&self) -> Vec<(&'static str, u64)> {
        let s = self.locked().navigator.stats();
        vec![
            ("frames", s.frames),
            ("odometry", s.odometry),
            ("frames_without_odometry", s.frames_without_odometry),
            ("phase1_solves", s.phase1_solves),
            ("odometry_dropped", s.odometry_dropped),
            ("rematched", s.rematched),
            ("rejected", s.rejected),
            ("refused_updates", s.refused_updates),
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use numpy::ndarray::array;

    #[test]
    fn phase_codes_index_the_phase_names() {
        for phase in PHASES {
            assert_eq!(PHASES[usize::from(phase_code(phase))], phase);
        }
        assert_eq!(phase_names(), ["calibrating", "navigating"]);
        assert_eq!(phase_of(nav::Phase::Navigating), Phase::Navigating);
    }

    #[test]
    fn settings_keep_the_defaults_but_the_two_given() {
        let s = nav_settings(true, None, false).expect("defaults");
        assert_eq!(s.ekf.camera_update, vslam_ekf::CameraUpdate::Refine);
        let c = nav_settings(false, None, true).expect("consider");
        assert_eq!(c.ekf.camera_update, vslam_ekf::CameraUpdate::Consider);
        assert!(s.skip_phase1);
        assert_eq!(s.phase1, NavSettings::default().phase1);
        assert_eq!(
            nav_settings(false, Some(200), false)
                .expect("200")
                .phase1
                .max_frames,
            200
        );
        let err = nav_settings(false, Some(1), false).expect_err("one frame");
        assert!(err.contains("max_frames = 1"), "{err}");
    }

    #[test]
    fn odometry_is_checked_whole_against_the_last_sample() {
        let t = array![10_u64, 20];
        let v = array![[0.1, 0.0, 0.0], [0.1, 0.0, f64::NAN]];
        let err = odometry_samples(&t.view(), &v.view(), None).expect_err("NaN");
        assert_eq!(err, "odometry[1] vtheta is NaN, not a finite number");
        let v = array![[0.1, 0.0, 0.0], [0.2, 0.0, 0.1]];
        let samples = odometry_samples(&t.view(), &v.view(), Some(10)).expect("equal is fine");
        assert_eq!(samples.len(), 2);
        assert_eq!((samples[1].t_us, samples[1].vx), (20, 0.2));
        let err = odometry_samples(&t.view(), &v.view(), Some(11)).expect_err("older");
        assert!(
            err.starts_with("odometry[0] t_us 10 is before the last sample pushed (t_us 11)"),
            "{err}"
        );
        let back = array![20_u64, 10];
        let err = odometry_samples(&back.view(), &v.view(), None).expect_err("unsorted");
        assert!(
            err.starts_with("odometry[1] t_us 10 is before odometry[0] t_us 20"),
            "{err}"
        );
        let err = odometry_samples(&t.view(), &v.t(), None).expect_err("shape");
        assert!(err.contains("shape (3, 2), expected (2, 3)"), "{err}");
    }

    #[test]
    fn pixels_are_checked_by_row_and_field() {
        let a = array![[400.0, 250.0], [300.0, f64::INFINITY]];
        let err = pixels("right", &a.view()).expect_err("inf");
        assert_eq!(err, "right[1] v is inf, not a finite number");
        let three = array![[400.0, 250.0, 1.0]];
        let err = pixels("left", &three.view()).expect_err("three columns");
        assert_eq!(
            err,
            "left has shape (1, 3), expected (N, 2) = (u, v) pixels"
        );
        let ok = pixels("left", &array![[1.5, 2.25]].view()).expect("finite");
        assert_eq!(ok, [Pixel::new(1.5, 2.25)]);
    }

    /// Runs in an embedded interpreter (see `lib.rs`); whether or not it can import
    /// `stereonav`, the classes are the built-in ones the package's derive from.
    #[test]
    fn errors_become_value_errors_or_the_packages_error() {
        Python::initialize();
        Python::attach(|py| {
            let path = std::env::temp_dir().join("stereonav-py-no-such-replay.mcap");
            let err = replay::replay_log(&path, None, &NavSettings::default(), &mut |_, _| {})
                .expect_err("missing");
            let py_err = replay_error(py, &err);
            assert!(py_err.is_instance_of::<pyo3::exceptions::PyValueError>(py));
            assert!(
                py_err.to_string().contains("no-such-replay.mcap"),
                "{py_err}"
            );
            let cause = py_err.cause(py).expect("the OSError");
            assert!(cause.is_instance_of::<pyo3::exceptions::PyFileNotFoundError>(py));
            let late = nav::Error::FrameOutOfOrder {
                t_us: 5,
                last_us: 10,
            };
            assert!(step_error(py, late).is_instance_of::<pyo3::exceptions::PyValueError>(py));
            let refused = nav::Error::Filter(vslam_ekf::Error::StateNotFinite { index: 0 });
            let refused = step_error(py, refused);
            assert!(!refused.is_instance_of::<pyo3::exceptions::PyValueError>(py));
        });
    }

    #[test]
    fn camera_arrays_are_in_param_order() {
        let rig_camera =
            rig_model::CameraParams::from_vector(&rig_model::ParamVector::from_fn(|i, _| i as f64));
        let mut cov = vslam_ekf::CameraCovariance::zeros();
        cov[(3, 3)] = 4e-6;
        let params = ParamEstimate::all(&rig_camera, &cov);
        assert_eq!(params.len(), rig_model::N_PARAMS);
        assert_eq!(params[3].param, Param::Baseline);
        assert!((params[3].sigma - 2e-3).abs() < 1e-15);
        assert_eq!(params[0].sigma, 0.0);
        for (i, p) in params.iter().enumerate() {
            assert_eq!((p.param.index(), p.value), (i, i as f64));
        }
    }
}
