//! A ROS 2 bag's schema text and CDR message (vehicle_log::ros2): any bytes parse or fail,
//! decode or fail, never panic, hang or allocate without bound. The input is a schema text, a
//! NUL, then a message; the message is also decoded as a `sensor_msgs/msg/Image` and a
//! `nav_msgs/msg/Odometry` of the standard definitions.
#![no_main]

use libfuzzer_sys::fuzz_target;
use vehicle_log::ros2::{cdr, msgdef::MsgDefs};

const HEADER: &str = "================================================================================\n\
MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n\
================================================================================\n\
MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n";

fuzz_target!(|data: &[u8]| {
    let (schema, message) = match data.iter().position(|&b| b == 0) {
        Some(i) => (&data[..i], &data[i + 1..]),
        None => (data, &[][..]),
    };
    if let Ok(text) = std::str::from_utf8(schema)
        && let Ok(defs) = MsgDefs::parse("p/T", text)
    {
        let _ = cdr::decode(&defs, message);
    }
    let image = format!(
        "std_msgs/Header header\nuint32 height\nuint32 width\nstring encoding\nuint8 is_bigendian\nuint32 step\nuint8[] data\n{HEADER}"
    );
    if let Ok(defs) = MsgDefs::parse("sensor_msgs/msg/Image", &image) {
        let _ = cdr::decode(&defs, data);
    }
});
