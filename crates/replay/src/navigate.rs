//! The whole stack on a log: the navigator (crate `nav`) fed with the log's board frames and
//! odometry in data-time order, the estimates collected into a [`Replay`], and the errors
//! against the simulator's truth when the log carries it.

use std::collections::{BTreeMap, VecDeque};
use std::f64::consts::PI;
use std::path::{Path, PathBuf};

use nav::{NavSettings, Navigator};
use rig_model::camera::{CameraParams, Param, Pose2};
use rig_model::config::Rig;
use vehicle_log::{Ros2Topics, TruthCamera, TruthPose};

use crate::stream::{Input, LogStream, TruthStream};
use crate::{
    Association, CameraSample, DecodedFrame, Error, FrameEstimate, LandmarkEstimate, MapSnapshot,
    ParamEstimate, Phase, Replay, ReplayEnd, RigSource, TruthErrors,
};

/// Data time between two map snapshots in the replay, microseconds.
pub const MAP_SNAPSHOT_US: u64 = 1_000_000;

/// A lamp counts as seen when it is inside both images at this many frames (one
/// second at 20 Hz). A landmark needs the tracker's confirmation (3 frames) and its own (3
/// consistent triangulations) first; lamps that only cross an image corner at speed are in
/// view for fewer frames than that, some of them at the border where the stereo match fails
/// (measured on the warehouse: 2 of 174 lamps in view for 10-12 frames were not mapped).
pub const LAMP_SEEN_FRAMES: usize = 20;

/// A landmark is matched to the nearest lamp within this distance, metres.
pub const LAMP_MATCH_RADIUS_M: f64 = 0.10;

fn phase_of(p: nav::Phase) -> Phase {
    match p {
        nav::Phase::Calibrating => Phase::Calibrating,
        nav::Phase::Navigating => Phase::Navigating,
    }
}

fn matrix3(m: &nalgebra::Matrix3<f64>) -> [[f64; 3]; 3] {
    core::array::from_fn(|r| core::array::from_fn(|c| m[(r, c)]))
}

fn map_of(navigator: &Navigator) -> Vec<LandmarkEstimate> {
    let Some(ekf) = navigator.ekf() else {
        return Vec::new();
    };
    let mut out: Vec<LandmarkEstimate> = ekf
        .landmarks()
        .map(|l| LandmarkEstimate {
            id: l.id.0,
            position: [l.position.x, l.position.y, l.position.z],
            covariance: matrix3(&l.covariance),
            observations: l.observations,
        })
        .collect();
    out.sort_by_key(|l| l.id);
    out
}

/// The error the filter's landmarks share: the weighted least-squares rigid motion `d = (tx,
/// ty, tz, yaw)` about their centroid `o` that their errors `e_i` imply,
/// `d = N^-1 sum A_i^T W_i e_i` with `A_i = [[1, 0, 0, -(y_i - o_y)], [0, 1, 0, x_i - o_x],
/// [0, 0, 1, 0]]`, `W_i` the inverse of landmark `i`'s marginal covariance and
/// `N = sum A_i^T W_i A_i`, has the covariance `N^-1 (sum_ij A_i^T W_i P_ij W_j A_j) N^-1`
/// from the joint covariance `P` of the landmarks. The weights keep a landmark the filter
/// barely knows (one seen twice, known to kilometres along its ray) from swamping it.
/// `None` with fewer than two usable landmarks (a yaw needs two).
fn common_error(ekf: &vslam_ekf::Ekf) -> Option<([f64; 2], [[f64; 4]; 4])> {
    use nalgebra::{Matrix3, Matrix4};
    let lamps: Vec<(usize, nalgebra::Vector3<f64>, Matrix3<f64>)> = ekf
        .landmarks()
        .filter_map(|l| {
            let w = l.covariance.try_inverse()?;
            let i = ekf.landmark_state_index(l.id)?;
            w.iter()
                .all(|v| v.is_finite())
                .then_some((i, l.position, w))
        })
        .collect();
    if lamps.len() < 2 {
        return None;
    }
    let total: Matrix3<f64> = lamps.iter().map(|(_, _, w)| w).sum();
    let centre = total.try_inverse()?
        * lamps
            .iter()
            .map(|(_, p, w)| w * p)
            .sum::<nalgebra::Vector3<f64>>();
    let (ox, oy) = (centre.x, centre.y);
    // A(p) of the map file's common error, as the localiser reads it.
    let motion = localize::CommonError {
        origin: (ox, oy),
        covariance: Matrix4::zeros(),
    };
    let a = |p: &nalgebra::Vector3<f64>| motion.jacobian(p);
    let normal: Matrix4<f64> = lamps
        .iter()
        .map(|(_, p, w)| a(p).transpose() * w * a(p))
        .sum();
    let n_inv = normal.try_inverse()?;
    let p = ekf.covariance();
    let weighted: Vec<nalgebra::Matrix4x3<f64>> =
        lamps.iter().map(|(_, q, w)| a(q).transpose() * w).collect();
    let mut middle = Matrix4::zeros();
    for ((i, _, _), ai) in lamps.iter().zip(&weighted) {
        for ((j, _, _), aj) in lamps.iter().zip(&weighted) {
            let block = p.fixed_view::<3, 3>(*i, *j).into_owned();
            middle += ai * block * aj.transpose();
        }
    }
    let c = n_inv * middle * n_inv;
    let c = 0.5 * (c + c.transpose());
    c.iter().all(|v| v.is_finite()).then(|| {
        (
            [ox, oy],
            std::array::from_fn(|r| std::array::from_fn(|k| c[(r, k)])),
        )
    })
}

