//! The stereo camera board's Harris corner detector, bit for bit.
//!
//! The board (see `board-icd.md`, section 2) runs the Harris (Stephens & Harris) combined corner
//! and edge detector on each 8-bit image in fixed-point arithmetic, one pixel per clock, holding
//! only a few line buffers. This crate mirrors that arithmetic exactly:
//!
//! * [`HarrisStream`] is the row-streaming detector: push image rows one at a time, receive each
//!   row's features as soon as they are final, in the board's order. It owns fixed-capacity line
//!   buffers sized by its `MAX_WIDTH` parameter (about 41 KiB at 752 pixels), never allocates and
//!   works without `std` or `alloc`.
//! * [`detect`] (feature `alloc`) runs a whole image and returns its features and overflow flag.
//! * [`reference`] (feature `alloc`) holds two slow, literal transcriptions of the ICD used as
//!   oracles in tests: an integer one, and a floating-point one that shows the relation to
//!   OpenCV's `cornerHarris(img, 5, 3, 41/1024)`.
//!
//! ```
//! use harris_core::{HarrisStream, Registers};
//! let regs = Registers { width: 32, height: 32, ..Registers::default() };
//! let mut stream = HarrisStream::<32>::new(regs)?;
//! let mut image = [[0u8; 32]; 32];
//! for y in 14..18 { for x in 14..18 { image[y][x] = 255; } }   // a small bright lamp
//! let mut features = Vec::new();
//! for row in &image {
//!     features.extend_from_slice(stream.push_row(row)?);
//! }
//! let summary = stream.finish()?;
//! assert_eq!(summary.features, features.len());
//! assert!(!summary.overflow);
//! # Ok::<(), harris_core::Error>(())
//! ```
#![cfg_attr(not(feature = "std"), no_std)]
#![forbid(unsafe_code)]
#![deny(missing_docs)]
#![warn(clippy::cast_possible_truncation, clippy::cast_sign_loss, clippy::cast_possible_wrap)]

#[cfg(feature = "alloc")]
extern crate alloc;

mod error;
#[cfg(feature = "alloc")]
mod image;
mod kernels;
#[cfg(feature = "alloc")]
pub mod reference;
mod stream;

pub use error::Error;
#[cfg(feature = "alloc")]
pub use image::{Detection, detect, response_map};
pub use stream::{BoardStream, HarrisStream, ImageSummary};

/// Smallest `WIDTH` and `HEIGHT` register value (ICD section 1).
pub const MIN_SIZE: usize = 16;
/// Largest `WIDTH` and `HEIGHT` register value (ICD section 1).
pub const MAX_SIZE: usize = 4095;
/// The board sensor's width (ICD section 1, `WIDTH` default).
pub const BOARD_WIDTH: usize = 752;
/// The board sensor's height (ICD section 1, `HEIGHT` default).
pub const BOARD_HEIGHT: usize = 480;
/// Default `THRESHOLD`, 2^18 (ICD section 1).
pub const DEFAULT_THRESHOLD: i32 = 1 << 18;
/// Default `MAX_FEATURES` (ICD section 1).
pub const DEFAULT_MAX_FEATURES: usize = 512;
/// Largest `MAX_FEATURES` (ICD section 1; also the wire format's count limit).
pub const MAX_FEATURES_LIMIT: usize = 1023;

/// Largest magnitude of a Sobel gradient, `4 * 255` (ICD step 1).
pub const GRADIENT_MAX: i32 = 1020;
/// Half-size of the 5x5 window of the structure tensor sums (ICD step 2).
pub const WINDOW_RADIUS: usize = 2;
/// Numerator of the Harris constant `k = 41 / 1024` (ICD step 3).
pub const K_NUMERATOR: u64 = 41;
/// `k`'s denominator is `1 << K_SHIFT` (ICD step 3: `Rs = (det << 10) - 41 T^2`).
pub const K_SHIFT: u32 = 10;
/// The reported response is `r = Rs >> RESPONSE_SHIFT` (ICD step 3).
pub const RESPONSE_SHIFT: u32 = 27;
/// No candidate lies closer than this to an image edge (ICD step 4).
pub const CANDIDATE_BORDER: usize = 4;
/// Sub-pixel offsets are in `1 / SUBPIXEL_SCALE` pixel (ICD step 6).
pub const SUBPIXEL_SCALE: i64 = 16;
/// Sub-pixel offsets are clamped to `[-SUBPIXEL_CLAMP, SUBPIXEL_CLAMP]` (ICD step 6).
pub const SUBPIXEL_CLAMP: i64 = 8;
/// Output coordinates are Q12.4: `x_q4 = (x << Q4_SHIFT) + ox` (ICD step 7).
pub const Q4_SHIFT: u32 = 4;

