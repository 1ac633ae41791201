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
/// a rig's `[lens.*]` tables (vehicle-interfaces.md 1.1): `(N, 2)`, NaN rows for points
/// that cannot be mapped; the input unchanged without lens tables. Raises
/// `stereonav.InputError` for a bad file, shape or camera name. The GIL is released.
#[pyfunction]
pub(crate) fn rectify_points<'py>(
    py: Python<'py>,
    points: PyReadonlyArray2<'py, f64>,
    rig: PyRef<'py, PyRig>,
    camera: &str,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let rig = &rig.rig;
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

/// A rig file (`vehicle-interfaces.md` section 3), checked: every table the command line
/// reads (`[camera]`, `[mount]`, `[estimate]`, `[prior]`, `[noise]`, `[vehicle]`,
/// `[lens.*]`, `[board]`), held as the Rust rig itself. Every function of the module that
/// needs a rig takes this object, so that Python hands the native code exactly what the
/// command line's reading of the same file gives (`stereonav.RigConfig` wraps it).
#[pyclass(name = "Rig", module = "stereonav._native", frozen)]
pub(crate) struct PyRig {
    pub(crate) rig: Rig,
}

fn rig_result(py: Python<'_>, rig: Result<Rig, rig_model::RigFileError>) -> PyResult<PyRig> {
    rig.map(|rig| PyRig { rig })
        .map_err(|e| input_error(py, e.to_string()))
}

#[pymethods]
impl PyRig {
    /// Reads a rig file (TOML); raises `stereonav.InputError` naming the file, the key and the
    /// problem.
    #[staticmethod]
    fn load(py: Python<'_>, path: std::path::PathBuf) -> PyResult<Self> {
        rig_result(py, Rig::load(&path))
    }

    /// Parses a rig file's TOML text; `source` names it in errors.
    #[staticmethod]
    fn from_toml(py: Python<'_>, text: &str, source: &str) -> PyResult<Self> {
        rig_result(py, Rig::from_toml_str(text, source))
    }

    /// Parses the JSON form of a rig file (a log's `/rig` message); `source` names it in
    /// errors.
    #[staticmethod]
    fn from_json(py: Python<'_>, text: &str, source: &str) -> PyResult<Self> {
        rig_result(py, Rig::from_json_str(text, source))
    }

    /// A rig from a rig file's tables as a dict of dicts (`{"camera": {"width": 752, ...},
    /// ...}`, what `tables()` returns), checked as the file is; `source` names the values in
    /// errors. A value of a type a rig file cannot hold raises `stereonav.InputError` naming
    /// its key.
    #[staticmethod]
    fn from_tables(py: Python<'_>, tables: &Bound<'_, PyDict>, source: &str) -> PyResult<Self> {
        let root = table_from_py(py, tables, source, "")?;
        rig_result(py, Rig::from_toml_table(&root, source))
    }

    /// The rig file's tables as a dict of dicts: every table and key of this rig, as the
    /// rig file (or `to_toml()`) has them; `from_tables` gives the same rig back.
    fn tables<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        table_to_py(py, &self.rig.to_toml_table())
    }

    /// The rig file as TOML text (every table this rig has).
    fn to_toml(&self) -> String {
        self.rig.to_toml()
    }

    /// The rig file's tables as JSON (the form of a log's `/rig` message).
    fn to_json(&self) -> String {
        self.rig.to_json()
    }

    /// Whether the two rigs are the same in every table.
    fn __eq__(&self, other: &Self) -> bool {
        self.rig == other.rig
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

    /// The nominal vehicle parameters (`[vehicle]`), 4 values in `VEHICLE_PARAMETERS` order.
    #[getter]
    fn vehicle<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        Param::VEHICLE
            .iter()
            .map(|&p| self.rig.nominal.get(p))
            .collect::<Vec<f64>>()
            .into_pyarray(py)
    }

    /// Names of the estimated parameters, in `CAMERA_PARAMETERS` + `VEHICLE_PARAMETERS` order.
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

    /// Time constant of the odometry's velocity errors (s; 0: white).
    #[getter]
    fn velocity_tau(&self) -> f64 {
        self.rig.noise.velocity_tau
    }

    /// Time constant of the odometry's yaw-rate errors (s; 0: white).
    #[getter]
    fn yaw_rate_tau(&self) -> f64 {
        self.rig.noise.yaw_rate_tau
    }

    /// The board's `THRESHOLD` register for images the host detects on (`[board]`).
    #[getter]
    fn board_threshold(&self) -> i32 {
        self.rig.board.threshold
    }

    /// The board's `MAX_FEATURES` register (`[board]`).
    #[getter]
    fn board_max_features(&self) -> usize {
        self.rig.board.max_features
    }

    /// Whether the rig has `[lens.left]` and `[lens.right]` (raw board features).
    #[getter]
    fn has_lens(&self) -> bool {
        self.rig.lens.is_some()
    }
}

