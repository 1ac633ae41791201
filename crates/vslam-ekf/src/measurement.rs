//! Eq. (8), the measurement Jacobian: the four measurements `(uL, vL, uR, vR)` of one landmark
//! depend on the pose, that landmark and the estimated camera parameters only, so its rows of
//! `H` are non-zero in at most `6 + m` columns ([`measurement_jacobian_columns`]). The update
//! never forms `H`; the dense one ([`Ekf::measurement_jacobian`]) is for tests and tools.

use alloc::vec::Vec;

use nalgebra::{DMatrix, Matrix4, Vector3};
use rig_model::camera::Param;
use rig_model::rig::{Jac4x3, RigError};
use rig_model::{CameraParams, Measurement, N_PARAMS, Pose2, project_with_jacobians};

use crate::error::Error;
use crate::filter::Ekf;
use crate::kernels::Obs;
use crate::landmarks::LandmarkId;
use crate::state::{LANDMARK_DIM, POSE_DIM, StateLayout};

/// Most non-zero columns of one landmark's rows of `H`: the pose, the landmark, every camera
/// parameter.
pub const MAX_H_COLUMNS: usize = POSE_DIM + LANDMARK_DIM + N_PARAMS;

/// One landmark's four rows of `H` (eq. (8)) as their non-zero columns.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HColumns {
    /// State indices of the non-zero columns, increasing: the pose's three, the landmark's
    /// three, the estimated camera parameters' (see [`measurement_jacobian_columns`]).
    pub cols: [usize; MAX_H_COLUMNS],
    /// `h[r][t]`: row `r` (`uL, vL, uR, vR`) of `H` at state index `cols[t]`.
    pub h: [[f64; MAX_H_COLUMNS]; 4],
    /// Columns in use.
    pub len: usize,
}

/// Eq. (8): the measurement Jacobian `H = dh/dx` of the landmark in state-order slot `s`, at
/// `pose`, `landmark` and `camera`, with the predicted measurement `h(x)`. Its rows are
/// `[H_pose, 0, ..., H_landmark, 0, ..., H_camera]`: the pose's three columns, the
/// landmark's own three (at [`StateLayout::landmark`]) and one per estimated parameter (from
/// [`StateLayout::camera_start`], in `estimated` order) except the vehicle's, on which the
/// projection does not depend. The blocks are the rig model's analytic projection Jacobians
/// ([`rig_model::project_with_jacobians`]).
pub fn measurement_jacobian_columns(
    layout: &StateLayout,
    s: usize,
    estimated: &[Param],
    camera: &CameraParams,
    pose: &Pose2,
    landmark: &Vector3<f64>,
) -> Result<(Measurement, HColumns), RigError> {
    let (predicted, jac) = project_with_jacobians(camera, pose, landmark)?;
    let mut h = HColumns {
        cols: [0; MAX_H_COLUMNS],
        h: [[0.0; MAX_H_COLUMNS]; 4],
        len: 0,
    };
    let mut push = |col: usize, column: nalgebra::Vector4<f64>| {
        if let Some(slot) = h.cols.get_mut(h.len) {
            *slot = col;
            for (r, row) in h.h.iter_mut().enumerate() {
                row[h.len] = column[r];
            }
            h.len += 1;
        }
    };
    let blocks: [(usize, &Jac4x3); 2] = [(0, &jac.pose), (StateLayout::landmark(s), &jac.landmark)];
    for (start, block) in blocks {
        for k in 0..3 {
            push(start + k, block.column(k).into_owned());
        }
    }
    let c0 = layout.camera_start();
    for (k, p) in estimated.iter().enumerate() {
        // The projection does not depend on the vehicle's parameters: no column.
        if !p.is_vehicle() {
            push(c0 + k, jac.camera.column(p.index()).into_owned());
        }
    }
    Ok((predicted, h))
}

