//! The prediction's motion model (the motion that eq. (4) applies and the noise eq. (5)
//! propagates, `crate::predict`): the planar arc of constant robot-frame velocities
//! (vehicle-interfaces.md section 2), its Jacobians, and its noise.
//!
//! Noise model, the one phase 1 uses (`selfcal::solver`): each odometry sample's velocities
//! carry white noise (`velocity` m/s on `vx` and `vy`, `yaw_rate` rad/s on `vtheta`) that is
//! *held* with the sample (errors with memory, `velocity_tau` and `yaw_rate_tau`, as the white
//! noise of the same variance over spans longer than the time constant:
//! [`rig_model::Noise::white_equivalent`]), so one sample held for `dt` contributes `G diag(sv^2, sv^2, sw^2) G^T`
//! with `G` the exact Jacobian of the arc with respect to the velocities; for short steps
//! `G ~ dt I`, the `(sigma dt)^2` of phase 1. A frame time usually falls inside an odometry
//! sample, which two predictions then share; treating its two pieces as independent would
//! under-count its variance by the factor `(dt1^2 + dt2^2) / (dt1 + dt2)^2`, so
//! [`Increment::from_odometry`] gives a piece of a sample the variance `sigma^2 period dt`
//! (linear in time within the sample): a whole sample keeps its variance however it is cut,
//! and only the small correlation between the pieces is dropped.
//!
//! **Gaps.** A sample held for longer than [`ODOMETRY_HOLD_LIMIT_US`] (samples lost on the bus,
//! a chunk of the log lost to damage, odometry that stopped) says nothing about the motion
//! after that limit: the vehicle may have sped up, braked or turned. Past the limit the piece
//! takes the error of an unknown acceleration, [`GAP_ACCELERATION_MPS2`] and
//! [`GAP_YAW_ACCELERATION_RADPS2`] (1 sigma), held since the limit: a position error
//! `a tau^2 / 2` after `tau` beyond it (5.6 cm and 3.2 degrees after a 1 s gap). Samples at
//! their usual rate never reach the limit, so a log without gaps is predicted as before.
//!
//! The 1-sigma accelerations were chosen on bit-damaged logs (docs/benchmarks.md, "Logs that
//! survive"): 0.5 m/s^2 and rad/s^2, the limits of the simulator's drives, open the gates so
//! wide after a 2 s gap that the five lamps of the paper's experiment re-associate rotated
//! (10 of 24 copies off by metres); none at all keeps the held velocity's error (15 of 24 off
//! by 0.1 to 1.2 m); 0.2 gives 18 of 24 within 3 mm. A gap that spans a reversal still needs
//! the relocalisation of the map issue.

use nalgebra::Matrix3;
use rig_model::Noise;
use rig_model::odometry::{Motion, OdomSample, constant_velocity_motion};

use crate::error::Error;

/// An odometry sample held longer than this, microseconds, is a gap past it (see the module
/// docs): 2.5 periods of a 10 Hz odometry, 25 of the usual 100 Hz.
pub const ODOMETRY_HOLD_LIMIT_US: u64 = 250_000;

/// The vehicle's acceleration assumed over an odometry gap, 1 sigma, m/s^2 (a forklift's
/// typical; its limit, and the simulator's drives', is about 0.5: see the module docs).
pub const GAP_ACCELERATION_MPS2: f64 = 0.2;

/// The vehicle's yaw acceleration assumed over an odometry gap, 1 sigma, rad/s^2 (about
/// 11 deg/s^2; the limit is about 30).
pub const GAP_YAW_ACCELERATION_RADPS2: f64 = 0.2;