/// Every table of a rig file and its keys as the Rust reader reads them
/// (`rig_model::RIG_FILE_KEYS`): `[(table, [key, ...]), ...]`, `[prior]`'s keys being
/// parameter names. The Python tests check that `RigConfig` shows each of them.
#[pyfunction]
pub(crate) fn rig_file_keys() -> Vec<(&'static str, Vec<&'static str>)> {
    rig_model::RIG_FILE_KEYS
        .iter()
        .map(|(table, keys)| (*table, keys.to_vec()))
        .collect()
}

fn table_to_py<'py>(py: Python<'py>, table: &toml::Table) -> PyResult<Bound<'py, PyDict>> {
    let out = PyDict::new(py);
    for (key, value) in table {
        out.set_item(key, value_to_py(py, value)?)?;
    }
    Ok(out)
}

fn value_to_py<'py>(py: Python<'py>, value: &toml::Value) -> PyResult<Bound<'py, PyAny>> {
    use pyo3::IntoPyObjectExt;
    match value {
        toml::Value::String(s) => s.into_bound_py_any(py),
        toml::Value::Integer(i) => i.into_bound_py_any(py),
        toml::Value::Float(x) => x.into_bound_py_any(py),
        toml::Value::Boolean(b) => b.into_bound_py_any(py),
        toml::Value::Datetime(d) => d.to_string().into_bound_py_any(py),
        toml::Value::Array(items) => {
            let list = pyo3::types::PyList::empty(py);
            for item in items {
                list.append(value_to_py(py, item)?)?;
            }
            Ok(list.into_any())
        }
        toml::Value::Table(t) => Ok(table_to_py(py, t)?.into_any()),
    }
}

/// A dict of a rig's tables as TOML values; `at` is the dotted path of `dict` (for errors).
fn table_from_py(
    py: Python<'_>,
    dict: &Bound<'_, PyDict>,
    source: &str,
    at: &str,
) -> PyResult<toml::Table> {
    let mut out = toml::Table::new();
    for (key, value) in dict.iter() {
        let Ok(key) = key.extract::<String>() else {
            return Err(input_error(
                py,
                format!(
                    "{source}: {}: a table's keys must be strings, found {}",
                    if at.is_empty() { "tables" } else { at },
                    type_name(&key)
                ),
            ));
        };
        let path = if at.is_empty() {
            key.clone()
        } else {
            format!("{at}.{key}")
        };
        out.insert(key, value_from_py(py, &value, source, &path)?);
    }
    Ok(out)
}

fn value_from_py(
    py: Python<'_>,
    value: &Bound<'_, PyAny>,
    source: &str,
    at: &str,
) -> PyResult<toml::Value> {
    use pyo3::types::{PyBool, PyFloat, PyInt, PyList, PyString, PyTuple};
    if value.is_instance_of::<PyBool>() {
        return Ok(toml::Value::Boolean(value.extract()?));
    }
    if value.is_instance_of::<PyInt>() {
        return value
            .extract::<i64>()
            .map(toml::Value::Integer)
            .map_err(|_| {
                input_error(
                    py,
                    format!("{source}: {at}: {value} does not fit a 64-bit integer"),
                )
            });
    }
    if value.is_instance_of::<PyFloat>() {
        return Ok(toml::Value::Float(value.extract()?));
    }
    if value.is_instance_of::<PyString>() {
        return Ok(toml::Value::String(value.extract()?));
    }
    if let Ok(dict) = value.cast::<PyDict>() {
        return Ok(toml::Value::Table(table_from_py(py, dict, source, at)?));
    }
    if value.is_instance_of::<PyList>() || value.is_instance_of::<PyTuple>() {
        let mut items = Vec::new();
        for (i, item) in value.try_iter()?.enumerate() {
            items.push(value_from_py(py, &item?, source, &format!("{at}[{i}]"))?);
        }
        return Ok(toml::Value::Array(items));
    }
    // NumPy scalars and other numbers: integers first (`__index__`), then floats.
    if value.hasattr("__index__")?
        && let Ok(i) = value.extract::<i64>()
    {
        return Ok(toml::Value::Integer(i));
    }
    if let Ok(x) = value.extract::<f64>() {
        return Ok(toml::Value::Float(x));
    }
    Err(input_error(
        py,
        format!(
            "{source}: {at}: a rig file holds numbers, strings, lists and tables, found {}",
            type_name(value)
        ),
    ))
}

fn type_name(value: &Bound<'_, PyAny>) -> String {
    value
        .get_type()
        .qualname()
        .map_or_else(|_| "an object".to_string(), |n| n.to_string())
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
