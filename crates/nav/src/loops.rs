//! Loops closed by the lamps' constellation (issue 35, item 2).
//!
//! After a long stretch without lamps the pose is metres uncertain: a returning lamp's
//! landmark is one of several inside its gate (lamps are a grid a few metres apart), and a
//! lamp mapped from the lost pose would tell the filter where it is (the EKF's spurious
//! information along unobservable directions: Huang, Mourikis and Roumeliotis, ICRA 2008). So
//! while lost the navigator maps nothing: the lamps it sees are [`Held`], each triangulated in
//! every frame it is seen in and averaged, in the world of the dead-reckoned pose, where they
//! are precise *relative to each other* (dead reckoning is good over seconds).
//!
//! [`constellation`] recognises the place: the planar rigid motion (a rotation about the
//! vertical and a translation) that lays at least [`MIN_PAIRS`] held lamps onto landmarks
//! within their tolerances, heights agreeing, and lays no more than one in
//! [`MAX_CONFLICT_SHARE`] a jitter away from a landmark (on a grid laid one spacing off most
//! lamps are such conflicts; laid right, a held lamp that is no landmark is a new lamp, a lamp
//! spacing from any). It answers only when that motion is unique: another motion laying a
//! different set of nearly as many pairs ([`MARGIN_PAIRS`]) means the place is ambiguous and
//! nothing is closed yet. The navigator then updates the filter with the pairs' held lamps as
//! points relative to the vehicle (`vslam_ekf::Ekf::update_relative`, iterated from where the
//! motion puts the vehicle), so the pose, the map and the vehicle's parameters move with
//! their covariances, and maps the other held lamps from where they were held
//! (`vslam_ekf::Ekf::add_landmark_relative`).

use alloc::collections::BTreeMap;
use alloc::vec::Vec;

use nalgebra::{Matrix3, Vector3};
use vslam_ekf::LandmarkId;

/// Pairs a loop closure needs at least.
pub const MIN_PAIRS: usize = 5;

/// A competing motion (one laying a different set of pairs) must have this many pairs fewer
/// than the best for the best to count as unique.
pub const MARGIN_PAIRS: usize = 2;

/// How far a lamp laid by the motion may lie from its old landmark, horizontally, metres, at
/// most: well below a jittered grid's irregularity (0.3 m in the halls). Each pair's own
/// tolerance is three sigma of the held lamp's averaged position and the landmark's
/// ([`OLD_SIGMA_M`]), between [`MIN_TOLERANCE_M`] and this.
pub const PAIR_TOLERANCE_M: f64 = 0.15;

/// A candidate the motion lays this near an old landmark, but outside its tolerance, is a
/// conflict ([`conflicts`]), metres: well above the tolerance, well below a lamp spacing.
pub const CONFLICT_RADIUS_M: f64 = 0.8;

/// A motion with more than one conflict for this many pairs is not considered.
pub const MAX_CONFLICT_SHARE: usize = 4;

/// The smallest pair tolerance, metres.
pub const MIN_TOLERANCE_M: f64 = 0.05;

/// How far the heights of a pair may differ at most, metres (the height does not drift with
/// the pose; a single frame's triangulation is a few decimetres uncertain in height).
pub const HEIGHT_TOLERANCE_M: f64 = 0.3;

/// An old landmark's position sigma relative to its neighbours assumed by the tolerances,
/// metres (the map's landmarks are a few centimetres apart from the truth, most of it shared).
pub const OLD_SIGMA_M: f64 = 0.03;

/// The lever dead reckoning's heading error acts on between two held lamps seen at
/// different times, metres: about a ceiling camera's footprint.
pub const SPREAD_M: f64 = 5.0;

/// A held lamp takes part in the constellation once triangulated in this many frames.
pub const MIN_FRAMES: u32 = 8;

/// A held lamp not seen for this many frames leaves the constellation (dead reckoning is
/// good over seconds, not over the whole stretch); it is still mapped when the loop closes,
/// its covariance grown by the dead reckoning since.
pub const MAX_AGE_FRAMES: u64 = 200;

