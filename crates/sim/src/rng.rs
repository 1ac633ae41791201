//! The run's random streams: one ChaCha8 generator per purpose (and per frame where frames are
//! independent), all from the scenario's seed, so that turning one source of noise on or off
//! does not change the draws of another, and the same seed gives the same bytes.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// What a random stream is used for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u64)]
pub(crate) enum Stream {
    /// Lamp jitter of the world's grids.
    World = 1,
    /// Odometry noise.
    Odometry = 2,
    /// Fast mode: pixel noise, responses and clutter of one frame.
    Features = 3,
    /// Rendered mode: sensor noise of one frame.
    Image = 4,
    /// Link faults.
    Faults = 5,
    /// Chunking and host jitter.
    Chunks = 6,
}

/// The generator of `stream`, sub-stream `index` (a frame index, or 0).
pub(crate) fn stream_rng(seed: u64, stream: Stream, index: u64) -> ChaCha8Rng {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    // 2^40 sub-streams per purpose: far more frames than any run has.
    rng.set_stream(((stream as u64) << 40) | (index & ((1 << 40) - 1)));
    rng
}
