//! The sans-IO streaming decoder (board-icd.md section 3).

use crate::error::Corruption;
use crate::packet::{Frame, HEADER_LEN, Header, MAX_PACKET_LEN, SYNC, check_crc};

/// What the decoder found in the stream.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Event<'a> {
    /// A good packet.
    Frame(Frame<'a>),
    /// A packet that started with a sync pattern but was rejected; the search for the next
    /// sync goes on from the byte after this one's sync.
    Corrupt(Corruption),
}

/// The decoder's counters since it was created or reset.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Hash)]
pub struct Stats {
    /// Good packets.
    pub packets: u64,
    /// Packets rejected (bad version, reserved bits or field, counts, CRC, or cut off by the end
    /// of the stream).
    pub corrupt: u64,
    /// Frames lost: the sum of the gaps in frame counters (modulo 2^32) between good packets.
    pub lost: u64,
    /// Bytes that were not part of a good packet.
    pub bytes_skipped: u64,
}

/// Decodes the board's byte stream pushed in chunks of any size, without allocating.
///
/// Feed each chunk to [`decode`](Self::decode) until it returns no event (every byte is then
/// consumed or held), and at the end of the stream drain [`decode_end`](Self::decode_end).
/// A packet that lies whole in the pushed chunk is decoded in place; one split across chunks
/// is assembled in the decoder's own buffer, which never holds more than one packet
/// ([`MAX_PACKET_LEN`] bytes). Garbage always makes progress: every call consumes input or
/// returns an event.
///
/// ```
/// use fpga_link::{Decoder, Event, Header, encode_packet, MAX_PACKET_LEN};
/// use harris_core::Feature;
/// let mut bytes = [0u8; MAX_PACKET_LEN];
/// let header = Header { frame: 7, t_us: 1_000, ..Header::default() };
/// let left = [Feature { x_q4: 160, y_q4: 320, r: 1 << 20 }];
/// let n = encode_packet(&header, &left, &[], &mut bytes)?;
///
/// let mut decoder = Decoder::new();
/// let mut frames = 0;
/// for chunk in bytes[..n].chunks(5) {          // any chunking
///     let mut rest = chunk;
///     loop {
///         let (used, event) = decoder.decode(rest);
///         rest = &rest[used..];
///         match event {
///             Some(Event::Frame(frame)) => {
///                 assert_eq!(frame.left().collect::<Vec<_>>(), left);
///                 frames += 1;
///             }
///             Some(Event::Corrupt(why)) => panic!("{why}"),
///             None => break,
///         }
///     }
/// }
/// assert!(decoder.decode_end().is_none());
/// assert_eq!((frames, decoder.stats().packets), (1, 1));
/// # Ok::<(), fpga_link::EncodeError>(())
/// ```
#[derive(Clone)]
pub struct Decoder {
    /// Bytes of a packet split across chunks; always starts with a prefix of [`SYNC`].
    buf: [u8; MAX_PACKET_LEN],
    len: usize,
    /// Bytes at the front of `buf` that the last returned frame borrowed, dropped next call.
    release: usize,
    last_frame: Option<u32>,
    stats: Stats,
}

impl core::fmt::Debug for Decoder {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Decoder")
            .field("buffered", &self.len)
            .field("last_frame", &self.last_frame)
            .field("stats", &self.stats)
            .finish_non_exhaustive()
    }
}

impl Default for Decoder {
    fn default() -> Self {
        Self::new()
    }
}

/// The outcome of the buffered path.
enum Step {
    /// A good packet of `len` bytes at the front of the buffer.
    Frame {
        header: Header,
        lost: u32,
        len: usize,
    },
    /// The packet at the front of the buffer was rejected.
    Corrupt(Corruption),
    /// All input was taken and the buffer waits for more.
    Pending,
    /// The buffer emptied without a packet; input may remain.
    Drained,
}

/// What the bytes at the front of the buffer need next.
enum Need {
    /// This many bytes in all before the next check.
    Bytes(usize),
}

impl Decoder {
    /// A decoder at the start of a stream.
    pub const fn new() -> Self {
        Self {
            buf: [0; MAX_PACKET_LEN],
            len: 0,
            release: 0,
            last_frame: None,
            stats: Stats {
                packets: 0,
                corrupt: 0,
                lost: 0,
                bytes_skipped: 0,
            },
        }
    }

