//! Why a packet was rejected, and why an encoding failed.

/// The reason a packet that started with a sync pattern was treated as corrupt
/// (board-icd.md section 3).
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum Corruption {
    /// The version byte is not 1.
    #[error("version {found}, expected {expected}")]
    Version {
        /// The version byte found.
        found: u8,
        /// The only version this decoder knows.
        expected: u8,
    },
    /// A flags bit other than the two overflow bits is set.
    #[error("reserved flag bits set: flags 0x{flags:02x}")]
    ReservedFlags {
        /// The flags byte found.
        flags: u8,
    },
    /// The reserved 16-bit field is not 0.
    #[error("reserved field is 0x{found:04x}, expected 0")]
    ReservedField {
        /// The value found.
        found: u16,
    },
    /// A feature count exceeds 1023.
    #[error("{side} count {count} exceeds {max}")]
    Count {
        /// `"left"` or `"right"`.
        side: &'static str,
        /// The count found.
        count: u16,
        /// The largest count allowed.
        max: u16,
    },
    /// The CRC-32 over the packet does not match the one sent.
    #[error("CRC-32 mismatch: sent 0x{sent:08x}, calculated 0x{calculated:08x}")]
    Crc {
        /// The CRC in the packet.
        sent: u32,
        /// The CRC of the bytes received.
        calculated: u32,
    },
    /// The stream ended inside the packet.
    #[error("stream ended after {received} of {expected} bytes")]
    Truncated {
        /// Bytes of the packet received.
        received: usize,
        /// Bytes the packet needed (the header's length, or the header itself when it was
        /// incomplete).
        expected: usize,
    },
}

/// Why a packet could not be encoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum EncodeError {
    /// More features on one side than the wire format carries.
    #[error("{side} has {count} features, at most {max} fit in a packet")]
    TooManyFeatures {
        /// `"left"` or `"right"`.
        side: &'static str,
        /// Features given.
        count: usize,
        /// The largest count allowed.
        max: usize,
    },
    /// The output buffer is too small for the packet.
    #[error("output buffer holds {available} bytes, the packet needs {needed}")]
    BufferTooSmall {
        /// Bytes the packet needs.
        needed: usize,
        /// Bytes available.
        available: usize,
    },
    /// Flags other than the two overflow bits.
    #[error("flags 0x{flags:02x} set reserved bits")]
    ReservedFlags {
        /// The flags given.
        flags: u8,
    },
}
