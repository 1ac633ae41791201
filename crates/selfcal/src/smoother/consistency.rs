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
//! The statistic is the mean of those normalised squares over non-overlapping windows, each
//! clipped at ten times their median, divided by the same clipped mean of the squares when the
//! model is right (a chi-square variable of one degree of freedom for the heading; the mean of
//! two for the translation's `dx` and `dy`), so that
//! a few windows over an odometry gap or a slip the model covers do not move it; over single
//! frame intervals the same ratio tells errors that are larger than stated (both ratios
//! high) from errors with memory (the long span's ratio well above the single frame's).

use alloc::vec::Vec;

use nalgebra::{Matrix3, Vector3};
use rig_model::camera::{Pose2, Vehicle};
use rig_model::odometry::{Motion, compose_jacobian_first, compose_jacobian_second};

use super::Frame;
use super::factors::odometry_residual;

/// A frame interval's odometry: its motion and the covariance of that motion under the noise
/// model in use.
pub type OdometryStep = (Motion, Matrix3<f64>);

/// The spans of the windows compared, seconds: a second, and several time constants of a
/// real vehicle's wheel slip (0.6 s), over which errors with memory reach 80 % of their
/// long-run variance rate. The two ratios give the memory's time constant
/// ([`long_run_ratio`]).
pub const SPANS_S: [f64; 2] = [1.0, 3.0];

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

/// How the batch widened the odometry's noise model (issue 36, item 2): its solved
/// trajectory disagreed with the odometry over spans of [`SPANS_S`] by more than the model
/// allows ([`RATIO_LIMIT`] times its variance).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OdometryWidening {
    /// The frame at which it first widened, board time, microseconds.
    pub first_t_us: u64,
    /// The consistency that first triggered it (ratios against the rig file's model).
    pub first: OdometryConsistency,
    /// The variance factors applied so far, all widenings together: `(translation, heading)`.
    pub factors: (f64, f64),
    /// The time constants of the odometry's errors the check saw, `(translation, heading)`,
    /// seconds (0: none seen, or not yet measurable).
    pub time_constants_s: (f64, f64),
    /// Looks taken with both spans (the errors' memory seen): the `k`-th needs `8 * 2^k`
    /// windows of the long span, and there are at most [`MAX_LOOKS`].
    pub looks: u32,
}

/// The long-run ratio of the odometry's residual variance to the model above which the batch
/// widens the model (4: odometry twice as bad as stated in sigma; errors of 0.6 s memory
/// stated as white give about 120 at 100 Hz). Odometry as good as stated gives about 1: the
/// batch's relative poses over a second are good to a millimetre or two.
pub(crate) const RATIO_LIMIT: f64 = 4.0;

/// The long-run ratio above which a model widened from the short span alone is widened once
/// more when the long span has its windows: any excess (the first widening saw a second of
/// the errors, not their memory's whole share; the one look cannot feed itself).
pub(crate) const REFINE_LIMIT: f64 = 1.0;

/// Looks with both spans at most: the check measures against a trajectory the widened
/// odometry holds less tightly, and must not feed itself.
pub(crate) const MAX_LOOKS: u32 = 3;

/// The longest time constant of the odometry's errors the check extrapolates with, seconds
/// (a real vehicle's wheel slip lasts about 0.6 s).
pub(crate) const MAX_TAU_S: f64 = 3.0;

/// The most the odometry's variance is widened, all widenings together (sigma 100-fold):
/// past it the odometry is not odometry, and the batch's trajectory, which the check measures
/// against, would no longer be held by it between landmarks.
pub(crate) const MAX_WIDENING: f64 = 1e4;

/// Windows of a span needed before the check over it is trusted (8 s of data over the 1 s
/// span, 24 s over the 3 s one).
pub(crate) const MIN_WINDOWS: usize = 8;

/// Windows of the short span enough for a first widening on strong evidence
/// ([`STRONG_HEADING_LIMIT`]): a phase 1 that a short frame budget ends before
/// [`MIN_WINDOWS`] (150 frames, 7.5 s) must not hand over a white model for odometry whose
/// errors last 0.6 s.
pub(crate) const MIN_STRONG_WINDOWS: usize = 4;

