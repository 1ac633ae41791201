//! Slow, literal transcriptions of the ICD, used as oracles in tests (feature `alloc`).
//!
//! [`integer`] follows board-icd.md section 2 step by step on whole-image arrays, with every
//! intermediate in 64-bit integers and no cleverness, so that the fast row-streaming detector
//! can be checked against it. [`float`] computes the same detector in `f64` without the final
//! floor; its response is `r` before truncation, which is what OpenCV's
//! `cornerHarris(img, blockSize=5, ksize=3, k=41/1024) * 5100^4 / 2^17` computes in `f32`.

use alloc::{vec, vec::Vec};

use crate::{
    CANDIDATE_BORDER, Error, Feature, K_NUMERATOR, K_SHIFT, RESPONSE_SHIFT, Registers,
    q4_coordinate, subpixel_offset,
};

/// The result of the integer reference: the full response map and the detection.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct IntegerReference {
    /// `r(x, y)` row-major, zero where the ICD defines none.
    pub response: Vec<i32>,
    /// Every feature before the `MAX_FEATURES` cap, in raster order.
    pub all_features: Vec<Feature>,
    /// The first `MAX_FEATURES` features.
    pub features: Vec<Feature>,
    /// `all_features.len() > MAX_FEATURES`.
    pub overflow: bool,
}

fn check(image: &[u8], regs: &Registers) -> Result<(), Error> {
    regs.validate()?;
    if image.len() != regs.width * regs.height {
        return Err(Error::ImageSize {
            width: regs.width,
            height: regs.height,
            expected: regs.width * regs.height,
            actual: image.len(),
        });
    }
    Ok(())
}

/// Sobel gradients (ICD step 1) on the whole image as i64, zero on the one-pixel border.
fn gradients(image: &[u8], w: usize, h: usize) -> (Vec<i64>, Vec<i64>) {
    let p = |x: usize, y: usize| i64::from(image[y * w + x]);
    let mut gx = vec![0i64; w * h];
    let mut gy = vec![0i64; w * h];
    for y in 1..h - 1 {
        for x in 1..w - 1 {
            gx[y * w + x] = (p(x + 1, y - 1) + 2 * p(x + 1, y) + p(x + 1, y + 1))
                - (p(x - 1, y - 1) + 2 * p(x - 1, y) + p(x - 1, y + 1));
            gy[y * w + x] = (p(x - 1, y + 1) + 2 * p(x, y + 1) + p(x + 1, y + 1))
                - (p(x - 1, y - 1) + 2 * p(x, y - 1) + p(x + 1, y - 1));
        }
    }
    (gx, gy)
}

/// Window sums (ICD step 2) at `(x, y)`, `3 <= x <= w - 4`, `3 <= y <= h - 4`.
fn window_sums(gx: &[i64], gy: &[i64], w: usize, x: usize, y: usize) -> (i64, i64, i64) {
    let (mut sxx, mut syy, mut sxy) = (0, 0, 0);
    for yy in y - 2..=y + 2 {
        for xx in x - 2..=x + 2 {
            let (a, b) = (gx[yy * w + xx], gy[yy * w + xx]);
            sxx += a * a;
            syy += b * b;
            sxy += a * b;
        }
    }
    (sxx, syy, sxy)
}

