//! The odometry's errors as states (issue 36; [`crate::Settings::odometry_error_states`]).
//!
//! Real wheels slip for a while: vehicle-interfaces.md section 2 and `[noise] velocity_tau`,
//! `yaw_rate_tau` state the errors of the reported velocities as a first-order Gauss-Markov
//! process, `e_{k+1} = phi e_k + w_k`, `phi = exp(-period / tau)`, of stationary sigma the
//! rig's `velocity` (each of `vx`, `vy`) or `yaw_rate`. Weighed as white noise of the same
//! long-run variance ([`rig_model::Noise::white_equivalent`]) the filter cannot tell a slip
//! that lasts a second from a wrong yaw bias, clock offset or map: every later frame
//! explains it by what it estimates. Held as states `E` (one per axis with memory, after the
//! camera block), the prediction over a frame interval `dt` is
//!
//! - the motion of the reported velocities minus `E` (`D_E = d motion / d E`,
//!   [`crate::motion::reported_error_jacobian`]), `E` held over the interval: its columns
//!   enter `P`'s pose rows like the vehicle's parameters' (`crate::predict`);
//! - the error's own change within the interval as noise on the motion: the integral of the
//!   process over `dt` given its start has the variance
//!   `sigma^2 tau^2 (2 dt / tau - 3 + 4 phi - phi^2)` (`phi = exp(-dt / tau)`; about
//!   `2 sigma^2 dt^3 / (3 tau)` for `dt << tau`, against the start's `sigma^2 dt^2`), through
//!   the same columns over `dt^2`;
//! - then `E <- phi E`, `P_E. <- phi P_E.`, `P_EE += (1 - phi^2) sigma^2`: O(n).
//!
//! Taking `E` as constant over the interval (rather than decaying within it) is an error of
//! `dt / (2 tau)` in its effect, 4 % at 20 Hz and 0.6 s. A sample's own period does not
//! appear: the process is the same whatever the odometry's rate. The smoother and phase 1's
//! batch still weigh the odometry by the white equivalent; the smoother's estimate, put back
//! ([`Ekf::replace_marginal`], [`Ekf::set_joint`]), carries `E` along through its
//! cross-covariances.
//!
//! **Off by default: it biases the odometry scales** (docs/vehicle.md, "The errors as
//! states"). The reported velocity is the prediction's input and carries the very error `E`
//! estimates (errors in variables): on a drive of straights and U-turns the odometry scale
//! ends 3 to 6 sigma high, and the 24 memory halls of `hall_mc` end with 76 of 96 vehicle
//! parameters inside 3 sigma (93 with the white equivalent). A one-dimensional filter shows
//! the same and what is honest instead: the true velocity as a state, the reported odometry
//! its measurement (`scripts/odometry_input_bias.py`). That form is here too
//! ([`crate::Settings::odometry_velocity_states`], "the velocity-state form"): honest on the
//! filter-alone drives, failing on the generated halls (not yet traced); off by default.

use alloc::vec::Vec;

use nalgebra::Vector3;
use rig_model::Noise;
use rig_model::odometry::OdomSample;

use crate::error::Error;
use crate::filter::Ekf;
use crate::motion::{Increment, reported_error_jacobian};

/// The velocities' sigma before the first odometry, with the velocity-state form: m/s and
/// rad/s, wider than any forklift's.
pub const VELOCITY_PRIOR_SIGMA: f64 = 2.0;

/// An axis of the reported odometry whose error is a state.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ErrorAxis {
    /// `vx`, m/s.
    Vx,
    /// `vy`, m/s.
    Vy,
    /// `vtheta`, rad/s.
    YawRate,
}

impl ErrorAxis {
    /// The axis's column in `(vx, vy, vtheta)`.
    #[must_use]
    pub const fn index(self) -> usize {
        match self {
            Self::Vx => 0,
            Self::Vy => 1,
            Self::YawRate => 2,
        }
    }

    /// `(stationary sigma, time constant)` of the axis under `noise`.
    #[must_use]
    pub const fn process(self, noise: &Noise) -> (f64, f64) {
        match self {
            Self::Vx | Self::Vy => (noise.velocity, noise.velocity_tau),
            Self::YawRate => (noise.yaw_rate, noise.yaw_rate_tau),
        }
    }

