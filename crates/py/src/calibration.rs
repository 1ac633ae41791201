//! Phase 1 of the method, self-calibration (`selfcal::solver`), for Python.
//!
//! The data come as plain NumPy arrays, checked here and turned into
//! [`FramePair`]s:
//!
//! * observations: `pair` (u64, the row of the motion arrays) and `(N, 8)` float64
//!   `uL0, vL0, uR0, vR0, uL1, vL1, uR1, vR1`: one landmark seen at both instants of a pair;
//! * motions: `t_us` (u64, time of the pair's second frame), `(P, 4)` float64
//!   `dx, dy, dtheta, dt_s` ([`Motion`], eq. (1)'s `dT` and `dtheta`) and `samples` (u64).
//!
//! [`frame_pairs`] builds those arrays from per-frame measurements with landmark ids and the
//! odometry, with `rig_model::odometry::integrate`. Whatever the source of the pairs (these
//! arrays here, or the association of a vehicle log in [`calibrate_log`]), the batch solve
//! ends in a [`CalibrationResult`] that hands the answer to Python.
//!
//! Bad values raise `stereonav.InputError` naming the array, the row and the field; a log
//! that cannot be used raises it naming the file. The solves run with the GIL released.

use std::collections::BTreeMap;
use std::fmt;
use std::path::PathBuf;

use numpy::ndarray::{Array2, ArrayView2};
use numpy::{IntoPyArray, PyArray1, PyArray2, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;
use replay::{LogCalibration, RigSource};
use rig_model::handover::{FramePair, LandmarkPair, ObservabilityReport};
use rig_model::odometry::{Motion, OdomSample, integrate};
use rig_model::{CameraParams, Measurement, N_CAMERA, Param, ParamVector, Rig};
use selfcal::solver::{Calibration, SolveStatus, SolverSettings, StableRule};
use track::{PairSettings, PairingScheme, SettingsError};

use crate::input_error;
use crate::rig::PyRig;

/// Fields of the `(N, 8)` observation values, in column order.
const OBSERVATION_FIELDS: [&str; 8] = ["uL0", "vL0", "uR0", "vR0", "uL1", "vL1", "uR1", "vR1"];
/// Fields of the `(P, 4)` motion values, in column order.
const MOTION_FIELDS: [&str; 4] = ["dx", "dy", "dtheta", "dt_s"];
/// Fields of the `(N, 4)` per-frame measurement values, in column order.
const MEASUREMENT_FIELDS: [&str; 4] = ["uL", "vL", "uR", "vR"];
/// Fields of the `(S, 3)` odometry values, in column order (section 2 of the interfaces).
const ODOMETRY_FIELDS: [&str; 3] = ["vx", "vy", "vtheta"];

/// Observations as passed: `pair` (N,) and the values (N, 8).
type ObservationArrays<'py> = (PyReadonlyArray1<'py, u64>, PyReadonlyArray2<'py, f64>);
/// Motions as passed: `t_us` (P,), `dx, dy, dtheta, dt_s` (P, 4), `samples` (P,).
type MotionArrays<'py> = (
    PyReadonlyArray1<'py, u64>,
    PyReadonlyArray2<'py, f64>,
    PyReadonlyArray1<'py, u64>,
);
/// Per-frame measurements as passed: `t_us` (N,), landmark `id` (N,), `uL, vL, uR, vR` (N, 4).
type MeasurementArrays<'py> = (
    PyReadonlyArray1<'py, u64>,
    PyReadonlyArray1<'py, u64>,
    PyReadonlyArray2<'py, f64>,
);
/// Odometry as passed: `t_us` (S,) and `vx, vy, vtheta` (S, 3).
type OdometryArrays<'py> = (PyReadonlyArray1<'py, u64>, PyReadonlyArray2<'py, f64>);
/// Observations handed back: `pair` (N,) and the values (N, 8).
type PyObservations<'py> = (Bound<'py, PyArray1<u64>>, Bound<'py, PyArray2<f64>>);
/// Motions handed back: `t_us` (P,), the values (P, 4), `samples` (P,).
type PyMotions<'py> = (
    Bound<'py, PyArray1<u64>>,
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray1<u64>>,
);
/// Integrated spans handed back: the values (P, 4) and `samples` (P,).
type PyIntegrated<'py> = (Bound<'py, PyArray2<f64>>, Bound<'py, PyArray1<u64>>);
/// A calibration input the solver cannot take; the message names the array, the row, the
/// field and the value.
#[derive(Debug, Clone, PartialEq)]
enum CalibInputError {
    /// A 2-D value array has the wrong number of columns.
    Columns {
        /// The array (`observations`, `motions`, ...).
        array: &'static str,
        /// Its shape.
        shape: [usize; 2],
        /// The columns expected.
        expected: usize,
    },
    /// Two arrays of the same table have different lengths.
    Length {
        /// The table.
        array: &'static str,
        /// The field whose length differs.
        field: &'static str,
        /// Its length.
        len: usize,
        /// The table's rows.
        expected: usize,
    },
    /// A value is NaN or infinite.
    NonFinite {
        /// The array.
        array: &'static str,
        /// The row.
        row: usize,
        /// The field.
        field: &'static str,
        /// The value.
        value: f64,
    },
    /// A duration is negative.
    NegativeDuration {
        /// The row of `motions`.
        row: usize,
        /// The value.
        dt_s: f64,
    },
    /// An observation refers to a pair that `motions` does not have.
    PairIndex {
        /// The row of `observations`.
        row: usize,
        /// Its `pair`.
        pair: u64,
        /// Rows of `motions`.
        pairs: usize,
    },
    /// Odometry samples are not sorted by time.
    Unsorted {
        /// The row of `odometry` that goes back in time.
        row: usize,
        /// Its `t_us`.
        t_us: u64,
        /// The previous row's `t_us`.
        previous_us: u64,
    },
    /// A landmark appears twice in one frame.
    DuplicateId {
        /// The second row of `measurements` with it.
        row: usize,
        /// The first one.
        first_row: usize,
        /// The landmark id.
        id: u64,
        /// The frame's time.
        t_us: u64,
    },
    /// An odometry span ends before it starts.
    BackwardSpan {
        /// The row.
        row: usize,
        /// Its start.
        t0_us: u64,
        /// Its end.
        t1_us: u64,
    },
    /// An odometry span starts before the first odometry sample (or there is none).
    Uncovered {
        /// The row.
        row: usize,
        /// Its start.
        t0_us: u64,
        /// The first sample's time, if any.
        first_us: Option<u64>,
    },
    /// A solver setting or stability rule value out of range.
    Setting {
        /// The keyword.
        name: &'static str,
        /// The value.
        value: f64,
        /// What it must be.
        expected: &'static str,
    },
    /// The start camera has a value the rig model cannot take.
    Camera {
        /// The parameter.
        param: Param,
        /// The value.
        value: f64,
    },
    /// The start camera does not have ten values.
    CameraLength {
        /// The values given.
        len: usize,
    },
    /// `pairing` is not the name of a pairing scheme.
    Pairing {
        /// The name given.
        name: String,
    },
    /// A setting of the log's association is out of range (`stride`).
    Association(SettingsError),
    /// Phase 1 refused its settings otherwise than by a field out of range.
    Phase1(selfcal::Error),
}

