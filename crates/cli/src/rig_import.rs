//! `stereonav rig import (--kalibr CAMCHAIN.yaml | --ros LEFT.yaml RIGHT.yaml | --opencv
//! STEREO.yml) --out RIG.toml` (vehicle-interfaces.md section 5): a rig file with `[camera]`
//! and `[lens.left]` / `[lens.right]` from a stereo calibration.
//!
//! * Kalibr (`camchain.yaml`): `cam0` is the left camera, `cam1` the right one; `pinhole`
//!   cameras with `radtan` or `equidistant` distortion; `cam1`'s `T_cn_cnm1` takes cam0
//!   coordinates to cam1 coordinates (OpenCV's `R`, `T`).
//! * ROS (`camera_info` YAML of each camera): `R` and `P` are used as given: `f`, `cx`, `cy`
//!   from the left `P`, the baseline `-P_right[0,3] / P_right[0,0]`.
//! * OpenCV (`FileStorage` YAML with `K1 D1 K2 D2 R T`, `width`, `height` and
//!   `model: equidistant` for `cv2.fisheye.stereoCalibrate`'s, else `plumb_bob`).
//!
//! Kalibr and OpenCV calibrations are rectified by [`rig_model::stereo_rectify`], as OpenCV's
//! `stereoRectify` (`fisheye.stereoRectify`) with `CALIB_ZERO_DISPARITY` and `alpha = 0`
//! (`balance = 0`) at the calibration's image size. The baseline is in the calibration's
//! length unit, taken as metres (Kalibr's and EuRoC's are; OpenCV's `T` is in the unit of
//! the calibration target's square size). The tables a calibration does not give (`[mount]`,
//! `[estimate]`, `[prior]`, `[noise]`) get defaults, commented for the user to fill in. The
//! file written is read back with [`rig_model::Rig::from_toml_str`] before it is saved.

use std::fmt::Write as _;
use std::io::{self, Write};
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, anyhow, bail};
use nalgebra::{Matrix3, Matrix3x4, Vector3};
use rig_model::Rig;
use rig_model::lens::{Lens, LensModel, StereoLens};
use rig_model::stereo_rectify::{
    ROTATION_TOLERANCE, RawCamera, StereoCalibration, rotation_deviation, stereo_rectify,
};
use saphyr::{LoadableYamlNode, ScalarOwned, YamlOwned};

/// Arguments of `stereonav rig`.
#[derive(Debug, clap::Args)]
pub(crate) struct Args {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, clap::Subcommand)]
enum Command {
    /// Write a rig file from a stereo calibration by Kalibr, ROS or OpenCV: `[camera]` (the
    /// rectified f, cx, cy and baseline) and `[lens.*]` (the raw lenses and their
    /// rectification), with commented defaults for the other tables.
    Import(ImportArgs),
}

/// Arguments of `stereonav rig import`.
#[derive(Debug, clap::Args)]
#[command(group(
    clap::ArgGroup::new("calibration")
        .required(true)
        .args(["kalibr", "ros", "opencv"])
))]
struct ImportArgs {
    /// Kalibr's camchain.yaml: cam0 left, cam1 right (rectified as OpenCV's stereoRectify).
    #[arg(long, value_name = "CAMCHAIN.yaml")]
    kalibr: Option<PathBuf>,
    /// ROS camera_info YAML of the left and of the right camera (their R and P as given).
    #[arg(long, num_args = 2, value_names = ["LEFT.yaml", "RIGHT.yaml"])]
    ros: Option<Vec<PathBuf>>,
    /// OpenCV FileStorage YAML with K1 D1 K2 D2 R T width height [model] (rectified as
    /// OpenCV's stereoRectify, or fisheye.stereoRectify for `model: equidistant`).
    #[arg(long, value_name = "STEREO.yml")]
    opencv: Option<PathBuf>,
    /// The rig file to write.
    #[arg(long, value_name = "RIG.toml")]
    out: PathBuf,
}

/// The board's image sizes (the rig file's `[camera] width`, `height`).
const IMAGE_SIZES: std::ops::RangeInclusive<i64> = 16..=4095;
/// Two projection-matrix entries that must agree do so to this, pixels (ROS files print a
/// few digits fewer than double precision).
const PROJECTION_TOLERANCE_PX: f64 = 1e-3;
/// A baseline above this many units is most likely not in metres.
const LARGEST_PLAUSIBLE_BASELINE_M: f64 = 2.0;

