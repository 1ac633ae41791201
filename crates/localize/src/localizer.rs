//! The localiser: frames and odometry in, the pose in the map's frame out, with whether it
//! stands behind it.

use alloc::collections::VecDeque;
use alloc::vec::Vec;

use nalgebra::{Matrix3, Matrix3x4, Vector3};
use rig_model::camera::{CameraParams, Pose2, Vehicle};
use rig_model::config::Rig;
use rig_model::odometry::OdomSample;
use track::{FrontEnd, Model, Pixel};
use vslam_ekf::{CameraCovariance, Increment};

use crate::error::Error;
use crate::filter::PoseFilter;
use crate::hall::{LampCounts, NewLamp, NewLamps};
use crate::map::LampMap;
use crate::reloc::{Decision, Relocalizer};
use crate::settings::LocalizerSettings;
use crate::view::{Observation, View};

/// Odometry samples held at most (100 s at 100 Hz).
const MAX_ODOMETRY: usize = 10_000;

/// Why the localiser does not know where it is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum LostReason {
    /// It has not fixed its position since it started.
    Start,
    /// The cameras were blind, or the log has a gap, longer than allowed.
    Gap,
    /// The odometry stopped: the motion since the last frame is unknown.
    NoOdometry,
    /// The lamps stopped fitting where the pose says they are (the vehicle was moved).
    Innovations,
    /// The pose's uncertainty grew too large (no lamps for too long).
    Uncertain,
}

/// The localiser's state.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Status {
    /// It stands behind its pose.
    Localized,
    /// It does not know where it is; relocalising.
    Lost(LostReason),
}

/// What one frame gave.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameResult {
    /// The frame's time, microseconds.
    pub t_us: u64,
    /// The status after the frame.
    pub status: Status,
    /// The pose: the filter's while localised; while lost, the best hypothesis's, or the last
    /// pose carried on by the odometry, or nothing.
    pub pose: Option<Pose2>,
    /// Its covariance (the filter's, or the hypothesis's), with the map's common error added
    /// when the map has one: the pose's uncertainty in the world the map was made in.
    pub pose_covariance: Matrix3<f64>,
    /// Map lamps associated, by id, with their NIS (localised only).
    pub matched: Vec<(u64, f64)>,
    /// Map lamps expected in view (localised only).
    pub expected: usize,
    /// Stereo observations in the frame.
    pub observations: usize,
    /// Live hypotheses (while lost).
    pub hypotheses: usize,
    /// The position was (re)gained at this frame.
    pub fixed: bool,
    /// The position was lost at this frame, and why.
    pub lost: Option<LostReason>,
}

/// Counters over the localiser's life.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct LocalizerStats {
    /// Frames processed.
    pub frames: u64,
    /// Frames localised.
    pub localized_frames: u64,
    /// Odometry samples accepted.
    pub odometry: u64,
    /// Features the lens model could not map (dropped).
    pub features_unmapped: u64,
    /// Times the position was lost, by reason: gap, no odometry, innovations, uncertain.
    pub lost: [u64; 4],
    /// Hypotheses generated.
    pub hypotheses: u64,
}

/// Localisation on a saved map (crate docs).
#[derive(Debug, Clone)]
pub struct Localizer {
    rig: Rig,
    settings: LocalizerSettings,
    map: LampMap,
    view: View,
    front_end: FrontEnd,
    vehicle: Vehicle,
    vehicle_sigma: [f64; 4],
    status: Status,
    filter: Option<PoseFilter>,
    /// The last pose carried on by the odometry while lost.
    guess: Option<PoseFilter>,
    reloc: Relocalizer,
    odometry: Vec<OdomSample>,
    last_odometry_t: Option<u64>,
    last_frame_t: Option<u64>,
    /// The last frames' `(expected, matched)` while localised.
    fit: VecDeque<(usize, usize)>,
    counts: LampCounts,
    new_lamps: NewLamps,
    localized_t_us: Vec<u64>,
    sigma_px: f64,
    /// Relative sigma of the map's scale (its baseline's, [`Localizer::new`]).
    scale_sigma: f64,
    stats: LocalizerStats,
}

