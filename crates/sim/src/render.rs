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

use harris_core::Registers;
use rand::Rng;
use rand_distr::{Distribution, StandardNormal};
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
}

impl Renderer {
    /// A renderer for the true camera `camera`, the image size of `regs`, the optics, sensor
    /// and background of `params`, and the lamps.
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
        }
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
        let mut radiance = vec![0.0f32; self.width * self.height];
        self.draw_background(pose, side, &mut radiance);
        self.draw_lamps(pose, side, &mut radiance);
        sensor(&radiance, &self.params, noise)
    }

    /// The camera centre in the world and the world direction of rig ray `(a, b, 1)` as
    /// `a * ex + b * ey + ez`.
    fn rays(&self, pose: &Pose2, side: Side) -> ([f64; 3], [[f64; 3]; 3]) {
        let world_from_rig =
            pose.world_from_robot_rotation() * self.camera.mount.robot_from_rig_rotation();
        let half_b = self.camera.baseline / 2.0;
        let centre_in_rig = nalgebra::Vector3::new(
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
        let half_w = p.beam_width_m / 2.0;
        let inv_spacing = 1.0 / p.beam_spacing_m;
        let (roof, beam) = (p.roof_dn, p.beam_dn);
        // Beam edges are ramps about one blurred pixel wide.
        let soft = (1.0 + 2.0 * p.optics_blur_px) / self.camera.f;
        let coverage = |t: f64, pixel_m: f64| -> f64 {
            let d = (t * inv_spacing - (t * inv_spacing).round()).abs() * p.beam_spacing_m;
            ((half_w - d) / pixel_m + 0.5).clamp(0.0, 1.0)
        };
        // The reflection along each beam's middle.
        let half_h = p.beam_highlight_width_m / 2.0;
        let glint = |t: f64, pixel_m: f64| -> f64 {
            if p.beam_highlight_dn <= 0.0 {
                return 0.0;
            }
            let d = (t * inv_spacing - (t * inv_spacing).round()).abs() * p.beam_spacing_m;
            ((half_h - d) / pixel_m + 0.5).clamp(0.0, 1.0)
        };
        for (row, b) in out.chunks_exact_mut(self.width).zip(&self.ray_y) {
            let base = [ey[0] * b + ez[0], ey[1] * b + ez[1], ey[2] * b + ez[2]];
            for (px, a) in row.iter_mut().zip(&self.ray_x) {
                let dz = ex[2] * a + base[2];
                let value = if dz <= 1e-9 || p.beams == Beams::None {
                    roof
                } else {
                    let lambda = dz_roof / dz;
                    let x = o[0] + lambda * (ex[0] * a + base[0]);
                    let y = o[1] + lambda * (ex[1] * a + base[1]);
                    let pixel_m = lambda * soft;
                    let (c, g) = match p.beams {
                        Beams::X => (coverage(y, pixel_m), glint(y, pixel_m)),
                        Beams::Y => (coverage(x, pixel_m), glint(x, pixel_m)),
                        Beams::Both => (
                            coverage(y, pixel_m).max(coverage(x, pixel_m)),
                            glint(y, pixel_m).max(glint(x, pixel_m)),
                        ),
                        Beams::None => (0.0, 0.0),
                    };
                    roof + (beam - roof) * c + (p.beam_highlight_dn - beam).max(0.0) * g
                };
                #[allow(clippy::cast_possible_truncation)] // DN values, far inside f32
                {
                    *px = value as f32;
                }
            }
        }
    }

    fn draw_lamps(&self, pose: &Pose2, side: Side, out: &mut [f32]) {
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
                    self.draw_panel(pose, side, panel, out);
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
            let reach = radius_px + PATCH_SIGMAS * sigma + 1.0;
            if u < -reach || v < -reach || u > w + reach || v > h + reach {
                continue;
            }
            self.draw_disk(u, v, radius_px, lamp.radiance_dn, out);
        }
    }

    /// Adds a panel: each pixel's coverage by the rectangle, from a 4 x 4 grid of rays per
    /// pixel through the panel's plane, blurred by the optics (a separable Gaussian).
    /// Supersampled rather than exact like the disk: the panel's edges are long and straight,
    /// and the corners the detector sees are blurred over pixels anyway.
    fn draw_panel(&self, pose: &Pose2, side: Side, panel: &Panel, out: &mut [f32]) {
        const SUB: usize = 4;
        let c = &self.camera;
        let rig_from_world = RigFromWorld::new(c, pose);
        let half_b = match side {
            Side::Left => c.baseline / 2.0,
            Side::Right => -c.baseline / 2.0,
        };
        #[allow(clippy::cast_precision_loss)]
        let (w, h) = (self.width as f64, self.height as f64);
        // The image box of the panel: its corners (and centre) projected.
        let (s, co) = panel.yaw.sin_cos();
        let (l, hw) = (panel.half_length_m, panel.half_width_m);
        let mut bounds = (
            f64::INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NEG_INFINITY,
        );
        for (a, b) in [(-l, -hw), (l, -hw), (l, hw), (-l, hw)] {
            let q = nalgebra::Vector3::new(
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
            bounds = (
                bounds.0.min(u),
                bounds.1.min(v),
                bounds.2.max(u),
                bounds.3.max(v),
            );
        }
        let sigma = self.params.optics_blur_px;
        let margin = PATCH_SIGMAS * sigma + 1.0;
        if bounds.2 < -margin
            || bounds.3 < -margin
            || bounds.0 > w + margin
            || bounds.1 > h + margin
        {
            return;
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
        let (cols, rows) = (x1 - x0 + 1, y1 - y0 + 1);
        let (o, [ex, ey, ez]) = self.rays(pose, side);
        let mut cover = vec![0.0f64; cols * rows];
        for k in 0..rows {
            for i in 0..cols {
                let mut hits = 0usize;
                for sy in 0..SUB {
                    #[allow(clippy::cast_precision_loss)]
                    let vv = (y0 + k) as f64 - 0.5 + (sy as f64 + 0.5) / SUB as f64;
                    let b = (vv - c.cy) / c.f;
                    for sx in 0..SUB {
                        #[allow(clippy::cast_precision_loss)]
                        let uu = (x0 + i) as f64 - 0.5 + (sx as f64 + 0.5) / SUB as f64;
                        let a = (uu - c.cx) / c.f;
                        let dz = ex[2] * a + ey[2] * b + ez[2];
                        if dz <= 1e-9 {
                            continue;
                        }
                        let lambda = (panel.centre.z - o[2]) / dz;
                        let x = o[0] + lambda * (ex[0] * a + ey[0] * b + ez[0]);
                        let y = o[1] + lambda * (ex[1] * a + ey[1] * b + ez[1]);
                        if lambda > 0.0 && panel.contains(x, y) {
                            hits += 1;
                        }
                    }
                }
                if let Some(cv) = cover.get_mut(k * cols + i) {
                    #[allow(clippy::cast_precision_loss)]
                    {
                        *cv = hits as f64 / (SUB * SUB) as f64;
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
                        *d += (p * panel.radiance_dn) as f32;
                    }
                }
            }
        }
    }

    /// Adds a disk of radius `radius_px` centred at `(u, v)`, of `radiance` DN per pixel of
    /// area, blurred by the optics and integrated over each pixel.
    fn draw_disk(&self, u: f64, v: f64, radius_px: f64, radiance: f64, out: &mut [f32]) {
        let sigma = self.params.optics_blur_px;
        let reach = radius_px + PATCH_SIGMAS * sigma + 1.0;
        #[allow(clippy::cast_possible_truncation)] // clamped to the image just below
        let clamp = |x: f64, n: usize| -> usize { x.max(0.0).min(n as f64 - 1.0) as usize };
        #[allow(clippy::cast_precision_loss)]
        let (x0, x1, y0, y1) = (
            clamp((u - reach).floor(), self.width),
            clamp((u + reach).ceil(), self.width),
            clamp((v - reach).floor(), self.height),
            clamp((v + reach).ceil(), self.height),
        );
        let cols = x1 - x0 + 1;
        let rows = y1 - y0 + 1;
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        // positive and capped
        let strips = ((2.0 * radius_px * STRIPS_PER_PIXEL).ceil().min(MAX_STRIPS) as usize).max(1);
        #[allow(clippy::cast_precision_loss)]
        let strip_h = 2.0 * radius_px / strips as f64;
        // The strips' half-widths, normalised so that the disk's area is exact.
        #[allow(clippy::cast_precision_loss)]
        let half_widths: Vec<f64> = (0..strips)
            .map(|j| {
                let dy = -radius_px + (j as f64 + 0.5) * strip_h;
                (radius_px * radius_px - dy * dy).max(0.0).sqrt()
            })
            .collect();
        let area: f64 = half_widths.iter().map(|w| 2.0 * w * strip_h).sum();
        let scale = if area > 0.0 {
            std::f64::consts::PI * radius_px * radius_px / area
        } else {
            0.0
        };
        let mut patch = vec![0.0f64; cols * rows];
        let mut sx = vec![0.0f64; cols];
        let mut edge = vec![0.0f64; cols + 1];
        for (j, &hw) in half_widths.iter().enumerate() {
            #[allow(clippy::cast_precision_loss)]
            let sy = v - radius_px + (j as f64 + 0.5) * strip_h;
            let (a, b) = (u - hw, u + hw);
            // Integral over the segment [a, b] and the columns left of each pixel edge.
            for (k, e) in edge.iter_mut().enumerate() {
                #[allow(clippy::cast_precision_loss)]
                let x = (x0 + k) as f64 - 0.5;
                *e = if hw < 1e-6 {
                    2.0 * hw * phi((x - u) / sigma)
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
            let weight = radiance * strip_h * scale;
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
