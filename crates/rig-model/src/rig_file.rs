//! The rig file (vehicle-interfaces.md section 3): nominal camera parameters, which of them to
//! estimate, their priors, and the noise model. Read from TOML files, or from the JSON of a
//! log's `/rig` message; written back as JSON.

use alloc::format;
use alloc::string::{String, ToString};
use alloc::vec::Vec;
#[cfg(feature = "std")]
use std::path::Path;

use toml::{Table, Value};

use crate::camera::{CameraParams, Mount, N_PARAMS, Param, Vehicle};
use crate::config::{Board, Noise, Rig};
use crate::lens::{Lens, LensModel, StereoLens};

/// A rig file that cannot be used; the message names the file, the key and the problem.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum RigFileError {
    /// The file could not be read.
    #[error("{path}: cannot read rig file: {reason}")]
    Io {
        /// The file.
        path: String,
        /// The operating system's reason.
        reason: String,
    },
    /// The text is not valid TOML (or JSON).
    #[error("{source_name}: not a valid rig file: {reason}")]
    Syntax {
        /// The file or message the text came from.
        source_name: String,
        /// The parser's reason, on one line.
        reason: String,
    },
    /// A key is missing, has the wrong type or an impossible value, or is unknown.
    #[error("{source_name}: {key}: {problem}")]
    Key {
        /// The file or message the text came from.
        source_name: String,
        /// The key, as `[table] key`.
        key: String,
        /// What is wrong with it.
        problem: String,
    },
}

/// `[camera]`'s keys.
const CAMERA_KEYS: [&str; 6] = ["width", "height", "f", "cx", "cy", "baseline"];
/// `[mount]`'s keys.
const MOUNT_KEYS: [&str; 6] = ["x", "y", "z", "roll", "pitch", "yaw"];
/// `[estimate]`'s keys.
const ESTIMATE_KEYS: [&str; 1] = ["parameters"];
/// `[noise]`'s keys (the two time constants are v3's and optional).
const NOISE_KEYS: [&str; 5] = [
    "pixel",
    "velocity",
    "yaw_rate",
    "velocity_tau",
    "yaw_rate_tau",
];
/// `[vehicle]`'s keys: the parameters of `V` (vehicle-interfaces.md 1.2).
const VEHICLE_KEYS: [&str; 4] = [
    "odom_scale",
    "odom_yaw_scale",
    "odom_yaw_bias",
    "time_offset",
];
/// `[lens.left]`'s and `[lens.right]`'s keys.
const LENS_KEYS: [&str; 7] = [
    "model",
    "fx",
    "fy",
    "cx",
    "cy",
    "coefficients",
    "rectification",
];
/// `[board]`'s keys (v3, 4.1): the detector's registers for images the host detects on.
const BOARD_KEYS: [&str; 2] = ["threshold", "max_features"];

/// Every table of a rig file and the keys it may hold, as this reader reads them
/// (vehicle-interfaces.md section 3); `[prior]`'s keys are parameter names ([`Param::ALL`]).
/// Front ends check against this list that they show every table and key (one reading of
/// the format: a table one side reads and the other does not fails their tests).
pub const RIG_FILE_KEYS: [(&str, &[&str]); 9] = [
    ("camera", &CAMERA_KEYS),
    ("mount", &MOUNT_KEYS),
    ("estimate", &ESTIMATE_KEYS),
    ("prior", &[]),
    ("noise", &NOISE_KEYS),
    ("vehicle", &VEHICLE_KEYS),
    ("lens.left", &LENS_KEYS),
    ("lens.right", &LENS_KEYS),
    ("board", &BOARD_KEYS),
];

const TABLES: [&str; 8] = [
    "camera", "mount", "estimate", "prior", "noise", "vehicle", "lens", "board",
];

struct Reader<'a> {
    source: &'a str,
    root: &'a Table,
}

