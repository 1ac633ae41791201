//! Loading a file into a [`Model`]: a vehicle log is replayed through the stack
//! (`replay::replay_log`), or run on a saved map (`replay::localize_log`, with
//! [`LoadOptions::map`]), and its board stream decoded again for the features of every frame;
//! an estimates file is read back (`estimates_log::read_estimates`).

use std::path::{Path, PathBuf};

use replay::{LocalizerSettings, NavSettings};
use rig_model::camera::CameraParams;
use rig_model::config::Rig;
use vehicle_log::Record;

use crate::Error;
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
}

/// Loads `path`: a vehicle log (replayed with `options`; `progress` is called with
/// `(bytes read, bytes in the file)`) or an estimates file written by `stereonav replay`.
///
/// With [`LoadOptions::map`], the vehicle log is localised on the map instead
/// ([`Model::localization`]); the map is read first.
///
/// Errors: the file cannot be read or is not MCAP, it is an MCAP file of neither kind, a
/// vehicle message is malformed, or the replay fails (no rig, bad settings); with a map, the
/// map cannot be read or cannot localise, or the file is not a vehicle log. A log cut short
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
    let mut truth = Truth::default();
    let mut camera = None;
    for r in records {
        match r {
            Record::TruthPose(p) => truth.poses.push((p.t_us, [p.x, p.y, p.theta])),
            Record::TruthLandmarks(lamps) if truth.lamps.is_empty() => {
                truth.lamps = lamps.iter().map(|l| [l.x, l.y, l.z]).collect();
            }
            Record::TruthCamera(c) if camera.is_none() => camera = Some(*c),
            _ => {}
        }
    }
    truth.poses.sort_by_key(|(t_us, _)| *t_us);
    let truth_camera = camera.as_ref().map(replay::truth_camera);
    let any = !truth.poses.is_empty() || !truth.lamps.is_empty();
    (any.then_some(truth), truth_camera)
}
