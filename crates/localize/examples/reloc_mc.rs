//! Seeded Monte Carlo of global relocalisation on a saved map (issue 20):
//! `cargo run --release -p localize --example reloc_mc -- [RUNS] [FIRST_SEED] [--trace] [--exact-map] [--grid=NXxNY] [--jittered-only]`
//! (defaults 100 runs from seed 0; `--trace` prints every frame of every run; `--exact-map`
//! saves the true lamp positions in the map, still with their 5 mm covariance: a diagnosis of
//! what the map's errors do, not the scenario; `--grid=125x80` runs on a hall of that
//! many lamps, the 10,000-lamp map of issue 37; `--jittered-only` leaves out the regular grid).
//!
//! For a regular and a jittered grid of 16 x 10 lamps at 2.5 m, 7 m up, and for each seed:
//! the hall (its jitter), the map (each lamp off by its 5 mm sigma), a start pose anywhere on
//! the floor that the localiser is not told, and a drive at about 1 m/s (`tests/support`).
//!
//! - `start`: 20 s from the start pose.
//! - `kidnap`: the same first 10 s, then 8 s with neither frames nor odometry while the
//!   vehicle is carried to another random pose, then 10 s more.
//!
//! Per run: whether and when it (re)gained its position, whether any frame reported
//! `Localized` was more than 0.25 m or 3 degrees from the truth (a false fix), and the
//! position and heading error RMS over the localised frames. The same seed gives the same
//! run.
#![allow(clippy::print_stdout, clippy::print_stderr)] // a command-line tool

#[path = "../tests/support/mod.rs"]
mod support;

use std::process::ExitCode;
use std::time::Instant;

use localize::{FrameResult, Localizer};
use support::{FRAMES_10_S, Grid, Hall, Leg, Outcome, Step, pose_error};

/// The grid of the Monte Carlo: 160 lamps, a hall of 37.5 m x 22.5 m.
const GRID: (usize, usize) = (16, 10);

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Variant {
    Start,
    Kidnap,
}

/// How a run is done and shown.
#[derive(Debug, Clone, Copy)]
struct Options {
    trace: bool,
    exact_map: bool,
}

/// Prints one frame of a run (`--trace`): the status, the hypotheses, the error, and the live
/// hypothesis nearest the truth (whether the truth is still among them).
fn trace_frame(
    seed: u64,
    variant: Variant,
    leg: usize,
    step: &Step,
    result: &FrameResult,
    localizer: &Localizer,
) {
    let (e, h) = result
        .pose
        .map_or((f64::NAN, f64::NAN), |p| pose_error(&p, &step.truth));
    let (ne, nh) = localizer
        .hypotheses()
        .iter()
        .map(|p| pose_error(p, &step.truth))
        .min_by(|a, b| a.0.total_cmp(&b.0))
        .unwrap_or((f64::NAN, f64::NAN));
    #[allow(clippy::cast_precision_loss)]
    let t_s = step.t_us as f64 * 1e-6;
    println!(
        "trace seed {seed} {variant:?} t {t_s:6.2} leg {leg} {:?} hyp {} obs {} in_view {} matched {} err {e:.3} m {:.2} deg; nearest hypothesis {ne:.3} m {:.2} deg; truth ({:.2}, {:.2}, {:.1} deg)",
        result.status,
        result.hypotheses,
        result.observations,
        step.lamps_in_view,
        result.matched.len(),
        h.to_degrees(),
        nh.to_degrees(),
        step.truth.x,
        step.truth.y,
        step.truth.theta.to_degrees()
    );
}

fn run(grid: Grid, seed: u64, variant: Variant, options: Options) -> Result<Outcome, String> {
    let mut hall = Hall::new(grid, seed);
    if options.exact_map {
        for (lamp, truth) in hall.map.iter_mut().zip(&hall.truth) {
            lamp.position = *truth;
        }
    }
    let legs: &[usize] = match variant {
        Variant::Start => &[2 * FRAMES_10_S],
        Variant::Kidnap => &[FRAMES_10_S, FRAMES_10_S],
    };
    let mut on_frame = |leg: usize, step: &Step, result: &FrameResult, l: &Localizer| {
        if options.trace {
            trace_frame(seed, variant, leg, step, result, l);
        }
    };
    support::run(&hall, seed, legs, &mut on_frame).map_err(|e| e.to_string())
}

