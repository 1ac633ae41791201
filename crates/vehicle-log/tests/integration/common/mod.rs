//! Helpers shared by the tests: a seeded generator, sample logs, paths.
#![allow(dead_code, unreachable_pub, clippy::unwrap_used, clippy::expect_used)]

pub mod layout;

use std::io::{Cursor, Seek, Write};
use std::path::{Path, PathBuf};

use fpga_link::{Encoder, Feature};
use vehicle_log::{LogWriter, OdomSample, Record, TruthCamera, TruthLandmark, TruthPose};

/// A deterministic pseudo-random generator (xorshift64*), so tests need no RNG crate.
pub struct Rng(pub u64);

impl Rng {
    pub fn next_u64(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    pub fn below(&mut self, n: u64) -> u64 {
        self.next_u64() % n.max(1)
    }
    /// Uniform in [lo, hi).
    pub fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    /// Any finite float, from its bits: subnormals, -0.0, extremes included.
    pub fn any_finite(&mut self) -> f64 {
        loop {
            let x = f64::from_bits(self.next_u64());
            if x.is_finite() {
                return x;
            }
        }
    }
    /// A float that is sometimes ordinary and sometimes from any bits.
    pub fn float(&mut self, lo: f64, hi: f64) -> f64 {
        match self.below(8) {
            0 => self.any_finite(),
            1 => -0.0,
            _ => self.uniform(lo, hi),
        }
    }
}

/// A fresh path under the integration tests' scratch folder.
pub fn tmp(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("vehicle-log");
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

/// The third-party data folder beside the project, if present.
pub fn shared_data() -> Option<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data");
    dir.is_dir().then_some(dir)
}

/// A packet of the board with `n` features a side, in raster order like the board's.
pub fn packet(rng: &mut Rng, enc: &mut Encoder, t_us: u64, n: usize) -> Vec<u8> {
    let side = |rng: &mut Rng| {
        let mut f: Vec<Feature> = (0..n)
            .map(|_| Feature {
                x_q4: rng.below(752 * 16) as u16,
                y_q4: rng.below(480 * 16) as u16,
                r: (1 << 18) + rng.below(1 << 28) as i32,
            })
            .collect();
        f.sort_by_key(|f| (f.y_q4 >> 4, f.x_q4));
        f
    };
    let left = side(rng);
    let right = side(rng);
    let mut bytes = Vec::new();
    enc.encode_to_vec(t_us, (&left, false), (&right, false), &mut bytes)
        .unwrap();
    bytes
}

/// A sample log in arrival order: a rig message, truth camera and landmarks, then odometry
/// at 100 Hz, the board's packets at 20 Hz cut into chunks of random sizes arriving with
/// jitter, and a truth pose per packet; `seconds` long.
pub fn sample(seed: u64, seconds: u64) -> Vec<Record> {
    let mut rng = Rng(seed | 1);
    let mut records = vec![
        Record::Rig(
            r#"{"camera": {"width": 752, "height": 480, "f": 700.0, "cx": 376.0, "cy": 240.0, "baseline": 0.12},
 "mount": {"x": 0.0, "y": 0.0, "z": 1.0, "roll": 0.0, "pitch": 0.0, "yaw": 0.0},
 "estimate": {"parameters": ["baseline", "f"]}, "prior": {"f": 30.0, "baseline": 0.01},
 "noise": {"pixel": 0.3, "velocity": 0.02, "yaw_rate": 0.01}}"#
                .to_owned(),
        ),
        Record::TruthCamera(TruthCamera {
            f: rng.float(650.0, 750.0),
            cx: rng.float(370.0, 380.0),
            cy: rng.float(235.0, 245.0),
            baseline: rng.float(0.11, 0.13),
            mount_x: rng.float(-0.1, 0.1),
            mount_y: rng.float(-0.1, 0.1),
            mount_z: rng.float(0.9, 1.1),
            mount_roll: rng.float(-0.01, 0.01),
            mount_pitch: rng.float(-0.01, 0.01),
            mount_yaw: rng.float(-0.01, 0.01),
            odom_scale: rng.float(0.98, 1.02),
            odom_yaw_scale: rng.float(0.99, 1.01),
            odom_yaw_bias: rng.float(-0.003, 0.003),
            time_offset: rng.float(-0.02, 0.02),
        }),
        Record::TruthLandmarks(
            (0..40)
                .map(|id| TruthLandmark {
                    id: id * 7 + u32::from(id == 39) * (u32::MAX - 7 * 39),
                    x: rng.float(-20.0, 20.0),
                    y: rng.float(-20.0, 20.0),
                    z: rng.float(5.0, 8.0),
                })
                .collect(),
        ),
    ];
    let t0_us = 1_000_000 + rng.below(1_000_000);
    let mut enc = Encoder::starting_at(rng.next_u64() as u32);
    let mut timeline: Vec<(u64, Record)> = Vec::new();
    for i in 0..seconds * 100 {
        let t_us = t0_us + i * 10_000;
        timeline.push((
            t_us * 1000,
            Record::Odom(OdomSample {
                t_us,
                vx: rng.float(-1.0, 2.0),
                vy: rng.float(-0.1, 0.1),
                vtheta: rng.float(-0.5, 0.5),
            }),
        ));
    }
    for i in 0..seconds * 20 {
        let t_us = t0_us + i * 50_000;
        let n = rng.below(60) as usize;
        let bytes = packet(&mut rng, &mut enc, t_us, n);
        // The packet arrives 1 to 3 ms after its exposure, in chunks of 0 to 300 bytes, each
        // a few microseconds apart.
        let mut arrival_ns = (t_us + 1000 + rng.below(2000)) * 1000;
        let mut at = 0;
        while at < bytes.len() {
            let len = (rng.below(300) as usize).min(bytes.len() - at);
            timeline.push((
                arrival_ns,
                Record::Features {
                    log_time_ns: arrival_ns,
                    bytes: bytes[at..at + len].to_vec(),
                },
            ));
            at += len;
            arrival_ns += 1000 * rng.below(50);
        }
        timeline.push((
            (t_us + 5000) * 1000,
            Record::TruthPose(TruthPose {
                t_us,
                x: rng.float(-20.0, 20.0),
                y: rng.float(-20.0, 20.0),
                theta: rng.float(-3.2, 3.2),
            }),
        ));
    }
    // Arrival order; equal times keep their order of creation.
    timeline.sort_by_key(|(arrival, _)| *arrival);
    records.extend(timeline.into_iter().map(|(_, r)| r));
    records
}

