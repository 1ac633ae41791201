//! Phase 1 of the method: self-calibration of the camera parameters from relative motion.
//!
//! Landmarks triangulated in the robot frame at two instants, `L_t` and `L_{t+1}`, and the
//! odometry motion between them, `(dtheta, dT)`, must satisfy eq. (1):
//! `L_t = Rot_z(dtheta) L_{t+1} + dT`. The mismatch `E_L` over every landmark of every frame
//! pair drives a Levenberg-Marquardt update of the estimated camera parameters, eq. (2):
//! `dC = -(J^T W J + k D)^-1 J^T W E_L` (the paper writes it with `E_L` of the opposite sign and
//! `W = I`, `D = I`), with `W` the inverse covariance of `E_L` from the pixel and odometry noise,
//! a Huber loss against wrong associations, the rig file's priors, and an adaptive damping `k`.
//!
//! Before and after solving, an observability analysis compares what the data say about each
//! estimated parameter with its prior; a parameter the data cannot constrain is held at its
//! nominal value and reported with the reason (the known traps: an upward-looking camera on
//! planar motion cannot give `f`; planar motion never gives the camera height; a straight path
//! cannot give the mounting offsets or the roll).

// Loops over the ten parameter indices address several arrays at once.
#![allow(clippy::needless_range_loop)]

use alloc::vec::Vec;
use core::ops::Range;

use nalgebra::{DMatrix, Matrix3, Vector3};

use crate::error::{Error, check_fields};
use rig_model::camera::{CameraParams, N_PARAMS, Param, ParamVector, rot_z};
use rig_model::config::Rig;
use rig_model::handover::{FramePair, Handover, Mat10, ObservabilityReport, ParamObservability};
use rig_model::rig::{ReducedMeasurement, RigError, check_triangulation_camera};

fn sq(x: f64) -> f64 {
    x * x
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// Settings of the solver.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SolverSettings {
    /// Huber threshold on the Mahalanobis norm of a landmark's `E_L` (unitless).
    pub huber: f64,
    /// Most Levenberg-Marquardt iterations.
    pub max_iterations: usize,
    /// Convergence: every step below this fraction of the parameter's sigma.
    pub step_tolerance: f64,
    /// A parameter is observable when the data shrink its sigma to at most this fraction of
    /// its prior sigma.
    pub observable_ratio: f64,
}

impl Default for SolverSettings {
    fn default() -> Self {
        Self {
            huber: 3.0,
            max_iterations: 50,
            step_tolerance: 1e-2,
            observable_ratio: 0.5,
        }
    }
}

impl SolverSettings {
    /// Checks every field: the first out of its range is an [`Error::Setting`]. Any
    /// `max_iterations` is valid (0 returns the start, [`SolveStatus::MaxIterations`]).
    pub fn validate(&self) -> Result<(), Error> {
        check_fields(
            "SolverSettings",
            [
                (
                    "huber",
                    self.huber,
                    self.huber.is_finite() && self.huber > 0.0,
                    POSITIVE,
                ),
                (
                    "step_tolerance",
                    self.step_tolerance,
                    self.step_tolerance.is_finite() && self.step_tolerance > 0.0,
                    POSITIVE,
                ),
                (
                    "observable_ratio",
                    self.observable_ratio,
                    self.observable_ratio > 0.0 && self.observable_ratio <= 1.0,
                    "a number in (0, 1]",
                ),
            ],
        )
    }
}

/// What a positive real setting must be.
const POSITIVE: &str = "a positive finite number";

/// How a solve ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SolveStatus {
    /// Steps fell below the tolerance.
    Converged,
    /// The iteration limit came first; the best estimate is returned.
    MaxIterations,
    /// No step could lower the cost (damping exhausted); the best estimate is returned.
    Stalled,
    /// No usable landmark pair (nothing to estimate from); the nominal values are returned.
    NoData,
}

