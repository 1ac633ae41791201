//! Phase 1's loop closure after a blind stretch (issue 36). The batch binds a new track to a
//! landmark when the landmark projects within `rebind_px` of it from the dead-reckoned pose.
//! After a stretch with no lamp in view the dead-reckoned pose is far off (with 0.6 s of
//! memory in the odometry's errors, 3 to 4 degrees and 0.3 m after 15 m), so every lamp the
//! vehicle came back to was declined and became a second landmark, the batch's landmark budget
//! filled, and phase 1 handed over at the worst moment: the pose at 5 to 10 degrees of sigma,
//! and the filter closing the loop in linearised updates that left it several degrees off
//! with a tenth of a degree of sigma (docs/vehicle.md, "Dark stretches").
//!
//! Here the returning lamps are recognised as a constellation instead:
//!
//! - The stretch is measured ([`Blind`]) from the last frame that saw two landmarks of the map
//!   as it was before the stretch: landmarks born during it were placed from the drifting
//!   pose and re-anchor nothing.
//! - Once it is [`BLIND_MIN_M`] long, the tracks the per-observation test declines are
//!   triangulated in the dead-reckoned world and held for [`HOLD_FRAMES`] frames: lamps 4 m
//!   apart come back into view one at a time, and the dead reckoning over a few seconds is
//!   good enough to put them together.
//! - A rigid 2-D correction of the pose (a turn about the vehicle and a shift, each within
//!   what the stretch allows and never a lamp spacing) is sought that puts at least
//!   [`MIN_SUPPORT`] of them on distinct landmarks of the old map. Each hypothesis comes from
//!   two point-to-landmark pairings and is refined over its supporters (2-D Procrustes).
//! - It is then checked where the measurements are, in pixels: the correction refined by
//!   Gauss-Newton on the supporters' pixels (each seen from its own frame's corrected pose)
//!   must put every supporter within [`VERIFY_PX`] of its four coordinates, and the map must
//!   not contradict it (landmarks that would be well inside the images now but are not seen).
//! - Two distinct corrections that both pass mean a repeating pattern: none is taken.
//! - While the map has landmarks within reach of the declined tracks, they wait (at most
//!   [`DEFER_FRAMES`] frames) instead of becoming second landmarks, their measurements held
//!   like a tentative track's; a part of the hall seen for the first time is mapped at once.
//!
//! The batch then solves the loop with every frame (Gauss-Newton), the frames and landmarks of
//! the stretch started on the correction spread along it.
//!
//! Written here rather than shared with the navigator's relocaliser (`localize`): that one
//! scores hypotheses against a finished map with its lamp levels and triangle index; this one
//! has at most the batch's landmark budget of landmarks and needs no index.

use alloc::vec::Vec;

use nalgebra::{Vector2, Vector3};
use rig_model::camera::{CameraParams, Pose2, wrap_angle};
use rig_model::rig::{Measurement, project};

/// Extent ([`Blind::extent_m`]) of a stretch with fewer than two landmarks in view before a
/// declined track is tried as part of a constellation, metres.
pub(crate) const BLIND_MIN_M: f64 = 3.0;

/// Frames a blind vehicle's declined tracks wait for a constellation, when the map has
/// landmarks within reach of them, before they become new landmarks: five seconds at 20 Hz,
/// for lamps 4 m apart to come back into view two at a time.
pub(crate) const DEFER_FRAMES: usize = 100;

/// Frames a declined track is held for the constellation after it was last seen: five
/// seconds at 20 Hz (the heading drifts about a degree in that time with 0.6 s of memory in
/// the odometry's errors, 0.15 m at 8 m).
pub(crate) const HOLD_FRAMES: usize = 100;

/// Supporters a correction needs. Two points fix a turn and a shift; their eight pixel
/// coordinates checked from the corrected pose ([`VERIFY_PX`]) are the redundancy, and the
/// bounded correction keeps a lamp grid's other fits (a spacing away) out. Lamps 4 m apart
/// come back into view one at a time, seconds apart: waiting for a third kept the returning
/// lamps out for longer than phase 1 could wait.
pub(crate) const MIN_SUPPORT: usize = 2;

