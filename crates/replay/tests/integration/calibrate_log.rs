//! Phase 1 on vehicle logs: the committed paper log against the truth it carries, logs with
//! faults the simulator puts in, and inputs that are not vehicle logs.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::{Path, PathBuf};

use replay::{Error, FramePairSettings, NavSettings, RigSource, calibrate_log};
use rig_model::Param;
use selfcal::solve::{SolveStatus, calibrate};
use track::PairSettings;
use vehicle_log::{Record, TruthCamera};

fn fixture(name: &str) -> PathBuf {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/logs")
        .join(name);
    assert!(
        path.exists(),
        "{} is missing: regenerate it as fixtures/README.md says",
        path.display()
    );
    path
}

fn scratch(name: &str) -> PathBuf {
    Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("replay-{name}"))
}

/// The truth a simulated log carries: the camera and the number of stereo frames.
fn truth(path: &Path) -> (TruthCamera, usize) {
    let log = vehicle_log::read_log(path).unwrap();
    let mut camera = None;
    let mut frames = 0;
    for r in log.records {
        match r {
            Record::TruthCamera(c) => camera = Some(c),
            Record::TruthPose(_) => frames += 1,
            _ => {}
        }
    }
    (
        camera.expect("a simulated log carries /truth/camera"),
        frames,
    )
}

/// paper-calibration.mcap with the log's own /rig: the baseline within 1 mm, f within three
/// of its sigmas, every frame decoded.
#[test]
fn paper_calibration_log_gives_f_and_baseline() {
    let path = fixture("paper-calibration.mcap");
    let (true_camera, n_frames) = truth(&path);
    let start = std::time::Instant::now();
    let out = calibrate_log(&path, None, &NavSettings::default()).unwrap();
    println!("{:?}: {:#?}", start.elapsed(), out.counts);
    let cal = &out.calibration;
    let (f, b) = (cal.camera.f, cal.camera.baseline);
    let (sf, sb) = (cal.sigma(Param::F), cal.sigma(Param::Baseline));
    println!(
        "f {f:.3} (truth {}, sigma {sf:.3}), baseline {b:.6} (truth {}, sigma {sb:.6}), warnings {:?}",
        true_camera.f, true_camera.baseline, out.warnings
    );
    assert_eq!(out.rig_source, RigSource::Log);
    assert_eq!(out.counts.frames as usize, n_frames);
    assert_eq!((out.counts.corrupt, out.counts.lost), (0, 0));
    assert!(out.counts.pairs > 50 && out.counts.confirmed_tracks > 0);
    assert_eq!(cal.status, SolveStatus::Converged);
    assert!(out.warnings.is_empty(), "{:?}", out.warnings);
    assert!((b - true_camera.baseline).abs() < 0.001, "baseline {b}");
    assert!((f - true_camera.f).abs() <= 3.0 * sf, "f {f} sigma {sf}");
    // Far better than the nominal values, 3 % off.
    assert!((f - true_camera.f).abs() < (out.rig.nominal.f - true_camera.f).abs() / 5.0);
}

/// The same log with its rig file given: the same calibration, no warning.
#[test]
fn a_given_rig_file_is_used_as_the_log_rig_would_be() {
    let path = fixture("paper-calibration.mcap");
    let rig = rig_model::Rig::load(&fixture("paper-calibration.rig.toml")).unwrap();
    let from_log = calibrate_log(&path, None, &NavSettings::default()).unwrap();
    let given = calibrate_log(&path, Some(rig.clone()), &NavSettings::default()).unwrap();
    assert_eq!(given.rig_source, RigSource::Given);
    assert_eq!(given.calibration, from_log.calibration);
    assert!(given.warnings.is_empty(), "{:?}", given.warnings);
    // A rig that differs from the log's is used, with a warning.
    let mut other = rig;
    other.nominal.f = 690.0;
    let out = calibrate_log(&path, Some(other), &NavSettings::default()).unwrap();
    assert_eq!(out.rig.nominal.f, 690.0);
    assert!(
        out.warnings.iter().any(|w| w.contains("differs")),
        "{:?}",
        out.warnings
    );
}

/// The incremental calibrator reports when the estimate became stable: with the default
/// options (disjoint pairs 40 frames apart, 88 pairs on this log, a solve every 10), the camera
/// at hand-over is already within the accuracy bounds.
#[test]
fn the_hand_over_time_is_reported() {
    let path = fixture("paper-calibration.mcap");
    let (true_camera, _) = truth(&path);
    let options = NavSettings::default();
    let out = calibrate_log(&path, None, &options).unwrap();
    let h = out.handover.as_ref().expect("calibration becomes stable");
    let (t_last, _, _) = *out.history.last().unwrap();
    println!(
        "{} pairs, hand-over at {} us after {} solves: f {} baseline {}",
        out.counts.pairs,
        h.t_us,
        out.history.len(),
        h.camera.f,
        h.camera.baseline
    );
    assert_eq!(
        h.t_us, t_last,
        "the incremental solver stops at the hand-over"
    );
    let rule = options.frame_pairs.stable;
    assert!(out.history.len() * options.frame_pairs.solve_every >= rule.min_pairs);
    assert!(h.t_us < 182_000_000 + 1_000_000, "{}", h.t_us);
    let sf = h.covariance[(Param::F.index(), Param::F.index())].sqrt();
    assert!((h.camera.baseline - true_camera.baseline).abs() < 0.001);
    assert!((h.camera.f - true_camera.f).abs() <= 3.0 * sf);
}

