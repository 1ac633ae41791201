//! What the board sends for one stereo frame, and the fast mode that makes it without images.
//!
//! Fast mode projects each lamp with [`rig_model::project`] and the true camera parameters, keeps
//! those in front of the cameras and inside the detector's candidate area, adds Gaussian pixel
//! noise, adds clutter, quantises to Q12.4 (`x_q4 = round(16 u)`), gives each a plausible
//! response, applies the board's 3x3 non-maximum suppression between features, orders them
//! as the board does and applies the `MAX_FEATURES` cap.

use harris_core::{CANDIDATE_BORDER, Feature, Q4_SHIFT, Registers};
use nalgebra::{Matrix3, Vector3};
use rand::{Rng, RngExt};
use rand_distr::{Distribution, Poisson, StandardNormal};
use rig_model::{CameraParams, Pose2};

use crate::scenario::{Clutter, NoiseSpec};
use crate::world::Lamp;

/// One feature as the board sends it, with where it came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct SimFeature {
    /// Column, Q12.4 pixels.
    pub x_q4: u16,
    /// Row, Q12.4 pixels.
    pub y_q4: u16,
    /// Harris response.
    pub r: i32,
    /// The lamp it is an image of, or `None` for clutter.
    pub lamp: Option<u32>,
}

impl SimFeature {
    /// As the board's feature (without the source).
    pub fn feature(&self) -> Feature {
        Feature {
            x_q4: self.x_q4,
            y_q4: self.y_q4,
            r: self.r,
        }
    }

    /// The integer pixel `(row, column)` the board's raster order sorts by:
    /// `((y_q4 + 8) / 16, (x_q4 + 8) / 16)`.
    pub fn raster_key(&self) -> (u32, u32) {
        raster_key(self.x_q4, self.y_q4)
    }
}

/// Half a pixel in Q12.4.
const HALF_PIXEL_Q4: u32 = 1 << (Q4_SHIFT - 1);

/// The board's raster order key of a Q12.4 position: the integer pixel `(row, column)`,
/// `((y_q4 + 8) >> 4, (x_q4 + 8) >> 4)` (board-icd.md step 7: the offset is within half a
/// pixel of the integer pixel).
pub fn raster_key(x_q4: u16, y_q4: u16) -> (u32, u32) {
    (
        (u32::from(y_q4) + HALF_PIXEL_Q4) >> Q4_SHIFT,
        (u32::from(x_q4) + HALF_PIXEL_Q4) >> Q4_SHIFT,
    )
}

/// One camera's features of a stereo frame.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct ImageFeatures {
    /// At most `MAX_FEATURES`, in the board's raster order.
    pub features: Vec<SimFeature>,
    /// More features were found than `MAX_FEATURES` (the camera's overflow flag).
    pub overflow: bool,
}

impl ImageFeatures {
    /// The board's features, without sources.
    pub fn board_features(&self) -> Vec<Feature> {
        self.features.iter().map(SimFeature::feature).collect()
    }
}

/// A lamp's true, noise-free projection in a stereo frame, in the rectified model (through real
/// lenses the board sees it at the raw pixel [`rig_model::lens::Lens::unrectify`] gives).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LampView {
    /// The lamp.
    pub id: u32,
    /// Left column, pixels.
    pub u_left: f64,
    /// Left row, pixels.
    pub v_left: f64,
    /// Right column, pixels.
    pub u_right: f64,
    /// Right row, pixels.
    pub v_right: f64,
    /// Depth along the optical axis, metres.
    pub depth_m: f64,
    /// Inside the left detector's candidate area (4 pixels from every edge).
    pub in_left: bool,
    /// Inside the right detector's candidate area.
    pub in_right: bool,
}

/// `rig_from_world` for one pose: `p_in_rig = rotation * p_in_world + translation`.
#[derive(Debug, Clone, Copy)]
pub(crate) struct RigFromWorld {
    pub rotation: Matrix3<f64>,
    pub translation: Vector3<f64>,
}

