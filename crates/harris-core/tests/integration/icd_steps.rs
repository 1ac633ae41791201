//! Hand-worked cases for each step of board-icd.md section 2, with the arithmetic written out.
//! Every expected number here was computed by hand (see the comments), not by the code under
//! test; the detector, `response_map` and the reference must all agree with it.
#![cfg(feature = "alloc")] // the whole-image calls and the references need `alloc`

use crate::common;

use common::{assert_matches_reference, boxed_stream, regs, run_stream};
use harris_core::{
    DEFAULT_THRESHOLD, Feature, Registers, detect, q4_coordinate, response, response_map,
    subpixel_offset,
};

/// `2^27`, the divisor of step 3.
const TWO_27: i64 = 1 << 27;

/// A `width x height` image of zeros with `255` on the rectangle `x0..x0+bw`, `y0..y0+bh`.
fn blocks(width: usize, height: usize, rects: &[(usize, usize, usize, usize)]) -> Vec<u8> {
    let mut img = vec![0u8; width * height];
    for &(x0, y0, bw, bh) in rects {
        for y in y0..y0 + bh {
            img[y * width + x0..y * width + x0 + bw].fill(255);
        }
    }
    img
}

fn map_of(img: &[u8], width: usize, height: usize) -> Vec<i32> {
    response_map(img, &regs(width, height, 0, 1)).unwrap_or_else(|e| panic!("{e}"))
}

fn features_of(img: &[u8], r: &Registers) -> Vec<Feature> {
    let d = detect(img, r).unwrap_or_else(|e| panic!("{e}"));
    assert!(!d.overflow);
    d.features
}

// ---------------------------------------------------------------------------------------------
// Steps 1 and 2: gradients and window sums, seen through the response.
// ---------------------------------------------------------------------------------------------

/// A vertical step edge, 16x16: `p = 0` for `x < 8`, `255` for `x >= 8`.
///
/// Step 1: every column is constant, so `gy = 0` everywhere. `gx(x) = 4 (p(x+1) - p(x-1))`:
/// `x = 7`: `4 * (255 - 0) = 1020`; `x = 8`: `4 * (255 - 0) = 1020`; every other column has
/// equal neighbours, `gx = 0`. So `gx = 1020` on columns 7 and 8 of rows 1..=14.
///
/// Step 2: the 5x5 window at `(x, y)` (any `3 <= y <= 12`) holds `n` columns out of {7, 8}:
/// `n = 0` for `x <= 4` and `x >= 11`, `n = 1` for `x = 5, 10`, `n = 2` for `x = 6..=9`.
/// `Sxx = 5 n 1020^2 = n * 5,202,000`, `Syy = Sxy = 0`.
///
/// Step 3: `T = Sxx`, `det = 0`, `Rs = -41 Sxx^2`.
/// * `n = 1`: `Rs = -41 * 5,202,000^2 = -41 * 27,060,804,000,000 = -1,109,492,964,000,000`;
///   `/ 2^27 = -8,266,366.75...`, floor `r = -8,266,367`.
/// * `n = 2`: `Sxx = 10,404,000`, `Rs = -41 * 108,243,216,000,000 = -4,437,971,856,000,000`;
///   `/ 2^27 = -33,065,467.0000076...`, floor `r = -33,065,468` (truncation would say
///   `-33,065,467`).
#[test]
fn vertical_step_edge() {
    const N1: i32 = -8_266_367;
    const N2: i32 = -33_065_468;
    let (w, h) = (16, 16);
    let mut img = vec![0u8; w * h];
    for row in img.chunks_exact_mut(w) {
        row[8..].fill(255);
    }
    assert_eq!(
        (-1_109_492_964_000_000i64).div_euclid(TWO_27),
        i64::from(N1)
    );
    assert_eq!(
        (-4_437_971_856_000_000i64).div_euclid(TWO_27),
        i64::from(N2)
    );
    assert_eq!(response(5_202_000, 0, 0), N1);
    assert_eq!(response(10_404_000, 0, 0), N2);
    let expected_row = [0, 0, 0, 0, 0, N1, N2, N2, N2, N2, N1, 0, 0, 0, 0, 0];
    let map = map_of(&img, w, h);
    for y in 0..h {
        let expected = if (3..=12).contains(&y) {
            expected_row
        } else {
            [0; 16]
        };
        assert_eq!(&map[y * w..(y + 1) * w], &expected, "row {y}");
    }
    assert_matches_reference(&img, &regs(w, h, i32::MIN, 1023), "vertical step");
    // An edge is no corner: nothing above the default threshold.
    assert!(features_of(&img, &regs(w, h, DEFAULT_THRESHOLD, 512)).is_empty());
}

