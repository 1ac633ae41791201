//! A synthetic hall for the localiser, shared by the relocalisation test (`tests/reloc.rs`,
//! as `mod support`), the Monte Carlo (`examples/reloc_mc.rs`) and the benchmark
//! (`benches/localize_10k.rs`, both with `#[path]`): a grid of ceiling lamps (regular or
//! jittered), the map a mapping run would have saved of it (each lamp off by its 5 mm sigma),
//! the hall's rig, a seeded drive through the hall at about 1 m/s, and what the board and
//! the odometry report of it (vehicle-interfaces.md 1, 2): 100 Hz odometry with noise, 20 Hz
//! stereo frames of the lamps in view with pixel noise, quantised to the board's 1/16 px, and
//! a little clutter.
//!
//! It lives here, not in the library, so that the `no_std` crate needs no random-number
//! dependency or feature for it: the three targets use only dev-dependencies.
//!
//! Everything is drawn from `ChaCha8` generators seeded from the run's seed, one stream per
//! purpose (hall, map, start, drive, sensors), so a run is the same for a seed whatever the
//! others do.
#![allow(dead_code, unreachable_pub)] // each target uses a part

use localize::{Error, LampMap, Localizer, LocalizerSettings, MapLamp};
use nalgebra::{Matrix3, Vector3};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Poisson, StandardNormal};
use rig_model::camera::{CameraParams, Mount, N_PARAMS, Pose2, Vehicle, wrap_angle};
use rig_model::config::{Noise, Rig};
use rig_model::odometry::{OdomSample, constant_velocity_motion};
use rig_model::project;
use track::Pixel;

/// Odometry period, microseconds (100 Hz).
pub const ODOMETRY_PERIOD_US: u64 = 10_000;
/// Stereo frame period, microseconds (20 Hz).
pub const FRAME_PERIOD_US: u64 = 50_000;
/// Odometry samples per frame.
const ODOMETRY_PER_FRAME: u64 = FRAME_PERIOD_US / ODOMETRY_PERIOD_US;
/// Pixel noise, 1 sigma, each of `uL, vL, uR, vR`.
pub const PIXEL_SIGMA_PX: f64 = 0.3;
/// Odometry noise per sample, each of `vx, vy`, m/s.
pub const VELOCITY_SIGMA: f64 = 0.02;
/// Odometry yaw-rate noise per sample, rad/s.
pub const YAW_RATE_SIGMA: f64 = 0.01;
/// The board's sub-pixel step (`u = x_q4 / 16`).
const Q4_SCALE: f64 = 16.0;
/// Lamp spacing, metres.
pub const SPACING_M: f64 = 2.5;
/// Lamp height above the floor, metres.
pub const LAMP_HEIGHT_M: f64 = 7.0;
/// The map's lamp sigma (each axis), and the size of the map's error, metres.
pub const MAP_SIGMA_M: f64 = 0.005;
/// Mean clutter stereo pairs per frame (Poisson).
pub const CLUTTER_PER_FRAME: f64 = 1.0;
/// The drive keeps this far inside the lamp grid's outline, metres.
pub const HALL_MARGIN_M: f64 = 1.5;

/// One generator per seed and purpose.
pub fn rng(seed: u64, purpose: u64) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ purpose)
}

fn normal(rng: &mut ChaCha8Rng) -> f64 {
    StandardNormal.sample(rng)
}

/// The hall's rig: 752x480, f = 250 px (rectified, no lens), baseline 0.12 m, mounted 2.2 m
/// up and 0.3 m forward, pitched 0.05 rad; the noise of this module.
pub fn rig() -> Rig {
    Rig {
        width: 752,
        height: 480,
        nominal: CameraParams {
            f: 250.0,
            cx: 376.0,
            cy: 240.0,
            baseline: 0.12,
            mount: Mount {
                x: 0.3,
                y: 0.0,
                z: 2.2,
                roll: 0.0,
                pitch: 0.05,
                yaw: 0.0,
            },
            vehicle: Vehicle::NOMINAL,
        },
        estimate: Vec::new(),
        prior: [None; N_PARAMS],
        noise: Noise::white(PIXEL_SIGMA_PX, VELOCITY_SIGMA, YAW_RATE_SIGMA),
        lens: None,
        board: rig_model::Board::DEFAULT,
    }
}

