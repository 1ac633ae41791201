//! What a localiser on a saved map needs of the simulator (issue 20): a start pose in the
//! hall's frame, a vehicle carried while blind, lamps gone dark and lamps added, and the
//! hall's jitter apart from the run's noise; and the two hall scenarios built from them.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failure is the test failing

use crate::common;

use nalgebra::Vector3;
use rig_model::Pose2;
use sim::scenario::{LampSpec, MovedOdometry, PoseSpec, Segment};
use vehicle_log::Record;

/// `(min, mean, max)` of the lamps in view of both cameras per frame.
fn in_view(run: &sim::SimRun) -> (usize, f64, usize) {
    stats(&run.visible_counts())
}

/// Lamps in view of both cameras whose rectified pixels lie within `deg` of the rectified
/// optical axis of a camera of focal length 220 px centred at (376, 240) (the halls' rig).
fn in_field(run: &sim::SimRun, deg: f64) -> (usize, f64, usize) {
    let field = rig_model::lens::FieldOfUse::new(deg.to_radians(), 220.0, 376.0, 240.0);
    let counts: Vec<usize> = run
        .frames
        .iter()
        .map(|f| {
            f.views
                .iter()
                .filter(|v| v.in_left && v.in_right)
                .filter(|v| {
                    field.contains(v.u_left, v.v_left) && field.contains(v.u_right, v.v_right)
                })
                .count()
        })
        .collect();
    stats(&counts)
}

fn stats(counts: &[usize]) -> (usize, f64, usize) {
    let min = counts.iter().copied().min().unwrap();
    let max = counts.iter().copied().max().unwrap();
    #[allow(clippy::cast_precision_loss)]
    let mean = counts.iter().sum::<usize>() as f64 / counts.len() as f64;
    (min, mean, max)
}

/// `world_from_old`: the pose `start` composed with a pose of the old world frame.
fn compose(start: &Pose2, p: &Pose2) -> Pose2 {
    let (s, c) = start.theta.sin_cos();
    Pose2::new(
        start.x + c * p.x - s * p.y,
        start.y + s * p.x + c * p.y,
        start.theta + p.theta,
    )
}

fn angle_diff(a: f64, b: f64) -> f64 {
    sim::wrap_angle(a - b).abs()
}

#[test]
fn a_start_pose_puts_the_truth_and_the_lamps_in_the_halls_frame() {
    let base = common::shorten(common::load("paper-experiment"), 3);
    let start = PoseSpec {
        x_m: 12.0,
        y_m: -4.0,
        yaw_deg: 120.0,
    };
    let start_pose = start.pose();
    // The same lamps, carried into a hall frame in which the robot starts at `start`.
    let mut moved = base.clone();
    moved.spec.path.start = start;
    for l in &mut moved.spec.world.lamps {
        let p = compose(&start_pose, &Pose2::new(l.x_m, l.y_m, 0.0));
        (l.x_m, l.y_m) = (p.x, p.y);
    }
    let a = sim::simulate(&base, sim::Mode::Fast).unwrap();
    let b = sim::simulate(&moved, sim::Mode::Fast).unwrap();
    assert_eq!(a.frames.len(), b.frames.len());
    // The first frame is at the start pose, exactly; every truth pose is the old one seen
    // from the hall.
    assert_eq!(b.frames[0].pose.x, 12.0);
    assert_eq!(b.frames[0].pose.y, -4.0);
    assert!(angle_diff(b.frames[0].pose.theta, 120f64.to_radians()) < 1e-15);
    for (fa, fb) in a.frames.iter().zip(&b.frames) {
        let expected = compose(&start_pose, &fa.pose);
        assert!((fb.pose.x - expected.x).abs() < 1e-9, "{fb:?}");
        assert!((fb.pose.y - expected.y).abs() < 1e-9);
        assert!(angle_diff(fb.pose.theta, expected.theta) < 1e-12);
        // The cameras see the same thing.
        assert_eq!(fa.views.len(), fb.views.len());
        for (va, vb) in fa.views.iter().zip(&fb.views) {
            assert_eq!(va.id, vb.id);
            assert!((va.u_left - vb.u_left).abs() < 1e-6 && (va.v_right - vb.v_right).abs() < 1e-6);
        }
    }
    // The odometry is robot-frame: the same samples.
    assert_eq!(a.odometry, b.odometry);
    // The logged truth is the hall's.
    assert_eq!(b.truth_poses()[0].x, 12.0);
    let truth = b.truth_landmarks();
    assert!((truth[0].x - moved.spec.world.lamps[0].x_m).abs() < 1e-15);
    // The default start is the old world frame: nothing moved.
    assert_eq!(base.spec.path.start, PoseSpec::default());
    assert_eq!(a.frames[0].pose, Pose2::default());
}

