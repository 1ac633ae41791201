"""Robot logs with camera images: ROS 2 bags in MCAP (``vehicle-interfaces.md`` section 4.1).

A vehicle without the camera board records its two cameras' images and its wheel odometry
as a ROS 2 bag (rosbag2's MCAP storage, or any writer of the ``ros2msg`` profile). The stack
replays such a bag directly -- :func:`stereonav.replay` and :func:`stereonav.localize` with
``left=``, ``right=`` and ``odom=`` naming its topics -- by running the board's arithmetic on
the host: each image to 8-bit gray (``mono8``; ``rgb8`` and ``bgr8`` with OpenCV's weights;
PNG and JPEG decoded), left and right paired by stamp (within a quarter of the frame
interval), the board's Harris detector on each with the rig's ``[camera]`` size and
``[board]`` registers.

For analysis and tests:

- :func:`read_bag` reads a bag whole as the replay reads it and hands back the stereo frames
  the host board detected (the board's features, raw pixel coordinates), what became of the
  images (:class:`ImageCounts`) and the odometry decoded from the bag;
- :func:`decode_image` is the host's decode of one PNG or JPEG file to gray, for comparing
  with other decoders.
"""

from __future__ import annotations

import dataclasses
import os
from typing import Optional, Union, final

import numpy as np
import numpy.typing as npt

from . import _native
from ._arrays import readonly as _readonly
from ._errors import InputTypeError
from .calibration import RigLike, _describe
from .logs import LogDamage
from .navigation import _path, _rig, _topic
from .simulation import ODOMETRY_DTYPE

__all__ = ["BagFrame", "ImageCounts", "Ros2Bag", "decode_image", "read_bag"]

#: One stereo frame of a bag, detected on the host (a frozen native object): what the board's
#: packet would have carried.
#:
#: Attributes: ``t_us`` (int, the frame's time: the left image's ``header.stamp`` in
#: microseconds), ``left`` and ``right`` (numpy.ndarray of FEATURE_DTYPE, shape (N,): each
#: image's features in the board's order, as :func:`stereonav.harris` returns them for the
#: image's gray pixels, raw (unrectified) pixel coordinates), ``overflow`` (bool: either image
#: had more than ``max_features`` features).
BagFrame = _native.BagFrame

#: What became of a bag's camera images (a frozen native object; ``==`` compares the counts).
#:
#: Attributes (int): ``left``, ``right`` (images read on each camera topic), ``frames``
#: (stereo frames detected), ``unpaired`` (images without a partner within a quarter of the
#: frame interval: frames with one image), ``wrong_size`` (another size than the rig's
#: ``[camera]``), ``unsupported`` (an encoding or format not read: not ``mono8``, ``rgb8``,
#: ``bgr8``, 8-bit PNG or JPEG), ``undecodable`` (bytes or a message that do not decode),
#: ``frames_dropped`` (frames lost because one of their images could not be read; those
#: images are counted above too); ``problems`` (list of str: the first problem of each kind,
#: one line each). The replay's ``SUMMARY.json`` has the same counts as ``images_left``,
#: ``images_right``, ``frames``, ``images_unpaired``, ``images_wrong_size``,
#: ``images_unsupported``, ``images_undecodable`` and ``image_frames_dropped``.
ImageCounts = _native.ImageCounts

#: ``bytes``, ``bytearray``, ``memoryview`` or a 1-D ``uint8`` array.
BytesLike = Union[bytes, bytearray, memoryview, npt.NDArray[np.uint8]]


@final
@dataclasses.dataclass(frozen=True, eq=False, repr=False)
class Ros2Bag:
    """A ROS 2 bag read whole by :func:`read_bag`, as the replay reads it.

    Every array is read-only.

    Attributes
    ----------
    path : str
        The file read.
    frames : tuple of BagFrame
        The stereo frames the host board paired and detected, in stamp order: each with
        ``t_us``, ``left``, ``right`` (:data:`stereonav.FEATURE_DTYPE` arrays, raw pixel
        coordinates: map them with :func:`stereonav.rectify_points` when the rig has
        ``[lens.*]`` tables) and ``overflow``. Empty when no camera topic was named.
    images : ImageCounts or None
        What became of the camera images; None when no camera topic was named.
    odometry : numpy.ndarray of ODOMETRY_DTYPE, shape (S,)
        The samples of the odometry topic in log order (not sorted): ``t_us`` (``<u8``,
        ``header.stamp``), ``vx``, ``vy`` (``<f8``, m/s, ``twist.twist.linear``), ``vtheta``
        (``<f8``, rad/s, ``twist.twist.angular.z``). Empty when no odometry topic was named.
    topics : dict of str to tuple of (str, str)
        Each named topic by its argument (``"left"``, ``"right"``, ``"odom"``): ``(topic,
        type)``, the type as the bag's schema names it (``"sensor_msgs/msg/Image"``).
    messages : dict of str to int
        Messages read on each named topic, by argument.
    warnings : tuple of str
        What looked wrong but did not stop the reading, one line each.
    truncated : str or None
        Why the bag ends early (cut short while recording), or None.
    damage : LogDamage
        What could not be read (damaged chunks, a cut); ``damage.damaged`` is False for an
        intact file.
    """

    path: str
    frames: tuple[BagFrame, ...]
    images: Optional[ImageCounts]
    odometry: npt.NDArray[np.void]
    topics: dict[str, tuple[str, str]]
    messages: dict[str, int]
    warnings: tuple[str, ...]
    truncated: Optional[str]
    damage: LogDamage

    @classmethod
    def _from_native(cls, path: str, native: _native.BagContents) -> Ros2Bag:
        t_us, values = native.odometry
        odometry = np.zeros(len(t_us), dtype=ODOMETRY_DTYPE)
        odometry["t_us"] = t_us
        for k, field in enumerate(("vx", "vy", "vtheta")):
            odometry[field] = values[:, k]
        topics = {argument: (topic, type_name) for argument, topic, type_name in native.topics}
        return cls(
            path=path,
            frames=tuple(native.frames),
            images=native.images,
            odometry=_readonly(odometry),
            topics=topics,
            messages={
                argument: count
                for argument, count in zip(("left", "right", "odom"), native.messages)
                if argument in topics
            },
            warnings=tuple(native.warnings),
            truncated=native.truncated,
            damage=native.damage,
        )

    def __repr__(self) -> str:
        ends = f", truncated ({self.truncated})" if self.truncated is not None else ""
        return (
            f"<stereonav.Ros2Bag {self.path!r}: {len(self.frames)} stereo frames, "
            f"{len(self.odometry)} odometry samples{ends}>"
        )


