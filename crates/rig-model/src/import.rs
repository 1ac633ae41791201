//! Rig files from a lab stereo calibration (vehicle-interfaces.md section 5, `stereonav rig
//! import (--kalibr CAMCHAIN.yaml | --ros LEFT.yaml RIGHT.yaml | --opencv STEREO.yml) --out
//! RIG.toml`, and Python's `stereonav.import_rig`): a rig file with `[camera]` and
//! `[lens.left]` / `[lens.right]` from a stereo calibration.
//!
//! * Kalibr (`camchain.yaml`, [`import_kalibr`]): `cam0` is the left camera, `cam1` the right
//!   one; `pinhole` cameras with `radtan` or `equidistant` distortion; `cam1`'s `T_cn_cnm1`
//!   takes cam0 coordinates to cam1 coordinates (OpenCV's `R`, `T`).
//! * ROS (`camera_info` YAML of each camera, [`import_ros`]): `R` and `P` are used as given:
//!   `f`, `cx`, `cy` from the left `P`, the baseline `-P_right[0,3] / P_right[0,0]`.
//! * OpenCV (`FileStorage` YAML with `K1 D1 K2 D2 R T`, `width`, `height` and
//!   `model: equidistant` for `cv2.fisheye.stereoCalibrate`'s, else `plumb_bob`;
//!   [`import_opencv`]).
//!
//! Kalibr and OpenCV calibrations are rectified by [`crate::stereo_rectify`], as OpenCV's
//! `stereoRectify` (`fisheye.stereoRectify`) with `CALIB_ZERO_DISPARITY` and `alpha = 0`
//! (`balance = 0`) at the calibration's image size. The baseline is in the calibration's
//! length unit, taken as metres (Kalibr's and EuRoC's are; OpenCV's `T` is in the unit of
//! the calibration target's square size; [`Imported::baseline_warning`] says when it looks
//! like millimetres). The tables a calibration does not give (`[mount]`, `[estimate]`,
//! `[prior]`, `[noise]`) get defaults, commented for the user to fill in
//! ([`Imported::to_toml`]). That text is read back with [`Rig::from_toml_str`] before an
//! import succeeds, and [`Imported::rig`] is what it reads: the rig exactly as the written
//! file will load.
//!
//! Every error is one line naming the file, the key and the problem ([`ImportError`]).

mod yaml;

use std::fmt::Write as _;
use std::path::Path;

use nalgebra::{Matrix3, Matrix3x4, Vector3};

use crate::config::Rig;
use crate::lens::{Lens, LensModel, StereoLens};
use crate::rig_file::RigFileError;
use crate::stereo_rectify::{
    ROTATION_TOLERANCE, RawCamera, RectifyError, StereoCalibration, rotation_deviation,
    stereo_rectify,
};
use yaml::{Node, load_yaml};

/// The board's image sizes (the rig file's `[camera] width`, `height`).
const IMAGE_SIZES: std::ops::RangeInclusive<i64> = 16..=4095;
/// Two projection-matrix entries that must agree do so to this, pixels (ROS files print a
/// few digits fewer than double precision).
const PROJECTION_TOLERANCE_PX: f64 = 1e-3;
/// A baseline above this many units is most likely not in metres
/// ([`Imported::baseline_warning`]).
pub const LARGEST_PLAUSIBLE_BASELINE_M: f64 = 2.0;
/// The name the imported rig file goes by while it is read back ([`ImportError::NotLoadable`]).
const IMPORTED_RIG_NAME: &str = "the imported rig";

/// A calibration that cannot be imported; the one-line message names the file, the key and
/// the problem (the command line prints it after `stereonav: error: `).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum ImportError {
    /// The file could not be read (or is not UTF-8 text).
    #[error("cannot read {file}: {reason}")]
    Io {
        /// The file, as the caller named it.
        file: String,
        /// The operating system's reason.
        reason: String,
    },
    /// The text is not YAML.
    #[error("{file}: not a YAML file: {reason}")]
    Syntax {
        /// The file.
        file: String,
        /// The parser's reason, on one line.
        reason: String,
    },
    /// The file as a whole is not what the calibration needs (empty, not a mapping, one
    /// camera only, image sizes that differ, a projection matrix not of the rig model).
    #[error("{file}: {problem}")]
    File {
        /// The file.
        file: String,
        /// What is wrong with it.
        problem: String,
    },
    /// A key is missing, or its value has the wrong type, size or an impossible value.
    #[error("{file}: {key}: {problem}")]
    Key {
        /// The file.
        file: String,
        /// The key path, as `cam1.T_cn_cnm1` or `K1.data[0]`.
        key: String,
        /// What is wrong with it.
        problem: String,
    },
    /// The left and the right camera's files (ROS) do not agree.
    #[error("{left_file} is {left} and {right_file} {right}: {problem}")]
    Disagree {
        /// The left camera's file.
        left_file: String,
        /// What it says (`752 x 480`, `plumb_bob`).
        left: String,
        /// The right camera's file.
        right_file: String,
        /// What it says.
        right: String,
        /// Why they must agree.
        problem: &'static str,
    },
    /// The calibration cannot be rectified into the rig model.
    #[error("{file}: {reason}")]
    Rectify {
        /// The calibration file.
        file: String,
        /// Why, with the values that were wrong.
        #[source]
        reason: RectifyError,
    },
    /// The rig file made from the calibration does not load (a value the rig file refuses).
    #[error("the rig file made from the calibration does not load: {0}")]
    NotLoadable(#[source] RigFileError),
}

