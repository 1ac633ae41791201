//! Extreme images: nothing overflows (the tests run with overflow checks on), every response
//! fits the ICD's widths, and the detector equals the integer reference at thresholds and caps
//! from one end of their ranges to the other.
#![cfg(feature = "alloc")] // the whole-image calls and the references need `alloc`

use crate::common;

use common::{Kind, assert_matches_reference, boxed_stream, generate, regs, run_stream};
use harris_core::{DEFAULT_THRESHOLD, MAX_FEATURES_LIMIT, MAX_SIZE, MIN_SIZE, response_map};

const THRESHOLDS: [i32; 8] = [
    i32::MIN,
    -1_000_000,
    -1,
    0,
    1,
    DEFAULT_THRESHOLD,
    1 << 28,
    i32::MAX,
];
const CAPS: [usize; 3] = [1, 512, MAX_FEATURES_LIMIT];

/// Compares with the reference at every threshold and cap above, streaming too, and returns the
/// response map.
fn check_everywhere(img: &[u8], width: usize, height: usize, what: &str) -> Vec<i32> {
    for threshold in THRESHOLDS {
        for max_features in CAPS {
            let r = regs(width, height, threshold, max_features);
            let what = format!("{what} {width}x{height} threshold {threshold} cap {max_features}");
            let expected = assert_matches_reference(img, &r, &what);
            if width <= 64 {
                let got = run_stream(&mut *boxed_stream::<64>(&r), img, &r);
                assert_eq!(
                    got,
                    (expected.features, expected.overflow),
                    "{what}, streamed"
                );
            }
        }
    }
    response_map(img, &regs(width, height, 0, 1)).unwrap_or_else(|e| panic!("{e}"))
}

fn image_from(width: usize, height: usize, f: impl Fn(usize, usize) -> u8) -> Vec<u8> {
    (0..height)
        .flat_map(|y| (0..width).map(move |x| (x, y)))
        .map(|(x, y)| f(x, y))
        .collect()
}

#[test]
fn flat_images_have_zero_response_and_no_features() {
    for (width, height) in [(16, 16), (17, 23), (64, 16)] {
        for level in [0u8, 1, 128, 255] {
            let img = vec![level; width * height];
            let map = check_everywhere(&img, width, height, &format!("flat {level}"));
            assert!(map.iter().all(|&r| r == 0), "flat {level}");
            // Even at threshold i32::MIN no pixel beats its (equal) upper neighbour strictly.
            let d = harris_core::detect(&img, &regs(width, height, i32::MIN, 1023))
                .unwrap_or_else(|e| panic!("{e}"));
            assert!(d.features.is_empty() && !d.overflow);
        }
    }
}

#[test]
fn checkerboards_of_period_one_two_three() {
    for period in 1..=3 {
        for phase in 0..period {
            for (width, height) in [(16, 16), (31, 29), (40, 17)] {
                let img = image_from(width, height, |x, y| {
                    if ((x + phase) / period + y / period) % 2 == 0 {
                        0
                    } else {
                        255
                    }
                });
                check_everywhere(
                    &img,
                    width,
                    height,
                    &format!("checker {period} phase {phase}"),
                );
            }
        }
    }
}

/// Vertical stripes `0, 0, 255, 255, ...` (period 4) give `|gx| = 1020` at every pixel
/// (`gx = 4 (p(x+1) - p(x-1))` and the stripes make `p(x+1) - p(x-1) = +-255` everywhere) and
/// `gy = 0`: `Sxx = 25 * 1020^2 = 26,010,000`, the ICD's bound, a pure edge:
/// `r = floor(-41 * 26,010,000^2 / 2^27) = -206,659,169` at every inner pixel.
#[test]
fn stripes_reach_the_gradient_bound() {
    let (width, height) = (32, 20);
    let img = image_from(width, height, |x, _| if (x / 2) % 2 == 0 { 0 } else { 255 });
    let map = check_everywhere(&img, width, height, "stripes");
    for y in 3..=height - 4 {
        for x in 3..=width - 4 {
            assert_eq!(map[y * width + x], -206_659_169, "(x {x}, y {y})");
        }
    }
    let transposed = image_from(height, width, |_, y| if (y / 2) % 2 == 0 { 0 } else { 255 });
    let map = check_everywhere(&transposed, height, width, "horizontal stripes");
    assert_eq!(map[10 * height + 10], -206_659_169);
}

