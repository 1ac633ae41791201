//! The fixed-lag smoother over part of the map: the filter's marginal over the pose, the
//! camera and some landmarks ([`Ekf::joint_of`]), and the smoother's better estimate of that
//! marginal put back with the rest of the map carried along ([`Ekf::replace_marginal`]).
//!
//! The smoother re-linearises the last few seconds of pixels and odometry, which the filter
//! linearised once; its cost grows with the square of the landmarks it carries, so in a hall
//! it carries only the ones near the vehicle (docs/halls.md, "The smoother over part of the
//! map"). Both saw the same measurements since the smoother started from the filter, and
//! those measurements involve only the smoother's states `S`; what the filter knows of the
//! other landmarks `Q` given `S` (the conditional `p(Q | S)`) is therefore what it was, and
//! only the marginal of `S` changes. With `a, P_SS` the filter's marginal and `b, P'` the
//! smoother's, `K = P_QS P_SS^-1`:
//!
//! `x_Q += K (b - a)`, `P_QS' = K P'`, `P_QQ' = P_QQ - K (P_SS - P') K^T`,
//!
//! which is, over every state, `x += P_{.S} g` and `P -= P_{.S} M P_{S.}` with
//! `g = P_SS^-1 (b - a)` and `M = P_SS^-1 (P_SS - P') P_SS^-1`: an update whose gain has
//! the form of a Kalman update's, except that `M` need not be positive (the re-linearised
//! estimate may be less certain in some direction). It is applied the same way in the local
//! session (`crate::local`) when `S` is active, independent of the map's size; otherwise
//! over the dense covariance. With `S` every state, it is the smoother's joint itself.

use alloc::vec::Vec;

use nalgebra::{DMatrix, DVector, Vector3};
use rig_model::camera::wrap_angle;
use rig_model::handover::JointEstimate;

use crate::error::Error;
use crate::filter::Ekf;
use crate::kernels::{diagonal_change, gather_columns};
use crate::landmarks::LandmarkId;
use crate::linalg::{gemm, rank_update_lower, sym};
use crate::local::Place;
use crate::state::{LANDMARK_DIM, POSE_DIM, StateLayout};
use crate::update::{check_state, check_variances, correct_state};

impl Ekf {
    /// The filter's marginal over the pose, the estimated camera parameters and the landmarks
    /// `ids` (in that order), in the batch's layout (`[pose, estimated C, landmarks]`): what
    /// the fixed-lag smoother is restarted from when it carries part of the map. An id the
    /// filter does not hold is an [`Error::UnknownLandmark`].
    pub fn joint_of(&self, t_us: u64, ids: &[LandmarkId]) -> Result<JointEstimate, Error> {
        let slots = ids
            .iter()
            .map(|&id| self.slot(id).ok_or(Error::UnknownLandmark { id }))
            .collect::<Result<Vec<usize>, Error>>()?;
        Ok(self.joint_over(t_us, &slots))
    }

    /// The marginal over the pose, the estimated camera parameters and the landmarks in
    /// `slots` (in that order), in the batch's layout: [`Self::joint_of`] and, over every
    /// slot, `Ekf::joint`.
    pub(crate) fn joint_over(&self, t_us: u64, slots: &[usize]) -> JointEstimate {
        let m = self.estimated.len();
        let c0 = self.camera_offset();
        let mut rows: Vec<usize> = (0..POSE_DIM).collect();
        rows.extend(c0..c0 + m);
        let mut landmarks = Vec::with_capacity(slots.len());
        for &s in slots {
            let i = StateLayout::landmark(s);
            rows.extend(i..i + LANDMARK_DIM);
            landmarks.push(Vector3::new(self.x[i], self.x[i + 1], self.x[i + 2]));
        }
        let n = rows.len();
        let covariance = DMatrix::from_fn(n, n, |r, c| self.cov(rows[r], rows[c]));
        JointEstimate {
            t_us,
            pose: self.pose(),
            camera: self.camera(),
            estimated: self.estimated.clone(),
            landmarks,
            covariance,
        }
    }

