//! `stereonav simulate SCENARIO.toml --out LOG.mcap [--rig RIG.toml] [--truth TRUTH.json]
//! [--rendered] [--ros2 raw|png|jpeg [--jpeg-quality Q]] [--seed N]`: runs the seeded simulator
//! and writes a vehicle log (vehicle-interfaces.md section 4) or, with `--ros2`, a ROS 2 bag of
//! the rendered images and the odometry (4.1), the nominal rig file and the ground truth.

use std::path::PathBuf;

use anyhow::{Context, Result};

use crate::progress::FrameProgress;

/// How `--ros2` writes the images.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub(crate) enum Ros2Images {
    /// `sensor_msgs/msg/Image`, mono8, on /cam0/image_raw and /cam1/image_raw.
    Raw,
    /// `sensor_msgs/msg/CompressedImage`, PNG, on /cam0/image_raw/compressed and
    /// /cam1/image_raw/compressed.
    Png,
    /// `sensor_msgs/msg/CompressedImage`, JPEG (8-bit gray), on the same topics.
    Jpeg,
}

/// Arguments of `stereonav simulate`.
#[derive(Debug, clap::Args)]
pub(crate) struct Args {
    /// The scenario file (TOML; see fixtures/scenarios/).
    scenario: PathBuf,
    /// Where to write the vehicle log, or the ROS 2 bag with `--ros2` (MCAP).
    #[arg(long, value_name = "LOG.mcap")]
    out: PathBuf,
    /// Also write the scenario's nominal rig file (what a user of the vehicle would have) here.
    #[arg(long, value_name = "RIG.toml")]
    rig: Option<PathBuf>,
    /// Also write the ground truth here as JSON: the trajectory at each stereo frame, the
    /// landmarks and the true camera parameters.
    #[arg(long, value_name = "TRUTH.json")]
    truth: Option<PathBuf>,
    /// Render the stereo images and run the board's detector on them (slower) instead of
    /// projecting the lamps.
    #[arg(long)]
    rendered: bool,
    /// Write a ROS 2 bag instead of a vehicle log (implies --rendered): the rendered images of
    /// both cameras (raw through the rig's lenses, with sensor noise, 8 bits), the odometry as
    /// nav_msgs/msg/Odometry on /odom and the truth on /truth/...; no /fpga/features.
    #[arg(long, value_name = "IMAGES")]
    ros2: Option<Ros2Images>,
    /// The JPEG quality of `--ros2 jpeg`, 1 to 100.
    #[arg(long, value_name = "Q", default_value_t = sim::bag::DEFAULT_JPEG_QUALITY,
          value_parser = clap::value_parser!(u8).range(1..=100))]
    jpeg_quality: u8,
    /// Use this seed instead of the scenario's.
    #[arg(long)]
    seed: Option<u64>,
}

pub(crate) fn run(args: &Args) -> Result<()> {
    let mut scenario = sim::Scenario::load(&args.scenario)?;
    if let Some(seed) = args.seed {
        scenario = scenario.with_seed(seed);
    }
    let mode = if args.rendered || args.ros2.is_some() {
        sim::Mode::Rendered
    } else {
        sim::Mode::Fast
    };
    let mut bar = FrameProgress::new("simulating");
    let mut progress = |done: usize, total: usize| bar.update(done as u64, total as u64);
    let result = match args.ros2 {
        None => sim::simulate_with_progress(&scenario, mode, &mut progress)
            .and_then(|run| run.write_log(&args.out).map(|()| run)),
        Some(images) => {
            let images = match images {
                Ros2Images::Raw => sim::BagImages::Raw,
                Ros2Images::Png => sim::BagImages::Png,
                Ros2Images::Jpeg => sim::BagImages::Jpeg {
                    quality: args.jpeg_quality,
                },
            };
            sim::write_bag(&scenario, images, &args.out, &mut progress)
        }
    };
    bar.finish();
    let run = result?;
    if let Some(path) = &args.rig {
        std::fs::write(path, &scenario.rig_text)
            .with_context(|| format!("{}: cannot write the rig file", path.display()))?;
    }
    if let Some(path) = &args.truth {
        std::fs::write(path, run.truth_json() + "\n")
            .with_context(|| format!("{}: cannot write the truth file", path.display()))?;
    }
    Ok(())
}
