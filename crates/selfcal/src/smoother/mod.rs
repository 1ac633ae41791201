//! Phase 1 as one batch over every frame: every pose since the first frame, every landmark and
//! the estimated camera parameters `C` solved together by Levenberg-Marquardt on the pixels
//! and the odometry (docs/phase1.md, "The batch over every frame").
//!
//! The paper's eq. (1) compares landmarks triangulated at two instants with the odometry's
//! motion between them. Frame pairs far apart share no noise but use one frame in forty; pairs
//! that overlap share their odometry and pixel noise, and treating them as independent made the
//! sigmas four times too small (docs/phase1.md). Solving for the poses of every frame instead
//! models every correlation exactly: each frame's pixels enter once, each odometry interval
//! once, between consecutive frames. The maximum-likelihood estimate of `C` then uses all the
//! information the drive carries, so the stable rule fires as soon as that information allows.
//!
//! Unknowns: poses `x_1 .. x_{n-1}` (the first frame's pose is the world origin,
//! vehicle-interfaces.md section 1), the estimated camera parameters and the landmarks. The
//! normal equations are block tridiagonal in the poses (odometry between neighbours) with an
//! arrow (each pose sees some landmarks and `C`): the poses are eliminated in time order, which
//! costs `O(n w^2)` for an arrow of width `w = |C| + 3 m`, and the reduced system over the last
//! pose, `C` and the landmarks is exactly their joint marginal information. Its inverse is what
//! phase 2 starts from: the EKF's state and covariance at the switch, with the map in the first
//! frame's world frame and the frames of phase 1 all mapped.
//!
//! Hand-written rather than a sparse solver from a crate: the structure is fixed and known
//! (a chain with an arrow), the solve must build without `std` for the vehicle controller, and
//! the elimination order that makes the reduced system the phase-2 prior is part of the method.
//!
//! By concern: [`SmootherSettings`] (`settings`), the odometry and lens-whitened pixel factors
//! (`factors`), the normal equations, their elimination and the damped step (`system`); the
//! [`Smoother`] here holds the frames, the landmarks, the marginalised prior and the hand-over.

mod closure;
mod consistency;
mod factors;
mod settings;
mod system;

pub use consistency::{
    OdometryConsistency, OdometryStep, OdometryWidening, SPANS_S as CONSISTENCY_SPANS_S,
    STRONG_HEADING_LIMIT, heading_strongly_worse, judge as judge_odometry, long_run_ratio,
    trajectory_consistency, widened as widened_odometry_covariance,
};
pub use settings::SmootherSettings;

use alloc::collections::BTreeMap;
use alloc::vec::Vec;

use nalgebra::{DMatrix, DVector, Matrix3, SMatrix, Vector2, Vector3};

use crate::observability::structural_trap;
use rig_model::camera::{CameraParams, N_CAMERA, N_PARAMS, Param, ParamVector, Pose2, wrap_angle};
use rig_model::config::Rig;
use rig_model::handover::{
    BatchHandover, BatchLandmark, HandoverReason, JointEstimate, Mat10, ObservabilityReport,
    ParamObservability,
};
use rig_model::odometry::OdometryFactor;
use rig_model::rig::{Measurement, project, project_with_jacobians, triangulate};

use factors::{huber_cost, lens_whitening, odometry_information};
use system::{Step, System, vec3x3};

/// What the marginalised frames said: a Gaussian over `[first kept pose, C, landmarks
/// 0..L0]` in information form, linearised at the estimate when they were marginalised.
/// Cost `dx^T info dx - 2 eta^T dx` with `dx` the offset from that estimate.
#[derive(Debug, Clone)]
struct Prior {
    info: DMatrix<f64>,
    eta: DVector<f64>,
    pose: Pose2,
    camera: Vec<f64>,
    landmarks: Vec<Vector3<f64>>,
}

impl Prior {
    fn delta(
        &self,
        pose: &Pose2,
        camera: &CameraParams,
        estimated: &[Param],
        landmarks: &[Vector3<f64>],
    ) -> DVector<f64> {
        let mut dx = DVector::zeros(self.info.nrows());
        dx[0] = pose.x - self.pose.x;
        dx[1] = pose.y - self.pose.y;
        dx[2] = wrap_angle(pose.theta - self.pose.theta);
        let m = estimated.len();
        for (a, (p, c0)) in estimated.iter().zip(&self.camera).enumerate() {
            dx[3 + a] = camera.get(*p) - c0;
        }
        for (j, (l, l0)) in landmarks.iter().zip(&self.landmarks).enumerate() {
            for a in 0..3 {
                dx[3 + m + 3 * j + a] = l[a] - l0[a];
            }
        }
        dx
    }
}

/// The result of one solve.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SolveSummary {
    /// Iterations taken.
    pub iterations: usize,
    /// Robust cost at the solution.
    pub cost: f64,
    /// Observations used, and how many the Huber loss down-weighted.
    pub observations: usize,
    /// Observations beyond the Huber threshold.
    pub outliers: usize,
}

#[derive(Debug, Clone)]
struct Frame {
    t_us: u64,
    pose: Pose2,
    /// Odometry from the previous frame: the motion (with its dependence on `V`) and its
    /// information (inverse covariance).
    odometry: Option<(OdometryFactor, Matrix3<f64>)>,
    observations: Vec<(usize, Measurement)>,
    /// Each observation's whitening through real lenses ([`lens_whitening`]), computed once.
    whitening: Vec<Option<nalgebra::Matrix4<f64>>>,
    /// Measurements of tracks not yet confirmed, by track: they join their landmark when
    /// the track is confirmed (kept for [`TENTATIVE_FRAMES`] frames).
    tentative: Vec<(u64, Measurement)>,
}

/// A parameter further than this many prior sigmas from its nominal value is not a step the
/// batch takes ([`Smoother::plausible`]): the prior says it cannot be there.
const PLAUSIBLE_PRIOR_SIGMAS: f64 = 10.0;

/// A change of speed that counts as excitation for the clock offset, m/s: well above the
/// odometry noise of a frame interval.
const SPEED_STEP_MPS: f64 = 0.05;

/// A yaw rate that counts as turning, rad/s (about 1 degree a second: above a gyro's bias).
const MOVING_YAW_RATE_RADPS: f64 = 0.02;

/// Distance the vehicle must have travelled (or [`MIN_TURN_FOR_STABLE_RAD`] turned) before
/// phase 1 may call itself stable, metres: two seconds of the paper's 0.25 m/s.
pub const MIN_TRAVEL_FOR_STABLE_M: f64 = 0.5;

/// The turn that does as well, radians (about 17 degrees).
pub const MIN_TURN_FOR_STABLE_RAD: f64 = 0.3;

/// Frames back that a newly confirmed track's earlier measurements are looked for.
const TENTATIVE_FRAMES: usize = 8;

/// Frames a track's held measurements are kept: a tentative track's, and a track held back
/// while a blind vehicle waits for a constellation ([`closure::DEFER_FRAMES`]).
const TENTATIVE_KEEP: usize = TENTATIVE_FRAMES + closure::DEFER_FRAMES;