/// The same edge turned horizontal: now `gx = 0` and `gy = 1020` on rows 7 and 8, and the
/// transposed map has the same numbers (`Syy` plays `Sxx`'s part in `T` and `det`).
#[test]
fn horizontal_step_edge() {
    let (w, h) = (16, 16);
    let mut img = vec![0u8; w * h];
    img[8 * w..].fill(255);
    let map = map_of(&img, w, h);
    let column = [
        0,
        0,
        0,
        0,
        0,
        -8_266_367,
        -33_065_468,
        -33_065_468,
        -33_065_468,
        -33_065_468,
        -8_266_367,
        0,
        0,
        0,
        0,
        0,
    ];
    for y in 0..h {
        for x in 0..w {
            let expected = if (3..=12).contains(&x) { column[y] } else { 0 };
            assert_eq!(map[y * w + x], expected, "(x {x}, y {y})");
        }
    }
    assert_eq!(response(0, 5_202_000, 0), -8_266_367);
}

/// One pixel of value `v = 255` at `(8, 8)` on zeros, 17x17.
///
/// Step 1, on the 3x3 neighbourhood (rows 7..=9, columns 7..=9; zero elsewhere):
/// ```text
/// gx = [ v  0 -v ]     gy = [  v  2v  v ]
///      [2v  0 -2v]          [  0   0  0 ]
///      [ v  0 -v ]          [ -v -2v -v ]
/// ```
/// Step 2 at `(8, 8)` (and at every `(x, y)` with `|x - 8|, |y - 8| <= 1`, whose window
/// still covers the whole 3x3): `Sxx = v^2 (1 + 4 + 1 + 1 + 4 + 1) = 12 * 65,025 = 780,300`,
/// `Syy = 780,300` likewise, `Sxy = v^2 (1 - 1 - 1 + 1) = 0` (corners only).
/// Step 3: `T = 1,560,600`, `det = 780,300^2 = 608,868,090,000`,
/// `Rs = 1024 * 608,868,090,000 - 41 * 1,560,600^2
///     = 623,480,924,160,000 - 99,854,366,760,000 = 523,626,557,400,000`,
/// `r = floor(523,626,557,400,000 / 134,217,728) = floor(3,901,321.87) = 3,901,321`.
///
/// At `(10, 10)` the window (columns and rows 8..=12) holds only the bottom-right 2x2 of the
/// neighbourhood: `gx = {0, -2v; 0, -v}`, `gy = {0, 0; -2v, -v}` for (8,8), (9,8); (8,9), (9,9):
/// `Sxx = 4v^2 + v^2 = 325,125`, `Syy = 325,125`, `Sxy = (-v)(-v) = 65,025`;
/// `T = 650,250`, `det = 325,125^2 - 65,025^2 = 260,100 * 390,150 = 101,478,015,000`,
/// `Rs = 103,913,487,360,000 - 41 * 422,825,062,500 = 103,913,487,360,000 - 17,335,827,562,500
///     = 86,577,659,797,500`, `r = floor(645,053.83) = 645,053`. At `(6, 10)` `Sxy` flips sign
/// (`gx` is odd in x), which `det` does not see: the same `645,053`.
#[test]
fn single_bright_pixel_window_sums() {
    let (w, h) = (17, 17);
    let mut img = vec![0u8; w * h];
    img[8 * w + 8] = 255;
    assert_eq!(response(780_300, 780_300, 0), 3_901_321);
    assert_eq!(response(325_125, 325_125, 65_025), 645_053);
    assert_eq!(response(325_125, 325_125, -65_025), 645_053);
    assert_eq!(523_626_557_400_000i64 >> 27, 3_901_321);
    assert_eq!(86_577_659_797_500i64 >> 27, 645_053);
    let map = map_of(&img, w, h);
    for y in 7..=9 {
        for x in 7..=9 {
            assert_eq!(map[y * w + x], 3_901_321, "(x {x}, y {y})");
        }
    }
    for (x, y) in [(10, 10), (6, 10), (6, 6), (10, 6)] {
        assert_eq!(map[y * w + x], 645_053, "(x {x}, y {y})");
    }
    // Beyond 2 + 1 pixels from the bright pixel no gradient reaches the window.
    for y in 3..=13usize {
        for x in 3..=13usize {
            if x.abs_diff(8) > 3 || y.abs_diff(8) > 3 {
                assert_eq!(map[y * w + x], 0, "(x {x}, y {y})");
            }
        }
    }
    assert_matches_reference(&img, &regs(w, h, 0, 1023), "single pixel");
}

