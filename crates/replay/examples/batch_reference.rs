//! How close the navigator's final map comes to what the data allow: each seed of a scenario
//! is simulated to a vehicle log and replayed (the whole method, no flags), and the same
//! frames are solved as one batch (every pose, lamp and estimated camera parameter at once,
//! Levenberg-Marquardt on every frame's pixels and the odometry, `selfcal::smoother` never
//! handing over) with the association taken from the truth: each feature the simulator made
//! of a lamp is that lamp's observation, clutter is left out.
//!
//! `cargo run --release -p replay --example batch_reference -- SCENARIO.toml RUNS [--velocity-noise MPS] [--window FRAMES] [--solve-every FRAMES]`
//!
//! Prints, over the seeds, the landmark RMS of both (over every run's landmarks matched to a
//! lamp) and their ratio, and the baseline error of both.
#![allow(clippy::print_stdout, clippy::print_stderr)] // a command-line tool

use std::path::PathBuf;
use std::process::ExitCode;

use replay::{NavSettings, replay_log};
use rig_model::Param;

#[path = "common/reference.rs"]
mod reference;

fn main() -> ExitCode {
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("batch_reference: {e}");
            ExitCode::FAILURE
        }
    }
}

fn run() -> Result<(), String> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let usage = "usage: batch_reference SCENARIO.toml RUNS [--velocity-noise MPS] [--window FRAMES] [--solve-every FRAMES]";
    let scenario_path = PathBuf::from(args.first().ok_or(usage)?);
    let runs: u64 = args
        .get(1)
        .map(|s| s.parse().map_err(|_| format!("RUNS {s:?} is not a count")))
        .transpose()?
        .unwrap_or(10);
    let mut velocity_noise: Option<f64> = None;
    let mut nav = NavSettings::default();
    let mut solve_every = 20;
    let mut rest = args.iter().skip(2);
    while let Some(a) = rest.next() {
        match a.as_str() {
            "--solve-every" => {
                let v = rest.next().ok_or("--solve-every needs a value")?;
                solve_every = v.parse().map_err(|_| format!("--solve-every {v:?}"))?;
            }
            "--window" => {
                let v = rest.next().ok_or("--window needs a value")?;
                nav.phase1.window = v.parse().map_err(|_| format!("--window {v:?}"))?;
            }
            "--velocity-noise" => {
                let v = rest.next().ok_or("--velocity-noise needs a value")?;
                velocity_noise = Some(v.parse().map_err(|_| format!("--velocity-noise {v:?}"))?);
            }
            other => return Err(format!("unknown argument {other:?}; {usage}")),
        }
    }
    let mut scenario = sim::Scenario::load(&scenario_path).map_err(|e| e.to_string())?;
    if let Some(v) = velocity_noise {
        scenario.spec.noise.velocity_mps = v;
        scenario.rig.noise.velocity = v;
    }
    let log = std::env::temp_dir().join(format!("batch-ref-{}.mcap", std::process::id()));
    let (mut nav_sq, mut nav_n, mut ref_sq, mut ref_n) = (0.0, 0usize, 0.0, 0usize);
    let (mut nav_b, mut ref_b) = (Vec::new(), Vec::new());
    let mut ratios = Vec::new();
    for seed in 0..runs {
        let sc = scenario.clone().with_seed(seed);
        let sim_run = sim::simulate(&sc, sim::Mode::Fast).map_err(|e| e.to_string())?;
        sim_run.write_log(&log).map_err(|e| e.to_string())?;
        let r = replay_log(&log, None, &nav, &mut |_, _| {}).map_err(|e| e.to_string())?;
        let lamp_near = |p: [f64; 3]| {
            let p = nalgebra::Vector3::from(p);
            sim_run
                .landmarks
                .iter()
                .map(|l| (l.position - p).norm())
                .min_by(f64::total_cmp)
                .filter(|d| *d <= 0.1)
        };
        let (mut s_nav, mut n_nav) = (0.0, 0usize);
        for l in &r.landmarks {
            if std::env::var_os("BATCH_REF_DEBUG").is_some() {
                let p = nalgebra::Vector3::from(l.position);
                if let Some(lamp) = sim_run
                    .landmarks
                    .iter()
                    .min_by(|a, b| (a.position - p).norm().total_cmp(&(b.position - p).norm()))
                {
                    let e = 1e3 * (p - lamp.position);
                    println!(
                        "  nav lamp {}: {:+.2} {:+.2} {:+.2} mm ({} obs)",
                        lamp.id, e.x, e.y, e.z, l.observations
                    );
                }
            }
            if let Some(d) = lamp_near(l.position) {
                s_nav += d * d;
                n_nav += 1;
            }
        }
        // The reference: the frames the replay decoded, associated by the truth.
        let decoded: std::collections::BTreeSet<u64> = r.frames.iter().map(|f| f.t_us).collect();
        let handover = reference::solve(&sc.rig, &sim_run, &decoded, solve_every)
            .ok_or("the reference batch had no frame")?;
        for p in Param::VEHICLE {
            if handover.estimated.contains(&p) {
                let (scale, unit) = p.display_unit();
                let sigma = handover.sigma(p);
                println!(
                    "seed {seed}: reference {} error {:+.3} {unit} (sigma {:.3})",
                    p.name(),
                    scale * (handover.camera.get(p) - sim_run.camera.get(p)),
                    scale * sigma
                );
            }
        }
        if std::env::var_os("BATCH_REF_DEBUG").is_some() {
            for l in &handover.landmarks {
                if let Some(lamp) = reference::lamp_of(l, &sim_run) {
                    let e = 1e3 * (l.position - lamp.position);
                    println!(
                        "  ref lamp {}: {:+.2} {:+.2} {:+.2} mm ({} obs)",
                        lamp.id, e.x, e.y, e.z, l.observations
                    );
                }
            }
        }
        let (rms_ref, n_ref) = reference::landmark_rms(&handover, &sim_run);
        #[allow(clippy::cast_precision_loss)]
        let s_ref = rms_ref * rms_ref * n_ref as f64;
        let truth_b = sim_run.camera.baseline;
        nav_b.push(
            r.final_camera
                .iter()
                .find(|c| c.param == Param::Baseline)
                .map_or(f64::NAN, |c| c.value - truth_b),
        );
        ref_b.push(handover.camera.baseline - truth_b);
        let (rn, rr) = (
            (s_nav / n_nav.max(1) as f64).sqrt(),
            (s_ref / n_ref.max(1) as f64).sqrt(),
        );
        ratios.push(rn / rr);
        println!(
            "seed {seed}: navigator {:.2} mm ({n_nav} landmarks), reference {:.2} mm ({n_ref}), ratio {:.2}; baseline error {:+.3} / {:+.3} mm",
            1e3 * rn,
            1e3 * rr,
            rn / rr,
            1e3 * nav_b.last().copied().unwrap_or(f64::NAN),
            1e3 * ref_b.last().copied().unwrap_or(f64::NAN),
        );
        nav_sq += s_nav;
        nav_n += n_nav;
        ref_sq += s_ref;
        ref_n += n_ref;
    }
    std::fs::remove_file(&log).ok();
    let rms = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len().max(1) as f64).sqrt();
    let (nav, reference) = (
        (nav_sq / nav_n.max(1) as f64).sqrt(),
        (ref_sq / ref_n.max(1) as f64).sqrt(),
    );
    ratios.sort_by(f64::total_cmp);
    println!(
        "{runs} seeds of {}{}: landmark RMS over all runs: navigator {:.2} mm, batch reference {:.2} mm, ratio {:.2} (per run: median {:.2}, worst {:.2}); baseline error RMS {:.3} / {:.3} mm",
        scenario_path.display(),
        velocity_noise.map_or(String::new(), |v| format!(" (odometry noise {v} m/s)")),
        1e3 * nav,
        1e3 * reference,
        nav / reference,
        ratios.get(ratios.len() / 2).copied().unwrap_or(f64::NAN),
        ratios.last().copied().unwrap_or(f64::NAN),
        1e3 * rms(&nav_b),
        1e3 * rms(&ref_b),
    );
    Ok(())
}