impl Localizer {
    /// A localiser on `map` for the rig `rig` (its lens, image size and noise; the map's
    /// calibration `camera` (C and V) with the standard deviations `camera_sigma` of every
    /// parameter, [`rig_model::Param::ALL`] order).
    ///
    /// Errors: a setting out of range, or a camera that cannot project.
    pub fn new(
        map: LampMap,
        rig: Rig,
        camera: CameraParams,
        camera_sigma: &[f64; rig_model::N_PARAMS],
        settings: LocalizerSettings,
    ) -> Result<Self, Error> {
        settings.validate()?;
        rig_model::rig::check_triangulation_camera(&camera)?;
        let mut cov = CameraCovariance::zeros();
        for (i, s) in camera_sigma.iter().enumerate() {
            if s.is_finite() {
                cov[(i, i)] = s * s;
            }
        }
        let model = Model::from_rig(&rig).with_camera(camera, cov);
        let sigma_px = libm::sqrt(model.pixel_variance_px2());
        let view = View::new(
            camera,
            rig.width,
            rig.height,
            model.pixel_variance_px2(),
            model.pixel_noise,
            &map,
            &settings,
        );
        let front_end = FrontEnd::new(model, settings.front_end)?;
        let vehicle_sigma = core::array::from_fn(|k| {
            camera_sigma
                .get(rig_model::N_CAMERA + k)
                .copied()
                .filter(|s| s.is_finite())
                .unwrap_or(0.0)
        });
        let counts = LampCounts::new(map.len());
        // Stereo sets the map's scale: a point triangulated at disparity d lies at (u - cx)
        // B / d, so the whole map scales with the baseline about the mapping run's origin.
        let baseline_sigma = camera_sigma
            .get(rig_model::Param::Baseline.index())
            .copied()
            .filter(|s| s.is_finite())
            .unwrap_or(0.0);
        let scale_sigma = baseline_sigma / camera.baseline;
        Ok(Self {
            vehicle: camera.vehicle,
            vehicle_sigma,
            rig,
            reloc: Relocalizer::new(settings.reloc),
            settings,
            map,
            view,
            front_end,
            status: Status::Lost(LostReason::Start),
            filter: None,
            guess: None,
            odometry: Vec::new(),
            last_odometry_t: None,
            last_frame_t: None,
            fit: VecDeque::new(),
            counts,
            new_lamps: NewLamps::default(),
            localized_t_us: Vec::new(),
            sigma_px,
            scale_sigma,
            stats: LocalizerStats::default(),
        })
    }

    /// The map.
    pub fn map(&self) -> &LampMap {
        &self.map
    }

    /// The status.
    pub fn status(&self) -> Status {
        self.status
    }

    /// Every time the position was (re)gained, microseconds.
    pub fn localized_t_us(&self) -> &[u64] {
        &self.localized_t_us
    }

    /// Counters.
    pub fn stats(&self) -> LocalizerStats {
        LocalizerStats {
            hypotheses: self.reloc.generated,
            ..self.stats
        }
    }

    /// The relocaliser: its live hypotheses with their scores, its last generation.
    pub fn relocalizer(&self) -> &Relocalizer {
        &self.reloc
    }

    /// The live relocalisation hypotheses' poses (while lost).
    pub fn hypotheses(&self) -> Vec<Pose2> {
        self.reloc.hypotheses().iter().map(|h| h.pose()).collect()
    }

    /// The vehicle's parameters and their standard deviations: the filter's while it runs (it
    /// refines them), else the map's.
    pub fn vehicle(&self) -> (Vehicle, [f64; 4]) {
        match &self.filter {
            Some(f) => (f.vehicle(), f.vehicle_sigma()),
            None => (self.vehicle, self.vehicle_sigma),
        }
    }

    /// How often each map lamp (by index) was expected and seen while localised.
    pub fn lamp_counts(&self) -> &LampCounts {
        &self.counts
    }

