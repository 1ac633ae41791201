//! ROS 2 message definitions as an MCAP `ros2msg` schema carries them: the root type's `.msg`
//! text, then each type it uses as a block after a line of `=` and a line `MSG: pkg/Type`
//! (the layout rosbag2 and the MCAP `ros2` profile write).
//!
//! Only what decoding needs is kept: each type's fields in order, with their types. Constants
//! are skipped (CDR does not carry them), as are default values and comments.

use std::collections::HashMap;
use std::fmt;

/// Deepest nesting of message types a schema may have (sensor_msgs/Image has 3; a schema
/// whose types refer to each other in a cycle would otherwise never end).
pub const MAX_DEPTH: usize = 16;

/// A primitive of the ROS 2 interface definition language.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Prim {
    /// `bool`, one byte.
    Bool,
    /// `byte`, `char`, `uint8`.
    U8,
    /// `int8`.
    I8,
    /// `int16`.
    I16,
    /// `uint16`.
    U16,
    /// `int32`.
    I32,
    /// `uint32`.
    U32,
    /// `int64`.
    I64,
    /// `uint64`.
    U64,
    /// `float32`.
    F32,
    /// `float64`.
    F64,
    /// `string` (bounded or not).
    String,
    /// `wstring` (bounded or not).
    WString,
}

impl Prim {
    fn from_name(name: &str) -> Option<Self> {
        Some(match name {
            "bool" => Self::Bool,
            "byte" | "char" | "uint8" => Self::U8,
            "int8" => Self::I8,
            "int16" => Self::I16,
            "uint16" => Self::U16,
            "int32" => Self::I32,
            "uint32" => Self::U32,
            "int64" => Self::I64,
            "uint64" => Self::U64,
            "float32" => Self::F32,
            "float64" => Self::F64,
            "string" => Self::String,
            "wstring" => Self::WString,
            _ => return None,
        })
    }

    /// Bytes of one value in CDR (the length word of a string).
    pub fn size(self) -> usize {
        match self {
            Self::Bool | Self::U8 | Self::I8 => 1,
            Self::I16 | Self::U16 => 2,
            Self::I32 | Self::U32 | Self::F32 | Self::String | Self::WString => 4,
            Self::I64 | Self::U64 | Self::F64 => 8,
        }
    }

    /// The type's name in messages.
    pub fn name(self) -> &'static str {
        match self {
            Self::Bool => "bool",
            Self::U8 => "uint8",
            Self::I8 => "int8",
            Self::I16 => "int16",
            Self::U16 => "uint16",
            Self::I32 => "int32",
            Self::U32 => "uint32",
            Self::I64 => "int64",
            Self::U64 => "uint64",
            Self::F32 => "float32",
            Self::F64 => "float64",
            Self::String => "string",
            Self::WString => "wstring",
        }
    }
}

/// A field's element type.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Base {
    /// A primitive.
    Prim(Prim),
    /// A message type, by its full name `pkg/Type`.
    Msg(String),
}

/// Whether a field is one value or an array.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Array {
    /// One value.
    No,
    /// `T[N]`: exactly N, no length in CDR.
    Fixed(usize),
    /// `T[]` or `T[<=N]`: a length, then the elements.
    Sequence,
}

/// One field of a message type.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Field {
    /// Its name.
    pub name: String,
    /// Its element type.
    pub base: Base,
    /// One value or an array.
    pub array: Array,
}

impl fmt::Display for Field {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match &self.base {
            Base::Prim(p) => write!(f, "{}", p.name())?,
            Base::Msg(m) => write!(f, "{m}")?,
        }
        match self.array {
            Array::No => Ok(()),
            Array::Fixed(n) => write!(f, "[{n}]"),
            Array::Sequence => write!(f, "[]"),
        }
    }
}

/// A schema's message types: the root and every type it uses.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MsgDefs {
    root: String,
    types: HashMap<String, Vec<Field>>,
}

/// `pkg/msg/Type` and `pkg/Type` are one type; `pkg/Type` is how this module names it.
pub fn normalise_type_name(name: &str) -> String {
    let parts: Vec<&str> = name.split('/').collect();
    match parts.as_slice() {
        [pkg, "msg", ty] => format!("{pkg}/{ty}"),
        _ => name.to_owned(),
    }
}

