//! Robot logs with camera images (vehicle-interfaces.md 4.1): ROS 2 bags in MCAP (rosbag2's
//! MCAP storage or any writer of the `ros2msg` profile), whose camera and odometry topics the
//! caller names ([`Ros2Topics`], [`crate::LogReader::set_ros2_topics`]).
//!
//! | role | ROS 2 type | fields read |
//! |---|---|---|
//! | left, right images | `sensor_msgs/msg/Image` or `sensor_msgs/msg/CompressedImage` | `header.stamp`; `width`, `height`, `encoding`, `step`, `data` or `format`, `data` |
//! | odometry | `nav_msgs/msg/Odometry` | `header.stamp`, `twist.twist.linear.x`, `.y`, `twist.twist.angular.z` |
//!
//! A named topic's schema must be `ros2msg` text of one of these types, its messages `cdr`; the
//! fields are looked up in the schema the file carries ([`msgdef`]) and each message decoded by
//! it ([`cdr`]), so a writer that adds fields, or writes big-endian CDR, reads all the same. A
//! topic of another type is refused by its name. The pixels are not decoded here (see the
//! `host-board` crate): an image is handed on as its message holds it ([`ImagePayload`]).

pub mod cdr;
pub mod msgdef;

use std::fmt;

use cdr::Value;
use msgdef::{Array, Base, MsgDefs, Prim};

use crate::types::OdomSample;

/// The topics of a ROS 2 bag the stack reads: the two cameras and the wheel odometry.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct Ros2Topics {
    /// The left camera's images.
    pub left: String,
    /// The right camera's images.
    pub right: String,
    /// The wheel odometry.
    pub odom: String,
}

impl Ros2Topics {
    /// The role of `topic`, if it is one of these. A topic named for two roles is its first.
    pub fn role(&self, topic: &str) -> Option<Role> {
        Role::ALL.into_iter().find(|r| self.topic(*r) == topic)
    }

    /// The topic named for `role`.
    pub fn topic(&self, role: Role) -> &str {
        match role {
            Role::Left => &self.left,
            Role::Right => &self.right,
            Role::Odom => &self.odom,
        }
    }
}

/// What a named topic is for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Role {
    /// The left camera.
    Left,
    /// The right camera.
    Right,
    /// The odometry.
    Odom,
}

impl Role {
    /// Every role, in [`Role::index`] order.
    pub const ALL: [Role; 3] = [Role::Left, Role::Right, Role::Odom];

    /// 0, 1, 2.
    pub fn index(self) -> usize {
        self as usize
    }

    /// The command-line option that names its topic.
    pub fn option(self) -> &'static str {
        match self {
            Role::Left => "--left",
            Role::Right => "--right",
            Role::Odom => "--odom",
        }
    }
}

impl fmt::Display for Role {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Role::Left => "left camera",
            Role::Right => "right camera",
            Role::Odom => "odometry",
        })
    }
}

/// Which camera an image is from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Side {
    /// The left camera.
    Left,
    /// The right camera.
    Right,
}

/// One camera image of a bag, its pixels as the message holds them.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CameraImage {
    /// Which camera.
    pub side: Side,
    /// `header.stamp` in microseconds (rounded down).
    pub t_us: u64,
    /// The message's log time, ns.
    pub log_time_ns: u64,
    /// The pixels.
    pub payload: ImagePayload,
}

/// An image's pixels as a message holds them.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ImagePayload {
    /// `sensor_msgs/msg/Image`.
    Raw {
        /// Columns.
        width: u32,
        /// Rows.
        height: u32,
        /// The pixel encoding (`mono8`, `rgb8`, ...).
        encoding: String,
        /// Bytes per row.
        step: u32,
        /// The rows.
        data: Vec<u8>,
    },
    /// `sensor_msgs/msg/CompressedImage`.
    Compressed {
        /// The `format` field (`jpeg`, `png`, or image_transport's `mono8; jpeg compressed
        /// mono8`).
        format: String,
        /// The file's bytes.
        data: Vec<u8>,
    },
}

