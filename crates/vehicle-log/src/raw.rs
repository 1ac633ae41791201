//! The MCAP record scanner under [`crate::LogReader`]: every record it can still read, of any
//! topic, with the losses in band.
//!
//! Why a scanner of our own: the `mcap` crate's readers stop at the first error (its sans-IO
//! `LinearReader` ends at a bad chunk CRC, an unknown compression or a length that runs past
//! the end), and the indexed reader needs an intact summary. A vehicle log damaged by bit
//! errors or cut by a power loss still holds readable chunks after the damage, so this module
//! walks the outer records itself, skips what it cannot use and finds its way back to the
//! next chunk. It uses the `mcap` crate for the record bodies ([`mcap::parse_record`]) and the
//! `zstd` and `lz4` crates for the chunks.
//!
//! The file format is the MCAP specification's (mcap.dev/spec): magic, records of `opcode u8,
//! length u64, body` (little-endian), magic. Memory: one chunk at a time (its compressed and
//! its uncompressed bytes, each at most [`MAX_RECORD_LEN`]), the summary's schemas, channels
//! and chunk index, and a 64 KiB read buffer.

use std::collections::{BTreeMap, HashMap, HashSet, VecDeque};
use std::fs::File;
use std::io::{ErrorKind, Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

use mcap::records::{self, op};

use crate::damage::{Damage, LostSpan, SummaryState};
use crate::error::{Error, NotMcap, Result};

/// The largest record or chunk the reader accepts, bytes: a corrupt length must not make it
/// allocate without bound. Larger than any chunk [`crate::LogWriter`] writes.
pub const MAX_RECORD_LEN: usize = 256 << 20;

/// [`MAX_RECORD_LEN`] as a file length.
const MAX_RECORD_LEN_U64: u64 = MAX_RECORD_LEN as u64;

/// Opcode u8 and length u64 before every record body.
const RECORD_HEADER_LEN: u64 = 9;

/// Footer body: summary_start u64, summary_offset_start u64, summary_crc u32.
const FOOTER_BODY_LEN: u64 = 20;

/// The footer record, header included.
const FOOTER_RECORD_LEN: u64 = RECORD_HEADER_LEN + FOOTER_BODY_LEN;

/// Footer bytes covered by the summary CRC: opcode, length, summary_start, summary_offset_start.
const FOOTER_CRC_COVERED: u64 = RECORD_HEADER_LEN + 16;

/// Chunk body up to its compression string's bytes: message_start_time u64,
/// message_end_time u64, uncompressed_size u64, uncompressed_crc u32, compression length u32.
const CHUNK_FIXED_LEN: u64 = 8 + 8 + 8 + 4 + 4;

/// The records length (u64) after the compression string.
const CHUNK_RECORDS_LEN_LEN: u64 = 8;

/// Longest compression string a chunk may name ("zstd"; anything longer is no chunk header).
const MAX_COMPRESSION_LEN: u64 = 16;

/// Bytes read to parse a chunk header: record header, fixed part, compression, records length.
const CHUNK_PEEK_LEN: usize =
    (RECORD_HEADER_LEN + CHUNK_FIXED_LEN + MAX_COMPRESSION_LEN + CHUNK_RECORDS_LEN_LEN) as usize;

/// Bytes the source reads at a time.
const READ_BUF_LEN: usize = 64 << 10;

/// Length of the MCAP magic at both ends of a file.
const MAGIC_LEN: u64 = 8;

/// A schema record.
#[derive(Debug, Clone, PartialEq, Eq)]
#[non_exhaustive]
pub struct RawSchema {
    /// Its id (never 0).
    pub id: u16,
    /// Its name.
    pub name: String,
    /// Its encoding (`jsonschema`, `ros2msg`, ...).
    pub encoding: String,
    /// The schema document.
    pub data: Vec<u8>,
}

/// A channel record.
#[derive(Debug, Clone, PartialEq, Eq)]
#[non_exhaustive]
pub struct RawChannel {
    /// Its id.
    pub id: u16,
    /// Its schema's id, 0 for none.
    pub schema_id: u16,
    /// Its topic.
    pub topic: String,
    /// Its message encoding.
    pub message_encoding: String,
    /// Its metadata.
    pub metadata: BTreeMap<String, String>,
}

/// A message record.
#[derive(Debug, Clone, PartialEq, Eq)]
#[non_exhaustive]
pub struct RawMessage {
    /// The channel it was logged on.
    pub channel_id: u16,
    /// The writer's sequence number.
    pub sequence: u32,
    /// Log time, ns.
    pub log_time: u64,
    /// Publish time, ns.
    pub publish_time: u64,
    /// The message.
    pub data: Vec<u8>,
    /// Whether it came from a chunk whose CRC checked (a message outside chunks, in a chunk
    /// without a CRC, or in the readable prefix of a chunk cut by the end of the file has none).
    pub verified: bool,
}

/// One record of a log as [`RawReader`] yields it.
#[derive(Debug, Clone, PartialEq, Eq)]
#[non_exhaustive]
pub enum RawRecord {
    /// A schema, before the first channel that uses it.
    Schema(RawSchema),
    /// A channel, before its first message.
    Channel(RawChannel),
    /// A message.
    Message(RawMessage),
    /// Data that could not be read, at the place of the loss (just before the next good
    /// message), when it may have held messages.
    Lost(LostSpan),
}

/// Where the file was found to be cut.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum CutAt {
    /// Inside its data section (a record runs past the end, or no data end record).
    Data,
    /// Inside its summary section (after the data end record).
    Summary,
}

/// A chunk of the summary's chunk index.
#[derive(Debug, Clone)]
struct IndexedChunk {
    offset: u64,
    length: u64,
    start_ns: u64,
    end_ns: u64,
    /// Channels with a message index record after the chunk.
    channels: Vec<u16>,
}

/// What the summary section gave.
#[derive(Debug, Default)]
struct Summary {
    schemas: BTreeMap<u16, RawSchema>,
    channels: BTreeMap<u16, RawChannel>,
    /// By offset.
    chunks: Vec<IndexedChunk>,
    /// Messages per channel, from the statistics record.
    counts: Option<BTreeMap<u16, u64>>,
}

/// A chunk's header fields.
#[derive(Debug, Clone)]
struct ChunkHead {
    start_ns: u64,
    end_ns: u64,
    uncompressed_size: u64,
    crc: u32,
    compression: String,
    /// File offset of the compressed records.
    records_at: u64,
    /// The records' length as the chunk body says.
    records_len: u64,
}

/// A decoded chunk whose records are being yielded.
#[derive(Debug)]
struct OpenChunk {
    data: Vec<u8>,
    at: usize,
    verified: bool,
    /// The chunk is the readable prefix of one cut by the end of the file.
    cut: Option<ChunkHead>,
    /// File offset of the chunk record.
    offset: u64,
}

/// One lost chunk that message index records after it may still describe.
#[derive(Debug)]
struct ChunkPiece {
    /// Times: (start, end, trusted): trusted from the summary's chunk index.
    times: Option<(u64, u64, bool)>,
    /// The chunk is cut by the end of the file.
    cut: bool,
    header_times: (u64, u64),
    /// Messages per channel from the message index records met after the chunk.
    counts: Option<BTreeMap<u16, u64>>,
    index_times: Option<(u64, u64)>,
    /// Channels the summary's chunk index says have message index records.
    expected: Option<Vec<u16>>,
}

/// The times of a loss that lost no message yet: an empty span.
const NO_TIMES: (u64, u64, bool) = (u64::MAX, 0, true);

/// A loss not yet yielded: the next good message sets its end.
#[derive(Debug)]
struct PendingLoss {
    offset: u64,
    bytes: u64,
    chunks: u64,
    why: String,
    pieces: u64,
    /// Messages per channel of the folded pieces; `None` once one did not know.
    counts: Option<BTreeMap<u16, u64>>,
    /// (earliest start, latest end, every piece trusted) of the folded pieces, `None` once
    /// one had no times.
    times: Option<(u64, u64, bool)>,
    /// The last good message's log time before the loss.
    before_ns: Option<u64>,
    /// The last lost chunk, still open to its message index records.
    open: Option<ChunkPiece>,
    /// A chunk cut by the end of the file is among the pieces: its span runs from the last
    /// message read to its header's end time, bounds rather than the lost messages' own.
    cut: bool,
}

impl PendingLoss {
    /// A loss starting at `offset`, after a good message at `before_ns`.
    fn new(offset: u64, why: String, before_ns: Option<u64>) -> Self {
        Self {
            offset,
            bytes: 0,
            chunks: 0,
            why,
            pieces: 0,
            counts: Some(BTreeMap::new()),
            times: Some(NO_TIMES),
            before_ns,
            open: None,
            cut: false,
        }
    }
}

/// Messages per channel of two losses together; `None` when either does not know.
fn add_counts(
    a: Option<BTreeMap<u16, u64>>,
    b: Option<BTreeMap<u16, u64>>,
) -> Option<BTreeMap<u16, u64>> {
    let (mut a, b) = (a?, b?);
    for (channel, n) in b {
        *a.entry(channel).or_default() += n;
    }
    Some(a)
}

