//! `stereonav localize LOG.mcap --map MAP [--rig RIG.toml] [--summary SUMMARY.json]
//! [--trajectory TRAJ.csv] [--trajectory-tum TRAJ.tum] [--truth-tum TRUTH.tum] [--save-map NEW_MAP]`:
//! a vehicle log on a saved map
//! (vehicle-interfaces.md section 5; `replay::localize_log`).
//!
//! The vehicle may start anywhere in the map and be moved while the stack is blind; poses are
//! in the map's frame. Prints a short human summary on stdout (frames localised, the fixes,
//! the lamps missing and new and, when the log has simulator truth, the errors); warnings go
//! to stderr.

use std::fmt::Write as _;
use std::io::{self, Write};
use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::Result;
use replay::{
    LocalizeEnd, LocalizedTrajectoryWriter, LocalizerSettings, TRAJ_TUM_FILE, TRUTH_TUM_FILE,
    TumWriter,
};
use rig_model::Rig;

use crate::progress::ByteProgress;

/// Arguments of `stereonav localize`.
#[derive(Debug, clap::Args)]
pub(crate) struct Args {
    /// The vehicle log (MCAP, vehicle-interfaces.md section 4), or a ROS 2 bag of camera images
    /// and wheel odometry with --left, --right and --odom (4.1).
    #[arg(value_name = "LOG.mcap")]
    log: PathBuf,
    #[command(flatten)]
    topics: crate::topics::TopicArgs,
    /// The saved map (`stereonav replay --save-map` or `stereonav map import`, docs/maps.md).
    #[arg(long, value_name = "MAP")]
    map: PathBuf,
    /// The rig file (its lens, image size and noise); without it, the rig the map was made
    /// with. The camera's calibration comes from the map; a map imported from a lighting plan
    /// has none and takes this rig's nominal camera and priors (required when such a map
    /// carries no rig).
    #[arg(long, value_name = "RIG.toml")]
    rig: Option<PathBuf>,
    /// Write the summary as JSON (the replay's keys plus `localized_t_us` and `lamps_missing`).
    #[arg(long, value_name = "SUMMARY.json")]
    summary: Option<PathBuf>,
    /// Write the trajectory as CSV (`t_us,x,y,theta,localized`, a row per stereo frame).
    #[arg(long, value_name = "TRAJ.csv")]
    trajectory: Option<PathBuf>,
    /// Write the localised frames' poses in the TUM format (`t x y z qx qy qz qw`, z = 0, the
    /// yaw as a quaternion) for evo and other SLAM tools; lost frames have no line.
    #[arg(long, value_name = "TRAJ.tum")]
    trajectory_tum: Option<PathBuf>,
    /// Write the log's true pose at those frames in the TUM format, when the log has truth
    /// (simulator logs): `evo_ape tum TRUTH.tum TRAJ.tum` then gives the summary's ATE.
    #[arg(long, value_name = "TRUTH.tum")]
    truth_tum: Option<PathBuf>,
    /// Write a new version of the map with the lamps this run found that are not in it.
    #[arg(long, value_name = "NEW_MAP")]
    save_map: Option<PathBuf>,
}

