//! The row-streaming detector: the board's pipeline with line buffers only.
//!
//! Latency, as on the board: the gradients of row `y - 1` need pixel row `y`; the window sums
//! and response of row `c` need gradient rows `c - 2 ..= c + 2`, so pixel row `c + 3`; the
//! suppression and sub-pixel step of row `m` need responses `m - 1 ..= m + 1`. The features of
//! row `m` are therefore final, and returned, when pixel row `m + 4` is pushed. When the last
//! row is pushed every feature of the image has been returned.

use crate::kernels::{self, ColumnSums, Columns, Gradients, PixelRows, ResponseRows, SobelScratch};
use crate::{
    CANDIDATE_BORDER, Error, Feature, K_NUMERATOR, K_SHIFT, MAX_SIZE, RESPONSE_SHIFT, Registers,
    WINDOW_RADIUS, q4_coordinate, response, subpixel_offset,
};

/// Pixel rows held for the 3x3 Sobel (ICD step 1).
const PIXEL_ROWS: usize = 3;
/// Rows in the 5x5 window (ICD step 2).
const WINDOW_ROWS: usize = 2 * WINDOW_RADIUS + 1;
/// Gradient rows held: the window's five, and the one that just left it, from which the column
/// sums of the previous response row are rebuilt (see `late_exact`).
const GRADIENT_ROWS: usize = WINDOW_ROWS + 1;
/// Response rows held for the 3x3 suppression and sub-pixel step (ICD steps 5, 6).
const RESPONSE_ROWS: usize = 3;
/// First column (and row) where the window sums, and so the response, are defined (ICD step 2).
const RESPONSE_BORDER: usize = 1 + WINDOW_RADIUS;

/// A detector sized for the board's 752-pixel sensor.
pub type BoardStream = HarrisStream<{ crate::BOARD_WIDTH }>;

/// What the detector saw in one whole image.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ImageSummary {
    /// Features returned for this image (at most `MAX_FEATURES`).
    pub features: usize,
    /// The image had more than `MAX_FEATURES` features; the first `MAX_FEATURES` in raster order
    /// were returned (the camera's overflow flag in the wire format).
    pub overflow: bool,
}

/// Row-streaming Harris detector with fixed line buffers for images up to `MAX_WIDTH` wide.
///
/// The state is a few rows of each pipeline stage (`size_of::<BoardStream>()` is 51,336 bytes, about 50 KiB),
/// with no heap. Push the `HEIGHT` rows of an image in order with [`push_row`](Self::push_row);
/// each call returns the features that became final, in the board's raster order, already
/// limited to `MAX_FEATURES`. [`finish`](Self::finish) closes the image and readies the
/// detector for the next one.
#[derive(Clone)]
pub struct HarrisStream<const MAX_WIDTH: usize> {
    regs: Registers,
    /// Rows of the current image pushed so far.
    rows_in: usize,
    /// Features returned so far for the current image.
    emitted: usize,
    /// More than `MAX_FEATURES` features were found in the current image.
    overflow: bool,
    /// Image row of the response row computed by the last push, if any.
    last_response_row: Option<usize>,
    pixels: [[u8; MAX_WIDTH]; PIXEL_ROWS],
    gx: [[i16; MAX_WIDTH]; GRADIENT_ROWS],
    gy: [[i16; MAX_WIDTH]; GRADIENT_ROWS],
    /// Scratch rows of the separable Sobel (see `kernels::gradient_row`).
    smooth: [i16; MAX_WIDTH],
    diff: [i16; MAX_WIDTH],
    /// Column sums over the last five gradient rows of gx^2, gy^2, gx*gy and gx^2 + gy^2.
    col_xx: [i32; MAX_WIDTH],
    col_yy: [i32; MAX_WIDTH],
    col_xy: [i32; MAX_WIDTH],
    col_tt: [i32; MAX_WIDTH],
    /// Scratch flags of one row: pixels that may exceed the threshold, then local maxima.
    flags: [u8; MAX_WIDTH],
    /// Chunks of the last two response rows (ring by row parity) holding such a pixel.
    chunk_maybe: [ChunkSet; 2],
    /// Chunks of the last two response rows whose responses were computed exactly.
    chunk_exact: [ChunkSet; 2],
    /// Smallest trace `T = Sxx + Syy` whose response can exceed `THRESHOLD`.
    trace_min: i32,
    /// Responses of the last three rows: exact where it can matter, [`UNDECIDED`] elsewhere.
    responses: [[i32; MAX_WIDTH]; RESPONSE_ROWS],
    /// Features of the row that became final in the last push.
    row_features: [Feature; MAX_WIDTH],
}

