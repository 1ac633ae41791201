//! Odometry integration (vehicle-interfaces.md section 2): robot-frame velocities
//! `(vx, vy, vtheta)`, each held constant from its timestamp until the next sample.

#[cfg(feature = "alloc")]
use alloc::vec::Vec;

use nalgebra::Matrix3;
use nalgebra::{Matrix3x4, Vector3};

use crate::camera::{Pose2, Vehicle};

/// One odometry sample: robot-frame velocities held from `t_us` until the next sample (the
/// one type for it, from the log to the estimators).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct OdomSample {
    /// Timestamp, microseconds, on the board's clock.
    pub t_us: u64,
    /// Forward velocity, m/s.
    pub vx: f64,
    /// Leftward velocity, m/s.
    pub vy: f64,
    /// Yaw rate, rad/s.
    pub vtheta: f64,
}

/// The robot's motion between two instants, expressed in the robot frame at the first one:
/// `pose_1 = pose_0 (+) motion`, so that a point seen at both instants satisfies
/// `L_0 = Rz(dtheta) L_1 + dT` (eq. (1)).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Motion {
    /// Translation `dT`, x, metres.
    pub dx: f64,
    /// Translation `dT`, y, metres.
    pub dy: f64,
    /// Rotation `dtheta`, radians.
    pub dtheta: f64,
    /// Duration, seconds.
    pub dt_s: f64,
    /// Odometry samples that contributed (for the noise model).
    pub samples: usize,
}

impl Motion {
    /// Appends a motion that follows this one: `self (+) next`.
    pub fn then(&self, next: &Self) -> Self {
        let (s, c) = (libm::sin(self.dtheta), libm::cos(self.dtheta));
        Self {
            dx: self.dx + c * next.dx - s * next.dy,
            dy: self.dy + s * next.dx + c * next.dy,
            dtheta: self.dtheta + next.dtheta,
            dt_s: self.dt_s + next.dt_s,
            samples: self.samples + next.samples,
        }
    }

    /// The pose reached from `pose` by this motion.
    pub fn apply(&self, pose: &Pose2) -> Pose2 {
        let (s, c) = (libm::sin(pose.theta), libm::cos(pose.theta));
        Pose2::new(
            pose.x + c * self.dx - s * self.dy,
            pose.y + s * self.dx + c * self.dy,
            pose.theta + self.dtheta,
        )
    }
}

/// The exact motion of constant robot-frame velocities `(vx, vy, w)` held for `dt` seconds
/// (a circular arc, or a straight line when `w = 0`).
pub fn constant_velocity_motion(vx: f64, vy: f64, w: f64, dt: f64) -> Motion {
    let a = w * dt;
    // sin(a)/w and (1 - cos(a))/w, by series near w = 0 to keep full precision.
    let (sa, ca) = if libm::fabs(a) < 1e-4 {
        (dt * (1.0 - a * a / 6.0), dt * (a / 2.0 - a * a * a / 24.0))
    } else {
        (libm::sin(a) / w, (1.0 - libm::cos(a)) / w)
    };
    Motion {
        dx: sa * vx - ca * vy,
        dy: ca * vx + sa * vy,
        dtheta: a,
        dt_s: dt,
        samples: 1,
    }
}

/// Integrates the samples (sorted by time) from `t0_us` to `t1_us`, each held from its
/// timestamp until the next. Returns `None` when no sample covers `t0_us`.
pub fn integrate(samples: &[OdomSample], t0_us: u64, t1_us: u64) -> Option<Motion> {
    integrate_with(samples, t0_us, t1_us, |s| (s.vx, s.vy, s.vtheta))
}

/// The motion between two stereo frames stamped `t0_us` and `t1_us` by the board, for the
/// vehicle `v` (vehicle-interfaces.md 1.2, 2): the frames were exposed at odometry-clock times
/// `t - time_offset`, and the true velocities are the reported ones through `V`.
pub fn integrate_vehicle(
    samples: &[OdomSample],
    t0_us: u64,
    t1_us: u64,
    v: &Vehicle,
) -> Option<Motion> {
    integrate_with(
        samples,
        v.odometry_time_us(t0_us),
        v.odometry_time_us(t1_us),
        |s| v.true_velocities(s.vx, s.vy, s.vtheta),
    )
}

