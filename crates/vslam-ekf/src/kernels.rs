//! The update's arithmetic on column-major slices (eq. (6)-(7): `A = P H^T`, `S = H A + R`,
//! the gain's factors, the rank update), written for auto-vectorisation.
//!
//! The loops that carry the update's O(n k) and O(n k^2) work are compiled for AVX-512, AVX2
//! and the build's baseline by `multiversion`, which picks the best the CPU has at run time
//! under `std` (the baseline alone without it). No version fuses or reorders floating-point
//! operations, so all give the same numbers.

use alloc::vec::Vec;

use multiversion::multiversion;

/// Rows are padded to a multiple of this for the small-state kernels, so that every column
/// is whole 512-bit vectors.
pub(crate) const LANES: usize = 8;

/// Largest rank a padded update takes at once (one landmark's Joseph update is rank 8).
pub(crate) const MAX_PADDED_RANK: usize = 8;

/// Most states one observation involves: pose, one landmark, every camera parameter.
pub(crate) const MAX_INVOLVED: usize = crate::measurement::MAX_H_COLUMNS;

/// One observation's linearisation: the non-zero columns of its four rows of `H` (pose, its
/// landmark, the estimated camera parameters) and its innovation.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Obs {
    /// State indices of the involved columns.
    pub(crate) cols: [usize; MAX_INVOLVED],
    /// `h[r][t]`: row `r` of `H` at state `cols[t]`.
    pub(crate) h: [[f64; MAX_INVOLVED]; 4],
    /// Involved columns in use.
    pub(crate) q: usize,
    /// Innovation `z - h(x)`.
    pub(crate) nu: [f64; 4],
    /// Variances of the measurement's `uL, vL, uR, vR`, px^2 (the diagonal of `R`).
    pub(crate) r: [f64; 4],
}

impl Obs {
    /// The observation whose rows of `H` are `h` (eq. (8)), its innovation zero.
    pub(crate) fn new(h: &crate::measurement::HColumns) -> Self {
        Self {
            cols: h.cols,
            h: h.h,
            q: h.len,
            nu: [0.0; 4],
            r: [0.0; 4],
        }
    }
}

/// Work buffers of the update, kept between updates to avoid allocating per frame.
#[derive(Debug, Clone, Default)]
pub(crate) struct Workspace {
    /// `A = P H^T`, `n x d`.
    pub(crate) a: Vec<f64>,
    /// `S = H P H^T + R`, `d x d`.
    pub(crate) s: Vec<f64>,
    /// `W = A L^-T`, `n x d`.
    pub(crate) w: Vec<f64>,
    /// Left factor of the rank update, `n x c`.
    pub(crate) lhs: Vec<f64>,
    /// Right factor of the rank update, `n x c`.
    pub(crate) rhs: Vec<f64>,
    /// State correction `K nu`.
    pub(crate) dx: Vec<f64>,
    /// `L^-1 nu`, then the change of the diagonal.
    pub(crate) y: Vec<f64>,
    /// Working copy of `P` (sequential updates).
    pub(crate) p: Vec<f64>,
    /// Accumulated state correction (sequential updates).
    pub(crate) dx_total: Vec<f64>,
    /// The states the batch involves, increasing.
    pub(crate) union: Vec<usize>,
    /// Their whole columns of `P`, `n x union.len()`.
    pub(crate) g: Vec<f64>,
}