/// Horizontal distance within which a triangulated point supports a landmark, metres: a
/// lamp 8 m away triangulates with about 0.2 m of horizontal spread through a 12 cm baseline.
const MATCH_H_M: f64 = 0.4;

/// Height difference within which a triangulated point supports a landmark, metres (the
/// depth of a point 8 m away is known to about 0.4 m).
const MATCH_Z_M: f64 = 1.2;

/// Pixels within which a supporter's landmark must project from the corrected pose refined
/// on the supporters' pixels, each of its four coordinates (the batch's usual `rebind_px`):
/// a lamp 8 m away moved by 0.1 m moves 5 px, so a wrong pairing of a jittered grid's lamps
/// does not fit.
pub(crate) const VERIFY_PX: f64 = 6.0;

/// The shift a correction may make: this much, metres ...
const SHIFT_BASE_M: f64 = 0.3;
/// ... plus this fraction of the blind distance ...
const SHIFT_PER_M: f64 = 0.15;
/// ... and never more than this: well below the spacing of lamps (2.5 m and more), so that
/// a grid's neighbouring fit stays out of reach.
const SHIFT_MAX_M: f64 = 1.5;
/// The turn a correction may make: this much, radians (2 degrees) ...
const TURN_BASE_RAD: f64 = 0.035;
/// ... plus this much per metre blind (0.6 degrees) ...
const TURN_PER_M_RAD: f64 = 0.0105;
/// ... and never more than this (10 degrees).
const TURN_MAX_RAD: f64 = 0.175;

/// Two corrections closer than this (shift, metres; turn, radians) are the same one.
const SAME_SHIFT_M: f64 = 0.3;
const SAME_TURN_RAD: f64 = 0.035;

/// Metres of blind driving that a second standing blind counts as: the odometry's errors
/// turn the heading at a stop too (a yaw-rate error with memory does not stop with the
/// wheels), half as fast as at 1 m/s.
const BLIND_M_PER_S: f64 = 0.5;

/// How far the vehicle has gone without seeing the map.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Blind {
    /// Distance driven since the last frame with two or more landmarks in view, metres.
    pub(crate) distance_m: f64,
    /// Time since that frame, seconds.
    pub(crate) seconds: f64,
    /// Index (into the batch's frames) of that last frame.
    pub(crate) since_frame: Option<usize>,
    /// Index of the frame where the stretch became long enough to search
    /// ([`Blind::searching`]): landmarks born from then on were placed from a drifting pose
    /// and neither end the stretch nor are searched for.
    pub(crate) searching_since: Option<usize>,
    /// Consecutive frames whose declined tracks were held back waiting for a constellation.
    pub(crate) deferred: usize,
}

impl Blind {
    /// Whether a declined track is tried as part of a constellation.
    pub(crate) fn searching(&self) -> bool {
        self.extent_m() >= BLIND_MIN_M
    }

    /// The blind stretch's extent, metres: the distance driven and the time it took
    /// ([`BLIND_M_PER_S`]); the correction allowed grows with it.
    pub(crate) fn extent_m(&self) -> f64 {
        self.distance_m + BLIND_M_PER_S * self.seconds
    }
}

/// A point triangulated from a declined track: the track and the point in the dead-reckoned
/// world, with its measurement.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Declined {
    pub(crate) track: u64,
    pub(crate) world: Vector3<f64>,
    pub(crate) z: Measurement,
    /// The dead-reckoned pose of the frame it was measured in.
    pub(crate) pose: Pose2,
    /// That frame's index.
    pub(crate) frame: usize,
}

/// A correction found: the corrected pose and the declined tracks it binds, `(track,
/// landmark index)`.
#[derive(Debug, Clone)]
pub(crate) struct Closure {
    pub(crate) pose: Pose2,
    pub(crate) bound: Vec<(u64, usize)>,
}

/// `v` turned by `turn` radians.
fn rotated(turn: f64, v: &Vector2<f64>) -> Vector2<f64> {
    let (s, c) = libm::sincos(turn);
    Vector2::new(c * v.x - s * v.y, s * v.x + c * v.y)
}

