//! Speed of the board on the host (issue 39): a stereo frame of two 752x480 JPEG images (the
//! ten real EuRoC V1_01 pairs of ../shared/data, encoded as 8-bit gray JPEG of quality 90 by
//! the `image` crate) decoded and detected, as a ROS 2 bag's replay does it. At 20 Hz, ten
//! times real time is 5 ms per stereo frame.
//!
//! `cargo bench -p host-board --bench decode_detect`. Skips (prints why) when ../shared is
//! absent. `bench/bag_frontend_vs_opencv.py` times OpenCV's decode of the same images in one
//! process with the Python module's.
#![allow(clippy::print_stderr)] // says why a bench is skipped

use std::hint::black_box;
use std::path::PathBuf;

use criterion::{Criterion, criterion_group, criterion_main};
use harris_core::Registers;
use host_board::HostBoard;
use image::codecs::jpeg::JpegEncoder;
use image::codecs::png::PngEncoder;
use image::{ExtendedColorType, ImageEncoder};
use vehicle_log::{CameraImage, ImagePayload, Side};

/// Gray stereo pairs `(width, height, [(left, right)])`.
type Pairs = (u32, u32, Vec<(Vec<u8>, Vec<u8>)>);

/// The EuRoC pairs as gray pixels.
fn euroc_pairs() -> Option<Pairs> {
    let dir =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/euroc-v101-stereo");
    let list = |side: &str| -> Option<Vec<PathBuf>> {
        let mut paths: Vec<_> = std::fs::read_dir(dir.join(side))
            .ok()?
            .filter_map(|e| Some(e.ok()?.path()))
            .collect();
        paths.sort();
        Some(paths)
    };
    let (left, right) = (list("left")?, list("right")?);
    let mut size = (0, 0);
    let mut pairs = Vec::new();
    for (l, r) in left.iter().zip(&right) {
        let l = image::open(l).ok()?.into_luma8();
        let r = image::open(r).ok()?.into_luma8();
        size = (l.width(), l.height());
        pairs.push((l.into_raw(), r.into_raw()));
    }
    (!pairs.is_empty()).then_some((size.0, size.1, pairs))
}

fn jpeg(pixels: &[u8], width: u32, height: u32) -> Vec<u8> {
    let mut out = Vec::new();
    JpegEncoder::new_with_quality(&mut out, 90)
        .write_image(pixels, width, height, ExtendedColorType::L8)
        .unwrap_or_else(|e| panic!("{e}"));
    out
}

fn png(pixels: &[u8], width: u32, height: u32) -> Vec<u8> {
    let mut out = Vec::new();
    PngEncoder::new(&mut out)
        .write_image(pixels, width, height, ExtendedColorType::L8)
        .unwrap_or_else(|e| panic!("{e}"));
    out
}

fn image(side: Side, t_us: u64, payload: ImagePayload) -> CameraImage {
    CameraImage {
        side,
        t_us,
        log_time_ns: t_us * 1000,
        payload,
    }
}

fn bench(c: &mut Criterion) {
    let Some((width, height, pairs)) = euroc_pairs() else {
        eprintln!("../shared/data/euroc-v101-stereo is absent: host-board benches skipped");
        return;
    };
    let regs = Registers {
        width: width as usize,
        height: height as usize,
        ..Registers::default()
    };
    let compressed = |encode: fn(&[u8], u32, u32) -> Vec<u8>,
                      format: &str|
     -> Vec<(ImagePayload, ImagePayload)> {
        pairs
            .iter()
            .map(|(l, r)| {
                let p = |px: &[u8]| ImagePayload::Compressed {
                    format: format.to_owned(),
                    data: encode(px, width, height),
                };
                (p(l), p(r))
            })
            .collect()
    };
    let raw: Vec<(ImagePayload, ImagePayload)> = pairs
        .iter()
        .map(|(l, r)| {
            let p = |px: &Vec<u8>| ImagePayload::Raw {
                width,
                height,
                encoding: "mono8".to_owned(),
                step: width,
                data: px.clone(),
            };
            (p(l), p(r))
        })
        .collect();
    let jpegs = compressed(jpeg, "jpeg");
    let pngs = compressed(png, "png");
    let bytes = |v: &[(ImagePayload, ImagePayload)]| -> usize {
        v.iter()
            .map(|(l, _)| match l {
                ImagePayload::Compressed { data, .. } | ImagePayload::Raw { data, .. } => {
                    data.len()
                }
            })
            .sum::<usize>()
            / v.len()
    };
    eprintln!(
        "{} EuRoC pairs {width}x{height}: JPEG q90 {} bytes, PNG {} bytes an image",
        pairs.len(),
        bytes(&jpegs),
        bytes(&pngs)
    );

    let mut group = c.benchmark_group("host_board_752x480");
    for (name, set) in [("jpeg", &jpegs), ("png", &pngs), ("mono8", &raw)] {
        // One stereo frame through the host board: pairing, decoding and detecting both
        // images, as the replay of a bag does it; the frames cycle through the ten pairs.
        let mut board = HostBoard::new(regs).unwrap_or_else(|e| panic!("{e}"));
        let mut k = 0_u64;
        group.bench_function(format!("stereo_frame_{name}"), |b| {
            b.iter(|| {
                let (l, r) = &set[(k as usize) % set.len()];
                let t = 1_000_000 + 50_000 * k;
                k += 1;
                board.push(image(Side::Left, t, l.clone()));
                board.push(image(Side::Right, t, r.clone()));
                // The pairing lets a frame out once the next one is in: drain what is ready.
                let mut n = 0;
                while let Some(f) = board.pop() {
                    n += f.left.len() + f.right.len();
                }
                black_box(n)
            });
        });
        group.bench_function(format!("decode_{name}"), |b| {
            let mut k = 0;
            b.iter(|| {
                let (l, _) = &set[k % set.len()];
                k += 1;
                black_box(host_board::gray_pixels(l, width, height).map(|p| p.len()))
            });
        });
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