/// Central-difference steps of the scales and the yaw bias: small against their plausible
/// errors, large against rounding.
const VEHICLE_STEPS: [f64; 3] = [1e-4, 1e-4, 1e-4];

/// Half-width of the window the clock offset's regressor averages the velocities over,
/// microseconds (ten odometry samples either side at 100 Hz). The regressor's own noise is
/// an error in the variables: at +-30 ms the paper's slow drive (0.25 m/s, 0.02 m/s noise a
/// sample) gave an offset 11 of 20 seeds inside 3 sigma (full-state NEES 2.05), at +-100 ms
/// 20 of 20 (1.09), and the aisle's offset 0.35 ms median instead of 0.56.
pub const SMOOTHING_HALF_WINDOW_US: u64 = 100_000;

/// The true robot-frame velocities `(vx, vy, vtheta)` of vehicle `v` averaged over the
/// odometry-clock window `[t - half, t + half]` (each sample held from its timestamp until the
/// next; the window clipped to the samples' span, the last sample held to the window's end).
/// `None` without a sample at or before the window's end.
pub fn smoothed_velocity(
    samples: &[OdomSample],
    t_us: u64,
    half_us: u64,
    v: &Vehicle,
) -> Option<(f64, f64, f64)> {
    let (from, to) = (t_us.saturating_sub(half_us), t_us.saturating_add(half_us));
    let first = samples
        .partition_point(|s| s.t_us <= from)
        .saturating_sub(1);
    let (mut sx, mut sy, mut sw, mut total) = (0.0, 0.0, 0.0, 0.0);
    for (i, s) in samples.iter().enumerate().skip(first) {
        if s.t_us >= to {
            break;
        }
        let start = s.t_us.max(from);
        let end = samples.get(i + 1).map_or(to, |n| n.t_us.min(to));
        if end <= start {
            continue;
        }
        #[allow(clippy::cast_precision_loss)]
        let dt = (end - start) as f64;
        let (vx, vy, w) = v.true_velocities(s.vx, s.vy, s.vtheta);
        sx += vx * dt;
        sy += vy * dt;
        sw += w * dt;
        total += dt;
    }
    (total > 0.0).then(|| (sx / total, sy / total, sw / total))
}

/// `d(dx, dy, dtheta) / dV` of [`integrate_vehicle`] at `v` (3 x 4, [`crate::Param::VEHICLE`]
/// order).
///
/// The scales and the bias by central differences (the motion is smooth in them). The clock
/// offset analytically, with velocities averaged over [`SMOOTHING_HALF_WINDOW_US`] at the
/// interval's ends: moving both ends of the interval earlier by `d` adds the start's twist and
/// drops the end's, `dm/d offset = (v(a) + w(a) S m_xy - R(m_theta) v(b), w(a) - w(b))`. The
/// samples' own velocities at the ends would carry the very noise the motion's residual holds
/// (the end sample is inside the interval): with frames exposed at the odometry's sample
/// times, the batch then fits that noise with the offset, half a sample off (4 ms at 100 Hz).
pub fn vehicle_jacobian(
    samples: &[OdomSample],
    t0_us: u64,
    t1_us: u64,
    v: &Vehicle,
) -> Option<Matrix3x4<f64>> {
    let base = integrate_vehicle(samples, t0_us, t1_us, v)?;
    let vector = |m: &Motion| Vector3::new(m.dx, m.dy, m.dtheta);
    let mut j = Matrix3x4::zeros();
    for (k, h) in VEHICLE_STEPS.iter().enumerate() {
        let shifted = |sign: f64| {
            let mut w = *v;
            let slot = match k {
                0 => &mut w.odom_scale,
                1 => &mut w.odom_yaw_scale,
                _ => &mut w.odom_yaw_bias,
            };
            *slot += sign * h;
            integrate_vehicle(samples, t0_us, t1_us, &w).map(|m| vector(&m))
        };
        let column = match (shifted(1.0), shifted(-1.0)) {
            (Some(p), Some(m)) => (p - m) / (2.0 * h),
            (Some(p), None) => (p - vector(&base)) / *h,
            (None, Some(m)) => (vector(&base) - m) / *h,
            (None, None) => Vector3::zeros(),
        };
        j.set_column(k, &column);
    }
    let (a, b) = (v.odometry_time_us(t0_us), v.odometry_time_us(t1_us));
    if let (Some((ax, ay, aw)), Some((bx, by, bw))) = (
        smoothed_velocity(samples, a, SMOOTHING_HALF_WINDOW_US, v),
        smoothed_velocity(samples, b, SMOOTHING_HALF_WINDOW_US, v),
    ) {
        let (s, c) = (libm::sin(base.dtheta), libm::cos(base.dtheta));
        j.set_column(
            3,
            &Vector3::new(
                ax - aw * base.dy - (c * bx - s * by),
                ay + aw * base.dx - (s * bx + c * by),
                aw - bw,
            ),
        );
    }
    Some(j)
}

