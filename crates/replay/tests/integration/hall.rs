//! Issue 20's hall, end to end. Two halls of 70 lamps 7 m up on a jittered grid, seen through
//! a wide fisheye lens from a forklift with a real vehicle's odometry: the dense hall
//! (`hall-dense-map.toml`, a 2.5 m grid, the issue's acceptance layout, about 25 lamps in view)
//! and the sparse one (`hall-map.toml`, a 4 m grid, about 9 in view). Each mapping drive is
//! replayed with no flags and its map saved; then its localisation drive (`hall-dense-
//! localize.toml`, `hall-localize.toml`: the same hall, a start unknown to the stack, 8 s
//! carried while blind, 7 lamps dark and 3 new) is localised on that map, over several noise
//! seeds. The issue's bounds: localised within 3 s of the start and of the end of the blind
//! move, at least 85 % of the frames localised, no localised frame more than 0.25 m off, at
//! least 5 of the 7 dark lamps reported and at most 2 wrongly.
//!
//! The issue also asks for a trajectory error of at most 20 mm RMS while localised. The
//! localiser's error relative to its map is a few mm; what remains is the map's own scale
//! error (the baseline, which only the lever arm makes observable, 0.1 to 0.3 % off: 20 to
//! 60 mm across a 20 m hall). The dense hall meets 20 mm on its mapping seed (checked below);
//! the sparse hall does not (about 44 mm), which the ignored test records: docs/localize.md,
//! "The hall".
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::PathBuf;

use replay::{LocalizerSettings, NavSettings, Replayer};

use crate::scenario;

/// A file of its own for each call: the tests run in parallel in one process.
fn scratch(name: &str) -> PathBuf {
    static NEXT: std::sync::atomic::AtomicU32 = std::sync::atomic::AtomicU32::new(0);
    let k = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    crate::scratch_dir().join(format!("stereonav-hall-{}-{k}-{name}", std::process::id()))
}

/// The mapping drive `name` replayed with no flags, its map saved; with the simulator's lamps.
fn mapped(name: &str) -> (map_file::Map, Vec<sim::Lamp>) {
    let run = sim::simulate(&scenario(name), sim::Mode::Fast).unwrap();
    let log = scratch("map.mcap");
    run.write_log(&log).unwrap();
    let replayer = Replayer::open(&log, None, &NavSettings::default()).unwrap();
    let rig = replayer.rig().clone();
    let mut sink = replay::ReplayCollector::default();
    let end = replayer.run(&mut sink, &mut |_, _| {}).unwrap();
    let map = replay::saved_map(&end, &rig, &log);
    std::fs::remove_file(&log).ok();
    (map, run.landmarks)
}

/// What the issue judges of one drive (read through `Debug` in the messages).
#[allow(dead_code)]
#[derive(Debug)]
struct Judged {
    seed: u64,
    first_fix_s: Option<f64>,
    refix_s: Option<f64>,
    localized_fraction: f64,
    wrong_frames: u64,
    ate_rms_m: f64,
    dark_reported: usize,
    missing_wrong: usize,
    new_near_added: usize,
}

/// The localisation drive `name` with noise seed `seed` on `map`, judged.
fn localized(map: &map_file::Map, hall: &[sim::Lamp], name: &str, seed: u64) -> Judged {
    let sc = scenario(name).with_seed(seed);
    let run = sim::simulate(&sc, sim::Mode::Fast).unwrap();
    let log = scratch(&format!("loc-{seed}.mcap"));
    run.write_log(&log).unwrap();
    let mut frames = Vec::new();
    let end = replay::localize_log(
        &log,
        None,
        map,
        None,
        LocalizerSettings::default(),
        &mut |f| {
            frames.push(*f);
            Ok(())
        },
        &mut |_, _| {},
    )
    .unwrap();
    std::fs::remove_file(&log).ok();
    let first = frames.first().unwrap().t_us;
    // The blind move: the longest gap between two frames.
    let (gap_end, _) = frames
        .windows(2)
        .map(|w| (w[1].t_us, w[1].t_us - w[0].t_us))
        .max_by_key(|&(_, d)| d)
        .unwrap();
    let s = |t: u64, from: u64| (t - from) as f64 * 1e-6;
    let first_fix_s = end.localized_t_us.first().map(|&t| s(t, first));
    let refix_s = end
        .localized_t_us
        .iter()
        .find(|&&t| t >= gap_end)
        .map(|&t| s(t, gap_end));
    let truth = end.truth.unwrap();
    // A map landmark within 0.75 m of a dark lamp counts as that lamp.
    let near = |p: [f64; 3], q: &nalgebra::Vector3<f64>| (p[0] - q.x).hypot(p[1] - q.y) <= 0.75;
    let position = |id: u64| map.landmarks.iter().find(|l| l.id == id).unwrap().position;
    let dark: Vec<&sim::Lamp> = hall
        .iter()
        .filter(|l| run.landmarks.get(l.id as usize).is_some_and(|r| !r.lit))
        .collect();
    assert_eq!(dark.len(), 7, "the scenario's dark lamps");
    let dark_reported = dark
        .iter()
        .filter(|d| {
            end.lamps_missing
                .iter()
                .any(|&m| near(position(m), &d.position))
        })
        .count();
    let missing_wrong = end
        .lamps_missing
        .iter()
        .filter(|&&m| !dark.iter().any(|d| near(position(m), &d.position)))
        .count();
    let added: Vec<&sim::Lamp> = run.landmarks.iter().skip(hall.len()).collect();
    let new_near_added = end
        .new_lamps
        .iter()
        .filter(|n| {
            added
                .iter()
                .any(|a| near([n.position.x, n.position.y, n.position.z], &a.position))
        })
        .count();
    Judged {
        seed,
        first_fix_s,
        refix_s,
        localized_fraction: truth.localized_frames as f64 / truth.frames as f64,
        wrong_frames: truth.wrong_frames,
        ate_rms_m: truth.ate_rms_m,
        dark_reported,
        missing_wrong,
        new_near_added,
    }
}

