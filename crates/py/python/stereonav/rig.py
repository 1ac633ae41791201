"""The stereo rig model (``vehicle-interfaces.md`` sections 1 and 3) over NumPy arrays.

A world point ``L`` seen by the robot at pose ``(X, Y, theta)`` gives four pixel measurements
``(uL, vL, uR, vR)``; :func:`project` computes them with the analytic Jacobians with respect
to the pose, the landmark and the ten camera parameters, and :func:`triangulate` goes back
from measurements to points with their covariance. :func:`load_rig` reads a rig file.
"""

from __future__ import annotations

import dataclasses
import os
import warnings
from collections.abc import Mapping
from typing import Any, NamedTuple, Optional, Union, final

import numpy as np
import numpy.typing as npt

from . import _native
from ._errors import InputError, InputTypeError

__all__ = [
    "CAMERA_PARAMETERS",
    "VEHICLE_PARAMETERS",
    "Board",
    "Camera",
    "Lens",
    "Projection",
    "RigConfig",
    "StereoLens",
    "Triangulated",
    "Vehicle",
    "load_rig",
    "import_rig",
    "project",
    "triangulate",
]

#: The ten camera parameters ``C``, in the order of every camera array and Jacobian column.
CAMERA_PARAMETERS: tuple[str, ...] = tuple(_native.camera_parameter_names())
#: The four parameters of the vehicle ``V`` (``vehicle-interfaces.md`` 1.2: odometry scale,
#: yaw-rate scale and bias, the board's clock offset), in ``SUMMARY.json``'s ``vehicle`` order.
VEHICLE_PARAMETERS: tuple[str, ...] = tuple(_native.vehicle_parameter_names())

@dataclasses.dataclass(frozen=True)
class Camera:
    """The camera parameters ``C``: shared intrinsics of the rectified pair, baseline, mount.

    Lengths in metres, angles in radians, ``f``, ``cx``, ``cy`` in pixels. The mount is the
    rig's pose in the robot frame, ``R_RS = Rz(yaw) Ry(pitch) Rx(roll)``; all zero means the
    optical axis points straight up.
    """

    f: float
    cx: float
    cy: float
    baseline: float
    mount_x: float = 0.0
    mount_y: float = 0.0
    mount_z: float = 0.0
    mount_roll: float = 0.0
    mount_pitch: float = 0.0
    mount_yaw: float = 0.0

    def to_array(self) -> npt.NDArray[np.float64]:
        """The ten values as a float64 array in :data:`CAMERA_PARAMETERS` order."""
        return np.array([getattr(self, name) for name in CAMERA_PARAMETERS], dtype=np.float64)

    @classmethod
    def from_array(cls, values: npt.ArrayLike) -> Camera:
        """Camera parameters from ten values in :data:`CAMERA_PARAMETERS` order."""
        array = np.asarray(values, dtype=np.float64)
        if array.shape != (len(CAMERA_PARAMETERS),):
            raise InputError(f"camera array has shape {array.shape}, expected (10,)")
        return cls(**{name: float(v) for name, v in zip(CAMERA_PARAMETERS, array)})


@dataclasses.dataclass(frozen=True)
class Vehicle:
    """The vehicle's own parameters ``V`` (``vehicle-interfaces.md`` 1.2, the rig file's
    ``[vehicle]`` table): reported ``vx, vy`` = ``odom_scale`` x true, reported ``vtheta`` =
    ``odom_yaw_scale`` x true + ``odom_yaw_bias`` (rad/s), and ``time_offset`` (s: a board
    timestamp ``t`` was exposed at odometry-clock time ``t - time_offset``)."""

    odom_scale: float = 1.0
    odom_yaw_scale: float = 1.0
    odom_yaw_bias: float = 0.0
    time_offset: float = 0.0


