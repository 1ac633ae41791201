//! Issue 35: a hall mapped once. Mapping drives through real lenses, simulated with the
//! cameras' whole raw views (a lamp is in view where its raw pixel is), replayed with no
//! flags: every lamp in view for 20 frames or more is one landmark (none twice, none
//! missed but for the odd lamp seen only far out in a fisheye's edge), and the map is honest.
//! docs/halls.md has the measurements behind the bounds.

use std::path::Path;

use replay::{NavSettings, Replayer, TruthErrors};

/// `name` simulated with `seed` (the scenario's own without), replayed with no flags.
fn replayed(name: &str, seed: Option<u64>) -> (TruthErrors, u64) {
    replayed_with(name, seed, None)
}

/// [`replayed`], the lamps laid out from `world` (`[world] seed`) when given.
fn replayed_with(name: &str, seed: Option<u64>, world: Option<u64>) -> (TruthErrors, u64) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/scenarios")
        .join(name);
    let mut scenario = sim::Scenario::load(&path).unwrap();
    if let Some(seed) = seed {
        scenario = scenario.with_seed(seed);
    }
    if let Some(world) = world {
        scenario = scenario.with_world_seed(world);
    }
    let run = sim::simulate(&scenario, sim::Mode::Fast).unwrap();
    static NEXT: std::sync::atomic::AtomicU32 = std::sync::atomic::AtomicU32::new(0);
    let k = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let log = crate::scratch_dir().join(format!(
        "stereonav-once-{}-{k}-{name}.mcap",
        std::process::id()
    ));
    run.write_log(&log).unwrap();
    let replayer = Replayer::open(&log, None, &NavSettings::default()).unwrap();
    let mut sink = replay::ReplayCollector::default();
    let end = replayer.run(&mut sink, &mut |_, _| {}).unwrap();
    std::fs::remove_file(&log).ok();
    (end.truth.unwrap(), end.counts.landmarks_merged)
}

fn assert_once(t: &TruthErrors, what: &str, missed: usize, rms_m: f64) {
    let d = format!("{what}: {t:?}");
    assert_eq!(t.landmarks_duplicate, 0, "{d}");
    assert!(t.lamps_missed <= missed, "{d}");
    // At most 2 % spurious (and one on a small map).
    let total = t.landmarks_matched + t.landmarks_unmatched;
    assert!(t.landmarks_unmatched <= (total / 50).max(1), "{d}");
    assert!(t.landmark_rms <= rms_m, "{d}");
}

/// Our writing of wave 2's held-out fisheye log (36 lamps, three passes, U-turns), which
/// mapped 99 landmarks for 36 lamps: through the fisheye's whole raw view, over three seeds.
/// No lamp twice; the lamps of the two outer rows, seen only more than 55 degrees off the
/// axis, are outside the navigator's field of use and not mapped (the next test).
/// The landmark error is mostly the map's scale (the baseline's prior, 0.3 mm of 119 mm:
/// 20 mm at 15 m).
#[test]
fn a_fisheye_over_three_passes_maps_each_lamp_once() {
    for seed in [None, Some(37), Some(38)] {
        let (t, _) = replayed("fisheye-passes.toml", seed);
        assert_once(&t, &format!("seed {seed:?}"), 0, 0.030);
    }
}

/// Every lamp of the fisheye passes mapped, the outer rows too, seen only far off the axis:
/// they are born from many frames at once in the far band and updated alone there
/// (docs/halls.md, "The far band"; 7 of 36 were not mapped before).
#[test]
fn every_lamp_of_the_fisheye_passes_is_mapped() {
    let (t, _) = replayed("fisheye-passes.toml", None);
    assert_once(&t, "fisheye-passes", 0, 0.030);
}

