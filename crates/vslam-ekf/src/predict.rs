//! Eq. (4)-(5), the prediction: the pose moved by the odometry's motion ([`Increment::apply`],
//! eq. (4)) and the covariance propagated through it ([`predict_covariance`], eq. (5)). Only
//! the pose rows and columns of `P` change: O(n), never an `n x n` product. The motion and its
//! noise come from [`crate::motion`].

use alloc::vec::Vec;

use nalgebra::{DMatrix, Matrix3, Matrix3x4, RowVector3, Vector3};
use rig_model::Pose2;
use rig_model::camera::wrap_angle;
use rig_model::odometry::OdomSample;

use crate::error::Error;
use crate::filter::{Ekf, check_finite};
use crate::linalg::sym;
use crate::motion::{Increment, compose_jacobian_first, compose_jacobian_second};
use crate::state::{POSE_DIM, at};

impl Increment {
    /// Eq. (4): the pose predicted from `pose`, `pose' = pose (+) motion`, with what eq. (5)
    /// propagates the covariance with: the Jacobian `F = d pose' / d pose` and the process
    /// noise `Q = Rz(theta) Cov(motion) Rz(theta)^T` it adds (the angle untouched).
    pub fn apply(&self, pose: &Pose2) -> (Pose2, Matrix3<f64>, Matrix3<f64>) {
        let f = compose_jacobian_first(pose.theta, &self.motion);
        let g = compose_jacobian_second(pose.theta);
        (
            self.motion.apply(pose),
            f,
            g * self.covariance * g.transpose(),
        )
    }
}

