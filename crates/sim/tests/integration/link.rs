//! The byte stream: it decodes back to the simulated frames, and with faults the decoder's
//! counters match the injected faults.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failure is the test failing

use crate::common;

use fpga_link::SYNC;
use sim::scenario::Chunking;
use sim::{Mode, PacketFate};

#[test]
fn stream_decodes_to_the_simulated_frames_without_faults() {
    for chunking in [Chunking::Packet, Chunking::Random] {
        let mut s = common::noise_off(common::load("warehouse"));
        s = common::shorten(s, 3);
        s.spec.clutter.per_image = 3.0;
        s.spec.link.chunking = chunking;
        s.spec.rates.first_frame = u32::MAX - 5; // the counter wraps
        let run = sim::simulate(&s, Mode::Fast).unwrap();
        assert!(run.packets.iter().all(|p| p.fate == PacketFate::Sent));
        let (decoded, stats) = common::decode(run.chunks.iter().map(|c| c.bytes.as_slice()));
        assert_eq!(decoded.len(), run.frames.len());
        assert_eq!((stats.corrupt, stats.lost, stats.bytes_skipped), (0, 0, 0));
        for (d, f) in decoded.iter().zip(&run.frames) {
            assert_eq!(d.frame, f.frame_counter);
            assert_eq!(d.t_us, f.t_us);
            assert_eq!(d.left, f.left.board_features());
            assert_eq!(d.right, f.right.board_features());
            assert_eq!(
                d.flags,
                u8::from(f.left.overflow) | (u8::from(f.right.overflow) << 1)
            );
        }
        // Chunks arrive after their frame's timestamp, in order.
        assert!(
            run.chunks
                .windows(2)
                .all(|w| w[0].log_time_ns <= w[1].log_time_ns)
        );
        if chunking == Chunking::Packet {
            for (c, f) in run.chunks.iter().zip(&run.frames) {
                let latency_ns = c.log_time_ns - f.t_us * 1000;
                assert!(
                    latency_ns > s.spec.link.ready_latency_us * 1000,
                    "{latency_ns}"
                );
            }
        } else {
            // Chunks cut through packets.
            assert!(run.chunks.iter().any(|c| !c.bytes.starts_with(&SYNC)));
        }
    }
}

#[test]
fn decoder_counters_match_the_injected_faults() {
    let mut s = common::load("warehouse");
    s.spec.link.loss_probability = 0.05;
    s.spec.link.bit_flip_probability = 0.05;
    let run = sim::simulate(&common::shorten(s, 3), Mode::Fast).unwrap();
    let fates: Vec<PacketFate> = run.packets.iter().map(|p| p.fate).collect();
    let lost = fates.iter().filter(|f| **f == PacketFate::Lost).count();
    let flips_in_sync = fates
        .iter()
        .filter(|f| matches!(f, PacketFate::BitFlip { byte, .. } if *byte < SYNC.len()))
        .count();
    let flips = fates
        .iter()
        .filter(|f| matches!(f, PacketFate::BitFlip { .. }))
        .count();
    assert!(lost > 5 && flips > 5, "{lost} {flips}");
    let good: Vec<usize> = (0..fates.len())
        .filter(|&i| fates[i] == PacketFate::Sent)
        .collect();
    let (decoded, stats) = common::decode(run.chunks.iter().map(|c| c.bytes.as_slice()));
    // Every intact packet and only those.
    assert_eq!(stats.packets as usize, good.len());
    let counters: Vec<u32> = good.iter().map(|&i| run.packets[i].frame_counter).collect();
    assert_eq!(
        decoded.iter().map(|d| d.frame).collect::<Vec<_>>(),
        counters
    );
    // A flipped bit anywhere but in the sync makes a corrupt packet (the CRC catches every
    // single-bit error); a flipped sync hides the packet, whose bytes are skipped.
    assert_eq!(stats.corrupt as usize, flips - flips_in_sync);
    // Lost: the gaps in frame counters between the first and the last good packet.
    let (first, last) = (good[0], *good.last().unwrap());
    assert_eq!(stats.lost as usize, last - first + 1 - good.len());
    let good_bytes: usize = good.iter().map(|&i| run.packets[i].bytes.len()).sum();
    let received: usize = run.chunks.iter().map(|c| c.bytes.len()).sum();
    assert_eq!(stats.bytes_skipped as usize, received - good_bytes);
    // Lost packets never reach the host.
    let sent_bytes: usize = run
        .packets
        .iter()
        .filter(|p| p.fate != PacketFate::Lost)
        .map(|p| p.bytes.len())
        .sum();
    assert_eq!(received, sent_bytes);
}
