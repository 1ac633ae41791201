//! The stereo rig model: projection of a world point to the four pixel measurements
//! `(uL, vL, uR, vR)`, its analytic Jacobians, and triangulation back
//! (vehicle-interfaces.md section 1).

use nalgebra::{Matrix3, Matrix4, SMatrix, Vector3, Vector4};

use crate::camera::{CameraParams, N_PARAMS, Param, Pose2, skew};

/// The four pixel measurements of one landmark: `(uL, vL, uR, vR)`.
pub type Measurement = Vector4<f64>;
/// Jacobian of the measurements with respect to a 3-vector (pose or landmark).
pub type Jac4x3 = SMatrix<f64, 4, 3>;
/// Jacobian of the measurements with respect to every camera parameter, [`Param::ALL`] order.
pub type Jac4xC = SMatrix<f64, 4, N_PARAMS>;
/// Jacobian of a 3-D point with respect to the four measurements.
pub type Jac3x4 = SMatrix<f64, 3, 4>;
/// Jacobian of a 3-D point with respect to every camera parameter.
pub type Jac3xC = SMatrix<f64, 3, N_PARAMS>;

/// Why a point cannot be projected or triangulated.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum RigError {
    /// The point is not in front of the cameras (`zs <= 0` in the rig frame).
    #[error("point is behind the cameras: depth {depth_m} m in the rig frame")]
    BehindCamera {
        /// Depth along the optical axis, metres.
        depth_m: f64,
    },
    /// The disparity `uL - uR` is not positive: the point would be at or beyond infinity.
    #[error("disparity {disparity_px} px is not positive")]
    NonPositiveDisparity {
        /// `uL - uR`, pixels.
        disparity_px: f64,
    },
    /// A pose, landmark or measurement value is NaN or infinite.
    #[error("{what} is not finite")]
    NonFinite {
        /// Which input.
        what: &'static str,
    },
    /// The focal length or baseline is not positive and finite.
    #[error("camera parameter {param} = {value} must be positive and finite")]
    BadCamera {
        /// Which parameter.
        param: Param,
        /// Its value.
        value: f64,
    },
}

/// The analytic Jacobians of the four measurements (the blocks of eq. (8)'s `H`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProjectionJacobians {
    /// With respect to the robot pose `(X, Y, theta)`.
    pub pose: Jac4x3,
    /// With respect to the landmark's world coordinates.
    pub landmark: Jac4x3,
    /// With respect to every camera parameter, [`Param::ALL`] order.
    pub camera: Jac4xC,
}

/// Checks that `f` and the baseline are positive and finite.
fn check_camera(c: &CameraParams) -> Result<(), RigError> {
    for (param, value) in [(Param::F, c.f), (Param::Baseline, c.baseline)] {
        if !(value.is_finite() && value > 0.0) {
            return Err(RigError::BadCamera { param, value });
        }
    }
    Ok(())
}

fn check_inputs(pose: &Pose2, landmark: &Vector3<f64>) -> Result<(), RigError> {
    if !(pose.x.is_finite() && pose.y.is_finite() && pose.theta.is_finite()) {
        return Err(RigError::NonFinite { what: "robot pose" });
    }
    if !landmark.iter().all(|v| v.is_finite()) {
        return Err(RigError::NonFinite { what: "landmark" });
    }
    Ok(())
}

/// The landmark in the rig frame, `p_in_rig = R_RS^T (Rz(-theta) (L - (X, Y, 0)) - t)`.
pub fn point_in_rig(c: &CameraParams, pose: &Pose2, landmark: &Vector3<f64>) -> Vector3<f64> {
    let robot_from_rig = c.mount.robot_from_rig_rotation();
    robot_from_rig.transpose() * (pose.point_in_robot(landmark) - c.mount.translation())
}

