//! Saved maps: what `stereonav replay --save-map MAP` writes and `stereonav localize` reads
//! (vehicle-interfaces.md section 5; the format is docs/maps.md).
//!
//! A map file is one header line and a JSON body:
//!
//! ```text
//! stereonav-map 1 len=<body bytes> crc32=<8 hex digits>\n
//! {"format": "stereonav-map", "version": 1, "created_unix_s": ..., "source_log": "...",
//!  "rig": {...the rig file's JSON form...},
//!  "parameters": [{"name": "f", "value": ..., "sigma": ...}, ...every parameter of C and V],
//!  "landmarks": [{"id": ..., "position": [x, y, z], "covariance": [[...], [...], [...]],
//!                 "observations": ...}, ...]}
//! ```
//!
//! The header says what the file is before anything is parsed: another format is refused by
//! its first bytes, a newer version by its number, a cut or damaged file by the body's length
//! and CRC-32 (IEEE, over the body's bytes). The body is plain JSON so that other tools read it.
//!
//! A map made from a hall's lighting plan (`stereonav map import`, [`Map::from_plan`]) has
//! its lamps only: no calibration, no log, and a rig only when one was given. A map without a
//! rig is written as version 2, which builds that read only version 1 refuse by its number;
//! every other map is written as version 1, which they read ([`Map::format_version`]).
//! Hand-written rather than a serde derive: the messages must name the key that is wrong, and
//! the rig goes in its own JSON form, checked by the rig file's reader.
#![forbid(unsafe_code)]
#![deny(missing_docs)]

mod error;
mod plan;

use std::path::Path;

use rig_model::Param;
use rig_model::config::Rig;
use serde_json::{Map as JsonMap, Value, json};

pub use error::Error;
pub use plan::{DEFAULT_LAMP_SIGMA_M, PlanLamp, PlanProblem, parse_plan};

/// The first word of every map file.
pub const MAGIC: &str = "stereonav-map";
/// The newest format version this build reads. It writes the oldest version that holds the
/// map ([`Map::format_version`]): 2 for a map without a rig, else 1.
pub const VERSION: u32 = 2;

/// The version of a map with a rig: what every build reads.
const VERSION_WITH_RIG: u32 = 1;

/// One landmark (lamp) of a map, in the map's world frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MapLandmark {
    /// Its id (as in the `SUMMARY.json` of the run that made the map).
    pub id: u64,
    /// World position, metres.
    pub position: [f64; 3],
    /// Its 3x3 covariance, row-major, square metres.
    pub covariance: [[f64; 3]; 3],
    /// Updates it took part in.
    pub observations: u64,
}

/// One calibrated parameter of C or V.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MapParam {
    /// The parameter.
    pub param: Param,
    /// Its value.
    pub value: f64,
    /// Its 1-sigma (0 when it was held fixed).
    pub sigma: f64,
}

/// The error the map's landmarks share: a small rigid motion of the whole map (the mapping
/// run's drift of its frame, which every landmark carries), as the covariance of `(tx, ty, tz,
/// yaw)` about a point of the floor plan. A landmark at `p` moves by `A(p) d` for a motion
/// `d`, `A(p) = [[1, 0, 0, -(p.y - o.y)], [0, 1, 0, p.x - o.x], [0, 0, 1, 0]]`; its marginal
/// covariance in [`MapLandmark::covariance`] includes `A C A^T`. A localiser that treats the
/// landmarks' errors as independent must consider this part once, for all of them: it does
/// not average out over the lamps in view.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CommonError {
    /// The point `o` the yaw turns about, `(x, y)`, metres (the landmarks' centroid).
    pub origin: [f64; 2],
    /// Covariance of `(tx, ty, tz, yaw)`, metres and radians.
    pub covariance: [[f64; 4]; 4],
}

/// A saved map: the lamps, the calibration, the rig it was made with, and where it came from.
#[derive(Debug, Clone, PartialEq)]
pub struct Map {
    /// The landmarks.
    pub landmarks: Vec<MapLandmark>,
    /// The calibrated camera and vehicle parameters (every one of [`Param::ALL`]; none in a
    /// map imported from a lighting plan, which has no calibration).
    pub parameters: Vec<MapParam>,
    /// The rig the map was made with (key `rig`; `None` only in a map imported from a
    /// lighting plan without one, written as version 2).
    pub rig: Option<Rig>,
    /// The log the map was made from (as given to the replay); empty for a map imported from
    /// a lighting plan.
    pub source_log: String,
    /// The lighting plan or survey the lamps were imported from (`stereonav map import`), as
    /// given (key `source_plan`, optional: `None` in maps made by a replay).
    pub source_plan: Option<String>,
    /// When the map was written, seconds since the Unix epoch.
    pub created_unix_s: u64,
    /// The error the landmarks share (key `common_error`, optional: `None` in maps written
    /// before it, read as unknown).
    pub common_error: Option<CommonError>,
}

