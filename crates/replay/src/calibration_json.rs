//! The whole result of phase 1 on a log (`replay::calibrate_log`) as one JSON document: what
//! `stereonav calibrate --out RESULT.json` writes and Python's `calibrate_log(...).document`
//! gives, from this one function.

use rig_model::handover::{Handover, ObservabilityReport};
use rig_model::{CameraParams, Param, ParamVector};
use selfcal::solve::{Calibration, SolveStatus};
use serde_json::{Map, Value, json};

use crate::{Counts, LogCalibration, RigSource};

/// `"converged"`, `"max_iterations"`, `"stalled"` or `"no_data"`, as in the Python package.
pub fn solve_status_name(status: SolveStatus) -> &'static str {
    match status {
        SolveStatus::Converged => "converged",
        SolveStatus::MaxIterations => "max_iterations",
        SolveStatus::Stalled => "stalled",
        SolveStatus::NoData => "no_data",
    }
}

/// Whether the solve estimated `p` from the data: the rig asks for it and the data constrain
/// it. Every other parameter is at its nominal value with sigma 0.
pub fn is_estimated(report: &ObservabilityReport, p: Param) -> bool {
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

/// The `stereonav calibrate --out` document (Python: `LogCalibration.document`).
///
/// `status`, `iterations`, `residuals`, `outliers`, `reduced_chi2` of the batch solve;
/// `camera`: every parameter's `value`, `sigma`, `nominal` and whether the data `estimated`
/// it; `observability`: one record per parameter of the rig's `[estimate]` list;
/// `max_correlation`; `handover`: the incremental calibration's hand-over to phase 2, or
/// `null` when it never became stable; `history`: the ten values (in `parameters` order)
/// after each Levenberg-Marquardt iteration of the batch solve, the start first;
/// `incremental`: `t_us`, `values` and `sigmas` after each incremental solve up to the
/// hand-over; `counts`; `warnings`; `rig_source` (`"given"` or `"log"`).
pub fn calibration_json(result: &LogCalibration) -> Value {
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
        "status": solve_status_name(cal.status),
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn non_finite_numbers_become_null() {
        assert_eq!(number(f64::INFINITY), Value::Null);
        assert_eq!(number(f64::NAN), Value::Null);
        assert_eq!(number(1.5), json!(1.5));
    }
}
