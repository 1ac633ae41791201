//! The seeded Monte Carlo evaluation of phase 2 (`eval::monte_carlo`) for Python: per-run
//! arrays (rows in seed order) and the consistency statistics with their chi-square bands.

use std::path::PathBuf;

use eval::{Banded, RunResult, RunSettings, Summary};
use numpy::ndarray::Array2;
use numpy::{IntoPyArray, PyArray1, PyArray2};
use pyo3::prelude::*;

use crate::input_error;

/// A [`Banded`] handed back: `(value, low, high)`.
type BandedTuple = (f64, f64, f64);

fn banded(b: &Banded) -> BandedTuple {
    (b.value, b.low, b.high)
}

/// `(R, F)` rows of per-frame values, each run's row padded with `pad` to the longest run.
fn per_frame<'py, T: numpy::Element + Copy>(
    py: Python<'py>,
    runs: &[RunResult],
    pad: T,
    values: impl Fn(&RunResult) -> Vec<T>,
) -> Bound<'py, PyArray2<T>> {
    let rows: Vec<Vec<T>> = runs.iter().map(values).collect();
    let frames = rows.iter().map(Vec::len).max().unwrap_or(0);
    Array2::from_shape_fn((rows.len(), frames), |(r, k)| {
        rows[r].get(k).copied().unwrap_or(pad)
    })
    .into_pyarray(py)
}

/// One value per run, `(R,)`.
fn per_run<'py, T: numpy::Element>(
    py: Python<'py>,
    runs: &[RunResult],
    value: impl Fn(&RunResult) -> T,
) -> Bound<'py, PyArray1<T>> {
    runs.iter().map(value).collect::<Vec<_>>().into_pyarray(py)
}

/// Many runs of phase 2 on one scenario, summarised (`eval::Summary`). Arrays are copied out
/// on access; rows are runs in seed order.
#[pyclass(module = "stereonav._native", frozen)]
pub(crate) struct MonteCarloResult {
    summary: Summary,
}

impl MonteCarloResult {
    /// The estimated camera parameters (those of the first run; every run has the same rig).
    fn params(&self) -> Vec<rig_model::Param> {
        self.summary
            .runs
            .first()
            .map(|r| r.camera.iter().map(|c| c.param).collect())
            .unwrap_or_default()
    }

    /// `(R, m)`: one value per run and estimated parameter (NaN where a run lacks it).
    fn camera_table<'py>(
        &self,
        py: Python<'py>,
        value: impl Fn(&eval::CameraResult) -> f64,
    ) -> Bound<'py, PyArray2<f64>> {
        let params = self.params();
        let runs = &self.summary.runs;
        Array2::from_shape_fn((runs.len(), params.len()), |(r, k)| {
            runs[r].camera_result(params[k]).map_or(f64::NAN, &value)
        })
        .into_pyarray(py)
    }
}

#[pymethods]
impl MonteCarloResult {
    /// Seeds, (R,) uint64.
    #[getter]
    fn seeds<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<u64>> {
        per_run(py, &self.summary.runs, |r| r.seed)
    }

    /// Frames processed per run, (R,) uint64.
    #[getter]
    fn frames<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<u64>> {
        per_run(py, &self.summary.runs, |r| r.frames as u64) // usize is at most 64 bits
    }

