"""The whole stack: the navigator fed frame by frame, and the replay of a vehicle log.

The method runs in two phases (crate ``nav``): phase 1 self-calibrates the camera parameters
from frame pairs while the pose is dead reckoning from the odometry; once the calibration is
stable the navigator switches to phase 2, EKF SLAM with the camera parameters in the state,
which builds the map of ceiling lamps (landmarks) and keeps the pose on it. Phase 1 can be
skipped: phase 2 then starts at the first frame from the rig's nominal values and priors, as
in the paper's experiment.

- :class:`Navigator` is fed by hand, in time order: the odometry
  (:meth:`Navigator.push_odometry`) up to a stereo frame's time, then the frame's left and
  right features (:meth:`Navigator.push_frame`, as the board sends them or in pixels); each
  frame returns a :class:`FrameOutcome`.
- :func:`replay` runs the navigator on a whole vehicle log (MCAP,
  ``vehicle-interfaces.md`` section 4), as ``stereonav replay`` does, and returns a
  :class:`Replay`: the summary (``SUMMARY.json``), the trajectory, the map, the camera
  parameters over time, the NIS of every accepted observation, the errors against the
  simulator's truth when the log has it, and the writers of ``EST.mcap``, ``SUMMARY.json``
  and ``TRAJ.csv`` (section 5).

Everything runs in Rust with the GIL released; arrays come back as copies.
"""

from __future__ import annotations

import dataclasses
import json
import os
from typing import Any, NamedTuple, Optional, Union, final

import numpy as np
import numpy.typing as npt

from . import _native
from ._arrays import readonly as _readonly
from ._errors import InputError, InputTypeError
from .calibration import RigLike, _count, _describe, _odometry_tables, _times
from ._arrays import bindings as _bindings
from ._arrays import gated as _gated
from .rig import CAMERA_PARAMETERS, VEHICLE_PARAMETERS, RigConfig, _native_rig
from .simulation import TRAJECTORY_DTYPE

__all__ = [
    "FRAME_INFO_DTYPE",
    "MAP_LANDMARK_DTYPE",
    "NIS_DTYPE",
    "ODOMETRY_LOOKAHEAD_US",
    "PHASES",
    "CameraHistory",
    "FrameOutcome",
    "MapSnapshot",
    "Navigator",
    "ParamEstimate",
    "Replay",
    "replay",
]

#: The navigator's phases, in the order of the per-frame phase codes: code 0 is
#: ``"calibrating"`` (phase 1: self-calibration, dead reckoning), code 1 is ``"navigating"``
#: (phase 2: EKF SLAM).
PHASES: tuple[str, ...] = tuple(_native.phase_names())
#: How far past a frame's timestamp a log's replay feeds the odometry before the frame,
#: microseconds: a frame stamped ``t`` was exposed at odometry time ``t - time_offset``
#: (``vehicle-interfaces.md`` 1.2), after ``t`` for a negative offset. Feeding a
#: :class:`Navigator` the same way gives exactly what :func:`replay` gives.
ODOMETRY_LOOKAHEAD_US: int = _native.ODOMETRY_LOOKAHEAD_US
#: One landmark of the map: ``id`` (``<u8``, stable for its life), its world position ``x, y,
#: z`` (``<f8``, metres), its per-axis 1-sigma ``sx, sy, sz`` (``<f8``, metres), its position
#: ``covariance`` (``<f8``, shape (3, 3), m**2) and ``observations`` (``<u8``: the measurement
#: that created it and every accepted one since). The rows of ``SUMMARY.json``'s
#: ``landmarks``, with the covariance.
MAP_LANDMARK_DTYPE = np.dtype(
    [
        ("id", "<u8"),
        ("x", "<f8"),
        ("y", "<f8"),
        ("z", "<f8"),
        ("sx", "<f8"),
        ("sy", "<f8"),
        ("sz", "<f8"),
        ("covariance", "<f8", (3, 3)),
        ("observations", "<u8"),
    ]
)
#: What the navigator did at one stereo frame (the ``/est/frame`` messages of ``EST.mcap``):
#: ``t_us`` (``<u8``), ``phase`` (``u1``, an index into :data:`PHASES`), ``accepted`` and
#: ``rejected`` (``<u4``: landmark observations the gate let through and left out) and
#: ``landmarks`` (``<u4``: landmarks in the map after the frame).
FRAME_INFO_DTYPE = np.dtype(
    [
        ("t_us", "<u8"),
        ("phase", "u1"),
        ("accepted", "<u4"),
        ("rejected", "<u4"),
        ("landmarks", "<u4"),
    ]
)
#: One accepted landmark observation: ``t_us`` (``<u8``, the frame), ``id`` (``<u8``, the
#: landmark) and ``nis`` (``<f8``, its normalised innovation squared, 4 dof: chi-square with
#: 4 degrees of freedom, mean 4, when the filter is consistent).
NIS_DTYPE = np.dtype([("t_us", "<u8"), ("id", "<u8"), ("nis", "<f8")])

