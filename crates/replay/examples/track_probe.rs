//! The front end alone on a log: how stable each track's measurements are (on a standing
//! vehicle a lamp's four pixels should not move), and how the stereo disparity of a track
//! changes over its life. A diagnostic for real logs (docs/real-images.md).
//!
//! `cargo run --release -p replay --example track_probe -- LOG.mcap RIG.toml`
#![allow(clippy::print_stdout, clippy::print_stderr)] // a command-line tool

use std::collections::BTreeMap;
use std::process::ExitCode;

use track::{FrontEnd, FrontEndSettings, Model};

fn main() -> ExitCode {
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("track_probe: {e}");
            ExitCode::FAILURE
        }
    }
}

fn run() -> Result<(), String> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let usage = "usage: track_probe LOG.mcap RIG.toml";
    let log = args.first().ok_or(usage)?;
    let rig_path = args.get(1).ok_or(usage)?;
    let text = std::fs::read_to_string(rig_path).map_err(|e| format!("{rig_path}: {e}"))?;
    let rig = rig_model::config::Rig::from_toml_str(&text, rig_path).map_err(|e| e.to_string())?;
    let input = replay::read_vehicle_log(std::path::Path::new(log), Some(rig.clone()))
        .map_err(|e| e.to_string())?;
    let mut fe = FrontEnd::new(Model::from_rig(&rig), FrontEndSettings::default())
        .map_err(|e| e.to_string())?;
    let mut odometry = input.odometry.iter().peekable();
    let mut tracks: BTreeMap<u64, Vec<(usize, rig_model::Measurement, bool)>> = BTreeMap::new();
    let mut per_frame = Vec::new();
    for (k, f) in input.frames.iter().enumerate() {
        while let Some(s) = odometry.next_if(|s| s.t_us <= f.t_us) {
            fe.push_odometry(*s);
        }
        let t = fe.push_frame(f.t_us, &f.left, &f.right);
        per_frame.push((
            f.left.len(),
            f.right.len(),
            t.observations.len(),
            t.confirmed().count(),
        ));
        for o in &t.observations {
            tracks
                .entry(o.track.0)
                .or_default()
                .push((k, o.measurement, o.confirmed));
        }
    }
    let n = per_frame.len().max(1);
    let mean = |i: usize| {
        per_frame
            .iter()
            .map(|p| [p.0, p.1, p.2, p.3][i] as f64)
            .sum::<f64>()
            / n as f64
    };
    println!(
        "{} frames: features left {:.0} right {:.0} a frame; stereo tracks {:.0}, confirmed {:.0} a frame; {} tracks in all",
        per_frame.len(),
        mean(0),
        mean(1),
        mean(2),
        mean(3),
        tracks.len()
    );
    let mut lengths: Vec<usize> = tracks.values().map(Vec::len).collect();
    lengths.sort_unstable();
    println!(
        "track length: median {}, 90 % {}, max {}",
        lengths.get(lengths.len() / 2).copied().unwrap_or(0),
        lengths.get(lengths.len() * 9 / 10).copied().unwrap_or(0),
        lengths.last().copied().unwrap_or(0)
    );
    // Long tracks: spread of uL and of the disparity over the track, and the drift of the
    // disparity from its first third to its last third.
    let (mut spread_u, mut spread_d, mut drift) = (Vec::new(), Vec::new(), Vec::new());
    for obs in tracks.values().filter(|o| o.len() >= 20) {
        let d: Vec<f64> = obs.iter().map(|(_, z, _)| z[0] - z[2]).collect();
        let u: Vec<f64> = obs.iter().map(|(_, z, _)| z[0]).collect();
        let range = |v: &[f64]| {
            v.iter().copied().fold(f64::NEG_INFINITY, f64::max)
                - v.iter().copied().fold(f64::INFINITY, f64::min)
        };
        spread_u.push(range(&u));
        spread_d.push(range(&d));
        let third = d.len() / 3;
        let a: f64 = d[..third].iter().sum::<f64>() / third as f64;
        let b: f64 = d[d.len() - third..].iter().sum::<f64>() / third as f64;
        drift.push((b - a) / a.abs().max(1e-9));
    }
    for v in [&mut spread_u, &mut spread_d, &mut drift] {
        v.sort_by(f64::total_cmp);
    }
    let q = |v: &[f64], p: f64| {
        v.get(((v.len() as f64 - 1.0) * p) as usize)
            .copied()
            .unwrap_or(f64::NAN)
    };
    println!(
        "{} tracks of 20+ frames: uL range median {:.3} px (90 % {:.3}); disparity range median {:.3} px (90 % {:.3}, max {:.2}); relative disparity drift first -> last third: median {:+.4}, 10 % {:+.4}, 90 % {:+.4}, mean {:+.4}",
        spread_u.len(),
        q(&spread_u, 0.5),
        q(&spread_u, 0.9),
        q(&spread_d, 0.5),
        q(&spread_d, 0.9),
        q(&spread_d, 1.0),
        q(&drift, 0.5),
        q(&drift, 0.1),
        q(&drift, 0.9),
        drift.iter().sum::<f64>() / drift.len().max(1) as f64
    );
    // The image's common motion: per frame, the mean shift of every track seen in the frame
    // and in the first frame it was seen in (left pixel), against that first frame.
    let mut shift: Vec<(f64, f64, f64, usize)> = vec![(0.0, 0.0, 0.0, 0); per_frame.len()];
    for obs in tracks.values().filter(|o| o.len() >= 20) {
        let (_, z0, _) = obs[0];
        let d0 = z0[0] - z0[2];
        for (k, z, _) in obs {
            if let Some(s) = shift.get_mut(*k) {
                s.0 += z[0] - z0[0];
                s.1 += z[1] - z0[1];
                s.2 += (z[0] - z[2]) - d0;
                s.3 += 1;
            }
        }
    }
    for (k, s) in shift.iter().enumerate().step_by(10) {
        let n = s.3.max(1) as f64;
        println!(
            "frame {k:3}: mean shift of the long tracks since their first frame: du {:+.3} dv {:+.3} px, disparity {:+.3} px ({} tracks)",
            s.0 / n,
            s.1 / n,
            s.2 / n,
            s.3
        );
    }
    Ok(())
}