/// Writes `records` with the writer, in order.
pub fn write_records<W: Write + Seek>(writer: &mut LogWriter<W>, records: &[Record]) {
    for record in records {
        match record {
            Record::Features { log_time_ns, bytes } => writer.features(*log_time_ns, bytes),
            Record::Odom(s) => writer.odom(s),
            Record::Rig(text) => writer.rig_json(text),
            Record::TruthPose(p) => writer.truth_pose(p),
            Record::TruthLandmarks(l) => writer.truth_landmarks(l),
            Record::TruthCamera(c) => writer.truth_camera(c),
            other => panic!("unexpected record {other:?}"),
        }
        .unwrap();
    }
}

/// A log of `records`, in memory.
pub fn log_bytes(records: &[Record]) -> Vec<u8> {
    let mut writer = LogWriter::new(Cursor::new(Vec::new())).unwrap();
    write_records(&mut writer, records);
    writer.finish().unwrap().into_inner()
}

/// The records with their floats as bit patterns, for bit-exact comparisons (`==` on f64
/// takes -0.0 for 0.0).
pub fn exact(records: &[Record]) -> String {
    // `{:?}` of a finite f64 is its shortest round-trip form, with the sign of zero.
    format!("{records:?}")
}

/// The concatenated byte stream of the features records.
pub fn stream_of(records: &[Record]) -> Vec<u8> {
    records
        .iter()
        .filter_map(|r| match r {
            Record::Features { bytes, .. } => Some(bytes.as_slice()),
            _ => None,
        })
        .flatten()
        .copied()
        .collect()
}
