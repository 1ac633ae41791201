//! Reading the YAML of a calibration file: a node with its place in the file, so that every
//! error names the file, the key and the problem ([`ImportError::Key`]).

use std::borrow::Cow;
use std::fmt::Display;
use std::path::Path;

use saphyr::{LoadableYamlNode, ScalarOwned, YamlOwned};

use super::ImportError;

/// A node of an input file with its place in it, for errors that name the file and the key.
#[derive(Debug, Clone)]
pub(super) struct Node<'a> {
    file: &'a str,
    /// The key path, `cam1.T_cn_cnm1`.
    key: String,
    yaml: &'a YamlOwned,
}

/// Reads and parses a YAML file; the root must be a mapping. Returns the file's name (as
/// errors give it) and its root.
pub(super) fn load_yaml(path: &Path) -> Result<(String, YamlOwned), ImportError> {
    let file = path.display().to_string();
    let text = match std::fs::read_to_string(path) {
        Ok(text) => text,
        Err(e) => {
            return Err(ImportError::Io {
                file,
                reason: e.to_string(),
            });
        }
    };
    let root = parse_yaml(&file, &text)?;
    Ok((file, root))
}

/// Parses the text of the YAML file `file`; the root must be a mapping.
pub(super) fn parse_yaml(file: &str, text: &str) -> Result<YamlOwned, ImportError> {
    let text = without_opencv_directive(text);
    let documents = YamlOwned::load_from_str(&text).map_err(|e| ImportError::Syntax {
        file: file.to_string(),
        reason: e
            .to_string()
            .split_whitespace()
            .collect::<Vec<_>>()
            .join(" "),
    })?;
    let Some(root) = documents.into_iter().next() else {
        return Err(ImportError::File {
            file: file.to_string(),
            problem: "an empty YAML file".to_string(),
        });
    };
    if untagged(&root).as_mapping().is_none() {
        return Err(ImportError::File {
            file: file.to_string(),
            problem: format!(
                "not a calibration file: expected a YAML mapping of keys, found {}",
                describe(&root)
            ),
        });
    }
    Ok(root)
}

/// OpenCV's `FileStorage` before version 5 (and files made after it, such as EuRoC's
/// `sensor.yaml`) starts with `%YAML:1.0`, which is not a YAML directive (YAML's is
/// `%YAML 1.2`, with a space) and which every YAML parser rejects. That line alone is blanked
/// (the line numbers of parser errors stay right); the rest is plain YAML. OpenCV's
/// `!!opencv-matrix` tags need nothing: the parser keeps the tagged mapping, and
/// [`untagged`] looks through the tag.
fn without_opencv_directive(text: &str) -> Cow<'_, str> {
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let first = text.lines().next().unwrap_or("");
    if first.trim_end().starts_with("%YAML:") {
        Cow::Owned(format!("#{text}"))
    } else {
        Cow::Borrowed(text)
    }
}

/// The node under any tags (`!!opencv-matrix`).
fn untagged(yaml: &YamlOwned) -> &YamlOwned {
    match yaml {
        YamlOwned::Tagged(_, inner) => untagged(inner),
        other => other,
    }
}

fn describe(yaml: &YamlOwned) -> String {
    match untagged(yaml) {
        YamlOwned::Value(ScalarOwned::Null) => "null".to_string(),
        YamlOwned::Value(ScalarOwned::Boolean(b)) => format!("boolean {b}"),
        YamlOwned::Value(ScalarOwned::Integer(i)) => format!("integer {i}"),
        YamlOwned::Value(ScalarOwned::FloatingPoint(x)) => format!("number {x}"),
        YamlOwned::Value(ScalarOwned::String(s)) => format!("string {s:?}"),
        YamlOwned::Representation(s, _, _) => format!("{s:?}"),
        YamlOwned::Sequence(items) => format!("a list of {}", items.len()),
        YamlOwned::Mapping(_) => "a mapping".to_string(),
        YamlOwned::Alias(_) => "an alias (not supported)".to_string(),
        YamlOwned::Tagged(..) | YamlOwned::BadValue => "an unreadable value".to_string(),
    }
}

impl<'a> Node<'a> {
    /// The root of the file named `file`.
    pub(super) fn root(file: &'a str, yaml: &'a YamlOwned) -> Self {
        Self {
            file,
            key: String::new(),
            yaml,
        }
    }