/// `A = P H^T` (`n x 4k`), each column a sum of the few columns of `P` that its row of `H`
/// touches (gathered once into `g` from the lower triangle), and `S = H A + R` (`4k x 4k`,
/// symmetrised).
pub(crate) fn innovation_products(p: &[f64], n: usize, obs: &[Obs], ws: &mut Workspace) {
    let d = 4 * obs.len();
    // The union of the involved states, and each observation's columns in it.
    ws.union.clear();
    for o in obs {
        ws.union.extend_from_slice(&o.cols[..o.q.min(MAX_INVOLVED)]);
    }
    ws.union.sort_unstable();
    ws.union.dedup();
    ws.g.clear();
    ws.g.resize(n * ws.union.len(), 0.0);
    gather_columns(p, n, &ws.union, &mut ws.g);
    ws.a.clear();
    ws.a.resize(n * d, 0.0);
    combine_columns(n, obs, &ws.union, &ws.g, &mut ws.a);
    let s = &mut ws.s;
    s.clear();
    s.resize(d * d, 0.0);
    for (col, a_col) in ws.a.chunks_exact(n).enumerate() {
        let s_col = &mut s[col * d..(col + 1) * d];
        for (o, s_rows) in obs.iter().zip(s_col.chunks_exact_mut(4)) {
            for (r, v) in s_rows.iter_mut().enumerate() {
                let mut acc = 0.0;
                for (h, &c) in o.h[r].iter().zip(&o.cols).take(o.q) {
                    acc += h * a_col.get(c).copied().unwrap_or(0.0);
                }
                *v = acc;
            }
        }
    }
    for i in 0..d {
        for j in 0..i {
            let v = 0.5 * (s[j * d + i] + s[i * d + j]);
            s[j * d + i] = v;
            s[i * d + j] = v;
        }
        s[i * d + i] += obs.get(i / 4).map_or(0.0, |o| o.r[i % 4]);
    }
}

/// `A = P H^T` (`n x 4`) and `S = H A + R` (4x4, column-major) of one observation, from
/// the lower triangle of `P` (the small states' working copy).
pub(crate) fn observation_products(
    p: &[f64],
    n: usize,
    o: &Obs,
    a: &mut Vec<f64>,
    s: &mut [f64; 16],
) {
    a.clear();
    a.resize(4 * n, 0.0);
    axpy_columns_lower(p, n, o, a);
    for (c, a_col) in a.chunks_exact(n).enumerate() {
        for r in 0..4 {
            let mut acc = 0.0;
            for (h, &col) in o.h[r].iter().zip(&o.cols).take(o.q) {
                acc += h * a_col.get(col).copied().unwrap_or(0.0);
            }
            s[c * 4 + r] = acc;
        }
    }
    for i in 0..4 {
        for j in 0..i {
            let v = 0.5 * (s[j * 4 + i] + s[i * 4 + j]);
            s[j * 4 + i] = v;
            s[i * 4 + j] = v;
        }
        s[i * 4 + i] += o.r[i];
    }
}

/// Largest state whose columns [`axpy_columns_lower`] copies to the stack.
pub(crate) const MAX_SMALL_STATE: usize = 64;

/// `a[:, r] += sum_t h[r][t] P[:, cols[t]]` for `n <= MAX_SMALL_STATE`, each column of `P`
/// first copied whole from the lower triangle (along its row above the diagonal, down the
/// column from it).
#[multiversion(targets("x86_64+avx512f+avx512vl", "x86_64+avx2+fma"))]
fn axpy_columns_lower(p: &[f64], n: usize, o: &Obs, a: &mut [f64]) {
    let mut column = [0.0; MAX_SMALL_STATE];
    let Some(column) = column.get_mut(..n) else {
        return;
    };
    for (t, &col) in o.cols.iter().enumerate().take(o.q) {
        let (above, below) = column.split_at_mut(col.min(n));
        for (i, v) in above.iter_mut().enumerate() {
            *v = p.get(i * n + col).copied().unwrap_or(0.0);
        }
        if let Some(src) = p.get(col * n + col..(col + 1) * n) {
            below.copy_from_slice(src);
        }
        for (r, a_col) in a.chunks_exact_mut(n).enumerate() {
            let h = o.h[r][t];
            if h != 0.0 {
                for (av, &pv) in a_col.iter_mut().zip(column.iter()) {
                    *av += h * pv;
                }
            }
        }
    }
}

