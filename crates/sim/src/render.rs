//! The rendered mode: 8-bit left and right images of the lamps over a roof with beams, as the
//! board's sensors would see them, for the board's own detector.
//!
//! A lamp is a uniformly bright disk whose apparent radius is `f * radius / depth`, blurred by
//! the optics (a Gaussian of `optics_blur_px`) and integrated over each pixel's area. The
//! integral is exact across each thin horizontal strip of the disk (the Gaussian's integral
//! over a pixel and a line segment has a closed form) and a fine sum along the disk's height,
//! so the image of a lamp is centred on its projection to far better than the detector's
//! 1/16 pixel. The roof is a plane seen through each pixel's ray, with anti-aliased beams.
//! The sensor adds shot noise and read noise and rounds to 8 bits.
//!
//! **Through real lenses** ([`Renderer::with_lens`]: the rig's `[lens.*]` tables, taken as the
//! truth) each camera's image is its raw sensor's: distorted and unrectified, what the board's
//! detector sees on a real vehicle (vehicle-interfaces.md 1.1). Every raw pixel sees along
//! its own ray (undistorted through the lens model, rotated by the rectification into the
//! rig's orientation), computed once per renderer; the roof, its beams and the panels are
//! drawn through those rays.
//!
//! A lamp is drawn in raw pixels as the lens maps it locally: its disk, centred on the raw
//! pixel of its rectified projection ([`Lens::unrectify`]), mapped by the lens's Jacobian
//! there (`d raw / d rectified`) into an ellipse, which the same strips integrate exactly
//! (its light centred on that raw pixel to 1e-5 px), as bright per raw pixel of area as the
//! disk (a lens keeps the brightness of what it images), blurred by the optics in raw pixels
//! (the blur is the lens's, on the sensor). Why the local map rather than each raw pixel
//! through the exact lens: the lamps are points, half a pixel across in the halls, over which
//! the lens is affine to far below the detector's 1/16 px (the second order moves the light
//! of a disk of radius `r` by about `r^2 / 8` times the map's second derivatives, and the
//! magnification's change across it by as much again: under 1e-3 px for a 1 px lamp in the
//! corners of EuRoC's lens, 2e-3 px in a fisheye), while supersampling a lamp finely enough
//! for that (thousands of points a pixel) costs far more and still has to blur each point.
//! Where the lens does bend over a lamp (a large lamp, or one far out in a fisheye's field:
//! [`MAX_AFFINE_BEND_PX`]), the lamp is drawn through the exact rays instead
//! ([`Renderer::draw_large_lamp`]). `tests/integration/lens.rs` checks both against the
//! exact lens, and the board's detector on the raw images of EuRoC's lens and a fisheye.

use harris_core::Registers;
use nalgebra::{Matrix2, Vector2, Vector3};
use rand::Rng;
use rand_distr::{Distribution, StandardNormal};
use rig_model::lens::{Lens, StereoLens};
use rig_model::{CameraParams, Pose2};

use crate::features::RigFromWorld;
use crate::scenario::{Beams, Render};
use crate::world::{Lamp, Panel};

/// Strips per pixel of a lamp's apparent diameter (the sum along the disk's height).
const STRIPS_PER_PIXEL: f64 = 8.0;
/// A lamp's blurred image is drawn out to this many blur sigmas beyond its disk.
const PATCH_SIGMAS: f64 = 4.5;
/// At most this many strips per lamp (a lamp hundreds of pixels across is no point lamp).
const MAX_STRIPS: f64 = 4096.0;
/// Points along each edge of a panel whose raw pixels bound its raw image (a lens bends the
/// edges: the corners alone do not bound it).
const PANEL_EDGE_SAMPLES: usize = 32;
/// Through a lens, a lamp over which the lens bends by more than this, raw pixels (the sum
/// over two axes of the outline's second-order offsets, about four times the centroid's), is
/// drawn through the lens's exact map ([`Renderer::draw_large_lamp`]) rather than its local
/// affine map. The light of a lamp drawn through the affine map is then within about 0.005 px
/// of the exact map's (which also weighs the light by the lens's varying magnification). The
/// point lamps of the halls (half a pixel across) stay far below it; in the corners of
/// EuRoC's lens a lamp of 2 px radius reaches it.
const MAX_AFFINE_BEND_PX: f64 = 0.005;
/// Points of the supersampling grid along the smaller half-axis of a large lamp's raw image (at
/// least 4 and at most 64 a pixel): about 13,000 points on any lamp, which put its light
/// within 0.006 px of the exact integral's (16 leave 0.03 px).
const LARGE_LAMP_SAMPLES: f64 = 64.0;
/// Points along a large lamp's outline whose raw pixels bound its raw image.
const LAMP_OUTLINE_SAMPLES: usize = 64;
/// A rectified ray must point this far in front of the camera (as [`Lens::rectify`] asks).
const MIN_RAY_Z: f64 = 1e-9;

/// One stereo pair of 8-bit images, row-major.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct StereoImages {
    /// Pixels per row.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// The left camera's image.
    pub left: Vec<u8>,
    /// The right camera's image.
    pub right: Vec<u8>,
}

/// Which camera of the rig.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Side {
    /// The camera at `-B/2` along rig x.
    Left,
    /// The camera at `+B/2`.
    Right,
}

/// Draws the scene as the board's cameras see it.
#[derive(Debug, Clone)]
pub struct Renderer {
    camera: CameraParams,
    width: usize,
    height: usize,
    params: Render,
    lamps: Vec<Lamp>,
    /// `(u - cx) / f` of each column.
    ray_x: Vec<f64>,
    /// `(v - cy) / f` of each row.
    ray_y: Vec<f64>,
    /// The raw cameras, left and right, when the images are drawn through real lenses.
    raw: Option<Box<[RawCamera; 2]>>,
}

