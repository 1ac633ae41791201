//! Dense kernels on column-major buffers: the symmetric low-rank covariance update and the
//! mirroring that keeps `P` exactly symmetric.
//!
//! All matrices here are plain `&[f64]` in column-major order with their leading dimension
//! equal to their row count, which is nalgebra's `DMatrix` layout, so that the covariance
//! buffer can be viewed by nalgebra and by faer alike.
//!
//! Only the lower triangle of `P` (diagonal included) is maintained: for a large state the
//! update is memory-bound (`P` is 18 MB at 1504 states and fits in no cache), and mirroring
//! after every update would write the whole upper half once more (docs/benchmarks.md, "Phase 2
//! EKF SLAM"). The upper triangle is filled in only when a caller asks for the whole matrix.

/// Up to this state size the rank update is a plain loop (axpys down each column's lower
/// part): for small states the set-up of a blocked kernel costs more than the arithmetic.
const SMALL_STATE: usize = 64;

/// Width of a column panel of the blocked update and of a tile of the mirroring.
const PANEL: usize = 32;

/// `lower(P) += alpha lhs rhs^T` for an `n x n` buffer `p` and `n x c` buffers `lhs`, `rhs`:
/// the lower triangle (diagonal included) is updated; above it, entries are left stale or
/// overwritten with meaningless values.
pub(crate) fn rank_update_lower(
    p: &mut [f64],
    n: usize,
    lhs: &[f64],
    rhs: &[f64],
    c: usize,
    alpha: f64,
) {
    let (Some(p), Some(lhs), Some(rhs)) = (p.get_mut(..n * n), lhs.get(..n * c), rhs.get(..n * c))
    else {
        return;
    };
    if n == 0 || c == 0 {
        return;
    }
    if n <= SMALL_STATE {
        crate::kernels::rank_update_lower_loops(p, n, lhs, rhs, alpha);
        return;
    }
    // Column panels: each a rectangular multiply over the rows from its diagonal block down.
    for jb in (0..n).step_by(PANEL) {
        #[cfg(feature = "std")]
        panel_update_faer(p, n, jb, PANEL.min(n - jb), lhs, rhs, c, alpha);
        #[cfg(not(feature = "std"))]
        panel_update_nalgebra(p, n, jb, PANEL.min(n - jb), lhs, rhs, c, alpha);
    }
}

/// `P[jb.., jb..jb + w] += alpha lhs[jb.., :] rhs[jb..jb + w, :]^T` with faer, one thread.
#[cfg(feature = "std")]
#[allow(clippy::too_many_arguments)]
fn panel_update_faer(
    p: &mut [f64],
    n: usize,
    jb: usize,
    w: usize,
    lhs: &[f64],
    rhs: &[f64],
    c: usize,
    alpha: f64,
) {
    use faer::{Accum, MatMut, MatRef, Par};
    let dst = MatMut::from_column_major_slice_mut(p, n, n).submatrix_mut(jb, jb, n - jb, w);
    let lhs = MatRef::from_column_major_slice(lhs, n, c).subrows(jb, n - jb);
    let rhs = MatRef::from_column_major_slice(rhs, n, c).subrows(jb, w);
    faer::linalg::matmul::matmul(dst, Accum::Add, lhs, rhs.transpose(), alpha, Par::Seq);
}

/// `P[jb.., jb..jb + w] += alpha lhs[jb.., :] rhs[jb..jb + w, :]^T` with nalgebra's gemm.
#[cfg(any(not(feature = "std"), test))]
#[allow(clippy::too_many_arguments)]
fn panel_update_nalgebra(
    p: &mut [f64],
    n: usize,
    jb: usize,
    w: usize,
    lhs: &[f64],
    rhs: &[f64],
    c: usize,
    alpha: f64,
) {
    use nalgebra::{DMatrixView, DMatrixViewMut};
    let mut dst = DMatrixViewMut::from_slice(p, n, n);
    let lhs = DMatrixView::from_slice(lhs, n, c);
    let rhs = DMatrixView::from_slice(rhs, n, c);
    let rhs_t = rhs.rows(jb, w).transpose();
    dst.view_mut((jb, jb), (n - jb, w))
        .gemm(alpha, &lhs.rows(jb, n - jb), &rhs_t, 1.0);
}

/// `dst = alpha a b` (`beta` false) or `dst += alpha a b` (true), for column-major `a`
/// (`m x k`), `b` (`k x n`) and `dst` (`m x n`): faer's kernels with `std`, nalgebra's
/// otherwise.
#[allow(clippy::too_many_arguments)]
pub(crate) fn gemm(
    dst: &mut [f64],
    m: usize,
    n: usize,
    a: &[f64],
    b: &[f64],
    k: usize,
    alpha: f64,
    accumulate: bool,
) {
    let (Some(dst), Some(a), Some(b)) = (dst.get_mut(..m * n), a.get(..m * k), b.get(..k * n))
    else {
        return;
    };
    if m == 0 || n == 0 {
        return;
    }
    #[cfg(feature = "std")]
    {
        use faer::{Accum, MatMut, MatRef, Par};
        let dst = MatMut::from_column_major_slice_mut(dst, m, n);
        let a = MatRef::from_column_major_slice(a, m, k);
        let b = MatRef::from_column_major_slice(b, k, n);
        let accum = if accumulate {
            Accum::Add
        } else {
            Accum::Replace
        };
        faer::linalg::matmul::matmul(dst, accum, a, b, alpha, Par::Seq);
    }
    #[cfg(not(feature = "std"))]
    {
        use nalgebra::{DMatrixView, DMatrixViewMut};
        let mut dst = DMatrixViewMut::from_slice(dst, m, n);
        let a = DMatrixView::from_slice(a, m, k);
        let b = DMatrixView::from_slice(b, k, n);
        dst.gemm(alpha, &a, &b, if accumulate { 1.0 } else { 0.0 });
    }
}