impl<const MAX_WIDTH: usize> core::fmt::Debug for HarrisStream<MAX_WIDTH> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("HarrisStream")
            .field("max_width", &MAX_WIDTH)
            .field("regs", &self.regs)
            .field("rows_in", &self.rows_in)
            .field("emitted", &self.emitted)
            .field("overflow", &self.overflow)
            .finish_non_exhaustive()
    }
}

impl<const MAX_WIDTH: usize> HarrisStream<MAX_WIDTH> {
    /// A detector for images with the given registers.
    ///
    /// Fails when a register is outside the ICD's range or the width exceeds `MAX_WIDTH`.
    pub fn new(regs: Registers) -> Result<Self, Error> {
        Self::check(&regs)?;
        Ok(Self {
            regs,
            rows_in: 0,
            emitted: 0,
            overflow: false,
            last_response_row: None,
            pixels: [[0; MAX_WIDTH]; PIXEL_ROWS],
            gx: [[0; MAX_WIDTH]; GRADIENT_ROWS],
            gy: [[0; MAX_WIDTH]; GRADIENT_ROWS],
            smooth: [0; MAX_WIDTH],
            diff: [0; MAX_WIDTH],
            col_xx: [0; MAX_WIDTH],
            col_yy: [0; MAX_WIDTH],
            col_xy: [0; MAX_WIDTH],
            col_tt: [0; MAX_WIDTH],
            flags: [0; MAX_WIDTH],
            chunk_maybe: [ChunkSet::EMPTY; 2],
            chunk_exact: [ChunkSet::EMPTY; 2],
            trace_min: trace_min(regs.threshold),
            responses: [[0; MAX_WIDTH]; RESPONSE_ROWS],
            row_features: [Feature::default(); MAX_WIDTH],
        })
    }

    fn check(regs: &Registers) -> Result<(), Error> {
        regs.validate()?;
        if regs.width > MAX_WIDTH {
            return Err(Error::WidthExceedsCapacity {
                width: regs.width,
                capacity: MAX_WIDTH,
            });
        }
        Ok(())
    }

    /// The registers in force.
    pub fn registers(&self) -> Registers {
        self.regs
    }

    /// Changes the registers, as the host does between images, and starts a new image.
    pub fn set_registers(&mut self, regs: Registers) -> Result<(), Error> {
        Self::check(&regs)?;
        self.regs = regs;
        self.trace_min = trace_min(regs.threshold);
        self.reset();
        Ok(())
    }

    /// Rows of the current image pushed so far.
    pub fn rows_pushed(&self) -> usize {
        self.rows_in
    }

    /// Whether the current image has had more than `MAX_FEATURES` features so far.
    pub fn overflow(&self) -> bool {
        self.overflow
    }

    /// Drops the current image and starts a new one.
    pub fn reset(&mut self) {
        self.rows_in = 0;
        self.emitted = 0;
        self.overflow = false;
        self.last_response_row = None;
        // The gradient ring starts at zero so that the first five rows "subtract" nothing from
        // the column sums; see `gradient_row`.
        for row in self.gx.iter_mut().chain(self.gy.iter_mut()) {
            row.fill(0);
        }
        self.col_xx.fill(0);
        self.col_yy.fill(0);
        self.col_xy.fill(0);
        self.col_tt.fill(0);
        self.chunk_maybe = [ChunkSet::EMPTY; 2];
        self.chunk_exact = [ChunkSet::EMPTY; 2];
    }