/// One raw camera: its lens and the ray of each of its pixels.
#[derive(Clone)]
struct RawCamera {
    lens: Lens,
    width: usize,
    height: usize,
    /// The unit ray of each raw pixel's centre in the rig's (rectified) orientation, row-major;
    /// NaN where the lens gives none (the undistortion does not converge, or the rectified
    /// ray points behind the camera): such a pixel sees the bare roof.
    rays: Vec<[f64; 3]>,
    /// The angle each raw pixel spans, radians (the square root of its solid angle): the
    /// anti-aliasing of the beams' edges.
    pixel_rad: Vec<f64>,
}

impl std::fmt::Debug for RawCamera {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RawCamera")
            .field("lens", &self.lens)
            .field("width", &self.width)
            .field("height", &self.height)
            .finish_non_exhaustive()
    }
}

impl RawCamera {
    fn new(lens: Lens, width: usize, height: usize) -> Self {
        let mut rays = Vec::with_capacity(width * height);
        for v in 0..height {
            for u in 0..width {
                #[allow(clippy::cast_precision_loss)] // image sizes are at most 4095
                let d = Vector2::new(
                    (u as f64 - lens.cx) / lens.fx,
                    (v as f64 - lens.cy) / lens.fy,
                );
                let ray = lens
                    .model
                    .undistort(d)
                    .map(|p| lens.rectification * Vector3::new(p.x, p.y, 1.0))
                    .filter(|r| r.z > MIN_RAY_Z && r.iter().all(|x| x.is_finite()));
                rays.push(ray.map_or([f64::NAN; 3], |r| {
                    let n = r.normalize();
                    [n.x, n.y, n.z]
                }));
            }
        }
        // The pixel's span from its neighbours' rays (one-sided at the edges of the image and
        // of the lens's field).
        let valid = |i: usize| rays.get(i).is_some_and(|r| r[0].is_finite());
        let diff = |i: usize, before: Option<usize>, after: Option<usize>| -> Option<[f64; 3]> {
            let sub = |a: usize, b: usize, n: f64| {
                let (ra, rb) = (rays.get(a)?, rays.get(b)?);
                Some([
                    (ra[0] - rb[0]) / n,
                    (ra[1] - rb[1]) / n,
                    (ra[2] - rb[2]) / n,
                ])
            };
            match (before.filter(|&b| valid(b)), after.filter(|&a| valid(a))) {
                (Some(b), Some(a)) => sub(a, b, 2.0),
                (Some(b), None) => sub(i, b, 1.0),
                (None, Some(a)) => sub(a, i, 1.0),
                (None, None) => None,
            }
        };
        let fallback = 1.0 / lens.fx.max(lens.fy);
        let pixel_rad = (0..width * height)
            .map(|i| {
                if !valid(i) {
                    return fallback;
                }
                let (u, v) = (i % width, i / width);
                let du = diff(i, (u > 0).then(|| i - 1), (u + 1 < width).then_some(i + 1));
                let dv = diff(
                    i,
                    (v > 0).then(|| i - width),
                    (v + 1 < height).then_some(i + width),
                );
                match (du, dv) {
                    (Some(a), Some(b)) => {
                        let n = Vector3::from(a).cross(&Vector3::from(b)).norm().sqrt();
                        if n.is_finite() && n > 0.0 {
                            n
                        } else {
                            fallback
                        }
                    }
                    _ => fallback,
                }
            })
            .collect();
        Self {
            lens,
            width,
            height,
            rays,
            pixel_rad,
        }
    }

    /// The unit ray at the raw position `(u, v)` (pixels, any fraction), interpolated
    /// bilinearly between the pixels' rays; NaN where one of them has none.
    fn ray_at(&self, u: f64, v: f64) -> [f64; 3] {
        #[allow(clippy::cast_precision_loss)]
        let (u, v) = (
            u.clamp(0.0, (self.width - 1) as f64),
            v.clamp(0.0, (self.height - 1) as f64),
        );
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        // clamped to the image just above
        let (i, j) = (u.floor() as usize, v.floor() as usize);
        let (i1, j1) = ((i + 1).min(self.width - 1), (j + 1).min(self.height - 1));
        #[allow(clippy::cast_precision_loss)]
        let (fu, fv) = (u - i as f64, v - j as f64);
        let at = |x: usize, y: usize| {
            self.rays
                .get(y * self.width + x)
                .copied()
                .unwrap_or([f64::NAN; 3])
        };
        let (a, b, c, d) = (at(i, j), at(i1, j), at(i, j1), at(i1, j1));
        let mut r = [0.0; 3];
        for (k, x) in r.iter_mut().enumerate() {
            *x =
                (1.0 - fv) * ((1.0 - fu) * a[k] + fu * b[k]) + fv * ((1.0 - fu) * c[k] + fu * d[k]);
        }
        let n = (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]).sqrt();
        [r[0] / n, r[1] / n, r[2] / n]
    }
}

/// How the roof looks where a ray meets it.
struct Roof<'a> {
    p: &'a Render,
    half_w: f64,
    half_h: f64,
    inv_spacing: f64,
}

impl<'a> Roof<'a> {
    fn new(p: &'a Render) -> Self {
        Self {
            p,
            half_w: p.beam_width_m / 2.0,
            half_h: p.beam_highlight_width_m / 2.0,
            inv_spacing: 1.0 / p.beam_spacing_m,
        }
    }

    /// The brightness at the roof point `(x, y)` seen by a pixel `pixel_m` across there (beam
    /// edges are ramps about one blurred pixel wide).
    fn value(&self, x: f64, y: f64, pixel_m: f64) -> f64 {
        let p = self.p;
        let coverage = |t: f64| -> f64 {
            let d =
                (t * self.inv_spacing - (t * self.inv_spacing).round()).abs() * p.beam_spacing_m;
            ((self.half_w - d) / pixel_m + 0.5).clamp(0.0, 1.0)
        };
        // The reflection along each beam's middle.
        let glint = |t: f64| -> f64 {
            if p.beam_highlight_dn <= 0.0 {
                return 0.0;
            }
            let d =
                (t * self.inv_spacing - (t * self.inv_spacing).round()).abs() * p.beam_spacing_m;
            ((self.half_h - d) / pixel_m + 0.5).clamp(0.0, 1.0)
        };
        let (c, g) = match p.beams {
            Beams::X => (coverage(y), glint(y)),
            Beams::Y => (coverage(x), glint(x)),
            Beams::Both => (coverage(y).max(coverage(x)), glint(y).max(glint(x))),
            Beams::None => (0.0, 0.0),
        };
        let (roof, beam) = (p.roof_dn, p.beam_dn);
        roof + (beam - roof) * c + (p.beam_highlight_dn - beam).max(0.0) * g
    }
}

