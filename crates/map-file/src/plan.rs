//! A map from a hall's lighting plan or survey (`stereonav map import LAMPS.csv --out MAP`,
//! vehicle-interfaces.md section 5; docs/maps.md, "A map from a lighting plan").
//!
//! The plan is a CSV file: a header line naming the columns, then a row per lamp.
//!
//! ```text
//! # hall 3, survey of 2031-04-02 (comment lines start with '#')
//! id,x,y,z,sigma
//! 0, 1.20, 3.40, 7.02, 0.01
//! 1, 5.20, 3.41, 7.00, 0.01
//! ```
//!
//! - Columns `x`, `y`, `z` (metres, the hall's frame, z up) are required; `id` (a non-negative
//!   integer; without it the lamps are numbered 0, 1, ... in row order) and `sigma` (the
//!   lamp's 1-sigma position uncertainty in metres, its covariance `sigma^2 I`; without it
//!   every lamp gets the default, `--sigma`) are optional. Any order; names are read without
//!   case (`X` is `x`). Any other column is an error naming it, so that a typo (`sigam`) is
//!   not silently dropped.
//! - Plain comma-separated values: fields are split at every comma and trimmed of spaces; no
//!   quoting (a quoted number is not a number). Blank lines and lines whose first non-blank
//!   character is `#` are skipped; a comment after the values is not allowed. A UTF-8 byte
//!   order mark and CRLF line ends (spreadsheet exports) are accepted.
//!
//! Hand-written rather than the `csv` crate (not in the workspace's lock file): the format is
//! this small, and every message must name the line and the field that is wrong.

use std::collections::HashMap;
use std::path::Path;
use std::time::{SystemTime, UNIX_EPOCH};

use rig_model::config::Rig;

use crate::{Error, Map, MapLandmark};

/// The 1-sigma position uncertainty of a lamp whose row gives none, metres (`--sigma`'s
/// default): a surveyed lamp, or a plan drawn to the centimetre.
pub const DEFAULT_LAMP_SIGMA_M: f64 = 0.02;

/// The columns a plan must have.
const REQUIRED: [&str; 3] = ["x", "y", "z"];
/// Every column a plan may have.
const KNOWN: [&str; 5] = ["x", "y", "z", "id", "sigma"];

/// One lamp of a lighting plan.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlanLamp {
    /// Its id (the `id` column, or its row's index).
    pub id: u64,
    /// Position in the hall's frame, metres.
    pub position: [f64; 3],
    /// 1-sigma position uncertainty, metres (isotropic).
    pub sigma_m: f64,
    /// The line of the file it is on (1-based).
    pub line: usize,
}

