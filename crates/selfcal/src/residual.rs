//! eq. (1), relative landmark motion, and its whitening.
//!
//! Landmarks triangulated in the robot frame at two instants, `L_t` and `L_{t+1}`, and the
//! odometry motion between them, `(dtheta, dT)`, must satisfy eq. (1):
//! `L_t = Rot_z(dtheta) L_{t+1} + dT`. The mismatch `E_L` of one landmark pair is
//! [`relative_landmark_motion`]; over the landmarks of one frame pair it is whitened by its
//! covariance from the pixel noise (the triangulation at both instants) and the odometry noise
//! shared by the pair's landmarks (`whitened_residual`), which is what eq. (2) weighs with `W`.

use alloc::vec::Vec;

use nalgebra::{Matrix3, Vector3};

use rig_model::camera::{CameraParams, rot_z};
use rig_model::config::Rig;
use rig_model::handover::FramePair;
use rig_model::rig::{ReducedMeasurement, RigError, check_triangulation_camera};

/// `x^2`.
pub(crate) fn sq(x: f64) -> f64 {
    x * x
}

/// `a . b`.
pub(crate) fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// eq. (1): relative landmark motion. One landmark seen at two instants and the odometry's
/// motion `(dtheta, dT)` between them: `E_L = L_t - (Rot_z(dtheta) L_{t+1} + dT)`, zero for the
/// true camera parameters and a perfect measurement.
///
/// Takes `L_t` (`l_t`), `Rot_z(dtheta) L_{t+1}` (`turned_l_next`: the solver turns the mount and
/// the rig-frame point separately, once per pair, so the rotation is applied by the caller) and
/// `dT = (dx, dy, 0)` (`d_t`), all in the robot frame at `t`. Its Jacobian with respect to the
/// motion is [`RelativeLandmarkMotion::jac_motion`].
#[inline]
pub fn relative_landmark_motion(
    l_t: &Vector3<f64>,
    turned_l_next: &Vector3<f64>,
    d_t: &Vector3<f64>,
) -> RelativeLandmarkMotion {
    let e_l = l_t - (turned_l_next + d_t);
    // dE/d(dtheta) = -dRz/dtheta L1 = ((R L1).y, -(R L1).x, 0).
    RelativeLandmarkMotion {
        e_l,
        de_ddtheta: Vector3::new(turned_l_next.y, -turned_l_next.x, 0.0),
    }
}

/// The residual of eq. (1) for one landmark pair ([`relative_landmark_motion`]) with the part
/// of its Jacobian that is not constant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RelativeLandmarkMotion {
    /// `E_L = L_t - (Rot_z(dtheta) L_{t+1} + dT)`, metres in the robot frame at `t`.
    pub e_l: Vector3<f64>,
    /// `dE_L / d(dtheta) = ((Rot_z L_{t+1}).y, -(Rot_z L_{t+1}).x, 0)`; `dE_L / d(dx, dy)` is
    /// `(-e_x, -e_y)` whatever the landmark.
    pub de_ddtheta: Vector3<f64>,
}

impl RelativeLandmarkMotion {
    /// `G = dE_L / d(dx, dy, dtheta) = [-e_x, -e_y, de_ddtheta]`.
    pub fn jac_motion(&self) -> Matrix3<f64> {
        Matrix3::from_columns(&[-Vector3::x(), -Vector3::y(), self.de_ddtheta])
    }
}

/// A camera with what every residual needs of it computed once.
pub(crate) struct Prepared {
    pub(crate) c: CameraParams,
    /// Whether [`triangulate`](rig_model::rig::triangulate) accepts `c`; when not, no landmark
    /// can be triangulated and every pair fails.
    valid: bool,
    robot_from_rig: Matrix3<f64>,
    mount: Vector3<f64>,
    /// `a a^T` for the optical axis in the robot frame, `a = R_RS e_z` (see [`landmark_terms`]).
    axis_outer: Matrix3<f64>,
}

impl Prepared {
    pub(crate) fn new(c: &CameraParams) -> Self {
        let robot_from_rig = c.mount.robot_from_rig_rotation();
        let axis = robot_from_rig.column(2).into_owned();
        Self {
            c: *c,
            valid: check_triangulation_camera(c).is_ok(),
            robot_from_rig,
            mount: c.mount.translation(),
            axis_outer: axis * axis.transpose(),
        }
    }
}

