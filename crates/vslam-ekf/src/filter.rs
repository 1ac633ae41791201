//! The filter type [`Ekf`], its settings and what an update reports. Its state is laid out as
//! eq. (3) says (`state`); the steps of the method are implemented in their own modules:
//! `start` (the constructors from phase 1's hand-over), `predict` (eq. (4)-(5)),
//! `measurement` (eq. (8)), `update` (eq. (6)-(7)) and `landmarks` (initialisation, removal).

use alloc::vec::Vec;

use nalgebra::{DMatrix, DVector, Matrix3};
use rig_model::camera::Param;
use rig_model::lens::PixelNoise;
use rig_model::{CameraParams, Measurement, N_PARAMS, Noise};

use crate::error::Error;
use crate::health::{Health, HealthState};
use crate::kernels::Workspace;
use crate::landmarks::{LandmarkId, Slot};

/// How the covariance update is written (see the crate docs for why).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum CovarianceUpdate {
    /// The Joseph form expanded into one symmetric rank-2k update,
    /// `P - K A^T - A K^T + K S K^T`: first-order insensitive to errors in the gain.
    Joseph,
    /// `P - W W^T` with `W = A L^-T`, `S = L L^T`: half the multiply-adds of the Joseph form.
    Factored,
    /// Joseph up to [`AUTO_JOSEPH_MAX_STATES`] states, factored above.
    Auto,
}

/// Largest state updated one landmark at a time (the whole covariance fits in the first-level
/// cache); larger states are updated as one batch.
pub const SEQUENTIAL_MAX_STATES: usize = crate::kernels::MAX_SMALL_STATE;

/// Largest state [`CovarianceUpdate::Auto`] updates in the Joseph form. Above it the
/// factored form keeps the 500-landmark update within its time budget (docs/benchmarks.md).
pub const AUTO_JOSEPH_MAX_STATES: usize = 400;

/// A pose position sigma above this makes [`Ekf::update`] iterate (the iterated EKF): its
/// projections are not linear over the prior's spread, metres.
pub const ITERATE_POSITION_SIGMA_M: f64 = 0.1;

/// A heading sigma above this makes [`Ekf::update`] iterate, radians (2 degrees).
pub const ITERATE_HEADING_SIGMA_RAD: f64 = 0.035;

/// The heading sigma below which the prediction takes the pose's first estimates, radians
/// (0.5 degrees; [`Settings::first_estimate_prediction_heading_sigma_rad`]).
pub const FEJ_PREDICTION_HEADING_SIGMA_RAD: f64 = 0.5 * core::f64::consts::PI / 180.0;

/// The iterated update stops when every accepted residual is within this many pixel-noise
/// sigmas of its linear model's.
pub const ITERATE_TOLERANCE_SIGMAS: f64 = 0.1;

/// First-estimates Jacobians (the FEJ-EKF of Huang, Mourikis and Roumeliotis, ICRA 2008): the
/// update's Jacobians of a landmark's observation are taken at a fixed linearisation point of
/// that landmark (the pose's and the landmark's columns; the camera's at the estimate, as
/// they are not in the unobservable directions), which follows the landmark's estimate until
/// its largest position sigma is below this, metres, and the camera is learned
/// ([`FEJ_CAMERA_RELATIVE`]), and then stays; a joint estimate from the smoother
/// (`Ekf::set_joint`) is a new linearisation point, and the iterated update relinearises at
/// the estimate but for the heading's column (the observability constraint at this point:
/// `Ekf::observation_model_constrained`). Jacobians at each
/// update's estimate gave the filter information on its global heading from lamps seen for the first time: on a loop (5.6
/// degrees of heading sigma became 0.4 within a second, docs/halls.md "Loops") and after
/// every dark stretch of the generated halls (the heading's sigma halved by new lamps while
/// its error grew to 0.5 degrees, 3 sigma; docs/benchmarks.md, "Halls with LED panels and
/// dark stretches"). Frozen at the landmark's very first estimate, a narrow lens's lamps 5 m
/// above the cameras were linearised too far off (two of eight halls inconsistent); 0.5 m
/// left every hall consistent. The rule of [`Settings::follow_points`] off; on (the default),
/// the point follows the estimate for good, the covariance re-linearised with it, and this
/// only says when the iterated update relinearises the landmark.
pub const FEJ_SETTLE_SIGMA_M: f64 = 0.5;