/// Recent landmarks tried as the motion's defining pairs at most (the best observed first):
/// `O(k^2 c^2)` motions for `c` candidates each.
const MAX_DEFINING: usize = 12;

/// A held lamp relative to the vehicle ([`Held::relative`]).
#[derive(Debug, Clone, Copy)]
pub struct Relative {
    /// Its position from the vehicle: x ahead, y left, the world height, metres.
    pub position: Vector3<f64>,
    /// The covariance of `position`, m^2.
    pub covariance: Matrix3<f64>,
}

/// A lamp seen now and the older landmarks it could be.
#[derive(Debug, Clone)]
pub struct Candidate {
    /// The caller's key for the lamp (a track).
    pub key: u64,
    /// Its position.
    pub position: Vector3<f64>,
    /// How far the motion may lay it from an old landmark, horizontally, metres.
    pub tolerance: f64,
    /// How far its height may be from an old landmark's, metres.
    pub height_tolerance: f64,
    /// Older landmarks it could be, with their positions.
    pub olds: Vec<(LandmarkId, Vector3<f64>)>,
}

impl Candidate {
    /// A candidate whose tolerances are three sigma of its position's covariance and of
    /// [`OLD_SIGMA_M`], within [`MIN_TOLERANCE_M`] and the maxima.
    pub fn new(
        key: u64,
        position: Vector3<f64>,
        covariance: &Matrix3<f64>,
        olds: Vec<(LandmarkId, Vector3<f64>)>,
    ) -> Self {
        let old = OLD_SIGMA_M * OLD_SIGMA_M;
        let horizontal = covariance[(0, 0)].max(covariance[(1, 1)]);
        let tol = |v: f64, max: f64| {
            let t = 3.0 * libm::sqrt(v + old);
            if t.is_finite() {
                t.clamp(MIN_TOLERANCE_M, max)
            } else {
                max
            }
        };
        Self {
            key,
            position,
            tolerance: tol(horizontal, PAIR_TOLERANCE_M),
            height_tolerance: tol(covariance[(2, 2)], HEIGHT_TOLERANCE_M),
            olds,
        }
    }
}

/// What [`constellation`] found.
#[derive(Debug, Clone, PartialEq)]
pub enum Found {
    /// One motion lays these `(key, old)` pairs onto each other; no other motion lays a
    /// different set of nearly as many ([`MARGIN_PAIRS`]).
    Unique {
        /// The pairs.
        pairs: Vec<(u64, LandmarkId)>,
        /// The motion refitted to them: `(angle, tx, ty)`, `p -> R(angle) p + t`.
        motion: (f64, f64, f64),
    },
    /// Several motions fit different sets: the place is ambiguous.
    Ambiguous,
    /// No motion lays [`MIN_PAIRS`] pairs.
    None,
}

/// A planar rigid motion `p -> R(angle) p + t` (z unchanged).
#[derive(Debug, Clone, Copy)]
struct Motion {
    cos: f64,
    sin: f64,
    tx: f64,
    ty: f64,
}

impl Motion {
    fn apply(&self, p: &Vector3<f64>) -> (f64, f64) {
        (
            self.cos * p.x - self.sin * p.y + self.tx,
            self.sin * p.x + self.cos * p.y + self.ty,
        )
    }