/// A dark pixel on 255 negates every gradient of a bright pixel on 0, and the response is
/// even in the gradients: the maps are equal.
#[test]
fn single_bright_and_single_dark_pixel() {
    for (width, height, x, y) in [
        (16, 16, 8, 8),
        (16, 16, 4, 4),
        (16, 16, 11, 11),
        (33, 17, 16, 8),
        (17, 17, 0, 0),
    ] {
        let mut bright = vec![0u8; width * height];
        bright[y * width + x] = 255;
        let mut dark = vec![255u8; width * height];
        dark[y * width + x] = 0;
        let a = check_everywhere(&bright, width, height, &format!("bright pixel ({x}, {y})"));
        let b = check_everywhere(&dark, width, height, &format!("dark pixel ({x}, {y})"));
        assert_eq!(a, b, "({x}, {y})");
    }
}

#[test]
fn bright_square_on_black() {
    for (width, height, x0, y0, side) in [
        (16, 16, 4, 4, 8),
        (40, 40, 10, 10, 20),
        (40, 40, 0, 0, 20),
        (24, 24, 5, 7, 1),
    ] {
        let img = image_from(width, height, |x, y| {
            if (x0..x0 + side).contains(&x) && (y0..y0 + side).contains(&y) {
                255
            } else {
                0
            }
        });
        check_everywhere(
            &img,
            width,
            height,
            &format!("square {side} at ({x0}, {y0})"),
        );
    }
}

#[test]
fn random_noise_and_binary_noise() {
    for seed in 0..6 {
        for (width, height) in [(16, 16), (48, 37)] {
            let img = generate(Kind::Noise, width, height, seed);
            check_everywhere(&img, width, height, &format!("noise seed {seed}"));
            let binary: Vec<u8> = img.iter().map(|&p| if p < 128 { 0 } else { 255 }).collect();
            check_everywhere(&binary, width, height, &format!("binary noise seed {seed}"));
        }
    }
}

/// Images of exactly the smallest size: the response is defined on columns and rows 3..=12,
/// candidates on 4..=11.
#[test]
fn smallest_images() {
    for kind in common::KINDS {
        for seed in 0..8 {
            let img = generate(kind, MIN_SIZE, MIN_SIZE, seed);
            check_everywhere(&img, MIN_SIZE, MIN_SIZE, &format!("{kind:?} seed {seed}"));
        }
    }
}

/// The widest and the tallest images the board accepts.
#[test]
fn widest_and_tallest_images() {
    for (width, height) in [(MAX_SIZE, MIN_SIZE), (MIN_SIZE, MAX_SIZE)] {
        for (what, img) in [
            ("noise", generate(Kind::Noise, width, height, 7)),
            ("blobs", generate(Kind::Blobs, width, height, 8)),
            (
                "checker 1",
                image_from(width, height, |x, y| if (x + y) % 2 == 0 { 0 } else { 255 }),
            ),
            ("white", vec![255; width * height]),
        ] {
            for (threshold, max_features) in [
                (i32::MIN, 1023),
                (-1, 7),
                (0, 1023),
                (DEFAULT_THRESHOLD, 512),
                (i32::MAX, 1),
            ] {
                let r = regs(width, height, threshold, max_features);
                let what = format!("{what} {width}x{height} threshold {threshold}");
                let expected = assert_matches_reference(&img, &r, &what);
                let got = run_stream(&mut *boxed_stream::<MAX_SIZE>(&r), &img, &r);
                assert_eq!(
                    got,
                    (expected.features, expected.overflow),
                    "{what}, streamed"
                );
            }
        }
    }
}

