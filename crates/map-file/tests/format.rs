//! The map format: a round trip, and every kind of bad file refused with its one-line reason.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::Path;

use map_file::{CommonError, Error, Map, MapLandmark, MapParam};
use rig_model::Param;
use rig_model::config::Rig;

fn map() -> Map {
    let rig_path =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/logs/paper-experiment.rig.toml");
    let rig = Rig::load(&rig_path).unwrap();
    Map {
        landmarks: (0..5)
            .map(|i| MapLandmark {
                id: 10 + i,
                position: [0.1 * i as f64, -1.0 / 3.0, 2.5],
                covariance: [[1e-6, 1e-8, 0.0], [1e-8, 2e-6, 0.0], [0.0, 0.0, 4e-6]],
                observations: 100 + i,
            })
            .collect(),
        parameters: Param::ALL
            .iter()
            .map(|&param| MapParam {
                param,
                value: rig.nominal.get(param) + 1e-3,
                sigma: 1e-4,
            })
            .collect(),
        rig: Some(rig),
        source_log: "fixtures/logs/paper-experiment.mcap".to_string(),
        source_plan: None,
        created_unix_s: 1_796_000_000,
        common_error: Some(CommonError {
            origin: [0.2, -1.0 / 3.0],
            covariance: std::array::from_fn(|r| {
                std::array::from_fn(|c| if r == c { 1e-5 / 3.0 } else { 1e-7 })
            }),
        }),
    }
}

/// A map written before the common error (no `common_error` key) still reads.
#[test]
fn a_map_without_the_common_error_reads() {
    let m = Map {
        common_error: None,
        ..map()
    };
    let back = Map::from_bytes(&m.to_bytes().unwrap(), "old.map").unwrap();
    assert_eq!(back, m);
}

#[test]
fn a_map_reads_back_as_written_bit_for_bit() {
    let m = map();
    let bytes = m.to_bytes().unwrap();
    assert!(bytes.starts_with(b"stereonav-map 1 len="));
    let back = Map::from_bytes(&bytes, "m.map").unwrap();
    assert_eq!(back, m);
    // And through a file.
    let path = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("map-file-test-{}.map", std::process::id()));
    m.save(&path).unwrap();
    assert_eq!(Map::load(&path).unwrap(), m);
    std::fs::remove_file(&path).ok();
}

#[test]
fn the_json_body_reads_back_as_the_map() {
    let m = map();
    let body = m.to_json().unwrap();
    assert_eq!(Map::from_json(&body, "m").unwrap(), m);
    let bytes = m.to_bytes().unwrap();
    let text = bytes.splitn(2, |&b| b == b'\n').nth(1).unwrap();
    assert_eq!(
        serde_json::from_slice::<serde_json::Value>(text).unwrap(),
        body
    );
    let mut missing = body.clone();
    missing.as_object_mut().unwrap().remove("landmarks");
    let e = Map::from_json(&missing, "m").expect_err("no landmarks");
    assert_eq!(e.to_string(), "m: missing key 'landmarks'");
}

fn refused(bytes: &[u8]) -> Error {
    Map::from_bytes(bytes, "m.map").expect_err("refused")
}

#[test]
fn a_foreign_file_is_not_a_map() {
    let mcap = std::fs::read(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/logs/paper-square.mcap"),
    )
    .unwrap();
    for bytes in [
        &mcap[..],
        b"",
        b"{\"format\": \"stereonav-map\"}",
        b"stereonav-mapX 1",
    ] {
        let e = refused(bytes);
        assert!(matches!(e, Error::NotAMap { .. }), "{e:?}");
        assert_eq!(
            e.to_string(),
            "m.map: not a stereonav map (no 'stereonav-map' header line)"
        );
    }
}

#[test]
fn a_newer_version_is_refused_by_its_number() {
    let bytes = map().to_bytes().unwrap();
    let newer = [b"stereonav-map 3".as_slice(), &bytes[15..]].concat();
    let e = refused(&newer);
    assert!(
        matches!(
            e,
            Error::NewerVersion {
                found: 3,
                supported: 2,
                ..
            }
        ),
        "{e:?}"
    );
    assert!(e.to_string().contains("version 3 is newer"), "{e}");
}

#[test]
fn damaged_or_cut_files_are_refused() {
    let bytes = map().to_bytes().unwrap();
    let header_len = bytes.iter().position(|&b| b == b'\n').unwrap() + 1;
    // Every single-bit flip in the body is caught by the CRC (or the length, never parsed).
    for i in (header_len..bytes.len()).step_by(97) {
        let mut bad = bytes.clone();
        bad[i] ^= 0x10;
        let e = refused(&bad);
        assert!(matches!(e, Error::Checksum { .. }), "byte {i}: {e:?}");
        assert!(e.to_string().contains("damaged"), "{e}");
    }
    let e = refused(&bytes[..bytes.len() - 10]);
    assert!(matches!(e, Error::Length { .. }), "{e:?}");
    let e = refused(&bytes[..header_len - 1]);
    assert!(matches!(e, Error::BadHeader { .. }), "{e:?}");
    let mut longer = bytes.clone();
    longer.extend_from_slice(b"\n");
    assert!(matches!(refused(&longer), Error::Length { .. }));
}