/// Whole columns `cols` of the symmetric matrix whose lower triangle `p` holds, into `out`
/// (`n x cols.len()`): above the diagonal a column is read along its row, below it down the
/// column.
pub(crate) fn gather_columns(p: &[f64], n: usize, cols: &[usize], out: &mut [f64]) {
    for (&c, dst) in cols.iter().zip(out.chunks_exact_mut(n)) {
        let (above, below) = dst.split_at_mut(c.min(n));
        for (i, v) in above.iter_mut().enumerate() {
            *v = p.get(i * n + c).copied().unwrap_or(0.0);
        }
        if let Some(src) = p.get(c * n + c..(c + 1) * n) {
            below.copy_from_slice(src);
        }
    }
}

#[multiversion(targets("x86_64+avx512f+avx512vl", "x86_64+avx2+fma"))]
fn combine_columns(n: usize, obs: &[Obs], union: &[usize], g: &[f64], a: &mut [f64]) {
    for (o, a4) in obs.iter().zip(a.chunks_exact_mut(4 * n)) {
        for (t, col) in o.cols.iter().enumerate().take(o.q) {
            let Ok(k) = union.binary_search(col) else {
                continue;
            };
            let Some(gcol) = g.get(k * n..(k + 1) * n) else {
                continue;
            };
            for (r, a_col) in a4.chunks_exact_mut(n).enumerate() {
                let h = o.h[r][t];
                if h != 0.0 {
                    for (av, &gv) in a_col.iter_mut().zip(gcol) {
                        *av += h * gv;
                    }
                }
            }
        }
    }
}

/// Keeps the observations `keep` (indices into the batch, increasing) in `A` and `S`.
pub(crate) fn compact(n: usize, d_old: usize, keep: &[usize], a: &mut Vec<f64>, s: &mut Vec<f64>) {
    let d = 4 * keep.len();
    for (new_j, &old_j) in keep.iter().enumerate() {
        if new_j != old_j {
            a.copy_within(4 * old_j * n..4 * (old_j + 1) * n, 4 * new_j * n);
        }
    }
    a.truncate(n * d);
    let old = core::mem::take(s);
    s.resize(d * d, 0.0);
    for (bj, &oj) in keep.iter().enumerate() {
        for (bi, &oi) in keep.iter().enumerate() {
            for c in 0..4 {
                for r in 0..4 {
                    s[(4 * bj + c) * d + 4 * bi + r] = old[(4 * oj + c) * d_old + 4 * oi + r];
                }
            }
        }
    }
}

