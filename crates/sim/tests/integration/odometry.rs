//! Odometry: integrating the samples, each held until the next, gives the truth.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failure is the test failing

use crate::common;

use rig_model::Pose2;
use sim::OdomSample;

/// An integrator independent of the simulator's closed form: midpoint steps of at most
/// 100 us, each sample's velocities held until the next. Returns the pose at each of `times`
/// (increasing).
fn integrate_fine(samples: &[OdomSample], times: &[u64]) -> Vec<Pose2> {
    let (mut x, mut y, mut theta) = (0.0f64, 0.0f64, 0.0f64);
    let mut t = samples[0].t_us;
    let mut out = Vec::new();
    let mut k = 0;
    for &target in times {
        while t < target {
            while samples.get(k + 1).is_some_and(|n| n.t_us <= t) {
                k += 1;
            }
            let s = &samples[k];
            let next = samples.get(k + 1).map_or(u64::MAX, |n| n.t_us);
            let step = (target.min(next) - t).min(100);
            let h = step as f64 * 1e-6;
            let mid = theta + 0.5 * s.vtheta * h;
            let (sn, cs) = mid.sin_cos();
            x += h * (cs * s.vx - sn * s.vy);
            y += h * (sn * s.vx + cs * s.vy);
            theta += s.vtheta * h;
            t += step;
        }
        out.push(Pose2::new(x, y, theta));
    }
    out
}

fn angle_diff(a: f64, b: f64) -> f64 {
    sim::wrap_angle(a - b).abs()
}

#[test]
fn integrated_odometry_is_the_true_trajectory() {
    for name in ["paper-square", "paper-calibration", "warehouse"] {
        let s = common::noise_off(common::load(name));
        let s = if name == "warehouse" {
            common::shorten(s, 3)
        } else {
            s
        };
        let run = sim::simulate(&s, sim::Mode::Fast).unwrap();
        assert_eq!(run.odometry, run.odometry_truth, "{name}: noise off");
        // World frame = robot frame at the first stereo frame.
        assert_eq!(run.frames[0].pose, Pose2::default(), "{name}");
        let mut worst = 0.0f64;
        let times: Vec<u64> = run.frames.iter().map(|f| f.t_us).collect();
        let fine = integrate_fine(&run.odometry, &times);
        for (f, p) in run.frames.iter().zip(&fine) {
            worst = worst.max((p.x - f.pose.x).hypot(p.y - f.pose.y));
            assert!(
                angle_diff(p.theta, f.pose.theta) < 1e-9,
                "{name} frame {}",
                f.index
            );
        }
        // The library's own integrator agrees too.
        for f in run.frames.iter().step_by(97) {
            let q = sim::integrate_samples(&run.odometry, Pose2::default(), f.t_us);
            assert!((q.x - f.pose.x).abs() < 1e-9 && (q.y - f.pose.y).abs() < 1e-9);
        }
        assert!(worst < 1e-6, "{name}: {worst} m");
    }
}

#[test]
fn paths_are_what_the_segments_say() {
    // The square: back at the start, heading a whole number of turns, after 2 x 4 x 2 m.
    let run = sim::simulate(
        &common::noise_off(common::load("paper-square")),
        sim::Mode::Fast,
    )
    .unwrap();
    let end = run.odometry_truth.last().unwrap().t_us;
    let last = sim::integrate_samples(&run.odometry_truth, Pose2::default(), end);
    assert!(last.x.abs() < 1e-9 && last.y.abs() < 1e-9, "{last:?}");
    assert!(angle_diff(last.theta, 0.0) < 1e-9);
    let mut corner = false;
    for f in &run.frames {
        let p = f.pose;
        corner |= (p.x - 2.0).abs() < 1e-9 && (p.y - 2.0).abs() < 1e-9;
        assert!((-1e-9..=2.0 + 1e-9).contains(&p.x) && (-1e-9..=2.0 + 1e-9).contains(&p.y));
    }
    assert!(corner, "passes the far corner");
    // Speeds and accelerations stay inside the limits.
    let spec = &run_spec();
    let mut prev = 0.0;
    for s in &run.odometry_truth {
        assert!(s.vx.abs() <= spec.0 + 1e-9 && s.vtheta.abs() <= spec.1 + 1e-9);
        assert!((s.vx - prev).abs() / 0.01 <= spec.2 * 1.001 + 1e-9);
        prev = s.vx;
    }
    // Samples every 10 ms, frames every 50 ms, both on the same clock.
    assert!(
        run.odometry
            .windows(2)
            .all(|w| w[1].t_us - w[0].t_us == 10_000)
    );
    assert!(
        run.frames
            .windows(2)
            .all(|w| w[1].t_us - w[0].t_us == 50_000)
    );
    assert_eq!(run.frames[0].t_us, run.odometry[0].t_us);
}

fn run_spec() -> (f64, f64, f64) {
    let p = common::load("paper-square").spec.path;
    (
        p.max_speed_mps,
        p.max_yaw_rate_degps.to_radians(),
        p.max_accel_mps2,
    )
}

