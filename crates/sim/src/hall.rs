//! Large halls for Monte Carlo runs (issue 35): a generator of mapping drives through whole
//! halls, drawn from a seed.
//!
//! A hall is a jittered grid of high-bay lamps, optionally with sprinkler heads between them
//! and beam corners above them (persistent features that are not lamps: dimmer, smaller, at
//! other heights), and a row of tubes along one wall (lamps that are not points: a tube is two
//! landmarks, its ends). The forklift drives serpentine aisles along the hall with a stop in
//! each, returns along the end wall and drives the first aisle again (the other way), so that
//! lamps are seen from neighbouring aisles and again minutes later. The head looks up through
//! one of the project's two real lenses (EuRoC's radtan, `hall-radtan.rig.toml`; TUM VI's
//! fisheye, `hall-map.rig.toml`), whose nominal rig files are compiled in; the vehicle's errors
//! (odometry scale, yaw-rate scale and bias, a board clock offset) are those of a real vehicle
//! or none.
//!
//! [`HallSpec::draw`] draws a hall from a seed, [`scenario_toml`] writes it as a scenario file
//! (to look at, or to keep), [`scenario`] makes the [`Scenario`] itself.

use core::fmt::Write as _;

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rig_model::config::Rig;

use crate::error::Result;
use crate::scenario::{Scenario, ScenarioSpec};

/// EuRoC's radtan lenses rectified at EuRoC's own focal length (the radtan hall's rig).
const RADTAN_RIG: &str = include_str!("../../../fixtures/scenarios/hall-radtan.rig.toml");
/// TUM VI's fisheyes rectified at f = 220 px (the sparse hall's rig).
const FISHEYE_RIG: &str = include_str!("../../../fixtures/scenarios/hall-map.rig.toml");

/// The lens a hall is seen through.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum HallLens {
    /// EuRoC's radtan lenses (`hall-radtan.rig.toml`).
    Radtan,
    /// TUM VI's equidistant fisheyes (`hall-map.rig.toml`).
    Fisheye,
}

impl HallLens {
    /// `radtan` or `fisheye`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Radtan => "radtan",
            Self::Fisheye => "fisheye",
        }
    }

    /// The nominal rig file's text.
    fn rig_text(self) -> &'static str {
        match self {
            Self::Radtan => RADTAN_RIG,
            Self::Fisheye => FISHEYE_RIG,
        }
    }

    /// The true camera's `f, cx, cy` (the rig's, rectified).
    fn camera(self) -> (f64, f64, f64) {
        match self {
            Self::Radtan => (436.2443, 364.4412, 256.9517),
            Self::Fisheye => (220.0, 376.0, 240.0),
        }
    }
}

/// One hall and its mapping drive.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HallSpec {
    /// Serpentine aisles, at least 1.
    pub aisles: u32,
    /// Length of each aisle, metres.
    pub aisle_length_m: f64,
    /// Between neighbouring aisles, metres (the U-turns' diameter).
    pub aisle_spacing_m: f64,
    /// The lamp grid's spacing, metres.
    pub lamp_spacing_m: f64,
    /// The lamps' height above the floor, metres (the cameras are 2.2 m up).
    pub lamp_height_m: f64,
    /// Uniform jitter of each lamp in x and y, metres.
    pub jitter_xy_m: f64,
    /// Sprinkler heads between the lamps (a grid offset by half a spacing, 0.4 m lower).
    pub sprinklers: bool,
    /// Beam corners above the lamps (a grid of twice the spacing, 0.5 m higher).
    pub beam_corners: bool,
    /// A row of tubes along the hall's wall at `y < 0`.
    pub tubes: bool,
    /// A row of square LED panels (0.6 m) along the hall's other wall: four corners each.
    pub panels: bool,
    /// A dark stretch across the hall's middle, metres (0: none): no lamp, sprinkler head,
    /// beam corner, tube or panel there, so that each aisle drives this far blind and comes
    /// back to lamps mapped from the neighbouring aisle (a loop, item 2 of issue 35).
    pub dark_stretch_m: f64,
    /// The lens.
    pub lens: HallLens,
    /// A real vehicle's errors: odometry 1 % fast, yaw rates 0.5 % high with a 0.002 rad/s
    /// bias, the board's clock 12 ms ahead; none when false.
    pub vehicle_errors: bool,
    /// Top speed, m/s.
    pub max_speed_mps: f64,
    /// The stop in the middle of each aisle, seconds.
    pub stop_s: f64,
}

