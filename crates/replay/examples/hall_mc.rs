//! A seeded Monte Carlo over generated halls (issue 35, item 6): each seed draws a hall
//! ([`sim::hall::HallSpec::draw`]: aisles, lamp grid and height, sprinkler heads, beam corners,
//! tubes, radtan or fisheye lens, a real vehicle's errors), simulates its mapping drive through
//! the whole raw views, and replays it with no flags. Per hall: lamps and landmarks,
//! duplicates, lamps missed (in view of both raw images for 20 frames or more, unmapped),
//! unmatched landmarks, landmark and trajectory RMS, the landmarks within 3 sigma of their lamp
//! on every axis, the vehicle's parameters within 3 sigma, the baseline's error and sigma (the
//! map's scale), and the replay's speed; then the totals and the process's peak memory.
//!
//! `cargo run --release -p replay --example hall_mc -- HALLS [FIRST_SEED] [--field DEG] [--lens radtan|fisheye] [--margin M] [--outer-gain G] [--far-gain G] [--outer-birth S] [--smooth-near] [--frozen-points] [--no-follow-scale] [--fej-pose] [--fej-always | --no-fej-prediction] [--error-states] [--velocity-states] [--no-smoother] [--print-vehicle] [--relative-lost] [--reference] [--keep DIR] [--odometry-tau S [--tau-unstated]] [--noise-seed S]`
//! (`--field`: the navigator's field of use, `vslam_ekf::Settings::max_off_axis_deg`;
//! `--lens`: every hall through that lens; `--margin`: the local sessions' margin,
//! `vslam_ekf::Settings::local_margin_m`, 0 for the dense filter; `--smooth-near`: phase 2's
//! smoother over the landmarks near the vehicle, `nav::NavSettings::smooth_near_vehicle`;
//! `--fej-pose`: the pose's first-estimates Jacobians while it is lost
//! (`vslam_ekf::Settings::first_estimate_pose`); `--fej-always`: the prediction's
//! first-estimates column on every frame, whatever the heading's sigma
//! (`vslam_ekf::Settings::first_estimate_prediction_heading_sigma_rad` infinite; by default
//! only below 0.5 degrees); `--no-fej-prediction`: never
//! (`vslam_ekf::Settings::first_estimate_prediction` off);
//! `--relative-lost`: lost only relative to
//! the map around the pose as well (`nav::NavSettings::relative_lost`); `--error-states`:
//! the odometry's errors with memory held as states of the filter
//! (`vslam_ekf::Settings::odometry_error_states`); `--velocity-states`: the vehicle's
//! velocities as states too, the odometry their measurement
//! (`vslam_ekf::Settings::odometry_velocity_states`); `--no-smoother`: phase 2 without its
//! fixed-lag smoother (`nav::NavSettings::smooth_phase2` off); `--print-vehicle`: each hall's vehicle
//! parameters' errors and sigmas on stderr;
//! `--frozen-points`: linearisation points that follow the landmarks' estimates without the
//! covariance until they are known to 0.5 m and then stay (`vslam_ekf::Settings::follow_points`
//! off, the rule before 2026-12-06); `--no-follow-scale`: each update's correction in metres, not
//! re-taken in units of the baseline (`vslam_ekf::Settings::follow_scale` off, the filter before
//! 2026-12-07); `--reference`: each hall's frames also solved as one batch with the truth's association,
//! its landmark RMS and the navigator's ratio to it printed: a minute or more a hall). With `--keep DIR` each
//! hall's vehicle log is kept there as `hall-SEED.mcap` (to replay or profile one alone).
//! `--odometry-tau S` gives the odometry's errors that time constant of memory (issue 36), in
//! the simulator and in the log's rig; `--tau-unstated` leaves the rig silent about it.
//! `--noise-seed S`: every hall's noise drawn from seed `S` (the hall itself, its path and its
//! vehicle errors still from the hall's seed): one hall over many draws of its noise, to tell
//! a bias from one draw.
#![allow(clippy::print_stdout, clippy::print_stderr)] // a command-line tool

use std::process::ExitCode;
use std::time::Instant;

use replay::{NavSettings, Replayer};

#[path = "common/reference.rs"]
mod reference;
use rig_model::Param;

