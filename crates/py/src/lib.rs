//! `stereonav._native`: the Python extension module of stereonav (pyo3 + rust-numpy).
//!
//! This is the thin native layer under the typed wrapper `python/stereonav/__init__.py`; call
//! that instead. Each function takes NumPy arrays in and gives NumPy arrays out, runs the Rust
//! code with the GIL released, and maps every Rust error to a Python exception:
//!
//! * bad values (image size, `threshold`, `max_features` outside the board's ranges, see
//!   `board-icd.md` section 1) raise `stereonav.InputError`, a `ValueError` subclass, with the
//!   message of the Rust error, which names the value that was wrong;
//! * a wrong array type, dtype or number of dimensions is refused by the argument conversion
//!   with a `TypeError`.
//!
//! Nothing here panics on outside data, and `unsafe` code is forbidden.
#![forbid(unsafe_code)]
#![deny(missing_docs)]

mod bags;
mod calibration;
mod filter;
mod localization;
mod logs;
mod maps;
mod montecarlo;
mod navigator;
mod rig;
mod rig_import;
mod simulation;
mod stream;

use std::borrow::Cow;
use std::fmt;

use harris_core::{Feature, MAX_FEATURES_LIMIT, Registers};
use numpy::ndarray::ArrayView2;
use numpy::{PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray2};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::sync::PyOnceLock;
use pyo3::types::PyType;

/// Any error of a run that reads and writes files (a log, a map, an output), for
/// [`calibration::file_error`] to turn into `stereonav.InputError`.
pub(crate) type FileError = Box<dyn std::error::Error + Send + Sync>;

/// Bytes of one packed feature record: `x_q4` u16, `y_q4` u16, `r` i32, little-endian, as in
/// the board's feature stream (`board-icd.md` section 3).
pub const FEATURE_RECORD_BYTES: usize = 8;

/// Python module that defines the package's exception classes (pure Python, so that the
/// hierarchy under `stereonav.Error` can grow without touching this crate).
const ERRORS_MODULE: &str = "stereonav._errors";
/// The exception class raised for input values out of range (a `ValueError` subclass).
const INPUT_ERROR_CLASS: &str = "InputError";

/// `stereonav._errors.InputError`, imported on first use.
static INPUT_ERROR: PyOnceLock<Py<PyType>> = PyOnceLock::new();

/// An argument value the detector cannot take.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum InputError {
    /// `threshold` does not fit the signed 32-bit `THRESHOLD` register.
    Threshold {
        /// The value that was passed.
        threshold: i64,
    },
    /// `max_features` is negative or too large for this platform's `usize`.
    MaxFeatures {
        /// The value that was passed.
        max_features: i64,
    },
    /// The detector refused the registers or the image (out-of-range size or `max_features`).
    Detector(harris_core::Error),
}

impl fmt::Display for InputError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Threshold { threshold } => write!(
                f,
                "threshold {threshold} is outside the board's range {}..={} (signed 32-bit)",
                i32::MIN,
                i32::MAX
            ),
            Self::MaxFeatures { max_features } => write!(
                f,
                "max_features {max_features} is outside the board's range 1..={MAX_FEATURES_LIMIT}"
            ),
            Self::Detector(err) => err.fmt(f),
        }
    }
}

impl From<harris_core::Error> for InputError {
    fn from(err: harris_core::Error) -> Self {
        Self::Detector(err)
    }
}

impl InputError {
    /// The Python exception for this error: `stereonav.InputError` with this error's message,
    /// or a plain `ValueError` (caused by the import error) if that class cannot be imported.
    fn into_pyerr(self, py: Python<'_>) -> PyErr {
        input_error(py, self.to_string())
    }
}

/// `stereonav.InputError(message)`, or a plain `ValueError` (caused by the import error) if
/// that class cannot be imported.
pub(crate) fn input_error(py: Python<'_>, message: String) -> PyErr {
    match INPUT_ERROR.import(py, ERRORS_MODULE, INPUT_ERROR_CLASS) {
        Ok(class) => PyErr::from_type(class.clone(), message),
        Err(import_error) => {
            let err = PyValueError::new_err(message);
            err.set_cause(py, Some(import_error));
            err
        }
    }
}

/// The detector's registers for an image of `shape = (height, width)` (NumPy order) and the
/// given `THRESHOLD` and `MAX_FEATURES` values. Range checks of size and `MAX_FEATURES` are
/// left to the detector, which reports them with the expected range.
fn registers(
    shape: [usize; 2],
    threshold: i64,
    max_features: i64,
) -> Result<Registers, InputError> {
    let [height, width] = shape;
    let threshold = i32::try_from(threshold).map_err(|_| InputError::Threshold { threshold })?;
    let max_features =
        usize::try_from(max_features).map_err(|_| InputError::MaxFeatures { max_features })?;
    Ok(Registers {
        width,
        height,
        threshold,
        max_features,
    })
}

