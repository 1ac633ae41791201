//! The order in which the navigator takes its inputs: the board's frames and the odometry as
//! they arrive (a log's chunks, a UART and the wheel encoders' callback), put in data-time
//! order in a window, each frame let out after the odometry up to its look-ahead.
//!
//! A frame stamped `t` is let out once the odometry has passed `t +`
//! [`ODOMETRY_LOOKAHEAD_US`] and a later frame has arrived [`REORDER_US`] of data time after
//! it (a frame reaching the stack late is still put in its place), or a later frame is
//! [`ODOMETRY_WAIT_US`] newer (odometry that stopped does not stall the frames), or more than
//! [`MAX_HELD_FRAMES`] wait, or the data ended; before it, every odometry sample up to its
//! look-ahead. Odometry with no frame after it is let out when more than
//! [`MAX_HELD_ODOMETRY`] samples wait. `stereonav replay` (a log) and the C interface (live
//! bytes and samples) both feed the navigator through this, so that they give the same map.

use alloc::collections::{BinaryHeap, VecDeque};
use core::cmp::{Ordering, Reverse};

use rig_model::odometry::OdomSample;

use crate::ODOMETRY_LOOKAHEAD_US;

/// The reorder window, microseconds of data time: a frame arriving up to this much after a
/// later frame is still put in its place. The board's latency (exposure, read-out, the
/// detector, the link) is tens of milliseconds.
pub const REORDER_US: u64 = 2_000_000;

/// A frame waits at most this long (data time of later frames) for the odometry to pass its
/// look-ahead: data whose odometry ends early, or has none, still streams.
pub const ODOMETRY_WAIT_US: u64 = 10_000_000;

/// Most frames held in the window (frames far out of order still stream).
pub const MAX_HELD_FRAMES: usize = 2_000;

/// Most odometry samples held waiting for a frame (an hour at 100 Hz: no frames for that
/// long still streams, the odometry then let out ahead of the next frame's).
pub const MAX_HELD_ODOMETRY: usize = 360_000;

/// One input of the navigator, in data-time order.
#[derive(Debug, Clone, PartialEq)]
pub enum Sequenced<F> {
    /// An odometry sample.
    Odometry(OdomSample),
    /// A frame with its stamp, microseconds.
    Frame(u64, F),
}

/// Something held in the window, ordered by `(t_us, arrival)`.
#[derive(Debug, Clone)]
struct Held<T> {
    t_us: u64,
    arrival: u64,
    item: T,
}

impl<T> PartialEq for Held<T> {
    fn eq(&self, other: &Self) -> bool {
        (self.t_us, self.arrival) == (other.t_us, other.arrival)
    }
}
impl<T> Eq for Held<T> {}
impl<T> PartialOrd for Held<T> {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}
impl<T> Ord for Held<T> {
    fn cmp(&self, other: &Self) -> Ordering {
        (self.t_us, self.arrival).cmp(&(other.t_us, other.arrival))
    }
}

/// The window (module docs); `F` is a frame's data.
#[derive(Debug, Clone)]
pub struct Sequencer<F> {
    frames: BinaryHeap<Reverse<Held<F>>>,
    odometry: BinaryHeap<Reverse<Held<OdomSample>>>,
    arrivals: u64,
    latest_frame_t: Option<u64>,
    latest_odometry_t: Option<u64>,
    last_pushed_frame_t: Option<u64>,
    frames_out_of_order: u64,
    ready: VecDeque<Sequenced<F>>,
    ended: bool,
}

impl<F> Default for Sequencer<F> {
    fn default() -> Self {
        Self::new()
    }
}

impl<F> Sequencer<F> {
    /// An empty window.
    pub fn new() -> Self {
        Self {
            frames: BinaryHeap::new(),
            odometry: BinaryHeap::new(),
            arrivals: 0,
            latest_frame_t: None,
            latest_odometry_t: None,
            last_pushed_frame_t: None,
            frames_out_of_order: 0,
            ready: VecDeque::new(),
            ended: false,
        }
    }

    /// An odometry sample arrived.
    pub fn push_odometry(&mut self, sample: OdomSample) {
        self.latest_odometry_t = self.latest_odometry_t.max(Some(sample.t_us));
        self.arrivals += 1;
        self.odometry.push(Reverse(Held {
            t_us: sample.t_us,
            arrival: self.arrivals,
            item: sample,
        }));
    }

    /// A frame stamped `t_us` arrived.
    pub fn push_frame(&mut self, t_us: u64, frame: F) {
        if self.last_pushed_frame_t.is_some_and(|last| t_us < last) {
            self.frames_out_of_order += 1;
        }
        self.last_pushed_frame_t = Some(t_us);
        self.latest_frame_t = self.latest_frame_t.max(Some(t_us));
        self.arrivals += 1;
        self.frames.push(Reverse(Held {
            t_us,
            arrival: self.arrivals,
            item: frame,
        }));
    }

    /// The data ended: everything held is let out.
    pub fn end(&mut self) {
        self.ended = true;
    }

    /// Whether [`Self::end`] was called.
    pub fn ended(&self) -> bool {
        self.ended
    }

    /// Frames that arrived older than the frame before them (put in their place if the
    /// window still held it).
    pub fn frames_out_of_order(&self) -> u64 {
        self.frames_out_of_order
    }

    /// Frames and odometry samples held.
    pub fn held(&self) -> (usize, usize) {
        (self.frames.len(), self.odometry.len())
    }

    /// The next input that may go to the navigator, if any yet.
    pub fn pop(&mut self) -> Option<Sequenced<F>> {
        loop {
            if let Some(input) = self.ready.pop_front() {
                return Some(input);
            }
            if !self.release() {
                return None;
            }
        }
    }

    /// Moves what the window can let out to `ready`; whether it moved anything.
    fn release(&mut self) -> bool {
        // Odometry after the last frame's look-ahead is never needed: at the end it stays.
        let Some(Reverse(first)) = self.frames.peek() else {
            return self.release_odometry_overflow();
        };
        let t = first.t_us;
        let look_ahead = t.saturating_add(ODOMETRY_LOOKAHEAD_US);
        let later_frame = |wait: u64| {
            self.latest_frame_t
                .is_some_and(|latest| latest >= t.saturating_add(wait))
        };
        let odometry_past = self.latest_odometry_t.is_some_and(|o| o >= look_ahead);
        let due = self.ended
            || self.frames.len() > MAX_HELD_FRAMES
            || (later_frame(REORDER_US) && odometry_past)
            || later_frame(ODOMETRY_WAIT_US);
        if !due {
            return self.release_odometry_overflow();
        }
        while self
            .odometry
            .peek()
            .is_some_and(|Reverse(s)| s.t_us <= look_ahead)
        {
            if let Some(Reverse(s)) = self.odometry.pop() {
                self.ready.push_back(Sequenced::Odometry(s.item));
            }
        }
        if let Some(Reverse(frame)) = self.frames.pop() {
            self.ready
                .push_back(Sequenced::Frame(frame.t_us, frame.item));
        }
        true
    }

    /// Lets out the oldest odometry when more than [`MAX_HELD_ODOMETRY`] samples wait.
    fn release_odometry_overflow(&mut self) -> bool {
        if self.odometry.len() <= MAX_HELD_ODOMETRY {
            return false;
        }
        if let Some(Reverse(s)) = self.odometry.pop() {
            self.ready.push_back(Sequenced::Odometry(s.item));
        }
        true
    }
}
