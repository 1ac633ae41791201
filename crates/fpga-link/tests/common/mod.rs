//! Helpers shared by the decoder tests.
#![allow(dead_code, unreachable_pub, clippy::unwrap_used)] // test helpers: a failed encode is a test bug

use fpga_link::{Decoder, Encoder, Event, Feature, Stats};

/// A decoded frame, owned, for comparisons.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Owned {
    pub frame: u32,
    pub t_us: u64,
    pub flags: u8,
    pub lost_before: u32,
    pub left: Vec<Feature>,
    pub right: Vec<Feature>,
}

/// Decodes `chunks` in order, then ends the stream; returns frames, corruption count seen as
/// events, and the counters. Checks the decoder's progress and memory invariants on the way.
pub fn decode_chunks<'a>(chunks: impl IntoIterator<Item = &'a [u8]>) -> (Vec<Owned>, u64, Stats) {
    let mut decoder = Decoder::new();
    let mut frames = Vec::new();
    let mut corrupt_events = 0;
    let mut fed = 0u64;
    for chunk in chunks {
        fed += chunk.len() as u64;
        let mut rest = chunk;
        let mut guard = 0usize;
        loop {
            let (used, event) = decoder.decode(rest);
            assert!(used <= rest.len());
            rest = &rest[used..];
            match event {
                Some(Event::Frame(f)) => frames.push(own(&f)),
                Some(Event::Corrupt(_)) => corrupt_events += 1,
                None => {
                    assert!(rest.is_empty(), "None must mean all input was taken");
                    break;
                }
            }
            guard += 1;
            // Each event consumes input or at least one buffered byte.
            assert!(
                guard <= chunk.len() + fpga_link::MAX_PACKET_LEN + 1,
                "no progress"
            );
        }
        assert!(decoder.buffered() <= fpga_link::MAX_PACKET_LEN);
    }
    while let Some(event) = decoder.decode_end() {
        match event {
            Event::Frame(f) => frames.push(own(&f)),
            Event::Corrupt(_) => corrupt_events += 1,
        }
    }
    assert_eq!(decoder.buffered(), 0);
    let stats = decoder.stats();
    let good_bytes: u64 = frames
        .iter()
        .map(|f| fpga_link::packet_len(f.left.len() + f.right.len()) as u64)
        .sum();
    assert_eq!(
        stats.bytes_skipped + good_bytes,
        fed,
        "every byte is accounted for"
    );
    (frames, corrupt_events, stats)
}

pub fn own(f: &fpga_link::Frame<'_>) -> Owned {
    Owned {
        frame: f.frame(),
        t_us: f.t_us(),
        flags: f.flags(),
        lost_before: f.lost_before(),
        left: f.left().collect(),
        right: f.right().collect(),
    }
}

/// A deterministic pseudo-random generator (xorshift64*), so tests need no RNG crate.
pub struct Rng(pub u64);

impl Rng {
    pub fn next_u64(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    pub fn below(&mut self, n: u64) -> u64 {
        self.next_u64() % n.max(1)
    }
}

pub fn features(rng: &mut Rng, n: usize) -> Vec<Feature> {
    (0..n)
        .map(|_| Feature {
            x_q4: rng.next_u64() as u16,
            y_q4: rng.next_u64() as u16,
            r: rng.next_u64() as i32,
        })
        .collect()
}

/// A stream of `frames` packets with `n_left`, `n_right` features each; returns the bytes and
/// the packets' (start, end) offsets.
pub fn stream(
    rng: &mut Rng,
    frames: usize,
    n_left: usize,
    n_right: usize,
) -> (Vec<u8>, Vec<(usize, usize)>, Vec<Owned>) {
    let mut enc = Encoder::starting_at(rng.next_u64() as u32);
    let mut bytes = Vec::new();
    let mut spans = Vec::new();
    let mut expected = Vec::new();
    for i in 0..frames {
        let left = features(rng, n_left);
        let right = features(rng, n_right);
        let flags = (rng.below(4)) as u8;
        let t_us = 1_000_000 + 50_000 * i as u64;
        let frame = enc.next_frame();
        let start = bytes.len();
        enc.encode_to_vec(
            t_us,
            (&left, flags & 1 != 0),
            (&right, flags & 2 != 0),
            &mut bytes,
        )
        .unwrap();
        spans.push((start, bytes.len()));
        expected.push(Owned {
            frame,
            t_us,
            flags,
            lost_before: 0,
            left,
            right,
        });
    }
    (bytes, spans, expected)
}