    /// The counters so far.
    pub fn stats(&self) -> Stats {
        self.stats
    }

    /// Bytes held in the decoder's buffer: the start of a packet waiting for the rest.
    pub fn buffered(&self) -> usize {
        self.len - self.release
    }

    /// Forgets the stream: empties the buffer, zeroes the counters and the frame counter.
    pub fn reset(&mut self) {
        *self = Self::new();
    }

    /// Decodes from `input`: returns how many bytes of `input` were consumed and the next
    /// event, if any. `None` means every byte was consumed (decoded, skipped or buffered) and
    /// more input is needed; call again with the unconsumed rest until then.
    pub fn decode<'a>(&'a mut self, input: &'a [u8]) -> (usize, Option<Event<'a>>) {
        self.drop_released();
        let mut used = 0;
        if self.len > 0 {
            let (n, step) = self.decode_buffered(input, false);
            used = n;
            match step {
                Step::Drained => {} // the buffer held no packet: go on with the input
                step => return (used, self.event(step)),
            }
        }
        let (n, event) = self.decode_in_place(input.get(used..).unwrap_or_default());
        (used + n, event)
    }

    /// Ends the stream: a packet still incomplete is corrupt, and the packets inside its
    /// claimed length are still found. Call until it returns `None`; the decoder is then
    /// empty, with its counters kept.
    pub fn decode_end(&mut self) -> Option<Event<'_>> {
        self.drop_released();
        if self.len == 0 {
            return None;
        }
        let (_, step) = self.decode_buffered(&[], true);
        self.event(step)
    }

    fn event(&self, step: Step) -> Option<Event<'_>> {
        match step {
            Step::Frame { header, lost, len } => Some(Event::Frame(Frame::new(
                header,
                lost,
                self.buf.get(..len).unwrap_or_default(),
            ))),
            Step::Corrupt(why) => Some(Event::Corrupt(why)),
            Step::Pending | Step::Drained => None,
        }
    }

    fn drop_released(&mut self) {
        if self.release > 0 {
            let n = self.release;
            self.release = 0;
            self.drop_front(n);
            self.resync_buffer();
        }
    }

    /// The buffered bytes.
    fn pending(&self) -> &[u8] {
        self.buf.get(..self.len).unwrap_or_default()
    }

    /// Removes `n` bytes from the front of the buffer.
    fn drop_front(&mut self, n: usize) {
        let n = n.min(self.len);
        self.buf.copy_within(n..self.len, 0);
        self.len -= n;
    }

    /// Makes the buffer start at the next sync candidate (a prefix of [`SYNC`] as far as the
    /// bytes go), counting the bytes before it as skipped.
    fn resync_buffer(&mut self) {
        let at = next_candidate(self.pending(), 0).unwrap_or(self.len);
        self.stats.bytes_skipped += at as u64;
        self.drop_front(at);
    }

    /// Rejects the packet at the front of the buffer and resumes the search one byte later.
    fn reject_buffered(&mut self, why: Corruption) -> Step {
        self.stats.corrupt += 1;
        self.stats.bytes_skipped += 1;
        self.drop_front(1);
        self.resync_buffer();
        Step::Corrupt(why)
    }

    fn accept(&mut self, header: &Header) -> u32 {
        let lost = match self.last_frame {
            Some(prev) => header.frame.wrapping_sub(prev).wrapping_sub(1),
            None => 0,
        };
        self.last_frame = Some(header.frame);
        self.stats.packets += 1;
        self.stats.lost += u64::from(lost);
        lost
    }

    /// The buffered path: completes the packet at the front of the buffer from `input`.
    fn decode_buffered(&mut self, input: &[u8], ended: bool) -> (usize, Step) {
        let mut used = 0;
        loop {
            if self.len == 0 {
                return (used, Step::Drained);
            }
            let Need::Bytes(needed) = self.need();
            if self.len < needed {
                let src = input.get(used..).unwrap_or_default();
                let take = (needed - self.len).min(src.len());
                if let (Some(dst), Some(src)) =
                    (self.buf.get_mut(self.len..self.len + take), src.get(..take))
                {
                    dst.copy_from_slice(src);
                    self.len += take;
                    used += take;
                }
            }
            if self.len < needed {
                if !ended {
                    return (used, Step::Pending);
                }
                if self.len < SYNC.len() {
                    // A partial sync at the very end: not a packet.
                    self.stats.bytes_skipped += self.len as u64;
                    self.len = 0;
                    return (used, Step::Drained);
                }
                let why = Corruption::Truncated {
                    received: self.len,
                    expected: needed,
                };
                return (used, self.reject_buffered(why));
            }
            // `needed` bytes are here: check what they allow.
            if self.buf.get(..SYNC.len()) != Some(&SYNC[..]) {
                // The prefix looked like a sync, the fourth byte says otherwise.
                self.stats.bytes_skipped += 1;
                self.drop_front(1);
                self.resync_buffer();
                continue;
            }
            let header = match Header::parse(self.pending()) {
                None => continue, // need() now asks for the header
                Some(Err(why)) => return (used, self.reject_buffered(why)),
                Some(Ok(header)) => header,
            };
            let total = header.packet_len();
            if self.len < total {
                continue; // need() now asks for the whole packet
            }
            if let Err(why) = check_crc(self.buf.get(..total).unwrap_or_default()) {
                return (used, self.reject_buffered(why));
            }
            let lost = self.accept(&header);
            self.release = total;
            return (
                used,
                Step::Frame {
                    header,
                    lost,
                    len: total,
                },
            );
        }
    }

    /// Bytes the front of the buffer needs before the next check.
    fn need(&self) -> Need {
        if self.len < SYNC.len() {
            return Need::Bytes(SYNC.len());
        }
        match Header::parse(self.pending()) {
            None => Need::Bytes(HEADER_LEN),
            Some(Ok(header)) => Need::Bytes(header.packet_len()),
            Some(Err(_)) => Need::Bytes(HEADER_LEN), // rejected as soon as it is looked at
        }
    }

    /// The fast path: packets that lie whole in `input` are decoded where they are.
    fn decode_in_place<'a>(&'a mut self, input: &'a [u8]) -> (usize, Option<Event<'a>>) {
        let mut pos = 0;
        loop {
            let Some(start) = next_candidate(input, pos) else {
                self.stats.bytes_skipped += (input.len() - pos) as u64;
                return (input.len(), None);
            };
            self.stats.bytes_skipped += (start - pos) as u64;
            let rest = input.get(start..).unwrap_or_default();
            if rest.len() < HEADER_LEN {
                // A sync prefix or a short header: keep it for the next chunk.
                return (input.len(), self.hold(rest));
            }
            if rest.get(..SYNC.len()) != Some(&SYNC[..]) {
                self.stats.bytes_skipped += 1;
                pos = start + 1;
                continue;
            }
            let header = match Header::parse(rest) {
                Some(Ok(header)) => header,
                Some(Err(why)) => return (start + 1, Some(self.reject_in_place(why))),
                None => return (input.len(), self.hold(rest)),
            };
            let total = header.packet_len();
            let Some(packet) = rest.get(..total) else {
                return (input.len(), self.hold(rest));
            };
            if let Err(why) = check_crc(packet) {
                return (start + 1, Some(self.reject_in_place(why)));
            }
            let lost = self.accept(&header);
            return (
                start + total,
                Some(Event::Frame(Frame::new(header, lost, packet))),
            );
        }
    }

    fn reject_in_place(&mut self, why: Corruption) -> Event<'static> {
        self.stats.corrupt += 1;
        self.stats.bytes_skipped += 1;
        Event::Corrupt(why)
    }

    /// Buffers the start of a packet (at most one packet's bytes, so it always fits).
    fn hold(&mut self, bytes: &[u8]) -> Option<Event<'static>> {
        let n = bytes.len().min(MAX_PACKET_LEN);
        if let (Some(dst), Some(src)) = (self.buf.get_mut(..n), bytes.get(..n)) {
            dst.copy_from_slice(src);
            self.len = n;
        }
        None
    }
}

/// The first position at or after `from` where `bytes` hold a prefix of [`SYNC`] (the whole
/// sync, or its start cut off by the end of `bytes`).
fn next_candidate(bytes: &[u8], from: usize) -> Option<usize> {
    let mut pos = from;
    loop {
        let at = pos + memchr::memchr(SYNC[0], bytes.get(pos..)?)?;
        let rest = bytes.get(at..).unwrap_or_default();
        let n = rest.len().min(SYNC.len());
        if rest.get(..n) == SYNC.get(..n) {
            return Some(at);
        }
        pos = at + 1;
    }
}