/// A file source with a read buffer, its length known.
struct Source<R> {
    inner: R,
    len: u64,
    buf: Vec<u8>,
    /// File offset of `buf[0]`.
    start: u64,
    /// The inner reader's position.
    at: u64,
}

impl<R: Read + Seek> Source<R> {
    fn new(mut inner: R) -> std::io::Result<Self> {
        let len = inner.seek(SeekFrom::End(0))?;
        Ok(Self {
            inner,
            len,
            buf: Vec::new(),
            start: 0,
            at: len,
        })
    }

    /// Up to `n` bytes at `offset`: fewer only at the end of the file.
    fn bytes(&mut self, offset: u64, n: usize) -> std::io::Result<&[u8]> {
        if offset >= self.len {
            return Ok(&[]);
        }
        let end = offset.saturating_add(n as u64).min(self.len);
        let buf_end = self.start + self.buf.len() as u64;
        if offset < self.start || end > buf_end {
            let want = (end - offset)
                .max(READ_BUF_LEN as u64)
                .min(self.len - offset);
            self.buf.clear();
            self.buf
                .resize(usize::try_from(want).unwrap_or(READ_BUF_LEN), 0);
            self.seek(offset)?;
            let got = read_up_to(&mut self.inner, &mut self.buf)?;
            self.buf.truncate(got);
            self.start = offset;
            self.at = offset + got as u64;
        }
        let from = usize::try_from(offset - self.start).unwrap_or(usize::MAX);
        let to = usize::try_from(end - self.start).unwrap_or(usize::MAX);
        Ok(self.buf.get(from..to.min(self.buf.len())).unwrap_or(&[]))
    }

    /// Reads `len` bytes at `offset` into `out` (fewer at the end of the file).
    fn read_into(&mut self, offset: u64, len: u64, out: &mut Vec<u8>) -> std::io::Result<()> {
        out.clear();
        let len = len.min(self.len.saturating_sub(offset));
        let end = offset + len;
        // What the read buffer already holds is not read again.
        let buf_end = self.start + self.buf.len() as u64;
        let mut from = offset;
        if offset >= self.start && offset < buf_end {
            let a = usize::try_from(offset - self.start).unwrap_or(usize::MAX);
            let b = usize::try_from(end.min(buf_end) - self.start).unwrap_or(usize::MAX);
            out.extend_from_slice(self.buf.get(a..b).unwrap_or(&[]));
            from = end.min(buf_end);
        }
        if from < end {
            self.seek(from)?;
            let got = (&mut self.inner).take(end - from).read_to_end(out)?;
            self.at = from + got as u64;
        }
        Ok(())
    }

    fn seek(&mut self, offset: u64) -> std::io::Result<()> {
        if self.at != offset {
            self.inner.seek(SeekFrom::Start(offset))?;
            self.at = offset;
        }
        Ok(())
    }
}

/// Streams every readable schema, channel and message of an MCAP file in file order, with
/// [`RawRecord::Lost`] where data could not be read; [`RawReader::damage`] totals the losses.
///
/// Schemas and channels come from the summary section first when it is intact (each once,
/// just before the first channel or message that needs it, or at the end), so that a damaged
/// first chunk does not orphan the messages of later ones. A chunk whose CRC fails or that
/// does not decompress is skipped; where the record framing is lost the reader goes on at the
/// next chunk of the summary's chunk index, or at the next plausible chunk record it finds by
/// scanning. Only an I/O error ends the iteration with an `Err`.
pub struct RawReader<R = File> {
    src: Source<R>,
    path: PathBuf,
    /// Next top-level record.
    pos: u64,
    /// Where the linear pass stops: the summary's start when it is intact, else the file end.
    data_end: u64,
    /// The start of a summary that could not be used, from its footer: bytes past it are not
    /// counted as lost data.
    summary_hint: Option<u64>,
    /// Resyncing looks for a chunk at or after this offset (past every chunk met so far).
    floor: u64,
    summary: Summary,
    chunk: Option<OpenChunk>,
    /// Whether any chunk record was met or indexed (else resync looks for bare records).
    chunked: bool,
    schemas_out: HashSet<u16>,
    channels_out: HashMap<u16, String>,
    read_counts: BTreeMap<u16, u64>,
    out: VecDeque<RawRecord>,
    pending: Option<PendingLoss>,
    last_ns: Option<u64>,
    damage: Damage,
    cut_at: Option<CutAt>,
    profile: Option<String>,
    /// Reading stopped at the data end record (or the footer).
    data_end_met: bool,
    done: bool,
    /// Scratch buffer for a chunk's compressed bytes.
    compressed: Vec<u8>,
    /// Whether chunks damaged by one flipped bit are mended ([`RawReader::mend_bit_errors`]).
    mend: bool,
    /// Lost bytes are counted up to here (the reader may look at a region twice).
    lost_to: u64,
}

impl<R> std::fmt::Debug for RawReader<R> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RawReader")
            .field("path", &self.path)
            .field("pos", &self.pos)
            .field("len", &self.src.len)
            .field("damage", &self.damage)
            .field("done", &self.done)
            .finish_non_exhaustive()
    }
}

impl RawReader<File> {
    /// Opens the MCAP file at `path`.
    pub fn open(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let file = File::open(path).map_err(|source| Error::Open {
            path: path.to_path_buf(),
            source,
        })?;
        Self::new(file, path)
    }
}

impl<R> RawReader<R> {
    /// The profile of the header record (`ros2`, ...), once read; empty for none.
    pub fn profile(&self) -> Option<&str> {
        self.profile.as_deref()
    }

    /// How far the reading has come, bytes of the file.
    pub fn position(&self) -> u64 {
        self.pos.min(self.src.len)
    }

    /// The file's length, bytes.
    pub fn file_len(&self) -> u64 {
        self.src.len
    }

    /// The file (or the name given to [`RawReader::new`]).
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Whether a chunk whose CRC fails (or that does not decompress) is mended when one
    /// flipped bit explains it (on by default; see [`Damage::repaired_chunks`]). The search
    /// tries every bit of the compressed chunk, about a second for a 32 KiB chunk: off, such a
    /// chunk is lost at once.
    pub fn mend_bit_errors(&mut self, on: bool) {
        self.mend = on;
    }

    /// What was lost so far; complete once the iteration has ended.
    pub fn damage(&self) -> &Damage {
        &self.damage
    }

    /// Whether the file has chunks (met so far or in the summary's index).
    pub(crate) fn chunked(&self) -> bool {
        self.chunked
    }

    /// Where the file is cut, once the iteration has ended (`None`: not cut).
    pub(crate) fn cut_at(&self) -> Option<CutAt> {
        self.cut_at
    }

    /// Messages read per channel so far.
    pub fn messages_read(&self) -> &BTreeMap<u16, u64> {
        &self.read_counts
    }

    fn not_mcap(&self, why: NotMcap) -> Error {
        Error::NotMcap {
            path: self.path.clone(),
            why,
        }
    }

    fn io_error(&self, source: std::io::Error) -> Error {
        Error::Read {
            path: self.path.clone(),
            source,
        }
    }
}

impl<R: Read + Seek> RawReader<R> {
    /// Starts reading an MCAP file from `source`; `name` stands for it in messages.
    ///
    /// Refuses ([`Error::NotMcap`]) an empty file, one that ends inside the magic, and one
    /// that does not start with the magic unless its end is an MCAP footer and magic or it
    /// holds a chunk whose CRC checks (then it is read with [`Damage::header_damaged`]).
    pub fn new(source: R, name: impl Into<PathBuf>) -> Result<Self> {
        let path = name.into();
        let io = |source| Error::Read {
            path: path.clone(),
            source,
        };
        let mut src = Source::new(source).map_err(io)?;
        let start = src.bytes(0, MAGIC_LEN as usize).map_err(io)?.to_vec();
        let magic = check_magic(&start);
        let len = src.len;
        let mut reader = Self {
            src,
            path,
            pos: MAGIC_LEN,
            data_end: len,
            summary_hint: None,
            floor: MAGIC_LEN,
            summary: Summary::default(),
            chunk: None,
            chunked: false,
            schemas_out: HashSet::new(),
            channels_out: HashMap::new(),
            read_counts: BTreeMap::new(),
            out: VecDeque::new(),
            pending: None,
            last_ns: None,
            damage: Damage::default(),
            cut_at: None,
            profile: None,
            data_end_met: false,
            done: false,
            compressed: Vec::new(),
            mend: true,
            lost_to: 0,
        };
        match magic {
            Ok(()) => {
                reader.read_tail()?;
            }
            Err(why @ (NotMcap::Empty | NotMcap::ShorterThanMagic { .. })) => {
                return Err(reader.not_mcap(why));
            }
            Err(why) => {
                let tail_intact = reader.read_tail()?;
                if !tail_intact && !reader.probe_verified_chunk()? {
                    return Err(reader.not_mcap(why));
                }
                reader.damage.header_damaged = true;
            }
        }
        reader.chunked = !reader.summary.chunks.is_empty();
        Ok(reader)
    }

