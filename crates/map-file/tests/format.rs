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
        rig,
        source_log: "fixtures/logs/paper-experiment.mcap".to_string(),
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
    let path = std::env::temp_dir().join(format!("map-file-test-{}.map", std::process::id()));
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
    let newer = [b"stereonav-map 2".as_slice(), &bytes[15..]].concat();
    let e = refused(&newer);
    assert!(
        matches!(
            e,
            Error::NewerVersion {
                found: 2,
                supported: 1,
                ..
            }
        ),
        "{e:?}"
    );
    assert!(e.to_string().contains("version 2 is newer"), "{e}");
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
