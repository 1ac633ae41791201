//! The saved map as the localiser holds it: every lamp with its covariance, and a uniform grid
//! over the floor plan so that the lamps near a pose are found in time independent of the
//! map's size.

use alloc::vec::Vec;

use nalgebra::{Matrix3, Matrix3x4, Matrix4, Vector3};

use crate::error::Error;

/// One lamp of the map, in the map's world frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MapLamp {
    /// The landmark id of the run that made the map (`SUMMARY.json`'s ids).
    pub id: u64,
    /// Position, metres.
    pub position: Vector3<f64>,
    /// Covariance of the position, m^2 (the mapping run's marginal; cross-covariances between
    /// lamps are not used: see [`crate::filter`]).
    pub covariance: Matrix3<f64>,
}

/// The error the map's lamps share: a small rigid motion `d = (tx, ty, tz, yaw)` of the whole
/// map about `origin`, with covariance `covariance` (the mapping run's drift of its frame).
/// A lamp at `p` moves by `A(p) d`, [`CommonError::jacobian`]. It does not average out over
/// the lamps in view: a pose found from the map's lamps moves with the map. The filter works
/// in the map's frame (the lamps' errors relative to it); the localiser adds the common part
/// to the pose covariance it reports ([`CommonError::pose_covariance`]), so that the reported
/// sigma is the pose's uncertainty in the world the map was made in.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CommonError {
    /// The point the yaw turns about, `(x, y)`, metres.
    pub origin: (f64, f64),
    /// Covariance of `(tx, ty, tz, yaw)`.
    pub covariance: Matrix4<f64>,
}

impl CommonError {
    /// The covariance the common error adds to a planar pose at `(x, y)`: the pose moves with
    /// the map, `(x, y, theta)` by `J d`, `J = [[1, 0, 0, -(y - o.y)], [0, 1, 0, x - o.x],
    /// [0, 0, 0, 1]]`.
    pub fn pose_covariance(&self, x: f64, y: f64) -> Matrix3<f64> {
        let (ox, oy) = self.origin;
        let j = Matrix3x4::new(
            1.0,
            0.0,
            0.0,
            -(y - oy),
            0.0,
            1.0,
            0.0,
            x - ox,
            0.0,
            0.0,
            0.0,
            1.0,
        );
        j * self.covariance * j.transpose()
    }

    /// `A(p)`: how a lamp at `p` moves with `(tx, ty, tz, yaw)`.
    pub fn jacobian(&self, p: &Vector3<f64>) -> Matrix3x4<f64> {
        let (ox, oy) = self.origin;
        Matrix3x4::new(
            1.0,
            0.0,
            0.0,
            -(p.y - oy),
            0.0,
            1.0,
            0.0,
            p.x - ox,
            0.0,
            0.0,
            1.0,
            0.0,
        )
    }
}

/// A triangle of lamps for relocalisation, its vertices in canonical order: the side opposite
/// vertex `k` is the `k`-th shortest (horizontal lengths).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct LampTriangle {
    /// The sorted side lengths' bins packed (`q2 << 20 | q1 << 10 | q0`), the index's sort key.
    pub key: u32,
    /// The three lamps (indices into the map), canonical order.
    pub lamps: [u32; 3],
    /// The sides opposite them, metres (ascending): the look-up's first, cheap test.
    pub sides: [f32; 3],
}

/// A height level of the map: lamps hung at one height (high-bay lamps), or at another
/// (sprinkler heads, beam corners). Relocalisation projects what a frame sees onto each level.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Level {
    /// Mean height of its lamps, metres.
    pub z: f64,
    /// Largest distance of one of its lamps from `z`, metres.
    pub spread: f64,
}

