//! The filter: state, covariance, prediction, update, landmark initialisation and removal.

use alloc::vec::Vec;

use nalgebra::{DMatrix, DVector, Matrix3, Matrix4, SMatrix, Vector3, Vector4};
use rig_model::camera::{Param, wrap_angle};
use rig_model::handover::Handover;
use rig_model::handover::{BatchHandover, JointEstimate};
use rig_model::odometry::OdomSample;
use rig_model::rig::Jac4x3;
use rig_model::{CameraParams, Measurement, N_PARAMS, Noise, Pose2, Rig, project_with_jacobians};

use crate::chi2::chi2_quantile;
use crate::error::Error;
use crate::health::{DOF, Health, HealthState};
use crate::kernels::{
    LANES, MAX_INVOLVED, Obs, Workspace, cholesky4, compact, diagonal_change, gain_factors,
    gain_factors4, gather_columns, innovation_products, mahalanobis4, observation_products,
    rank_update_lower_padded,
};
use crate::linalg::{mirror_lower, rank_update_lower, sym};
use crate::motion::{Increment, check_noise};

/// A landmark's id: stable for its life, never reused after it is removed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct LandmarkId(pub u64);

impl core::fmt::Display for LandmarkId {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "landmark {}", self.0)
    }
}

/// The 10x10 covariance of the camera parameters, [`Param::ALL`] order.
pub type CameraCovariance = SMatrix<f64, N_PARAMS, N_PARAMS>;

/// Size of the pose block `(X, Y, theta)`.
pub const POSE_DIM: usize = 3;
/// Size of a landmark block `(x, y, z)`.
pub const LANDMARK_DIM: usize = 3;

/// How the covariance update is written (see the crate docs for why).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum CovarianceUpdate {
    /// The Joseph form expanded into one symmetric rank-2k update,
    /// `P - K A^T - A K^T + K S K^T`: first-order insensitive to errors in the gain.
    Joseph,
    /// `P - W W^T` with `W = A L^-T`, `S = L L^T`: half the multiply-adds of the Joseph form.
    Factored,
    /// Joseph up to [`AUTO_JOSEPH_MAX_STATES`] states, factored above.
    Auto,
}

/// Largest state updated one landmark at a time (the whole covariance fits in the first-level
/// cache); larger states are updated as one batch.
pub const SEQUENTIAL_MAX_STATES: usize = crate::kernels::MAX_SMALL_STATE;

/// Largest state [`CovarianceUpdate::Auto`] updates in the Joseph form. Above it the
/// factored form keeps the 500-landmark update within its time budget (docs/benchmarks.md).
pub const AUTO_JOSEPH_MAX_STATES: usize = 400;

/// What the update does with the camera parameters.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum CameraUpdate {
    /// Refined by every update, with the landmarks and the pose (the method's phase 2).
    Refine,
    /// Considered, not estimated (Schmidt-Kalman): their covariance and cross-covariances are
    /// carried, so that the pose and landmark sigmas include the camera's uncertainty, but the
    /// gain's camera rows are zero: the values and their covariance stay those phase 1 handed
    /// over. For data on which refining them is over-confident (docs/phase2.md,
    /// "Linearisation"). The update is then always in the Joseph form, which holds for any gain.
    Consider,
}

/// The filter's tuning.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Settings {
    /// Probability mass inside each landmark's innovation gate (4 dof): 0.999 gives a NIS
    /// bound of 18.47.
    pub gate_probability: f64,
    /// Gate outcomes kept for the health's NIS statistics.
    pub nis_window: usize,
    /// A landmark rejected by the gate this many times in a row is removed as false.
    pub max_consecutive_rejections: u32,
    /// Form of the covariance update.
    pub covariance_update: CovarianceUpdate,
    /// Refine the camera parameters, or only consider them.
    pub camera_update: CameraUpdate,
}

impl Default for Settings {
    fn default() -> Self {
        Self {
            gate_probability: 0.999,
            nis_window: 100,
            max_consecutive_rejections: 5,
            covariance_update: CovarianceUpdate::Auto,
            camera_update: CameraUpdate::Refine,
        }
    }
}

impl Settings {
    fn check(&self) -> Result<(), Error> {
        let p = self.gate_probability;
        if !(p.is_finite() && p > 0.0 && p < 1.0) {
            return Err(Error::BadValue {
                name: "Settings.gate_probability",
                value: p,
                expected: "strictly between 0 and 1",
            });
        }
        if self.nis_window == 0 {
            return Err(Error::BadValue {
                name: "Settings.nis_window",
                value: 0.0,
                expected: "at least 1",
            });
        }
        if self.max_consecutive_rejections == 0 {
            return Err(Error::BadValue {
                name: "Settings.max_consecutive_rejections",
                value: 0.0,
                expected: "at least 1",
            });
        }
        Ok(())
    }
}

/// The camera parameters the filter starts from, with their covariance.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraStart {
    /// Every camera parameter's value; the ones not estimated stay at it.
    pub camera: CameraParams,
    /// Covariance, [`Param::ALL`] order. An estimated parameter whose variance is zero here
    /// enters the filter with the rig's prior variance instead (a parameter phase 1 held at
    /// nominal).
    pub covariance: CameraCovariance,
}

impl CameraStart {
    /// Phase 1 skipped: the rig's nominal values with the `[prior]` sigmas.
    pub fn from_prior(rig: &Rig) -> Self {
        let mut covariance = CameraCovariance::zeros();
        for &p in &rig.estimate {
            if let Some(s) = rig.prior[p.index()] {
                covariance[(p.index(), p.index())] = s * s;
            }
        }
        Self {
            camera: rig.nominal,
            covariance,
        }
    }

    /// Phase 1's result.
    pub fn from_handover(handover: &Handover) -> Self {
        Self {
            camera: handover.camera,
            covariance: handover.covariance,
        }
    }
}

/// What a caller sees of one landmark.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LandmarkEstimate {
    /// Its id.
    pub id: LandmarkId,
    /// Position in the world frame, metres.
    pub position: Vector3<f64>,
    /// Its covariance.
    pub covariance: Matrix3<f64>,
    /// Measurements used: the one that initialised it and every accepted one since.
    pub observations: u64,
}

/// One landmark observation's gate outcome.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Gated {
    /// The landmark.
    pub id: LandmarkId,
    /// Its normalised innovation squared (4 dof); infinite when the landmark could not be
    /// projected at the current estimate.
    pub nis: f64,
}

/// What one update did.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct UpdateReport {
    /// Observations used, with their NIS.
    pub accepted: Vec<Gated>,
    /// Observations left out by the gate, with their NIS.
    pub rejected: Vec<Gated>,
    /// Landmarks removed after this update for too many rejections in a row.
    pub removed: Vec<LandmarkId>,
}

/// Per-landmark bookkeeping, in state order.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Slot {
    id: LandmarkId,
    observations: u64,
    rejections_in_a_row: u32,
}

/// EKF SLAM with the camera parameters in the state (eq. 3-8).
///
/// State `x = [X, Y, theta, L_1, ..., L_N, C_est]`; see the crate docs for the layout, the
/// update form and the rest of the design.
#[derive(Debug, Clone)]
pub struct Ekf {
    x: DVector<f64>,
    p: DMatrix<f64>,
    landmarks: Vec<Slot>,
    estimated: Vec<Param>,
    /// Values of the parameters not estimated (the estimated ones are read from `x`).
    camera_base: CameraParams,
    noise: Noise,
    width: u32,
    height: u32,
    settings: Settings,
    gate: f64,
    next_id: u64,
    health: HealthState,
    /// Process noise accumulated on the pose since [`Ekf::take_motion_covariance`], in the
    /// current pose's frame: the relative pose uncertainty between two frames.
    motion_covariance: Matrix3<f64>,
    workspace: Workspace,
    /// Estimated camera parameters held this frame ([`Ekf::set_held`]), by [`Param::index`].
    held: [bool; N_PARAMS],
}

fn check_finite(what: &'static str, value: f64) -> Result<(), Error> {
    if value.is_finite() {
        Ok(())
    } else {
        Err(Error::NonFinite { what, value })
    }
}

