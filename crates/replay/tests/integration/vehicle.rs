//! The vehicle's own parameters (vehicle-interfaces.md 1.2): a forklift whose odometry reports
//! speeds 1.5 % high and yaw rates 0.5 % high with a 0.002 rad/s bias, and whose board clock
//! runs 12 ms ahead, in the 40-lamp aisle (`fixtures/scenarios/aisle-vehicle.toml`), replayed
//! with no flags: the rig estimates the baseline (known from a lab calibration to 0.3 mm) and
//! all four vehicle parameters from their priors. Issue 17's bounds, each estimate also inside
//! 3 sigma.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use replay::NavSettings;
use rig_model::Param;

use crate::{assert_nine_in_ten_inside, hall_scenario, parameters, replayed_run, scenario};

#[test]
fn a_forklift_with_odometry_errors_and_a_clock_offset_is_calibrated() {
    calibrated(scenario("aisle-vehicle.toml"), 0..2, "ahead");
}

/// The board's clock behind the odometry's: frames exposed after their stamps, the first one
/// before the odometry's first sample (the first interval once had no odometry, and the map
/// was lost: nav::ODOMETRY_LOOKAHEAD_US, rig_model::odometry::BACKWARD_HOLD_US).
#[test]
fn a_clock_offset_of_the_other_sign_is_calibrated_too() {
    let mut sc = scenario("aisle-vehicle.toml");
    sc.spec.rates.board_clock_offset_s = -0.012;
    calibrated(sc, 2..3, "behind");
}

fn calibrated(sc: sim::Scenario, seeds: std::ops::Range<u64>, tag: &str) {
    let log = crate::scratch_log(&format!("aisle-vehicle-{tag}"));
    // Bound on |error| of each parameter (the issue's), SI units.
    let bounds = [
        (Param::Baseline, 0.001),
        (Param::OdomScale, 0.006),
        (Param::OdomYawScale, 0.003),
        (Param::OdomYawBias, 0.0005),
        (Param::TimeOffset, 0.003),
    ];
    for seed in seeds {
        let run = sim::simulate(&sc.clone().with_seed(seed), sim::Mode::Fast).unwrap();
        run.write_log(&log).unwrap();
        let r = replay::replay_log(&log, None, &NavSettings::default(), &mut |_, _| {}).unwrap();
        let t = r.truth.as_ref().unwrap();
        let d = format!("seed {seed}: {t:?}");
        assert!(t.landmark_rms <= 0.025, "{d}");
        assert_eq!(t.lamps_missed, 0, "{d}");
        for (p, bound) in bounds {
            let error = t.camera.iter().find(|(q, _)| *q == p).unwrap().1;
            let sigma = r.final_camera.iter().find(|c| c.param == p).unwrap().sigma;
            assert!(error.abs() <= bound, "{p}: error {error} > {bound}; {d}");
            assert!(
                error.abs() <= 3.0 * sigma,
                "{p}: error {error} outside 3 sigma {sigma}; {d}"
            );
        }
    }
    std::fs::remove_file(&log).ok();
}