    /// Closes the current image: checks that all rows arrived, reports the feature count and the
    /// overflow flag, and readies the detector for the next image.
    pub fn finish(&mut self) -> Result<ImageSummary, Error> {
        if self.rows_in != self.regs.height {
            return Err(Error::IncompleteImage {
                rows: self.rows_in,
                height: self.regs.height,
            });
        }
        let summary = ImageSummary {
            features: self.emitted,
            overflow: self.overflow,
        };
        self.reset();
        Ok(summary)
    }

    /// Makes every response exact, not only those that can matter for features, so that
    /// [`last_response_row`](Self::last_response_row) gives the whole response map.
    #[cfg(feature = "alloc")]
    pub(crate) fn compute_every_response(&mut self) {
        self.trace_min = 0;
    }

    /// The response row completed by the last [`push_row`](Self::push_row), with its image
    /// row: `r(x, y)` for `3 <= x <= WIDTH - 4`, zero left and right of that. Exact everywhere
    /// only after [`compute_every_response`](Self::compute_every_response).
    #[cfg(feature = "alloc")]
    pub(crate) fn last_response_row(&self) -> Option<(usize, &[i32])> {
        let y = self.last_response_row?;
        let row = self.responses.get(y % RESPONSE_ROWS)?;
        Some((y, row.get(..self.regs.width)?))
    }

    /// Pushes the next image row (`WIDTH` pixels) and returns the features that became final,
    /// in raster order, already limited to `MAX_FEATURES` for the image.
    pub fn push_row(&mut self, row: &[u8]) -> Result<&[Feature], Error> {
        let width = self.regs.width;
        let y = self.rows_in;
        if row.len() != width {
            return Err(Error::RowLength {
                row: y,
                expected: width,
                actual: row.len(),
            });
        }
        if y >= self.regs.height {
            return Err(Error::TooManyRows {
                height: self.regs.height,
            });
        }
        self.rows_in += 1;
        self.last_response_row = None;
        if self.overflow {
            // Every feature this image can still send has been sent and its flag is set.
            return Ok(&[]);
        }
        self.pixels[y % PIXEL_ROWS][..width].copy_from_slice(row);
        if y < 2 {
            return Ok(&[]);
        }
        let g = y - 1;
        self.gradient_row(g);
        if g < WINDOW_ROWS {
            return Ok(&[]);
        }
        let c = g - WINDOW_RADIUS;
        self.response_row(c);
        self.last_response_row = Some(c);
        if c < CANDIDATE_BORDER + 1 {
            return Ok(&[]);
        }
        let n = self.suppress_row(c - 1);
        Ok(&self.row_features[..n])
    }

    /// ICD steps 1 and 2 (vertical part): Sobel gradients of row `g` (from pixel rows
    /// `g - 1 ..= g + 1`) into the gradient ring, and the column sums moved down one row: the
    /// products of row `g - 5`, which leaves the window, subtracted, the new row's added.
    fn gradient_row(&mut self, g: usize) {
        let n = self.regs.width - 2; // gradient columns 1 ..= w - 2
        let px = PixelRows {
            above: &self.pixels[(g - 1) % PIXEL_ROWS],
            here: &self.pixels[g % PIXEL_ROWS],
            below: &self.pixels[(g + 1) % PIXEL_ROWS],
        };
        // Slot of row g - 5 (g + 1 = g - 5 mod 6); all zero while g - 5 < 1, so the first
        // five rows subtract nothing.
        let leaving = (g + 1) % GRADIENT_ROWS;
        let [gx_new, gx_old] = self
            .gx
            .get_disjoint_mut([g % GRADIENT_ROWS, leaving])
            .unwrap_or_else(|_| unreachable!("g and g + 1 differ mod 6"));
        let [gy_new, gy_old] = self
            .gy
            .get_disjoint_mut([g % GRADIENT_ROWS, leaving])
            .unwrap_or_else(|_| unreachable!("g and g + 1 differ mod 6"));
        let gradients = Gradients {
            gx: &mut gx_new[1..=n],
            gy: &mut gy_new[1..=n],
            old_gx: &gx_old[1..=n],
            old_gy: &gy_old[1..=n],
        };
        let sums = ColumnSums {
            xx: &mut self.col_xx[1..=n],
            yy: &mut self.col_yy[1..=n],
            xy: &mut self.col_xy[1..=n],
            tt: &mut self.col_tt[1..=n],
        };
        let scratch = SobelScratch {
            smooth: &mut self.smooth,
            diff: &mut self.diff,
        };
        kernels::gradient_row(px, scratch, gradients, sums);
    }

