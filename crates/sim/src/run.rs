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
use crate::render::Renderer;
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
    // The exposures (index, time), without those of a blind camera (a carried vehicle).
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
        Mode::Rendered => Some(Renderer::new(camera, &regs, spec.render, landmarks.clone())),
        Mode::Fast => None,
    };
    // The board stamps a frame exposed at odometry-clock time T with T + its clock offset.
    let offset_us = (rates.board_clock_offset_s * 1e6).round();
    let stamp = |t: u64| -> u64 {
        #[allow(
            clippy::cast_precision_loss,
            clippy::cast_possible_truncation,
            clippy::cast_sign_loss
        )]
        let s = (t as f64 + offset_us).max(0.0) as u64;
        s
    };
    let one_frame = |index: usize, exposed_us: u64| -> Result<FrameTruth> {
        let pose = motion.pose_at(exposed_us);
        let t_us = stamp(exposed_us);
        let views = lamp_views(
            &camera,
            &pose,
            &landmarks,
            &regs,
            scenario.rig.lens.as_ref(),
        );
        let (left, right) = match &renderer {
            None => fast_frame(
                &views,
                &spec.noise,
                &spec.clutter,
                spec.world.lamp_response,
                &regs,
                scenario.rig.lens.as_ref().map(|l| (l, &camera)),
                &mut stream_rng(seed, Stream::Features, index as u64),
            ),
            Some(renderer) => {
                let mut noise_left = stream_rng(seed, Stream::Image, 2 * index as u64);
                let mut noise_right = stream_rng(seed, Stream::Image, 2 * index as u64 + 1);
                let images = renderer.render(&pose, Some((&mut noise_left, &mut noise_right)));
                let detect = |image: &[u8]| {
                    harris_core::detect(image, &regs).map_err(|source| Error::Detect {
                        frame: index,
                        source,
                    })
                };
                let (l, r) = (detect(&images.left)?, detect(&images.right)?);
                (
                    associate(&l, &views, |v| (v.u_left, v.v_left)),
                    associate(&r, &views, |v| (v.u_right, v.v_right)),
                )
            }
        };
        Ok(FrameTruth {
            index,
            frame_counter: rates
                .first_frame
                .wrapping_add(u32::try_from(index).unwrap_or(0)),
            t_us,
            pose: Pose2::new(pose.x, pose.y, wrap_angle(pose.theta)),
            views,
            left,
            right,
        })
    };
    let threads = match mode {
        Mode::Rendered => std::thread::available_parallelism().map_or(1, usize::from),
        Mode::Fast => 1,
    };
    let mut frames = Vec::with_capacity(times.len());
    progress(0, times.len());
    for batch in times.chunks(BATCH) {
        if threads <= 1 {
            for &(k, t) in batch {
                frames.push(one_frame(k, t)?);
            }
        } else {
            let results: Vec<Result<FrameTruth>> = std::thread::scope(|s| {
                let handles: Vec<_> = (0..threads)
                    .map(|w| {
                        let one_frame = &one_frame;
                        s.spawn(move || {
                            batch
                                .iter()
                                .enumerate()
                                .skip(w)
                                .step_by(threads)
                                .map(|(i, &(k, t))| (i, one_frame(k, t)))
                                .collect::<Vec<_>>()
                        })
                    })
                    .collect();
                let mut all: Vec<(usize, Result<FrameTruth>)> = Vec::with_capacity(batch.len());
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
                frames.push(r?);
            }
        }
        progress(frames.len(), times.len());
    }
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
        name: scenario_name(&scenario.source_name),
        seed,
        mode,
        camera,
        rig: scenario.rig.clone(),
        registers: regs,
        landmarks,
        odometry,
        odometry_truth: motion.sent_truth(),
        frames,
        packets,
        chunks,
        log_rig: spec.log.rig,
        log_truth: spec.log.truth,
    })
}

/// The detected features with the lamp each is an image of: the nearest lamp in view within
/// 2 pixels, if any.
fn associate(
    detection: &harris_core::Detection,
    views: &[LampView],
    at: impl Fn(&LampView) -> (f64, f64),
) -> ImageFeatures {
    const MAX_DISTANCE_PX: f64 = 2.0;
    let features = detection
        .features
        .iter()
        .map(|f| {
            let (u, v) = (f.u(), f.v());
            let lamp = views
                .iter()
                .map(|view| {
                    let (x, y) = at(view);
                    (view.id, (x - u).hypot(y - v))
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
        self.landmarks
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