/// A 3x3 block of 255 centred at `(8, 8)` on zeros.
///
/// Step 1, on the 5x5 around the centre (rows top to bottom, columns left to right):
/// the column left of the block and the block's left column see the block on their right
/// only, with weights 1, 1+2, 1+2+1, 2+1, 1 down the rows: `gx = 255, 765, 1020, 765, 255`;
/// the centre column sees the block on both sides: `gx = 0`; the two right columns the
/// negatives. So `Sxx = 4 columns * 255^2 (1 + 9 + 16 + 9 + 1) = 4 * 65,025 * 36 = 9,363,600`,
/// `Syy = 9,363,600` (the transpose), and `Sxy = 0` (`gx` is odd about the centre column,
/// `gy` even).
/// Step 3: `T = 18,727,200`, `det = 9,363,600^2 = 87,677,004,960,000`,
/// `Rs = det (1024 - 41 * 4) = 860 det = 75,402,224,265,600,000`,
/// `r = floor(561,790,349.08) = 561,790,349`.
#[test]
fn three_by_three_block() {
    let (w, h) = (17, 17);
    let img = blocks(w, h, &[(7, 7, 3, 3)]);
    assert_eq!(860 * 87_677_004_960_000i64, 75_402_224_265_600_000);
    assert_eq!(75_402_224_265_600_000i64 >> 27, 561_790_349);
    assert_eq!(response(9_363_600, 9_363_600, 0), 561_790_349);
    let map = map_of(&img, w, h);
    assert_eq!(map[8 * w + 8], 561_790_349);
    // By the block's symmetry, one feature exactly at its centre: r(7,8) = r(9,8) makes
    // `num = 0`, so no sub-pixel offset.
    assert_eq!(map[8 * w + 7], map[8 * w + 9]);
    let f = features_of(&img, &regs(w, h, DEFAULT_THRESHOLD, 512));
    assert_eq!(
        f,
        [Feature {
            x_q4: 128,
            y_q4: 128,
            r: 561_790_349
        }]
    );
}

// ---------------------------------------------------------------------------------------------
// Step 3: the response's rounding.
// ---------------------------------------------------------------------------------------------

