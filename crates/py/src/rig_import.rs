//! `stereonav rig import` for Python (vehicle-interfaces.md section 5): a rig from a Kalibr,
//! ROS or OpenCV stereo calibration, read by the same library code as the command line
//! ([`rig_model::import`]), with the commented rig file the command line writes.
//!
//! The typed wrapper is `stereonav.import_rig` (`python/stereonav/rig.py`). A calibration
//! that cannot be imported raises `stereonav.InputError` with the command line's one-line
//! message (the file, the key and the problem). The files are read with the GIL released.

use std::path::PathBuf;

use pyo3::prelude::*;
use rig_model::import::{ImportError, Imported};

use crate::input_error;
use crate::rig::PyRig;

/// A calibration imported as a rig file (`rig_model::import::Imported`).
#[pyclass(module = "stereonav._native", frozen, get_all)]
pub(crate) struct ImportedRig {
    /// The rig, exactly as `toml` reads back.
    rig: Py<PyRig>,
    /// The commented rig file, byte for byte what `stereonav rig import --out` writes.
    toml: String,
    /// Where the calibration came from and how it was rectified.
    provenance: String,
    /// The line `stereonav rig import` prints after the file's name (f, cx, cy, baseline).
    summary: String,
    /// The command line's warning for a baseline over 2 (metres expected), else None.
    baseline_warning: Option<String>,
}

/// The Python result of an import, or `stereonav.InputError` with its message.
fn imported(py: Python<'_>, result: Result<Imported, ImportError>) -> PyResult<ImportedRig> {
    let imported = result.map_err(|e| input_error(py, e.to_string()))?;
    Ok(ImportedRig {
        toml: imported.to_toml(),
        provenance: imported.provenance().to_string(),
        summary: imported.summary(),
        baseline_warning: imported.baseline_warning(),
        rig: Py::new(
            py,
            PyRig {
                rig: imported.into_rig(),
            },
        )?,
    })
}

/// Kalibr's `camchain.yaml` (cam0 left, cam1 right) as a rig, rectified as OpenCV's
/// `stereoRectify`. Raises `stereonav.InputError`. The GIL is released.
#[pyfunction]
pub(crate) fn import_rig_kalibr(py: Python<'_>, path: PathBuf) -> PyResult<ImportedRig> {
    let result = py.detach(|| rig_model::import::import_kalibr(&path));
    imported(py, result)
}

/// The ROS `camera_info` YAML files of the left and the right camera (their `R` and `P` as
/// given) as a rig. Raises `stereonav.InputError`. The GIL is released.
#[pyfunction]
pub(crate) fn import_rig_ros(
    py: Python<'_>,
    left: PathBuf,
    right: PathBuf,
) -> PyResult<ImportedRig> {
    let result = py.detach(|| rig_model::import::import_ros(&left, &right));
    imported(py, result)
}

/// OpenCV's `FileStorage` YAML (`K1 D1 K2 D2 R T width height [model]`) as a rig, rectified
/// as OpenCV's `stereoRectify` (`fisheye.stereoRectify`). Raises `stereonav.InputError`. The
/// GIL is released.
#[pyfunction]
pub(crate) fn import_rig_opencv(py: Python<'_>, path: PathBuf) -> PyResult<ImportedRig> {
    let result = py.detach(|| rig_model::import::import_opencv(&path));
    imported(py, result)
}
