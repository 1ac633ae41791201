//! `stereonav calibrate LOG.mcap [--rig RIG.toml] [--stride N] [--pairing disjoint|interleaved]
//! [--out RESULT.json]`: phase 1, self-calibration of the camera parameters, in batch on a
//! vehicle log (`replay::calibrate_log`).
//!
//! Prints a short summary on stdout: the solve's status, each estimated parameter with its
//! value, sigma and nominal value, the parameters the data cannot give and why, the hand-over
//! time of the incremental calibration, and what was read. `--out` writes the whole result as
//! JSON (`replay::calibration_json`, which Python's `calibrate_log` gives too); it never holds
//! NaN or infinity (`null` instead). Warnings (a log cut
//! short, a rig file that differs from the log's) go to stderr, one line each.

use std::fmt::Write as _;
use std::io::{self, Write};
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use replay::{FramePairSettings, LogCalibration, NavSettings, RigSource};
use rig_model::{Param, Rig};
use track::{PairSettings, PairingScheme};

/// Arguments of `stereonav calibrate`.
#[derive(Debug, clap::Args)]
pub(crate) struct Args {
    /// The vehicle log (MCAP, vehicle-interfaces.md section 4).
    #[arg(value_name = "LOG.mcap")]
    log: PathBuf,
    /// The rig file (TOML, section 3); without it, the log's /rig message.
    #[arg(long, value_name = "RIG.toml")]
    rig: Option<PathBuf>,
    /// Frames from the first frame of a pair to its second (at 20 Hz, 40 frames are 2 s).
    #[arg(long, value_name = "N", default_value_t = PairSettings::default().stride)]
    stride: usize,
    /// Which frames are paired: disjoint pairs (no frame in two pairs) or interleaved ones
    /// (every frame in exactly one pair).
    #[arg(long, value_enum, default_value_t = Pairing::Disjoint)]
    pairing: Pairing,
    /// Also write the whole result here as JSON.
    #[arg(long, value_name = "RESULT.json")]
    out: Option<PathBuf>,
}

/// `--pairing`: [`PairingScheme`] for clap.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum Pairing {
    /// `(0, s)`, `(s + 1, 2s + 1)`, ...
    Disjoint,
    /// `(k, k + s)` for `k` in each block `[j 2s, j 2s + s)`.
    Interleaved,
}

impl From<Pairing> for PairingScheme {
    fn from(p: Pairing) -> Self {
        match p {
            Pairing::Disjoint => Self::Disjoint,
            Pairing::Interleaved => Self::Interleaved,
        }
    }
}

pub(crate) fn run(args: &Args) -> Result<()> {
    let defaults = FramePairSettings::default();
    let settings = NavSettings {
        frame_pairs: FramePairSettings {
            pairs: PairSettings {
                scheme: args.pairing.into(),
                stride: args.stride,
                ..defaults.pairs
            },
            ..defaults
        },
        ..NavSettings::default()
    };
    // Before the log is read: a bad setting should not wait for a long log.
    settings
        .frame_pairs
        .pairs
        .validate()
        .with_context(|| format!("--stride {}", args.stride))?;
    let rig = args.rig.as_deref().map(Rig::load).transpose()?;
    let result = replay::calibrate_log(&args.log, rig, &settings)?;

    {
        let mut stderr = io::stderr().lock();
        for warning in &result.warnings {
            writeln!(stderr, "stereonav: warning: {warning}")?;
        }
    }
    if let Some(path) = &args.out {
        let text = serde_json::to_string_pretty(&replay::calibration_json(&result))
            .context("cannot format the result as JSON")?;
        std::fs::write(path, text + "\n")
            .with_context(|| format!("cannot write {}", path.display()))?;
    }
    let mut stdout = io::stdout().lock();
    stdout.write_all(summary(&args.log, args.rig.as_deref(), &result).as_bytes())?;
    stdout.flush()?;
    Ok(())
}

/// `x ± sigma` with as many decimals as the sigma's two leading digits need.
fn with_sigma(x: f64, sigma: f64) -> String {
    if !(sigma.is_finite() && sigma > 0.0) {
        return format!("{x}");
    }
    // Two significant digits of sigma; the cast is of a small integer (at most 12).
    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
    let decimals = (1.0 - sigma.log10().floor()).clamp(0.0, 12.0) as usize;
    format!("{x:.decimals$} ± {sigma:.decimals$}")
}

/// The human summary printed on stdout.
fn summary(log: &Path, rig_path: Option<&Path>, result: &LogCalibration) -> String {
    let cal = &result.calibration;
    let report = &cal.observability;
    let mut s = String::new();
    // Writing to a String cannot fail.
    let _ = writeln!(s, "{}: phase-1 calibration", log.display());
    let _ = match (result.rig_source, rig_path) {
        (RigSource::Given, Some(path)) => writeln!(s, "rig: {}", path.display()),
        _ => writeln!(s, "rig: the log's /rig message"),
    };
    let _ = writeln!(
        s,
        "status: {} after {} iterations ({} landmark residuals, {} outliers, reduced chi2 {:.2})",
        replay::solve_status_name(cal.status),
        cal.iterations,
        cal.residuals,
        cal.outliers,
        cal.reduced_chi2
    );
    let estimated: Vec<Param> = Param::ALL
        .into_iter()
        .filter(|&p| replay::is_estimated(report, p))
        .collect();
    if estimated.is_empty() {
        let _ = writeln!(s, "estimated: none (every parameter at its nominal value)");
    } else {
        let _ = writeln!(s, "estimated:");
        for p in estimated {
            let _ = writeln!(
                s,
                "  {:<11} {}  (nominal {})",
                p.name(),
                with_sigma(cal.camera.get(p), cal.sigma(p)),
                result.rig.nominal.get(p)
            );
        }
    }
    for o in report.unobservable() {
        let _ = writeln!(
            s,
            "not observable: {} held at {}: {}",
            o.param,
            result.rig.nominal.get(o.param),
            o.reason.unwrap_or("the data do not constrain it")
        );
    }
    let _ = match &result.handover {
        Some(h) => writeln!(
            s,
            "hand-over to phase 2: at t_us {} (stable after {} incremental solves)",
            h.t_us,
            result.history.len()
        ),
        None => writeln!(
            s,
            "hand-over to phase 2: not stable ({} incremental solves)",
            result.history.len()
        ),
    };
    let c = &result.counts;
    let _ = writeln!(
        s,
        "counts: {} frames, {} corrupt, {} lost, {} pairs ({} landmark pairs), {} odometry samples",
        c.frames, c.corrupt, c.lost, c.pairs, c.landmark_pairs, c.odometry
    );
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn values_show_two_digits_of_their_sigma() {
        assert_eq!(with_sigma(720.777_1, 0.482), "720.78 ± 0.48");
        assert_eq!(with_sigma(0.116_524, 0.000_392), "0.11652 ± 0.00039");
        assert_eq!(with_sigma(700.0, 0.0), "700");
        assert_eq!(with_sigma(1234.5, 35.0), "1234 ± 35");
    }
}
