//! What the viewer shows, as plain data: a vehicle log replayed (or an estimates file read
//! back, or a log localised on a saved map), the board's features per frame, the simulator's
//! truth, and the series that the plots draw, all computed once at load time
//! ([`Model::from_replay`], [`Model::from_localization`]). Nothing here draws; the
//! queries at one instant ([`Model::frame_at`], [`Model::map_at`], [`Model::marks`],
//! [`Model::field_of_view`]) are binary searches and work in proportion to what one frame
//! shows, never to the length of the log, so that scrubbing a long log stays smooth.

use std::collections::VecDeque;
use std::ops::Range;
use std::path::PathBuf;

use nalgebra::Vector3;
use replay::{
    CameraSample, FrameEstimate, LandmarkEstimate, LocalizeEnd, LocalizeTruth, LocalizedFrame,
    MapSnapshot, Phase, Replay,
};
use rig_model::camera::{CameraParams, Param, Pose2};
use rig_model::lens::StereoLens;

use crate::images::BagImages;

/// In a localisation run, a feature is marked as near a map lamp when it lies within this
/// distance of the lamp's projection at the frame's pose, pixels: the localiser reports how many
/// lamps it matched, not which. A replay's features are marked by the navigator's own
/// associations instead ([`FrameEstimate::associations`]).
pub const ASSOCIATION_RADIUS_PX: f64 = 4.0;

/// Most points of one plotted series; longer series are thinned by time (see [`thin_by_time`]).
pub const PLOT_POINTS: usize = 2000;

/// Most points of the drawn trajectory (estimate or truth); longer paths are thinned by time.
pub const PATH_POINTS: usize = 2000;

/// Most per-frame NIS points plotted (each is a small disc: fewer than the lines get).
pub const NIS_POINTS: usize = 1000;

/// A feature's position in an image, `(u, v)` pixels.
pub type ImagePoint = [f32; 2];

/// Degrees of freedom of one landmark observation `(uL, vL, uR, vR)`.
const NIS_DOF: f64 = 4.0;

/// Height of the lamp plane above the floor when neither the map nor the truth gives one:
/// this much above the rig, metres.
const DEFAULT_LAMPS_ABOVE_RIG_M: f64 = 2.0;

/// Where the data came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SourceKind {
    /// A vehicle log, replayed through the stack when it was loaded.
    VehicleLog,
    /// An estimates file (`EST.mcap`) written by `stereonav replay`.
    Estimates,
}

/// The board's features of one stereo frame: ranges into [`Features::points`].
#[derive(Debug, Clone, PartialEq)]
pub struct FeatureFrame {
    /// The frame's timestamp, microseconds.
    pub t_us: u64,
    /// Left image features.
    pub left: Range<usize>,
    /// Right image features.
    pub right: Range<usize>,
}

/// Every frame's features, flat.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Features {
    /// Frames sorted by timestamp.
    pub frames: Vec<FeatureFrame>,
    /// The features of all frames.
    pub points: Vec<ImagePoint>,
}

impl Features {
    /// Adds a frame (frames must come in time order).
    pub fn push(&mut self, t_us: u64, left: &[ImagePoint], right: &[ImagePoint]) {
        let start = self.points.len();
        self.points.extend_from_slice(left);
        let middle = self.points.len();
        self.points.extend_from_slice(right);
        self.frames.push(FeatureFrame {
            t_us,
            left: start..middle,
            right: middle..self.points.len(),
        });
    }

    /// The left and right features of the frame at exactly `t_us`, if the log has it.
    pub fn at(&self, t_us: u64) -> Option<(&[ImagePoint], &[ImagePoint])> {
        let i = self.frames.binary_search_by_key(&t_us, |f| f.t_us).ok()?;
        let f = self.frames.get(i)?;
        Some((
            self.points.get(f.left.clone())?,
            self.points.get(f.right.clone())?,
        ))
    }
}

/// The simulator's truth in a log.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Truth {
    /// `(t_us, x, y, theta)` at each stereo frame, sorted by time.
    pub poses: Vec<(u64, [f64; 3])>,
    /// Every lamp, world metres.
    pub lamps: Vec<[f64; 3]>,
}

/// One camera parameter over time, in display units, thinned to at most [`PLOT_POINTS`].
#[derive(Debug, Clone, PartialEq)]
pub struct ParamSeries {
    /// The parameter.
    pub param: Param,
    /// Display unit (`px`, `mm`, `deg`).
    pub unit: &'static str,
    /// Seconds from the log's start.
    pub t_s: Vec<f64>,
    /// Values, display units.
    pub value: Vec<f64>,
    /// 1-sigma, display units.
    pub sigma: Vec<f64>,
    /// The simulator's true value, display units, when the log's truth has it.
    pub truth: Option<f64>,
}

/// The filter's consistency over time: the NIS of the accepted observations, per degree of
/// freedom (1 on average for a consistent filter), thinned to at most [`PLOT_POINTS`] (the
/// frame means to [`NIS_POINTS`]).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct NisSeries {
    /// `(t_s, mean NIS per dof of the frame's accepted observations)`; within a thinning
    /// bucket, the largest is kept (a spike must not vanish).
    pub frame_mean: Vec<[f64; 2]>,
    /// `(t_s, mean NIS per dof over the last `window` accepted observations)`, the filter's
    /// health window.
    pub window_mean: Vec<[f64; 2]>,
    /// `(t_s, upper bound of that mean)`: `chi2_p(4 w) / (4 w)` for the `w` observations in
    /// the window, `p` = [`vslam_ekf::health::DIVERGENCE_PROBABILITY`].
    pub window_bound: Vec<[f64; 2]>,
    /// Observations in the full window.
    pub window: usize,
}

/// A board feature of one image at the current frame (raw pixels, as the board sent it), with
/// what the navigator made of it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FeatureMark {
    /// Column, pixels.
    pub u: f32,
    /// Row, pixels.
    pub v: f32,
    /// The landmark the navigator's update was given it as an observation of at this frame
    /// ([`FrameEstimate::associations`]); in a localisation run, the map lamp whose projection
    /// it lies near ([`ASSOCIATION_RADIUS_PX`]).
    pub landmark: Option<u64>,
    /// The observation was accepted: the landmark was updated with it (else the gate rejected
    /// it; in a localisation run, never set).
    pub observed: bool,
}

/// A landmark's projection into one image at the current frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Projection {
    /// The landmark.
    pub id: u64,
    /// Column, pixels: in the board's raw image when the rig has lens tables
    /// ([`Model::lens`]), where the features are.
    pub u: f64,
    /// Row, pixels, likewise.
    pub v: f64,
    /// It was updated at this frame.
    pub observed: bool,
}

/// The two images at one frame: the features marked by the navigator's associations, and the
/// landmarks' projections, both in the board's pixels.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct FrameMarks {
    /// Left image features.
    pub left: Vec<FeatureMark>,
    /// Right image features.
    pub right: Vec<FeatureMark>,
    /// Landmarks projected into the left image (inside it).
    pub projected_left: Vec<Projection>,
    /// Landmarks projected into the right image (inside it).
    pub projected_right: Vec<Projection>,
    /// The features of each image the navigator's update took as observations of landmarks
    /// at this frame (its accepted associations: one left and one right feature each); `None`
    /// when the source does not say which (an estimates file without associations, or without
    /// features; a localisation run).
    pub on_landmarks: Option<usize>,
}

