//! Runs the detector on one image many times, for profilers (perf, callgrind):
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
    let regs = Registers { width, height: image.height() as usize, ..Registers::default() };
    let mut stream = match BoardStream::new(regs) {
        Ok(s) => Box::new(s),
        Err(e) => {
            eprintln!("{e}");
            return ExitCode::FAILURE;
        }
    };
    let mut total = 0;
    let start = std::time::Instant::now();
    for _ in 0..repeats {
        for row in image.as_raw().chunks_exact(width) {
            total += stream.push_row(row).map_or(0, <[_]>::len);
        }
        let _ = stream.finish();
    }
    let per_frame = start.elapsed() / u32::try_from(repeats).unwrap_or(u32::MAX);
    println!("{} features per frame, {per_frame:?} per frame", total / repeats.max(1));
    ExitCode::SUCCESS
}
