//! Runs the detector on one image many times, for profilers (perf, callgrind):
#![allow(clippy::print_stdout, clippy::print_stderr)] // a command-line tool: printing is its job
//! `cargo run --release -p harris-core --example profile_frame -- IMAGE.png [REPEATS]`.

use std::process::ExitCode;

use harris_core::{BoardStream, Registers};

fn main() -> ExitCode {
    let mut args = std::env::args().skip(1);
    let Some(path) = args.next() else {
        eprintln!("usage: profile_frame IMAGE [REPEATS]");
        return ExitCode::FAILURE;
    };
    let repeats: usize = args.next().and_then(|s| s.parse().ok()).unwrap_or(1000);
    let image = match image::open(&path) {
        Ok(image) => image.into_luma8(),
        Err(e) => {
            eprintln!("{path}: {e}");
            return ExitCode::FAILURE;
        }
    };
    let width = image.width() as usize;
    let regs = Registers {
        width,
        height: image.height() as usize,
        ..Registers::default()
    };
    let mut stream = match BoardStream::new(regs) {
        Ok(s) => Box::new(s),
        Err(e) => {
            eprintln!("{e}");
            return ExitCode::FAILURE;
        }
    };
    // Batches of 100 frames; the fastest batch is the least disturbed by the rest of the machine.
    let mut total = 0;
    let mut best = std::time::Duration::MAX;
    for _ in 0..repeats.div_ceil(100) {
        let start = std::time::Instant::now();
        for _ in 0..100 {
            for row in image.as_raw().chunks_exact(width) {
                total += stream.push_row(row).map_or(0, <[_]>::len);
            }
            let _ = stream.finish();
        }
        best = best.min(start.elapsed() / 100);
    }
    println!(
        "{} features per frame, best batch {best:?} per frame",
        total / (repeats.div_ceil(100) * 100)
    );
    ExitCode::SUCCESS
}