pub(crate) fn run(args: &Args) -> Result<()> {
    match &args.command {
        Command::Import(import) => run_import(import),
    }
}

/// What an import gives the rig file.
#[derive(Debug)]
struct Imported {
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

fn run_import(args: &ImportArgs) -> Result<()> {
    let imported = if let Some(path) = &args.kalibr {
        import_kalibr(path)?
    } else if let Some(paths) = &args.ros {
        let [left, right] = paths.as_slice() else {
            bail!(
                "--ros takes two files, LEFT.yaml RIGHT.yaml; got {}",
                paths.len()
            );
        };
        import_ros(left, right)?
    } else if let Some(path) = &args.opencv {
        import_opencv(path)?
    } else {
        bail!("one of --kalibr, --ros or --opencv is required");
    };
    let text = rig_toml(&imported);
    let out = args.out.display().to_string();
    // What is written must load as written.
    Rig::from_toml_str(&text, &out)
        .map_err(|e| anyhow!("the rig file made from the calibration does not load: {e}"))?;
    std::fs::write(&args.out, &text).with_context(|| format!("cannot write {out}"))?;
    if imported.baseline > LARGEST_PLAUSIBLE_BASELINE_M {
        writeln!(
            io::stderr().lock(),
            "stereonav: warning: baseline {} is over {LARGEST_PLAUSIBLE_BASELINE_M} m: the rig \
             file takes metres (was the calibration made in millimetres?)",
            imported.baseline
        )?;
    }
    writeln!(
        io::stdout().lock(),
        "{out}: f {:.4} px, cx {:.4}, cy {:.4}, baseline {:.6} m, {} lenses ({})",
        imported.f,
        imported.cx,
        imported.cy,
        imported.baseline,
        imported.lens.left.model.name(),
        imported.provenance
    )?;
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// YAML

/// A node of an input file with its place in it, for errors that name the file and the key.
#[derive(Debug, Clone)]
struct Node<'a> {
    file: &'a str,
    /// The key path, `cam1.T_cn_cnm1`.
    key: String,
    yaml: &'a YamlOwned,
}

/// Reads and parses a YAML file; the root must be a mapping.
fn load_yaml(path: &Path) -> Result<(String, YamlOwned)> {
    let name = path.display().to_string();
    let text = std::fs::read_to_string(path).with_context(|| format!("cannot read {name}"))?;
    let text = without_opencv_directive(&text);
    let documents = YamlOwned::load_from_str(&text).map_err(|e| {
        anyhow!(
            "{name}: not a YAML file: {}",
            e.to_string()
                .split_whitespace()
                .collect::<Vec<_>>()
                .join(" ")
        )
    })?;
    let Some(root) = documents.into_iter().next() else {
        bail!("{name}: an empty YAML file");
    };
    if untagged(&root).as_mapping().is_none() {
        bail!(
            "{name}: not a calibration file: expected a YAML mapping of keys, found {}",
            describe(&root)
        );
    }
    Ok((name, root))
}

/// OpenCV's `FileStorage` before version 5 (and files made after it, such as EuRoC's
/// `sensor.yaml`) starts with `%YAML:1.0`, which is not a YAML directive (YAML's is
/// `%YAML 1.2`, with a space) and which every YAML parser rejects. That line alone is blanked
/// (the line numbers of parser errors stay right); the rest is plain YAML. OpenCV's
/// `!!opencv-matrix` tags need nothing: the parser keeps the tagged mapping, and
/// [`untagged`] looks through the tag.
fn without_opencv_directive(text: &str) -> std::borrow::Cow<'_, str> {
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let first = text.lines().next().unwrap_or("");
    if first.trim_end().starts_with("%YAML:") {
        std::borrow::Cow::Owned(format!("#{}", text))
    } else {
        std::borrow::Cow::Borrowed(text)
    }
}

/// The node under any tags (`!!opencv-matrix`).
fn untagged(yaml: &YamlOwned) -> &YamlOwned {
    match yaml {
        YamlOwned::Tagged(_, inner) => untagged(inner),
        other => other,
    }
}

