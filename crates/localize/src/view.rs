//! What the cameras see from a pose: the map's lamps predicted into both images, their
//! association with a frame's observations, and the frame's score under the pose.

use alloc::vec::Vec;

use nalgebra::{Matrix4, Vector3, Vector4};
use rig_model::camera::CameraParams;
use rig_model::lens::PixelNoise;
use vslam_ekf::chi2::chi2_quantile;

use crate::filter::{PoseFilter, Prediction};
use crate::map::LampMap;
use crate::settings::LocalizerSettings;

/// One stereo measurement of a frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Observation {
    /// `(uL, vL, uR, vR)` in the rectified model, pixels.
    pub z: Vector4<f64>,
    /// The front end's track.
    pub track: u64,
    /// Frames the track has been seen in.
    pub hits: u32,
    /// Whether the tracker has confirmed the track.
    pub confirmed: bool,
}

/// A ray from the rig into the ceiling, in the robot frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ray {
    /// Where it starts (the rig's centre), metres.
    pub origin: Vector3<f64>,
    /// Its direction (`z > 0`), not normalised.
    pub direction: Vector3<f64>,
}

impl Ray {
    /// Where it meets the height `z`; `None` below its origin.
    pub fn at_height(&self, z: f64) -> Option<Vector3<f64>> {
        let s = (z - self.origin.z) / self.direction.z;
        (s > 0.0).then(|| self.origin + self.direction * s)
    }
}

/// A frame scored under one pose.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Scored {
    /// Log-likelihood ratio of the frame under the pose against clutter.
    pub llr: f64,
    /// `(lamp, observation index)` associated.
    pub matched: Vec<(u32, usize)>,
    /// The NIS of each association (before the updates), in `matched`'s order.
    pub nis: Vec<f64>,
    /// Lamps expected in view (well inside both images).
    pub expected: usize,
    /// The lamps expected, by index.
    pub expected_lamps: Vec<u32>,
    /// Mean NIS of the associations (0 without).
    pub mean_nis: f64,
}

/// The camera model and the constants of association and scoring.
#[derive(Debug, Clone)]
pub struct View {
    camera: CameraParams,
    width: f64,
    height: f64,
    margin_px: f64,
    r: Matrix4<f64>,
    pixel_variance: f64,
    pixel_noise: PixelNoise,
    reach_m: f64,
    min_depth_m: f64,
    max_depth_m: f64,
    gate: f64,
    ln_pd: f64,
    ln_miss: f64,
    ln_clutter_density: f64,
}

impl View {
    /// The view of the camera `camera` on a `width x height` image with pixel variance
    /// `pixel_variance` (px^2, of a raw feature) stretched by the lenses as `pixel_noise`
    /// says, over the map `map`.
    pub fn new(
        camera: CameraParams,
        width: u32,
        height: u32,
        pixel_variance: f64,
        pixel_noise: PixelNoise,
        map: &LampMap,
        settings: &LocalizerSettings,
    ) -> Self {
        let (w, h) = (f64::from(width), f64::from(height));
        // The widest ray in view: the image's corner off the optical axis, tilted by the
        // mount; where it meets the highest lamp is as far as a lamp can be seen.
        let corner = libm::atan(libm::hypot(w / 2.0, h / 2.0) / camera.f);
        let tilt = libm::fabs(camera.mount.pitch) + libm::fabs(camera.mount.roll);
        let angle = (corner + tilt).min(1.45);
        let above = (map.max_height() - camera.mount.z).max(0.5);
        let reach_m = libm::hypot(camera.mount.x, camera.mount.y) + above * libm::tan(angle) + 0.5;
        let fb = camera.f * camera.baseline;
        let st = settings.front_end.stereo;
        let d_range = (fb / st.min_depth_m - fb / st.max_depth_m).max(1.0);
        let row_band = 2.0 * st.row_gate_sigmas * libm::sqrt(2.0 * pixel_variance);
        let volume = w * h * d_range * row_band.max(1.0);
        let pd = settings.detection_probability;
        Self {
            camera,
            width: w,
            height: h,
            margin_px: settings.image_margin_px,
            r: Matrix4::identity() * pixel_variance,
            pixel_variance,
            pixel_noise,
            reach_m: reach_m.min(settings.max_reach_m),
            min_depth_m: st.min_depth_m,
            max_depth_m: st.max_depth_m,
            gate: chi2_quantile(settings.match_probability, 4.0),
            ln_pd: libm::log(pd),
            ln_miss: libm::log(1.0 - pd),
            ln_clutter_density: libm::log(settings.clutter_per_frame / volume),
        }
    }

    /// The camera parameters.
    pub fn camera(&self) -> &CameraParams {
        &self.camera
    }

    /// The pixel noise's covariance at the measurement `z` (diagonal: the lens's gains,
    /// [`PixelNoise::gains`], times the raw feature's variance).
    pub fn r_at(&self, z: &Vector4<f64>) -> Matrix4<f64> {
        if self.pixel_noise.is_uniform() {
            self.r
        } else {
            Matrix4::from_diagonal(&(self.pixel_noise.gains(z) * self.pixel_variance))
        }
    }

    /// Farthest a lamp in view can be from the robot, horizontally, metres.
    pub fn reach_m(&self) -> f64 {
        self.reach_m
    }