impl fmt::Display for CalibInputError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Columns {
                array,
                shape,
                expected,
            } => write!(
                f,
                "{array} values have shape {shape:?}, expected (N, {expected})"
            ),
            Self::Length {
                array,
                field,
                len,
                expected,
            } => write!(
                f,
                "{array} field {field} has {len} rows, expected {expected} like the other fields"
            ),
            Self::NonFinite {
                array,
                row,
                field,
                value,
            } => write!(f, "{array}[{row}] {field} is {value}, not a finite number"),
            Self::NegativeDuration { row, dt_s } => {
                write!(f, "motions[{row}] dt_s is {dt_s}, expected >= 0 seconds")
            }
            Self::PairIndex { row, pair, pairs } => write!(
                f,
                "observations[{row}] pair is {pair}, but motions has {pairs} rows (pairs 0..{pairs})"
            ),
            Self::Unsorted {
                row,
                t_us,
                previous_us,
            } => write!(
                f,
                "odometry[{row}] t_us {t_us} is before odometry[{}] t_us {previous_us}: \
                 samples must be sorted by time",
                row - 1
            ),
            Self::DuplicateId {
                row,
                first_row,
                id,
                t_us,
            } => write!(
                f,
                "measurements[{row}] repeats landmark id {id} of measurements[{first_row}] \
                 in the frame at t_us {t_us}"
            ),
            Self::BackwardSpan { row, t0_us, t1_us } => {
                write!(f, "span {row}: t1_us {t1_us} is before t0_us {t0_us}")
            }
            Self::Uncovered {
                row,
                t0_us,
                first_us: Some(first),
            } => write!(
                f,
                "span {row}: t0_us {t0_us} is before the first odometry sample at t_us {first}"
            ),
            Self::Uncovered {
                row,
                t0_us,
                first_us: None,
            } => write!(
                f,
                "span {row}: no odometry to integrate from t0_us {t0_us} (odometry is empty)"
            ),
            Self::Setting {
                name,
                value,
                expected,
            } => write!(f, "{name} is {value}, expected {expected}"),
            Self::Camera { param, value } => {
                write!(
                    f,
                    "start camera {param} is {value}, expected {}",
                    match param {
                        Param::F | Param::Baseline => "a positive finite number",
                        _ => "a finite number",
                    }
                )
            }
            Self::CameraLength { len } => write!(
                f,
                "start camera has {len} values, expected {N_CAMERA} in CAMERA_PARAMETERS order"
            ),
            Self::Pairing { name } => write!(
                f,
                "pairing is {name:?}, expected {:?} or {:?}",
                PairingScheme::Disjoint.name(),
                PairingScheme::Interleaved.name()
            ),
            Self::Association(err) => err.fmt(f),
            Self::Phase1(err) => err.fmt(f),
        }
    }
}

impl CalibInputError {
    /// `stereonav.InputError` with this error's message.
    fn into_pyerr(self, py: Python<'_>) -> PyErr {
        input_error(py, self.to_string())
    }
}