/// Every variance stays positive after adding `change` to the diagonal of `p` (or stays zero:
/// the start pose before the first prediction).
fn check_variances(p: &[f64], n: usize, change: &[f64]) -> Result<(), Error> {
    for (i, c) in change.iter().enumerate() {
        let before = p.get(at(n, i, i)).copied().unwrap_or(f64::NAN);
        let after = before + c;
        if !(after > 0.0 || (after == 0.0 && before == 0.0)) {
            return Err(Error::VarianceNotPositive {
                index: i,
                before,
                after,
            });
        }
    }
    Ok(())
}

/// The corrected state is finite.
fn check_state(x: &DVector<f64>, dx: &[f64]) -> Result<(), Error> {
    for (i, (&xi, &dxi)) in x.iter().zip(dx).enumerate() {
        if !(xi + dxi).is_finite() {
            return Err(Error::StateNotFinite { index: i });
        }
    }
    Ok(())
}

/// Index of column `j`, row `i` in an `n`-row column-major buffer.
#[inline]
const fn at(n: usize, i: usize, j: usize) -> usize {
    j * n + i
}

impl Ekf {
    /// A filter at the world origin (zero pose covariance: the world frame is the robot at the
    /// first frame), with no landmarks and the camera from `start`.
    pub fn new(rig: &Rig, start: &CameraStart, settings: Settings) -> Result<Self, Error> {
        settings.check()?;
        check_noise(&rig.noise)?;
        for p in Param::ALL {
            check_finite("start camera parameter", start.camera.get(p))?;
        }
        for (name, value) in [
            ("camera f", start.camera.f),
            ("camera baseline", start.camera.baseline),
        ] {
            if value <= 0.0 {
                return Err(Error::BadValue {
                    name,
                    value,
                    expected: "positive",
                });
            }
        }
        for v in start.covariance.iter() {
            check_finite("start camera covariance entry", *v)?;
        }
        let mut estimated: Vec<Param> = Vec::with_capacity(rig.estimate.len());
        for &p in &rig.estimate {
            if estimated.contains(&p) {
                return Err(Error::DuplicateEstimate { param: p });
            }
            estimated.push(p);
        }
        let m = estimated.len();
        let n = POSE_DIM + m;
        let mut x = DVector::zeros(n);
        let mut p_mat = DMatrix::zeros(n, n);
        for (a, &pa) in estimated.iter().enumerate() {
            x[POSE_DIM + a] = start.camera.get(pa);
        }
        // Parameters phase 1 held at nominal (zero variance) enter with the prior variance,
        // uncorrelated with the others.
        let held: Vec<bool> = estimated
            .iter()
            .map(|pa| start.covariance[(pa.index(), pa.index())] <= 0.0)
            .collect();
        for (a, &pa) in estimated.iter().enumerate() {
            for (b, &pb) in estimated.iter().enumerate() {
                let v = if a == b && held[a] {
                    let sigma = rig.prior[pa.index()].ok_or(Error::MissingPrior { param: pa })?;
                    if !(sigma.is_finite() && sigma > 0.0) {
                        return Err(Error::BadValue {
                            name: "prior sigma",
                            value: sigma,
                            expected: "finite and positive",
                        });
                    }
                    sigma * sigma
                } else if held[a] || held[b] {
                    0.0
                } else {
                    // Symmetrised: the hand-over may carry rounding asymmetry.
                    0.5 * (start.covariance[(pa.index(), pb.index())]
                        + start.covariance[(pb.index(), pa.index())])
                };
                p_mat[(POSE_DIM + a, POSE_DIM + b)] = v;
            }
        }
        if m > 0 {
            let block = p_mat.view((POSE_DIM, POSE_DIM), (m, m)).into_owned();
            if nalgebra::Cholesky::new(block).is_none() {
                return Err(Error::BadCameraCovariance);
            }
        }
        let gate = chi2_quantile(settings.gate_probability, DOF);
        Ok(Self {
            x,
            p: p_mat,
            landmarks: Vec::new(),
            estimated,
            camera_base: start.camera,
            noise: rig.noise,
            width: rig.width,
            height: rig.height,
            settings,
            gate,
            next_id: 0,
            health: HealthState::new(settings.nis_window),
            motion_covariance: Matrix3::zeros(),
            workspace: Workspace::default(),
            held: [false; N_PARAMS],
        })
    }

    /// A filter starting from the rig's nominal camera and `[prior]` sigmas (phase 1 skipped).
    pub fn from_prior(rig: &Rig, settings: Settings) -> Result<Self, Error> {
        Self::new(rig, &CameraStart::from_prior(rig), settings)
    }

    /// A filter starting from phase 1's hand-over.
    pub fn from_handover(
        rig: &Rig,
        handover: &Handover,
        settings: Settings,
    ) -> Result<Self, Error> {
        Self::new(rig, &CameraStart::from_handover(handover), settings)
    }

    /// A filter starting from phase 1's batch ([`rig_model::handover::BatchHandover`]): the last
    /// frame's pose, every landmark and the estimated camera parameters with their joint
    /// covariance, so that the frames of phase 1 are in the map. Returns the filter and the
    /// landmarks' ids in the hand-over's order.
    pub fn from_batch(
        rig: &Rig,
        handover: &BatchHandover,
        settings: Settings,
    ) -> Result<(Self, Vec<LandmarkId>), Error> {
        let start = CameraStart {
            camera: handover.camera,
            covariance: handover.camera_covariance,
        };
        let mut ekf = Self::new(rig, &start, settings)?;
        let m = ekf.estimated.len();
        let nl = handover.landmarks.len();
        let n = POSE_DIM + LANDMARK_DIM * nl + m;
        let src = &handover.covariance;
        let mb = handover.estimated.len();
        if src.nrows() != POSE_DIM + mb + LANDMARK_DIM * nl || src.ncols() != src.nrows() {
            return Err(Error::BadCameraCovariance);
        }
        // Batch order [pose, its estimated C, landmarks] -> filter order [pose, landmarks,
        // C]; a parameter the batch held at nominal enters with its prior, uncorrelated.
        let mut map: Vec<usize> = Vec::with_capacity(src.nrows());
        map.extend(0..POSE_DIM);
        for pb in &handover.estimated {
            let a = ekf
                .estimated
                .iter()
                .position(|pa| pa == pb)
                .ok_or(Error::BadCameraCovariance)?;
            map.push(POSE_DIM + LANDMARK_DIM * nl + a);
        }
        map.extend((0..LANDMARK_DIM * nl).map(|j| POSE_DIM + j));
        let mut x = DVector::zeros(n);
        x[0] = handover.pose.x;
        x[1] = handover.pose.y;
        x[2] = wrap_angle(handover.pose.theta);
        for (j, l) in handover.landmarks.iter().enumerate() {
            for a in 0..LANDMARK_DIM {
                x[POSE_DIM + LANDMARK_DIM * j + a] = l.position[a];
            }
        }
        for (a, &pa) in ekf.estimated.iter().enumerate() {
            x[POSE_DIM + LANDMARK_DIM * nl + a] = handover.camera.get(pa);
        }
        if let Some(&value) = x.iter().find(|v| !v.is_finite()) {
            return Err(Error::NonFinite {
                what: "phase-1 batch state",
                value,
            });
        }
        let mut p = DMatrix::zeros(n, n);
        for (i, &mi) in map.iter().enumerate() {
            for (j, &mj) in map.iter().enumerate() {
                p[(mi, mj)] = 0.5 * (src[(i, j)] + src[(j, i)]);
            }
        }
        for (a, pa) in ekf.estimated.iter().enumerate() {
            if !handover.estimated.contains(pa) {
                let sigma = rig.prior[pa.index()].ok_or(Error::MissingPrior { param: *pa })?;
                let k = POSE_DIM + LANDMARK_DIM * nl + a;
                p[(k, k)] = sigma * sigma;
            }
        }
        if p.iter().any(|v| !v.is_finite()) {
            return Err(Error::BadCameraCovariance);
        }
        ekf.x = x;
        ekf.p = p;
        let mut ids = Vec::with_capacity(nl);
        for l in &handover.landmarks {
            let id = LandmarkId(ekf.next_id);
            ekf.next_id += 1;
            ekf.landmarks.push(Slot {
                id,
                observations: l.observations,
                rejections_in_a_row: 0,
            });
            ids.push(id);
        }
        Ok((ekf, ids))
    }

