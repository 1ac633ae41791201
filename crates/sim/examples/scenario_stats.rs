//! Prints what a scenario gives: frames, path length, duration, lamps in view per frame, and
//! the time to simulate it.
//!
//! `cargo run --release -p sim --example scenario_stats -- fixtures/scenarios/paper-square.toml [--rendered]`
#![allow(clippy::print_stdout, clippy::print_stderr)]

use std::path::Path;
use std::process::ExitCode;
use std::time::Instant;

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let rendered = args.iter().any(|a| a == "--rendered");
    let mode = if rendered {
        sim::Mode::Rendered
    } else {
        sim::Mode::Fast
    };
    for path in args.iter().filter(|a| !a.starts_with("--")) {
        let scenario = match sim::Scenario::load(Path::new(path)) {
            Ok(s) => s,
            Err(e) => {
                eprintln!("{e}");
                return ExitCode::FAILURE;
            }
        };
        let start = Instant::now();
        let run = match sim::simulate(&scenario, mode) {
            Ok(r) => r,
            Err(e) => {
                eprintln!("{e}");
                return ExitCode::FAILURE;
            }
        };
        let elapsed = start.elapsed().as_secs_f64();
        let counts = run.visible_counts();
        let n = counts.len().max(1);
        let min = counts.iter().copied().min().unwrap_or(0);
        let max = counts.iter().copied().max().unwrap_or(0);
        #[allow(clippy::cast_precision_loss)]
        let mean = counts.iter().sum::<usize>() as f64 / n as f64;
        let below = |k: usize| counts.iter().filter(|&&c| c < k).count();
        // Driven, not carried: frames on both sides of a "moved" segment are not consecutive.
        let mut length = 0.0;
        let mut prev: Option<&sim::FrameTruth> = None;
        for f in &run.frames {
            if let Some(p) = prev.filter(|p| p.index + 1 == f.index) {
                length += (f.pose.x - p.pose.x).hypot(f.pose.y - p.pose.y);
            }
            prev = Some(f);
        }
        let lit = run.landmarks.iter().filter(|l| l.lit).count();
        let duration_s = run
            .frames
            .last()
            .zip(run.frames.first())
            .map_or(0.0, |(l, f)| (l.t_us - f.t_us) as f64 * 1e-6);
        let lamp_features: usize = run
            .frames
            .iter()
            .map(|f| f.left.features.iter().filter(|x| x.lamp.is_some()).count())
            .sum();
        let all_features: usize = run.frames.iter().map(|f| f.left.features.len()).sum();
        let lost = run
            .packets
            .iter()
            .filter(|p| p.fate == sim::PacketFate::Lost)
            .count();
        let flipped = run
            .packets
            .iter()
            .filter(|p| matches!(p.fate, sim::PacketFate::BitFlip { .. }))
            .count();
        let mut hist = vec![0usize; max + 1];
        for &c in &counts {
            hist[c] += 1;
        }
        println!(
            "{}: {} lamps ({lit} lit), {} frames, {:.1} s, path {:.1} m; lamps in both views per frame: min {min} mean {mean:.2} max {max}; frames with <2: {}, <3: {}; histogram {:?}",
            run.name,
            run.landmarks.len(),
            run.frames.len(),
            duration_s,
            length,
            below(2),
            below(3),
            hist
        );
        println!(
            "  left features {all_features} ({lamp_features} of lamps); packets lost {lost}, bit flips {flipped}; stream {} bytes in {} chunks; simulated in {elapsed:.3} s ({:.0}x real time, {:.1} frames/s) [{}]",
            run.chunks.iter().map(|c| c.bytes.len()).sum::<usize>(),
            run.chunks.len(),
            duration_s / elapsed,
            run.frames.len() as f64 / elapsed,
            mode.name()
        );
    }
    ExitCode::SUCCESS
}
