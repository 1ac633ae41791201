//! Phase 2 of the method, the EKF of `vslam-ekf` (eq. 3-8), for Python.
//!
//! [`Filter`] holds one [`Ekf`] and the [`Candidates`] that confirm new landmarks from track-keyed
//! measurements. Inputs are plain NumPy arrays, checked here:
//!
//! * measurements: `(M, 4)` float64 `uL, vL, uR, vR` (pixels), with `(M,)` uint64 landmark
//!   ids ([`Filter::update`]) or track ids ([`Filter::observe`]);
//! * odometry: `t_us` (S,) uint64 and `vx, vy, vtheta` (S, 3) float64, sorted by time.
//!
//! A bad value (a shape, a NaN, an unknown landmark id, a setting out of range) raises
//! `stereonav.InputError` naming it; an update the filter refuses because its covariance lost
//! positive definiteness (the state is left as it was) raises `stereonav.Error`. Every call
//! that touches the state runs with the GIL released. The filter lives behind a mutex only
//! because Python classes must be `Sync`: mutating calls borrow it exclusively through pyo3
//! and never lock; readers lock without ever releasing the GIL, so no lock is ever waited on.

use std::sync::{Mutex, MutexGuard, PoisonError};

use nalgebra::DMatrix;
use numpy::ndarray::{Array2, Array3, ArrayView1, ArrayView2};
use numpy::{IntoPyArray, PyArray1, PyArray2, PyArray3, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::exceptions::PyRuntimeError;
use pyo3::prelude::*;
use pyo3::sync::PyOnceLock;
use pyo3::types::PyType;
use rig_model::odometry::OdomSample;
use rig_model::{Measurement, N_CAMERA, Param};
use vslam_ekf::{
    CameraCovariance, CameraStart, CandidateSettings, Candidates, CovarianceUpdate, Ekf,
    FrameReport, Health, LandmarkId, Settings, UpdateReport,
};

use crate::input_error;
use crate::rig::PyRig;

/// Fields of a `(M, 4)` measurement row, in column order.
const MEASUREMENT_FIELDS: [&str; 4] = ["uL", "vL", "uR", "vR"];
/// Fields of a `(S, 3)` odometry row, in column order.
const ODOMETRY_FIELDS: [&str; 3] = ["vx", "vy", "vtheta"];
/// Names of [`CovarianceUpdate`]'s forms, as the `covariance_update` keyword takes them.
const COVARIANCE_UPDATES: [(&str, CovarianceUpdate); 3] = [
    ("auto", CovarianceUpdate::Auto),
    ("joseph", CovarianceUpdate::Joseph),
    ("factored", CovarianceUpdate::Factored),
];

/// Python module of the package's exception classes.
const ERRORS_MODULE: &str = "stereonav._errors";
/// The base class of the package's exceptions, raised for refused updates.
const ERROR_CLASS: &str = "Error";
/// `stereonav._errors.Error`, imported on first use.
static ERROR: PyOnceLock<Py<PyType>> = PyOnceLock::new();

/// The start camera as passed: `(camera (10,), covariance (10, 10))`.
type StartArrays<'py> = (PyReadonlyArray1<'py, f64>, PyReadonlyArray2<'py, f64>);
/// Odometry as passed: `t_us` (S,) and `vx, vy, vtheta` (S, 3).
type OdometryArrays<'py> = (PyReadonlyArray1<'py, u64>, PyReadonlyArray2<'py, f64>);
/// An [`UpdateReport`] handed back: accepted ids and NIS, rejected ids and NIS, removed ids.
type UpdateTuple<'py> = (
    Bound<'py, PyArray1<u64>>,
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray1<u64>>,
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray1<u64>>,
);
/// A [`FrameReport`] handed back: the update, added and removed `(track, landmark)` pairs
/// `(K, 2)`, measurements ignored, candidates pending.
type FrameTuple<'py> = (
    UpdateTuple<'py>,
    Bound<'py, PyArray2<u64>>,
    Bound<'py, PyArray2<u64>>,
    usize,
    usize,
);
/// The landmarks handed back: ids (N,), positions (N, 3), covariances (N, 3, 3),
/// observations (N,).
type LandmarkTuple<'py> = (
    Bound<'py, PyArray1<u64>>,
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray3<f64>>,
    Bound<'py, PyArray1<u64>>,
);
/// A predicted measurement (4,) with a matrix: its innovation covariance (4, 4) or its
/// Jacobian (4, n).
type PredictedTuple<'py> = (Bound<'py, PyArray1<f64>>, Bound<'py, PyArray2<f64>>);

