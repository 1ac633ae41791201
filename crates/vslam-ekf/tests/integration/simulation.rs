//! End to end on the simulator's paper experiment (Fig. 9: five LEDs, straight back and forth,
//! only the baseline estimated, 19 states): lamp ids stand in for the association's track ids,
//! the odometry is the logged one, the filter starts from the rig's priors.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::Path;

use rig_model::Param;
use vslam_ekf::{CandidateSettings, Candidates, Ekf, Settings};

fn scenario(name: &str) -> sim::Scenario {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/scenarios")
        .join(name);
    sim::Scenario::load(&path).unwrap()
}

struct Outcome {
    run: sim::SimRun,
    ekf: Ekf,
    candidates: Candidates,
    /// Largest pose error over the run, metres, and its largest Mahalanobis distance.
    worst_pose_m: f64,
}

fn run_filter(sc: &sim::Scenario) -> Outcome {
    let run = sim::simulate(sc, sim::Mode::Fast).unwrap();
    let odometry = run.odometry.clone();
    let mut ekf = Ekf::from_prior(&run.rig, Settings::default()).unwrap();
    let mut candidates = Candidates::new(CandidateSettings::default()).unwrap();
    let mut last_t = None;
    let mut worst_pose_m: f64 = 0.0;
    for frame in &run.frames {
        if let Some(t0) = last_t {
            ekf.predict_odometry(&odometry, t0, frame.t_us).unwrap();
        }
        last_t = Some(frame.t_us);
        let mut meas: Vec<(u64, rig_model::Measurement)> = frame
            .lamp_measurements()
            .into_iter()
            .map(|(lamp, z)| (u64::from(lamp), z))
            .collect();
        meas.sort_by_key(|(t, _)| *t);
        candidates.observe(&mut ekf, &meas).unwrap();
        let pose = ekf.pose();
        let err = ((pose.x - frame.pose.x).powi(2) + (pose.y - frame.pose.y).powi(2)).sqrt();
        worst_pose_m = worst_pose_m.max(err);
    }
    Outcome {
        run,
        ekf,
        candidates,
        worst_pose_m,
    }
}

fn report(o: &Outcome) -> String {
    let mut s = String::new();
    for (track, id) in o.candidates.bindings() {
        let lm = o.ekf.landmark(id).unwrap();
        let truth = o.run.landmarks[track as usize].position;
        let e = lm.position - truth;
        let sig = lm.covariance.diagonal().map(f64::sqrt);
        s += &format!(
            "lamp {track}: error {:.4} {:.4} {:.4} m, sigma {:.4} {:.4} {:.4}, obs {}\n",
            e.x, e.y, e.z, sig.x, sig.y, sig.z, lm.observations
        );
    }
    let cov = o.ekf.camera_covariance();
    let b = Param::Baseline.index();
    s += &format!(
        "baseline {:.5} (truth {:.5}, nominal {:.5}) sigma {:.5}; pose error worst {:.4} m\n{:?}\n",
        o.ekf.camera().baseline,
        o.run.camera.baseline,
        o.run.rig.nominal.baseline,
        cov[(b, b)].sqrt(),
        o.worst_pose_m,
        o.ekf.health()
    );
    s
}

/// The scenario as it stands (odometry with white noise only): every lamp within a few mm and
/// inside 3 sigma, the baseline from 3 % off to within 3 sigma of the truth, no clutter in the
/// map, a healthy NIS.
#[test]
fn paper_experiment_converges() {
    let sc = scenario("paper-experiment.toml");
    let o = run_filter(&sc);
    let text = report(&o);
    assert_eq!(o.ekf.landmark_count(), 5, "{text}");
    assert_eq!(o.candidates.bindings().count(), 5, "{text}");
    for (track, id) in o.candidates.bindings() {
        let lm = o.ekf.landmark(id).unwrap();
        let e = lm.position - o.run.landmarks[track as usize].position;
        for k in 0..3 {
            let sigma = lm.covariance[(k, k)].sqrt();
            assert!(e[k].abs() <= 3.0 * sigma, "lamp {track} axis {k}\n{text}");
        }
        assert!(e.norm() < 0.01, "lamp {track}: {e}\n{text}");
    }
    let b = o.ekf.camera().baseline;
    let sigma_b =
        o.ekf.camera_covariance()[(Param::Baseline.index(), Param::Baseline.index())].sqrt();
    assert!((b - o.run.camera.baseline).abs() <= 3.0 * sigma_b, "{text}");
    assert!(o.worst_pose_m < 0.03, "{text}");
    let h = o.ekf.health();
    assert!(!h.diverged, "{text}");
    assert_eq!(h.refused_updates, 0);
    assert_eq!(h.landmarks_removed, 0);
}

/// With a 1 % odometry scale error and a yaw-rate bias (a vehicle whose odometry was never
/// calibrated), the only metric scale of the run is 1 % wrong and so is the baseline: it still
/// moves from 3 % off toward the truth, and the map holds the five lamps and nothing else.
#[test]
fn paper_experiment_with_biased_odometry_moves_toward_the_truth() {
    let mut sc = scenario("paper-experiment.toml");
    sc.spec.noise.velocity_scale_error = 0.01;
    sc.spec.noise.yaw_rate_bias_radps = 0.002;
    let o = run_filter(&sc);
    let text = report(&o);
    assert_eq!(o.ekf.landmark_count(), 5, "{text}");
    let (b, truth, nominal) = (
        o.ekf.camera().baseline,
        o.run.camera.baseline,
        o.run.rig.nominal.baseline,
    );
    assert!((b - truth).abs() < 0.5 * (nominal - truth).abs(), "{text}");
    assert_eq!(o.ekf.health().refused_updates, 0);
}
