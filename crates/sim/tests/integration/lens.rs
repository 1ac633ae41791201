//! The rendered mode through real lenses (vehicle-interfaces.md 1.1): each camera's image is
//! its raw sensor's, a lamp's light is centred on the raw pixel of its centre, the board's
//! detector finds it there as well as it finds a lamp in a rectified image, and a rendered
//! run labels its raw features.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failure is the test failing

use crate::common;

use nalgebra::{Vector2, Vector3};
use rand_chacha::ChaCha8Rng;
use rig_model::lens::Lens;
use rig_model::{CameraParams, Pose2};
use sim::scenario::{Beams, Render};
use sim::{Lamp, Mode, Renderer, Side};

const RADTAN: &str = "paper-experiment-radtan";
const FISHEYE: &str = "paper-experiment-fisheye";
/// Lamps this far from every edge of the raw image count.
const MARGIN_PX: f64 = 8.0;
/// Lamps this far above the cameras (rig z).
const DEPTH_M: f64 = 2.5;

fn origin() -> Pose2 {
    Pose2::new(0.0, 0.0, 0.0)
}

/// A lamp and the raw pixel of its centre in each camera (`None`: the lens has none).
struct GridLamp {
    lamp: Lamp,
    left: Option<Vector2<f64>>,
    right: Option<Vector2<f64>>,
    /// Its rectified projection `(uL, vL, uR, vR)`.
    rect: [f64; 4],
}

/// Lamps over the whole raw image of the left camera, one every `spacing` raw pixels from 10
/// px off the edges to 10 px off the others, at sub-pixel positions spread over the pixel,
/// `DEPTH_M` above the rig, each `radius_px` rectified pixels in radius (a lamp of one size
/// at one height). `constant_flux`: each as bright per raw pixel of area as makes its light in
/// the raw image that of a lamp seen through no lens (a fisheye shrinks the lamps far off its
/// axis into dots too faint for the detector).
fn grid(s: &sim::Scenario, spacing: usize, radius_px: f64, constant_flux: bool) -> Vec<GridLamp> {
    let c = s.true_camera();
    let lens = s.rig.lens.unwrap();
    let regs = s.registers();
    let mut out = Vec::new();
    let mut k = 0u32;
    for v in (10..regs.height - 10).step_by(spacing) {
        for u in (10..regs.width - 10).step_by(spacing) {
            let at = Vector2::new(
                u as f64 + (f64::from(k) * 0.618_034).fract(),
                v as f64 + (f64::from(k) * 0.414_214).fract(),
            );
            let Some((rect, rect_from_raw)) = lens.left.rectify(at, c.f, c.cx, c.cy) else {
                continue;
            };
            let p_in_rig = Vector3::new(
                (rect.x - c.cx) / c.f * DEPTH_M - c.baseline / 2.0,
                (rect.y - c.cy) / c.f * DEPTH_M,
                DEPTH_M,
            );
            let position = c.mount.robot_from_rig_rotation() * p_in_rig + c.mount.translation();
            let m = rig_model::project(&c, &origin(), &position).unwrap();
            let radiance_dn = if constant_flux {
                400.0 * rect_from_raw.determinant().abs()
            } else {
                400.0
            };
            out.push(GridLamp {
                lamp: Lamp {
                    id: k,
                    position,
                    radius_m: radius_px * DEPTH_M / c.f,
                    radiance_dn,
                    panel: None,
                    lit: true,
                },
                left: lens
                    .left
                    .unrectify(Vector2::new(m[0], m[1]), c.f, c.cx, c.cy),
                right: lens
                    .right
                    .unrectify(Vector2::new(m[2], m[3]), c.f, c.cx, c.cy),
                rect: [m[0], m[1], m[2], m[3]],
            });
            k += 1;
        }
    }
    out
}

/// Clean images of the lamps alone: a black roof without beams.
fn dark_roof(s: &sim::Scenario) -> Render {
    let mut render = s.spec.render;
    render.beams = Beams::None;
    render.roof_dn = 0.0;
    render
}

