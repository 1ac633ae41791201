//! Phase 1 on a simulated scenario over several seeds, associating features by the simulator's
//! lamp ids (the navigator's association is not in this experiment):
//! `cargo run --release -p eval --example phase1_accuracy -- fixtures/scenarios/paper-calibration.toml 20 [STRIDE] [disjoint|interleaved]`.
#![allow(clippy::print_stdout, clippy::print_stderr)] // a command-line tool

use std::path::Path;
use std::process::ExitCode;

use rig_model::Param;
use selfcal::solve::{SolverSettings, calibrate};

fn main() -> ExitCode {
    let mut args = std::env::args().skip(1);
    let Some(path) = args.next() else {
        eprintln!("usage: phase1_accuracy SCENARIO.toml [SEEDS] [STRIDE] [disjoint|interleaved]");
        return ExitCode::FAILURE;
    };
    let seeds: u64 = args.next().and_then(|s| s.parse().ok()).unwrap_or(5);
    // Frames apart in each pair: more motion, more parallax per pair.
    let stride: usize = args.next().and_then(|s| s.parse().ok()).unwrap_or(1);
    // Which frames are paired (track::PairingScheme).
    let scheme = match args.next() {
        None => track::PairingScheme::Disjoint,
        Some(name) => match track::PairingScheme::from_name(&name) {
            Some(s) => s,
            None => {
                eprintln!("unknown pairing scheme {name:?}: use disjoint or interleaved");
                return ExitCode::FAILURE;
            }
        },
    };
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
        let pairs = eval::phase1::frame_pairs_by_lamp_with(&run, scheme, stride);
        let start = std::time::Instant::now();
        let cal = calibrate(
            &pairs,
            &run.rig,
            &run.rig.nominal,
            &SolverSettings::default(),
        );
        let took = start.elapsed();
        let mut line = format!(
            "seed {seed}: {} {} pairs, {:?} {} it, {} residuals, chi2/dof {:.2}, {:?}:",
            scheme.name(),
            pairs.len(),
            cal.status,
            cal.iterations,
            cal.residuals,
            cal.reduced_chi2,
            took
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