    /// Re-seeds the filter with a joint estimate of the fixed-lag smoother (phase 2's batch,
    /// [`selfcal::smoother::Smoother::start_mapping`]): the pose, every landmark the map holds
    /// (`index(id)` gives its place in the batch) and the estimated camera parameters, with
    /// their joint covariance. The landmarks' ids and counters stay. Fails, changing nothing,
    /// when a landmark or parameter is missing from the estimate or a value is not finite.
    pub fn set_joint(
        &mut self,
        joint: &JointEstimate,
        index: impl Fn(LandmarkId) -> Option<usize>,
    ) -> Result<(), Error> {
        let nl = self.landmarks.len();
        let m = self.estimated.len();
        let n = POSE_DIM + LANDMARK_DIM * nl + m;
        let src = &joint.covariance;
        let mb = joint.estimated.len();
        let nb = joint.landmarks.len();
        if src.nrows() != POSE_DIM + mb + LANDMARK_DIM * nb || src.ncols() != src.nrows() {
            return Err(Error::BadCameraCovariance);
        }
        // Filter index -> batch index.
        let mut map: Vec<usize> = Vec::with_capacity(n);
        map.extend(0..POSE_DIM);
        for slot in &self.landmarks {
            let j = index(slot.id)
                .filter(|&j| j < nb)
                .ok_or(Error::UnknownLandmark { id: slot.id })?;
            map.extend((0..LANDMARK_DIM).map(|a| POSE_DIM + mb + LANDMARK_DIM * j + a));
        }
        for pa in &self.estimated {
            let b = joint
                .estimated
                .iter()
                .position(|pb| pb == pa)
                .ok_or(Error::MissingPrior { param: *pa })?;
            map.push(POSE_DIM + b);
        }
        let mut x = DVector::zeros(n);
        x[0] = joint.pose.x;
        x[1] = joint.pose.y;
        x[2] = wrap_angle(joint.pose.theta);
        for (k, slot) in self.landmarks.iter().enumerate() {
            let j = index(slot.id).ok_or(Error::UnknownLandmark { id: slot.id })?;
            let l = joint
                .landmarks
                .get(j)
                .ok_or(Error::UnknownLandmark { id: slot.id })?;
            for a in 0..LANDMARK_DIM {
                x[POSE_DIM + LANDMARK_DIM * k + a] = l[a];
            }
        }
        for (a, &pa) in self.estimated.iter().enumerate() {
            x[POSE_DIM + LANDMARK_DIM * nl + a] = joint.camera.get(pa);
        }
        if let Some(&value) = x.iter().find(|v| !v.is_finite()) {
            return Err(Error::NonFinite {
                what: "smoother state",
                value,
            });
        }
        let p = DMatrix::from_fn(n, n, |i, j| {
            let (bi, bj) = (map[i], map[j]);
            0.5 * (src[(bi, bj)] + src[(bj, bi)])
        });
        if p.iter().any(|v| !v.is_finite()) || (0..n).any(|i| p[(i, i)] < 0.0) {
            return Err(Error::BadCameraCovariance);
        }
        self.x = x;
        self.p = p;
        Ok(())
    }

    /// The filter's joint estimate in the batch's layout (`[pose, estimated C, landmarks]`,
    /// landmarks in map order), with the landmark ids in that order: what the fixed-lag
    /// smoother is (re)started from (`selfcal::smoother::Smoother::restart_mapping`).
    pub fn joint(&self, t_us: u64) -> (JointEstimate, Vec<LandmarkId>) {
        let nl = self.landmarks.len();
        let m = self.estimated.len();
        let c0 = self.camera_offset();
        // Batch index -> filter index.
        let mut map: Vec<usize> = (0..POSE_DIM).collect();
        map.extend(c0..c0 + m);
        map.extend(POSE_DIM..POSE_DIM + LANDMARK_DIM * nl);
        let n = map.len();
        let ps = self.p.as_slice();
        let nn = self.x.len();
        let covariance = DMatrix::from_fn(n, n, |i, j| {
            let (fi, fj) = (
                map.get(i).copied().unwrap_or(0),
                map.get(j).copied().unwrap_or(0),
            );
            sym(ps, nn, fi, fj)
        });
        let landmarks = (0..nl)
            .map(|k| {
                let i = POSE_DIM + LANDMARK_DIM * k;
                Vector3::new(self.x[i], self.x[i + 1], self.x[i + 2])
            })
            .collect();
        (
            JointEstimate {
                t_us,
                pose: self.pose(),
                camera: self.camera(),
                estimated: self.estimated.clone(),
                landmarks,
                covariance,
            },
            self.landmarks.iter().map(|l| l.id).collect(),
        )
    }

    /// Sets the start pose and its covariance (symmetric positive semi-definite), before any
    /// landmark is added.
    pub fn set_start_pose(&mut self, pose: Pose2, covariance: &Matrix3<f64>) -> Result<(), Error> {
        if !self.landmarks.is_empty() {
            return Err(Error::PoseAfterLandmarks {
                landmarks: self.landmarks.len(),
            });
        }
        check_finite("start pose x", pose.x)?;
        check_finite("start pose y", pose.y)?;
        check_finite("start pose theta", pose.theta)?;
        if covariance.iter().any(|v| !v.is_finite())
            || (covariance - covariance.transpose()).abs().max() > 1e-12 * covariance.abs().max()
            || covariance.symmetric_eigenvalues().min() < 0.0
        {
            return Err(Error::BadPoseCovariance);
        }
        self.x[0] = pose.x;
        self.x[1] = pose.y;
        self.x[2] = wrap_angle(pose.theta);
        for i in 0..POSE_DIM {
            for j in 0..POSE_DIM {
                self.p[(i, j)] = 0.5 * (covariance[(i, j)] + covariance[(j, i)]);
            }
        }
        Ok(())
    }

    // ---------------------------------------------------------------- inspection

    /// Length of the state vector, `3 + 3 N + m`.
    pub fn state_len(&self) -> usize {
        self.x.len()
    }

    /// The state vector `[X, Y, theta, L_1, ..., L_N, C_est]`.
    pub fn state(&self) -> &DVector<f64> {
        &self.x
    }

    /// The covariance `P`, `n x n`, exactly symmetric (a copy: O(n^2)).
    pub fn covariance(&self) -> DMatrix<f64> {
        let mut p = self.p.clone();
        let n = p.nrows();
        mirror_lower(p.as_mut_slice(), n);
        p
    }

    /// The covariance buffer itself, column-major (`as_slice()` is the one buffer nalgebra and
    /// faer views are made of): its lower triangle, diagonal included, is `P`; the strict
    /// upper triangle is not maintained (see the crate docs).
    pub fn covariance_lower(&self) -> &DMatrix<f64> {
        &self.p
    }

    /// Entry `(i, j)` of `P`.
    pub fn covariance_entry(&self, i: usize, j: usize) -> Option<f64> {
        let n = self.x.len();
        (i < n && j < n).then(|| sym(self.p.as_slice(), n, i, j))
    }

    /// The `3 x 3` block of `P` at `(i, i)`.
    fn block3(&self, i: usize) -> Matrix3<f64> {
        let n = self.x.len();
        Matrix3::from_fn(|r, c| sym(self.p.as_slice(), n, i + r, i + c))
    }

    /// The robot pose.
    pub fn pose(&self) -> Pose2 {
        Pose2::new(self.x[0], self.x[1], self.x[2])
    }

    /// The pose covariance over `(X, Y, theta)`.
    pub fn pose_covariance(&self) -> Matrix3<f64> {
        self.block3(0)
    }

    /// The camera parameters estimated, in state order (the rig's `estimate` order).
    pub fn estimated_parameters(&self) -> &[Param] {
        &self.estimated
    }

