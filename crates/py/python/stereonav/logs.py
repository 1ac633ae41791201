"""Vehicle logs (MCAP, ``vehicle-interfaces.md`` section 4) read whole, for analysis.

:func:`read_log` hands back what a vehicle logged, as it was logged: the camera board's byte
stream and the frames decoded from it, the odometry, the rig of the ``/rig`` message, and the
simulator's truth when the log has it. Nothing is estimated; :func:`stereonav.replay` runs the
stack on the same file.
"""

from __future__ import annotations

import dataclasses
import os
from typing import Optional, Union, final

import numpy as np
import numpy.typing as npt

from . import _native
from ._arrays import readonly as _readonly
from .board_stream import Frame, StreamDecoder, StreamStats
from .navigation import _path
from .rig import Camera, RigConfig
from .simulation import ODOMETRY_DTYPE, TRAJECTORY_DTYPE

__all__ = ["LogDamage", "LogTruth", "LostSpan", "VehicleLog", "read_log"]

#: What could not be read in a damaged log, in total (frozen; see :attr:`VehicleLog.damage`):
#: ``damaged`` (bool), ``spans`` (list of :class:`LostSpan`, the first 256 in file order),
#: ``spans_total``, ``bytes_lost``, ``chunks_lost``, ``messages_lost`` (dict topic -> count,
#: or None when nothing counts them), ``header_damaged``, ``tail_damaged``, ``cut``,
#: ``summary`` (``"intact"``, ``"damaged"``, ``"absent"``), ``summary_problem``,
#: ``unverified_chunks`` (chunks read without a CRC check), ``repaired_chunks`` (chunks mended:
#: one flipped bit explained the damage).
LogDamage = _native.LogDamage
#: One stretch of a log that could not be read (frozen): ``offset`` and ``bytes`` in the file,
#: ``start_ns`` and ``end_ns`` (the lost messages' log times when ``exact_times``, else the
#: good messages' around the loss), ``chunks``, ``messages`` (dict topic -> count, or None),
#: ``why`` (one line).
LostSpan = _native.LostSpan


def _table(
    dtype: np.dtype[np.void], t_us: npt.NDArray[np.uint64], values: npt.NDArray[np.float64]
) -> npt.NDArray[np.void]:
    """A read-only structured array: ``t_us`` then one field per column of ``values``."""
    out = np.zeros(len(t_us), dtype=dtype)
    out["t_us"] = t_us
    for k, field in enumerate(dtype.names[1:] if dtype.names else ()):
        out[field] = values[:, k]
    return _readonly(out)


@final
@dataclasses.dataclass(frozen=True, eq=False, repr=False)
class LogTruth:
    """The simulator's truth logged with a run (``/truth/*`` topics).

    Every array is read-only. A log may have part of the truth only; what it lacks is empty
    (or None).

    Attributes
    ----------
    trajectory : numpy.ndarray of TRAJECTORY_DTYPE, shape (F,)
        The true pose at each stereo frame (``/truth/pose``), in log order: ``t_us``
        (``<u8``, the frame's timestamp), ``x``, ``y`` (``<f8``, metres), ``theta`` (``<f8``,
        radians) in the world frame.
    landmark_ids : numpy.ndarray of uint64, shape (N,)
        The simulator's landmark ids (``/truth/landmarks``), in the order logged.
    landmarks : numpy.ndarray of float64, shape (N, 3)
        The landmarks' world positions ``x, y, z`` in metres, row ``i`` for
        ``landmark_ids[i]``.
    camera : Camera or None
        The true camera parameters (``/truth/camera``).
    """

    trajectory: npt.NDArray[np.void]
    landmark_ids: npt.NDArray[np.uint64]
    landmarks: npt.NDArray[np.float64]
    camera: Optional[Camera]

    def __repr__(self) -> str:
        camera = "camera" if self.camera is not None else "no camera"
        return (
            f"<stereonav.LogTruth: {len(self.trajectory)} poses, "
            f"{len(self.landmark_ids)} landmarks, {camera}>"
        )