/// A landmark's linearisation point settles ([`FEJ_SETTLE_SIGMA_M`]) only once the camera's
/// estimated parameters move a landmark by at most this share of its distance (their sigmas
/// over the focal length or the baseline, or in radians and metres): from nominal values
/// 2.5 % off (the paper's square) a point settled early left the focal length 6.8 sigma off
/// and lost every lamp of a seed as the camera converged.
pub const FEJ_CAMERA_RELATIVE: f64 = 0.005;

/// While the pose's position sigma is above this, metres, the pose is lost: a new landmark's
/// linearisation point stays at its first estimate (lamps seen for the first time must not
/// tell the filter where it is).
pub const FEJ_POSITION_SIGMA_M: f64 = 0.5;

/// While the pose's heading sigma is above this, radians, the pose is lost as it is by
/// [`FEJ_POSITION_SIGMA_M`]: new landmarks keep their first estimates. Wheels that slip for a
/// while leave the position known to a decimetre after a 15 m dark stretch but the heading to
/// 2.3 degrees; the update iterated at each estimate (its threshold
/// [`ITERATE_HEADING_SIGMA_RAD`]) took the heading's sigma to 0.9 degrees from two lamps seen
/// for the first time, 4.4 degrees off (docs/vehicle.md, "Dark stretches").
pub(crate) const FEJ_HEADING_SIGMA_RAD: f64 = ITERATE_HEADING_SIGMA_RAD;

/// Passes of the iterated update at most (the first, linear one included).
pub const ITERATE_MAX_PASSES: usize = 8;

/// What the update does with the camera parameters.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum CameraUpdate {
    /// Refined by every update, with the landmarks and the pose (the method's phase 2).
    Refine,
    /// Considered, not estimated (Schmidt-Kalman): their covariance and cross-covariances are
    /// carried, so that the pose and landmark sigmas include the camera's uncertainty, but the
    /// gain's camera rows are zero: the values and their covariance stay those phase 1 handed
    /// over. For data on which refining them is over-confident (docs/phase2.md,
    /// "Linearisation"). The update is then always in the Joseph form, which holds for any gain.
    Consider,
}