/// Eq. (5): the covariance prediction, on the lower triangle of the `n x n` buffer `p`:
/// `P_rr = F P_rr F^T + F P_rV G^T + G P_Vr F^T + G P_VV G^T + Q` and
/// `P_xr = P_xr F^T + P_xV G^T` for every other state `x`, with `F` and `Q` from eq. (4) and
/// `g` the columns of `G = d pose' / dV` for the estimated vehicle parameters `V`, as
/// `(state index, column)` (empty for a motion that does not depend on them). Only the pose
/// rows and columns change: O(n).
pub fn predict_covariance(
    p: &mut DMatrix<f64>,
    f: &Matrix3<f64>,
    q: &Matrix3<f64>,
    g: &[(usize, Vector3<f64>)],
) {
    let n = p.nrows();
    // F = [[1, 0, a], [0, 1, b], [0, 0, 1]].
    let (fa, fb) = (f[(0, 2)], f[(1, 2)]);
    let buf = p.as_mut_slice();
    let prr = Matrix3::from_fn(|r, c| sym(buf, n, r, c));
    // P_Vr before the pose columns change (row c >= 3 of columns 0..3).
    let pvr: Vec<RowVector3<f64>> = g
        .iter()
        .map(|(c, _)| RowVector3::new(buf[at(n, *c, 0)], buf[at(n, *c, 1)], buf[at(n, *c, 2)]))
        .collect();
    let mut new_rr = f * prr * f.transpose() + q;
    for (a, (ca, ga)) in g.iter().enumerate() {
        let cross = f * pvr[a].transpose() * ga.transpose();
        new_rr += cross + cross.transpose();
        for (cb, gb) in g {
            let pab = buf[at(n, (*ca).max(*cb), (*ca).min(*cb))];
            new_rr += ga * gb.transpose() * pab;
        }
    }
    let new_rr = 0.5 * (new_rr + new_rr.transpose());
    // P_xr = P_rx^T lies in columns 0..3 below the pose block (the lower triangle).
    for j in POSE_DIM..n {
        let (p0, p1, p2) = (buf[at(n, j, 0)], buf[at(n, j, 1)], buf[at(n, j, 2)]);
        let mut row = RowVector3::new(p0 + fa * p2, p1 + fb * p2, p2);
        for (c, gc) in g {
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
}

impl Ekf {
    /// Eq. (4)-(5): predicts with the robot-frame velocities `(vx, vy, vtheta)` held for
    /// `dt_s` seconds (one odometry sample).
    pub fn predict(&mut self, vx: f64, vy: f64, vtheta: f64, dt_s: f64) -> Result<(), Error> {
        let inc = Increment::from_velocities(vx, vy, vtheta, dt_s, &self.noise)?;
        self.predict_increment(&inc)
    }

    /// Eq. (4)-(5) over `[t0_us, t1_us]` with the odometry samples (sorted by time), each held
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

    /// Eq. (4)-(5) with a motion and its covariance: `pose' = pose (+) motion`,
    /// `P_rr = F P_rr F^T + Q`, `P_rx = F P_rx`. Only the pose rows and columns change: O(n).
    pub fn predict_increment(&mut self, inc: &Increment) -> Result<(), Error> {
        self.predict_increment_vehicle(inc, &Matrix3x4::zeros())
    }

    /// [`Self::predict_increment`] for a motion that depends on the vehicle's parameters `V`
    /// (vehicle-interfaces.md 1.2): `vehicle_jacobian` is `d motion / dV` at the filter's `V`
    /// ([`rig_model::Param::VEHICLE`] order; the motion was integrated with it). With
    /// `G = d pose' / dV` for the estimated ones,
    /// `P_rr = F P_rr F^T + F P_rV G^T + G P_Vr F^T + G P_VV G^T + Q` and
    /// `P_rx = F P_rx + G P_Vx` ([`predict_covariance`]): still only the pose rows and columns
    /// change, O(n).
    pub fn predict_increment_vehicle(
        &mut self,
        inc: &Increment,
        vehicle_jacobian: &Matrix3x4<f64>,
    ) -> Result<(), Error> {
        self.predict_with_columns(inc, vehicle_jacobian, &[])
    }

    /// [`Self::predict_increment_vehicle`] with more columns of `d motion / d x`: `(state
    /// index, column in the robot frame at the interval's start)`, the odometry's error states
    /// (`crate::errors`).
    pub(crate) fn predict_with_columns(
        &mut self,
        inc: &Increment,
        vehicle_jacobian: &Matrix3x4<f64>,
        extra: &[(usize, Vector3<f64>)],
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
        let (pose, mut f, q) = inc.apply(&self.pose());
        // `F`'s heading column is `J (p' - p)`; with `Settings::first_estimate_pose` on a lost
        // pose (with `Settings::first_estimate_prediction` on one whose heading is known to
        // its bound), `p` is where the previous prediction left it, so that the covariance's
        // turn of the world goes to `J p'` whatever the update in between did to the estimate.
        if let Some(a) = self.predicted_at.filter(|_| {
            (self.settings.first_estimate_prediction
                && self.cov(2, 2)
                    < self.settings.first_estimate_prediction_heading_sigma_rad
                        * self.settings.first_estimate_prediction_heading_sigma_rad)
                || (self.settings.first_estimate_pose && self.pose_lost())
        }) {
            f[(0, 2)] = -(pose.y - a[1]);
            f[(1, 2)] = pose.x - a[0];
        }
        self.predicted_at = Some([pose.x, pose.y]);
        // G's columns for the estimated vehicle parameters: (state index, d pose' / dV_k).
        let rot = compose_jacobian_second(theta);
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
            .chain(extra.iter().map(|(i, col)| (*i, rot * col)))
            .filter(|(_, col)| col.iter().any(|v| *v != 0.0))
            .collect();
        self.x[0] = pose.x;
        self.x[1] = pose.y;
        self.x[2] = wrap_angle(pose.theta);
        match self.local.as_deref_mut() {
            None => predict_covariance(&mut self.p, &f, &q, &g),
            Some(l) => {
                // P_AA as the dense P (the camera block is active), and phi's pose rows by
                // the same transform as P_xr's: F phi_r + sum_c g_c phi_c.
                let g_local: Vec<(usize, Vector3<f64>)> = g
                    .iter()
                    .filter_map(|(c, v)| match l.place.get(*c) {
                        Some(&crate::local::Place::Active(k)) => Some((k, *v)),
                        _ => None,
                    })
                    .collect();
                predict_covariance(&mut l.paa, &f, &q, &g_local);
                let na0 = l.n_a0;
                let (fa, fb) = (f[(0, 2)], f[(1, 2)]);
                for t in 0..na0 {
                    let at_col = |c: usize| l.phit.get(c * na0 + t).copied().unwrap_or(0.0);
                    let (p0, p1, p2) = (at_col(0), at_col(1), at_col(2));
                    let mut row = RowVector3::new(p0 + fa * p2, p1 + fb * p2, p2);
                    for (c, gc) in &g_local {
                        row += gc.transpose() * at_col(*c);
                    }
                    for (r, v) in row.iter().enumerate() {
                        if let Some(dst) = l.phit.get_mut(r * na0 + t) {
                            *dst = *v;
                        }
                    }
                }
            }
        }
        self.motion_covariance = f * self.motion_covariance * f.transpose() + q;
        Ok(())
    }
}