impl Map {
    /// The format version this map is written as: the oldest that holds it, 2 for a map
    /// without a rig (which builds reading up to version 1 could not use), else 1.
    #[must_use]
    pub fn format_version(&self) -> u32 {
        if self.rig.is_some() {
            VERSION_WITH_RIG
        } else {
            VERSION
        }
    }

    /// The file's bytes: the header line, then the JSON body. Refuses non-finite values.
    pub fn to_bytes(&self) -> Result<Vec<u8>, Error> {
        let body = self.body()?;
        let body = serde_json::to_vec_pretty(&body).map_err(|e| Error::Invalid {
            detail: e.to_string(),
        })?;
        let crc = crc32fast::hash(&body);
        let version = self.format_version();
        let mut out =
            format!("{MAGIC} {version} len={} crc32={crc:08x}\n", body.len()).into_bytes();
        out.extend_from_slice(&body);
        Ok(out)
    }

    /// Writes the map to `path`.
    pub fn save(&self, path: &Path) -> Result<(), Error> {
        let bytes = self.to_bytes()?;
        std::fs::write(path, bytes).map_err(|source| Error::Io {
            path: path.to_path_buf(),
            source,
        })
    }

    /// Reads the map at `path`.
    pub fn load(path: &Path) -> Result<Self, Error> {
        let bytes = std::fs::read(path).map_err(|source| Error::Io {
            path: path.to_path_buf(),
            source,
        })?;
        Self::from_bytes(&bytes, &path.display().to_string())
    }

    /// A map from a file's bytes; `source_name` names it in errors.
    pub fn from_bytes(bytes: &[u8], source_name: &str) -> Result<Self, Error> {
        let name = || source_name.to_string();
        let Some(rest) = bytes
            .strip_prefix(MAGIC.as_bytes())
            .and_then(|r| r.strip_prefix(b" "))
        else {
            return Err(Error::NotAMap {
                source_name: name(),
            });
        };
        let newline = rest
            .iter()
            .position(|&b| b == b'\n')
            .ok_or_else(|| bad_header(source_name, "no end of the header line"))?;
        let (header, body) = (&rest[..newline], &rest[newline + 1..]);
        let header = std::str::from_utf8(header)
            .map_err(|_| bad_header(source_name, "the header line is not text"))?;
        let mut words = header.split(' ');
        let version: u32 = words
            .next()
            .and_then(|v| v.parse().ok())
            .ok_or_else(|| bad_header(source_name, "no version number"))?;
        if version > VERSION {
            return Err(Error::NewerVersion {
                source_name: name(),
                found: version,
                supported: VERSION,
            });
        }
        if version == 0 {
            return Err(bad_header(source_name, "version 0"));
        }
        let field = |key: &str| -> Result<&str, Error> {
            header
                .split(' ')
                .find_map(|w| w.strip_prefix(key))
                .ok_or_else(|| bad_header(source_name, &format!("no '{key}'")))
        };
        let expected_len: u64 = field("len=")?
            .parse()
            .map_err(|_| bad_header(source_name, "len= is not a number"))?;
        let expected_crc = u32::from_str_radix(field("crc32=")?, 16)
            .map_err(|_| bad_header(source_name, "crc32= is not 8 hex digits"))?;
        let found_len = body.len() as u64;
        if found_len != expected_len {
            return Err(Error::Length {
                source_name: name(),
                expected: expected_len,
                found: found_len,
            });
        }
        let crc = crc32fast::hash(body);
        if crc != expected_crc {
            return Err(Error::Checksum {
                source_name: name(),
                expected: expected_crc,
                found: crc,
            });
        }
        let value: Value = serde_json::from_slice(body).map_err(|e| Error::Content {
            source_name: name(),
            detail: format!("the body is not JSON: {e}"),
        })?;
        parse_body(&value, version, source_name)
    }

    /// The JSON body (docs/maps.md: the object under the header line) that [`Map::to_bytes`]
    /// writes. Refuses non-finite values. For bindings that hand the map to another language.
    pub fn to_json(&self) -> Result<Value, Error> {
        self.body()
    }

