//! Robot paths and odometry (vehicle-interfaces.md section 2).
//!
//! A path is a list of segments (straight, turn in place, arc, wait), each driven from rest to
//! rest with a trapezoidal speed profile inside the speed and acceleration limits. The profile
//! is cut into odometry intervals: each sample's velocity is the interval's mean velocity,
//! held constant until the next sample, so that integrating the true samples with
//! [`integrate`] gives the true trajectory exactly (it *is* the true trajectory), and the
//! segments' lengths and angles come out exact. The path starts at `path.start`.
//!
//! A `"moved"` segment is the exception: the vehicle is carried while its wheels stand still.
//! Its ticks hold zero velocities (what the wheels did), the pose stays where it was until the
//! segment's last tick and is then the segment's target: the camera is blind in between, so
//! nobody sees the pose there.

use rand::Rng;
use rand_distr::{Distribution, StandardNormal};
use rig_model::Pose2;

use crate::scenario::{MovedOdometry, PathSpec, Segment, SegmentKind};

/// One odometry sample (vehicle-log's type): robot-frame velocities held from `t_us` until
/// the next sample.
pub use vehicle_log::OdomSample;

/// Moves `pose` by the robot-frame velocities `(vx, vy, vtheta)` held for `dt_s` seconds:
/// the exact solution of `dX/dt, dY/dt = Rz(theta) (vx, vy)`, `dtheta/dt = vtheta`
/// (vehicle-interfaces.md section 2). Theta is not wrapped.
pub fn integrate(pose: &Pose2, vx: f64, vy: f64, vtheta: f64, dt_s: f64) -> Pose2 {
    let a = vtheta * dt_s;
    // (sin a) / vtheta and (1 - cos a) / vtheta, by their series near a = 0.
    let (s, c) = if a.abs() < 1e-4 {
        let a2 = a * a;
        (dt_s * (1.0 - a2 / 6.0), dt_s * a / 2.0 * (1.0 - a2 / 12.0))
    } else {
        (a.sin() / vtheta, (1.0 - a.cos()) / vtheta)
    };
    let dx_in_robot = vx * s - vy * c;
    let dy_in_robot = vx * c + vy * s;
    let (st, ct) = pose.theta.sin_cos();
    Pose2::new(
        pose.x + ct * dx_in_robot - st * dy_in_robot,
        pose.y + st * dx_in_robot + ct * dy_in_robot,
        pose.theta + a,
    )
}

/// The pose at `t_us` from odometry samples, starting from `start` at the first sample's time
/// (before it: `start`). Each sample's velocities are held until the next; the last one's
/// until `t_us`.
pub fn integrate_samples(samples: &[OdomSample], start: Pose2, t_us: u64) -> Pose2 {
    let mut pose = start;
    for (i, s) in samples.iter().enumerate() {
        if s.t_us >= t_us {
            break;
        }
        let end = samples.get(i + 1).map_or(t_us, |n| n.t_us.min(t_us));
        pose = integrate(&pose, s.vx, s.vy, s.vtheta, us_to_s(end - s.t_us));
    }
    pose
}

/// An angle in `(-pi, pi]`, by `rem_euclid`. Not the rig model's
/// (`rig_model::camera::wrap_angle`, by `floor`, no_std): the two round differently in the
/// last bit outside `(-pi, pi]`, and the committed fixture logs hold this one's truth bit for
/// bit (`tests/integration/fixture_logs.rs`); changing it means regenerating them.
pub fn wrap_angle(a: f64) -> f64 {
    let w = a.rem_euclid(std::f64::consts::TAU);
    if w > std::f64::consts::PI {
        w - std::f64::consts::TAU
    } else {
        w
    }
}

#[allow(clippy::cast_precision_loss)] // microsecond spans of a run are far below 2^52
pub(crate) fn us_to_s(us: u64) -> f64 {
    us as f64 * 1e-6
}

/// The time of tick `i` of a clock of `hz` from `start_t_us` (rounded to the microsecond, no
/// drift).
#[allow(
    clippy::cast_possible_truncation,
    clippy::cast_sign_loss,
    clippy::cast_precision_loss
)]
pub(crate) fn tick_us(start_t_us: u64, phase_us: u64, hz: f64, i: usize) -> u64 {
    // i / hz * 1e6 is positive and below 2^53 for any run that fits in memory.
    start_t_us + phase_us + (i as f64 * 1e6 / hz).round() as u64
}

