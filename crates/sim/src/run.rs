//! A simulated run: odometry, stereo frames with their features, the board's packets and the
//! chunks the host receives, and the ground truth.

use std::collections::HashMap;
use std::io::{Seek, Write};
use std::path::Path;

use fpga_link::Encoder;
use harris_core::Registers;
use rig_model::{CameraParams, Measurement, Param, Pose2, Rig};
use vehicle_log::{LogWriter, TruthCamera, TruthLandmark, TruthPose};

use crate::error::{Error, Result};
use crate::features::{ImageFeatures, LampView, SimFeature, fast_frame, lamp_views};
use crate::link::{Chunk, Packet, PacketFate, chunks, draw_fates};
use crate::motion::{Motion, OdomSample, tick_us, wrap_angle};
use crate::render::{Renderer, StereoImages};
use crate::rng::{Stream, stream_rng};
use crate::scenario::Scenario;
use crate::world::{Lamp, lamps};

/// How the board's features are made.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Mode {
    /// Project the lamps with the rig model, add noise and clutter, quantise (no images).
    Fast,
    /// Render both images and run the board's detector on them.
    Rendered,
}

impl Mode {
    /// `"fast"` or `"rendered"`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Fast => "fast",
            Self::Rendered => "rendered",
        }
    }
}

/// One stereo frame: when, where the robot truly was, what it saw and what the board sent.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameTruth {
    /// Index of the exposure in the run, from 0: the camera clock's tick. Frames are not sent
    /// while the vehicle is carried (a `"moved"` segment), so the indices jump across one.
    pub index: usize,
    /// The packet's frame counter: `rates.first_frame` plus `index` (wrapping). It jumps
    /// across a `"moved"` segment as a board that ran on would count, while nothing reached
    /// the vehicle computer: a receiver sees the blind frames as lost.
    pub frame_counter: u32,
    /// Mid-exposure timestamp, microseconds.
    pub t_us: u64,
    /// The robot's true pose in the world frame (theta in `(-pi, pi]`).
    pub pose: Pose2,
    /// The lamps in view, with their exact projections.
    pub views: Vec<LampView>,
    /// The left camera's features, as sent.
    pub left: ImageFeatures,
    /// The right camera's features, as sent.
    pub right: ImageFeatures,
}

impl FrameTruth {
    /// `(uL, vL, uR, vR)` of every lamp seen in both images of this frame, by lamp id: the
    /// simulator's own labelling of its features, for judging estimators apart from
    /// association.
    pub fn lamp_measurements(&self) -> HashMap<u32, Measurement> {
        let right: HashMap<u32, (u16, u16)> = self
            .right
            .features
            .iter()
            .filter_map(|f| Some((f.lamp?, (f.x_q4, f.y_q4))))
            .collect();
        let q = |v: u16| f64::from(v) / 16.0;
        self.left
            .features
            .iter()
            .filter_map(|l| {
                let (rx, ry) = right.get(&l.lamp?)?;
                Some((
                    l.lamp?,
                    Measurement::new(q(l.x_q4), q(l.y_q4), q(*rx), q(*ry)),
                ))
            })
            .collect()
    }
}