/// A lamp grid: `nx x ny` lamps at [`SPACING_M`], [`LAMP_HEIGHT_M`] up, each moved by a
/// uniform jitter of up to `jitter_xy_m` in x and y and `jitter_z_m` in z.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Grid {
    /// Lamps along x.
    pub nx: usize,
    /// Lamps along y.
    pub ny: usize,
    /// Half-width of the uniform jitter in x and y, metres.
    pub jitter_xy_m: f64,
    /// Half-width of the uniform jitter in z, metres.
    pub jitter_z_m: f64,
}

impl Grid {
    /// A regular grid (no jitter).
    pub const fn regular(nx: usize, ny: usize) -> Self {
        Self {
            nx,
            ny,
            jitter_xy_m: 0.0,
            jitter_z_m: 0.0,
        }
    }

    /// A jittered grid: 0.25 m in x and y, 0.1 m in z.
    pub const fn jittered(nx: usize, ny: usize) -> Self {
        Self {
            nx,
            ny,
            jitter_xy_m: 0.25,
            jitter_z_m: 0.1,
        }
    }
}

/// The hall: the true lamps (row-major, `x` fastest), the map of them, and the floor the
/// drive keeps to.
#[derive(Debug, Clone)]
pub struct Hall {
    /// The grid it was made from.
    pub grid: Grid,
    /// True lamp positions, index `iy * nx + ix`.
    pub truth: Vec<Vector3<f64>>,
    /// The saved map: every lamp off by `N(0, MAP_SIGMA_M^2)` per axis, with that covariance.
    pub map: Vec<MapLamp>,
    /// The floor the drive keeps to: `(x0, y0, x1, y1)`, metres.
    pub floor: (f64, f64, f64, f64),
}

impl Hall {
    /// The hall of `grid` for `seed`.
    pub fn new(grid: Grid, seed: u64) -> Self {
        let mut rng_hall = rng(seed, 1);
        let mut rng_map = rng(seed, 2);
        let mut truth = Vec::with_capacity(grid.nx * grid.ny);
        for iy in 0..grid.ny {
            for ix in 0..grid.nx {
                let jitter = |rng: &mut ChaCha8Rng, half: f64| {
                    if half > 0.0 {
                        rng.random_range(-half..half)
                    } else {
                        0.0
                    }
                };
                #[allow(clippy::cast_precision_loss)]
                let (x, y) = (ix as f64 * SPACING_M, iy as f64 * SPACING_M);
                truth.push(Vector3::new(
                    x + jitter(&mut rng_hall, grid.jitter_xy_m),
                    y + jitter(&mut rng_hall, grid.jitter_xy_m),
                    LAMP_HEIGHT_M + jitter(&mut rng_hall, grid.jitter_z_m),
                ));
            }
        }
        let map = truth
            .iter()
            .enumerate()
            .map(|(i, p)| MapLamp {
                id: i as u64,
                position: p + Vector3::new(
                    normal(&mut rng_map),
                    normal(&mut rng_map),
                    normal(&mut rng_map),
                ) * MAP_SIGMA_M,
                covariance: Matrix3::identity() * (MAP_SIGMA_M * MAP_SIGMA_M),
            })
            .collect();
        #[allow(clippy::cast_precision_loss)]
        let (w, h) = (
            (grid.nx.max(1) - 1) as f64 * SPACING_M,
            (grid.ny.max(1) - 1) as f64 * SPACING_M,
        );
        Self {
            grid,
            truth,
            map,
            floor: (
                HALL_MARGIN_M,
                HALL_MARGIN_M,
                w - HALL_MARGIN_M,
                h - HALL_MARGIN_M,
            ),
        }
    }

    /// A pose drawn uniformly on the floor, any heading.
    pub fn random_pose(&self, rng: &mut ChaCha8Rng) -> Pose2 {
        let (x0, y0, x1, y1) = self.floor;
        Pose2::new(
            rng.random_range(x0..x1),
            rng.random_range(y0..y1),
            rng.random_range(-core::f64::consts::PI..core::f64::consts::PI),
        )
    }