/// The rows of a 2-D value array of `fields.len()` columns, every value finite.
fn finite_rows<const N: usize>(
    array: &'static str,
    fields: &[&'static str; N],
    values: &ArrayView2<'_, f64>,
) -> Result<Vec<[f64; N]>, CalibInputError> {
    if values.ncols() != N {
        return Err(CalibInputError::Columns {
            array,
            shape: [values.nrows(), values.ncols()],
            expected: N,
        });
    }
    let mut out = Vec::with_capacity(values.nrows());
    for (row, r) in values.rows().into_iter().enumerate() {
        let mut out_row = [0.0; N];
        for ((slot, &value), &field) in out_row.iter_mut().zip(r.iter()).zip(fields) {
            if !value.is_finite() {
                return Err(CalibInputError::NonFinite {
                    array,
                    row,
                    field,
                    value,
                });
            }
            *slot = value;
        }
        out.push(out_row);
    }
    Ok(out)
}

/// Checks that a per-row field has as many rows as the table.
fn same_length(
    array: &'static str,
    field: &'static str,
    len: usize,
    expected: usize,
) -> Result<(), CalibInputError> {
    if len == expected {
        Ok(())
    } else {
        Err(CalibInputError::Length {
            array,
            field,
            len,
            expected,
        })
    }
}

/// The motions table as [`Motion`]s, with their `t_us`.
fn motions(
    t_us: &[u64],
    values: &ArrayView2<'_, f64>,
    samples: &[u64],
) -> Result<Vec<(u64, Motion)>, CalibInputError> {
    let rows = finite_rows("motions", &MOTION_FIELDS, values)?;
    same_length("motions", "t_us", t_us.len(), rows.len())?;
    same_length("motions", "samples", samples.len(), rows.len())?;
    rows.iter()
        .zip(t_us.iter().zip(samples))
        .enumerate()
        .map(|(row, (&[dx, dy, dtheta, dt_s], (&t, &n)))| {
            if dt_s < 0.0 {
                return Err(CalibInputError::NegativeDuration { row, dt_s });
            }
            // u64 fits usize on the 64-bit platforms the wheel is built for; saturate otherwise.
            let samples = usize::try_from(n).unwrap_or(usize::MAX);
            Ok((
                t,
                Motion {
                    dx,
                    dy,
                    dtheta,
                    dt_s,
                    samples,
                },
            ))
        })
        .collect()
}

/// Frame pairs from the observation and motion tables: pair `p` has motion row `p` and the
/// observations whose `pair` is `p`, in row order.
fn pairs_from_tables(
    pair: &[u64],
    observations: &ArrayView2<'_, f64>,
    t_us: &[u64],
    motion_values: &ArrayView2<'_, f64>,
    samples: &[u64],
) -> Result<Vec<FramePair>, CalibInputError> {
    let motions = motions(t_us, motion_values, samples)?;
    let rows = finite_rows("observations", &OBSERVATION_FIELDS, observations)?;
    same_length("observations", "pair", pair.len(), rows.len())?;
    let mut pairs: Vec<FramePair> = motions
        .into_iter()
        .map(|(t_us, motion)| FramePair {
            t_us,
            motion,
            landmarks: Vec::new(),
        })
        .collect();
    let n_pairs = pairs.len();
    for (row, (&p, z)) in pair.iter().zip(&rows).enumerate() {
        let target = usize::try_from(p)
            .ok()
            .and_then(|i| pairs.get_mut(i))
            .ok_or(CalibInputError::PairIndex {
                row,
                pair: p,
                pairs: n_pairs,
            })?;
        target.landmarks.push(LandmarkPair {
            first: Measurement::new(z[0], z[1], z[2], z[3]),
            second: Measurement::new(z[4], z[5], z[6], z[7]),
        });
    }
    Ok(pairs)
}

/// Odometry samples, finite and sorted by time.
fn odometry_samples(
    t_us: &[u64],
    values: &ArrayView2<'_, f64>,
) -> Result<Vec<OdomSample>, CalibInputError> {
    let rows = finite_rows("odometry", &ODOMETRY_FIELDS, values)?;
    same_length("odometry", "t_us", t_us.len(), rows.len())?;
    let mut previous = None;
    let mut out = Vec::with_capacity(rows.len());
    for (row, (&t, &[vx, vy, vtheta])) in t_us.iter().zip(&rows).enumerate() {
        if let Some(previous_us) = previous.filter(|&p| t < p) {
            return Err(CalibInputError::Unsorted {
                row,
                t_us: t,
                previous_us,
            });
        }
        previous = Some(t);
        out.push(OdomSample {
            t_us: t,
            vx,
            vy,
            vtheta,
        });
    }
    Ok(out)
}

/// The motion of each span `t0_us[i] .. t1_us[i]`, integrated from the odometry
/// (`rig_model::odometry::integrate`).
fn integrate_spans(
    odometry: &[OdomSample],
    t0_us: &[u64],
    t1_us: &[u64],
) -> Result<Vec<Motion>, CalibInputError> {
    same_length("spans", "t1_us", t1_us.len(), t0_us.len())?;
    t0_us
        .iter()
        .zip(t1_us)
        .enumerate()
        .map(|(row, (&t0_us, &t1_us))| {
            if t1_us < t0_us {
                return Err(CalibInputError::BackwardSpan { row, t0_us, t1_us });
            }
            integrate(odometry, t0_us, t1_us).ok_or(CalibInputError::Uncovered {
                row,
                t0_us,
                first_us: odometry.first().map(|s| s.t_us),
            })
        })
        .collect()
}

/// Frame pairs from per-frame measurements with landmark ids: frames are the distinct `t_us`
/// in time order; pairs are disjoint, `stride` frames apart (frames `(0, stride)`,
/// `(stride + 1, 2 stride + 1)`, ...), so that no frame's noise counts in two pairs; each has
/// the odometry integrated between its frames and the landmarks seen in both, by id (in id
/// order). A pair whose first frame precedes the odometry is left out.
fn pairs_by_id(
    t_us: &[u64],
    ids: &[u64],
    values: &ArrayView2<'_, f64>,
    odometry: &[OdomSample],
    stride: usize,
) -> Result<Vec<FramePair>, CalibInputError> {
    let rows = finite_rows("measurements", &MEASUREMENT_FIELDS, values)?;
    same_length("measurements", "t_us", t_us.len(), rows.len())?;
    same_length("measurements", "id", ids.len(), rows.len())?;
    // Frame time -> landmark id -> (row, measurement).
    let mut frames: BTreeMap<u64, BTreeMap<u64, (usize, Measurement)>> = BTreeMap::new();
    for (row, ((&t, &id), z)) in t_us.iter().zip(ids).zip(&rows).enumerate() {
        let frame = frames.entry(t).or_default();
        if let Some((first_row, _)) = frame.get(&id) {
            return Err(CalibInputError::DuplicateId {
                row,
                first_row: *first_row,
                id,
                t_us: t,
            });
        }
        frame.insert(id, (row, Measurement::from(*z)));
    }
    // The navigator's pairing (track::labelled_pairs), the ids standing in for its tracks.
    let frames = frames.into_iter().map(|(t, lamps)| {
        let lamps = lamps.into_iter().map(|(id, (_, z))| (id, z)).collect();
        (t, lamps)
    });
    Ok(track::labelled_pairs(
        frames,
        odometry,
        PairingScheme::Disjoint,
        stride,
    ))
}

/// [`SolverSettings`] from the keyword values, checked by [`SolverSettings::validate`].
fn solver_settings(
    (huber, max_iterations, step_tolerance, observable_ratio): (f64, usize, f64, f64),
) -> Result<SolverSettings, CalibInputError> {
    let settings = SolverSettings {
        huber,
        max_iterations,
        step_tolerance,
        observable_ratio,
    };
    settings.validate().map_err(CalibInputError::from)?;
    Ok(settings)
}

/// [`StableRule`] from the keyword values, checked by [`StableRule::validate`].
fn stable_rule(
    (min_pairs, sigma_fraction, step_fraction, consecutive): (usize, f64, f64, usize),
) -> Result<StableRule, CalibInputError> {
    let rule = StableRule {
        min_pairs,
        sigma_fraction,
        step_fraction,
        consecutive,
    };
    rule.validate().map_err(CalibInputError::from)?;
    Ok(rule)
}

impl From<selfcal::Error> for CalibInputError {
    /// A field out of range is named by its keyword.
    fn from(err: selfcal::Error) -> Self {
        match err {
            selfcal::Error::Setting {
                name,
                value,
                expected,
                ..
            } => Self::Setting {
                name,
                value,
                expected,
            },
            other => Self::Phase1(other),
        }
    }
}

/// The start camera from ten values in [`Param::CAMERA`] order (the vehicle nominal: the
/// frame-pair solver does not model V).
fn start_camera(values: &[f64]) -> Result<CameraParams, CalibInputError> {
    if values.len() != N_CAMERA {
        return Err(CalibInputError::CameraLength { len: values.len() });
    }
    for (&param, &value) in Param::CAMERA.iter().zip(values) {
        let positive_needed = matches!(param, Param::F | Param::Baseline);
        if !value.is_finite() || (positive_needed && value <= 0.0) {
            return Err(CalibInputError::Camera { param, value });
        }
    }
    Ok(crate::camera_from_values(
        values,
        &rig_model::Vehicle::NOMINAL,
    ))
}

/// The batch solve (`selfcal::solver::calibrate`) of checked frame pairs, with the GIL
/// released. Every source of frame pairs ends here.
fn solve(
    py: Python<'_>,
    pairs: &[FramePair],
    rig: &Rig,
    start: Option<CameraParams>,
    settings: &SolverSettings,
) -> CalibrationResult {
    let start = start.unwrap_or(rig.nominal);
    let calibration = py.detach(|| selfcal::solver::calibrate(pairs, rig, &start, settings));
    CalibrationResult { calibration }
}

/// The camera's part `C` of a parameter vector (the Python arrays hold C only).
fn vector_array<'py>(py: Python<'py>, v: &ParamVector) -> Bound<'py, PyArray1<f64>> {
    v.iter()
        .take(N_CAMERA)
        .copied()
        .collect::<Vec<_>>()
        .into_pyarray(py)
}

/// The camera's block of a covariance over C and V.
fn covariance_array<'py>(
    py: Python<'py>,
    cov: &nalgebra::SMatrix<f64, { rig_model::N_PARAMS }, { rig_model::N_PARAMS }>,
) -> Bound<'py, PyArray2<f64>> {
    Array2::from_shape_fn((N_CAMERA, N_CAMERA), |(i, j)| cov[(i, j)]).into_pyarray(py)
}

/// Rows of parameter vectors as a `(K, 10)` array.
fn vectors_array<'py, 'a>(
    py: Python<'py>,
    rows: impl ExactSizeIterator<Item = &'a ParamVector>,
) -> Bound<'py, PyArray2<f64>> {
    let k = rows.len();
    let flat: Vec<f64> = rows
        .flat_map(|v| v.iter().take(N_CAMERA).copied())
        .collect();
    Array2::from_shape_vec((k, N_CAMERA), flat)
        .unwrap_or_else(|_| Array2::zeros((0, N_CAMERA)))
        .into_pyarray(py)
}