    /// ICD steps 2 (horizontal part) and 3 for row `c`, columns `3 ..= w - 4`: the response
    /// where it can matter.
    ///
    /// The exact response needs the three window sums and 64-bit products, but most pixels lie
    /// in flat regions whose response cannot reach the threshold: since `det <= T^2 / 4`,
    /// `Rs <= 215 T^2`, so a window trace `T < trace_min` proves `r <= THRESHOLD`, and the trace
    /// is one 5-wide sum of `col_tt`. Such a pixel can be neither a candidate nor beat one in
    /// suppression, so its response only matters when a direct neighbour's sub-pixel step
    /// reads it. The row is handled in chunks of [`CHUNK`] pixels: a chunk's responses are
    /// computed exactly when the chunk, a chunk beside it, or the same chunk of the row above
    /// holds a pixel that may exceed the threshold, and are left [`UNDECIDED`] otherwise. The
    /// row below is not known yet; when it turns out to need this row's values, they are
    /// computed then (see [`late_exact`](Self::late_exact)).
    fn response_row(&mut self, c: usize) {
        let w = self.regs.width;
        let range = RESPONSE_BORDER..w - RESPONSE_BORDER;
        let first_tap = RESPONSE_BORDER - WINDOW_RADIUS;
        let flags = &mut self.flags[range.clone()];
        kernels::may_exceed(&self.col_tt[first_tap..], self.trace_min, flags);
        let maybe = kernels::chunks_with_flags(flags);
        let needed = maybe.dilated().union(&self.chunk_maybe[(c + 1) % 2]);
        self.chunk_maybe[c % 2] = maybe;
        self.chunk_exact[c % 2] = needed;
        let out = &mut self.responses[c % RESPONSE_ROWS];
        for (start, end, exact) in needed.runs(range.clone()) {
            if exact {
                let cols = Columns {
                    xx: &self.col_xx[start - WINDOW_RADIUS..],
                    yy: &self.col_yy[start - WINDOW_RADIUS..],
                    xy: &self.col_xy[start - WINDOW_RADIUS..],
                };
                kernels::response_run(cols, &mut out[start..end]);
            } else {
                kernels::fill(&mut out[start..end], UNDECIDED);
            }
        }
        if c > RESPONSE_BORDER {
            self.late_exact(c - 1);
        }
    }

    /// Exact responses of the chunks of row `m` that were left undecided but that row `m + 1`
    /// needs (its vertical sub-pixel step reads `r(x, m)`). Row `m`'s column sums are rebuilt
    /// from the current ones, which cover gradient rows `m - 1 ..= m + 3`: minus the products
    /// of row `m + 3`, plus those of row `m - 2`, both still in the gradient ring.
    // `x` and `col` index five arrays at once; iterators would hide the window arithmetic.
    #[allow(clippy::needless_range_loop)]
    fn late_exact(&mut self, m: usize) {
        let range = RESPONSE_BORDER..self.regs.width - RESPONSE_BORDER;
        let late = self.chunk_maybe[(m + 1) % 2].minus(&self.chunk_exact[m % 2]);
        if late.is_empty() {
            return;
        }
        let (added, removed) = ((m + 3) % GRADIENT_ROWS, (m - 2) % GRADIENT_ROWS);
        let out = &mut self.responses[m % RESPONSE_ROWS];
        for (start, end, exact) in late.runs(range) {
            if !exact {
                continue;
            }
            for x in start..end {
                let (mut sxx, mut syy, mut sxy) = (0, 0, 0);
                for col in x - WINDOW_RADIUS..=x + WINDOW_RADIUS {
                    let (ax, ay) = (
                        i32::from(self.gx[added][col]),
                        i32::from(self.gy[added][col]),
                    );
                    let (rx, ry) = (
                        i32::from(self.gx[removed][col]),
                        i32::from(self.gy[removed][col]),
                    );
                    sxx += self.col_xx[col] - ax * ax + rx * rx;
                    syy += self.col_yy[col] - ay * ay + ry * ry;
                    sxy += self.col_xy[col] - ax * ay + rx * ry;
                }
                out[x] = response(sxx, syy, sxy);
            }
        }
    }

