//! The decoder against every rule of board-icd.md section 3.

mod common;

use common::{Owned, Rng, decode_chunks, stream};
use fpga_link::{
    Corruption, Decoder, EncodeError, Encoder, Event, Feature, Header, MAX_PACKET_LEN, SYNC,
    encode_packet,
};
use proptest::prelude::*;

fn whole(bytes: &[u8]) -> (Vec<Owned>, u64, fpga_link::Stats) {
    decode_chunks([bytes])
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    /// Encode then decode is the identity under any chunking, for 0..=1023 features a side.
    #[test]
    fn round_trip_under_random_chunking(
        seed in any::<u64>(),
        n_left in 0usize..=1023,
        n_right in 0usize..=1023,
        frames in 1usize..4,
        cuts in proptest::collection::vec(1usize..20_000, 0..12),
    ) {
        let mut rng = Rng(seed | 1);
        let (bytes, _, expected) = stream(&mut rng, frames, n_left, n_right);
        let mut chunks = Vec::new();
        let mut at = 0;
        for cut in cuts {
            let end = (at + cut).min(bytes.len());
            chunks.push(&bytes[at..end]);
            at = end;
        }
        chunks.push(&bytes[at..]);
        let (frames, corrupt, stats) = decode_chunks(chunks);
        prop_assert_eq!(frames, expected);
        prop_assert_eq!((corrupt, stats.corrupt, stats.lost, stats.bytes_skipped), (0, 0, 0, 0));
    }

    /// Garbage of any kind never panics, always makes progress, and every byte is accounted.
    #[test]
    fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..4096), chunk in 1usize..300) {
        let (_, corrupt, stats) = decode_chunks(bytes.chunks(chunk));
        prop_assert_eq!(corrupt, stats.corrupt);
    }

    /// Streams made of packet fragments, syncs and headers (the hard cases for resync).
    #[test]
    fn fragments_of_packets_never_panic(seed in any::<u64>(), pieces in proptest::collection::vec((0usize..4, 0usize..64), 1..40), chunk in 1usize..100) {
        let mut rng = Rng(seed | 1);
        let (good, spans, _) = stream(&mut rng, 3, 3, 2);
        let mut bytes = Vec::new();
        for (kind, len) in pieces {
            match kind {
                0 => bytes.extend_from_slice(&SYNC),
                1 => { let (s, e) = spans[len % spans.len()]; bytes.extend_from_slice(&good[s..e]); }
                2 => { let (s, e) = spans[len % spans.len()]; bytes.extend_from_slice(&good[s..s + (len % (e - s))]); }
                _ => bytes.extend((0..len).map(|_| rng.next_u64() as u8)),
            }
        }
        let (_, corrupt, stats) = decode_chunks(bytes.chunks(chunk));
        prop_assert_eq!(corrupt, stats.corrupt);
    }
}

#[test]
fn every_single_bit_flip_is_detected_and_the_next_packets_still_decode() {
    let mut rng = Rng(7);
    let (bytes, spans, expected) = stream(&mut rng, 3, 5, 4);
    let (start, end) = spans[1];
    for bit in 0..(end - start) * 8 {
        let mut corrupted = bytes.clone();
        corrupted[start + bit / 8] ^= 1 << (bit % 8);
        for chunk in [corrupted.len(), 1, 7] {
            let (frames, _, stats) = decode_chunks(corrupted.chunks(chunk));
            assert_eq!(frames.len(), 2, "bit {bit}, chunk {chunk}: {stats:?}");
            assert_eq!(frames[0], expected[0]);
            assert_eq!(frames[1].left, expected[2].left);
            assert_eq!(frames[1].lost_before, 1, "the flipped frame is lost");
            assert_eq!(stats.lost, 1);
            let sync_hit = bit < 32;
            // A flipped sync is garbage, not a corrupt packet; anything else is caught.
            assert_eq!(stats.corrupt, u64::from(!sync_hit), "bit {bit}");
        }
    }
}

#[test]
fn fake_syncs_inside_payloads_are_not_packets() {
    // Features whose bytes spell the sync pattern and whole fake headers.
    let sync_feature = Feature {
        x_q4: 0xA55A,
        y_q4: 0xC33C,
        r: 0x0000_0001,
    };
    let fake_header = Feature {
        x_q4: 0x0000,
        y_q4: 0x0000,
        r: 0,
    };
    let left = vec![sync_feature, fake_header, sync_feature, sync_feature];
    let mut enc = Encoder::default();
    let mut bytes = Vec::new();
    for _ in 0..3 {
        enc.encode_to_vec(5, (&left, false), (&left, true), &mut bytes)
            .unwrap();
    }
    for chunk in [1, 3, 5, 64, bytes.len()] {
        let (frames, corrupt, stats) = decode_chunks(bytes.chunks(chunk));
        assert_eq!(frames.len(), 3);
        assert!(
            frames
                .iter()
                .all(|f| f.left == left && f.right == left && f.flags == 2)
        );
        assert_eq!((corrupt, stats.bytes_skipped), (0, 0));
    }
}