impl Default for HallSpec {
    /// The radtan hall's layout (`hall-radtan.toml`): five aisles of 42 m, 6 m apart, lamps on
    /// a 3 m grid 7 m up, sprinkler heads, a real vehicle's errors.
    fn default() -> Self {
        Self {
            aisles: 5,
            aisle_length_m: 42.0,
            aisle_spacing_m: 6.0,
            lamp_spacing_m: 3.0,
            lamp_height_m: 7.0,
            jitter_xy_m: 0.3,
            sprinklers: true,
            beam_corners: false,
            tubes: false,
            panels: false,
            dark_stretch_m: 0.0,
            lens: HallLens::Radtan,
            vehicle_errors: true,
            max_speed_mps: 1.2,
            stop_s: 3.0,
        }
    }
}

impl HallSpec {
    /// A hall drawn from `seed`: 3 to 6 aisles of 24 to 48 m, 5 to 8 m apart, lamps every 2.5
    /// to 4.5 m, 5.5 to 9 m up, with jitter up to 0.4 m; sprinkler heads, beam corners and
    /// tubes each in about half the halls; either lens; always a real vehicle's errors; LED
    /// panels in about half the halls and a dark stretch of 8 to 16 m across the middle in
    /// about half (drawn after the rest, so that a seed's other features are as before).
    pub fn draw(seed: u64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x4841_4c4c); // "HALL"
        let mut uniform = |lo: f64, hi: f64| lo + (hi - lo) * rng.random::<f64>();
        let round = |x: f64, step: f64| (x / step).round() * step;
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let aisles = (uniform(3.0, 7.0).floor() as u32).clamp(3, 6);
        let aisle_length_m = round(uniform(24.0, 48.0), 1.0);
        let aisle_spacing_m = round(uniform(5.0, 8.0), 0.5);
        let lamp_spacing_m = round(uniform(2.5, 4.5), 0.5);
        let lamp_height_m = round(uniform(5.5, 9.0), 0.1);
        let jitter_xy_m = round(uniform(0.0, 0.4), 0.05);
        let sprinklers = uniform(0.0, 1.0) < 0.5;
        let beam_corners = uniform(0.0, 1.0) < 0.5;
        let tubes = uniform(0.0, 1.0) < 0.5;
        let lens = if uniform(0.0, 1.0) < 0.5 {
            HallLens::Radtan
        } else {
            HallLens::Fisheye
        };
        let panels = uniform(0.0, 1.0) < 0.5;
        let dark = uniform(0.0, 1.0) < 0.5;
        // At least 6 m of lamps left at each end.
        let dark_stretch_m = if dark {
            round(uniform(8.0, 16.0).min(aisle_length_m - 12.0), 1.0).max(0.0)
        } else {
            0.0
        };
        Self {
            aisles,
            aisle_length_m,
            aisle_spacing_m,
            lamp_spacing_m,
            lamp_height_m,
            jitter_xy_m,
            sprinklers,
            beam_corners,
            tubes,
            panels,
            dark_stretch_m,
            lens,
            vehicle_errors: true,
            max_speed_mps: 1.2,
            stop_s: 3.0,
        }
    }

    /// The dark stretch's `[from, to]` in x, if any: centred on the aisles' middle.
    fn dark_band(&self) -> Option<(f64, f64)> {
        (self.dark_stretch_m > 0.0).then(|| {
            let mid = 0.5 * self.aisle_length_m;
            (
                mid - 0.5 * self.dark_stretch_m,
                mid + 0.5 * self.dark_stretch_m,
            )
        })
    }

    /// One line saying what the hall is.
    pub fn describe(&self) -> String {
        let mut extras = Vec::new();
        if self.sprinklers {
            extras.push("sprinkler heads");
        }
        if self.beam_corners {
            extras.push("beam corners");
        }
        if self.tubes {
            extras.push("tubes");
        }
        if self.panels {
            extras.push("LED panels");
        }
        let dark = if self.dark_stretch_m > 0.0 {
            format!(", {:.0} m dark across the middle", self.dark_stretch_m)
        } else {
            String::new()
        };
        format!(
            "{} aisles of {:.0} m {:.1} m apart, lamps every {:.1} m {:.1} m up{}{}{dark}, {} lens{}",
            self.aisles,
            self.aisle_length_m,
            self.aisle_spacing_m,
            self.lamp_spacing_m,
            self.lamp_height_m,
            if extras.is_empty() { "" } else { " with " },
            extras.join(", "),
            self.lens.name(),
            if self.vehicle_errors {
                ", a real vehicle's errors"
            } else {
                ""
            }
        )
    }
}