    /// Ids of the map lamps that should have been seen often and were not.
    pub fn lamps_missing(&self) -> Vec<u64> {
        self.counts
            .missing(
                self.settings.missing_min_expected,
                self.settings.missing_max_seen_fraction,
            )
            .into_iter()
            .filter_map(|i| self.map.lamp(i))
            // A lamp the map knows poorly may be missed where the map puts it and seen as
            // another: not reported.
            .filter(|l| {
                let s = self.settings.missing_max_map_sigma_m;
                (0..3).all(|k| l.covariance[(k, k)] <= s * s)
            })
            .map(|l| l.id)
            .collect()
    }

    /// Lamps seen that are not in the map.
    pub fn new_lamps(&self) -> Vec<NewLamp> {
        self.new_lamps.confirmed(
            &self.map,
            self.settings.new_lamp_min_observations,
            self.settings.new_lamp_max_sigma_m,
            self.settings.new_lamp_min_separation_m,
        )
    }

    /// Adds an odometry sample (robot-frame velocities held from `t_us` until the next one),
    /// in time order.
    pub fn push_odometry(&mut self, sample: OdomSample) -> Result<(), Error> {
        for (what, value) in [
            ("odometry vx", sample.vx),
            ("odometry vy", sample.vy),
            ("odometry vtheta", sample.vtheta),
        ] {
            if !value.is_finite() {
                return Err(Error::NonFinite {
                    what,
                    t_us: sample.t_us,
                    value,
                });
            }
        }
        if let Some(last) = self.last_odometry_t
            && sample.t_us < last
        {
            return Err(Error::OdometryOutOfOrder {
                t_us: sample.t_us,
                last_us: last,
            });
        }
        self.last_odometry_t = Some(sample.t_us);
        self.front_end.push_odometry(sample);
        if self.odometry.len() >= MAX_ODOMETRY {
            self.odometry.drain(..MAX_ODOMETRY / 2);
        }
        self.odometry.push(sample);
        self.stats.odometry += 1;
        Ok(())
    }

    fn lose(&mut self, why: LostReason, result: &mut FrameResult) {
        if self.status == Status::Localized {
            self.guess = self.filter.take();
            let slot = match why {
                LostReason::Gap | LostReason::Start => 0,
                LostReason::NoOdometry => 1,
                LostReason::Innovations => 2,
                LostReason::Uncertain => 3,
            };
            if let Some(n) = self.stats.lost.get_mut(slot) {
                *n += 1;
            }
            result.lost = Some(why);
        }
        if matches!(why, LostReason::Gap | LostReason::NoOdometry) {
            // Moved while blind: the carried-on pose means nothing.
            self.guess = None;
            self.reloc.clear();
        }
        self.filter = None;
        self.fit.clear();
        self.status = Status::Lost(why);
    }

    /// The motion since the previous frame for the vehicle `v`, or why there is none.
    fn motion(
        &self,
        t0: u64,
        t1: u64,
        v: &Vehicle,
        jacobian: bool,
    ) -> Result<(Increment, Matrix3x4<f64>), LostReason> {
        if t1.saturating_sub(t0) > self.settings.max_frame_gap_us {
            return Err(LostReason::Gap);
        }
        let end = v.odometry_time_us(t1);
        let fresh = self
            .odometry
            .iter()
            .rev()
            .find(|s| s.t_us <= end)
            .is_some_and(|s| end - s.t_us <= self.settings.max_odometry_age_us);
        if !fresh {
            return Err(LostReason::NoOdometry);
        }
        match Increment::from_odometry_vehicle(&self.odometry, t0, t1, &self.rig.noise, v, jacobian)
        {
            Ok((inc, _, jv)) => Ok((inc, jv)),
            Err(_) => Err(LostReason::NoOdometry),
        }
    }