    fn camera_offset(&self) -> usize {
        POSE_DIM + LANDMARK_DIM * self.landmarks.len()
    }

    /// Index in the state of an estimated camera parameter.
    pub fn camera_state_index(&self, param: Param) -> Option<usize> {
        let k = self.estimated.iter().position(|&p| p == param)?;
        Some(self.camera_offset() + k)
    }

    /// Every camera parameter: the estimated ones from the state, the others fixed.
    pub fn camera(&self) -> CameraParams {
        let mut c = self.camera_base;
        let c0 = self.camera_offset();
        for (k, &p) in self.estimated.iter().enumerate() {
            c.set(p, self.x[c0 + k]);
        }
        c
    }

    /// Covariance of every camera parameter, [`Param::ALL`] order: zero rows and columns for
    /// the ones not estimated.
    pub fn camera_covariance(&self) -> CameraCovariance {
        let mut cov = CameraCovariance::zeros();
        let c0 = self.camera_offset();
        for (a, pa) in self.estimated.iter().enumerate() {
            for (b, pb) in self.estimated.iter().enumerate() {
                cov[(pa.index(), pb.index())] =
                    sym(self.p.as_slice(), self.x.len(), c0 + a, c0 + b);
            }
        }
        cov
    }

    /// The noise model (rig file `[noise]`).
    pub fn noise(&self) -> &Noise {
        &self.noise
    }

    /// The settings.
    pub fn settings(&self) -> &Settings {
        &self.settings
    }

    /// Switches the form of the covariance update (both are exact; see the crate docs).
    pub fn set_covariance_update(&mut self, form: CovarianceUpdate) {
        self.settings.covariance_update = form;
    }

    /// The NIS bound of the innovation gate (4 dof).
    pub fn gate_bound(&self) -> f64 {
        self.gate
    }

    /// Landmarks in the map.
    pub fn landmark_count(&self) -> usize {
        self.landmarks.len()
    }

    /// Whether a landmark is in the map.
    pub fn contains(&self, id: LandmarkId) -> bool {
        self.slot(id).is_some()
    }

    /// Position of a landmark in the state order (ids increase along it).
    fn slot(&self, id: LandmarkId) -> Option<usize> {
        self.landmarks.binary_search_by_key(&id, |s| s.id).ok()
    }

    /// Index in the state of a landmark's `x` (then `y`, `z`).
    pub fn landmark_state_index(&self, id: LandmarkId) -> Option<usize> {
        self.slot(id).map(|s| POSE_DIM + LANDMARK_DIM * s)
    }

    fn estimate_at(&self, s: usize, slot: &Slot) -> LandmarkEstimate {
        let i = POSE_DIM + LANDMARK_DIM * s;
        LandmarkEstimate {
            id: slot.id,
            position: self.x.fixed_rows::<3>(i).into_owned(),
            covariance: self.block3(i),
            observations: slot.observations,
        }
    }

    /// One landmark's estimate.
    pub fn landmark(&self, id: LandmarkId) -> Option<LandmarkEstimate> {
        let s = self.slot(id)?;
        self.landmarks.get(s).map(|slot| self.estimate_at(s, slot))
    }

    /// Measurements a landmark has used (the one that initialised it and every accepted one).
    pub fn observations_of(&self, id: LandmarkId) -> Option<u64> {
        let s = self.slot(id)?;
        self.landmarks.get(s).map(|slot| slot.observations)
    }

    /// The images' size, pixels.
    pub fn image_size(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    /// Every landmark's estimate, in state order (increasing id).
    pub fn landmarks(&self) -> impl Iterator<Item = LandmarkEstimate> + '_ {
        self.landmarks
            .iter()
            .enumerate()
            .map(|(s, slot)| self.estimate_at(s, slot))
    }

    /// The filter's health: counters, windowed NIS, divergence flag.
    pub fn health(&self) -> Health {
        self.health.snapshot()
    }

    /// The process noise added to the pose since the last call, propagated to the current
    /// pose (`M <- F M F^T + Q` at each prediction), and resets it: the uncertainty of the
    /// relative motion between two frames, for the confirmation gate.
    pub(crate) fn take_motion_covariance(&mut self) -> Matrix3<f64> {
        core::mem::replace(&mut self.motion_covariance, Matrix3::zeros())
    }

    // ---------------------------------------------------------------- prediction

    /// Eq. 3-4: predicts with the robot-frame velocities `(vx, vy, vtheta)` held for `dt_s`
    /// seconds (one odometry sample).
    pub fn predict(&mut self, vx: f64, vy: f64, vtheta: f64, dt_s: f64) -> Result<(), Error> {
        let inc = Increment::from_velocities(vx, vy, vtheta, dt_s, &self.noise)?;
        self.predict_increment(&inc)
    }

    /// Predicts over `[t0_us, t1_us]` with the odometry samples (sorted by time), each held
    /// from its timestamp until the next, as one composed motion.
    pub fn predict_odometry(
        &mut self,
        samples: &[OdomSample],
        t0_us: u64,
        t1_us: u64,
    ) -> Result<(), Error> {
        let inc = Increment::from_odometry(samples, t0_us, t1_us, &self.noise)?;
        self.predict_increment(&inc)
    }

    /// Predicts with a motion and its covariance: `pose' = pose (+) motion`,
    /// `P_rr = F P_rr F^T + Q`, `P_rx = F P_rx`. Only the pose rows and columns change: O(n).
    pub fn predict_increment(&mut self, inc: &Increment) -> Result<(), Error> {
        self.predict_increment_vehicle(inc, &nalgebra::Matrix3x4::zeros())
    }

    /// [`Self::predict_increment`] for a motion that depends on the vehicle's parameters `V`
    /// (vehicle-interfaces.md 1.2): `vehicle_jacobian` is `d motion / dV` at the filter's `V`
    /// ([`Param::VEHICLE`] order; the motion was integrated with it). With `G = d pose' / dV`
    /// for the estimated ones, `P_rr = F P_rr F^T + F P_rV G^T + G P_Vr F^T + G P_VV G^T + Q`
    /// and `P_rx = F P_rx + G P_Vx`: still only the pose rows and columns change, O(n).
    pub fn predict_increment_vehicle(
        &mut self,
        inc: &Increment,
        vehicle_jacobian: &nalgebra::Matrix3x4<f64>,
    ) -> Result<(), Error> {
        let m = &inc.motion;
        for (what, value) in [
            ("motion dx", m.dx),
            ("motion dy", m.dy),
            ("motion dtheta", m.dtheta),
        ] {
            check_finite(what, value)?;
        }
        for (what, matrix) in [
            ("motion covariance", inc.covariance.as_slice()),
            ("motion vehicle Jacobian", vehicle_jacobian.as_slice()),
        ] {
            if let Some(v) = matrix.iter().copied().find(|v| !v.is_finite()) {
                return Err(Error::NonFinite { what, value: v });
            }
        }
        let theta = self.x[2];
        let (pose, f, q) = inc.apply(&self.pose());
        let n = self.x.len();
        // G's columns for the estimated vehicle parameters: (state index, d pose' / dV_k).
        let rot = crate::motion::compose_jacobian_second(theta);
        let c0 = self.camera_offset();
        let g: Vec<(usize, Vector3<f64>)> = self
            .estimated
            .iter()
            .enumerate()
            .filter(|(_, p)| p.is_vehicle())
            .map(|(k, p)| {
                (
                    c0 + k,
                    rot * vehicle_jacobian.column(p.index() - rig_model::N_CAMERA),
                )
            })
            .filter(|(_, col)| col.iter().any(|v| *v != 0.0))
            .collect();
        self.x[0] = pose.x;
        self.x[1] = pose.y;
        self.x[2] = wrap_angle(pose.theta);
        // F = [[1, 0, a], [0, 1, b], [0, 0, 1]].
        let (fa, fb) = (f[(0, 2)], f[(1, 2)]);
        let prr = self.pose_covariance();
        let buf = self.p.as_mut_slice();
        // P_Vr before the pose columns change (row c >= 3 of columns 0..3).
        let pvr: Vec<nalgebra::RowVector3<f64>> = g
            .iter()
            .map(|(c, _)| {
                nalgebra::RowVector3::new(buf[at(n, *c, 0)], buf[at(n, *c, 1)], buf[at(n, *c, 2)])
            })
            .collect();
        let mut new_rr = f * prr * f.transpose() + q;
        for (a, (ca, ga)) in g.iter().enumerate() {
            let cross = f * pvr[a].transpose() * ga.transpose();
            new_rr += cross + cross.transpose();
            for (cb, gb) in &g {
                let pab = buf[at(n, (*ca).max(*cb), (*ca).min(*cb))];
                new_rr += ga * gb.transpose() * pab;
            }
        }
        let new_rr = 0.5 * (new_rr + new_rr.transpose());
        // P_xr = P_rx^T lies in columns 0..3 below the pose block (the lower triangle).
        for j in POSE_DIM..n {
            let (p0, p1, p2) = (buf[at(n, j, 0)], buf[at(n, j, 1)], buf[at(n, j, 2)]);
            let mut row = nalgebra::RowVector3::new(p0 + fa * p2, p1 + fb * p2, p2);
            for (c, gc) in &g {
                let pjc = buf[at(n, j.max(*c), j.min(*c))];
                row += gc.transpose() * pjc;
            }
            buf[at(n, j, 0)] = row[0];
            buf[at(n, j, 1)] = row[1];
            buf[at(n, j, 2)] = row[2];
        }
        for i in 0..POSE_DIM {
            for j in 0..POSE_DIM {
                buf[at(n, i, j)] = new_rr[(i, j)];
            }
        }
        self.motion_covariance = f * self.motion_covariance * f.transpose() + q;
        Ok(())
    }

