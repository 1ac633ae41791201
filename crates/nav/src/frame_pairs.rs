//! Phase 1 by the paper's frame pairs: the navigator's calibration-only mode
//! ([`NavMode::CalibrateFramePairs`](crate::NavMode::CalibrateFramePairs)).
//!
//! The navigator's association ([`track::FrontEnd`]) feeds [`track::PairBuilder`], whose frame
//! pairs (two frames `stride` apart with the odometry between them, eq. (1)) go to the
//! incremental calibrator ([`SelfCalibrator`]) until it is stable, and are all kept for one
//! batch solve at the end ([`FramePairCalibration::calibrate`]). This is `stereonav calibrate`
//! (`replay::calibrate_log`); the navigator's own phase 1 is the batch over every frame
//! (`selfcal::smoother`), which needs no pairing.

use alloc::vec::Vec;

use rig_model::camera::ParamVector;
use rig_model::config::Rig;
use rig_model::handover::{FramePair, Handover};
use rig_model::odometry::OdomSample;
use selfcal::calibrator::{SelfCalibrator, StableRule};
use selfcal::solve::{Calibration, SolverSettings, calibrate};
use track::{PairBuilder, PairSettings, TrackedFrame};

use crate::Error;

/// How the calibration-only mode pairs frames and calibrates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FramePairSettings {
    /// Phase 1's frame pairs.
    pub pairs: PairSettings,
    /// The phase-1 solver.
    pub solver: SolverSettings,
    /// When the incremental calibration counts as stable (its hand-over time).
    pub stable: StableRule,
    /// The incremental calibrator re-solves every this many pairs.
    pub solve_every: usize,
}

impl Default for FramePairSettings {
    /// The crates' defaults; the incremental calibrator re-solves every 10 pairs (20 s of
    /// driving at the default 40 frames between the frames of a pair).
    fn default() -> Self {
        Self {
            pairs: PairSettings::default(),
            solver: SolverSettings::default(),
            stable: StableRule::default(),
            solve_every: 10,
        }
    }
}

impl FramePairSettings {
    /// Checks every setting; the error names the first one out of range.
    pub fn validate(&self) -> Result<(), Error> {
        self.pairs.validate()?;
        self.solver.validate()?;
        self.stable.validate()?;
        if self.solve_every == 0 {
            return Err(Error::Settings {
                name: "solve_every",
                value: 0.0,
                expected: "at least 1",
            });
        }
        Ok(())
    }
}

/// The frame pairs of a drive, the incremental calibration over them and the batch solve.
#[derive(Debug, Clone)]
pub struct FramePairCalibration {
    rig: Rig,
    solver: SolverSettings,
    builder: PairBuilder,
    incremental: SelfCalibrator,
    pairs: Vec<FramePair>,
}

impl FramePairCalibration {
    /// A calibration for this rig, from its nominal parameters.
    pub fn new(rig: &Rig, settings: &FramePairSettings) -> Result<Self, Error> {
        settings.validate()?;
        Ok(Self {
            rig: rig.clone(),
            solver: settings.solver,
            builder: PairBuilder::new(settings.pairs)?,
            incremental: SelfCalibrator::new(
                rig.clone(),
                settings.solver,
                settings.stable,
                settings.solve_every,
            ),
            pairs: Vec::new(),
        })
    }

    /// An odometry sample, in time order.
    pub fn push_odometry(&mut self, sample: OdomSample) {
        self.builder.push_odometry(sample);
    }

    /// A frame's tracks: a new pair goes to the incremental calibrator until it is stable, and
    /// is kept for the batch.
    pub fn push_frame(&mut self, tracked: &TrackedFrame) {
        if let Some(pair) = self.builder.push_frame(tracked) {
            if self.incremental.handover().is_none() {
                self.incremental.add_pair(pair.clone());
            }
            self.pairs.push(pair);
        }
    }

    /// Every frame pair so far.
    pub fn pairs(&self) -> &[FramePair] {
        &self.pairs
    }

    /// The incremental calibration's hand-over, once it became stable.
    pub fn handover(&self) -> Option<&Handover> {
        self.incremental.handover()
    }

    /// `(t_us, parameters, sigmas)` after each incremental solve, up to the hand-over.
    pub fn history(&self) -> &[(u64, ParamVector, ParamVector)] {
        self.incremental.history()
    }

    /// Eq. (1)-(2) over every frame pair so far, from the rig's nominal parameters.
    pub fn calibrate(&self) -> Calibration {
        calibrate(&self.pairs, &self.rig, &self.rig.nominal, &self.solver)
    }
}
