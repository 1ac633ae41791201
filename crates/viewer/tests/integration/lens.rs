//! A log through EuRoC's real radtan lenses (`fixtures/scenarios/paper-experiment-radtan.toml`:
//! the board's features are raw pixels, the rig's `[lens.*]` tables map them into the
//! rectified model) in the viewer: the landmarks' rings are taken back through the lenses, so
//! each lies on the raw features the navigator associated with its landmark, and the features
//! "on landmarks" are the navigator's own associations. The screenshot shows each accepted
//! feature as a green dot inside its green ring.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failure is the test failing

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use viewer::model::{FeatureMark, FrameMarks, Projection};
use viewer::{Frame, LoadOptions, MIN_SCREENSHOT_SIZE, Model, image_to_screen, load, screenshot};

/// The scenario simulated once per test process (seed 0), written as a vehicle log.
fn radtan_log() -> &'static Path {
    static LOG: OnceLock<PathBuf> = OnceLock::new();
    LOG.get_or_init(|| {
        let scenario = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../fixtures/scenarios/paper-experiment-radtan.toml");
        let sc = sim::Scenario::load(&scenario).unwrap();
        assert!(sc.rig.lens.is_some(), "the scenario has lens tables");
        let log = crate::scratch("lens", "paper-experiment-radtan.mcap");
        sim::simulate(&sc, sim::Mode::Fast)
            .unwrap()
            .write_log(&log)
            .unwrap();
        log
    })
}

/// The log replayed as `stereonav view LOG` does it: the log's own rig (with its lenses),
/// phase 1, the switch, phase 2.
fn radtan() -> Model {
    load(radtan_log(), &LoadOptions::default(), &mut |_, _| {}).unwrap()
}

/// Each feature the navigator's update accepted, with its landmark's ring in the same image.
fn accepted_on_rings<'a>(
    features: &'a [FeatureMark],
    rings: &'a [Projection],
) -> impl Iterator<Item = (&'a FeatureMark, Option<&'a Projection>)> {
    features.iter().filter(|f| f.observed).map(|f| {
        let ring = rings.iter().find(|p| Some(p.id) == f.landmark);
        (f, ring)
    })
}

fn distance(f: &FeatureMark, p: &Projection) -> f64 {
    (f64::from(f.u) - p.u).hypot(f64::from(f.v) - p.v)
}

/// Over every frame: the count on landmarks is the navigator's (the landmarks its update
/// accepted, as many features in each image; as many marked rejected as the gate rejected);
/// each ring is the rectified model's projection taken exactly through the lens; the accepted
/// features lie on their rings (within a pixel but for a few, early in phase 2, where the
/// estimate's own residual is larger); and the rings left in the rectified model (the lens
/// ignored) would miss them by many pixels.
#[test]
fn rings_through_the_lens_lie_on_the_navigators_features() {
    let model = radtan();
    let lens = model.lens.expect("the log's /rig carries the lens tables");
    let c = model.nominal.unwrap();
    let mut rectified = model.clone();
    rectified.lens = None;
    let (mut accepted, mut round_trips) = (0usize, 0usize);
    let mut distances: Vec<f64> = Vec::new();
    let mut rectified_distances: Vec<f64> = Vec::new();
    for (i, frame) in model.replay.frames.iter().enumerate() {
        let marks: FrameMarks = model.marks(i);
        let on = marks
            .on_landmarks
            .expect("a replayed log records its associations");
        assert_eq!(on, frame.observed.len(), "frame {i}");
        for side in [&marks.left, &marks.right] {
            assert_eq!(side.iter().filter(|f| f.observed).count(), on, "frame {i}");
        }
        let rejected = marks.left.iter().filter(|f| f.landmark.is_some()).count() - on;
        assert_eq!(rejected, frame.rejected as usize, "frame {i}");
        accepted += on;
        let plain = rectified.marks(i);
        assert_eq!(
            plain.left, marks.left,
            "the features do not depend on the rings"
        );
        for (side, features, projected, plain_projected) in [
            (
                &lens.left,
                &marks.left,
                &marks.projected_left,
                &plain.projected_left,
            ),
            (
                &lens.right,
                &marks.right,
                &marks.projected_right,
                &plain.projected_right,
            ),
        ] {
            for ring in projected {
                let back = side
                    .rectify_point(nalgebra::Vector2::new(ring.u, ring.v), c.f, c.cx, c.cy)
                    .unwrap();
                // (A ring inside the raw image may be outside the rectified one.)
                let Some(plain) = plain_projected.iter().find(|p| p.id == ring.id) else {
                    continue;
                };
                round_trips += 1;
                let d = (back.x - plain.u).hypot(back.y - plain.v);
                assert!(
                    d < 1e-6,
                    "frame {i}: {ring:?} is {plain:?} through the lens: {d}"
                );
            }
            for (f, ring) in accepted_on_rings(features, projected) {
                let Some(ring) = ring else { continue };
                assert!(ring.observed, "frame {i}: {ring:?}");
                let d = distance(f, ring);
                assert!(d <= 3.0, "frame {i}: {f:?} is {d:.2} px from {ring:?}");
                distances.push(d);
            }
            for (f, ring) in accepted_on_rings(features, plain_projected) {
                if let Some(ring) = ring {
                    rectified_distances.push(distance(f, ring));
                }
            }
        }
    }
    assert!(accepted > 1000, "{accepted} accepted observations");
    assert!(round_trips > 2000, "{round_trips} rings mapped back");
    assert!(distances.len() > 2000, "{} rings checked", distances.len());
    let quantile = |v: &mut Vec<f64>, q: f64| {
        v.sort_by(f64::total_cmp);
        v[((v.len() - 1) as f64 * q) as usize]
    };
    let (median, p90) = (quantile(&mut distances, 0.5), quantile(&mut distances, 0.9));
    let worst = quantile(&mut distances, 1.0);
    let without = quantile(&mut rectified_distances, 0.5);
    eprintln!(
        "{accepted} accepted observations, {} rings: {median:.2} px from their features \
         (median), {p90:.2} (90 %), {worst:.2} at most; without the lens {without:.1} (median)",
        distances.len()
    );
    assert!(median <= 0.5 && p90 <= 1.0, "{median} {p90}");
    assert!(
        without > 10.0,
        "the lens moves the rings by {without:.2} px (median)"
    );
}