    /// ICD steps 4 to 7 for row `m`: candidates, 3x3 suppression with raster-order tie
    /// breaking, sub-pixel offsets and output, with the `MAX_FEATURES` cap. Returns how many
    /// features of `row_features` are this row's.
    ///
    /// Only chunks that may hold a candidate are scanned. A candidate's responses and those of
    /// its neighbours are exact (see [`response_row`](Self::response_row)), except neighbours
    /// known to be at most the threshold, which are [`UNDECIDED`] (below every response), so
    /// every comparison has the ICD's outcome.
    fn suppress_row(&mut self, m: usize) -> usize {
        let w = self.regs.width;
        let threshold = self.regs.threshold;
        let prev = &self.responses[(m - 1) % RESPONSE_ROWS];
        let cur = &self.responses[m % RESPONSE_ROWS];
        let next = &self.responses[(m + 1) % RESPONSE_ROWS];
        let candidates = CANDIDATE_BORDER..w - CANDIDATE_BORDER;
        let mut count = 0;
        for (start, end, maybe) in
            self.chunk_maybe[m % 2].runs(RESPONSE_BORDER..w - RESPONSE_BORDER)
        {
            let (start, end) = (start.max(candidates.start), end.min(candidates.end));
            if !maybe || start >= end {
                continue;
            }
            let rows = ResponseRows {
                prev: &prev[start - 1..=end],
                cur: &cur[start - 1..=end],
                next: &next[start - 1..=end],
            };
            let flags = &mut self.flags[start..end];
            kernels::local_maxima(rows, threshold, flags);
            for (word_start, word) in flags.chunks(8).enumerate() {
                if !any_set(word) {
                    continue;
                }
                for (i, _) in word.iter().enumerate().filter(|&(_, &f)| f != 0) {
                    let x = start + 8 * word_start + i;
                    if self.emitted == self.regs.max_features {
                        self.overflow = true;
                        return count;
                    }
                    let r = cur[x];
                    let ox = subpixel_offset(cur[x - 1], r, cur[x + 1]);
                    let oy = subpixel_offset(prev[x], r, next[x]);
                    self.row_features[count] = Feature {
                        x_q4: q4_coordinate(x, ox),
                        y_q4: q4_coordinate(m, oy),
                        r,
                    };
                    count += 1;
                    self.emitted += 1;
                }
            }
        }
        count
    }
}

/// Marks a response that was not computed because it is known to be at most `THRESHOLD`.
/// Every real response is above it (`r >= -41 T^2 / 2^27 > -2^30`).
const UNDECIDED: i32 = i32::MIN;

/// Pixels per chunk in the decisions of [`HarrisStream::response_row`].
pub(crate) const CHUNK: usize = 16;

/// Words of a [`ChunkSet`]: enough chunks for the widest image the ICD allows.
const CHUNK_WORDS: usize = MAX_SIZE.div_ceil(CHUNK * 64);

/// A set of chunk indices of one row, as a bitset.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct ChunkSet([u64; CHUNK_WORDS]);

impl ChunkSet {
    pub(crate) const EMPTY: Self = Self([0; CHUNK_WORDS]);

