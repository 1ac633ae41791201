//! Property tests: the fast row-streaming detector equals the integer reference (a literal
//! transcription of board-icd.md section 2) on random images of several kinds, random sizes,
//! thresholds over the whole i32 range and random `MAX_FEATURES`; row-by-row streaming with
//! line buffers wider than the image equals `detect`; one stream reused for many images equals
//! fresh ones.
//!
//! Every image is generated from `(kind, width, height, seed)` (see `common::generate`), so a
//! failure message is enough to reproduce it.
#![cfg(feature = "alloc")] // the whole-image calls and the references need `alloc`

use crate::common;

use common::{
    KINDS, Kind, assert_features_eq, assert_matches_reference, boxed_stream, generate, regs,
    run_stream,
};
use harris_core::{BoardStream, HarrisStream, Registers, detect, response_map};
use proptest::prelude::*;

/// `cases` cases (the `PROPTEST_CASES` environment variable overrides it, for longer hunts),
/// with failures saved next to this file for replay.
fn config(cases: u32) -> ProptestConfig {
    ProptestConfig {
        cases,
        failure_persistence: Some(Box::new(
            prop::test_runner::FileFailurePersistence::WithSource("regressions"),
        )),
        ..ProptestConfig::default()
    }
}

/// How a case picks its threshold.
#[derive(Debug, Clone, Copy)]
enum Threshold {
    /// This exact value.
    Fixed(i32),
    /// The response at quantile `q` of the image's own interior responses, plus `offset`
    /// (so that some pixels sit exactly at, one above and one below the threshold).
    Quantile(f64, i32),
}

fn threshold_strategy() -> impl Strategy<Value = Threshold> {
    prop_oneof![
        3 => any::<i32>().prop_map(Threshold::Fixed),
        2 => prop_oneof![
            Just(i32::MIN),
            Just(i32::MIN + 1),
            Just(-1),
            Just(0),
            Just(1),
            Just(1 << 18),
            Just((1 << 18) - 1),
            Just(i32::MAX - 1),
            Just(i32::MAX),
        ]
        .prop_map(Threshold::Fixed),
        2 => (-5000..5000i32).prop_map(Threshold::Fixed),
        2 => (0..(1i32 << 24)).prop_map(Threshold::Fixed),
        1 => (i32::MIN..-(1i32 << 20)).prop_map(Threshold::Fixed),
        4 => (0.5f64..=1.0, -1..=1i32).prop_map(|(q, o)| Threshold::Quantile(q, o)),
        1 => (0.0f64..0.5, -1..=1i32).prop_map(|(q, o)| Threshold::Quantile(q, o)),
    ]
}

/// Resolves a threshold against the image's response map.
fn resolve(t: Threshold, image: &[u8], width: usize, height: usize) -> i32 {
    match t {
        Threshold::Fixed(v) => v,
        Threshold::Quantile(q, offset) => {
            let map =
                response_map(image, &regs(width, height, 0, 1)).unwrap_or_else(|e| panic!("{e}"));
            let mut inner: Vec<i32> = (3..height - 3)
                .flat_map(|y| (3..width - 3).map(move |x| (x, y)))
                .map(|(x, y)| map[y * width + x])
                .collect();
            inner.sort_unstable();
            let i = ((inner.len() - 1) as f64 * q).round() as usize;
            inner[i].saturating_add(offset)
        }
    }
}

fn kind_strategy() -> impl Strategy<Value = Kind> {
    prop::sample::select(KINDS.to_vec())
}

fn max_features_strategy() -> impl Strategy<Value = usize> {
    prop_oneof![2 => 1..=1023usize, 2 => 1..=12usize, 1 => Just(1023usize)]
}

/// Sizes near multiples of the 16-pixel chunks, both of the image (`16 k + {-1, 0, 1}`) and of
/// the response range `3 ..= W - 4`, whose chunks start at column 3 (`16 k + {5, 6, 7}`).
fn chunk_edge_size(max: usize) -> impl Strategy<Value = usize> {
    (
        1..=max / 16,
        prop::sample::select(vec![-1i64, 0, 1, 5, 6, 7]),
    )
        .prop_map(|(k, d)| (16 * k as i64 + d) as usize)
        .prop_filter("ICD size range", move |&s| (16..=max).contains(&s))
}