    /// Reads the footer and the summary; whether the file ends as an MCAP file does (its
    /// magic, or a footer record before the last 8 bytes).
    fn read_tail(&mut self) -> Result<bool> {
        let len = self.src.len;
        let Some(footer_at) = len.checked_sub(MAGIC_LEN + FOOTER_RECORD_LEN) else {
            self.damage.cut = true;
            return Ok(false);
        };
        let tail = self.peek(footer_at, (FOOTER_RECORD_LEN + MAGIC_LEN) as usize)?;
        let magic_ok = tail.get(FOOTER_RECORD_LEN as usize..) == Some(mcap::MAGIC);
        let footer = (tail.first() == Some(&op::FOOTER)
            && le_u64(&tail, 1) == Some(FOOTER_BODY_LEN))
        .then(|| (le_u64(&tail, 9), le_u32(&tail, 25)));
        if !magic_ok && footer.is_none() {
            self.damage.cut = true;
            return Ok(false);
        }
        self.damage.tail_damaged = !magic_ok;
        let Some((Some(summary_start), Some(crc))) = footer else {
            self.damage.summary = SummaryState::Damaged {
                why: format!("the footer record at offset {footer_at} is unreadable"),
            };
            return Ok(true);
        };
        if summary_start == 0 {
            return Ok(true);
        }
        if summary_start < MAGIC_LEN || summary_start > footer_at {
            self.damage.summary = SummaryState::Damaged {
                why: format!(
                    "the footer puts the summary at offset {summary_start}, outside the file's \
                     {MAGIC_LEN}..{footer_at}"
                ),
            };
            return Ok(true);
        }
        self.summary_hint = Some(summary_start);
        let covered = footer_at + FOOTER_CRC_COVERED - summary_start;
        if covered > MAX_RECORD_LEN_U64 {
            self.damage.summary = SummaryState::Damaged {
                why: format!(
                    "its {covered} bytes are more than the {MAX_RECORD_LEN} a record may have"
                ),
            };
            return Ok(true);
        }
        let mut bytes = Vec::new();
        self.src
            .read_into(summary_start, covered, &mut bytes)
            .map_err(|e| self.io_error(e))?;
        let records_len = usize::try_from(footer_at - summary_start).unwrap_or(usize::MAX);
        let parsed = parse_summary(bytes.get(..records_len).unwrap_or(&[]), summary_start);
        let computed = crc32fast::hash(&bytes);
        let why = match parsed {
            Ok(summary) if crc == 0 || computed == crc => {
                self.summary = summary;
                self.damage.summary = SummaryState::Intact;
                self.data_end = summary_start;
                return Ok(true);
            }
            Ok(summary) => (
                summary,
                format!(
                    "its CRC fails (saved {crc:08x}, computed {computed:08x}) at offsets \
                     {summary_start}..{footer_at}"
                ),
            ),
            Err(partial) => *partial,
        };
        // A damaged summary still names the channels (and their schemas) that parse in it:
        // they stand in for channel records the data has lost; its index and statistics are
        // not trusted.
        let (summary, why) = why;
        self.summary.schemas = summary.schemas;
        self.summary.channels = summary.channels;
        self.damage.summary = SummaryState::Damaged { why };
        Ok(true)
    }

    /// Whether the file holds a chunk whose CRC checks (for a file without the magic).
    fn probe_verified_chunk(&mut self) -> Result<bool> {
        let mut from = 0;
        while let Some(at) = self.scan(from, true)? {
            let peek = self.peek(at, CHUNK_PEEK_LEN)?;
            if let Some(head) = parse_chunk_head(at, &peek)
                && head.crc != 0
            {
                let mut compressed = std::mem::take(&mut self.compressed);
                let read = self
                    .src
                    .read_into(head.records_at, head.records_len, &mut compressed)
                    .map_err(|e| self.io_error(e));
                let good = read.is_ok()
                    && compressed.len() as u64 == head.records_len
                    && decode(&head, &compressed).is_ok();
                self.compressed = compressed;
                read?;
                if good {
                    return Ok(true);
                }
            }
            from = at + 1;
        }
        Ok(false)
    }

    fn peek(&mut self, at: u64, n: usize) -> Result<Vec<u8>> {
        match self.src.bytes(at, n) {
            Ok(b) => Ok(b.to_vec()),
            Err(e) => Err(self.io_error(e)),
        }
    }

    /// One step of the reading: the next record of the open chunk, or the next top-level
    /// record.
    fn step(&mut self) -> Result<()> {
        if self.chunk.is_some() {
            return self.chunk_step();
        }
        if self.data_end_met || self.pos >= self.data_end {
            self.finish();
            return Ok(());
        }
        let at = self.pos;
        let head = self.peek(at, RECORD_HEADER_LEN as usize)?;
        let (Some(&opcode), Some(len)) = (head.first(), le_u64(&head, 1)) else {
            // Fewer than 9 bytes left: the file is cut inside a record header, or they are
            // the closing magic of a file whose footer was not met.
            if self.damage.cut {
                return self.past_end(at, None);
            }
            self.finish();
            return Ok(());
        };
        let end = at
            .checked_add(RECORD_HEADER_LEN)
            .and_then(|b| b.checked_add(len));
        if opcode == op::CHUNK {
            return self.chunk_record(at, len);
        }
        let known = (op::HEADER..=op::DATA_END).contains(&opcode);
        let first = at == MAGIC_LEN;
        if first && opcode != op::HEADER {
            self.damage.header_damaged = true;
        }
        // A record that would run over a chunk of the index (or into the summary) has a
        // damaged length.
        let overlong = end.is_some_and(|end| {
            (end > self.data_end && opcode != op::FOOTER)
                || self.indexed_chunk_inside(at + 1, end).is_some()
        });
        match end {
            Some(end) if known && len <= MAX_RECORD_LEN_U64 && end <= self.src.len && !overlong => {
                self.pos = end;
                self.floor = self.floor.max(at + 1);
                self.record(at, opcode, len)
            }
            Some(_) if known && len <= MAX_RECORD_LEN_U64 && self.damage.cut => {
                self.past_end(at, Some(opcode))
            }
            _ if !known && opcode >= 0x80 && self.private_record_fits(end) => {
                // A private record (the spec reserves 0x80..=0xff): skipped.
                self.pos = end.unwrap_or(self.src.len);
                Ok(())
            }
            _ => {
                if first {
                    self.damage.header_damaged = true;
                }
                let why = if !known {
                    format!("unknown opcode {opcode:#04x}")
                } else if overlong {
                    format!(
                        "{} record of {len} bytes would run over the next chunk",
                        record_name(opcode)
                    )
                } else if len > MAX_RECORD_LEN_U64 {
                    format!(
                        "{} record of {len} bytes, more than the {MAX_RECORD_LEN} a record may have",
                        record_name(opcode)
                    )
                } else {
                    format!(
                        "{} record of {len} bytes runs past the end of the file",
                        record_name(opcode)
                    )
                };
                self.resync(
                    at,
                    format!("the record framing is lost at offset {at} ({why})"),
                )
            }
        }
    }

    /// Whether a private record ending at `end` is followed by a plausible record (or the end).
    fn private_record_fits(&mut self, end: Option<u64>) -> bool {
        let Some(end) = end else { return false };
        if end == self.data_end {
            return true;
        }
        matches!(self.plausible_record(end), Ok(Some(_)))
    }

    /// A top-level record other than a chunk, whole in the file.
    fn record(&mut self, at: u64, opcode: u8, len: u64) -> Result<()> {
        let body_at = at + RECORD_HEADER_LEN;
        let awaits_index = self.pending.as_ref().is_some_and(|p| p.open.is_some());
        match opcode {
            op::HEADER | op::SCHEMA | op::CHANNEL | op::MESSAGE => {}
            // Only the message index of a lost chunk is read (it counts what was lost).
            op::MESSAGE_INDEX if awaits_index => {}
            op::MESSAGE_INDEX => return Ok(()),
            op::DATA_END | op::FOOTER => return self.end_record(at, opcode, len),
            // Attachments, metadata, indexes, statistics and summary offsets: not needed.
            _ => {
                self.close_open_piece();
                return Ok(());
            }
        }
        let mut body = std::mem::take(&mut self.compressed);
        let read = self.src.read_into(body_at, len, &mut body);
        if let Err(e) = read {
            self.compressed = body;
            return Err(self.io_error(e));
        }
        let parsed = parse_checked(opcode, &body).map(owned);
        self.compressed = body;
        match parsed {
            Ok(Some(Parsed::Header(profile))) => self.profile = Some(profile),
            Ok(Some(Parsed::Index(index))) => self.message_index(&index),
            Ok(Some(Parsed::Raw(record))) => {
                self.close_open_piece();
                self.top_level(record);
            }
            Ok(None) => {}
            Err(err) => {
                if opcode == op::HEADER {
                    self.damage.header_damaged = true;
                    return Ok(());
                }
                let none = opcode == op::MESSAGE_INDEX;
                self.lose(
                    at,
                    RECORD_HEADER_LEN + len,
                    0,
                    none.then(BTreeMap::new),
                    format!(
                        "{} record at offset {at} is unreadable ({err})",
                        record_name(opcode)
                    ),
                );
            }
        }
        Ok(())
    }