/// The ROS 2 types each role accepts, for messages.
pub fn accepted_types(role: Role) -> &'static str {
    match role {
        Role::Left | Role::Right => "sensor_msgs/msg/Image or sensor_msgs/msg/CompressedImage",
        Role::Odom => "nav_msgs/msg/Odometry",
    }
}

/// How to read one named topic's messages: its schema and where the fields are.
#[derive(Debug, Clone)]
pub(crate) struct Plan {
    defs: MsgDefs,
    kind: Kind,
    sec: Vec<usize>,
    nanosec: Vec<usize>,
}

#[derive(Debug, Clone)]
enum Kind {
    Image {
        width: Vec<usize>,
        height: Vec<usize>,
        encoding: Vec<usize>,
        step: Vec<usize>,
        data: Vec<usize>,
    },
    Compressed {
        format: Vec<usize>,
        data: Vec<usize>,
    },
    Odometry {
        vx: Vec<usize>,
        vy: Vec<usize>,
        vtheta: Vec<usize>,
    },
}

/// What a field must be.
#[derive(Clone, Copy)]
enum Want {
    Integer,
    Float,
    Text,
    Bytes,
}

impl Want {
    fn fits(self, base: &Base, array: Array) -> bool {
        let Base::Prim(p) = base else { return false };
        match self {
            Want::Integer => {
                array == Array::No
                    && matches!(
                        p,
                        Prim::U8
                            | Prim::I8
                            | Prim::I16
                            | Prim::U16
                            | Prim::I32
                            | Prim::U32
                            | Prim::I64
                            | Prim::U64
                    )
            }
            Want::Float => array == Array::No && matches!(p, Prim::F32 | Prim::F64),
            Want::Text => array == Array::No && *p == Prim::String,
            Want::Bytes => array == Array::Sequence && matches!(p, Prim::U8 | Prim::I8),
        }
    }

    fn name(self) -> &'static str {
        match self {
            Want::Integer => "an integer",
            Want::Float => "a float",
            Want::Text => "a string",
            Want::Bytes => "uint8[]",
        }
    }
}

impl Plan {
    /// The plan for a channel of `role` whose schema is `schema_name` in `schema_encoding`
    /// with the text `schema`, and whose messages are in `message_encoding`. Errors are
    /// one line: the type or encoding that does not fit, or the field the schema lacks.
    pub(crate) fn new(
        role: Role,
        message_encoding: &str,
        schema: Option<(&str, &str, &[u8])>,
    ) -> Result<Self, String> {
        let Some((name, encoding, text)) = schema else {
            return Err(format!(
                "it has no schema (a ROS 2 topic must carry its ros2msg schema: {})",
                accepted_types(role)
            ));
        };
        let norm = msgdef::normalise_type_name(name);
        let type_ok = match role {
            Role::Left | Role::Right => {
                norm == "sensor_msgs/Image" || norm == "sensor_msgs/CompressedImage"
            }
            Role::Odom => norm == "nav_msgs/Odometry",
        };
        if !type_ok {
            return Err(format!("its type is {name}, not {}", accepted_types(role)));
        }
        if encoding != "ros2msg" {
            return Err(format!(
                "its schema {name} is encoded as {encoding:?}, not \"ros2msg\" (only ROS 2 .msg \
                 schemas are read)"
            ));
        }
        if message_encoding != "cdr" {
            return Err(format!(
                "its messages are encoded as {message_encoding:?}, not \"cdr\""
            ));
        }
        let text = std::str::from_utf8(text)
            .map_err(|_| format!("its schema {name} is not UTF-8 text"))?;
        let defs = MsgDefs::parse(name, text).map_err(|e| format!("its schema {name}: {e}"))?;
        let find = |path: &str, want: Want| -> Result<Vec<usize>, String> {
            match defs.resolve(path) {
                Some((idx, f)) if want.fits(&f.base, f.array) => Ok(idx),
                Some((_, f)) => Err(format!(
                    "its schema {name} has {path} as {f}, not {}",
                    want.name()
                )),
                None => Err(format!("its schema {name} has no field {path}")),
            }
        };
        let sec = find("header.stamp.sec", Want::Integer)?;
        let nanosec = find("header.stamp.nanosec", Want::Integer)?;
        let kind = match norm.as_str() {
            "sensor_msgs/Image" => Kind::Image {
                width: find("width", Want::Integer)?,
                height: find("height", Want::Integer)?,
                encoding: find("encoding", Want::Text)?,
                step: find("step", Want::Integer)?,
                data: find("data", Want::Bytes)?,
            },
            "sensor_msgs/CompressedImage" => Kind::Compressed {
                format: find("format", Want::Text)?,
                data: find("data", Want::Bytes)?,
            },
            _ => Kind::Odometry {
                vx: find("twist.twist.linear.x", Want::Float)?,
                vy: find("twist.twist.linear.y", Want::Float)?,
                vtheta: find("twist.twist.angular.z", Want::Float)?,
            },
        };
        Ok(Self {
            defs,
            kind,
            sec,
            nanosec,
        })
    }