/// What is wrong with a lighting plan (the line is in [`Error::Plan`]).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum PlanProblem {
    /// The file holds nothing but blank and comment lines.
    #[error(
        "no header line: the file is empty or holds only blank and comment lines (expected a header naming the columns x,y,z)"
    )]
    NoHeader,
    /// A header and no row.
    #[error("no lamps: no row follows the header")]
    NoRows,
    /// The file is not UTF-8 text.
    #[error("not UTF-8 text")]
    NotText,
    /// A header field without a name (a trailing comma).
    #[error("column {column} of the header has no name")]
    UnnamedColumn {
        /// The column, 1-based.
        column: usize,
    },
    /// A column named twice.
    #[error("column '{column}' is named twice in the header")]
    DuplicateColumn {
        /// Its name.
        column: String,
    },
    /// A required column is missing.
    #[error(
        "the header has no {} column{} (it needs x, y, z; optional: id, sigma){}",
        quoted(missing),
        if missing.len() > 1 { "s" } else { "" },
        if unknown.is_empty() { String::new() } else { format!("; it has unknown {}", quoted(unknown)) }
    )]
    MissingColumns {
        /// The required columns missing.
        missing: Vec<&'static str>,
        /// Columns the format does not have (a misspelling, often).
        unknown: Vec<String>,
    },
    /// A column the format does not have.
    #[error(
        "unknown column{} {} (the columns are x, y, z and optionally id, sigma)",
        if unknown.len() > 1 { "s" } else { "" },
        quoted(unknown)
    )]
    UnknownColumns {
        /// Their names.
        unknown: Vec<String>,
    },
    /// A row with another number of fields than the header has columns.
    #[error("{found} fields, the header names {expected} columns")]
    FieldCount {
        /// Fields in the row.
        found: usize,
        /// Columns in the header.
        expected: usize,
    },
    /// An empty field.
    #[error("{column} is empty")]
    EmptyField {
        /// The column.
        column: &'static str,
    },
    /// A field that is not a number.
    #[error("{column} '{text}' is not a number")]
    NotANumber {
        /// The column.
        column: &'static str,
        /// The field.
        text: String,
    },
    /// A number that is NaN or infinite.
    #[error("{column} is {text}, not a finite number")]
    NotFinite {
        /// The column.
        column: &'static str,
        /// The field.
        text: String,
    },
    /// A lamp's sigma that is zero or negative.
    #[error("sigma {value} is not positive (a lamp's position uncertainty, metres)")]
    SigmaNotPositive {
        /// The sigma given.
        value: f64,
    },
    /// An id that is not a non-negative integer.
    #[error("id '{text}' is not a non-negative integer")]
    BadId {
        /// The field.
        text: String,
    },
    /// An id given to two lamps.
    #[error("id {id} is given twice (first on line {first_line})")]
    DuplicateId {
        /// The id.
        id: u64,
        /// The line of its first lamp.
        first_line: usize,
    },
}

/// `'a', 'b'`.
fn quoted<S: AsRef<str>>(names: &[S]) -> String {
    names
        .iter()
        .map(|n| format!("'{}'", n.as_ref()))
        .collect::<Vec<_>>()
        .join(", ")
}

/// The lamps of the lighting plan `bytes` (the CSV text), in row order; `source_name` names
/// it in errors, `default_sigma_m` is the sigma of a lamp whose row gives none.
///
/// Errors: [`Error::BadDefaultSigma`], or [`Error::Plan`] with the line and the problem.
pub fn parse_plan(
    bytes: &[u8],
    source_name: &str,
    default_sigma_m: f64,
) -> Result<Vec<PlanLamp>, Error> {
    if !(default_sigma_m.is_finite() && default_sigma_m > 0.0) {
        return Err(Error::BadDefaultSigma {
            value: default_sigma_m,
        });
    }
    let at = |line: usize, problem: PlanProblem| Error::Plan {
        source_name: source_name.to_string(),
        line,
        problem,
    };
    let text = std::str::from_utf8(bytes).map_err(|e| {
        let before = bytes.get(..e.valid_up_to()).unwrap_or_default();
        let line = before.iter().filter(|&&b| b == b'\n').count() + 1;
        at(line, PlanProblem::NotText)
    })?;
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    // The lines that hold values, numbered from 1 as an editor numbers them.
    let mut lines = text
        .split('\n')
        .map(str::trim)
        .enumerate()
        .map(|(i, l)| (i + 1, l))
        .filter(|(_, l)| !l.is_empty() && !l.starts_with('#'));
    let Some((header_line, header)) = lines.next() else {
        return Err(at(1, PlanProblem::NoHeader));
    };
    let columns = header_columns(header).map_err(|p| at(header_line, p))?;

    let mut lamps = Vec::new();
    let mut first_line_of: HashMap<u64, usize> = HashMap::new();
    for (line, row) in lines {
        let fields: Vec<&str> = row.split(',').map(str::trim).collect();
        if fields.len() != columns.count {
            return Err(at(
                line,
                PlanProblem::FieldCount {
                    found: fields.len(),
                    expected: columns.count,
                },
            ));
        }
        let field = |i: usize| fields.get(i).copied().unwrap_or_default();
        let number = |i: usize, column: &'static str| number(field(i), column);
        let [ix, iy, iz] = columns.xyz;
        let position = [number(ix, "x"), number(iy, "y"), number(iz, "z")];
        let mut p = [0.0; 3];
        for (v, parsed) in p.iter_mut().zip(position) {
            *v = parsed.map_err(|e| at(line, e))?;
        }
        let sigma_m = match columns.sigma {
            None => default_sigma_m,
            Some(i) => {
                let s = number(i, "sigma").map_err(|e| at(line, e))?;
                if s <= 0.0 {
                    return Err(at(line, PlanProblem::SigmaNotPositive { value: s }));
                }
                s
            }
        };
        let id = match columns.id {
            None => lamps.len() as u64,
            Some(i) => {
                let text = field(i);
                if text.is_empty() {
                    return Err(at(line, PlanProblem::EmptyField { column: "id" }));
                }
                text.parse::<u64>().map_err(|_| {
                    at(
                        line,
                        PlanProblem::BadId {
                            text: text.to_string(),
                        },
                    )
                })?
            }
        };
        if let Some(&first_line) = first_line_of.get(&id) {
            return Err(at(line, PlanProblem::DuplicateId { id, first_line }));
        }
        first_line_of.insert(id, line);
        lamps.push(PlanLamp {
            id,
            position: p,
            sigma_m,
            line,
        });
    }
    if lamps.is_empty() {
        return Err(at(header_line, PlanProblem::NoRows));
    }
    Ok(lamps)
}