/// Everything a run produced, as plain data.
#[derive(Debug, Clone, PartialEq)]
pub struct SimRun {
    /// The scenario's name (its file name without `.toml`).
    pub name: String,
    /// The seed used.
    pub seed: u64,
    /// How the features were made.
    pub mode: Mode,
    /// The true camera parameters `C`.
    pub camera: CameraParams,
    /// The nominal rig a user would have.
    pub rig: Rig,
    /// The board's registers.
    pub registers: Registers,
    /// Every lamp of the hall and the added ones, in the world frame, `landmarks[i].id == i`;
    /// the dark ones are here with `lit` false (the truth's landmarks leave them out).
    pub landmarks: Vec<Lamp>,
    /// Odometry as measured (noise, scale error, bias), as logged; nothing during a
    /// `"moved"` segment with `odometry = "none"`.
    pub odometry: Vec<OdomSample>,
    /// The true odometry at the same times, what the wheels did: integrated, it gives the
    /// true trajectory, except across a `"moved"` segment (the vehicle was carried; the truth
    /// poses say where to).
    pub odometry_truth: Vec<OdomSample>,
    /// The stereo frames (none while the vehicle is carried).
    pub frames: Vec<FrameTruth>,
    /// One packet per stereo frame, as encoded, with its fate on the link.
    pub packets: Vec<Packet>,
    /// The byte stream as received, in arrival order.
    pub chunks: Vec<Chunk>,
    /// Whether the log gets `/rig`.
    pub log_rig: bool,
    /// Whether the log gets `/truth/...`.
    pub log_truth: bool,
}

/// Simulates a scenario.
pub fn simulate(scenario: &Scenario, mode: Mode) -> Result<SimRun> {
    simulate_with_progress(scenario, mode, &mut |_, _| {})
}

/// Frames simulated between two progress reports (and per batch of worker threads).
const BATCH: usize = 64;

/// Simulates a scenario, calling `progress(frames_done, frames_total)` now and then.
pub fn simulate_with_progress(
    scenario: &Scenario,
    mode: Mode,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<SimRun> {
    let plan = Plan::new(scenario, mode)?;
    let mut frames = Vec::with_capacity(plan.frame_count());
    plan.frames(
        BATCH,
        &|_, _| Ok(()),
        &mut |frame, ()| {
            frames.push(frame);
            Ok(())
        },
        progress,
    )?;
    plan.finish(frames)
}

/// A run before its frames: everything the scenario fixes (the true camera, the lamps, the
/// path and its odometry, the exposure times, the renderer).
pub(crate) struct Plan<'a> {
    scenario: &'a Scenario,
    mode: Mode,
    pub(crate) camera: CameraParams,
    regs: Registers,
    pub(crate) landmarks: Vec<Lamp>,
    motion: Motion,
    pub(crate) odometry: Vec<OdomSample>,
    /// The exposures (index, time), without those of a blind camera (a carried vehicle).
    times: Vec<(usize, u64)>,
    renderer: Option<Renderer>,
    /// The board's clock offset, microseconds.
    offset_us: f64,
}

impl<'a> Plan<'a> {
    pub(crate) fn new(scenario: &'a Scenario, mode: Mode) -> Result<Self> {
        let spec = &scenario.spec;
        // The fields are public: check them again in case they were changed after loading.
        spec.validate(&scenario.source_name)?;
        let seed = spec.seed;
        let camera = scenario.true_camera();
        let regs = scenario.registers();
        let landmarks = lamps(&spec.world, seed);
        let rates = &spec.rates;
        let first_frame_us = tick_us(rates.start_t_us, rates.camera_phase_us, rates.camera_hz, 0);
        let motion = Motion::new(
            &spec.path,
            rates.start_t_us,
            rates.odometry_hz,
            first_frame_us,
        );
        let odometry = motion.measured(&spec.noise, &mut stream_rng(seed, Stream::Odometry, 0));
        let end_us = motion.end_us();
        let times: Vec<(usize, u64)> = (0..)
            .map(|k| {
                (
                    k,
                    tick_us(rates.start_t_us, rates.camera_phase_us, rates.camera_hz, k),
                )
            })
            .take_while(|&(_, t)| t <= end_us)
            .filter(|&(_, t)| !motion.blind_at(t))
            .collect();
        let renderer = match mode {
            Mode::Rendered => {
                let renderer = Renderer::new(camera, &regs, spec.render, landmarks.clone());
                // Through the rig's lenses (the truth) the board sees raw images.
                Some(match &scenario.rig.lens {
                    Some(lens) => renderer.with_lens(lens),
                    None => renderer,
                })
            }
            Mode::Fast => None,
        };
        Ok(Self {
            scenario,
            mode,
            camera,
            regs,
            landmarks,
            motion,
            odometry,
            times,
            renderer,
            // The board stamps a frame exposed at odometry-clock time T with T + its offset.
            offset_us: (rates.board_clock_offset_s * 1e6).round(),
        })
    }

