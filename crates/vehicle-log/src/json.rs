//! The JSON topics' messages, both ways, with errors that name the key and the value.

use serde::Serialize;
use serde_json::{Map, Value};

use crate::error::Problem;
use crate::types::{OdomSample, TruthCamera, TruthLandmark, TruthPose};

/// Longest rendering of a wrong value in an error message, in characters.
const MAX_SHOWN_VALUE_CHARS: usize = 40;

type Object = Map<String, Value>;

/// Parses `bytes` as a JSON object.
pub(crate) fn object(bytes: &[u8]) -> Result<Object, Problem> {
    match serde_json::from_slice::<Value>(bytes) {
        Ok(Value::Object(map)) => Ok(map),
        Ok(other) => Err(Problem::NotObject {
            found: kind(&other),
        }),
        Err(err) => Err(Problem::NotJson {
            detail: err.to_string(),
        }),
    }
}

/// The kind of a JSON value, for messages.
fn kind(value: &Value) -> &'static str {
    match value {
        Value::Null => "null",
        Value::Bool(_) => "a boolean",
        Value::Number(n) if n.is_f64() => "a float",
        Value::Number(_) => "an integer",
        Value::String(_) => "a string",
        Value::Array(_) => "an array",
        Value::Object(_) => "an object",
    }
}

/// A value as JSON, shortened, for messages.
fn shown(value: &Value) -> String {
    let text = value.to_string();
    if text.chars().count() <= MAX_SHOWN_VALUE_CHARS {
        text
    } else {
        let mut short: String = text.chars().take(MAX_SHOWN_VALUE_CHARS).collect();
        short.push_str("...");
        short
    }
}

/// The key path `prefix.key` (or `key` alone).
fn path(prefix: &str, key: &str) -> String {
    if prefix.is_empty() {
        key.to_owned()
    } else {
        format!("{prefix}.{key}")
    }
}

fn field<'a>(obj: &'a Object, prefix: &str, key: &str) -> Result<&'a Value, Problem> {
    obj.get(key).ok_or_else(|| Problem::MissingKey {
        key: path(prefix, key),
    })
}

/// A non-negative integer (a float such as `1.0` or `1e6` is refused: it is not an integer).
fn u64_field(obj: &Object, prefix: &str, key: &str) -> Result<u64, Problem> {
    let value = field(obj, prefix, key)?;
    value.as_u64().ok_or_else(|| Problem::WrongType {
        key: path(prefix, key),
        expected: "a non-negative integer",
        found: shown(value),
    })
}

fn u32_field(obj: &Object, prefix: &str, key: &str) -> Result<u32, Problem> {
    let value = field(obj, prefix, key)?;
    value
        .as_u64()
        .and_then(|v| u32::try_from(v).ok())
        .ok_or_else(|| Problem::WrongType {
            key: path(prefix, key),
            expected: "an integer from 0 to 4294967295",
            found: shown(value),
        })
}

/// Any JSON number (an integer such as `0` is a valid float).
fn f64_field(obj: &Object, prefix: &str, key: &str) -> Result<f64, Problem> {
    let value = field(obj, prefix, key)?;
    match value {
        Value::Number(n) => n.as_f64().ok_or_else(|| Problem::WrongType {
            key: path(prefix, key),
            expected: "a number",
            found: shown(value),
        }),
        _ => Err(Problem::WrongType {
            key: path(prefix, key),
            expected: "a number",
            found: shown(value),
        }),
    }
}

/// Refuses NaN and infinities, which JSON cannot carry (serde_json would write `null`).
fn finite(key: &str, value: f64) -> Result<(), Problem> {
    if value.is_finite() {
        Ok(())
    } else {
        Err(Problem::NotFinite {
            key: key.to_owned(),
            value,
        })
    }
}

fn to_json<T: Serialize>(value: &T) -> Result<Vec<u8>, Problem> {
    // Serializing plain structs of integers and finite floats cannot fail; map it anyway.
    serde_json::to_vec(value).map_err(|err| Problem::NotJson {
        detail: err.to_string(),
    })
}

pub(crate) fn decode_odom(bytes: &[u8]) -> Result<OdomSample, Problem> {
    let obj = object(bytes)?;
    Ok(OdomSample {
        t_us: u64_field(&obj, "", "t_us")?,
        vx: f64_field(&obj, "", "vx")?,
        vy: f64_field(&obj, "", "vy")?,
        vtheta: f64_field(&obj, "", "vtheta")?,
    })
}

