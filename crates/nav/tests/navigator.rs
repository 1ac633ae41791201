//! The navigator fed by hand with a simulated run: phase 1, the switch, phase 2, and refusals
//! of bad input that leave it as it was.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::indexing_slicing)]

use std::path::Path;

use nav::{Error, NavSettings, Navigator, Phase};
use rig_model::odometry::OdomSample;
use track::Pixel;

fn run(name: &str) -> sim::SimRun {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/scenarios")
        .join(format!("{name}.toml"));
    let sc = sim::Scenario::load(&path).unwrap();
    sim::simulate(&sc, sim::Mode::Fast).unwrap()
}

fn pixels(f: &sim::ImageFeatures) -> Vec<Pixel> {
    f.features
        .iter()
        .map(|x| Pixel::from_q4(x.x_q4, x.y_q4))
        .collect()
}

/// Feeds the whole run in time order; returns the navigator.
fn feed(run: &sim::SimRun, settings: NavSettings) -> Navigator {
    let mut nav = Navigator::new(run.rig.clone(), settings).unwrap();
    let mut odom = run.odometry.iter().peekable();
    for f in &run.frames {
        while let Some(s) = odom.next_if(|s| s.t_us <= f.t_us) {
            nav.push_odometry(OdomSample {
                t_us: s.t_us,
                vx: s.vx,
                vy: s.vy,
                vtheta: s.vtheta,
            })
            .unwrap();
        }
        nav.push_frame(f.t_us, &pixels(&f.left), &pixels(&f.right))
            .unwrap();
    }
    nav
}

#[test]
fn phase_1_hands_over_to_phase_2_on_the_calibration_drive() {
    let run = run("paper-calibration");
    let nav = feed(&run, NavSettings::default());
    assert_eq!(nav.phase(), Phase::Navigating);
    let switch = nav.phase_switch_t_us().unwrap();
    let handover = nav.handover().unwrap();
    assert_eq!(handover.t_us, switch);
    let ekf = nav.ekf().unwrap();
    // Every lamp mapped once, no clutter landmark.
    assert_eq!(ekf.landmark_count(), run.landmarks.len());
    // The filter continued from the hand-over: the baseline's sigma no larger than phase 1's.
    let i = rig_model::Param::Baseline.index();
    let s_handover = handover.covariance[(i, i)].sqrt();
    let s_now = ekf.camera_covariance()[(i, i)].sqrt();
    assert!(s_now <= s_handover * 1.0001, "{s_now} > {s_handover}");
}

#[test]
fn phase_1_can_be_skipped() {
    let run = run("paper-experiment");
    let settings = NavSettings {
        skip_phase1: true,
        ..NavSettings::default()
    };
    let nav = feed(&run, settings);
    assert_eq!(nav.phase(), Phase::Navigating);
    assert_eq!(nav.phase_switch_t_us(), None);
    let ekf = nav.ekf().unwrap();
    assert_eq!(ekf.landmark_count(), 5);
    let b = ekf.camera().baseline;
    assert!((b - run.camera.baseline).abs() < 0.0005, "{b}");
    // The pose at the end against the truth: within 3 sigma per axis.
    let (pose, cov) = nav.pose();
    let truth = run.frames.last().unwrap().pose;
    for (k, e) in [pose.x - truth.x, pose.y - truth.y].into_iter().enumerate() {
        assert!(e.abs() <= 3.0 * cov[(k, k)].sqrt() + 1e-9, "axis {k}: {e}");
    }
}

#[test]
fn bad_input_is_refused_and_changes_nothing() {
    let run = run("paper-experiment");
    let settings = NavSettings {
        skip_phase1: true,
        ..NavSettings::default()
    };
    let mut nav = Navigator::new(run.rig.clone(), settings).unwrap();
    let s = |t_us, vx: f64| OdomSample {
        t_us,
        vx,
        vy: 0.0,
        vtheta: 0.0,
    };
    nav.push_odometry(s(1_000_000, 0.1)).unwrap();
    let e = nav.push_odometry(s(2_000_000, f64::NAN)).unwrap_err();
    assert!(matches!(e, Error::NonFinite { .. }), "{e}");
    assert!(e.to_string().contains("odometry vx"), "{e}");
    nav.push_odometry(s(2_000_000, 0.1)).unwrap();
    let e = nav.push_odometry(s(1_500_000, 0.1)).unwrap_err();
    assert!(matches!(e, Error::OdometryOutOfOrder { .. }), "{e}");
    assert_eq!(nav.stats().odometry, 2);
    nav.push_frame(2_000_000, &[], &[]).unwrap();
    let e = nav.push_frame(1_000_000, &[], &[]).unwrap_err();
    assert!(matches!(e, Error::FrameOutOfOrder { .. }), "{e}");
    let e = nav
        .push_frame(2_100_000, &[Pixel::new(f64::NAN, 1.0)], &[])
        .unwrap_err();
    assert!(e.to_string().contains("not finite"), "{e}");
    assert_eq!(nav.stats().frames, 1);
    assert_eq!(nav.last_frame_t_us(), Some(2_000_000));
    // Settings out of range.
    let bad = NavSettings {
        map_match_probability: 1.0,
        ..NavSettings::default()
    };
    let e = Navigator::new(run.rig.clone(), bad).unwrap_err();
    assert!(e.to_string().contains("map_match_probability"), "{e}");
}