impl Reader<'_> {
    fn error(&self, key: String, problem: String) -> RigFileError {
        RigFileError::Key {
            source_name: self.source.to_string(),
            key,
            problem,
        }
    }

    fn table(&self, name: &str) -> Result<&Table, RigFileError> {
        match self.root.get(name) {
            Some(Value::Table(t)) => Ok(t),
            Some(other) => Err(self.error(
                format!("[{name}]"),
                format!("expected a table, found {}", describe(other)),
            )),
            None => Err(self.error(format!("[{name}]"), "missing table".to_string())),
        }
    }

    fn check_keys(&self, table: &str, allowed: &[&str]) -> Result<(), RigFileError> {
        for key in self.table(table)?.keys() {
            if !allowed.contains(&key.as_str()) {
                return Err(self.error(
                    format!("[{table}] {}", key.escape_debug()),
                    format!("unknown key (known: {})", allowed.join(", ")),
                ));
            }
        }
        Ok(())
    }

    fn number(&self, table: &str, key: &str) -> Result<f64, RigFileError> {
        let value = self
            .table(table)?
            .get(key)
            .ok_or_else(|| self.error(format!("[{table}] {key}"), "missing key".to_string()))?;
        self.finite(&format!("[{table}] {key}"), value, "a number")
    }

    /// A finite number (an integer counts), or an error naming `key`; `expected` says what a
    /// value of another type should have been.
    fn finite(&self, key: &str, value: &Value, expected: &str) -> Result<f64, RigFileError> {
        let x = match value {
            Value::Float(x) => *x,
            #[allow(clippy::cast_precision_loss)] // rig values are far below 2^53
            Value::Integer(i) => *i as f64,
            other => {
                return Err(self.error(
                    key.to_string(),
                    format!("expected {expected}, found {}", describe(other)),
                ));
            }
        };
        if !x.is_finite() {
            return Err(self.error(key.to_string(), format!("{x} is not a finite number")));
        }
        Ok(x)
    }

    fn positive(&self, table: &str, key: &str) -> Result<f64, RigFileError> {
        let x = self.number(table, key)?;
        if x > 0.0 {
            Ok(x)
        } else {
            Err(self.error(format!("[{table}] {key}"), format!("{x} must be positive")))
        }
    }

    /// An optional `[noise]` time constant (v3): seconds, `>= 0`; absent means 0 (white).
    fn time_constant(&self, key: &str) -> Result<f64, RigFileError> {
        if !self.table("noise")?.contains_key(key) {
            return Ok(0.0);
        }
        let x = self.number("noise", key)?;
        if x >= 0.0 {
            Ok(x)
        } else {
            Err(self.error(
                format!("[noise] {key}"),
                format!("{x} must be >= 0 (0: the odometry's errors are white)"),
            ))
        }
    }

    fn size(&self, key: &str) -> Result<u32, RigFileError> {
        let name = format!("[camera] {key}");
        match self.table("camera")?.get(key) {
            Some(Value::Integer(i)) if (16..=4095).contains(i) => {
                u32::try_from(*i).map_err(|_| self.error(name, format!("{i} is out of range")))
            }
            Some(Value::Integer(i)) => {
                Err(self.error(name, format!("{i} is outside the board's range 16..=4095")))
            }
            Some(other) => Err(self.error(
                name,
                format!("expected an integer, found {}", describe(other)),
            )),
            None => Err(self.error(name, "missing key".to_string())),
        }
    }
}