/// The aisle driven straight back and forth, never turned: the yaw scale is not in the data,
/// and the rig's prior is all there is to know of it. The filter predicts with the yaw rate's
/// noise in its pose, and its yaw scale's column of `d motion / dV` once held that same noise
/// (the interval's own samples): every update that took the noise back out of the heading
/// moved the yaw scale by the product, always up. On this drive (seed 1) the filter alone
/// ended with the yaw scale at 1.152 +- 1.9 % (truth 1.005, 8 sigma); with the column from
/// the yaw rate reported before the interval, far enough back that the heading no longer
/// holds its noise (`rig_model::odometry::filter_yaw_scale_column`), at 1.009. Phase 2's
/// smoother, which owns the estimates while it carries the whole map, is switched off here so
/// that the test sees the filter, which maps a hall alone (docs/vehicle.md, "Errors in the
/// variables").
#[test]
fn the_yaw_rate_s_noise_does_not_pull_the_yaw_scale_on_a_straight_drive() {
    let mut sc = scenario("aisle-vehicle.toml");
    let path = &mut sc.spec.path;
    path.segments
        .retain(|s| s.kind != sim::scenario::SegmentKind::Turn);
    let mut forward = true;
    for s in path
        .segments
        .iter_mut()
        .filter(|s| s.kind == sim::scenario::SegmentKind::Straight)
    {
        s.length_m = s.length_m.map(|l| if forward { l.abs() } else { -l.abs() });
        forward = !forward;
    }
    let run = sim::simulate(&sc.with_seed(1), sim::Mode::Fast).unwrap();
    let log = crate::scratch_log("aisle-straight");
    run.write_log(&log).unwrap();
    let settings = NavSettings {
        smooth_phase2: false,
        ..NavSettings::default()
    };
    let r = replay::replay_log(&log, None, &settings, &mut |_, _| {}).unwrap();
    std::fs::remove_file(&log).ok();
    let t = r.truth.as_ref().unwrap();
    let d = format!("{t:?}");
    assert_eq!(t.lamps_missed, 0, "{d}");
    // The odometry as stated (white, not widened): the column from before the interval is
    // the one in use.
    assert!(
        r.odometry.as_ref().is_none_or(|o| o.widened.is_none()),
        "{:?}",
        r.warnings
    );
    let yaw = r
        .final_camera
        .iter()
        .find(|c| c.param == Param::OdomYawScale)
        .unwrap();
    let error = t
        .camera
        .iter()
        .find(|(p, _)| *p == Param::OdomYawScale)
        .unwrap()
        .1;
    // Nothing to learn: the estimate stays within its prior's sigma of the nominal value, and
    // inside 2 sigma of the truth (0.5 % from the nominal value).
    assert!(
        (yaw.value - 1.0).abs() <= 0.02,
        "yaw scale {} +- {}; {d}",
        yaw.value,
        yaw.sigma
    );
    assert!(
        error.abs() <= 2.0 * yaw.sigma,
        "yaw scale error {error} against sigma {}; {d}",
        yaw.sigma
    );
}

/// The same drive told nothing about the vehicle (its rig's `[estimate]` without V): the
/// odometry's 1.5 % scale, 0.002 rad/s yaw bias and clock offset are errors the rig's noise
/// model does not allow, so the test above is not passing on an easy log. Once the batch's
/// residuals show it (issue 36), the navigator widens its odometry model and says so: the map
/// is then made by the lamps, and the trajectory carries the odometry's scale until phase 2.
#[test]
fn without_estimating_v_the_same_drive_is_seen_to_have_worse_odometry() {
    let mut sc = scenario("aisle-vehicle.toml");
    sc.rig.estimate.retain(|p| !p.is_vehicle());
    for p in Param::VEHICLE {
        sc.rig.prior[p.index()] = None;
    }
    let run = sim::simulate(&sc.with_seed(0), sim::Mode::Fast).unwrap();
    let log = crate::scratch_log("aisle-no-v");
    run.write_log(&log).unwrap();
    let r = replay::replay_log(&log, None, &NavSettings::default(), &mut |_, _| {}).unwrap();
    let t = r.truth.as_ref().unwrap();
    assert!(t.ate_rms > 0.05, "{t:?}");
    assert!(r.odometry.unwrap().widened.is_some(), "{:?}", r.warnings);
    assert!(
        r.warnings
            .iter()
            .any(|w| w.starts_with("the odometry is worse than the rig file states")),
        "{:?}",
        r.warnings
    );
    std::fs::remove_file(&log).ok();
}

/// `sim::hall`'s hall 26 (45 m aisles, lamps every 4.5 m 6.2 m up) through the radtan lens,
/// the odometry as good as stated, replayed with no flags. At the end of its third aisle the
/// vehicle turns in place under two or three lamps, its camera 0.5 m ahead of the axle
/// sweeping an arc, the pose's sigma just above 0.1 m so that the update iterates. With the
/// linearisation points frozen once a landmark was known to 0.5 m (the rule before
/// 2026-12-06), that turn told the filter the map's scale: the baseline moved 0.3 mm in 1.5 s
/// while its sigma fell from 0.176 to 0.115 mm, and the map ended with the baseline 2.9 sigma
/// off, the odometry's scale 3.1 sigma off and 41 of 78 landmarks inside 3 sigma (the batch
/// over every frame: the baseline's sigma 0.18 mm). With the points following the estimates
/// and the covariance re-linearised with them (`vslam_ekf::Settings::follow_points`, the
/// default; docs/halls.md, "The linearisation point"): the baseline -0.094 mm off at 0.186,
/// every parameter and 92 of 92 landmarks inside 3 sigma.
#[test]
fn a_turn_in_place_does_not_tell_the_filter_the_map_s_scale() {
    let r = radtan_hall(26, "hall-26-scale");
    assert_parameters_inside(&r);
    assert_eq!(
        r.inside, r.near,
        "{} of {} inside 3 sigma",
        r.inside, r.near
    );
    assert_eq!(r.replay.truth.as_ref().unwrap().landmarks_duplicate, 0);
}