    /// An error naming the file and this key (the file alone at the root).
    pub(super) fn error(&self, problem: impl Display) -> ImportError {
        if self.key.is_empty() {
            ImportError::File {
                file: self.file.to_string(),
                problem: problem.to_string(),
            }
        } else {
            ImportError::Key {
                file: self.file.to_string(),
                key: self.key.clone(),
                problem: problem.to_string(),
            }
        }
    }

    fn child_key(&self, key: &str) -> String {
        if self.key.is_empty() {
            key.to_string()
        } else {
            format!("{}.{key}", self.key)
        }
    }

    /// The value of `key` in this mapping, if present.
    pub(super) fn get_opt(&self, key: &str) -> Result<Option<Node<'a>>, ImportError> {
        let Some(mapping) = untagged(self.yaml).as_mapping() else {
            return Err(self.error(format!("expected a mapping, found {}", describe(self.yaml))));
        };
        let found = mapping
            .iter()
            .find(|(k, _)| untagged(k).as_str() == Some(key))
            .map(|(_, v)| Node {
                file: self.file,
                key: self.child_key(key),
                yaml: v,
            });
        Ok(found)
    }

    /// The value of `key` in this mapping.
    pub(super) fn get(&self, key: &str) -> Result<Node<'a>, ImportError> {
        self.get_opt(key)?.ok_or_else(|| ImportError::Key {
            file: self.file.to_string(),
            key: self.child_key(key),
            problem: "missing key".to_string(),
        })
    }

    /// A finite number (an integer counts).
    pub(super) fn number(&self) -> Result<f64, ImportError> {
        let x = match untagged(self.yaml) {
            YamlOwned::Value(ScalarOwned::FloatingPoint(x)) => x.into_inner(),
            #[allow(clippy::cast_precision_loss)] // calibration values are far below 2^53
            YamlOwned::Value(ScalarOwned::Integer(i)) => *i as f64,
            // OpenCV writes NaN as `.Nan`, which YAML 1.2's core schema reads as a string.
            YamlOwned::Value(ScalarOwned::String(s)) if s.eq_ignore_ascii_case(".nan") => f64::NAN,
            other => {
                return Err(self.error(format!("expected a number, found {}", describe(other))));
            }
        };
        if !x.is_finite() {
            return Err(self.error(format!("{x} is not a finite number")));
        }
        Ok(x)
    }

    /// An integer.
    pub(super) fn integer(&self) -> Result<i64, ImportError> {
        match untagged(self.yaml) {
            YamlOwned::Value(ScalarOwned::Integer(i)) => Ok(*i),
            other => Err(self.error(format!("expected an integer, found {}", describe(other)))),
        }
    }

    /// A string.
    pub(super) fn string(&self) -> Result<&'a str, ImportError> {
        match untagged(self.yaml) {
            YamlOwned::Value(ScalarOwned::String(s)) => Ok(s.as_str()),
            other => Err(self.error(format!("expected a string, found {}", describe(other)))),
        }
    }

    /// The items of a list, each named `key[i]`.
    pub(super) fn items(&self) -> Result<Vec<Node<'a>>, ImportError> {
        let YamlOwned::Sequence(items) = untagged(self.yaml) else {
            return Err(self.error(format!("expected a list, found {}", describe(self.yaml))));
        };
        Ok(items
            .iter()
            .enumerate()
            .map(|(i, yaml)| Node {
                file: self.file,
                key: format!("{}[{i}]", self.key),
                yaml,
            })
            .collect())
    }

    /// A list of finite numbers.
    pub(super) fn numbers(&self) -> Result<Vec<f64>, ImportError> {
        self.items()?.iter().map(Node::number).collect()
    }

    /// A list of exactly `n` numbers; `what` names them in the error.
    pub(super) fn numbers_n(&self, n: usize, what: &str) -> Result<Vec<f64>, ImportError> {
        let v = self.numbers()?;
        if v.len() != n {
            return Err(self.error(format!("{} numbers; expected {n} ({what})", v.len())));
        }
        Ok(v)
    }

    /// A matrix written as `{rows, cols, data}` (ROS `camera_info`, OpenCV's
    /// `!!opencv-matrix`): `(rows, cols, data)` with `data` row-major.
    pub(super) fn matrix(&self) -> Result<(usize, usize, Vec<f64>), ImportError> {
        let size = |key: &str| -> Result<usize, ImportError> {
            let node = self.get(key)?;
            let n = node.integer()?;
            usize::try_from(n)
                .ok()
                .filter(|&n| (1..=64).contains(&n))
                .ok_or_else(|| node.error(format!("{n} is not a matrix size")))
        };
        let (rows, cols) = (size("rows")?, size("cols")?);
        let data = self.get("data")?.numbers()?;
        if data.len() != rows * cols {
            return Err(self.error(format!(
                "{rows} x {cols} matrix with {} numbers of data",
                data.len()
            )));
        }
        Ok((rows, cols, data))
    }

    /// A `rows x cols` matrix, row-major.
    pub(super) fn matrix_sized(&self, rows: usize, cols: usize) -> Result<Vec<f64>, ImportError> {
        let (r, c, data) = self.matrix()?;
        if (r, c) != (rows, cols) {
            return Err(self.error(format!("a {r} x {c} matrix; expected {rows} x {cols}")));
        }
        Ok(data)
    }

    /// A vector stored as a `1 x n` or `n x 1` matrix.
    pub(super) fn vector(&self) -> Result<Vec<f64>, ImportError> {
        let (r, c, data) = self.matrix()?;
        if r != 1 && c != 1 {
            return Err(self.error(format!("a {r} x {c} matrix; expected a vector (1 x n)")));
        }
        Ok(data)
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::indexing_slicing)]
mod tests {
    use super::*;

