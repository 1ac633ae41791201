//! `stereonav replay LOG.mcap [--rig RIG.toml] [--out EST.mcap] [--summary SUMMARY.json]
//! [--trajectory TRAJ.csv] [--trajectory-tum TRAJ.tum] [--truth-tum TRUTH.tum] [--save-map MAP]
//! [--skip-phase1] [--phase1-frames N] [--consider-camera]`: the whole stack on a vehicle log
//! (vehicle-interfaces.md section 5; `replay::Replayer`).
//!
//! The replay streams: `EST.mcap` and `TRAJ.csv` are written as the frames come and
//! `SUMMARY.json` at the end, in memory bounded by the map whatever the log's length.
//!
//! Prints a short human summary on stdout (frames, the phase switch, the map, the camera
//! parameters, the final pose and, when the log has simulator truth, the errors); warnings
//! (a log cut short, phase 1 never stable) go to stderr, one line each. A progress bar is drawn
//! on stderr when it is a terminal, nothing otherwise.

use std::fmt::Write as _;
use std::io::{self, Write};
use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use replay::{NavSettings, OutputFiles, ReplayEnd, Replayer};
use rig_model::{Param, Rig};

use crate::progress::ByteProgress;
use selfcal::smoother::SmootherSettings;

/// Arguments of `stereonav replay`.
#[derive(Debug, clap::Args)]
pub(crate) struct Args {
    /// The vehicle log (MCAP, vehicle-interfaces.md section 4), or a ROS 2 bag of camera images
    /// and wheel odometry with --left, --right and --odom (4.1).
    #[arg(value_name = "LOG.mcap")]
    log: PathBuf,
    #[command(flatten)]
    topics: crate::topics::TopicArgs,
    /// The rig file (TOML, section 3); without it, the log's /rig message.
    #[arg(long, value_name = "RIG.toml")]
    rig: Option<PathBuf>,
    /// Write the estimates (trajectory, landmarks with their uncertainty, camera parameters over
    /// time) as MCAP, in Foxglove's well-known schemas where one fits.
    #[arg(long, value_name = "EST.mcap")]
    out: Option<PathBuf>,
    /// Write the summary as JSON.
    #[arg(long, value_name = "SUMMARY.json")]
    summary: Option<PathBuf>,
    /// Write the trajectory as CSV (`t_us,x,y,theta`, a row per stereo frame).
    #[arg(long, value_name = "TRAJ.csv")]
    trajectory: Option<PathBuf>,
    /// Write the trajectory in the TUM format (`t x y z qx qy qz qw`, a line per stereo frame,
    /// z = 0, the yaw as a quaternion) for evo and other SLAM tools.
    #[arg(long, value_name = "TRAJ.tum")]
    trajectory_tum: Option<PathBuf>,
    /// Write the log's true pose at those frames in the TUM format, when the log has truth
    /// (simulator logs): `evo_ape tum TRUTH.tum TRAJ.tum` then gives the summary's ATE.
    #[arg(long, value_name = "TRUTH.tum")]
    truth_tum: Option<PathBuf>,
    /// Write the map the run built (landmarks with their covariance, the calibrated C and V,
    /// the rig) in the project's map format (docs/maps.md).
    #[arg(long, value_name = "MAP")]
    save_map: Option<PathBuf>,
    /// Skip phase 1: start phase 2 at the first frame from the rig's nominal values and priors
    /// (as in the paper's experiment).
    #[arg(long)]
    skip_phase1: bool,
    /// Frames phase 1's batch holds at most: when it is full before calibration is stable,
    /// phase 2 starts from what the data gave (2000 frames are 100 s at 20 Hz).
    #[arg(long, value_name = "N", default_value_t = SmootherSettings::default().max_frames)]
    phase1_frames: usize,
    /// Keep phase 2 from refining the camera parameters: their covariance is carried into the
    /// pose and landmark sigmas, their values stay phase 1's (Schmidt-Kalman; for drives on
    /// which refining them is over-confident, docs/phase2.md).
    #[arg(long)]
    consider_camera: bool,
}

/// The navigator's settings from the command line, checked before any log is read (a bad
/// setting should not wait for a long log).
pub(crate) fn nav_settings(
    skip_phase1: bool,
    phase1_frames: usize,
    consider_camera: bool,
) -> Result<NavSettings> {
    let defaults = NavSettings::default();
    let settings = NavSettings {
        skip_phase1,
        ekf: vslam_ekf::Settings {
            camera_update: if consider_camera {
                vslam_ekf::CameraUpdate::Consider
            } else {
                vslam_ekf::CameraUpdate::Refine
            },
            ..defaults.ekf
        },
        phase1: SmootherSettings {
            max_frames: phase1_frames,
            ..defaults.phase1
        },
        ..defaults
    };
    settings
        .phase1
        .validate()
        .with_context(|| format!("--phase1-frames {phase1_frames}"))?;
    Ok(settings)
}

/// The warning for `--truth-tum` on a log without truth (the file then holds its header only);
/// `replay` and `localize` print it after the run's own warnings.
pub(crate) fn truth_tum_warning(asked: bool, has_truth: bool) -> Option<&'static str> {
    (asked && !has_truth).then_some("the log has no truth: --truth-tum wrote no pose")
}