/// The extra 1-sigma velocity error, `(linear m/s, yaw rad/s)`, that a piece `[t, end]` of a
/// sample taken at `sample_t` carries for the part of its hold beyond
/// [`ODOMETRY_HOLD_LIMIT_US`], as a velocity held over the piece's `dt` seconds: the position
/// error of an unknown acceleration `a`, `a ((end - L)^2 - (max(t, L) - L)^2) / 2`, over `dt`.
fn gap_velocity_error(sample_t: u64, t: u64, end: u64, dt: f64) -> (f64, f64) {
    let limit = sample_t.saturating_add(ODOMETRY_HOLD_LIMIT_US);
    if end <= limit || dt <= 0.0 {
        return (0.0, 0.0);
    }
    #[allow(clippy::cast_precision_loss)] // microsecond spans far below 2^53
    let past = |u: u64| u.saturating_sub(limit) as f64 * 1e-6;
    let (a0, a1) = (past(t), past(end));
    let growth = 0.5 * (a1 * a1 - a0 * a0) / dt;
    (
        GAP_ACCELERATION_MPS2 * growth,
        GAP_YAW_ACCELERATION_RADPS2 * growth,
    )
}

/// A motion in the robot frame at its start with the covariance of its error: what the
/// prediction adds to the pose.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Increment {
    /// The motion `(dx, dy, dtheta)` in the robot frame at its start.
    pub motion: Motion,
    /// Covariance of `(dx, dy, dtheta)`.
    pub covariance: Matrix3<f64>,
}

impl Default for Increment {
    fn default() -> Self {
        Self {
            motion: Motion::default(),
            covariance: Matrix3::zeros(),
        }
    }
}

/// `d(dx, dy, dtheta) / d(vx, vy, vtheta)` of [`constant_velocity_motion`], exact.
pub fn arc_velocity_jacobian(vx: f64, vy: f64, w: f64, dt: f64) -> Matrix3<f64> {
    let a = w * dt;
    // sa = sin(a)/w, ca = (1 - cos a)/w and their derivatives in w; by series near w = 0,
    // where the closed forms cancel (the series are exact to rounding below |a| = 1e-2).
    let (sa, ca, dsa, dca) = if libm::fabs(a) < 1e-2 {
        let a2 = a * a;
        let dt2 = dt * dt;
        (
            dt * (1.0 - a2 / 6.0 * (1.0 - a2 / 20.0 * (1.0 - a2 / 42.0))),
            dt * a / 2.0 * (1.0 - a2 / 12.0 * (1.0 - a2 / 30.0 * (1.0 - a2 / 56.0))),
            dt2 * a * (-1.0 / 3.0 + a2 / 30.0 - a2 * a2 / 840.0),
            dt2 * (0.5 - a2 / 8.0 + a2 * a2 / 144.0 - a2 * a2 * a2 / 5760.0),
        )
    } else {
        let (s, c) = (libm::sin(a), libm::cos(a));
        let sa = s / w;
        let ca = (1.0 - c) / w;
        (sa, ca, (dt * c - sa) / w, (dt * s - ca) / w)
    };
    Matrix3::new(
        sa,
        -ca,
        dsa * vx - dca * vy,
        ca,
        sa,
        dca * vx + dsa * vy,
        0.0,
        0.0,
        dt,
    )
}

/// The Jacobians of a composition of motions (rig-model's, shared with the batch).
pub use rig_model::odometry::{compose_jacobian_first, compose_jacobian_second};

/// Checks a noise model's odometry sigmas.
pub(crate) fn check_noise(noise: &Noise) -> Result<(), Error> {
    for (name, value) in [
        ("noise.velocity", noise.velocity),
        ("noise.yaw_rate", noise.yaw_rate),
    ] {
        if !(value.is_finite() && value >= 0.0) {
            return Err(Error::BadValue {
                name,
                value,
                expected: "finite and non-negative",
            });
        }
    }
    if !(noise.pixel.is_finite() && noise.pixel > 0.0) {
        return Err(Error::BadValue {
            name: "noise.pixel",
            value: noise.pixel,
            expected: "finite and positive",
        });
    }
    Ok(())
}

