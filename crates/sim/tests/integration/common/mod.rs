//! Helpers shared by the simulator's tests.
#![allow(dead_code, unreachable_pub, clippy::unwrap_used, clippy::expect_used)]

use std::path::{Path, PathBuf};

use fpga_link::{Decoder, Event, Feature, Stats};

/// A committed scenario file.
pub fn scenario_path(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/scenarios")
        .join(format!("{name}.toml"))
}

pub fn load(name: &str) -> sim::Scenario {
    sim::Scenario::load(&scenario_path(name)).expect("the committed scenario loads")
}

/// Keeps only the first `n` segments of the path and one repetition: a short run.
pub fn shorten(mut s: sim::Scenario, n: usize) -> sim::Scenario {
    s.spec.path.segments.truncate(n);
    s.spec.path.repeat = 1;
    s
}

/// Turns every source of noise, clutter and fault off.
pub fn noise_off(mut s: sim::Scenario) -> sim::Scenario {
    let n = &mut s.spec.noise;
    n.pixel_px = 0.0;
    n.velocity_mps = 0.0;
    n.yaw_rate_radps = 0.0;
    n.velocity_scale_error = 0.0;
    n.yaw_rate_bias_radps = 0.0;
    s.spec.clutter.per_image = 0.0;
    s.spec.clutter.stereo_per_frame = 0.0;
    s.spec.link.loss_probability = 0.0;
    s.spec.link.bit_flip_probability = 0.0;
    s.spec.render.read_noise_dn = 0.0;
    s.spec.render.electrons_per_dn = 0.0;
    s
}

/// A decoded frame, owned.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Decoded {
    pub frame: u32,
    pub t_us: u64,
    pub flags: u8,
    pub left: Vec<Feature>,
    pub right: Vec<Feature>,
}

/// Decodes chunks in order with fpga-link's decoder.
pub fn decode<'a>(chunks: impl IntoIterator<Item = &'a [u8]>) -> (Vec<Decoded>, Stats) {
    let mut decoder = Decoder::new();
    let mut out = Vec::new();
    let mut push = |event: Event<'_>| {
        if let Event::Frame(f) = event {
            out.push(Decoded {
                frame: f.frame(),
                t_us: f.t_us(),
                flags: f.flags(),
                left: f.left().collect(),
                right: f.right().collect(),
            });
        }
    };
    for chunk in chunks {
        let mut rest = chunk;
        loop {
            let (used, event) = decoder.decode(rest);
            rest = &rest[used..];
            match event {
                Some(e) => push(e),
                None => break,
            }
        }
    }
    while let Some(e) = decoder.decode_end() {
        push(e);
    }
    (out, decoder.stats())
}