    pub(crate) fn frame_count(&self) -> usize {
        self.times.len()
    }

    /// The board's timestamp of the first frame, if any.
    pub(crate) fn first_stamp_us(&self) -> Option<u64> {
        self.times.first().map(|&(_, t)| self.stamp(t))
    }

    /// The board's timestamp of an exposure at odometry-clock time `t`.
    fn stamp(&self, t: u64) -> u64 {
        #[allow(
            clippy::cast_precision_loss,
            clippy::cast_possible_truncation,
            clippy::cast_sign_loss
        )]
        let s = (t as f64 + self.offset_us).max(0.0) as u64;
        s
    }

    /// One frame, with its images in the rendered mode.
    fn frame(&self, index: usize, exposed_us: u64) -> Result<(FrameTruth, Option<StereoImages>)> {
        let spec = &self.scenario.spec;
        let (camera, regs, seed) = (&self.camera, &self.regs, spec.seed);
        let lens = self.scenario.rig.lens.as_ref();
        let pose = self.motion.pose_at(exposed_us);
        let t_us = self.stamp(exposed_us);
        let views = lamp_views(camera, &pose, &self.landmarks, regs, lens);
        let (left, right, images) = match &self.renderer {
            None => {
                let (l, r) = fast_frame(
                    &views,
                    &spec.noise,
                    &spec.clutter,
                    spec.world.lamp_response,
                    regs,
                    lens.map(|l| (l, camera)),
                    &mut stream_rng(seed, Stream::Features, index as u64),
                );
                (l, r, None)
            }
            Some(renderer) => {
                let mut noise_left = stream_rng(seed, Stream::Image, 2 * index as u64);
                let mut noise_right = stream_rng(seed, Stream::Image, 2 * index as u64 + 1);
                let images = renderer.render(&pose, Some((&mut noise_left, &mut noise_right)));
                let detect = |image: &[u8]| {
                    harris_core::detect(image, regs).map_err(|source| Error::Detect {
                        frame: index,
                        source,
                    })
                };
                let (l, r) = (detect(&images.left)?, detect(&images.right)?);
                // The features are where the board sees the lamps: raw pixels through a lens.
                let seen = |lens: Option<&rig_model::lens::Lens>, u: f64, v: f64| match lens {
                    None => Some((u, v)),
                    Some(l) => l
                        .unrectify(nalgebra::Vector2::new(u, v), camera.f, camera.cx, camera.cy)
                        .map(|p| (p.x, p.y)),
                };
                (
                    associate(&l, &views, |v| {
                        seen(lens.map(|l| &l.left), v.u_left, v.v_left)
                    }),
                    associate(&r, &views, |v| {
                        seen(lens.map(|l| &l.right), v.u_right, v.v_right)
                    }),
                    Some(images),
                )
            }
        };
        let frame = FrameTruth {
            index,
            frame_counter: spec
                .rates
                .first_frame
                .wrapping_add(u32::try_from(index).unwrap_or(0)),
            t_us,
            pose: Pose2::new(pose.x, pose.y, wrap_angle(pose.theta)),
            views,
            left,
            right,
        };
        Ok((frame, images))
    }

    /// Simulates every frame in order, `batch` frames at a time over the machine's threads in
    /// the rendered mode: each frame and its images (rendered mode) go through `post` in the
    /// worker thread, and the frame and what `post` made of it to `sink`, in frame order, a
    /// batch at a time, so at most `batch` frames' images are alive at once.
    pub(crate) fn frames<T: Send>(
        &self,
        batch: usize,
        post: &(dyn Fn(&FrameTruth, Option<StereoImages>) -> Result<T> + Sync),
        sink: &mut dyn FnMut(FrameTruth, T) -> Result<()>,
        progress: &mut dyn FnMut(usize, usize),
    ) -> Result<()> {
        let threads = match self.mode {
            Mode::Rendered => std::thread::available_parallelism().map_or(1, usize::from),
            Mode::Fast => 1,
        };
        let one = |k: usize, t: u64| -> Result<(FrameTruth, T)> {
            let (frame, images) = self.frame(k, t)?;
            let extra = post(&frame, images)?;
            Ok((frame, extra))
        };
        let total = self.times.len();
        let mut done = 0;
        progress(0, total);
        for batch in self.times.chunks(batch.max(1)) {
            if threads <= 1 {
                for &(k, t) in batch {
                    let (frame, extra) = one(k, t)?;
                    sink(frame, extra)?;
                }
            } else {
                let results: Vec<Result<(FrameTruth, T)>> = std::thread::scope(|s| {
                    let handles: Vec<_> = (0..threads)
                        .map(|w| {
                            let one = &one;
                            s.spawn(move || {
                                batch
                                    .iter()
                                    .enumerate()
                                    .skip(w)
                                    .step_by(threads)
                                    .map(|(i, &(k, t))| (i, one(k, t)))
                                    .collect::<Vec<_>>()
                            })
                        })
                        .collect();
                    let mut all: Vec<(usize, Result<(FrameTruth, T)>)> =
                        Vec::with_capacity(batch.len());
                    for h in handles {
                        // A worker panics only on a bug; report it as a panic in this thread.
                        match h.join() {
                            Ok(v) => all.extend(v),
                            Err(p) => std::panic::resume_unwind(p),
                        }
                    }
                    all.sort_by_key(|(i, _)| *i);
                    all.into_iter().map(|(_, r)| r).collect()
                });
                for r in results {
                    let (frame, extra) = r?;
                    sink(frame, extra)?;
                }
            }
            done += batch.len();
            progress(done, total);
        }
        Ok(())
    }

    /// The run from its frames: the board's packets, their fates on the link and the chunks.
    pub(crate) fn finish(self, frames: Vec<FrameTruth>) -> Result<SimRun> {
        let spec = &self.scenario.spec;
        let (seed, rates) = (spec.seed, &spec.rates);
        let mut encoder = Encoder::starting_at(rates.first_frame);
        let mut packets = Vec::with_capacity(frames.len());
        for f in &frames {
            if encoder.next_frame() != f.frame_counter {
                // Across a carry: the counter jumps over the frames that were never sent.
                encoder = Encoder::starting_at(f.frame_counter);
            }
            let mut bytes = Vec::new();
            let frame_counter = encoder.next_frame();
            encoder
                .encode_to_vec(
                    f.t_us,
                    (&f.left.board_features(), f.left.overflow),
                    (&f.right.board_features(), f.right.overflow),
                    &mut bytes,
                )
                .map_err(|source| Error::Encode {
                    frame: f.index,
                    source,
                })?;
            packets.push(Packet {
                frame_index: f.index,
                frame_counter,
                t_us: f.t_us,
                bytes,
                fate: PacketFate::Sent,
            });
        }
        draw_fates(
            &mut packets,
            &spec.link,
            &mut stream_rng(seed, Stream::Faults, 0),
        );
        let chunks = chunks(
            &packets,
            &spec.link,
            &mut stream_rng(seed, Stream::Chunks, 0),
        );
        Ok(SimRun {
            name: scenario_name(&self.scenario.source_name),
            seed,
            mode: self.mode,
            camera: self.camera,
            rig: self.scenario.rig.clone(),
            registers: self.regs,
            odometry_truth: self.motion.sent_truth(),
            landmarks: self.landmarks,
            odometry: self.odometry,
            frames,
            packets,
            chunks,
            log_rig: spec.log.rig,
            log_truth: spec.log.truth,
        })
    }
}

