//! The whole stack on a log: the navigator (crate `nav`) fed with the log's board frames and
//! odometry in data-time order, the estimates collected into a [`Replay`], and the errors
//! against the simulator's truth when the log carries it.

use std::collections::BTreeMap;
use std::f64::consts::PI;
use std::path::Path;

use calib::camera::{CameraParams, Param, Pose2};
use calib::config::Rig;
use nav::{NavSettings, Navigator};
use vehicle_log::{Record, TruthCamera, TruthLandmark, TruthPose};

use crate::{
    CameraSample, Error, FrameEstimate, LandmarkEstimate, MapSnapshot, ParamEstimate, Phase,
    Replay, TruthErrors, read_vehicle_log,
};

/// Data time between two map snapshots in the replay, microseconds.
pub const MAP_SNAPSHOT_US: u64 = 1_000_000;

/// A lamp counts as seen when it is inside both images at this many frames (one
/// second at 20 Hz). A landmark needs the tracker's confirmation (3 frames) and its own (3
/// consistent triangulations) first; lamps that only cross an image corner at speed are in
/// view for fewer frames than that, some of them at the border where the stereo match fails
/// (measured on the warehouse: 2 of 174 lamps in view for 10-12 frames were not mapped).
pub const LAMP_SEEN_FRAMES: usize = 20;

/// A landmark is matched to the nearest lamp within this distance, metres.
pub const LAMP_MATCH_RADIUS_M: f64 = 0.10;

fn phase_of(p: nav::Phase) -> Phase {
    match p {
        nav::Phase::Calibrating => Phase::Calibrating,
        nav::Phase::Navigating => Phase::Navigating,
    }
}

fn matrix3(m: &nalgebra::Matrix3<f64>) -> [[f64; 3]; 3] {
    core::array::from_fn(|r| core::array::from_fn(|c| m[(r, c)]))
}

fn map_of(navigator: &Navigator) -> Vec<LandmarkEstimate> {
    let Some(ekf) = navigator.ekf() else {
        return Vec::new();
    };
    let mut out: Vec<LandmarkEstimate> = ekf
        .landmarks()
        .map(|l| LandmarkEstimate {
            id: l.id.0,
            position: [l.position.x, l.position.y, l.position.z],
            covariance: matrix3(&l.covariance),
            observations: l.observations,
        })
        .collect();
    out.sort_by_key(|l| l.id);
    out
}

