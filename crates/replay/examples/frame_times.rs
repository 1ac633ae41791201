//! The navigator's cost per frame (issue 35: each frame's cost bounded): a log read into
//! memory first, then fed as the replay feeds it (odometry up to
//! [`nav::ODOMETRY_LOOKAHEAD_US`] past each frame first), each `Navigator::push_frame` timed
//! on its own, and `Navigator::finish` too. Prints the mean, the percentiles and the largest,
//! the frames that took longest with their landmark count, and the real-time factor of the
//! navigator alone (the replay adds the log's decoding and the outputs).
//!
//! `cargo run --release -p replay --example frame_times -- LOG.mcap [RIG.toml]`
#![allow(clippy::print_stdout, clippy::print_stderr)] // a command-line tool

use std::process::ExitCode;
use std::time::Instant;

use nav::{NavSettings, Navigator};

fn main() -> ExitCode {
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("frame_times: {e}");
            ExitCode::FAILURE
        }
    }
}

fn percentile(sorted: &[f64], q: f64) -> f64 {
    #[allow(
        clippy::cast_possible_truncation,
        clippy::cast_sign_loss,
        clippy::cast_precision_loss
    )]
    let i = ((sorted.len().saturating_sub(1)) as f64 * q).round() as usize;
    sorted.get(i).copied().unwrap_or(f64::NAN)
}

/// The value after `flag` in `args`, parsed, both taken out of `args`.
fn take_value<T: std::str::FromStr>(
    args: &mut Vec<String>,
    flag: &str,
    usage: &str,
) -> Result<Option<T>, String> {
    let Some(k) = args.iter().position(|a| a == flag) else {
        return Ok(None);
    };
    let v = args.get(k + 1).ok_or(usage)?;
    let parsed = v.parse().map_err(|_| format!("{flag} {v:?}: {usage}"))?;
    args.drain(k..k + 2);
    Ok(Some(parsed))
}

fn run() -> Result<(), String> {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    let usage = "usage: frame_times LOG.mcap [RIG.toml] [--far-gain G] [--far-budget N]";
    let mut settings = NavSettings::default();
    if let Some(v) = take_value(&mut args, "--far-gain", usage)? {
        settings.ekf.far_max_noise_gain = v;
    }
    if let Some(v) = take_value(&mut args, "--far-budget", usage)? {
        settings.ekf.far_updates_per_frame = v;
    }
    let log = args.first().ok_or(usage)?;
    let rig = match args.get(1) {
        Some(path) => {
            let text = std::fs::read_to_string(path).map_err(|e| format!("{path}: {e}"))?;
            Some(rig_model::config::Rig::from_toml_str(&text, path).map_err(|e| e.to_string())?)
        }
        None => None,
    };
    let input =
        replay::read_vehicle_log(std::path::Path::new(log), rig).map_err(|e| e.to_string())?;
    let mut nav = Navigator::new(input.rig.clone(), settings).map_err(|e| e.to_string())?;
    let mut odometry = input.odometry.iter().peekable();
    // (milliseconds, frame index, landmarks after it)
    let mut times: Vec<(f64, usize, usize)> = Vec::with_capacity(input.frames.len());
    let start = Instant::now();
    for (k, f) in input.frames.iter().enumerate() {
        let ahead = f.t_us.saturating_add(nav::ODOMETRY_LOOKAHEAD_US);
        while let Some(s) = odometry.next_if(|s| s.t_us <= ahead) {
            nav.push_odometry(*s).map_err(|e| e.to_string())?;
        }
        let t0 = Instant::now();
        nav.push_frame(f.t_us, &f.left, &f.right)
            .map_err(|e| e.to_string())?;
        let ms = t0.elapsed().as_secs_f64() * 1e3;
        let landmarks = nav.ekf().map_or(0, vslam_ekf::Ekf::landmark_count);
        times.push((ms, k, landmarks));
    }
    let t0 = Instant::now();
    nav.finish().map_err(|e| e.to_string())?;
    let finish_ms = t0.elapsed().as_secs_f64() * 1e3;
    let total = start.elapsed().as_secs_f64();
    let mut sorted: Vec<f64> = times.iter().map(|t| t.0).collect();
    sorted.sort_by(f64::total_cmp);
    #[allow(clippy::cast_precision_loss)]
    let mean = sorted.iter().sum::<f64>() / sorted.len().max(1) as f64;
    let span_s = match (input.frames.first(), input.frames.last()) {
        (Some(a), Some(b)) => (b.t_us - a.t_us) as f64 * 1e-6,
        _ => 0.0,
    };
    println!(
        "{log}: {} frames ({span_s:.1} s of data); navigator {total:.2} s ({:.0}x real time), finish {finish_ms:.1} ms",
        times.len(),
        span_s / total
    );
    println!(
        "per frame, ms: mean {mean:.3}, p50 {:.3}, p90 {:.3}, p99 {:.3}, p99.9 {:.3}, largest {:.3}",
        percentile(&sorted, 0.5),
        percentile(&sorted, 0.9),
        percentile(&sorted, 0.99),
        percentile(&sorted, 0.999),
        sorted.last().copied().unwrap_or(f64::NAN)
    );
    if let Some(ekf) = nav.ekf() {
        let h = ekf.health();
        println!(
            "filter: {} updates, {} local sessions, {} settled, state {}",
            h.updates,
            h.local_sessions,
            h.local_settles,
            ekf.state_len()
        );
    }
    let stats = nav.stats();
    println!(
        "smoother: {} solves, {} restarts, {} reseeds refused ({} inconsistent)",
        stats.phase2_solves,
        stats.phase2_smoother_restarts,
        stats.phase2_reseeds_refused,
        stats.phase2_reseeds_inconsistent
    );
    // Where along the log the time goes: mean per block of 500 frames.
    for block in times.chunks(500) {
        let (first, last) = (block[0], block[block.len() - 1]);
        #[allow(clippy::cast_precision_loss)]
        let mean = block.iter().map(|t| t.0).sum::<f64>() / block.len() as f64;
        println!(
            "  frames {}-{}: mean {mean:.3} ms, {} to {} landmarks",
            first.1, last.1, first.2, last.2
        );
    }
    times.sort_by(|a, b| b.0.total_cmp(&a.0));
    for (ms, k, landmarks) in times.iter().take(5) {
        println!("  frame {k}: {ms:.2} ms, {landmarks} landmarks after it");
    }
    Ok(())
}