/// `(z (4,), H (4, n))` of one of the filter's dense Jacobians, or its error as Python's.
fn dense_jacobian<'py>(
    py: Python<'py>,
    jacobian: Result<(Measurement, DMatrix<f64>), vslam_ekf::Error>,
) -> PyResult<PredictedTuple<'py>> {
    let (z, h) = jacobian.map_err(|e| filter_error(py, e))?;
    Ok((
        z.iter().copied().collect::<Vec<_>>().into_pyarray(py),
        matrix_array(py, &h),
    ))
}
/// `stereonav.Error(message)`, or a plain `RuntimeError` (caused by the import error) if that
/// class cannot be imported.
pub(crate) fn stereonav_error(py: Python<'_>, message: String) -> PyErr {
    match ERROR.import(py, ERRORS_MODULE, ERROR_CLASS) {
        Ok(class) => PyErr::from_type(class.clone(), message),
        Err(import_error) => {
            let err = PyRuntimeError::new_err(message);
            err.set_cause(py, Some(import_error));
            err
        }
    }
}

/// The Python exception for a refusal of the filter: `stereonav.Error` when the filter's own
/// numbers refused the step (a covariance that lost positive definiteness, a state that would
/// not be finite, a landmark that cannot be projected at the current estimate), otherwise
/// `stereonav.InputError` (the caller's value was wrong). The message is the filter's, which
/// names the value.
fn filter_error(py: Python<'_>, err: vslam_ekf::Error) -> PyErr {
    use vslam_ekf::Error as E;
    let message = err.to_string();
    match err {
        E::InnovationNotPositiveDefinite { .. }
        | E::VarianceNotPositive { .. }
        | E::StateNotFinite { .. }
        | E::Projection { .. } => stereonav_error(py, message),
        _ => input_error(py, message),
    }
}

/// The rows of a `(M, 4)` measurement array, each value finite; `what` names the rows' ids in
/// messages (`"landmark"`, `"track"`), `ids` gives them.
fn measurement_rows(
    what: &str,
    ids: &ArrayView1<'_, u64>,
    z: &ArrayView2<'_, f64>,
) -> Result<Vec<(u64, Measurement)>, String> {
    if z.ncols() != MEASUREMENT_FIELDS.len() || z.nrows() != ids.len() {
        return Err(format!(
            "z has shape ({}, {}), expected ({}, 4): one row uL, vL, uR, vR per {what} id",
            z.nrows(),
            z.ncols(),
            ids.len()
        ));
    }
    let mut out = Vec::with_capacity(z.nrows());
    for (row, (&id, values)) in ids.iter().zip(z.rows()).enumerate() {
        let mut m = [0.0; 4];
        for ((slot, &v), field) in m.iter_mut().zip(values.iter()).zip(MEASUREMENT_FIELDS) {
            if !v.is_finite() {
                return Err(format!(
                    "z[{row}] {field} (of {what} {id}) is {v}, not a finite number"
                ));
            }
            *slot = v;
        }
        out.push((id, Measurement::from(m)));
    }
    Ok(out)
}

/// One measurement `uL, vL, uR, vR` from a `(4,)` array, each value finite.
fn one_measurement(z: &ArrayView1<'_, f64>) -> Result<Measurement, String> {
    if z.len() != MEASUREMENT_FIELDS.len() {
        return Err(format!(
            "z has shape ({},), expected (4,) = (uL, vL, uR, vR)",
            z.len()
        ));
    }
    let mut m = [0.0; 4];
    for ((slot, &v), field) in m.iter_mut().zip(z.iter()).zip(MEASUREMENT_FIELDS) {
        if !v.is_finite() {
            return Err(format!("z {field} is {v}, not a finite number"));
        }
        *slot = v;
    }
    Ok(Measurement::from(m))
}

