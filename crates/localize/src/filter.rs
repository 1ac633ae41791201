//! The localiser's filter: a Schmidt (consider) Kalman filter whose state is the pose and the
//! vehicle's parameters `V`, with the map's lamps considered, not estimated.
//!
//! State `x = [X, Y, theta, odom_scale, odom_yaw_scale, odom_yaw_bias, time_offset]` (7) with
//! covariance `P`. A lamp `j` of the map enters each update with its covariance `P_jj`; the
//! filter also keeps the cross-covariance `P_xj` of the state with the lamps it has updated
//! from (the Schmidt filter's bookkeeping), so that seeing the same lamp again does not count
//! its map error as new information: without it the pose sigma shrinks below the map's own
//! uncertainty (the frame-after-frame observations of one lamp are not independent of its
//! map error).
//!
//! The lamps' cross-covariances *with each other* (the mapping run's correlations) are not
//! used: the map holds each lamp's marginal, which treats the lamps' errors as independent.
//! That overstates the uncertainty of the lamps' relative geometry (a SLAM map knows the
//! lamps better relative to each other than absolutely), so the pose sigma errs on the large
//! side. The cross-covariances `P_xj` are kept for the lamps seen in the last
//! [`crate::LocalizerSettings::consider_memory_us`] (at most [`MAX_CONSIDERED`] lamps, the
//! oldest dropped): a lamp out of view that long has its correlation with the pose diluted by
//! the odometry's noise since. The cost of an update is then bounded, independent of the map.
//!
//! Equations, with `H_x` (4 x 7: the pose block of eq. (8), zero for `V`) and `H_j` (4 x 3):
//!
//! - predict: `x' = f(x)`, `P' = F P F^T + Q`, `P_xj' = F P_xj` (`F` with the pose's Jacobian
//!   and `d pose' / dV`; `Q` the odometry's noise);
//! - update with lamp `j`: `S = H_x P H_x^T + H_x P_xj H_j^T + H_j P_jx H_x^T + H_j P_jj H_j^T + R`,
//!   `K = (P H_x^T + P_xj H_j^T) S^-1`, `x += K (z - h)`, `P -= K S K^T`,
//!   `P_xl -= K (H_x P_xl + H_j P_jl)` for every considered lamp `l` (`P_jl = P_jj` if `l = j`,
//!   else 0); the lamps never change.

use alloc::vec::Vec;

use nalgebra::{Matrix3, Matrix4, SMatrix, SVector, Vector3, Vector4};
use rig_model::camera::{CameraParams, Pose2, Vehicle, wrap_angle};
use rig_model::project_with_jacobians;
use vslam_ekf::Increment;

use crate::map::MapLamp;

/// Size of the state: pose (3) and `V` (4).
pub const STATE_DIM: usize = 7;

/// Most lamps whose cross-covariance with the state is kept.
pub const MAX_CONSIDERED: usize = 48;

/// The state vector.
pub type State = SVector<f64, STATE_DIM>;
/// The state covariance.
pub type StateCov = SMatrix<f64, STATE_DIM, STATE_DIM>;
/// Cross-covariance of the state with one lamp.
pub type CrossCov = SMatrix<f64, STATE_DIM, 3>;

/// A predicted measurement of a lamp, with what the update needs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Prediction {
    /// The lamp (index into the map).
    pub lamp: u32,
    /// `(uL, vL, uR, vR)` predicted, pixels.
    pub z: Vector4<f64>,
    /// Innovation covariance `S`, px^2.
    pub s: Matrix4<f64>,
    /// `d h / d pose` (4 x 3).
    pub h_pose: SMatrix<f64, 4, 3>,
    /// `d h / d lamp` (4 x 3).
    pub h_lamp: SMatrix<f64, 4, 3>,
}

/// The Schmidt filter over pose and `V`.
#[derive(Debug, Clone)]
pub struct PoseFilter {
    x: State,
    p: StateCov,
    /// `(lamp index, P_xj, last time it was updated from, microseconds)`.
    considered: Vec<(u32, CrossCov, u64)>,
    /// Random walk of `V` per second of motion (variance), in [`Vehicle::to_array`] order.
    vehicle_walk: [f64; 4],
}

impl PoseFilter {
    /// A filter at `pose` with covariance `pose_cov` and the vehicle `v` with the standard
    /// deviations `v_sigma` ([`Vehicle::to_array`] order; 0 holds a parameter exact).
    pub fn new(
        pose: Pose2,
        pose_cov: &Matrix3<f64>,
        v: &Vehicle,
        v_sigma: [f64; 4],
        vehicle_walk: [f64; 4],
    ) -> Self {
        let va = v.to_array();
        let x = State::from_column_slice(&[pose.x, pose.y, pose.theta, va[0], va[1], va[2], va[3]]);
        let mut p = StateCov::zeros();
        p.fixed_view_mut::<3, 3>(0, 0).copy_from(pose_cov);
        for (k, s) in v_sigma.iter().enumerate() {
            p[(3 + k, 3 + k)] = s * s;
        }
        Self {
            x,
            p,
            considered: Vec::new(),
            vehicle_walk,
        }
    }

