//! Odometry as real wheels give it (issue 36): errors with memory, a first-order Gauss-Markov
//! process of 0.6 s (vehicle-interfaces.md section 2), in the real vehicle's aisle
//! (`fixtures/scenarios/aisle-vehicle-slip.toml`: odometry scale, yaw scale and bias, clock
//! offset, all estimated from priors). With the time constants in the rig file the map and the
//! calibration are right and honest; with the rig file silent the navigator sees from the
//! batch's residuals that the odometry is worse than stated, widens its model and says so;
//! a standing vehicle does not make phase 1 stable; a parameter pulled far from its nominal
//! value is named.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use replay::NavSettings;

use crate::{Run, assert_nine_in_ten_inside, hall_scenario, parameters, replayed_run, scenario};
use rig_model::Param;

/// The rig file silent about the odometry's memory (its time constants 0).
fn silent(mut sc: sim::Scenario) -> sim::Scenario {
    sc.rig.noise.velocity_tau = 0.0;
    sc.rig.noise.yaw_rate_tau = 0.0;
    sc
}

/// One pass of the aisle there and back (53 s), not two.
fn one_pass(mut sc: sim::Scenario) -> sim::Scenario {
    sc.spec.path.repeat = 1;
    sc
}

fn run(sc: &sim::Scenario, seed: u64, tag: &str) -> Run {
    run_with(sc, seed, tag, &NavSettings::default())
}

fn run_with(sc: &sim::Scenario, seed: u64, tag: &str, settings: &NavSettings) -> Run {
    replayed_run(
        &sc.clone().with_seed(seed),
        &format!("slip-{tag}-{seed}"),
        settings,
    )
}

#[test]
fn slipping_wheels_stated_in_the_rig_file_give_an_honest_map() {
    let sc = one_pass(scenario("aisle-vehicle-slip.toml"));
    assert_eq!(sc.rig.noise.velocity_tau, 0.6);
    let r = run(&sc, 0, "stated");
    let t = r.replay.truth.as_ref().unwrap();
    let d = format!("{t:?}");
    assert_eq!(t.lamps_missed, 0, "{d}");
    assert_eq!(t.landmarks_duplicate, 0, "{d}");
    assert!(t.landmark_rms <= 0.025 && t.ate_rms <= 0.06, "{d}");
    assert!(
        10 * r.inside >= 9 * r.near && r.near >= 38,
        "{} of {} inside 3 sigma",
        r.inside,
        r.near
    );
    for (p, error, sigma) in parameters(&r.replay) {
        assert!(
            error.abs() <= 3.0 * sigma,
            "{p}: {error} against sigma {sigma}; {d}"
        );
    }
    // As stated: the model is not widened.
    let o = r.replay.odometry.unwrap();
    assert_eq!(o.widened, None);
    assert_eq!(o.stated, [0.02, 0.01, 0.6, 0.6]);
    assert_eq!(o.used, [0.02, 0.01]);
}

#[test]
fn slipping_wheels_the_rig_file_is_silent_about_are_seen_and_said() {
    let sc = silent(one_pass(scenario("aisle-vehicle-slip.toml")));
    let r = run(&sc, 1, "silent");
    let o = r.replay.odometry.unwrap();
    let w = o.widened.expect("the odometry's model widened");
    // Errors of 0.6 s memory at 100 Hz stated as white: about 120 times the variance over
    // long spans, about 60 over a second.
    let (kt, kh) = (w.variance_factors[0], w.variance_factors[1]);
    assert!(
        (20.0..=600.0).contains(&kt) && (20.0..=600.0).contains(&kh),
        "{w:?}"
    );
    assert!((o.used[0] / 0.02 - kt.sqrt()).abs() < 1e-9);
    assert!(
        r.replay
            .warnings
            .iter()
            .any(|m| m.starts_with("the odometry is worse than the rig file states")),
        "{:?}",
        r.replay.warnings
    );
    let t = r.replay.truth.as_ref().unwrap();
    let d = format!("{t:?}");
    assert_eq!(t.lamps_missed, 0, "{d}");
    assert!(t.landmarks_unmatched * 20 <= t.landmarks_matched, "{d}");
    assert_nine_in_ten_inside(&r);
    let baseline = parameters(&r.replay)
        .into_iter()
        .find(|(p, _, _)| *p == Param::Baseline)
        .unwrap();
    assert!(baseline.1.abs() <= 3.0 * baseline.2, "{baseline:?}");
}

