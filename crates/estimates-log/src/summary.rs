//! The summary of a replay ([`summary_json`], [`end_summary_json`]): the `/est/summary`
//! message of `EST.mcap` (schema `stereonav.Summary`), which the replay also writes as
//! `SUMMARY.json`.

use serde_json::{Value, json};

use crate::{
    Counts, FrameEstimate, LandmarkEstimate, OdometryModel, ParamEstimate, Replay, ReplayEnd,
    TruthErrors,
};

/// What the summary is made of, borrowed from a [`Replay`] or a [`ReplayEnd`].
struct SummaryParts<'a> {
    counts: &'a Counts,
    phase_switch_t_us: Option<u64>,
    last_frame: Option<&'a FrameEstimate>,
    final_camera: &'a [ParamEstimate],
    landmarks: &'a [LandmarkEstimate],
    phase1_skipped: bool,
    warnings: &'a [String],
    frames_processed: u64,
    truth: Option<&'a TruthErrors>,
    log_damage: Option<&'a vehicle_log::Damage>,
    odometry: Option<&'a OdometryModel>,
}

/// The content of `SUMMARY.json`, and of the `/est/summary` message.
///
/// The keys of vehicle-interfaces.md section 5:
///
/// - `frames`, `corrupt`, `lost`: the decoder's counts (good packets, rejected packets, gaps in
///   the frame counter);
/// - `phase_switch_t_us`: when phase 2 started, or `null`;
/// - `pose`: `{t_us, x, y, theta}` at the last frame, or `null` when no frame was processed;
/// - `camera`: `{name: {value, sigma}}` for every parameter of `C` (the final estimate);
/// - `vehicle`: the same for every parameter of `V` (1.2);
/// - `landmarks`: `[{id, x, y, z, sigma: [sx, sy, sz], observations}]`, the final map;
///
/// and also:
///
/// - `phase1_skipped`: phase 2 ran from the rig's nominal values;
/// - `warnings`: one line each;
/// - `counts`: the other counters, by their [`Counts`] names, and `frames_processed` (the
///   frames in the trajectory);
/// - `truth`: `null`, or the errors against the simulator's truth: `landmark_rms_m`,
///   `landmark_rms_aligned_m`, `landmarks_matched`, `landmarks_unmatched`, `landmarks_duplicate`, `lamps_missed`,
///   `match_radius_m`, `ate_rms_m`, `ate_max_m`, `heading_rms_rad`, `camera` and `vehicle`
///   (`{name: estimate - truth}`);
/// - `log_damage`: `null` for a log read whole, or what the reader could not read:
///   `spans_total`, `bytes_lost`, `chunks_lost`, `messages_lost` (`{topic: n}` or `null`),
///   `header_damaged`, `tail_damaged`, `cut`, `summary` (`"intact"`, `"absent"` or
///   `"damaged: why"`), `unverified_chunks`, `repaired_chunks`, and `spans`, the first 100 stretches lost:
///   `{offset, bytes, start_ns, end_ns, exact_times, chunks, messages, why}`.
///
/// Non-finite numbers are `null` (see the crate docs).
pub fn summary_json(replay: &Replay) -> Value {
    summary_value(&SummaryParts {
        counts: &replay.counts,
        phase_switch_t_us: replay.phase_switch_t_us,
        last_frame: replay.frames.last(),
        final_camera: &replay.final_camera,
        landmarks: &replay.landmarks,
        phase1_skipped: replay.phase1_skipped,
        warnings: &replay.warnings,
        frames_processed: replay.frames.len() as u64,
        truth: replay.truth.as_ref(),
        log_damage: replay.log_damage.as_ref(),
        odometry: replay.odometry.as_ref(),
    })
}

/// [`summary_json`] of a streaming replay's end (the same keys and values as of the
/// [`Replay`] of the same log).
pub fn end_summary_json(end: &ReplayEnd) -> Value {
    summary_value(&SummaryParts {
        counts: &end.counts,
        phase_switch_t_us: end.phase_switch_t_us,
        last_frame: end.last_frame.as_ref(),
        final_camera: &end.final_camera,
        landmarks: &end.landmarks,
        phase1_skipped: end.phase1_skipped,
        warnings: &end.warnings,
        frames_processed: end.frames_processed,
        truth: end.truth.as_ref(),
        log_damage: end.log_damage.as_ref(),
        odometry: end.odometry.as_ref(),
    })
}

fn summary_value(s: &SummaryParts<'_>) -> Value {
    let c = s.counts;
    let pose = s.last_frame.map_or(Value::Null, |f| {
        let [x, y, theta] = f.pose;
        json!({"t_us": f.t_us, "x": x, "y": y, "theta": theta})
    });
    json!({
        "frames": c.frames,
        "corrupt": c.corrupt,
        "lost": c.lost,
        "phase_switch_t_us": s.phase_switch_t_us,
        "pose": pose,
        "camera": params_json(camera_part(s.final_camera)),
        "vehicle": params_json(vehicle_part(s.final_camera)),
        "landmarks": s.landmarks.iter().map(landmark_json).collect::<Vec<_>>(),
        "phase1_skipped": s.phase1_skipped,
        "warnings": s.warnings,
        "counts": counts_json(c, s.frames_processed),
        "truth": s.truth.map_or(Value::Null, truth_json),
        "log_damage": s.log_damage.map_or(Value::Null, damage_json),
        "odometry": s.odometry.map_or(Value::Null, odometry_json),
    })
}