/// The issue's bounds other than the 20 mm, for one drive.
fn assert_meets_the_issue(j: &Judged) {
    let d = format!("{j:?}");
    assert!(j.first_fix_s.is_some_and(|t| t <= 3.0), "{d}");
    assert!(j.refix_s.is_some_and(|t| t <= 3.0), "{d}");
    assert!(j.localized_fraction >= 0.85, "{d}");
    assert_eq!(j.wrong_frames, 0, "{d}");
    assert!(j.dark_reported >= 5, "{d}");
    assert!(j.missing_wrong <= 2, "{d}");
    assert!(j.new_near_added >= 2, "{d}");
}

#[test]
fn the_dense_hall_is_localised_from_an_unknown_start_and_after_a_blind_move() {
    let (map, hall) = mapped("hall-dense-map.toml");
    for seed in [81, 82, 83] {
        let j = localized(&map, &hall, "hall-dense-localize.toml", seed);
        assert_meets_the_issue(&j);
        assert!(j.ate_rms_m <= 0.020, "{j:?}");
    }
}

#[test]
fn the_sparse_hall_is_localised_from_an_unknown_start_and_after_a_blind_move() {
    let (map, hall) = mapped("hall-map.toml");
    for seed in [71, 72, 73] {
        assert_meets_the_issue(&localized(&map, &hall, "hall-localize.toml", seed));
    }
}

/// Issue 20's 20 mm on the sparse hall: fails by the map's scale error (about 44 mm; see the
/// module docs).
#[test]
#[ignore = "the sparse hall's map is 0.2 % off in scale (the baseline): about 44 mm, unfinished"]
fn the_sparse_hall_s_trajectory_error_is_within_20_mm() {
    let (map, hall) = mapped("hall-map.toml");
    let j = localized(&map, &hall, "hall-localize.toml", 71);
    assert!(j.ate_rms_m <= 0.020, "{j:?}");
}

/// Issue 37's next day in issue 35's whole hall (`hall-radtan.toml`: 187 lamps and 160
/// sprinkler heads, a radtan lens, five aisles mapped in one drive with no flags):
/// `hall-radtan-localize.toml` starts where the stack does not know, is carried 29.5 m while
/// blind, passes under 7 dark lamps and 3 new ones. The bounds of issue 37 but the 20 mm
/// (below).
#[test]
fn the_radtan_hall_is_localised_the_next_day() {
    let (map, hall) = mapped("hall-radtan.toml");
    let j = localized(&map, &hall, "hall-radtan-localize.toml", 3701);
    assert_meets_the_issue(&j);
}

/// Issue 37's 20 mm on the whole hall: the localiser is a few mm from its map, the map itself
/// (one drive through the hall) about 57 mm RMS from the truth, mostly its scale (issue 35's
/// remainder).
#[test]
#[ignore = "the radtan hall's map is about 57 mm RMS off the truth (its scale): unfinished"]
fn the_radtan_hall_s_trajectory_error_is_within_20_mm() {
    let (map, hall) = mapped("hall-radtan.toml");
    let j = localized(&map, &hall, "hall-radtan-localize.toml", 3701);
    assert!(j.ate_rms_m <= 0.020, "{j:?}");
}

/// Issue 37's lighting plan: the same next-day drive in the radtan hall localised on a map
/// imported from the hall's plan (its 187 lamps only, surveyed to about a centimetre, in the
/// hall's frame; the 160 sprinkler heads the cameras also see are not in it) with the rig's
/// nominal calibration. Judged like a saved map, and within 30 mm RMS.
#[test]
fn the_radtan_hall_is_localised_on_its_lighting_plan() {
    use rand::SeedableRng;
    use rand_distr::Distribution;
    use std::fmt::Write as _;
    let sc = scenario("hall-radtan.toml");
    let run = sim::simulate(&sc, sim::Mode::Fast).unwrap();
    // The 7 m grid's lamps come first (the first grid), the sprinkler heads after them.
    let lamps: Vec<sim::Lamp> = run
        .landmarks
        .iter()
        .filter(|l| l.position.z > 6.85)
        .cloned()
        .collect();
    assert_eq!(lamps.len(), 187);
    let noise = rand_distr::Normal::new(0.0, 0.01).unwrap();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3737);
    let mut csv = String::from("id,x,y,z\n");
    for l in &lamps {
        let p = l.position.map(|v| v + noise.sample(&mut rng));
        writeln!(csv, "{},{},{},{}", l.id, p.x, p.y, p.z).unwrap();
    }
    let map = map_file::Map::from_plan(csv.as_bytes(), "hall-radtan-plan.csv", 0.01, Some(sc.rig))
        .unwrap();
    let j = localized(&map, &lamps, "hall-radtan-localize.toml", 3701);
    assert!(j.first_fix_s.is_some_and(|t| t <= 3.0), "{j:?}");
    assert!(j.refix_s.is_some_and(|t| t <= 3.0), "{j:?}");
    assert!(j.localized_fraction >= 0.85, "{j:?}");
    assert_eq!(j.wrong_frames, 0, "{j:?}");
    assert!(j.ate_rms_m <= 0.030, "{j:?}");
    assert!(j.dark_reported >= 5, "{j:?}");
}