/// A rigid 2-D correction: world points move by `p -> pivot + R(turn) (p - pivot) + shift`.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Correction {
    pub(crate) turn: f64,
    pub(crate) shift: Vector2<f64>,
}

impl Correction {
    pub(crate) fn apply(&self, pivot: &Vector2<f64>, p: &Vector2<f64>) -> Vector2<f64> {
        pivot + rotated(self.turn, &(p - pivot)) + self.shift
    }

    /// A pose moved by the correction.
    pub(crate) fn apply_pose(&self, pivot: &Vector2<f64>, pose: &Pose2) -> Pose2 {
        let p = self.apply(pivot, &Vector2::new(pose.x, pose.y));
        Pose2 {
            x: p.x,
            y: p.y,
            theta: wrap_angle(pose.theta + self.turn),
        }
    }

    fn same(&self, other: &Self) -> bool {
        (self.shift - other.shift).norm() <= SAME_SHIFT_M
            && libm::fabs(wrap_angle(self.turn - other.turn)) <= SAME_TURN_RAD
    }
}

/// The largest shift (metres) and turn (radians) of a correction after `blind_m` metres of
/// blind driving.
fn limits(blind_m: f64) -> (f64, f64) {
    (
        (SHIFT_BASE_M + SHIFT_PER_M * blind_m).min(SHIFT_MAX_M),
        (TURN_BASE_RAD + TURN_PER_M_RAD * blind_m).min(TURN_MAX_RAD),
    )
}

/// How far a declined point at `w` may be from its landmark under the largest correction a
/// pose `blind_m` metres blind allows, metres: the shift, the turn about the vehicle at the
/// point's distance, and the match distance.
fn reach(pose: &Pose2, blind_m: f64, w: &Vector2<f64>) -> f64 {
    let (max_shift, max_turn) = limits(blind_m);
    max_shift + (w - Vector2::new(pose.x, pose.y)).norm() * libm::sin(max_turn) + MATCH_H_M
}

/// Whether any of `landmarks` is within reach of a declined point: whether the map has
/// something where the vehicle came back to.
pub(crate) fn within_reach(
    pose: &Pose2,
    blind_m: f64,
    declined: &[Declined],
    landmarks: &[(usize, Vector3<f64>)],
) -> bool {
    declined.iter().any(|d| {
        let w = d.world.xy();
        let r = reach(pose, blind_m, &w);
        landmarks.iter().any(|(_, l)| (l.xy() - w).norm() <= r)
    })
}

