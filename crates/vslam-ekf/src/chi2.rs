//! Chi-square quantiles for the gates and the health bound, without `std`.
//!
//! The gates need the quantile for 3 and 4 degrees of freedom and the health check for `4 W`
//! (W observations in the NIS window); both come from the regularised incomplete gamma
//! function, inverted by a safeguarded Newton iteration started at the Wilson-Hilferty
//! approximation.

/// Regularised lower incomplete gamma function `P(a, x)`, `a > 0`, `x >= 0`
/// (series below `a + 1`, Lentz's continued fraction above).
fn gamma_p(a: f64, x: f64) -> f64 {
    if x <= 0.0 {
        return 0.0;
    }
    let log_prefactor = -x + a * libm::log(x) - libm::lgamma(a);
    if x < a + 1.0 {
        let (mut term, mut sum, mut ap) = (1.0 / a, 1.0 / a, a);
        for _ in 0..10_000 {
            ap += 1.0;
            term *= x / ap;
            sum += term;
            if libm::fabs(term) < libm::fabs(sum) * 1e-16 {
                break;
            }
        }
        (sum * libm::exp(log_prefactor)).clamp(0.0, 1.0)
    } else {
        const TINY: f64 = 1e-300;
        let mut b = x + 1.0 - a;
        let mut c = 1.0 / TINY;
        let mut d = 1.0 / b;
        let mut h = d;
        for i in 1..10_000 {
            let fi = f64::from(i);
            let an = -fi * (fi - a);
            b += 2.0;
            d = an * d + b;
            if libm::fabs(d) < TINY {
                d = TINY;
            }
            c = b + an / c;
            if libm::fabs(c) < TINY {
                c = TINY;
            }
            d = 1.0 / d;
            let delta = d * c;
            h *= delta;
            if libm::fabs(delta - 1.0) < 1e-16 {
                break;
            }
        }
        (1.0 - libm::exp(log_prefactor) * h).clamp(0.0, 1.0)
    }
}

/// `P(X <= x)` for `X ~ chi^2(dof)`.
pub fn chi2_cdf(x: f64, dof: f64) -> f64 {
    gamma_p(dof / 2.0, x / 2.0)
}

/// Density of `chi^2(dof)` at `x > 0`.
fn chi2_pdf(x: f64, dof: f64) -> f64 {
    let k = dof / 2.0;
    libm::exp((k - 1.0) * libm::log(x) - x / 2.0 - k * core::f64::consts::LN_2 - libm::lgamma(k))
}

/// Standard normal quantile by Acklam's rational approximation (relative error 1e-9), good
/// enough for a starting point.
fn normal_quantile(p: f64) -> f64 {
    const A: [f64; 6] = [
        -3.969_683_028_665_376e1,
        2.209_460_984_245_205e2,
        -2.759_285_104_469_687e2,
        1.383_577_518_672_69e2,
        -3.066_479_806_614_716e1,
        2.506_628_277_459_239,
    ];
    const B: [f64; 5] = [
        -5.447_609_879_822_406e1,
        1.615_858_368_580_409e2,
        -1.556_989_798_598_866e2,
        6.680_131_188_771_972e1,
        -1.328_068_155_288_572e1,
    ];
    const C: [f64; 6] = [
        -7.784_894_002_430_293e-3,
        -3.223_964_580_411_365e-1,
        -2.400_758_277_161_838,
        -2.549_732_539_343_734,
        4.374_664_141_464_968,
        2.938_163_982_698_783,
    ];
    const D: [f64; 4] = [
        7.784_695_709_041_462e-3,
        3.224_671_290_700_398e-1,
        2.445_134_137_142_996,
        3.754_408_661_907_416,
    ];
    let tail = |q: f64| {
        (((((C[0] * q + C[1]) * q + C[2]) * q + C[3]) * q + C[4]) * q + C[5])
            / ((((D[0] * q + D[1]) * q + D[2]) * q + D[3]) * q + 1.0)
    };
    if p < 0.02425 {
        tail(libm::sqrt(-2.0 * libm::log(p)))
    } else if p > 1.0 - 0.02425 {
        -tail(libm::sqrt(-2.0 * libm::log(1.0 - p)))
    } else {
        let q = p - 0.5;
        let r = q * q;
        (((((A[0] * r + A[1]) * r + A[2]) * r + A[3]) * r + A[4]) * r + A[5]) * q
            / (((((B[0] * r + B[1]) * r + B[2]) * r + B[3]) * r + B[4]) * r + 1.0)
    }
}

/// The `p` quantile of `chi^2(dof)`: `x` with `P(X <= x) = p`, for `0 < p < 1`, `dof > 0`.
pub fn chi2_quantile(p: f64, dof: f64) -> f64 {
    // Wilson-Hilferty: (X / k)^(1/3) is nearly normal with mean 1 - 2/(9k), variance 2/(9k).
    let v = 2.0 / (9.0 * dof);
    let start = dof * libm::pow(1.0 - v + normal_quantile(p) * libm::sqrt(v), 3.0);
    let (mut lo, mut hi) = (0.0_f64, f64::INFINITY);
    let mut x = if start > 0.0 { start } else { dof.max(1e-3) };
    for _ in 0..200 {
        let f = chi2_cdf(x, dof) - p;
        if f < 0.0 {
            lo = x;
        } else {
            hi = x;
        }
        let step = f / chi2_pdf(x, dof);
        let mut next = x - step;
        if !(next > lo && next < hi && next.is_finite()) {
            next = if hi.is_finite() {
                0.5 * (lo + hi)
            } else {
                2.0 * x
            };
        }
        if libm::fabs(next - x) <= 1e-13 * x {
            return next;
        }
        x = next;
    }
    x
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles_match_tables() {
        // Tabulated chi-square quantiles.
        for (p, dof, q) in [
            (0.999, 4.0, 18.466_826_952_903_17),
            (0.999, 3.0, 16.266_236_196_238_13),
            (0.95, 4.0, 9.487_729_036_781_154),
            (0.99, 1.0, 6.634_896_601_021_214),
            (0.5, 2.0, 1.386_294_361_119_890_6),
        ] {
            let got = chi2_quantile(p, dof);
            assert!((got - q).abs() < 1e-6 * q, "p {p} dof {dof}: {got} vs {q}");
            assert!((chi2_cdf(got, dof) - p).abs() < 1e-10);
        }
        // Closed forms for 4 and 3 dof, on both sides of the series / fraction switch.
        for x in [0.3_f64, 2.0, 7.3, 18.0, 40.0] {
            let cdf4 = 1.0 - (-x / 2.0).exp() * (1.0 + x / 2.0);
            assert!((chi2_cdf(x, 4.0) - cdf4).abs() < 1e-13, "x {x}");
            let cdf3 = libm::erf((x / 2.0).sqrt())
                - (2.0 * x / core::f64::consts::PI).sqrt() * (-x / 2.0).exp();
            assert!((chi2_cdf(x, 3.0) - cdf3).abs() < 1e-13, "x {x}");
        }
        // Large dof (the health window): the quantile inverts the cdf and sits where
        // Wilson-Hilferty puts it.
        for dof in [40.0, 400.0, 4000.0] {
            let q = chi2_quantile(0.999, dof);
            assert!((chi2_cdf(q, dof) - 0.999).abs() < 1e-10, "dof {dof}");
            let v = 2.0 / (9.0 * dof);
            let wh = dof * (1.0 - v + 3.090_232_306_167_813 * v.sqrt()).powi(3);
            assert!((q - wh).abs() < 2e-3 * q, "dof {dof}: {q} vs {wh}");
        }
    }
}
