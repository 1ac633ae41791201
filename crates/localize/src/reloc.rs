//! Global (re)localisation: the pose unknown, the lamps in view matched against the map as a
//! constellation, hypotheses that live only while odometry and later frames agree.
//!
//! 1. **Generation.** Two lamps seen in one frame fix the planar pose once we say which map
//!    lamps they are: each one's ray from the cameras meets the height of its map lamp at a
//!    point of the floor plan (the lamps' heights come from the map, which knows them far
//!    better than one frame's disparity at 5 m). Every pair of observations is compared with
//!    every pair of map lamps at the same horizontal distance (the map's pairs sorted by
//!    distance); each match, both ways round, gives a pose, kept only if the frame's other
//!    observations land on map lamps under it.
//! 2. **Scoring.** Each hypothesis is a [`PoseFilter`] predicted by the odometry and updated by
//!    the lamps it associates (nearest by Mahalanobis distance, one to one). Its score is the
//!    log-likelihood ratio of the frame's data under it against all of it being clutter, the
//!    track score of multiple-hypothesis tracking: `ln(P_D) - d^2/2 - ln|2 pi S|/2 - ln(lambda)`
//!    for each associated lamp (`lambda` the clutter density in measurement space) and
//!    `ln(1 - P_D)` for each lamp it expects in view and does not see.
//! 3. **Decision.** Hypotheses are compared over the frames both have lived (at most a window):
//!    one far behind the best is dropped; `localized` is declared only when one hypothesis has
//!    lived long enough, is ahead of every other by a margin over their common frames, and
//!    explains its frame. On a regular grid the shifted hypotheses explain the data as well as
//!    the true one: none is ahead, and the localiser stays lost rather than guess (a wrong
//!    fix is worse than none). The jitter of real lamp grids, the hall's edges and the
//!    odometry's motion between frames separate them.

use alloc::collections::VecDeque;
use alloc::vec::Vec;

use nalgebra::{Matrix3, Vector3};
use rig_model::camera::{Pose2, Vehicle, wrap_angle};
use vslam_ekf::Increment;

use crate::filter::PoseFilter;
use crate::map::{LampMap, LampTriangle, opposite_sides};
use crate::settings::RelocSettings;
use crate::view::{Observation, Ray, View};

/// One pose hypothesis.
#[derive(Debug, Clone)]
pub struct Hypothesis {
    /// Its filter (pose; `V` held at the map's values).
    pub filter: PoseFilter,
    /// Frames it has lived.
    pub age: u32,
    /// Its score of each of the last frames, newest last.
    pub history: VecDeque<f64>,
    /// Lamps it associated at its last frame.
    pub matched: usize,
    /// Lamps it expected in view at its last frame.
    pub expected: usize,
    /// Mean NIS of its associations at its last frame.
    pub mean_nis: f64,
    /// Distinct lamps it has associated over its life (capped).
    pub distinct: Vec<u32>,
}

impl Hypothesis {
    fn new(filter: PoseFilter) -> Self {
        Self {
            filter,
            age: 0,
            history: VecDeque::new(),
            matched: 0,
            expected: 0,
            mean_nis: 0.0,
            distinct: Vec::new(),
        }
    }

    /// Its score over its last `k` frames.
    pub fn recent(&self, k: usize) -> f64 {
        self.history.iter().rev().take(k).sum()
    }

    /// The pose.
    pub fn pose(&self) -> Pose2 {
        self.filter.pose()
    }
}

/// What the decision found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Decision {
    /// No hypothesis stands out.
    Undecided,
    /// Hypothesis `i` is unique.
    Unique(usize),
}

/// What the last generation of hypotheses did (for traces and the viewer).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Generation {
    /// Observations it drew triangles from.
    pub observations: usize,
    /// Triangles of observations it looked up.
    pub triangles: usize,
    /// Of those, the ones looked up whole (no look-up too common to try).
    pub whole: usize,
    /// Map triangles the look-ups returned.
    pub map_triangles: usize,
    /// Candidate poses that the frame's other observations supported.
    pub candidates: usize,
    /// New hypotheses (candidates not already held, associating enough lamps).
    pub new: usize,
}