/// Where a camera's pixels are and how they see: through the rectified pinhole model of the
/// rig, or through its raw lens.
#[derive(Clone, Copy)]
enum View<'a> {
    Rectified,
    Raw(&'a RawCamera),
}

impl Renderer {
    /// A renderer for the true camera `camera`, the image size of `regs`, the optics, sensor
    /// and background of `params`, and the lamps. Its images are rectified (the pinhole model
    /// of vehicle-interfaces.md 1); [`Renderer::with_lens`] makes them raw.
    pub fn new(camera: CameraParams, regs: &Registers, params: Render, lamps: Vec<Lamp>) -> Self {
        #[allow(clippy::cast_precision_loss)] // image sizes are at most 4095
        let ray_x = (0..regs.width)
            .map(|u| (u as f64 - camera.cx) / camera.f)
            .collect();
        #[allow(clippy::cast_precision_loss)]
        let ray_y = (0..regs.height)
            .map(|v| (v as f64 - camera.cy) / camera.f)
            .collect();
        Self {
            camera,
            width: regs.width,
            height: regs.height,
            params,
            lamps,
            ray_x,
            ray_y,
            raw: None,
        }
    }

    /// The same renderer drawing each camera's raw image through its real lens (the rig's
    /// `[lens.left]` and `[lens.right]`, taken as the truth, which map raw pixels into the
    /// rectified model of this renderer's true camera, as the fast mode's features do): every
    /// raw pixel sees along the ray that the lens model and the rectification give it
    /// (vehicle-interfaces.md 1.1). The rays are computed here, once (two undistortions per
    /// pixel pair).
    #[must_use]
    pub fn with_lens(mut self, lens: &StereoLens) -> Self {
        self.raw = Some(Box::new([
            RawCamera::new(lens.left, self.width, self.height),
            RawCamera::new(lens.right, self.width, self.height),
        ]));
        self
    }

    /// The lenses the images are drawn through, if any.
    pub fn lens(&self) -> Option<StereoLens> {
        self.raw.as_ref().map(|r| StereoLens {
            left: r[0].lens,
            right: r[1].lens,
        })
    }

    /// The lamps (those not `lit` are not drawn).
    pub fn lamps(&self) -> &[Lamp] {
        &self.lamps
    }

    /// Both images at `pose`; `noise` draws the sensor noise of the left then the right image
    /// (`None`: clean images, exactly the expected sensor values rounded).
    pub fn render<R: Rng>(&self, pose: &Pose2, noise: Option<(&mut R, &mut R)>) -> StereoImages {
        let (left, right) = match noise {
            Some((l, r)) => (
                self.render_side(pose, Side::Left, Some(l)),
                self.render_side(pose, Side::Right, Some(r)),
            ),
            None => (
                self.render_side::<R>(pose, Side::Left, None),
                self.render_side::<R>(pose, Side::Right, None),
            ),
        };
        StereoImages {
            width: self.width,
            height: self.height,
            left,
            right,
        }
    }

    /// One camera's image.
    pub fn render_side<R: Rng>(&self, pose: &Pose2, side: Side, noise: Option<&mut R>) -> Vec<u8> {
        sensor(&self.radiance(pose, side), &self.params, noise)
    }

    /// One camera's expected sensor values (DN, before noise and rounding), row-major.
    pub fn radiance(&self, pose: &Pose2, side: Side) -> Vec<f32> {
        let mut radiance = vec![0.0f32; self.width * self.height];
        let view = self.view(side);
        match view {
            View::Rectified => self.draw_background(pose, side, &mut radiance),
            View::Raw(raw) => self.draw_background_raw(pose, side, raw, &mut radiance),
        }
        self.draw_lamps(pose, side, view, &mut radiance);
        radiance
    }

