//! The camera board's feature stream (board-icd.md section 3), both ways.
//!
//! The board sends one packet per stereo frame: a sync pattern, a header (version, overflow
//! flags, feature counts, frame counter, timestamp), the left and right features, and a
//! CRC-32. The host may receive the byte stream in any chunking, with bytes lost or corrupted.
//!
//! * [`Decoder`] is a sans-IO streaming decoder: push chunks, pull [`Event`]s (good frames and
//!   corrupt packets), read the [`Stats`] (packets, corrupt, lost, bytes skipped). It never
//!   allocates, never panics, and holds at most one packet of bytes.
//! * [`encode_packet`] and [`Encoder`] are the board's side, for tests, the simulator and a
//!   board emulator.
//!
//! `#![no_std]` without `alloc` (firmware); `std` turns on run-time CPU detection in the CRC
//! and the sync search.
#![cfg_attr(not(feature = "std"), no_std)]
#![forbid(unsafe_code)]
#![deny(missing_docs)]
#![warn(clippy::cast_possible_truncation, clippy::indexing_slicing)]

#[cfg(feature = "alloc")]
extern crate alloc;

mod decoder;
mod encoder;
mod error;
mod packet;

pub use decoder::{Decoder, Event, Stats};
pub use encoder::{Encoder, encode_packet};
pub use error::{Corruption, EncodeError};
pub use harris_core::Feature;
pub use packet::{
    CRC_LEN, FEATURE_LEN, FLAG_LEFT_OVERFLOW, FLAG_RIGHT_OVERFLOW, Features, Frame, HEADER_LEN,
    Header, MAX_COUNT, MAX_PACKET_LEN, RESERVED_FLAGS, SYNC, VERSION, packet_len,
};