/// paper-experiment's first drive, then a carry to `(3, 1, 90 deg)`, then a straight.
fn carried(odometry: MovedOdometry) -> sim::Scenario {
    let mut s = common::noise_off(common::shorten(common::load("paper-experiment"), 2));
    s.spec.noise.yaw_rate_bias_radps = 0.0;
    s.spec
        .path
        .segments
        .push(Segment::moved(2.0, 3.0, 1.0, 90.0, odometry));
    s.spec.path.segments.push(Segment::wait(0.5));
    s.spec.path.segments.push(Segment::straight(1.0));
    s
}

#[test]
fn no_frames_and_the_chosen_odometry_while_carried() {
    for odometry in [MovedOdometry::None, MovedOdometry::Zero] {
        let s = carried(odometry);
        let run = sim::simulate(&s, sim::Mode::Fast).unwrap();
        let plain = sim::simulate(
            &common::noise_off(common::shorten(common::load("paper-experiment"), 2)),
            sim::Mode::Fast,
        )
        .unwrap();
        // The carry starts where the first two segments end.
        let t_carry = plain.odometry_truth.last().unwrap().t_us;
        let t_down = t_carry + 2_000_000;
        let name = odometry.name();
        // No frame strictly inside the carry; frames on both sides.
        assert!(
            run.frames
                .iter()
                .all(|f| f.t_us <= t_carry || f.t_us >= t_down),
            "{name}"
        );
        let before = run.frames.iter().filter(|f| f.t_us <= t_carry).count();
        let after = &run.frames[before..];
        assert!(before > 0 && !after.is_empty(), "{name}");
        // The exposures strictly inside the carry are not sent; the counter jumps over them.
        let first_frame_us = s.spec.rates.start_t_us;
        let blind = (0..)
            .map(|k| first_frame_us + 50_000 * k)
            .take_while(|&t| t < t_down)
            .filter(|&t| t > t_carry)
            .count();
        assert!((39..=40).contains(&blind));
        let jump = after[0].frame_counter - run.frames[before - 1].frame_counter;
        assert_eq!(jump as usize, blind + 1, "{name}");
        assert_eq!(after[0].index, run.frames[before - 1].index + blind + 1);
        let (decoded, stats) = common::decode(run.chunks.iter().map(|c| c.bytes.as_slice()));
        assert_eq!(decoded.len(), run.frames.len(), "{name}");
        assert_eq!(
            stats.lost as usize, blind,
            "{name}: a receiver sees the blind frames as lost"
        );
        // Put down at the target, at rest, then 1 m straight ahead (+y).
        let down = after[0].pose;
        assert!((down.x - 3.0).abs() < 1e-12 && (down.y - 1.0).abs() < 1e-12);
        assert!(angle_diff(down.theta, 90f64.to_radians()) < 1e-12);
        let end = run.frames.last().unwrap().pose;
        assert!(
            (end.x - 3.0).abs() < 1e-9 && (end.y - 2.0).abs() < 1e-9,
            "{name}: {end:?}"
        );
        // The odometry: nothing, or rest at the odometry rate, during the carry.
        let during: Vec<_> = run
            .odometry
            .iter()
            .filter(|o| o.t_us >= t_carry && o.t_us < t_down)
            .collect();
        match odometry {
            MovedOdometry::None => assert!(during.is_empty(), "{during:?}"),
            MovedOdometry::Zero => {
                assert_eq!(during.len(), 200);
                assert!(
                    during
                        .iter()
                        .all(|o| o.vx == 0.0 && o.vy == 0.0 && o.vtheta == 0.0)
                );
            }
        }
        assert!(run.odometry.iter().any(|o| o.t_us == t_down), "{name}");
        assert_eq!(run.odometry.len(), run.odometry_truth.len());
        // The log: the truth poses of the frames that exist, the odometry as sent.
        let bytes = run.write_log_to(std::io::Cursor::new(Vec::new())).unwrap();
        let path = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!(
            "sim-hall-carried-{name}-{}.mcap",
            std::process::id()
        ));
        std::fs::write(&path, bytes.into_inner()).unwrap();
        let log = vehicle_log::read_log(&path).unwrap();
        std::fs::remove_file(&path).ok();
        let poses = log
            .records
            .iter()
            .filter(|r| matches!(r, Record::TruthPose(_)))
            .count();
        let odom = log
            .records
            .iter()
            .filter(|r| matches!(r, Record::Odom(_)))
            .count();
        assert_eq!((poses, odom), (run.frames.len(), run.odometry.len()));
    }
}

