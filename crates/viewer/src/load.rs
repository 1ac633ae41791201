//! Loading a file into a [`Model`]: a vehicle log is replayed through the stack
//! (`replay::replay_log`), or run on a saved map (`replay::localize_log`, with
//! [`LoadOptions::map`]), and its board stream decoded again for the features of every frame;
//! an estimates file is read back (`estimates_log::read_estimates`).
//!
//! A ROS 2 bag ([`LoadOptions::topics`], vehicle-interfaces.md 4.1) is replayed (or localised)
//! with its named topics as `stereonav replay` and `stereonav localize` run it, while a second
//! thread reads it once more: it pairs the camera images as the replay's host board does, runs
//! the board's detector on them for the features of every frame (the navigator's own do not
//! leave the replay) and indexes where each frame's images are, keeping no pixels
//! ([`crate::images`]). On two cores the two passes run at the same time.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};

use replay::{LocalizerSettings, NavSettings, Replay, ReplayCollector, Ros2Topics};
use rig_model::camera::CameraParams;
use rig_model::config::Rig;
use vehicle_log::{LogReader, Record, SummaryState};

use crate::Error;
use crate::images::{BagImages, Indexer};
use crate::model::{Features, ImagePoint, Model, SourceKind, Truth};

/// A decoded frame: its timestamp and the left and right features.
type DecodedFrame = (u64, Vec<ImagePoint>, Vec<ImagePoint>);

/// How a vehicle log is replayed.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct LoadOptions {
    /// The rig file's content; without it, the log's `/rig` message (or, on a map, the rig
    /// the map was made with).
    pub rig: Option<Rig>,
    /// The navigator's settings (phase 1 skipped or not, the size of phase 1's batch); not
    /// used on a map.
    pub settings: NavSettings,
    /// A saved map (`stereonav replay --save-map`): the log is localised on it
    /// (`replay::localize_log`, default settings) instead of replayed.
    pub map: Option<PathBuf>,
    /// A ROS 2 bag's camera and odometry topics (vehicle-interfaces.md 4.1): the file is such
    /// a bag, replayed (or localised) from them, and its images are shown under the features
    /// ([`Model::images`]).
    pub topics: Option<Ros2Topics>,
}