/// Runs the navigator over the vehicle log at `path` (see [`crate::calibrate_log`] for the
/// reading, the rig choice and the ordering by data time). `progress` is called with
/// `(frames done, frames in the log)` after each frame.
///
/// Errors: the file cannot be read, is not MCAP, has no vehicle topics, there is no rig, or the
/// settings are out of range. A log cut short is replayed as far as it goes, with a warning;
/// an update the filter refuses leaves the state as it was and is counted in a warning.
pub fn replay_log(
    path: impl AsRef<Path>,
    rig: Option<Rig>,
    settings: &NavSettings,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<Replay, Error> {
    let path = path.as_ref();
    let input = read_vehicle_log(path, rig)?;
    let mut warnings = input.warnings;
    let mut counts = input.counts;
    let rig = input.rig;
    let mut navigator = Navigator::new(rig.clone(), *settings)?;

    let total = input.frames.len() as u64;
    let mut frames: Vec<FrameEstimate> = Vec::with_capacity(input.frames.len());
    let mut camera: Vec<CameraSample> = Vec::new();
    let mut maps: Vec<MapSnapshot> = Vec::new();
    let mut next_snapshot: Option<u64> = None;
    let mut refused: BTreeMap<String, u64> = BTreeMap::new();
    let mut next_odom = input.odometry.iter().peekable();
    // Final poses from phase 2's fixed-lag smoother, as it marginalises its frames.
    let mut smoothed_poses: Vec<(u64, Pose2)> = Vec::new();
    let (mut nees_sum, mut nees_frames, mut nees_last) = (0.0, 0usize, f64::NAN);
    for (k, frame) in input.frames.iter().enumerate() {
        // The odometry past the frame's stamp too: a frame exposed after its stamp (a negative
        // clock offset) needs it (nav::ODOMETRY_LOOKAHEAD_US).
        let until = frame.t_us.saturating_add(nav::ODOMETRY_LOOKAHEAD_US);
        while let Some(s) = next_odom.next_if(|s| s.t_us <= until) {
            if let Err(e) = navigator.push_odometry(*s) {
                *refused.entry(e.to_string()).or_default() += 1;
            }
        }
        let outcome = match navigator.push_frame(frame.t_us, &frame.left, &frame.right) {
            Ok(o) => o,
            Err(e) => {
                *refused.entry(e.to_string()).or_default() += 1;
                nav::FrameOutcome::default()
            }
        };
        let phase = phase_of(navigator.phase());
        let (pose, pose_cov) = navigator.pose();
        if phase == Phase::Navigating
            && let Some(t) = input.truth.as_ref().and_then(|t| t.pose_at(frame.t_us))
            && let Some(v) = pose_nees(&pose, &pose_cov, t)
        {
            nees_sum += v;
            nees_frames += 1;
            nees_last = v;
        }
        let landmarks = navigator.ekf().map_or(0, vslam_ekf::Ekf::landmark_count);
        frames.push(FrameEstimate {
            t_us: frame.t_us,
            phase,
            pose: [pose.x, pose.y, pose.theta],
            pose_covariance: matrix3(&pose_cov),
            observed: outcome.accepted.iter().map(|(id, _)| id.0).collect(),
            nis: outcome.accepted.iter().map(|(id, v)| (id.0, *v)).collect(),
            rejected: u32::try_from(outcome.rejected.len()).unwrap_or(u32::MAX),
            landmarks,
        });
        if phase == Phase::Navigating || outcome.solved {
            let (c, cov) = navigator.camera();
            camera.push(CameraSample {
                t_us: frame.t_us,
                phase,
                params: ParamEstimate::all(&c, &cov),
            });
        }
        if phase == Phase::Navigating {
            let due = next_snapshot.is_none_or(|t| frame.t_us >= t);
            if due {
                maps.push(MapSnapshot {
                    t_us: frame.t_us,
                    landmarks: map_of(&navigator),
                });
                next_snapshot = Some(frame.t_us.saturating_add(MAP_SNAPSHOT_US));
            }
        }
        smoothed_poses.extend(navigator.take_smoothed());
        progress(k as u64 + 1, total);
    }
    // A log that ends in phase 1 is still mapped: phase 2 starts from the batch of every frame.
    if let Err(e) = navigator.finish() {
        *refused.entry(e.to_string()).or_default() += 1;
    }
    // The frames of phase 1 take the batch's smoothed poses: the whole trajectory is in the
    // first frame's world frame.
    set_poses(
        &mut frames,
        navigator.phase1_trajectory(),
        Some(Phase::Calibrating),
    );
    // Every frame phase 2's smoother held takes its smoothed pose.
    smoothed_poses.extend(navigator.take_smoothed());
    smoothed_poses.extend(navigator.smoother_window());
    set_poses(&mut frames, &smoothed_poses, None);
    let landmarks = map_of(&navigator);
    if let Some(last) = frames.last()
        && navigator.ekf().is_some()
    {
        // The final map (after the smoother's last solve) is the last snapshot.
        match maps.last_mut() {
            Some(m) if m.t_us == last.t_us => m.landmarks.clone_from(&landmarks),
            _ => maps.push(MapSnapshot {
                t_us: last.t_us,
                landmarks: landmarks.clone(),
            }),
        }
    }
    let (final_c, final_cov) = navigator.camera();
    let final_camera = ParamEstimate::all(&final_c, &final_cov);
    // The last frame's camera sample and pose covariance are the final ones (after the
    // smoother's last solve).
    if let Some(last) = frames.last_mut()
        && last.phase == Phase::Navigating
    {
        last.pose_covariance = matrix3(&navigator.pose().1);
        if let Some(c) = camera.last_mut()
            && c.t_us == last.t_us
        {
            c.params.clone_from(&final_camera);
        }
    }
    let stats = navigator.stats();
    let tracker = navigator.front_end().tracker().stats();
    counts.stereo_matches = navigator.front_end().stereo_stats().matches;
    counts.tracks = tracker.started;
    counts.confirmed_tracks = tracker.confirmed;
    counts.tracker_resets = tracker.resets;
    counts.phase1_solves = stats.phase1_solves;
    for (why, n) in refused {
        warnings.push(format!("{n} input(s) refused by the navigator: {why}"));
    }
    if stats.frames_without_odometry > 0 {
        warnings.push(format!(
            "{} frame(s) had no odometry since the frame before: the pose was held there",
            stats.frames_without_odometry
        ));
    }
    if stats.odometry_dropped > 0 {
        warnings.push(format!(
            "{} odometry sample(s) dropped: no stereo frame came for longer than the navigator's odometry buffer",
            stats.odometry_dropped
        ));
    }
    for (p, sigma, prior) in navigator.spurious_information() {
        let (scale, unit) = p.display_unit();
        warnings.push(format!(
            "the filter holds information on {} (sigma {:.2} {unit}, prior {:.2} {unit}) that the motion cannot give (the odometry travelled {:.3} m significantly): a model error elsewhere, such as the camera moving while the odometry says the vehicle stands",
            p.name(),
            scale * sigma,
            scale * prior,
            stats.significant_translation_m
        ));
    }
    if let Some((reason, uninformed)) = navigator.uninformed()
        && (reason != calib::smoother::HandoverReason::Stable || !uninformed.is_empty())
    {
        let why = match reason {
            calib::smoother::HandoverReason::Stable => "phase 1 became stable",
            calib::smoother::HandoverReason::BufferFull => {
                "phase 1 was not stable when its buffer (frames or landmarks) filled"
            }
            calib::smoother::HandoverReason::Requested => {
                "phase 1 was not stable by the end of the log"
            }
        };
        let names: Vec<&str> = uninformed.iter().map(|p| p.name()).collect();
        warnings.push(if names.is_empty() {
            format!("{why}: phase 2 mapped from its estimate")
        } else {
            format!(
                "{why}; the data did not inform {}: phase 2 used the rig's nominal values and priors for them",
                names.join(", ")
            )
        });
    }
    let truth = input.truth.as_ref().map(|t| {
        let mut e = truth_errors(t, &frames, &landmarks, &final_c, &rig);
        let last = frames.last().and_then(|f| t.pose_at(f.t_us));
        let state = navigator
            .ekf()
            .zip(last)
            .and_then(|(ekf, pose)| state_nees(ekf, pose, t));
        if nees_frames > 0 || state.is_some() {
            let (state_nees, state_dof) = state.unwrap_or((f64::NAN, 0));
            e.consistency = Some(crate::Consistency {
                pose_nees: nees_sum / nees_frames.max(1) as f64,
                pose_frames: nees_frames,
                final_pose_nees: nees_last,
                state_nees,
                state_dof,
            });
        }
        e
    });
    Ok(Replay {
        frames,
        camera,
        maps,
        landmarks,
        final_camera,
        phase_switch_t_us: navigator.phase_switch_t_us(),
        phase1_skipped: settings.skip_phase1,
        counts,
        truth,
        warnings,
    })
}

/// The simulator's truth in a log.
#[derive(Debug, Clone, Default)]
pub(crate) struct Truth {
    pub(crate) poses: Vec<TruthPose>,
    pub(crate) landmarks: Vec<TruthLandmark>,
    pub(crate) camera: Option<TruthCamera>,
}

impl Truth {
    /// Collects the truth records of a log; `None` when it has none.
    pub(crate) fn from_records(records: &[Record]) -> Option<Self> {
        let mut t = Self::default();
        for r in records {
            match r {
                Record::TruthPose(p) => t.poses.push(*p),
                Record::TruthLandmarks(l) if t.landmarks.is_empty() => t.landmarks.clone_from(l),
                Record::TruthCamera(c) if t.camera.is_none() => t.camera = Some(*c),
                _ => {}
            }
        }
        let any = !t.poses.is_empty() || !t.landmarks.is_empty() || t.camera.is_some();
        t.poses.sort_by_key(|p| p.t_us);
        any.then_some(t)
    }

    /// The true pose at exactly `t_us`, if the log has one.
    pub(crate) fn pose_at(&self, t_us: u64) -> Option<&TruthPose> {
        let i = self.poses.binary_search_by_key(&t_us, |p| p.t_us).ok()?;
        self.poses.get(i)
    }
}

/// The camera parameters of the simulator's truth (`/truth/camera`).
pub fn truth_camera(t: &TruthCamera) -> CameraParams {
    CameraParams {
        vehicle: calib::Vehicle {
            odom_scale: t.odom_scale,
            odom_yaw_scale: t.odom_yaw_scale,
            odom_yaw_bias: t.odom_yaw_bias,
            time_offset: t.time_offset,
        },
        f: t.f,
        cx: t.cx,
        cy: t.cy,
        baseline: t.baseline,
        mount: calib::camera::Mount {
            x: t.mount_x,
            y: t.mount_y,
            z: t.mount_z,
            roll: t.mount_roll,
            pitch: t.mount_pitch,
            yaw: t.mount_yaw,
        },
    }
}

fn truth_errors(
    truth: &Truth,
    frames: &[FrameEstimate],
    landmarks: &[LandmarkEstimate],
    final_camera: &CameraParams,
    rig: &Rig,
) -> TruthErrors {
    // Trajectory: frames with a true pose at the same timestamp.
    let mut sq = 0.0;
    let mut sq_heading = 0.0;
    let mut max: f64 = 0.0;
    let mut n = 0usize;
    for f in frames {
        let Some(p) = truth.pose_at(f.t_us) else {
            continue;
        };
        let [x, y, theta] = f.pose;
        let e2 = (x - p.x).powi(2) + (y - p.y).powi(2);
        sq += e2;
        max = max.max(e2.sqrt());
        let dh = (theta - p.theta + PI).rem_euclid(2.0 * PI) - PI;
        sq_heading += dh * dh;
        n += 1;
    }
    let count = n.max(1) as f64;
    // Landmarks: the map is anchored where phase 2 started, at the dead-reckoned pose, so it
    // is first carried onto the truth by the planar motion that best takes the phase-2
    // trajectory onto the true one (the map's gauge: rotation from the mean heading error,
    // well defined even when the robot turns on the spot, then the mean position offset); then
    // each landmark is matched to the nearest lamp within the radius, one-to-one, closest pairs
    // first. The errors are taken without that motion.
    let phase2: Vec<(&FrameEstimate, &TruthPose)> = frames
        .iter()
        .filter(|f| f.phase == Phase::Navigating)
        .filter_map(|f| Some((f, truth.pose_at(f.t_us)?)))
        .collect();
    let gauge = if phase2.is_empty() {
        Planar::IDENTITY
    } else {
        let (s, c) = phase2.iter().fold((0.0, 0.0), |(s, c), (f, p)| {
            let d = p.theta - f.pose[2];
            (s + d.sin(), c + d.cos())
        });
        let angle = f64::atan2(s, c);
        let (sn, cs) = angle.sin_cos();
        let m = phase2.len() as f64;
        let (tx, ty) = phase2.iter().fold((0.0, 0.0), |(tx, ty), (f, p)| {
            (
                tx + p.x - (cs * f.pose[0] - sn * f.pose[1]),
                ty + p.y - (sn * f.pose[0] + cs * f.pose[1]),
            )
        });
        Planar {
            angle,
            tx: tx / m,
            ty: ty / m,
        }
    };
    let mut candidates: Vec<(f64, f64, usize, usize)> = Vec::new();
    for (li, l) in landmarks.iter().enumerate() {
        let moved = gauge.apply(l.position);
        for (ti, t) in truth.landmarks.iter().enumerate() {
            let near = distance(moved, [t.x, t.y, t.z]);
            if near <= LAMP_MATCH_RADIUS_M {
                candidates.push((near, distance(l.position, [t.x, t.y, t.z]), li, ti));
            }
        }
    }
    candidates.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut used_l = vec![false; landmarks.len()];
    let mut used_t = vec![false; truth.landmarks.len()];
    let mut lm_sq = 0.0;
    let mut matched = 0usize;
    let mut pairs: Vec<([f64; 3], [f64; 3])> = Vec::new();
    for (_, d, li, ti) in candidates {
        if used_l.get(li).copied().unwrap_or(true) || used_t.get(ti).copied().unwrap_or(true) {
            continue;
        }
        if let (Some(a), Some(b)) = (used_l.get_mut(li), used_t.get_mut(ti)) {
            *a = true;
            *b = true;
        }
        lm_sq += d * d;
        matched += 1;
        if let (Some(l), Some(t)) = (landmarks.get(li), truth.landmarks.get(ti)) {
            pairs.push((l.position, [t.x, t.y, t.z]));
        }
    }
    // Lamps in view of both cameras at enough frames (both phases are mapped), with no landmark.
    let true_camera = truth.camera.as_ref().map_or(rig.nominal, truth_camera);
    let (w, h) = (f64::from(rig.width), f64::from(rig.height));
    let inside = |u: f64, v: f64| u >= 0.0 && u < w && v >= 0.0 && v < h;
    let mut seen = vec![0usize; truth.landmarks.len()];
    for f in frames {
        let Some(p) = truth.pose_at(f.t_us) else {
            continue;
        };
        let pose = Pose2::new(p.x, p.y, p.theta);
        for (lamp, count) in truth.landmarks.iter().zip(seen.iter_mut()) {
            let l = nalgebra::Vector3::new(lamp.x, lamp.y, lamp.z);
            if let Ok(z) = calib::project(&true_camera, &pose, &l)
                && inside(z[0], z[1])
                && inside(z[2], z[3])
            {
                *count += 1;
            }
        }
    }
    let lamps_missed = seen
        .iter()
        .zip(&used_t)
        .filter(|&(&s, &used)| s >= LAMP_SEEN_FRAMES && !used)
        .count();
    let camera = truth.camera.as_ref().map_or_else(Vec::new, |c| {
        let t = truth_camera(c);
        Param::ALL
            .iter()
            .map(|&p| (p, final_camera.get(p) - t.get(p)))
            .collect()
    });
    TruthErrors {
        landmark_rms: if matched > 0 {
            (lm_sq / matched as f64).sqrt()
        } else {
            f64::NAN
        },
        landmark_rms_aligned: aligned_rms(&pairs),
        landmarks_matched: matched,
        landmarks_unmatched: landmarks.len() - matched,
        lamps_missed,
        match_radius: LAMP_MATCH_RADIUS_M,
        ate_rms: if n > 0 { (sq / count).sqrt() } else { f64::NAN },
        ate_max: if n > 0 { max } else { f64::NAN },
        heading_rms: if n > 0 {
            (sq_heading / count).sqrt()
        } else {
            f64::NAN
        },
        camera,
        consistency: None,
    }
}

/// Each frame (of `phase` only, when given) with a pose in `poses` (sorted by time) at its
/// timestamp takes it.
fn set_poses(frames: &mut [FrameEstimate], poses: &[(u64, Pose2)], phase: Option<Phase>) {
    let mut i = 0usize;
    for f in frames {
        while poses.get(i).is_some_and(|(t, _)| *t < f.t_us) {
            i += 1;
        }
        if let Some((t, p)) = poses.get(i)
            && *t == f.t_us
            && phase.is_none_or(|ph| ph == f.phase)
        {
            f.pose = [p.x, p.y, p.theta];
        }
    }
}

/// Pose NEES of a filtered pose against the truth.
fn pose_nees(pose: &Pose2, cov: &nalgebra::Matrix3<f64>, t: &TruthPose) -> Option<f64> {
    let e = nalgebra::Vector3::new(
        pose.x - t.x,
        pose.y - t.y,
        calib::camera::wrap_angle(pose.theta - t.theta),
    );
    let v = e.dot(&(cov.try_inverse()? * e));
    v.is_finite().then_some(v)
}

/// Full-state NEES of the filter at the end against the truth (pose, the landmarks within
/// 10 cm of a lamp, the estimated camera parameters) and its degrees of freedom.
fn state_nees(ekf: &vslam_ekf::Ekf, pose: &TruthPose, truth: &Truth) -> Option<(f64, usize)> {
    let x = ekf.state();
    let p = ekf.covariance();
    let mut index: Vec<usize> = vec![0, 1, 2];
    let mut err: Vec<f64> = vec![
        x[0] - pose.x,
        x[1] - pose.y,
        calib::camera::wrap_angle(x[2] - pose.theta),
    ];
    for l in ekf.landmarks() {
        let i = ekf.landmark_state_index(l.id)?;
        let near = truth.landmarks.iter().min_by(|a, b| {
            let da = distance(l.position.into(), [a.x, a.y, a.z]);
            let db = distance(l.position.into(), [b.x, b.y, b.z]);
            da.total_cmp(&db)
        })?;
        if distance(l.position.into(), [near.x, near.y, near.z]) > LAMP_MATCH_RADIUS_M {
            continue;
        }
        for (a, t) in [near.x, near.y, near.z].into_iter().enumerate() {
            index.push(i + a);
            err.push(x[i + a] - t);
        }
    }
    if let Some(c) = &truth.camera {
        let c = truth_camera(c);
        for &param in ekf.estimated_parameters() {
            let i = ekf.camera_state_index(param)?;
            index.push(i);
            err.push(x[i] - c.get(param));
        }
    }
    let n = index.len();
    let sub = nalgebra::DMatrix::from_fn(n, n, |a, b| p[(index[a], index[b])]);
    let e = nalgebra::DVector::from_vec(err);
    let v = e.dot(&(sub.cholesky()?.solve(&e)));
    v.is_finite().then_some((v, n))
}

/// A planar rigid motion: rotation about z by `angle`, then translation `(tx, ty)`.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Planar {
    angle: f64,
    tx: f64,
    ty: f64,
}