/// A frame pair reduced, once per solve, to what [`whitened_residual`] needs of it: none of this
/// depends on `C`.
pub(crate) struct PreparedPair {
    /// `Rot_z(dtheta)` of the odometry motion.
    rot: Matrix3<f64>,
    /// `dT = (dx, dy, 0)`.
    d_t: Vector3<f64>,
    /// Variance of the odometry error of `(dx, dy, dtheta)`; `None` when a component is zero,
    /// and the motion is then taken as exact (no shared error to solve for).
    motion_var: Option<Vector3<f64>>,
    /// Each landmark's measurements at both instants, reduced for triangulation.
    pub(crate) landmarks: Vec<[ReducedMeasurement; 2]>,
    /// Huber threshold of the pair ([`pair_threshold`]).
    pub(crate) threshold: f64,
}

impl PreparedPair {
    /// `None` for a pair no `C` can use: no landmark, or a measurement that cannot be
    /// triangulated (non-positive disparity, non-finite row).
    pub(crate) fn new(pair: &FramePair, rig: &Rig, huber_k: f64) -> Option<Self> {
        if pair.landmarks.is_empty() {
            return None;
        }
        let landmarks = pair
            .landmarks
            .iter()
            .map(|lm| {
                Ok([
                    ReducedMeasurement::new(&lm.first)?,
                    ReducedMeasurement::new(&lm.second)?,
                ])
            })
            .collect::<Result<Vec<_>, RigError>>()
            .ok()?;
        let m = &pair.motion;
        // Odometry noise: white velocity noise per sample, held for the sample period (errors
        // with memory as their white equivalent, `Noise::white_equivalent`).
        let motion_var = if m.samples > 0 {
            #[allow(clippy::cast_precision_loss)]
            let n = m.samples as f64;
            let period = m.dt_s / n;
            let noise = rig.noise.white_equivalent(period);
            Vector3::new(
                sq(noise.velocity * period) * n,
                sq(noise.velocity * period) * n,
                sq(noise.yaw_rate * period) * n,
            )
        } else {
            Vector3::zeros()
        };
        Some(Self {
            rot: rot_z(m.dtheta),
            d_t: Vector3::new(m.dx, m.dy, 0.0),
            motion_var: motion_var.iter().all(|&v| v > 0.0).then_some(motion_var),
            landmarks,
            threshold: pair_threshold(huber_k, pair),
        })
    }
}

/// Huber threshold of a frame pair: `huber_k` per landmark, grown with the pair's degrees of
/// freedom so that a pair of `k` good landmarks sits as far inside it as one landmark does.
fn pair_threshold(huber_k: f64, pair: &FramePair) -> f64 {
    #[allow(clippy::cast_precision_loss)]
    let k = pair.landmarks.len().max(1) as f64;
    huber_k * libm::sqrt(k)
}

