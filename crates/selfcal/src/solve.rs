//! The frame-pair solver: Levenberg-Marquardt over the estimated camera parameters `C`
//! ([`calibrate`]), minimising the whitened eq. (1) residual of every landmark of every frame
//! pair ([`crate::residual`]) with a Huber loss against wrong associations and the rig file's
//! priors, by steps of eq. (2) ([`crate::step::levenberg_marquardt_step`]) with an adaptive
//! damping `k`. Before and after solving, the observability analysis
//! ([`crate::observability`]) decides what is estimated and reports what is not.

// Loops over the ten parameter indices address several arrays at once.
#![allow(clippy::needless_range_loop)]

use alloc::vec::Vec;
use core::ops::Range;

use rig_model::camera::{CameraParams, N_PARAMS, Param, ParamVector};
use rig_model::config::Rig;
use rig_model::handover::{FramePair, Mat10, ObservabilityReport};

use crate::error::{Error, POSITIVE, check_fields};
use crate::observability::observability;
use crate::residual::{Prepared, PreparedPair, dot, sq, whitened_residual};
use crate::step::{covariance, levenberg_marquardt_step};

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
            if whitened_residual(&camera, pair, self.sigma2, &mut values, &mut blocks) {
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
                    whitened_residual(moved, pair, self.sigma2, column, &mut blocks)
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
pub(crate) fn estimated_mask(rig: &Rig) -> [bool; N_PARAMS] {
    let mut mask = [false; N_PARAMS];
    for p in &rig.estimate {
        mask[p.index()] = true;
    }
    mask
}

/// Prior precision (inverse variance) of each parameter; zero for those not estimated.
pub(crate) fn prior_precision(rig: &Rig, active: &[bool; N_PARAMS]) -> ParamVector {
    ParamVector::from_fn(|i, _| match (active[i], rig.prior[i]) {
        (true, Some(s)) if s > 0.0 => 1.0 / (s * s),
        _ => 0.0,
    })
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
                let Some(step) = levenberg_marquardt_step(&h, &g, lambda, &active) else {
                    lambda *= 10.0;
                    if lambda > 1e12 {
                        status = SolveStatus::Stalled;
                        break 'outer;
                    }
                    continue;
                };
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
