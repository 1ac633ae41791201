//! The stereo rig model (`vehicle-interfaces.md` sections 1 and 3) for Python: projection with
//! Jacobians and triangulation over NumPy arrays, and rig files.

use nalgebra::Vector3;
use numpy::ndarray::{Array2, Array3};
use numpy::{IntoPyArray, PyArray1, PyArray2, PyArray3, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use rig_model::{CameraParams, N_CAMERA, Param, Pose2, Rig};

use crate::input_error;

/// The camera parameters from a 1-D array of the 10 values of C in `Param::CAMERA` order.
fn camera(py: Python<'_>, c: &PyReadonlyArray1<'_, f64>) -> PyResult<CameraParams> {
    let c = c.as_array();
    if c.len() != N_CAMERA {
        return Err(input_error(
            py,
            format!("camera has {} values, expected {N_CAMERA}", c.len()),
        ));
    }
    if let Some((i, v)) = c.iter().enumerate().find(|(_, v)| !v.is_finite()) {
        return Err(input_error(
            py,
            format!("camera {} is {v}, not a finite number", Param::CAMERA[i]),
        ));
    }
    Ok(crate::camera_from_values(
        &c.iter().copied().collect::<Vec<_>>(),
        &rig_model::Vehicle::NOMINAL,
    ))
}

fn pose(py: Python<'_>, p: &PyReadonlyArray1<'_, f64>) -> PyResult<Pose2> {
    let p = p.as_array();
    match p.as_slice() {
        Some(&[x, y, theta]) if x.is_finite() && y.is_finite() && theta.is_finite() => {
            Ok(Pose2::new(x, y, theta))
        }
        _ => Err(input_error(
            py,
            format!("pose must be 3 finite values (x, y, theta), got {p}"),
        )),
    }
}

fn rows<const N: usize>(
    py: Python<'_>,
    name: &str,
    a: &PyReadonlyArray2<'_, f64>,
) -> PyResult<Vec<[f64; N]>> {
    let a = a.as_array();
    if a.ncols() != N {
        return Err(input_error(
            py,
            format!("{name} has shape {:?}, expected (N, {N})", a.shape()),
        ));
    }
    let mut out = Vec::with_capacity(a.nrows());
    for (i, row) in a.rows().into_iter().enumerate() {
        let mut r = [0.0; N];
        for (k, v) in row.iter().enumerate() {
            if !v.is_finite() {
                return Err(input_error(
                    py,
                    format!("{name}[{i}, {k}] is {v}, not a finite number"),
                ));
            }
            r[k] = *v;
        }
        out.push(r);
    }
    Ok(out)
}

/// The measurements `(uL, vL, uR, vR)` of world landmarks `(N, 3)` seen from `pose` with camera
/// parameters `camera` (10 values), with the analytic Jacobians. Returns `(z (N, 4),
/// d_pose (N, 4, 3), d_landmark (N, 4, 3), d_camera (N, 4, 10))`; a landmark behind the
/// cameras gives NaN rows (and NaN Jacobians).
#[pyfunction]
#[allow(clippy::type_complexity)]
pub(crate) fn project<'py>(
    py: Python<'py>,
    landmarks: PyReadonlyArray2<'py, f64>,
    pose_xyt: PyReadonlyArray1<'py, f64>,
    camera_params: PyReadonlyArray1<'py, f64>,
) -> PyResult<(
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray3<f64>>,
    Bound<'py, PyArray3<f64>>,
    Bound<'py, PyArray3<f64>>,
)> {
    let c = camera(py, &camera_params)?;
    let pose = pose(py, &pose_xyt)?;
    let points = rows::<3>(py, "landmarks", &landmarks)?;
    let n = points.len();
    let mut z = Array2::from_elem((n, 4), f64::NAN);
    let mut jp = Array3::from_elem((n, 4, 3), f64::NAN);
    let mut jl = Array3::from_elem((n, 4, 3), f64::NAN);
    let mut jc = Array3::from_elem((n, 4, N_CAMERA), f64::NAN);
    for (i, p) in points.iter().enumerate() {
        let Ok((m, j)) = rig_model::project_with_jacobians(&c, &pose, &Vector3::from(*p)) else {
            continue;
        };
        for r in 0..4 {
            z[[i, r]] = m[r];
            for k in 0..3 {
                jp[[i, r, k]] = j.pose[(r, k)];
                jl[[i, r, k]] = j.landmark[(r, k)];
            }
            for k in 0..N_CAMERA {
                jc[[i, r, k]] = j.camera[(r, k)];
            }
        }
    }
    Ok((
        z.into_pyarray(py),
        jp.into_pyarray(py),
        jl.into_pyarray(py),
        jc.into_pyarray(py),
    ))
}