/// Pixel measurements of a point given in the rig frame.
pub fn project_rig_point(c: &CameraParams, p: &Vector3<f64>) -> Result<Measurement, RigError> {
    check_camera(c)?;
    if !p.iter().all(|v| v.is_finite()) {
        return Err(RigError::NonFinite {
            what: "point in the rig frame",
        });
    }
    if p.z.is_nan() || p.z <= 0.0 {
        return Err(RigError::BehindCamera { depth_m: p.z });
    }
    let half_b = c.baseline / 2.0;
    let v = c.cy + c.f * p.y / p.z;
    Ok(Measurement::new(
        c.cx + c.f * (p.x + half_b) / p.z,
        v,
        c.cx + c.f * (p.x - half_b) / p.z,
        v,
    ))
}

/// Projects a world landmark seen from robot pose `pose` to `(uL, vL, uR, vR)`.
pub fn project(
    c: &CameraParams,
    pose: &Pose2,
    landmark: &Vector3<f64>,
) -> Result<Measurement, RigError> {
    Projector::new(c, pose).project(landmark)
}

/// [`project`] for many landmarks from one pose: the mount's and the pose's rotations are
/// taken once (their sines and cosines were most of a projection's cost when every lamp of a
/// hall is projected each frame). The same arithmetic as [`project`], to the bit.
#[derive(Debug, Clone, Copy)]
pub struct Projector {
    c: CameraParams,
    robot_from_world: Matrix3<f64>,
    rig_from_robot: Matrix3<f64>,
    origin: Vector3<f64>,
    mount: Vector3<f64>,
}

impl Projector {
    /// The camera `c` on the robot at `pose`.
    pub fn new(c: &CameraParams, pose: &Pose2) -> Self {
        Self {
            c: *c,
            robot_from_world: pose.world_from_robot_rotation().transpose(),
            rig_from_robot: c.mount.robot_from_rig_rotation().transpose(),
            origin: Vector3::new(pose.x, pose.y, 0.0),
            mount: c.mount.translation(),
        }
    }

    /// The landmark's pixels, as [`project`] gives them.
    pub fn project(&self, landmark: &Vector3<f64>) -> Result<Measurement, RigError> {
        let p_robot = self.robot_from_world * (landmark - self.origin);
        project_rig_point(&self.c, &(self.rig_from_robot * (p_robot - self.mount)))
    }
}

