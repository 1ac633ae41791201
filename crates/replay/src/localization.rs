//! `stereonav localize`: a vehicle log run on a saved map (vehicle-interfaces.md section 5).
//!
//! The log is read as for a replay (decoded, in data-time order); each frame goes through the
//! [`localize::Localizer`] built from the map: its lamps, its calibrated `C` and `V`, and the
//! rig (the one given, or else the map's own; the lens, image size and noise come from it).
//! The log's `/rig` is not needed: the map carries the rig it was made with. A map imported
//! from a lighting plan has no calibration (and a rig only when one was given to the import):
//! the rig's nominal `C` and `V` are used, with its priors as their sigmas.

use std::io::Write as _;
use std::path::{Path, PathBuf};

use localize::reloc::{Generation, Waiting, Weighed};
use localize::{
    CommonError, FrameResult, LampMap, Localizer, LocalizerSettings, MapLamp, NewLamp, Status,
};
use map_file::{Map, MapLandmark};
use nalgebra::{Matrix3, Matrix4, Vector3};
use rig_model::Param;
use rig_model::camera::{CameraParams, wrap_angle};
use rig_model::config::Rig;
use serde_json::{Value, json};

use crate::stream::{Input, LogStream};
use crate::{Counts, Error, ParamEstimate};

/// One frame of a localisation run, as `TRAJ.csv` has it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LocalizedFrame {
    /// The frame's time, microseconds.
    pub t_us: u64,
    /// The pose (map frame), or `None` when the localiser has no guess.
    pub pose: Option<[f64; 3]>,
    /// Its 1-sigma in x, y and theta (NaN without a pose).
    pub sigma: [f64; 3],
    /// Whether the localiser stands behind the pose.
    pub localized: bool,
    /// Map lamps associated at this frame.
    pub matched: u32,
    /// Live relocalisation hypotheses.
    pub hypotheses: u32,
    /// The log's true pose at this frame's time, when it has one (simulator logs): what the
    /// errors against the truth compare the pose to.
    pub truth: Option<[f64; 3]>,
    /// While lost: what holds a fix back (no hypothesis, an incomplete generation, the best
    /// too young, too few lamps, a poor fit, or its margin over the next); `None` when
    /// localised.
    pub waiting: Option<Waiting>,
    /// While lost: the best hypotheses, best first (at most [`WEIGHED_SHOWN`]), each with how
    /// far behind the best it is: the hypotheses being weighed.
    pub weighed: [Option<Weighed>; WEIGHED_SHOWN],
    /// While lost: the relocaliser's last generation of hypotheses (how many triangles of the
    /// frame it looked up, how many map triangles they returned, the candidates).
    pub generation: Option<Generation>,
}

/// Hypotheses a [`LocalizedFrame`] keeps of those being weighed.
pub const WEIGHED_SHOWN: usize = 6;

impl LocalizedFrame {
    /// The pose the localiser stands behind: `Some` for a localised frame, `None` for a lost
    /// one (even with a best guess). The frames the errors against the truth are over, and
    /// those a TUM trajectory holds.
    #[must_use]
    pub fn localized_pose(&self) -> Option<[f64; 3]> {
        self.pose.filter(|_| self.localized)
    }
}

/// The errors of a localisation run against the log's simulator truth (the truth taken to be
/// in the map's frame: the mapping run started at the truth's origin).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LocalizeTruth {
    /// Frames with a true pose.
    pub frames: u64,
    /// Of those, frames localised.
    pub localized_frames: u64,
    /// Position error RMS over the localised frames, metres.
    pub ate_rms_m: f64,
    /// Largest position error of a localised frame, metres.
    pub ate_max_m: f64,
    /// Heading error RMS over the localised frames, radians.
    pub heading_rms_rad: f64,
    /// Localised frames with a position error over [`WRONG_FIX_M`].
    pub wrong_frames: u64,
    /// Mean NEES of the localised pose `(x, y, theta)` against the truth (3 for an honest
    /// covariance; the map's own error is in the truth's error, so a map that is right but
    /// uncertain gives less).
    pub pose_nees: f64,
}

