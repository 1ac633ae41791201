//! The navigator on the logs of the simulator's four scenarios (the committed paper logs, and
//! the warehouse simulated here): every lamp found, no clutter landmark, the map and the camera
//! parameters within the phase-2 bounds, the trajectory error reported. One seed each, fast;
//! the Monte Carlo over seeds is `examples/replay_mc.rs`.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::print_stderr)]

use std::path::{Path, PathBuf};

use calib::Param;
use replay::{NavSettings, Replay, replay_log};

fn log(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/logs")
        .join(name)
}

fn run(name: &str, skip_phase1: bool) -> Replay {
    let settings = NavSettings {
        skip_phase1,
        ..NavSettings::default()
    };
    replay_log(log(name), None, &settings, &mut |_, _| {}).unwrap()
}

fn camera_error(r: &Replay, p: Param) -> f64 {
    r.truth
        .as_ref()
        .unwrap()
        .camera
        .iter()
        .find(|(q, _)| *q == p)
        .unwrap()
        .1
}

fn sigma(r: &Replay, p: Param) -> f64 {
    r.final_camera.iter().find(|c| c.param == p).unwrap().sigma
}

/// Every lamp in view found, every landmark a lamp, the trajectory error reported.
fn assert_map_complete(r: &Replay, lamps: usize) {
    let d = describe(r);
    let t = r.truth.as_ref().unwrap();
    assert_eq!(t.lamps_missed, 0, "{d}");
    assert_eq!(t.landmarks_unmatched, 0, "{d}");
    assert_eq!(t.landmarks_matched, lamps, "{d}");
    assert_eq!(r.landmarks.len(), lamps, "{d}");
    assert!(t.ate_rms.is_finite() && t.ate_max >= t.ate_rms, "{d}");
    assert!(r.warnings.is_empty(), "{d}");
}

fn describe(r: &Replay) -> String {
    format!(
        "truth {:?}, switch {:?}, landmarks {}, camera {:?}, warnings {:?}",
        r.truth,
        r.phase_switch_t_us,
        r.landmarks.len(),
        r.final_camera
            .iter()
            .filter(|p| p.sigma > 0.0)
            .collect::<Vec<_>>(),
        r.warnings
    )
}

/// paper-experiment as in the paper (phase 2 from the rig's priors; phase 1 has too few frame
/// pairs in 48 s to become stable): the five LEDs within the phase-2 bounds.
#[test]
fn paper_experiment_with_phase_1_skipped() {
    let r = run("paper-experiment.mcap", true);
    let d = describe(&r);
    assert_map_complete(&r, 5);
    let t = r.truth.as_ref().unwrap();
    assert!(t.landmark_rms <= 0.002, "{d}");
    let b = camera_error(&r, Param::Baseline);
    assert!(b.abs() <= 0.0005, "{d}");
    assert!(b.abs() <= 3.0 * sigma(&r, Param::Baseline), "{d}");
    assert_eq!(r.phase_switch_t_us, None);
    assert!(r.phase1_skipped);
}

/// Without skipping, phase 1 never becomes stable on it: said in a warning, no map, no panic.
#[test]
fn paper_experiment_without_a_stable_phase_1_says_so() {
    let r = run("paper-experiment.mcap", false);
    assert_eq!(r.phase_switch_t_us, None);
    assert!(r.landmarks.is_empty());
    assert!(
        r.warnings
            .iter()
            .any(|w| w.contains("phase 1 never became stable")),
        "{:?}",
        r.warnings
    );
    assert!(
        r.frames
            .iter()
            .all(|f| f.phase == replay::Phase::Calibrating)
    );
}

/// paper-square, f and baseline in the state from 2.5 % off: within the phase-2 bounds and
/// their sigmas.
#[test]
fn paper_square_with_phase_1_skipped() {
    let r = run("paper-square.mcap", true);
    let d = describe(&r);
    assert_map_complete(&r, 5);
    assert!(r.truth.as_ref().unwrap().landmark_rms <= 0.002, "{d}");
    for p in [Param::F, Param::Baseline] {
        assert!(
            camera_error(&r, p).abs() <= 3.0 * sigma(&r, p),
            "{p:?}: {d}"
        );
    }
    assert!(camera_error(&r, Param::Baseline).abs() <= 0.0005, "{d}");
}