/// One case: compares `detect`, `response_map` and row-by-row streams of several capacities
/// with the reference.
fn check_case(
    kind: Kind,
    width: usize,
    height: usize,
    seed: u64,
    t: Threshold,
    max_features: usize,
) {
    let image = generate(kind, width, height, seed);
    let threshold = resolve(t, &image, width, height);
    let r = regs(width, height, threshold, max_features);
    let what =
        format!("{kind:?} {width}x{height} seed {seed} threshold {threshold} max {max_features}");
    let expected = assert_matches_reference(&image, &r, &what);
    // Row by row, with line buffers exactly as wide as, or wider than, the image.
    let streamed = if width <= 80 {
        run_stream(&mut *boxed_stream::<80>(&r), &image, &r)
    } else {
        run_stream(&mut *boxed_stream::<331>(&r), &image, &r)
    };
    assert_features_eq(
        &streamed.0,
        &expected.features,
        &format!("{what}, row by row"),
    );
    assert_eq!(
        streamed.1, expected.overflow,
        "{what}, row by row: overflow"
    );
    if width <= 96 {
        let streamed = run_stream(&mut *boxed_stream::<96>(&r), &image, &r);
        assert_features_eq(
            &streamed.0,
            &expected.features,
            &format!("{what}, HarrisStream<96>"),
        );
        assert_eq!(streamed.1, expected.overflow);
    }
    let board = run_stream(
        &mut *Box::new(BoardStream::new(r).unwrap_or_else(|e| panic!("{e}"))),
        &image,
        &r,
    );
    assert_features_eq(
        &board.0,
        &expected.features,
        &format!("{what}, BoardStream"),
    );
    assert_eq!(board.1, expected.overflow);
}

proptest! {
    #![proptest_config(config(1000))]

    /// Small images, 16..=80 each way.
    #[test]
    fn small_images_equal_reference(
        kind in kind_strategy(),
        width in 16..=80usize,
        height in 16..=80usize,
        seed in any::<u64>(),
        t in threshold_strategy(),
        max_features in max_features_strategy(),
    ) {
        check_case(kind, width, height, seed, t, max_features);
    }
}

proptest! {
    #![proptest_config(config(400))]

    /// Wide images whose widths sit at chunk edges (up to 311 pixels), and tall ones.
    #[test]
    fn chunk_edge_sizes_equal_reference(
        kind in kind_strategy(),
        (width, height) in prop_oneof![
            (chunk_edge_size(311), 16..=40usize),
            (16..=40usize, chunk_edge_size(311)),
        ],
        seed in any::<u64>(),
        t in threshold_strategy(),
        max_features in max_features_strategy(),
    ) {
        check_case(kind, width, height, seed, t, max_features);
    }
}

/// One image of a reuse sequence.
#[derive(Debug, Clone)]
struct Job {
    kind: Kind,
    width: usize,
    height: usize,
    seed: u64,
    threshold: Threshold,
    max_features: usize,
    /// Rows of another image pushed, then abandoned (by `set_registers` or `reset`), first.
    abandoned_rows: Option<usize>,
    /// Whether to start this image with `reset()` (else `set_registers`) after abandoning.
    abandon_by_reset: bool,
}

fn job_strategy() -> impl Strategy<Value = Job> {
    (
        kind_strategy(),
        prop_oneof![16..=64usize, chunk_edge_size(128)],
        16..=48usize,
        any::<u64>(),
        threshold_strategy(),
        max_features_strategy(),
        prop::option::weighted(0.3, 0..64usize),
        any::<bool>(),
    )
        .prop_map(
            |(
                kind,
                width,
                height,
                seed,
                threshold,
                max_features,
                abandoned_rows,
                abandon_by_reset,
            )| Job {
                kind,
                width,
                height,
                seed,
                threshold,
                max_features,
                abandoned_rows,
                abandon_by_reset,
            },
        )
}