/// The optional `[vehicle]` table (vehicle-interfaces.md 1.2, 3): each key defaults to its
/// nominal value; the scales must be positive.
fn vehicle(r: &Reader<'_>) -> Result<Vehicle, RigFileError> {
    let mut v = Vehicle::NOMINAL;
    if !r.root.contains_key("vehicle") {
        return Ok(v);
    }
    r.check_keys("vehicle", &VEHICLE_KEYS)?;
    let t = r.table("vehicle")?;
    for (key, slot, positive) in [
        ("odom_scale", &mut v.odom_scale, true),
        ("odom_yaw_scale", &mut v.odom_yaw_scale, true),
        ("odom_yaw_bias", &mut v.odom_yaw_bias, false),
        ("time_offset", &mut v.time_offset, false),
    ] {
        if t.contains_key(key) {
            *slot = if positive {
                r.positive("vehicle", key)?
            } else {
                r.number("vehicle", key)?
            };
        }
    }
    Ok(v)
}

/// `[lens.left]` and `[lens.right]` (vehicle-interfaces.md section 3): both or neither.
fn lenses(r: &Reader<'_>) -> Result<Option<StereoLens>, RigFileError> {
    let Some(value) = r.root.get("lens") else {
        return Ok(None);
    };
    let Value::Table(lens) = value else {
        return Err(r.error(
            "[lens]".to_string(),
            format!(
                "expected tables [lens.left] and [lens.right], found {}",
                describe(value)
            ),
        ));
    };
    for key in lens.keys() {
        if key != "left" && key != "right" {
            return Err(r.error(
                format!("[lens.{}]", key.escape_debug()),
                "unknown table (known: lens.left, lens.right)".to_string(),
            ));
        }
    }
    let sub = Reader {
        source: r.source,
        root: lens,
    };
    // Errors name the table as the file does.
    let named = |e: RigFileError| match e {
        RigFileError::Key {
            source_name,
            key,
            problem,
        } => RigFileError::Key {
            source_name,
            key: key.replacen('[', "[lens.", 1),
            problem,
        },
        other => other,
    };
    let side = |name: &str| -> Result<Lens, RigFileError> {
        sub.check_keys(name, &LENS_KEYS)?;
        let t = sub.table(name)?;
        let numbers = |key: &str, lens_of: &[usize]| -> Result<Vec<f64>, RigFileError> {
            let found = t
                .get(key)
                .ok_or_else(|| sub.error(format!("[{name}] {key}"), "missing key".to_string()))?;
            let Value::Array(items) = found else {
                return Err(sub.error(
                    format!("[{name}] {key}"),
                    format!("expected an array of numbers, found {}", describe(found)),
                ));
            };
            let out = items
                .iter()
                .map(|item| sub.finite(&format!("[{name}] {key}"), item, "numbers"))
                .collect::<Result<Vec<f64>, RigFileError>>()?;
            if !lens_of.contains(&out.len()) {
                return Err(sub.error(
                    format!("[{name}] {key}"),
                    format!(
                        "{} numbers; expected {}",
                        out.len(),
                        lens_of
                            .iter()
                            .map(ToString::to_string)
                            .collect::<Vec<_>>()
                            .join(" or ")
                    ),
                ));
            }
            Ok(out)
        };
        let model_name = match t.get("model") {
            Some(Value::String(m)) => m.as_str(),
            Some(other) => {
                return Err(sub.error(
                    format!("[{name}] model"),
                    format!("expected a string, found {}", describe(other)),
                ));
            }
            None => return Err(sub.error(format!("[{name}] model"), "missing key".to_string())),
        };
        let model = match model_name {
            "plumb_bob" => {
                let k = numbers("coefficients", &[4, 5])?;
                let at = |i: usize| k.get(i).copied().unwrap_or(0.0);
                LensModel::PlumbBob {
                    k1: at(0),
                    k2: at(1),
                    p1: at(2),
                    p2: at(3),
                    k3: at(4),
                }
            }
            "equidistant" => {
                let k = numbers("coefficients", &[4])?;
                let at = |i: usize| k.get(i).copied().unwrap_or(0.0);
                LensModel::Equidistant {
                    k1: at(0),
                    k2: at(1),
                    k3: at(2),
                    k4: at(3),
                }
            }
            other => {
                return Err(sub.error(
                    format!("[{name}] model"),
                    format!("unknown lens model {other:?} (known: plumb_bob, equidistant)"),
                ));
            }
        };
        let rect = numbers("rectification", &[9])?;
        let rectification = nalgebra::Matrix3::from_row_slice(&rect);
        // A rotation: orthonormal with determinant +1.
        let off =
            (rectification * rectification.transpose() - nalgebra::Matrix3::identity()).amax();
        if off > 1e-5 || rectification.determinant() < 0.0 {
            return Err(sub.error(
                format!("[{name}] rectification"),
                format!("not a rotation matrix (R R^T differs from I by {off:.1e})"),
            ));
        }
        Ok(Lens {
            model,
            fx: sub.positive(name, "fx")?,
            fy: sub.positive(name, "fy")?,
            cx: sub.number(name, "cx")?,
            cy: sub.number(name, "cy")?,
            rectification,
        })
    };
    match (lens.contains_key("left"), lens.contains_key("right")) {
        (true, true) => Ok(Some(StereoLens {
            left: side("left").map_err(named)?,
            right: side("right").map_err(named)?,
        })),
        (l, _) => Err(r.error(
            format!("[lens.{}]", if l { "right" } else { "left" }),
            "missing table: [lens.left] and [lens.right] come together or not at all".to_string(),
        )),
    }
}

