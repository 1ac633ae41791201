//! The batch's factors: the odometry between consecutive frames (residual, Jacobians,
//! information, the vehicle parameters' Jacobian) and the whitening of a pixel measurement
//! through real lenses; the Huber cost they are weighed with.

use nalgebra::{Matrix3, Vector3};

use rig_model::camera::{CameraParams, Pose2, wrap_angle};
use rig_model::config::Rig;
use rig_model::odometry::{Motion, OdometryFactor};
use rig_model::rig::Measurement;

use super::Frame;
#[cfg(doc)]
use rig_model::camera::Param;

/// The batch's odometry residual (the counterpart of the motion in eq. (1), between
/// consecutive frames): `h(x_a, x_b) - m` with `h = (Rz(-theta_a) (p_b - p_a), theta_b -
/// theta_a)` and its Jacobians with respect to `x_a` and `x_b`.
pub(super) fn odometry_residual(
    a: &Pose2,
    b: &Pose2,
    m: &Motion,
) -> (Vector3<f64>, Matrix3<f64>, Matrix3<f64>) {
    let (s, c) = (libm::sin(a.theta), libm::cos(a.theta));
    let (dx, dy) = (b.x - a.x, b.y - a.y);
    let hx = c * dx + s * dy;
    let hy = -s * dx + c * dy;
    let r = Vector3::new(
        hx - m.dx,
        hy - m.dy,
        wrap_angle(b.theta - a.theta - m.dtheta),
    );
    let ja = Matrix3::new(-c, -s, hy, s, -c, -hx, 0.0, 0.0, -1.0);
    let jb = Matrix3::new(c, s, 0.0, -s, c, 0.0, 0.0, 0.0, 1.0);
    (r, ja, jb)
}

/// The odometry motion with its information (inverse covariance); `None` when there is none
/// or its covariance cannot be inverted.
pub(super) fn odometry_information(
    odometry: Option<OdometryFactor>,
) -> Option<(OdometryFactor, Matrix3<f64>)> {
    odometry.and_then(|o| {
        let info = o.covariance.try_inverse()?;
        (info.iter().all(|v| v.is_finite()) && o.vehicle_jacobian.iter().all(|v| v.is_finite()))
            .then_some((o, 0.5 * (info + info.transpose())))
    })
}

/// The whitening of one stereo measurement through real lenses (vehicle-interfaces.md 1.1):
/// the rig's pixel sigma is that of the raw board features, so a rectified measurement's
/// noise is `sigma^2 J^-1 J^-T` per camera, `J = d raw / d rectified` (the lens's forward map,
/// `Lens::unrectify`, at the measurement). `A = blockdiag(J_left, J_right) / sigma` has
/// `A^T A = R^-1`: the whitened residual is the residual in raw pixels over sigma (a fisheye
/// stretches the noise toward the rectified image's edges, and the batch weighs those
/// measurements less). `None` without lenses, or where the forward map fails (the rig's one
/// sigma then).
pub(super) fn lens_whitening(rig: &Rig, z: &Measurement) -> Option<nalgebra::Matrix4<f64>> {
    let lens = rig.lens.as_ref()?;
    let c = &rig.nominal;
    // Central differences of the closed-form forward map (0.001 px: its curvature is far
    // below the pixel noise at that scale).
    let jacobian = |l: &rig_model::lens::Lens, u: f64, v: f64| -> Option<nalgebra::Matrix2<f64>> {
        let h = 1e-3;
        let at =
            |du: f64, dv: f64| l.unrectify(nalgebra::Vector2::new(u + du, v + dv), c.f, c.cx, c.cy);
        let (px, mx, py, my) = (at(h, 0.0)?, at(-h, 0.0)?, at(0.0, h)?, at(0.0, -h)?);
        Some(nalgebra::Matrix2::from_columns(&[
            (px - mx) / (2.0 * h),
            (py - my) / (2.0 * h),
        ]))
    };
    let jl = jacobian(&lens.left, z[0], z[1])?;
    let jr = jacobian(&lens.right, z[2], z[3])?;
    let s = rig.noise.pixel;
    let mut a = nalgebra::Matrix4::zeros();
    a.fixed_view_mut::<2, 2>(0, 0).copy_from(&(jl / s));
    a.fixed_view_mut::<2, 2>(2, 2).copy_from(&(jr / s));
    a.iter().all(|v| v.is_finite()).then_some(a)
}