/// The pixels of `view` in row-major order: borrowed when the view is C-contiguous, otherwise
/// copied row by row (strided, transposed, Fortran-ordered or broadcast views).
fn row_major_pixels<'a>(view: &ArrayView2<'a, u8>) -> Cow<'a, [u8]> {
    if let Some(pixels) = view.to_slice() {
        return Cow::Borrowed(pixels);
    }
    let mut pixels = Vec::with_capacity(view.len());
    for row in view.rows() {
        match row.to_slice() {
            Some(contiguous) => pixels.extend_from_slice(contiguous),
            None => pixels.extend(row.iter().copied()),
        }
    }
    Cow::Owned(pixels)
}

/// Packs features into [`FEATURE_RECORD_BYTES`]-byte little-endian records, in the given order.
pub(crate) fn pack_features(features: &[Feature]) -> Vec<u8> {
    let mut packed = Vec::with_capacity(features.len() * FEATURE_RECORD_BYTES);
    for feature in features {
        packed.extend_from_slice(&feature.x_q4.to_le_bytes());
        packed.extend_from_slice(&feature.y_q4.to_le_bytes());
        packed.extend_from_slice(&feature.r.to_le_bytes());
    }
    packed
}

/// Runs the board's detector (ICD section 2) on a row-major image and packs its features.
/// Returns the packed records and the overflow flag.
fn detect_packed(pixels: &[u8], regs: &Registers) -> Result<(Vec<u8>, bool), harris_core::Error> {
    let detection = harris_core::detect(pixels, regs)?;
    Ok((pack_features(&detection.features), detection.overflow))
}

/// The board's Harris features of a 2-D `uint8` image (`board-icd.md` section 2), bit for bit.
///
/// Returns `(records, overflow)`: `records` is a 1-D `uint8` array of `8 * n` bytes, one packed
/// little-endian record `x_q4` (u16), `y_q4` (u16), `r` (i32) per feature in the board's
/// (raster) order, at most `max_features` of them; `overflow` is the camera's overflow flag.
/// Raises `stereonav.InputError` (a `ValueError`) for an image size, `threshold` or
/// `max_features` outside the board's ranges. The GIL is released while the detector runs.
#[pyfunction]
fn harris<'py>(
    py: Python<'py>,
    image: PyReadonlyArray2<'py, u8>,
    threshold: i64,
    max_features: i64,
) -> PyResult<(Bound<'py, PyArray1<u8>>, bool)> {
    let view = image.as_array();
    let shape = [view.nrows(), view.ncols()];
    let regs = registers(shape, threshold, max_features).map_err(|e| e.into_pyerr(py))?;
    let (packed, overflow) = py
        .detach(|| detect_packed(&row_major_pixels(&view), &regs))
        .map_err(|e| InputError::from(e).into_pyerr(py))?;
    Ok((PyArray1::from_vec(py, packed), overflow))
}

/// The board's Harris response map `r(x, y)` (ICD step 3) of a 2-D `uint8` image.
///
/// Returns a C-contiguous `int32` array of the image's shape `(H, W)`, zero outside
/// `3 <= x <= W - 4`, `3 <= y <= H - 4` where the board computes no response. Raises
/// `stereonav.InputError` (a `ValueError`) for an image size outside the board's range. The GIL
/// is released while the responses are computed.
#[pyfunction]
fn harris_response<'py>(
    py: Python<'py>,
    image: PyReadonlyArray2<'py, u8>,
) -> PyResult<Bound<'py, PyArray2<i32>>> {
    let view = image.as_array();
    let shape = [view.nrows(), view.ncols()];
    // Threshold and max_features do not matter for the response map; the defaults are valid.
    let regs = Registers {
        width: shape[1],
        height: shape[0],
        ..Registers::default()
    };
    let map = py
        .detach(|| harris_core::response_map(&row_major_pixels(&view), &regs))
        .map_err(|e| InputError::from(e).into_pyerr(py))?;
    PyArray1::from_vec(py, map).reshape(shape)
}