/// A grid of `n` points from `start` with `step` between them, covering `[lo, hi]`.
fn grid_count(lo: f64, hi: f64, step: f64) -> usize {
    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
    let n = ((hi - lo) / step).floor().max(0.0) as usize;
    n + 1
}

/// A grid row of `nx` points from `x0`, `d` apart, as the runs outside the dark band
/// `(from, to)`: `(x0, nx)` of each.
fn split_row(x0: f64, nx: usize, d: f64, band: Option<(f64, f64)>) -> Vec<(f64, usize)> {
    let Some((a, b)) = band else {
        return vec![(x0, nx)];
    };
    let mut runs: Vec<(f64, usize)> = Vec::new();
    for k in 0..nx {
        #[allow(clippy::cast_precision_loss)]
        let x = x0 + d * k as f64;
        if x >= a && x <= b {
            continue;
        }
        match runs.last_mut() {
            #[allow(clippy::cast_precision_loss)]
            Some((start, n)) if (x - (*start + d * *n as f64)).abs() < 1e-9 => *n += 1,
            _ => runs.push((x, 1)),
        }
    }
    runs
}

/// The hall as a scenario file (TOML) with `seed` (the noise's and the jitter's); its `rig`
/// key names the lens's rig file in `fixtures/scenarios/`.
pub fn scenario_toml(spec: &HallSpec, seed: u64) -> String {
    let (f, cx, cy) = spec.lens.camera();
    let margin = 3.0;
    let (x_lo, x_hi) = (-margin, spec.aisle_length_m + margin);
    let width = f64::from(spec.aisles.max(1) - 1) * spec.aisle_spacing_m;
    let (y_lo, y_hi) = (-margin, width + margin);
    let s = spec.lamp_spacing_m;
    let mut t = String::new();
    let rig_file = match spec.lens {
        HallLens::Radtan => "hall-radtan.rig.toml",
        HallLens::Fisheye => "hall-map.rig.toml",
    };
    // Writing to a String cannot fail.
    let _ = writeln!(
        t,
        "# Generated by sim::hall::scenario_toml (issue 35's hall Monte Carlo).\n\
         description = {:?}\nseed = {seed}\nrig = {rig_file:?}\n",
        spec.describe()
    );
    let _ = writeln!(
        t,
        "[camera]\nwidth = 752\nheight = 480\nf_px = {f}\ncx_px = {cx}\ncy_px = {cy}\n\
         baseline_m = 0.1192\n\
         mount = {{ x_m = 0.5, y_m = 0.0, z_m = 2.2, roll_deg = 0.0, pitch_deg = 5.0, yaw_deg = 0.0 }}\n"
    );
    let e = spec.vehicle_errors;
    let pick = |v: f64| if e { v } else { 0.0 };
    let _ = writeln!(
        t,
        "[rates]\nodometry_hz = 100.0\ncamera_hz = 20.0\nstart_t_us = 1000000\n\
         board_clock_offset_s = {}\n\n[noise]\npixel_px = 0.3\nvelocity_mps = 0.02\n\
         yaw_rate_radps = 0.01\nvelocity_scale_error = {}\nyaw_rate_scale_error = {}\n\
         yaw_rate_bias_radps = {}\n",
        pick(0.012),
        pick(0.01),
        pick(0.005),
        pick(0.002)
    );
    let _ = writeln!(
        t,
        "[world]\nlamp_radius_m = 0.003\nlamp_radiance_dn = 400.0\nseed = {}\ngrids = [",
        seed.wrapping_mul(7).wrapping_add(1)
    );
    let band = spec.dark_band();
    // One grid line (`rest` its keys after the spacing), split around the dark stretch.
    let mut grid = |x0: f64, y0: f64, z: f64, nx: usize, ny: usize, d: f64, rest: &str| {
        for (x0, nx) in split_row(x0, nx, d, band) {
            let _ = writeln!(
                t,
                "  {{ x0_m = {x0}, y0_m = {y0}, z_m = {z}, nx = {nx}, ny = {ny}, dx_m = {d}, dy_m = {d}, {rest} }},"
            );
        }
    };
    let (nx, ny) = (grid_count(x_lo, x_hi, s), grid_count(y_lo, y_hi, s));
    grid(
        x_lo,
        y_lo,
        spec.lamp_height_m,
        nx,
        ny,
        s,
        &format!("jitter_xy_m = {}, jitter_z_m = 0.1", spec.jitter_xy_m),
    );
    if spec.sprinklers {
        let (x0, y0) = (x_lo + 0.5 * s, y_lo + 0.5 * s);
        grid(
            x0,
            y0,
            spec.lamp_height_m - 0.4,
            grid_count(x0, x_hi, s),
            grid_count(y0, y_hi, s),
            s,
            &format!(
                "jitter_xy_m = {}, jitter_z_m = 0.05, radius_m = 0.002, radiance_dn = 150.0",
                spec.jitter_xy_m
            ),
        );
    }
    if spec.beam_corners {
        let b = 2.0 * s;
        let (x0, y0) = (x_lo + 0.25 * s, y_lo + 0.25 * s);
        grid(
            x0,
            y0,
            spec.lamp_height_m + 0.5,
            grid_count(x0, x_hi, b),
            grid_count(y0, y_hi, b),
            b,
            "jitter_xy_m = 0.05, jitter_z_m = 0.02, radius_m = 0.002, radiance_dn = 120.0",
        );
    }
    let _ = writeln!(t, "]");
    let lit = |x: f64, half: f64| band.is_none_or(|(a, b)| x + half < a || x - half > b);
    if spec.tubes || spec.panels {
        let _ = writeln!(t, "panels = [");
        let step = 2.0 * s;
        for k in 0..grid_count(x_lo + s, x_hi - s, step) {
            #[allow(clippy::cast_precision_loss)]
            let x = x_lo + s + step * k as f64;
            if spec.tubes && lit(x, 0.6) {
                let _ = writeln!(
                    t,
                    "  {{ x_m = {x}, y_m = {}, z_m = {}, length_m = 1.2, width_m = 0.08 }},",
                    y_lo - 1.0,
                    spec.lamp_height_m - 0.2
                );
            }
            if spec.panels && lit(x, 0.3) {
                let _ = writeln!(
                    t,
                    "  {{ x_m = {x}, y_m = {}, z_m = {}, length_m = 0.6, width_m = 0.6 }},",
                    y_hi + 1.0,
                    spec.lamp_height_m - 0.1
                );
            }
        }
        let _ = writeln!(t, "]");
    }
    let _ = writeln!(
        t,
        "\n[path]\nmax_speed_mps = {}\nmax_accel_mps2 = 0.5\nmax_yaw_rate_degps = 30.0\n\
         max_yaw_accel_degps2 = 30.0\nmax_lateral_accel_mps2 = 0.8\nsegments = [\n  \
         {{ kind = \"wait\", duration_s = 2.0 }},",
        spec.max_speed_mps
    );
    let half = 0.5 * spec.aisle_length_m;
    let r = 0.5 * spec.aisle_spacing_m;
    for a in 0..spec.aisles.max(1) {
        let _ = writeln!(
            t,
            "  {{ kind = \"straight\", length_m = {half} }},\n  {{ kind = \"wait\", duration_s = {} }},\n  {{ kind = \"straight\", length_m = {half} }},",
            spec.stop_s
        );
        if a + 1 < spec.aisles {
            let angle = if a % 2 == 0 { 180.0 } else { -180.0 };
            let _ = writeln!(
                t,
                "  {{ kind = \"arc\", radius_m = {r}, angle_deg = {angle} }},"
            );
        }
    }
    // Back along the end wall to the first aisle, and the first aisle again. After an odd
    // number of aisles the vehicle is at the far end heading +x; after an even number, at the
    // start heading -x.
    let (turn, first_again) = if spec.aisles % 2 == 1 {
        (-90.0, spec.aisle_length_m)
    } else {
        (90.0, spec.aisle_length_m)
    };
    if spec.aisles > 1 {
        let _ = writeln!(
            t,
            "  {{ kind = \"turn\", angle_deg = {turn} }},\n  {{ kind = \"straight\", length_m = {width} }},\n  {{ kind = \"turn\", angle_deg = {turn} }},\n  {{ kind = \"straight\", length_m = {first_again} }},"
        );
    }
    let _ = writeln!(
        t,
        "  {{ kind = \"wait\", duration_s = 1.0 }},\n]\n\n[clutter]\nper_image = 1.0\nstereo_per_frame = 0.3"
    );
    t
}