    /// The true lamps within `radius` of `(x, y)` horizontally, by the grid's layout (each lamp
    /// is within its jitter of its grid point): the generator's own index, not the map's.
    fn lamps_near(&self, x: f64, y: f64, radius: f64) -> impl Iterator<Item = &Vector3<f64>> {
        let reach = radius + self.grid.jitter_xy_m;
        let range = |c: f64, n: usize| {
            #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
            let lo = (((c - reach) / SPACING_M).floor().max(0.0)) as usize;
            #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
            let hi = (((c + reach) / SPACING_M).ceil().max(0.0) as usize).min(n);
            lo..hi.max(lo)
        };
        let (rx, ry) = (range(x, self.grid.nx), range(y, self.grid.ny));
        let nx = self.grid.nx;
        ry.flat_map(move |iy| rx.clone().map(move |ix| iy * nx + ix))
            .filter_map(|i| self.truth.get(i))
            .filter(move |p| (p.x - x).hypot(p.y - y) <= radius)
    }
}

/// The localiser on `map` for [`rig`], as `stereonav localize` builds it
/// (`replay::localization::localizer_for`): default settings, the pair table out to twice
/// the footprint radius at 10 m (capped at the settings' reach), `C` exact (the synthetic
/// world's camera is the nominal one) and `V` known to a mapping run's sigmas.
pub fn localizer(map: Vec<MapLamp>) -> Result<Localizer, Error> {
    let rig = rig();
    let settings = LocalizerSettings::default();
    let index = LampMap::new(map, settings.max_reach_m.min(2.0 * pair_radius_m(&rig)))?;
    let mut sigma = [0.0; N_PARAMS];
    for (k, s) in [0.002, 0.002, 0.0005, 0.001].into_iter().enumerate() {
        if let Some(slot) = sigma.get_mut(rig_model::N_CAMERA + k) {
            *slot = s;
        }
    }
    let camera = rig.nominal;
    Localizer::new(index, rig, camera, &sigma, settings)
}

/// The pair radius `stereonav localize` uses (`replay::localization`'s `pair_radius`): the
/// footprint radius of the image's half-diagonal 10 m above the cameras.
pub fn pair_radius_m(rig: &Rig) -> f64 {
    let half = f64::from(rig.width).hypot(f64::from(rig.height)) / 2.0;
    let angle = (half / rig.nominal.f).atan().min(1.2);
    10.0 * angle.tan()
}

/// What the board and the odometry report between two frames, and the truth.
#[derive(Debug, Clone, PartialEq)]
pub struct Step {
    /// The odometry samples since the previous frame, up to and including the frame's time.
    pub odometry: Vec<OdomSample>,
    /// The frame's time, microseconds.
    pub t_us: u64,
    /// Left features (rectified pixels), in the board's raster order.
    pub left: Vec<Pixel>,
    /// Right features.
    pub right: Vec<Pixel>,
    /// The true pose at the frame.
    pub truth: Pose2,
    /// True lamps whose both pixels are in the images.
    pub lamps_in_view: usize,
}

/// The drive's plan: straights at 1 m/s and turns at 0.7 m/s and 0.5 rad/s, 1 to 3 s each,
/// turning back toward the middle of the hall whenever a straight would leave the floor.
#[derive(Debug, Clone)]
struct Plan {
    vx: f64,
    w: f64,
    left_us: u64,
}

/// A seeded drive through a hall with its sensors.
#[derive(Debug, Clone)]
pub struct Drive<'a> {
    hall: &'a Hall,
    camera: CameraParams,
    width: f64,
    height: f64,
    pose: Pose2,
    t_us: u64,
    started: bool,
    plan: Plan,
    rng_drive: ChaCha8Rng,
    rng_sensors: ChaCha8Rng,
    clutter: Poisson<f64>,
}

/// Straight speed, m/s.
const STRAIGHT_MPS: f64 = 1.0;
/// Turning speed, m/s.
const TURN_MPS: f64 = 0.7;
/// Turn rate, rad/s.
const TURN_RAD_S: f64 = 0.5;
/// How far ahead a straight must stay on the floor, metres.
const LOOKAHEAD_M: f64 = 2.0;

