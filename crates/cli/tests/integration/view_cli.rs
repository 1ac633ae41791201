//! `stereonav view` end to end: headless screenshots of a vehicle log replayed on the fly, of
//! one localised on a saved map and of an estimates file, and one-line errors on bad input,
//! also for the window when there is no display. The screenshots are rasterised on the CPU: no
//! display, GPU or system package is needed, so nothing here skips (but the foreign MCAP file
//! when `shared/` lacks it).

#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failure is the test failing

use crate::common;

use std::collections::HashSet;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use common::{assert_one_line_error, fixture, s, stereonav};

fn scratch(name: &str) -> PathBuf {
    common::scratch("view-cli", name)
}

fn ok(out: &Output) {
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// The PNG is `width x height` and far from a blank or single-colour image.
fn assert_screenshot(path: &Path, width: u32, height: u32) {
    let img = image::open(path).unwrap().to_rgba8();
    assert_eq!(img.dimensions(), (width, height));
    let colours: HashSet<[u8; 4]> = img.pixels().map(|p| p.0).collect();
    assert!(colours.len() > 100, "{} colours", colours.len());
}

#[test]
fn a_vehicle_log_replayed_on_the_fly_is_rendered_headless() {
    let png = scratch("pe.png");
    let out = stereonav(&[
        "view",
        s(&fixture("paper-experiment.mcap")),
        "--rig",
        s(&fixture("paper-experiment.rig.toml")),
        "--skip-phase1",
        "--screenshot",
        s(&png),
    ]);
    ok(&out);
    assert!(out.stdout.is_empty() && out.stderr.is_empty());
    assert_screenshot(&png, 1280, 800);
}

#[test]
fn an_estimates_file_is_rendered_at_a_time_and_size() {
    let est = scratch("pc-est.mcap");
    ok(&stereonav(&[
        "replay",
        s(&fixture("paper-calibration.mcap")),
        "--out",
        s(&est),
    ]));
    let png = scratch("pc-est.png");
    ok(&stereonav(&[
        "view",
        s(&est),
        "--screenshot",
        s(&png),
        "--time",
        "170",
        "--size",
        "1440x900",
    ]));
    assert_screenshot(&png, 1440, 900);
}

/// A log through EuRoC's radtan lenses, simulated and viewed by the command line: the
/// screenshot is the library's picture of the same log and rig at the same time (the viewer's
/// `tests/lens.rs` checks that picture: the rings taken through the lens, each around its
/// accepted raw feature), a frame at which the navigator's update accepted observations.
#[test]
fn a_lens_log_is_rendered_headless_as_the_library_renders_it() {
    let scenario = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/scenarios/paper-experiment-radtan.toml");
    let (log, rig) = (scratch("radtan.mcap"), scratch("radtan.rig.toml"));
    ok(&stereonav(&[
        "simulate",
        s(&scenario),
        "--out",
        s(&log),
        "--rig",
        s(&rig),
    ]));
    let png = scratch("radtan.png");
    let out = stereonav(&[
        "view",
        s(&log),
        "--rig",
        s(&rig),
        "--screenshot",
        s(&png),
        "--time",
        "15",
    ]);
    ok(&out);
    assert!(out.stdout.is_empty() && out.stderr.is_empty());
    assert_screenshot(&png, 1280, 800);

    let options = viewer::LoadOptions {
        rig: Some(rig_model::Rig::load(&rig).unwrap()),
        ..viewer::LoadOptions::default()
    };
    let model = viewer::load(&log, &options, &mut |_, _| {}).unwrap();
    assert!(model.lens.is_some());
    let marks = model.marks(model.frame_at(15.0).unwrap());
    assert!(marks.on_landmarks.unwrap() > 0, "{marks:?}");
    let shot = viewer::screenshot(model, Some(15.0), viewer::MIN_SCREENSHOT_SIZE).unwrap();
    let img = image::open(&png).unwrap().to_rgba8();
    assert!(
        img.as_raw() == &shot.frame.rgba,
        "the command line's picture is the library's"
    );
}

/// `--map`: the log localised on a map that `stereonav replay --save-map` made from it, shown
/// while still lost and at the end; the map's one-line errors.
#[test]
fn a_log_on_a_saved_map_is_rendered_headless() {
    let log = fixture("paper-experiment.mcap");
    let map = scratch("pe.map");
    let est = scratch("pe-est.mcap");
    ok(&stereonav(&[
        "replay",
        s(&log),
        "--rig",
        s(&fixture("paper-experiment.rig.toml")),
        "--save-map",
        s(&map),
        "--out",
        s(&est),
    ]));
    for (time, name) in [
        (None, "pe-localized-end.png"),
        (Some("2"), "pe-localized-2s.png"),
    ] {
        let png = scratch(name);
        let mut args = vec!["view", s(&log), "--map", s(&map), "--screenshot", s(&png)];
        args.extend(time.map(|t| ["--time", t]).iter().flatten());
        let out = stereonav(&args);
        ok(&out);
        assert!(out.stdout.is_empty() && out.stderr.is_empty());
        assert_screenshot(&png, 1280, 800);
    }
    let png = scratch("x.png");
    let out = stereonav(&["view", s(&est), "--map", s(&map), "--screenshot", s(&png)]);
    assert_one_line_error(&out, "not a vehicle log");
    let missing = scratch("no-such.map");
    let out = stereonav(&[
        "view",
        s(&log),
        "--map",
        s(&missing),
        "--screenshot",
        s(&png),
    ]);
    assert_one_line_error(&out, "no-such.map");
    let out = stereonav(&[
        "view",
        s(&log),
        "--map",
        s(&map),
        "--skip-phase1",
        "--screenshot",
        s(&png),
    ]);
    assert_one_line_error(&out, "--skip-phase1");
}

#[test]
fn a_missing_file_is_one_line() {
    let out = stereonav(&[
        "view",
        s(&scratch("no-such-log.mcap")),
        "--screenshot",
        s(&scratch("x.png")),
    ]);
    assert_one_line_error(&out, "no-such-log.mcap");
}

#[test]
fn a_text_file_is_not_mcap() {
    let out = stereonav(&[
        "view",
        s(&fixture("paper-experiment.rig.toml")),
        "--screenshot",
        s(&scratch("x.png")),
    ]);
    assert_one_line_error(&out, "not an MCAP file");
}

#[test]
fn a_foreign_mcap_file_is_neither_kind() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data/foreign-mcap/nav2_turtlebot.mcap");
    if !path.exists() {
        eprintln!("skipped: {} is absent", path.display());
        return;
    }
    let out = stereonav(&["view", s(&path), "--screenshot", s(&scratch("x.png"))]);
    assert_one_line_error(&out, "neither a vehicle log");
}