    /// Adds chunk `j` when `yes`, without a branch.
    pub(crate) fn insert_if(&mut self, j: usize, yes: bool) {
        if let Some(word) = self.0.get_mut(j / 64) {
            *word |= u64::from(yes) << (j % 64);
        }
    }

    fn is_empty(&self) -> bool {
        self.0.iter().all(|&w| w == 0)
    }

    /// The first chunk at or after `j` whose membership differs from chunk `j`'s.
    fn run_end(&self, j: usize) -> usize {
        let inside = self.contains(j);
        let mut k = j;
        while let Some(&word) = self.0.get(k / 64) {
            let word = if inside { !word } else { word };
            let rest = word >> (k % 64);
            if rest != 0 {
                return k + rest.trailing_zeros() as usize;
            }
            k = (k / 64 + 1) * 64;
        }
        k
    }

    fn contains(&self, j: usize) -> bool {
        self.0
            .get(j / 64)
            .is_some_and(|word| word >> (j % 64) & 1 != 0)
    }

    /// The set with each chunk's left and right neighbours added.
    fn dilated(&self) -> Self {
        let mut out = *self;
        for i in 0..CHUNK_WORDS {
            let carry_in_left = if i > 0 { self.0[i - 1] >> 63 } else { 0 };
            let carry_in_right = if i + 1 < CHUNK_WORDS {
                self.0[i + 1] << 63
            } else {
                0
            };
            out.0[i] |= (self.0[i] << 1) | carry_in_left | (self.0[i] >> 1) | carry_in_right;
        }
        out
    }

    fn union(&self, other: &Self) -> Self {
        let mut out = *self;
        for (a, b) in out.0.iter_mut().zip(other.0) {
            *a |= b;
        }
        out
    }

    fn minus(&self, other: &Self) -> Self {
        let mut out = *self;
        for (a, b) in out.0.iter_mut().zip(other.0) {
            *a &= !b;
        }
        out
    }

    /// The columns of `range`, chunk by chunk from `range.start`, as maximal runs
    /// `(start, end, in_set)` of chunks all in or all out of the set.
    fn runs(
        &self,
        range: core::ops::Range<usize>,
    ) -> impl Iterator<Item = (usize, usize, bool)> + '_ {
        let mut start = range.start;
        core::iter::from_fn(move || {
            if start >= range.end {
                return None;
            }
            let first = (start - range.start) / CHUNK;
            let inside = self.contains(first);
            let end = (range.start + self.run_end(first) * CHUNK).min(range.end);
            let run = (start, end, inside);
            start = end;
            Some(run)
        })
    }
}

/// Whether any flag in `flags` is set, tested eight flags at a time.
#[inline]
fn any_set(flags: &[u8]) -> bool {
    let mut words = flags.chunks_exact(8);
    let any = words
        .by_ref()
        .any(|w| <[u8; 8]>::try_from(w).map_or(1, u64::from_ne_bytes) != 0);
    any || words.remainder().iter().any(|&f| f != 0)
}

/// Smallest trace `T = Sxx + Syy` whose response can exceed `threshold`: `Rs <= 215 T^2`
/// (`det <= T^2 / 4`), and `r > threshold` needs `Rs >= (threshold + 1) 2^27`.
fn trace_min(threshold: i32) -> i32 {
    const RS_PER_TRACE_SQUARED: u64 = (1 << (K_SHIFT - 2)) - K_NUMERATOR; // 256 - 41 = 215
    let Ok(needed) = u64::try_from(i64::from(threshold) + 1) else {
        return 0; // threshold < 0: any trace may do
    };
    let needed = needed << RESPONSE_SHIFT; // < 2^59
    let mut t = (needed / RS_PER_TRACE_SQUARED).isqrt();
    while RS_PER_TRACE_SQUARED * t * t < needed {
        t += 1;
    }
    // t < 2^26 for every i32 threshold.
    i32::try_from(t).unwrap_or(i32::MAX)
}

#[cfg(test)]
mod tests {
    //! The private machinery of the lazy responses: the trace bound and the chunk bitsets.
    //! (Whole-detector behaviour is tested against the reference in `tests/`.)