/// A localised frame this far from the truth counts as a wrong fix, metres (the acceptance
/// bound of issue 20).
pub const WRONG_FIX_M: f64 = 0.25;

/// What a localisation run ends with.
#[derive(Debug, Clone, PartialEq)]
pub struct LocalizeEnd {
    /// The decoder's and reader's counters.
    pub counts: Counts,
    /// Frames processed.
    pub frames_processed: u64,
    /// Frames localised.
    pub localized_frames: u64,
    /// Each time the position was (re)gained, microseconds.
    pub localized_t_us: Vec<u64>,
    /// Map landmark ids that should have been seen often and were not.
    pub lamps_missing: Vec<u64>,
    /// Lamps seen that are not in the map.
    pub new_lamps: Vec<NewLamp>,
    /// The last frame.
    pub last_frame: Option<LocalizedFrame>,
    /// First frame's time, microseconds.
    pub first_t_us: Option<u64>,
    /// `C` (the map's) and `V` (refined), every parameter.
    pub parameters: Vec<ParamEstimate>,
    /// The map's landmarks, with the times each was associated in this run.
    pub landmarks: Vec<(MapLandmark, u32)>,
    /// Times lost, by reason: gap, no odometry, innovations, uncertain.
    pub lost: [u64; 4],
    /// Hypotheses generated.
    pub hypotheses: u64,
    /// Warnings, one line each.
    pub warnings: Vec<String>,
    /// Errors against the truth, when the log has it.
    pub truth: Option<LocalizeTruth>,
}

/// A map landmark known worse than this (standard deviation on any axis, metres) is not used.
pub const MAX_LAMP_SIGMA_M: f64 = 0.25;

/// The rig a run on `map` uses: `rig` (given), else the map's own.
///
/// Errors: neither (a map imported from a lighting plan without a rig).
fn rig_for(map: &Map, rig: Option<Rig>) -> Result<Rig, Error> {
    rig.or_else(|| map.rig.clone())
        .ok_or_else(|| Error::MapWithoutRig {
            plan: map.source_plan.clone(),
        })
}

/// The camera `C` and `V` a run on `map` with `rig` (the one [`rig_for`] gives) uses, and the
/// sigma of each parameter ([`Param::ALL`] order): the map's calibration, over the nominal
/// values of the map's rig (else `rig`'s) for a parameter it lacks; a map without calibration
/// (imported from a lighting plan) gives `rig`'s nominal values with its priors (0 for a
/// parameter it holds).
fn map_camera(map: &Map, rig: &Rig) -> (CameraParams, [f64; rig_model::N_PARAMS]) {
    let mut sigma = [0.0; rig_model::N_PARAMS];
    if map.parameters.is_empty() {
        for (s, p) in sigma.iter_mut().zip(rig.prior) {
            *s = p.unwrap_or(0.0);
        }
        return (rig.nominal, sigma);
    }
    let mut camera: CameraParams = map.rig.as_ref().unwrap_or(rig).nominal;
    for p in &map.parameters {
        camera.set(p.param, p.value);
        if let Some(s) = sigma.get_mut(p.param.index()) {
            *s = p.sigma;
        }
    }
    (camera, sigma)
}

