//! Misuse is an `Error` value carrying the values that were wrong, never a panic; and the
//! board-sized detector's state stays within the 64 KiB.
#![cfg(feature = "alloc")] // the whole-image calls and the references need `alloc`

use crate::common;

use common::{Kind, boxed_stream, generate, regs, run_stream};
use harris_core::{
    BOARD_WIDTH, BoardStream, Error, HarrisStream, MAX_FEATURES_LIMIT, MAX_SIZE, MIN_SIZE,
    Registers, detect, reference, response_map,
};

#[test]
fn board_stream_state_fits_in_64_kib() {
    let size = size_of::<BoardStream>();
    assert!(size <= 65_536, "BoardStream is {size} bytes");
    // And it grows linearly with the width: O(WIDTH) memory, as the ICD asks.
    let per_column = size_of::<HarrisStream<1024>>() - size_of::<HarrisStream<512>>();
    assert!(per_column <= 512 * 80, "{per_column} bytes per 512 columns");
    assert!(size_of::<HarrisStream<BOARD_WIDTH>>() == size);
}

/// Every register out of range, in every entry point that takes registers.
#[test]
fn registers_out_of_range() {
    let ok = Registers {
        width: 32,
        height: 32,
        ..Registers::default()
    };
    let cases = [
        (
            Registers {
                width: MIN_SIZE - 1,
                ..ok
            },
            Error::WidthOutOfRange {
                width: 15,
                min: 16,
                max: 4095,
            },
        ),
        (
            Registers {
                width: MAX_SIZE + 1,
                ..ok
            },
            Error::WidthOutOfRange {
                width: 4096,
                min: 16,
                max: 4095,
            },
        ),
        (
            Registers { width: 0, ..ok },
            Error::WidthOutOfRange {
                width: 0,
                min: 16,
                max: 4095,
            },
        ),
        (
            Registers {
                width: usize::MAX,
                ..ok
            },
            Error::WidthOutOfRange {
                width: usize::MAX,
                min: 16,
                max: 4095,
            },
        ),
        (
            Registers {
                height: MIN_SIZE - 1,
                ..ok
            },
            Error::HeightOutOfRange {
                height: 15,
                min: 16,
                max: 4095,
            },
        ),
        (
            Registers {
                height: MAX_SIZE + 1,
                ..ok
            },
            Error::HeightOutOfRange {
                height: 4096,
                min: 16,
                max: 4095,
            },
        ),
        (
            Registers {
                height: usize::MAX,
                ..ok
            },
            Error::HeightOutOfRange {
                height: usize::MAX,
                min: 16,
                max: 4095,
            },
        ),
        (
            Registers {
                max_features: 0,
                ..ok
            },
            Error::MaxFeaturesOutOfRange {
                max_features: 0,
                min: 1,
                max: 1023,
            },
        ),
        (
            Registers {
                max_features: MAX_FEATURES_LIMIT + 1,
                ..ok
            },
            Error::MaxFeaturesOutOfRange {
                max_features: 1024,
                min: 1,
                max: 1023,
            },
        ),
        // The first register out of range is reported.
        (
            Registers {
                width: 5,
                height: 5,
                threshold: 0,
                max_features: 0,
            },
            Error::WidthOutOfRange {
                width: 5,
                min: 16,
                max: 4095,
            },
        ),
    ];
    for (bad, expected) in cases {
        assert_eq!(bad.validate(), Err(expected), "{bad:?}");
        assert_eq!(
            HarrisStream::<64>::new(bad).err(),
            Some(expected),
            "new {bad:?}"
        );
        let mut stream = boxed_stream::<64>(&ok);
        assert_eq!(
            stream.set_registers(bad),
            Err(expected),
            "set_registers {bad:?}"
        );
        // A refused change leaves the detector as it was.
        assert_eq!(stream.registers(), ok);
        let img = generate(Kind::Noise, 32, 32, 1);
        assert_eq!(
            run_stream(&mut *stream, &img, &ok).0,
            detect(&img, &ok).map(|d| d.features).unwrap_or_default()
        );
        // Whole-image calls check the registers before the buffer (whose size would overflow).
        assert_eq!(detect(&[], &bad).err(), Some(expected), "detect {bad:?}");
        assert_eq!(
            response_map(&[], &bad).err(),
            Some(expected),
            "response_map {bad:?}"
        );
        assert_eq!(
            reference::integer(&[], &bad).err(),
            Some(expected),
            "reference::integer {bad:?}"
        );
        assert_eq!(
            reference::float(&[], &bad).err(),
            Some(expected),
            "reference::float {bad:?}"
        );
    }
    // Both ends of every range are accepted; any threshold is.
    for good in [
        Registers {
            width: MIN_SIZE,
            height: MAX_SIZE,
            threshold: i32::MIN,
            max_features: 1,
        },
        Registers {
            width: MAX_SIZE,
            height: MIN_SIZE,
            threshold: i32::MAX,
            max_features: MAX_FEATURES_LIMIT,
        },
    ] {
        assert_eq!(good.validate(), Ok(()));
        assert!(HarrisStream::<MAX_SIZE>::new(good).is_ok());
    }
    assert_eq!(
        Registers::default(),
        Registers {
            width: 752,
            height: 480,
            threshold: 1 << 18,
            max_features: 512
        }
    );
    assert_eq!(Registers::default().validate(), Ok(()));
}

