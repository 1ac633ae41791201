//! `stereonav map import LAMPS.csv --out MAP [--sigma S] [--rig RIG.toml]`
//! (vehicle-interfaces.md section 5): a saved map from a hall's lighting plan or survey.
//!
//! The plan's reading and the map are the library's ([`map_file::Map::import_plan`], which
//! Python's `stereonav.import_map` calls too; the CSV format is docs/maps.md, "A map from a
//! lighting plan"): this module parses the arguments, writes the map and prints a line naming
//! it with its lamps, where they came from and whether `stereonav localize` needs `--rig`.

use std::io::{self, Write};
use std::path::PathBuf;

use anyhow::Result;
use map_file::{DEFAULT_LAMP_SIGMA_M, Map};
use rig_model::Rig;

/// Arguments of `stereonav map`.
#[derive(Debug, clap::Args)]
pub(crate) struct Args {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, clap::Subcommand)]
enum Command {
    /// Make a map from a hall's lighting plan or survey: a CSV with the header x,y,z (metres,
    /// the hall's frame, z up) and optional columns id and sigma, a row per lamp. No mapping
    /// drive: `stereonav localize` runs on it in the hall's frame.
    Import(ImportArgs),
}

/// Arguments of `stereonav map import`.
#[derive(Debug, clap::Args)]
struct ImportArgs {
    /// The lighting plan: a header naming the columns x, y, z and optionally id, sigma (any
    /// order), then a row per lamp; blank lines and lines starting with '#' are skipped.
    #[arg(value_name = "LAMPS.csv")]
    plan: PathBuf,
    /// The map file to write (docs/maps.md).
    #[arg(long, value_name = "MAP")]
    out: PathBuf,
    /// The 1-sigma position uncertainty of a lamp whose row gives none, metres.
    #[arg(long, value_name = "S", default_value_t = DEFAULT_LAMP_SIGMA_M)]
    sigma: f64,
    /// A rig file to carry in the map, so that `stereonav localize` needs no --rig (without
    /// it the map has no rig and localize must be given one).
    #[arg(long, value_name = "RIG.toml")]
    rig: Option<PathBuf>,
}

pub(crate) fn run(args: &Args) -> Result<()> {
    match &args.command {
        Command::Import(import) => run_import(import),
    }
}

fn run_import(args: &ImportArgs) -> Result<()> {
    let rig = args.rig.as_deref().map(Rig::load).transpose()?;
    let map = Map::import_plan(&args.plan, args.sigma, rig)?;
    map.save(&args.out)?;
    let rig = match &args.rig {
        Some(path) => format!("the rig of {}", path.display()),
        None => "no rig: give `stereonav localize` one with --rig RIG.toml".to_string(),
    };
    writeln!(
        io::stdout().lock(),
        "{}: {} lamps from the lighting plan {} (map format version {}); {rig}",
        args.out.display(),
        map.landmarks.len(),
        args.plan.display(),
        map.format_version(),
    )?;
    Ok(())
}
