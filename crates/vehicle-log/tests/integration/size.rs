//! File sizes of a typical recording: 60 s of odometry at 100 Hz and 8 KB packets at 20 Hz.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use crate::common;

use std::time::Instant;

use common::{Rng, tmp};
use fpga_link::{Encoder, Feature};
use vehicle_log::{LogReader, LogWriter, OdomSample, Record};

/// Features a side for a packet of about 8 KB: 24-byte header, 8 bytes a feature, 4-byte CRC.
const FEATURES_PER_SIDE: usize = 510;

#[derive(Clone, Copy, Debug)]
enum Packets {
    /// Feature bits all random: the worst case for compression.
    RandomBits,
    /// Random positions in the image, in raster order, responses up to 2^28.
    RandomImage,
    /// A static scene: the same corners every frame with a quarter-pixel of noise (the
    /// vehicle standing still, as in the EuRoC log).
    StaticImage,
}

fn side(rng: &mut Rng, scene: Packets, base: &[Feature]) -> Vec<Feature> {
    let mut f: Vec<Feature> = match scene {
        Packets::RandomBits => (0..FEATURES_PER_SIDE)
            .map(|_| Feature {
                x_q4: rng.next_u64() as u16,
                y_q4: rng.next_u64() as u16,
                r: rng.next_u64() as i32,
            })
            .collect(),
        Packets::RandomImage => (0..FEATURES_PER_SIDE)
            .map(|_| Feature {
                x_q4: rng.below(752 * 16) as u16,
                y_q4: rng.below(480 * 16) as u16,
                r: (1 << 18) + rng.below(1 << 28) as i32,
            })
            .collect(),
        Packets::StaticImage => base
            .iter()
            .map(|b| Feature {
                x_q4: b.x_q4.wrapping_add(rng.below(9) as u16).wrapping_sub(4),
                y_q4: b.y_q4.wrapping_add(rng.below(9) as u16).wrapping_sub(4),
                r: b.r + rng.below(1 << 20) as i32 - (1 << 19),
            })
            .collect(),
    };
    if !matches!(scene, Packets::RandomBits) {
        f.sort_by_key(|f| (f.y_q4 >> 4, f.x_q4));
    }
    f
}

#[test]
fn a_minute_of_recording_compresses() {
    for scene in [
        Packets::RandomBits,
        Packets::RandomImage,
        Packets::StaticImage,
    ] {
        let mut rng = Rng(2024);
        let base: Vec<Feature> = side(&mut rng, Packets::RandomImage, &[]);
        let base_right: Vec<Feature> = side(&mut rng, Packets::RandomImage, &[]);
        let path = tmp(&format!("minute-{scene:?}.mcap"));
        let started = Instant::now();
        let mut writer = LogWriter::create(&path).unwrap();
        let mut enc = Encoder::starting_at(0);
        let mut raw_bytes = 0usize;
        let mut packet = Vec::new();
        let t0_us = 10_000_000;
        for tick in 0..6000u64 {
            let t_us = t0_us + tick * 10_000;
            let odom = OdomSample {
                t_us,
                vx: 0.8 + rng.uniform(-0.02, 0.02),
                vy: rng.uniform(-0.02, 0.02),
                vtheta: rng.uniform(-0.01, 0.01),
            };
            writer.odom(&odom).unwrap();
            raw_bytes += serde_json::to_vec(&odom).unwrap().len();
            if tick % 5 == 0 {
                let left = side(&mut rng, scene, &base);
                let right = side(&mut rng, scene, &base_right);
                packet.clear();
                enc.encode_to_vec(t_us, (&left, false), (&right, false), &mut packet)
                    .unwrap();
                // Arrives in 4 KB reads, 2 ms after exposure.
                for (i, chunk) in packet.chunks(4096).enumerate() {
                    writer
                        .features((t_us + 2000 + i as u64 * 100) * 1000, chunk)
                        .unwrap();
                }
                raw_bytes += packet.len();
            }
        }
        writer.finish().unwrap();
        let write_s = started.elapsed().as_secs_f64();
        let file_bytes = std::fs::metadata(&path).unwrap().len() as usize;

        let started = Instant::now();
        let mut reader = LogReader::open(&path).unwrap();
        let mut features = 0usize;
        let mut odom = 0usize;
        for record in &mut reader {
            match record.unwrap() {
                Record::Features { bytes, .. } => features += bytes.len(),
                Record::Odom(_) => odom += 1,
                _ => {}
            }
        }
        let read_s = started.elapsed().as_secs_f64();
        assert_eq!(reader.truncated(), None);
        assert_eq!(odom, 6000);
        assert_eq!(features, 1200 * packet.len());
        eprintln!(
            "{scene:?}: packet {} B, raw {:.2} MB (packets + odometry JSON), file {:.2} MB \
             ({:.0}% of raw, {:.0} kB/s); write {write_s:.2} s, read {read_s:.2} s",
            packet.len(),
            raw_bytes as f64 / 1e6,
            file_bytes as f64 / 1e6,
            100.0 * file_bytes as f64 / raw_bytes as f64,
            file_bytes as f64 / 60.0 / 1e3,
        );
        // At most 1 % over the raw data, whatever it holds (packed feature coordinates
        // compress little: the real EuRoC packets to about 80 %).
        assert!(file_bytes < raw_bytes + raw_bytes / 100, "{scene:?}");
    }
}