/// The lamp map with its spatial index.
///
/// The index is a uniform grid of square cells over the lamps' bounding box in `(x, y)`:
/// lamps within a radius of a point are found by visiting the cells the circle overlaps, so a
/// query costs the lamps near the point, whatever the map's size. A hand-written grid rather
/// than a k-d tree crate: the lamps are spread evenly over a floor, queries are discs of one
/// radius, and it is a few dozen lines that stay `no_std`.
#[derive(Debug, Clone)]
pub struct LampMap {
    lamps: Vec<MapLamp>,
    cell_m: f64,
    origin: (f64, f64),
    cols: usize,
    rows: usize,
    /// Start of each cell's run in `cell_lamps` (`cols * rows + 1` entries).
    cell_start: Vec<u32>,
    cell_lamps: Vec<u32>,
    /// Every triangle of lamps with sides in `[triangle_min_side_m, triangle_max_side_m]`,
    /// sorted by key.
    triangles: Vec<LampTriangle>,
    triangle_min_side_m: f64,
    triangle_max_side_m: f64,
    footprint_m: f64,
    levels: Vec<Level>,
    /// Each lamp's level (index into `levels`).
    lamp_level: Vec<u8>,
    common: Option<CommonError>,
}

impl LampMap {
    /// Cells of the index, metres on a side.
    pub const CELL_M: f64 = 2.0;

    /// Most cells the index may have: a map spread wider than this many cells gets larger
    /// cells (a 10,000-lamp hall of 250 m x 100 m has 6,250 of 2 m).
    const MAX_CELLS: usize = 1 << 20;

    /// Shortest side of an indexed triangle at most, metres: shorter sides give poor
    /// headings (and the four corners of an LED panel would fill the index with tiny
    /// triangles). A map whose lamps are closer (the paper's five LEDs, 0.65 m apart) gets
    /// half its median nearest-neighbour distance, at least [`Self::TRIANGLE_MIN_SIDE_FLOOR_M`].
    pub const TRIANGLE_MIN_SIDE_M: f64 = 1.0;

    /// See [`Self::TRIANGLE_MIN_SIDE_M`].
    pub const TRIANGLE_MIN_SIDE_FLOOR_M: f64 = 0.25;

    /// Bin of the triangles' side lengths in the index's key, metres.
    pub const TRIANGLE_BIN_M: f64 = 0.1;

    /// Lamps a triangle's longest side reaches on average: the longest side indexed is the
    /// radius of a disc holding this many lamps at the map's mean density (about 20 triangles
    /// a lamp; enough that the lamps in one frame's view form several), unless the footprint
    /// is smaller or the map has fewer than four times this many lamps (then the footprint).
    pub const TRIANGLE_NEIGHBOURS: f64 = 16.0;

    /// Lamps further apart in height than this are on different levels, metres.
    pub const LEVEL_GAP_M: f64 = 0.15;

    /// Most height levels: a map whose heights fall into more is one level with their spread.
    pub const MAX_LEVELS: usize = 3;

    /// Indexes `lamps`. `footprint_m` is the largest horizontal distance of two lamps that
    /// one frame can show: no triangle of the relocalisation's index is wider.
    ///
    /// Errors: no lamps, a non-finite position or covariance, or a covariance that is not
    /// symmetric positive semi-definite on its diagonal.
    pub fn new(lamps: Vec<MapLamp>, footprint_m: f64) -> Result<Self, Error> {
        if lamps.is_empty() {
            return Err(Error::EmptyMap);
        }
        if lamps.len() > u32::MAX as usize / 2 {
            return Err(Error::MapTooLarge { lamps: lamps.len() });
        }
        for l in &lamps {
            if !(l.position.iter().all(|v| v.is_finite())
                && l.covariance.iter().all(|v| v.is_finite())
                && (0..3).all(|i| l.covariance[(i, i)] >= 0.0))
            {
                return Err(Error::BadLamp { id: l.id });
            }
        }
        let (mut x0, mut y0, mut x1, mut y1) = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
        for l in &lamps {
            x0 = x0.min(l.position.x);
            y0 = y0.min(l.position.y);
            x1 = x1.max(l.position.x);
            y1 = y1.max(l.position.y);
        }
        let mut cell_m = Self::CELL_M;
        let (cols, rows) = loop {
            #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
            let (c, r) = (
                ((x1 - x0) / cell_m) as usize + 1,
                ((y1 - y0) / cell_m) as usize + 1,
            );
            if c.saturating_mul(r) <= Self::MAX_CELLS {
                break (c, r);
            }
            cell_m *= 2.0;
        };
        let mut map = Self {
            lamps,
            cell_m,
            origin: (x0, y0),
            cols,
            rows,
            cell_start: Vec::new(),
            cell_lamps: Vec::new(),
            triangles: Vec::new(),
            triangle_min_side_m: Self::TRIANGLE_MIN_SIDE_M,
            triangle_max_side_m: 0.0,
            footprint_m: if footprint_m.is_finite() {
                footprint_m.max(0.0)
            } else {
                0.0
            },
            levels: Vec::new(),
            lamp_level: Vec::new(),
            common: None,
        };
        map.build_cells();
        map.build_levels();
        map.build_triangles((x1 - x0).max(1.0) * (y1 - y0).max(1.0));
        Ok(map)
    }