/// The localiser for a map: its lamps indexed, the camera from the map's parameters (or, for
/// a map without calibration, the rig's nominal values and priors).
///
/// Errors: a map without lamps or with a bad one, a map without a rig when none is given,
/// settings out of range.
pub fn localizer_for(
    map: &Map,
    rig: Option<Rig>,
    settings: LocalizerSettings,
) -> Result<Localizer, Error> {
    let rig = rig_for(map, rig)?;
    let (camera, sigma) = map_camera(map, &rig);
    // A landmark the mapping run barely knew (seen twice, its depth unknown to metres) would
    // only mislead the association and the relocalisation's pairs: left out.
    let lamps: Vec<MapLamp> = map
        .landmarks
        .iter()
        .filter(|l| (0..3).all(|i| l.covariance[i][i] <= MAX_LAMP_SIGMA_M * MAX_LAMP_SIGMA_M))
        .map(|l| MapLamp {
            id: l.id,
            position: Vector3::from(l.position),
            covariance: Matrix3::from_fn(|r, c| l.covariance[r][c]),
        })
        .collect();
    let highest = lamps.iter().map(|l| l.position.z).fold(f64::MIN, f64::max);
    let pair_radius = pair_radius(&camera, &rig, highest).min(settings.max_reach_m);
    let mut index = LampMap::new(lamps, pair_radius).map_err(|e| Error::Localize(e.to_string()))?;
    if let Some(c) = &map.common_error {
        index = index
            .with_common_error(CommonError {
                origin: (c.origin[0], c.origin[1]),
                covariance: Matrix4::from_fn(|r, k| c.covariance[r][k]),
            })
            .map_err(|e| Error::Localize(e.to_string()))?;
    }
    Localizer::new(index, rig, camera, &sigma, settings).map_err(|e| Error::Localize(e.to_string()))
}

/// The widest horizontal distance two lamps seen in one frame can be apart, metres: the
/// diameter of the image's footprint on the ceiling at the highest lamp (the image's
/// half-diagonal off the optical axis, tilted by the mount).
fn pair_radius(c: &CameraParams, rig: &Rig, highest_m: f64) -> f64 {
    let half = f64::from(rig.width).hypot(f64::from(rig.height)) / 2.0;
    let tilt = c.mount.pitch.abs() + c.mount.roll.abs();
    let angle = ((half / c.f).atan() + tilt).min(1.3);
    2.0 * (highest_m - c.mount.z).max(0.5) * angle.tan()
}