    /// A map from a body already parsed, checked as [`Map::from_bytes`] checks a file's body
    /// (a missing key or a wrong type is refused naming the key; the version is the body's
    /// `version`, the newest read when it has none); `source_name` names it in errors.
    pub fn from_json(body: &Value, source_name: &str) -> Result<Self, Error> {
        let version = body
            .get("version")
            .and_then(Value::as_u64)
            .and_then(|v| u32::try_from(v).ok())
            .unwrap_or(VERSION);
        parse_body(body, version, source_name)
    }

    fn body(&self) -> Result<Value, Error> {
        for l in &self.landmarks {
            let mut values = l.position.iter().chain(l.covariance.iter().flatten());
            if !values.all(|v| v.is_finite()) {
                return Err(Error::Invalid {
                    detail: format!("landmark {} has a non-finite position or covariance", l.id),
                });
            }
        }
        for p in &self.parameters {
            if !(p.value.is_finite() && p.sigma.is_finite()) {
                return Err(Error::Invalid {
                    detail: format!("parameter {} is not finite", p.param),
                });
            }
        }
        if let Some(c) = &self.common_error
            && !c
                .origin
                .iter()
                .chain(c.covariance.iter().flatten())
                .all(|v| v.is_finite())
        {
            return Err(Error::Invalid {
                detail: "the common error is not finite".to_string(),
            });
        }
        let mut body = json!({
            "format": MAGIC,
            "version": self.format_version(),
            "created_unix_s": self.created_unix_s,
            "source_log": self.source_log,
            "parameters": self.parameters.iter().map(|p| json!({
                "name": p.param.name(),
                "value": p.value,
                "sigma": p.sigma,
            })).collect::<Vec<_>>(),
            "landmarks": self.landmarks.iter().map(|l| json!({
                "id": l.id,
                "position": l.position,
                "covariance": l.covariance,
                "observations": l.observations,
            })).collect::<Vec<_>>(),
        });
        let Some(obj) = body.as_object_mut() else {
            return Err(Error::Invalid {
                detail: "the body is not a JSON object".to_string(),
            });
        };
        if let Some(rig) = &self.rig {
            let rig: Value = serde_json::from_str(&rig.to_json()).map_err(|e| Error::Invalid {
                detail: format!("the rig's JSON form: {e}"),
            })?;
            obj.insert("rig".to_string(), rig);
        }
        if let Some(plan) = &self.source_plan {
            obj.insert("source_plan".to_string(), Value::from(plan.as_str()));
        }
        if let Some(c) = &self.common_error {
            obj.insert(
                "common_error".to_string(),
                json!({"origin": c.origin, "covariance": c.covariance}),
            );
        }
        Ok(body)
    }
}

fn bad_header(source_name: &str, detail: &str) -> Error {
    Error::BadHeader {
        source_name: source_name.to_string(),
        detail: detail.to_string(),
    }
}