    fn yaml(text: &str) -> YamlOwned {
        parse_yaml("test.yml", text).unwrap()
    }

    #[test]
    fn opencv_directive_and_matrix_tags_are_read() {
        for header in ["%YAML:1.0\n", "%YAML 1.2\n---\n", "\u{feff}%YAML:1.0\n", ""] {
            let doc = yaml(&format!(
                "{header}K1: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n   data: [ 458.654, \
                 0., 367.215, 0., 457.296,\n       248.375, 0., 0., 1. ]\nwidth: 752\n"
            ));
            let root = Node::root("s.yml", &doc);
            let k = root.get("K1").unwrap().matrix_sized(3, 3).unwrap();
            assert_eq!(k[0], 458.654);
            assert_eq!(k[8], 1.0);
            assert_eq!(root.get("width").unwrap().integer().unwrap(), 752);
        }
    }

    #[test]
    fn errors_name_the_file_the_key_and_the_value() {
        let doc = yaml(
            "a: {rows: 2, cols: 2, data: [1, 2, 3]}\nb: [1, .Nan]\nc: x\nd: {rows: 1, cols: 3, data: [1, 2, 3]}\n",
        );
        let root = Node::root("f.yml", &doc);
        let msg = |e: ImportError| e.to_string();
        assert_eq!(
            msg(root.get("a").unwrap().matrix().unwrap_err()),
            "f.yml: a: 2 x 2 matrix with 3 numbers of data"
        );
        assert_eq!(
            msg(root.get("b").unwrap().numbers().unwrap_err()),
            "f.yml: b[1]: NaN is not a finite number"
        );
        assert_eq!(
            msg(root.get("c").unwrap().number().unwrap_err()),
            "f.yml: c: expected a number, found string \"x\""
        );
        assert_eq!(
            msg(root.get("d").unwrap().matrix_sized(3, 3).unwrap_err()),
            "f.yml: d: a 1 x 3 matrix; expected 3 x 3"
        );
        assert_eq!(msg(root.get("e").unwrap_err()), "f.yml: e: missing key");
        assert_eq!(
            root.get("a")
                .unwrap()
                .get("rows")
                .unwrap()
                .string()
                .unwrap_err(),
            ImportError::Key {
                file: "f.yml".to_string(),
                key: "a.rows".to_string(),
                problem: "expected a string, found integer 2".to_string(),
            }
        );
    }

    #[test]
    fn files_that_are_no_mapping_are_named() {
        let err = |text: &str| parse_yaml("f.yml", text).unwrap_err().to_string();
        assert_eq!(err(""), "f.yml: an empty YAML file");
        assert_eq!(
            err("- 1\n- 2\n"),
            "f.yml: not a calibration file: expected a YAML mapping of keys, found a list of 2"
        );
        let syntax = err("cam0: [1, 2\n");
        assert!(syntax.starts_with("f.yml: not a YAML file: "), "{syntax}");
        assert_eq!(syntax.lines().count(), 1, "{syntax}");
    }
}