/// Hall 27 of the Monte Carlo (`hall_mc 1 27 --lens radtan`: 47 m aisles, lamps every 4.5 m
/// only 5.7 m up, white odometry). In the U-turn at the end of aisle 2 the lamp of an aisle-end
/// landmark is bound again, and the update iterates (the pose's sigma above 0.1 m). Its passes
/// took the heading's column from the observability constraint and the rest from the
/// derivative, and walked the pose and its two lamps together 0.04, 0.06, 0.08 ... m a pass,
/// 0.6 m in one frame: the map's shared translation moved 3.6 sigma, the loop down aisle 1
/// was never closed, 44 of 45 lamps missed, trajectory 742 mm. Gauss-Newton's passes now
/// stop when a pose step grows (docs/halls.md, "Not done yet"): 255 mm, 16 missed, but 2 of
/// 11 landmarks near their lamps inside 3 sigma. With the linearisation points following the
/// estimates (the default since 2026-12-06): 241 mm, 22 missed, the far halves of the aisles
/// 0.1 to 0.3 m off after the 13 m dark stretch, and 23 of 24 inside 3 sigma. With the
/// filter's yaw-scale column taken from the yaw rate reported before the interval
/// (2026-12-07, `rig_model::odometry::filter_yaw_scale_column`): 296 mm, 23 missed, 17 of 20
/// inside 3 sigma (the test below); with `vslam_ekf::Settings::follow_scale`, 344 mm, 13
/// missed, 2 of 10. Every lamp mapped is not reached yet.
#[test]
fn a_u_turn_s_iterated_update_does_not_walk_the_local_map_away() {
    let r = radtan_hall(27, "hall-27-u-turn");
    let t = r.replay.truth.as_ref().unwrap();
    let d = format!("{t:?}");
    assert!(t.ate_rms <= 0.4, "{d}");
    assert!(t.lamps_missed <= 25, "{d}");
    assert_eq!(t.landmarks_duplicate, 0, "{d}");
}

/// Hall 27's landmarks beyond the dark stretch honest: nine in ten of those near their lamp
/// inside 3 sigma. Held 24 of 24 until the filter's yaw-scale column stopped holding the
/// interval's noise (2026-12-07); since, 17 of 20. On the hall's first aisle that change does
/// what it should (the yaw scale 1.006 where it had drifted to 1.019, truth 1.005); after the
/// U-turns the two runs differ by chance, and both end with the far half short along the
/// aisles (0.15 to 0.20 m at x 42-47 m; sigma 60 to 80 mm) because the odometry scale ends
/// 2.0 and 2.3 sigma high: its own filter column holds the interval's speed noise the same
/// way, and pulls it up as the yaw scale's did (docs/vehicle.md, "Where the bias is"; a
/// column from the speed reported before the interval breaks the metric scale's gauge unless
/// the baseline's column takes the difference, and with it changes nothing). With the
/// corrections taken in units of the baseline (`vslam_ekf::Settings::follow_scale`,
/// 2026-12-07, later): 13 lamps missed (was 23), 344 mm, 2 of 10 inside 3 sigma. Over other
/// draws of the same hall's noise (`hall_mc 1 27 --lens radtan --noise-seed S`, S = 1 to 8;
/// 2026-12-07, session 23) the baseline is within 1.3 of its sigma in all eight; four are honest
/// (18 of 18 to 44 of 44 inside 3 sigma) while four are not (1 of 9 to 5 of 12): so it is not
/// the map's scale. Traced on seed 7 (`hall_mc ... --noise-seed 7 --keep DIR`, `loop_probe
/// DIR/hall-27.mcap`): the heading leaves the dark stretch 2 sigma off (-0.85 degrees at
/// 0.44, the yaw bias +1.4 sigma), the far half is mapped through it, and when the vehicle comes
/// back to the second aisle's lamps (234 s) and then to the first aisle's (257 s, a 0.57 m
/// jump) the heading's sigma falls to 0.20 and 0.14 degrees while its error stays at -1.2 and
/// -1.0 degrees: the EKF's overconfident heading at a loop closure (docs/vehicle.md, "Dark
/// stretches"). With the prediction's first-estimates Jacobian while the heading is known to
/// half a degree (`vslam_ekf::Settings::first_estimate_prediction`, the default since
/// 2026-12-08): 8 lamps missed, every landmark near its lamp inside 3 sigma; over the eight
/// draws, the overconfident ones go from four to one (docs/vehicle.md, "The prediction's
/// first estimates, gated by the heading's sigma").
#[test]
fn hall_27_s_far_half_is_inside_3_sigma() {
    let r = radtan_hall(27, "hall-27-far-half");
    assert_nine_in_ten_inside(&r);
}