/// Everything the viewer shows (see the module docs).
#[derive(Debug, Clone)]
pub struct Model {
    /// The file shown.
    pub path: PathBuf,
    /// What it was.
    pub kind: SourceKind,
    /// The estimates.
    pub replay: Replay,
    /// The time origin of the viewer's clock (the first frame), microseconds.
    pub t0_us: u64,
    /// Image size, pixels: the rig's, or `2 cx x 2 cy` for an estimates file (which has no rig).
    pub image_size: [f64; 2],
    /// The rig's nominal camera, when known (vehicle logs).
    pub nominal: Option<CameraParams>,
    /// The rig's lenses (`[lens.left]`, `[lens.right]`), when it has them: the board's
    /// features are raw pixels, and the landmarks' projections (in the rectified model whose
    /// `f, cx, cy` are [`Model::nominal`]'s, vehicle-interfaces.md 1.1) are taken back through
    /// them to be drawn among the features. Unused without a nominal camera.
    pub lens: Option<StereoLens>,
    /// The board's features (none for an estimates file). For a ROS 2 bag, those of the
    /// board's detector run on the host, as the replay ran it.
    pub features: Features,
    /// A ROS 2 bag's camera images, by frame: where each frame's two images are, read back
    /// when the frame is shown ([`crate::images`]). `None` for the board's stream and for an
    /// estimates file, which carry no images.
    pub images: Option<BagImages>,
    /// The simulator's truth, when the log has it.
    pub truth: Option<Truth>,
    /// The estimated camera parameters over time, [`Param::ALL`] order (those held fixed are
    /// left out).
    pub params: Vec<ParamSeries>,
    /// NIS over time.
    pub nis: NisSeries,
    /// The estimated trajectory thinned to [`PATH_POINTS`]: `(frame index, [x, y])`.
    pub trajectory: Vec<(usize, [f64; 2])>,
    /// The true trajectory thinned to [`PATH_POINTS`]: `(t_us, [x, y])`.
    pub truth_trajectory: Vec<(u64, [f64; 2])>,
    /// Height of the lamp plane, metres: where the field of view is drawn.
    pub lamp_height_m: f64,
    /// The world rectangle holding the trajectories, the final map and the lamps:
    /// `[min x, min y, max x, max y]`.
    pub bounds: [f64; 4],
    /// Things the viewer noticed while loading, one line each (the replay's warnings first).
    pub warnings: Vec<String>,
    /// The localisation run, when the log was run on a saved map ([`Model::from_localization`]).
    pub localization: Option<Localization>,
}

/// A lamp a localisation run saw that is not in the map (`localize::NewLamp`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NewLampMark {
    /// Position in the map's frame, metres.
    pub position: [f64; 3],
    /// Its covariance, row-major, square metres.
    pub covariance: [[f64; 3]; 3],
    /// Observations fused.
    pub observations: u32,
}

/// A stretch of the trajectory with one status, drawn in one colour: `(frame index, [x, y])`,
/// thinned. A stretch that follows another without a frame between them starts at the
/// other's last point, so that the line is unbroken; frames without a pose break it.
#[derive(Debug, Clone, PartialEq)]
pub struct TrackRun {
    /// Localised (else lost: the localiser's best guess).
    pub localized: bool,
    /// The points, frame indices ascending.
    pub points: Vec<(usize, [f64; 2])>,
}

/// Consecutive frames with one status: indices into [`Localization::frames`].
#[derive(Debug, Clone, PartialEq)]
pub struct StatusRun {
    /// The frames.
    pub frames: Range<usize>,
    /// Localised (else lost).
    pub localized: bool,
}

/// The localisation run's series over time, thinned to about [`PLOT_POINTS`] (every change of
/// status and of having a pose kept, so that no stretch vanishes); NaN where a frame has no
/// pose (a break in the line).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct LocalizationSeries {
    /// Seconds from the log's start.
    pub t_s: Vec<f64>,
    /// The frames kept, indices into [`Localization::frames`].
    pub frame: Vec<usize>,
    /// The frame was localised.
    pub localized: Vec<bool>,
    /// Position 1-sigma, `sqrt(sigma_x^2 + sigma_y^2)`, millimetres.
    pub position_sigma_mm: Vec<f64>,
    /// Heading 1-sigma, degrees.
    pub heading_sigma_deg: Vec<f64>,
    /// Map lamps associated at the frame.
    pub matched: Vec<f64>,
    /// Live relocalisation hypotheses.
    pub hypotheses: Vec<f64>,
    /// Distance of the pose from the log's true pose at the frame, millimetres (empty when the
    /// log has no truth).
    pub error_mm: Vec<f64>,
}

/// A vehicle log run on a saved map (`replay::localize_log`): what the localiser said at every
/// frame and at the end, with what the map, the plots and the timeline draw of it.
#[derive(Debug, Clone, PartialEq)]
pub struct Localization {
    /// The saved map.
    pub map_path: PathBuf,
    /// Every frame as the localiser gave it, at the indices of [`Model::replay`]'s frames.
    pub frames: Vec<LocalizedFrame>,
    /// The map's landmarks with the times each was associated in this run, ids ascending.
    pub seen: Vec<(u64, u32)>,
    /// Map landmarks that should have been seen often and were not, ids ascending.
    pub missing: Vec<u64>,
    /// Lamps seen that are not in the map.
    pub new_lamps: Vec<NewLampMark>,
    /// Each time the position was (re)gained, microseconds.
    pub fixes_t_us: Vec<u64>,
    /// Frames localised, as the localiser counts them.
    pub localized_frames: u64,
    /// Times lost, by reason: after a gap, without odometry, when the lamps stopped fitting,
    /// too uncertain.
    pub lost_by_reason: [u64; 4],
    /// Errors against the log's truth, when it has one.
    pub truth: Option<LocalizeTruth>,
    /// The trajectory (frames with a pose) in stretches of one status.
    pub track: Vec<TrackRun>,
    /// Every frame in stretches of one status, for the timeline.
    pub status: Vec<StatusRun>,
    /// The series the plots draw.
    pub series: LocalizationSeries,
}

impl Localization {
    /// The frame at an index.
    pub fn frame(&self, index: usize) -> Option<&LocalizedFrame> {
        self.frames.get(index)
    }

    /// Whether map landmark `id` was reported missing.
    pub fn is_missing(&self, id: u64) -> bool {
        self.missing.binary_search(&id).is_ok()
    }
}

/// A frame's pose in the plane, when it has a finite one.
fn planar(f: &LocalizedFrame) -> Option<[f64; 2]> {
    f.pose
        .map(|p| [p[0], p[1]])
        .filter(|p| p.iter().all(|v| v.is_finite()))
}

/// The frames kept when a localisation run is thinned: those of [`thin_by_time`], and both
/// frames of every change of status or of having a pose.
fn localization_keep(frames: &[LocalizedFrame], t_s: &[f64], max: usize) -> Vec<usize> {
    let mut keep = thin_by_time(t_s, max);
    let kind = |f: &LocalizedFrame| (f.localized, planar(f).is_some());
    for (i, w) in frames.windows(2).enumerate() {
        if let [a, b] = w
            && kind(a) != kind(b)
        {
            keep.extend([i, i + 1]);
        }
    }
    keep.sort_unstable();
    keep.dedup();
    keep
}