    /// The motion taking `a1 -> b1` and the direction `a1 a2` onto `b1 b2`, if the two
    /// horizontal distances agree within the tolerance.
    fn from_pairs(
        a1: &Vector3<f64>,
        a2: &Vector3<f64>,
        b1: &Vector3<f64>,
        b2: &Vector3<f64>,
        tolerance: f64,
    ) -> Option<Self> {
        let (dax, day) = (a2.x - a1.x, a2.y - a1.y);
        let (dbx, dby) = (b2.x - b1.x, b2.y - b1.y);
        let (la, lb) = (libm::hypot(dax, day), libm::hypot(dbx, dby));
        if la < 2.0 * PAIR_TOLERANCE_M || (la - lb).abs() > tolerance {
            return None;
        }
        let angle = libm::atan2(dby, dbx) - libm::atan2(day, dax);
        let (sin, cos) = (libm::sin(angle), libm::cos(angle));
        // The midpoints laid onto each other (errors shared between the two pairs).
        let (max, may) = ((a1.x + a2.x) / 2.0, (a1.y + a2.y) / 2.0);
        let (mbx, mby) = ((b1.x + b2.x) / 2.0, (b1.y + b2.y) / 2.0);
        Some(Self {
            cos,
            sin,
            tx: mbx - (cos * max - sin * may),
            ty: mby - (sin * max + cos * may),
        })
    }

    fn angle(&self) -> f64 {
        libm::atan2(self.sin, self.cos)
    }

    /// The least-squares motion laying the points `a` onto `b` (the planar Procrustes
    /// solution), if there are two or more.
    fn fit(a: &[(f64, f64)], b: &[(f64, f64)]) -> Option<Self> {
        let n = a.len();
        if n < 2 || b.len() != n {
            return None;
        }
        let mean = |p: &[(f64, f64)]| {
            let (sx, sy) = p.iter().fold((0.0, 0.0), |(x, y), q| (x + q.0, y + q.1));
            (sx / n as f64, sy / n as f64)
        };
        let (ma, mb) = (mean(a), mean(b));
        let (mut c, mut s) = (0.0, 0.0);
        for (p, q) in a.iter().zip(b) {
            let (ax, ay) = (p.0 - ma.0, p.1 - ma.1);
            let (bx, by) = (q.0 - mb.0, q.1 - mb.1);
            c += ax * bx + ay * by;
            s += ax * by - ay * bx;
        }
        let angle = libm::atan2(s, c);
        let (sin, cos) = (libm::sin(angle), libm::cos(angle));
        Some(Self {
            cos,
            sin,
            tx: mb.0 - (cos * ma.0 - sin * ma.1),
            ty: mb.1 - (sin * ma.0 + cos * ma.1),
        })
    }
}

/// The motion refitted to every pair it lays (least squares).
fn refit(candidates: &[Candidate], pairs: &[(u64, LandmarkId)]) -> Option<Motion> {
    let mut a = Vec::with_capacity(pairs.len());
    let mut b = Vec::with_capacity(pairs.len());
    for (key, old) in pairs {
        let c = candidates.iter().find(|c| c.key == *key)?;
        let (_, p) = c.olds.iter().find(|(id, _)| id == old)?;
        a.push((c.position.x, c.position.y));
        b.push((p.x, p.y));
    }
    Motion::fit(&a, &b)
}

/// The pairs the motion lays onto each other: for each candidate the old landmark nearest to
/// where the motion puts it, within the tolerances, each old landmark once.
fn support(candidates: &[Candidate], m: &Motion) -> Vec<(u64, LandmarkId)> {
    let mut pairs: Vec<(u64, LandmarkId)> = Vec::new();
    for c in candidates {
        let (x, y) = m.apply(&c.position);
        let best = c
            .olds
            .iter()
            .filter(|(_, p)| (p.z - c.position.z).abs() <= c.height_tolerance)
            .map(|(id, p)| (*id, libm::hypot(p.x - x, p.y - y)))
            .filter(|(_, d)| *d <= c.tolerance)
            .min_by(|a, b| a.1.total_cmp(&b.1));
        if let Some((old, _)) = best
            && !pairs.iter().any(|(_, o)| *o == old)
        {
            pairs.push((c.key, old));
        }
    }
    pairs
}

