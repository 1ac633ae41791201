//! The localiser's tuning, every field checked by `validate`.

use track::FrontEndSettings;

use crate::error::Error;

/// Global relocalisation ([`crate::reloc`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RelocSettings {
    /// Frames between two generations of new hypotheses while lost.
    pub generate_every_frames: u32,
    /// Fewest observations in a frame to generate from (two fix a pose; a third checks it).
    pub min_observations: usize,
    /// Most observations a generation pairs (the longest tracks).
    pub max_generation_observations: usize,
    /// Tolerance of a frame triangle's side against a map triangle's once the frame's points
    /// are put at their lamps' heights, metres, plus [`Self::pair_tolerance_fraction`] of the
    /// side (the map's errors, the pixel noise); the look-up adds how far a lamp's level's
    /// spread of heights can put a point.
    pub pair_tolerance_m: f64,
    /// See [`Self::pair_tolerance_m`].
    pub pair_tolerance_fraction: f64,
    /// An observation supports a pose when it lands this close to a map lamp, metres.
    pub support_radius_m: f64,
    /// Other observations that must support a pose (or all of them, if fewer)...
    pub min_support: usize,
    /// ...and at least this fraction of them (the rest: clutter, lamps not in the map, a
    /// plan's missing sprinkler heads).
    pub min_support_fraction: f64,
    /// Most candidate poses one generation tries.
    pub max_candidates: usize,
    /// Most triangles of observations one generation looks up.
    pub max_query_triangles: usize,
    /// Most map triangles one look-up may return (a bound on the work; the look-up is not
    /// tried beyond it).
    pub max_triangle_candidates: usize,
    /// Most poses one triangle of observations may give that the frame's other observations
    /// support: a triangle that fits more places tells them apart no better than a guess
    /// (a regular grid), and the generation is not complete.
    pub max_poses_per_triangle: usize,
    /// Initial standard deviation of a new hypothesis's position, metres.
    pub initial_sigma_m: f64,
    /// Initial standard deviation of a new hypothesis's heading, radians.
    pub initial_sigma_rad: f64,
    /// Hypotheses closer than this (and [`Self::merge_angle_rad`]) are one, metres.
    pub merge_distance_m: f64,
    /// See [`Self::merge_distance_m`].
    pub merge_angle_rad: f64,
    /// Frames over which hypotheses are compared.
    pub window_frames: usize,
    /// A hypothesis this far (log-likelihood, nats) behind the best over their common frames
    /// is dropped.
    pub prune_margin: f64,
    /// The best must be ahead of every other by this much (nats) over their common frames to
    /// be declared (a likelihood ratio of e^margin).
    pub decision_margin: f64,
    /// Frames the best must have lived.
    pub min_frames: u32,
    /// Lamps a hypothesis must associate in a frame (to live, and to be declared).
    pub min_matched: usize,
    /// Distinct lamps the best must have associated over its life.
    pub min_distinct_lamps: usize,
    /// Largest mean NIS (4 dof) of the best's associations at the decision.
    pub max_mean_nis: f64,
    /// Most hypotheses kept.
    pub max_hypotheses: usize,
}

impl Default for RelocSettings {
    fn default() -> Self {
        Self {
            generate_every_frames: 4,
            min_observations: 3,
            max_generation_observations: 10,
            pair_tolerance_m: 0.05,
            pair_tolerance_fraction: 0.01,
            support_radius_m: 0.1,
            min_support: 3,
            min_support_fraction: 0.3,
            max_candidates: 4000,
            max_query_triangles: 6,
            max_triangle_candidates: 200_000,
            max_poses_per_triangle: 16,
            initial_sigma_m: 0.15,
            initial_sigma_rad: 0.05,
            merge_distance_m: 0.3,
            merge_angle_rad: 0.08,
            window_frames: 40,
            prune_margin: 60.0,
            decision_margin: 30.0,
            min_frames: 10,
            min_matched: 3,
            min_distinct_lamps: 4,
            max_mean_nis: 8.0,
            max_hypotheses: 400,
        }
    }
}

