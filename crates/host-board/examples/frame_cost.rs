//! One pass of the ten EuRoC stereo pairs (../shared/data), each image encoded once as gray
//! JPEG (quality 90), through the host board: for counting instructions per stereo frame with
//! callgrind, whatever the machine's load:
//!
//! `valgrind --tool=callgrind --toggle-collect='host_board::HostBoard::pop'
//! target/release/examples/frame_cost` (docs/benchmarks.md, "ROS 2 bags").
#![allow(clippy::print_stdout, clippy::print_stderr)] // an example that reports

use std::path::PathBuf;

use image::ImageEncoder;
use vehicle_log::{CameraImage, ImagePayload, Side};

fn main() {
    let dir =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/euroc-v101-stereo");
    let list = |side: &str| -> Vec<PathBuf> {
        let mut p: Vec<PathBuf> = std::fs::read_dir(dir.join(side))
            .map(|d| d.filter_map(|e| Some(e.ok()?.path())).collect())
            .unwrap_or_default();
        p.sort();
        p
    };
    let (left, right) = (list("left"), list("right"));
    if left.is_empty() {
        eprintln!("../shared/data/euroc-v101-stereo is absent: nothing to do");
        return;
    }
    let jpeg = |path: &PathBuf| -> (u32, u32, Vec<u8>) {
        let img = image::open(path)
            .unwrap_or_else(|e| panic!("{e}"))
            .into_luma8();
        let mut out = Vec::new();
        image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, 90)
            .write_image(
                img.as_raw(),
                img.width(),
                img.height(),
                image::ExtendedColorType::L8,
            )
            .unwrap_or_else(|e| panic!("{e}"));
        (img.width(), img.height(), out)
    };
    let mut board = None;
    let mut features = 0;
    for (k, (l, r)) in left.iter().zip(&right).enumerate() {
        let t_us = 1_000_000 + 50_000 * k as u64;
        for (side, path) in [(Side::Left, l), (Side::Right, r)] {
            let (width, height, data) = jpeg(path);
            let board = board.get_or_insert_with(|| {
                host_board::HostBoard::new(harris_core::Registers {
                    width: width as usize,
                    height: height as usize,
                    ..harris_core::Registers::default()
                })
                .unwrap_or_else(|e| panic!("{e}"))
            });
            board.push(CameraImage {
                side,
                t_us,
                log_time_ns: t_us * 1000,
                payload: ImagePayload::Compressed {
                    format: "jpeg".to_owned(),
                    data,
                },
            });
        }
    }
    if let Some(board) = board.as_mut() {
        board.end();
        while let Some(f) = board.pop() {
            features += f.left.len() + f.right.len();
        }
        println!(
            "{} stereo frames, {features} features",
            board.counts().frames
        );
    }
}