_F64 = npt.NDArray[np.float64]
_U64 = npt.NDArray[np.uint64]
_U64_MAX = (1 << 64) - 1
_U32_MAX = (1 << 32) - 1
#: Q12.4 board coordinates: pixels are ``x_q4 / 16``, ``y_q4 / 16`` (``board-icd.md``).
_Q4_SCALE = 16.0


# --- Results -------------------------------------------------------------------------------


class ParamEstimate(NamedTuple):
    """One camera parameter's estimate."""

    #: The value (the nominal one when the parameter is not estimated).
    value: float
    #: Its 1-sigma (0 when it is held fixed).
    sigma: float


class CameraHistory(NamedTuple):
    """The camera parameters over a replay (K samples): after every phase-1 solve, then
    after every phase-2 frame."""

    #: ``(K,)`` uint64: time of the sample.
    t_us: _U64
    #: ``(K,)`` uint8: the phase that produced it, an index into :data:`PHASES`.
    phase: npt.NDArray[np.uint8]
    #: ``(K, 10)`` float64: every parameter, columns in :data:`CAMERA_PARAMETERS` order.
    values: _F64
    #: ``(K, 10)`` float64: their 1-sigma (0 for those held fixed).
    sigmas: _F64


class MapSnapshot(NamedTuple):
    """The map at one instant of a replay."""

    #: Time, microseconds.
    t_us: int
    #: ``(N,)`` :data:`MAP_LANDMARK_DTYPE`: every landmark, by id.
    landmarks: npt.NDArray[np.void]


def _camera_dict(raw: tuple[_F64, _F64]) -> dict[str, ParamEstimate]:
    return _estimates(CAMERA_PARAMETERS, raw)


def _vehicle_dict(raw: tuple[_F64, _F64]) -> dict[str, ParamEstimate]:
    return _estimates(VEHICLE_PARAMETERS, raw)


def _estimates(names: tuple[str, ...], raw: tuple[_F64, _F64]) -> dict[str, ParamEstimate]:
    values, sigmas = raw
    return {name: ParamEstimate(float(v), float(s)) for name, v, s in zip(names, values, sigmas)}


def _map(raw: tuple[_U64, _F64, _F64, _U64]) -> npt.NDArray[np.void]:
    ids, positions, covariances, observations = raw
    out = np.zeros(len(ids), dtype=MAP_LANDMARK_DTYPE)
    out["id"] = ids
    if len(ids):
        out["x"], out["y"], out["z"] = positions[:, 0], positions[:, 1], positions[:, 2]
        sigma = np.sqrt(np.clip(np.diagonal(covariances, axis1=1, axis2=2), 0.0, None))
        out["sx"], out["sy"], out["sz"] = sigma[:, 0], sigma[:, 1], sigma[:, 2]
        out["covariance"] = covariances
    out["observations"] = observations
    return _readonly(out)


