//! `stereonav localize` for Python: a vehicle log run on a saved map (`replay::localize_log`,
//! vehicle-interfaces.md section 5) with the outputs `SUMMARY.json` and `TRAJ.csv` of the
//! command line, and the map with the run's new lamps (`--save-map`).
//!
//! The map is read by crate `map-file` (the checks of `stereonav localize`); the run goes with
//! the GIL released. Every frame comes back as columns that the typed wrapper of
//! `python/stereonav/localization.py` turns into a structured array. A map, log or rig that
//! cannot be used raises `stereonav.InputError` naming the file and the problem.

use std::path::PathBuf;

use numpy::ndarray::{Array2, Array3};
use numpy::{IntoPyArray, PyArray1, PyArray2, PyArray3};
use pyo3::prelude::*;
use replay::{LocalizeEnd, LocalizedFrame, LocalizedTrajectoryWriter, LocalizerSettings};

use crate::FileError;
use crate::calibration::file_error;
use crate::rig::PyRig;

/// The lamps a run saw that are not in the map: positions (K, 3), covariances (K, 3, 3),
/// observations (K,).
type NewLampTuple<'py> = (
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray3<f64>>,
    Bound<'py, PyArray1<u64>>,
);

/// The vehicle log at `log_path` on the saved map at `map_path`, as `stereonav localize`
/// runs it: the vehicle may start anywhere in the map, poses are in the map's frame.
///
/// `rig` None uses the rig the map was made with (the camera's calibration always comes from
/// the map). `save_map` writes the map with the lamps this run found that are not in it, as
/// `--save-map`. `left`, `right` and `odom` (all three or none) name a ROS 2 bag's topics, as
/// for `replay`. Raises `stereonav.InputError` for a map that cannot be read (not a map, a
/// newer version, damaged) or cannot localise, a log that cannot be read or is not a vehicle
/// log, topics named badly or missing from the bag, or an output that cannot be written. The
/// GIL is released.
#[pyfunction]
#[pyo3(
    name = "localize",
    signature = (log_path, map_path, rig, save_map, left = None, right = None, odom = None)
)]
#[allow(clippy::too_many_arguments)] // the Python call's keywords, checked by its wrapper
pub(crate) fn localize_log(
    py: Python<'_>,
    log_path: PathBuf,
    map_path: PathBuf,
    rig: Option<PyRef<'_, PyRig>>,
    save_map: Option<PathBuf>,
    left: Option<String>,
    right: Option<String>,
    odom: Option<String>,
) -> PyResult<LocalizeResult> {
    let topics =
        crate::bags::ros2_topics(left, right, odom).map_err(|e| crate::input_error(py, e))?;
    let rig = rig.map(|r| r.rig.clone());
    py.detach(|| -> Result<LocalizeResult, FileError> {
        let map = map_file::Map::load(&map_path)?;
        let mut frames = Vec::new();
        let end = replay::localize_log(
            &log_path,
            topics.as_ref(),
            &map,
            rig,
            LocalizerSettings::default(),
            &mut |f| {
                frames.push(*f);
                Ok(())
            },
            &mut |_, _| {},
        )?;
        if let Some(path) = &save_map {
            replay::map_with_new_lamps(&map, &end, &log_path).save(path)?;
        }
        Ok(LocalizeResult { end, frames })
    })
    .map_err(|e| file_error(py, &*e))
}

/// Every frame of a localisation run, one row a frame (`replay::LocalizedFrame`).
#[pyclass(module = "stereonav._native", frozen, get_all)]
pub(crate) struct LocalizedFrames {
    /// `(F,)`: the frame's time.
    t_us: Py<PyArray1<u64>>,
    /// `(F, 3)`: the pose `X, Y, theta` in the map's frame, NaN when there is no guess.
    pose: Py<PyArray2<f64>>,
    /// `(F, 3)`: its 1-sigma in `X, Y, theta`, NaN without a pose.
    sigma: Py<PyArray2<f64>>,
    /// `(F,)`: the localiser stands behind the pose.
    localized: Py<PyArray1<bool>>,
    /// `(F,)`: map lamps associated at the frame.
    matched: Py<PyArray1<u32>>,
    /// `(F,)`: live relocalisation hypotheses.
    hypotheses: Py<PyArray1<u32>>,
}

