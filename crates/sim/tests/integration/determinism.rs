//! Same seed, same bytes; another seed, other bytes.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failure is the test failing

use crate::common;

use std::io::Cursor;

fn log_bytes(scenario: &sim::Scenario, mode: sim::Mode) -> Vec<u8> {
    let run = sim::simulate(scenario, mode).unwrap();
    run.write_log_to(Cursor::new(Vec::new()))
        .unwrap()
        .into_inner()
}

#[test]
fn same_seed_same_log_bytes_and_another_seed_other_bytes() {
    // The warehouse has every random source: jittered lamps, odometry noise, pixel noise,
    // clutter, lost packets, bit flips, random chunking and host jitter.
    let s = common::shorten(common::load("warehouse"), 3);
    let a = log_bytes(&s, sim::Mode::Fast);
    let b = log_bytes(&s, sim::Mode::Fast);
    assert!(a.len() > 10_000, "{}", a.len());
    assert_eq!(a, b, "same seed, same bytes");
    let c = log_bytes(&s.clone().with_seed(s.spec.seed + 1), sim::Mode::Fast);
    assert_ne!(a, c, "another seed, other bytes");
    // And the stream itself differs, not only the odometry.
    let ra = sim::simulate(&s, sim::Mode::Fast).unwrap();
    let rc = sim::simulate(&s.clone().with_seed(s.spec.seed + 1), sim::Mode::Fast).unwrap();
    assert_ne!(ra.stream_bytes(), rc.stream_bytes());
    assert_ne!(ra.landmarks, rc.landmarks, "grid jitter follows the seed");
}

#[test]
fn rendered_mode_is_deterministic_whatever_the_threads() {
    // Per-frame noise streams: the worker threads cannot change the bytes.
    let mut s = common::shorten(common::load("paper-experiment"), 2);
    s.spec.path.segments[0] = sim::scenario::Segment::wait(0.2);
    s.spec.path.segments[1] = sim::scenario::Segment::straight(0.5);
    let a = sim::simulate(&s, sim::Mode::Rendered).unwrap();
    let b = sim::simulate(&s, sim::Mode::Rendered).unwrap();
    assert!(
        a.frames.len() > 64,
        "more than one batch: {}",
        a.frames.len()
    );
    assert_eq!(a.stream_bytes(), b.stream_bytes());
    assert_eq!(a.frames, b.frames);
}