    /// Replaces the filter's marginal over the joint estimate's states (the pose, the
    /// estimated camera parameters and the landmarks `index` maps to the estimate's: filter
    /// landmark id -> the estimate's landmark index) by the estimate, the other landmarks
    /// following through their cross-covariances (module docs). Landmarks of the estimate the
    /// filter no longer holds are left out (marginalised). Returns the landmarks replaced.
    ///
    /// # Errors
    ///
    /// A covariance of the wrong size or not finite, an estimated parameter the estimate does
    /// not hold, a filter marginal that cannot be inverted, or a result with a non-positive
    /// variance or a non-finite state: the filter is then left as it was.
    pub fn replace_marginal(
        &mut self,
        joint: &JointEstimate,
        index: impl Fn(LandmarkId) -> Option<usize>,
    ) -> Result<usize, Error> {
        let src = &joint.covariance;
        let mb = joint.estimated.len();
        let nb = joint.landmarks.len();
        if src.nrows() != POSE_DIM + mb + LANDMARK_DIM * nb
            || src.ncols() != src.nrows()
            || src.iter().any(|v| !v.is_finite())
        {
            return Err(Error::BadCameraCovariance);
        }
        // (filter state index, estimate index) for every state replaced, and the target.
        let mut pairs: Vec<(usize, usize)> = (0..POSE_DIM).map(|i| (i, i)).collect();
        let mut target: Vec<f64> = alloc::vec![joint.pose.x, joint.pose.y, joint.pose.theta];
        let c0 = self.camera_offset();
        for (a, pa) in self.estimated.iter().enumerate() {
            let b = joint
                .estimated
                .iter()
                .position(|pb| pb == pa)
                .ok_or(Error::MissingPrior { param: *pa })?;
            pairs.push((c0 + a, POSE_DIM + b));
            target.push(joint.camera.get(*pa));
        }
        let mut slots = Vec::new();
        for (s, slot) in self.landmarks.iter().enumerate() {
            let Some(j) = index(slot.id).filter(|&j| j < nb) else {
                continue;
            };
            slots.push(s);
            let Some(l) = joint.landmarks.get(j) else {
                continue;
            };
            for a in 0..LANDMARK_DIM {
                pairs.push((StateLayout::landmark(s) + a, POSE_DIM + mb + 3 * j + a));
                target.push(l[a]);
            }
        }
        if let Some(&value) = target.iter().find(|v| !v.is_finite()) {
            return Err(Error::NonFinite {
                what: "smoother state",
                value,
            });
        }
        // In the local session when the landmarks can be active there (the pose and the
        // camera always are), over the dense covariance otherwise.
        self.prepare_local(&slots);
        let s = pairs.len();
        let p_ss = DMatrix::from_fn(s, s, |r, c| self.cov(pairs[r].0, pairs[c].0));
        let p_new = DMatrix::from_fn(s, s, |r, c| {
            let (i, j) = (pairs[r].1, pairs[c].1);
            0.5 * (src[(i, j)] + src[(j, i)])
        });
        let p_inv = p_ss
            .clone()
            .cholesky()
            .ok_or(Error::BadCameraCovariance)?
            .inverse();
        let mut delta = DVector::from_fn(s, |r, _| target[r] - self.x[pairs[r].0]);
        delta[2] = wrap_angle(delta[2]);
        let g = &p_inv * delta;
        let mut m = &p_inv * (&p_ss - &p_new) * &p_inv;
        m = 0.5 * (&m + m.transpose());
        let states: Vec<usize> = pairs.iter().map(|p| p.0).collect();
        self.apply_marginal_form(&states, &g, &m)?;
        self.relinearise_landmarks();
        self.predicted_at = None;
        Ok(slots.len())
    }

    /// `x += P_{.S} g`, `P -= P_{.S} M P_{S.}` over the states `states` (`S`): in the open
    /// local session when every state of `S` is active there, over the dense covariance
    /// (the session settled first) otherwise. [`Self::replace_marginal`]'s step, and any
    /// linear update of a few states (`g = H^T S^-1 nu`, `M = H^T S^-1 H`; the odometry's
    /// measurement, `crate::errors`).
    pub(crate) fn apply_marginal_form(
        &mut self,
        states: &[usize],
        g: &DVector<f64>,
        m: &DMatrix<f64>,
    ) -> Result<(), Error> {
        let active: Option<Vec<usize>> = self.local.as_deref().and_then(|l| {
            states
                .iter()
                .map(|&i| match l.place.get(i) {
                    Some(&Place::Active(k)) => Some(k),
                    _ => None,
                })
                .collect()
        });
        match active {
            Some(ks) => self.replace_in_session(&ks, g, m),
            None => {
                self.settle();
                self.replace_dense(states, g, m)
            }
        }
    }

    /// [`Self::replace_marginal`] over the dense covariance: `x += C g`, `P -= C M C^T` with
    /// `C = P_{.S}`.
    fn replace_dense(
        &mut self,
        cols: &[usize],
        g: &DVector<f64>,
        m: &DMatrix<f64>,
    ) -> Result<(), Error> {
        let n = self.x.len();
        let s = cols.len();
        let mut c = alloc::vec![0.0; n * s];
        gather_columns(self.p.as_slice(), n, cols, &mut c);
        let mut dx = alloc::vec![0.0; n];
        gemm(&mut dx, n, 1, &c, g.as_slice(), s, 1.0, false);
        let mut cm = alloc::vec![0.0; n * s];
        gemm(&mut cm, n, s, &c, m.as_slice(), s, 1.0, false);
        let mut change = Vec::new();
        diagonal_change(n, &cm, &c, -1.0, &mut change);
        check_variances(self.p.as_slice(), n, &change)?;
        check_state(&self.x, &dx)?;
        rank_update_lower(self.p.as_mut_slice(), n, &cm, &c, s, -1.0);
        correct_state(&mut self.x, &dx);
        Ok(())
    }