/// What one landmark of a pair contributes to [`whitened_residual`]: `E_i` (eq. (1),
/// [`relative_landmark_motion`]), its covariance `D_i` from the pixel noise, and the `dtheta` column of `G_i = dE_i / d(dx, dy, dtheta)` (the other two
/// are `-e_x` and `-e_y`).
///
/// `D_i` is `J J^T sigma^2` summed over both instants, with `J` the robot-frame Jacobian of the
/// triangulated point with respect to its four pixels. Written out from
/// [`Triangulation::jac_measurement`](rig_model::rig::Triangulation::jac_measurement), which is
/// `B/d` times rows `(1/2 - xs/B, 0, 1/2 + xs/B, 0)`, `(-ys/B, 1/2, ys/B, 1/2)`,
/// `(-zs/B, 0, zs/B, 0)`, that product is `(B/d)^2 (diag(1, 1, 0) / 2 + 2 p p^T / B^2)` in
/// the rig frame; rotated into the robot frame, `diag(1, 1, 0)` becomes `I - a a^T` for the
/// optical axis `a`, and `(B/d)^2 p p^T / B^2` becomes `q q^T / d^2` for `q = R_RS p` (both
/// turned by `Rot_z(dtheta)` at the second instant). This closed form is the same matrix at a
/// fraction of the cost of forming `J` and multiplying.
#[inline]
fn landmark_terms(
    cam: &Prepared,
    per_pair: &PairCamera,
    pair: &PreparedPair,
    lm: &[ReducedMeasurement; 2],
    sigma2: f64,
) -> (Vector3<f64>, Matrix3<f64>, Vector3<f64>) {
    let [m0, m1] = lm;
    let (q0, q1) = (
        cam.robot_from_rig * m0.point_in_rig(&cam.c),
        per_pair.rot_robot_from_rig * m1.point_in_rig(&cam.c),
    );
    // L_t = t + R_RS p_t, and Rot_z L_{t+1} = Rot_z t + Rot_z R_RS p_{t+1}.
    let motion = relative_landmark_motion(&(cam.mount + q0), &(per_pair.rot_mount + q1), &pair.d_t);
    let (h0, h1) = (
        0.5 * sigma2 * sq(m0.scale(&cam.c)),
        0.5 * sigma2 * sq(m1.scale(&cam.c)),
    );
    let (w0, w1) = (
        2.0 * sigma2 * sq(m0.inv_disparity),
        2.0 * sigma2 * sq(m1.inv_disparity),
    );
    let (aa0, aa1) = (&cam.axis_outer, &per_pair.rot_axis_outer);
    let entry = |i: usize, j: usize| {
        let diagonal = if i == j { h0 + h1 } else { 0.0 };
        diagonal - h0 * aa0[(i, j)] - h1 * aa1[(i, j)] + w0 * q0[i] * q0[j] + w1 * q1[i] * q1[j]
    };
    let (d10, d20, d21) = (entry(1, 0), entry(2, 0), entry(2, 1));
    #[rustfmt::skip]
    let d = Matrix3::new(
        entry(0, 0), d10, d20,
        d10, entry(1, 1), d21,
        d20, d21, entry(2, 2),
    );
    (motion.e_l, d, motion.de_ddtheta)
}

/// The camera as seen through one pair's odometry rotation, shared by its landmarks.
struct PairCamera {
    /// `Rot_z(dtheta) R_RS`.
    rot_robot_from_rig: Matrix3<f64>,
    /// `Rot_z(dtheta) t`.
    rot_mount: Vector3<f64>,
    /// `(Rot_z a)(Rot_z a)^T` for the optical axis `a`.
    rot_axis_outer: Matrix3<f64>,
}

/// `L^-1` for the lower-triangular Cholesky factor `L` of a symmetric 3x3 matrix (`L L^T = m`,
/// read from its lower triangle), or `None` when `m` is not positive definite.
///
/// Written out because nalgebra's general factorisation and triangular solves cost several
/// times more at this size, and the whitening only ever applies `L^-1`. The square roots and
/// divisions dominate, and the textbook order chains them (each pivot waits for the previous
/// one's root). Here the pivots come from the leading minors instead, `L_kk^2 = det_k /
/// det_(k-1)`, so that the three divisions and the three roots are independent of each other.
#[inline]
fn inverse_cholesky_factor(m: &Matrix3<f64>) -> Option<Matrix3<f64>> {
    let (m00, m10, m11) = (m[(0, 0)], m[(1, 0)], m[(1, 1)]);
    let (m20, m21, m22) = (m[(2, 0)], m[(2, 1)], m[(2, 2)]);
    let det2 = m00 * m11 - m10 * m10;
    let det3 = m00 * (m11 * m22 - m21 * m21) - m10 * (m10 * m22 - m21 * m20)
        + m20 * (m10 * m21 - m11 * m20);
    // Positive definite iff every leading minor is positive (Sylvester); NaN fails too.
    if !(m00 > 0.0 && det2 > 0.0 && det3 > 0.0) {
        return None;
    }
    let (i11, i22, i33) = (
        libm::sqrt(1.0 / m00),
        libm::sqrt(m00 / det2),
        libm::sqrt(det2 / det3),
    );
    let (l21, l31) = (m10 * i11, m20 * i11);
    let l32 = (m21 - l31 * l21) * i22;
    let i21 = -l21 * i11 * i22;
    let i32 = -l32 * i22 * i33;
    let i31 = -(l31 * i11 + l32 * i21) * i33;
    #[rustfmt::skip]
    let l_inv = Matrix3::new(
        i11, 0.0, 0.0,
        i21, i22, 0.0,
        i31, i32, i33,
    );
    Some(l_inv)
}