/// The optional `[board]` table (vehicle-interfaces.md 4.1): the board's registers, each key
/// defaulting to the board's power-on value and checked against board-icd.md's ranges.
fn board(r: &Reader<'_>) -> Result<Board, RigFileError> {
    let mut board = Board::DEFAULT;
    if !r.root.contains_key("board") {
        return Ok(board);
    }
    r.check_keys("board", &BOARD_KEYS)?;
    let t = r.table("board")?;
    let integer = |key: &str| -> Result<Option<i64>, RigFileError> {
        match t.get(key) {
            None => Ok(None),
            Some(Value::Integer(i)) => Ok(Some(*i)),
            Some(other) => Err(r.error(
                format!("[board] {key}"),
                format!("expected an integer, found {}", describe(other)),
            )),
        }
    };
    if let Some(i) = integer("threshold")? {
        board.threshold = i32::try_from(i).map_err(|_| {
            r.error(
                "[board] threshold".to_string(),
                format!(
                    "{i} is outside the THRESHOLD register's range {}..={}",
                    i32::MIN,
                    i32::MAX
                ),
            )
        })?;
    }
    if let Some(i) = integer("max_features")? {
        let limit = harris_core::MAX_FEATURES_LIMIT;
        board.max_features = usize::try_from(i)
            .ok()
            .filter(|n| (1..=limit).contains(n))
            .ok_or_else(|| {
                r.error(
                    "[board] max_features".to_string(),
                    format!("{i} is outside the MAX_FEATURES register's range 1..={limit}"),
                )
            })?;
    }
    Ok(board)
}

fn describe(v: &Value) -> String {
    match v {
        Value::String(s) => format!("string {s:?}"),
        Value::Integer(i) => format!("integer {i}"),
        Value::Float(x) => format!("float {x}"),
        Value::Boolean(b) => format!("boolean {b}"),
        Value::Datetime(d) => format!("datetime {d}"),
        Value::Array(_) => "an array".to_string(),
        Value::Table(_) => "a table".to_string(),
    }
}

