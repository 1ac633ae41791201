//! Stereo rectification of a raw calibration, as OpenCV computes it (vehicle-interfaces.md
//! section 5, `stereonav rig import`): `cv2.stereoRectify(K1, D1, K2, D2, size, R, T,
//! flags=CALIB_ZERO_DISPARITY, alpha=0)` for `plumb_bob` lenses and
//! `cv2.fisheye.stereoRectify(..., flags=CALIB_ZERO_DISPARITY, balance=0)` (fov_scale 1) for
//! `equidistant` ones, at the calibration's own image size.
//!
//! Written from OpenCV's documentation and from experiments against `cv2` (OpenCV 5.0), not
//! from its source. What the experiments fixed:
//!
//! * **Rotations** (both models): each camera turns by half of the rotation between them
//!   (`R^(1/2)` for the left, `R^(-1/2)` for the right), then both by the one rotation that
//!   takes the half-rotated baseline onto the x axis. `R1`, `R2` agree with `cv2` to 1e-16.
//! * **`plumb_bob` focal length and principal point**: the focal length starts as the mean
//!   of the two cameras' `fy` (not their minimum, and not shrunk by `k1` as older versions
//!   did). The principal point is, per camera, the image centre `((w-1)/2, (h-1)/2)` minus the
//!   mean of the four image corners undistorted, rotated and projected with that focal
//!   length; with `CALIB_ZERO_DISPARITY` the two cameras' are averaged. `alpha = 0` then
//!   scales the focal length (the principal point stays) by the largest factor at which the
//!   inner rectangle of the undistorted border of either camera (a 9 x 9 grid over the image;
//!   the largest x of its left column, the smallest of its right one, likewise in y) still
//!   reaches the image edges `0` and `w - 1`, `0` and `h - 1`.
//! * OpenCV undistorts those border points with [`OPENCV_FIXED_POINT_ITERATIONS`] fixed-point
//!   iterations (`cv::undistortPoints`' default), which have not converged at the corners of
//!   a strong radtan lens: with the exact inverse ([`LensModel::undistort`]) EuRoC's `f`
//!   comes out 0.023 px and `cy` 0.009 px away from OpenCV's. So this module runs OpenCV's
//!   iteration for the border points (on [`LensModel::distort`], the one lens model), and
//!   agrees with `cv2` to 1e-5 px (OpenCV computes these points in single precision).
//! * **`equidistant`** (`fisheye.stereoRectify`): per camera, the midpoints of the four image
//!   edges (`(w/2, 0)`, `(w, h/2)`, `(w/2, h)`, `(0, h/2)`: the full size, not `w - 1`) are
//!   undistorted (to convergence: OpenCV's fisheye inverse is Newton's method) and rotated;
//!   with `balance = 0` the focal length is the largest at which the border midpoints reach
//!   the edges about their mean (in units of `fx`, the y axis scaled by `fx / fy`), and the
//!   principal point puts that mean at the image centre. The rig's focal length is the
//!   smaller of the two cameras' (their `fy`), the principal point the mean of the two.
//!
//! Builds without `std` or `alloc` (nalgebra, `libm`), like the rest of the rig model.

use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector2, Vector3};

use crate::lens::{Lens, LensModel, StereoLens};

/// `cv::undistortPoints`' default: five fixed-point iterations, which OpenCV's
/// `stereoRectify` uses for the image border (its principal point and `alpha` scaling).
pub const OPENCV_FIXED_POINT_ITERATIONS: usize = 5;
/// Grid points along each side of the image for the `alpha` rectangles (OpenCV's 9 x 9).
const BORDER_GRID: usize = 9;
/// A rotation matrix read from a file is accepted when `R R^T` is the identity to this
/// (the rig file's own tolerance for its rectification matrices).
pub const ROTATION_TOLERANCE: f64 = 1e-5;

/// One raw camera of a stereo calibration: its lens and intrinsics, before rectification.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RawCamera {
    /// Lens model and coefficients.
    pub model: LensModel,
    /// Focal length along u, raw pixels.
    pub fx: f64,
    /// Focal length along v, raw pixels.
    pub fy: f64,
    /// Principal point, raw pixels.
    pub cx: f64,
    /// Principal point, raw pixels.
    pub cy: f64,
}