/// The integer detector, step by step as the ICD writes it.
///
/// # Panics
/// Panics if the ICD's claim that `r` fits in 32 signed bits were ever false (it is a test
/// oracle; the fast detector relies on that claim).
pub fn integer(image: &[u8], regs: &Registers) -> Result<IntegerReference, Error> {
    check(image, regs)?;
    let (w, h) = (regs.width, regs.height);
    let (gx, gy) = gradients(image, w, h);
    let mut response = vec![0i32; w * h];
    for y in 3..=h - 4 {
        for x in 3..=w - 4 {
            let (sxx, syy, sxy) = window_sums(&gx, &gy, w, x, y);
            let t = sxx + syy;
            let det = sxx * syy - sxy * sxy;
            let rs = (det << K_SHIFT) - K_NUMERATOR.cast_signed() * t * t;
            #[allow(clippy::expect_used)]
            let r = i32::try_from(rs >> RESPONSE_SHIFT).expect("ICD: r fits in i32");
            response[y * w + x] = r;
        }
    }
    let r = |x: usize, y: usize| response[y * w + x];
    let mut all_features = Vec::new();
    for y in CANDIDATE_BORDER..=h - 1 - CANDIDATE_BORDER {
        for x in CANDIDATE_BORDER..=w - 1 - CANDIDATE_BORDER {
            let c = r(x, y);
            if c <= regs.threshold {
                continue;
            }
            let strict = [r(x - 1, y - 1), r(x, y - 1), r(x + 1, y - 1), r(x - 1, y)];
            let loose = [r(x + 1, y), r(x - 1, y + 1), r(x, y + 1), r(x + 1, y + 1)];
            if strict.iter().all(|&n| c > n) && loose.iter().all(|&n| c >= n) {
                let ox = subpixel_offset(r(x - 1, y), c, r(x + 1, y));
                let oy = subpixel_offset(r(x, y - 1), c, r(x, y + 1));
                all_features.push(Feature {
                    x_q4: q4_coordinate(x, ox),
                    y_q4: q4_coordinate(y, oy),
                    r: c,
                });
            }
        }
    }
    let overflow = all_features.len() > regs.max_features;
    let features = all_features
        .iter()
        .copied()
        .take(regs.max_features)
        .collect();
    Ok(IntegerReference {
        response,
        all_features,
        features,
        overflow,
    })
}

/// A feature of the floating-point reference: position in pixels, response before flooring.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FloatFeature {
    /// Column in pixels, with the sub-pixel offset (not quantised).
    pub u: f64,
    /// Row in pixels, with the sub-pixel offset (not quantised).
    pub v: f64,
    /// Response `Rs / 2^27` before flooring.
    pub r: f64,
}

/// The result of the floating-point reference.
#[derive(Debug, Clone, PartialEq)]
pub struct FloatReference {
    /// `(det - k T^2) / 2^17` row-major (zero where undefined): `r` before the floor.
    pub response: Vec<f64>,
    /// Features from the same threshold and suppression on the float response, with
    /// un-quantised, un-clamped parabola offsets, before the cap.
    pub features: Vec<FloatFeature>,
}

/// The same detector in `f64`: Sobel, 5x5 sums, `det - k T^2` with `k = 41/1024`, scaled by
/// `2^-17` so that it equals the integer `r` before flooring.
pub fn float(image: &[u8], regs: &Registers) -> Result<FloatReference, Error> {
    check(image, regs)?;
    let (w, h) = (regs.width, regs.height);
    let (gx, gy) = gradients(image, w, h);
    let k = K_NUMERATOR as f64 / f64::from(1u32 << K_SHIFT);
    let scale = f64::from(1u32 << (RESPONSE_SHIFT - K_SHIFT));
    let mut response = vec![0f64; w * h];
    for y in 3..=h - 4 {
        for x in 3..=w - 4 {
            let (sxx, syy, sxy) = window_sums(&gx, &gy, w, x, y);
            let (sxx, syy, sxy) = (sxx as f64, syy as f64, sxy as f64);
            let t = sxx + syy;
            response[y * w + x] = (sxx * syy - sxy * sxy - k * t * t) / scale;
        }
    }
    let r = |x: usize, y: usize| response[y * w + x];
    let offset = |a: f64, b: f64, c: f64| {
        let den = 2.0 * (a - 2.0 * b + c);
        if den == 0.0 { 0.0 } else { (a - c) / den }
    };
    let mut features = Vec::new();
    for y in CANDIDATE_BORDER..=h - 1 - CANDIDATE_BORDER {
        for x in CANDIDATE_BORDER..=w - 1 - CANDIDATE_BORDER {
            let c = r(x, y);
            if c <= f64::from(regs.threshold) {
                continue;
            }
            let strict = [r(x - 1, y - 1), r(x, y - 1), r(x + 1, y - 1), r(x - 1, y)];
            let loose = [r(x + 1, y), r(x - 1, y + 1), r(x, y + 1), r(x + 1, y + 1)];
            if strict.iter().all(|&n| c > n) && loose.iter().all(|&n| c >= n) {
                features.push(FloatFeature {
                    u: x as f64 + offset(r(x - 1, y), c, r(x + 1, y)),
                    v: y as f64 + offset(r(x, y - 1), c, r(x, y + 1)),
                    r: c,
                });
            }
        }
    }
    Ok(FloatReference { response, features })
}