impl<'a> Drive<'a> {
    /// A drive through `hall` from `start` at `t0_us`, with the drive and the sensors drawn
    /// for `seed`.
    pub fn new(hall: &'a Hall, start: Pose2, t0_us: u64, seed: u64) -> Self {
        let rig = rig();
        Self {
            hall,
            camera: rig.nominal,
            width: f64::from(rig.width),
            height: f64::from(rig.height),
            pose: start,
            t_us: t0_us,
            started: false,
            plan: Plan {
                vx: 0.0,
                w: 0.0,
                left_us: 0,
            },
            rng_drive: rng(seed, 4),
            rng_sensors: rng(seed, 5),
            #[allow(clippy::unwrap_used)] // a positive constant mean
            clutter: Poisson::new(CLUTTER_PER_FRAME).unwrap(),
        }
    }

    /// The true pose now.
    pub fn pose(&self) -> Pose2 {
        self.pose
    }

    /// The time now, microseconds.
    pub fn t_us(&self) -> u64 {
        self.t_us
    }

    /// Moves the vehicle to `pose` while `gap_us` pass with neither frames nor odometry (a
    /// kidnap): the next step starts afresh there.
    pub fn teleport(&mut self, pose: Pose2, gap_us: u64) {
        self.pose = pose;
        self.t_us += gap_us;
        self.started = false;
        self.plan.left_us = 0;
    }

    fn on_floor(&self, x: f64, y: f64) -> bool {
        let (x0, y0, x1, y1) = self.hall.floor;
        x >= x0 && x <= x1 && y >= y0 && y <= y1
    }

    fn ahead_on_floor(&self, d: f64) -> bool {
        let p = &self.pose;
        self.on_floor(p.x + d * p.theta.cos(), p.y + d * p.theta.sin())
    }

    /// Turn direction toward the middle of the floor: +1 left, -1 right.
    fn toward_middle(&self) -> f64 {
        let (x0, y0, x1, y1) = self.hall.floor;
        let (mx, my) = (0.5 * (x0 + x1), 0.5 * (y0 + y1));
        let bearing = (my - self.pose.y).atan2(mx - self.pose.x);
        if wrap_angle(bearing - self.pose.theta) >= 0.0 {
            1.0
        } else {
            -1.0
        }
    }

    fn replan(&mut self) {
        let duration_s: f64 = self.rng_drive.random_range(1.0..3.0);
        let straight = self.rng_drive.random_bool(0.6);
        let sign = if self.rng_drive.random_bool(0.5) {
            1.0
        } else {
            -1.0
        };
        let clear = self.ahead_on_floor(STRAIGHT_MPS * duration_s + LOOKAHEAD_M);
        self.plan = if straight && clear {
            Plan {
                vx: STRAIGHT_MPS,
                w: 0.0,
                left_us: 0,
            }
        } else {
            let sign = if clear { sign } else { self.toward_middle() };
            Plan {
                vx: TURN_MPS,
                w: sign * TURN_RAD_S,
                left_us: 0,
            }
        };
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        {
            self.plan.left_us = (duration_s * 1e6) as u64;
        }
    }

    /// The plan for the next odometry period: a new segment when one ends; a straight that
    /// would leave the floor turns back toward the middle at once.
    fn decide(&mut self) {
        if self.plan.left_us == 0 {
            self.replan();
        }
        if self.plan.w == 0.0 && !self.ahead_on_floor(LOOKAHEAD_M) {
            self.plan = Plan {
                vx: TURN_MPS,
                w: self.toward_middle() * TURN_RAD_S,
                left_us: 1_500_000,
            };
        }
    }

    /// The sample reported at the current time: the velocities held until the next sample,
    /// plus noise.
    fn emit(&mut self) -> OdomSample {
        self.decide();
        OdomSample {
            t_us: self.t_us,
            vx: self.plan.vx + VELOCITY_SIGMA * normal(&mut self.rng_sensors),
            vy: VELOCITY_SIGMA * normal(&mut self.rng_sensors),
            vtheta: self.plan.w + YAW_RATE_SIGMA * normal(&mut self.rng_sensors),
        }
    }

    /// The truth moved on by one odometry period at the planned (true) velocities.
    fn advance(&mut self) {
        #[allow(clippy::cast_precision_loss)]
        let dt = ODOMETRY_PERIOD_US as f64 * 1e-6;
        let moved = constant_velocity_motion(self.plan.vx, 0.0, self.plan.w, dt).apply(&self.pose);
        self.pose = Pose2::new(moved.x, moved.y, wrap_angle(moved.theta));
        self.t_us += ODOMETRY_PERIOD_US;
        self.plan.left_us = self.plan.left_us.saturating_sub(ODOMETRY_PERIOD_US);
    }