/// The result of a calibration: the best estimate with its uncertainty and the why.
#[derive(Debug, Clone, PartialEq)]
pub struct Calibration {
    /// The estimated camera parameters (unestimated and unobservable ones at nominal).
    pub camera: CameraParams,
    /// Covariance of all ten parameters (zero rows for those not estimated).
    pub covariance: Mat10,
    /// How the solve ended.
    pub status: SolveStatus,
    /// Iterations taken.
    pub iterations: usize,
    /// Landmark residuals used, and how many the robust loss down-weighted.
    pub residuals: usize,
    /// Residuals beyond the Huber threshold at the solution.
    pub outliers: usize,
    /// Sum of squared Mahalanobis norms at the solution divided by the degrees of freedom.
    pub reduced_chi2: f64,
    /// The observability analysis at the solution.
    pub observability: ObservabilityReport,
    /// The parameter vector after each accepted iteration (the start first).
    pub history: Vec<ParamVector>,
}

impl Calibration {
    /// 1-sigma uncertainty of one parameter (0 for a parameter held fixed).
    pub fn sigma(&self, p: Param) -> f64 {
        libm::sqrt(self.covariance[(p.index(), p.index())].max(0.0))
    }
}

/// A camera with what every residual needs of it computed once.
struct Prepared {
    c: CameraParams,
    /// Whether [`triangulate`](rig_model::rig::triangulate) accepts `c`; when not, no landmark
    /// can be triangulated and every pair fails.
    valid: bool,
    robot_from_rig: Matrix3<f64>,
    mount: Vector3<f64>,
    /// `a a^T` for the optical axis in the robot frame, `a = R_RS e_z` (see [`landmark_terms`]).
    axis_outer: Matrix3<f64>,
}