/// `D = diag(odom_scale, odom_scale, odom_yaw_scale)`: a true-motion error in the reported
/// odometry's units (`Frame::odometry_factor`).
fn to_reported_units(v: &rig_model::camera::Vehicle) -> Matrix3<f64> {
    Matrix3::from_diagonal(&Vector3::new(v.odom_scale, v.odom_scale, v.odom_yaw_scale))
}

/// An odometry factor linearised: residual, its Jacobians with respect to the two poses,
/// information, and its Jacobian with respect to `V` ([`Param::VEHICLE`] order).
pub(super) type OdometryTerms = (
    Vector3<f64>,
    Matrix3<f64>,
    Matrix3<f64>,
    Matrix3<f64>,
    nalgebra::Matrix3x4<f64>,
);

/// Information of a frame interval without odometry: the pose is free to within metres.
const NO_ODOMETRY_INFORMATION: f64 = 1e-2;

impl Frame {
    /// The odometry factor's cost `r^T I r` (see [`Self::odometry_factor`]), without the
    /// Jacobians.
    pub(super) fn odometry_cost(&self, prev: &Pose2, pose: &Pose2, camera: &CameraParams) -> f64 {
        match &self.odometry {
            Some((o, info)) => {
                let v = &camera.vehicle;
                let (r0, _, _) = odometry_residual(prev, pose, &o.motion_for(v));
                let r = to_reported_units(v) * r0;
                r.dot(&(info * r))
            }
            None => {
                let (r, _, _) = odometry_residual(prev, pose, &Motion::default());
                r.dot(&r) * NO_ODOMETRY_INFORMATION
            }
        }
    }

    /// The odometry factor from the previous frame's pose `prev` to this frame's `pose`, for
    /// the vehicle parameters of `camera`: residual, Jacobians with respect to both poses,
    /// information, and the residual's Jacobian with respect to `V` ([`Param::VEHICLE`]
    /// order). Without odometry, a weak zero-motion factor.
    ///
    /// The residual is in the reported odometry's units, `D (h(x_a, x_b) - m(V))` with
    /// `D = diag(odom_scale, odom_scale, odom_yaw_scale)`: the odometry's noise is that of the
    /// reported velocities, whatever the true motion. A residual in true-motion units with the
    /// reported noise would shrink with the map (baseline and odometry scale along their
    /// product, vehicle-interfaces.md 1.2: the one direction the data cannot see), and the
    /// batch would drift along it, the odometry cost falling as the square of the scale.
    pub(super) fn odometry_factor(
        &self,
        prev: &Pose2,
        pose: &Pose2,
        camera: &CameraParams,
    ) -> OdometryTerms {
        match &self.odometry {
            Some((o, info)) => {
                let v = &camera.vehicle;
                let (motion, jacobian) = o.at(v);
                let (r0, ja, jb) = odometry_residual(prev, pose, &motion);
                let d = to_reported_units(v);
                let mut jv = -(d * jacobian);
                // d D / d odom_scale and d D / d odom_yaw_scale times the true-units residual.
                jv[(0, 0)] += r0.x;
                jv[(1, 0)] += r0.y;
                jv[(2, 1)] += r0.z;
                (d * r0, d * ja, d * jb, *info, jv)
            }
            None => {
                let (r, ja, jb) = odometry_residual(prev, pose, &Motion::default());
                (
                    r,
                    ja,
                    jb,
                    Matrix3::identity() * NO_ODOMETRY_INFORMATION,
                    nalgebra::Matrix3x4::zeros(),
                )
            }
        }
    }
}

