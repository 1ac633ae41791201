//! One phase-1 solve: 5 landmarks over 200 frame pairs (the 2 ms target).
//!
//! `cargo bench -p calib --bench selfcal`

use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::Vector3;

use calib::camera::{CameraParams, Mount, N_PARAMS, Param, Pose2};
use calib::config::{Noise, Rig};
use calib::odometry::{Motion, constant_velocity_motion};
use calib::selfcal::{FramePair, LandmarkPair, SolverSettings, calibrate};

/// xorshift64* with Box-Muller: deterministic data without an RNG crate.
struct Rng(u64);
impl Rng {
    fn uniform(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 / (1u64 << 53) as f64
    }
    fn gauss(&mut self) -> f64 {
        let (a, b) = (self.uniform().max(1e-300), self.uniform());
        (-2.0 * a.ln()).sqrt() * (std::f64::consts::TAU * b).cos()
    }
}

fn data() -> (Rig, Vec<FramePair>) {
    let truth = CameraParams {
        f: 702.0,
        cx: 376.0,
        cy: 240.0,
        baseline: 0.1215,
        mount: Mount {
            x: 0.3,
            y: 0.0,
            z: 1.2,
            roll: 0.0,
            pitch: 0.3,
            yaw: 0.0,
        },
    };
    let mut nominal = truth;
    nominal.f = 680.0;
    nominal.baseline = 0.118;
    let mut prior = [None; N_PARAMS];
    prior[Param::F.index()] = Some(30.0);
    prior[Param::Baseline.index()] = Some(0.01);
    let rig = Rig {
        width: 752,
        height: 480,
        nominal,
        estimate: vec![Param::F, Param::Baseline],
        prior,
        noise: Noise {
            pixel: 0.3,
            velocity: 0.02,
            yaw_rate: 0.01,
        },
    };
    let lamps = [
        Vector3::new(1.5, 0.0, 3.5),
        Vector3::new(2.2, 0.7, 3.4),
        Vector3::new(2.0, -0.8, 3.6),
        Vector3::new(1.0, 0.6, 3.5),
        Vector3::new(1.2, -0.5, 3.45),
    ];
    let mut rng = Rng(0x5EED);
    let mut pose = Pose2::default();
    let mut pairs = Vec::new();
    let mut prev: Option<Vec<Option<calib::Measurement>>> = None;
    let mut measured = Motion::default();
    for k in 0..201u64 {
        let (mut odo, mut real) = (Motion::default(), Motion::default());
        let w = if (k / 40) % 2 == 0 { 0.3 } else { -0.3 };
        for _ in 0..5 {
            real = real.then(&constant_velocity_motion(0.2, 0.0, w, 0.01));
            odo = odo.then(&constant_velocity_motion(
                0.2 + 0.02 * rng.gauss(),
                0.0,
                w + 0.01 * rng.gauss(),
                0.01,
            ));
        }
        let seen: Vec<_> = lamps
            .iter()
            .map(|l| {
                calib::project(&truth, &pose, l).ok().map(|z| {
                    z + calib::Measurement::new(rng.gauss(), rng.gauss(), rng.gauss(), rng.gauss())
                        * 0.3
                })
            })
            .collect();
        if let Some(prev) = &prev {
            let landmarks = prev
                .iter()
                .zip(&seen)
                .filter_map(|(a, b)| {
                    Some(LandmarkPair {
                        first: (*a)?,
                        second: (*b)?,
                    })
                })
                .collect();
            pairs.push(FramePair {
                t_us: 50_000 * k,
                motion: measured,
                landmarks,
            });
        }
        prev = Some(seen);
        pose = real.apply(&pose);
        measured = odo;
    }
    (rig, pairs)
}

fn bench(c: &mut Criterion) {
    let (rig, pairs) = data();
    let settings = SolverSettings::default();
    c.bench_function("selfcal_5_landmarks_200_pairs_f_baseline", |b| {
        b.iter(|| calibrate(&pairs, &rig, &rig.nominal, &settings));
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