/// The filter's tuning.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Settings {
    /// Probability mass inside each landmark's innovation gate (4 dof): 0.999 gives a NIS
    /// bound of 18.47.
    pub gate_probability: f64,
    /// Gate outcomes kept for the health's NIS statistics.
    pub nis_window: usize,
    /// A landmark rejected by the gate this many times in a row is removed as false.
    pub max_consecutive_rejections: u32,
    /// Form of the covariance update.
    pub covariance_update: CovarianceUpdate,
    /// Refine the camera parameters, or only consider them.
    pub camera_update: CameraUpdate,
    /// Through real lenses ([`rig_model::Rig::lens`]): the field of use, degrees from the
    /// rectified optical axis. Features whose rays lie farther out are not used
    /// (`track::rectify_features`) and landmarks predicted there are not in view
    /// ([`Ekf::visible_landmarks`]), so that the two agree. A fisheye's raw image reaches
    /// rays near 90 degrees, whose rectified pixels carry the raw noise stretched tens of
    /// times; used, they pulled the map's scale 0.5 to 0.9 % off (5 sigma) on a hall; a
    /// narrow field leaves lamps seen only off to the side unmapped (docs/halls.md, "A
    /// fisheye's outer band": 50 degrees kept the maps of 8 generated fisheye halls honest,
    /// 65 did not). 90 uses every ray in front of the camera; no effect without lens tables.
    pub max_off_axis_deg: f64,
    /// The outer band beyond the field of use, degrees from the axis: a stereo pair there
    /// updates only its own landmark (`Ekf::update`'s landmark-only update), so that lamps
    /// seen only off to the side are mapped without their far-out rays moving the pose, the
    /// camera or the map's scale. At or below `max_off_axis_deg`: no band.
    pub outer_off_axis_deg: f64,
    /// The largest variance gain of the lens's noise ([`PixelNoise::gains`]) a pair in the
    /// outer band may have to be used at all (`rig_model::lens::StereoField`): a barrel
    /// lens's corners stretch the noise little; a fisheye's far-out rays, tens of times, and
    /// their landmarks came out biased even with the update confined to them.
    pub outer_max_noise_gain: f64,
    /// The far band (`rig_model::lens::StereoField::in_far_band`): the outer band's pairs
    /// whose gains exceed `outer_max_noise_gain` but not this, a fisheye's far-out rays
    /// (1000: every ray out to `outer_off_axis_deg`; the fisheye passes' side lamps have
    /// gains above 100 in the diagonal bound of `rig_model::lens::PixelNoise`). A lamp seen there is born from all its frames at once
    /// (`crate::candidates`, `CandidateSettings::outer_birth_relative_sigma`), never from
    /// one pair, and its pairs update its landmark alone, as in the rest of the outer band.
    /// At or below `outer_max_noise_gain`: no far band.
    pub far_max_noise_gain: f64,
    /// A far pair is used only if its disparity is at least this many sigmas of its own
    /// noise (the lens's gains at the pair): far rays whose disparity is lost in its noise
    /// (lamps high above the cameras, seen far out) moved the maps of tall fisheye halls
    /// (docs/halls.md, "The far band"). 0: every far pair.
    pub far_min_snr: f64,
    /// The far band's pairs used in one frame at most, the least observed landmarks first
    /// (0: all): the far band of a tall hall holds dozens of lamps a frame.
    pub far_updates_per_frame: usize,
    /// Large states are updated in local sessions (`crate::local`, the compressed filter):
    /// the active landmarks are those predicted in the field of use from any pose within
    /// this many metres in x and y of the vehicle's when a session opens
    /// (and [`Settings::local_turn_rad`] in heading), and the far band's within this many
    /// metres beyond the farthest one in use, so that the vehicle can drive about as far
    /// before an observation needs a passive one and the session is settled. Exact
    /// either way; it moves cost between the updates (larger: more active states) and the
    /// settles (smaller: more often). 0 keeps every update dense.
    pub local_margin_m: f64,
    /// The turn, radians either way, within which a session's active landmarks stay in
    /// reach ([`Settings::local_margin_m`]).
    pub local_turn_rad: f64,
    /// Landmarks the map holds at most (`usize::MAX`: no cap). A firmware's memory bound: the
    /// covariance is `(3 + 3 N + cameras)^2` doubles for `N` landmarks, so the most memory the
    /// filter can take follows from this (docs/c-api.md). Once full, new landmarks are
    /// refused ([`crate::Error::LandmarkCap`]): lamps beyond it are not mapped.
    pub max_landmarks: usize,
    /// Whether a landmark's linearisation point follows its estimate for good, the
    /// covariance re-linearised with it at each move ([`Ekf::shear_linearisation_point`]:
    /// the heading's and every estimated camera parameter's column of the landmark's
    /// placement, the camera's taken from the pose it was placed from), the landmarks handed
    /// over by phase 1 included. On by default. Off, the point follows the estimate without
    /// the covariance until [`FEJ_SETTLE_SIGMA_M`] and then stays, and each move before it
    /// gives the filter information nothing in view holds: after hall 22's 16 m dark
    /// stretch, lamps seen for the first time took the heading's sigma from 0.26 to 0.08
    /// degrees with the heading 0.47 degrees off; on the radtan hall with odometry memory,
    /// eight seeds, the baseline's sigma 0.21 mm where the data hold its prior's 0.30, full
    /// state NEES per degree of freedom 2.91 (on: 0.92). On, the 24 white halls of `hall_mc`
    /// end with 3567 of 3578 landmarks near their lamp inside 3 sigma (off: 3227 of 3287);
    /// docs/halls.md, "The linearisation point". The points move before the update is
    /// linearised, and stay moved when it is refused: the shear changes the covariance's
    /// entries, not what it knows.
    pub follow_points: bool,
    /// Whether each update's correction of the pose and of the odometry's scale is taken in
    /// units of the baseline and mapped back, the covariance with it (`crate::scale`), so
    /// that the filter's linearisation point does not walk along the map's nearly
    /// unobservable metric scale. On by default. Off, the baseline drifts several of its
    /// prior sigmas in minutes of driving with its sigma unchanged, and every depth with it
    /// (docs/vehicle.md, "The baseline's drift").
    pub follow_scale: bool,
    /// While the pose is lost ([`FEJ_POSITION_SIGMA_M`]), the prediction's heading column
    /// taken from the pose the previous prediction left (before the update moved it), and the
    /// iterated update's constrained heading column from the pose before the update: the
    /// first-estimates Jacobians of the pose (Huang, Mourikis and Roumeliotis, "A
    /// First-Estimates Jacobian EKF for Improving SLAM Consistency", ISER 2008), so that the
    /// covariance's share of the world's unobservable turn and the estimate stay together
    /// while the updates move a lost pose by decimetres. Off, the pose's column follows the
    /// corrected estimate without the covariance, and lamps known only relative to the
    /// vehicle tell it the world's heading: hall 22 of `hall_mc 24 11 --lens radtan
    /// --odometry-tau 0.6`, handed over 4.0 degrees uncertain, 3.8 to 0.85 degrees in its
    /// third frame with the heading 7.5 degrees off (docs/halls.md, "The pose's linearisation
    /// point"). Off by default: on, the heading stays honest, but the navigator's rule for a
    /// lost pose (its sigma in the world, `nav::MATCH_MAX_POSE_SIGMA_M`) then holds the lamps
    /// of halls like it for longer, and the memory halls end worse (docs/benchmarks.md).
    pub first_estimate_pose: bool,
    /// While the heading is known to better than
    /// [`Settings::first_estimate_prediction_heading_sigma_rad`], the prediction's heading
    /// column taken from the pose the previous prediction left
    /// ([`Settings::first_estimate_pose`]'s prediction half, without its iterated-update
    /// half): the usual prediction after the pose's covariance was sheared with its
    /// linearisation point, `T = I + (J d) e_theta^T` for the update's move `d`, as
    /// [`Settings::follow_points`] shears the landmarks'. The first-estimates Jacobian of Huang,
    /// Mourikis and Roumeliotis (ISER 2008) for the prediction: the update's correction of the
    /// pose does not tell the covariance the world's heading, which no lamp observes. On by
    /// default (2026-12-08): hall 27 of the Monte Carlo (white odometry) was overconfident in
    /// its heading at the loop closures after its dark stretch (8 of its landmarks near their
    /// lamps outside 3 sigma; 0 with it), and every other hall of the comparison sets maps the
    /// same (docs/vehicle.md, "The prediction's first estimates, gated by the heading's
    /// sigma").
    pub first_estimate_prediction: bool,
    /// The heading sigma below which [`Settings::first_estimate_prediction`] applies, radians
    /// (0.5 degrees; `f64::INFINITY`: always). Above it the prediction takes the corrected
    /// pose, as the iterated update does above [`ITERATE_HEADING_SIGMA_RAD`]: a pose a dark
    /// stretch left degrees uncertain is corrected by decimetres when it finds the map again,
    /// and the first estimates' shear then carries that correction into the covariance. On
    /// every frame (no bound), fisheye hall 11 with 0.6 s of odometry memory came out of its
    /// dark stretch 2.5 degrees off at 1.7 of sigma and the lamps it found again took the
    /// heading to +1.6 degrees at 0.34 (4.8 sigma), missing 52 lamps (0 with the bound). Other
    /// bounds measured on the comparison sets: 0.3 degrees, hall 27 11 lamps missed and one
    /// landmark outside 3 sigma (8 and none at 0.5); 0.7, hall 27 15 missed and the silent
    /// memory hall 17 six outside; 1.0 (with the relative lost rule), fisheye memory hall 11
    /// 19 missed.
    pub first_estimate_prediction_heading_sigma_rad: f64,
    /// The odometry's errors with memory (`[noise] velocity_tau`, `yaw_rate_tau`: a
    /// first-order Gauss-Markov process of the rig's stationary sigma and that time constant)
    /// held as states of the filter (`crate::errors`): one per axis with memory, after the
    /// camera block, predicted through the motion and decaying towards zero, so that a slow
    /// slip is explained by the error process and not by the vehicle's parameters or the map.
    /// Off (the default), the errors are weighed as white noise of their long-run variance
    /// ([`rig_model::Noise::white_equivalent`]). Off by default because on, the odometry
    /// scales come out biased (`crate::errors`, docs/vehicle.md "The errors as states"). No
    /// effect when the rig states no memory.
    pub odometry_error_states: bool,
    /// The vehicle's true body-frame velocities `(vx, vy, vtheta)` held as states beside the
    /// odometry's errors (`crate::errors`, "the velocity-state form"): the pose is predicted
    /// from them, and each frame's reported odometry is a measurement of `D v + b + E`,
    /// never the prediction's input. With the rig stating memory only; it implies the error
    /// states. Off by default: honest on the filter-alone drives of the `odometry_errors`
    /// tests, it fails on the generated halls, not yet traced (docs/vehicle.md, "The
    /// velocity-state form").
    pub odometry_velocity_states: bool,
    /// The vehicle's acceleration assumed between frames with the velocity-state form, 1
    /// sigma: `(m/s^2, rad/s^2)`.
    pub velocity_state_acceleration: (f64, f64),
}