/// The set of hypotheses while lost.
#[derive(Debug, Clone)]
pub struct Relocalizer {
    settings: RelocSettings,
    hypotheses: Vec<Hypothesis>,
    frames_since_generation: u32,
    scratch: Vec<u32>,
    /// Frames during which no decision is taken because the set of hypotheses was cut
    /// (a generation hit its cap, or the set was truncated): a hypothesis that is unique only
    /// among those kept proves nothing.
    incomplete: usize,
    /// Hypotheses generated over the relocaliser's life.
    pub generated: u64,
    /// The last generation.
    pub last_generation: Generation,
}

impl Relocalizer {
    /// An empty relocaliser.
    pub fn new(settings: RelocSettings) -> Self {
        Self {
            settings,
            hypotheses: Vec::new(),
            frames_since_generation: u32::MAX,
            scratch: Vec::new(),
            incomplete: 0,
            generated: 0,
            last_generation: Generation::default(),
        }
    }

    /// Forgets every hypothesis (the vehicle was moved, or it is localised).
    pub fn clear(&mut self) {
        self.hypotheses.clear();
        self.frames_since_generation = u32::MAX;
        self.incomplete = 0;
    }

    /// Whether decisions are held back because the set of hypotheses was cut.
    pub fn incomplete(&self) -> bool {
        self.incomplete > 0
    }

    /// The live hypotheses.
    pub fn hypotheses(&self) -> &[Hypothesis] {
        &self.hypotheses
    }

    /// The best hypothesis by its recent score.
    pub fn best(&self) -> Option<&Hypothesis> {
        let w = self.settings.window_frames;
        self.hypotheses
            .iter()
            .max_by(|a, b| a.recent(w).total_cmp(&b.recent(w)))
    }

    /// Predicts every hypothesis with the odometry's motion (for the map's `V`).
    pub fn predict(&mut self, inc: &Increment, jv: &nalgebra::Matrix3x4<f64>) {
        for h in &mut self.hypotheses {
            h.filter.predict(inc, jv);
        }
    }

    /// One frame: hypotheses scored and updated, new ones generated when due, the weak ones
    /// dropped; then the decision.
    pub fn frame(
        &mut self,
        map: &LampMap,
        view: &View,
        observations: &[Observation],
        vehicle: &Vehicle,
        t_us: u64,
    ) -> Decision {
        let s = self.settings;
        for h in &mut self.hypotheses {
            let scored = view.score_and_update(map, &mut h.filter, observations, t_us);
            h.age = h.age.saturating_add(1);
            h.history.push_back(scored.llr);
            while h.history.len() > s.window_frames {
                h.history.pop_front();
            }
            h.matched = scored.matched.len();
            h.expected = scored.expected;
            h.mean_nis = scored.mean_nis;
            for (lamp, _) in scored.matched {
                if h.distinct.len() < 64 && !h.distinct.contains(&lamp) {
                    h.distinct.push(lamp);
                }
            }
        }
        self.incomplete = self.incomplete.saturating_sub(1);
        self.frames_since_generation = self.frames_since_generation.saturating_add(1);
        if self.frames_since_generation >= s.generate_every_frames
            && observations.len() >= s.min_observations
        {
            self.frames_since_generation = 0;
            self.generate(map, view, observations, vehicle, t_us);
        }
        self.prune();
        self.decide()
    }