impl Increment {
    /// Velocities `(vx, vy, vtheta)` held for `dt_s` seconds, with the held-noise covariance.
    pub fn from_velocities(
        vx: f64,
        vy: f64,
        vtheta: f64,
        dt_s: f64,
        noise: &Noise,
    ) -> Result<Self, Error> {
        for (what, value) in [
            ("odometry vx", vx),
            ("odometry vy", vy),
            ("odometry vtheta", vtheta),
            ("time step", dt_s),
        ] {
            if !value.is_finite() {
                return Err(Error::NonFinite { what, value });
            }
        }
        if dt_s < 0.0 {
            return Err(Error::NegativeTimeStep { dt_s });
        }
        check_noise(noise)?;
        Ok(Self::piece(vx, vy, vtheta, dt_s, noise))
    }

    /// One held sample, inputs checked.
    fn piece(vx: f64, vy: f64, vtheta: f64, dt_s: f64, noise: &Noise) -> Self {
        let motion = constant_velocity_motion(vx, vy, vtheta, dt_s);
        let g = arc_velocity_jacobian(vx, vy, vtheta, dt_s);
        let sv2 = noise.velocity * noise.velocity;
        let sw2 = noise.yaw_rate * noise.yaw_rate;
        let d = Matrix3::from_diagonal(&nalgebra::Vector3::new(sv2, sv2, sw2));
        Self {
            motion,
            covariance: g * d * g.transpose(),
        }
    }

    /// This increment followed by `next`: the motions composed, the covariances propagated.
    pub fn then(&self, next: &Self) -> Self {
        let ja = compose_jacobian_first(self.motion.dtheta, &next.motion);
        let jb = compose_jacobian_second(self.motion.dtheta);
        Self {
            motion: self.motion.then(&next.motion),
            covariance: ja * self.covariance * ja.transpose()
                + jb * next.covariance * jb.transpose(),
        }
    }

    /// The odometry samples (sorted by time) integrated from `t0_us` to `t1_us`, each held from
    /// its timestamp until the next, exactly as [`rig_model::odometry::integrate`] does, with the
    /// covariance of every held piece propagated.
    pub fn from_odometry(
        samples: &[OdomSample],
        t0_us: u64,
        t1_us: u64,
        noise: &Noise,
    ) -> Result<Self, Error> {
        Self::integrate(samples, t0_us, t1_us, noise, None)
    }

