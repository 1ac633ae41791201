//! Seeded Monte Carlo evaluation of phase 2 (the EKF of `vslam-ekf`) against the simulator's
//! truth.
//!
//! Each run simulates a scenario (fast mode) with its own seed, feeds the filter the logged
//! odometry and, frame by frame, the stereo measurements of the lamps keyed by the simulator's
//! lamp ids: association is perfect here on purpose, so that what is measured is the filter
//! (the navigator's association is judged on its own, in `track`). Gross outliers can be mixed
//! in at a chosen rate to exercise the gate. Along the way every frame records the pose NEES
//! and the full-state NEES (pose, the landmarks in the map, the estimated camera parameters)
//! with their degrees of freedom, and whether the state stayed finite and `P` positive
//! definite; at the end the landmark and camera errors with their sigmas.
//!
//! [`monte_carlo`] runs many seeds and summarises them the usual way for filter consistency
//! (Bar-Shalom, Li and Kirubarajan, *Estimation with Applications to Tracking and Navigation*,
//! section 5.4): with `N` runs, `N` times the NEES averaged over the runs at one frame is
//! chi-square with `N` times the dof, which gives the 95 % band of the average; the same for
//! the NIS of the accepted observations.
//!
//! [`phase1`]: phase 1's frame pairs built with the simulator's lamp labels instead of the
//! navigator's association, for judging the calibration apart from association.

pub mod phase1;

use std::collections::BTreeMap;

use nalgebra::{DMatrix, DVector, Vector3};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rig_model::camera::{CameraParams, Param};
use vslam_ekf::chi2::chi2_quantile;
use vslam_ekf::{CameraStart, CandidateSettings, Candidates, Ekf, Settings};

/// What can stop an evaluation.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// The simulator refused the scenario.
    #[error("simulation: {0}")]
    Sim(#[from] sim::Error),
    /// The filter refused its settings or the rig.
    #[error("filter: {0}")]
    Filter(#[from] vslam_ekf::Error),
    /// Settings out of range.
    #[error("{0}")]
    Settings(String),
}

/// Where the camera parameters start.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Start {
    /// Phase 1 skipped: the rig's nominal values with its `[prior]` sigmas.
    Prior,
}

/// How one run is set up.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RunSettings {
    /// The filter's tuning.
    pub ekf: Settings,
    /// Landmark confirmation.
    pub candidates: CandidateSettings,
    /// Where the camera parameters start.
    pub start: Start,
    /// Fraction of lamp measurements replaced by gross outliers.
    pub outlier_fraction: f64,
    /// Smallest and largest displacement of an outlier's four coordinates, pixels.
    pub outlier_px: (f64, f64),
    /// Frames to run (all when `None`).
    pub max_frames: Option<usize>,
}

impl Default for RunSettings {
    fn default() -> Self {
        Self {
            ekf: Settings::default(),
            candidates: CandidateSettings::default(),
            start: Start::Prior,
            outlier_fraction: 0.0,
            outlier_px: (5.0, 40.0),
            max_frames: None,
        }
    }
}

/// One landmark at the end of a run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LandmarkResult {
    /// The lamp it stands for.
    pub lamp: u32,
    /// Estimate minus truth, world frame, metres.
    pub error: Vector3<f64>,
    /// Its 1-sigma per axis, metres.
    pub sigma: Vector3<f64>,
    /// Squared Mahalanobis distance of the error (3 dof).
    pub nees: f64,
}

/// One estimated camera parameter at the end of a run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraResult {
    /// The parameter.
    pub param: Param,
    /// Estimate.
    pub value: f64,
    /// Truth.
    pub truth: f64,
    /// Its 1-sigma.
    pub sigma: f64,
}

impl CameraResult {
    /// Estimate minus truth.
    pub fn error(&self) -> f64 {
        self.value - self.truth
    }
}