impl Ekf {
    /// Linearises the observation of the landmark in slot `s` at the current estimate
    /// (eq. (8)): the predicted measurement and the non-zero columns of `H` (the innovation
    /// left zero).
    pub(crate) fn observation_model(
        &self,
        s: usize,
        camera: &CameraParams,
        pose: &Pose2,
    ) -> Result<(Measurement, Obs), Error> {
        self.observation_model_with(s, camera, pose, true)
    }

    /// [`Self::observation_model`]; with `fej` false `H` is at the current estimate throughout
    /// (the derivative itself).
    pub(crate) fn observation_model_with(
        &self,
        s: usize,
        camera: &CameraParams,
        pose: &Pose2,
        fej: bool,
    ) -> Result<(Measurement, Obs), Error> {
        let (predicted, h) = self.observation_columns(s, camera, pose, fej)?;
        Ok((predicted, Obs::new(&h)))
    }

    /// The iterated update's linearisation (`Ekf::update` on an uncertain pose): `H` at the
    /// current estimate, but for the heading's column, which comes from the observability
    /// constraint at the landmark's linearisation point (the OC-EKF of Huang, Mourikis and
    /// Roumeliotis, IEEE T-RO 2010). A rotation of the whole world about its origin, `dp = J
    /// p`, `dtheta = 1`, `dL = J L` with `J` the planar quarter turn, changes no prediction,
    /// `H_p J p + H_theta + H_L J L = 0`; `h` depends on `L - p` horizontally, so `H_theta =
    /// H_L J (p - L)`, with `L` where the filter's covariance ties the landmark to the heading.
    /// The other columns at the estimate keep Gauss-Newton's steps right where a landmark's
    /// first estimate is far from it (a linearisation point that had settled 0.25 m off made
    /// the closure of hall 11's loop out of a dark stretch undo itself in the next frame);
    /// the whole of `H` at the estimate gave the heading information from lamps seen for the
    /// first time (docs/vehicle.md, "Dark stretches").
    pub(crate) fn observation_model_constrained(
        &self,
        s: usize,
        camera: &CameraParams,
        pose: &Pose2,
        anchor: &Pose2,
    ) -> Result<(Measurement, Obs), Error> {
        let (predicted, mut h) = self.observation_columns(s, camera, pose, false)?;
        if let Some(first) = self.landmarks.get(s).and_then(|l| l.first) {
            let (dx, dy) = (anchor.x - first.x, anchor.y - first.y);
            // Columns 0..3 are the pose's (x, y, heading), 3..6 the landmark's.
            for row in &mut h.h {
                row[2] = -dy * row[3] + dx * row[4];
            }
        }
        Ok((predicted, Obs::new(&h)))
    }

    /// The predicted measurement and `H`'s non-zero columns ([`Self::observation_model_with`]).
    fn observation_columns(
        &self,
        s: usize,
        camera: &CameraParams,
        pose: &Pose2,
        fej: bool,
    ) -> Result<(Measurement, HColumns), Error> {
        let id = self.landmarks.get(s).map_or(LandmarkId(u64::MAX), |l| l.id);
        let landmark = self
            .x
            .fixed_rows::<3>(StateLayout::landmark(s))
            .into_owned();
        let (predicted, mut h) = measurement_jacobian_columns(
            &self.layout(),
            s,
            &self.estimated,
            camera,
            pose,
            &landmark,
        )
        .map_err(|source| Error::Projection { id, source })?;
        // `H` at the landmark's linearisation point (`crate::FEJ_SETTLE_SIGMA_M`); the
        // innovation stays the current estimate's.
        if fej
            && let Some(first) = self.landmarks.get(s).and_then(|l| l.first)
            && let Ok((_, at_first)) = measurement_jacobian_columns(
                &self.layout(),
                s,
                &self.estimated,
                camera,
                pose,
                &first,
            )
        {
            // The pose's and the landmark's columns only; the camera's at the estimate.
            for (row, first_row) in h.h.iter_mut().zip(at_first.h.iter()) {
                for (v, f) in row
                    .iter_mut()
                    .zip(first_row.iter())
                    .take(POSE_DIM + LANDMARK_DIM)
                {
                    *v = *f;
                }
            }
        }
        Ok((predicted, h))
    }