/// The same drive with white odometry as stated: no widening (the check does not fire on
/// odometry as good as its rig file says).
#[test]
fn odometry_as_good_as_stated_is_not_widened() {
    let sc = one_pass(scenario("aisle-vehicle.toml"));
    for seed in 0..2 {
        let r = run(&sc, seed, "white");
        assert_eq!(r.replay.odometry.unwrap().widened, None, "seed {seed}");
    }
    // Nor from a short phase 1, whose batch and phase 2's own check see a few windows only
    // (the dense hall of `a_short_phase_1_still_sees_the_odometry_s_memory`, white).
    let mut settings = NavSettings::default();
    settings.phase1.max_frames = 150;
    let sc = sim::hall::scenario(&sim::hall::HallSpec::draw(18), 18).unwrap();
    let r = run_with(&sc, 18, "white-short", &settings);
    assert_eq!(r.replay.odometry.unwrap().widened, None);
}

/// A vehicle that stands for 20 s before it drives, with a rig that estimates only what a
/// standing vehicle seems to inform (the yaw-rate bias) and what it cannot (the yaw scale and
/// the clock offset, structurally): phase 1 does not call itself stable before the vehicle has
/// moved.
#[test]
fn a_standing_vehicle_does_not_make_phase_1_stable() {
    let mut sc = scenario("aisle-vehicle.toml");
    sc.spec.path.repeat = 1;
    sc.spec.path.segments.truncate(2);
    if let Some(wait) = sc.spec.path.segments.first_mut() {
        wait.duration_s = Some(20.0);
    }
    sc.rig.estimate = vec![Param::OdomYawScale, Param::OdomYawBias, Param::TimeOffset];
    for p in [Param::Baseline, Param::OdomScale] {
        sc.rig.prior[p.index()] = None;
    }
    let sim_run = sim::simulate(&sc.clone().with_seed(0), sim::Mode::Fast).unwrap();
    let moving = sim_run
        .odometry_truth
        .iter()
        .find(|s| s.vx.abs() > 0.05)
        .unwrap()
        .t_us;
    let log = crate::scratch_log("standing");
    sim_run.write_log(&log).unwrap();
    let r = replay::replay_log(&log, None, &NavSettings::default(), &mut |_, _| {}).unwrap();
    std::fs::remove_file(&log).ok();
    let switch = r.phase_switch_t_us.expect("phase 2 ran");
    // 0.5 m at up to 0.5 m/s^2 takes 1.4 s; the board's clock is 12 ms ahead.
    assert!(
        switch >= moving + 1_000_000,
        "phase 1 ended at {switch} us, the vehicle moved at {moving} us"
    );
}

/// A yaw-rate bias ten times the rig file's nominal-plus-prior (0.02 rad/s against 0 +- 0.005):
/// the estimate goes there, and the warning names it.
#[test]
fn a_parameter_pulled_far_from_its_nominal_value_is_named() {
    let mut sc = one_pass(scenario("aisle-vehicle.toml"));
    sc.spec.noise.yaw_rate_bias_radps = 0.02;
    let r = run(&sc, 0, "pulled");
    assert!(
        r.replay
            .warnings
            .iter()
            .any(|m| m.starts_with("odom_yaw_bias ended") && m.contains("prior sigmas")),
        "{:?}",
        r.replay.warnings
    );
    assert!(
        !r.replay
            .warnings
            .iter()
            .any(|m| m.starts_with("baseline ended")),
        "{:?}",
        r.replay.warnings
    );
}

