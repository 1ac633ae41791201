//! `stereonav fpga decode FILE` end to end (vehicle-interfaces.md section 5).

#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failure is the test failing

use crate::common;

use std::path::PathBuf;
use std::process::Output;

use common::{assert_one_line_error, stereonav};

use fpga_link::{Encoder, Feature};
use serde_json::{Value, json};

fn scratch(name: &str) -> PathBuf {
    common::scratch("fpga-cli", name)
}

fn lines(out: &Output) -> Vec<Value> {
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).expect("each line is JSON"))
        .collect()
}

#[test]
fn decodes_packets_skips_garbage_and_counts() {
    let f = |x, y, r| Feature {
        x_q4: x,
        y_q4: y,
        r,
    };
    let mut enc = Encoder::starting_at(41);
    let mut bytes = b"noise before the first sync".to_vec();
    enc.encode_to_vec(
        1_000,
        (&[f(16, 32, 300_000)], false),
        (&[], true),
        &mut bytes,
    )
    .unwrap();
    let corrupt_at = bytes.len();
    enc.encode_to_vec(
        51_000,
        (&[f(1, 2, 3)], false),
        (&[f(4, 5, -6)], false),
        &mut bytes,
    )
    .unwrap();
    bytes[corrupt_at + 30] ^= 0x01; // a bit flip in the second packet's features
    enc.encode_to_vec(
        101_000,
        (&[], true),
        (&[f(7, 8, 9), f(10, 11, 12)], false),
        &mut bytes,
    )
    .unwrap();
    let path = scratch("stream.bin");
    std::fs::write(&path, &bytes).unwrap();

    let out = lines(&stereonav(&["fpga", "decode", path.to_str().unwrap()]));
    assert_eq!(
        out,
        [
            json!({"frame": 41, "t_us": 1000, "flags": 2, "left": [[16, 32, 300000]], "right": []}),
            json!({"frame": 43, "t_us": 101000, "flags": 1, "left": [],
                   "right": [[7, 8, 9], [10, 11, 12]]}),
            json!({"packets": 2, "corrupt": 1, "lost": 1,
                   "bytes_skipped": 27 + fpga_link::packet_len(2)}),
        ]
    );
}

#[test]
fn an_empty_stream_prints_only_the_counters() {
    let path = scratch("empty.bin");
    std::fs::write(&path, b"").unwrap();
    let out = lines(&stereonav(&["fpga", "decode", path.to_str().unwrap()]));
    assert_eq!(
        out,
        [json!({"packets": 0, "corrupt": 0, "lost": 0, "bytes_skipped": 0})]
    );
}

#[test]
fn unreadable_input_is_one_line_and_non_zero() {
    for (args, needle) in [
        (
            vec!["fpga", "decode", "/nonexistent/stream.bin"],
            "cannot open /nonexistent/stream.bin",
        ),
        (vec!["fpga", "decode", "/"], "cannot read /"),
        (vec!["fpga", "decode"], "<FILE>"),
        (vec!["fpga", "encode"], "encode"),
    ] {
        let out = stereonav(&args);
        assert_one_line_error(&out, needle);
        assert!(out.stdout.is_empty(), "{args:?}");
    }
}

#[test]
fn emulated_board_stream_decodes_to_the_detector_output() {
    let image = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/images/ceiling-lamps.png")
        .to_string_lossy()
        .into_owned();
    let out = scratch("emulated.bin");
    let out_str = out.to_str().unwrap();
    let status = stereonav(&[
        "fpga",
        "emulate",
        out_str,
        &image,
        &image,
        &image,
        &image,
        "--max-features",
        "5",
        "--first-frame",
        "4294967295",
        "--t0-us",
        "7",
        "--period-us",
        "100",
    ]);
    assert!(
        status.status.success(),
        "{}",
        String::from_utf8_lossy(&status.stderr)
    );
    let decoded = lines(&stereonav(&["fpga", "decode", out_str]));
    // The detector's first five features of the image, as `stereonav harris` prints them.
    let harris =
        String::from_utf8(stereonav(&["harris", &image, "--max-features", "5"]).stdout).unwrap();
    let expected: Vec<Value> = harris
        .lines()
        .skip(1)
        .map(|l| {
            Value::from(
                l.split(',')
                    .map(|v| v.parse::<i64>().unwrap())
                    .collect::<Vec<_>>(),
            )
        })
        .collect();
    assert_eq!(decoded.len(), 3);
    for (i, frame) in decoded[..2].iter().enumerate() {
        assert_eq!(frame["frame"], json!([4_294_967_295u64, 0][i]));
        assert_eq!(frame["t_us"], json!(7 + 100 * i));
        assert_eq!(
            frame["flags"],
            json!(3),
            "12 features > 5 on both sides: overflow"
        );
        assert_eq!(frame["left"], Value::from(expected.clone()));
        assert_eq!(frame["right"], Value::from(expected.clone()));
    }
    assert_eq!(
        decoded[2]["lost"],
        json!(0),
        "the counter wraps without a loss"
    );

    for (args, needle) in [
        (
            vec!["fpga", "emulate", out_str, &image],
            "2 values required",
        ),
        (
            vec!["fpga", "emulate", out_str, &image, &image, &image],
            "pairs of LEFT RIGHT",
        ),
        (
            vec!["fpga", "emulate", out_str, &image, "/nonexistent.png"],
            "cannot open image",
        ),
        (
            vec![
                "fpga",
                "emulate",
                "/nonexistent/dir/out.bin",
                &image,
                &image,
            ],
            "cannot write",
        ),
    ] {
        assert_one_line_error(&stereonav(&args), needle);
    }
}
