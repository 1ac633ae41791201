//! Left-right matching on the rectified rig (vehicle-interfaces.md section 1: `vR = vL`,
//! disparity `uL - uR = f B / zs > 0`).
//!
//! **Candidates.** A left feature `(uL, vL)` and a right feature `(uR, vR)` may be one lamp
//! when
//! * their rows agree: `|vL - vR| <= row_gate_sigmas * sigma_row`, where
//!   `sigma_row = sqrt(2 (sigma_px^2 + 1/16^2/12))` is the standard deviation of the difference
//!   of two independent, Q12.4-rounded rows (the pixel noise comes from the rig file);
//! * their disparity `d = uL - uR` is positive and puts the lamp between the nearest and the
//!   farthest plausible depth: `f B / max_depth_m <= d <= f B / min_depth_m` with the model's
//!   current `f` and `B`. The range should be generous: before calibration `f B` may be a few
//!   percent off.
//!
//! **Assignment.** The cost of a candidate is its row difference `|vL - vR|`. A pair is kept
//! only when each is the other's best candidate (mutual best, so the result does not depend on
//! the order of the features) and neither has a second candidate within
//! `ambiguity_sigmas * sigma_row` of the best: two candidates about equally good are an
//! ambiguity that the rows cannot settle (two lamps on one row, a reflection next to a lamp),
//! and a dropped measurement costs far less downstream than a wrong one.
//!
//! The matcher sorts the right features by row once and scans only the row window of each
//! left feature: `O((nL + nR) log nR)` plus the candidates, for the board's up to 1023
//! features per image.

use alloc::vec::Vec;

use rig_model::Measurement;

use crate::error::{SettingsError, check_real};
use crate::model::Model;

/// One feature's position in pixels (board coordinates: `u = x_q4 / 16`, `v = y_q4 / 16`).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Pixel {
    /// Column, pixels.
    pub u: f64,
    /// Row, pixels.
    pub v: f64,
}

/// Q12.4 fixed point: pixels are `value / 2^4` (board-icd.md, feature record).
const Q4_SCALE: f64 = 16.0;

impl Pixel {
    /// A position in pixels.
    pub const fn new(u: f64, v: f64) -> Self {
        Self { u, v }
    }

    /// A board feature's position: `u = x_q4 / 16`, `v = y_q4 / 16`.
    pub fn from_q4(x_q4: u16, y_q4: u16) -> Self {
        Self {
            u: f64::from(x_q4) / Q4_SCALE,
            v: f64::from(y_q4) / Q4_SCALE,
        }
    }

    fn is_finite(&self) -> bool {
        self.u.is_finite() && self.v.is_finite()
    }
}

/// One camera's board features mapped through its lens ([`rectify_features`]).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct RectifiedSide {
    /// The features the lens could map, rectified pixels, in the board's order.
    pub pixels: Vec<Pixel>,
    /// For each of them, its index in the board's (raw) list: the features dropped leave gaps.
    pub raw_index: Vec<usize>,
}

/// Both cameras' board features mapped through the rig's lenses ([`rectify_features`]).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct RectifiedFeatures {
    /// The left camera's.
    pub left: RectifiedSide,
    /// The right camera's.
    pub right: RectifiedSide,
    /// Features the lens could not map (dropped), both cameras.
    pub dropped: u64,
    /// Features mapped, but outside the field of use (left out), both cameras.
    pub outside_field: u64,
}

/// The board's raw features of both cameras mapped into the rectified model through the
/// rig's lens (vehicle-interfaces.md 1.1), each with its index in the board's list, the
/// count of features the lens could not map (dropped) and of those whose ray lies more than
/// `max_off_axis_rad` from the rectified optical axis (outside the field of use; `pi / 2` or
/// more keeps every ray in front of the camera); `None` for a rig without `[lens]` tables
/// (its features are rectified already).
///
/// The field of use exists for wide lenses: a fisheye's raw image reaches rays far from the
/// axis, whose rectified pixels carry the raw noise stretched many times and bias the
/// estimate of the map's scale (docs/halls.md, "A fisheye's outer band").
pub fn rectify_features(
    rig: &rig_model::config::Rig,
    left: &[Pixel],
    right: &[Pixel],
    max_off_axis_rad: f64,
) -> Option<RectifiedFeatures> {
    let lens = rig.lens.as_ref()?;
    let c = &rig.nominal;
    let field = rig_model::lens::FieldOfUse::new(max_off_axis_rad, c.f, c.cx, c.cy);
    let mut dropped = 0;
    let mut outside_field = 0;
    let mut map = |lens: &rig_model::lens::Lens, side: &[Pixel]| -> RectifiedSide {
        let mut out = RectifiedSide::default();
        for (i, p) in side.iter().enumerate() {
            match lens.rectify_point(nalgebra::Vector2::new(p.u, p.v), c.f, c.cx, c.cy) {
                Some(q) if field.contains(q.x, q.y) => {
                    out.pixels.push(Pixel { u: q.x, v: q.y });
                    out.raw_index.push(i);
                }
                Some(_) => outside_field += 1,
                None => dropped += 1,
            }
        }
        out
    };
    let left = map(&lens.left, left);
    let right = map(&lens.right, right);
    Some(RectifiedFeatures {
        left,
        right,
        dropped,
        outside_field,
    })
}