/// How well the data constrain one estimated parameter (`rig_model::handover::ParamObservability`).
#[pyclass(module = "stereonav._native", frozen, get_all, eq)]
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct ParamObservability {
    /// The parameter (one of `CAMERA_PARAMETERS`).
    name: &'static str,
    /// Its prior sigma (rig file `[prior]`).
    prior_sigma: f64,
    /// Its sigma from the data alone (`inf` when the data say nothing about it).
    data_sigma: f64,
    /// Its sigma from data and prior together.
    posterior_sigma: f64,
    /// Whether the data constrain it (`posterior_sigma <= observable_ratio * prior_sigma`).
    observable: bool,
    /// Why it is not observable, or None.
    reason: Option<&'static str>,
    /// Not observable because of a known trap of the rig and the path, not for lack of data.
    structural: bool,
}

#[pymethods]
impl ParamObservability {
    /// A hash consistent with `==` (hashable as the frozen dataclass it replaces).
    fn __hash__(&self) -> u64 {
        use std::hash::{Hash, Hasher};
        // 0.0 == -0.0: one hash for both.
        let bits = |v: f64| if v == 0.0 { 0 } else { v.to_bits() };
        let mut h = std::collections::hash_map::DefaultHasher::new();
        (
            self.name,
            bits(self.prior_sigma),
            bits(self.data_sigma),
            bits(self.posterior_sigma),
            self.observable,
            self.reason,
            self.structural,
        )
            .hash(&mut h);
        h.finish()
    }

    fn __repr__(&self) -> String {
        format!(
            "ParamObservability(name={:?}, prior_sigma={}, data_sigma={}, posterior_sigma={}, \
             observable={}, reason={}, structural={})",
            self.name,
            py_float(self.prior_sigma),
            py_float(self.data_sigma),
            py_float(self.posterior_sigma),
            py_bool(self.observable),
            self.reason.map_or("None".to_string(), |r| format!("{r:?}")),
            py_bool(self.structural),
        )
    }
}

/// A float as Python's `repr` writes it (`inf`, `nan`, `1.0`).
fn py_float(v: f64) -> String {
    if v.is_nan() {
        "nan".to_string()
    } else if v.is_infinite() {
        if v > 0.0 { "inf" } else { "-inf" }.to_string()
    } else {
        format!("{v:?}")
    }
}

fn py_bool(b: bool) -> &'static str {
    if b { "True" } else { "False" }
}

/// The observability analysis of the estimated parameters (`ObservabilityReport`).
#[pyclass(module = "stereonav._native", frozen, get_all)]
pub(crate) struct Observability {
    /// One record per estimated parameter, in `CAMERA_PARAMETERS` order.
    params: Vec<ParamObservability>,
    /// `(a, b, r)`: the most correlated pair of observable parameters, or None.
    max_correlation: Option<(&'static str, &'static str, f64)>,
    /// The information eigenvalues in prior-sigma units, ascending, `(E,)`.
    eigenvalues: Py<PyArray1<f64>>,
}

impl Observability {
    fn new(py: Python<'_>, report: &ObservabilityReport) -> Self {
        Self {
            params: report
                .params
                .iter()
                .map(|p| ParamObservability {
                    name: p.param.name(),
                    prior_sigma: p.prior_sigma,
                    data_sigma: p.data_sigma,
                    posterior_sigma: p.posterior_sigma,
                    observable: p.observable,
                    reason: p.reason,
                    structural: p.structural,
                })
                .collect(),
            max_correlation: report
                .max_correlation
                .map(|(a, b, r)| (a.name(), b.name(), r)),
            eigenvalues: report
                .information_eigenvalues
                .clone()
                .into_pyarray(py)
                .unbind(),
        }
    }
}

/// What phase 1 hands to phase 2 once calibration is stable (`rig_model::handover::Handover`).
#[pyclass(module = "stereonav._native", frozen, get_all)]
pub(crate) struct Handover {
    /// The calibrated camera, 10 values in `CAMERA_PARAMETERS` order.
    camera: Py<PyArray1<f64>>,
    /// Its covariance, (10, 10).
    covariance: Py<PyArray2<f64>>,
    /// Time of the frame at which calibration became stable.
    t_us: u64,
    /// The observability analysis at hand-over.
    observability: Py<Observability>,
}

impl Handover {
    fn new(py: Python<'_>, h: &rig_model::handover::Handover) -> PyResult<Self> {
        Ok(Self {
            camera: vector_array(py, &h.camera.to_vector()).unbind(),
            covariance: covariance_array(py, &h.covariance).unbind(),
            t_us: h.t_us,
            observability: Py::new(py, Observability::new(py, &h.observability))?,
        })
    }
}

/// The camera parameters after each solve of an incremental calibration (K solves).
#[pyclass(module = "stereonav._native", frozen, get_all)]
pub(crate) struct CalibrationHistory {
    /// `(K,)`: time of the last frame pair of each solve.
    t_us: Py<PyArray1<u64>>,
    /// `(K, 10)`: the parameters, `CAMERA_PARAMETERS` order.
    values: Py<PyArray2<f64>>,
    /// `(K, 10)`: their sigmas (0 for those held fixed).
    sigmas: Py<PyArray2<f64>>,
}

impl CalibrationHistory {
    fn new(py: Python<'_>, h: &[(u64, ParamVector, ParamVector)]) -> Self {
        Self {
            t_us: h
                .iter()
                .map(|(t, _, _)| *t)
                .collect::<Vec<_>>()
                .into_pyarray(py)
                .unbind(),
            values: vectors_array(py, h.iter().map(|(_, v, _)| v)).unbind(),
            sigmas: vectors_array(py, h.iter().map(|(_, _, s)| s)).unbind(),
        }
    }
}

/// The tables of `observations` and `motions` as frame pairs, or `stereonav.InputError`.
fn checked_pairs(
    py: Python<'_>,
    (pair, z): &ObservationArrays<'_>,
    (t_us, values, samples): &MotionArrays<'_>,
) -> PyResult<Vec<FramePair>> {
    let (pair, t_us, samples) = (pair.as_array(), t_us.as_array(), samples.as_array());
    pairs_from_tables(
        &pair.to_vec(),
        &z.as_array(),
        &t_us.to_vec(),
        &values.as_array(),
        &samples.to_vec(),
    )
    .map_err(|e| e.into_pyerr(py))
}

fn checked_odometry(
    py: Python<'_>,
    (t_us, values): &OdometryArrays<'_>,
) -> PyResult<Vec<OdomSample>> {
    odometry_samples(&t_us.as_array().to_vec(), &values.as_array()).map_err(|e| e.into_pyerr(py))
}

fn observations_out<'py>(py: Python<'py>, pairs: &[FramePair]) -> PyObservations<'py> {
    let mut index = Vec::new();
    let mut flat = Vec::new();
    for (p, pair) in pairs.iter().enumerate() {
        for lm in &pair.landmarks {
            index.push(p as u64); // usize is at most 64 bits wide
            flat.extend(lm.first.iter().chain(lm.second.iter()).copied());
        }
    }
    let n = index.len();
    let values = Array2::from_shape_vec((n, OBSERVATION_FIELDS.len()), flat)
        .unwrap_or_else(|_| Array2::zeros((0, OBSERVATION_FIELDS.len())));
    (index.into_pyarray(py), values.into_pyarray(py))
}