    /// `(phi, (1 - phi^2) sigma^2)` of the axis's error over `dt_s` seconds: how much of it
    /// remains, and the variance it gains.
    #[must_use]
    pub fn decay_over(self, noise: &Noise, dt_s: f64) -> (f64, f64) {
        let (sigma, tau) = self.process(noise);
        let phi = if tau > 0.0 {
            libm::exp(-dt_s / tau)
        } else {
            0.0
        };
        (phi, (1.0 - phi * phi) * sigma * sigma)
    }

    /// The axes with memory under `noise` (a finite, positive time constant and sigma), in
    /// state order.
    #[must_use]
    pub fn with_memory(noise: &Noise) -> Vec<Self> {
        [Self::Vx, Self::Vy, Self::YawRate]
            .into_iter()
            .filter(|a| {
                let (sigma, tau) = a.process(noise);
                tau.is_finite() && tau > 0.0 && sigma.is_finite() && sigma > 0.0
            })
            .collect()
    }
}

/// The variance of `int_0^dt e(t) dt - e(0) tau (1 - phi)` for a first-order Gauss-Markov
/// process of stationary sigma `sigma` and time constant `tau`: the part of the integrated
/// error that its value at the start does not predict, `sigma^2 tau^2 (2 dt/tau - 3 + 4 phi -
/// phi^2)`, `phi = exp(-dt / tau)` (by series below `dt / tau = 1e-3`, where the closed form
/// cancels).
#[must_use]
pub fn integrated_innovation_variance(sigma: f64, tau: f64, dt: f64) -> f64 {
    if !(tau > 0.0 && dt > 0.0) {
        return 0.0;
    }
    let r = dt / tau;
    let bracket = if r < 1e-3 {
        // 2r - 3 + 4 e^-r - e^-2r = 2 r^3 / 3 - r^4 / 2 + 7 r^5 / 30 - ...
        r * r * r * (2.0 / 3.0 - r / 2.0 + 7.0 * r * r / 30.0)
    } else {
        let phi = libm::exp(-r);
        2.0 * r - 3.0 + 4.0 * phi - phi * phi
    };
    sigma * sigma * tau * tau * bracket.max(0.0)
}

impl Ekf {
    /// The odometry's error axes held as states, in state order.
    pub fn error_axes(&self) -> &[ErrorAxis] {
        &self.errors
    }

    /// The odometry's error states: each axis with its estimate (in the reported velocity's
    /// units) and sigma.
    pub fn odometry_errors(&self) -> Vec<(ErrorAxis, f64, f64)> {
        let e0 = self.error_states_start();
        self.errors
            .iter()
            .enumerate()
            .map(|(k, &a)| {
                let i = e0 + k;
                (a, self.x[i], libm::sqrt(self.cov(i, i).max(0.0)))
            })
            .collect()
    }

    /// Index of the first error state (after the velocities, when they are states).
    fn error_states_start(&self) -> usize {
        self.layout().errors_start() + if self.velocity_states { 3 } else { 0 }
    }

