//! The filter's health: NIS over a sliding window, counters, a divergence flag.
//!
//! A consistent filter's normalised innovation squared (NIS, `nu^T S^-1 nu`) of an accepted
//! landmark is chi-square with 4 degrees of freedom, so the sum over the `w` accepted
//! observations in the window is chi-square with `4 w`. The window mean per degree of freedom
//! is therefore near 1, and above `chi2_{0.999}(4 w) / (4 w)` only once in a thousand windows
//! of a healthy filter: above it, the filter is overconfident or its model is wrong, and the
//! flag is raised. The gate truncates each NIS at its bound, which lowers the mean a little;
//! a diverging filter shows up in the rejection count of the window as well, which is
//! reported beside it. An update refused because `S` or `P` lost positive definiteness is
//! the other divergence signal and sticks.

use alloc::collections::VecDeque;
use core::cell::Cell;

use crate::chi2::chi2_quantile;

/// Upper tail probability of the window's NIS bound.
pub const DIVERGENCE_PROBABILITY: f64 = 0.999;

/// Degrees of freedom of one landmark observation `(uL, vL, uR, vR)`.
pub(crate) const DOF: f64 = 4.0;

/// What a caller sees of the filter's health.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Health {
    /// Updates applied (batches with at least one observation, accepted or not).
    pub updates: u64,
    /// Updates refused because `S` or `P` lost positive definiteness or the result was not
    /// finite (the state was left as it was).
    pub refused_updates: u64,
    /// Landmark observations accepted by the gate, in all.
    pub accepted: u64,
    /// Landmark observations rejected by the gate (or not projectable), in all.
    pub rejected: u64,
    /// Landmarks added, in all.
    pub landmarks_added: u64,
    /// Landmarks removed (by repeated rejection or on request), in all.
    pub landmarks_removed: u64,
    /// Local sessions opened (`crate::local`: updates confined to the states near the
    /// vehicle), in all.
    pub local_sessions: u64,
    /// Local sessions settled (their covariance written out), in all.
    pub local_settles: u64,
    /// Passes of the iterated update (`Ekf::update` on a pose too uncertain for one
    /// linearisation) beyond the first, in all.
    pub iterated_updates: u64,
    /// Gate outcomes in the window (at most its length).
    pub window_observations: usize,
    /// Rejections among them.
    pub window_rejected: usize,
    /// Mean NIS per degree of freedom of the accepted observations in the window (`None`
    /// while there are none): near 1 for a consistent filter.
    pub window_mean_nis_per_dof: Option<f64>,
    /// The mean's upper [`DIVERGENCE_PROBABILITY`] bound for that many observations.
    pub window_nis_bound: Option<f64>,
    /// The window mean is above its bound.
    pub nis_too_high: bool,
    /// `nis_too_high`, or an update was ever refused for lost positive definiteness.
    pub diverged: bool,
}

/// Running health bookkeeping inside the filter.
#[derive(Debug, Clone)]
pub(crate) struct HealthState {
    /// Last gate outcomes: `Some(nis)` accepted, `None` rejected.
    window: VecDeque<Option<f64>>,
    capacity: usize,
    pub(crate) updates: u64,
    pub(crate) refused_updates: u64,
    pub(crate) accepted: u64,
    pub(crate) rejected: u64,
    pub(crate) landmarks_added: u64,
    pub(crate) landmarks_removed: u64,
    pub(crate) local_sessions: u64,
    pub(crate) local_settles: u64,
    pub(crate) iterated_updates: u64,
    /// The last bound computed, by accepted count (the quantile costs a few microseconds).
    bound_cache: Cell<Option<(usize, f64)>>,
}

impl HealthState {
    pub(crate) fn new(capacity: usize) -> Self {
        Self {
            window: VecDeque::new(),
            capacity,
            updates: 0,
            refused_updates: 0,
            accepted: 0,
            rejected: 0,
            landmarks_added: 0,
            landmarks_removed: 0,
            local_sessions: 0,
            local_settles: 0,
            iterated_updates: 0,
            bound_cache: Cell::new(None),
        }
    }

    /// Records one gate outcome.
    pub(crate) fn record(&mut self, nis: Option<f64>) {
        if nis.is_some() {
            self.accepted += 1;
        } else {
            self.rejected += 1;
        }
        if self.window.len() >= self.capacity {
            self.window.pop_front();
        }
        self.window.push_back(nis);
    }

    fn bound(&self, count: usize) -> f64 {
        if let Some((c, b)) = self.bound_cache.get()
            && c == count
        {
            return b;
        }
        #[allow(clippy::cast_precision_loss)] // window lengths far below 2^53
        let dof = DOF * count as f64;
        let b = chi2_quantile(DIVERGENCE_PROBABILITY, dof) / dof;
        self.bound_cache.set(Some((count, b)));
        b
    }

    pub(crate) fn snapshot(&self) -> Health {
        let (mut sum, mut count) = (0.0, 0usize);
        for nis in self.window.iter().flatten() {
            sum += nis;
            count += 1;
        }
        #[allow(clippy::cast_precision_loss)]
        let mean = (count > 0).then(|| sum / (DOF * count as f64));
        let bound = (count > 0).then(|| self.bound(count));
        let nis_too_high = matches!((mean, bound), (Some(m), Some(b)) if m > b);
        Health {
            updates: self.updates,
            refused_updates: self.refused_updates,
            accepted: self.accepted,
            rejected: self.rejected,
            landmarks_added: self.landmarks_added,
            landmarks_removed: self.landmarks_removed,
            local_sessions: self.local_sessions,
            local_settles: self.local_settles,
            iterated_updates: self.iterated_updates,
            window_observations: self.window.len(),
            window_rejected: self.window.len() - count,
            window_mean_nis_per_dof: mean,
            window_nis_bound: bound,
            nis_too_high,
            diverged: nis_too_high || self.refused_updates > 0,
        }
    }
}