/// One run.
#[derive(Debug, Clone, PartialEq)]
pub struct RunResult {
    /// The seed.
    pub seed: u64,
    /// Frames processed.
    pub frames: usize,
    /// Pose NEES (3 dof) at each frame after the first.
    pub pose_nees: Vec<f64>,
    /// Full-state NEES at each frame after the first, with its dof.
    pub state_nees: Vec<(f64, usize)>,
    /// NIS of every accepted observation.
    pub nis: Vec<f64>,
    /// The landmarks at the end, one per lamp in the map.
    pub landmarks: Vec<LandmarkResult>,
    /// The estimated camera parameters at the end.
    pub camera: Vec<CameraResult>,
    /// Lamps that were seen but never made it into the map.
    pub lamps_missing: Vec<u32>,
    /// Observations rejected by the gate, outliers included.
    pub rejected: u64,
    /// Outliers mixed in.
    pub outliers: u64,
    /// Outliers the gate let through.
    pub outliers_accepted: u64,
    /// Updates the filter refused (the state left as it was).
    pub refused_updates: u64,
    /// The state stayed finite and `P` positive definite at every frame.
    pub healthy: bool,
    /// Final pose error `(dx, dy, dtheta)`.
    pub pose_error: Vector3<f64>,
}

impl RunResult {
    /// Root mean square of the landmarks' 3-D position errors, metres.
    pub fn landmark_rms(&self) -> f64 {
        if self.landmarks.is_empty() {
            return f64::NAN;
        }
        #[allow(clippy::cast_precision_loss)]
        let n = self.landmarks.len() as f64;
        (self
            .landmarks
            .iter()
            .map(|l| l.error.norm_squared())
            .sum::<f64>()
            / n)
            .sqrt()
    }

    /// The result of one camera parameter, if estimated.
    pub fn camera_result(&self, p: Param) -> Option<&CameraResult> {
        self.camera.iter().find(|c| c.param == p)
    }

    /// Every landmark inside its 3-sigma ellipsoid (NEES below the 3-dof chi-square quantile of
    /// the 3-sigma probability, 0.9973) and every camera parameter within 3 sigma.
    pub fn within_3_sigma(&self) -> bool {
        let bound = chi2_quantile(THREE_SIGMA, 3.0);
        self.landmarks.iter().all(|l| l.nees <= bound)
            && self.camera.iter().all(|c| c.error().abs() <= 3.0 * c.sigma)
    }
}

/// Probability inside 3 sigma of a Gaussian.
pub const THREE_SIGMA: f64 = 0.997_300_203_936_74;

/// The wrapped difference of two angles, in `(-pi, pi]`.
fn angle_diff(a: f64, b: f64) -> f64 {
    sim::wrap_angle(a - b)
}