    // ---------------------------------------------------------------- observation model

    /// Linearises the observation of the landmark in slot `s` at the current estimate: the
    /// predicted measurement and the non-zero columns of `H` (the innovation left zero).
    fn model(
        &self,
        s: usize,
        camera: &CameraParams,
        pose: &Pose2,
    ) -> Result<(Measurement, Obs), Error> {
        let id = self.landmarks.get(s).map_or(LandmarkId(u64::MAX), |l| l.id);
        let li = POSE_DIM + LANDMARK_DIM * s;
        let landmark = self.x.fixed_rows::<3>(li).into_owned();
        let (predicted, jac) = project_with_jacobians(camera, pose, &landmark)
            .map_err(|source| Error::Projection { id, source })?;
        let mut obs = Obs {
            cols: [0; MAX_INVOLVED],
            h: [[0.0; MAX_INVOLVED]; 4],
            q: 0,
            nu: [0.0; 4],
        };
        let mut push = |col: usize, column: Vector4<f64>| {
            if let Some(slot) = obs.cols.get_mut(obs.q) {
                *slot = col;
                for (r, row) in obs.h.iter_mut().enumerate() {
                    row[obs.q] = column[r];
                }
                obs.q += 1;
            }
        };
        let blocks: [(usize, &Jac4x3); 2] = [(0, &jac.pose), (li, &jac.landmark)];
        for (start, block) in blocks {
            for k in 0..3 {
                push(start + k, block.column(k).into_owned());
            }
        }
        let c0 = self.camera_offset();
        for (k, p) in self.estimated.iter().enumerate() {
            // The projection does not depend on the vehicle's parameters: no column.
            if !p.is_vehicle() {
                push(c0 + k, jac.camera.column(p.index()).into_owned());
            }
        }
        Ok((predicted, obs))
    }

    /// `H P H^T + R` of one observation (4x4), from the involved block of `P` only.
    fn innovation_covariance(&self, m: &Obs) -> Matrix4<f64> {
        let n = self.x.len();
        let buf = self.p.as_slice();
        let q = m.q.min(MAX_INVOLVED);
        // The involved block of P (its columns increase, so `a >= b` is in the lower triangle).
        let mut pq = [[0.0; MAX_INVOLVED]; MAX_INVOLVED];
        for (a, &ca) in m.cols.iter().enumerate().take(q) {
            for (b, &cb) in m.cols.iter().enumerate().take(a + 1) {
                // cb <= ca: (ca, cb) is in the lower triangle.
                let v = buf.get(cb * n + ca).copied().unwrap_or(f64::NAN);
                pq[a][b] = v;
                pq[b][a] = v;
            }
        }
        // T = H P_qq (4 x q), then S = T H^T.
        let mut t = [[0.0; MAX_INVOLVED]; 4];
        for (t_row, h_row) in t.iter_mut().zip(&m.h) {
            for (a, h) in h_row.iter().enumerate().take(q) {
                for (tv, pv) in t_row.iter_mut().zip(&pq[a]).take(q) {
                    *tv += h * pv;
                }
            }
        }
        let r2 = self.noise.pixel * self.noise.pixel;
        let mut s = Matrix4::zeros();
        for (r, t_row) in t.iter().enumerate() {
            for (c, h_row) in m.h.iter().enumerate().skip(r) {
                let mut v: f64 = t_row.iter().zip(h_row).take(q).map(|(a, b)| a * b).sum();
                if r == c {
                    v += r2;
                }
                s[(r, c)] = v;
                s[(c, r)] = v;
            }
        }
        s
    }

    /// The predicted measurement of a landmark and its innovation covariance
    /// `S = H P H^T + R` (4x4), for association and map matching.
    pub fn predict_measurement(
        &self,
        id: LandmarkId,
    ) -> Result<(Measurement, Matrix4<f64>), Error> {
        let s = self.slot(id).ok_or(Error::UnknownLandmark { id })?;
        let (z, m) = self.model(s, &self.camera(), &self.pose())?;
        Ok((z, self.innovation_covariance(&m)))
    }

    /// The predicted measurement of a landmark and the full `4 x n` Jacobian `H` of the
    /// measurement with respect to the state, dense. For tests and tools: the update never
    /// forms it.
    pub fn measurement_jacobian(
        &self,
        id: LandmarkId,
    ) -> Result<(Measurement, DMatrix<f64>), Error> {
        let s = self.slot(id).ok_or(Error::UnknownLandmark { id })?;
        let (z, m) = self.model(s, &self.camera(), &self.pose())?;
        let mut h = DMatrix::zeros(4, self.x.len());
        for (t, &c) in m.cols.iter().enumerate().take(m.q) {
            for r in 0..4 {
                h[(r, c)] = m.h[r][t];
            }
        }
        Ok((z, h))
    }

    /// The landmarks whose predicted measurement falls inside both images, with it.
    pub fn visible_landmarks(&self) -> Vec<(LandmarkId, Measurement)> {
        let camera = self.camera();
        let pose = self.pose();
        let (w, h) = (f64::from(self.width), f64::from(self.height));
        let inside = |u: f64, v: f64| u >= 0.0 && u < w && v >= 0.0 && v < h;
        self.landmarks
            .iter()
            .enumerate()
            .filter_map(|(s, slot)| {
                let li = POSE_DIM + LANDMARK_DIM * s;
                let l = self.x.fixed_rows::<3>(li).into_owned();
                let z = rig_model::project(&camera, &pose, &l).ok()?;
                (inside(z[0], z[1]) && inside(z[2], z[3])).then_some((slot.id, z))
            })
            .collect()
    }

    // ---------------------------------------------------------------- update

    /// Holds estimated camera parameters for the updates to come: they are considered, not
    /// refined (their gain rows are zero, as with [`CameraUpdate::Consider`] for all of them):
    /// value and variance stay, their covariance is carried into the pose and landmarks. For
    /// a parameter the data cannot inform yet (the baseline on a vehicle that has not moved:
    /// docs/real-images.md), so that model errors elsewhere cannot pull it. Parameters not
    /// estimated are ignored.
    pub fn set_held(&mut self, params: &[Param]) {
        self.held = [false; N_PARAMS];
        for p in params {
            if self.estimated.contains(p)
                && let Some(h) = self.held.get_mut(p.index())
            {
                *h = true;
            }
        }
    }