/// The robot's true motion: odometry ticks and the pose at each.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Motion {
    /// True odometry samples (the last one at rest, held forever): what the wheels did.
    pub samples: Vec<OdomSample>,
    /// The true pose at each sample's time (theta not wrapped).
    pub poses: Vec<Pose2>,
    /// The `"moved"` segments, in time order.
    pub carries: Vec<Carry>,
}

/// One `"moved"` segment as driven: odometry ticks `first..end` (the pose is the target from
/// tick `end` on).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Carry {
    /// Its first odometry tick.
    pub first: usize,
    /// The tick after its last: the vehicle stands at the target.
    pub end: usize,
    /// Where it is left, world frame (theta not wrapped).
    pub to: Pose2,
    /// What the odometry sends during it.
    pub odometry: MovedOdometry,
}

impl Motion {
    /// Builds the motion: at rest at `path.start` from `start_t_us` until the first tick at
    /// or after `first_frame_us`, then the path, then one last sample at rest.
    pub(crate) fn new(
        path: &PathSpec,
        start_t_us: u64,
        odometry_hz: f64,
        first_frame_us: u64,
    ) -> Self {
        let dt = 1.0 / odometry_hz;
        let mut velocities: Vec<(f64, f64)> = Vec::new();
        let mut carries = Vec::new();
        let t = |i| tick_us(start_t_us, 0, odometry_hz, i);
        // At rest until the first frame, so that the start pose is the pose at the first frame.
        while t(velocities.len()) < first_frame_us {
            velocities.push((0.0, 0.0));
        }
        for _ in 0..path.repeat {
            for seg in &path.segments {
                if seg.kind == SegmentKind::Moved {
                    let first = velocities.len();
                    velocities.extend(std::iter::repeat_n((0.0, 0.0), ticks(seg, dt).max(1)));
                    let value = |x: Option<f64>| x.unwrap_or(0.0); // validated: present
                    carries.push(Carry {
                        first,
                        end: velocities.len(),
                        to: Pose2::new(
                            value(seg.x_m),
                            value(seg.y_m),
                            value(seg.yaw_deg).to_radians(),
                        ),
                        odometry: seg.odometry.unwrap_or_default(),
                    });
                } else {
                    segment_velocities(path, seg, dt, &mut velocities);
                }
            }
        }
        let mut samples = Vec::with_capacity(velocities.len() + 1);
        let mut poses = Vec::with_capacity(velocities.len() + 1);
        let mut pose = path.start.pose();
        let mut next_carry = carries.iter().peekable();
        for (i, &(v, w)) in velocities.iter().enumerate() {
            let (t0, t1) = (t(i), t(i + 1));
            samples.push(OdomSample {
                t_us: t0,
                vx: v,
                vy: 0.0,
                vtheta: w,
            });
            poses.push(pose);
            pose = integrate(&pose, v, 0.0, w, us_to_s(t1 - t0));
            // Put down at the target at the end of a carry (two carries never end together:
            // each is at least one tick long).
            if let Some(c) = next_carry.next_if(|c| c.end == i + 1) {
                pose = c.to;
            }
        }
        samples.push(OdomSample {
            t_us: t(velocities.len()),
            vx: 0.0,
            vy: 0.0,
            vtheta: 0.0,
        });
        poses.push(pose);
        Self {
            samples,
            poses,
            carries,
        }
    }

    /// Whether the camera is blind at `t_us`: strictly inside a carry (at its first tick the
    /// vehicle still stands where it was, at its end where it was put down).
    pub(crate) fn blind_at(&self, t_us: u64) -> bool {
        self.carries.iter().any(|c| {
            let (Some(a), Some(b)) = (self.samples.get(c.first), self.samples.get(c.end)) else {
                return false;
            };
            a.t_us < t_us && t_us < b.t_us
        })
    }

    /// Whether the odometry sends sample `i`: not during a carry with `odometry = "none"`.
    pub(crate) fn sends(&self, i: usize) -> bool {
        !self
            .carries
            .iter()
            .any(|c| c.odometry == MovedOdometry::None && (c.first..c.end).contains(&i))
    }

    /// The true pose at `t_us` (at or after the first sample).
    pub(crate) fn pose_at(&self, t_us: u64) -> Pose2 {
        let i = self
            .samples
            .partition_point(|s| s.t_us <= t_us)
            .saturating_sub(1);
        match (self.samples.get(i), self.poses.get(i)) {
            (Some(s), Some(p)) if t_us >= s.t_us => {
                integrate(p, s.vx, s.vy, s.vtheta, us_to_s(t_us - s.t_us))
            }
            _ => Pose2::default(),
        }
    }

    /// Time of the last sample.
    pub(crate) fn end_us(&self) -> u64 {
        self.samples.last().map_or(0, |s| s.t_us)
    }

