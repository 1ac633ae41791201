//! A window of odometry samples fed in time order, integrated between two instants with
//! [`rig_model::odometry::integrate`] (vehicle-interfaces.md section 2: each sample held until
//! the next).

use alloc::vec::Vec;

use rig_model::odometry::{Motion, OdomSample, integrate};

/// Odometry samples kept for integration between frames.
///
/// Samples should come in time order; a late one is inserted in its place. A sample with a
/// NaN or infinite velocity is refused and counted. [`motion`](Self::motion) refuses to hold
/// a sample longer than `max_hold_us` (a gap in the odometry is not a constant velocity), and
/// [`forget_before`](Self::forget_before) bounds the memory.
#[derive(Debug, Clone)]
pub struct OdometryBuffer {
    samples: Vec<OdomSample>,
    max_hold_us: u64,
    refused: u64,
}

impl OdometryBuffer {
    /// An empty buffer; `max_hold_us` is the longest a sample may be held (use `u64::MAX`
    /// for no limit).
    pub fn new(max_hold_us: u64) -> Self {
        Self {
            samples: Vec::new(),
            max_hold_us,
            refused: 0,
        }
    }

    /// Adds a sample; returns `false` (and counts it) when a velocity is NaN or infinite.
    pub fn push(&mut self, sample: OdomSample) -> bool {
        if !(sample.vx.is_finite() && sample.vy.is_finite() && sample.vtheta.is_finite()) {
            self.refused += 1;
            return false;
        }
        if self.samples.last().is_none_or(|l| l.t_us <= sample.t_us) {
            self.samples.push(sample);
        } else {
            let at = self.samples.partition_point(|s| s.t_us <= sample.t_us);
            self.samples.insert(at, sample);
        }
        true
    }

    /// Samples refused for NaN or infinite values.
    pub fn refused(&self) -> u64 {
        self.refused
    }

    /// Samples held.
    pub fn len(&self) -> usize {
        self.samples.len()
    }

    /// Whether no sample is held.
    pub fn is_empty(&self) -> bool {
        self.samples.is_empty()
    }

    /// The motion from `t0_us` to `t1_us`, in the robot frame at `t0_us`; `None` when no sample
    /// covers `t0_us`, when `t1_us < t0_us`, or when a sample would be held longer than
    /// `max_hold_us` inside the interval.
    pub fn motion(&self, t0_us: u64, t1_us: u64) -> Option<Motion> {
        if t1_us < t0_us {
            return None;
        }
        let start = self
            .samples
            .partition_point(|s| s.t_us <= t0_us)
            .checked_sub(1)?;
        let end = self.samples.partition_point(|s| s.t_us < t1_us);
        let used = self.samples.get(start..end.max(start + 1))?;
        let mut held_from = used.first()?.t_us;
        for s in used.iter().skip(1) {
            if s.t_us.saturating_sub(held_from) > self.max_hold_us {
                return None;
            }
            held_from = s.t_us;
        }
        if t1_us.saturating_sub(held_from) > self.max_hold_us {
            return None;
        }
        integrate(used, t0_us, t1_us)
    }

    /// Drops the samples no longer needed to integrate from `t_us` on: all but the last one
    /// at or before it.
    pub fn forget_before(&mut self, t_us: u64) {
        let keep_from = self
            .samples
            .partition_point(|s| s.t_us <= t_us)
            .saturating_sub(1);
        if keep_from > 0 {
            self.samples.drain(..keep_from);
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    fn s(t_us: u64, vx: f64) -> OdomSample {
        OdomSample {
            t_us,
            vx,
            vy: 0.0,
            vtheta: 0.0,
        }
    }

    #[test]
    fn integrates_like_calib_and_forgets_safely() {
        let all: Vec<OdomSample> = (0..20).map(|k| s(k * 10_000, 0.1 * k as f64)).collect();
        let mut b = OdometryBuffer::new(u64::MAX);
        for x in &all {
            assert!(b.push(*x));
        }
        for (t0, t1) in [(5_000, 95_000), (0, 0), (10_000, 10_000), (12_345, 250_000)] {
            assert_eq!(b.motion(t0, t1), integrate(&all, t0, t1), "{t0} {t1}");
        }
        b.forget_before(55_000);
        assert_eq!(b.len(), 15);
        assert_eq!(b.motion(55_000, 95_000), integrate(&all, 55_000, 95_000));
        assert_eq!(b.motion(45_000, 95_000), None);
        assert_eq!(b.motion(95_000, 55_000), None);
    }

    #[test]
    fn late_samples_are_placed_and_bad_ones_refused() {
        let mut b = OdometryBuffer::new(u64::MAX);
        b.push(s(0, 1.0));
        b.push(s(20_000, 3.0));
        b.push(s(10_000, 2.0));
        assert!(!b.push(s(30_000, f64::NAN)));
        assert_eq!(b.refused(), 1);
        let m = b.motion(0, 30_000).unwrap();
        assert!((m.dx - 0.06).abs() < 1e-12, "{m:?}");
    }

    #[test]
    fn a_gap_in_the_odometry_is_no_motion() {
        let mut b = OdometryBuffer::new(100_000);
        b.push(s(0, 1.0));
        b.push(s(50_000, 1.0));
        b.push(s(400_000, 1.0));
        assert!(b.motion(0, 100_000).is_some());
        assert_eq!(b.motion(0, 200_000), None);
        assert_eq!(b.motion(40_000, 420_000), None);
        assert!(b.motion(400_000, 450_000).is_some());
        assert_eq!(b.motion(400_000, 600_000), None);
    }
}
