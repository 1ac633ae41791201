//! Times a whole simulation and the writing of its log: the speed figures of the simulator.
//!
//! `cargo run --release -p sim --example simulate_timed -- fixtures/scenarios/warehouse.toml [--rendered] [--out LOG.mcap]`
//!
//! Prints the simulated duration, the wall time of `simulate` and of `write_log`, and the
//! ratio to real time.
#![allow(clippy::print_stdout, clippy::print_stderr)]

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let rendered = args.iter().any(|a| a == "--rendered");
    let out = args
        .iter()
        .position(|a| a == "--out")
        .and_then(|i| args.get(i + 1))
        .map_or_else(
            || std::env::temp_dir().join("sim-timed.mcap"),
            PathBuf::from,
        );
    let Some(path) = args.first() else {
        eprintln!("usage: simulate_timed SCENARIO.toml [--rendered] [--out LOG.mcap]");
        return ExitCode::FAILURE;
    };
    let mode = if rendered {
        sim::Mode::Rendered
    } else {
        sim::Mode::Fast
    };
    let result = (|| -> sim::Result<()> {
        let t0 = Instant::now();
        let scenario = sim::Scenario::load(Path::new(path))?;
        let run = sim::simulate(&scenario, mode)?;
        let t1 = Instant::now();
        run.write_log(&out)?;
        let t2 = Instant::now();
        let duration_s = run
            .frames
            .last()
            .zip(run.frames.first())
            .map_or(0.0, |(l, f)| (l.t_us - f.t_us) as f64 * 1e-6);
        let sim_s = (t1 - t0).as_secs_f64();
        let total_s = (t2 - t0).as_secs_f64();
        let size = std::fs::metadata(&out).map_or(0, |m| m.len());
        println!(
            "{} [{}]: {} frames, {:.1} s simulated; simulate {:.3} s ({:.1} frames/s), + write_log {:.3} s = {:.3} s: {:.0}x real time; log {} bytes",
            run.name,
            mode.name(),
            run.frames.len(),
            duration_s,
            sim_s,
            run.frames.len() as f64 / sim_s,
            total_s - sim_s,
            total_s,
            duration_s / total_s,
            size
        );
        Ok(())
    })();
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("{e}");
            ExitCode::FAILURE
        }
    }
}
