//! The packet layout (board-icd.md section 3) and decoded frames.

use crate::Feature;
use crate::error::Corruption;

/// The 4-byte sync pattern that starts every packet.
pub const SYNC: [u8; 4] = [0x5A, 0xA5, 0x3C, 0xC3];
/// The only packet version.
pub const VERSION: u8 = 1;
/// Bytes from the sync to the first feature.
pub const HEADER_LEN: usize = 24;
/// Bytes of one feature: `x_q4` u16, `y_q4` u16, `r` i32.
pub const FEATURE_LEN: usize = 8;
/// Bytes of the trailing CRC-32.
pub const CRC_LEN: usize = 4;
/// Largest feature count of one side.
pub const MAX_COUNT: u16 = 1023;
/// Largest packet: header, 2 x 1023 features, CRC (16,396 bytes).
pub const MAX_PACKET_LEN: usize = packet_len(MAX_COUNT as usize * 2);
/// Flag bit: the left camera had more features than `MAX_FEATURES`.
pub const FLAG_LEFT_OVERFLOW: u8 = 1 << 0;
/// Flag bit: the right camera had more features than `MAX_FEATURES`.
pub const FLAG_RIGHT_OVERFLOW: u8 = 1 << 1;
/// Flag bits that must be zero.
pub const RESERVED_FLAGS: u8 = !(FLAG_LEFT_OVERFLOW | FLAG_RIGHT_OVERFLOW);

// Offsets of the header fields.
const VERSION_AT: usize = 4;
const FLAGS_AT: usize = 5;
const N_LEFT_AT: usize = 6;
const N_RIGHT_AT: usize = 8;
const RESERVED_AT: usize = 10;
const FRAME_AT: usize = 12;
const TIMESTAMP_AT: usize = 16;

/// Bytes of a packet carrying `features` features in all.
pub const fn packet_len(features: usize) -> usize {
    HEADER_LEN + FEATURE_LEN * features + CRC_LEN
}

/// The fields of a packet header.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Hash)]
pub struct Header {
    /// Flags: bit 0 left overflow, bit 1 right overflow.
    pub flags: u8,
    /// Left features in the packet.
    pub n_left: u16,
    /// Right features in the packet.
    pub n_right: u16,
    /// Frame counter, +1 per stereo frame, wrapping.
    pub frame: u32,
    /// Mid-exposure time in microseconds on the vehicle's clock.
    pub t_us: u64,
}

impl Header {
    /// Length of the whole packet this header announces.
    pub fn packet_len(&self) -> usize {
        packet_len(usize::from(self.n_left) + usize::from(self.n_right))
    }

    /// Reads and checks a header from the first [`HEADER_LEN`] bytes of `bytes`, which start
    /// with [`SYNC`]. Returns `None` when fewer bytes are given.
    pub(crate) fn parse(bytes: &[u8]) -> Option<Result<Self, Corruption>> {
        let head: &[u8; HEADER_LEN] = bytes.get(..HEADER_LEN)?.try_into().ok()?;
        let version = head[VERSION_AT];
        let flags = head[FLAGS_AT];
        let n_left = u16_at(head, N_LEFT_AT);
        let n_right = u16_at(head, N_RIGHT_AT);
        let reserved = u16_at(head, RESERVED_AT);
        let check = || {
            if version != VERSION {
                return Err(Corruption::Version {
                    found: version,
                    expected: VERSION,
                });
            }
            if flags & RESERVED_FLAGS != 0 {
                return Err(Corruption::ReservedFlags { flags });
            }
            if reserved != 0 {
                return Err(Corruption::ReservedField { found: reserved });
            }
            if n_left > MAX_COUNT {
                return Err(Corruption::Count {
                    side: "left",
                    count: n_left,
                    max: MAX_COUNT,
                });
            }
            if n_right > MAX_COUNT {
                return Err(Corruption::Count {
                    side: "right",
                    count: n_right,
                    max: MAX_COUNT,
                });
            }
            Ok(Self {
                flags,
                n_left,
                n_right,
                frame: u32_at(head, FRAME_AT),
                t_us: u64::from_le_bytes(array_at(head, TIMESTAMP_AT)),
            })
        };
        Some(check())
    }

    /// Writes the header, sync included, into `out[..HEADER_LEN]`.
    pub(crate) fn write(&self, out: &mut [u8; HEADER_LEN]) {
        out[..4].copy_from_slice(&SYNC);
        out[VERSION_AT] = VERSION;
        out[FLAGS_AT] = self.flags;
        out[N_LEFT_AT..N_LEFT_AT + 2].copy_from_slice(&self.n_left.to_le_bytes());
        out[N_RIGHT_AT..N_RIGHT_AT + 2].copy_from_slice(&self.n_right.to_le_bytes());
        out[RESERVED_AT..RESERVED_AT + 2].copy_from_slice(&[0, 0]);
        out[FRAME_AT..FRAME_AT + 4].copy_from_slice(&self.frame.to_le_bytes());
        out[TIMESTAMP_AT..TIMESTAMP_AT + 8].copy_from_slice(&self.t_us.to_le_bytes());
    }
}