/// The summary's `odometry`: the rig file's noise model, the one used, and the widening.
fn odometry_json(o: &OdometryModel) -> Value {
    let [velocity, yaw_rate, velocity_tau, yaw_rate_tau] = o.stated;
    json!({
        "velocity": velocity,
        "yaw_rate": yaw_rate,
        "velocity_tau": velocity_tau,
        "yaw_rate_tau": yaw_rate_tau,
        "used_velocity": o.used[0],
        "used_yaw_rate": o.used[1],
        "widened": o.widened.map_or(Value::Null, |w| json!({
            "t_us": w.t_us,
            "span_s": w.span_s,
            "translation_ratio": w.ratios[0],
            "heading_ratio": w.ratios[1],
            "variance_factors": w.variance_factors,
            "time_constants_s": w.time_constants_s,
        })),
    })
}

/// Lost stretches listed in the summary's `log_damage` (the counts hold the totals).
const MAX_SUMMARY_SPANS: usize = 100;

fn damage_json(d: &vehicle_log::Damage) -> Value {
    let summary = match &d.summary {
        vehicle_log::SummaryState::Intact => "intact".to_owned(),
        vehicle_log::SummaryState::Damaged { why } => format!("damaged: {why}"),
        _ => "absent".to_owned(),
    };
    let spans: Vec<Value> = d
        .spans
        .iter()
        .take(MAX_SUMMARY_SPANS)
        .map(|s| {
            json!({
                "offset": s.offset,
                "bytes": s.bytes,
                "start_ns": s.start_ns,
                "end_ns": s.end_ns,
                "exact_times": s.exact_times,
                "chunks": s.chunks,
                "messages": s.messages,
                "why": s.why,
            })
        })
        .collect();
    json!({
        "spans_total": d.spans_total,
        "bytes_lost": d.bytes_lost,
        "chunks_lost": d.chunks_lost,
        "messages_lost": d.messages_lost,
        "header_damaged": d.header_damaged,
        "tail_damaged": d.tail_damaged,
        "cut": d.cut,
        "summary": summary,
        "unverified_chunks": d.unverified_chunks,
        "repaired_chunks": d.repaired_chunks,
        "spans": spans,
    })
}

/// The estimates of `C` only.
fn camera_part(params: &[ParamEstimate]) -> impl Iterator<Item = &ParamEstimate> {
    params.iter().filter(|p| !p.param.is_vehicle())
}

/// The estimates of `V` only.
fn vehicle_part(params: &[ParamEstimate]) -> impl Iterator<Item = &ParamEstimate> {
    params.iter().filter(|p| p.param.is_vehicle())
}

pub(crate) fn params_json<'a>(params: impl Iterator<Item = &'a ParamEstimate>) -> Value {
    Value::Object(
        params
            .map(|p| {
                (
                    p.param.name().to_owned(),
                    json!({"value": p.value, "sigma": p.sigma}),
                )
            })
            .collect(),
    )
}

fn landmark_json(l: &LandmarkEstimate) -> Value {
    let [x, y, z] = l.position;
    json!({
        "id": l.id,
        "x": x,
        "y": y,
        "z": z,
        "sigma": landmark_sigma(l),
        "observations": l.observations,
    })
}

/// Per-axis 1-sigma of a landmark, metres; NaN where the variance is NaN (written `null`),
/// where [`LandmarkEstimate::sigma`] would say 0 (perfectly known).
pub(crate) fn landmark_sigma(l: &LandmarkEstimate) -> [f64; 3] {
    let [[xx, _, _], [_, yy, _], [_, _, zz]] = l.covariance;
    [xx, yy, zz].map(|v| if v.is_nan() { v } else { v.max(0.0).sqrt() })
}

/// The counters the summary does not hold at its top level, and the frames processed.
fn counts_json(c: &Counts, frames_processed: u64) -> Value {
    let mut map = serde_json::Map::new();
    map.insert("frames_processed".to_string(), json!(frames_processed));
    for (name, value) in c.named() {
        if !matches!(name, "frames" | "corrupt" | "lost") {
            map.insert(name.to_string(), json!(value));
        }
    }
    Value::Object(map)
}

fn truth_json(t: &TruthErrors) -> Value {
    let errors = |vehicle: bool| -> serde_json::Map<String, Value> {
        t.camera
            .iter()
            .filter(|(param, _)| param.is_vehicle() == vehicle)
            .map(|(param, error)| (param.name().to_owned(), json!(error)))
            .collect()
    };
    json!({
        "landmark_rms_m": t.landmark_rms,
        "landmark_rms_aligned_m": t.landmark_rms_aligned,
        "landmarks_matched": t.landmarks_matched,
        "landmarks_unmatched": t.landmarks_unmatched,
        "landmarks_duplicate": t.landmarks_duplicate,
        "lamps_missed": t.lamps_missed,
        "match_radius_m": t.match_radius,
        "ate_rms_m": t.ate_rms,
        "ate_max_m": t.ate_max,
        "heading_rms_rad": t.heading_rms,
        "camera": errors(false),
        "vehicle": errors(true),
        "consistency": t.consistency.map(|c| json!({
            "pose_nees": c.pose_nees,
            "pose_frames": c.pose_frames,
            "final_pose_nees": c.final_pose_nees,
            "state_nees": c.state_nees,
            "state_dof": c.state_dof,
        })),
    })
}