/// The trajectory of `frames` at the kept indices, in stretches of one status (see
/// [`TrackRun`]).
fn track_runs(frames: &[LocalizedFrame], keep: &[usize]) -> Vec<TrackRun> {
    let mut runs: Vec<TrackRun> = Vec::new();
    // A kept frame without a pose since the last point: the next point starts afresh. Every
    // change of having a pose is kept, so no such frame is thinned away.
    let mut broken = true;
    for &i in keep {
        let Some(f) = frames.get(i) else { continue };
        let Some(xy) = planar(f) else {
            broken = true;
            continue;
        };
        let last = runs.last_mut();
        match last {
            Some(run) if !broken && run.localized == f.localized => run.points.push((i, xy)),
            Some(run) if !broken => {
                let mut points = run.points.last().copied().into_iter().collect::<Vec<_>>();
                points.push((i, xy));
                runs.push(TrackRun {
                    localized: f.localized,
                    points,
                });
            }
            _ => runs.push(TrackRun {
                localized: f.localized,
                points: vec![(i, xy)],
            }),
        }
        broken = false;
    }
    runs
}

/// Every frame in stretches of one status.
fn status_runs(frames: &[LocalizedFrame]) -> Vec<StatusRun> {
    let mut runs: Vec<StatusRun> = Vec::new();
    for (i, f) in frames.iter().enumerate() {
        match runs.last_mut() {
            Some(run) if run.localized == f.localized => run.frames.end = i + 1,
            _ => runs.push(StatusRun {
                frames: i..i + 1,
                localized: f.localized,
            }),
        }
    }
    runs
}

/// The display unit and scale of a parameter.
pub fn display_unit(param: Param) -> (&'static str, f64) {
    let (scale, unit) = param.display_unit();
    (unit, scale)
}

/// Indices of the samples kept when a series at times `t` (sorted) is thinned to about `max`
/// points: the first sample of each of `max - 1` equal time buckets, and the last sample. A
/// short series is kept whole. Sparse stretches (phase 1's solves) keep every sample.
pub fn thin_by_time(t: &[f64], max: usize) -> Vec<usize> {
    if t.len() <= max || max < 2 {
        return (0..t.len()).collect();
    }
    let (Some(&first), Some(&last)) = (t.first(), t.last()) else {
        return Vec::new();
    };
    let width = (last - first) / (max - 1) as f64;
    if width.is_nan() || width <= 0.0 {
        return vec![0, t.len() - 1];
    }
    let mut keep = Vec::with_capacity(max + 1);
    let mut bucket: Option<i64> = None;
    for (i, &ti) in t.iter().enumerate() {
        let b = ((ti - first) / width).floor() as i64;
        if bucket != Some(b) {
            keep.push(i);
            bucket = Some(b);
        }
    }
    if keep.last() != Some(&(t.len() - 1)) {
        keep.push(t.len() - 1);
    }
    keep
}

impl Model {
    /// Builds the model from a replay (or an estimates file read back) and what the log holds
    /// besides: the board's features, the truth, the nominal camera and the image size.
    pub fn from_replay(
        path: PathBuf,
        kind: SourceKind,
        replay: Replay,
        features: Features,
        truth: Option<Truth>,
        nominal: Option<(CameraParams, [f64; 2])>,
        truth_camera: Option<CameraParams>,
    ) -> Self {
        let t0_us = replay
            .frames
            .first()
            .map(|f| f.t_us)
            .or_else(|| replay.camera.first().map(|c| c.t_us))
            .unwrap_or(0);
        let seconds = |t_us: u64| (t_us as f64 - t0_us as f64) * 1e-6;
        let image_size = match nominal {
            Some((_, size)) => size,
            None => replay
                .camera
                .first()
                .map(|c| {
                    let get = |p: Param| c.params.iter().find(|e| e.param == p).map(|e| e.value);
                    [
                        (2.0 * get(Param::Cx).unwrap_or(376.0)).round(),
                        (2.0 * get(Param::Cy).unwrap_or(240.0)).round(),
                    ]
                })
                .unwrap_or([752.0, 480.0]),
        };

        let params = param_series(&replay, &seconds, truth_camera.as_ref());
        let nis = nis_series(&replay.frames, &seconds);

        let frame_t: Vec<f64> = replay.frames.iter().map(|f| seconds(f.t_us)).collect();
        let trajectory: Vec<(usize, [f64; 2])> = thin_by_time(&frame_t, PATH_POINTS)
            .into_iter()
            .filter_map(|i| {
                let f = replay.frames.get(i)?;
                f.pose[..2]
                    .iter()
                    .all(|v| v.is_finite())
                    .then_some((i, [f.pose[0], f.pose[1]]))
            })
            .collect();
        let truth_trajectory: Vec<(u64, [f64; 2])> = truth.as_ref().map_or_else(Vec::new, |t| {
            let tt: Vec<f64> = t.poses.iter().map(|(t_us, _)| seconds(*t_us)).collect();
            thin_by_time(&tt, PATH_POINTS)
                .into_iter()
                .filter_map(|i| t.poses.get(i).map(|(t_us, p)| (*t_us, [p[0], p[1]])))
                .collect()
        });

        let mut heights: Vec<f64> = replay
            .landmarks
            .iter()
            .map(|l| l.position[2])
            .chain(truth.iter().flat_map(|t| t.lamps.iter().map(|l| l[2])))
            .filter(|z| z.is_finite())
            .collect();
        heights.sort_by(f64::total_cmp);
        let mount_z = nominal
            .map(|(c, _)| c.mount.z)
            .or_else(|| {
                replay
                    .final_camera
                    .iter()
                    .find(|p| p.param == Param::MountZ)
                    .map(|p| p.value)
            })
            .unwrap_or(0.0);
        let lamp_height_m = heights
            .get(heights.len() / 2)
            .copied()
            .unwrap_or(mount_z + DEFAULT_LAMPS_ABOVE_RIG_M);

        let xy = trajectory
            .iter()
            .map(|(_, p)| *p)
            .chain(truth_trajectory.iter().map(|(_, p)| *p))
            .chain(
                replay
                    .landmarks
                    .iter()
                    .map(|l| [l.position[0], l.position[1]]),
            )
            .chain(
                truth
                    .iter()
                    .flat_map(|t| t.lamps.iter().map(|l| [l[0], l[1]])),
            )
            .filter(|p| p.iter().all(|v| v.is_finite()));
        let mut bounds = [
            f64::INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NEG_INFINITY,
        ];
        for [x, y] in xy {
            bounds = [
                bounds[0].min(x),
                bounds[1].min(y),
                bounds[2].max(x),
                bounds[3].max(y),
            ];
        }
        if !bounds.iter().all(|v| v.is_finite()) {
            bounds = [-1.0, -1.0, 1.0, 1.0];
        }

        let warnings = replay.warnings.clone();
        Self {
            path,
            kind,
            t0_us,
            image_size,
            nominal: nominal.map(|(c, _)| c),
            lens: None,
            features,
            images: None,
            truth,
            params,
            nis,
            trajectory,
            truth_trajectory,
            lamp_height_m,
            bounds,
            warnings,
            replay,
            localization: None,
        }
    }