/// Runs the filter on one seeded simulation of `scenario`.
pub fn run(
    scenario: &sim::Scenario,
    seed: u64,
    settings: &RunSettings,
) -> Result<RunResult, Error> {
    let (lo, hi) = settings.outlier_px;
    let range_ok = lo > 0.0 && hi >= lo;
    if !(0.0..=1.0).contains(&settings.outlier_fraction) || !range_ok {
        return Err(Error::Settings(format!(
            "outlier fraction {} must be in [0, 1] and the displacement range {lo}..{hi} px positive",
            settings.outlier_fraction
        )));
    }
    let scenario = scenario.clone().with_seed(seed);
    let sim_run = sim::simulate(&scenario, sim::Mode::Fast)?;
    let rig = &sim_run.rig;
    let start = match settings.start {
        Start::Prior => CameraStart::from_prior(rig),
    };
    let mut ekf = Ekf::new(rig, &start, settings.ekf)?;
    let mut candidates = Candidates::new(settings.candidates)?;
    let odometry = sim_run.odometry.clone();
    let truth: BTreeMap<u32, Vector3<f64>> = sim_run
        .landmarks
        .iter()
        .map(|l| (l.id, l.position))
        .collect();
    // Outliers from their own stream, so that the same seed with and without them sees the
    // same simulation.
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x6f75_746c_6965_7273);
    let frames = settings
        .max_frames
        .map_or(sim_run.frames.len(), |m| m.min(sim_run.frames.len()));
    let mut result = RunResult {
        seed,
        frames,
        pose_nees: Vec::with_capacity(frames),
        state_nees: Vec::with_capacity(frames),
        nis: Vec::new(),
        landmarks: Vec::new(),
        camera: Vec::new(),
        lamps_missing: Vec::new(),
        rejected: 0,
        outliers: 0,
        outliers_accepted: 0,
        refused_updates: 0,
        healthy: true,
        pose_error: Vector3::zeros(),
    };
    let mut seen_lamps = std::collections::BTreeSet::new();
    let mut previous_t = None;
    for frame in sim_run.frames.iter().take(frames) {
        if let Some(t0) = previous_t {
            ekf.predict_odometry(&odometry, t0, frame.t_us)?;
        }
        previous_t = Some(frame.t_us);
        let mut observations: Vec<(u64, rig_model::Measurement)> = frame
            .lamp_measurements()
            .into_iter()
            .map(|(lamp, z)| (u64::from(lamp), z))
            .collect();
        observations.sort_by_key(|(lamp, _)| *lamp);
        let mut outlier_ids = Vec::new();
        for (lamp, z) in &mut observations {
            seen_lamps.insert(*lamp);
            if settings.outlier_fraction > 0.0 && rng.random::<f64>() < settings.outlier_fraction {
                for v in z.iter_mut() {
                    let magnitude = rng.random_range(lo..=hi);
                    *v += if rng.random::<bool>() {
                        magnitude
                    } else {
                        -magnitude
                    };
                }
                outlier_ids.push(*lamp);
                result.outliers += 1;
            }
        }
        match candidates.observe(&mut ekf, &observations) {
            Ok(report) => {
                result.rejected += report.update.rejected.len() as u64;
                for g in &report.update.accepted {
                    result.nis.push(g.nis);
                    if candidates
                        .track_of(g.id)
                        .is_some_and(|t| outlier_ids.contains(&t))
                    {
                        result.outliers_accepted += 1;
                    }
                }
            }
            Err(_) => result.refused_updates += 1,
        }
        let (pose_nees, state_nees, healthy) =
            nees(&ekf, &candidates, frame, &sim_run.camera, &truth);
        // The first frame's pose is the world origin, exactly: its covariance is zero there.
        if frame.index > 0 {
            result.healthy &= healthy;
            result.pose_nees.push(pose_nees);
            result.state_nees.push(state_nees);
        }
    }
    result.refused_updates = result.refused_updates.max(ekf.health().refused_updates);
    if let Some(last) = sim_run.frames.get(frames.saturating_sub(1)) {
        let pose = ekf.pose();
        result.pose_error = Vector3::new(
            pose.x - last.pose.x,
            pose.y - last.pose.y,
            angle_diff(pose.theta, last.pose.theta),
        );
    }
    for lamp in &seen_lamps {
        let Some(id) = candidates.landmark_of(*lamp) else {
            #[allow(clippy::cast_possible_truncation)]
            result.lamps_missing.push(*lamp as u32);
            continue;
        };
        #[allow(clippy::cast_possible_truncation)]
        let lamp = *lamp as u32;
        if let (Some(estimate), Some(t)) = (ekf.landmark(id), truth.get(&lamp)) {
            let error = estimate.position - t;
            let nees = estimate
                .covariance
                .cholesky()
                .map_or(f64::INFINITY, |c| error.dot(&c.solve(&error)));
            result.landmarks.push(LandmarkResult {
                lamp,
                error,
                sigma: estimate.covariance.diagonal().map(f64::sqrt),
                nees,
            });
        }
    }
    let camera = ekf.camera();
    let cov = ekf.camera_covariance();
    for &p in ekf.estimated_parameters() {
        result.camera.push(CameraResult {
            param: p,
            value: camera.get(p),
            truth: sim_run.camera.get(p),
            sigma: cov[(p.index(), p.index())].max(0.0).sqrt(),
        });
    }
    Ok(result)
}

