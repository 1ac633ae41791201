//! What the navigator does on a real log, frame by frame: the estimated camera parameters with
//! their sigmas, the map's size and median depth, the pose, the observations accepted and
//! rejected. A diagnostic for logs without truth (docs/real-images.md).
//!
//! `cargo run --release -p replay --example real_log_probe -- LOG.mcap RIG.toml [--skip-phase1] [--pixel-sigma PX] [--every N]`
#![allow(clippy::print_stdout, clippy::print_stderr)] // a command-line tool

use std::process::ExitCode;

use replay::{NavSettings, replay_log};

fn main() -> ExitCode {
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("real_log_probe: {e}");
            ExitCode::FAILURE
        }
    }
}

fn run() -> Result<(), String> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let usage =
        "usage: real_log_probe LOG.mcap RIG.toml [--skip-phase1] [--pixel-sigma PX] [--every N]";
    let log = args.first().ok_or(usage)?;
    let rig_path = args.get(1).ok_or(usage)?;
    let text = std::fs::read_to_string(rig_path).map_err(|e| format!("{rig_path}: {e}"))?;
    let mut rig =
        rig_model::config::Rig::from_toml_str(&text, rig_path).map_err(|e| e.to_string())?;
    let mut settings = NavSettings::default();
    let mut every = 5usize;
    let mut rest = args.iter().skip(2);
    while let Some(a) = rest.next() {
        match a.as_str() {
            "--skip-phase1" => settings.skip_phase1 = true,
            "--pixel-sigma" => {
                let v = rest.next().ok_or("--pixel-sigma needs a value")?;
                rig.noise.pixel = v.parse().map_err(|_| format!("--pixel-sigma {v:?}"))?;
            }
            "--every" => {
                let v = rest.next().ok_or("--every needs a value")?;
                every = v.parse().map_err(|_| format!("--every {v:?}"))?;
            }
            other => return Err(format!("unknown argument {other:?}; {usage}")),
        }
    }
    let r = replay_log(log, Some(rig), &settings, &mut |_, _| {}).map_err(|e| e.to_string())?;
    let t0 = r.frames.first().map_or(0, |f| f.t_us);
    for (k, f) in r.frames.iter().enumerate() {
        if k % every.max(1) != 0 && k + 1 != r.frames.len() {
            continue;
        }
        let camera = r.camera.iter().rfind(|c| c.t_us <= f.t_us);
        let params: Vec<String> = camera
            .map(|c| {
                c.params
                    .iter()
                    .filter(|p| p.sigma > 0.0)
                    .map(|p| format!("{} {:.5} +- {:.5}", p.param, p.value, p.sigma))
                    .collect()
            })
            .unwrap_or_default();
        let map = r.maps.iter().rfind(|m| m.t_us <= f.t_us);
        let mut depths: Vec<f64> = map
            .map(|m| m.landmarks.iter().map(|l| l.position[2]).collect())
            .unwrap_or_default();
        depths.sort_by(f64::total_cmp);
        let median = depths.get(depths.len() / 2).copied().unwrap_or(f64::NAN);
        println!(
            "t {:5.2} s {:?}: {} landmarks (map median z {:.3} m), {} accepted, {} rejected, pose {:+.4} {:+.4} {:+.3} deg; {}",
            (f.t_us - t0) as f64 * 1e-6,
            f.phase,
            f.landmarks,
            median,
            f.observed.len(),
            f.rejected,
            f.pose[0],
            f.pose[1],
            f.pose[2].to_degrees(),
            params.join(", ")
        );
    }
    for w in &r.warnings {
        println!("warning: {w}");
    }
    Ok(())
}