/// Entry `(i, j)` of the symmetric matrix whose lower triangle the buffer holds.
#[inline]
pub(crate) fn sym(p: &[f64], n: usize, i: usize, j: usize) -> f64 {
    let (r, c) = if i >= j { (i, j) } else { (j, i) };
    p.get(c * n + r).copied().unwrap_or(f64::NAN)
}

/// Copies the lower triangle of the `n x n` buffer onto the upper one.
pub(crate) fn mirror_lower(p: &mut [f64], n: usize) {
    if n == 0 || p.len() < n * n {
        return;
    }
    if n <= SMALL_STATE {
        // Column j above the diagonal is row j of the columns before it.
        for j in 1..n {
            let (left, right) = p.split_at_mut(j * n);
            for (v, src) in right.iter_mut().take(j).zip(left.chunks_exact(n)) {
                if let Some(&x) = src.get(j) {
                    *v = x;
                }
            }
        }
        return;
    }
    for jb in (0..n).step_by(PANEL) {
        mirror_panel(p, n, jb, PANEL.min(n - jb));
    }
}

/// Mirrors the lower part of the column panel `[jb, jb + w)` (rows `jb..n`) onto the row
/// panel above the diagonal, tile by tile through a buffer in L1, so that reads and writes of
/// `P` are whole runs of a column.
fn mirror_panel(p: &mut [f64], n: usize, jb: usize, w: usize) {
    let mut tile = [[0.0_f64; PANEL]; PANEL];
    for ib in (jb..n).step_by(PANEL) {
        let h = PANEL.min(n - ib);
        // tile[r][c] = P[ib + r, jb + c].
        for c in 0..w.min(PANEL) {
            let Some(col) = p.get((jb + c) * n + ib..(jb + c) * n + ib + h) else {
                return;
            };
            for (row, &v) in tile.iter_mut().zip(col) {
                row[c] = v;
            }
        }
        // P[jb + c, ib + r] = tile[r][c]; on the diagonal tile only above the diagonal.
        for (r, row) in tile.iter().enumerate().take(h) {
            let i = ib + r;
            let rows = if ib == jb { r.min(w) } else { w };
            let Some(dst) = p.get_mut(i * n + jb..i * n + jb + rows) else {
                return;
            };
            dst.copy_from_slice(&row[..rows]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::DMatrix;

    fn pseudo_random(rows: usize, cols: usize, seed: u64) -> DMatrix<f64> {
        let mut s = seed;
        DMatrix::from_fn(rows, cols, |_, _| {
            s = s
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            #[allow(clippy::cast_precision_loss)]
            let v = (s >> 11) as f64 / (1u64 << 53) as f64;
            v - 0.5
        })
    }

    #[test]
    fn rank_update_lower_equals_the_dense_product() {
        for (n, c) in [
            (1, 1),
            (5, 3),
            (19, 40),
            (64, 8),
            (65, 8),
            (200, 20),
            (301, 40),
            (70, 0),
        ] {
            let b = pseudo_random(n, n, 1);
            let p0 = &b * b.transpose();
            let w = pseudo_random(n, c, 2);
            let v = pseudo_random(n, c, 3);
            // Symmetric product of two different factors: w v^T + v w^T.
            let lhs = DMatrix::from_fn(
                n,
                2 * c,
                |i, k| if k < c { w[(i, k)] } else { v[(i, k - c)] },
            );
            let rhs = DMatrix::from_fn(
                n,
                2 * c,
                |i, k| if k < c { v[(i, k)] } else { w[(i, k - c)] },
            );
            let mut p = p0.clone();
            rank_update_lower(
                p.as_mut_slice(),
                n,
                lhs.as_slice(),
                rhs.as_slice(),
                2 * c,
                -0.5,
            );
            let full = &p0 - (&lhs * rhs.transpose()) * 0.5;
            for j in 0..n {
                for i in j..n {
                    let e = (p[(i, j)] - full[(i, j)]).abs();
                    assert!(
                        e < 1e-12 * (1.0 + full[(i, j)].abs()),
                        "n {n} c {c} ({i},{j})"
                    );
                    assert_eq!(sym(p.as_slice(), n, j, i), p[(i, j)]);
                }
            }
        }
    }

    /// The panels of the build without `std` (nalgebra's gemm) give the same lower triangle.
    #[test]
    fn nalgebra_panels_equal_the_dense_product() {
        for (n, c) in [(65, 8), (200, 40)] {
            let b = pseudo_random(n, n, 4);
            let p0 = &b * b.transpose();
            let w = pseudo_random(n, c, 5);
            let mut p = p0.clone();
            for jb in (0..n).step_by(PANEL) {
                panel_update_nalgebra(
                    p.as_mut_slice(),
                    n,
                    jb,
                    PANEL.min(n - jb),
                    w.as_slice(),
                    w.as_slice(),
                    c,
                    -1.0,
                );
            }
            let full = &p0 - &w * w.transpose();
            for j in 0..n {
                for i in j..n {
                    assert!((p[(i, j)] - full[(i, j)]).abs() < 1e-12 * (1.0 + full[(i, j)].abs()));
                }
            }
        }
    }

    #[test]
    fn mirroring_copies_the_lower_triangle() {
        for n in [1, 2, 31, 32, 33, 64, 65, 100] {
            let lower = pseudo_random(n, n, 9);
            let mut p = lower.clone();
            mirror_lower(p.as_mut_slice(), n);
            for j in 0..n {
                for i in j..n {
                    assert_eq!(p[(i, j)], lower[(i, j)]);
                    assert_eq!(p[(j, i)], lower[(i, j)]);
                }
            }
        }
    }
}