/// The heading's ratio over at least [`MIN_STRONG_WINDOWS`] windows that widens the model
/// before the span has [`MIN_WINDOWS`]: odometry as good as stated makes each window's
/// normalised square a chi-square variable of one degree of freedom, whose clipped mean over
/// four windows exceeds 8 times its own with a probability below 1e-5; 0.6 s of memory stated
/// as white gives 40 to 110 against the batch's trajectory. Against phase 2's filter, whose
/// relative headings are coarser, the white Monte Carlos gave at most 2.8 (docs/vehicle.md).
pub const STRONG_HEADING_LIMIT: f64 = 8.0;

/// Whether a span with at least [`MIN_STRONG_WINDOWS`] windows shows the heading's errors
/// more than [`STRONG_HEADING_LIMIT`] times the model's variance: the only first judgement
/// made before [`MIN_WINDOWS`], and the only one phase 2's filter makes on its own.
pub fn heading_strongly_worse(spans: &[Option<OdometryConsistency>; 2]) -> bool {
    spans
        .iter()
        .flatten()
        .any(|c| c.windows >= MIN_STRONG_WINDOWS && c.heading > STRONG_HEADING_LIMIT)
}

/// The variance factors `(translation, heading)` to widen the odometry's model by after a
/// solve whose consistency over the two spans is `spans`, given the widening so far, and the
/// widening after it (`None` when nothing changes). An axis is judged on the largest of its
/// ratios over the spans with enough windows, against [`RATIO_LIMIT`]. When both spans have
/// them, their quotient shows the errors' memory, and the factor is the long-run ratio
/// ([`long_run_ratio`], its time constant at most [`MAX_TAU_S`]: the extrapolation from
/// 3 s is at most 2.3-fold). A model widened before the long span had its windows (from the
/// short span alone, without the memory's share) is looked at again when the long span has
/// 8, 16 and 32 windows, against [`REFINE_LIMIT`]: each look with twice the data, at most
/// [`MAX_LOOKS`], so that the check, which measures against a trajectory the widened
/// odometry holds less tightly, cannot feed itself.
pub fn judge(
    spans: [Option<OdometryConsistency>; 2],
    so_far: Option<OdometryWidening>,
    t_us: u64,
    strong_first: bool,
) -> Option<((f64, f64), OdometryWidening)> {
    let usable = |c: Option<OdometryConsistency>| c.filter(|c| c.windows >= MIN_WINDOWS);
    let [short, long] = spans.map(usable);
    // Strong evidence is not made to wait for the windows a marginal ratio needs.
    let early =
        strong_first && so_far.is_none() && short.is_none() && heading_strongly_worse(&spans);
    // (Only the short span can be early: a long span of 4 windows has a short one of 12.)
    let short = if early { spans[0] } else { short };
    let first = short.or(long)?;
    // The look a long span of `n` windows is: 1 at 8, 2 at 16, 3 at 32.
    let look_of = |n: usize| (usize::BITS - (n / MIN_WINDOWS).leading_zeros()).min(MAX_LOOKS);
    let look = long.map_or(0, |l| look_of(l.windows));
    let refine = look > 0 && so_far.is_some_and(|w| w.looks < look);
    let limit = if refine { REFINE_LIMIT } else { RATIO_LIMIT };
    // The fewest windows behind a ratio: the long span's when it is used.
    let windows = long.or(short).map_or(MIN_WINDOWS, |c| c.windows);
    #[allow(clippy::cast_precision_loss)] // a count of windows far below 2^53
    let windows = windows as f64;
    // `variance_per_window`: the variance of one window's normalised square in units of its
    // mean (2 for a chi-square of one degree of freedom, 1 for the mean of two).
    let axis = |pick: fn(&OdometryConsistency) -> f64, variance_per_window: f64| -> (f64, f64) {
        let raw = [short, long]
            .iter()
            .flatten()
            .map(pick)
            .filter(|r| r.is_finite())
            .fold(f64::NAN, f64::max);
        let (long_run, tau) = match (short, long) {
            (Some(s), Some(l)) => long_run_ratio(pick(&s), pick(&l)),
            _ => (raw, 0.0),
        };
        let (ratio, tau) = if long_run.is_finite() && tau > 0.0 && tau <= MAX_TAU_S {
            (long_run.max(raw), tau)
        } else {
            (raw, 0.0)
        };
        // Judged on the estimate; widened by its one-sigma upper bound, as the ratio comes
        // from a few windows (+50 % at 8 of the heading's, +29 % at 24) and a model widened
        // too little is the error that matters (issue 36: honesty before accuracy).
        if ratio > limit {
            (
                ratio * (1.0 + libm::sqrt(variance_per_window / windows)),
                tau,
            )
        } else {
            (1.0, 0.0)
        }
    };
    let (kt, tau_t) = axis(|c| c.translation, 1.0);
    let (kh, tau_h) = axis(|c| c.heading, 2.0);
    let applied = so_far.map_or((1.0, 1.0), |w| w.factors);
    let kt = kt.min(MAX_WIDENING / applied.0).max(1.0);
    let kh = kh.min(MAX_WIDENING / applied.1).max(1.0);
    let mut w = so_far.unwrap_or(OdometryWidening {
        first_t_us: t_us,
        first,
        factors: (1.0, 1.0),
        time_constants_s: (0.0, 0.0),
        looks: 0,
    });
    if kt <= 1.0 && kh <= 1.0 {
        // This look taken: the next needs twice the windows.
        return refine.then(|| {
            w.looks = look;
            ((1.0, 1.0), w)
        });
    }
    w.factors = (w.factors.0 * kt, w.factors.1 * kh);
    w.looks = w.looks.max(look);
    if kt > 1.0 && tau_t > 0.0 {
        w.time_constants_s.0 = tau_t;
    }
    if kh > 1.0 && tau_h > 0.0 {
        w.time_constants_s.1 = tau_h;
    }
    Some(((kt, kh), w))
}