    /// Eq. (4)-(5) with the odometry's errors as states (module docs): the samples over the
    /// board's `[t0_us, t1_us]` for the vehicle `v`, their errors `E` taken out of the motion,
    /// the axes without memory weighed as white noise of `noise` (the model in use, widened
    /// or not), `vehicle_jacobian` as [`Self::predict_increment_vehicle`]'s. Without error
    /// states it is [`Self::predict_increment_vehicle`] of the white-equivalent increment.
    ///
    /// # Errors
    ///
    /// As [`Increment::from_odometry_vehicle`] and [`Self::predict_increment_vehicle`].
    pub fn predict_odometry_vehicle(
        &mut self,
        samples: &[OdomSample],
        (t0_us, t1_us): (u64, u64),
        noise: &Noise,
        v: &rig_model::Vehicle,
        vehicle_jacobian: &nalgebra::Matrix3x4<f64>,
    ) -> Result<(), Error> {
        if self.errors.is_empty() {
            let (inc, _, _) =
                Increment::from_odometry_vehicle(samples, t0_us, t1_us, noise, v, false)?;
            return self.predict_increment_vehicle(&inc, vehicle_jacobian);
        }
        if self.velocity_states {
            return self.predict_velocity_form(samples, (t0_us, t1_us), noise, v);
        }
        // The samples around the interval with the errors' estimate taken out: the motion,
        // its derivative in the errors and, when V is estimated, in V are the EKF's Jacobians
        // at the estimate. Taken at the reported samples instead, `d motion / d odom_scale`
        // holds the sample's own error, which the error state's update then correlates with:
        // the scale drifted 3 to 9 sigma high on a straight drive (the test
        // `odometry_errors`).
        let e0 = self.error_states_start();
        let mut offset = [0.0; 3];
        for (k, &axis) in self.errors.iter().enumerate() {
            if let Some(slot) = offset.get_mut(axis.index()) {
                *slot = self.x.get(e0 + k).copied().unwrap_or(0.0);
            }
        }
        let margin = 2 * rig_model::odometry::SMOOTHING_HALF_WINDOW_US + 1_000_000;
        let first = samples
            .partition_point(|s| s.t_us.saturating_add(margin) < t0_us)
            .saturating_sub(1);
        let last = samples.partition_point(|s| s.t_us <= t1_us.saturating_add(margin));
        let shifted: Vec<OdomSample> = samples
            .get(first..last)
            .unwrap_or_default()
            .iter()
            .map(|s| OdomSample {
                t_us: s.t_us,
                vx: s.vx - offset[0],
                vy: s.vy - offset[1],
                vtheta: s.vtheta - offset[2],
            })
            .collect();
        // The axes without memory stay white; the ones held as states carry no white noise.
        let held = |axis: ErrorAxis| self.errors.contains(&axis);
        let white = Noise {
            velocity: if held(ErrorAxis::Vx) {
                0.0
            } else {
                noise.velocity
            },
            yaw_rate: if held(ErrorAxis::YawRate) {
                0.0
            } else {
                noise.yaw_rate
            },
            velocity_tau: 0.0,
            yaw_rate_tau: 0.0,
            ..*noise
        };
        let (mut inc, _, _) =
            Increment::from_odometry_vehicle(&shifted, t0_us, t1_us, &white, v, false)?;
        let d_e = reported_error_jacobian(&shifted, t0_us, t1_us, v)?;
        let jv = if vehicle_jacobian.iter().any(|x| *x != 0.0) {
            rig_model::odometry::vehicle_jacobian(&shifted, t0_us, t1_us, v)
                .unwrap_or(*vehicle_jacobian)
        } else {
            *vehicle_jacobian
        };
        #[allow(clippy::cast_precision_loss)] // microsecond spans far below 2^53
        let dt = t1_us.saturating_sub(t0_us) as f64 * 1e-6;
        let mut columns: Vec<(usize, Vector3<f64>)> = Vec::with_capacity(self.errors.len());
        let mut decay: Vec<(usize, f64, f64)> = Vec::with_capacity(self.errors.len());
        // Cov(the motion's innovation, the error's new value's), in the robot frame: the
        // integral of the process over the interval and its value at the end move together.
        let mut cross: Vec<(usize, Vector3<f64>)> = Vec::with_capacity(self.errors.len());
        for (k, &axis) in self.errors.iter().enumerate() {
            let (sigma, tau) = axis.process(noise);
            let column: Vector3<f64> = d_e.column(axis.index()).into_owned();
            if dt > 0.0 {
                let innovation = integrated_innovation_variance(sigma, tau, dt) / (dt * dt);
                inc.covariance += column * column.transpose() * innovation;
            }
            let (phi, q) = axis.decay_over(noise, dt);
            decay.push((e0 + k, phi, q));
            if dt > 0.0 {
                let c = sigma * sigma * tau * (1.0 - phi) * (1.0 - phi) / dt;
                cross.push((e0 + k, column * c));
            }
            columns.push((e0 + k, column));
        }
        let rot = crate::motion::compose_jacobian_second(self.x[2]);
        self.predict_with_columns(&inc, &jv, &columns)?;
        for (i, phi, q) in decay {
            self.decay_state(i, phi, q);
        }
        for (i, c) in cross {
            self.add_pose_cross(i, &(rot * c));
        }
        Ok(())
    }