#[test]
fn a_bad_rig_is_one_line_naming_it() {
    let text = std::fs::read_to_string(fixture("paper-experiment.rig.toml")).unwrap();
    let rig = scratch("bad.rig.toml");
    std::fs::write(&rig, text.replacen("f = 700.0", "f = \"seven hundred\"", 1)).unwrap();
    let out = stereonav(&[
        "view",
        s(&fixture("paper-experiment.mcap")),
        "--rig",
        s(&rig),
        "--screenshot",
        s(&scratch("x.png")),
    ]);
    assert_one_line_error(&out, "bad.rig.toml");
    let out = stereonav(&[
        "view",
        s(&fixture("paper-experiment.mcap")),
        "--rig",
        s(&scratch("no-such.rig.toml")),
    ]);
    assert_one_line_error(&out, "no-such.rig.toml");
}

#[test]
fn bad_times_sizes_and_outputs_are_one_line() {
    let log = fixture("paper-experiment.mcap");
    let png = scratch("x.png");
    let base = ["view", s(&log), "--skip-phase1", "--screenshot", s(&png)];
    let cases: [(&[&str], &str); 5] = [
        (&["--time", "1000"], "outside the log"),
        (&["--time=-1"], "--time"),
        (&["--size", "640x480"], "640x480"),
        (&["--size", "big"], "WIDTHxHEIGHT"),
        (&["--stride", "0"], "stride"),
    ];
    for (extra, needle) in cases {
        let args: Vec<&str> = base.iter().chain(extra).copied().collect();
        assert_one_line_error(&stereonav(&args), needle);
    }
    let out = stereonav(&[
        "view",
        s(&log),
        "--skip-phase1",
        "--screenshot",
        s(&scratch("no-such-dir/x.png")),
    ]);
    assert_one_line_error(&out, "x.png");
}

/// Without `--screenshot` the viewer opens a window; with no display that is one line saying
/// so and what to do instead.
#[test]
fn the_window_without_a_display_is_one_line() {
    let out = Command::new(env!("CARGO_BIN_EXE_stereonav"))
        .args([
            "view",
            s(&fixture("paper-experiment.mcap")),
            "--skip-phase1",
        ])
        .env_remove("DISPLAY")
        .env_remove("WAYLAND_DISPLAY")
        .output()
        .unwrap();
    assert_one_line_error(&out, "no display");
    assert!(String::from_utf8_lossy(&out.stderr).contains("--screenshot"));
}