/// From `A`, `S`'s Cholesky factor `L` (column-major, lower triangle used) and the
/// innovations: `W = A L^-T`, `y = L^-1 nu`, `dx = W y`, and, for the Joseph form, the rank
/// update's factors `lhs = [K S - A, -K]`, `rhs = [K, A]` with `K = W L^-1`.
#[allow(clippy::too_many_arguments)]
#[multiversion(targets("x86_64+avx512f+avx512vl", "x86_64+avx2+fma"))]
pub(crate) fn gain_factors(
    n: usize,
    d: usize,
    l: &[f64],
    s: &[f64],
    nu: &[f64],
    joseph: bool,
    ws_a: &[f64],
    w: &mut Vec<f64>,
    y: &mut Vec<f64>,
    dx: &mut Vec<f64>,
    lhs: &mut Vec<f64>,
    rhs: &mut Vec<f64>,
) {
    let lij = |i: usize, j: usize| l.get(j * d + i).copied().unwrap_or(0.0);
    // W L^T = A: column i of W from columns j < i (forward substitution over columns).
    w.clear();
    w.extend_from_slice(ws_a);
    #[cfg(feature = "std")]
    let solved = solve_w_faer(w, n, d, l);
    #[cfg(not(feature = "std"))]
    let solved = false;
    for i in (0..d).filter(|_| !solved) {
        let (done, rest) = w.split_at_mut(i * n);
        let Some(wi) = rest.get_mut(..n) else {
            return;
        };
        for (j, wj) in done.chunks_exact(n).enumerate() {
            let f = lij(i, j);
            if f != 0.0 {
                for (a, &b) in wi.iter_mut().zip(wj) {
                    *a -= f * b;
                }
            }
        }
        let inv = 1.0 / lij(i, i);
        for v in wi.iter_mut() {
            *v *= inv;
        }
    }
    // y = L^-1 nu.
    y.clear();
    y.extend_from_slice(nu);
    for i in 0..d {
        let (done, rest) = y.split_at_mut(i);
        let Some(yi) = rest.first_mut() else {
            break;
        };
        let mut v = *yi;
        for (j, &yj) in done.iter().enumerate() {
            v -= lij(i, j) * yj;
        }
        *yi = v / lij(i, i);
    }
    // dx = K nu = W y.
    dx.clear();
    dx.resize(n, 0.0);
    for (wi, &yi) in w.chunks_exact(n).zip(y.iter()) {
        for (a, &b) in dx.iter_mut().zip(wi) {
            *a += yi * b;
        }
    }
    if !joseph {
        return;
    }
    // rhs = [K, A] with K L = W (back substitution over columns).
    rhs.clear();
    rhs.resize(2 * n * d, 0.0);
    let (k, a_part) = rhs.split_at_mut(n * d);
    a_part.copy_from_slice(ws_a);
    for i in (0..d).rev() {
        let (head, tail) = k.split_at_mut((i + 1) * n);
        let Some(ki) = head.get_mut(i * n..) else {
            return;
        };
        ki.copy_from_slice(&w[i * n..(i + 1) * n]);
        for (off, kj) in tail.chunks_exact(n).enumerate() {
            let f = lij(i + 1 + off, i);
            if f != 0.0 {
                for (a, &b) in ki.iter_mut().zip(kj) {
                    *a -= f * b;
                }
            }
        }
        let inv = 1.0 / lij(i, i);
        for v in ki.iter_mut() {
            *v *= inv;
        }
    }
    // lhs = [K S - A, -K].
    lhs.clear();
    lhs.resize(2 * n * d, 0.0);
    let (v_part, negk) = lhs.split_at_mut(n * d);
    for (c, v_col) in v_part.chunks_exact_mut(n).enumerate() {
        for (v, &a) in v_col.iter_mut().zip(&ws_a[c * n..(c + 1) * n]) {
            *v = -a;
        }
        for (b, k_col) in k.chunks_exact(n).enumerate() {
            let sbc = s.get(c * d + b).copied().unwrap_or(0.0);
            for (v, &kv) in v_col.iter_mut().zip(k_col) {
                *v += kv * sbc;
            }
        }
    }
    for (v, &kv) in negk.iter_mut().zip(k.iter()) {
        *v = -kv;
    }
}

/// `W L^T = A` for `W` (holding `A`, `n x d`) with faer's blocked triangular solve, as
/// `L W^T = A^T`: the forward substitution's arithmetic in gemm-sized blocks, several times
/// faster than column axpys once `d` is a few dozen. `false` (nothing done) when the
/// buffers do not have the shapes.
#[cfg(feature = "std")]
fn solve_w_faer(w: &mut [f64], n: usize, d: usize, l: &[f64]) -> bool {
    use faer::{MatMut, MatRef, Par};
    let (Some(w), Some(l)) = (w.get_mut(..n * d), l.get(..d * d)) else {
        return false;
    };
    if n == 0 || d == 0 {
        return false;
    }
    let lower = MatRef::from_column_major_slice(l, d, d);
    let wt = MatMut::from_column_major_slice_mut(w, n, d).transpose_mut();
    faer::linalg::triangular_solve::solve_lower_triangular_in_place(lower, wt, Par::Seq);
    true
}