    /// A data end or footer record: the end of the data, unless it cannot be (a damaged
    /// opcode): then the framing is lost.
    fn end_record(&mut self, at: u64, opcode: u8, len: u64) -> Result<()> {
        let end = at + RECORD_HEADER_LEN + len;
        let genuine = if self.damage.summary == SummaryState::Intact {
            match opcode {
                op::DATA_END => len == 4 && end == self.data_end,
                _ => end + MAGIC_LEN == self.src.len,
            }
        } else {
            // Nothing tells where the data ends: it does here if no chunk follows.
            let next = self.resync_target(self.floor.max(end))?;
            next.is_none()
        };
        if genuine {
            self.data_end_met = true;
            return Ok(());
        }
        self.resync(
            at,
            format!(
                "the record framing is lost at offset {at} ({} record where the data goes on)",
                record_name(opcode)
            ),
        )
    }

    /// The first chunk of the index that starts in `from..to`.
    fn indexed_chunk_inside(&self, from: u64, to: u64) -> Option<u64> {
        if self.damage.summary != SummaryState::Intact {
            return None;
        }
        let i = self.summary.chunks.partition_point(|c| c.offset < from);
        self.summary
            .chunks
            .get(i)
            .map(|c| c.offset)
            .filter(|&o| o < to)
    }

    /// A schema, channel or message outside chunks (or inside one).
    fn top_level(&mut self, record: RawRecord) {
        match record {
            RawRecord::Schema(schema) => self.schema(schema),
            RawRecord::Channel(channel) => self.channel(channel),
            RawRecord::Message(message) => self.message(message),
            RawRecord::Lost(_) => {}
        }
    }

    fn schema(&mut self, schema: RawSchema) {
        if schema.id != 0 && self.schemas_out.insert(schema.id) {
            self.out.push_back(RawRecord::Schema(schema));
        }
    }

    fn channel(&mut self, channel: RawChannel) {
        if self.channels_out.contains_key(&channel.id) {
            return;
        }
        self.ensure_schema(channel.schema_id);
        self.channels_out.insert(channel.id, channel.topic.clone());
        self.out.push_back(RawRecord::Channel(channel));
    }

    fn ensure_schema(&mut self, id: u16) {
        if id != 0
            && !self.schemas_out.contains(&id)
            && let Some(schema) = self.summary.schemas.get(&id).cloned()
        {
            self.schema(schema);
        }
    }

    fn message(&mut self, message: RawMessage) {
        if !self.channels_out.contains_key(&message.channel_id)
            && let Some(channel) = self.summary.channels.get(&message.channel_id).cloned()
        {
            self.channel(channel);
        }
        self.flush_loss(Some(message.log_time));
        *self.read_counts.entry(message.channel_id).or_default() += 1;
        self.last_ns = Some(message.log_time);
        self.out.push_back(RawRecord::Message(message));
    }

    /// A chunk record at `at` whose outer length is `outer_len`.
    fn chunk_record(&mut self, at: u64, outer_len: u64) -> Result<()> {
        self.close_open_piece();
        self.floor = self.floor.max(at + 1);
        let peek = self.peek(at, CHUNK_PEEK_LEN)?;
        let Some(head) = parse_chunk_head(at, &peek) else {
            if peek.len() < CHUNK_PEEK_LEN && self.damage.cut {
                return self.past_end(at, Some(op::CHUNK));
            }
            return self.resync(
                at,
                format!("the record framing is lost at offset {at} (no chunk header there)"),
            );
        };
        self.chunked = true;
        let indexed = self.indexed(at).cloned();
        let outer_records = (at + RECORD_HEADER_LEN)
            .checked_add(outer_len)
            .and_then(|end| end.checked_sub(head.records_at));
        let index_records = indexed.as_ref().and_then(|c| {
            (at + c.length)
                .checked_sub(head.records_at)
                .filter(|_| c.length >= RECORD_HEADER_LEN)
        });
        let len = self.src.len;
        let fits = |n: &u64| {
            head.records_at
                .checked_add(*n)
                .is_some_and(|end| end <= len)
        };
        // The records' length: the summary's (its CRC checked) first, then the shorter of
        // the chunk's own two first: a zstd or lz4 frame decodes from any longer run of bytes
        // that holds it, so the shortest length that checks is the chunk's.
        let mut lengths = [Some(head.records_len), outer_records];
        lengths.sort_unstable();
        let mut candidates: Vec<u64> = Vec::new();
        for n in std::iter::once(index_records).chain(lengths).flatten() {
            if fits(&n) && n <= MAX_RECORD_LEN_U64 && !candidates.contains(&n) {
                candidates.push(n);
            }
        }
        let consistent = outer_records == Some(head.records_len);
        let whole = RECORD_HEADER_LEN.saturating_add(outer_len);
        if !matches!(head.compression.as_str(), "" | "zstd" | "lz4") {
            let why = format!(
                "chunk at offset {at}: compression {:?} is not supported",
                head.compression
            );
            return self.lost_chunk(at, &head, indexed.as_ref(), whole, consistent, why);
        }
        let Some(&longest) = candidates.iter().max() else {
            if self.damage.cut && !fits(&head.records_len) {
                return self.cut_chunk(at, head);
            }
            let why = format!(
                "chunk at offset {at}: its records ({} bytes) run past the end of the file",
                head.records_len
            );
            return self.lost_chunk(at, &head, indexed.as_ref(), whole, false, why);
        };
        let mut compressed = std::mem::take(&mut self.compressed);
        if let Err(e) = self
            .src
            .read_into(head.records_at, longest, &mut compressed)
        {
            self.compressed = compressed;
            return Err(self.io_error(e));
        }
        let mut first_why = None;
        let mut accepted = None;
        for &n in &candidates {
            let Some(bytes) = compressed.get(..usize::try_from(n).unwrap_or(usize::MAX)) else {
                continue;
            };
            match decode(&head, bytes) {
                // Without a CRC, only lengths that agree are trusted.
                Ok((data, verified)) if verified || consistent => {
                    accepted = Some((n, data, verified));
                    break;
                }
                Ok(_) => {
                    first_why.get_or_insert_with(|| {
                        "its lengths disagree and it has no CRC to tell which is right".to_owned()
                    });
                }
                Err(why) => {
                    first_why.get_or_insert(why);
                }
            }
        }
        // Every length failed: a single flipped bit, found by the chunk's CRC, is mended.
        if accepted.is_none() && head.crc != 0 && self.mend {
            for &n in &candidates {
                let Some(bytes) = compressed.get(..usize::try_from(n).unwrap_or(usize::MAX)) else {
                    continue;
                };
                if let Some(data) = repair(&head, bytes) {
                    self.damage.repaired_chunks += 1;
                    accepted = Some((n, data, true));
                    break;
                }
            }
        }
        self.compressed = compressed;
        match accepted {
            Some((n, data, verified)) => {
                let end = head.records_at + n;
                if !verified {
                    self.damage.unverified_chunks += 1;
                }
                if verified {
                    self.floor = self.floor.max(end);
                }
                self.pos = end;
                self.chunk = Some(OpenChunk {
                    data,
                    at: 0,
                    verified,
                    cut: None,
                    offset: at,
                });
                Ok(())
            }
            None if self.damage.cut && !fits(&head.records_len) => self.cut_chunk(at, head),
            None => {
                let why = format!(
                    "chunk at offset {at}: {}",
                    first_why.unwrap_or_else(|| "unreadable".to_owned())
                );
                let framed = consistent || index_records.is_some();
                self.lost_chunk(at, &head, indexed.as_ref(), whole, framed, why)
            }
        }
    }

    /// A chunk that cannot be used: skipped whole when its length can be trusted, else the
    /// framing is lost.
    fn lost_chunk(
        &mut self,
        at: u64,
        head: &ChunkHead,
        indexed: Option<&IndexedChunk>,
        whole: u64,
        framed: bool,
        why: String,
    ) -> Result<()> {
        let length = indexed.map_or(whole, |c| c.length);
        let piece = ChunkPiece {
            times: indexed.map(|c| (c.start_ns, c.end_ns, true)),
            cut: false,
            header_times: (head.start_ns, head.end_ns),
            counts: None,
            index_times: None,
            expected: indexed.map(|c| c.channels.clone()),
        };
        if framed && at.saturating_add(length) <= self.src.len {
            self.lose_chunk(at, length, piece, why);
            self.pos = at + length;
            return Ok(());
        }
        let target = self.jump(at + 1)?;
        let to = target.unwrap_or_else(|| self.lost_data_end(at));
        self.lose_chunk(at, to.saturating_sub(at), piece, why);
        self.go_to(target);
        Ok(())
    }

    /// A chunk cut by the end of the file: its readable prefix is decoded and its complete
    /// records are used, without a CRC check.
    fn cut_chunk(&mut self, at: u64, head: ChunkHead) -> Result<()> {
        let available = self.src.len.saturating_sub(head.records_at);
        let mut compressed = std::mem::take(&mut self.compressed);
        if let Err(e) = self.src.read_into(
            head.records_at,
            available.min(MAX_RECORD_LEN_U64),
            &mut compressed,
        ) {
            self.compressed = compressed;
            return Err(self.io_error(e));
        }
        let data = decode_prefix(&head, &compressed);
        self.compressed = compressed;
        self.damage.unverified_chunks += 1;
        self.cut_at.get_or_insert(CutAt::Data);
        self.pos = self.src.len;
        self.chunk = Some(OpenChunk {
            data,
            at: 0,
            verified: false,
            cut: Some(head),
            offset: at,
        });
        Ok(())
    }

