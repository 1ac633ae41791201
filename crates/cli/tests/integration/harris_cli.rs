//! `stereonav harris` end to end: output format, registers, and one-line errors.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failure is the test failing

use crate::common;

use std::path::{Path, PathBuf};

use common::{assert_one_line_error, stereonav};

fn fixture(name: &str) -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/images")
        .join(name)
        .to_string_lossy()
        .into_owned()
}

fn scratch_dir(test: &str) -> PathBuf {
    let dir = common::scratch(&format!("cli-{test}"), "");
    std::fs::create_dir_all(&dir).expect("temp dir");
    dir
}

fn parse(stdout: &[u8]) -> Vec<(u16, u16, i32)> {
    let text = String::from_utf8(stdout.to_vec()).expect("utf-8");
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some("x_q4,y_q4,r"));
    lines
        .map(|line| {
            let f: Vec<&str> = line.split(',').collect();
            assert_eq!(f.len(), 3, "{line}");
            (
                f[0].parse().unwrap(),
                f[1].parse().unwrap(),
                f[2].parse().unwrap(),
            )
        })
        .collect()
}

#[test]
fn finds_every_lamp_of_the_bundled_ceiling_in_board_order() {
    let out = stereonav(&["harris", &fixture("ceiling-lamps.png")]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let features = parse(&out.stdout);
    // The eight lamps of fixtures/make_ceiling_image.py, each within 0.1 px.
    let lamps = [
        (100.3, 80.6),
        (260.0, 95.25),
        (421.7, 70.1),
        (610.5, 88.8),
        (140.2, 330.4),
        (330.9, 350.0),
        (505.5, 315.7),
        (680.1, 401.3),
    ];
    for (u, v) in lamps {
        let found = features.iter().any(|&(x, y, _)| {
            (f64::from(x) / 16.0 - u).abs() <= 0.1 && (f64::from(y) / 16.0 - v).abs() <= 0.1
        });
        assert!(found, "lamp at ({u}, {v}) not found in {features:?}");
    }
    // Raster order by the integer pixel.
    let keys: Vec<_> = features
        .iter()
        .map(|&(x, y, _)| ((y + 8) / 16, (x + 8) / 16))
        .collect();
    let mut sorted = keys.clone();
    sorted.sort_unstable();
    assert_eq!(keys, sorted);
}

#[test]
fn registers_change_the_output() {
    let all = parse(&stereonav(&["harris", &fixture("ceiling-lamps.png")]).stdout);
    let capped = parse(
        &stereonav(&[
            "harris",
            &fixture("ceiling-lamps.png"),
            "--max-features",
            "3",
        ])
        .stdout,
    );
    assert_eq!(capped, all[..3]);
    let strong = parse(
        &stereonav(&[
            "harris",
            &fixture("ceiling-lamps.png"),
            "--threshold",
            "55000000",
        ])
        .stdout,
    );
    assert!(!strong.is_empty() && strong.len() < all.len());
    assert!(strong.iter().all(|&(_, _, r)| r > 55_000_000));
    let negative = stereonav(&[
        "harris",
        &fixture("ceiling-lamps.png"),
        "--threshold",
        "-5",
        "--max-features",
        "1023",
    ]);
    assert!(negative.status.success());
}

#[test]
fn reads_pgm_like_png() {
    let dir = scratch_dir("pgm");
    let png = fixture("ceiling-lamps.png");
    let pgm = dir.join("ceiling.pgm");
    image::open(&png).unwrap().save(&pgm).unwrap();
    let from_png = stereonav(&["harris", &png]);
    let from_pgm = stereonav(&["harris", pgm.to_str().unwrap()]);
    assert!(
        from_pgm.status.success(),
        "{}",
        String::from_utf8_lossy(&from_pgm.stderr)
    );
    assert_eq!(from_png.stdout, from_pgm.stdout);
}

#[test]
fn bad_input_is_one_line_and_non_zero() {
    let dir = scratch_dir("bad");
    assert_one_line_error(
        &stereonav(&["harris", "/nonexistent/ceiling.png"]),
        "cannot open image",
    );

    let not_image = dir.join("notes.png");
    std::fs::write(&not_image, b"these are not pixels").unwrap();
    assert_one_line_error(
        &stereonav(&["harris", not_image.to_str().unwrap()]),
        "notes.png",
    );

    let truncated = dir.join("truncated.png");
    let bytes = std::fs::read(fixture("ceiling-lamps.png")).unwrap();
    std::fs::write(&truncated, &bytes[..bytes.len() / 2]).unwrap();
    assert_one_line_error(
        &stereonav(&["harris", truncated.to_str().unwrap()]),
        "truncated.png",
    );

    let colour = dir.join("colour.png");
    image::RgbImage::new(32, 32).save(&colour).unwrap();
    assert_one_line_error(
        &stereonav(&["harris", colour.to_str().unwrap()]),
        "expected 8-bit grayscale",
    );

    let tiny = dir.join("tiny.png");
    image::GrayImage::new(8, 32).save(&tiny).unwrap();
    assert_one_line_error(&stereonav(&["harris", tiny.to_str().unwrap()]), "width 8");

    let png = fixture("ceiling-lamps.png");
    assert_one_line_error(
        &stereonav(&["harris", &png, "--max-features", "0"]),
        "max_features 0",
    );
    assert_one_line_error(
        &stereonav(&["harris", &png, "--max-features", "1024"]),
        "1024",
    );
    assert_one_line_error(
        &stereonav(&["harris", &png, "--threshold", "lots"]),
        "--threshold",
    );
    assert_one_line_error(
        &stereonav(&["harris", &png, "--threshold", "4294967296"]),
        "--threshold",
    );
    assert_one_line_error(&stereonav(&["harris"]), "<IMAGE>");
    assert_one_line_error(&stereonav(&["harris", &png, "--bogus"]), "--bogus");
}

#[test]
fn help_still_prints_in_full() {
    let out = stereonav(&["harris", "--help"]);
    assert!(out.status.success());
    assert!(String::from_utf8_lossy(&out.stdout).contains("--max-features"));
}