    /// New hypotheses from the frame's observations (module docs, step 1). Each new one is
    /// scored on this frame at once.
    fn generate(
        &mut self,
        map: &LampMap,
        view: &View,
        observations: &[Observation],
        vehicle: &Vehicle,
        t_us: u64,
    ) {
        let s = self.settings;
        // The steadiest observations first: the longest tracks (clutter rarely lasts).
        let mut order: Vec<usize> = (0..observations.len()).collect();
        order.sort_by_key(|&i| core::cmp::Reverse(observations.get(i).map_or(0, |o| o.hits)));
        order.truncate(s.max_generation_observations);
        let origin = view.camera().mount.translation();
        let levels = map.levels();
        // Each observation's ray once (the mount's rotation is not worked out per test).
        let rays: Vec<Option<Ray>> = observations.iter().map(|o| view.ray(o)).collect();
        // Each observation on each level's mean height, with how far off that puts it if its
        // lamp hangs anywhere in the level (radially from the rig: r dz / (z - z_rig)), plus
        // half the side tolerance.
        let floor: Vec<Vec<Option<OnLevel>>> = levels
            .iter()
            .map(|level| {
                let above = (level.z - origin.z).max(0.5);
                order
                    .iter()
                    .map(|&i| {
                        let p = rays.get(i).copied().flatten()?.at_height(level.z)?;
                        let r = libm::hypot(p.x - origin.x, p.y - origin.y);
                        Some((p, 0.5 * s.pair_tolerance_m + r * level.spread / above))
                    })
                    .collect()
            })
            .collect();
        let min_side = map.triangle_min_side_m();
        let max_side = map.triangle_max_side_m();
        let n = order.len();
        // The triangles nearest the rig first (a point's error from its lamp's unknown height
        // grows with its distance from the rig, and with it the look-up's tolerance and the
        // map triangles it returns), each sharing at most one observation with those before
        // it (so that one observation that is clutter or a new lamp does not spoil them all),
        // then the others.
        let reach = |k: usize| {
            floor
                .first()
                .and_then(|f| f.get(k))
                .copied()
                .flatten()
                .map_or(f64::INFINITY, |(p, _)| {
                    libm::hypot(p.x - origin.x, p.y - origin.y)
                })
        };
        let mut all: Vec<([usize; 3], f64)> = Vec::new();
        for a in 0..n {
            for b in a + 1..n {
                for c in b + 1..n {
                    all.push(([a, b, c], reach(a).max(reach(b)).max(reach(c))));
                }
            }
        }
        all.sort_by(|x, y| x.1.total_cmp(&y.1));
        let mut triangles: Vec<[usize; 3]> = Vec::with_capacity(all.len());
        let mut rest: Vec<[usize; 3]> = Vec::new();
        for (t, _) in all {
            let spread = triangles
                .iter()
                .all(|u| t.iter().filter(|v| u.contains(v)).count() <= 1);
            if spread {
                triangles.push(t);
            } else {
                rest.push(t);
            }
        }
        triangles.extend(rest);
        let n_levels = levels.len();
        let combos = n_levels * n_levels * n_levels;
        let mut candidates: Vec<Pose2> = Vec::new();
        let mut found = Vec::new();
        let mut whole = 0_usize;
        let mut tried = 0_usize;
        let mut stats = Generation {
            observations: n,
            ..Generation::default()
        };
        'triangles: for tri in triangles {
            if tried >= s.max_query_triangles {
                break;
            }
            let mut complete = true;
            let mut used = false;
            for combo in 0..combos {
                let lv = [
                    combo % n_levels,
                    (combo / n_levels) % n_levels,
                    combo / (n_levels * n_levels),
                ];
                let mut pts = [Vector3::zeros(); 3];
                let mut err = [0.0; 3];
                let mut ok = true;
                for v in 0..3 {
                    match (tri.get(v), lv.get(v)) {
                        (Some(&k), Some(&l)) => {
                            match floor.get(l).and_then(|f| f.get(k)).copied().flatten() {
                                Some((p, e)) => {
                                    if let (Some(pt), Some(er)) = (pts.get_mut(v), err.get_mut(v)) {
                                        (*pt, *er) = (p, e);
                                    }
                                }
                                None => ok = false,
                            }
                        }
                        _ => ok = false,
                    }
                }
                if !ok {
                    continue;
                }
                let sides = opposite_sides(&pts);
                let [e0, e1, e2] = err;
                let longest = sides.iter().copied().fold(0.0, f64::max);
                let tol = (e0 + e1).max(e1 + e2).max(e0 + e2) + s.pair_tolerance_fraction * longest;
                let mut sorted = sides;
                sorted.sort_by(f64::total_cmp);
                let [lo, _, hi] = sorted;
                // Only a triangle the index can hold (its sides may be a tolerance off).
                if lo + tol < min_side || hi - tol > max_side {
                    continue;
                }
                used = true;
                if !map.triangles_near(sorted, tol, &mut found, s.max_triangle_candidates) {
                    // A shape this common tells no place from another (a regular grid).
                    complete = false;
                    continue;
                }
                stats.map_triangles += found.len();
                let mut poses = 0;
                let before = candidates.len();
                for t in &found {
                    poses += self.try_triangle(
                        map,
                        &rays,
                        &order,
                        tri,
                        lv,
                        &sides,
                        tol,
                        t,
                        &mut candidates,
                    );
                    if poses > s.max_poses_per_triangle {
                        // The frame's triangle fits too many places (a regular grid, or a
                        // stretch of one): it tells them apart no better than a guess, and
                        // its poses are not kept (scoring hundreds of equal hypotheses every
                        // frame would cost the time and could never decide).
                        complete = false;
                        candidates.truncate(before);
                        break;
                    }
                    if candidates.len() > s.max_candidates {
                        self.incomplete = s.window_frames;
                        break 'triangles;
                    }
                }
            }
            if used {
                tried += 1;
                whole += usize::from(complete);
            }
        }
        // When a look-up was cut, unless three triangles were tried whole, the set may miss
        // the true pose while it holds others: no decision for a while.
        if whole < tried && whole < 3 {
            self.incomplete = s.window_frames;
        }
        stats.triangles = tried;
        stats.whole = whole;
        stats.candidates = candidates.len();
        let sigma_xy = s.initial_sigma_m;
        let sigma_th = s.initial_sigma_rad;
        let cov = Matrix3::from_diagonal(&Vector3::new(
            sigma_xy * sigma_xy,
            sigma_xy * sigma_xy,
            sigma_th * sigma_th,
        ));
        for pose in candidates {
            if self
                .hypotheses
                .iter()
                .any(|h| same_pose(&h.pose(), &pose, &s))
            {
                continue;
            }
            let mut filter = PoseFilter::new(pose, &cov, vehicle, [0.0; 4], [0.0; 4]);
            let scored = view.score_and_update(map, &mut filter, observations, t_us);
            if scored.matched.len() < s.min_matched {
                continue;
            }
            // Merge after the update too: two seeds that converge are one hypothesis.
            if self
                .hypotheses
                .iter()
                .any(|h| same_pose(&h.pose(), &filter.pose(), &s))
            {
                continue;
            }
            // Its birth frame is not in its score: it was associated with the seed's loose
            // covariance, which the score's normalisation penalises against hypotheses that
            // have converged (a true pose born late was dropped at once for it). With no
            // common frame it neither is compared nor lets another be declared unique.
            let mut h = Hypothesis::new(filter);
            h.matched = scored.matched.len();
            h.expected = scored.expected;
            h.mean_nis = scored.mean_nis;
            h.distinct = scored.matched.iter().map(|(l, _)| *l).collect();
            self.hypotheses.push(h);
            self.generated += 1;
            stats.new += 1;
        }
        self.last_generation = stats;
    }

    /// One map triangle `t` against the frame's triangle `tri` (indices into `order`, on the
    /// levels `lv`, opposite sides `sides` within `tol`): every correspondence of vertices the
    /// sides allow, on the right levels, the frame's points put at their lamps' own heights,
    /// the same shape and handedness; the pose that carries the three onto the lamps, kept in
    /// `candidates` when the frame's other observations land on map lamps under it. Returns
    /// the poses so supported (kept or already held).
    #[allow(clippy::too_many_arguments)]
    fn try_triangle(
        &mut self,
        map: &LampMap,
        rays: &[Option<Ray>],
        order: &[usize],
        tri: [usize; 3],
        lv: [usize; 3],
        sides: &[f64; 3],
        tol: f64,
        t: &LampTriangle,
        candidates: &mut Vec<Pose2>,
    ) -> usize {
        let s = self.settings;
        let mut supported = 0;
        let [a, b, c] = t.lamps;
        let (Some(m0), Some(m1), Some(m2)) = (map.lamp(a), map.lamp(b), map.lamp(c)) else {
            return 0;
        };
        let mp = [m0.position, m1.position, m2.position];
        let msides = opposite_sides(&mp);
        let hand = |p: &[Vector3<f64>; 3]| {
            let [a, b, c] = p;
            (b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x)
        };
        let mhand = hand(&mp);
        for perm in PERMUTATIONS {
            // Map vertex k is the frame's vertex perm[k].
            let fits =
                (0..3).all(
                    |k| match (msides.get(k), perm.get(k).and_then(|&v| sides.get(v))) {
                        (Some(a), Some(b)) => libm::fabs(a - b) <= tol,
                        _ => false,
                    },
                );
            let levels_fit = (0..3).all(|k| {
                let lamp = t.lamps.get(k).copied().unwrap_or(u32::MAX);
                perm.get(k).and_then(|&v| lv.get(v)).copied() == map.level_of(lamp)
            });
            if !(fits && levels_fit) {
                continue;
            }
            // The frame's points at their lamps' own heights.
            let mut q = [Vector3::zeros(); 3];
            let mut ok = true;
            for k in 0..3 {
                let ray = perm
                    .get(k)
                    .and_then(|&v| tri.get(v))
                    .and_then(|&i| order.get(i))
                    .and_then(|&o| rays.get(o).copied().flatten());
                let z = mp.get(k).map_or(0.0, |p| p.z);
                match (ray.and_then(|r| r.at_height(z)), q.get_mut(k)) {
                    (Some(p), Some(slot)) => *slot = p,
                    _ => ok = false,
                }
            }
            if !ok {
                continue;
            }
            let qsides = opposite_sides(&q);
            let same_shape = (0..3).all(|k| match (qsides.get(k), msides.get(k)) {
                (Some(a), Some(b)) => {
                    libm::fabs(a - b) <= s.pair_tolerance_m + s.pair_tolerance_fraction * b
                }
                _ => false,
            });
            // A mirror image is not the place (the camera sees the ceiling from one side);
            // a triangle with almost no area (three lamps nearly in a row) has no handedness
            // to tell.
            let longest = msides.iter().copied().fold(0.0, f64::max);
            let flat = libm::fabs(mhand) < 0.05 * longest * longest;
            if !same_shape || (!flat && hand(&q) * mhand <= 0.0) {
                continue;
            }
            let pose = align(&q, &mp);
            let on_lamps = q.iter().zip(mp.iter()).all(|(p, l)| {
                let w = pose.point_in_world(p);
                libm::hypot(w.x - l.x, w.y - l.y) <= s.support_radius_m
            });
            if !on_lamps {
                continue;
            }
            // Every other observation of the frame, not only the steadiest: a wrong pose that
            // puts a few on lamps by chance (a jittered grid repeats itself within its jitter)
            // rarely puts a third of twenty there. Stops as soon as the count cannot be met.
            let skip: [Option<usize>; 3] = tri.map(|k| order.get(k).copied());
            let others = rays.len().saturating_sub(3);
            #[allow(
                clippy::cast_precision_loss,
                clippy::cast_possible_truncation,
                clippy::cast_sign_loss
            )]
            let need = s
                .min_support
                .min(others)
                .max(libm::ceil(s.min_support_fraction * others as f64) as usize);
            let (mut support, mut missed) = (0, 0);
            for (o, ray) in rays.iter().enumerate() {
                if skip.contains(&Some(o)) {
                    continue;
                }
                if ray.is_some_and(|r| self.supports(map, &r, &pose)) {
                    support += 1;
                } else {
                    missed += 1;
                    if others - missed < need {
                        break;
                    }
                }
            }
            if support >= need {
                supported += 1;
                if !candidates.iter().any(|c| same_pose(c, &pose, &s)) {
                    candidates.push(pose);
                }
            }
        }
        supported
    }

    /// Whether the observation along `ray` lands on a map lamp under `pose` (on any of the
    /// map's levels).
    fn supports(&mut self, map: &LampMap, ray: &Ray, pose: &Pose2) -> bool {
        let s = self.settings;
        for level in map.levels() {
            let Some(p) = ray.at_height(level.z) else {
                continue;
            };
            let w = pose.point_in_world(&p);
            let reach = s.support_radius_m * 2.0 + level.spread;
            let Some((i, _)) = map.nearest(w.x, w.y, reach, &mut self.scratch) else {
                continue;
            };
            let Some(lamp) = map.lamp(i) else {
                continue;
            };
            let Some(p) = ray.at_height(lamp.position.z) else {
                continue;
            };
            let w = pose.point_in_world(&p);
            if libm::hypot(w.x - lamp.position.x, w.y - lamp.position.y) <= s.support_radius_m {
                return true;
            }
        }
        false
    }

    /// Drops hypotheses far behind the best over their common frames, merges duplicates, and
    /// keeps at most the configured number.
    fn prune(&mut self) {
        let s = self.settings;
        let w = s.window_frames;
        // Duplicates: the older (higher-scoring) one stays.
        self.hypotheses
            .sort_by(|a, b| b.recent(w).total_cmp(&a.recent(w)));
        let mut kept: Vec<Hypothesis> = Vec::with_capacity(self.hypotheses.len());
        for h in self.hypotheses.drain(..) {
            if !kept.iter().any(|k| same_pose(&k.pose(), &h.pose(), &s)) {
                kept.push(h);
            }
        }
        let Some(best) = kept.first().cloned() else {
            self.hypotheses = kept;
            return;
        };
        kept.retain(|h| {
            let k = common(&best, h, w);
            let behind = best.recent(k) - h.recent(k);
            let starved = h.age >= 3 && h.matched < s.min_matched.min(h.expected.max(1));
            behind <= s.prune_margin && !starved
        });
        if kept.len() > s.max_hypotheses {
            kept.truncate(s.max_hypotheses);
            self.incomplete = s.window_frames;
        }
        self.hypotheses = kept;
    }

    /// The decision (module docs, step 3).
    fn decide(&self) -> Decision {
        match self.verdict() {
            Ok(i) => Decision::Unique(i),
            Err(_) => Decision::Undecided,
        }
    }

    /// What holds the decision back while lost (`None` when the best hypothesis is unique):
    /// why a fix is taking the time it takes.
    pub fn waiting(&self) -> Option<Waiting> {
        self.verdict().err()
    }

    /// The live hypotheses, best first, each with how far behind the best it is over their
    /// common frames (nats; 0 for the best).
    pub fn weighed(&self) -> Vec<Weighed> {
        let w = self.settings.window_frames;
        let mut out: Vec<Weighed> = Vec::with_capacity(self.hypotheses.len());
        let Some(best) = self
            .hypotheses
            .iter()
            .max_by(|a, b| a.recent(w).total_cmp(&b.recent(w)))
        else {
            return out;
        };
        for h in &self.hypotheses {
            let k = common(best, h, w);
            out.push(Weighed {
                pose: h.pose(),
                behind_nats: best.recent(k) - h.recent(k),
                age: h.age,
                matched: h.matched,
            });
        }
        out.sort_by(|a, b| a.behind_nats.total_cmp(&b.behind_nats));
        out
    }

    /// The best hypothesis's index when it is unique, else what holds it back.
    fn verdict(&self) -> Result<usize, Waiting> {
        let s = self.settings;
        let w = s.window_frames;
        let Some((bi, best)) = self
            .hypotheses
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.recent(w).total_cmp(&b.1.recent(w)))
        else {
            return Err(Waiting::NoHypothesis);
        };
        if self.incomplete > 0 {
            return Err(Waiting::Incomplete);
        }
        if best.age < s.min_frames {
            return Err(Waiting::Young { frames: best.age });
        }
        if best.matched < s.min_matched || best.distinct.len() < s.min_distinct_lamps {
            return Err(Waiting::FewLamps {
                matched: best.matched,
                distinct: best.distinct.len(),
            });
        }
        if best.mean_nis > s.max_mean_nis {
            return Err(Waiting::PoorFit {
                mean_nis: best.mean_nis,
            });
        }
        let ahead = self
            .hypotheses
            .iter()
            .enumerate()
            .filter(|&(i, _)| i != bi)
            .map(|(_, h)| {
                let k = common(best, h, w);
                best.recent(k) - h.recent(k)
            })
            .fold(f64::INFINITY, f64::min);
        if ahead >= s.decision_margin {
            Ok(bi)
        } else {
            Err(Waiting::Margin { ahead_nats: ahead })
        }
    }
}