/// Projects and returns the analytic Jacobians with respect to pose, landmark and `C`.
pub fn project_with_jacobians(
    c: &CameraParams,
    pose: &Pose2,
    landmark: &Vector3<f64>,
) -> Result<(Measurement, ProjectionJacobians), RigError> {
    check_inputs(pose, landmark)?;
    let robot_from_rig = c.mount.robot_from_rig_rotation();
    let rig_from_robot = robot_from_rig.transpose();
    let robot_from_world = pose.world_from_robot_rotation().transpose();
    let p_robot = pose.point_in_robot(landmark);
    let q = p_robot - c.mount.translation();
    let p = rig_from_robot * q;
    let z = project_rig_point(c, &p)?;

    // d(uL, vL, uR, vR) / d(xs, ys, zs).
    let (xs, ys, zs) = (p.x, p.y, p.z);
    let half_b = c.baseline / 2.0;
    let fz = c.f / zs;
    let dh_dp = Jac4x3::new(
        fz,
        0.0,
        -c.f * (xs + half_b) / (zs * zs),
        0.0,
        fz,
        -c.f * ys / (zs * zs),
        fz,
        0.0,
        -c.f * (xs - half_b) / (zs * zs),
        0.0,
        fz,
        -c.f * ys / (zs * zs),
    );

    // Landmark: dp/dL = R_RS^T Rz(-theta).
    let landmark_jac = dh_dp * (rig_from_robot * robot_from_world);
    // Pose: dp_R/dX = -Rz(-theta) e_x, dp_R/dY = -Rz(-theta) e_y, dp_R/dtheta = (p_R.y, -p_R.x, 0).
    let mut dpr_dpose = Matrix3::zeros();
    dpr_dpose.set_column(0, &(-robot_from_world.column(0)));
    dpr_dpose.set_column(1, &(-robot_from_world.column(1)));
    dpr_dpose.set_column(2, &Vector3::new(p_robot.y, -p_robot.x, 0.0));
    let pose_jac = dh_dp * rig_from_robot * dpr_dpose;

    // Camera parameters.
    let mut camera = Jac4xC::zeros();
    camera.set_column(
        Param::F.index(),
        &Vector4::new((xs + half_b) / zs, ys / zs, (xs - half_b) / zs, ys / zs),
    );
    camera.set_column(Param::Cx.index(), &Vector4::new(1.0, 0.0, 1.0, 0.0));
    camera.set_column(Param::Cy.index(), &Vector4::new(0.0, 1.0, 0.0, 1.0));
    camera.set_column(
        Param::Baseline.index(),
        &Vector4::new(fz / 2.0, 0.0, -fz / 2.0, 0.0),
    );
    // Mount translation: dp/dt = -R_RS^T.
    let dh_dt = dh_dp * (-rig_from_robot);
    for (k, param) in [Param::MountX, Param::MountY, Param::MountZ]
        .into_iter()
        .enumerate()
    {
        camera.set_column(param.index(), &dh_dt.column(k));
    }
    // Mount angles: p = Rx^T Ry^T Rz^T q, and d(R(a)^T)/da = -[e]x R(a)^T.
    let (rx, ry, rz) = (
        crate::camera::rot_x(c.mount.roll),
        crate::camera::rot_y(c.mount.pitch),
        crate::camera::rot_z(c.mount.yaw),
    );
    let (ex, ey, ez) = (Vector3::x(), Vector3::y(), Vector3::z());
    let rz_q = rz.transpose() * q;
    let ry_rz_q = ry.transpose() * rz_q;
    let dp_droll = -skew(&ex) * p;
    let dp_dpitch = rx.transpose() * (-skew(&ey) * ry_rz_q);
    let dp_dyaw = rx.transpose() * ry.transpose() * (-skew(&ez) * rz_q);
    camera.set_column(Param::MountRoll.index(), &(dh_dp * dp_droll));
    camera.set_column(Param::MountPitch.index(), &(dh_dp * dp_dpitch));
    camera.set_column(Param::MountYaw.index(), &(dh_dp * dp_dyaw));

    Ok((
        z,
        ProjectionJacobians {
            pose: pose_jac,
            landmark: landmark_jac,
            camera,
        },
    ))
}

/// A landmark triangulated from one stereo measurement, in the rig frame, with the Jacobians
/// that propagate uncertainty.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Triangulation {
    /// The point in the rig frame, metres.
    pub p_in_rig: Vector3<f64>,
    /// `d p_in_rig / d (uL, vL, uR, vR)`.
    pub jac_measurement: Jac3x4,
    /// `d p_in_rig / d C` (only `f`, `cx`, `cy` and `baseline` are non-zero).
    pub jac_camera: Jac3xC,
}

impl Triangulation {
    /// Covariance of `p_in_rig` from independent pixel noise of `sigma_px` on each of the four
    /// measurements.
    pub fn covariance_in_rig(&self, sigma_px: f64) -> Matrix3<f64> {
        self.jac_measurement * self.jac_measurement.transpose() * (sigma_px * sigma_px)
    }

    /// The point in the robot frame, `t + R_RS p_in_rig`.
    pub fn p_in_robot(&self, c: &CameraParams) -> Vector3<f64> {
        c.mount.translation() + c.mount.robot_from_rig_rotation() * self.p_in_rig
    }

    /// Covariance in the robot frame from pixel noise only.
    pub fn covariance_in_robot(&self, c: &CameraParams, sigma_px: f64) -> Matrix3<f64> {
        let r = c.mount.robot_from_rig_rotation();
        r * self.covariance_in_rig(sigma_px) * r.transpose()
    }