/// Runs the log at `path` on `map`; `trajectory` gets every frame; `progress` is called with
/// `(bytes read, bytes in the file)`.
///
/// Errors: the log cannot be read or is not a vehicle log, the map cannot localise.
pub fn localize_log(
    path: &Path,
    topics: Option<&vehicle_log::Ros2Topics>,
    map: &Map,
    rig: Option<Rig>,
    settings: LocalizerSettings,
    trajectory: &mut dyn FnMut(&LocalizedFrame) -> Result<(), Error>,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<LocalizeEnd, Error> {
    let rig = rig_for(map, rig)?;
    let regs = rig.board_registers();
    let (camera, camera_sigma) = map_camera(map, &rig);
    let mut localizer = localizer_for(map, Some(rig), settings)?;
    let mut stream = LogStream::open(path, topics)?;
    stream.preamble(false)?;
    stream.start_host_board(regs)?;
    let mut refused: std::collections::BTreeMap<String, u64> = std::collections::BTreeMap::new();
    let mut frames = 0_u64;
    let mut first_t = None;
    let mut last = None;
    let mut truth = TruthSums::default();
    while let Some(input) = stream.next_input()? {
        match input {
            Input::Odometry(s) => {
                if let Err(e) = localizer.push_odometry(s) {
                    *refused.entry(e.to_string()).or_default() += 1;
                }
            }
            Input::Frame(f) => {
                let result = match localizer.push_frame(f.t_us, &f.left, &f.right) {
                    Ok(r) => r,
                    Err(e) => {
                        *refused.entry(e.to_string()).or_default() += 1;
                        continue;
                    }
                };
                frames += 1;
                first_t.get_or_insert(f.t_us);
                let mut row = frame_row(&result, &localizer);
                if let Some(t) = stream.truth.pose_at(f.t_us) {
                    let pose = [t.x, t.y, t.theta];
                    row.truth = Some(pose);
                    truth.add(&row, pose, &result.pose_covariance);
                }
                stream.truth.forget_before(f.t_us);
                trajectory(&row)?;
                last = Some(row);
                let (done, total) = stream.progress();
                progress(done, total);
            }
        }
    }
    let mut warnings: Vec<String> = Vec::new();
    if let Some(why) = stream.reader().truncated() {
        warnings.push(format!(
            "the log ends early ({why}): localised as far as it goes"
        ));
    }
    warnings.extend(stream.reader().warnings().iter().cloned());
    for (what, n) in &refused {
        warnings.push(format!("{n} inputs refused: {what}"));
    }
    warnings.extend(stream.input_warnings());
    let unused = map.landmarks.len() - localizer.map().len();
    if unused > 0 {
        warnings.push(format!(
            "{unused} map landmarks known worse than {MAX_LAMP_SIGMA_M} m were not used"
        ));
    }
    if localizer.localized_t_us().is_empty() && frames > 0 {
        warnings.push(
            "never localised: no lamp constellation in view matched the map uniquely".to_string(),
        );
    }
    let stats = localizer.stats();
    let (v, v_sigma) = localizer.vehicle();
    let mut parameters: Vec<ParamEstimate> = Param::ALL
        .iter()
        .map(|&param| ParamEstimate {
            param,
            value: camera.get(param),
            sigma: camera_sigma.get(param.index()).copied().unwrap_or(0.0),
        })
        .collect();
    for (k, p) in Param::VEHICLE.iter().enumerate() {
        if let Some(e) = parameters.iter_mut().find(|e| e.param == *p) {
            e.value = v.to_array().get(k).copied().unwrap_or(e.value);
            e.sigma = v_sigma.get(k).copied().unwrap_or(e.sigma);
        }
    }
    let seen = &localizer.lamp_counts().seen;
    let landmarks = map
        .landmarks
        .iter()
        .zip(seen)
        .map(|(l, &n)| (*l, n))
        .collect();
    Ok(LocalizeEnd {
        counts: stream.counts,
        frames_processed: frames,
        localized_frames: stats.localized_frames,
        localized_t_us: localizer.localized_t_us().to_vec(),
        lamps_missing: localizer.lamps_missing(),
        new_lamps: localizer.new_lamps(),
        last_frame: last,
        first_t_us: first_t,
        parameters,
        landmarks,
        lost: stats.lost,
        hypotheses: stats.hypotheses,
        warnings,
        truth: stream.truth.any.then(|| truth.finish()),
    })
}

fn frame_row(r: &FrameResult, localizer: &Localizer) -> LocalizedFrame {
    let c = &r.pose_covariance;
    let lost = r.status != Status::Localized;
    let reloc = localizer.relocalizer();
    let mut weighed = [None; WEIGHED_SHOWN];
    if lost {
        for (slot, w) in weighed.iter_mut().zip(reloc.weighed()) {
            *slot = Some(w);
        }
    }
    let sd = |v: f64| if v >= 0.0 { v.sqrt() } else { f64::NAN };
    LocalizedFrame {
        t_us: r.t_us,
        pose: r.pose.map(|p| [p.x, p.y, p.theta]),
        sigma: if r.pose.is_some() {
            [sd(c[(0, 0)]), sd(c[(1, 1)]), sd(c[(2, 2)])]
        } else {
            [f64::NAN; 3]
        },
        localized: r.status == Status::Localized,
        matched: u32::try_from(r.matched.len()).unwrap_or(u32::MAX),
        hypotheses: u32::try_from(r.hypotheses).unwrap_or(u32::MAX),
        truth: None,
        waiting: if lost { reloc.waiting() } else { None },
        generation: lost.then_some(reloc.last_generation),
        weighed,
    }
}

#[derive(Debug, Default)]
struct TruthSums {
    frames: u64,
    localized: u64,
    sq: f64,
    sq_heading: f64,
    max: f64,
    wrong: u64,
    nees: f64,
    nees_frames: u64,
}

impl TruthSums {
    fn add(&mut self, row: &LocalizedFrame, truth: [f64; 3], cov: &Matrix3<f64>) {
        self.frames += 1;
        if let (true, Some(p)) = (row.localized, row.pose) {
            let e = (p[0] - truth[0]).hypot(p[1] - truth[1]);
            let h = wrap_angle(p[2] - truth[2]);
            let d = Vector3::new(p[0] - truth[0], p[1] - truth[1], h);
            if let Some(inv) = cov.try_inverse() {
                let nees = (d.transpose() * inv * d)[(0, 0)];
                if nees.is_finite() {
                    self.nees += nees;
                    self.nees_frames += 1;
                }
            }
            self.localized += 1;
            self.sq += e * e;
            self.sq_heading += h * h;
            self.max = self.max.max(e);
            if e > WRONG_FIX_M {
                self.wrong += 1;
            }
        }
    }

    fn finish(&self) -> LocalizeTruth {
        #[allow(clippy::cast_precision_loss)]
        let n = self.localized.max(1) as f64;
        LocalizeTruth {
            frames: self.frames,
            localized_frames: self.localized,
            ate_rms_m: if self.localized > 0 {
                (self.sq / n).sqrt()
            } else {
                f64::NAN
            },
            ate_max_m: if self.localized > 0 {
                self.max
            } else {
                f64::NAN
            },
            heading_rms_rad: if self.localized > 0 {
                (self.sq_heading / n).sqrt()
            } else {
                f64::NAN
            },
            wrong_frames: self.wrong,
            #[allow(clippy::cast_precision_loss)]
            pose_nees: if self.nees_frames > 0 {
                self.nees / self.nees_frames as f64
            } else {
                f64::NAN
            },
        }
    }
}

/// `SUMMARY.json` of a localisation run: the replay's keys (vehicle-interfaces.md section 5;
/// `phase_switch_t_us` is `null`, `landmarks` the map's with the associations of this run as
/// `observations`), plus `localized_t_us`, `lamps_missing`, `new_lamps` (`[{x, y, z, sigma,
/// observations}]`), `localized_frames`, `lost_by_reason`, `warnings`, and `truth` (or
/// `null`).
pub fn localize_summary_json(end: &LocalizeEnd) -> Value {
    let c = &end.counts;
    let pose = end.last_frame.and_then(|f| {
        f.pose
            .map(|[x, y, theta]| json!({"t_us": f.t_us, "x": x, "y": y, "theta": theta, "localized": f.localized}))
    });
    let params = |vehicle: bool| {
        Value::Object(
            end.parameters
                .iter()
                .filter(|p| p.param.is_vehicle() == vehicle)
                .map(|p| {
                    (
                        p.param.name().to_owned(),
                        json!({"value": finite(p.value), "sigma": finite(p.sigma)}),
                    )
                })
                .collect(),
        )
    };
    let landmarks: Vec<Value> = end
        .landmarks
        .iter()
        .map(|(l, n)| {
            let [x, y, z] = l.position;
            let s = |i: usize| l.covariance[i][i].max(0.0).sqrt();
            json!({"id": l.id, "x": x, "y": y, "z": z, "sigma": [s(0), s(1), s(2)], "observations": n})
        })
        .collect();
    let new_lamps: Vec<Value> = end
        .new_lamps
        .iter()
        .map(|l| {
            let s = |i: usize| l.covariance[(i, i)].max(0.0).sqrt();
            json!({"x": l.position.x, "y": l.position.y, "z": l.position.z,
                   "sigma": [s(0), s(1), s(2)], "observations": l.observations})
        })
        .collect();
    let truth = end.truth.map_or(Value::Null, |t| {
        json!({
            "frames": t.frames,
            "localized_frames": t.localized_frames,
            "ate_rms_m": finite(t.ate_rms_m),
            "ate_max_m": finite(t.ate_max_m),
            "heading_rms_rad": finite(t.heading_rms_rad),
            "wrong_frames": t.wrong_frames,
            "pose_nees": finite(t.pose_nees),
            "wrong_fix_m": WRONG_FIX_M,
        })
    });
    json!({
        "frames": c.frames,
        "corrupt": c.corrupt,
        "lost": c.lost,
        "phase_switch_t_us": Value::Null,
        "pose": pose.unwrap_or(Value::Null),
        "camera": params(false),
        "vehicle": params(true),
        "landmarks": landmarks,
        "localized_t_us": end.localized_t_us,
        "lamps_missing": end.lamps_missing,
        "new_lamps": new_lamps,
        "frames_processed": end.frames_processed,
        "localized_frames": end.localized_frames,
        "lost_by_reason": {"gap": end.lost[0], "no_odometry": end.lost[1],
                           "innovations": end.lost[2], "uncertain": end.lost[3]},
        "hypotheses": end.hypotheses,
        "counts": Value::Object(c.named().iter().map(|(k, v)| ((*k).to_owned(), json!(v))).collect()),
        "warnings": end.warnings,
        "truth": truth,
    })
}

fn finite(v: f64) -> Value {
    if v.is_finite() { json!(v) } else { Value::Null }
}

/// `TRAJ.csv` of a localisation run, written as the frames come: header
/// `t_us,x,y,theta,localized`, the pose columns empty when there is no guess.
#[derive(Debug)]
pub struct LocalizedTrajectoryWriter {
    path: PathBuf,
    out: std::io::BufWriter<std::fs::File>,
}

impl LocalizedTrajectoryWriter {
    /// Creates the file and writes the header.
    pub fn create(path: &Path) -> Result<Self, Error> {
        let io = |e| Error::Output {
            file: "TRAJ.csv",
            path: path.to_path_buf(),
            source: e,
        };
        let file = std::fs::File::create(path).map_err(io)?;
        let mut out = std::io::BufWriter::new(file);
        writeln!(out, "t_us,x,y,theta,localized").map_err(io)?;
        Ok(Self {
            path: path.to_path_buf(),
            out,
        })
    }

    /// One row.
    pub fn frame(&mut self, f: &LocalizedFrame) -> Result<(), Error> {
        let l = u8::from(f.localized);
        let r = match f.pose {
            Some([x, y, th]) => writeln!(self.out, "{},{x},{y},{th},{l}", f.t_us),
            None => writeln!(self.out, "{},,,,{l}", f.t_us),
        };
        r.map_err(|e| Error::Output {
            file: "TRAJ.csv",
            path: self.path.clone(),
            source: e,
        })
    }

    /// Flushes the file.
    pub fn finish(mut self) -> Result<(), Error> {
        self.out.flush().map_err(|e| Error::Output {
            file: "TRAJ.csv",
            path: self.path.clone(),
            source: e,
        })
    }
}

/// The map with the run's new lamps added (ids after the map's largest), as a new version of
/// it made from `log`; the missing lamps stay (a dark lamp is usually repaired).
pub fn map_with_new_lamps(map: &Map, end: &LocalizeEnd, log: &Path) -> Map {
    let mut out = map.clone();
    let first = map
        .landmarks
        .iter()
        .map(|l| l.id)
        .max()
        .map_or(0, |m| m + 1);
    for (id, l) in (first..).zip(&end.new_lamps) {
        out.landmarks.push(MapLandmark {
            id,
            position: [l.position.x, l.position.y, l.position.z],
            covariance: std::array::from_fn(|r| std::array::from_fn(|c| l.covariance[(r, c)])),
            observations: u64::from(l.observations),
        });
    }
    for p in &mut out.parameters {
        if let Some(e) = end.parameters.iter().find(|e| e.param == p.param)
            && p.param.is_vehicle()
        {
            p.value = e.value;
            p.sigma = e.sigma;
        }
    }
    out.source_log = log.display().to_string();
    out.created_unix_s = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    out
}