impl RigFromWorld {
    pub(crate) fn new(c: &CameraParams, pose: &Pose2) -> Self {
        let rig_from_robot = c.mount.robot_from_rig_rotation().transpose();
        let robot_from_world = pose.world_from_robot_rotation().transpose();
        let rotation = rig_from_robot * robot_from_world;
        let translation = -(rig_from_robot
            * (robot_from_world * Vector3::new(pose.x, pose.y, 0.0) + c.mount.translation()));
        Self {
            rotation,
            translation,
        }
    }

    pub(crate) fn apply(&self, p: &Vector3<f64>) -> Vector3<f64> {
        self.rotation * p + self.translation
    }
}

/// Whether a position in pixels falls, once rounded to the board's integer pixel, inside the
/// detector's candidate area (board-icd.md step 4).
pub fn in_candidate_area(u: f64, v: f64, width: usize, height: usize) -> bool {
    #[allow(clippy::cast_precision_loss)] // image sizes are at most 4095
    let (lo, hi_x, hi_y) = (
        CANDIDATE_BORDER as f64,
        (width - 1 - CANDIDATE_BORDER) as f64,
        (height - 1 - CANDIDATE_BORDER) as f64,
    );
    let (x, y) = (u.round(), v.round());
    (lo..=hi_x).contains(&x) && (lo..=hi_y).contains(&y)
}

/// The lamps seen from `pose`: lit, in front of both cameras and inside the candidate area of
/// at least one, with their exact (rectified) projections by [`rig_model::project`].
///
/// With `lens` (the true raw lenses and the true camera), "inside" is tested where the board
/// sees the lamp: at its raw pixel ([`rig_model::lens::Lens::unrectify`]), against the raw
/// image. A raw image's rectified view is not the rectified rectangle (a barrel lens sees past
/// the rectangle's corners, a fisheye far past its edges), and a real camera sees all of it
/// (issue 35: a simulator that cropped the view to the rectangle hid the navigator's mistakes
/// there).
pub fn lamp_views(
    c: &CameraParams,
    pose: &Pose2,
    lamps: &[Lamp],
    regs: &Registers,
    lens: Option<&rig_model::lens::StereoLens>,
) -> Vec<LampView> {
    let rig_from_world = RigFromWorld::new(c, pose);
    #[allow(clippy::cast_precision_loss)]
    let (w, h) = (regs.width as f64, regs.height as f64);
    // A cheap cone test first; the survivors are projected by the rig model.
    let margin = 2.0;
    let (u_lo, u_hi) = ((-margin - c.cx) / c.f, (w + margin - c.cx) / c.f);
    let (v_lo, v_hi) = ((-margin - c.cy) / c.f, (h + margin - c.cy) / c.f);
    let half_b = c.baseline / 2.0;
    let mut out = Vec::new();
    for lamp in lamps.iter().filter(|l| l.lit) {
        let p = rig_from_world.apply(&lamp.position);
        if p.z <= 1e-6 {
            continue;
        }
        let (x_l, x_r, y) = ((p.x + half_b) / p.z, (p.x - half_b) / p.z, p.y / p.z);
        if lens.is_none()
            && (!(y >= v_lo && y <= v_hi)
                || (x_l < u_lo || x_l > u_hi) && (x_r < u_lo || x_r > u_hi))
        {
            continue;
        }
        let Ok(m) = rig_model::project(c, pose, &lamp.position) else {
            continue;
        };
        let inside = |lens: Option<&rig_model::lens::Lens>, u: f64, v: f64| match lens {
            None => in_candidate_area(u, v, regs.width, regs.height),
            Some(l) => l
                .unrectify(nalgebra::Vector2::new(u, v), c.f, c.cx, c.cy)
                .is_some_and(|raw| in_candidate_area(raw.x, raw.y, regs.width, regs.height)),
        };
        let in_left = inside(lens.map(|l| &l.left), m[0], m[1]);
        let in_right = inside(lens.map(|l| &l.right), m[2], m[3]);
        if in_left || in_right {
            out.push(LampView {
                id: lamp.id,
                u_left: m[0],
                v_left: m[1],
                u_right: m[2],
                v_right: m[3],
                depth_m: p.z,
                in_left,
                in_right,
            });
        }
    }
    out
}

/// `round(16 u)` as a Q12.4 coordinate, or `None` outside the 16-bit range.
pub fn quantise_q4(u: f64) -> Option<u16> {
    let q = (16.0 * u).round();
    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
    // checked against the u16 range first
    if (0.0..=f64::from(u16::MAX)).contains(&q) {
        Some(q as u16)
    } else {
        None
    }
}