/// The detected features with the lamp each is an image of: the nearest lamp in view within
/// 2 pixels of where the detector sees it (`at`: its projection in the image detected on, raw
/// through a lens; `None` where it has none), if any.
fn associate(
    detection: &harris_core::Detection,
    views: &[LampView],
    at: impl Fn(&LampView) -> Option<(f64, f64)>,
) -> ImageFeatures {
    const MAX_DISTANCE_PX: f64 = 2.0;
    let features = detection
        .features
        .iter()
        .map(|f| {
            let (u, v) = (f.u(), f.v());
            let lamp = views
                .iter()
                .filter_map(|view| {
                    let (x, y) = at(view)?;
                    Some((view.id, (x - u).hypot(y - v)))
                })
                .filter(|&(_, d)| d <= MAX_DISTANCE_PX)
                .min_by(|a, b| a.1.total_cmp(&b.1))
                .map(|(id, _)| id);
            SimFeature {
                x_q4: f.x_q4,
                y_q4: f.y_q4,
                r: f.r,
                lamp,
            }
        })
        .collect();
    ImageFeatures {
        features,
        overflow: detection.overflow,
    }
}

fn scenario_name(source_name: &str) -> String {
    let file = Path::new(source_name).file_name().map_or_else(
        || source_name.to_string(),
        |f| f.to_string_lossy().into_owned(),
    );
    file.strip_suffix(".toml").unwrap_or(&file).to_string()
}

