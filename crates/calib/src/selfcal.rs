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

use nalgebra::{DMatrix, Matrix3, SMatrix, Vector3};

use crate::camera::{CameraParams, N_PARAMS, Param, ParamVector, rot_z};
use crate::config::Rig;
use crate::odometry::Motion;
use crate::rig::{Measurement, triangulate};

fn sq(x: f64) -> f64 {
    x * x
}

/// Normal-equation matrices over all ten parameters.
type Mat10 = SMatrix<f64, N_PARAMS, N_PARAMS>;

/// One landmark seen at both instants of a frame pair.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LandmarkPair {
    /// `(uL, vL, uR, vR)` at the first instant.
    pub first: Measurement,
    /// `(uL, vL, uR, vR)` at the second instant.
    pub second: Measurement,
}

/// Two stereo frames close in time, the odometry motion between them, and the landmarks
/// associated across them.
#[derive(Debug, Clone, PartialEq)]
pub struct FramePair {
    /// Timestamp of the second frame, microseconds (for histories).
    pub t_us: u64,
    /// Motion from the first frame to the second, in the first frame's robot frame.
    pub motion: Motion,
    /// The landmarks seen in both.
    pub landmarks: Vec<LandmarkPair>,
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

/// How well one estimated parameter is constrained.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ParamObservability {
    /// The parameter.
    pub param: Param,
    /// Its prior sigma (rig file).
    pub prior_sigma: f64,
    /// Its sigma from the data alone (infinite when the data say nothing).
    pub data_sigma: f64,
    /// Its sigma from data and prior together.
    pub posterior_sigma: f64,
    /// Whether the data constrain it (`posterior_sigma <= observable_ratio * prior_sigma`).
    pub observable: bool,
    /// Why not, when it is not.
    pub reason: Option<&'static str>,
}

/// The observability analysis of the estimated parameters.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ObservabilityReport {
    /// One entry per estimated parameter.
    pub params: Vec<ParamObservability>,
    /// Largest absolute correlation between two estimated, observable parameters, and which.
    pub max_correlation: Option<(Param, Param, f64)>,
    /// Eigenvalues of the data's information matrix in prior-sigma units, ascending.
    pub information_eigenvalues: Vec<f64>,
}

impl ObservabilityReport {
    /// The parameters the data cannot give.
    pub fn unobservable(&self) -> impl Iterator<Item = &ParamObservability> {
        self.params.iter().filter(|p| !p.observable)
    }
}

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

/// A camera with the rotations that every residual needs computed once.
struct Prepared {
    c: CameraParams,
    robot_from_rig: Matrix3<f64>,
    mount: Vector3<f64>,
}

impl Prepared {
    fn new(c: &CameraParams) -> Self {
        Self {
            c: *c,
            robot_from_rig: c.mount.robot_from_rig_rotation(),
            mount: c.mount.translation(),
        }
    }
}

/// The whitened residual of one frame pair, written into `out` (cleared first): `E_L` of
/// every landmark seen at both instants, whitened by their joint covariance.
///
/// That covariance is the triangulation noise of each landmark at both instants (independent
/// between landmarks, `D_i`) plus the odometry noise `M` of the pair's motion, which is
/// *shared* by all its landmarks (`E = eps + G delta`, `delta ~ N(0, M)`): treating the
/// landmarks as independent would count the odometry error once per landmark and make the
/// sigmas of `C` too small. Rather than factor the dense `3k x 3k` matrix `D + G M G^T`, the
/// shared motion error is solved for in closed form (variable projection): with
/// `delta* = argmin sum |D_i^-1/2 (E_i - G_i delta)|^2 + |M^-1/2 delta|^2`, the vector
/// `[D_i^-1/2 (E_i - G_i delta*) ..., M^-1/2 delta*]` has exactly `E^T (D + G M G^T)^-1 E` as
/// its squared norm (a Schur complement), and only 3x3 systems are solved.
///
/// Whitening with the covariance *at the same* `C` matters too: the triangulated points, and
/// so `E_L` and its covariance, scale with `f` (depth) and `B` (everything); measured in units
/// of its own uncertainty the error is unchanged by such a scaling unless the odometry's
/// metric motion pins it. A fixed weight would instead reward shrinking `f` or `B`.
/// Returns `false` when a landmark cannot be triangulated or a covariance is singular.
/// Per-landmark pieces of [`whitened`]: `E_i`, the Cholesky factor of `D_i`, and `G_i`.
type Block = (
    Vector3<f64>,
    nalgebra::Cholesky<f64, nalgebra::U3>,
    Matrix3<f64>,
);