@final
@dataclasses.dataclass(frozen=True, eq=False, repr=False)
class VehicleLog:
    """A vehicle log read whole (:func:`read_log`), as it was logged.

    Every array is read-only.

    Attributes
    ----------
    path : str
        The file read.
    stream : bytes
        The camera board's byte stream as received (``board-icd.md`` section 3): every
        ``/fpga/features`` message concatenated in log order.
    chunks : int
        The number of ``/fpga/features`` messages the stream came in.
    frames : list of Frame
        The good packets of :attr:`stream`, decoded with :class:`StreamDecoder` in stream
        order (not sorted by timestamp); corrupt packets and garbage are skipped.
    stream_stats : StreamStats
        The decoder's counters after the whole stream: ``packets``, ``corrupt``, ``lost``,
        ``bytes_skipped``.
    odometry : numpy.ndarray of ODOMETRY_DTYPE, shape (S,)
        The ``/odom`` samples in log order (not sorted): ``t_us`` (``<u8``), ``vx``, ``vy``
        (``<f8``, m/s), ``vtheta`` (``<f8``, rad/s).
    rig_json : str or None
        The text of the first ``/rig`` message (the rig file's tables as a JSON object), or
        None when the log has none. :attr:`rig` parses it.
    truth : LogTruth or None
        The simulator's truth, or None when the log has none of it (a real vehicle's log).
    warnings : tuple of str
        What looked wrong but did not stop the reading (a known topic with a foreign
        encoding, a message on an undeclared channel), one line each.
    truncated : str or None
        Why the log ends early (a file cut short while recording), or None when it was read
        to its end. Everything readable before that point is here.
    damage : LogDamage
        What could not be read: chunks whose CRC failed, bytes skipped where the record
        framing was lost, the rest of a chunk cut by the end of the file, a damaged header or
        summary. ``damage.damaged`` is False for an intact log. Everything else was read:
        the records after a damaged chunk are here (the stream of a lost stretch is simply
        missing from :attr:`stream`; the decoder resynchronises).
    ignored_topics : tuple of str
        The topics that are not vehicle topics (or foreign channels of their names), each
        once, in the order met; their messages are skipped.
    ignored_messages : int
        How many messages those topics had.
    topics : tuple of str
        The vehicle topics with a channel in the log, each once, in the order met.
    """

    path: str
    stream: bytes
    chunks: int
    frames: list[Frame]
    stream_stats: StreamStats
    odometry: npt.NDArray[np.void]
    rig_json: Optional[str]
    truth: Optional[LogTruth]
    warnings: tuple[str, ...]
    truncated: Optional[str]
    damage: LogDamage
    ignored_topics: tuple[str, ...]
    ignored_messages: int
    topics: tuple[str, ...]
    _contents: _native.LogContents

    @classmethod
    def _from_native(cls, path: str, native: _native.LogContents) -> VehicleLog:
        """The typed log of a native one, the stream decoded and the arrays copied out once."""
        stream = bytes(native.stream)
        decoder = StreamDecoder()
        frames = decoder.push(stream) + decoder.finish()
        return cls(
            path=path,
            stream=stream,
            chunks=native.chunks,
            frames=frames,
            stream_stats=decoder.stats,
            odometry=_table(ODOMETRY_DTYPE, *native.odometry),
            rig_json=native.rig_json,
            truth=_truth(native),
            warnings=tuple(native.warnings),
            truncated=native.truncated,
            damage=native.damage,
            ignored_topics=tuple(native.ignored_topics),
            ignored_messages=native.ignored_messages,
            topics=tuple(native.topics),
            _contents=native,
        )

    @property
    def rig(self) -> Optional[RigConfig]:
        """The rig of the first ``/rig`` message, as :func:`stereonav.load_rig` reads a rig
        file, or None when the log has no ``/rig``.

        Raises
        ------
        InputError
            (a ``ValueError``) the message is not a valid rig; the error names the file's
            ``/rig``, the key and the problem (:attr:`rig_json` still has the text).
        """
        raw = self._contents.rig()
        return None if raw is None else RigConfig._from_native(raw)

    def __repr__(self) -> str:
        ends = f", truncated ({self.truncated})" if self.truncated is not None else ""
        if self.damage.damaged and self.truncated is None:
            ends = f", damaged ({self.damage.spans_total} spans lost)"
        truth = ", with truth" if self.truth is not None else ""
        return (
            f"<stereonav.VehicleLog {self.path!r}: {len(self.frames)} frames, "
            f"{len(self.odometry)} odometry samples{truth}{ends}>"
        )


def _truth(native: _native.LogContents) -> Optional[LogTruth]:
    """The truth of a native log, or None when it has none."""
    trajectory = _table(TRAJECTORY_DTYPE, *native.truth_poses)
    ids, positions = native.truth_landmarks
    camera_values = native.truth_camera
    camera = None if camera_values is None else Camera.from_array(camera_values)
    if len(trajectory) == 0 and len(ids) == 0 and camera is None:
        return None
    return LogTruth(
        trajectory=trajectory,
        landmark_ids=_readonly(ids),
        landmarks=_readonly(positions),
        camera=camera,
    )


def read_log(path: Union[str, "os.PathLike[str]"]) -> VehicleLog:
    """Read a vehicle log (MCAP, ``vehicle-interfaces.md`` section 4) whole, for analysis.

    In Rust with the GIL released, the file is read in log order (CRCs checked); then the
    board's byte stream is decoded into frames. Records are kept as logged: neither frames nor
    odometry are sorted by timestamp (:func:`stereonav.replay` sorts them).

    Parameters
    ----------
    path : str or os.PathLike
        The vehicle log.

    Returns
    -------
    VehicleLog

    Raises
    ------
    InputTypeError
        (a ``TypeError``) ``path`` is not a ``str`` or ``os.PathLike``.
    InputError
        (a ``ValueError``) the file cannot be opened or read (the message names it, and the
        ``OSError``, e.g. ``FileNotFoundError``, is the ``__cause__``), is not an MCAP file,
        has a malformed message on a vehicle topic, or is an MCAP file without the vehicle
        topics (``... is not a vehicle log: it has no /fpga/features or /odom channel ...``,
        naming the topics it has, as :func:`stereonav.replay` says). A damaged or cut log is
        not an error: every record that can still be read is read, :attr:`VehicleLog.damage`
        says what was lost and where, :attr:`VehicleLog.truncated` why it ends early.

    Examples
    --------
    >>> log = stereonav.read_log("paper-experiment.mcap")              # doctest: +SKIP
    >>> len(log.frames), len(log.odometry), log.rig.nominal.baseline  # doctest: +SKIP
    (961, ..., ...)
    """
    checked = _path("path", path)
    return VehicleLog._from_native(checked, _native.read_log(checked))