/// Finds the correction of `pose` (dead-reckoned, `blind_m` metres since the map was last in
/// view) that binds the `declined` points to `landmarks` (index, position; the ones not seen
/// in this frame), or `None` when there is none or more than one (see the module docs).
pub(crate) fn find(
    camera: &CameraParams,
    pose: &Pose2,
    blind_m: f64,
    declined: &[Declined],
    landmarks: &[(usize, Vector3<f64>)],
    view: &View<'_>,
) -> Option<Closure> {
    if declined.len() < MIN_SUPPORT || landmarks.len() < MIN_SUPPORT {
        return None;
    }
    let pivot = Vector2::new(pose.x, pose.y);
    let (max_shift, max_turn) = limits(blind_m);
    // Landmarks a point may be, within the largest correction allowed.
    let candidates: Vec<Vec<usize>> = declined
        .iter()
        .map(|d| {
            let w = d.world.xy();
            let reach = reach(pose, blind_m, &w);
            landmarks
                .iter()
                .enumerate()
                .filter(|(_, (_, l))| {
                    (l.xy() - w).norm() <= reach && libm::fabs(l.z - d.world.z) <= MATCH_Z_M
                })
                .map(|(k, _)| k)
                .collect()
        })
        .collect();
    // Each correction that passed: the correction, the corrected pose, its supporters.
    type Passed = (Correction, Pose2, Vec<(usize, usize)>);
    let mut accepted: Vec<Passed> = Vec::new();
    for (a, da) in declined.iter().enumerate() {
        for (b, db) in declined.iter().enumerate().skip(a + 1) {
            let (wa, wb) = (da.world.xy(), db.world.xy());
            let sep = (wb - wa).norm();
            if sep < 2.0 * MATCH_H_M {
                continue;
            }
            for &ka in candidates.get(a).map_or(&[][..], Vec::as_slice) {
                for &kb in candidates.get(b).map_or(&[][..], Vec::as_slice) {
                    let (Some((_, la)), Some((_, lb))) = (landmarks.get(ka), landmarks.get(kb))
                    else {
                        continue;
                    };
                    if ka == kb || libm::fabs((lb.xy() - la.xy()).norm() - sep) > 2.0 * MATCH_H_M {
                        continue;
                    }
                    let dl = lb.xy() - la.xy();
                    let dw = wb - wa;
                    let turn = wrap_angle(libm::atan2(dl.y, dl.x) - libm::atan2(dw.y, dw.x));
                    if libm::fabs(turn) > max_turn {
                        continue;
                    }
                    let rough = Correction {
                        turn,
                        shift: Vector2::zeros(),
                    };
                    let mid_w = rough.apply(&pivot, &(0.5 * (wa + wb)));
                    let shift = 0.5 * (la.xy() + lb.xy()) - mid_w;
                    if shift.norm() > max_shift {
                        continue;
                    }
                    let hypothesis = Correction { turn, shift };
                    if accepted.iter().any(|(c, _, _)| c.same(&hypothesis)) {
                        continue;
                    }
                    let Some((refined, pairs)) = refine(
                        &hypothesis,
                        &pivot,
                        declined,
                        landmarks,
                        max_shift,
                        max_turn,
                    ) else {
                        continue;
                    };
                    if accepted.iter().any(|(c, _, _)| c.same(&refined)) {
                        continue;
                    }
                    let Some((corrected, verified)) =
                        verify(camera, pose, &refined, &pairs, declined, landmarks, view)
                    else {
                        continue;
                    };
                    if verified.len() >= MIN_SUPPORT {
                        accepted.push((refined, corrected, verified));
                        if accepted.len() > 1 {
                            // A repeating pattern: two places fit.
                            return None;
                        }
                    }
                }
            }
        }
    }
    let (_, corrected, pairs) = accepted.pop()?;
    Some(Closure {
        pose: corrected,
        bound: pairs
            .iter()
            .filter_map(|&(i, k)| Some((declined.get(i)?.track, landmarks.get(k)?.0)))
            .collect(),
    })
}

/// What the cameras saw in this frame: every feature pair's measurement (bound or not) and
/// the image size, for the negative evidence of a correction.
pub(crate) struct View<'a> {
    pub(crate) seen: &'a [Measurement],
    pub(crate) width: f64,
    pub(crate) height: f64,
}

/// Pixels from the image's edge inside which a landmark that projects there must have been
/// seen (a lamp at the very edge may be cut by the raw view or the detector's border).
const INNER_MARGIN_PX: f64 = 60.0;

