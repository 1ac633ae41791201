//! What the association assumes about the sensors: the camera parameters it triangulates and
//! projects with, how uncertain they are, and the noise of pixels and odometry.

use nalgebra::{SMatrix, Vector4};
use rig_model::Measurement;
use rig_model::camera::{CameraParams, N_PARAMS, Param};
use rig_model::config::{Noise, Rig};
use rig_model::lens::PixelNoise;

/// Covariance of the ten camera parameters, in [`Param::ALL`] order.
pub type CameraCovariance = SMatrix<f64, N_PARAMS, N_PARAMS>;

/// Variance of rounding a coordinate to the board's Q12.4 grid, px^2: `(1/16)^2 / 12`.
pub const Q4_ROUNDING_VARIANCE_PX2: f64 = 1.0 / (16.0 * 16.0 * 12.0);

/// The sensor model of the association.
#[derive(Debug, Clone, PartialEq)]
pub struct Model {
    /// The camera parameters used to triangulate and project (nominal before phase 1, the
    /// calibrated ones after).
    pub camera: CameraParams,
    /// Their covariance: the tracker widens its gates by it. Zero for parameters known exactly.
    pub camera_covariance: CameraCovariance,
    /// Pixel and odometry noise (rig file `[noise]`).
    pub noise: Noise,
    /// How the rig's lenses stretch the pixel noise in the rectified image
    /// ([`Rig::pixel_noise`]; gains of 1 without lens tables).
    pub pixel_noise: PixelNoise,
}

impl Model {
    /// The model before calibration: the rig's nominal parameters, with the rig file's prior
    /// sigma on each estimated parameter (a parameter without a prior counts as exact).
    pub fn from_rig(rig: &Rig) -> Self {
        let mut camera_covariance = CameraCovariance::zeros();
        for p in &rig.estimate {
            let i = p.index();
            if let (Some(Some(sigma)), Some(slot)) =
                (rig.prior.get(i), camera_covariance.get_mut((i, i)))
                && sigma.is_finite()
            {
                *slot = sigma * sigma;
            }
        }
        Self {
            camera: rig.nominal,
            camera_covariance,
            noise: rig.noise,
            pixel_noise: rig.pixel_noise(),
        }
    }

    /// The same noise model with new camera parameters and covariance (after calibration).
    pub fn with_camera(&self, camera: CameraParams, camera_covariance: CameraCovariance) -> Self {
        Self {
            camera,
            camera_covariance,
            noise: self.noise,
            pixel_noise: self.pixel_noise,
        }
    }

    /// Variance of one pixel coordinate as the board sends it, px^2: the pixel noise plus the
    /// Q12.4 rounding. Never NaN: a NaN or negative pixel noise counts as zero.
    pub fn pixel_variance_px2(&self) -> f64 {
        let sigma = self.noise.pixel;
        let noise = if sigma.is_finite() {
            sigma * sigma
        } else {
            0.0
        };
        noise + Q4_ROUNDING_VARIANCE_PX2
    }

    /// The variances of a measurement's `uL, vL, uR, vR` in the rectified image, px^2:
    /// [`Model::pixel_variance_px2`] times the lens's gain at `z`.
    pub fn measurement_variances_px2(&self, z: &Measurement) -> Vector4<f64> {
        self.pixel_noise.gains(z) * self.pixel_variance_px2()
    }

    /// The prior sigma of one parameter in this model (0 when held exact).
    pub fn camera_sigma(&self, p: Param) -> f64 {
        let i = p.index();
        self.camera_covariance
            .get((i, i))
            .map_or(0.0, |v| libm::sqrt(v.max(0.0)))
    }
}

#[cfg(test)]
#[allow(clippy::indexing_slicing)]
pub(crate) mod tests {
    use super::*;
    use alloc::vec;
    use rig_model::camera::Mount;

    pub(crate) fn rig() -> Rig {
        let mut prior = [None; N_PARAMS];
        prior[Param::F.index()] = Some(30.0);
        prior[Param::Baseline.index()] = Some(0.006);
        Rig {
            lens: None,
            board: rig_model::Board::DEFAULT,
            width: 752,
            height: 480,
            nominal: CameraParams {
                vehicle: Default::default(),
                f: 700.0,
                cx: 376.0,
                cy: 240.0,
                baseline: 0.12,
                mount: Mount {
                    z: 0.8,
                    pitch: 0.3,
                    ..Mount::default()
                },
            },
            estimate: vec![Param::F, Param::Baseline],
            prior,
            noise: Noise::white(0.3, 0.02, 0.01),
        }
    }

    #[test]
    fn the_rig_priors_become_the_camera_covariance() {
        let m = Model::from_rig(&rig());
        assert!((m.camera_sigma(Param::F) - 30.0).abs() < 1e-12);
        assert!((m.camera_sigma(Param::Baseline) - 0.006).abs() < 1e-15);
        assert_eq!(m.camera_sigma(Param::Cx), 0.0);
        assert!((m.pixel_variance_px2() - (0.09 + 1.0 / 3072.0)).abs() < 1e-15);
        let mut bad = rig();
        bad.noise.pixel = f64::NAN;
        bad.prior[Param::F.index()] = Some(f64::INFINITY);
        let m = Model::from_rig(&bad);
        assert!(m.pixel_variance_px2().is_finite());
        assert_eq!(m.camera_sigma(Param::F), 0.0);
    }
}