    /// Builds the model of a localisation run: the log at `path` run on the saved map at
    /// `map_path` (`replay::localize_log`), `frames` as it gave them, with the board's
    /// features, the log's truth (taken to be in the map's frame, as the localiser's report
    /// takes it) and the rig it ran with (the nominal camera and the image size).
    ///
    /// The map is shown as the run's only map snapshot, the camera as the map's (with the
    /// vehicle parameters as the run refined them), the poses with the localiser's 1-sigma;
    /// frames without a pose have a NaN pose (left out of the trajectory). No parameter is
    /// plotted (the camera is the map's, fixed): the plots are the run's
    /// ([`LocalizationSeries`]).
    #[allow(clippy::too_many_arguments)] // each is a separate thing the run is shown with
    pub fn from_localization(
        path: PathBuf,
        map_path: PathBuf,
        frames: Vec<LocalizedFrame>,
        end: LocalizeEnd,
        features: Features,
        truth: Option<Truth>,
        nominal: (CameraParams, [f64; 2]),
    ) -> Self {
        let landmark_count = end.landmarks.len();
        let mut landmarks: Vec<LandmarkEstimate> = end
            .landmarks
            .iter()
            .map(|(l, _)| LandmarkEstimate {
                id: l.id,
                position: l.position,
                covariance: l.covariance,
                observations: l.observations,
            })
            .collect();
        // The map's queries find a landmark by binary search on its id.
        landmarks.sort_by_key(|l| l.id);
        let mut seen: Vec<(u64, u32)> = end.landmarks.iter().map(|(l, n)| (l.id, *n)).collect();
        seen.sort_unstable();
        let mut missing = end.lamps_missing.clone();
        missing.sort_unstable();
        let estimates: Vec<FrameEstimate> = frames
            .iter()
            .map(|f| {
                let [sx, sy, st] = f.sigma;
                let mut pose_covariance = [[0.0; 3]; 3];
                for (k, s) in [sx, sy, st].into_iter().enumerate() {
                    if let Some(row) = pose_covariance.get_mut(k)
                        && let Some(v) = row.get_mut(k)
                    {
                        *v = s * s;
                    }
                }
                FrameEstimate {
                    t_us: f.t_us,
                    phase: Phase::Navigating,
                    pose: f.pose.unwrap_or([f64::NAN; 3]),
                    pose_covariance,
                    observed: Vec::new(),
                    nis: Vec::new(),
                    rejected: 0,
                    landmarks: landmark_count,
                    // The localiser reports how many lamps it matched, not which.
                    associations: None,
                }
            })
            .collect();
        let t0_us = frames
            .first()
            .map(|f| f.t_us)
            .or(end.first_t_us)
            .unwrap_or(0);
        let replay = Replay {
            frames: estimates,
            camera: vec![CameraSample {
                t_us: t0_us,
                phase: Phase::Navigating,
                params: end.parameters.clone(),
            }],
            maps: vec![MapSnapshot {
                t_us: t0_us,
                landmarks: landmarks.clone(),
            }],
            landmarks,
            final_camera: end.parameters.clone(),
            phase_switch_t_us: None,
            phase1_skipped: false,
            counts: end.counts,
            truth: None,
            warnings: end.warnings.clone(),
            log_damage: None,
            odometry: None,
        };
        let new_lamps: Vec<NewLampMark> = end
            .new_lamps
            .iter()
            .map(|l| NewLampMark {
                position: [l.position.x, l.position.y, l.position.z],
                covariance: std::array::from_fn(|r| {
                    std::array::from_fn(|c| l.covariance.get((r, c)).copied().unwrap_or(f64::NAN))
                }),
                observations: l.observations,
            })
            .collect();
        let mut model = Self::from_replay(
            path,
            SourceKind::VehicleLog,
            replay,
            features,
            truth,
            Some(nominal),
            None,
        );
        model.params.clear();
        for l in &new_lamps {
            let [x, y, _] = l.position;
            if x.is_finite() && y.is_finite() {
                let b = &mut model.bounds;
                *b = [b[0].min(x), b[1].min(y), b[2].max(x), b[3].max(y)];
            }
        }

        let t_s: Vec<f64> = frames.iter().map(|f| model.seconds(f.t_us)).collect();
        let keep = localization_keep(&frames, &t_s, PLOT_POINTS.max(PATH_POINTS));
        let track = track_runs(&frames, &keep);
        let status = status_runs(&frames);
        let truth_pose = |t_us: u64| -> Option<[f64; 3]> {
            let poses = &model.truth.as_ref()?.poses;
            let i = poses.binary_search_by_key(&t_us, |(t, _)| *t).ok()?;
            poses.get(i).map(|(_, p)| *p)
        };
        let has_truth = model.truth.as_ref().is_some_and(|t| !t.poses.is_empty());
        let mut series = LocalizationSeries::default();
        for &i in &keep {
            let (Some(f), Some(&t)) = (frames.get(i), t_s.get(i)) else {
                continue;
            };
            let [sx, sy, st] = if planar(f).is_some() {
                f.sigma
            } else {
                [f64::NAN; 3]
            };
            series.t_s.push(t);
            series.frame.push(i);
            series.localized.push(f.localized);
            series.position_sigma_mm.push(sx.hypot(sy) * 1e3);
            series.heading_sigma_deg.push(st.to_degrees());
            series.matched.push(f64::from(f.matched));
            series.hypotheses.push(f64::from(f.hypotheses));
            if has_truth {
                let error = match (planar(f), truth_pose(f.t_us)) {
                    (Some([x, y]), Some([tx, ty, _])) => (x - tx).hypot(y - ty) * 1e3,
                    _ => f64::NAN,
                };
                series.error_mm.push(error);
            }
        }
        model.localization = Some(Localization {
            map_path,
            frames,
            seen,
            missing,
            new_lamps,
            fixes_t_us: end.localized_t_us.clone(),
            localized_frames: end.localized_frames,
            lost_by_reason: end.lost,
            truth: end.truth,
            track,
            status,
            series,
        });
        model
    }
}

/// The estimated parameters' series (those with a non-zero sigma at some time).
fn param_series(
    replay: &Replay,
    seconds: &dyn Fn(u64) -> f64,
    truth_camera: Option<&CameraParams>,
) -> Vec<ParamSeries> {
    let t: Vec<f64> = replay.camera.iter().map(|c| seconds(c.t_us)).collect();
    let keep = thin_by_time(&t, PLOT_POINTS);
    Param::ALL
        .iter()
        .filter_map(|&param| {
            let estimate_of =
                |c: &CameraSample| c.params.iter().find(|e| e.param == param).copied();
            let estimated = replay
                .camera
                .iter()
                .any(|c| estimate_of(c).is_some_and(|e| e.sigma > 0.0));
            if !estimated {
                return None;
            }
            let (unit, scale) = display_unit(param);
            let mut series = ParamSeries {
                param,
                unit,
                t_s: Vec::with_capacity(keep.len()),
                value: Vec::with_capacity(keep.len()),
                sigma: Vec::with_capacity(keep.len()),
                truth: truth_camera.map(|c| c.get(param) * scale),
            };
            for &i in &keep {
                let (Some(c), Some(&ti)) = (replay.camera.get(i), t.get(i)) else {
                    continue;
                };
                if let Some(e) = estimate_of(c) {
                    series.t_s.push(ti);
                    series.value.push(e.value * scale);
                    series.sigma.push(e.sigma * scale);
                }
            }
            Some(series)
        })
        .collect()
}

