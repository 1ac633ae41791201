//! Phase 2 Monte Carlo on a scenario: accuracy, honesty of the sigmas and consistency (NEES,
//! NIS) over many seeds, with optional gross outliers:
//! `cargo run --release -p eval --example phase2_mc -- fixtures/scenarios/paper-experiment.toml 50`
//! `cargo run --release -p eval --example phase2_mc -- fixtures/scenarios/paper-experiment.toml 1000 0.05 200`
//! (arguments: scenario, runs, outlier fraction, frames per run).
#![allow(clippy::print_stdout, clippy::print_stderr)] // a command-line tool

use std::path::Path;
use std::process::ExitCode;
use std::time::Instant;

use eval::{RunSettings, monte_carlo};

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some(path) = args.first() else {
        eprintln!("usage: phase2_mc SCENARIO.toml [RUNS] [OUTLIER_FRACTION] [FRAMES]");
        return ExitCode::FAILURE;
    };
    let runs: u64 = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(20);
    let settings = RunSettings {
        outlier_fraction: args.get(2).and_then(|s| s.parse().ok()).unwrap_or(0.0),
        max_frames: args.get(3).and_then(|s| s.parse().ok()),
        ..RunSettings::default()
    };
    let scenario = match sim::Scenario::load(Path::new(path)) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("{e}");
            return ExitCode::FAILURE;
        }
    };
    let started = Instant::now();
    let summary = match monte_carlo(&scenario, 0..runs, &settings) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("{e}");
            return ExitCode::FAILURE;
        }
    };
    let took = started.elapsed();
    let mut rms: Vec<f64> = summary
        .runs
        .iter()
        .map(eval::RunResult::landmark_rms)
        .collect();
    rms.sort_by(f64::total_cmp);
    let worst_rms = rms.last().copied().unwrap_or(f64::NAN);
    println!(
        "{} runs of {} in {took:.2?} ({:.1} ms a run)",
        summary.runs.len(),
        path,
        took.as_secs_f64() * 1e3 / summary.runs.len().max(1) as f64
    );
    let squared: Vec<f64> = summary
        .runs
        .iter()
        .flat_map(|r| r.landmarks.iter().map(|l| l.error.norm_squared()))
        .collect();
    let overall = (squared.iter().sum::<f64>() / squared.len().max(1) as f64).sqrt();
    println!(
        "landmark RMS error: over all runs {:.2} mm; per run median {:.2} mm, worst {:.2} mm",
        1e3 * overall,
        1e3 * rms.get(rms.len() / 2).copied().unwrap_or(f64::NAN),
        1e3 * worst_rms
    );
    if let Some(first) = summary.runs.first() {
        for c in &first.camera {
            let p = c.param;
            let errors: Vec<f64> = summary
                .runs
                .iter()
                .filter_map(|r| r.camera_result(p).map(eval::CameraResult::error))
                .collect();
            let worst = errors.iter().fold(0.0_f64, |m, e| m.max(e.abs()));
            let rms =
                (errors.iter().map(|e| e * e).sum::<f64>() / errors.len().max(1) as f64).sqrt();
            let sigma: f64 = summary
                .runs
                .iter()
                .filter_map(|r| r.camera_result(p).map(|c| c.sigma))
                .sum::<f64>()
                / summary.runs.len().max(1) as f64;
            println!("{p}: error RMS {rms:.3e}, worst {worst:.3e}, mean sigma {sigma:.3e}");
        }
    }
    let n = summary.runs.len();
    println!(
        "inside 3 sigma (every landmark and camera parameter): {} of {n}",
        summary.within_3_sigma
    );
    println!(
        "finite and positive definite throughout: {} of {n}",
        summary.healthy
    );
    let band = |b: &eval::Banded| format!("{:.3} (95 % band {:.3}..{:.3})", b.value, b.low, b.high);
    println!(
        "pose NEES (3 dof), mean: {}; frames inside their band: {:.1} %",
        band(&summary.pose_nees),
        100.0 * summary.pose_nees_frames_inside
    );
    println!(
        "full-state NEES per dof, mean: {}; frames inside their band: {:.1} %",
        band(&summary.state_nees_per_dof),
        100.0 * summary.state_nees_frames_inside
    );
    println!("NIS (4 dof), mean: {}", band(&summary.nis));
    let outliers: u64 = summary.runs.iter().map(|r| r.outliers).sum();
    let leaked: u64 = summary.runs.iter().map(|r| r.outliers_accepted).sum();
    let rejected: u64 = summary.runs.iter().map(|r| r.rejected).sum();
    let refused: u64 = summary.runs.iter().map(|r| r.refused_updates).sum();
    let missing: usize = summary.runs.iter().map(|r| r.lamps_missing.len()).sum();
    println!(
        "outliers mixed in {outliers}, accepted by the gate {leaked}; observations rejected {rejected}; updates refused {refused}; lamps never mapped {missing}"
    );
    ExitCode::SUCCESS
}