#[test]
fn carried_odometry_keeps_the_noise_of_the_samples_after() {
    // The noise of a sample does not depend on whether the carry's samples were sent.
    let mut none = carried(MovedOdometry::None);
    let mut zero = carried(MovedOdometry::Zero);
    for s in [&mut none, &mut zero] {
        s.spec.noise.velocity_mps = 0.02;
        s.spec.noise.yaw_rate_bias_radps = 0.002;
    }
    let (a, b) = (
        sim::simulate(&none, sim::Mode::Fast).unwrap(),
        sim::simulate(&zero, sim::Mode::Fast).unwrap(),
    );
    assert!(a.odometry.len() + 200 == b.odometry.len());
    let b_sent: Vec<_> = b
        .odometry
        .iter()
        .filter(|o| a.odometry.iter().any(|x| x.t_us == o.t_us))
        .copied()
        .collect();
    assert_eq!(a.odometry, b_sent);
    // "zero" reports rest as any sample at rest: the bias and the white noise.
    let t_carry = a
        .odometry
        .windows(2)
        .find(|w| w[1].t_us - w[0].t_us > 10_000)
        .unwrap()[0]
        .t_us
        + 10_000;
    let during: Vec<_> = b
        .odometry
        .iter()
        .filter(|o| o.t_us >= t_carry && o.t_us < t_carry + 2_000_000)
        .collect();
    assert_eq!(during.len(), 200);
    assert!(during.iter().all(|o| o.vtheta == 0.002), "the bias");
    let rms = (during.iter().map(|o| o.vx * o.vx).sum::<f64>() / 200.0).sqrt();
    assert!((0.015..0.025).contains(&rms), "white noise {rms}");
}

/// paper-experiment without noise, with lamp `dark` off.
fn with_dark(dark: &[u32]) -> sim::Scenario {
    let mut s = common::noise_off(common::shorten(common::load("paper-experiment"), 2));
    s.spec.world.dark = dark.to_vec();
    s
}

#[test]
fn dark_lamps_are_never_seen_nor_drawn_and_the_others_keep_their_ids() {
    let lit = sim::simulate(&with_dark(&[]), sim::Mode::Fast).unwrap();
    let dark = sim::simulate(&with_dark(&[2]), sim::Mode::Fast).unwrap();
    assert!(lit.frames.iter().any(|f| f.views.iter().any(|v| v.id == 2)));
    for (a, b) in lit.frames.iter().zip(&dark.frames) {
        assert!(b.views.iter().all(|v| v.id != 2));
        assert!(
            b.left
                .features
                .iter()
                .chain(&b.right.features)
                .all(|f| f.lamp != Some(2))
        );
        let others: Vec<_> = a.views.iter().filter(|v| v.id != 2).copied().collect();
        assert_eq!(b.views, others);
    }
    // The truth leaves it out; the others keep their ids and positions.
    let ids: Vec<u32> = dark.truth_landmarks().iter().map(|l| l.id).collect();
    assert_eq!(ids, [0, 1, 3, 4]);
    assert_eq!(dark.landmarks.len(), 5);
    assert!(!dark.landmarks[2].lit && dark.landmarks[3].lit);
    assert_eq!(dark.landmarks[3].position, lit.landmarks[3].position);
    let truth: serde_json::Value = serde_json::from_str(&dark.truth_json()).unwrap();
    assert_eq!(truth["landmarks"].as_array().unwrap().len(), 4);
    // Rendered: a dark lamp is not drawn; the image is that of the hall without it.
    let s = with_dark(&[2]);
    let camera = s.true_camera();
    let regs = s.registers();
    let lamps = dark.landmarks.clone();
    let without: Vec<_> = lamps.iter().filter(|l| l.id != 2).copied().collect();
    let pose = lit
        .frames
        .iter()
        .find(|f| f.views.iter().any(|v| v.id == 2 && v.in_left && v.in_right))
        .unwrap()
        .pose;
    let render = |lamps: Vec<sim::Lamp>| {
        sim::Renderer::new(camera, &regs, s.spec.render, lamps)
            .render::<rand_chacha::ChaCha8Rng>(&pose, None)
    };
    let (a, b, c) = (
        render(lamps),
        render(without),
        render(lit.landmarks.clone()),
    );
    assert!(a == b, "a dark lamp is not drawn");
    assert!(a != c, "a lit lamp is drawn");
}