    /// The estimated parameters held ([`Ekf::set_held`]).
    pub fn held(&self) -> Vec<Param> {
        self.estimated
            .iter()
            .copied()
            .filter(|p| self.held.get(p.index()).copied().unwrap_or(false))
            .collect()
    }

    /// Camera state rows whose gain is zero: all with [`CameraUpdate::Consider`], else the
    /// held ones.
    fn frozen(&self, k: usize) -> bool {
        self.settings.camera_update == CameraUpdate::Consider
            || self
                .estimated
                .get(k)
                .is_some_and(|p| self.held.get(p.index()).copied().unwrap_or(false))
    }

    /// Whether the next update uses the Joseph form (camera considered or held, or a small
    /// state in [`CovarianceUpdate::Auto`]): it costs about twice the factored form.
    pub fn uses_joseph(&self) -> bool {
        self.joseph()
    }

    fn joseph(&self) -> bool {
        if self.settings.camera_update == CameraUpdate::Consider || self.held.iter().any(|h| *h) {
            return true;
        }
        match self.settings.covariance_update {
            CovarianceUpdate::Joseph => true,
            CovarianceUpdate::Factored => false,
            CovarianceUpdate::Auto => self.x.len() <= AUTO_JOSEPH_MAX_STATES,
        }
    }

    /// Eq. 5-8: updates with a batch of landmark measurements `(uL, vL, uR, vR)`.
    ///
    /// Each observation is gated on its own NIS first; the accepted ones are applied together.
    /// On an error nothing changes (the health counts refused updates).
    pub fn update(&mut self, batch: &[(LandmarkId, Measurement)]) -> Result<UpdateReport, Error> {
        let mut slots: Vec<usize> = Vec::with_capacity(batch.len());
        for (id, z) in batch {
            if let Some(&value) = z.iter().find(|v| !v.is_finite()) {
                return Err(Error::NonFiniteMeasurement { id: *id, value });
            }
            let s = self.slot(*id).ok_or(Error::UnknownLandmark { id: *id })?;
            if slots.contains(&s) {
                return Err(Error::DuplicateObservation { id: *id });
            }
            slots.push(s);
        }
        let camera = self.camera();
        let pose = self.pose();
        // Linearise every observation at the current estimate; one that cannot be projected
        // is rejected outright.
        let mut obs: Vec<Obs> = Vec::with_capacity(batch.len());
        let mut nis: Vec<f64> = alloc::vec![f64::INFINITY; batch.len()];
        let mut projected: Vec<usize> = Vec::with_capacity(batch.len());
        for (b, (&s, (_, z))) in slots.iter().zip(batch).enumerate() {
            if let Ok((predicted, mut o)) = self.model(s, &camera, &pose) {
                let nu = z - predicted;
                o.nu = [nu[0], nu[1], nu[2], nu[3]];
                obs.push(o);
                projected.push(b);
            }
        }
        let mut ws = core::mem::take(&mut self.workspace);
        let result = self.gate_and_update(&obs, &projected, &mut nis, &mut ws);
        self.workspace = ws;
        if let Err(e) = result {
            self.health.refused_updates += 1;
            return Err(e);
        }
        let mut report = UpdateReport::default();
        if !batch.is_empty() {
            self.health.updates += 1;
        }
        for ((&s, (id, _)), &v) in slots.iter().zip(batch).zip(&nis) {
            let accepted = v <= self.gate;
            self.health.record(accepted.then_some(v));
            let gated = Gated { id: *id, nis: v };
            if accepted {
                report.accepted.push(gated);
            } else {
                report.rejected.push(gated);
            }
            if let Some(slot) = self.landmarks.get_mut(s) {
                if accepted {
                    slot.observations += 1;
                    slot.rejections_in_a_row = 0;
                } else {
                    slot.rejections_in_a_row = slot.rejections_in_a_row.saturating_add(1);
                }
            }
        }
        let limit = self.settings.max_consecutive_rejections;
        if self
            .landmarks
            .iter()
            .any(|l| l.rejections_in_a_row >= limit)
        {
            let doomed: Vec<LandmarkId> = self
                .landmarks
                .iter()
                .filter(|l| l.rejections_in_a_row >= limit)
                .map(|l| l.id)
                .collect();
            for id in doomed {
                if self.remove_landmark(id).is_ok() {
                    report.removed.push(id);
                }
            }
        }
        Ok(report)
    }

    /// `A`, `S`, the gate (each observation's NIS into `nis[projected[j]]`), and the batch
    /// update of the accepted ones. Checks everything before touching the state; on an error
    /// the state is as it was.
    fn gate_and_update(
        &mut self,
        obs: &[Obs],
        projected: &[usize],
        nis: &mut [f64],
        ws: &mut Workspace,
    ) -> Result<(), Error> {
        if obs.is_empty() {
            return Ok(());
        }
        let n = self.x.len();
        if n <= SEQUENTIAL_MAX_STATES {
            // Gate each observation on the prior, then apply the accepted ones in turn.
            let mut keep: Vec<&Obs> = Vec::with_capacity(obs.len());
            for (j, o) in obs.iter().enumerate() {
                let s4 = self.innovation_covariance(o);
                let l = cholesky4(&core::array::from_fn(|r| {
                    core::array::from_fn(|c| s4[(r, c)])
                }))
                .ok_or(Error::InnovationNotPositiveDefinite { observations: 1 })?;
                let v = mahalanobis4(&l, &o.nu);
                if let Some(slot) = projected.get(j).and_then(|&b| nis.get_mut(b)) {
                    *slot = if v.is_finite() { v } else { f64::INFINITY };
                }
                if v.is_finite() && v <= self.gate {
                    keep.push(o);
                }
            }
            return self.sequential_update(&keep, ws);
        }
        let r2 = self.noise.pixel * self.noise.pixel;
        innovation_products(self.p.as_slice(), n, obs, r2, ws);
        let mut d = 4 * obs.len();
        if ws.s.iter().any(|v| !v.is_finite()) {
            return Err(Error::InnovationNotPositiveDefinite {
                observations: obs.len(),
            });
        }
        // Gate: each observation's NIS with its own 4x4 block of S.
        let mut keep: Vec<usize> = Vec::with_capacity(obs.len());
        for (j, o) in obs.iter().enumerate() {
            let block = Matrix4::from_fn(|r, c| ws.s[(4 * j + c) * d + 4 * j + r]);
            let chol = block
                .cholesky()
                .ok_or(Error::InnovationNotPositiveDefinite { observations: 1 })?;
            let nu = Vector4::from(o.nu);
            let v = nu.dot(&chol.solve(&nu));
            if let Some(slot) = projected.get(j).and_then(|&b| nis.get_mut(b)) {
                *slot = if v.is_finite() { v } else { f64::INFINITY };
            }
            if v.is_finite() && v <= self.gate {
                keep.push(j);
            }
        }
        if keep.is_empty() {
            return Ok(());
        }
        if keep.len() < obs.len() {
            compact(n, d, &keep, &mut ws.a, &mut ws.s);
            d = 4 * keep.len();
        }
        let nu: Vec<f64> = keep
            .iter()
            .filter_map(|&j| obs.get(j))
            .flat_map(|o| o.nu)
            .collect();
        let chol = nalgebra::Cholesky::new(DMatrix::from_column_slice(d, d, &ws.s)).ok_or(
            Error::InnovationNotPositiveDefinite {
                observations: keep.len(),
            },
        )?;
        let joseph = self.joseph();
        gain_factors(
            n,
            d,
            chol.l_dirty().as_slice(),
            &ws.s,
            &nu,
            joseph,
            &ws.a,
            &mut ws.w,
            &mut ws.y,
            &mut ws.dx,
            &mut ws.lhs,
            &mut ws.rhs,
        );
        self.freeze_camera_rows(n, d, ws);
        let (lhs, rhs, alpha) = if joseph {
            (&ws.lhs, &ws.rhs, 1.0)
        } else {
            (&ws.w, &ws.w, -1.0)
        };
        // Checks before committing: every variance stays positive (O(n d) from the factors),
        // the new state is finite.
        diagonal_change(n, lhs, rhs, alpha, &mut ws.y);
        check_variances(self.p.as_slice(), n, &ws.y)?;
        check_state(&self.x, &ws.dx)?;
        // Commit.
        rank_update_lower(
            self.p.as_mut_slice(),
            n,
            lhs,
            rhs,
            lhs.len() / n.max(1),
            alpha,
        );
        for (xi, dxi) in self.x.iter_mut().zip(&ws.dx) {
            *xi += dxi;
        }
        self.x[2] = wrap_angle(self.x[2]);
        Ok(())
    }