    /// Processes one stereo frame: the board's left and right features (raw pixels; the
    /// rig's lens maps them) at `t_us`, after the odometry up to `t_us`.
    pub fn push_frame(
        &mut self,
        t_us: u64,
        left: &[Pixel],
        right: &[Pixel],
    ) -> Result<FrameResult, Error> {
        if let Some(last) = self.last_frame_t
            && t_us < last
        {
            return Err(Error::FrameOutOfOrder {
                t_us,
                last_us: last,
            });
        }
        for p in left.iter().chain(right) {
            if !(p.u.is_finite() && p.v.is_finite()) {
                return Err(Error::NonFinite {
                    what: "feature pixel coordinate",
                    t_us,
                    value: if p.u.is_finite() { p.v } else { p.u },
                });
            }
        }
        self.stats.frames += 1;
        let mut result = FrameResult {
            t_us,
            status: self.status,
            pose: None,
            pose_covariance: Matrix3::zeros(),
            matched: Vec::new(),
            expected: 0,
            observations: 0,
            hypotheses: 0,
            fixed: false,
            lost: None,
        };

        // Prediction of everything that lives: the filter (its own V), the carried-on guess
        // and the hypotheses (the map's V).
        if let Some(t0) = self.last_frame_t {
            let v_filter = self.filter.as_ref().map(PoseFilter::vehicle);
            match v_filter.map(|v| self.motion(t0, t_us, &v, true)) {
                Some(Ok((inc, jv))) => {
                    if let Some(f) = &mut self.filter {
                        f.predict(&inc, &jv);
                    }
                }
                Some(Err(why)) => self.lose(why, &mut result),
                None => {}
            }
            match self.motion(t0, t_us, &self.vehicle, false) {
                Ok((inc, jv)) => {
                    if let Some(g) = &mut self.guess {
                        g.predict(&inc, &jv);
                    }
                    self.reloc.predict(&inc, &jv);
                }
                Err(why) => {
                    self.guess = None;
                    self.reloc.clear();
                    if self.status != Status::Localized {
                        self.status = Status::Lost(why);
                    }
                }
            }
        }
        self.last_frame_t = Some(t_us);
        self.forget_odometry(t_us);

        let observations = self.observe(t_us, left, right);
        result.observations = observations.len();

        if self.status == Status::Localized {
            self.track(&observations, t_us, &mut result);
        }
        if self.status != Status::Localized {
            let decision =
                self.reloc
                    .frame(&self.map, &self.view, &observations, &self.vehicle, t_us);
            if let Decision::Unique(i) = decision
                && let Some(h) = self.reloc.hypotheses().get(i)
            {
                // The hypothesis's filter goes on (its pose, covariance and the
                // cross-covariances with the lamps and the map's common error); from here it
                // refines V too.
                let mut filter = h.filter.clone();
                let (v, vs) = match &self.guess {
                    Some(g) => (g.vehicle(), g.vehicle_sigma()),
                    None => (self.vehicle, self.vehicle_sigma),
                };
                filter.release_vehicle(&v, vs, self.settings.vehicle_walk);
                self.filter = Some(filter);
                self.status = Status::Localized;
                self.localized_t_us.push(t_us);
                self.reloc.clear();
                self.guess = None;
                result.fixed = true;
            }
            result.hypotheses = self.reloc.hypotheses().len();
        }

        result.status = self.status;
        match (&self.filter, self.reloc.best(), &self.guess) {
            (Some(f), _, _) => {
                result.pose = Some(f.pose());
                result.pose_covariance = f.pose_covariance();
            }
            (None, Some(h), _) => {
                result.pose = Some(h.pose());
                result.pose_covariance = h.filter.pose_covariance();
            }
            (None, None, Some(g)) => {
                result.pose = Some(g.pose());
                result.pose_covariance = g.pose_covariance();
            }
            (None, None, None) => {}
        }
        // The pose in the world the map was made in: its uncertainty relative to the map and
        // the map's own common error, its rigid part and its scale's (the map scales with its
        // baseline about its origin; the two are taken as independent, which overstates the
        // sum a little: the rigid part's fit holds some of the scale error).
        if let (Some(p), Some(c)) = (&result.pose, self.map.common_error()) {
            result.pose_covariance += c.pose_covariance(p.x, p.y);
            let j = Vector3::new(p.x, p.y, 0.0) * self.scale_sigma;
            result.pose_covariance += j * j.transpose();
        }
        if self.status == Status::Localized {
            self.stats.localized_frames += 1;
        }
        Ok(result)
    }

