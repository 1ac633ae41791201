"""stereonav: ceiling-lamp stereo navigation for autonomous forklifts.

The Python face of the stereonav navigation stack. The heavy lifting happens in Rust, in the
native module :mod:`stereonav._native`; the functions here check their arguments, call it with
the GIL released, and hand back plain NumPy arrays with documented dtypes and shapes.

Corner detection (the camera board's detector, ``board-icd.md`` section 2, bit for bit):

- :func:`harris` -- the features of one image, as the board sends them;
- :func:`harris_detect` -- the same, with the board's overflow flag;
- :func:`harris_response` -- the board's Harris response map.

The board's feature stream (``board-icd.md`` section 3): :class:`StreamDecoder` takes the raw
bytes in any chunking and returns :class:`Frame` objects; :func:`encode_packet` writes packets.

Phase 1, self-calibration of the camera parameters (:mod:`stereonav.calibration`):
:func:`calibrate` solves frame pairs given as structured arrays (:data:`OBSERVATION_DTYPE`,
:data:`MOTION_DTYPE`), which :func:`frame_pairs` builds from measurements with landmark ids
and the odometry; :class:`SelfCalibrator` runs it pair by pair until it hands over to phase 2;
:func:`calibrate_log` runs all of phase 1 on a vehicle log (MCAP) and returns a
:class:`LogCalibration`.

Phase 2, EKF SLAM with the camera parameters in the state (:mod:`stereonav.filter`):
:class:`Filter` starts from phase 1's :class:`Handover` (or the rig's priors) and is stepped
frame by frame with the odometry (:meth:`Filter.predict_odometry`) and the stereo
measurements keyed by track (:meth:`Filter.observe`, which confirms new landmarks) or by
landmark (:meth:`Filter.update`); its map comes back as a :data:`LANDMARK_DTYPE` array and its
:class:`Health` says whether it stays consistent. :func:`monte_carlo` evaluates it over seeded
simulations (:mod:`stereonav.montecarlo`) against the truth: errors, sigmas, NEES and NIS.

The whole stack (:mod:`stereonav.navigation`): :class:`Navigator` runs both phases -- phase 1
until the calibration is stable, the switch, phase 2 -- fed by hand with the odometry and the
board's frames (:meth:`Navigator.push_odometry`, :meth:`Navigator.push_frame`);
:func:`replay` runs it on a whole vehicle log, as ``stereonav replay`` does, and returns a
:class:`Replay` with the summary (``SUMMARY.json``), the trajectory, the map, the camera
parameters over time and the writers of ``EST.mcap``, ``SUMMARY.json`` and ``TRAJ.csv``.

Saved maps and runs on them (:mod:`stereonav.localization`, ``docs/maps.md``): ``replay(...,
save_map=path)`` saves the map a replay built, as ``stereonav replay --save-map`` does;
:func:`localize` runs a vehicle log on a saved map, as ``stereonav localize`` does -- the
vehicle may start anywhere in the map -- and returns a :class:`Localization` with the summary
(``SUMMARY.json``), the trajectory in the map's frame (:data:`LOCALIZED_TRAJECTORY_DTYPE`,
with whether the stack stood behind each pose), when it (re)gained its position
(``localized_t_us``), the map's lamps it missed (``lamps_missing``) and the lamps new to the
map (:data:`NEW_LAMP_DTYPE`). :func:`read_map` reads a map file into a dict (its JSON body:
``format``, ``version``, ``created_unix_s``, ``source_log``, ``rig``, ``parameters``,
``landmarks``) and :func:`write_map` writes such a dict as a map file, both through the Rust
reader and writer of ``stereonav localize`` (the same checks; floats bit for bit).
:func:`import_map` makes a map from a hall's lighting plan or survey (a CSV of the lamps'
positions), as ``stereonav map import`` does: localised on in the hall's frame with the
vehicle's rig, without a mapping drive.

Vehicle logs for analysis (:mod:`stereonav.logs`): :func:`read_log` reads a log whole and
returns a :class:`VehicleLog` with what was logged -- the board's byte stream and its decoded
frames, the odometry, the ``/rig`` rig and, from the simulator, the truth (:class:`LogTruth`).

Robot logs with camera images (:mod:`stereonav.bags`, ``vehicle-interfaces.md`` 4.1): a ROS 2
bag (MCAP) of a vehicle without the board is replayed with its topics named --
``replay(bag, rig, left=..., right=..., odom=...)``, likewise :func:`localize` -- the board's
arithmetic running on the host. :func:`read_bag` reads such a bag as the replay does and
returns the stereo frames the host detected, the image counts (:class:`ImageCounts`) and the
odometry; :func:`decode_image` is the host's decode of one PNG or JPEG to gray.

Rig files (:mod:`stereonav.rig`): :func:`load_rig` reads one into a :class:`RigConfig`;
:func:`import_rig` makes one from a Kalibr, ROS or OpenCV stereo calibration, as
``stereonav rig import`` does (the same code; ``to_toml()`` gives the same file).

Exceptions derive from :class:`Error`: :class:`InputError` (also a ``ValueError``) for values
out of range, :class:`InputTypeError` (also a ``TypeError``) for arguments of the wrong type.
"""