impl Default for Settings {
    fn default() -> Self {
        Self {
            gate_probability: 0.999,
            nis_window: 100,
            max_consecutive_rejections: 5,
            covariance_update: CovarianceUpdate::Auto,
            camera_update: CameraUpdate::Refine,
            max_off_axis_deg: 50.0,
            outer_off_axis_deg: 70.0,
            outer_max_noise_gain: 4.0,
            far_max_noise_gain: 1000.0,
            far_min_snr: 2.0,
            far_updates_per_frame: 8,
            local_margin_m: 1.0,
            local_turn_rad: 0.1,
            max_landmarks: usize::MAX,
            follow_points: true,
            follow_scale: true,
            first_estimate_pose: false,
            first_estimate_prediction: true,
            first_estimate_prediction_heading_sigma_rad: FEJ_PREDICTION_HEADING_SIGMA_RAD,
            odometry_error_states: false,
            odometry_velocity_states: false,
            velocity_state_acceleration: (0.2, 0.2),
        }
    }
}

impl Settings {
    /// Where stereo pairs are used, for a rectified camera `c`: the field of use
    /// ([`Settings::max_off_axis_deg`]) and the outer band's pairs whose noise the lens
    /// stretches little ([`Settings::outer_off_axis_deg`], [`Settings::outer_max_noise_gain`]).
    pub fn stereo_field(&self, c: &CameraParams, pixel_sigma: f64) -> rig_model::lens::StereoField {
        rig_model::lens::StereoField::new(
            self.max_off_axis_deg.to_radians(),
            self.outer_off_axis_deg.to_radians(),
            self.outer_max_noise_gain,
            c.f,
            c.cx,
            c.cy,
        )
        .with_far_band(self.far_max_noise_gain, self.far_min_snr, pixel_sigma)
    }