impl RawCamera {
    /// This camera with its rectification rotation (raw camera -> rectified rig orientation).
    pub fn with_rectification(&self, rectification: Matrix3<f64>) -> Lens {
        Lens {
            model: self.model,
            fx: self.fx,
            fy: self.fy,
            cx: self.cx,
            cy: self.cy,
            rectification,
        }
    }

    /// The normalised distorted point of a raw pixel.
    fn normalised(&self, pixel: Vector2<f64>) -> Vector2<f64> {
        Vector2::new((pixel.x - self.cx) / self.fx, (pixel.y - self.cy) / self.fy)
    }
}

/// A stereo calibration as OpenCV's `stereoCalibrate` (or Kalibr) gives it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StereoCalibration {
    /// The left camera (OpenCV's camera 1, Kalibr's cam0).
    pub left: RawCamera,
    /// The right camera (camera 2, cam1).
    pub right: RawCamera,
    /// Rotation taking a point in left-camera coordinates to right-camera coordinates
    /// (OpenCV's `R`, the rotation of Kalibr's `T_cn_cnm1`).
    pub right_from_left_rotation: Matrix3<f64>,
    /// Translation likewise: `p_in_right = R p_in_left + t` (OpenCV's `T`), in the
    /// calibration's length unit.
    pub right_from_left_translation: Vector3<f64>,
    /// Image width, pixels (both cameras).
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
}

/// The rectified rig: OpenCV's `P1 = [f 0 cx 0; 0 f cy 0; 0 0 1 0]`,
/// `P2 = [f 0 cx -f B; 0 f cy 0; 0 0 1 0]`, `R1`, `R2`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rectification {
    /// Focal length of both rectified cameras, pixels.
    pub f: f64,
    /// Principal point of both rectified cameras, pixels.
    pub cx: f64,
    /// Principal point of both rectified cameras, pixels.
    pub cy: f64,
    /// `-P2[0,3] / P2[0,0]`: the length of the translation, in its unit; positive.
    pub baseline: f64,
    /// The raw cameras with their rectification matrices (`R1` left, `R2` right).
    pub lens: StereoLens,
}

/// A calibration that cannot be rectified into the rig model; the values say what was wrong.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum RectifyError {
    /// The image is too small to have a border.
    #[error("image size {width} x {height}: expected at least 2 x 2 pixels")]
    ImageSize {
        /// Width, pixels.
        width: u32,
        /// Height, pixels.
        height: u32,
    },
    /// An intrinsic parameter or coefficient is not finite, or a focal length not positive.
    #[error("{camera} camera: {what} = {value} must be {expected}")]
    BadCamera {
        /// `"left"` or `"right"`.
        camera: &'static str,
        /// Which value.
        what: &'static str,
        /// The value.
        value: f64,
        /// `"positive and finite"` or `"finite"`.
        expected: &'static str,
    },
    /// The two lenses have different models (OpenCV rectifies a pair of one kind).
    #[error("the left lens is {left} and the right one {right}: both must have the same model")]
    MixedModels {
        /// The left lens model.
        left: &'static str,
        /// The right lens model.
        right: &'static str,
    },
    /// The rotation between the cameras is not a rotation matrix.
    #[error(
        "the rotation between the cameras is not a rotation matrix (R R^T differs from I by \
         {deviation:.1e}, determinant {determinant})"
    )]
    NotARotation {
        /// Largest element of `|R R^T - I|` (NaN for non-finite entries).
        deviation: f64,
        /// `det R`.
        determinant: f64,
    },
    /// The translation between the cameras is zero or not finite.
    #[error(
        "the translation between the cameras ({x}, {y}, {z}) has length {length}: expected a \
         positive, finite baseline"
    )]
    ZeroBaseline {
        /// Translation, x.
        x: f64,
        /// Translation, y.
        y: f64,
        /// Translation, z.
        z: f64,
        /// Its length.
        length: f64,
    },
    /// The cameras are one above the other: OpenCV would rectify them vertically, which the
    /// rig model (cameras side by side along x) cannot describe.
    #[error(
        "the cameras are one above the other (translation after the half rotations: x {x}, y \
         {y}): the rig model needs them side by side"
    )]
    VerticalBaseline {
        /// Half-rotated translation, x.
        x: f64,
        /// Half-rotated translation, y.
        y: f64,
    },
    /// The "right" camera is on the left of the "left" one.
    #[error(
        "the right camera is to the left of the left one (rectified translation x = {x}, \
         expected negative): swap the cameras"
    )]
    CamerasSwapped {
        /// Rectified translation `R2 T`, x.
        x: f64,
    },
    /// The image border cannot be undistorted and rectified (the lens model does not hold
    /// over the whole image, or the border folds over the principal point).
    #[error(
        "{camera} camera: the image border does not undistort into a usable rectangle \
         ({what} = {value}): the lens model does not hold over the whole image"
    )]
    Border {
        /// `"left"` or `"right"`.
        camera: &'static str,
        /// What came out wrong.
        what: &'static str,
        /// Its value.
        value: f64,
    },
}

