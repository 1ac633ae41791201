//! A landmark triangulated from several frames: the delayed initialisation of a lamp seen
//! only far off the axis (issue 35).
//!
//! One stereo pair far out through a fisheye fixes a lamp's depth poorly: its rectified
//! pixels carry the raw noise stretched ten to thirty times, its disparity is a few of its
//! own sigmas, and a point triangulated from it is biased (the depth goes as the inverse of
//! the disparity) and its linearised covariance is wrong. Landmarks born so were kept off and
//! their tracks retired when the lamp came into the middle of the view (docs/halls.md, "The
//! outer band"). The vehicle's own motion fixes the depth far better: over a second or two it
//! moves a metre or more across the ray. So such a candidate is followed over its frames and
//! triangulated from all of them at once, by Gauss-Newton on the four rectified coordinates
//! of each frame with the filter's pose of that frame, and becomes a landmark only when that
//! estimate is good (Montiel, Civera and Davison, RSS 2006, argue the same for monocular
//! points, and answer with an inverse-depth state; a multi-frame triangulation before the
//! landmark enters the state is the delayed form of it).
//!
//! Written here rather than taken from a library: it is a few lines over the rig's own
//! projection and its Jacobians (`rig_model::project_with_jacobians`), no_std.

use alloc::vec::Vec;

use nalgebra::{Matrix3, Vector3, Vector4};
use rig_model::rig::Jac3xC;
use rig_model::{CameraParams, Measurement, Pose2};

/// One frame of a candidate: the filter's pose then and the pair measured.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct View {
    pub pose: Pose2,
    pub z: Measurement,
}

/// A point triangulated from several frames.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Triangulated {
    /// In the world, metres.
    pub position: Vector3<f64>,
    /// Its covariance from the pixel noise, the poses taken as given, m^2.
    pub covariance: Matrix3<f64>,
    /// `d position / d C` over every camera parameter (`rig_model::Param::ALL` order).
    pub camera_jacobian: Jac3xC,
    /// The weighted squared residual at the solution.
    pub chi2: f64,
    /// Residual rows (four per frame).
    pub rows: usize,
}

/// Gauss-Newton steps at most.
const MAX_ITERATIONS: usize = 12;

/// A step smaller than this ends the iteration, metres.
const CONVERGED_M: f64 = 1e-7;

/// Triangulates a point from its frames, starting at `start`; `variances` gives the four
/// coordinates' noise variances at a (predicted) measurement. `None` when the problem is
/// singular, the point goes behind a camera, or the iteration does not settle.
pub(crate) fn triangulate_views(
    camera: &CameraParams,
    views: &[View],
    start: Vector3<f64>,
    variances: impl Fn(&Measurement) -> [f64; 4],
) -> Option<Triangulated> {
    if views.is_empty() {
        return None;
    }
    let mut l = start;
    let mut converged = false;
    for _ in 0..MAX_ITERATIONS {
        let (a, b, _, _) = normal_equations(camera, views, &l, &variances)?;
        let step = a.cholesky()?.solve(&b);
        l += step;
        if !l.iter().all(|v| v.is_finite()) {
            return None;
        }
        if step.norm() < CONVERGED_M {
            converged = true;
            break;
        }
    }
    if !converged {
        return None;
    }
    let (a, _, chi2, jlc) = normal_equations(camera, views, &l, &variances)?;
    let covariance = a.try_inverse()?;
    // At the solution sum J_L^T W (z - h(L, C)) = 0; differentiating in C gives
    // dL/dC = -A^-1 sum J_L^T W J_C.
    let camera_jacobian = -(covariance * jlc);
    Some(Triangulated {
        position: l,
        covariance: (covariance + covariance.transpose()) * 0.5,
        camera_jacobian,
        chi2,
        rows: 4 * views.len(),
    })
}

/// `A = sum J^T W J`, `b = sum J^T W r`, `chi2 = sum r^T W r` and `sum J_L^T W J_C` at `l`.
fn normal_equations(
    camera: &CameraParams,
    views: &[View],
    l: &Vector3<f64>,
    variances: &impl Fn(&Measurement) -> [f64; 4],
) -> Option<(Matrix3<f64>, Vector3<f64>, f64, Jac3xC)> {
    let mut a = Matrix3::zeros();
    let mut b = Vector3::zeros();
    let mut chi2 = 0.0;
    let mut jlc = Jac3xC::zeros();
    for v in views {
        let (h, jac) = rig_model::project_with_jacobians(camera, &v.pose, l).ok()?;
        let var = variances(&h);
        if !var.iter().all(|s| s.is_finite() && *s > 0.0) {
            return None;
        }
        let w = Vector4::new(1.0 / var[0], 1.0 / var[1], 1.0 / var[2], 1.0 / var[3]);
        let r = v.z - h;
        let jl = jac.landmark;
        let wjl = Matrix4x3W::from_fn(|i, j| w[i] * jl[(i, j)]);
        a += jl.transpose() * wjl;
        b += wjl.transpose() * r;
        chi2 += r.component_mul(&w).dot(&r);
        jlc += wjl.transpose() * jac.camera;
    }
    Some((a, b, chi2, jlc))
}

