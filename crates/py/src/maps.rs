//! Saved maps for Python (docs/maps.md): read and written by crate `map-file`, so that a map
//! file is checked the same way here as by `stereonav localize`.
//!
//! The body crosses the boundary as JSON text: `read_map` hands back the body of a file that
//! passed every check of `map_file::Map::load` (header, version, length, CRC-32, keys and
//! types), `write_map` takes a body, checks it as a file's body is checked and writes it with
//! its header. `serde_json`'s `float_roundtrip` and Python's `json` both read the shortest
//! representation back to the same float, so a map read and written again is the same file,
//! byte for byte.
//!
//! `import_map` is `stereonav map import`: a map from a hall's lighting plan (a CSV file), read
//! by the same code as the command line (`map_file::Map::import_plan`), written as it writes
//! it; a plan that cannot make a map raises `stereonav.InputError` with the command line's
//! one-line message (the file, the line and the problem).
//!
//! A body that cannot make a map (a missing key, a wrong type, a key the format does not have,
//! another version) raises `stereonav.InputError` naming the key; a file that cannot be read or
//! written raises it naming the file, with the `OSError` as its `__cause__`. The file is read
//! and written with the GIL released.

use std::path::PathBuf;

use map_file::Map;
use pyo3::prelude::*;
use serde_json::Value;

use crate::calibration::file_error;
use crate::input_error;
use crate::rig::PyRig;

/// How a body given by the caller is named in messages (`map: missing key 'landmarks'`).
const GIVEN_MAP: &str = "map";

/// The JSON body of the map file at `path` (the table of docs/maps.md), after every check of
/// `map_file::Map::load`. Raises `stereonav.InputError` naming the file and the problem (not a
/// map, a newer version, cut or damaged, a missing key or wrong type; the `OSError` as
/// `__cause__` when the system refused the file). The GIL is released.
#[pyfunction]
pub(crate) fn read_map(py: Python<'_>, path: PathBuf) -> PyResult<String> {
    py.detach(|| -> Result<String, map_file::Error> {
        let map = Map::load(&path)?;
        Ok(map.to_json()?.to_string())
    })
    .map_err(|e| file_error(py, &e))
}

/// The map of the lighting plan (CSV) at `csv_path`, as `stereonav map import` makes it:
/// `sigma` the 1-sigma position of a lamp whose row gives none (metres), `rig` carried in the
/// map when given. Written to `out_path` unless None; returns the map's JSON body. Raises
/// `stereonav.InputError` naming the file, the line and the problem (the `OSError` as
/// `__cause__` when the system refused a file). The GIL is released.
#[pyfunction]
#[pyo3(signature = (csv_path, out_path, sigma, rig))]
pub(crate) fn import_map(
    py: Python<'_>,
    csv_path: PathBuf,
    out_path: Option<PathBuf>,
    sigma: f64,
    rig: Option<PyRef<'_, PyRig>>,
) -> PyResult<String> {
    let rig = rig.map(|r| r.rig.clone());
    py.detach(|| -> Result<String, map_file::Error> {
        let map = Map::import_plan(&csv_path, sigma, rig)?;
        if let Some(path) = &out_path {
            map.save(path)?;
        }
        Ok(map.to_json()?.to_string())
    })
    .map_err(|e| file_error(py, &e))
}

/// Writes the map whose JSON body is `body` to `path`, as `stereonav replay --save-map` writes
/// one. The body is checked first, as a file's body is (`map_file::Map::from_json`), and must
/// have the `version` the map is written as (`map_file::Map::format_version`: 1, or 2 for a
/// map without a rig) and no key the format does not have (it would be lost).
/// Raises `stereonav.InputError` naming the key, or the file when it cannot be written. The
/// GIL is released while the file is written.
#[pyfunction]
pub(crate) fn write_map(py: Python<'_>, body: &str, path: PathBuf) -> PyResult<()> {
    let map = map_from_body(body).map_err(|m| input_error(py, m))?;
    py.detach(|| map.save(&path))
        .map_err(|e| file_error(py, &e))
}

/// The map of a body given as JSON text, or why not (one line, naming the key).
fn map_from_body(body: &str) -> Result<Map, String> {
    let given: Value = serde_json::from_str(body)
        .map_err(|e| format!("{GIVEN_MAP}: the body is not JSON: {e}"))?;
    let map = Map::from_json(&given, GIVEN_MAP).map_err(|e| e.to_string())?;
    // The version the map is written as (1, or 2 without a rig): a dict that says another
    // would not be saved as it says.
    let version = map.format_version();
    match given.get("version") {
        None => return Err(format!("{GIVEN_MAP}: missing key 'version'")),
        Some(v) if v.as_u64() != Some(u64::from(version)) => {
            return Err(format!(
                "{GIVEN_MAP}: 'version' is {v}, this stereonav writes {} as map format version {version}",
                if map.rig.is_some() {
                    "a map with a rig"
                } else {
                    "a map without a rig"
                }
            ));
        }
        Some(_) => {}
    }
    let kept = map.to_json().map_err(|e| e.to_string())?;
    if let Some(unknown) = unknown_key(&given, &kept, "") {
        return Err(format!(
            "{GIVEN_MAP}: {unknown}: the map format has no such key (it would not be saved)"
        ));
    }
    Ok(map)
}