#[test]
fn a_dark_panel_is_not_drawn() {
    let s = common::noise_off(common::shorten(common::load("real-lamps"), 2));
    let n = s.spec.world.lamps.len()
        + s.spec
            .world
            .grids
            .iter()
            .map(|g| g.nx * g.ny)
            .sum::<usize>();
    let first = u32::try_from(n).unwrap();
    let mut dark = s.clone();
    dark.spec.world.dark = (first..first + 4).collect();
    let lit = sim::simulate(&s, sim::Mode::Fast).unwrap();
    let off = sim::simulate(&dark, sim::Mode::Fast).unwrap();
    assert!(lit.landmarks[n].panel.is_some() && !off.landmarks[n].lit);
    let pose = lit
        .frames
        .iter()
        .find(|f| f.views.iter().any(|v| v.id == first))
        .unwrap()
        .pose;
    let regs = s.registers();
    let render = |lamps: Vec<sim::Lamp>| {
        sim::Renderer::new(s.true_camera(), &regs, s.spec.render, lamps)
            .render::<rand_chacha::ChaCha8Rng>(&pose, None)
    };
    let without: Vec<_> = lit
        .landmarks
        .iter()
        .filter(|l| !(first..first + 4).contains(&l.id))
        .copied()
        .collect();
    assert!(render(off.landmarks.clone()) == render(without));
    assert!(render(off.landmarks) != render(lit.landmarks));
}

#[test]
fn added_lamps_come_after_every_other_and_are_seen() {
    let mut s = common::noise_off(common::shorten(common::load("real-lamps"), 2));
    let before = sim::simulate(&s, sim::Mode::Fast).unwrap();
    let n = before.landmarks.len();
    s.spec.world.added = vec![LampSpec {
        x_m: 1.0,
        y_m: 0.1,
        z_m: 3.5,
        radius_m: None,
        radiance_dn: None,
    }];
    let after = sim::simulate(&s, sim::Mode::Fast).unwrap();
    assert_eq!(after.landmarks.len(), n + 1);
    assert_eq!(&after.landmarks[..n], &before.landmarks[..]);
    let added = after.landmarks[n];
    assert_eq!(usize::try_from(added.id).unwrap(), n);
    assert_eq!(added.position, Vector3::new(1.0, 0.1, 3.5));
    assert!(added.panel.is_none() && added.lit);
    assert_eq!(added.radius_m, s.spec.world.lamp_radius_m);
    assert!(
        after
            .frames
            .iter()
            .any(|f| f.views.iter().any(|v| v.id == added.id))
    );
    assert_eq!(after.truth_landmarks().last().unwrap().id, added.id);
}

#[test]
fn world_seed_decouples_the_jitter_from_the_noise() {
    let hall = |seed: u64, world_seed: Option<u64>| {
        let mut s = common::shorten(common::load("aisle"), 2).with_seed(seed);
        s.spec.world.seed = world_seed;
        sim::simulate(&s, sim::Mode::Fast).unwrap()
    };
    let positions = |r: &sim::SimRun| r.landmarks.iter().map(|l| l.position).collect::<Vec<_>>();
    // Without world.seed the jitter follows the seed (as before the key existed).
    let (a, b) = (hall(1, None), hall(2, None));
    assert_ne!(positions(&a), positions(&b));
    assert_eq!(positions(&hall(1, Some(1))), positions(&a));
    // With it, the same hall under other noise.
    let (c, d) = (hall(1, Some(99)), hall(2, Some(99)));
    assert_eq!(positions(&c), positions(&d));
    assert_ne!(positions(&c), positions(&a));
    assert_ne!(c.odometry, d.odometry);
    assert_eq!(
        c.odometry, a.odometry,
        "world.seed does not touch the noise"
    );
}