/// The candidates the motion lays near an old landmark but outside their tolerance: lamps
/// that would have to be new lamps within [`CONFLICT_RADIUS_M`] of a mapped one. On a grid
/// laid one spacing off, most candidates are such conflicts (the grid's jitter apart); laid
/// right, the candidates that are not old landmarks are new lamps, a lamp spacing from any.
fn conflicts(candidates: &[Candidate], m: &Motion) -> usize {
    candidates
        .iter()
        .filter(|c| {
            let (x, y) = m.apply(&c.position);
            let nearest = c
                .olds
                .iter()
                .map(|(_, p)| libm::hypot(p.x - x, p.y - y))
                .fold(f64::INFINITY, f64::min);
            nearest > c.tolerance && nearest < CONFLICT_RADIUS_M
        })
        .count()
}

/// The unique constellation match of the recent landmarks onto older ones (module docs);
/// motions rotating by more than `max_rotation` radians are not considered.
pub fn constellation(candidates: &[Candidate], max_rotation: f64) -> Found {
    let with_olds: Vec<&Candidate> = candidates.iter().filter(|c| !c.olds.is_empty()).collect();
    if with_olds.len() < MIN_PAIRS {
        return Found::None;
    }
    let defining: Vec<&Candidate> = with_olds.iter().copied().take(MAX_DEFINING).collect();
    let mut found: Vec<Vec<(u64, LandmarkId)>> = Vec::new();
    for (i, c1) in defining.iter().enumerate() {
        for c2 in defining.iter().skip(i + 1) {
            for (o1, p1) in &c1.olds {
                for (o2, p2) in &c2.olds {
                    if o1 == o2 {
                        continue;
                    }
                    let tolerance = c1.tolerance + c2.tolerance;
                    let Some(m) = Motion::from_pairs(&c1.position, &c2.position, p1, p2, tolerance)
                    else {
                        continue;
                    };
                    if m.angle().abs() > max_rotation {
                        continue;
                    }
                    let mut pairs = support(candidates, &m);
                    if pairs.len() < MIN_PAIRS - 1 {
                        continue;
                    }
                    // Refitted to all its pairs, the motion may lay more (or fewer).
                    if let Some(r) = refit(candidates, &pairs)
                        && r.angle().abs() <= max_rotation
                    {
                        let refitted = support(candidates, &r);
                        if refitted.len() >= pairs.len() {
                            pairs = refitted;
                        }
                    }
                    if pairs.len() < MIN_PAIRS - 1 {
                        continue;
                    }
                    let laid = refit(candidates, &pairs).unwrap_or(m);
                    if conflicts(candidates, &laid) * MAX_CONFLICT_SHARE > pairs.len() {
                        continue;
                    }
                    pairs.sort();
                    if !found.contains(&pairs) {
                        found.push(pairs);
                    }
                }
            }
        }
    }
    // Motions whose pairs are all among another's are the same place seen from fewer lamps;
    // a competitor lays a pair the best does not, and nearly as many.
    let largest = found.iter().map(Vec::len).max().unwrap_or(0);
    if largest < MIN_PAIRS {
        return Found::None;
    }
    let Some(best) = found.iter().find(|p| p.len() == largest) else {
        return Found::None;
    };
    let competing = found
        .iter()
        .any(|p| p.len() + MARGIN_PAIRS > largest && p.iter().any(|pair| !best.contains(pair)));
    if competing {
        return Found::Ambiguous;
    }
    match refit(candidates, best) {
        Some(m) => Found::Unique {
            pairs: best.clone(),
            motion: (m.angle(), m.tx, m.ty),
        },
        None => Found::None,
    }
}

/// The lamps held out of the map while the pose is lost, each averaged over the frames it
/// was triangulated in, in the world of the dead-reckoned pose (which the filter's prediction
/// alone moves while nothing is bound, so the held lamps stay precise relative to each other).
#[derive(Debug, Clone, Default)]
pub struct Held {
    lamps: BTreeMap<u64, HeldLamp>,
    /// Dead reckoning's variance accumulated so far: position (the sum over both axes, m^2)
    /// and heading (rad^2), from the odometry increments' covariances.
    odometry_position_var: f64,
    odometry_heading_var: f64,
    /// The latest frame a lamp was added in.
    frame: u64,
}

