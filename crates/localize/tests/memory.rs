//! The most memory a localiser takes for a map's size (issue 38, item 3), checked: jittered
//! lamp grids of 160 and 10,000 lamps, a drive from an unknown start with a kidnap (lost,
//! relocalising, localised), the heap counted by this binary's own allocator from the
//! localiser's creation to its end, against the bound docs/c-api.md states.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    unsafe_code,
    clippy::print_stderr
)]

#[path = "support/mod.rs"]
mod support;

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

use support::{FRAMES_10_S, Grid, Hall};

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

/// The bound docs/c-api.md states for a map of `lamps` evenly spread lamps, bytes: the lamps
/// and their grid, the relocalisation's triangles (about 20 a lamp, 28 bytes each, and the
/// sort's copy), and a fixed part (the front end, the hypotheses, the filter).
fn bound(lamps: usize) -> usize {
    lamps * (200 + 2 * 28 * 30) + 8 * 1024 * 1024
}

#[test]
fn a_localiser_stays_within_the_stated_memory_for_its_map() {
    for (nx, ny) in [(16, 10), (125, 80)] {
        let hall = Hall::new(Grid::jittered(nx, ny), 38);
        let base = LIVE.load(Ordering::Relaxed);
        PEAK.store(base, Ordering::Relaxed);
        let outcome =
            support::run(&hall, 38, &[FRAMES_10_S, FRAMES_10_S], &mut |_, _, _, _| {}).unwrap();
        let peak = PEAK.load(Ordering::Relaxed) - base;
        let lamps = nx * ny;
        eprintln!(
            "{lamps} lamps: heap peak {:.1} MiB, bound {:.1} MiB; fixed {:?}",
            peak as f64 / 1_048_576.0,
            bound(lamps) as f64 / 1_048_576.0,
            outcome.legs.iter().map(|l| l.fix_s).collect::<Vec<_>>()
        );
        assert!(
            outcome.legs.iter().all(|l| l.fix_s.is_some()),
            "it localises"
        );
        assert!(
            peak <= bound(lamps),
            "{peak} bytes over the bound {}",
            bound(lamps)
        );
    }
}
