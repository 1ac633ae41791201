//! Whether the odometry is as good as the rig file says (issue 36, item 2): the batch's solved
//! trajectory against the odometry over spans of about a second.
//!
//! Real wheels slip for a while, and a rig file may state white errors for odometry whose
//! errors last 0.6 s (vehicle-interfaces.md section 2), or state too small a sigma. Over one
//! frame interval the two look alike, but over a second the correlated errors add up
//! coherently: their variance over a span `T` is about `2 sigma^2 tau T` against the white
//! model's `sigma^2 period T` (120 times larger for 0.6 s of memory at 100 Hz). The batch's
//! relative poses over a second come from the landmarks, to a millimetre or two, so the
//! odometry's residual over such a span, squared and divided by the variance the noise model
//! gives it, is about 1 when the model is right and far above it when it is not.
//!
//! The statistic is the median of those normalised squares over non-overlapping windows,
//! divided by the median the squares have when the model is right (a chi-square variable of
//! one degree of freedom for the heading, 0.455; the mean of two for the translation's `dx`
//! and `dy`, ln 2), so that
//! a few windows over an odometry gap or a slip the model covers do not move it; over single
//! frame intervals the same ratio tells errors that are larger than stated (both ratios
//! high) from errors with memory (the long span's ratio well above the single frame's).

use alloc::vec::Vec;

use nalgebra::{Matrix3, Vector3};
use rig_model::camera::Vehicle;
use rig_model::odometry::Motion;

use super::Frame;
use super::factors::odometry_residual;

/// The spans of the windows compared, seconds: a second, and several time constants of a
/// real vehicle's wheel slip (0.6 s), over which errors with memory reach 80 % of their
/// long-run variance rate. The two ratios give the memory's time constant
/// ([`long_run_ratio`]).
pub const SPANS_S: [f64; 2] = [1.0, 3.0];

/// The median of a chi-square variable of one degree of freedom.
const CHI2_1_MEDIAN: f64 = 0.454_936_423_119_572_7;

/// The median of the mean of two chi-square variables of one degree of freedom (`ln 2`).
const CHI2_2_HALF_MEDIAN: f64 = core::f64::consts::LN_2;

/// The odometry's residuals against the batch's solved trajectory, each normalised by the
/// variance the noise model gives it (see the module docs): about 1 when the rig file's
/// odometry noise is right, far above 1 when the odometry is worse or its errors last longer.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OdometryConsistency {
    /// Windows of about the span asked for compared.
    pub windows: usize,
    /// Their mean span, seconds.
    pub span_s: f64,
    /// The translation's ratio (`dx` and `dy` in the window's first frame) over the windows.
    pub translation: f64,
    /// The heading's ratio over the windows.
    pub heading: f64,
    /// The translation's ratio over single frame intervals.
    pub frame_translation: f64,
    /// The heading's ratio over single frame intervals.
    pub frame_heading: f64,
}

/// `a (+) b` of two motions with the covariance propagated (`cov_a`, `cov_b` independent).
fn compose(
    a: &Motion,
    cov_a: &Matrix3<f64>,
    b: &Motion,
    cov_b: &Matrix3<f64>,
) -> (Motion, Matrix3<f64>) {
    let (s, c) = (libm::sin(a.dtheta), libm::cos(a.dtheta));
    let ja = Matrix3::new(
        1.0,
        0.0,
        -s * b.dx - c * b.dy,
        0.0,
        1.0,
        c * b.dx - s * b.dy,
        0.0,
        0.0,
        1.0,
    );
    let jb = Matrix3::new(c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0);
    (
        a.then(b),
        ja * cov_a * ja.transpose() + jb * cov_b * jb.transpose(),
    )
}

/// The normalised squares `(r_x^2 / v_x + r_y^2 / v_y) / 2` and `r_theta^2 / v_theta` of a
/// residual `r` with the model's covariance `cov` (`None` where a variance is not positive).
fn normalised(r: &Vector3<f64>, cov: &Matrix3<f64>) -> Option<(f64, f64)> {
    let (vx, vy, vt) = (cov[(0, 0)], cov[(1, 1)], cov[(2, 2)]);
    (vx > 0.0 && vy > 0.0 && vt > 0.0)
        .then(|| (0.5 * (r.x * r.x / vx + r.y * r.y / vy), r.z * r.z / vt))
}

/// The median of `v` over `expected`, the median under the model (`v` reordered); `NaN`
/// when empty.
fn ratio(v: &mut [f64], expected: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    let mid = v.len() / 2;
    let (_, m, _) = v.select_nth_unstable_by(mid, f64::total_cmp);
    *m / expected
}

