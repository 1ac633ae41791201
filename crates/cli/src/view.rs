//! `stereonav view LOG.mcap [--rig RIG.toml] [--skip-phase1] [--phase1-frames N] [--map MAP]
//! [--left TOPIC --right TOPIC --odom TOPIC] [--screenshot OUT.png] [--time SECONDS]
//! [--size WxH]`: the viewer (crate `viewer`) on a vehicle log, replayed on the fly or, with
//! `--map`, localised on a saved map as `stereonav localize` does; or on a ROS 2 bag read from
//! its named topics as `stereonav replay` reads it, its camera images under the features; or
//! on an estimates file written by `stereonav replay --out`.
//!
//! With `--screenshot` it renders the viewer headless (on the CPU: no display, GPU or driver
//! needed) at the end of the log or at `--time`, writes the PNG and exits; otherwise it opens a
//! window (OpenGL under X11), and says so in one line when there is no display. Warnings of
//! the replay go to stderr, one line each.

use std::io::{self, Write};
use std::path::PathBuf;

use crate::progress::ByteProgress;
use anyhow::{Context, Result, bail};
use rig_model::Rig;
use selfcal::smoother::SmootherSettings;

/// Arguments of `stereonav view`.
#[derive(Debug, clap::Args)]
pub(crate) struct Args {
    /// A vehicle log (MCAP, vehicle-interfaces.md section 4) or, with --left --right --odom,
    /// a ROS 2 bag (section 4.1), replayed (or, with --map, localised) when it is opened; or an
    /// estimates file written by `stereonav replay --out`.
    #[arg(value_name = "LOG.mcap")]
    log: PathBuf,
    #[command(flatten)]
    topics: crate::topics::TopicArgs,
    /// The rig file (TOML, section 3); without it, the log's /rig message (with --map, the rig
    /// the map was made with).
    #[arg(long, value_name = "RIG.toml")]
    rig: Option<PathBuf>,
    /// A saved map (`stereonav replay --save-map`): localise the log on it, as `stereonav
    /// localize` does, and show the run: localised or lost over time, the pose and its
    /// uncertainty, the map's lamps with those missing, and the new lamps found.
    #[arg(long, value_name = "MAP", conflicts_with_all = ["skip_phase1", "phase1_frames"])]
    map: Option<PathBuf>,
    /// Skip phase 1: start phase 2 at the first frame from the rig's nominal values and priors.
    #[arg(long)]
    skip_phase1: bool,
    /// Frames phase 1's batch holds at most (as for `stereonav replay`).
    #[arg(long, value_name = "N", default_value_t = SmootherSettings::default().max_frames)]
    phase1_frames: usize,
    /// Render the viewer headless and write it as PNG, then exit (no window).
    #[arg(long, value_name = "OUT.png")]
    screenshot: Option<PathBuf>,
    /// Show this time, seconds from the log's first frame (default: its end).
    #[arg(long, value_name = "SECONDS")]
    time: Option<f64>,
    /// The screenshot's size in pixels, at least 1280x800.
    #[arg(long, value_name = "WxH", default_value = "1280x800", value_parser = parse_size)]
    size: [u32; 2],
}

/// `WxH` as two whole numbers of pixels.
fn parse_size(text: &str) -> Result<[u32; 2], String> {
    let parsed = text
        .split_once(['x', 'X'])
        .and_then(|(w, h)| Some([w.trim().parse().ok()?, h.trim().parse().ok()?]));
    parsed.ok_or_else(|| format!("expected WIDTHxHEIGHT in pixels, like 1280x800, got {text:?}"))
}

pub(crate) fn run(args: &Args) -> Result<()> {
    // Before the log is read: bad settings should not wait for a long replay.
    let settings = crate::replay::nav_settings(args.skip_phase1, args.phase1_frames, false)?;
    if args.screenshot.is_some() {
        viewer::check_size(args.size).context("--size")?;
    } else if args.size != viewer::MIN_SCREENSHOT_SIZE {
        bail!("--size applies to --screenshot only");
    }
    if let Some(t) = args.time
        && !(t.is_finite() && t >= 0.0)
    {
        bail!("--time {t}: expected seconds from the log's first frame, at least 0");
    }
    let rig = args.rig.as_deref().map(Rig::load).transpose()?;
    if args.screenshot.is_none() {
        // Before the replay: a missing display should not wait for a long log.
        viewer::check_display()?;
    }
    let options = viewer::LoadOptions {
        rig,
        settings,
        map: args.map.clone(),
        topics: args.topics.topics(),
    };

    let mut bar = ByteProgress::new(if args.map.is_some() {
        "localising"
    } else {
        "replaying"
    });
    let mut progress = |done: u64, total: u64| bar.update(done, total);
    let loaded = viewer::load(&args.log, &options, &mut progress);
    bar.finish();
    let model = loaded?;
    {
        let mut stderr = io::stderr().lock();
        for w in &model.warnings {
            writeln!(stderr, "stereonav: warning: {w}")?;
        }
        if model.kind == viewer::model::SourceKind::Estimates
            && (args.skip_phase1 || args.phase1_frames != SmootherSettings::default().max_frames)
        {
            writeln!(
                stderr,
                "stereonav: warning: {}: an estimates file is shown as it was replayed: --skip-phase1 and --phase1-frames are not used",
                args.log.display()
            )?;
        }
    }
    if let Some(t) = args.time {
        viewer::check_time(&model, t).context("--time")?;
    }
    match &args.screenshot {
        Some(out) => {
            let shot = viewer::screenshot(model, args.time, args.size)?;
            viewer::write_png(out, &shot.frame)?;
            Ok(())
        }
        None => {
            let mut v = viewer::Viewer::new(model);
            if let Some(t) = args.time {
                v.set_time(t);
            }
            viewer::run_window(v)?;
            Ok(())
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_parse() {
        assert_eq!(parse_size("1280x800"), Ok([1280, 800]));
        assert_eq!(parse_size("1920X1080"), Ok([1920, 1080]));
        assert!(parse_size("1280").is_err());
        assert!(parse_size("ax800").is_err());
        assert!(parse_size("-1x800").is_err());
    }
}