    /// The next record of the open chunk.
    fn chunk_step(&mut self) -> Result<()> {
        let Some(chunk) = self.chunk.as_mut() else {
            return Ok(());
        };
        let rest = chunk.data.get(chunk.at..).unwrap_or(&[]);
        let verified = chunk.verified;
        let parsed = match (rest.first(), le_u64(rest, 1)) {
            _ if rest.is_empty() => None,
            (Some(&opcode), Some(len)) => {
                let body = usize::try_from(len)
                    .ok()
                    .and_then(|len| rest.get(9..9usize.checked_add(len)?));
                body.map(|body| {
                    // Only schemas, channels and messages are used from a chunk.
                    let parsed = if matches!(opcode, op::SCHEMA | op::CHANNEL | op::MESSAGE) {
                        parse_checked(opcode, body).map(owned)
                    } else {
                        Ok(None)
                    };
                    (opcode, body.len(), parsed)
                })
            }
            _ => None,
        };
        let Some((opcode, body_len, parsed)) = parsed else {
            // The chunk's records end (or its last record is incomplete).
            let left = rest.len();
            let Some(chunk) = self.chunk.take() else {
                return Ok(());
            };
            return self.close_chunk(chunk, left);
        };
        chunk.at += 9 + body_len;
        match parsed {
            Ok(Some(Parsed::Raw(RawRecord::Message(mut message)))) => {
                message.verified = verified;
                self.message(message);
            }
            Ok(Some(Parsed::Raw(record))) => self.top_level(record),
            Ok(_) => {}
            Err(err) => {
                let offset = self.chunk.as_ref().map_or(0, |c| c.offset);
                let none = !matches!(opcode, op::MESSAGE);
                self.lose(
                    offset,
                    0,
                    0,
                    none.then(BTreeMap::new),
                    format!(
                        "chunk at offset {offset}: a {} record in it is unreadable ({err})",
                        record_name(opcode)
                    ),
                );
            }
        }
        Ok(())
    }

    /// The end of a chunk's records; `left` bytes of it were not records.
    fn close_chunk(&mut self, chunk: OpenChunk, left: usize) -> Result<()> {
        match chunk.cut {
            Some(head) => {
                let start = self.last_ns.unwrap_or(head.start_ns);
                let piece = ChunkPiece {
                    times: (head.end_ns >= start).then_some((start, head.end_ns, false)),
                    cut: true,
                    header_times: (head.start_ns, head.end_ns),
                    counts: None,
                    index_times: None,
                    expected: None,
                };
                let bytes = self.src.len.saturating_sub(chunk.offset);
                self.lose_chunk(
                    chunk.offset,
                    bytes,
                    piece,
                    format!(
                        "chunk at offset {}: the file ends inside it (cut short); its readable \
                         prefix was used without a CRC check, the rest is lost",
                        chunk.offset
                    ),
                );
                self.close_open_piece();
                // Chunks after it mean its length was damaged, not cut: they are read too.
                return self.resync_after(chunk.offset + 1);
            }
            None if left > 0 => {
                self.lose(
                    chunk.offset,
                    0,
                    0,
                    None,
                    format!(
                        "chunk at offset {}: its last {left} bytes are not a whole record",
                        chunk.offset
                    ),
                );
            }
            None => {}
        }
        Ok(())
    }

    /// A message index record: counts for the lost chunk before it, if any.
    fn message_index(&mut self, index: &records::MessageIndex) {
        let Some(piece) = self.pending.as_mut().and_then(|p| p.open.as_mut()) else {
            return;
        };
        let counts = piece.counts.get_or_insert_with(BTreeMap::new);
        *counts.entry(index.channel_id).or_default() += index.records.len() as u64;
        for entry in &index.records {
            let t = entry.log_time;
            piece.index_times = Some(match piece.index_times {
                Some((a, b)) => (a.min(t), b.max(t)),
                None => (t, t),
            });
        }
    }

    /// The file ends inside the record at `at` (or its header).
    fn past_end(&mut self, at: u64, opcode: Option<u8>) -> Result<()> {
        self.damage.cut = true;
        self.cut_at.get_or_insert(if self.data_end_met {
            CutAt::Summary
        } else {
            CutAt::Data
        });
        let bytes = self.src.len.saturating_sub(at);
        if bytes > 0 {
            let holds_none = opcode.is_some_and(|o| o != op::CHUNK && o != op::MESSAGE);
            let kind = opcode.map_or("a record header", record_name);
            self.lose(
                at,
                bytes,
                u64::from(opcode == Some(op::CHUNK)),
                holds_none.then(BTreeMap::new),
                format!("the file ends inside {kind} at offset {at} (cut short)"),
            );
        }
        self.resync_after(at + 1)
    }

    /// The framing is lost at `at`: go on at the next chunk.
    fn resync(&mut self, at: u64, why: String) -> Result<()> {
        let target = self.jump(MAGIC_LEN)?;
        let to = target.unwrap_or_else(|| self.lost_data_end(at));
        let bytes = to.saturating_sub(at);
        // With the chunk index, nothing between here and the next chunk held messages.
        let none = self.damage.summary == SummaryState::Intact && self.chunked;
        if bytes > 0 {
            self.lose(at, bytes, 0, none.then(BTreeMap::new), why);
        }
        self.go_to(target);
        Ok(())
    }

    /// After a loss whose bytes are counted: go on at the next chunk at or after `from`.
    fn resync_after(&mut self, from: u64) -> Result<()> {
        let target = self.jump(from)?;
        self.go_to(target);
        Ok(())
    }

    /// The next place to resume at, at or after `from` and the floor; the floor moves past
    /// it, so that every resync makes progress.
    fn jump(&mut self, from: u64) -> Result<Option<u64>> {
        let target = self.resync_target(self.floor.max(from))?;
        if let Some(t) = target {
            self.floor = self.floor.max(t + 1);
        }
        Ok(target)
    }

    /// Resumes at `target`, or ends the data pass.
    fn go_to(&mut self, target: Option<u64>) {
        match target {
            Some(t) => self.pos = t,
            None => self.finish(),
        }
    }

    /// Where lost data ends when no chunk follows: the summary's start if the footer said
    /// where it is, else the end of the file.
    fn lost_data_end(&self, at: u64) -> u64 {
        match self.summary_hint {
            Some(h) if h > at => h,
            _ => self.src.len,
        }
    }

    /// The next chunk at or after `from`: from the chunk index, or by scanning.
    fn resync_target(&mut self, from: u64) -> Result<Option<u64>> {
        if self.damage.summary == SummaryState::Intact && !self.summary.chunks.is_empty() {
            let next = self
                .summary
                .chunks
                .iter()
                .map(|c| c.offset)
                .find(|&o| o >= from);
            return Ok(next.filter(|&o| o < self.data_end));
        }
        let found = self.scan(from, self.chunked)?;
        Ok(found.filter(|&o| o < self.data_end))
    }

    /// The first offset at or after `from` where a plausible chunk record starts (or, in a
    /// file without chunks, a schema, channel or message record followed by another plausible
    /// record).
    fn scan(&mut self, from: u64, chunks_only: bool) -> Result<Option<u64>> {
        let mut at = from;
        while at < self.src.len {
            let hit = {
                let window = self.src.bytes(at, READ_BUF_LEN).map_err(|e| Error::Read {
                    path: self.path.clone(),
                    source: e,
                })?;
                if window.is_empty() {
                    return Ok(None);
                }
                let hit = if chunks_only {
                    memchr::memchr(op::CHUNK, window)
                } else {
                    window
                        .iter()
                        .position(|b| matches!(*b, op::SCHEMA..=op::CHUNK))
                };
                match hit {
                    Some(i) => Ok(i),
                    None => Err(window.len()),
                }
            };
            match hit {
                Err(n) => at += n as u64,
                Ok(i) => {
                    let candidate = at + i as u64;
                    if self.plausible_start(candidate, chunks_only)? {
                        return Ok(Some(candidate));
                    }
                    at = candidate + 1;
                }
            }
        }
        Ok(None)
    }

    /// Whether a record that the reader can resume at starts at `at`.
    fn plausible_start(&mut self, at: u64, chunks_only: bool) -> Result<bool> {
        let peek = self.peek(at, CHUNK_PEEK_LEN)?;
        if peek.first() == Some(&op::CHUNK) {
            let Some(head) = parse_chunk_head(at, &peek) else {
                return Ok(false);
            };
            let outer = le_u64(&peek, 1);
            let end = head.records_at.checked_add(head.records_len);
            let plausible = matches!(head.compression.as_str(), "" | "zstd" | "lz4")
                && head.uncompressed_size <= MAX_RECORD_LEN_U64
                && head.start_ns <= head.end_ns
                && end.is_some_and(|e| Some(e - at - RECORD_HEADER_LEN) == outer)
                && end.is_some_and(|e| e <= self.src.len || self.damage.cut);
            return Ok(plausible);
        }
        if chunks_only {
            return Ok(false);
        }
        let Some((opcode, end)) = self.plausible_record(at)? else {
            return Ok(false);
        };
        if !matches!(opcode, op::SCHEMA | op::CHANNEL | op::MESSAGE) {
            return Ok(false);
        }
        Ok(end == self.data_end || end == self.src.len || self.plausible_record(end)?.is_some())
    }

