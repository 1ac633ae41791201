//! The rig configuration (vehicle-interfaces.md section 3) as data; reading and writing the
//! file is in [`crate::rig_file`] (feature `std`).

use alloc::vec::Vec;

use crate::camera::{CameraParams, N_PARAMS, Param};

/// Sensor noise, 1 sigma (rig file `[noise]`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Noise {
    /// Pixel noise of each of `uL, vL, uR, vR`, pixels.
    pub pixel: f64,
    /// Odometry velocity noise per sample, each of `vx, vy`, m/s.
    pub velocity: f64,
    /// Odometry yaw-rate noise per sample, rad/s.
    pub yaw_rate: f64,
}

/// A rig file: what a user knows about the stereo head before the vehicle moves.
#[derive(Debug, Clone, PartialEq)]
pub struct Rig {
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    /// Nominal camera parameters (the truth may differ).
    pub nominal: CameraParams,
    /// Parameters to estimate, in [`Param::ALL`] order; the others stay at their nominal value.
    pub estimate: Vec<Param>,
    /// 1-sigma prior of each estimated parameter, in [`Param::ALL`] order (`None` for the
    /// others).
    pub prior: [Option<f64>; N_PARAMS],
    /// Noise model.
    pub noise: Noise,
    /// The raw cameras' lenses (`[lens.left]`, `[lens.right]`, vehicle-interfaces.md 1.1):
    /// the board's features are raw and are mapped into the rectified model; `None`: they
    /// are rectified already.
    pub lens: Option<crate::lens::StereoLens>,
}

impl Rig {
    /// The rectified pixel noise of this rig's board features: [`Noise::pixel`] carried
    /// through its lenses into the rectified image the host maps them into (the nominal
    /// camera's `f, cx, cy`), gains of 1 without lens tables.
    pub fn pixel_noise(&self) -> crate::lens::PixelNoise {
        crate::lens::PixelNoise::new(self.lens, self.nominal.f, self.nominal.cx, self.nominal.cy)
    }
}