impl MsgDefs {
    /// Parses the schema `text` of the type `name` (`pkg/msg/Type` or `pkg/Type`). Errors:
    /// a line that is not a field or a constant, a field's type that no block defines.
    pub fn parse(name: &str, text: &str) -> Result<Self, String> {
        let root = normalise_type_name(name);
        let mut types = HashMap::new();
        let mut current = root.clone();
        let mut fields = Vec::new();
        let package = |ty: &str| ty.split('/').next().unwrap_or_default().to_owned();
        let mut pkg = package(&root);
        let mut expect_msg_line = false;
        for (i, raw) in text.lines().enumerate() {
            let line = raw.split('#').next().unwrap_or_default().trim();
            if line.is_empty() {
                continue;
            }
            if line.len() >= 3 && line.bytes().all(|b| b == b'=') {
                types.insert(std::mem::take(&mut current), std::mem::take(&mut fields));
                expect_msg_line = true;
                continue;
            }
            if expect_msg_line {
                let Some(ty) = line.strip_prefix("MSG:") else {
                    return Err(format!(
                        "line {}: expected \"MSG: pkg/Type\" after a separator, found {line:?}",
                        i + 1
                    ));
                };
                current = normalise_type_name(ty.trim());
                pkg = package(&current);
                expect_msg_line = false;
                continue;
            }
            if let Some(field) =
                parse_line(line, &pkg).map_err(|e| format!("line {}: {e}", i + 1))?
            {
                fields.push(field);
            }
        }
        if !expect_msg_line {
            types.insert(current, fields);
        }
        let defs = Self { root, types };
        defs.check(&defs.root, 0)?;
        Ok(defs)
    }

    /// The root type's name, `pkg/Type`.
    pub fn root(&self) -> &str {
        &self.root
    }

    /// The fields of the type `name` (`pkg/Type`).
    pub fn fields(&self, name: &str) -> Option<&[Field]> {
        self.types.get(name).map(Vec::as_slice)
    }

    /// Every message type used by `name` is defined, no deeper than [`MAX_DEPTH`].
    fn check(&self, name: &str, depth: usize) -> Result<(), String> {
        if depth > MAX_DEPTH {
            return Err(format!("types nest deeper than {MAX_DEPTH} at {name}"));
        }
        let fields = self
            .types
            .get(name)
            .ok_or_else(|| format!("type {name} is used but not defined in the schema"))?;
        for field in fields {
            if let Base::Msg(m) = &field.base {
                self.check(m, depth + 1)?;
            }
        }
        Ok(())
    }

    /// The field at `path` (`header.stamp.sec`) from the root: its index at each level and the
    /// field itself. `None` if some name is not there or passes through an array.
    pub fn resolve(&self, path: &str) -> Option<(Vec<usize>, &Field)> {
        let mut ty = self.root.as_str();
        let mut indices = Vec::new();
        let mut names = path.split('.').peekable();
        while let Some(name) = names.next() {
            let fields = self.types.get(ty)?;
            let (i, field) = fields.iter().enumerate().find(|(_, f)| f.name == name)?;
            indices.push(i);
            if names.peek().is_none() {
                return Some((indices, field));
            }
            match (&field.base, field.array) {
                (Base::Msg(m), Array::No) => ty = m,
                _ => return None,
            }
        }
        None
    }
}