/// eq. (1), whitened: the residual of one frame pair, appended to `out`: `E_L` of every
/// landmark seen at both instants ([`relative_landmark_motion`]), whitened by their joint
/// covariance from the pixel and the odometry noise (`W^1/2 E_L` of eq. (2)).
///
/// That covariance is the triangulation noise of each landmark at both instants (independent
/// between landmarks, `D_i`) plus the odometry noise `M` of the pair's motion, which is
/// *shared* by all its landmarks (`E = eps + G delta`, `delta ~ N(0, M)`): treating the
/// landmarks as independent would count the odometry error once per landmark and make the
/// sigmas of `C` too small. Rather than factor the dense `3k x 3k` matrix `D + G M G^T`, the
/// shared motion error is solved for in closed form (variable projection): with
/// `delta* = argmin sum |D_i^-1/2 (E_i - G_i delta)|^2 + |M^-1/2 delta|^2`, the vector
/// `[D_i^-1/2 (E_i - G_i delta*) ..., M^-1/2 delta*]` has exactly `E^T (D + G M G^T)^-1 E` as
/// its squared norm (a Schur complement), and only 3x3 systems are solved. `D_i^-1/2` is
/// `L_i^-1` for the lower Cholesky factor `L_i` of `D_i`.
///
/// Whitening with the covariance *at the same* `C` matters too: the triangulated points, and
/// so `E_L` and its covariance, scale with `f` (depth) and `B` (everything); measured in units
/// of its own uncertainty the error is unchanged by such a scaling unless the odometry's
/// metric motion pins it. A fixed weight would instead reward shrinking `f` or `B`.
///
/// Returns `false` (with `out` in an unspecified state past its old length) when the camera
/// cannot triangulate or a covariance is singular. `blocks` is scratch space reused between
/// calls (no allocation once grown).
pub(crate) fn whitened_residual(
    cam: &Prepared,
    pair: &PreparedPair,
    sigma2: f64,
    out: &mut Vec<f64>,
    blocks: &mut Vec<(Vector3<f64>, Matrix3<f64>)>,
) -> bool {
    if !cam.valid {
        return false;
    }
    blocks.clear();
    let rot_axis = pair.rot * cam.robot_from_rig.column(2);
    let per_pair = PairCamera {
        rot_robot_from_rig: pair.rot * cam.robot_from_rig,
        rot_mount: pair.rot * cam.mount,
        rot_axis_outer: rot_axis * rot_axis.transpose(),
    };
    // Normal equations of delta: a = sum G_i^T D_i^-1 G_i (+ M^-1), b = sum G_i^T D_i^-1 E_i.
    let mut a = Matrix3::zeros();
    let mut b = Vector3::zeros();
    for lm in &pair.landmarks {
        let (e, d, g_theta) = landmark_terms(cam, &per_pair, pair, lm, sigma2);
        let Some(l_inv) = inverse_cholesky_factor(&d) else {
            return false;
        };
        // L^-1 G_i, column by column: G_i = [-e_x, -e_y, g_theta].
        let g_w = Matrix3::from_columns(&[-l_inv.column(0), -l_inv.column(1), l_inv * g_theta]);
        let e_w = l_inv * e;
        a += g_w.transpose() * g_w;
        b += g_w.transpose() * e_w;
        blocks.push((e_w, g_w));
    }
    let delta = match pair.motion_var {
        Some(var) => {
            a += Matrix3::from_diagonal(&var.map(|v| 1.0 / v));
            let Some(a_inv_factor) = inverse_cholesky_factor(&a) else {
                return false;
            };
            a_inv_factor.transpose() * (a_inv_factor * b)
        }
        None => Vector3::zeros(),
    };
    let start = out.len();
    for (e_w, g_w) in blocks.iter() {
        out.extend_from_slice((e_w - g_w * delta).as_slice());
    }
    if let Some(var) = pair.motion_var {
        out.extend(
            delta
                .iter()
                .zip(var.iter())
                .map(|(d, v)| d / libm::sqrt(*v)),
        );
    }
    out[start..].iter().all(|v| v.is_finite())
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used)]
mod tests {
    use nalgebra::DMatrix;

