//! The paper experiment's log as the C interface's tests use it: its rig, the board's byte
//! stream and the odometry as logged, and `stereonav replay`'s run of it (the parity
//! reference, and the map it saves).
#![allow(dead_code, clippy::unwrap_used)] // each test binary uses part of it

use std::path::{Path, PathBuf};

use replay::{NavSettings, Replayer};
use rig_model::Rig;
use rig_model::odometry::OdomSample;
use vehicle_log::Record;

/// The repository's root.
pub(crate) fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// `fixtures/logs/paper-experiment.mcap` and its rig.
pub(crate) struct Paper {
    /// The log's path.
    pub(crate) log: PathBuf,
    /// The rig file's path.
    pub(crate) rig_path: PathBuf,
    /// The rig.
    pub(crate) rig: Rig,
    /// The board's byte stream, its chunks concatenated.
    pub(crate) stream: Vec<u8>,
    /// The odometry, in log order.
    pub(crate) odometry: Vec<OdomSample>,
    /// `stereonav replay LOG --rig RIG`, in process.
    pub(crate) end: replay::ReplayEnd,
    /// The map that replay saves (`--save-map`), as bytes.
    pub(crate) map: Vec<u8>,
}

/// Reads and replays the paper experiment.
pub(crate) fn paper() -> Paper {
    let log = root().join("fixtures/logs/paper-experiment.mcap");
    let rig_path = root().join("fixtures/logs/paper-experiment.rig.toml");
    let rig = Rig::load(&rig_path).unwrap();
    let read = vehicle_log::read_log(&log).unwrap();
    let mut stream = Vec::new();
    let mut odometry = Vec::new();
    for r in &read.records {
        match r {
            Record::Features { bytes, .. } => stream.extend_from_slice(bytes),
            Record::Odom(s) => odometry.push(*s),
            _ => {}
        }
    }
    let replayer = Replayer::open(&log, Some(rig.clone()), &NavSettings::default()).unwrap();
    let mut sink = replay::ReplayCollector::default();
    let end = replayer.run(&mut sink, &mut |_, _| {}).unwrap();
    let map = replay::saved_map(&end, &rig, &log).to_bytes().unwrap();
    Paper {
        log,
        rig_path,
        rig,
        stream,
        odometry,
        end,
        map,
    }
}