#[test]
fn odometry_noise_scale_and_bias_are_as_configured() {
    let mut s = common::load("paper-experiment");
    s.spec.noise.velocity_mps = 0.02;
    s.spec.noise.yaw_rate_radps = 0.01;
    s.spec.noise.velocity_scale_error = 0.01;
    s.spec.noise.yaw_rate_bias_radps = 0.002;
    s.spec.path.repeat = 6;
    let run = sim::simulate(&s, sim::Mode::Fast).unwrap();
    let n = run.odometry.len() as f64;
    let (mut ex, mut ex2, mut ew, mut ew2) = (0.0, 0.0, 0.0, 0.0);
    for (m, t) in run.odometry.iter().zip(&run.odometry_truth) {
        let dx = m.vx - 1.01 * t.vx;
        let dw = m.vtheta - t.vtheta;
        ex += dx;
        ex2 += dx * dx;
        ew += dw;
        ew2 += dw * dw;
        assert_eq!(m.t_us, t.t_us);
    }
    let (mx, mw) = (ex / n, ew / n);
    let (sx, sw) = ((ex2 / n - mx * mx).sqrt(), (ew2 / n - mw * mw).sqrt());
    assert!(n > 5_000.0);
    assert!(mx.abs() < 0.002 && (sx - 0.02).abs() < 0.001, "{mx} {sx}");
    assert!(
        (mw - 0.002).abs() < 0.0005 && (sw - 0.01).abs() < 0.0005,
        "{mw} {sw}"
    );
}

/// The odometry's errors with memory (vehicle-interfaces.md section 2): with
/// `velocity_tau_s` and `yaw_rate_tau_s` the measured-minus-true velocities are a first-order
/// Gauss-Markov process: the stationary sigma the scenario gives, and a correlation from one
/// sample to the next of `exp(-dt / tau)`; without them, white (no correlation).
#[test]
fn odometry_errors_have_the_memory_the_scenario_gives() {
    let stats = |tau_v: f64, tau_w: f64| {
        let mut s = common::load("aisle-vehicle");
        s.spec.noise.velocity_scale_error = 0.0;
        s.spec.noise.yaw_rate_scale_error = 0.0;
        s.spec.noise.yaw_rate_bias_radps = 0.0;
        s.spec.noise.velocity_tau_s = tau_v;
        s.spec.noise.yaw_rate_tau_s = tau_w;
        s.spec.link.loss_probability = 0.0;
        s.spec.link.bit_flip_probability = 0.0;
        let run = sim::simulate(&s, sim::Mode::Fast).unwrap();
        assert_eq!(run.odometry.len(), run.odometry_truth.len());
        let errors: Vec<[f64; 3]> = run
            .odometry
            .iter()
            .zip(&run.odometry_truth)
            .map(|(m, t)| [m.vx - t.vx, m.vy - t.vy, m.vtheta - t.vtheta])
            .collect();
        let mut out = [(0.0, 0.0); 3];
        for (axis, o) in out.iter_mut().enumerate() {
            let e: Vec<f64> = errors.iter().map(|e| e[axis]).collect();
            let n = e.len() as f64;
            let var = e.iter().map(|v| v * v).sum::<f64>() / n;
            let lag1 = e.windows(2).map(|w| w[0] * w[1]).sum::<f64>() / (n - 1.0);
            *o = (var.sqrt(), lag1 / var);
        }
        (out, errors.len())
    };
    // 100 Hz odometry: phi = exp(-0.01 / 0.6) = 0.9835, exp(-0.01 / 0.3) = 0.9672.
    let (with_memory, n) = stats(0.6, 0.3);
    assert!(n > 5000, "{n} samples");
    for (axis, (sigma, phi), want_sigma, want_phi) in [
        (0, with_memory[0], 0.02, (-0.01f64 / 0.6).exp()),
        (1, with_memory[1], 0.02, (-0.01f64 / 0.6).exp()),
        (2, with_memory[2], 0.01, (-0.01f64 / 0.3).exp()),
    ] {
        // A process of time constant 0.6 s over ~90 s has ~75 independent stretches: its
        // sample sigma is within ~25 % of the stationary one at 3 sigma.
        assert!(
            (sigma / want_sigma - 1.0).abs() < 0.3,
            "axis {axis}: sigma {sigma} against {want_sigma}"
        );
        assert!(
            (phi - want_phi).abs() < 0.01,
            "axis {axis}: correlation {phi} against {want_phi}"
        );
    }
    let (white, _) = stats(0.0, 0.0);
    for (axis, (sigma, phi)) in white.iter().enumerate() {
        let want = if axis == 2 { 0.01 } else { 0.02 };
        assert!(
            (sigma / want - 1.0).abs() < 0.05,
            "axis {axis}: white sigma {sigma}"
        );
        assert!(phi.abs() < 0.05, "axis {axis}: white correlation {phi}");
    }
}