    /// The true samples the odometry sends (not those of a carry with `odometry = "none"`).
    pub(crate) fn sent_truth(&self) -> Vec<OdomSample> {
        self.samples
            .iter()
            .enumerate()
            .filter(|&(i, _)| self.sends(i))
            .map(|(_, s)| *s)
            .collect()
    }

    /// The measured odometry as sent: `(1 + scale) v + e_v`, `(1 + yaw scale) w + bias + e_w`.
    /// The errors `e` are white, or with `velocity_tau_s` / `yaw_rate_tau_s` a first-order
    /// Gauss-Markov process of that time constant and of the stationary sigma given
    /// (vehicle-interfaces.md section 2): `e_k = phi e_(k-1) + sqrt(1 - phi^2) sigma n_k`,
    /// `phi = exp(-dt / tau)`, started from its stationary distribution. Every sample draws its
    /// three normals, sent or not, so that a sample's noise does not depend on what the odometry
    /// did before it, and a white run (`tau = 0`, `phi = 0`) draws the same numbers as before.
    pub(crate) fn measured(
        &self,
        noise: &crate::scenario::NoiseSpec,
        rng: &mut impl Rng,
    ) -> Vec<OdomSample> {
        let mut errors = [0.0_f64; 3];
        let mut last_t: Option<u64> = None;
        let sigma = [noise.velocity_mps, noise.velocity_mps, noise.yaw_rate_radps];
        let tau = [
            noise.velocity_tau_s,
            noise.velocity_tau_s,
            noise.yaw_rate_tau_s,
        ];
        let measured = self.samples.iter().map(|s| {
            let draws: [f64; 3] = [
                StandardNormal.sample(rng),
                StandardNormal.sample(rng),
                StandardNormal.sample(rng),
            ];
            #[allow(clippy::cast_precision_loss)] // microsecond spans far below 2^53
            let dt = last_t.map(|t0| s.t_us.saturating_sub(t0) as f64 * 1e-6);
            last_t = Some(s.t_us);
            for ((e, n), (sd, tc)) in errors.iter_mut().zip(draws).zip(sigma.into_iter().zip(tau)) {
                // The first sample starts from the stationary distribution (phi = 0).
                let phi = match dt {
                    Some(dt) if tc > 0.0 => (-dt / tc).exp(),
                    _ => 0.0,
                };
                *e = phi * *e + (1.0 - phi * phi).sqrt() * sd * n;
            }
            let scale = 1.0 + noise.velocity_scale_error;
            OdomSample {
                t_us: s.t_us,
                vx: scale * s.vx + errors[0],
                vy: scale * s.vy + errors[1],
                vtheta: (1.0 + noise.yaw_rate_scale_error) * s.vtheta
                    + noise.yaw_rate_bias_radps
                    + errors[2],
            }
        });
        measured
            .enumerate()
            .filter(|&(i, _)| self.sends(i))
            .map(|(_, s)| s)
            .collect()
    }
}

/// What a segment's profile covers: the distance (metres, or radians for a turn), its
/// speed and acceleration limits, and how a unit of it maps to `(v, w)`.
struct Profile {
    distance: f64,
    vmax: f64,
    amax: f64,
    /// `(v, w)` per unit of the profile's speed (signs included).
    per_unit: (f64, f64),
}

/// The profile of a moving segment, `None` for a wait.
fn profile(path: &PathSpec, seg: &Segment) -> Option<Profile> {
    let value = |x: Option<f64>| x.unwrap_or(0.0); // validated: present for the kind
    match seg.kind {
        SegmentKind::Straight => {
            let length_m = value(seg.length_m);
            Some(Profile {
                distance: length_m.abs(),
                vmax: seg
                    .speed_mps
                    .unwrap_or(path.max_speed_mps)
                    .min(path.max_speed_mps),
                amax: path.max_accel_mps2,
                per_unit: (length_m.signum(), 0.0),
            })
        }
        SegmentKind::Turn => {
            let angle_deg = value(seg.angle_deg);
            Some(Profile {
                distance: angle_deg.abs().to_radians(),
                vmax: seg
                    .yaw_rate_degps
                    .unwrap_or(path.max_yaw_rate_degps)
                    .min(path.max_yaw_rate_degps)
                    .to_radians(),
                amax: path.max_yaw_accel_degps2.to_radians(),
                per_unit: (0.0, angle_deg.signum()),
            })
        }
        SegmentKind::Arc => {
            let (radius_m, angle_deg) = (value(seg.radius_m), value(seg.angle_deg));
            Some(Profile {
                distance: angle_deg.abs().to_radians() * radius_m,
                vmax: seg
                    .speed_mps
                    .unwrap_or(path.max_speed_mps)
                    .min(path.max_speed_mps)
                    .min(path.max_yaw_rate_degps.to_radians() * radius_m)
                    .min((path.max_lateral_accel_mps2 * radius_m).sqrt()),
                amax: path
                    .max_accel_mps2
                    .min(path.max_yaw_accel_degps2.to_radians() * radius_m),
                per_unit: (1.0, angle_deg.signum() / radius_m),
            })
        }
        SegmentKind::Wait | SegmentKind::Moved => None,
    }
}