/// Phase 1 over every frame (see the module docs).
#[derive(Debug, Clone)]
pub struct Smoother {
    rig: Rig,
    settings: SmootherSettings,
    estimated: Vec<Param>,
    camera: CameraParams,
    frames: Vec<Frame>,
    landmarks: Vec<BatchLandmark>,
    track_landmark: BTreeMap<u64, usize>,
    lambda: f64,
    total_rotation: f64,
    /// Sum of the absolute changes of speed between frames, m/s (the clock offset's
    /// excitation).
    speed_change: f64,
    /// The last frame interval's speed, m/s.
    last_speed: Option<f64>,
    /// Distance the odometry travelled at [`SPEED_STEP_MPS`] or faster, and rotation it turned
    /// at [`MOVING_YAW_RATE_RADPS`] or faster: motion, not its noise or a yaw-rate bias
    /// ([`MIN_TRAVEL_FOR_STABLE_M`]).
    moved: (f64, f64),
    /// `(t_us, values, sigmas)` of C after each solve.
    history: Vec<(u64, ParamVector, ParamVector)>,
    /// Joint covariance `[last pose, C, landmarks]` of the last solve.
    last_covariance: Option<DMatrix<f64>>,
    last_summary: Option<SolveSummary>,
    stable_run: usize,
    handover: Option<BatchHandover>,
    /// Phase 2: the batch goes on as a fixed-lag smoother ([`Smoother::start_mapping`]).
    mapping: bool,
    /// What the marginalised frames said about the first kept frame's pose, C and the
    /// landmarks (`None`: nothing marginalised yet, the first frame is the world origin).
    prior: Option<Prior>,
    /// Frames marginalised so far: the absolute index of `frames[0]`.
    dropped: usize,
    /// Final poses of the marginalised frames, not yet taken.
    smoothed: Vec<(u64, Pose2)>,
    /// Frames added since the last solve (mapping).
    since_solve: usize,
    /// How the odometry's noise model was widened ([`Smoother::odometry_widening`]).
    widening: Option<OdometryWidening>,
    /// How far phase 1 has driven without the map in view ([`closure`]).
    blind: closure::Blind,
    /// Loops phase 1 closed by a constellation after a blind stretch.
    loops_closed: usize,
    /// The tracks declined in the last [`closure::HOLD_FRAMES`] frames of a blind stretch,
    /// the latest of each: the constellation searched for.
    declined_tracks: BTreeMap<u64, closure::Declined>,
}

impl Smoother {
    /// A batch for this rig; the first frame's pose is the world origin.
    pub fn new(rig: Rig, settings: SmootherSettings) -> Self {
        let estimated = rig.estimate.clone();
        let camera = rig.nominal;
        Self {
            rig,
            settings,
            estimated,
            camera,
            frames: Vec::new(),
            landmarks: Vec::new(),
            track_landmark: BTreeMap::new(),
            lambda: 1e-4,
            total_rotation: 0.0,
            speed_change: 0.0,
            last_speed: None,
            moved: (0.0, 0.0),
            history: Vec::new(),
            last_covariance: None,
            last_summary: None,
            stable_run: 0,
            handover: None,
            mapping: false,
            prior: None,
            dropped: 0,
            smoothed: Vec::new(),
            since_solve: 0,
            widening: None,
            blind: closure::Blind::default(),
            loops_closed: 0,
            declined_tracks: BTreeMap::new(),
        }
    }

    /// How the odometry agrees with the batch's trajectory (the last solve's, dead reckoning
    /// since) over each of [`CONSISTENCY_SPANS_S`] and over single frame intervals, each
    /// residual against the variance its factor gives it (issue 36; see
    /// [`OdometryConsistency`]): about 1 when the rig file's odometry noise is right. `None`
    /// for a span the frames do not cover once. `O(frames)`.
    pub fn odometry_consistency(&self) -> [Option<OdometryConsistency>; 2] {
        consistency::odometry_consistency(&self.frames, &self.camera.vehicle, CONSISTENCY_SPANS_S)
    }

    /// Whether the odometry's check has had enough windows of its first span to judge
    /// (`consistency::MIN_WINDOWS`), or the batch has waited for them twice as long as they
    /// take (a log whose odometry is missing or gapped would otherwise keep phase 1 to its
    /// frame budget).
    #[allow(clippy::cast_precision_loss)] // a handful of windows; microseconds of a drive
    fn odometry_checked(&self) -> bool {
        let [short] = consistency::odometry_consistency(
            &self.frames,
            &self.camera.vehicle,
            [CONSISTENCY_SPANS_S[0]],
        );
        let waited_s = 2.0 * consistency::MIN_WINDOWS as f64 * CONSISTENCY_SPANS_S[0];
        let span_s = match (self.frames.first(), self.frames.last()) {
            (Some(a), Some(b)) => b.t_us.saturating_sub(a.t_us) as f64 * 1e-6,
            _ => 0.0,
        };
        short.is_some_and(|c| c.windows >= consistency::MIN_WINDOWS) || span_s >= waited_s
    }

    /// How the batch widened the odometry's noise model after its solves showed the odometry
    /// worse, or its errors longer-lived, than the rig file states (issue 36; `None`: it did
    /// not). The caller integrates later frames' odometry with the rig file's `velocity` and
    /// `yaw_rate` times the square roots of [`OdometryWidening::factors`].
    pub fn odometry_widening(&self) -> Option<OdometryWidening> {
        self.widening
    }

    /// Takes a widening, its own (after a solve) or one judged elsewhere (phase 2's check of
    /// the filter's trajectory: this smoother's window of 5 s holds fewer than the eight
    /// windows of the short span a judgement needs, and it takes no first widening on strong
    /// evidence, [`judge_odometry`]): every stored odometry factor's variance widened by
    /// `translation` and `heading` (variance factors, at least 1; none while it is stopped,
    /// when it holds no frames), and `widening` the model from now on.
    pub fn widen_odometry(&mut self, translation: f64, heading: f64, widening: OdometryWidening) {
        if translation > 1.0 || heading > 1.0 {
            consistency::widen(&mut self.frames, translation.max(1.0), heading.max(1.0));
        }
        self.widening = Some(widening);
    }

    /// After a solve: judges the odometry against it and widens every stored odometry
    /// factor's variance when the check says so ([`consistency::judge`]). Returns whether it
    /// widened.
    fn check_odometry(&mut self, t_us: u64) -> bool {
        let spans = self.odometry_consistency();
        // Strong evidence on a few windows is taken by phase 1's batch, which looks once
        // against a trajectory good to a millimetre; not by phase 2's smoother, which looks at
        // its short window every few frames (the navigator's check takes it there).
        let strong_first = !self.mapping;
        let Some(((kt, kh), w)) = consistency::judge(spans, self.widening, t_us, strong_first)
        else {
            return false;
        };
        self.widen_odometry(kt, kh, w);
        kt > 1.0 || kh > 1.0
    }

    /// The buffered frames' poses and the odometry's motion between each and the next with its
    /// covariance under the model in use (`steps[i]` from `poses[i]` to `poses[i + 1]`;
    /// `None` without odometry): what [`trajectory_consistency`] judges. At the hand-over,
    /// phase 2's check of the odometry begins with it.
    pub fn odometry_track(&self) -> (Vec<Pose2>, Vec<Option<OdometryStep>>) {
        consistency::track(&self.frames, &self.camera.vehicle)
    }

    /// Frames buffered.
    pub fn frames(&self) -> usize {
        self.frames.len()
    }

    /// Landmarks so far.
    pub fn landmarks(&self) -> &[BatchLandmark] {
        &self.landmarks
    }

    /// The current camera estimate.
    pub fn camera(&self) -> CameraParams {
        self.camera
    }

    /// The camera covariance of the last solve (the prior before the first).
    pub fn camera_covariance(&self) -> Mat10 {
        let mut cov = Mat10::zeros();
        match &self.last_covariance {
            Some(joint) => {
                for (a, pa) in self.estimated.iter().enumerate() {
                    for (b, pb) in self.estimated.iter().enumerate() {
                        if let Some(v) = joint.get((3 + a, 3 + b)) {
                            cov[(pa.index(), pb.index())] = *v;
                        }
                    }
                }
            }
            None => {
                for p in &self.estimated {
                    let s = self.rig.prior[p.index()].unwrap_or(0.0);
                    cov[(p.index(), p.index())] = s * s;
                }
            }
        }
        cov
    }

    /// The latest frame's pose and its covariance (the last solve's, dead reckoning since).
    pub fn last_pose(&self) -> Option<Pose2> {
        self.frames.last().map(|f| f.pose)
    }