    /// The point in the world frame seen from `pose`.
    pub fn p_in_world(&self, c: &CameraParams, pose: &Pose2) -> Vector3<f64> {
        pose.point_in_world(&self.p_in_robot(c))
    }

    /// Covariance in the world frame from pixel noise and, optionally, the pose's covariance
    /// (3x3 over `X, Y, theta`) and the camera parameters' covariance (10x10).
    pub fn covariance_in_world(
        &self,
        c: &CameraParams,
        pose: &Pose2,
        sigma_px: f64,
        pose_cov: Option<&Matrix3<f64>>,
        camera_cov: Option<&SMatrix<f64, N_PARAMS, N_PARAMS>>,
    ) -> Matrix3<f64> {
        self.rig_covariance_in_world(
            c,
            pose,
            &self.covariance_in_rig(sigma_px),
            pose_cov,
            camera_cov,
        )
    }

    /// Covariance in the rig frame from the variances of the measurement's `uL, vL, uR, vR`
    /// (px^2; a lens stretches them unequally, `lens::PixelNoise`).
    pub fn covariance_in_rig_of(&self, variances: &Vector4<f64>) -> Matrix3<f64> {
        self.jac_measurement * Matrix4::from_diagonal(variances) * self.jac_measurement.transpose()
    }

    /// [`Triangulation::covariance_in_world`] with per-coordinate measurement variances
    /// ([`Triangulation::covariance_in_rig_of`]).
    pub fn covariance_in_world_of(
        &self,
        c: &CameraParams,
        pose: &Pose2,
        variances: &Vector4<f64>,
        pose_cov: Option<&Matrix3<f64>>,
        camera_cov: Option<&SMatrix<f64, N_PARAMS, N_PARAMS>>,
    ) -> Matrix3<f64> {
        self.rig_covariance_in_world(
            c,
            pose,
            &self.covariance_in_rig_of(variances),
            pose_cov,
            camera_cov,
        )
    }

    fn rig_covariance_in_world(
        &self,
        c: &CameraParams,
        pose: &Pose2,
        in_rig: &Matrix3<f64>,
        pose_cov: Option<&Matrix3<f64>>,
        camera_cov: Option<&SMatrix<f64, N_PARAMS, N_PARAMS>>,
    ) -> Matrix3<f64> {
        let world_from_robot = pose.world_from_robot_rotation();
        let world_from_rig = world_from_robot * c.mount.robot_from_rig_rotation();
        let mut cov = world_from_rig * in_rig * world_from_rig.transpose();
        if let Some(pc) = pose_cov {
            let j = self.jac_pose(c, pose);
            cov += j * pc * j.transpose();
        }
        if let Some(cc) = camera_cov {
            let j = self.jac_camera_in_world(c, pose);
            cov += j * cc * j.transpose();
        }
        cov
    }

    /// `d p_in_world / d (X, Y, theta)`.
    pub fn jac_pose(&self, c: &CameraParams, pose: &Pose2) -> Matrix3<f64> {
        let p_robot = self.p_in_robot(c);
        let (s, co) = (libm::sin(pose.theta), libm::cos(pose.theta));
        Matrix3::new(
            1.0,
            0.0,
            -s * p_robot.x - co * p_robot.y,
            0.0,
            1.0,
            co * p_robot.x - s * p_robot.y,
            0.0,
            0.0,
            0.0,
        )
    }