from __future__ import annotations

from typing import Final

import numpy as np
import numpy.typing as npt

from . import _native
from ._arrays import FEATURE_DTYPE
from ._errors import Error, InputError, InputTypeError
from .board_stream import Frame, StreamDecoder, StreamStats, encode_packet
from .simulation import ODOMETRY_DTYPE, TRAJECTORY_DTYPE, Simulation, simulate
from .calibration import (
    MEASUREMENT_DTYPE,
    MOTION_DTYPE,
    OBSERVATION_DTYPE,
    Calibration,
    CalibrationHistory,
    Correlation,
    Handover,
    LogCalibration,
    Observability,
    ParamObservability,
    SelfCalibrator,
    calibrate,
    calibrate_log,
    frame_pairs,
    integrate_odometry,
)
from .filter import (
    BINDING_DTYPE,
    COVARIANCE_UPDATES,
    GATE_DTYPE,
    LANDMARK_DTYPE,
    Filter,
    FrameReport,
    Health,
    PredictedMeasurement,
    UpdateReport,
)
from .navigation import (
    FRAME_INFO_DTYPE,
    MAP_LANDMARK_DTYPE,
    NIS_DTYPE,
    ODOMETRY_LOOKAHEAD_US,
    PHASES,
    CameraHistory,
    FrameOutcome,
    MapSnapshot,
    Navigator,
    ParamEstimate,
    Replay,
    replay,
)
from .localization import (
    DEFAULT_LAMP_SIGMA_M,
    LOCALIZED_TRAJECTORY_DTYPE,
    MAP_VERSION,
    NEW_LAMP_DTYPE,
    Localization,
    import_map,
    localize,
    read_map,
    write_map,
)
from .logs import LogDamage, LogTruth, LostSpan, VehicleLog, read_log
from .bags import BagFrame, ImageCounts, Ros2Bag, decode_image, read_bag
from .montecarlo import Banded, MonteCarloRuns, MonteCarloSummary, monte_carlo
from .rig import (
    CAMERA_PARAMETERS,
    VEHICLE_PARAMETERS,
    Board,
    Camera,
    Lens,
    Projection,
    RigConfig,
    StereoLens,
    Triangulated,
    Vehicle,
    load_rig,
    import_rig,
    project,
    rectify_points,
    triangulate,
)

__all__ = [
    "DEFAULT_LAMP_SIGMA_M",
    "LOCALIZED_TRAJECTORY_DTYPE",
    "MAP_VERSION",
    "NEW_LAMP_DTYPE",
    "Localization",
    "import_map",
    "localize",
    "read_map",
    "write_map",
    "LogDamage",
    "LogTruth",
    "LostSpan",
    "VehicleLog",
    "read_log",
    "BagFrame",
    "ImageCounts",
    "Ros2Bag",
    "decode_image",
    "read_bag",
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
    "BINDING_DTYPE",
    "COVARIANCE_UPDATES",
    "GATE_DTYPE",
    "LANDMARK_DTYPE",
    "Filter",
    "FrameReport",
    "Health",
    "PredictedMeasurement",
    "UpdateReport",
    "Banded",
    "MonteCarloRuns",
    "MonteCarloSummary",
    "monte_carlo",
    "MEASUREMENT_DTYPE",
    "MOTION_DTYPE",
    "OBSERVATION_DTYPE",
    "Calibration",
    "CalibrationHistory",
    "Correlation",
    "Handover",
    "LogCalibration",
    "Observability",
    "ParamObservability",
    "SelfCalibrator",
    "calibrate",
    "calibrate_log",
    "frame_pairs",
    "integrate_odometry",
    "ODOMETRY_DTYPE",
    "TRAJECTORY_DTYPE",
    "Simulation",
    "simulate",
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
    "rectify_points",
    "project",
    "triangulate",
    "DEFAULT_MAX_FEATURES",
    "DEFAULT_THRESHOLD",
    "Error",
    "FEATURE_DTYPE",
    "Frame",
    "InputError",
    "InputTypeError",
    "MAX_FEATURES_LIMIT",
    "MAX_IMAGE_SIZE",
    "MIN_IMAGE_SIZE",
    "StreamDecoder",
    "StreamStats",
    "__version__",
    "encode_packet",
    "harris",
    "harris_detect",
    "harris_response",
]

