//! Thinning what a frame draws to what the screen can show.
//!
//! Software OpenGL (llvmpipe, the renderer of a machine without a GPU) spends a frame's time
//! mostly on triangle setup and on filling pixels, so the viewer hands it no more line points
//! than the pixels can tell apart: a series is cut to the plot's visible time range, reduced
//! to the lowest and highest sample of each pixel column, and then simplified
//! (Ramer-Douglas-Peucker) to a fraction of a pixel. A line drawn from the thinned points
//! differs from the full line by less than [`TOLERANCE_PX`] anywhere.

/// How far, pixels, a thinned line may stray from the full one.
pub const TOLERANCE_PX: f32 = 0.25;

/// The indices of the points of the polyline `points` (pixels) that keep it within
/// `tolerance` pixels (Ramer-Douglas-Peucker), in order. The first and the last point are
/// always kept, and so are the `anchors` (for a plot: its lowest and highest point, so that
/// the thinned line spans the same range) and every non-finite point (a break in the line
/// stays a break).
pub fn simplify(points: &[[f32; 2]], tolerance: f32, anchors: &[usize]) -> Vec<usize> {
    let n = points.len();
    if n <= 2 {
        return (0..n).collect();
    }
    let finite = |k: usize| {
        points
            .get(k)
            .is_some_and(|p| p[0].is_finite() && p[1].is_finite())
    };
    let mut keep = vec![false; n];
    for k in anchors.iter().copied().filter(|k| *k < n) {
        if let Some(slot) = keep.get_mut(k) {
            *slot = true;
        }
    }
    let mut stack = Vec::new();
    let mut run_start: Option<usize> = None;
    for k in 0..=n {
        let is_finite = k < n && finite(k);
        match (run_start, is_finite) {
            (None, true) => run_start = Some(k),
            (Some(a), false) => {
                // A run of finite points, a..k: its ends and its anchors cut it into pieces.
                let mut from = a;
                for b in a + 1..k {
                    if keep.get(b).copied().unwrap_or(false) || b == k - 1 {
                        stack.push((from, b));
                        from = b;
                    }
                }
                for end in [a, k - 1] {
                    if let Some(slot) = keep.get_mut(end) {
                        *slot = true;
                    }
                }
                run_start = None;
            }
            _ => {}
        }
        if k < n
            && !is_finite
            && let Some(slot) = keep.get_mut(k)
        {
            *slot = true;
        }
    }
    let tol2 = tolerance * tolerance;
    while let Some((a, b)) = stack.pop() {
        if b <= a + 1 {
            continue;
        }
        let (Some(pa), Some(pb)) = (points.get(a), points.get(b)) else {
            continue;
        };
        let mut worst = (0.0_f32, a);
        for (k, p) in points.iter().enumerate().take(b).skip(a + 1) {
            let d = segment_distance2(*p, *pa, *pb);
            if d > worst.0 {
                worst = (d, k);
            }
        }
        if worst.0 > tol2 {
            if let Some(slot) = keep.get_mut(worst.1) {
                *slot = true;
            }
            stack.push((a, worst.1));
            stack.push((worst.1, b));
        }
    }
    keep.iter()
        .enumerate()
        .filter_map(|(i, k)| k.then_some(i))
        .collect()
}