    /// Starts estimating `V` from here: its standard deviations `v_sigma` (uncorrelated with
    /// the pose) and its random walk; the pose, its covariance and the cross-covariances stay.
    pub fn release_vehicle(&mut self, v: &Vehicle, v_sigma: [f64; 4], vehicle_walk: [f64; 4]) {
        let va = v.to_array();
        for k in 0..4 {
            self.x[3 + k] = va[k];
            for j in 0..STATE_DIM {
                self.p[(3 + k, j)] = 0.0;
                self.p[(j, 3 + k)] = 0.0;
            }
            self.p[(3 + k, 3 + k)] = v_sigma[k] * v_sigma[k];
            for (_, c, _) in &mut self.considered {
                c.row_mut(3 + k).fill(0.0);
            }
        }
        self.vehicle_walk = vehicle_walk;
    }

    /// The pose.
    pub fn pose(&self) -> Pose2 {
        Pose2::new(self.x[0], self.x[1], self.x[2])
    }

    /// The pose's covariance.
    pub fn pose_covariance(&self) -> Matrix3<f64> {
        self.p.fixed_view::<3, 3>(0, 0).into_owned()
    }

    /// The vehicle's parameters.
    pub fn vehicle(&self) -> Vehicle {
        Vehicle {
            odom_scale: self.x[3],
            odom_yaw_scale: self.x[4],
            odom_yaw_bias: self.x[5],
            time_offset: self.x[6],
        }
    }

    /// Standard deviations of `V`, [`Vehicle::to_array`] order.
    pub fn vehicle_sigma(&self) -> [f64; 4] {
        core::array::from_fn(|k| libm::sqrt(self.p[(3 + k, 3 + k)].max(0.0)))
    }

    /// The full covariance.
    pub fn covariance(&self) -> &StateCov {
        &self.p
    }

    /// Lamps whose cross-covariance is kept.
    pub fn considered(&self) -> usize {
        self.considered.len()
    }

    /// Eq. (4)-(5) for the pose and `V`: `inc` the odometry's motion for the current `V`,
    /// `jv = d motion / dV`.
    pub fn predict(&mut self, inc: &Increment, jv: &SMatrix<f64, 3, 4>) {
        let (pose, f, q) = inc.apply(&self.pose());
        // d pose' / dV = G * d motion / dV, G = Rz(theta) on the translation.
        let g = vslam_ekf::motion::compose_jacobian_second(self.x[2]) * jv;
        let mut phi = StateCov::identity();
        phi.fixed_view_mut::<3, 3>(0, 0).copy_from(&f);
        phi.fixed_view_mut::<3, 4>(0, 3).copy_from(&g);
        let mut qf = StateCov::zeros();
        qf.fixed_view_mut::<3, 3>(0, 0).copy_from(&q);
        for (k, w) in self.vehicle_walk.iter().enumerate() {
            qf[(3 + k, 3 + k)] = w * inc.motion.dt_s;
        }
        self.x[0] = pose.x;
        self.x[1] = pose.y;
        self.x[2] = wrap_angle(pose.theta);
        let p = phi * self.p * phi.transpose() + qf;
        self.p = 0.5 * (p + p.transpose());
        for (_, c, _) in &mut self.considered {
            *c = phi * *c;
        }
    }

    /// Grows the pose's covariance by `q` (a motion the odometry did not see).
    pub fn inflate(&mut self, q: &Matrix3<f64>) {
        let mut b = self.p.fixed_view_mut::<3, 3>(0, 0);
        b += q;
    }

    /// The cross-covariance kept for `lamp`, or zero.
    fn cross(&self, lamp: u32) -> CrossCov {
        self.considered
            .iter()
            .find(|(l, _, _)| *l == lamp)
            .map_or_else(CrossCov::zeros, |(_, c, _)| *c)
    }

    /// The predicted measurement of lamp `lamp` at `position` with map covariance `p_jj`, or
    /// `None` when it is behind the cameras. `r` is the pixel noise's covariance.
    pub fn predict_lamp(
        &self,
        c: &CameraParams,
        lamp: u32,
        position: &Vector3<f64>,
        p_jj: &Matrix3<f64>,
        r: &Matrix4<f64>,
    ) -> Option<Prediction> {
        let (z, j) = project_with_jacobians(c, &self.pose(), position).ok()?;
        let mut hx = SMatrix::<f64, 4, STATE_DIM>::zeros();
        hx.fixed_view_mut::<4, 3>(0, 0).copy_from(&j.pose);
        let pxj = self.cross(lamp);
        let cross = hx * pxj * j.landmark.transpose();
        let s = hx * self.p * hx.transpose()
            + cross
            + cross.transpose()
            + j.landmark * p_jj * j.landmark.transpose()
            + r;
        Some(Prediction {
            lamp,
            z,
            s: 0.5 * (s + s.transpose()),
            h_pose: j.pose,
            h_lamp: j.landmark,
        })
    }