    /// [`Self::replace_marginal`] in the open local session, `S` its active rows `ks`: with
    /// `A = P_{A S}` and `B = phi^T H^T` (`H` selecting `S`), `P_AA -= A M A^T`,
    /// `phi^T -= B M A^T`, `psi += B M B^T` and the passive states through `P0_BA0 B g`
    /// (`crate::local`'s module docs).
    fn replace_in_session(
        &mut self,
        ks: &[usize],
        g: &DVector<f64>,
        m: &DMatrix<f64>,
    ) -> Result<(), Error> {
        let Some(l) = self.local.as_deref() else {
            return Ok(());
        };
        let (na, na0, n0) = (l.n_active(), l.n_a0, l.n0);
        let s = ks.len();
        let paa = l.paa.as_slice();
        let mut a = alloc::vec![0.0; na * s];
        for (col, &k) in a.chunks_exact_mut(na).zip(ks) {
            for (r, v) in col.iter_mut().enumerate() {
                *v = sym(paa, na, r, k);
            }
        }
        let mut b = alloc::vec![0.0; na0 * s];
        for (col, &k) in b.chunks_exact_mut(na0).zip(ks) {
            if let Some(src) = l.phit.get(k * na0..(k + 1) * na0) {
                col.copy_from_slice(src);
            }
        }
        let mut dx_a = alloc::vec![0.0; na];
        gemm(&mut dx_a, na, 1, &a, g.as_slice(), s, 1.0, false);
        let mut bg = alloc::vec![0.0; na0];
        gemm(&mut bg, na0, 1, &b, g.as_slice(), s, 1.0, false);
        let mut dx_b = alloc::vec![0.0; n0];
        gemm(&mut dx_b, n0, 1, &l.g0, &bg, na0, 1.0, false);
        let mut am = alloc::vec![0.0; na * s];
        gemm(&mut am, na, s, &a, m.as_slice(), s, 1.0, false);
        let mut bm = alloc::vec![0.0; na0 * s];
        gemm(&mut bm, na0, s, &b, m.as_slice(), s, 1.0, false);
        let mut change = Vec::new();
        diagonal_change(na, &am, &a, -1.0, &mut change);
        check_variances(paa, na, &change)?;
        let dx = l.scatter(&dx_a, &dx_b);
        check_state(&self.x, &dx)?;
        if let Some(l) = self.local.as_deref_mut() {
            l.commit(&am, &a, &bm, &b, s);
        }
        correct_state(&mut self.x, &dx);
        Ok(())
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used)]
mod tests {
    use super::*;
    use crate::local::tests::drive;

    /// The landmarks within 1.5 m of the vehicle, horizontally.
    fn near(ekf: &Ekf) -> Vec<LandmarkId> {
        let pose = ekf.pose();
        ekf.landmarks()
            .filter(|l| libm::hypot(l.position.x - pose.x, l.position.y - pose.y) < 1.5)
            .map(|l| l.id)
            .collect()
    }

    /// The filter's state indices of a `joint_of` estimate's rows.
    fn rows(ekf: &Ekf, ids: &[LandmarkId]) -> Vec<usize> {
        let c0 = ekf.camera_offset();
        let mut rows: Vec<usize> = (0..POSE_DIM).collect();
        rows.extend(c0..c0 + ekf.estimated.len());
        for id in ids {
            let i = StateLayout::landmark(ekf.slot(*id).unwrap());
            rows.extend(i..i + LANDMARK_DIM);
        }
        rows
    }

    /// The closed form over the whole dense state (module docs), by nalgebra.
    fn reference(
        ekf: &Ekf,
        rows: &[usize],
        b: &DVector<f64>,
        p_new: &DMatrix<f64>,
    ) -> (DVector<f64>, DMatrix<f64>) {
        let x = ekf.state().clone();
        let p = ekf.covariance();
        let c = DMatrix::from_fn(p.nrows(), rows.len(), |i, k| p[(i, rows[k])]);
        let p_ss = DMatrix::from_fn(rows.len(), rows.len(), |r, k| p[(rows[r], rows[k])]);
        let a = DVector::from_fn(rows.len(), |r, _| x[rows[r]]);
        let inv = p_ss.clone().try_inverse().unwrap();
        let x_ref = &x + &c * &inv * (b - a);
        let p_ref = &p - &c * &inv * (&p_ss - p_new) * &inv * c.transpose();
        (x_ref, p_ref)
    }

