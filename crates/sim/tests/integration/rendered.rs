//! The rendered mode: the board's detector on clean rendered images finds every lamp in view
//! within 0.1 px of its true projection.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failure is the test failing

use crate::common;

use rand_chacha::ChaCha8Rng;
use sim::scenario::Beams;
use sim::{Mode, Renderer};

/// Lamps this far from every edge count as "not at the border".
const MARGIN_PX: f64 = 8.0;

/// Distances from each lamp in view (not at the border) to the nearest detected feature, over
/// every `step`-th frame of a scenario rendered without noise.
fn lamp_errors(name: &str, step: usize, beams: bool) -> Vec<f64> {
    let mut s = common::noise_off(common::load(name));
    if !beams {
        s.spec.render.beams = Beams::None;
    }
    let regs = s.registers();
    let run = sim::simulate(&s, Mode::Fast).unwrap();
    let renderer = Renderer::new(s.true_camera(), &regs, s.spec.render, run.landmarks.clone());
    let (w, h) = (regs.width as f64, regs.height as f64);
    let inside = |u: f64, v: f64| {
        u >= MARGIN_PX && v >= MARGIN_PX && u <= w - 1.0 - MARGIN_PX && v <= h - 1.0 - MARGIN_PX
    };
    let mut errors = Vec::new();
    for f in run.frames.iter().step_by(step) {
        let images = renderer.render::<ChaCha8Rng>(&f.pose, None);
        for (image, side) in [(&images.left, 0), (&images.right, 1)] {
            let detection = harris_core::detect(image, &regs).unwrap();
            for view in &f.views {
                let (u, v) = if side == 0 {
                    (view.u_left, view.v_left)
                } else {
                    (view.u_right, view.v_right)
                };
                if inside(u, v) {
                    let nearest = detection
                        .features
                        .iter()
                        .map(|x| (x.u() - u).hypot(x.v() - v))
                        .fold(f64::INFINITY, f64::min);
                    errors.push(nearest);
                }
            }
        }
    }
    errors
}

const SCENARIOS: [(&str, usize); 4] = [
    ("paper-calibration", 23),
    ("paper-square", 11),
    ("paper-experiment", 7),
    ("warehouse", 97),
];

#[test]
fn rendered_lamps_are_found_within_a_tenth_of_a_pixel() {
    // Clean images: no sensor noise, a plain roof.
    for (name, step) in SCENARIOS {
        let errors = lamp_errors(name, step, false);
        assert!(errors.len() > 400, "{name}: {}", errors.len());
        let worst = errors.iter().copied().fold(0.0, f64::max);
        assert!(
            worst <= 0.1,
            "{name}: a lamp is {worst} px from its projection"
        );
    }
}

#[test]
fn beam_edges_pull_few_lamps_and_not_far() {
    // With the roof's beams, a lamp right on a beam's edge is pulled by the edge's gradient
    // (up to about 0.3 px in the warehouse); the others stay within 0.1 px.
    for (name, step) in SCENARIOS {
        let errors = lamp_errors(name, step, true);
        let far = errors.iter().filter(|&&e| e > 0.1).count();
        let worst = errors.iter().copied().fold(0.0, f64::max);
        assert!(
            far * 50 <= errors.len(),
            "{name}: {far} of {} beyond 0.1 px",
            errors.len()
        );
        assert!(worst <= 0.5, "{name}: {worst} px");
    }
}

#[test]
fn rendered_run_sends_what_the_detector_finds() {
    let mut s = common::shorten(common::load("paper-experiment"), 2);
    s.spec.path.segments[1] = sim::scenario::Segment::straight(0.3);
    let regs = s.registers();
    let run = sim::simulate(&s, Mode::Rendered).unwrap();
    let renderer = Renderer::new(s.true_camera(), &regs, s.spec.render, run.landmarks.clone());
    // With sensor noise every lamp in view is still found, close to its projection.
    for f in run.frames.iter().step_by(5) {
        let clean = renderer.render::<ChaCha8Rng>(&f.pose, None);
        let det = harris_core::detect(&clean.left, &regs).unwrap();
        assert!(!det.features.is_empty());
        let lamps_sent = f.left.features.iter().filter(|x| x.lamp.is_some()).count();
        assert_eq!(
            lamps_sent,
            f.views.iter().filter(|v| v.in_left).count(),
            "frame {}",
            f.index
        );
        for feat in f.left.features.iter().filter(|x| x.lamp.is_some()) {
            let view = f.views.iter().find(|v| Some(v.id) == feat.lamp).unwrap();
            let d = (f64::from(feat.x_q4) / 16.0 - view.u_left)
                .hypot(f64::from(feat.y_q4) / 16.0 - view.v_left);
            assert!(d < 0.5, "with sensor noise: {d} px");
        }
    }
    // The packets carry exactly the features of each frame.
    let (decoded, stats) = common::decode(run.chunks.iter().map(|c| c.bytes.as_slice()));
    assert_eq!(stats.packets as usize, run.frames.len());
    for (d, f) in decoded.iter().zip(&run.frames) {
        assert_eq!(d.left, f.left.board_features());
        assert_eq!(d.right, f.right.board_features());
    }
}