/// The odometry ticks of a wait or a carry: its duration rounded to whole ticks.
fn ticks(seg: &Segment, dt: f64) -> usize {
    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
    // validated: 0..=1e5 s, so the tick count is small and positive
    let n = (seg.duration_s.unwrap_or(0.0) / dt).round() as usize;
    n
}

/// How long the path takes, seconds (before rounding each segment to whole odometry ticks).
pub fn path_duration_s(path: &PathSpec) -> f64 {
    let once: f64 = path
        .segments
        .iter()
        .map(|seg| match profile(path, seg) {
            Some(p) => trapezoid_duration(p.distance, p.vmax, p.amax),
            None => seg.duration_s.unwrap_or(0.0),
        })
        .sum();
    #[allow(clippy::cast_precision_loss)] // repeat is validated to at most 10000
    let total = once * path.repeat as f64;
    total
}

/// Appends one segment's per-tick `(v, w)`.
fn segment_velocities(path: &PathSpec, seg: &Segment, dt: f64, out: &mut Vec<(f64, f64)>) {
    match profile(path, seg) {
        Some(p) => {
            for d in trapezoid_steps(p.distance, p.vmax, p.amax, dt) {
                let speed = d / dt;
                out.push((speed * p.per_unit.0, speed * p.per_unit.1));
            }
        }
        None => out.extend(std::iter::repeat_n((0.0, 0.0), ticks(seg, dt))),
    }
}

/// Duration of a rest-to-rest trapezoidal profile, seconds.
fn trapezoid_duration(distance: f64, vmax: f64, amax: f64) -> f64 {
    if distance <= 0.0 {
        0.0
    } else if distance >= vmax * vmax / amax {
        distance / vmax + vmax / amax
    } else {
        2.0 * (distance / amax).sqrt()
    }
}