    /// The velocity-state form (docs/vehicle.md, "The velocity-state form"): the frame's
    /// reported odometry a measurement of `D u + b + E`, then the pose predicted from the
    /// velocities `u` over the frame, `u` driven by a white acceleration, `E` decaying.
    fn predict_velocity_form(
        &mut self,
        samples: &[OdomSample],
        (t0_us, t1_us): (u64, u64),
        noise: &Noise,
        v: &rig_model::Vehicle,
    ) -> Result<(), Error> {
        #[allow(clippy::cast_precision_loss)] // microsecond spans far below 2^53
        let dt = t1_us.saturating_sub(t0_us) as f64 * 1e-6;
        let u0 = self.layout().errors_start();
        let e0 = u0 + 3;
        self.measure_odometry(samples, (t0_us, t1_us), noise, v, dt)?;
        let u = Vector3::new(self.x[u0], self.x[u0 + 1], self.x[u0 + 2]);
        let motion = rig_model::odometry::constant_velocity_motion(u.x, u.y, u.z, dt);
        let j = crate::motion::arc_velocity_jacobian(u.x, u.y, u.z, dt);
        // `u` is the frame's mean velocity, what the frame's odometry measures: the pose moves
        // by it exactly, and the next frame's mean differs from it by `w` (1 sigma `a dt`).
        // Held as the velocity at the frame's start instead (the pose moving by `u + w / 2`),
        // the odometry's mean and the pose's motion were half a frame apart, and the clock
        // offset took the difference: +25 ms with noise-free odometry (docs/vehicle.md, "The
        // velocity-state form").
        let (a, alpha) = self.settings.velocity_state_acceleration;
        let w2 = Vector3::new(a * a * dt * dt, a * a * dt * dt, alpha * alpha * dt * dt);
        let inc = Increment {
            motion,
            covariance: nalgebra::Matrix3::zeros(),
        };
        for (what, value) in [
            ("velocity state", u.x),
            ("velocity state", u.y),
            ("velocity state", u.z),
        ] {
            crate::filter::check_finite(what, value)?;
        }
        let columns: Vec<(usize, Vector3<f64>)> =
            (0..3).map(|k| (u0 + k, j.column(k).into_owned())).collect();
        self.predict_with_columns(&inc, &nalgebra::Matrix3x4::zeros(), &columns)?;
        for k in 0..3 {
            self.decay_state(u0 + k, 1.0, w2[k]);
        }
        for (k, axis) in self.errors.clone().into_iter().enumerate() {
            let (phi, q) = axis.decay_over(noise, dt);
            self.decay_state(e0 + k, phi, q);
        }
        Ok(())
    }