impl Rig {
    /// Reads a rig file (TOML). Errors name the file, the key and what was wrong.
    #[cfg(feature = "std")]
    pub fn load(path: &Path) -> Result<Self, RigFileError> {
        let name = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|e| RigFileError::Io {
            path: name.clone(),
            reason: e.to_string(),
        })?;
        Self::from_toml_str(&text, &name)
    }

    /// Parses a rig file's TOML text; `source_name` names it in errors.
    pub fn from_toml_str(text: &str, source_name: &str) -> Result<Self, RigFileError> {
        let root: Table = text
            .parse()
            .map_err(|e: toml::de::Error| RigFileError::Syntax {
                source_name: source_name.to_string(),
                reason: one_line(&e.to_string()),
            })?;
        Self::from_table(&root, source_name)
    }

    /// Parses the JSON form of a rig file (a log's `/rig` message: the same tables as JSON).
    pub fn from_json_str(text: &str, source_name: &str) -> Result<Self, RigFileError> {
        let json: serde_json::Value =
            serde_json::from_str(text).map_err(|e| RigFileError::Syntax {
                source_name: source_name.to_string(),
                reason: one_line(&e.to_string()),
            })?;
        if let Some(key) = null_key(&json) {
            return Err(RigFileError::Key {
                source_name: source_name.to_string(),
                key,
                problem: "null is not a value: expected a number, string or array".to_string(),
            });
        }
        let Some(Value::Table(root)) = json_to_toml(&json) else {
            return Err(RigFileError::Syntax {
                source_name: source_name.to_string(),
                reason:
                    "expected a JSON object of tables (camera, mount, estimate, prior, noise, ...)"
                        .to_string(),
            });
        };
        Self::from_table(&root, source_name)
    }

    /// A rig from a rig file's tables as a program holds them (a TOML table: the Python
    /// `RigConfig`'s `tables`, a rig edited in memory), checked as the file's text is, with
    /// the same errors (`source_name` names the values in them).
    pub fn from_toml_table(root: &Table, source_name: &str) -> Result<Self, RigFileError> {
        Self::from_table(root, source_name)
    }

    /// The rig file's tables (every table and key this rig has, as [`Rig::to_json`] writes
    /// them): [`Rig::from_toml_table`] gives this rig back.
    pub fn to_toml_table(&self) -> Table {
        // The JSON form holds no null, so every value converts.
        match json_to_toml(&self.to_json_value()) {
            Some(Value::Table(t)) => t,
            _ => Table::new(),
        }
    }

    fn from_table(root: &Table, source: &str) -> Result<Self, RigFileError> {
        let r = Reader { source, root };
        for key in root.keys() {
            if !TABLES.contains(&key.as_str()) {
                return Err(r.error(
                    format!("[{}]", key.escape_debug()),
                    format!("unknown table (known: {})", TABLES.join(", ")),
                ));
            }
        }
        r.check_keys("camera", &CAMERA_KEYS)?;
        r.check_keys("mount", &MOUNT_KEYS)?;
        r.check_keys("estimate", &ESTIMATE_KEYS)?;
        r.check_keys("noise", &NOISE_KEYS)?;
        let nominal = CameraParams {
            f: r.positive("camera", "f")?,
            cx: r.number("camera", "cx")?,
            cy: r.number("camera", "cy")?,
            baseline: r.positive("camera", "baseline")?,
            mount: Mount {
                x: r.number("mount", "x")?,
                y: r.number("mount", "y")?,
                z: r.number("mount", "z")?,
                roll: r.number("mount", "roll")?,
                pitch: r.number("mount", "pitch")?,
                yaw: r.number("mount", "yaw")?,
            },
            vehicle: vehicle(&r)?,
        };
        let list = match r.table("estimate")?.get("parameters") {
            Some(Value::Array(a)) => a,
            Some(other) => {
                return Err(r.error(
                    "[estimate] parameters".to_string(),
                    format!(
                        "expected an array of parameter names, found {}",
                        describe(other)
                    ),
                ));
            }
            None => {
                return Err(r.error(
                    "[estimate] parameters".to_string(),
                    "missing key".to_string(),
                ));
            }
        };
        let known = || {
            Param::ALL
                .iter()
                .map(|p| p.name())
                .collect::<Vec<_>>()
                .join(", ")
        };
        let mut estimate = Vec::new();
        for item in list {
            let Value::String(name) = item else {
                return Err(r.error(
                    "[estimate] parameters".to_string(),
                    format!("expected parameter names, found {}", describe(item)),
                ));
            };
            let param = Param::from_name(name).ok_or_else(|| {
                r.error(
                    "[estimate] parameters".to_string(),
                    format!("unknown parameter {name:?} (known: {})", known()),
                )
            })?;
            if estimate.contains(&param) {
                return Err(r.error(
                    "[estimate] parameters".to_string(),
                    format!("{name:?} is listed twice"),
                ));
            }
            estimate.push(param);
        }
        estimate.sort();
        let mut prior = [None; N_PARAMS];
        for (name, _) in r.table("prior")? {
            let param = Param::from_name(name).ok_or_else(|| {
                r.error(
                    format!("[prior] {}", name.escape_debug()),
                    format!("unknown parameter (known: {})", known()),
                )
            })?;
            if !estimate.contains(&param) {
                return Err(r.error(
                    format!("[prior] {name}"),
                    "prior given for a parameter that [estimate] does not list".to_string(),
                ));
            }
            prior[param.index()] = Some(r.positive("prior", name)?);
        }
        for param in &estimate {
            if prior[param.index()].is_none() {
                return Err(r.error(
                    format!("[prior] {param}"),
                    "missing key: every estimated parameter needs a prior sigma".to_string(),
                ));
            }
        }
        let noise = Noise {
            pixel: r.positive("noise", "pixel")?,
            velocity: r.positive("noise", "velocity")?,
            yaw_rate: r.positive("noise", "yaw_rate")?,
            velocity_tau: r.time_constant("velocity_tau")?,
            yaw_rate_tau: r.time_constant("yaw_rate_tau")?,
        };
        let lens = lenses(&r)?;
        let board = board(&r)?;
        Ok(Self {
            width: r.size("width")?,
            height: r.size("height")?,
            nominal,
            estimate,
            prior,
            noise,
            lens,
            board,
        })
    }

    /// The rig file's tables as JSON (the `/rig` message of a log).
    pub fn to_json(&self) -> String {
        self.to_json_value().to_string()
    }

    /// The rig file's tables as a JSON value: every table this rig needs to be read back as
    /// it is (`[vehicle]`, `[board]` and the noise's time constants only when they are not
    /// the defaults, so that older rigs read as before).
    fn to_json_value(&self) -> serde_json::Value {
        let c = &self.nominal;
        let m = &c.mount;
        let mut prior = serde_json::Map::new();
        for p in &self.estimate {
            if let Some(s) = self.prior[p.index()] {
                prior.insert(p.name().to_string(), s.into());
            }
        }
        let mut json = serde_json::json!({
            "camera": {"width": self.width, "height": self.height, "f": c.f, "cx": c.cx, "cy": c.cy, "baseline": c.baseline},
            "mount": {"x": m.x, "y": m.y, "z": m.z, "roll": m.roll, "pitch": m.pitch, "yaw": m.yaw},
            "estimate": {"parameters": self.estimate.iter().map(|p| p.name()).collect::<Vec<_>>()},
            "prior": prior,
            "noise": {"pixel": self.noise.pixel, "velocity": self.noise.velocity, "yaw_rate": self.noise.yaw_rate},
        });
        if let Some(noise) = json
            .get_mut("noise")
            .and_then(serde_json::Value::as_object_mut)
        {
            // v3's time constants only when the odometry's errors have memory, so that the
            // rig of a white-noise log reads as before.
            for (key, tau) in [
                ("velocity_tau", self.noise.velocity_tau),
                ("yaw_rate_tau", self.noise.yaw_rate_tau),
            ] {
                if tau != 0.0 {
                    noise.insert(key.to_string(), tau.into());
                }
            }
        }
        if let Some(obj) = json.as_object_mut()
            && !self.board.is_default()
        {
            obj.insert(
                "board".to_string(),
                serde_json::json!({"threshold": self.board.threshold, "max_features": self.board.max_features}),
            );
        }
        if let Some(obj) = json.as_object_mut()
            && !c.vehicle.is_nominal()
        {
            let v = &c.vehicle;
            obj.insert(
                "vehicle".to_string(),
                serde_json::json!({"odom_scale": v.odom_scale, "odom_yaw_scale": v.odom_yaw_scale, "odom_yaw_bias": v.odom_yaw_bias, "time_offset": v.time_offset}),
            );
        }
        if let (Some(l), Some(obj)) = (&self.lens, json.as_object_mut()) {
            let side = |lens: &Lens| {
                let (model, coefficients): (_, Vec<f64>) =
                    (lens.model.name(), lens.model.coefficients().collect());
                let r = &lens.rectification;
                let rect: Vec<f64> = (0..3)
                    .flat_map(|i| (0..3).map(move |j| r[(i, j)]))
                    .collect();
                serde_json::json!({"model": model, "fx": lens.fx, "fy": lens.fy, "cx": lens.cx, "cy": lens.cy, "coefficients": coefficients, "rectification": rect})
            };
            obj.insert(
                "lens".to_string(),
                serde_json::json!({"left": side(&l.left), "right": side(&l.right)}),
            );
        }
        json
    }

    /// The rig file as TOML text.
    pub fn to_toml(&self) -> String {
        let c = &self.nominal;
        let m = &c.mount;
        let names: Vec<String> = self
            .estimate
            .iter()
            .map(|p| format!("{:?}", p.name()))
            .collect();
        let mut out = format!(
            "[camera]\nwidth = {}\nheight = {}\nf = {:?}\ncx = {:?}\ncy = {:?}\nbaseline = {:?}\n\n\
             [mount]\nx = {:?}\ny = {:?}\nz = {:?}\nroll = {:?}\npitch = {:?}\nyaw = {:?}\n\n\
             [estimate]\nparameters = [{}]\n\n[prior]\n",
            self.width,
            self.height,
            c.f,
            c.cx,
            c.cy,
            c.baseline,
            m.x,
            m.y,
            m.z,
            m.roll,
            m.pitch,
            m.yaw,
            names.join(", ")
        );
        for p in &self.estimate {
            if let Some(s) = self.prior[p.index()] {
                out.push_str(&format!("{} = {s:?}\n", p.name()));
            }
        }
        out.push_str(&format!(
            "\n[noise]\npixel = {:?}\nvelocity = {:?}\nyaw_rate = {:?}\n",
            self.noise.pixel, self.noise.velocity, self.noise.yaw_rate
        ));
        for (key, tau) in [
            ("velocity_tau", self.noise.velocity_tau),
            ("yaw_rate_tau", self.noise.yaw_rate_tau),
        ] {
            if tau != 0.0 {
                out.push_str(&format!("{key} = {tau:?}\n"));
            }
        }
        if !self.board.is_default() {
            out.push_str(&format!(
                "\n[board]\nthreshold = {}\nmax_features = {}\n",
                self.board.threshold, self.board.max_features
            ));
        }
        if !c.vehicle.is_nominal() {
            let v = &c.vehicle;
            out.push_str(&format!(
                "\n[vehicle]\nodom_scale = {:?}\nodom_yaw_scale = {:?}\nodom_yaw_bias = {:?}\ntime_offset = {:?}\n",
                v.odom_scale, v.odom_yaw_scale, v.odom_yaw_bias, v.time_offset
            ));
        }
        if let Some(l) = &self.lens {
            for (name, lens) in [("left", &l.left), ("right", &l.right)] {
                let coefficients: Vec<f64> = lens.model.coefficients().collect();
                let model = lens.model.name();
                let list = |v: &[f64]| {
                    v.iter()
                        .map(|x| format!("{x:?}"))
                        .collect::<Vec<_>>()
                        .join(", ")
                };
                let r = &lens.rectification;
                let rect: Vec<f64> = (0..3)
                    .flat_map(|i| (0..3).map(move |j| r[(i, j)]))
                    .collect();
                out.push_str(&format!(
                    "\n[lens.{name}]\nmodel = {model:?}\nfx = {:?}\nfy = {:?}\ncx = {:?}\ncy = {:?}\ncoefficients = [{}]\nrectification = [{}]\n",
                    lens.fx,
                    lens.fy,
                    lens.cx,
                    lens.cy,
                    list(&coefficients),
                    list(&rect)
                ));
            }
        }
        out
    }
}