/// A file written by another tool with the right header and CRC but a wrong body.
fn with_body(body: &str) -> Vec<u8> {
    let crc = crc32fast::hash(body.as_bytes());
    format!("stereonav-map 1 len={} crc32={crc:08x}\n{body}", body.len()).into_bytes()
}

#[test]
fn a_body_with_a_missing_key_or_a_wrong_type_names_it() {
    let bytes = map().to_bytes().unwrap();
    let body_start = bytes.iter().position(|&b| b == b'\n').unwrap() + 1;
    let good: serde_json::Value = serde_json::from_slice(&bytes[body_start..]).unwrap();
    let mut no_landmarks = good.clone();
    no_landmarks.as_object_mut().unwrap().remove("landmarks");
    let e = refused(&with_body(&no_landmarks.to_string()));
    assert!(e.to_string().contains("missing key 'landmarks'"), "{e}");

    let mut bad_id = good.clone();
    bad_id["landmarks"][2]["id"] = serde_json::json!("seven");
    let e = refused(&with_body(&bad_id.to_string()));
    assert!(e.to_string().contains("landmarks[2]: 'id'"), "{e}");

    let mut bad_param = good.clone();
    bad_param["parameters"][0]["name"] = serde_json::json!("zoom");
    let e = refused(&with_body(&bad_param.to_string()));
    assert!(e.to_string().contains("unknown parameter"), "{e}");

    let e = refused(&with_body("[1, 2]"));
    assert!(e.to_string().contains("not a JSON object"), "{e}");
    let e = refused(&with_body("{not json"));
    assert!(e.to_string().contains("not JSON"), "{e}");
}

#[test]
fn non_finite_values_are_not_written() {
    let mut m = map();
    m.landmarks[1].covariance[0][0] = f64::NAN;
    let e = m.to_bytes().expect_err("NaN refused");
    assert!(e.to_string().contains("landmark 11"), "{e}");
}

/// A map imported from a lighting plan without a rig: written as version 2 (builds that read
/// up to version 1 refuse it by its number), read back as written; with a rig, or with the
/// plan's name alone (a key older builds skip), a map stays version 1.
#[test]
fn a_map_without_a_rig_is_version_2_and_reads_back() {
    let plan = Map::from_plan(
        b"id,x,y,z,sigma\n4,1.5,-2,7,0.01\n9,5.5,-2,7.1,0.03\n",
        "hall.csv",
        0.02,
        None,
    )
    .unwrap();
    assert_eq!(plan.format_version(), 2);
    let bytes = plan.to_bytes().unwrap();
    assert!(bytes.starts_with(b"stereonav-map 2 len="));
    let back = Map::from_bytes(&bytes, "hall.map").unwrap();
    assert_eq!(back, plan);
    let body = back.to_json().unwrap();
    assert_eq!(body["version"], 2);
    assert_eq!(body["source_plan"], "hall.csv");
    assert_eq!(body["source_log"], "");
    assert!(body.get("rig").is_none());
    assert_eq!(Map::from_json(&body, "m").unwrap(), plan);

    // With a rig: version 1, and `source_plan` kept.
    let with_rig = Map {
        rig: map().rig,
        ..plan.clone()
    };
    let bytes = with_rig.to_bytes().unwrap();
    assert!(bytes.starts_with(b"stereonav-map 1 len="));
    assert_eq!(Map::from_bytes(&bytes, "m.map").unwrap(), with_rig);
    let replayed = Map {
        source_plan: Some("plan.csv".to_string()),
        ..map()
    };
    assert_eq!(replayed.format_version(), 1);
    assert_eq!(
        Map::from_bytes(&replayed.to_bytes().unwrap(), "m.map").unwrap(),
        replayed
    );
}

/// A map of version 1 must have its rig: only version 2 may leave it out.
#[test]
fn a_version_1_map_without_a_rig_is_refused() {
    let mut body = map().to_json().unwrap();
    body.as_object_mut().unwrap().remove("rig");
    let e = refused(&with_body(&body.to_string()));
    assert_eq!(e.to_string(), "m.map: missing key 'rig'");
    let e = Map::from_json(&body, "m").expect_err("version 1 without a rig");
    assert_eq!(e.to_string(), "m: missing key 'rig'");
    body["source_plan"] = serde_json::json!(3);
    body["version"] = serde_json::json!(2);
    let e = Map::from_json(&body, "m").expect_err("a bad source_plan");
    assert_eq!(e.to_string(), "m: 'source_plan' is not a string");
}