/// Where a streaming replay's series go as they are final: the estimate of each frame, the
/// camera samples and the map snapshots, in data-time order (a frame, then the camera
/// sample and the map taken after it). [`ReplayCollector`] keeps them (a [`Replay`]);
/// [`crate::OutputFiles`] writes `EST.mcap` and `TRAJ.csv` as they come.
pub trait ReplaySink {
    /// A frame's final estimate.
    fn frame(&mut self, frame: &FrameEstimate) -> Result<(), Error>;
    /// The camera parameters after a frame (a phase-1 solve or a phase-2 frame).
    fn camera(&mut self, sample: &CameraSample) -> Result<(), Error>;
    /// The map at a frame, about once a second of data time, and at the end.
    fn map(&mut self, map: &MapSnapshot) -> Result<(), Error>;
    /// The log's true pose `(x, y, theta)` at a frame's time, after that frame, when the log
    /// has one (simulator logs): the pose the errors against the truth compare the frame to.
    /// Ignored unless a sink wants it.
    fn truth(&mut self, t_us: u64, pose: [f64; 3]) -> Result<(), Error> {
        let _ = (t_us, pose);
        Ok(())
    }
}

/// A [`ReplaySink`] that keeps everything: the series of a [`Replay`].
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ReplayCollector {
    /// The frames, in order.
    pub frames: Vec<FrameEstimate>,
    /// The camera samples.
    pub camera: Vec<CameraSample>,
    /// The map snapshots.
    pub maps: Vec<MapSnapshot>,
}

impl ReplaySink for ReplayCollector {
    fn frame(&mut self, frame: &FrameEstimate) -> Result<(), Error> {
        self.frames.push(frame.clone());
        Ok(())
    }
    fn camera(&mut self, sample: &CameraSample) -> Result<(), Error> {
        self.camera.push(sample.clone());
        Ok(())
    }
    fn map(&mut self, map: &MapSnapshot) -> Result<(), Error> {
        self.maps.push(map.clone());
        Ok(())
    }
}

/// Runs the navigator over the vehicle log at `path` and keeps every estimate (a
/// [`Replayer`] into a [`ReplayCollector`]; its memory grows with the log, the replayer's
/// own does not). `progress` is called with `(bytes read, bytes in the file)` as the reading
/// goes.
///
/// Errors: the file cannot be read, is not MCAP, has no vehicle topics, there is no rig, or the
/// settings are out of range. A log cut short is replayed as far as it goes, with a warning;
/// an update the filter refuses leaves the state as it was and is counted in a warning.
pub fn replay_log(
    path: impl AsRef<Path>,
    rig: Option<Rig>,
    settings: &NavSettings,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<Replay, Error> {
    replay_log_with_topics(path, None, rig, settings, progress)
}

/// [`replay_log`] of a ROS 2 bag whose named topics are the input (`None`: the board's
/// stream; see [`Replayer::open_with_topics`]).
pub fn replay_log_with_topics(
    path: impl AsRef<Path>,
    topics: Option<&Ros2Topics>,
    rig: Option<Rig>,
    settings: &NavSettings,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<Replay, Error> {
    let replayer = Replayer::open_with_topics(path.as_ref(), topics, rig, settings)?;
    let mut collected = ReplayCollector::default();
    let end = replayer.run(&mut collected, progress)?;
    Ok(Replay::from_parts(
        end,
        collected.frames,
        collected.camera,
        collected.maps,
    ))
}

/// A frame's estimate with the camera sample and map taken after it, held until the frame's
/// pose is final.
#[derive(Debug, Clone)]
struct Bundle {
    frame: FrameEstimate,
    camera: Option<CameraSample>,
    map: Option<MapSnapshot>,
}

/// The replay of one log as a stream (vehicle-interfaces.md section 5): log -> decoder ->
/// data-time order (a window of seconds) -> navigator -> a [`ReplaySink`], in memory bounded
/// by the map, not by the log's length.
///
/// A frame's estimate goes to the sink once its pose is final: the frames of phase 1 take the
/// batch's smoothed poses at the hand-over, and those phase 2's fixed-lag smoother holds take
/// its poses as it marginalises them, so frames wait that long (at most phase 1's buffer, then
/// the smoother's window). The summary's quantities (counts, the errors against the truth,
/// the filter's consistency) are accumulated frame by frame.
///
/// [`Replayer::open`] reads the start of the log (so that a foreign file, or one without a
/// rig, is refused before any output is made); [`Replayer::run`] does the rest.
pub struct Replayer {
    path: PathBuf,
    stream: LogStream,
    navigator: Navigator,
    rig: Rig,
    given_rig: bool,
    settings: NavSettings,
    warnings: Vec<String>,
    refused: Refusals,
    pending: VecDeque<Bundle>,
    next_snapshot: Option<u64>,
    nees_sum: f64,
    nees_frames: usize,
    nees_last: f64,
    truth: TruthAccumulator,
    frames_processed: u64,
    phase2_frames: u64,
    first_t_us: Option<u64>,
    phase1_poses_applied: bool,
}

impl std::fmt::Debug for Replayer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Replayer")
            .field("path", &self.path)
            .field("frames_processed", &self.frames_processed)
            .field("pending", &self.pending.len())
            .finish_non_exhaustive()
    }
}

impl Replayer {
    /// Opens the log at `path` and reads its start: the rig (`rig`, or else the log's
    /// `/rig`), and far enough to know it is a vehicle log.
    ///
    /// Errors: the file cannot be read, is not MCAP, has no vehicle topics, there is no rig, or
    /// the settings are out of range.
    pub fn open(path: &Path, rig: Option<Rig>, settings: &NavSettings) -> Result<Self, Error> {
        Self::open_with_topics(path, None, rig, settings)
    }

    /// [`Replayer::open`] for a ROS 2 bag whose named camera and odometry topics are the
    /// input (vehicle-interfaces.md 4.1; `None`: the board's stream). Further errors: a named
    /// topic the bag does not have, or of another type, or a rig whose `[board]` registers
    /// cannot run the detector.
    pub fn open_with_topics(
        path: &Path,
        topics: Option<&Ros2Topics>,
        rig: Option<Rig>,
        settings: &NavSettings,
    ) -> Result<Self, Error> {
        let mut stream = LogStream::open(path, topics)?;
        stream.preamble(rig.is_none())?;
        let given_rig = rig.is_some();
        let rig = match rig {
            Some(rig) => rig,
            None => {
                let text = stream.rig_text.as_deref().unwrap_or_default();
                Rig::from_json_str(text, &format!("{} /rig", path.display()))?
            }
        };
        stream.start_host_board(rig.board_registers())?;
        let navigator = Navigator::new(rig.clone(), *settings)?;
        Ok(Self {
            path: path.to_path_buf(),
            stream,
            navigator,
            rig,
            given_rig,
            settings: *settings,
            warnings: Vec::new(),
            refused: BTreeMap::new(),
            pending: VecDeque::new(),
            next_snapshot: None,
            nees_sum: 0.0,
            nees_frames: 0,
            nees_last: f64::NAN,
            truth: TruthAccumulator::default(),
            frames_processed: 0,
            phase2_frames: 0,
            first_t_us: None,
            phase1_poses_applied: false,
        })
    }