/// The correction refined from `rough` on the supporters' pixels (Gauss-Newton over its
/// turn and shift, each supporter seen from its own frame's corrected pose), the supporters
/// whose four coordinates then lie within [`VERIFY_PX`], and the check that the map does not
/// contradict it: landmarks that project well inside both images from the corrected current
/// pose and have no feature of this frame near them count against it, and as many of them as
/// supporters (and at least two) refuse it. Returns the corrected current pose; `None` when
/// fewer than [`MIN_SUPPORT`] supporters verify or the map contradicts.
fn verify(
    camera: &CameraParams,
    pose: &Pose2,
    rough: &Correction,
    pairs: &[(usize, usize)],
    declined: &[Declined],
    landmarks: &[(usize, Vector3<f64>)],
    view: &View<'_>,
) -> Option<(Pose2, Vec<(usize, usize)>)> {
    let pivot = Vector2::new(pose.x, pose.y);
    let data: Vec<(&Declined, Vector3<f64>, (usize, usize))> = pairs
        .iter()
        .filter_map(|&(i, k)| Some((declined.get(i)?, landmarks.get(k)?.1, (i, k))))
        .collect();
    let mut c = *rough;
    for _ in 0..3 {
        c = refine_pixels(camera, &pivot, &c, &data)?;
    }
    let verified: Vec<(usize, usize)> = data
        .iter()
        .filter(|(d, l, _)| {
            project(camera, &c.apply_pose(&pivot, &d.pose), l)
                .is_ok_and(|p| (p - d.z).amax() <= VERIFY_PX)
        })
        .map(|(_, _, pair)| *pair)
        .collect();
    if verified.len() < MIN_SUPPORT {
        return None;
    }
    let now = c.apply_pose(&pivot, pose);
    let inside = |p: &Measurement| {
        let m = INNER_MARGIN_PX;
        [p[0], p[2]]
            .iter()
            .all(|u| (m..=view.width - m).contains(u))
            && [p[1], p[3]]
                .iter()
                .all(|v| (m..=view.height - m).contains(v))
    };
    let unseen = landmarks
        .iter()
        .filter(|(_, l)| {
            project(camera, &now, l).is_ok_and(|p| {
                inside(&p) && !view.seen.iter().any(|z| (p - z).amax() <= 2.0 * VERIFY_PX)
            })
        })
        .count();
    if unseen >= 2 && unseen >= verified.len() {
        return None;
    }
    Some((now, verified))
}

/// One Gauss-Newton step on the correction `(turn, shift)` over the pixel residuals of
/// `data` (each point seen from its frame's corrected pose), the Jacobian by central
/// differences; `None` when a landmark does not project or the normal equations are
/// singular.
fn refine_pixels(
    camera: &CameraParams,
    pivot: &Vector2<f64>,
    c: &Correction,
    data: &[(&Declined, Vector3<f64>, (usize, usize))],
) -> Option<Correction> {
    const STEP: [f64; 3] = [1e-5, 1e-4, 1e-4];
    let moved = |k: usize, h: f64| {
        let mut m = *c;
        match k {
            0 => m.turn += h,
            1 => m.shift.x += h,
            _ => m.shift.y += h,
        }
        m
    };
    let mut jtj = nalgebra::Matrix3::<f64>::zeros();
    let mut jtr = Vector3::<f64>::zeros();
    for (d, l, _) in data {
        let r = project(camera, &c.apply_pose(pivot, &d.pose), l).ok()? - d.z;
        let mut j = nalgebra::Matrix4x3::<f64>::zeros();
        for (k, h) in STEP.iter().enumerate() {
            let plus = project(camera, &moved(k, *h).apply_pose(pivot, &d.pose), l).ok()?;
            let minus = project(camera, &moved(k, -*h).apply_pose(pivot, &d.pose), l).ok()?;
            j.set_column(k, &((plus - minus) / (2.0 * h)));
        }
        jtj += j.transpose() * j;
        jtr += j.transpose() * r;
    }
    let step = jtj.cholesky()?.solve(&jtr);
    Some(Correction {
        turn: wrap_angle(c.turn - step.x),
        shift: Vector2::new(c.shift.x - step.y, c.shift.y - step.z),
    })
}