/// Hall `seed` of the Monte Carlo (`hall_mc 1 SEED --lens radtan`), simulated, written and
/// replayed with no flags.
fn radtan_hall(seed: u64, tag: &str) -> crate::Run {
    let sc = hall_scenario(seed, sim::hall::HallLens::Radtan);
    replayed_run(&sc, tag, &NavSettings::default())
}

/// Every estimated parameter within 3 sigma of the truth.
fn assert_parameters_inside(r: &crate::Run) {
    let d = format!("{:?}", r.replay.truth);
    for (p, error, sigma) in parameters(&r.replay) {
        assert!(
            error.abs() <= 3.0 * sigma,
            "{p}: error {error} outside 3 sigma {sigma}; {d}"
        );
    }
}

/// The aisle driven six times (5 minutes) with the odometry's noise off, so that only the
/// pixels' noise can move the baseline. The pixels fix every length in units of the baseline
/// and the odometry in metres, so the map's metric scale rests on the rig's lever arm alone,
/// and a filter that corrects its pose in metres walks its linearisation point along that
/// nearly unobservable direction. With `vslam_ekf::Settings::follow_scale` off, the four
/// seeds ended with the baseline +0.94 to +1.23 sigma off (+0.10 to +0.13 mm, the sigma
/// 0.103 mm) and the landmarks 8.5 to 10.6 mm RMS; with it (the default) -0.24 to +0.01 sigma
/// and 1.4 to 4.6 mm (docs/vehicle.md, "The baseline's drift"). Phase 2's smoother is off, as
/// above, so that the test sees the filter.
#[test]
fn the_pixels_noise_does_not_walk_the_baseline() {
    let mut sc = scenario("aisle-vehicle.toml");
    sc.spec.path.repeat = 6;
    sc.spec.noise.velocity_mps = 0.0;
    sc.spec.noise.yaw_rate_radps = 0.0;
    let settings = NavSettings {
        smooth_phase2: false,
        ..NavSettings::default()
    };
    let mut z_sum = 0.0;
    let seeds = 0..4u64;
    for seed in seeds.clone() {
        let run = sim::simulate(&sc.clone().with_seed(seed), sim::Mode::Fast).unwrap();
        let log = crate::scratch_log(&format!("aisle-pixels-{seed}"));
        run.write_log(&log).unwrap();
        let r = replay::replay_log(&log, None, &settings, &mut |_, _| {}).unwrap();
        std::fs::remove_file(&log).ok();
        let t = r.truth.as_ref().unwrap();
        let d = format!("seed {seed}: {t:?}");
        let error = t
            .camera
            .iter()
            .find(|(q, _)| *q == Param::Baseline)
            .unwrap()
            .1;
        let sigma = r
            .final_camera
            .iter()
            .find(|c| c.param == Param::Baseline)
            .unwrap()
            .sigma;
        assert_eq!(t.lamps_missed, 0, "{d}");
        assert!(t.landmark_rms <= 0.006, "{d}");
        z_sum += error / sigma;
    }
    let z_mean = z_sum / seeds.count() as f64;
    assert!(
        z_mean.abs() <= 0.5,
        "the baseline's mean error {z_mean} sigma"
    );
}