    pub(crate) fn check(&self) -> Result<(), Error> {
        let p = self.gate_probability;
        if !(p.is_finite() && p > 0.0 && p < 1.0) {
            return Err(Error::BadValue {
                name: "Settings.gate_probability",
                value: p,
                expected: "strictly between 0 and 1",
            });
        }
        if self.nis_window == 0 {
            return Err(Error::BadValue {
                name: "Settings.nis_window",
                value: 0.0,
                expected: "at least 1",
            });
        }
        for (name, a) in [
            ("Settings.max_off_axis_deg", self.max_off_axis_deg),
            ("Settings.outer_off_axis_deg", self.outer_off_axis_deg),
        ] {
            if !(a.is_finite() && a > 0.0 && a <= 90.0) {
                return Err(Error::BadValue {
                    name,
                    value: a,
                    expected: "in (0, 90] degrees",
                });
            }
        }
        for (name, value, least, expected) in [
            (
                "Settings.outer_max_noise_gain",
                self.outer_max_noise_gain,
                1.0,
                "finite and at least 1",
            ),
            (
                "Settings.far_max_noise_gain",
                self.far_max_noise_gain,
                1.0,
                "finite and at least 1",
            ),
            (
                "Settings.far_min_snr",
                self.far_min_snr,
                0.0,
                "finite and at least 0",
            ),
            (
                "Settings.local_margin_m",
                self.local_margin_m,
                0.0,
                "finite and at least 0",
            ),
            (
                "Settings.local_turn_rad",
                self.local_turn_rad,
                0.0,
                "finite and at least 0",
            ),
        ] {
            if !(value.is_finite() && value >= least) {
                return Err(Error::BadValue {
                    name,
                    value,
                    expected,
                });
            }
        }
        if self.max_consecutive_rejections == 0 {
            return Err(Error::BadValue {
                name: "Settings.max_consecutive_rejections",
                value: 0.0,
                expected: "at least 1",
            });
        }
        Ok(())
    }
}

