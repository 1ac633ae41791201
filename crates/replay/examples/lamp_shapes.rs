//! Real lamps are not points (issue 16): the real-lamps scenario (panels, tubes, large discs,
//! beam reflections) rendered, the board's Harris on the images, replayed with no flags, and
//! each landmark scored against the lamps' feature points (a panel's corners, a tube's ends,
//! a disc's centre): how many landmarks each point got (more than one is a duplicate),
//! landmarks near no point (spurious: a disc's rim, a reflection), the error of the matched
//! ones, and their jitter (how far a landmark's estimate moved in the map snapshots, once a
//! second, after its first two seconds).
//!
//! `cargo run --release -p replay --example lamp_shapes -- [SCENARIO.toml] [RUNS] [--fast]`
#![allow(clippy::print_stdout, clippy::print_stderr)] // a command-line tool

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::process::ExitCode;

use nalgebra::Vector3;
use replay::{NavSettings, replay_log};

fn main() -> ExitCode {
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("lamp_shapes: {e}");
            ExitCode::FAILURE
        }
    }
}

#[derive(Default)]
struct Tally {
    points: usize,
    matched: usize,
    duplicates: usize,
    sq: f64,
    jitter_sq: f64,
    jitter_n: usize,
}

fn kind(l: &sim::Lamp) -> &'static str {
    match &l.panel {
        Some(p) if p.is_tube() => "tube end",
        Some(_) => "panel corner",
        None if l.radius_m >= 0.05 => "disc centre",
        None => "point lamp",
    }
}

fn run() -> Result<(), String> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let fast = args.iter().any(|a| a == "--fast");
    let rest: Vec<&String> = args.iter().filter(|a| *a != "--fast").collect();
    let path = rest.first().map_or_else(
        || {
            PathBuf::from(env!("CARGO_MANIFEST_DIR"))
                .join("../../fixtures/scenarios/real-lamps.toml")
        },
        PathBuf::from,
    );
    let runs: u64 = rest
        .get(1)
        .map(|s| s.parse().map_err(|_| format!("RUNS {s:?} is not a count")))
        .transpose()?
        .unwrap_or(3);
    let scenario = sim::Scenario::load(&path).map_err(|e| e.to_string())?;
    let mode = if fast {
        sim::Mode::Fast
    } else {
        sim::Mode::Rendered
    };
    let log = std::env::temp_dir().join(format!("lamp-shapes-{}.mcap", std::process::id()));
    let mut tallies: BTreeMap<&'static str, Tally> = BTreeMap::new();
    let (mut spurious, mut landmarks, mut started, mut confirmed) = (0usize, 0usize, 0u64, 0u64);
    for seed in 0..runs {
        let sc = scenario.clone().with_seed(seed);
        let sim_run = sim::simulate(&sc, mode).map_err(|e| e.to_string())?;
        sim_run.write_log(&log).map_err(|e| e.to_string())?;
        let r = replay_log(&log, None, &NavSettings::default(), &mut |_, _| {})
            .map_err(|e| e.to_string())?;
        started += r.counts.tracks;
        confirmed += r.counts.confirmed_tracks;
        landmarks += r.landmarks.len();
        let truth: Vec<(Vector3<f64>, &'static str)> = sim_run
            .landmarks
            .iter()
            .map(|l| (l.position, kind(l)))
            .collect();
        // Each landmark to its nearest truth point within 10 cm.
        let mut owner: Vec<Option<usize>> = Vec::new();
        for l in &r.landmarks {
            let p = Vector3::from(l.position);
            let best = truth
                .iter()
                .enumerate()
                .map(|(i, (t, _))| (i, (t - p).norm()))
                .min_by(|a, b| a.1.total_cmp(&b.1))
                .filter(|(_, d)| *d <= 0.1);
            owner.push(best.map(|(i, _)| i));
            if best.is_none() {
                spurious += 1;
            }
        }
        for (i, (t, k)) in truth.iter().enumerate() {
            let tally = tallies.entry(k).or_default();
            tally.points += 1;
            let mine: Vec<usize> = owner
                .iter()
                .enumerate()
                .filter(|(_, o)| **o == Some(i))
                .map(|(j, _)| j)
                .collect();
            if mine.is_empty() {
                continue;
            }
            tally.matched += 1;
            tally.duplicates += mine.len() - 1;
            if mine.len() > 1 && std::env::var_os("LAMP_SHAPES_DEBUG").is_some() {
                for &j in &mine {
                    if let Some(l) = r.landmarks.get(j) {
                        let e = 1e3 * (Vector3::from(l.position) - t);
                        println!(
                            "  {k} {i}: landmark {} off by {:+.0} {:+.0} {:+.0} mm, {} observations",
                            l.id, e.x, e.y, e.z, l.observations
                        );
                    }
                }
            }
            let Some(best) = mine
                .iter()
                .filter_map(|&j| r.landmarks.get(j))
                .min_by(|a, b| {
                    (Vector3::from(a.position) - t)
                        .norm()
                        .total_cmp(&(Vector3::from(b.position) - t).norm())
                })
            else {
                continue;
            };
            tally.sq += (Vector3::from(best.position) - t).norm_squared();
            // Jitter: its snapshots after its first two, against its final position.
            let history: Vec<Vector3<f64>> = r
                .maps
                .iter()
                .filter_map(|m| m.landmarks.iter().find(|l| l.id == best.id))
                .map(|l| Vector3::from(l.position))
                .collect();
            for h in history.iter().skip(2) {
                tally.jitter_sq += (h - Vector3::from(best.position)).norm_squared();
                tally.jitter_n += 1;
            }
        }
    }
    std::fs::remove_file(&log).ok();
    println!(
        "{runs} runs of {} ({} mode): {landmarks} landmarks, {spurious} near no lamp feature point (spurious); tracks started {started}, confirmed {confirmed}",
        path.display(),
        if fast { "fast" } else { "rendered" }
    );
    for (k, t) in &tallies {
        println!(
            "{k}: {} points, {} with a landmark, {} duplicates; error RMS {:.1} mm; jitter RMS {:.2} mm",
            t.points,
            t.matched,
            t.duplicates,
            1e3 * (t.sq / t.matched.max(1) as f64).sqrt(),
            1e3 * (t.jitter_sq / t.jitter_n.max(1) as f64).sqrt(),
        );
    }
    Ok(())
}