def read_bag(
    log_path: Union[str, "os.PathLike[str]"],
    rig_path: Optional[RigLike] = None,
    *,
    left: Optional[str] = None,
    right: Optional[str] = None,
    odom: Optional[str] = None,
) -> Ros2Bag:
    """Read a ROS 2 bag whole with the camera board on the host, as the replay reads it.

    In Rust with the GIL released: the bag (MCAP, ``ros2msg`` schemas, CDR messages) is read
    in log order by the replay's reader; every image of the ``left`` and ``right`` topics goes
    through the board on the host (gray, paired by stamp, the board's Harris arithmetic with
    the rig's ``[camera]`` size and ``[board]`` registers) exactly as in
    ``stereonav.replay(..., left=, right=, odom=)``, and the ``odom`` topic's
    ``nav_msgs/msg/Odometry`` messages are decoded by their schema. Nothing is estimated.

    Name the camera topics (both), the odometry topic, or all three: a bag without images
    (a robot's drive without cameras) can be read for its odometry alone, without a rig.

    Parameters
    ----------
    log_path : str or os.PathLike
        The bag's MCAP file (for a rosbag2 directory, the ``.mcap`` file inside it).
    rig_path : path or RigConfig, optional
        The rig file (or :func:`stereonav.load_rig`'s result): its ``[camera]`` size and
        ``[board]`` registers. Required with camera topics.
    left, right : str, keyword-only
        The camera topics (``sensor_msgs/msg/Image`` or ``sensor_msgs/msg/CompressedImage``),
        both or neither.
    odom : str, keyword-only
        The odometry topic (``nav_msgs/msg/Odometry``).

    Returns
    -------
    Ros2Bag

    Raises
    ------
    InputTypeError
        (a ``TypeError``) an argument has the wrong type.
    InputError
        (a ``ValueError``) one camera topic without the other, nothing named, camera topics
        without a rig, an empty topic name; a named topic the bag does not have (the message
        names the bag's topics and types) or of another type; the file cannot be read (the
        ``OSError`` is the ``__cause__``) or is not MCAP; the rig is not valid. An image that
        cannot be read is no error: it is counted in :attr:`Ros2Bag.images`.

    Examples
    --------
    >>> bag = stereonav.read_bag("drive.mcap", "rig.toml", left="/cam0/image_raw",
    ...                          right="/cam1/image_raw", odom="/odom")  # doctest: +SKIP
    >>> len(bag.frames), bag.images.unpaired, bag.odometry["vx"].mean()   # doctest: +SKIP
    """
    path = _path("log_path", log_path)
    native_rig = None if rig_path is None else _rig("rig_path", rig_path)
    native = _native.read_bag(
        path,
        native_rig,
        _topic("left", left),
        _topic("right", right),
        _topic("odom", odom),
    )
    return Ros2Bag._from_native(path, native)


def decode_image(data: BytesLike) -> npt.NDArray[np.uint8]:
    """Decode a PNG or JPEG file's bytes to gray as the board on the host does.

    The decode of ``sensor_msgs/msg/CompressedImage`` images in :func:`read_bag` and the
    replay (the Rust ``image`` crate), at the file's own size: 8-bit gray as it is, 8-bit RGB
    to gray with OpenCV's ``COLOR_RGB2GRAY`` weights. For comparing with other decoders
    (``cv2.imdecode``) on the same bytes; JPEG decoders may differ by a grey level here and
    there (the standard leaves the inverse DCT's rounding to them).

    Parameters
    ----------
    data : bytes, bytearray, memoryview or numpy.ndarray of uint8
        The file's bytes.

    Returns
    -------
    numpy.ndarray of uint8, shape (H, W)
        The gray image, a new C-contiguous array.

    Raises
    ------
    InputTypeError
        (a ``TypeError``) ``data`` is not bytes-like.
    InputError
        (a ``ValueError``) the bytes are neither PNG nor JPEG, do not decode, or hold pixels
        the host does not read (16 bits, an alpha channel).
    """
    if isinstance(data, bytes):
        raw = data
    elif isinstance(data, (bytearray, memoryview)):
        raw = bytes(data)
    elif isinstance(data, np.ndarray) and data.dtype == np.uint8 and data.ndim == 1:
        raw = data.tobytes()
    else:
        raise InputTypeError(
            "data must be bytes, bytearray, memoryview or a 1-D uint8 array, "
            f"got {_describe(data)}"
        )
    return _native.decode_image(raw)