/// Rectifies a stereo calibration as OpenCV does (module documentation): `stereoRectify`
/// with `CALIB_ZERO_DISPARITY` and `alpha = 0` for `plumb_bob` lenses,
/// `fisheye.stereoRectify` with `CALIB_ZERO_DISPARITY` and `balance = 0` for `equidistant`.
pub fn stereo_rectify(cal: &StereoCalibration) -> Result<Rectification, RectifyError> {
    validate(cal)?;
    let Rotations {
        left_rect_from_left,
        right_rect_from_right,
        t_rect,
    } = rotations(
        &cal.right_from_left_rotation,
        &cal.right_from_left_translation,
    )?;
    let (w, h) = (f64::from(cal.width), f64::from(cal.height));
    let (f, c) = match cal.left.model {
        LensModel::PlumbBob { .. } => plumb_bob_projection(
            [
                (&cal.left, &left_rect_from_left, "left"),
                (&cal.right, &right_rect_from_right, "right"),
            ],
            w,
            h,
        )?,
        LensModel::Equidistant { .. } => {
            let (fy_left, c_left) =
                fisheye_new_camera(&cal.left, &left_rect_from_left, w, h, "left")?;
            let (fy_right, c_right) =
                fisheye_new_camera(&cal.right, &right_rect_from_right, w, h, "right")?;
            (fy_left.min(fy_right), (c_left + c_right) * 0.5)
        }
    };
    Ok(Rectification {
        f,
        cx: c.x,
        cy: c.y,
        baseline: -t_rect.x,
        lens: StereoLens {
            left: cal.left.with_rectification(left_rect_from_left),
            right: cal.right.with_rectification(right_rect_from_right),
        },
    })
}

/// Deviation of `m` from a rotation: the largest element of `|m m^T - I|` (NaN if `m` is
/// not finite) and `det m`.
pub fn rotation_deviation(m: &Matrix3<f64>) -> (f64, f64) {
    if !m.iter().all(|v| v.is_finite()) {
        return (f64::NAN, f64::NAN);
    }
    (
        (m * m.transpose() - Matrix3::identity()).amax(),
        m.determinant(),
    )
}

fn validate(cal: &StereoCalibration) -> Result<(), RectifyError> {
    if cal.width < 2 || cal.height < 2 {
        return Err(RectifyError::ImageSize {
            width: cal.width,
            height: cal.height,
        });
    }
    for (camera, cam) in [("left", &cal.left), ("right", &cal.right)] {
        let bad = |what, value, expected| RectifyError::BadCamera {
            camera,
            what,
            value,
            expected,
        };
        for (what, value) in [("fx", cam.fx), ("fy", cam.fy)] {
            if !(value.is_finite() && value > 0.0) {
                return Err(bad(what, value, "positive and finite"));
            }
        }
        let coefficients = match cam.model {
            LensModel::PlumbBob { k1, k2, p1, p2, k3 } => {
                [("k1", k1), ("k2", k2), ("p1", p1), ("p2", p2), ("k3", k3)]
            }
            LensModel::Equidistant { k1, k2, k3, k4 } => {
                [("k1", k1), ("k2", k2), ("k3", k3), ("k4", k4), ("k4", k4)]
            }
        };
        for (what, value) in [("cx", cam.cx), ("cy", cam.cy)]
            .into_iter()
            .chain(coefficients)
        {
            if !value.is_finite() {
                return Err(bad(what, value, "finite"));
            }
        }
    }
    let (left, right) = (cal.left.model.name(), cal.right.model.name());
    if left != right {
        return Err(RectifyError::MixedModels { left, right });
    }
    let (deviation, determinant) = rotation_deviation(&cal.right_from_left_rotation);
    // Written so that NaN fails.
    if !(deviation <= ROTATION_TOLERANCE && determinant > 0.0) {
        return Err(RectifyError::NotARotation {
            deviation,
            determinant,
        });
    }
    let t = &cal.right_from_left_translation;
    let length = t.norm();
    if !(length.is_finite() && length > 0.0) {
        return Err(RectifyError::ZeroBaseline {
            x: t.x,
            y: t.y,
            z: t.z,
            length,
        });
    }
    Ok(())
}

