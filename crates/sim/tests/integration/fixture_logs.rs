//! The logs committed in `fixtures/logs/` hold what the simulator makes of their scenarios
//! today (regenerate them as fixtures/README.md says when this fails).
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failure is the test failing

use crate::common;

use std::path::Path;

use vehicle_log::Record;

#[test]
fn committed_logs_match_their_scenarios() {
    let logs = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/logs");
    for name in ["paper-calibration", "paper-square", "paper-experiment"] {
        let scenario = common::load(name);
        let run = sim::simulate(&scenario, sim::Mode::Fast).unwrap();
        let log = vehicle_log::read_log(logs.join(format!("{name}.mcap"))).unwrap();
        assert!(log.truncated.is_none(), "{name}");
        let (mut odom, mut chunks, mut poses, mut rig) = (Vec::new(), Vec::new(), Vec::new(), None);
        for r in log.records {
            match r {
                Record::Odom(o) => odom.push(o),
                Record::Features { log_time_ns, bytes } => chunks.push((log_time_ns, bytes)),
                Record::TruthPose(p) => poses.push(p),
                Record::Rig(text) => rig = Some(text),
                _ => {}
            }
        }
        let stale =
            format!("fixtures/logs/{name}.mcap is stale: regenerate it (fixtures/README.md)");
        assert_eq!(odom, run.odometry, "{stale}");
        let expected: Vec<(u64, Vec<u8>)> = run
            .chunks
            .iter()
            .map(|c| (c.log_time_ns, c.bytes.clone()))
            .collect();
        assert!(chunks == expected, "{stale}");
        assert_eq!(poses, run.truth_poses(), "{stale}");
        assert_eq!(rig, Some(scenario.rig.to_json()), "{stale}");
        let rig_file = std::fs::read_to_string(logs.join(format!("{name}.rig.toml"))).unwrap();
        assert_eq!(rig_file, scenario.rig_text, "{stale}");
    }
}