fn motions_out<'py>(
    py: Python<'py>,
    motions: impl ExactSizeIterator<Item = (u64, Motion)>,
) -> PyMotions<'py> {
    let n = motions.len();
    let (mut t_us, mut flat, mut samples) = (
        Vec::with_capacity(n),
        Vec::with_capacity(4 * n),
        Vec::with_capacity(n),
    );
    for (t, m) in motions {
        t_us.push(t);
        flat.extend([m.dx, m.dy, m.dtheta, m.dt_s]);
        samples.push(m.samples as u64); // usize is at most 64 bits wide
    }
    let values = Array2::from_shape_vec((n, MOTION_FIELDS.len()), flat)
        .unwrap_or_else(|_| Array2::zeros((0, MOTION_FIELDS.len())));
    (
        t_us.into_pyarray(py),
        values.into_pyarray(py),
        samples.into_pyarray(py),
    )
}

/// The result of a phase-1 solve (`selfcal::solver::Calibration`). Arrays are copied out on
/// access.
#[pyclass(module = "stereonav._native", frozen)]
pub(crate) struct CalibrationResult {
    calibration: Calibration,
}

#[pymethods]
impl CalibrationResult {
    /// The estimated camera parameters, 10 values in `CAMERA_PARAMETERS` order.
    #[getter]
    fn camera<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        vector_array(py, &self.calibration.camera.to_vector())
    }

    /// Covariance of the 10 parameters, (10, 10); zero rows for those held fixed.
    #[getter]
    fn covariance<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        covariance_array(py, &self.calibration.covariance)
    }

    /// `"converged"`, `"max_iterations"`, `"stalled"` or `"no_data"`.
    #[getter]
    fn status(&self) -> &'static str {
        match self.calibration.status {
            SolveStatus::Converged => "converged",
            SolveStatus::MaxIterations => "max_iterations",
            SolveStatus::Stalled => "stalled",
            SolveStatus::NoData => "no_data",
        }
    }

    /// Levenberg-Marquardt iterations taken.
    #[getter]
    fn iterations(&self) -> usize {
        self.calibration.iterations
    }

    /// Landmark residuals used.
    #[getter]
    fn residuals(&self) -> usize {
        self.calibration.residuals
    }

    /// Frame pairs beyond the Huber threshold at the solution.
    #[getter]
    fn outliers(&self) -> usize {
        self.calibration.outliers
    }

    /// Chi-square at the solution over its degrees of freedom.
    #[getter]
    fn reduced_chi2(&self) -> f64 {
        self.calibration.reduced_chi2
    }

    /// The observability analysis at the solution.
    #[getter]
    fn observability(&self, py: Python<'_>) -> Observability {
        Observability::new(py, &self.calibration.observability)
    }

    /// The parameter vector after each accepted iteration, the start first: (K, 10).
    #[getter]
    fn history<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        vectors_array(py, self.calibration.history.iter())
    }
}

/// The settings of the phase-1 solver (`selfcal::solver::SolverSettings`); a keyword left out
/// takes the Rust default. Raises `stereonav.InputError` for a value out of range.
#[pyclass(name = "SolverSettings", module = "stereonav._native", frozen, get_all)]
#[derive(Debug, Clone, Copy)]
pub(crate) struct PySolverSettings {
    /// Huber threshold on a landmark's Mahalanobis norm.
    huber: f64,
    /// Most Levenberg-Marquardt iterations.
    max_iterations: usize,
    /// Converged when every step is below this fraction of the parameter's sigma.
    step_tolerance: f64,
    /// Observable when the data bring a sigma to at most this fraction of its prior, (0, 1].
    observable_ratio: f64,
}

impl PySolverSettings {
    fn settings(&self) -> SolverSettings {
        SolverSettings {
            huber: self.huber,
            max_iterations: self.max_iterations,
            step_tolerance: self.step_tolerance,
            observable_ratio: self.observable_ratio,
        }
    }
}

#[pymethods]
impl PySolverSettings {
    #[new]
    #[pyo3(signature = (*, huber=None, max_iterations=None, step_tolerance=None, observable_ratio=None))]
    fn new(
        py: Python<'_>,
        huber: Option<f64>,
        max_iterations: Option<usize>,
        step_tolerance: Option<f64>,
        observable_ratio: Option<f64>,
    ) -> PyResult<Self> {
        let d = SolverSettings::default();
        let s = solver_settings((
            huber.unwrap_or(d.huber),
            max_iterations.unwrap_or(d.max_iterations),
            step_tolerance.unwrap_or(d.step_tolerance),
            observable_ratio.unwrap_or(d.observable_ratio),
        ))
        .map_err(|e| e.into_pyerr(py))?;
        Ok(Self {
            huber: s.huber,
            max_iterations: s.max_iterations,
            step_tolerance: s.step_tolerance,
            observable_ratio: s.observable_ratio,
        })
    }
}

/// The stability rule of the incremental calibration (`selfcal::solver::StableRule`) and the
/// pairs between two solves (`solve_every`, the replay's default); a keyword left out takes
/// the Rust default. Raises `stereonav.InputError` for a value out of range.
#[pyclass(name = "StableRule", module = "stereonav._native", frozen, get_all)]
#[derive(Debug, Clone, Copy)]
pub(crate) struct PyStableRule {
    /// Pairs at least, before calibration can be stable.
    min_pairs: usize,
    /// Each observable sigma at most this fraction of its prior sigma.
    sigma_fraction: f64,
    /// Each step between two solves below this fraction of the sigma.
    step_fraction: f64,
    /// Solves in a row that must meet the rule.
    consecutive: usize,
    /// Pairs between two solves.
    solve_every: usize,
}

impl PyStableRule {
    fn rule(&self) -> StableRule {
        StableRule {
            min_pairs: self.min_pairs,
            sigma_fraction: self.sigma_fraction,
            step_fraction: self.step_fraction,
            consecutive: self.consecutive,
        }
    }
}

#[pymethods]
impl PyStableRule {
    #[new]
    #[pyo3(signature = (*, min_pairs=None, sigma_fraction=None, step_fraction=None, consecutive=None, solve_every=None))]
    fn new(
        py: Python<'_>,
        min_pairs: Option<usize>,
        sigma_fraction: Option<f64>,
        step_fraction: Option<f64>,
        consecutive: Option<usize>,
        solve_every: Option<usize>,
    ) -> PyResult<Self> {
        let d = StableRule::default();
        let r = stable_rule((
            min_pairs.unwrap_or(d.min_pairs),
            sigma_fraction.unwrap_or(d.sigma_fraction),
            step_fraction.unwrap_or(d.step_fraction),
            consecutive.unwrap_or(d.consecutive),
        ))
        .map_err(|e| e.into_pyerr(py))?;
        let solve_every = solve_every.unwrap_or(replay::FramePairSettings::default().solve_every);
        if solve_every == 0 {
            return Err(CalibInputError::Setting {
                name: "solve_every",
                value: 0.0,
                expected: "at least 1",
            }
            .into_pyerr(py));
        }
        Ok(Self {
            min_pairs: r.min_pairs,
            sigma_fraction: r.sigma_fraction,
            step_fraction: r.step_fraction,
            consecutive: r.consecutive,
            solve_every,
        })
    }
}