    /// RMS landmark position error per run, metres, (R,).
    #[getter]
    fn landmark_rms<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        per_run(py, &self.summary.runs, RunResult::landmark_rms)
    }

    /// Landmarks in the map at the end of each run, (R,) uint64.
    #[getter]
    fn landmarks<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<u64>> {
        per_run(py, &self.summary.runs, |r| r.landmarks.len() as u64)
    }

    /// Lamps seen but never mapped, per run, (R,) uint64.
    #[getter]
    fn lamps_missing<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<u64>> {
        per_run(py, &self.summary.runs, |r| r.lamps_missing.len() as u64)
    }

    /// Names of the estimated camera parameters, the columns of the camera tables.
    #[getter]
    fn camera_parameters(&self) -> Vec<&'static str> {
        self.params().iter().map(|p| p.name()).collect()
    }

    /// Estimated value of each estimated camera parameter at the end, (R, m).
    #[getter]
    fn camera_value<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        self.camera_table(py, |c| c.value)
    }

    /// True value of each estimated camera parameter, (R, m).
    #[getter]
    fn camera_truth<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        self.camera_table(py, |c| c.truth)
    }

    /// 1-sigma of each estimated camera parameter at the end, (R, m).
    #[getter]
    fn camera_sigma<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        self.camera_table(py, |c| c.sigma)
    }

    /// Runs with every landmark and camera parameter inside 3 sigma, (R,) bool.
    #[getter]
    fn within_3_sigma<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<bool>> {
        per_run(py, &self.summary.runs, RunResult::within_3_sigma)
    }

    /// Runs whose state stayed finite and `P` positive definite throughout, (R,) bool.
    #[getter]
    fn healthy<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<bool>> {
        per_run(py, &self.summary.runs, |r| r.healthy)
    }

    /// Pose NEES (3 dof) at each frame after the first, (R, F), NaN-padded.
    #[getter]
    fn pose_nees<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        per_frame(py, &self.summary.runs, f64::NAN, |r| r.pose_nees.clone())
    }

    /// Full-state NEES at each frame after the first, (R, F), NaN-padded.
    #[getter]
    fn state_nees<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        per_frame(py, &self.summary.runs, f64::NAN, |r| {
            r.state_nees.iter().map(|(v, _)| *v).collect()
        })
    }

    /// Degrees of freedom of each full-state NEES, (R, F) uint64, zero-padded.
    #[getter]
    fn state_nees_dof<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<u64>> {
        per_frame(py, &self.summary.runs, 0, |r| {
            r.state_nees.iter().map(|(_, d)| *d as u64).collect()
        })
    }

    /// Mean NIS of each run's accepted observations (4 dof), (R,); NaN for a run without any.
    #[getter]
    fn mean_nis<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        per_run(py, &self.summary.runs, |r| {
            if r.nis.is_empty() {
                f64::NAN
            } else {
                #[allow(clippy::cast_precision_loss)] // counts far below 2^53
                let n = r.nis.len() as f64;
                r.nis.iter().sum::<f64>() / n
            }
        })
    }

    /// Accepted observations per run (the NIS count), (R,) uint64.
    #[getter]
    fn accepted<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<u64>> {
        per_run(py, &self.summary.runs, |r| r.nis.len() as u64)
    }

    /// Observations rejected by the gate per run, outliers included, (R,) uint64.
    #[getter]
    fn rejected<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<u64>> {
        per_run(py, &self.summary.runs, |r| r.rejected)
    }

    /// Gross outliers mixed in per run, (R,) uint64.
    #[getter]
    fn outliers<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<u64>> {
        per_run(py, &self.summary.runs, |r| r.outliers)
    }

    /// Outliers the gate let through per run, (R,) uint64.
    #[getter]
    fn outliers_accepted<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<u64>> {
        per_run(py, &self.summary.runs, |r| r.outliers_accepted)
    }

    /// Updates the filter refused per run, (R,) uint64.
    #[getter]
    fn refused_updates<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<u64>> {
        per_run(py, &self.summary.runs, |r| r.refused_updates)
    }

    /// Final pose error `(dx, dy, dtheta)` per run, (R, 3).
    #[getter]
    fn pose_error<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        let runs = &self.summary.runs;
        Array2::from_shape_fn((runs.len(), 3), |(r, k)| runs[r].pose_error[k]).into_pyarray(py)
    }

    /// Pose NEES averaged over runs and frames, with its 95 % band: `(value, low, high)`.
    #[getter]
    fn pose_nees_band(&self) -> BandedTuple {
        banded(&self.summary.pose_nees)
    }

    /// Fraction of frames whose run-averaged pose NEES lies inside its 95 % band.
    #[getter]
    fn pose_nees_frames_inside(&self) -> f64 {
        self.summary.pose_nees_frames_inside
    }

    /// Full-state NEES per dof, averaged over runs and frames, with its 95 % band.
    #[getter]
    fn state_nees_per_dof_band(&self) -> BandedTuple {
        banded(&self.summary.state_nees_per_dof)
    }

    /// Fraction of frames whose run-summed full-state NEES lies inside its 95 % band.
    #[getter]
    fn state_nees_frames_inside(&self) -> f64 {
        self.summary.state_nees_frames_inside
    }

    /// Mean NIS of every accepted observation (4 dof), with its 95 % band.
    #[getter]
    fn nis_band(&self) -> BandedTuple {
        banded(&self.summary.nis)
    }

    /// Runs with every landmark and camera parameter inside 3 sigma.
    #[getter]
    fn within_3_sigma_count(&self) -> usize {
        self.summary.within_3_sigma
    }

    /// Runs whose state stayed finite and `P` positive definite throughout.
    #[getter]
    fn healthy_count(&self) -> usize {
        self.summary.healthy
    }
}

/// `runs` seeded runs of phase 2 on the scenario file (`eval::monte_carlo`), seeds
/// `first_seed ..`, a fraction `outlier_fraction` of the lamp measurements replaced by gross
/// outliers, at most `max_frames` frames each. The GIL is released while the runs go. Raises
/// `stereonav.InputError` for a bad scenario, rig or setting.
#[pyfunction]
#[pyo3(signature = (scenario, runs, first_seed, outlier_fraction, max_frames))]
pub(crate) fn monte_carlo(
    py: Python<'_>,
    scenario: PathBuf,
    runs: u64,
    first_seed: u64,
    outlier_fraction: f64,
    max_frames: Option<usize>,
) -> PyResult<MonteCarloResult> {
    let end = first_seed.checked_add(runs).ok_or_else(|| {
        input_error(
            py,
            format!("first_seed {first_seed} + runs {runs} does not fit 64 bits"),
        )
    })?;
    if runs == 0 {
        return Err(input_error(
            py,
            "runs is 0, expected at least 1".to_string(),
        ));
    }
    let scenario = sim::Scenario::load(&scenario).map_err(|e| input_error(py, e.to_string()))?;
    let settings = RunSettings {
        outlier_fraction,
        max_frames,
        ..RunSettings::default()
    };
    let summary = py
        .detach(|| eval::monte_carlo(&scenario, first_seed..end, &settings))
        .map_err(|e| input_error(py, e.to_string()))?;
    Ok(MonteCarloResult { summary })
}
