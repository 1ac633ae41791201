//! The board's side of the link: packets from features.

#[cfg(feature = "alloc")]
use alloc::vec::Vec;

use crate::Feature;
use crate::error::EncodeError;
use crate::packet::{
    CRC_LEN, FEATURE_LEN, HEADER_LEN, Header, MAX_COUNT, RESERVED_FLAGS, SYNC, feature_bytes,
    packet_len,
};

/// Writes one packet for a stereo frame into `out` and returns its length
/// (board-icd.md section 3). `header.n_left` and `header.n_right` are taken from the slices.
pub fn encode_packet(
    header: &Header,
    left: &[Feature],
    right: &[Feature],
    out: &mut [u8],
) -> Result<usize, EncodeError> {
    let count = |side, features: &[Feature]| {
        u16::try_from(features.len())
            .ok()
            .filter(|&n| n <= MAX_COUNT)
            .ok_or(EncodeError::TooManyFeatures {
                side,
                count: features.len(),
                max: usize::from(MAX_COUNT),
            })
    };
    let header = Header {
        n_left: count("left", left)?,
        n_right: count("right", right)?,
        ..*header
    };
    if header.flags & RESERVED_FLAGS != 0 {
        return Err(EncodeError::ReservedFlags {
            flags: header.flags,
        });
    }
    let len = packet_len(left.len() + right.len());
    let available = out.len();
    let Some(out) = out.get_mut(..len) else {
        return Err(EncodeError::BufferTooSmall {
            needed: len,
            available,
        });
    };
    let (covered, crc) = out.split_at_mut(len - CRC_LEN);
    let (head, body) = covered.split_at_mut(HEADER_LEN);
    if let Ok(head) = <&mut [u8; HEADER_LEN]>::try_from(head) {
        header.write(head);
    }
    for (dst, f) in body
        .chunks_exact_mut(FEATURE_LEN)
        .zip(left.iter().chain(right))
    {
        dst.copy_from_slice(&feature_bytes(f));
    }
    // The CRC covers everything but the sync and itself.
    let crc_value = crc32fast::hash(covered.get(SYNC.len()..).unwrap_or_default());
    crc.copy_from_slice(&crc_value.to_le_bytes());
    Ok(len)
}

/// The board's packet writer: numbers frames and sets the overflow flags.
#[derive(Debug, Clone, Default)]
pub struct Encoder {
    next_frame: u32,
}

impl Encoder {
    /// An encoder whose first packet carries frame counter `first_frame`.
    pub fn starting_at(first_frame: u32) -> Self {
        Self {
            next_frame: first_frame,
        }
    }

    /// The counter the next packet will carry.
    pub fn next_frame(&self) -> u32 {
        self.next_frame
    }

    /// Writes the next frame's packet into `out` and returns its length. The frame counter
    /// advances (wrapping) only when the packet was written.
    pub fn encode(
        &mut self,
        t_us: u64,
        left: (&[Feature], bool),
        right: (&[Feature], bool),
        out: &mut [u8],
    ) -> Result<usize, EncodeError> {
        let flags = u8::from(left.1) | (u8::from(right.1) << 1);
        let header = Header {
            flags,
            frame: self.next_frame,
            t_us,
            ..Header::default()
        };
        let n = encode_packet(&header, left.0, right.0, out)?;
        self.next_frame = self.next_frame.wrapping_add(1);
        Ok(n)
    }

    /// Appends the next frame's packet to `out` (feature `alloc`).
    #[cfg(feature = "alloc")]
    pub fn encode_to_vec(
        &mut self,
        t_us: u64,
        left: (&[Feature], bool),
        right: (&[Feature], bool),
        out: &mut Vec<u8>,
    ) -> Result<usize, EncodeError> {
        let start = out.len();
        out.resize(start + packet_len(left.0.len() + right.0.len()), 0);
        let result = self.encode(t_us, left, right, out.get_mut(start..).unwrap_or_default());
        if result.is_err() {
            out.truncate(start);
        }
        result
    }
}
