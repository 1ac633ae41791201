//! Reading speed of `LogReader` on a large log: writes one (a `MINUTES`-minute recording of
//! 8 kB board packets at 20 Hz, random bits, and odometry at 100 Hz) at `PATH` unless it
//! exists, then reads it whole three times and prints the best time and MB/s. Uses only the
//! API the reader had before the damage-tolerant one, so that the same file measures both.
//!
//! ```sh
//! cargo run --release -p vehicle-log --example read_speed -- /tmp/big.mcap 10
//! ```
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::print_stdout)]

use std::time::Instant;

use vehicle_log::{LogReader, LogWriter, OdomSample, Record};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let path = args.get(1).map_or("/tmp/big.mcap", String::as_str);
    let minutes: u64 = args.get(2).map_or(10, |a| a.parse().unwrap());
    if !std::path::Path::new(path).exists() {
        let mut writer = LogWriter::create(path).unwrap();
        let mut x = 0x1234_5678_9abc_def1u64;
        let mut packet = vec![0u8; 8192];
        for tick in 0..minutes * 60 * 100 {
            let t_us = 1_000_000 + tick * 10_000;
            writer
                .odom(&OdomSample {
                    t_us,
                    vx: 0.8,
                    vy: 0.0,
                    vtheta: (tick % 100) as f64 * 1e-3,
                })
                .unwrap();
            if tick % 5 == 0 {
                for b in &mut packet {
                    x ^= x >> 12;
                    x ^= x << 25;
                    x ^= x >> 27;
                    *b = (x.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 56) as u8;
                }
                for (i, chunk) in packet.chunks(4096).enumerate() {
                    writer
                        .features((t_us + 2000 + i as u64 * 100) * 1000, chunk)
                        .unwrap();
                }
            }
        }
        writer.finish().unwrap();
    }
    let bytes = std::fs::metadata(path).unwrap().len() as f64;
    let mut best = f64::INFINITY;
    let (mut features, mut odom) = (0u64, 0u64);
    for _ in 0..3 {
        let started = Instant::now();
        (features, odom) = (0, 0);
        for record in LogReader::open(path).unwrap() {
            match record.unwrap() {
                Record::Features { bytes, .. } => features += bytes.len() as u64,
                Record::Odom(_) => odom += 1,
                _ => {}
            }
        }
        best = best.min(started.elapsed().as_secs_f64());
    }
    println!(
        "{path}: {:.1} MB, {odom} odometry samples, {:.1} MB of features; read in {best:.3} s \
         (best of 3): {:.0} MB/s",
        bytes / 1e6,
        features as f64 / 1e6,
        bytes / 1e6 / best
    );
}