/// The sparse hall (70 lamps, the TUM VI fisheye at 4.8 m) through the whole raw view: its
/// outer band once made 269 landmarks, then a map 0.9 % small (docs/halls.md).
#[test]
fn the_sparse_fisheye_hall_maps_each_lamp_once_and_to_scale() {
    let (t, _) = replayed("hall-map.toml", None);
    assert_once(&t, "hall-map", 1, 0.080);
}

/// The radtan hall (187 lamps and 160 sprinkler heads, five aisles, the first again): 486
/// landmarks with 158 twins before the fixes. Two lamps seen only from the side on the
/// return along the wall are mapped more than the match radius off, so counted missed (the
/// issue's target is none). A 5-minute drive replayed in about 10 s.
#[test]
fn the_radtan_hall_maps_each_lamp_once() {
    let (t, _) = replayed("hall-radtan.toml", None);
    assert_once(&t, "hall-radtan", 2, 0.070);
}

/// Item 2 of the issue, a loop closed when drift has grown past the gate: `hall-loop.toml`
/// (poor odometry, 100 m without lamps, then the lamps again, 2.8 m of pose sigma). Single
/// lamps matched from the lost pose closed this seed (3.0 mm) but made wrong maps on ten of
/// the seventeen variants below; the lamps are now held while lost and the loop closed when
/// their constellation is recognised (docs/halls.md, "Loops"). Two lamps of the return lane,
/// seen only while held and seconds before the place was recognised, are mapped from where
/// they were held: one 66 mm off, one beyond the match radius (counted missed). 15.3 mm
/// then; 24.9 mm since pairs in the lens's corners update their own landmarks (the outer
/// band, docs/halls.md), with a 41st lamp in view.
#[test]
fn a_loop_through_a_dark_stretch_is_closed() {
    let (t, _) = replayed("hall-loop.toml", None);
    assert_once(&t, "hall-loop", 1, 0.030);
}

/// The loop over seventeen variants (slow tier): the scenario's noise reseeded (seeds 52 to
/// 60) and its lamp grid too (seeds 53 to 60, world seeds 3536 to 3543). Never a wrong map or
/// a twin, on any: no duplicate, at most one landmark beyond the match radius. Closed (at
/// most two lamps missed, landmark RMS within 55 mm) on at least 14. Measured 2026-12-05:
/// closed on all but three of the reseeded grids, where the return lane sees no mapped lamp
/// and the place is recognised only back on the first lane, after the return lane's held
/// lamps have aged out (15 or 16 lamps missed, none wrong).
#[test]
fn slow_loops_through_a_dark_stretch_close_without_a_wrong_map() {
    let mut closed = Vec::new();
    let variants = (52..61)
        .map(|seed| (seed, None))
        .chain((53..61).map(|seed| (seed, Some(seed + 3535 - 52))));
    for (seed, world) in variants {
        let (t, _) = replayed_with("hall-loop.toml", Some(seed), world);
        let d = format!("seed {seed}, world {world:?}: {t:?}");
        assert_eq!(t.landmarks_duplicate, 0, "{d}");
        assert!(t.landmarks_unmatched <= 1, "{d}");
        if t.lamps_missed <= 2 && t.landmark_rms <= 0.055 {
            closed.push((seed, world));
        }
    }
    assert!(closed.len() >= 14, "closed on {closed:?} only");
}

/// Every variant closed with every lamp mapped: needs the lamps held while lost kept precise
/// over the whole lost stretch (their path, not only the pose now), or the place recognised
/// from fewer lamps.
#[test]
#[ignore = "unfinished: lamps seen only while lost are mapped only if the place is recognised within seconds"]
fn loops_through_dark_stretches_are_closed_on_every_seed() {
    let variants = (52..61)
        .map(|seed| (seed, None))
        .chain((53..61).map(|seed| (seed, Some(seed + 3535 - 52))));
    for (seed, world) in variants {
        let (t, _) = replayed_with("hall-loop.toml", Some(seed), world);
        assert_once(
            &t,
            &format!("hall-loop seed {seed}, world {world:?}"),
            0,
            0.050,
        );
    }
}
