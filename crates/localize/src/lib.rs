//! Localisation on a saved map (issue 20, vehicle-interfaces.md section 5: `stereonav
//! localize`): a forklift that maps its hall once and then works in it, switched on wherever
//! it was parked, pushed while off, under lamps that fail and are replaced.
//!
//! - [`LampMap`]: the map's lamps with their covariance and a uniform grid over the floor, so
//!   that the lamps in view are found in time independent of the map's size.
//! - [`filter::PoseFilter`]: a Schmidt (consider) Kalman filter over the pose and the
//!   vehicle's parameters `V`, the lamps' map uncertainty considered with the cross-covariance
//!   of the lamps recently seen, so that the pose sigma is honest and an update costs the lamps
//!   in view.
//! - [`reloc`]: global relocalisation from the constellation of lamps in view, with
//!   hypotheses scored by their likelihood over odometry and frames and a fix declared only
//!   when one is unique by a margin (a regular grid gives no fix rather than a wrong one).
//! - [`hall`]: the map lamps that should be seen and are not (`lamps_missing`) and the lamps
//!   that are not in the map (candidates triangulated from the localised pose), neither ever
//!   moving the pose.
//! - [`Localizer`]: all of it fed with the board's frames and the odometry in time order;
//!   localised or lost (at the start, after a gap or blind spell, when the lamps stop fitting,
//!   when the pose's sigma grows), relocalising while lost.
//!
//! The camera `C` and the vehicle's `V` come from the map (the mapping run's calibration);
//! `V` is refined by the filter, `C` is held. The association reuses the navigator's front end
//! (lens rectification, left-right matching, tracking) with the map's camera.
//!
//! `#![no_std]` with `alloc`, like the navigator.
#![no_std]
#![forbid(unsafe_code)]
#![deny(missing_docs)]

#[cfg(not(feature = "alloc"))]
compile_error!("the localize crate needs the `alloc` feature (or `std`)");

extern crate alloc;
#[cfg(feature = "std")]
extern crate std;

mod error;
pub mod filter;
pub mod hall;
mod localizer;
mod map;
pub mod reloc;
mod settings;
pub mod view;

pub use error::Error;
pub use hall::NewLamp;
pub use localizer::{FrameResult, Localizer, LocalizerStats, LostReason, Status};
pub use map::{CommonError, LampMap, MapLamp};
pub use settings::{LocalizerSettings, RelocSettings};