    /// The predicted measurement of a landmark and its innovation covariance
    /// `S = H P H^T + R` (4x4), for association and map matching.
    pub fn predict_measurement(
        &self,
        id: LandmarkId,
    ) -> Result<(Measurement, Matrix4<f64>), Error> {
        self.predict_measurement_with(id, false)
    }

    /// [`Self::predict_measurement`] with an upper bound of `S` in the positive
    /// semi-definite order that costs `O(n)` instead of `O(n^2)` for a landmark passive in
    /// an open local session (its block as the session found it): a gate with it never
    /// leaves out what the exact one takes.
    pub fn predict_measurement_bound(
        &self,
        id: LandmarkId,
    ) -> Result<(Measurement, Matrix4<f64>), Error> {
        self.predict_measurement_with(id, true)
    }

    /// [`Self::predict_measurement`], with `upper` an upper bound of `S` that costs less
    /// while a local session is open ([`Self::innovation_covariance_with`]).
    fn predict_measurement_with(
        &self,
        id: LandmarkId,
        upper: bool,
    ) -> Result<(Measurement, Matrix4<f64>), Error> {
        let s = self.slot(id).ok_or(Error::UnknownLandmark { id })?;
        // The derivative at the estimate: where the landmark is predicted and how uncertainly
        // (the first-estimates Jacobians are the update's, for its information), but for the
        // heading's column, constrained as the iterated update's: where the landmark's
        // estimate has moved from the point its covariance ties it to the heading at (lamps
        // mapped out of a dark stretch, half a metre in depth), the derivative's heading column
        // measured the heading's spread with a lever the covariance does not have, and map
        // matching's gates on hall 11 after the stretch (`hall_mc 4 11 --lens radtan
        // --odometry-tau 0.6`) were off: trajectory 528 mm against 204 mm with it
        // (docs/vehicle.md, "Dark stretches").
        let (z, mut m) =
            self.observation_model_constrained(s, &self.camera(), &self.pose(), &self.pose())?;
        m.r = self.measurement_variances(&z);
        Ok((z, self.innovation_covariance_with(&m, upper)))
    }

    /// The predicted measurement of a landmark and the full `4 x n` Jacobian `H` of the
    /// measurement with respect to the state (eq. (8)), dense. For tests and tools: the update
    /// never forms it.
    pub fn measurement_jacobian(
        &self,
        id: LandmarkId,
    ) -> Result<(Measurement, DMatrix<f64>), Error> {
        self.dense_jacobian(id, false)
    }

    /// The predicted measurement of a landmark and the `4 x n` matrix `H` the update uses for
    /// it, dense: [`Self::measurement_jacobian`] but for the pose's and the landmark's
    /// columns, which are taken at the landmark's linearisation point where the update uses
    /// first-estimates Jacobians (`crate::FEJ_SETTLE_SIGMA_M`). For tests and tools.
    pub fn update_jacobian(&self, id: LandmarkId) -> Result<(Measurement, DMatrix<f64>), Error> {
        self.dense_jacobian(id, true)
    }

    /// The predicted measurement of a landmark and the `4 x n` matrix `H` that
    /// [`Self::predict_measurement`]'s innovation covariance is formed with, dense:
    /// [`Self::measurement_jacobian`] but for the heading's column, from the observability
    /// constraint at the landmark's linearisation point (as the iterated update's). For tests
    /// and tools.
    pub fn prediction_jacobian(
        &self,
        id: LandmarkId,
    ) -> Result<(Measurement, DMatrix<f64>), Error> {
        let s = self.slot(id).ok_or(Error::UnknownLandmark { id })?;
        let (z, m) =
            self.observation_model_constrained(s, &self.camera(), &self.pose(), &self.pose())?;
        Ok((z, self.dense_of(&m)))
    }