/// The judgement over six seeds of the whole drive (two passes), the rig file stating
/// the memory and silent about it.
#[test]
fn slow_slipping_wheels_over_many_seeds() {
    for (sc, tag) in [
        (scenario("aisle-vehicle-slip.toml"), "stated"),
        (silent(scenario("aisle-vehicle-slip.toml")), "silent"),
    ] {
        let (mut near, mut inside, mut matched, mut unmatched, mut outside) =
            (0, 0, 0, 0, Vec::new());
        for seed in 0..6 {
            let r = run(&sc, seed, tag);
            let t = r.replay.truth.as_ref().unwrap();
            let d = format!("{tag} seed {seed}: {t:?}");
            assert_eq!(t.lamps_missed, 0, "{d}");
            assert_eq!(t.landmarks_duplicate, 0, "{d}");
            near += r.near;
            inside += r.inside;
            matched += t.landmarks_matched;
            unmatched += t.landmarks_unmatched;
            if tag == "stated" {
                assert!(t.landmark_rms <= 0.025 && t.ate_rms <= 0.06, "{d}");
            }
            for (p, error, sigma) in parameters(&r.replay) {
                if p == Param::Baseline {
                    assert!(error.abs() <= 0.001, "{d}");
                }
                if error.abs() > 3.0 * sigma {
                    outside.push(format!("{tag} seed {seed}: {p} {error} sigma {sigma}"));
                }
            }
        }
        assert!(
            10 * inside >= 9 * near,
            "{tag}: {inside} of {near} inside 3 sigma"
        );
        assert!(
            unmatched * 20 <= matched,
            "{tag}: {unmatched} spurious, {matched} matched"
        );
        assert!(outside.is_empty(), "{outside:?}");
    }
}

/// `sim::hall`'s hall 18 (lamps every 2.5 m, no dark stretch) through `lens`, its odometry's
/// errors of 0.6 s memory unstated in the rig file, replayed with `settings`.
fn dense_hall_silent_with(lens: sim::hall::HallLens, settings: &NavSettings) -> Run {
    let mut sc = hall_scenario(18, lens);
    (sc.spec.noise.velocity_tau_s, sc.spec.noise.yaw_rate_tau_s) = (0.6, 0.6);
    let tag = format!("dense-{lens:?}-{}", settings.phase1.max_frames);
    run_with(&silent(sc), 18, &tag, settings)
}

/// The same, replayed with no flags.
fn dense_hall_silent(lens: sim::hall::HallLens) -> Run {
    dense_hall_silent_with(lens, &NavSettings::default())
}

/// The dense hall again, phase 1 cut to 150 frames (`stereonav replay --phase1-frames 150`):
/// it hands over at 8.5 s, before the batch's check had the 8 one-second windows a marginal
/// ratio needs. The model was never widened and the run was confidently wrong (27.8 m, the
/// yaw scale at 149 %). The heading's ratio (59 over 4 windows at 5 s, where odometry as
/// stated gives about 1) is now strong evidence on its own: the batch widens then, and
/// phase 2 goes on checking from the batch's trajectory.
#[test]
fn a_short_phase_1_still_sees_the_odometry_s_memory() {
    let mut settings = NavSettings::default();
    settings.phase1.max_frames = 150;
    let r = dense_hall_silent_with(sim::hall::HallLens::Radtan, &settings);
    assert!(
        r.replay.phase_switch_t_us.is_some_and(|t| t < 9_000_000),
        "{:?}",
        r.replay.phase_switch_t_us
    );
    let w = r.replay.odometry.unwrap().widened.expect("widened");
    assert!(
        w.t_us < 8_000_000 && w.variance_factors.iter().all(|&k| k >= 50.0),
        "{w:?}"
    );
    let t = r.replay.truth.as_ref().unwrap();
    let d = format!("{t:?}");
    let total = t.landmarks_matched + t.landmarks_unmatched;
    assert!(t.lamps_missed * 50 <= total && t.ate_rms <= 0.06, "{d}");
    for (p, error, sigma) in parameters(&r.replay) {
        assert!(
            error.abs() <= 3.0 * sigma,
            "{p:?}: {error} against sigma {sigma}"
        );
    }
    assert_nine_in_ten_inside(&r);
}

