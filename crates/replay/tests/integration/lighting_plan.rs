//! A map from a lighting plan (`stereonav map import`, docs/maps.md), localised on end to end:
//! the true lamps of `hall-localize.toml`'s hall (its 70 grid lamps, the 7 dark ones among
//! them, not the 3 fitted after the plan was drawn) written as a survey's CSV with 1 cm of
//! noise, imported without a rig, and the drive localised on it with the scenario's nominal
//! rig. The simulator's truth and the plan are both in the hall's frame, so the poses are
//! compared with the truth directly: it localises early, no localised frame is more than
//! 0.25 m off, and the plan's lamps that are dark on this drive are reported missing.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::fmt::Write as _;

use map_file::Map;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use replay::{LocalizerSettings, WRONG_FIX_M};
use rig_model::Rig;

use crate::scenario;

/// The survey's 1-sigma per coordinate, metres.
const SURVEY_SIGMA_M: f64 = 0.01;

#[test]
fn a_drive_localises_on_the_map_of_its_halls_lighting_plan() {
    let sc = scenario("hall-localize.toml");
    let run = sim::simulate(&sc, sim::Mode::Fast).unwrap();
    // The plan: the hall's lamps (dark or not), without those added since (the last ones).
    let planned = run.landmarks.len() - sc.spec.world.added.len();
    let noise = Normal::new(0.0, SURVEY_SIGMA_M).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(37);
    let mut csv = String::from("# hall-localize's hall, surveyed to 1 cm\nz,x,y,id,sigma\n");
    for lamp in &run.landmarks[..planned] {
        let p = lamp.position.map(|v| v + noise.sample(&mut rng));
        writeln!(csv, "{},{},{},{},{SURVEY_SIGMA_M}", p.z, p.x, p.y, lamp.id).unwrap();
    }
    let map = Map::from_plan(csv.as_bytes(), "hall-plan.csv", 0.02, None).unwrap();
    assert_eq!(map.landmarks.len(), 70);
    assert_eq!(map.format_version(), 2);
    let map = Map::from_bytes(&map.to_bytes().unwrap(), "hall-plan.map").unwrap();

    let log = crate::scratch_log("stereonav-lighting-plan");
    run.write_log(&log).unwrap();
    let localize = |rig: Option<Rig>| {
        let mut frames = Vec::new();
        let end = replay::localize_log(
            &log,
            None,
            &map,
            rig,
            LocalizerSettings::default(),
            &mut |f| {
                frames.push(*f);
                Ok(())
            },
            &mut |_, _| {},
        );
        (end, frames)
    };
    // Without a rig: one line saying what to give.
    let (end, _) = localize(None);
    assert_eq!(
        end.expect_err("a map without a rig").to_string(),
        "the map has no rig (it was imported from the lighting plan hall-plan.csv without one): \
         give the vehicle's rig file (--rig RIG.toml)"
    );
    // With the scenario's nominal rig (what the vehicle's user has).
    let rig = sc.rig.clone();
    let (end, frames) = localize(Some(rig.clone()));
    std::fs::remove_file(&log).ok();
    let end = end.unwrap();
    let truth = end.truth.unwrap();
    let first = frames.first().unwrap().t_us;
    let first_fix_s = end
        .localized_t_us
        .first()
        .map(|&t| (t - first) as f64 * 1e-6);
    let d = format!(
        "first fix {first_fix_s:?} s, {truth:?}, warnings {:?}",
        end.warnings
    );
    assert!(first_fix_s.is_some_and(|t| t <= 3.0), "{d}");
    assert_eq!(truth.wrong_frames, 0, "{d}");
    assert!(truth.ate_max_m <= WRONG_FIX_M, "{d}");
    assert!(
        truth.localized_frames as f64 >= 0.85 * truth.frames as f64,
        "{d}"
    );
    eprintln!(
        "DEBUG {d} missing {:?} new {}",
        end.lamps_missing,
        end.new_lamps.len()
    );
    // The camera is the rig's nominal one, its priors the sigmas (the plan has no calibration).
    let baseline = end
        .parameters
        .iter()
        .find(|p| p.param == rig_model::Param::Baseline)
        .unwrap();
    assert_eq!(baseline.value, rig.nominal.baseline);
    assert_eq!(
        Some(baseline.sigma),
        rig.prior[rig_model::Param::Baseline.index()]
    );
}
