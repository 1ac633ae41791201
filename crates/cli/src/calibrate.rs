//! `stereonav calibrate LOG.mcap [--rig RIG.toml] [--stride N] [--pairing disjoint|interleaved]
//! [--out RESULT.json]`: phase 1, self-calibration of the camera parameters, in batch on a
//! vehicle log (`replay::calibrate_log`).
//!
//! Prints a short summary on stdout: the solve's status, each estimated parameter with its
//! value, sigma and nominal value, the parameters the data cannot give and why, the hand-over
//! time of the incremental calibration, and what was read. `--out` writes the whole result as
//! JSON ([`result_json`]); it never holds NaN or infinity (`null` instead). Warnings (a log cut
//! short, a rig file that differs from the log's) go to stderr, one line each.

use std::fmt::Write as _;
use std::io::{self, Write};
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use replay::{Counts, FramePairSettings, LogCalibration, NavSettings, RigSource};
use rig_model::handover::{Handover, ObservabilityReport};
use rig_model::{CameraParams, Param, ParamVector, Rig};
use selfcal::solve::{Calibration, SolveStatus};
use serde_json::{Map, Value, json};
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
        let text = serde_json::to_string_pretty(&result_json(&result))
            .context("cannot format the result as JSON")?;
        std::fs::write(path, text + "\n")
            .with_context(|| format!("cannot write {}", path.display()))?;
    }
    let mut stdout = io::stdout().lock();
    stdout.write_all(summary(&args.log, args.rig.as_deref(), &result).as_bytes())?;
    stdout.flush()?;
    Ok(())
}

/// `"converged"`, `"max_iterations"`, `"stalled"` or `"no_data"`, as in the Python package.
fn status_name(status: SolveStatus) -> &'static str {
    match status {
        SolveStatus::Converged => "converged",
        SolveStatus::MaxIterations => "max_iterations",
        SolveStatus::Stalled => "stalled",
        SolveStatus::NoData => "no_data",
    }
}

/// Whether the solve estimated `p` from the data: the rig asks for it and the data constrain
/// it. Every other parameter is at its nominal value with sigma 0.
fn is_estimated(report: &ObservabilityReport, p: Param) -> bool {
    report.params.iter().any(|o| o.param == p && o.observable)
}

/// A JSON number, or `null` for NaN and infinity (JSON has neither).
fn number(x: f64) -> Value {
    serde_json::Number::from_f64(x).map_or(Value::Null, Value::Number)
}

fn vector(v: &ParamVector) -> Value {
    Value::Array(v.iter().copied().map(number).collect())
}

/// `{"<param>": {"value", "sigma"}}` for the ten parameters of C.
fn camera_values(camera: &CameraParams, sigma: impl Fn(Param) -> f64) -> Map<String, Value> {
    Param::CAMERA
        .iter()
        .map(|&p| {
            let entry = json!({"value": number(camera.get(p)), "sigma": number(sigma(p))});
            (p.name().to_string(), entry)
        })
        .collect()
}

fn counts_json(c: &Counts) -> Value {
    Value::Object(
        c.named()
            .into_iter()
            .map(|(name, value)| (name.to_string(), json!(value)))
            .collect(),
    )
}

fn observability_json(report: &ObservabilityReport) -> Value {
    report
        .params
        .iter()
        .map(|o| {
            json!({
                "parameter": o.param.name(),
                "prior_sigma": number(o.prior_sigma),
                "data_sigma": number(o.data_sigma),
                "posterior_sigma": number(o.posterior_sigma),
                "observable": o.observable,
                "reason": o.reason,
                "structural": o.structural,
            })
        })
        .collect()
}

fn correlation_json(report: &ObservabilityReport) -> Value {
    report.max_correlation.map_or(
        Value::Null,
        |(a, b, r)| json!({"first": a.name(), "second": b.name(), "value": number(r)}),
    )
}

fn handover_json(h: &Handover) -> Value {
    json!({
        "t_us": h.t_us,
        "camera": camera_values(&h.camera, |p| {
            h.covariance[(p.index(), p.index())].max(0.0).sqrt()
        }),
        "observability": observability_json(&h.observability),
        "max_correlation": correlation_json(&h.observability),
    })
}

/// The `--out` document.
///
/// `status`, `iterations`, `residuals`, `outliers`, `reduced_chi2` of the batch solve;
/// `camera`: every parameter's `value`, `sigma`, `nominal` and whether the data `estimated`
/// it; `observability`: one record per parameter of the rig's `[estimate]` list;
/// `max_correlation`; `handover`: the incremental calibration's hand-over to phase 2, or
/// `null` when it never became stable; `history`: the ten values (in `parameters` order)
/// after each Levenberg-Marquardt iteration of the batch solve, the start first;
/// `incremental`: `t_us`, `values` and `sigmas` after each incremental solve up to the
/// hand-over; `counts`; `warnings`; `rig_source` (`"given"` or `"log"`).
fn result_json(result: &LogCalibration) -> Value {
    let cal: &Calibration = &result.calibration;
    let report = &cal.observability;
    let entries = |params: &[Param]| -> Map<String, Value> {
        params
            .iter()
            .map(|&p| {
                let entry = json!({
                    "value": number(cal.camera.get(p)),
                    "sigma": number(cal.sigma(p)),
                    "nominal": number(result.rig.nominal.get(p)),
                    "estimated": is_estimated(report, p),
                });
                (p.name().to_string(), entry)
            })
            .collect()
    };
    let camera = entries(&Param::CAMERA);
    let vehicle = entries(&Param::VEHICLE);
    let incremental: Vec<Value> = result
        .history
        .iter()
        .map(|(t_us, values, sigmas)| {
            json!({"t_us": t_us, "values": vector(values), "sigmas": vector(sigmas)})
        })
        .collect();
    json!({
        "status": status_name(cal.status),
        "iterations": cal.iterations,
        "residuals": cal.residuals,
        "outliers": cal.outliers,
        "reduced_chi2": number(cal.reduced_chi2),
        "rig_source": rig_source_name(result.rig_source),
        "parameters": Param::ALL.iter().map(|p| p.name()).collect::<Vec<_>>(),
        "camera": camera,
        "vehicle": vehicle,
        "observability": observability_json(report),
        "max_correlation": correlation_json(report),
        "handover": result.handover.as_ref().map_or(Value::Null, handover_json),
        "history": cal.history.iter().map(vector).collect::<Vec<_>>(),
        "incremental": incremental,
        "counts": counts_json(&result.counts),
        "warnings": result.warnings,
    })
}

fn rig_source_name(source: RigSource) -> &'static str {
    match source {
        RigSource::Given => "given",
        RigSource::Log => "log",
    }
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
        status_name(cal.status),
        cal.iterations,
        cal.residuals,
        cal.outliers,
        cal.reduced_chi2
    );
    let estimated: Vec<Param> = Param::ALL
        .into_iter()
        .filter(|&p| is_estimated(report, p))
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
    fn non_finite_numbers_become_null() {
        assert_eq!(number(f64::INFINITY), Value::Null);
        assert_eq!(number(f64::NAN), Value::Null);
        assert_eq!(number(1.5), json!(1.5));
    }

    #[test]
    fn values_show_two_digits_of_their_sigma() {
        assert_eq!(with_sigma(720.777_1, 0.482), "720.78 ± 0.48");
        assert_eq!(with_sigma(0.116_524, 0.000_392), "0.11652 ± 0.00039");
        assert_eq!(with_sigma(700.0, 0.0), "700");
        assert_eq!(with_sigma(1234.5, 35.0), "1234 ± 35");
    }
}