/// The `q`-quantile of sorted values (nearest rank).
fn quantile(sorted: &[f64], q: f64) -> Option<f64> {
    if sorted.is_empty() {
        return None;
    }
    #[allow(
        clippy::cast_possible_truncation,
        clippy::cast_sign_loss,
        clippy::cast_precision_loss
    )]
    let k = ((q * sorted.len() as f64).ceil() as usize).clamp(1, sorted.len()) - 1;
    sorted.get(k).copied()
}

fn seconds(v: Option<f64>) -> String {
    v.map_or_else(|| "-".to_string(), |s| format!("{s:.2} s"))
}

/// One table row of leg `leg` over the runs: runs, fixed, correct-fix rate (fixed and no
/// false fix in the leg), time to fix (median, p95, worst, over the runs that fixed), false
/// fixes, error RMS while localised.
fn row(name: &str, results: &[Outcome], leg: usize) -> String {
    let legs: Vec<&Leg> = results.iter().filter_map(|r| r.legs.get(leg)).collect();
    let runs = legs.len();
    let mut fixed: Vec<f64> = legs.iter().filter_map(|l| l.fix_s).collect();
    fixed.sort_by(f64::total_cmp);
    let false_runs = legs.iter().filter(|l| l.false_frames > 0).count();
    let false_frames: u32 = legs.iter().map(|l| l.false_frames).sum();
    let correct = legs
        .iter()
        .filter(|l| l.fix_s.is_some() && l.false_frames == 0)
        .count();
    let n: u64 = legs.iter().map(|l| l.localized_frames).sum();
    let sq_m: f64 = legs.iter().map(|l| l.sum_sq_m).sum();
    let sq_rad: f64 = legs.iter().map(|l| l.sum_sq_rad).sum();
    #[allow(clippy::cast_precision_loss)]
    let (rms_mm, rms_deg) = (
        (sq_m / n.max(1) as f64).sqrt() * 1e3,
        (sq_rad / n.max(1) as f64).sqrt().to_degrees(),
    );
    let max_mm = legs.iter().map(|l| l.max_err_m).fold(0.0, f64::max) * 1e3;
    #[allow(clippy::cast_precision_loss)]
    let rate = 100.0 * correct as f64 / runs.max(1) as f64;
    format!(
        "| {name} | {runs} | {} | {rate:.1} % | {} | {} | {} | {false_runs} ({false_frames} frames) | {rms_mm:.1} mm, {rms_deg:.3} deg (max {max_mm:.0} mm) |",
        fixed.len(),
        seconds(quantile(&fixed, 0.5)),
        seconds(quantile(&fixed, 0.95)),
        seconds(fixed.last().copied()),
    )
}