/// The supporters of `c` (each declined point's nearest landmark within the match distance,
/// each landmark once) and `c` refined over them by 2-D Procrustes; `None` below
/// [`MIN_SUPPORT`] or when the refined correction leaves the allowed range.
fn refine(
    c: &Correction,
    pivot: &Vector2<f64>,
    declined: &[Declined],
    landmarks: &[(usize, Vector3<f64>)],
    max_shift: f64,
    max_turn: f64,
) -> Option<(Correction, Vec<(usize, usize)>)> {
    let mut current = *c;
    let mut pairs: Vec<(usize, usize)> = Vec::new();
    for _ in 0..2 {
        pairs = supporters(&current, pivot, declined, landmarks);
        if pairs.len() < MIN_SUPPORT {
            return None;
        }
        // Procrustes about the pivot: the turn that best maps the points' offsets from their
        // centroid onto the landmarks', then the shift of the centroids.
        #[allow(clippy::cast_precision_loss)] // a handful of points
        let n = pairs.len() as f64;
        let (mut cw, mut cl) = (Vector2::zeros(), Vector2::zeros());
        for &(i, k) in &pairs {
            cw += declined.get(i)?.world.xy() - pivot;
            cl += landmarks.get(k)?.1.xy() - pivot;
        }
        cw /= n;
        cl /= n;
        let (mut sxx, mut sxy) = (0.0, 0.0);
        for &(i, k) in &pairs {
            let w = declined.get(i)?.world.xy() - pivot - cw;
            let l = landmarks.get(k)?.1.xy() - pivot - cl;
            sxx += w.dot(&l);
            sxy += w.x * l.y - w.y * l.x;
        }
        let turn = libm::atan2(sxy, sxx);
        let shift = cl - rotated(turn, &cw);
        if libm::fabs(turn) > max_turn || shift.norm() > max_shift {
            return None;
        }
        current = Correction { turn, shift };
    }
    Some((current, pairs))
}