/// `r = Rs >> 27` floors (arithmetic shift), also for negative `Rs`.
#[test]
fn response_floors_negative_values() {
    // (0, 0, 0): T = 0, det = 0, Rs = 0, r = 0.
    assert_eq!(response(0, 0, 0), 0);
    // Sxx = 49, Syy = 980, Sxy = 75: T = 1029, det = 48,020 - 5,625 = 42,395,
    // Rs = 1024 * 42,395 - 41 * 1029^2 = 43,412,480 - 43,412,481 = -1, r = floor(-1 / 2^27) = -1
    // (truncation toward zero would give 0).
    assert_eq!(response(49, 980, 75), -1);
    assert_eq!(response(49, 980, -75), -1);
    // Sxx = 1024, Syy = 23,552, Sxy = 256: T = 24,576, det = 24,117,248 - 65,536 = 24,051,712,
    // Rs = 24,628,953,088 - 41 * 603,979,776 = 24,628,953,088 - 24,763,170,816 = -134,217,728
    // = -2^27 exactly: r = -1.
    assert_eq!(response(1024, 23_552, 256), -1);
    // Sxx = 19, Syy = 2034, Sxy = 31: T = 2053, det = 38,646 - 961 = 37,685,
    // Rs = 38,589,440 - 41 * 4,214,809 = 38,589,440 - 172,807,169 = -134,217,729 = -2^27 - 1:
    // r = -2 (truncation: -1).
    assert_eq!(response(19, 2034, 31), -2);
    // Sxx = 451, Syy = 568, Sxy = 289: T = 1019, det = 256,168 - 83,521 = 172,647,
    // Rs = 176,790,528 - 41 * 1,038,361 = 176,790,528 - 42,572,801 = 134,217,727 = 2^27 - 1: r = 0.
    assert_eq!(response(451, 568, 289), 0);
    // Sxx = 1536, Syy = 23,040, Sxy = 3328: T = 24,576, det = 35,389,440 - 11,075,584
    // = 24,313,856, Rs = 24,897,388,544 - 24,763,170,816 = 134,217,728 = 2^27: r = 1.
    assert_eq!(response(1536, 23_040, 3328), 1);
    // Pure edge at the gradient's limit: 25 * 1020^2 = 26,010,000 = Sxx, Syy = Sxy = 0:
    // Rs = -41 * 26,010,000^2 = -41 * 676,520,100,000,000 = -27,737,324,100,000,000,
    // r = floor(-206,659,168.4) = -206,659,169.
    assert_eq!(response(26_010_000, 0, 0), -206_659_169);
    // Sxx = Syy = S, Sxy = S (a rank-one tensor, gx = gy): det = 0, Rs = -41 (2S)^2.
    // S = 1000: Rs = -41 * 4,000,000 = -164,000,000, r = floor(-1.22) = -2.
    assert_eq!(response(1000, 1000, 1000), -2);
    assert_eq!(response(1000, 1000, -1000), -2);
}

// ---------------------------------------------------------------------------------------------
// Step 5: suppression ties, broken in raster order.
// ---------------------------------------------------------------------------------------------

/// The single bright pixel's 3x3 plateau (see `single_bright_pixel_window_sums`): nine equal
/// responses, tied horizontally, vertically and diagonally. Only the first in raster order,
/// `(7, 7)`, is a feature: `>=` its right and lower neighbours, `>` the rest (all smaller).
/// Sub-pixel: `r(6,7) = 1,604,884`, `r(7,7) = r(8,7) = 3,901,321`: `num = 1,604,884 - 3,901,321
/// = -2,296,437`, `den = 2 (1,604,884 - 7,802,642 + 3,901,321) = -4,592,874`, `16 num / den = 8`.
/// Same for y. So `x_q4 = y_q4 = 16 * 7 + 8 = 120`.
#[test]
fn ties_on_a_plateau_go_to_the_first_in_raster_order() {
    let (w, h) = (17, 17);
    let mut img = vec![0u8; w * h];
    img[8 * w + 8] = 255;
    let map = map_of(&img, w, h);
    assert_eq!(map[7 * w + 6], 1_604_884);
    assert_eq!(subpixel_offset(1_604_884, 3_901_321, 3_901_321), 8);
    let f = features_of(&img, &regs(w, h, 0, 1023));
    assert_eq!(
        f,
        [Feature {
            x_q4: 120,
            y_q4: 120,
            r: 3_901_321
        }]
    );
}