    /// A landmark's predicted measurement and its `H` as a dense `4 x n` matrix, at the
    /// estimate or (`fej`) as the update takes it ([`Self::observation_model_with`]).
    fn dense_jacobian(
        &self,
        id: LandmarkId,
        fej: bool,
    ) -> Result<(Measurement, DMatrix<f64>), Error> {
        let s = self.slot(id).ok_or(Error::UnknownLandmark { id })?;
        let (z, m) = self.observation_model_with(s, &self.camera(), &self.pose(), fej)?;
        Ok((z, self.dense_of(&m)))
    }

    /// An observation's non-zero columns as a dense `4 x n` matrix.
    fn dense_of(&self, m: &Obs) -> DMatrix<f64> {
        let mut h = DMatrix::zeros(4, self.x.len());
        for (t, &c) in m.cols.iter().enumerate().take(m.q) {
            for r in 0..4 {
                h[(r, c)] = m.h[r][t];
            }
        }
        h
    }

    /// The landmarks not among `in_view` (the caller's [`Ekf::visible_landmarks`], computed
    /// once a frame) whose predicted pixels, left and
    /// right, lie within `k_sigma` standard deviations of the prediction (the innovation
    /// covariance's variances) of the rectified image, with the prediction and its innovation
    /// covariance: the landmarks a feature in the image might be when the pose is uncertain.
    /// Map matching needs them to call a match unique: with the pose metres off, a lamp's own
    /// landmark may be predicted outside the image while its neighbour's is inside (issue 35,
    /// `hall-loop.toml`). Landmarks predicted more than an image's size outside are skipped
    /// before their covariance is formed.
    pub fn landmarks_near_view(
        &self,
        k_sigma: f64,
        in_view: &[(LandmarkId, Measurement)],
    ) -> Vec<(LandmarkId, Measurement, Matrix4<f64>)> {
        let projector = rig_model::Projector::new(&self.camera(), &self.pose());
        let (w, h) = (f64::from(self.width), f64::from(self.height));
        let mut out = Vec::new();
        for (s, slot) in self.landmarks.iter().enumerate() {
            if in_view.iter().any(|(id, _)| *id == slot.id) {
                continue;
            }
            let l = self
                .x
                .fixed_rows::<3>(StateLayout::landmark(s))
                .into_owned();
            let Ok(z) = projector.project(&l) else {
                continue;
            };
            let coarse = |u: f64, v: f64| u > -w && u < 2.0 * w && v > -h && v < 2.0 * h;
            if !(coarse(z[0], z[1]) && coarse(z[2], z[3])) {
                continue;
            }
            let near = |z: &Measurement, cov: &Matrix4<f64>| {
                let near = |u: usize, v: usize| {
                    let su = k_sigma * libm::sqrt(cov[(u, u)].max(0.0));
                    let sv = k_sigma * libm::sqrt(cov[(v, v)].max(0.0));
                    z[u] + su >= 0.0 && z[u] - su < w && z[v] + sv >= 0.0 && z[v] - sv < h
                };
                near(0, 1) && near(2, 3)
            };
            // While a local session is open, a passive landmark is first tested with an
            // upper bound of its covariance, which costs less, then exactly.
            if self.local.is_some()
                && !self
                    .predict_measurement_with(slot.id, true)
                    .is_ok_and(|(z, cov)| near(&z, &cov))
            {
                continue;
            }
            let Ok((z, cov)) = self.predict_measurement(slot.id) else {
                continue;
            };
            if near(&z, &cov) {
                out.push((slot.id, z, cov));
            }
        }
        out
    }