/// Loads `path`: a vehicle log (replayed with `options`; `progress` is called with
/// `(bytes read, bytes in the file)`) or an estimates file written by `stereonav replay`.
///
/// With [`LoadOptions::map`], the vehicle log is localised on the map instead
/// ([`Model::localization`]); the map is read first. With [`LoadOptions::topics`], the file is
/// a ROS 2 bag read from those topics, its images indexed for the image planes.
///
/// Errors: the file cannot be read or is not MCAP, it is an MCAP file of neither kind, a
/// vehicle message is malformed, or the replay fails (no rig, bad settings); with a map, the
/// map cannot be read or cannot localise, or the file is not a vehicle log; with topics, those
/// of the replay of a bag (a topic the bag does not have, or of another type). A log cut short
/// is shown as far as it goes, with a warning in [`Model::warnings`].
pub fn load(
    path: impl AsRef<Path>,
    options: &LoadOptions,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<Model, Error> {
    let path = path.as_ref();
    // Before the log: a bad map should not wait for a long read.
    let map = options
        .map
        .as_deref()
        .map(|p| map_file::Map::load(p).map(|m| (p, m)))
        .transpose()?;
    if let Some(topics) = &options.topics {
        return load_bag(path, topics, map, options, progress);
    }
    let log = vehicle_log::read_log(path)?;
    if let Some((map_path, map)) = map {
        if !log.has_vehicle_topics() {
            return Err(Error::MapNeedsVehicleLog {
                path: path.to_path_buf(),
                map: map_path.to_path_buf(),
            });
        }
        return localize(path, map_path, &map, &log.records, options, progress);
    }
    if log.has_vehicle_topics() {
        let logged_rig = log.records.iter().find_map(|r| match r {
            Record::Rig(text) => Some(text.as_str()),
            _ => None,
        });
        let rig = match (&options.rig, logged_rig) {
            (Some(rig), _) => Some(rig.clone()),
            (None, Some(text)) => {
                let name = format!("{} /rig", path.display());
                Some(Rig::from_json_str(text, &name)?)
            }
            (None, None) => None,
        };
        let features = decode_features(&log.records);
        let (truth, truth_camera) = truth_of(&log.records);
        let replay = replay::replay_log(path, options.rig.clone(), &options.settings, progress)?;
        let nominal = rig
            .as_ref()
            .map(|r| (r.nominal, [f64::from(r.width), f64::from(r.height)]));
        let mut model = Model::from_replay(
            path.to_path_buf(),
            SourceKind::VehicleLog,
            replay,
            features,
            truth,
            nominal,
            truth_camera,
        );
        model.lens = rig.and_then(|r| r.lens);
        return Ok(model);
    }
    if log
        .ignored_topics
        .iter()
        .any(|t| t == estimates_log::topics::FRAME)
    {
        let replay = estimates_log::read_estimates(path)?;
        let mut model = Model::from_replay(
            path.to_path_buf(),
            SourceKind::Estimates,
            replay,
            Features::default(),
            None,
            None,
            None,
        );
        if options.rig.is_some() {
            model.warnings.push(format!(
                "{}: an estimates file carries its camera estimates: the rig given is not used",
                path.display()
            ));
        }
        return Ok(model);
    }
    Err(Error::NotViewable {
        path: path.to_path_buf(),
        topics: log.ignored_topics,
        truncated: log.truncated,
    })
}

/// The vehicle log at `path` (its records read) run on `map` (read from `map_path`).
fn localize(
    path: &Path,
    map_path: &Path,
    map: &map_file::Map,
    records: &[Record],
    options: &LoadOptions,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<Model, Error> {
    let features = decode_features(records);
    let (truth, _) = truth_of(records);
    // A map imported from a lighting plan may have no rig: then one must be given.
    let rig = options
        .rig
        .clone()
        .or_else(|| map.rig.clone())
        .ok_or_else(|| replay::Error::MapWithoutRig {
            plan: map.source_plan.clone(),
        })?;
    let nominal = (rig.nominal, [f64::from(rig.width), f64::from(rig.height)]);
    let mut frames = Vec::new();
    let end = replay::localize_log(
        path,
        None,
        map,
        options.rig.clone(),
        LocalizerSettings::default(),
        &mut |f| {
            frames.push(*f);
            Ok(())
        },
        progress,
    )?;
    let mut model = Model::from_localization(
        path.to_path_buf(),
        map_path.to_path_buf(),
        frames,
        end,
        features,
        truth,
        nominal,
    );
    model.lens = rig.lens;
    Ok(model)
}

/// The board's stream (the `/fpga/features` chunks concatenated in log order) decoded into
/// features per frame, sorted by the frames' timestamps (as the replay orders them).
fn decode_features(records: &[Record]) -> Features {
    let chunks: Vec<&[u8]> = records
        .iter()
        .filter_map(|r| match r {
            Record::Features { bytes, .. } => Some(bytes.as_slice()),
            _ => None,
        })
        .collect();
    // Pixels of a 4095-pixel image at most: exact in f32.
    let points = |px: &[track::Pixel]| -> Vec<ImagePoint> {
        px.iter().map(|p| [p.u as f32, p.v as f32]).collect()
    };
    let mut frames: Vec<DecodedFrame> = replay::decode_stream(&chunks)
        .0
        .iter()
        .map(|f| (f.t_us, points(&f.left), points(&f.right)))
        .collect();
    // Stable: equal timestamps keep stream order, as in the replay.
    frames.sort_by_key(|(t_us, _, _)| *t_us);
    let mut features = Features::default();
    for (t_us, left, right) in &frames {
        features.push(*t_us, left, right);
    }
    features
}

/// The simulator's truth in a log, and its camera.
fn truth_of(records: &[Record]) -> (Option<Truth>, Option<CameraParams>) {
    let mut truth = TruthCollector::default();
    for r in records {
        truth.record(r);
    }
    truth.finish()
}

/// The simulator's truth as a log's records go by.
#[derive(Debug, Default)]
struct TruthCollector {
    truth: Truth,
    camera: Option<vehicle_log::TruthCamera>,
}

impl TruthCollector {
    fn record(&mut self, r: &Record) {
        match r {
            Record::TruthPose(p) => self.truth.poses.push((p.t_us, [p.x, p.y, p.theta])),
            Record::TruthLandmarks(lamps) if self.truth.lamps.is_empty() => {
                self.truth.lamps = lamps.iter().map(|l| [l.x, l.y, l.z]).collect();
            }
            Record::TruthCamera(c) if self.camera.is_none() => self.camera = Some(*c),
            _ => {}
        }
    }

    /// The truth, if the log has any, and its camera.
    fn finish(mut self) -> (Option<Truth>, Option<CameraParams>) {
        self.truth.poses.sort_by_key(|(t_us, _)| *t_us);
        let truth_camera = self.camera.as_ref().map(replay::truth_camera);
        let any = !self.truth.poses.is_empty() || !self.truth.lamps.is_empty();
        (any.then_some(self.truth), truth_camera)
    }
}

/// What the second pass over a bag found: every frame's features, the truth when the bag
/// carries a simulator's, and where each frame's images are.
struct BagPass {
    features: Features,
    truth: Option<Truth>,
    truth_camera: Option<CameraParams>,
    images: BagImages,
}

/// The ROS 2 bag at `path` with its named `topics`: replayed, or localised on `map` (read from
/// its path), with the second pass over it alongside (see the module docs).
fn load_bag(
    path: &Path,
    topics: &Ros2Topics,
    map: Option<(&Path, map_file::Map)>,
    options: &LoadOptions,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<Model, Error> {
    let nominal_of = |rig: &Rig| (rig.nominal, [f64::from(rig.width), f64::from(rig.height)]);
    if let Some((map_path, map)) = map {
        // As `replay::localize_log` chooses it: the rig given, else the map's.
        let rig = options
            .rig
            .clone()
            .or_else(|| map.rig.clone())
            .ok_or_else(|| replay::Error::MapWithoutRig {
                plan: map.source_plan.clone(),
            })?;
        let mut frames = Vec::new();
        let (end, pass) = alongside_bag_pass(path, topics, &rig, || {
            replay::localize_log(
                path,
                Some(topics),
                &map,
                options.rig.clone(),
                LocalizerSettings::default(),
                &mut |f| {
                    frames.push(*f);
                    Ok(())
                },
                progress,
            )
        });
        let (end, pass) = (end?, pass?);
        let mut model = Model::from_localization(
            path.to_path_buf(),
            map_path.to_path_buf(),
            frames,
            end,
            pass.features,
            pass.truth,
            nominal_of(&rig),
        );
        model.lens = rig.lens;
        set_images(&mut model, pass.images);
        return Ok(model);
    }
    // The replayer reads the bag's start: the rig (given, or the bag's /rig) is known before
    // the second pass needs its size and registers.
    let replayer = replay::Replayer::open_with_topics(
        path,
        Some(topics),
        options.rig.clone(),
        &options.settings,
    )?;
    let rig = replayer.rig().clone();
    let mut collected = ReplayCollector::default();
    let (end, pass) = alongside_bag_pass(path, topics, &rig, || {
        replayer.run(&mut collected, progress)
    });
    let replay = Replay::from_parts(end?, collected.frames, collected.camera, collected.maps);
    let pass = pass?;
    let mut model = Model::from_replay(
        path.to_path_buf(),
        SourceKind::VehicleLog,
        replay,
        pass.features,
        pass.truth,
        Some(nominal_of(&rig)),
        pass.truth_camera,
    );
    model.lens = rig.lens;
    set_images(&mut model, pass.images);
    Ok(model)
}

/// A bag's image index into the model, with a warning when its images cannot be read back.
fn set_images(model: &mut Model, images: BagImages) {
    if let Some(why) = images.unavailable() {
        model.warnings.push(format!(
            "{}: the camera images cannot be shown, {why}: the frames are found through the \
             bag's chunk index (`mcap recover` writes the file again with one)",
            model.path.display()
        ));
    }
    model.images = Some(images);
}

/// Runs `run` (the replay or the localisation) here and the second pass over the bag on
/// another thread at the same time; when `run` fails, the pass is cut short (its result is
/// then of no use).
fn alongside_bag_pass<T>(
    path: &Path,
    topics: &Ros2Topics,
    rig: &Rig,
    run: impl FnOnce() -> Result<T, replay::Error>,
) -> (Result<T, replay::Error>, Result<BagPass, Error>) {
    let stop = AtomicBool::new(false);
    std::thread::scope(|scope| {
        let pass = scope.spawn(|| bag_pass(path, topics, rig, &stop));
        let out = run();
        if out.is_err() {
            stop.store(true, Ordering::Relaxed);
        }
        let pass = pass
            .join()
            .unwrap_or_else(|panic| std::panic::resume_unwind(panic));
        (out, pass)
    })
}

/// The second pass over a bag (see the module docs), as far as it went before `stop` was set.
fn bag_pass(
    path: &Path,
    topics: &Ros2Topics,
    rig: &Rig,
    stop: &AtomicBool,
) -> Result<BagPass, Error> {
    let mut reader = LogReader::open(path)?;
    reader.set_ros2_topics(topics.clone());
    let mut indexer =
        Indexer::new(rig.board_registers()).map_err(|e| replay::Error::HostBoard {
            path: path.to_path_buf(),
            problem: e.to_string(),
        })?;
    let mut truth = TruthCollector::default();
    for record in &mut reader {
        if stop.load(Ordering::Relaxed) {
            break;
        }
        match record? {
            Record::Image(image) => indexer.push(image),
            other => truth.record(&other),
        }
    }
    let summary = match &reader.damage().summary {
        SummaryState::Intact => Ok(()),
        SummaryState::Damaged { why } => {
            Err(format!("the bag's summary section is damaged ({why})"))
        }
        _ => Err(match reader.truncated() {
            Some(why) => format!("the bag has no summary section ({why})"),
            None => "the bag has no summary section".to_owned(),
        }),
    };
    let (frames, images) = indexer.finish(path, topics, [rig.width, rig.height], summary);
    let mut features = Features::default();
    for f in &frames {
        features.push(f.images.t_us, &f.left, &f.right);
    }
    let (truth, truth_camera) = truth.finish();
    Ok(BagPass {
        features,
        truth,
        truth_camera,
        images,
    })
}