/// What holds a fix back while lost ([`Relocalizer::waiting`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Waiting {
    /// No hypothesis: too few observations, or none of the map's places fits them.
    NoHypothesis,
    /// A generation was cut (too many candidates, or a triangle of the frame fits too many
    /// places: a regular grid): a hypothesis unique among those kept proves nothing.
    Incomplete,
    /// The best has lived this few frames.
    Young {
        /// Frames it has lived.
        frames: u32,
    },
    /// The best associates too few lamps (now, or distinct over its life).
    FewLamps {
        /// Lamps it associated at its last frame.
        matched: usize,
        /// Distinct lamps over its life.
        distinct: usize,
    },
    /// The best's associations fit poorly.
    PoorFit {
        /// Their mean NIS.
        mean_nis: f64,
    },
    /// The best is not far enough ahead of the next.
    Margin {
        /// Its lead over the nearest rival, nats.
        ahead_nats: f64,
    },
}

impl core::fmt::Display for Waiting {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            Self::NoHypothesis => write!(f, "no hypothesis fits the lamps in view"),
            Self::Incomplete => write!(f, "a generation was cut (the view fits too many places)"),
            Self::Young { frames } => write!(f, "the best has lived {frames} frames"),
            Self::FewLamps { matched, distinct } => write!(
                f,
                "the best matches {matched} lamps ({distinct} distinct so far)"
            ),
            Self::PoorFit { mean_nis } => {
                write!(f, "the best fits poorly (mean NIS {mean_nis:.1})")
            }
            Self::Margin { ahead_nats } => {
                write!(f, "the best is only {ahead_nats:.1} nats ahead of the next")
            }
        }
    }
}

