//! What the readers could not read in a damaged log: one [`LostSpan`] per place of loss, in
//! band ([`crate::Record::Lost`], [`crate::RawRecord::Lost`]) and in total ([`Damage`]).

use std::collections::BTreeMap;

/// Spans kept in [`Damage::spans`]; any more are only counted ([`Damage::spans_total`]), so
/// that the report of a log damaged everywhere stays small.
pub const MAX_KEPT_SPANS: usize = 256;

/// One stretch of a log that could not be read: a chunk whose CRC fails or that does not
/// decompress, bytes skipped while the record framing was lost, or the unreadable end of a
/// chunk cut by the end of the file. Contiguous losses (no good message between them) are one
/// span.
#[derive(Debug, Clone, PartialEq, Eq)]
#[non_exhaustive]
pub struct LostSpan {
    /// File offset of the first byte not used.
    pub offset: u64,
    /// Bytes of the file not used, from `offset` (several pieces when the span joins
    /// several losses; then the sum).
    pub bytes: u64,
    /// Log time, ns, of the first message lost ([`LostSpan::exact_times`]) or of the last
    /// good message before the loss (`None`: the loss is at the start).
    pub start_ns: Option<u64>,
    /// Log time, ns, of the last message lost ([`LostSpan::exact_times`]) or of the first
    /// good message after the loss (`None`: nothing good came after it).
    pub end_ns: Option<u64>,
    /// Whether `start_ns..=end_ns` is the lost messages' own span (from the summary's chunk
    /// index, the chunk's message index, or the chunk's header where its times lie between
    /// the good messages around it), rather than the bounds set by those good messages.
    pub exact_times: bool,
    /// Chunk records lost, wholly or in part.
    pub chunks: u64,
    /// Messages lost per topic (the channel's topic name), when the message index records
    /// after the lost chunks (or the summary) tell; `None` when nothing tells.
    pub messages: Option<BTreeMap<String, u64>>,
    /// What was wrong, one line (the first loss's reason when the span joins several).
    pub why: String,
}

impl LostSpan {
    /// Messages lost on `topic`, when known.
    pub fn messages_on(&self, topic: &str) -> Option<u64> {
        self.messages
            .as_ref()
            .map(|m| m.get(topic).copied().unwrap_or(0))
    }

    /// Whether the span may have held messages (it is then yielded in band; a span known to
    /// hold none, such as a damaged message index, is only in [`Damage::spans`]).
    pub fn may_hold_messages(&self) -> bool {
        self.messages
            .as_ref()
            .is_none_or(|m| m.values().any(|n| *n > 0))
    }
}

/// The state of a log's summary section (the schemas, channels, chunk index and statistics
/// that a writer puts after the data).
#[derive(Debug, Clone, PartialEq, Eq, Default)]
#[non_exhaustive]
pub enum SummaryState {
    /// Found through the footer, its CRC checked (or, where the writer wrote none, every
    /// record of it parsed): its schemas and channels were read first, its chunk index guided
    /// the reader past damage, and its statistics count what was lost.
    Intact,
    /// There is one, but its CRC fails or a record of it is unreadable: the reason. The data
    /// section was read without its chunk index and statistics; the channels and schemas
    /// that still parse in it stand in only for those whose records the data lost.
    Damaged {
        /// Why, one line.
        why: String,
    },
    /// The log has none (its writer wrote none, or the file is cut before it).
    #[default]
    Absent,
}

/// Everything a reader could not read in a log, in total. Built as the reading goes; complete
/// once the reader has yielded its last record.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
#[non_exhaustive]
pub struct Damage {
    /// The first [`MAX_KEPT_SPANS`] spans lost, in file order.
    pub spans: Vec<LostSpan>,
    /// Spans lost in all.
    pub spans_total: u64,
    /// Bytes of the file not used, in all.
    pub bytes_lost: u64,
    /// Chunk records lost (wholly or in part), in all.
    pub chunks_lost: u64,
    /// Messages lost per topic: written minus read, by the summary's statistics when the
    /// summary is intact; otherwise the sum of the spans' counts when every span that may hold
    /// messages knows them; otherwise `None`.
    pub messages_lost: Option<BTreeMap<String, u64>>,
    /// The file does not start with the MCAP magic and header record (it was read all the
    /// same: its end or a chunk whose CRC checks showed it is MCAP).
    pub header_damaged: bool,
    /// The file does not end with the MCAP magic although its footer is there.
    pub tail_damaged: bool,
    /// The summary section.
    pub summary: SummaryState,
    /// The file is cut short: it ends inside a record (power lost while recording).
    pub cut: bool,
    /// Chunks whose records were used without a CRC check: the writer wrote no CRC, or the
    /// chunk is cut by the end of the file (its readable prefix was used).
    pub unverified_chunks: u64,
    /// Chunks whose CRC failed (or that did not decompress) mended: one flipped bit, in the
    /// header or the compressed records, explained the damage and the CRC checks after the
    /// mend (they are used whole, and are not a loss).
    pub repaired_chunks: u64,
}

impl Damage {
    /// Whether nothing is damaged: no loss, intact magic and header, no damaged summary,
    /// not cut, no chunk mended. (A log without a summary, or with chunks without CRCs, may be clean.)
    pub fn is_clean(&self) -> bool {
        self.spans_total == 0
            && !self.header_damaged
            && !self.tail_damaged
            && !self.cut
            && !matches!(self.summary, SummaryState::Damaged { .. })
            && self.repaired_chunks == 0
    }

    /// Adds a span to the totals.
    pub(crate) fn add(&mut self, span: &LostSpan) {
        self.spans_total += 1;
        self.bytes_lost += span.bytes;
        self.chunks_lost += span.chunks;
        if self.spans.len() < MAX_KEPT_SPANS {
            self.spans.push(span.clone());
        }
    }
}