    /// The opcode and end of a record at `at` whose opcode is known and which ends in the
    /// file.
    fn plausible_record(&mut self, at: u64) -> Result<Option<(u8, u64)>> {
        let head = self.peek(at, RECORD_HEADER_LEN as usize)?;
        let (Some(&opcode), Some(len)) = (head.first(), le_u64(&head, 1)) else {
            return Ok(None);
        };
        let end = (at + RECORD_HEADER_LEN).checked_add(len);
        let ok = (op::HEADER..=op::DATA_END).contains(&opcode)
            && len <= MAX_RECORD_LEN_U64
            && end.is_some_and(|e| e <= self.src.len);
        Ok(ok.then_some((opcode, end.unwrap_or(0))))
    }

    /// The summary's chunk index entry of the chunk at `at`.
    fn indexed(&self, at: u64) -> Option<&IndexedChunk> {
        if self.damage.summary != SummaryState::Intact {
            return None;
        }
        let i = self
            .summary
            .chunks
            .binary_search_by_key(&at, |c| c.offset)
            .ok()?;
        self.summary.chunks.get(i)
    }

    /// Records a loss of `bytes` at `offset` (`messages`: per channel, when known).
    fn lose(
        &mut self,
        offset: u64,
        bytes: u64,
        chunks: u64,
        messages: Option<BTreeMap<u16, u64>>,
        why: String,
    ) {
        let bytes = self.uncounted(offset, bytes);
        let before = self.last_ns;
        let pending = self
            .pending
            .get_or_insert_with(|| PendingLoss::new(offset, why, before));
        // A loss that may have held messages has no times of its own.
        if !messages.as_ref().is_some_and(BTreeMap::is_empty) {
            pending.times = None;
        }
        pending.pieces += 1;
        pending.bytes += bytes;
        pending.chunks += chunks;
        pending.counts = add_counts(pending.counts.take(), messages);
    }

    /// The bytes of `offset..offset + bytes` not counted as lost yet; counts them.
    fn uncounted(&mut self, offset: u64, bytes: u64) -> u64 {
        let end = offset.saturating_add(bytes).min(self.src.len);
        let start = offset.max(self.lost_to);
        if end <= start {
            return 0;
        }
        self.lost_to = end;
        end - start
    }

    /// Records the loss of a chunk that message index records after it may describe.
    fn lose_chunk(&mut self, offset: u64, bytes: u64, piece: ChunkPiece, why: String) {
        self.close_open_piece();
        let bytes = self.uncounted(offset, bytes);
        let before = self.last_ns;
        let pending = self
            .pending
            .get_or_insert_with(|| PendingLoss::new(offset, why, before));
        pending.pieces += 1;
        pending.bytes += bytes;
        pending.chunks += 1;
        pending.open = Some(piece);
    }

    /// Folds the lost chunk still open to message index records into its span.
    fn close_open_piece(&mut self) {
        let Some(pending) = self.pending.as_mut() else {
            return;
        };
        let Some(piece) = pending.open.take() else {
            return;
        };
        pending.cut |= piece.cut;
        let counts = match (&piece.counts, &piece.expected) {
            (Some(c), Some(expected)) if expected.iter().all(|ch| c.contains_key(ch)) => {
                Some(c.clone())
            }
            (None, Some(expected)) if expected.is_empty() => Some(BTreeMap::new()),
            (Some(c), None) => Some(c.clone()),
            _ => None,
        };
        pending.counts = add_counts(pending.counts.take(), counts);
        // Times: the summary's (trusted), else the message index's, else the header's.
        let times = piece
            .times
            .or(piece.index_times.map(|(a, b)| (a, b, false)))
            .or(Some((piece.header_times.0, piece.header_times.1, false)));
        pending.times = match (pending.times, times) {
            (Some((a, b, ta)), Some((c, d, tb))) if c <= d => Some((a.min(c), b.max(d), ta && tb)),
            _ => None,
        };
    }

    /// Yields the pending loss, if any, now that the next good message (at `next_ns`) or the
    /// end has come.
    fn flush_loss(&mut self, next_ns: Option<u64>) {
        self.close_open_piece();
        let Some(pending) = self.pending.take() else {
            return;
        };
        let before = pending.before_ns;
        let exact = pending.times.filter(|&(a, b, trusted)| {
            a <= b && (trusted || (before.is_none_or(|p| p <= a) && next_ns.is_none_or(|n| b <= n)))
        });
        let (start_ns, end_ns, exact_times) = match exact {
            Some((a, b, _)) => (Some(a), Some(b), !pending.cut),
            None => (before, next_ns, false),
        };
        let messages = pending.counts.map(|counts| {
            counts
                .into_iter()
                .map(|(channel, n)| (self.topic_of(channel), n))
                .fold(BTreeMap::new(), |mut m, (topic, n)| {
                    *m.entry(topic).or_default() += n;
                    m
                })
        });
        let span = LostSpan {
            offset: pending.offset,
            bytes: pending.bytes,
            start_ns,
            end_ns,
            exact_times,
            chunks: pending.chunks,
            messages,
            why: if pending.pieces > 1 {
                format!("{} (and {} more losses)", pending.why, pending.pieces - 1)
            } else {
                pending.why
            },
        };
        self.damage.add(&span);
        if span.may_hold_messages() {
            self.out.push_back(RawRecord::Lost(span));
        }
    }

    fn topic_of(&self, channel: u16) -> String {
        self.channels_out
            .get(&channel)
            .cloned()
            .or_else(|| self.summary.channels.get(&channel).map(|c| c.topic.clone()))
            .unwrap_or_else(|| format!("(channel {channel})"))
    }

    /// Ends the reading: the last loss, the schemas and channels of the summary not met yet,
    /// the totals.
    fn finish(&mut self) {
        if self.done {
            return;
        }
        self.done = true;
        self.flush_loss(None);
        if self.damage.cut && self.cut_at.is_none() {
            self.cut_at = Some(if self.data_end_met {
                CutAt::Summary
            } else {
                CutAt::Data
            });
        }
        let channels: Vec<RawChannel> = self.summary.channels.values().cloned().collect();
        for channel in channels {
            self.channel(channel);
        }
        let schemas: Vec<RawSchema> = self.summary.schemas.values().cloned().collect();
        for schema in schemas {
            self.schema(schema);
        }
        self.damage.messages_lost = self.messages_lost();
    }

    /// Messages lost per topic, as [`Damage::messages_lost`] says.
    fn messages_lost(&self) -> Option<BTreeMap<String, u64>> {
        let mut lost = BTreeMap::new();
        if let Some(counts) = &self.summary.counts {
            for (channel, written) in counts {
                let read = self.read_counts.get(channel).copied().unwrap_or(0);
                if *written > read {
                    *lost.entry(self.topic_of(*channel)).or_default() += written - read;
                }
            }
            return Some(lost);
        }
        if self.damage.spans_total > self.damage.spans.len() as u64 {
            return None;
        }
        for span in &self.damage.spans {
            for (topic, n) in span.messages.as_ref()? {
                *lost.entry(topic.clone()).or_default() += n;
            }
        }
        Some(lost)
    }
}

impl<R: Read + Seek> Iterator for RawReader<R> {
    type Item = Result<RawRecord>;

    fn next(&mut self) -> Option<Self::Item> {
        loop {
            if let Some(record) = self.out.pop_front() {
                return Some(Ok(record));
            }
            if self.done {
                return None;
            }
            if let Err(err) = self.step() {
                self.done = true;
                self.out.clear();
                return Some(Err(err));
            }
        }
    }
}

impl<R: Read + Seek> std::iter::FusedIterator for RawReader<R> {}

/// A parsed record this reader uses.
enum Parsed {
    Header(String),
    Index(records::MessageIndex),
    Raw(RawRecord),
}

/// The owned form of the records the reader uses; `None` for the others.
fn owned(record: records::Record<'_>) -> Option<Parsed> {
    Some(match record {
        records::Record::Header(h) => Parsed::Header(h.profile),
        records::Record::MessageIndex(index) => Parsed::Index(index),
        records::Record::Schema { header, data } => Parsed::Raw(RawRecord::Schema(RawSchema {
            id: header.id,
            name: header.name,
            encoding: header.encoding,
            data: data.into_owned(),
        })),
        records::Record::Channel(c) => Parsed::Raw(RawRecord::Channel(RawChannel {
            id: c.id,
            schema_id: c.schema_id,
            topic: c.topic,
            message_encoding: c.message_encoding,
            metadata: c.metadata,
        })),
        records::Record::Message { header, data } => Parsed::Raw(RawRecord::Message(RawMessage {
            channel_id: header.channel_id,
            sequence: header.sequence,
            log_time: header.log_time,
            publish_time: header.publish_time,
            data: data.into_owned(),
            verified: false,
        })),
        _ => return None,
    })
}