/// Triangulates stereo measurements `(N, 4)` = `(uL, vL, uR, vR)`. Returns `(p_in_rig (N, 3),
/// p_in_robot (N, 3), p_in_world (N, 3), cov_in_world (N, 3, 3))` for the robot at `pose` with
/// pixel noise `sigma_px`; rows with a non-positive disparity are NaN.
#[pyfunction]
#[allow(clippy::type_complexity)]
pub(crate) fn triangulate<'py>(
    py: Python<'py>,
    measurements: PyReadonlyArray2<'py, f64>,
    pose_xyt: PyReadonlyArray1<'py, f64>,
    camera_params: PyReadonlyArray1<'py, f64>,
    sigma_px: f64,
) -> PyResult<(
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray3<f64>>,
)> {
    let c = camera(py, &camera_params)?;
    let pose = pose(py, &pose_xyt)?;
    if !(sigma_px.is_finite() && sigma_px >= 0.0) {
        return Err(input_error(
            py,
            format!("sigma_px {sigma_px} must be finite and >= 0"),
        ));
    }
    let zs = rows::<4>(py, "measurements", &measurements)?;
    let n = zs.len();
    let mut rig = Array2::from_elem((n, 3), f64::NAN);
    let mut robot = Array2::from_elem((n, 3), f64::NAN);
    let mut world = Array2::from_elem((n, 3), f64::NAN);
    let mut cov = Array3::from_elem((n, 3, 3), f64::NAN);
    for (i, z) in zs.iter().enumerate() {
        let Ok(t) = rig_model::triangulate(&c, &rig_model::Measurement::from(*z)) else {
            continue;
        };
        let (pr, pw) = (t.p_in_robot(&c), t.p_in_world(&c, &pose));
        let cw = t.covariance_in_world(&c, &pose, sigma_px, None, None);
        for k in 0..3 {
            rig[[i, k]] = t.p_in_rig[k];
            robot[[i, k]] = pr[k];
            world[[i, k]] = pw[k];
            for l in 0..3 {
                cov[[i, k, l]] = cw[(k, l)];
            }
        }
    }
    Ok((
        rig.into_pyarray(py),
        robot.into_pyarray(py),
        world.into_pyarray(py),
        cov.into_pyarray(py),
    ))
}

/// Raw pixels `(N, 2)` of one camera (`"left"` or `"right"`) into the rectified rig model of
/// a rig file's `[lens.*]` tables (vehicle-interfaces.md 1.1): `(N, 2)`, NaN rows for points
/// that cannot be mapped; the input unchanged without lens tables. Raises
/// `stereonav.InputError` for a bad file, shape or camera name. The GIL is released.
#[pyfunction]
pub(crate) fn rectify_points<'py>(
    py: Python<'py>,
    points: PyReadonlyArray2<'py, f64>,
    path: std::path::PathBuf,
    camera: &str,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let rig = Rig::load(&path).map_err(|e| input_error(py, e.to_string()))?;
    let p = points.as_array();
    if p.ncols() != 2 {
        return Err(input_error(
            py,
            format!("points has shape {:?}, expected (N, 2)", p.shape()),
        ));
    }
    let lens = match (&rig.lens, camera) {
        (_, "left" | "right") => rig
            .lens
            .map(|l| if camera == "left" { l.left } else { l.right }),
        _ => {
            return Err(input_error(
                py,
                format!("camera {camera:?}: expected \"left\" or \"right\""),
            ));
        }
    };
    let owned = p.to_owned();
    let c = rig.nominal;
    let out = py.detach(move || {
        let Some(lens) = lens else {
            return owned;
        };
        let mut out = owned;
        for mut row in out.rows_mut() {
            let raw = nalgebra::Vector2::new(row[0], row[1]);
            let (u, v) = lens
                .rectify(raw, c.f, c.cx, c.cy)
                .map_or((f64::NAN, f64::NAN), |(q, _)| (q.x, q.y));
            row[0] = u;
            row[1] = v;
        }
        out
    });
    Ok(out.into_pyarray(py))
}

/// A rig file (`vehicle-interfaces.md` section 3), checked: image size, nominal camera, the
/// parameters to estimate, their priors and the noise model. Every function of the module that
/// needs a rig takes this object (see `stereonav.RigConfig`, which builds it).
#[pyclass(name = "Rig", module = "stereonav._native", frozen)]
pub(crate) struct PyRig {
    pub(crate) rig: Rig,
}