/// Pose NEES, full-state NEES with its dof, and whether the state is finite and `P` positive
/// definite, at one frame.
fn nees(
    ekf: &Ekf,
    candidates: &Candidates,
    frame: &sim::FrameTruth,
    true_camera: &CameraParams,
    truth: &BTreeMap<u32, Vector3<f64>>,
) -> (f64, (f64, usize), bool) {
    let x = ekf.state();
    let p = ekf.covariance();
    let finite = x.iter().all(|v| v.is_finite()) && p.iter().all(|v| v.is_finite());
    let positive = finite && p.clone().cholesky().is_some();
    if !positive {
        return (f64::NAN, (f64::NAN, 0), false);
    }
    // Error of every state element whose truth is known: the pose, the landmarks that stand
    // for a lamp, the estimated camera parameters.
    let pose = ekf.pose();
    let mut index = vec![0, 1, 2];
    let mut error = vec![
        pose.x - frame.pose.x,
        pose.y - frame.pose.y,
        angle_diff(pose.theta, frame.pose.theta),
    ];
    let pose_nees = quadratic(&p, &index, &error);
    for estimate in ekf.landmarks() {
        let (Some(track), Some(i)) = (
            candidates.track_of(estimate.id),
            ekf.landmark_state_index(estimate.id),
        ) else {
            continue;
        };
        let Some(t) = u32::try_from(track).ok().and_then(|lamp| truth.get(&lamp)) else {
            continue;
        };
        for k in 0..3 {
            index.push(i + k);
            error.push(estimate.position[k] - t[k]);
        }
    }
    let camera = ekf.camera();
    for &param in ekf.estimated_parameters() {
        if let Some(i) = ekf.camera_state_index(param) {
            index.push(i);
            error.push(camera.get(param) - true_camera.get(param));
        }
    }
    let dof = index.len();
    (pose_nees, (quadratic(&p, &index, &error), dof), true)
}

/// `e^T P[idx, idx]^-1 e`; infinite when the block is singular.
fn quadratic(p: &DMatrix<f64>, idx: &[usize], e: &[f64]) -> f64 {
    let block = DMatrix::from_fn(idx.len(), idx.len(), |a, b| p[(idx[a], idx[b])]);
    let e = DVector::from_column_slice(e);
    block
        .cholesky()
        .map_or(f64::INFINITY, |c| e.dot(&c.solve(&e)))
}

/// A value with its two-sided 95 % chi-square band.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Banded {
    /// The value.
    pub value: f64,
    /// Lower end of the band.
    pub low: f64,
    /// Upper end of the band.
    pub high: f64,
}

impl Banded {
    /// The average of `count` chi-square variables with `dof` degrees of freedom each.
    fn average(value: f64, dof: f64, count: f64) -> Self {
        let total = dof * count;
        Self {
            value,
            low: chi2_quantile(0.025, total) / count,
            high: chi2_quantile(0.975, total) / count,
        }
    }

    /// The value lies inside its band.
    pub fn inside(&self) -> bool {
        self.value >= self.low && self.value <= self.high
    }
}

/// Many runs summarised.
#[derive(Debug, Clone, PartialEq)]
pub struct Summary {
    /// The runs, in seed order.
    pub runs: Vec<RunResult>,
    /// Pose NEES averaged over the runs and the frames, with the 95 % band of one frame's
    /// average over the runs (frames are correlated in time).
    pub pose_nees: Banded,
    /// Fraction of frames whose run-averaged pose NEES lies inside its 95 % band.
    pub pose_nees_frames_inside: f64,
    /// Full-state NEES per dof, averaged over runs and frames, with the 95 % band of one
    /// frame's average over the runs.
    pub state_nees_per_dof: Banded,
    /// Fraction of frames whose run-averaged full-state NEES lies inside its 95 % band.
    pub state_nees_frames_inside: f64,
    /// Mean NIS of the accepted observations (4 dof: near 4), with its 95 % band.
    pub nis: Banded,
    /// Runs with every landmark and camera parameter inside 3 sigma.
    pub within_3_sigma: usize,
    /// Runs whose state stayed finite and `P` positive definite throughout.
    pub healthy: usize,
}

/// Runs every seed of `seeds` and summarises them.
pub fn monte_carlo(
    scenario: &sim::Scenario,
    seeds: impl IntoIterator<Item = u64>,
    settings: &RunSettings,
) -> Result<Summary, Error> {
    let runs: Vec<RunResult> = seeds
        .into_iter()
        .map(|seed| run(scenario, seed, settings))
        .collect::<Result<_, _>>()?;
    Ok(summarise(runs))
}