fn describe(yaml: &YamlOwned) -> String {
    match untagged(yaml) {
        YamlOwned::Value(ScalarOwned::Null) => "null".to_string(),
        YamlOwned::Value(ScalarOwned::Boolean(b)) => format!("boolean {b}"),
        YamlOwned::Value(ScalarOwned::Integer(i)) => format!("integer {i}"),
        YamlOwned::Value(ScalarOwned::FloatingPoint(x)) => format!("number {x}"),
        YamlOwned::Value(ScalarOwned::String(s)) => format!("string {s:?}"),
        YamlOwned::Representation(s, _, _) => format!("{s:?}"),
        YamlOwned::Sequence(items) => format!("a list of {}", items.len()),
        YamlOwned::Mapping(_) => "a mapping".to_string(),
        YamlOwned::Alias(_) => "an alias (not supported)".to_string(),
        YamlOwned::Tagged(..) | YamlOwned::BadValue => "an unreadable value".to_string(),
    }
}

impl<'a> Node<'a> {
    fn root(file: &'a str, yaml: &'a YamlOwned) -> Self {
        Self {
            file,
            key: String::new(),
            yaml,
        }
    }

    /// An error naming the file and this key.
    fn error(&self, problem: impl std::fmt::Display) -> anyhow::Error {
        if self.key.is_empty() {
            anyhow!("{}: {problem}", self.file)
        } else {
            anyhow!("{}: {}: {problem}", self.file, self.key)
        }
    }

    fn child_key(&self, key: &str) -> String {
        if self.key.is_empty() {
            key.to_string()
        } else {
            format!("{}.{key}", self.key)
        }
    }

    /// The value of `key` in this mapping, if present.
    fn get_opt(&self, key: &str) -> Result<Option<Node<'a>>> {
        let Some(mapping) = untagged(self.yaml).as_mapping() else {
            return Err(self.error(format!("expected a mapping, found {}", describe(self.yaml))));
        };
        let found = mapping
            .iter()
            .find(|(k, _)| untagged(k).as_str() == Some(key))
            .map(|(_, v)| Node {
                file: self.file,
                key: self.child_key(key),
                yaml: v,
            });
        Ok(found)
    }

    /// The value of `key` in this mapping.
    fn get(&self, key: &str) -> Result<Node<'a>> {
        self.get_opt(key)?.ok_or_else(|| {
            let key = self.child_key(key);
            anyhow!("{}: {key}: missing key", self.file)
        })
    }

    /// A finite number (an integer counts).
    fn number(&self) -> Result<f64> {
        let x = match untagged(self.yaml) {
            YamlOwned::Value(ScalarOwned::FloatingPoint(x)) => x.into_inner(),
            #[allow(clippy::cast_precision_loss)] // calibration values are far below 2^53
            YamlOwned::Value(ScalarOwned::Integer(i)) => *i as f64,
            // OpenCV writes NaN as `.Nan`, which YAML 1.2's core schema reads as a string.
            YamlOwned::Value(ScalarOwned::String(s)) if s.eq_ignore_ascii_case(".nan") => f64::NAN,
            other => {
                return Err(self.error(format!("expected a number, found {}", describe(other))));
            }
        };
        if !x.is_finite() {
            return Err(self.error(format!("{x} is not a finite number")));
        }
        Ok(x)
    }

    fn integer(&self) -> Result<i64> {
        match untagged(self.yaml) {
            YamlOwned::Value(ScalarOwned::Integer(i)) => Ok(*i),
            other => Err(self.error(format!("expected an integer, found {}", describe(other)))),
        }
    }

    fn string(&self) -> Result<&'a str> {
        match untagged(self.yaml) {
            YamlOwned::Value(ScalarOwned::String(s)) => Ok(s.as_str()),
            other => Err(self.error(format!("expected a string, found {}", describe(other)))),
        }
    }

    fn items(&self) -> Result<Vec<Node<'a>>> {
        let YamlOwned::Sequence(items) = untagged(self.yaml) else {
            return Err(self.error(format!("expected a list, found {}", describe(self.yaml))));
        };
        Ok(items
            .iter()
            .enumerate()
            .map(|(i, yaml)| Node {
                file: self.file,
                key: format!("{}[{i}]", self.key),
                yaml,
            })
            .collect())
    }

    /// A list of finite numbers.
    fn numbers(&self) -> Result<Vec<f64>> {
        self.items()?.iter().map(Node::number).collect()
    }

    /// A list of exactly `n` numbers.
    fn numbers_n(&self, n: usize, what: &str) -> Result<Vec<f64>> {
        let v = self.numbers()?;
        if v.len() != n {
            return Err(self.error(format!("{} numbers; expected {n} ({what})", v.len())));
        }
        Ok(v)
    }

    /// A matrix written as `{rows, cols, data}` (ROS `camera_info`, OpenCV's
    /// `!!opencv-matrix`): `(rows, cols, data)` with `data` row-major.
    fn matrix(&self) -> Result<(usize, usize, Vec<f64>)> {
        let size = |key: &str| -> Result<usize> {
            let node = self.get(key)?;
            let n = node.integer()?;
            usize::try_from(n)
                .ok()
                .filter(|&n| (1..=64).contains(&n))
                .ok_or_else(|| node.error(format!("{n} is not a matrix size")))
        };
        let (rows, cols) = (size("rows")?, size("cols")?);
        let data = self.get("data")?.numbers()?;
        if data.len() != rows * cols {
            return Err(self.error(format!(
                "{rows} x {cols} matrix with {} numbers of data",
                data.len()
            )));
        }
        Ok((rows, cols, data))
    }

    /// A `rows x cols` matrix, row-major.
    fn matrix_sized(&self, rows: usize, cols: usize) -> Result<Vec<f64>> {
        let (r, c, data) = self.matrix()?;
        if (r, c) != (rows, cols) {
            return Err(self.error(format!("a {r} x {c} matrix; expected {rows} x {cols}")));
        }
        Ok(data)
    }

    /// A vector stored as a `1 x n` or `n x 1` matrix.
    fn vector(&self) -> Result<Vec<f64>> {
        let (r, c, data) = self.matrix()?;
        if r != 1 && c != 1 {
            return Err(self.error(format!("a {r} x {c} matrix; expected a vector (1 x n)")));
        }
        Ok(data)
    }
}