/// The Cholesky factor `L` (lower, `l[r][c]`) of a symmetric 4x4 matrix given by rows, or
/// `None` when it is not positive definite (or not finite).
pub(crate) fn cholesky4(s: &[[f64; 4]; 4]) -> Option<[[f64; 4]; 4]> {
    let mut l = [[0.0; 4]; 4];
    for j in 0..4 {
        let lj = l[j];
        let d = s[j][j] - lj.iter().take(j).map(|v| v * v).sum::<f64>();
        if !(d > 0.0 && d.is_finite()) {
            return None;
        }
        let ljj = libm::sqrt(d);
        l[j][j] = ljj;
        for i in j + 1..4 {
            let dot: f64 = l[i].iter().zip(&lj).take(j).map(|(a, b)| a * b).sum();
            l[i][j] = (s[i][j] - dot) / ljj;
        }
    }
    Some(l)
}

/// `|L^-1 v|^2 = v^T S^-1 v` for `S = L L^T`: the NIS of an innovation.
pub(crate) fn mahalanobis4(l: &[[f64; 4]; 4], v: &[f64; 4]) -> f64 {
    let mut y = [0.0; 4];
    let mut sum = 0.0;
    for i in 0..4 {
        let mut t = v[i];
        for k in 0..i {
            t -= l[i][k] * y[k];
        }
        y[i] = t / l[i][i];
        sum += y[i] * y[i];
    }
    sum
}

/// Makes `v` `len` long; its contents are left unspecified (the caller overwrites them all).
pub(crate) fn set_len(v: &mut Vec<f64>, len: usize) {
    if v.len() != len {
        v.clear();
        v.resize(len, 0.0);
    }
}