/// The rectifying rotations of both cameras.
struct Rotations {
    /// `R1`: raw left camera -> rectified orientation.
    left_rect_from_left: Matrix3<f64>,
    /// `R2`: raw right camera -> rectified orientation.
    right_rect_from_right: Matrix3<f64>,
    /// The rectified translation `R2 T` = `(-B, 0, 0)`.
    t_rect: Vector3<f64>,
}

/// `R1`, `R2` and the rectified translation.
///
/// Each camera turns by half of `R` towards the other (OpenCV's `Rodrigues(-0.5 om)`), then
/// both by the rotation that takes the half-rotated translation onto the x axis.
fn rotations(right_from_left: &Matrix3<f64>, t: &Vector3<f64>) -> Result<Rotations, RectifyError> {
    // The nearest rotation (a file's matrix is orthonormal only to its printed digits), as a
    // unit quaternion: its rotation vector keeps full precision at small angles, where one
    // taken from the matrix trace (acos) would not.
    let rotation = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix(right_from_left));
    let half_back = UnitQuaternion::from_scaled_axis(rotation.scaled_axis() * -0.5)
        .to_rotation_matrix()
        .into_inner();
    let t_half = half_back * t;
    if libm::fabs(t_half.x) <= libm::fabs(t_half.y) {
        return Err(RectifyError::VerticalBaseline {
            x: t_half.x,
            y: t_half.y,
        });
    }
    let target = Vector3::new(libm::copysign(1.0, t_half.x), 0.0, 0.0);
    let axis = t_half.cross(&target);
    let axis_norm = axis.norm();
    let align = if axis_norm > 0.0 {
        let angle = libm::acos((libm::fabs(t_half.x) / t_half.norm()).min(1.0));
        Rotation3::new(axis * (angle / axis_norm)).into_inner()
    } else {
        Matrix3::identity()
    };
    let left_rect_from_left = align * half_back.transpose();
    let right_rect_from_right = align * half_back;
    let t_rect = right_rect_from_right * t;
    if t_rect.x >= 0.0 {
        return Err(RectifyError::CamerasSwapped { x: t_rect.x });
    }
    Ok(Rotations {
        left_rect_from_left,
        right_rect_from_right,
        t_rect,
    })
}

/// OpenCV's approximate inverse of the `plumb_bob` model (`cv::undistortPoints` with its
/// default five iterations): `p <- (d - tangential(p)) / radial(p)` from `p = d`, stopping
/// with `p = d` if the radial factor turns negative. Only `stereoRectify`'s border points go
/// through it, to land where OpenCV's do; features use the exact [`LensModel::undistort`].
fn opencv_fixed_point_undistort(model: &LensModel, d: Vector2<f64>) -> Vector2<f64> {
    let LensModel::PlumbBob { k1, k2, k3, .. } = *model else {
        return d;
    };
    let mut p = d;
    for _ in 0..OPENCV_FIXED_POINT_ITERATIONS {
        let r2 = p.norm_squared();
        let radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
        if radial < 0.0 {
            return d;
        }
        let (distorted, _) = model.distort(p);
        let tangential = distorted - p * radial;
        p = (d - tangential) / radial;
    }
    p
}

/// The undistorted normalised point `p` rotated by `rect_from_raw` and projected with focal
/// length `f` and principal point `c`.
fn rotate_and_project(
    rect_from_raw: &Matrix3<f64>,
    p: Vector2<f64>,
    f: f64,
    c: Vector2<f64>,
) -> Vector2<f64> {
    let ray = rect_from_raw * Vector3::new(p.x, p.y, 1.0);
    c + Vector2::new(ray.x, ray.y) * (f / ray.z)
}