    /// The ray of observation `o`: from the rig's centre through the mean of its two pixels,
    /// in the robot frame; `None` when it does not rise.
    pub fn ray(&self, o: &Observation) -> Option<Ray> {
        let c = &self.camera;
        let u = 0.5 * (o.z[0] + o.z[2]);
        let v = 0.5 * (o.z[1] + o.z[3]);
        let d_rig = Vector3::new((u - c.cx) / c.f, (v - c.cy) / c.f, 1.0);
        let d = c.mount.robot_from_rig_rotation() * d_rig;
        (d.z > 1e-6 && d.iter().all(|v| v.is_finite())).then(|| Ray {
            origin: c.mount.translation(),
            direction: d,
        })
    }

    /// Where the ray of observation `o` meets the height `z` (world, which is the robot
    /// frame's), in the robot frame; `None` when the ray does not rise to it.
    pub fn on_height(&self, o: &Observation, z: f64) -> Option<Vector3<f64>> {
        self.ray(o)?.at_height(z)
    }

    /// Whether a predicted measurement lies well inside both images at a plausible depth.
    fn in_view(&self, z: &Vector4<f64>) -> bool {
        let m = self.margin_px;
        let inside = |u: f64, v: f64| {
            u >= m && u <= self.width - 1.0 - m && v >= m && v <= self.height - 1.0 - m
        };
        let disparity = z[0] - z[2];
        let fb = self.camera.f * self.camera.baseline;
        inside(z[0], z[1])
            && inside(z[2], z[3])
            && disparity > 0.0
            && fb / disparity >= self.min_depth_m
            && fb / disparity <= self.max_depth_m
    }

    /// The map's lamps in view from the filter's pose, predicted, into `out`.
    pub fn predict(
        &self,
        map: &LampMap,
        filter: &PoseFilter,
        near: &mut Vec<u32>,
        out: &mut Vec<Prediction>,
    ) {
        out.clear();
        let pose = filter.pose();
        map.within(pose.x, pose.y, self.reach_m, near);
        for &i in near.iter() {
            let Some(lamp) = map.lamp(i) else { continue };
            let zero = Matrix4::zeros();
            if let Some(mut p) =
                filter.predict_lamp(&self.camera, i, &lamp.position, &lamp.covariance, &zero)
                && self.in_view(&p.z)
            {
                p.s += self.r_at(&p.z);
                out.push(p);
            }
        }
    }

    /// Associates the frame's observations with the lamps in view from the filter's pose
    /// (one to one, nearest first by Mahalanobis distance inside the gate), scores the frame
    /// and updates the filter with every association.
    pub fn score_and_update(
        &self,
        map: &LampMap,
        filter: &mut PoseFilter,
        observations: &[Observation],
        t_us: u64,
    ) -> Scored {
        let mut near = Vec::new();
        let mut predictions = Vec::new();
        self.predict(map, filter, &mut near, &mut predictions);
        let mut scored = self.associate(&predictions, observations);
        for (k, &(lamp, o)) in scored.matched.iter().enumerate() {
            let (Some(l), Some(obs)) = (map.lamp(lamp), observations.get(o)) else {
                continue;
            };
            if filter
                .update(&self.camera, lamp, l, &self.r_at(&obs.z), &obs.z, t_us)
                .is_none()
                && let Some(n) = scored.nis.get_mut(k)
            {
                *n = f64::NAN;
            }
        }
        scored
    }

    /// The association and the score of a frame against predictions (no update).
    pub fn associate(&self, predictions: &[Prediction], observations: &[Observation]) -> Scored {
        let mut pairs: Vec<(f64, usize, usize, f64)> = Vec::new();
        for (pi, p) in predictions.iter().enumerate() {
            let Some(s_inv) = p.s.try_inverse() else {
                continue;
            };
            let det = p.s.determinant();
            if det.is_nan() || det <= 0.0 {
                continue;
            }
            let ln_norm = 0.5 * (4.0 * libm::log(2.0 * core::f64::consts::PI) + libm::log(det));
            for (oi, o) in observations.iter().enumerate() {
                let nu = o.z - p.z;
                let d2 = (nu.transpose() * s_inv * nu)[(0, 0)];
                if d2 <= self.gate {
                    pairs.push((d2, pi, oi, ln_norm));
                }
            }
        }
        pairs.sort_by(|a, b| a.0.total_cmp(&b.0));
        let mut used_p = alloc::vec![false; predictions.len()];
        let mut used_o = alloc::vec![false; observations.len()];
        let mut scored = Scored {
            expected: predictions.len(),
            expected_lamps: predictions.iter().map(|p| p.lamp).collect(),
            ..Scored::default()
        };
        for (d2, pi, oi, ln_norm) in pairs {
            let (Some(up), Some(uo)) = (used_p.get(pi).copied(), used_o.get(oi).copied()) else {
                continue;
            };
            if up || uo {
                continue;
            }
            if let Some(u) = used_p.get_mut(pi) {
                *u = true;
            }
            if let Some(u) = used_o.get_mut(oi) {
                *u = true;
            }
            let Some(p) = predictions.get(pi) else {
                continue;
            };
            scored.llr += self.ln_pd - 0.5 * d2 - ln_norm - self.ln_clutter_density;
            scored.matched.push((p.lamp, oi));
            scored.nis.push(d2);
        }
        #[allow(clippy::cast_precision_loss)]
        let missed = (predictions.len() - scored.matched.len()) as f64;
        scored.llr += missed * self.ln_miss;
        if !scored.nis.is_empty() {
            #[allow(clippy::cast_precision_loss)]
            let n = scored.nis.len() as f64;
            scored.mean_nis = scored.nis.iter().sum::<f64>() / n;
        }
        scored
    }
}