    fn view(&self, side: Side) -> View<'_> {
        match (&self.raw, side) {
            (None, _) => View::Rectified,
            (Some(raw), Side::Left) => View::Raw(&raw[0]),
            (Some(raw), Side::Right) => View::Raw(&raw[1]),
        }
    }

    /// The camera centre in the world and the world direction of rig ray `(a, b, 1)` as
    /// `a * ex + b * ey + ez`.
    fn rays(&self, pose: &Pose2, side: Side) -> ([f64; 3], [[f64; 3]; 3]) {
        let world_from_rig =
            pose.world_from_robot_rotation() * self.camera.mount.robot_from_rig_rotation();
        let half_b = self.camera.baseline / 2.0;
        let centre_in_rig = Vector3::new(
            match side {
                Side::Left => -half_b,
                Side::Right => half_b,
            },
            0.0,
            0.0,
        );
        let centre_in_robot = self.camera.mount.robot_from_rig_rotation() * centre_in_rig
            + self.camera.mount.translation();
        let centre = pose.point_in_world(&centre_in_robot);
        let col = |i: usize| {
            let c = world_from_rig.column(i);
            [c[0], c[1], c[2]]
        };
        ([centre.x, centre.y, centre.z], [col(0), col(1), col(2)])
    }

    fn draw_background(&self, pose: &Pose2, side: Side, out: &mut [f32]) {
        let p = &self.params;
        let (o, [ex, ey, ez]) = self.rays(pose, side);
        let dz_roof = p.roof_z_m - o[2];
        let roof = Roof::new(p);
        // Beam edges are ramps about one blurred pixel wide.
        let soft = (1.0 + 2.0 * p.optics_blur_px) / self.camera.f;
        for (row, b) in out.chunks_exact_mut(self.width).zip(&self.ray_y) {
            let base = [ey[0] * b + ez[0], ey[1] * b + ez[1], ey[2] * b + ez[2]];
            for (px, a) in row.iter_mut().zip(&self.ray_x) {
                let dz = ex[2] * a + base[2];
                let value = if dz <= 1e-9 || p.beams == Beams::None {
                    p.roof_dn
                } else {
                    let lambda = dz_roof / dz;
                    let x = o[0] + lambda * (ex[0] * a + base[0]);
                    let y = o[1] + lambda * (ex[1] * a + base[1]);
                    roof.value(x, y, lambda * soft)
                };
                #[allow(clippy::cast_possible_truncation)] // DN values, far inside f32
                {
                    *px = value as f32;
                }
            }
        }
    }

    /// The roof and beams through a raw camera's rays: a pixel `pixel_rad` across sees
    /// `distance * pixel_rad` of the roof, blurred over about `1 + 2 optics_blur_px` of it.
    fn draw_background_raw(&self, pose: &Pose2, side: Side, raw: &RawCamera, out: &mut [f32]) {
        let p = &self.params;
        let (o, [ex, ey, ez]) = self.rays(pose, side);
        let dz_roof = p.roof_z_m - o[2];
        let roof = Roof::new(p);
        let soft = 1.0 + 2.0 * p.optics_blur_px;
        for ((px, r), span) in out.iter_mut().zip(&raw.rays).zip(&raw.pixel_rad) {
            let dz = ex[2] * r[0] + ey[2] * r[1] + ez[2] * r[2];
            // NaN (no ray) fails the test too: the bare roof.
            let value = if !in_front(dz) || p.beams == Beams::None {
                p.roof_dn
            } else {
                let distance = dz_roof / dz;
                let x = o[0] + distance * (ex[0] * r[0] + ey[0] * r[1] + ez[0] * r[2]);
                let y = o[1] + distance * (ex[1] * r[0] + ey[1] * r[1] + ez[1] * r[2]);
                roof.value(x, y, distance * span * soft)
            };
            #[allow(clippy::cast_possible_truncation)] // DN values, far inside f32
            {
                *px = value as f32;
            }
        }
    }

    fn draw_lamps(&self, pose: &Pose2, side: Side, view: View<'_>, out: &mut [f32]) {
        let c = &self.camera;
        let rig_from_world = RigFromWorld::new(c, pose);
        let sigma = self.params.optics_blur_px;
        #[allow(clippy::cast_precision_loss)]
        let (w, h) = (self.width as f64, self.height as f64);
        let half_b = match side {
            Side::Left => c.baseline / 2.0,
            Side::Right => -c.baseline / 2.0,
        };
        let mut panels_drawn: Vec<u32> = Vec::new();
        // A dark panel's points are all dark (scenario validation): it is not drawn.
        for lamp in self.lamps.iter().filter(|l| l.lit) {
            if let Some(panel) = &lamp.panel {
                if !panels_drawn.contains(&panel.index) {
                    panels_drawn.push(panel.index);
                    self.draw_panel(pose, side, view, panel, out);
                }
                continue;
            }
            let p = rig_from_world.apply(&lamp.position);
            if p.z <= 1e-3 {
                continue;
            }
            let u = c.cx + c.f * (p.x + half_b) / p.z;
            let v = c.cy + c.f * p.y / p.z;
            let radius_px = c.f * lamp.radius_m / p.z;
            let (u, v, shape) = match view {
                View::Rectified => (u, v, None),
                View::Raw(raw) => {
                    // The disk's centre in the raw image, and the lens's local map there.
                    let rect = Vector2::new(u, v);
                    let Some(at) = raw.lens.unrectify(rect, c.f, c.cx, c.cy) else {
                        continue;
                    };
                    let Some(raw_from_rect) = raw
                        .lens
                        .rectify(at, c.f, c.cx, c.cy)
                        .and_then(|(_, rect_from_raw)| rect_from_raw.try_inverse())
                    else {
                        continue;
                    };
                    // How far the lens bends away from its affine map over the disk: the
                    // midpoints of opposite points of the outline off the centre (half the
                    // second-order term along each axis; the centroid moves by about a
                    // quarter of their sum).
                    let bend = [Vector2::new(radius_px, 0.0), Vector2::new(0.0, radius_px)]
                        .iter()
                        .map(|e| {
                            let unrect = |p| raw.lens.unrectify(p, c.f, c.cx, c.cy);
                            match (unrect(rect + e), unrect(rect - e)) {
                                (Some(a), Some(b)) => ((a + b) / 2.0 - at).norm(),
                                _ => f64::INFINITY,
                            }
                        })
                        .sum::<f64>();
                    if bend > MAX_AFFINE_BEND_PX {
                        let (extent_u, extent_v) = blob_extent(radius_px, Some(&raw_from_rect));
                        self.draw_large_lamp(
                            raw,
                            rect,
                            radius_px,
                            extent_u.min(extent_v),
                            lamp.radiance_dn,
                            out,
                        );
                        continue;
                    }
                    (at.x, at.y, Some(raw_from_rect))
                }
            };
            let (extent_u, extent_v) = blob_extent(radius_px, shape.as_ref());
            let (reach_u, reach_v) = (
                extent_u + PATCH_SIGMAS * sigma + 1.0,
                extent_v + PATCH_SIGMAS * sigma + 1.0,
            );
            if u < -reach_u || v < -reach_v || u > w + reach_u || v > h + reach_v {
                continue;
            }
            self.draw_blob(u, v, radius_px, shape.as_ref(), lamp.radiance_dn, out);
        }
    }

    /// Adds a panel: each pixel's coverage by the rectangle, from a 4 x 4 grid of rays per
    /// pixel through the panel's plane, blurred by the optics (a separable Gaussian).
    /// Supersampled rather than exact like the disk: the panel's edges are long and straight,
    /// and the corners the detector sees are blurred over pixels anyway. Through a lens the
    /// rays of the grid are interpolated between the raw pixels' rays (bilinearly: the lens
    /// map bends by far less than a hundredth of a pixel over one pixel).
    fn draw_panel(&self, pose: &Pose2, side: Side, view: View<'_>, panel: &Panel, out: &mut [f32]) {
        let c = &self.camera;
        let rig_from_world = RigFromWorld::new(c, pose);
        let half_b = match side {
            Side::Left => c.baseline / 2.0,
            Side::Right => -c.baseline / 2.0,
        };
        // The image box of the panel: its corners projected (through a lens, points all along
        // its edges).
        let (s, co) = panel.yaw.sin_cos();
        let (l, hw) = (panel.half_length_m, panel.half_width_m);
        let corners = [(-l, -hw), (l, -hw), (l, hw), (-l, hw)];
        let outline: Vec<(f64, f64)> = match view {
            View::Rectified => corners.to_vec(),
            View::Raw(_) => (0..4)
                .flat_map(|k| {
                    let (a, b) = (corners[k], corners[(k + 1) % 4]);
                    (0..PANEL_EDGE_SAMPLES).map(move |i| {
                        #[allow(clippy::cast_precision_loss)]
                        let t = i as f64 / PANEL_EDGE_SAMPLES as f64;
                        (a.0 + t * (b.0 - a.0), a.1 + t * (b.1 - a.1))
                    })
                })
                .collect(),
        };
        let mut bounds = (
            f64::INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NEG_INFINITY,
        );
        for (a, b) in outline {
            let q = Vector3::new(
                panel.centre.x + co * a - s * b,
                panel.centre.y + s * a + co * b,
                panel.centre.z,
            );
            let p = rig_from_world.apply(&q);
            if p.z <= 1e-3 {
                return; // partly behind the camera: not drawn
            }
            let u = c.cx + c.f * (p.x + half_b) / p.z;
            let v = c.cy + c.f * p.y / p.z;
            let (u, v) = match view {
                View::Rectified => (u, v),
                View::Raw(raw) => match raw.lens.unrectify(Vector2::new(u, v), c.f, c.cx, c.cy) {
                    Some(at) => (at.x, at.y),
                    None => return, // partly outside the lens's field: not drawn
                },
            };
            bounds = (
                bounds.0.min(u),
                bounds.1.min(v),
                bounds.2.max(u),
                bounds.3.max(v),
            );
        }
        let (o, [ex, ey, ez]) = self.rays(pose, side);
        // The rig ray of an image position: `(a, b, 1)` in the rectified image, a unit ray
        // through a lens.
        let ray = |uu: f64, vv: f64| -> [f64; 3] {
            match view {
                View::Rectified => [(uu - c.cx) / c.f, (vv - c.cy) / c.f, 1.0],
                View::Raw(raw) => raw.ray_at(uu, vv),
            }
        };
        self.draw_covered(bounds, 4, panel.radiance_dn, out, |uu, vv| {
            let [a, b, z] = ray(uu, vv);
            let dz = ex[2] * a + ey[2] * b + ez[2] * z;
            // NaN (no ray through a lens) fails the test too.
            if !in_front(dz) {
                return false;
            }
            let lambda = (panel.centre.z - o[2]) / dz;
            let x = o[0] + lambda * (ex[0] * a + ey[0] * b + ez[0] * z);
            let y = o[1] + lambda * (ex[1] * a + ey[1] * b + ez[1] * z);
            lambda > 0.0 && panel.contains(x, y)
        });
    }

    /// Adds a lamp of radius `radius_px` centred at `rect` in the rectified image, through a
    /// lens, by supersampling its raw pixels through their rays (as a panel: a point is on
    /// the lamp when its ray falls inside the rectified disk), at least
    /// [`LARGE_LAMP_SAMPLES`] points along its smaller raw half-axis `half_axis_px`. For lamps
    /// over which the lens is not affine ([`MAX_AFFINE_BEND_PX`]): large ones, or those far
    /// out in a fisheye's field.
    fn draw_large_lamp(
        &self,
        raw: &RawCamera,
        rect: Vector2<f64>,
        radius_px: f64,
        half_axis_px: f64,
        radiance: f64,
        out: &mut [f32],
    ) {
        let c = &self.camera;
        let mut bounds = (
            f64::INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NEG_INFINITY,
        );
        for i in 0..LAMP_OUTLINE_SAMPLES {
            #[allow(clippy::cast_precision_loss)]
            let angle = std::f64::consts::TAU * i as f64 / LAMP_OUTLINE_SAMPLES as f64;
            let (s, co) = angle.sin_cos();
            // A little outside the disk: the raw outline bulges between the samples.
            let at = rect + 1.05 * radius_px * Vector2::new(co, s);
            match raw.lens.unrectify(at, c.f, c.cx, c.cy) {
                Some(p) => {
                    bounds = (
                        bounds.0.min(p.x),
                        bounds.1.min(p.y),
                        bounds.2.max(p.x),
                        bounds.3.max(p.y),
                    );
                }
                None => return, // partly outside the lens's field: not drawn
            }
        }
        let (a0, b0) = ((rect.x - c.cx) / c.f, (rect.y - c.cy) / c.f);
        let r2 = (radius_px / c.f) * (radius_px / c.f);
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)] // clamped to 4..=64
        let sub = (LARGE_LAMP_SAMPLES / half_axis_px).ceil().clamp(4.0, 64.0) as usize;
        self.draw_splatted(bounds, sub, radiance, out, |uu, vv| {
            let [x, y, z] = raw.ray_at(uu, vv);
            if !in_front(z) {
                return false;
            }
            let (a, b) = (x / z - a0, y / z - b0);
            a * a + b * b <= r2
        });
    }

    /// Adds a shape of `radiance` DN per pixel of area whose image lies within `bounds`
    /// (`u_min, v_min, u_max, v_max`) from a `sub` x `sub` grid of points per pixel (`hit(u,
    /// v)`: whether the shape is seen at the image position), each blurred by the optics
    /// where it is and integrated over the pixels: the supersampled form of the disk's exact
    /// integral. Unlike a pixel's coverage blurred from the pixel's centre (a panel's), it
    /// keeps the position of a shape thinner than a pixel (a large lamp far out in a
    /// fisheye's field is a streak a fraction of a pixel wide).
    fn draw_splatted(
        &self,
        bounds: (f64, f64, f64, f64),
        sub: usize,
        radiance: f64,
        out: &mut [f32],
        hit: impl Fn(f64, f64) -> bool,
    ) {
        let sigma = self.params.optics_blur_px;
        let Some((x0, y0, cols, rows)) = self.patch(bounds, PATCH_SIGMAS * sigma + 1.0) else {
            return;
        };
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let reach = (PATCH_SIGMAS * sigma).ceil() as usize + 1;
        #[allow(clippy::cast_precision_loss)]
        let position = |first: usize, i: usize, s: usize| -> f64 {
            (first + i) as f64 - 0.5 + (s as f64 + 0.5) / sub as f64
        };
        // The share of a point at `t` (pixels) of pixel `p`: the Gaussian over the pixel.
        #[allow(clippy::cast_precision_loss)]
        let share = |p: usize, t: f64| -> f64 {
            let p = p as f64;
            phi((p + 0.5 - t) / sigma) - phi((p - 0.5 - t) / sigma)
        };
        // Pixels `first..=last` of the patch within reach of pixel `i`.
        let near = |i: usize, n: usize| (i.saturating_sub(reach), (i + reach).min(n - 1));
        // The shares of the columns for each point column (the same for every row).
        let column_shares: Vec<f64> = (0..cols * sub)
            .flat_map(|m| {
                let (i, s) = (m / sub, m % sub);
                let t = position(x0, i, s);
                (0..=2 * reach).map(move |j| {
                    let column = (i + j).checked_sub(reach).filter(|&c| c < cols);
                    column.map_or(0.0, |c| share(x0 + c, t))
                })
            })
            .collect();
        #[allow(clippy::cast_precision_loss)]
        let weight = radiance / (sub * sub) as f64;
        let mut patch = vec![0.0f64; cols * rows];
        let mut across = vec![0.0f64; cols];
        for k in 0..rows {
            for sy in 0..sub {
                let vv = position(y0, k, sy);
                across.fill(0.0);
                let mut any = false;
                for i in 0..cols {
                    for sx in 0..sub {
                        if !hit(position(x0, i, sx), vv) {
                            continue;
                        }
                        any = true;
                        let m = i * sub + sx;
                        let shares =
                            column_shares.get(m * (2 * reach + 1)..(m + 1) * (2 * reach + 1));
                        for (j, s) in shares.into_iter().flatten().enumerate() {
                            if let Some(a) =
                                (i + j).checked_sub(reach).and_then(|c| across.get_mut(c))
                            {
                                *a += s;
                            }
                        }
                    }
                }
                if !any {
                    continue;
                }
                let (first, last) = near(k, rows);
                for r in first..=last {
                    let e = weight * share(y0 + r, vv);
                    if let Some(row) = patch.get_mut(r * cols..(r + 1) * cols) {
                        for (p, &a) in row.iter_mut().zip(&across) {
                            *p += e * a;
                        }
                    }
                }
            }
        }
        self.add_patch(&patch, x0, y0, cols, out);
    }

    /// The pixels `(x0, y0, columns, rows)` of the box `bounds` (`u_min, v_min, u_max,
    /// v_max`) grown by `margin`, clipped to the image; `None` when it is wholly outside.
    fn patch(
        &self,
        bounds: (f64, f64, f64, f64),
        margin: f64,
    ) -> Option<(usize, usize, usize, usize)> {
        #[allow(clippy::cast_precision_loss)]
        let (w, h) = (self.width as f64, self.height as f64);
        if !(bounds.2 >= -margin
            && bounds.3 >= -margin
            && bounds.0 <= w + margin
            && bounds.1 <= h + margin)
        {
            return None;
        }
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)] // clamped
        let clamp = |x: f64, n: usize| -> usize { x.max(0.0).min(n as f64 - 1.0) as usize };
        let (x0, y0) = (
            clamp((bounds.0 - margin).floor(), self.width),
            clamp((bounds.1 - margin).floor(), self.height),
        );
        let (x1, y1) = (
            clamp((bounds.2 + margin).ceil(), self.width),
            clamp((bounds.3 + margin).ceil(), self.height),
        );
        Some((x0, y0, x1 - x0 + 1, y1 - y0 + 1))
    }

    /// Adds a patch of `cols` columns whose first pixel is `(x0, y0)` to the image.
    fn add_patch(&self, patch: &[f64], x0: usize, y0: usize, cols: usize, out: &mut [f32]) {
        for (k, row) in patch.chunks_exact(cols).enumerate() {
            let start = (y0 + k) * self.width + x0;
            if let Some(dst) = out.get_mut(start..start + cols) {
                for (d, &p) in dst.iter_mut().zip(row) {
                    #[allow(clippy::cast_possible_truncation)] // DN values, far inside f32
                    {
                        *d += p as f32;
                    }
                }
            }
        }
    }

    /// Adds a shape of `radiance` DN per pixel of area whose image lies within `bounds`
    /// (`u_min, v_min, u_max, v_max`): each pixel's coverage from a `sub` x `sub` grid of
    /// points per pixel (`hit(u, v)`: whether the shape is seen at the image position),
    /// blurred by the optics (a separable Gaussian).
    fn draw_covered(
        &self,
        bounds: (f64, f64, f64, f64),
        sub: usize,
        radiance: f64,
        out: &mut [f32],
        hit: impl Fn(f64, f64) -> bool,
    ) {
        let sigma = self.params.optics_blur_px;
        let margin = PATCH_SIGMAS * sigma + 1.0;
        let Some((x0, y0, cols, rows)) = self.patch(bounds, margin) else {
            return;
        };
        let mut cover = vec![0.0f64; cols * rows];
        for k in 0..rows {
            for i in 0..cols {
                let mut hits = 0usize;
                for sy in 0..sub {
                    #[allow(clippy::cast_precision_loss)]
                    let vv = (y0 + k) as f64 - 0.5 + (sy as f64 + 0.5) / sub as f64;
                    for sx in 0..sub {
                        #[allow(clippy::cast_precision_loss)]
                        let uu = (x0 + i) as f64 - 0.5 + (sx as f64 + 0.5) / sub as f64;
                        if hit(uu, vv) {
                            hits += 1;
                        }
                    }
                }
                if let Some(cv) = cover.get_mut(k * cols + i) {
                    #[allow(clippy::cast_precision_loss)]
                    {
                        *cv = hits as f64 / (sub * sub) as f64;
                    }
                }
            }
        }
        // The optics: a separable Gaussian over the patch.
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let reach = (PATCH_SIGMAS * sigma).ceil() as usize;
        #[allow(clippy::cast_precision_loss)]
        let kernel: Vec<f64> = (0..=2 * reach)
            .map(|t| {
                let x = t as f64 - reach as f64;
                phi((x + 0.5) / sigma.max(1e-6)) - phi((x - 0.5) / sigma.max(1e-6))
            })
            .collect();
        let blur = |src: &[f64], n: usize, stride: usize, count: usize, step: usize| {
            let mut dst = vec![0.0f64; src.len()];
            for line in 0..count {
                for t in 0..n {
                    let mut acc = 0.0;
                    for (j, kv) in kernel.iter().enumerate() {
                        let q = t + j;
                        if q < reach || q - reach >= n {
                            continue;
                        }
                        if let Some(v) = src.get(line * stride + (q - reach) * step) {
                            acc += kv * v;
                        }
                    }
                    if let Some(d) = dst.get_mut(line * stride + t * step) {
                        *d = acc;
                    }
                }
            }
            dst
        };
        let across = blur(&cover, cols, cols, rows, 1);
        let both = blur(&across, rows, 1, cols, cols);
        for k in 0..rows {
            let start = (y0 + k) * self.width + x0;
            if let (Some(dst), Some(src)) = (
                out.get_mut(start..start + cols),
                both.get(k * cols..(k + 1) * cols),
            ) {
                for (d, &p) in dst.iter_mut().zip(src) {
                    #[allow(clippy::cast_possible_truncation)] // DN values, far inside f32
                    {
                        *d += (p * radiance) as f32;
                    }
                }
            }
        }
    }

    /// Adds a disk of radius `radius_px` centred at `(u, v)`, of `radiance` DN per pixel of
    /// area, blurred by the optics and integrated over each pixel.
    #[cfg(test)]
    fn draw_disk(&self, u: f64, v: f64, radius_px: f64, radiance: f64, out: &mut [f32]) {
        self.draw_blob(u, v, radius_px, None, radiance, out);
    }

    /// Adds a lamp's disk of radius `radius_px` (rectified pixels), of `radiance` DN per pixel
    /// of area, blurred by the optics and integrated over each pixel: centred at `(u, v)` of
    /// the image drawn, and there either the disk itself (`shape` `None`: a rectified image)
    /// or its image under the affine map `shape` (`d raw / d rectified` of a lens at the
    /// centre: an ellipse in the raw image, with the brightness per raw pixel of area of the
    /// disk's, as a lens keeps the brightness of what it images).
    ///
    /// The ellipse `{J q : |q| <= r}` is cut into horizontal strips like the disk: with
    /// `A = J J^T`, the disk's strip at height `t` (`|t| <= r`, half-width `sqrt(r^2 - t^2)`)
    /// lies at row offset `sqrt(A22) t`, its middle at column offset `A12 / sqrt(A22) t`, its
    /// half-width scaled by `sqrt(det A) / sqrt(A22)`. The strips are symmetric about the
    /// centre, so the image's centroid is the centre exactly.
    fn draw_blob(
        &self,
        u: f64,
        v: f64,
        radius_px: f64,
        shape: Option<&Matrix2<f64>>,
        radiance: f64,
        out: &mut [f32],
    ) {
        let sigma = self.params.optics_blur_px;
        let (extent_u, extent_v) = blob_extent(radius_px, shape);
        let (reach_u, reach_v) = (
            extent_u + PATCH_SIGMAS * sigma + 1.0,
            extent_v + PATCH_SIGMAS * sigma + 1.0,
        );
        #[allow(clippy::cast_possible_truncation)] // clamped to the image just below
        let clamp = |x: f64, n: usize| -> usize { x.max(0.0).min(n as f64 - 1.0) as usize };
        #[allow(clippy::cast_precision_loss)]
        let (x0, x1, y0, y1) = (
            clamp((u - reach_u).floor(), self.width),
            clamp((u + reach_u).ceil(), self.width),
            clamp((v - reach_v).floor(), self.height),
            clamp((v + reach_v).ceil(), self.height),
        );
        let cols = x1 - x0 + 1;
        let rows = y1 - y0 + 1;
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        // positive and capped
        let strips = ((2.0 * extent_v * STRIPS_PER_PIXEL).ceil().min(MAX_STRIPS) as usize).max(1);
        #[allow(clippy::cast_precision_loss)]
        let strip_h = 2.0 * radius_px / strips as f64;
        // Each strip's row, middle and half-width in the image drawn, and its height there.
        let form = shape.map(|j| j * j.transpose());
        let strip_height = form.map_or(strip_h, |a| strip_h * a.m22.sqrt());
        #[allow(clippy::cast_precision_loss)]
        let segments: Vec<(f64, f64, f64)> = (0..strips)
            .map(|j| {
                let dy = -radius_px + (j as f64 + 0.5) * strip_h;
                let half_width = (radius_px * radius_px - dy * dy).max(0.0).sqrt();
                match form {
                    None => (v - radius_px + (j as f64 + 0.5) * strip_h, u, half_width),
                    Some(a) => {
                        let k = a.m22.sqrt();
                        let det = (a.m11 * a.m22 - a.m12 * a.m12).max(0.0);
                        (v + k * dy, u + a.m12 / k * dy, half_width * det.sqrt() / k)
                    }
                }
            })
            .collect();
        // The strips' areas normalised so that the disk's (or ellipse's) area is exact.
        let area: f64 = segments
            .iter()
            .map(|&(_, _, w)| 2.0 * w * strip_height)
            .sum();
        let exact = match form {
            None => std::f64::consts::PI * radius_px * radius_px,
            Some(a) => {
                std::f64::consts::PI
                    * radius_px
                    * radius_px
                    * (a.m11 * a.m22 - a.m12 * a.m12).max(0.0).sqrt()
            }
        };
        let scale = if area > 0.0 { exact / area } else { 0.0 };
        let mut patch = vec![0.0f64; cols * rows];
        let mut sx = vec![0.0f64; cols];
        let mut edge = vec![0.0f64; cols + 1];
        for &(sy, middle, hw) in &segments {
            let (a, b) = (middle - hw, middle + hw);
            // Integral over the segment [a, b] and the columns left of each pixel edge.
            for (k, e) in edge.iter_mut().enumerate() {
                #[allow(clippy::cast_precision_loss)]
                let x = (x0 + k) as f64 - 0.5;
                *e = if hw < 1e-6 {
                    2.0 * hw * phi((x - middle) / sigma)
                } else {
                    sigma * (psi((x - a) / sigma) - psi((x - b) / sigma))
                };
            }
            for (k, s) in sx.iter_mut().enumerate() {
                *s = edge[k + 1] - edge[k];
            }
            // Only the rows within reach of the strip's blur.
            let near = PATCH_SIGMAS * sigma + 1.0;
            #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
            // clamped to the patch's rows
            let (k0, k1) = (
                ((sy - near).floor() - y0 as f64).clamp(0.0, (rows - 1) as f64) as usize,
                ((sy + near).ceil() - y0 as f64).clamp(0.0, (rows - 1) as f64) as usize,
            );
            let weight = radiance * strip_height * scale;
            for k in k0..=k1 {
                #[allow(clippy::cast_precision_loss)]
                let y = (y0 + k) as f64;
                let e = phi((y + 0.5 - sy) / sigma) - phi((y - 0.5 - sy) / sigma);
                let we = weight * e;
                if let Some(row) = patch.get_mut(k * cols..(k + 1) * cols) {
                    for (p, &s) in row.iter_mut().zip(&sx) {
                        *p += we * s;
                    }
                }
            }
        }
        for (k, row) in patch.chunks_exact(cols).enumerate() {
            let start = (y0 + k) * self.width + x0;
            if let Some(dst) = out.get_mut(start..start + cols) {
                for (d, &p) in dst.iter_mut().zip(row) {
                    #[allow(clippy::cast_possible_truncation)] // DN values, far inside f32
                    {
                        *d += p as f32;
                    }
                }
            }
        }
    }
}

