"""ROS 2 bags (MCAP, ``ros2msg`` schemas, CDR messages) written by two independent writers,
for the tests of ``vehicle-interfaces.md`` 4.1 (``test_ros2_bag.py``):

- :class:`McapRos2Bag`: ``mcap_ros2.writer.Writer`` (mcap-ros2-support), with the standard
  message definitions written out here (:data:`MSGDEFS`, ``ros2msg`` text as rosbag2 stores
  it: the type's fields, then each dependency after a line of 80 ``=`` and ``MSG: pkg/Type``);
- :class:`RosbagsBag`: ``rosbags.rosbag2.Writer`` (version 9, MCAP storage), with rosbags'
  own built-in definitions (its ROS 2 Humble type store). It writes a bag directory; the
  ``.mcap`` file inside is what the stack reads.

Both take the same calls (:class:`BagWriter`): an image (raw ``sensor_msgs/msg/Image`` or
``sensor_msgs/msg/CompressedImage``) or an odometry sample at a stamp, then :meth:`close`,
which returns the MCAP file. Log times are the stamps (as a recorder's would be, in order).
:func:`read_odometry` reads a bag's odometry back with mcap_ros2's decoder, as the reference
for the stack's own CDR decoder; :func:`rewrite` writes a bag again through either writer.
"""

from __future__ import annotations

import pathlib
from collections.abc import Iterator, Sequence
from typing import Any, Optional, Protocol

import numpy as np
import numpy.typing as npt

#: The line between a type and each of its dependencies in ``ros2msg`` text.
SEPARATOR = "=" * 80

_HEADER = """builtin_interfaces/Time stamp
string frame_id"""
_TIME = """int32 sec
uint32 nanosec"""


def _msgdef(fields: str, *deps: tuple[str, str]) -> str:
    parts = [fields.strip() + "\n"]
    for name, text in deps:
        parts.append(f"{SEPARATOR}\nMSG: {name}\n{text.strip()}\n")
    return "".join(parts)


#: The ``ros2msg`` definitions of the three types, with their dependencies (comments and
#: defaults as in the ROS 2 sources, so that the stack's parser meets them).
MSGDEFS: dict[str, str] = {
    "sensor_msgs/msg/Image": _msgdef(
        """
# This message contains an uncompressed image
std_msgs/Header header # Header timestamp should be acquisition time of image
uint32 height                # image height, that is, number of rows
uint32 width                 # image width, that is, number of columns
string encoding       # Encoding of pixels -- channel meaning, ordering, size
uint8 is_bigendian    # is this data bigendian?
uint32 step           # Full row length in bytes
uint8[] data          # actual matrix data, size is (step * rows)
""",
        ("std_msgs/Header", _HEADER),
        ("builtin_interfaces/Time", _TIME),
    ),
    "sensor_msgs/msg/CompressedImage": _msgdef(
        """
std_msgs/Header header # Header timestamp should be acquisition time of image
string format                # Specifies the format of the data
uint8[] data                 # Compressed image buffer
""",
        ("std_msgs/Header", _HEADER),
        ("builtin_interfaces/Time", _TIME),
    ),
    "nav_msgs/msg/Odometry": _msgdef(
        """
# This represents an estimate of a position and velocity in free space.
std_msgs/Header header
string child_frame_id
geometry_msgs/PoseWithCovariance pose
geometry_msgs/TwistWithCovariance twist
""",
        ("std_msgs/Header", _HEADER),
        ("builtin_interfaces/Time", _TIME),
        ("geometry_msgs/PoseWithCovariance", "Pose pose\nfloat64[36] covariance"),
        ("geometry_msgs/Pose", "Point position\nQuaternion orientation"),
        ("geometry_msgs/Point", "float64 x\nfloat64 y\nfloat64 z"),
        ("geometry_msgs/Quaternion", "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1"),
        ("geometry_msgs/TwistWithCovariance", "Twist twist\nfloat64[36] covariance"),
        ("geometry_msgs/Twist", "Vector3  linear\nVector3  angular"),
        ("geometry_msgs/Vector3", "float64 x\nfloat64 y\nfloat64 z"),
    ),
}

IMAGE = "sensor_msgs/msg/Image"
COMPRESSED = "sensor_msgs/msg/CompressedImage"
ODOMETRY = "nav_msgs/msg/Odometry"


def stamp(t_us: int) -> tuple[int, int]:
    """``(sec, nanosec)`` of a time in microseconds."""
    return t_us // 1_000_000, (t_us % 1_000_000) * 1000