/// Frames without any odometry (a vehicle whose odometry link is down) hold the pose and are
/// counted; nothing panics.
#[test]
fn frames_without_odometry_hold_the_pose() {
    let run = run("paper-experiment");
    let settings = NavSettings {
        skip_phase1: true,
        ..NavSettings::default()
    };
    let mut nav = Navigator::new(run.rig.clone(), settings).unwrap();
    for f in run.frames.iter().take(20) {
        let o = nav
            .push_frame(f.t_us, &pixels(&f.left), &pixels(&f.right))
            .unwrap();
        if f.index > 0 {
            assert!(o.no_odometry);
        }
    }
    assert_eq!(nav.stats().frames_without_odometry, 19);
    assert_eq!(nav.pose().0, rig_model::Pose2::default());
}

/// Through EuRoC's radtan lenses (the board's features raw, the rig's `[lens.*]` mapping them):
/// every observation the update is given names the two raw board features it was made of,
/// both images of one lamp, always the same lamp for a landmark; accepted and rejected as the
/// outcome counts them.
#[test]
fn associations_name_the_raw_features_of_one_lamp() {
    let run = run("paper-experiment-radtan");
    assert!(run.rig.lens.is_some());
    let mut nav = Navigator::new(run.rig.clone(), NavSettings::default()).unwrap();
    let mut odom = run.odometry.iter().peekable();
    let mut lamp_of: std::collections::BTreeMap<u64, u32> = Default::default();
    let mut accepted_total = 0;
    for f in &run.frames {
        while let Some(s) = odom.next_if(|s| s.t_us <= f.t_us) {
            nav.push_odometry(OdomSample {
                t_us: s.t_us,
                vx: s.vx,
                vy: s.vy,
                vtheta: s.vtheta,
            })
            .unwrap();
        }
        let o = nav
            .push_frame(f.t_us, &pixels(&f.left), &pixels(&f.right))
            .unwrap();
        let accepted: Vec<_> = o.associations.iter().filter(|a| a.accepted).collect();
        let ids: Vec<_> = accepted.iter().map(|a| a.landmark).collect();
        let expected: Vec<_> = o.accepted.iter().map(|(id, _)| *id).collect();
        assert_eq!(ids, expected, "frame {}", f.index);
        assert_eq!(
            o.associations.len() - accepted.len(),
            o.rejected.len(),
            "frame {}",
            f.index
        );
        for a in &o.associations {
            let left = f.left.features[a.left].lamp.unwrap();
            let right = f.right.features[a.right].lamp.unwrap();
            assert_eq!(left, right, "frame {}: {a:?}", f.index);
            let lamp = *lamp_of.entry(a.landmark.0).or_insert(left);
            assert_eq!(lamp, left, "frame {}: {a:?}", f.index);
        }
        accepted_total += accepted.len();
    }
    assert_eq!(lamp_of.len(), 5, "{lamp_of:?}");
    assert!(accepted_total > 1000, "{accepted_total}");
}

/// Phase 2's smoother over the landmarks near the vehicle (`smooth_near_vehicle`) with a
/// budget of a third of the aisle's lamps is the smoother over the whole map: it starts again
/// from the filter's marginal as the vehicle moves on (the rest of the map carried by the
/// cross-covariances when it is put back), solves all along the drive, and the map it leaves
/// is the one the smoother over every landmark leaves, lamp for lamp.
#[test]
fn the_smoother_near_the_vehicle_is_the_smoother_over_the_whole_map() {
    let run = run("aisle");
    let whole = feed(&run, NavSettings::default());
    let mut settings = NavSettings {
        smooth_near_vehicle: true,
        ..NavSettings::default()
    };
    settings.phase1.max_landmarks = 12;
    let near = feed(&run, settings);
    let (sw, sn) = (whole.stats(), near.stats());
    assert_eq!(sw.phase2_smoother_restarts, 0, "{sw:?}");
    assert!(sn.phase2_smoother_restarts >= 10, "{sn:?}");
    assert!(
        sn.phase2_solves * 10 >= sw.phase2_solves * 7,
        "{sn:?} {sw:?}"
    );
    assert_eq!(sn.phase2_reseeds_refused, 0, "{sn:?}");
    let (ew, en) = (whole.ekf().unwrap(), near.ekf().unwrap());
    assert_eq!(ew.landmark_count(), en.landmark_count());
    let mut largest: f64 = 0.0;
    for l in en.landmarks() {
        let twin = ew
            .landmarks()
            .map(|w| (w.position - l.position).norm())
            .fold(f64::INFINITY, f64::min);
        largest = largest.max(twin);
    }
    let db = (en.camera().baseline - ew.camera().baseline).abs();
    eprintln!(
        "largest landmark difference {:.2} mm, baseline {:.4} mm",
        1e3 * largest,
        1e3 * db
    );
    assert!(
        largest < 0.0015,
        "a landmark {:.2} mm from the whole smoother's",
        1e3 * largest
    );
    assert!(
        db < 1e-5,
        "baseline {:.4} mm from the whole smoother's",
        1e3 * db
    );
}
