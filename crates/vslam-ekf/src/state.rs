//! Eq. (3), the state: its layout `x = [X, Y, theta, L_1, ..., L_N, C_est, E]` ([`StateLayout`],
//! the one place that says where each block sits), the covariance buffer's indexing, and what a
//! caller reads of the pose, the camera and the covariance.

use nalgebra::{DMatrix, DVector, Matrix3, SMatrix};
use rig_model::camera::Param;
use rig_model::{CameraParams, N_PARAMS, Pose2};

use crate::filter::Ekf;
use crate::linalg::{mirror_lower, sym};

/// Size of the pose block `(X, Y, theta)`.
pub const POSE_DIM: usize = 3;
/// Size of a landmark block `(x, y, z)`.
pub const LANDMARK_DIM: usize = 3;

/// The 10x10 covariance of the camera parameters, [`Param::ALL`] order.
pub type CameraCovariance = SMatrix<f64, N_PARAMS, N_PARAMS>;

/// Eq. (3): the state layout `x = [X, Y, theta, L_1, ..., L_N, C_est, E]`: the planar pose
/// at `0..3`, landmark `s` (in state order) at `3 + 3 s`, the estimated camera parameters (the
/// rig file's `estimate` order) after the landmarks, so that every observation's `H` has the
/// same shape and a new landmark is inserted just before the camera block, and last the
/// odometry's block when it is held (`crate::errors`: the vehicle's velocities `u` with
/// `Settings::odometry_velocity_states`, then the errors `E`; no lamp's observation involves
/// them). Every index into `x` and `P` is computed here.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct StateLayout {
    /// Landmarks in the state, `N`.
    pub landmarks: usize,
    /// Camera (and vehicle) parameters estimated, `m`.
    pub camera: usize,
    /// The odometry's block after the camera (`crate::errors`), `e`: the velocities (3, with
    /// the velocity-state form) and the errors (0 to 3), so 0 to 6.
    pub errors: usize,
}

impl StateLayout {
    /// Length of the state, `3 + 3 N + m + e`.
    #[must_use]
    pub const fn dim(&self) -> usize {
        POSE_DIM + LANDMARK_DIM * self.landmarks + self.camera + self.errors
    }

    /// Index of the `x` of the landmark in state-order slot `s` (`y`, `z` follow).
    #[must_use]
    pub const fn landmark(s: usize) -> usize {
        POSE_DIM + LANDMARK_DIM * s
    }

    /// Index of the first estimated camera parameter (the end of the landmark blocks).
    #[must_use]
    pub const fn camera_start(&self) -> usize {
        Self::landmark(self.landmarks)
    }

    /// Index of the odometry's block (the end of the camera block).
    #[must_use]
    pub const fn errors_start(&self) -> usize {
        self.camera_start() + self.camera
    }

    /// The states after the landmarks: the camera block and the odometry's block, `m + e`.
    #[must_use]
    pub const fn tail(&self) -> usize {
        self.camera + self.errors
    }
}

/// Index of column `j`, row `i` in an `n`-row column-major buffer.
#[inline]
pub(crate) const fn at(n: usize, i: usize, j: usize) -> usize {
    j * n + i
}

impl Ekf {
    /// The state's layout (eq. (3)) at this moment.
    pub fn layout(&self) -> StateLayout {
        StateLayout {
            landmarks: self.landmarks.len(),
            camera: self.estimated.len(),
            errors: self.errors.len() + if self.velocity_states { 3 } else { 0 },
        }
    }

    /// Index of the first estimated camera parameter in the state.
    pub(crate) fn camera_offset(&self) -> usize {
        self.layout().camera_start()
    }

    /// Length of the state vector, `3 + 3 N + m`.
    pub fn state_len(&self) -> usize {
        self.x.len()
    }

    /// The state vector `[X, Y, theta, L_1, ..., L_N, C_est, E]`.
    pub fn state(&self) -> &DVector<f64> {
        &self.x
    }

    /// The covariance `P`, `n x n`, exactly symmetric (a copy: O(n^2); with a local session
    /// open, the session is settled on the copy: see [`Ekf::settle`]).
    pub fn covariance(&self) -> DMatrix<f64> {
        let mut p = if self.local.is_some() {
            let mut settled = self.clone();
            settled.settle();
            settled.p
        } else {
            self.p.clone()
        };
        let n = p.nrows();
        mirror_lower(p.as_mut_slice(), n);
        p
    }

    /// Entry `(i, j)` of `P`.
    pub fn covariance_entry(&self, i: usize, j: usize) -> Option<f64> {
        let n = self.x.len();
        (i < n && j < n).then(|| self.cov(i, j))
    }

    /// The `3 x 3` block of `P` at `(i, i)`.
    pub(crate) fn block3(&self, i: usize) -> Matrix3<f64> {
        match &self.local {
            None => {
                let n = self.x.len();
                Matrix3::from_fn(|r, c| sym(self.p.as_slice(), n, i + r, i + c))
            }
            Some(l) => l.block3(self.p.as_slice(), i),
        }
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
                cov[(pa.index(), pb.index())] = self.cov(c0 + a, c0 + b);
            }
        }
        cov
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_layout_puts_landmarks_between_pose_and_camera() {
        let layout = StateLayout {
            landmarks: 5,
            camera: 1,
            errors: 0,
        };
        assert_eq!(layout.dim(), 19);
        assert_eq!(StateLayout::landmark(0), 3);
        assert_eq!(StateLayout::landmark(4), 15);
        assert_eq!(layout.camera_start(), 18);
    }
}