    /// The rig used.
    pub fn rig(&self) -> &Rig {
        &self.rig
    }

    /// Where the rig came from.
    pub fn rig_source(&self) -> RigSource {
        if self.given_rig {
            RigSource::Given
        } else {
            RigSource::Log
        }
    }

    /// Replays the rest of the log into `sink`; `progress` is called with `(bytes read,
    /// bytes in the file)` after each frame.
    ///
    /// Errors: a malformed message on a vehicle topic (what came before it has gone to the
    /// sink), or the sink's.
    pub fn run(
        mut self,
        sink: &mut dyn ReplaySink,
        progress: &mut dyn FnMut(u64, u64),
    ) -> Result<ReplayEnd, Error> {
        while let Some(input) = self.stream.next_input()? {
            match input {
                Input::Odometry(s) => {
                    if let Err(e) = self.navigator.push_odometry(s) {
                        refuse(&mut self.refused, &e);
                    }
                }
                Input::Frame(frame) => {
                    self.frame(&frame);
                    self.release(sink, false)?;
                    let (done, total) = self.stream.progress();
                    progress(done, total);
                }
            }
        }
        self.finish(sink)
    }

    /// One frame through the navigator; its estimate joins the pending frames.
    fn frame(&mut self, frame: &DecodedFrame) {
        let outcome = match self
            .navigator
            .push_frame(frame.t_us, &frame.left, &frame.right)
        {
            Ok(o) => o,
            Err(e) => {
                refuse(&mut self.refused, &e);
                nav::FrameOutcome::default()
            }
        };
        self.frames_processed += 1;
        self.first_t_us.get_or_insert(frame.t_us);
        let phase = phase_of(self.navigator.phase());
        let (pose, pose_cov) = self.navigator.pose();
        if phase == Phase::Navigating {
            self.phase2_frames += 1;
            if let Some(t) = self.stream.truth.pose_at(frame.t_us)
                && let Some(v) = pose_nees(&pose, &pose_cov, t)
            {
                self.nees_sum += v;
                self.nees_frames += 1;
                self.nees_last = v;
            }
        }
        let landmarks = self
            .navigator
            .ekf()
            .map_or(0, vslam_ekf::Ekf::landmark_count);
        let estimate = FrameEstimate {
            t_us: frame.t_us,
            phase,
            pose: [pose.x, pose.y, pose.theta],
            pose_covariance: matrix3(&pose_cov),
            observed: outcome.accepted.iter().map(|(id, _)| id.0).collect(),
            nis: outcome.accepted.iter().map(|(id, v)| (id.0, *v)).collect(),
            rejected: u32::try_from(outcome.rejected.len()).unwrap_or(u32::MAX),
            landmarks,
            associations: Some(
                outcome
                    .associations
                    .iter()
                    .map(|a| Association {
                        id: a.landmark.0,
                        left: a.left,
                        right: a.right,
                        accepted: a.accepted,
                    })
                    .collect(),
            ),
        };
        let camera = (phase == Phase::Navigating || outcome.solved).then(|| {
            let (c, cov) = self.navigator.camera();
            CameraSample {
                t_us: frame.t_us,
                phase,
                params: ParamEstimate::all(&c, &cov),
            }
        });
        let mut map = None;
        if phase == Phase::Navigating && self.next_snapshot.is_none_or(|t| frame.t_us >= t) {
            map = Some(MapSnapshot {
                t_us: frame.t_us,
                landmarks: map_of(&self.navigator),
            });
            self.next_snapshot = Some(frame.t_us.saturating_add(MAP_SNAPSHOT_US));
        }
        self.pending.push_back(Bundle {
            frame: estimate,
            camera,
            map,
        });
        self.take_final_poses();
    }

    /// The poses that became final (phase 1's at the hand-over, the smoother's as it
    /// marginalises) go to their pending frames.
    fn take_final_poses(&mut self) {
        if !self.phase1_poses_applied && !self.navigator.phase1_trajectory().is_empty() {
            self.phase1_poses_applied = true;
            let poses = self.navigator.phase1_trajectory().to_vec();
            set_poses(&mut self.pending, &poses, Some(Phase::Calibrating));
        }
        let smoothed = self.navigator.take_smoothed();
        set_poses(&mut self.pending, &smoothed, None);
    }

    /// Hands the pending frames whose poses are final to the sink, oldest first, keeping the
    /// last one (the end of the log changes it) unless `all`.
    fn release(&mut self, sink: &mut dyn ReplaySink, all: bool) -> Result<(), Error> {
        let in_phase1 = self.navigator.phase() == nav::Phase::Calibrating;
        let smoothing_since = self.navigator.smoothing_since_t_us();
        while let Some(first) = self.pending.front() {
            if !all {
                let last = self.pending.len() == 1;
                let waits_for_phase1 = first.frame.phase == Phase::Calibrating && in_phase1;
                let in_window = smoothing_since.is_some_and(|t| first.frame.t_us >= t);
                if last || waits_for_phase1 || in_window {
                    break;
                }
            }
            let Some(bundle) = self.pending.pop_front() else {
                break;
            };
            self.truth.add(&bundle.frame, &self.stream.truth, &self.rig);
            let true_pose = self
                .stream
                .truth
                .pose_at(bundle.frame.t_us)
                .map(|p| [p.x, p.y, p.theta]);
            self.stream.truth.forget_before(bundle.frame.t_us);
            sink.frame(&bundle.frame)?;
            if let Some(p) = true_pose {
                sink.truth(bundle.frame.t_us, p)?;
            }
            if let Some(c) = &bundle.camera {
                sink.camera(c)?;
            }
            if let Some(m) = &bundle.map {
                sink.map(m)?;
            }
        }
        Ok(())
    }