    /// `(t_us, values, sigmas)` of C after each solve.
    pub fn history(&self) -> &[(u64, ParamVector, ParamVector)] {
        &self.history
    }

    /// The last solve's summary.
    pub fn last_summary(&self) -> Option<SolveSummary> {
        self.last_summary
    }

    /// The hand-over, once it happened.
    pub fn handover(&self) -> Option<&BatchHandover> {
        self.handover.as_ref()
    }

    /// Adds a frame: the odometry motion since the previous frame with its covariance
    /// (`None` for the first frame, or when no odometry covered the interval), the
    /// confirmed tracks' measurements and the tentative tracks' (they are used once their
    /// track is confirmed: the first frames of a track count too, and the first frame's
    /// lamps anchor the map). Returns `true` when a solve ran. Does nothing once the
    /// hand-over happened.
    pub fn add_frame(
        &mut self,
        t_us: u64,
        odometry: Option<OdometryFactor>,
        observations: &[(u64, Measurement)],
        tentative: &[(u64, Measurement)],
    ) -> bool {
        if self.handover.is_some() {
            return false;
        }
        let odometry = odometry_information(odometry);
        let mut pose = match (self.frames.last(), &odometry) {
            (None, _) => Pose2::default(),
            (Some(prev), Some((o, _))) => o.motion_for(&self.camera.vehicle).apply(&prev.pose),
            (Some(prev), None) => prev.pose,
        };
        if let Some((o, _)) = &odometry {
            self.total_rotation += libm::fabs(o.motion.dtheta);
            if o.motion.dt_s > 0.0 {
                // Changes beyond SPEED_STEP_MPS from the last counted speed: the odometry's
                // noise is not a change of speed.
                let speed = libm::hypot(o.motion.dx, o.motion.dy) / o.motion.dt_s;
                if speed >= SPEED_STEP_MPS {
                    self.moved.0 += speed * o.motion.dt_s;
                }
                if libm::fabs(o.motion.dtheta) >= MOVING_YAW_RATE_RADPS * o.motion.dt_s {
                    self.moved.1 += libm::fabs(o.motion.dtheta);
                }
                match self.last_speed {
                    Some(last) if libm::fabs(speed - last) >= SPEED_STEP_MPS => {
                        self.speed_change += libm::fabs(speed - last);
                        self.last_speed = Some(speed);
                    }
                    Some(_) => {}
                    None => self.last_speed = Some(speed),
                }
            }
        }
        let k = self.dropped + self.frames.len();
        let mut used: Vec<(usize, Measurement)> = Vec::with_capacity(observations.len());
        let seen_now: Vec<usize> = observations
            .iter()
            .filter_map(|(t, _)| self.track_landmark.get(t).copied())
            .collect();
        let defer = self.close_loop(&mut pose, &odometry, observations, &seen_now);
        // Again: a closure binds tracks.
        let seen_now: Vec<usize> = observations
            .iter()
            .filter_map(|(t, _)| self.track_landmark.get(t).copied())
            .collect();
        let mut created = 0usize;
        let mut held: Vec<(u64, Measurement)> = Vec::new();
        let mut held_at_budget = false;
        let mut landmarks_full = false;
        for (track, z) in observations {
            if !z.iter().all(|v| v.is_finite()) {
                continue;
            }
            let index = match self.track_landmark.get(track) {
                Some(&j) => j,
                None => {
                    let Some(j) = self.rebind(&pose, z, &seen_now, &used) else {
                        if defer {
                            // Held, like a tentative track's: bound or born later, it is
                            // backfilled.
                            held.push((*track, *z));
                            continue;
                        }
                        if seen_now.len() + created >= self.settings.max_in_view {
                            continue;
                        }
                        if self.landmarks.len() >= self.settings.max_landmarks {
                            // Blind, the hand-over waits for the map to come back into view
                            // (a hand-over now would give phase 2 a pose still blind).
                            if self.blind.searching() && self.blind.deferred < closure::DEFER_FRAMES
                            {
                                held_at_budget = true;
                                held.push((*track, *z));
                            } else {
                                landmarks_full = true;
                            }
                            continue;
                        }
                        created += 1;
                        let Ok(tri) = triangulate(&self.camera, z) else {
                            continue;
                        };
                        let position = tri.p_in_world(&self.camera, &pose);
                        if !position.iter().all(|v| v.is_finite()) {
                            continue;
                        }
                        if self.landmarks.iter().any(|l| {
                            (l.position - position).norm() < self.settings.min_separation_m
                        }) {
                            created -= 1;
                            continue;
                        }
                        self.landmarks.push(BatchLandmark {
                            position,
                            track: *track,
                            first_frame: k,
                            observations: 0,
                        });
                        let j = self.landmarks.len() - 1;
                        self.track_landmark.insert(*track, j);
                        self.backfill(*track, j);
                        used.push((j, *z));
                        continue;
                    };
                    self.track_landmark.insert(*track, j);
                    self.backfill(*track, j);
                    j
                }
            };
            if used.iter().any(|(u, _)| *u == index) {
                continue;
            }
            if let Some(l) = self.landmarks.get_mut(index) {
                l.track = *track;
            }
            used.push((index, *z));
        }
        if held_at_budget && !defer {
            self.blind.deferred += 1;
        }
        for (j, _) in &used {
            if let Some(l) = self.landmarks.get_mut(*j) {
                l.observations += 1;
            }
        }
        let tentative: Vec<(u64, Measurement)> = tentative
            .iter()
            .filter(|(_, z)| z.iter().all(|v| v.is_finite()))
            .copied()
            .chain(held)
            .collect();
        if let Some(old) = self.frames.len().checked_sub(TENTATIVE_KEEP)
            && let Some(f) = self.frames.get_mut(old)
        {
            f.tentative = Vec::new();
        }
        self.frames.push(Frame {
            t_us,
            pose,
            odometry,
            whitening: used
                .iter()
                .map(|(_, z)| lens_whitening(&self.rig, z))
                .collect(),
            observations: used,
            tentative,
        });
        let n = self.frames.len();
        let due = n >= 2 && (n - 1).is_multiple_of(self.settings.solve_every);
        // A full landmark budget hands over only once the odometry's check has had its first
        // span's windows (`consistency::MIN_WINDOWS`, 8 s of them): a hand-over before it
        // carries a noise model nothing has checked. A fisheye's dense hall filled its 48
        // landmarks in 8.8 s, its odometry's 0.6 s of memory unstated, and phase 2, on the
        // white model, ended 9.8 m off (docs/vehicle.md, "Phase 2 looks again").
        let full = n >= self.settings.max_frames
            || (landmarks_full && (self.mapping || self.odometry_checked()));
        if !(due || full) {
            return false;
        }
        self.solve_and_judge(t_us);
        if full && self.handover.is_none() {
            self.hand_over(HandoverReason::BufferFull);
        }
        true
    }

    /// Forces the hand-over now (the end of a log), after a last solve.
    pub fn finish(&mut self) -> Option<&BatchHandover> {
        if self.handover.is_none() && !self.frames.is_empty() {
            if self.frames.len() >= 2 {
                self.solve_and_judge(self.frames.last().map_or(0, |f| f.t_us));
            }
            if self.handover.is_none() {
                self.hand_over(HandoverReason::Requested);
            }
        }
        self.handover.as_ref()
    }

    /// A track just bound to landmark `j`: its tentative measurements of the frames before
    /// (consecutive, newest first) become observations of `j`.
    fn backfill(&mut self, track: u64, j: usize) {
        let n = self.frames.len();
        let mut earliest = None;
        for i in (n.saturating_sub(TENTATIVE_KEEP)..n).rev() {
            let Some(f) = self.frames.get_mut(i) else {
                break;
            };
            let Some(&(_, z)) = f.tentative.iter().find(|(t, _)| *t == track) else {
                continue;
            };
            if f.observations.iter().any(|(u, _)| *u == j) {
                break;
            }
            f.observations.push((j, z));
            f.whitening.push(lens_whitening(&self.rig, &z));
            earliest = Some(i);
        }
        if let (Some(i), Some(l)) = (earliest, self.landmarks.get_mut(j)) {
            l.observations += (n - i) as u64;
            l.first_frame = l.first_frame.min(self.dropped + i);
        }
    }