@dataclasses.dataclass(frozen=True)
class Lens:
    """One raw camera's lens (``vehicle-interfaces.md`` 1.1, ``[lens.left]`` or
    ``[lens.right]``): ``model`` ``"plumb_bob"`` (``k1 k2 p1 p2 [k3]``) or ``"equidistant"``
    (``k1 k2 k3 k4``), the raw intrinsics, and ``rectification``, the 3x3 rotation from the raw
    camera to the rectified rig (row-major, as ROS ``CameraInfo`` ``R``)."""

    model: str
    fx: float
    fy: float
    cx: float
    cy: float
    coefficients: tuple[float, ...]
    #: Row-major 3x3.
    rectification: tuple[float, ...]


@dataclasses.dataclass(frozen=True)
class StereoLens:
    """The two lenses of a rig with raw board features (``[lens.left]`` and ``[lens.right]``)."""

    left: Lens
    right: Lens


@dataclasses.dataclass(frozen=True)
class Board:
    """The board's detector registers for images the host detects on (``[board]``,
    ``vehicle-interfaces.md`` 4.1; ``board-icd.md`` section 1)."""

    threshold: int
    max_features: int


#: The :meth:`RigConfig.replace` keywords and the rig-file table each one sets.
_REPLACEABLE = {
    "width": "camera",
    "height": "camera",
    "nominal": "camera, mount",
    "estimate": "estimate",
    "prior": "prior",
    "pixel_noise": "noise",
    "velocity_noise": "noise",
    "yaw_rate_noise": "noise",
    "velocity_tau": "noise",
    "yaw_rate_tau": "noise",
    "vehicle": "vehicle",
    "lens": "lens",
    "board": "board",
}

_NOISE_KEYS = {
    "pixel_noise": "pixel",
    "velocity_noise": "velocity",
    "yaw_rate_noise": "yaw_rate",
    "velocity_tau": "velocity_tau",
    "yaw_rate_tau": "yaw_rate_tau",
}