    /// The end of the log: phase 1 ended if it still ran, the last poses, the final map and
    /// camera, the summary.
    fn finish(mut self, sink: &mut dyn ReplaySink) -> Result<ReplayEnd, Error> {
        // A log that ends in phase 1 is still mapped: phase 2 starts from the batch of every
        // frame.
        if let Err(e) = self.navigator.finish() {
            refuse(&mut self.refused, &e);
        }
        self.take_final_poses();
        // Every frame phase 2's smoother still holds takes its pose.
        let window = self.navigator.smoother_window();
        set_poses(&mut self.pending, &window, None);
        let landmarks = map_of(&self.navigator);
        let (final_c, final_cov) = self.navigator.camera();
        let final_camera = ParamEstimate::all(&final_c, &final_cov);
        let final_pose_cov = matrix3(&self.navigator.pose().1);
        let has_filter = self.navigator.ekf().is_some();
        if let Some(last) = self.pending.back_mut() {
            // The final map (after the smoother's last solve) is the last snapshot.
            if has_filter {
                match &mut last.map {
                    Some(m) => m.landmarks.clone_from(&landmarks),
                    None => {
                        last.map = Some(MapSnapshot {
                            t_us: last.frame.t_us,
                            landmarks: landmarks.clone(),
                        });
                    }
                }
            }
            // The last frame's camera sample and pose covariance are the final ones.
            if last.frame.phase == Phase::Navigating {
                last.frame.pose_covariance = final_pose_cov;
                if let Some(c) = &mut last.camera {
                    c.params.clone_from(&final_camera);
                }
            }
        }
        let last_frame = self.pending.back().map(|b| b.frame.clone());
        let last_truth = last_frame
            .as_ref()
            .and_then(|f| self.stream.truth.pose_at(f.t_us).copied());
        self.release(sink, true)?;

        let mut counts = self.stream.counts;
        let mut warnings = self.read_warnings();
        warnings.append(&mut self.warnings);
        warnings.extend(self.stream.input_warnings());
        let navigator = &self.navigator;
        let stats = navigator.stats();
        let tracker = navigator.front_end().tracker().stats();
        counts.stereo_matches = navigator.front_end().stereo_stats().matches;
        counts.tracks = tracker.started;
        counts.confirmed_tracks = tracker.confirmed;
        counts.tracker_resets = tracker.resets;
        counts.phase1_solves = stats.phase1_solves;
        counts.landmarks_merged = stats.landmarks_merged;
        counts.features_outside_field = stats.features_outside_field;
        counts.loops_closed = stats.loops_closed;
        counts.loops_refused = stats.loops_refused;
        counts.lamps_held_mapped = stats.held_mapped;
        let damage = self.stream.reader().damage();
        counts.log_spans_lost = damage.spans_total;
        counts.log_bytes_lost = damage.bytes_lost;
        counts.log_chunks_lost = damage.chunks_lost;
        counts.log_time_lost_ms = time_lost_ms(damage);
        let log_damage = (!damage.is_clean()).then(|| damage.clone());
        navigator_warnings(navigator, &self.refused, &mut warnings);

        let truth_stream = &self.stream.truth;
        let truth = truth_stream.any.then(|| {
            let mut e = self
                .truth
                .errors(truth_stream, &landmarks, &final_c, &self.rig);
            let state = navigator
                .ekf()
                .zip(last_truth.as_ref())
                .and_then(|(ekf, pose)| state_nees(ekf, pose, truth_stream));
            if self.nees_frames > 0 || state.is_some() {
                let (state_nees, state_dof) = state.unwrap_or((f64::NAN, 0));
                e.consistency = Some(crate::Consistency {
                    pose_nees: self.nees_sum / self.nees_frames.max(1) as f64,
                    pose_frames: self.nees_frames,
                    final_pose_nees: self.nees_last,
                    state_nees,
                    state_dof,
                });
            }
            e
        });
        Ok(ReplayEnd {
            last_frame,
            first_t_us: self.first_t_us,
            frames_processed: self.frames_processed,
            phase2_frames: self.phase2_frames,
            landmarks,
            final_camera,
            phase_switch_t_us: navigator.phase_switch_t_us(),
            phase1_skipped: self.settings.skip_phase1,
            counts,
            truth,
            warnings,
            log_damage,
            map_common_error: navigator.ekf().and_then(common_error),
            odometry: Some(odometry_model(navigator)),
        })
    }

    /// The reading's warnings: the log ending early, the reader's, the rig given differing
    /// from the log's.
    fn read_warnings(&self) -> Vec<String> {
        let reader = self.stream.reader();
        let mut warnings = Vec::new();
        if let Some(why) = reader.truncated() {
            warnings.push(format!(
                "the log ends early ({why}): replayed as far as it goes"
            ));
        }
        warnings.extend(reader.warnings().iter().cloned());
        let damage = reader.damage();
        for span in damage.spans.iter().take(MAX_SPAN_WARNINGS) {
            warnings.push(span_warning(span));
        }
        if damage.spans_total > MAX_SPAN_WARNINGS as u64 {
            warnings.push(format!(
                "and {} more stretches of the log lost ({} bytes, {} chunks in all)",
                damage.spans_total - MAX_SPAN_WARNINGS as u64,
                damage.bytes_lost,
                damage.chunks_lost
            ));
        }
        if self.given_rig
            && let Some(text) = &self.stream.rig_text
        {
            warnings.extend(crate::rig_differs(&self.path, &self.rig, text));
        }
        warnings
    }
}

/// Lost stretches of a damaged log told one warning each (the rest in one more line).
const MAX_SPAN_WARNINGS: usize = 10;