fn inside(at: Vector2<f64>, s: &sim::Scenario) -> bool {
    let regs = s.registers();
    let (w, h) = (regs.width as f64, regs.height as f64);
    at.x >= MARGIN_PX
        && at.y >= MARGIN_PX
        && at.x <= w - 1.0 - MARGIN_PX
        && at.y <= h - 1.0 - MARGIN_PX
}

/// The centroid and the sum of the light within `reach` px of `at`.
fn light_at(light: &[f32], width: usize, at: Vector2<f64>, reach: i64) -> (Vector2<f64>, f64) {
    let height = light.len() / width;
    let (cu, cv) = (at.x.round() as i64, at.y.round() as i64);
    let (mut sum, mut su, mut sv) = (0.0, 0.0, 0.0);
    for y in (cv - reach).max(0)..=(cv + reach).min(height as i64 - 1) {
        for x in (cu - reach).max(0)..=(cu + reach).min(width as i64 - 1) {
            let p = f64::from(light[y as usize * width + x as usize]);
            sum += p;
            su += p * x as f64;
            sv += p * y as f64;
        }
    }
    (Vector2::new(su / sum, sv / sum), sum)
}

/// The raw pixel of each lamp in one camera.
fn raw_of(l: &GridLamp, side: Side) -> Option<Vector2<f64>> {
    match side {
        Side::Left => l.left,
        Side::Right => l.right,
    }
}

fn lens_of(s: &sim::Scenario, side: Side) -> Lens {
    let lens = s.rig.lens.unwrap();
    match side {
        Side::Left => lens.left,
        Side::Right => lens.right,
    }
}

/// The lamp's light, integrated exactly by the renderer, is centred on the raw pixel of its
/// centre (`Lens::unrectify` of its rectified projection) to far below the detector's 1/16 px,
/// everywhere in both raw images, corners included; and it holds the lamp's flux: its
/// brightness over its area in raw pixels (the disk's area times the lens's `|det d raw /
/// d rect|`).
#[test]
fn a_lamp_s_light_is_centred_on_its_raw_pixel() {
    for name in [RADTAN, FISHEYE] {
        let s = common::load(name);
        let c = s.true_camera();
        let regs = s.registers();
        let lamps = grid(&s, 37, 1.0, false);
        let renderer = Renderer::new(
            c,
            &regs,
            dark_roof(&s),
            lamps.iter().map(|l| l.lamp).collect(),
        )
        .with_lens(&s.rig.lens.unwrap());
        let mut checked = 0;
        for side in [Side::Left, Side::Right] {
            let light = renderer.radiance(&origin(), side);
            let lens = lens_of(&s, side);
            for l in &lamps {
                let Some(at) = raw_of(l, side).filter(|&a| inside(a, &s)) else {
                    continue;
                };
                let (centroid, flux) = light_at(&light, regs.width, at, 7);
                let off = (centroid - at).norm();
                assert!(
                    off < 1e-4,
                    "{name} {side:?}: lamp {} at {at:?}: {off} px off",
                    l.lamp.id
                );
                let (_, rect_from_raw) = lens.rectify(at, c.f, c.cx, c.cy).unwrap();
                let area = std::f64::consts::PI / rect_from_raw.determinant().abs();
                let expected = l.lamp.radiance_dn * area;
                assert!(
                    (flux - expected).abs() < 1e-3 * expected,
                    "{name} {side:?}: lamp {}: flux {flux} for {expected}",
                    l.lamp.id
                );
                checked += 1;
            }
        }
        // Every raw pixel of EuRoC's lens has a ray; the fisheye's corners look past 90 degrees.
        let least = if name == RADTAN { 2 * 17 * 12 } else { 2 * 160 };
        assert!(checked >= least, "{name}: {checked} lamps");
    }
}