/// The localiser's tuning.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LocalizerSettings {
    /// Stereo matching and tracking.
    pub front_end: FrontEndSettings,
    /// Relocalisation.
    pub reloc: RelocSettings,
    /// Probability mass inside the association gate (4 dof).
    pub match_probability: f64,
    /// Probability that a lamp in view is detected and matched (the score's `P_D`).
    pub detection_probability: f64,
    /// Clutter measurements per frame that pass the stereo matching (the score's density).
    pub clutter_per_frame: f64,
    /// A lamp counts as in view when both its pixels are this far inside the images.
    pub image_margin_px: f64,
    /// Upper bound of the distance at which lamps are looked for, metres.
    pub max_reach_m: f64,
    /// A longer time between two frames (the cameras blind, a gap in the log) loses the
    /// position, microseconds.
    pub max_frame_gap_us: u64,
    /// Odometry older than this at a frame (its stream stopped) loses the position,
    /// microseconds.
    pub max_odometry_age_us: u64,
    /// Frames over which a localised filter's fit is watched.
    pub lost_window_frames: usize,
    /// Lamps expected over the window before the fit is judged.
    pub lost_min_expected: usize,
    /// Below this fraction of the expected lamps matched over the window, the position is lost.
    pub lost_min_matched_fraction: f64,
    /// A position sigma larger than this (metres) is lost.
    pub lost_max_sigma_m: f64,
    /// Cross-covariances with lamps not seen for this long are dropped, microseconds.
    pub consider_memory_us: u64,
    /// Random walk of `V` (variance per second), [`rig_model::Vehicle::to_array`] order.
    pub vehicle_walk: [f64; 4],
    /// A map lamp is reported missing when it was expected in view at least this often...
    pub missing_min_expected: u32,
    /// ...and seen in at most this fraction of those frames, if the map knows it to this
    /// (standard deviation on every axis, metres).
    pub missing_max_seen_fraction: f64,
    /// See [`Self::missing_max_seen_fraction`].
    pub missing_max_map_sigma_m: f64,
    /// Two map lamps closer than this (metres) are one lamp mapped twice: the one not seen
    /// while its twin is does not count as missing.
    pub missing_twin_m: f64,
    /// A lamp not in the map is reported after this many observations...
    pub new_lamp_min_observations: u32,
    /// ...with its position known to this (largest standard deviation, metres)...
    pub new_lamp_max_sigma_m: f64,
    /// ...and at least this far from every map lamp, metres.
    pub new_lamp_min_separation_m: f64,
}

impl Default for LocalizerSettings {
    fn default() -> Self {
        Self {
            front_end: FrontEndSettings::default(),
            reloc: RelocSettings::default(),
            match_probability: 0.999,
            detection_probability: 0.9,
            clutter_per_frame: 2.0,
            image_margin_px: 12.0,
            max_reach_m: 30.0,
            max_frame_gap_us: 1_000_000,
            max_odometry_age_us: 500_000,
            lost_window_frames: 20,
            lost_min_expected: 12,
            lost_min_matched_fraction: 0.25,
            lost_max_sigma_m: 0.5,
            consider_memory_us: 30_000_000,
            vehicle_walk: [1e-8, 1e-8, 1e-10, 1e-10],
            missing_min_expected: 20,
            missing_max_seen_fraction: 0.1,
            missing_max_map_sigma_m: 0.1,
            missing_twin_m: 0.3,
            new_lamp_min_observations: 20,
            new_lamp_max_sigma_m: 0.15,
            new_lamp_min_separation_m: 0.5,
        }
    }
}

fn check(name: &'static str, value: f64, ok: bool) -> Result<(), Error> {
    if value.is_finite() && ok {
        Ok(())
    } else {
        Err(Error::Settings { name, value })
    }
}