/// Where each column of a plan is.
#[derive(Debug, Clone, Copy)]
struct Columns {
    /// Columns in the header.
    count: usize,
    /// The indices of x, y and z.
    xyz: [usize; 3],
    /// The index of id.
    id: Option<usize>,
    /// The index of sigma.
    sigma: Option<usize>,
}

/// The header's columns, checked: each named once, x, y and z there, no other than [`KNOWN`]
/// (names read without case).
fn header_columns(header: &str) -> Result<Columns, PlanProblem> {
    let given: Vec<&str> = header.split(',').map(str::trim).collect();
    let names: Vec<String> = given.iter().map(|c| c.to_ascii_lowercase()).collect();
    for (k, c) in names.iter().enumerate() {
        if c.is_empty() {
            return Err(PlanProblem::UnnamedColumn { column: k + 1 });
        }
        if names[..k].contains(c) {
            return Err(PlanProblem::DuplicateColumn { column: c.clone() });
        }
    }
    let unknown: Vec<String> = given
        .iter()
        .zip(&names)
        .filter(|(_, n)| !KNOWN.contains(&n.as_str()))
        .map(|(g, _)| (*g).to_string())
        .collect();
    let index = |name: &str| names.iter().position(|c| c == name);
    let missing: Vec<&'static str> = REQUIRED
        .into_iter()
        .filter(|r| index(r).is_none())
        .collect();
    let (Some(x), Some(y), Some(z)) = (index("x"), index("y"), index("z")) else {
        return Err(PlanProblem::MissingColumns { missing, unknown });
    };
    if !unknown.is_empty() {
        return Err(PlanProblem::UnknownColumns { unknown });
    }
    Ok(Columns {
        count: names.len(),
        xyz: [x, y, z],
        id: index("id"),
        sigma: index("sigma"),
    })
}

/// A field of the column `column` as a finite number.
fn number(text: &str, column: &'static str) -> Result<f64, PlanProblem> {
    if text.is_empty() {
        return Err(PlanProblem::EmptyField { column });
    }
    let v: f64 = text.parse().map_err(|_| PlanProblem::NotANumber {
        column,
        text: text.to_string(),
    })?;
    if !v.is_finite() {
        return Err(PlanProblem::NotFinite {
            column,
            text: text.to_string(),
        });
    }
    Ok(v)
}