/// One line of a `.msg` block: a field, or `None` for a constant.
fn parse_line(line: &str, pkg: &str) -> Result<Option<Field>, String> {
    let mut tokens = line.split_whitespace();
    let ty = tokens.next().unwrap_or_default();
    let rest = line[ty.len()..].trim_start();
    // A constant is `TYPE NAME=VALUE` (the name may touch the `=`); a default value is
    // `TYPE name VALUE`.
    let name_end = rest
        .find(|c: char| c.is_whitespace() || c == '=')
        .unwrap_or(rest.len());
    let name = &rest[..name_end];
    if name.is_empty() {
        return Err(format!("a type without a field name: {line:?}"));
    }
    if rest[name_end..].trim_start().starts_with('=') {
        return Ok(None);
    }
    if !name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
        return Err(format!("bad field name {name:?}"));
    }
    let (element, array) = match ty.find('[') {
        None => (ty, Array::No),
        Some(open) => {
            let inside = ty[open + 1..]
                .strip_suffix(']')
                .ok_or_else(|| format!("bad array type {ty:?}"))?;
            let array = if inside.is_empty() || inside.starts_with("<=") {
                Array::Sequence
            } else {
                Array::Fixed(
                    inside
                        .parse()
                        .map_err(|_| format!("bad array length in {ty:?}"))?,
                )
            };
            (&ty[..open], array)
        }
    };
    // `string<=N`: a bounded string is a string on the wire.
    let element = element.split("<=").next().unwrap_or_default();
    let base = match Prim::from_name(element) {
        Some(p) => Base::Prim(p),
        None => Base::Msg(match element {
            // ROS 1's names, which some converted schemas still use.
            "Header" => "std_msgs/Header".to_owned(),
            "time" => "builtin_interfaces/Time".to_owned(),
            "duration" => "builtin_interfaces/Duration".to_owned(),
            e if e.contains('/') => normalise_type_name(e),
            "" => return Err(format!("bad type {ty:?}")),
            e => format!("{pkg}/{e}"),
        }),
    };
    Ok(Some(Field {
        name: name.to_owned(),
        base,
        array,
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    const IMAGE: &str = "\
# This message contains an uncompressed image
std_msgs/Header header # Header timestamp should be acquisition time of image
uint32 height                # image height, that is, number of rows
uint32 width                 # image width, that is, number of columns
string encoding       # Encoding of pixels -- channel meaning, ordering, size
uint8 is_bigendian    # is this data bigendian?
uint32 step           # Full row length in bytes
uint8[] data          # actual matrix data, size is (step * rows)

================================================================================
MSG: std_msgs/Header
# Standard metadata for higher-level stamped data types.
builtin_interfaces/Time stamp
string frame_id

================================================================================
MSG: builtin_interfaces/Time
# This message communicates ROS Time defined here:
int32 sec
uint32 nanosec
";

    #[test]
    fn parses_image_schema() {
        let defs = MsgDefs::parse("sensor_msgs/msg/Image", IMAGE).unwrap();
        assert_eq!(defs.root(), "sensor_msgs/Image");
        let (idx, f) = defs.resolve("header.stamp.nanosec").unwrap();
        assert_eq!(idx, vec![0, 0, 1]);
        assert_eq!(f.base, Base::Prim(Prim::U32));
        let (_, data) = defs.resolve("data").unwrap();
        assert_eq!(data.array, Array::Sequence);
        assert_eq!(data.to_string(), "uint8[]");
        assert!(defs.resolve("header.stamp.nope").is_none());
    }

    #[test]
    fn constants_defaults_and_bounds() {
        let text = "uint8 A=1\nint32 B = -2\nstring<=5 name \"x\"\nfloat64[9] k\nint16[<=3] s\nstring<=4[] t\n";
        let defs = MsgDefs::parse("p/T", text).unwrap();
        let fields = defs.fields("p/T").unwrap();
        let shown: Vec<String> = fields.iter().map(|f| format!("{f} {}", f.name)).collect();
        assert_eq!(
            shown,
            ["string name", "float64[9] k", "int16[] s", "string[] t"]
        );
    }

    #[test]
    fn undefined_and_cyclic_types_refused() {
        let e = MsgDefs::parse("p/T", "Other o\n").unwrap_err();
        assert!(e.contains("p/Other"), "{e}");
        let cyclic = format!("p/U u\n{}\nMSG: p/U\np/T t\n", "=".repeat(80));
        let e = MsgDefs::parse("p/T", &cyclic).unwrap_err();
        assert!(e.contains("deeper"), "{e}");
        let e =
            MsgDefs::parse("p/T", &format!("int32 a\n{}\nint32 b\n", "=".repeat(80))).unwrap_err();
        assert!(e.contains("MSG:"), "{e}");
    }
}