@final
@dataclasses.dataclass(frozen=True, eq=False, repr=False)
class Replay:
    """A whole vehicle log replayed (:func:`replay`).

    Every array is read-only; :attr:`summary` and :attr:`truth` are new dicts at each access.

    Attributes
    ----------
    summary : dict
        ``SUMMARY.json`` (``vehicle-interfaces.md`` section 5): ``frames``, ``corrupt``,
        ``lost`` (int), ``phase_switch_t_us`` (int or None), ``pose`` (``{t_us, x, y,
        theta}`` at the last frame, or None), ``camera`` (``{name: {value, sigma}}`` for every
        parameter of :data:`CAMERA_PARAMETERS`), ``landmarks`` (``[{id, x, y, z, sigma: [sx,
        sy, sz], observations}]``), and ``phase1_skipped``, ``warnings``, ``counts`` and
        ``truth`` (as :attr:`truth`). Numbers that are not finite are None.
    trajectory : numpy.ndarray of TRAJECTORY_DTYPE, shape (F,)
        The pose at every stereo frame, in time order: ``t_us`` (``<u8``), ``x``, ``y``
        (``<f8``, metres), ``theta`` (``<f8``, radians) in the world frame (the robot at the
        first frame). Dead reckoning in phase 1, the filter's in phase 2.
    pose_covariance : numpy.ndarray of float64, shape (F, 3, 3)
        The covariance of each pose.
    phase : numpy.ndarray of uint8, shape (F,)
        The phase each frame was processed in: an index into :data:`PHASES` (0 calibrating,
        1 navigating).
    frames : numpy.ndarray of FRAME_INFO_DTYPE, shape (F,)
        What the navigator did at each frame.
    nis : numpy.ndarray of NIS_DTYPE, shape (K,)
        Every accepted landmark observation with its NIS, in frame order.
    landmarks : numpy.ndarray of MAP_LANDMARK_DTYPE, shape (N,)
        The final map, by id (empty when phase 2 never ran).
    maps : tuple of MapSnapshot
        The map about once a second of data time in phase 2, and at the end.
    camera : dict of str to ParamEstimate
        The final camera parameters, every one of :data:`CAMERA_PARAMETERS`.
    vehicle : dict of str to ParamEstimate
        The final vehicle parameters, every one of :data:`VEHICLE_PARAMETERS` (the summary's
        ``vehicle``).
    camera_history : CameraHistory
        The camera parameters after every phase-1 solve, then every phase-2 frame.
    phase_switch_t_us : int or None
        When phase 2 started: None when phase 1 was skipped (a log that ends in phase 1 is
        handed over at its last frame).
    phase1_skipped : bool
        Phase 2 ran from the rig's nominal values and priors.
    counts : dict of str to int
        What was read, decoded and associated: ``frames`` (good packets), ``corrupt``,
        ``lost``, ``bytes_skipped``, ``frames_out_of_order``, ``odometry``,
        ``stereo_matches``, ``tracks``, ``confirmed_tracks``, ``pairs``, ``landmark_pairs``
        (frame pairs: ``calibrate_log`` only), ``tracker_resets``, ``phase1_solves`` (solves
        of phase 1's batch over every frame), and what a damaged log lost:
        ``log_spans_lost``, ``log_bytes_lost``, ``log_chunks_lost``, ``log_time_lost_ms``
        (docs/logs.md), ``landmarks_merged`` (landmarks the map-level guard merged into
        another as the same lamp), ``features_outside_field`` (board features outside the
        field of use through a lens; docs/halls.md), ``loops_closed`` (loops closed by the
        constellation of the lamps held while the pose was lost), ``loops_refused`` (frames
        whose held lamps fitted one place the lost pose's covariance rules out, refused as a
        lattice alias) and ``lamps_held_mapped`` (those lamps mapped from where they were
        held; docs/halls.md, "Loops").
    warnings : tuple of str
        What limits the result without stopping it (a log cut short, phase 1 never stable,
        frames without odometry, updates the filter refused), one line each.
    truth : dict or None
        When the log carries the simulator's truth, the errors against it (``SUMMARY.json``'s
        ``truth``): ``landmark_rms_m``, ``landmark_rms_aligned_m``, ``landmarks_matched``,
        ``landmarks_unmatched``, ``landmarks_duplicate`` (of the unmatched, a lamp's second
        landmark), ``lamps_missed``, ``match_radius_m``, ``ate_rms_m``, ``ate_max_m``,
        ``heading_rms_rad``, ``camera`` (``{name: estimate - truth}``) and
        ``consistency`` (``pose_nees``, ``pose_frames``, ``final_pose_nees``, ``state_nees``,
        ``state_dof``: the filter's NEES against the truth; ``None`` without a phase 2).
    """

    trajectory: npt.NDArray[np.void]
    pose_covariance: _F64
    phase: npt.NDArray[np.uint8]
    frames: npt.NDArray[np.void]
    nis: npt.NDArray[np.void]
    landmarks: npt.NDArray[np.void]
    maps: tuple[MapSnapshot, ...]
    camera: dict[str, ParamEstimate]
    vehicle: dict[str, ParamEstimate]
    camera_history: CameraHistory
    phase_switch_t_us: Optional[int]
    phase1_skipped: bool
    counts: dict[str, int]
    warnings: tuple[str, ...]
    _summary_json: str
    _result: _native.ReplayResult

    @classmethod
    def _from_native(cls, native: _native.ReplayResult) -> Replay:
        """The typed result of a native replay, every array copied out once."""
        columns = native.frames
        t_us, phase, poses, covariances = (
            columns.t_us,
            columns.phase,
            columns.pose,
            columns.pose_covariance,
        )
        trajectory = np.zeros(len(t_us), dtype=TRAJECTORY_DTYPE)
        trajectory["t_us"] = t_us
        if len(t_us):
            trajectory["x"], trajectory["y"], trajectory["theta"] = poses.T
        frames = np.zeros(len(t_us), dtype=FRAME_INFO_DTYPE)
        frames["t_us"], frames["phase"] = t_us, phase
        for field in ("accepted", "rejected", "landmarks"):
            frames[field] = np.minimum(getattr(columns, field), _U32_MAX)
        nis_t, nis_id, nis_value = native.nis
        nis = np.zeros(len(nis_t), dtype=NIS_DTYPE)
        nis["t_us"], nis["id"], nis["nis"] = nis_t, nis_id, nis_value
        return cls(
            trajectory=_readonly(trajectory),
            pose_covariance=_readonly(covariances),
            phase=_readonly(phase),
            frames=_readonly(frames),
            nis=_readonly(nis),
            landmarks=_map(native.landmarks),
            maps=tuple(MapSnapshot(t, _map(raw)) for t, raw in native.maps),
            camera=_camera_dict(native.camera),
            vehicle=_vehicle_dict(native.vehicle),
            camera_history=CameraHistory(*(_readonly(a) for a in native.camera_history)),
            phase_switch_t_us=native.phase_switch_t_us,
            phase1_skipped=native.phase1_skipped,
            counts=dict(native.counts),
            warnings=tuple(native.warnings),
            _summary_json=native.summary_json(),
            _result=native,
        )

    @property
    def summary(self) -> dict[str, Any]:
        """``SUMMARY.json`` as a dict (a new one at each access); see the class docs."""
        summary: dict[str, Any] = json.loads(self._summary_json)
        return summary

    @property
    def truth(self) -> Optional[dict[str, Any]]:
        """The errors against the simulator's truth, or None; see the class docs."""
        truth: Optional[dict[str, Any]] = self.summary["truth"]
        return truth

    def write_estimates(self, path: Union[str, "os.PathLike[str]"]) -> None:
        """Write ``EST.mcap``: the estimates for a viewer (``vehicle-interfaces.md`` section 5).

        JSON messages throughout, in Foxglove's well-known schemas where one fits:
        ``/est/pose`` (``foxglove.PoseInFrame``, every frame), ``/est/trajectory``
        (``foxglove.PosesInFrame``), ``/est/landmarks`` (``foxglove.SceneUpdate``: the map
        with 3-sigma ellipsoids), and this project's ``/est/camera``
        (``stereonav.CameraEstimate``), ``/est/frame`` (``stereonav.FrameInfo``) and
        ``/est/summary`` (``stereonav.Summary``, the summary). zstd chunks, CRCs, a summary
        section. The GIL is released.

        Raises
        ------
        InputTypeError
            ``path`` is not a path.
        InputError
            The file cannot be created or written (the message names it; the ``OSError`` is
            the ``__cause__``), or a time is too late for a Foxglove timestamp.
        """
        self._result.write_estimates(_path("path", path))

    def write_summary(self, path: Union[str, "os.PathLike[str]"]) -> None:
        """Write ``SUMMARY.json``: :attr:`summary`, pretty-printed. Raises as
        :meth:`write_estimates`."""
        self._result.write_summary(_path("path", path))

    def write_trajectory(self, path: Union[str, "os.PathLike[str]"]) -> None:
        """Write ``TRAJ.csv``: a header ``t_us,x,y,theta`` and a row per stereo frame
        (:attr:`trajectory`; every number reads back to the same float). Raises as
        :meth:`write_estimates`."""
        self._result.write_trajectory(_path("path", path))

    def write_trajectory_tum(self, path: Union[str, "os.PathLike[str]"]) -> None:
        """Write the trajectory in the TUM format, as ``stereonav replay --trajectory-tum``:
        ``t x y z qx qy qz qw`` a line per stereo frame (``t`` in seconds exact to the
        microsecond, ``z = 0``, the heading as the quaternion ``(0, 0, sin(theta/2),
        cos(theta/2))``), for evo and other SLAM tools. Raises as :meth:`write_estimates`."""
        self._result.write_trajectory_tum(_path("path", path))

    def __repr__(self) -> str:
        switch = (
            "phase 1 skipped"
            if self.phase1_skipped
            else f"phase switch at t_us {self.phase_switch_t_us}"
        )
        return (
            f"<stereonav.Replay: {len(self.trajectory)} frames, {switch}, "
            f"{len(self.landmarks)} landmarks, {len(self.warnings)} warnings>"
        )


