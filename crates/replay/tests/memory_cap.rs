//! The most memory a navigator takes, checked at its cap (issue 38, item 3): a hall of 347
//! lamps and sprinkler heads driven whole (`hall-radtan.toml`), mapped with the filter's
//! landmarks capped (`vslam_ekf::Settings::max_landmarks`), its heap counted from
//! `Navigator::new` to the end by a counting allocator (this binary's own: nothing else runs in
//! it), against the bound docs/c-api.md states for that cap and phase 1's frames.
#![allow(clippy::unwrap_used, clippy::expect_used, unsafe_code)]

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

use nav::sequencer::{Sequenced, Sequencer};
use nav::{NavSettings, Navigator};
use track::Pixel;

struct Counting;

static LIVE: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);

// SAFETY: every call goes to the system allocator unchanged; the counters only observe.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        // SAFETY: forwarded as given.
        let p = unsafe { System.alloc(layout) };
        if !p.is_null() {
            let now = LIVE.fetch_add(layout.size(), Ordering::Relaxed) + layout.size();
            PEAK.fetch_max(now, Ordering::Relaxed);
        }
        p
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: forwarded as given.
        unsafe { System.dealloc(ptr, layout) };
        LIVE.fetch_sub(layout.size(), Ordering::Relaxed);
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// The bound docs/c-api.md states: the most heap a navigator takes with at most `landmarks`
/// landmarks in its filter and `frames` frames in phase 1's batch, bytes.
fn bound(landmarks: usize, frames: usize) -> usize {
    // The filter's state dimension: the pose, the landmarks, the camera and vehicle
    // parameters (at most 14).
    let n = 3 + 3 * landmarks + 14;
    // The covariance and the update's copies of it (at most four n x n at once), phase 1's
    // batch (per frame: its pose block, its observations and odometry factors), and a fixed
    // part (the tracker, the window, the smoother's dense prior).
    4 * 8 * n * n + 6_000 * frames + 24 * 1024 * 1024
}

/// The heap peak, bytes, of a navigator with `settings` over the hall's log, and the
/// landmarks it mapped.
fn peak(settings: NavSettings) -> (usize, usize) {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/scenarios/hall-radtan.toml");
    let scenario = sim::Scenario::load(&path).unwrap();
    let run = sim::simulate(&scenario, sim::Mode::Fast).unwrap();
    let log = std::path::Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("stereonav-memory-cap-{}.mcap", std::process::id()));
    run.write_log(&log).unwrap();
    let read = vehicle_log::read_log(&log).unwrap();
    std::fs::remove_file(&log).ok();
    let rig = scenario.rig.clone();
    drop(run);
    let base = LIVE.load(Ordering::Relaxed);
    PEAK.store(base, Ordering::Relaxed);
    let mut navigator = Navigator::new(rig, settings).unwrap();
    let mut decoder = fpga_link::Decoder::new();
    let mut window: Sequencer<(Vec<Pixel>, Vec<Pixel>)> = Sequencer::new();
    let feed = |window: &mut Sequencer<(Vec<Pixel>, Vec<Pixel>)>, nav: &mut Navigator| {
        while let Some(input) = window.pop() {
            match input {
                Sequenced::Odometry(s) => {
                    nav.push_odometry(s).ok();
                }
                Sequenced::Frame(t, (l, r)) => {
                    nav.push_frame(t, &l, &r).ok();
                }
            }
        }
    };
    for record in &read.records {
        match record {
            vehicle_log::Record::Odom(s) => window.push_odometry(*s),
            vehicle_log::Record::Features { bytes, .. } => {
                let mut rest: &[u8] = bytes;
                loop {
                    let (used, event) = decoder.decode(rest);
                    rest = &rest[used..];
                    match event {
                        Some(fpga_link::Event::Frame(f)) => {
                            let px = |x: fpga_link::Feature| Pixel::from_q4(x.x_q4, x.y_q4);
                            window.push_frame(
                                f.t_us(),
                                (f.left().map(px).collect(), f.right().map(px).collect()),
                            );
                        }
                        Some(fpga_link::Event::Corrupt(_)) => {}
                        None => break,
                    }
                }
            }
            _ => {}
        }
        feed(&mut window, &mut navigator);
    }
    window.end();
    feed(&mut window, &mut navigator);
    navigator.finish().unwrap();
    let mapped = navigator.ekf().map_or(0, |e| e.landmark_count());
    drop(navigator);
    (PEAK.load(Ordering::Relaxed) - base, mapped)
}

#[test]
fn a_navigator_at_its_landmark_cap_stays_within_the_stated_memory() {
    for cap in [60, 200] {
        let mut settings = NavSettings::default();
        settings.ekf.max_landmarks = cap;
        let frames = settings.phase1.max_frames;
        let (bytes, mapped) = peak(settings);
        eprintln!(
            "cap {cap}: {mapped} landmarks, heap peak {:.1} MiB, bound {:.1} MiB",
            bytes as f64 / 1_048_576.0,
            bound(cap, frames) as f64 / 1_048_576.0
        );
        assert_eq!(
            mapped, cap,
            "the hall has more lamps than the cap: the map is full"
        );
        assert!(
            bytes <= bound(cap, frames),
            "{bytes} bytes over the bound {}",
            bound(cap, frames)
        );
    }
}