/// The NIS series (see [`NisSeries`]).
fn nis_series(frames: &[FrameEstimate], seconds: &dyn Fn(u64) -> f64) -> NisSeries {
    let window = vslam_ekf::Settings::default().nis_window;
    let p = vslam_ekf::health::DIVERGENCE_PROBABILITY;
    // The bound for w observations, computed once per w (it only depends on w).
    let mut bounds: Vec<f64> = Vec::new();
    let mut bound_of = |w: usize| -> f64 {
        while bounds.len() <= w {
            let n = bounds.len() as f64 * NIS_DOF;
            let b = if n > 0.0 {
                vslam_ekf::chi2::chi2_quantile(p, n) / n
            } else {
                f64::NAN
            };
            bounds.push(b);
        }
        bounds.get(w).copied().unwrap_or(f64::NAN)
    };
    let mut last: VecDeque<f64> = VecDeque::with_capacity(window + 1);
    let mut sum = 0.0;
    let mut t = Vec::new();
    let mut frame_mean = Vec::new();
    let mut window_mean = Vec::new();
    let mut window_bound = Vec::new();
    for f in frames.iter().filter(|f| !f.nis.is_empty()) {
        let ts = seconds(f.t_us);
        let n = f.nis.len() as f64;
        frame_mean.push([ts, f.nis.iter().map(|(_, v)| v).sum::<f64>() / n / NIS_DOF]);
        for &(_, v) in &f.nis {
            last.push_back(v);
            sum += v;
            if last.len() > window {
                sum -= last.pop_front().unwrap_or(0.0);
            }
        }
        let w = last.len();
        t.push(ts);
        window_mean.push([ts, sum / (w as f64 * NIS_DOF)]);
        window_bound.push([ts, bound_of(w)]);
    }
    // Thin: the window mean and its bound by time; the frame means keep each bucket's largest.
    let keep = thin_by_time(&t, PLOT_POINTS);
    let pick = |v: &[[f64; 2]]| -> Vec<[f64; 2]> {
        keep.iter().filter_map(|&i| v.get(i).copied()).collect()
    };
    let buckets = thin_by_time(&t, NIS_POINTS);
    let mut peaks: Vec<[f64; 2]> = Vec::with_capacity(buckets.len());
    for (k, &start) in buckets.iter().enumerate() {
        let end = buckets.get(k + 1).copied().unwrap_or(frame_mean.len());
        let peak = frame_mean
            .get(start..end.max(start + 1))
            .unwrap_or_default()
            .iter()
            .copied()
            .max_by(|a, b| a[1].total_cmp(&b[1]));
        peaks.extend(peak);
    }
    NisSeries {
        frame_mean: peaks,
        window_mean: pick(&window_mean),
        window_bound: pick(&window_bound),
        window,
    }
}

impl Model {
    /// Seconds from the log's start (the first frame) of a timestamp.
    pub fn seconds(&self, t_us: u64) -> f64 {
        (t_us as f64 - self.t0_us as f64) * 1e-6
    }

    /// The timestamp at `t_s` seconds from the log's start (clamped at 0).
    pub fn t_us_at(&self, t_s: f64) -> u64 {
        let t = (t_s * 1e6).round();
        if t.is_nan() || t <= 0.0 {
            self.t0_us
        } else {
            self.t0_us.saturating_add(t as u64)
        }
    }

    /// The log's length, seconds (the last frame or camera sample).
    pub fn duration_s(&self) -> f64 {
        let last = self
            .replay
            .frames
            .last()
            .map(|f| f.t_us)
            .max(self.replay.camera.last().map(|c| c.t_us))
            .unwrap_or(self.t0_us);
        self.seconds(last)
    }

    /// The index of the last frame at or before `t_s`; `None` before the first frame.
    pub fn frame_at(&self, t_s: f64) -> Option<usize> {
        let t_us = self.t_us_at(t_s);
        self.replay
            .frames
            .partition_point(|f| f.t_us <= t_us)
            .checked_sub(1)
    }

    /// The frame at an index.
    pub fn frame(&self, index: usize) -> Option<&FrameEstimate> {
        self.replay.frames.get(index)
    }

    /// The map at `t_us`: the last snapshot at or before it (empty before the first).
    pub fn map_at(&self, t_us: u64) -> &[LandmarkEstimate] {
        let i = self.replay.maps.partition_point(|m| m.t_us <= t_us);
        i.checked_sub(1)
            .and_then(|i| self.replay.maps.get(i))
            .map_or(&[], |m| m.landmarks.as_slice())
    }

    /// The camera at `t_us`: the last estimate at or before it; before the first, the rig's
    /// nominal camera (or else the first estimate).
    pub fn camera_at(&self, t_us: u64) -> Option<CameraParams> {
        let i = self.replay.camera.partition_point(|c| c.t_us <= t_us);
        let sample = i
            .checked_sub(1)
            .and_then(|i| self.replay.camera.get(i))
            .or_else(|| {
                self.nominal
                    .is_none()
                    .then(|| self.replay.camera.first())
                    .flatten()
            });
        match sample {
            Some(s) => {
                let mut c = self.nominal.unwrap_or(CameraParams {
                    vehicle: Default::default(),
                    f: 1.0,
                    cx: 0.0,
                    cy: 0.0,
                    baseline: 0.0,
                    mount: rig_model::camera::Mount::default(),
                });
                for e in &s.params {
                    c.set(e.param, e.value);
                }
                Some(c)
            }
            None => self.nominal,
        }
    }

    /// One parameter's estimate at `t_us`: the last camera sample at or before it.
    pub fn param_at(&self, t_us: u64, param: Param) -> Option<replay::ParamEstimate> {
        let i = self.replay.camera.partition_point(|c| c.t_us <= t_us);
        let sample = self.replay.camera.get(i.checked_sub(1)?)?;
        sample.params.iter().find(|e| e.param == param).copied()
    }

    /// The phase at `t_s` (that of the frame then; before the first, the first's).
    pub fn phase_at(&self, t_s: f64) -> Option<Phase> {
        self.frame_at(t_s)
            .and_then(|i| self.frame(i))
            .or_else(|| self.replay.frames.first())
            .map(|f| f.phase)
    }

    /// A landmark's position for drawing at `t_us`: from the map at that time, else from the
    /// final map (a landmark added since the last snapshot).
    fn landmark_position(&self, map: &[LandmarkEstimate], id: u64) -> Option<[f64; 3]> {
        let find = |m: &[LandmarkEstimate]| {
            m.binary_search_by_key(&id, |l| l.id)
                .ok()
                .and_then(|i| m.get(i))
                .map(|l| l.position)
        };
        find(map).or_else(|| find(&self.replay.landmarks))
    }

