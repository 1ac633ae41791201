//! The stereo camera board's Harris corner detector, bit for bit.
//!
//! The board (see `board-icd.md`, section 2) runs the Harris (Stephens & Harris) combined corner
//! and edge detector on each 8-bit image in fixed-point arithmetic, one pixel per clock, holding
//! only a few line buffers. This crate mirrors that arithmetic exactly:
//!
//! * [`HarrisStream`] is the row-streaming detector: push image rows one at a time, receive each
//!   row's features as soon as they are final, in the board's order. It owns fixed-capacity line
//!   buffers sized by its `MAX_WIDTH` parameter (about 50 KiB at 752 pixels), never allocates and
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
#![warn(
    clippy::cast_possible_truncation,
    clippy::cast_sign_loss,
    clippy::cast_possible_wrap
)]

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
            return Err(Error::WidthOutOfRange {
                width: self.width,
                min: MIN_SIZE,
                max: MAX_SIZE,
            });
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
///
/// The result is exact for every window an 8-bit image can produce: one pixel's
/// `gx^2 + gy^2` is at most 1,300,500 (`gx` and `gy` cannot both reach 1020), so
/// `T <= 32,512,500` and `r <= 215 T^2 / 2^27 < 2^31`. The ICD's separate bounds on
/// `Sxx` and `Syy` would allow sums (both at 26,010,000 with `Sxy = 0`) whose response does
/// not fit in 32 bits; no image has them, and for them this function wraps.
#[inline(always)]
#[allow(
    clippy::cast_sign_loss,
    clippy::cast_possible_truncation,
    clippy::cast_possible_wrap
)]
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
#[allow(
    clippy::cast_possible_truncation,
    clippy::cast_sign_loss,
    clippy::cast_possible_wrap
)]
pub fn q4_coordinate(p: usize, offset: i32) -> u16 {
    (((p as i32) << Q4_SHIFT) + offset) as u16
}

#[cfg(test)]
mod tests {
    //! The per-pixel arithmetic of ICD steps 3, 6 and 7 against 128-bit transcriptions, over
    //! its whole domain. (Hand-worked cases and whole images are in `tests/`.)

    use super::*;

    /// xorshift64*, deterministic.
    struct Rng(u64);

    impl Rng {
        fn next(&mut self) -> u64 {
            self.0 ^= self.0 >> 12;
            self.0 ^= self.0 << 25;
            self.0 ^= self.0 >> 27;
            self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
        }
        fn below(&mut self, n: u64) -> u64 {
            self.next() % n
        }
    }

    /// ICD step 3 in 128 bits: `floor(((det << 10) - 41 T^2) / 2^27)`.
    fn exact_response(sxx: i32, syy: i32, sxy: i32) -> i128 {
        let (sxx, syy, sxy) = (i128::from(sxx), i128::from(syy), i128::from(sxy));
        let t = sxx + syy;
        let rs = ((sxx * syy - sxy * sxy) << 10) - 41 * t * t;
        rs.div_euclid(1 << 27)
    }

    /// Window sums within the ICD's ranges and Cauchy-Schwarz (`Sxy^2 <= Sxx Syy`), as every
    /// image gives, biased toward small values and the edges of the ranges.
    fn window_sums(rng: &mut Rng) -> (i32, i32, i32) {
        let max = match rng.below(4) {
            0 => 100,
            1 => 100_000,
            _ => 26_010_000,
        };
        let sxx = rng.below(max + 1);
        let syy = if rng.below(4) == 0 {
            sxx
        } else {
            rng.below(max + 1)
        };
        let limit = (sxx * syy).isqrt().min(14_630_625);
        let sxy = match rng.below(4) {
            0 => limit,
            1 => 0,
            _ => rng.below(limit + 1),
        };
        let sign = if rng.below(2) == 0 { 1 } else { -1 };
        let as_i32 = |v: u64| i32::try_from(v).unwrap_or(i32::MAX);
        (as_i32(sxx), as_i32(syy), sign * as_i32(sxy))
    }

    #[test]
    fn response_equals_the_exact_floor() {
        let mut rng = Rng(0x5EED_1234_ABCD_0001);
        let mut checked = 0;
        for _ in 0..200_000 {
            let (sxx, syy, sxy) = window_sums(&mut rng);
            let exact = exact_response(sxx, syy, sxy);
            // The ICD's ranges allow triples no image reaches, whose r would not fit in 32 bits
            // (e.g. Sxx = Syy = 26,010,000 with Sxy = 0); every image's r does (the largest
            // found by search is about 8.9e8), so only those are compared.
            let Ok(exact) = i32::try_from(exact) else {
                continue;
            };
            assert_eq!(response(sxx, syy, sxy), exact, "({sxx}, {syy}, {sxy})");
            assert_eq!(
                response(syy, sxx, -sxy),
                exact,
                "symmetry ({sxx}, {syy}, {sxy})"
            );
            checked += 1;
        }
        assert!(checked > 150_000, "{checked}");
    }

