//! What the scrub bench and the window example share: the warehouse log they scrub, the
//! scrub's positions and the summary of per-frame times.

use std::path::{Path, PathBuf};

use replay::NavSettings;
use viewer::{LoadOptions, Model};

/// The warehouse scenario (fast mode, its seed) simulated into a temporary file named after
/// `tag` and this process.
pub(crate) fn simulate_warehouse(tag: &str) -> Result<PathBuf, String> {
    let scenario =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/scenarios/warehouse.toml");
    let sc = sim::Scenario::load(&scenario).map_err(|e| e.to_string())?;
    let run = sim::simulate(&sc, sim::Mode::Fast).map_err(|e| e.to_string())?;
    let path = std::env::temp_dir().join(format!("{tag}-{}.mcap", std::process::id()));
    run.write_log(&path).map_err(|e| e.to_string())?;
    Ok(path)
}

/// A log replayed with the default settings and loaded.
pub(crate) fn load(path: &Path) -> Result<Model, String> {
    let settings = NavSettings::default();
    viewer::load(
        path,
        &LoadOptions {
            rig: None,
            settings,
            map: None,
            topics: None,
        },
        &mut |_, _| {},
    )
    .map_err(|e| e.to_string())
}

/// `n` positions sweeping the log forward then back, as a slider dragged to and fro.
pub(crate) fn scrub_times(duration_s: f64, n: usize) -> Vec<f64> {
    (0..n)
        .map(|i| {
            let phase = (i as f64 / n as f64) * 2.0;
            let x = if phase <= 1.0 { phase } else { 2.0 - phase };
            // An irrational step so that consecutive positions land on different frames.
            (x * duration_s + i as f64 * 0.618_034).rem_euclid(duration_s.max(1e-9))
        })
        .collect()
}

/// One line of statistics of per-frame times in milliseconds: count, mean, median, 99th
/// percentile, worst and how many were over the 50 ms target.
pub(crate) fn summary(name: &str, mut ms: Vec<f64>) -> String {
    if ms.is_empty() {
        return format!("{name}: no frames");
    }
    ms.sort_by(f64::total_cmp);
    let at = |q: usize| ms.get(q).copied().unwrap_or(f64::NAN);
    let mean = ms.iter().sum::<f64>() / ms.len() as f64;
    let over = ms.iter().filter(|x| **x > 50.0).count();
    format!(
        "{name}: {} frames, mean {mean:.2} ms, median {:.2} ms, 99th percentile {:.2} ms, worst {:.2} ms, {over} over 50 ms",
        ms.len(),
        at(ms.len() / 2),
        at(ms.len() * 99 / 100),
        at(ms.len() - 1),
    )
}
