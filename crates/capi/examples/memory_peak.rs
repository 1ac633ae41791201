//! The heap a navigator takes, at its peak, fed a vehicle log through the C interface (issue
//! 38, item 3's figures): `cargo run --release -p stereonav-capi --example memory_peak --
//! LOG.mcap [RIG.toml]` (without a rig, the log's `/rig`).
//!
//! The log is read whole first; then a counting allocator (the system allocator, with the
//! bytes live and their peak counted) measures from `sn_navigator_new` to
//! `sn_navigator_free`: the peak of the bytes the navigator held at once, and how many
//! allocations it made.
#![allow(clippy::print_stdout, clippy::print_stderr, unsafe_code)]

use std::alloc::{GlobalAlloc, Layout, System};
use std::path::Path;
use std::process::ExitCode;
use std::sync::atomic::{AtomicUsize, Ordering};

use stereonav::{
    sn_navigator, sn_navigator_finish, sn_navigator_free, sn_navigator_landmarks, sn_navigator_new,
    sn_navigator_parameter, sn_navigator_push_odometry, sn_navigator_push_stream,
};

/// The system allocator with the live bytes, their peak and the allocations counted.
struct Counting;

static LIVE: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);
static COUNT: AtomicUsize = AtomicUsize::new(0);

// SAFETY: every call goes to the system allocator with the caller's layout unchanged; the
// counters only observe.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        // SAFETY: forwarded as given.
        let p = unsafe { System.alloc(layout) };
        if !p.is_null() {
            let now = LIVE.fetch_add(layout.size(), Ordering::Relaxed) + layout.size();
            PEAK.fetch_max(now, Ordering::Relaxed);
            COUNT.fetch_add(1, Ordering::Relaxed);
        }
        p
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: forwarded as given.
        unsafe { System.dealloc(ptr, layout) };
        LIVE.fetch_sub(layout.size(), Ordering::Relaxed);
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        // SAFETY: forwarded as given.
        let p = unsafe { System.realloc(ptr, layout, new_size) };
        if !p.is_null() {
            if new_size >= layout.size() {
                let now = LIVE.fetch_add(new_size - layout.size(), Ordering::Relaxed)
                    + (new_size - layout.size());
                PEAK.fetch_max(now, Ordering::Relaxed);
            } else {
                LIVE.fetch_sub(layout.size() - new_size, Ordering::Relaxed);
            }
            COUNT.fetch_add(1, Ordering::Relaxed);
        }
        p
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some(log) = args.first() else {
        eprintln!("usage: memory_peak LOG.mcap [RIG.toml]");
        return ExitCode::FAILURE;
    };
    let read = match vehicle_log::read_log(Path::new(log)) {
        Ok(r) => r,
        Err(e) => {
            eprintln!("memory_peak: {e}");
            return ExitCode::FAILURE;
        }
    };
    let rig_text = match args.get(1) {
        Some(p) => match std::fs::read_to_string(p) {
            Ok(t) => t,
            Err(e) => {
                eprintln!("memory_peak: {p}: {e}");
                return ExitCode::FAILURE;
            }
        },
        None => match read.records.iter().find_map(|r| match r {
            vehicle_log::Record::Rig(t) => Some(t.clone()),
            _ => None,
        }) {
            Some(t) => t,
            None => {
                eprintln!("memory_peak: the log has no /rig: give a rig file");
                return ExitCode::FAILURE;
            }
        },
    };
    let base = LIVE.load(Ordering::Relaxed);
    PEAK.store(base, Ordering::Relaxed);
    let count0 = COUNT.load(Ordering::Relaxed);
    let mut nav: *mut sn_navigator = std::ptr::null_mut();
    let (mut frames, mut done) = (0_usize, 0_usize);
    // SAFETY: the rig text's bytes are readable; `nav` is writable, then a live handle
    // until it is freed at the end; the feature bytes are readable.
    unsafe {
        if sn_navigator_new(rig_text.as_ptr().cast(), rig_text.len(), &raw mut nav) != 0 {
            eprintln!("memory_peak: the rig was refused");
            return ExitCode::FAILURE;
        }
        for r in &read.records {
            match r {
                vehicle_log::Record::Odom(s) => {
                    sn_navigator_push_odometry(nav, s.t_us, s.vx, s.vy, s.vtheta);
                }
                vehicle_log::Record::Features { bytes, .. } => {
                    sn_navigator_push_stream(nav, bytes.as_ptr(), bytes.len(), &raw mut done);
                    frames += done;
                }
                _ => {}
            }
        }
        sn_navigator_finish(nav);
        let (mut count, mut baseline, mut sigma) = (0_usize, 0.0, 0.0);
        sn_navigator_landmarks(nav, std::ptr::null_mut(), 0, &raw mut count);
        sn_navigator_parameter(nav, c"baseline".as_ptr(), &raw mut baseline, &raw mut sigma);
        println!(
            "{log}: {count} landmarks, baseline {:.2} +- {:.2} mm (through the C interface)",
            baseline * 1e3,
            sigma * 1e3
        );
        sn_navigator_free(nav);
    }
    let peak = PEAK.load(Ordering::Relaxed) - base;
    println!(
        "{log}: {frames} frames; the navigator's heap at its peak {:.1} MiB, {} allocations",
        peak as f64 / (1 << 20) as f64,
        COUNT.load(Ordering::Relaxed) - count0
    );
    ExitCode::SUCCESS
}