impl Prepared {
    fn new(c: &CameraParams) -> Self {
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

/// A frame pair reduced, once per solve, to what [`whitened`] needs of it: none of this
/// depends on `C`.
struct PreparedPair {
    /// `Rot_z(dtheta)` of the odometry motion.
    rot: Matrix3<f64>,
    /// `dT = (dx, dy, 0)`.
    d_t: Vector3<f64>,
    /// Variance of the odometry error of `(dx, dy, dtheta)`; `None` when a component is zero,
    /// and the motion is then taken as exact (no shared error to solve for).
    motion_var: Option<Vector3<f64>>,
    /// Each landmark's measurements at both instants, reduced for triangulation.
    landmarks: Vec<[ReducedMeasurement; 2]>,
    /// Huber threshold of the pair ([`pair_threshold`]).
    threshold: f64,
}

impl PreparedPair {
    /// `None` for a pair no `C` can use: no landmark, or a measurement that cannot be
    /// triangulated (non-positive disparity, non-finite row).
    fn new(pair: &FramePair, rig: &Rig, huber_k: f64) -> Option<Self> {
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
        // Odometry noise: white velocity noise per sample, held for the sample period.
        let motion_var = if m.samples > 0 {
            #[allow(clippy::cast_precision_loss)]
            let n = m.samples as f64;
            let period = m.dt_s / n;
            Vector3::new(
                sq(rig.noise.velocity * period) * n,
                sq(rig.noise.velocity * period) * n,
                sq(rig.noise.yaw_rate * period) * n,
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

/// What one landmark of a pair contributes to [`whitened`]: `E_i`, its covariance `D_i` from
/// the pixel noise, and the `dtheta` column of `G_i = dE_i / d(dx, dy, dtheta)` (the other two
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
    let rl1 = per_pair.rot_mount + q1;
    let e = (cam.mount + q0) - (rl1 + pair.d_t);
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
    // dE/d(dtheta) = -dRz/dtheta L1 = ((R L1).y, -(R L1).x, 0).
    (e, d, Vector3::new(rl1.y, -rl1.x, 0.0))
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

/// The whitened residual of one frame pair, appended to `out`: `E_L` of every landmark seen at
/// both instants, whitened by their joint covariance.
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
fn whitened(
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

/// Huber weight and cost of a whitened residual of norm `d`.
fn huber(d: f64, k: f64) -> (f64, f64) {
    if d <= k {
        (1.0, d * d)
    } else {
        (k / d, 2.0 * k * d - k * k)
    }
}

/// The linearised problem at one parameter vector.
struct Linearised {
    h: Mat10,
    g: ParamVector,
    residuals: usize,
    outliers: usize,
    chi2: f64,
}

/// Finite-difference step of each parameter.
fn fd_step(c: &CameraParams, rig: &Rig, i: usize) -> f64 {
    let scale = rig.prior[i]
        .unwrap_or(0.0)
        .max(libm::fabs(c.get(Param::ALL[i])) * 1e-3)
        .max(1e-6);
    scale * 1e-4
}

/// Huber threshold of a frame pair: `huber_k` per landmark, grown with the pair's degrees of
/// freedom so that a pair of `k` good landmarks sits as far inside it as one landmark does.
fn pair_threshold(huber_k: f64, pair: &FramePair) -> f64 {
    #[allow(clippy::cast_precision_loss)]
    let k = pair.landmarks.len().max(1) as f64;
    huber_k * libm::sqrt(k)
}

/// The whitened residuals of every pair at one `C`, with their robust cost. A trial step needs
/// only the cost; once accepted, the residuals are the base point of the next linearisation,
/// which so does not compute them again.
struct Evaluation {
    camera: Prepared,
    /// The residuals of all pairs, back to back.
    values: Vec<f64>,
    /// Per prepared pair, where its residual lies in `values`; `None` when it cannot be
    /// whitened at this `C`.
    spans: Vec<Option<Range<usize>>>,
    /// Robust cost (Huber) over the pairs that could be whitened.
    cost: f64,
    /// Pairs that could not be whitened at this `C` (a camera that cannot triangulate them).
    failed: usize,
}

/// The data of a solve, prepared once.
struct Problem<'a> {
    pairs: Vec<PreparedPair>,
    rig: &'a Rig,
    /// Pixel noise variance.
    sigma2: f64,
}

impl<'a> Problem<'a> {
    fn new(pairs: &[FramePair], rig: &'a Rig, huber_k: f64) -> Self {
        Self {
            pairs: pairs
                .iter()
                .filter_map(|p| PreparedPair::new(p, rig, huber_k))
                .collect(),
            rig,
            sigma2: sq(rig.noise.pixel),
        }
    }

    /// Whitened residuals and robust cost at `c`.
    fn evaluate(&self, c: &CameraParams) -> Evaluation {
        let camera = Prepared::new(c);
        let capacity = self.pairs.iter().map(|p| 3 * p.landmarks.len() + 3).sum();
        let mut values = Vec::with_capacity(capacity);
        let mut spans = Vec::with_capacity(self.pairs.len());
        let mut blocks = Vec::new();
        let mut cost = 0.0;
        let mut failed = 0;
        for pair in &self.pairs {
            let start = values.len();
            if whitened(&camera, pair, self.sigma2, &mut values, &mut blocks) {
                let norm = libm::sqrt(values[start..].iter().map(|v| v * v).sum::<f64>());
                cost += huber(norm, pair.threshold).1;
                spans.push(Some(start..values.len()));
            } else {
                values.truncate(start);
                spans.push(None);
                failed += 1;
            }
        }
        Evaluation {
            camera,
            values,
            spans,
            cost,
            failed,
        }
    }

    /// Gauss-Newton normal equations of the robust cost at `base` over the `active` parameters.
    fn linearise(&self, base: &Evaluation, active: &[bool; N_PARAMS]) -> Linearised {
        let mut out = Linearised {
            h: Mat10::zeros(),
            g: ParamVector::zeros(),
            residuals: 0,
            outliers: 0,
            chi2: 0.0,
        };
        let c = &base.camera.c;
        // Cameras displaced along each active parameter `i` by `h`, for forward differences of
        // the whitened residual (its covariance depends on C too, which an analytic Jacobian
        // of E_L misses).
        let displaced: Vec<(usize, Prepared, f64)> = (0..N_PARAMS)
            .filter(|&i| active[i])
            .map(|i| {
                let h = fd_step(c, self.rig, i);
                let mut moved = *c;
                moved.set(Param::ALL[i], c.get(Param::ALL[i]) + h);
                (i, Prepared::new(&moved), h)
            })
            .collect();
        let mut blocks = Vec::new();
        // Per displaced camera, its residual, then in place the Jacobian column.
        let mut columns: Vec<Vec<f64>> = alloc::vec![Vec::new(); displaced.len()];
        for (pair, span) in self.pairs.iter().zip(&base.spans) {
            let Some(span) = span else {
                continue;
            };
            let r = &base.values[span.clone()];
            let ok = displaced
                .iter()
                .zip(columns.iter_mut())
                .all(|((_, moved, _), column)| {
                    column.clear();
                    whitened(moved, pair, self.sigma2, column, &mut blocks)
                });
            if !ok {
                continue;
            }
            let d2 = dot(r, r);
            let (weight, _) = huber(libm::sqrt(d2), pair.threshold);
            if weight < 1.0 {
                out.outliers += 1;
            }
            // J[k, i] = (r_i[k] - r[k]) / h_i.
            for ((_, _, h), column) in displaced.iter().zip(columns.iter_mut()) {
                let inv_h = 1.0 / h;
                column
                    .iter_mut()
                    .zip(r)
                    .for_each(|(j, r)| *j = (*j - r) * inv_h);
            }
            for (a, (i, ..)) in displaced.iter().enumerate() {
                out.g[*i] += weight * dot(&columns[a], r);
                for (b, (j, ..)) in displaced.iter().enumerate().skip(a) {
                    let v = weight * dot(&columns[a], &columns[b]);
                    out.h[(*i, *j)] += v;
                    if i != j {
                        out.h[(*j, *i)] += v;
                    }
                }
            }
            out.chi2 += d2;
            out.residuals += pair.landmarks.len();
        }
        out
    }
}

/// `true` at the rig's estimated parameters.
fn estimated_mask(rig: &Rig) -> [bool; N_PARAMS] {
    let mut mask = [false; N_PARAMS];
    for p in &rig.estimate {
        mask[p.index()] = true;
    }
    mask
}

/// Prior precision (inverse variance) of each parameter; zero for those not estimated.
fn prior_precision(rig: &Rig, active: &[bool; N_PARAMS]) -> ParamVector {
    ParamVector::from_fn(|i, _| match (active[i], rig.prior[i]) {
        (true, Some(s)) if s > 0.0 => 1.0 / (s * s),
        _ => 0.0,
    })
}

/// Restricts a 10x10 system to `active` parameters: inactive rows and columns become the
/// identity, so that their step is zero.
fn masked(h: &Mat10, active: &[bool; N_PARAMS]) -> Mat10 {
    let mut m = *h;
    for i in 0..N_PARAMS {
        if !active[i] {
            m.row_mut(i).fill(0.0);
            m.column_mut(i).fill(0.0);
            m[(i, i)] = 1.0;
        }
    }
    m
}

fn covariance(h: &Mat10, active: &[bool; N_PARAMS]) -> Mat10 {
    let mut cov = masked(h, active)
        .cholesky()
        .map_or_else(Mat10::zeros, |ch| ch.inverse());
    for i in 0..N_PARAMS {
        if !active[i] {
            cov.row_mut(i).fill(0.0);
            cov.column_mut(i).fill(0.0);
        }
    }
    cov
}

/// The known trap of the rig and the path that makes `p` unobservable, if any: an upward head
/// (`tilted` false) for `f`, planar motion for the camera height, a straight path
/// (`total_rotation_rad`, the sum of the odometry's absolute yaw changes, under 0.3 rad) for
/// the mounting offsets and angles and the odometry's yaw scale, and a path without changes
/// of speed or heading (`speed_change_mps`, the sum of the absolute changes of speed between
/// frames, under 0.2 m/s, and no turn) for the clock offset (vehicle-interfaces.md 1.2).
/// Anything else is a lack of data so far.
pub fn structural_trap(
    p: Param,
    tilted: bool,
    total_rotation_rad: f64,
    speed_change_mps: f64,
) -> Option<&'static str> {
    match p {
        Param::OdomYawScale if total_rotation_rad < 0.3 => Some(
            "the odometry's yaw scale needs turns: on a straight path the yaw rate is zero whatever its scale",
        ),
        Param::TimeOffset if total_rotation_rad < 0.3 && speed_change_mps < 0.2 => Some(
            "the clock offset needs changes of speed or heading: at a constant velocity it only shifts the path",
        ),
        Param::F if !tilted => Some(
            "with the camera looking straight up and planar motion, f and every landmark depth scale together: f is not observable unless the camera is tilted or a lamp height is known",
        ),
        Param::MountZ => Some(
            "the camera height is not observable from planar motion: it cancels between the two instants",
        ),
        Param::MountX | Param::MountY | Param::MountYaw if total_rotation_rad < 0.3 => Some(
            "a straight path cannot give the mounting offsets: they cancel unless the vehicle turns",
        ),
        Param::MountRoll | Param::MountPitch if total_rotation_rad < 0.3 => Some(
            "a straight path cannot give the roll about the direction of travel: the vehicle must turn",
        ),
        _ => None,
    }
}

/// Observability of the estimated parameters from the data's information matrix `h_data`.
fn observability(
    h_data: &Mat10,
    rig: &Rig,
    pairs: &[FramePair],
    c: &CameraParams,
    settings: &SolverSettings,
) -> ObservabilityReport {
    let estimated = estimated_mask(rig);
    let prior = prior_precision(rig, &estimated);
    let posterior = covariance(&(h_data + Mat10::from_diagonal(&prior)), &estimated);
    let total_rotation: f64 = pairs.iter().map(|p| libm::fabs(p.motion.dtheta)).sum();
    let tilted = c.mount.is_tilted();
    let mut report = ObservabilityReport::default();
    // Information in prior-sigma units: S H S with S = diag(prior sigma).
    let mut scaled = Mat10::identity();
    let idx: Vec<usize> = rig.estimate.iter().map(|p| p.index()).collect();
    for &i in &idx {
        for &j in &idx {
            let (si, sj) = (rig.prior[i].unwrap_or(1.0), rig.prior[j].unwrap_or(1.0));
            scaled[(i, j)] = h_data[(i, j)] * si * sj;
        }
    }
    let sub = DMatrix::from_fn(idx.len(), idx.len(), |a, b| scaled[(idx[a], idx[b])]);
    let mut eig: Vec<f64> = sub.symmetric_eigenvalues().iter().copied().collect();
    eig.sort_by(f64::total_cmp);
    report.information_eigenvalues = eig;
    for p in &rig.estimate {
        let i = p.index();
        let prior_sigma = rig.prior[i].unwrap_or(f64::INFINITY);
        let posterior_sigma = libm::sqrt(posterior[(i, i)].max(0.0));
        let info = h_data[(i, i)];
        let data_sigma = if info > 0.0 {
            1.0 / libm::sqrt(info)
        } else {
            f64::INFINITY
        };
        let observable = posterior_sigma <= settings.observable_ratio * prior_sigma;
        // The known traps are properties of the rig and the path; anything else is a lack of
        // data so far, which more driving may cure.
        // The pair solver does not model V (its motions are fixed): no speed term.
        let trap = structural_trap(*p, tilted, total_rotation, f64::INFINITY);
        let reason = (!observable).then_some(trap.unwrap_or(
            "the data so far constrain it less than its prior: more motion (turns, speed) or more landmarks are needed",
        ));
        let structural = !observable && trap.is_some();
        report.params.push(ParamObservability {
            param: *p,
            prior_sigma,
            data_sigma,
            posterior_sigma,
            observable,
            reason,
            structural,
        });
    }
    let obs: Vec<usize> = report
        .params
        .iter()
        .filter(|p| p.observable)
        .map(|p| p.param.index())
        .collect();
    for (a, &i) in obs.iter().enumerate() {
        for &j in obs.iter().skip(a + 1) {
            let denom = libm::sqrt(posterior[(i, i)] * posterior[(j, j)]);
            if denom > 0.0 {
                let r = posterior[(i, j)] / denom;
                if report
                    .max_correlation
                    .is_none_or(|(_, _, m)| libm::fabs(r) > libm::fabs(m))
                {
                    report.max_correlation = Some((Param::ALL[i], Param::ALL[j], r));
                }
            }
        }
    }
    report
}

/// Calibrates the rig's estimated parameters from frame pairs (batch), starting from `start`
/// (usually the nominal values, or the last estimate when fed incrementally).
///
/// Parameters the data cannot constrain are held at their nominal values and reported in
/// [`Calibration::observability`]. Never fails: without data it returns the nominal values with
/// [`SolveStatus::NoData`], and when the iterations run out or stall it returns the best
/// estimate with the status saying so.
pub fn calibrate(
    pairs: &[FramePair],
    rig: &Rig,
    start: &CameraParams,
    settings: &SolverSettings,
) -> Calibration {
    let nominal = rig.nominal.to_vector();
    let mut c = *start;
    // Observability at the start decides what is estimated.
    let estimated = estimated_mask(rig);
    let problem = Problem::new(pairs, rig, settings.huber);
    let mut eval = problem.evaluate(&c);
    let lin0 = problem.linearise(&eval, &estimated);
    let report = observability(&lin0.h, rig, pairs, &c, settings);
    let mut active = [false; N_PARAMS];
    for p in report.params.iter().filter(|p| p.observable) {
        active[p.param.index()] = true;
    }
    for i in 0..N_PARAMS {
        if !active[i] {
            c.set(Param::ALL[i], nominal[i]);
        }
    }
    let prior = prior_precision(rig, &active);
    let prior_cost = |v: &ParamVector| -> f64 {
        (0..N_PARAMS)
            .map(|i| prior[i] * sq(v[i] - nominal[i]))
            .sum()
    };
    let mut history = alloc::vec![c.to_vector()];
    let mut status = if lin0.residuals == 0 {
        SolveStatus::NoData
    } else {
        SolveStatus::MaxIterations
    };
    let mut iterations = 0;
    let mut lambda = 1e-3;
    let mut last_lin = None;
    if status != SolveStatus::NoData && active.iter().any(|&a| a) {
        // The start moved when a parameter is held at nominal that `start` had elsewhere
        // (unobservable, or not estimated at all): evaluate again there.
        let start_changed = c != *start || report.params.iter().any(|p| !p.observable);
        let mut lin = if start_changed {
            eval = problem.evaluate(&c);
            problem.linearise(&eval, &active)
        } else {
            lin0
        };
        let mut cost = eval.cost + prior_cost(&c.to_vector());
        'outer: while iterations < settings.max_iterations {
            iterations += 1;
            let v = c.to_vector();
            let h = lin.h + Mat10::from_diagonal(&prior);
            let g = lin.g + prior.component_mul(&(v - nominal));
            loop {
                let mut damped = h;
                for i in 0..N_PARAMS {
                    damped[(i, i)] += lambda * h[(i, i)].max(1e-12);
                }
                let Some(ch) = masked(&damped, &active).cholesky() else {
                    lambda *= 10.0;
                    if lambda > 1e12 {
                        status = SolveStatus::Stalled;
                        break 'outer;
                    }
                    continue;
                };
                let mut step = -ch.solve(&g);
                for i in 0..N_PARAMS {
                    if !active[i] {
                        step[i] = 0.0;
                    }
                }
                let candidate = CameraParams::from_vector(&(v + step));
                let trial = problem.evaluate(&candidate);
                let new_cost = trial.cost + prior_cost(&candidate.to_vector());
                // A step that loses pairs (a camera that can no longer triangulate them) would
                // look cheaper than it is: refused like a step that raises the cost.
                if new_cost.is_finite() && new_cost <= cost && trial.failed <= eval.failed {
                    c = candidate;
                    eval = trial;
                    lambda = (lambda * 0.1).max(1e-9);
                    history.push(c.to_vector());
                    cost = new_cost;
                    // Converged when every step is a small fraction of the parameter's sigma.
                    let cov = covariance(&h, &active);
                    let small = (0..N_PARAMS).all(|i| {
                        !active[i]
                            || libm::fabs(step[i])
                                <= settings.step_tolerance * libm::sqrt(cov[(i, i)].max(1e-300))
                    });
                    if small {
                        status = SolveStatus::Converged;
                        break 'outer;
                    }
                    lin = problem.linearise(&eval, &active);
                    break;
                }
                lambda *= 10.0;
                if lambda > 1e12 {
                    // No step lowers the cost: at a minimum (to numerical precision).
                    status = SolveStatus::Converged;
                    break 'outer;
                }
            }
        }
        last_lin = Some(lin);
    }
    // The last linearisation serves for the covariance when it covers every estimated
    // parameter (the final step, below 1 % of a sigma, does not change it measurably).
    let lin = match last_lin {
        Some(lin) if active == estimated => lin,
        _ => problem.linearise(&problem.evaluate(&c), &estimated),
    };
    let covariance = covariance(&(lin.h + Mat10::from_diagonal(&prior)), &active);
    let dof = (3 * lin.residuals).saturating_sub(active.iter().filter(|&&a| a).count());
    #[allow(clippy::cast_precision_loss)]
    let reduced_chi2 = if dof > 0 { lin.chi2 / dof as f64 } else { 0.0 };
    let observability = observability(&lin.h, rig, pairs, &c, settings);
    Calibration {
        camera: c,
        covariance,
        status,
        iterations,
        residuals: lin.residuals,
        outliers: lin.outliers,
        reduced_chi2,
        observability,
        history,
    }
}

/// The rule that decides that calibration has converged and phase 2 may start: for
/// `consecutive` solves in a row, every estimated, observable parameter moved less than
/// `step_fraction` of its sigma since the previous solve and its sigma is at most
/// `sigma_fraction` of its prior sigma, with at least `min_pairs` frame pairs used; and no
/// estimated parameter is still waiting for data (unobservable for lack of data rather than
/// because of a known trap, [`ParamObservability::structural`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StableRule {
    /// Fewest frame pairs before calibration can be stable.
    pub min_pairs: usize,
    /// Largest posterior / prior sigma ratio of every observable estimated parameter.
    pub sigma_fraction: f64,
    /// Largest change between consecutive solves, in posterior sigmas.
    pub step_fraction: f64,
    /// Solves in a row that must satisfy the above.
    pub consecutive: usize,
}

impl Default for StableRule {
    fn default() -> Self {
        Self {
            // About 80 s of driving at the usual 2 s between the frames of a pair.
            min_pairs: 40,
            sigma_fraction: 0.2,
            // Each solve adds some 10 % more data, which moves an estimate by about a third of
            // its sigma on average: half a sigma was exceeded by chance too often to ever hold
            // three times in a row.
            step_fraction: 1.0,
            consecutive: 3,
        }
    }
}

impl StableRule {
    /// Checks every field: the first out of its range is an [`Error::Setting`]. Any
    /// `min_pairs` is valid.
    pub fn validate(&self) -> Result<(), Error> {
        #[allow(clippy::cast_precision_loss)] // a count shown in the message only
        let consecutive = self.consecutive as f64;
        check_fields(
            "StableRule",
            [
                (
                    "sigma_fraction",
                    self.sigma_fraction,
                    self.sigma_fraction.is_finite() && self.sigma_fraction > 0.0,
                    POSITIVE,
                ),
                (
                    "step_fraction",
                    self.step_fraction,
                    self.step_fraction.is_finite() && self.step_fraction > 0.0,
                    POSITIVE,
                ),
                (
                    "consecutive",
                    consecutive,
                    self.consecutive >= 1,
                    "at least 1",
                ),
            ],
        )
    }
}

/// Phase 1 fed frame by frame: collects frame pairs, re-solves every `solve_every` pairs
/// (warm-started), and decides by [`StableRule`] when the calibration is stable.
#[derive(Debug, Clone)]
pub struct SelfCalibrator {
    rig: Rig,
    settings: SolverSettings,
    rule: StableRule,
    solve_every: usize,
    pairs: Vec<FramePair>,
    last: Option<Calibration>,
    /// Estimated parameter vector after each solve, with the time of its last pair.
    history: Vec<(u64, ParamVector, ParamVector)>,
    stable_run: usize,
    stable: Option<Handover>,
}

impl SelfCalibrator {
    /// A calibrator for this rig.
    pub fn new(rig: Rig, settings: SolverSettings, rule: StableRule, solve_every: usize) -> Self {
        Self {
            rig,
            settings,
            rule,
            solve_every: solve_every.max(1),
            pairs: Vec::new(),
            last: None,
            history: Vec::new(),
            stable_run: 0,
            stable: None,
        }
    }

    /// Adds a frame pair; returns the new calibration when this pair triggered a solve.
    pub fn add_pair(&mut self, pair: FramePair) -> Option<&Calibration> {
        let t_us = pair.t_us;
        self.pairs.push(pair);
        if !self.pairs.len().is_multiple_of(self.solve_every) {
            return None;
        }
        let start = self.last.as_ref().map_or(self.rig.nominal, |c| c.camera);
        let cal = calibrate(&self.pairs, &self.rig, &start, &self.settings);
        let sigmas = ParamVector::from_fn(|i, _| cal.sigma(Param::ALL[i]));
        let v = cal.camera.to_vector();
        let steady = self.history.last().is_some_and(|(_, prev, _)| {
            cal.observability
                .params
                .iter()
                .filter(|p| p.observable)
                .all(|p| {
                    let i = p.param.index();
                    libm::fabs(v[i] - prev[i]) <= self.rule.step_fraction * sigmas[i]
                        && p.posterior_sigma <= self.rule.sigma_fraction * p.prior_sigma
                })
        });
        let params = &cal.observability.params;
        let any_observable = params.iter().any(|p| p.observable);
        // A parameter still waiting for data blocks the hand-over; one that a known trap makes
        // unobservable (held at nominal, reported) does not.
        let none_waiting = params.iter().all(|p| p.observable || p.structural);
        self.stable_run = if steady
            && any_observable
            && none_waiting
            && self.pairs.len() >= self.rule.min_pairs
        {
            self.stable_run + 1
        } else {
            0
        };
        self.history.push((t_us, v, sigmas));
        if self.stable.is_none() && self.stable_run >= self.rule.consecutive {
            self.stable = Some(Handover {
                camera: cal.camera,
                covariance: cal.covariance,
                t_us,
                observability: cal.observability.clone(),
            });
        }
        self.last = Some(cal);
        self.last.as_ref()
    }

    /// The latest calibration, if any solve ran.
    pub fn latest(&self) -> Option<&Calibration> {
        self.last.as_ref()
    }

    /// The hand-over to phase 2, once calibration is stable.
    pub fn handover(&self) -> Option<&Handover> {
        self.stable.as_ref()
    }

    /// `(t_us, parameters, sigmas)` after each solve: the history of C.
    pub fn history(&self) -> &[(u64, ParamVector, ParamVector)] {
        &self.history
    }

    /// Frame pairs collected.
    pub fn pairs(&self) -> usize {
        self.pairs.len()
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used)]
mod tests {
    use nalgebra::DMatrix;

    use super::*;
    use rig_model::camera::{Mount, Pose2};
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
            width: 752,
            height: 480,
            nominal: camera(),
            estimate: alloc::vec![Param::F, Param::Baseline],
            prior,
            noise: Noise {
                pixel: 0.3,
                velocity: 0.02,
                yaw_rate: 0.01,
            },
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
    fn reference_whitened(c: &CameraParams, pair: &FramePair, rig: &Rig) -> Vec<f64> {
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
    /// factored densely: the definition that [`whitened`] computes by variable projection.
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
            assert!(whitened(
                &Prepared::new(&c),
                &prepared,
                sq(rig.noise.pixel),
                &mut r,
                &mut Vec::new()
            ));
            let reference = reference_whitened(&c, &pair, &rig);
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
            assert!(!whitened(
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
}