    /// The frame's reported odometry (its mean over the odometry-clock interval of the board's
    /// `[t0_us, t1_us]`) as a measurement of `h = D u + b + E` over the velocities, the errors
    /// and the estimated vehicle parameters, applied as a linear update of those states
    /// (`crate::marginal`'s form: `x += P_.S g`, `P -= P_.S M P_S.`). No measurement over a gap
    /// in the odometry (a sample held past `motion::ODOMETRY_HOLD_LIMIT_US`) or before it.
    fn measure_odometry(
        &mut self,
        samples: &[OdomSample],
        (t0_us, t1_us): (u64, u64),
        noise: &Noise,
        v: &rig_model::Vehicle,
        dt: f64,
    ) -> Result<(), Error> {
        use rig_model::odometry::smoothed_velocity;
        if dt <= 0.0 {
            return Ok(());
        }
        let (a, b) = (v.odometry_time_us(t0_us), v.odometry_time_us(t1_us));
        let first = samples.partition_point(|s| s.t_us <= a);
        if first == 0 {
            return Ok(());
        }
        let last = samples.partition_point(|s| s.t_us < b);
        let held = samples
            .get(first.saturating_sub(1)..last)
            .unwrap_or_default();
        let mut count = 0_usize;
        for (k, s) in held.iter().enumerate() {
            let end = held.get(k + 1).map_or(b, |n| n.t_us);
            if end.saturating_sub(s.t_us) > crate::motion::ODOMETRY_HOLD_LIMIT_US {
                return Ok(());
            }
            count += 1;
        }
        let nominal = rig_model::Vehicle::NOMINAL;
        let half = (b - a) / 2;
        let Some(z) = smoothed_velocity(samples, a + half, half, &nominal) else {
            return Ok(());
        };
        let z = Vector3::new(z.0, z.1, z.2);
        let u0 = self.layout().errors_start();
        let e0 = u0 + 3;
        let u = Vector3::new(self.x[u0], self.x[u0 + 1], self.x[u0 + 2]);
        let mut e = Vector3::zeros();
        // The states measured and H's columns for them.
        let mut cols: Vec<(usize, Vector3<f64>)> = Vec::new();
        let d = Vector3::new(v.odom_scale, v.odom_scale, v.odom_yaw_scale);
        for k in 0..3 {
            let mut c = Vector3::zeros();
            c[k] = d[k];
            cols.push((u0 + k, c));
        }
        let mut r = Vector3::zeros();
        #[allow(clippy::cast_precision_loss)]
        let n = count.max(1) as f64;
        for axis in [ErrorAxis::Vx, ErrorAxis::Vy, ErrorAxis::YawRate] {
            let k = axis.index();
            let (sigma, tau) = axis.process(noise);
            match self.errors.iter().position(|a| *a == axis) {
                Some(slot) => {
                    e[k] = self.x[e0 + slot];
                    let mut c = Vector3::zeros();
                    c[k] = 1.0;
                    cols.push((e0 + slot, c));
                    r[k] = integrated_innovation_variance(sigma, tau, dt) / (dt * dt);
                }
                // White errors: the frame's mean of `n` samples.
                None => r[k] = sigma * sigma / n,
            }
        }
        for (k, p) in self.estimated.iter().enumerate() {
            let c = match p {
                rig_model::Param::OdomScale => Vector3::new(u.x, u.y, 0.0),
                rig_model::Param::OdomYawScale => Vector3::new(0.0, 0.0, u.z),
                rig_model::Param::OdomYawBias => Vector3::new(0.0, 0.0, 1.0),
                rig_model::Param::TimeOffset => {
                    // `z` is the mean over the interval at the offset's estimate: moving the
                    // interval earlier by d gains the start's velocity and loses the end's,
                    // so `z(estimate) = h(truth) + dz/d offset (estimate - truth)` and
                    // `dh / d offset = -dz / d offset`.
                    let at = |t: u64| {
                        smoothed_velocity(
                            samples,
                            t,
                            rig_model::odometry::SMOOTHING_HALF_WINDOW_US,
                            &nominal,
                        )
                        .map(|w| Vector3::new(w.0, w.1, w.2))
                    };
                    match (at(a), at(b)) {
                        (Some(va), Some(vb)) => (vb - va) / dt,
                        _ => Vector3::zeros(),
                    }
                }
                _ => Vector3::zeros(),
            };
            if c.iter().any(|x| *x != 0.0) {
                cols.push((self.camera_offset() + k, c));
            }
        }
        let h = Vector3::new(
            d.x * u.x + e.x,
            d.y * u.y + e.y,
            d.z * u.z + v.odom_yaw_bias + e.z,
        );
        let nu = z - h;
        // S = H P_SS H^T + R; g = H^T S^-1 nu; M = H^T S^-1 H.
        let m = cols.len();
        let hm = nalgebra::DMatrix::from_fn(3, m, |row, c| cols[c].1[row]);
        let pss = nalgebra::DMatrix::from_fn(m, m, |i, j| self.cov(cols[i].0, cols[j].0));
        let mut s_mat = &hm * &pss * hm.transpose();
        for k in 0..3 {
            s_mat[(k, k)] += r[k].max(1e-12);
        }
        let Some(s_inv) = s_mat.clone().cholesky().map(|c| c.inverse()) else {
            return Err(Error::BadCameraCovariance);
        };
        let nu_d = nalgebra::DVector::from_column_slice(nu.as_slice());
        let g = hm.transpose() * &s_inv * nu_d;
        let mut mm = hm.transpose() * &s_inv * &hm;
        mm = 0.5 * (&mm + mm.transpose());
        let states: Vec<usize> = cols.iter().map(|c| c.0).collect();
        self.apply_marginal_form(&states, &g, &mm)
    }