/// The native module `stereonav._native`.
#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add("FEATURE_RECORD_BYTES", FEATURE_RECORD_BYTES)?;
    m.add_function(wrap_pyfunction!(harris, m)?)?;
    m.add_function(wrap_pyfunction!(harris_response, m)?)?;
    m.add_class::<stream::StreamDecoder>()?;
    m.add_class::<stream::Frame>()?;
    m.add_function(wrap_pyfunction!(rig::project, m)?)?;
    m.add_function(wrap_pyfunction!(rig::triangulate, m)?)?;
    m.add_class::<rig::PyRig>()?;
    m.add_function(wrap_pyfunction!(rig::rectify_points, m)?)?;
    m.add_function(wrap_pyfunction!(rig::rig_file_keys, m)?)?;
    m.add_function(wrap_pyfunction!(rig::camera_parameter_names, m)?)?;
    m.add_function(wrap_pyfunction!(rig::vehicle_parameter_names, m)?)?;
    m.add_class::<simulation::SimRun>()?;
    m.add_function(wrap_pyfunction!(simulation::simulate, m)?)?;
    m.add_function(wrap_pyfunction!(stream::encode_packet, m)?)?;
    m.add_class::<calibration::CalibrationResult>()?;
    m.add_class::<calibration::SelfCalibrator>()?;
    m.add_class::<calibration::LogCalibrationResult>()?;
    m.add_function(wrap_pyfunction!(calibration::calibrate_log, m)?)?;
    m.add_function(wrap_pyfunction!(calibration::calibrate, m)?)?;
    m.add_function(wrap_pyfunction!(calibration::integrate_odometry, m)?)?;
    m.add_function(wrap_pyfunction!(calibration::frame_pairs, m)?)?;
    m.add_class::<calibration::PySolverSettings>()?;
    m.add_class::<calibration::PyStableRule>()?;
    m.add_class::<calibration::PyPairSettings>()?;
    m.add_class::<calibration::ParamObservability>()?;
    m.add_class::<calibration::Observability>()?;
    m.add_class::<calibration::Handover>()?;
    m.add_class::<calibration::CalibrationHistory>()?;
    m.add_class::<filter::Filter>()?;
    m.add_class::<filter::PyFilterSettings>()?;
    m.add_class::<filter::PyHealth>()?;
    m.add_class::<montecarlo::MonteCarloResult>()?;
    m.add_function(wrap_pyfunction!(montecarlo::monte_carlo, m)?)?;
    m.add_class::<navigator::Navigator>()?;
    m.add_class::<navigator::ReplayResult>()?;
    m.add_class::<navigator::ReplayFrames>()?;
    m.add_class::<navigator::FrameOutcome>()?;
    m.add_function(wrap_pyfunction!(navigator::replay_log, m)?)?;
    m.add_function(wrap_pyfunction!(navigator::phase_names, m)?)?;
    m.add_class::<logs::LogContents>()?;
    m.add_class::<logs::LogDamage>()?;
    m.add_class::<logs::LostSpan>()?;
    m.add_function(wrap_pyfunction!(logs::read_log, m)?)?;
    m.add_class::<bags::BagContents>()?;
    m.add_class::<bags::BagFrame>()?;
    m.add_class::<bags::ImageCounts>()?;
    m.add_function(wrap_pyfunction!(bags::read_bag, m)?)?;
    m.add_function(wrap_pyfunction!(bags::decode_image, m)?)?;
    m.add("MAP_VERSION", map_file::VERSION)?;
    m.add("ODOMETRY_LOOKAHEAD_US", nav::ODOMETRY_LOOKAHEAD_US)?;
    m.add_function(wrap_pyfunction!(maps::read_map, m)?)?;
    m.add_function(wrap_pyfunction!(maps::write_map, m)?)?;
    m.add_function(wrap_pyfunction!(maps::import_map, m)?)?;
    m.add("DEFAULT_LAMP_SIGMA_M", map_file::DEFAULT_LAMP_SIGMA_M)?;
    m.add_class::<localization::LocalizeResult>()?;
    m.add_class::<localization::LocalizedFrames>()?;
    m.add_function(wrap_pyfunction!(localization::localize_log, m)?)?;
    m.add_class::<rig_import::ImportedRig>()?;
    m.add_function(wrap_pyfunction!(rig_import::import_rig_kalibr, m)?)?;
    m.add_function(wrap_pyfunction!(rig_import::import_rig_ros, m)?)?;
    m.add_function(wrap_pyfunction!(rig_import::import_rig_opencv, m)?)?;
    Ok(())
}

/// A camera from the ten values of `C` in [`rig_model::Param::CAMERA`] order (the Python
/// arrays hold C only) and the vehicle's parameters `vehicle`.
pub(crate) fn camera_from_values(
    values: &[f64],
    vehicle: &rig_model::Vehicle,
) -> rig_model::CameraParams {
    let mut c = rig_model::CameraParams::from_vector(&rig_model::ParamVector::zeros());
    c.vehicle = *vehicle;
    for (&p, &v) in rig_model::Param::CAMERA.iter().zip(values) {
        c.set(p, v);
    }
    c
}