fn pixel(frame: &Frame, x: i64, y: i64) -> [u8; 4] {
    let inside =
        (0..i64::from(frame.width)).contains(&x) && (0..i64::from(frame.height)).contains(&y);
    if !inside {
        return [0; 4];
    }
    let i = ((y * i64::from(frame.width) + x) * 4) as usize;
    frame.rgba[i..i + 4].try_into().unwrap()
}

/// The viewer's green (an accepted observation), anti-aliased shades included.
fn green(p: [u8; 4]) -> bool {
    let [r, g, b, _] = p;
    i32::from(g) > i32::from(r) + 50 && i32::from(g) > i32::from(b) + 50
}

/// The screenshot at the frame with the most accepted observations: each accepted feature is
/// drawn as a green dot, and a green ring (6 px) surrounds it: sampled on 48 rays around the
/// feature's own position, nearly every ray meets green between 5 and 7 px.
#[test]
fn a_screenshot_draws_each_accepted_feature_inside_its_ring() {
    let model = radtan();
    let (index, marks) = (0..model.replay.frames.len())
        .map(|i| (i, model.marks(i)))
        .max_by_key(|(_, m)| m.on_landmarks.unwrap_or(0))
        .unwrap();
    assert!(marks.on_landmarks.unwrap() >= 3, "{marks:?}");
    let t_s = model.seconds(model.replay.frames[index].t_us);
    let [w, h] = model.image_size;
    let shot = screenshot(model, Some(t_s), MIN_SCREENSHOT_SIZE).unwrap();
    let f = &shot.frame;
    let mut checked = 0;
    for (rect, features) in [
        (shot.regions.left_image, &marks.left),
        (shot.regions.right_image, &marks.right),
    ] {
        for feature in features.iter().filter(|m| m.observed) {
            let at_screen =
                image_to_screen(rect, [w, h], f64::from(feature.u), f64::from(feature.v));
            let (x, y) = (f64::from(at_screen.x), f64::from(at_screen.y));
            let at = |dx: f64, dy: f64| pixel(f, (x + dx).floor() as i64, (y + dy).floor() as i64);
            assert!(
                green(at(0.0, 0.0)),
                "{feature:?}: the dot at ({x:.1}, {y:.1})"
            );
            let rays = 48;
            let hits = (0..rays)
                .filter(|k| {
                    let a = f64::from(*k) * std::f64::consts::TAU / f64::from(rays);
                    (0..=8).any(|s| {
                        let r = 5.0 + 0.25 * f64::from(s);
                        green(at(r * a.cos(), r * a.sin()))
                    })
                })
                .count();
            assert!(
                hits >= 44,
                "{feature:?}: the ring met on {hits} of {rays} rays"
            );
            checked += 1;
        }
    }
    assert!(checked >= 6, "{checked} features checked");
}