    /// `P_{pose, i} += c` (both halves): process noise shared by the pose and state `i`.
    fn add_pose_cross(&mut self, i: usize, c: &Vector3<f64>) {
        let add = |p: &mut nalgebra::DMatrix<f64>, k: usize| {
            for (r, v) in c.iter().enumerate() {
                if let Some(e) = p.get_mut((r, k)) {
                    *e += v;
                }
                if let Some(e) = p.get_mut((k, r)) {
                    *e += v;
                }
            }
        };
        match self.local.as_deref_mut() {
            None => add(&mut self.p, i),
            Some(l) => {
                if let Some(&crate::local::Place::Active(k)) = l.place.get(i) {
                    add(&mut l.paa, k);
                }
            }
        }
    }

    /// `x_i <- phi x_i`, `P_i. <- phi P_i.` (both halves), `P_ii += q`: a state that decays
    /// towards zero with process noise `q`. O(n); in an open local session, on `P_AA` and
    /// `phi`'s row (the error states are always active there).
    fn decay_state(&mut self, i: usize, phi: f64, q: f64) {
        if let Some(v) = self.x.get_mut(i) {
            *v *= phi;
        }
        // phi = 1 (the velocities' random walk) only adds the variance: no row to scan.
        let decays = phi != 1.0;
        let scale = |p: &mut nalgebra::DMatrix<f64>, k: usize| {
            let n = p.nrows();
            if k >= n {
                return;
            }
            for j in (0..n).filter(|_| decays) {
                if j == k {
                    continue;
                }
                if let Some(v) = p.get_mut((k, j)) {
                    *v *= phi;
                }
                if let Some(v) = p.get_mut((j, k)) {
                    *v *= phi;
                }
            }
            if let Some(v) = p.get_mut((k, k)) {
                *v = *v * phi * phi + q;
            }
        };
        match self.local.as_deref_mut() {
            None => scale(&mut self.p, i),
            Some(l) => {
                let Some(&crate::local::Place::Active(k)) = l.place.get(i) else {
                    return;
                };
                scale(&mut l.paa, k);
                let na0 = l.n_a0;
                if let Some(row) = l.phit.get_mut(k * na0..(k + 1) * na0).filter(|_| decays) {
                    for v in row {
                        *v *= phi;
                    }
                }
            }
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::indexing_slicing)]
mod tests {
    use super::*;
    use nalgebra::{DMatrix, DVector};
    use rig_model::Param;

    /// A filter of the pose, the odometry scale and the yaw bias and the three error states, its state and covariance set to `x` and `p`.
    fn filter(x: &DVector<f64>, p: &DMatrix<f64>) -> (Ekf, Noise) {
        let mut rig = crate::filter::tests::rig_estimating(&[
            (Param::OdomScale, 0.02),
            (Param::OdomYawBias, 0.005),
        ]);
        rig.noise.velocity_tau = 0.6;
        rig.noise.yaw_rate_tau = 0.4;
        let settings = crate::Settings {
            odometry_error_states: true,
            ..crate::Settings::default()
        };
        let mut ekf = Ekf::from_prior(&rig, settings).unwrap();
        assert_eq!(ekf.state_len(), 8);
        ekf.x = x.clone();
        ekf.p = p.clone();
        (ekf, rig.noise)
    }