/// How long a stretch of reported yaw rate [`filter_yaw_scale_column`] averages, microseconds.
pub const INSTRUMENT_WINDOW_US: u64 = 2 * SMOOTHING_HALF_WINDOW_US;

/// How long before the interval [`filter_yaw_scale_column`]'s stretch ends, microseconds: long
/// enough that the filter's heading no longer holds that stretch's noise (the stereo updates
/// take it out within a few frames). Measured on the independent simulator's straight drive
/// (the filter alone, yaw scale unobservable, prior 1 +- 2 %): the yaw scale ended at 1.115
/// with the interval's own samples, 1.041 with the stretch just before the interval, 1.010,
/// 1.008 and 1.010 with gaps of 100, 200 and 400 ms.
pub const INSTRUMENT_GAP_US: u64 = 150_000;

/// The yaw scale's column of `d motion / dV` for a filter that predicts with the motion
/// (`pose' = pose (+) m(V)`): the interval `[t0_us, t1_us]` integrated as if the vehicle had
/// held the velocities reported over [`INSTRUMENT_WINDOW_US`] ending [`INSTRUMENT_GAP_US`]
/// before it. `None` when the samples do not cover that stretch (the log's start, a gap in
/// the odometry): the interval's own column is the one then.
///
/// Why not the interval's own samples (errors in the variables): the filter's prediction puts
/// their noise into the pose and, through this column, into the pose's covariance with the
/// yaw scale; the update that takes the noise back out of the heading then moves the yaw
/// scale by the product of the two, whose mean is not zero, and always up (a larger scale
/// explains the noise as a smaller motion). On a straight drive, where the true yaw rate is
/// zero and the column is noise alone, the filter's yaw scale rose 7 of its prior's sigmas in
/// 80 s (`crates/replay/tests/integration/vehicle.rs`). A stretch just before the interval
/// shares no noise with it, but the heading still holds part of that stretch's noise when
/// the update comes: the gap lets the updates between take it out. The batch's factor keeps
/// its own column: its residual is in the reported odometry's units, where the yaw scale's
/// derivative is the estimated heading change, not the reported one (docs/vehicle.md, "Errors
/// in the variables"). For errors with memory the stretch shares the interval's errors and is
/// no instrument: the navigator then keeps the interval's own column.
pub fn filter_yaw_scale_column(
    samples: &[OdomSample],
    t0_us: u64,
    t1_us: u64,
    v: &Vehicle,
) -> Option<Vector3<f64>> {
    let start_us = v.odometry_time_us(t0_us);
    let to = start_us.checked_sub(INSTRUMENT_GAP_US)?;
    let from = to.checked_sub(INSTRUMENT_WINDOW_US)?;
    if samples.first()?.t_us > from {
        return None;
    }
    // The samples from the stretch's start to the interval's, each held until the next: a
    // dropout shows as a long hold (in the gap too, where a sample held into the interval
    // would share its noise). Longer than the stretch itself is a dropout; a 10 Hz odometry's
    // 100 ms holds are not (its stretch then averages two samples).
    let first = samples
        .partition_point(|s| s.t_us <= from)
        .saturating_sub(1);
    let end = samples.partition_point(|s| s.t_us < start_us);
    let held_longest = samples
        .get(first..end)?
        .iter()
        .enumerate()
        .map(|(k, s)| {
            let next = samples
                .get(first + k + 1)
                .map_or(start_us, |n| n.t_us.min(start_us));
            next.saturating_sub(s.t_us.max(from))
        })
        .max()?;
    if held_longest > INSTRUMENT_WINDOW_US {
        return None;
    }
    let half = INSTRUMENT_WINDOW_US / 2;
    let (vx, vy, vtheta) = smoothed_velocity(samples, from + half, half, &Vehicle::NOMINAL)?;
    let held = [OdomSample {
        t_us: start_us,
        vx,
        vy,
        vtheta,
    }];
    vehicle_jacobian(&held, t0_us, t1_us, v).map(|j| j.column(1).into_owned())
}