/// The hall as a [`Scenario`] (its rig is the lens's, compiled in).
pub fn scenario(spec: &HallSpec, seed: u64) -> Result<Scenario> {
    let name = format!("hall {seed} ({})", spec.describe());
    let parsed = ScenarioSpec::from_toml_str(&scenario_toml(spec, seed), &name)?;
    let rig = Rig::from_toml_str(spec.lens.rig_text(), spec.lens.name())?;
    Scenario::from_parts(parsed, rig, &name)
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::float_cmp)]
mod tests {
    use super::*;

    #[test]
    fn the_default_hall_is_the_radtan_hall_s_layout() {
        let sc = scenario(&HallSpec::default(), 35).unwrap();
        let w = &sc.spec.world;
        assert_eq!(w.grids.len(), 2);
        assert_eq!((w.grids[0].nx, w.grids[0].ny), (17, 11));
        assert_eq!(sc.spec.path.segments.len(), 25);
    }

    #[test]
    fn drawn_halls_load_and_differ() {
        let mut lenses = std::collections::BTreeSet::new();
        for seed in 0..20 {
            let spec = HallSpec::draw(seed);
            assert!((3..=6).contains(&spec.aisles), "{spec:?}");
            let sc = scenario(&spec, seed).unwrap();
            assert_eq!(sc.spec.seed, seed);
            lenses.insert(spec.lens.name());
            // The drive ends on the first aisle, where it started (x within the aisle).
            assert!(sc.spec.path.segments.len() >= 4 * spec.aisles as usize);
        }
        assert_eq!(lenses.len(), 2);
        assert_ne!(HallSpec::draw(1), HallSpec::draw(2));
    }

