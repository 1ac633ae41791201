//! Every frame of a localisation run while it is lost, and the frame it (re)gains its
//! position: what holds a fix back and the hypotheses being weighed (issue 37, item 4, in
//! text; the viewer draws the same).
//!
//! `cargo run --release -p replay --example localize_trace -- LOG.mcap MAP [RIG.toml]`
#![allow(clippy::print_stdout, clippy::print_stderr)] // a command-line tool

use std::path::Path;
use std::process::ExitCode;

use replay::{LocalizerSettings, Waiting};

fn waiting(w: Option<Waiting>) -> String {
    w.map_or_else(|| "-".into(), |w| w.to_string())
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (Some(log), Some(map)) = (args.first(), args.get(1)) else {
        eprintln!("usage: localize_trace LOG.mcap MAP [RIG.toml]");
        return ExitCode::FAILURE;
    };
    let run = || -> Result<(), String> {
        let map = map_file::Map::load(Path::new(map)).map_err(|e| e.to_string())?;
        let rig = match args.get(2) {
            Some(r) => Some(rig_model::Rig::load(Path::new(r)).map_err(|e| e.to_string())?),
            None => None,
        };
        let mut first = None;
        let mut was_localized = false;
        replay::localize_log(
            Path::new(log), None,
            &map,
            rig,
            LocalizerSettings::default(),
            &mut |f| {
                let t0 = *first.get_or_insert(f.t_us);
                let t = (f.t_us - t0) as f64 * 1e-6;
                if !f.localized || !was_localized {
                    let err = match (f.pose, f.truth) {
                        (Some(p), Some(q)) => {
                            format!("{:.3} m off", (p[0] - q[0]).hypot(p[1] - q[1]))
                        }
                        _ => String::new(),
                    };
                    let weighed: Vec<String> = f
                        .weighed
                        .iter()
                        .flatten()
                        .map(|w| {
                            format!(
                                "({:.2}, {:.2}, {:.0} deg) -{:.0} age {} matched {}",
                                w.pose.x,
                                w.pose.y,
                                w.pose.theta.to_degrees(),
                                w.behind_nats,
                                w.age,
                                w.matched
                            )
                        })
                        .collect();
                    let generation = f.generation.map_or(String::new(), |g| {
                        format!(
                            "last generation: {} observations, {} triangles ({} whole), {} map triangles, {} candidates, {} new",
                            g.observations, g.triangles, g.whole, g.map_triangles, g.candidates, g.new
                        )
                    });
                    println!(
                        "{t:7.2} s {} {err} | {} hypotheses | waiting: {} | {} | {generation}",
                        if f.localized { "LOCALISED" } else { "lost" },
                        f.hypotheses,
                        waiting(f.waiting),
                        weighed.join("; ")
                    );
                }
                was_localized = f.localized;
                Ok(())
            },
            &mut |_, _| {},
        )
        .map_err(|e| e.to_string())?;
        Ok(())
    };
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("localize_trace: {e}");
            ExitCode::FAILURE
        }
    }
}