    fn cell_of(&self, x: f64, y: f64) -> (i64, i64) {
        #[allow(clippy::cast_possible_truncation)]
        (
            libm::floor((x - self.origin.0) / self.cell_m) as i64,
            libm::floor((y - self.origin.1) / self.cell_m) as i64,
        )
    }

    fn build_cells(&mut self) {
        let n_cells = self.cols * self.rows;
        let mut counts = alloc::vec![0_u32; n_cells + 1];
        let cells: Vec<usize> = self
            .lamps
            .iter()
            .map(|l| {
                let (cx, cy) = self.cell_of(l.position.x, l.position.y);
                #[allow(clippy::cast_sign_loss, clippy::cast_possible_truncation)]
                let (cx, cy) = (
                    (cx.max(0) as usize).min(self.cols - 1),
                    (cy.max(0) as usize).min(self.rows - 1),
                );
                cy * self.cols + cx
            })
            .collect();
        for &c in &cells {
            if let Some(n) = counts.get_mut(c + 1) {
                *n += 1;
            }
        }
        for i in 1..counts.len() {
            let before = counts.get(i - 1).copied().unwrap_or(0);
            if let Some(n) = counts.get_mut(i) {
                *n += before;
            }
        }
        let mut fill = counts.clone();
        let mut cell_lamps = alloc::vec![0_u32; self.lamps.len()];
        for (i, &c) in cells.iter().enumerate() {
            if let Some(slot) = fill.get_mut(c) {
                if let Some(out) = cell_lamps.get_mut(*slot as usize) {
                    #[allow(clippy::cast_possible_truncation)] // checked in new
                    {
                        *out = i as u32;
                    }
                }
                *slot += 1;
            }
        }
        self.cell_start = counts;
        self.cell_lamps = cell_lamps;
    }

    /// Groups the lamps' heights into levels: sorted, split where two neighbours in height are
    /// more than [`Self::LEVEL_GAP_M`] apart; more than [`Self::MAX_LEVELS`] groups make one
    /// level with the whole spread.
    fn build_levels(&mut self) {
        let mut order: Vec<u32> = (0..self.lamps.len())
            .map(|i| u32::try_from(i).unwrap_or(u32::MAX))
            .collect();
        let z = |i: u32| self.lamps.get(i as usize).map_or(0.0, |l| l.position.z);
        order.sort_by(|&a, &b| z(a).total_cmp(&z(b)));
        let mut groups: Vec<(usize, usize)> = Vec::new(); // [start, end) in `order`
        let mut start = 0;
        for k in 1..=order.len() {
            let split = match (order.get(k - 1), order.get(k)) {
                (Some(&a), Some(&b)) => z(b) - z(a) > Self::LEVEL_GAP_M,
                _ => true,
            };
            if split {
                groups.push((start, k));
                start = k;
            }
        }
        if groups.len() > Self::MAX_LEVELS {
            groups = alloc::vec![(0, order.len())];
        }
        let mut lamp_level = alloc::vec![0_u8; self.lamps.len()];
        let mut levels = Vec::with_capacity(groups.len());
        for (g, &(s, e)) in groups.iter().enumerate() {
            let members = order.get(s..e).unwrap_or_default();
            #[allow(clippy::cast_precision_loss)]
            let mean = members.iter().map(|&i| z(i)).sum::<f64>() / members.len().max(1) as f64;
            let spread = members
                .iter()
                .map(|&i| libm::fabs(z(i) - mean))
                .fold(0.0, f64::max);
            for &i in members {
                if let Some(l) = lamp_level.get_mut(i as usize) {
                    *l = u8::try_from(g).unwrap_or(0);
                }
            }
            levels.push(Level { z: mean, spread });
        }
        self.levels = levels;
        self.lamp_level = lamp_level;
    }

