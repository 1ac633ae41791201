//! Phase 1 on a simulated scenario over several seeds, associating features by the simulator's
//! lamp ids (the navigator's association is not in this experiment):
//! `cargo run --release -p sim --example phase1_accuracy -- fixtures/scenarios/paper-calibration.toml 20`.
#![allow(clippy::print_stdout, clippy::print_stderr)] // a command-line tool

use std::collections::HashMap;
use std::path::Path;
use std::process::ExitCode;

use calib::odometry::{OdomSample, integrate};
use calib::selfcal::{FramePair, LandmarkPair, SolverSettings, calibrate};
use calib::{Measurement, Param};

fn measurements(frame: &sim::FrameTruth) -> HashMap<u32, Measurement> {
    let right: HashMap<u32, &sim::SimFeature> = frame
        .right
        .features
        .iter()
        .filter_map(|f| Some((f.lamp?, f)))
        .collect();
    frame
        .left
        .features
        .iter()
        .filter_map(|l| {
            let id = l.lamp?;
            let r = right.get(&id)?;
            let q = |v: u16| f64::from(v) / 16.0;
            Some((
                id,
                Measurement::new(q(l.x_q4), q(l.y_q4), q(r.x_q4), q(r.y_q4)),
            ))
        })
        .collect()
}

fn main() -> ExitCode {
    let mut args = std::env::args().skip(1);
    let Some(path) = args.next() else {
        eprintln!("usage: phase1_accuracy SCENARIO.toml [SEEDS]");
        return ExitCode::FAILURE;
    };
    let seeds: u64 = args.next().and_then(|s| s.parse().ok()).unwrap_or(5);
    // Frames apart in each pair: more motion, more parallax per pair.
    let stride: usize = args.next().and_then(|s| s.parse().ok()).unwrap_or(1);
    let mut scenario = match sim::Scenario::load(Path::new(&path)) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("{e}");
            return ExitCode::FAILURE;
        }
    };
    let mut inside = 0;
    for seed in 0..seeds {
        scenario.spec.seed = seed;
        let run = match sim::simulate(&scenario, sim::Mode::Fast) {
            Ok(r) => r,
            Err(e) => {
                eprintln!("{e}");
                return ExitCode::FAILURE;
            }
        };
        let odo: Vec<OdomSample> = run
            .odometry
            .iter()
            .map(|s| OdomSample {
                t_us: s.t_us,
                vx: s.vx,
                vy: s.vy,
                vtheta: s.vtheta,
            })
            .collect();
        let mut pairs = Vec::new();
        for w in run.frames.windows(stride + 1).step_by(stride + 1) {
            let (first, last) = (&w[0], &w[stride]);
            let (a, b) = (measurements(first), measurements(last));
            let Some(motion) = integrate(&odo, first.t_us, last.t_us) else {
                continue;
            };
            let landmarks = a
                .iter()
                .filter_map(|(id, za)| {
                    Some(LandmarkPair {
                        first: *za,
                        second: *b.get(id)?,
                    })
                })
                .collect();
            pairs.push(FramePair {
                t_us: last.t_us,
                motion,
                landmarks,
            });
        }
        let start = std::time::Instant::now();
        let cal = calibrate(
            &pairs,
            &run.rig,
            &run.rig.nominal,
            &SolverSettings::default(),
        );
        let took = start.elapsed();
        let mut line = format!(
            "seed {seed}: {:?} {} it, {} residuals, chi2/dof {:.2}, {:?}:",
            cal.status, cal.iterations, cal.residuals, cal.reduced_chi2, took
        );
        let mut ok = true;
        for p in &run.rig.estimate {
            let (est, truth, sigma) = (cal.camera.get(*p), run.camera.get(*p), cal.sigma(*p));
            line += &format!(
                " {p} {est:.5} (truth {truth:.5}, err {:+.5}, sigma {sigma:.5})",
                est - truth
            );
            ok &= (est - truth).abs() <= 3.0 * sigma;
            if *p == Param::F {
                line += &format!(" [{:.3} %]", 100.0 * (est - truth) / truth);
            }
        }
        for u in cal.observability.unobservable() {
            line += &format!(" UNOBSERVABLE {}: {}", u.param, u.reason.unwrap_or(""));
        }
        inside += usize::from(ok);
        println!("{line}");
    }
    println!("error within 3 sigma in {inside} of {seeds} runs");
    ExitCode::SUCCESS
}
