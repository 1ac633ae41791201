//! The integration tests of replaying vehicle logs, one module per subject, in one test binary:
//! one link of the crate's dependencies instead of one per file (docs/testing.md).
//! A new file here needs its `mod` line below; a file directly in `tests/` would be a test
//! binary of its own.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failure is the test failing

mod calibrate_log;
mod estimates_reader;
mod hall;
mod lens;
mod lighting_plan;
mod mapped_once;
mod navigate;
mod output;
mod real_log;
mod ros2_bag;
mod slipping_wheels;
mod streaming;
mod vehicle;

/// Hall `seed` of the Monte Carlo (`hall_mc 1 SEED --lens LENS`) as a scenario with its own
/// seed ([`sim::hall::HallSpec::draw`]).
fn hall_scenario(seed: u64, lens: sim::hall::HallLens) -> sim::Scenario {
    let mut spec = sim::hall::HallSpec::draw(seed);
    spec.lens = lens;
    sim::hall::scenario(&spec, seed).unwrap()
}

/// A committed scenario of `fixtures/scenarios` (`name` with its `.toml`).
fn scenario(name: &str) -> sim::Scenario {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/scenarios")
        .join(name);
    sim::Scenario::load(&path).unwrap()
}

/// A simulated drive replayed with `settings`, and its landmarks against the lamps.
struct Run {
    replay: estimates_log::Replay,
    /// Landmarks within 10 cm of a lamp, and of them those inside the 3-D chi-square bound
    /// of 3 sigma (`eval::landmarks_against_lamps`).
    near: usize,
    inside: usize,
    /// The simulator's lamps.
    lamps: Vec<sim::Lamp>,
}

/// Where the suite's scratch logs go: one directory under Cargo's `target/tmp` (which `cargo
/// clean` removes), not the system's temporary directory; created on first use. Each test's
/// file names stay its own (a tag and the process id), and the tests remove their logs.
fn scratch_dir() -> std::path::PathBuf {
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("replay-integration");
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A log named after `tag` and the process id in [`scratch_dir`].
fn scratch_log(tag: &str) -> std::path::PathBuf {
    scratch_dir().join(format!("{tag}-{}.mcap", std::process::id()))
}

/// `sc` simulated as it is (its own seed), written to a log named after `tag` and replayed.
fn replayed_run(sc: &sim::Scenario, tag: &str, settings: &replay::NavSettings) -> Run {
    let sim_run = sim::simulate(sc, sim::Mode::Fast).unwrap();
    let log = scratch_log(tag);
    sim_run.write_log(&log).unwrap();
    let replay = replay::replay_log(&log, None, settings, &mut |_, _| {}).unwrap();
    std::fs::remove_file(&log).ok();
    let (near, inside) = eval::landmarks_against_lamps(
        replay.landmarks.iter().map(|l| (l.position, l.covariance)),
        &sim_run.landmarks,
        0.1,
    );
    Run {
        replay,
        near,
        inside,
        lamps: sim_run.landmarks,
    }
}

/// At least 90 % of the landmarks near a lamp inside 3 sigma of it.
fn assert_nine_in_ten_inside(r: &Run) {
    assert!(
        10 * r.inside >= 9 * r.near,
        "{} of {} inside 3 sigma",
        r.inside,
        r.near
    );
}

/// Each estimated parameter's error and its sigma.
fn parameters(r: &estimates_log::Replay) -> Vec<(rig_model::Param, f64, f64)> {
    let t = r.truth.as_ref().unwrap();
    r.final_camera
        .iter()
        .filter(|c| c.sigma > 0.0)
        .map(|c| {
            let error = t.camera.iter().find(|(q, _)| *q == c.param).unwrap().1;
            (c.param, error, c.sigma)
        })
        .collect()
}