/// `stereoRectify`'s focal length and principal point for `plumb_bob` lenses, `alpha = 0`.
fn plumb_bob_projection(
    cameras: [(&RawCamera, &Matrix3<f64>, &'static str); 2],
    w: f64,
    h: f64,
) -> Result<(f64, Vector2<f64>), RectifyError> {
    let f0 = 0.5 * (cameras[0].0.fy + cameras[1].0.fy);
    let border = |cam: &RawCamera, rect: &Matrix3<f64>, pixel: Vector2<f64>, c: Vector2<f64>| {
        let p = opencv_fixed_point_undistort(&cam.model, cam.normalised(pixel));
        rotate_and_project(rect, p, f0, c)
    };
    // The principal point: the image centre minus the mean of the undistorted corners.
    let centre = Vector2::new((w - 1.0) * 0.5, (h - 1.0) * 0.5);
    let mut c = Vector2::zeros();
    for (cam, rect, _) in cameras {
        let mut mean = Vector2::zeros();
        for (x, y) in [
            (0.0, 0.0),
            (w - 1.0, 0.0),
            (0.0, h - 1.0),
            (w - 1.0, h - 1.0),
        ] {
            mean += border(cam, rect, Vector2::new(x, y), Vector2::zeros()) * 0.25;
        }
        c += (centre - mean) * 0.5;
    }
    // alpha = 0: the largest scale at which either camera's inner rectangle still reaches the
    // image edges.
    let mut scale = f64::NEG_INFINITY;
    for (cam, rect, camera) in cameras {
        let at = |i: usize, j: usize| {
            // i along x, j along y; grid indices are below 9, exact in f64.
            #[allow(clippy::cast_precision_loss)]
            let step = |k: usize, size: f64| k as f64 * (size - 1.0) / (BORDER_GRID - 1) as f64;
            border(cam, rect, Vector2::new(step(i, w), step(j, h)), c)
        };
        let last = BORDER_GRID - 1;
        let (mut left, mut right) = (f64::NEG_INFINITY, f64::INFINITY);
        let (mut top, mut bottom) = (f64::NEG_INFINITY, f64::INFINITY);
        for k in 0..BORDER_GRID {
            left = left.max(at(0, k).x);
            right = right.min(at(last, k).x);
            top = top.max(at(k, 0).y);
            bottom = bottom.min(at(k, last).y);
        }
        for (what, ratio) in [
            ("left edge scale", c.x / (c.x - left)),
            ("top edge scale", c.y / (c.y - top)),
            ("right edge scale", (w - 1.0 - c.x) / (right - c.x)),
            ("bottom edge scale", (h - 1.0 - c.y) / (bottom - c.y)),
        ] {
            if !(ratio.is_finite() && ratio > 0.0) {
                return Err(RectifyError::Border {
                    camera,
                    what,
                    value: ratio,
                });
            }
            scale = scale.max(ratio);
        }
    }
    Ok((f0 * scale, c))
}

/// `fisheye.estimateNewCameraMatrixForUndistortRectify` with `balance = 0`, `fov_scale = 1`:
/// the new `fy` and principal point of one camera.
fn fisheye_new_camera(
    cam: &RawCamera,
    rect_from_raw: &Matrix3<f64>,
    w: f64,
    h: f64,
    camera: &'static str,
) -> Result<(f64, Vector2<f64>), RectifyError> {
    let aspect = cam.fx / cam.fy;
    let mut points = [Vector2::zeros(); 4];
    let midpoints = [(w * 0.5, 0.0), (w, h * 0.5), (w * 0.5, h), (0.0, h * 0.5)];
    for (point, (u, v)) in points.iter_mut().zip(midpoints) {
        let d = cam.normalised(Vector2::new(u, v));
        let p = cam.model.undistort(d).ok_or(RectifyError::Border {
            camera,
            what: "undistortion of an edge midpoint, u",
            value: u,
        })?;
        let ray = rect_from_raw * Vector3::new(p.x, p.y, 1.0);
        // In units of fx along both axes.
        *point = Vector2::new(ray.x / ray.z, ray.y / ray.z * aspect);
    }
    let mean = points.iter().sum::<Vector2<f64>>() * 0.25;
    let (mut min, mut max) = (points[0], points[0]);
    for p in &points {
        min = min.inf(p);
        max = max.sup(p);
    }
    let mut f = f64::NEG_INFINITY;
    for (what, candidate) in [
        ("left edge focal length", w * 0.5 / (mean.x - min.x)),
        ("right edge focal length", w * 0.5 / (max.x - mean.x)),
        ("top edge focal length", h * 0.5 * aspect / (mean.y - min.y)),
        (
            "bottom edge focal length",
            h * 0.5 * aspect / (max.y - mean.y),
        ),
    ] {
        if !(candidate.is_finite() && candidate > 0.0) {
            return Err(RectifyError::Border {
                camera,
                what,
                value: candidate,
            });
        }
        f = f.max(candidate);
    }
    let c = Vector2::new(
        w * 0.5 - mean.x * f,
        (h * aspect * 0.5 - mean.y * f) / aspect,
    );
    Ok((f / aspect, c))
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::indexing_slicing)]
mod tests {
    use super::*;

    /// EuRoC V1_01's cam0 and cam1 (their sensor.yaml) and the transform between them,
    /// `inverse(T_BS_cam1) * T_BS_cam0`.
    fn euroc() -> StereoCalibration {
        StereoCalibration {
            left: RawCamera {
                model: LensModel::PlumbBob {
                    k1: -0.283_408_11,
                    k2: 0.073_959_07,
                    p1: 0.000_193_59,
                    p2: 1.761_871_14e-5,
                    k3: 0.0,
                },
                fx: 458.654,
                fy: 457.296,
                cx: 367.215,
                cy: 248.375,
            },
            right: RawCamera {
                model: LensModel::PlumbBob {
                    k1: -0.283_683_65,
                    k2: 0.074_512_84,
                    p1: -0.000_104_73,
                    p2: -3.555_907e-5,
                    k3: 0.0,
                },
                fx: 457.587,
                fy: 456.134,
                cx: 379.999,
                cy: 255.238,
            },
            right_from_left_rotation: Matrix3::new(
                0.999_997_256_477_881_2,
                0.002_312_067_192_423_886_4,
                0.000_376_008_102_415_593_8,
                -0.002_317_135_723_281_235_4,
                0.999_898_048_506_643_8,
                0.014_089_835_846_648_196,
                -0.000_343_393_120_524_162_1,
                -0.014_090_668_452_714_59,
                0.999_900_662_637_728_3,
            ),
            right_from_left_translation: Vector3::new(
                -0.110_073_808_127_186_78,
                0.000_399_121_547_014_148_06,
                -0.000_853_702_503_358_044_9,
            ),
            width: 752,
            height: 480,
        }
    }

    /// A fisheye pair of our own: 752 x 480, k1..k4, a small rotation, 0.11 m baseline.
    fn fisheye() -> StereoCalibration {
        let lens = |k1, k2, k3, k4| LensModel::Equidistant { k1, k2, k3, k4 };
        StereoCalibration {
            left: RawCamera {
                model: lens(-0.0137, 0.0182, -0.0114, 0.0025),
                fx: 360.0,
                fy: 360.4,
                cx: 375.0,
                cy: 240.5,
            },
            right: RawCamera {
                model: lens(-0.0121, 0.0171, -0.0109, 0.0023),
                fx: 361.2,
                fy: 361.0,
                cx: 378.3,
                cy: 236.9,
            },
            right_from_left_rotation: Rotation3::new(Vector3::new(0.004, -0.01, 0.002))
                .into_inner(),
            right_from_left_translation: Vector3::new(-0.11, 0.0012, -0.0008),
            width: 752,
            height: 480,
        }
    }

    /// `cv2.stereoRectify(K1, D1, K2, D2, (752, 480), R, T, flags=CALIB_ZERO_DISPARITY,
    /// alpha=0)` on [`euroc`] (OpenCV 5.0.0): `P1[0,0]`, `P1[0,2]`, `P1[1,2]`,
    /// `-P2[0,3] / P2[0,0]`, and `R1`, `R2` row-major.
    const EUROC_OPENCV: [f64; 4] = [
        436.244295647102,
        364.44123458862305,
        256.95167541503906,
        0.1100778421917611,
    ];
    const EUROC_OPENCV_R1: [f64; 9] = [
        0.9999663475300326,
        -0.0014227391387192799,
        0.008079580483489718,
        0.001365741834640079,
        0.9999741760894847,
        0.007055629199258192,
        -0.00808941015693637,
        -0.007044357138835821,
        0.9999424675829172,
    ];
    const EUROC_OPENCV_R2: [f64; 9] = [
        0.9999633526194371,
        -0.0036258118715556003,
        0.007755443660230329,
        0.0036803985472554446,
        0.9999684752771629,
        -0.007035845251224842,
        -0.007729688520780125,
        0.007064130529506773,
        0.9999451734846435,
    ];
    /// `cv2.fisheye.stereoRectify(..., flags=CALIB_ZERO_DISPARITY, balance=0, fov_scale=1)`
    /// on [`fisheye`]: `P1[0,0]`, `P1[0,2]`, `P1[1,2]`, `-P2[0,3] / P2[0,0]`.
    const FISHEYE_OPENCV: [f64; 4] = [
        304.6459425989734,
        375.69704900224,
        238.19813911892328,
        0.11000945413917841,
    ];

    #[test]
    fn euroc_equals_opencv() {
        let r = stereo_rectify(&euroc()).unwrap();
        let [f, cx, cy, b] = EUROC_OPENCV;
        // OpenCV's border points are single precision: 1e-4 px.
        assert!((r.f - f).abs() < 1e-4, "f {} vs {f}", r.f);
        assert!((r.cx - cx).abs() < 1e-4, "cx {} vs {cx}", r.cx);
        assert!((r.cy - cy).abs() < 1e-4, "cy {} vs {cy}", r.cy);
        assert!((r.baseline - b).abs() < 1e-12, "baseline {}", r.baseline);
        let r1 = Matrix3::from_row_slice(&EUROC_OPENCV_R1);
        let r2 = Matrix3::from_row_slice(&EUROC_OPENCV_R2);
        assert!((r.lens.left.rectification - r1).amax() < 1e-12);
        assert!((r.lens.right.rectification - r2).amax() < 1e-12);
    }

    #[test]
    fn fisheye_equals_opencv() {
        let r = stereo_rectify(&fisheye()).unwrap();
        let [f, cx, cy, b] = FISHEYE_OPENCV;
        assert!((r.f - f).abs() < 1e-6, "f {} vs {f}", r.f);
        assert!((r.cx - cx).abs() < 1e-6, "cx {} vs {cx}", r.cx);
        assert!((r.cy - cy).abs() < 1e-6, "cy {} vs {cy}", r.cy);
        assert!((r.baseline - b).abs() < 1e-12, "baseline {}", r.baseline);
    }

    /// The exact inverse would not give OpenCV's numbers for EuRoC: the reason for the
    /// fixed-point iteration at the border.
    #[test]
    fn opencv_fixed_point_has_not_converged_at_the_corners() {
        let cal = euroc();
        let d = cal.left.normalised(Vector2::new(0.0, 0.0));
        let approx = opencv_fixed_point_undistort(&cal.left.model, d);
        let exact = cal.left.model.undistort(d).unwrap();
        let px = (approx - exact).amax() * cal.left.fx;
        assert!(px > 0.01, "{px} px");
        // Near the centre both agree.
        let d = cal.left.normalised(Vector2::new(380.0, 250.0));
        let approx = opencv_fixed_point_undistort(&cal.left.model, d);
        assert!((approx - cal.left.model.undistort(d).unwrap()).amax() < 1e-12);
    }

    /// The raw pixel of a point in a camera's own coordinates.
    fn raw_pixel(cam: &RawCamera, p: Vector3<f64>) -> Vector2<f64> {
        let (d, _) = cam.model.distort(Vector2::new(p.x / p.z, p.y / p.z));
        Vector2::new(cam.cx + cam.fx * d.x, cam.cy + cam.fy * d.y)
    }

    /// The epipolar rows line up: a 3-D point seen by both raw cameras maps (through the lens
    /// model and the rectification) to the same v in both rectified images, at the disparity
    /// `f B / z` of the rig model.
    #[test]
    fn rectified_rows_line_up_and_the_disparity_is_f_b_over_z() {
        for cal in [euroc(), fisheye()] {
            let r = stereo_rectify(&cal).unwrap();
            let mut worst: f64 = 0.0;
            for (x, y, z) in [
                (0.0, 0.0, 2.0),
                (0.6, -0.4, 1.5),
                (-0.9, 0.5, 3.0),
                (0.3, 0.7, 8.0),
                (-0.2, -0.3, 0.8),
            ] {
                let in_left = Vector3::new(x, y, z);
                let in_right =
                    cal.right_from_left_rotation * in_left + cal.right_from_left_translation;
                let left = r
                    .lens
                    .left
                    .rectify_point(raw_pixel(&cal.left, in_left), r.f, r.cx, r.cy)
                    .unwrap();
                let right = r
                    .lens
                    .right
                    .rectify_point(raw_pixel(&cal.right, in_right), r.f, r.cx, r.cy)
                    .unwrap();
                let depth = (r.lens.left.rectification * in_left).z;
                worst = worst
                    .max((left.y - right.y).abs())
                    .max((left.x - right.x - r.f * r.baseline / depth).abs());
            }
            assert!(worst < 1e-6, "{worst} px");
        }
    }

    #[test]
    fn r1_and_r2_are_rotations_that_carry_r_between_them() {
        for cal in [euroc(), fisheye()] {
            let r = stereo_rectify(&cal).unwrap();
            let (r1, r2) = (r.lens.left.rectification, r.lens.right.rectification);
            for m in [r1, r2] {
                let (deviation, det) = rotation_deviation(&m);
                assert!(deviation < 1e-14 && (det - 1.0).abs() < 1e-14);
            }
            // Both rectified cameras share one orientation: R2 R R1^T = I ...
            let shared = r2 * cal.right_from_left_rotation * r1.transpose();
            // (to the orthonormality of EuRoC's R, products of 12-digit matrices)
            let off = (shared - Matrix3::identity()).amax();
            assert!(off < 1e-12, "{off}");
            // ... and the baseline lies along x.
            let t = r2 * cal.right_from_left_translation;
            assert!(t.y.abs() < 1e-15 && t.z.abs() < 1e-15, "{t:?}");
            let length = cal.right_from_left_translation.norm();
            assert!((r.baseline - length).abs() < 1e-15);
        }
    }

    #[test]
    fn a_pair_without_rotation_keeps_its_axes() {
        let mut cal = euroc();
        cal.right_from_left_rotation = Matrix3::identity();
        cal.right_from_left_translation = Vector3::new(-0.12, 0.0, 0.0);
        let r = stereo_rectify(&cal).unwrap();
        assert_eq!(r.lens.left.rectification, Matrix3::identity());
        assert_eq!(r.lens.right.rectification, Matrix3::identity());
        assert!((r.baseline - 0.12).abs() < 1e-15);
    }

    #[test]
    fn impossible_calibrations_are_refused_with_their_values() {
        let mut cal = euroc();
        cal.right_from_left_translation = Vector3::zeros();
        assert!(matches!(
            stereo_rectify(&cal),
            Err(RectifyError::ZeroBaseline { length, .. }) if length == 0.0
        ));

        let mut cal = euroc();
        cal.right_from_left_translation = Vector3::new(0.11, 0.0, 0.0);
        assert!(matches!(
            stereo_rectify(&cal),
            Err(RectifyError::CamerasSwapped { x }) if x > 0.1
        ));

        let mut cal = euroc();
        cal.right_from_left_translation = Vector3::new(0.01, -0.11, 0.0);
        assert!(matches!(
            stereo_rectify(&cal),
            Err(RectifyError::VerticalBaseline { .. })
        ));

        let mut cal = euroc();
        cal.right_from_left_rotation[(0, 0)] = 1.1;
        let err = stereo_rectify(&cal).unwrap_err();
        assert!(matches!(err, RectifyError::NotARotation { deviation, .. } if deviation > 0.1));

        let mut cal = euroc();
        cal.right_from_left_rotation = -Matrix3::identity();
        assert!(matches!(
            stereo_rectify(&cal),
            Err(RectifyError::NotARotation { determinant, .. }) if determinant < 0.0
        ));

        let mut cal = euroc();
        cal.right.model = fisheye().right.model;
        assert!(matches!(
            stereo_rectify(&cal),
            Err(RectifyError::MixedModels {
                left: "plumb_bob",
                right: "equidistant"
            })
        ));

        let mut cal = euroc();
        cal.left.fy = f64::NAN;
        let err = stereo_rectify(&cal).unwrap_err();
        assert!(matches!(
            err,
            RectifyError::BadCamera {
                camera: "left",
                what: "fy",
                ..
            }
        ));

        let mut cal = euroc();
        cal.width = 1;
        assert!(matches!(
            stereo_rectify(&cal),
            Err(RectifyError::ImageSize { width: 1, .. })
        ));

        // A fisheye whose model folds over before the image edge.
        let mut cal = fisheye();
        cal.left.model = LensModel::Equidistant {
            k1: -0.9,
            k2: 0.0,
            k3: 0.0,
            k4: 0.0,
        };
        assert!(matches!(
            stereo_rectify(&cal),
            Err(RectifyError::Border { camera: "left", .. })
        ));
    }
}
