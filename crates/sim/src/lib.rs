//! A seeded simulator of the vehicle's sensors: ceiling lamps seen by the upward stereo camera
//! of a forklift, its odometry, the camera board's feature stream, and vehicle logs.
//!
//! ```no_run
//! use std::path::Path;
//! let scenario = sim::Scenario::load(Path::new("fixtures/scenarios/paper-square.toml"))?;
//! let run = sim::simulate(&scenario, sim::Mode::Fast)?;
//! println!("{} frames, {} odometry samples", run.frames.len(), run.odometry.len());
//! run.write_log(Path::new("paper-square.mcap"))?;
//! # Ok::<(), sim::Error>(())
//! ```
//!
//! * [`scenario`]: scenario files (TOML): world, path, rates, noise, true `C`, seed, board
//!   registers, clutter, link faults, and the nominal rig file.
//! * [`world`]: point lamps, from lists and jittered grids (a hall of its own seed), panels,
//!   lamps added to a hall and lamps dark in a drive.
//! * [`motion`]: paths of segments with bounded speed and acceleration from a start pose in
//!   the hall, the vehicle carried while the camera is blind, odometry samples
//!   held until the next (vehicle-interfaces.md section 2) with white noise, scale error and
//!   yaw-rate bias; [`integrate`] is the exact integration of one held sample.
//! * [`features`]: the fast mode (project, noise, clutter, Q12.4, the board's order and cap).
//! * [`render`]: the rendered mode's images (lamps as blurred disks over a roof with beams,
//!   sensor noise), for [`harris_core::detect`]; through the rig's real lenses
//!   ([`Renderer::with_lens`]) the raw images each camera's sensor sees.
//! * [`link`]: packets through [`fpga_link::Encoder`], lost packets, bit flips, chunking and
//!   arrival times.
//! * [`run`]: [`simulate`] gives a [`SimRun`] (plain data); [`SimRun::write_log`] writes the
//!   MCAP log through `vehicle-log`, [`SimRun::truth_json`] the ground truth.
//! * [`bag`]: [`write_bag`] simulates the rendered mode into a ROS 2 bag (vehicle-interfaces.md
//!   4.1): both cameras' images (raw, PNG or JPEG; raw through the rig's lenses), the odometry
//!   as `nav_msgs/msg/Odometry`, and the truth, as a robot without the board records them.
//!
//! Determinism: every random draw comes from ChaCha8 streams seeded by the scenario's seed
//! (one stream per purpose, and per frame for the frames' noise), never from the operating
//! system or the time, so the same scenario and seed give the same bytes, whatever the number
//! of threads.
#![forbid(unsafe_code)]
#![deny(missing_docs)]

pub mod bag;
mod error;
pub mod features;
pub mod hall;
pub mod link;
pub mod motion;
pub mod render;
mod rng;
pub mod run;
pub mod scenario;
pub mod world;

pub use bag::{BagImages, write_bag, write_bag_to};
pub use error::{Error, Result};
pub use features::{ImageFeatures, LampView, SimFeature};
pub use link::{Chunk, Packet, PacketFate};
pub use motion::{OdomSample, integrate, integrate_samples, wrap_angle};
pub use render::{Renderer, Side, StereoImages};
pub use run::{FrameTruth, Mode, SimRun, simulate, simulate_with_progress};
pub use scenario::{Scenario, ScenarioSpec};
pub use world::{Lamp, Panel};
