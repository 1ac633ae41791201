//! Headless screenshots of the bundled paper experiment (replayed on the fly with phase 1
//! skipped): the PNG is written at the fixed size, and the map, the images and the plots were
//! drawn (several distinct colours where each should be, not a blank or single-colour image).
//!
//! These need no system package at all: the viewer rasterises egui's output on the CPU, so they
//! run everywhere `cargo test` runs, CI included, and never skip.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failure is the test failing

use std::collections::HashSet;
use std::path::{Path, PathBuf};

use replay::NavSettings;
use viewer::{Frame, LoadOptions, MIN_SCREENSHOT_SIZE, Screenshot, load, screenshot, write_png};

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/logs")
        .join(name)
}

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("viewer-screenshot-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

fn paper_experiment() -> viewer::Model {
    let options = LoadOptions {
        rig: Some(rig_model::Rig::load(&fixture("paper-experiment.rig.toml")).unwrap()),
        settings: NavSettings {
            skip_phase1: true,
            ..NavSettings::default()
        },
    };
    load(fixture("paper-experiment.mcap"), &options, &mut |_, _| {}).unwrap()
}

fn pixel(frame: &Frame, x: u32, y: u32) -> [u8; 4] {
    let i = ((y * frame.width + x) * 4) as usize;
    frame.rgba[i..i + 4].try_into().unwrap()
}

/// The distinct colours inside a rectangle, and how many of its pixels differ from the colour
/// most common in it (the background).
fn colours_in(frame: &Frame, rect: egui::Rect) -> (usize, usize) {
    let mut counts: std::collections::HashMap<[u8; 4], usize> = Default::default();
    let (x0, y0) = (rect.left().max(0.0) as u32, rect.top().max(0.0) as u32);
    let x1 = (rect.right() as u32).min(frame.width);
    let y1 = (rect.bottom() as u32).min(frame.height);
    for y in y0..y1 {
        for x in x0..x1 {
            *counts.entry(pixel(frame, x, y)).or_default() += 1;
        }
    }
    let total: usize = counts.values().sum();
    let background = counts.values().copied().max().unwrap_or(0);
    (counts.len(), total - background)
}

/// Colours that are clearly chromatic (not grey): the data layers, not the frame of the UI.
fn chromatic_in(frame: &Frame, rect: egui::Rect) -> HashSet<[u8; 3]> {
    let mut set = HashSet::new();
    let (x0, y0) = (rect.left().max(0.0) as u32, rect.top().max(0.0) as u32);
    let x1 = (rect.right() as u32).min(frame.width);
    let y1 = (rect.bottom() as u32).min(frame.height);
    for y in y0..y1 {
        for x in x0..x1 {
            let [r, g, b, _] = pixel(frame, x, y);
            let (max, min) = (r.max(g).max(b), r.min(g).min(b));
            if max - min >= 60 {
                // Quantised so that anti-aliased shades of one colour count once.
                set.insert([r / 32, g / 32, b / 32]);
            }
        }
    }
    set
}

fn assert_drawn(shot: &Screenshot) {
    let f = &shot.frame;
    assert_eq!(f.rgba.len(), (f.width * f.height * 4) as usize);
    let everything = egui::Rect::from_min_size(
        egui::Pos2::ZERO,
        egui::vec2(f.width as f32, f.height as f32),
    );
    let (colours, _) = colours_in(f, everything);
    assert!(colours > 100, "{colours} colours in the whole image");
    let r = shot.regions;
    for (name, rect, min_changed) in [
        ("map", r.map, 2000),
        ("plots", r.plots, 2000),
        ("left image", r.left_image, 30),
        ("right image", r.right_image, 30),
    ] {
        assert!(
            rect.width() > 100.0 && rect.height() > 60.0,
            "{name}: {rect:?}"
        );
        assert!(everything.contains_rect(rect), "{name}: {rect:?}");
        let (colours, changed) = colours_in(f, rect);
        assert!(colours >= 8, "{name}: {colours} colours");
        assert!(
            changed >= min_changed,
            "{name}: {changed} pixels off the background"
        );
    }
    // The data layers: trajectory (blue), landmarks (orange), ellipses, fields of view in the
    // map; estimate (blue), band, phase or NIS markers (red, orange) in the plots.
    let map = chromatic_in(f, r.map);
    assert!(map.len() >= 4, "map: {} chromatic colours", map.len());
    let plots = chromatic_in(f, r.plots);
    assert!(plots.len() >= 4, "plots: {} chromatic colours", plots.len());
    let images = chromatic_in(f, r.left_image);
    assert!(!images.is_empty(), "left image: no coloured feature marks");
}

#[test]
fn paper_experiment_at_the_end_draws_the_map_images_and_plots() {
    let shot = screenshot(paper_experiment(), None, MIN_SCREENSHOT_SIZE).unwrap();
    assert_eq!([shot.frame.width, shot.frame.height], MIN_SCREENSHOT_SIZE);
    assert_drawn(&shot);
    let png = scratch("paper-experiment.png");
    write_png(&png, &shot.frame).unwrap();
    let back = image::open(&png).unwrap().to_rgba8();
    assert_eq!(back.dimensions(), (1280, 800));
    assert_eq!(back.as_raw(), &shot.frame.rgba);
}

#[test]
fn a_time_in_the_middle_and_a_larger_size() {
    let shot = screenshot(paper_experiment(), Some(20.0), [1600, 1000]).unwrap();
    assert_eq!([shot.frame.width, shot.frame.height], [1600, 1000]);
    assert_drawn(&shot);
}

#[test]
fn sizes_and_times_outside_the_limits_are_errors() {
    let e = screenshot(paper_experiment(), None, [640, 480]).unwrap_err();
    assert!(e.to_string().contains("640x480"), "{e}");
    let e = screenshot(paper_experiment(), Some(1e6), MIN_SCREENSHOT_SIZE).unwrap_err();
    assert!(e.to_string().contains("outside the log"), "{e}");
    let e = screenshot(paper_experiment(), Some(f64::NAN), MIN_SCREENSHOT_SIZE).unwrap_err();
    assert!(e.to_string().contains("outside the log"), "{e}");
}

/// Scrubbing the whole method (phase 1, the switch, phase 2) at many times, the switch itself
/// and the ends included: every frame draws, and the estimated parameters are plotted.
#[test]
fn scrubbing_paper_calibration_draws_every_frame() {
    let model = load(
        fixture("paper-calibration.mcap"),
        &LoadOptions::default(),
        &mut |_, _| {},
    )
    .unwrap();
    let switch = model.seconds(model.replay.phase_switch_t_us.unwrap());
    let end = model.duration_s();
    let names: Vec<&str> = model.params.iter().map(|p| p.param.name()).collect();
    assert_eq!(names, ["f", "baseline"]);
    let mut headless = viewer::Headless::new(viewer::Viewer::new(model), MIN_SCREENSHOT_SIZE);
    let mut times: Vec<f64> = (0..=40).map(|k| end * f64::from(k) / 40.0).collect();
    times.extend([switch - 0.05, switch, switch + 0.05]);
    for t in times {
        headless.viewer_mut().set_time(t);
        assert!(headless.run_frame() > 1000, "t = {t}");
    }
    let shot = headless.render();
    assert_eq!([shot.width, shot.height], MIN_SCREENSHOT_SIZE);
}
