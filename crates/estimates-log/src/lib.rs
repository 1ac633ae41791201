//! `EST.mcap`, the replay's estimates for a viewer (vehicle-interfaces.md section 5): the
//! records a replay produces ([`Replay`], [`FrameEstimate`], ...), their topics and JSON
//! Schemas ([`topics`], the data files `schemas/*.json`), the writer
//! ([`write_estimates`], [`EstimatesWriter`]) and the reader ([`read_estimates`]) side by side,
//! and the summary ([`summary_json`]), which the replay also writes as `SUMMARY.json`.
//!
//! `EST.mcap` is JSON throughout: every channel has message encoding `json` and a schema with
//! encoding `jsonschema`. The trajectory and the map use Foxglove's well-known schemas
//! (`foxglove.PoseInFrame`, `foxglove.PosesInFrame`, `foxglove.SceneUpdate`, encoded as
//! Foxglove's JSON encoding: timestamps `{"sec", "nsec"}`, enums as their integer values), so
//! Foxglove's 3D panel draws them; the filter's own quantities use this project's schemas
//! (`stereonav.CameraEstimate`, `stereonav.FrameInfo`, `stereonav.Summary`), which the Plot and
//! Raw Messages panels read.
//!
//! | topic             | schema                     | messages                                   |
//! |-------------------|----------------------------|--------------------------------------------|
//! | `/est/pose`       | `foxglove.PoseInFrame`     | one per frame                              |
//! | `/est/trajectory` | `foxglove.PosesInFrame`    | the path so far, about once a second       |
//! | `/est/landmarks`  | `foxglove.SceneUpdate`     | one per [`MapSnapshot`]                    |
//! | `/est/camera`     | `stereonav.CameraEstimate` | one per [`CameraSample`]                   |
//! | `/est/frame`      | `stereonav.FrameInfo`      | one per frame                              |
//! | `/est/summary`    | `stereonav.Summary`        | one, at the end ([`summary_json`])         |
//!
//! The channels are added in this order (ids 0 to 5, [`Topic::ALL`]), every one even when it
//! has no message. Log time (and publish time) is the data's `t_us` in nanoseconds; messages
//! are written in data-time order, in zstd chunks of vehicle-log's size.
//!
//! **Numbers that are not finite.** JSON has no NaN or infinity. A non-finite number in this
//! project's messages and in `SUMMARY.json` is written as `null`, which their schemas allow
//! (`"type": ["number", "null"]`): it should not occur (a parameter that is not estimated has
//! sigma 0, not NaN), and if it does a reader sees it rather than a made-up value. Foxglove's
//! schemas allow no `null`, so a frame whose pose is not finite has no `/est/pose` message and
//! is left out of `/est/trajectory` (its `/est/frame` message still says what it was), a
//! landmark whose position is not finite is left out of `/est/landmarks`, and one whose
//! covariance is not finite has no uncertainty ellipsoid. The reader turns `null` back into
//! NaN.
#![forbid(unsafe_code)]
#![deny(missing_docs)]

mod error;
mod reader;
mod summary;
pub mod topics;
mod types;
mod writer;

pub use error::{ReadError, WriteError};
pub use reader::read_estimates;
pub use summary::{end_summary_json, summary_json};
pub use topics::Topic;
pub use types::{
    Association, CameraSample, Consistency, Counts, FrameEstimate, LandmarkEstimate, MapSnapshot,
    OdometryModel, OdometryWidened, ParamEstimate, Phase, Replay, ReplayEnd, TruthErrors,
};
pub use writer::{EstimatesWriter, write_estimates};