/// The lit lamps as vehicle-log's truth messages ([`SimRun::truth_landmarks`]).
pub(crate) fn truth_landmarks(lamps: &[Lamp]) -> Vec<TruthLandmark> {
    lamps
        .iter()
        .filter(|l| l.lit)
        .map(|l| TruthLandmark {
            id: l.id,
            x: l.position.x,
            y: l.position.y,
            z: l.position.z,
        })
        .collect()
}

/// The true camera parameters as vehicle-log's truth message.
pub fn truth_camera(c: &CameraParams) -> TruthCamera {
    TruthCamera {
        f: c.f,
        cx: c.cx,
        cy: c.cy,
        baseline: c.baseline,
        mount_x: c.mount.x,
        mount_y: c.mount.y,
        mount_z: c.mount.z,
        mount_roll: c.mount.roll,
        mount_pitch: c.mount.pitch,
        mount_yaw: c.mount.yaw,
        odom_scale: c.vehicle.odom_scale,
        odom_yaw_scale: c.vehicle.odom_yaw_scale,
        odom_yaw_bias: c.vehicle.odom_yaw_bias,
        time_offset: c.vehicle.time_offset,
    }
}

impl SimRun {
    /// The byte stream as received: the chunks concatenated in arrival order.
    pub fn stream_bytes(&self) -> Vec<u8> {
        self.chunks
            .iter()
            .flat_map(|c| c.bytes.iter().copied())
            .collect()
    }

    /// Lamps seen by both cameras (inside both candidate areas) in each frame.
    pub fn visible_counts(&self) -> Vec<usize> {
        self.frames
            .iter()
            .map(|f| f.views.iter().filter(|v| v.in_left && v.in_right).count())
            .collect()
    }

    /// The landmarks as vehicle-log's truth messages: every lit lamp with its id (dark lamps
    /// are left out: nothing of them can be seen in this drive, and a replay judges the map
    /// against every truth landmark in view).
    pub fn truth_landmarks(&self) -> Vec<TruthLandmark> {
        truth_landmarks(&self.landmarks)
    }

    /// The true pose at each stereo frame as vehicle-log's truth messages.
    pub fn truth_poses(&self) -> Vec<TruthPose> {
        self.frames
            .iter()
            .map(|f| TruthPose {
                t_us: f.t_us,
                x: f.pose.x,
                y: f.pose.y,
                theta: f.pose.theta,
            })
            .collect()
    }

