//! `stereonav`: the navigation stack's command line (vehicle-interfaces.md section 5).
//!
//! Every failure ends with one line on stderr naming the problem and a non-zero exit status.

use std::io::{self, Write};
use std::process::ExitCode;

use clap::{Parser, Subcommand};

mod calibrate;
mod fpga;
mod harris;
mod localize;
mod log;
mod map_import;
mod progress;
mod replay;
mod rig_import;
mod simulate;
mod topics;
mod view;

/// Ceiling-lamp stereo navigation for autonomous forklifts.
#[derive(Debug, Parser)]
#[command(name = "stereonav", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Run the board's Harris detector on an 8-bit grayscale PGM or PNG image and print
    /// `x_q4,y_q4,r`, one feature a line, in the board's order.
    Harris(harris::Args),
    /// The board's feature stream (board-icd.md section 3).
    Fpga(fpga::Args),
    /// Simulate a scenario (seeded) and write a vehicle log, optionally the nominal rig file
    /// and the ground truth.
    Simulate(simulate::Args),
    /// Phase 1 on a vehicle log: self-calibrate the camera parameters in batch and print a
    /// summary (value, sigma and nominal value of each estimated parameter, the hand-over
    /// time); `--out` writes the whole result as JSON.
    Calibrate(calibrate::Args),
    /// The whole stack on a vehicle log: phase 1 self-calibration, the switch, phase 2 EKF
    /// SLAM; prints a short summary and writes the estimates (MCAP), the summary (JSON) and the
    /// trajectory (CSV) on request.
    Replay(replay::Args),
    /// A vehicle log on a saved map (`replay --save-map`, `map import`): the vehicle may start
    /// anywhere in it and be moved while blind; prints whether and where it localised, the
    /// lamps missing and new, and writes the summary (JSON) and trajectory (CSV) on request.
    Localize(localize::Args),
    /// Vehicle logs: `log check` says what is damaged and what a replay will use (exit 0 only
    /// for an undamaged log); `log recover` writes every readable record to a clean log.
    Log(log::Args),
    /// Rig files: `rig import` writes one from a stereo calibration by Kalibr, ROS or OpenCV.
    Rig(rig_import::Args),
    /// Saved maps: `map import` makes one from a hall's lighting plan or survey (a CSV of the
    /// lamps' positions), to localise on without a mapping drive.
    Map(map_import::Args),
    /// The viewer: a vehicle log (replayed on the fly) or an estimates file, with the image
    /// planes, the map, the camera parameters and the NIS over time and a timeline;
    /// `--map MAP` localises the log on a saved map instead and shows where it was localised
    /// or lost, the pose's uncertainty and the lamps missing and new; `--screenshot OUT.png`
    /// renders it headless to PNG and exits.
    View(view::Args),
}

/// Parses the command line; a usage error becomes one line on stderr and exit status 2, while
/// `--help` and `--version` print as usual.
fn parse_args() -> Result<Cli, ExitCode> {
    Cli::try_parse().map_err(|err| {
        use clap::error::ErrorKind;
        if matches!(
            err.kind(),
            ErrorKind::DisplayHelp
                | ErrorKind::DisplayVersion
                | ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand
        ) {
            let _ = err.print();
            return ExitCode::SUCCESS;
        }
        let text = err.to_string();
        let message: Vec<&str> = text
            .lines()
            .map(str::trim)
            .take_while(|l| !l.starts_with("Usage:") && !l.starts_with("For more information"))
            .filter(|l| !l.is_empty())
            .collect();
        let _ = writeln!(io::stderr().lock(), "stereonav: {}", message.join(" "));
        ExitCode::from(2)
    })
}

fn main() -> ExitCode {
    let cli = match parse_args() {
        Ok(cli) => cli,
        Err(code) => return code,
    };
    let done = |r: anyhow::Result<()>| r.map(|()| ExitCode::SUCCESS);
    let result = match cli.command {
        Command::Harris(args) => done(harris::run(&args)),
        Command::Fpga(args) => done(fpga::run(&args)),
        Command::Simulate(args) => done(simulate::run(&args)),
        Command::Calibrate(args) => done(calibrate::run(&args)),
        Command::Replay(args) => done(replay::run(&args)),
        Command::Localize(args) => done(localize::run(&args)),
        // `log check` exits 1 for a damaged log, without an error line.
        Command::Log(args) => log::run(&args),
        Command::Rig(args) => done(rig_import::run(&args)),
        Command::Map(args) => done(map_import::run(&args)),
        Command::View(args) => done(view::run(&args)),
    };
    match result {
        Ok(code) => code,
        Err(err) => {
            // A closed pipe (`stereonav harris img.png | head`) is not a failure.
            if err
                .downcast_ref::<io::Error>()
                .is_some_and(|e| e.kind() == io::ErrorKind::BrokenPipe)
            {
                return ExitCode::SUCCESS;
            }
            let _ = writeln!(io::stderr().lock(), "stereonav: error: {}", one_line(&err));
            ExitCode::FAILURE
        }
    }
}

/// The chain of causes joined with ": ", on one line. A cause whose text its parent's message
/// already holds (errors that print their source and also return it from `source()`) is
/// skipped, so that nothing is said twice.
fn one_line(err: &anyhow::Error) -> String {
    let mut message = String::new();
    for cause in err.chain() {
        let text = cause.to_string();
        if message.contains(&text) {
            continue;
        }
        if !message.is_empty() {
            message.push_str(": ");
        }
        message.push_str(&text);
    }
    message.lines().map(str::trim).collect::<Vec<_>>().join(" ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug)]
    struct Leaf;
    impl std::fmt::Display for Leaf {
        fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
            f.write_str("no such file")
        }
    }
    impl std::error::Error for Leaf {}

    #[test]
    fn causes_join_on_one_line_without_repeats() {
        let err = anyhow::Error::new(Leaf).context("cannot open a.mcap");
        assert_eq!(one_line(&err), "cannot open a.mcap: no such file");
        let err = anyhow::Error::new(Leaf).context("cannot open a.mcap: no such file");
        assert_eq!(one_line(&err), "cannot open a.mcap: no such file");
        let err = anyhow::anyhow!("two\n  lines").context("outer");
        assert_eq!(one_line(&err), "outer: two lines");
    }
}