/// The odometry between two frames as the estimators take it: the motion integrated for the
/// vehicle estimate `vehicle`, its covariance, and how it changes with `V`, so that a solver
/// that refines `V` moves the motion with it. With the reported samples around the interval
/// ([`Self::samples`]) the motion is integrated again for every `V` a solver tries
/// ([`Self::at`]): a first-order model of the clock offset made at one offset uses the
/// velocities of other samples than the ones the frames were exposed between, and their
/// noise is then an error in the regressor that shrinks the offset's estimate toward the
/// linearisation point (errors in variables; 8 of 12 ms on the aisle).
#[cfg(feature = "alloc")]
#[derive(Debug, Clone, PartialEq)]
pub struct OdometryFactor {
    /// The motion for `vehicle`.
    pub motion: Motion,
    /// Covariance of `(dx, dy, dtheta)` in the reported odometry's units: from the noise of
    /// the reported velocities (the batch weighs `diag(odom_scale, odom_scale, odom_yaw_scale)`
    /// times the true-motion residual with it).
    pub covariance: Matrix3<f64>,
    /// The vehicle parameters the motion was integrated with.
    pub vehicle: Vehicle,
    /// `d(dx, dy, dtheta) / dV` at `vehicle`, [`crate::Param::VEHICLE`] order.
    pub vehicle_jacobian: Matrix3x4<f64>,
    /// The board's stamps of the two frames, microseconds.
    pub frames_us: (u64, u64),
    /// The reported odometry samples around the interval (empty: the first-order model only).
    pub samples: Vec<OdomSample>,
}

#[cfg(feature = "alloc")]
impl OdometryFactor {
    /// A motion that does not depend on `V` (the vehicle nominal, no Jacobian, no samples).
    pub fn fixed(motion: Motion, covariance: Matrix3<f64>) -> Self {
        Self {
            motion,
            covariance,
            vehicle: Vehicle::NOMINAL,
            vehicle_jacobian: Matrix3x4::zeros(),
            frames_us: (0, 0),
            samples: Vec::new(),
        }
    }

    /// The motion for the vehicle `v`, to first order in `v - vehicle`.
    pub fn motion_at(&self, v: &Vehicle) -> Motion {
        let a = v.to_array();
        let b = self.vehicle.to_array();
        let d = nalgebra::Vector4::from_fn(|i, _| a[i] - b[i]);
        let dm = self.vehicle_jacobian * d;
        Motion {
            dx: self.motion.dx + dm.x,
            dy: self.motion.dy + dm.y,
            dtheta: self.motion.dtheta + dm.z,
            ..self.motion
        }
    }

    /// The motion for the vehicle `v`: integrated again from the samples for its scales and
    /// bias, over the interval of the offset it was made with, and moved to `v`'s clock offset
    /// to first order with the smoothed regressor ([`vehicle_jacobian`]): integrating again
    /// over a shifted interval would let the offset fit the noise of the samples it moves
    /// across. Without samples, all to first order.
    pub fn motion_for(&self, v: &Vehicle) -> Motion {
        self.at_inner(v, false).0
    }