#[derive(Debug, Clone)]
struct HeldLamp {
    /// The sum of the triangulations' information matrices.
    information: Matrix3<f64>,
    /// The sum of information times position.
    weighted: Vector3<f64>,
    frames: u32,
    last_frame: u64,
    /// The camera's share of one triangulation's covariance (the latest), common to all.
    systematic: Matrix3<f64>,
    /// [`Held`]'s odometry variances when the lamp was last seen.
    position_var_then: f64,
    heading_var_then: f64,
}

impl Held {
    /// Nothing held.
    pub fn new() -> Self {
        Self::default()
    }

    /// Lamps held.
    pub fn len(&self) -> usize {
        self.lamps.len()
    }

    /// Whether nothing is held.
    pub fn is_empty(&self) -> bool {
        self.lamps.is_empty()
    }

    /// Forgets every held lamp (the pose is found again, or a new stretch begins).
    pub fn clear(&mut self) {
        self.lamps.clear();
    }

    /// Adds one frame's triangulation of a held lamp (its position and covariance in the
    /// world of the current pose estimate, the pose's own uncertainty left out; the camera's
    /// share of it, `systematic`, apart: it is common to every frame). A covariance that
    /// cannot be inverted is ignored.
    pub fn add(
        &mut self,
        key: u64,
        position: Vector3<f64>,
        covariance: &Matrix3<f64>,
        systematic: &Matrix3<f64>,
        frame: u64,
    ) {
        let Some(information) = covariance.try_inverse() else {
            return;
        };
        if !(information.iter().all(|v| v.is_finite()) && position.iter().all(|v| v.is_finite())) {
            return;
        }
        let lamp = self.lamps.entry(key).or_insert_with(|| HeldLamp {
            information: Matrix3::zeros(),
            weighted: Vector3::zeros(),
            frames: 0,
            last_frame: frame,
            systematic: Matrix3::zeros(),
            position_var_then: 0.0,
            heading_var_then: 0.0,
        });
        lamp.information += information;
        lamp.weighted += information * position;
        lamp.frames += 1;
        lamp.last_frame = frame;
        if systematic.iter().all(|v| v.is_finite()) {
            lamp.systematic = *systematic;
        }
        lamp.position_var_then = self.odometry_position_var;
        lamp.heading_var_then = self.odometry_heading_var;
        self.frame = frame;
    }

    /// Whether a lamp was seen recently enough to take part in the constellation.
    fn recent(&self, lamp: &HeldLamp) -> bool {
        self.frame.saturating_sub(lamp.last_frame) <= MAX_AGE_FRAMES
    }

    /// One frame's odometry increment (its covariance, `(dx, dy, dtheta)`): what dead
    /// reckoning adds to the error of a held lamp relative to the vehicle.
    pub fn add_motion(&mut self, covariance: &Matrix3<f64>) {
        let (p, h) = (covariance[(0, 0)] + covariance[(1, 1)], covariance[(2, 2)]);
        if p.is_finite() && h.is_finite() && p >= 0.0 && h >= 0.0 {
            self.odometry_position_var += p;
            self.odometry_heading_var += h;
        }
    }

    /// The held lamps of `pairs` as points relative to the vehicle at `pose`
    /// ([`Held::relative`]) for the filter's update ([`vslam_ekf::Ekf::update_relative`]).
    /// Pairs whose lamp is not held are left out.
    pub fn relative_observations(
        &self,
        pairs: &[(u64, LandmarkId)],
        pose: &rig_model::camera::Pose2,
    ) -> Vec<(u64, vslam_ekf::RelativeObservation)> {
        pairs
            .iter()
            .filter_map(|&(key, id)| {
                let r = self.relative(key, pose)?;
                Some((
                    key,
                    vslam_ekf::RelativeObservation {
                        id,
                        position: r.position,
                        covariance: r.covariance,
                    },
                ))
            })
            .collect()
    }