    /// Keeps the odometry the next interval needs.
    fn forget_odometry(&mut self, t_us: u64) {
        let v = self
            .filter
            .as_ref()
            .map_or(self.vehicle, PoseFilter::vehicle);
        let keep_until = v.odometry_time_us(t_us).min(t_us).saturating_sub(200_000);
        let keep_from = self
            .odometry
            .partition_point(|s| s.t_us <= keep_until)
            .saturating_sub(1);
        self.odometry.drain(..keep_from);
    }

    /// The frame's features through the lens and the front end: its stereo observations.
    fn observe(&mut self, t_us: u64, left: &[Pixel], right: &[Pixel]) -> Vec<Observation> {
        // The localiser uses the whole raw view (the navigator's field of use,
        // vslam_ekf::Settings::max_off_axis_deg, is for mapping).
        let rectified =
            track::rectify_features(&self.rig, left, right, core::f64::consts::FRAC_PI_2);
        let (left, right) = match &rectified {
            Some(r) => {
                self.stats.features_unmapped += r.dropped;
                (r.left.pixels.as_slice(), r.right.pixels.as_slice())
            }
            None => (left, right),
        };
        let tracked = self.front_end.push_frame(t_us, left, right);
        tracked
            .observations
            .iter()
            .map(|o| Observation {
                z: o.measurement,
                track: o.track.0,
                hits: o.hits,
                confirmed: o.confirmed,
            })
            .collect()
    }

    /// A localised frame: association, update, the fit watched, the hall's changes counted.
    fn track(&mut self, observations: &[Observation], t_us: u64, result: &mut FrameResult) {
        let Some(filter) = &mut self.filter else {
            return;
        };
        let scored = self
            .view
            .score_and_update(&self.map, filter, observations, t_us);
        filter.forget_before(t_us.saturating_sub(self.settings.consider_memory_us));
        result.expected = scored.expected;
        result.matched = scored
            .matched
            .iter()
            .zip(&scored.nis)
            .filter_map(|(&(l, _), &n)| self.map.lamp(l).map(|lamp| (lamp.id, n)))
            .collect();
        let pose = filter.pose();
        let cov = filter.pose_covariance();
        let sigma = libm::sqrt(cov[(0, 0)].max(cov[(1, 1)]).max(0.0));

        self.fit.push_back((scored.expected, scored.matched.len()));
        while self.fit.len() > self.settings.lost_window_frames {
            self.fit.pop_front();
        }
        let (expected, matched) = self
            .fit
            .iter()
            .fold((0, 0), |(e, m), &(a, b)| (e + a, m + b));
        #[allow(clippy::cast_precision_loss)]
        let misfit = self.fit.len() >= self.settings.lost_window_frames
            && expected >= self.settings.lost_min_expected
            && (matched as f64) < self.settings.lost_min_matched_fraction * expected as f64;
        if misfit {
            self.lose(LostReason::Innovations, result);
            return;
        }
        if sigma > self.settings.lost_max_sigma_m {
            self.lose(LostReason::Uncertain, result);
            return;
        }
        // The hall's changes, judged from a pose known well and a frame that fits (never the
        // pose from them): a frame whose lamps stop fitting is the start of a loss, and its
        // unassociated lamps would be placed where they are not.
        let fits = scored.matched.len() >= 3 && 2 * scored.matched.len() >= scored.expected;
        if sigma < 0.1 && fits {
            self.counts.add(
                &self.map,
                &scored.expected_lamps,
                &scored.matched,
                self.settings.missing_twin_m,
            );
            let mut taken = alloc::vec![false; observations.len()];
            for &(_, o) in &scored.matched {
                if let Some(t) = taken.get_mut(o) {
                    *t = true;
                }
            }
            let unmatched: Vec<Observation> = observations
                .iter()
                .zip(&taken)
                .filter(|(_, t)| !**t)
                .map(|(o, _)| *o)
                .collect();
            self.new_lamps.add(
                self.view.camera(),
                &pose,
                &cov,
                self.sigma_px,
                &self.front_end.model().pixel_noise,
                &unmatched,
                t_us,
            );
        }
    }
}