    /// The two images at frame `index`: the board's features marked by the navigator's
    /// associations at that frame ([`FrameEstimate::associations`]; in a localisation run, by
    /// nearness to a map lamp's projection, [`ASSOCIATION_RADIUS_PX`]) and the landmarks of the
    /// map projected at the frame's estimated pose and camera, taken through the rig's lenses
    /// when it has them ([`Model::lens`]), so that both are in the board's pixels. Work: the
    /// frame's features and associations, plus the landmarks in view.
    pub fn marks(&self, index: usize) -> FrameMarks {
        let Some(frame) = self.frame(index) else {
            return FrameMarks::default();
        };
        let (left, right) = self.features.at(frame.t_us).unwrap_or((&[], &[]));
        let unmarked = |p: &ImagePoint| FeatureMark {
            u: p[0],
            v: p[1],
            landmark: None,
            observed: false,
        };
        let mut marks = FrameMarks {
            left: left.iter().map(unmarked).collect(),
            right: right.iter().map(unmarked).collect(),
            ..FrameMarks::default()
        };
        let has_features = !marks.left.is_empty() || !marks.right.is_empty();
        if let Some(associations) = &frame.associations
            && has_features
        {
            let mut on = 0;
            for a in associations {
                let (Some(l), Some(r)) = (marks.left.get_mut(a.left), marks.right.get_mut(a.right))
                else {
                    continue;
                };
                for f in [l, r] {
                    f.landmark = Some(a.id);
                    f.observed = a.accepted;
                }
                on += usize::from(a.accepted);
            }
            marks.on_landmarks = Some(on);
        }
        let Some(camera) = self.camera_at(frame.t_us) else {
            return marks;
        };
        let pose = Pose2::new(frame.pose[0], frame.pose[1], frame.pose[2]);
        let map = self.map_at(frame.t_us);
        let [w, h] = self.image_size;
        let inside = |u: f64, v: f64| (0.0..w).contains(&u) && (0.0..h).contains(&v);
        // Landmarks the frame names that the last snapshot predates (drawn from the final map).
        let mut named: Vec<u64> = frame
            .observed
            .iter()
            .copied()
            .chain(frame.associations.iter().flatten().map(|a| a.id))
            .filter(|id| map.binary_search_by_key(id, |l| l.id).is_err())
            .collect();
        named.sort_unstable();
        named.dedup();
        let ids = map.iter().map(|l| l.id).chain(named);
        // The rectified model's pixels into the board's raw ones. The rings are markers of a
        // fixed size on the screen, not uncertainties, so only their centres go through the
        // lens (no covariance to carry through its Jacobian).
        let lens = self.lens.as_ref().zip(self.nominal.as_ref());
        let to_raw = |left: bool, u: f64, v: f64| -> Option<(f64, f64)> {
            let Some((lens, c)) = lens else {
                return Some((u, v));
            };
            let side = if left { &lens.left } else { &lens.right };
            let raw = side.unrectify(nalgebra::Vector2::new(u, v), c.f, c.cx, c.cy)?;
            (raw.x.is_finite() && raw.y.is_finite()).then_some((raw.x, raw.y))
        };
        for id in ids {
            let Some(p) = self.landmark_position(map, id) else {
                continue;
            };
            let Ok(z) = rig_model::project(&camera, &pose, &Vector3::from(p)) else {
                continue;
            };
            let observed = frame.observed.contains(&id);
            if let Some((u, v)) = to_raw(true, z[0], z[1])
                && inside(u, v)
            {
                marks.projected_left.push(Projection { id, u, v, observed });
            }
            if let Some((u, v)) = to_raw(false, z[2], z[3])
                && inside(u, v)
            {
                marks
                    .projected_right
                    .push(Projection { id, u, v, observed });
            }
        }
        if self.localization.is_some() {
            associate(&mut marks.left, &marks.projected_left);
            associate(&mut marks.right, &marks.projected_right);
        }
        marks
    }

    /// The footprints of the left and right images on the lamp plane at frame `index`
    /// ([`Model::lamp_height_m`]), world `(x, y)` corners in image order (0,0), (w,0), (w,h),
    /// (0,h); `None` where a corner's ray does not reach the plane.
    pub fn field_of_view(&self, index: usize) -> [Option<[[f64; 2]; 4]>; 2] {
        let Some((frame, camera)) = self
            .frame(index)
            .and_then(|f| Some((f, self.camera_at(f.t_us)?)))
        else {
            return [None, None];
        };
        let pose = Pose2::new(frame.pose[0], frame.pose[1], frame.pose[2]);
        let [w, h] = self.image_size;
        let robot_from_rig = camera.mount.robot_from_rig_rotation();
        let footprint = |x_centre: f64| -> Option<[[f64; 2]; 4]> {
            let origin = pose.point_in_world(
                &(robot_from_rig * Vector3::new(x_centre, 0.0, 0.0) + camera.mount.translation()),
            );
            let corner = |u: f64, v: f64| -> Option<[f64; 2]> {
                let d_in_rig =
                    Vector3::new((u - camera.cx) / camera.f, (v - camera.cy) / camera.f, 1.0);
                let d = pose.world_from_robot_rotation() * (robot_from_rig * d_in_rig);
                let s = (self.lamp_height_m - origin.z) / d.z;
                (s.is_finite() && s > 0.0).then(|| [origin.x + s * d.x, origin.y + s * d.y])
            };
            Some([
                corner(0.0, 0.0)?,
                corner(w, 0.0)?,
                corner(w, h)?,
                corner(0.0, h)?,
            ])
        };
        [
            footprint(-camera.baseline / 2.0),
            footprint(camera.baseline / 2.0),
        ]
    }
}