/// Odometry samples from `t_us` (S,) and `vx, vy, vtheta` (S, 3): finite, sorted by time.
fn odometry_samples(
    t_us: &ArrayView1<'_, u64>,
    values: &ArrayView2<'_, f64>,
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
        for (&value, field) in v.iter().zip(ODOMETRY_FIELDS) {
            if !value.is_finite() {
                return Err(format!(
                    "odometry[{row}] {field} is {value}, not a finite number"
                ));
            }
        }
        if let Some(previous) = out.last().filter(|p| t < p.t_us) {
            return Err(format!(
                "odometry[{row}] t_us {t} is before odometry[{}] t_us {}: samples must be \
                 sorted by time",
                row - 1,
                previous.t_us
            ));
        }
        out.push(OdomSample {
            t_us: t,
            vx: v[0],
            vy: v[1],
            vtheta: v[2],
        });
    }
    Ok(out)
}

/// The start camera from `(camera (10,), covariance (10, 10))`: shapes checked here, values
/// by the filter.
fn camera_start(
    camera: &ArrayView1<'_, f64>,
    cov: &ArrayView2<'_, f64>,
) -> Result<CameraStart, String> {
    if camera.len() != N_CAMERA {
        return Err(format!(
            "start camera has {} values, expected {N_CAMERA} in CAMERA_PARAMETERS order",
            camera.len()
        ));
    }
    if cov.shape() != [N_CAMERA, N_CAMERA] {
        return Err(format!(
            "start camera covariance has shape {:?}, expected ({N_CAMERA}, {N_CAMERA})",
            cov.shape()
        ));
    }
    Ok(CameraStart {
        camera: crate::camera_from_values(
            &camera.iter().copied().collect::<Vec<_>>(),
            &rig_model::Vehicle::NOMINAL,
        ),
        covariance: CameraCovariance::from_fn(|i, j| {
            if i < N_CAMERA && j < N_CAMERA {
                cov[[i, j]]
            } else {
                0.0
            }
        }),
    })
}

/// The [`CovarianceUpdate`] of its name.
fn covariance_form(form: &str) -> Result<CovarianceUpdate, String> {
    COVARIANCE_UPDATES
        .iter()
        .find(|(name, _)| *name == form)
        .map(|(_, f)| *f)
        .ok_or_else(|| unknown_form(form))
}

/// The settings of [`Filter`] (`vslam_ekf::Settings` and `CandidateSettings`); a keyword left
/// out takes the Rust default. Ranges are checked by the filter when it is made.
#[pyclass(name = "FilterSettings", module = "stereonav._native", frozen, get_all)]
#[derive(Debug, Clone)]
pub(crate) struct PyFilterSettings {
    /// Probability mass inside each observation's innovation gate (4 dof), in (0, 1).
    gate_probability: f64,
    /// Gate outcomes kept for the health's NIS statistics.
    nis_window: usize,
    /// A landmark rejected this many times in a row is removed as false.
    max_consecutive_rejections: u32,
    /// Form of the covariance update: `"auto"`, `"joseph"` or `"factored"`.
    covariance_update: &'static str,
    /// Consecutive frames with consistent triangulations before a track becomes a landmark.
    frames_to_confirm: u32,
    /// Probability mass inside the consistency gate of a candidate's world points (3 dof).
    consistency_probability: f64,
}

#[pymethods]
impl PyFilterSettings {
    #[new]
    #[pyo3(signature = (*, gate_probability=None, nis_window=None, max_consecutive_rejections=None, covariance_update=None, frames_to_confirm=None, consistency_probability=None))]
    fn new(
        py: Python<'_>,
        gate_probability: Option<f64>,
        nis_window: Option<usize>,
        max_consecutive_rejections: Option<u32>,
        covariance_update: Option<&str>,
        frames_to_confirm: Option<u32>,
        consistency_probability: Option<f64>,
    ) -> PyResult<Self> {
        let s = Settings::default();
        let c = CandidateSettings::default();
        let form = match covariance_update {
            Some(name) => covariance_form(name).map_err(|m| input_error(py, m))?,
            None => s.covariance_update,
        };
        Ok(Self {
            gate_probability: gate_probability.unwrap_or(s.gate_probability),
            nis_window: nis_window.unwrap_or(s.nis_window),
            max_consecutive_rejections: max_consecutive_rejections
                .unwrap_or(s.max_consecutive_rejections),
            covariance_update: covariance_update_name(form),
            frames_to_confirm: frames_to_confirm.unwrap_or(c.frames_to_confirm),
            consistency_probability: consistency_probability.unwrap_or(c.consistency_probability),
        })
    }
}

