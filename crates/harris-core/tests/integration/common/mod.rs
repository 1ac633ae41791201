//! Shared helpers of the harris-core integration tests: seeded image generators, the
//! row-by-row driver, and the comparison with the integer reference.
#![allow(dead_code, unreachable_pub)] // each test binary uses a different subset

use harris_core::{Feature, HarrisStream, Registers, detect, reference, response_map};

/// SplitMix64: a tiny seeded generator, so that every failing image is reproducible from its
/// `(kind, width, height, seed)` alone.
#[derive(Debug, Clone)]
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Self(seed ^ 0x9E37_79B9_7F4A_7C15)
    }
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in `0..n` (`n > 0`; the modulo bias is irrelevant here).
    pub fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n as u64) as usize
    }
    pub fn byte(&mut self) -> u8 {
        self.next_u64().to_le_bytes()[0]
    }
    /// Uniform in `[0, 1)`.
    pub fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// The kinds of image content the property tests draw from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// Every pixel uniform in `0..=255`.
    Noise,
    /// A dark, slightly noisy background with a few small bright blobs (lamps): mostly flat,
    /// so most chunks of the streaming detector stay undecided.
    Blobs,
    /// A smooth ramp plus a slow ripple: large traces, few corners.
    Gradient,
    /// 0/255 rectangles and checkers of random periods.
    Binary,
    /// A flat image with a few isolated random pixels.
    SparseNoise,
}

pub const KINDS: [Kind; 5] = [
    Kind::Noise,
    Kind::Blobs,
    Kind::Gradient,
    Kind::Binary,
    Kind::SparseNoise,
];

fn clamp_u8(v: f64) -> u8 {
    v.round().clamp(0.0, 255.0) as u8
}

/// A `width x height` row-major image of the given kind, from `seed`.
pub fn generate(kind: Kind, width: usize, height: usize, seed: u64) -> Vec<u8> {
    let mut rng = Rng::new(seed);
    let mut img = vec![0u8; width * height];
    match kind {
        Kind::Noise => img.iter_mut().for_each(|p| *p = rng.byte()),
        Kind::Blobs => {
            let base = rng.below(40) as u8;
            let noise = rng.below(4) as u8;
            for p in &mut img {
                *p = base
                    + if noise > 0 {
                        rng.byte() % (noise + 1)
                    } else {
                        0
                    };
            }
            let blobs = 1 + rng.below(1 + width * height / 200);
            for _ in 0..blobs {
                let (cx, cy) = (rng.below(width), rng.below(height));
                let (bw, bh) = (1 + rng.below(4), 1 + rng.below(4));
                let level = 60 + rng.below(196);
                let soft = rng.below(2) == 0;
                for y in cy.saturating_sub(3)..(cy + bh + 3).min(height) {
                    for x in cx.saturating_sub(3)..(cx + bw + 3).min(width) {
                        let inside = (cx..cx + bw).contains(&x) && (cy..cy + bh).contains(&y);
                        let v = if inside {
                            level as f64
                        } else if soft {
                            let dx = if x < cx {
                                cx - x
                            } else {
                                x.saturating_sub(cx + bw - 1)
                            };
                            let dy = if y < cy {
                                cy - y
                            } else {
                                y.saturating_sub(cy + bh - 1)
                            };
                            level as f64 * (-((dx * dx + dy * dy) as f64) / 2.0).exp()
                        } else {
                            continue;
                        };
                        let p = &mut img[y * width + x];
                        *p = (*p).max(clamp_u8(v));
                    }
                }
            }
        }
        Kind::Gradient => {
            let (a, bx, by) = (
                rng.unit() * 255.0,
                rng.unit() * 6.0 - 3.0,
                rng.unit() * 6.0 - 3.0,
            );
            let (amp, fx, fy) = (rng.unit() * 60.0, rng.unit() * 0.3, rng.unit() * 0.3);
            for y in 0..height {
                for x in 0..width {
                    let (xf, yf) = (x as f64, y as f64);
                    img[y * width + x] =
                        clamp_u8(a + bx * xf + by * yf + amp * (fx * xf + fy * yf).sin());
                }
            }
        }
        Kind::Binary => {
            let (px, py) = (1 + rng.below(6), 1 + rng.below(6));
            let checker = rng.below(3) == 0;
            if checker {
                for y in 0..height {
                    for x in 0..width {
                        img[y * width + x] = if (x / px + y / py) % 2 == 0 { 0 } else { 255 };
                    }
                }
            }
            for _ in 0..1 + rng.below(12) {
                let (x0, y0) = (rng.below(width), rng.below(height));
                let (x1, y1) = (
                    (x0 + 1 + rng.below(20)).min(width),
                    (y0 + 1 + rng.below(20)).min(height),
                );
                let v = if rng.below(2) == 0 { 0 } else { 255 };
                for y in y0..y1 {
                    img[y * width + x0..y * width + x1].fill(v);
                }
            }
        }
        Kind::SparseNoise => {
            let base = rng.byte();
            img.fill(base);
            for _ in 0..1 + rng.below(1 + width * height / 64) {
                let i = rng.below(width * height);
                img[i] = rng.byte();
            }
        }
    }
    img
}