/// [`gain_factors`] for one landmark (`d = 4`), row by row: every row of `W`, `K` and
/// `K S - A` is a 4-vector times a 4x4 matrix, computed in registers (the sequential update of
/// small states calls this once per landmark).
#[allow(clippy::too_many_arguments, clippy::many_single_char_names)]
#[multiversion(targets("x86_64+avx512f+avx512vl", "x86_64+avx2+fma"))]
pub(crate) fn gain_factors4(
    n: usize,
    l: &[[f64; 4]; 4],
    s: &[[f64; 4]; 4],
    nu: &[f64; 4],
    joseph: bool,
    a: &[f64],
    w: &mut Vec<f64>,
    dx: &mut Vec<f64>,
    lhs: &mut Vec<f64>,
    rhs: &mut Vec<f64>,
) {
    // l[r][c] = L(r, c), lower; s[r][c] = S(r, c).
    let inv = [1.0 / l[0][0], 1.0 / l[1][1], 1.0 / l[2][2], 1.0 / l[3][3]];
    // y = L^-1 nu.
    let y0 = nu[0] * inv[0];
    let y1 = (nu[1] - l[1][0] * y0) * inv[1];
    let y2 = (nu[2] - l[2][0] * y0 - l[2][1] * y1) * inv[2];
    let y3 = (nu[3] - l[3][0] * y0 - l[3][1] * y1 - l[3][2] * y2) * inv[3];
    // Every entry of the outputs is written below.
    set_len(w, 4 * n);
    set_len(dx, n);
    let c = if joseph { 8 * n } else { 0 };
    set_len(lhs, c);
    set_len(rhs, c);
    let (Some(a), Some(w)) = (a.get(..4 * n), w.get_mut(..4 * n)) else {
        return;
    };
    let (a0, rest) = a.split_at(n);
    let (a1, rest) = rest.split_at(n);
    let (a2, a3) = rest.split_at(n);
    let (w0, rest) = w.split_at_mut(n);
    let (w1, rest) = rest.split_at_mut(n);
    let (w2, w3) = rest.split_at_mut(n);
    // W L^T = A, row by row; dx = W y.
    for i in 0..n {
        let x0 = a0[i] * inv[0];
        let x1 = (a1[i] - l[1][0] * x0) * inv[1];
        let x2 = (a2[i] - l[2][0] * x0 - l[2][1] * x1) * inv[2];
        let x3 = (a3[i] - l[3][0] * x0 - l[3][1] * x1 - l[3][2] * x2) * inv[3];
        w0[i] = x0;
        w1[i] = x1;
        w2[i] = x2;
        w3[i] = x3;
        dx[i] = x0 * y0 + x1 * y1 + x2 * y2 + x3 * y3;
    }
    if !joseph {
        return;
    }
    // K L = W; lhs = [K S - A, -K], rhs = [K, A].
    let mut lc = lhs.chunks_exact_mut(n);
    let mut rc = rhs.chunks_exact_mut(n);
    let (Some(v0), Some(v1), Some(v2), Some(v3), Some(m0), Some(m1), Some(m2), Some(m3)) = (
        lc.next(),
        lc.next(),
        lc.next(),
        lc.next(),
        lc.next(),
        lc.next(),
        lc.next(),
        lc.next(),
    ) else {
        return;
    };
    let (Some(k0), Some(k1), Some(k2), Some(k3), Some(r4), Some(r5), Some(r6), Some(r7)) = (
        rc.next(),
        rc.next(),
        rc.next(),
        rc.next(),
        rc.next(),
        rc.next(),
        rc.next(),
        rc.next(),
    ) else {
        return;
    };
    for i in 0..n {
        let q3 = w3[i] * inv[3];
        let q2 = (w2[i] - q3 * l[3][2]) * inv[2];
        let q1 = (w1[i] - q2 * l[2][1] - q3 * l[3][1]) * inv[1];
        let q0 = (w0[i] - q1 * l[1][0] - q2 * l[2][0] - q3 * l[3][0]) * inv[0];
        let (e0, e1, e2, e3) = (a0[i], a1[i], a2[i], a3[i]);
        k0[i] = q0;
        k1[i] = q1;
        k2[i] = q2;
        k3[i] = q3;
        r4[i] = e0;
        r5[i] = e1;
        r6[i] = e2;
        r7[i] = e3;
        v0[i] = q0 * s[0][0] + q1 * s[1][0] + q2 * s[2][0] + q3 * s[3][0] - e0;
        v1[i] = q0 * s[0][1] + q1 * s[1][1] + q2 * s[2][1] + q3 * s[3][1] - e1;
        v2[i] = q0 * s[0][2] + q1 * s[1][2] + q2 * s[2][2] + q3 * s[3][2] - e2;
        v3[i] = q0 * s[0][3] + q1 * s[1][3] + q2 * s[2][3] + q3 * s[3][3] - e3;
        m0[i] = -q0;
        m1[i] = -q1;
        m2[i] = -q2;
        m3[i] = -q3;
    }
}

/// The diagonal of `alpha lhs rhs^T` (`n x c` factors), accumulated into `out`: the change
/// the update makes to every variance, in O(n c).
#[multiversion(targets("x86_64+avx512f+avx512vl", "x86_64+avx2+fma"))]
pub(crate) fn diagonal_change(n: usize, lhs: &[f64], rhs: &[f64], alpha: f64, out: &mut Vec<f64>) {
    out.clear();
    out.resize(n, 0.0);
    for (l, r) in lhs.chunks_exact(n).zip(rhs.chunks_exact(n)) {
        for ((o, &a), &b) in out.iter_mut().zip(l).zip(r) {
            *o += a * b;
        }
    }
    for o in out.iter_mut() {
        *o *= alpha;
    }
}