/// The map of a body of format version `version` (a map without a rig is version 2 or newer).
fn parse_body(value: &Value, version: u32, source_name: &str) -> Result<Map, Error> {
    let content = |detail: String| Error::Content {
        source_name: source_name.to_string(),
        detail,
    };
    let top = value
        .as_object()
        .ok_or_else(|| content("the body is not a JSON object".to_string()))?;
    let key = |obj: &JsonMap<String, Value>, at: &str, k: &str| -> Result<Value, Error> {
        obj.get(k)
            .cloned()
            .ok_or_else(|| content(format!("{at}missing key '{k}'")))
    };
    if key(top, "", "format")?.as_str() != Some(MAGIC) {
        return Err(content(format!("'format' is not \"{MAGIC}\"")));
    }
    let u64_of = |v: &Value, what: &str| -> Result<u64, Error> {
        v.as_u64()
            .ok_or_else(|| content(format!("{what} is not a non-negative integer")))
    };
    let f64_of = |v: &Value, what: &str| -> Result<f64, Error> {
        v.as_f64()
            .filter(|x| x.is_finite())
            .ok_or_else(|| content(format!("{what} is not a finite number")))
    };
    let array_of = |v: Value, what: &str| -> Result<Vec<Value>, Error> {
        match v {
            Value::Array(a) => Ok(a),
            _ => Err(content(format!("{what} is not an array"))),
        }
    };
    let created_unix_s = u64_of(&key(top, "", "created_unix_s")?, "'created_unix_s'")?;
    let source_log = key(top, "", "source_log")?
        .as_str()
        .ok_or_else(|| content("'source_log' is not a string".to_string()))?
        .to_string();
    let rig = match top.get("rig") {
        // Only a map without a rig is written as version 2: one of version 1 must have it.
        None | Some(Value::Null) if version >= 2 => None,
        _ => Some(
            Rig::from_json_str(
                &key(top, "", "rig")?.to_string(),
                &format!("{source_name} rig"),
            )
            .map_err(|e| content(format!("the map's rig: {e}")))?,
        ),
    };
    let source_plan = match top.get("source_plan") {
        None | Some(Value::Null) => None,
        Some(v) => Some(
            v.as_str()
                .ok_or_else(|| content("'source_plan' is not a string".to_string()))?
                .to_string(),
        ),
    };

    let mut parameters = Vec::new();
    for (i, p) in array_of(key(top, "", "parameters")?, "'parameters'")?
        .iter()
        .enumerate()
    {
        let at = format!("parameters[{i}]: ");
        let obj = p
            .as_object()
            .ok_or_else(|| content(format!("{at}not an object")))?;
        let name = key(obj, &at, "name")?;
        let param = name
            .as_str()
            .and_then(Param::from_name)
            .ok_or_else(|| content(format!("{at}unknown parameter {name}")))?;
        parameters.push(MapParam {
            param,
            value: f64_of(&key(obj, &at, "value")?, &format!("{at}'value'"))?,
            sigma: f64_of(&key(obj, &at, "sigma")?, &format!("{at}'sigma'"))?,
        });
    }

    let mut landmarks = Vec::new();
    for (i, l) in array_of(key(top, "", "landmarks")?, "'landmarks'")?
        .into_iter()
        .enumerate()
    {
        let at = format!("landmarks[{i}]: ");
        let obj = l
            .as_object()
            .ok_or_else(|| content(format!("{at}not an object")))?;
        let position = array_of(key(obj, &at, "position")?, &format!("{at}'position'"))?;
        let rows = array_of(key(obj, &at, "covariance")?, &format!("{at}'covariance'"))?;
        if position.len() != 3 || rows.len() != 3 {
            return Err(content(format!(
                "{at}'position' must hold 3 numbers and 'covariance' 3 rows"
            )));
        }
        let mut p = [0.0; 3];
        for (a, v) in p.iter_mut().zip(&position) {
            *a = f64_of(v, &format!("{at}'position'"))?;
        }
        let mut c = [[0.0; 3]; 3];
        for (row, v) in c.iter_mut().zip(rows) {
            let v = array_of(v, &format!("{at}'covariance' row"))?;
            if v.len() != 3 {
                return Err(content(format!(
                    "{at}a 'covariance' row must hold 3 numbers"
                )));
            }
            for (a, x) in row.iter_mut().zip(&v) {
                *a = f64_of(x, &format!("{at}'covariance'"))?;
            }
        }
        landmarks.push(MapLandmark {
            id: u64_of(&key(obj, &at, "id")?, &format!("{at}'id'"))?,
            position: p,
            covariance: c,
            observations: u64_of(
                &key(obj, &at, "observations")?,
                &format!("{at}'observations'"),
            )?,
        });
    }
    let common_error = match top.get("common_error") {
        None | Some(Value::Null) => None,
        Some(v) => {
            let at = "common_error: ";
            let obj = v
                .as_object()
                .ok_or_else(|| content(format!("{at}not an object")))?;
            let origin = array_of(key(obj, at, "origin")?, &format!("{at}'origin'"))?;
            let rows = array_of(key(obj, at, "covariance")?, &format!("{at}'covariance'"))?;
            if origin.len() != 2 || rows.len() != 4 {
                return Err(content(format!(
                    "{at}'origin' must hold 2 numbers and 'covariance' 4 rows"
                )));
            }
            let mut o = [0.0; 2];
            for (a, x) in o.iter_mut().zip(&origin) {
                *a = f64_of(x, &format!("{at}'origin'"))?;
            }
            let mut c = [[0.0; 4]; 4];
            for (row, v) in c.iter_mut().zip(rows) {
                let v = array_of(v, &format!("{at}'covariance' row"))?;
                if v.len() != 4 {
                    return Err(content(format!(
                        "{at}a 'covariance' row must hold 4 numbers"
                    )));
                }
                for (a, x) in row.iter_mut().zip(&v) {
                    *a = f64_of(x, &format!("{at}'covariance'"))?;
                }
            }
            Some(CommonError {
                origin: o,
                covariance: c,
            })
        }
    };
    Ok(Map {
        common_error,
        landmarks,
        parameters,
        rig,
        source_log,
        source_plan,
        created_unix_s,
    })
}