/// The detector's registers (ICD section 1).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Registers {
    /// `WIDTH`, image width in pixels, `16..=4095`.
    pub width: usize,
    /// `HEIGHT`, image height in pixels, `16..=4095`.
    pub height: usize,
    /// `THRESHOLD`: a pixel is a candidate when its response `r > threshold`.
    pub threshold: i32,
    /// `MAX_FEATURES`, features kept per image, `1..=1023`.
    pub max_features: usize,
}

impl Default for Registers {
    /// The board's power-on registers: 752x480, threshold 2^18, 512 features.
    fn default() -> Self {
        Self {
            width: BOARD_WIDTH,
            height: BOARD_HEIGHT,
            threshold: DEFAULT_THRESHOLD,
            max_features: DEFAULT_MAX_FEATURES,
        }
    }
}

impl Registers {
    /// Checks every register against the ICD's ranges.
    pub fn validate(&self) -> Result<(), Error> {
        if !(MIN_SIZE..=MAX_SIZE).contains(&self.width) {
            return Err(Error::WidthOutOfRange { width: self.width, min: MIN_SIZE, max: MAX_SIZE });
        }
        if !(MIN_SIZE..=MAX_SIZE).contains(&self.height) {
            return Err(Error::HeightOutOfRange {
                height: self.height,
                min: MIN_SIZE,
                max: MAX_SIZE,
            });
        }
        if !(1..=MAX_FEATURES_LIMIT).contains(&self.max_features) {
            return Err(Error::MaxFeaturesOutOfRange {
                max_features: self.max_features,
                min: 1,
                max: MAX_FEATURES_LIMIT,
            });
        }
        Ok(())
    }
}

/// One detected feature as the board sends it (ICD step 7).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Hash)]
pub struct Feature {
    /// Column in Q12.4 pixels: `16 x + ox`.
    pub x_q4: u16,
    /// Row in Q12.4 pixels: `16 y + oy`.
    pub y_q4: u16,
    /// Harris response `r` at the integer pixel.
    pub r: i32,
}

impl Feature {
    /// Column in pixels, `x_q4 / 16`.
    pub fn u(&self) -> f64 {
        f64::from(self.x_q4) / 16.0
    }
    /// Row in pixels, `y_q4 / 16`.
    pub fn v(&self) -> f64 {
        f64::from(self.y_q4) / 16.0
    }
}

/// ICD step 3: the Harris response `r = ((det << 10) - 41 T^2) >> 27` of one pixel's window sums.
///
/// `sxx`, `syy` are sums of squares (`0..=26_010_000`) and `|sxy| <= 14_630_625`, so every
/// product below is an unsigned 32x32->64 bit multiply (cheap on every CPU and in SIMD).
#[inline(always)]
#[allow(clippy::cast_sign_loss, clippy::cast_possible_truncation, clippy::cast_possible_wrap)]
pub fn response(sxx: i32, syy: i32, sxy: i32) -> i32 {
    // Sums of squares are never negative, so `as u32` keeps their value.
    let (sxx, syy) = (u64::from(sxx as u32), u64::from(syy as u32));
    let trace = sxx + syy; // < 2^26
    let sxy = u64::from(sxy.unsigned_abs());
    // Cauchy-Schwarz holds exactly for integer sums: Sxy^2 <= Sxx Syy, so det >= 0.
    let det = sxx * syy - sxy * sxy;
    // Two's complement of the signed Rs (|Rs| < 2^59, so no bits are lost mod 2^64).
    let rs = (det << K_SHIFT).wrapping_sub(K_NUMERATOR * trace * trace);
    // Bits 27..=58 of Rs are the same for an arithmetic and a logical shift, and the ICD
    // guarantees r fits in 32 signed bits, so the truncation to u32 then i32 is exact.
    (rs >> RESPONSE_SHIFT) as u32 as i32
}

/// ICD step 6: sub-pixel offset along one axis in 1/16 pixel, from the responses before,
/// at and after the feature. Division truncates toward zero; the result is clamped to `[-8, 8]`.
#[inline]
#[allow(clippy::cast_possible_truncation)]
pub fn subpixel_offset(before: i32, at: i32, after: i32) -> i32 {
    let (before, at, after) = (i64::from(before), i64::from(at), i64::from(after));
    let num = before - after;
    let den = 2 * (before - 2 * at + after);
    if den == 0 {
        return 0;
    }
    // Rust's `/` on integers truncates toward zero, as the ICD requires; the clamp makes the
    // narrowing exact.
    ((SUBPIXEL_SCALE * num) / den).clamp(-SUBPIXEL_CLAMP, SUBPIXEL_CLAMP) as i32
}

/// ICD step 7: the Q12.4 coordinate of integer pixel `p` with sub-pixel offset `offset`.
///
/// `p <= 4090` and `|offset| <= 8` for every feature, so the result fits in 16 bits.
#[inline]
#[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss, clippy::cast_possible_wrap)]
pub fn q4_coordinate(p: usize, offset: i32) -> u16 {
    (((p as i32) << Q4_SHIFT) + offset) as u16
}