/// The largest row-noise gain of one image's features (1 without a lens).
fn max_row_gain(model: &Model, left: bool, features: &[Pixel]) -> f64 {
    if model.pixel_noise.is_uniform() {
        return 1.0;
    }
    features
        .iter()
        .filter(|p| p.is_finite())
        .map(|p| model.pixel_noise.point_gains(left, p.u, p.v).1)
        .fold(1.0, f64::max)
}

/// Settings of the left-right matching.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StereoSettings {
    /// Row gate, in standard deviations of the row difference `vL - vR`.
    pub row_gate_sigmas: f64,
    /// Two candidates whose row differences lie within this many standard deviations of each
    /// other are ambiguous: the feature is dropped.
    pub ambiguity_sigmas: f64,
    /// Nearest plausible lamp depth along the optical axis, metres (sets the largest
    /// disparity).
    pub min_depth_m: f64,
    /// Farthest plausible lamp depth, metres (sets the smallest disparity; may be infinite).
    pub max_depth_m: f64,
}

impl Default for StereoSettings {
    /// 3-sigma rows, 1-sigma ambiguity margin, lamps 1 to 50 m from the cameras (a forklift's
    /// ceiling lamps are 2 to 10 m away).
    fn default() -> Self {
        Self {
            row_gate_sigmas: 3.0,
            ambiguity_sigmas: 1.0,
            min_depth_m: 1.0,
            max_depth_m: 50.0,
        }
    }
}

impl StereoSettings {
    /// Checks every field.
    pub fn validate(&self) -> Result<(), SettingsError> {
        check_real(
            "stereo.row_gate_sigmas",
            self.row_gate_sigmas,
            0.0,
            true,
            "positive and finite",
        )?;
        check_real(
            "stereo.ambiguity_sigmas",
            self.ambiguity_sigmas,
            0.0,
            false,
            "at least 0 and finite",
        )?;
        check_real(
            "stereo.min_depth_m",
            self.min_depth_m,
            0.0,
            true,
            "positive and finite",
        )?;
        if self.max_depth_m.is_nan() || self.max_depth_m <= self.min_depth_m {
            return Err(SettingsError::Real {
                name: "stereo.max_depth_m",
                value: self.max_depth_m,
                expected: "greater than stereo.min_depth_m (may be infinite)",
            });
        }
        Ok(())
    }
}

/// One left-right match.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StereoMatch {
    /// Index of the left feature in the frame's left list.
    pub left: usize,
    /// Index of the right feature in the frame's right list.
    pub right: usize,
    /// `(uL, vL, uR, vR)`, pixels.
    pub measurement: Measurement,
}

/// Counters of the matching, per frame or summed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Hash)]
pub struct StereoStats {
    /// Left features offered (finite ones).
    pub left: u64,
    /// Right features offered (finite ones).
    pub right: u64,
    /// Left-right candidates inside the row gate and the disparity range.
    pub candidates: u64,
    /// Matches made.
    pub matches: u64,
    /// Left features dropped because their best candidate had a rival within the ambiguity
    /// margin (on either side).
    pub ambiguous: u64,
    /// Left features whose best right feature preferred another left feature.
    pub not_mutual: u64,
}

impl StereoStats {
    /// Adds another frame's counters.
    pub fn add(&mut self, other: &Self) {
        self.left += other.left;
        self.right += other.right;
        self.candidates += other.candidates;
        self.matches += other.matches;
        self.ambiguous += other.ambiguous;
        self.not_mutual += other.not_mutual;
    }
}