impl LocalizedFrames {
    fn new(py: Python<'_>, frames: &[LocalizedFrame]) -> Self {
        let n = frames.len();
        let pose = |i: usize, k: usize| frames[i].pose.map_or(f64::NAN, |p| p[k]);
        Self {
            t_us: frames
                .iter()
                .map(|f| f.t_us)
                .collect::<Vec<_>>()
                .into_pyarray(py)
                .unbind(),
            pose: Array2::from_shape_fn((n, 3), |(i, k)| pose(i, k))
                .into_pyarray(py)
                .unbind(),
            sigma: Array2::from_shape_fn((n, 3), |(i, k)| frames[i].sigma[k])
                .into_pyarray(py)
                .unbind(),
            localized: frames
                .iter()
                .map(|f| f.localized)
                .collect::<Vec<_>>()
                .into_pyarray(py)
                .unbind(),
            matched: frames
                .iter()
                .map(|f| f.matched)
                .collect::<Vec<_>>()
                .into_pyarray(py)
                .unbind(),
            hypotheses: frames
                .iter()
                .map(|f| f.hypotheses)
                .collect::<Vec<_>>()
                .into_pyarray(py)
                .unbind(),
        }
    }
}

/// A whole log run on a map (`replay::LocalizeEnd` and every frame). Arrays are copied out on
/// access.
#[pyclass(module = "stereonav._native", frozen)]
pub(crate) struct LocalizeResult {
    end: LocalizeEnd,
    frames: Vec<LocalizedFrame>,
}

#[pymethods]
impl LocalizeResult {
    /// The content of `SUMMARY.json` (`replay::localize_summary_json`) as JSON text;
    /// non-finite numbers are `null`.
    fn summary_json(&self) -> String {
        replay::localize_summary_json(&self.end).to_string()
    }

    /// Every frame, as columns.
    #[getter]
    fn frames(&self, py: Python<'_>) -> LocalizedFrames {
        LocalizedFrames::new(py, &self.frames)
    }

    /// Each time the position was (re)gained, microseconds.
    #[getter]
    fn localized_t_us(&self) -> Vec<u64> {
        self.end.localized_t_us.clone()
    }

    /// Map landmark ids that should have been seen often and were not.
    #[getter]
    fn lamps_missing(&self) -> Vec<u64> {
        self.end.lamps_missing.clone()
    }

    /// The lamps seen that are not in the map: `(positions (K, 3), covariances (K, 3, 3),
    /// observations (K,))`.
    #[getter]
    fn new_lamps<'py>(&self, py: Python<'py>) -> NewLampTuple<'py> {
        let lamps = &self.end.new_lamps;
        let k = lamps.len();
        (
            Array2::from_shape_fn((k, 3), |(i, a)| lamps[i].position[a]).into_pyarray(py),
            Array3::from_shape_fn((k, 3, 3), |(i, a, b)| lamps[i].covariance[(a, b)])
                .into_pyarray(py),
            lamps
                .iter()
                .map(|l| u64::from(l.observations))
                .collect::<Vec<_>>()
                .into_pyarray(py),
        )
    }

    /// `[(name, count), ...]`: what was read and decoded.
    #[getter]
    fn counts(&self) -> Vec<(&'static str, u64)> {
        self.end.counts.named().to_vec()
    }

    /// What limits the result without stopping it, one line each.
    #[getter]
    fn warnings(&self) -> Vec<String> {
        self.end.warnings.clone()
    }

    /// Writes `SUMMARY.json` (`replay::write_summary_value`). Raises `stereonav.InputError`
    /// naming the file when it cannot be written. The GIL is released.
    fn write_summary(&self, py: Python<'_>, path: PathBuf) -> PyResult<()> {
        let end = &self.end;
        py.detach(|| replay::write_summary_value(&path, &replay::localize_summary_json(end)))
            .map_err(|e| file_error(py, &e))
    }

    /// Writes `TRAJ.csv` (`replay::LocalizedTrajectoryWriter`: `t_us,x,y,theta,localized`).
    /// Raises as `write_summary`.
    fn write_trajectory(&self, py: Python<'_>, path: PathBuf) -> PyResult<()> {
        let frames = &self.frames;
        py.detach(|| -> Result<(), replay::Error> {
            let mut out = LocalizedTrajectoryWriter::create(&path)?;
            for f in frames {
                out.frame(f)?;
            }
            out.finish()
        })
        .map_err(|e| file_error(py, &e))
    }

    /// Writes the localised frames' poses in the TUM format (`replay::TumWriter`, as
    /// `stereonav localize --trajectory-tum`). Raises as `write_summary`.
    fn write_trajectory_tum(&self, py: Python<'_>, path: PathBuf) -> PyResult<()> {
        let frames = &self.frames;
        py.detach(|| -> Result<(), replay::Error> {
            let mut out = replay::TumWriter::create(replay::TRAJ_TUM_FILE, &path)?;
            for f in frames {
                if let Some(pose) = f.localized_pose() {
                    out.pose(f.t_us, pose)?;
                }
            }
            out.finish()
        })
        .map_err(|e| file_error(py, &e))
    }
}