    /// The schema's type, `pkg/Type`.
    pub(crate) fn type_name(&self) -> &str {
        self.defs.root()
    }

    /// Decodes one message: `(stamp in us, what it holds)`.
    pub(crate) fn decode(&self, data: &[u8]) -> Result<(u64, Decoded), String> {
        let msg = cdr::decode(&self.defs, data)?;
        let int = |idx: &[usize]| -> Result<i128, String> {
            match msg.at(idx) {
                Some(Value::Int(i)) => Ok(i128::from(*i)),
                Some(Value::UInt(u)) => Ok(i128::from(*u)),
                other => Err(format!("expected an integer, found {other:?}")),
            }
        };
        let float = |idx: &[usize], what: &str| -> Result<f64, String> {
            match msg.at(idx) {
                Some(Value::Float(x)) => Ok(*x),
                other => Err(format!("{what}: expected a float, found {other:?}")),
            }
        };
        let text = |idx: &[usize]| -> String {
            match msg.at(idx) {
                Some(Value::Str(s)) => s.clone(),
                _ => String::new(),
            }
        };
        let bytes = |idx: &[usize]| -> Vec<u8> {
            match msg.at(idx) {
                Some(Value::Bytes(b)) => b.to_vec(),
                _ => Vec::new(),
            }
        };
        let sec = int(&self.sec)?;
        let nanosec = int(&self.nanosec)?;
        if sec < 0 || !(0..1_000_000_000).contains(&nanosec) {
            return Err(format!(
                "header.stamp {sec} s {nanosec} ns is not a time after 1970"
            ));
        }
        let t_us = u64::try_from(sec * 1_000_000 + nanosec / 1000)
            .map_err(|_| "header.stamp out of range".to_owned())?;
        let decoded = match &self.kind {
            Kind::Image {
                width,
                height,
                encoding,
                step,
                data,
            } => {
                let u32_of = |idx: &[usize], what: &str| -> Result<u32, String> {
                    u32::try_from(int(idx)?).map_err(|_| format!("{what} out of range"))
                };
                Decoded::Image(ImagePayload::Raw {
                    width: u32_of(width, "width")?,
                    height: u32_of(height, "height")?,
                    encoding: text(encoding),
                    step: u32_of(step, "step")?,
                    data: bytes(data),
                })
            }
            Kind::Compressed { format, data } => Decoded::Image(ImagePayload::Compressed {
                format: text(format),
                data: bytes(data),
            }),
            Kind::Odometry { vx, vy, vtheta } => {
                let values = [
                    float(vx, "twist.twist.linear.x")?,
                    float(vy, "twist.twist.linear.y")?,
                    float(vtheta, "twist.twist.angular.z")?,
                ];
                match values.iter().position(|v| !v.is_finite()) {
                    Some(i) => Decoded::NonFinite(format!(
                        "{} is {}",
                        [
                            "twist.twist.linear.x",
                            "twist.twist.linear.y",
                            "twist.twist.angular.z"
                        ][i],
                        values[i]
                    )),
                    None => Decoded::Odom(OdomSample {
                        t_us,
                        vx: values[0],
                        vy: values[1],
                        vtheta: values[2],
                    }),
                }
            }
        };
        Ok((t_us, decoded))
    }
}