/// A dense hall (`sim::hall`'s seed 18: lamps every 2.5 m, no dark stretch) with 0.6 s of
/// memory the rig file is silent about. Phase 1 hands over after 14 s, its landmark budget
/// full, having widened the model from the one-second span alone (about 45 and 76 times the
/// variance, where the long run needs about 120): before phase 2 looked again, 41 of its 272
/// lamps were mapped more than 10 cm off. Phase 2's own check, once the smoother has stopped,
/// sees the memory over three-second spans and widens the model to its long run.
#[test]
fn a_dense_hall_silent_about_the_memory_is_widened_to_its_long_run() {
    let r = dense_hall_silent(sim::hall::HallLens::Radtan);
    let w = r.replay.odometry.unwrap().widened.expect("widened");
    let [tt, th] = w.time_constants_s;
    let [kt, kh] = w.variance_factors;
    assert!(
        (0.3..=1.5).contains(&tt) && (0.3..=1.5).contains(&th) && kt >= 90.0 && kh >= 90.0,
        "{w:?}"
    );
    let t = r.replay.truth.as_ref().unwrap();
    let d = format!("{t:?}");
    let total = t.landmarks_matched + t.landmarks_unmatched;
    assert!(
        t.lamps_missed * 50 <= total && t.landmarks_unmatched * 50 <= total,
        "{d}"
    );
    assert_nine_in_ten_inside(&r);
}

/// The same hall through a fisheye: its 48-landmark budget filled in 8.8 s, before the
/// batch's check of the odometry had its 8 one-second windows, and phase 1 handed over a
/// model nothing had checked (the odometry's 0.6 s of memory unstated): phase 2 ended 9.8 m
/// off, the baseline 27 sigma off. A full budget now waits for the check.
#[test]
fn a_dense_fisheye_hall_hands_over_only_once_the_odometry_is_checked() {
    let r = dense_hall_silent(sim::hall::HallLens::Fisheye);
    assert!(
        r.replay.phase_switch_t_us.is_some_and(|t| t >= 9_000_000),
        "{:?}",
        r.replay.phase_switch_t_us
    );
    assert!(r.replay.odometry.unwrap().widened.is_some());
    let t = r.replay.truth.as_ref().unwrap();
    let d = format!("{t:?}");
    assert!(t.ate_rms <= 0.06 && t.landmarks_duplicate == 0, "{d}");
    assert_nine_in_ten_inside(&r);
    for (p, error, sigma) in parameters(&r.replay) {
        assert!(
            error.abs() <= 3.0 * sigma,
            "{p}: {error} against sigma {sigma}; {d}"
        );
    }
}