/// A live hypothesis as [`Relocalizer::weighed`] reports it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Weighed {
    /// Its pose.
    pub pose: Pose2,
    /// How far behind the best it is over their common frames, nats (0 for the best).
    pub behind_nats: f64,
    /// Frames it has lived.
    pub age: u32,
    /// Lamps it associated at its last frame.
    pub matched: usize,
}

/// Frames two hypotheses have both lived, at most `w`.
fn common(a: &Hypothesis, b: &Hypothesis, w: usize) -> usize {
    (a.history.len()).min(b.history.len()).min(w)
}

/// Whether two poses are the same hypothesis.
fn same_pose(a: &Pose2, b: &Pose2, s: &RelocSettings) -> bool {
    libm::hypot(a.x - b.x, a.y - b.y) <= s.merge_distance_m
        && libm::fabs(wrap_angle(a.theta - b.theta)) <= s.merge_angle_rad
}

/// An observation on a level's mean height: the point (robot frame) and how far off it can be.
type OnLevel = (Vector3<f64>, f64);

/// The six orders of a triangle's vertices.
const PERMUTATIONS: [[usize; 3]; 6] = [
    [0, 1, 2],
    [0, 2, 1],
    [1, 0, 2],
    [1, 2, 0],
    [2, 0, 1],
    [2, 1, 0],
];

