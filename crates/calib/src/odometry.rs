//! Odometry integration (vehicle-interfaces.md section 2): robot-frame velocities
//! `(vx, vy, vtheta)`, each held constant from its timestamp until the next sample.

use crate::camera::Pose2;

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
        motion = motion.then(&constant_velocity_motion(s.vx, s.vy, s.vtheta, dt));
        t = end;
    }
    Some(motion)
}