    /// [`CameraUpdate::Consider`]: the camera rows of the gain set to zero in the update's
    /// factors (Joseph form, `n` rows, `d` measurement columns): `dx_c = 0`, and in
    /// `lhs = [K S - A, -K]`, `rhs = [K, A]` the camera rows become `[-A_c, 0]` and `[0, A_c]`,
    /// so that `P_cc` is left as it was and `P_xc` becomes `P_xc - K_x A_c^T`.
    fn freeze_camera_rows(&self, n: usize, d: usize, ws: &mut Workspace) {
        let c0 = self.camera_offset();
        for (k, i) in (c0..c0 + self.estimated.len()).enumerate() {
            if !self.frozen(k) {
                continue;
            }
            if let Some(v) = ws.dx.get_mut(i) {
                *v = 0.0;
            }
            for c in 0..d {
                let a = ws.rhs.get((d + c) * n + i).copied().unwrap_or(0.0);
                if let Some(v) = ws.lhs.get_mut(c * n + i) {
                    *v = -a;
                }
                if let Some(v) = ws.lhs.get_mut((d + c) * n + i) {
                    *v = 0.0;
                }
                if let Some(v) = ws.rhs.get_mut(c * n + i) {
                    *v = 0.0;
                }
            }
        }
    }

    /// The accepted observations applied one landmark at a time, for small states: exactly
    /// the batch update (the linearisation stays at the prior estimate; each innovation is
    /// corrected by `H_j dx` for the corrections before it), without the batch's `O(n k^2)`
    /// gain terms, which for the paper's 19 states and 20 measurements are as large as the
    /// rank update itself. Works on a copy of `P` so that a failure changes nothing.
    fn sequential_update(&mut self, obs: &[&Obs], ws: &mut Workspace) -> Result<(), Error> {
        if obs.is_empty() {
            return Ok(());
        }
        // The work is done on a copy of P padded with zero states to whole vectors: a state
        // with zero variance and no correlation is left exactly as it is by the update.
        let n = self.x.len();
        let np = n.next_multiple_of(LANES);
        let r2 = self.noise.pixel * self.noise.pixel;
        let joseph = self.joseph();
        ws.p.clear();
        ws.p.resize(np * np, 0.0);
        for (dst, src) in
            ws.p.chunks_exact_mut(np)
                .zip(self.p.as_slice().chunks_exact(n))
        {
            dst[..n].copy_from_slice(src);
        }
        ws.dx_total.clear();
        ws.dx_total.resize(np, 0.0);
        let mut s16 = [0.0; 16];
        for o in obs {
            observation_products(&ws.p, np, o, r2, &mut ws.a, &mut s16);
            let s4: [[f64; 4]; 4] =
                core::array::from_fn(|r| core::array::from_fn(|c| s16[c * 4 + r]));
            let l4 =
                cholesky4(&s4).ok_or(Error::InnovationNotPositiveDefinite { observations: 1 })?;
            // nu - H dx: the innovation at the estimate corrected so far.
            let mut nu = o.nu;
            for (r, v) in nu.iter_mut().enumerate() {
                for (h, &c) in o.h[r].iter().zip(&o.cols).take(o.q) {
                    *v -= h * ws.dx_total.get(c).copied().unwrap_or(0.0);
                }
            }
            gain_factors4(
                np,
                &l4,
                &s4,
                &nu,
                joseph,
                &ws.a,
                &mut ws.w,
                &mut ws.dx,
                &mut ws.lhs,
                &mut ws.rhs,
            );
            self.freeze_camera_rows(np, 4, ws);
            let (lhs, rhs, alpha) = if joseph {
                (&ws.lhs, &ws.rhs, 1.0)
            } else {
                (&ws.w, &ws.w, -1.0)
            };
            diagonal_change(np, lhs, rhs, alpha, &mut ws.y);
            check_variances(&ws.p, np, &ws.y)?;
            rank_update_lower_padded(&mut ws.p, np, lhs, rhs, alpha);
            for (t, d) in ws.dx_total.iter_mut().zip(&ws.dx) {
                *t += d;
            }
        }
        check_state(&self.x, &ws.dx_total)?;
        for (dst, src) in self
            .p
            .as_mut_slice()
            .chunks_exact_mut(n)
            .zip(ws.p.chunks_exact(np))
        {
            dst.copy_from_slice(&src[..n]);
        }
        for (xi, dxi) in self.x.iter_mut().zip(&ws.dx_total) {
            *xi += dxi;
        }
        self.x[2] = wrap_angle(self.x[2]);
        Ok(())
    }

    // ---------------------------------------------------------------- landmarks

    /// Adds a landmark triangulated from a measurement at the current pose and camera, with
    /// its joint linearised covariance and cross-covariances (see the crate docs).
    pub fn add_landmark(&mut self, z: &Measurement) -> Result<LandmarkId, Error> {
        if let Some(&value) = z.iter().find(|v| !v.is_finite()) {
            return Err(Error::NonFinite {
                what: "measurement of a new landmark",
                value,
            });
        }
        let camera = self.camera();
        let pose = self.pose();
        let tri =
            rig_model::triangulate(&camera, z).map_err(|source| Error::Triangulation { source })?;
        let position = tri.p_in_world(&camera, &pose);
        if let Some(&value) = position.iter().find(|v| !v.is_finite()) {
            return Err(Error::NonFinite {
                what: "triangulated landmark",
                value,
            });
        }
        let n = self.x.len();
        let c0 = self.camera_offset();
        let m = self.estimated.len();
        // G = [Gp | Gc] over the involved states (pose, estimated camera).
        let gp = tri.jac_pose(&camera, &pose);
        let gc_full = tri.jac_camera_in_world(&camera, &pose);
        let mut idx: [usize; POSE_DIM + N_PARAMS] = [0; POSE_DIM + N_PARAMS];
        let mut g = [[0.0; POSE_DIM + N_PARAMS]; 3];
        for k in 0..POSE_DIM {
            idx[k] = k;
            for a in 0..3 {
                g[a][k] = gp[(a, k)];
            }
        }
        for (k, p) in self.estimated.iter().enumerate() {
            idx[POSE_DIM + k] = c0 + k;
            for a in 0..3 {
                g[a][POSE_DIM + k] = gc_full[(a, p.index())];
            }
        }
        let q = POSE_DIM + m;
        // Cross covariance P_xL (n x 3): column a = sum_t G[a][t] P[:, idx[t]].
        let mut columns = alloc::vec![0.0; n * q];
        gather_columns(self.p.as_slice(), n, &idx[..q], &mut columns);
        let mut cross = [Vec::new(), Vec::new(), Vec::new()];
        for (a, col) in cross.iter_mut().enumerate() {
            col.resize(n, 0.0);
            for (t, pcol) in columns.chunks_exact(n).enumerate() {
                let gat = g[a][t];
                if gat == 0.0 {
                    continue;
                }
                for (c, &p) in col.iter_mut().zip(pcol) {
                    *c += gat * p;
                }
            }
        }
        // P_LL = G P_qq G^T + Gz R Gz^T, Gz the measurement Jacobian in the world frame.
        let world_from_rig =
            pose.world_from_robot_rotation() * camera.mount.robot_from_rig_rotation();
        let gz = world_from_rig * tri.jac_measurement;
        let r2 = self.noise.pixel * self.noise.pixel;
        let mut pll = gz * gz.transpose() * r2;
        for a in 0..3 {
            for b in 0..3 {
                let mut v = 0.0;
                for t in 0..q {
                    v += g[a][t] * cross[b][idx[t]];
                }
                pll[(a, b)] += v;
            }
        }
        let pll = 0.5 * (pll + pll.transpose());
        if pll.iter().any(|v| !v.is_finite()) || cross.iter().flatten().any(|v| !v.is_finite()) {
            return Err(Error::NonFinite {
                what: "new landmark covariance",
                value: f64::NAN,
            });
        }
        // Grow: insert 3 rows and columns at c0 (before the camera block).
        let n2 = n + LANDMARK_DIM;
        let mut p2 = DMatrix::<f64>::zeros(n2, n2);
        {
            let old = self.p.as_slice();
            let new = p2.as_mut_slice();
            for j2 in 0..n2 {
                let dst = &mut new[at(n2, 0, j2)..at(n2, 0, j2 + 1)];
                if (c0..c0 + LANDMARK_DIM).contains(&j2) {
                    let a = j2 - c0;
                    dst[..c0].copy_from_slice(&cross[a][..c0]);
                    for b in 0..LANDMARK_DIM {
                        dst[c0 + b] = pll[(b, a)];
                    }
                    dst[c0 + LANDMARK_DIM..].copy_from_slice(&cross[a][c0..]);
                } else {
                    let j = if j2 < c0 { j2 } else { j2 - LANDMARK_DIM };
                    let src = &old[at(n, 0, j)..at(n, 0, j + 1)];
                    dst[..c0].copy_from_slice(&src[..c0]);
                    for b in 0..LANDMARK_DIM {
                        dst[c0 + b] = cross[b][j];
                    }
                    dst[c0 + LANDMARK_DIM..].copy_from_slice(&src[c0..]);
                }
            }
        }
        let mut x2 = DVector::<f64>::zeros(n2);
        x2.rows_mut(0, c0).copy_from(&self.x.rows(0, c0));
        x2.fixed_rows_mut::<3>(c0).copy_from(&position);
        x2.rows_mut(c0 + LANDMARK_DIM, m)
            .copy_from(&self.x.rows(c0, m));
        self.x = x2;
        self.p = p2;
        let id = LandmarkId(self.next_id);
        self.next_id += 1;
        self.landmarks.push(Slot {
            id,
            observations: 1,
            rejections_in_a_row: 0,
        });
        self.health.landmarks_added += 1;
        Ok(id)
    }