    /// The median over the lamps (at most 1,000 of them, evenly picked) of the horizontal
    /// distance to the nearest other lamp, metres (searched out to 16 m; `INFINITY` for a
    /// single lamp).
    fn median_spacing(&self) -> f64 {
        let step = (self.lamps.len() / 1000).max(1);
        let mut near = Vec::new();
        let mut d: Vec<f64> = Vec::new();
        for (i, l) in self.lamps.iter().enumerate().step_by(step) {
            let mut r = 1.0;
            while r <= 16.0 {
                self.within(l.position.x, l.position.y, r, &mut near);
                let nearest = near
                    .iter()
                    .filter(|&&j| j as usize != i)
                    .filter_map(|&j| self.lamps.get(j as usize))
                    .map(|m| horizontal(&l.position, &m.position))
                    .fold(f64::INFINITY, f64::min);
                if nearest.is_finite() {
                    d.push(nearest);
                    break;
                }
                r *= 2.0;
            }
        }
        d.sort_by(f64::total_cmp);
        d.get(d.len() / 2).copied().unwrap_or(f64::INFINITY)
    }

    /// Indexes every triangle of lamps whose sides are between the shortest side ([`Self::TRIANGLE_MIN_SIDE_M`])
    /// and the longest side (see [`Self::TRIANGLE_NEIGHBOURS`]; `area` the lamps' bounding
    /// box, m^2), sorted by the key of its sorted side lengths: a frame's triangle finds the
    /// map's triangles of its shape by a few binary searches, whatever the map's size
    /// (geometric hashing with a sorted table instead of a hash map: `no_std`, compact, and
    /// ranges of one bin come out contiguous).
    fn build_triangles(&mut self, area: f64) {
        #[allow(clippy::cast_precision_loss)]
        let density = self.lamps.len() as f64 / area;
        let by_density = libm::sqrt(Self::TRIANGLE_NEIGHBOURS / (core::f64::consts::PI * density));
        let min_side = (0.5 * self.median_spacing())
            .clamp(Self::TRIANGLE_MIN_SIDE_FLOOR_M, Self::TRIANGLE_MIN_SIDE_M);
        // A small map (a few dozen lamps) is indexed out to the footprint: its triangles are
        // few whatever their size, and its lamps' spread says little about a density.
        #[allow(clippy::cast_precision_loss)]
        let small = (self.lamps.len() as f64) < 4.0 * Self::TRIANGLE_NEIGHBOURS;
        let max_side = if small {
            self.footprint_m
        } else {
            by_density.min(self.footprint_m)
        }
        .max(2.0 * min_side);
        self.triangle_min_side_m = min_side;
        self.triangle_max_side_m = max_side;
        let (lo, hi) = (min_side, max_side);
        let mut triangles = Vec::new();
        let mut near = Vec::new();
        let mut later: Vec<(u32, Vector3<f64>)> = Vec::new();
        for (i, l) in self.lamps.iter().enumerate() {
            let Ok(i) = u32::try_from(i) else {
                break;
            };
            self.within(l.position.x, l.position.y, hi, &mut near);
            later.clear();
            for &j in &near {
                if j <= i {
                    continue;
                }
                if let Some(m) = self.lamps.get(j as usize) {
                    let d = horizontal(&l.position, &m.position);
                    if d >= lo {
                        later.push((j, m.position));
                    }
                }
            }
            for (a, &(j, pj)) in later.iter().enumerate() {
                for &(k, pk) in later.get(a + 1..).unwrap_or_default() {
                    let d = horizontal(&pj, &pk);
                    if d < lo || d > hi {
                        continue;
                    }
                    triangles.push(canonical([i, j, k], [l.position, pj, pk]));
                }
            }
        }
        triangles.sort_unstable_by_key(|t| t.key);
        self.triangles = triangles;
    }