impl LocalizerSettings {
    /// Checks every field: probabilities inside (0, 1), distances and counts positive.
    pub fn validate(&self) -> Result<(), Error> {
        self.front_end.stereo.validate()?;
        self.front_end.tracker.validate()?;
        let p = |v: f64| v > 0.0 && v < 1.0;
        check(
            "match_probability",
            self.match_probability,
            p(self.match_probability),
        )?;
        check(
            "detection_probability",
            self.detection_probability,
            p(self.detection_probability),
        )?;
        check(
            "clutter_per_frame",
            self.clutter_per_frame,
            self.clutter_per_frame > 0.0,
        )?;
        check(
            "image_margin_px",
            self.image_margin_px,
            self.image_margin_px >= 0.0,
        )?;
        check("max_reach_m", self.max_reach_m, self.max_reach_m > 0.0)?;
        check(
            "lost_min_matched_fraction",
            self.lost_min_matched_fraction,
            (0.0..=1.0).contains(&self.lost_min_matched_fraction),
        )?;
        check(
            "lost_max_sigma_m",
            self.lost_max_sigma_m,
            self.lost_max_sigma_m > 0.0,
        )?;
        for w in self.vehicle_walk {
            check("vehicle_walk", w, w >= 0.0)?;
        }
        check(
            "missing_max_seen_fraction",
            self.missing_max_seen_fraction,
            (0.0..=1.0).contains(&self.missing_max_seen_fraction),
        )?;
        check(
            "new_lamp_max_sigma_m",
            self.new_lamp_max_sigma_m,
            self.new_lamp_max_sigma_m > 0.0,
        )?;
        check(
            "new_lamp_min_separation_m",
            self.new_lamp_min_separation_m,
            self.new_lamp_min_separation_m >= 0.0,
        )?;
        let r = &self.reloc;
        #[allow(clippy::cast_precision_loss)]
        for (name, v, ok) in [
            (
                "reloc.generate_every_frames",
                f64::from(r.generate_every_frames),
                r.generate_every_frames >= 1,
            ),
            (
                "reloc.min_observations",
                r.min_observations as f64,
                r.min_observations >= 3,
            ),
            (
                "reloc.max_generation_observations",
                r.max_generation_observations as f64,
                r.max_generation_observations >= r.min_observations,
            ),
            (
                "reloc.window_frames",
                r.window_frames as f64,
                r.window_frames >= 1,
            ),
            (
                "reloc.max_hypotheses",
                r.max_hypotheses as f64,
                r.max_hypotheses >= 1,
            ),
            (
                "reloc.min_support_fraction",
                r.min_support_fraction,
                (0.0..=1.0).contains(&r.min_support_fraction),
            ),
            (
                "reloc.max_query_triangles",
                r.max_query_triangles as f64,
                r.max_query_triangles >= 1,
            ),
            (
                "reloc.max_poses_per_triangle",
                r.max_poses_per_triangle as f64,
                r.max_poses_per_triangle >= 1,
            ),
            (
                "reloc.max_triangle_candidates",
                r.max_triangle_candidates as f64,
                r.max_triangle_candidates >= 1,
            ),
            (
                "reloc.min_matched",
                r.min_matched as f64,
                r.min_matched >= 2,
            ),
            (
                "reloc.pair_tolerance_m",
                r.pair_tolerance_m,
                r.pair_tolerance_m > 0.0,
            ),
            (
                "reloc.pair_tolerance_fraction",
                r.pair_tolerance_fraction,
                r.pair_tolerance_fraction >= 0.0,
            ),
            (
                "reloc.support_radius_m",
                r.support_radius_m,
                r.support_radius_m > 0.0,
            ),
            (
                "reloc.initial_sigma_m",
                r.initial_sigma_m,
                r.initial_sigma_m > 0.0,
            ),
            (
                "reloc.initial_sigma_rad",
                r.initial_sigma_rad,
                r.initial_sigma_rad > 0.0,
            ),
            (
                "reloc.merge_distance_m",
                r.merge_distance_m,
                r.merge_distance_m >= 0.0,
            ),
            (
                "reloc.merge_angle_rad",
                r.merge_angle_rad,
                r.merge_angle_rad >= 0.0,
            ),
            ("reloc.prune_margin", r.prune_margin, r.prune_margin > 0.0),
            (
                "reloc.decision_margin",
                r.decision_margin,
                r.decision_margin > 0.0,
            ),
            ("reloc.max_mean_nis", r.max_mean_nis, r.max_mean_nis > 0.0),
        ] {
            check(name, v, ok)?;
        }
        Ok(())
    }
}