/// The runs of `seeds`, on as many threads as the machine has (each run is independent and
/// seeded: the results do not depend on the threads; one thread with `--trace`), in seed
/// order.
fn runs(
    grid: Grid,
    seeds: std::ops::Range<u64>,
    variant: Variant,
    options: Options,
) -> Result<Vec<Outcome>, String> {
    let threads = if options.trace {
        1 // the trace in order
    } else {
        std::thread::available_parallelism().map_or(1, std::num::NonZero::get)
    };
    let seeds: Vec<u64> = seeds.collect();
    let chunk = seeds.len().div_ceil(threads).max(1);
    let parts: Vec<Result<Vec<Outcome>, String>> = std::thread::scope(|s| {
        let handles: Vec<_> = seeds
            .chunks(chunk)
            .map(|part| {
                s.spawn(move || {
                    part.iter()
                        .map(|&seed| run(grid, seed, variant, options))
                        .collect::<Result<Vec<Outcome>, String>>()
                })
            })
            .collect();
        handles
            .into_iter()
            .map(|h| {
                h.join()
                    .unwrap_or_else(|_| Err("a run panicked".to_string()))
            })
            .collect()
    });
    let mut out = Vec::with_capacity(seeds.len());
    for p in parts {
        out.extend(p?);
    }
    Ok(out)
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let options = Options {
        trace: args.iter().any(|a| a == "--trace"),
        exact_map: args.iter().any(|a| a == "--exact-map"),
    };
    let numbers: Vec<&String> = args.iter().filter(|a| !a.starts_with("--")).collect();
    let jittered_only = args.iter().any(|a| a == "--jittered-only");
    let grid = match args.iter().find_map(|a| a.strip_prefix("--grid=")) {
        None => Ok(GRID),
        Some(g) => g
            .split_once('x')
            .and_then(|(a, b)| Some((a.parse().ok()?, b.parse().ok()?)))
            .filter(|&(a, b): &(usize, usize)| a >= 2 && b >= 2)
            .ok_or_else(|| format!("--grid={g}: give it as NXxNY, e.g. --grid=125x80")),
    };
    let grid = match grid {
        Ok(g) => g,
        Err(e) => {
            eprintln!("{e}");
            return ExitCode::FAILURE;
        }
    };
    let parse = |k: usize, default: u64| -> Result<u64, String> {
        numbers.get(k).map_or(Ok(default), |s| {
            s.parse().map_err(|_| {
                format!(
                    "not a number: {s} (usage: reloc_mc [RUNS] [FIRST_SEED] [--trace] [--exact-map])"
                )
            })
        })
    };
    let (count, first) = match (parse(0, 100), parse(1, 0)) {
        (Ok(r), Ok(f)) => (r, f),
        (Err(e), _) | (_, Err(e)) => {
            eprintln!("{e}");
            return ExitCode::FAILURE;
        }
    };
    let (nx, ny) = grid;
    println!(
        "reloc_mc: {count} runs per grid and variant, seeds {first}..{}, grid {nx} x {ny} lamps at {} m, {} m up{}",
        first + count,
        support::SPACING_M,
        support::LAMP_HEIGHT_M,
        if options.exact_map {
            "; EXACT MAP (diagnosis: lamps saved without their errors)"
        } else {
            ""
        }
    );
    let started = Instant::now();
    let mut table = Vec::new();
    let mut findings = Vec::new();
    for (name, grid) in [
        ("regular", Grid::regular(nx, ny)),
        ("jittered", Grid::jittered(nx, ny)),
    ] {
        if jittered_only && name == "regular" {
            continue;
        }
        for variant in [Variant::Start, Variant::Kidnap] {
            let t = Instant::now();
            let results = match runs(grid, first..first + count, variant, options) {
                Ok(r) => r,
                Err(e) => {
                    eprintln!("{name} {variant:?}: {e}");
                    return ExitCode::FAILURE;
                }
            };
            let frames: u64 = results.iter().flat_map(|r| &r.legs).map(|l| l.frames).sum();
            let in_view: u64 = results
                .iter()
                .flat_map(|r| &r.legs)
                .map(|l| l.lamps_in_view)
                .sum();
            #[allow(clippy::cast_precision_loss)]
            let mean_in_view = in_view as f64 / frames.max(1) as f64;
            println!(
                "{name} {variant:?}: {:.1} s for {count} runs, {mean_in_view:.1} lamps in view a frame",
                t.elapsed().as_secs_f64()
            );
            let leg_names: &[&str] = match variant {
                Variant::Start => &["start, 20 s"],
                Variant::Kidnap => &["kidnap: first 10 s", "kidnap: 10 s after the gap"],
            };
            for (k, leg) in leg_names.iter().enumerate() {
                table.push(row(&format!("{name}, {leg}"), &results, k));
            }
            for r in &results {
                for (k, leg) in r.legs.iter().enumerate() {
                    let which = leg_names.get(k).copied().unwrap_or("?");
                    if let Some((t, e, h)) = leg.first_false {
                        findings.push(format!(
                            "FALSE FIX: {name} {which} seed {}: {} localised frames off, the first {t:.2} s into the leg: {e:.3} m, {h:.2} deg",
                            r.seed, leg.false_frames
                        ));
                    }
                    if leg.fix_s.is_none() && name == "jittered" {
                        findings.push(format!("NO FIX: {name} {which} seed {}", r.seed));
                    }
                }
                if r.refused > 0 {
                    findings.push(format!(
                        "REFUSED: {name} {variant:?} seed {}: {} inputs refused",
                        r.seed, r.refused
                    ));
                }
            }
        }
    }
    println!();
    println!(
        "| grid, variant | runs | fixed | correct-fix rate | time to fix: median | p95 | worst | false fixes: runs (frames) | error RMS while localised |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    for r in &table {
        println!("{r}");
    }
    println!();
    for f in &findings {
        println!("{f}");
    }
    println!(
        "{} findings; {:.1} s in all",
        findings.len(),
        started.elapsed().as_secs_f64()
    );
    ExitCode::SUCCESS
}