    /// Takes `common` as the error the lamps share ([`crate::Localizer`] adds it to the pose
    /// covariance it reports). Errors: a non-finite or asymmetric common covariance.
    pub fn with_common_error(mut self, common: CommonError) -> Result<Self, Error> {
        let c = common.covariance;
        if !(c.iter().all(|v| v.is_finite())
            && common.origin.0.is_finite()
            && common.origin.1.is_finite()
            && (c - c.transpose()).amax() <= 1e-9 * c.amax().max(f64::MIN_POSITIVE))
        {
            return Err(Error::BadCommonError);
        }
        self.common = Some(common);
        Ok(self)
    }

    /// The error the lamps share, when the map gave one.
    pub fn common_error(&self) -> Option<CommonError> {
        self.common
    }

    /// The lamps, in the order they were given.
    pub fn lamps(&self) -> &[MapLamp] {
        &self.lamps
    }

    /// Lamp `i`.
    pub fn lamp(&self, i: u32) -> Option<&MapLamp> {
        self.lamps.get(i as usize)
    }

    /// Number of lamps.
    pub fn len(&self) -> usize {
        self.lamps.len()
    }

    /// Whether the map has no lamps (never: [`LampMap::new`] refuses an empty one).
    pub fn is_empty(&self) -> bool {
        self.lamps.is_empty()
    }

    /// The lamps within `radius` of `(x, y)` horizontally, into `out` (cleared first), by index.
    pub fn within(&self, x: f64, y: f64, radius: f64, out: &mut Vec<u32>) {
        out.clear();
        let (ax, ay) = self.cell_of(x - radius, y - radius);
        let (bx, by) = self.cell_of(x + radius, y + radius);
        let cols = i64::try_from(self.cols).unwrap_or(i64::MAX);
        let rows = i64::try_from(self.rows).unwrap_or(i64::MAX);
        let r2 = radius * radius;
        for cy in ay.max(0)..=by.min(rows - 1) {
            for cx in ax.max(0)..=bx.min(cols - 1) {
                #[allow(clippy::cast_sign_loss, clippy::cast_possible_truncation)]
                let cell = (cy as usize) * self.cols + cx as usize;
                let (Some(&s), Some(&e)) =
                    (self.cell_start.get(cell), self.cell_start.get(cell + 1))
                else {
                    continue;
                };
                for &i in self
                    .cell_lamps
                    .get(s as usize..e as usize)
                    .unwrap_or_default()
                {
                    if let Some(l) = self.lamps.get(i as usize) {
                        let (dx, dy) = (l.position.x - x, l.position.y - y);
                        if dx * dx + dy * dy <= r2 {
                            out.push(i);
                        }
                    }
                }
            }
        }
    }

    /// The nearest lamp to `(x, y)` horizontally within `radius`, with its distance.
    pub fn nearest(
        &self,
        x: f64,
        y: f64,
        radius: f64,
        scratch: &mut Vec<u32>,
    ) -> Option<(u32, f64)> {
        self.within(x, y, radius, scratch);
        scratch
            .iter()
            .filter_map(|&i| {
                self.lamps
                    .get(i as usize)
                    .map(|l| (i, libm::hypot(l.position.x - x, l.position.y - y)))
            })
            .min_by(|a, b| a.1.total_cmp(&b.1))
    }

    /// The indexed triangles whose sorted side lengths are each within `tol` of `sides`
    /// (sorted ascending), into `out`; `false` (and `out` cut)
    /// when there are more than `cap`: the shape is too common in this map to tell places
    /// apart (a regular grid).
    pub(crate) fn triangles_near(
        &self,
        sides: [f64; 3],
        tol: f64,
        out: &mut Vec<LampTriangle>,
        cap: usize,
    ) -> bool {
        out.clear();
        let range = |s: f64| (side_bin(s - tol), side_bin(s + tol));
        let [s0, s1, s2] = sides;
        let ((a0, b0), (a1, b1), (a2, b2)) = (range(s0), range(s1), range(s2));
        for q2 in a2..=b2 {
            for q1 in a1..=b1 {
                let (lo, hi) = (pack(a0, q1, q2), pack(b0, q1, q2));
                let s = self.triangles.partition_point(|t| t.key < lo);
                let e = self.triangles.partition_point(|t| t.key <= hi);
                let run = self.triangles.get(s..e.max(s)).unwrap_or_default();
                for t in run {
                    let near = t
                        .sides
                        .iter()
                        .zip(sides.iter())
                        .all(|(&a, &b)| libm::fabs(f64::from(a) - b) <= tol + 1e-4);
                    if near {
                        if out.len() >= cap {
                            return false;
                        }
                        out.push(*t);
                    }
                }
            }
        }
        true
    }