impl PyFilterSettings {
    fn settings(&self) -> Result<(Settings, CandidateSettings), String> {
        Ok((
            Settings {
                gate_probability: self.gate_probability,
                nis_window: self.nis_window,
                max_consecutive_rejections: self.max_consecutive_rejections,
                covariance_update: covariance_form(self.covariance_update)?,
                ..Settings::default()
            },
            CandidateSettings {
                frames_to_confirm: self.frames_to_confirm,
                consistency_probability: self.consistency_probability,
                ..CandidateSettings::default()
            },
        ))
    }
}

fn unknown_form(form: &str) -> String {
    format!("covariance_update is {form:?}, expected \"auto\", \"joseph\" or \"factored\"")
}

fn covariance_update_name(form: CovarianceUpdate) -> &'static str {
    COVARIANCE_UPDATES
        .iter()
        .find(|(_, f)| *f == form)
        .map_or("auto", |(name, _)| name)
}

/// A `(K, 2)` uint64 array of `(track, landmark)` pairs.
fn pairs_array<'py>(py: Python<'py>, pairs: &[(u64, LandmarkId)]) -> Bound<'py, PyArray2<u64>> {
    Array2::from_shape_fn((pairs.len(), 2), |(i, k)| {
        let (track, id) = pairs[i];
        if k == 0 { track } else { id.0 }
    })
    .into_pyarray(py)
}

fn update_tuple<'py>(py: Python<'py>, report: &UpdateReport) -> UpdateTuple<'py> {
    let ids = |g: &[vslam_ekf::Gated]| g.iter().map(|g| g.id.0).collect::<Vec<_>>();
    let nis = |g: &[vslam_ekf::Gated]| g.iter().map(|g| g.nis).collect::<Vec<_>>();
    (
        ids(&report.accepted).into_pyarray(py),
        nis(&report.accepted).into_pyarray(py),
        ids(&report.rejected).into_pyarray(py),
        nis(&report.rejected).into_pyarray(py),
        report
            .removed
            .iter()
            .map(|id| id.0)
            .collect::<Vec<_>>()
            .into_pyarray(py),
    )
}

fn frame_tuple<'py>(py: Python<'py>, report: &FrameReport) -> FrameTuple<'py> {
    (
        update_tuple(py, &report.update),
        pairs_array(py, &report.added),
        pairs_array(py, &report.removed),
        report.ignored,
        report.pending,
    )
}

/// The filter's health (`vslam_ekf::Health`): counters, the NIS over a sliding window, a
/// divergence flag.
#[pyclass(name = "Health", module = "stereonav._native", frozen, get_all)]
#[derive(Debug, Clone)]
pub(crate) struct PyHealth {
    /// Updates applied.
    updates: u64,
    /// Updates refused (covariance not positive definite, or a result not finite).
    refused_updates: u64,
    /// Landmark observations accepted by the gate, in all.
    accepted: u64,
    /// Landmark observations rejected by the gate, in all.
    rejected: u64,
    /// Landmarks added, in all.
    landmarks_added: u64,
    /// Landmarks removed, in all.
    landmarks_removed: u64,
    /// Gate outcomes in the window.
    window_observations: usize,
    /// Rejections among them.
    window_rejected: usize,
    /// Mean NIS per degree of freedom of the accepted observations in the window, or None.
    window_mean_nis_per_dof: Option<f64>,
    /// That mean's 99.9 % bound, or None.
    window_nis_bound: Option<f64>,
    /// The window mean is above its bound.
    nis_too_high: bool,
    /// `nis_too_high`, or an update was ever refused.
    diverged: bool,
}

impl From<&Health> for PyHealth {
    fn from(h: &Health) -> Self {
        Self {
            updates: h.updates,
            refused_updates: h.refused_updates,
            accepted: h.accepted,
            rejected: h.rejected,
            landmarks_added: h.landmarks_added,
            landmarks_removed: h.landmarks_removed,
            window_observations: h.window_observations,
            window_rejected: h.window_rejected,
            window_mean_nis_per_dof: h.window_mean_nis_per_dof,
            window_nis_bound: h.window_nis_bound,
            nis_too_high: h.nis_too_high,
            diverged: h.diverged,
        }
    }
}

