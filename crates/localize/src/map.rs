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

/// Pairs of lamps by their horizontal distance, for relocalisation: every pair closer than the
/// widest constellation one frame can see.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct LampPair {
    /// Horizontal distance, metres.
    pub distance: f64,
    /// The two lamps (indices into the map), `a < b`.
    pub a: u32,
    /// See `a`.
    pub b: u32,
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
    pairs: Vec<LampPair>,
    pair_radius_m: f64,
    common: Option<CommonError>,
}

impl LampMap {
    /// Cells of the index, metres on a side.
    pub const CELL_M: f64 = 2.0;

    /// Most cells the index may have: a map spread wider than this many cells gets larger
    /// cells (a 10,000-lamp hall of 250 m x 100 m has 6,250 of 2 m).
    const MAX_CELLS: usize = 1 << 20;

    /// Indexes `lamps`. `pair_radius_m` is the largest horizontal distance of two lamps that
    /// one frame can show (the relocalisation's pairs).
    ///
    /// Errors: no lamps, a non-finite position or covariance, or a covariance that is not
    /// symmetric positive semi-definite on its diagonal.
    pub fn new(lamps: Vec<MapLamp>, pair_radius_m: f64) -> Result<Self, Error> {
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
            pairs: Vec::new(),
            pair_radius_m: pair_radius_m.max(0.0),
            common: None,
        };
        map.build_cells();
        map.build_pairs();
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

    fn build_pairs(&mut self) {
        let mut pairs = Vec::new();
        let r = self.pair_radius_m;
        let mut near = Vec::new();
        for (i, l) in self.lamps.iter().enumerate() {
            self.within(l.position.x, l.position.y, r, &mut near);
            for &j in &near {
                if (j as usize) <= i {
                    continue;
                }
                let Some(m) = self.lamps.get(j as usize) else {
                    continue;
                };
                let d = libm::hypot(m.position.x - l.position.x, m.position.y - l.position.y);
                #[allow(clippy::cast_possible_truncation)] // checked in new
                pairs.push(LampPair {
                    distance: d,
                    a: i as u32,
                    b: j,
                });
            }
        }
        pairs.sort_by(|p, q| p.distance.total_cmp(&q.distance));
        self.pairs = pairs;
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

    /// The pairs of lamps whose horizontal distance is within `[lo, hi]`.
    pub(crate) fn pairs_between(&self, lo: f64, hi: f64) -> &[LampPair] {
        let s = self.pairs.partition_point(|p| p.distance < lo);
        let e = self.pairs.partition_point(|p| p.distance <= hi);
        self.pairs.get(s..e.max(s)).unwrap_or_default()
    }

    /// Number of pairs held for relocalisation.
    pub fn pair_count(&self) -> usize {
        self.pairs.len()
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
    fn pairs_are_every_pair_within_the_radius_sorted_by_distance() {
        let map = LampMap::new(grid(6, 5, 2.5), 5.1).unwrap();
        let n = map.len();
        let mut brute = 0;
        for i in 0..n {
            for j in i + 1..n {
                let (a, b) = (map.lamps()[i].position, map.lamps()[j].position);
                if libm::hypot(a.x - b.x, a.y - b.y) <= 5.1 {
                    brute += 1;
                }
            }
        }
        assert_eq!(map.pair_count(), brute);
        let p = map.pairs_between(3.5, 3.6);
        assert!(!p.is_empty() && p.iter().all(|q| (q.distance - 3.5355).abs() < 1e-3));
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