    /// `d p_in_world / d C`: through the triangulation (`f, cx, cy, baseline`) and the mount.
    pub fn jac_camera_in_world(&self, c: &CameraParams, pose: &Pose2) -> Jac3xC {
        let world_from_robot = pose.world_from_robot_rotation();
        let robot_from_rig = c.mount.robot_from_rig_rotation();
        let mut j = world_from_robot * robot_from_rig * self.jac_camera;
        for (k, param) in [Param::MountX, Param::MountY, Param::MountZ]
            .into_iter()
            .enumerate()
        {
            j.set_column(param.index(), &world_from_robot.column(k));
        }
        // p_robot = t + Rz(yaw) Ry(pitch) Rx(roll) p, dR/da = R [e]x for the rotated axis.
        let (rx, ry, rz) = (
            crate::camera::rot_x(c.mount.roll),
            crate::camera::rot_y(c.mount.pitch),
            crate::camera::rot_z(c.mount.yaw),
        );
        let p = self.p_in_rig;
        let d_roll = rz * ry * rx * skew(&Vector3::x()) * p;
        let d_pitch = rz * ry * skew(&Vector3::y()) * rx * p;
        let d_yaw = rz * skew(&Vector3::z()) * ry * rx * p;
        j.set_column(Param::MountRoll.index(), &(world_from_robot * d_roll));
        j.set_column(Param::MountPitch.index(), &(world_from_robot * d_pitch));
        j.set_column(Param::MountYaw.index(), &(world_from_robot * d_yaw));
        j
    }
}

/// Whether [`triangulate`] accepts `c`: `f` and the baseline positive and finite, the principal
/// point finite.
pub fn check_triangulation_camera(c: &CameraParams) -> Result<(), RigError> {
    check_camera(c)?;
    if !(c.cx.is_finite() && c.cy.is_finite()) {
        return Err(RigError::NonFinite {
            what: "principal point",
        });
    }
    Ok(())
}

/// The disparity `uL - uR` of a measurement that can be triangulated: an error for a
/// non-finite row (vL or vR) or a disparity that is not positive.
fn checked_disparity(z: &Measurement) -> Result<f64, RigError> {
    if z[1].is_nan() || z[3].is_nan() || z[1].is_infinite() || z[3].is_infinite() {
        return Err(RigError::NonFinite {
            what: "measurement row (vL or vR)",
        });
    }
    let d = z[0] - z[2];
    if d.is_nan() || d <= 0.0 {
        return Err(RigError::NonPositiveDisparity { disparity_px: d });
    }
    Ok(d)
}

/// Triangulates one stereo measurement `(uL, vL, uR, vR)` into the rig frame:
/// `zs = f B / (uL - uR)`, `xs = ((uL + uR) / 2 - cx) zs / f`, `ys = ((vL + vR) / 2 - cy) zs / f`.
pub fn triangulate(c: &CameraParams, z: &Measurement) -> Result<Triangulation, RigError> {
    check_triangulation_camera(c)?;
    let d = checked_disparity(z)?;
    let (ul, vl, ur, vr) = (z[0], z[1], z[2], z[3]);
    let (f, b) = (c.f, c.baseline);
    let zs = f * b / d;
    let um = (ul + ur) / 2.0 - c.cx;
    let vm = (vl + vr) / 2.0 - c.cy;
    // xs = um B / d, ys = vm B / d, zs = f B / d.
    let p = Vector3::new(um * b / d, vm * b / d, zs);
    let dd = d * d;
    // Derivatives with d = uL - uR: d(1/d)/duL = -1/d^2, d(1/d)/duR = +1/d^2.
    let jac_measurement = Jac3x4::new(
        b / (2.0 * d) - um * b / dd,
        0.0,
        b / (2.0 * d) + um * b / dd,
        0.0,
        -vm * b / dd,
        b / (2.0 * d),
        vm * b / dd,
        b / (2.0 * d),
        -f * b / dd,
        0.0,
        f * b / dd,
        0.0,
    );
    let mut jac_camera = Jac3xC::zeros();
    jac_camera.set_column(Param::F.index(), &Vector3::new(0.0, 0.0, b / d));
    jac_camera.set_column(Param::Cx.index(), &Vector3::new(-b / d, 0.0, 0.0));
    jac_camera.set_column(Param::Cy.index(), &Vector3::new(0.0, -b / d, 0.0));
    jac_camera.set_column(
        Param::Baseline.index(),
        &Vector3::new(um / d, vm / d, f / d),
    );
    Ok(Triangulation {
        p_in_rig: p,
        jac_measurement,
        jac_camera,
    })
}