impl Map {
    /// The map of a lighting plan or survey: its lamps, each with the covariance `sigma^2 I`,
    /// no calibration (`parameters` empty: the localiser takes the rig's nominal camera and
    /// priors), no log (`source_log` empty), `source_plan` naming the plan, and `rig` (None:
    /// the rig must be given when localising). `source_name` names the plan in the map and in
    /// errors. The landmarks' `observations` are 0.
    ///
    /// Errors: as [`parse_plan`].
    pub fn from_plan(
        bytes: &[u8],
        source_name: &str,
        default_sigma_m: f64,
        rig: Option<Rig>,
    ) -> Result<Self, Error> {
        let lamps = parse_plan(bytes, source_name, default_sigma_m)?;
        Ok(Self {
            landmarks: lamps
                .iter()
                .map(|l| {
                    let v = l.sigma_m * l.sigma_m;
                    MapLandmark {
                        id: l.id,
                        position: l.position,
                        covariance: [[v, 0.0, 0.0], [0.0, v, 0.0], [0.0, 0.0, v]],
                        observations: 0,
                    }
                })
                .collect(),
            parameters: Vec::new(),
            rig,
            source_log: String::new(),
            source_plan: Some(source_name.to_string()),
            created_unix_s: SystemTime::now()
                .duration_since(UNIX_EPOCH)
                .map_or(0, |d| d.as_secs()),
            common_error: None,
        })
    }