    /// The motion and its Jacobian `d motion / dV` for the vehicle `v` (see
    /// [`Self::motion_for`]).
    pub fn at(&self, v: &Vehicle) -> (Motion, Matrix3x4<f64>) {
        self.at_inner(v, true)
    }

    fn at_inner(&self, v: &Vehicle, jacobian: bool) -> (Motion, Matrix3x4<f64>) {
        if *v == self.vehicle || self.samples.is_empty() {
            return (self.motion_at(v), self.vehicle_jacobian);
        }
        let (t0, t1) = self.frames_us;
        let at_made = Vehicle {
            time_offset: self.vehicle.time_offset,
            ..*v
        };
        let Some(m) = integrate_vehicle(&self.samples, t0, t1, &at_made) else {
            return (self.motion_at(v), self.vehicle_jacobian);
        };
        let j = if jacobian {
            vehicle_jacobian(&self.samples, t0, t1, &at_made).unwrap_or(self.vehicle_jacobian)
        } else {
            self.vehicle_jacobian
        };
        let d = v.time_offset - self.vehicle.time_offset;
        let shift = j.column(3) * d;
        (
            Motion {
                dx: m.dx + shift.x,
                dy: m.dy + shift.y,
                dtheta: m.dtheta + shift.z,
                ..m
            },
            j,
        )
    }
}

/// How long before the first sample the odometry may be taken as that sample held back,
/// microseconds. A frame can be exposed before the odometry's first sample (a log that starts
/// with a frame, or a frame stamped before its exposure by a negative clock offset still
/// unknown): without it the first interval had no odometry, phase 1's chain hung from the
/// first frame by a weak factor, and a -24 ms offset left the pose known to 10 m at the
/// hand-over.
pub const BACKWARD_HOLD_US: u64 = 100_000;

/// The index of the sample held at `t0_us` (the last at or before it, or the first one when
/// `t0_us` is at most [`BACKWARD_HOLD_US`] before it) and the time to integrate from.
pub fn start_of(samples: &[OdomSample], t0_us: u64) -> Option<(usize, u64)> {
    match samples.partition_point(|s| s.t_us <= t0_us).checked_sub(1) {
        Some(i) => Some((i, t0_us)),
        None => {
            let first = samples.first()?;
            (first.t_us - t0_us <= BACKWARD_HOLD_US).then_some((0, t0_us))
        }
    }
}

/// [`integrate`] with the velocities of each sample given by `velocities` (the reported ones
/// corrected by a vehicle model).
pub fn integrate_with(
    samples: &[OdomSample],
    t0_us: u64,
    t1_us: u64,
    velocities: impl Fn(&OdomSample) -> (f64, f64, f64),
) -> Option<Motion> {
    if t1_us < t0_us {
        return None;
    }
    let (start, t0_us) = start_of(samples, t0_us)?;
    let mut motion = Motion::default();
    let mut t = t0_us;
    for (i, s) in samples.iter().enumerate().skip(start) {
        if t >= t1_us {
            break;
        }
        let end = samples.get(i + 1).map_or(t1_us, |n| n.t_us.min(t1_us));
        if end <= t {
            continue;
        }
        #[allow(clippy::cast_precision_loss)] // microsecond spans far below 2^53
        let dt = (end - t) as f64 * 1e-6;
        let (vx, vy, w) = velocities(s);
        motion = motion.then(&constant_velocity_motion(vx, vy, w, dt));
        t = end;
    }
    Some(motion)
}

/// `d(a (+) b) / d a` for motions (or a pose `a` and a motion `b`): the Jacobian of the
/// composition with respect to the first, at `a`'s angle `theta_a`.
pub fn compose_jacobian_first(theta_a: f64, b: &Motion) -> Matrix3<f64> {
    let (s, c) = (libm::sin(theta_a), libm::cos(theta_a));
    Matrix3::new(
        1.0,
        0.0,
        -s * b.dx - c * b.dy,
        0.0,
        1.0,
        c * b.dx - s * b.dy,
        0.0,
        0.0,
        1.0,
    )
}

