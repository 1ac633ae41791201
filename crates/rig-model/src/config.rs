//! The rig configuration (vehicle-interfaces.md section 3) as data; reading and writing the
//! file is in [`crate::rig_file`] (feature `std`).

use alloc::string::String;
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
    /// Time constant of the velocity errors, s (`[noise] velocity_tau`, v3): the errors of
    /// `vx, vy` are a first-order Gauss-Markov process of this time constant whose stationary
    /// sigma is [`Noise::velocity`]; `0`: white from one sample to the next.
    pub velocity_tau: f64,
    /// Time constant of the yaw-rate errors, s (`[noise] yaw_rate_tau`), as
    /// [`Noise::velocity_tau`] for [`Noise::yaw_rate`].
    pub yaw_rate_tau: f64,
}

impl Noise {
    /// Noise whose odometry errors are white (no memory: both time constants 0), as every
    /// rig file before v3 states it.
    pub const fn white(pixel: f64, velocity: f64, yaw_rate: f64) -> Self {
        Self {
            pixel,
            velocity,
            yaw_rate,
            velocity_tau: 0.0,
            yaw_rate_tau: 0.0,
        }
    }

    /// Whether the odometry's errors are stated to have memory (a time constant above 0).
    pub fn odometry_has_memory(&self) -> bool {
        self.velocity_tau > 0.0 || self.yaw_rate_tau > 0.0
    }

    /// The warning for a rig file that states time constants the estimators do not model
    /// yet: its odometry errors are taken as white (`None` when it states none).
    pub fn memory_not_modelled_warning(&self) -> Option<String> {
        self.odometry_has_memory().then(|| {
            alloc::format!(
                "the rig file gives the odometry's errors memory (velocity_tau {} s, yaw_rate_tau {} s), which this version does not model yet: they are taken as white, and the sigmas may be too small",
                self.velocity_tau, self.yaw_rate_tau
            )
        })
    }
}

/// The board's detector registers that a rig file may set (`[board]`, vehicle-interfaces.md
/// 4.1): used when the host runs the board's Harris arithmetic on camera images itself; the
/// image size is the `[camera]` table's.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Board {
    /// `THRESHOLD` (board-icd.md section 1): a pixel is a candidate when its response is above.
    pub threshold: i32,
    /// `MAX_FEATURES`: features kept per image, `1..=1023`.
    pub max_features: usize,
}

impl Board {
    /// The board's power-on registers (board-icd.md section 1), used when the rig file has no
    /// `[board]` table.
    pub const DEFAULT: Self = Self {
        threshold: harris_core::DEFAULT_THRESHOLD,
        max_features: harris_core::DEFAULT_MAX_FEATURES,
    };

    /// Whether these are the board's defaults (a rig file need not say them).
    pub fn is_default(&self) -> bool {
        *self == Self::DEFAULT
    }
}

impl Default for Board {
    fn default() -> Self {
        Self::DEFAULT
    }
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
    /// The detector's registers for images the host detects on (`[board]`; the defaults
    /// without the table).
    pub board: Board,
}

impl Rig {
    /// The rectified pixel noise of this rig's board features: [`Noise::pixel`] carried
    /// through its lenses into the rectified image the host maps them into (the nominal
    /// camera's `f, cx, cy`), gains of 1 without lens tables.
    pub fn pixel_noise(&self) -> crate::lens::PixelNoise {
        crate::lens::PixelNoise::new(self.lens, self.nominal.f, self.nominal.cx, self.nominal.cy)
    }

    /// The board's registers for this rig's images: `[camera]`'s size and `[board]`'s
    /// threshold and feature limit.
    pub fn board_registers(&self) -> harris_core::Registers {
        harris_core::Registers {
            // u32 -> usize cannot drop bits on the 32- and 64-bit targets the stack builds
            // for, and the rig file's sizes are at most 4095.
            width: self.width as usize,
            height: self.height as usize,
            threshold: self.board.threshold,
            max_features: self.board.max_features,
        }
    }
}