pub(crate) fn encode_odom(sample: &OdomSample) -> Result<Vec<u8>, Problem> {
    finite("vx", sample.vx)?;
    finite("vy", sample.vy)?;
    finite("vtheta", sample.vtheta)?;
    to_json(sample)
}

pub(crate) fn decode_truth_pose(bytes: &[u8]) -> Result<TruthPose, Problem> {
    let obj = object(bytes)?;
    Ok(TruthPose {
        t_us: u64_field(&obj, "", "t_us")?,
        x: f64_field(&obj, "", "x")?,
        y: f64_field(&obj, "", "y")?,
        theta: f64_field(&obj, "", "theta")?,
    })
}

pub(crate) fn encode_truth_pose(pose: &TruthPose) -> Result<Vec<u8>, Problem> {
    finite("x", pose.x)?;
    finite("y", pose.y)?;
    finite("theta", pose.theta)?;
    to_json(pose)
}

pub(crate) fn decode_truth_landmarks(bytes: &[u8]) -> Result<Vec<TruthLandmark>, Problem> {
    let obj = object(bytes)?;
    let list = field(&obj, "", "landmarks")?;
    let Value::Array(items) = list else {
        return Err(Problem::WrongType {
            key: "landmarks".to_owned(),
            expected: "an array",
            found: shown(list),
        });
    };
    let mut landmarks = Vec::with_capacity(items.len());
    for (i, item) in items.iter().enumerate() {
        let prefix = format!("landmarks[{i}]");
        let Value::Object(lm) = item else {
            return Err(Problem::WrongType {
                key: prefix,
                expected: "an object",
                found: shown(item),
            });
        };
        landmarks.push(TruthLandmark {
            id: u32_field(lm, &prefix, "id")?,
            x: f64_field(lm, &prefix, "x")?,
            y: f64_field(lm, &prefix, "y")?,
            z: f64_field(lm, &prefix, "z")?,
        });
    }
    Ok(landmarks)
}

pub(crate) fn encode_truth_landmarks(landmarks: &[TruthLandmark]) -> Result<Vec<u8>, Problem> {
    #[derive(Serialize)]
    struct Message<'a> {
        landmarks: &'a [TruthLandmark],
    }
    for (i, lm) in landmarks.iter().enumerate() {
        for (key, value) in [("x", lm.x), ("y", lm.y), ("z", lm.z)] {
            finite(&format!("landmarks[{i}].{key}"), value)?;
        }
    }
    to_json(&Message { landmarks })
}

pub(crate) fn decode_truth_camera(bytes: &[u8]) -> Result<TruthCamera, Problem> {
    let obj = object(bytes)?;
    let f = |key| f64_field(&obj, "", key);
    // V is optional: nominal when a simulator does not model it.
    let v = |key, nominal: f64| {
        if obj.contains_key(key) {
            f(key)
        } else {
            Ok(nominal)
        }
    };
    Ok(TruthCamera {
        odom_scale: v("odom_scale", 1.0)?,
        odom_yaw_scale: v("odom_yaw_scale", 1.0)?,
        odom_yaw_bias: v("odom_yaw_bias", 0.0)?,
        time_offset: v("time_offset", 0.0)?,
        f: f("f")?,
        cx: f("cx")?,
        cy: f("cy")?,
        baseline: f("baseline")?,
        mount_x: f("mount_x")?,
        mount_y: f("mount_y")?,
        mount_z: f("mount_z")?,
        mount_roll: f("mount_roll")?,
        mount_pitch: f("mount_pitch")?,
        mount_yaw: f("mount_yaw")?,
    })
}

pub(crate) fn encode_truth_camera(camera: &TruthCamera) -> Result<Vec<u8>, Problem> {
    for (key, value) in [
        ("f", camera.f),
        ("cx", camera.cx),
        ("cy", camera.cy),
        ("baseline", camera.baseline),
        ("mount_x", camera.mount_x),
        ("mount_y", camera.mount_y),
        ("mount_z", camera.mount_z),
        ("mount_roll", camera.mount_roll),
        ("mount_pitch", camera.mount_pitch),
        ("mount_yaw", camera.mount_yaw),
        ("odom_scale", camera.odom_scale),
        ("odom_yaw_scale", camera.odom_yaw_scale),
        ("odom_yaw_bias", camera.odom_yaw_bias),
        ("time_offset", camera.time_offset),
    ] {
        finite(key, value)?;
    }
    to_json(camera)
}

