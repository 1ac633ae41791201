//! The whole stack over many seeds of a scenario: each seed simulated to a vehicle log (the
//! board's byte stream, link faults and all), replayed, and scored against the truth.
//!
//! `cargo run --release -p replay --example replay_mc -- SCENARIO.toml RUNS [--skip-phase1] [--stride N] [--consider-camera]`
#![allow(clippy::print_stdout, clippy::print_stderr)] // a command-line tool

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use calib::Param;
use replay::{NavSettings, replay_log};

fn main() -> ExitCode {
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("replay_mc: {e}");
            ExitCode::FAILURE
        }
    }
}

fn percentile(v: &mut [f64], q: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    let i = ((v.len().saturating_sub(1)) as f64 * q).round() as usize;
    v.get(i).copied().unwrap_or(f64::NAN)
}

fn run() -> Result<(), String> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let usage =
        "usage: replay_mc SCENARIO.toml RUNS [--skip-phase1] [--stride N] [--consider-camera]";
    let scenario_path = PathBuf::from(args.first().ok_or(usage)?);
    let runs: u64 = args
        .get(1)
        .map(|s| s.parse().map_err(|_| format!("RUNS {s:?} is not a count")))
        .transpose()?
        .unwrap_or(10);
    let mut settings = NavSettings::default();
    let mut rest = args.iter().skip(2);
    while let Some(a) = rest.next() {
        match a.as_str() {
            "--skip-phase1" => settings.skip_phase1 = true,
            "--consider-camera" => {
                settings.ekf.camera_update = vslam_ekf::CameraUpdate::Consider;
            }
            "--stride" => {
                let v = rest.next().ok_or("--stride needs a value")?;
                settings.pairs.stride = v.parse().map_err(|_| format!("--stride {v:?}"))?;
            }
            other => return Err(format!("unknown argument {other:?}; {usage}")),
        }
    }
    let scenario = sim::Scenario::load(&scenario_path).map_err(|e| e.to_string())?;
    let log = std::env::temp_dir().join(format!("replay-mc-{}.mcap", std::process::id()));
    let (mut lm, mut lm_aligned, mut ate, mut b_err, mut b_norm) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let (mut missed, mut unmatched, mut switched, mut replay_s, mut data_s) = (0, 0, 0, 0.0, 0.0);
    for seed in 0..runs {
        let sc = scenario.clone().with_seed(seed);
        let sim_run = sim::simulate(&sc, sim::Mode::Fast).map_err(|e| e.to_string())?;
        sim_run.write_log(&log).map_err(|e| e.to_string())?;
        let started = Instant::now();
        let r = replay_log(&log, None, &settings, &mut |_, _| {}).map_err(|e| e.to_string())?;
        replay_s += started.elapsed().as_secs_f64();
        if let (Some(a), Some(b)) = (r.frames.first(), r.frames.last()) {
            data_s += (b.t_us - a.t_us) as f64 * 1e-6;
        }
        switched += usize::from(r.phase_switch_t_us.is_some());
        let Some(t) = &r.truth else {
            return Err("the simulated log has no truth".into());
        };
        missed += t.lamps_missed;
        unmatched += t.landmarks_unmatched;
        lm.push(t.landmark_rms);
        lm_aligned.push(t.landmark_rms_aligned);
        ate.push(t.ate_rms);
        if let Some((_, e)) = t.camera.iter().find(|(p, _)| *p == Param::Baseline) {
            b_err.push(e.abs());
            let sigma = r
                .final_camera
                .iter()
                .find(|c| c.param == Param::Baseline)
                .map_or(f64::NAN, |c| c.sigma);
            if sigma > 0.0 {
                b_norm.push(e.abs() / sigma);
            }
        }
    }
    std::fs::remove_file(&log).ok();
    let inside3 = b_norm.iter().filter(|v| **v <= 3.0).count();
    println!(
        "{runs} seeds of {}: replayed {data_s:.0} s of data in {replay_s:.2} s ({:.0}x real time)",
        scenario_path.display(),
        data_s / replay_s
    );
    println!(
        "phase switch in {switched} of {runs}; lamps missed {missed}, landmarks not a lamp {unmatched} (over all runs)"
    );
    println!(
        "landmark RMS: median {:.2} mm, worst {:.2} mm; after planar alignment median {:.2} mm, worst {:.2} mm",
        1e3 * percentile(&mut lm, 0.5),
        1e3 * percentile(&mut lm, 1.0),
        1e3 * percentile(&mut lm_aligned, 0.5),
        1e3 * percentile(&mut lm_aligned, 1.0)
    );
    println!(
        "trajectory error RMS: median {:.2} mm, worst {:.2} mm",
        1e3 * percentile(&mut ate, 0.5),
        1e3 * percentile(&mut ate, 1.0)
    );
    println!(
        "baseline error: median {:.3} mm, worst {:.3} mm; inside 3 sigma in {inside3} of {}",
        1e3 * percentile(&mut b_err, 0.5),
        1e3 * percentile(&mut b_err, 1.0),
        b_norm.len()
    );
    Ok(())
}