def __getattr__(name: str) -> object:
    """``stereonav.fleet`` on first use: it needs the ``fleet`` extra (Dask, pandas), which
    ``import stereonav`` does not; without it the import error says what to install."""
    if name == "fleet":
        import importlib

        return importlib.import_module(f"{__name__}.fleet")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


#: The package version (the Rust workspace's version).
__version__: Final[str] = _native.__version__

#: The board's default ``THRESHOLD`` register, 2**18: a pixel is a candidate when ``r > T``.
DEFAULT_THRESHOLD: Final[int] = 1 << 18
#: The board's default ``MAX_FEATURES`` register: features kept per image.
DEFAULT_MAX_FEATURES: Final[int] = 512
#: Largest ``MAX_FEATURES`` register value (``max_features`` is in ``1..=1023``).
MAX_FEATURES_LIMIT: Final[int] = 1023
#: Smallest image width and height the board takes, in pixels.
MIN_IMAGE_SIZE: Final[int] = 16
#: Largest image width and height the board takes, in pixels.
MAX_IMAGE_SIZE: Final[int] = 4095

_I32_MIN: Final[int] = -(1 << 31)
_I32_MAX: Final[int] = (1 << 31) - 1


def _checked_image(image: object) -> npt.NDArray[np.uint8]:
    """Return ``image`` if it is a 2-D ``uint8`` array of a size the board takes, else raise."""
    if not isinstance(image, np.ndarray):
        raise InputTypeError(
            f"image must be a numpy.ndarray of dtype uint8, got {type(image).__qualname__}"
        )
    if image.dtype != np.uint8:
        raise InputTypeError(
            f"image dtype is {image.dtype}, expected uint8 (the board's 8-bit sensor); "
            "convert explicitly, e.g. with image.astype(np.uint8) after scaling"
        )
    if image.ndim != 2:
        raise InputError(
            f"image shape is {image.shape}, expected a 2-D (height, width) array "
            "(one grayscale image)"
        )
    height, width = image.shape
    for name, size in (("height", height), ("width", width)):
        if not MIN_IMAGE_SIZE <= size <= MAX_IMAGE_SIZE:
            raise InputError(
                f"image {name} {size} (shape {image.shape}) is outside the board's range "
                f"{MIN_IMAGE_SIZE}..={MAX_IMAGE_SIZE}"
            )
    return image


def _checked_int(name: str, value: object, low: int, high: int) -> int:
    """Return ``value`` as an ``int`` if it is an integer in ``low..=high``, else raise."""
    # bool is an int subclass, but True is no register value; NumPy integers are welcome.
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise InputTypeError(f"{name} must be an int, got {type(value).__qualname__} {value!r}")
    number = int(value)
    if not low <= number <= high:
        raise InputError(f"{name} {number} is outside the board's range {low}..={high}")
    return number


