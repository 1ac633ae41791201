//! Decoding allocates nothing: a counting global allocator watches a whole realistic stream,
//! split into odd chunks, go through the decoder.
#![allow(unsafe_code)] // a global allocator cannot be written without it
#![allow(clippy::unwrap_used)] // test code

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

use fpga_link::{Decoder, Encoder, Event, Feature};

struct Counting;

static ALLOCATIONS: AtomicUsize = AtomicUsize::new(0);

// SAFETY: forwards to the system allocator, only counting calls.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: same contract as the caller's.
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn decoding_a_stream_allocates_nothing() {
    let features: Vec<Feature> = (0..500u16)
        .map(|i| Feature {
            x_q4: i * 16,
            y_q4: i,
            r: i32::from(i) << 12,
        })
        .collect();
    let mut bytes = Vec::new();
    let mut enc = Encoder::default();
    for t in 0..50 {
        enc.encode_to_vec(t, (&features, false), (&features, t % 3 == 0), &mut bytes)
            .unwrap();
    }
    bytes[20_000] ^= 0x40; // one corrupt packet on the way
    let mut decoder = Box::new(Decoder::new());
    let before = ALLOCATIONS.load(Ordering::Relaxed);
    let (mut frames, mut sum) = (0u32, 0i64);
    for chunk in bytes.chunks(4093) {
        let mut rest = chunk;
        loop {
            let (used, event) = decoder.decode(rest);
            rest = &rest[used..];
            match event {
                Some(Event::Frame(f)) => {
                    frames += 1;
                    sum += f
                        .left()
                        .chain(f.right())
                        .map(|f| i64::from(f.r))
                        .sum::<i64>();
                }
                Some(Event::Corrupt(_)) => {}
                None => break,
            }
        }
    }
    while decoder.decode_end().is_some() {}
    let after = ALLOCATIONS.load(Ordering::Relaxed);
    assert_eq!(after - before, 0, "the decoder allocated");
    assert_eq!(frames, 49);
    assert!(sum > 0);
}