    /// ICD step 6 in 128 bits with an explicit truncation toward zero and clamp.
    fn exact_offset(before: i32, at: i32, after: i32) -> i128 {
        let (b, a, c) = (i128::from(before), i128::from(at), i128::from(after));
        let num = 16 * (b - c);
        let den = 2 * (b - 2 * a + c);
        if den == 0 {
            return 0;
        }
        let q = num.abs() / den.abs();
        let q = if (num < 0) != (den < 0) { -q } else { q };
        q.clamp(-8, 8)
    }

    #[test]
    fn subpixel_offset_equals_the_exact_truncation() {
        let mut rng = Rng(0x5EED_1234_ABCD_0002);
        let pick = |rng: &mut Rng| -> i32 {
            const EDGES: [i32; 7] = [i32::MIN, i32::MIN + 1, -1, 0, 1, i32::MAX - 1, i32::MAX];
            match rng.below(5) {
                0 => usize::try_from(rng.below(7))
                    .ok()
                    .and_then(|i| EDGES.get(i))
                    .map_or(0, |&v| v),
                1 => i32::try_from(rng.below(2001)).unwrap_or(0) - 1000,
                _ => {
                    let b = rng.next().to_le_bytes();
                    i32::from_le_bytes([b[0], b[1], b[2], b[3]])
                }
            }
        };
        for _ in 0..200_000 {
            let (b, a, c) = (pick(&mut rng), pick(&mut rng), pick(&mut rng));
            let got = subpixel_offset(b, a, c);
            assert_eq!(i128::from(got), exact_offset(b, a, c), "({b}, {a}, {c})");
            assert_eq!(subpixel_offset(c, a, b), -got, "mirror ({b}, {a}, {c})");
        }
        // For a local maximum (`at > before`, `at >= after`) the offset never needs the clamp.
        for _ in 0..100_000 {
            let at = i32::try_from(rng.below(1 << 30)).unwrap_or(0);
            let before = at - 1 - i32::try_from(rng.below(1 << 30)).unwrap_or(0);
            let after = at - i32::try_from(rng.below(1 << 30)).unwrap_or(0);
            let num = 16 * (i128::from(before) - i128::from(after));
            let den = 2 * (i128::from(before) - 2 * i128::from(at) + i128::from(after));
            assert!(
                (num / den).abs() <= 8 && (-8..=8).contains(&subpixel_offset(before, at, after))
            );
        }
    }

    #[test]
    fn q4_coordinates_cover_every_feature_position() {
        for p in CANDIDATE_BORDER..=MAX_SIZE - 1 - CANDIDATE_BORDER {
            for offset in -8..=8 {
                let expected = 16 * i64::try_from(p).unwrap_or(0) + i64::from(offset);
                assert_eq!(
                    i64::from(q4_coordinate(p, offset)),
                    expected,
                    "({p}, {offset})"
                );
            }
        }
        let f = Feature {
            x_q4: 16 * 100 + 8,
            y_q4: 16 * 4 - 8,
            r: 1,
        };
        assert_eq!((f.u(), f.v()), (100.5, 3.5));
    }

    #[test]
    fn register_ranges() {
        let ok = Registers::default();
        assert_eq!(ok.validate(), Ok(()));
        for width in [0, 15, 4096] {
            assert_eq!(
                Registers { width, ..ok }.validate(),
                Err(Error::WidthOutOfRange {
                    width,
                    min: 16,
                    max: 4095
                })
            );
        }
        for height in [0, 15, 4096] {
            assert_eq!(
                Registers { height, ..ok }.validate(),
                Err(Error::HeightOutOfRange {
                    height,
                    min: 16,
                    max: 4095
                })
            );
        }
        for max_features in [0, 1024] {
            assert_eq!(
                Registers { max_features, ..ok }.validate(),
                Err(Error::MaxFeaturesOutOfRange {
                    max_features,
                    min: 1,
                    max: 1023
                })
            );
        }
        for (width, height, max_features) in [(16, 16, 1), (4095, 4095, 1023)] {
            for threshold in [i32::MIN, 0, i32::MAX] {
                assert_eq!(
                    Registers {
                        width,
                        height,
                        threshold,
                        max_features
                    }
                    .validate(),
                    Ok(())
                );
            }
        }
    }
}
