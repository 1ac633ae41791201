//! Real lenses (vehicle-interfaces.md 1.1): the board's features through a real lens are raw;
//! with `[lens.*]` in the rig the navigator maps them into the rectified model and maps as it
//! does on rectified features. The paper experiment's rectified features are distorted here
//! through a strong radtan lens (EuRoC's coefficients) and a fisheye, each with a small
//! rectification rotation, and replayed with the lens rig.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::Path;

use nalgebra::{Matrix3, Rotation3, Vector2};
use replay::{LogInput, NavSettings, Navigator, read_vehicle_log};
use rig_model::lens::{Lens, LensModel, StereoLens};
use track::Pixel;

fn experiment() -> LogInput {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/logs");
    read_vehicle_log(&dir.join("paper-experiment.mcap"), None).unwrap()
}

fn lens(model: LensModel, f: f64, rot: Matrix3<f64>) -> Lens {
    Lens {
        model,
        fx: f,
        fy: f * 1.002,
        cx: 371.5,
        cy: 243.0,
        rectification: rot,
    }
}

fn drive(nav: &mut Navigator, input: &LogInput, raw: Option<&StereoLens>) {
    let c = input.rig.nominal;
    let distort = |l: &Lens, side: &[Pixel]| -> Vec<Pixel> {
        side.iter()
            .map(|p| {
                let q = l
                    .unrectify(Vector2::new(p.u, p.v), c.f, c.cx, c.cy)
                    .unwrap();
                Pixel { u: q.x, v: q.y }
            })
            .collect()
    };
    let mut next = 0;
    for f in &input.frames {
        while let Some(s) = input.odometry.get(next).filter(|s| s.t_us <= f.t_us) {
            nav.push_odometry(*s).unwrap();
            next += 1;
        }
        let (left, right) = match raw {
            Some(l) => (distort(&l.left, &f.left), distort(&l.right, &f.right)),
            None => (f.left.clone(), f.right.clone()),
        };
        nav.push_frame(f.t_us, &left, &right).unwrap();
    }
    nav.finish().unwrap();
}

#[test]
fn raw_features_through_a_lens_map_as_the_rectified_ones() {
    let input = experiment();
    let mut plain = Navigator::new(input.rig.clone(), NavSettings::default()).unwrap();
    drive(&mut plain, &input, None);
    let rot = |a: f64| Rotation3::from_euler_angles(0.4 * a, -a, 0.3 * a).into_inner();
    let radtan = LensModel::PlumbBob {
        k1: -0.283_408_11,
        k2: 0.073_959_07,
        p1: 0.000_193_59,
        p2: 1.761_871_14e-5,
        k3: 0.0,
    };
    let fisheye = LensModel::Equidistant {
        k1: -0.0137,
        k2: 0.0182,
        k3: -0.0114,
        k4: 0.0025,
    };
    for (name, stereo) in [
        (
            "radtan",
            StereoLens {
                left: lens(radtan, 730.0, rot(0.004)),
                right: lens(radtan, 726.0, rot(-0.003)),
            },
        ),
        (
            "fisheye",
            StereoLens {
                left: lens(fisheye, 690.0, rot(0.002)),
                right: lens(fisheye, 692.0, rot(-0.005)),
            },
        ),
    ] {
        let mut rig = input.rig.clone();
        rig.lens = Some(stereo);
        let mut nav = Navigator::new(rig, NavSettings::default()).unwrap();
        drive(&mut nav, &input, Some(&stereo));
        assert_eq!(nav.stats().features_unmapped, 0, "{name}");
        let (a, b) = (plain.ekf().unwrap(), nav.ekf().unwrap());
        assert_eq!(a.landmark_count(), b.landmark_count(), "{name}");
        for (la, lb) in a.landmarks().zip(b.landmarks()) {
            let d = (la.position - lb.position).norm();
            assert!(d < 1e-3, "{name}: landmark {:?} moved {d} m", la.id);
        }
        let (ca, cb) = (a.camera(), b.camera());
        assert!((ca.baseline - cb.baseline).abs() < 1e-5, "{name}");
    }
}

#[test]
fn features_a_lens_cannot_map_are_dropped_and_counted() {
    let input = experiment();
    let mut rig = input.rig.clone();
    let fisheye = LensModel::Equidistant {
        k1: -0.0137,
        k2: 0.0182,
        k3: -0.0114,
        k4: 0.0025,
    };
    // A lens so wide (f = 120 px) that the image's corners are beyond 90 degrees.
    let wide = lens(fisheye, 120.0, Matrix3::identity());
    rig.lens = Some(StereoLens {
        left: wide,
        right: wide,
    });
    let mut nav = Navigator::new(rig, NavSettings::default()).unwrap();
    let corner = [Pixel { u: 1.0, v: 1.0 }, Pixel { u: 371.5, v: 243.0 }];
    nav.push_frame(1, &corner, &corner).unwrap();
    assert_eq!(nav.stats().features_unmapped, 2);
}

/// A log through EuRoC's real radtan lenses (the simulator carries each lamp's projection to
/// the raw image; the rig's [lens.*] map the board's raw features back), no flags: every lamp
/// mapped, within the 5 mm (landmarks) and 0.5 mm (baseline).
#[test]
fn a_log_through_real_radtan_lenses_maps() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/scenarios/paper-experiment-radtan.toml");
    let sc = sim::Scenario::load(&path).unwrap();
    assert!(sc.rig.lens.is_some());
    let log = crate::scratch_log("lens-radtan");
    for seed in 0..2 {
        let run = sim::simulate(&sc.clone().with_seed(seed), sim::Mode::Fast).unwrap();
        run.write_log(&log).unwrap();
        let r = replay::replay_log(&log, None, &NavSettings::default(), &mut |_, _| {}).unwrap();
        let t = r.truth.as_ref().unwrap();
        let b = t
            .camera
            .iter()
            .find(|(p, _)| *p == rig_model::Param::Baseline)
            .unwrap()
            .1;
        let d = format!("seed {seed}: {t:?}");
        assert_eq!((t.lamps_missed, t.landmarks_unmatched), (0, 0), "{d}");
        assert_eq!(t.landmarks_matched, 5, "{d}");
        assert!(t.landmark_rms <= 0.005, "{d}");
        assert!(b.abs() <= 0.0005, "{d}");
    }
    std::fs::remove_file(&log).ok();
}