#[test]
fn clean_images_are_what_the_sensor_would_give() {
    let s = common::noise_off(common::load("warehouse"));
    let regs = s.registers();
    let run = sim::simulate(&common::shorten(s.clone(), 2), Mode::Fast).unwrap();
    let renderer = Renderer::new(s.true_camera(), &regs, s.spec.render, run.landmarks.clone());
    let f = &run.frames[run.frames.len() / 2];
    let img = renderer.render::<ChaCha8Rng>(&f.pose, None);
    assert_eq!((img.width, img.height), (752, 480));
    assert_eq!(img.left.len(), 752 * 480);
    // The roof and beams are dark; lamps are bright spots.
    let roof = s.spec.render.roof_dn as u8;
    let beam = s.spec.render.beam_dn as u8;
    let background = img.left.iter().filter(|&&p| p == roof || p == beam).count();
    assert!(background > 752 * 480 * 8 / 10, "{background}");
    for view in f.views.iter().filter(|v| v.in_left) {
        let (x, y) = (view.u_left.round() as usize, view.v_left.round() as usize);
        assert!(
            img.left[y * 752 + x] > roof + 60,
            "lamp {} is bright",
            view.id
        );
    }
    assert_ne!(
        img.left, img.right,
        "the two cameras see the lamps at different columns"
    );
}

/// Real lamps (issue 16): a panel is drawn as a bright rectangle (its inside at the panel's
/// brightness, its outside at the roof's), and the board's detector finds a feature within
/// 3 px of every panel corner in view; a panel's landmarks are its corners, a tube's its ends.
#[test]
fn panels_are_rectangles_seen_at_their_corners() {
    let mut s = common::noise_off(common::load("real-lamps"));
    s.spec.render.beams = Beams::None;
    let regs = s.registers();
    let run = sim::simulate(&s, Mode::Fast).unwrap();
    // 2 discs, 3 panels x 4 corners, 2 tubes x 2 ends.
    assert_eq!(run.landmarks.len(), 2 + 12 + 4);
    let tubes = run
        .landmarks
        .iter()
        .filter(|l| l.panel.is_some_and(|p| p.is_tube()))
        .count();
    assert_eq!(tubes, 4);
    let renderer = Renderer::new(s.true_camera(), &regs, s.spec.render, run.landmarks.clone());
    let (w, h) = (regs.width as f64, regs.height as f64);
    let mut corners_checked = 0;
    for f in run.frames.iter().step_by(40) {
        let images = renderer.render::<ChaCha8Rng>(&f.pose, None);
        let detection = harris_core::detect(&images.left, &regs).unwrap();
        for view in &f.views {
            let Some(lamp) = run.landmarks.iter().find(|l| l.id == view.id) else {
                continue;
            };
            let Some(panel) = lamp.panel else { continue };
            let (u, v) = (view.u_left, view.v_left);
            if panel.is_tube() || u < 12.0 || v < 12.0 || u > w - 13.0 || v > h - 13.0 {
                continue;
            }
            let nearest = detection
                .features
                .iter()
                .map(|p| (p.u() - u).hypot(p.v() - v))
                .fold(f64::INFINITY, f64::min);
            assert!(
                nearest <= 3.0,
                "corner {} at ({u:.1}, {v:.1}): nearest {nearest:.2} px",
                lamp.id
            );
            corners_checked += 1;
        }
    }
    assert!(corners_checked >= 10, "{corners_checked}");
    // The panel's inside is bright and the roof dark: the centre of the first panel in view.
    let f = &run.frames[0];
    let images = renderer.render::<ChaCha8Rng>(&f.pose, None);
    let corners: Vec<_> = f
        .views
        .iter()
        .filter(|v| {
            run.landmarks
                .iter()
                .any(|l| l.id == v.id && l.panel.is_some_and(|p| p.index == 0))
        })
        .collect();
    assert_eq!(corners.len(), 4, "the first panel is in view at the start");
    let (cu, cv) = (
        corners.iter().map(|v| v.u_left).sum::<f64>() / 4.0,
        corners.iter().map(|v| v.v_left).sum::<f64>() / 4.0,
    );
    let at = |u: f64, v: f64| images.left[(v.round() as usize) * regs.width + u.round() as usize];
    assert!(at(cu, cv) >= 200, "inside {}", at(cu, cv));
    let roof = at(cu, cv - 200.0_f64.min(cv - 1.0));
    assert!(roof <= 80, "outside {roof}");
}