    use super::*;
    use rig_model::camera::{Mount, Pose2};
    use rig_model::camera::{N_PARAMS, Param};
    use rig_model::config::Noise;
    use rig_model::handover::LandmarkPair;
    use rig_model::odometry::Motion;
    use rig_model::odometry::constant_velocity_motion;
    use rig_model::rig::Measurement;
    use rig_model::rig::{project, triangulate};

    /// A tilted head with every mount angle and offset non-zero, so that no term of the
    /// closed-form covariance vanishes.
    fn camera() -> CameraParams {
        CameraParams {
            vehicle: Default::default(),
            f: 702.0,
            cx: 376.0,
            cy: 240.0,
            baseline: 0.1215,
            mount: Mount {
                x: 0.3,
                y: -0.05,
                z: 1.2,
                roll: 0.04,
                pitch: 0.3,
                yaw: -0.1,
            },
        }
    }

    fn rig() -> Rig {
        let mut prior = [None; N_PARAMS];
        prior[Param::F.index()] = Some(30.0);
        prior[Param::Baseline.index()] = Some(0.01);
        Rig {
            lens: None,
            board: rig_model::Board::DEFAULT,
            width: 752,
            height: 480,
            nominal: camera(),
            estimate: alloc::vec![Param::F, Param::Baseline],
            prior,
            noise: Noise::white(0.3, 0.02, 0.01),
        }
    }

    /// Four lamps seen from two poses 50 ms apart on a turn, with pixel and odometry errors of
    /// a few sigma (fixed, not random).
    fn pair(c: &CameraParams, samples: usize) -> FramePair {
        let mut truth = Motion::default();
        for _ in 0..5 {
            truth = truth.then(&constant_velocity_motion(0.2, 0.0, 0.5, 0.01));
        }
        let pose0 = Pose2::new(1.0, -0.5, 0.3);
        let pose1 = truth.apply(&pose0);
        let lamps = [
            Vector3::new(3.2, 0.1, 3.5),
            Vector3::new(3.6, -0.9, 3.4),
            Vector3::new(2.5, 0.4, 3.6),
            Vector3::new(3.0, -0.2, 3.45),
        ];
        let mut k = 0.0;
        let mut noisy = |z: Measurement| {
            k += 1.0;
            z + Measurement::new(
                0.3 * libm::sin(1.7 * k),
                0.3 * libm::cos(2.3 * k),
                0.3 * libm::sin(0.9 * k + 1.0),
                0.3 * libm::cos(1.1 * k + 2.0),
            )
        };
        let landmarks = lamps
            .iter()
            .map(|l| LandmarkPair {
                first: noisy(project(c, &pose0, l).unwrap()),
                second: noisy(project(c, &pose1, l).unwrap()),
            })
            .collect();
        FramePair {
            t_us: 50_000,
            motion: Motion {
                dx: truth.dx + 4e-4,
                dy: truth.dy - 3e-4,
                dtheta: truth.dtheta + 2e-4,
                samples,
                ..truth
            },
            landmarks,
        }
    }

    /// The whitening as first written: `triangulate`'s Jacobians multiplied out, nalgebra's
    /// Cholesky and triangular solves.
    fn reference_whitened_residual(c: &CameraParams, pair: &FramePair, rig: &Rig) -> Vec<f64> {
        let sigma2 = sq(rig.noise.pixel);
        let (rr, mount) = (c.mount.robot_from_rig_rotation(), c.mount.translation());
        let m = &pair.motion;
        let rot = rot_z(m.dtheta);
        let mut blocks = Vec::new();
        let (mut a, mut b) = (Matrix3::zeros(), Vector3::zeros());
        for lm in &pair.landmarks {
            let (t0, t1) = (
                triangulate(c, &lm.first).unwrap(),
                triangulate(c, &lm.second).unwrap(),
            );
            let (l0, l1) = (mount + rr * t0.p_in_rig, mount + rr * t1.p_in_rig);
            let rl1 = rot * l1;
            let e = l0 - (rl1 + Vector3::new(m.dx, m.dy, 0.0));
            let (j0, j1) = (rr * t0.jac_measurement, rot * rr * t1.jac_measurement);
            let d = (j0 * j0.transpose() + j1 * j1.transpose()) * sigma2;
            let g = Matrix3::new(-1.0, 0.0, rl1.y, 0.0, -1.0, -rl1.x, 0.0, 0.0, 0.0);
            let chol = d.cholesky().unwrap();
            let d_inv_g = chol.solve(&g);
            a += g.transpose() * d_inv_g;
            b += d_inv_g.transpose() * e;
            blocks.push((e, chol, g));
        }
        let var = PreparedPair::new(pair, rig, 3.0).unwrap().motion_var;
        let delta = var.map_or_else(Vector3::zeros, |v| {
            (a + Matrix3::from_diagonal(&v.map(|v| 1.0 / v)))
                .cholesky()
                .unwrap()
                .solve(&b)
        });
        let mut out = Vec::new();
        for (e, chol, g) in &blocks {
            let w = chol.l().solve_lower_triangular(&(e - g * delta)).unwrap();
            out.extend_from_slice(w.as_slice());
        }
        if let Some(v) = var {
            out.extend(delta.iter().zip(v.iter()).map(|(d, v)| d / libm::sqrt(*v)));
        }
        out
    }