    /// Removes a landmark: its rows and columns leave the state.
    pub fn remove_landmark(&mut self, id: LandmarkId) -> Result<(), Error> {
        let s = self.slot(id).ok_or(Error::UnknownLandmark { id })?;
        let n = self.x.len();
        let li = POSE_DIM + LANDMARK_DIM * s;
        let n2 = n - LANDMARK_DIM;
        let keep = |i: usize| if i < li { i } else { i + LANDMARK_DIM };
        let mut p2 = DMatrix::<f64>::zeros(n2, n2);
        {
            let old = self.p.as_slice();
            let new = p2.as_mut_slice();
            for j2 in 0..n2 {
                let src = &old[at(n, 0, keep(j2))..at(n, 0, keep(j2) + 1)];
                let dst = &mut new[at(n2, 0, j2)..at(n2, 0, j2 + 1)];
                dst[..li].copy_from_slice(&src[..li]);
                dst[li..].copy_from_slice(&src[li + LANDMARK_DIM..]);
            }
        }
        let x2 = DVector::from_fn(n2, |i, _| self.x[keep(i)]);
        self.x = x2;
        self.p = p2;
        self.landmarks.remove(s);
        self.health.landmarks_removed += 1;
        Ok(())
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used)]
mod tests {
    use super::*;
    use rig_model::camera::Mount;

    fn rig() -> Rig {
        let mut prior = [None; N_PARAMS];
        prior[Param::Baseline.index()] = Some(0.005);
        Rig {
            lens: None,
            width: 752,
            height: 480,
            nominal: CameraParams {
                vehicle: Default::default(),
                f: 700.0,
                cx: 376.0,
                cy: 240.0,
                baseline: 0.12,
                mount: Mount {
                    z: 0.8,
                    ..Mount::default()
                },
            },
            estimate: alloc::vec![Param::Baseline],
            prior,
            noise: Noise {
                pixel: 0.3,
                velocity: 0.02,
                yaw_rate: 0.01,
            },
        }
    }

    /// Two landmarks seen from the origin, after one prediction.
    fn filter() -> (Ekf, [(LandmarkId, Measurement); 2]) {
        let rig = rig();
        let mut ekf = Ekf::from_prior(&rig, Settings::default()).unwrap();
        let pose = Pose2::default();
        let points = [Vector3::new(0.5, 0.2, 3.0), Vector3::new(-0.3, -0.4, 3.2)];
        let z = points.map(|p| rig_model::project(&rig.nominal, &pose, &p).unwrap());
        let ids = z.map(|z| ekf.add_landmark(&z).unwrap());
        ekf.predict(0.1, 0.0, 0.05, 0.1).unwrap();
        (ekf, [(ids[0], z[0]), (ids[1], z[1])])
    }

    #[test]
    fn a_broken_covariance_is_refused_not_propagated() {
        // S not positive definite: the observed landmark's block made negative definite.
        let (mut ekf, obs) = filter();
        let li = ekf.landmark_state_index(obs[0].0).unwrap();
        for k in 0..3 {
            ekf.p[(li + k, li + k)] = -100.0;
        }
        let before = ekf.clone();
        let e = ekf.update(&obs[..1]).unwrap_err();
        assert_eq!(e, Error::InnovationNotPositiveDefinite { observations: 1 });
        assert_eq!(ekf.x, before.x);
        assert_eq!(ekf.p, before.p);
        let h = ekf.health();
        assert_eq!(h.refused_updates, 1);
        assert!(h.diverged);
        assert_eq!(h.accepted + h.rejected, 0);

        // S fine but an unobserved variance would go negative: landmark 2 nearly certain yet
        // strongly correlated with landmark 1 (an indefinite P).
        let (mut ekf, obs) = filter();
        let (l1, l2) = (
            ekf.landmark_state_index(obs[0].0).unwrap(),
            ekf.landmark_state_index(obs[1].0).unwrap(),
        );
        ekf.p[(l2, l2)] = 1e-6;
        ekf.p[(l1, l2)] = 0.01;
        ekf.p[(l2, l1)] = 0.01;
        for form in [CovarianceUpdate::Joseph, CovarianceUpdate::Factored] {
            ekf.settings.covariance_update = form;
            let before = ekf.clone();
            let e = ekf.update(&obs[..1]).unwrap_err();
            assert!(
                matches!(e, Error::VarianceNotPositive { index, .. } if index == l2),
                "{form:?}: {e}"
            );
            assert_eq!(ekf.x, before.x);
            assert_eq!(ekf.p, before.p);
        }
        assert_eq!(ekf.health().refused_updates, 2);
    }

    #[test]
    fn the_start_pose_keeps_zero_variance_until_the_first_prediction() {
        let rig = rig();
        let mut ekf = Ekf::from_prior(&rig, Settings::default()).unwrap();
        let p = Vector3::new(0.5, 0.2, 3.0);
        let z = rig_model::project(&rig.nominal, &Pose2::default(), &p).unwrap();
        let id = ekf.add_landmark(&z).unwrap();
        let report = ekf.update(&[(id, z)]).unwrap();
        assert_eq!(report.accepted.len(), 1);
        assert_eq!(ekf.pose_covariance(), Matrix3::zeros());
        assert_eq!(ekf.pose(), Pose2::default());
    }

    #[test]
    fn angles_wrap_into_minus_pi_pi() {
        use core::f64::consts::PI;
        for (a, w) in [
            (0.0, 0.0),
            (PI, PI),
            (-PI, PI),
            (3.0 * PI, PI),
            (2.0 * PI + 0.1, 0.1),
            (-2.0 * PI - 0.1, -0.1),
            (7.0, 7.0 - 2.0 * PI),
        ] {
            assert!((wrap_angle(a) - w).abs() < 1e-12, "{a}: {}", wrap_angle(a));
        }
    }
}
