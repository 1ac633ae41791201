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
use crate::map::LampMap;
use crate::settings::RelocSettings;
use crate::view::{Observation, View};

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
        }
    }

    /// Forgets every hypothesis (the vehicle was moved, or it is localised).
    pub fn clear(&mut self) {
        self.hypotheses.clear();
        self.frames_since_generation = u32::MAX;
        self.incomplete = 0;
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
        let z_mean = map.mean_height();
        let floor: Vec<Option<Vector3<f64>>> = order
            .iter()
            .map(|&i| observations.get(i).and_then(|o| view.on_height(o, z_mean)))
            .collect();
        let mut candidates: Vec<Pose2> = Vec::new();
        // Disjoint pairs first ((0, 1), (2, 3), ...), then the others: the true pose is among
        // the candidates of any pair of two mapped lamps tried whole, and disjoint pairs do
        // not all fall with one observation that is clutter or a new lamp.
        let n = order.len();
        let mut pairs: Vec<(usize, usize)> = (0..n / 2).map(|k| (2 * k, 2 * k + 1)).collect();
        for a in 0..n {
            for b in a + 1..n {
                if !(b == a + 1 && a % 2 == 0) {
                    pairs.push((a, b));
                }
            }
        }
        let mut disjoint_done = 0;
        for (pi, &(a, b)) in pairs.iter().enumerate() {
            {
                let (Some(pa), Some(pb)) = (
                    floor.get(a).copied().flatten(),
                    floor.get(b).copied().flatten(),
                ) else {
                    continue;
                };
                let d = libm::hypot(pa.x - pb.x, pa.y - pb.y);
                if d < s.min_pair_distance_m {
                    continue;
                }
                let tol = s.pair_tolerance_m + s.pair_tolerance_fraction * d;
                let (Some(&oa), Some(&ob)) = (order.get(a), order.get(b)) else {
                    continue;
                };
                let (Some(obs_a), Some(obs_b)) = (observations.get(oa), observations.get(ob))
                else {
                    continue;
                };
                for pair in map.pairs_between(d - tol, d + tol) {
                    for (i, j) in [(pair.a, pair.b), (pair.b, pair.a)] {
                        let (Some(li), Some(lj)) = (map.lamp(i), map.lamp(j)) else {
                            continue;
                        };
                        let (Some(qa), Some(qb)) = (
                            view.on_height(obs_a, li.position.z),
                            view.on_height(obs_b, lj.position.z),
                        ) else {
                            continue;
                        };
                        let dq = libm::hypot(qa.x - qb.x, qa.y - qb.y);
                        if libm::fabs(dq - pair.distance) > s.pair_tolerance_m {
                            continue;
                        }
                        let pose = align(&qa, &qb, &li.position, &lj.position);
                        let support = order
                            .iter()
                            .enumerate()
                            .filter(|&(k, _)| k != a && k != b)
                            .filter(|&(_, &o)| {
                                observations
                                    .get(o)
                                    .is_some_and(|obs| self.supports(map, view, obs, &pose, z_mean))
                            })
                            .count();
                        let others = order.len() - 2;
                        if support >= s.min_support.min(others)
                            && support * 2 >= others
                            && !candidates.iter().any(|c| same_pose(c, &pose, &s))
                        {
                            candidates.push(pose);
                        }
                    }
                }
            }
            if pi < n / 2 {
                disjoint_done += 1;
            }
            if candidates.len() > s.max_candidates {
                // The rest of the pairs are not tried. Unless three disjoint pairs were tried
                // whole, the set may miss the true pose: no decision for a while.
                if disjoint_done < 3.min(n / 2) {
                    self.incomplete = s.window_frames;
                }
                break;
            }
        }
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
        }
    }

    /// Whether observation `obs` lands on a map lamp under `pose`.
    fn supports(
        &mut self,
        map: &LampMap,
        view: &View,
        obs: &Observation,
        pose: &Pose2,
        z_mean: f64,
    ) -> bool {
        let s = self.settings;
        let Some(p) = view.on_height(obs, z_mean) else {
            return false;
        };
        let w = pose.point_in_world(&p);
        let Some((i, _)) = map.nearest(w.x, w.y, s.support_radius_m * 2.0, &mut self.scratch)
        else {
            return false;
        };
        let Some(lamp) = map.lamp(i) else {
            return false;
        };
        let Some(p) = view.on_height(obs, lamp.position.z) else {
            return false;
        };
        let w = pose.point_in_world(&p);
        libm::hypot(w.x - lamp.position.x, w.y - lamp.position.y) <= s.support_radius_m
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
        let s = self.settings;
        let w = s.window_frames;
        let Some((bi, best)) = self
            .hypotheses
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.recent(w).total_cmp(&b.1.recent(w)))
        else {
            return Decision::Undecided;
        };
        if self.incomplete > 0
            || best.age < s.min_frames
            || best.matched < s.min_matched
            || best.distinct.len() < s.min_distinct_lamps
            || best.mean_nis > s.max_mean_nis
        {
            return Decision::Undecided;
        }
        let unique = self.hypotheses.iter().enumerate().all(|(i, h)| {
            i == bi || {
                let k = common(best, h, w);
                best.recent(k) - h.recent(k) >= s.decision_margin
            }
        });
        if unique {
            Decision::Unique(bi)
        } else {
            Decision::Undecided
        }
    }
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

/// The planar pose that carries the robot-frame points `qa`, `qb` onto the map points `ma`,
/// `mb` (horizontally): the heading from the two directions, the position from the midpoints.
fn align(qa: &Vector3<f64>, qb: &Vector3<f64>, ma: &Vector3<f64>, mb: &Vector3<f64>) -> Pose2 {
    let th = libm::atan2(mb.y - ma.y, mb.x - ma.x) - libm::atan2(qb.y - qa.y, qb.x - qa.x);
    let (s, c) = (libm::sin(th), libm::cos(th));
    let (qx, qy) = (0.5 * (qa.x + qb.x), 0.5 * (qa.y + qb.y));
    let (mx, my) = (0.5 * (ma.x + mb.x), 0.5 * (ma.y + mb.y));
    Pose2::new(
        mx - (c * qx - s * qy),
        my - (s * qx + c * qy),
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
        let got = align(&qa, &qb, &ma, &mb);
        assert!((got.x - pose.x).abs() < 1e-12 && (got.y - pose.y).abs() < 1e-12);
        assert!((got.theta - pose.theta).abs() < 1e-12);
    }
}