    /// A held lamp relative to the vehicle at `pose` (the dead-reckoned pose it was
    /// triangulated with): its averaged position carried into the vehicle's frame (x ahead,
    /// y left, the world height), and its covariance: the average's, plus the camera's share
    /// (common to every frame, so not averaged away), plus dead reckoning's since the lamp was
    /// last seen (the odometry's position variance, and its heading variance times the lamp's
    /// distance squared).
    pub fn relative(&self, key: u64, pose: &rig_model::camera::Pose2) -> Option<Relative> {
        let (s, c) = (libm::sin(pose.theta), libm::cos(pose.theta));
        let rot = Matrix3::new(c, s, 0.0, -s, c, 0.0, 0.0, 0.0, 1.0);
        let lamp = self.lamps.get(&key)?;
        let covariance = lamp.information.try_inverse()?;
        let world = covariance * lamp.weighted;
        let d = Vector3::new(world.x - pose.x, world.y - pose.y, world.z);
        let (dp, dh) = self.drift_since(lamp);
        let horizontal = dp + dh * (d.x * d.x + d.y * d.y);
        let world_cov = covariance
            + lamp.systematic
            + Matrix3::from_diagonal(&Vector3::new(horizontal, horizontal, 0.0));
        Some(Relative {
            position: rot * d,
            covariance: rot * world_cov * rot.transpose(),
        })
    }

    /// Every held lamp: its key, averaged position (the dead-reckoned world) and the frames it
    /// was seen in.
    pub fn positions(&self) -> Vec<(u64, Vector3<f64>, u32)> {
        self.lamps
            .iter()
            .filter_map(|(&k, l)| Some((k, l.information.try_inverse()? * l.weighted, l.frames)))
            .collect()
    }

    /// The held lamps seen in [`MIN_FRAMES`] frames or more.
    pub fn mature_keys(&self) -> Vec<u64> {
        self.lamps
            .iter()
            .filter(|(_, l)| l.frames >= MIN_FRAMES)
            .map(|(&k, _)| k)
            .collect()
    }

    /// Dead reckoning's variance added since a lamp was last seen: position (per axis, m^2)
    /// and heading (rad^2).
    fn drift_since(&self, lamp: &HeldLamp) -> (f64, f64) {
        (
            (self.odometry_position_var - lamp.position_var_then).max(0.0) / 2.0,
            (self.odometry_heading_var - lamp.heading_var_then).max(0.0),
        )
    }

    /// Held lamps seen in [`MIN_FRAMES`] frames or more, the last within [`MAX_AGE_FRAMES`]
    /// (those the constellation takes).
    pub fn mature(&self) -> usize {
        self.lamps
            .values()
            .filter(|l| l.frames >= MIN_FRAMES && self.recent(l))
            .count()
    }

    /// The held lamps seen in [`MIN_FRAMES`] frames or more as constellation candidates, the
    /// most often seen first: each with the landmarks of `map` it could be, those within
    /// `reach(position)` of it horizontally (the lost pose's uncertainty carried to the lamp)
    /// and [`HEIGHT_TOLERANCE_M`] in height.
    pub fn candidates(
        &self,
        map: &[(LandmarkId, Vector3<f64>)],
        reach: impl Fn(&Vector3<f64>) -> f64,
    ) -> Vec<Candidate> {
        let mut out: Vec<(u32, Candidate)> = self
            .lamps
            .iter()
            .filter(|(_, l)| l.frames >= MIN_FRAMES && self.recent(l))
            .filter_map(|(&key, l)| {
                let averaged = l.information.try_inverse()?;
                let position = averaged * l.weighted;
                // Dead reckoning since the lamp was seen moves it against the lamps seen now.
                let (dp, dh) = self.drift_since(l);
                let horizontal = dp + dh * (SPREAD_M * SPREAD_M);
                let covariance = averaged
                    + l.systematic
                    + Matrix3::from_diagonal(&Vector3::new(horizontal, horizontal, 0.0));
                let r = reach(&position);
                let olds = map
                    .iter()
                    .filter(|(_, p)| {
                        (p.z - position.z).abs() <= HEIGHT_TOLERANCE_M
                            && libm::hypot(p.x - position.x, p.y - position.y) <= r
                    })
                    .copied()
                    .collect();
                Some((l.frames, Candidate::new(key, position, &covariance, olds)))
            })
            .collect();
        out.sort_by_key(|(frames, _)| core::cmp::Reverse(*frames));
        out.into_iter().map(|(_, c)| c).collect()
    }
}