def harris_detect(
    image: npt.NDArray[np.uint8],
    *,
    threshold: int = DEFAULT_THRESHOLD,
    max_features: int = DEFAULT_MAX_FEATURES,
) -> tuple[npt.NDArray[np.void], bool]:
    """Detect the camera board's Harris features of an image, with the overflow flag.

    Runs the board's fixed-point Harris detector (``board-icd.md`` section 2) exactly: Sobel
    gradients, 5x5 window sums, response ``r = ((det << 10) - 41 T**2) >> 27`` (``k = 41/1024``),
    threshold, 3x3 non-maximum suppression with ties broken in raster order, sub-pixel offsets.

    Parameters
    ----------
    image : numpy.ndarray of uint8, shape (H, W)
        One 8-bit grayscale image, ``16 <= H, W <= 4095``. Any memory layout (views, strides,
        Fortran order) is accepted; a non-C-contiguous image is copied once.
    threshold : int, keyword-only
        The ``THRESHOLD`` register, a signed 32-bit integer: a pixel is a candidate when its
        response ``r > threshold``. Default ``2**18``.
    max_features : int, keyword-only
        The ``MAX_FEATURES`` register, ``1..=1023``: at most this many features are returned,
        the first ones in raster order. Default 512.

    Returns
    -------
    features : numpy.ndarray of FEATURE_DTYPE, shape (N,)
        ``N <= max_features`` features in the board's order (row by row, left to right, by
        the integer pixel): fields ``x_q4`` (``<u2``), ``y_q4`` (``<u2``), ``r`` (``<i4``).
        A new, writable, C-contiguous array.
    overflow : bool
        True when the image had more than ``max_features`` features (the board's overflow
        flag); the rest were dropped.

    Raises
    ------
    InputTypeError
        (a ``TypeError``) ``image`` is not a NumPy array or not ``uint8``; ``threshold`` or
        ``max_features`` is not an integer (``bool`` is refused).
    InputError
        (a ``ValueError``) ``image`` is not 2-D, or its size, ``threshold`` or ``max_features``
        is outside the board's range.
    """
    checked = _checked_image(image)
    t = _checked_int("threshold", threshold, _I32_MIN, _I32_MAX)
    n = _checked_int("max_features", max_features, 1, MAX_FEATURES_LIMIT)
    records, overflow = _native.harris(checked, t, n)
    # The native records are packed little-endian x_q4 u16, y_q4 u16, r i32: FEATURE_DTYPE.
    return records.view(FEATURE_DTYPE), bool(overflow)


def harris(
    image: npt.NDArray[np.uint8],
    threshold: int = DEFAULT_THRESHOLD,
    max_features: int = DEFAULT_MAX_FEATURES,
) -> npt.NDArray[np.void]:
    """Detect the camera board's Harris features of an image.

    The same as :func:`harris_detect` without the overflow flag: the features the board would
    send for this image with these registers, bit for bit (``board-icd.md`` section 2).

    Parameters
    ----------
    image : numpy.ndarray of uint8, shape (H, W)
        One 8-bit grayscale image, ``16 <= H, W <= 4095``, any memory layout.
    threshold : int
        The ``THRESHOLD`` register (signed 32-bit): candidates have ``r > threshold``.
        Default ``2**18``.
    max_features : int
        The ``MAX_FEATURES`` register, ``1..=1023``. Default 512.

    Returns
    -------
    numpy.ndarray of FEATURE_DTYPE, shape (N,)
        ``N <= max_features`` features in the board's (raster) order, fields ``x_q4``
        (``<u2``, column in 1/16 pixel), ``y_q4`` (``<u2``, row in 1/16 pixel) and ``r``
        (``<i4``, the response at the integer pixel).

    Raises
    ------
    InputTypeError
        (a ``TypeError``) wrong type of ``image`` (not an ndarray, not ``uint8``),
        ``threshold`` or ``max_features``.
    InputError
        (a ``ValueError``) ``image`` not 2-D, or a size or register value out of range.

    Examples
    --------
    >>> import numpy as np, stereonav
    >>> image = np.zeros((64, 64), np.uint8)
    >>> image[31:34, 31:34] = 255                      # one small bright lamp
    >>> features = stereonav.harris(image)
    >>> features["x_q4"] / 16, features["y_q4"] / 16
    (array([32.]), array([32.]))
    """
    features, _ = harris_detect(image, threshold=threshold, max_features=max_features)
    return features


def harris_response(image: npt.NDArray[np.uint8]) -> npt.NDArray[np.int32]:
    """Compute the camera board's Harris response map of an image.

    ``r(x, y) = ((det << 10) - 41 T**2) >> 27`` with ``det = Sxx Syy - Sxy**2`` and
    ``T = Sxx + Syy`` over the 5x5 window of Sobel gradients (``board-icd.md`` section 2,
    steps 1 to 3), exactly. Inside the border it equals
    ``cv2.cornerHarris(image, 5, 3, 41/1024) * 5100**4 / 2**17`` up to float32 rounding and
    the floor.

    Parameters
    ----------
    image : numpy.ndarray of uint8, shape (H, W)
        One 8-bit grayscale image, ``16 <= H, W <= 4095``, any memory layout.

    Returns
    -------
    numpy.ndarray of int32, shape (H, W)
        The response ``r[y, x]``, zero outside ``3 <= x <= W - 4``, ``3 <= y <= H - 4``,
        where the board computes none. A new, C-contiguous array.

    Raises
    ------
    InputTypeError
        (a ``TypeError``) ``image`` is not a NumPy array or not ``uint8``.
    InputError
        (a ``ValueError``) ``image`` is not 2-D or its size is outside ``16..=4095``.
    """
    return _native.harris_response(_checked_image(image))