    /// Number of triangles held for relocalisation.
    pub fn triangle_count(&self) -> usize {
        self.triangles.len()
    }

    /// The shortest side of an indexed triangle, metres ([`Self::TRIANGLE_MIN_SIDE_M`]).
    pub fn triangle_min_side_m(&self) -> f64 {
        self.triangle_min_side_m
    }

    /// The longest side of an indexed triangle, metres.
    pub fn triangle_max_side_m(&self) -> f64 {
        self.triangle_max_side_m
    }

    /// The map's height levels.
    pub(crate) fn levels(&self) -> &[Level] {
        &self.levels
    }

    /// The level of lamp `i`.
    pub(crate) fn level_of(&self, i: u32) -> Option<usize> {
        self.lamp_level.get(i as usize).map(|&l| usize::from(l))
    }

    /// Mean lamp height, metres.
    pub fn mean_height(&self) -> f64 {
        #[allow(clippy::cast_precision_loss)]
        let n = self.lamps.len() as f64;
        self.lamps.iter().map(|l| l.position.z).sum::<f64>() / n
    }

    /// Highest lamp, metres.
    pub fn max_height(&self) -> f64 {
        self.lamps
            .iter()
            .map(|l| l.position.z)
            .fold(f64::MIN, f64::max)
    }
}

/// Horizontal distance of two points.
pub(crate) fn horizontal(a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
    libm::hypot(a.x - b.x, a.y - b.y)
}

/// The bin of a side length in the triangle index's key (clamped to the key's 10 bits).
fn side_bin(s: f64) -> u32 {
    let q = libm::floor(s / LampMap::TRIANGLE_BIN_M);
    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)] // clamped
    if q.is_finite() {
        q.clamp(0.0, 1023.0) as u32
    } else {
        0
    }
}

/// The key of sorted side bins.
fn pack(q0: u32, q1: u32, q2: u32) -> u32 {
    (q2 << 20) | (q1 << 10) | q0
}

/// The sides of the triangle `p` opposite each vertex: `[|p1 p2|, |p0 p2|, |p0 p1|]`.
pub(crate) fn opposite_sides(p: &[Vector3<f64>; 3]) -> [f64; 3] {
    let [a, b, c] = p;
    [horizontal(b, c), horizontal(a, c), horizontal(a, b)]
}

/// The triangle of lamps `ids` at `p` in canonical order (ascending opposite sides), with its
/// key.
fn canonical(ids: [u32; 3], p: [Vector3<f64>; 3]) -> LampTriangle {
    let sides = opposite_sides(&p);
    let mut order = [0_usize, 1, 2];
    order.sort_by(|&a, &b| {
        let sa = sides.get(a).copied().unwrap_or(0.0);
        let sb = sides.get(b).copied().unwrap_or(0.0);
        sa.total_cmp(&sb)
    });
    let side = |k: usize| sides.get(k).copied().unwrap_or(0.0);
    let id = |k: usize| ids.get(k).copied().unwrap_or(0);
    let [o0, o1, o2] = order;
    #[allow(clippy::cast_possible_truncation)] // a first test; the exact one is in f64
    LampTriangle {
        key: pack(side_bin(side(o0)), side_bin(side(o1)), side_bin(side(o2))),
        lamps: [id(o0), id(o1), id(o2)],
        sides: [side(o0) as f32, side(o1) as f32, side(o2) as f32],
    }
}

#[cfg(test)]
#[allow(clippy::indexing_slicing, clippy::unwrap_used)]
mod tests {
    use super::*;

    fn grid(nx: usize, ny: usize, d: f64) -> Vec<MapLamp> {
        let mut out = Vec::new();
        for iy in 0..ny {
            for ix in 0..nx {
                #[allow(clippy::cast_precision_loss)]
                out.push(MapLamp {
                    id: (iy * nx + ix) as u64,
                    position: Vector3::new(ix as f64 * d, iy as f64 * d, 7.0),
                    covariance: Matrix3::identity() * 1e-6,
                });
            }
        }
        out
    }