@final
@dataclasses.dataclass(frozen=True, eq=False)
class FrameOutcome:
    """What one frame of :meth:`Navigator.push_frame` did.

    Attributes
    ----------
    accepted : numpy.ndarray of GATE_DTYPE, shape (A,)
        Landmarks updated at this frame with their NIS (4 dof).
    rejected : numpy.ndarray of uint64, shape (R,)
        Landmarks whose observation the gate left out.
    added : numpy.ndarray of uint64, shape (K,)
        Landmarks added (tracks confirmed as new landmarks).
    removed : numpy.ndarray of uint64, shape (D,)
        Landmarks removed as false (rejected too many times in a row).
    rematched : numpy.ndarray of BINDING_DTYPE, shape (M,)
        Tracks bound to an existing landmark by map matching (a lamp seen again).
    solved : bool
        Phase 1 solved at this frame (a new calibration estimate).
    switched : bool
        The switch to phase 2 happened at this frame.
    no_odometry : bool
        The odometry did not reach back to the previous frame: the pose was held.
    """

    accepted: npt.NDArray[np.void]
    rejected: _U64
    added: _U64
    removed: _U64
    rematched: npt.NDArray[np.void]
    solved: bool
    switched: bool
    no_odometry: bool


# --- Checking the arguments ----------------------------------------------------------------


def _path(name: str, value: object) -> str:
    """A path as a ``str``."""
    if not isinstance(value, (str, os.PathLike)):
        raise InputTypeError(f"{name} must be a str or os.PathLike, got {_describe(value)}")
    path = os.fspath(value)
    if not isinstance(path, str):
        raise InputTypeError(f"{name} must be a str path, got {_describe(path)}")
    return path


