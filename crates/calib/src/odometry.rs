//! Odometry integration (vehicle-interfaces.md section 2): robot-frame velocities
//! `(vx, vy, vtheta)`, each held constant from its timestamp until the next sample.

use nalgebra::{Matrix3, Matrix3x4, Vector3};

use crate::camera::{Pose2, Vehicle};

/// One odometry sample.
#[derive(Debug, Clone, Copy, PartialEq)]
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

/// Central-difference steps of the vehicle parameters, [`crate::Param::VEHICLE`] order: small
/// against their plausible errors, large against rounding (the clock offset moves the
/// interval by whole microseconds).
const VEHICLE_STEPS: [f64; 4] = [1e-4, 1e-4, 1e-4, 1e-3];

/// `d(dx, dy, dtheta) / dV` of [`integrate_vehicle`] at `v` (3 x 4, [`crate::Param::VEHICLE`]
/// order), by central differences: the motion is smooth in the scales and the bias, and in
/// the clock offset piecewise smooth (a sample boundary inside the step gives the mean slope).
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
                2 => &mut w.odom_yaw_bias,
                _ => &mut w.time_offset,
            };
            *slot += sign * h;
            integrate_vehicle(samples, t0_us, t1_us, &w).map(|m| vector(&m))
        };
        // One-sided where the shifted interval leaves the samples (the clock offset at the
        // start of the odometry).
        let column = match (shifted(1.0), shifted(-1.0)) {
            (Some(p), Some(m)) => (p - m) / (2.0 * h),
            (Some(p), None) => (p - vector(&base)) / *h,
            (None, Some(m)) => (vector(&base) - m) / *h,
            (None, None) => Vector3::zeros(),
        };
        j.set_column(k, &column);
    }
    Some(j)
}

/// The odometry between two frames as the estimators take it: the motion integrated for the
/// vehicle estimate `vehicle`, its covariance, and how it changes with `V`, so that a solver
/// that refines `V` moves the motion with it (to first order, `m(V) = m + J (V - vehicle)`).
#[derive(Debug, Clone, Copy, PartialEq)]
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
}

impl OdometryFactor {
    /// A motion that does not depend on `V` (the vehicle nominal, no Jacobian).
    pub fn fixed(motion: Motion, covariance: Matrix3<f64>) -> Self {
        Self {
            motion,
            covariance,
            vehicle: Vehicle::NOMINAL,
            vehicle_jacobian: Matrix3x4::zeros(),
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
    // The last sample at or before t0.
    let start = samples
        .partition_point(|s| s.t_us <= t0_us)
        .checked_sub(1)?;
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