/// `lower(P) += alpha lhs rhs^T` by axpys down each column's lower part (for small states,
/// where a blocked kernel's set-up costs more than the arithmetic).
#[multiversion(targets("x86_64+avx512f+avx512vl", "x86_64+avx2+fma"))]
pub(crate) fn rank_update_lower_loops(
    p: &mut [f64],
    n: usize,
    lhs: &[f64],
    rhs: &[f64],
    alpha: f64,
) {
    for (j, column) in p.chunks_exact_mut(n).enumerate() {
        let Some(dst) = column.get_mut(j..) else {
            continue;
        };
        for (l, r) in lhs.chunks_exact(n).zip(rhs.chunks_exact(n)) {
            let f = alpha * r.get(j).copied().unwrap_or(0.0);
            if f == 0.0 {
                continue;
            }
            if let Some(l) = l.get(j..) {
                for (a, &b) in dst.iter_mut().zip(l) {
                    *a += f * b;
                }
            }
        }
    }
}

/// `lower(P) += alpha lhs rhs^T` for a padded `n x n` buffer (`n` a multiple of [`LANES`],
/// the padding rows and columns zero) and at most [`MAX_PADDED_RANK`] factor columns: each
/// column from the vector holding its diagonal on, every vector updated once with the sum of
/// all factor columns (a few entries above the diagonal are written too; they are not read).
#[multiversion(targets("x86_64+avx512f+avx512vl", "x86_64+avx2+fma"))]
pub(crate) fn rank_update_lower_padded(
    p: &mut [f64],
    n: usize,
    lhs: &[f64],
    rhs: &[f64],
    alpha: f64,
) {
    let mut cols: [&[f64]; MAX_PADDED_RANK] = [&[]; MAX_PADDED_RANK];
    let mut count = 0;
    for (slot, l) in cols.iter_mut().zip(lhs.chunks_exact(n)) {
        *slot = l;
        count += 1;
    }
    let mut f = [0.0; MAX_PADDED_RANK];
    for (j, column) in p.chunks_exact_mut(n).enumerate() {
        for (fc, r) in f.iter_mut().zip(rhs.chunks_exact(n)) {
            *fc = alpha * r.get(j).copied().unwrap_or(0.0);
        }
        if f.iter().all(|&v| v == 0.0) {
            // A padding column (or a state the update does not reach).
            continue;
        }
        let start = j - j % LANES;
        let Some(dst) = column.get_mut(start..) else {
            continue;
        };
        for (k, d8) in dst.chunks_exact_mut(LANES).enumerate() {
            let base = start + k * LANES;
            let mut acc = [0.0; LANES];
            acc.copy_from_slice(d8);
            for (fc, l) in f.iter().zip(&cols).take(count) {
                if let Some(l8) = l.get(base..base + LANES) {
                    for (a, &b) in acc.iter_mut().zip(l8) {
                        *a += fc * b;
                    }
                }
            }
            d8.copy_from_slice(&acc);
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use nalgebra::{Matrix4, Vector4};

    #[test]
    fn cholesky4_and_mahalanobis4_agree_with_nalgebra() {
        let b = Matrix4::new(
            1.0, 0.2, -0.3, 0.4, 0.1, 2.0, 0.5, -0.2, 0.3, -0.1, 1.5, 0.2, -0.4, 0.3, 0.1, 0.9,
        );
        let s = b * b.transpose() + Matrix4::identity() * 0.09;
        let rows: [[f64; 4]; 4] = core::array::from_fn(|r| core::array::from_fn(|c| s[(r, c)]));
        let l = cholesky4(&rows).unwrap();
        let chol = s.cholesky().unwrap();
        let lref = chol.l();
        for r in 0..4 {
            for c in 0..4 {
                assert!((l[r][c] - lref[(r, c)]).abs() < 1e-14, "({r},{c})");
            }
        }
        let v = [0.3, -1.2, 0.7, 2.0];
        let nv = Vector4::from(v);
        let reference = nv.dot(&chol.solve(&nv));
        assert!((mahalanobis4(&l, &v) - reference).abs() < 1e-12 * reference);
        let mut bad = rows;
        bad[2][2] = -1.0;
        assert!(cholesky4(&bad).is_none());
        bad[2][2] = f64::NAN;
        assert!(cholesky4(&bad).is_none());
    }
}