/// The fast mode's features of one stereo frame from the lamps in view. With `lens` (the rig
/// file's `[lens.*]` tables, taken as the truth, and the true camera), each lamp's rectified
/// projection is carried to the raw image of its camera before the pixel noise (the board sees
/// raw pixels: vehicle-interfaces.md 1.1).
#[allow(clippy::too_many_arguments)]
pub(crate) fn fast_frame(
    views: &[LampView],
    noise: &NoiseSpec,
    clutter: &Clutter,
    lamp_response: f64,
    regs: &Registers,
    lens: Option<(&rig_model::lens::StereoLens, &CameraParams)>,
    rng: &mut impl Rng,
) -> (ImageFeatures, ImageFeatures) {
    let raw = |side: usize, u: f64, v: f64| -> Option<(f64, f64)> {
        let Some((l, c)) = lens else {
            return Some((u, v));
        };
        let lens = if side == 0 { &l.left } else { &l.right };
        lens.unrectify(nalgebra::Vector2::new(u, v), c.f, c.cx, c.cy)
            .map(|p| (p.x, p.y))
    };
    let mut left = Vec::new();
    let mut right = Vec::new();
    let (w, h) = (regs.width, regs.height);
    let mut normal = || -> f64 { StandardNormal.sample(&mut *rng) };
    let response = |z: f64| {
        let r = lamp_response * (noise.response_log_sigma * z).exp();
        #[allow(clippy::cast_possible_truncation)] // clamped to the i32 range
        let r = r.clamp(0.0, f64::from(i32::MAX)) as i32;
        r
    };
    for view in views {
        let n = [normal(), normal(), normal(), normal()];
        let (z_left, z_right) = (normal(), normal());
        let sigma = noise.pixel_px;
        let (Some((ul, vl)), Some((ur, vr))) = (
            raw(0, view.u_left, view.v_left),
            raw(1, view.u_right, view.v_right),
        ) else {
            continue;
        };
        let sides = [
            (
                view.in_left,
                ul + sigma * n[0],
                vl + sigma * n[1],
                z_left,
                &mut left,
            ),
            (
                view.in_right,
                ur + sigma * n[2],
                vr + sigma * n[3],
                z_right,
                &mut right,
            ),
        ];
        for (seen, u, v, z, out) in sides {
            if !seen || !in_candidate_area(u, v, w, h) {
                continue;
            }
            if let (Some(x_q4), Some(y_q4)) = (quantise_q4(u), quantise_q4(v)) {
                out.push(SimFeature {
                    x_q4,
                    y_q4,
                    r: response(z),
                    lamp: Some(view.id),
                });
            }
        }
    }
    add_clutter(clutter, regs, rng, &mut left, &mut right);
    (board_order(left, regs), board_order(right, regs))
}

/// Draws a Poisson count (0 for a zero mean).
fn poisson(mean: f64, rng: &mut impl Rng) -> u64 {
    match Poisson::new(mean) {
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        // a Poisson draw is a non-negative whole number, far below 2^53 for validated means
        Ok(p) => p.sample(rng) as u64,
        Err(_) => 0,
    }
}