fn record_name(opcode: u8) -> &'static str {
    match opcode {
        op::HEADER => "a header",
        op::FOOTER => "a footer",
        op::SCHEMA => "a schema",
        op::CHANNEL => "a channel",
        op::MESSAGE => "a message",
        op::CHUNK => "a chunk",
        op::MESSAGE_INDEX => "a message index",
        op::CHUNK_INDEX => "a chunk index",
        op::ATTACHMENT => "an attachment",
        op::ATTACHMENT_INDEX => "an attachment index",
        op::STATISTICS => "a statistics",
        op::METADATA => "a metadata",
        op::METADATA_INDEX => "a metadata index",
        op::SUMMARY_OFFSET => "a summary offset",
        op::DATA_END => "a data end",
        _ => "an unknown",
    }
}

/// [`mcap::parse_record`], after checking that every string length prefix of the body fits in
/// it: the `mcap` crate reserves a string's stated length before reading it, and a damaged
/// length must not make the reader allocate gigabytes (or abort where it cannot).
fn parse_checked(opcode: u8, body: &[u8]) -> Result<records::Record<'_>, String> {
    if !strings_fit(opcode, body) {
        return Err("a string length runs past the record".to_owned());
    }
    mcap::parse_record(opcode, body).map_err(|e| e.to_string())
}

/// Whether the strings of a header, schema, channel or chunk index record body lie inside it.
fn strings_fit(opcode: u8, body: &[u8]) -> bool {
    let mut c = Fields { body, at: 0 };
    let fits = match opcode {
        op::HEADER => c.string().and_then(|()| c.string()),
        op::SCHEMA => c
            .skip(2)
            .and_then(|()| c.string())
            .and_then(|()| c.string()),
        op::CHANNEL => c
            .skip(4)
            .and_then(|()| c.string())
            .and_then(|()| c.string())
            .and_then(|()| c.string_map()),
        // Start and end times, offset, length; the message index offsets (fixed-size pairs);
        // the message index length; the compression.
        op::CHUNK_INDEX => c
            .skip(32)
            .and_then(|()| c.sized())
            .and_then(|()| c.skip(8))
            .and_then(|()| c.string()),
        _ => Some(()),
    };
    fits.is_some()
}

/// A walk over a record body's length-prefixed fields.
struct Fields<'a> {
    body: &'a [u8],
    at: usize,
}

impl Fields<'_> {
    fn skip(&mut self, n: usize) -> Option<()> {
        self.at = self.at.checked_add(n)?;
        (self.at <= self.body.len()).then_some(())
    }

    /// A u32 length, then that many bytes.
    fn sized(&mut self) -> Option<()> {
        let n = usize::try_from(le_u32(self.body, self.at)?).ok()?;
        self.skip(4)?;
        self.skip(n)
    }

    fn string(&mut self) -> Option<()> {
        self.sized()
    }

    /// A u32 byte length, then key and value strings.
    fn string_map(&mut self) -> Option<()> {
        let n = usize::try_from(le_u32(self.body, self.at)?).ok()?;
        self.skip(4)?;
        let end = self.at.checked_add(n)?;
        if end > self.body.len() {
            return None;
        }
        while self.at < end {
            self.string()?;
            self.string()?;
        }
        (self.at == end).then_some(())
    }
}

/// The summary's records (`bytes` from offset `at`).
/// Or, where a record is unreadable, what came before it and why.
fn parse_summary(bytes: &[u8], at: u64) -> Result<Summary, Box<(Summary, String)>> {
    let mut summary = Summary::default();
    let mut first_error = None;
    let mut rest = bytes;
    let mut offset = at;
    while !rest.is_empty() {
        let (Some(&opcode), Some(len)) = (rest.first(), le_u64(rest, 1)) else {
            return Err(Box::new((
                summary,
                format!("a record header at offset {offset} is cut by the footer"),
            )));
        };
        let Some(body) = usize::try_from(len)
            .ok()
            .and_then(|len| rest.get(9..9usize.checked_add(len)?))
        else {
            return Err(Box::new((
                summary,
                format!("a record at offset {offset} runs into the footer"),
            )));
        };
        let used = matches!(
            opcode,
            op::SCHEMA | op::CHANNEL | op::CHUNK_INDEX | op::STATISTICS
        );
        let parsed = if used {
            parse_checked(opcode, body)
        } else {
            Ok(records::Record::Unknown {
                opcode,
                data: std::borrow::Cow::Borrowed(&[]),
            })
        };
        match parsed {
            Ok(records::Record::Schema { header, data }) => {
                summary.schemas.insert(
                    header.id,
                    RawSchema {
                        id: header.id,
                        name: header.name,
                        encoding: header.encoding,
                        data: data.into_owned(),
                    },
                );
            }
            Ok(records::Record::Channel(c)) => {
                summary.channels.insert(
                    c.id,
                    RawChannel {
                        id: c.id,
                        schema_id: c.schema_id,
                        topic: c.topic,
                        message_encoding: c.message_encoding,
                        metadata: c.metadata,
                    },
                );
            }
            Ok(records::Record::ChunkIndex(c)) => summary.chunks.push(IndexedChunk {
                offset: c.chunk_start_offset,
                length: c.chunk_length,
                start_ns: c.message_start_time,
                end_ns: c.message_end_time,
                channels: c.message_index_offsets.keys().copied().collect(),
            }),
            Ok(records::Record::Statistics(s)) => summary.counts = Some(s.channel_message_counts),
            Ok(_) => {}
            // The records after it may still be good (their framing is): read on.
            Err(err) => {
                first_error.get_or_insert_with(|| {
                    format!(
                        "{} record at offset {offset} is unreadable ({err})",
                        record_name(opcode)
                    )
                });
            }
        }
        let step = 9 + body.len();
        rest = rest.get(step..).unwrap_or(&[]);
        offset += step as u64;
    }
    summary.chunks.sort_by_key(|c| c.offset);
    summary.chunks.dedup_by_key(|c| c.offset);
    match first_error {
        None => Ok(summary),
        Some(why) => Err(Box::new((summary, why))),
    }
}

/// The header of a chunk record at `at`, from the bytes `peek` read there; `None` when they
/// are no chunk header (too short, a compression string longer than any).
fn parse_chunk_head(at: u64, peek: &[u8]) -> Option<ChunkHead> {
    if peek.first() != Some(&op::CHUNK) {
        return None;
    }
    let b = 9;
    let start_ns = le_u64(peek, b)?;
    let end_ns = le_u64(peek, b + 8)?;
    let uncompressed_size = le_u64(peek, b + 16)?;
    let crc = le_u32(peek, b + 24)?;
    let clen = u64::from(le_u32(peek, b + 28)?);
    if clen > MAX_COMPRESSION_LEN {
        return None;
    }
    let c_at = b + 32;
    let c_end = c_at + usize::try_from(clen).ok()?;
    let compression = String::from_utf8_lossy(peek.get(c_at..c_end)?).into_owned();
    let records_len = le_u64(peek, c_end)?;
    Some(ChunkHead {
        start_ns,
        end_ns,
        uncompressed_size,
        crc,
        compression,
        records_at: at + RECORD_HEADER_LEN + CHUNK_FIXED_LEN + clen + CHUNK_RECORDS_LEN_LEN,
        records_len,
    })
}

/// Decompresses a whole chunk's records and checks them: `(records, CRC checked)`, or why not.
fn decode(head: &ChunkHead, compressed: &[u8]) -> Result<(Vec<u8>, bool), String> {
    if head.uncompressed_size > MAX_RECORD_LEN_U64 {
        return Err(format!(
            "its uncompressed size {} is more than the {MAX_RECORD_LEN} bytes a record may have",
            head.uncompressed_size
        ));
    }
    let cap = head.uncompressed_size + 1;
    let mut data = Vec::new();
    let result = match head.compression.as_str() {
        "" => {
            data.extend_from_slice(compressed);
            Ok(())
        }
        "zstd" => zstd::stream::read::Decoder::with_buffer(compressed)
            .map(zstd::stream::read::Decoder::single_frame)
            .and_then(|d| d.take(cap).read_to_end(&mut data).map(|_| ())),
        "lz4" => lz4::Decoder::new(compressed)
            .and_then(|d| d.take(cap).read_to_end(&mut data).map(|_| ())),
        other => return Err(format!("compression {other:?} is not supported")),
    };
    if let Err(err) = result {
        return Err(format!("it does not decompress ({err})"));
    }
    if data.len() as u64 != head.uncompressed_size {
        return Err(format!(
            "it decompresses to {} bytes, not the {} its header says",
            data.len(),
            head.uncompressed_size
        ));
    }
    if head.crc == 0 {
        return Ok((data, false));
    }
    let computed = crc32fast::hash(&data);
    if computed != head.crc {
        return Err(format!(
            "its CRC fails (saved {:08x}, computed {computed:08x})",
            head.crc
        ));
    }
    Ok((data, true))
}

/// Most work a repair may do, in bytes decompressed (or checked) over all its trials: about
/// a second or two of zstd (a 32 KiB chunk of 13 KiB compressed takes 3.4 GB).
const MAX_REPAIR_WORK: u64 = 1 << 32;