/// A lamp's light is where the exact lens puts the light of its disk (each point of the disk
/// through the lens, weighed by the lens's magnification there), to within 0.01 px, from
/// point lamps (drawn through the lens's local affine map) to lamps 8 px across (through the
/// exact map where the affine one is off: `MAX_AFFINE_BEND_PX`), over both lenses' fields.
#[test]
fn a_lamp_s_light_is_where_the_exact_lens_puts_it() {
    for name in [RADTAN, FISHEYE] {
        let s = common::load(name);
        let c = s.true_camera();
        let regs = s.registers();
        let lens = s.rig.lens.unwrap().left;
        for radius_px in [1.0, 3.0, 8.0] {
            let lamps = grid(&s, 74, radius_px, false);
            let renderer = Renderer::new(
                c,
                &regs,
                dark_roof(&s),
                lamps.iter().map(|l| l.lamp).collect(),
            )
            .with_lens(&s.rig.lens.unwrap());
            let light = renderer.radiance(&origin(), Side::Left);
            let mut worst: f64 = 0.0;
            for l in &lamps {
                let Some(at) = l.left.filter(|&a| inside(a, &s)) else {
                    continue;
                };
                let rect = Vector2::new(l.rect[0], l.rect[1]);
                let exact = mapped_disk_centroid(&lens, &c, rect, radius_px);
                let (centroid, _) = light_at(&light, regs.width, at, 30);
                worst = worst.max((centroid - exact).norm());
            }
            assert!(worst < 0.01, "{name}, {radius_px} px: {worst} px");
        }
    }
}

/// The centroid of the raw image of the rectified disk of radius `r` at `rect` through the
/// exact lens: a polar quadrature over the disk (midpoints of 24 rings, 64 angles), each point
/// mapped by the lens and weighed by its area in raw pixels (a lens keeps the brightness per
/// raw pixel).
fn mapped_disk_centroid(lens: &Lens, c: &CameraParams, rect: Vector2<f64>, r: f64) -> Vector2<f64> {
    let (rings, angles) = (24, 64);
    let (mut n, mut sum) = (0.0, Vector2::zeros());
    for i in 0..rings {
        let rho = r * (f64::from(i) + 0.5) / f64::from(rings);
        for j in 0..angles {
            let a = std::f64::consts::TAU * f64::from(j) / f64::from(angles);
            let q = rect + rho * Vector2::new(a.cos(), a.sin());
            let at = lens.unrectify(q, c.f, c.cx, c.cy).unwrap();
            let (_, rect_from_raw) = lens.rectify(at, c.f, c.cx, c.cy).unwrap();
            let w = rho / rect_from_raw.determinant().abs();
            n += w;
            sum += w * at;
        }
    }
    sum / n
}

/// A lamp over which a lens is not affine (large, or far out in a fisheye's field) is drawn
/// through the lens's exact map: its light is centred where the lens puts the disk's light,
/// not on the raw pixel of its centre.
#[test]
fn a_large_lamp_is_drawn_through_the_exact_lens() {
    for (name, at, radius_px) in [
        (RADTAN, Vector2::new(60.3, 55.8), 30.0),
        (FISHEYE, Vector2::new(150.2, 240.6), 20.0),
    ] {
        let s = common::load(name);
        let c = s.true_camera();
        let regs = s.registers();
        let lens = s.rig.lens.unwrap().left;
        let rect = lens.rectify_point(at, c.f, c.cx, c.cy).unwrap();
        let p_in_rig = Vector3::new(
            (rect.x - c.cx) / c.f * DEPTH_M - c.baseline / 2.0,
            (rect.y - c.cy) / c.f * DEPTH_M,
            DEPTH_M,
        );
        let lamp = Lamp {
            id: 0,
            position: c.mount.robot_from_rig_rotation() * p_in_rig + c.mount.translation(),
            radius_m: radius_px * DEPTH_M / c.f,
            radiance_dn: 100.0,
            panel: None,
            lit: true,
        };
        let renderer =
            Renderer::new(c, &regs, dark_roof(&s), vec![lamp]).with_lens(&s.rig.lens.unwrap());
        let light = renderer.radiance(&origin(), Side::Left);
        let (centroid, _) = light_at(&light, regs.width, at, 45);
        let exact = mapped_disk_centroid(&lens, &c, rect, radius_px);
        let (moved, off) = ((exact - at).norm(), (centroid - exact).norm());
        assert!(
            moved > 0.1,
            "{name}: the lens moves the lamp's light by {moved} px"
        );
        assert!(
            off < 0.015,
            "{name}: {off} px from the lamp's light ({moved} px from its centre)"
        );
    }
}