fn add_clutter<R: Rng>(
    clutter: &Clutter,
    regs: &Registers,
    rng: &mut R,
    left: &mut Vec<SimFeature>,
    right: &mut Vec<SimFeature>,
) {
    #[allow(clippy::cast_precision_loss)]
    let (lo, hi_x, hi_y) = (
        CANDIDATE_BORDER as f64,
        (regs.width - 1 - CANDIDATE_BORDER) as f64,
        (regs.height - 1 - CANDIDATE_BORDER) as f64,
    );
    // Clutter is weaker than lamps, but above the threshold: 1.1x to 12x of it.
    let base = f64::from(regs.threshold.max(1 << 16));
    fn strength<R: Rng>(base: f64, rng: &mut R) -> i32 {
        let k: f64 = rng.random_range(0.1..2.5);
        #[allow(clippy::cast_possible_truncation)] // clamped to the i32 range
        let r = (base * k.exp()).min(f64::from(i32::MAX)) as i32;
        r
    }
    let point =
        |rng: &mut R| -> (f64, f64) { (rng.random_range(lo..hi_x), rng.random_range(lo..hi_y)) };
    for out in [&mut *left, &mut *right] {
        for _ in 0..poisson(clutter.per_image, rng) {
            let (u, v) = point(rng);
            if let (Some(x_q4), Some(y_q4)) = (quantise_q4(u), quantise_q4(v)) {
                out.push(SimFeature {
                    x_q4,
                    y_q4,
                    r: strength(base, rng),
                    lamp: None,
                });
            }
        }
    }
    for _ in 0..poisson(clutter.stereo_per_frame, rng) {
        let (u, v) = point(rng);
        let disparity: f64 = rng.random_range(2.0..60.0);
        let r = strength(base, rng);
        let ur = u - disparity;
        if ur < lo {
            continue;
        }
        for (out, u) in [(&mut *left, u), (&mut *right, ur)] {
            if let (Some(x_q4), Some(y_q4)) = (quantise_q4(u), quantise_q4(v)) {
                out.push(SimFeature {
                    x_q4,
                    y_q4,
                    r,
                    lamp: None,
                });
            }
        }
    }
}

/// The board's treatment of a set of features: 3x3 non-maximum suppression between them
/// (two features never sit on neighbouring integer pixels; the stronger one, or the first in
/// raster order on a tie, survives), dropping responses at or below `THRESHOLD`, raster order
/// by integer pixel `(row, column)`, and the `MAX_FEATURES` cap with its overflow flag.
pub fn board_order(mut features: Vec<SimFeature>, regs: &Registers) -> ImageFeatures {
    features.retain(|f| f.r > regs.threshold);
    // Strongest first; ties by raster order, as the board's suppression breaks them.
    features.sort_by(|a, b| b.r.cmp(&a.r).then(a.raster_key().cmp(&b.raster_key())));
    let mut kept: Vec<SimFeature> = Vec::with_capacity(features.len());
    for f in features {
        let (y, x) = f.raster_key();
        let clash = kept.iter().any(|k| {
            let (ky, kx) = k.raster_key();
            ky.abs_diff(y) <= 1 && kx.abs_diff(x) <= 1
        });
        if !clash {
            kept.push(f);
        }
    }
    kept.sort_by_key(SimFeature::raster_key);
    let overflow = kept.len() > regs.max_features;
    kept.truncate(regs.max_features);
    ImageFeatures {
        features: kept,
        overflow,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn f(x: f64, y: f64, r: i32) -> SimFeature {
        SimFeature {
            x_q4: quantise_q4(x).unwrap_or(0),
            y_q4: quantise_q4(y).unwrap_or(0),
            r,
            lamp: None,
        }
    }

    #[test]
    fn board_order_sorts_suppresses_and_caps() {
        let regs = Registers {
            max_features: 2,
            threshold: 10,
            ..Registers::default()
        };
        // (100.4, 50) and (99.6, 51) are neighbours: the weaker goes. (10, 60) is below the
        // threshold. The rest sorted by row then column; the cap keeps the first two.
        let out = board_order(
            vec![
                f(300.0, 80.0, 50),
                f(100.4, 50.0, 40),
                f(99.6, 51.0, 30),
                f(10.0, 60.0, 5),
                f(200.0, 49.6, 20),
            ],
            &regs,
        );
        let got: Vec<(u16, u16)> = out.features.iter().map(|f| (f.x_q4, f.y_q4)).collect();
        assert_eq!(got, vec![(1606, 800), (3200, 794)]);
        assert!(out.overflow);
        // A row ending in .5 rounds up in Q4 but sorts by (y_q4 + 8) / 16.
        assert_eq!(raster_key(16 * 7 + 8, 16 * 3 + 8), (4, 8));
        assert_eq!(raster_key(16 * 7 + 7, 16 * 3 + 7), (3, 7));
    }

    #[test]
    fn candidate_area() {
        assert!(in_candidate_area(4.0, 4.0, 752, 480));
        assert!(in_candidate_area(3.6, 475.4, 752, 480));
        assert!(!in_candidate_area(3.4, 10.0, 752, 480));
        assert!(!in_candidate_area(747.6, 10.0, 752, 480));
    }
}