/// The ten values of `C`, [`rig_model::Param::CAMERA`] order.
pub(crate) fn camera_values(c: &rig_model::CameraParams) -> Vec<f64> {
    rig_model::Param::CAMERA.iter().map(|&p| c.get(p)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use numpy::ndarray::{Array2, Axis, ShapeBuilder, Slice};

    /// A 32x32 image with one 4x4 bright lamp, as in harris-core's crate example.
    fn lamp_image() -> Array2<u8> {
        // (ndarray's `s!` macro expands to `#[allow(unsafe_code)]`, which `forbid` refuses.)
        let lamp = 14..18;
        Array2::from_shape_fn((32, 32), |(y, x)| {
            if lamp.contains(&y) && lamp.contains(&x) {
                255
            } else {
                0
            }
        })
    }

    #[test]
    fn records_are_packed_little_endian() {
        let features = [
            Feature {
                x_q4: 0x0102,
                y_q4: 0x0304,
                r: 0x0506_0708,
            },
            Feature {
                x_q4: 65535,
                y_q4: 0,
                r: -2,
            },
        ];
        assert_eq!(
            pack_features(&features),
            [
                0x02, 0x01, 0x04, 0x03, 0x08, 0x07, 0x06, 0x05, //
                0xff, 0xff, 0x00, 0x00, 0xfe, 0xff, 0xff, 0xff,
            ]
        );
    }

    #[test]
    fn contiguous_views_are_borrowed_and_others_copied_in_row_major_order() {
        let image = lamp_image();
        let view = image.view();
        assert!(matches!(row_major_pixels(&view), Cow::Borrowed(_)));

        let fortran = Array2::from_shape_vec((32, 32).f(), image.t().iter().copied().collect())
            .expect("32 * 32 pixels");
        assert_eq!(fortran, image);
        let pixels = row_major_pixels(&fortran.view());
        assert!(matches!(pixels, Cow::Owned(_)));
        assert_eq!(pixels.as_ref(), image.as_slice().expect("standard layout"));

        let strided = image
            .slice_axis(Axis(0), Slice::new(0, None, 2))
            .slice_axis_move(Axis(1), Slice::new(1, None, 3));
        assert_eq!(strided.dim(), (16, 11));
        let expected: Vec<u8> = strided.iter().copied().collect();
        assert_eq!(row_major_pixels(&strided).as_ref(), expected.as_slice());
    }

    #[test]
    fn registers_take_numpy_shape_order() {
        let regs = registers([480, 752], -5, 7).expect("valid");
        assert_eq!(
            regs,
            Registers {
                width: 752,
                height: 480,
                threshold: -5,
                max_features: 7
            }
        );
    }

    #[test]
    fn out_of_range_arguments_name_the_value() {
        let too_big = i64::from(i32::MAX) + 1;
        let err = registers([480, 752], too_big, 512).expect_err("threshold > i32::MAX");
        assert_eq!(err, InputError::Threshold { threshold: too_big });
        assert!(
            err.to_string().contains("threshold 2147483648 is outside"),
            "{err}"
        );

        let err = registers([480, 752], 0, -1).expect_err("negative max_features");
        assert!(
            err.to_string().contains("max_features -1 is outside"),
            "{err}"
        );

        let regs = registers([8, 752], 0, 512).expect("checked by the detector");
        let err = InputError::from(detect_packed(&[0; 8 * 752], &regs).expect_err("height 8"));
        assert!(
            err.to_string().contains("image height 8 is outside"),
            "{err}"
        );
    }

    /// Runs in an embedded interpreter, so the test binary must link libpython (pyo3's
    /// `extension-module` feature, which would stop that, stays off). Whether or not that
    /// interpreter can import `stereonav`, the error is a `ValueError` naming the value.
    #[test]
    fn input_errors_become_value_errors_even_without_the_package() {
        Python::initialize();
        Python::attach(|py| {
            let err = InputError::Threshold { threshold: 1 << 40 }.into_pyerr(py);
            assert!(err.is_instance_of::<PyValueError>(py), "{err}");
            assert!(
                err.to_string()
                    .contains("threshold 1099511627776 is outside"),
                "{err}"
            );
        });
    }

    #[test]
    fn a_lamp_gives_one_feature_at_its_centre() {
        let image = lamp_image();
        let regs = registers([32, 32], 1 << 18, 512).expect("valid");
        let pixels = row_major_pixels(&image.view());
        let (packed, overflow) = detect_packed(&pixels, &regs).expect("valid image");
        assert!(!overflow);
        assert_eq!(packed.len(), FEATURE_RECORD_BYTES);
        let x_q4 = u16::from_le_bytes([packed[0], packed[1]]);
        let y_q4 = u16::from_le_bytes([packed[2], packed[3]]);
        // The lamp covers pixels 14..=17, so its centre is at 15.5 = 248 / 16.
        assert!((i32::from(x_q4) - 248).abs() <= 2, "x_q4 = {x_q4}");
        assert!((i32::from(y_q4) - 248).abs() <= 2, "y_q4 = {y_q4}");
    }
}