/// The best and second-best candidate costs of one feature.
#[derive(Debug, Clone, Copy, Default)]
struct Best {
    first: Option<(f64, usize)>,
    second: Option<f64>,
}

impl Best {
    fn offer(&mut self, cost: f64, index: usize) {
        match self.first {
            Some((best, _)) if cost >= best => {
                self.second = Some(self.second.map_or(cost, |s| s.min(cost)));
            }
            Some((best, _)) => {
                self.second = Some(best);
                self.first = Some((cost, index));
            }
            None => self.first = Some((cost, index)),
        }
    }

    /// Whether the best is better than the runner-up by more than `margin`.
    fn clear(&self, margin: f64) -> bool {
        match (self.first, self.second) {
            (Some((best, _)), Some(second)) => second - best > margin,
            _ => true,
        }
    }
}

/// Left-right matcher; holds its scratch buffers so that matching a frame does not allocate
/// once they have grown.
#[derive(Debug, Clone)]
pub struct StereoMatcher {
    settings: StereoSettings,
    /// Right features `(v, index)` sorted by row.
    by_row: Vec<(f64, usize)>,
    best_left: Vec<Best>,
    best_right: Vec<Best>,
}

impl StereoMatcher {
    /// A matcher with these settings.
    pub fn new(settings: StereoSettings) -> Result<Self, SettingsError> {
        settings.validate()?;
        Ok(Self {
            settings,
            by_row: Vec::new(),
            best_left: Vec::new(),
            best_right: Vec::new(),
        })
    }

    /// The settings.
    pub fn settings(&self) -> &StereoSettings {
        &self.settings
    }

    /// Standard deviation of the row difference `vL - vR` under `model`, pixels.
    pub fn row_sigma_px(model: &Model) -> f64 {
        libm::sqrt(2.0 * model.pixel_variance_px2())
    }

    /// Matches one stereo frame's features; `out` is cleared and receives the matches in the
    /// order of the left features. NaN or infinite positions are ignored.
    pub fn match_frame(
        &mut self,
        model: &Model,
        left: &[Pixel],
        right: &[Pixel],
        out: &mut Vec<StereoMatch>,
    ) -> StereoStats {
        out.clear();
        let mut stats = StereoStats::default();
        let sigma_row = Self::row_sigma_px(model);
        let tolerance = self.settings.row_gate_sigmas * sigma_row;
        let margin = self.settings.ambiguity_sigmas * sigma_row;
        // The rows searched: the gate of the most stretched pair (gains of 1 without a lens).
        let window = tolerance
            * libm::sqrt(
                0.5 * (max_row_gain(model, true, left) + max_row_gain(model, false, right)),
            );
        let fb = model.camera.f * model.camera.baseline;
        // d = f B / z; an infinite max depth gives 0 (then only d > 0 is required).
        let (d_min, d_max) = (
            fb / self.settings.max_depth_m,
            fb / self.settings.min_depth_m,
        );

        self.by_row.clear();
        self.by_row.extend(
            right
                .iter()
                .enumerate()
                .filter(|(_, p)| p.is_finite())
                .map(|(j, p)| (p.v, j)),
        );
        self.by_row
            .sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        stats.right = self.by_row.len() as u64;
        self.best_left.clear();
        self.best_left.resize(left.len(), Best::default());
        self.best_right.clear();
        self.best_right.resize(right.len(), Best::default());
        if !(fb.is_finite() && fb > 0.0 && tolerance.is_finite()) {
            stats.left = left.iter().filter(|p| p.is_finite()).count() as u64;
            return stats;
        }

        for (i, l) in left.iter().enumerate() {
            if !l.is_finite() {
                continue;
            }
            stats.left += 1;
            let lo = self.by_row.partition_point(|(v, _)| *v < l.v - window);
            for &(v, j) in self.by_row.iter().skip(lo) {
                if v > l.v + window {
                    break;
                }
                let Some(r) = right.get(j) else { continue };
                let d = l.u - r.u;
                // Through a lens the window is widened by the pair's own disparity noise (the
                // row gate's sigmas): far from the axis a fisheye stretches it past the
                // disparity itself, and a window that cut it off kept the pairs whose noise
                // made them nearer, which shrank the map (docs/halls.md). Without a lens the
                // window is the depth range's.
                let slack = if model.pixel_noise.is_uniform() {
                    0.0
                } else {
                    let (gl, _) = model.pixel_noise.point_gains(true, l.u, l.v);
                    let (gr, _) = model.pixel_noise.point_gains(false, r.u, r.v);
                    self.settings.row_gate_sigmas
                        * libm::sqrt((gl + gr) * model.pixel_variance_px2())
                };
                if !((slack > 0.0 || d > 0.0) && d >= d_min - slack && d <= d_max + slack) {
                    continue;
                }
                let mut cost = libm::fabs(l.v - v);
                if !model.pixel_noise.is_uniform() {
                    // The row gate in this pair's own sigma (a lens stretches the rows'
                    // noise unequally), in pixels of the base sigma.
                    let (_, gl) = model.pixel_noise.point_gains(true, l.u, l.v);
                    let (_, gr) = model.pixel_noise.point_gains(false, r.u, r.v);
                    cost *= libm::sqrt(2.0 / (gl + gr));
                    if cost > tolerance {
                        continue;
                    }
                }
                stats.candidates += 1;
                if let Some(b) = self.best_left.get_mut(i) {
                    b.offer(cost, j);
                }
                if let Some(b) = self.best_right.get_mut(j) {
                    b.offer(cost, i);
                }
            }
        }

        for (i, (best, l)) in self.best_left.iter().zip(left).enumerate() {
            let Some((_, j)) = best.first else { continue };
            let (Some(rb), Some(r)) = (self.best_right.get(j), right.get(j)) else {
                continue;
            };
            if rb.first.map(|(_, back)| back) != Some(i) {
                stats.not_mutual += 1;
            } else if !(best.clear(margin) && rb.clear(margin)) {
                stats.ambiguous += 1;
            } else {
                out.push(StereoMatch {
                    left: i,
                    right: j,
                    measurement: Measurement::new(l.u, l.v, r.u, r.v),
                });
            }
        }
        stats.matches = out.len() as u64;
        stats
    }
}