/// An image size in the board's range, from two integers.
fn image_size(node: &Node<'_>, width: i64, height: i64) -> Result<(u32, u32)> {
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
fn camera_matrix(node: &Node<'_>, k: &[f64]) -> Result<[f64; 4]> {
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
fn lens_model(node: &Node<'_>, fisheye: bool, d: &[f64]) -> Result<LensModel> {
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
fn rotation(node: &Node<'_>, m: &[f64]) -> Result<Matrix3<f64>> {
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
fn rectified(file: &str, cal: &StereoCalibration, provenance: String) -> Result<Imported> {
    let r = stereo_rectify(cal).map_err(|e| anyhow!("{file}: {e}"))?;
    Ok(Imported {
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
fn kalibr_camera(cam: &Node<'_>) -> Result<(RawCamera, (u32, u32))> {
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

fn import_kalibr(path: &Path) -> Result<Imported> {
    let (file, yaml) = load_yaml(path)?;
    let root = Node::root(&file, &yaml);
    let cam0 = root.get("cam0")?;
    let Some(cam1) = root.get_opt("cam1")? else {
        bail!(
            "{file}: one camera only (no cam1): a stereo calibration has cam0 (left) and cam1 (right)"
        );
    };
    let (left, left_size) = kalibr_camera(&cam0)?;
    let (right, right_size) = kalibr_camera(&cam1)?;
    if left_size != right_size {
        bail!(
            "{file}: cam0's resolution {} x {} differs from cam1's {} x {}: the rig has one image size",
            left_size.0,
            left_size.1,
            right_size.0,
            right_size.1
        );
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
    rectified(&file, &cal, format!("Kalibr camchain {file}, {how}"))
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
fn ros_camera(path: &Path) -> Result<RosCamera> {
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

fn import_ros(left_path: &Path, right_path: &Path) -> Result<Imported> {
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
        bail!(
            "{left_file} is {} x {} and {right_file} {} x {}: the rig has one image size",
            left_size.0,
            left_size.1,
            right_size.0,
            right_size.1
        );
    }
    if left.model.name() != right.model.name() {
        bail!(
            "{left_file} is {} and {right_file} {}: both lenses must have the same model",
            left.model.name(),
            right.model.name()
        );
    }
    let (f, cx, cy) = (p_left[(0, 0)], p_left[(0, 2)], p_left[(1, 2)]);
    // Finite: every number read is.
    if f <= 0.0 {
        bail!("{left_file}: projection_matrix: focal length {f} must be positive");
    }
    // The rig model: both rectified cameras [f 0 cx -f B_i; 0 f cy 0; 0 0 1 0], B_left = 0.
    let expected = |tx: f64| Matrix3x4::new(f, 0.0, cx, tx, 0.0, f, cy, 0.0, 0.0, 0.0, 1.0, 0.0);
    for (file, p, tx) in [
        (&left_file, &p_left, 0.0),
        (&right_file, &p_right, p_right[(0, 3)]),
    ] {
        let off = (p - expected(tx)).amax();
        if off > PROJECTION_TOLERANCE_PX {
            bail!(
                "{file}: projection_matrix [{}] is not [f 0 cx {}; 0 f cy 0; 0 0 1 0] with the \
                 left camera's f {f}, cx {cx}, cy {cy} (off by {off:.3e}): stereonav needs a \
                 rectification with CALIB_ZERO_DISPARITY and the cameras side by side",
                join(p.transpose().as_slice()),
                if tx == 0.0 { "0" } else { "-f B" }
            );
        }
    }
    let baseline = -p_right[(0, 3)] / p_right[(0, 0)];
    if baseline <= 0.0 {
        bail!(
            "{right_file}: projection_matrix: baseline -P[0,3] / P[0,0] = {baseline}; expected \
             positive (are LEFT.yaml and RIGHT.yaml swapped?)"
        );
    }
    Ok(Imported {
        width: left_size.0,
        height: left_size.1,
        f,
        cx,
        cy,
        baseline,
        lens: StereoLens { left, right },
        provenance: format!("ROS camera_info {left_file} and {right_file}, their R and P as given"),
    })
}

// ---------------------------------------------------------------------------------------------
// OpenCV

fn import_opencv(path: &Path) -> Result<Imported> {
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
    let camera = |k: &str, d: &str| -> Result<RawCamera> {
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
    rectified(&file, &cal, format!("OpenCV FileStorage {file}, {how}"))
}

// ---------------------------------------------------------------------------------------------
// The rig file

/// The rig file (vehicle-interfaces.md section 3), every number in full precision.
fn rig_toml(imported: &Imported) -> String {
    let mut out = String::new();
    let Imported {
        width,
        height,
        f,
        cx,
        cy,
        baseline,
        lens,
        provenance,
    } = imported;
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
    use super::*;

    fn yaml(text: &str) -> YamlOwned {
        let text = without_opencv_directive(text);
        YamlOwned::load_from_str(&text)
            .unwrap()
            .into_iter()
            .next()
            .unwrap()
    }

    #[test]
    fn opencv_directive_and_matrix_tags_are_read() {
        for header in ["%YAML:1.0\n", "%YAML 1.2\n---\n", ""] {
            let doc = yaml(&format!(
                "{header}K1: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n   data: [ 458.654, \
                 0., 367.215, 0., 457.296,\n       248.375, 0., 0., 1. ]\nwidth: 752\n"
            ));
            let root = Node::root("s.yml", &doc);
            let k = root.get("K1").unwrap().matrix_sized(3, 3).unwrap();
            assert_eq!(k[0], 458.654);
            assert_eq!(k[8], 1.0);
            assert_eq!(root.get("width").unwrap().integer().unwrap(), 752);
        }
    }

    #[test]
    fn errors_name_the_file_the_key_and_the_value() {
        let doc = yaml(
            "a: {rows: 2, cols: 2, data: [1, 2, 3]}\nb: [1, .Nan]\nc: x\nd: {rows: 1, cols: 3, data: [1, 2, 3]}\n",
        );
        let root = Node::root("f.yml", &doc);
        let msg = |e: anyhow::Error| e.to_string();
        assert_eq!(
            msg(root.get("a").unwrap().matrix().unwrap_err()),
            "f.yml: a: 2 x 2 matrix with 3 numbers of data"
        );
        assert_eq!(
            msg(root.get("b").unwrap().numbers().unwrap_err()),
            "f.yml: b[1]: NaN is not a finite number"
        );
        assert_eq!(
            msg(root.get("c").unwrap().number().unwrap_err()),
            "f.yml: c: expected a number, found string \"x\""
        );
        assert_eq!(
            msg(root.get("d").unwrap().matrix_sized(3, 3).unwrap_err()),
            "f.yml: d: a 1 x 3 matrix; expected 3 x 3"
        );
        assert_eq!(msg(root.get("e").unwrap_err()), "f.yml: e: missing key");
    }

    #[test]
    fn lens_coefficients() {
        let doc = yaml("a: 1");
        let node = Node::root("f", &doc);
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