    /// `E^T (D + G M G^T)^-1 E` with the joint covariance of the pair's `3k` errors formed and
    /// factored densely: the definition that [`whitened_residual`] computes by variable projection.
    fn dense_mahalanobis2(c: &CameraParams, pair: &FramePair, rig: &Rig) -> f64 {
        let sigma2 = sq(rig.noise.pixel);
        let (rr, mount) = (c.mount.robot_from_rig_rotation(), c.mount.translation());
        let m = &pair.motion;
        let rot = rot_z(m.dtheta);
        let n = 3 * pair.landmarks.len();
        let (mut e_all, mut cov, mut g_all) = (
            DMatrix::zeros(n, 1),
            DMatrix::zeros(n, n),
            DMatrix::zeros(n, 3),
        );
        for (i, lm) in pair.landmarks.iter().enumerate() {
            let (t0, t1) = (
                triangulate(c, &lm.first).unwrap(),
                triangulate(c, &lm.second).unwrap(),
            );
            let rl1 = rot * (mount + rr * t1.p_in_rig);
            let e = mount + rr * t0.p_in_rig - (rl1 + Vector3::new(m.dx, m.dy, 0.0));
            let (j0, j1) = (rr * t0.jac_measurement, rot * rr * t1.jac_measurement);
            let d = (j0 * j0.transpose() + j1 * j1.transpose()) * sigma2;
            let g = Matrix3::new(-1.0, 0.0, rl1.y, 0.0, -1.0, -rl1.x, 0.0, 0.0, 0.0);
            e_all.view_mut((3 * i, 0), (3, 1)).copy_from(&e);
            cov.view_mut((3 * i, 3 * i), (3, 3)).copy_from(&d);
            g_all.view_mut((3 * i, 0), (3, 3)).copy_from(&g);
        }
        if let Some(v) = PreparedPair::new(pair, rig, 3.0).unwrap().motion_var {
            let mv = DMatrix::from_diagonal(&nalgebra::DVector::from_column_slice(v.as_slice()));
            cov += &g_all * mv * g_all.transpose();
        }
        let solved = cov.cholesky().unwrap().solve(&e_all);
        (e_all.transpose() * solved)[(0, 0)]
    }

    /// The closed-form covariance, the hand-written factorisation and the variable projection
    /// give the same whitened vector as the plain implementation, component by component (so
    /// the same Gauss-Newton Jacobian, not only the same cost), and its squared norm is the
    /// dense Mahalanobis distance.
    #[test]
    fn whitened_residual_matches_its_definition() {
        let (c, rig) = (camera(), rig());
        for samples in [5, 0] {
            let pair = pair(&c, samples);
            let prepared = PreparedPair::new(&pair, &rig, 3.0).unwrap();
            assert_eq!(prepared.motion_var.is_some(), samples > 0);
            let mut r = Vec::new();
            assert!(whitened_residual(
                &Prepared::new(&c),
                &prepared,
                sq(rig.noise.pixel),
                &mut r,
                &mut Vec::new()
            ));
            let reference = reference_whitened_residual(&c, &pair, &rig);
            assert_eq!(r.len(), reference.len());
            let scale = reference.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
            assert!(scale > 0.5, "errors of a few sigma: {reference:?}");
            for (k, (a, b)) in r.iter().zip(&reference).enumerate() {
                assert!((a - b).abs() <= 1e-9 * scale, "component {k}: {a} vs {b}");
            }
            let dense = dense_mahalanobis2(&c, &pair, &rig);
            assert!(
                (dot(&r, &r) - dense).abs() <= 1e-9 * dense,
                "{} vs {dense}",
                dot(&r, &r)
            );
        }
    }