/// A stereo measurement reduced to what [`triangulate`] uses of it: the mean column and row of
/// the two images and the inverse of the disparity `d = uL - uR`, checked once.
///
/// None of it depends on `C`, so phase 1, which triangulates the same measurements under many
/// trial `C`, reduces them once per solve and triangulates with multiplications only. The
/// point is [`triangulate`]'s up to rounding (a unit test checks that they agree).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReducedMeasurement {
    /// `(uL + uR) / 2`, pixels.
    pub u_mean_px: f64,
    /// `(vL + vR) / 2`, pixels.
    pub v_mean_px: f64,
    /// `1 / (uL - uR)`, per pixel, positive.
    pub inv_disparity: f64,
}

impl ReducedMeasurement {
    /// The reduction of `(uL, vL, uR, vR)`, with [`triangulate`]'s errors for a non-finite row
    /// or a disparity that is not positive.
    pub fn new(z: &Measurement) -> Result<Self, RigError> {
        let d = checked_disparity(z)?;
        Ok(Self {
            u_mean_px: (z[0] + z[2]) / 2.0,
            v_mean_px: (z[1] + z[3]) / 2.0,
            inv_disparity: 1.0 / d,
        })
    }

    /// `B / d`: metres in the rig frame per pixel of the mean image position (and `zs / f`).
    pub fn scale(&self, c: &CameraParams) -> f64 {
        c.baseline * self.inv_disparity
    }

    /// The point in the rig frame, `(B / d) (u_mean - cx, v_mean - cy, f)`. Does not check
    /// `c`: callers check it once with [`check_triangulation_camera`].
    pub fn point_in_rig(&self, c: &CameraParams) -> Vector3<f64> {
        Vector3::new(self.u_mean_px - c.cx, self.v_mean_px - c.cy, c.f) * self.scale(c)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Mount;

    #[test]
    fn reduced_measurement_triangulates_as_triangulate_does() {
        let c = CameraParams {
            vehicle: Default::default(),
            f: 702.0,
            cx: 376.0,
            cy: 240.0,
            baseline: 0.1215,
            mount: Mount::default(),
        };
        for z in [
            Measurement::new(420.5, 100.25, 390.0, 100.75),
            Measurement::new(10.0, 470.0, 9.5, 469.0),
            Measurement::new(700.0, -3.0, 100.0, -2.0),
        ] {
            let (Ok(tri), Ok(reduced)) = (triangulate(&c, &z), ReducedMeasurement::new(&z)) else {
                panic!("valid measurement {z:?}");
            };
            let p = reduced.point_in_rig(&c);
            assert!(
                (p - tri.p_in_rig).norm() <= 1e-14 * tri.p_in_rig.norm(),
                "{p} {}",
                tri.p_in_rig
            );
            assert!((reduced.scale(&c) - tri.jac_camera[(2, Param::F.index())]).abs() < 1e-16);
        }
        for z in [
            Measurement::new(400.0, 240.0, 400.0, 240.0),
            Measurement::new(f64::NAN, 240.0, 380.0, 240.0),
            Measurement::new(400.0, f64::INFINITY, 380.0, 240.0),
        ] {
            let (Err(reduced), Err(full)) = (ReducedMeasurement::new(&z), triangulate(&c, &z))
            else {
                panic!("invalid measurement {z:?} accepted");
            };
            // Compared by kind: a NaN disparity is not equal to itself.
            assert_eq!(
                core::mem::discriminant(&reduced),
                core::mem::discriminant(&full),
                "{z:?}"
            );
        }
    }
}