    /// Landmarks `0..seen(k)` for each absolute frame `k`: a prefix that holds every
    /// landmark first seen at or before `k` (first frames are in creation order but for the
    /// few frames a backfill reaches back).
    fn seen_prefix(&self) -> Vec<usize> {
        let mut suffix_min: Vec<usize> = Vec::with_capacity(self.landmarks.len());
        let mut low = usize::MAX;
        for l in self.landmarks.iter().rev() {
            low = low.min(l.first_frame);
            suffix_min.push(low);
        }
        suffix_min.reverse();
        suffix_min
    }

    /// Phase 1's loop closure after a blind stretch ([`closure`]): keeps count of the distance
    /// driven without two landmarks in view; once it is long enough, the tracks that the
    /// per-observation test ([`Self::rebind`]) declines are tried as a constellation against
    /// the landmarks not in view. A correction found moves `pose` (and the blind frames
    /// before it, spread along the stretch, as the solve's start) and binds them. Returns
    /// whether this frame's declined tracks wait for a constellation instead of becoming new
    /// landmarks (at most [`closure::DEFER_FRAMES`] frames in a row).
    fn close_loop(
        &mut self,
        pose: &mut Pose2,
        odometry: &Option<(OdometryFactor, Matrix3<f64>)>,
        observations: &[(u64, Measurement)],
        seen_now: &[usize],
    ) -> bool {
        let k = self.dropped + self.frames.len();
        // The map as it was when the vehicle last saw it: landmarks born during the blind
        // stretch were placed from the drifting pose and re-anchor nothing.
        let searching_since = self.blind.searching_since;
        let old = |l: &BatchLandmark| searching_since.is_none_or(|a| l.first_frame < a);
        let old_seen = seen_now
            .iter()
            .filter(|&&j| self.landmarks.get(j).is_some_and(old))
            .count();
        if old_seen >= 2 {
            self.map_in_view(k);
            return false;
        }
        if let Some((o, _)) = odometry {
            self.blind.distance_m += libm::hypot(o.motion.dx, o.motion.dy);
            self.blind.seconds += o.motion.dt_s.max(0.0);
        }
        if !self.blind.searching() {
            return false;
        }
        if self.blind.searching_since.is_none() {
            self.blind.searching_since = Some(k);
        }
        let declined: Vec<closure::Declined> = observations
            .iter()
            .filter(|(t, z)| {
                !self.track_landmark.contains_key(t)
                    && z.iter().all(|v| v.is_finite())
                    && self.rebind(pose, z, seen_now, &[]).is_none()
            })
            .filter_map(|(t, z)| {
                let world = triangulate(&self.camera, z)
                    .ok()?
                    .p_in_world(&self.camera, pose);
                world
                    .iter()
                    .all(|v| v.is_finite())
                    .then_some(closure::Declined {
                        track: *t,
                        world,
                        z: *z,
                        pose: *pose,
                        frame: k,
                    })
            })
            .collect();
        // The constellation spans a few seconds of the stretch: lamps 4 m apart come back
        // into view one at a time, and the dead reckoning over seconds is good enough to
        // put them together ([`closure::HOLD_FRAMES`]).
        for d in &declined {
            self.declined_tracks.insert(d.track, *d);
        }
        let track_landmark = &self.track_landmark;
        self.declined_tracks
            .retain(|t, d| d.frame + closure::HOLD_FRAMES >= k && !track_landmark.contains_key(t));
        let constellation: Vec<closure::Declined> =
            self.declined_tracks.values().copied().collect();
        if declined.is_empty() {
            return false;
        }
        let landmarks: Vec<(usize, Vector3<f64>)> = self
            .landmarks
            .iter()
            .enumerate()
            .filter(|(j, l)| !seen_now.contains(j) && old(l))
            .map(|(j, l)| (j, l.position))
            .collect();
        let seen: Vec<Measurement> = observations.iter().map(|(_, z)| *z).collect();
        let view = closure::View {
            seen: &seen,
            width: f64::from(self.rig.width),
            height: f64::from(self.rig.height),
        };
        if let Some(found) = closure::find(
            &self.camera,
            pose,
            self.blind.extent_m(),
            &constellation,
            &landmarks,
            &view,
        ) {
            self.spread_correction(pose, &found.pose);
            *pose = found.pose;
            for (track, j) in found.bound {
                self.track_landmark.insert(track, j);
                self.backfill(track, j);
            }
            self.loops_closed += 1;
            self.map_in_view(k);
            return false;
        }
        // Wait for a constellation only where the map has landmarks the declined points may
        // be: a part of the hall seen for the first time is mapped at once.
        if self.blind.deferred < closure::DEFER_FRAMES
            && closure::within_reach(pose, self.blind.extent_m(), &declined, &landmarks)
        {
            self.blind.deferred += 1;
            return true;
        }
        false
    }

    /// Frame `k` has the map in view (seen, or found again): no blind stretch, nothing held
    /// for a constellation.
    fn map_in_view(&mut self, k: usize) {
        self.declined_tracks.clear();
        self.blind = closure::Blind {
            since_frame: Some(k),
            ..closure::Blind::default()
        };
    }

    /// Moves the blind frames (after the last one with the map in view) by a share of the
    /// correction `from -> to` of the newest pose that grows along the stretch: the start the
    /// solve needs to close the loop without Gauss-Newton crossing degrees in one step.
    fn spread_correction(&mut self, from: &Pose2, to: &Pose2) {
        let Some(start) = self.blind.since_frame else {
            return;
        };
        let dropped = self.dropped;
        let span = (dropped + self.frames.len()).saturating_sub(start);
        if span == 0 {
            return;
        }
        let turn = wrap_angle(to.theta - from.theta);
        #[allow(clippy::cast_precision_loss)] // frame counts far below 2^53
        let share_at = |frame: usize| {
            frame
                .checked_sub(start)
                .filter(|s| *s > 0)
                .map(|s| s as f64 / span as f64)
        };
        // `share` of the correction: that share of the turn about `from`, of the shift.
        let pivot = Vector2::new(from.x, from.y);
        let shift = Vector2::new(to.x, to.y) - pivot;
        let part = |share: f64| closure::Correction {
            turn: share * turn,
            shift: share * shift,
        };
        // A landmark born in the stretch moves with the frame it was born in.
        for l in &mut self.landmarks {
            if let Some(share) = share_at(l.first_frame) {
                let p = part(share).apply(&pivot, &l.position.xy());
                (l.position.x, l.position.y) = (p.x, p.y);
            }
        }
        for (i, f) in self.frames.iter_mut().enumerate() {
            if let Some(share) = share_at(dropped + i) {
                f.pose = part(share).apply_pose(&pivot, &f.pose);
            }
        }
    }

    /// Loops phase 1 closed by recognising the lamps it came back to after a blind stretch
    /// as a constellation of the map's (docs/vehicle.md, "Dark stretches").
    pub fn loops_closed(&self) -> usize {
        self.loops_closed
    }

    /// The unique landmark, not seen under another track in this frame, that projects close
    /// to `z` from `pose`.
    fn rebind(
        &self,
        pose: &Pose2,
        z: &Measurement,
        seen_now: &[usize],
        used: &[(usize, Measurement)],
    ) -> Option<usize> {
        let mut found = None;
        for (j, l) in self.landmarks.iter().enumerate() {
            if seen_now.contains(&j) || used.iter().any(|(u, _)| *u == j) {
                continue;
            }
            let Ok(p) = project(&self.camera, pose, &l.position) else {
                continue;
            };
            if (p - z).amax() <= self.settings.rebind_px {
                if found.is_some() {
                    return None;
                }
                found = Some(j);
            }
        }
        found
    }