pub(crate) fn run(args: &Args) -> Result<()> {
    let settings = nav_settings(args.skip_phase1, args.phase1_frames, args.consider_camera)?;
    let rig = args.rig.as_deref().map(Rig::load).transpose()?;
    let mut bar = ByteProgress::new("replaying");
    let mut progress = |done: u64, total: u64| bar.update(done, total);
    let started = Instant::now();
    // The log's start first: a foreign file or one without a rig makes no output.
    let topics = args.topics.topics();
    let replayer = Replayer::open_with_topics(&args.log, topics.as_ref(), rig, &settings)?;
    let rig_used = replayer.rig().clone();
    let mut outputs = OutputFiles::create(args.out.as_deref(), args.trajectory.as_deref())?
        .with_tum(args.trajectory_tum.as_deref(), args.truth_tum.as_deref())?;
    let result = replayer.run(&mut outputs, &mut progress);
    bar.finish();
    let end = result?;
    outputs.finish(&end, args.summary.as_deref())?;
    if let Some(path) = &args.save_map {
        replay::saved_map(&end, &rig_used, &args.log).save(path)?;
    }
    let took = started.elapsed();
    {
        let mut stderr = io::stderr().lock();
        let truth_tum = truth_tum_warning(args.truth_tum.is_some(), end.truth.is_some());
        for w in end.warnings.iter().map(String::as_str).chain(truth_tum) {
            writeln!(stderr, "stereonav: warning: {w}")?;
        }
    }
    let text = human_summary(&args.log, &end, took);
    io::stdout().lock().write_all(text.as_bytes())?;
    Ok(())
}

/// The few lines a person reads after a replay.
fn human_summary(log: &std::path::Path, r: &ReplayEnd, took: Duration) -> String {
    let mut s = String::new();
    let span_s = match (r.first_t_us, &r.last_frame) {
        (Some(a), Some(b)) => (b.t_us.saturating_sub(a)) as f64 * 1e-6,
        _ => 0.0,
    };
    let speed = if took.as_secs_f64() > 0.0 {
        span_s / took.as_secs_f64()
    } else {
        f64::INFINITY
    };
    let _ = writeln!(
        s,
        "{}: {} stereo frames ({span_s:.1} s of data) replayed in {:.2} s ({speed:.0}x real time); {} corrupt packets, {} frames lost",
        log.display(),
        r.frames_processed,
        took.as_secs_f64(),
        r.counts.corrupt,
        r.counts.lost
    );
    let c = &r.counts;
    if c.images_left + c.images_right > 0 {
        let _ = writeln!(
            s,
            "camera images: {} left, {} right, {} stereo frames detected on the host; {} without a partner, {} unreadable",
            c.images_left,
            c.images_right,
            c.frames,
            c.images_unpaired,
            c.images_wrong_size + c.images_unsupported + c.images_undecodable
        );
    }
    let phase2 = r.phase2_frames;
    let phases = match (r.phase1_skipped, r.phase_switch_t_us) {
        (true, _) => "phase 1 skipped: phase 2 from the rig's priors".to_string(),
        (false, Some(t)) if phase2 == 0 => format!(
            "phase 1 ran to the end of the log (t = {:.2} s): the map is its batch over every frame",
            t as f64 * 1e-6
        ),
        (false, Some(t)) => format!(
            "phase 1 handed over at t = {:.2} s (the first frame's world): phase 2 for {phase2} frames",
            t as f64 * 1e-6
        ),
        (false, None) => "no frame: no map".to_string(),
    };
    let _ = writeln!(s, "{phases}");
    let merged = match r.counts.landmarks_merged {
        0 => String::new(),
        1 => " (1 more merged into another as the same lamp)".to_string(),
        n => format!(" ({n} more merged into others as the same lamps)"),
    };
    let loops = match r.counts.loops_closed {
        0 => String::new(),
        1 => "; 1 loop closed by the constellation of lamps held while lost".to_string(),
        n => format!("; {n} loops closed by the constellation of lamps held while lost"),
    };
    let refused = match r.counts.loops_refused {
        0 => String::new(),
        1 => "; 1 recognised place refused (beyond the lost pose's reach)".to_string(),
        n => format!("; {n} recognised places refused (beyond the lost pose's reach)"),
    };
    let _ = writeln!(
        s,
        "map: {} landmarks{merged}{loops}{refused}",
        r.landmarks.len()
    );
    for p in r.final_camera.iter().filter(|p| p.sigma > 0.0) {
        let name = p.param.name();
        let (scale, unit) = p.param.display_unit();
        match p.param {
            Param::F | Param::Cx | Param::Cy => {
                let _ = writeln!(s, "{name}: {:.3} +- {:.3}", p.value, p.sigma);
            }
            // A scale near 1: the value itself, its sigma in percent.
            Param::OdomScale | Param::OdomYawScale => {
                let _ = writeln!(s, "{name}: {:.5} +- {:.3} %", p.value, p.sigma * scale);
            }
            _ => {
                let _ = writeln!(
                    s,
                    "{name}: {:.2} +- {:.2} {unit}",
                    p.value * scale,
                    p.sigma * scale
                );
            }
        }
    }
    if let Some(f) = &r.last_frame {
        let _ = writeln!(
            s,
            "final pose: x {:.3} m, y {:.3} m, theta {:.2} deg",
            f.pose[0],
            f.pose[1],
            f.pose[2].to_degrees()
        );
    }
    if let Some(t) = &r.truth {
        let _ = writeln!(
            s,
            "against the log's truth: landmark RMS {:.2} mm ({} matched, {} unmatched, {} duplicates, {} lamps missed), trajectory error RMS {:.2} mm (max {:.2} mm), heading RMS {:.3} deg",
            t.landmark_rms * 1e3,
            t.landmarks_matched,
            t.landmarks_unmatched,
            t.landmarks_duplicate,
            t.lamps_missed,
            t.ate_rms * 1e3,
            t.ate_max * 1e3,
            t.heading_rms.to_degrees()
        );
        for (p, e) in &t.camera {
            if r.final_camera
                .iter()
                .any(|c| c.param == *p && c.sigma > 0.0)
            {
                let _ = writeln!(s, "  {} error {e:+.3e}", p.name());
            }
        }
    }
    s
}