fn array_at<const N: usize>(bytes: &[u8; HEADER_LEN], at: usize) -> [u8; N] {
    let mut out = [0; N];
    if let Some(src) = bytes.get(at..at + N) {
        out.copy_from_slice(src);
    }
    out
}

fn u16_at(bytes: &[u8; HEADER_LEN], at: usize) -> u16 {
    u16::from_le_bytes(array_at(bytes, at))
}

fn u32_at(bytes: &[u8; HEADER_LEN], at: usize) -> u32 {
    u32::from_le_bytes(array_at(bytes, at))
}

/// Checks the CRC of a complete packet (`bytes.len() == header.packet_len()`).
pub(crate) fn check_crc(bytes: &[u8]) -> Result<(), Corruption> {
    let (body, crc) = bytes.split_at(bytes.len().saturating_sub(CRC_LEN));
    let sent = crc.try_into().map_or(0, u32::from_le_bytes);
    let calculated = crc32fast::hash(body.get(SYNC.len()..).unwrap_or_default());
    if sent == calculated {
        Ok(())
    } else {
        Err(Corruption::Crc { sent, calculated })
    }
}

/// One good packet: a stereo frame's features as the board sent them.
///
/// The features are read from the packet's bytes as they are iterated; nothing is copied.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Frame<'a> {
    header: Header,
    /// Frames lost between the previous good packet and this one (counter gap mod 2^32).
    lost_before: u32,
    /// The `8 * (n_left + n_right)` feature bytes.
    features: &'a [u8],
}

impl<'a> Frame<'a> {
    pub(crate) fn new(header: Header, lost_before: u32, packet: &'a [u8]) -> Self {
        let end = packet.len().saturating_sub(CRC_LEN);
        Self {
            header,
            lost_before,
            features: packet.get(HEADER_LEN..end).unwrap_or_default(),
        }
    }

    /// The packet header.
    pub fn header(&self) -> &Header {
        &self.header
    }

    /// Frame counter.
    pub fn frame(&self) -> u32 {
        self.header.frame
    }

    /// Mid-exposure timestamp, microseconds.
    pub fn t_us(&self) -> u64 {
        self.header.t_us
    }

    /// Flags byte.
    pub fn flags(&self) -> u8 {
        self.header.flags
    }

    /// The left camera had more than `MAX_FEATURES` features.
    pub fn left_overflow(&self) -> bool {
        self.header.flags & FLAG_LEFT_OVERFLOW != 0
    }

    /// The right camera had more than `MAX_FEATURES` features.
    pub fn right_overflow(&self) -> bool {
        self.header.flags & FLAG_RIGHT_OVERFLOW != 0
    }

    /// Frames lost just before this one: the gap in frame counters modulo 2^32 since the
    /// previous good packet (0 for the first packet of a stream).
    pub fn lost_before(&self) -> u32 {
        self.lost_before
    }

    /// The left image's features, in the board's order.
    pub fn left(&self) -> Features<'a> {
        let split = FEATURE_LEN * usize::from(self.header.n_left);
        Features(
            self.features
                .get(..split)
                .unwrap_or_default()
                .chunks_exact(FEATURE_LEN),
        )
    }

    /// The right image's features, in the board's order.
    pub fn right(&self) -> Features<'a> {
        let split = FEATURE_LEN * usize::from(self.header.n_left);
        Features(
            self.features
                .get(split..)
                .unwrap_or_default()
                .chunks_exact(FEATURE_LEN),
        )
    }

    /// The raw feature bytes: `n_left` then `n_right` records of 8 little-endian bytes.
    pub fn feature_bytes(&self) -> &'a [u8] {
        self.features
    }
}

/// The features of one camera in a [`Frame`], decoded as iterated.
#[derive(Debug, Clone)]
pub struct Features<'a>(core::slice::ChunksExact<'a, u8>);

impl Iterator for Features<'_> {
    type Item = Feature;

    #[inline]
    fn next(&mut self) -> Option<Feature> {
        self.0.next().map(feature_from_bytes)
    }

    fn size_hint(&self) -> (usize, Option<usize>) {
        self.0.size_hint()
    }
}

impl ExactSizeIterator for Features<'_> {}

#[inline]
fn feature_from_bytes(b: &[u8]) -> Feature {
    let mut rec = [0u8; FEATURE_LEN];
    if let Some(src) = b.get(..FEATURE_LEN) {
        rec.copy_from_slice(src);
    }
    Feature {
        x_q4: u16::from_le_bytes([rec[0], rec[1]]),
        y_q4: u16::from_le_bytes([rec[2], rec[3]]),
        r: i32::from_le_bytes([rec[4], rec[5], rec[6], rec[7]]),
    }
}

/// Writes one feature's 8 bytes.
pub(crate) fn feature_bytes(f: &Feature) -> [u8; FEATURE_LEN] {
    let mut out = [0; FEATURE_LEN];
    out[..2].copy_from_slice(&f.x_q4.to_le_bytes());
    out[2..4].copy_from_slice(&f.y_q4.to_le_bytes());
    out[4..].copy_from_slice(&f.r.to_le_bytes());
    out
}
