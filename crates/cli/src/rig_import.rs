//! `stereonav rig import (--kalibr CAMCHAIN.yaml | --ros LEFT.yaml RIGHT.yaml | --opencv
//! STEREO.yml) --out RIG.toml` (vehicle-interfaces.md section 5): a rig file with `[camera]`
//! and `[lens.left]` / `[lens.right]` from a stereo calibration.
//!
//! The reading of the three formats, the rectification and the rig file's text are the
//! library's ([`rig_model::import`], which Python's `stereonav.import_rig` calls too): this
//! module parses the arguments, writes the file the import gives (read back by the library
//! before it is written) and prints a line naming it with the rectified `f`, `cx`, `cy` and
//! baseline, and a warning on stderr for a baseline that looks like millimetres.

use std::io::{self, Write};
use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use rig_model::import::{import_kalibr, import_opencv, import_ros};

/// Arguments of `stereonav rig`.
#[derive(Debug, clap::Args)]
pub(crate) struct Args {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, clap::Subcommand)]
enum Command {
    /// Write a rig file from a stereo calibration by Kalibr, ROS or OpenCV: `[camera]` (the
    /// rectified f, cx, cy and baseline) and `[lens.*]` (the raw lenses and their
    /// rectification), with commented defaults for the other tables.
    Import(ImportArgs),
}

/// Arguments of `stereonav rig import`.
#[derive(Debug, clap::Args)]
#[command(group(
    clap::ArgGroup::new("calibration")
        .required(true)
        .args(["kalibr", "ros", "opencv"])
))]
struct ImportArgs {
    /// Kalibr's camchain.yaml: cam0 left, cam1 right (rectified as OpenCV's stereoRectify).
    #[arg(long, value_name = "CAMCHAIN.yaml")]
    kalibr: Option<PathBuf>,
    /// ROS camera_info YAML of the left and of the right camera (their R and P as given).
    #[arg(long, num_args = 2, value_names = ["LEFT.yaml", "RIGHT.yaml"])]
    ros: Option<Vec<PathBuf>>,
    /// OpenCV FileStorage YAML with K1 D1 K2 D2 R T width height [model] (rectified as
    /// OpenCV's stereoRectify, or fisheye.stereoRectify for `model: equidistant`).
    #[arg(long, value_name = "STEREO.yml")]
    opencv: Option<PathBuf>,
    /// The rig file to write.
    #[arg(long, value_name = "RIG.toml")]
    out: PathBuf,
}

pub(crate) fn run(args: &Args) -> Result<()> {
    match &args.command {
        Command::Import(import) => run_import(import),
    }
}

fn run_import(args: &ImportArgs) -> Result<()> {
    let imported = if let Some(path) = &args.kalibr {
        import_kalibr(path)?
    } else if let Some(paths) = &args.ros {
        let [left, right] = paths.as_slice() else {
            bail!(
                "--ros takes two files, LEFT.yaml RIGHT.yaml; got {}",
                paths.len()
            );
        };
        import_ros(left, right)?
    } else if let Some(path) = &args.opencv {
        import_opencv(path)?
    } else {
        bail!("one of --kalibr, --ros or --opencv is required");
    };
    let out = args.out.display().to_string();
    std::fs::write(&args.out, imported.to_toml()).with_context(|| format!("cannot write {out}"))?;
    if let Some(warning) = imported.baseline_warning() {
        writeln!(io::stderr().lock(), "stereonav: warning: {warning}")?;
    }
    writeln!(io::stdout().lock(), "{out}: {}", imported.summary())?;
    Ok(())
}