pub(crate) fn run(args: &Args) -> Result<()> {
    let map = map_file::Map::load(&args.map)?;
    let rig = args.rig.as_deref().map(Rig::load).transpose()?;
    // A map imported from a lighting plan without a rig needs one: said, naming the map,
    // before any output is made.
    if rig.is_none() && map.rig.is_none() {
        let e = replay::Error::MapWithoutRig {
            plan: map.source_plan.clone(),
        };
        return Err(anyhow::Error::new(e).context(args.map.display().to_string()));
    }
    let mut traj = args
        .trajectory
        .as_deref()
        .map(LocalizedTrajectoryWriter::create)
        .transpose()?;
    let mut traj_tum = args
        .trajectory_tum
        .as_deref()
        .map(|p| TumWriter::create(TRAJ_TUM_FILE, p))
        .transpose()?;
    let mut truth_tum = args
        .truth_tum
        .as_deref()
        .map(|p| TumWriter::create(TRUTH_TUM_FILE, p))
        .transpose()?;
    let mut bar = ByteProgress::new("localising");
    let mut progress = |done: u64, total: u64| bar.update(done, total);
    let started = Instant::now();
    let mut rows = |f: &replay::LocalizedFrame| {
        if let Some(t) = traj.as_mut() {
            t.frame(f)?;
        }
        // The frames the summary's ATE is over: localised, with a true pose for the truth.
        if let Some(pose) = f.localized_pose() {
            if let Some(t) = traj_tum.as_mut() {
                t.pose(f.t_us, pose)?;
            }
            if let (Some(t), Some(truth)) = (truth_tum.as_mut(), f.truth) {
                t.pose(f.t_us, truth)?;
            }
        }
        Ok(())
    };
    let topics = args.topics.topics();
    let result = replay::localize_log(
        &args.log,
        topics.as_ref(),
        &map,
        rig,
        LocalizerSettings::default(),
        &mut rows,
        &mut progress,
    );
    bar.finish();
    let end = result?;
    if let Some(t) = traj {
        t.finish()?;
    }
    for t in [traj_tum, truth_tum].into_iter().flatten() {
        t.finish()?;
    }
    if let Some(path) = &args.summary {
        replay::write_summary_value(path, &replay::localize_summary_json(&end))?;
    }
    if let Some(path) = &args.save_map {
        replay::map_with_new_lamps(&map, &end, &args.log).save(path)?;
    }
    let took = started.elapsed();
    {
        let mut stderr = io::stderr().lock();
        let truth_tum =
            crate::replay::truth_tum_warning(args.truth_tum.is_some(), end.truth.is_some());
        for w in end.warnings.iter().map(String::as_str).chain(truth_tum) {
            writeln!(stderr, "stereonav: warning: {w}")?;
        }
    }
    let text = human_summary(&args.log, &end, took);
    io::stdout().lock().write_all(text.as_bytes())?;
    Ok(())
}

/// The few lines a person reads after a localisation run.
fn human_summary(log: &std::path::Path, r: &LocalizeEnd, took: Duration) -> String {
    let mut s = String::new();
    let span_s = match (r.first_t_us, &r.last_frame) {
        (Some(a), Some(b)) => (b.t_us.saturating_sub(a)) as f64 * 1e-6,
        _ => 0.0,
    };
    let _ = writeln!(
        s,
        "{}: {} stereo frames ({span_s:.1} s of data) localised in {:.2} s; {} corrupt packets, {} frames lost",
        log.display(),
        r.frames_processed,
        took.as_secs_f64(),
        r.counts.corrupt,
        r.counts.lost
    );
    let pct = if r.frames_processed > 0 {
        100.0 * r.localized_frames as f64 / r.frames_processed as f64
    } else {
        0.0
    };
    let first = r.first_t_us.unwrap_or(0);
    let fixes: Vec<String> = r
        .localized_t_us
        .iter()
        .map(|t| format!("{:.2} s", t.saturating_sub(first) as f64 * 1e-6))
        .collect();
    let _ = writeln!(
        s,
        "localised in {} of {} frames ({pct:.1} %); position (re)gained at {}",
        r.localized_frames,
        r.frames_processed,
        if fixes.is_empty() {
            "never".to_string()
        } else {
            fixes.join(", ")
        }
    );
    let _ = writeln!(
        s,
        "lost: {} after gaps, {} without odometry, {} when the lamps stopped fitting, {} too uncertain",
        r.lost[0], r.lost[1], r.lost[2], r.lost[3]
    );
    let _ = writeln!(
        s,
        "map: {} landmarks; missing: {:?}; new lamps: {}",
        r.landmarks.len(),
        r.lamps_missing,
        r.new_lamps.len()
    );
    if let Some(f) = &r.last_frame
        && let Some([x, y, th]) = f.pose
    {
        let _ = writeln!(
            s,
            "final pose: x {x:.3} m, y {y:.3} m, theta {:.2} deg ({})",
            th.to_degrees(),
            if f.localized {
                "localised"
            } else {
                "lost: best guess"
            }
        );
    }
    if let Some(t) = &r.truth {
        let _ = writeln!(
            s,
            "against the log's truth: error RMS {:.2} mm (max {:.2} mm) over {} localised frames, heading RMS {:.3} deg, pose NEES {:.2} (3 is honest), {} frames localised more than {:.2} m off",
            t.ate_rms_m * 1e3,
            t.ate_max_m * 1e3,
            t.localized_frames,
            t.heading_rms_rad.to_degrees(),
            t.pose_nees,
            t.wrong_frames,
            replay::WRONG_FIX_M
        );
    }
    s
}