#[test]
fn garbage_between_packets_is_skipped_and_counted() {
    let mut rng = Rng(11);
    let (bytes, spans, expected) = stream(&mut rng, 4, 10, 10);
    let mut noisy = Vec::new();
    let mut garbage_len = 0;
    for (i, &(s, e)) in spans.iter().enumerate() {
        let garbage: Vec<u8> = (0..(37 * i + 5))
            .map(|_| rng.next_u64() as u8 & 0x7F)
            .collect();
        garbage_len += garbage.len();
        noisy.extend_from_slice(&garbage);
        noisy.extend_from_slice(&bytes[s..e]);
    }
    for chunk in [1, 13, noisy.len()] {
        let (frames, _, stats) = decode_chunks(noisy.chunks(chunk));
        assert_eq!(frames, expected);
        assert_eq!(stats.bytes_skipped, garbage_len as u64);
    }
}

#[test]
fn truncated_packet_at_the_end_is_corrupt_and_its_inside_is_searched() {
    let mut rng = Rng(3);
    let (good, spans, expected) = stream(&mut rng, 2, 2, 1);
    // A packet claiming 1023 + 1023 features, cut short, with two good packets inside it.
    let header = Header {
        n_left: 1023,
        n_right: 1023,
        frame: 99,
        ..Header::default()
    };
    let mut big = vec![0u8; MAX_PACKET_LEN];
    let n = encode_packet(
        &header,
        &vec![Feature::default(); 1023],
        &vec![Feature::default(); 1023],
        &mut big,
    )
    .unwrap();
    let mut bytes = big[..64].to_vec();
    bytes.extend_from_slice(&good);
    assert!(bytes.len() < n);
    for chunk in [1, 100, bytes.len()] {
        let (frames, corrupt, stats) = decode_chunks(bytes.chunks(chunk));
        assert_eq!(frames, expected, "chunk {chunk}");
        assert_eq!((corrupt, stats.corrupt), (1, 1));
        assert_eq!(stats.bytes_skipped, 64);
    }
    // A lone truncated header.
    let (frames, corrupt, _) = whole(&good[..spans[0].1 - 1]);
    assert_eq!((frames.len(), corrupt), (0, 1));
}

#[test]
fn a_wrong_length_does_not_swallow_the_good_packets_behind_it() {
    let mut rng = Rng(5);
    let (good, _, expected) = stream(&mut rng, 5, 1, 1);
    // A header whose counts claim 800 features, then the good packets: its CRC fails once
    // enough bytes arrive, and every good packet behind its sync is still found.
    let mut lying = vec![0u8; 28];
    encode_packet(
        &Header {
            frame: 1,
            ..Header::default()
        },
        &[],
        &[],
        &mut lying,
    )
    .unwrap();
    lying[6..8].copy_from_slice(&800u16.to_le_bytes());
    let mut bytes = lying.clone();
    bytes.extend_from_slice(&good);
    bytes.extend(std::iter::repeat_n(0u8, 7000)); // enough bytes for the claimed length
    for chunk in [1, 17, 4096, bytes.len()] {
        let (frames, corrupt, _) = decode_chunks(bytes.chunks(chunk));
        assert_eq!(frames, expected, "chunk {chunk}");
        assert_eq!(corrupt, 1);
    }
}

#[test]
fn counter_gaps_count_lost_frames_modulo_2_pow_32() {
    let mut bytes = Vec::new();
    let mut out = vec![0u8; 64];
    for frame in [u32::MAX - 2, u32::MAX - 1, u32::MAX, 0, 1, 5, 6] {
        let n = encode_packet(
            &Header {
                frame,
                ..Header::default()
            },
            &[],
            &[],
            &mut out,
        )
        .unwrap();
        bytes.extend_from_slice(&out[..n]);
    }
    let (frames, _, stats) = whole(&bytes);
    assert_eq!(
        frames.iter().map(|f| f.lost_before).collect::<Vec<_>>(),
        [0, 0, 0, 0, 0, 3, 0]
    );
    assert_eq!(stats.lost, 3);
    assert_eq!(stats.packets, 7);
}