/// A 4x3 block (columns 7..=10, rows 7..=9), mirror-symmetric about `x = 8.5`: so
/// `r(8, y) = r(9, y)`, a horizontal tie at the maximum. The left one, `(8, 8)`, wins (`>=`
/// its right neighbour); the right one loses (`>` its left neighbour fails). Sub-pixel: with
/// `r(9) = r(8)`, `num = r(7) - r(8)`, `den = 2 (r(7) - r(8))`, so `16 num / den = 8`: the
/// feature sits at `x = 8.5`, the block's centre; in y the block is symmetric about row 8:
/// offset 0.
#[test]
fn horizontal_tie() {
    let (w, h) = (18, 18);
    let img = blocks(w, h, &[(7, 7, 4, 3)]);
    let map = map_of(&img, w, h);
    let r = |x: usize, y: usize| map[y * w + x];
    assert_eq!(r(8, 8), r(9, 8));
    assert!(r(8, 8) > r(8, 7) && r(8, 8) > r(8, 9) && r(8, 8) > r(7, 8));
    let f = features_of(&img, &regs(w, h, DEFAULT_THRESHOLD, 512));
    assert_eq!(
        f,
        [Feature {
            x_q4: 16 * 8 + 8,
            y_q4: 16 * 8,
            r: r(8, 8)
        }]
    );
}

/// The same turned: a 3x4 block, `r(8, 8) = r(8, 9)`, a vertical tie: the upper one wins
/// (`>=` the pixel below), at `y = 8.5`.
#[test]
fn vertical_tie() {
    let (w, h) = (18, 18);
    let img = blocks(w, h, &[(7, 7, 3, 4)]);
    let map = map_of(&img, w, h);
    let r = |x: usize, y: usize| map[y * w + x];
    assert_eq!(r(8, 8), r(8, 9));
    assert!(r(8, 8) > r(7, 8) && r(8, 8) > r(9, 8) && r(8, 8) > r(8, 7));
    let f = features_of(&img, &regs(w, h, DEFAULT_THRESHOLD, 512));
    assert_eq!(
        f,
        [Feature {
            x_q4: 16 * 8,
            y_q4: 16 * 8 + 8,
            r: r(8, 8)
        }]
    );
}

/// Two overlapping 3x3 blocks centred at `(8, 8)` and `(9, 9)`: symmetric under the half
/// turn about `(8.5, 8.5)`, so `r(8, 8) = r(9, 9)`, a diagonal tie (and `r(9, 8) = r(8, 9)`
/// by the reflection in the diagonal, both lower). The upper-left `(8, 8)` wins (`>=` its
/// lower-right neighbour), `(9, 9)` loses (`>` its upper-left one fails).
///
/// Then its mirror image (blocks at `(9, 8)` and `(8, 9)`): the anti-diagonal tie
/// `r(9, 8) = r(8, 9)`; `(9, 8)` comes first in raster order and wins (`>=` its lower-left
/// neighbour), `(8, 9)` loses (`>` its upper-right one fails).
#[test]
fn diagonal_ties() {
    let (w, h) = (18, 18);
    let img = blocks(w, h, &[(7, 7, 3, 3), (8, 8, 3, 3)]);
    let map = map_of(&img, w, h);
    let r = |x: usize, y: usize| map[y * w + x];
    assert_eq!(r(8, 8), r(9, 9));
    assert_eq!(r(9, 8), r(8, 9));
    assert!(r(8, 8) > r(9, 8));
    let f = features_of(&img, &regs(w, h, DEFAULT_THRESHOLD, 512));
    assert_eq!(f.len(), 1, "{f:?}");
    assert_eq!(
        (
            f[0].r,
            (usize::from(f[0].x_q4) + 8) / 16,
            (usize::from(f[0].y_q4) + 8) / 16
        ),
        (r(8, 8), 8, 8)
    );

    let img = blocks(w, h, &[(8, 7, 3, 3), (7, 8, 3, 3)]);
    let map = map_of(&img, w, h);
    let r = |x: usize, y: usize| map[y * w + x];
    assert_eq!(r(9, 8), r(8, 9));
    assert!(r(9, 8) > r(8, 8) && r(9, 8) > r(9, 9));
    let f = features_of(&img, &regs(w, h, DEFAULT_THRESHOLD, 512));
    assert_eq!(f.len(), 1, "{f:?}");
    assert_eq!(
        (
            f[0].r,
            (usize::from(f[0].x_q4) + 8) / 16,
            (usize::from(f[0].y_q4) + 8) / 16
        ),
        (r(9, 8), 9, 8)
    );
}

