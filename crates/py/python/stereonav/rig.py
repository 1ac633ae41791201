"""The stereo rig model (``vehicle-interfaces.md`` sections 1 and 3) over NumPy arrays.

A world point ``L`` seen by the robot at pose ``(X, Y, theta)`` gives four pixel measurements
``(uL, vL, uR, vR)``; :func:`project` computes them with the analytic Jacobians with respect
to the pose, the landmark and the ten camera parameters, and :func:`triangulate` goes back
from measurements to points with their covariance. :func:`load_rig` reads a rig file.
"""

from __future__ import annotations

import dataclasses
import os
from typing import NamedTuple, Union

import numpy as np
import numpy.typing as npt

from . import _native
from ._errors import InputError, InputTypeError

__all__ = [
    "CAMERA_PARAMETERS",
    "VEHICLE_PARAMETERS",
    "Camera",
    "Projection",
    "RigConfig",
    "Triangulated",
    "load_rig",
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
class RigConfig:
    """A rig file: image size, nominal camera, what to estimate, priors and noise."""

    width: int
    height: int
    nominal: Camera
    #: Names of the estimated parameters (the others stay at their nominal values).
    estimate: tuple[str, ...]
    #: 1-sigma prior of each estimated parameter.
    prior: dict[str, float]
    #: Pixel noise of each of uL, vL, uR, vR (px, 1 sigma).
    pixel_noise: float
    #: Odometry velocity noise per sample (m/s, 1 sigma).
    velocity_noise: float
    #: Odometry yaw-rate noise per sample (rad/s, 1 sigma).
    yaw_rate_noise: float


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


def rectify_points(
    points: npt.ArrayLike, rig_path: Union[str, os.PathLike[str]], camera: str = "left"
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
    rig_path : path
        The rig file (TOML).
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
    return _native.rectify_points(np.ascontiguousarray(array), os.fspath(rig_path), str(camera))


def load_rig(path: Union[str, os.PathLike[str]]) -> RigConfig:
    """Read a rig file (TOML, ``vehicle-interfaces.md`` section 3).

    Raises :class:`stereonav.InputError` naming the file, the key and the problem.
    """
    return _rig_config(_native.Rig.load(os.fspath(path)))


def _rig_config(native: _native.Rig) -> RigConfig:
    """The :class:`RigConfig` of a native rig (:func:`load_rig`, a log's ``/rig``)."""
    return RigConfig(
        width=native.width,
        height=native.height,
        nominal=Camera.from_array(native.nominal),
        estimate=tuple(native.estimate),
        prior=dict(native.prior),
        pixel_noise=native.pixel_noise,
        velocity_noise=native.velocity_noise,
        yaw_rate_noise=native.yaw_rate_noise,
    )


def _native_rig(rig: object) -> _native.Rig:
    """The native rig of a :class:`RigConfig` or a rig file's path, checked as a rig file is
    (errors name the path, or ``RigConfig``)."""
    if isinstance(rig, (str, os.PathLike)):
        source = os.fspath(rig)
        if not isinstance(source, str):
            raise InputTypeError(f"rig path must be a str path, got {type(source).__qualname__}")
        config = load_rig(source)
    elif isinstance(rig, RigConfig):
        source, config = "RigConfig", rig
    else:
        raise InputTypeError(
            "rig must be a stereonav.RigConfig or the path of a rig file, "
            f"got {type(rig).__qualname__}"
        )
    try:
        return _native.Rig(
            width=config.width,
            height=config.height,
            nominal=np.ascontiguousarray(config.nominal.to_array()),
            estimate=list(config.estimate),
            prior=list(dict(config.prior).items()),
            pixel_noise=config.pixel_noise,
            velocity_noise=config.velocity_noise,
            yaw_rate_noise=config.yaw_rate_noise,
            source=source,
        )
    except (TypeError, OverflowError) as err:
        raise InputError(f"{source}: not a valid rig: {err}") from err