/// A simulated run written as a log, with `edit` applied to the scenario first.
fn simulated_log(name: &str, edit: impl FnOnce(&mut sim::Scenario)) -> (sim::SimRun, PathBuf) {
    let scenario_path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/scenarios")
        .join(format!("{name}.toml"));
    let mut sc = sim::Scenario::load(&scenario_path).unwrap();
    edit(&mut sc);
    let run = sim::simulate(&sc, sim::Mode::Fast).unwrap();
    let path = scratch(&format!("{name}-{}.mcap", std::process::id()));
    run.write_log(&path).unwrap();
    (run, path)
}

/// warehouse: lost packets, bit flips and random chunking on the link. Every good packet is
/// decoded and the faults counted. The baseline (the one estimated parameter) is what phase 1
/// finds with the simulator's lamp ids (the association adds no error). Pairs 10 frames
/// (0.5 s) apart: at 1.5 m/s, frames 2 s apart share few lamps. (An odometry scale error would
/// go into the baseline one to one: `sim/tests/phase1.rs`.)
#[test]
fn a_log_with_link_faults_is_decoded_and_counted() {
    let (run, path) = simulated_log("warehouse", |_| {});
    let options = NavSettings {
        frame_pairs: FramePairSettings {
            pairs: PairSettings {
                stride: 10,
                ..PairSettings::default()
            },
            ..FramePairSettings::default()
        },
        ..NavSettings::default()
    };
    let out = calibrate_log(&path, None, &options).unwrap();
    std::fs::remove_file(&path).ok();
    let sent = run
        .packets
        .iter()
        .filter(|p| p.fate == sim::PacketFate::Sent)
        .count();
    let faulty = run.packets.len() - sent;
    println!(
        "{} packets, {faulty} lost or flipped: {:#?}",
        run.packets.len(),
        out.counts
    );
    assert!(faulty > 0);
    assert_eq!(out.counts.frames as usize, sent);
    assert!(out.counts.corrupt > 0 && out.counts.lost > 0);
    assert!(out.counts.lost as usize <= faulty);
    assert_eq!(out.counts.frames_out_of_order, 0);
    assert!(out.warnings.is_empty(), "{:?}", out.warnings);
    let cal = &out.calibration;
    let (b, sb) = (cal.camera.baseline, cal.sigma(Param::Baseline));
    let by_lamp = calibrate(
        &eval::phase1::frame_pairs_by_lamp(&run, 10),
        &run.rig,
        &run.rig.nominal,
        &options.frame_pairs.solver,
    );
    let b_lamp = by_lamp.camera.baseline;
    println!(
        "baseline {b} sigma {sb}, by lamp id {b_lamp}, truth {}",
        run.camera.baseline
    );
    // The two associations keep slightly different measurements (the tracker skips ambiguous
    // ones): estimates within a sigma or so of each other.
    assert!((b - b_lamp).abs() <= 1.5 * sb, "{b} against {b_lamp}");
    assert!((b - run.camera.baseline).abs() < 0.015 * run.camera.baseline);
}

/// Data time, not arrival: the same log with every odometry sample written after all the
/// features, newest first, gives the same calibration.
#[test]
fn frames_and_odometry_are_ordered_by_their_timestamps() {
    let path = fixture("paper-calibration.mcap");
    let log = vehicle_log::read_log(&path).unwrap();
    let shuffled = scratch(&format!("shuffled-{}.mcap", std::process::id()));
    let mut w = vehicle_log::LogWriter::create(&shuffled).unwrap();
    let mut odometry = Vec::new();
    for r in &log.records {
        match r {
            Record::Rig(text) => w.rig_json(text).unwrap(),
            Record::Features { log_time_ns, bytes } => w.features(*log_time_ns, bytes).unwrap(),
            Record::Odom(s) => odometry.push(*s),
            _ => {}
        }
    }
    for s in odometry.iter().rev() {
        w.odom(s).unwrap();
    }
    w.finish().unwrap();
    let a = calibrate_log(&path, None, &NavSettings::default()).unwrap();
    let b = calibrate_log(&shuffled, None, &NavSettings::default()).unwrap();
    std::fs::remove_file(&shuffled).ok();
    assert_eq!(a.calibration, b.calibration);
    assert_eq!(a.counts, b.counts);
}

/// A log cut short (power lost while recording): calibrated on what was read, with a warning.
#[test]
fn a_truncated_log_is_used_as_far_as_it_goes() {
    let path = fixture("paper-calibration.mcap");
    let bytes = std::fs::read(&path).unwrap();
    let cut = scratch(&format!("cut-{}.mcap", std::process::id()));
    std::fs::write(&cut, &bytes[..bytes.len() * 2 / 3]).unwrap();
    let out = calibrate_log(&cut, None, &NavSettings::default()).unwrap();
    std::fs::remove_file(&cut).ok();
    println!("{:#?} {:?}", out.counts, out.warnings);
    assert!(
        out.warnings.iter().any(|w| w.contains("ends early")),
        "{:?}",
        out.warnings
    );
    assert!(out.counts.frames > 1000 && out.counts.frames < 3641);
    assert!(out.counts.pairs > 0);
}