/// How a vehicle log's frames become frame pairs (`track::PairSettings`): `stride` frames
/// apart, `pairing` `"disjoint"` or `"interleaved"`; a keyword left out takes the Rust
/// default. Raises `stereonav.InputError` for a value out of range.
#[pyclass(name = "PairSettings", module = "stereonav._native", frozen, get_all)]
#[derive(Debug, Clone)]
pub(crate) struct PyPairSettings {
    /// Frames from the first frame of a pair to its second.
    stride: usize,
    /// The pairing scheme's name.
    pairing: &'static str,
}

#[pymethods]
impl PyPairSettings {
    #[new]
    #[pyo3(signature = (*, stride=None, pairing=None))]
    fn new(py: Python<'_>, stride: Option<usize>, pairing: Option<&str>) -> PyResult<Self> {
        let d = replay::FramePairSettings::default().pairs;
        let p = pair_settings(
            stride.unwrap_or(d.stride),
            pairing.unwrap_or(d.scheme.name()),
        )
        .map_err(|e| e.into_pyerr(py))?;
        Ok(Self {
            stride: p.stride,
            pairing: p.scheme.name(),
        })
    }
}

/// Phase-1 batch solve of frame pairs given as tables (see the module documentation).
///
/// `start` is the 10 start values (default the rig's nominal ones). Raises `stereonav.InputError` naming
/// the array, row and field of a bad value. The GIL is released while solving.
#[pyfunction]
#[pyo3(signature = (rig, observations, motions, start, settings))]
pub(crate) fn calibrate(
    py: Python<'_>,
    rig: PyRef<'_, PyRig>,
    observations: ObservationArrays<'_>,
    motions: MotionArrays<'_>,
    start: Option<PyReadonlyArray1<'_, f64>>,
    settings: PyRef<'_, PySolverSettings>,
) -> PyResult<CalibrationResult> {
    let rig = &rig.rig;
    let settings = settings.settings();
    let start = start
        .map(|s| start_camera(&s.as_array().to_vec()))
        .transpose()
        .map_err(|e| e.into_pyerr(py))?;
    let pairs = checked_pairs(py, &observations, &motions)?;
    Ok(solve(py, &pairs, rig, start, &settings))
}

/// The motion of each span `t0_us[i] .. t1_us[i]` from the odometry `(t_us (S,), vx vy
/// vtheta (S, 3))`, sorted by time: `(dx dy dtheta dt_s (P, 4), samples (P,))`. Raises
/// `stereonav.InputError` for unsorted or non-finite odometry, a span that ends before it
/// starts, or one that starts before the first sample.
#[pyfunction]
pub(crate) fn integrate_odometry<'py>(
    py: Python<'py>,
    odometry: OdometryArrays<'py>,
    t0_us: PyReadonlyArray1<'py, u64>,
    t1_us: PyReadonlyArray1<'py, u64>,
) -> PyResult<PyIntegrated<'py>> {
    let samples = checked_odometry(py, &odometry)?;
    let (t0_us, t1_us) = (t0_us.as_array().to_vec(), t1_us.as_array().to_vec());
    let motions = py
        .detach(|| integrate_spans(&samples, &t0_us, &t1_us))
        .map_err(|e| e.into_pyerr(py))?;
    let (_, values, samples) = motions_out(py, t1_us.iter().copied().zip(motions));
    Ok((values, samples))
}

/// Frame pairs from per-frame measurements `(t_us (N,), id (N,), uL vL uR vR (N, 4))` and
/// the odometry, `stride` frames apart, disjoint, landmarks matched by id. Returns the
/// tables `((pair, values (M, 8)), (t_us, values (P, 4), samples))`. Raises
/// `stereonav.InputError` for a bad value, naming the array, row and field.
#[pyfunction]
pub(crate) fn frame_pairs<'py>(
    py: Python<'py>,
    measurements: MeasurementArrays<'py>,
    odometry: OdometryArrays<'py>,
    stride: usize,
) -> PyResult<(PyObservations<'py>, PyMotions<'py>)> {
    let samples = checked_odometry(py, &odometry)?;
    let (t_us, ids, values) = &measurements;
    let (t_us, ids) = (t_us.as_array().to_vec(), ids.as_array().to_vec());
    let pairs = pairs_by_id(&t_us, &ids, &values.as_array(), &samples, stride)
        .map_err(|e| e.into_pyerr(py))?;
    Ok((
        observations_out(py, &pairs),
        motions_out(py, pairs.iter().map(|p| (p.t_us, p.motion))),
    ))
}

/// The pair settings of a log's association: `stride` frames apart, `pairing` by name.
fn pair_settings(stride: usize, pairing: &str) -> Result<PairSettings, CalibInputError> {
    let scheme = PairingScheme::from_name(pairing).ok_or_else(|| CalibInputError::Pairing {
        name: pairing.to_string(),
    })?;
    let settings = PairSettings {
        scheme,
        stride,
        ..PairSettings::default()
    };
    settings.validate().map_err(CalibInputError::Association)?;
    Ok(settings)
}

/// `stereonav.InputError` for a log that could not be calibrated or replayed, or an output that
/// could not be written; its message names the file and the problem. When the operating system
/// refused the file, its `OSError` (with the errno: `FileNotFoundError`, `PermissionError`,
/// ...) is the exception's `__cause__`.
pub(crate) fn replay_error(py: Python<'_>, err: &replay::Error) -> PyErr {
    file_error(py, err)
}

