//! Where phase 2 starts: the filter built from the rig's priors (phase 1 skipped), from phase
//! 1's hand-over ([`rig_model::handover::Handover`]) or its batch
//! ([`rig_model::handover::BatchHandover`]: every landmark with the joint covariance), a start
//! pose, and the re-seeding from the fixed-lag smoother's joint estimate
//! ([`rig_model::handover::JointEstimate`]) with the estimate it is restarted from.

use alloc::vec::Vec;

use nalgebra::{DMatrix, DVector, Matrix3};
use rig_model::camera::{Param, wrap_angle};
use rig_model::handover::{BatchHandover, Handover, JointEstimate};
use rig_model::{CameraParams, N_PARAMS, Pose2, Rig};

use crate::chi2::chi2_quantile;
use crate::error::Error;
use crate::errors::ErrorAxis;
use crate::filter::{Ekf, Settings, check_finite};
use crate::health::{DOF, HealthState};
use crate::kernels::Workspace;
use crate::landmarks::{LandmarkId, Placement, Slot};
use crate::motion::check_noise;
use crate::state::{CameraCovariance, LANDMARK_DIM, POSE_DIM, StateLayout};

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
        let errors = if settings.odometry_error_states || settings.odometry_velocity_states {
            ErrorAxis::with_memory(&rig.noise)
        } else {
            Vec::new()
        };
        let velocity_states = settings.odometry_velocity_states && !errors.is_empty();
        let v = if velocity_states { 3 } else { 0 };
        let layout = StateLayout {
            landmarks: 0,
            camera: m,
            errors: v + errors.len(),
        };
        let (n, c0) = (layout.dim(), layout.camera_start());
        let mut x = DVector::zeros(n);
        let mut p_mat = DMatrix::zeros(n, n);
        // The velocities start unknown (the first frame's odometry tells them), the
        // odometry's errors at their stationary spread, zero mean.
        for k in 0..v {
            let i = layout.errors_start() + k;
            p_mat[(i, i)] =
                crate::errors::VELOCITY_PRIOR_SIGMA * crate::errors::VELOCITY_PRIOR_SIGMA;
        }
        for (k, axis) in errors.iter().enumerate() {
            let (sigma, _) = axis.process(&rig.noise);
            let i = layout.errors_start() + v + k;
            p_mat[(i, i)] = sigma * sigma;
        }
        for (a, &pa) in estimated.iter().enumerate() {
            x[c0 + a] = start.camera.get(pa);
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
                p_mat[(c0 + a, c0 + b)] = v;
            }
        }
        if m > 0 {
            let block = p_mat.view((c0, c0), (m, m)).into_owned();
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
            errors,
            velocity_states,
            camera_base: start.camera,
            noise: rig.noise,
            pixel_noise: rig.pixel_noise(),
            lens: rig.lens,
            width: rig.width,
            height: rig.height,
            settings,
            gate,
            next_id: 0,
            health: HealthState::new(settings.nis_window),
            motion_covariance: Matrix3::zeros(),
            predicted_at: None,
            workspace: Workspace::default(),
            held: [false; N_PARAMS],
            local: None,
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
        if nl > settings.max_landmarks {
            return Err(Error::LandmarkCap {
                cap: settings.max_landmarks,
            });
        }
        let layout = StateLayout {
            landmarks: nl,
            camera: m,
            errors: ekf.layout().errors,
        };
        let (n, c0) = (layout.dim(), layout.camera_start());
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
            map.push(c0 + a);
        }
        map.extend(StateLayout::landmark(0)..c0);
        let mut x = DVector::zeros(n);
        x[0] = handover.pose.x;
        x[1] = handover.pose.y;
        x[2] = wrap_angle(handover.pose.theta);
        for (j, l) in handover.landmarks.iter().enumerate() {
            for a in 0..LANDMARK_DIM {
                x[StateLayout::landmark(j) + a] = l.position[a];
            }
        }
        for (a, &pa) in ekf.estimated.iter().enumerate() {
            x[c0 + a] = handover.camera.get(pa);
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
                let k = c0 + a;
                p[(k, k)] = sigma * sigma;
            }
        }
        // The odometry's errors as `Self::new` started them (the batch holds none).
        let e_new = layout.errors_start();
        let e_old = ekf.layout().errors_start();
        for k in 0..ekf.layout().errors {
            p[(e_new + k, e_new + k)] = ekf.p[(e_old + k, e_old + k)];
        }
        if p.iter().any(|v| !v.is_finite()) {
            return Err(Error::BadCameraCovariance);
        }
        ekf.x = x;
        ekf.p = p;
        let mut ids = Vec::with_capacity(nl);
        for (k, l) in handover.landmarks.iter().enumerate() {
            let id = LandmarkId(ekf.next_id);
            ekf.next_id += 1;
            // With `Settings::follow_points`, linearised where the batch's covariance was
            // taken, its estimate; else at the estimate throughout.
            let first = ekf
                .settings
                .follow_points
                .then(|| ekf.x.fixed_rows::<3>(StateLayout::landmark(k)).into_owned());
            ekf.landmarks.push(Slot {
                id,
                first,
                observations: l.observations,
                rejections_in_a_row: 0,
                settled: true,
                placement: None,
            });
            ids.push(id);
        }
        // Seen from the hand-over's pose, with the camera read once every slot is in (its rows
        // follow the landmarks').
        let camera = ekf.camera();
        for k in 0..ekf.landmarks.len() {
            let placement = ekf
                .landmarks
                .get(k)
                .and_then(|l| l.first)
                .and_then(|at| Placement::at(&camera, &handover.pose, &at));
            if let Some(slot) = ekf.landmarks.get_mut(k) {
                slot.placement = placement;
            }
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
        let layout = self.layout();
        let (n, c0) = (layout.dim(), layout.camera_start());
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
                x[StateLayout::landmark(k) + a] = l[a];
            }
        }
        for (a, &pa) in self.estimated.iter().enumerate() {
            x[c0 + a] = joint.camera.get(pa);
        }
        let e0 = layout.errors_start();
        for i in e0..n {
            x[i] = self.x[i];
        }
        if let Some(&value) = x.iter().find(|v| !v.is_finite()) {
            return Err(Error::NonFinite {
                what: "smoother state",
                value,
            });
        }
        // The odometry's errors are not in the joint estimate: their block stays, their
        // cross-covariances with the states set anew are dropped (a block-diagonal of two
        // covariances is one).
        let p = DMatrix::from_fn(n, n, |i, j| match (i >= e0, j >= e0) {
            (true, true) => self.cov(i, j),
            (false, false) => {
                let (bi, bj) = (map[i], map[j]);
                0.5 * (src[(bi, bj)] + src[(bj, bi)])
            }
            _ => 0.0,
        });
        if p.iter().any(|v| !v.is_finite()) || (0..n).any(|i| p[(i, i)] < 0.0) {
            return Err(Error::BadCameraCovariance);
        }
        self.local = None;
        self.x = x;
        self.p = p;
        self.predicted_at = None;
        self.relinearise_landmarks();
        Ok(())
    }

    /// The filter's joint estimate in the batch's layout (`[pose, estimated C, landmarks]`,
    /// landmarks in map order), with the landmark ids in that order: what the fixed-lag
    /// smoother is (re)started from (`selfcal::smoother::Smoother::restart_mapping`).
    pub fn joint(&self, t_us: u64) -> (JointEstimate, Vec<LandmarkId>) {
        let slots: Vec<usize> = (0..self.landmarks.len()).collect();
        (
            self.joint_over(t_us, &slots),
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
        self.predicted_at = None;
        for i in 0..POSE_DIM {
            for j in 0..POSE_DIM {
                self.p[(i, j)] = 0.5 * (covariance[(i, j)] + covariance[(j, i)]);
            }
        }
        Ok(())
    }
}