/// `fixtures/scenarios/hall-radtan.toml` (187 lamps, 160 sprinkler heads, five aisles, the
/// radtan lens) with odometry errors of 0.6 s memory, stated in the rig file and not, each
/// simulated with the scenario's own seed and replayed with no flags. The drive holds little
/// of the map's scale: the baseline ends at its prior's sigma (0.30 mm) and 0.2 to 0.3 mm off
/// over seeds, 0.25 % of scale and 70 mm of landmark RMS on a hall 60 m long. So the checks
/// are the for honesty and its accuracy with the scale taken out: every landmark
/// within 0.5 m of a lamp, none twice, all but two lamps mapped, 90 % inside 3 sigma, the baseline within 1 mm and
/// every parameter inside 3 sigma, and the map's RMS after its best scale and shift within
/// 25 mm. Until 2026-12-06 this checked 25 mm of landmark RMS as it stands, and the seed met
/// it (19.6 and 21.0 mm) with the baseline's sigma at 0.21 mm: spurious, from linearisation
/// points moved without the covariance; over eight seeds that rule's map was 74 mm RMS with
/// a full-state NEES of 2.9 per degree of freedom (`replay_mc fixtures/scenarios/hall-radtan.toml
/// 8 --odometry-tau 0.6`; docs/halls.md, "The linearisation point"). Stated and silent: 75.1 and
/// 67.9 mm as it stands, 16.3 and 16.8 mm after scales of 0.9974 and 0.9978, 347 landmarks
/// for the 347 lamps seen, every one inside 3 sigma.
#[test]
fn the_radtan_hall_with_slipping_wheels_stays_mapped() {
    for stated in [true, false] {
        let mut sc = scenario("hall-radtan.toml");
        (sc.spec.noise.velocity_tau_s, sc.spec.noise.yaw_rate_tau_s) = (0.6, 0.6);
        if stated {
            (sc.rig.noise.velocity_tau, sc.rig.noise.yaw_rate_tau) = (0.6, 0.6);
        }
        let r = replayed_run(
            &sc,
            &format!("slip-hall-radtan-{stated}"),
            &NavSettings::default(),
        );
        let t = r.replay.truth.as_ref().unwrap();
        let d = format!("stated {stated}: {t:?}");
        assert_eq!(t.landmarks_duplicate, 0, "{d}");
        let (near, inside) = eval::landmarks_against_lamps(
            r.replay
                .landmarks
                .iter()
                .map(|l| (l.position, l.covariance)),
            &r.lamps,
            0.5,
        );
        assert_eq!(
            near,
            r.replay.landmarks.len(),
            "landmarks beyond 0.5 m of a lamp; {d}"
        );
        assert!(
            10 * inside >= 9 * near,
            "{inside} of {near} inside 3 sigma; {d}"
        );
        let (rms, scale) = rms_after_scale(&r);
        assert!(rms <= 0.025, "{rms} m after the scale {scale}; {d}");
        for (p, error, sigma) in parameters(&r.replay) {
            assert!(
                error.abs() <= 3.0 * sigma,
                "{p}: {error} against sigma {sigma}; {d}"
            );
            if p == Param::Baseline {
                assert!(error.abs() <= 0.001, "{d}");
            }
        }
    }
}

/// The landmarks' RMS distance from their nearest lamps after the map's best scale and shift
/// (least squares: the lamps' positions `s L + t` against the landmarks'), and `s`: the map's
/// shape, without the scale its baseline's error gives it.
fn rms_after_scale(r: &Run) -> (f64, f64) {
    let pairs: Vec<(nalgebra::Vector3<f64>, nalgebra::Vector3<f64>)> = r
        .replay
        .landmarks
        .iter()
        .filter_map(|l| {
            let p = nalgebra::Vector3::from(l.position);
            let lamp = r
                .lamps
                .iter()
                .min_by(|a, b| (a.position - p).norm().total_cmp(&(b.position - p).norm()))?;
            Some((p, lamp.position))
        })
        .collect();
    let n = pairs.len() as f64;
    let mean_est = pairs.iter().map(|(e, _)| e).sum::<nalgebra::Vector3<f64>>() / n;
    let mean_lamp = pairs.iter().map(|(_, l)| l).sum::<nalgebra::Vector3<f64>>() / n;
    let (num, den) = pairs.iter().fold((0.0, 0.0), |(num, den), (e, l)| {
        let (e, l) = (e - mean_est, l - mean_lamp);
        (num + e.dot(&l), den + l.dot(&l))
    });
    let s = num / den;
    let sum: f64 = pairs
        .iter()
        .map(|(e, l)| (e - mean_est - s * (l - mean_lamp)).norm_squared())
        .sum();
    ((sum / n).sqrt(), s)
}

