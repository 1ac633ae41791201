//! The decoder on arbitrary bytes in arbitrary chunks: it never panics, every call makes
//! progress (consumes input or returns an event from buffered bytes), it never holds more than
//! one packet, and every byte ends up in a good packet or counted as skipped.
#![no_main]

use fpga_link::{Decoder, Event, MAX_PACKET_LEN, packet_len};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    // The first byte picks the chunk size, the rest is the stream.
    let Some((&chunk, stream)) = data.split_first() else { return };
    let chunk = usize::from(chunk).max(1);
    let mut decoder = Decoder::new();
    let mut good_bytes = 0u64;
    for part in stream.chunks(chunk) {
        let mut rest = part;
        let mut calls = 0usize;
        loop {
            let (used, event) = decoder.decode(rest);
            assert!(used <= rest.len());
            rest = &rest[used..];
            calls += 1;
            assert!(calls <= part.len() + MAX_PACKET_LEN + 1, "no progress");
            match event {
                Some(Event::Frame(f)) => {
                    good_bytes += packet_len(f.left().len() + f.right().len()) as u64;
                }
                Some(Event::Corrupt(_)) => {}
                None => {
                    assert!(rest.is_empty());
                    break;
                }
            }
            assert!(decoder.buffered() <= MAX_PACKET_LEN);
        }
    }
    while let Some(event) = decoder.decode_end() {
        if let Event::Frame(f) = event {
            good_bytes += packet_len(f.left().len() + f.right().len()) as u64;
        }
    }
    assert_eq!(decoder.buffered(), 0);
    assert_eq!(decoder.stats().bytes_skipped + good_bytes, stream.len() as u64);
});