type Matrix4x3W = nalgebra::SMatrix<f64, 4, 3>;

/// The derivative of a triangulated point in the odometry's scale and yaw-rate scale,
/// columns of [`Triangulated::camera_jacobian`]: the frames' poses are the odometry's
/// integration back from the current pose `now`, so their offsets from it scale with the
/// reported speeds over the true (`1 / odom_scale`) and their heading changes with
/// `1 / odom_yaw_scale` (the offsets turning with half the change, an arc's chord). The
/// point's depth far out comes mostly from this motion: left out, a landmark born so would
/// carry the odometry's scale into the map as if it were the baseline's (measured: the
/// baseline's sigma halved and its error three sigma on a fisheye hall).
pub(crate) fn add_vehicle_sensitivity(
    camera: &CameraParams,
    views: &[View],
    now: &Pose2,
    t: &mut Triangulated,
    variances: impl Fn(&Measurement) -> [f64; 4],
) {
    const EPS: f64 = 1e-4;
    let v = camera.vehicle;
    let cases = [
        (rig_model::Param::OdomScale, v.odom_scale, 1.0, 0.0),
        (rig_model::Param::OdomYawScale, v.odom_yaw_scale, 0.0, 1.0),
    ];
    for (param, value, scale, yaw) in cases {
        if !(value.is_finite() && value > 0.0) {
            continue;
        }
        // A relative increase EPS of the parameter shrinks the motion by EPS.
        let moved: Vec<View> = views
            .iter()
            .map(|w| {
                let (dx, dy) = (w.pose.x - now.x, w.pose.y - now.y);
                let dtheta = rig_model::camera::wrap_angle(w.pose.theta - now.theta);
                let k = 1.0 - EPS * scale;
                let turn = -EPS * yaw * dtheta;
                let (s, c) = (libm::sin(turn / 2.0), libm::cos(turn / 2.0));
                View {
                    pose: Pose2 {
                        x: now.x + k * (c * dx - s * dy),
                        y: now.y + k * (s * dx + c * dy),
                        theta: now.theta + dtheta + turn,
                    },
                    z: w.z,
                }
            })
            .collect();
        if let Some(p) = triangulate_views(camera, &moved, t.position, &variances) {
            let d = (p.position - t.position) / (EPS * value);
            t.camera_jacobian.set_column(param.index(), &d);
        }
    }
}

/// The views a candidate keeps at most (the latest): enough for a second or two of motion.
pub(crate) const MAX_VIEWS: usize = 40;

/// Appends a view, dropping the oldest beyond [`MAX_VIEWS`].
pub(crate) fn push_view(views: &mut Vec<View>, view: View) {
    if views.len() >= MAX_VIEWS {
        views.remove(0);
    }
    views.push(view);
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used)]
mod tests {
    use super::*;
    use rig_model::Mount;

    fn camera() -> CameraParams {
        CameraParams {
            vehicle: Default::default(),
            f: 220.0,
            cx: 376.0,
            cy: 240.0,
            baseline: 0.12,
            mount: Mount::default(),
        }
    }

    #[test]
    fn views_from_a_moving_vehicle_give_the_point_and_its_camera_derivative() {
        let c = camera();
        let lamp = Vector3::new(3.0, 2.5, 3.3);
        let views: Vec<View> = (0..20)
            .map(|k| {
                let pose = Pose2 {
                    x: 0.05 * f64::from(k),
                    y: 0.0,
                    theta: 0.01 * f64::from(k),
                };
                View {
                    pose,
                    z: rig_model::project(&c, &pose, &lamp).unwrap(),
                }
            })
            .collect();
        let t = triangulate_views(&c, &views, Vector3::new(2.0, 1.0, 2.0), |_| [0.25; 4])
            .expect("settles");
        assert!((t.position - lamp).norm() < 1e-9, "{:?}", t.position);
        assert!(t.chi2 < 1e-12);
        assert_eq!(t.rows, 80);
        // The camera derivative against a finite difference in the baseline: the views
        // re-triangulated with the baseline changed (their pixels kept).
        let k = rig_model::Param::Baseline.index();
        let mut c2 = c;
        let h = 1e-6;
        c2.baseline += h;
        let t2 = triangulate_views(&c2, &views, lamp, |_| [0.25; 4]).expect("settles");
        let fd = (t2.position - t.position) / h;
        let an = t.camera_jacobian.column(k);
        assert!((fd - an).norm() < 1e-4 * an.norm().max(1.0), "{fd} vs {an}");
    }

    #[test]
    fn no_views_or_a_point_behind_the_cameras_give_nothing() {
        let c = camera();
        assert!(triangulate_views(&c, &[], Vector3::new(0.0, 0.0, 3.0), |_| [0.25; 4]).is_none());
        let pose = Pose2 {
            x: 0.0,
            y: 0.0,
            theta: 0.0,
        };
        let z = rig_model::project(&c, &pose, &Vector3::new(1.0, 0.0, 3.0)).unwrap();
        let views = [View { pose, z }];
        assert!(
            triangulate_views(&c, &views, Vector3::new(1.0, 0.0, 3.0), |_| [f64::NAN; 4]).is_none()
        );
    }
}
