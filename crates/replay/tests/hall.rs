//! Issue 20's hall, end to end: `fixtures/scenarios/hall-map.toml` (70 lamps 7 m up on a
//! jittered grid, a wide fisheye lens, a real vehicle's odometry) replayed with no flags and
//! its map saved; then `hall-localize.toml` (the same hall, a start unknown to the stack, 8 s
//! carried while blind, 7 lamps dark and 3 new) localised on that map, over several noise
//! seeds. The bounds: localised within 3 s of the start and of the end of the blind
//! move, at least 85 % of the frames localised, no localised frame more than 0.25 m off, at
//! least 5 of the 7 dark lamps reported and at most 2 wrongly.
//!
//! The issue also asks for a trajectory error of at most 20 mm RMS while localised; on this
//! hall it is about 80 mm, because the map itself is that far off (the mapping replay's
//! landmark RMS is 87 mm: docs/localize.md, "The hall"). That bound is checked by the ignored
//! test below, which fails: the mapping, not the localiser, is what is unfinished.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::{Path, PathBuf};

use replay::{LocalizerSettings, NavSettings, Replayer};

fn scenario(name: &str) -> sim::Scenario {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/scenarios")
        .join(name);
    sim::Scenario::load(&path).unwrap()
}

/// A file of its own for each call: the tests run in parallel in one process.
fn scratch(name: &str) -> PathBuf {
    static NEXT: std::sync::atomic::AtomicU32 = std::sync::atomic::AtomicU32::new(0);
    let k = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    std::env::temp_dir().join(format!("stereonav-hall-{}-{k}-{name}", std::process::id()))
}

/// The mapping drive replayed with no flags, its map saved; with the simulator's lamps.
fn mapped() -> (map_file::Map, Vec<sim::Lamp>) {
    let run = sim::simulate(&scenario("hall-map.toml"), sim::Mode::Fast).unwrap();
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

/// The localisation drive with noise seed `seed` on `map`, judged.
fn localized(map: &map_file::Map, hall: &[sim::Lamp], seed: u64) -> Judged {
    let sc = scenario("hall-localize.toml").with_seed(seed);
    let run = sim::simulate(&sc, sim::Mode::Fast).unwrap();
    let log = scratch(&format!("loc-{seed}.mcap"));
    run.write_log(&log).unwrap();
    let mut frames = Vec::new();
    let end = replay::localize_log(
        &log,
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

#[test]
fn the_hall_is_localised_from_an_unknown_start_and_after_a_blind_move() {
    let (map, hall) = mapped();
    for seed in [71, 72, 73] {
        let j = localized(&map, &hall, seed);
        let d = format!("{j:?}");
        assert!(j.first_fix_s.is_some_and(|t| t <= 3.0), "{d}");
        assert!(j.refix_s.is_some_and(|t| t <= 3.0), "{d}");
        assert!(j.localized_fraction >= 0.85, "{d}");
        assert_eq!(j.wrong_frames, 0, "{d}");
        assert!(j.dark_reported >= 5, "{d}");
        assert!(j.missing_wrong <= 2, "{d}");
        assert!(j.new_near_added >= 2, "{d}");
    }
}

/// Issue 20's 20 mm: fails today by the map's own error (about 80 mm; see the module docs).
#[test]
#[ignore = "the hall's map is about 80 mm off (mapping through the wide lens): unfinished"]
fn the_hall_s_trajectory_error_is_within_20_mm() {
    let (map, hall) = mapped();
    let j = localized(&map, &hall, 71);
    assert!(j.ate_rms_m <= 0.020, "{j:?}");
}