/// `stereonav.InputError` with the message of `err` (one line naming the file and the
/// problem: a log, a map, an output), the `OSError` of the first I/O error among its sources
/// as the `__cause__`.
pub(crate) fn file_error(py: Python<'_>, err: &(dyn std::error::Error + 'static)) -> PyErr {
    let py_err = input_error(py, err.to_string());
    let mut source: Option<&(dyn std::error::Error + 'static)> = Some(err);
    while let Some(e) = source {
        if let Some(io) = e.downcast_ref::<std::io::Error>() {
            let os = io.raw_os_error().map_or_else(
                || std::io::Error::new(io.kind(), io.to_string()),
                std::io::Error::from_raw_os_error,
            );
            py_err.set_cause(py, Some(PyErr::from(os)));
            break;
        }
        source = e.source();
    }
    py_err
}

/// Phase 1 on the vehicle log at `log_path` (`replay::calibrate_log`): read, decode, associate
/// with `pairs`, then the batch solve with `settings` and the incremental one with `rule` for
/// the hand-over.
///
/// `rig` None uses the log's `/rig` message. Raises `stereonav.InputError` for a log that
/// cannot be read or is not a vehicle log, or a bad rig. The GIL is released during the run.
#[pyfunction]
#[pyo3(signature = (log_path, rig, pairs, settings, rule))]
pub(crate) fn calibrate_log(
    py: Python<'_>,
    log_path: PathBuf,
    rig: Option<PyRef<'_, PyRig>>,
    pairs: PyRef<'_, PyPairSettings>,
    settings: PyRef<'_, PySolverSettings>,
    rule: PyRef<'_, PyStableRule>,
) -> PyResult<LogCalibrationResult> {
    let rig = rig.map(|r| r.rig.clone());
    let settings = replay::NavSettings {
        frame_pairs: replay::FramePairSettings {
            pairs: pair_settings(pairs.stride, pairs.pairing).map_err(|e| e.into_pyerr(py))?,
            solver: settings.settings(),
            stable: rule.rule(),
            solve_every: rule.solve_every,
        },
        ..replay::NavSettings::default()
    };
    let result = py
        .detach(|| replay::calibrate_log(&log_path, rig, &settings))
        .map_err(|e| replay_error(py, &e))?;
    Ok(LogCalibrationResult { result })
}

/// Phase 1 on a whole vehicle log (`replay::LogCalibration`). Arrays are copied out on access.
#[pyclass(module = "stereonav._native", frozen)]
pub(crate) struct LogCalibrationResult {
    result: LogCalibration,
}

#[pymethods]
impl LogCalibrationResult {
    /// The whole result as the JSON text `stereonav calibrate --out` writes
    /// (`replay::calibration_json`; NaN and infinity are null).
    fn document_json(&self) -> String {
        replay::calibration_json(&self.result).to_string()
    }

    /// The batch solve over every frame pair of the log.
    #[getter]
    fn calibration(&self) -> CalibrationResult {
        CalibrationResult {
            calibration: self.result.calibration.clone(),
        }
    }

    /// The incremental calibration's hand-over to phase 2, or None when it never became
    /// stable.
    #[getter]
    fn handover(&self, py: Python<'_>) -> PyResult<Option<Handover>> {
        self.result
            .handover
            .as_ref()
            .map(|h| Handover::new(py, h))
            .transpose()
    }

    /// The camera after each incremental solve, up to the hand-over.
    #[getter]
    fn history(&self, py: Python<'_>) -> CalibrationHistory {
        CalibrationHistory::new(py, &self.result.history)
    }

    /// `[(name, count), ...]`: what was read, decoded, associated and paired.
    #[getter]
    fn counts(&self) -> Vec<(&'static str, u64)> {
        self.result.counts.named().to_vec()
    }

    /// What limits the result without stopping it (a log cut short, a rig that differs from
    /// the log's), one line each.
    #[getter]
    fn warnings(&self) -> Vec<String> {
        self.result.warnings.clone()
    }

    /// `"given"` (the rig passed) or `"log"` (the log's `/rig` message).
    #[getter]
    fn rig_source(&self) -> &'static str {
        match self.result.rig_source {
            RigSource::Given => "given",
            RigSource::Log => "log",
        }
    }
}

/// Phase 1 fed pair by pair (`selfcal::solver::SelfCalibrator`): re-solves every
/// `solve_every` pairs, warm-started, until the stability rule hands over to phase 2.
#[pyclass(module = "stereonav._native")]
pub(crate) struct SelfCalibrator {
    inner: selfcal::solver::SelfCalibrator,
}

#[pymethods]
impl SelfCalibrator {
    /// A calibrator for the rig with the solver `settings` and the stability `rule`.
    #[new]
    fn new(
        rig: PyRef<'_, PyRig>,
        settings: PyRef<'_, PySolverSettings>,
        rule: PyRef<'_, PyStableRule>,
    ) -> Self {
        Self {
            inner: selfcal::solver::SelfCalibrator::new(
                rig.rig.clone(),
                settings.settings(),
                rule.rule(),
                rule.solve_every,
            ),
        }
    }

    /// Adds the frame pairs of the tables, in order; returns how many solves they triggered.
    /// Nothing is added when a value is bad (`stereonav.InputError`). The GIL is released
    /// while solving.
    fn add_pairs(
        &mut self,
        py: Python<'_>,
        observations: ObservationArrays<'_>,
        motions: MotionArrays<'_>,
    ) -> PyResult<usize> {
        let pairs = checked_pairs(py, &observations, &motions)?;
        let inner = &mut self.inner;
        Ok(py.detach(|| {
            let mut solves = 0;
            for pair in pairs {
                if inner.add_pair(pair).is_some() {
                    solves += 1;
                }
            }
            solves
        }))
    }

    /// The latest solve, or None before the first.
    #[getter]
    fn latest(&self) -> Option<CalibrationResult> {
        self.inner.latest().map(|c| CalibrationResult {
            calibration: c.clone(),
        })
    }

    /// The hand-over to phase 2 once calibration is stable, else None.
    #[getter]
    fn handover(&self, py: Python<'_>) -> PyResult<Option<Handover>> {
        self.inner
            .handover()
            .map(|h| Handover::new(py, h))
            .transpose()
    }

    /// The camera after each solve.
    #[getter]
    fn history(&self, py: Python<'_>) -> CalibrationHistory {
        CalibrationHistory::new(py, self.inner.history())
    }