// ---------------------------------------------------------------------------------------------
// Step 6: sub-pixel offsets.
// ---------------------------------------------------------------------------------------------

/// Truncation toward zero, the clamp, and `den = 0`.
#[test]
fn subpixel_offset_truncates_toward_zero_and_clamps() {
    // before 95, at 100, after 90: num = 95 - 90 = 5, den = 2 (95 - 200 + 90) = -30,
    // 16 * 5 / -30 = -80 / 30 = -2.67: truncated -2 (floor would be -3).
    assert_eq!(subpixel_offset(95, 100, 90), -2);
    // Mirrored: num = -5, den = -30, 80 / 30 = 2.67: 2.
    assert_eq!(subpixel_offset(90, 100, 95), 2);
    // before -7, at 0, after -8 (negative responses): num = 1, den = 2 (-7 - 0 - 8) = -30,
    // 16 / -30 = -0.53: 0 (floor: -1).
    assert_eq!(subpixel_offset(-7, 0, -8), 0);
    // Exactly -8 and 8: num = 100 - 0 = 100, den = 2 (100 - 200 + 0) = -200: 1600 / -200 = -8.
    assert_eq!(subpixel_offset(100, 100, 0), -8);
    assert_eq!(subpixel_offset(0, 100, 100), 8);
    // Beyond: before 300, at 100, after 0: num = 300, den = 2 (300 - 200) = 200,
    // 4800 / 200 = 24, clamped to 8; mirrored -24 -> -8.
    assert_eq!(subpixel_offset(300, 100, 0), 8);
    assert_eq!(subpixel_offset(0, 100, 300), -8);
    // Non-integer beyond the clamp: num = 7, den = 2 (7 - 6 + 0) = 2: 112 / 2 = 56 -> 8.
    assert_eq!(subpixel_offset(7, 3, 0), 8);
    // den = 0: flat (10, 10, 10) and linear (0, 5, 10): offset 0.
    assert_eq!(subpixel_offset(10, 10, 10), 0);
    assert_eq!(subpixel_offset(0, 5, 10), 0);
    // The whole i32 range, in 64-bit: num = 2^31 - 1 - (-2^31) = 2^32 - 1,
    // den = 2 (2^31 - 1 + 2^32 + (-2^31)) = 2 (2^32 - 1): 16 num / den = 8.
    assert_eq!(subpixel_offset(i32::MAX, i32::MIN, i32::MIN), 8);
    assert_eq!(subpixel_offset(i32::MIN, i32::MIN, i32::MAX), -8);
    assert_eq!(subpixel_offset(i32::MIN, i32::MAX, i32::MIN), 0);
    // Step 7: 16 x + offset.
    assert_eq!(q4_coordinate(4, -8), 56);
    assert_eq!(q4_coordinate(4090, 8), 65_448);
    assert_eq!(q4_coordinate(100, -2), 1598);
}