    /// The next frame and the odometry before it: at the start (or after a teleport) the
    /// sample at the frame's time, then the five since the previous frame, the last one at
    /// the frame's time (held until the next), so that the odometry covers every frame.
    pub fn step(&mut self) -> Step {
        let mut odometry = Vec::with_capacity(ODOMETRY_PER_FRAME as usize);
        if self.started {
            for _ in 0..ODOMETRY_PER_FRAME {
                self.advance();
                odometry.push(self.emit());
            }
        } else {
            odometry.push(self.emit());
            self.started = true;
        }
        let t_us = self.t_us;
        let truth = self.pose;
        let (left, right, lamps_in_view) = self.frame(&truth);
        Step {
            odometry,
            t_us,
            left,
            right,
            truth,
            lamps_in_view,
        }
    }

    fn inside(&self, u: f64, v: f64) -> bool {
        u >= 0.0 && u <= self.width - 1.0 && v >= 0.0 && v <= self.height - 1.0
    }

    /// The board's features of the true lamps in view from `pose`, plus clutter.
    fn frame(&mut self, pose: &Pose2) -> (Vec<Pixel>, Vec<Pixel>, usize) {
        let q = |x: f64| (x * Q4_SCALE).round() / Q4_SCALE;
        let mut left = Vec::new();
        let mut right = Vec::new();
        let mut in_view = 0;
        let c = self.camera;
        // 15 m covers the widest ray of this rig to lamps 7 m up (about 10 m).
        let near: Vec<Vector3<f64>> = self
            .hall
            .lamps_near(pose.x, pose.y, 15.0)
            .copied()
            .collect();
        for lamp in &near {
            let Ok(z) = project(&c, pose, lamp) else {
                continue;
            };
            let mut n = [0.0; 4];
            for v in &mut n {
                *v = PIXEL_SIGMA_PX * normal(&mut self.rng_sensors);
            }
            let (ul, vl, ur, vr) = (
                q(z[0] + n[0]),
                q(z[1] + n[1]),
                q(z[2] + n[2]),
                q(z[3] + n[3]),
            );
            let (l_in, r_in) = (self.inside(ul, vl), self.inside(ur, vr));
            if l_in {
                left.push(Pixel { u: ul, v: vl });
            }
            if r_in {
                right.push(Pixel { u: ur, v: vr });
            }
            if l_in && r_in {
                in_view += 1;
            }
        }
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let clutter = self.clutter.sample(&mut self.rng_sensors) as usize;
        for _ in 0..clutter {
            let u = self.rng_sensors.random_range(0.0..self.width - 1.0);
            let v = self.rng_sensors.random_range(0.0..self.height - 1.0);
            let d = self.rng_sensors.random_range(2.0..30.0);
            let vr = v + PIXEL_SIGMA_PX * normal(&mut self.rng_sensors);
            left.push(Pixel { u: q(u), v: q(v) });
            if self.inside(u - d, vr) {
                right.push(Pixel {
                    u: q(u - d),
                    v: q(vr),
                });
            }
        }
        let raster = |a: &Pixel, b: &Pixel| a.v.total_cmp(&b.v).then(a.u.total_cmp(&b.u));
        left.sort_by(raster);
        right.sort_by(raster);
        (left, right, in_view)
    }
}

/// Position and heading error of `estimate` against `truth`: metres, radians (absolute).
pub fn pose_error(estimate: &Pose2, truth: &Pose2) -> (f64, f64) {
    (
        (estimate.x - truth.x).hypot(estimate.y - truth.y),
        wrap_angle(estimate.theta - truth.theta).abs(),
    )
}

/// A localised frame farther than this from the truth is a false fix, metres (issue 20).
pub const FALSE_FIX_M: f64 = 0.25;
/// ... or this far off in heading, radians (3 degrees).
pub const FALSE_FIX_RAD: f64 = 3.0 * core::f64::consts::PI / 180.0;
/// Frames at 20 Hz in 10 s.
pub const FRAMES_10_S: usize = 200;
/// The kidnap's blind spell, microseconds.
pub const KIDNAP_GAP_US: u64 = 8_000_000;
/// The first frame's time, microseconds.
const T0_US: u64 = 1_000_000;