def _topic(name: str, value: object) -> Optional[str]:
    """A ROS 2 topic's name, or None; whether the topics named fit together is checked by the
    native call (one message for the command line's rule: all three or none)."""
    if value is None or isinstance(value, str):
        return value
    raise InputTypeError(f"{name} must be a topic name (str) or None, got {_describe(value)}")


def _flag(name: str, value: object) -> bool:
    if not isinstance(value, (bool, np.bool_)):
        raise InputTypeError(f"{name} must be a bool, got {_describe(value)} {value!r}")
    return bool(value)


def _phase1_frames(value: object) -> Optional[int]:
    return None if value is None else _count("phase1_frames", value, 2)


def _timestamp(name: str, value: object) -> int:
    """A time in microseconds: an integer in ``0..2**64``."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise InputTypeError(
            f"{name} must be an int (microseconds), got {_describe(value)} {value!r}"
        )
    number = int(value)
    if not 0 <= number <= _U64_MAX:
        raise InputError(f"{name} is {number}, expected microseconds in 0..2**64")
    return number


def _column(name: str, value: object, rows: int) -> _F64:
    """A 1-D array of ``rows`` numbers, or one number for all of them, as a float64
    ``(rows,)`` array."""
    array = np.asarray(value)
    if array.dtype.kind not in "fiu":
        raise InputTypeError(f"{name} must be numbers, got {_describe(value)}")
    if array.ndim == 0:
        array = np.full(rows, array, dtype=np.float64)
    if array.shape != (rows,):
        raise InputError(f"{name} has shape {array.shape}, expected ({rows},) like t_us")
    return array.astype(np.float64)


def _features(side: str, value: object) -> _F64:
    """One image's features as a C-contiguous ``(N, 2)`` float64 array of pixels ``u, v``.

    Takes a structured array with integer fields ``x_q4`` and ``y_q4`` (the board's Q12.4
    coordinates: :attr:`Frame.left <stereonav.Frame>`, :func:`stereonav.harris`), converted
    exactly to ``x_q4 / 16``, ``y_q4 / 16``; or ``(N, 2)`` numbers, pixels ``u, v``.
    """
    if isinstance(value, np.ndarray) and value.dtype.names is not None:
        names = value.dtype.names
        if "x_q4" not in names or "y_q4" not in names:
            raise InputTypeError(
                f"{side} is a structured array with fields {', '.join(names)}; expected the "
                "fields x_q4 and y_q4 (FEATURE_DTYPE) or an (N, 2) array of pixels u, v"
            )
        if value.ndim != 1:
            raise InputError(f"{side} has shape {value.shape}, expected a 1-D array (N,)")
        columns = []
        for field in ("x_q4", "y_q4"):
            column = value[field]
            if column.dtype.kind not in "iu" or column.ndim != 1:
                raise InputTypeError(
                    f"{side} field {field!r} has dtype {column.dtype}, expected an unsigned "
                    "16-bit integer (<u2)"
                )
            if len(column) and (column.min() < 0 or column.max() > 0xFFFF):
                row = int(np.argmax((column < 0) | (column > 0xFFFF)))
                raise InputError(
                    f"{side}[{row}] {field} is {column[row]}, expected 0..=65535 (Q12.4)"
                )
            columns.append(column.astype(np.float64) / _Q4_SCALE)
        if not columns[0].size:
            return np.zeros((0, 2), dtype=np.float64)
        return np.ascontiguousarray(np.column_stack(columns))
    array = np.asarray(value)
    if array.dtype.kind not in "fiu":
        raise InputTypeError(
            f"{side} has dtype {array.dtype}, expected pixels (N, 2) as numbers or a "
            "structured array with fields x_q4 and y_q4"
        )
    if array.size == 0:
        array = array.reshape(0, 2)
    if array.ndim != 2 or array.shape[1] != 2:
        raise InputError(f"{side} has shape {array.shape}, expected (N, 2) = (u, v) pixels")
    return np.ascontiguousarray(array, dtype=np.float64)


def _rig(name: str, rig: object) -> _native.Rig:
    if not isinstance(rig, (str, os.PathLike, RigConfig)):
        raise InputTypeError(
            f"{name} must be a stereonav.RigConfig or the path of a rig file, got {_describe(rig)}"
        )
    return _native_rig(rig)


# --- The replay ----------------------------------------------------------------------------


def replay(
    log_path: Union[str, "os.PathLike[str]"],
    rig_path: Optional[RigLike] = None,
    *,
    skip_phase1: bool = False,
    phase1_frames: Optional[int] = None,
    consider_camera: bool = False,
    save_map: Optional[Union[str, "os.PathLike[str]"]] = None,
    left: Optional[str] = None,
    right: Optional[str] = None,
    odom: Optional[str] = None,
) -> Replay:
    """Run the whole stack on a vehicle log, as ``stereonav replay`` does.

    In Rust with the GIL released: the log (MCAP, ``vehicle-interfaces.md`` section 4) is
    read, the board's byte stream decoded (corrupt packets and lost frames are counted, never
    fatal), frames and odometry ordered by their timestamps, and the :class:`Navigator` fed
    with them frame by frame: phase 1 until the calibration is stable, the switch, phase 2.
    When the log carries the simulator's truth, the result says how far from it the estimates
    are (:attr:`Replay.truth`).

    A ROS 2 bag with camera images instead of the board's stream (section 4.1) is replayed
    with its topics named, as ``stereonav replay --left --right --odom`` does: the board's
    arithmetic runs on the host (:mod:`stereonav.bags`), and the summary's ``counts`` say what
    became of the images (``images_left``, ``images_right``, ``images_unpaired``,
    ``images_wrong_size``, ``images_unsupported``, ``images_undecodable``,
    ``image_frames_dropped``; an image that cannot be read is counted, never an error).

    Parameters
    ----------
    log_path : str or os.PathLike
        The vehicle log.
    rig_path : path or RigConfig, optional
        The rig file (or :func:`stereonav.load_rig`'s result); default: the log's ``/rig``
        message. A rig that differs from the log's is used, with a warning.
    skip_phase1 : bool, keyword-only
        Start phase 2 at the first frame from the rig's nominal values and priors (as in the
        paper's experiment) instead of self-calibrating first.
    phase1_frames : int, keyword-only
        Frames phase 1's batch (every pose, every landmark and the camera parameters at once)
        holds at most, ``>= 2``; when it is full before the calibration is stable, phase 2
        starts from what the data gave. Default 2000 (100 s at 20 Hz).
    consider_camera : bool, keyword-only
        Keep phase 2 from refining the camera parameters: their covariance is carried into
        the pose and landmark sigmas, their values stay phase 1's (Schmidt-Kalman; for drives
        on which refining them is over-confident, ``docs/phase2.md``).
    save_map : str or os.PathLike, keyword-only
        Write the map the run built to this file, as ``stereonav replay --save-map`` does: the
        final landmarks with their covariance, the calibrated camera and vehicle parameters
        and the rig, in the project's map format (``docs/maps.md``), for
        :func:`stereonav.localize` and :func:`stereonav.read_map`. Written after the run.
    left, right : str, keyword-only
        A ROS 2 bag's camera topics (``sensor_msgs/msg/Image`` or
        ``sensor_msgs/msg/CompressedImage``), as ``--left`` and ``--right``.
    odom : str, keyword-only
        The bag's odometry topic (``nav_msgs/msg/Odometry``), as ``--odom``. The three topics
        are named together or not at all; without them the log's ``/fpga/features`` and
        ``/odom`` are read. A bag carries no ``/rig``: give ``rig_path``.

    Returns
    -------
    Replay

    Raises
    ------
    InputTypeError
        (a ``TypeError``) an argument has the wrong type.
    InputError
        (a ``ValueError``) the log cannot be read (missing or unreadable file: the message
        names it, and the ``OSError`` is the ``__cause__``), is not an MCAP file, is an MCAP
        file without the vehicle topics, or has a malformed vehicle message; there is no rig
        (none given and no ``/rig`` in the log) or it is not valid (the file, the key and the
        problem are named); ``phase1_frames`` is out of range; the map cannot be written (the
        message names the file, the ``OSError`` is the ``__cause__``); one or two of ``left``,
        ``right``, ``odom`` are named (the message names the missing ones), a named topic is
        not in the bag (the message names the bag's topics) or is of another type; a ROS 2 bag
        with camera topics is replayed without them named (the message names its camera and
        odometry topics). A log cut short is not
        an error: it is replayed as far as it goes, and :attr:`Replay.warnings` says so.

    Examples
    --------
    >>> r = stereonav.replay("paper-experiment.mcap", "paper-experiment.rig.toml",
    ...                      skip_phase1=True)                     # doctest: +SKIP
    >>> r.summary["camera"]["baseline"], len(r.landmarks)         # doctest: +SKIP
    ({'value': 0.1164..., 'sigma': 0.0001...}, 5)
    """
    path = _path("log_path", log_path)
    native_rig = None if rig_path is None else _rig("rig_path", rig_path)
    native = _native.replay(
        path,
        native_rig,
        _flag("skip_phase1", skip_phase1),
        _phase1_frames(phase1_frames),
        _flag("consider_camera", consider_camera),
        None if save_map is None else _path("save_map", save_map),
        _topic("left", left),
        _topic("right", right),
        _topic("odom", odom),
    )
    return Replay._from_native(native)


# --- The navigator -------------------------------------------------------------------------


@final
class Navigator:
    """The method's two phases in one object, fed with odometry and stereo frames.

    Phase 1 (``"calibrating"``): each frame goes through the association (left-right
    matching on the rectified rig, frame-to-frame tracking predicted by the odometry); every
    frame's confirmed tracks and the odometry feed phase 1's batch (every pose, every landmark
    and the camera parameters solved at once, every half second). At the frame where the
    calibration becomes stable the navigator switches (:attr:`phase_switch_t_us`) to phase 2
    (``"navigating"``): the EKF with the camera parameters in the state starts from the
    batch's joint estimate of the pose, the landmarks and the camera, so that the frames of
    phase 1 are mapped; tracks bound to landmarks update it, unbound tracks are matched
    against the map or confirmed as new landmarks.

    Feed the odometry up to a frame's time (:meth:`push_odometry`) before the frame
    (:meth:`push_frame`); both must come in time order. The world frame is the robot at the
    first frame. A log's replay feeds the odometry up to :data:`ODOMETRY_LOOKAHEAD_US` past
    each frame's time (the board's clock offset may put the exposure after the stamp): fed
    that way, the navigator gives exactly what :func:`replay` gives.

    Parameters
    ----------
    rig : RigConfig or path
        The rig file (:func:`stereonav.load_rig`) or its path: image size, nominal camera,
        which parameters to estimate, their priors, the noise model.
    skip_phase1 : bool, keyword-only
        Start phase 2 at the first frame from the rig's nominal values and priors.
    phase1_frames : int, keyword-only
        Frames phase 1's batch holds at most, ``>= 2`` (default 2000; see :func:`replay`).
    consider_camera : bool, keyword-only
        Keep phase 2 from refining the camera parameters (see :func:`replay`).

    Raises
    ------
    InputTypeError
        (a ``TypeError``) an argument has the wrong type.
    InputError
        (a ``ValueError``) a bad rig (the file, the key and the problem are named) or a
        setting out of range.
    """

    def __init__(
        self,
        rig: RigLike,
        *,
        skip_phase1: bool = False,
        phase1_frames: Optional[int] = None,
        consider_camera: bool = False,
    ) -> None:
        self._native = _native.Navigator(
            _rig("rig", rig),
            _flag("skip_phase1", skip_phase1),
            _phase1_frames(phase1_frames),
            _flag("consider_camera", consider_camera),
        )

    def __repr__(self) -> str:
        x, y, theta = self.pose
        return (
            f"<stereonav.Navigator: {self.phase}, {len(self.landmarks)} landmarks, "
            f"pose ({x:.3f} m, {y:.3f} m, {theta:.4f} rad)>"
        )

    def push_odometry(
        self,
        t_us: Union[int, npt.ArrayLike],
        vx: Union[float, npt.ArrayLike],
        vy: Union[float, npt.ArrayLike],
        vtheta: Union[float, npt.ArrayLike],
    ) -> None:
        """Add odometry: one sample (scalars) or several (1-D arrays of equal length; a
        velocity given as one number holds for every sample).

        Robot-frame velocities, each held from its ``t_us`` until the next sample
        (``vehicle-interfaces.md`` section 2). Samples must be sorted by time and none older
        than those already pushed. The whole batch is checked before any sample is added.

        Parameters
        ----------
        t_us : int or array_like of int, shape (S,)
            Timestamps, microseconds.
        vx, vy : float or array_like of float, shape (S,)
            Velocities in the robot frame, m/s (one number: the same for every sample).
        vtheta : float or array_like of float, shape (S,)
            Yaw rate, rad/s (one number: the same for every sample).

        Raises
        ------
        InputTypeError
            A time that is not an integer, a velocity that is not a number.
        InputError
            Lengths that differ, a negative time, a velocity that is not finite, or a time
            before the previous sample's (the row is named). Nothing is added.
        """
        t_array = np.atleast_1d(np.asarray(t_us))
        if t_array.size == 0 and t_array.dtype.kind == "f":
            t_array = t_array.astype(np.uint64)  # an empty list: no samples
        times = _times("t_us", t_array)
        values = np.zeros((len(times), 3), dtype=np.float64)
        for k, (name, value) in enumerate((("vx", vx), ("vy", vy), ("vtheta", vtheta))):
            values[:, k] = _column(name, value, len(times))
        self._native.push_odometry(times, values)

    def push_odometry_samples(self, odometry: npt.NDArray[np.void]) -> None:
        """Add odometry given as a structured array of ``ODOMETRY_DTYPE`` (``t_us``, ``vx``,
        ``vy``, ``vtheta``), e.g. :attr:`Simulation.odometry <stereonav.Simulation>` or a
        slice of it. Checked and added as :meth:`push_odometry`.

        Raises
        ------
        InputTypeError
            ``odometry`` is not a structured array with those fields.
        InputError
            As :meth:`push_odometry`.
        """
        self._native.push_odometry(*_odometry_tables(odometry))

    def push_frame(self, t_us: int, left: npt.ArrayLike, right: npt.ArrayLike) -> FrameOutcome:
        """Process one stereo frame: its left and right features at ``t_us``.

        Push the odometry up to ``t_us`` first. The pose moves with the odometry since the
        previous frame; the features are matched left to right and tracked; in phase 1,
        frame pairs feed the self-calibration (which may switch to phase 2 at this frame); in
        phase 2, the filter is updated with the tracks bound to landmarks and new landmarks
        are confirmed. The GIL is released.

        Parameters
        ----------
        t_us : int
            The frame's timestamp (mid-exposure), microseconds; not before the previous
            frame's.
        left, right : numpy.ndarray
            Each image's features, either as the board sends them -- a structured array with
            integer fields ``x_q4``, ``y_q4`` (Q12.4 pixels), such as :attr:`Frame.left
            <stereonav.Frame>` of :class:`stereonav.StreamDecoder` or the result of
            :func:`stereonav.harris` -- or as ``(N, 2)`` numbers, pixels ``u, v``. Either
            may be empty.

        Returns
        -------
        FrameOutcome

        Raises
        ------
        InputTypeError
            A time that is not an integer, features of the wrong type or dtype.
        InputError
            A wrong shape, a pixel that is not finite (the side, row and field are named), a
            frame older than the previous one. Nothing changes.
        Error
            The filter refused this frame's update (its covariance lost positive
            definiteness); the frame's motion was applied, the update not.
        """
        t = _timestamp("t_us", t_us)
        native = self._native.push_frame(t, _features("left", left), _features("right", right))
        return FrameOutcome(
            accepted=_gated(native.accepted, native.accepted_nis),
            rejected=_readonly(native.rejected),
            added=_readonly(native.added),
            removed=_readonly(native.removed),
            rematched=_readonly(_bindings(native.rematched)),
            solved=native.solved,
            switched=native.switched,
            no_odometry=native.no_odometry,
        )

    def finish(self) -> bool:
        """The end of the drive (or of a log), as :func:`replay` does after the last frame.

        Phase 1, if it is still running, hands over now (so the frames seen so far are
        mapped even when the calibration never became stable); in phase 2 the fixed-lag
        smoother solves once more over its last frames and the filter takes its estimate.
        After it, the navigator's map, pose and camera equal :func:`replay`'s for the same log.

        Returns
        -------
        bool
            Whether phase 1 handed over now.

        Raises
        ------
        Error
            Phase 2 could not start from phase 1's hand-over.
        """
        return self._native.finish()

    @property
    def phase(self) -> str:
        """``"calibrating"`` (phase 1) or ``"navigating"`` (phase 2); see :data:`PHASES`."""
        return self._native.phase

    @property
    def phase_switch_t_us(self) -> Optional[int]:
        """When phase 2 started (the frame at which phase 1 became stable); None before, or
        when phase 1 was skipped."""
        return self._native.phase_switch_t_us

    @property
    def last_frame_t_us(self) -> Optional[int]:
        """Timestamp of the last frame processed, or None before the first."""
        return self._native.last_frame_t_us

    @property
    def pose(self) -> _F64:
        """``(3,)`` float64: the robot pose ``(X, Y, theta)``, metres and radians: the
        filter's in phase 2, dead reckoning before."""
        return self._native.pose

    @property
    def pose_covariance(self) -> _F64:
        """``(3, 3)`` float64: the covariance of :attr:`pose`."""
        return self._native.pose_covariance

    @property
    def camera(self) -> dict[str, ParamEstimate]:
        """Every camera parameter of :data:`CAMERA_PARAMETERS` with its 1-sigma: the
        filter's in phase 2, phase 1's latest solve before (the rig's nominal values and
        priors before the first solve)."""
        return _camera_dict(self._native.camera)

    @property
    def vehicle(self) -> dict[str, ParamEstimate]:
        """Every vehicle parameter of :data:`VEHICLE_PARAMETERS` (``vehicle-interfaces.md``
        1.2) with its 1-sigma, as :attr:`camera` gives the camera's."""
        return _vehicle_dict(self._native.vehicle)

    @property
    def camera_covariance(self) -> _F64:
        """``(10, 10)`` float64: the covariance of :attr:`camera`, :data:`CAMERA_PARAMETERS`
        order."""
        return self._native.camera_covariance

    @property
    def landmarks(self) -> npt.NDArray[np.void]:
        """``(N,)`` :data:`MAP_LANDMARK_DTYPE`: the map, by id (empty in phase 1)."""
        return _map(self._native.landmarks)

    @property
    def stats(self) -> dict[str, int]:
        """Counters over the navigator's life: ``frames``, ``odometry`` (samples),
        ``frames_without_odometry``, ``pairs`` (phase-1 frame pairs), ``rematched`` (tracks
        bound to a landmark by map matching), ``rejected`` (observations the gate left out),
        ``refused_updates`` (updates the filter refused)."""
        return dict(self._native.stats)