/// One line for a lost stretch of the log: where, which log time, what it held, why.
fn span_warning(span: &vehicle_log::LostSpan) -> String {
    let s = |ns: u64| ns as f64 * 1e-9;
    let bound = if span.exact_times { "" } else { "within " };
    let time = match (span.start_ns, span.end_ns) {
        (Some(a), Some(b)) => format!("{bound}log time {:.3} s to {:.3} s", s(a), s(b)),
        (None, Some(b)) => format!("log time before {:.3} s", s(b)),
        (Some(a), None) => format!("log time after {:.3} s", s(a)),
        (None, None) => "log time unknown".to_owned(),
    };
    let held = span.messages.as_ref().map_or(String::new(), |m| {
        let parts: Vec<String> = m.iter().map(|(t, n)| format!("{n} on {t}")).collect();
        format!(
            ", {} messages: {}",
            m.values().sum::<u64>(),
            parts.join(", ")
        )
    });
    format!(
        "lost {} bytes of the log at offset {} ({time}{held}): {}",
        span.bytes, span.offset, span.why
    )
}

/// Data time covered by the lost stretches whose both ends are known, milliseconds.
pub(crate) fn time_lost_ms(damage: &vehicle_log::Damage) -> u64 {
    damage
        .spans
        .iter()
        .filter_map(|s| Some(s.end_ns?.saturating_sub(s.start_ns?)))
        .sum::<u64>()
        / 1_000_000
}

/// The odometry's noise model the navigator used, for the summary (issue 36).
fn odometry_model(navigator: &Navigator) -> estimates_log::OdometryModel {
    let stated = navigator.rig().noise;
    let used = navigator.odometry_noise();
    estimates_log::OdometryModel {
        stated: [
            stated.velocity,
            stated.yaw_rate,
            stated.velocity_tau,
            stated.yaw_rate_tau,
        ],
        used: [used.velocity, used.yaw_rate],
        widened: navigator
            .stats()
            .odometry_widened
            .map(|w| estimates_log::OdometryWidened {
                t_us: w.first_t_us,
                span_s: w.first.span_s,
                ratios: [w.first.translation, w.first.heading],
                variance_factors: [w.factors.0, w.factors.1],
                time_constants_s: [w.time_constants_s.0, w.time_constants_s.1],
            }),
    }
}

/// The warning for an odometry noise model the navigator widened (issue 36): what the rig file
/// stated, what the first widening's residuals showed (the batch's, or phase 2's filter's when
/// `phase2_first`), what was used, and how many times phase 2's own check widened it after
/// the hand-over (`phase2_widenings`, the first widening included when it was phase 2's).
pub(crate) fn odometry_widened_warning(
    stated: &rig_model::Noise,
    used: &rig_model::Noise,
    w: &selfcal::OdometryWidening,
    phase2_widenings: u64,
    phase2_first: bool,
) -> String {
    let memory = match w.time_constants_s {
        (t, h) if t > 0.0 && h > 0.0 => {
            format!("; its errors last about {t:.2} s (translation) and {h:.2} s (heading)")
        }
        (t, _) if t > 0.0 => format!("; its translation errors last about {t:.2} s"),
        (_, h) if h > 0.0 => format!("; its heading errors last about {h:.2} s"),
        _ => String::new(),
    };
    let phase2 = match phase2_widenings {
        0 => String::new(),
        n => format!(" ({n} time(s) by phase 2's own check of its filter's trajectory)"),
    };
    let first = if phase2_first {
        "the phase-2 filter"
    } else {
        "the batch"
    };
    format!(
        "the odometry is worse than the rig file states (velocity {} m/s, yaw_rate {} rad/s, velocity_tau {} s, yaw_rate_tau {} s): from {:.1} s on, {}'s trajectory disagreed with it over {:.0} s spans {:.1}x (translation) and {:.1}x (heading) in variance{}; its noise model was widened to velocity {:.4} m/s and yaw_rate {:.4} rad/s (variance x{:.1} and x{:.1}){}: state the odometry's noise and memory in the rig file's [noise]",
        stated.velocity,
        stated.yaw_rate,
        stated.velocity_tau,
        stated.yaw_rate_tau,
        w.first_t_us as f64 * 1e-6,
        first,
        w.first.span_s,
        w.first.translation,
        w.first.heading,
        memory,
        used.velocity,
        used.yaw_rate,
        w.factors.0,
        w.factors.1,
        phase2,
    )
}