    #[test]
    fn a_disc_query_finds_exactly_the_lamps_inside_it() {
        let map = LampMap::new(grid(30, 20, 2.5), 8.0).unwrap();
        let mut out = Vec::new();
        for &(x, y, r) in &[
            (10.0, 10.0, 6.0),
            (-3.0, -3.0, 5.0),
            (70.0, 45.0, 3.0),
            (37.0, 20.0, 0.1),
        ] {
            map.within(x, y, r, &mut out);
            let mut brute: Vec<u32> = (0..map.len() as u32)
                .filter(|&i| {
                    let p = map.lamp(i).unwrap().position;
                    libm::hypot(p.x - x, p.y - y) <= r
                })
                .collect();
            out.sort_unstable();
            brute.sort_unstable();
            assert_eq!(out, brute, "query ({x}, {y}, {r})");
        }
    }

    #[test]
    fn the_triangles_are_every_triangle_within_the_sides_and_a_shape_finds_its_own() {
        let mut lamps = grid(12, 9, 2.5);
        // Jitter, so that the shapes differ.
        for (k, l) in lamps.iter_mut().enumerate() {
            let k = k as f64;
            l.position.x += 0.3 * libm::sin(1.7 * k);
            l.position.y += 0.3 * libm::cos(2.3 * k);
        }
        let map = LampMap::new(lamps, 8.0).unwrap();
        let (lo, hi) = (map.triangle_min_side_m(), map.triangle_max_side_m());
        assert!(hi > 2.5 && hi <= 8.0, "{hi}");
        let n = map.len() as u32;
        let d = |i: u32, j: u32| {
            horizontal(
                &map.lamp(i).unwrap().position,
                &map.lamp(j).unwrap().position,
            )
        };
        let ok = |s: f64| s >= lo && s <= hi;
        let mut brute = 0;
        for i in 0..n {
            for j in i + 1..n {
                for k in j + 1..n {
                    if ok(d(i, j)) && ok(d(j, k)) && ok(d(i, k)) {
                        brute += 1;
                    }
                }
            }
        }
        assert_eq!(map.triangle_count(), brute);
        // Lamps 13, 14 and 26: found by their own sides, in canonical order.
        let p = [13_u32, 14, 26].map(|i| map.lamp(i).unwrap().position);
        let mut sides = opposite_sides(&p);
        sides.sort_by(f64::total_cmp);
        let mut out = Vec::new();
        assert!(map.triangles_near(sides, 0.02, &mut out, 1000));
        let found = out
            .iter()
            .find(|t| {
                let mut l = t.lamps;
                l.sort_unstable();
                l == [13, 14, 26]
            })
            .unwrap();
        let q = found.lamps.map(|i| map.lamp(i).unwrap().position);
        let s = opposite_sides(&q);
        assert!(s[0] <= s[1] && s[1] <= s[2]);
        // A cap smaller than the shape's matches says so.
        assert!(!map.triangles_near(sides, 1.0, &mut out, 3));
    }

    #[test]
    fn heights_fall_into_levels() {
        let mut lamps = grid(6, 4, 3.0);
        for (k, l) in lamps.iter_mut().enumerate() {
            l.position.z = if k % 2 == 0 {
                7.0 + 0.01 * (k % 5) as f64
            } else {
                6.6
            };
        }
        let map = LampMap::new(lamps, 8.0).unwrap();
        assert_eq!(map.levels().len(), 2);
        assert!((map.levels()[0].z - 6.6).abs() < 1e-12);
        assert!(map.levels()[1].spread <= 0.04 + 1e-12);
        assert_eq!(map.level_of(1), Some(0));
        assert_eq!(map.level_of(0), Some(1));
    }

    #[test]
    fn an_empty_map_or_a_nan_lamp_is_refused() {
        assert!(matches!(
            LampMap::new(Vec::new(), 5.0),
            Err(Error::EmptyMap)
        ));
        let mut g = grid(2, 2, 1.0);
        g[3].position.z = f64::NAN;
        assert!(matches!(
            LampMap::new(g, 5.0),
            Err(Error::BadLamp { id: 3 })
        ));
    }
}