    /// [`Map::from_plan`] of the file at `path` (named in the map and in errors as given).
    ///
    /// Errors: [`Error::Io`] when the file cannot be read, else as [`parse_plan`].
    pub fn import_plan(path: &Path, default_sigma_m: f64, rig: Option<Rig>) -> Result<Self, Error> {
        let bytes = std::fs::read(path).map_err(|source| Error::Io {
            path: path.to_path_buf(),
            source,
        })?;
        Self::from_plan(&bytes, &path.display().to_string(), default_sigma_m, rig)
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used)]

    use super::*;

    fn lamps(text: &str) -> Vec<PlanLamp> {
        parse_plan(text.as_bytes(), "plan.csv", DEFAULT_LAMP_SIGMA_M).unwrap()
    }

    /// The line and problem of a refused plan, and its one-line message.
    fn refused(text: &[u8]) -> (usize, PlanProblem, String) {
        match parse_plan(text, "plan.csv", DEFAULT_LAMP_SIGMA_M).expect_err("refused") {
            e @ Error::Plan { .. } => {
                let message = e.to_string();
                assert!(!message.contains('\n'), "{message}");
                let Error::Plan { line, problem, .. } = e else {
                    unreachable!()
                };
                (line, problem, message)
            }
            e => panic!("not a plan error: {e}"),
        }
    }

    #[test]
    fn a_plan_reads_in_any_column_order_with_comments_and_spaces() {
        let got = lamps(
            "\u{feff}# hall 3\r\n\r\nZ, sigma ,x,Y,id\r\n 7.0, 0.01, 1.5, -2.25, 12\r\n\
             # a comment between rows\n6.9,0.05,3.5,-2,4\n",
        );
        assert_eq!(
            got,
            vec![
                PlanLamp {
                    id: 12,
                    position: [1.5, -2.25, 7.0],
                    sigma_m: 0.01,
                    line: 4
                },
                PlanLamp {
                    id: 4,
                    position: [3.5, -2.0, 6.9],
                    sigma_m: 0.05,
                    line: 6
                },
            ]
        );
    }

    #[test]
    fn without_id_and_sigma_lamps_are_numbered_in_row_order_with_the_default_sigma() {
        let got = parse_plan(b"x,y,z\n0,0,7\n4,0,7\n8,0,7.1", "p", 0.05).unwrap();
        assert_eq!(got.iter().map(|l| l.id).collect::<Vec<_>>(), [0, 1, 2]);
        assert!(got.iter().all(|l| l.sigma_m == 0.05));
        assert_eq!(got[2].position, [8.0, 0.0, 7.1]);
    }

    #[test]
    fn a_plan_makes_a_map_without_calibration_or_rig() {
        let map = Map::from_plan(b"id,x,y,z,sigma\n3,1,2,7,0.1\n", "hall.csv", 0.02, None).unwrap();
        assert_eq!(map.source_plan.as_deref(), Some("hall.csv"));
        assert_eq!(map.source_log, "");
        assert!(map.rig.is_none() && map.parameters.is_empty() && map.common_error.is_none());
        let l = map.landmarks[0];
        assert_eq!((l.id, l.position, l.observations), (3, [1.0, 2.0, 7.0], 0));
        let v = 0.1 * 0.1;
        assert_eq!(l.covariance, [[v, 0.0, 0.0], [0.0, v, 0.0], [0.0, 0.0, v]]);
    }

    #[test]
    fn an_empty_file_or_one_without_rows_is_refused() {
        for text in [&b""[..], b"\n\n", b"# only a comment\n", b"\xef\xbb\xbf"] {
            let (line, problem, message) = refused(text);
            assert_eq!((line, problem), (1, PlanProblem::NoHeader));
            assert!(
                message.starts_with("plan.csv:1: no header line"),
                "{message}"
            );
        }
        let (line, problem, message) = refused(b"# plan\nx,y,z\n\n# nothing\n");
        assert_eq!((line, problem), (2, PlanProblem::NoRows));
        assert_eq!(message, "plan.csv:2: no lamps: no row follows the header");
    }

    #[test]
    fn a_missing_required_column_is_named() {
        let (line, problem, message) = refused(b"x,y\n1,2\n");
        assert_eq!(line, 1);
        assert_eq!(
            problem,
            PlanProblem::MissingColumns {
                missing: vec!["z"],
                unknown: vec![]
            }
        );
        assert_eq!(
            message,
            "plan.csv:1: the header has no 'z' column (it needs x, y, z; optional: id, sigma)"
        );
        // A misspelt column is named too.
        let (_, _, message) = refused(b"x,y,zz\n1,2,3\n");
        assert!(message.ends_with("; it has unknown 'zz'"), "{message}");
        let (_, _, message) = refused(b"a;b;c\n");
        assert!(
            message.contains("no 'x', 'y', 'z' columns") && message.contains("'a;b;c'"),
            "{message}"
        );
    }

    #[test]
    fn unknown_unnamed_and_repeated_columns_are_refused() {
        let (_, problem, message) = refused(b"x,y,z,sigam,lux\n1,2,3,0.1,400\n");
        assert_eq!(
            problem,
            PlanProblem::UnknownColumns {
                unknown: vec!["sigam".to_string(), "lux".to_string()]
            }
        );
        assert_eq!(
            message,
            "plan.csv:1: unknown columns 'sigam', 'lux' (the columns are x, y, z and optionally id, sigma)"
        );
        let (_, problem, _) = refused(b"x,y,z,\n1,2,3,\n");
        assert_eq!(problem, PlanProblem::UnnamedColumn { column: 4 });
        let (_, problem, _) = refused(b"x,y,z,X\n1,2,3,4\n");
        assert_eq!(
            problem,
            PlanProblem::DuplicateColumn {
                column: "x".to_string()
            }
        );
    }

    #[test]
    fn a_row_with_the_wrong_number_of_fields_names_its_line() {
        let (line, problem, message) = refused(b"x,y,z\n1,2,3\n# c\n1,2\n");
        assert_eq!(
            (line, problem),
            (
                4,
                PlanProblem::FieldCount {
                    found: 2,
                    expected: 3
                }
            )
        );
        assert_eq!(message, "plan.csv:4: 2 fields, the header names 3 columns");
        let (line, problem, _) = refused(b"x,y,z\n1,2,3,\n");
        assert_eq!(
            (line, problem),
            (
                2,
                PlanProblem::FieldCount {
                    found: 4,
                    expected: 3
                }
            )
        );
    }

    #[test]
    fn a_field_that_is_not_a_finite_number_is_named() {
        let (line, problem, message) = refused(b"x,y,z\n1,2,3\n1,two,3\n");
        assert_eq!(line, 3);
        assert_eq!(
            problem,
            PlanProblem::NotANumber {
                column: "y",
                text: "two".to_string()
            }
        );
        assert_eq!(message, "plan.csv:3: y 'two' is not a number");
        for bad in ["nan", "NaN", "inf", "-inf", "infinity", "1e999"] {
            let (line, problem, _) = refused(format!("x,y,z\n1,2,{bad}\n").as_bytes());
            assert_eq!(line, 2);
            assert_eq!(
                problem,
                PlanProblem::NotFinite {
                    column: "z",
                    text: bad.to_string()
                },
                "{bad}"
            );
        }
        let (_, problem, message) = refused(b"x,y,z\n1,,3\n");
        assert_eq!(problem, PlanProblem::EmptyField { column: "y" });
        assert_eq!(message, "plan.csv:2: y is empty");
        let (_, problem, _) = refused(b"x,y,z\n\"1\",2,3\n");
        assert!(matches!(
            problem,
            PlanProblem::NotANumber { column: "x", .. }
        ));
        let (line, problem, _) = refused(b"x,y,z,sigma\n1,2,3,nan\n");
        assert_eq!(line, 2);
        assert!(matches!(
            problem,
            PlanProblem::NotFinite {
                column: "sigma",
                ..
            }
        ));
    }

    #[test]
    fn a_zero_or_negative_sigma_is_refused() {
        for (text, value) in [("0", 0.0), ("-0.01", -0.01), ("-0", -0.0)] {
            let (line, problem, message) =
                refused(format!("x,y,z,sigma\n1,2,3,0.1\n1,2,3,{text}\n").as_bytes());
            assert_eq!(
                (line, problem),
                (3, PlanProblem::SigmaNotPositive { value })
            );
            assert!(message.starts_with("plan.csv:3: sigma "), "{message}");
        }
        for bad in [0.0, -0.02, f64::NAN, f64::INFINITY] {
            let e = parse_plan(b"x,y,z\n1,2,3\n", "p", bad).expect_err("refused");
            assert!(matches!(e, Error::BadDefaultSigma { .. }), "{e:?}");
            assert!(e.to_string().contains("not a positive"), "{e}");
        }
    }

    #[test]
    fn duplicate_and_bad_ids_are_refused() {
        let (line, problem, message) = refused(b"id,x,y,z\n7,1,2,3\n8,1,2,3\n\n7,5,2,3\n");
        assert_eq!(
            (line, problem),
            (
                5,
                PlanProblem::DuplicateId {
                    id: 7,
                    first_line: 2
                }
            )
        );
        assert_eq!(message, "plan.csv:5: id 7 is given twice (first on line 2)");
        for bad in ["-1", "1.5", "x", "1e3"] {
            let (line, problem, _) = refused(format!("id,x,y,z\n{bad},1,2,3\n").as_bytes());
            assert_eq!(
                (line, problem),
                (
                    2,
                    PlanProblem::BadId {
                        text: bad.to_string()
                    }
                )
            );
        }
        let (_, problem, _) = refused(b"id,x,y,z\n,1,2,3\n");
        assert_eq!(problem, PlanProblem::EmptyField { column: "id" });
    }

    #[test]
    fn a_file_that_is_not_text_names_the_line() {
        let (line, problem, message) = refused(b"x,y,z\n1,2,3\n1,\xff,3\n");
        assert_eq!((line, problem), (3, PlanProblem::NotText));
        assert_eq!(message, "plan.csv:3: not UTF-8 text");
    }
}