/// Huber cost of a whitened residual of norm `e` at threshold `k`.
pub(super) fn huber_cost(e: f64, k: f64) -> f64 {
    if e <= k { e * e } else { 2.0 * k * e - k * k }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used, clippy::indexing_slicing)]
mod tests {
    use super::*;
    use rig_model::camera::{CameraParams, N_PARAMS, Param};
    use rig_model::rig::Measurement;

    fn rig_with(model: rig_model::lens::LensModel, fx: f64) -> Rig {
        let lens = rig_model::lens::Lens {
            model,
            fx,
            fy: fx,
            cx: 376.0,
            cy: 240.0,
            rectification: Matrix3::identity(),
        };
        let mut prior = [None; N_PARAMS];
        prior[Param::Baseline.index()] = Some(0.01);
        Rig {
            width: 752,
            height: 480,
            nominal: CameraParams {
                f: 700.0,
                cx: 376.0,
                cy: 240.0,
                baseline: 0.12,
                mount: rig_model::camera::Mount::default(),
                vehicle: rig_model::camera::Vehicle::NOMINAL,
            },
            estimate: alloc::vec![Param::Baseline],
            prior,
            noise: rig_model::config::Noise::white(0.3, 0.02, 0.01),
            lens: Some(rig_model::lens::StereoLens {
                left: lens,
                right: lens,
            }),
            board: rig_model::Board::DEFAULT,
        }
    }

    /// Through a lens without distortion at the rectified focal length, the whitening is the
    /// rig's sigma; through a fisheye at a lower raw focal length, a measurement near the
    /// rectified image's corner weighs less than one at the centre (its noise is stretched).
    #[test]
    fn lens_whitening_carries_the_raw_noise() {
        let flat = rig_with(
            rig_model::lens::LensModel::PlumbBob {
                k1: 0.0,
                k2: 0.0,
                p1: 0.0,
                p2: 0.0,
                k3: 0.0,
            },
            700.0,
        );
        let z = Measurement::new(400.0, 250.0, 380.0, 250.0);
        let a = lens_whitening(&flat, &z).unwrap();
        assert!(
            (a - nalgebra::Matrix4::identity() / 0.3).amax() < 1e-6,
            "{a}"
        );
        let fisheye = rig_with(
            rig_model::lens::LensModel::Equidistant {
                k1: 0.0,
                k2: 0.0,
                k3: 0.0,
                k4: 0.0,
            },
            350.0,
        );
        let centre = lens_whitening(&fisheye, &Measurement::new(380.0, 242.0, 372.0, 242.0))
            .unwrap()
            .norm();
        let corner = lens_whitening(&fisheye, &Measurement::new(740.0, 470.0, 730.0, 470.0))
            .unwrap()
            .norm();
        assert!(corner < 0.9 * centre, "corner {corner}, centre {centre}");
        let mut plain = flat.clone();
        plain.lens = None;
        assert!(lens_whitening(&plain, &z).is_none());
    }

    #[test]
    fn odometry_jacobians_match_finite_differences() {
        let a = Pose2::new(0.3, -0.2, 0.7);
        let b = Pose2::new(0.5, 0.1, 0.9);
        let m = Motion {
            dx: 0.1,
            dy: 0.05,
            dtheta: 0.1,
            dt_s: 0.05,
            samples: 5,
        };
        let (r0, ja, jb) = odometry_residual(&a, &b, &m);
        let h = 1e-7;
        for k in 0..3 {
            let mut a2 = a;
            let mut b2 = b;
            match k {
                0 => {
                    a2.x += h;
                    b2.x += h;
                }
                1 => {
                    a2.y += h;
                    b2.y += h;
                }
                _ => {
                    a2.theta += h;
                    b2.theta += h;
                }
            }
            let (ra, _, _) = odometry_residual(&a2, &b, &m);
            let (rb, _, _) = odometry_residual(&a, &b2, &m);
            for i in 0..3 {
                assert!(((ra[i] - r0[i]) / h - ja[(i, k)]).abs() < 1e-5);
                assert!(((rb[i] - r0[i]) / h - jb[(i, k)]).abs() < 1e-5);
            }
        }
    }
}