/// Widths at the edges of the line-buffer capacities: the board's 752, the chunk bitsets'
/// 64-chunk words (`3 + 16 * 64 = 1027`), and the ICD's 4095; each a pixel below and above.
#[test]
fn widths_at_capacity_edges() {
    for width in [
        751, 752, 753, 1026, 1027, 1028, 1030, 1031, 1535, 1536, 1537, 2051, 4094, 4095,
    ] {
        let height = 16 + width % 5;
        for (kind, seed) in [(Kind::Blobs, width as u64), (Kind::Noise, 1)] {
            let img = generate(kind, width, height, seed);
            for (threshold, max_features) in [
                (i32::MIN, 1023),
                (0, 1023),
                (DEFAULT_THRESHOLD, 512),
                (1 << 24, 3),
            ] {
                let r = regs(width, height, threshold, max_features);
                let what = format!("{kind:?} {width}x{height} threshold {threshold}");
                let expected = assert_matches_reference(&img, &r, &what);
                let got = run_stream(&mut *boxed_stream::<MAX_SIZE>(&r), &img, &r);
                assert_eq!(
                    got,
                    (expected.features, expected.overflow),
                    "{what}, streamed"
                );
            }
        }
    }
}

/// Lamps straddling the chunk edges of a wide image (chunk `j` covers columns
/// `3 + 16 j ..= 18 + 16 j`), including the edges between the 64-chunk words, at a threshold
/// that leaves everything but the lamps undecided.
#[test]
fn lamps_on_chunk_edges_of_a_wide_image() {
    let (width, height) = (2200, 24);
    for shift in [-2i64, -1, 0, 1, 2] {
        let mut img = vec![3u8; width * height];
        let mut y = 6;
        for j in [1usize, 2, 5, 63, 64, 65, 127, 128, 129] {
            let edge = 3 + 16 * j as i64; // first column of chunk j
            let cx = usize::try_from(edge + shift).unwrap_or(0);
            for yy in y - 1..=y + 1 {
                img[yy * width + cx - 1..=yy * width + cx + 1].fill(200);
            }
            y = if y == 6 { 14 } else { 6 };
        }
        for threshold in [0, DEFAULT_THRESHOLD, 1 << 26] {
            let r = regs(width, height, threshold, 1023);
            let what = format!("lamps at chunk edges + {shift}, threshold {threshold}");
            let expected = assert_matches_reference(&img, &r, &what);
            assert!(
                threshold > DEFAULT_THRESHOLD || expected.features.len() == 9,
                "{what}: {:?}",
                expected.features
            );
            let got = run_stream(&mut *boxed_stream::<MAX_SIZE>(&r), &img, &r);
            assert_eq!(
                got,
                (expected.features, expected.overflow),
                "{what}, streamed"
            );
        }
    }
}

/// The largest response a local search over 7x7 binary patches found (the 5x5 window's
/// gradients read exactly a 7x7 patch). Its window sums are `Sxx = Syy = 11,769,525`,
/// `Sxy = -455,175`: `T = 23,539,050`, `det = (11,769,525 - 455,175)(11,769,525 + 455,175)
/// = 11,314,350 * 12,224,700 = 138,314,534,445,000`,
/// `Rs = 141,634,083,271,680,000 - 41 * 554,086,874,902,500
///     = 141,634,083,271,680,000 - 22,717,561,871,002,500 = 118,916,521,400,677,500`,
/// `r = floor(885,997,127.0016) = 885,997,127`: 2.4 times below `i32::MAX`, the ICD's claim
/// that `r` fits in 32 bits with room to spare.
#[test]
fn largest_response_found() {
    const PATCH: [[u8; 7]; 7] = [
        [0, 0, 0, 0, 0, 0, 255],
        [0, 255, 255, 0, 0, 255, 255],
        [0, 255, 255, 255, 0, 255, 255],
        [0, 0, 255, 255, 0, 0, 255],
        [0, 0, 0, 0, 0, 0, 255],
        [0, 255, 255, 0, 0, 255, 255],
        [255, 255, 255, 255, 255, 255, 255],
    ];
    assert_eq!(
        harris_core::response(11_769_525, 11_769_525, -455_175),
        885_997_127
    );
    let (width, height) = (16, 16);
    for background in [0u8, 255] {
        let mut img = vec![background; width * height];
        for (dy, row) in PATCH.iter().enumerate() {
            img[(5 + dy) * width + 5..(5 + dy) * width + 12].copy_from_slice(row);
        }
        let map = check_everywhere(
            &img,
            width,
            height,
            &format!("largest response on {background}"),
        );
        assert_eq!(map[8 * width + 8], 885_997_127);
        assert!(map.iter().all(|&r| r <= 885_997_127));
    }
}