/// `a (+) b` of two motions with the covariance propagated (`cov_a`, `cov_b` independent).
fn compose(
    a: &Motion,
    cov_a: &Matrix3<f64>,
    b: &Motion,
    cov_b: &Matrix3<f64>,
) -> (Motion, Matrix3<f64>) {
    let ja = compose_jacobian_first(a.dtheta, b);
    let jb = compose_jacobian_second(a.dtheta);
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

/// The ratio of `v`'s spread to what the model gives it: the mean of `v` with every value
/// clipped at [`CLIP_MEDIANS`] times `v`'s median (an odometry gap or a slip the model covers
/// cannot dominate it), over that clipped mean under the model, `clipped_mean` (for a
/// chi-square `v`, its mean with the same clip at the same multiple of its own median: the
/// ratio is the same whatever the scale). `v` is reordered; `NaN` when empty. The mean, not
/// the median: with the 8 to 30 windows the check has, the median of a chi-square of one
/// degree of freedom is off by 80 % (one sigma) at 8 windows, the mean by 50 %.
fn ratio(v: &mut [f64], clipped_mean: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    let mid = v.len() / 2;
    let (_, m, _) = v.select_nth_unstable_by(mid, f64::total_cmp);
    let clip = CLIP_MEDIANS * *m;
    #[allow(clippy::cast_precision_loss)] // a count of windows far below 2^53
    let mean = v.iter().map(|x| x.min(clip)).sum::<f64>() / v.len() as f64;
    mean / clipped_mean
}

/// Values above this many medians are clipped ([`ratio`]).
const CLIP_MEDIANS: f64 = 10.0;

/// The mean of a chi-square variable of one degree of freedom clipped at [`CLIP_MEDIANS`]
/// times its median (`1 - E[(X - c)^+]`, `c = 4.549`).
const CHI2_1_CLIPPED_MEAN: f64 = 0.941_885_836_754_694_5;

/// The same for the mean of two (an exponential variable of mean 1: `1 - exp(-10 ln 2)`).
const CHI2_2_HALF_CLIPPED_MEAN: f64 = 0.999_023_437_5;

/// The consistency of `frames`' odometry with their poses for the vehicle `v` over windows
/// of each of `spans_s` (see the module docs); `None` for a span without a single window.
pub(super) fn odometry_consistency<const N: usize>(
    frames: &[Frame],
    v: &Vehicle,
    spans_s: [f64; N],
) -> [Option<OdometryConsistency>; N] {
    let (poses, steps) = track(frames, v);
    spans_s.map(|span_s| trajectory_consistency(&poses, &steps, span_s))
}

/// `frames`' poses and the odometry's motion between each and the next, with its covariance,
/// for the vehicle `v` ([`trajectory_consistency`]'s input).
pub(super) fn track(frames: &[Frame], v: &Vehicle) -> (Vec<Pose2>, Vec<Option<OdometryStep>>) {
    let poses: Vec<Pose2> = frames.iter().map(|f| f.pose).collect();
    // The factor's covariance is in the reported odometry's units; D = diag(odom_scale,
    // odom_scale, odom_yaw_scale) is within a few per cent of 1, well inside what the ratio
    // is compared with.
    let steps = frames
        .iter()
        .skip(1)
        .map(|f| {
            f.odometry
                .as_ref()
                .map(|(o, _)| (o.motion_for(v), o.covariance))
        })
        .collect();
    (poses, steps)
}

/// The consistency of a trajectory's odometry with its poses over windows of `span_s` (see the
/// module docs), for an estimator other than the batch (phase 2's filter, `nav`): `poses[i]`
/// and `poses[i + 1]` are the estimates at two frames, `steps[i]` the odometry's motion
/// between them and its covariance under the model in use (`None`: no odometry, the window
/// ends uncounted). `None` without a single window.
pub fn trajectory_consistency(
    poses: &[Pose2],
    steps: &[Option<OdometryStep>],
    span_s: f64,
) -> Option<OdometryConsistency> {
    let (mut long_t, mut long_h, mut frame_t, mut frame_h) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut span_sum = 0.0;
    // The window being built: its first frame's index, the composed motion and covariance.
    let mut window: Option<(usize, Motion, Matrix3<f64>)> = None;
    for (i, (pair, step)) in poses.windows(2).zip(steps).enumerate() {
        let (Some(a), Some(b)) = (pair.first(), pair.get(1)) else {
            continue;
        };
        let Some((m, cov)) = *step else {
            // No odometry over this interval: the window ends without being counted.
            window = None;
            continue;
        };
        let (r, _, _) = odometry_residual(a, b, &m);
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
        let Some(first) = poses.get(start) else {
            continue;
        };
        let (r, _, _) = odometry_residual(first, b, &motion);
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
        translation: ratio(&mut long_t, CHI2_2_HALF_CLIPPED_MEAN),
        heading: ratio(&mut long_h, CHI2_1_CLIPPED_MEAN),
        frame_translation: ratio(&mut frame_t, CHI2_2_HALF_CLIPPED_MEAN),
        frame_heading: ratio(&mut frame_h, CHI2_1_CLIPPED_MEAN),
    })
}