/// Displacement in each tick of a rest-to-rest trapezoidal profile covering `distance`
/// (at least zero) with speed at most `vmax` and acceleration at most `amax`. The profile is
/// stretched in time to a whole number of ticks (which only lowers speed and acceleration),
/// and the displacements add up to `distance`.
pub(crate) fn trapezoid_steps(distance: f64, vmax: f64, amax: f64, dt: f64) -> Vec<f64> {
    if distance <= 0.0 {
        return Vec::new();
    }
    let ta_full = vmax / amax;
    let (ta, v_peak, total) = if distance >= vmax * ta_full {
        (ta_full, vmax, distance / vmax + ta_full)
    } else {
        let ta = (distance / amax).sqrt();
        (ta, amax * ta, 2.0 * ta)
    };
    let position = |t: f64| -> f64 {
        if t <= 0.0 {
            0.0
        } else if t < ta {
            0.5 * amax * t * t
        } else if t < total - ta {
            0.5 * amax * ta * ta + v_peak * (t - ta)
        } else if t < total {
            let r = total - t;
            distance - 0.5 * amax * r * r
        } else {
            distance
        }
    };
    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
    // total / dt is positive and bounded by the validated path lengths and limits
    let n = ((total / dt) - 1e-9).ceil().max(1.0) as usize;
    #[allow(clippy::cast_precision_loss)]
    let stretch = total / (n as f64 * dt);
    let mut steps = Vec::with_capacity(n);
    let mut prev = 0.0;
    for i in 1..=n {
        #[allow(clippy::cast_precision_loss)]
        let s = if i == n {
            distance
        } else {
            position(i as f64 * dt * stretch)
        };
        steps.push(s - prev);
        prev = s;
    }
    steps
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn trapezoid_covers_the_distance_within_limits() {
        for (d, vmax, amax) in [
            (2.0, 0.5, 0.5),
            (0.1, 1.0, 0.5),
            (100.0, 2.0, 0.8),
            (1e-4, 1.0, 1.0),
        ] {
            let dt = 0.01;
            let steps = trapezoid_steps(d, vmax, amax, dt);
            let sum: f64 = steps.iter().sum();
            assert!((sum - d).abs() < 1e-12, "{sum} vs {d}");
            let mut prev = 0.0;
            for s in &steps {
                let v = s / dt;
                assert!(v <= vmax * (1.0 + 1e-9), "{v} > {vmax}");
                // The mean acceleration between ticks stays within the limit.
                assert!((v - prev).abs() / dt <= amax * (1.0 + 1e-6) + 1e-9, "accel");
                prev = v;
            }
        }
    }

    #[test]
    fn integrate_matches_fine_euler_steps() {
        let start = Pose2::new(1.0, -2.0, 0.3);
        let (vx, vy, w, dt) = (0.7, 0.1, 0.9, 0.5);
        let exact = integrate(&start, vx, vy, w, dt);
        let mut p = start;
        let n = 200_000;
        let h = dt / f64::from(n);
        for _ in 0..n {
            let (s, c) = (p.theta + 0.5 * w * h).sin_cos();
            p = Pose2::new(
                p.x + h * (c * vx - s * vy),
                p.y + h * (s * vx + c * vy),
                p.theta + w * h,
            );
        }
        assert!((p.x - exact.x).abs() < 1e-9 && (p.y - exact.y).abs() < 1e-9);
        assert!((p.theta - exact.theta).abs() < 1e-9);
        // Tiny yaw rates take the series branch.
        let a = integrate(&start, vx, vy, 1e-7, dt);
        let b = integrate(&start, vx, vy, 0.0, dt);
        assert!((a.x - b.x).abs() < 1e-6 && (a.y - b.y).abs() < 1e-6);
    }

    fn path(segments: Vec<Segment>) -> PathSpec {
        PathSpec {
            max_speed_mps: 1.0,
            max_accel_mps2: 1.0,
            max_yaw_rate_degps: 90.0,
            max_yaw_accel_degps2: 90.0,
            max_lateral_accel_mps2: 1.0,
            repeat: 1,
            start: crate::scenario::PoseSpec {
                x_m: 2.0,
                y_m: 3.0,
                yaw_deg: 90.0,
            },
            segments,
        }
    }

    #[test]
    fn a_carry_puts_the_vehicle_down_at_its_target_and_blinds_the_camera_between() {
        let p = path(vec![
            Segment::straight(1.0),
            Segment::moved(0.5, -4.0, 1.0, 180.0, MovedOdometry::None),
            Segment::straight(2.0),
        ]);
        let m = Motion::new(&p, 0, 100.0, 0);
        // From the start pose: 1 m along +y.
        assert_eq!(m.poses[0], Pose2::new(2.0, 3.0, 90f64.to_radians()));
        let c = m.carries[0];
        assert_eq!(c.end - c.first, 50);
        let before = m.poses[c.first];
        assert!((before.x - 2.0).abs() < 1e-12 && (before.y - 4.0).abs() < 1e-12);
        // Standing still until put down at the target.
        assert_eq!(m.poses[c.end - 1], before);
        assert_eq!(m.poses[c.end], Pose2::new(-4.0, 1.0, std::f64::consts::PI));
        let end = m.poses.last().copied().unwrap_or_default();
        assert!((end.x + 6.0).abs() < 1e-9 && (end.y - 1.0).abs() < 1e-9);
        // Blind strictly inside; the odometry silent on the carry's ticks.
        let (t0, t1) = (m.samples[c.first].t_us, m.samples[c.end].t_us);
        assert!(!m.blind_at(t0) && m.blind_at(t0 + 1) && m.blind_at(t1 - 1) && !m.blind_at(t1));
        assert!(m.sends(c.first - 1) && !m.sends(c.first) && !m.sends(c.end - 1) && m.sends(c.end));
        assert_eq!(m.sent_truth().len(), m.samples.len() - 50);
        // A carry shorter than a tick is one tick.
        let p = path(vec![Segment::moved(
            1e-4,
            0.0,
            0.0,
            0.0,
            MovedOdometry::Zero,
        )]);
        let m = Motion::new(&p, 0, 100.0, 0);
        assert_eq!(m.carries[0].end - m.carries[0].first, 1);
        assert_eq!(m.sent_truth().len(), m.samples.len());
        assert_eq!(m.poses.last().copied(), Some(Pose2::default()));
    }

    #[test]
    fn wrap() {
        assert!((wrap_angle(3.0 * std::f64::consts::PI) - std::f64::consts::PI).abs() < 1e-12);
        assert!((wrap_angle(-0.5) + 0.5).abs() < 1e-15);
    }
}