/// For each lamp inside the raw image: the distance from the raw pixel of its centre to the
/// nearest feature the board's detector finds on the clean images (`pinhole`: the same lamps
/// rendered without the lens, against their rectified projections, inside the rectified
/// image).
fn detection_errors(
    name: &str,
    constant_flux: bool,
    pinhole: bool,
    max_off_axis_deg: f64,
) -> Vec<f64> {
    let s = common::load(name);
    let c = s.true_camera();
    let regs = s.registers();
    let lamps = grid(&s, 37, 0.8, constant_flux);
    let renderer = Renderer::new(
        c,
        &regs,
        dark_roof(&s),
        lamps.iter().map(|l| l.lamp).collect(),
    );
    let renderer = if pinhole {
        renderer
    } else {
        renderer.with_lens(&s.rig.lens.unwrap())
    };
    let images = renderer.render::<ChaCha8Rng>(&origin(), None);
    let mut errors = Vec::new();
    for (side, image) in [(Side::Left, &images.left), (Side::Right, &images.right)] {
        let detection = harris_core::detect(image, &regs).unwrap();
        for l in &lamps {
            let off_axis = (l.lamp.position - c.mount.translation()).angle(&Vector3::z());
            if off_axis.to_degrees() > max_off_axis_deg {
                continue;
            }
            let at = if pinhole {
                let i = if side == Side::Left { 0 } else { 2 };
                Some(Vector2::new(l.rect[i], l.rect[i + 1]))
            } else {
                raw_of(l, side)
            };
            let Some(at) = at.filter(|&a| inside(a, &s)) else {
                continue;
            };
            let nearest = detection
                .features
                .iter()
                .map(|f| (f.u() - at.x).hypot(f.v() - at.y))
                .fold(f64::INFINITY, f64::min);
            errors.push(nearest);
        }
    }
    errors
}

fn rms(e: &[f64]) -> f64 {
    (e.iter().map(|x| x * x).sum::<f64>() / e.len() as f64).sqrt()
}

/// The board's detector finds every lamp of a clean raw image within 0.08 px of the raw pixel
/// of its centre (0.035 px RMS), over the whole raw image of EuRoC's lens, corners included,
/// and over a fisheye's field out to 70 degrees off its axis: as well as it finds them in a
/// rectified image without a lens (its Q12.4 rounding alone is up to 0.044 px, 0.026 px RMS).
#[test]
fn the_detector_finds_raw_lamps_where_the_lens_puts_them() {
    let baseline = detection_errors(RADTAN, false, true, 90.0);
    for (name, constant_flux, max_off_axis_deg, least) in [
        (RADTAN, true, 90.0, 2 * 17 * 12),
        (FISHEYE, true, 70.0, 2 * 100),
    ] {
        let errors = detection_errors(name, constant_flux, false, max_off_axis_deg);
        assert!(errors.len() >= least, "{name}: {} lamps", errors.len());
        let worst = errors.iter().copied().fold(0.0, f64::max);
        assert!(
            worst <= 0.08,
            "{name}: a lamp is {worst} px from its raw pixel"
        );
        assert!(
            rms(&errors) <= 0.04,
            "{name}: RMS {} px (without the lens {} px)",
            rms(&errors),
            rms(&baseline)
        );
    }
}