#[pymethods]
impl PyRig {
    /// A rig from the values of a rig file's tables, checked as the file is (the same
    /// `stereonav.InputError`, `source` naming the values in it).
    #[new]
    #[pyo3(signature = (*, width, height, nominal, estimate, prior, pixel_noise, velocity_noise, yaw_rate_noise, source))]
    #[allow(clippy::too_many_arguments)] // the fields of a rig file, by keyword
    fn new(
        py: Python<'_>,
        width: i64,
        height: i64,
        nominal: PyReadonlyArray1<'_, f64>,
        estimate: Vec<String>,
        prior: Vec<(String, f64)>,
        pixel_noise: f64,
        velocity_noise: f64,
        yaw_rate_noise: f64,
        source: &str,
    ) -> PyResult<Self> {
        let values = nominal.as_array();
        if values.len() != N_CAMERA {
            return Err(input_error(
                py,
                format!(
                    "{source}: nominal has {} values, expected {N_CAMERA}",
                    values.len()
                ),
            ));
        }
        let nominal = crate::camera_from_values(
            &values.iter().copied().collect::<Vec<_>>(),
            &rig_model::Vehicle::NOMINAL,
        );
        let estimate: Vec<&str> = estimate.iter().map(String::as_str).collect();
        let prior: Vec<(&str, f64)> = prior.iter().map(|(n, s)| (n.as_str(), *s)).collect();
        let values = rig_model::RigValues {
            width,
            height,
            nominal,
            estimate: &estimate,
            prior: &prior,
            noise: rig_model::Noise {
                pixel: pixel_noise,
                velocity: velocity_noise,
                yaw_rate: yaw_rate_noise,
            },
        };
        let rig = Rig::from_values(&values, source).map_err(|e| input_error(py, e.to_string()))?;
        Ok(Self { rig })
    }

    /// Reads a rig file (TOML); raises `stereonav.InputError` naming the file, the key and the
    /// problem.
    #[staticmethod]
    fn load(py: Python<'_>, path: std::path::PathBuf) -> PyResult<Self> {
        let rig = Rig::load(&path).map_err(|e| input_error(py, e.to_string()))?;
        Ok(Self { rig })
    }

    /// Image width, pixels.
    #[getter]
    fn width(&self) -> u32 {
        self.rig.width
    }

    /// Image height, pixels.
    #[getter]
    fn height(&self) -> u32 {
        self.rig.height
    }

    /// The nominal camera, 10 values in `CAMERA_PARAMETERS` order.
    #[getter]
    fn nominal<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        crate::camera_values(&self.rig.nominal).into_pyarray(py)
    }

    /// Names of the estimated parameters, in `CAMERA_PARAMETERS` order.
    #[getter]
    fn estimate(&self) -> Vec<&'static str> {
        self.rig.estimate.iter().map(|p| p.name()).collect()
    }

    /// 1-sigma prior of each estimated parameter, by name, in the order of `estimate`.
    #[getter]
    fn prior<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let out = PyDict::new(py);
        for p in &self.rig.estimate {
            if let Some(s) = self.rig.prior[p.index()] {
                out.set_item(p.name(), s)?;
            }
        }
        Ok(out)
    }

    /// Pixel noise of each of uL, vL, uR, vR (px, 1 sigma).
    #[getter]
    fn pixel_noise(&self) -> f64 {
        self.rig.noise.pixel
    }

    /// Odometry velocity noise per sample (m/s, 1 sigma).
    #[getter]
    fn velocity_noise(&self) -> f64 {
        self.rig.noise.velocity
    }

    /// Odometry yaw-rate noise per sample (rad/s, 1 sigma).
    #[getter]
    fn yaw_rate_noise(&self) -> f64 {
        self.rig.noise.yaw_rate
    }
}

/// The names of the 10 camera parameters, in the order of the camera arrays.
#[pyfunction]
pub(crate) fn camera_parameter_names() -> Vec<&'static str> {
    Param::CAMERA.iter().map(|p| p.name()).collect()
}

/// The names of the 4 vehicle parameters `V` (vehicle-interfaces.md 1.2), in SUMMARY.json's
/// `vehicle` order.
#[pyfunction]
pub(crate) fn vehicle_parameter_names() -> Vec<&'static str> {
    Param::VEHICLE.iter().map(|p| p.name()).collect()
}