/// The consistency statistics of finished runs.
pub fn summarise(runs: Vec<RunResult>) -> Summary {
    #[allow(clippy::cast_precision_loss)]
    let n = runs.len().max(1) as f64;
    let frames = runs.iter().map(|r| r.pose_nees.len()).min().unwrap_or(0);
    let (mut pose_inside, mut state_inside) = (0usize, 0usize);
    let (mut pose_sum, mut state_sum, mut state_dof) = (0.0, 0.0, 0.0);
    for k in 0..frames {
        let pose: f64 = runs.iter().map(|r| r.pose_nees[k]).sum::<f64>() / n;
        pose_sum += pose;
        pose_inside += usize::from(Banded::average(pose, 3.0, n).inside());
        let (value, dof) = runs.iter().fold((0.0, 0usize), |(v, d), r| {
            let (nees, dof) = r.state_nees[k];
            (v + nees, d + dof)
        });
        #[allow(clippy::cast_precision_loss)]
        let dof = dof as f64;
        if dof > 0.0 {
            // Sum of chi-squares: chi-square with the summed dof.
            let band_low = chi2_quantile(0.025, dof);
            let band_high = chi2_quantile(0.975, dof);
            state_inside += usize::from(value >= band_low && value <= band_high);
            state_sum += value;
            state_dof += dof;
        }
    }
    #[allow(clippy::cast_precision_loss)]
    let frames_f = frames.max(1) as f64;
    // The frames of a run are strongly correlated (a pose error lasts), so averaging over them
    // adds little information: the bands of the time averages are those of one frame's
    // average over the runs, which is conservative.
    let pose_nees = Banded::average(pose_sum / frames_f, 3.0, n);
    let state_nees_per_dof = if state_dof > 0.0 {
        Banded::average(state_sum / state_dof, 1.0, state_dof / frames_f)
    } else {
        Banded::average(f64::NAN, 1.0, 1.0)
    };
    let all_nis: Vec<f64> = runs.iter().flat_map(|r| r.nis.iter().copied()).collect();
    #[allow(clippy::cast_precision_loss)]
    let nis_count = all_nis.len().max(1) as f64;
    let nis = Banded::average(all_nis.iter().sum::<f64>() / nis_count, 4.0, nis_count);
    Summary {
        within_3_sigma: runs.iter().filter(|r| r.within_3_sigma()).count(),
        healthy: runs.iter().filter(|r| r.healthy).count(),
        pose_nees,
        pose_nees_frames_inside: pose_inside as f64 / frames_f,
        state_nees_per_dof,
        state_nees_frames_inside: state_inside as f64 / frames_f,
        nis,
        runs,
    }
}

/// The 3-D chi-square bound equivalent to three sigma (probability 0.9973), the bound
/// [`landmarks_against_lamps`] counts a landmark inside of.
pub const THREE_SIGMA_CHI2_3: f64 = 14.16;

/// A map's landmarks against the simulator's lamps: each landmark's nearest lamp within
/// `radius` metres, and its 3-D Mahalanobis distance under the landmark's covariance. Returns
/// `(landmarks with a lamp within radius, of them inside the three-sigma bound
/// `THREE_SIGMA_CHI2_3`)`. `landmarks` are `(position, covariance)`, world frame.
pub fn landmarks_against_lamps(
    landmarks: impl IntoIterator<Item = ([f64; 3], [[f64; 3]; 3])>,
    lamps: &[sim::Lamp],
    radius: f64,
) -> (usize, usize) {
    let (mut near, mut inside) = (0, 0);
    for (position, covariance) in landmarks {
        let p = Vector3::from(position);
        let Some(lamp) = lamps
            .iter()
            .min_by(|a, b| (a.position - p).norm().total_cmp(&(b.position - p).norm()))
        else {
            continue;
        };
        let e = p - lamp.position;
        if e.norm() > radius {
            continue;
        }
        let cov = nalgebra::Matrix3::from_fn(|i, j| covariance[i][j]);
        let d2 = cov
            .try_inverse()
            .map_or(f64::INFINITY, |ci| e.dot(&(ci * e)));
        near += 1;
        inside += usize::from(d2 <= THREE_SIGMA_CHI2_3);
    }
    (near, inside)
}