    /// The update with the measurement `z` of lamp `lamp` (index into the map), at time `t_us`; the prediction recomputed
    /// at the current state (after earlier updates of the same frame). Returns the NIS, or
    /// `None` when `S` is singular or the lamp is behind the cameras.
    pub fn update(
        &mut self,
        c: &CameraParams,
        lamp: u32,
        map_lamp: &MapLamp,
        r: &Matrix4<f64>,
        z: &Vector4<f64>,
        t_us: u64,
    ) -> Option<f64> {
        let p_jj = &map_lamp.covariance;
        let pred = self.predict_lamp(c, lamp, &map_lamp.position, p_jj, r)?;
        let s_inv = pred.s.try_inverse()?;
        let mut hx = SMatrix::<f64, 4, STATE_DIM>::zeros();
        hx.fixed_view_mut::<4, 3>(0, 0).copy_from(&pred.h_pose);
        let hl = pred.h_lamp;
        let pxj = self.cross(lamp);
        let k = (self.p * hx.transpose() + pxj * hl.transpose()) * s_inv;
        let nu = z - pred.z;
        let nis = (nu.transpose() * s_inv * nu)[(0, 0)];
        self.x += k * nu;
        self.x[2] = wrap_angle(self.x[2]);
        let p = self.p - k * pred.s * k.transpose();
        self.p = 0.5 * (p + p.transpose());
        let mut found = false;
        for (l, cxl, seen) in &mut self.considered {
            let hj_pjl = if *l == lamp {
                found = true;
                *seen = t_us;
                hl * p_jj
            } else {
                SMatrix::<f64, 4, 3>::zeros()
            };
            *cxl -= k * (hx * *cxl + hj_pjl);
        }
        if !found {
            let cxl = -k * (hl * p_jj);
            if self.considered.len() >= MAX_CONSIDERED
                && let Some((oldest, _)) = self
                    .considered
                    .iter()
                    .enumerate()
                    .min_by_key(|(_, (_, _, t))| *t)
            {
                self.considered.swap_remove(oldest);
            }
            self.considered.push((lamp, cxl, t_us));
        }
        Some(nis)
    }

    /// Drops the cross-covariances of lamps not updated from since `before_us`.
    pub fn forget_before(&mut self, before_us: u64) {
        self.considered.retain(|(_, _, t)| *t >= before_us);
    }
}

#[cfg(test)]
#[allow(clippy::indexing_slicing, clippy::unwrap_used)]
mod tests {
    use super::*;
    use rig_model::camera::Mount;
    use rig_model::project;

    pub(crate) fn camera() -> CameraParams {
        CameraParams {
            f: 300.0,
            cx: 376.0,
            cy: 240.0,
            baseline: 0.12,
            mount: Mount {
                x: 0.3,
                y: 0.0,
                z: 2.2,
                roll: 0.0,
                pitch: 0.05,
                yaw: 0.0,
            },
            vehicle: Vehicle::NOMINAL,
        }
    }

    #[test]
    fn seeing_one_uncertain_lamp_again_and_again_never_beats_its_map_sigma() {
        // One lamp known to 5 cm in x and y; the robot stands and sees it 500 times with
        // 0.3 px noise. A filter that counts the map error afresh each time would end far
        // below 5 cm; the Schmidt filter's pose sigma stays at about the map's.
        let c = camera();
        let lamp = Vector3::new(1.0, 0.5, 7.0);
        let p_jj = Matrix3::from_diagonal(&Vector3::new(0.05_f64.powi(2), 0.05_f64.powi(2), 0.01));
        let r = Matrix4::identity() * 0.09;
        let pose = Pose2::new(0.0, 0.0, 0.0);
        let mut f = PoseFilter::new(
            pose,
            &Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, 1e-8)),
            &Vehicle::NOMINAL,
            [0.0; 4],
            [0.0; 4],
        );
        let z = project(&c, &pose, &lamp).unwrap();
        let map_lamp = MapLamp {
            id: 0,
            position: lamp,
            covariance: p_jj,
        };
        for t in 0..500 {
            f.update(&c, 0, &map_lamp, &r, &z, t).unwrap();
        }
        let sx = f.pose_covariance()[(0, 0)].sqrt();
        assert!(sx > 0.045 && sx < 0.06, "pose sigma {sx}");
        assert_eq!(f.considered(), 1);
    }
}