fn main() -> ExitCode {
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("hall_mc: {e}");
            ExitCode::FAILURE
        }
    }
}

/// The process's peak resident memory, MiB (Linux: `VmHWM` of /proc/self/status).
fn peak_mib() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib / 1024.0)
}

#[derive(Default)]
struct Totals {
    halls: usize,
    landmarks: usize,
    duplicates: usize,
    missed: usize,
    unmatched: usize,
    /// Unmatched landmarks whose nearest lamp is inside 3 sigma on every axis (off, but
    /// honestly so).
    unmatched_honest: usize,
    inside: usize,
    matched: usize,
    vehicle_inside: usize,
    vehicle_total: usize,
    data_s: f64,
    replay_s: f64,
    /// The navigator's landmark RMS over the batch reference's, per hall.
    ratios: Vec<f64>,
}

fn run() -> Result<(), String> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let usage = "usage: hall_mc HALLS [FIRST_SEED] [--field DEG] [--lens radtan|fisheye] [--margin M] [--outer-gain G] [--far-gain G] [--outer-birth S] [--smooth-near] [--frozen-points] [--no-follow-scale] [--fej-pose] [--fej-always | --no-fej-prediction] [--error-states] [--velocity-states] [--no-smoother] [--print-vehicle] [--relative-lost] [--reference] [--keep DIR] [--odometry-tau S [--tau-unstated]] [--noise-seed S]";
    let mut settings = NavSettings::default();
    let mut print_vehicle = false;
    let mut lens = None;
    let mut positional = Vec::new();
    let mut keep: Option<std::path::PathBuf> = None;
    let mut with_reference = false;
    let mut odometry_tau: Option<f64> = None;
    let mut tau_unstated = false;
    let mut noise_seed: Option<u64> = None;
    let mut rest = args.iter();
    while let Some(a) = rest.next() {
        match a.as_str() {
            "--field" => {
                let v = rest.next().ok_or(usage)?;
                settings.ekf.max_off_axis_deg =
                    v.parse().map_err(|_| format!("--field {v:?}: {usage}"))?;
            }
            "--margin" => {
                let v = rest.next().ok_or(usage)?;
                settings.ekf.local_margin_m =
                    v.parse().map_err(|_| format!("--margin {v:?}: {usage}"))?;
            }
            "--outer-gain" => {
                let v = rest.next().ok_or(usage)?;
                settings.ekf.outer_max_noise_gain = v
                    .parse()
                    .map_err(|_| format!("--outer-gain {v:?}: {usage}"))?;
            }
            "--outer-birth" => {
                let v = rest.next().ok_or(usage)?;
                settings.candidates.outer_birth_relative_sigma = v
                    .parse()
                    .map_err(|_| format!("--outer-birth {v:?}: {usage}"))?;
            }
            "--far-snr" => {
                let v = rest.next().ok_or(usage)?;
                settings.ekf.far_min_snr = v.parse().map_err(|_| usage.to_string())?;
            }
            "--far-gain" => {
                let v = rest.next().ok_or(usage)?;
                settings.ekf.far_max_noise_gain = v
                    .parse()
                    .map_err(|_| format!("--far-gain {v:?}: {usage}"))?;
            }
            "--smooth-near" => settings.smooth_near_vehicle = true,
            "--frozen-points" => settings.ekf.follow_points = false,
            "--no-follow-scale" => settings.ekf.follow_scale = false,
            "--fej-pose" => settings.ekf.first_estimate_pose = true,
            "--fej-always" => {
                settings.ekf.first_estimate_prediction_heading_sigma_rad = f64::INFINITY;
            }
            "--no-fej-prediction" => settings.ekf.first_estimate_prediction = false,
            "--error-states" => settings.ekf.odometry_error_states = true,
            "--velocity-states" => settings.ekf.odometry_velocity_states = true,
            "--no-smoother" => settings.smooth_phase2 = false,
            "--print-vehicle" => print_vehicle = true,
            "--relative-lost" => settings.relative_lost = true,
            "--odometry-tau" => {
                let v = rest.next().ok_or(usage)?;
                odometry_tau = Some(
                    v.parse()
                        .map_err(|_| format!("--odometry-tau {v:?}: {usage}"))?,
                );
            }
            "--tau-unstated" => tau_unstated = true,
            "--noise-seed" => {
                let v = rest.next().ok_or(usage)?;
                noise_seed = Some(
                    v.parse()
                        .map_err(|_| format!("--noise-seed {v:?}: {usage}"))?,
                );
            }
            "--reference" => with_reference = true,
            "--keep" => {
                keep = Some(std::path::PathBuf::from(rest.next().ok_or(usage)?));
            }
            "--lens" => {
                lens = Some(match rest.next().map(String::as_str) {
                    Some("radtan") => sim::hall::HallLens::Radtan,
                    Some("fisheye") => sim::hall::HallLens::Fisheye,
                    _ => return Err(usage.to_string()),
                });
            }
            _ => positional.push(a),
        }
    }
    let halls: u64 = positional
        .first()
        .ok_or(usage)?
        .parse()
        .map_err(|_| usage.to_string())?;
    let first: u64 = match positional.get(1) {
        Some(s) => s.parse().map_err(|_| usage.to_string())?,
        None => 1,
    };
    let mut totals = Totals::default();
    println!(
        "seed | hall | lamps seen | landmarks | duplicates | missed | unmatched | landmark RMS | inside 3 sigma | trajectory RMS | vehicle inside 3 sigma | baseline error (sigma) | speed"
    );
    for seed in first..first + halls {
        let mut spec = sim::hall::HallSpec::draw(seed);
        if let Some(lens) = lens {
            spec.lens = lens;
        }
        let mut scenario = sim::hall::scenario(&spec, seed).map_err(|e| e.to_string())?;
        if let Some(noise) = noise_seed {
            scenario = scenario.with_seed(noise);
        }
        if let Some(tau) = odometry_tau {
            let n = &mut scenario.spec.noise;
            (n.velocity_tau_s, n.yaw_rate_tau_s) = (tau, tau);
            if !tau_unstated {
                let r = &mut scenario.rig.noise;
                (r.velocity_tau, r.yaw_rate_tau) = (tau, tau);
            }
        }
        let run = sim::simulate(&scenario, sim::Mode::Fast).map_err(|e| e.to_string())?;
        let log = std::env::temp_dir().join(format!(
            "stereonav-hall-mc-{}-{seed}.mcap",
            std::process::id()
        ));
        run.write_log(&log).map_err(|e| e.to_string())?;
        let t0 = Instant::now();
        let replayer = Replayer::open(&log, None, &settings).map_err(|e| e.to_string())?;
        let mut sink = replay::ReplayCollector::default();
        let end = replayer
            .run(&mut sink, &mut |_, _| {})
            .map_err(|e| e.to_string())?;
        let took = t0.elapsed().as_secs_f64();
        match &keep {
            Some(dir) => {
                std::fs::rename(&log, dir.join(format!("hall-{seed}.mcap")))
                    .or_else(|_| {
                        std::fs::copy(&log, dir.join(format!("hall-{seed}.mcap"))).map(|_| ())
                    })
                    .map_err(|e| format!("--keep {}: {e}", dir.display()))?;
                std::fs::remove_file(&log).ok();
            }
            None => {
                std::fs::remove_file(&log).ok();
            }
        }
        let truth = end.truth.as_ref().ok_or("the log has no truth")?;
        // Each landmark against its nearest lamp within the match radius: inside 3 sigma on
        // every axis.
        let mut inside = 0;
        let mut matched = 0;
        for l in &end.landmarks {
            let nearest = run
                .landmarks
                .iter()
                .map(|lamp| {
                    let d = [
                        l.position[0] - lamp.position.x,
                        l.position[1] - lamp.position.y,
                        l.position[2] - lamp.position.z,
                    ];
                    (d, (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt())
                })
                .min_by(|a, b| a.1.total_cmp(&b.1));
            if let Some((d, dist)) = nearest {
                let within = (0..3).all(|k| d[k].abs() <= 3.0 * l.covariance[k][k].max(0.0).sqrt());
                if dist <= truth.match_radius {
                    matched += 1;
                    inside += usize::from(within);
                } else {
                    totals.unmatched_honest += usize::from(within);
                }
            }
        }
        let vehicle: Vec<(Param, f64)> = truth
            .camera
            .iter()
            .filter(|(p, _)| p.is_vehicle())
            .copied()
            .collect();
        let sigma = |p: Param| {
            end.final_camera
                .iter()
                .find(|e| e.param == p)
                .map_or(0.0, |e| e.sigma)
        };
        let estimated: Vec<&(Param, f64)> =
            vehicle.iter().filter(|(p, _)| sigma(*p) > 0.0).collect();
        if print_vehicle {
            for (p, err) in &estimated {
                eprintln!("  {p:?}: error {err:+.5}, sigma {:.5}", sigma(*p));
            }
        }
        let vehicle_inside = estimated
            .iter()
            .filter(|(p, err)| err.abs() <= 3.0 * sigma(*p))
            .count();
        let data_s = match (end.first_t_us, end.last_frame.as_ref()) {
            (Some(a), Some(b)) => (b.t_us - a) as f64 * 1e-6,
            _ => 0.0,
        };
        let seen = truth.landmarks_matched + truth.lamps_missed;
        // The map's scale: the baseline's error against the truth, with its sigma.
        let baseline = end.final_camera.iter().find(|e| e.param == Param::Baseline);
        println!(
            "{seed} | {} | {seen} | {} | {} | {} | {} | {:.1} mm | {inside} of {matched} | {:.1} mm | {vehicle_inside} of {} | {:+.3} mm ({:.3}) | {:.0}x",
            spec.describe(),
            end.landmarks.len(),
            truth.landmarks_duplicate,
            truth.lamps_missed,
            truth.landmarks_unmatched,
            truth.landmark_rms * 1e3,
            truth.ate_rms * 1e3,
            estimated.len(),
            baseline.map_or(f64::NAN, |b| (b.value - run.camera.baseline) * 1e3),
            baseline.map_or(f64::NAN, |b| b.sigma * 1e3),
            data_s / took
        );
        if with_reference {
            let decoded: std::collections::BTreeSet<u64> =
                sink.frames.iter().map(|f| f.t_us).collect();
            let batch = reference::solve(&scenario.rig, &run, &decoded, 500)
                .ok_or("the reference batch had no frame")?;
            let (rms, n) = reference::landmark_rms(&batch, &run);
            let ratio = truth.landmark_rms / rms;
            println!(
                "{seed} | batch reference: {:.1} mm over {n} lamps, baseline {:+.3} mm off ({:.3}); the navigator {ratio:.2}x",
                rms * 1e3,
                (batch.camera.baseline - run.camera.baseline) * 1e3,
                batch.sigma(Param::Baseline) * 1e3
            );
            totals.ratios.push(ratio);
        }
        totals.halls += 1;
        totals.landmarks += end.landmarks.len();
        totals.duplicates += truth.landmarks_duplicate;
        totals.missed += truth.lamps_missed;
        totals.unmatched += truth.landmarks_unmatched;
        totals.inside += inside;
        totals.matched += matched;
        totals.vehicle_inside += vehicle_inside;
        totals.vehicle_total += estimated.len();
        totals.data_s += data_s;
        totals.replay_s += took;
    }
    println!(
        "{} halls: {} landmarks, {} duplicates, {} lamps missed, {} unmatched ({} of them with their nearest lamp inside 3 sigma); {} of {} landmarks inside 3 sigma; vehicle parameters inside 3 sigma {} of {}; {:.0} s of data replayed in {:.1} s ({:.0}x); peak memory {}",
        totals.halls,
        totals.landmarks,
        totals.duplicates,
        totals.missed,
        totals.unmatched,
        totals.unmatched_honest,
        totals.inside,
        totals.matched,
        totals.vehicle_inside,
        totals.vehicle_total,
        totals.data_s,
        totals.replay_s,
        totals.data_s / totals.replay_s.max(1e-9),
        peak_mib().map_or_else(|| "unknown".to_string(), |m| format!("{m:.0} MiB"))
    );
    if !totals.ratios.is_empty() {
        totals.ratios.sort_by(f64::total_cmp);
        println!(
            "against the batch reference: median {:.2}x, worst {:.2}x",
            totals.ratios[totals.ratios.len() / 2],
            totals.ratios[totals.ratios.len() - 1]
        );
    }
    Ok(())
}