/// One leg of a run against the truth.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Leg {
    /// Seconds from the leg's first frame to its first localised one.
    pub fix_s: Option<f64>,
    /// Localised frames farther than [`FALSE_FIX_M`] or [`FALSE_FIX_RAD`] from the truth.
    pub false_frames: u32,
    /// The first of them: time since the leg's start (s), position error (m), heading
    /// error (deg).
    pub first_false: Option<(f64, f64, f64)>,
    /// Largest position error of a localised frame, metres.
    pub max_err_m: f64,
    /// Localised frames.
    pub localized_frames: u64,
    /// Sum of the squared position errors of the localised frames, m^2.
    pub sum_sq_m: f64,
    /// Sum of the squared heading errors of the localised frames, rad^2.
    pub sum_sq_rad: f64,
    /// Frames pushed.
    pub frames: u64,
    /// Sum over the frames of the true lamps in view.
    pub lamps_in_view: u64,
}

/// One run's outcome: its legs, and the inputs the localiser refused (none expected).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Outcome {
    /// The seed.
    pub seed: u64,
    /// Each leg (one, or two around a kidnap).
    pub legs: Vec<Leg>,
    /// Inputs refused.
    pub refused: u64,
}

impl Outcome {
    /// Localised frames off the truth over the whole run.
    pub fn false_frames(&self) -> u32 {
        self.legs.iter().map(|l| l.false_frames).sum()
    }

    /// Position error RMS over the run's localised frames, metres.
    pub fn rms_m(&self) -> f64 {
        let n: u64 = self.legs.iter().map(|l| l.localized_frames).sum();
        let sq: f64 = self.legs.iter().map(|l| l.sum_sq_m).sum();
        #[allow(clippy::cast_precision_loss)]
        let rms = (sq / n.max(1) as f64).sqrt();
        rms
    }
}

/// Runs the localiser through `hall` for `seed`: from a random start pose (unknown to it),
/// one leg of `legs[0]` frames, then for every further leg a kidnap (neither frames nor
/// odometry for [`KIDNAP_GAP_US`] while the vehicle is carried to another random pose) and
/// that many frames more. `on_frame` sees every frame (leg, step, result, localiser).
pub fn run(
    hall: &Hall,
    seed: u64,
    legs: &[usize],
    on_frame: &mut dyn FnMut(usize, &Step, &localize::FrameResult, &Localizer),
) -> Result<Outcome, Error> {
    let mut localizer = localizer(hall.map.clone())?;
    let mut rng_start = rng(seed, 3);
    let start = hall.random_pose(&mut rng_start);
    let mut drive = Drive::new(hall, start, T0_US, seed);
    let mut out = Outcome {
        seed,
        legs: vec![Leg::default(); legs.len()],
        refused: 0,
    };
    for (leg, &frames) in legs.iter().enumerate() {
        if leg > 0 {
            let to = hall.random_pose(&mut rng_start);
            drive.teleport(to, KIDNAP_GAP_US);
        }
        let leg_t0 = drive.t_us();
        for _ in 0..frames {
            let step = drive.step();
            for s in &step.odometry {
                if localizer.push_odometry(*s).is_err() {
                    out.refused += 1;
                }
            }
            let Ok(result) = localizer.push_frame(step.t_us, &step.left, &step.right) else {
                out.refused += 1;
                continue;
            };
            on_frame(leg, &step, &result, &localizer);
            let Some(this) = out.legs.get_mut(leg) else {
                continue;
            };
            this.frames += 1;
            this.lamps_in_view += step.lamps_in_view as u64;
            if result.status != localize::Status::Localized {
                continue;
            }
            let (e, h) = result.pose.map_or((f64::INFINITY, f64::INFINITY), |p| {
                pose_error(&p, &step.truth)
            });
            #[allow(clippy::cast_precision_loss)]
            let since_leg_s = (step.t_us - leg_t0) as f64 * 1e-6;
            this.fix_s.get_or_insert(since_leg_s);
            this.localized_frames += 1;
            this.sum_sq_m += e * e;
            this.sum_sq_rad += h * h;
            this.max_err_m = this.max_err_m.max(e);
            if e > FALSE_FIX_M || h > FALSE_FIX_RAD {
                this.false_frames += 1;
                this.first_false
                    .get_or_insert((since_leg_s, e, h.to_degrees()));
            }
        }
    }
    Ok(out)
}