/// The planar pose that carries the robot-frame points `q` onto the map points `m`
/// (horizontally) in the least-squares sense: the rotation from the centred points' summed
/// dot and cross products, the translation from the centroids (2-D Procrustes).
fn align(q: &[Vector3<f64>; 3], m: &[Vector3<f64>; 3]) -> Pose2 {
    let c = |p: &[Vector3<f64>; 3]| {
        (
            (p[0].x + p[1].x + p[2].x) / 3.0,
            (p[0].y + p[1].y + p[2].y) / 3.0,
        )
    };
    let ((qx, qy), (mx, my)) = (c(q), c(m));
    let (mut dot, mut cross) = (0.0, 0.0);
    for (a, b) in q.iter().zip(m.iter()) {
        let (ax, ay, bx, by) = (a.x - qx, a.y - qy, b.x - mx, b.y - my);
        dot += ax * bx + ay * by;
        cross += ax * by - ay * bx;
    }
    let th = libm::atan2(cross, dot);
    let (s, co) = (libm::sin(th), libm::cos(th));
    Pose2::new(
        mx - (co * qx - s * qy),
        my - (s * qx + co * qy),
        wrap_angle(th),
    )
}

#[cfg(test)]
#[allow(clippy::indexing_slicing, clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn two_points_give_back_the_pose_that_moved_them() {
        let pose = Pose2::new(3.0, -2.0, 2.1);
        let qa = Vector3::new(1.0, 0.5, 7.0);
        let qb = Vector3::new(-2.0, 1.5, 6.8);
        let (ma, mb) = (pose.point_in_world(&qa), pose.point_in_world(&qb));
        let qc = Vector3::new(0.3, -2.5, 7.1);
        let mc = pose.point_in_world(&qc);
        let got = align(&[qa, qb, qc], &[ma, mb, mc]);
        assert!((got.x - pose.x).abs() < 1e-12 && (got.y - pose.y).abs() < 1e-12);
        assert!((got.theta - pose.theta).abs() < 1e-12);
    }
}