#[cfg(test)]
#[allow(clippy::indexing_slicing, clippy::unwrap_used)]
mod tests {
    use super::*;

    /// Lamps on a jittered 3 m grid (8 columns `i`, 6 rows `j`, lamp `6 i + j`).
    fn grid(jitter: f64) -> Vec<(LandmarkId, Vector3<f64>)> {
        let mut lamps = Vec::new();
        for i in 0..8u64 {
            for j in 0..6u64 {
                // A fixed pseudo-random jitter in [-0.5, 0.5) (splitmix64 of the lamp).
                let unit = |k: u64| {
                    let mut z = k.wrapping_add(0x9e37_79b9_7f4a_7c15);
                    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
                    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
                    (z ^ (z >> 31)) as f64 / u64::MAX as f64 - 0.5
                };
                let (h, g) = (unit(2 * (6 * i + j)), unit(2 * (6 * i + j) + 1));
                lamps.push((
                    LandmarkId(6 * i + j),
                    Vector3::new(
                        3.0 * i as f64 + jitter * h,
                        3.0 * j as f64 + jitter * g,
                        7.0,
                    ),
                ));
            }
        }
        lamps
    }

    /// The `held` lamps as the drifted pose saw them (the drift `(0.06 rad, 2.1 m, -1.4 m)`
    /// undone by the motion found), each with the `mapped` landmarks within `reach` as the
    /// ones it could be; the true pairs among them.
    fn scene(
        jitter: f64,
        reach: f64,
        held: &[u64],
        mapped: impl Fn(u64) -> bool,
    ) -> (Vec<Candidate>, Vec<(u64, LandmarkId)>) {
        let lamps = grid(jitter);
        let map: Vec<(LandmarkId, Vector3<f64>)> = lamps
            .iter()
            .copied()
            .filter(|(id, _)| mapped(id.0))
            .collect();
        let (angle, tx, ty) = (0.06f64, 2.1, -1.4);
        let (s, c) = (libm::sin(angle), libm::cos(angle));
        let mut candidates = Vec::new();
        let mut truth = Vec::new();
        for &(old, p) in lamps.iter().filter(|(id, _)| held.contains(&id.0)) {
            let (x, y) = (p.x - tx, p.y - ty);
            let position = Vector3::new(c * x + s * y, -s * x + c * y, p.z + 0.01);
            let olds = map
                .iter()
                .filter(|(_, q)| (q - position).xy().norm() <= reach)
                .copied()
                .collect();
            let key = 1000 + old.0;
            let covariance = Matrix3::from_diagonal_element(0.02 * 0.02);
            candidates.push(Candidate::new(key, position, &covariance, olds));
            if mapped(old.0) {
                truth.push((key, old));
            }
        }
        truth.sort();
        (candidates, truth)
    }

    /// Eight lamps in view: two rows of four.
    const EIGHT: [u64; 8] = [8, 9, 14, 15, 20, 21, 26, 27];

    #[test]
    fn a_jittered_grid_is_recognised_through_metres_of_drift() {
        // (Five lamps are not always enough: a grid shifted one spacing may lay four of them
        // within their tolerance; the navigator then waits for more lamps.)
        let (candidates, truth) = scene(0.6, 6.0, &EIGHT, |_| true);
        let found = constellation(&candidates, 0.2);
        let Found::Unique { pairs, motion } = found else {
            panic!("not recognised: {found:?}");
        };
        assert_eq!(pairs, truth);
        // The motion laying the held lamps back where they are: the drift undone.
        assert!((motion.0 - 0.06).abs() < 1e-9, "{motion:?}");
        assert!(
            (motion.1 - 2.1).abs() < 1e-9 && (motion.2 + 1.4).abs() < 1e-9,
            "{motion:?}"
        );
    }