#[test]
fn bad_version_reserved_bits_field_and_counts_are_corrupt() {
    let mut template = vec![0u8; 28 + 16];
    let f = [Feature {
        x_q4: 1,
        y_q4: 2,
        r: 3,
    }];
    let n = encode_packet(
        &Header {
            frame: 1,
            ..Header::default()
        },
        &f,
        &f,
        &mut template,
    )
    .unwrap();
    let good = template[..n].to_vec();
    type Case = (usize, u8, fn(&Corruption) -> bool);
    let cases: [Case; 5] = [
        (4, 2, |c| {
            matches!(
                c,
                Corruption::Version {
                    found: 2,
                    expected: 1
                }
            )
        }),
        (5, 0x04, |c| {
            matches!(c, Corruption::ReservedFlags { flags: 0x04 })
        }),
        (10, 1, |c| {
            matches!(c, Corruption::ReservedField { found: 1 })
        }),
        (7, 0x04, |c| {
            matches!(
                c,
                Corruption::Count {
                    side: "left",
                    count: 1025,
                    max: 1023
                }
            )
        }),
        (9, 0x04, |c| {
            matches!(
                c,
                Corruption::Count {
                    side: "right",
                    count: 1025,
                    max: 1023
                }
            )
        }),
    ];
    for (offset, value, expected) in cases {
        let mut bad = good.clone();
        bad[offset] = value;
        let mut stream = bad.clone();
        stream.extend_from_slice(&good);
        for chunk in [1, stream.len()] {
            let mut decoder = Decoder::new();
            let mut events = Vec::new();
            for part in stream.chunks(chunk) {
                let mut rest = part;
                loop {
                    let (used, event) = decoder.decode(rest);
                    rest = &rest[used..];
                    match event {
                        Some(Event::Corrupt(c)) => events.push(Err(c)),
                        Some(Event::Frame(fr)) => events.push(Ok(fr.frame())),
                        None => break,
                    }
                }
            }
            assert_eq!(events.len(), 2, "offset {offset}: {events:?}");
            assert!(
                events[0].as_ref().is_err_and(expected),
                "offset {offset}: {events:?}"
            );
            assert_eq!(events[1], Ok(1));
        }
    }
    // A CRC mismatch names both values.
    let mut bad = good.clone();
    let last = bad.len() - 1;
    bad[last] ^= 0xFF;
    let mut decoder = Decoder::new();
    let (_, event) = decoder.decode(&bad);
    assert!(
        matches!(event, Some(Event::Corrupt(Corruption::Crc { sent, calculated })) if sent != calculated)
    );
}

#[test]
fn only_sync_bytes_and_megabytes_of_zeros() {
    let syncs: Vec<u8> = SYNC.iter().copied().cycle().take(40_000).collect();
    for chunk in [1, 3, 4096, syncs.len()] {
        let (frames, _, stats) = decode_chunks(syncs.chunks(chunk));
        assert!(frames.is_empty());
        assert_eq!(stats.bytes_skipped, syncs.len() as u64);
    }
    let zeros = vec![0u8; 4 << 20];
    let (frames, corrupt, stats) = decode_chunks(zeros.chunks(1 << 20));
    assert!(frames.is_empty());
    assert_eq!((corrupt, stats.bytes_skipped), (0, zeros.len() as u64));
}

#[test]
fn encoder_refuses_what_the_wire_cannot_carry() {
    let mut out = vec![0u8; MAX_PACKET_LEN];
    let too_many = vec![Feature::default(); 1024];
    assert_eq!(
        encode_packet(&Header::default(), &too_many, &[], &mut out),
        Err(EncodeError::TooManyFeatures {
            side: "left",
            count: 1024,
            max: 1023
        })
    );
    assert_eq!(
        encode_packet(&Header::default(), &[], &[], &mut out[..27]),
        Err(EncodeError::BufferTooSmall {
            needed: 28,
            available: 27
        })
    );
    assert_eq!(
        encode_packet(
            &Header {
                flags: 0x80,
                ..Header::default()
            },
            &[],
            &[],
            &mut out
        ),
        Err(EncodeError::ReservedFlags { flags: 0x80 })
    );
    let max = vec![Feature::default(); 1023];
    assert_eq!(
        encode_packet(&Header::default(), &max, &max, &mut out),
        Ok(MAX_PACKET_LEN)
    );
    let mut enc = Encoder::starting_at(u32::MAX);
    enc.encode(0, (&[], false), (&[], false), &mut out).unwrap();
    assert_eq!(enc.next_frame(), 0, "the counter wraps");
}