#[test]
fn width_above_capacity() {
    let r = regs(65, 20, 0, 10);
    assert_eq!(
        HarrisStream::<64>::new(r).err(),
        Some(Error::WidthExceedsCapacity {
            width: 65,
            capacity: 64
        })
    );
    let mut stream = boxed_stream::<64>(&regs(64, 20, 0, 10));
    assert_eq!(
        stream.set_registers(r),
        Err(Error::WidthExceedsCapacity {
            width: 65,
            capacity: 64
        })
    );
    assert_eq!(stream.registers(), regs(64, 20, 0, 10));
    let board = Registers {
        width: BOARD_WIDTH + 1,
        ..Registers::default()
    };
    assert_eq!(
        BoardStream::new(board).err(),
        Some(Error::WidthExceedsCapacity {
            width: 753,
            capacity: 752
        })
    );
    // A detector too small for any image the board takes.
    assert_eq!(
        HarrisStream::<8>::new(regs(16, 16, 0, 1)).err(),
        Some(Error::WidthExceedsCapacity {
            width: 16,
            capacity: 8
        })
    );
}

/// Rows of the wrong length, too many rows, finishing early: errors with the values, after
/// which the stream carries on as if the bad call had not happened.
#[test]
fn stream_misuse() {
    let (w, h) = (24, 18);
    let r = regs(w, h, -1, 1023);
    let img = generate(Kind::Noise, w, h, 5);
    let expected = detect(&img, &r).unwrap_or_else(|e| panic!("{e}"));
    let mut stream = boxed_stream::<32>(&r);
    assert_eq!(
        stream.finish(),
        Err(Error::IncompleteImage { rows: 0, height: h })
    );
    let mut features = Vec::new();
    for (y, row) in img.chunks_exact(w).enumerate() {
        assert_eq!(
            stream.push_row(&row[1..]).err(),
            Some(Error::RowLength {
                row: y,
                expected: w,
                actual: w - 1
            })
        );
        assert_eq!(
            stream.push_row(&[]).err(),
            Some(Error::RowLength {
                row: y,
                expected: w,
                actual: 0
            })
        );
        let longer = [row, &[0u8; 9][..]].concat();
        assert_eq!(
            stream.push_row(&longer).err(),
            Some(Error::RowLength {
                row: y,
                expected: w,
                actual: w + 9
            })
        );
        assert_eq!(stream.rows_pushed(), y);
        if y == 10 {
            assert_eq!(
                stream.finish(),
                Err(Error::IncompleteImage {
                    rows: 10,
                    height: h
                })
            );
        }
        features.extend_from_slice(stream.push_row(row).unwrap_or_else(|e| panic!("{e}")));
    }
    assert_eq!(
        stream.push_row(&img[..w]).err(),
        Some(Error::TooManyRows { height: h })
    );
    assert_eq!(
        stream.push_row(&img[..w]).err(),
        Some(Error::TooManyRows { height: h })
    );
    assert_eq!(stream.rows_pushed(), h);
    let summary = stream.finish().unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(features, expected.features);
    assert_eq!(
        (summary.features, summary.overflow),
        (expected.features.len(), expected.overflow)
    );
    // After finishing, a new image: finishing it at once is early again.
    assert_eq!(
        stream.finish(),
        Err(Error::IncompleteImage { rows: 0, height: h })
    );
    assert_eq!(
        run_stream(&mut *stream, &img, &r),
        (expected.features, expected.overflow)
    );
}

/// `detect`, `response_map` and the references with a buffer of the wrong size.
#[test]
fn whole_image_buffer_of_the_wrong_size() {
    let r = regs(20, 17, 0, 10);
    for len in [0, 1, 339, 341, 20 * 20, 100_000] {
        let buffer = vec![7u8; len];
        let expected = Error::ImageSize {
            width: 20,
            height: 17,
            expected: 340,
            actual: len,
        };
        assert_eq!(detect(&buffer, &r).err(), Some(expected));
        assert_eq!(response_map(&buffer, &r).err(), Some(expected));
        assert_eq!(reference::integer(&buffer, &r).err(), Some(expected));
        assert_eq!(reference::float(&buffer, &r).err(), Some(expected));
    }
    assert!(detect(&[7u8; 340], &r).is_ok());
}

/// Every error says what was wrong, with the numbers.
#[test]
fn error_messages_carry_the_values() {
    let cases = [
        (
            Error::WidthOutOfRange {
                width: 15,
                min: 16,
                max: 4095,
            },
            ["15", "16", "4095"].as_slice(),
        ),
        (
            Error::HeightOutOfRange {
                height: 4096,
                min: 16,
                max: 4095,
            },
            &["4096", "16", "4095"],
        ),
        (
            Error::MaxFeaturesOutOfRange {
                max_features: 0,
                min: 1,
                max: 1023,
            },
            &["0", "1", "1023"],
        ),
        (
            Error::WidthExceedsCapacity {
                width: 800,
                capacity: 752,
            },
            &["800", "752"],
        ),
        (
            Error::RowLength {
                row: 3,
                expected: 752,
                actual: 751,
            },
            &["3", "752", "751"],
        ),
        (Error::TooManyRows { height: 480 }, &["480"]),
        (
            Error::IncompleteImage {
                rows: 12,
                height: 480,
            },
            &["12", "480"],
        ),
        (
            Error::ImageSize {
                width: 20,
                height: 17,
                expected: 340,
                actual: 339,
            },
            &["20", "17", "340", "339"],
        ),
    ];
    for (error, values) in cases {
        let message = error.to_string();
        for v in values {
            assert!(message.contains(v), "{message:?} lacks {v}");
        }
    }
}