/// A calibration imported as a rig file: the rig and its commented TOML text.
#[derive(Debug, Clone, PartialEq)]
pub struct Imported {
    /// The rig, as [`Imported::to_toml`]'s text reads back.
    rig: Rig,
    /// Where it came from and how it was rectified, for the file's header.
    provenance: String,
    /// The rig file, commented.
    toml: String,
}

impl Imported {
    /// The rig, exactly as the file [`Imported::to_toml`] writes reads back: `[camera]` and
    /// `[lens.*]` from the calibration, the other tables' defaults.
    pub fn rig(&self) -> &Rig {
        &self.rig
    }

    /// The rig, as [`Imported::rig`].
    pub fn into_rig(self) -> Rig {
        self.rig
    }

    /// Where the calibration came from and how it was rectified
    /// (`Kalibr camchain camchain.yaml, rectified as OpenCV's stereoRectify with ...`).
    pub fn provenance(&self) -> &str {
        &self.provenance
    }

    /// The rig file (vehicle-interfaces.md section 3) that `stereonav rig import` writes,
    /// every number in full precision: a header saying where it came from, `[camera]` and
    /// `[lens.*]` from the calibration, and `[mount]`, `[estimate]`, `[prior]`, `[noise]`
    /// defaults marked `DEFAULT, fill in`.
    pub fn to_toml(&self) -> String {
        self.toml.clone()
    }

    /// One line on what was imported, as the command line prints it after the file's name:
    /// `f 436.2443 px, cx 364.4412, cy 256.9517, baseline 0.110078 m, plumb_bob lenses
    /// (provenance)`.
    pub fn summary(&self) -> String {
        let c = &self.rig.nominal;
        format!(
            "f {:.4} px, cx {:.4}, cy {:.4}, baseline {:.6} m, {} lenses ({})",
            c.f,
            c.cx,
            c.cy,
            c.baseline,
            self.rig.lens.map_or("no", |l| l.left.model.name()),
            self.provenance
        )
    }

    /// A warning when the baseline is over [`LARGEST_PLAUSIBLE_BASELINE_M`]: the rig file
    /// takes metres, and a calibration made in millimetres gives a thousand times too much.
    pub fn baseline_warning(&self) -> Option<String> {
        let baseline = self.rig.nominal.baseline;
        (baseline > LARGEST_PLAUSIBLE_BASELINE_M).then(|| {
            format!(
                "baseline {baseline} is over {LARGEST_PLAUSIBLE_BASELINE_M} m: the rig file \
                 takes metres (was the calibration made in millimetres?)"
            )
        })
    }
}

/// What a calibration gives the rig file, before the file is written.
#[derive(Debug)]
struct Calibrated {
    width: u32,
    height: u32,
    f: f64,
    cx: f64,
    cy: f64,
    baseline: f64,
    lens: StereoLens,
    /// Where it came from and how it was rectified, for the file's header.
    provenance: String,
}

impl Calibrated {
    /// The rig file's text, read back.
    fn imported(self) -> Result<Imported, ImportError> {
        let toml = rig_toml(&self);
        let rig = Rig::from_toml_str(&toml, IMPORTED_RIG_NAME).map_err(ImportError::NotLoadable)?;
        Ok(Imported {
            rig,
            provenance: self.provenance,
            toml,
        })
    }
}

// ---------------------------------------------------------------------------------------------
// What every format has: image sizes, camera matrices, lenses, rotations

/// An image size in the board's range, from two integers.
fn image_size(node: &Node<'_>, width: i64, height: i64) -> Result<(u32, u32), ImportError> {
    let fits = |n: i64| {
        IMAGE_SIZES
            .contains(&n)
            .then(|| u32::try_from(n).ok())
            .flatten()
    };
    match (fits(width), fits(height)) {
        (Some(w), Some(h)) => Ok((w, h)),
        _ => Err(node.error(format!(
            "image size {width} x {height} is outside the board's range {}..={}",
            IMAGE_SIZES.start(),
            IMAGE_SIZES.end()
        ))),
    }
}