    /// Frame pairs collected.
    #[getter]
    fn pairs(&self) -> usize {
        self.inner.pairs()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use numpy::ndarray::{Axis, array};

    fn odometry() -> Vec<OdomSample> {
        (0..=100)
            .map(|i| OdomSample {
                t_us: 1_000_000 + i * 10_000,
                vx: 0.1,
                vy: 0.0,
                vtheta: 0.05,
            })
            .collect()
    }

    #[test]
    fn tables_become_pairs_in_row_order() {
        let z = array![
            [400.0, 250.0, 380.0, 250.0, 401.0, 251.0, 381.0, 251.0],
            [300.0, 200.0, 280.0, 200.0, 301.0, 201.0, 281.0, 201.0],
            [500.0, 210.0, 470.0, 210.0, 502.0, 212.0, 472.0, 212.0],
        ];
        let m = array![[0.1, 0.0, 0.01, 0.5], [0.2, 0.01, 0.0, 0.5]];
        let pairs = pairs_from_tables(&[1, 0, 1], &z.view(), &[10, 20], &m.view(), &[50, 50])
            .expect("valid");
        assert_eq!(pairs.len(), 2);
        assert_eq!(pairs[0].landmarks.len(), 1);
        assert_eq!(pairs[1].landmarks.len(), 2);
        assert_eq!(pairs[1].t_us, 20);
        assert_eq!(pairs[1].motion.dx, 0.2);
        assert_eq!(pairs[1].motion.samples, 50);
        assert_eq!(pairs[1].landmarks[1].second[0], 502.0);
        assert_eq!(pairs[0].landmarks[0].first[0], 300.0);
    }

    #[test]
    fn bad_tables_name_the_row_and_field() {
        let mut z = array![[400.0, 250.0, 380.0, 250.0, 401.0, 251.0, 381.0, 251.0]];
        let m = array![[0.1, 0.0, 0.01, 0.5]];
        let err = pairs_from_tables(&[1], &z.view(), &[10], &m.view(), &[5]).expect_err("pair 1");
        assert_eq!(
            err.to_string(),
            "observations[0] pair is 1, but motions has 1 rows (pairs 0..1)"
        );
        z[[0, 5]] = f64::NAN;
        let err = pairs_from_tables(&[0], &z.view(), &[10], &m.view(), &[5]).expect_err("NaN");
        assert_eq!(
            err.to_string(),
            "observations[0] vL1 is NaN, not a finite number"
        );
        let err = pairs_from_tables(
            &[0],
            &z.slice_axis(Axis(1), (0..7).into()),
            &[10],
            &m.view(),
            &[5],
        )
        .expect_err("7 columns");
        assert!(
            err.to_string().contains("shape [1, 7], expected (N, 8)"),
            "{err}"
        );
        let bad_m = array![[0.1, 0.0, 0.01, -0.5]];
        let err = pairs_from_tables(
            &[],
            &z.slice_axis(Axis(0), (0..0).into()),
            &[10],
            &bad_m.view(),
            &[5],
        )
        .expect_err("negative dt");
        assert_eq!(
            err.to_string(),
            "motions[0] dt_s is -0.5, expected >= 0 seconds"
        );
        let err = pairs_from_tables(&[0], &z.view(), &[10, 11], &m.view(), &[5]).expect_err("len");
        assert!(
            err.to_string()
                .contains("motions field t_us has 2 rows, expected 1"),
            "{err}"
        );
    }

    #[test]
    fn spans_integrate_the_odometry() {
        let odom = odometry();
        let m = integrate_spans(&odom, &[1_000_000, 1_500_000], &[1_500_000, 1_500_000])
            .expect("covered");
        assert!((m[0].dt_s - 0.5).abs() < 1e-12 && m[0].samples == 50);
        assert!((m[0].dtheta - 0.025).abs() < 1e-12);
        assert_eq!(m[1].dt_s, 0.0);
        let err = integrate_spans(&odom, &[5], &[10]).expect_err("before odometry");
        assert_eq!(
            err.to_string(),
            "span 0: t0_us 5 is before the first odometry sample at t_us 1000000"
        );
        let err = integrate_spans(&odom, &[1_000_010], &[1_000_000]).expect_err("backward");
        assert!(
            err.to_string()
                .contains("t1_us 1000000 is before t0_us 1000010"),
            "{err}"
        );
    }

    #[test]
    fn unsorted_odometry_is_refused() {
        let v = array![[0.1, 0.0, 0.0], [0.1, 0.0, 0.0]];
        let err = odometry_samples(&[20, 10], &v.view()).expect_err("unsorted");
        assert!(
            err.to_string()
                .starts_with("odometry[1] t_us 10 is before odometry[0] t_us 20"),
            "{err}"
        );
    }

    #[test]
    fn frames_pair_disjointly_by_id() {
        let odom = odometry();
        // Four frames 50 ms apart; landmark 7 in all, landmark 3 only in frames 0 and 2.
        let t = [
            1_000_000, 1_000_000, 1_050_000, 1_100_000, 1_100_000, 1_150_000,
        ];
        let ids = [7, 3, 7, 3, 7, 7];
        let z = Array2::from_shape_fn((6, 4), |(i, k)| {
            300.0 + 10.0 * i as f64 + [0.0, 0.0, -20.0, 0.0][k]
        });
        let pairs = pairs_by_id(&t, &ids, &z.view(), &odom, 1).expect("valid");
        // Frames (0, 1) and (2, 3).
        assert_eq!(pairs.len(), 2);
        assert_eq!(pairs[0].t_us, 1_050_000);
        assert_eq!(pairs[0].landmarks.len(), 1);
        assert_eq!(pairs[0].landmarks[0].second[0], 320.0);
        assert_eq!(pairs[1].landmarks.len(), 1);
        let pairs = pairs_by_id(&t, &ids, &z.view(), &odom, 2).expect("valid");
        // Frames (0, 2): landmarks 3 and 7, in id order.
        assert_eq!(pairs.len(), 1);
        assert_eq!(pairs[0].landmarks.len(), 2);
        assert_eq!(pairs[0].landmarks[0].first[0], 310.0);
        assert!((pairs[0].motion.dt_s - 0.1).abs() < 1e-12);
        let err = pairs_by_id(
            &[1, 1],
            &[4, 4],
            &z.slice_axis(Axis(0), (0..2).into()),
            &odom,
            1,
        )
        .expect_err("duplicate");
        assert_eq!(
            err.to_string(),
            "measurements[1] repeats landmark id 4 of measurements[0] in the frame at t_us 1"
        );
    }

    #[test]
    fn settings_and_start_are_checked() {
        let (s, r) = (SolverSettings::default(), StableRule::default());
        let s = (
            s.huber,
            s.max_iterations,
            s.step_tolerance,
            s.observable_ratio,
        );
        assert!(solver_settings(s).is_ok());
        let r = (
            r.min_pairs,
            r.sigma_fraction,
            r.step_fraction,
            r.consecutive,
        );
        assert!(stable_rule(r).is_ok());
        let err = solver_settings((f64::NAN, 5, 0.01, 0.5)).expect_err("NaN huber");
        assert_eq!(
            err.to_string(),
            "huber is NaN, expected a positive finite number"
        );
        let err = solver_settings((3.0, 5, 0.01, 1.5)).expect_err("ratio");
        assert!(err.to_string().contains("observable_ratio is 1.5"), "{err}");
        let err = stable_rule((10, 0.2, 0.5, 0)).expect_err("consecutive");
        assert!(err.to_string().contains("consecutive"), "{err}");
        let mut c = [700.0, 376.0, 240.0, 0.12, 0.0, 0.0, 0.8, 0.0, 0.3, 0.0];
        assert_eq!(start_camera(&c).expect("valid").baseline, 0.12);
        c[3] = -0.12;
        let err = start_camera(&c).expect_err("negative baseline");
        assert!(
            err.to_string().contains("start camera baseline is -0.12"),
            "{err}"
        );
        assert!(start_camera(&c[..9]).is_err());
    }

    #[test]
    fn pair_settings_are_checked_by_name_and_range() {
        let p = pair_settings(20, "interleaved").expect("valid");
        assert_eq!((p.stride, p.scheme), (20, PairingScheme::Interleaved));
        let err = pair_settings(40, "Disjoint").expect_err("names are lower case");
        assert_eq!(
            err.to_string(),
            "pairing is \"Disjoint\", expected \"disjoint\" or \"interleaved\""
        );
        let err = pair_settings(0, "disjoint").expect_err("stride 0");
        assert!(err.to_string().contains("stride = 0"), "{err}");
    }

    #[test]
    fn a_missing_log_is_an_input_error_caused_by_the_os_error() {
        Python::initialize();
        Python::attach(|py| {
            let path = std::env::temp_dir().join("stereonav-py-no-such-log.mcap");
            let err = replay::calibrate_log(&path, None, &replay::NavSettings::default())
                .expect_err("missing");
            let py_err = replay_error(py, &err);
            assert!(py_err.to_string().contains("no-such-log.mcap"), "{py_err}");
            let cause = py_err.cause(py).expect("the OSError");
            assert!(
                cause.is_instance_of::<pyo3::exceptions::PyFileNotFoundError>(py),
                "{cause}"
            );
        });
    }
}