    #[test]
    fn a_camera_that_cannot_triangulate_whitens_nothing() {
        let rig = rig();
        let prepared = PreparedPair::new(&pair(&camera(), 5), &rig, 3.0).unwrap();
        for (param, value) in [
            (Param::F, 0.0),
            (Param::Baseline, -0.1),
            (Param::Cx, f64::NAN),
        ] {
            let mut c = camera();
            c.set(param, value);
            let mut r = Vec::new();
            assert!(!whitened_residual(
                &Prepared::new(&c),
                &prepared,
                0.09,
                &mut r,
                &mut Vec::new()
            ));
        }
    }

    #[test]
    fn a_pair_with_a_measurement_that_cannot_be_triangulated_is_dropped() {
        let mut bad = pair(&camera(), 5);
        bad.landmarks[2].second[2] = bad.landmarks[2].second[0] + 1.0;
        assert!(PreparedPair::new(&bad, &rig(), 3.0).is_none());
        bad.landmarks.clear();
        assert!(PreparedPair::new(&bad, &rig(), 3.0).is_none());
    }

    #[test]
    fn inverse_cholesky_factor_matches_nalgebra() {
        // Symmetric positive definite matrices B B^T + eps I over a range of scales and
        // conditions (as D_i spans lateral and depth noise).
        for k in 0..200_u32 {
            let x = f64::from(k);
            let b = Matrix3::from_fn(|i, j| {
                #[allow(clippy::cast_precision_loss)]
                let (i, j) = (i as f64, j as f64);
                libm::sin(1.3 * x + 2.1 * i + 0.7 * j) * libm::pow(10.0, (i - 1.0) * (x % 4.0))
            });
            let scale = libm::pow(10.0, -(x % 7.0));
            let m = (b * b.transpose() + Matrix3::identity() * 1e-3) * scale;
            let ours = inverse_cholesky_factor(&m).expect("positive definite");
            let theirs = m.cholesky().unwrap().l().try_inverse().unwrap();
            assert!(
                (ours - theirs).norm() <= 1e-9 * theirs.norm(),
                "{m}: {ours} vs {theirs}"
            );
            assert!(
                (ours.upper_triangle() - Matrix3::from_diagonal(&ours.diagonal())).norm() == 0.0
            );
        }
        for m in [
            Matrix3::zeros(),
            Matrix3::from_diagonal(&Vector3::new(1.0, -1.0, 1.0)),
            Matrix3::new(1.0, 2.0, 0.0, 2.0, 1.0, 0.0, 0.0, 0.0, 1.0),
            Matrix3::new(1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0),
            Matrix3::identity() * f64::NAN,
        ] {
            assert!(inverse_cholesky_factor(&m).is_none(), "{m}");
            assert!(m.cholesky().is_none(), "{m}");
        }
    }

    /// [`RelativeLandmarkMotion::jac_motion`] against central differences of eq. (1) in
    /// `(dx, dy, dtheta)`.
    #[test]
    fn relative_landmark_motion_jacobian_matches_finite_differences() {
        let (l_t, l_next) = (Vector3::new(3.1, -0.4, 2.2), Vector3::new(2.7, 0.3, 2.25));
        let e = |m: &Vector3<f64>| {
            relative_landmark_motion(&l_t, &(rot_z(m.z) * l_next), &Vector3::new(m.x, m.y, 0.0)).e_l
        };
        let m = Vector3::new(0.3, -0.1, 0.2);
        let analytic =
            relative_landmark_motion(&l_t, &(rot_z(m.z) * l_next), &Vector3::new(m.x, m.y, 0.0))
                .jac_motion();
        let h = 1e-6;
        let numeric = Matrix3::from_fn(|i, j| {
            let mut step = Vector3::zeros();
            step[j] = h;
            (e(&(m + step))[i] - e(&(m - step))[i]) / (2.0 * h)
        });
        assert!(
            (analytic - numeric).norm() <= 1e-8,
            "{analytic} vs {numeric}"
        );
    }
}