/// The roof's beams through the lens: a raw pixel shows a beam exactly where the ray that
/// the lens gives it (`Lens::rectify_point`, then the rig's ray) meets a beam on the roof.
#[test]
fn the_roof_is_seen_through_the_lens() {
    for name in [RADTAN, FISHEYE] {
        let s = common::load(name);
        let c = s.true_camera();
        let regs = s.registers();
        let mut render = s.spec.render;
        render.beams = Beams::X;
        render.beam_highlight_dn = 0.0;
        let renderer = Renderer::new(c, &regs, render, Vec::new()).with_lens(&s.rig.lens.unwrap());
        let pose = Pose2::new(0.4, 0.7, 0.3);
        let (mut beam, mut roof) = (0, 0);
        for side in [Side::Left, Side::Right] {
            let light = renderer.radiance(&pose, side);
            let lens = lens_of(&s, side);
            let x_in_rig = if side == Side::Left {
                -c.baseline / 2.0
            } else {
                c.baseline / 2.0
            };
            let centre = pose.point_in_world(
                &(c.mount.robot_from_rig_rotation() * Vector3::new(x_in_rig, 0.0, 0.0)
                    + c.mount.translation()),
            );
            let world_from_rig =
                pose.world_from_robot_rotation() * c.mount.robot_from_rig_rotation();
            for v in (0..regs.height).step_by(3) {
                for u in (0..regs.width).step_by(5) {
                    let Some(rect) =
                        lens.rectify_point(Vector2::new(u as f64, v as f64), c.f, c.cx, c.cy)
                    else {
                        continue;
                    };
                    let ray = world_from_rig
                        * Vector3::new((rect.x - c.cx) / c.f, (rect.y - c.cy) / c.f, 1.0);
                    if ray.z < 0.5 * ray.norm() {
                        continue; // far out, a pixel spans a beam's edge
                    }
                    let y = centre.y + (render.roof_z_m - centre.z) / ray.z * ray.y;
                    // Distance to the nearest beam's middle, metres.
                    let d = (y / render.beam_spacing_m - (y / render.beam_spacing_m).round()).abs()
                        * render.beam_spacing_m;
                    let value = f64::from(light[v * regs.width + u]);
                    if d < render.beam_width_m / 2.0 - 0.08 {
                        assert_eq!(value, render.beam_dn, "{name} {side:?} ({u}, {v})");
                        beam += 1;
                    } else if d > render.beam_width_m / 2.0 + 0.08 {
                        assert_eq!(value, render.roof_dn, "{name} {side:?} ({u}, {v})");
                        roof += 1;
                    }
                }
            }
        }
        assert!(
            beam > 100 && roof > 1000,
            "{name}: {beam} beam, {roof} roof pixels"
        );
    }
}

/// A rendered run through EuRoC's lenses (the scenario as it is): the board's features are
/// raw, and the simulator labels each with the lamp whose raw pixel it is at (the views carry
/// rectified projections), within half a pixel with the sensor's noise.
#[test]
fn a_rendered_run_through_a_lens_labels_its_raw_features() {
    let mut s = common::shorten(common::load(RADTAN), 2);
    s.spec.path.segments[1] = sim::scenario::Segment::straight(0.5);
    let c = s.true_camera();
    let lens = s.rig.lens.unwrap();
    let run = sim::simulate(&s, Mode::Rendered).unwrap();
    let (mut labelled, mut in_view, mut far_from_rect) = (0, 0, 0);
    for f in &run.frames {
        for (features, side) in [(&f.left, Side::Left), (&f.right, Side::Right)] {
            let lens = if side == Side::Left {
                lens.left
            } else {
                lens.right
            };
            in_view += f
                .views
                .iter()
                .filter(|v| {
                    if side == Side::Left {
                        v.in_left
                    } else {
                        v.in_right
                    }
                })
                .count();
            for feat in features.features.iter().filter(|x| x.lamp.is_some()) {
                labelled += 1;
                let view = f.views.iter().find(|v| Some(v.id) == feat.lamp).unwrap();
                let rect = if side == Side::Left {
                    Vector2::new(view.u_left, view.v_left)
                } else {
                    Vector2::new(view.u_right, view.v_right)
                };
                let raw = lens.unrectify(rect, c.f, c.cx, c.cy).unwrap();
                let at = Vector2::new(f64::from(feat.x_q4), f64::from(feat.y_q4)) / 16.0;
                let d = (at - raw).norm();
                assert!(d < 0.5, "frame {}: {d} px from its raw pixel", f.index);
                if (at - rect).norm() > 2.0 {
                    far_from_rect += 1;
                }
            }
        }
    }
    assert!(labelled > 400, "{labelled} lamp features");
    // All but a few lamps at the edges of the images, dimmed by the lens.
    assert!(
        labelled <= in_view && labelled * 100 >= in_view * 99,
        "{labelled} of {in_view} lamps in view found and labelled"
    );
    assert!(
        far_from_rect * 4 > labelled,
        "{far_from_rect} of {labelled} far from the rectified projection"
    );
}