/// The navigator's warnings at the end of a replay.
fn navigator_warnings(navigator: &Navigator, refused: &Refusals, warnings: &mut Vec<String>) {
    let stats = navigator.stats();
    for (n, first) in refused.values() {
        warnings.push(if *n == 1 {
            format!("1 input refused by the navigator: {first}")
        } else {
            format!("{n} inputs refused by the navigator, the first: {first}")
        });
    }
    if stats.frames_without_odometry > 0 {
        warnings.push(format!(
            "{} frame(s) had no odometry since the frame before: the pose was held there",
            stats.frames_without_odometry
        ));
    }
    if stats.loops_given_up > 0 {
        warnings.push(format!(
            "the pose was lost (more than {} m uncertain) and {} lamps seen then matched no place of the map{}: they were mapped as new ground",
            nav::MATCH_MAX_POSE_SIGMA_M,
            nav::LOOP_GIVE_UP_LAMPS,
            if stats.loops_given_up > 1 {
                format!(" ({} times)", stats.loops_given_up)
            } else {
                String::new()
            }
        ));
    }
    let held = navigator.held_lamps().len();
    if held > 0 {
        warnings.push(format!(
            "the log ended with the pose lost (more than {} m uncertain): {held} lamp(s) seen since were held out of the map and are not in it",
            nav::MATCH_MAX_POSE_SIGMA_M
        ));
    }
    for (p, value, nominal, prior, sigma) in navigator.pulled_from_prior() {
        let (scale, unit) = p.display_unit();
        warnings.push(format!(
            "{} ended {:.1} prior sigmas from its nominal value ({:.3} +- {:.3} {unit} against the rig file's {:.3} +- {:.3} {unit}): the rig file's nominal value or prior is wrong, or a model error (odometry worse than stated) pulled it there",
            p.name(),
            (value - nominal).abs() / prior,
            scale * value,
            scale * sigma,
            scale * nominal,
            scale * prior,
        ));
    }
    if let Some(w) = &stats.odometry_widened {
        warnings.push(odometry_widened_warning(
            &navigator.rig().noise,
            &navigator.odometry_noise(),
            w,
            stats.phase2_odometry_widenings,
            stats.phase2_widened_first,
        ));
    }
    if stats.odometry_dropped > 0 {
        warnings.push(format!(
            "{} odometry sample(s) dropped: no stereo frame came for longer than the navigator's odometry buffer",
            stats.odometry_dropped
        ));
    }
    for (p, sigma, prior) in navigator.spurious_information() {
        let (scale, unit) = p.display_unit();
        warnings.push(format!(
            "the filter holds information on {} (sigma {:.2} {unit}, prior {:.2} {unit}) that the motion cannot give (the odometry travelled {:.3} m significantly): a model error elsewhere, such as the camera moving while the odometry says the vehicle stands",
            p.name(),
            scale * sigma,
            scale * prior,
            stats.significant_translation_m
        ));
    }
    if let Some((reason, uninformed)) = navigator.uninformed()
        && (reason != rig_model::handover::HandoverReason::Stable || !uninformed.is_empty())
    {
        let why = match reason {
            rig_model::handover::HandoverReason::Stable => "phase 1 became stable",
            rig_model::handover::HandoverReason::BufferFull => {
                "phase 1 was not stable when its buffer (frames or landmarks) filled"
            }
            rig_model::handover::HandoverReason::Requested => {
                "phase 1 was not stable by the end of the log"
            }
        };
        let names: Vec<&str> = uninformed.iter().map(|p| p.name()).collect();
        warnings.push(if names.is_empty() {
            format!("{why}: phase 2 mapped from its estimate")
        } else {
            format!(
                "{why}; the data did not inform {} at the hand-over: phase 2 started them from the rig's nominal values and priors (the values and sigmas reported are phase 2's)",
                names.join(", ")
            )
        });
    }
}

/// The navigator's refusals by kind: how many, and the first one's message (bounded however
/// many inputs are refused).
type Refusals = BTreeMap<&'static str, (u64, String)>;

fn refuse(refused: &mut Refusals, e: &nav::Error) {
    refused
        .entry(e.kind())
        .and_modify(|(n, _)| *n += 1)
        .or_insert_with(|| (1, e.to_string()));
}

/// Each pending frame (of `phase` only, when given) with a pose in `poses` (sorted by time)
/// at its timestamp takes it.
fn set_poses(pending: &mut VecDeque<Bundle>, poses: &[(u64, Pose2)], phase: Option<Phase>) {
    if poses.is_empty() {
        return;
    }
    let mut i = 0usize;
    for b in pending.iter_mut() {
        let f = &mut b.frame;
        while poses.get(i).is_some_and(|(t, _)| *t < f.t_us) {
            i += 1;
        }
        if let Some((t, p)) = poses.get(i)
            && *t == f.t_us
            && phase.is_none_or(|ph| ph == f.phase)
        {
            f.pose = [p.x, p.y, p.theta];
        }
    }
}

/// The errors against the truth, accumulated over the frames as they become final: the
/// trajectory error, the map's gauge (the planar motion that best takes the phase-2
/// trajectory onto the true one) and how often each lamp was in view.
#[derive(Debug, Clone, Default)]
struct TruthAccumulator {
    sq: f64,
    sq_heading: f64,
    max: f64,
    n: usize,
    /// Phase-2 frames with a true pose: sums of sin and cos of the heading error, of the true
    /// and estimated positions.
    gauge_sin: f64,
    gauge_cos: f64,
    true_x: f64,
    true_y: f64,
    est_x: f64,
    est_y: f64,
    gauge_frames: usize,
    gauge_weight: f64,
    /// Frames each true lamp was inside both images at.
    seen: Vec<usize>,
}

/// The floor of a frame's position sigma in the gauge's weights, metres.
const GAUGE_FLOOR_M: f64 = 0.01;

impl TruthAccumulator {
    /// A final frame estimate against the true pose at its timestamp, if any.
    fn add(&mut self, f: &FrameEstimate, truth: &TruthStream, rig: &Rig) {
        let Some(p) = truth.pose_at(f.t_us) else {
            return;
        };
        let [x, y, theta] = f.pose;
        let e2 = (x - p.x).powi(2) + (y - p.y).powi(2);
        self.sq += e2;
        self.max = self.max.max(e2.sqrt());
        let dh = (theta - p.theta + PI).rem_euclid(2.0 * PI) - PI;
        self.sq_heading += dh * dh;
        self.n += 1;
        if f.phase == Phase::Navigating {
            // Each frame weighed by its pose's precision (a centimetre's floor): frames dead
            // reckoned through a dark stretch, metres off with metres of sigma, say nothing
            // about where the map sits.
            let c = &f.pose_covariance;
            let w = 1.0 / (c[0][0] + c[1][1] + GAUGE_FLOOR_M * GAUGE_FLOOR_M);
            let w = if w.is_finite() { w } else { 0.0 };
            let d = p.theta - theta;
            self.gauge_sin += w * d.sin();
            self.gauge_cos += w * d.cos();
            self.true_x += w * p.x;
            self.true_y += w * p.y;
            self.est_x += w * x;
            self.est_y += w * y;
            self.gauge_weight += w;
            self.gauge_frames += 1;
        }
        // Lamps in view of both cameras (both phases are mapped).
        if self.seen.len() != truth.landmarks.len() {
            self.seen = vec![0; truth.landmarks.len()];
        }
        let true_camera = truth.camera.as_ref().map_or(rig.nominal, truth_camera);
        let (w, h) = (f64::from(rig.width), f64::from(rig.height));
        let inside = |u: f64, v: f64| u >= 0.0 && u < w && v >= 0.0 && v < h;
        // Through real lenses a lamp is in view where its raw pixels are, as the simulator
        // decides.
        let c = &rig.nominal;
        let in_view = |z: &rig_model::Measurement| match &rig.lens {
            None => inside(z[0], z[1]) && inside(z[2], z[3]),
            Some(lens) => lens.sees(z, c.f, c.cx, c.cy, w, h),
        };
        let projector = rig_model::Projector::new(&true_camera, &Pose2::new(p.x, p.y, p.theta));
        for (lamp, count) in truth.landmarks.iter().zip(self.seen.iter_mut()) {
            let l = nalgebra::Vector3::new(lamp.x, lamp.y, lamp.z);
            if let Ok(z) = projector.project(&l)
                && in_view(&z)
            {
                *count += 1;
            }
        }
    }