/// Pushes `image` row by row through `stream` (already set to `regs`), checking the stream's
/// own promises on the way: each push returns only features of the row that became final
/// (row `y - 4` when pixel row `y` is pushed), and `finish` reports what was returned.
/// Returns the features and the overflow flag.
pub fn run_stream<const N: usize>(
    stream: &mut HarrisStream<N>,
    image: &[u8],
    regs: &Registers,
) -> (Vec<Feature>, bool) {
    assert_eq!(stream.registers(), *regs);
    let mut features = Vec::new();
    for (y, row) in image.chunks_exact(regs.width).enumerate() {
        assert_eq!(stream.rows_pushed(), y);
        let got = stream
            .push_row(row)
            .unwrap_or_else(|e| panic!("row {y}: {e}"));
        for f in got {
            // The feature's integer row is y - 4, so y_q4 is within 8/16 px of 16 (y - 4).
            let centre = 16 * (y as i64 - 4);
            assert!(
                (i64::from(f.y_q4) - centre).abs() <= 8,
                "feature {f:?} returned with pixel row {y}, not row y - 4"
            );
        }
        features.extend_from_slice(got);
    }
    let overflow = stream.overflow();
    let summary = stream.finish().unwrap_or_else(|e| panic!("finish: {e}"));
    assert_eq!(summary.features, features.len(), "summary count");
    assert_eq!(summary.overflow, overflow, "summary overflow");
    assert_eq!(stream.rows_pushed(), 0, "finish starts a new image");
    (features, overflow)
}

/// A fresh heap-allocated stream of capacity `N`.
pub fn boxed_stream<const N: usize>(regs: &Registers) -> Box<HarrisStream<N>> {
    Box::new(HarrisStream::<N>::new(*regs).unwrap_or_else(|e| panic!("new: {e}")))
}

/// The integer reference's result for `image`, panicking with the registers on error.
pub fn reference_of(image: &[u8], regs: &Registers) -> reference::IntegerReference {
    reference::integer(image, regs).unwrap_or_else(|e| panic!("reference {regs:?}: {e}"))
}

/// Asserts that `detect` and `response_map` equal the integer reference; returns the reference.
pub fn assert_matches_reference(
    image: &[u8],
    regs: &Registers,
    what: &str,
) -> reference::IntegerReference {
    let expected = reference_of(image, regs);
    let got = detect(image, regs).unwrap_or_else(|e| panic!("{what}: detect: {e}"));
    assert_features_eq(&got.features, &expected.features, what);
    assert_eq!(got.overflow, expected.overflow, "{what}: overflow flag");
    let map = response_map(image, regs).unwrap_or_else(|e| panic!("{what}: response_map: {e}"));
    assert_map_eq(&map, &expected.response, regs.width, what);
    expected
}

/// Feature lists equal, with the first difference in the message.
pub fn assert_features_eq(got: &[Feature], expected: &[Feature], what: &str) {
    if got != expected {
        let first = got.iter().zip(expected).position(|(a, b)| a != b);
        panic!(
            "{what}: features differ: got {} expected {}; first difference at index {first:?}: \
             got {:?} expected {:?}",
            got.len(),
            expected.len(),
            first.and_then(|i| got.get(i)).or(got.get(expected.len())),
            first
                .and_then(|i| expected.get(i))
                .or(expected.get(got.len())),
        );
    }
}

/// Response maps equal, with the first differing pixel in the message.
pub fn assert_map_eq(got: &[i32], expected: &[i32], width: usize, what: &str) {
    assert_eq!(got.len(), expected.len(), "{what}: response map size");
    if let Some(i) = got.iter().zip(expected).position(|(a, b)| a != b) {
        panic!(
            "{what}: response maps differ at (x {}, y {}): got {} expected {}",
            i % width,
            i / width,
            got[i],
            expected[i]
        );
    }
}

/// Registers for a `width x height` image with the given threshold and cap.
pub fn regs(width: usize, height: usize, threshold: i32, max_features: usize) -> Registers {
    Registers {
        width,
        height,
        threshold,
        max_features,
    }
}

/// Integer pixel of a feature: the `(x, y)` whose Q12.4 coordinates are within 8/16 of it.
/// (Only unambiguous when the offsets are known to be below 8 in magnitude.)
pub fn pixel_of(f: &Feature) -> (usize, usize) {
    (
        (usize::from(f.x_q4) + 7) / 16,
        (usize::from(f.y_q4) + 7) / 16,
    )
}
