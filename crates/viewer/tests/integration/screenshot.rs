//! Headless screenshots of the bundled paper experiment (replayed on the fly with phase 1
//! skipped, or localised on a map made from it): the PNG is written at the fixed size, and the
//! map, the images and the plots were drawn (several distinct colours where each should be,
//! not a blank or single-colour image).
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
    crate::scratch("screenshot", name)
}

fn paper_experiment() -> viewer::Model {
    let options = LoadOptions {
        rig: Some(rig_model::Rig::load(&fixture("paper-experiment.rig.toml")).unwrap()),
        settings: NavSettings {
            skip_phase1: true,
            ..NavSettings::default()
        },
        map: None,
        topics: None,
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

/// A saved map of paper-experiment made in a temporary directory as `stereonav replay
/// --save-map` makes it (the replay, then `replay::saved_map`), with its last lamp along the
/// aisle taken out (the run should find it as a new lamp) and a lamp that is not there put in
/// between two others (the run should report it missing). Returns the map's path, the id of
/// the lamp put in and the position of the one taken out.
fn paper_experiment_map() -> (PathBuf, u64, [f64; 3]) {
    let log = fixture("paper-experiment.mcap");
    let rig = rig_model::Rig::load(&fixture("paper-experiment.rig.toml")).unwrap();
    let replayer =
        replay::Replayer::open(&log, Some(rig.clone()), &NavSettings::default()).unwrap();
    let end = replayer
        .run(&mut replay::ReplayCollector::default(), &mut |_, _| {})
        .unwrap();
    let mut map = replay::saved_map(&end, &rig, &log);
    assert_eq!(map.landmarks.len(), 5, "the experiment's five lamps");
    let last = map
        .landmarks
        .iter()
        .copied()
        .max_by(|a, b| a.position[0].total_cmp(&b.position[0]))
        .unwrap();
    let phantom = map.landmarks.iter().map(|l| l.id).max().unwrap() + 1;
    map.landmarks.retain(|l| l.id != last.id);
    let template = map.landmarks[0];
    map.landmarks.push(map_file::MapLandmark {
        id: phantom,
        position: [1.6, 0.35, 3.3],
        ..template
    });
    let path = scratch("paper-experiment.map");
    map.save(&path).unwrap();
    (path, phantom, last.position)
}

#[test]
fn a_localisation_run_holds_every_frame_and_draws_its_status_and_lamps() {
    let (map, phantom, removed) = paper_experiment_map();
    let options = LoadOptions {
        map: Some(map.clone()),
        ..LoadOptions::default()
    };
    let model = load(fixture("paper-experiment.mcap"), &options, &mut |_, _| {}).unwrap();
    let loc = model.localization.as_ref().expect("a localisation run");
    assert_eq!(loc.map_path, map);

    // Every frame, at the replay's indices, with its pose and flag.
    assert_eq!(loc.frames.len(), 961);
    assert_eq!(model.replay.frames.len(), loc.frames.len());
    for (f, e) in loc.frames.iter().zip(&model.replay.frames) {
        assert_eq!(f.t_us, e.t_us);
        assert_eq!(f.pose.is_some(), e.pose.iter().all(|v| v.is_finite()));
    }
    // Lost from the start until the constellation in view is unique, then localised.
    let localized = loc.frames.iter().filter(|f| f.localized).count();
    assert_eq!(localized as u64, loc.localized_frames);
    assert!(localized > 800, "{localized} frames localised");
    assert!(!loc.frames[0].localized && loc.frames.last().unwrap().localized);
    let first_fix = loc.frames.iter().find(|f| f.localized).unwrap().t_us;
    assert_eq!(loc.fixes_t_us.first(), Some(&first_fix));
    assert!(loc.frames.iter().any(|f| !f.localized && f.hypotheses > 0));
    let runs: Vec<bool> = loc.status.iter().map(|r| r.localized).collect();
    assert_eq!(runs, [false, true]);
    assert_eq!(
        loc.status.iter().map(|r| r.frames.len()).sum::<usize>(),
        961
    );
    // The trajectory: a lost stretch (the best guess), then a localised one starting where it
    // ends; every point a frame with a pose.
    // The trajectory: lost stretches (the best guess; a frame without a pose breaks the
    // line), then a localised one starting where the last lost one ends; every point a frame
    // with a pose.
    let (last, lost) = loc.track.split_last().unwrap();
    assert!(last.localized && !lost.is_empty() && lost.iter().all(|r| !r.localized));
    assert_eq!(
        lost.last().unwrap().points.last(),
        last.points.first(),
        "unbroken at the fix"
    );
    for w in loc.track.windows(2) {
        let (a, b) = (w[0].points.last().unwrap(), w[1].points.first().unwrap());
        if a != b {
            assert!(
                (a.0 + 1..b.0).any(|i| loc.frames[i].pose.is_none()),
                "a break between frames {} and {} without a frame lacking a pose",
                a.0,
                b.0
            );
        }
    }
    for run in &loc.track {
        for (i, _) in &run.points {
            assert!(loc.frames[*i].pose.is_some());
        }
        for (i, _) in &run.points[1..] {
            assert_eq!(loc.frames[*i].localized, run.localized);
        }
    }
    // Against the simulator's truth: millimetres.
    let truth = loc.truth.unwrap();
    assert_eq!(truth.wrong_frames, 0);
    assert!(truth.ate_rms_m < 0.01, "{}", truth.ate_rms_m);
    // The lamp put in is missing; the one taken out is found.
    assert_eq!(loc.missing, [phantom]);
    assert_eq!(loc.seen.len(), 5);
    assert_eq!(loc.new_lamps.len(), 1);
    let found = loc.new_lamps[0].position;
    let off = (found[0] - removed[0]).hypot(found[1] - removed[1]);
    assert!(
        off < 0.05,
        "new lamp {found:?}, the one taken out {removed:?}"
    );

    // At the end (localised) and while still lost: every part is drawn; the map (outside its
    // colour key) shows the missing lamp's ring and the new lamp's cross, the robot and the
    // trajectory in the colour of the status; the timeline's strip both stretches.
    let (localized_colour, lost_colour) = ([80, 200, 255], [255, 80, 170]);
    let lost_s = model.seconds(first_fix) / 2.0;
    for (time, status) in [(None, localized_colour), (Some(lost_s), lost_colour)] {
        let shot = screenshot(model.clone(), time, MIN_SCREENSHOT_SIZE).unwrap();
        assert_drawn(&shot);
        let r = shot.regions;
        assert!(r.map.contains_rect(r.map_legend), "{r:?}");
        let near = |rect: egui::Rect, colour: [u8; 3]| {
            let (x0, y0) = (rect.left().max(0.0) as u32, rect.top().max(0.0) as u32);
            let x1 = (rect.right() as u32).min(shot.frame.width);
            let y1 = (rect.bottom() as u32).min(shot.frame.height);
            (y0..y1)
                .flat_map(|y| (x0..x1).map(move |x| (x, y)))
                .filter(|(x, y)| !r.map_legend.contains(egui::pos2(*x as f32, *y as f32)))
                .filter(|(x, y)| {
                    let p = pixel(&shot.frame, *x, *y);
                    (0..3).all(|k| p[k].abs_diff(colour[k]) <= 12)
                })
                .count()
        };
        assert!(
            near(r.map, [255, 50, 50]) >= 10,
            "missing lamp's ring, t = {time:?}"
        );
        assert!(
            near(r.map, [110, 235, 80]) >= 10,
            "new lamp's cross, t = {time:?}"
        );
        assert!(
            near(r.map, status) >= 30,
            "trajectory and robot, t = {time:?}"
        );
        assert!(
            near(r.timeline, lost_colour) >= 20,
            "lost stretch, t = {time:?}"
        );
        assert!(
            near(r.timeline, localized_colour) >= 20,
            "localised stretch, t = {time:?}"
        );
    }

    // Scrubbing the run, across the fix: every frame draws.
    let end = model.duration_s();
    let fix_s = model.seconds(first_fix);
    let mut headless = viewer::Headless::new(viewer::Viewer::new(model), MIN_SCREENSHOT_SIZE);
    let mut times: Vec<f64> = (0..=20).map(|k| end * f64::from(k) / 20.0).collect();
    times.extend([fix_s - 0.05, fix_s, fix_s + 0.05]);
    for t in times {
        headless.viewer_mut().set_time(t);
        assert!(headless.run_frame() > 1000, "t = {t}");
    }
}

#[test]
fn a_bad_map_is_an_error_before_the_log_is_read() {
    let bad = scratch("not-a.map");
    std::fs::write(&bad, "hello\n").unwrap();
    let options = LoadOptions {
        map: Some(bad),
        ..LoadOptions::default()
    };
    // The map is read first: its error, not the missing log's.
    let e = load(scratch("no-such-log.mcap"), &options, &mut |_, _| {}).unwrap_err();
    assert!(e.to_string().contains("not a stereonav map"), "{e}");
}