/// A C-ordered copy of a dense matrix.
fn matrix_array<'py>(py: Python<'py>, m: &DMatrix<f64>) -> Bound<'py, PyArray2<f64>> {
    Array2::from_shape_fn((m.nrows(), m.ncols()), |(i, j)| m[(i, j)]).into_pyarray(py)
}

/// A C-ordered copy of a fixed-size matrix.
fn fixed_array<'py, const R: usize, const C: usize>(
    py: Python<'py>,
    m: &nalgebra::SMatrix<f64, R, C>,
) -> Bound<'py, PyArray2<f64>> {
    Array2::from_shape_fn((R, C), |(i, j)| m[(i, j)]).into_pyarray(py)
}

/// The filter and its confirmation bookkeeping.
#[derive(Debug, Clone)]
struct State {
    ekf: Ekf,
    candidates: Candidates,
}

/// Phase 2, the EKF with the camera parameters in the state (`vslam_ekf::Ekf`), with the
/// track-keyed confirmation of new landmarks (`vslam_ekf::Candidates`).
#[pyclass(module = "stereonav._native")]
#[derive(Debug)]
pub(crate) struct Filter {
    state: Mutex<State>,
}

impl Filter {
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

    fn landmark_id(&self, py: Python<'_>, id: u64) -> PyResult<LandmarkId> {
        let id = LandmarkId(id);
        if self.locked().ekf.contains(id) {
            Ok(id)
        } else {
            Err(filter_error(py, vslam_ekf::Error::UnknownLandmark { id }))
        }
    }
}

#[pymethods]
impl Filter {
    /// A filter for the rig, starting from `start = (camera (10,), covariance (10, 10))`
    /// (phase 1's hand-over) or, when None, from the rig's nominal camera and prior sigmas.
    /// Raises `stereonav.InputError` for a bad start or setting.
    #[new]
    #[pyo3(signature = (rig, start, settings))]
    fn new(
        py: Python<'_>,
        rig: PyRef<'_, PyRig>,
        start: Option<StartArrays<'_>>,
        settings: PyRef<'_, PyFilterSettings>,
    ) -> PyResult<Self> {
        let rig = &rig.rig;
        let start = match &start {
            Some((camera, cov)) => {
                camera_start(&camera.as_array(), &cov.as_array()).map_err(|m| input_error(py, m))?
            }
            None => CameraStart::from_prior(rig),
        };
        let (settings, candidates) = settings.settings().map_err(|m| input_error(py, m))?;
        let candidates = Candidates::new(candidates).map_err(|e| filter_error(py, e))?;
        let ekf = Ekf::new(rig, &start, settings).map_err(|e| filter_error(py, e))?;
        Ok(Self {
            state: Mutex::new(State { ekf, candidates }),
        })
    }

    /// An independent copy: state, covariance, landmarks, bindings, health. The GIL is
    /// released while copying.
    fn copy(&mut self, py: Python<'_>) -> Self {
        let state = self.state_mut();
        let copy = py.detach(move || state.clone());
        Self {
            state: Mutex::new(copy),
        }
    }

    /// Eq. 3-4: predicts with the robot-frame velocities `(vx, vy, vtheta)` held for `dt_s`
    /// seconds. Raises `stereonav.InputError` for a non-finite value or a negative `dt_s`.
    fn predict(
        &mut self,
        py: Python<'_>,
        vx: f64,
        vy: f64,
        vtheta: f64,
        dt_s: f64,
    ) -> PyResult<()> {
        let ekf = &mut self.state_mut().ekf;
        py.detach(|| ekf.predict(vx, vy, vtheta, dt_s))
            .map_err(|e| filter_error(py, e))
    }

    /// Predicts over `[t0_us, t1_us]` with the odometry `(t_us (S,), vx vy vtheta (S, 3))`,
    /// sorted by time, each sample held until the next. Raises `stereonav.InputError` for
    /// unsorted or non-finite odometry, an interval that ends before it starts or that no
    /// sample covers.
    fn predict_odometry(
        &mut self,
        py: Python<'_>,
        odometry: OdometryArrays<'_>,
        t0_us: u64,
        t1_us: u64,
    ) -> PyResult<()> {
        let (t_us, values) = &odometry;
        let samples = odometry_samples(&t_us.as_array(), &values.as_array())
            .map_err(|m| input_error(py, m))?;
        let ekf = &mut self.state_mut().ekf;
        py.detach(|| ekf.predict_odometry(&samples, t0_us, t1_us))
            .map_err(|e| filter_error(py, e))
    }