fn one_line(s: &str) -> String {
    s.split_whitespace().collect::<Vec<_>>().join(" ")
}

/// The `[table] key` of the first JSON `null` in a rig object, if any.
fn null_key(json: &serde_json::Value) -> Option<String> {
    let serde_json::Value::Object(tables) = json else {
        return None;
    };
    for (table, value) in tables {
        match value {
            serde_json::Value::Null => return Some(format!("[{}]", table.escape_debug())),
            serde_json::Value::Object(keys) => {
                for (key, v) in keys {
                    let has_null = match v {
                        serde_json::Value::Null => true,
                        serde_json::Value::Array(items) => {
                            items.iter().any(serde_json::Value::is_null)
                        }
                        _ => false,
                    };
                    if has_null {
                        return Some(format!("[{}] {}", table.escape_debug(), key.escape_debug()));
                    }
                }
            }
            _ => {}
        }
    }
    None
}

fn json_to_toml(v: &serde_json::Value) -> Option<Value> {
    Some(match v {
        serde_json::Value::Null => return None,
        serde_json::Value::Bool(b) => Value::Boolean(*b),
        serde_json::Value::Number(n) => match n.as_i64() {
            Some(i) => Value::Integer(i),
            None => Value::Float(n.as_f64()?),
        },
        serde_json::Value::String(s) => Value::String(s.clone()),
        serde_json::Value::Array(a) => {
            Value::Array(a.iter().map(json_to_toml).collect::<Option<_>>()?)
        }
        serde_json::Value::Object(o) => {
            let mut t = Table::new();
            for (k, v) in o {
                t.insert(k.clone(), json_to_toml(v)?);
            }
            Value::Table(t)
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_line_collapses_all_whitespace() {
        assert_eq!(
            one_line("TOML parse error at line 1\n  |\n1 | a =\n  |    ^\r\n\tmissing value"),
            "TOML parse error at line 1 | 1 | a = | ^ missing value"
        );
        assert_eq!(one_line(""), "");
    }

    #[test]
    fn json_values_map_to_toml_values() {
        let j = |s: &str| serde_json::from_str::<serde_json::Value>(s).unwrap_or_default();
        assert_eq!(json_to_toml(&j("752")), Some(Value::Integer(752)));
        assert_eq!(json_to_toml(&j("-3")), Some(Value::Integer(-3)));
        assert_eq!(json_to_toml(&j("752.0")), Some(Value::Float(752.0)));
        assert_eq!(json_to_toml(&j("1e3")), Some(Value::Float(1000.0)));
        // Beyond i64: a float (the size check then reports a float, not a wrapped integer).
        assert_eq!(
            json_to_toml(&j("18446744073709551615")),
            Some(Value::Float(18_446_744_073_709_551_615.0))
        );
        assert_eq!(json_to_toml(&j("true")), Some(Value::Boolean(true)));
        assert_eq!(
            json_to_toml(&j(r#"["f", 1]"#)),
            Some(Value::Array(std::vec![
                Value::String("f".to_string()),
                Value::Integer(1)
            ]))
        );
        assert_eq!(json_to_toml(&j("null")), None);
        assert_eq!(json_to_toml(&j(r#"{"a": {"b": [1, null]}}"#)), None);
    }
}
