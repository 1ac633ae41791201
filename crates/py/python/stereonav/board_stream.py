"""The camera board's feature stream (``board-icd.md`` section 3): decoding and encoding.

The board sends one packet per stereo frame over a byte stream that may arrive in any
chunking, with bytes lost or corrupted. :class:`StreamDecoder` takes the bytes as they come
and returns the good frames; corrupt packets and garbage are skipped and counted.
:func:`encode_packet` writes a packet as the board does (for tests and emulators).
"""

from __future__ import annotations

from typing import NamedTuple, Union

import numpy as np
import numpy.typing as npt

from . import _native
from ._arrays import FEATURE_DTYPE as _FEATURE_DTYPE
from ._errors import InputError, InputTypeError

__all__ = ["Frame", "StreamDecoder", "StreamStats", "encode_packet"]

#: Anything that exposes bytes: ``bytes``, ``bytearray``, ``memoryview`` or a ``uint8`` array.
BytesLike = Union[bytes, bytearray, memoryview, npt.NDArray[np.uint8]]

_U32_MAX = (1 << 32) - 1
_U64_MAX = (1 << 64) - 1


#: One good packet: a stereo frame's features as the board sent them (a frozen native object).
#:
#: Attributes: ``frame`` (int, the frame counter, u32, +1 per stereo frame, wraps), ``t_us``
#: (int, mid-exposure timestamp, microseconds, on the vehicle's clock), ``flags`` (int, bit 0:
#: the left camera overflowed ``MAX_FEATURES``; bit 1: the right one did), ``lost_before``
#: (int, frames lost just before this one: the gap in counters modulo 2**32), ``left`` and
#: ``right`` (numpy.ndarray of FEATURE_DTYPE, shape (N,): the features of each camera in the
#: board's order), ``left_overflow`` and ``right_overflow`` (bool, the two flags).
Frame = _native.Frame


class StreamStats(NamedTuple):
    """The decoder's counters."""

    #: Good packets.
    packets: int
    #: Packets rejected (version, reserved bits, counts, CRC, or cut off by the end).
    corrupt: int
    #: Frames lost: the sum of the gaps in frame counters between good packets.
    lost: int
    #: Bytes that were not part of a good packet.
    bytes_skipped: int


def _as_bytes(name: str, data: object) -> bytes:
    if isinstance(data, bytes):
        return data
    if isinstance(data, (bytearray, memoryview)):
        return bytes(data)
    if isinstance(data, np.ndarray):
        if data.dtype != np.uint8:
            raise InputTypeError(f"{name} array dtype is {data.dtype}, expected uint8")
        return data.tobytes()
    raise InputTypeError(
        f"{name} must be bytes, bytearray, memoryview or a uint8 array, "
        f"got {type(data).__qualname__}"
    )


class StreamDecoder:
    """Push decoder of the board's byte stream.

    Feed the bytes as they arrive, in chunks of any size, with :meth:`push`; each call
    returns the frames the chunk completed. At the end of the stream call :meth:`finish`: a
    packet still incomplete is corrupt, and the packets inside its claimed length are still
    found. The decoder holds at most one packet of bytes and never fails on bad data.

    Examples
    --------
    >>> import numpy as np, stereonav
    >>> left = np.array([(160, 320, 1 << 20)], dtype=stereonav.FEATURE_DTYPE)
    >>> packet = stereonav.encode_packet(left, left[:0], frame=7, t_us=1000)
    >>> decoder = stereonav.StreamDecoder()
    >>> frames = decoder.push(packet[:10]) + decoder.push(packet[10:]) + decoder.finish()
    >>> [(f.frame, f.t_us, f.left["x_q4"].tolist()) for f in frames]
    [(7, 1000, [160])]
    >>> decoder.stats
    StreamStats(packets=1, corrupt=0, lost=0, bytes_skipped=0)
    """

    def __init__(self) -> None:
        self._native = _native.StreamDecoder()

    def push(self, data: BytesLike) -> list[Frame]:
        """Decode a chunk of the stream; return the frames it completed, in stream order.

        Raises :class:`stereonav.InputTypeError` (a ``TypeError``) if ``data`` is not
        bytes-like. The GIL is released while decoding.
        """
        return self._native.push(_as_bytes("data", data))

    def finish(self) -> list[Frame]:
        """End the stream; return the frames found in a packet cut off by the end."""
        return self._native.finish()

    @property
    def stats(self) -> StreamStats:
        """The counters so far: packets, corrupt, lost, bytes_skipped."""
        return StreamStats(*self._native.stats)

    @property
    def buffered(self) -> int:
        """Bytes held waiting for the rest of a packet (at most 16,396)."""
        return int(self._native.buffered)


def _records(name: str, features: object) -> bytes:
    if not isinstance(features, np.ndarray):
        raise InputTypeError(f"{name} must be a numpy array of FEATURE_DTYPE, got {type(features).__qualname__}")
    if features.dtype.names != ("x_q4", "y_q4", "r"):
        raise InputTypeError(f"{name} dtype is {features.dtype}, expected FEATURE_DTYPE")
    if features.ndim != 1:
        raise InputError(f"{name} shape is {features.shape}, expected (N,)")
    return np.ascontiguousarray(features, dtype=_FEATURE_DTYPE).tobytes()


def _checked(name: str, value: object, high: int) -> int:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise InputTypeError(f"{name} must be an int, got {type(value).__qualname__}")
    if not 0 <= int(value) <= high:
        raise InputError(f"{name} {int(value)} is outside 0..={high}")
    return int(value)


def encode_packet(
    left: npt.NDArray[np.void],
    right: npt.NDArray[np.void],
    *,
    frame: int,
    t_us: int,
    left_overflow: bool = False,
    right_overflow: bool = False,
) -> bytes:
    """Write one packet as the board does (``board-icd.md`` section 3).

    Parameters
    ----------
    left, right : numpy.ndarray of FEATURE_DTYPE, shape (N,)
        Each camera's features in the board's order, at most 1023 each.
    frame : int
        Frame counter, ``0 ..= 2**32 - 1``.
    t_us : int
        Timestamp in microseconds, ``0 ..= 2**64 - 1``.
    left_overflow, right_overflow : bool
        The overflow flags.

    Returns
    -------
    bytes
        The packet: sync, header, features, CRC-32.

    Raises
    ------
    InputTypeError
        (a ``TypeError``) arrays of another dtype, or counters that are not integers.
    InputError
        (a ``ValueError``) more than 1023 features a side, or a counter out of range.
    """
    flags = (1 if left_overflow else 0) | (2 if right_overflow else 0)
    return _native.encode_packet(
        _checked("frame", frame, _U32_MAX),
        _checked("t_us", t_us, _U64_MAX),
        flags,
        _records("left", left),
        _records("right", right),
    )