#[cfg(test)]
#[allow(clippy::indexing_slicing, clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::model::tests::rig;
    use alloc::vec;
    use proptest::prelude::*;

    fn matcher() -> StereoMatcher {
        StereoMatcher::new(StereoSettings::default()).unwrap()
    }

    fn pairs(out: &[StereoMatch]) -> Vec<(usize, usize)> {
        out.iter().map(|m| (m.left, m.right)).collect()
    }

    #[test]
    fn matches_on_rows_within_the_disparity_range() {
        let model = Model::from_rig(&rig());
        // f B = 84 px m: depths 1..50 m give disparities 1.68..84 px.
        let left = [
            Pixel::new(300.0, 100.0), // partner at d = 30
            Pixel::new(500.0, 200.0), // partner at d = 90: too near
            Pixel::new(200.0, 300.0), // partner 1.5 px off the row: outside 3 sigma (1.28 px)
            Pixel::new(100.0, 400.0), // partner at d = -5
            Pixel::new(600.0, 50.0),  // partner at d = 1: farther than 50 m
        ];
        let right = [
            Pixel::new(270.0, 100.3),
            Pixel::new(410.0, 200.0),
            Pixel::new(180.0, 301.5),
            Pixel::new(105.0, 400.0),
            Pixel::new(599.0, 50.0),
        ];
        let mut out = Vec::new();
        let stats = matcher().match_frame(&model, &left, &right, &mut out);
        assert_eq!(pairs(&out), vec![(0, 0)]);
        assert_eq!(
            out[0].measurement,
            Measurement::new(300.0, 100.0, 270.0, 100.3)
        );
        assert_eq!((stats.left, stats.right, stats.candidates), (5, 5, 1));
    }

    #[test]
    fn equally_good_candidates_are_dropped_and_clear_ones_kept() {
        let model = Model::from_rig(&rig());
        // Left 0 has two right candidates on its row, 0.1 px apart in row difference: dropped.
        // Left 1 has two, one exact and one 1 px off (beyond the 0.42 px margin): matched.
        let left = [Pixel::new(300.0, 100.0), Pixel::new(300.0, 200.0)];
        let right = [
            Pixel::new(280.0, 100.2),
            Pixel::new(260.0, 99.9),
            Pixel::new(280.0, 200.0),
            Pixel::new(250.0, 201.0),
        ];
        let mut out = Vec::new();
        let stats = matcher().match_frame(&model, &left, &right, &mut out);
        assert_eq!(pairs(&out), vec![(1, 2)]);
        assert_eq!(stats.ambiguous, 1);
        // Two left features wanting one right feature equally: neither gets it.
        let left = [Pixel::new(300.0, 100.1), Pixel::new(320.0, 99.9)];
        let right = [Pixel::new(280.0, 100.0)];
        matcher().match_frame(&model, &left, &right, &mut out);
        assert!(out.is_empty());
    }

    #[test]
    fn mutual_best_settles_a_shared_candidate() {
        let model = Model::from_rig(&rig());
        // Right 0 is the best of both lefts; left 0 is right 0's best. Left 1 then has no
        // match (its best was taken), and right 1 (its second) is not guessed either.
        let left = [Pixel::new(300.0, 100.0), Pixel::new(330.0, 101.0)];
        let right = [Pixel::new(280.0, 100.0), Pixel::new(290.0, 102.2)];
        let mut out = Vec::new();
        let stats = matcher().match_frame(&model, &left, &right, &mut out);
        assert_eq!(pairs(&out), vec![(0, 0)]);
        assert_eq!(stats.not_mutual, 1);
    }

    #[test]
    fn nan_inputs_and_a_broken_camera_give_no_matches() {
        let mut model = Model::from_rig(&rig());
        let left = [
            Pixel::new(f64::NAN, 100.0),
            Pixel::new(300.0, f64::INFINITY),
        ];
        let right = [Pixel::new(280.0, f64::NAN), Pixel::new(280.0, 100.0)];
        let mut out = Vec::new();
        let stats = matcher().match_frame(&model, &left, &right, &mut out);
        assert!(out.is_empty());
        assert_eq!((stats.left, stats.right), (0, 1));
        let ok = [Pixel::new(300.0, 100.0)];
        for f in [f64::NAN, -700.0, 0.0, f64::INFINITY] {
            model.camera.f = f;
            matcher().match_frame(&model, &ok, &right, &mut out);
            assert!(out.is_empty(), "f = {f}");
        }
        model.camera.f = 700.0;
        model.noise.pixel = f64::NAN;
        matcher().match_frame(&model, &ok, &right, &mut out);
        assert_eq!(pairs(&out), vec![(0, 1)]);
    }

    #[test]
    fn settings_are_checked() {
        let bad = [
            StereoSettings {
                row_gate_sigmas: f64::NAN,
                ..StereoSettings::default()
            },
            StereoSettings {
                ambiguity_sigmas: -1.0,
                ..StereoSettings::default()
            },
            StereoSettings {
                min_depth_m: 0.0,
                ..StereoSettings::default()
            },
            StereoSettings {
                max_depth_m: 0.5,
                ..StereoSettings::default()
            },
        ];
        for s in bad {
            let e = StereoMatcher::new(s).unwrap_err();
            assert!(alloc::format!("{e}").contains("stereo."), "{e}");
        }
        let infinite = StereoSettings {
            max_depth_m: f64::INFINITY,
            ..StereoSettings::default()
        };
        assert!(StereoMatcher::new(infinite).is_ok());
    }

    proptest! {
        /// Any input: no panic, one-to-one, every match inside the gates, and the result does
        /// not depend on the order of the right features.
        #[test]
        fn one_to_one_inside_the_gates_and_order_free(
            l in proptest::collection::vec((0.0f64..752.0, 0.0f64..480.0), 0..40),
            r in proptest::collection::vec((0.0f64..752.0, 0.0f64..480.0), 0..40),
        ) {
            let model = Model::from_rig(&rig());
            let left: Vec<Pixel> = l.iter().map(|&(u, v)| Pixel::new(u, v)).collect();
            let right: Vec<Pixel> = r.iter().map(|&(u, v)| Pixel::new(u, v)).collect();
            let mut out = Vec::new();
            matcher().match_frame(&model, &left, &right, &mut out);
            let mut seen_r = vec![false; right.len()];
            let tol = 3.0 * StereoMatcher::row_sigma_px(&model);
            for m in &out {
                prop_assert!(!seen_r[m.right]);
                seen_r[m.right] = true;
                let d = m.measurement[0] - m.measurement[2];
                prop_assert!(d > 0.0 && d <= 84.0 + 1e-9);
                prop_assert!((m.measurement[1] - m.measurement[3]).abs() <= tol);
            }
            let reversed: Vec<Pixel> = right.iter().rev().copied().collect();
            let mut out2 = Vec::new();
            matcher().match_frame(&model, &left, &reversed, &mut out2);
            let n = right.len();
            let mapped: Vec<(usize, usize)> = out2.iter().map(|m| (m.left, n - 1 - m.right)).collect();
            prop_assert_eq!(pairs(&out), mapped);
        }
    }
}