/// Half the width and half the height of a disk of radius `r` under the affine map `shape`
/// (the disk itself for `None`): `r sqrt(A11)`, `r sqrt(A22)` with `A = J J^T`.
fn blob_extent(r: f64, shape: Option<&Matrix2<f64>>) -> (f64, f64) {
    match shape {
        None => (r, r),
        Some(j) => {
            let a = j * j.transpose();
            (r * a.m11.sqrt(), r * a.m22.sqrt())
        }
    }
}

/// Whether a ray's component along the axis (the rig's z, or the world's up for the roof) points
/// ahead: false for NaN (no ray).
fn in_front(z: f64) -> bool {
    z > MIN_RAY_Z
}

/// The standard normal CDF.
fn phi(t: f64) -> f64 {
    0.5 * (1.0 + libm::erf(t * std::f64::consts::FRAC_1_SQRT_2))
}

/// `t Phi(t) + phi(t)`, the integral of the standard normal CDF.
fn psi(t: f64) -> f64 {
    let density = (-0.5 * t * t).exp() / (2.0 * std::f64::consts::PI).sqrt();
    t * phi(t) + density
}

/// The sensor: shot and read noise on the expected values, clipped and rounded to 8 bits.
fn sensor<R: Rng>(radiance: &[f32], params: &Render, noise: Option<&mut R>) -> Vec<u8> {
    let to_u8 = |x: f64| -> u8 {
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        // clamped to 0..=255 first
        let q = x.round().clamp(0.0, 255.0) as u8;
        q
    };
    match noise {
        None => radiance.iter().map(|&x| to_u8(f64::from(x))).collect(),
        Some(rng) => {
            let read_var = params.read_noise_dn * params.read_noise_dn;
            let shot = if params.electrons_per_dn > 0.0 {
                1.0 / params.electrons_per_dn
            } else {
                0.0
            };
            radiance
                .iter()
                .map(|&x| {
                    let x = f64::from(x);
                    let sd = (read_var + shot * x.max(0.0)).sqrt();
                    let z: f64 = StandardNormal.sample(&mut *rng);
                    to_u8(x + sd * z)
                })
                .collect()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenario::Render;

    fn renderer() -> Renderer {
        let camera = CameraParams {
            vehicle: Default::default(),
            f: 700.0,
            cx: 376.0,
            cy: 240.0,
            baseline: 0.12,
            mount: rig_model::Mount::default(),
        };
        Renderer::new(camera, &Registers::default(), Render::default(), Vec::new())
    }

    #[test]
    fn a_disk_keeps_its_flux_and_its_centre() {
        let r = renderer();
        for (u, v, radius) in [
            (100.3, 200.7, 0.9),
            (400.0, 100.5, 2.5),
            (50.77, 60.12, 0.01),
        ] {
            let mut img = vec![0.0f32; 752 * 480];
            r.draw_disk(u, v, radius, 100.0, &mut img);
            let (mut sum, mut su, mut sv) = (0.0, 0.0, 0.0);
            for (i, &p) in img.iter().enumerate() {
                let p = f64::from(p);
                sum += p;
                su += p * (i % 752) as f64;
                sv += p * (i / 752) as f64;
            }
            let flux = 100.0 * std::f64::consts::PI * radius * radius;
            assert!((sum - flux).abs() < 1e-4 * flux, "{sum} vs {flux}");
            assert!((su / sum - u).abs() < 1e-4 && (sv / sum - v).abs() < 1e-4);
        }
    }

    #[test]
    fn psi_is_the_integral_of_phi() {
        for (a, b) in [(-3.0, 0.5), (0.1, 0.2), (-0.7, 2.9)] {
            let n = 100_000;
            let h = (b - a) / f64::from(n);
            let numeric: f64 = (0..n).map(|i| phi(a + (f64::from(i) + 0.5) * h) * h).sum();
            assert!((psi(b) - psi(a) - numeric).abs() < 1e-9);
        }
    }
}