/// The consistency of `frames`' odometry with their poses for the vehicle `v` over windows
/// of `span_s` (see the module docs); `None` without a single window.
pub(super) fn odometry_consistency(
    frames: &[Frame],
    v: &Vehicle,
    span_s: f64,
) -> Option<OdometryConsistency> {
    let (mut long_t, mut long_h, mut frame_t, mut frame_h) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut span_sum = 0.0;
    // The window being built: its first frame's index, the composed motion and covariance.
    let mut window: Option<(usize, Motion, Matrix3<f64>)> = None;
    for (i, pair) in frames.windows(2).enumerate() {
        let (Some(a), Some(b)) = (pair.first(), pair.get(1)) else {
            continue;
        };
        let Some((o, _)) = &b.odometry else {
            // No odometry over this interval: the window ends without being counted.
            window = None;
            continue;
        };
        let m = o.motion_for(v);
        // The factor's covariance is in the reported odometry's units; D = diag(odom_scale,
        // odom_scale, odom_yaw_scale) is within a few per cent of 1, well inside what the
        // ratio is compared with.
        let cov = o.covariance;
        let (r, _, _) = odometry_residual(&a.pose, &b.pose, &m);
        if let Some((t, h)) = normalised(&r, &cov) {
            frame_t.push(t);
            frame_h.push(h);
        }
        let (start, motion, covariance) = match window.take() {
            None => (i, m, cov),
            Some((start, wm, wc)) => {
                let (motion, covariance) = compose(&wm, &wc, &m, &cov);
                (start, motion, covariance)
            }
        };
        if motion.dt_s + 1e-9 < span_s {
            window = Some((start, motion, covariance));
            continue;
        }
        let Some(first) = frames.get(start) else {
            continue;
        };
        let (r, _, _) = odometry_residual(&first.pose, &b.pose, &motion);
        if let Some((t, h)) = normalised(&r, &covariance) {
            long_t.push(t);
            long_h.push(h);
            span_sum += motion.dt_s;
        }
    }
    if long_t.is_empty() {
        return None;
    }
    #[allow(clippy::cast_precision_loss)] // a count of windows far below 2^53
    let span_s = span_sum / long_t.len() as f64;
    Some(OdometryConsistency {
        windows: long_t.len(),
        span_s,
        translation: ratio(&mut long_t, CHI2_2_HALF_MEDIAN),
        heading: ratio(&mut long_h, CHI2_1_MEDIAN),
        frame_translation: ratio(&mut frame_t, CHI2_2_HALF_MEDIAN),
        frame_heading: ratio(&mut frame_h, CHI2_1_MEDIAN),
    })
}

/// Scales the stored odometry factors' covariance by `translation` on `dx, dy` and `heading`
/// on `dtheta` (variance factors, at least 1), their information by the inverse.
pub(super) fn widen(frames: &mut [Frame], translation: f64, heading: f64) {
    let s = Matrix3::from_diagonal(&Vector3::new(
        libm::sqrt(translation),
        libm::sqrt(translation),
        libm::sqrt(heading),
    ));
    let s_inv = Matrix3::from_diagonal(&Vector3::new(
        1.0 / libm::sqrt(translation),
        1.0 / libm::sqrt(translation),
        1.0 / libm::sqrt(heading),
    ));
    for f in frames {
        if let Some((o, info)) = &mut f.odometry {
            o.covariance = s * o.covariance * s;
            *info = s_inv * *info * s_inv;
        }
    }
}

/// The fraction of its long-run variance rate that a first-order Gauss-Markov error of time
/// constant `tau` reaches over a span `t`: its integral's variance is
/// `2 sigma^2 tau^2 (t / tau - 1 + exp(-t / tau))`, against `2 sigma^2 tau t` in the long run.
fn memory_fraction(t: f64, tau: f64) -> f64 {
    if tau <= 0.0 {
        return 1.0;
    }
    let x = t / tau;
    // 1 - (1 - exp(-x)) / x, with expm1 for the small x of a long memory.
    1.0 + libm::expm1(-x) / x
}

/// The ratio over long spans, and the time constant, from the ratios `short` and `long`
/// over the two [`SPANS_S`]: a white model's variance grows as the span, the variance of
/// errors with memory `tau` as the span times [`memory_fraction`], so `short / long` is
/// `memory_fraction(1 s) / memory_fraction(3 s)`, 1 for white errors and down to 1/3 for a
/// memory much longer than the spans. Returns `(long-run ratio, tau seconds)`; `tau` 0 when
/// the two ratios show no memory.
pub fn long_run_ratio(short: f64, long: f64) -> (f64, f64) {
    let [t1, t2] = SPANS_S;
    if !(short.is_finite() && long.is_finite() && short > 0.0 && long > 0.0) {
        return (f64::NAN, 0.0);
    }
    let q = short / long;
    if q >= 1.0 {
        return (long, 0.0);
    }
    let ratio_at = |tau: f64| memory_fraction(t1, tau) / memory_fraction(t2, tau);
    // ratio_at falls from 1 (tau -> 0) to t1 / t2 (tau -> infinity): bisect in log tau.
    let (mut lo, mut hi) = (1e-3_f64, 1e3_f64);
    if q <= ratio_at(hi) {
        return (long / memory_fraction(t2, hi), hi);
    }
    for _ in 0..60 {
        let mid = libm::sqrt(lo * hi);
        if ratio_at(mid) > q {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let tau = libm::sqrt(lo * hi);
    (long / memory_fraction(t2, tau), tau)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_two_spans_give_the_memory_and_the_long_run_ratio() {
        // Errors of 0.6 s memory whose long-run variance is 120 times the model's.
        for tau in [0.1, 0.6, 2.0] {
            let (short, long) = (
                120.0 * memory_fraction(SPANS_S[0], tau),
                120.0 * memory_fraction(SPANS_S[1], tau),
            );
            let (r, t) = long_run_ratio(short, long);
            assert!((t / tau - 1.0).abs() < 1e-6, "{t} against {tau}");
            assert!((r / 120.0 - 1.0).abs() < 1e-6, "{r}");
        }
        // White errors, too large: the same ratio over both spans.
        assert_eq!(long_run_ratio(9.0, 9.0), (9.0, 0.0));
        assert!(long_run_ratio(f64::NAN, 1.0).0.is_nan());
        // 0.6 s: 51 % of the long-run rate over a second, 80 % over three.
        assert!((memory_fraction(1.0, 0.6) - 0.513).abs() < 1e-3);
        assert!((memory_fraction(3.0, 0.6) - 0.801).abs() < 1e-3);
    }
}
