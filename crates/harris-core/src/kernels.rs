//! The inner loops of the pipeline, one image row at a time, written for auto-vectorisation.
//!
//! Each is compiled for several instruction sets (AVX-512, AVX2 and the target's baseline)
//! by `multiversion`, which picks the best the CPU has at run time when `std` is on, and the
//! one the build targets otherwise (firmware). The arithmetic is the same in every version.

use multiversion::multiversion;

use crate::response;

/// The pixel rows around one gradient row, each `n + 2` pixels wide.
#[derive(Debug, Clone, Copy)]
pub(crate) struct PixelRows<'a> {
    pub(crate) above: &'a [u8],
    pub(crate) here: &'a [u8],
    pub(crate) below: &'a [u8],
}

/// Column sums of the structure-tensor products over the last five gradient rows.
#[derive(Debug)]
pub(crate) struct ColumnSums<'a> {
    pub(crate) xx: &'a mut [i32],
    pub(crate) yy: &'a mut [i32],
    pub(crate) xy: &'a mut [i32],
}

/// ICD step 1, and the vertical part of step 2: Sobel gradients of the `n` inner columns of a
/// row into `gx`, `gy` (which hold the gradients of the row leaving the window), and the
/// column sums updated by the difference of the products.
#[multiversion(targets("x86_64+avx512f+avx512bw+avx512vl", "x86_64+avx2"))]
pub(crate) fn gradient_row(
    px: PixelRows<'_>,
    gx: &mut [i16],
    gy: &mut [i16],
    sums: ColumnSums<'_>,
) {
    let n = gx.len();
    let (a_l, a_c, a_r) = (&px.above[..n], &px.above[1..=n], &px.above[2..n + 2]);
    let (b_l, b_r) = (&px.here[..n], &px.here[2..n + 2]);
    let (c_l, c_c, c_r) = (&px.below[..n], &px.below[1..=n], &px.below[2..n + 2]);
    let gy = &mut gy[..n];
    let (col_xx, col_yy, col_xy) = (&mut sums.xx[..n], &mut sums.yy[..n], &mut sums.xy[..n]);
    for i in 0..n {
        let (al, ac, ar) = (i16::from(a_l[i]), i16::from(a_c[i]), i16::from(a_r[i]));
        let (bl, br) = (i16::from(b_l[i]), i16::from(b_r[i]));
        let (cl, cc, cr) = (i16::from(c_l[i]), i16::from(c_c[i]), i16::from(c_r[i]));
        // |gx|, |gy| <= 1020: 11 signed bits.
        let new_x = (ar + 2 * br + cr) - (al + 2 * bl + cl);
        let new_y = (cl + 2 * cc + cr) - (al + 2 * ac + ar);
        let (old_x, old_y) = (gx[i], gy[i]);
        // Column sums of 5 products: |sum| <= 5 * 1020^2 < 2^23. The squares change by
        // `new^2 - old^2 = (new - old)(new + old)`, factors within 12 signed bits: one
        // 16x16->32 bit multiply each instead of two.
        col_xx[i] += i32::from(new_x - old_x) * i32::from(new_x + old_x);
        col_yy[i] += i32::from(new_y - old_y) * i32::from(new_y + old_y);
        col_xy[i] += i32::from(new_x) * i32::from(new_y) - i32::from(old_x) * i32::from(old_y);
        gx[i] = new_x;
        gy[i] = new_y;
    }
}

/// Window sums of one response row.
#[derive(Debug)]
pub(crate) struct WindowSums<'a> {
    pub(crate) xx: &'a mut [i32],
    pub(crate) yy: &'a mut [i32],
    pub(crate) xy: &'a mut [i32],
}