    use super::*;

    /// `215 T^2` against `(threshold + 1) 2^27`, in 128 bits so the test cannot overflow.
    fn bound(t: i64) -> i128 {
        215 * i128::from(t) * i128::from(t)
    }

    fn needed(threshold: i32) -> i128 {
        (i128::from(threshold) + 1) << 27
    }

    /// `trace_min` is the smallest trace whose response can exceed the threshold: below it
    /// `Rs <= 215 T^2 < (threshold + 1) 2^27`, so `r <= threshold` (sound); at it the bound
    /// reaches the threshold (minimal, so no chunk is left undecided without need).
    #[test]
    fn trace_min_is_sound_and_minimal() {
        let check = |threshold: i32| {
            let t = trace_min(threshold);
            if threshold < 0 {
                assert_eq!(t, 0, "threshold {threshold}: any trace may exceed it");
                return;
            }
            let t = i64::from(t);
            assert!((1..1 << 26).contains(&t), "threshold {threshold}: {t}");
            assert!(
                bound(t - 1) < needed(threshold),
                "threshold {threshold}: {t} is not sound"
            );
            assert!(
                bound(t) >= needed(threshold),
                "threshold {threshold}: {t} is not minimal"
            );
        };
        for threshold in [
            i32::MIN,
            -1_000_000,
            -2,
            -1,
            0,
            1,
            2,
            1000,
            (1 << 18) - 1,
            1 << 18,
            (1 << 18) + 1,
            1 << 24,
            1 << 30,
            i32::MAX - 1,
            i32::MAX,
        ] {
            check(threshold);
        }
        // A deterministic xorshift sweep of the whole range.
        let mut x: u32 = 0x1234_5678;
        for _ in 0..4000 {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            check(x.cast_signed());
            check((x >> 8).cast_signed());
        }
    }

    /// The best case of the bound, `Sxx = Syy = T / 2`, `Sxy = 0`: just below `trace_min` it
    /// does not exceed the threshold; at `trace_min` (rounded up to even) it does. (Not for
    /// thresholds near `i32::MAX`, whose `trace_min` lies beyond any image's traces, where
    /// this best case is no image's and its `r` would not fit in 32 bits.)
    #[test]
    fn trace_min_against_the_response() {
        for threshold in [0, 1, 5000, 1 << 18, 1 << 20, 1 << 28, 1 << 29] {
            let t = trace_min(threshold);
            let below = t - 1;
            assert!(
                response(below / 2, below - below / 2, 0) <= threshold,
                "{threshold}"
            );
            let even = t + t % 2;
            assert!(response(even / 2, even / 2, 0) > threshold, "{threshold}");
        }
    }

    fn set_of(chunks: &[usize]) -> ChunkSet {
        let mut set = ChunkSet::EMPTY;
        for &j in chunks {
            set.insert_if(j, true);
        }
        set
    }