/// A chunk whose CRC fails or that does not decompress, mended when one flipped bit explains
/// it (the usual damage of storage: a bit error in one place): the stored CRC or the
/// uncompressed size one bit off from what the records give, or one bit of the compressed
/// records flipped back making them decompress to the stated size with the stated CRC. The
/// CRC-32 vouches for the result (a wrong mend would need a 32-bit coincidence among the
/// trials, about 1 in 40,000 for the largest allowed). `None` when no single bit does, or the
/// chunk is too big to try within [`MAX_REPAIR_WORK`].
///
/// Written here because no MCAP or compression library offers error correction; the search is
/// the textbook one for a CRC (one trial per bit), bounded.
fn repair(head: &ChunkHead, compressed: &[u8]) -> Option<Vec<u8>> {
    if head.uncompressed_size > MAX_RECORD_LEN_U64 {
        return None;
    }
    let size = usize::try_from(head.uncompressed_size).ok()?;
    let one_bit = |a: u64, b: u64| (a ^ b).count_ones() == 1;
    // The records are intact and the damage is in the header: the CRC or the size field.
    let mut whole = Vec::new();
    let streamed = match head.compression.as_str() {
        "" => {
            whole.extend_from_slice(compressed);
            true
        }
        "zstd" => zstd::stream::read::Decoder::with_buffer(compressed)
            .map(zstd::stream::read::Decoder::single_frame)
            .and_then(|d| d.take(MAX_RECORD_LEN_U64).read_to_end(&mut whole))
            .is_ok(),
        "lz4" => lz4::Decoder::new(compressed)
            .and_then(|d| d.take(MAX_RECORD_LEN_U64).read_to_end(&mut whole))
            .is_ok(),
        _ => false,
    };
    if streamed {
        let crc = crc32fast::hash(&whole);
        let size_ok = whole.len() == size || one_bit(whole.len() as u64, head.uncompressed_size);
        if (crc == head.crc && size_ok)
            || (whole.len() == size && one_bit(crc.into(), head.crc.into()))
        {
            return Some(whole);
        }
    }
    // One bit of the compressed records.
    let bits = (compressed.len() as u64).saturating_mul(8);
    if bits.saturating_mul(head.uncompressed_size.max(1)) > MAX_REPAIR_WORK {
        return None;
    }
    let mut trial = compressed.to_vec();
    let mut out = Vec::with_capacity(size);
    for i in 0..trial.len() {
        for bit in 0..8 {
            let mask = 1u8 << bit;
            if let Some(b) = trial.get_mut(i) {
                *b ^= mask;
            }
            let good = decompress_into(head, &trial, size, &mut out)
                && out.len() == size
                && crc32fast::hash(&out) == head.crc;
            if let Some(b) = trial.get_mut(i) {
                *b ^= mask;
            }
            if good {
                return Some(out);
            }
        }
    }
    None
}

/// Decompresses `compressed` into `out` (cleared first), at most `cap` bytes; whether it
/// decoded without error.
fn decompress_into(head: &ChunkHead, compressed: &[u8], cap: usize, out: &mut Vec<u8>) -> bool {
    out.clear();
    match head.compression.as_str() {
        "" => {
            if compressed.len() > cap {
                return false;
            }
            out.extend_from_slice(compressed);
            true
        }
        "zstd" => {
            out.reserve(cap);
            zstd::bulk::Decompressor::new()
                .and_then(|mut d| d.decompress_to_buffer(compressed, out))
                .is_ok()
        }
        "lz4" => lz4::Decoder::new(compressed)
            .and_then(|d| d.take(cap as u64 + 1).read_to_end(out).map(|_| ()))
            .is_ok(),
        _ => false,
    }
}

/// Decompresses what there is of a chunk cut by the end of the file: whatever the decoder
/// gives before the bytes run out (at most the chunk's uncompressed size).
fn decode_prefix(head: &ChunkHead, compressed: &[u8]) -> Vec<u8> {
    let cap = head.uncompressed_size.min(MAX_RECORD_LEN_U64);
    let mut data = Vec::new();
    // An error is the end of the bytes (or damage): what was decoded before it is kept.
    let _ = match head.compression.as_str() {
        "" => {
            let n = usize::try_from(cap).unwrap_or(usize::MAX);
            data.extend_from_slice(compressed.get(..n).unwrap_or(compressed));
            Ok(())
        }
        "zstd" => zstd::stream::read::Decoder::with_buffer(compressed)
            .map(zstd::stream::read::Decoder::single_frame)
            .and_then(|d| read_until_error(d.take(cap), &mut data)),
        "lz4" => {
            lz4::Decoder::new(compressed).and_then(|d| read_until_error(d.take(cap), &mut data))
        }
        _ => Ok(()),
    };
    data
}

/// Reads into `out` until the end or an error, keeping what came before the error.
fn read_until_error(mut r: impl Read, out: &mut Vec<u8>) -> std::io::Result<()> {
    let mut buf = [0u8; 16 << 10];
    loop {
        match r.read(&mut buf) {
            Ok(0) => return Ok(()),
            Ok(n) => out.extend_from_slice(buf.get(..n).unwrap_or(&[])),
            Err(e) if e.kind() == ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
}

fn le_u64(bytes: &[u8], at: usize) -> Option<u64> {
    let b: [u8; 8] = bytes.get(at..at.checked_add(8)?)?.try_into().ok()?;
    Some(u64::from_le_bytes(b))
}

fn le_u32(bytes: &[u8], at: usize) -> Option<u32> {
    let b: [u8; 4] = bytes.get(at..at.checked_add(4)?)?.try_into().ok()?;
    Some(u32::from_le_bytes(b))
}

/// Reads until `buf` is full or the source ends; returns the bytes read.
fn read_up_to(source: &mut impl Read, buf: &mut [u8]) -> std::io::Result<usize> {
    let mut len = 0;
    while let Some(rest) = buf.get_mut(len..) {
        if rest.is_empty() {
            break;
        }
        match source.read(rest) {
            Ok(0) => break,
            Ok(n) => len += n,
            Err(err) if err.kind() == ErrorKind::Interrupted => {}
            Err(err) => return Err(err),
        }
    }
    Ok(len)
}

/// Checks the first bytes of a file against the MCAP magic.
pub(crate) fn check_magic(found: &[u8]) -> Result<(), NotMcap> {
    if found == mcap::MAGIC {
        return Ok(());
    }
    if found.is_empty() {
        return Err(NotMcap::Empty);
    }
    if found.len() < mcap::MAGIC.len() && mcap::MAGIC.starts_with(found) {
        return Err(NotMcap::ShorterThanMagic {
            len: found.len(),
            magic_len: mcap::MAGIC.len(),
        });
    }
    Err(NotMcap::BadMagic {
        found: hex(found),
        expected: hex(mcap::MAGIC),
    })
}

fn hex(bytes: &[u8]) -> String {
    bytes
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect::<Vec<_>>()
        .join(" ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn magic_checks() {
        assert_eq!(check_magic(mcap::MAGIC), Ok(()));
        assert_eq!(check_magic(&[]), Err(NotMcap::Empty));
        assert_eq!(
            check_magic(&mcap::MAGIC[..5]),
            Err(NotMcap::ShorterThanMagic {
                len: 5,
                magic_len: 8
            })
        );
        assert_eq!(
            check_magic(b"PK\x03\x04").unwrap_err().to_string(),
            "it starts with 50 4b 03 04, not the MCAP magic 89 4d 43 41 50 30 0d 0a"
        );
    }

    #[test]
    fn string_lengths_past_the_body_are_refused_before_the_mcap_crate_allocates() {
        let mut header = 4u32.to_le_bytes().to_vec();
        header.extend(b"ros2");
        header.extend(0u32.to_le_bytes());
        assert!(strings_fit(op::HEADER, &header));
        assert!(parse_checked(op::HEADER, &header).is_ok());
        header[4 + 4..].copy_from_slice(&0xFEFF_FFFEu32.to_le_bytes());
        assert!(!strings_fit(op::HEADER, &header));
        assert!(parse_checked(op::HEADER, &header).is_err());
        // A channel whose metadata map holds a string longer than the map.
        let mut channel = vec![1, 0, 0, 0];
        for s in [&b"/odom"[..], b"json"] {
            channel.extend((s.len() as u32).to_le_bytes());
            channel.extend(s);
        }
        channel.extend(12u32.to_le_bytes());
        channel.extend(100u32.to_le_bytes());
        channel.extend([0; 8]);
        assert!(!strings_fit(op::CHANNEL, &channel));
    }

    #[test]
    fn a_chunk_header_parses_and_refuses_long_compression_names() {
        let mut b = vec![op::CHUNK];
        b.extend(100u64.to_le_bytes());
        b.extend(1u64.to_le_bytes());
        b.extend(2u64.to_le_bytes());
        b.extend(30u64.to_le_bytes());
        b.extend(7u32.to_le_bytes());
        b.extend(4u32.to_le_bytes());
        b.extend(b"zstd");
        b.extend(20u64.to_le_bytes());
        let head = parse_chunk_head(1000, &b).unwrap();
        assert_eq!((head.start_ns, head.end_ns), (1, 2));
        assert_eq!(head.uncompressed_size, 30);
        assert_eq!(head.compression, "zstd");
        assert_eq!(head.records_at, 1000 + 9 + 32 + 4 + 8);
        assert_eq!(head.records_len, 20);
        b[9 + 28] = 200;
        assert!(parse_chunk_head(1000, &b).is_none());
        assert!(parse_chunk_head(1000, &b[..20]).is_none());
    }
}