impl Planar {
    const IDENTITY: Self = Self {
        angle: 0.0,
        tx: 0.0,
        ty: 0.0,
    };

    /// The least-squares motion mapping the points `a` onto `b` (closed form); the identity
    /// with fewer than two pairs.
    fn fit(pairs: &[([f64; 2], [f64; 2])]) -> Self {
        if pairs.len() < 2 {
            return Self::IDENTITY;
        }
        let n = pairs.len() as f64;
        let (mut ax, mut ay, mut bx, mut by) = (0.0, 0.0, 0.0, 0.0);
        for (a, b) in pairs {
            ax += a[0];
            ay += a[1];
            bx += b[0];
            by += b[1];
        }
        let (ax, ay, bx, by) = (ax / n, ay / n, bx / n, by / n);
        let (mut c, mut s) = (0.0, 0.0);
        for (a, b) in pairs {
            let (px, py) = (a[0] - ax, a[1] - ay);
            let (qx, qy) = (b[0] - bx, b[1] - by);
            c += px * qx + py * qy;
            s += px * qy - py * qx;
        }
        let angle = s.atan2(c);
        let (sn, cs) = angle.sin_cos();
        Self {
            angle,
            tx: bx - (cs * ax - sn * ay),
            ty: by - (sn * ax + cs * ay),
        }
    }

    fn apply(&self, p: [f64; 3]) -> [f64; 3] {
        let (sn, cs) = self.angle.sin_cos();
        [
            cs * p[0] - sn * p[1] + self.tx,
            sn * p[0] + cs * p[1] + self.ty,
            p[2],
        ]
    }
}

fn distance(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// RMS of the 3-D differences after the planar rigid motion that best maps the estimates onto
/// the truths.
fn aligned_rms(pairs: &[([f64; 3], [f64; 3])]) -> f64 {
    if pairs.is_empty() {
        return f64::NAN;
    }
    let planar: Vec<([f64; 2], [f64; 2])> = pairs
        .iter()
        .map(|(e, t)| ([e[0], e[1]], [t[0], t[1]]))
        .collect();
    let fit = Planar::fit(&planar);
    let sq: f64 = pairs
        .iter()
        .map(|(e, t)| distance(fit.apply(*e), *t).powi(2))
        .sum();
    (sq / pairs.len() as f64).sqrt()
}