/// One landmark observation's gate outcome.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Gated {
    /// The landmark.
    pub id: LandmarkId,
    /// Its normalised innovation squared (4 dof); infinite when the landmark could not be
    /// projected at the current estimate.
    pub nis: f64,
}

/// What one update did.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct UpdateReport {
    /// Observations used, with their NIS.
    pub accepted: Vec<Gated>,
    /// Observations left out by the gate, with their NIS.
    pub rejected: Vec<Gated>,
    /// Landmarks removed after this update for too many rejections in a row.
    pub removed: Vec<LandmarkId>,
}

/// EKF SLAM with the camera parameters in the state (eq. (3)-(8)).
///
/// State `x = [X, Y, theta, L_1, ..., L_N, C_est, E]`; see the crate docs for the layout, the
/// update form and the rest of the design.
#[derive(Debug, Clone)]
pub struct Ekf {
    pub(crate) x: DVector<f64>,
    pub(crate) p: DMatrix<f64>,
    pub(crate) landmarks: Vec<Slot>,
    pub(crate) estimated: Vec<Param>,
    /// The odometry's errors held as states, in state order after the camera block
    /// ([`Settings::odometry_error_states`]).
    pub(crate) errors: Vec<crate::errors::ErrorAxis>,
    /// The vehicle's velocities held as states before the errors
    /// ([`Settings::odometry_velocity_states`]).
    pub(crate) velocity_states: bool,
    /// Values of the parameters not estimated (the estimated ones are read from `x`).
    pub(crate) camera_base: CameraParams,
    pub(crate) noise: Noise,
    /// The rectified pixel noise through the rig's lenses ([`rig_model::Rig::pixel_noise`]).
    pub(crate) pixel_noise: PixelNoise,
    /// The rig's raw lenses: what the cameras see is the raw images, whose rectified view is
    /// not the rectified rectangle ([`Ekf::visible_landmarks`]).
    pub(crate) lens: Option<rig_model::lens::StereoLens>,
    pub(crate) width: u32,
    pub(crate) height: u32,
    pub(crate) settings: Settings,
    pub(crate) gate: f64,
    pub(crate) next_id: u64,
    pub(crate) health: HealthState,
    /// Process noise accumulated on the pose since [`Ekf::take_motion_covariance`], in the
    /// current pose's frame: the relative pose uncertainty between two frames.
    pub(crate) motion_covariance: Matrix3<f64>,
    /// The pose's position where the latest prediction left it, before any update moved it
    /// ([`Settings::first_estimate_pose`]); `None` after the state was set anew.
    pub(crate) predicted_at: Option<[f64; 2]>,
    pub(crate) workspace: Workspace,
    /// Estimated camera parameters held this frame ([`Ekf::set_held`]), by [`Param::index`].
    pub(crate) held: [bool; N_PARAMS],
    /// The open local session, if any (`crate::local`): while it is open, `p` is the
    /// covariance as the session found it and [`Ekf::cov`] reads the current one.
    pub(crate) local: Option<alloc::boxed::Box<crate::local::Local>>,
}

pub(crate) fn check_finite(what: &'static str, value: f64) -> Result<(), Error> {
    if value.is_finite() {
        Ok(())
    } else {
        Err(Error::NonFinite { what, value })
    }
}

impl Ekf {
    /// The noise model (rig file `[noise]`).
    pub fn noise(&self) -> &Noise {
        &self.noise
    }

    /// The rectified pixel noise of the rig's board features (its lenses' stretch).
    pub fn pixel_noise(&self) -> &PixelNoise {
        &self.pixel_noise
    }