    /// The ground truth as JSON: `{"scenario", "seed", "mode", "camera": {"f", ..., "mount_yaw"},
    /// "landmarks": [{"id", "x", "y", "z"}], "trajectory": [{"frame", "t_us", "x", "y", "theta"}]}`
    /// (world frame, metres and radians; `camera` keyed like a replay summary; the landmarks
    /// are those of [`Self::truth_landmarks`]).
    pub fn truth_json(&self) -> String {
        let camera: serde_json::Map<String, serde_json::Value> = Param::ALL
            .iter()
            .map(|p| (p.name().to_string(), self.camera.get(*p).into()))
            .collect();
        let landmarks: Vec<serde_json::Value> = self
            .landmarks
            .iter()
            .filter(|l| l.lit)
            .map(|l| {
                serde_json::json!({"id": l.id, "x": l.position.x, "y": l.position.y, "z": l.position.z})
            })
            .collect();
        let trajectory: Vec<serde_json::Value> = self
            .frames
            .iter()
            .map(|f| {
                serde_json::json!({"frame": f.frame_counter, "t_us": f.t_us, "x": f.pose.x, "y": f.pose.y, "theta": f.pose.theta})
            })
            .collect();
        serde_json::json!({
            "scenario": self.name,
            "seed": self.seed,
            "mode": self.mode.name(),
            "camera": camera,
            "landmarks": landmarks,
            "trajectory": trajectory,
        })
        .to_string()
    }

    /// Writes the vehicle log (vehicle-interfaces.md section 4) to `path`.
    pub fn write_log(&self, path: &Path) -> Result<()> {
        let writer = LogWriter::create(path)?;
        self.write_log_with(writer)?;
        Ok(())
    }

    /// Writes the vehicle log into `w` and returns it.
    pub fn write_log_to<W: Write + Seek>(&self, w: W) -> Result<W> {
        self.write_log_with(LogWriter::new(w)?)
    }

    /// Messages in arrival (log time) order: `/rig` and the truth's landmarks and camera
    /// first, then odometry at `t_us`, the truth pose at the frame's `t_us`, and the feature
    /// chunks at their arrival times; on equal times odometry, then truth, then features.
    fn write_log_with<W: Write + Seek>(&self, mut log: LogWriter<W>) -> Result<W> {
        if self.log_rig {
            log.rig_json(&self.rig.to_json())?;
        }
        if self.log_truth {
            log.truth_camera(&truth_camera(&self.camera))?;
            log.truth_landmarks(&self.truth_landmarks())?;
        }
        let poses = if self.log_truth {
            self.truth_poses()
        } else {
            Vec::new()
        };
        let (mut i, mut j, mut k) = (0, 0, 0);
        let ns = |t_us: u64| t_us.saturating_mul(1000);
        loop {
            let t_odom = self.odometry.get(i).map(|s| ns(s.t_us));
            let t_pose = poses.get(j).map(|p| ns(p.t_us));
            let t_chunk = self.chunks.get(k).map(|c| c.log_time_ns);
            let next = [t_odom, t_pose, t_chunk]
                .into_iter()
                .enumerate()
                .filter_map(|(n, t)| t.map(|t| (t, n)))
                .min();
            match next {
                None => break,
                Some((_, 0)) => {
                    if let Some(s) = self.odometry.get(i) {
                        log.odom(s)?;
                    }
                    i += 1;
                }
                Some((_, 1)) => {
                    if let Some(p) = poses.get(j) {
                        log.truth_pose(p)?;
                    }
                    j += 1;
                }
                Some(_) => {
                    if let Some(c) = self.chunks.get(k) {
                        log.features(c.log_time_ns, &c.bytes)?;
                    }
                    k += 1;
                }
            }
        }
        Ok(log.finish()?)
    }
}
