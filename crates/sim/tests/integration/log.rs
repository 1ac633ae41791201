//! A log written and read back with vehicle-log equals what was simulated.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failure is the test failing

use crate::common;

use vehicle_log::Record;

#[test]
fn log_reads_back_as_simulated() {
    let s = common::shorten(common::load("warehouse"), 3);
    let run = sim::simulate(&s, sim::Mode::Fast).unwrap();
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("sim-log-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("warehouse.mcap");
    run.write_log(&path).unwrap();
    let log = vehicle_log::read_log(&path).unwrap();
    assert!(log.truncated.is_none() && log.warnings.is_empty());
    let mut odom = Vec::new();
    let mut chunks = Vec::new();
    let mut poses = Vec::new();
    let mut rig = None;
    let mut camera = None;
    let mut landmarks = None;
    let mut last_time = 0u64;
    for r in &log.records {
        match r {
            Record::Odom(o) => {
                assert!(o.t_us * 1000 >= last_time, "odometry in arrival order");
                last_time = o.t_us * 1000;
                odom.push(*o);
            }
            Record::Features { log_time_ns, bytes } => {
                assert!(*log_time_ns >= last_time, "chunks in arrival order");
                last_time = *log_time_ns;
                chunks.push((*log_time_ns, bytes.clone()));
            }
            Record::TruthPose(p) => poses.push(*p),
            Record::Rig(text) => rig = Some(text.clone()),
            Record::TruthCamera(c) => camera = Some(*c),
            Record::TruthLandmarks(l) => landmarks = Some(l.clone()),
            _ => {}
        }
    }
    assert_eq!(odom, run.odometry);
    let expected: Vec<(u64, Vec<u8>)> = run
        .chunks
        .iter()
        .map(|c| (c.log_time_ns, c.bytes.clone()))
        .collect();
    assert_eq!(chunks, expected);
    assert_eq!(poses, run.truth_poses());
    assert_eq!(camera, Some(sim::run::truth_camera(&run.camera)));
    assert_eq!(landmarks, Some(run.truth_landmarks()));
    // The nominal rig, not the truth.
    let rig = rig_model::Rig::from_json_str(&rig.unwrap(), "/rig").unwrap();
    assert_eq!(rig, s.rig);
    assert_ne!(rig.nominal.baseline, run.camera.baseline);
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn rig_and_truth_topics_are_optional() {
    let mut s = common::shorten(common::load("paper-experiment"), 2);
    s.spec.log.rig = false;
    s.spec.log.truth = false;
    let run = sim::simulate(&s, sim::Mode::Fast).unwrap();
    let bytes = run
        .write_log_to(std::io::Cursor::new(Vec::new()))
        .unwrap()
        .into_inner();
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("sim-log-test-opt-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("bare.mcap");
    std::fs::write(&path, bytes).unwrap();
    let log = vehicle_log::read_log(&path).unwrap();
    assert_eq!(log.topics, vec!["/odom", "/fpga/features"]);
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn truth_json_has_trajectory_landmarks_and_camera() {
    let s = common::load("paper-experiment");
    let run = sim::simulate(&s, sim::Mode::Fast).unwrap();
    let v: serde_json::Value = serde_json::from_str(&run.truth_json()).unwrap();
    assert_eq!(v["scenario"], "paper-experiment");
    assert_eq!(v["trajectory"].as_array().unwrap().len(), run.frames.len());
    assert_eq!(v["landmarks"].as_array().unwrap().len(), 5);
    assert_eq!(v["camera"]["baseline"], 0.1164);
    assert_eq!(v["camera"]["f"], 700.0);
    assert_eq!(v["trajectory"][0]["t_us"], run.frames[0].t_us);
    assert_eq!(v["trajectory"][0]["x"], 0.0);
}