/// The first key of `given` (a body, or an object or array in it at `at`) that the map made of
/// it does not keep (`kept`, that map's body), as `landmarks[2]: unknown key 'note'`. The rig
/// is left to its own reader, which refuses unknown keys itself.
fn unknown_key(given: &Value, kept: &Value, at: &str) -> Option<String> {
    let inside = |k: &str| {
        if at.is_empty() {
            k.to_string()
        } else {
            format!("{at}.{k}")
        }
    };
    match (given, kept) {
        (Value::Object(given), Value::Object(kept)) => {
            given.iter().find_map(|(k, v)| match kept.get(k) {
                // An optional key given as None (`rig`, `common_error`): absent, as read.
                None if v.is_null() => None,
                None if at.is_empty() => Some(format!("unknown key '{k}'")),
                None => Some(format!("{at}: unknown key '{k}'")),
                Some(_) if at.is_empty() && k == "rig" => None,
                Some(w) => unknown_key(v, w, &inside(k)),
            })
        }
        (Value::Array(given), Value::Array(kept)) => given
            .iter()
            .zip(kept)
            .enumerate()
            .find_map(|(i, (v, w))| unknown_key(v, w, &format!("{at}[{i}]"))),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    fn body() -> Value {
        let rig = rig_model::config::Rig::load(
            &Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("../../fixtures/logs/paper-experiment.rig.toml"),
        )
        .expect("the fixture rig");
        let map = Map {
            landmarks: vec![map_file::MapLandmark {
                id: 3,
                position: [0.1, -1.0 / 3.0, 2.5],
                covariance: [[1e-6, 0.0, 0.0], [0.0, 2e-6, 0.0], [0.0, 0.0, 3e-6]],
                observations: 7,
            }],
            parameters: vec![],
            rig: Some(rig),
            source_log: "a.mcap".to_string(),
            source_plan: None,
            created_unix_s: 1,
            common_error: Some(map_file::CommonError {
                origin: [0.5, 0.25],
                covariance: [
                    [1e-6, 0.0, 0.0, 0.0],
                    [0.0, 1e-6, 0.0, 0.0],
                    [0.0, 0.0, 1e-6, 0.0],
                    [0.0, 0.0, 0.0, 1e-8],
                ],
            }),
        };
        map.to_json().expect("finite")
    }

    #[test]
    fn a_body_makes_its_map_and_nothing_is_lost() {
        let given = body();
        let map = map_from_body(&given.to_string()).expect("a good body");
        assert_eq!(map.to_json().expect("finite"), given);
    }

    #[test]
    fn bad_bodies_name_the_key() {
        let refused = |edit: &dyn Fn(&mut Value)| {
            let mut b = body();
            edit(&mut b);
            map_from_body(&b.to_string()).expect_err("refused")
        };
        assert_eq!(
            refused(&|b| {
                b.as_object_mut().map(|o| o.remove("landmarks"));
            }),
            "map: missing key 'landmarks'"
        );
        assert_eq!(
            refused(&|b| b["landmarks"][0]["id"] = Value::from("three")),
            "map: landmarks[0]: 'id' is not a non-negative integer"
        );
        assert_eq!(
            refused(&|b| {
                b.as_object_mut().map(|o| o.remove("version"));
            }),
            "map: missing key 'version'"
        );
        assert_eq!(
            refused(&|b| b["version"] = Value::from(2)),
            "map: 'version' is 2, this stereonav writes a map with a rig as map format version 1"
        );
        // Without a rig, version 1 is refused by the reader (its rig is required).
        assert_eq!(
            refused(&|b| {
                b.as_object_mut().map(|o| o.remove("rig"));
            }),
            "map: missing key 'rig'"
        );
        assert_eq!(
            refused(&|b| b["notes"] = Value::from("x")),
            "map: unknown key 'notes': the map format has no such key (it would not be saved)"
        );
        assert_eq!(
            refused(&|b| b["landmarks"][0]["colour"] = Value::from("x")),
            "map: landmarks[0]: unknown key 'colour': the map format has no such key (it would \
             not be saved)"
        );
        assert!(
            map_from_body("[1")
                .expect_err("not JSON")
                .starts_with("map: the body is not JSON")
        );
    }
}