/// `d(a (+) b) / d b`: the rotation of `a` in the plane, identity on the angle.
pub fn compose_jacobian_second(theta_a: f64) -> Matrix3<f64> {
    let (s, c) = (libm::sin(theta_a), libm::cos(theta_a));
    Matrix3::new(c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0)
}

#[cfg(all(test, feature = "alloc"))]
mod tests {
    use super::*;

    /// A vehicle accelerating and turning: true velocities at `hz`, as functions of time.
    fn truth(t_s: f64) -> (f64, f64, f64) {
        (0.2 + 0.5 * t_s, 0.02 * t_s, 0.1 + 0.2 * t_s)
    }

    fn reported(v: &Vehicle, hz: f64, seconds: f64) -> Vec<OdomSample> {
        let n = (seconds * hz) as usize;
        (0..n)
            .map(|i| {
                let t_s = i as f64 / hz;
                let (vx, vy, w) = truth(t_s);
                let (vx, vy, vtheta) = v.reported_velocities(vx, vy, w);
                OdomSample {
                    t_us: (t_s * 1e6).round() as u64,
                    vx,
                    vy,
                    vtheta,
                }
            })
            .collect()
    }

    const V: Vehicle = Vehicle {
        odom_scale: 1.015,
        odom_yaw_scale: 0.995,
        odom_yaw_bias: 0.002,
        time_offset: 0.012,
    };

    /// The reported odometry of a vehicle `V`, integrated for `V` between two board stamps,
    /// is the true motion between the exposures.
    #[test]
    fn integrating_for_the_vehicle_undoes_its_errors() {
        let samples = reported(&V, 100.0, 3.0);
        let truth_samples = reported(&Vehicle::NOMINAL, 100.0, 3.0);
        let (t0, t1) = (1_012_000, 1_512_000); // stamps; exposures at 1.0 s and 1.5 s
        let m = integrate_vehicle(&samples, t0, t1, &V).unwrap();
        let want = integrate(&truth_samples, 1_000_000, 1_500_000).unwrap();
        for (a, b) in [(m.dx, want.dx), (m.dy, want.dy), (m.dtheta, want.dtheta)] {
            assert!((a - b).abs() < 1e-12, "{a} vs {b}");
        }
        // Nominal: the plain integration.
        assert_eq!(
            integrate_vehicle(&samples, t0, t1, &Vehicle::NOMINAL),
            integrate(&samples, t0, t1)
        );
    }

    /// The Jacobian with respect to V matches finite differences of the integration on a
    /// finely sampled smooth drive (the clock offset's column from smoothed velocities too).
    #[test]
    fn vehicle_jacobian_matches_finite_differences() {
        let samples = reported(&V, 1000.0, 3.0);
        let (t0, t1) = (1_012_000, 1_512_000);
        let j = vehicle_jacobian(&samples, t0, t1, &V).unwrap();
        let steps = [1e-3, 1e-3, 1e-3, 2e-3];
        for (k, h) in steps.iter().enumerate() {
            let at = |sign: f64| {
                let mut w = V;
                let slot = match k {
                    0 => &mut w.odom_scale,
                    1 => &mut w.odom_yaw_scale,
                    2 => &mut w.odom_yaw_bias,
                    _ => &mut w.time_offset,
                };
                *slot += sign * h;
                let m = integrate_vehicle(&samples, t0, t1, &w).unwrap();
                Vector3::new(m.dx, m.dy, m.dtheta)
            };
            let fd = (at(1.0) - at(-1.0)) / (2.0 * h);
            let err = (fd - j.column(k)).norm();
            assert!(
                err <= 2e-3 * fd.norm().max(1e-3),
                "column {k}: {fd} vs {}",
                j.column(k)
            );
        }
    }