    /// The variances of a measurement's `uL, vL, uR, vR`, px^2: [`Noise::pixel`] squared
    /// times the lens's gain at `z` ([`PixelNoise::gains`]).
    pub fn measurement_variances(&self, z: &Measurement) -> [f64; 4] {
        let r2 = self.noise.pixel * self.noise.pixel;
        if self.pixel_noise.is_uniform() {
            return [r2; 4];
        }
        let g = self.pixel_noise.gains(z);
        [r2 * g[0], r2 * g[1], r2 * g[2], r2 * g[3]]
    }

    /// Whether a stereo pair lies beyond the field of use (either point), in the outer band
    /// ([`Settings::outer_off_axis_deg`]), with the rig's lens; never without lens tables.
    pub fn in_outer_band(&self, z: &Measurement) -> bool {
        self.lens.is_some()
            && self.settings.outer_off_axis_deg > self.settings.max_off_axis_deg
            && !self.stereo_field().inner_contains(z)
    }

    /// Whether the pose is lost for the first-estimates Jacobians: its position sigma above
    /// [`FEJ_POSITION_SIGMA_M`] or its heading sigma above [`FEJ_HEADING_SIGMA_RAD`].
    pub(crate) fn pose_lost(&self) -> bool {
        self.cov(0, 0).max(self.cov(1, 1)) > FEJ_POSITION_SIGMA_M * FEJ_POSITION_SIGMA_M
            || self.cov(2, 2) > FEJ_HEADING_SIGMA_RAD * FEJ_HEADING_SIGMA_RAD
    }

    /// Whether a stereo pair lies in the far band ([`Settings::far_max_noise_gain`]).
    pub fn in_far_band(&self, z: &Measurement) -> bool {
        self.lens.is_some()
            && self
                .stereo_field()
                .in_far_band(z, &self.pixel_noise.gains(z).into())
    }

    /// Where the filter uses stereo pairs, with its current camera: the field of use and the
    /// outer band's pairs whose noise the lens stretches little
    /// ([`Settings::outer_off_axis_deg`], [`Settings::outer_max_noise_gain`]).
    pub fn stereo_field(&self) -> rig_model::lens::StereoField {
        self.settings.stereo_field(&self.camera(), self.noise.pixel)
    }

    /// The settings.
    pub fn settings(&self) -> &Settings {
        &self.settings
    }

    /// Switches the form of the covariance update (both are exact; see the crate docs).
    pub fn set_covariance_update(&mut self, form: CovarianceUpdate) {
        self.settings.covariance_update = form;
    }

    /// The NIS bound of the innovation gate (4 dof).
    pub fn gate_bound(&self) -> f64 {
        self.gate
    }

    /// The images' size, pixels.
    pub fn image_size(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    /// The filter's health: counters, windowed NIS, divergence flag.
    pub fn health(&self) -> Health {
        self.health.snapshot()
    }

    /// The process noise added to the pose since the last call, propagated to the current
    /// pose (`M <- F M F^T + Q` at each prediction), and resets it: the uncertainty of the
    /// relative motion between two frames, for the confirmation gate.
    pub(crate) fn take_motion_covariance(&mut self) -> Matrix3<f64> {
        core::mem::replace(&mut self.motion_covariance, Matrix3::zeros())
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used)]
pub(crate) mod tests {
    use super::*;
    use nalgebra::Vector3;
    use rig_model::camera::{Mount, wrap_angle};
    use rig_model::{Measurement, Pose2, Rig};

    /// The unit tests' rig: a 752 x 480 camera (f 700 px, baseline 0.12 m) 0.8 m up looking
    /// straight up, no lens, estimating the baseline (prior sigma 5 mm).
    fn rig() -> Rig {
        rig_estimating(&[(Param::Baseline, 0.005)])
    }

    /// [`rig`], estimating these parameters with these prior sigmas.
    pub(crate) fn rig_estimating(estimate: &[(Param, f64)]) -> Rig {
        let mut prior = [None; N_PARAMS];
        for &(p, sigma) in estimate {
            prior[p.index()] = Some(sigma);
        }
        Rig {
            lens: None,
            board: rig_model::Board::DEFAULT,
            width: 752,
            height: 480,
            nominal: CameraParams {
                vehicle: Default::default(),
                f: 700.0,
                cx: 376.0,
                cy: 240.0,
                baseline: 0.12,
                mount: Mount {
                    z: 0.8,
                    ..Mount::default()
                },
            },
            estimate: estimate.iter().map(|&(p, _)| p).collect(),
            prior,
            noise: Noise::white(0.3, 0.02, 0.01),
        }
    }