/// What a message of a named topic holds.
#[derive(Debug)]
pub(crate) enum Decoded {
    Image(ImagePayload),
    Odom(OdomSample),
    /// An odometry message whose velocities are not all finite (a driver's NaN): one line.
    NonFinite(String),
}

#[cfg(test)]
mod tests {
    use super::*;

    const IMAGE: &str = "std_msgs/Header header\nuint32 height\nuint32 width\nstring encoding\n\
        uint8 is_bigendian\nuint32 step\nuint8[] data\n\
        ================================================================================\n\
        MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n\
        ================================================================================\n\
        MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n";

    /// A CDR writer for the test, the encoding of the module docs.
    struct W {
        out: Vec<u8>,
        little: bool,
    }

    impl W {
        fn new(little: bool) -> Self {
            Self {
                out: vec![0, u8::from(little), 0, 0],
                little,
            }
        }
        fn align(&mut self, n: usize) {
            while !(self.out.len() - 4).is_multiple_of(n) {
                self.out.push(0);
            }
        }
        fn u32(&mut self, v: u32) {
            self.align(4);
            let b = if self.little {
                v.to_le_bytes()
            } else {
                v.to_be_bytes()
            };
            self.out.extend_from_slice(&b);
        }
        fn string(&mut self, s: &str) {
            self.u32(u32::try_from(s.len() + 1).unwrap());
            self.out.extend_from_slice(s.as_bytes());
            self.out.push(0);
        }
    }

    fn image_message(little: bool) -> Vec<u8> {
        let mut w = W::new(little);
        w.u32(1_700_000_000); // sec
        w.u32(123_456_789); // nanosec
        w.string("cam0");
        w.u32(2); // height
        w.u32(3); // width
        w.string("mono8");
        w.out.push(0); // is_bigendian
        w.u32(3); // step
        w.u32(6);
        w.out.extend_from_slice(&[1, 2, 3, 4, 5, 6]);
        w.out
    }

    #[test]
    fn image_in_both_byte_orders() {
        let plan = Plan::new(
            Role::Left,
            "cdr",
            Some(("sensor_msgs/msg/Image", "ros2msg", IMAGE.as_bytes())),
        )
        .unwrap();
        for little in [true, false] {
            let (t_us, decoded) = plan.decode(&image_message(little)).unwrap();
            assert_eq!(t_us, 1_700_000_000_123_456);
            let Decoded::Image(ImagePayload::Raw {
                width,
                height,
                encoding,
                step,
                data,
            }) = decoded
            else {
                panic!("not an image: {decoded:?}");
            };
            assert_eq!((width, height, step), (3, 2, 3));
            assert_eq!(encoding, "mono8");
            assert_eq!(data, [1, 2, 3, 4, 5, 6]);
        }
    }

    #[test]
    fn cut_and_foreign_messages_are_errors_not_panics() {
        let plan = Plan::new(
            Role::Right,
            "cdr",
            Some(("sensor_msgs/msg/Image", "ros2msg", IMAGE.as_bytes())),
        )
        .unwrap();
        let full = image_message(true);
        for n in 0..full.len() {
            assert!(plan.decode(&full[..n]).is_err(), "cut at {n}");
        }
        let mut pl = full.clone();
        pl[1] = 3;
        let e = plan.decode(&pl).unwrap_err();
        assert!(e.contains("encapsulation"), "{e}");
    }