    /// Two rows in view, only the first mapped: laid one row off, the unmapped row would fall
    /// onto mapped lamps a jitter away from each (conflicts); laid right, it falls where
    /// nothing is mapped.
    #[test]
    fn lamps_half_on_new_ground_are_recognised_by_the_mapped_half() {
        let held: Vec<u64> = (1..7).flat_map(|i| [6 * i + 2, 6 * i + 3]).collect();
        let (candidates, truth) = scene(0.6, 6.0, &held, |id| id % 6 <= 2);
        assert_eq!(truth.len(), 6);
        let Found::Unique { pairs, .. } = constellation(&candidates, 0.2) else {
            panic!("not recognised");
        };
        assert_eq!(pairs, truth);
    }

    #[test]
    fn a_regular_grid_is_ambiguous() {
        let (candidates, _) = scene(0.0, 6.0, &EIGHT, |_| true);
        assert_eq!(constellation(&candidates, 0.2), Found::Ambiguous);
    }

    #[test]
    fn too_few_lamps_close_nothing() {
        let (candidates, _) = scene(0.6, 6.0, &EIGHT[..MIN_PAIRS - 1], |_| true);
        assert_eq!(constellation(&candidates, 0.2), Found::None);
    }

    #[test]
    fn a_rotation_beyond_the_bound_is_not_considered() {
        let (candidates, _) = scene(0.6, 6.0, &EIGHT, |_| true);
        assert_eq!(constellation(&candidates, 0.01), Found::None);
    }

    /// Two triangulations of a held lamp average by their information; relative to the
    /// vehicle, the covariance grows by dead reckoning's since the lamp was last seen.
    #[test]
    fn a_held_lamp_is_averaged_and_carried_to_the_vehicle() {
        let mut held = Held::new();
        let a = Vector3::new(4.0, 1.0, 7.0);
        let b = Vector3::new(4.3, 1.0, 7.0);
        let ca = Matrix3::from_diagonal_element(0.01);
        let cb = Matrix3::from_diagonal_element(0.02);
        let zero = Matrix3::zeros();
        held.add(1, a, &ca, &zero, 0);
        assert_eq!(held.mature(), 0);
        held.add(1, b, &cb, &zero, 1);
        let positions = held.positions();
        let (_, p, frames) = positions[0];
        assert_eq!(frames, 2);
        // (a / 0.01 + b / 0.02) / (1 / 0.01 + 1 / 0.02) = a + (b - a) / 3.
        assert!((p - Vector3::new(4.1, 1.0, 7.0)).norm() < 1e-12, "{p}");
        let pose = rig_model::camera::Pose2::new(1.0, 1.0, core::f64::consts::FRAC_PI_2);
        let r = held.relative(1, &pose).unwrap();
        // 3.1 m east of a vehicle facing north: 3.1 m to its right.
        assert!(
            (r.position - Vector3::new(0.0, -3.1, 7.0)).norm() < 1e-12,
            "{r:?}"
        );
        let averaged = 1.0 / (1.0 / 0.01 + 1.0 / 0.02);
        assert!((r.covariance[(1, 1)] - averaged).abs() < 1e-12);
        // Dead reckoning since: 2e-4 m^2 over both axes, 1e-5 rad^2 at 3.1 m.
        held.add_motion(&Matrix3::new(
            1e-4, 0.0, 0.0, 0.0, 1e-4, 0.0, 0.0, 0.0, 1e-5,
        ));
        let r = held.relative(1, &pose).unwrap();
        let grown = averaged + 1e-4 + 1e-5 * 3.1 * 3.1;
        assert!((r.covariance[(0, 0)] - grown).abs() < 1e-12, "{r:?}");
        assert!((r.covariance[(2, 2)] - averaged).abs() < 1e-12, "{r:?}");
        held.clear();
        assert!(held.is_empty());
    }
}