    /// Two landmarks seen from the origin, after one prediction.
    fn filter() -> (Ekf, [(LandmarkId, Measurement); 2]) {
        let rig = rig();
        let mut ekf = Ekf::from_prior(&rig, Settings::default()).unwrap();
        let pose = Pose2::default();
        let points = [Vector3::new(0.5, 0.2, 3.0), Vector3::new(-0.3, -0.4, 3.2)];
        let z = points.map(|p| rig_model::project(&rig.nominal, &pose, &p).unwrap());
        let ids = z.map(|z| ekf.add_landmark(&z).unwrap());
        ekf.predict(0.1, 0.0, 0.05, 0.1).unwrap();
        (ekf, [(ids[0], z[0]), (ids[1], z[1])])
    }

    #[test]
    fn a_broken_covariance_is_refused_not_propagated() {
        // S not positive definite: the observed landmark's block made negative definite.
        let (mut ekf, obs) = filter();
        let li = ekf.landmark_state_index(obs[0].0).unwrap();
        for k in 0..3 {
            ekf.p[(li + k, li + k)] = -100.0;
        }
        let before = ekf.clone();
        let e = ekf.update(&obs[..1]).unwrap_err();
        assert_eq!(e, Error::InnovationNotPositiveDefinite { observations: 1 });
        assert_eq!(ekf.x, before.x);
        assert_eq!(ekf.p, before.p);
        let h = ekf.health();
        assert_eq!(h.refused_updates, 1);
        assert!(h.diverged);
        assert_eq!(h.accepted + h.rejected, 0);

        // S fine but an unobserved variance would go negative: landmark 2 nearly certain yet
        // strongly correlated with landmark 1 (an indefinite P).
        let (mut ekf, obs) = filter();
        let (l1, l2) = (
            ekf.landmark_state_index(obs[0].0).unwrap(),
            ekf.landmark_state_index(obs[1].0).unwrap(),
        );
        ekf.p[(l2, l2)] = 1e-6;
        ekf.p[(l1, l2)] = 0.01;
        ekf.p[(l2, l1)] = 0.01;
        for form in [CovarianceUpdate::Joseph, CovarianceUpdate::Factored] {
            ekf.settings.covariance_update = form;
            let before = ekf.clone();
            let e = ekf.update(&obs[..1]).unwrap_err();
            assert!(
                matches!(e, Error::VarianceNotPositive { index, .. } if index == l2),
                "{form:?}: {e}"
            );
            assert_eq!(ekf.x, before.x);
            assert_eq!(ekf.p, before.p);
        }
        assert_eq!(ekf.health().refused_updates, 2);
    }

    #[test]
    fn the_start_pose_keeps_zero_variance_until_the_first_prediction() {
        let rig = rig();
        let mut ekf = Ekf::from_prior(&rig, Settings::default()).unwrap();
        let p = Vector3::new(0.5, 0.2, 3.0);
        let z = rig_model::project(&rig.nominal, &Pose2::default(), &p).unwrap();
        let id = ekf.add_landmark(&z).unwrap();
        let report = ekf.update(&[(id, z)]).unwrap();
        assert_eq!(report.accepted.len(), 1);
        assert_eq!(ekf.pose_covariance(), Matrix3::zeros());
        assert_eq!(ekf.pose(), Pose2::default());
    }

    #[test]
    fn angles_wrap_into_minus_pi_pi() {
        use core::f64::consts::PI;
        for (a, w) in [
            (0.0, 0.0),
            (PI, PI),
            (-PI, PI),
            (3.0 * PI, PI),
            (2.0 * PI + 0.1, 0.1),
            (-2.0 * PI - 0.1, -0.1),
            (7.0, 7.0 - 2.0 * PI),
        ] {
            assert!((wrap_angle(a) - w).abs() < 1e-12, "{a}: {}", wrap_angle(a));
        }
    }
}
