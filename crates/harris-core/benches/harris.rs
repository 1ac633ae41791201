//! Speed of the board detector on a real 752x480 frame (EuRoC V1_01, from ../shared/data).
//!
//! `cargo bench -p harris-core --bench harris`. Skips (prints why) when ../shared is absent.
#![allow(clippy::print_stderr)] // says why a bench is skipped

use std::hint::black_box;
use std::path::PathBuf;

use criterion::{Criterion, criterion_group, criterion_main};
use harris_core::{BoardStream, Registers, detect};

fn euroc_frame() -> Option<(usize, usize, Vec<u8>)> {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data/euroc-v101-stereo/left");
    let mut paths: Vec<_> = std::fs::read_dir(dir)
        .ok()?
        .filter_map(|e| Some(e.ok()?.path()))
        .collect();
    paths.sort();
    let image = image::open(paths.first()?).ok()?.into_luma8();
    Some((
        image.width() as usize,
        image.height() as usize,
        image.into_raw(),
    ))
}

fn bench(c: &mut Criterion) {
    let Some((width, height, pixels)) = euroc_frame() else {
        eprintln!("../shared/data/euroc-v101-stereo is absent: harris benches skipped");
        return;
    };
    let regs = Registers {
        width,
        height,
        ..Registers::default()
    };
    let features = detect(&pixels, &regs)
        .map(|d| d.features.len())
        .unwrap_or(0);
    eprintln!("EuRoC frame {width}x{height}: {features} features at the default registers");

    let mut group = c.benchmark_group("harris_752x480");
    group.bench_function("whole_image_detect", |b| {
        b.iter(|| detect(black_box(&pixels), black_box(&regs)));
    });
    let mut stream = Box::new(BoardStream::new(regs).unwrap_or_else(|e| panic!("{e}")));
    group.bench_function("streaming_push_rows", |b| {
        b.iter(|| {
            let mut n = 0;
            for row in black_box(&pixels).chunks_exact(width) {
                n += stream.push_row(row).map(<[_]>::len).unwrap_or(0);
            }
            (n, stream.finish())
        });
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