/// ICD step 2, horizontal part: the 5x5 window sums of `n = out.xx.len()` columns from the
/// column sums starting two columns to their left, and `maybe[i] = 1` where the trace
/// `Sxx + Syy >= trace_min`.
#[multiversion(targets("x86_64+avx512f+avx512bw+avx512vl", "x86_64+avx2"))]
pub(crate) fn window_row(
    col_xx: &[i32],
    col_yy: &[i32],
    col_xy: &[i32],
    out: WindowSums<'_>,
    maybe: &mut [u8],
    trace_min: i32,
) {
    let n = out.xx.len();
    let (sxx, syy, sxy, maybe) = (&mut out.xx[..n], &mut out.yy[..n], &mut out.xy[..n], &mut maybe[..n]);
    let (xx0, xx1, xx2, xx3, xx4) = taps(col_xx, n);
    let (yy0, yy1, yy2, yy3, yy4) = taps(col_yy, n);
    let (xy0, xy1, xy2, xy3, xy4) = taps(col_xy, n);
    for i in 0..n {
        let xx = xx0[i] + xx1[i] + xx2[i] + xx3[i] + xx4[i];
        let yy = yy0[i] + yy1[i] + yy2[i] + yy3[i] + yy4[i];
        sxx[i] = xx;
        syy[i] = yy;
        sxy[i] = xy0[i] + xy1[i] + xy2[i] + xy3[i] + xy4[i];
        maybe[i] = u8::from(xx + yy >= trace_min);
    }
}

/// The five slices whose element-wise sum is the 5-wide box sum of `col` at `2 .. n + 2`.
type Taps<'a> = (&'a [i32], &'a [i32], &'a [i32], &'a [i32], &'a [i32]);

#[inline(always)]
fn taps(col: &[i32], n: usize) -> Taps<'_> {
    (&col[..n], &col[1..=n], &col[2..n + 2], &col[3..n + 3], &col[4..n + 4])
}

/// ICD step 3 over a run of pixels.
#[multiversion(targets("x86_64+avx512f+avx512bw+avx512vl", "x86_64+avx2"))]
pub(crate) fn response_run(sxx: &[i32], syy: &[i32], sxy: &[i32], out: &mut [i32]) {
    let n = out.len();
    let (sxx, syy, sxy) = (&sxx[..n], &syy[..n], &sxy[..n]);
    for i in 0..n {
        out[i] = response(sxx[i], syy[i], sxy[i]);
    }
}

/// The response rows around one row of candidates, as slices starting one column to the left
/// of the first candidate (so `cur[i + 1]` is the candidate's own response).
#[derive(Debug, Clone, Copy)]
pub(crate) struct ResponseRows<'a> {
    pub(crate) prev: &'a [i32],
    pub(crate) cur: &'a [i32],
    pub(crate) next: &'a [i32],
}

/// ICD steps 4 and 5 over a run of `flags.len()` pixels: `flags[i] = 1` where the pixel is
/// above the threshold and a 3x3 local maximum with raster-order tie breaking (`>` against
/// the four neighbours before it, `>=` against the four after it).
#[multiversion(targets("x86_64+avx512f+avx512bw+avx512vl", "x86_64+avx2"))]
pub(crate) fn local_maxima(rows: ResponseRows<'_>, threshold: i32, flags: &mut [u8]) {
    let n = flags.len();
    let (p0, p1, p2) = (&rows.prev[..n], &rows.prev[1..=n], &rows.prev[2..n + 2]);
    let (c0, c1, c2) = (&rows.cur[..n], &rows.cur[1..=n], &rows.cur[2..n + 2]);
    let (n0, n1, n2) = (&rows.next[..n], &rows.next[1..=n], &rows.next[2..n + 2]);
    for i in 0..n {
        let r = c1[i];
        // `&` rather than `&&`: no branches, so the loop vectorises.
        let is_max = (r > threshold)
            & (r > p0[i])
            & (r > p1[i])
            & (r > p2[i])
            & (r > c0[i])
            & (r >= c2[i])
            & (r >= n0[i])
            & (r >= n1[i])
            & (r >= n2[i]);
        flags[i] = u8::from(is_max);
    }
}