    /// The map's gauge: rotation from the mean heading error (well defined even when the
    /// robot turns on the spot), then the mean position offset, each frame weighed by its
    /// pose's precision.
    fn gauge(&self) -> Planar {
        if self.gauge_frames == 0 {
            return Planar::IDENTITY;
        }
        let angle = f64::atan2(self.gauge_sin, self.gauge_cos);
        let (sn, cs) = angle.sin_cos();
        let m = self.gauge_weight;
        if m <= 0.0 {
            return Planar::IDENTITY;
        }
        Planar {
            angle,
            tx: (self.true_x - (cs * self.est_x - sn * self.est_y)) / m,
            ty: (self.true_y - (sn * self.est_x + cs * self.est_y)) / m,
        }
    }

    /// The errors, with the final map and camera.
    fn errors(
        &self,
        truth: &TruthStream,
        landmarks: &[LandmarkEstimate],
        final_camera: &CameraParams,
        _rig: &Rig,
    ) -> TruthErrors {
        let n = self.n;
        let count = n.max(1) as f64;
        // Landmarks: the map is anchored where phase 2 started, at the dead-reckoned pose, so
        // it is first carried onto the truth by the gauge; then each landmark is matched to
        // the nearest lamp within the radius, one-to-one, closest pairs first. The errors are
        // taken without that motion.
        let gauge = self.gauge();
        let mut candidates: Vec<(f64, f64, usize, usize)> = Vec::new();
        for (li, l) in landmarks.iter().enumerate() {
            let moved = gauge.apply(l.position);
            for (ti, t) in truth.landmarks.iter().enumerate() {
                let near = distance(moved, [t.x, t.y, t.z]);
                if near <= LAMP_MATCH_RADIUS_M {
                    candidates.push((near, distance(l.position, [t.x, t.y, t.z]), li, ti));
                }
            }
        }
        candidates.sort_by(|a, b| a.0.total_cmp(&b.0));
        let mut used_l = vec![false; landmarks.len()];
        let mut used_t = vec![false; truth.landmarks.len()];
        let mut lm_sq = 0.0;
        let mut matched = 0usize;
        let mut pairs: Vec<([f64; 3], [f64; 3])> = Vec::new();
        for (_, d, li, ti) in candidates {
            if used_l.get(li).copied().unwrap_or(true) || used_t.get(ti).copied().unwrap_or(true) {
                continue;
            }
            if let (Some(a), Some(b)) = (used_l.get_mut(li), used_t.get_mut(ti)) {
                *a = true;
                *b = true;
            }
            lm_sq += d * d;
            matched += 1;
            if let (Some(l), Some(t)) = (landmarks.get(li), truth.landmarks.get(ti)) {
                pairs.push((l.position, [t.x, t.y, t.z]));
            }
        }
        // A lamp mapped twice: a landmark left unmatched within the radius of a lamp that
        // another landmark took (counted among the unmatched too).
        let landmarks_duplicate = landmarks
            .iter()
            .zip(&used_l)
            .filter(|&(l, &used)| {
                !used && {
                    let moved = gauge.apply(l.position);
                    truth.landmarks.iter().zip(&used_t).any(|(t, &taken)| {
                        taken && distance(moved, [t.x, t.y, t.z]) <= LAMP_MATCH_RADIUS_M
                    })
                }
            })
            .count();
        let lamps_missed = self
            .seen
            .iter()
            .zip(&used_t)
            .filter(|&(&s, &used)| s >= LAMP_SEEN_FRAMES && !used)
            .count();
        let camera = truth.camera.as_ref().map_or_else(Vec::new, |c| {
            let t = truth_camera(c);
            Param::ALL
                .iter()
                .map(|&p| (p, final_camera.get(p) - t.get(p)))
                .collect()
        });
        TruthErrors {
            landmark_rms: if matched > 0 {
                (lm_sq / matched as f64).sqrt()
            } else {
                f64::NAN
            },
            landmark_rms_aligned: aligned_rms(&pairs),
            landmarks_matched: matched,
            landmarks_unmatched: landmarks.len() - matched,
            landmarks_duplicate,
            lamps_missed,
            match_radius: LAMP_MATCH_RADIUS_M,
            ate_rms: if n > 0 {
                (self.sq / count).sqrt()
            } else {
                f64::NAN
            },
            ate_max: if n > 0 { self.max } else { f64::NAN },
            heading_rms: if n > 0 {
                (self.sq_heading / count).sqrt()
            } else {
                f64::NAN
            },
            camera,
            consistency: None,
        }
    }
}

/// The camera parameters of the simulator's truth (`/truth/camera`).
pub fn truth_camera(t: &TruthCamera) -> CameraParams {
    CameraParams {
        vehicle: rig_model::Vehicle {
            odom_scale: t.odom_scale,
            odom_yaw_scale: t.odom_yaw_scale,
            odom_yaw_bias: t.odom_yaw_bias,
            time_offset: t.time_offset,
        },
        f: t.f,
        cx: t.cx,
        cy: t.cy,
        baseline: t.baseline,
        mount: rig_model::camera::Mount {
            x: t.mount_x,
            y: t.mount_y,
            z: t.mount_z,
            roll: t.mount_roll,
            pitch: t.mount_pitch,
            yaw: t.mount_yaw,
        },
    }
}

/// Pose NEES of a filtered pose against the truth.
fn pose_nees(pose: &Pose2, cov: &nalgebra::Matrix3<f64>, t: &TruthPose) -> Option<f64> {
    let e = nalgebra::Vector3::new(
        pose.x - t.x,
        pose.y - t.y,
        rig_model::camera::wrap_angle(pose.theta - t.theta),
    );
    let v = e.dot(&(cov.try_inverse()? * e));
    v.is_finite().then_some(v)
}