    /// Baseline and odometry scale both estimated: only their product is observable (stereo
    /// and odometry are the run's only metric scales, vehicle-interfaces.md 1.2), so the one
    /// with the looser prior follows the other's prior and is not held against the stable rule.
    fn scale_pair_trap(&self, p: Param) -> Option<&'static str> {
        (matches!(p, Param::Baseline | Param::OdomScale)
            && self.estimated.contains(&Param::Baseline)
            && self.estimated.contains(&Param::OdomScale))
        .then_some(
            "only the product baseline x odom_scale is observable: each is known only as well as the other's prior",
        )
    }

    /// Whether a trial step's parameters are physically possible: an odometry scale or yaw
    /// scale between 0.5 and 2, and every estimated parameter within
    /// [`PLAUSIBLE_PRIOR_SIGMAS`] prior sigmas of its nominal value. Near a scale of zero the
    /// reported-units odometry residual degenerates (a yaw scale of 0.0004 makes every
    /// interval a tight spiral whose predicted motion, and residual, vanish), and a solve from
    /// a poor start once stepped there; the damping then grows instead.
    fn plausible(&self, c: &CameraParams) -> bool {
        let v = &c.vehicle;
        if !((0.5..=2.0).contains(&v.odom_scale) && (0.5..=2.0).contains(&v.odom_yaw_scale)) {
            return false;
        }
        self.estimated.iter().all(|&p| {
            let s = self.prior_sigma(p);
            !s.is_finite()
                || libm::fabs(c.get(p) - self.rig.nominal.get(p)) <= PLAUSIBLE_PRIOR_SIGMAS * s
        })
    }

    fn prior_sigma(&self, p: Param) -> f64 {
        self.rig.prior[p.index()].unwrap_or(f64::INFINITY)
    }

    /// Solves, records C, applies the stable rule.
    fn solve_and_judge(&mut self, t_us: u64) {
        let Some(summary) = self.solve() else {
            return;
        };
        self.last_summary = Some(summary);
        if self.check_odometry(t_us) {
            // The sigmas of this solve were the narrower model's: not a step toward stability.
            self.stable_run = 0;
            return;
        }
        let cov = self.camera_covariance();
        let values = self.camera.to_vector();
        let sigmas = ParamVector::from_fn(|i, _| libm::sqrt(cov[(i, i)].max(0.0)));
        let report = self.observability(&cov);
        let steady = self.history.last().is_some_and(|(_, prev, _)| {
            report.params.iter().all(|p| {
                let i = p.param.index();
                p.structural
                    || (p.observable
                        && libm::fabs(values[i] - prev[i])
                            <= self.settings.step_fraction * sigmas[i])
            })
        });
        let any = report.params.iter().any(|p| p.observable) || report.params.is_empty();
        self.stable_run = if steady && any {
            self.stable_run + 1
        } else {
            0
        };
        self.history.push((t_us, values, sigmas));
        // A standing vehicle informs no scale and no turn: whatever the batch's sigmas say
        // (they are as right as the odometry's noise model), phase 1 is not stable before the
        // vehicle has moved (issue 36).
        let moved =
            self.moved.0 >= MIN_TRAVEL_FOR_STABLE_M || self.moved.1 >= MIN_TURN_FOR_STABLE_RAD;
        if self.stable_run >= self.settings.consecutive && moved {
            self.hand_over(HandoverReason::Stable);
        }
    }

    /// The joint covariance of `[last pose, C, landmarks]` over every parameter in `all`, the
    /// `held` ones at their nominal values with their prior (the consider, or Schmidt,
    /// covariance): `P_x|u + S P_u S^T` for the others, `S P_u` across, `P_u` for the held,
    /// with `S` the sensitivity of the solution to the held parameters. It is the inverse of
    /// the normal equations over every parameter whose held block is changed so that the
    /// held parameters' Schur complement is their prior's information: `H_uu + P_u^-1 -
    /// Sigma_u^-1`. Returns `(parameters, covariance, C's 10 x 10 block)`; `None` when a
    /// system is singular.
    fn considered_covariance(
        &mut self,
        all: &[Param],
        held: &[Param],
    ) -> Option<(Vec<Param>, DMatrix<f64>, Mat10)> {
        let poses: Vec<Pose2> = self.frames.iter().map(|f| f.pose).collect();
        let landmarks: Vec<Vector3<f64>> = self.landmarks.iter().map(|l| l.position).collect();
        // The normal equations over every parameter: the batch estimating `all` for this
        // one system, then its own list again.
        let reduced = core::mem::replace(&mut self.estimated, all.to_vec());
        let mut sys = self.normal_equations(&self.camera, &poses, &landmarks);
        self.estimated = reduced;
        let joint = sys.marginal_covariance()?;
        let at: Vec<usize> = held
            .iter()
            .filter_map(|p| all.iter().position(|q| q == p))
            .collect();
        let k = at.len();
        let sigma_u = DMatrix::from_fn(k, k, |a, b| {
            joint[(
                3 + at.get(a).copied().unwrap_or(0),
                3 + at.get(b).copied().unwrap_or(0),
            )]
        });
        let sigma_u_inv = sigma_u.try_inverse()?;
        for (a, &ia) in at.iter().enumerate() {
            for (b, &ib) in at.iter().enumerate() {
                let prior = if a == b {
                    let s = held.get(a).map_or(f64::INFINITY, |p| self.prior_sigma(*p));
                    1.0 / (s * s)
                } else {
                    0.0
                };
                sys.z[(ia, ib)] += prior - sigma_u_inv[(a, b)];
            }
        }
        let covariance = sys.marginal_covariance()?;
        if !covariance.iter().all(|v| v.is_finite()) {
            return None;
        }
        let mut camera_covariance = Mat10::zeros();
        for (a, pa) in all.iter().enumerate() {
            for (b, pb) in all.iter().enumerate() {
                camera_covariance[(pa.index(), pb.index())] = covariance[(3 + a, 3 + b)];
            }
        }
        Some((all.to_vec(), covariance, camera_covariance))
    }

    /// Which estimated parameters the data informed.
    fn observability(&self, cov: &Mat10) -> ObservabilityReport {
        let c = &self.camera;
        let tilted = c.mount.is_tilted();
        let mut report = ObservabilityReport::default();
        for &p in &self.estimated {
            let i = p.index();
            let prior_sigma = self.prior_sigma(p);
            let posterior_sigma = libm::sqrt(cov[(i, i)].max(0.0));
            let data_info =
                1.0 / (posterior_sigma * posterior_sigma) - 1.0 / (prior_sigma * prior_sigma);
            let data_sigma = if data_info > 0.0 {
                1.0 / libm::sqrt(data_info)
            } else {
                f64::INFINITY
            };
            let observable = posterior_sigma <= self.settings.sigma_fraction * prior_sigma;
            let trap = structural_trap(p, tilted, self.total_rotation, self.speed_change)
                .or_else(|| self.scale_pair_trap(p));
            let reason = (!observable).then_some(trap.unwrap_or(
                "the data so far constrain it less than its prior: more motion (turns, speed) or more landmarks are needed",
            ));
            report.params.push(ParamObservability {
                param: p,
                prior_sigma,
                data_sigma,
                posterior_sigma,
                observable,
                reason,
                structural: !observable && trap.is_some(),
            });
        }
        report
    }

    fn hand_over(&mut self, reason: HandoverReason) {
        if self.frames.is_empty() {
            return;
        }
        // Parameters the data did not inform are held at nominal, not left where the batch
        // drifted them, and the batch is solved again without them.
        let report = self.observability(&self.camera_covariance());
        let uninformed: Vec<Param> = report
            .params
            .iter()
            .filter(|p| !p.observable)
            .map(|p| p.param)
            .collect();
        let mut considered = None;
        if !uninformed.is_empty() {
            for p in &uninformed {
                self.camera.set(*p, self.rig.nominal.get(*p));
            }
            let all = self.estimated.clone();
            self.estimated.retain(|p| !uninformed.contains(p));
            self.last_covariance = None;
            if self.frames.len() >= 2 {
                let _ = self.solve();
                considered = self.considered_covariance(&all, &uninformed);
            }
        }
        // With parameters held, the consider covariance carries their prior into the
        // landmarks, the pose and the informed parameters: a landmark's position depends on
        // the baseline held at nominal, and its sigma must say so.
        let (estimated, covariance, camera_covariance) = match considered {
            Some(c) => c,
            None => {
                let m = self.estimated.len();
                let covariance = self.last_covariance.clone().unwrap_or_else(|| {
                    // No solve: the prior for C, the landmarks known only to within a metre.
                    let w = 3 + m + 3 * self.landmarks.len();
                    let mut p = DMatrix::zeros(w, w);
                    for (a, &pa) in self.estimated.iter().enumerate() {
                        let s = self.prior_sigma(pa);
                        p[(3 + a, 3 + a)] = s * s;
                    }
                    for j in 0..3 * self.landmarks.len() {
                        p[(3 + m + j, 3 + m + j)] = 1.0;
                    }
                    p
                });
                (self.estimated.clone(), covariance, self.camera_covariance())
            }
        };
        let Some(last) = self.frames.last() else {
            return;
        };
        self.handover = Some(BatchHandover {
            t_us: last.t_us,
            reason,
            camera: self.camera,
            camera_covariance,
            pose: last.pose,
            landmarks: self.landmarks.clone(),
            estimated,
            covariance,
            trajectory: self.frames.iter().map(|f| (f.t_us, f.pose)).collect(),
            observability: report,
        });
    }

    /// After the hand-over (or from the first frame, when phase 1 is skipped), the batch goes
    /// on as phase 2's fixed-lag smoother: the caller adds frames with the filter's
    /// associations ([`Self::add_landmark`], [`Self::add_mapped_frame`]); every
    /// [`SmootherSettings::solve_every`] frames it is solved again over the last
    /// [`SmootherSettings::window`] frames, older frames marginalised into a prior, and the
    /// filter is re-seeded with [`Self::joint`]. Every estimated parameter of the rig is
    /// solved for again (the ones phase 1 could not inform start from their prior).
    pub fn start_mapping(&mut self) {
        if self.mapping {
            return;
        }
        self.mapping = true;
        self.estimated = self.rig.estimate.clone();
        self.last_covariance = None;
        self.since_solve = 0;
    }

    /// Starts the fixed-lag smoother afresh from a joint estimate (the filter's, when the
    /// smoother could not continue from phase 1's frames: phase 1 skipped, or parameters held
    /// for a while): its frames and landmarks are replaced by one frame at the estimate's
    /// pose with the estimate as the prior (information = the inverse of its covariance),
    /// and the estimate's parameters are the ones solved for. Landmark `j` is the estimate's
    /// `j`th. Returns `false` (and does not start) when the covariance cannot be inverted.
    pub fn restart_mapping(&mut self, joint: &JointEstimate) -> bool {
        // A state known exactly (the start pose) gets a tiny variance: it is pinned.
        let mut cov = joint.covariance.clone();
        for i in 0..cov.nrows() {
            cov[(i, i)] += 1e-14;
        }
        let Some(info) = cov.cholesky().map(|c| c.inverse()) else {
            return false;
        };
        if !info.iter().all(|v| v.is_finite()) {
            return false;
        }
        self.stop_mapping();
        self.dropped += 1;
        self.estimated = joint.estimated.clone();
        self.camera = joint.camera;
        self.landmarks = joint
            .landmarks
            .iter()
            .map(|&position| BatchLandmark {
                position,
                track: 0,
                first_frame: self.dropped.saturating_sub(1),
                observations: 0,
            })
            .collect();
        let q = info.nrows();
        self.prior = Some(Prior {
            info: 0.5 * (&info + info.transpose()),
            eta: DVector::zeros(q),
            pose: joint.pose,
            camera: self
                .estimated
                .iter()
                .map(|p| joint.camera.get(*p))
                .collect(),
            landmarks: joint.landmarks.clone(),
        });
        self.frames = alloc::vec![Frame {
            t_us: joint.t_us,
            pose: joint.pose,
            odometry: None,
            observations: Vec::new(),
            whitening: Vec::new(),
            tentative: Vec::new(),
        }];
        self.mapping = true;
        self.last_covariance = None;
        self.since_solve = 0;
        true
    }

    /// Whether the batch goes on as phase 2's smoother.
    pub fn is_mapping(&self) -> bool {
        self.mapping
    }

    /// Stops the smoother: the kept frames' poses become final ([`Self::take_smoothed`]),
    /// the buffers are freed.
    pub fn stop_mapping(&mut self) {
        self.mapping = false;
        let frames = core::mem::take(&mut self.frames);
        self.smoothed
            .extend(frames.iter().map(|f| (f.t_us, f.pose)));
        self.prior = None;
        self.last_covariance = None;
    }

    /// A landmark the filter created: its position now; it is observed from the next frame
    /// added. Returns its index in the batch.
    pub fn add_landmark(&mut self, position: Vector3<f64>, track: u64) -> usize {
        self.landmarks.push(BatchLandmark {
            position,
            track,
            first_frame: self.dropped + self.frames.len(),
            observations: 0,
        });
        self.landmarks.len() - 1
    }

    /// A frame of phase 2: the odometry since the previous frame (as [`Self::add_frame`]),
    /// the filter's pose for it (the starting guess) and the observations the filter used, by
    /// batch landmark index. Returns `true` when a solve ran ([`Self::joint`] is then this
    /// frame's joint estimate). Does nothing unless mapping.
    pub fn add_mapped_frame(
        &mut self,
        t_us: u64,
        odometry: Option<OdometryFactor>,
        pose: Pose2,
        observations: &[(usize, Measurement)],
    ) -> bool {
        if !self.mapping {
            return false;
        }
        let odometry = odometry_information(odometry);
        let mut used: Vec<(usize, Measurement)> = Vec::with_capacity(observations.len());
        for (j, z) in observations {
            if *j < self.landmarks.len()
                && z.iter().all(|v| v.is_finite())
                && !used.iter().any(|(u, _)| u == j)
            {
                used.push((*j, *z));
            }
        }
        for (j, _) in &used {
            if let Some(l) = self.landmarks.get_mut(*j) {
                l.observations += 1;
            }
        }
        let pose = if pose.x.is_finite() && pose.y.is_finite() && pose.theta.is_finite() {
            pose
        } else {
            match (self.frames.last(), &odometry) {
                (Some(prev), Some((o, _))) => o.motion_for(&self.camera.vehicle).apply(&prev.pose),
                (Some(prev), None) => prev.pose,
                (None, _) => Pose2::default(),
            }
        };
        self.frames.push(Frame {
            t_us,
            pose,
            odometry,
            whitening: used
                .iter()
                .map(|(_, z)| lens_whitening(&self.rig, z))
                .collect(),
            observations: used,
            tentative: Vec::new(),
        });
        self.since_solve += 1;
        if self.since_solve < self.settings.solve_every || self.frames.len() < 2 {
            return false;
        }
        self.since_solve = 0;
        if self.solve().is_none() {
            return false;
        }
        self.check_odometry(t_us);
        let excess = self.frames.len().saturating_sub(self.settings.window);
        if excess > 0 {
            self.marginalise(excess);
        }
        true
    }

    /// Solves now when frames came since the last solve (the end of a log, in mapping).
    /// Returns whether it solved.
    pub fn flush(&mut self) -> bool {
        if !self.mapping || self.since_solve == 0 || self.frames.len() < 2 {
            return false;
        }
        self.since_solve = 0;
        self.solve().is_some()
    }

    /// The last solve's joint estimate at its last frame.
    pub fn joint(&self) -> Option<JointEstimate> {
        let covariance = self.last_covariance.clone()?;
        let m = self.estimated.len();
        let nl = covariance.nrows().checked_sub(3 + m)? / 3;
        let last = self.frames.last()?;
        Some(JointEstimate {
            t_us: last.t_us,
            pose: last.pose,
            camera: self.camera,
            estimated: self.estimated.clone(),
            landmarks: self.landmarks.iter().take(nl).map(|l| l.position).collect(),
            covariance,
        })
    }

    /// The final poses of the frames marginalised since the last call, oldest first.
    pub fn take_smoothed(&mut self) -> Vec<(u64, Pose2)> {
        core::mem::take(&mut self.smoothed)
    }

    /// The timestamp of the oldest frame kept (whose pose a later solve may still change).
    pub fn window_start_t_us(&self) -> Option<u64> {
        self.frames.first().map(|f| f.t_us)
    }

    /// The kept frames' `(t_us, pose)` (the last solve's, the filter's since).
    pub fn window_poses(&self) -> Vec<(u64, Pose2)> {
        self.frames.iter().map(|f| (f.t_us, f.pose)).collect()
    }

    /// Marginalises the oldest `count` frames (at the current estimate, just solved): the
    /// poses are eliminated in time order from the factors that involve them (their pixels,
    /// the odometry up to the first kept frame, the prior), and what remains over the first
    /// kept pose, C and the landmarks known by then is the new prior.
    fn marginalise(&mut self, count: usize) {
        if count == 0 || count >= self.frames.len() {
            return;
        }
        let poses: Vec<Pose2> = self.frames.iter().map(|f| f.pose).collect();
        let landmarks: Vec<Vector3<f64>> = self.landmarks.iter().map(|l| l.position).collect();
        let sys = self.normal_equations_upto(&self.camera, &poses, &landmarks, count + 1, false);
        let Some((big, rhs, _)) = sys.eliminate(0.0) else {
            return;
        };
        let m = self.estimated.len();
        let l0 = self
            .seen_prefix()
            .partition_point(|&f| f < self.dropped + count);
        let q = 3 + m + 3 * l0;
        if big.nrows() < q {
            return;
        }
        let info = big.view((0, 0), (q, q)).into_owned();
        let info = 0.5 * (&info + info.transpose());
        let Some(&pose) = poses.get(count) else {
            return;
        };
        self.prior = Some(Prior {
            info,
            eta: rhs.rows(0, q).into_owned(),
            pose,
            camera: self.estimated.iter().map(|p| self.camera.get(*p)).collect(),
            landmarks: landmarks.iter().take(l0).copied().collect(),
        });
        for f in self.frames.drain(..count) {
            self.smoothed.push((f.t_us, f.pose));
        }
        if let Some(f) = self.frames.first_mut() {
            f.odometry = None;
        }
        self.dropped += count;
    }

    /// Index of frame `i`'s pose among the unknowns: the first frame is the world origin
    /// until a prior replaces it.
    fn first_variable(&self) -> usize {
        usize::from(self.prior.is_none())
    }

    /// Robust cost at the current state.
    fn cost(&self, camera: &CameraParams, poses: &[Pose2], landmarks: &[Vector3<f64>]) -> f64 {
        let sigma = self.rig.noise.pixel;
        let mut cost = 0.0;
        for (i, f) in self.frames.iter().enumerate() {
            let Some(pose) = poses.get(i) else { continue };
            if i > 0
                && let Some(prev) = poses.get(i - 1)
            {
                cost += f.odometry_cost(prev, pose, camera);
            }
            for (k, (j, z)) in f.observations.iter().enumerate() {
                let Some(l) = landmarks.get(*j) else { continue };
                let e = match project(camera, pose, l) {
                    Ok(p) => match f.whitening.get(k).copied().flatten() {
                        Some(a) => (a * (z - p)).norm(),
                        None => (z - p).norm() / sigma,
                    },
                    Err(_) => self.settings.huber * 10.0,
                };
                cost += huber_cost(e, self.settings.huber);
            }
        }
        match &self.prior {
            // The rig's prior on C is inside the marginalised frames' prior.
            Some(prior) => {
                if let Some(pose) = poses.first() {
                    let dx = prior.delta(pose, camera, &self.estimated, landmarks);
                    cost += dx.dot(&(&prior.info * &dx)) - 2.0 * prior.eta.dot(&dx);
                }
            }
            None => {
                for &p in &self.estimated {
                    let s = self.prior_sigma(p);
                    if s.is_finite() {
                        let d = (camera.get(p) - self.rig.nominal.get(p)) / s;
                        cost += d * d;
                    }
                }
            }
        }
        cost
    }

    /// Levenberg-Marquardt on the whole batch, warm-started; `None` when nothing can be solved.
    fn solve(&mut self) -> Option<SolveSummary> {
        let n = self.frames.len();
        if n < 2 {
            return None;
        }
        let mut poses: Vec<Pose2> = self.frames.iter().map(|f| f.pose).collect();
        let mut landmarks: Vec<Vector3<f64>> = self.landmarks.iter().map(|l| l.position).collect();
        let mut camera = self.camera;
        let mut cost = self.cost(&camera, &poses, &landmarks);
        let mut iterations = 0;
        for _ in 0..self.settings.max_iterations {
            iterations += 1;
            let system = self.normal_equations(&camera, &poses, &landmarks);
            let mut accepted = false;
            let mut converged = false;
            for _ in 0..12 {
                let Some(step) = system.lm_step(self.lambda) else {
                    self.lambda *= 10.0;
                    continue;
                };
                let (c2, p2, l2) = self.apply(&camera, &poses, &landmarks, &step);
                if !self.plausible(&c2) {
                    self.lambda *= 10.0;
                    continue;
                }
                let cost2 = self.cost(&c2, &p2, &l2);
                if cost2.is_finite() && cost2 <= cost {
                    let decrease = cost - cost2;
                    camera = c2;
                    poses = p2;
                    landmarks = l2;
                    cost = cost2;
                    self.lambda = (self.lambda / 10.0).max(1e-9);
                    accepted = true;
                    converged = decrease <= 1e-6 * (1.0 + cost);
                    break;
                }
                self.lambda *= 10.0;
            }
            if !accepted || converged {
                break;
            }
        }
        // Commit and take the covariance at the solution (undamped).
        self.camera = camera;
        for (f, p) in self.frames.iter_mut().zip(&poses) {
            f.pose = *p;
        }
        for (l, p) in self.landmarks.iter_mut().zip(&landmarks) {
            l.position = *p;
        }
        let system = self.normal_equations(&camera, &poses, &landmarks);
        self.last_covariance = system.marginal_covariance();
        Some(SolveSummary {
            iterations,
            cost,
            observations: system.observations,
            outliers: system.outliers,
        })
    }

    fn apply(
        &self,
        camera: &CameraParams,
        poses: &[Pose2],
        landmarks: &[Vector3<f64>],
        step: &Step,
    ) -> (CameraParams, Vec<Pose2>, Vec<Vector3<f64>>) {
        let mut c = *camera;
        for (a, &p) in self.estimated.iter().enumerate() {
            c.set(p, c.get(p) + step.camera.get(a).copied().unwrap_or(0.0));
        }
        let mut p2 = poses.to_vec();
        let first = self.first_variable();
        for (k, d) in step.poses.iter().enumerate() {
            if let Some(p) = p2.get_mut(k + first) {
                p.x += d.x;
                p.y += d.y;
                p.theta += d.z;
            }
        }
        let mut l2 = landmarks.to_vec();
        for (l, d) in l2.iter_mut().zip(&step.landmarks) {
            *l += d;
        }
        (c, p2, l2)
    }

    /// The normal equations at the current state, in the chain-and-arrow layout.
    fn normal_equations(
        &self,
        camera: &CameraParams,
        poses: &[Pose2],
        landmarks: &[Vector3<f64>],
    ) -> System {
        self.normal_equations_upto(camera, poses, landmarks, self.frames.len(), true)
    }

    /// The normal equations of the factors of frames `0..upto` (the pixels of the last one
    /// only with `last_pixels`), the odometry between them and the prior.
    fn normal_equations_upto(
        &self,
        camera: &CameraParams,
        poses: &[Pose2],
        landmarks: &[Vector3<f64>],
        upto: usize,
        last_pixels: bool,
    ) -> System {
        let n = upto.min(self.frames.len());
        let m = self.estimated.len();
        let w = m + 3 * landmarks.len();
        let first = self.first_variable();
        let pv = n.saturating_sub(first); // pose variables: frames first..n-1
        let mut sys = System {
            d: vec3x3(pv),
            e: vec3x3(pv),
            f: (0..pv).map(|_| DMatrix::zeros(3, w)).collect(),
            b: alloc::vec![Vector3::zeros(); pv],
            active: alloc::vec![m; pv],
            z: DMatrix::zeros(w, w),
            bz: DVector::zeros(w),
            m,
            observations: 0,
            outliers: 0,
        };
        // Landmarks are in first-seen order, so the arrow columns a pose touches (with the
        // fill from the poses before it) are a prefix.
        let suffix_min = self.seen_prefix();
        for (k, a) in sys.active.iter_mut().enumerate() {
            let frame = self.dropped + k + first;
            let seen = suffix_min.partition_point(|&f| f <= frame);
            *a = m + 3 * seen;
        }
        let inv_var = 1.0 / (self.rig.noise.pixel * self.rig.noise.pixel);
        for (i, f) in self.frames.iter().enumerate().take(n) {
            let Some(pose) = poses.get(i) else { continue };
            // Odometry factor between frames i-1 and i.
            if i > 0
                && let Some(prev) = poses.get(i - 1)
            {
                let (r, ja, jb, info, jv) = f.odometry_factor(prev, pose, camera);
                let kb = i - first; // variable index of pose i
                sys.d[kb] += jb.transpose() * info * jb;
                sys.b[kb] -= jb.transpose() * info * r;
                if i > first {
                    let ka = kb - 1;
                    sys.d[ka] += ja.transpose() * info * ja;
                    sys.e[ka] += ja.transpose() * info * jb;
                    sys.b[ka] -= ja.transpose() * info * r;
                }
                // The estimated vehicle parameters move the motion (vehicle-interfaces.md
                // 1.2): they join the arrow's C block through this factor.
                for (a, pa) in self.estimated.iter().enumerate() {
                    if !pa.is_vehicle() {
                        continue;
                    }
                    let ca: Vector3<f64> = jv.column(pa.index() - N_CAMERA).into_owned();
                    if ca.iter().all(|v| *v == 0.0) {
                        continue;
                    }
                    let wa = info * ca;
                    sys.bz[a] -= wa.dot(&r);
                    for (b, pb) in self.estimated.iter().enumerate() {
                        if pb.is_vehicle() {
                            let cb = jv.column(pb.index() - N_CAMERA);
                            sys.z[(a, b)] += wa.dot(&cb);
                        }
                    }
                    let fb = jb.transpose() * wa;
                    for row in 0..3 {
                        sys.f[kb][(row, a)] += fb[row];
                    }
                    if i > first {
                        let fa = ja.transpose() * wa;
                        for row in 0..3 {
                            sys.f[kb - 1][(row, a)] += fa[row];
                        }
                    }
                }
            }
            if i + 1 == n && !last_pixels {
                continue;
            }
            for (k, (j, zm)) in f.observations.iter().enumerate() {
                let Some(l) = landmarks.get(*j) else { continue };
                let Ok((zh, jac)) = project_with_jacobians(camera, pose, l) else {
                    continue;
                };
                // Through real lenses the residual and its Jacobians are whitened per
                // observation (lens_whitening); else the rig's one pixel sigma.
                let (r, jl, jp, jc, unit) = match f.whitening.get(k).copied().flatten() {
                    Some(a) => (
                        a * (zm - zh),
                        a * jac.landmark,
                        a * jac.pose,
                        a * jac.camera,
                        1.0,
                    ),
                    None => (zm - zh, jac.landmark, jac.pose, jac.camera, inv_var),
                };
                let e = r.norm() * libm::sqrt(unit);
                let wgt = if e > self.settings.huber {
                    sys.outliers += 1;
                    self.settings.huber / e
                } else {
                    1.0
                };
                sys.observations += 1;
                let wi = wgt * unit;
                let jc: SMatrix<f64, 4, N_PARAMS> = jc;
                let col = m + 3 * j;
                // Landmark and camera blocks of the arrow.
                let ll = jl.transpose() * jl * wi;
                let bl = jl.transpose() * r * wi;
                for a in 0..3 {
                    sys.bz[col + a] += bl[a];
                    for b in 0..3 {
                        sys.z[(col + a, col + b)] += ll[(a, b)];
                    }
                }
                for (a, pa) in self.estimated.iter().enumerate() {
                    let ca = jc.column(pa.index());
                    sys.bz[a] += ca.dot(&r) * wi;
                    for (b, pb) in self.estimated.iter().enumerate() {
                        sys.z[(a, b)] += ca.dot(&jc.column(pb.index())) * wi;
                    }
                    let cl = ca.transpose() * jl * wi;
                    for b in 0..3 {
                        sys.z[(a, col + b)] += cl[b];
                        sys.z[(col + b, a)] += cl[b];
                    }
                }
                if i >= first {
                    let k = i - first;
                    sys.d[k] += jp.transpose() * jp * wi;
                    sys.b[k] += jp.transpose() * r * wi;
                    let pl = jp.transpose() * jl * wi;
                    let fk = &mut sys.f[k];
                    for a in 0..3 {
                        for b in 0..3 {
                            fk[(a, col + b)] += pl[(a, b)];
                        }
                        for (c, pc) in self.estimated.iter().enumerate() {
                            fk[(a, c)] += jp.column(a).dot(&jc.column(pc.index())) * wi;
                        }
                    }
                }
            }
        }
        match &self.prior {
            // The marginalised frames' prior (it holds the rig's prior on C).
            Some(prior) => {
                if let (Some(pose), Some(d0), Some(b0), Some(f0)) = (
                    poses.first(),
                    sys.d.first_mut(),
                    sys.b.first_mut(),
                    sys.f.first_mut(),
                ) {
                    let dx = prior.delta(pose, camera, &self.estimated, landmarks);
                    let g = &prior.eta - &prior.info * &dx;
                    let q = prior.info.nrows() - 3;
                    for a in 0..3 {
                        b0[a] += g[a];
                        for b in 0..3 {
                            d0[(a, b)] += prior.info[(a, b)];
                        }
                        for c in 0..q {
                            f0[(a, c)] += prior.info[(a, 3 + c)];
                        }
                    }
                    for r in 0..q {
                        sys.bz[r] += g[3 + r];
                        for c in 0..q {
                            sys.z[(r, c)] += prior.info[(3 + r, 3 + c)];
                        }
                    }
                }
            }
            // The prior on C.
            None => {
                for (a, &p) in self.estimated.iter().enumerate() {
                    let s = self.prior_sigma(p);
                    if s.is_finite() && s > 0.0 {
                        sys.z[(a, a)] += 1.0 / (s * s);
                        sys.bz[a] -= (camera.get(p) - self.rig.nominal.get(p)) / (s * s);
                    }
                }
            }
        }
        sys
    }
}