    /// [`Self::from_odometry`], and with `offset` the motion's derivative with respect to a
    /// constant offset added to every sample's velocities `(vx, vy, vtheta)`, composed piece by
    /// piece as the motions are (`d (a then b) = J_a d a + J_b d b`, the arc's
    /// [`arc_velocity_jacobian`] for each piece).
    fn integrate(
        samples: &[OdomSample],
        t0_us: u64,
        t1_us: u64,
        noise: &Noise,
        mut offset: Option<&mut Matrix3<f64>>,
    ) -> Result<Self, Error> {
        if t1_us < t0_us {
            return Err(Error::BackwardInterval { t0_us, t1_us });
        }
        check_noise(noise)?;
        // The last sample at or before t0 (or the first, held back a little:
        // rig_model::odometry::BACKWARD_HOLD_US).
        let (start, _) =
            rig_model::odometry::start_of(samples, t0_us).ok_or(Error::NoOdometry {
                t0_us,
                first_us: samples.first().map(|s| s.t_us),
            })?;
        let mut total = Self::default();
        let mut t = t0_us;
        for (i, s) in samples.iter().enumerate().skip(start) {
            if t >= t1_us {
                break;
            }
            let end = samples.get(i + 1).map_or(t1_us, |n| n.t_us.min(t1_us));
            if end <= t {
                continue;
            }
            for (what, value) in [
                ("odometry vx", s.vx),
                ("odometry vy", s.vy),
                ("odometry vtheta", s.vtheta),
            ] {
                if !value.is_finite() {
                    return Err(Error::NonFinite { what, value });
                }
            }
            #[allow(clippy::cast_precision_loss)] // microsecond spans far below 2^53
            let dt = (end - t) as f64 * 1e-6;
            // A frame's time usually falls inside an odometry sample, which two predictions
            // then share. The sample's noise is one draw held over its whole period, so the two
            // pieces' errors are fully correlated; a filter that treats them as independent
            // (variance (sigma dt)^2 each) loses part of the sample's variance (half of it for a
            // sample cut in the middle) and turns overconfident. Variance linear in time within
            // a sample, sigma^2 * period * dt, keeps the variance of a whole sample exact
            // however it is cut (only the small correlation between the pieces is dropped).
            let period = samples
                .get(i + 1)
                .map_or(0, |n| n.t_us.saturating_sub(s.t_us));
            #[allow(clippy::cast_precision_loss)]
            let period = period as f64 * 1e-6;
            // Errors with memory (`[noise] velocity_tau`, `yaw_rate_tau`) are weighed as the
            // white noise that gives their variance over spans longer than the time constant
            // (`Noise::white_equivalent`; the last sample's period is unknown: its piece's).
            let noise = &noise.white_equivalent(if period > 0.0 { period } else { dt });
            let mut piece_noise = if period > dt && dt > 0.0 {
                let k = libm::sqrt(period / dt);
                Noise {
                    velocity: noise.velocity * k,
                    yaw_rate: noise.yaw_rate * k,
                    ..*noise
                }
            } else {
                *noise
            };
            let (gap_v, gap_w) = gap_velocity_error(s.t_us, t, end, dt);
            if gap_v > 0.0 {
                piece_noise.velocity = libm::hypot(piece_noise.velocity, gap_v);
                piece_noise.yaw_rate = libm::hypot(piece_noise.yaw_rate, gap_w);
            }
            if let Some(j) = offset.as_deref_mut() {
                let next = constant_velocity_motion(s.vx, s.vy, s.vtheta, dt);
                *j = compose_jacobian_first(total.motion.dtheta, &next) * *j
                    + compose_jacobian_second(total.motion.dtheta)
                        * arc_velocity_jacobian(s.vx, s.vy, s.vtheta, dt);
            }
            total = total.then(&Self::piece(s.vx, s.vy, s.vtheta, dt, &piece_noise));
            t = end;
        }
        Ok(total)
    }

    /// [`Self::from_odometry`] between two stereo frames stamped `t0_us` and `t1_us` by the
    /// board, for the vehicle `v` (vehicle-interfaces.md 1.2): over the odometry-clock
    /// interval `t - time_offset`, with the true velocities of `V`. Returns the increment (its
    /// covariance that of the true motion: the reported velocities' noise through `V`), the
    /// covariance in the reported odometry's units (what the batch weighs its residual with,
    /// [`rig_model::odometry::OdometryFactor`]), and, with `jacobian`, `d motion / dV` at `v`
    /// ([`rig_model::Param::VEHICLE`] order; zero without).
    pub fn from_odometry_vehicle(
        samples: &[OdomSample],
        t0_us: u64,
        t1_us: u64,
        noise: &Noise,
        v: &rig_model::Vehicle,
        jacobian: bool,
    ) -> Result<(Self, Matrix3<f64>, nalgebra::Matrix3x4<f64>), Error> {
        if v.is_nominal() && !jacobian {
            let inc = Self::from_odometry(samples, t0_us, t1_us, noise)?;
            return Ok((inc, inc.covariance, nalgebra::Matrix3x4::zeros()));
        }
        let (a, b, corrected) = corrected_samples(samples, t0_us, t1_us, v);
        let mut inc = Self::from_odometry(&corrected, a, b, noise)?;
        let reported = inc.covariance;
        // The true motion's error is the reported one through D^-1, D = diag(odom_scale,
        // odom_scale, odom_yaw_scale) (to first order in the scales' errors).
        let d_inv = Matrix3::from_diagonal(&nalgebra::Vector3::new(
            1.0 / v.odom_scale,
            1.0 / v.odom_scale,
            1.0 / v.odom_yaw_scale,
        ));
        inc.covariance = d_inv * reported * d_inv;
        let j = if jacobian {
            rig_model::odometry::vehicle_jacobian(samples, t0_us, t1_us, v)
                .unwrap_or_else(nalgebra::Matrix3x4::zeros)
        } else {
            nalgebra::Matrix3x4::zeros()
        };
        Ok((inc, reported, j))
    }
}