/// Full-state NEES of the filter at the end against the truth (pose, the landmarks within
/// 10 cm of a lamp, the estimated camera parameters) and its degrees of freedom.
fn state_nees(ekf: &vslam_ekf::Ekf, pose: &TruthPose, truth: &TruthStream) -> Option<(f64, usize)> {
    let x = ekf.state();
    let p = ekf.covariance();
    let mut index: Vec<usize> = vec![0, 1, 2];
    let mut err: Vec<f64> = vec![
        x[0] - pose.x,
        x[1] - pose.y,
        rig_model::camera::wrap_angle(x[2] - pose.theta),
    ];
    for l in ekf.landmarks() {
        let i = ekf.landmark_state_index(l.id)?;
        let near = truth.landmarks.iter().min_by(|a, b| {
            let da = distance(l.position.into(), [a.x, a.y, a.z]);
            let db = distance(l.position.into(), [b.x, b.y, b.z]);
            da.total_cmp(&db)
        })?;
        if distance(l.position.into(), [near.x, near.y, near.z]) > LAMP_MATCH_RADIUS_M {
            continue;
        }
        for (a, t) in [near.x, near.y, near.z].into_iter().enumerate() {
            index.push(i + a);
            err.push(x[i + a] - t);
        }
    }
    if let Some(c) = &truth.camera {
        let c = truth_camera(c);
        for &param in ekf.estimated_parameters() {
            let i = ekf.camera_state_index(param)?;
            index.push(i);
            err.push(x[i] - c.get(param));
        }
    }
    // faer's blocked factorisation: nalgebra's took a tenth of a 587-lamp hall's replay.
    use faer::linalg::solvers::Solve;
    let n = index.len();
    let sub = faer::Mat::<f64>::from_fn(n, n, |a, b| p[(index[a], index[b])]);
    let e = faer::Mat::<f64>::from_fn(n, 1, |a, _| err[a]);
    let solved = sub.llt(faer::Side::Lower).ok()?.solve(&e);
    let v: f64 = (0..n).map(|a| err[a] * solved[(a, 0)]).sum();
    v.is_finite().then_some((v, n))
}

/// A planar rigid motion: rotation about z by `angle`, then translation `(tx, ty)`.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Planar {
    angle: f64,
    tx: f64,
    ty: f64,
}

impl Planar {
    const IDENTITY: Self = Self {
        angle: 0.0,
        tx: 0.0,
        ty: 0.0,
    };

    /// The least-squares motion mapping the points `a` onto `b` (closed form); the identity
    /// with fewer than two pairs.
    fn fit(pairs: &[([f64; 2], [f64; 2])]) -> Self {
        if pairs.len() < 2 {
            return Self::IDENTITY;
        }
        let n = pairs.len() as f64;
        let (mut ax, mut ay, mut bx, mut by) = (0.0, 0.0, 0.0, 0.0);
        for (a, b) in pairs {
            ax += a[0];
            ay += a[1];
            bx += b[0];
            by += b[1];
        }
        let (ax, ay, bx, by) = (ax / n, ay / n, bx / n, by / n);
        let (mut c, mut s) = (0.0, 0.0);
        for (a, b) in pairs {
            let (px, py) = (a[0] - ax, a[1] - ay);
            let (qx, qy) = (b[0] - bx, b[1] - by);
            c += px * qx + py * qy;
            s += px * qy - py * qx;
        }
        let angle = s.atan2(c);
        let (sn, cs) = angle.sin_cos();
        Self {
            angle,
            tx: bx - (cs * ax - sn * ay),
            ty: by - (sn * ax + cs * ay),
        }
    }

    fn apply(&self, p: [f64; 3]) -> [f64; 3] {
        let (sn, cs) = self.angle.sin_cos();
        [
            cs * p[0] - sn * p[1] + self.tx,
            sn * p[0] + cs * p[1] + self.ty,
            p[2],
        ]
    }
}

fn distance(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// RMS of the 3-D differences after the planar rigid motion that best maps the estimates onto
/// the truths.
fn aligned_rms(pairs: &[([f64; 3], [f64; 3])]) -> f64 {
    if pairs.is_empty() {
        return f64::NAN;
    }
    let planar: Vec<([f64; 2], [f64; 2])> = pairs
        .iter()
        .map(|(e, t)| ([e[0], e[1]], [t[0], t[1]]))
        .collect();
    let fit = Planar::fit(&planar);
    let sq: f64 = pairs
        .iter()
        .map(|(e, t)| distance(fit.apply(*e), *t).powi(2))
        .sum();
    (sq / pairs.len() as f64).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_widening_warning_names_who_widened_first_and_how_often_phase_2_did() {
        let stated = rig_model::Noise::white(0.5, 0.02, 0.01);
        let used = rig_model::Noise::white(0.5, 0.2, 0.1);
        let w = selfcal::OdometryWidening {
            first_t_us: 5_000_000,
            first: selfcal::OdometryConsistency {
                windows: 4,
                span_s: 1.0,
                translation: 62.3,
                heading: 58.6,
                frame_translation: 1.0,
                frame_heading: 1.0,
            },
            factors: (100.0, 100.0),
            time_constants_s: (0.0, 0.6),
            looks: 1,
        };
        let batch = odometry_widened_warning(&stated, &used, &w, 0, false);
        assert!(
            batch.contains("from 5.0 s on, the batch's trajectory disagreed"),
            "{batch}"
        );
        assert!(
            batch.contains("heading errors last about 0.60 s"),
            "{batch}"
        );
        assert!(!batch.contains("phase 2's own check"), "{batch}");
        let filter = odometry_widened_warning(&stated, &used, &w, 2, true);
        assert!(
            filter.contains("the phase-2 filter's trajectory disagreed"),
            "{filter}"
        );
        assert!(
            filter.contains("(2 time(s) by phase 2's own check"),
            "{filter}"
        );
    }
}