@final
class RigConfig:
    """A rig file (``vehicle-interfaces.md`` section 3), read and checked by the same Rust
    reader as the command line's: every table (``[camera]``, ``[mount]``, ``[estimate]``,
    ``[prior]``, ``[noise]``, ``[vehicle]``, ``[lens.*]``, ``[board]``) reaches the stack
    exactly as ``stereonav replay --rig`` reads it.

    The object holds the native rig itself; its attributes are read-only views of it. Make
    one with :func:`load_rig`, :meth:`from_toml`, :meth:`from_tables` or
    :func:`stereonav.import_rig`, change one with :meth:`replace` (checked again, as a file
    is), write it with :meth:`to_toml`.
    """

    __slots__ = ("_rig", "_text")

    _rig: _native.Rig
    _text: Optional[str]

    def __init__(self) -> None:
        raise InputTypeError(
            "make a RigConfig with stereonav.load_rig(path), RigConfig.from_toml(text), "
            "RigConfig.from_tables(tables) or stereonav.import_rig(...)"
        )

    @classmethod
    def _from_native(cls, native: _native.Rig, toml: Optional[str] = None) -> RigConfig:
        """Wrap a native rig; ``toml``, when given, is the text :meth:`to_toml` returns (a
        file as written, with its comments)."""
        self = object.__new__(cls)
        object.__setattr__(self, "_rig", native)
        object.__setattr__(self, "_text", toml)
        return self

    def __setattr__(self, name: str, value: object) -> None:
        raise dataclasses.FrozenInstanceError(f"RigConfig is read-only: use replace({name}=...)")

    @classmethod
    def load(cls, path: Union[str, os.PathLike[str]]) -> RigConfig:
        """Read a rig file (TOML); the same as :func:`load_rig`."""
        return load_rig(path)

    @classmethod
    def from_toml(cls, text: str, source: str = "RigConfig") -> RigConfig:
        """A rig from a rig file's TOML text; ``source`` names it in errors."""
        if not isinstance(text, str) or not isinstance(source, str):
            raise InputTypeError(
                f"text and source must be str, got {type(text).__qualname__} and "
                f"{type(source).__qualname__}"
            )
        return cls._from_native(_native.Rig.from_toml(text, source))

    @classmethod
    def from_json(cls, text: str, source: str = "RigConfig") -> RigConfig:
        """A rig from the JSON form of a rig file (a log's ``/rig`` message)."""
        if not isinstance(text, str) or not isinstance(source, str):
            raise InputTypeError(
                f"text and source must be str, got {type(text).__qualname__} and "
                f"{type(source).__qualname__}"
            )
        return cls._from_native(_native.Rig.from_json(text, source))

    @classmethod
    def from_tables(cls, tables: Mapping[str, Any], source: str = "RigConfig") -> RigConfig:
        """A rig from a rig file's tables as a dict of dicts (``{"camera": {"width": 752,
        ...}, "mount": {...}, ...}``, what :attr:`tables` returns), checked as the file is."""
        if not isinstance(tables, Mapping):
            raise InputTypeError(f"tables must be a dict of tables, got {type(tables).__qualname__}")
        return cls._from_native(_native.Rig.from_tables(_plain(tables), source))

    @property
    def tables(self) -> dict[str, Any]:
        """The rig file's tables as a dict of dicts (a fresh copy): every table and key of
        this rig, as :meth:`to_toml` writes them."""
        return self._rig.tables()

    def to_toml(self) -> str:
        """The rig file as TOML text (for a rig from :func:`stereonav.import_rig`, the file
        ``stereonav rig import`` writes, comments included)."""
        return self._text if self._text is not None else self._rig.to_toml()

    def to_json(self) -> str:
        """The rig file's tables as JSON (the form of a log's ``/rig`` message)."""
        return self._rig.to_json()

    def save(self, path: Union[str, os.PathLike[str]]) -> None:
        """Write :meth:`to_toml` to ``path``."""
        with open(os.fspath(path), "w", encoding="utf-8") as out:
            out.write(self.to_toml())

    def replace(self, **changes: Any) -> RigConfig:
        """A copy with some values changed, checked again as a rig file is (errors name
        ``RigConfig``). Keywords: ``width``, ``height``, ``nominal`` (a :class:`Camera`),
        ``estimate``, ``prior`` (the whole ``[prior]`` table), ``pixel_noise``,
        ``velocity_noise``, ``yaw_rate_noise``, ``velocity_tau``, ``yaw_rate_tau``,
        ``vehicle`` (a :class:`Vehicle`), ``lens`` (a :class:`StereoLens` or None), ``board``
        (a :class:`Board`). Every other table is kept as it is."""
        tables = self.tables
        for name, value in changes.items():
            if name not in _REPLACEABLE:
                raise InputTypeError(
                    f"RigConfig.replace: unknown field {name!r} (known: {', '.join(_REPLACEABLE)})"
                )
            if name in ("width", "height"):
                tables["camera"][name] = value
            elif name == "nominal":
                if not isinstance(value, Camera):
                    raise InputTypeError(f"nominal must be a Camera, got {type(value).__qualname__}")
                for key in ("f", "cx", "cy", "baseline"):
                    tables["camera"][key] = getattr(value, key)
                for key in ("x", "y", "z", "roll", "pitch", "yaw"):
                    tables["mount"][key] = getattr(value, f"mount_{key}")
            elif name == "estimate":
                tables["estimate"]["parameters"] = list(value)
            elif name == "prior":
                tables["prior"] = dict(value)
            elif name in _NOISE_KEYS:
                tables["noise"][_NOISE_KEYS[name]] = value
            elif name == "vehicle":
                if not isinstance(value, Vehicle):
                    raise InputTypeError(f"vehicle must be a Vehicle, got {type(value).__qualname__}")
                tables["vehicle"] = dataclasses.asdict(value)
            elif name == "lens":
                if value is None:
                    tables.pop("lens", None)
                elif isinstance(value, StereoLens):
                    tables["lens"] = {
                        side: dataclasses.asdict(getattr(value, side)) for side in ("left", "right")
                    }
                else:
                    raise InputTypeError(
                        f"lens must be a StereoLens or None, got {type(value).__qualname__}"
                    )
            else:  # board
                if not isinstance(value, Board):
                    raise InputTypeError(f"board must be a Board, got {type(value).__qualname__}")
                tables["board"] = dataclasses.asdict(value)
        return RigConfig.from_tables(tables, "RigConfig")

    #: :func:`copy.replace` (Python 3.13) does what :meth:`replace` does.
    __replace__ = replace

    def __reduce__(self) -> tuple[Any, ...]:
        # Pickled as its TOML text (Dask workers, multiprocessing): read back by the same parser.
        return (RigConfig.from_toml, (self._rig.to_toml(), "RigConfig"))

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, RigConfig):
            return NotImplemented
        return self._rig == other._rig

    __hash__ = None  # type: ignore[assignment]

    def __repr__(self) -> str:
        lens = self.lens
        return (
            f"RigConfig({self.width}x{self.height}, f={self.nominal.f}, "
            f"baseline={self.nominal.baseline}, estimate={list(self.estimate)}, "
            f"lens={'none' if lens is None else lens.left.model})"
        )

    @property
    def width(self) -> int:
        """``[camera] width``, pixels."""
        return self._rig.width

    @property
    def height(self) -> int:
        """``[camera] height``, pixels."""
        return self._rig.height

    @property
    def nominal(self) -> Camera:
        """The nominal camera: ``[camera]`` and ``[mount]``."""
        return Camera.from_array(self._rig.nominal)

    @property
    def vehicle(self) -> Vehicle:
        """The nominal vehicle parameters (``[vehicle]``; the defaults without the table)."""
        return Vehicle(*(float(v) for v in self._rig.vehicle))

    @property
    def estimate(self) -> tuple[str, ...]:
        """Names of the estimated parameters (the others stay at their nominal values)."""
        return tuple(self._rig.estimate)

    @property
    def prior(self) -> dict[str, float]:
        """1-sigma prior of each estimated parameter."""
        return dict(self._rig.prior)

    @property
    def pixel_noise(self) -> float:
        """Pixel noise of each of uL, vL, uR, vR (px, 1 sigma; of the raw features with lens
        tables)."""
        return self._rig.pixel_noise

    @property
    def velocity_noise(self) -> float:
        """Odometry velocity noise per sample (m/s, 1 sigma)."""
        return self._rig.velocity_noise

    @property
    def yaw_rate_noise(self) -> float:
        """Odometry yaw-rate noise per sample (rad/s, 1 sigma)."""
        return self._rig.yaw_rate_noise

    @property
    def velocity_tau(self) -> float:
        """Time constant of the odometry's velocity errors (s; 0: white)."""
        return self._rig.velocity_tau

    @property
    def yaw_rate_tau(self) -> float:
        """Time constant of the odometry's yaw-rate errors (s; 0: white)."""
        return self._rig.yaw_rate_tau

    @property
    def lens(self) -> Optional[StereoLens]:
        """The raw cameras' lenses (``[lens.left]``, ``[lens.right]``), or None when the
        board's features are rectified already."""
        table = self.tables.get("lens")
        if table is None:
            return None
        return StereoLens(*(_lens(table[side]) for side in ("left", "right")))

    @property
    def board(self) -> Board:
        """The board's registers for images the host detects on (``[board]``; the board's
        defaults without the table)."""
        return Board(self._rig.board_threshold, self._rig.board_max_features)