/// A negative, non-integer offset in a real image: the anti-diagonal blocks of `diagonal_ties`,
/// feature `(9, 8)`. Its row reads `r(8, 8) = 551,626,750`, `r(9, 8) = 561,963,615`,
/// `r(10, 8) = 311,718,641` (the map is the mirror image of the diagonal one, checked in the
/// test): `num = 551,626,750 - 311,718,641 = 239,908,109`,
/// `den = 2 (551,626,750 - 1,123,927,230 + 311,718,641) = 2 * -260,581,839 = -521,163,678`,
/// `16 num / den = 3,838,529,744 / -521,163,678 = -7.365...`: truncated `-7` (floor: `-8`).
/// So `x_q4 = 16 * 9 - 7 = 137`. For a local maximum `|16 num / den| <= 8` always (with
/// `a = r(x) - r(x-1) > 0`, `b = r(x) - r(x+1) >= 0` it is `8 (a - b) / (a + b)`), so the
/// clamp never bites on a real feature; only the function-level cases above reach it.
#[test]
fn negative_subpixel_offset_in_an_image() {
    let (w, h) = (18, 18);
    let diag = map_of(&blocks(w, h, &[(7, 7, 3, 3), (8, 8, 3, 3)]), w, h);
    let anti = map_of(&blocks(w, h, &[(8, 7, 3, 3), (7, 8, 3, 3)]), w, h);
    for y in 0..h {
        for x in 0..w {
            // Mirror x -> 17 - x (zero columns 0..=2 and 15..=17 map onto each other).
            assert_eq!(anti[y * w + x], diag[y * w + (w - 1 - x)], "(x {x}, y {y})");
        }
    }
    assert_eq!(
        [anti[8 * w + 8], anti[8 * w + 9], anti[8 * w + 10]],
        [551_626_750, 561_963_615, 311_718_641]
    );
    assert_eq!(subpixel_offset(551_626_750, 561_963_615, 311_718_641), -7);
    assert_eq!(3_838_529_744i64 / -521_163_678, -7);
    let f = features_of(
        &blocks(w, h, &[(8, 7, 3, 3), (7, 8, 3, 3)]),
        &regs(w, h, DEFAULT_THRESHOLD, 512),
    );
    assert_eq!(f.len(), 1);
    assert_eq!(f[0].x_q4, 137);
}

// ---------------------------------------------------------------------------------------------
// Step 4: the 4-pixel candidate border.
// ---------------------------------------------------------------------------------------------

/// A 3x3 block centred at column (or row) 3 peaks there, where the response is defined but no
/// candidate may lie: nothing is reported (its neighbour at 4 is lower, so no maximum). Centred
/// at 4 it is reported, with the hand-computed `r = 561,790,349` of `three_by_three_block`
/// (the block's gradients, columns 2..=6, all lie inside the image). Same at the far edges:
/// column `W - 5` reported, `W - 4` not.
#[test]
fn candidate_border_is_four_pixels() {
    let (w, h) = (24, 22);
    let r = regs(w, h, DEFAULT_THRESHOLD, 512);
    let at = |cx: usize, cy: usize| blocks(w, h, &[(cx - 1, cy - 1, 3, 3)]);
    let feature = |cx: usize, cy: usize| Feature {
        x_q4: q4_coordinate(cx, 0),
        y_q4: q4_coordinate(cy, 0),
        r: 561_790_349,
    };
    for (cx, cy, reported) in [
        (3, 10, false),
        (4, 10, true),
        (w - 5, 10, true),
        (w - 4, 10, false),
        (10, 3, false),
        (10, 4, true),
        (10, h - 5, true),
        (10, h - 4, false),
        (4, 4, true),
        (w - 5, h - 5, true),
        (3, 4, false),
        (w - 4, h - 5, false),
    ] {
        let img = at(cx, cy);
        let map = map_of(&img, w, h);
        assert_eq!(
            map[cy * w + cx],
            561_790_349,
            "({cx}, {cy}): the response is defined there"
        );
        let expected = if reported {
            vec![feature(cx, cy)]
        } else {
            vec![]
        };
        assert_eq!(
            features_of(&img, &r),
            expected,
            "block centred at ({cx}, {cy})"
        );
        assert_matches_reference(&img, &r, &format!("block at ({cx}, {cy})"));
    }
}