    /// The filter's yaw-scale column holds none of the noise reported inside the interval or
    /// in the gap before it: it is the interval integrated with the mean yaw rate reported
    /// over the stretch before the gap. Without samples over the stretch, or with a dropout
    /// between it and the interval, there is none (the interval's own column then).
    #[test]
    fn the_filter_s_yaw_scale_column_is_free_of_the_interval_s_noise() {
        let samples = reported(&V, 100.0, 3.0);
        let (t0, t1) = (1_512_000, 1_562_000);
        let start = V.odometry_time_us(t0);
        let mut noisy = samples.clone();
        for (k, s) in noisy.iter_mut().enumerate() {
            if s.t_us + INSTRUMENT_GAP_US >= start && s.t_us < V.odometry_time_us(t1) {
                s.vtheta += if k % 2 == 0 { 0.05 } else { -0.03 };
            }
        }
        let clean = filter_yaw_scale_column(&samples, t0, t1, &V).unwrap();
        let dirty = filter_yaw_scale_column(&noisy, t0, t1, &V).unwrap();
        assert!((clean - dirty).norm() < 1e-12, "{clean} vs {dirty}");
        // The yaw rate held through the interval is the stretch's mean (the samples held
        // from their ticks: the ramp's value half a sample before the stretch's middle).
        let mid_s = (start - INSTRUMENT_GAP_US - INSTRUMENT_WINDOW_US / 2) as f64 * 1e-6 - 0.005;
        let dt = (t1 - t0) as f64 * 1e-6;
        let want = -truth(mid_s).2 / V.odom_yaw_scale * dt;
        assert!(
            (clean.z - want).abs() < 1e-3 * want.abs(),
            "{} vs {want}",
            clean.z
        );
        // The interval's own column holds the noise.
        let own = |s: &[OdomSample]| {
            vehicle_jacobian(s, t0, t1, &V)
                .unwrap()
                .column(1)
                .into_owned()
        };
        assert!((own(&samples) - own(&noisy)).norm() > 1e-6);
        // Before the samples cover the stretch: none (the interval's own column then).
        assert!(filter_yaw_scale_column(&samples, 100_000, 150_000, &V).is_none());
        let late: Vec<OdomSample> = samples
            .iter()
            .copied()
            .filter(|s| s.t_us >= 1_300_000)
            .collect();
        assert!(filter_yaw_scale_column(&late, t0, t1, &V).is_none());
        // A dropout of 250 ms in the gap (the sample before it held into the interval): none.
        let dropout: Vec<OdomSample> = samples
            .iter()
            .copied()
            .filter(|s| !(s.t_us > start - 250_000 && s.t_us < start))
            .collect();
        assert!(filter_yaw_scale_column(&dropout, t0, t1, &V).is_none());
        // 10 Hz odometry (holds of 100 ms): a column.
        let ten_hz: Vec<OdomSample> = samples.iter().copied().step_by(10).collect();
        assert!(filter_yaw_scale_column(&ten_hz, t0, t1, &V).is_some());
    }

    /// A factor moved to another V: exact in the scales and the bias (integrated again),
    /// first order in the clock offset.
    #[test]
    fn a_factor_follows_v() {
        let samples = reported(&V, 100.0, 3.0);
        let (t0, t1) = (1_012_000, 1_062_000);
        let made = Vehicle::NOMINAL;
        let factor = OdometryFactor {
            motion: integrate_vehicle(&samples, t0, t1, &made).unwrap(),
            covariance: Matrix3::identity() * 1e-6,
            vehicle: made,
            vehicle_jacobian: vehicle_jacobian(&samples, t0, t1, &made).unwrap(),
            frames_us: (t0, t1),
            samples: samples.clone(),
        };
        let scales_only = Vehicle {
            time_offset: 0.0,
            ..V
        };
        let m = factor.motion_for(&scales_only);
        let want = integrate_vehicle(&samples, t0, t1, &scales_only).unwrap();
        assert!((m.dx - want.dx).abs() < 1e-12 && (m.dtheta - want.dtheta).abs() < 1e-12);
        let (m, _) = factor.at(&V);
        let want = integrate_vehicle(&samples, t0, t1, &V).unwrap();
        // 12 ms of a 0.5 m/s^2 drive: first order leaves well under a millimetre.
        assert!((m.dx - want.dx).abs() < 2e-4, "{} vs {}", m.dx, want.dx);
        // Without samples: first order throughout.
        let bare = OdometryFactor {
            samples: Vec::new(),
            ..factor.clone()
        };
        assert_eq!(bare.motion_for(&V), bare.motion_at(&V));
    }
}