    /// 100 Hz samples of a vehicle speeding up in a turn, 0 to 0.3 s.
    fn samples() -> Vec<OdomSample> {
        (0..30)
            .map(|k| {
                let t = f64::from(k) * 0.01;
                OdomSample {
                    t_us: 10_000 * u64::try_from(k).unwrap(),
                    vx: 0.4 + 0.5 * t,
                    vy: 0.01,
                    vtheta: 0.3 - 0.4 * t,
                }
            })
            .collect()
    }

    fn predicted(x: &DVector<f64>, p: &DMatrix<f64>) -> (DVector<f64>, DMatrix<f64>) {
        let (mut ekf, noise) = filter(x, p);
        let v = ekf.camera().vehicle;
        let s = samples();
        let jv = rig_model::odometry::vehicle_jacobian(&s, 100_000, 150_000, &v).unwrap();
        ekf.predict_odometry_vehicle(&s, (100_000, 150_000), &noise, &v, &jv)
            .unwrap();
        (ekf.state().clone(), ekf.covariance())
    }

    /// The prediction's covariance is `A P A^T + Q` with `A` the derivative of its own mean
    /// in the state (central differences: the pose, the vehicle's parameters and the errors
    /// taken out of the motion) and `Q` not depending on `P`.
    #[test]
    fn the_prediction_propagates_the_covariance_with_its_mean_s_derivative() {
        let x = DVector::from_vec(alloc::vec![
            0.3, -0.2, 0.4, // pose
            1.02, 0.003, // odometry scale, yaw bias
            0.015, -0.01, 0.006, // errors: vx, vy, vtheta
        ]);
        let n = x.len();
        let spd = |seed: f64| {
            let b = DMatrix::from_fn(n, n, |i, j| {
                0.01 * libm::sin(seed * (1.0 + i as f64) * (2.0 + j as f64))
            });
            &b * b.transpose() + DMatrix::from_diagonal_element(n, n, 1e-5)
        };
        let mut a = DMatrix::zeros(n, n);
        for j in 0..n {
            let h = 1e-6;
            let (mut xp, mut xm) = (x.clone(), x.clone());
            xp[j] += h;
            xm[j] -= h;
            let d = (predicted(&xp, &spd(1.0)).0 - predicted(&xm, &spd(1.0)).0) / (2.0 * h);
            a.set_column(j, &d);
        }
        let q = |p: &DMatrix<f64>| predicted(&x, p).1 - &a * p * a.transpose();
        let (q1, q2) = (q(&spd(1.0)), q(&spd(2.3)));
        let scale = q1.abs().max().max(1e-12);
        let diff = (&q1 - &q2).abs().max();
        assert!(
            diff < 1e-6 * spd(1.0).abs().max(),
            "Q differs by {diff} ({scale})\n{}",
            &q1 - &q2
        );
        // The errors decay with their own time constants over the 50 ms.
        let (x1, _) = predicted(&x, &spd(1.0));
        assert!((x1[5] - 0.015 * libm::exp(-0.05 / 0.6)).abs() < 1e-12);
        assert!((x1[7] - 0.006 * libm::exp(-0.05 / 0.4)).abs() < 1e-12);
    }

    /// The closed form against a direct sum of a fine-grained process: the integral's
    /// variance given its start.
    #[test]
    fn the_integrated_innovation_matches_a_fine_discretisation() {
        let (sigma, tau) = (0.02, 0.6);
        for dt in [1e-5, 0.01, 0.05, 0.5, 3.0] {
            // e_k = phi e_{k-1} + w_k over steps h; I = sum h e_k; with e_0 = 0 its
            // variance is sum_j (h sum_{k>=j} phi^(k-j))^2 q.
            let steps = 20_000;
            let h = dt / f64::from(steps);
            let phi = libm::exp(-h / tau);
            let q = (1.0 - phi * phi) * sigma * sigma;
            let mut var = 0.0;
            for j in 0..steps {
                let tail = (1.0 - libm::pow(phi, f64::from(steps - j))) / (1.0 - phi);
                var += h * h * tail * tail * q;
            }
            let closed = integrated_innovation_variance(sigma, tau, dt);
            assert!(
                (closed - var).abs() <= 2e-3 * var + 1e-30,
                "dt {dt}: {closed} vs {var}"
            );
        }
    }
}
