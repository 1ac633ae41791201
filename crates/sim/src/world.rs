//! The world: point lamps (LEDs, ceiling lights) and rectangular panels and tubes in the
//! world frame `W` (the robot's frame at the first stereo frame). A panel is its corners as
//! landmarks (a tube its ends): the points a corner detector finds on it.

use nalgebra::Vector3;
use rand::RngExt;

use crate::rng::{Stream, stream_rng};
use crate::scenario::World;

/// A rectangular lamp flat on the ceiling (world frame).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Panel {
    /// Its index among the scenario's panels.
    pub index: u32,
    /// Centre, metres.
    pub centre: Vector3<f64>,
    /// Half its length along its axis, metres.
    pub half_length_m: f64,
    /// Half its width, metres.
    pub half_width_m: f64,
    /// Its axis from the world's x axis, radians.
    pub yaw: f64,
    /// Brightness, DN.
    pub radiance_dn: f64,
}

impl Panel {
    /// Whether the world point `(x, y)` (at the panel's height) is on the panel.
    pub fn contains(&self, x: f64, y: f64) -> bool {
        let (s, c) = self.yaw.sin_cos();
        let (dx, dy) = (x - self.centre.x, y - self.centre.y);
        (c * dx + s * dy).abs() <= self.half_length_m
            && (-s * dx + c * dy).abs() <= self.half_width_m
    }

    /// A tube: less than a seventh as wide as it is long.
    pub fn is_tube(&self) -> bool {
        7.0 * self.half_width_m < self.half_length_m
    }

    /// The points the detector sees: the four corners, or a tube's two ends.
    pub fn feature_points(&self) -> Vec<Vector3<f64>> {
        let (s, c) = self.yaw.sin_cos();
        let at = |a: f64, b: f64| {
            Vector3::new(
                self.centre.x + c * a - s * b,
                self.centre.y + s * a + c * b,
                self.centre.z,
            )
        };
        let (l, w) = (self.half_length_m, self.half_width_m);
        if self.is_tube() {
            vec![at(-l, 0.0), at(l, 0.0)]
        } else {
            vec![at(-l, -w), at(l, -w), at(l, w), at(-l, w)]
        }
    }
}

/// One lamp: a landmark of the map.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Lamp {
    /// Landmark id: the lamp's index in the run.
    pub id: u32,
    /// Position in the world frame, metres (z: height above the floor).
    pub position: Vector3<f64>,
    /// Physical radius, metres (its apparent size in rendered images).
    pub radius_m: f64,
    /// Brightness: the sensor value of a pixel wholly covered by the lamp, DN.
    pub radiance_dn: f64,
    /// The panel this point is a corner (or a tube end) of: the renderer draws the panel, not
    /// a disk.
    pub panel: Option<Panel>,
}

/// The lamps of a scenario: the explicit list first, then each grid row by row (`y` outer,
/// `x` inner), each grid lamp moved by uniform jitter drawn from the seed.
pub fn lamps(world: &World, seed: u64) -> Vec<Lamp> {
    let mut rng = stream_rng(seed, Stream::World, 0);
    let mut out = Vec::new();
    let mut push = |position: Vector3<f64>, radius: Option<f64>, radiance: Option<f64>| {
        let id = u32::try_from(out.len()).unwrap_or(u32::MAX);
        out.push(Lamp {
            id,
            position,
            radius_m: radius.unwrap_or(world.lamp_radius_m),
            radiance_dn: radiance.unwrap_or(world.lamp_radiance_dn),
            panel: None,
        });
    };
    for l in &world.lamps {
        push(Vector3::new(l.x_m, l.y_m, l.z_m), l.radius_m, l.radiance_dn);
    }
    for g in &world.grids {
        for iy in 0..g.ny {
            for ix in 0..g.nx {
                // Always draw, so that the jitter of one lamp does not depend on another's.
                let jx: f64 = rng.random_range(-1.0..=1.0);
                let jy: f64 = rng.random_range(-1.0..=1.0);
                let jz: f64 = rng.random_range(-1.0..=1.0);
                #[allow(clippy::cast_precision_loss)] // grid indices are far below 2^52
                let p = Vector3::new(
                    g.x0_m + ix as f64 * g.dx_m + jx * g.jitter_xy_m,
                    g.y0_m + iy as f64 * g.dy_m + jy * g.jitter_xy_m,
                    g.z_m + jz * g.jitter_z_m,
                );
                push(p, g.radius_m, g.radiance_dn);
            }
        }
    }
    for (i, q) in world.panels.iter().enumerate() {
        let panel = Panel {
            index: u32::try_from(i).unwrap_or(u32::MAX),
            centre: Vector3::new(q.x_m, q.y_m, q.z_m),
            half_length_m: q.length_m / 2.0,
            half_width_m: q.width_m / 2.0,
            yaw: q.yaw_deg.to_radians(),
            radiance_dn: q.radiance_dn.unwrap_or(world.lamp_radiance_dn),
        };
        for position in panel.feature_points() {
            let id = u32::try_from(out.len()).unwrap_or(u32::MAX);
            out.push(Lamp {
                id,
                position,
                radius_m: 0.0,
                radiance_dn: panel.radiance_dn,
                panel: Some(panel),
            });
        }
    }
    out
}
