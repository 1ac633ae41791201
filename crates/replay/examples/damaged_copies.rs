//! Bit errors in a vehicle log, replayed: `copies` copies of a log, each with 1 to 10 bits
//! flipped at random (seeded), replayed with the default settings; for each copy, the share of
//! the board's frames it kept against the share of the board stream lying in the chunks the
//! flips did not touch (the most a reader that skips damaged chunks can keep).
//!
//! `cargo run --release -p replay --example damaged_copies -- LOG [COPIES] [SEED]`
//!
//! Prints one line per copy and the median and worst of `kept / allowed`.
#![allow(clippy::print_stdout, clippy::print_stderr)]

use std::path::{Path, PathBuf};

use replay::{NavSettings, replay_log};

/// A small deterministic generator (splitmix64): the copies must be the same every run.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }
    fn below(&mut self, n: u64) -> u64 {
        self.next() % n.max(1)
    }
}

/// `(offset, length, features bytes inside)` of every chunk, from the intact file's summary.
fn chunks(bytes: &[u8]) -> Result<Vec<(u64, u64, u64)>, String> {
    let summary = mcap::Summary::read(bytes)
        .map_err(|e| e.to_string())?
        .ok_or("no summary")?;
    let features: Vec<u16> = summary
        .channels
        .values()
        .filter(|c| c.topic == "/fpga/features")
        .map(|c| c.id)
        .collect();
    let mut out = Vec::new();
    for index in &summary.chunk_indexes {
        let mut feature_bytes = 0u64;
        for m in summary
            .stream_chunk(bytes, index)
            .map_err(|e| e.to_string())?
        {
            let m = m.map_err(|e| e.to_string())?;
            if features.contains(&m.channel.id) {
                feature_bytes += m.data.len() as u64;
            }
        }
        out.push((index.chunk_start_offset, index.chunk_length, feature_bytes));
    }
    Ok(out)
}

fn run() -> Result<(), String> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let log = PathBuf::from(
        args.first()
            .ok_or("usage: damaged_copies LOG [COPIES] [SEED]")?,
    );
    let copies: usize = args
        .get(1)
        .map_or(Ok(30), |s| s.parse())
        .map_err(|e| format!("{e}"))?;
    let seed: u64 = args
        .get(2)
        .map_or(Ok(1), |s| s.parse())
        .map_err(|e| format!("{e}"))?;
    let bytes = std::fs::read(&log).map_err(|e| format!("{}: {e}", log.display()))?;
    let chunks = chunks(&bytes)?;
    let total_feature_bytes: u64 = chunks.iter().map(|c| c.2).sum();
    let settings = NavSettings::default();
    let reference = replay_log(&log, None, &settings, &mut |_, _| {}).map_err(|e| e.to_string())?;
    let frames = reference.frames.len() as f64;
    println!(
        "{}: {} bytes, {} chunks, {} frames",
        log.display(),
        bytes.len(),
        chunks.len(),
        reference.frames.len()
    );
    let dir = std::env::temp_dir().join("stereonav-damaged-copies");
    std::fs::create_dir_all(&dir).map_err(|e| e.to_string())?;
    let mut rng = Rng(seed);
    let mut ratios = Vec::new();
    for copy in 0..copies {
        let mut damaged = bytes.clone();
        let flips = 1 + rng.below(10) as usize;
        let mut touched = vec![false; chunks.len()];
        for _ in 0..flips {
            let at = rng.below(damaged.len() as u64);
            let bit = rng.below(8);
            if let Some(b) = damaged.get_mut(at as usize) {
                *b ^= 1 << bit;
            }
            for (i, (start, len, _)) in chunks.iter().enumerate() {
                if at >= *start && at < start + len {
                    touched[i] = true;
                }
            }
        }
        let intact: u64 = chunks
            .iter()
            .zip(&touched)
            .filter(|(_, t)| !**t)
            .map(|(c, _)| c.2)
            .sum();
        let allowed = intact as f64 / total_feature_bytes.max(1) as f64;
        let path: PathBuf = dir.join(format!("copy-{copy}.mcap"));
        std::fs::write(&path, &damaged).map_err(|e| e.to_string())?;
        let (kept, note) = match replay_log(Path::new(&path), None, &settings, &mut |_, _| {}) {
            Ok(r) => {
                let ate = r.truth.as_ref().map_or(f64::NAN, |t| t.ate_max);
                (
                    r.frames.len() as f64 / frames,
                    format!("ate max {:.3} m", ate),
                )
            }
            Err(e) => (0.0, format!("refused: {e}")),
        };
        let ratio = if allowed > 0.0 { kept / allowed } else { 1.0 };
        ratios.push(ratio);
        println!(
            "copy {copy:2}: {flips:2} flips, {:2} chunks hit, allowed {:5.1} %, kept {:5.1} %, kept/allowed {:5.1} %, {note}",
            touched.iter().filter(|t| **t).count(),
            100.0 * allowed,
            100.0 * kept,
            100.0 * ratio
        );
    }
    ratios.sort_by(f64::total_cmp);
    let median = ratios.get(ratios.len() / 2).copied().unwrap_or(f64::NAN);
    let worst = ratios.first().copied().unwrap_or(f64::NAN);
    println!(
        "kept/allowed: median {:.1} %, worst {:.1} %",
        100.0 * median,
        100.0 * worst
    );
    Ok(())
}

fn main() -> std::process::ExitCode {
    match run() {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("damaged_copies: {e}");
            std::process::ExitCode::FAILURE
        }
    }
}