/// The one-line error contract: the message names the file and the problem.
fn one_line(e: &Error, path: &Path, what: &str) {
    let msg = e.to_string();
    assert!(!msg.contains('\n'), "{msg}");
    assert!(msg.contains(&path.display().to_string()), "{msg}");
    assert!(msg.contains(what), "{msg}");
}

#[test]
fn a_missing_file_is_an_error_naming_it() {
    let path = scratch("no-such-log.mcap");
    let e = calibrate_log(&path, None, &NavSettings::default()).unwrap_err();
    assert!(matches!(e, Error::Log(_)), "{e:?}");
    one_line(&e, &path, "cannot open");
}

#[test]
fn a_text_file_is_not_a_log() {
    let path = scratch(&format!("text-{}.txt", std::process::id()));
    std::fs::write(&path, "t_us,x,y,theta\n0,0,0,0\n").unwrap();
    let e = calibrate_log(&path, None, &NavSettings::default()).unwrap_err();
    std::fs::remove_file(&path).ok();
    assert!(matches!(e, Error::Log(_)), "{e:?}");
    one_line(&e, &path, "not an MCAP file");
}

/// Another tool's MCAP file (ROS 2, with its own /odom): refused, naming its topics. Skipped
/// where the shared data folder is absent (a user's clone).
#[test]
fn a_foreign_mcap_file_is_not_a_vehicle_log() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data/foreign-mcap/nav2_turtlebot.mcap");
    if !path.exists() {
        println!("skipped: {} is absent", path.display());
        return;
    }
    let e = calibrate_log(&path, None, &NavSettings::default()).unwrap_err();
    assert!(matches!(e, Error::NotVehicleLog { .. }), "{e:?}");
    one_line(&e, &path, "not a vehicle log");
    assert!(e.to_string().contains("/tf"), "{e}");
}

/// No rig given and none in the log: refused; with the rig file given it runs. A /rig message
/// missing its keys is refused naming the key.
#[test]
fn a_log_without_a_usable_rig_needs_one_given() {
    let (run, path) = simulated_log("paper-experiment", |sc| sc.spec.log.rig = false);
    let e = calibrate_log(&path, None, &NavSettings::default()).unwrap_err();
    assert!(matches!(e, Error::NoRig { .. }), "{e:?}");
    one_line(&e, &path, "no rig");
    let out = calibrate_log(&path, Some(run.rig.clone()), &NavSettings::default()).unwrap();
    std::fs::remove_file(&path).ok();
    assert_eq!(out.rig_source, RigSource::Given);
    assert!(out.counts.pairs > 0);

    let path = scratch(&format!("bad-rig-{}.mcap", std::process::id()));
    let mut w = vehicle_log::LogWriter::create(&path).unwrap();
    w.rig_json(r#"{"camera": {"width": 752}}"#).unwrap();
    w.odom(&vehicle_log::OdomSample {
        t_us: 0,
        vx: 0.0,
        vy: 0.0,
        vtheta: 0.0,
    })
    .unwrap();
    w.finish().unwrap();
    let e = calibrate_log(&path, None, &NavSettings::default()).unwrap_err();
    std::fs::remove_file(&path).ok();
    assert!(matches!(e, Error::BadRig(_)), "{e:?}");
    one_line(&e, &path, "/rig");
}

/// A vehicle log with odometry but no frames: no error, the nominal values and warnings.
#[test]
fn a_log_without_frames_says_so() {
    let path = scratch(&format!("odom-only-{}.mcap", std::process::id()));
    let rig = rig_model::Rig::load(&fixture("paper-calibration.rig.toml")).unwrap();
    let mut w = vehicle_log::LogWriter::create(&path).unwrap();
    for k in 0..100 {
        w.odom(&vehicle_log::OdomSample {
            t_us: k * 10_000,
            vx: 0.1,
            vy: 0.0,
            vtheta: 0.0,
        })
        .unwrap();
    }
    w.finish().unwrap();
    let out = calibrate_log(&path, Some(rig.clone()), &NavSettings::default()).unwrap();
    std::fs::remove_file(&path).ok();
    assert_eq!(out.calibration.status, SolveStatus::NoData);
    assert_eq!(out.calibration.camera, rig.nominal);
    assert!(
        out.warnings.iter().any(|w| w.contains("no stereo frame")),
        "{:?}",
        out.warnings
    );
}

#[test]
fn bad_options_are_an_error() {
    let path = fixture("paper-calibration.mcap");
    let mut options = NavSettings::default();
    options.frame_pairs.pairs.stride = 0;
    let e = calibrate_log(&path, None, &options).unwrap_err();
    assert!(matches!(e, Error::Settings(_)), "{e:?}");
    assert!(e.to_string().contains("pairs.stride"), "{e}");
}
