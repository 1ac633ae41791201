//! Issue 6's judgement of phase 2, as seeded Monte Carlo runs on the simulator's paper
//! scenarios (association by lamp id: the filter alone is judged here). Longer runs (1000
//! runs with outliers) are in `examples/phase2_mc.rs`; figures in docs/benchmarks.md.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::Path;

use eval::{RunSettings, Summary, monte_carlo};
use rig_model::Param;

fn scenario(name: &str) -> sim::Scenario {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/scenarios")
        .join(name);
    sim::Scenario::load(&path).unwrap()
}

fn report(s: &Summary) -> String {
    format!(
        "pose NEES {:?} ({:.2} of frames inside), state NEES/dof {:?} ({:.2} inside), NIS {:?}, within 3 sigma {}, healthy {}",
        s.pose_nees,
        s.pose_nees_frames_inside,
        s.state_nees_per_dof,
        s.state_nees_frames_inside,
        s.nis,
        s.within_3_sigma,
        s.healthy
    )
}

/// paper-experiment (five LEDs, straight back and forth, the 19-element state with the
/// baseline), 0.3 px pixel noise, 50 seeds: landmark RMS error at most 2 mm, baseline error at
/// most 0.5 mm, the error inside 3 sigma in at least 95 % of the runs, and the filter
/// consistent: NEES of the pose and of the full state inside their 95 % bands, NIS near 4.
#[test]
fn paper_experiment_meets_the_targets_over_50_seeds() {
    let sc = scenario("paper-experiment.toml");
    let s = monte_carlo(&sc, 0..50, &RunSettings::default()).unwrap();
    let mut squared = Vec::new();
    for r in &s.runs {
        assert_eq!(
            r.landmarks.len(),
            5,
            "seed {}: {:?}",
            r.seed,
            r.lamps_missing
        );
        assert_eq!(r.frames, 961);
        let state = 3 + 3 * 5 + 1;
        assert_eq!(
            r.state_nees.last().unwrap().1,
            state,
            "the 19-element state"
        );
        squared.extend(r.landmarks.iter().map(|l| l.error.norm_squared()));
        let b = r.camera_result(Param::Baseline).unwrap();
        assert!(
            b.error().abs() <= 0.0005,
            "seed {}: baseline error {}",
            r.seed,
            b.error()
        );
    }
    // The landmark RMS error over the 50 runs (every landmark of every run).
    let rms = (squared.iter().sum::<f64>() / squared.len() as f64).sqrt();
    assert!(rms <= 0.002, "landmark RMS {rms}");
    let summary = report(&s);
    assert!(s.within_3_sigma >= 48, "{summary}");
    assert_eq!(s.healthy, 50, "{summary}");
    assert!(s.pose_nees.inside(), "{summary}");
    assert!(s.state_nees_per_dof.inside(), "{summary}");
    assert!((s.nis.value - 4.0).abs() < 0.2, "{summary}");
}

/// paper-square with f and the baseline in the state, started from the rig's nominal values
/// (f 2.5 % low, baseline 2.5 % long): both converge far inside their priors, with honest
/// sigmas (the error inside 3 sigma in at least 95 % of the runs, the pose NEES inside its
/// 95 % band, NIS near 4). The full-state NEES is not held here: started 2.5 % off, the first
/// landmarks are triangulated with the wrong f and the linearisation leaves the joint
/// state over-confident (per dof about 1.4; from the true values 1.09, inside its band):
/// docs/phase2.md.
#[test]
fn paper_square_converges_on_f_and_baseline_with_honest_sigmas() {
    let sc = scenario("paper-square.toml");
    let s = monte_carlo(&sc, 0..20, &RunSettings::default()).unwrap();
    let summary = report(&s);
    assert_eq!(s.healthy, 20, "{summary}");
    for r in &s.runs {
        assert_eq!(
            r.landmarks.len(),
            5,
            "seed {}: {:?}",
            r.seed,
            r.lamps_missing
        );
        let f = r.camera_result(Param::F).unwrap();
        let b = r.camera_result(Param::Baseline).unwrap();
        // Priors (fixtures/scenarios/paper-square.rig.toml): 30 px and 6 mm.
        assert!(
            f.sigma < 30.0 / 100.0 && f.error().abs() < 4.0 * f.sigma,
            "seed {}: {f:?}",
            r.seed
        );
        assert!(
            b.sigma < 0.006 / 100.0 && b.error().abs() < 4.0 * b.sigma,
            "seed {}: {b:?}",
            r.seed
        );
    }
    assert!(s.within_3_sigma >= 19, "{summary}");
    assert!(s.pose_nees.inside(), "{summary}");
    assert!((s.nis.value - 4.0).abs() < 0.2, "{summary}");
}

/// Gross outliers in 5 % of the measurements: the gate rejects them, nothing goes NaN or
/// loses positive definiteness (1000 runs in the example; 100 shortened runs here).
#[test]
fn outliers_never_break_the_filter() {
    let sc = scenario("paper-experiment.toml");
    let settings = RunSettings {
        outlier_fraction: 0.05,
        max_frames: Some(300),
        ..RunSettings::default()
    };
    let s = monte_carlo(&sc, 1000..1100, &settings).unwrap();
    let summary = report(&s);
    assert_eq!(s.healthy, 100, "{summary}");
    let outliers: u64 = s.runs.iter().map(|r| r.outliers).sum();
    let leaked: u64 = s.runs.iter().map(|r| r.outliers_accepted).sum();
    assert!(outliers > 1000, "{outliers}");
    assert!(
        leaked * 100 < outliers,
        "{leaked} of {outliers} outliers accepted"
    );
    for r in &s.runs {
        assert_eq!(r.refused_updates, 0, "seed {}", r.seed);
        assert!(
            r.landmark_rms() < 0.01,
            "seed {}: {}",
            r.seed,
            r.landmark_rms()
        );
    }
}