/// `covariance` widened by the variance factors `translation` on `dx, dy` and `heading` on
/// `dtheta` (at least 1): `S C S` with `S` their square roots on the diagonal.
pub fn widened(covariance: &Matrix3<f64>, translation: f64, heading: f64) -> Matrix3<f64> {
    let s = Matrix3::from_diagonal(&Vector3::new(
        libm::sqrt(translation),
        libm::sqrt(translation),
        libm::sqrt(heading),
    ));
    s * covariance * s
}

/// Scales the stored odometry factors' covariance by `translation` on `dx, dy` and `heading`
/// on `dtheta` (variance factors, at least 1), their information by the inverse.
pub(super) fn widen(frames: &mut [Frame], translation: f64, heading: f64) {
    let s_inv = Matrix3::from_diagonal(&Vector3::new(
        1.0 / libm::sqrt(translation),
        1.0 / libm::sqrt(translation),
        1.0 / libm::sqrt(heading),
    ));
    for f in frames {
        if let Some((o, info)) = &mut f.odometry {
            o.covariance = widened(&o.covariance, translation, heading);
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
    use rand_chacha::ChaCha8Rng;
    use rand_chacha::rand_core::SeedableRng;
    use rand_distr::{Distribution, StandardNormal};

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

    /// A trajectory known exactly (the filter's where lamps are in view, to first order) and
    /// its odometry at 100 Hz with errors of 0.6 s memory, stated as white: the two spans'
    /// ratios are what the batch sees (about 62 and 96), and their quotient gives the memory.
    #[test]
    fn a_trajectory_shows_the_odometry_s_memory() {
        let (sigma_v, sigma_w, tau, period) = (0.02, 0.01, 0.6, 0.01);
        let phi = libm::exp(-period / tau);
        let drive = libm::sqrt(1.0 - phi * phi);
        let mut rng = ChaCha8Rng::seed_from_u64(36);
        let mut draw = || -> f64 { StandardNormal.sample(&mut rng) };
        let (mut ev, mut ew) = (sigma_v * draw(), sigma_w * draw());
        let mut poses = alloc::vec![Pose2::new(0.0, 0.0, 0.0)];
        let mut steps = Vec::new();
        // 20 Hz frames over 300 s, each five odometry samples of 1 m/s and 0.05 rad/s.
        for _ in 0..6000 {
            let mut reported = Motion::default();
            let mut truth = Motion::default();
            for _ in 0..5 {
                ev = phi * ev + drive * sigma_v * draw();
                ew = phi * ew + drive * sigma_w * draw();
                truth = truth.then(&rig_model::odometry::constant_velocity_motion(
                    1.0, 0.0, 0.05, period,
                ));
                reported = reported.then(&rig_model::odometry::constant_velocity_motion(
                    1.0 + ev,
                    0.0,
                    0.05 + ew,
                    period,
                ));
            }
            // The white model: each sample's variance (sigma dt)^2, as `Increment` gives it.
            let cov = Matrix3::from_diagonal(&Vector3::new(
                5.0 * (sigma_v * period).powi(2),
                5.0 * (sigma_v * period).powi(2),
                5.0 * (sigma_w * period).powi(2),
            ));
            let last = poses[poses.len() - 1];
            poses.push(truth.apply(&last));
            steps.push(Some((reported, cov)));
        }
        let [short, long] =
            SPANS_S.map(|span| trajectory_consistency(&poses, &steps, span).unwrap());
        assert!(
            short.windows >= 290 && long.windows >= 95,
            "{short:?} {long:?}"
        );
        let (expect_short, expect_long) = (
            120.0 * memory_fraction(1.0, tau),
            120.0 * memory_fraction(3.0, tau),
        );
        // The heading's errors are the yaw rate's alone; the translation's half of it is the
        // lateral `dy`, which the velocity's errors do not reach.
        for (got, want) in [(short.heading, expect_short), (long.heading, expect_long)] {
            assert!((got / want - 1.0).abs() < 0.35, "{got} against {want}");
        }
        assert!(
            short.translation > RATIO_LIMIT && long.translation > 1.2 * short.translation,
            "{short:?} {long:?}"
        );
        let (ratio, t) = long_run_ratio(short.heading, long.heading);
        assert!(
            (0.3..=1.2).contains(&t) && (60.0..=240.0).contains(&ratio),
            "{ratio} {t}"
        );
        // Judged after a widening from the short span alone (phase 1 handed over early):
        // widened again, to about the long-run ratio, and the memory named.
        let first = judge(
            [
                Some(OdometryConsistency {
                    windows: 8,
                    ..short
                }),
                None,
            ],
            None,
            9_000_000,
            true,
        )
        .unwrap()
        .1;
        let rescaled = |c: OdometryConsistency| OdometryConsistency {
            translation: c.translation / first.factors.0,
            heading: c.heading / first.factors.1,
            ..c
        };
        let ((kt, kh), w) = judge(
            [Some(rescaled(short)), Some(rescaled(long))],
            Some(first),
            60_000_000,
            true,
        )
        .unwrap();
        assert!(kt > 1.0 && kh > 1.0, "{kt} {kh}");
        assert!(w.factors.0 >= 90.0 && w.factors.1 >= 90.0, "{w:?}");
        assert!(
            w.time_constants_s.0 > 0.0 && w.time_constants_s.1 > 0.0,
            "{w:?}"
        );
    }

    fn spans(
        windows: usize,
        short: (f64, f64),
        long: Option<(f64, f64)>,
    ) -> [Option<OdometryConsistency>; 2] {
        let c = |span_s: f64, (translation, heading): (f64, f64)| OdometryConsistency {
            windows,
            span_s,
            translation,
            heading,
            frame_translation: 1.0,
            frame_heading: 1.0,
        };
        [Some(c(1.0, short)), long.map(|l| c(3.0, l))]
    }

    #[test]
    fn strong_evidence_widens_before_the_span_has_its_windows_and_only_strong_evidence() {
        // Four one-second windows whose heading's ratio is far beyond what odometry as stated
        // gives (0.6 s of memory stated as white, about 60 over a second): widened now, both
        // axes judged, the translation's bound from the four windows (+50 %).
        let ((kt, kh), w) = judge(
            spans(MIN_STRONG_WINDOWS, (60.0, 58.0), None),
            None,
            5_000_000,
            true,
        )
        .expect("widened");
        assert!((kt / (60.0 * 1.5) - 1.0).abs() < 1e-12, "{kt}");
        assert!(
            (kh / (58.0 * (1.0 + (0.5f64).sqrt())) - 1.0).abs() < 1e-12,
            "{kh}"
        );
        assert!(w.first_t_us == 5_000_000 && w.looks == 0);
        // Fewer windows, or a heading's ratio at the limit (the translation's alone is not
        // strong evidence: phase 2's filter's relative translations are too coarse for it).
        for (n, ratios) in [
            (MIN_STRONG_WINDOWS - 1, (60.0, 58.0)),
            (MIN_STRONG_WINDOWS, (60.0, STRONG_HEADING_LIMIT)),
            (MIN_WINDOWS - 1, (60.0, 3.0)),
        ] {
            assert!(!heading_strongly_worse(&spans(n, ratios, None)));
            assert_eq!(
                judge(spans(n, ratios, None), None, 5_000_000, true),
                None,
                "{n} {ratios:?}"
            );
        }
        // A model widened already is refined only as before, when the spans have their windows;
        // and without `strong_first` (phase 2's smoother) nothing is widened before them.
        assert_eq!(
            judge(
                spans(MIN_STRONG_WINDOWS, (60.0, 58.0), None),
                Some(w),
                6_000_000,
                true,
            ),
            None
        );
        assert_eq!(
            judge(
                spans(MIN_WINDOWS - 1, (60.0, 58.0), None),
                None,
                5_000_000,
                false,
            ),
            None
        );
    }

    #[test]
    fn the_odometry_is_widened_when_the_batch_disagrees_with_it_and_only_then() {
        // As stated: nothing; too few windows for anything but strong evidence (the
        // heading's, `heading_strongly_worse`): nothing.
        assert_eq!(
            judge(spans(20, (1.2, 0.8), Some((1.5, 0.9))), None, 5, true),
            None
        );
        assert_eq!(
            judge(spans(MIN_WINDOWS - 1, (100.0, 6.0), None), None, 5, true),
            None
        );
        // Errors of 0.6 s memory stated as white, seen over the short span first: widened by
        // its ratio's one-sigma upper bound (8 windows: the translation's +35 %), the memory
        // not yet seen.
        let short = 120.0 * memory_fraction(1.0, 0.6);
        let ((kt, kh), w) = judge(spans(8, (short, 3.0), None), None, 9_000_000, true).unwrap();
        assert!((kt / (short * (1.0 + (1.0f64 / 8.0).sqrt())) - 1.0).abs() < 1e-12);
        assert_eq!(kh, 1.0);
        assert!(w.looks == 0 && w.first_t_us == 9_000_000);
        // The long span's windows: the memory's share, once (REFINE_LIMIT), to the long-run
        // ratio's upper bound (24 windows: +20 %).
        let after = |r: f64, tau: f64, t: f64| r * memory_fraction(t, tau) / kt;
        let seen = spans(
            24,
            (after(120.0, 0.6, 1.0), 1.0),
            Some((after(120.0, 0.6, 3.0), 1.0)),
        );
        let ((k2, kh), w) = judge(seen, Some(w), 24_000_000, true).unwrap();
        let upper = 1.0 + (1.0f64 / 24.0).sqrt();
        assert!((k2 * kt / (120.0 * upper) - 1.0).abs() < 1e-6, "{k2}");
        assert_eq!(kh, 1.0);
        assert!(w.looks == 2 && (w.time_constants_s.0 - 0.6).abs() < 1e-6);
        assert!((w.factors.0 / (120.0 * upper) - 1.0).abs() < 1e-6);
        // That look taken (24 windows): ratios of 2 are not widened again until the long span
        // has twice the windows (only above RATIO_LIMIT meanwhile).
        assert_eq!(
            judge(
                spans(30, (2.0, 1.0), Some((3.0, 1.0))),
                Some(w),
                30_000_000,
                true
            ),
            None
        );
        // The third and last look, at 32 windows.
        let ((k3, _), w) = judge(
            spans(32, (1.2, 1.0), Some((1.1, 1.0))),
            Some(w),
            40_000_000,
            true,
        )
        .unwrap();
        assert!((k3 / (1.2 * (1.0 + (1.0f64 / 32.0).sqrt())) - 1.0).abs() < 1e-12);
        assert_eq!(w.looks, MAX_LOOKS);
        assert_eq!(
            judge(
                spans(64, (1.2, 1.0), Some((1.1, 1.0))),
                Some(w),
                80_000_000,
                true
            ),
            None
        );
        // A widening never goes past MAX_WIDENING in all.
        let ((kt, _), w) = judge(spans(8, (1e6, 1.0), None), None, 1, true).unwrap();
        assert_eq!((kt, w.factors.0), (MAX_WIDENING, MAX_WIDENING));
        assert_eq!(judge(spans(8, (1e6, 1.0), None), Some(w), 2, true), None);
    }
}