/// Hall 32 of the Monte Carlo (`hall_mc 1 32 --lens radtan --odometry-tau 0.6`: five aisles
/// of 33 m, lamps every 4 m 6.3 m up among beam corners, tubes and LED panels, no dark
/// stretch) with odometry errors of 0.6 s memory stated in the rig file. Phase 1's landmark
/// budget fills before the calibration is stable, and the hand-over is honest but wide (the
/// pose 1.1 m and 2.2 degrees uncertain in the world). Phase 2 then reads the heading from a
/// single lamp in three frames (its sigma 2.2 -> 0.21 degrees, the heading 4.3 degrees off):
/// the iterated update's heading column is taken at a linearisation point the lost pose
/// left behind (docs/halls.md, "A wide hand-over and the points that follow"). It ends with
/// 84 of 98 lamps missed, 8 of 18 landmarks near their lamp inside 3 sigma and the baseline
/// 3.5 sigma off. The check for honesty (issue 36): the baseline and every vehicle
/// parameter inside 3 sigma, nine in ten landmarks near their lamp inside it, no duplicate.
/// Fails today with the defaults; it passes with the pose's first-estimates Jacobians and
/// "lost" judged relative to the map (`slow_a_wide_hand_over_stays_honest_with_the_pose_s_
/// first_estimates`), which are options because they move the Monte Carlo's other halls
/// both ways (docs/halls.md, "The pose's linearisation point").
#[test]
#[ignore = "known failure, not fixed: docs/halls.md, \"A wide hand-over and the points that follow\""]
fn a_wide_hand_over_on_odometry_with_memory_stays_honest() {
    hall_32_with_memory_is_honest("slip-hall-32-handover", &NavSettings::default());
}

/// Hall 32 with 0.6 s of odometry memory stated in the rig file, replayed with `settings`
/// under `tag`, checked for issue 36's honesty: no duplicate, the baseline and every vehicle
/// parameter inside 3 sigma, nine in ten landmarks near their lamp inside it.
fn hall_32_with_memory_is_honest(tag: &str, settings: &NavSettings) -> Run {
    let mut sc = hall_scenario(32, sim::hall::HallLens::Radtan);
    (sc.spec.noise.velocity_tau_s, sc.spec.noise.yaw_rate_tau_s) = (0.6, 0.6);
    (sc.rig.noise.velocity_tau, sc.rig.noise.yaw_rate_tau) = (0.6, 0.6);
    let r = replayed_run(&sc, tag, settings);
    let t = r.replay.truth.as_ref().unwrap();
    let d = format!("{t:?}");
    assert_eq!(t.landmarks_duplicate, 0, "{d}");
    for (p, error, sigma) in parameters(&r.replay) {
        assert!(
            error.abs() <= 3.0 * sigma,
            "{p}: {error} against sigma {sigma}; {d}"
        );
    }
    assert_nine_in_ten_inside(&r);
    r
}

/// The same hall with the pose's first-estimates Jacobians while it is lost
/// (`vslam_ekf::Settings::first_estimate_pose`) and "lost" judged relative to the map around
/// the pose as well (`NavSettings::relative_lost`): the hand-over's heading stays 2 degrees
/// uncertain, phase 2 maps on from the lamps it was handed, and the hall is mapped (1 of 98
/// lamps missed, every landmark near its lamp inside 3 sigma, the baseline 1 sigma off;
/// `hall_mc 1 32 --lens radtan --odometry-tau 0.6 --fej-pose --relative-lost`). Neither is
/// the default: over the 24 memory halls they move other halls both ways (hall 22 breaks;
/// docs/halls.md, "The pose's linearisation point"). Slow tier (20 s).
#[test]
fn slow_a_wide_hand_over_stays_honest_with_the_pose_s_first_estimates() {
    let defaults = NavSettings::default();
    let settings = NavSettings {
        relative_lost: true,
        ekf: vslam_ekf::Settings {
            first_estimate_pose: true,
            ..defaults.ekf
        },
        ..defaults
    };
    let r = hall_32_with_memory_is_honest("slip-hall-32-fej", &settings);
    let t = r.replay.truth.as_ref().unwrap();
    assert!(t.lamps_missed <= 3, "{t:?}");
}