/// paper-calibration, the whole method: phase 1 until stable, the switch, phase 2. The map is
/// anchored at the dead-reckoned pose of the switch (165 s of odometry), so its absolute error
/// is that pose's. The camera parameters are held to phase 1's bounds (f within 0.15 %, the
/// baseline within 0.75 mm, docs/phase1.md) and the map's shape to 20 mm. This seed meets
/// them; over 20 seeds phase 2 does not (the baseline's median error grows to 1.2 mm after the
/// switch, a known weakness of the EKF on this drive: docs/navigator.md and docs/phase2.md).
#[test]
fn paper_calibration_hands_over_from_phase_1() {
    let r = run("paper-calibration.mcap", false);
    let d = describe(&r);
    assert_map_complete(&r, 5);
    let switch = r.phase_switch_t_us.unwrap();
    for f in &r.frames {
        let calibrating = f.phase == replay::Phase::Calibrating;
        assert_eq!(f.t_us < switch, calibrating, "frame at {}", f.t_us);
    }
    let t = r.truth.as_ref().unwrap();
    assert!(t.landmark_rms_aligned <= 0.020, "{d}");
    assert!(camera_error(&r, Param::F).abs() <= 0.0015 * 721.0, "{d}");
    assert!(camera_error(&r, Param::Baseline).abs() <= 0.00075, "{d}");
    // Phase 1's estimates are in the camera history before the switch.
    assert!(
        r.camera
            .iter()
            .any(|c| c.phase == replay::Phase::Calibrating)
    );
}

/// warehouse: 410 lamps, a 296 m loop at up to 1.5 m/s, clutter, a lossy link. Phase 1 with
/// pairs 10 frames apart (lamps leave the view within 2 s at that speed), then phase 2 maps
/// every lamp it passes, with no clutter landmark and no duplicate.
#[test]
fn warehouse_maps_every_lamp_it_passes() {
    let path =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/scenarios/warehouse.toml");
    let sc = sim::Scenario::load(&path).unwrap();
    let sim_run = sim::simulate(&sc, sim::Mode::Fast).unwrap();
    let log_path =
        std::env::temp_dir().join(format!("navigate-warehouse-{}.mcap", std::process::id()));
    sim_run.write_log(&log_path).unwrap();
    let mut settings = NavSettings::default();
    settings.pairs.stride = 10;
    let r = replay_log(&log_path, None, &settings, &mut |_, _| {}).unwrap();
    std::fs::remove_file(&log_path).ok();
    let d = describe(&r);
    let t = r.truth.as_ref().unwrap();
    assert!(r.phase_switch_t_us.is_some(), "{d}");
    assert_eq!(t.lamps_missed, 0, "{d}");
    assert_eq!(t.landmarks_unmatched, 0, "{d}");
    assert!(t.landmarks_matched > 150, "{d}");
    assert!(t.landmark_rms_aligned <= 0.005, "{d}");
    assert!(camera_error(&r, Param::Baseline).abs() <= 0.0005, "{d}");
    assert!(r.counts.corrupt > 0 && r.counts.lost > 0, "{d}");
}

/// The same drive with the camera parameters only considered in phase 2: they stay exactly
/// what phase 1 handed over, with its sigmas, and the map is complete.
#[test]
fn paper_calibration_with_the_camera_considered_keeps_the_hand_over() {
    let mut settings = NavSettings::default();
    settings.ekf.camera_update = vslam_ekf::CameraUpdate::Consider;
    let r = replay_log(
        log("paper-calibration.mcap"),
        None,
        &settings,
        &mut |_, _| {},
    )
    .unwrap();
    let d = describe(&r);
    assert_map_complete(&r, 5);
    let switch = r.phase_switch_t_us.unwrap();
    let at_switch = r
        .camera
        .iter()
        .find(|c| c.t_us == switch && c.phase == replay::Phase::Navigating)
        .unwrap();
    assert_eq!(at_switch.params, r.final_camera, "{d}");
    for p in [Param::F, Param::Baseline] {
        assert!(
            camera_error(&r, p).abs() <= 3.0 * sigma(&r, p),
            "{p:?}: {d}"
        );
    }
}
