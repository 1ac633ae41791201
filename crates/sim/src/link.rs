//! The link from the board to the vehicle computer: the board's packets (board-icd.md
//! section 3, through [`fpga_link::Encoder`]), their faults, and the chunks the host receives
//! with their arrival times.
//!
//! A packet is ready `ready_latency_us` after its frame's mid-exposure timestamp (read-out and
//! the detector's pipeline), then goes out byte after byte at the link's rate behind the
//! packets before it. A chunk arrives when its last byte has crossed, plus the host's latency
//! and jitter; arrival times never go backwards.

use rand::{Rng, RngExt};

use crate::scenario::{Chunking, Link};

/// What happened to a packet on the link.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum PacketFate {
    /// Sent intact.
    Sent,
    /// Lost whole: none of its bytes arrive.
    Lost,
    /// Sent with one bit flipped: bit `bit` (0 = least significant) of byte `byte`.
    BitFlip {
        /// Offset of the byte in the packet.
        byte: usize,
        /// The bit, `0..8`.
        bit: u8,
    },
}

/// One stereo frame's packet.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Packet {
    /// The stereo frame's [`crate::FrameTruth::index`].
    pub frame_index: usize,
    /// The packet's frame counter.
    pub frame_counter: u32,
    /// The packet's timestamp (mid-exposure), microseconds.
    pub t_us: u64,
    /// The packet as the board encoded it (before any fault).
    pub bytes: Vec<u8>,
    /// What the link did to it.
    pub fate: PacketFate,
}

/// A chunk of the byte stream as the host received it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Chunk {
    /// Arrival time (the log time), nanoseconds on the board's clock.
    pub log_time_ns: u64,
    /// The bytes.
    pub bytes: Vec<u8>,
}

/// Draws each packet's fate: lost with `loss_probability`, else one bit flipped with
/// `bit_flip_probability`.
pub(crate) fn draw_fates(packets: &mut [Packet], link: &Link, rng: &mut impl Rng) {
    for p in packets {
        // Three draws per packet whatever the outcome, so that fates do not shift.
        let lost: f64 = rng.random();
        let flip: f64 = rng.random();
        let at: u64 = rng.random();
        p.fate = if lost < link.loss_probability {
            PacketFate::Lost
        } else if flip < link.bit_flip_probability && !p.bytes.is_empty() {
            let bits = p.bytes.len() as u64 * 8;
            let k = at % bits;
            PacketFate::BitFlip {
                byte: usize::try_from(k / 8).unwrap_or(0),
                bit: u8::try_from(k % 8).unwrap_or(0),
            }
        } else {
            PacketFate::Sent
        };
    }
}

/// The chunks the host receives: the packets that were not lost, with their faults, cut as
/// `link.chunking` says, stamped with their arrival times.
pub(crate) fn chunks(packets: &[Packet], link: &Link, rng: &mut impl Rng) -> Vec<Chunk> {
    let us_per_byte = 1e6 / link.rate_bytes_per_s;
    // The transmitted stream, and for each packet in it: its first byte's offset in the
    // stream and the time (us, float) its transmission starts.
    let mut stream = Vec::new();
    let mut starts: Vec<(usize, f64)> = Vec::new();
    let mut link_free_us = 0.0f64;
    for p in packets {
        let mut bytes = p.bytes.clone();
        match p.fate {
            PacketFate::Lost => continue,
            PacketFate::BitFlip { byte, bit } => {
                if let Some(b) = bytes.get_mut(byte) {
                    *b ^= 1 << bit;
                }
            }
            PacketFate::Sent => {}
        }
        #[allow(clippy::cast_precision_loss)] // microsecond times far below 2^52
        let ready = (p.t_us + link.ready_latency_us) as f64;
        let start = ready.max(link_free_us);
        #[allow(clippy::cast_precision_loss)]
        {
            link_free_us = start + bytes.len() as f64 * us_per_byte;
        }
        starts.push((stream.len(), start));
        stream.extend_from_slice(&bytes);
    }
    // When byte `i` of the stream has crossed the link.
    let crossed_us = |i: usize| -> f64 {
        let k = starts
            .partition_point(|&(off, _)| off <= i)
            .saturating_sub(1);
        let (off, start) = starts.get(k).copied().unwrap_or((0, 0.0));
        #[allow(clippy::cast_precision_loss)]
        let t = start + (i - off + 1) as f64 * us_per_byte;
        t
    };
    let mut cuts: Vec<(usize, usize)> = Vec::new();
    match link.chunking {
        Chunking::Packet => {
            for (k, &(off, _)) in starts.iter().enumerate() {
                let end = starts.get(k + 1).map_or(stream.len(), |&(o, _)| o);
                cuts.push((off, end));
            }
        }
        Chunking::Random => {
            let mut at = 0;
            while at < stream.len() {
                let n = rng.random_range(link.chunk_min_bytes..=link.chunk_max_bytes);
                let end = (at + n).min(stream.len());
                cuts.push((at, end));
                at = end;
            }
        }
    }
    let mut out = Vec::with_capacity(cuts.len());
    let mut last_ns = 0u64;
    for (a, b) in cuts {
        let jitter = rng.random_range(0..=link.host_jitter_us);
        #[allow(clippy::cast_precision_loss)]
        let arrival_us = crossed_us(b.saturating_sub(1)) + (link.host_latency_us + jitter) as f64;
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        // positive and far below 2^63 ns
        let ns = (arrival_us * 1000.0).round() as u64;
        last_ns = last_ns.max(ns);
        out.push(Chunk {
            log_time_ns: last_ns,
            bytes: stream.get(a..b).unwrap_or_default().to_vec(),
        });
    }
    out
}