#[test]
fn the_hall_scenarios_share_their_lamps_and_see_most_of_the_hall() {
    let map = sim::simulate(&common::load("hall-map"), sim::Mode::Fast).unwrap();
    let loc_scenario = common::load("hall-localize");
    let loc = sim::simulate(&loc_scenario, sim::Mode::Fast).unwrap();
    for (name, run) in [("hall-map", &map), ("hall-localize", &loc)] {
        let (min, mean, max) = in_view(run);
        let seconds = run.frames.len() as f64 / 20.0;
        println!(
            "{name}: lamps in view min {min} / mean {mean:.2} / max {max}, {} frames ({seconds:.1} s of frames), last t {:.1} s",
            run.frames.len(),
            (run.frames.last().unwrap().t_us - run.frames[0].t_us) as f64 * 1e-6
        );
        let (fmin, fmean, fmax) = in_field(run, 50.0);
        println!("{name}: within 50 degrees of the axis min {fmin} / mean {fmean:.2} / max {fmax}");
        // The fisheyes' whole raw view reaches rays near 90 degrees: most of the hall.
        assert!(mean >= 30.0, "{name}: {mean}");
        // The navigator's field of use (vslam_ekf::Settings::max_off_axis_deg, 50 degrees):
        // a circle of 5.7 m on the roof, about six lamps, never fewer than two.
        assert!((4.0..=10.0).contains(&fmean), "{name}: {fmean}");
        assert!(fmin >= 2, "{name}: {fmin}");
    }
    // The same hall: the lamps of the map, seven of them dark, three added after them.
    assert_eq!(map.landmarks.len(), 70);
    assert_eq!(loc.landmarks.len(), 73);
    for (a, b) in map.landmarks.iter().zip(&loc.landmarks) {
        assert_eq!((a.id, a.position), (b.id, b.position));
    }
    let dark: Vec<u32> = loc
        .landmarks
        .iter()
        .filter(|l| !l.lit)
        .map(|l| l.id)
        .collect();
    assert_eq!(dark, loc_scenario.spec.world.dark);
    assert_eq!(dark.len(), 7);
    assert_eq!(loc.truth_landmarks().len(), 66);
    // Every lamp of the hall is seen by the mapping drive; the dark ones were on the
    // localising drive's way; so were the added ones.
    let seen = |run: &sim::SimRun, id: u32| {
        run.frames
            .iter()
            .filter(|f| {
                f.views
                    .iter()
                    .any(|v| v.id == id && v.in_left && v.in_right)
            })
            .count()
    };
    for id in 0..70 {
        assert!(seen(&map, id) >= 40, "lamp {id}: {} frames", seen(&map, id));
    }
    let mut all_lit = loc_scenario.clone();
    all_lit.spec.world.dark.clear();
    let lit = sim::simulate(&all_lit, sim::Mode::Fast).unwrap();
    for id in dark {
        assert_eq!(seen(&loc, id), 0);
        assert!(
            seen(&lit, id) >= 40,
            "dark lamp {id} would be seen in {} frames",
            seen(&lit, id)
        );
    }
    for id in 70..73 {
        assert!(
            seen(&loc, id) >= 40,
            "added lamp {id}: {} frames",
            seen(&loc, id)
        );
    }
    // Starts well away from the mapping drive's start; carried once, 8 s blind.
    let p = loc.frames[0].pose;
    assert!((p.x - 12.0).abs() < 1e-12 && (p.y - 6.0).abs() < 1e-12);
    let gap = loc
        .frames
        .windows(2)
        .map(|w| w[1].t_us - w[0].t_us)
        .max()
        .unwrap();
    assert!((7_900_000..=8_100_000).contains(&gap), "{gap}");
}
