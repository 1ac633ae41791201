//! The simulator for Python: a scenario run as NumPy arrays (truth included).

use std::path::PathBuf;

use numpy::ndarray::Array2;
use numpy::{IntoPyArray, PyArray1, PyArray2};
use pyo3::prelude::*;
use pyo3::types::PyBytes;

use crate::input_error;

/// One simulated run of a scenario. Arrays are copied out on access.
#[pyclass(module = "stereonav._native", frozen)]
pub(crate) struct SimRun {
    run: sim::SimRun,
}

#[pymethods]
impl SimRun {
    /// Scenario name.
    #[getter]
    fn name(&self) -> &str {
        &self.run.name
    }

    /// Seed used.
    #[getter]
    fn seed(&self) -> u64 {
        self.run.seed
    }

    /// `"fast"` or `"rendered"`.
    #[getter]
    fn mode(&self) -> &'static str {
        self.run.mode.name()
    }

    /// True camera parameters, 10 values in `CAMERA_PARAMETERS` order.
    #[getter]
    fn camera<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        crate::camera_values(&self.run.camera).into_pyarray(py)
    }

    /// The nominal rig file (TOML text) a user of this vehicle would have.
    #[getter]
    fn rig_toml(&self) -> String {
        self.run.rig.to_toml()
    }

    /// Frame timestamps (u64 microseconds), shape (F,).
    #[getter]
    fn frame_t_us<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<u64>> {
        self.run
            .frames
            .iter()
            .map(|f| f.t_us)
            .collect::<Vec<_>>()
            .into_pyarray(py)
    }

    /// True pose at each frame `(x, y, theta)`, shape (F, 3).
    #[getter]
    fn frame_poses<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        let f = &self.run.frames;
        Array2::from_shape_fn((f.len(), 3), |(i, k)| {
            let p = &f[i].pose;
            [p.x, p.y, p.theta][k]
        })
        .into_pyarray(py)
    }

    /// Lamps visible at each frame, shape (F,).
    #[getter]
    fn visible<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<u64>> {
        self.run
            .visible_counts()
            .into_iter()
            .map(|n| n as u64)
            .collect::<Vec<_>>()
            .into_pyarray(py)
    }

    /// Landmark world positions, shape (N, 3), row i is landmark id i.
    #[getter]
    fn landmarks<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        let l = &self.run.landmarks;
        Array2::from_shape_fn((l.len(), 3), |(i, k)| l[i].position[k]).into_pyarray(py)
    }

    /// Odometry as logged `(t_us, vx, vy, vtheta)`, shape (S, 4) float64.
    #[getter]
    fn odometry<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        odometry(py, &self.run.odometry)
    }

    /// The true velocities at the same instants, shape (S, 4).
    #[getter]
    fn odometry_truth<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        odometry(py, &self.run.odometry_truth)
    }

    /// The board's byte stream as received (all chunks concatenated).
    #[getter]
    fn stream<'py>(&self, py: Python<'py>) -> Bound<'py, PyBytes> {
        PyBytes::new(py, &self.run.stream_bytes())
    }

    /// Ground truth as JSON text (trajectory, landmarks, true C).
    fn truth_json(&self) -> String {
        self.run.truth_json()
    }

    /// Writes the vehicle log (MCAP). The GIL is released while writing.
    fn write_log(&self, py: Python<'_>, path: PathBuf) -> PyResult<()> {
        py.detach(|| self.run.write_log(&path))
            .map_err(|e| input_error(py, e.to_string()))
    }
}

#[allow(clippy::cast_precision_loss)] // microsecond timestamps far below 2^53
fn odometry<'py>(py: Python<'py>, samples: &[sim::OdomSample]) -> Bound<'py, PyArray2<f64>> {
    Array2::from_shape_fn((samples.len(), 4), |(i, k)| {
        let s = &samples[i];
        [s.t_us as f64, s.vx, s.vy, s.vtheta][k]
    })
    .into_pyarray(py)
}

/// Simulates a scenario file (fast mode, or rendered images through the board's detector);
/// `seed` overrides the scenario's. The GIL is released while simulating. Raises
/// `stereonav.InputError` for a bad scenario, naming the file, the key and the problem.
#[pyfunction]
#[pyo3(signature = (scenario, rendered, seed=None))]
pub(crate) fn simulate(
    py: Python<'_>,
    scenario: PathBuf,
    rendered: bool,
    seed: Option<u64>,
) -> PyResult<SimRun> {
    let mut scenario =
        sim::Scenario::load(&scenario).map_err(|e| input_error(py, e.to_string()))?;
    if let Some(seed) = seed {
        scenario.spec.seed = seed;
    }
    let mode = if rendered {
        sim::Mode::Rendered
    } else {
        sim::Mode::Fast
    };
    let run = py
        .detach(|| sim::simulate(&scenario, mode))
        .map_err(|e| input_error(py, e.to_string()))?;
    Ok(SimRun { run })
}