/// The odometry-clock interval of the board's `[t0_us, t1_us]` for the vehicle `v` and the
/// samples over it with the true velocities of `v` (vehicle-interfaces.md 1.2).
fn corrected_samples(
    samples: &[OdomSample],
    t0_us: u64,
    t1_us: u64,
    v: &rig_model::Vehicle,
) -> (u64, u64, alloc::vec::Vec<OdomSample>) {
    let (a, b) = (v.odometry_time_us(t0_us), v.odometry_time_us(t1_us));
    let first = samples.partition_point(|s| s.t_us <= a).saturating_sub(1);
    let last = samples.partition_point(|s| s.t_us < b).max(first + 1);
    let corrected = samples
        .get(first..last.min(samples.len()))
        .unwrap_or_default()
        .iter()
        .map(|s| {
            let (vx, vy, vtheta) = v.true_velocities(s.vx, s.vy, s.vtheta);
            OdomSample {
                t_us: s.t_us,
                vx,
                vy,
                vtheta,
            }
        })
        .collect();
    (a, b, corrected)
}

/// `d motion / d e` for errors `e = (e_vx, e_vy, e_vtheta)` in the *reported* velocities held
/// over the board's `[t0_us, t1_us]` (the reported samples minus `e` are the measured ones,
/// `crate::errors`): with `true = D^-1 (reported - bias - e)`, `D = diag(odom_scale,
/// odom_scale, odom_yaw_scale)`, it is `-J D^-1`, `J` the motion's derivative in a constant
/// offset of the true velocities. In the robot frame at the interval's start.
///
/// # Errors
///
/// As [`Increment::from_odometry`].
pub fn reported_error_jacobian(
    samples: &[OdomSample],
    t0_us: u64,
    t1_us: u64,
    v: &rig_model::Vehicle,
) -> Result<Matrix3<f64>, Error> {
    let (a, b, corrected) = corrected_samples(samples, t0_us, t1_us, v);
    let mut j = Matrix3::zeros();
    Increment::integrate(&corrected, a, b, &Noise::white(1.0, 0.0, 0.0), Some(&mut j))?;
    let d_inv = Matrix3::from_diagonal(&nalgebra::Vector3::new(
        -1.0 / v.odom_scale,
        -1.0 / v.odom_scale,
        -1.0 / v.odom_yaw_scale,
    ));
    Ok(j * d_inv)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn motion_vector(vx: f64, vy: f64, w: f64, dt: f64) -> nalgebra::Vector3<f64> {
        let m = constant_velocity_motion(vx, vy, w, dt);
        nalgebra::Vector3::new(m.dx, m.dy, m.dtheta)
    }

    /// A gap in the odometry (a sample held 1 s) is predicted with the error of an unknown
    /// acceleration past the hold limit; samples at their usual rate are not.
    #[test]
    fn a_gap_in_the_odometry_widens_the_prediction() {
        let noise = Noise::white(0.3, 0.005, 0.01);
        let at = |t_us: u64| OdomSample {
            t_us,
            vx: 1.0,
            vy: 0.0,
            vtheta: 0.0,
        };
        let steady: alloc::vec::Vec<OdomSample> = (0..=100).map(|i| at(i * 10_000)).collect();
        let gap = [at(0), at(1_000_000)];
        let a = Increment::from_odometry(&steady, 0, 1_000_000, &noise).unwrap();
        let b = Increment::from_odometry(&gap, 0, 1_000_000, &noise).unwrap();
        assert!((a.motion.dx - b.motion.dx).abs() < 1e-12);
        // 100 samples of 5 mm/s noise held 10 ms each: 0.5 mm.
        assert!(a.covariance[(0, 0)].sqrt() < 1e-3, "{}", a.covariance);
        // 0.75 s past the limit: a tau^2 / 2 along (5.6 cm at 0.2 m/s^2), more across (the
        // heading's error too).
        let expected = 0.5 * GAP_ACCELERATION_MPS2 * 0.75 * 0.75;
        let along = b.covariance[(0, 0)].sqrt();
        assert!(
            (along - expected).abs() < 0.01 * expected + 0.006,
            "{along}"
        );
        assert!(b.covariance[(1, 1)].sqrt() > expected);
        let yaw = b.covariance[(2, 2)].sqrt();
        let expected_yaw = 0.5 * GAP_YAW_ACCELERATION_RADPS2 * 0.75 * 0.75;
        assert!((yaw - expected_yaw).abs() < 0.02 * expected_yaw, "{yaw}");
        // Cut into two frames, the pieces add up to the same growth (the error's own
        // correlation between them aside).
        let first = Increment::from_odometry(&gap, 0, 500_000, &noise).unwrap();
        let second = Increment::from_odometry(&gap, 500_000, 1_000_000, &noise).unwrap();
        assert!(first.covariance[(0, 0)].sqrt() < 0.5 * GAP_ACCELERATION_MPS2 * 0.0626 + 0.003);
        assert!(second.covariance[(0, 0)] > first.covariance[(0, 0)]);
    }

    /// A frame time in the middle of an odometry sample: the two predictions that share the
    /// sample add up to the variance of the whole sample, not half of it.
    #[test]
    fn a_sample_cut_by_a_frame_keeps_its_variance() {
        let noise = Noise::white(0.3, 0.02, 0.01);
        let samples = [
            OdomSample {
                t_us: 0,
                vx: 0.0,
                vy: 0.0,
                vtheta: 0.0,
            },
            OdomSample {
                t_us: 10_000,
                vx: 0.0,
                vy: 0.0,
                vtheta: 0.0,
            },
        ];
        let whole = Increment::from_odometry(&samples, 0, 10_000, &noise).unwrap();
        let first = Increment::from_odometry(&samples, 0, 4_000, &noise).unwrap();
        let second = Increment::from_odometry(&samples, 4_000, 10_000, &noise).unwrap();
        let cut = first.covariance + second.covariance;
        assert!((cut - whole.covariance).norm() <= 1e-12 * whole.covariance.norm());
        assert!((whole.covariance[(0, 0)] - (0.02_f64 * 0.01).powi(2)).abs() < 1e-15);
    }

    #[test]
    fn arc_jacobian_matches_central_differences_across_the_series_switch() {
        for &(vx, vy, w, dt) in &[
            (0.3, 0.05, 0.0, 0.01),
            (0.3, -0.1, 1e-7, 0.01),
            (0.25, 0.0, 0.3, 0.05),
            (-0.2, 0.1, 0.99, 0.01), // a just below 1e-2
            (0.2, 0.1, 1.01, 0.01),  // a just above 1e-2
            (1.0, -0.5, -2.0, 0.4),
        ] {
            let j = arc_velocity_jacobian(vx, vy, w, dt);
            let h = 1e-6;
            for k in 0..3 {
                let mut plus = [vx, vy, w];
                let mut minus = plus;
                plus[k] += h;
                minus[k] -= h;
                let d = (motion_vector(plus[0], plus[1], plus[2], dt)
                    - motion_vector(minus[0], minus[1], minus[2], dt))
                    / (2.0 * h);
                let err = (d - j.column(k)).norm();
                assert!(
                    err < 1e-9 * (1.0 + d.norm()),
                    "{vx} {vy} {w} {dt} col {k}: {err}"
                );
            }
        }
    }
}
