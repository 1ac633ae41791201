//! The whole stack over many seeds of a scenario: each seed simulated to a vehicle log (the
//! board's byte stream, link faults and all), replayed, and scored against the truth.
//!
//! `cargo run --release -p replay --example replay_mc -- SCENARIO.toml RUNS [--skip-phase1] [--no-smoother] [--iterations N] [--consider-camera] [--velocity-noise MPS] [--detail] [--window FRAMES] [--max-landmarks N] [--smooth-near] [--odometry-tau S] [--tau-unstated] [--error-states] [--velocity-states]`
//!
//! Prints, over the seeds: when phase 1 handed over (time since the first frame, and since the
//! vehicle first moved), the whole method's errors (landmark RMS, trajectory RMS in the first
//! frame's world frame, every estimated camera parameter) and the 3-sigma counts (camera
//! parameters; landmarks, by their 3-D Mahalanobis distance against the 3-sigma-equivalent
//! chi-square bound 14.16, `eval::landmarks_against_lamps`). `--velocity-noise` overrides the scenario's odometry noise (and the
//! rig's noise model with it). `--odometry-tau` gives the odometry's errors (both axes) that
//! time constant of memory, in the simulator and in the rig file; `--tau-unstated` leaves the
//! rig file silent about the memory the scenario has (its time constants 0).
#![allow(clippy::print_stdout, clippy::print_stderr)] // a command-line tool

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use replay::{NavSettings, replay_log};
use rig_model::Param;

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
    let usage = "usage: replay_mc SCENARIO.toml RUNS [--skip-phase1] [--no-smoother] [--iterations N] [--consider-camera] [--velocity-noise MPS] [--detail] [--window FRAMES] [--max-landmarks N] [--smooth-near] [--odometry-tau S] [--tau-unstated] [--error-states] [--velocity-states]";
    let scenario_path = PathBuf::from(args.first().ok_or(usage)?);
    let runs: u64 = args
        .get(1)
        .map(|s| s.parse().map_err(|_| format!("RUNS {s:?} is not a count")))
        .transpose()?
        .unwrap_or(10);
    let mut settings = NavSettings::default();
    let mut velocity_noise: Option<f64> = None;
    let mut odometry_tau: Option<f64> = None;
    let mut tau_unstated = false;
    let mut detail = false;
    let mut rest = args.iter().skip(2);
    while let Some(a) = rest.next() {
        match a.as_str() {
            "--skip-phase1" => settings.skip_phase1 = true,
            "--no-smoother" => settings.smooth_phase2 = false,
            "--smooth-near" => settings.smooth_near_vehicle = true,
            "--iterations" => {
                let v = rest.next().ok_or("--iterations needs a value")?;
                settings.phase1.max_iterations =
                    v.parse().map_err(|_| format!("--iterations {v:?}"))?;
            }
            "--detail" => detail = true,
            "--max-landmarks" | "--window" => {
                let v = rest
                    .next()
                    .ok_or("--max-landmarks / --window need a value")?;
                let n: usize = v.parse().map_err(|_| format!("{a} {v:?}"))?;
                if a == "--window" {
                    settings.phase1.window = n;
                } else {
                    settings.phase1.max_landmarks = n;
                }
            }
            "--consider-camera" => {
                settings.ekf.camera_update = vslam_ekf::CameraUpdate::Consider;
            }
            "--velocity-noise" => {
                let v = rest.next().ok_or("--velocity-noise needs a value")?;
                velocity_noise = Some(v.parse().map_err(|_| format!("--velocity-noise {v:?}"))?);
            }
            "--odometry-tau" => {
                let v = rest.next().ok_or("--odometry-tau needs a value")?;
                odometry_tau = Some(v.parse().map_err(|_| format!("--odometry-tau {v:?}"))?);
            }
            "--tau-unstated" => tau_unstated = true,
            "--error-states" => settings.ekf.odometry_error_states = true,
            "--velocity-states" => settings.ekf.odometry_velocity_states = true,
            other => return Err(format!("unknown argument {other:?}; {usage}")),
        }
    }
    let mut scenario = sim::Scenario::load(&scenario_path).map_err(|e| e.to_string())?;
    if let Some(v) = velocity_noise {
        scenario.spec.noise.velocity_mps = v;
        scenario.rig.noise.velocity = v;
    }
    if let Some(tau) = odometry_tau {
        scenario.spec.noise.velocity_tau_s = tau;
        scenario.spec.noise.yaw_rate_tau_s = tau;
        scenario.rig.noise.velocity_tau = tau;
        scenario.rig.noise.yaw_rate_tau = tau;
    }
    if tau_unstated {
        scenario.rig.noise.velocity_tau = 0.0;
        scenario.rig.noise.yaw_rate_tau = 0.0;
    }
    let log = std::env::temp_dir().join(format!("replay-mc-{}.mcap", std::process::id()));
    let (mut lm, mut ate, mut switch_s, mut switch_motion_s) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let (mut missed, mut unmatched, mut matched, mut replay_s, mut data_s) = (0, 0, 0, 0.0, 0.0);
    let (mut lm_inside, mut lm_total) = (0usize, 0usize);
    let estimated: Vec<Param> = scenario.rig.estimate.clone();
    let mut cam_err: Vec<Vec<f64>> = vec![Vec::new(); estimated.len()];
    let mut cam_inside: Vec<usize> = vec![0; estimated.len()];
    // Consistency: per run the time-averaged and the final pose NEES, the final full-state
    // NEES and its degrees of freedom.
    let (mut nees_time, mut nees_final, mut nees_state, mut dof_state) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for seed in 0..runs {
        let sc = scenario.clone().with_seed(seed);
        let sim_run = sim::simulate(&sc, sim::Mode::Fast).map_err(|e| e.to_string())?;
        sim_run.write_log(&log).map_err(|e| e.to_string())?;
        let started = Instant::now();
        let r = replay_log(&log, None, &settings, &mut |_, _| {}).map_err(|e| e.to_string())?;
        replay_s += started.elapsed().as_secs_f64();
        let t0 = r.frames.first().map_or(0, |f| f.t_us);
        if let Some(b) = r.frames.last() {
            data_s += (b.t_us - t0) as f64 * 1e-6;
        }
        if let Some(ts) = r.phase_switch_t_us {
            switch_s.push((ts - t0) as f64 * 1e-6);
            let moving = sim_run
                .odometry_truth
                .iter()
                .find(|s| s.vx.abs() + s.vy.abs() > 1e-3 || s.vtheta.abs() > 1e-3)
                .map_or(t0, |s| s.t_us.max(t0));
            switch_motion_s.push(ts.saturating_sub(moving) as f64 * 1e-6);
        }
        let Some(t) = &r.truth else {
            return Err("the simulated log has no truth".into());
        };
        if let Some(c) = t.consistency {
            nees_time.push(c.pose_nees);
            nees_final.push(c.final_pose_nees);
            nees_state.push(c.state_nees);
            dof_state.push(c.state_dof as f64);
        }
        missed += t.lamps_missed;
        unmatched += t.landmarks_unmatched;
        matched += t.landmarks_matched;
        lm.push(t.landmark_rms);
        ate.push(t.ate_rms);
        for (k, p) in estimated.iter().enumerate() {
            let e = t
                .camera
                .iter()
                .find(|(q, _)| q == p)
                .map_or(f64::NAN, |(_, e)| *e);
            let sigma = r
                .final_camera
                .iter()
                .find(|c| c.param == *p)
                .map_or(f64::NAN, |c| c.sigma);
            if let Some(v) = cam_err.get_mut(k) {
                v.push(e.abs());
            }
            if e.abs() <= 3.0 * sigma
                && let Some(c) = cam_inside.get_mut(k)
            {
                *c += 1;
            }
        }
        if detail {
            let mut last = 0u64;
            for m in &r.maps {
                if m.t_us < last + 20_000_000 && !std::ptr::eq(m, r.maps.last().unwrap_or(m)) {
                    continue;
                }
                last = m.t_us;
                let mut mean = nalgebra::Vector3::zeros();
                let mut n = 0.0;
                let mut sz = 0.0;
                for l in &m.landmarks {
                    let p = nalgebra::Vector3::from(l.position);
                    if let Some(lamp) = sim_run
                        .landmarks
                        .iter()
                        .min_by(|a, b| (a.position - p).norm().total_cmp(&(b.position - p).norm()))
                        && (lamp.position - p).norm() < 0.2
                    {
                        mean += p - lamp.position;
                        sz += l.covariance[2][2].sqrt();
                        n += 1.0;
                    }
                }
                println!(
                    "seed {seed} t {:.1} s: {n} landmarks, mean error {:.1} {:.1} {:.1} mm, mean sigma z {:.1} mm",
                    (m.t_us - t0) as f64 * 1e-6,
                    1e3 * mean.x / n,
                    1e3 * mean.y / n,
                    1e3 * mean.z / n,
                    1e3 * sz / n
                );
            }
        }
        // Each landmark against its nearest lamp (within 10 cm): its 3-D Mahalanobis distance.
        let (near, inside) = eval::landmarks_against_lamps(
            r.landmarks.iter().map(|l| (l.position, l.covariance)),
            &sim_run.landmarks,
            0.1,
        );
        lm_total += near;
        lm_inside += inside;
    }
    std::fs::remove_file(&log).ok();
    println!(
        "{runs} seeds of {}{}: replayed {data_s:.0} s of data in {replay_s:.2} s ({:.0}x real time)",
        scenario_path.display(),
        velocity_noise.map_or(String::new(), |v| format!(" (odometry noise {v} m/s)")),
        data_s / replay_s
    );
    println!(
        "phase switch in {} of {runs}: after {:.1} s median, {:.1} s worst ({:.1} / {:.1} s after the vehicle first moved)",
        switch_s.len(),
        percentile(&mut switch_s.clone(), 0.5),
        percentile(&mut switch_s, 1.0),
        percentile(&mut switch_motion_s.clone(), 0.5),
        percentile(&mut switch_motion_s, 1.0),
    );
    println!(
        "landmarks: {matched} matched, {unmatched} not a lamp, {missed} lamps missed (over all runs); inside 3 sigma {lm_inside} of {lm_total} ({:.1} %)",
        100.0 * lm_inside as f64 / lm_total.max(1) as f64
    );
    println!(
        "landmark RMS: median {:.2} mm, worst {:.2} mm; trajectory error RMS (first frame's world): median {:.2} mm, worst {:.2} mm",
        1e3 * percentile(&mut lm.clone(), 0.5),
        1e3 * percentile(&mut lm, 1.0),
        1e3 * percentile(&mut ate.clone(), 0.5),
        1e3 * percentile(&mut ate, 1.0)
    );
    if !nees_final.is_empty() {
        let n = nees_final.len() as f64;
        let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
        let band = |dof: f64| {
            (
                vslam_ekf::chi2::chi2_quantile(0.025, dof) / dof,
                vslam_ekf::chi2::chi2_quantile(0.975, dof) / dof,
            )
        };
        let (lo, hi) = band(3.0 * n);
        let dof: f64 = dof_state.iter().sum();
        let (slo, shi) = band(dof);
        println!(
            "pose NEES at the last frame: mean {:.2} over {} runs (95 % band {:.2}-{:.2}); averaged over each run's phase-2 frames {:.2}",
            mean(&nees_final),
            nees_final.len(),
            3.0 * lo,
            3.0 * hi,
            mean(&nees_time)
        );
        println!(
            "full-state NEES per degree of freedom at the end: {:.3} ({} dof over the runs, 95 % band {:.3}-{:.3})",
            nees_state.iter().sum::<f64>() / dof,
            dof,
            slo,
            shi
        );
    }
    for (k, p) in estimated.iter().enumerate() {
        let (scale, unit) = p.display_unit();
        let v = cam_err.get(k).cloned().unwrap_or_default();
        println!(
            "{p}: error median {:.3} {unit}, worst {:.3} {unit}; inside 3 sigma in {} of {}",
            scale * percentile(&mut v.clone(), 0.5),
            scale * percentile(&mut v.clone(), 1.0),
            cam_inside.get(k).copied().unwrap_or(0),
            v.len()
        );
    }
    Ok(())
}