/// Each declined point's nearest landmark under `c` within [`MATCH_H_M`] horizontally and
/// [`MATCH_Z_M`] in height, a landmark taken by one point at most (the nearer).
fn supporters(
    c: &Correction,
    pivot: &Vector2<f64>,
    declined: &[Declined],
    landmarks: &[(usize, Vector3<f64>)],
) -> Vec<(usize, usize)> {
    let mut best: Vec<(usize, usize, f64)> = Vec::new();
    for (i, d) in declined.iter().enumerate() {
        let w = c.apply(pivot, &d.world.xy());
        let nearest = landmarks
            .iter()
            .enumerate()
            .filter(|(_, (_, l))| libm::fabs(l.z - d.world.z) <= MATCH_Z_M)
            .map(|(k, (_, l))| (k, (l.xy() - w).norm()))
            .filter(|(_, dist)| *dist <= MATCH_H_M)
            .min_by(|a, b| a.1.total_cmp(&b.1));
        if let Some((k, dist)) = nearest {
            match best.iter_mut().find(|(_, kk, _)| *kk == k) {
                Some(entry) if entry.2 > dist => *entry = (i, k, dist),
                Some(_) => {}
                None => best.push((i, k, dist)),
            }
        }
    }
    best.into_iter().map(|(i, k, _)| (i, k)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn camera() -> CameraParams {
        CameraParams {
            vehicle: rig_model::Vehicle::default(),
            f: 450.0,
            cx: 376.0,
            cy: 240.0,
            baseline: 0.12,
            mount: rig_model::Mount {
                z: 1.0,
                ..rig_model::Mount::default()
            },
        }
    }

    /// Declined points of the lamps `lamps` seen from `truth`, in the world of `believed`
    /// (the dead-reckoned pose): what the batch triangulates after a blind stretch.
    fn declined(
        c: &CameraParams,
        truth: &Pose2,
        believed: &Pose2,
        lamps: &[Vector3<f64>],
    ) -> Vec<Declined> {
        lamps
            .iter()
            .enumerate()
            .filter_map(|(i, l)| {
                let z = project(c, truth, l).ok()?;
                let inside = [z[0], z[2]].iter().all(|u| (0.0..752.0).contains(u))
                    && [z[1], z[3]].iter().all(|v| (0.0..480.0).contains(v));
                if !inside {
                    return None;
                }
                let tri = rig_model::rig::triangulate(c, &z).ok()?;
                Some(Declined {
                    track: i as u64,
                    world: tri.p_in_world(c, believed),
                    z,
                    pose: *believed,
                    frame: 0,
                })
            })
            .collect()
    }

    /// Lamps every 2.5 m, 7 m up, jittered by up to 0.3 m (a pattern that does not repeat
    /// within the grid).
    fn grid() -> Vec<Vector3<f64>> {
        let mut v = Vec::new();
        for i in 0..10 {
            for j in 0..5 {
                let dx = 0.13 * f64::from((i * 7 + j * 3) % 5) - 0.26;
                let dy = 0.11 * f64::from((i * 3 + j * 5) % 4) - 0.16;
                v.push(Vector3::new(
                    2.5 * f64::from(i) + dx,
                    2.5 * f64::from(j) - 5.0 + dy,
                    7.0,
                ));
            }
        }
        v
    }

    /// The vehicle's true pose, and the pose it believes after a blind stretch: 0.5 m and
    /// 3.4 degrees off.
    fn drifted() -> (Pose2, Pose2) {
        let truth = Pose2 {
            x: 11.0,
            y: 0.5,
            theta: 0.1,
        };
        let believed = Pose2 {
            x: 11.4,
            y: 0.2,
            theta: 0.1 + 0.06,
        };
        (truth, believed)
    }

    #[test]
    fn a_drifted_pose_is_corrected_onto_the_lamps_it_sees_again() {
        let c = camera();
        let lamps = grid();
        let (truth, believed) = drifted();
        let d = declined(&c, &truth, &believed, &lamps);
        assert!(d.len() >= 3, "{} lamps in view", d.len());
        let map: Vec<(usize, Vector3<f64>)> = lamps.iter().copied().enumerate().collect();
        let closure = find(&c, &believed, 15.0, &d, &map, &view(&d)).expect("a closure");
        assert!(
            (closure.pose.x - truth.x).abs() < 0.05,
            "{:?}",
            closure.pose
        );
        assert!(
            (closure.pose.y - truth.y).abs() < 0.05,
            "{:?}",
            closure.pose
        );
        assert!(wrap_angle(closure.pose.theta - truth.theta).abs() < 0.005);
        assert!(closure.bound.len() >= 3);
        for (track, k) in &closure.bound {
            assert_eq!(*track as usize, *k, "track {track} bound to lamp {k}");
        }
    }

    #[test]
    fn too_short_a_blind_stretch_allows_no_large_correction() {
        let c = camera();
        let lamps = grid();
        let (truth, believed) = drifted();
        let d = declined(&c, &truth, &believed, &lamps);
        let map: Vec<(usize, Vector3<f64>)> = lamps.iter().copied().enumerate().collect();
        assert!(find(&c, &believed, 0.0, &d, &map, &view(&d)).is_none());
    }

    #[test]
    fn new_lamps_bind_to_nothing() {
        let c = camera();
        let lamps = grid();
        // The vehicle sees lamps that are not in the map (the map holds others, 40 m away).
        let far: Vec<(usize, Vector3<f64>)> = lamps
            .iter()
            .map(|l| l + Vector3::new(60.0, 0.0, 0.0))
            .enumerate()
            .collect();
        let pose = Pose2 {
            x: 11.0,
            y: 0.5,
            theta: 0.1,
        };
        let d = declined(&c, &pose, &pose, &lamps);
        let found = find(&c, &pose, 15.0, &d, &far, &view(&d));
        assert!(found.is_none(), "{found:?} declined {d:?}");
    }

    #[test]
    fn a_regular_grid_that_fits_two_ways_binds_nothing() {
        let c = camera();
        // Lamps every 2 m in a row: a shift by one spacing fits as well as none.
        let lamps: Vec<Vector3<f64>> = (0..12)
            .map(|i| Vector3::new(2.0 * f64::from(i), 0.0, 7.0))
            .collect();
        let truth = Pose2 {
            x: 10.0,
            y: 0.0,
            theta: 0.0,
        };
        let believed = Pose2 {
            x: 10.9,
            y: 0.0,
            theta: 0.0,
        };
        let d = declined(&c, &truth, &believed, &lamps);
        let map: Vec<(usize, Vector3<f64>)> = lamps.iter().copied().enumerate().collect();
        assert!(find(&c, &believed, 15.0, &d, &map, &view(&d)).is_none());
    }

    fn seen(d: &[Declined]) -> Vec<Measurement> {
        d.iter().map(|d| d.z).collect()
    }

    fn view(d: &[Declined]) -> View<'static> {
        View {
            seen: Box::leak(seen(d).into_boxed_slice()),
            width: 752.0,
            height: 480.0,
        }
    }
}