/// The squared distance from `p` to the segment `a`-`b`.
fn segment_distance2(p: [f32; 2], a: [f32; 2], b: [f32; 2]) -> f32 {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let (px, py) = (p[0] - a[0], p[1] - a[1]);
    let len2 = dx * dx + dy * dy;
    let s = if len2 > 0.0 {
        ((px * dx + py * dy) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let (ex, ey) = (px - s * dx, py - s * dy);
    ex * ex + ey * ey
}

/// The indices of a time series (`xy(point)` gives `[x, y]`, `x` ascending) worth drawing in
/// a plot whose x axis maps `x` to the pixel column `column(x)` (increasing), between the
/// columns `first` and `last` (the visible part): the samples of that range plus one on each
/// side (so that the line reaches the edges), and, where a column holds more than two samples,
/// only its lowest and highest finite `y` (in their order), which draw the same column of a
/// line.
pub fn column_extremes<P>(
    points: &[P],
    xy: impl Fn(&P) -> [f64; 2],
    column: impl Fn(f64) -> f64,
    first: f64,
    last: f64,
) -> Vec<usize> {
    let n = points.len();
    let col = |k: usize| points.get(k).map_or(f64::NAN, |p| column(xy(p)[0]).floor());
    let y = |k: usize| points.get(k).map_or(f64::NAN, |p| xy(p)[1]);
    let begin = points
        .partition_point(|p| column(xy(p)[0]) < first)
        .saturating_sub(1);
    let end = points
        .partition_point(|p| column(xy(p)[0]) <= last)
        .saturating_add(1)
        .min(n);
    let mut out = Vec::new();
    let mut i = begin;
    while i < end {
        let c = col(i);
        let mut j = i + 1;
        while j < end && col(j) == c {
            j += 1;
        }
        if j - i <= 2 {
            out.extend(i..j);
        } else {
            let (mut lo, mut hi): (Option<usize>, Option<usize>) = (None, None);
            for k in i..j {
                let v = y(k);
                if !v.is_finite() {
                    continue;
                }
                if lo.is_none_or(|l| v < y(l)) {
                    lo = Some(k);
                }
                if hi.is_none_or(|h| v > y(h)) {
                    hi = Some(k);
                }
            }
            match (lo, hi) {
                (Some(lo), Some(hi)) => {
                    out.push(lo.min(hi));
                    if hi != lo {
                        out.push(lo.max(hi));
                    }
                }
                _ => out.push(i),
            }
        }
        i = j;
    }
    out
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::indexing_slicing)]

    use super::*;

    #[test]
    fn a_straight_line_keeps_its_ends() {
        let pts: Vec<[f32; 2]> = (0..1000).map(|i| [i as f32, 2.0 * i as f32]).collect();
        assert_eq!(simplify(&pts, 0.25, &[]), vec![0, 999]);
        assert_eq!(simplify(&pts, 0.25, &[500]), vec![0, 500, 999]);
    }

    #[test]
    fn a_corner_is_kept_and_the_line_stays_within_the_tolerance() {
        // An L and a sine: every dropped point lies within the tolerance of the kept line.
        let mut pts: Vec<[f32; 2]> = (0..100).map(|i| [i as f32, 0.0]).collect();
        pts.extend((1..100).map(|i| [99.0, i as f32]));
        pts.extend(
            (0..500).map(|i| [99.0 + i as f32 * 0.3, 99.0 + 20.0 * (i as f32 * 0.05).sin()]),
        );
        let kept = simplify(&pts, 0.25, &[]);
        assert!(kept.contains(&99), "the corner");
        assert!(
            kept.len() < pts.len() / 2,
            "{} of {}",
            kept.len(),
            pts.len()
        );
        for w in kept.windows(2) {
            for k in w[0]..=w[1] {
                assert!(segment_distance2(pts[k], pts[w[0]], pts[w[1]]) <= 0.25 * 0.25 + 1e-6);
            }
        }
    }

    #[test]
    fn non_finite_points_stay_as_breaks() {
        let pts = [
            [0.0, 0.0],
            [1.0, 0.0],
            [2.0, 0.0],
            [f32::NAN, 0.0],
            [3.0, 0.0],
            [4.0, 0.0],
            [5.0, 0.0],
        ];
        assert_eq!(simplify(&pts, 0.25, &[]), vec![0, 2, 3, 4, 6]);
    }

    #[test]
    fn columns_keep_their_extremes_in_order() {
        // Ten samples a pixel column over 20 columns, a spike in column 7.
        let x: Vec<f64> = (0..200).map(|i| i as f64 / 10.0).collect();
        let mut y: Vec<f64> = (0..200).map(|i| (i % 10) as f64).collect();
        y[75] = 100.0;
        let pts: Vec<[f64; 2]> = x.iter().zip(&y).map(|(x, y)| [*x, *y]).collect();
        let kept = column_extremes(&pts, |p| *p, |v| v, 0.0, 19.99);
        assert!(kept.contains(&75));
        assert!(kept.windows(2).all(|w| w[0] < w[1]));
        assert!(kept.len() <= 40, "{}", kept.len());
        for c in 0..20 {
            let col: Vec<usize> = kept.iter().copied().filter(|k| k / 10 == c).collect();
            let lo = (c * 10..c * 10 + 10)
                .map(|k| y[k])
                .fold(f64::INFINITY, f64::min);
            let hi = (c * 10..c * 10 + 10)
                .map(|k| y[k])
                .fold(f64::NEG_INFINITY, f64::max);
            assert!(col.iter().any(|k| y[*k] == lo) && col.iter().any(|k| y[*k] == hi));
        }
    }

    #[test]
    fn columns_cut_to_the_visible_range_with_one_sample_beyond() {
        let pts: Vec<[f64; 2]> = (0..100).map(|i| [f64::from(i), 0.0]).collect();
        let kept = column_extremes(&pts, |p| *p, |v| v, 40.0, 59.0);
        assert_eq!(kept.first(), Some(&39));
        assert_eq!(kept.last(), Some(&60));
    }
}