// ---------------------------------------------------------------------------------------------
// Step 7: the MAX_FEATURES cap and the overflow flag.
// ---------------------------------------------------------------------------------------------

/// 16 separate 3x3 blocks centred at `(8 + 10 i, 8 + 10 j)` in a 48x48 image: each is one
/// feature at its centre with `r = 561,790,349` (10 pixels apart, their 9x9 zones of influence
/// do not overlap), in raster order `j` then `i`.
#[test]
fn max_features_cap_and_overflow_flag() {
    let (w, h) = (48, 48);
    let centres: Vec<(usize, usize)> = (0..4)
        .flat_map(|j| (0..4).map(move |i| (8 + 10 * i, 8 + 10 * j)))
        .collect();
    let rects: Vec<_> = centres.iter().map(|&(x, y)| (x - 1, y - 1, 3, 3)).collect();
    let img = blocks(w, h, &rects);
    let all: Vec<Feature> = centres
        .iter()
        .map(|&(x, y)| Feature {
            x_q4: q4_coordinate(x, 0),
            y_q4: q4_coordinate(y, 0),
            r: 561_790_349,
        })
        .collect();
    for max_features in [1023, 17, 16, 15, 5, 4, 1] {
        let r = regs(w, h, DEFAULT_THRESHOLD, max_features);
        let d = detect(&img, &r).unwrap_or_else(|e| panic!("{e}"));
        let kept = max_features.min(16);
        assert_eq!(d.features, all[..kept], "max_features {max_features}");
        assert_eq!(d.overflow, max_features < 16, "max_features {max_features}");
        // Row by row: the same features and flag.
        let mut stream = boxed_stream::<48>(&r);
        let (f, overflow) = run_stream(&mut *stream, &img, &r);
        assert_eq!((f, overflow), (d.features.clone(), d.overflow));
        assert_matches_reference(&img, &r, &format!("cap {max_features}"));
    }
}

/// The overflow flag as the rows go by: with `MAX_FEATURES = 4` the fifth feature (the first
/// of the second row of blocks, row 18) is found when pixel row 18 + 4 = 22 is pushed; the
/// flag goes up then, and no further feature is returned.
#[test]
fn overflow_flag_rises_with_the_first_feature_too_many() {
    let (w, h) = (48, 48);
    let rects: Vec<_> = (0..4)
        .flat_map(|j| (0..4).map(move |i| (7 + 10 * i, 7 + 10 * j, 3, 3)))
        .collect();
    let img = blocks(w, h, &rects);
    let r = regs(w, h, DEFAULT_THRESHOLD, 4);
    let mut stream = boxed_stream::<64>(&r);
    let mut sent = 0;
    for (y, row) in img.chunks_exact(w).enumerate() {
        sent += stream.push_row(row).unwrap_or_else(|e| panic!("{e}")).len();
        assert_eq!(stream.overflow(), y >= 22, "after pixel row {y}");
        assert_eq!(sent, if y >= 12 { 4 } else { 0 }, "after pixel row {y}");
    }
    let summary = stream.finish().unwrap_or_else(|e| panic!("{e}"));
    assert_eq!((summary.features, summary.overflow), (4, true));
    // The next image starts clean.
    let r2 = regs(w, h, i32::MAX, 4);
    stream.set_registers(r2).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(run_stream(&mut *stream, &img, &r2), (vec![], false));
}