    #[test]
    fn wrong_types_refused_by_name() {
        let e = Plan::new(
            Role::Odom,
            "cdr",
            Some(("sensor_msgs/msg/Image", "ros2msg", IMAGE.as_bytes())),
        )
        .unwrap_err();
        assert_eq!(
            e,
            "its type is sensor_msgs/msg/Image, not nav_msgs/msg/Odometry"
        );
        let e = Plan::new(
            Role::Left,
            "json",
            Some(("sensor_msgs/msg/Image", "ros2msg", IMAGE.as_bytes())),
        )
        .unwrap_err();
        assert!(e.contains("\"cdr\""), "{e}");
        let e = Plan::new(
            Role::Left,
            "cdr",
            Some((
                "sensor_msgs/msg/Image",
                "ros2msg",
                IMAGE.replace("uint32 step", "float32 step").as_bytes(),
            )),
        )
        .unwrap_err();
        assert_eq!(
            e,
            "its schema sensor_msgs/msg/Image has step as float32, not an integer"
        );
        let e = Plan::new(Role::Left, "cdr", None).unwrap_err();
        assert!(e.contains("no schema"), "{e}");
    }

    #[test]
    fn nested_empty_arrays_cannot_blow_up() {
        let mut text = String::from("p/A[200] a\n");
        for (name, next) in [("A", "B"), ("B", "C"), ("C", "D"), ("D", "E")] {
            text.push_str(&format!(
                "{}\nMSG: p/{name}\np/{next}[200] x\n",
                "=".repeat(80)
            ));
        }
        text.push_str(&format!("{}\nMSG: p/E\n", "=".repeat(80)));
        let defs = MsgDefs::parse("p/T", &text).unwrap();
        // Enough bytes for every count check: only the value budget stops 200^5 values.
        let mut message = vec![0, 1, 0, 0];
        message.resize(404, 0);
        let e = cdr::decode(&defs, &message).unwrap_err();
        assert!(e.contains("more values"), "{e}");
    }

    proptest::proptest! {
        /// Any bytes as a message of any of the three types: a value or an error, never a
        /// panic or a runaway allocation.
        #[test]
        fn any_bytes_decode_or_fail(bytes in proptest::collection::vec(proptest::prelude::any::<u8>(), 0..512), little in proptest::prelude::any::<bool>()) {
            let plan = Plan::new(Role::Left, "cdr", Some(("sensor_msgs/msg/Image", "ros2msg", IMAGE.as_bytes()))).unwrap();
            let mut message = vec![0, u8::from(little), 0, 0];
            message.extend_from_slice(&bytes);
            let _ = plan.decode(&message);
            let _ = plan.decode(&bytes);
        }

        /// Any text as a schema: parsed or refused, never a panic.
        #[test]
        fn any_schema_text_parses_or_fails(text in "[a-z_/0-9\\[\\]<=# \n]{0,200}") {
            let _ = MsgDefs::parse("p/T", &text);
            let _ = Plan::new(Role::Odom, "cdr", Some(("nav_msgs/msg/Odometry", "ros2msg", text.as_bytes())));
        }

        /// A valid image message cut or flipped anywhere: a value or an error.
        #[test]
        fn damaged_image_messages_never_panic(at in 0usize..64, bit in 0u8..8, little in proptest::prelude::any::<bool>()) {
            let plan = Plan::new(Role::Right, "cdr", Some(("sensor_msgs/msg/Image", "ros2msg", IMAGE.as_bytes()))).unwrap();
            let mut m = image_message(little);
            let i = at % m.len();
            m[i] ^= 1 << bit;
            let _ = plan.decode(&m);
        }
    }
}