    #[test]
    fn a_dark_stretch_leaves_no_feature_in_its_band_and_panels_have_their_row() {
        let spec = HallSpec {
            dark_stretch_m: 12.0,
            panels: true,
            tubes: true,
            beam_corners: true,
            ..HallSpec::default()
        };
        let sc = scenario(&spec, 35).unwrap();
        let (a, b) = spec.dark_band().unwrap();
        assert_eq!((a, b), (15.0, 27.0));
        let w = &sc.spec.world;
        // Each of the three grids split in two around the band.
        assert_eq!(w.grids.len(), 6);
        for g in &w.grids {
            for k in 0..g.nx {
                #[allow(clippy::cast_precision_loss)]
                let x = g.x0_m + g.dx_m * k as f64;
                assert!(x < a || x > b, "a grid point at x = {x} in the dark band");
            }
        }
        let panels = w.panels.iter().filter(|p| p.length_m == 0.6).count();
        let tubes = w.panels.iter().filter(|p| p.length_m == 1.2).count();
        assert!(panels > 0 && tubes > 0);
        assert!(w.panels.iter().all(|p| p.x_m + 0.6 < a || p.x_m - 0.6 > b));
        // Without a dark stretch nothing is split.
        assert_eq!(split_row(0.0, 5, 1.0, None), vec![(0.0, 5)]);
        assert_eq!(
            split_row(0.0, 10, 1.0, Some((3.5, 6.5))),
            vec![(0.0, 4), (7.0, 3)]
        );
    }
}
