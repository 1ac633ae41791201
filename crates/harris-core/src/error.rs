//! Errors of the detector: register values out of the ICD's ranges and misuse of the row stream.

/// Everything that can go wrong when configuring or feeding the detector.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// `WIDTH` outside the ICD's range (board-icd.md section 1).
    #[error("image width {width} is outside the board's range {min}..={max}")]
    WidthOutOfRange {
        /// The width that was asked for.
        width: usize,
        /// Smallest width the board supports.
        min: usize,
        /// Largest width the board supports.
        max: usize,
    },
    /// `HEIGHT` outside the ICD's range (board-icd.md section 1).
    #[error("image height {height} is outside the board's range {min}..={max}")]
    HeightOutOfRange {
        /// The height that was asked for.
        height: usize,
        /// Smallest height the board supports.
        min: usize,
        /// Largest height the board supports.
        max: usize,
    },
    /// `MAX_FEATURES` outside `1..=1023` (board-icd.md section 1).
    #[error("max_features {max_features} is outside the board's range {min}..={max}")]
    MaxFeaturesOutOfRange {
        /// The value that was asked for.
        max_features: usize,
        /// Smallest allowed value.
        min: usize,
        /// Largest allowed value.
        max: usize,
    },
    /// The image is wider than the line buffers this detector was built with.
    #[error("image width {width} exceeds the line-buffer capacity {capacity} of this detector")]
    WidthExceedsCapacity {
        /// The width that was asked for.
        width: usize,
        /// The detector's `MAX_WIDTH`.
        capacity: usize,
    },
    /// A pushed row does not have `WIDTH` pixels.
    #[error("row {row} has {actual} pixels, expected {expected}")]
    RowLength {
        /// Index of the offending row in the image.
        row: usize,
        /// `WIDTH`.
        expected: usize,
        /// Pixels in the pushed row.
        actual: usize,
    },
    /// More rows were pushed than the image has.
    #[error("image has {height} rows, but another row was pushed")]
    TooManyRows {
        /// `HEIGHT`.
        height: usize,
    },
    /// The image was finished before all of its rows arrived.
    #[error("image finished after {rows} of {height} rows")]
    IncompleteImage {
        /// Rows received.
        rows: usize,
        /// `HEIGHT`.
        height: usize,
    },
    /// A whole-image buffer does not hold `width * height` pixels.
    #[error("image buffer has {actual} bytes, expected {expected} ({width}x{height})")]
    ImageSize {
        /// Image width.
        width: usize,
        /// Image height.
        height: usize,
        /// `width * height`.
        expected: usize,
        /// Bytes in the buffer.
        actual: usize,
    },
}