def _lens(table: Mapping[str, Any]) -> Lens:
    return Lens(
        model=str(table["model"]),
        fx=float(table["fx"]),
        fy=float(table["fy"]),
        cx=float(table["cx"]),
        cy=float(table["cy"]),
        coefficients=tuple(float(v) for v in table["coefficients"]),
        rectification=tuple(float(v) for v in table["rectification"]),
    )


def _plain(value: Any) -> Any:
    """Mappings as dicts and sequences as lists, all the way down (for the native reader)."""
    if isinstance(value, Mapping):
        return {key: _plain(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(item) for item in value]
    if isinstance(value, np.ndarray):
        return _plain(value.tolist())
    return value


class Projection(NamedTuple):
    """Measurements and Jacobians of :func:`project` (N landmarks)."""

    #: ``(N, 4)`` float64: ``uL, vL, uR, vR`` in pixels; NaN rows for points behind the cameras.
    z: npt.NDArray[np.float64]
    #: ``(N, 4, 3)``: d z / d (X, Y, theta).
    d_pose: npt.NDArray[np.float64]
    #: ``(N, 4, 3)``: d z / d landmark (world x, y, z).
    d_landmark: npt.NDArray[np.float64]
    #: ``(N, 4, 10)``: d z / d C, columns in :data:`CAMERA_PARAMETERS` order.
    d_camera: npt.NDArray[np.float64]


class Triangulated(NamedTuple):
    """Points of :func:`triangulate` (N measurements)."""

    #: ``(N, 3)``: in the rig frame (metres).
    p_in_rig: npt.NDArray[np.float64]
    #: ``(N, 3)``: in the robot frame.
    p_in_robot: npt.NDArray[np.float64]
    #: ``(N, 3)``: in the world frame.
    p_in_world: npt.NDArray[np.float64]
    #: ``(N, 3, 3)``: world-frame covariance from the pixel noise.
    cov_in_world: npt.NDArray[np.float64]


def _camera(camera: object) -> npt.NDArray[np.float64]:
    if isinstance(camera, Camera):
        return camera.to_array()
    try:
        array = np.asarray(camera, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise InputTypeError(f"camera must be a Camera or 10 numbers, got {type(camera).__qualname__}") from err
    if array.shape != (len(CAMERA_PARAMETERS),):
        raise InputError(f"camera has shape {array.shape}, expected (10,) in CAMERA_PARAMETERS order")
    return array


def _array(name: str, value: object, columns: int) -> npt.NDArray[np.float64]:
    try:
        array = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise InputTypeError(f"{name} must be numbers, got {type(value).__qualname__}") from err
    if array.ndim == 1 and columns > 0 and array.shape[0] == columns:
        array = array[np.newaxis, :]
    if array.ndim != 2 or array.shape[1] != columns:
        raise InputError(f"{name} has shape {array.shape}, expected (N, {columns})")
    return np.ascontiguousarray(array)


def _pose(pose: object) -> npt.NDArray[np.float64]:
    try:
        array = np.asarray(pose, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise InputTypeError(f"pose must be 3 numbers, got {type(pose).__qualname__}") from err
    if array.shape != (3,):
        raise InputError(f"pose has shape {array.shape}, expected (3,) = (x, y, theta)")
    return array


def project(
    landmarks: npt.ArrayLike, *, pose: npt.ArrayLike = (0.0, 0.0, 0.0), camera: Camera | npt.ArrayLike
) -> Projection:
    """Project world landmarks to ``(uL, vL, uR, vR)`` with the analytic Jacobians.

    Parameters
    ----------
    landmarks : array_like, shape (N, 3) or (3,)
        World coordinates in metres.
    pose : array_like, shape (3,)
        Robot pose ``(X, Y, theta)`` in the world frame.
    camera : Camera or array_like of 10 floats
        The camera parameters ``C``.

    Returns
    -------
    Projection
        ``z`` (N, 4) and the Jacobians ``d_pose`` (N, 4, 3), ``d_landmark`` (N, 4, 3),
        ``d_camera`` (N, 4, 10). Points behind the cameras give NaN rows.

    Raises
    ------
    InputError
        Wrong shapes or non-finite values.
    """
    return Projection(*_native.project(_array("landmarks", landmarks, 3), _pose(pose), _camera(camera)))


def triangulate(
    measurements: npt.ArrayLike,
    *,
    camera: Camera | npt.ArrayLike,
    pose: npt.ArrayLike = (0.0, 0.0, 0.0),
    sigma_px: float = 0.3,
) -> Triangulated:
    """Triangulate stereo measurements ``(uL, vL, uR, vR)`` into points with covariance.

    ``zs = f B / (uL - uR)``, ``xs = ((uL + uR) / 2 - cx) zs / f``,
    ``ys = ((vL + vR) / 2 - cy) zs / f`` in the rig frame, then through the mount and the pose.
    Rows whose disparity is not positive are NaN.

    Parameters
    ----------
    measurements : array_like, shape (N, 4) or (4,)
        Pixels.
    camera : Camera or array_like of 10 floats
        The camera parameters ``C``.
    pose : array_like, shape (3,)
        Robot pose ``(X, Y, theta)``.
    sigma_px : float
        Pixel noise (1 sigma) of each measurement, for the covariance.
    """
    return Triangulated(
        *_native.triangulate(
            _array("measurements", measurements, 4), _pose(pose), _camera(camera), float(sigma_px)
        )
    )


def import_rig(
    *,
    kalibr: str | os.PathLike[str] | None = None,
    ros: tuple[str | os.PathLike[str], str | os.PathLike[str]] | None = None,
    opencv: str | os.PathLike[str] | None = None,
) -> RigConfig:
    """A rig from a lab stereo calibration, as ``stereonav rig import`` makes it.

    ``vehicle-interfaces.md`` section 5, the same library code as the command line
    (``rig_model::import``): ``[camera]`` (the rectified ``f``, ``cx``, ``cy`` and baseline)
    and ``[lens.left]`` / ``[lens.right]`` (the raw lenses and their rectification) from the
    calibration, ``[mount]``, ``[estimate]``, ``[prior]`` and ``[noise]`` defaults to fill in.
    Kalibr and OpenCV calibrations are rectified exactly as OpenCV's ``stereoRectify``
    (``fisheye.stereoRectify`` for equidistant lenses) with ``CALIB_ZERO_DISPARITY`` and
    ``alpha = 0``; ROS ``camera_info`` files are taken with their ``R`` and ``P`` as given.
    ``docs/lenses.md`` says what each format must hold.

    Parameters
    ----------
    kalibr : path, optional
        Kalibr's ``camchain.yaml``: ``cam0`` left, ``cam1`` right.
    ros : (path, path), optional
        The ROS ``camera_info`` YAML of the left and of the right camera.
    opencv : path, optional
        OpenCV ``FileStorage`` YAML with ``K1 D1 K2 D2 R T``, ``width``, ``height`` (and
        ``model: equidistant`` for ``cv2.fisheye.stereoCalibrate``'s).

    Returns
    -------
    RigConfig
        The rig, exactly as the file ``stereonav rig import --out`` writes reads back; its
        ``to_toml()`` is that file, byte for byte (with the comments and the defaults marked
        ``DEFAULT, fill in``).

    Raises
    ------
    InputTypeError
        Not exactly one of ``kalibr``, ``ros`` and ``opencv``; a path that is not a ``str`` or
        ``os.PathLike``; ``ros`` not a pair.
    InputError
        ``ros`` with other than two paths; a calibration that cannot be imported, with the
        command line's one-line message naming the file, the key and the problem.

    Warns
    -----
    UserWarning
        A baseline over 2: the rig file takes metres (the command line's warning).
    """
    given = [name for name, value in (("kalibr", kalibr), ("ros", ros), ("opencv", opencv)) if value is not None]
    if len(given) > 1:
        raise InputTypeError(f"import_rig takes one calibration, got {' and '.join(given)}")
    if kalibr is not None:
        imported = _native.import_rig_kalibr(_calibration_path("kalibr", kalibr))
    elif ros is not None:
        if isinstance(ros, (str, bytes, os.PathLike)) or not isinstance(ros, (tuple, list)):
            raise InputTypeError(f"ros must be a pair of paths (left, right), got {type(ros).__qualname__}")
        if len(ros) != 2:
            raise InputError(f"ros must be two paths (left, right), got {len(ros)}")
        imported = _native.import_rig_ros(_calibration_path("ros[0]", ros[0]), _calibration_path("ros[1]", ros[1]))
    elif opencv is not None:
        imported = _native.import_rig_opencv(_calibration_path("opencv", opencv))
    else:
        raise InputTypeError(
            "import_rig needs one of kalibr=CAMCHAIN.yaml, ros=(LEFT.yaml, RIGHT.yaml) or opencv=STEREO.yml"
        )
    if imported.baseline_warning is not None:
        warnings.warn(imported.baseline_warning, UserWarning, stacklevel=2)
    return RigConfig._from_native(imported.rig, imported.toml)


def _calibration_path(name: str, value: object) -> str:
    """The ``str`` path of a calibration file argument, or :class:`InputTypeError`."""
    if not isinstance(value, (str, os.PathLike)):
        raise InputTypeError(f"{name} must be a path (str or os.PathLike), got {type(value).__qualname__}")
    path = os.fspath(value)
    if not isinstance(path, str):
        raise InputTypeError(f"{name} must be a str path, got {type(path).__qualname__}")
    return path


def rectify_points(
    points: npt.ArrayLike, rig_path: Union[RigConfig, str, os.PathLike[str]], camera: str = "left"
) -> npt.NDArray[np.float64]:
    """Raw pixel coordinates of one camera into the rectified rig model.

    ``vehicle-interfaces.md`` section 1.1: each point is undistorted with the rig file's
    ``[lens.left]`` or ``[lens.right]`` model (``plumb_bob`` or ``equidistant``, inverted
    exactly, not OpenCV's five fixed-point iterations), rotated by its rectification and
    projected with the ``[camera]`` table's ``f, cx, cy``.

    Parameters
    ----------
    points : array_like, shape (N, 2)
        Raw pixels ``u, v`` of that camera.
    rig_path : path or RigConfig
        The rig file (TOML), or the rig.
    camera : {"left", "right"}
        Which camera the points are of.

    Returns
    -------
    numpy.ndarray, shape (N, 2)
        The rectified pixels; ``NaN`` rows for points whose undistortion does not converge or
        whose ray points behind the camera. Without ``[lens]`` tables, the input.

    Raises
    ------
    InputError
        A bad rig file, a shape that is not ``(N, 2)``, a camera name not ``left``/``right``.
    """
    array = np.asarray(points, dtype=np.float64)
    if array.ndim != 2 or array.shape[1] != 2:
        raise InputError(f"points has shape {array.shape}, expected (N, 2)")
    return _native.rectify_points(np.ascontiguousarray(array), _native_rig(rig_path), str(camera))


def load_rig(path: Union[str, os.PathLike[str]]) -> RigConfig:
    """Read a rig file (TOML, ``vehicle-interfaces.md`` section 3), every table of it, with
    the command line's reader.

    Raises :class:`stereonav.InputError` naming the file, the key and the problem.
    """
    return RigConfig._from_native(_native.Rig.load(_rig_path(path)))


def _rig_path(path: object) -> str:
    if not isinstance(path, (str, os.PathLike)):
        raise InputTypeError(f"rig path must be a str or os.PathLike, got {type(path).__qualname__}")
    source = os.fspath(path)
    if not isinstance(source, str):
        raise InputTypeError(f"rig path must be a str path, got {type(source).__qualname__}")
    return source


def _native_rig(rig: object) -> _native.Rig:
    """The native rig of a :class:`RigConfig` (the one it holds) or a rig file's path (read
    by the command line's reader): nothing is copied, so no table is lost on the way."""
    if isinstance(rig, RigConfig):
        return rig._rig
    if isinstance(rig, (str, os.PathLike)):
        return _native.Rig.load(_rig_path(rig))
    raise InputTypeError(
        "rig must be a stereonav.RigConfig or the path of a rig file, "
        f"got {type(rig).__qualname__}"
    )