    /// The landmarks whose predicted measurement falls inside both images, with it. With
    /// raw lenses ([`rig_model::Rig::lens`]) the images are the raw ones: the prediction is
    /// mapped through each lens ([`rig_model::lens::Lens::unrectify`]) and tested against the
    /// raw image, whose rectified view is not the rectified rectangle (a barrel lens sees past
    /// its corners, a fisheye far past its edges; issue 35), and only within the field of use
    /// ([`crate::Settings::max_off_axis_deg`]), where the navigator takes features.
    pub fn visible_landmarks(&self) -> Vec<(LandmarkId, Measurement)> {
        self.landmarks_in_view(false)
    }

    /// [`Ekf::visible_landmarks`] and those predicted in the far band
    /// ([`crate::Settings::far_max_noise_gain`]): the landmarks a feature may be of.
    pub fn landmarks_reached(&self) -> Vec<(LandmarkId, Measurement)> {
        self.landmarks_in_view(true)
    }

    fn landmarks_in_view(&self, far: bool) -> Vec<(LandmarkId, Measurement)> {
        self.landmarks_in_view_from(&self.pose(), far)
            .into_iter()
            .filter_map(|(s, z)| self.landmarks.get(s).map(|l| (l.id, z)))
            .collect()
    }

    /// The slots of the landmarks predicted in the field of use (with `far`, also in the far
    /// band) from `pose`, with their predictions.
    pub(crate) fn landmarks_in_view_from(
        &self,
        pose: &Pose2,
        far: bool,
    ) -> Vec<(usize, Measurement)> {
        let view = self.view();
        let projector = rig_model::Projector::new(&view.0, pose);
        (0..self.landmarks.len())
            .filter_map(|s| {
                let z = self.predicted_from(&projector, s)?;
                self.in_view(&view, &z, far).then_some((s, z))
            })
            .collect()
    }

    /// The camera and its field, for [`Ekf::in_use_from`].
    pub(crate) fn view(&self) -> (CameraParams, rig_model::lens::StereoField) {
        (self.camera(), self.stereo_field())
    }

    /// Whether landmark `s` is predicted in the field of use through `projector` (the
    /// camera of `view`, from [`Ekf::view`], at some pose).
    pub(crate) fn in_use_from(
        &self,
        view: &(CameraParams, rig_model::lens::StereoField),
        projector: &rig_model::Projector,
        s: usize,
    ) -> bool {
        self.predicted_from(projector, s)
            .is_some_and(|z| self.in_view(view, &z, false))
    }

    /// Landmark `s` projected, `None` when it cannot be.
    fn predicted_from(&self, projector: &rig_model::Projector, s: usize) -> Option<Measurement> {
        if s >= self.landmarks.len() {
            return None;
        }
        let l = self
            .x
            .fixed_rows::<3>(StateLayout::landmark(s))
            .into_owned();
        projector.project(&l).ok()
    }

    /// Whether a prediction is in the field of use (with `far`, also the far band), inside
    /// both images of the lens.
    pub(crate) fn in_view(
        &self,
        (camera, field): &(CameraParams, rig_model::lens::StereoField),
        z: &Measurement,
        far: bool,
    ) -> bool {
        let (w, h) = (f64::from(self.width), f64::from(self.height));
        let inside_image = |u: f64, v: f64| u >= 0.0 && u < w && v >= 0.0 && v < h;
        match &self.lens {
            None => inside_image(z[0], z[1]) && inside_image(z[2], z[3]),
            Some(lens) => {
                // The cheap tests first: the gains are the lens's Jacobians.
                let inner = field.inner_contains(z);
                if !(inner || field.outer_contains(z))
                    || !lens.sees(z, camera.f, camera.cx, camera.cy, w, h)
                {
                    return false;
                }
                inner || {
                    let gains = self.pixel_noise.gains(z).into();
                    if far {
                        field.reaches(z, &gains)
                    } else {
                        field.uses(z, &gains)
                    }
                }
            }
        }
    }
}
