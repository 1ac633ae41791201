//! The world: point lamps (LEDs, ceiling lights) in the world frame `W` (the robot's frame at
//! the first stereo frame).

use nalgebra::Vector3;
use rand::RngExt;

use crate::rng::{Stream, stream_rng};
use crate::scenario::World;

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
    out
}
