//! The batch's tuning ([`SmootherSettings`]) and its range check.

use crate::error::{Error, check_fields};

#[cfg(doc)]
use super::Smoother;

/// Tuning of the batch.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SmootherSettings {
    /// Frames kept at most. When the buffer is full and calibration is still not stable, the
    /// hand-over is forced with what the data gave (parameters they did not inform keep about
    /// their prior, and the navigator says so): memory and solve time stay bounded.
    pub max_frames: usize,
    /// Frames between solves.
    pub solve_every: usize,
    /// Gauss-Newton iterations at most per solve (warm-started, usually 1-3).
    pub max_iterations: usize,
    /// Huber threshold on an observation's whitened residual norm (4 measurements).
    pub huber: f64,
    /// A new track is bound to an existing landmark not seen in this frame when the
    /// landmark projects within this many pixels of each of its four measurements, and to no
    /// other (a lamp seen again after leaving the view keeps its landmark).
    pub rebind_px: f64,
    /// Largest posterior / prior sigma ratio for a parameter to count as informed.
    pub sigma_fraction: f64,
    /// Largest change between consecutive solves, in posterior sigmas.
    pub step_fraction: f64,
    /// Solves in a row that must satisfy both.
    pub consecutive: usize,
    /// Frames the batch keeps after the hand-over, when it goes on as phase 2's fixed-lag
    /// smoother ([`Smoother::start_mapping`]): older frames are marginalised into a prior.
    pub window: usize,
    /// Landmarks the batch carries at most: its cost is `O(n w^2)` a solve for `w = 3 x
    /// landmarks` (and its dense prior `O(w^2)` a frame in phase 2). In phase 1 a lamp that
    /// would need one more forces the hand-over (phase 2 maps it); in phase 2 the smoother
    /// stops and the filter goes on alone (docs/phase2.md).
    pub max_landmarks: usize,
    /// Landmarks observed in one frame at most: a new track becomes a landmark only while
    /// fewer are (a textured real scene would otherwise add one for every corner it has;
    /// docs/real-images.md).
    pub max_in_view: usize,
    /// A new track whose point is closer than this to a landmark becomes none: a second
    /// feature of the same thing (a tube end's two corners), metres.
    pub min_separation_m: f64,
}

impl Default for SmootherSettings {
    fn default() -> Self {
        Self {
            // 100 s at 20 Hz.
            max_frames: 2000,
            // Half a second at 20 Hz.
            solve_every: 10,
            max_iterations: 8,
            huber: 4.0,
            rebind_px: 6.0,
            sigma_fraction: 0.2,
            step_fraction: 1.0,
            consecutive: 3,
            // Five seconds at 20 Hz: every pose is re-linearised over 100 frames of data
            // before it is marginalised.
            window: 100,
            max_landmarks: 48,
            max_in_view: 48,
            min_separation_m: 0.05,
        }
    }
}

impl SmootherSettings {
    /// Checks every field: the first out of its range is an [`Error::Setting`].
    pub fn validate(&self) -> Result<(), Error> {
        #[allow(clippy::cast_precision_loss)]
        let checks: [(&'static str, f64, bool, &'static str); 12] = [
            (
                "max_frames",
                self.max_frames as f64,
                self.max_frames >= 2,
                "at least 2",
            ),
            (
                "solve_every",
                self.solve_every as f64,
                self.solve_every >= 1,
                "at least 1",
            ),
            (
                "max_iterations",
                self.max_iterations as f64,
                self.max_iterations >= 1,
                "at least 1",
            ),
            (
                "huber",
                self.huber,
                self.huber.is_finite() && self.huber > 0.0,
                "positive",
            ),
            (
                "rebind_px",
                self.rebind_px,
                self.rebind_px.is_finite() && self.rebind_px >= 0.0,
                "finite, >= 0",
            ),
            (
                "sigma_fraction",
                self.sigma_fraction,
                self.sigma_fraction > 0.0 && self.sigma_fraction <= 1.0,
                "in (0, 1]",
            ),
            (
                "step_fraction",
                self.step_fraction,
                self.step_fraction.is_finite() && self.step_fraction > 0.0,
                "positive",
            ),
            (
                "consecutive",
                self.consecutive as f64,
                self.consecutive >= 1,
                "at least 1",
            ),
            ("window", self.window as f64, self.window >= 2, "at least 2"),
            ("max_landmarks", self.max_landmarks as f64, true, "a count"),
            (
                "max_in_view",
                self.max_in_view as f64,
                self.max_in_view >= 1,
                "at least 1",
            ),
            (
                "min_separation_m",
                self.min_separation_m,
                self.min_separation_m.is_finite() && self.min_separation_m >= 0.0,
                "finite, >= 0",
            ),
        ];
        check_fields("SmootherSettings", checks)
    }
}
