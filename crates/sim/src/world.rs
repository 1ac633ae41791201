//! The world: point lamps (LEDs, ceiling lights) and rectangular panels and tubes in the
//! world frame `W` (the robot's frame at the first stereo frame, or the hall's frame when the
//! path has a start pose: [`crate::scenario::PathSpec::start`]). A panel is its corners as
//! landmarks (a tube its ends): the points a corner detector finds on it. Lamps that are dark
//! in a drive stay in the list (ids are indices), marked off.

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
    /// On in this drive; a dark lamp (`world.dark`) is never seen nor drawn.
    pub lit: bool,
}

/// The lamps of a scenario, with `id` their index: the explicit list first, then each grid
/// row by row (`y` outer, `x` inner), each grid lamp moved by uniform jitter drawn from
/// `world.seed` (or, without it, the scenario's `seed`), then the panels' points, then
/// `world.added`. The lamps of `world.dark` are there with `lit` false.
pub fn lamps(world: &World, seed: u64) -> Vec<Lamp> {
    let mut rng = stream_rng(world.seed.unwrap_or(seed), Stream::World, 0);
    let mut out = Vec::new();
    let mut push = |position: Vector3<f64>, radius: Option<f64>, radiance: Option<f64>| {
        let id = u32::try_from(out.len()).unwrap_or(u32::MAX);
        out.push(Lamp {
            id,
            position,
            radius_m: radius.unwrap_or(world.lamp_radius_m),
            radiance_dn: radiance.unwrap_or(world.lamp_radiance_dn),
            panel: None,
            lit: true,
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
                lit: true,
            });
        }
    }
    for l in &world.added {
        let id = u32::try_from(out.len()).unwrap_or(u32::MAX);
        out.push(Lamp {
            id,
            position: Vector3::new(l.x_m, l.y_m, l.z_m),
            radius_m: l.radius_m.unwrap_or(world.lamp_radius_m),
            radiance_dn: l.radiance_dn.unwrap_or(world.lamp_radiance_dn),
            panel: None,
            lit: true,
        });
    }
    for &id in &world.dark {
        if let Some(lamp) = usize::try_from(id).ok().and_then(|i| out.get_mut(i)) {
            lamp.lit = false;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenario::{GridSpec, LampSpec, PanelSpec};

    fn lamp(x_m: f64) -> LampSpec {
        LampSpec {
            x_m,
            y_m: 0.0,
            z_m: 3.0,
            radius_m: None,
            radiance_dn: None,
        }
    }

    fn world() -> World {
        World {
            lamp_radius_m: 0.003,
            lamp_radiance_dn: 400.0,
            lamp_response: 5.0e7,
            lamps: vec![lamp(0.0)],
            grids: vec![GridSpec {
                x0_m: 0.0,
                y0_m: 0.0,
                z_m: 4.0,
                nx: 3,
                ny: 2,
                dx_m: 1.0,
                dy_m: 1.0,
                jitter_xy_m: 0.1,
                jitter_z_m: 0.1,
                radius_m: None,
                radiance_dn: None,
            }],
            panels: vec![PanelSpec {
                x_m: 1.0,
                y_m: 1.0,
                z_m: 4.0,
                length_m: 1.2,
                width_m: 0.04,
                yaw_deg: 0.0,
                radiance_dn: None,
            }],
            added: Vec::new(),
            dark: Vec::new(),
            seed: None,
        }
    }

    #[test]
    fn ids_run_through_lamps_grids_panels_then_added_and_dark_ones_stay() {
        let plain = lamps(&world(), 1);
        assert_eq!(plain.len(), 1 + 6 + 2);
        let mut w = world();
        w.added = vec![lamp(7.0), lamp(8.0)];
        w.dark = vec![3, 7, 8];
        let l = lamps(&w, 1);
        assert_eq!(l.len(), 11);
        assert!(l.iter().enumerate().all(|(i, x)| x.id as usize == i));
        assert_eq!(
            &l[..9].iter().map(|x| x.position).collect::<Vec<_>>(),
            &plain.iter().map(|x| x.position).collect::<Vec<_>>()
        );
        assert_eq!((l[9].position.x, l[10].position.x), (7.0, 8.0));
        let dark: Vec<u32> = l.iter().filter(|x| !x.lit).map(|x| x.id).collect();
        assert_eq!(dark, [3, 7, 8]);
        assert!(l[7].panel.is_some() && l[8].panel.is_some());
    }

    #[test]
    fn world_seed_is_the_seed_of_the_jitter() {
        let mut w = world();
        let positions = |w: &World, seed: u64| {
            lamps(w, seed)
                .iter()
                .map(|x| x.position)
                .collect::<Vec<_>>()
        };
        let (a, b) = (positions(&w, 1), positions(&w, 2));
        assert_ne!(a, b);
        w.seed = Some(1);
        assert_eq!(positions(&w, 2), a);
        assert_eq!(positions(&w, 1), a);
    }
}
