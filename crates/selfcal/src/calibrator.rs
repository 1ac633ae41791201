//! The incremental calibrator: phase 1 fed pair by pair ([`SelfCalibrator`]), re-solving as
//! frame pairs come in and deciding by [`StableRule`] when `C` is stable enough to hand over
//! to phase 2.

use alloc::vec::Vec;

use rig_model::camera::{Param, ParamVector};
use rig_model::config::Rig;
use rig_model::handover::{FramePair, Handover};

use crate::error::{Error, POSITIVE, check_fields};
use crate::solve::{Calibration, SolverSettings, calibrate};

/// The rule that decides that calibration has converged and phase 2 may start: for
/// `consecutive` solves in a row, every estimated, observable parameter moved less than
/// `step_fraction` of its sigma since the previous solve and its sigma is at most
/// `sigma_fraction` of its prior sigma, with at least `min_pairs` frame pairs used; and no
/// estimated parameter is still waiting for data (unobservable for lack of data rather than
/// because of a known trap, [`ParamObservability::structural`](rig_model::handover::ParamObservability::structural)).
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
