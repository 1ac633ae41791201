//! The navigator on the logs of the simulator's four scenarios (the committed paper logs, and
//! the warehouse simulated here): every lamp found, no clutter landmark, the map and the camera
//! parameters within the phase-2 bounds, the trajectory error reported. One seed each, fast;
//! the Monte Carlo over seeds is `examples/replay_mc.rs`.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::print_stderr)]

use std::path::{Path, PathBuf};

use replay::{NavSettings, Replay, replay_log};
use rig_model::Param;

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

/// The camera estimate of the switch's frame: phase 1's hand-over, as phase 2 took it.
fn camera_at_switch(r: &Replay) -> &replay::CameraSample {
    let switch = r.phase_switch_t_us.unwrap();
    r.camera
        .iter()
        .find(|c| c.t_us == switch && c.phase == replay::Phase::Navigating)
        .unwrap()
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

/// The whole method by default on the paper's straight drive: phase 1's batch over every
/// frame hands over within 15 s of motion, and the map (frames of phase 1 included) and the
/// trajectory are in the first frame's world frame, within the paper's bounds.
#[test]
fn paper_experiment_whole_method_by_default() {
    let r = run("paper-experiment.mcap", false);
    let d = describe(&r);
    assert_map_complete(&r, 5);
    let t0 = r.frames.first().unwrap().t_us;
    let switch = r.phase_switch_t_us.expect("phase 1 hands over");
    assert!(switch - t0 <= 15_000_000, "{d}");
    let t = r.truth.as_ref().unwrap();
    assert!(t.landmark_rms <= 0.002, "{d}");
    assert!(t.ate_rms <= 0.010, "{d}");
    let b = camera_error(&r, Param::Baseline);
    assert!(
        b.abs() <= 0.0005 && b.abs() <= 3.0 * sigma(&r, Param::Baseline),
        "{d}"
    );
}

/// A log that ends before phase 1 is stable is still mapped, from the batch of every frame,
/// with the parameters the data did not inform held at nominal and named in a warning: the
/// paper's experiment with a stable rule that cannot fire and a buffer longer than the log.
#[test]
fn a_log_that_ends_in_phase_1_is_still_mapped() {
    let mut settings = NavSettings::default();
    // More frames than the log has: the hand-over can only come from the end of the log.
    settings.phase1.max_frames = 100_000;
    settings.phase1.sigma_fraction = 1e-6;
    let r = replay_log(
        log("paper-experiment.mcap"),
        None,
        &settings,
        &mut |_, _| {},
    )
    .unwrap();
    let d = describe(&r);
    assert_eq!(r.landmarks.len(), 5, "{d}");
    assert!(
        r.warnings
            .iter()
            .any(|w| w.contains("not stable by the end of the log") && w.contains("baseline")),
        "{d}"
    );
    let b = r
        .final_camera
        .iter()
        .find(|c| c.param == Param::Baseline)
        .unwrap();
    // Its prior's sigma, to the rounding of the consider covariance (the batch's hand-over).
    assert!(
        b.value == 0.12 && (b.sigma / 0.006 - 1.0).abs() < 1e-6,
        "held at nominal with its prior: {d}"
    );
    assert!(
        r.frames
            .iter()
            .all(|f| f.phase == replay::Phase::Calibrating)
    );
    // The nominal baseline is 3 % off the truth (3.6 mm), inside its prior's 3 sigma, and the
    // map's scale follows it: about 3 % of the lamps' 2 m range.
    assert!(
        camera_error(&r, Param::Baseline).abs() <= 3.0 * 0.006,
        "{d}"
    );
    assert!(r.truth.as_ref().unwrap().landmark_rms <= 0.1, "{d}");
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

/// paper-calibration, the whole method: phase 1's batch over every frame until stable (within
/// 30 s of motion), the switch, phase 2; the map and the trajectory in the first frame's world
/// frame. The hand-over is held to phase 1's bounds (f within 0.15 %, the baseline within
/// 0.75 mm, both inside 3 sigma). Phase 2 then refines the camera for 150 s with 0.02 m/s
/// odometry, and on this drive it drifts (the baseline by about 3 mm, the landmarks' heights
/// with it): the known weakness of the EKF at realistic odometry noise (docs/phase2.md,
/// issue 15's item 4, still open). The final values are therefore not held to those bounds.
#[test]
fn paper_calibration_hands_over_from_phase_1() {
    let r = run("paper-calibration.mcap", false);
    let d = describe(&r);
    assert_map_complete(&r, 5);
    let switch = r.phase_switch_t_us.unwrap();
    let t0 = r.frames.first().unwrap().t_us;
    assert!(switch - t0 <= 32_000_000, "{d}");
    for f in &r.frames {
        let calibrating = f.phase == replay::Phase::Calibrating;
        assert_eq!(f.t_us < switch, calibrating, "frame at {}", f.t_us);
    }
    let t = r.truth.as_ref().unwrap();
    assert!(t.ate_rms <= 0.010, "{d}");
    let at_switch = camera_at_switch(&r);
    let truth = [
        (Param::F, 721.0, 0.0015 * 721.0),
        (Param::Baseline, 0.1164, 0.00075),
    ];
    for (p, value, bound) in truth {
        let c = at_switch.params.iter().find(|c| c.param == p).unwrap();
        let e = c.value - value;
        assert!(
            e.abs() <= bound && e.abs() <= 3.0 * c.sigma,
            "{p:?} at the switch {c:?}: {d}"
        );
    }
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
    let log_path = crate::scratch_log("navigate-warehouse");
    sim_run.write_log(&log_path).unwrap();
    let settings = NavSettings::default();
    let r = replay_log(&log_path, None, &settings, &mut |_, _| {}).unwrap();
    std::fs::remove_file(&log_path).ok();
    let d = describe(&r);
    let t = r.truth.as_ref().unwrap();
    assert!(r.phase_switch_t_us.is_some(), "{d}");
    assert_eq!(t.lamps_missed, 0, "{d}");
    assert_eq!(t.landmarks_unmatched, 0, "{d}");
    assert!(t.landmarks_matched > 150, "{d}");
    assert!(t.landmark_rms_aligned <= 0.005, "{d}");
    // No --stride any more: phase 1 hands over within seconds at 1.5 m/s, and the trajectory
    // is in the first frame's world frame.
    let t0 = r.frames.first().unwrap().t_us;
    assert!(r.phase_switch_t_us.unwrap() - t0 <= 30_000_000, "{d}");
    assert!(t.ate_rms <= 0.040, "{d}");
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
    let at_switch = camera_at_switch(&r);
    assert_eq!(at_switch.params, r.final_camera, "{d}");
    for p in [Param::F, Param::Baseline] {
        assert!(
            camera_error(&r, p).abs() <= 3.0 * sigma(&r, p),
            "{p:?}: {d}"
        );
    }
}

/// The whole method, no flag, over seeds of a scenario with realistic odometry (0.02 m/s per
/// sample): every lamp mapped and nothing else, the map, trajectory and camera within the
/// issue's bounds, and honest: every estimated camera parameter and at least 90 % of the
/// landmarks inside 3 sigma, the full-state NEES per degree of freedom near 1 (the 20-seed
/// Monte Carlo with the 95 % bands is `examples/replay_mc.rs`).
fn whole_method_is_honest(
    scenario: &str,
    seeds: u64,
    switch_after_motion_s: f64,
    landmark_rms_bound: f64,
) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/scenarios")
        .join(scenario);
    let sc = sim::Scenario::load(&path).unwrap();
    let log_path = crate::scratch_dir().join(format!(
        "navigate-honest-{}-{scenario}.mcap",
        std::process::id()
    ));
    let (mut inside, mut total, mut nees, mut dof) = (0usize, 0usize, 0.0, 0usize);
    for seed in 0..seeds {
        let sim_run = sim::simulate(&sc.clone().with_seed(seed), sim::Mode::Fast).unwrap();
        sim_run.write_log(&log_path).unwrap();
        let r = replay_log(&log_path, None, &NavSettings::default(), &mut |_, _| {}).unwrap();
        let d = format!("{scenario} seed {seed}: {}", describe(&r));
        let t = r.truth.as_ref().unwrap();
        assert_eq!(t.lamps_missed, 0, "{d}");
        assert_eq!(t.landmarks_unmatched, 0, "{d}");
        // With 0.02 m/s odometry the data allow 3-5 mm landmark RMS over runs (the batch
        // reference over the same frames with the truth's association is as far:
        // docs/benchmarks.md, "Phase 2 re-linearised"); the bound is the drive's.
        assert!(t.landmark_rms <= landmark_rms_bound, "{d}");
        assert!(t.ate_rms <= 0.010, "{d}");
        let moving = sim_run
            .odometry_truth
            .iter()
            .find(|s| s.vx.abs() + s.vy.abs() > 1e-3 || s.vtheta.abs() > 1e-3)
            .unwrap()
            .t_us;
        let switch = r.phase_switch_t_us.unwrap();
        assert!(
            switch.saturating_sub(moving) as f64 * 1e-6 <= switch_after_motion_s,
            "{d}"
        );
        for p in &sc.rig.estimate {
            assert!(
                camera_error(&r, *p).abs() <= 3.0 * sigma(&r, *p),
                "{p:?}: {d}"
            );
        }
        for l in &r.landmarks {
            let p = nalgebra::Vector3::from(l.position);
            let lamp = sim_run
                .landmarks
                .iter()
                .min_by(|a, b| (a.position - p).norm().total_cmp(&(b.position - p).norm()))
                .unwrap();
            let e = p - lamp.position;
            let cov = nalgebra::Matrix3::from_fn(|i, j| l.covariance[i][j]);
            total += 1;
            inside += usize::from(e.dot(&(cov.try_inverse().unwrap() * e)) <= 14.16);
        }
        let c = t.consistency.unwrap();
        nees += c.state_nees;
        dof += c.state_dof;
    }
    std::fs::remove_file(&log_path).ok();
    assert!(
        10 * inside >= 9 * total,
        "{scenario}: {inside} of {total} inside 3 sigma"
    );
    let per_dof = nees / dof as f64;
    assert!(
        (0.7..=1.4).contains(&per_dof),
        "{scenario}: full-state NEES per dof {per_dof:.3} over {dof} dof"
    );
}

#[test]
fn realistic_odometry_paper_experiment_is_honest() {
    whole_method_is_honest("paper-experiment-realistic.toml", 10, 15.0, 0.010);
}

#[test]
fn realistic_odometry_paper_square_is_honest() {
    whole_method_is_honest("paper-square-realistic.toml", 10, 30.0, 0.010);
}

#[test]
fn realistic_odometry_paper_calibration_is_honest() {
    // The slow drive informs the scale least: the lamps' heights have sigma 7 mm at the end, and
    // a run whose baseline is 2 sigma off has its map 16 mm high.
    whole_method_is_honest("paper-calibration.toml", 10, 30.0, 0.025);
}

/// The issue's third kind of drive: a 40-lamp aisle at 1 m/s with 0.02 m/s odometry, clutter
/// and a lossy link, no flags: at least 90 % of its lamps mapped and no clutter landmark, the
/// map within 20 mm and the trajectory within 40 mm (RMS, the first frame's world), the
/// baseline inside 3 sigma.
#[test]
fn the_aisle_maps_within_the_issue_bounds() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/scenarios/aisle.toml");
    let sc = sim::Scenario::load(&path).unwrap();
    let sim_run = sim::simulate(&sc, sim::Mode::Fast).unwrap();
    let log_path = crate::scratch_log("navigate-aisle");
    sim_run.write_log(&log_path).unwrap();
    let r = replay_log(&log_path, None, &NavSettings::default(), &mut |_, _| {}).unwrap();
    std::fs::remove_file(&log_path).ok();
    let d = describe(&r);
    let t = r.truth.as_ref().unwrap();
    assert!(t.landmarks_matched >= 36, "{d}");
    assert_eq!(t.landmarks_unmatched, 0, "{d}");
    assert!(t.landmark_rms <= 0.020, "{d}");
    assert!(t.ate_rms <= 0.040, "{d}");
    assert!(
        camera_error(&r, Param::Baseline).abs() <= 3.0 * sigma(&r, Param::Baseline),
        "{d}"
    );
    assert!(r.counts.corrupt > 0 || r.counts.lost > 0, "{d}");
}
