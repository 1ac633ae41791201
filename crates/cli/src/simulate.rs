//! `stereonav simulate SCENARIO.toml --out LOG.mcap [--rig RIG.toml] [--truth TRUTH.json]
//! [--rendered] [--seed N]`: runs the seeded simulator and writes a vehicle log
//! (vehicle-interfaces.md section 4), the nominal rig file and the ground truth.

use std::path::PathBuf;

use anyhow::{Context, Result};

use crate::progress::FrameProgress;

/// Arguments of `stereonav simulate`.
#[derive(Debug, clap::Args)]
pub(crate) struct Args {
    /// The scenario file (TOML; see fixtures/scenarios/).
    scenario: PathBuf,
    /// Where to write the vehicle log (MCAP).
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
    /// Use this seed instead of the scenario's.
    #[arg(long)]
    seed: Option<u64>,
}

pub(crate) fn run(args: &Args) -> Result<()> {
    let mut scenario = sim::Scenario::load(&args.scenario)?;
    if let Some(seed) = args.seed {
        scenario = scenario.with_seed(seed);
    }
    let mode = if args.rendered {
        sim::Mode::Rendered
    } else {
        sim::Mode::Fast
    };
    let mut bar = FrameProgress::new("simulating");
    let mut progress = |done: usize, total: usize| bar.update(done as u64, total as u64);
    let result = sim::simulate_with_progress(&scenario, mode, &mut progress);
    bar.finish();
    let run = result?;
    run.write_log(&args.out)?;
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
