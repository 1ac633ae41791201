//! Fast-mode features against the rig model, and the board's order, cap and flags.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failure is the test failing

use crate::common;

use rig_model::Pose2;
use sim::Mode;

#[test]
fn fast_features_are_the_projections_within_quantisation() {
    for name in [
        "paper-calibration",
        "paper-square",
        "paper-experiment",
        "warehouse",
    ] {
        let s = common::noise_off(common::load(name));
        let s = if name == "warehouse" {
            common::shorten(s, 3)
        } else {
            s
        };
        let c = s.true_camera();
        let run = sim::simulate(&s, Mode::Fast).unwrap();
        let mut checked = 0;
        for f in &run.frames {
            for (side, feats) in [(0, &f.left), (1, &f.right)] {
                assert!(!feats.overflow);
                // Every lamp in the candidate area is there, and nothing else (no clutter).
                let seen = f
                    .views
                    .iter()
                    .filter(|v| if side == 0 { v.in_left } else { v.in_right })
                    .count();
                assert_eq!(feats.features.len(), seen, "{name} frame {}", f.index);
                for feat in &feats.features {
                    let id = feat.lamp.expect("no clutter with clutter off");
                    let lamp = run.landmarks[id as usize].position;
                    let m = rig_model::project(&c, &f.pose, &lamp).unwrap();
                    let (u, v) = (m[2 * side], m[2 * side + 1]);
                    let (du, dv) = (
                        f64::from(feat.x_q4) / 16.0 - u,
                        f64::from(feat.y_q4) / 16.0 - v,
                    );
                    assert!(
                        du.abs() <= 1.0 / 32.0 + 1e-12 && dv.abs() <= 1.0 / 32.0 + 1e-12,
                        "{name} frame {} lamp {id}: ({du}, {dv})",
                        f.index
                    );
                    checked += 1;
                }
            }
        }
        assert!(checked > 1000, "{name}: {checked}");
    }
}

#[test]
fn features_leave_in_the_boards_order_with_the_cap_and_flags() {
    let mut s = common::shorten(common::load("warehouse"), 2);
    s.spec.clutter.per_image = 40.0;
    s.spec.board.max_features = 12;
    let run = sim::simulate(&s, Mode::Fast).unwrap();
    let mut overflowed = 0;
    for f in &run.frames {
        for side in [&f.left, &f.right] {
            let keys: Vec<_> = side
                .features
                .iter()
                .map(sim::SimFeature::raster_key)
                .collect();
            assert!(
                keys.windows(2).all(|w| w[0] < w[1]),
                "raster order, one per pixel"
            );
            assert!(side.features.len() <= 12);
            assert!(side.features.iter().all(|x| x.r > s.spec.board.threshold));
            overflowed += usize::from(side.overflow);
            if side.overflow {
                assert_eq!(side.features.len(), 12);
            }
        }
    }
    assert!(overflowed > run.frames.len(), "{overflowed}");
    // The flags reach the packets.
    let (decoded, _) = common::decode(run.chunks.iter().map(|c| c.bytes.as_slice()));
    for d in decoded.iter().take(50) {
        let f = &run.frames[(d.frame - s.spec.rates.first_frame) as usize];
        assert_eq!(
            d.flags,
            u8::from(f.left.overflow) | (u8::from(f.right.overflow) << 1)
        );
    }
}

#[test]
fn pixel_noise_has_the_configured_spread() {
    let mut s = common::noise_off(common::load("paper-calibration"));
    s.spec.noise.pixel_px = 0.3;
    let c = s.true_camera();
    let run = sim::simulate(&s, Mode::Fast).unwrap();
    let (mut n, mut sum, mut sum2) = (0.0, 0.0, 0.0);
    for f in &run.frames {
        for feat in &f.left.features {
            let lamp = run.landmarks[feat.lamp.unwrap() as usize].position;
            let m = rig_model::project(&c, &f.pose, &lamp).unwrap();
            let d = f64::from(feat.x_q4) / 16.0 - m[0];
            n += 1.0;
            sum += d;
            sum2 += d * d;
        }
    }
    let mean = sum / n;
    let sd = (sum2 / n - mean * mean).sqrt();
    // 0.3 px of noise plus 1/16 px of rounding: sqrt(0.09 + 1/3072).
    assert!(
        mean.abs() < 0.02 && (sd - 0.3005).abs() < 0.01,
        "{mean} {sd}"
    );
}

#[test]
fn lamps_stay_in_view_along_the_paper_paths() {
    // The scenarios are laid out so that the estimator always has landmarks to work with.
    for (name, min) in [
        ("paper-calibration", 1), // the tilted head loses lamps while turning in place
        ("paper-square", 2),
        ("paper-experiment", 3),
        ("warehouse", 3),
    ] {
        let run = sim::simulate(&common::load(name), Mode::Fast).unwrap();
        let counts = run.visible_counts();
        let least = counts.iter().copied().min().unwrap();
        assert!(least >= min, "{name}: {least} lamps in some frame");
        assert_eq!(run.frames[0].pose, Pose2::default());
    }
}