    fn close(what: &str, a: &DMatrix<f64>, b: &DMatrix<f64>) {
        let scale = a.abs().max();
        let diff = (a - b).abs().max();
        assert!(diff <= 1e-8 * scale, "{what} differs by {diff} of {scale}");
    }

    /// A smoother's marginal over the pose, the camera and the landmarks near the vehicle,
    /// tighter (a direct measurement of them) and looser (every variance half again), put
    /// back over the dense covariance and in a local session: both give the closed form over
    /// the whole state, the far landmarks moved through their cross-covariances, and the
    /// session stays open.
    #[test]
    fn a_replaced_marginal_carries_the_rest_of_the_map_exactly() {
        for margin in [0.0, 1.0] {
            for looser in [false, true] {
                let mut ekf = drive(margin);
                let ids = near(&ekf);
                assert!(ids.len() >= 3 && ids.len() < 30, "{} near", ids.len());
                let mut joint = ekf.joint_of(5, &ids).unwrap();
                let rows = rows(&ekf, &ids);
                let s = rows.len();
                let p_ss = joint.covariance.clone();
                let a = DVector::from_fn(s, |r, _| ekf.state()[rows[r]]);
                // The target: a shifted mean and a covariance a measurement of S (noise R)
                // or a looser one gives.
                let shift = DVector::from_fn(s, |r, _| 0.3 * p_ss[(r, r)].sqrt());
                let p_new = if looser {
                    1.5 * &p_ss
                } else {
                    let r = DMatrix::from_diagonal(&p_ss.diagonal());
                    let k = &p_ss * (&p_ss + r).try_inverse().unwrap();
                    let p = (DMatrix::identity(s, s) - k) * &p_ss;
                    0.5 * (&p + p.transpose())
                };
                let b = &a + &shift;
                joint.pose = rig_model::Pose2::new(b[0], b[1], b[2]);
                for (k, p) in joint.estimated.clone().iter().enumerate() {
                    joint.camera.set(*p, b[POSE_DIM + k]);
                }
                let m = joint.estimated.len();
                for (j, l) in joint.landmarks.iter_mut().enumerate() {
                    let o = POSE_DIM + m + 3 * j;
                    *l = Vector3::new(b[o], b[o + 1], b[o + 2]);
                }
                joint.covariance = p_new.clone();
                let (x_ref, p_ref) = reference(&ekf, &rows, &b, &p_new);
                let was_local = ekf.is_local();
                let replaced = ekf
                    .replace_marginal(&joint, |id| ids.iter().position(|i| *i == id))
                    .unwrap();
                assert_eq!(replaced, ids.len());
                assert_eq!(ekf.is_local(), was_local, "margin {margin}");
                assert_eq!(was_local, margin > 0.0);
                let x = DMatrix::from_column_slice(x_ref.len(), 1, ekf.state().as_slice());
                close(
                    "state",
                    &DMatrix::from_column_slice(x.nrows(), 1, x_ref.as_slice()),
                    &x,
                );
                close("covariance", &p_ref, &ekf.covariance());
                // The far landmarks moved too (they are correlated with the pose and the
                // camera).
                let before = drive(margin);
                let moved = ekf
                    .landmarks()
                    .filter(|l| !ids.contains(&l.id))
                    .map(|l| {
                        let i = StateLayout::landmark(before.slot(l.id).unwrap());
                        (l.position - before.state().fixed_rows::<3>(i)).norm()
                    })
                    .fold(0.0, f64::max);
                assert!(moved > 1e-4, "far landmarks moved {moved} m at most");
            }
        }
    }

    /// With every state in it, the replaced marginal is the smoother's joint itself.
    #[test]
    fn a_marginal_over_every_state_is_the_joint() {
        let mut ekf = drive(0.0);
        let ids: Vec<LandmarkId> = ekf.landmarks().map(|l| l.id).collect();
        let mut joint = ekf.joint_of(5, &ids).unwrap();
        joint.covariance *= 0.8;
        joint.pose.x += 0.01;
        joint.landmarks[3].z -= 0.02;
        let mut set = ekf.clone();
        let index = |id: LandmarkId| ids.iter().position(|i| *i == id);
        set.set_joint(&joint, index).unwrap();
        ekf.replace_marginal(&joint, index).unwrap();
        close("covariance", &set.covariance(), &ekf.covariance());
        let dx = (set.state() - ekf.state()).abs().max();
        assert!(dx < 1e-9, "state differs by {dx}");
    }
}