proptest! {
    #![proptest_config(config(200))]

    /// One stream reused across several images, with registers changed (or not) between them
    /// and some images abandoned half-way, gives what fresh detectors give.
    #[test]
    fn reused_stream_equals_fresh(jobs in prop::collection::vec(job_strategy(), 2..=6)) {
        let mut stream: Box<HarrisStream<128>> = boxed_stream(&regs(128, 16, 0, 1));
        let mut previous: Option<Registers> = None;
        for (i, job) in jobs.iter().enumerate() {
            let image = generate(job.kind, job.width, job.height, job.seed);
            let threshold = resolve(job.threshold, &image, job.width, job.height);
            let r = regs(job.width, job.height, threshold, job.max_features);
            let what = format!("job {i} of {jobs:?}");
            if let Some(rows) = job.abandoned_rows {
                // Some rows of another image with the previous registers, then abandoned.
                let old = stream.registers();
                let other = generate(Kind::Noise, old.width, old.height, job.seed ^ 1);
                for row in other.chunks_exact(old.width).take(rows.min(old.height)) {
                    stream.push_row(row).unwrap_or_else(|e| panic!("{what}: {e}"));
                }
                if job.abandon_by_reset && old == r {
                    stream.reset();
                }
            }
            // Registers equal to the previous image's may be kept without `set_registers`
            // (unless an image was abandoned and not reset).
            let keep = previous == Some(r)
                && (job.abandoned_rows.is_none() || job.abandon_by_reset)
                && job.seed % 2 == 0;
            if !keep {
                stream.set_registers(r).unwrap_or_else(|e| panic!("{what}: {e}"));
            }
            let reused = run_stream(&mut *stream, &image, &r);
            let fresh = detect(&image, &r).unwrap_or_else(|e| panic!("{what}: {e}"));
            assert_features_eq(&reused.0, &fresh.features, &what);
            prop_assert_eq!(reused.1, fresh.overflow, "{}", what);
            previous = Some(r);
        }
    }
}

proptest! {
    #![proptest_config(config(12))]

    /// A few very wide or very tall images: the chunk bitsets span several 64-bit words
    /// beyond 1030 pixels.
    #[test]
    fn very_wide_and_tall_images_equal_reference(
        kind in kind_strategy(),
        (width, height) in prop_oneof![
            (1000..=4095usize, 16..=24usize),
            (16..=24usize, 1000..=4095usize),
        ],
        seed in any::<u64>(),
        t in threshold_strategy(),
        max_features in max_features_strategy(),
    ) {
        let image = generate(kind, width, height, seed);
        let threshold = resolve(t, &image, width, height);
        let r = regs(width, height, threshold, max_features);
        let what = format!("{kind:?} {width}x{height} seed {seed} threshold {threshold} max {max_features}");
        let expected = assert_matches_reference(&image, &r, &what);
        let streamed = run_stream(&mut *boxed_stream::<4095>(&r), &image, &r);
        assert_features_eq(&streamed.0, &expected.features, &what);
        prop_assert_eq!(streamed.1, expected.overflow);
    }
}

proptest! {
    #![proptest_config(config(150))]

    /// A stream cloned part-way through an image carries on exactly like the original.
    #[test]
    fn cloned_stream_continues_like_the_original(
        kind in kind_strategy(),
        width in 16..=64usize,
        height in 16..=48usize,
        seed in any::<u64>(),
        t in threshold_strategy(),
        max_features in max_features_strategy(),
        split in 0..48usize,
    ) {
        let image = generate(kind, width, height, seed);
        let threshold = resolve(t, &image, width, height);
        let r = regs(width, height, threshold, max_features);
        let mut stream = boxed_stream::<64>(&r);
        let split = split.min(height);
        let mut before = Vec::new();
        for row in image.chunks_exact(width).take(split) {
            before.extend_from_slice(stream.push_row(row).unwrap_or_else(|e| panic!("{e}")));
        }
        let mut copy = stream.clone();
        let mut rest = [Vec::new(), Vec::new()];
        for row in image.chunks_exact(width).skip(split) {
            rest[0].extend_from_slice(stream.push_row(row).unwrap_or_else(|e| panic!("{e}")));
            rest[1].extend_from_slice(copy.push_row(row).unwrap_or_else(|e| panic!("{e}")));
        }
        prop_assert_eq!(&rest[0], &rest[1]);
        prop_assert_eq!(stream.finish(), copy.finish());
        before.extend_from_slice(&rest[0]);
        let fresh = detect(&image, &r).unwrap_or_else(|e| panic!("{e}"));
        prop_assert_eq!(before, fresh.features);
    }
}
