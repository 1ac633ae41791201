//! A changing hall: lamps of the map that should be seen and are not, and lamps that are not
//! in the map. Neither ever touches the pose: a missing lamp is only counted, a new one is
//! triangulated from the localised pose and tracked as a candidate.

use alloc::collections::BTreeMap;
use alloc::vec::Vec;

use nalgebra::{Matrix3, Vector3};
use rig_model::camera::{CameraParams, Pose2};
use rig_model::triangulate;

use crate::map::LampMap;
use crate::view::Observation;

/// How often each map lamp was expected in view and seen, while localised.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LampCounts {
    /// Frames each lamp (by map index) was expected in view.
    pub expected: Vec<u32>,
    /// Frames it was associated.
    pub seen: Vec<u32>,
}

impl LampCounts {
    /// Zero counts for `n` lamps.
    pub fn new(n: usize) -> Self {
        Self {
            expected: alloc::vec![0; n],
            seen: alloc::vec![0; n],
        }
    }

    /// One localised frame: the lamps expected and the ones associated. A lamp expected and
    /// not seen while a map lamp within `twin_m` of it was seen is not counted: a map holds
    /// some lamps twice (two landmarks for one lamp), and the observation goes to one of them.
    pub fn add(&mut self, map: &LampMap, expected: &[u32], seen: &[(u32, usize)], twin_m: f64) {
        let near = |a: u32, b: u32| match (map.lamp(a), map.lamp(b)) {
            (Some(p), Some(q)) => {
                libm::hypot(p.position.x - q.position.x, p.position.y - q.position.y) <= twin_m
            }
            _ => false,
        };
        for &i in expected {
            let taken = seen.iter().any(|&(j, _)| j == i);
            if !taken && seen.iter().any(|&(j, _)| near(i, j)) {
                continue;
            }
            if let Some(n) = self.expected.get_mut(i as usize) {
                *n += 1;
            }
        }
        for &(i, _) in seen {
            if let Some(n) = self.seen.get_mut(i as usize) {
                *n += 1;
            }
        }
    }

    /// Map indices of the lamps expected at least `min_expected` times and seen in at most
    /// `max_fraction` of them.
    pub fn missing(&self, min_expected: u32, max_fraction: f64) -> Vec<u32> {
        self.expected
            .iter()
            .zip(&self.seen)
            .enumerate()
            .filter(|&(_, (&e, &s))| {
                e >= min_expected && f64::from(s) <= max_fraction * f64::from(e)
            })
            .filter_map(|(i, _)| u32::try_from(i).ok())
            .collect()
    }
}

/// A lamp that is not in the map, as fused so far.
#[derive(Debug, Clone, PartialEq)]
pub struct NewLamp {
    /// Position in the map's frame, metres.
    pub position: Vector3<f64>,
    /// Its covariance, m^2.
    pub covariance: Matrix3<f64>,
    /// Observations fused.
    pub observations: u32,
    /// First and last time seen, microseconds.
    pub seen_us: (u64, u64),
}

#[derive(Debug, Clone)]
struct Candidate {
    information: Matrix3<f64>,
    eta: Vector3<f64>,
    observations: u32,
    seen_us: (u64, u64),
}

impl Candidate {
    fn estimate(&self) -> Option<(Vector3<f64>, Matrix3<f64>)> {
        let cov = self.information.try_inverse()?;
        Some((cov * self.eta, cov))
    }
}

/// Candidates for new lamps: unassociated, confirmed tracks triangulated from the localised
/// pose and fused (information form) per candidate, a track bound to its candidate.
#[derive(Debug, Clone, Default)]
pub struct NewLamps {
    candidates: Vec<Candidate>,
    by_track: BTreeMap<u64, usize>,
}

/// Most candidates held (the oldest weak ones go first).
const MAX_CANDIDATES: usize = 512;

/// Gate of a triangulation against a candidate (3 dof, 0.999).
const CANDIDATE_GATE: f64 = 16.27;