/// Marks each feature with the nearest projection within [`ASSOCIATION_RADIUS_PX`] (a
/// localisation run: its localiser does not say which features it matched), never as observed.
fn associate(features: &mut [FeatureMark], projections: &[Projection]) {
    let r2 = ASSOCIATION_RADIUS_PX * ASSOCIATION_RADIUS_PX;
    for f in features {
        let nearest = projections
            .iter()
            .map(|p| {
                let (du, dv) = (p.u - f64::from(f.u), p.v - f64::from(f.v));
                (du * du + dv * dv, p)
            })
            .filter(|(d2, _)| *d2 <= r2)
            .min_by(|a, b| a.0.total_cmp(&b.0));
        if let Some((_, p)) = nearest {
            f.landmark = Some(p.id);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use replay::{Counts, ParamEstimate};
    use rig_model::camera::Mount;

    fn camera(pitch: f64) -> CameraParams {
        CameraParams {
            vehicle: Default::default(),
            f: 700.0,
            cx: 376.0,
            cy: 240.0,
            baseline: 0.12,
            mount: Mount {
                z: 0.8,
                pitch,
                ..Mount::default()
            },
        }
    }

    /// A frame whose update accepted the observations of `observed` and rejected those of
    /// `rejected`; landmark `id`'s features are at index `id` of both images (see [`model`]).
    fn frame(t_us: u64, pose: [f64; 3], observed: Vec<u64>, rejected: Vec<u64>) -> FrameEstimate {
        let association = |id: u64, accepted: bool| replay::Association {
            id,
            left: id as usize,
            right: id as usize,
            accepted,
        };
        FrameEstimate {
            t_us,
            phase: Phase::Navigating,
            pose,
            pose_covariance: [[1e-6, 0.0, 0.0], [0.0, 1e-6, 0.0], [0.0, 0.0, 1e-6]],
            nis: observed.iter().map(|id| (*id, 4.0)).collect(),
            associations: Some(
                observed
                    .iter()
                    .map(|id| association(*id, true))
                    .chain(rejected.iter().map(|id| association(*id, false)))
                    .collect(),
            ),
            rejected: rejected.len() as u32,
            observed,
            landmarks: 2,
        }
    }

    fn landmark(id: u64, position: [f64; 3]) -> LandmarkEstimate {
        LandmarkEstimate {
            id,
            position,
            covariance: [[1e-6, 0.0, 0.0], [0.0, 1e-6, 0.0], [0.0, 0.0, 1e-6]],
            observations: 10,
        }
    }

    fn params(c: &CameraParams, sigma: f64) -> Vec<ParamEstimate> {
        Param::ALL
            .iter()
            .map(|&param| ParamEstimate {
                param,
                value: c.get(param),
                sigma: if param == Param::Baseline { sigma } else { 0.0 },
            })
            .collect()
    }

    /// Two frames 1 s apart, two landmarks 2 m above the robot (one added after the first
    /// snapshot), features at the landmarks' projections and one of clutter (index 0); at the
    /// second frame the gate rejected landmark 1's observation.
    fn model(pitch: f64) -> Model {
        let c = camera(pitch);
        let lamps = [landmark(1, [0.2, 0.1, 2.8]), landmark(2, [-0.1, -0.2, 2.8])];
        let frames = vec![
            frame(1_000_000, [0.0, 0.0, 0.0], vec![1], vec![]),
            frame(2_000_000, [0.1, 0.0, 0.1], vec![2], vec![1]),
        ];
        let replay = Replay {
            camera: frames
                .iter()
                .map(|f| CameraSample {
                    t_us: f.t_us,
                    phase: Phase::Navigating,
                    params: params(&c, 1e-4),
                })
                .collect(),
            maps: vec![MapSnapshot {
                t_us: 1_000_000,
                landmarks: vec![lamps[0]],
            }],
            landmarks: lamps.to_vec(),
            final_camera: params(&c, 1e-4),
            phase_switch_t_us: None,
            phase1_skipped: true,
            counts: Counts::default(),
            truth: None,
            warnings: Vec::new(),
            log_damage: None,
            odometry: None,
            frames,
        };
        let mut features = Features::default();
        for f in &replay.frames {
            let pose = Pose2::new(f.pose[0], f.pose[1], f.pose[2]);
            let mut left = vec![[10.0, 10.0]];
            let mut right = vec![[700.0, 400.0]];
            for l in &lamps {
                let z = rig_model::project(&c, &pose, &Vector3::from(l.position)).unwrap();
                left.push([z[0] as f32 + 0.5, z[1] as f32]);
                right.push([z[2] as f32, z[3] as f32 - 0.5]);
            }
            features.push(f.t_us, &left, &right);
        }
        Model::from_replay(
            PathBuf::from("test.mcap"),
            SourceKind::VehicleLog,
            replay,
            features,
            None,
            Some((c, [752.0, 480.0])),
            None,
        )
    }

    fn localized(t_us: u64, pose: Option<[f64; 3]>, localized: bool) -> LocalizedFrame {
        LocalizedFrame {
            t_us,
            pose,
            sigma: if pose.is_some() {
                [1e-3, 2e-3, 1e-4]
            } else {
                [f64::NAN; 3]
            },
            localized,
            matched: u32::from(localized) * 3,
            hypotheses: u32::from(!localized) * 2,
            truth: None,
            waiting: None,
            weighed: [None; replay::WEIGHED_SHOWN],
            generation: None,
        }
    }

    /// 10,000 frames: lost with a pose (0-99), lost without one (100-101), lost with a pose
    /// again (102-4999), localised (5000-9998), lost again at the last frame.
    fn run() -> Vec<LocalizedFrame> {
        (0..10_000_u64)
            .map(|i| {
                let pose = (!(100..102).contains(&i)).then_some([i as f64 * 1e-3, 0.0, 0.0]);
                localized(i * 50_000, pose, (5000..9999).contains(&i))
            })
            .collect()
    }

    #[test]
    fn a_localisation_run_thinned_keeps_every_change_of_status_and_pose() {
        let frames = run();
        let t: Vec<f64> = frames.iter().map(|f| f.t_us as f64 * 1e-6).collect();
        let keep = localization_keep(&frames, &t, 100);
        assert!(keep.len() < 120, "{}", keep.len());
        for i in [99, 100, 101, 102, 4999, 5000, 9998, 9999] {
            assert!(keep.contains(&i), "{i}");
        }
        assert!(keep.windows(2).all(|w| w[0] < w[1]));

        let track = track_runs(&frames, &keep);
        let shape: Vec<(bool, usize, usize)> = track
            .iter()
            .map(|r| {
                let first = r.points.first().map_or(0, |p| p.0);
                let last = r.points.last().map_or(0, |p| p.0);
                (r.localized, first, last)
            })
            .collect();
        // Broken where there is no pose; unbroken (the next starts at the last point) where
        // only the status changes.
        assert_eq!(
            shape,
            [
                (false, 0, 99),
                (false, 102, 4999),
                (true, 4999, 9998),
                (false, 9998, 9999)
            ]
        );

        let status: Vec<(Range<usize>, bool)> = status_runs(&frames)
            .into_iter()
            .map(|r| (r.frames, r.localized))
            .collect();
        assert_eq!(
            status,
            [(0..5000, false), (5000..9999, true), (9999..10_000, false)]
        );
    }

    #[test]
    fn a_localisation_model_holds_the_run_and_its_series() {
        let c = camera(0.0);
        let frames = run();
        let lamp = |id: u64, x: f64| {
            (
                map_file::MapLandmark {
                    id,
                    position: [x, 0.5, 3.0],
                    covariance: [[1e-6, 0.0, 0.0], [0.0, 1e-6, 0.0], [0.0, 0.0, 1e-6]],
                    observations: 10,
                },
                5,
            )
        };
        let end = LocalizeEnd {
            counts: Counts::default(),
            frames_processed: frames.len() as u64,
            localized_frames: 4999,
            localized_t_us: vec![5000 * 50_000],
            lamps_missing: vec![7],
            new_lamps: Vec::new(),
            last_frame: frames.last().copied(),
            first_t_us: Some(0),
            parameters: params(&c, 1e-4),
            landmarks: vec![lamp(7, 1.0), lamp(3, 2.0)],
            lost: [0, 0, 1, 0],
            hypotheses: 4,
            warnings: Vec::new(),
            truth: None,
        };
        let m = Model::from_localization(
            PathBuf::from("log.mcap"),
            PathBuf::from("log.map"),
            frames.clone(),
            end,
            Features::default(),
            None,
            (c, [752.0, 480.0]),
        );
        let loc = m.localization.as_ref().unwrap();
        // (Compared by time and flag: a frame without a pose has a NaN sigma.)
        assert!(
            loc.frames.len() == frames.len()
                && loc.frames.iter().zip(&frames).all(|(a, b)| a.t_us == b.t_us
                    && a.localized == b.localized
                    && a.pose == b.pose)
        );
        assert_eq!(m.replay.frames.len(), frames.len());
        // No pose: NaN, left out of the trajectory; a pose: its sigma squared on the diagonal.
        assert!(m.replay.frames[100].pose.iter().all(|v| v.is_nan()));
        assert!((m.replay.frames[0].pose_covariance[1][1] - 4e-6).abs() < 1e-18);
        assert!(loc.is_missing(7) && !loc.is_missing(3));
        assert_eq!(loc.seen, [(3, 5), (7, 5)]);
        // The map, sorted by id, is the only snapshot.
        let ids: Vec<u64> = m.map_at(m.t0_us).iter().map(|l| l.id).collect();
        assert_eq!(ids, [3, 7]);
        assert!(m.params.is_empty());
        assert_eq!(m.camera_at(m.t0_us).map(|c| c.f), Some(700.0));
        let s = &loc.series;
        assert_eq!(s.t_s.len(), s.frame.len());
        assert!(s.error_mm.is_empty(), "no truth");
        let k = s.frame.binary_search(&100).unwrap();
        assert!(s.position_sigma_mm[k].is_nan());
        let k = s.frame.binary_search(&5000).unwrap();
        assert!((s.position_sigma_mm[k] - 5f64.sqrt()).abs() < 1e-9);
        assert_eq!(
            (s.matched[k], s.hypotheses[k], s.localized[k]),
            (3.0, 0.0, true)
        );
    }

    #[test]
    fn thinning_keeps_short_series_and_bounds_long_ones() {
        let short: Vec<f64> = (0..10).map(f64::from).collect();
        assert_eq!(thin_by_time(&short, 100), (0..10).collect::<Vec<_>>());
        let long: Vec<f64> = (0..100_000).map(|i| f64::from(i) * 0.05).collect();
        let kept = thin_by_time(&long, 1000);
        assert!(kept.len() <= 1001 && kept.len() >= 990, "{}", kept.len());
        assert_eq!(kept.first(), Some(&0));
        assert_eq!(kept.last(), Some(&99_999));
        assert!(kept.windows(2).all(|w| w[0] < w[1]));
        // A sparse stretch (phase 1's solves) keeps every sample.
        let mut mixed: Vec<f64> = vec![0.0, 20.0, 40.0];
        mixed.extend((0..100_000).map(|i| 50.0 + f64::from(i) * 1e-3));
        let kept = thin_by_time(&mixed, 500);
        assert_eq!(&kept[..3], &[0, 1, 2]);
    }

    #[test]
    fn queries_at_a_time_are_the_last_at_or_before_it() {
        let m = model(0.0);
        assert_eq!(m.t0_us, 1_000_000);
        assert!((m.duration_s() - 1.0).abs() < 1e-12);
        assert_eq!(m.frame_at(-1.0), Some(0));
        assert_eq!(m.frame_at(0.0), Some(0));
        assert_eq!(m.frame_at(0.999), Some(0));
        assert_eq!(m.frame_at(1.0), Some(1));
        assert_eq!(m.frame_at(5.0), Some(1));
        assert_eq!(m.map_at(999_999).len(), 0);
        assert_eq!(m.map_at(1_500_000).len(), 1);
        assert_eq!(m.params.len(), 1, "only the baseline is estimated");
        let baseline = &m.params[0];
        assert_eq!((baseline.param, baseline.unit), (Param::Baseline, "mm"));
        assert!((baseline.value[0] - 120.0).abs() < 1e-9);
        assert!((baseline.sigma[0] - 0.1).abs() < 1e-12);
        assert_eq!(m.nis.frame_mean, vec![[0.0, 1.0], [1.0, 1.0]]);
        assert_eq!(m.nis.window_mean.len(), 2);
        // chi2_0.999(4) / 4 = 18.47 / 4.
        assert!((m.nis.window_bound[0][1] - 18.4668 / 4.0).abs() < 1e-3);
    }

    #[test]
    fn features_are_marked_by_the_navigators_associations() {
        let m = model(0.0);
        let first = m.marks(0);
        assert_eq!(first.left.len(), 3);
        // Frame 0: only landmark 1 is in the map (snapshot at 1 s); it was updated.
        assert_eq!(first.projected_left.len(), 1);
        assert_eq!(first.left[0].landmark, None, "clutter");
        assert_eq!(
            (first.left[1].landmark, first.left[1].observed),
            (Some(1), true)
        );
        assert_eq!(first.left[2].landmark, None, "landmark 2 is not mapped yet");
        assert_eq!(first.on_landmarks, Some(1));
        // Frame 1: landmark 2 was updated although the snapshot predates it: its position
        // comes from the final map. Landmark 1's observation was rejected by the gate.
        let second = m.marks(1);
        assert_eq!(second.projected_right.len(), 2);
        assert_eq!(
            (second.right[1].landmark, second.right[1].observed),
            (Some(1), false)
        );
        assert_eq!(
            (second.right[2].landmark, second.right[2].observed),
            (Some(2), true)
        );
        assert_eq!(second.right[0].landmark, None);
        assert_eq!(second.on_landmarks, Some(1), "the rejected one is not on");
        assert_eq!(m.marks(7), FrameMarks::default());
    }

    /// Nearness is not association: a feature on a landmark's ring that the navigator did not
    /// give the update is not marked, and a frame whose source did not record the
    /// associations has no count (not a 0).
    #[test]
    fn nearness_alone_marks_nothing_and_unrecorded_associations_have_no_count() {
        let mut m = model(0.0);
        m.replay.frames[0].associations = Some(Vec::new());
        let marks = m.marks(0);
        assert_eq!(marks.projected_left.len(), 1);
        assert!(marks.left.iter().all(|f| f.landmark.is_none()));
        assert_eq!(marks.on_landmarks, Some(0));
        m.replay.frames[0].associations = None;
        assert_eq!(m.marks(0).on_landmarks, None);
        m.features = Features::default();
        m.replay.frames[1].associations = Some(Vec::new());
        assert_eq!(
            m.marks(1).on_landmarks,
            None,
            "no features: nothing to count"
        );
    }

    /// With lens tables the rings are the rectified projections taken back through each
    /// camera's lens, with the nominal camera's `f, cx, cy`.
    #[test]
    fn rings_go_through_the_lens_into_the_raw_image() {
        use rig_model::lens::{Lens, LensModel};
        let lens = |fx: f64, k1: f64| Lens {
            model: LensModel::PlumbBob {
                k1,
                k2: 0.07,
                p1: 0.0,
                p2: 0.0,
                k3: 0.0,
            },
            fx,
            fy: fx,
            cx: 370.0,
            cy: 245.0,
            rectification: nalgebra::Matrix3::identity(),
        };
        let stereo = StereoLens {
            left: lens(720.0, -0.28),
            right: lens(715.0, -0.2),
        };
        let plain = model(0.0);
        let mut through = model(0.0);
        through.lens = Some(stereo);
        let c = camera(0.0);
        for i in 0..2 {
            let (a, b) = (plain.marks(i), through.marks(i));
            assert_eq!(a.projected_left.len(), b.projected_left.len());
            for (side, pa, pb) in [
                (&stereo.left, &a.projected_left, &b.projected_left),
                (&stereo.right, &a.projected_right, &b.projected_right),
            ] {
                for (p, q) in pa.iter().zip(pb) {
                    let raw = side
                        .unrectify(nalgebra::Vector2::new(p.u, p.v), c.f, c.cx, c.cy)
                        .unwrap();
                    assert_eq!(p.id, q.id);
                    assert!((raw.x - q.u).abs() < 1e-9 && (raw.y - q.v).abs() < 1e-9);
                    assert!(
                        (p.u - q.u).abs() + (p.v - q.v).abs() > 1.0,
                        "the lens moved it"
                    );
                }
            }
            // The features are marked by the associations, wherever the rings are.
            assert_eq!(a.left, b.left);
            assert_eq!(a.on_landmarks, b.on_landmarks);
        }
    }

    #[test]
    fn the_field_of_view_is_above_the_rig_and_moves_forward_with_pitch() {
        let up = model(0.0);
        assert!((up.lamp_height_m - 2.8).abs() < 1e-12);
        let [Some(left), Some(right)] = up.field_of_view(0) else {
            panic!("both footprints reach the lamp plane");
        };
        let centre = |q: &[[f64; 2]; 4]| {
            [
                q.iter().map(|p| p[0]).sum::<f64>() / 4.0,
                q.iter().map(|p| p[1]).sum::<f64>() / 4.0,
            ]
        };
        // 2 m above the rig: 752 px at f = 700 is 2.15 m across; the principal point is the
        // image centre, so each footprint is centred on its camera.
        let width = left[1][0] - left[0][0];
        assert!((width - 752.0 / 700.0 * 2.0).abs() < 1e-9, "{width}");
        assert!((centre(&left)[0] + 0.06).abs() < 1e-9);
        assert!((centre(&right)[0] - 0.06).abs() < 1e-9);
        // Image u along rig x = robot x, v along rig y = robot y (left).
        assert!(left[0][0] < left[1][0] && left[0][1] < left[3][1]);
        // Tilted toward the front, the view moves forward.
        let tilted = model(0.3);
        let [Some(left), _] = tilted.field_of_view(0) else {
            panic!("footprint");
        };
        // The principal ray meets the plane 2 tan(0.3) = 0.62 m ahead; the far edge is wider.
        let c = centre(&left);
        assert!(c[0] > 0.62 && c[0] < 1.0 && c[1].abs() < 1e-9, "{c:?}");
    }
}