/// A camera matrix `[fx 0 cx; 0 fy cy; 0 0 1]` (row-major): `fx, fy, cx, cy`.
fn camera_matrix(node: &Node<'_>, k: &[f64]) -> Result<[f64; 4], ImportError> {
    let [fx, skew, cx, z0, fy, cy, z1, z2, one] = k else {
        return Err(node.error(format!("{} numbers; expected 9 (3 x 3)", k.len())));
    };
    if *skew != 0.0 || *z0 != 0.0 || *z1 != 0.0 || *z2 != 0.0 || *one != 1.0 {
        return Err(node.error(format!(
            "[{}] is not a camera matrix [fx 0 cx; 0 fy cy; 0 0 1] (skew and other entries \
             are not supported)",
            join(k)
        )));
    }
    if !(*fx > 0.0 && *fy > 0.0) {
        return Err(node.error(format!("focal lengths fx {fx}, fy {fy} must be positive")));
    }
    Ok([*fx, *fy, *cx, *cy])
}

fn join(values: &[f64]) -> String {
    values
        .iter()
        .map(|v| format!("{v}"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// The lens model for a model name and its coefficients (`plumb_bob`: `k1 k2 p1 p2 [k3]`,
/// and OpenCV's longer rational vectors when their extra terms are zero; `equidistant`:
/// `k1 k2 k3 k4`).
fn lens_model(node: &Node<'_>, fisheye: bool, d: &[f64]) -> Result<LensModel, ImportError> {
    if fisheye {
        let [k1, k2, k3, k4] = d else {
            return Err(node.error(format!(
                "{} coefficients; expected 4 (equidistant: k1 k2 k3 k4)",
                d.len()
            )));
        };
        return Ok(LensModel::Equidistant {
            k1: *k1,
            k2: *k2,
            k3: *k3,
            k4: *k4,
        });
    }
    match d {
        [k1, k2, p1, p2, rest @ ..] if matches!(rest.len(), 0 | 1 | 4 | 8 | 10) => {
            let k3 = rest.first().copied().unwrap_or(0.0);
            if let Some(extra) = rest.iter().skip(1).find(|x| **x != 0.0) {
                return Err(node.error(format!(
                    "{} coefficients with a non-zero term beyond k3 ({extra}): only plumb_bob \
                     k1 k2 p1 p2 [k3] is supported (not the rational, thin-prism or tilted \
                     models)",
                    d.len()
                )));
            }
            Ok(LensModel::PlumbBob {
                k1: *k1,
                k2: *k2,
                p1: *p1,
                p2: *p2,
                k3,
            })
        }
        _ => Err(node.error(format!(
            "{} coefficients; expected 4 or 5 (plumb_bob: k1 k2 p1 p2 [k3])",
            d.len()
        ))),
    }
}

/// A rotation matrix (row-major) to the rig file's tolerance.
fn rotation(node: &Node<'_>, m: &[f64]) -> Result<Matrix3<f64>, ImportError> {
    if m.len() != 9 {
        return Err(node.error(format!("{} numbers; expected 9 (3 x 3)", m.len())));
    }
    let r = Matrix3::from_row_slice(m);
    let (deviation, determinant) = rotation_deviation(&r);
    if !(deviation <= ROTATION_TOLERANCE && determinant > 0.0) {
        return Err(node.error(format!(
            "not a rotation matrix (R R^T differs from I by {deviation:.1e}, determinant \
             {determinant})"
        )));
    }
    Ok(r)
}

/// Rectifies a Kalibr or OpenCV calibration; its errors name the file.
fn rectified(
    file: &str,
    cal: &StereoCalibration,
    provenance: String,
) -> Result<Calibrated, ImportError> {
    let r = stereo_rectify(cal).map_err(|reason| ImportError::Rectify {
        file: file.to_string(),
        reason,
    })?;
    Ok(Calibrated {
        width: cal.width,
        height: cal.height,
        f: r.f,
        cx: r.cx,
        cy: r.cy,
        baseline: r.baseline,
        lens: r.lens,
        provenance,
    })
}

fn rectified_how(model: &LensModel) -> &'static str {
    match model {
        LensModel::PlumbBob { .. } => {
            "rectified as OpenCV's stereoRectify with CALIB_ZERO_DISPARITY, alpha = 0"
        }
        LensModel::Equidistant { .. } => {
            "rectified as OpenCV's fisheye.stereoRectify with CALIB_ZERO_DISPARITY, balance = 0"
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Kalibr

/// One camera of a Kalibr camchain, and its image size.
fn kalibr_camera(cam: &Node<'_>) -> Result<(RawCamera, (u32, u32)), ImportError> {
    let model = cam.get("camera_model")?;
    let name = model.string()?;
    if name != "pinhole" {
        return Err(model.error(format!("unknown camera model {name:?} (known: pinhole)")));
    }
    let intrinsics = cam.get("intrinsics")?;
    let values = intrinsics.numbers()?;
    let [fx, fy, cx, cy] = values[..] else {
        return Err(intrinsics.error(format!(
            "{} numbers; expected 4 (fu fv pu pv)",
            values.len()
        )));
    };
    if !(fx > 0.0 && fy > 0.0) {
        return Err(intrinsics.error(format!("focal lengths fu {fx}, fv {fy} must be positive")));
    }
    let distortion = cam.get("distortion_model")?;
    let fisheye = match distortion.string()? {
        "radtan" => false,
        "equidistant" => true,
        other => {
            return Err(distortion.error(format!(
                "unknown distortion model {other:?} (known: radtan, equidistant)"
            )));
        }
    };
    let coeffs_node = cam.get("distortion_coeffs")?;
    let coeffs = coeffs_node.numbers_n(
        4,
        if fisheye {
            "k1 k2 k3 k4"
        } else {
            "k1 k2 r1 r2"
        },
    )?;
    let model = lens_model(&coeffs_node, fisheye, &coeffs)?;
    let resolution = cam.get("resolution")?;
    let size = resolution.items()?;
    let [w, h] = size.as_slice() else {
        return Err(resolution.error(format!("{} numbers; expected 2 (width height)", size.len())));
    };
    let size = image_size(&resolution, w.integer()?, h.integer()?)?;
    Ok((
        RawCamera {
            model,
            fx,
            fy,
            cx,
            cy,
        },
        size,
    ))
}

/// Imports Kalibr's `camchain.yaml`: `cam0` left, `cam1` right, `cam1`'s `T_cn_cnm1` as
/// OpenCV's `R`, `T`; rectified as OpenCV's `stereoRectify` (`fisheye.stereoRectify` for
/// `equidistant` lenses) with `CALIB_ZERO_DISPARITY`, `alpha = 0`.
pub fn import_kalibr(path: &Path) -> Result<Imported, ImportError> {
    let (file, yaml) = load_yaml(path)?;
    let root = Node::root(&file, &yaml);
    let cam0 = root.get("cam0")?;
    let Some(cam1) = root.get_opt("cam1")? else {
        return Err(root.error(
            "one camera only (no cam1): a stereo calibration has cam0 (left) and cam1 (right)",
        ));
    };
    let (left, left_size) = kalibr_camera(&cam0)?;
    let (right, right_size) = kalibr_camera(&cam1)?;
    if left_size != right_size {
        return Err(root.error(format!(
            "cam0's resolution {} x {} differs from cam1's {} x {}: the rig has one image size",
            left_size.0, left_size.1, right_size.0, right_size.1
        )));
    }
    let t_node = cam1.get("T_cn_cnm1")?;
    let rows = t_node.items()?;
    if rows.len() != 4 {
        return Err(t_node.error(format!("{} rows; expected a 4 x 4 matrix", rows.len())));
    }
    let mut t = Vec::with_capacity(16);
    for row in &rows {
        t.extend(row.numbers_n(4, "a row of the 4 x 4 matrix")?);
    }
    let last_row = t.get(12..16).unwrap_or_default();
    if last_row != [0.0, 0.0, 0.0, 1.0] {
        return Err(t_node.error(format!(
            "last row [{}]; expected [0, 0, 0, 1] (a rigid transform)",
            join(last_row)
        )));
    }
    let rotation_rows: Vec<f64> = [0..3, 4..7, 8..11]
        .into_iter()
        .flat_map(|r| t.get(r).unwrap_or_default().iter().copied())
        .collect();
    let right_from_left_rotation = rotation(&t_node, &rotation_rows)?;
    let at = |i: usize| t.get(i).copied().unwrap_or(f64::NAN);
    let cal = StereoCalibration {
        left,
        right,
        right_from_left_rotation,
        right_from_left_translation: Vector3::new(at(3), at(7), at(11)),
        width: left_size.0,
        height: left_size.1,
    };
    let how = rectified_how(&left.model);
    rectified(&file, &cal, format!("Kalibr camchain {file}, {how}"))?.imported()
}

// ---------------------------------------------------------------------------------------------
// ROS

/// One ROS `camera_info` file.
#[derive(Debug)]
struct RosCamera {
    file: String,
    lens: Lens,
    /// `P`, the rectified camera's projection matrix.
    projection: Matrix3x4<f64>,
    /// Width, height.
    size: (u32, u32),
}

/// Reads one ROS `camera_info` file.
fn ros_camera(path: &Path) -> Result<RosCamera, ImportError> {
    let (file, yaml) = load_yaml(path)?;
    let root = Node::root(&file, &yaml);
    let size = image_size(
        &root,
        root.get("image_width")?.integer()?,
        root.get("image_height")?.integer()?,
    )?;
    let k_node = root.get("camera_matrix")?;
    let [fx, fy, cx, cy] = camera_matrix(&k_node, &k_node.matrix_sized(3, 3)?)?;
    let model_node = root.get("distortion_model")?;
    let fisheye = match model_node.string()? {
        "plumb_bob" => false,
        "equidistant" => true,
        other => {
            return Err(model_node.error(format!(
                "unknown distortion model {other:?} (known: plumb_bob, equidistant)"
            )));
        }
    };
    let d_node = root.get("distortion_coefficients")?;
    let model = lens_model(&d_node, fisheye, &d_node.vector()?)?;
    let r_node = root.get("rectification_matrix")?;
    let rectification = rotation(&r_node, &r_node.matrix_sized(3, 3)?)?;
    let p_node = root.get("projection_matrix")?;
    let p = Matrix3x4::from_row_slice(&p_node.matrix_sized(3, 4)?);
    let lens = Lens {
        model,
        fx,
        fy,
        cx,
        cy,
        rectification,
    };
    Ok(RosCamera {
        file,
        lens,
        projection: p,
        size,
    })
}

/// Imports the ROS `camera_info` YAML files of the left and of the right camera, their `R`
/// and `P` as given: `f`, `cx`, `cy` from the left `P`, the baseline
/// `-P_right[0,3] / P_right[0,0]`. Both `P` must be the rig model's
/// (`[f 0 cx -f B; 0 f cy 0; 0 0 1 0]`, the same `f, cx, cy`, to 1e-3 px).
pub fn import_ros(left_path: &Path, right_path: &Path) -> Result<Imported, ImportError> {
    let RosCamera {
        file: left_file,
        lens: left,
        projection: p_left,
        size: left_size,
    } = ros_camera(left_path)?;
    let RosCamera {
        file: right_file,
        lens: right,
        projection: p_right,
        size: right_size,
    } = ros_camera(right_path)?;
    if left_size != right_size {
        return Err(ImportError::Disagree {
            left_file,
            left: format!("{} x {}", left_size.0, left_size.1),
            right_file,
            right: format!("{} x {}", right_size.0, right_size.1),
            problem: "the rig has one image size",
        });
    }
    if left.model.name() != right.model.name() {
        return Err(ImportError::Disagree {
            left_file,
            left: left.model.name().to_string(),
            right_file,
            right: right.model.name().to_string(),
            problem: "both lenses must have the same model",
        });
    }
    let (f, cx, cy) = (p_left[(0, 0)], p_left[(0, 2)], p_left[(1, 2)]);
    // Finite: every number read is.
    if f <= 0.0 {
        return Err(ImportError::Key {
            file: left_file,
            key: "projection_matrix".to_string(),
            problem: format!("focal length {f} must be positive"),
        });
    }
    // The rig model: both rectified cameras [f 0 cx -f B_i; 0 f cy 0; 0 0 1 0], B_left = 0.
    let expected = |tx: f64| Matrix3x4::new(f, 0.0, cx, tx, 0.0, f, cy, 0.0, 0.0, 0.0, 1.0, 0.0);
    for (file, p, tx) in [
        (&left_file, &p_left, 0.0),
        (&right_file, &p_right, p_right[(0, 3)]),
    ] {
        let off = (p - expected(tx)).amax();
        if off > PROJECTION_TOLERANCE_PX {
            return Err(ImportError::File {
                file: file.clone(),
                problem: format!(
                    "projection_matrix [{}] is not [f 0 cx {}; 0 f cy 0; 0 0 1 0] with the \
                     left camera's f {f}, cx {cx}, cy {cy} (off by {off:.3e}): stereonav needs \
                     a rectification with CALIB_ZERO_DISPARITY and the cameras side by side",
                    join(p.transpose().as_slice()),
                    if tx == 0.0 { "0" } else { "-f B" }
                ),
            });
        }
    }
    let baseline = -p_right[(0, 3)] / p_right[(0, 0)];
    if baseline <= 0.0 {
        return Err(ImportError::Key {
            file: right_file,
            key: "projection_matrix".to_string(),
            problem: format!(
                "baseline -P[0,3] / P[0,0] = {baseline}; expected positive (are LEFT.yaml and \
                 RIGHT.yaml swapped?)"
            ),
        });
    }
    Calibrated {
        width: left_size.0,
        height: left_size.1,
        f,
        cx,
        cy,
        baseline,
        lens: StereoLens { left, right },
        provenance: format!("ROS camera_info {left_file} and {right_file}, their R and P as given"),
    }
    .imported()
}

// ---------------------------------------------------------------------------------------------
// OpenCV

/// Imports OpenCV's `FileStorage` YAML with `K1 D1 K2 D2 R T`, `width`, `height` (and
/// `model: equidistant` for `cv2.fisheye.stereoCalibrate`'s, else `plumb_bob`), as
/// `cv2.stereoCalibrate` returns them; OpenCV 4's `%YAML:1.0` first line is read too.
/// Rectified as OpenCV's `stereoRectify` (`fisheye.stereoRectify`) with
/// `CALIB_ZERO_DISPARITY`, `alpha = 0`.
pub fn import_opencv(path: &Path) -> Result<Imported, ImportError> {
    let (file, yaml) = load_yaml(path)?;
    let root = Node::root(&file, &yaml);
    let fisheye = match root.get_opt("model")? {
        None => false,
        Some(node) => match node.string()? {
            "plumb_bob" => false,
            "equidistant" => true,
            other => {
                return Err(node.error(format!(
                    "unknown model {other:?} (known: plumb_bob, equidistant)"
                )));
            }
        },
    };
    let size = image_size(
        &root,
        root.get("width")?.integer()?,
        root.get("height")?.integer()?,
    )?;
    let camera = |k: &str, d: &str| -> Result<RawCamera, ImportError> {
        let k_node = root.get(k)?;
        let [fx, fy, cx, cy] = camera_matrix(&k_node, &k_node.matrix_sized(3, 3)?)?;
        let d_node = root.get(d)?;
        let model = lens_model(&d_node, fisheye, &d_node.vector()?)?;
        Ok(RawCamera {
            model,
            fx,
            fy,
            cx,
            cy,
        })
    };
    let left = camera("K1", "D1")?;
    let right = camera("K2", "D2")?;
    let r_node = root.get("R")?;
    let right_from_left_rotation = rotation(&r_node, &r_node.matrix_sized(3, 3)?)?;
    let t_node = root.get("T")?;
    let t = t_node.vector()?;
    let [x, y, z] = t[..] else {
        return Err(t_node.error(format!(
            "{} numbers; expected 3 (a 3 x 1 translation)",
            t.len()
        )));
    };
    let cal = StereoCalibration {
        left,
        right,
        right_from_left_rotation,
        right_from_left_translation: Vector3::new(x, y, z),
        width: size.0,
        height: size.1,
    };
    let how = rectified_how(&left.model);
    rectified(&file, &cal, format!("OpenCV FileStorage {file}, {how}"))?.imported()
}

// ---------------------------------------------------------------------------------------------
// The rig file

/// The rig file (vehicle-interfaces.md section 3), every number in full precision.
fn rig_toml(calibrated: &Calibrated) -> String {
    let mut out = String::new();
    let Calibrated {
        width,
        height,
        f,
        cx,
        cy,
        baseline,
        lens,
        provenance,
    } = calibrated;
    // `writeln!` into a String cannot fail.
    let _ = writeln!(
        out,
        "# Rig file (vehicle-interfaces.md section 3) written by `stereonav rig import` from\n\
         # {provenance}.\n\
         # [camera] and [lens.*] come from the calibration. [mount], [estimate], [prior] and\n\
         # [noise] are DEFAULTS that a calibration does not give: fill them in for the vehicle.\n\
         \n\
         [camera]          # the rectified left projection matrix P1 and the baseline\n\
         width = {width}\n\
         height = {height}\n\
         f = {f:?}   # px\n\
         cx = {cx:?}\n\
         cy = {cy:?}\n\
         baseline = {baseline:?}   # m (the calibration's length unit, taken as metres)\n\
         \n\
         [mount]           # DEFAULT, fill in: the rig in the robot frame, metres and radians\n\
         x = 0.0\n\
         y = 0.0\n\
         z = 1.0\n\
         roll = 0.0\n\
         pitch = 0.0\n\
         yaw = 0.0\n\
         \n\
         [estimate]        # DEFAULT, fill in: the parameters to estimate on the vehicle\n\
         parameters = [\"baseline\"]\n\
         \n\
         [prior]           # DEFAULT, fill in: 1-sigma uncertainty of each estimated value\n\
         baseline = 0.005   # m\n\
         \n\
         [noise]           # DEFAULT, fill in: the board's raw pixel noise and the odometry's\n\
         pixel = 0.3       # px, 1 sigma, each raw feature coordinate\n\
         velocity = 0.02   # m/s, 1 sigma per odometry sample, each of vx vy\n\
         yaw_rate = 0.01   # rad/s, 1 sigma per odometry sample"
    );
    for (side, which, l) in [("left", "R1", &lens.left), ("right", "R2", &lens.right)] {
        let (model, coefficients): (_, Vec<f64>) =
            (l.model.name(), l.model.coefficients().collect());
        // The comments line up with the other tables' (column 19).
        let pad = " ".repeat(18usize.saturating_sub("[lens.]".len() + side.len()));
        let r = &l.rectification;
        let rows: Vec<String> = (0..3)
            .map(|i| format!("{:?}, {:?}, {:?}", r[(i, 0)], r[(i, 1)], r[(i, 2)]))
            .collect();
        let _ = writeln!(
            out,
            "\n[lens.{side}]{pad}# the raw {side} camera\n\
             model = \"{model}\"\n\
             fx = {:?}\n\
             fy = {:?}\n\
             cx = {:?}\n\
             cy = {:?}\n\
             coefficients = [{}]   # {}\n\
             rectification = [{}]   # {which}, row-major",
            l.fx,
            l.fy,
            l.cx,
            l.cy,
            coefficients
                .iter()
                .map(|c| format!("{c:?}"))
                .collect::<Vec<_>>()
                .join(", "),
            if model == "plumb_bob" {
                "k1 k2 p1 p2 k3"
            } else {
                "k1 k2 k3 k4"
            },
            rows.join(",  ")
        );
    }
    out
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::indexing_slicing)]
mod tests {
    use std::path::PathBuf;

    use saphyr::{LoadableYamlNode, YamlOwned};

    use super::*;

    /// A calibration file in the temporary directory, removed when dropped.
    struct TempFile(PathBuf);

    impl TempFile {
        fn new(name: &str, text: &[u8]) -> Self {
            let path = std::env::temp_dir()
                .join(format!("rig-model-import-{}-{name}", std::process::id()));
            std::fs::write(&path, text).unwrap();
            Self(path)
        }

        fn name(&self) -> String {
            self.0.display().to_string()
        }
    }

    impl Drop for TempFile {
        fn drop(&mut self) {
            let _ = std::fs::remove_file(&self.0);
        }
    }

    /// EuRoC V1_01's two cameras as Kalibr's camchain.yaml.
    const CAMCHAIN: &str = "\
cam0:
  camera_model: pinhole
  distortion_coeffs: [-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05]
  distortion_model: radtan
  intrinsics: [458.654, 457.296, 367.215, 248.375]
  resolution: [752, 480]
cam1:
  T_cn_cnm1:
  - [0.9999972564778812, 0.0023120671924238864, 0.0003760081024155938, -0.11007380812718678]
  - [-0.0023171357232812354, 0.9998980485066438, 0.014089835846648196, 0.00039912154701414806]
  - [-0.0003433931205241621, -0.01409066845271459, 0.9999006626377283, -0.0008537025033580449]
  - [0.0, 0.0, 0.0, 1.0]
  camera_model: pinhole
  distortion_coeffs: [-0.28368365, 0.07451284, -0.00010473, -3.5559070e-05]
  distortion_model: radtan
  intrinsics: [457.587, 456.134, 379.999, 255.238]
  resolution: [752, 480]
";

    fn kalibr_error(name: &str, camchain: &str) -> (ImportError, String) {
        let file = TempFile::new(name, camchain.as_bytes());
        (import_kalibr(&file.0).unwrap_err(), file.name())
    }

    fn assert_one_line(err: &ImportError) -> String {
        let message = err.to_string();
        assert_eq!(message.lines().count(), 1, "{message:?}");
        message
    }

    #[test]
    fn a_kalibr_camchain_reads_back_as_written() {
        let file = TempFile::new("camchain.yaml", CAMCHAIN.as_bytes());
        let imported = import_kalibr(&file.0).unwrap();
        let toml = imported.to_toml();
        assert_eq!(
            Rig::from_toml_str(&toml, "rig.toml").unwrap(),
            *imported.rig()
        );
        assert!(toml.contains(&format!("Kalibr camchain {}", file.name())));
        assert!(toml.contains("DEFAULT, fill in"));
        let rig = imported.rig();
        assert_eq!((rig.width, rig.height), (752, 480));
        // OpenCV 5.0's cv2.stereoRectify of the same calibration.
        assert!((rig.nominal.f - 436.244295647102).abs() < 1e-4);
        assert!((rig.nominal.baseline - 0.1100778421917611).abs() < 1e-9);
        let lens = rig.lens.unwrap();
        assert_eq!(lens.left.fx, 458.654);
        assert_eq!(rig.estimate, vec![crate::Param::Baseline]);
        assert!(imported.summary().starts_with("f 436.2443 px, cx "));
        assert!(
            imported
                .summary()
                .contains("plumb_bob lenses (Kalibr camchain")
        );
        assert_eq!(imported.baseline_warning(), None);
        assert_eq!(imported.clone().into_rig(), *rig);
    }

    #[test]
    fn a_baseline_in_millimetres_is_warned_of() {
        let mm = CAMCHAIN
            .replace("-0.11007380812718678", "-110.07380812718678")
            .replace("0.00039912154701414806]", "0.39912154701414806]")
            .replace("-0.0008537025033580449", "-0.8537025033580449");
        let file = TempFile::new("mm.yaml", mm.as_bytes());
        let imported = import_kalibr(&file.0).unwrap();
        let warning = imported.baseline_warning().unwrap();
        assert!(warning.starts_with("baseline 110.07"), "{warning}");
        assert!(warning.ends_with("(was the calibration made in millimetres?)"));
    }

    #[test]
    fn a_missing_key_is_named_on_one_line() {
        let (err, file) = kalibr_error(
            "nointr.yaml",
            &CAMCHAIN.replacen(
                "  intrinsics: [458.654, 457.296, 367.215, 248.375]\n",
                "",
                1,
            ),
        );
        assert_eq!(
            err,
            ImportError::Key {
                file: file.clone(),
                key: "cam0.intrinsics".to_string(),
                problem: "missing key".to_string(),
            }
        );
        assert_eq!(
            assert_one_line(&err),
            format!("{file}: cam0.intrinsics: missing key")
        );
        let (err, file) = kalibr_error("cam0.yaml", CAMCHAIN.split("cam1:").next().unwrap());
        assert_eq!(
            assert_one_line(&err),
            format!(
                "{file}: one camera only (no cam1): a stereo calibration has cam0 (left) and \
                 cam1 (right)"
            )
        );
    }

    #[test]
    fn a_wrong_type_is_named_on_one_line() {
        let (err, file) = kalibr_error(
            "strintr.yaml",
            &CAMCHAIN.replacen("[458.654, 457.296, 367.215, 248.375]", "fast", 1),
        );
        assert_eq!(
            assert_one_line(&err),
            format!("{file}: cam0.intrinsics: expected a list, found string \"fast\"")
        );
        let (err, file) = kalibr_error("notnum.yaml", &CAMCHAIN.replacen("458.654", "abc", 1));
        assert_eq!(
            assert_one_line(&err),
            format!("{file}: cam0.intrinsics[0]: expected a number, found string \"abc\"")
        );
        let (err, file) = kalibr_error(
            "fsize.yaml",
            &CAMCHAIN.replacen("[752, 480]", "[752.5, 480]", 1),
        );
        assert_eq!(
            assert_one_line(&err),
            format!("{file}: cam0.resolution[0]: expected an integer, found number 752.5")
        );
    }

    #[test]
    fn unreadable_and_non_yaml_files_are_named_on_one_line() {
        let (err, file) = kalibr_error("bad.yaml", "cam0: [1, 2\n");
        assert!(matches!(err, ImportError::Syntax { .. }), "{err:?}");
        assert!(
            assert_one_line(&err).starts_with(&format!("{file}: not a YAML file: ")),
            "{err}"
        );
        let (err, file) = kalibr_error("list.yaml", "- 1\n- 2\n");
        assert_eq!(
            assert_one_line(&err),
            format!(
                "{file}: not a calibration file: expected a YAML mapping of keys, found a list \
                 of 2"
            )
        );
        let (err, file) = kalibr_error("empty.yaml", "");
        assert_eq!(assert_one_line(&err), format!("{file}: an empty YAML file"));
        let binary = TempFile::new("binary.yaml", &[0xff, 0xfe, 0x00, 0x12]);
        let err = import_opencv(&binary.0).unwrap_err();
        assert!(matches!(err, ImportError::Io { .. }), "{err:?}");
        assert!(assert_one_line(&err).starts_with(&format!("cannot read {}: ", binary.name())));
        let missing = Path::new("/no/such/left.yaml");
        let err = import_ros(missing, missing).unwrap_err();
        assert!(assert_one_line(&err).starts_with("cannot read /no/such/left.yaml: "));
    }

    #[test]
    fn rectification_errors_name_the_file() {
        let (err, file) = kalibr_error(
            "t0.yaml",
            &CAMCHAIN
                .replace("-0.11007380812718678", "0.0")
                .replace("0.00039912154701414806]", "0.0]")
                .replace("-0.0008537025033580449", "0.0"),
        );
        assert!(
            matches!(
                err,
                ImportError::Rectify {
                    reason: RectifyError::ZeroBaseline { .. },
                    ..
                }
            ),
            "{err:?}"
        );
        let message = assert_one_line(&err);
        assert!(message.starts_with(&format!("{file}: ")), "{message}");
        assert!(message.contains("has length 0"), "{message}");
    }

    #[test]
    fn lens_coefficients() {
        let doc = YamlOwned::load_from_str("a: 1").unwrap();
        let node = Node::root("f", &doc[0]);
        assert!(matches!(
            lens_model(&node, false, &[0.1, 0.2, 0.3, 0.4]).unwrap(),
            LensModel::PlumbBob { k3, .. } if k3 == 0.0
        ));
        // OpenCV's 8-term vector with the rational terms zero is plumb_bob.
        let mut eight = [0.0; 8];
        eight[4] = 0.01;
        assert!(matches!(
            lens_model(&node, false, &eight).unwrap(),
            LensModel::PlumbBob { k3, .. } if k3 == 0.01
        ));
        eight[5] = 0.5;
        assert!(
            lens_model(&node, false, &eight)
                .unwrap_err()
                .to_string()
                .contains("beyond k3 (0.5)")
        );
        assert!(lens_model(&node, true, &[0.1; 5]).is_err());
        assert!(lens_model(&node, false, &[0.1; 3]).is_err());
    }
}