impl NewLamps {
    /// Adds the observations of this localised frame that no map lamp took: each one's
    /// triangulation (with the pose's uncertainty and the pixel noise `sigma_px` through the
    /// lenses, `pixel_noise`) fused into its track's candidate, or the
    /// candidate it falls on, or a new one.
    #[allow(clippy::too_many_arguments)] // the frame's pose, its noise and its leftovers
    pub fn add(
        &mut self,
        c: &CameraParams,
        pose: &Pose2,
        pose_cov: &Matrix3<f64>,
        sigma_px: f64,
        pixel_noise: &rig_model::lens::PixelNoise,
        unmatched: &[Observation],
        t_us: u64,
    ) {
        for o in unmatched.iter().filter(|o| o.confirmed) {
            let Ok(tri) = triangulate(c, &o.z) else {
                continue;
            };
            let p = tri.p_in_world(c, pose);
            let cov = if pixel_noise.is_uniform() {
                tri.covariance_in_world(c, pose, sigma_px, Some(pose_cov), None)
            } else {
                let r = pixel_noise.gains(&o.z) * (sigma_px * sigma_px);
                tri.covariance_in_world_of(c, pose, &r, Some(pose_cov), None)
            };
            let Some(info) = cov.try_inverse() else {
                continue;
            };
            let slot = self.by_track.get(&o.track).copied().or_else(|| {
                self.candidates
                    .iter()
                    .enumerate()
                    .filter_map(|(k, cand)| {
                        let (q, qc) = cand.estimate()?;
                        let d = p - q;
                        let s = (qc + cov).try_inverse()?;
                        let d2 = (d.transpose() * s * d)[(0, 0)];
                        (d2 <= CANDIDATE_GATE).then_some((k, d2))
                    })
                    .min_by(|a, b| a.1.total_cmp(&b.1))
                    .map(|(k, _)| k)
            });
            match slot.and_then(|k| self.candidates.get_mut(k).map(|c| (k, c))) {
                Some((k, cand)) => {
                    cand.information += info;
                    cand.eta += info * p;
                    cand.observations += 1;
                    cand.seen_us.1 = t_us;
                    self.by_track.insert(o.track, k);
                }
                None => {
                    if self.candidates.len() >= MAX_CANDIDATES {
                        self.evict();
                    }
                    self.candidates.push(Candidate {
                        information: info,
                        eta: info * p,
                        observations: 1,
                        seen_us: (t_us, t_us),
                    });
                    self.by_track.insert(o.track, self.candidates.len() - 1);
                }
            }
        }
    }

    /// Drops the candidate with the fewest observations (the oldest among equals) and
    /// re-binds the tracks.
    fn evict(&mut self) {
        let Some((k, _)) = self
            .candidates
            .iter()
            .enumerate()
            .min_by_key(|(_, c)| (c.observations, c.seen_us.1))
        else {
            return;
        };
        self.candidates.swap_remove(k);
        let moved = self.candidates.len();
        self.by_track.retain(|_, v| *v != k);
        for v in self.by_track.values_mut() {
            if *v == moved {
                *v = k;
            }
        }
    }

    /// The candidates that count as new lamps: seen often enough, known well enough, and not
    /// on a map lamp.
    pub fn confirmed(
        &self,
        map: &LampMap,
        min_observations: u32,
        max_sigma_m: f64,
        min_separation_m: f64,
    ) -> Vec<NewLamp> {
        let mut scratch = Vec::new();
        let mut found: Vec<NewLamp> = self
            .candidates
            .iter()
            .filter(|c| c.observations >= min_observations)
            // Seen over 2 s at least: not the last frames of a pose that was going wrong.
            .filter(|c| c.seen_us.1.saturating_sub(c.seen_us.0) >= 2_000_000)
            .filter_map(|c| {
                let (p, cov) = c.estimate()?;
                let sigma = libm::sqrt(cov[(0, 0)].max(cov[(1, 1)]).max(cov[(2, 2)]).max(0.0));
                if sigma > max_sigma_m {
                    return None;
                }
                if map
                    .nearest(p.x, p.y, min_separation_m, &mut scratch)
                    .is_some()
                {
                    return None;
                }
                Some(NewLamp {
                    position: p,
                    covariance: cov,
                    observations: c.observations,
                    seen_us: c.seen_us,
                })
            })
            .collect();
        // Two candidates of one lamp (two tracks that never met): the better seen one stays.
        found.sort_by_key(|l| core::cmp::Reverse(l.observations));
        let mut kept: Vec<NewLamp> = Vec::with_capacity(found.len());
        for l in found {
            let twin = kept.iter().any(|k| {
                libm::hypot(k.position.x - l.position.x, k.position.y - l.position.y)
                    < min_separation_m
            });
            if !twin {
                kept.push(l);
            }
        }
        kept
    }
}