/// The rig message: any JSON object, kept as the text it was.
pub(crate) fn decode_rig(bytes: &[u8]) -> Result<String, Problem> {
    object(bytes)?;
    // Valid JSON is valid UTF-8 (serde_json checks strings; everything else is ASCII).
    String::from_utf8(bytes.to_vec()).map_err(|err| Problem::NotJson {
        detail: err.to_string(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::topics;

    #[test]
    fn schemas_are_json_and_require_what_the_decoders_read() {
        let cases: [(&str, &[&str]); 4] = [
            (topics::ODOMETRY_SCHEMA, &["t_us", "vx", "vy", "vtheta"]),
            (topics::TRUTH_POSE_SCHEMA, &["t_us", "x", "y", "theta"]),
            (topics::TRUTH_LANDMARKS_SCHEMA, &["landmarks"]),
            (
                topics::TRUTH_CAMERA_SCHEMA,
                &[
                    "f",
                    "cx",
                    "cy",
                    "baseline",
                    "mount_x",
                    "mount_y",
                    "mount_z",
                    "mount_roll",
                    "mount_pitch",
                    "mount_yaw",
                ],
            ),
        ];
        for (schema, keys) in cases {
            let value: Value = serde_json::from_str(schema).unwrap();
            let required: Vec<&str> = value["required"]
                .as_array()
                .unwrap()
                .iter()
                .map(|v| v.as_str().unwrap())
                .collect();
            assert_eq!(required, keys);
            for key in keys {
                assert!(value["properties"][key].is_object(), "{key}");
            }
        }
        let rig: Value = serde_json::from_str(topics::RIG_SCHEMA).unwrap();
        assert_eq!(rig["type"], "object");
        for table in ["camera", "mount", "estimate", "prior", "noise"] {
            assert!(rig["properties"][table].is_object(), "{table}");
        }
    }

    #[test]
    fn odom_errors_name_the_key_and_value() {
        let missing = decode_odom(br#"{"t_us": 1, "vx": 0.5, "vy": 0}"#).unwrap_err();
        assert_eq!(missing.to_string(), r#"missing key "vtheta""#);
        let float_time = decode_odom(br#"{"t_us": 1.5, "vx": 0, "vy": 0, "vtheta": 0}"#);
        assert_eq!(
            float_time.unwrap_err().to_string(),
            r#"key "t_us": expected a non-negative integer, found 1.5"#
        );
        let string = decode_odom(br#"{"t_us": 1, "vx": "fast", "vy": 0, "vtheta": 0}"#);
        assert_eq!(
            string.unwrap_err().to_string(),
            r#"key "vx": expected a number, found "fast""#
        );
        assert_eq!(
            decode_odom(b"[1, 2]").unwrap_err().to_string(),
            "expected a JSON object, found an array"
        );
        assert!(matches!(
            decode_odom(b"{\"t_us\": 1,"),
            Err(Problem::NotJson { .. })
        ));
        let nan = OdomSample {
            t_us: 0,
            vx: 0.0,
            vy: f64::NAN,
            vtheta: 0.0,
        };
        assert!(matches!(encode_odom(&nan), Err(Problem::NotFinite { key, .. }) if key == "vy"));
    }

    #[test]
    fn landmark_errors_name_the_element() {
        let err = decode_truth_landmarks(br#"{"landmarks": [{"id": 1, "x": 0, "y": 0, "z": 3}, {"id": -2, "x": 0, "y": 0, "z": 3}]}"#)
            .unwrap_err();
        assert_eq!(
            err.to_string(),
            r#"key "landmarks[1].id": expected an integer from 0 to 4294967295, found -2"#
        );
    }

    #[test]
    fn long_values_are_shortened() {
        let long = format!(
            r#"{{"t_us": "{}", "vx": 0, "vy": 0, "vtheta": 0}}"#,
            "x".repeat(500)
        );
        let msg = decode_odom(long.as_bytes()).unwrap_err().to_string();
        assert!(msg.len() < 120, "{msg}");
        assert!(msg.ends_with("..."), "{msg}");
    }
}