    fn members(set: &ChunkSet) -> impl Iterator<Item = usize> + '_ {
        (0..CHUNK_WORDS * 64).filter(|&j| set.contains(j))
    }

    #[test]
    fn chunk_set_basics() {
        let mut set = ChunkSet::EMPTY;
        assert!(set.is_empty());
        set.insert_if(5, false);
        assert!(set.is_empty());
        set.insert_if(5, true);
        set.insert_if(64, true);
        set.insert_if(255, true);
        // Beyond the widest image: ignored, never a panic.
        set.insert_if(CHUNK_WORDS * 64, true);
        set.insert_if(usize::MAX, true);
        assert!(members(&set).eq([5, 64, 255]));
        assert!(!set.contains(CHUNK_WORDS * 64) && !set.contains(usize::MAX));
        let other = set_of(&[5, 63, 200]);
        assert!(members(&set.union(&other)).eq([5, 63, 64, 200, 255]));
        assert!(members(&set.minus(&other)).eq([64, 255]));
        assert!(set.minus(&set).is_empty());
    }

    /// Dilation adds each chunk's neighbours, also across the 64-bit words (chunks 63/64,
    /// 127/128, 191/192) and at both ends.
    #[test]
    fn chunk_set_dilation_crosses_words() {
        let cases: [(&[usize], &[usize]); 7] = [
            (&[0], &[0, 1]),
            (&[63], &[62, 63, 64]),
            (&[64], &[63, 64, 65]),
            (&[127, 128], &[126, 127, 128, 129]),
            (&[191], &[190, 191, 192]),
            (&[255], &[254, 255]),
            (&[10, 12], &[9, 10, 11, 12, 13]),
        ];
        for (input, expected) in cases {
            assert!(
                members(&set_of(input).dilated()).eq(expected.iter().copied()),
                "{input:?}"
            );
        }
        assert!(ChunkSet::EMPTY.dilated().is_empty());
    }

    /// `runs` partitions the range into maximal runs of chunks in or out of the set, chunk
    /// boundaries counted from `range.start`, the last chunk partial.
    #[test]
    fn chunk_set_runs_partition_the_range() {
        let check = |set: &ChunkSet, range: core::ops::Range<usize>| {
            let mut next = range.start;
            let mut last_inside = None;
            for (start, end, inside) in set.runs(range.clone()) {
                assert_eq!(start, next, "runs are contiguous");
                assert!(start < end && end <= range.end);
                assert_ne!(Some(inside), last_inside, "runs are maximal");
                for x in start..end {
                    assert_eq!(
                        set.contains((x - range.start) / CHUNK),
                        inside,
                        "column {x}"
                    );
                }
                next = end;
                last_inside = Some(inside);
            }
            assert_eq!(next, range.end, "runs cover the range");
        };
        let sets = [
            ChunkSet::EMPTY,
            set_of(&[0]),
            set_of(&[1, 2, 3]),
            set_of(&[63, 64]),
            set_of(&[62, 65, 127, 128, 200]),
            set_of(&[255]),
            ChunkSet([u64::MAX; CHUNK_WORDS]),
            set_of(&[0, 2, 4, 6]).dilated(),
        ];
        for set in &sets {
            for range in [
                3..13,
                3..19,
                3..20,
                3..4089,
                3..4092,
                3..3 + 16 * 64 + 1,
                3..749,
            ] {
                check(set, range);
            }
        }
        assert_eq!(ChunkSet::EMPTY.runs(3..3).count(), 0);
    }

    /// `chunks_with_flags` sets a chunk when any of its (up to) 16 flags is set, including the
    /// last partial chunk.
    #[test]
    fn chunks_with_flags_sees_every_flag() {
        let mut flags = [0u8; 4089];
        for len in [10, 16, 17, 31, 32, 33, 1025, 4089] {
            for i in [0, 15, 16, len / 2, len - 1]
                .into_iter()
                .filter(|&i| i < len)
            {
                flags[..len].fill(0);
                flags[i] = 1;
                let set = kernels::chunks_with_flags(&flags[..len]);
                assert!(members(&set).eq([i / CHUNK]), "len {len} flag {i}");
            }
            flags[..len].fill(0);
            assert!(kernels::chunks_with_flags(&flags[..len]).is_empty());
        }
    }

    #[test]
    fn any_set_sees_every_flag() {
        let mut flags = [0u8; 21];
        for len in 0..=21 {
            assert!(!any_set(&flags[..len]));
            for i in 0..len {
                flags[i] = 1;
                assert!(any_set(&flags[..len]), "len {len} flag {i}");
                flags[i] = 0;
            }
        }
    }

    /// The undecided marker is below every response the ICD allows (`r >= -41 T^2 / 2^27`
    /// with `T <= 2 * 26,010,000`), so comparisons against it always go the ICD's way.
    #[test]
    fn undecided_is_below_every_response() {
        let t = 2 * 26_010_000i64;
        let lowest = (-41 * t * t) >> 27;
        assert!(i64::from(UNDECIDED) < lowest, "{lowest}");
        assert!(response(26_010_000, 0, 0) > UNDECIDED);
    }
}