class Raw:
    """A ``sensor_msgs/msg/Image``'s content: the pixels and how they are laid out."""

    def __init__(
        self,
        data: bytes,
        width: int,
        height: int,
        encoding: str,
        step: int,
    ) -> None:
        self.data, self.width, self.height = data, width, height
        self.encoding, self.step = encoding, step

    @classmethod
    def of(cls, pixels: npt.NDArray[Any], encoding: str) -> Raw:
        """An image from a ``(H, W)`` or ``(H, W, C)`` array, rows packed."""
        array = np.ascontiguousarray(pixels)
        height, width = array.shape[:2]
        return cls(array.tobytes(), width, height, encoding, array.nbytes // height)


class Compressed:
    """A ``sensor_msgs/msg/CompressedImage``'s content."""

    def __init__(self, data: bytes, format: str) -> None:
        self.data, self.format = data, format


class BagWriter(Protocol):
    """What both writers do."""

    def image(self, topic: str, t_us: int, payload: Raw | Compressed) -> None: ...

    def odom(self, topic: str, t_us: int, vx: float, vy: float, vtheta: float) -> None: ...

    def close(self) -> pathlib.Path: ...


def _header(t_us: int, frame_id: str) -> dict[str, Any]:
    sec, nanosec = stamp(t_us)
    return {"stamp": {"sec": sec, "nanosec": nanosec}, "frame_id": frame_id}


class McapRos2Bag:
    """A bag written by ``mcap_ros2.writer.Writer`` with :data:`MSGDEFS` (zstd chunks)."""

    name = "mcap_ros2"

    def __init__(self, path: pathlib.Path) -> None:
        from mcap_ros2.writer import Writer

        self.path = path
        self._file = path.open("wb")
        self._writer = Writer(self._file)
        self._schemas: dict[str, Any] = {}

    def _schema(self, type_name: str) -> Any:
        if type_name not in self._schemas:
            self._schemas[type_name] = self._writer.register_msgdef(type_name, MSGDEFS[type_name])
        return self._schemas[type_name]

    def image(self, topic: str, t_us: int, payload: Raw | Compressed) -> None:
        header = _header(t_us, topic.strip("/").split("/")[0])
        if isinstance(payload, Raw):
            schema, message = self._schema(IMAGE), {
                "header": header,
                "height": payload.height,
                "width": payload.width,
                "encoding": payload.encoding,
                "is_bigendian": 0,
                "step": payload.step,
                "data": payload.data,
            }
        else:
            schema, message = self._schema(COMPRESSED), {
                "header": header,
                "format": payload.format,
                "data": payload.data,
            }
        self._writer.write_message(topic, schema, message, log_time=t_us * 1000)

    def odom(self, topic: str, t_us: int, vx: float, vy: float, vtheta: float) -> None:
        vector = lambda x, y, z: {"x": x, "y": y, "z": z}  # noqa: E731
        message = {
            "header": _header(t_us, "odom"),
            "child_frame_id": "base_link",
            "pose": {
                "pose": {
                    "position": vector(0.0, 0.0, 0.0),
                    "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0},
                },
                "covariance": [0.0] * 36,
            },
            "twist": {
                "twist": {"linear": vector(vx, vy, 0.0), "angular": vector(0.0, 0.0, vtheta)},
                "covariance": [0.0] * 36,
            },
        }
        self._writer.write_message(topic, self._schema(ODOMETRY), message, log_time=t_us * 1000)

    def close(self) -> pathlib.Path:
        self._writer.finish()
        self._file.close()
        return self.path


class RosbagsBag:
    """A bag written by ``rosbags.rosbag2.Writer`` (version 9, MCAP storage) with rosbags'
    built-in ROS 2 Humble definitions. ``path`` is the bag directory to create; :meth:`close`
    returns the ``.mcap`` file in it."""

    name = "rosbags"

    def __init__(self, path: pathlib.Path) -> None:
        from rosbags.rosbag2 import StoragePlugin, Writer
        from rosbags.typesys import Stores, get_typestore

        self.path = path
        self._store = get_typestore(Stores.ROS2_HUMBLE)
        self._writer = Writer(path, version=9, storage_plugin=StoragePlugin.MCAP)
        self._writer.open()
        self._connections: dict[str, Any] = {}
        self._types = self._store.types

    def _connection(self, topic: str, type_name: str) -> Any:
        if topic not in self._connections:
            self._connections[topic] = self._writer.add_connection(
                topic, type_name, typestore=self._store
            )
        return self._connections[topic]

    def _header(self, t_us: int, frame_id: str) -> Any:
        sec, nanosec = stamp(t_us)
        return self._types["std_msgs/msg/Header"](
            stamp=self._types["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec),
            frame_id=frame_id,
        )

    def _write(self, topic: str, type_name: str, t_us: int, message: Any) -> None:
        data = self._store.serialize_cdr(message, type_name)
        self._writer.write(self._connection(topic, type_name), t_us * 1000, data)

    def image(self, topic: str, t_us: int, payload: Raw | Compressed) -> None:
        header = self._header(t_us, topic.strip("/").split("/")[0])
        data = np.frombuffer(payload.data, dtype=np.uint8)
        if isinstance(payload, Raw):
            message = self._types[IMAGE](
                header=header,
                height=payload.height,
                width=payload.width,
                encoding=payload.encoding,
                is_bigendian=0,
                step=payload.step,
                data=data,
            )
            self._write(topic, IMAGE, t_us, message)
        else:
            message = self._types[COMPRESSED](header=header, format=payload.format, data=data)
            self._write(topic, COMPRESSED, t_us, message)

    def odom(self, topic: str, t_us: int, vx: float, vy: float, vtheta: float) -> None:
        t = self._types
        vector = t["geometry_msgs/msg/Vector3"]
        message = t[ODOMETRY](
            header=self._header(t_us, "odom"),
            child_frame_id="base_link",
            pose=t["geometry_msgs/msg/PoseWithCovariance"](
                pose=t["geometry_msgs/msg/Pose"](
                    position=t["geometry_msgs/msg/Point"](x=0.0, y=0.0, z=0.0),
                    orientation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
                ),
                covariance=np.zeros(36),
            ),
            twist=t["geometry_msgs/msg/TwistWithCovariance"](
                twist=t["geometry_msgs/msg/Twist"](
                    linear=vector(x=vx, y=vy, z=0.0), angular=vector(x=0.0, y=0.0, z=vtheta)
                ),
                covariance=np.zeros(36),
            ),
        )
        self._write(topic, ODOMETRY, t_us, message)

    def close(self) -> pathlib.Path:
        self._writer.close()
        return self.path / f"{self.path.name}.mcap"


WRITERS = {"mcap_ros2": McapRos2Bag, "rosbags": RosbagsBag}


def writer(name: str, directory: pathlib.Path, stem: str) -> McapRos2Bag | RosbagsBag:
    """The writer ``name`` of a new bag named ``stem`` in ``directory``."""
    if name == "mcap_ros2":
        return McapRos2Bag(directory / f"{stem}.mcap")
    return RosbagsBag(directory / stem)


def decoded_messages(path: pathlib.Path, topics: Sequence[str]) -> Iterator[tuple[Any, Any, Any]]:
    """``(schema, channel, decoded message)`` of ``topics`` in log order, decoded by
    mcap_ros2's decoder (its own CDR decoder and ``ros2msg`` parser; the reader
    ``mcap_ros2.reader.read_ros2_messages`` does the same and is deprecated for this)."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    with path.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for schema, channel, _, msg in reader.iter_decoded_messages(topics=list(topics)):
            yield schema, channel, msg


def read_odometry(path: pathlib.Path, topic: str) -> npt.NDArray[np.float64]:
    """The odometry topic's ``(t_us, vx, vy, vtheta)`` rows in log order, decoded by
    mcap_ros2 (:func:`decoded_messages`)."""
    rows = []
    for _, _, msg in decoded_messages(path, [topic]):
        t_us = msg.header.stamp.sec * 1_000_000 + msg.header.stamp.nanosec // 1000
        twist = msg.twist.twist
        rows.append((t_us, twist.linear.x, twist.linear.y, twist.angular.z))
    return np.array(rows, dtype=np.float64).reshape(-1, 4)


def rewrite(
    source: pathlib.Path, name: str, directory: pathlib.Path, stem: str, topics: Sequence[str]
) -> pathlib.Path:
    """The ROS 2 bag ``source`` read by mcap_ros2's reader (decoded by its schemas) and
    written again by writer ``name``: the image and odometry messages of ``topics``, stamps
    (to the microsecond) and fields as read, in the order read."""
    out = writer(name, directory, stem)
    for schema_record, channel, msg in decoded_messages(source, topics):
        schema = schema_record.name if schema_record is not None else ""
        topic = channel.topic
        t_us = msg.header.stamp.sec * 1_000_000 + msg.header.stamp.nanosec // 1000
        if schema == IMAGE:
            out.image(topic, t_us, Raw(bytes(msg.data), msg.width, msg.height, msg.encoding, msg.step))
        elif schema == COMPRESSED:
            out.image(topic, t_us, Compressed(bytes(msg.data), msg.format))
        elif schema == ODOMETRY:
            twist = msg.twist.twist
            out.odom(topic, t_us, twist.linear.x, twist.linear.y, twist.angular.z)
        else:
            raise ValueError(f"{topic}: {schema} is neither an image nor odometry")
    return out.close()
