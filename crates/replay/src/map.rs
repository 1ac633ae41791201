//! The map a replay built, as a saved map (`--save-map`, crate `map-file`).

use std::path::Path;
use std::time::{SystemTime, UNIX_EPOCH};

use map_file::{CommonError, Map, MapLandmark, MapParam};
use rig_model::config::Rig;

use crate::ReplayEnd;

/// The replay's final map (landmarks with their covariance), its calibrated C and V and the
/// rig it ran with, as a [`Map`] stamped with the log's path and the time now.
pub fn saved_map(end: &ReplayEnd, rig: &Rig, log: &Path) -> Map {
    Map {
        landmarks: end
            .landmarks
            .iter()
            .map(|l| MapLandmark {
                id: l.id,
                position: l.position,
                covariance: l.covariance,
                observations: l.observations,
            })
            .collect(),
        parameters: end
            .final_camera
            .iter()
            .map(|p| MapParam {
                param: p.param,
                value: p.value,
                sigma: p.sigma,
            })
            .collect(),
        common_error: end
            .map_common_error
            .map(|(origin, covariance)| CommonError { origin, covariance }),
        rig: Some(rig.clone()),
        source_log: log.display().to_string(),
        source_plan: None,
        created_unix_s: SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .map_or(0, |d| d.as_secs()),
    }
}
