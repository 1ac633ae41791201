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

    /// The odometry noise that a white model of samples `period_s` apart needs so that the
    /// variance of their sum over spans longer than the time constants is that of the
    /// Gauss-Markov errors the rig file states (vehicle-interfaces.md section 2): the
    /// stationary sigma times `sqrt((1 + phi) / (1 - phi))`, `phi = exp(-period / tau)`, on
    /// each axis with memory (an AR(1) sequence's sum of `K` samples has variance
    /// `K sigma^2 (1 + phi) / (1 - phi)` for large `K`); time constants 0. With 0.6 s of memory
    /// and 100 Hz odometry the sigma grows 11-fold. Over spans shorter than the time constant
    /// this white equivalent is pessimistic (the held error integrates as `sigma dt` while
    /// the equivalent gives `sigma sqrt(2 tau dt)`), never optimistic: the estimators weigh
    /// correlated odometry as they would weigh white odometry of that spread. A
    /// `period_s` of 0 or below (unknown) leaves the noise as it is.
    #[must_use]
    pub fn white_equivalent(&self, period_s: f64) -> Self {
        Self {
            velocity: self.velocity * memory_gain(self.velocity_tau, period_s),
            yaw_rate: self.yaw_rate * memory_gain(self.yaw_rate_tau, period_s),
            velocity_tau: 0.0,
            yaw_rate_tau: 0.0,
            ..*self
        }
    }
}

/// `sqrt((1 + phi) / (1 - phi))`, `phi = exp(-period / tau)`: the factor on the sigma of a
/// white model equivalent to first-order Gauss-Markov errors of time constant `tau` over long
/// spans ([`Noise::white_equivalent`]); 1 without memory or without a period.
fn memory_gain(tau: f64, period_s: f64) -> f64 {
    if !(tau > 0.0 && period_s > 0.0 && tau.is_finite() && period_s.is_finite()) {
        return 1.0;
    }
    let phi = libm::exp(-period_s / tau);
    // (1 + phi) / (1 - phi) = coth(period / (2 tau)); for period << tau, 2 tau / period.
    // expm1 keeps 1 - phi exact when the period is a tiny fraction of tau.
    let one_minus_phi = -libm::expm1(-period_s / tau);
    libm::sqrt((1.0 + phi) / one_minus_phi)
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn errors_with_memory_weigh_as_their_long_run_white_equivalent() {
        let white = Noise::white(0.3, 0.02, 0.01);
        assert_eq!(white.white_equivalent(0.01), white);
        let slipping = Noise {
            velocity_tau: 0.6,
            yaw_rate_tau: 0.3,
            ..white
        };
        let e = slipping.white_equivalent(0.01);
        // (1 + phi) / (1 - phi) with phi = exp(-0.01 / tau): 120.0 and 60.0 in variance.
        let phi = |tau: f64| (-0.01 / tau).exp();
        let gain = |tau: f64| ((1.0 + phi(tau)) / (1.0 - phi(tau))).sqrt();
        assert!((e.velocity / (0.02 * gain(0.6)) - 1.0).abs() < 1e-12);
        assert!((e.yaw_rate / (0.01 * gain(0.3)) - 1.0).abs() < 1e-12);
        assert!((e.velocity / 0.02 - 120.0f64.sqrt()).abs() < 0.01);
        assert_eq!((e.velocity_tau, e.yaw_rate_tau, e.pixel), (0.0, 0.0, 0.3));
        // The sum of K samples of an AR(1) sequence: its variance over K against K sigma^2,
        // exactly, tends to the gain squared.
        let (p, k) = (phi(0.6), 20_000.0_f64);
        let exact = k * (1.0 + p) / (1.0 - p) - 2.0 * p * (1.0 - p.powf(k)) / (1.0 - p).powi(2);
        assert!((exact / k / gain(0.6).powi(2) - 1.0).abs() < 0.01);
        // An unknown period leaves the noise as it is.
        assert_eq!(slipping.white_equivalent(0.0).velocity, 0.02);
    }
}