/// `blocks` is scratch space reused between calls (no allocation once grown).
fn whitened(
    prep: &Prepared,
    rot: &Matrix3<f64>,
    pair: &FramePair,
    rig: &Rig,
    out: &mut Vec<f64>,
    blocks: &mut Vec<Block>,
) -> bool {
    out.clear();
    blocks.clear();
    let c = &prep.c;
    let sigma2 = sq(rig.noise.pixel);
    let rr = &prep.robot_from_rig;
    let m = &pair.motion;
    // Per landmark: E_i, the Cholesky factor of D_i, and G_i (dE_i / d(dx, dy, dtheta)).
    let mut a = Matrix3::zeros();
    let mut b = Vector3::zeros();
    for lm in &pair.landmarks {
        let (Ok(t0), Ok(t1)) = (triangulate(c, &lm.first), triangulate(c, &lm.second)) else {
            return false;
        };
        let (l0, l1) = (prep.mount + rr * t0.p_in_rig, prep.mount + rr * t1.p_in_rig);
        let rl1 = rot * l1;
        let e = l0 - (rl1 + Vector3::new(m.dx, m.dy, 0.0));
        let (j0, j1) = (rr * t0.jac_measurement, rot * rr * t1.jac_measurement);
        let d = (j0 * j0.transpose() + j1 * j1.transpose()) * sigma2;
        // dE/d(dtheta) = -dRz/dtheta L1 = ((R L1).y, -(R L1).x, 0).
        let g = Matrix3::new(-1.0, 0.0, rl1.y, 0.0, -1.0, -rl1.x, 0.0, 0.0, 0.0);
        let Some(chol) = d.cholesky() else {
            return false;
        };
        let d_inv_g = chol.solve(&g);
        a += g.transpose() * d_inv_g;
        b += d_inv_g.transpose() * e;
        blocks.push((e, chol, g));
    }
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
    let mut delta = Vector3::zeros();
    if motion_var.iter().all(|&v| v > 0.0) {
        a += Matrix3::from_diagonal(&motion_var.map(|v| 1.0 / v));
        let Some(chol) = a.cholesky() else {
            return false;
        };
        delta = chol.solve(&b);
    }
    for (e, chol, g) in blocks.iter() {
        let Some(w) = chol.l().solve_lower_triangular(&(e - g * delta)) else {
            return false;
        };
        out.extend_from_slice(w.as_slice());
    }
    if motion_var.iter().all(|&v| v > 0.0) {
        out.extend(
            delta
                .iter()
                .zip(motion_var.iter())
                .map(|(d, v)| d / libm::sqrt(*v)),
        );
    }
    out.iter().all(|v| v.is_finite())
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
    cost: f64,
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

fn linearise(
    c: &CameraParams,
    pairs: &[FramePair],
    rig: &Rig,
    huber_k: f64,
    active: &[bool; N_PARAMS],
) -> Linearised {
    let mut out = Linearised {
        h: Mat10::zeros(),
        g: ParamVector::zeros(),
        cost: 0.0,
        residuals: 0,
        outliers: 0,
        chi2: 0.0,
    };
    let prep = Prepared::new(c);
    // Cameras displaced along each active parameter, for forward differences of the whitened
    // residual (its covariance depends on C too, which an analytic Jacobian of E_L misses).
    let mut displaced: [Option<(Prepared, f64)>; N_PARAMS] = Default::default();
    for i in 0..N_PARAMS {
        if active[i] {
            let h = fd_step(c, rig, i);
            let mut moved = *c;
            moved.set(Param::ALL[i], c.get(Param::ALL[i]) + h);
            displaced[i] = Some((Prepared::new(&moved), h));
        }
    }
    let mut r = Vec::new();
    let mut blocks = Vec::new();
    let mut moved_r: [Vec<f64>; N_PARAMS] = Default::default();
    for pair in pairs {
        if pair.landmarks.is_empty() {
            continue;
        }
        let rot = rot_z(pair.motion.dtheta);
        if !whitened(&prep, &rot, pair, rig, &mut r, &mut blocks) {
            continue;
        }
        let ok = displaced
            .iter()
            .zip(moved_r.iter_mut())
            .all(|(d, buf)| match d {
                Some((moved, _)) => {
                    whitened(moved, &rot, pair, rig, buf, &mut blocks) && buf.len() == r.len()
                }
                None => true,
            });
        if !ok {
            continue;
        }
        let d2: f64 = r.iter().map(|v| v * v).sum();
        let (weight, cost) = huber(libm::sqrt(d2), pair_threshold(huber_k, pair));
        if weight < 1.0 {
            out.outliers += 1;
        }
        // J[k, i] = (r_i[k] - r[k]) / h_i for the active parameters.
        for i in 0..N_PARAMS {
            let Some((_, hi)) = &displaced[i] else {
                continue;
            };
            let ji = |k: usize| (moved_r[i][k] - r[k]) / hi;
            out.g[i] += weight * (0..r.len()).map(|k| ji(k) * r[k]).sum::<f64>();
            for j in i..N_PARAMS {
                let Some((_, hj)) = &displaced[j] else {
                    continue;
                };
                let v = weight
                    * (0..r.len())
                        .map(|k| ji(k) * (moved_r[j][k] - r[k]) / hj)
                        .sum::<f64>();
                out.h[(i, j)] += v;
                if i != j {
                    out.h[(j, i)] += v;
                }
            }
        }
        out.cost += cost;
        out.chi2 += d2;
        out.residuals += pair.landmarks.len();
    }
    out
}

/// Huber threshold of a frame pair: `huber_k` per landmark, grown with the pair's degrees of
/// freedom so that a pair of `k` good landmarks sits as far inside it as one landmark does.
fn pair_threshold(huber_k: f64, pair: &FramePair) -> f64 {
    #[allow(clippy::cast_precision_loss)]
    let k = pair.landmarks.len().max(1) as f64;
    huber_k * libm::sqrt(k)
}

/// The robust cost at `c`.
fn cost_at(c: &CameraParams, pairs: &[FramePair], rig: &Rig, huber_k: f64) -> f64 {
    let prep = Prepared::new(c);
    let mut cost = 0.0;
    let mut r = Vec::new();
    let mut blocks = Vec::new();
    for pair in pairs.iter().filter(|p| !p.landmarks.is_empty()) {
        let rot = rot_z(pair.motion.dtheta);
        if whitened(&prep, &rot, pair, rig, &mut r, &mut blocks) {
            let norm = libm::sqrt(r.iter().map(|v| v * v).sum::<f64>());
            cost += huber(norm, pair_threshold(huber_k, pair)).1;
        }
    }
    cost
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
    let tilted = libm::fabs(c.mount.pitch) > 0.05 || libm::fabs(c.mount.roll) > 0.05;
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
        let reason = (!observable).then_some(match p {
            Param::F if !tilted => "with the camera looking straight up and planar motion, f and every landmark depth scale together: f is not observable unless the camera is tilted or a lamp height is known",
            Param::MountZ => "the camera height is not observable from planar motion: it cancels between the two instants",
            Param::MountX | Param::MountY | Param::MountYaw if total_rotation < 0.3 => "a straight path cannot give the mounting offsets: they cancel unless the vehicle turns",
            Param::MountRoll | Param::MountPitch if total_rotation < 0.3 => "a straight path cannot give the roll about the direction of travel: the vehicle must turn",
            _ => "the data so far constrain it less than its prior: more motion (turns, speed) or more landmarks are needed",
        });
        report.params.push(ParamObservability {
            param: *p,
            prior_sigma,
            data_sigma,
            posterior_sigma,
            observable,
            reason,
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
    let lin0 = linearise(&c, pairs, rig, settings.huber, &estimated);
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
        let start_changed = report.params.iter().any(|p| !p.observable);
        let mut lin = if start_changed {
            linearise(&c, pairs, rig, settings.huber, &active)
        } else {
            lin0
        };
        let mut cost = lin.cost + prior_cost(&c.to_vector());
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
                let new_cost = cost_at(&candidate, pairs, rig, settings.huber)
                    + prior_cost(&candidate.to_vector());
                if new_cost.is_finite() && new_cost <= cost {
                    c = candidate;
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
                    lin = linearise(&c, pairs, rig, settings.huber, &active);
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
        _ => linearise(&c, pairs, rig, settings.huber, &estimated),
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
/// `sigma_fraction` of its prior sigma, with at least `min_pairs` frame pairs used.
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
            min_pairs: 200,
            sigma_fraction: 0.2,
            step_fraction: 0.5,
            consecutive: 3,
        }
    }
}

/// What phase 1 hands to phase 2: the camera parameters with their covariance.
#[derive(Debug, Clone, PartialEq)]
pub struct Handover {
    /// The calibrated camera parameters.
    pub camera: CameraParams,
    /// Their covariance (zero rows for parameters not estimated or held at nominal).
    pub covariance: Mat10,
    /// Time of the frame at which calibration became stable, microseconds.
    pub t_us: u64,
    /// The observability report at hand-over.
    pub observability: ObservabilityReport,
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
        let any_observable = cal.observability.params.iter().any(|p| p.observable);
        self.stable_run = if steady && any_observable && self.pairs.len() >= self.rule.min_pairs {
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
