//! The inner loops of the pipeline, one image row at a time, written for auto-vectorisation.
//!
//! Each is compiled for several instruction sets (AVX-512, AVX2 and the target's baseline)
//! by `multiversion`, which picks the best the CPU has at run time when `std` is on, and the
//! one the build targets otherwise (firmware). The arithmetic is the same in every version.

use multiversion::multiversion;

use crate::response;
use crate::stream::{CHUNK, ChunkSet};

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
    /// `xx + yy`, for the window trace.
    pub(crate) tt: &'a mut [i32],
}

/// The gradient row being computed, and the one leaving the window.
#[derive(Debug)]
pub(crate) struct Gradients<'a> {
    pub(crate) gx: &'a mut [i16],
    pub(crate) gy: &'a mut [i16],
    pub(crate) old_gx: &'a [i16],
    pub(crate) old_gy: &'a [i16],
}

/// Scratch rows of the separable Sobel: the vertical smoothing `p(y-1) + 2 p(y) + p(y+1)` and
/// the vertical difference `p(y+1) - p(y-1)` of every column.
#[derive(Debug)]
pub(crate) struct SobelScratch<'a> {
    pub(crate) smooth: &'a mut [i16],
    pub(crate) diff: &'a mut [i16],
}

/// ICD step 1, and the vertical part of step 2: Sobel gradients of the `n` inner columns of a
/// row, and the column sums updated by the difference of the new and the old row's products.
///
/// The Sobel kernels are separable: `gx = S(x+1) - S(x-1)` with `S` the vertical smoothing,
/// and `gy = D(x-1) + 2 D(x) + D(x+1)` with `D` the vertical difference; the sums are the
/// ICD's, in another order, and exact.
#[multiversion(targets("x86_64+avx512f+avx512bw+avx512vl", "x86_64+avx2"))]
pub(crate) fn gradient_row(
    px: PixelRows<'_>,
    scratch: SobelScratch<'_>,
    grad: Gradients<'_>,
    sums: ColumnSums<'_>,
) {
    let n = grad.gx.len();
    let (above, here, below) = (&px.above[..n + 2], &px.here[..n + 2], &px.below[..n + 2]);
    let (smooth, diff) = (&mut scratch.smooth[..n + 2], &mut scratch.diff[..n + 2]);
    for i in 0..n + 2 {
        let (a, b, c) = (i16::from(above[i]), i16::from(here[i]), i16::from(below[i]));
        smooth[i] = a + 2 * b + c;
        diff[i] = c - a;
    }
    let (s_l, s_r) = (&smooth[..n], &smooth[2..n + 2]);
    let (d_l, d_c, d_r) = (&diff[..n], &diff[1..=n], &diff[2..n + 2]);
    let (gx, gy) = (&mut grad.gx[..n], &mut grad.gy[..n]);
    let (old_gx, old_gy) = (&grad.old_gx[..n], &grad.old_gy[..n]);
    let (col_xx, col_yy) = (&mut sums.xx[..n], &mut sums.yy[..n]);
    let (col_xy, col_tt) = (&mut sums.xy[..n], &mut sums.tt[..n]);
    for i in 0..n {
        // |gx|, |gy| <= 1020: 11 signed bits.
        let new_x = s_r[i] - s_l[i];
        let new_y = d_l[i] + 2 * d_c[i] + d_r[i];
        let (old_x, old_y) = (old_gx[i], old_gy[i]);
        // Column sums of 5 products: |sum| <= 5 * 2 * 1020^2 < 2^24. The squares change by
        // `new^2 - old^2 = (new - old)(new + old)`, factors within 12 signed bits: one
        // 16x16->32 bit multiply each instead of two.
        let dxx = i32::from(new_x - old_x) * i32::from(new_x + old_x);
        let dyy = i32::from(new_y - old_y) * i32::from(new_y + old_y);
        col_xx[i] += dxx;
        col_yy[i] += dyy;
        col_tt[i] += dxx + dyy;
        col_xy[i] += i32::from(new_x) * i32::from(new_y) - i32::from(old_x) * i32::from(old_y);
        gx[i] = new_x;
        gy[i] = new_y;
    }
}

/// ICD steps 2 and 3 decided cheaply: `flags[i] = 1` where the window trace (the 5-wide sum
/// of `col_tt[i ..= i + 4]`) reaches `trace_min`, so that the response may exceed the
/// threshold.
#[multiversion(targets("x86_64+avx512f+avx512bw+avx512vl", "x86_64+avx2"))]
pub(crate) fn may_exceed(col_tt: &[i32], trace_min: i32, flags: &mut [u8]) {
    let n = flags.len();
    let (t0, t1, t2, t3, t4) = taps(col_tt, n);
    for i in 0..n {
        flags[i] = u8::from(t0[i] + t1[i] + t2[i] + t3[i] + t4[i] >= trace_min);
    }
}

/// The chunks of [`CHUNK`] flags holding a non-zero flag, without branches.
pub(crate) fn chunks_with_flags(flags: &[u8]) -> ChunkSet {
    let mut set = ChunkSet::EMPTY;
    let mut chunks = flags.chunks_exact(CHUNK);
    for (j, chunk) in chunks.by_ref().enumerate() {
        let word = <[u8; CHUNK]>::try_from(chunk).map_or(1, u128::from_ne_bytes);
        set.insert_if(j, word != 0);
    }
    let rest = chunks.remainder();
    set.insert_if(flags.len() / CHUNK, rest.iter().any(|&f| f != 0));
    set
}

/// Column sums starting two columns left of the first pixel of a run.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Columns<'a> {
    pub(crate) xx: &'a [i32],
    pub(crate) yy: &'a [i32],
    pub(crate) xy: &'a [i32],
}

/// ICD steps 2 and 3 over a run of pixels: the 5x5 window sums from the column sums, and the
/// exact response.
#[multiversion(targets("x86_64+avx512f+avx512bw+avx512vl", "x86_64+avx2"))]
pub(crate) fn response_run(cols: Columns<'_>, out: &mut [i32]) {
    let n = out.len();
    let (xx0, xx1, xx2, xx3, xx4) = taps(cols.xx, n);
    let (yy0, yy1, yy2, yy3, yy4) = taps(cols.yy, n);
    let (xy0, xy1, xy2, xy3, xy4) = taps(cols.xy, n);
    for i in 0..n {
        let sxx = xx0[i] + xx1[i] + xx2[i] + xx3[i] + xx4[i];
        let syy = yy0[i] + yy1[i] + yy2[i] + yy3[i] + yy4[i];
        let sxy = xy0[i] + xy1[i] + xy2[i] + xy3[i] + xy4[i];
        out[i] = response(sxx, syy, sxy);
    }
}

/// `out[..] = value`, vectorised.
#[multiversion(targets("x86_64+avx512f+avx512bw+avx512vl", "x86_64+avx2"))]
pub(crate) fn fill(out: &mut [i32], value: i32) {
    for o in out.iter_mut() {
        *o = value;
    }
}

/// The five slices whose element-wise sum is the 5-wide box sum of `col` at `2 .. n + 2`.
type Taps<'a> = (&'a [i32], &'a [i32], &'a [i32], &'a [i32], &'a [i32]);

#[inline(always)]
fn taps(col: &[i32], n: usize) -> Taps<'_> {
    (
        &col[..n],
        &col[1..=n],
        &col[2..n + 2],
        &col[3..n + 3],
        &col[4..n + 4],
    )
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