    /// Eq. 5-8: updates with landmark measurements, `ids` (M,) and `z` (M, 4). Returns
    /// `(accepted ids, accepted NIS, rejected ids, rejected NIS, removed ids)`. Raises
    /// `stereonav.InputError` for a bad shape, a non-finite value, an unknown or repeated id
    /// (nothing changes), `stereonav.Error` when the filter refuses the update (nothing
    /// changes).
    fn update<'py>(
        &mut self,
        py: Python<'py>,
        ids: PyReadonlyArray1<'py, u64>,
        z: PyReadonlyArray2<'py, f64>,
    ) -> PyResult<UpdateTuple<'py>> {
        let rows = measurement_rows("landmark", &ids.as_array(), &z.as_array())
            .map_err(|m| input_error(py, m))?;
        let batch: Vec<(LandmarkId, Measurement)> = rows
            .into_iter()
            .map(|(id, z)| (LandmarkId(id), z))
            .collect();
        let ekf = &mut self.state_mut().ekf;
        let report = py
            .detach(|| ekf.update(&batch))
            .map_err(|e| filter_error(py, e))?;
        Ok(update_tuple(py, &report))
    }

    /// One stereo frame keyed by track ids, `tracks` (M,) and `z` (M, 4): bound tracks update
    /// the filter, unbound ones are candidates that become landmarks once confirmed. Returns
    /// `(update, added (K, 2), removed (K, 2), ignored, pending)`. Raises as `update`.
    fn observe<'py>(
        &mut self,
        py: Python<'py>,
        tracks: PyReadonlyArray1<'py, u64>,
        z: PyReadonlyArray2<'py, f64>,
    ) -> PyResult<FrameTuple<'py>> {
        let frame = measurement_rows("track", &tracks.as_array(), &z.as_array())
            .map_err(|m| input_error(py, m))?;
        let State { ekf, candidates } = self.state_mut();
        let report = py
            .detach(|| candidates.observe(ekf, &frame))
            .map_err(|e| filter_error(py, e))?;
        Ok(frame_tuple(py, &report))
    }

    /// Adds a landmark triangulated from one measurement `z` (4,) at the current pose and
    /// camera; returns its id. Raises `stereonav.InputError` for a bad or non-triangulable
    /// measurement.
    fn add_landmark(&mut self, py: Python<'_>, z: PyReadonlyArray1<'_, f64>) -> PyResult<u64> {
        let z = one_measurement(&z.as_array()).map_err(|m| input_error(py, m))?;
        let ekf = &mut self.state_mut().ekf;
        py.detach(|| ekf.add_landmark(&z))
            .map(|id| id.0)
            .map_err(|e| filter_error(py, e))
    }

    /// Removes a landmark (and unbinds its track). Raises `stereonav.InputError` for an
    /// unknown id.
    fn remove_landmark(&mut self, py: Python<'_>, id: u64) -> PyResult<()> {
        let State { ekf, candidates } = self.state_mut();
        py.detach(|| candidates.remove_landmark(ekf, LandmarkId(id)))
            .map_err(|e| filter_error(py, e))
    }

    /// `(z (4,), S (4, 4))`: a landmark's predicted measurement and innovation covariance.
    fn predict_measurement<'py>(&self, py: Python<'py>, id: u64) -> PyResult<PredictedTuple<'py>> {
        let (z, s) = self
            .locked()
            .ekf
            .predict_measurement(LandmarkId(id))
            .map_err(|e| filter_error(py, e))?;
        Ok((
            z.iter().copied().collect::<Vec<_>>().into_pyarray(py),
            fixed_array(py, &s),
        ))
    }

    /// `(z (4,), H (4, n))`: a landmark's predicted measurement and the dense Jacobian of the
    /// measurement with respect to the whole state (the update itself never forms it).
    fn measurement_jacobian<'py>(&self, py: Python<'py>, id: u64) -> PyResult<PredictedTuple<'py>> {
        dense_jacobian(py, self.locked().ekf.measurement_jacobian(LandmarkId(id)))
    }

    /// `(z (4,), H (4, n))`: the Jacobian `predict_measurement`'s `S` is formed with, dense:
    /// `measurement_jacobian`'s but for the heading's column, from the observability
    /// constraint at the landmark's linearisation point.
    fn prediction_jacobian<'py>(&self, py: Python<'py>, id: u64) -> PyResult<PredictedTuple<'py>> {
        dense_jacobian(py, self.locked().ekf.prediction_jacobian(LandmarkId(id)))
    }

    /// The state `[X, Y, theta, L_1 .. L_N, C_est]`, (n,).
    #[getter]
    fn state<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        self.locked()
            .ekf
            .state()
            .iter()
            .copied()
            .collect::<Vec<_>>()
            .into_pyarray(py)
    }

    /// The covariance, (n, n), C order.
    #[getter]
    fn covariance<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        matrix_array(py, &self.locked().ekf.covariance())
    }

    /// The pose `(X, Y, theta)`, (3,).
    #[getter]
    fn pose<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        let p = self.locked().ekf.pose();
        vec![p.x, p.y, p.theta].into_pyarray(py)
    }

    /// The pose covariance, (3, 3).
    #[getter]
    fn pose_covariance<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        fixed_array(py, &self.locked().ekf.pose_covariance())
    }

    /// Every camera parameter, (10,) in `CAMERA_PARAMETERS` order.
    #[getter]
    fn camera<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        crate::camera_values(&self.locked().ekf.camera()).into_pyarray(py)
    }

    /// The camera covariance, (10, 10) in `CAMERA_PARAMETERS` order, zero for the parameters
    /// not estimated.
    #[getter]
    fn camera_covariance<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        let cov = self.locked().ekf.camera_covariance();
        fixed_array(py, &cov.fixed_view::<N_CAMERA, N_CAMERA>(0, 0).into_owned())
    }

    /// Names of the estimated camera parameters, in state order.
    #[getter]
    fn estimated_parameters(&self) -> Vec<&'static str> {
        self.locked()
            .ekf
            .estimated_parameters()
            .iter()
            .map(|p| p.name())
            .collect()
    }

    /// Every landmark in state order: `(ids (N,), positions (N, 3), covariances (N, 3, 3),
    /// observations (N,))`.
    #[getter]
    fn landmarks<'py>(&self, py: Python<'py>) -> LandmarkTuple<'py> {
        let state = self.locked();
        let all: Vec<_> = state.ekf.landmarks().collect();
        let n = all.len();
        (
            all.iter()
                .map(|l| l.id.0)
                .collect::<Vec<_>>()
                .into_pyarray(py),
            Array2::from_shape_fn((n, 3), |(i, k)| all[i].position[k]).into_pyarray(py),
            Array3::from_shape_fn((n, 3, 3), |(i, a, b)| all[i].covariance[(a, b)])
                .into_pyarray(py),
            all.iter()
                .map(|l| l.observations)
                .collect::<Vec<_>>()
                .into_pyarray(py),
        )
    }

    /// A landmark's position covariance, (3, 3). Raises `stereonav.InputError` for an
    /// unknown id.
    fn landmark_covariance<'py>(
        &self,
        py: Python<'py>,
        id: u64,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let id = self.landmark_id(py, id)?;
        let estimate = self.locked().ekf.landmark(id);
        estimate
            .map(|l| fixed_array(py, &l.covariance))
            .ok_or_else(|| filter_error(py, vslam_ekf::Error::UnknownLandmark { id }))
    }

    /// Index in the state of a landmark's `x` (then `y`, `z`). Raises `stereonav.InputError`
    /// for an unknown id.
    fn landmark_state_index(&self, py: Python<'_>, id: u64) -> PyResult<usize> {
        let id = LandmarkId(id);
        self.locked()
            .ekf
            .landmark_state_index(id)
            .ok_or_else(|| filter_error(py, vslam_ekf::Error::UnknownLandmark { id }))
    }

    /// Index in the state of an estimated camera parameter. Raises `stereonav.InputError` for
    /// an unknown name or a parameter not estimated.
    fn camera_state_index(&self, py: Python<'_>, name: &str) -> PyResult<usize> {
        let param = Param::from_name(name).ok_or_else(|| {
            let names: Vec<&str> = Param::ALL.iter().map(|p| p.name()).collect();
            input_error(
                py,
                format!("{name:?} is not a camera parameter (one of {names:?})"),
            )
        })?;
        let state = self.locked();
        state.ekf.camera_state_index(param).ok_or_else(|| {
            let estimated: Vec<&str> = state
                .ekf
                .estimated_parameters()
                .iter()
                .map(|p| p.name())
                .collect();
            input_error(
                py,
                format!("camera parameter {name} is not estimated (the state has {estimated:?})"),
            )
        })
    }

    /// The health: `(updates, refused_updates, accepted, rejected, landmarks_added,
    /// landmarks_removed, window_observations, window_rejected, window_mean_nis_per_dof,
    /// window_nis_bound, nis_too_high, diverged)`.
    #[getter]
    fn health(&self) -> PyHealth {
        PyHealth::from(&self.locked().ekf.health())
    }

    /// Every `(track, landmark)` binding, (K, 2), by track.
    #[getter]
    fn bindings<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<u64>> {
        let pairs: Vec<(u64, LandmarkId)> = self.locked().candidates.bindings().collect();
        pairs_array(py, &pairs)
    }

    /// Candidates waiting for confirmation.
    #[getter]
    fn pending(&self) -> usize {
        self.locked().candidates.pending_count()
    }

    /// The NIS bound of the innovation gate (4 dof).
    #[getter]
    fn gate_bound(&self) -> f64 {
        self.locked().ekf.gate_bound()
    }

    /// The form of the covariance update: `"auto"`, `"joseph"` or `"factored"`.
    #[getter]
    fn covariance_update(&self) -> &'static str {
        covariance_update_name(self.locked().ekf.settings().covariance_update)
    }

    /// Switches the form of the covariance update (both are exact). Raises
    /// `stereonav.InputError` for another name.
    #[setter]
    fn set_covariance_update(&mut self, py: Python<'_>, form: &str) -> PyResult<()> {
        let form = covariance_form(form).map_err(|m| input_error(py, m))?;
        self.state_mut().ekf.set_covariance_update(form);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use numpy::ndarray::array;

    #[test]
    fn measurements_are_checked_by_row_and_field() {
        let ids = array![3_u64, 7];
        let z = array![
            [400.0, 250.0, 380.0, 250.0],
            [300.0, f64::NAN, 280.0, 200.0]
        ];
        let err = measurement_rows("landmark", &ids.view(), &z.view()).expect_err("NaN");
        assert_eq!(err, "z[1] vL (of landmark 7) is NaN, not a finite number");
        let err = measurement_rows("track", &ids.view(), &z.t()).expect_err("shape");
        assert!(
            err.starts_with("z has shape (4, 2), expected (2, 4)"),
            "{err}"
        );
        let ok = measurement_rows(
            "landmark",
            &ids.view(),
            &z.slice_axis(numpy::ndarray::Axis(0), (0..1).into()),
        );
        assert!(ok.is_err(), "one row for two ids");
    }

    #[test]
    fn odometry_must_be_sorted_and_finite() {
        let t = array![10_u64, 5];
        let v = array![[0.1, 0.0, 0.0], [0.1, 0.0, 0.0]];
        let err = odometry_samples(&t.view(), &v.view()).expect_err("unsorted");
        assert!(
            err.starts_with("odometry[1] t_us 5 is before odometry[0] t_us 10"),
            "{err}"
        );
        let t = array![1_u64, 5];
        let v = array![[0.1, 0.0, 0.0], [0.1, 0.0, f64::INFINITY]];
        let err = odometry_samples(&t.view(), &v.view()).expect_err("inf");
        assert_eq!(err, "odometry[1] vtheta is inf, not a finite number");
    }

    #[test]
    fn covariance_update_names_round_trip() {
        for (name, form) in COVARIANCE_UPDATES {
            assert_eq!(covariance_update_name(form), name);
            assert_eq!(covariance_form(name), Ok(form));
        }
        let err = covariance_form("Joseph").expect_err("case");
        assert!(err.contains("\"Joseph\""), "{err}");
    }
}
